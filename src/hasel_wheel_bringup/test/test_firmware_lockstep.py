"""The C++ firmware core and the Python device core, tick for tick over 60 s of a realistic
wheel under the MPC, with every fault the device guards against and START frames (protocol
v1.1): the same frames, byte for byte, and the same state on all 18,000 ticks."""
import pytest

from hasel_wheel_common import protocol as P
from hasel_wheel_bringup.lockstep import run_lockstep


@pytest.mark.parametrize("seed", [1, 7])
def test_sixty_seconds_with_faults_byte_for_byte(firmware_build, seed):
    r = run_lockstep(firmware_build, seconds=60.0, seed=seed)
    assert r.first_mismatch == ""
    assert r.ticks == 18000 and r.frames > 18000          # every telemetry, plus the answers
    # every fault the schedule injects was seen by the device and the host
    assert r.faults_seen == (P.F_WATCHDOG | P.F_HV_MONITOR | P.F_OVERCURRENT | P.F_MAX_ON
                             | P.F_ENCODER | P.F_REJECTED | P.F_ESTOP)
    assert r.rejects == {P.R_N_A: 1, P.R_ORDER: 1, P.R_HV_DISABLED: 1, P.R_ESTOP: 2,
                         P.R_CONFIG: 2, P.R_NOT_IN_CONTACT: 1, P.R_ACTUATOR_ON: 1}
    assert r.starts_acked == 1                            # the START for the pad in contact
    assert r.host_frames_dropped == 6                     # five flipped bits, one cut frame
    # the MPC drove the wheel through the faults of the first 50 s: a switch-on per command,
    # the reference held at every whole second from 2 s to 50 s but the first after a fault
    assert r.switch_ons > 150 and r.commands_acked >= r.switch_ons
    held = [v for sec, v in enumerate(r.speeds[:50], start=1)
            if sec > 2 and sec % 10 not in (6, 7)]
    assert all(v == pytest.approx(r.reference, rel=0.15) for v in held)
