"""``hasel_wheel bag info`` and ``export`` from the command line."""
import pytest

from hasel_wheel_common import topics
from hasel_wheel_bag.layout import BagError, BagErrorCode
from hasel_wheel_bag.writer import BagWriter
from hasel_wheel_bringup.cli import main


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


def test_export_parquet_round_trips_in_row_groups(tmp_path, capsys, monkeypatch):
    """Telemetry to Parquet in batches of 7 rows (so several row groups): every value and
    type comes back as written.  pyarrow is optional (``colcon test`` may run without it)."""
    pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow is not installed (optional: "
                             "pip install 'pyarrow<26')")

    from hasel_wheel_bag import export as bagexport
    from hasel_wheel_common import samples

    monkeypatch.setattr(bagexport._ParquetSink, "BATCH", 7)
    bag = tmp_path / "p"
    n = 30
    with BagWriter(bag) as b:
        b.add_topic("/w0/telemetry", topics.TELEMETRY.type, topics.TELEMETRY.qos)
        for k in range(n):
            t = k / 300
            s = samples.TelemetrySample(t, round(t * 1e6), k, k % 1024, 0.01 * k, k % 2, k % 16,
                                        k, 1 << (k % 16), 9000.0, 3e-4, k // 3, 0)
            b.write("/w0/telemetry", samples.telemetry_msg(s), round(t * 1e9))
    assert main(["bag", "export", str(bag), "--out", str(tmp_path / "pq"),
                 "--format", "parquet"]) == 0
    assert "/w0/telemetry: 30 rows" in capsys.readouterr().out
    f = pq.ParquetFile(tmp_path / "pq" / "w0__telemetry.parquet")
    assert f.metadata.num_row_groups == 5                  # 7 + 7 + 7 + 7 + 2
    table = f.read()
    assert table.num_rows == n
    assert table.column("sequence").to_pylist() == list(range(n))
    assert table.column("angle").to_pylist() == [0.01 * k for k in range(n)]
    assert table.column("t").to_pylist() == [round(k / 300 * 1e9) / 1e9 for k in range(n)]
    assert str(table.schema.field("hv_monitor").type) == "double"
    assert table.column("header.frame_id").to_pylist() == ["wheel"] * n


def test_export_refuses_an_unknown_format(tmp_path):
    from hasel_wheel_bag.export import export
    with pytest.raises(BagError, match="'xlsx'") as refused:
        export(tmp_path, tmp_path / "o", fmt="xlsx")
    assert refused.value.code == BagErrorCode.EXPORT_FORMAT


def test_parquet_without_pyarrow_says_what_to_install(tmp_path, monkeypatch):
    import sys

    from hasel_wheel_bag.export import export
    monkeypatch.setitem(sys.modules, "pyarrow", None)          # import pyarrow now fails
    bag = tmp_path / "b"
    with BagWriter(bag) as b:
        b.add_topic("/r", topics.REFERENCE.type, topics.REFERENCE.qos)
        b.write("/r", {"data": 1.0}, 0)
    with pytest.raises(BagError, match="pyarrow") as refused:
        export(bag, tmp_path / "o", fmt="parquet")
    assert refused.value.code == BagErrorCode.EXPORT_NEEDS_PYARROW
