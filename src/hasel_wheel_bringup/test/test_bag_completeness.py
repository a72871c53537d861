"""bag completeness: the bag's telemetry against the device node's own published count."""
import json

from hasel_wheel_bag.writer import BagWriter
from hasel_wheel_bringup.bag_completeness import bag_completeness
from hasel_wheel_bringup.cli import main
from hasel_wheel_common import samples, topics
from hasel_wheel_common.published_count import PublishedCount

DEVICE_LOST = {50, 51}         # sequences the device itself never published


def _status(node: str, count: PublishedCount) -> dict:
    values = [{"key": k, "value": v} for k, v in count.diagnostics().items()]
    return {"header": samples.header(0.0, ""), "status": [
        {"level": 0, "name": f"{node}: simulator", "message": "simulating",
         "hardware_id": "hasel_wheel_sim", "values": values}]}


def _bag(path, recording_loses=()):
    """Sequences 0..199 minus DEVICE_LOST published on /w0; the device reports after 150
    and after 199; ``recording_loses`` never reach the bag."""
    tlm, diag = topics.TELEMETRY, topics.DIAGNOSTICS
    count = PublishedCount()
    with BagWriter(path) as b:
        b.add_topic("/w0/telemetry", tlm.type, tlm.qos)
        b.add_topic("/diagnostics", diag.type, diag.qos)
        for k in range(200):
            t_ns = k * 3_333_333
            if k not in DEVICE_LOST:
                count.count(k)
                if k not in recording_loses:
                    s = samples.TelemetrySample(k / 300, k * 3333, k, 0, 0.0, 0, 0, 0, 0, 0.0,
                                                0.0, 0, 0)
                    b.write("/w0/telemetry", samples.telemetry_msg(s), t_ns)
            if k in (150, 199):
                b.write("/diagnostics", _status("/w0/sim", count), t_ns + 1)
    return path


def test_a_complete_recording_holds_every_published_sample(tmp_path):
    (w,) = bag_completeness(_bag(tmp_path / "bag"))
    assert (w.namespace, w.recorded, w.published, w.last_sequence) == ("/w0", 198, 198, 199)
    assert w.sequence_gaps == len(DEVICE_LOST)     # the device's own losses show as gaps
    assert w.missing == 0


def test_samples_lost_by_the_recording_are_counted(tmp_path):
    (w,) = bag_completeness(_bag(tmp_path / "bag", recording_loses={10, 11, 12}))
    assert w.missing == 3 and w.recorded == 195 and w.sequence_gaps == 5


def test_the_command_exits_1_when_samples_are_missing(tmp_path, capsys):
    assert main(["bag", "completeness", str(_bag(tmp_path / "ok"))]) == 0
    capsys.readouterr()
    assert main(["bag", "completeness", "--json",
                 str(_bag(tmp_path / "lossy", recording_loses={7}))]) == 1
    (report,) = json.loads(capsys.readouterr().out)
    assert (report["namespace"], report["missing"]) == ("/w0", 1)


def test_without_a_device_report_nothing_is_claimed(tmp_path):
    tlm = topics.TELEMETRY
    with BagWriter(tmp_path / "bag") as b:
        b.add_topic("/telemetry", tlm.type, tlm.qos)
        s = samples.TelemetrySample(0.0, 0, 0, 0, 0.0, 0, 0, 0, 0, 0.0, 0.0, 0, 0)
        b.write("/telemetry", samples.telemetry_msg(s), 1)
    (w,) = bag_completeness(tmp_path / "bag")
    assert (w.namespace, w.recorded, w.missing) == ("", 1, None)
    assert main(["bag", "completeness", str(tmp_path / "bag")]) == 1
