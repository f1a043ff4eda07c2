"""A lab's own export (CSV files in its units and conventions) read through a mapping file (TOML)
into a :class:`~pipeline.formats.recording.Recording`.

The map says which lab column is which joint and pose coordinate and how to convert it:

* ``[robot]`` ``name`` (a registered robot), ``description`` (optional: a ``Robot.description()``
  JSON, or a recording's or command file's sidecar, whose ``nominal_geometry`` is taken; a path
  relative to the map), ``tolerance`` (optional: the machine's manufacturing tolerance, one
  standard deviation, as a table by unit ``{mm = 2.0, rad = 0.02}`` and/or by parameter name
  ``{"B3.y" = 5.0}``; written as the sidecar's ``meta.parameter_tolerance``, the run's prior);
* ``[noise]`` (optional) the declared noise, the keys of a recording's ``declared_noise``;
* ``[csv]`` (optional) ``delimiter`` (one character), ``decimal`` (``"."`` or ``","``),
  ``skip_lines`` (lines before the header line);
* ``[time]`` ``format`` ``"seconds"`` | ``"iso"`` (ISO 8601 timestamps) | ``"none"`` (rows in
  order: ``t_s`` = 0, 1, 2, ...), ``column``, ``unit`` (``"s"`` | ``"ms"``, seconds),
  ``origin`` (iso: an ISO timestamp, default the session's first kept row; seconds: a number,
  default 0): ``t_s`` is the time since the origin;
* ``[position]`` ``columns`` (x, y, z), ``unit`` (``"m"`` | ``"mm"`` | ``"in"``), ``offset``
  (optional ``[x, y, z]``, mm: added to every position after the unit conversion);
* ``[orientation]`` (robots whose pose has angles) ``kind`` ``"quaternion"`` (``scalar``
  ``"first"`` | ``"last"``) | ``"matrix"`` (9 columns, ``order`` ``"row"`` (R11 R12 R13 R21 ...) |
  ``"column"``) | ``"euler"`` (``sequence``: SciPy's, lowercase = fixed axes, uppercase = moving
  axes; the project's own is ``"xyz"``; ``unit`` ``"rad"`` | ``"deg"``), ``columns``; ``rotation``
  ``"platform_to_instrument"`` (default: the rotation maps platform-frame vectors to the
  instrument's frame) | ``"instrument_to_platform"`` (the inverse: a quaternion's conjugate);
* ``[joints]`` ``columns`` (one per chain), ``reading`` ``"value"`` | ``"counts"`` |
  ``"revolutions"``, ``unit`` (of ``scale`` and ``zero``, or of the value: a length unit for
  length joints, ``"rad"`` | ``"deg"`` for angle joints; default the robot's), ``scale`` (per count
  or revolution) and ``zero`` (the joint's value at reading 0), one number or one per joint:
  ``joint = zero + scale * reading``;
* ``[rows]`` (optional: rows to keep, 1-based data rows of each file) ``first``, ``last``,
  ``drop`` (a list), ``keep_column`` (a column whose cell is 1/true/yes to keep, 0/false/no to drop);
* ``[set]`` (optional) ``column``, ``calibration`` and ``validation`` (the cell values); or
  ``[sessions] set``;
* ``[extra]`` (optional) ``name = "lab column"``: channels kept by name (``temperature_C``);
* ``[sessions]`` (optional; one session per input file) ``names`` (default ``"1"``, ``"2"``, ...),
  ``frame`` (``"auto"`` | ``"base"`` | ``"estimate"``, or one per file, where an entry may also
  name another session: that file was captured in the named session's instrument frame, and its
  rows are predicted there; the named session has its own frame and calibration rows, and a
  session without calibration rows must name one or be ``"base"``): the instrument frame of each
  session (with one file: the recording's ``meta.measurement``); ``set`` (one per file, or one for
  all: ``"calibration"`` | ``"validation"``, every row of that file in that set; not with
  ``[set]``); ``[sessions.NAME.joints]``: keys of ``[joints]`` (``columns``, ``reading``, ``unit``,
  ``scale``, ``zero``) that differ for that session's file, each overriding ``[joints]``'s.

Every key is checked (an unknown one is named); every fault of a lab file names the file, the
row (1-based data row and its line) and the column. The files are read, converted and written
:data:`CHUNK_ROWS` rows at a time (:func:`import_lab_files`): memory is bounded by a chunk, not by
the files. The converted data are then checked on evidence against the nominal machine, with one
key changed at a time (:mod:`pipeline.formats.lab_checks`), on a seeded subsample of the rows
(:class:`CheckSample`, at most about :data:`CHECK_ROWS`): a unit or convention key the data prove
wrong is named.
"""

from __future__ import annotations

import codecs
import csv
import json
import math
import sys
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from calib.measurement import FRAME_MODES
from calib.noise import SensorNoise
from calib.prior import ParameterPrior
from calib.robot import Robot
from calib.robots import ROBOTS, default_robot, robot_from_description
from calib.rotation import euler_from_matrix, euler_from_quaternion
from mjcf.units import M_PER_MM

from .recording import (DEFAULT_SESSION, MIN_ROBOT_SIZE_MM, SESSION_NAME, SETS, Recording, check_channel_name,
                        check_session_name, columns, finite_number, read_text_file, recording_header,
                        write_recording_rows)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 (pyproject installs tomli there)
    import tomli as tomllib

__all__ = ["LabExportError", "LabMap", "read_map", "import_lab_files", "LabImport", "LabSample", "LabFile", "LabTable",
           "CheckSample", "poses_and_joints", "session_joint_mapping", "joint_readings", "CHUNK_ROWS", "CHECK_ROWS",
           "CHECK_ROWS_PER_GROUP", "CHECK_SEED", "LAB_FILE",
           "LENGTH_UNITS", "ANGLE_UNITS", "TIME_UNITS", "TIME_FORMATS", "ORIENTATION_COLUMNS", "JOINT_READINGS",
           "MAP_SCHEMA", "SESSION_JOINT_KEYS", "ROTATION_DIRECTIONS"]

#: mm per unit of length.
LENGTH_UNITS = {"mm": 1.0, "m": 1.0 / M_PER_MM, "in": 25.4}
#: rad per unit of angle.
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
#: Units of a time column: how many make one second.
TIME_UNITS = {"s": 1.0, "ms": 1000.0}
TIME_FORMATS = ("seconds", "iso", "none")
#: Orientation kinds and their number of columns.
ORIENTATION_COLUMNS = {"quaternion": 4, "matrix": 9, "euler": 3}
JOINT_READINGS = ("value", "counts", "revolutions")
#: What the orientation columns' rotation maps (``[orientation] rotation``): platform-frame vectors
#: to the instrument's frame (the default), or the inverse (a quaternion's conjugate, a matrix's
#: transpose).
ROTATION_DIRECTIONS = ("platform_to_instrument", "instrument_to_platform")
#: A quaternion whose norm is further than this from 1, or a matrix further than this (largest
#: entry of R R^T - I) from a rotation, is refused: the columns are not an orientation, or not in
#: the declared order. Generous to a lab's rounding (4 decimals give ~1e-4).
ORIENTATION_TOLERANCE = 0.01
#: Cells of a ``rows.keep_column`` that keep or drop their row (lower case).
KEEP_WORDS = {"1": True, "true": True, "yes": True, "0": False, "false": False, "no": False}
#: table -> (whether the table is required, {key: whether required}).
MAP_SCHEMA = {
    "robot": (True, {"name": True, "description": False, "tolerance": False}),
    "noise": (False, {"position_mm": False, "orientation_rad": False, "joint": False, "distribution": False}),
    "csv": (False, {"delimiter": False, "decimal": False, "skip_lines": False}),
    "time": (True, {"format": True, "column": False, "unit": False, "origin": False}),
    "position": (True, {"columns": True, "unit": True, "offset": False}),
    "orientation": (False, {"kind": True, "columns": True, "scalar": False, "order": False, "sequence": False,
                            "unit": False, "rotation": False}),
    "joints": (True, {"columns": True, "reading": True, "unit": False, "scale": False, "zero": False}),
    "rows": (False, {"first": False, "last": False, "drop": False, "keep_column": False}),
    "set": (False, {"column": True, "calibration": True, "validation": True}),
    "extra": (False, {}),
    "sessions": (False, {"names": False, "frame": False, "set": False}),
}
#: The keys a session's own ``[sessions.NAME.joints]`` may override.
SESSION_JOINT_KEYS = ("columns", "reading", "unit", "scale", "zero")


class LabExportError(ValueError):
    """A mapping file or a lab file is refused; the message (one line) names the file and the key,
    or the row and column."""


@dataclass(frozen=True, eq=False)
class LabMap:
    """A checked mapping file (:func:`read_map`): each table as a dict of checked values.

    Attributes:
        path: the map file.
        robot: the robot, with the nominal geometry of ``robot.description`` (or its default).
        noise: the declared noise.
        tables: table name -> {key: checked value} (every table of :data:`MAP_SCHEMA`, empty when
            absent; numbers per joint as (C,) arrays).
    """

    path: Path
    robot: Robot
    noise: SensorNoise
    tables: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- the map


def _fail(path: Path, key: str, what: str) -> LabExportError:
    return LabExportError(f"{path}: key {key}: {what}")


def _choice(path: Path, key: str, value, choices) -> str:
    if not isinstance(value, str) or value not in choices:
        raise _fail(path, key, f"must be one of {', '.join(map(repr, choices))}, got {value!r}")
    return value


def _number(path: Path, key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _fail(path, key, f"must be a finite number, got {value!r}")
    return float(value)


def _positive_int(path: Path, key: str, value, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise _fail(path, key, f"must be an integer >= {minimum}, got {value!r}")
    return value


def _column_names(path: Path, key: str, value, n: int) -> tuple[str, ...]:
    if not isinstance(value, list) or len(value) != n or not all(isinstance(v, str) and v.strip() for v in value):
        raise _fail(path, key, f"must be a list of {n} column names, got {value!r}")
    return tuple(v.strip() for v in value)


def _per_joint(path: Path, key: str, value, n: int, nonzero: bool = False) -> np.ndarray:
    """(n,) one number for every joint, or one each."""
    values = value if isinstance(value, list) else [value] * n
    if len(values) != n:
        raise _fail(path, key, f"must be one number or a list of {n} (one per joint), got {len(values)}")
    out = np.array([_number(path, key, v) for v in values])
    if nonzero and np.any(out == 0):
        raise _fail(path, key, "must not be 0")
    return out


def _tables(path: Path, doc: dict) -> dict:
    """Every table of :data:`MAP_SCHEMA` (absent ones empty), its keys known and the required
    ones there."""
    unknown = [t for t in doc if t not in MAP_SCHEMA]
    if unknown:
        raise LabExportError(f"{path}: unknown table(s) {', '.join(f'[{t}]' for t in unknown)}; the tables are "
                             f"{', '.join(f'[{t}]' for t in MAP_SCHEMA)}")
    tables = {}
    for name, (required, keys) in MAP_SCHEMA.items():
        table = doc.get(name, {})
        if not isinstance(table, dict):
            raise _fail(path, name, f"must be a table [{name}], got {type(table).__name__}")
        if required and name not in doc:
            raise LabExportError(f"{path}: missing table [{name}]")
        extra = [k for k in table if k not in keys and not (name == "sessions" and isinstance(table[k], dict))] \
            if keys else []
        if extra:
            raise _fail(path, f"{name}.{extra[0]}", f"unknown key; the keys of [{name}] are {', '.join(keys)}")
        missing = [k for k, req in keys.items() if req and k not in table] if name in doc else []
        if missing:
            raise _fail(path, f"{name}.{missing[0]}", "missing")
        tables[name] = dict(table)
    return tables


def _robot(path: Path, table: dict) -> Robot:
    name = table["name"]
    if not isinstance(name, str) or name not in ROBOTS:
        raise _fail(path, "robot.name", f"must be one of {', '.join(sorted(ROBOTS))}, got {name!r}")
    if "description" not in table:
        return default_robot(name)
    where = table["description"]
    if not isinstance(where, str):
        raise _fail(path, "robot.description", f"must be the path of a JSON file, got {where!r}")
    file = path.parent / where
    try:
        text = read_text_file(file, "robot description (JSON)")
    except ValueError as exc:  # missing, a folder, not text: the message names the file
        raise _fail(path, "robot.description", str(exc)) from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise _fail(path, "robot.description", f"{file}: not valid JSON: {exc}") from None
    doc = doc.get("nominal_geometry", doc) if isinstance(doc, dict) else doc
    try:
        robot = robot_from_description(name, doc)
    except (KeyError, ValueError, TypeError, IndexError, AttributeError) as exc:
        raise _fail(path, "robot.description", f"{file} is not a {name} description: {exc}") from None
    if not robot.length_scale_mm >= MIN_ROBOT_SIZE_MM:
        raise _fail(path, "robot.description", f"{file} describes a {name} {robot.length_scale_mm:.3g} mm in size: "
                                               "it seems to be in metres; lengths must be in mm")
    return robot


def _noise(path: Path, table: dict) -> SensorNoise:
    for key, value in table.items():
        if key == "distribution":
            _choice(path, "noise.distribution", value, ("uniform", "normal"))
        elif _number(path, f"noise.{key}", value) < 0:
            raise _fail(path, f"noise.{key}", f"must be >= 0, got {value!r}")
    return SensorNoise(**table)


def _check_csv(path: Path, t: dict) -> None:
    delimiter = t.setdefault("delimiter", ",")
    if not isinstance(delimiter, str) or len(delimiter) != 1 or delimiter in "\"\r\n":
        raise _fail(path, "csv.delimiter", f"must be one character (\",\", \";\", \"\\t\"), got {delimiter!r}")
    _choice(path, "csv.decimal", t.setdefault("decimal", "."), (".", ","))
    if t["decimal"] == delimiter:
        raise _fail(path, "csv.decimal", f"{delimiter!r} is also the delimiter")
    _positive_int(path, "csv.skip_lines", t.setdefault("skip_lines", 0), 0)


def _check_time(path: Path, t: dict) -> None:
    fmt = _choice(path, "time.format", t["format"], TIME_FORMATS)
    if fmt == "none":
        extra = [k for k in ("column", "unit", "origin") if k in t]
        if extra:
            raise _fail(path, f"time.{extra[0]}", "has no meaning with time.format = \"none\" (rows in order)")
        return
    if "column" not in t:
        raise _fail(path, "time.column", f"missing (time.format = {fmt!r})")
    t["column"] = _column_names(path, "time.column", [t["column"]], 1)[0]
    if fmt == "iso":
        if "unit" in t:
            raise _fail(path, "time.unit", "has no meaning with ISO timestamps")
        if "origin" in t:
            t["origin"] = _timestamp(t["origin"], lambda what: _fail(path, "time.origin", what))
        return
    _choice(path, "time.unit", t.setdefault("unit", "s"), tuple(TIME_UNITS))
    t["origin"] = _number(path, "time.origin", t.get("origin", 0.0))


def _check_orientation(path: Path, robot: Robot, t: dict) -> None:
    angles = bool(robot.angle_pose_mask.any())
    if angles and not t:
        raise LabExportError(f"{path}: missing table [orientation] (the {robot.name}'s pose has angles: "
                             f"{', '.join(robot.pose_names)})")
    if not t:
        return
    if not angles:
        raise _fail(path, "orientation", f"the {robot.name}'s pose has no angles ({', '.join(robot.pose_names)}); "
                                         "remove [orientation]")
    kind = _choice(path, "orientation.kind", t["kind"], tuple(ORIENTATION_COLUMNS))
    _choice(path, "orientation.rotation", t.setdefault("rotation", ROTATION_DIRECTIONS[0]), ROTATION_DIRECTIONS)
    t["columns"] = _column_names(path, "orientation.columns", t["columns"], ORIENTATION_COLUMNS[kind])
    allowed = {"quaternion": ("scalar",), "matrix": ("order",), "euler": ("sequence", "unit")}[kind]
    extra = [k for k in ("scalar", "order", "sequence", "unit") if k in t and k not in allowed]
    if extra:
        raise _fail(path, f"orientation.{extra[0]}", f"has no meaning with orientation.kind = {kind!r}")
    if kind == "quaternion":
        _choice(path, "orientation.scalar", t.get("scalar"), ("first", "last"))
    elif kind == "matrix":
        _choice(path, "orientation.order", t.setdefault("order", "row"), ("row", "column"))
    else:
        _choice(path, "orientation.unit", t.get("unit"), tuple(ANGLE_UNITS))
        seq = t.get("sequence")
        if not (isinstance(seq, str) and len(seq) == 3 and (set(seq) <= set("xyz") or set(seq) <= set("XYZ"))
                and seq[0] != seq[1] and seq[1] != seq[2]):
            raise _fail(path, "orientation.sequence", "must be three axes, all lowercase (fixed axes) or all "
                                                      f"uppercase (moving axes), e.g. \"xyz\" or \"ZYX\", got {seq!r}")


def _check_joints(path: Path, robot: Robot, t: dict, key: str = "joints") -> None:
    """Check a ``[joints]`` table (``key``: how messages name it, ``sessions.NAME.joints`` for a
    session's own), its numbers made (C,) arrays."""
    c = robot.n_chains
    t["columns"] = _column_names(path, f"{key}.columns", t["columns"], c)
    reading = _choice(path, f"{key}.reading", t["reading"], JOINT_READINGS)
    units = LENGTH_UNITS if robot.joint_unit == "mm" else ANGLE_UNITS
    _choice(path, f"{key}.unit", t.setdefault("unit", robot.joint_unit), tuple(units))
    if reading == "value" and "scale" in t:
        raise _fail(path, f"{key}.scale", "has no meaning with joints.reading = \"value\" (give zero for an offset)")
    if reading != "value" and "scale" not in t:
        raise _fail(path, f"{key}.scale", f"missing: the {t['unit']} per {reading[:-1]} of each joint")
    t["scale"] = _per_joint(path, f"{key}.scale", t.get("scale", 1.0), c, nonzero=True)
    t["zero"] = _per_joint(path, f"{key}.zero", t.get("zero", 0.0), c)


def _session_joints(path: Path, robot: Robot, base: dict, name: str, table) -> dict:
    """Session ``name``'s joint mapping: ``[joints]`` (``base``, as written) with the keys of
    ``[sessions.NAME.joints]`` in place of its own, checked."""
    key = f"sessions.{name}"
    if not isinstance(table, dict) or set(table) != {"joints"}:
        got = sorted(table) if isinstance(table, dict) else type(table).__name__
        raise _fail(path, key, f"a session's table holds one table, [{key}.joints] (the keys of [joints] that "
                               f"differ for its file), got {got}")
    own = table["joints"]
    if not isinstance(own, dict) or not own:
        raise _fail(path, f"{key}.joints", f"must be a table of [joints] keys ({', '.join(SESSION_JOINT_KEYS)})")
    extra = [k for k in own if k not in SESSION_JOINT_KEYS]
    if extra:
        raise _fail(path, f"{key}.joints.{extra[0]}", f"unknown key; a session may override "
                                                      f"{', '.join(SESSION_JOINT_KEYS)}")
    merged = {k: v for k, v in base.items() if not (k == "scale" and own.get("reading") == "value")}
    merged.update(own)
    _check_joints(path, robot, merged, f"{key}.joints")
    return merged


def _check_tolerance(path: Path, robot: Robot, value) -> dict:
    """``[robot] tolerance`` as the sidecar's ``meta.parameter_tolerance``: ``{unit or parameter
    name: standard deviation}``, checked by :meth:`calib.prior.ParameterPrior.from_tolerance`."""
    if not isinstance(value, dict) or not value:
        raise _fail(path, "robot.tolerance", "must be a table by unit (mm = ..., rad = ...) "
                                             f"or by parameter name (\"{robot.table.names[0]}\" = ...), got {value!r}")
    for k, v in value.items():
        if _number(path, f"robot.tolerance.{k}", v) <= 0:
            raise _fail(path, f"robot.tolerance.{k}", f"must be > 0, got {v!r}")
    tolerance = {k: float(v) for k, v in value.items()}
    try:
        ParameterPrior.from_tolerance(robot, tolerance)
    except (TypeError, ValueError) as exc:
        raise _fail(path, "robot.tolerance", str(exc)) from None
    return tolerance


def _check_position(path: Path, t: dict) -> None:
    t["columns"] = _column_names(path, "position.columns", t["columns"], 3)
    _choice(path, "position.unit", t["unit"], tuple(LENGTH_UNITS))
    offset = t.setdefault("offset", [0.0, 0.0, 0.0])
    if not isinstance(offset, list) or len(offset) != 3:
        raise _fail(path, "position.offset", f"must be [x, y, z] in mm, got {offset!r}")
    t["offset"] = np.array([_number(path, "position.offset", v) for v in offset])


def _check_rows(path: Path, t: dict) -> None:
    for key in ("first", "last"):
        if key in t:
            _positive_int(path, f"rows.{key}", t[key])
    if t.get("first", 1) > t.get("last", math.inf):
        raise _fail(path, "rows.last", f"{t['last']} is before rows.first = {t['first']}")
    drop = t.setdefault("drop", [])
    if not isinstance(drop, list):
        raise _fail(path, "rows.drop", f"must be a list of row numbers, got {drop!r}")
    for v in drop:
        _positive_int(path, "rows.drop", v)
    if "keep_column" in t:
        t["keep_column"] = _column_names(path, "rows.keep_column", [t["keep_column"]], 1)[0]


def _check_set(path: Path, t: dict) -> None:
    if not t:
        return
    t["column"] = _column_names(path, "set.column", [t["column"]], 1)[0]
    for key in SETS:
        if not isinstance(t[key], str):
            raise _fail(path, f"set.{key}", f"must be the cell value of a {key} row, got {t[key]!r}")
    if t["calibration"].strip() == t["validation"].strip():
        raise _fail(path, "set.validation", "is the same as set.calibration")


def _check_extra(path: Path, robot: Robot, t: dict) -> None:
    for name, column in t.items():
        check_channel_name(name, columns(robot), LabExportError, f"{path}: key extra.{name}")
        t[name] = _column_names(path, f"extra.{name}", [column], 1)[0]


def _check_sessions(path: Path, robot: Robot, t: dict, joints: dict, has_set_table: bool) -> None:
    """Check ``[sessions]``: ``names``, ``frame`` (modes or session names), ``set``, and each
    session's ``[sessions.NAME.joints]`` (merged with ``joints``, ``[joints]`` as written, into
    ``t["joints"]``: session name -> its mapping)."""
    if "names" in t:
        names = t["names"]
        if not isinstance(names, list) or not names:
            raise _fail(path, "sessions.names", f"must be a list of session names (one per file), got {names!r}")
        for name in names:
            check_session_name(name, LabExportError, f"{path}: key sessions.names")
        if len(set(names)) != len(names):
            raise _fail(path, "sessions.names", f"names a session twice: {names!r}")
    frame = t.get("frame", "auto")
    for f in frame if isinstance(frame, list) else [frame]:
        if not isinstance(f, str) or f not in FRAME_MODES and not SESSION_NAME.fullmatch(f):
            raise _fail(path, "sessions.frame", f"each must be one of {', '.join(map(repr, FRAME_MODES))} or the "
                                                f"name of another session, got {f!r}")
    if "set" in t:
        if has_set_table:
            raise _fail(path, "sessions.set", "and the table [set] both say which rows are validation; keep one")
        for s in t["set"] if isinstance(t["set"], list) else [t["set"]]:
            _choice(path, "sessions.set", s, SETS)
    own = {k: t.pop(k) for k in [k for k in t if k not in MAP_SCHEMA["sessions"][1]]}
    for name in own:
        check_session_name(name, LabExportError, f"{path}: key sessions.{name}")
    t["joints"] = {name: _session_joints(path, robot, joints, name, table) for name, table in own.items()}


def read_map(path: str | Path) -> LabMap:
    """Read and check a mapping file (see the module's description).

    Raises:
        LabExportError: naming the file and the key (or the TOML line) at fault.
    """
    path = Path(path)
    text = read_text_file(path, "mapping file (TOML)", LabExportError)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise LabExportError(f"{path}: not valid TOML: {exc}") from None
    tables = _tables(path, doc)
    robot = _robot(path, tables["robot"])
    if "tolerance" in tables["robot"]:
        tables["robot"]["tolerance"] = _check_tolerance(path, robot, tables["robot"]["tolerance"])
    noise = _noise(path, tables["noise"])
    _check_csv(path, tables["csv"])
    _check_time(path, tables["time"])
    _check_position(path, tables["position"])
    _check_orientation(path, robot, tables["orientation"])
    joints_as_written = dict(tables["joints"])
    _check_joints(path, robot, tables["joints"])
    _check_rows(path, tables["rows"])
    _check_set(path, tables["set"])
    _check_extra(path, robot, tables["extra"])
    _check_sessions(path, robot, tables["sessions"], joints_as_written, bool(tables["set"]))
    return LabMap(path=path, robot=robot, noise=noise, tables=tables)


def _timestamp(value, fail) -> datetime:
    """A datetime of an ISO 8601 timestamp (a TOML datetime is taken as it is), or ``fail(what)``."""
    if isinstance(value, datetime):
        return value
    if not isinstance(value, str):
        raise fail(f"must be an ISO 8601 timestamp, got {value!r}")
    text = value.strip()
    try:
        return datetime.fromisoformat(text[:-1] + "+00:00" if text.endswith(("Z", "z")) else text)
    except ValueError:
        raise fail(f"{value!r} is not an ISO 8601 timestamp (e.g. 2024-03-01T09:30:00.250)") from None


# --------------------------------------------------------------------------- the lab's files

#: What a lab file is called in messages.
LAB_FILE = "lab file (CSV)"
#: Data rows of a lab file read, converted and written at a time: the importer's memory is bounded
#: by this many rows, not by the file's.
CHUNK_ROWS = 20_000
#: The checks on evidence (:mod:`pipeline.formats.lab_checks`) judge the map on a seeded subsample
#: of about this many rows (all of them when there are no more) ...
CHECK_ROWS = 2_000
#: ... with at least this many (or all) of each session's calibration rows, and of its validation rows.
CHECK_ROWS_PER_GROUP = 20
#: The seed of that subsample.
CHECK_SEED = 0


@dataclass(frozen=True, eq=False)
class LabTable:
    """Data rows of a lab file (all, a chunk of them, or a subsample), cells as text, with each
    row's number (0-based data row of the file) and line in the file, and the file's header."""

    path: Path
    header: tuple[str, ...]
    header_line: int
    rows: list
    lines: list
    decimal: str
    numbers_of_rows: range | list

    def where(self, i: int) -> str:
        """How messages name row ``i`` of this table: file, data row (1-based) and line."""
        return f"{self.path}: row {self.numbers_of_rows[i] + 1} (line {self.lines[i]})"

    def index(self, name: str, key: str) -> int:
        """The place of column ``name`` (given by map key ``key``) in the header."""
        hits = [k for k, h in enumerate(self.header) if h == name]
        if not hits:
            shown = ", ".join(self.header[:16]) + (", ..." if len(self.header) > 16 else "")
            raise LabExportError(f"{self.path}: line {self.header_line}: no column {name!r} (key {key}); the "
                                 f"header has {shown}")
        if len(hits) > 1:
            raise LabExportError(f"{self.path}: line {self.header_line}: column {name!r} (key {key}) appears "
                                 f"{len(hits)} times in the header")
        return hits[0]

    def numbers(self, kept: np.ndarray, names: tuple[str, ...], key: str) -> np.ndarray:
        """(len(kept), len(names)) the cells of columns ``names`` in rows ``kept``, finite numbers."""
        out = np.empty((len(kept), len(names)))
        for j, name in enumerate(names):
            col = self.index(name, key)
            texts = [self.rows[i][col].strip() for i in kept]
            if self.decimal == ",":
                texts = [t.replace(",", ".") for t in texts]
            try:
                out[:, j] = np.array(texts, dtype=float)
                if np.all(np.isfinite(out[:, j])):
                    continue
            except ValueError:
                pass
            for i, text in zip(kept, texts):  # the first bad cell, named
                cell = self.rows[i][col].strip().replace("{", "{{").replace("}", "}}")
                finite_number(text, f"{self.where(i)}, column {name!r}: {cell!r} is", LabExportError)
        return out

    def subset(self, rows) -> "LabTable":
        """The table of rows ``rows`` (indices into this one) alone."""
        return LabTable(self.path, self.header, self.header_line, [self.rows[i] for i in rows],
                        [self.lines[i] for i in rows], self.decimal, [self.numbers_of_rows[i] for i in rows])


def _text_lines(path: Path):
    """The lines of a lab file (UTF-8, a byte-order mark accepted), read one at a time; a folder,
    a missing or unreadable file, NUL bytes or bytes that are not UTF-8 refused naming it."""
    if path.is_dir():
        raise LabExportError(f"{path}: is a folder, not a {LAB_FILE}")
    if not path.exists():
        raise LabExportError(f"{path}: {LAB_FILE} not found")
    try:
        stream = open(path, "rb")
    except OSError as exc:
        raise LabExportError(f"{path}: cannot read the {LAB_FILE}: {exc.strerror or exc}") from None
    with stream:
        offset = 0
        for raw in stream:
            if offset == 0 and raw.startswith(codecs.BOM_UTF8):
                raw, offset = raw[len(codecs.BOM_UTF8):], len(codecs.BOM_UTF8)
            if b"\0" in raw:
                raise LabExportError(f"{path}: not a text file (it holds NUL bytes): expected a {LAB_FILE}")
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise LabExportError(f"{path}: not UTF-8 text (byte {offset + exc.start}): expected a "
                                     f"{LAB_FILE}") from None
            offset += len(raw)
            if "\r" in text.rstrip("\r\n"):  # lines ended by a lone carriage return
                yield from text.splitlines(keepends=True)
            else:
                yield text


class LabFile:
    """A lab file split by the map's ``[csv]`` dialect, read :data:`CHUNK_ROWS` data rows at a
    time: iterating gives :class:`LabTable` chunks (header line after ``skip_lines``, trailing
    blank lines dropped); :attr:`data_rows`, once read, the number of data rows."""

    def __init__(self, path: str | Path, lab_map: LabMap, chunk_rows: int | None = None):
        self.path, self.dialect, self.chunk_rows = Path(path), lab_map.tables["csv"], chunk_rows or CHUNK_ROWS
        self.data_rows = 0

    def _header(self, row: list, line: int) -> tuple[str, ...]:
        header = tuple(h.strip() for h in row)
        delimiter = self.dialect["delimiter"]
        others = [d for d in ",;\t" if d != delimiter and len(header) == 1 and d in header[0]]
        if others:
            raise LabExportError(f"{self.path}: line {line}: the fields seem separated by {others[0]!r}, not "
                                 f"{delimiter!r} (key csv.delimiter)")
        return header

    def __iter__(self):
        skip = self.dialect["skip_lines"]
        lines = _text_lines(self.path)
        for _ in range(skip):
            next(lines, None)
        reader = csv.reader(lines, delimiter=self.dialect["delimiter"])
        first, header, rows, ends, blank = None, None, [], [], []
        try:
            for row in reader:
                line = reader.line_num + skip
                if first is None:
                    first = (row, line)
                elif not any(c.strip() for c in row):
                    blank.append((row, line))  # data only if a row follows
                else:
                    header = header or self._header(*first)
                    rows += [b[0] for b in blank] + [row]
                    ends += [b[1] for b in blank] + [line]
                    blank.clear()
                    if len(rows) >= self.chunk_rows:
                        yield self._chunk(header, first[1], rows, ends)
                        rows, ends = [], []
        except csv.Error as exc:
            raise LabExportError(f"{self.path}: line {reader.line_num + skip}: not readable as CSV: {exc}") from None
        if header is None:
            empty = first is None or not any(c.strip() for c in first[0])
            raise LabExportError(f"{self.path}: {'no header line' if empty else 'no data rows'} after the "
                                 f"{skip} line(s) skipped (key csv.skip_lines)")
        if rows:
            yield self._chunk(header, first[1], rows, ends)

    def _chunk(self, header: tuple, header_line: int, rows: list, ends: list) -> LabTable:
        start = self.data_rows
        self.data_rows += len(rows)
        return LabTable(self.path, header, header_line, rows, ends, self.dialect["decimal"],
                        range(start, start + len(rows)))


def _kept_rows(table: LabTable, spec: dict) -> np.ndarray:
    """Indices of the rows of a chunk ``table`` that ``[rows]`` keeps, each with a full set of fields
    (the rows the file lacks for ``first``, ``last``, ``drop``: :func:`_check_row_counts`)."""
    first, last, drop = spec.get("first", 1) - 1, spec.get("last", math.inf), set(spec["drop"])
    rows = [i for i, r in enumerate(table.numbers_of_rows) if first <= r < last and r + 1 not in drop]
    for i in rows:
        if not any(c.strip() for c in table.rows[i]):
            raise LabExportError(f"{table.where(i)}: blank line inside the data (drop it with rows.drop)")
        if len(table.rows[i]) != len(table.header):
            raise LabExportError(f"{table.where(i)}: expected {len(table.header)} fields (as the header), got "
                                 f"{len(table.rows[i])}")
    if "keep_column" in spec and rows:
        name = spec["keep_column"]
        col = table.index(name, "rows.keep_column")
        words = [table.rows[i][col].strip().lower() for i in rows]
        bad = [k for k, w in enumerate(words) if w not in KEEP_WORDS]
        if bad:
            raise LabExportError(f"{table.where(rows[bad[0]])}, column {name!r}: {table.rows[rows[bad[0]]][col]!r} is "
                                 "not 1/true/yes (keep the row) or 0/false/no (drop it) (key rows.keep_column)")
        rows = [i for i, w in zip(rows, words) if KEEP_WORDS[w]]
    return np.array(rows, dtype=int)


def _check_row_counts(path: Path, spec: dict, data_rows: int, kept: int) -> None:
    """Refuse ``[rows]`` keys naming rows a file of ``data_rows`` data rows lacks, or keeping none."""
    for key in ("first", "last"):
        if spec.get(key, 1) > data_rows:
            raise LabExportError(f"{path}: key rows.{key} = {spec[key]}, but the file has {data_rows} data rows")
    beyond = [d for d in spec["drop"] if d > data_rows]
    if beyond:
        raise LabExportError(f"{path}: key rows.drop names row {beyond[0]}, but the file has {data_rows} data rows")
    if not kept:
        raise LabExportError(f"{path}: no data row kept (keys rows.first, rows.last, rows.drop, rows.keep_column)")


@dataclass
class SessionStream:
    """What one file's conversion carries from chunk to chunk: rows kept so far, of them
    validation rows, the time origin (ISO) and the last row's time."""

    kept: int = 0
    validation: int = 0
    origin: datetime | None = None
    last_t: float | None = None


def _times(table: LabTable, kept: np.ndarray, spec: dict, state: SessionStream) -> np.ndarray:
    """(len(kept),) ``t_s`` of a chunk's kept rows; time must not go backwards, in the chunk or
    from the session's previous chunk (``state``)."""
    if spec["format"] == "none":
        return np.arange(state.kept, state.kept + len(kept), dtype=float)
    name = spec["column"]
    if spec["format"] == "seconds":
        t_s = (table.numbers(kept, (name,), "time.column")[:, 0] - spec["origin"]) / TIME_UNITS[spec["unit"]]
    else:
        col = table.index(name, "time.column")
        stamps = [_timestamp(table.rows[i][col], lambda what, i=i: LabExportError(
            f"{table.where(i)}, column {name!r}: {what}")) for i in kept]
        origin = state.origin = state.origin or spec.get("origin", stamps[0])
        for i, s in zip(kept, stamps):
            if (s.tzinfo is None) != (origin.tzinfo is None):
                raise LabExportError(f"{table.where(i)}, column {name!r}: {table.rows[i][col].strip()!r} has "
                                     f"{'no' if s.tzinfo is None else 'a'} time zone and the origin "
                                     f"({origin.isoformat()}) {'has' if s.tzinfo is None else 'has none'}")
        t_s = np.array([(s - origin).total_seconds() for s in stamps])
    before = np.concatenate([[state.last_t] if state.last_t is not None else [], t_s])
    back = np.flatnonzero(np.diff(before) < 0)
    if back.size:
        k = back[0] + 1 - (len(before) - len(t_s))  # the kept row that goes back
        raise LabExportError(f"{table.where(kept[k])}, column {name!r}: time goes backwards ({before[back[0] + 1]!r} s "
                             f"after {before[back[0]]!r} s); rows must be in the order taken (or dropped: key "
                             "rows.drop)")
    state.last_t = float(t_s[-1])
    return t_s


def _time_info(spec: dict, state: SessionStream) -> dict:
    """What a session declares of its time (the sidecar's ``sessions.NAME``)."""
    if spec["format"] == "none":
        return {"time": "row order"}
    return {"time": "measured", **({"time_origin": state.origin.isoformat()} if spec["format"] == "iso" else {})}
def _orientation(table: LabTable, kept: np.ndarray, spec: dict) -> np.ndarray:
    """(N, 3) the angles ``[alpha, beta, gamma]`` of the orientation columns, rad (of the inverse
    rotation with ``rotation = "instrument_to_platform"``: the quaternion's conjugate, the
    matrix's transpose)."""
    names, kind = spec["columns"], spec["kind"]
    inverse = spec["rotation"] != ROTATION_DIRECTIONS[0]
    raw = table.numbers(kept, names, "orientation.columns")
    if kind == "euler":
        from scipy.spatial.transform import Rotation

        R = Rotation.from_euler(spec["sequence"], raw * ANGLE_UNITS[spec["unit"]]).as_matrix()
        return euler_from_matrix(np.swapaxes(R, 1, 2) if inverse else R)
    if kind == "quaternion":
        q = raw if spec["scalar"] == "first" else raw[:, [3, 0, 1, 2]]
        off = np.abs(np.linalg.norm(q, axis=1) - 1.0)
        what = "a quaternion of norm {norm:.6g}"
    else:
        R = raw.reshape(-1, 3, 3) if spec["order"] == "row" else raw.reshape(-1, 3, 3).transpose(0, 2, 1)
        gram = np.abs(R @ R.transpose(0, 2, 1) - np.eye(3)).max(axis=(1, 2))
        off = np.where(np.linalg.det(R) > 0, gram, np.inf)
        what = "not a rotation matrix (largest entry of R R^T - I: {gram:.3g}, determinant {det:.6g})"
    bad = np.flatnonzero(~(off <= ORIENTATION_TOLERANCE))
    if bad.size:
        k = bad[0]
        detail = what.format(norm=np.linalg.norm(raw[k]), gram=gram[k] if kind == "matrix" else 0.0,
                             det=np.linalg.det(R[k]) if kind == "matrix" else 0.0)
        raise LabExportError(f"{table.where(kept[k])}, columns {', '.join(names)}: {detail}; the columns must be "
                             f"the orientation (key orientation.columns) in the declared order")
    if kind == "quaternion":
        return euler_from_quaternion(q * np.array([1.0, -1.0, -1.0, -1.0]) if inverse else q)
    return euler_from_matrix(np.swapaxes(R, 1, 2) if inverse else R)


def joint_readings(spec: dict, robot: Robot, joints) -> np.ndarray:
    """(N, C) the lab's readings of joint values ``joints`` (N, C, the robot's unit) by the checked
    ``[joints]`` mapping ``spec``: ``(joint / unit - zero) / scale`` (the inverse of the import)."""
    factor = (LENGTH_UNITS if robot.joint_unit == "mm" else ANGLE_UNITS)[spec["unit"]]
    return (np.asarray(joints, dtype=float) / factor - spec["zero"]) / spec["scale"]


def session_joint_mapping(lab_map: LabMap, session: str | None = None) -> dict:
    """The checked ``[joints]`` mapping of ``session`` (its ``[sessions.NAME.joints]`` over
    ``[joints]``; None or a session without its own: ``[joints]``)."""
    return lab_map.tables["sessions"].get("joints", {}).get(session, lab_map.tables["joints"])


def _joint_key(lab_map: LabMap, session: str) -> str:
    """The map's table of ``session``'s joint mapping, as messages name it."""
    return f"sessions.{session}.joints" if session in lab_map.tables["sessions"].get("joints", {}) else "joints"


def poses_and_joints(lab_map: LabMap, table: LabTable, kept: np.ndarray, session: str) -> tuple[np.ndarray, np.ndarray]:
    """``(measured (N, D), joints (N, C))`` of rows ``kept`` of session ``session``'s ``table`` in
    the recording's units, as ``lab_map`` reads them."""
    robot, t = lab_map.robot, lab_map.tables
    poses = np.empty((len(kept), robot.pose_dim))
    angle = robot.angle_pose_mask
    poses[:, ~angle] = table.numbers(kept, t["position"]["columns"], "position.columns") \
        * LENGTH_UNITS[t["position"]["unit"]] + t["position"]["offset"]
    if angle.any():
        poses[:, angle] = _orientation(table, kept, t["orientation"])
    j = session_joint_mapping(lab_map, session)
    factor = (LENGTH_UNITS if robot.joint_unit == "mm" else ANGLE_UNITS)[j["unit"]]
    joints = (j["zero"] + j["scale"] * table.numbers(kept, j["columns"], f"{_joint_key(lab_map, session)}.columns")) \
        * factor
    return poses, joints


def _sets(table: LabTable, kept: np.ndarray, spec: dict, whole_set: str | None) -> np.ndarray:
    """(len(kept),) each kept row's set: ``whole_set``, or by ``[set]``'s column, or calibration."""
    sets = np.full(len(kept), whole_set or SETS[0], dtype=object)
    if spec:
        col = table.index(spec["column"], "set.column")
        labels = {spec[s].strip(): s for s in SETS}
        for k, i in enumerate(kept):
            cell = table.rows[i][col].strip()
            if cell not in labels:
                raise LabExportError(f"{table.where(i)}, column {spec['column']!r}: {cell!r} is neither "
                                     f"{spec['calibration']!r} (key set.calibration) nor "
                                     f"{spec['validation']!r} (key set.validation)")
            sets[k] = labels[cell]
    return sets.astype(str)


class CheckSample:
    """A seeded subsample of the rows kept, for the checks on evidence: each (session, set) group's
    rows drawn uniformly without replacement (every row a random key, the smallest kept: the draw
    does not depend on how the files are chunked); :data:`CHECK_ROWS` rows in all, at least
    :data:`CHECK_ROWS_PER_GROUP` (or all) of each group; every row when there are no more than
    :data:`CHECK_ROWS`."""

    def __init__(self, seed: int = CHECK_SEED, size: int | None = None):
        self.seed, self.size, self.rng = seed, size or CHECK_ROWS, np.random.default_rng(seed)
        self.kept = max(self.size, CHECK_ROWS_PER_GROUP)  # the most rows a group may give
        self.groups: dict = {}  # (session, set) -> [keys, [(row number, cells, line, time)], rows seen]
        self.files: dict = {}  # session -> a table of its file (its path, header, decimal)

    def add(self, session: str, table: LabTable, kept: np.ndarray, sets: np.ndarray, t_s: np.ndarray) -> None:
        """Offer a chunk's kept rows ``kept`` of ``table`` (their sets and times)."""
        keys = self.rng.random(len(kept))
        self.files.setdefault(session, table.subset([]))
        for name in SETS:
            mine = np.flatnonzero(sets == name)
            group = self.groups.setdefault((session, name), [np.empty(0), [], 0])
            group[2] += mine.size
            if len(group[0]) >= self.kept:  # only rows that can enter
                mine = mine[keys[mine] < group[0].max()]
            if not mine.size:
                continue
            group[0] = np.concatenate([group[0], keys[mine]])
            group[1] += [(table.numbers_of_rows[kept[k]], table.rows[kept[k]], table.lines[kept[k]], float(t_s[k]))
                         for k in mine]
            if len(group[0]) > self.kept:
                best = np.argpartition(group[0], self.kept)[:self.kept]
                group[0], group[1] = group[0][best], [group[1][b] for b in best]

    def rows(self) -> int:
        """The rows offered."""
        return sum(group[2] for group in self.groups.values())

    def drawn(self, session: str) -> tuple[LabTable, np.ndarray, np.ndarray]:
        """``(table, t_s, sets)`` of session ``session``'s rows drawn, in the file's order."""
        total, picked = self.rows(), []
        for name in SETS:
            keys, items, seen = self.groups.get((session, name), (np.empty(0), [], 0))
            take = seen if total <= self.size else min(seen, max(CHECK_ROWS_PER_GROUP, round(self.size * seen / total)))
            picked += [(items[k], name) for k in np.argsort(keys)[:take]]
        picked.sort(key=lambda p: p[0][0])
        f = self.files[session]
        table = LabTable(f.path, f.header, f.header_line, [p[0][1] for p in picked], [p[0][2] for p in picked],
                         f.decimal, [p[0][0] for p in picked])
        return table, np.array([p[0][3] for p in picked]), np.array([p[1] for p in picked], dtype=str)


def _stream_file(lab_map: LabMap, path: Path, session: str, whole_set: str | None, writer,
                 sample: CheckSample) -> dict:
    """Convert one lab file chunk by chunk, each chunk's kept rows written as recording rows of
    session ``session`` by ``writer`` and offered to ``sample``; ``whole_set``: every row's set
    (``[sessions] set``), or None (``[set]``, or every row calibration). Returns what the
    sidecar says of the file (``data_rows``, ``kept_rows``, ``validation_rows``, ``time``)."""
    t = lab_map.tables
    state, lab = SessionStream(), LabFile(path, lab_map)
    for table in lab:
        kept = _kept_rows(table, t["rows"])
        if not kept.size:
            continue
        t_s = _times(table, kept, t["time"], state)
        measured, joints = poses_and_joints(lab_map, table, kept, session)
        sets = _sets(table, kept, t["set"], whole_set)
        extras = [table.numbers(kept, (column,), f"extra.{name}")[:, 0] for name, column in t["extra"].items()]
        write_recording_rows(writer, t_s, joints, measured, extras, sets, [session] * len(kept))
        sample.add(session, table, kept, sets, t_s)
        state.kept += len(kept)
        state.validation += int(np.sum(sets == SETS[1]))
    _check_row_counts(path, t["rows"], lab.data_rows, state.kept)
    return {"data_rows": lab.data_rows, "kept_rows": state.kept, "validation_rows": state.validation,
            "time": _time_info(t["time"], state)}


def _session_frames(lab_map: LabMap, names: list, frames: list, calibrated: dict) -> None:
    """Refuse a frame naming a session that is not another with its own frame and calibration
    rows (``calibrated``: session -> whether it has any), and a session without calibration rows
    whose frame is to be estimated."""
    path = lab_map.path
    own = {n: f for n, f in zip(names, frames)}
    for name, frame in own.items():
        if frame is None or frame in FRAME_MODES:
            if not calibrated[name] and len(names) > 1 and frame != "base":
                raise _fail(path, "sessions.frame", f"session {name!r} has no calibration rows, so its instrument "
                                                    f"frame ({frame or 'auto'!r}) cannot be estimated: name the "
                                                    "session whose frame it was captured in, or \"base\"")
            continue
        if frame == name or frame not in own:
            raise _fail(path, "sessions.frame", f"session {name!r}: {frame!r} is neither one of "
                                                f"{', '.join(map(repr, FRAME_MODES))} nor another session "
                                                f"({', '.join(map(repr, names))})")
        if own[frame] is not None and own[frame] not in FRAME_MODES:
            raise _fail(path, "sessions.frame", f"session {name!r} names session {frame!r}, whose frame is "
                                                f"session {own[frame]!r}'s: name {own[frame]!r}")
        if not calibrated[frame]:
            raise _fail(path, "sessions.frame", f"session {name!r} names session {frame!r}, which has no "
                                                "calibration rows: its frame cannot be estimated")


@dataclass(frozen=True, eq=False)
class LabSample:
    """The rows the checks on evidence judge the map on (:class:`CheckSample`'s draw).

    Attributes:
        recording: those rows as the map reads them (the recording's sessions, frames, meta).
        tables: session -> its rows drawn, as the lab wrote them.
        rows: the rows kept in all (``len(recording.t_s)`` of them drawn).
        seed: the draw's seed.
    """

    recording: Recording
    tables: dict
    rows: int
    seed: int

    @property
    def all_rows(self) -> bool:
        """Whether every row kept is in the sample."""
        return len(self.recording.t_s) == self.rows

    def read_as(self, lab_map: LabMap) -> tuple[np.ndarray, np.ndarray]:
        """``(joints, measured)`` of the sample's rows as ``lab_map`` (the map with a key changed)
        reads them.

        Raises:
            LabExportError: they cannot be read so.
        """
        parts = [poses_and_joints(lab_map, table, np.arange(len(table.rows)), name)
                 for name, table in self.tables.items()]
        return np.concatenate([p[1] for p in parts]), np.concatenate([p[0] for p in parts])


@dataclass(frozen=True, eq=False)
class LabImport:
    """What :func:`import_lab_files` wrote and what the sidecar says of it.

    Attributes:
        header: the recording's CSV header.
        meta: the sidecar's ``meta`` (``imported``: the map and, per file, its session, data rows and
            rows kept; ``parameter_tolerance``; ``measurement``).
        session_info: the sidecar's ``sessions`` (session -> its source, time and frame).
        validation_rows: session -> its validation rows.
        sample: the rows the checks on evidence judge the map on.
    """

    header: tuple[str, ...]
    meta: dict
    session_info: dict
    validation_rows: dict
    sample: LabSample


def _sessions_of(lab_map: LabMap, files: list) -> tuple[list, list, list]:
    """``(names, frames, sets)``: one each per file, by ``[sessions]`` (checked against the files)."""
    if not files:
        raise LabExportError("no lab file given")
    twice = sorted({str(f) for f in files if files.count(f) > 1})
    if twice:
        raise LabExportError(f"{twice[0]}: given twice (one session per file)")
    s = lab_map.tables["sessions"]
    names = s.get("names", [DEFAULT_SESSION] if len(files) == 1 else [str(k + 1) for k in range(len(files))])
    frames = s["frame"] if isinstance(s.get("frame"), list) else [s.get("frame")] * len(files)
    sets = s["set"] if isinstance(s.get("set"), list) else [s.get("set")] * len(files)
    for key, given in (("sessions.names", names), ("sessions.frame", frames), ("sessions.set", sets)):
        if len(given) != len(files):
            raise _fail(lab_map.path, key, f"lists {len(given)} sessions for {len(files)} files")
    stray = [n for n in s.get("joints", {}) if n not in names]
    if stray:
        raise _fail(lab_map.path, f"sessions.{stray[0]}", f"names no session ({', '.join(map(repr, names))})")
    return names, frames, sets


def import_lab_files(lab_map: LabMap, files, csv_file, seed: int = CHECK_SEED) -> LabImport:
    """Convert a lab's files, one session per file (see the module's description), writing the
    recording's CSV rows to the open text file ``csv_file`` as they are converted,
    :data:`CHUNK_ROWS` rows at a time (memory bounded by a chunk, not by the files); the rows the
    checks on evidence judge the map on drawn on the way (``seed``).

    Raises:
        LabExportError: naming the file and the row and column, or the map's key, at fault.
    """
    files = [Path(f) for f in files]
    names, frames, sets = _sessions_of(lab_map, files)
    header = recording_header(lab_map.robot, {}, lab_map.tables["extra"], True)
    writer = csv.writer(csv_file, lineterminator="\n")
    writer.writerow(header)
    sample = CheckSample(seed)
    done = [_stream_file(lab_map, f, n, w, writer, sample) for f, n, w in zip(files, names, sets)]
    _session_frames(lab_map, names, frames, {n: d["kept_rows"] > d["validation_rows"] for n, d in zip(names, done)})
    meta = {"imported": {"map": str(lab_map.path), "files": [
        {"file": str(f), "session": n, "data_rows": d["data_rows"], "kept_rows": d["kept_rows"]}
        for f, n, d in zip(files, names, done)]}}
    if "tolerance" in lab_map.tables["robot"]:
        meta["parameter_tolerance"] = dict(lab_map.tables["robot"]["tolerance"])
    info = {n: {"source": str(f), **d["time"]} for f, n, d in zip(files, names, done)}
    if len(files) == 1 and frames[0] is not None:
        meta["measurement"] = {"frame": frames[0]}
    for n, frame in zip(names, frames):
        if len(files) > 1 and frame is not None:
            info[n]["measurement"] = {"frame": frame}
    drawn = {n: sample.drawn(n) for n in names}
    read = {n: poses_and_joints(lab_map, table, np.arange(len(table.rows)), n) for n, (table, _, _) in drawn.items()}
    rec = Recording(robot=lab_map.robot, noise=lab_map.noise, meta=meta, session_info=info,
                    t_s=np.concatenate([d[1] for d in drawn.values()]),
                    joints=np.concatenate([r[1] for r in read.values()]),
                    measured=np.concatenate([r[0] for r in read.values()]),
                    sets=np.concatenate([d[2] for d in drawn.values()]),
                    sessions=np.concatenate([[n] * len(d[1]) for n, d in drawn.items()]))
    return LabImport(header=header, meta=meta, session_info=info,
                     validation_rows={n: d["validation_rows"] for n, d in zip(names, done)},
                     sample=LabSample(rec, {n: d[0] for n, d in drawn.items()}, sample.rows(), seed))
