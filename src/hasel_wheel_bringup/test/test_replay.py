"""Offline replay: a recorded closed loop re-computed from its bag.

Unchanged, every estimate and decision must come back bit for bit; changed, the report must
show differences, and none before the first decision the change can affect (causality: the
replay is open loop on recorded telemetry).
"""
import dataclasses
import math
import shutil

import numpy as np
import pytest

from hasel_wheel_common import samples
from hasel_wheel_bag.layout import BagError
from hasel_wheel_bag.reader import bag_configuration, read_messages
from hasel_wheel_bringup.bag_cli import main as bag_main
from hasel_wheel_sim.params import packaged
from hasel_wheel_mpc.closed_loop import run_closed_loop
from hasel_wheel_mpc.config import ControllerConfig
from hasel_wheel_mpc.mpc import Mpc, MpcConfig
from hasel_wheel_mpc.observer import ObserverConfig
from hasel_wheel_mpc.recorder import Recorder
from hasel_wheel_bringup.replay import PlaybackClock, replay_bag
from hasel_wheel_sim.params import ParameterError
from hasel_wheel_sim.plant import load_plant_config

#: up, up, then down far enough to brake (2.2 -> 1.2 rad/s)
PROFILE = ((0.0, 1.0), (4.0, 2.2), (8.0, 1.2))
DURATION = 12.0


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A 12 s closed loop on the realistic plant (wall-clock MPC deadline), recorded."""
    path = tmp_path_factory.mktemp("replay") / "run"
    plant = dataclasses.replace(load_plant_config(packaged("hasel_wheel_sim",
                                                            "plant_realistic.yaml")),
                                switching="tick")
    rec = Recorder(path, {"tool": "test_replay"})
    log = run_closed_loop(PROFILE, DURATION, plant_config=plant, recorder=rec,
                          observer_config=ObserverConfig(accel_noise=0.07))
    rec.close()
    return path, log


def test_unchanged_replay_is_identical(recorded):
    path, log = recorded
    [rep] = replay_bag(path)
    assert rep.configuration == "the bag (/wheel0/controller.yaml)"
    assert rep.identical, rep.text()
    assert rep.samples == len(log.t) == rep.estimates_recorded == rep.estimates_compared
    assert rep.decisions_recomputed == rep.decisions_recorded == len(log.decisions) > 30
    assert any(d.braking for _, d in log.decisions)          # the braking path is covered too
    assert "IDENTICAL" in rep.text()


def test_recorded_configuration_is_the_run_s(recorded):
    path, _ = recorded
    cfg = ControllerConfig.from_yaml(bag_configuration(path)["/wheel0/controller.yaml"])
    assert cfg == ControllerConfig(observer=ObserverConfig(accel_noise=0.07))


def test_a_lone_mcap_file_keeps_its_configuration(recorded, tmp_path):
    """Without metadata.yaml (a killed recorder writes none) the configuration comes from
    the MCAP file's own records, and the replay is still exact."""
    path, _ = recorded
    lone = tmp_path / "copy.mcap"
    shutil.copy(next(path.glob("*.mcap")), lone)
    assert bag_configuration(lone)["tool"] == "test_replay"
    [rep] = replay_bag(lone)
    assert rep.identical and rep.configuration.startswith("the bag")


def test_a_changed_brake_threshold_differs_from_a_decision_on(recorded):
    path, log = recorded
    [rep] = replay_bag(path, {"mpc.brake_threshold": 0.6})
    assert not rep.identical
    decided_at = {round(t, 6) for t, _ in log.decisions}
    t1 = rep.first_difference
    assert round(t1, 6) in decided_at                      # the first change is a decision
    assert all(d.first_t > t1 for d in rep.estimate_diffs.values())   # estimates follow it
    # the higher threshold first shows as a decision that drives where the run braked
    assert rep.decision_diffs["braking"].first_t == t1
    assert rep.decision_diffs["command.mode"].first_t == t1
    assert "DIFFERENT from t =" in rep.text() and "decision.braking" in rep.text()


def test_no_estimator_changes_the_disturbance_first(recorded):
    path, _ = recorded
    [rep] = replay_bag(path, {"estimator.gain": None})
    assert rep.decision_diffs["disturbance"].first_t == rep.first_difference


def test_playback_clock_replays_compute_times():
    clock = PlaybackClock([0.25, 0.001])
    assert [clock() for _ in range(6)] == [0.0, 0.25, 0.0, 0.001, 0.0, 0.0]


def test_a_played_back_late_decision_takes_the_fallback():
    """A recorded compute time longer than the time to the switch-off must give the same
    miss and fallback again: slack = left - margin - compute (closed form)."""
    mpc = Mpc(config=MpcConfig(), clock=PlaybackClock([0.5]))
    fallback = mpc.last_drive
    sector = math.pi / 8
    d = mpc.decide(xi1=3 * sector + math.radians(10.0), xi2=2.0, eta_unwrapped=3,
                   phi_a_now=math.radians(3.0), phi_d_now=math.radians(22.0), reference=2.0)
    assert d.compute_time == 0.5 and d.deadline_missed
    assert (d.command.phi_a, d.command.phi_d) == fallback
    assert d.deadline_slack < 0.0


def test_configuration_yaml_round_trip_and_errors():
    cfg = ControllerConfig(estimator_gain=None, speed_source="finite_difference",
                           mpc=MpcConfig(brake_threshold=0.25))
    assert ControllerConfig.from_yaml(cfg.to_yaml()) == cfg
    assert cfg.with_overrides({"model.wheel.tau_f": 1.5}).params.tau_f == 1.5
    with pytest.raises(ParameterError, match="no field 'bogus'.*known: .*brake_threshold"):
        cfg.with_overrides({"mpc.bogus": 1})
    with pytest.raises(ParameterError, match="no section 'mcp'"):
        cfg.with_overrides({"mcp.brake_threshold": 1})
    with pytest.raises(ParameterError, match="brake_threshold = -1.*expected > 0"):
        cfg.with_overrides({"mpc.brake_threshold": -1})
    with pytest.raises(ParameterError, match="speed_source = 'gps'"):
        cfg.with_overrides({"speed_source": "gps"})
    with pytest.raises(ParameterError, match="estimator gain = 'fast': expected null"):
        cfg.with_overrides({"estimator.gain": "fast"})
    with pytest.raises(ParameterError, match="accel_noise = 'abc': expected a finite number"):
        cfg.with_overrides({"observer.accel_noise": "abc"})
    with pytest.raises(ParameterError, match="time_weighted = 1: expected true or false"):
        cfg.with_overrides({"mpc.time_weighted": 1})
    with pytest.raises(ParameterError, match="phi_a = 'x': expected a list of finite numbers"):
        cfg.with_overrides({"mpc.phi_a": "x"})
    assert cfg.with_overrides({"observer.window": 200}).observer.window == 200


def test_as_received_is_what_a_node_decodes(recorded):
    """The runner's controller sees each sample exactly as decoded from the bag: the device
    clock in whole microseconds as its time, the monitors as float32."""
    path, log = recorded
    n = 0
    for (_, _, m), t_plant in zip(read_messages(path, topics=["/wheel0/telemetry"]), log.t):
        s = samples.telemetry_from_msg(m)
        assert s.t == m.device_time_us * 1e-6 and abs(s.t - t_plant) <= 0.5e-6
        assert samples.as_received(s) == s
        n += 1
    assert n == len(log.t)
    raw = samples.TelemetrySample(1 / 3, 333_333, 1, 0, 0.1, 0, 0, 0, 0, 0.1, 0.3, 0)
    seen = samples.as_received(raw)
    assert seen.t == 0.333333 and seen.hv_monitor == float(np.float32(0.1)) != 0.1
    assert seen.current_monitor == float(np.float32(0.3))


def test_replay_errors_name_what_is_missing(recorded):
    path, _ = recorded
    with pytest.raises(BagError, match="namespace '/wheel9' has no telemetry.*'/wheel0'"):
        replay_bag(path, namespaces=["/wheel9"])


def test_replay_cli(recorded, capsys):
    path, _ = recorded
    assert bag_main(["replay", str(path), "--check"]) == 0
    assert "IDENTICAL" in capsys.readouterr().out
    assert bag_main(["replay", str(path), "--check", "--set", "mpc.brake_threshold=0.6"]) == 1
    assert "DIFFERENT" in capsys.readouterr().out
    assert bag_main(["replay", str(path), "--set", "mpc.nope=1"]) == 2
    assert "no field 'nope'" in capsys.readouterr().err


def test_the_packaged_ros_parameter_files_are_the_core_defaults():
    """observer.yaml and mpc.yaml (what the nodes load) build the same controller as the
    core's defaults, so a ROS bag replays with what the nodes ran."""
    from hasel_wheel_mpc.config import controller_from_ros_files
    obs = packaged("hasel_wheel_mpc", "observer.yaml").read_text()
    mpc = packaged("hasel_wheel_mpc", "mpc.yaml").read_text()
    assert controller_from_ros_files(obs, mpc) == ControllerConfig()
    changed = controller_from_ros_files(
        obs.replace("accel_noise: 0.05", "accel_noise: 0.08"),
        mpc.replace("brake_threshold: 0.2", "brake_threshold: 0.25").replace(
            "estimator_gain: 0.07", "estimator_gain: 0.0"))
    assert changed.observer.accel_noise == 0.08 and changed.estimator_gain is None
    assert changed.mpc.brake_threshold == 0.25
    with pytest.raises(ParameterError, match="no 'mpc_node: ros__parameters:' section"):
        controller_from_ros_files(obs, obs)
