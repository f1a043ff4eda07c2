"""The report delivery (``--to report``): the HTML report a lab keeps
(:func:`pipeline.formats.write_report`), of the run's summary (``--summary``) or of the
calibration file alone (:func:`calibration_summary`)."""

from __future__ import annotations

from pathlib import Path

from calib.calibration import Calibration
from calib.measurement import frame_to_dict
from calib.robots import ROBOTS
from pipeline.formats import read_json_file
from pipeline.report import write_report

from .protocol import Delivery, ExportReport, ExportSettings

__all__ = ["DELIVERY", "write_lab_report", "calibration_summary"]


def calibration_summary(cal: Calibration) -> dict:
    """The summary keys a report reads, from a calibration file alone: the machine, the recording,
    every identified parameter with its standard uncertainty, the instrument frames, the declared
    noise. The verdict says the rest (held-out figures, flagged rows) belongs to the run's summary."""
    table = cal.robot.table
    free = set(cal.free)
    det = {n: {"value": float(cal.theta[k]), "error": float(cal.theta[k] - table.nominal[k]), "unit": table.units[k],
               "posterior_std": float(cal.std[k]), "prior_std": None, "source": None if n in free else "held"}
           for k, n in enumerate(table.names)}
    summary = {"robot": cal.robot.name, "scenario": str(cal.recording.get("name") or cal.recording.get("simulated") or ""),
               "success": None, "parameter_determination": det, "free_parameters": list(cal.free),
               "declared_noise": cal.noise.to_dict(), "prior": {"source": "not stated in the calibration file"},
               "verdict": {"words": "from the calibration file alone: its verdict, held-out figures and flagged rows "
                                    "are in the summary of the run that wrote it (pipeline.export --summary S.json)"}}
    if cal.frames:
        summary["measurement_frames"] = {s: frame_to_dict(f) for s, f in cal.frames.items()}
    return summary


def write_lab_report(cal: Calibration, settings: ExportSettings) -> ExportReport:
    """The report a lab keeps, one HTML file at ``settings.out``
    (:func:`pipeline.formats.write_report`), of the run's summary (``settings.summary``, which must
    be of the calibration's robot) or of the calibration file alone (:func:`calibration_summary`).

    Raises:
        ValueError: a summary that cannot be read or is of another robot (the file named).
        FileExistsError: the file exists and ``overwrite`` is off.
    """
    if settings.summary is None:
        summary = calibration_summary(cal)
    else:
        summary = read_json_file(Path(settings.summary), "summary")
        if not isinstance(summary, dict) or summary.get("robot") != cal.robot.name:
            raise ValueError(f"--summary {settings.summary}: not the summary of a {cal.robot.name} run "
                             f"(its robot: {summary.get('robot') if isinstance(summary, dict) else None!r})")
    path = write_report(summary, Path(settings.out), overwrite=settings.overwrite)
    return ExportReport(format="report", robot=cal.robot.name, paths={Path(path).name: str(path)}, messages=[],
                        summary={"path": str(path)})


#: The delivery: every robot.
DELIVERY = Delivery(name="report", robots=tuple(ROBOTS), write=write_lab_report)
