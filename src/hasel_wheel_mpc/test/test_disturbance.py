"""Disturbance estimator (57)-(58): converges on a constant offset at the rate K implies."""
import pytest

from hasel_wheel_mpc.disturbance import IntegralEstimator


@pytest.mark.parametrize("gain", [0.05, 0.2, 0.5, 1.0, 1.5])
def test_constant_offset_closes_geometrically(gain):
    est = IntegralEstimator(gain=gain, mode="paper")
    e = 0.12                       # the wheel runs 0.12 rad/s faster than modelled
    model = 2.0
    for k in range(1, 40):
        d = est.step(model + e, model, reference=2.0)
        assert d == pytest.approx(e * (1 - (1 - gain) ** k), abs=1e-12)


def test_gated_outside_the_band_near_the_reference():
    est = IntegralEstimator(gain=0.5, gate=0.64, mode="paper")
    assert est.step(1.1, 1.0, reference=2.0) == 0.0          # 1.0 rad/s away: off
    assert est.step(1.5, 1.4, reference=2.0) == pytest.approx(0.05)   # 0.6 rad/s: on
    assert est.updates == 1


@pytest.mark.parametrize("gain, match", [(0.0, "0 < K < 2"), (2.0, "0 < K < 2"),
                                         (float("nan"), "0 < K < 2")])
def test_unstable_gains_are_refused(gain, match):
    with pytest.raises(ValueError, match=match):
        IntegralEstimator(gain=gain)


@pytest.mark.parametrize("gain", [0.05, 0.1, 0.5, 1.5])
def test_tracking_mode_closes_a_constant_offset_at_the_same_rate(gain):
    # an ideal MPC makes model + d = reference; the wheel then runs e faster than the model
    est = IntegralEstimator(gain=gain, mode="tracking")
    e, ref = -0.07, 1.5
    for k in range(1, 40):
        measured = (ref - est.d) + e
        d = est.step(measured, ref - est.d, reference=ref)
        assert d == pytest.approx(e * (1 - (1 - gain) ** k), abs=1e-12)


def test_tracking_mode_is_gated_on_the_measured_speed():
    est = IntegralEstimator(gain=0.5, gate=0.64, mode="tracking")
    assert est.step(1.0, 2.0, reference=2.0) == 0.0           # 1 rad/s short: transient
    assert est.step(1.8, 2.0, reference=2.0) == pytest.approx(-0.1)


def test_unknown_mode_is_refused():
    with pytest.raises(ValueError, match="'paper' or 'tracking'"):
        IntegralEstimator(mode="pid")
