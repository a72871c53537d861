"""The identification report on disk (:func:`write_report`): ``report.md`` with PNG figures
(:mod:`.report_md`), ``report.json`` (:mod:`.report_json`, its keys documented there) and
``model.yaml``, the identified model that the sim and the MPC load."""
from __future__ import annotations

import json
from pathlib import Path

from hasel_wheel_sim.model_file import save_model

from hasel_wheel_ident import plots
from hasel_wheel_ident.identification import Identification
from hasel_wheel_ident.report_json import json_number, to_json
from hasel_wheel_ident.report_md import to_markdown
from hasel_wheel_ident.report_text import near_miss_text, near_miss_texts, stall_texts

#: the sentences the command and the benchmarks print, beside the writer
__all__ = ["write_report", "near_miss_text", "near_miss_texts", "stall_texts"]


def write_report(ident: Identification, out: Path | str, identifiability: list[str] | None = None,
                 closed_loop: dict | None = None, provenance: dict | None = None) -> dict:
    """Write report.md, report.json, the figures and model.yaml under ``out``; returns the
    JSON dict."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figures = [plots.speed_fits(ident, out), plots.evidence(ident, out)]
    if ident.diagnostics_before is not None:
        figures += [plots.correlations(ident.diagnostics_before, ident.diagnostics_after, out),
                    plots.structure(ident.diagnostics_before, ident.diagnostics_after, out),
                    plots.spectra(ident.diagnostics_before, ident.diagnostics_after, out)]
    params, ext, left_out = ident.model()
    save_model(out / "model.yaml", params, ext,
               dict(provenance or {}, tool="hasel_wheel identify",
                    chosen_effects=list(ident.chosen), left_out_effects=left_out))
    data = to_json(ident, figures, left_out)
    if identifiability:
        data["identifiability"] = identifiability
    if closed_loop:
        data["closed_loop"] = {name: {"rmse_rad_s": json_number(m["rmse"]), "nrmse": json_number(m["nrmse"]),
                                      "segment_steady_error_percent":
                                          [json_number(v) for v in m["segment_steady_error"]],
                                      "decisions": m["decisions"], "braking": m["braking"]}
                               for name, m in closed_loop.items()}
    (out / "report.json").write_text(json.dumps(data, indent=2, sort_keys=False) + "\n")
    (out / "report.md").write_text(to_markdown(ident, data, closed_loop))
    return data
