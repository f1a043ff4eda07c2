"""The MuJoCo delivery (``--to mjcf``): the identified machine as a MuJoCo model file
(:mod:`pipeline.simulation.mjcf_export`), the effects MuJoCo can hold built in, the others named
in the file's comment and on stderr. Every robot has a MuJoCo machine (``mjcf.MACHINES``)."""

from __future__ import annotations

from pathlib import Path

from calib.calibration import Calibration
from calib.robots import ROBOTS

from .protocol import Delivery, ExportReport, ExportSettings

__all__ = ["DELIVERY", "write_mjcf"]


def write_mjcf(cal: Calibration, settings: ExportSettings) -> ExportReport:
    """The identified machine as a MuJoCo MJCF file at ``settings.out`` (a file path;
    :func:`pipeline.simulation.mjcf_export.export_mjcf`): the effects MuJoCo can hold built in, the
    others named in the file's comment and here, one line each.

    Raises:
        FileExistsError: the file exists and ``overwrite`` is off.
    """
    from pipeline.simulation.mjcf_export import export_mjcf, identified_machine  # MuJoCo only for this delivery

    path = export_mjcf(cal, settings.out, overwrite=settings.overwrite)
    machine = identified_machine(cal)
    messages = [f"not held by the MuJoCo model: {name} ({why})" for name, why in machine.not_held.items()]
    return ExportReport(format="mjcf", robot=cal.robot.name, paths={Path(path).name: str(path)}, messages=messages,
                        summary={"path": str(path), "held": list(machine.held), "not_held": dict(machine.not_held)})


#: The delivery: every robot (each has its MuJoCo builder, docs/architecture.md's robot recipe).
DELIVERY = Delivery(name="mjcf", robots=tuple(ROBOTS), write=write_mjcf)
