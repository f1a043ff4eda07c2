"""What a delivery is: a name, the robots it accepts, and ``write(cal, settings) -> ExportReport``.

A delivery writes a calibration where it is used (a controller's configuration, a MuJoCo model,
the lab's report). It is a :class:`Delivery`, registered once in :mod:`pipeline.deliveries`;
``python -m pipeline.export --to NAME`` and ``Calibration.deliver(NAME, out)`` both find it there.
The controllers' mathematics is in calib (:mod:`calib.linuxcnc`); a delivery writes its files.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

__all__ = ["Delivery", "ExportSettings", "ExportReport"]


@dataclass(frozen=True)
class ExportSettings:
    """What a delivery writes (``python -m pipeline.export --help`` for each field).

    Attributes:
        calibration: the calibration file (as given: a delivery that names it writes it so), or
            None for a calibration made in memory.
        to: the delivery's name (a key of :data:`pipeline.deliveries.DELIVERIES`).
        out: where to write (a folder for ``linuxcnc``).
        overwrite: allow replacing existing files.
        summary: ``report``: the summary JSON of the run that wrote the calibration (its verdict,
            held-out figures and flagged rows), or None (the calibration file alone).
    """

    calibration: Path | None
    to: str
    out: Path
    overwrite: bool = False
    summary: Path | None = None


@dataclass
class ExportReport:
    """What a delivery wrote.

    Attributes:
        format: the delivery's name.
        robot: the robot's name.
        paths: ``{file name: path}`` written.
        messages: what the user must know (what the target cannot hold, with the accuracy given
            up; the projection's residual), one line each, for stderr.
        summary: the delivery's record (``export.json`` for LinuxCNC).
    """

    format: str
    robot: str
    paths: dict = field(default_factory=dict)
    messages: list = field(default_factory=list)
    summary: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Delivery:
    """One target a calibration is delivered to.

    Attributes:
        name: what ``--to`` and ``Calibration.deliver`` call it.
        robots: the robots (``calib.robots.ROBOTS`` names) it accepts; any other is refused in one
            line before anything is written (:func:`pipeline.deliveries.deliver`).
        write: ``write(cal, settings) -> ExportReport``: writes ``cal`` to ``settings.out``
            (atomically; an existing file refused without ``settings.overwrite``).
        refusal: the words refusing a robot it does not accept, after ``--to NAME: ``, with
            ``{robot}``, ``{source}`` (the calibration file) and ``{robots}`` (those it accepts)
            filled in.
        names_its_file: its files name and hash the calibration file, so a calibration made in
            memory is refused (written first, read back).
    """

    name: str
    robots: tuple
    write: Callable = field(repr=False)
    refusal: str = "it does not deliver the {robot} ({source}); it delivers the {robots}"
    names_its_file: bool = False
