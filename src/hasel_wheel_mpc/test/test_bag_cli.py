"""``hasel_wheel bag info`` from the command line."""
from hasel_wheel_driver import topics
from hasel_wheel_driver.bagio import BagWriter
from hasel_wheel_mpc.cli import main


def test_the_command_line_prints_it_and_names_a_bad_path(tmp_path, capsys):
    bag = tmp_path / "b"
    with BagWriter(bag) as b:
        b.add_topic("/slow", topics.REFERENCE.type, topics.REFERENCE.qos)
        for k in range(11):
            b.write("/slow", {"data": float(k)}, k * 100_000_000)
    assert main(["bag", "info", str(bag)]) == 0
    out = capsys.readouterr().out
    assert "/slow" in out and "10.00" in out and "duration 1.000 s, 11 messages" in out
    assert main(["bag", "info", str(tmp_path / "nope")]) == 2
    assert "no such bag" in capsys.readouterr().err
