"""The identification's result record, :class:`Identification`."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import BY_ID
from hasel_wheel_ident.consistency import Consistency
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.evaluation import Evaluation
from hasel_wheel_ident.fit import FrictionEstimate, Problem
from hasel_wheel_ident.friction_trend import CoastFriction, FrictionTrend
from hasel_wheel_ident.prediction import PredictionResidual
from hasel_wheel_ident.residual import Diagnostics, Signature
from hasel_wheel_ident.screen import Screening
from hasel_wheel_ident.session import Session
from hasel_wheel_ident.steps import GainStep, latest_gains


@dataclass
class Identification:
    """Everything the search found, in the order it found it."""

    friction: FrictionEstimate | None
    nominal: Evaluation
    final: Evaluation
    rounds: list[list[Evaluation]] = field(default_factory=list)
    screenings: list[list[Screening]] = field(default_factory=list)
    diagnostics_before: Diagnostics | None = None
    diagnostics_after: Diagnostics | None = None
    problem_before: Problem | None = None
    problem_after: Problem | None = None
    folds: list[list[int]] = field(default_factory=list)
    prediction_before: dict[str, PredictionResidual] = field(default_factory=dict)
    prediction_after: dict[str, PredictionResidual] = field(default_factory=dict)
    trials: list[Trial] = field(default_factory=list)
    base: WheelParams = field(default_factory=WheelParams)
    window: float = 1.0
    #: the chosen effects refitted trial by trial and on the halves of each drive, as checked
    #: when each was added (:mod:`.consistency`); keyed by effect id
    consistency: dict[str, Consistency] = field(default_factory=dict)
    #: periodic signatures of the residual that their refit did not confirm
    #: (:func:`~.periodic.confirmed`): listed apart, not as unexplained structure
    unconfirmed: list[Signature] = field(default_factory=list)
    #: the refit (one of ``rounds``' evaluations, or a restart's) that stopped at its limit
    #: and ran on into ``final``, whose values are therefore not its own; None when the
    #: final model did not run on
    ran_on_from: Evaluation | None = None
    #: the free-run bar [1] the search judged with (``identify``'s ``min_gain``)
    min_gain: float = 0.10
    #: the trials as a session: their order, start times and gaps (:mod:`.session`)
    session: Session | None = None
    #: tau_f of each coast-down in session order, and its trend along session time
    #: (:mod:`.friction_trend`; None without three timed coast-downs)
    coast_friction: list[CoastFriction] = field(default_factory=list)
    friction_trend: FrictionTrend | None = None
    #: a pad whose gain changed between two trials of a timed session (:mod:`.steps`); the
    #: identified model takes its gain after the change
    gain_step: GainStep | None = None

    @property
    def chosen(self) -> tuple[str, ...]:
        """The chosen effects' ids, in the order chosen."""
        return self.final.effects

    def problem(self, effects: tuple[str, ...]) -> Problem:
        """The fit problem of the model nominal + ``effects`` on all trials."""
        return Problem(self.trials, self.base, tuple(BY_ID[i] for i in effects), self.window)

    def model(self) -> tuple[WheelParams, Extensions, list[str]]:
        """The identified model as the plant and the MPC take it: (wheel parameters,
        extensions, the chosen effects that have no field there and are left out); a pad
        whose gain stepped in the session at its gain after the step (:mod:`.steps`)."""
        prob = self.problem(self.chosen)
        params = prob.wheel_params(prob.full_theta(self.final.fit.theta))
        fields: dict = {}
        left_out = []
        i = prob.n_nominal
        values = prob.full_theta(self.final.fit.theta)
        for c in prob.candidates:
            x = values[i:i + c.size]
            i += c.size
            if c.extension is None:
                left_out.append(c.id)
            else:
                fields.update(c.extension(x))
        if self.gain_step is not None and "gains" in fields:
            fields["gains"] = tuple(float(g) for g in latest_gains(np.asarray(fields["gains"]),
                                                                   self.gain_step))
        return params, Extensions(**fields), left_out
