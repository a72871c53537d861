"""Why a refit's values cannot be the effect they name: implausible values, or a stand-in
for another effect (:mod:`.stand_ins`).  :class:`Refusals` judges each fit once and keeps
what the report and the unexplained structure's description need."""
from __future__ import annotations

from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.acceptance import implausibility
from hasel_wheel_ident.candidates import Candidate
from hasel_wheel_ident.consistency import Consistency
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.fit import FitResult
from hasel_wheel_ident.reasons import Finding
from hasel_wheel_ident.stand_ins import drift_stand_in, lag_stand_in, stand_in_reason
from hasel_wheel_ident.trial_refit import trial_consistency


class Refusals:
    """The refusals of one search on ``trials`` (``window`` [s], bar ``min_gain`` [1]).

    ``stand_ins``: effect id -> (candidate, finding) refused as a stand-in for a trend with
    the trials' speed; ``within``: (fit bytes, effect id) -> a note on an effect refused
    beside a measuring device; ``checked``: (fit bytes, effect id) -> the effect refitted
    trial by trial."""

    def __init__(self, trials: list[Trial], base: WheelParams, window: float,
                 min_gain: float, threads: int) -> None:
        self.trials, self.base, self.window = trials, base, window
        self.min_gain, self.threads = min_gain, threads
        self.refused: dict[bytes, Finding | None] = {}
        self.stand_ins: dict[str, tuple[Candidate, Finding]] = {}
        self.within: dict[tuple[bytes, str], str] = {}
        self.checked: dict[tuple[bytes, str], Consistency] = {}

    def __call__(self, f: FitResult, effects: tuple[Candidate, ...],
                 added: tuple[Candidate, ...]) -> Finding | None:
        """Why the values of ``added`` in the fit ``f`` of the model ``effects`` cannot be
        the effects they name (codes ``IMPLAUSIBLE``, ``SPEED_STAND_IN``,
        ``DRIFT_STAND_IN``, ``HV_LOSS_LOOKALIKE``, ``SWITCH_ON_LAG_STAND_IN``), or None;
        judged once per fit."""
        key = f.z.tobytes() + ("+".join(c.id for c in effects) + "|"
                               + "+".join(c.id for c in added)).encode()
        if key not in self.refused:
            why = implausibility(f, added)
            if why is None:
                why = self._stand_in(f, effects, added)
            self.refused[key] = why
        return self.refused[key]

    def _stand_in(self, f: FitResult, effects: tuple[Candidate, ...],
                  added: tuple[Candidate, ...]) -> Finding | None:
        """The first of ``added`` refitted trial by trial that stands in for another effect:
        its size trends with the speed, or it does not hold beside a measuring device."""
        for c in added:
            con = trial_consistency(self.trials, self.base, effects, f, c, self.window,
                                    self.threads)
            self.checked[(f.z.tobytes(), c.id)] = con
            why = stand_in_reason(c, con)
            if why is not None:
                self.stand_ins[c.id] = (c, why)
                return why
            why = self._beside_device(f, effects, c, con)
            if why is not None:
                return why
        return None

    def _beside_device(self, f: FitResult, effects: tuple[Candidate, ...], c: Candidate,
                       con: Consistency) -> Finding | None:
        """``c`` refused beside a measuring device: a change within the trials, then a size
        that grows with the speed; the refusal is noted in ``within``."""
        for check, kept in ((drift_stand_in, "beside"), (lag_stand_in, "beside_lag")):
            why = check(self.trials, self.base, effects, f, c, con, self.min_gain,
                        self.window, self.threads)
            if why is not None:
                b = getattr(con, kept)
                self.within[(f.z.tobytes(), c.id)] = (f"{c.id} took up part of it and was "
                                                      f"refused, {b.text(c.id, need=True)}")
                return why
        return None
