"""The host-run open-loop schedule (the trial node's core) on the simulated wheel."""
import math

import pytest

from hasel_wheel_common.samples import ENCODER_COUNT
from hasel_wheel_bringup.trial_schedule import TrialSchedule
from hasel_wheel_bringup.trials import TrialSpec, run_trial
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.plant import Plant, PlantConfig

D = math.radians


def drive(schedule, seconds_after=1.0):
    """Run the paper model's plant (1 rad/s at t = 0) under ``schedule`` until it is done and
    ``seconds_after`` more; returns (sent commands with their sample times, the true angle
    [rad] by simulated time [s] rounded to 1 us)."""
    plant = Plant(None, PlantConfig(), xi1=0.0, xi2=1.0)
    sent, true_angle = [], {}
    cmd, t_done = None, math.inf
    while plant.t < t_done + seconds_after:
        s = plant.step(cmd)
        cmd = None
        true_angle[round(plant.t, 6)] = plant.wheel.s[L.S_XI1]
        if s is None:
            continue
        cmd = schedule.step(s)
        if cmd is not None:
            sent.append((s.t, cmd))
        if schedule.done and t_done == math.inf:
            t_done = s.t
    return sent, true_angle


@pytest.fixture(scope="module")
def two_steps():
    steps = [TrialSpec(D(3.0), D(22.0), duration=30.0), TrialSpec(D(9.0), D(22.0), duration=30.0)]
    schedule = TrialSchedule(steps)
    sent, true_angle = drive(schedule)
    return schedule, sent, true_angle


def test_steps_run_back_to_back_from_the_first_sample_with_hv_on(two_steps):
    schedule, sent, _ = two_steps
    r1, r2 = schedule.results
    assert schedule.done and schedule.current is None
    t0 = sent[0][0]                                     # the first command: the first HV-on sample
    assert (r1.t_start, r1.t_end) == (t0, pytest.approx(t0 + 30.0))
    assert (r2.t_start, r2.t_end) == (r1.t_end, pytest.approx(t0 + 60.0))
    # each command carries its step's angles; nothing is sent once the schedule is over
    assert all(c.phi_a == D(3.0) and c.phi_d == D(22.0) for t, c in sent if t < r1.t_end)
    assert all(c.phi_a == D(9.0) for t, c in sent if t >= r1.t_end)
    assert max(t for t, _ in sent) < r2.t_end
    assert r1.commands + r2.commands == len(sent)
    assert [c.sequence for _, c in sent] == list(range(1, len(sent) + 1))


def test_first_step_matches_the_firmware_run_sequential_schedule(two_steps):
    # The host's rule (the pad after the one that switched on, decided at switch-on) is the
    # firmware's 'after_active' schedule, so the first step's steady speed is the embedded
    # trial's from the same start (1 rad/s), up to the encoder's resolution over 10 s.
    schedule, _, _ = two_steps
    firmware = run_trial(TrialSpec(D(3.0), D(22.0), duration=30.0))
    assert schedule.results[0].steady_speed == pytest.approx(firmware.steady_speed,
                                                             abs=2 * ENCODER_COUNT / 10.0)


def test_steady_speed_is_the_true_mean_speed_over_the_window(two_steps):
    schedule, _, true_angle = two_steps
    for r in schedule.results:
        assert r.window == pytest.approx(10.0, abs=2 / 300)
        t1 = math.ceil(r.t_end * 300 - 1e-6) / 300      # the sample that closed the step
        t0 = t1 - r.window
        true = (true_angle[round(t1, 6)] - true_angle[round(t0, 6)]) / (t1 - t0)
        # the encoder quantises each end to one count
        assert r.steady_speed == pytest.approx(true, abs=2 * ENCODER_COUNT / r.window)
    assert schedule.results[0].steady_speed > schedule.results[1].steady_speed > 1.0


def test_priming_commands_use_the_priming_angle_then_the_step_angle():
    step = TrialSpec(D(9.0), D(22.0), duration=4.0, priming=6, priming_phi_a=D(3.0))
    schedule = TrialSchedule([step])
    sent, _ = drive(schedule, seconds_after=0.0)
    angles = [c.phi_a for _, c in sent]
    assert angles[:6] == [D(3.0)] * 6 and set(angles[6:]) == {D(9.0)} and len(angles) > 8
    assert schedule.results[0].window == pytest.approx(2.0, abs=2 / 300)   # half a short step


def test_nothing_is_sent_before_hv_is_on():
    from hasel_wheel_common.samples import TelemetrySample
    schedule = TrialSchedule([TrialSpec(D(3.0), D(22.0), duration=1.0)])
    off = TelemetrySample(0.5, 500000, 1, 0, 0.0, 0, 0, 0, 0, 0.0, 0.0, 0)
    assert schedule.step(off) is None and schedule.index == -1
    assert schedule.step(off._replace(t=0.6, hv_monitor=9000.0)).sequence == 1
    assert schedule.t_start == 0.6


def test_bad_schedules_are_refused_with_the_reason():
    with pytest.raises(ValueError, match="at least one"):
        TrialSchedule([])
    with pytest.raises(ValueError, match=r"steady_window = 0.0 s: expected a positive time"):
        TrialSchedule([TrialSpec(D(3.0), D(22.0))], steady_window=0.0)
