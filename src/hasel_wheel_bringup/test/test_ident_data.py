"""Identification inputs: CSV import with clear errors, bags, activations and coast-downs;
friction from coast-downs against the closed form."""
import math

import numpy as np
import pytest

from hasel_wheel_ident import data as D
from hasel_wheel_ident import fit as F
from hasel_wheel_ident import synthetic as S
from hasel_wheel_mpc.closed_loop import run_closed_loop
from hasel_wheel_mpc.core import START_ANGLES
from hasel_wheel_mpc.recorder import Recorder
from hasel_wheel_bringup.trials import TrialSpec, run_trial
from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import PlantConfig

ENCODER = S.ENCODER


@pytest.fixture(scope="module")
def trial():
    """A short open-loop trial with a coast-down, through the 10-bit encoder."""
    cfg = PlantConfig(seed=2, switching="tick", effects=effects_from_mapping(ENCODER))
    return S.record(S.SyntheticTrial(math.radians(3.0), drive=12.0, coast=8.0), config=cfg)


def test_activations_follow_the_pads_and_coast_is_found(trial):
    acts = trial.activations
    assert len(acts) > 50
    # sequential schedule: every activation is on the next pad, inside its angle window
    assert all(b.eta == a.eta + 1 for a, b in zip(acts[6:], acts[7:]))
    for a in acts[10:]:
        xc = trial.angle[a.start] - a.eta * math.pi / 8
        assert a.phi_a - 0.03 < xc < a.phi_d + 0.03
    (c0, c1), = trial.coasts
    assert trial.t[c0] == pytest.approx(12.0, abs=0.01) and trial.t[c1] - trial.t[c0] > 3.0


def test_activations_survive_lost_samples_between_two_pads(trial):
    # drop every q = 0 sample between pads k and k + 1 (a USB frame burst lost): the two
    # activations must stay two, on their own pads, starting at the same times
    acts = trial.activations
    k = 20
    keep = np.ones(trial.t.shape[0], bool)
    keep[acts[k].stop:acts[k + 1].start] = False
    assert 0 < np.sum(~keep) < 20
    cut = D.Trial("cut", *(getattr(trial, c)[keep] for c in
                           ("t", "angle", "q", "eta", "n_a", "phi_a", "phi_d")))
    assert [a.eta for a in cut.activations] == [a.eta for a in acts]
    assert [cut.t[a.start] for a in cut.activations] == [trial.t[a.start] for a in acts]
    assert cut.t[cut.activations[k].stop - 1] == trial.t[acts[k].stop - 1]


def _columns(trial, **changed):
    cols = {c: getattr(trial, c).copy() for c in ("t", "angle", "q", "eta", "n_a", "phi_a",
                                                   "phi_d")}
    cols.update(changed)
    return cols


def test_a_pad_that_switches_on_after_the_schedule_is_cleared_keeps_its_command(trial):
    # the command link's delay: the host has cleared its schedule (n_a = -1, no angles) when
    # the pad it last commanded switches on; the activation takes that last command's angles
    acts = trial.activations
    a = acts[30]
    cols = _columns(trial)
    cols["phi_a"][a.start - 1] = 0.07                 # the last command before the clear
    cols["n_a"][a.start:] = -1
    cols["phi_a"][a.start:] = np.nan
    cols["phi_d"][a.start:] = np.nan
    cut = D.Trial("latched", **cols)
    assert [(c.start, c.stop, c.eta) for c in cut.activations] == [
        (c.start, c.stop, c.eta) for c in acts]
    assert {(c.phi_a, c.phi_d) for c in cut.activations[30:]} == {(0.07, trial.phi_d[0])}
    # with no row before that gives the angles, the error names the row
    cols["phi_a"][:] = np.nan
    with pytest.raises(D.TrialError, match=rf"row {acts[0].start + 2}: q = 1 but phi_a / "
                                           rf"phi_d are empty here and in every row before"):
        D.Trial("none", **cols)


def test_a_glitch_inside_an_activation_neither_splits_it_nor_moves_its_pad_a_turn(trial):
    # a reading of -3.1 rad (just under pi, so unwrapping keeps it) one sample after a
    # switch-on: read off the raw angle it puts that sample's pad a whole turn (16) back
    acts = trial.activations
    cols = _columns(trial)
    k = np.array([a.start + 1 for a in acts[10:40:5]])
    cols["angle"][k] -= 3.1
    raw = D.unwrap_eta(cols["angle"], cols["eta"], cols["phi_a"], cols["phi_d"], cols["q"])
    assert np.any(raw[k] == trial.eta_unwrapped[k] - 16)      # the hazard is real
    glitched = D.Trial("glitched", **cols)
    np.testing.assert_array_equal(glitched.eta_unwrapped, trial.eta_unwrapped)
    assert [(a.start, a.stop, a.eta) for a in glitched.activations] == [
        (a.start, a.stop, a.eta) for a in acts]


@pytest.mark.parametrize("form", ["unwrapped", "wrapped", "device slip"])
def test_a_glitch_half_a_turn_off_does_not_shift_the_rest_of_the_trial_a_turn(trial, form):
    # a reading just under half a turn below the one before: the step down is shorter than
    # pi, the step back up (the same plus the wheel's motion) longer, so np.unwrap takes it
    # as a wrap and everything after is a turn low.  A device that unwraps its counts itself
    # can make the same slip: then the recording is a turn low from the sample after the
    # glitch on.
    truth = trial.angle
    k = next(i for i in range(3000, 4000) if truth[i + 1] - truth[i - 1] > 0.005)
    count = 2 * math.pi / 1024
    cols = _columns(trial)
    cols["angle"][k] = truth[k - 1] - (math.pi - 0.5 * count)
    if form == "wrapped":
        cols["angle"] = np.mod(cols["angle"], 2 * math.pi)
    elif form == "device slip":
        cols["angle"][k + 1:] -= 2 * math.pi
    slipped = np.unwrap(cols["angle"])
    assert abs(slipped[-1] - slipped[0] - (truth[-1] - truth[0])) > 6.0    # the hazard is real
    glitched = D.Trial("glitched", **cols)
    others = np.arange(truth.shape[0]) != k
    turns = (glitched.angle[0] - truth[0]) / (2 * math.pi)   # wrapping starts on another turn
    assert turns == pytest.approx(round(turns), abs=1e-9)
    offset = 2 * math.pi * round(turns)
    np.testing.assert_allclose(glitched.angle[others] - offset, truth[others], atol=1e-9)
    assert abs(glitched.angle[k] - offset - truth[k]) < math.pi      # the glitch on its own turn
    np.testing.assert_array_equal(glitched.eta_unwrapped - 16 * round(turns),
                                  trial.eta_unwrapped)
    assert [(a.start, a.stop, a.eta - 16 * round(turns)) for a in glitched.activations] == [
        (a.start, a.stop, a.eta) for a in trial.activations]


def test_the_measured_speed_bridges_isolated_encoder_glitches(trial):
    # a glitched count (a random reading for one sample) must not reach the compared speed
    from hasel_wheel_ident.metrics import measured_speed, speed_from_angle
    cols = _columns(trial)
    k = np.arange(500, trial.t.shape[0] - 500, 997)
    cols["angle"][k] += np.where(k % 2, 1.0, -2.0)          # jumps of 1-2 rad, far from 1 count
    glitched = D.Trial("glitched", **cols)
    clean = measured_speed(trial)
    assert np.max(np.abs(speed_from_angle(glitched.t, glitched.angle) - clean)) > 1.0
    # a bridged sample (the mean of its neighbours' readings) differs from its true reading
    # by the floors' difference (< 1 count) and the noise (1 mrad x sqrt(1.5), 4 sigma: 0.8
    # count): under 2 counts, which the filter passes on with its largest derivative weight
    impulse = np.zeros(trial.t.shape[0])
    impulse[3000] = 1.0
    weight = np.max(np.abs(speed_from_angle(trial.t, impulse)))      # [1/s]
    assert np.max(np.abs(measured_speed(glitched) - clean)) < 2 * 2 * math.pi / 1024 * weight


@pytest.mark.parametrize("where", [0, -1])
def test_a_glitch_at_either_end_is_rejected_as_one_inside_is(trial, where):
    # the first and the last reading have one neighbour each; a random count there must be
    # rejected as one inside is, or it puts a speed spike and a wrong start into the trial's
    # free run
    from hasel_wheel_ident.metrics import measured_speed
    assert D.clean_mask(trial.t, trial.angle).all()
    cols = _columns(trial)
    cols["angle"][where] += 1.5
    glitched = D.Trial("glitched", **cols)
    for modulo in (None, 2 * math.pi):
        ok = D.clean_mask(glitched.t, glitched.angle, modulo=modulo)
        # the end is rejected, and at most its neighbour with it (judged on the line through
        # the glitch)
        assert not ok[where] and ok.sum() >= ok.shape[0] - 2
    # the compared speed at that end stays within a tenth of a rad/s of the clean trial's
    # (the spike of a 1.5 rad jump over one sample would be hundreds of rad/s)
    assert np.max(np.abs(measured_speed(glitched) - measured_speed(trial))) < 0.1


def test_csv_round_trip_keeps_every_value(tmp_path, trial):
    p = tmp_path / "trial.csv"
    D.write_csv(trial, p)
    back = D.read_csv(p)
    np.testing.assert_array_equal(back.t, trial.t)
    np.testing.assert_array_equal(back.angle, trial.angle)
    np.testing.assert_array_equal(back.q, trial.q)
    np.testing.assert_array_equal(back.n_a, trial.n_a)
    np.testing.assert_array_equal(np.isnan(back.phi_a), np.isnan(trial.phi_a))
    assert [(a.start, a.eta) for a in back.activations] == [(a.start, a.eta) for a in trial.activations]


def test_csv_columns_in_any_order_and_wrapped_angles(tmp_path, trial):
    p = tmp_path / "shuffled.csv"
    D.write_csv(trial, p)
    lines = p.read_text().splitlines()
    rows = [ln.split(",") for ln in lines]
    order = [6, 2, 0, 5, 1, 4, 3]
    wrapped = []
    for i, r in enumerate(rows):
        if i:   # wrap the angle into [0, 2 pi) as an absolute encoder reports it
            r[1] = repr(float(r[1]) % (2 * math.pi))
        wrapped.append(",".join(r[j] for j in order))
    p.write_text("\n".join(wrapped) + "\n")
    back = D.read_csv(p)
    np.testing.assert_allclose(back.angle, trial.angle, atol=1e-9)
    assert len(back.activations) == len(trial.activations)


@pytest.mark.parametrize("edit, match", [
    (lambda h, r: (h.replace("phi_d", "phi_x"), r), r"row 1 \(header\): missing column\(s\) \['phi_d'\]"),
    (lambda h, r: (h, r[:3] + ["0.1,abc" + r[3][r[3].index(",", r[3].index(",") + 1):]] + r[4:]),
     r"row 5, column angle: 'abc' is not a number"),
    (lambda h, r: (h, r[:5] + [r[5].replace(",0,", ",7,", 1)] + r[6:]), r"row 7, column q: 7 is outside 0\.\.1"),
    # row 4 jumps ahead, so row 5 is the first whose time is not after the one before
    (lambda h, r: (h, r[:2] + [r[5]] + r[3:]), r"row 5, column t: .* is not after"),
])
def test_bad_csv_names_row_and_column(tmp_path, trial, edit, match):
    p = tmp_path / "bad.csv"
    D.write_csv(trial.slice(0, 100), p)
    header, *rows = p.read_text().splitlines()
    header, rows = edit(header, rows)
    p.write_text("\n".join([header] + rows) + "\n")
    with pytest.raises(D.TrialError, match=match):
        D.read_csv(p)


def test_degrees_instead_of_radians_is_named(tmp_path, trial):
    p = tmp_path / "deg.csv"
    tr = trial.slice(0, 100)
    tr.phi_a = np.where(np.isnan(tr.phi_a), np.nan, 3.0)
    D.write_csv(tr, p)
    with pytest.raises(D.TrialError, match=r"column phi_a: 3\.0 rad is outside .*degrees"):
        D.read_csv(p)


def test_bag_from_the_embedded_runner_gives_the_same_activations(tmp_path):
    rec = Recorder(tmp_path / "bag")
    run_trial(TrialSpec(math.radians(5.0), math.radians(22.0), duration=6.0, initial_speed=2.0),
              config=PlantConfig(switching="tick"), recorder=rec, namespace="wheel0")
    rec.close()
    trials = D.load_trials([tmp_path / "bag"])
    assert [t.name for t in trials] == ["bag_wheel0"]
    tr = trials[0]
    assert tr.t.shape[0] == 6 * 300 and len(tr.activations) > 20
    on = [a for a in tr.activations[2:]]
    assert all(a.phi_a == pytest.approx(math.radians(5.0)) for a in on)
    assert all(b.eta == a.eta + 1 for a, b in zip(on, on[1:]))


@pytest.mark.parametrize("config, warned", [
    ({"wheels": "3", "same_wheel": "false"}, True),
    ({"wheels": "3"}, True),                  # no same_wheel record: separate wheels
    ({"wheels": "3", "same_wheel": "true"}, False),
    ({"wheels": "1", "same_wheel": "false"}, False),
    ({}, False),                              # not the demo's bag
])
def test_a_bag_of_separate_wheels_is_told_apart_from_runs_of_one(tmp_path, config, warned):
    rec = Recorder(tmp_path / "bag", custom_data={"tool": "hasel_wheel demo", **config})
    rec.close()
    note = D.separate_wheels(tmp_path / "bag")
    if warned:
        assert "records 3 separate wheels" in note and "--same-wheel" in note
    else:
        assert note is None


def test_a_closed_loop_bag_gives_the_start_command_to_the_pads_it_drives(tmp_path):
    # the runner starts the wheel with its own command (sequence 0) before the MPC decides;
    # with viscous drag (seed 3) the first switch-on falls on the sample where the MPC's first
    # command goes out, and that pad takes its angles from the recorded start command
    rec = Recorder(tmp_path / "bag")
    drag = {"viscous_drag": {"enabled": True,
                             "coefficient": {"value": 1e-3, "unit": "N*m*s/rad"}}}
    run_closed_loop(((0.0, 1.0),), 2.0, PlantConfig(seed=3, switching="tick",
                                                    effects=effects_from_mapping(drag)),
                    recorder=rec, clock=lambda: 0.0)
    rec.close()
    tr = D.load_trials([tmp_path / "bag"])[0]
    first = tr.activations[0]
    assert (first.phi_a, first.phi_d) == pytest.approx(START_ANGLES)
    assert tr.n_a[first.start] == 1                      # the start command's pad
    assert len(tr.activations) > 3 and any(a.phi_a != first.phi_a for a in tr.activations)


def test_coastdown_friction_matches_the_closed_form():
    # Coulomb friction alone: constant deceleration (r + L)/L tau_f / (J/L); the fit is exact on
    # exact data and within 2 % through the 10-bit encoder with noise
    base = WheelParams()
    for effects, tol in (({}, 1e-6), (ENCODER, 0.02)):
        cfg = PlantConfig(seed=4, switching="tick", effects=effects_from_mapping(effects))
        trials = [S.record(S.SyntheticTrial(math.radians(a), drive=8.0, coast=8.0), config=cfg)
                  for a in (2.0, 6.0)]
        est = F.coastdown_friction(trials, base)
        assert est.segments == 2
        assert est.tau_f == pytest.approx(base.tau_f, rel=tol)
        assert est.ci95[0] <= base.tau_f * (1 + tol) and est.ci95[1] >= base.tau_f * (1 - tol)


def test_hv_time_counts_each_actuators_own_on_time():
    # 0.1 s steps, a pattern of 10 samples three times: pad 0 on for 3 samples, pad 1 for 2,
    # pad 0 again for 2; per pattern pad 0 gains 0.5 s and pad 1 0.2 s of HV time
    t = np.arange(30) * 0.1
    q = np.tile([1, 1, 1, 0, 1, 1, 0, 1, 1, 0], 3)
    pad = np.tile([0, 0, 0, 0, 1, 1, 1, 0, 0, 0], 3)
    tr = D.Trial("x", t, np.arange(30) * 0.01, q, pad, np.zeros(30, dtype=int),
                 np.zeros(30), np.full(30, 0.3))
    # the on-time before each sample of the actuator of interest, its own clock only
    first = np.array([0.0, 0.1, 0.2, 0.3, 0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    gained = np.where(pad[:10] == 0, 0.5, 0.2)
    expected = np.concatenate([first + k * gained for k in range(3)])
    assert D.hv_time(tr) == pytest.approx(expected, abs=1e-12)


def test_a_glitch_in_the_tail_at_rest_does_not_keep_the_tail():
    # the wheel stops during the coast; the samples at rest after it carry nothing and are
    # trimmed.  One random count among them (a faulty encoder) must not end the rest there:
    # the tail kept would leave a constant residual that correlates the whole fit's
    cfg = PlantConfig(seed=2, switching="tick", effects=effects_from_mapping(ENCODER))
    trial = S.record(S.SyntheticTrial(math.radians(3.0), drive=6.0, coast=14.0), config=cfg)
    trimmed = F.at_rest_trimmed(trial)
    end = trimmed.t.shape[0]
    n = trial.t.shape[0]
    assert trial.t[-1] - trimmed.t[-1] > 1.0                # a second or more at rest
    k = end + (n - end) // 2                                 # halfway through the rest
    # a count far off, one just over the band of 0.015 rad (under the fit's glitch
    # tolerance, 0.05), and one in either of the last two samples
    for row, jump in ((k, 0.5), (k, 0.03), (k, -0.02), (n - 1, 0.5), (n - 2, -0.5),
                      (n - 1, 0.02)):
        cols = _columns(trial)
        cols["angle"][row] += jump
        assert F.at_rest_trimmed(D.Trial("glitched", **cols)).t.shape[0] == end, (row, jump)
    # the wheel moved on during the tail and rests again from row k: the rest starts there
    # (a row later: the step's two edges are each off the line through their neighbours)
    cols = _columns(trial)
    cols["angle"][k:] += 0.5
    assert F.at_rest_trimmed(D.Trial("moved", **cols)).t.shape[0] == k + 2


def test_a_coast_down_ends_where_the_wheel_rests_though_its_count_flickers():
    # a wheel stopped between two encoder counts reads one or the other: the count changes
    # long after the wheel stopped.  The coast-down must end where the rest begins, as the
    # fit's trimming does, or the parabola takes in seconds of rest and reads a fraction of
    # the deceleration
    cfg = PlantConfig(seed=2, switching="tick", effects=effects_from_mapping(ENCODER))
    trial = S.record(S.SyntheticTrial(math.radians(3.0), drive=6.0, coast=14.0), config=cfg)
    (a, b), = trial.coasts
    end = F.at_rest_trimmed(trial).t.shape[0]
    assert b == end and trial.t[-1] - trial.t[b] > 1.0      # a second or more at rest
    count = 2 * math.pi / 1024
    cols = _columns(trial)
    rest = np.arange(b, trial.t.shape[0])
    cols["angle"][rest[::7]] += count                       # flickers to the next count
    cols["angle"][rest[-5:-3]] += count                     # and near the end
    flicker = D.Trial("flicker", **cols)
    (c0, c1), = flicker.coasts
    # the flicker widens what the band holds: the rest is judged to start a little later
    assert c0 == a and 0.0 <= flicker.t[c1] - trial.t[b] < 0.1
    base = WheelParams()
    est = F.coastdown_friction([flicker], base)
    assert est.tau_f == pytest.approx(base.tau_f, rel=0.02)
    # the premise, on these data (no code of ours in it): ending at the last count change
    # reads far too little friction
    last = int(np.flatnonzero(np.diff(cols["angle"][a:]))[-1]) + a + 1
    t, y = flicker.t[a:last] - flicker.t[a], flicker.angle[a:last]
    curv = np.polyfit(t, y, 2)[0]
    alpha = -2.0 * curv
    assert alpha * base.inertia * base.L / (base.r + base.L) < 0.8 * base.tau_f


def test_rest_start_finds_the_rest_that_ends_a_record():
    # moving, then resting within the band (a flicker of one count), then nothing at rest
    t = np.arange(100) * 0.01
    y = np.concatenate([np.linspace(0.0, 1.0, 60), np.full(40, 1.0)])
    y[70::5] += 2 * np.pi / 1024
    assert D.rest_start(t, y) == 59                 # the wheel reaches 1.0 at sample 59
    assert D.rest_start(t, np.full(100, 0.3)) == 0  # never moved
    assert D.rest_start(t, np.linspace(0.0, 5.0, 100)) is None    # 0.05 rad a sample to the end
