"""The reference profile by the device clock: parsed back from its text, each reference due
at its start from the first sample, refused with the entry named."""
import pytest

from hasel_wheel_bringup.reference_profile import (ProfilePlayer, check_profile, parse_profile,
                                                   profile_text)
from hasel_wheel_mpc.closed_loop import FIG11_DURATION, FIG11_PROFILE


def test_the_demo_profile_reads_back_from_its_text():
    assert parse_profile(profile_text(FIG11_PROFILE)) == FIG11_PROFILE


def test_each_reference_is_due_once_at_its_start_from_the_first_sample():
    player = ProfilePlayer(((0.0, 1.0), (0.051, 1.5), (0.101, 2.0)), duration=0.2)
    t0 = 1234.5                                   # device clock at the first sample [s]
    due = {}
    for k in range(61):                           # 300 Hz samples over 0.2 s
        ref = player.step(t0 + k / 300.0)
        if ref is not None:
            due[k] = ref
    # the first sample at or after each start: k = ceil(start x 300), 16 and 31
    assert due == {0: 1.0, 16: 1.5, 31: 2.0}
    assert player.done


def test_a_late_first_sample_gets_every_reference_due_by_then_at_once():
    player = ProfilePlayer(FIG11_PROFILE, FIG11_DURATION)
    player.step(0.0)
    assert player.step(85.0) == 2.0               # 1.5 (40 s) and 2.0 (80 s) both passed
    assert player.step(85.1) is None


@pytest.mark.parametrize("text, match", [("0:1.0, 40", "'40'"), ("0:1.0, x:2", "'x:2'"),
                                         ("0:1.0, 40:nan", "'40:nan'")])
def test_a_bad_item_is_named(text, match):
    with pytest.raises(ValueError, match=match):
        parse_profile(text)


@pytest.mark.parametrize("profile, match", [(((5.0, 1.0),), "starting at 0"),
                                            (((0.0, 1.0), (0.0, 2.0)), "0:2"),
                                            (((0.0, -1.0),), "0:-1")])
def test_a_bad_profile_is_refused(profile, match):
    with pytest.raises(ValueError, match=match):
        check_profile(profile)


def test_a_duration_before_the_last_start_is_refused():
    with pytest.raises(ValueError, match="duration = 200"):
        ProfilePlayer(FIG11_PROFILE, 200.0)
