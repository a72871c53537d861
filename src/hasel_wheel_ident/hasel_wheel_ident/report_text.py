"""The report's sentences that the command, the benchmarks and report.md share."""
from __future__ import annotations

from hasel_wheel_ident.acceptance import near_misses
from hasel_wheel_ident.evaluation import Evaluation
from hasel_wheel_ident.identification import Identification
from hasel_wheel_ident.report_json import near_miss


def fmt_number(v: float | None, spec: str) -> str:
    """A JSON number for the Markdown; null (nan or inf) reads as "n/a"."""
    return "n/a" if v is None else format(v, spec)


def near_miss_text(m: dict) -> str:
    """One line on a ``near_misses`` entry of report.json."""
    each = {i: ", ".join(f"{k} {fmt_number(v, '.4g')}" for k, v in m["physical"][i].items())
            for i in m["ids"]}
    values = "; ".join(f"{i}: {v}" for i, v in each.items()) if len(each) > 1 else \
        next(iter(each.values()), "")
    return (f"{'+'.join(m['ids'])} ({values}): Wald p {fmt_number(m['wald_p'], '.1e')}, held-out "
            f"simulation error {fmt_number(m['final_heldout_simulation_rmse_rad_s'], '.4f')} -> "
            f"{fmt_number(m['heldout_simulation_rmse_rad_s'], '.4f')} rad/s "
            f"({fmt_number(None if m['cut'] is None else 100 * m['cut'], '.1f')} % lower; the bar "
            f"is {100 * m['bar']:.0f} %)")


def stall_texts(data: dict) -> list[str]:
    """The stalls of report.json's trials in words, one per trial that stalled."""
    return [t["rest_tail"]["text"] for t in data["trials"]
            if t["rest_tail"] is not None and t["rest_tail"]["stalled"]]


def near_miss_texts(ident: Identification) -> list[str]:
    """One line per refit :func:`~.acceptance.near_misses` lists for ``ident`` (as the command's
    summary prints them)."""
    return [near_miss_text(near_miss(e, ident.final, ident.min_gain))
            for e in near_misses(ident)]


def fit_status_text(ev: Evaluation, label: str) -> str:
    """One sentence on whether the fit of ``ev`` on all trials converged."""
    if ev.fit.converged:
        return f"The {label} fit converged after {ev.fit.nfev} evaluations."
    return (f"**The {label} fit did not converge**: it stopped at its limit of {ev.fit.nfev} "
            f"evaluations ({ev.fit.message}), so its values are where it stopped, not a "
            f"minimum.  A model that lacks an effect present in the data typically does this: "
            f"its force law drifts along a direction the data hardly determine while the "
            f"error falls slowly.")
