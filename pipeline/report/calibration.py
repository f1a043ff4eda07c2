"""The report of a calibration run (``python -m pipeline.run``): its sections made from the run's
objects, its files and timing once they are known."""

from __future__ import annotations

from dataclasses import replace

from .model import OUTPUT_KEYS, Outputs, Report, Timing

__all__ = ["finished_report", "outputs_of"]


def outputs_of(paths: dict) -> Outputs:
    """The files a run wrote, ``paths`` by summary key (:data:`~pipeline.report.model.OUTPUT_KEYS`, in their order)."""
    return Outputs(files=tuple((k, str(paths[k])) for k in OUTPUT_KEYS if paths.get(k)))


def finished_report(report: Report, paths: dict, wall_time_s: float, split: dict) -> Report:
    """``report`` with the files the run wrote (``paths`` by summary key; ``suggested_poses`` the
    suggested poses' file) and its wall time, in total and by stage (``split``, s)."""
    determination = report.determination
    if determination is not None and determination.suggested is not None and paths.get("suggested_poses"):
        determination = replace(determination,
                                suggested=replace(determination.suggested, path=str(paths["suggested_poses"])))
    return replace(report, determination=determination, outputs=outputs_of(paths),
                   timing=Timing(float(wall_time_s), tuple((k, float(v)) for k, v in split.items())))
