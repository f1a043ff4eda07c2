"""Calibration command files: the poses to measure and the joints the nominal controller commands
for them, a CSV whose header comes from the robot (its pose coordinates with their units, then its
joints with theirs) plus a JSON sidecar describing how they were made."""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path

import numpy as np

from calib.robot import Robot
from calib.robots import ROBOTS, default_robot

from .outputs import atomic_write
from .recording import finite_number, sidecar_path

__all__ = ["TIME_COLUMN", "command_columns", "command_csv", "write_command_rows", "write_command_file",
           "read_command_file"]


def command_columns(robot: Robot) -> tuple[str, ...]:
    """Header of the robot's command file: pose coordinates then joints, each ``name_unit``."""
    return tuple(f"{n}_{u}" for n, u in zip(robot.pose_names, robot.pose_units)) + \
        tuple(f"{n}_{robot.joint_unit}" for n in robot.joint_names)


def _check_rows(robot: Robot, poses, joints) -> tuple[np.ndarray, np.ndarray]:
    poses = np.asarray(poses, dtype=float)
    joints = np.asarray(joints, dtype=float)
    if poses.ndim != 2 or poses.shape[1] != robot.pose_dim:
        raise ValueError(f"poses must have shape (N, {robot.pose_dim}), got {poses.shape}")
    if joints.shape != (poses.shape[0], robot.n_chains):
        raise ValueError(f"joints must have shape {(poses.shape[0], robot.n_chains)}, got {joints.shape}")
    return poses, joints


#: The optional last column of a command file: each command's time since the machine started, s.
TIME_COLUMN = "t_s"


def write_command_rows(file, robot: Robot, poses, joints, t_s=None, extra: dict | None = None) -> None:
    """Write a command file's CSV (full float64 precision) to the open text file ``file``, row by
    row (its size grows as it is written); ``t_s`` (N,) adds the time column; ``extra``
    (``{column: (N,) values}``) columns after it (the commands in a controller's units)."""
    poses, joints = _check_rows(robot, poses, joints)
    extra = extra or {}
    w = csv.writer(file, lineterminator="\n")
    w.writerow(command_columns(robot) + (() if t_s is None else (TIME_COLUMN,)) + tuple(extra))
    rows = np.c_[poses, joints] if t_s is None else np.c_[poses, joints, np.asarray(t_s, dtype=float)]
    if extra:
        rows = np.c_[rows, np.column_stack([np.asarray(v, dtype=float) for v in extra.values()])]
    for row in rows:
        w.writerow([repr(float(v)) for v in row])


def command_csv(robot: Robot, poses, joints, t_s=None, extra: dict | None = None) -> str:
    """CSV text of a command file (:func:`write_command_rows`)."""
    buf = io.StringIO()
    write_command_rows(buf, robot, poses, joints, t_s, extra)
    return buf.getvalue()


def write_command_file(path: str | os.PathLike, robot: Robot, poses, joints, meta: dict, *,
                       overwrite: bool = False) -> tuple[Path, Path]:
    """Write the CSV command file and its JSON sidecar (``path`` with suffix ``.json``).

    Args:
        path: CSV path.
        robot: the robot (gives the columns).
        poses: (N, D) target poses, the robot's pose units.
        joints: (N, C) commanded joints, the robot's joint unit.
        meta: JSON-ready metadata for the sidecar (``robot`` is added).
        overwrite: replace existing files.

    Returns:
        ``(csv_path, json_path)``.

    Raises:
        FileExistsError: a file exists and ``overwrite`` is False (nothing is written).
    """
    text = command_csv(robot, poses, joints)
    path = Path(path)
    side = sidecar_path(path)
    if side == path:
        raise ValueError(f"command file must not have a .json suffix, got {path}")
    for p in (path, side):
        if p.exists() and not overwrite:
            raise FileExistsError(f"{p} exists; pass --overwrite (overwrite=True) to replace it")
    atomic_write(side, json.dumps({"robot": robot.name, **meta}, indent=2) + "\n", overwrite=overwrite)
    atomic_write(path, text, overwrite=overwrite)
    return path, side


def _robot_of_header(path: Path, header: tuple) -> Robot:
    known = {name: default_robot(name) for name in sorted(ROBOTS)}
    for robot in known.values():
        if command_columns(robot) in (header, header[:-1]):
            return robot
    expected = "; ".join(f"{name}: {','.join(command_columns(r))}" for name, r in known.items())
    raise ValueError(f"{path}: line 1: header {','.join(header)} is no registered robot's (expected {expected})")


def read_command_file(path: str | os.PathLike, robot: Robot | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Read a command file.

    Args:
        path: CSV written by :func:`write_command_file` (or by hand, same header).
        robot: the robot whose columns the header must have; default: the registered robot
            whose columns it has.

    Returns:
        ``(poses, joints)``: (N, D) target poses, (N, C) commanded joints, the robot's units.

    Raises:
        ValueError: naming the file, and the row (line number) and column of a bad value, or
            the header.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"command file {path} not found")
    rows = list(csv.reader(path.read_text().splitlines()))
    if not rows:
        kinds = [robot] if robot is not None else [default_robot(name) for name in sorted(ROBOTS)]
        raise ValueError(f"{path}: empty command file, expected a header such as "
                         f"{'; '.join(','.join(command_columns(r)) for r in kinds)}")
    header = tuple(h.strip() for h in rows[0])
    if robot is None:
        robot = _robot_of_header(path, header)
    columns = command_columns(robot)
    if header == columns + (TIME_COLUMN,):  # a compensated command file's times
        columns = header
    if header != columns:
        raise ValueError(f"{path}: line 1: header must be {','.join(columns)} (the {robot.name}'s), "
                         f"got {','.join(header)} (a last column {TIME_COLUMN} is allowed)")
    data = []
    for line, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(columns):
            raise ValueError(f"{path}: line {line}: expected {len(columns)} columns, got {len(row)}")
        data.append([finite_number(cell, f"{path}: line {line}, column {col}: {{cell!r}} is")
                     for col, cell in zip(columns, row)])
    if not data:
        raise ValueError(f"{path}: no data rows after the header")
    a = np.array(data, dtype=float)
    d = robot.pose_dim
    return a[:, :d].copy(), a[:, d:d + robot.n_chains].copy()
