"""The calibration file at pipeline's edge: :mod:`calib.calibration` owns the :class:`Calibration`
and its file (``NAME.calibration.json``, read and written by ``Calibration.read`` and
``Calibration.write``); its names are exported here for the code that reads them from
``pipeline.formats``. :func:`recording_source` (the recording files' hashes a calibration file
names) is pipeline's own: it knows the recording's sidecar.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from calib.calibration import (CALIBRATION_FORMAT, CALIBRATION_SUFFIX, CALIBRATION_VERSION, Calibration,
                               CalibrationFileError, calibration_text, read_calibration, validity_domain,
                               write_calibration)

from .recording import sidecar_path

__all__ = ["CALIBRATION_FORMAT", "CALIBRATION_VERSION", "CALIBRATION_SUFFIX", "Calibration", "CalibrationFileError",
           "write_calibration", "read_calibration", "calibration_text", "recording_source", "validity_domain"]


def recording_source(csv_path) -> dict:
    """``{"name", "sha256", "sidecar_sha256"}`` of a recording's files (the sidecar's hash None
    when it has none)."""
    csv_path = Path(csv_path)
    side = sidecar_path(csv_path)
    return {"name": csv_path.name, "sha256": hashlib.sha256(csv_path.read_bytes()).hexdigest(),
            "sidecar_sha256": hashlib.sha256(side.read_bytes()).hexdigest() if side.is_file() else None}
