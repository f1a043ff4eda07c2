"""The calibration file at pipeline's edge: :mod:`calib.calibration` owns the :class:`Calibration`
and its file (``NAME.calibration.json``, read and written by ``Calibration.read`` and
``Calibration.write``); its names are exported here for the code that reads them from
``pipeline.formats``. :func:`recording_source` (the recording files' hashes a calibration file
names) is pipeline's own: it knows the recording's sidecar.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from calib.calibration import (CALIBRATION_FORMAT, CALIBRATION_SUFFIX, CALIBRATION_VERSION, Calibration,
                               CalibrationFileError, calibration_text, read_calibration, validity_domain,
                               write_calibration)

from .recording import sidecar_path

__all__ = ["CALIBRATION_FORMAT", "CALIBRATION_VERSION", "CALIBRATION_SUFFIX", "Calibration", "CalibrationFileError",
           "write_calibration", "read_calibration", "calibration_text", "recording_source", "validity_domain",
           "check_plausible_parameters", "ABSURD_TOLERANCES"]

#: An identified parameter further from nominal than this many of the robot's manufacturing
#: tolerances (``default_parameter_tolerance``), or than the robot's size (``length_scale_mm``;
#: pi for an angle), is absurd: no calibration of a machine of this description gives it (a
#: capture body mounted 2 degrees off moves the platform joints 50 tolerances; a 6-RUS motor read
#: backwards turns its axis by pi, 600).
ABSURD_TOLERANCES = 1000.0


def recording_source(csv_path) -> dict:
    """``{"name", "sha256", "sidecar_sha256"}`` of a recording's files (the sidecar's hash None
    when it has none)."""
    csv_path = Path(csv_path)
    side = sidecar_path(csv_path)
    return {"name": csv_path.name, "sha256": hashlib.sha256(csv_path.read_bytes()).hexdigest(),
            "sidecar_sha256": hashlib.sha256(side.read_bytes()).hexdigest() if side.is_file() else None}


def check_plausible_parameters(cal: Calibration, path) -> None:
    """Refuse a calibration whose identified parameter is absurdly far from nominal: beyond
    :data:`ABSURD_TOLERANCES` of the robot's manufacturing tolerance, or beyond the robot's size
    (``length_scale_mm``; pi for an angle), whatever its standard deviation in the file.

    Raises:
        CalibrationFileError: naming the file, the parameter, its offset, its std and the limit.
    """
    from calib.prior import ParameterPrior

    robot = cal.robot
    table = robot.table
    tol = ParameterPrior.from_tolerance(robot).std
    offset = np.abs(cal.theta - table.nominal)
    angle = np.array([u == "rad" for u in table.units])
    size = np.where(angle, np.pi, robot.length_scale_mm)
    limit = np.minimum(ABSURD_TOLERANCES * tol, size)
    bad = ~(offset <= limit)
    if not bad.any():
        return
    k = int(np.argmax(np.where(bad, offset / limit, -np.inf)))
    unit, name = table.units[k], table.names[k]
    beyond = (f"{ABSURD_TOLERANCES:.0f} tolerances ({limit[k]:.4g} {unit})" if limit[k] < size[k] else
              ("pi rad" if angle[k] else f"the {robot.name}'s own size ({size[k]:.4g} mm)"))
    raise CalibrationFileError(
        f"{path}: parameter {name}: identified {cal.theta[k]:.6g} {unit}, {cal.theta[k] - table.nominal[k]:+.4g} "
        f"{unit} from nominal ({offset[k] / tol[k]:.3g} times the {robot.name}'s tolerance {tol[k]:.3g} {unit}; its "
        f"std in the file {cal.std[k]:.3g} {unit}): beyond {beyond}, no machine of this description: the "
        "calibration file's parameter is implausible (recalibrate, or check the recording it came from)")
