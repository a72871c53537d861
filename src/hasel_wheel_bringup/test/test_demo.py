"""The main job: the demo runs as the README says, prints the table next to the paper, and
writes a bag that an independent reader decodes completely; the same config gives the same
bag byte for byte."""
import math

import pytest
import yaml
from rosbags.highlevel import AnyReader

from hasel_wheel_bringup import cli
from hasel_wheel_sim import paper
from hasel_wheel_mpc.config import ControllerConfig
from hasel_wheel_sim.params import packaged


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    import contextlib
    import io
    # the packaged trials at 1 and 11 deg only (the six take 3x as long and test nothing more)
    shipped = yaml.safe_load(packaged("hasel_wheel_bringup", "demo_open_loop.yaml").read_text())
    shipped["open_loop"]["phi_a"]["values"] = [math.radians(1.0), math.radians(11.0)]
    trials = out / "trials.yaml"
    trials.write_text(yaml.safe_dump(shipped))
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert cli.main(["table2", "--out", str(out), "--trials", str(trials)]) == 0
    return out, buf.getvalue()


def test_demo_prints_the_table_beside_table_ii(demo):
    _, text = demo
    rows = [l for l in text.splitlines() if l.strip().split("|")[0].strip().endswith("deg")]
    assert [int(r.split()[0]) for r in rows] == [1, 11]
    one = rows[0].split("|")
    exact_ss = float(one[1].split()[0])
    paper_ss = float(one[3].split()[0])
    assert paper_ss == pytest.approx(paper.TABLE_II_PHI_D22[1][1] / 0.157, abs=0.01)
    assert float(one[4].split()[0]) == pytest.approx(exact_ss / paper_ss, abs=0.01)
    assert exact_ss == pytest.approx(4.73, rel=0.02)          # cli.NOTES_CROSS_CHECK


def test_demo_bag_decodes_completely_with_rosbags(demo):
    out, _ = demo
    info = yaml.safe_load((out / "bag" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    counts = {}
    last = {}
    with AnyReader([out / "bag"]) as r:
        for conn, ts, raw in r.messages():
            msg = r.deserialize(raw, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            last[conn.topic] = msg
    assert sum(counts.values()) == info["message_count"]
    per_topic = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    assert counts == per_topic
    assert len(per_topic) == 4 * 4                      # 2 trials x 2 switching modes x 4 topics
    # 60 s at 300 Hz on every telemetry topic, ending at the trial's last sample
    tel = last["/exact/phi_a_01p0deg/telemetry"]
    assert counts["/exact/phi_a_01p0deg/telemetry"] == 18000
    assert tel.sequence == 18000 and tel.header.stamp.sec == 60
    truth = last["/exact/phi_a_01p0deg/sim/true_state"]
    assert 4.0 < truth.xi2 < 5.5 and truth.eta == truth.eta_unwrapped % 16
    assert set(info["custom_data"]) >= {"git_revision", "seed", "wheel_params.yaml", "plant.yaml"}


def test_same_config_same_bag_bytes(tmp_path):
    cfg = tmp_path / "short.yaml"
    cfg.write_text(yaml.safe_dump({"open_loop": {
        "duration": {"value": 3.0, "unit": "s"}, "initial_speed": {"value": 1.0, "unit": "rad/s"},
        "phi_d": {"value": math.radians(22), "unit": "rad"},
        "phi_a": {"values": [math.radians(3)], "unit": "rad"}, "priming_count": 6}}))
    for name in ("a", "b"):
        assert cli.main(["table2", "--out", str(tmp_path / name), "--trials", str(cfg)]) == 0
    a = (tmp_path / "a" / "bag" / "bag_0.mcap").read_bytes()
    b = (tmp_path / "b" / "bag" / "bag_0.mcap").read_bytes()
    assert a == b and len(a) > 10_000


def test_bad_trials_file_is_a_clear_error(tmp_path, capsys):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(yaml.safe_dump({"open_loop": {"phi_a": {"values": [0.5], "unit": "rad"}}}))
    assert cli.main(["table2", "--out", str(tmp_path / "o"), "--trials", str(cfg)]) == 2
    err = capsys.readouterr().err
    assert "phi_a.values[0]" in err and "0.5" in err and "rad" in err


def test_trials_take_paired_phi_a_phi_d():
    from hasel_wheel_bringup.trials import trials_from_mapping
    from hasel_wheel_sim.params import ParameterError
    r = math.radians
    specs = trials_from_mapping({"phi_a": {"values": [r(1), r(3)], "unit": "rad"},
                                 "phi_d": {"values": [r(22), r(14)], "unit": "rad"},
                                 "priming_count": 6})
    assert [(s.phi_a, s.phi_d, s.priming) for s in specs] == [(r(1), r(22), 6), (r(3), r(14), 6)]
    assert specs[1].label == "phi_a_03p0deg_phi_d_14p0deg"
    with pytest.raises(ParameterError, match="phi_d has 3 values but phi_a has 2"):
        trials_from_mapping({"phi_a": {"values": [r(1), r(3)], "unit": "rad"},
                             "phi_d": {"values": [r(22)] * 3, "unit": "rad"}})
    with pytest.raises(ParameterError, match="trial 0: phi_a = .* must be smaller than phi_d"):
        trials_from_mapping({"phi_a": {"value": r(12), "unit": "rad"},
                             "phi_d": {"value": r(11), "unit": "rad"}})


def test_link_run_drives_the_wheel_over_a_pty_and_records(tmp_path, capsys):
    assert cli.main(["link-run", "--seconds", "12", "--time-scale", "4",
                     "--out", str(tmp_path / "lr")]) == 0
    cap = capsys.readouterr()
    out = cap.out
    print(out, cap.err)
    assert "CRC errors 0, framing errors 0, sequence gaps 0" in out
    assert "device rejects 0" in out and "HV off confirmed" in out
    speed = float(out.split("final speed ")[1].split()[0])
    assert speed > 2.5                                    # driven from 2 rad/s at 3 deg
    info = yaml.safe_load((tmp_path / "lr" / "bag" / "metadata.yaml").read_text())
    counts = {t["topic_metadata"]["name"]: t["message_count"]
              for t in info["rosbag2_bagfile_information"]["topics_with_message_count"]}
    assert counts["/wheel0/telemetry"] > 12 * 300 * 0.9 and counts["/wheel0/command"] > 50


def test_closed_loop_demo_writes_bag_plots_and_table(tmp_path, capsys):
    from rosbags.highlevel import AnyReader
    out = tmp_path / "cl"
    assert cli.main(["demo", "--out", str(out), "--hold-scale", "0.25", "--no-compare"]) == 0
    text = capsys.readouterr().out
    assert "with estimator (tracking)" in text and "fall time ~1.2 s" in text
    assert not (out / "fig11a_without_estimator.png").exists()       # --no-compare: no such run
    for name in ("fig11b_with_estimator.png", "fig11c_braking_step.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    topics_seen = {}
    with AnyReader([out / "bag"]) as reader:
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            topics_seen.setdefault(conn.topic, []).append(msg)
    refs = [m.data for m in topics_seen["/wheel0/reference_speed"]]
    assert refs == [1.0, 1.5, 2.0, 2.5, 2.6, 2.0]                     # the Fig. 11 profile
    status = topics_seen["/wheel0/mpc_status"]
    # every decision's command, after the runner's own start command (sequence 0, no status)
    commands = topics_seen["/wheel0/command"]
    assert commands[0].sequence == 0 and commands[0].n_a == 1
    assert len(status) == len(commands) - 1 > 50
    assert [c.sequence for c in commands[1:]] == [s.command.sequence for s in status]
    assert all(s.candidates_evaluated >= 15 for s in status if not s.braking)
    est = topics_seen["/wheel0/state_estimate"]
    assert len(est) == len(topics_seen["/wheel0/telemetry"]) > 10000
    # the recorded run re-computes exactly from its own bag (wall-clock deadline included)
    assert cli.main(["bag", "replay", str(out / "bag"), "--check"]) == 0
    assert "IDENTICAL" in capsys.readouterr().out


def test_closed_loop_demo_runs_n_wheels_each_under_its_namespace(tmp_path, capsys):
    """Two wheels in lockstep on plants with seeds 0 and 1: one bag, each wheel under its own
    namespace with its own controller configuration; both replay exactly, and the noise
    draws differ (different seeds), so their telemetry does too."""
    from hasel_wheel_bag.reader import bag_configuration, read_messages
    from hasel_wheel_bringup.bag_metrics import bag_metrics
    out = tmp_path / "two"
    assert cli.main(["demo", "--out", str(out), "--hold-scale", "0.08", "--no-compare",
                     "--wheels", "2", "--set", "mpc.brake_phi_d=-0.12"]) == 0
    text = capsys.readouterr().out
    assert "with estimator (tracking), /wheel1:" in text
    bag = out / "bag"
    cfg = bag_configuration(bag)
    assert {"/wheel0/controller.yaml", "/wheel1/controller.yaml"} <= set(cfg)
    for ns in ("/wheel0", "/wheel1"):          # --set reached every wheel's controller
        assert ControllerConfig.from_yaml(cfg[f"{ns}/controller.yaml"]).mpc.brake_phi_d == -0.12
    assert cfg["wheels"] == "2" and cfg["same_wheel"] == "false"
    assert [w.namespace for w in bag_metrics(bag)] == ["/wheel0", "/wheel1"]
    angles = {"/wheel0/telemetry": [], "/wheel1/telemetry": []}
    last = -1
    for topic, t_ns, m in read_messages(bag, topics=list(angles)):
        assert t_ns >= last                       # lockstep: one time-ordered recording
        last = t_ns
        angles[topic].append(m.encoder_raw)
    assert len(angles["/wheel0/telemetry"]) > 4000
    assert angles["/wheel0/telemetry"] != angles["/wheel1/telemetry"]
    assert cli.main(["bag", "replay", str(bag), "--check"]) == 0
    assert capsys.readouterr().out.count("IDENTICAL") == 2
    assert cli.main(["demo", "--out", str(tmp_path / "o"), "--wheels", "0"]) == 2


@pytest.mark.parametrize("same_wheel", [True, False])
def test_closed_loop_demo_records_runs_of_one_wheel_or_separate_wheels(tmp_path, capsys,
                                                                       same_wheel):
    """On a plant whose only random draw is the gain spread (no encoder noise), two runs of
    one wheel (``--same-wheel``) record the very same telemetry; two wheels, each with the
    gains of its own seed, do not."""
    from hasel_wheel_bag.reader import bag_configuration, read_messages
    plant = tmp_path / "plant.yaml"
    plant.write_text(yaml.safe_dump({"plant": {"seed": 4, "switching": "tick", "effects": {
        "gain_spread": {"enabled": True, "std": {"value": 0.1, "unit": "1"}},
        "encoder": {"enabled": True, "noise_std": {"value": 0.0, "unit": "rad"}}}}}))
    out = tmp_path / "o"
    args = ["demo", "--out", str(out), "--plant", str(plant), "--hold-scale", "0.04",
            "--no-compare", "--wheels", "2"]
    assert cli.main(args + (["--same-wheel"] if same_wheel else [])) == 0
    capsys.readouterr()
    assert bag_configuration(out / "bag")["same_wheel"] == str(same_wheel).lower()
    raw = {"/wheel0/telemetry": [], "/wheel1/telemetry": []}
    for topic, _t, m in read_messages(out / "bag", topics=list(raw)):
        raw[topic].append((m.encoder_raw, m.q, m.eta))
    assert len(raw["/wheel0/telemetry"]) > 2000
    assert (raw["/wheel0/telemetry"] == raw["/wheel1/telemetry"]) is same_wheel


def test_the_comparison_runs_are_on_the_plant_of_the_first_wheel(monkeypatch):
    """With runs of one wheel, wheel 0 and the comparison runs share one plant: its gains
    held and its noise seed (not the plant of the bare configuration, whose noise would
    follow its own draw of the gains)."""
    from hasel_wheel_bringup import demo as D
    from hasel_wheel_sim.effects import REALISTIC, effects_from_mapping
    from hasel_wheel_sim.plant import PlantConfig, run_configs
    seen = []
    real_loop, real_run = D.WheelLoop, D.run_controller

    def loop(cfg, profile, plant_config, **kw):
        seen.append(("loop", plant_config))
        return real_loop(cfg, profile, plant_config, **kw)

    def run(cfg, profile, duration, plant_config, **kw):
        seen.append(("compare", plant_config))
        return real_run(cfg, profile, duration, plant_config, **kw)

    monkeypatch.setattr(D, "WheelLoop", loop)
    monkeypatch.setattr(D, "run_controller", run)
    pc = PlantConfig(seed=5, switching="tick", effects=effects_from_mapping(
        {"gain_spread": REALISTIC["gain_spread"], "encoder": REALISTIC["encoder"]}))
    D.run_variants(pc, 0.01, D.VARIANTS[:2], wheels=2, same_wheel=True)
    wheels = run_configs(pc, 2, same_wheel=True)
    assert seen == [("loop", wheels[0]), ("loop", wheels[1]), ("compare", wheels[0])]
    assert wheels[0].effects.gains is not None and pc.effects.gains is None


def test_same_wheel_needs_several_runs(tmp_path, capsys):
    assert cli.main(["demo", "--out", str(tmp_path / "o"), "--same-wheel"]) == 2
    assert "--same-wheel records several runs of one wheel: give --wheels 2 or more (got " \
        "--wheels 1)" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_closed_loop_demo_refuses_an_unknown_override_before_writing(tmp_path, capsys):
    out = tmp_path / "o"
    assert cli.main(["demo", "--out", str(out), "--set", "mpc.brake_angle=-0.3"]) == 2
    assert "no field 'brake_angle'; known: ['brake_phi_a'" in capsys.readouterr().err
    assert not out.exists()


def test_closed_loop_demo_refuses_a_bad_hold_scale(tmp_path, capsys):
    assert cli.main(["demo", "--out", str(tmp_path / "o"), "--hold-scale", "0"]) == 2
    assert "--hold-scale 0.0: expected a positive factor" in capsys.readouterr().err


def test_an_earlier_or_empty_bag_dir_is_replaced_but_anything_else_is_kept(tmp_path, capsys):
    out = tmp_path / "out"
    (out / "bag").mkdir(parents=True)                 # a run killed before it recorded
    assert cli._fresh_bag_dir(out) == out / "bag" and not (out / "bag").exists()
    (out / "bag").mkdir()
    (out / "bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    assert cli._fresh_bag_dir(out) == out / "bag" and not (out / "bag").exists()
    (out / "bag").mkdir()
    (out / "bag" / "bag_0.mcap").write_bytes(b"\x89MCAP0\r\n")   # cut off before it closed
    assert cli._fresh_bag_dir(out) is None
    assert (out / "bag" / "bag_0.mcap").read_bytes() == b"\x89MCAP0\r\n"
    assert "no metadata.yaml" in capsys.readouterr().err
