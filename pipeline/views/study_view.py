"""The Rerun view of a Monte Carlo study (rerun-sdk 0.41 API): the calibration poses'
observability, per method the MSE / CRB and the empirical standard deviation of each parameter,
the held-out position error per trial, and a markdown summary."""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from .charts import application_id, chart_view, save_recording
from .observability import log_bars, log_observability, observability_views

__all__ = ["write_study_rrd", "study_markdown"]


def study_markdown(summary: dict) -> str:
    """The study's summary as a markdown document (one row a method)."""
    noise = summary["noise"]
    lines = ["# Monte Carlo study", "",
             f"{summary['robot']}: {summary['trials']} trials, seed {summary['seed']}, {summary['n_poses']} "
             f"{summary['poses']} poses ({summary['workspace']['name']} workspace), Gaussian noise std "
             f"{noise['position_mm']:g} mm, {noise['orientation_rad']:g} rad, joints {noise['joint']:g}. "
             f"Machine: {summary['simulated_machine']}.", "",
             f"CRB parameter RMS: {summary['crb_rms_mm']:.4g} mm", "",
             "| method | param. error RMS (mm) | MSE/CRB min | mean | max (param) "
             "| held-out position mean / RMS (um) |",
             "|---|---|---|---|---|---|"]
    for m, f in summary["methods"].items():
        h = f["heldout_position_mm"]
        lines.append(f"| {m} | {f['parameter_error_rms_mm']:.4g} | {f['mse_over_crb_min']:.3f} | "
                     f"{f['mse_over_crb_mean']:.3f} | {f['mse_over_crb_max']:.3f} "
                     f"({f['mse_over_crb_max_parameter']}) | "
                     + (f"{h['mean'] * 1e3:.4g} / {h['rms'] * 1e3:.4g} |" if h else "- |"))
    if summary["predicted_heldout_position_rms_mm_at_crb"] is not None:
        lines += ["", f"Held-out position error RMS predicted at the CRB: "
                      f"{summary['predicted_heldout_position_rms_mm_at_crb'] * 1e3:.4g} um"]
    return "\n".join(lines) + "\n"


def write_study_rrd(path, analysis, results, figures, summary, overwrite) -> None:
    """The study's ``.rrd`` (see the module docstring): ``analysis`` the calibration poses'
    observability, ``results`` and ``figures`` per method as :func:`pipeline.workflows.study.run_study`
    makes them, ``summary`` its summary."""

    names = list(analysis.names)
    views = [observability_views("study/observability", "Calibration poses", per_parameter=True)]
    for m in results:
        views.append(rrb.Vertical(
            chart_view(f"study/{m}/mse_over_crb", f"{m}: MSE / CRB per parameter"),
            chart_view(f"study/{m}/empirical_std_mm", f"{m}: empirical std per parameter (mm)"),
            rrb.TimeSeriesView(origin=f"study/{m}/heldout_position_um", name=f"{m}: held-out position error (um) per trial"),
            row_shares=[2, 2, 1],
        ))
    bp = rrb.Blueprint(rrb.Horizontal(rrb.TextDocumentView(origin="study/summary", name="Summary"), *views),
                       rrb.TimePanel(timeline="trial", play_state="paused", state="collapsed"), collapse_panels=True)

    def log(rec):
        log_observability(rec, analysis, "study/observability", title=f"Calibration poses ({summary['robot']})")
        rec.log("study/summary", rr.TextDocument(study_markdown(summary), media_type=rr.MediaType.MARKDOWN), static=True)
        for m, r in results.items():
            f = figures[m]
            log_bars(rec, f"study/{m}/mse_over_crb", np.array([f["mse_over_crb"][n] for n in names]), names,
                     unit="1 (MSE / CRB)", title=f"{m}: MSE / CRB")
            # An angle's std as the length it moves at the machine's size, like crb_std_mm.
            log_bars(rec, f"study/{m}/empirical_std_mm",
                     np.array([f["empirical_std"][n] for n in names]) * analysis.scale, names, unit="mm",
                     title=f"{m}: empirical std")
            hp = r["heldout_position_mm"]
            if not np.all(np.isnan(hp)):
                rec.send_columns(f"study/{m}/heldout_position_um",
                                 indexes=[rr.TimeColumn("trial", sequence=np.arange(hp.size))],
                                 columns=rr.Scalars.columns(scalars=hp * 1e3))

    save_recording(path, log, application_id=application_id("study", summary["robot"]), overwrite=overwrite, bp=bp)
