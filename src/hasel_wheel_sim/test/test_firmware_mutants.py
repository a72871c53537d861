"""Each safety rule of the C++ firmware core has a test that fails without it: the core is
copied, one rule is taken out of the copy, the copy is built, and the rule's tests from
``test_device_rules.py`` are run against it; they must fail."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from hasel_wheel_sim.device_cpp import FIRMWARE_DIR, build_core

DEVICE = "core/src/hasel_core/device.cpp"
ENCODER = "core/src/hasel_core/encoder.cpp"
RULES = Path(__file__).with_name("test_device_rules.py")

#: rule -> (file, text of the rule, what replaces it, the tests that must then fail)
MUTANTS = {
    "HV off at power-up": (DEVICE, "  s_ = DeviceState{};\n",
                           "  s_ = DeviceState{};\n  s_.hv_enabled = true;\n", "power_up"),
    "a defined state after reset": (DEVICE, "  s_ = DeviceState{};\n", "", "reset_returns"),
    "watchdog": (DEVICE, "if (s_.hv_enabled && now_us - s_.last_host_us >=", "if (false && 1 >=",
                 "watchdog"),
    "maximum on-time": (DEVICE, "if (s_.q && now_us - s_.on_since_us >=", "if (false && 1 >=",
                        "maximum_on_time"),
    "over-current trip": (DEVICE, "if (!(sensors.current_monitor <= kCurrentLimitA))",
                          "if (false)", "over_current"),
    "HV monitor trip": (DEVICE, "} else if (now_us - s_.hv_on_since_us >= kHvSettleUs &&",
                        "} else if (false &&", "hv_monitor"),
    "never more than one pad": (DEVICE, "uint16_t(1u << mod(s_.eta_unwrapped, kPads))",
                                "uint16_t(3u << mod(s_.eta_unwrapped, kPads))", "at_most_one_pad"),
    "a command needs HV enabled": (DEVICE, "if (!reason && !s_.hv_enabled) reason = kReasonHvDisabled;",
                                   "", "rejected_command"),
    "emergency stop latches": (DEVICE, "      s_.estop = true;\n", "", "estop"),
    "HV enable refused under estop": (DEVICE, "} else if (s_.estop) {\n        reason = kReasonEstop;\n",
                                      "} else if (false) {\n", "estop"),
    "HV enable only with value 1": (DEVICE, "if (m.enable > 1) {", "if (false) {",
                                    "other_than_0_or_1"),
    "a glitch is not taken": (ENCODER, "if (d > limit || d < -limit) {",
                              "if (limit < 0) {",
                              "glitched_reading"),
    "HV off on request": (DEVICE, "} else if (m.enable == 0) {\n        hv_off();",
                          "} else if (m.enable == 0) {", "hv_off_switches"),
    "HV off forgets every command": (DEVICE, "  s_.hv_enabled = false;\n  pads_off();",
                                     "  s_.hv_enabled = false;\n  s_.q = false;", "hv_off_switches"),
    "only host frames are handled": (DEVICE, "&& is_host_type(m.type)) handle",
                                     "&& is_host_type(m.type | 0x10)) handle",
                                     "device_types"),
    "a rejected configuration changes nothing": (
        DEVICE, "      reason = check_config(m);\n",
        "      s_.watchdog_ms = m.watchdog_ms;\n      reason = check_config(m);\n",
        "rejected_configuration"),
    "a lost position switches HV off": (DEVICE, "if (reading.lost) hv_off();", "",
                                        "lose_the_position"),
    "a START needs HV enabled": (
        DEVICE, "if (!reason && !s_.hv_enabled) reason = kReasonHvDisabled;",
        "if (!reason && !s_.hv_enabled && m.type == kCommand) reason = kReasonHvDisabled;",
        "start_needs_hv"),
    "a START only while no actuator is on": (DEVICE, "if (s_.q) return kReasonActuatorOn;", "",
                                             "start_is_refused_while_an_actuator"),
    "a START only in the contact window": (
        DEVICE, "!start_sector(m.n_a, m.phi_a, m.phi_d, c, &n)",
        "!(start_sector(m.n_a, m.phi_a, m.phi_d, c, &n) || true)", "start_outside_the_window"),
    "a START only on a known position": (
        DEVICE, "bool known = enc_.started() && enc_.bad_run() < kLostAfter;",
        "bool known = true;", "start_is_refused_while_the_position_is_lost"),
}


@pytest.mark.parametrize("rule", sorted(MUTANTS))
def test_removing_a_safety_rule_makes_its_test_fail(firmware_build, tmp_path, rule):
    path, text, replacement, selector = MUTANTS[rule]
    src = tmp_path / "firmware"
    shutil.copytree(FIRMWARE_DIR, src, ignore=shutil.ignore_patterns("teensy", "*.md"))
    source = (src / path).read_text()
    assert source.count(text) == 1, f"{rule}: its text is no longer once in {path}; update MUTANTS"
    (src / path).write_text(source.replace(text, replacement))
    build = build_core(tmp_path / "build", src, build_type="Debug", targets=("hasel_device_host",))
    env = dict(os.environ, HASEL_DEVICE_CORE_BUILD=str(build))
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        "-p", "no:randomly", str(RULES), "-k", f"{selector} and cpp"],
                       env=env, capture_output=True, text=True, cwd=FIRMWARE_DIR.parent)
    assert r.returncode == 1, f"{rule}: its tests did not fail (exit {r.returncode}):\n{r.stdout[-2000:]}"
    assert " failed" in r.stdout.splitlines()[-1]
