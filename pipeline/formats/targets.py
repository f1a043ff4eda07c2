"""Target files: the poses a machine is to be commanded to, in order (``pipeline.compensate``).

A CSV with the robot's pose columns (``x_mm, y_mm, z_mm, alpha_rad, beta_rad, gamma_rad`` for the
hexapod: the recording's pose columns), optionally ``t_s`` (the time of each target since the
machine started, as in a recording: what drift and warm-up compensation follow) and other numeric
columns (recorded channels, such as ``temperature_C``, that a kept law follows; a pose or joint
column of another robot's recordings is refused by name: targets of another machine). Rows are
the order in which the targets are commanded.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib.robot import Robot

from .recording import check_channel_name, columns, csv_rows, finite_number, header_names, read_text_file

__all__ = ["Targets", "read_targets", "TargetsError"]


class TargetsError(ValueError):
    """A target file is malformed; the message names the file, row and column."""


@dataclass(frozen=True, eq=False)
class Targets:
    """Targets read from a file.

    Attributes:
        poses: (N, D) target poses, the robot's pose units, in the file's frame.
        t_s: (N,) times, s, or None when the file has no ``t_s`` column.
        channels: ``{name: (N,)}`` the other columns.
    """

    poses: np.ndarray
    t_s: np.ndarray | None = None
    channels: dict = field(default_factory=dict)


def _not_another_robots(path: Path, name: str, robot: Robot) -> None:
    """Refuse column ``name`` when it is a pose or joint column of a registered robot's recordings
    and not a pose column of ``robot``'s (targets of another machine)."""
    from calib.robots import ROBOTS, default_robot

    own = columns(robot)[1]
    for other in sorted(ROBOTS):
        if other == robot.name:
            continue
        joints, poses = columns(default_robot(other))
        if name in poses:
            raise TargetsError(f"{path}: line 1: column {name!r} is not a pose coordinate of the {robot.name} "
                               f"({', '.join(own)}): it is the {other}'s; are these targets for another machine?")
        if name in joints:
            raise TargetsError(f"{path}: line 1: column {name!r} is a joint column (the {other}'s), not a pose "
                               f"coordinate of the {robot.name} ({', '.join(own)}): a target file holds poses")


def read_targets(path, robot: Robot) -> Targets:
    """Read a target file of ``robot`` (see the module docstring).

    Raises:
        TargetsError: naming the file, and the line, row and column of what is wrong.
    """
    path = Path(path)
    pose_cols = columns(robot)[1]
    rows = csv_rows(path, read_text_file(path, "target file", TargetsError), pose_cols, TargetsError)
    header = header_names(path, rows[0], pose_cols, f"the {robot.name}'s pose columns", TargetsError)
    others = [h for h in header if h not in pose_cols and h != "t_s"]
    for h in others:
        _not_another_robots(path, h, robot)
        try:
            check_channel_name(h, columns(robot))
        except ValueError as exc:
            raise TargetsError(f"{path}: line 1: column {h!r}: {exc}") from None
    data = rows[1:]
    if not data:
        raise TargetsError(f"{path}: no data rows after the header")
    values = np.empty((len(data), len(header)))
    for r, row in enumerate(data, start=1):
        where = f"{path}: row {r} (line {r + 1})"
        if not any(c.strip() for c in row):
            raise TargetsError(f"{where}: blank line inside the data")
        if len(row) != len(header):
            raise TargetsError(f"{where}: expected {len(header)} fields, got {len(row)}")
        values[r - 1] = [finite_number(c.strip(), f"{where}, column {h!r}: {{cell!r}} is", TargetsError)
                         for h, c in zip(header, row)]
    col = {h: values[:, i] for i, h in enumerate(header)}
    t_s = col.get("t_s")
    if t_s is not None and np.any(np.diff(t_s) < 0):
        r = int(np.flatnonzero(np.diff(t_s) < 0)[0]) + 2
        raise TargetsError(f"{path}: row {r} (line {r + 1}), column 't_s': time goes backwards "
                           f"({t_s[r - 1]!r} after {t_s[r - 2]!r}); targets are commanded in the order of the rows")
    return Targets(poses=np.stack([col[c] for c in pose_cols], axis=1), t_s=t_s,
                   channels={h: col[h] for h in others})
