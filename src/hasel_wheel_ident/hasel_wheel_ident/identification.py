"""The identification's result record, :class:`Identification`."""
from __future__ import annotations

from dataclasses import dataclass, field

from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import BY_ID
from hasel_wheel_ident.consistency import Consistency
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.evaluation import Evaluation
from hasel_wheel_ident.fit import FrictionEstimate, Problem
from hasel_wheel_ident.prediction import PredictionResidual
from hasel_wheel_ident.residual import Diagnostics, Signature
from hasel_wheel_ident.screen import Screening


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

    @property
    def chosen(self) -> tuple[str, ...]:
        """The chosen effects' ids, in the order chosen."""
        return self.final.effects

    def problem(self, effects: tuple[str, ...]) -> Problem:
        """The fit problem of the model nominal + ``effects`` on all trials."""
        return Problem(self.trials, self.base, tuple(BY_ID[i] for i in effects), self.window)

    def model(self) -> tuple[WheelParams, Extensions, list[str]]:
        """The identified model as the plant and the MPC take it: (wheel parameters,
        extensions, the chosen effects that have no field there and are left out)."""
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
        return params, Extensions(**fields), left_out
