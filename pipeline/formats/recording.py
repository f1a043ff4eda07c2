"""Measurement recordings on disk, the same format for every robot: a CSV plus a JSON sidecar.

CSV: one row per measurement in the order taken, columns

    t_s, <joints>, <pose>[, <extra channels>][, set][, session]

with the robot's joint columns (``l1_mm .. l6_mm`` for the hexapod, ``q1_rad .. q3_rad`` for
the Delta: what was commanded, or read when joints are measured) and pose columns (``x_mm, y_mm,
z_mm[, alpha_rad, beta_rad, gamma_rad]``: the measured pose, base frame, or the instrument's
frame with ``meta.measurement``; position-only data have ``t1_x_mm, t1_y_mm, t1_z_mm, t2_x_mm ...``
instead, one triple per target, see :mod:`calib.measurement`); the optional ``set``
column is ``calibration`` or ``validation`` (default ``calibration``). Extra channels
(``temperature_C``, ``load_N``, ...: any number the lab logged beside the pose, kept by name for
discovery) are the columns the sidecar's ``columns`` lists beyond these. The optional ``session``
column names each row's session (a short name; default one session ``"1"``): one machine, each
session its own instrument frame and its own time origin (``t_s`` may restart at a new session; a
session's rows are together, and its time does not go backwards). The sidecar's optional
``sessions`` field declares, per session, its instrument frame (``measurement``: ``frame``,
``initial_frame`` as in ``meta.measurement``, which they override for that session; or ``frame``
naming another session: the session was captured in that session's instrument frame, which has
its own), its
``source`` file, its ``time_origin`` and whether ``time`` was ``measured`` or is the ``row order``.
The JSON sidecar names the robot, its nominal geometry and parameter table, the declared noise and
the units.

A recording without extra channels and with the one default session writes exactly as before
these were added (no ``session`` column, no ``sessions`` field).

Reading validates everything and names file, row and column on error; writing is atomic
(temporary file + rename) and never overwrites an existing file unless asked to.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib.files import read_json_file, read_text_file
from calib.measurement import FRAME_MODES, MeasurementSettings, frame_from_dict, measurement_settings, target_names
from calib.noise import SensorNoise
from calib.robot import Robot
from calib.robots import ROBOTS, robot_from_description

from .outputs import ResultSet

__all__ = ["RecordingError", "Recording", "write_recording", "read_recording", "read_sidecar_geometry", "columns",
           "recording_texts", "recording_header", "write_recording_rows", "sidecar_text", "sidecar_path",
           "finite_number", "row_words", "row_message", "FORMAT", "FORMAT_VERSION", "SETS", "SIDECAR_FIELDS",
           "READABLE_VERSIONS",
           "MIN_ROBOT_SIZE_MM", "DEFAULT_SESSION", "SESSION_KEYS", "SESSION_TIMES", "session_measurement",
           "check_session_name", "check_channel_name", "read_text_file", "frame_session", "shared_frame_error",
           "SESSION_NAME", "row_frame_groups"]

SETS = ("calibration", "validation")
FORMAT = "parallel-calib recording"
#: Version 2: any robot (joint and pose columns from the robot, parameter table in the sidecar);
#: version 1 (hexapod only) is read too.
FORMAT_VERSION = 2
UNITS = {"length": "mm", "angle": "rad", "time": "s"}
#: The session of every row of a recording without a ``session`` column.
DEFAULT_SESSION = "1"
#: What the sidecar's ``sessions`` field may declare of a session.
SESSION_KEYS = ("measurement", "source", "time_origin", "time")
#: A session's ``time``: ``t_s`` measured (s from its origin), or the rows' order (0, 1, 2...).
SESSION_TIMES = ("measured", "row order")
#: The keys of a session's ``measurement`` (the rest of ``meta.measurement`` is the recording's).
SESSION_MEASUREMENT_KEYS = ("frame", "initial_frame")
#: A session's name: short, no spaces or commas.
SESSION_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,31}")
#: An extra channel's name: a word with its unit after the last underscore (``temperature_C``).
CHANNEL_NAME = re.compile(r"[A-Za-z][A-Za-z0-9]*(_[A-Za-z0-9]+)*")


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
        sessions: (N,) str, each row's session (None: every row in :data:`DEFAULT_SESSION`).
        session_info: session name -> what the sidecar declares of it (:data:`SESSION_KEYS`,
            JSON-ready); sessions not named here have the recording's defaults.
        extras: channel name (``temperature_C``) -> (N,) float, extra columns kept by name.
    """

    robot: Robot
    noise: SensorNoise
    t_s: np.ndarray
    joints: np.ndarray
    measured: np.ndarray
    sets: np.ndarray
    meta: dict = field(default_factory=dict)
    sessions: np.ndarray | None = None
    session_info: dict = field(default_factory=dict)
    extras: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.t_s)
        sessions = np.full(n, DEFAULT_SESSION) if self.sessions is None else np.asarray(self.sessions, dtype=str)
        if sessions.shape != (n,):
            raise ValueError(f"sessions must have shape ({n},), got {sessions.shape}")
        object.__setattr__(self, "sessions", sessions)
        extras = {}
        for name, values in self.extras.items():
            extras[name] = np.asarray(values, dtype=float)
            if extras[name].shape != (n,):
                raise ValueError(f"extra channel {name!r} must have shape ({n},), got {extras[name].shape}")
        object.__setattr__(self, "extras", extras)
        for name in np.unique(sessions):
            check_session_name(str(name), ValueError, "session")
        for name in extras:
            check_channel_name(name, columns(self.robot, measurement_settings(self.meta.get("measurement")).n_targets),
                               ValueError, "extra channel")
        unused = [name for name in self.session_info if name not in sessions]
        if unused:
            raise ValueError(f"session_info names session(s) {', '.join(map(repr, unused))} without rows")
        wrong = shared_frame_error(self.session_info, set(sessions.tolist()))
        if wrong:
            raise ValueError(f"session_info: {wrong}")

    @property
    def session_names(self) -> tuple[str, ...]:
        """The sessions, in the order of their first row."""
        names, first = np.unique(self.sessions, return_index=True)
        return tuple(str(names[k]) for k in np.argsort(first))

    def session_rows(self, name: str) -> np.ndarray:
        """0-based indices of the rows of session ``name``."""
        return np.flatnonzero(self.sessions == name)

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


def _has_sessions(rec: Recording) -> bool:
    """Whether ``rec`` writes a ``session`` column and a ``sessions`` field (not one default session)."""
    return bool(rec.session_info) or bool(np.any(rec.sessions != DEFAULT_SESSION))


def recording_header(robot: Robot, meta: dict, extras, sessions: bool) -> tuple[str, ...]:
    """The CSV header of a recording of ``robot`` (``meta``'s measurement says its pose columns),
    its extra channels ``extras`` and, with ``sessions``, a ``session`` column."""
    joint_cols, pose_cols = columns(robot, measurement_settings(meta.get("measurement")).n_targets)
    return ("t_s",) + joint_cols + pose_cols + tuple(extras) + ("set",) + (("session",) if sessions else ())


def write_recording_rows(writer, t_s, joints, measured, extras, sets, sessions=None) -> None:
    """Write recording rows with ``writer`` (a :func:`csv.writer`): each number as Python's
    shortest exact ``repr``; ``extras``: the channels' (N,) values in the header's order;
    ``sessions``: each row's session, or None (no ``session`` column)."""
    extras = list(extras)
    for k in range(len(t_s)):
        writer.writerow([repr(float(t_s[k]))] + [repr(float(v)) for v in joints[k]]
                        + [repr(float(v)) for v in measured[k]] + [repr(float(e[k])) for e in extras]
                        + [sets[k]] + ([sessions[k]] if sessions is not None else []))


def sidecar_text(robot: Robot, noise: SensorNoise, meta: dict, header, sessions: dict | None) -> str:
    """The JSON sidecar of a recording with CSV ``header`` (:func:`recording_header`); ``sessions``:
    the ``sessions`` field (name -> what is declared of it, in the order of their first row), or
    None (one default session)."""
    table = robot.table
    sidecar = {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "robot": robot.name,
        "units": UNITS,
        "columns": list(header),
        **({"sessions": sessions} if sessions is not None else {}),
        "nominal_geometry": robot.description(),
        "parameter_table": [{"name": p.name, "unit": p.unit, "nominal": p.nominal, "chain": p.chain + 1}
                            for p in table],
        "declared_noise": noise.to_dict(),
        "meta": meta,
    }
    return json.dumps(sidecar, indent=1)


def recording_texts(rec: Recording) -> tuple[str, str]:
    """The CSV text and the JSON sidecar text of ``rec``."""
    sessions = _has_sessions(rec)
    header = recording_header(rec.robot, rec.meta, rec.extras, sessions)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    write_recording_rows(w, rec.t_s, rec.joints, rec.measured, rec.extras.values(), rec.sets,
                         rec.sessions if sessions else None)
    declared = {name: rec.session_info.get(name, {}) for name in rec.session_names} if sessions else None
    return buf.getvalue(), sidecar_text(rec.robot, rec.noise, rec.meta, header, declared)


def check_session_name(name, error: type[Exception] = ValueError, where: str = "session") -> str:
    """``name`` if it is a session's name (:data:`SESSION_NAME`: up to 32 letters, digits, ``_.+-``),
    else ``error`` naming ``where``."""
    if not isinstance(name, str) or not SESSION_NAME.fullmatch(name):
        raise error(f"{where}: {name!r} is not a session name (1 to 32 letters, digits or _.+-, not starting "
                    "with a sign)")
    return name


def check_channel_name(name, recording_columns: tuple[tuple[str, ...], tuple[str, ...]],
                       error: type[Exception] = ValueError, where: str = "extra channel") -> str:
    """``name`` if it can name an extra channel (a word with its unit, ``temperature_C``; not a
    column the recording has anyway: ``recording_columns`` is :func:`columns`' answer), else
    ``error`` naming ``where``."""
    taken = ("t_s",) + recording_columns[0] + recording_columns[1] + ("set", "session")
    if not isinstance(name, str) or not CHANNEL_NAME.fullmatch(name):
        raise error(f"{where}: {name!r} is not a channel name (a word and its unit, e.g. temperature_C)")
    if name in taken:
        raise error(f"{where}: {name!r} is one of the recording's own columns ({', '.join(taken)})")
    return name


def frame_session(rec: Recording, name: str) -> str:
    """The session in whose instrument frame session ``name`` was captured: ``name`` itself, or the
    session its ``measurement.frame`` names."""
    frame = rec.session_info.get(name, {}).get("measurement", {}).get("frame", "auto")
    return name if frame in FRAME_MODES else frame


def shared_frame_error(session_info: dict, sessions: set) -> str | None:
    """What is wrong with a session's ``measurement.frame`` naming another session (it must name
    another session of the recording, one with its own frame), in words; None when nothing is."""
    for name, block in session_info.items():
        frame = block.get("measurement", {}).get("frame", "auto")
        if frame in FRAME_MODES:
            continue
        if frame == name or frame not in sessions:
            return (f"sessions.{name}.measurement.frame must be one of {', '.join(FRAME_MODES)} or another "
                    f"session of the recording, got {frame!r}")
        theirs = session_info.get(frame, {}).get("measurement", {}).get("frame", "auto")
        if theirs not in FRAME_MODES:
            return (f"sessions.{name}.measurement.frame names session {frame!r}, whose frame is session "
                    f"{theirs!r}'s: name {theirs!r}")
    return None


def session_measurement(rec: Recording, name: str) -> MeasurementSettings:
    """How session ``name`` was measured: ``meta.measurement`` with the own ``measurement`` (its
    instrument frame: ``frame``, ``initial_frame``) of the session whose frame it was captured in
    (:func:`frame_session`) in place of the recording's."""
    merged = dict(rec.meta.get("measurement") or {})
    merged.update(rec.session_info.get(frame_session(rec, name), {}).get("measurement", {}))
    return measurement_settings(merged or None)


def row_frame_groups(rec: Recording) -> tuple[np.ndarray | None, object]:
    """``(each row's frame group (N,) int or None for one, the frame mode(s))``: sessions captured
    in one instrument frame (a session naming another's) share it; the modes one a group (a
    list), or the one group's mode."""
    groups = list(dict.fromkeys(frame_session(rec, n) for n in rec.session_names))
    modes = [session_measurement(rec, g).frame for g in groups]
    modes = [m if m in FRAME_MODES else "auto" for m in modes]
    if len(groups) == 1:
        return None, modes[0]
    index = {n: groups.index(frame_session(rec, n)) for n in rec.session_names}
    return np.array([index[s] for s in rec.sessions]), modes


#: The row a calib message names (its own numbering, 0-based, of the arrays it was given).
CALIB_ROW = re.compile(r"\s*(?:(?:at|for) row \d+|^row \d+(?: is)?|^configuration \d+:)")


def row_words(path, r: int) -> str:
    """How every message names the 0-based data row ``r`` of a recording: ``FILE: row r+1 (line r+2)``
    (the row as a spreadsheet shows it below the header)."""
    return f"{path}: row {r + 1} (line {r + 2})"


def row_message(exc, path, rows) -> str:
    """A :class:`calib.robot.KinematicsError` said in the recording's numbering: its row (``exc.index``,
    0-based in the arrays it was given) mapped through ``rows`` (those arrays' 0-based data rows in the
    recording) and named as :func:`row_words` does, the calib message's own row number taken out."""
    text = CALIB_ROW.sub("", str(exc)).strip(" :")
    index = getattr(exc, "index", None)
    if index is None or not 0 <= index < len(rows):
        return f"{path}: {text}"
    return f"{row_words(path, int(rows[index]))}: {text}"


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
SIDECAR_FIELDS = ("format", "version", "robot", "units", "columns", "sessions", "nominal_geometry",
                  "parameter_table", "declared_noise", "meta")
#: Sidecar versions this reader understands.
READABLE_VERSIONS = (1, FORMAT_VERSION)
#: A parallel robot smaller than this (mm) is a geometry written in metres.
MIN_ROBOT_SIZE_MM = 5.0


def _describes(robot_name: str, description: dict) -> bool:
    """Whether ``description`` reads as a ``robot_name`` geometry."""
    try:
        robot_from_description(robot_name, description)
    except (KeyError, ValueError, TypeError, IndexError):
        return False
    return True


def _read_sidecar(json_path: Path) -> tuple[Robot, SensorNoise, dict, dict]:
    """``(robot, noise, meta, sidecar)`` of a checked sidecar (its columns and sessions are checked
    by :func:`_sidecar_layout`)."""
    if not json_path.exists() and not json_path.is_dir():
        raise RecordingError(f"{json_path}: sidecar not found (a recording is a CSV plus a JSON with the same stem)")
    side = read_json_file(json_path, "JSON sidecar", RecordingError)
    _object_of_known_keys(side, SIDECAR_FIELDS, f"{json_path}: top level", f"{json_path}: unknown field(s)",
                          "the fields are")
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
    except KeyError as exc:  # a key the robot's description needs is missing: another robot's geometry?
        missing = exc.args[0] if exc.args else exc
        others = [r for r in ROBOTS if r != name and _describes(r, side["nominal_geometry"])]
        also = f": it is a description of a {others[0]}; field 'robot' says {name!r}" if others else ""
        raise RecordingError(f"{json_path}: field 'nominal_geometry' is not a {name} description (no key "
                             f"{missing!r}){also}") from None
    except (ValueError, TypeError, IndexError) as exc:
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
    return robot, noise, meta, side


def read_sidecar_geometry(json_path: str | Path) -> Robot:
    """The robot of a recording's sidecar: its nominal geometry, read and checked as
    :func:`read_recording` reads it (the sidecar alone; no CSV needed).

    Raises:
        RecordingError: naming the sidecar and the field at fault.
    """
    return _read_sidecar(Path(json_path))[0]


def _sidecar_layout(json_path: Path, side: dict,
                    recording_columns: tuple[tuple[str, ...], tuple[str, ...]]) -> tuple[tuple[str, ...], dict]:
    """``(extra channels, session info)``: the columns a version-2 sidecar's ``columns`` lists
    beyond the recording's own, and its ``sessions`` field, checked."""
    listed = side.get("columns", []) if side["version"] == FORMAT_VERSION else []
    if not isinstance(listed, list) or not all(isinstance(c, str) for c in listed):
        raise RecordingError(f"{json_path}: field 'columns' must be a list of column names")
    own = ("t_s",) + recording_columns[0] + recording_columns[1] + ("set", "session")
    extras = tuple(dict.fromkeys(c for c in listed if c not in own))
    for name in extras:
        check_channel_name(name, recording_columns, RecordingError, f"{json_path}: field 'columns'")
    value = side.get("sessions", {})
    if not isinstance(value, dict):
        raise RecordingError(f"{json_path}: field 'sessions' must be an object (session name -> what it "
                             f"declares), got {type(value).__name__}")
    return extras, {check_session_name(name, RecordingError, f"{json_path}: field 'sessions'"):
                    _session_block(json_path, name, block) for name, block in value.items()}


def _object_of_known_keys(value, allowed, what: str, unknown_words: str, allowed_words: str) -> None:
    """RecordingError unless ``value`` is a JSON object whose keys are all in ``allowed`` (a misspelt
    key would otherwise be ignored silently)."""
    if not isinstance(value, dict):
        raise RecordingError(f"{what} must be an object, got {type(value).__name__}")
    unknown = [k for k in value if k not in allowed]
    if unknown:
        raise RecordingError(f"{unknown_words} {', '.join(map(repr, unknown))}; {allowed_words} {', '.join(allowed)}")


def _session_block(json_path: Path, name: str, block) -> dict:
    """A session's entry of the sidecar's ``sessions`` field, checked (:data:`SESSION_KEYS`)."""
    where = f"{json_path}: field sessions.{name}"
    _object_of_known_keys(block, SESSION_KEYS, where, f"{where}: unknown key(s)", "the keys are")
    for key in ("source", "time_origin"):
        if key in block and not isinstance(block[key], str):
            raise RecordingError(f"{where}.{key} must be a string, got {block[key]!r}")
    if "time" in block and block["time"] not in SESSION_TIMES:
        raise RecordingError(f"{where}.time must be one of {', '.join(map(repr, SESSION_TIMES))}, got {block['time']!r}")
    m = block.get("measurement", {})
    if not isinstance(m, dict):
        raise RecordingError(f"{where}.measurement must be an object, got {type(m).__name__}")
    extra = [k for k in m if k not in SESSION_MEASUREMENT_KEYS]
    if extra:
        raise RecordingError(f"{where}.measurement: unknown key(s) {', '.join(map(repr, extra))}: a session "
                             f"declares its instrument frame ({', '.join(SESSION_MEASUREMENT_KEYS)}); the targets "
                             "are the recording's (meta.measurement)")
    frame = m.get("frame", "auto")
    if frame not in FRAME_MODES and not (isinstance(frame, str) and SESSION_NAME.fullmatch(frame)):
        raise RecordingError(f"{where}.measurement.frame must be one of {', '.join(FRAME_MODES)} or another "
                             f"session's name, got {frame!r}")
    if frame not in FRAME_MODES and "initial_frame" in m:
        raise RecordingError(f"{where}.measurement.initial_frame: the session is in session {frame!r}'s frame "
                             "(measurement.frame), which declares it")
    if "initial_frame" in m:
        try:
            frame_from_dict(m["initial_frame"], f"sessions.{name}.measurement.initial_frame")
        except ValueError as exc:
            raise RecordingError(f"{json_path}: field {exc}") from None
    return block


def csv_rows(csv_path: Path, text: str, expected: tuple[str, ...], error: type[Exception] = None) -> list[list[str]]:
    """The CSV's rows (cells as text), trailing blank lines dropped; at least the header (else
    ``error``, default :class:`RecordingError`, naming the file and the ``expected`` columns)."""
    error = error or RecordingError
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise error(f"{csv_path}: not a readable CSV file: {exc}") from None
    while rows and not any(c.strip() for c in rows[-1]):
        rows.pop()  # trailing blank lines
    if not rows:
        raise error(f"{csv_path}: empty file (expected a header row {', '.join(expected)})")
    return rows


def header_names(csv_path: Path, row: list[str], expected: tuple[str, ...], whose: str,
                 error: type[Exception] = None) -> list[str]:
    """The header row's column names, checked: comma-separated, each once, the ``expected``
    columns all there (in any order; ``whose`` says whose they are); else ``error`` (default
    :class:`RecordingError`) naming line 1."""
    error = error or RecordingError
    header = [h.strip() for h in row]
    for sep, words in ((";", "';'"), ("\t", "tabs")):
        if len(header) == 1 and sep in header[0]:
            raise error(f"{csv_path}: line 1: the fields are separated by {words}; the file is comma-separated "
                        f"({','.join(expected[:2])},...)")
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise error(f"{csv_path}: line 1: column(s) {', '.join(dup)} appear more than once")
    missing = [c for c in expected if c not in header]
    if missing:
        raise error(f"{csv_path}: line 1: header lacks column(s) {', '.join(missing)} ({whose}); got "
                    f"{', '.join(header)}")
    return header


def _header(csv_path: Path, row: list[str], expected: tuple[str, ...], robot: Robot) -> list[str]:
    """The header row's column names, checked (:func:`header_names`), nothing else but ``set``
    and ``session``."""
    header = header_names(csv_path, row, expected, f"a {robot.name} recording, per its sidecar")
    unknown = [h for h in header if h not in expected + ("set", "session")]
    if unknown:
        raise RecordingError(f"{csv_path}: line 1: unknown column(s) {', '.join(unknown)}")
    return header


def _data_row(where: str, row: list[str], idx: dict[str, int],
              expected: tuple[str, ...]) -> tuple[list[float], str, str]:
    """One data row's values (finite numbers, in the ``expected`` columns' order), its set and its
    session; ``idx``: each column's place in the file; ``where``: how messages name the row."""
    if not any(c.strip() for c in row):
        raise RecordingError(f"{where}: blank line inside the data")
    if len(row) != len(idx):
        raise RecordingError(f"{where}: expected {len(idx)} fields, got {len(row)}")
    values = [finite_number(row[idx[name]].strip(), f"{where}, column {name!r}: {{cell!r}} is",
                            RecordingError) for name in expected]
    s = row[idx["set"]].strip() if "set" in idx else "calibration"
    if s not in SETS:
        raise RecordingError(f"{where}, column 'set': {s!r} is not one of {', '.join(SETS)}")
    session = row[idx["session"]].strip() if "session" in idx else DEFAULT_SESSION
    return values, s, check_session_name(session, RecordingError, f"{where}, column 'session'")


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
          expected: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(values, sets, sessions)``: (N, len(expected)) the data rows' values in the ``expected``
    columns' order (s, the joint unit, mm and rad), (N,) str their sets and (N,) str their
    sessions; a session's rows are together and its time does not go backwards (a row that
    repeats an earlier one exactly is named as copied)."""
    idx = {h: i for i, h in enumerate(header)}
    fast = _data_at_once(data, idx, expected)
    if fast is not None:
        return fast
    values = np.empty((len(data), len(expected)))
    labels = np.empty((len(data), 2), dtype=object)  # set, session
    ended: dict[str, int] = {}  # session -> its last row, once another has begun
    for r, row in enumerate(data, start=1):
        where = f"{csv_path}: row {r} (line {r + 1})"
        values[r - 1], labels[r - 1, 0], labels[r - 1, 1] = _data_row(where, row, idx, expected)
        if r > 1:
            _check_order(where, values[:r], labels[:r], ended)
    return values, labels[:, 0].astype(str), labels[:, 1].astype(str)


def _data_at_once(data: list[list[str]], idx: dict[str, int],
                  expected: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """:func:`_data`'s answer computed column by column with numpy (no Python work per cell), or
    None where any row breaks a rule: the row-by-row reading then names the first row, column and
    what is wrong (the same messages whichever path reads a valid file)."""
    width = len(idx)
    if any(len(row) != width for row in data):
        return None
    # The cells as Python strings, converted by Python's float (what the row-by-row reading calls):
    # the same numbers, and the same cells refused, in one numpy call a column block.
    cells = np.array(data, dtype=object).reshape(len(data), width)
    try:
        values = cells[:, [idx[name] for name in expected]].astype(float)
    except ValueError:
        return None
    if not np.all(np.isfinite(values)):
        return None
    sets = np.char.strip(cells[:, idx["set"]].astype(str)) if "set" in idx else np.full(len(data), "calibration")
    sessions = (np.char.strip(cells[:, idx["session"]].astype(str)) if "session" in idx
                else np.full(len(data), DEFAULT_SESSION))
    if not np.all(np.isin(sets, SETS)):
        return None
    names = np.unique(sessions)
    if not all(SESSION_NAME.fullmatch(str(name)) for name in names):
        return None
    begins = sessions[np.r_[0, np.flatnonzero(sessions[1:] != sessions[:-1]) + 1]] if len(data) else sessions
    if np.unique(begins).size != begins.size:
        return None  # a session resumes
    same = sessions[1:] == sessions[:-1]
    if np.any(same & (values[1:, 0] < values[:-1, 0])):
        return None  # time goes backwards (or a copied row)
    return values, sets.astype(str), sessions.astype(str)


def _check_order(where: str, values: np.ndarray, labels: np.ndarray, ended: dict[str, int]) -> None:
    """The last of ``values`` / ``labels`` (the rows so far) against those before it: its session
    continues the previous row's or begins (a session does not resume), its time is not earlier
    than the previous row's of the same session."""
    r = len(values)
    session, previous = labels[-1, 1], labels[-2, 1]
    if session != previous:
        ended[previous] = r - 1
        if session in ended:
            raise RecordingError(f"{where}, column 'session': session {session!r} resumes after session "
                                 f"{previous!r} (its rows ended at row {ended[session]}); a session's rows must "
                                 "be together")
        return
    if values[-1, 0] < values[-2, 0]:
        same = np.flatnonzero((values[:-1] == values[-1]).all(axis=1) & (labels[:-1] == labels[-1]).all(axis=1))
        if same.size:
            raise RecordingError(f"{where}: repeats row {same[0] + 1} exactly (time included): a copied row; "
                                 "delete it")
        raise RecordingError(f"{where}, column 't_s': time goes backwards "
                             f"({float(values[-1, 0])!r} after {float(values[-2, 0])!r}); rows must be in "
                             "the order taken")


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
    text = read_text_file(csv_path, "CSV recording", RecordingError)
    json_path = sidecar_path(csv_path)
    robot, noise, meta, side = _read_sidecar(json_path)
    joint_cols, pose_cols = columns(robot, measurement_settings(meta.get("measurement")).n_targets)
    extras, session_info = _sidecar_layout(json_path, side, (joint_cols, pose_cols))
    expected = ("t_s",) + joint_cols + pose_cols + extras
    rows = csv_rows(csv_path, text, expected)
    header = _header(csv_path, rows[0], expected, robot)
    if len(rows) == 1:
        raise RecordingError(f"{csv_path}: no data rows (the header alone)")
    values, sets, sessions = _data(csv_path, rows[1:], header, expected)
    idle = [name for name in session_info if name not in sessions]
    if idle:
        raise RecordingError(f"{json_path}: field 'sessions' declares session(s) {', '.join(map(repr, idle))} "
                             f"that no row of {csv_path.name} is in")
    wrong = shared_frame_error(session_info, set(sessions.tolist()))
    if wrong:
        raise RecordingError(f"{json_path}: field {wrong}")
    c, d = len(joint_cols), len(pose_cols)
    return Recording(robot=robot, noise=noise, t_s=values[:, 0], joints=values[:, 1:1 + c],
                     measured=values[:, 1 + c:1 + c + d], sets=sets, meta=meta, sessions=sessions,
                     session_info=session_info, extras={e: values[:, 1 + c + d + k] for k, e in enumerate(extras)})
