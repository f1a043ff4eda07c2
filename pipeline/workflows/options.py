"""Settings the tools share: where the many-task tools (pose design, Monte Carlo study) run and
what they write, and the bounds of the simulated sensor noise (``--noise-mm``, ``--noise-rad``,
``--noise-joint`` of the run, the study and the design)."""

from __future__ import annotations

from dataclasses import dataclass

from calib.noise import SensorNoise
from calib.robot import Robot

__all__ = ["ToolOptions", "noise_limits", "check_noise_flags"]


@dataclass(frozen=True, kw_only=True)
class ToolOptions:
    """Where a tool runs and what it writes.

    Attributes:
        workers: processes of the local Dask cluster (None: the cores; 1: here, no cluster).
        scheduler: address of an existing Dask scheduler instead of a local cluster.
        geometry: a robot description JSON (``Robot.description()``) instead of the registered
            robot's default machine.
        summary_json, rrd: where to write the summary and the Rerun file (None: not written).
        overwrite: allow replacing existing outputs.
    """

    workers: int | None = None
    scheduler: str | None = None
    geometry: str | None = None
    summary_json: str | None = None
    rrd: str | None = None
    overwrite: bool = False


def noise_limits(robot: Robot) -> dict:
    """``{flag: (largest value, unit, why)}`` of the noise flags on ``robot``.

    A noise is refused where the values it gives could not be a measurement of the machine: the
    bounds a recording's values are checked against (:mod:`pipeline.formats.checks`). Positions:
    :data:`~pipeline.formats.checks.REACH_FACTOR` times the robot's size (a position beyond is
    refused as far beyond any workspace; 12,166 mm on the hexapod, 26,000 mm on the Delta: a
    noise of 1000 mm, which drowns the geometry and is answered so, still fits). Angles:
    :data:`~pipeline.formats.checks.MAX_ANGLE_RAD` (beyond it a value is no angle in rad).
    Joints: the smallest range a joint travels (``Robot.joint_limits``), read past by a few per
    cent at most: a reading noisier than the joint's whole range cannot tell where it is. The
    bounds stand ten orders of magnitude below where the fits' squares overflow (1e154).
    """
    from pipeline.formats.checks import MAX_ANGLE_RAD, REACH_FACTOR

    limits = robot.joint_limits()
    size, span = robot.length_scale_mm, float((limits[:, 1] - limits[:, 0]).min())
    return {"--noise-mm": (REACH_FACTOR * size, "mm", f"{REACH_FACTOR:g} times the {robot.name}'s size, {size:.4g} "
                                                      "mm: a position beyond is far beyond any workspace"),
            "--noise-rad": (MAX_ANGLE_RAD, "rad", "2 pi: beyond it a value is no angle"),
            "--noise-joint": (span, robot.joint_unit, f"the {robot.name}'s smallest joint range: a reading noisier "
                                                      "than its whole range cannot tell where the joint is")}


def check_noise_flags(robot: Robot, noise: SensorNoise) -> None:
    """Refuse, naming the flag and the range that fits, a noise beyond :func:`noise_limits`.

    Raises:
        ValueError: ``--noise-mm 1e+300: a sensor noise of 1e+300 mm is no measurement of the
            hexapod; between 0 and 1.217e+04 mm would fit (100 times ...)``.
    """
    values = {"--noise-mm": noise.position_mm, "--noise-rad": noise.orientation_rad, "--noise-joint": noise.joint}
    for flag, (limit, unit, why) in noise_limits(robot).items():
        if values[flag] > limit:
            raise ValueError(f"{flag} {values[flag]:g}: a sensor noise of {values[flag]:g} {unit} is no measurement "
                             f"of the {robot.name}; between 0 and {limit:.4g} {unit} would fit ({why})")
