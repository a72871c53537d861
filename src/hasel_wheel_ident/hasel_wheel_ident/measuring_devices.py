"""The measuring devices, never named as effects: a force loss that grows with the
accumulated HV time (:data:`HV_LOSS`) and a force that builds up after each switch-on
(:data:`ON_LAG`).  An effect refitted beside one (:func:`measure_beside`) gives a
:class:`Beside`, which says whether the effect still holds there.  The evidence behind each
threshold is in docs/identification.md; tested in ``test_ident_consistency.py``
(``test_an_effect_holds_beside_a_device_when_significant_and_still_cutting_the_error``)."""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import BY_ID, Candidate, ParamSpec
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.fit import FitResult, Problem, effect_wald_p
from hasel_wheel_ident.metrics import fitted_metrics, pooled_rmse
from hasel_wheel_ident.trial_refit import MAX_NFEV

#: Charge retention's recovery [s] in the measuring device: far longer than any trial, so
#: that the loss grows with the accumulated HV time alone.
HV_LOSS_RECOVERY = 1e5
#: Beside the device, the effect must still differ from "no effect" at this level (the
#: search's Wald test) ...
BESIDE_P = 1e-6
#: ... and a device counts as there beside an effect at this level [1]
#: (:func:`~.stand_ins.drift_stand_in`, :func:`~.device_verdict.together_lead`).
LOOKALIKE_P = 1e-2
#: Evaluation limit of the measuring refit beside an unexplained drift, after the search
#: (:func:`refit_beside`, once per run and device): it starts from a force law bent to take
#: up the loss.  The stand-in tests during the search (:func:`measure_beside`) keep
#: :data:`~.trial_refit.MAX_NFEV`, since they start from the effect's own fit.
BESIDE_NFEV = 150


def _hv_loss(x, pv, extra):
    pv[L.P_RET_RATE] = x[0]
    pv[L.P_RET_RECOVERY] = HV_LOSS_RECOVERY


#: The measuring device for a change within the trials: every actuator's force
#: x exp(-loss_rate Q_i), Q_i its accumulated HV time [s], loss_rate [1/s].
HV_LOSS = Candidate("hv_loss", "actuator force lost with accumulated HV time (a measuring "
                    "device)", (ParamSpec("loss_rate", "1/s", 1e-3, 0.0, 1.0, 1e-2),),
                    _hv_loss, lambda x: {"rate_per_s": float(x[0])}, "hv_time")

#: The measuring device for a size that grows with the speed: the rise lag's physics, every
#: actuator's force x (1 - exp(-t_on / lag_tau)), t_on [s] the time since it was switched
#: on, lag_tau [s] from 20 ms, without the rise lag's screening or saved model fields.  A
#: loss at each switch-on takes a larger share of a shorter push, so it grows with speed.
ON_LAG = dataclasses.replace(
    BY_ID["rise_lag"], id="on_lag",
    title="actuator force that builds up after each switch-on (a measuring device)",
    params=(ParamSpec("lag_tau", "s", 0.02, 1e-5, 0.5, 0.01),), extension=None,
    screen_at=(), scan=())

#: Each device in words: (what it is, its fitted value [its unit] -> words).
DEVICE_WORDS: dict[str, tuple[str, Callable[[float], str]]] = {
    HV_LOSS.id: ("a force loss that grows with the accumulated HV time",
                 lambda v: f"rate {v:.3g}/s"),
    ON_LAG.id: ("a force that builds up after each switch-on",
                lambda v: f"time constant {1e3 * v:.3g} ms"),
}

#: The trend axis (:data:`~.residual.TREND_AXES`) along which each device's loss drifts:
#: a loss with HV time along the HV time, a loss at each switch-on along the speed.
DEVICE_TREND_AXIS = {HV_LOSS.id: "hv_time", ON_LAG.id: "speed"}


@dataclass
class Beside:
    """An effect refitted beside a measuring device (:func:`measure_beside`): ``value`` the
    device's one parameter in its unit, ``values`` the effect's own values there (each in its
    unit), ``p`` the effect's Wald p there (:func:`~.fit.effect_wald_p`), ``sim`` the
    pooled free-run error on all trials [rad/s] with the effect and without it (the device
    alone), and ``min_gain`` (a fraction) the search's, by which :meth:`holds` judges."""

    device: Candidate
    value: float
    values: dict[str, float]
    p: float
    sim: tuple[float, float]
    min_gain: float = 0.10
    #: the device's own Wald p beside the effect (:func:`~.fit.effect_wald_p`)
    device_p: float = math.nan

    def holds(self) -> bool:
        """Whether the effect still holds beside the device: its Wald p under
        :data:`BESIDE_P`, and it cuts the free run on all trials by half of ``min_gain`` or
        more against the device alone."""
        e1, e0 = self.sim
        return self.p < BESIDE_P and 1.0 - e1 / e0 >= 0.5 * self.min_gain

    def text(self, effect: str, need: bool = False) -> str:
        """The refit in words; with ``need``, what :meth:`holds` needs."""
        e1, e0 = self.sim
        needs = ((f" (need < {BESIDE_P:.0e})", f", need {50 * self.min_gain:.0f} %")
                 if need else ("", ""))
        cut = 1.0 - e1 / e0
        noun, value = DEVICE_WORDS[self.device.id]
        own = (f", itself at Wald p {self.device_p:.1e}" if math.isfinite(self.device_p)
               else "")
        return (f"refitted beside {noun} ({value(self.value)}, a measuring "
                f"device{own}; Wald p of {effect} {self.p:.1e}{needs[0]}, the free run on all "
                f"trials {e1:.4f} rad/s against {e0:.4f} without it, "
                f"{'a cut' if cut >= 0 else 'a rise'} of {100 * abs(cut):.1f} %{needs[1]})")


def can_measure_beside(effects: tuple[Candidate, ...]) -> bool:
    """Whether :data:`HV_LOSS` can go beside the model with ``effects``: not when it has a
    retention of its own (the device would be it) or the device already."""
    return not any(c.id in ("charge_retention", HV_LOSS.id) for c in effects)


def can_measure_lag(effects: tuple[Candidate, ...]) -> bool:
    """Whether :data:`ON_LAG` can go beside the model with ``effects``: not when it has a
    rise lag of its own (the device would be it) or the device already."""
    return not any(c.id in ("rise_lag", ON_LAG.id) for c in effects)


def refit_beside(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                 fit: FitResult, device: Candidate, window: float = 1.0, threads: int = 2,
                 max_nfev: int = BESIDE_NFEV) -> tuple[Problem, FitResult]:
    """(The problem, its fit): the model with ``effects`` (fitted on all ``trials`` as
    ``fit``; ``window`` [s]) refitted with the measuring ``device`` beside it, from ``fit``
    and the device's start value, for up to ``max_nfev`` evaluations."""
    problem = Problem(trials, base, effects + (device,), window, threads=threads)
    return problem, problem.fit(start=fit.values, x0=fit.x0, max_nfev=max_nfev)


def measure_beside(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                   fit: FitResult, effect: Candidate, device: Candidate, min_gain: float,
                   window: float = 1.0, threads: int = 2) -> Beside | None:
    """``effect`` (in ``effects``, the model fitted on all ``trials`` as ``fit``) refitted
    beside the measuring ``device``, and the model without ``effect`` but with the device
    (each :data:`~.trial_refit.MAX_NFEV` evaluations; the second from the first): a
    :class:`Beside` judged by ``min_gain`` (a fraction), or None when one of its figures is
    not finite."""
    with_it, f1 = refit_beside(trials, base, effects, fit, device, window, threads, MAX_NFEV)
    own = {p.name for p in effect.params}
    without = Problem(trials, base, tuple(c for c in effects if c is not effect) + (device,),
                      window, threads=threads)
    f0 = without.fit(start={k: v for k, v in f1.values.items() if k not in own},
                     x0=f1.x0, max_nfev=MAX_NFEV)
    e1 = pooled_rmse(fitted_metrics(with_it, f1, trials))
    e0 = pooled_rmse(fitted_metrics(without, f0, trials))
    p = effect_wald_p(f1, effect)
    value = f1.values[device.params[0].name]
    if not all(math.isfinite(v) for v in (e1, e0, p, value)) or e0 <= 0.0:
        return None
    return Beside(device, value, {n: f1.values[n] for n in own}, p, (e1, e0), min_gain,
                  effect_wald_p(f1, device))
