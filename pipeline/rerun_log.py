"""Rerun recordings of a calibration run (rerun-sdk 0.41 API).

Entities (all lengths in mm):

* ``machine/{nominal,actual,calibrated}/legs|platform``: the 3D machine at each measured pose
  (timeline ``pose``): the pose the controller intended (nominal), the pose measured on the
  machine (actual) and the pose the calibrated model predicts (calibrated);
  ``machine/error_x1000``: the position error magnified 1000 times (tens of micrometres are
  invisible at the scale of the machine).
* ``calibration/max_dqint``: max dQint per iteration (timeline ``iteration``).
* ``heldout/position_error_um/{before,after}``, ``heldout/orientation_error_urad/{before,after}``
  per held-out pose (timeline ``heldout_pose``).
* ``parameters/{injected,identified,difference}``: bar charts of the 42 errors, um.
* ``summary``: a markdown summary.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from calib.hexapod import Hexapod, parameter_table
from calib.rotation import rotation_matrix

from .obs_log import observability_views
from .recording import writing

__all__ = ["machine_points", "log_calibration_run", "save_recording", "rrd_entities"]

COLORS = {"nominal": [150, 150, 150], "actual": [230, 120, 30], "calibrated": [40, 160, 220]}


def machine_points(hexapod: Hexapod, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Base and platform joint positions of ``hexapod`` at ``pose``.

    Args:
        hexapod: parameter set whose joints to place.
        pose: (6,) mm and rad.

    Returns:
        ``(B, P)``: (6, 3) and (6, 3), mm, base frame.
    """
    R = rotation_matrix(pose[3:6])
    return hexapod.base_joints, hexapod.platform_joints @ R.T + pose[:3]


def _log_machine(rec: rr.RecordingStream, path: str, hexapod: Hexapod, pose: np.ndarray, color) -> None:
    B, P = machine_points(hexapod, pose)
    rec.log(f"{path}/legs", rr.LineStrips3D(np.stack([B, P], axis=1), colors=color, radii=1.5))
    rec.log(f"{path}/platform", rr.LineStrips3D([np.vstack([P, P[:1]])], colors=color, radii=1.0))


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
                    rrb.BarChartView(origin="parameters/identified", name="Identified (um)"),
                    rrb.BarChartView(origin="parameters/injected", name="Injected (um)"),
                    rrb.BarChartView(origin="parameters/difference", name="Identified - injected (um)"),
                    observability_views("observability", "Observability"),
                ),
                rrb.TextDocumentView(origin="summary", name="Summary"),
            ),
            column_shares=[2, 2, 2],
        ),
        collapse_panels=True,
    )


def log_calibration_run(
    rec: rr.RecordingStream,
    *,
    nominal: Hexapod,
    actual: Hexapod | None,
    identified: Hexapod,
    targets: np.ndarray,
    measured: np.ndarray,
    predicted: np.ndarray,
    history: tuple,
    heldout_before: np.ndarray | None,
    heldout_after: np.ndarray | None,
    summary_markdown: str,
) -> None:
    """Log one calibration run.

    Args:
        rec: the recording stream.
        nominal, actual, identified: parameter sets (``actual`` None for a real machine).
        targets: (N, 6) poses the controller intended, mm and rad.
        measured: (N, 6) measured poses.
        predicted: (N, 6) poses the identified model predicts at the commanded lengths.
        history: max dQint per iteration.
        heldout_before, heldout_after: (M, 6) held-out pose errors (reached - target), or None.
        summary_markdown: text of the summary panel.
    """
    rec.log("machine", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log("machine/base_joints", rr.Points3D(nominal.base_joints, radii=3.0, colors=[90, 90, 90]), static=True)
    for k in range(targets.shape[0]):
        rec.set_time("pose", sequence=k)
        _log_machine(rec, "machine/nominal", nominal, targets[k], COLORS["nominal"])
        _log_machine(rec, "machine/actual", actual if actual is not None else identified, measured[k], COLORS["actual"])
        _log_machine(rec, "machine/calibrated", identified, predicted[k], COLORS["calibrated"])
        err = (measured[k, :3] - targets[k, :3]) * 1000.0
        rec.log("machine/error_x1000", rr.Arrows3D(origins=[targets[k, :3]], vectors=[err], colors=[220, 30, 30]))
    for it, v in enumerate(history, start=1):
        rec.set_time("iteration", sequence=it)
        rec.log("calibration/max_dqint", rr.Scalars(v))
    if heldout_before is not None and heldout_after is not None:
        rec.log("heldout/position_error_um", rr.SeriesLines(names=["before", "after"]), static=True)
        for k in range(heldout_before.shape[0]):
            rec.set_time("heldout_pose", sequence=k)
            for name, e in (("before", heldout_before[k]), ("after", heldout_after[k])):
                rec.log(f"heldout/position_error_um/{name}", rr.Scalars(1000.0 * np.linalg.norm(e[:3])))
                rec.log(f"heldout/orientation_error_urad/{name}", rr.Scalars(1e6 * np.linalg.norm(e[3:])))
    names = [n for n, _, _ in parameter_table()]
    rec.log("parameters/names", rr.TextDocument(", ".join(names)), static=True)
    rec.log("parameters/identified", rr.BarChart(1000.0 * identified.vector), static=True)
    if actual is not None:
        rec.log("parameters/injected", rr.BarChart(1000.0 * actual.vector), static=True)
        rec.log("parameters/difference", rr.BarChart(1000.0 * (identified.vector - actual.vector)), static=True)
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
