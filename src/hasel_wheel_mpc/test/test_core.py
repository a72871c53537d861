"""The control core without ROS: its start policy, and that the path the nodes take (estimate
-> HybridStateEstimate message -> estimate, telemetry by message) makes the same commands as
the embedded runner, through a start, a step up and a braking step down."""
import math
from types import SimpleNamespace

import pytest

from hasel_wheel_common import samples
from hasel_wheel_mpc.closed_loop import WheelLoop, controller_config, reference_at
from hasel_wheel_mpc.core import (START, START_ANGLES, START_LEAD, START_PERIOD, START_WINDOW,
                                  ControlCore)
from hasel_wheel_mpc.observer import Estimate, Observer, estimate_from_msg
from hasel_wheel_sim.model import SECTOR
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import Plant, PlantConfig


def _estimate(xi1=0.0, xi2=1.0, q=0, act=math.inf, deact=math.inf, eta=0) -> Estimate:
    return Estimate(0.0, xi1, xi2, q, act, deact, eta, 0.01, 1.0)


def _feed(core: ControlCore, k: int, e: Estimate, speed: float = 1.0):
    """Sample k of a wheel turning at ``speed`` [rad/s] from e.xi1 at k = 0."""
    t = k / 300.0
    core.telemetry(t, e.xi1 + speed * t, 0)
    return core.step(e._replace(xi1=e.xi1 + speed * t), 1.0)


#: The first sample at which the encoder spans START_WINDOW (300 Hz samples from 0).
FIRST = math.ceil(START_WINDOW * 300 - 1e-9)


def test_a_wheel_with_no_pad_latched_gets_the_next_pad_ahead_of_the_encoder():
    core = ControlCore(controller_config())
    # an observer still converging reads 5 rad/s; the encoder says 1 rad/s
    out = [_feed(core, k, _estimate(xi1=0.3, xi2=5.0)) for k in range(FIRST + 1)]
    assert [r.command for r in out[:FIRST]] == [None] * FIRST
    lead = core.mpc.config.deadline_margin + START_LEAD
    angle = 0.3 + FIRST / 300.0
    # the first pad whose activation angle is ahead of the angle + 1 rad/s x lead
    want = math.floor((angle + lead - START_ANGLES[0]) / SECTOR) + 1
    assert out[FIRST].why == START and out[FIRST].decision is None
    assert out[FIRST].command == samples.Command(want, *START_ANGLES, 0)


def test_the_start_command_is_sent_again_only_after_its_period():
    core = ControlCore(controller_config())
    e = _estimate(xi1=0.0, xi2=0.0)
    sent = [k for k in range(FIRST + 3 * START_PERIOD + 1)
            if _feed(core, k, e, speed=0.0).command]
    assert sent == [FIRST + n * START_PERIOD for n in range(4)]


def test_no_start_command_while_a_pad_is_latched_within_two_sectors():
    core = ControlCore(controller_config())
    for k in range(2 * START_PERIOD):
        assert _feed(core, k, _estimate(act=1.5 * SECTOR)).command is None
    assert not core.started and core.starts == 0


def test_the_first_switch_on_ends_the_start_and_the_mpc_decides_there():
    core = ControlCore(controller_config())
    _feed(core, 0, _estimate())
    r = _feed(core, 1, _estimate(q=1, act=0.0, deact=0.3, eta=1))
    assert core.started and r.why == "switch_on" and r.decision is not None
    assert r.command.sequence == 1 and r.command.n_a == 2


class _NodePath:
    """Observer and core as observer_node and mpc_node use them: the estimate travels as a
    HybridStateEstimate message, the telemetry as a WheelTelemetry message."""

    def __init__(self, cfg):
        self.observer = Observer(cfg.params, cfg.extensions, config=cfg.observer)
        self.core = ControlCore(cfg, clock=lambda: 0.0)
        self.observer.command_sent(0, *START_ANGLES)

    def step(self, s, reference):
        e = self.observer.step(s)
        tm = samples.telemetry_msg(s)
        self.core.telemetry(tm["device_time_us"] * 1e-6, tm["angle"],
                            tm["last_command_sequence"])
        m = samples.state_msg(e.t, e.xi1, e.xi2, e.q, e.act_counter, e.deact_counter,
                              e.eta_unwrapped, e.xi2_std, e.quality, e.accel_disturbance,
                              e.accel_coefficients)
        stamp = SimpleNamespace(sec=int(e.t), nanosec=round((e.t - int(e.t)) * 1e9))
        msg = SimpleNamespace(**{**m, "header": SimpleNamespace(stamp=stamp)})
        r = self.core.step(estimate_from_msg(msg), reference)
        if r.command is not None:                    # observer_node hears it on `command`
            self.observer.command_sent(r.command.sequence, r.command.phi_a, r.command.phi_d)
        return r


@pytest.fixture(scope="module")
def both_paths():
    """A start from 1 rad/s, a step up to 2.6 rad/s at 6 s and a braking step down to 2.0 at
    14 s on the nominal plant: the embedded runner's commands, and the node path's commands
    from the same samples."""
    profile = ((0.0, 1.0), (6.0, 2.6), (14.0, 2.0))
    loop = WheelLoop(controller_config(), profile, PlantConfig(switching="tick"), w0=1.0,
                     clock=lambda: 0.0)
    node = _NodePath(controller_config())
    embedded, via_nodes = [], []
    start = loop._pending
    while loop.plant.t < 20.0:
        s = loop.plant.step(loop._pending)
        loop._pending = None
        if s is None:
            continue
        ref = reference_at(profile, s.t)
        s = samples.as_received(s)
        r = loop.ctrl.step(s, ref)
        n = node.step(s, ref)
        if r.command is not None:
            loop._pending = r.command
            embedded.append((s.t, r.command, r.d))
        if n.command is not None:
            via_nodes.append((s.t, n.command, n.d))
    return start, embedded, via_nodes, loop


def test_the_node_path_sends_the_embedded_runners_commands(both_paths):
    _, embedded, via_nodes, _ = both_paths
    decisions = [c for c in embedded if c[1].sequence > 0]
    assert len(decisions) > 60
    assert [c for c in via_nodes if c[1].sequence > 0] == decisions


def test_the_step_down_is_braked_and_the_step_up_driven(both_paths):
    _, embedded, _, _ = both_paths
    after_up = [c for t, c, _ in embedded if 6.0 <= t < 6.5]
    after_down = [c for t, c, _ in embedded if 14.0 <= t < 14.3]
    assert after_up and all(c.phi_a >= 0.0 for c in after_up)
    assert after_down and after_down[0].phi_a < 0.0 and after_down[0].phi_d <= 0.0


def test_the_embedded_runner_starts_with_the_core_start_command(both_paths):
    start, _, _, loop = both_paths
    assert start.sequence == 0 and (start.phi_a, start.phi_d) == START_ANGLES
    assert loop.ctrl.core.starts == 1 and loop.ctrl.core.started


def test_a_node_that_hears_the_estimate_before_its_telemetry_still_starts_the_wheel():
    """In the ROS graph estimates can reach mpc_node before the telemetry samples they are
    for, here ten at a time, and the observer's first estimates overshoot: the start pads
    then never step back and the wheel's first switch-on comes within a second."""
    cfg = controller_config()
    plant = Plant(WheelParams(), PlantConfig(switching="tick"), xi2=1.0)
    observer = Observer(cfg.params, cfg.extensions, config=cfg.observer)
    observer.command_sent(0, *START_ANGLES)
    core = ControlCore(cfg, clock=lambda: 0.0)
    pending, starts, first_on, held = None, [], None, []
    while plant.t < 1.0 and first_on is None:
        s = plant.step(pending)
        pending = None
        if s is None:
            continue
        s = samples.as_received(s)
        r = core.step(observer.step(s), 1.0)            # the estimate first ...
        held.append(s)
        if len(held) == 10:                             # ... then its samples, in a burst
            for h in held:
                core.telemetry(h.t, h.angle, h.last_command_sequence)
            held = []
        if r.command is not None:
            pending = r.command
            observer.command_sent(r.command.sequence, r.command.phi_a, r.command.phi_d)
            if r.why == START:
                starts.append(r.command.n_a)
        if s.q:
            first_on = s.t
    assert starts and starts == sorted(starts)
    assert first_on is not None and first_on < 1.0


def test_a_standing_wheel_is_started_with_a_start_of_the_pad_in_contact():
    from hasel_wheel_mpc.core import START_NOW_WINDOW, ControlCore
    from hasel_wheel_sim.model import SECTOR
    core = ControlCore()
    cmd = core.start_command(5 * SECTOR + math.radians(10), 0.0)
    assert (cmd.n_a, cmd.phi_a, cmd.phi_d, cmd.now) == (5, *START_NOW_WINDOW, True)
    rolling = core.start_command(5 * SECTOR + math.radians(10), 1.0)
    assert not rolling.now and rolling.n_a == 6
    core.sent_start(cmd, 5 * SECTOR + math.radians(10))
    assert core.angles_of(0) == pytest.approx((math.radians(10), SECTOR))  # where it switches on
