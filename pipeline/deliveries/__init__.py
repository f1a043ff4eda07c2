"""The deliveries of a calibration, in one registry: :data:`DELIVERIES`.

A delivery (:class:`Delivery`: a name, the robots it accepts, ``write(cal, settings) ->
ExportReport``) writes a calibration where it is used. ``python -m pipeline.export --to NAME``
offers the names of :data:`DELIVERIES` and runs :func:`deliver`; ``Calibration.deliver(NAME,
out)`` (and ``to_linuxcnc``, ``to_mjcf``, ``report``) looks this package up by name when it is
called (calib imports nothing of pipeline) and runs :func:`deliver_calibration`. Both refuse a
robot the delivery does not accept in one line, before anything is written.

One module a target: :mod:`.linuxcnc` (LinuxCNC's kinematics, INI and compensation tables),
:mod:`.mjcf` (the identified MuJoCo machine), :mod:`.report` (the lab's HTML report), each
holding its ``DELIVERY``. The next target (a controller: a Klipper configuration of a linear
Delta printer) is one more module here holding its ``DELIVERY``, named in
:data:`TARGET_MODULES`; its mathematics (a fit onto the controller's kinematics, its tables)
goes in calib, as :mod:`calib.linuxcnc` does for LinuxCNC. A package outside the project
registers its own with :func:`register`, once, and both front ends see it.
"""

from __future__ import annotations

from pathlib import Path

from . import klipper, linuxcnc, mjcf, report
from .protocol import Delivery, ExportReport, ExportSettings

__all__ = ["Delivery", "ExportSettings", "ExportReport", "DELIVERIES", "TARGET_MODULES", "register", "delivery",
           "deliver", "deliver_calibration"]

#: The deliveries by name, in the order ``pipeline.export --help`` offers them.
DELIVERIES: dict[str, Delivery] = {}
#: The project's target modules, each holding its ``DELIVERY``: registered when this package is imported.
TARGET_MODULES = (linuxcnc, klipper, mjcf, report)


def register(target: Delivery) -> Delivery:
    """Register ``target`` under its name (one registered again under a name is replaced);
    returns it.

    Raises:
        ValueError: its name is not a non-empty string, its robots not a tuple of names, or its
            ``write`` not callable.
    """
    if not isinstance(target.name, str) or not target.name:
        raise ValueError(f"a delivery's name must be a non-empty string, got {target.name!r}")
    if not isinstance(target.robots, tuple) or not all(isinstance(r, str) for r in target.robots):
        raise ValueError(f"delivery {target.name!r}: its robots must be a tuple of robot names, got {target.robots!r}")
    if not callable(target.write):
        raise ValueError(f"delivery {target.name!r}: write must be callable, got {type(target.write).__name__}")
    DELIVERIES[target.name] = target
    return target


def delivery(name: str) -> Delivery:
    """The delivery registered as ``name``.

    Raises:
        ValueError: no delivery ``name`` (the message names it and the ones registered).
    """
    if name not in DELIVERIES:
        raise ValueError(f"no delivery {name!r} is registered (installed: {', '.join(DELIVERIES) or 'none'}); a "
                         "delivery is a module of pipeline/deliveries/ or registered with pipeline.deliveries.register")
    return DELIVERIES[name]


def deliver(cal, settings: ExportSettings) -> ExportReport:
    """Write ``cal`` with the delivery ``settings.to`` (its report).

    Raises:
        ValueError: no such delivery; a calibration made in memory where the delivery names its
            file; a robot the delivery does not accept (its one line); what the delivery refuses.
        FileExistsError: an output exists and ``settings.overwrite`` is off.
    """
    target = delivery(settings.to)
    if target.names_its_file and settings.calibration is None:
        raise ValueError(f"--to {target.name}: the calibration was made in memory; its export names and hashes the "
                         "calibration file: write it (cal.write(path)) and read it back (Calibration.read(path))")
    if cal.robot.name not in target.robots:
        words = target.refusal.format(robot=cal.robot.name, source=settings.calibration, robots=", ".join(target.robots))
        raise ValueError(f"--to {target.name}: {words}")
    return target.write(cal, settings)


def deliver_calibration(cal, to: str, out, *, overwrite: bool = False) -> ExportReport:
    """What ``Calibration.deliver(to, out)`` does: :func:`deliver` of ``cal`` (its file, where it
    was read from one) to ``out``, the files ``python -m pipeline.export --calibration cal.source
    --to TO --out OUT`` writes."""
    return deliver(cal, ExportSettings(calibration=cal.source, to=to, out=Path(out), overwrite=overwrite))


for _module in TARGET_MODULES:
    register(_module.DELIVERY)
