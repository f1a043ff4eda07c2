"""The Rerun view of a pose design (rerun-sdk 0.41 API): the observability of the designed poses
(beside the robot's reference poses where it has them), the poses in 3D and the predicted
position uncertainty after calibration over the workspace."""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from calib.robot import Robot

from .charts import application_id, save_recording
from .observability import log_observability, observability_views

__all__ = ["write_design_rrd", "position_columns"]


def position_columns(robot: Robot, poses: np.ndarray) -> np.ndarray:
    """(N, 3) the position (mm) coordinates of poses, for drawing."""
    return np.asarray(poses)[:, ~robot.angle_pose_mask][:, :3]


def write_design_rrd(path: str, robot: Robot, analysis, reference, poses: np.ndarray, probe,
                     overwrite: bool) -> None:
    """The design's ``.rrd``: ``analysis`` (the designed poses' observability) beside ``reference``
    (the reference poses', or None), ``poses`` (N, D) and ``probe``: ``(probe_poses (M, D),
    predicted position RMS (M,) mm)``."""
    views = [observability_views("design/observability", "Designed poses", per_parameter=True)]
    if reference is not None:
        views.append(observability_views("reference_poses/observability", "Reference poses", per_parameter=True))
    bp = rrb.Blueprint(rrb.Horizontal(
        rrb.Vertical(
            rrb.Spatial3DView(origin="design/poses", name="Designed pose positions (mm)"),
            rrb.Spatial3DView(origin="design/pose_uncertainty",
                              name="Predicted position error RMS after calibration (radius, um)"),
        ), *views), collapse_panels=True)

    def log(rec):
        rec.log("design/poses", rr.Points3D(position_columns(robot, poses), radii=2.0), static=True)
        probe_poses, pos_rms = probe
        # Radius in mm drawn as the predicted RMS position error in um (1 um -> 1 mm sphere).
        rec.log("design/pose_uncertainty", rr.Points3D(position_columns(robot, probe_poses), radii=pos_rms * 1e3,
                                                      labels=[f"{v * 1e3:.2f} um" for v in pos_rms]), static=True)
        log_observability(rec, analysis, "design/observability", title=f"Designed poses ({robot.name})")
        if reference is not None:
            log_observability(rec, reference, "reference_poses/observability",
                              title=f"Reference poses ({robot.name})")

    try:
        save_recording(path, log, application_id=application_id("design", robot.name), overwrite=overwrite, bp=bp)
    except FileExistsError as exc:
        raise SystemExit(str(exc)) from None
