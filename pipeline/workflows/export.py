"""A calibration delivered where it is used, as a library function.

:func:`run_export` does what ``python -m pipeline.export`` does: read the calibration file
(:func:`pipeline.formats.read_calibration`) and hand it to the delivery asked for, from the one
registry of deliveries (:data:`pipeline.deliveries.DELIVERIES`, one module a target:
:mod:`pipeline.deliveries.linuxcnc`, :mod:`pipeline.deliveries.mjcf`,
:mod:`pipeline.deliveries.report`), which ``Calibration.deliver`` uses too.
"""

from __future__ import annotations

from pipeline.deliveries import DELIVERIES, ExportReport, ExportSettings, deliver
from pipeline.formats import read_calibration

__all__ = ["ExportSettings", "ExportReport", "run_export"]


def run_export(settings: ExportSettings) -> ExportReport:
    """Read the calibration file and deliver it (see the module docstring).

    Raises:
        ValueError: an unknown delivery, a bad calibration file (names the file and the key), a
            robot the delivery does not accept.
        FileExistsError: an output exists and ``overwrite`` is off.
    """
    if settings.to not in DELIVERIES:
        raise ValueError(f"--to {settings.to}: unknown format (expected one of {', '.join(DELIVERIES)})")
    cal = read_calibration(settings.calibration)
    return deliver(cal, settings)
