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


def test_export_writes_one_csv_per_topic_with_flat_columns(tmp_path, capsys):
    import csv
    import math

    bag = tmp_path / "j"
    with BagWriter(bag) as b:
        b.add_topic("/w0/joint_states", topics.JOINT_STATES.type, topics.JOINT_STATES.qos)
        b.add_topic("/w0/reference_speed", topics.REFERENCE.type, topics.REFERENCE.qos)
        for k in range(5):
            t_ns = round(k / 300 * 1e9)
            b.write("/w0/joint_states",
                    {"header": {"stamp": {"sec": 0, "nanosec": t_ns}, "frame_id": ""},
                     "name": ["wheel_joint"], "position": [0.1 * k], "velocity": [2.0],
                     "effort": []}, t_ns)
        b.write("/w0/reference_speed", {"data": 1.5}, 0)
    assert main(["bag", "export", str(bag), "--out", str(tmp_path / "csv"),
                 "--topics", "/w0/joint_states,/w0/nothing"]) == 0
    captured = capsys.readouterr()
    assert "/w0/joint_states: 5 rows" in captured.out
    assert "no messages on /w0/nothing" in captured.err
    with open(tmp_path / "csv" / "w0__joint_states.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 5
    assert list(rows[0]) == ["t", "header.stamp.sec", "header.stamp.nanosec", "header.frame_id",
                             "name[0]", "position[0]", "velocity[0]"]
    assert [float(r["position[0]"]) for r in rows] == [0.1 * k for k in range(5)]
    assert math.isclose(float(rows[3]["t"]), 3 / 300, abs_tol=1e-9)
    assert not (tmp_path / "csv" / "w0__reference_speed.csv").exists()
