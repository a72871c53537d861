"""The driver opens its link once its telemetry has the listeners it expects, or on timeout."""
import pytest

from hasel_wheel_driver.link_start import link_may_start


@pytest.mark.parametrize("matched,wanted,waited,starts", [
    (0, 0, 0.0, True),       # nobody to wait for: at once
    (2, 3, 0.5, False),      # the recorder has not subscribed yet
    (3, 3, 0.5, True),
    (4, 3, 0.1, True),       # an extra `ros2 topic echo` changes nothing
    (2, 3, 5.0, True),       # timeout reached: start without it
])
def test_the_link_starts_when_heard_or_on_timeout(matched, wanted, waited, starts):
    assert link_may_start(matched, wanted, waited, timeout=5.0) is starts
