"""Offline replay: a bag's telemetry through the observer, the estimator and the MPC again.

For every wheel (namespace) of the bag that has ``telemetry`` and ``reference_speed``,
:func:`replay_bag` builds the controller from the configuration recorded in the bag
(``<ns>/controller.yaml``, see :class:`~hasel_wheel_mpc.config.ControllerConfig`),
optionally changed by overrides, feeds it every recorded telemetry sample with the reference
in force at that sample, and compares what it computes with what the bag recorded:

* every ``state_estimate`` (paired with its telemetry sample by stamp), field by field;
* every ``mpc_status`` (paired in order), field by field, with its command.

The one thing a replay cannot re-compute is how long the MPC took on the recording machine;
the replay's MPC clock plays the recorded compute times back (:class:`PlaybackClock`), so the
deadline logic (slack, fallback on a miss) decides as it did
(``test_replay.py::test_playback_clock_replays_compute_times``,
``test_a_played_back_late_decision_takes_the_fallback``).  With the recorded configuration and
no overrides, everything matches exactly (bit for bit; ``test_unchanged_replay_is_identical``);
with changes, the report counts the differing fields, their largest difference and the first
time one differs (``test_a_changed_brake_threshold_differs_from_a_decision_on``).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_bag.export import flatten
from hasel_wheel_bag.layout import BagError
from hasel_wheel_bag.reader import bag_configuration, read_messages

from hasel_wheel_mpc.config import ControllerConfig, controller_from_ros_files
from hasel_wheel_mpc.controller import SpeedController

SUFFIX_TELEMETRY = "/" + topics.TELEMETRY.name
SUFFIX_REFERENCE = "/" + topics.REFERENCE.name
SUFFIX_ESTIMATE = "/" + topics.STATE_ESTIMATE.name
SUFFIX_STATUS = "/" + topics.MPC_STATUS.name
#: custom-data keys of the parameter files a ROS launch records (record.launch.py).
ROS_FILES = ("file:observer.yaml", "file:mpc.yaml")
#: Most estimates held while waiting for their twin (recomputed or recorded) [messages].
PAIRING_WINDOW = 3000


class PlaybackClock:
    """An MPC clock that replays recorded compute times [s].

    :meth:`hasel_wheel_mpc.mpc.Mpc.decide` reads its clock twice per decision (at the start
    and at the end); this clock answers 0 and then the recorded compute time of that
    decision.  Past the last recorded decision the compute time is 0.
    """

    def __init__(self, compute_times: Iterable[float]) -> None:
        self._times = list(compute_times)
        self._calls = 0

    def __call__(self) -> float:
        self._calls += 1
        if self._calls % 2:
            return 0.0
        k = self._calls // 2 - 1
        return self._times[k] if k < len(self._times) else 0.0


@dataclass
class FieldDiff:
    """How one field differed: ``count`` of the compared messages, the largest absolute
    difference (numbers; 1 for other types) and the bag time [s] of the first."""

    count: int = 0
    max_abs: float = 0.0
    first_t: float = math.inf


@dataclass
class ReplayReport:
    """One wheel's replay (times in seconds on the bag's clock)."""

    namespace: str
    configuration: str                  # where the controller's configuration came from
    overrides: dict[str, Any]
    samples: int = 0
    estimates_recorded: int = 0
    estimates_compared: int = 0
    decisions_recorded: int = 0
    decisions_recomputed: int = 0
    estimate_diffs: dict[str, FieldDiff] = field(default_factory=dict)
    decision_diffs: dict[str, FieldDiff] = field(default_factory=dict)

    @property
    def identical(self) -> bool:
        """Every sample gave an estimate that pairs with a recorded one, every recorded
        estimate and decision was re-computed, and all are equal."""
        return (not self.estimate_diffs and not self.decision_diffs
                and self.estimates_compared == self.estimates_recorded == self.samples
                and self.decisions_recomputed == self.decisions_recorded)

    @property
    def first_difference(self) -> float:
        """Bag time [s] of the first difference (inf when none)."""
        firsts = [d.first_t for d in (*self.estimate_diffs.values(),
                                      *self.decision_diffs.values())]
        return min(firsts, default=math.inf)

    def text(self) -> str:
        ov = ", ".join(f"{k}={v!r}" for k, v in self.overrides.items()) or "none"
        out = [f"wheel {self.namespace}: {self.samples} telemetry samples replayed; controller "
               f"from {self.configuration}; overrides: {ov}",
               f"  estimates: {self.estimates_compared} of {self.estimates_recorded} recorded "
               f"compared; decisions: {self.decisions_recomputed} re-computed, "
               f"{self.decisions_recorded} recorded"]
        if self.identical:
            out.append("  IDENTICAL: every estimate and decision equals the recorded one")
            return "\n".join(out)
        first = self.first_difference
        out.append("  DIFFERENT" + (f" from t = {first:.4f} s:" if math.isfinite(first) else
                                    ": the counts above differ (no field compared differs)"))
        for kind, diffs in (("estimate", self.estimate_diffs), ("decision", self.decision_diffs)):
            for name, d in sorted(diffs.items(), key=lambda kv: kv[1].first_t):
                out.append(f"    {kind}.{name}: {d.count} differ, largest |diff| "
                           f"{d.max_abs:.6g}, first at t = {d.first_t:.4f} s")
        return "\n".join(out)


def _flat(msg: Any) -> dict[str, Any]:
    """Fields of a message (decoded, or a dict) as {'a.b': value}, headers left out (the
    decision's time is compared as its log time; an estimate is paired by its stamp)."""
    return {k: v for k, v in flatten(msg).items() if "header" not in k.split(".")}


def _compare(recorded: Any, recomputed: Mapping[str, Any], t: float,
             diffs: dict[str, FieldDiff]) -> None:
    a, b = _flat(recorded), _flat(recomputed)
    # a field only one side has is a newer message definition than the bag's, not a
    # difference in what was computed (e.g. accel_c..accel_f, which older bags lack)
    for name in sorted(set(a) & set(b)):
        x, y = a.get(name), b.get(name)
        if isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
            continue
        if x == y:
            continue
        d = diffs.setdefault(name, FieldDiff())
        d.count += 1
        try:
            gap = abs(float(x) - float(y))
        except (TypeError, ValueError):
            gap = 1.0
        d.max_abs = max(d.max_abs, gap if math.isfinite(gap) else math.inf)
        d.first_t = min(d.first_t, t)


def _namespaces(path: str | os.PathLike, warn) -> dict[str, dict[str, list]]:
    """Pass 1: per namespace, the references (t_ns, value) and the recorded statuses."""
    found: dict[str, dict[str, list]] = {}

    def ns_of(topic: str, suffix: str) -> dict[str, list]:
        return found.setdefault(topic[: -len(suffix)], {"ref": [], "status": [], "tel": [0]})

    wanted = (SUFFIX_REFERENCE, SUFFIX_STATUS, SUFFIX_TELEMETRY)
    for topic, t_ns, m in read_messages(path, warn=warn, select=lambda n: n.endswith(wanted)):
        if topic.endswith(SUFFIX_REFERENCE):
            ns_of(topic, SUFFIX_REFERENCE)["ref"].append((t_ns, float(m.data)))
        elif topic.endswith(SUFFIX_STATUS):
            ns_of(topic, SUFFIX_STATUS)["status"].append((t_ns, m))
        else:
            ns_of(topic, SUFFIX_TELEMETRY)["tel"][0] += 1
    return found


def replay_bag(path: str | os.PathLike, overrides: Mapping[str, Any] | None = None,
               namespaces: Iterable[str] | None = None,
               config: ControllerConfig | None = None,
               warn: Callable[[str], None] | None = None,
               progress: bool = False) -> list[ReplayReport]:
    """Replay every wheel of the bag at ``path`` (or those in ``namespaces``) and compare.

    The controller is ``config`` when given, else the one recorded for the namespace
    (``<ns>/controller.yaml`` in the bag's configuration), else the one built from the ROS
    parameter files a launch recorded (:func:`controller_from_ros_files`), else the
    defaults (a warning says so); ``overrides`` ({'section.field': value}, see
    :meth:`ControllerConfig.with_overrides`) change it.  ``progress``: progress bars on
    stderr (on a terminal).  A namespace without ``reference_speed`` messages (a ROS
    recording that started after the reference was published, or one that set it as a
    parameter) takes the reference from its ``mpc_status`` records (``reference_speed``, in
    force from each decision on; a warning says so).  Raises :class:`BagError` when a wanted
    namespace has no telemetry, or neither reference nor MPC status.
    """
    say = warn or (lambda text: None)
    overrides = dict(overrides or {})
    recorded_cfg = bag_configuration(path)
    found = _namespaces(path, say)
    for ns, f in found.items():
        if not f["ref"] and f["status"]:
            f["ref"] = [(t, float(m.reference_speed)) for t, m in f["status"]]
            f["ref_source"] = SUFFIX_STATUS[1:]
    wanted = sorted(namespaces) if namespaces is not None else sorted(
        ns for ns, f in found.items() if f["tel"][0] and f["ref"])
    if not wanted:
        raise BagError(f"{path}: no wheel to replay: no namespace has both {SUFFIX_TELEMETRY[1:]} "
                       f"and {SUFFIX_REFERENCE[1:]} (or {SUFFIX_STATUS[1:]}) messages")
    reports = []
    for ns in wanted:
        f = found.get(ns)
        if f is None or not f["tel"][0]:
            raise BagError(f"{path}: namespace {ns!r} has no {SUFFIX_TELEMETRY[1:]} messages; "
                           f"namespaces with telemetry: {sorted(k for k, v in found.items() if v['tel'][0])}")
        if not f["ref"]:
            raise BagError(f"{path}: namespace {ns!r} has no {SUFFIX_REFERENCE[1:]} and no "
                           f"{SUFFIX_STATUS[1:]} messages: the replay needs the reference the "
                           f"controller tracked")
        if "ref_source" in f:
            say(f"{path}: {ns} has no {SUFFIX_REFERENCE[1:]} messages; the reference comes from "
                f"its {SUFFIX_STATUS[1:]} records (in force from each decision on)")
        key = f"{ns}/controller.yaml"
        if config is not None:
            cfg, source = config, "the caller"
        elif key in recorded_cfg:
            cfg = ControllerConfig.from_yaml(recorded_cfg[key], f"{path}: {key}")
            source = f"the bag ({key})"
        elif ROS_FILES[0] in recorded_cfg and ROS_FILES[1] in recorded_cfg:
            cfg = controller_from_ros_files(recorded_cfg[ROS_FILES[0]],
                                            recorded_cfg[ROS_FILES[1]], f"{path}: custom data")
            source = f"the bag's ROS parameter files ({', '.join(ROS_FILES)})"
            say(f"{path}: {ns}: controller from the recorded parameter files; run-time "
                f"changes (ros2 param set) are not replayed")
        else:
            cfg, source = ControllerConfig(), "the defaults"
            say(f"{path}: the bag records no {key}; replaying {ns} with the default controller")
        if overrides:
            cfg = cfg.with_overrides(overrides)
        reports.append(_replay_one(path, ns, cfg, source, overrides, f, say,
                                   f"replay {ns}" if progress else None))
    return reports


def _replay_one(path, ns: str, cfg: ControllerConfig, source: str, overrides: dict,
                f: dict[str, list], say, progress: str | None) -> ReplayReport:
    statuses = f["status"]
    clock = PlaybackClock(float(m.compute_time) for _, m in statuses)
    ctrl = SpeedController(cfg, clock)
    refs = sorted(f["ref"], key=lambda r: r[0])            # stable: arrival order kept
    rep = ReplayReport(ns, source, overrides, decisions_recorded=len(statuses))
    k_ref = 0
    ref = refs[0][1]
    # an estimate and its recorded twin arrive close together; unpaired ones are dropped
    # (oldest first) beyond PAIRING_WINDOW, so memory stays bounded on any bag
    pending_est: dict[int, tuple[dict, float]] = {}        # recomputed, waiting for the recorded
    recorded_est: dict[int, Any] = {}                      # recorded, waiting for the recomputed
    tel, est = ns + SUFFIX_TELEMETRY, ns + SUFFIX_ESTIMATE
    for topic, t_ns, m in read_messages(path, topics=[tel, est], warn=say,
                                          progress=progress):
        if topic == tel:
            while k_ref < len(refs) and refs[k_ref][0] <= t_ns:
                ref = refs[k_ref][1]
                k_ref += 1
            s = samples.telemetry_from_msg(m)
            r = ctrl.step(s, ref)
            rep.samples += 1
            e = r.estimate
            mine = samples.state_msg(e.t, e.xi1, e.xi2, e.q, e.act_counter, e.deact_counter,
                                     e.eta_unwrapped, e.xi2_std, e.quality,
                                     e.accel_disturbance, e.accel_coefficients)
            key = _stamp_ns(m.header.stamp)       # an estimate is stamped as its sample
            if key in recorded_est:
                _compare(recorded_est.pop(key), mine, t_ns / 1e9, rep.estimate_diffs)
                rep.estimates_compared += 1
            else:
                pending_est[key] = (mine, t_ns / 1e9)
                if len(pending_est) > PAIRING_WINDOW:
                    del pending_est[next(iter(pending_est))]
            if r.decision is not None:
                k = rep.decisions_recomputed
                rep.decisions_recomputed += 1
                d = r.decision
                mine_dec = samples.mpc_status_msg(s.t, d.command, ref, d.predicted_speed, d.cost,
                                                  d.compute_time, d.deadline_slack, d.candidates,
                                                  d.deadline_missed, d.braking, r.d)
                mine_dec["t"] = t_ns
                if k < len(statuses):
                    rec_t, rec = statuses[k]
                    _compare({"t": rec_t, **_flat(rec)}, mine_dec, t_ns / 1e9,
                             rep.decision_diffs)
                else:
                    _compare({}, {"extra_decision": True}, t_ns / 1e9, rep.decision_diffs)
        else:
            rep.estimates_recorded += 1
            key = _stamp_ns(m.header.stamp)
            if key in pending_est:
                mine, t = pending_est.pop(key)
                _compare(m, mine, t, rep.estimate_diffs)
                rep.estimates_compared += 1
            else:
                recorded_est[key] = m
                if len(recorded_est) > PAIRING_WINDOW:
                    del recorded_est[next(iter(recorded_est))]
    for t_ns, _ in statuses[rep.decisions_recomputed:]:
        _compare({"missing_decision": True}, {}, t_ns / 1e9, rep.decision_diffs)
    return rep


def _stamp_ns(stamp: Any) -> int:
    if isinstance(stamp, Mapping):
        return int(stamp["sec"]) * 1_000_000_000 + int(stamp["nanosec"])
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
