"""Rerun recordings of a calibration run, for any robot (rerun-sdk 0.41 API).

Entities (all lengths in mm):

* ``machine/{nominal,actual,calibrated}/chains|platform``: the 3D machine at each measured pose
  (timeline ``pose``), drawn from :meth:`calib.robot.Robot.chain_points`: the pose the controller
  intended (nominal), the pose measured on the machine (actual) and the pose the calibrated model
  predicts (calibrated); ``machine/error_x1000``: the position error magnified 1000 times.
* ``calibration/max_dqint``: max dQint per iteration (timeline ``iteration``).
* ``heldout/position_error_um/{before,after}``, ``heldout/orientation_error_urad/{before,after}``
  per held-out pose (timeline ``heldout_pose``).
* ``parameters/{injected,identified,difference}``: bar charts of the errors (um or urad),
  ``parameters/names`` their names in order.
* ``observability``: see :mod:`pipeline.obs_log`; ``summary``: a markdown summary.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from calib.robot import Robot

from .obs_log import log_observability, observability_views
from .recording import writing

__all__ = ["log_calibration_run", "save_recording", "rrd_entities", "summary_markdown", "blueprint"]

COLORS = {"nominal": [150, 150, 150], "actual": [230, 120, 30], "calibrated": [40, 160, 220]}
#: Magnification of the position error arrows (tens of micrometres are invisible at machine scale).
ERROR_MAGNIFICATION = 1000.0


def _log_machine(rec: rr.RecordingStream, path: str, points: np.ndarray, color) -> None:
    """``points``: (C, K, 3) chain polylines of one pose; the platform joins their last points."""
    rec.log(f"{path}/chains", rr.LineStrips3D(list(points), colors=color, radii=1.5))
    tips = points[:, -1]
    rec.log(f"{path}/platform", rr.LineStrips3D([np.vstack([tips, tips[:1]])], colors=color, radii=1.0))


def blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="machine", name="Machine: nominal / actual / calibrated"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="heldout/position_error_um", name="Held-out position error (um)"),
                rrb.TimeSeriesView(origin="heldout/orientation_error_urad", name="Held-out orientation error (urad)"),
                rrb.TimeSeriesView(origin="calibration", name="max dQint per iteration"),
            ),
            rrb.Vertical(
                rrb.Tabs(
                    rrb.BarChartView(origin="parameters/identified", name="Identified (um, urad)"),
                    rrb.BarChartView(origin="parameters/injected", name="Injected (um, urad)"),
                    rrb.BarChartView(origin="parameters/difference", name="Identified - injected (um, urad)"),
                    observability_views("observability", "Observability"),
                ),
                rrb.TextDocumentView(origin="summary", name="Summary"),
            ),
            column_shares=[2, 2, 2],
        ),
        collapse_panels=True,
    )


def summary_markdown(summary: dict) -> str:
    """The run summary as a markdown panel."""
    h = summary.get("heldout_position_error_mm")
    o = summary.get("heldout_orientation_error_rad")
    lines = [
        f"# Calibration of the {summary['robot']}",
        f"{summary['scenario']}",
        "",
        f"- method: **{summary['method']}** ({summary['solver']}), {summary['calibration_poses']} "
        f"calibration poses, {summary['heldout_poses']} held-out",
        f"- declared noise: {summary['declared_noise']}",
        f"- iterations: {summary['iterations']}",
        f"- stop: {summary['message']}",
    ]
    if h:
        lines += ["", "| held-out | before | after (mean) | after (max) |", "|---|---|---|---|",
                  f"| position, um | {1e3 * h['before']:.3f} | {1e3 * h['after']:.3f} | {1e3 * h['max_after']:.3f} |"]
        if o:
            lines.append(f"| orientation, urad | {1e6 * o['before']:.3f} | {1e6 * o['after']:.3f} | "
                         f"{1e6 * o['max_after']:.3f} |")
        lines += ["", f"Held-out basis: {summary['heldout_basis']}"]
    pe = summary.get("parameter_error")
    if pe and pe.get("rms_mm") is not None:
        lines.append(f"\nParameter error RMS (identified - injected, lengths): {1e3 * pe['rms_mm']:.3f} um")
    lines.append("\nCondition numbers: " + ", ".join(f"{c:.0f}" for c in summary["condition_numbers"]))
    fl = summary["flagged_poses"]
    out = summary.get("outliers") or {}
    state = ("left out" if out.get("left_out") else "kept (--keep-outliers)") if fl else ""
    lines.append(f"\nFlagged rows (data rows, row k = file line k + 1): "
                 f"{', '.join(str(i) for i in fl) + ', ' + state if fl else 'none'}")
    if out.get("verdict"):
        lines.append(f"\nOutlier test: {out['verdict']}")
    for w in summary.get("warnings") or ():
        lines.append(f"\nWarning: {w}")
    return "\n".join(lines)


def _bar_scale(robot: Robot) -> np.ndarray:
    """um per mm and urad per rad: errors of micrometres and microradians read as numbers."""
    return np.where(robot.table.angle_mask(), 1e6, 1e3)


def log_calibration_run(
    rec: rr.RecordingStream, *, robot: Robot, nominal: np.ndarray, actual: np.ndarray | None,
    identified: np.ndarray, std: np.ndarray, joints: np.ndarray, targets: np.ndarray, measured: np.ndarray,
    predicted: np.ndarray, history: tuple, heldout_before: np.ndarray | None,
    heldout_after: np.ndarray | None, summary_markdown: str, observability=None,
) -> None:
    """Log one calibration run.

    Args:
        rec: the recording stream.
        robot: the robot.
        nominal, actual, identified: (P,) parameter vectors (``actual`` None for a real machine).
        std: (P,) standard uncertainty of the identified parameters.
        joints: (N, C) commanded joints of the calibration poses.
        targets: (N, D) poses the controller intended.
        measured: (N, D) measured poses.
        predicted: (N, D) poses the identified model predicts at the commanded joints.
        history: max dQint (or cost) per iteration.
        heldout_before, heldout_after: (M, D) held-out pose errors (reached - target), or None.
        summary_markdown: text of the summary panel.
        observability: a :class:`calib.observability.ObservabilityAnalysis` to log, or None.
    """
    rec.log("machine", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    angle = robot.angle_pose_mask
    nominal_joints = robot.inverse_kinematics(nominal, targets)
    drawn = actual if actual is not None else identified
    for k in range(targets.shape[0]):
        rec.set_time("pose", sequence=k)
        _log_machine(rec, "machine/nominal", robot.chain_points(nominal, nominal_joints[k:k + 1], targets[k:k + 1])[0],
                     COLORS["nominal"])
        _log_machine(rec, "machine/actual", robot.chain_points(drawn, joints[k:k + 1], measured[k:k + 1])[0],
                     COLORS["actual"])
        _log_machine(rec, "machine/calibrated", robot.chain_points(identified, joints[k:k + 1], predicted[k:k + 1])[0],
                     COLORS["calibrated"])
        err = (measured[k, ~angle] - targets[k, ~angle]) * ERROR_MAGNIFICATION
        rec.log("machine/error_x1000", rr.Arrows3D(origins=[targets[k, ~angle]], vectors=[err], colors=[220, 30, 30]))
    for it, v in enumerate(history, start=1):
        rec.set_time("iteration", sequence=it)
        rec.log("calibration/max_dqint", rr.Scalars(v))
    if heldout_before is not None and heldout_after is not None:
        rec.log("heldout/position_error_um", rr.SeriesLines(names=["before", "after"]), static=True)
        for k in range(heldout_before.shape[0]):
            rec.set_time("heldout_pose", sequence=k)
            for name, e in (("before", heldout_before[k]), ("after", heldout_after[k])):
                rec.log(f"heldout/position_error_um/{name}", rr.Scalars(1000.0 * np.linalg.norm(e[~angle])))
                if angle.any():
                    rec.log(f"heldout/orientation_error_urad/{name}", rr.Scalars(1e6 * np.linalg.norm(e[angle])))
    scale = _bar_scale(robot)
    rec.log("parameters/names", rr.TextDocument(", ".join(robot.table.names)), static=True)
    rec.log("parameters/identified", rr.BarChart(scale * (identified - nominal)), static=True)
    rec.log("parameters/std", rr.BarChart(scale * std), static=True)
    if actual is not None:
        rec.log("parameters/injected", rr.BarChart(scale * (actual - nominal)), static=True)
        rec.log("parameters/difference", rr.BarChart(scale * (identified - actual)), static=True)
    if observability is not None:
        log_observability(rec, observability, "observability", title="Observability of the calibration poses")
    rec.log("summary", rr.TextDocument(summary_markdown, media_type=rr.MediaType.MARKDOWN), static=True)


def save_recording(path: str | Path, log_fn, *, application_id: str = "parallel_calib",
                   overwrite: bool = False, bp: rrb.Blueprint | None = None) -> Path:
    """Write an ``.rrd`` atomically: ``log_fn(rec)`` logs into a temporary file, then rename.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    path = Path(path)
    with writing(path, overwrite=overwrite) as tmp:
        rec = rr.RecordingStream(application_id)
        rec.save(str(tmp), default_blueprint=bp if bp is not None else blueprint())
        log_fn(rec)
        rec.flush()
        rec.disconnect()
    return path


def rrd_entities(path: str | Path) -> set[str]:
    """Entity paths present in an ``.rrd`` file (reads it back with ``rerun.chunk.RrdReader``)."""
    from rerun.chunk import RrdReader

    return {c.entity_path for c in RrdReader(str(path)).stream().to_chunks()}
