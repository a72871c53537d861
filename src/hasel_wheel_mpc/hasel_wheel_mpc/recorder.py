"""Record the embedded runner's traffic to a bag, under the same topics and types as ROS.

Each wheel or trial gets its own namespace (``/trial_01deg/telemetry`` ...), exactly as a
namespaced launch would publish them, so one bag holds several runs side by side.
"""
from __future__ import annotations

import hashlib
import subprocess
from pathlib import Path
from typing import Iterable, Mapping

import yaml

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_bag.writer import BagWriter
from hasel_wheel_common.samples import Command, TelemetrySample
from hasel_wheel_sim.wheel import HybridState


def git_revision(cwd: str | Path | None = None) -> str:
    """The current git commit (with '-dirty' when there are local changes), or 'unknown'."""
    try:
        rev = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True,
                             text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=cwd,
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return rev + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def package_versions() -> str:
    """'name version, ...' of this project's installed Python packages (what a bag from an
    installed workspace can say when the git revision is unknown)."""
    from importlib import metadata
    out = []
    for name in ("hasel_wheel_common", "hasel_wheel_bag", "hasel_wheel_driver", "hasel_wheel_sim",
                 "hasel_wheel_mpc", "hasel_wheel_ident", "hasel_wheel_bringup"):
        try:
            out.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            out.append(f"{name} (not installed)")
    return ", ".join(out)


def launch_custom_data(files: Iterable[str], extra: Mapping[str, str] | None = None
                       ) -> dict[str, str]:
    """custom_data for ``ros2 bag record --custom-data KEY=VALUE ...`` from a launch file: the
    git revision (of the working directory; 'unknown' outside a checkout), the installed
    package versions, ``extra``, and every file in ``files`` under
    ``file:<name>``.  Jazzy's recorder cuts each pair at every '=' (keeping the first two
    pieces), so a file goes in as its text when that has no '='; else as its YAML data
    re-written without comments (the same parameters) when that has none; else as its path
    and sha256.  An '=' in the keys or values of ``extra`` is refused
    (``test_recording.py::test_files_survive_jazzy_s_key_value_split``,
    ``test_an_equals_sign_in_extra_data_is_refused``)."""
    out = {"git_revision": git_revision(), "packages": package_versions()}
    for key, value in (extra or {}).items():
        if "=" in key or "=" in value:
            raise ValueError(f"custom data {key!r}: keys and values must not contain '=' "
                             f"(ros2 bag record splits KEY=VALUE at every '=')")
        out[key] = value
    for f in files:
        p = Path(f)
        text = p.read_text(encoding="utf-8")
        if "=" in text:
            try:
                text = "# comments dropped\n" + yaml.safe_dump(yaml.safe_load(text),
                                                               sort_keys=False)
            except yaml.YAMLError:
                pass
        out[f"file:{p.name}"] = (text if "=" not in text else
                                 f"{p.resolve()} sha256 {hashlib.sha256(p.read_bytes()).hexdigest()}")
    return out


class Recorder:
    """A bag plus the per-namespace topic bookkeeping of the runner."""


    def __init__(self, path: str | Path, custom_data: Mapping[str, str] | None = None) -> None:
        self.bag = BagWriter(path, custom_data=custom_data)
        self._namespaces: set[tuple[str, str]] = set()

    def _ensure(self, ns: str, *tps) -> None:
        """Declare the topics (per namespace, on first use: no empty topics in the bag)."""
        for tp in tps:
            if (ns, tp.name) not in self._namespaces:
                self.bag.add_topic(topics.qualified(tp, ns), tp.type, tp.qos)
                self._namespaces.add((ns, tp.name))

    @staticmethod
    def _ns_time(t: float) -> int:
        return int(round(t * 1e9))

    def telemetry(self, ns: str, s: TelemetrySample) -> None:
        """Record one device sample on ``telemetry`` and ``joint_states``."""
        self._ensure(ns, topics.TELEMETRY, topics.JOINT_STATES)
        tn = self._ns_time(s.t)
        self.bag.write(topics.qualified(topics.TELEMETRY, ns), samples.telemetry_msg(s), tn)
        self.bag.write(topics.qualified(topics.JOINT_STATES, ns), samples.joint_state_msg(s), tn)

    def command(self, ns: str, c: Command, t: float) -> None:
        """Record an actuation command (sent, or latched by the firmware's own schedule)."""
        self._ensure(ns, topics.COMMAND)
        self.bag.write(topics.qualified(topics.COMMAND, ns), samples.command_msg(c, t),
                       self._ns_time(t))

    def true_state(self, ns: str, t: float, x: HybridState) -> None:
        """Record the simulator's true hybrid state (``sim/true_state``)."""
        self._ensure(ns, topics.TRUE_STATE)
        self.bag.write(topics.qualified(topics.TRUE_STATE, ns),
                       samples.state_msg(t, x.xi1, x.xi2, x.q, x.act_counter, x.deact_counter,
                                         x.eta), self._ns_time(t))

    def estimate(self, ns: str, e, t: float | None = None) -> None:
        """Record an observer estimate (observer.Estimate) stamped ``t`` [s]: the telemetry
        sample's stamp, as observer_node stamps it (default the estimate's own time)."""
        self._ensure(ns, topics.STATE_ESTIMATE)
        t = e.t if t is None else t
        self.bag.write(topics.qualified(topics.STATE_ESTIMATE, ns),
                       samples.state_msg(t, e.xi1, e.xi2, e.q, e.act_counter, e.deact_counter,
                                         e.eta_unwrapped, e.xi2_std, e.quality,
                                         e.accel_disturbance, e.accel_coefficients),
                       self._ns_time(t))

    def decision(self, ns: str, t: float, dec, reference: float, d: float = 0.0) -> None:
        """Record an MPC decision (mpc.Decision) made with the estimator's ``d`` [rad/s] on
        ``mpc_status``, and its ``command``."""
        self._ensure(ns, topics.MPC_STATUS, topics.COMMAND)
        tn = self._ns_time(t)
        self.bag.write(topics.qualified(topics.MPC_STATUS, ns),
                       samples.mpc_status_msg(t, dec.command, reference, dec.predicted_speed,
                                              dec.cost, dec.compute_time, dec.deadline_slack,
                                              dec.candidates, dec.deadline_missed, dec.braking,
                                              d),
                       tn)
        self.bag.write(topics.qualified(topics.COMMAND, ns), samples.command_msg(dec.command, t), tn)

    def reference(self, ns: str, t: float, value: float) -> None:
        """Record a reference speed [rad/s] (std_msgs/Float64)."""
        self._ensure(ns, topics.REFERENCE)
        self.bag.write(topics.qualified(topics.REFERENCE, ns), {"data": value}, self._ns_time(t))

    def configuration(self, data: Mapping[str, str]) -> None:
        """Add ``{key: text}`` to the bag's recorded configuration (custom_data)."""
        self.bag.add_custom_data(data)

    def close(self) -> None:
        self.bag.close()
