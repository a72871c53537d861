"""Machine-readable reason codes for every refusal, caution and verdict of the search.

Each refit (:class:`~.evaluation.Evaluation`) carries ``codes``, a list of :class:`Reason`
values beside its prose ``reason``; report.json lists them under ``codes``.  The prose is for
people; tests and programs read the codes (``test_ident_candidates.py``,
``test_ident_effects.py``).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum


class Reason(StrEnum):
    """Why a model, a refit, a pair or an input was taken or turned away."""

    # the model the search starts from, or continues with
    NOMINAL = "nominal"
    RESTARTED = "refitted_from_better_optimum"
    ACCEPTED = "accepted"
    # gates on the fit on all trials (then the folds are not fitted)
    NOT_CROSS_VALIDATED = "not_cross_validated"
    SIM_FITTED_NOT_LOWER = "sim_fitted_not_lower"
    WINDOWS_NOT_BETTER = "windows_not_better"
    # the held-out rules
    SIM_GAIN_BELOW_BAR = "sim_gain_below_bar"
    HELDOUT_WINDOWS_NOT_BETTER = "heldout_windows_not_better"
    NOT_SIGNIFICANT = "wald_not_significant"
    # the values do not look like the effect they name
    IMPLAUSIBLE = "implausible"
    SPEED_STAND_IN = "speed_stand_in"
    DRIFT_STAND_IN = "drift_stand_in"
    HV_LOSS_LOOKALIKE = "hv_loss_lookalike"
    SWITCH_ON_LAG_STAND_IN = "switch_on_lag_stand_in"
    # cautions on an accepted effect: evidence that it may stand in, short of a refusal
    LEANS_ON_SPEED = "leans_on_speed"
    DRIFTS_WITHIN_TRIALS = "drifts_within_trials"
    HOLDS_BESIDE_HV_LOSS = "holds_beside_hv_loss"
    # which measuring device takes up the most of an unexplained drift
    DEVICE_LEADS = "device_leads"
    NO_DEVICE_REFITTED = "no_device_refitted"
    NO_DEVICE_CUTS = "no_device_cuts"
    DEVICES_NOT_TOLD_APART = "devices_not_told_apart"
    # the choice between refits, and the checks after it
    TIE = "tie_not_named"
    NAMED_TOGETHER = "named_together"
    TRIED_TOGETHER = "tried_together"
    REFIT_FROM_REFERENCE = "refit_from_reference"
    BETTER_OPTIMUM = "better_optimum_of_current"
    POORER_OPTIMUM = "current_in_poorer_optimum"
    RAN_ON = "ran_on"
    NEAR_MISS = "near_miss"
    # a screened candidate that was not refitted
    SCORE_NOT_SIGNIFICANT = "score_not_significant"
    NOT_PROMISING = "others_more_promising"
    # inputs
    TOO_FEW_TRIALS = "too_few_trials"
    TOO_FEW_FOLDS = "too_few_folds"


@dataclass(frozen=True)
class Finding:
    """A refusal or check result: its ``code``, its ``text`` for people, and the figures it
    rests on (``values``, by name, in the units the text gives)."""

    code: Reason
    text: str
    values: Mapping[str, object] = field(default_factory=dict)

    def __str__(self) -> str:
        return self.text


class InputRefused(ValueError):
    """An input the identification cannot run on; ``code`` says which rule it breaks."""

    def __init__(self, code: Reason, text: str) -> None:
        super().__init__(text)
        self.code = code
