"""The benchmarks' verdicts on data whose truth is known (ident.verdict)."""
import pytest

from hasel_wheel_ident.verdict import below_floor, verdict


def test_the_floor_is_the_bar_applied_to_the_true_model():
    # the bar is a 10 % cut: the true model must be below 0.9 x the nominal error
    assert below_floor(0.100, 0.0901)               # 9.9 % below: no fit could pass
    assert not below_floor(0.100, 0.0899)           # 10.1 % below: a fit could
    assert below_floor(0.100, 0.079, min_gain=0.25)
    assert not below_floor(0.100, 0.074, min_gain=0.25)


@pytest.mark.parametrize("chosen, truth, true_error, expected", [
    ((), None, None, "right"),
    (("viscous_drag",), "viscous_drag", 0.05, "right"),
    (("viscous_drag",), None, None, "wrong"),
    (("com_offset",), "viscous_drag", 0.05, "wrong"),
    (("viscous_drag", "com_offset"), "viscous_drag", 0.05, "wrong"),
    ((), "viscous_drag", 0.05, "missed"),               # the true model: 2x below
    ((), "viscous_drag", 0.095, "missed below the floor"),
    ((), "viscous_drag", None, "missed"),               # the floor not known
])
def test_verdicts(chosen, truth, true_error, expected):
    assert verdict(chosen, truth, 0.100, true_error) == expected


def test_the_choice_may_come_as_any_sequence():
    assert verdict(["viscous_drag"], "viscous_drag") == "right"
    assert verdict([], None) == "right"


def test_bad_arguments_are_refused_with_what_is_expected():
    with pytest.raises(ValueError, match=r"must be positive \[rad/s\], got before=0.1, "
                                         r"true_error=0.0"):
        below_floor(0.1, 0.0)
    with pytest.raises(ValueError, match=r"min_gain must be a fraction in \[0, 1\) \(0.10 is "
                                         r"a 10 % cut\), got 10"):
        below_floor(0.1, 0.05, min_gain=10)
    with pytest.raises(ValueError, match="true_error needs before"):
        verdict((), "viscous_drag", true_error=0.05)
