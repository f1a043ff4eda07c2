"""Measurement recordings on disk, the same format for every robot: a CSV plus a JSON sidecar.

CSV: one row per measurement in the order taken, columns

    t_s, <joints>, <pose>[, set]

with the robot's joint columns (``l1_mm .. l6_mm`` for the hexapod, ``q1_rad .. q3_rad`` for
the Delta: what was commanded, or read when joints are measured) and pose columns (``x_mm, y_mm,
z_mm[, alpha_rad, beta_rad, gamma_rad]``: the measured pose, base frame, or the instrument's
frame with ``meta.measurement``; position-only data have ``t1_x_mm, t1_y_mm, t1_z_mm, t2_x_mm ...``
instead, one triple per target, see :mod:`calib.measurement`); the optional ``set``
column is ``calibration`` or ``validation`` (default ``calibration``). The JSON sidecar names the
robot, its nominal geometry and parameter table, the declared noise and the units.

Reading validates everything and names file, row and column on error; writing is atomic
(temporary file + rename) and never overwrites an existing file unless asked to.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib.measurement import measurement_settings, target_names
from calib.noise import SensorNoise
from calib.robot import Robot
from calib.robots import ROBOTS, robot_from_description

__all__ = ["RecordingError", "Recording", "write_recording", "read_recording", "columns",
           "atomic_write", "publish", "writing", "sidecar_path", "FORMAT", "FORMAT_VERSION"]

SETS = ("calibration", "validation")
FORMAT = "parallel-calib recording"
#: Version 2: any robot (joint and pose columns from the robot, parameter table in the sidecar);
#: version 1 (hexapod only) is read too.
FORMAT_VERSION = 2
UNITS = {"length": "mm", "angle": "rad", "time": "s"}


class RecordingError(ValueError):
    """A recording file is malformed; the message names file, row and column."""


def columns(robot: Robot, n_targets: int = 0) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``(joint_columns, pose_columns)`` of a robot's recordings, e.g. ``("l1_mm", ...)``; with
    ``n_targets`` the target columns ``t1_x_mm ...`` stand for the pose columns."""
    joints = tuple(f"{n}_{robot.joint_unit}" for n in robot.joint_names)
    pose = tuple(f"{n}_{u}" for n, u in zip(robot.pose_names, robot.pose_units)) if n_targets == 0 else \
        tuple(f"{n}_mm" for n in target_names(n_targets))
    return joints, pose


@dataclass(frozen=True, eq=False)
class Recording:
    """Measurements of a robot and what is needed to analyse them.

    Attributes:
        robot: the robot measured, with its nominal geometry.
        noise: declared noise.
        t_s: (N,) time of each measurement, s, non-decreasing.
        joints: (N, C) commanded (or read) joint values, the robot's joint unit.
        measured: (N, D) measured poses, mm and rad, base frame (or the instrument's frame, or
            (N, 3K) target positions: ``meta["measurement"]``, see :mod:`calib.measurement`).
        sets: (N,) str, ``"calibration"`` or ``"validation"``.
        meta: free-form JSON-ready information (scenario, seed, simulation truth...).
    """

    robot: Robot
    noise: SensorNoise
    t_s: np.ndarray
    joints: np.ndarray
    measured: np.ndarray
    sets: np.ndarray
    meta: dict = field(default_factory=dict)

    def subset(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(joints, measured)`` of the rows in set ``name``."""
        mask = self.sets == name
        return self.joints[mask], self.measured[mask]

    def rows(self, name: str) -> np.ndarray:
        """0-based indices of the rows in set ``name``."""
        return np.flatnonzero(self.sets == name)


def sidecar_path(csv_path: str | Path) -> Path:
    """The JSON sidecar of a CSV recording."""
    return Path(csv_path).with_suffix(".json")


def _exists_message(path: Path) -> str:
    return f"{path} exists; pass --overwrite to replace it (refusing to overwrite it silently)"


def publish(tmp: str | Path, path: str | Path, *, overwrite: bool = False) -> None:
    """Move a finished temporary file into place with ordinary permissions.

    Without ``overwrite`` the move is a hard link, which fails if ``path`` appeared in the
    meantime: an existing file is never silently replaced.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    path = Path(path)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600
    if overwrite:
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise FileExistsError(_exists_message(path)) from None
    except OSError:  # a file system without hard links
        if path.exists():
            raise FileExistsError(_exists_message(path)) from None
        os.replace(tmp, path)
    else:
        os.unlink(tmp)


@contextlib.contextmanager
def writing(path: str | Path, *, overwrite: bool = False):
    """Yield a temporary path beside ``path``; when the block succeeds, :func:`publish` it there.

    Nothing is left behind on failure, and an existing file is refused up front.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(_exists_message(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        yield Path(tmp)
        publish(tmp, path, overwrite=overwrite)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def atomic_write(path: str | Path, data: str | bytes, *, overwrite: bool = False) -> Path:
    """Write text or bytes to ``path`` atomically (see :func:`writing`).

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    with writing(path, overwrite=overwrite) as tmp:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)
    return Path(path)


def write_recording(csv_path: str | Path, rec: Recording, *, overwrite: bool = False) -> tuple[Path, Path]:
    """Write ``rec`` as ``csv_path`` plus its JSON sidecar.

    Both files are checked before either is written, so that nothing is half-replaced.

    Returns:
        The paths of the CSV and JSON files.
    """
    csv_path = Path(csv_path)
    json_path = sidecar_path(csv_path)
    if not overwrite:
        for p in (csv_path, json_path):
            if p.exists():
                raise FileExistsError(_exists_message(p))
    joint_cols, pose_cols = columns(rec.robot, measurement_settings(rec.meta.get("measurement")).n_targets)
    header = ("t_s",) + joint_cols + pose_cols + ("set",)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for k in range(len(rec.t_s)):
        w.writerow([repr(float(rec.t_s[k]))] + [repr(float(v)) for v in rec.joints[k]]
                   + [repr(float(v)) for v in rec.measured[k]] + [rec.sets[k]])
    table = rec.robot.table
    sidecar = {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "robot": rec.robot.name,
        "units": UNITS,
        "columns": list(header),
        "nominal_geometry": rec.robot.description(),
        "parameter_table": [{"name": p.name, "unit": p.unit, "nominal": p.nominal, "chain": p.chain + 1}
                            for p in table],
        "declared_noise": rec.noise.to_dict(),
        "meta": rec.meta,
    }
    atomic_write(csv_path, buf.getvalue(), overwrite=overwrite)
    atomic_write(json_path, json.dumps(sidecar, indent=1), overwrite=overwrite)
    return csv_path, json_path


def _read_sidecar(json_path: Path) -> tuple[Robot, SensorNoise, dict]:
    if not json_path.exists():
        raise RecordingError(f"{json_path}: sidecar not found (a recording is a CSV plus a JSON with the same stem)")
    try:
        side = json.loads(json_path.read_text())
    except json.JSONDecodeError as exc:
        raise RecordingError(f"{json_path}: not valid JSON: {exc}") from exc
    if not isinstance(side, dict):
        raise RecordingError(f"{json_path}: top level must be an object")
    name = side.get("robot")
    if name not in ROBOTS:
        raise RecordingError(f"{json_path}: field 'robot' must be one of {', '.join(sorted(ROBOTS))}, got {name!r}")
    units = side.get("units")
    if units != UNITS:
        raise RecordingError(f"{json_path}: field 'units' must be {UNITS}, got {units!r}")
    for key in ("nominal_geometry", "declared_noise"):
        if key not in side:
            raise RecordingError(f"{json_path}: missing field {key!r}")
    try:
        robot = robot_from_description(name, side["nominal_geometry"])
    except (KeyError, ValueError, TypeError) as exc:
        raise RecordingError(f"{json_path}: field 'nominal_geometry': {exc}") from exc
    try:
        noise = SensorNoise(**side["declared_noise"])
    except (TypeError, ValueError) as exc:
        raise RecordingError(f"{json_path}: field 'declared_noise': {exc}") from exc
    meta = side.get("meta", {})
    if not isinstance(meta, dict):
        raise RecordingError(f"{json_path}: field 'meta' must be an object, got {type(meta).__name__}")
    try:
        measurement_settings(meta.get("measurement"))
    except ValueError as exc:
        raise RecordingError(f"{json_path}: field {exc}") from exc
    return robot, noise, meta


def read_recording(csv_path: str | Path) -> Recording:
    """Read and validate a recording (CSV + JSON sidecar).

    Raises:
        RecordingError: naming the file, the row (1-based data row, with its line number) and
            the column of the first problem found.
    """
    csv_path = Path(csv_path)
    if not csv_path.exists():
        raise RecordingError(f"{csv_path}: file not found")
    robot, noise, meta = _read_sidecar(sidecar_path(csv_path))
    joint_cols, pose_cols = columns(robot, measurement_settings(meta.get("measurement")).n_targets)
    expected = ("t_s",) + joint_cols + pose_cols
    with csv_path.open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise RecordingError(f"{csv_path}: empty file (expected a header row {', '.join(expected)})")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in expected if c not in header]
    if missing:
        raise RecordingError(f"{csv_path}: header lacks column(s) {', '.join(missing)}; got {', '.join(header)}")
    unknown = [h for h in header if h not in expected + ("set",)]
    if unknown:
        raise RecordingError(f"{csv_path}: unknown column(s) {', '.join(unknown)}")
    idx = {h: i for i, h in enumerate(header)}
    data = rows[1:]
    if not data:
        raise RecordingError(f"{csv_path}: no data rows")
    values = np.empty((len(data), len(expected)))
    sets = np.empty(len(data), dtype=object)
    for r, row in enumerate(data, start=1):
        where = f"{csv_path}: row {r} (line {r + 1})"
        if len(row) != len(header):
            raise RecordingError(f"{where}: expected {len(header)} fields, got {len(row)}")
        for c, name in enumerate(expected):
            cell = row[idx[name]].strip()
            try:
                v = float(cell)
            except ValueError:
                raise RecordingError(f"{where}, column {name!r}: {cell!r} is not a number") from None
            if not np.isfinite(v):
                raise RecordingError(f"{where}, column {name!r}: {cell!r} is not finite")
            values[r - 1, c] = v
        s = row[idx["set"]].strip() if "set" in idx else "calibration"
        if s not in SETS:
            raise RecordingError(f"{where}, column 'set': {s!r} is not one of {', '.join(SETS)}")
        sets[r - 1] = s
        if r > 1 and values[r - 1, 0] < values[r - 2, 0]:
            raise RecordingError(f"{where}, column 't_s': time goes backwards "
                                 f"({values[r - 1, 0]!r} after {values[r - 2, 0]!r}); rows must be in the order taken")
    sets = sets.astype(str)
    c = len(joint_cols)
    return Recording(robot=robot, noise=noise, t_s=values[:, 0], joints=values[:, 1:1 + c],
                     measured=values[:, 1 + c:], sets=sets, meta=meta)
