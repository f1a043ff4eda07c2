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

import csv
import dataclasses
import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib.measurement import measurement_settings, target_names
from calib.noise import SensorNoise
from calib.robot import Robot
from calib.robots import ROBOTS, robot_from_description

from .outputs import ResultSet

__all__ = ["RecordingError", "Recording", "write_recording", "read_recording", "columns", "recording_texts",
           "sidecar_path", "finite_number", "FORMAT", "FORMAT_VERSION", "SETS", "SIDECAR_FIELDS", "READABLE_VERSIONS",
           "MIN_ROBOT_SIZE_MM"]

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


def recording_texts(rec: Recording) -> tuple[str, str]:
    """The CSV text and the JSON sidecar text of ``rec``."""
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
    return buf.getvalue(), json.dumps(sidecar, indent=1)


def write_recording(csv_path: str | Path, rec: Recording, *, overwrite: bool = False) -> tuple[Path, Path]:
    """Write ``rec`` as ``csv_path`` plus its JSON sidecar, both or neither (see :class:`ResultSet`).

    Returns:
        The paths of the CSV and JSON files.
    """
    csv_path = Path(csv_path)
    json_path = sidecar_path(csv_path)
    csv_text, json_text = recording_texts(rec)
    with ResultSet({"csv": csv_path, "json": json_path}, overwrite=overwrite, create_folders=True) as out:
        out.temp("csv").write_text(csv_text)
        out.temp("json").write_text(json_text)
        out.publish()
    return csv_path, json_path


#: The sidecar's fields; any other is refused (a misspelt key would otherwise be ignored silently).
SIDECAR_FIELDS = ("format", "version", "robot", "units", "columns", "nominal_geometry", "parameter_table",
                  "declared_noise", "meta")
#: Sidecar versions this reader understands.
READABLE_VERSIONS = (1, FORMAT_VERSION)
#: A parallel robot smaller than this (mm) is a geometry written in metres.
MIN_ROBOT_SIZE_MM = 5.0


def _read_text(path: Path, what: str) -> str:
    """The text of ``path`` (UTF-8, a byte-order mark accepted), or a one-line RecordingError."""
    if path.is_dir():
        raise RecordingError(f"{path}: is a folder, not a {what}")
    if not path.exists():
        raise RecordingError(f"{path}: {what} not found")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    if b"\0" in data:
        raise RecordingError(f"{path}: not a text file (it holds NUL bytes): expected a {what}")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise RecordingError(f"{path}: not UTF-8 text (byte {exc.start}): expected a {what}") from None


def _read_sidecar(json_path: Path) -> tuple[Robot, SensorNoise, dict]:
    if not json_path.exists() and not json_path.is_dir():
        raise RecordingError(f"{json_path}: sidecar not found (a recording is a CSV plus a JSON with the same stem)")
    text = _read_text(json_path, "JSON sidecar")
    try:
        side = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RecordingError(f"{json_path}: not valid JSON: {exc}") from None
    if not isinstance(side, dict):
        raise RecordingError(f"{json_path}: top level must be an object, got {type(side).__name__}")
    unknown = [k for k in side if k not in SIDECAR_FIELDS]
    if unknown:
        raise RecordingError(f"{json_path}: unknown field(s) {', '.join(map(repr, unknown))}; "
                             f"the fields are {', '.join(SIDECAR_FIELDS)}")
    for key in ("format", "version", "robot", "units", "nominal_geometry", "declared_noise"):
        if key not in side:
            raise RecordingError(f"{json_path}: missing field {key!r}")
    if side["format"] != FORMAT:
        raise RecordingError(f"{json_path}: field 'format' must be {FORMAT!r}, got {side['format']!r}")
    version = side["version"]
    if isinstance(version, bool) or version not in READABLE_VERSIONS:
        raise RecordingError(f"{json_path}: field 'version' must be one of "
                             f"{', '.join(map(str, READABLE_VERSIONS))}, got {version!r}")
    name = side["robot"]
    if not isinstance(name, str) or name not in ROBOTS:
        raise RecordingError(f"{json_path}: field 'robot' must be one of {', '.join(sorted(ROBOTS))}, got {name!r}")
    units = side["units"]
    if units != UNITS:
        raise RecordingError(f"{json_path}: field 'units' must be {UNITS}, got {units!r}")
    for key in ("nominal_geometry", "declared_noise"):
        if not isinstance(side[key], dict):
            raise RecordingError(f"{json_path}: field {key!r} must be an object, got {type(side[key]).__name__}")
    try:
        robot = robot_from_description(name, side["nominal_geometry"])
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        raise RecordingError(f"{json_path}: field 'nominal_geometry': {exc}") from None
    scale = robot.length_scale_mm
    if not (np.isfinite(scale) and scale >= MIN_ROBOT_SIZE_MM):
        raise RecordingError(f"{json_path}: field 'nominal_geometry' describes a {name} {scale:.3g} mm in "
                             "size: it seems to be in metres; lengths must be in mm")
    fields = {f.name: f.type for f in dataclasses.fields(SensorNoise)}
    for key, value in side["declared_noise"].items():
        if key not in fields:
            raise RecordingError(f"{json_path}: field 'declared_noise': unknown key {key!r}; the keys are "
                                 f"{', '.join(fields)}")
        numeric = key != "distribution"
        if numeric and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise RecordingError(f"{json_path}: field 'declared_noise.{key}' must be a number, got {value!r}")
    try:
        noise = SensorNoise(**side["declared_noise"])
    except (TypeError, ValueError) as exc:
        raise RecordingError(f"{json_path}: field 'declared_noise': {exc}") from None
    meta = side.get("meta", {})
    if not isinstance(meta, dict):
        raise RecordingError(f"{json_path}: field 'meta' must be an object, got {type(meta).__name__}")
    try:
        measurement_settings(meta.get("measurement"))
    except ValueError as exc:
        raise RecordingError(f"{json_path}: field {exc}") from exc
    sim = meta.get("simulation")
    if sim is not None and not isinstance(sim, dict):
        raise RecordingError(f"{json_path}: field 'meta.simulation' must be an object, got {type(sim).__name__}")
    return robot, noise, meta


def _csv_rows(csv_path: Path, text: str, expected: tuple[str, ...]) -> list[list[str]]:
    """The CSV's rows (cells as text), trailing blank lines dropped; at least the header."""
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise RecordingError(f"{csv_path}: not a readable CSV file: {exc}") from None
    while rows and not any(c.strip() for c in rows[-1]):
        rows.pop()  # trailing blank lines
    if not rows:
        raise RecordingError(f"{csv_path}: empty file (expected a header row {', '.join(expected)})")
    return rows


def _header(csv_path: Path, row: list[str], expected: tuple[str, ...], robot: Robot) -> list[str]:
    """The header row's column names, checked: comma-separated, each once, the ``expected``
    columns all there (in any order), nothing else but ``set``."""
    header = [h.strip() for h in row]
    if len(header) == 1 and ";" in header[0]:
        raise RecordingError(f"{csv_path}: line 1: the fields are separated by ';'; a recording is "
                             "comma-separated (t_s,...)")
    if len(header) == 1 and "\t" in header[0]:
        raise RecordingError(f"{csv_path}: line 1: the fields are separated by tabs; a recording is "
                             "comma-separated (t_s,...)")
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise RecordingError(f"{csv_path}: line 1: column(s) {', '.join(dup)} appear more than once")
    missing = [c for c in expected if c not in header]
    if missing:
        raise RecordingError(f"{csv_path}: line 1: header lacks column(s) {', '.join(missing)} "
                             f"(a {robot.name} recording, per its sidecar); got {', '.join(header)}")
    unknown = [h for h in header if h not in expected + ("set",)]
    if unknown:
        raise RecordingError(f"{csv_path}: line 1: unknown column(s) {', '.join(unknown)}")
    return header


def _data_row(where: str, row: list[str], idx: dict[str, int], expected: tuple[str, ...]) -> tuple[list[float], str]:
    """One data row's values (finite numbers, in the ``expected`` columns' order) and its set;
    ``idx``: each column's place in the file; ``where``: how messages name the row."""
    if not any(c.strip() for c in row):
        raise RecordingError(f"{where}: blank line inside the data")
    if len(row) != len(idx):
        raise RecordingError(f"{where}: expected {len(idx)} fields, got {len(row)}")
    values = [finite_number(row[idx[name]].strip(), f"{where}, column {name!r}: {{cell!r}} is",
                            RecordingError) for name in expected]
    s = row[idx["set"]].strip() if "set" in idx else "calibration"
    if s not in SETS:
        raise RecordingError(f"{where}, column 'set': {s!r} is not one of {', '.join(SETS)}")
    return values, s


def finite_number(cell: str, message: str, error: type[Exception] = ValueError) -> float:
    """``float(cell)``, or ``error`` saying what is wrong: ``message`` with ``{cell!r}`` in it, then
    ``not a number`` or ``not finite``."""
    try:
        v = float(cell)
    except ValueError:
        raise error(f"{message.format(cell=cell)} not a number") from None
    if not np.isfinite(v):
        raise error(f"{message.format(cell=cell)} not finite")
    return v


def _data(csv_path: Path, data: list[list[str]], header: list[str],
          expected: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """``(values, sets)``: (N, len(expected)) the data rows' values in the ``expected`` columns'
    order (s, the joint unit, mm and rad) and (N,) str their sets; time must not go backwards
    (a row that repeats an earlier one exactly is named as copied)."""
    idx = {h: i for i, h in enumerate(header)}
    values = np.empty((len(data), len(expected)))
    sets = np.empty(len(data), dtype=object)
    for r, row in enumerate(data, start=1):
        where = f"{csv_path}: row {r} (line {r + 1})"
        values[r - 1], s = _data_row(where, row, idx, expected)
        sets[r - 1] = s
        if r > 1 and values[r - 1, 0] < values[r - 2, 0]:
            same = np.flatnonzero((values[:r - 1] == values[r - 1]).all(axis=1) & (sets[:r - 1] == s))
            if same.size:
                raise RecordingError(f"{where}: repeats row {same[0] + 1} exactly (time included): a copied row; "
                                     "delete it")
            raise RecordingError(f"{where}, column 't_s': time goes backwards "
                                 f"({float(values[r - 1, 0])!r} after {float(values[r - 2, 0])!r}); rows must be in "
                                 "the order taken")
    return values, sets.astype(str)


def read_recording(csv_path: str | Path) -> Recording:
    """Read and validate a recording (CSV + JSON sidecar).

    A UTF-8 byte-order mark, CRLF line ends and trailing blank lines are accepted; columns may be
    in any order (they are found by name).

    Raises:
        RecordingError: naming the file, the row (1-based data row, with its line number) and
            the column of the first problem found.
    """
    csv_path = Path(csv_path)
    if csv_path.is_dir():
        raise RecordingError(f"{csv_path}: is a folder, not a CSV recording")
    if not csv_path.exists():
        raise RecordingError(f"{csv_path}: file not found")
    text = _read_text(csv_path, "CSV recording")
    robot, noise, meta = _read_sidecar(sidecar_path(csv_path))
    joint_cols, pose_cols = columns(robot, measurement_settings(meta.get("measurement")).n_targets)
    expected = ("t_s",) + joint_cols + pose_cols
    rows = _csv_rows(csv_path, text, expected)
    header = _header(csv_path, rows[0], expected, robot)
    if len(rows) == 1:
        raise RecordingError(f"{csv_path}: no data rows (the header alone)")
    values, sets = _data(csv_path, rows[1:], header, expected)
    c = len(joint_cols)
    return Recording(robot=robot, noise=noise, t_s=values[:, 0], joints=values[:, 1:1 + c],
                     measured=values[:, 1 + c:], sets=sets, meta=meta)
