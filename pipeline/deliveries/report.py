"""The report delivery (``--to report``): the HTML report a lab keeps
(:func:`pipeline.report.write_report`), of the run's summary (``--summary``: the report it holds)
or of the calibration file alone (:func:`pipeline.report.calibration.calibration_file_report`)."""

from __future__ import annotations

from pathlib import Path

from calib.calibration import Calibration
from calib.robots import ROBOTS
from pipeline.formats import read_json_file
from pipeline.report import REPORT_KEY, Report, write_report
from pipeline.report.calibration import calibration_file_report

from .protocol import Delivery, ExportReport, ExportSettings

__all__ = ["DELIVERY", "write_lab_report", "summary_report"]


def summary_report(cal: Calibration, path: Path) -> Report:
    """The report a run's or a discovery's summary JSON holds (its :data:`pipeline.report.REPORT_KEY`),
    which must be of the calibration's robot.

    Raises:
        ValueError: a summary that cannot be read, of another robot, or holding no report (the file named).
    """
    summary = read_json_file(path, "summary")
    if not isinstance(summary, dict) or summary.get("robot") != cal.robot.name:
        raise ValueError(f"--summary {path}: not the summary of a {cal.robot.name} run "
                         f"(its robot: {summary.get('robot') if isinstance(summary, dict) else None!r})")
    if not isinstance(summary.get(REPORT_KEY), dict):
        raise ValueError(f"--summary {path}: no '{REPORT_KEY}' (the report a run's --summary-json writes beside its "
                         "keys): write the summary again with pipeline.run --summary-json")
    try:
        return Report.from_dict(summary[REPORT_KEY])
    except (KeyError, TypeError, ValueError, StopIteration) as exc:
        raise ValueError(f"--summary {path}: field '{REPORT_KEY}': not a report ({type(exc).__name__}: {exc})") from None


def write_lab_report(cal: Calibration, settings: ExportSettings) -> ExportReport:
    """The report a lab keeps, one HTML file at ``settings.out`` (:func:`pipeline.report.write_report`),
    of the run's summary (``settings.summary``: :func:`summary_report`) or of the calibration file
    alone (:func:`pipeline.report.calibration.calibration_file_report`).

    Raises:
        ValueError: a summary that cannot be read, is of another robot or holds no report (the file named).
        FileExistsError: the file exists and ``overwrite`` is off.
    """
    report = calibration_file_report(cal) if settings.summary is None else summary_report(cal, Path(settings.summary))
    path = write_report(report, Path(settings.out), overwrite=settings.overwrite)
    return ExportReport(format="report", robot=cal.robot.name, paths={Path(path).name: str(path)}, messages=[],
                        summary={"path": str(path)})


#: The delivery: every robot.
DELIVERY = Delivery(name="report", robots=tuple(ROBOTS), write=write_lab_report)
