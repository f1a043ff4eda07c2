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
import dataclasses
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
from calib.rotation import rotation_matrix

__all__ = ["output_folder", "RecordingError", "Recording", "write_recording", "read_recording", "columns",
           "atomic_write", "publish", "writing", "ResultSet", "OutputError", "recording_texts", "sidecar_path",
           "plausibility", "FORMAT", "FORMAT_VERSION",
           "SIDECAR_FIELDS", "READABLE_VERSIONS", "MIN_ROBOT_SIZE_MM", "REFUSED_CONDITION", "WARNED_CONDITION"]

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


class OutputError(ValueError):
    """An output path cannot be written; the message names it (and the flag that gave it)."""


def output_folder(out: str | Path) -> Path:
    """The output folder ``out`` (flag ``--out``), created if missing.

    Raises:
        OutputError: it is a file, or it cannot be created (the message names the flag).
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out}: is a file, not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"--out {out}: cannot create the folder: {exc.strerror or exc}") from None
    return out


class ResultSet:
    """The output files of one run, published together or not at all.

    Every path is checked when the set is made (before any work): not a folder, not existing
    unless ``overwrite``, in a folder that exists (or is created, ``create_folders``) and can be
    written. Each file is written to a temporary file beside its destination (:meth:`temp`);
    :meth:`publish` moves them all into place, and if one move fails, removes those already moved
    (restoring what they replaced). Leaving the ``with`` block without publishing removes the
    temporary files: an interrupted run leaves only hidden ``.*.tmp`` files, nothing that looks
    complete.

    Raises:
        FileExistsError: a path exists and ``overwrite`` is off.
        OutputError: a path cannot be written.
    """

    def __init__(self, paths: dict, *, overwrite: bool = False, flags: dict | None = None,
                 create_folders: bool = False):
        self.paths = {k: Path(v) for k, v in paths.items()}
        self.overwrite = overwrite
        self._tmp: dict[str, Path] = {}
        try:
            self._check(flags or {}, create_folders)
        except BaseException:
            self.discard()
            raise

    def _check(self, flags: dict, create_folders: bool) -> None:
        for key, path in self.paths.items():
            who = f"{flags[key]} {path}" if key in flags else str(path)
            if path.is_dir():
                raise OutputError(f"{who}: is a folder, not a file")
            if path.exists() and not self.overwrite:
                raise FileExistsError(f"{who} exists; pass --overwrite to replace it (refusing to overwrite it "
                                      "silently)")
            folder = path.parent
            if create_folders and not folder.exists():
                try:
                    folder.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise OutputError(f"{who}: cannot create the folder {folder}: {exc.strerror or exc}") from None
            if not folder.is_dir():
                raise OutputError(f"{who}: the folder {folder} does not exist" if not folder.exists() else
                                  f"{who}: {folder} is not a folder")
            try:  # the real test of writability (permissions, read-only file systems)
                fd, probe = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
            except OSError as exc:
                raise OutputError(f"{who}: cannot write in the folder {folder}: {exc.strerror or exc}") from None
            os.close(fd)
            self._tmp[key] = Path(probe)

    def temp(self, key: str) -> Path:
        """The temporary file that becomes ``paths[key]`` on :meth:`publish`."""
        return self._tmp[key]

    def publish(self) -> None:
        """Move every temporary file into place, all or none."""
        done: list[tuple[Path, Path | None]] = []
        try:
            for key, path in self.paths.items():
                backup = None
                if self.overwrite and path.exists():
                    fd, b = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".bak")
                    os.close(fd)
                    os.replace(path, b)
                    backup = Path(b)
                try:
                    publish(self._tmp[key], path, overwrite=self.overwrite)
                except BaseException:
                    if backup is not None:
                        os.replace(backup, path)
                    raise
                done.append((path, backup))
        except BaseException:
            for path, backup in reversed(done):
                if backup is not None:
                    os.replace(backup, path)
                elif path.exists():
                    path.unlink()
            raise
        for _, backup in done:
            if backup is not None:
                backup.unlink()

    def discard(self) -> None:
        """Remove the temporary files that were not published."""
        for tmp in self._tmp.values():
            if tmp.exists():
                tmp.unlink()

    def __enter__(self) -> "ResultSet":
        return self

    def __exit__(self, *exc) -> None:
        self.discard()


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
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise RecordingError(f"{csv_path}: not a readable CSV file: {exc}") from None
    while rows and not any(c.strip() for c in rows[-1]):
        rows.pop()  # trailing blank lines
    if not rows:
        raise RecordingError(f"{csv_path}: empty file (expected a header row {', '.join(expected)})")
    header = [h.strip() for h in rows[0]]
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
    idx = {h: i for i, h in enumerate(header)}
    data = rows[1:]
    if not data:
        raise RecordingError(f"{csv_path}: no data rows (the header alone)")
    values = np.empty((len(data), len(expected)))
    sets = np.empty(len(data), dtype=object)
    for r, row in enumerate(data, start=1):
        where = f"{csv_path}: row {r} (line {r + 1})"
        if not any(c.strip() for c in row):
            raise RecordingError(f"{where}: blank line inside the data")
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
            same = np.flatnonzero((values[:r - 1] == values[r - 1]).all(axis=1) & (sets[:r - 1] == s))
            if same.size:
                raise RecordingError(f"{where}: repeats row {same[0] + 1} exactly (time included): a copied row; "
                                     "delete it")
            raise RecordingError(f"{where}, column 't_s': time goes backwards "
                                 f"({float(values[r - 1, 0])!r} after {float(values[r - 2, 0])!r}); rows must be in "
                                 "the order taken")
    sets = sets.astype(str)
    c = len(joint_cols)
    return Recording(robot=robot, noise=noise, t_s=values[:, 0], joints=values[:, 1:1 + c],
                     measured=values[:, 1 + c:], sets=sets, meta=meta)


#: Column-scaled condition number of the identification Jacobian above which the calibration
#: poses are refused (too alike to tell the parameters apart), and above which a warning is given.
#: Poses spread over the workspace give 1e2 to 1e5.
REFUSED_CONDITION = 1e8
WARNED_CONDITION = 1e6


def _row(path: Path, r: int) -> str:
    """How messages name the 0-based data row ``r``: its spreadsheet row number and file line."""
    return f"{path}: row {r + 1} (line {r + 2})"


def _condition_in_words(cond: float) -> str:
    if not np.isfinite(cond) or cond > 1e12:
        return "numerically singular"
    if cond > REFUSED_CONDITION:
        return "nearly singular"
    return "poorly conditioned"


#: The rotation convention of recordings (the project's).
ROTATION_CONVENTION = "R = Rz(gamma) Ry(beta) Rx(alpha) (platform to base, angles in the columns alpha, beta, gamma)"


def _other_rotation_convention(rec: Recording) -> str | None:
    """The convention the recording's angles seem to follow when it is not the project's: the
    geometry identified (forward method) with the angles read in another convention explains the
    calibration rows at least ten times better (chi-square) than with the project's, which
    misfits (chi-square above 4 per degree of freedom); None otherwise. Only then: for small
    angles the conventions differ at second order, like a geometric error, so only a fit tells
    them apart."""
    from scipy.spatial.transform import Rotation

    from calib.engine import identify_forward
    from calib.rotation import euler_from_matrix

    joints, measured = rec.subset("calibration")
    robot = rec.robot
    angle = robot.angle_pose_mask
    angles = measured[:, angle]

    def chi2(converted_angles) -> float:
        poses = measured.copy()
        poses[:, angle] = converted_angles
        try:
            fit = identify_forward(robot, joints, poses, rec.noise)
        except (ValueError, ArithmeticError):  # KinematicsError is a ValueError
            return float("inf")
        value = fit.chi2 / max(fit.dof, 1)
        return value if np.isfinite(value) else float("inf")

    declared = chi2(angles)
    if not declared > 4.0:
        return None
    candidates = {
        "R = Rx(alpha) Ry(beta) Rz(gamma)": lambda: euler_from_matrix(Rotation.from_euler("XYZ", angles).as_matrix()),
        "the inverse rotation (base to platform)": lambda: euler_from_matrix(np.swapaxes(rotation_matrix(angles), 1, 2)),
        "the columns in the order gamma, beta, alpha": lambda: angles[:, ::-1],
    }
    misfit = {name: chi2(convert()) for name, convert in candidates.items()}
    best = min(misfit, key=misfit.get)
    return best if misfit[best] < 0.1 * declared else None


def plausibility(rec: Recording, csv_path: str | Path) -> list[str]:
    """Check that the machine can have produced ``rec`` before anything is fitted.

    Refuses: joint values outside the nominal geometry's range (the stroke of a leg), with a
    guess when the whole file seems to hold metres for mm or degrees for rad; poses whose
    positions or angles seem to be in metres or degrees; values beyond any workspace; rows copied
    exactly (time included); calibration poses too alike to identify the parameters
    (condition number in words).

    Returns:
        Warnings in words: repeated measurements (same joints and pose at another time), poorly
        excited calibration poses.

    Raises:
        RecordingError: naming the file, row and column, and what the file seems to hold.
    """
    from calib.robot import KinematicsError, pose_jacobian_of_parameters

    path = Path(csv_path)
    robot = rec.robot
    joint_cols, pose_cols = columns(robot)
    limits = robot.joint_limits()
    q = rec.joints
    out = (q < limits[:, 0]) | (q > limits[:, 1])
    warnings: list[str] = []
    if out.any():
        unit = robot.joint_unit
        factor = 1000.0 if unit == "mm" else 180.0 / np.pi
        other = "metres" if unit == "mm" else "degrees"
        scaled = q * factor if unit == "mm" else np.deg2rad(q)
        if out.all(axis=1).any() and not ((scaled < limits[:, 0]) | (scaled > limits[:, 1])).any():
            raise RecordingError(f"{path}: columns {', '.join(joint_cols)}: the joint values seem to be in "
                                 f"{other} (e.g. {q[0, 0]:.6g}), a recording holds {unit}")
        r, c = np.argwhere(out)[0]
        raise RecordingError(f"{_row(path, r)}, column {joint_cols[c]!r}: {q[r, c]:.6g} {unit} is outside the "
                             f"range [{limits[c, 0]:.6g}, {limits[c, 1]:.6g}] {unit} of the nominal geometry: "
                             "the machine cannot reach it")
    m = rec.measured
    nominal = robot.table.nominal
    targets = measurement_settings(rec.meta.get("measurement")).n_targets
    if targets:  # target positions (columns t1_x_mm ...), in the instrument's frame: no pose checks
        angle = np.zeros(m.shape[1], dtype=bool)
        pose_cols = tuple(f"{n}_mm" for n in target_names(targets))
        fk = None
    else:
        angle = robot.angle_pose_mask
        try:
            fk = robot.forward_kinematics(nominal, q, initial=np.repeat(robot.home_pose[None], len(q), axis=0))
        except KinematicsError:
            fk = None
    check_convention = False
    if fk is not None:
        pos = ~angle
        e1 = np.median(np.abs(m[:, pos] - fk[:, pos]))
        e1000 = np.median(np.abs(1000.0 * m[:, pos] - fk[:, pos]))
        if e1 > 1.0 and e1000 < 0.1 * e1:
            cols = [c for c, a in zip(pose_cols, angle) if not a]
            raise RecordingError(f"{path}: columns {', '.join(cols)}: the positions seem to be in metres "
                                 f"(e.g. {m[0, pos][-1]:.6g} where the joints put the platform near "
                                 f"{fk[0, pos][-1]:.6g} mm); a recording holds mm")
        if angle.any():
            e = np.median(np.abs(m[:, angle] - fk[:, angle]))
            edeg = np.median(np.abs(np.deg2rad(m[:, angle]) - fk[:, angle]))
            # Only where the positions say the poses are in the base frame (an instrument's
            # frame turns the angles too), and only for a close match once converted.
            in_base_frame = e1 < 0.05 * robot.length_scale_mm
            if in_base_frame and e > 0.01 and edeg < 0.1 * e and edeg < 0.01:
                cols = [c for c, a in zip(pose_cols, angle) if a]
                raise RecordingError(f"{path}: columns {', '.join(cols)}: the angles seem to be in degrees "
                                     "(they match the joints once converted from degrees); a recording holds rad")
            check_convention = in_base_frame and int(angle.sum()) == 3 and int((rec.sets == "calibration").sum()) >= 2
    bound = np.where(angle, 2 * np.pi, 100.0 * robot.length_scale_mm)
    far = np.abs(m) > bound
    if far.any():
        r, c = np.argwhere(far)[0]
        what = "not an angle in rad" if angle[c] else f"far beyond the {robot.name}'s reach"
        raise RecordingError(f"{_row(path, r)}, column {pose_cols[c]!r}: {m[r, c]:.6g} is {what}")
    if fk is not None and angle.any() and check_convention:  # after the magnitudes: a fit needs sane values
        other = _other_rotation_convention(rec)
        if other is not None:
            cols = [c for c, a in zip(pose_cols, angle) if a]
            raise RecordingError(f"{path}: columns {', '.join(cols)}: the angles seem to follow {other}; "
                                 f"a recording holds {ROTATION_CONVENTION}")
    full = np.column_stack([rec.t_s, q, m])
    body = np.column_stack([q, m])
    first: dict[bytes, int] = {}
    for r in range(len(full)):
        key = full[r].tobytes() + rec.sets[r].encode()
        if key in first:
            raise RecordingError(f"{_row(path, r)}: repeats row {first[key] + 1} exactly (time included): "
                                 "a copied row; delete it")
        first[key] = r
    seen: dict[bytes, int] = {}
    repeats = []
    for r in range(len(body)):
        key = body[r].tobytes()
        if key in seen:
            repeats.append(f"{r + 1} (= {seen[key] + 1})")
        else:
            seen[key] = r
    if repeats:
        warnings.append(f"{path}: rows {', '.join(repeats)} repeat the joints and pose of an earlier row exactly "
                        "(at another time): each counts as a new measurement and shrinks the uncertainty")
    cal = rec.sets == "calibration"
    if cal.sum() >= 2 and not targets:
        free = robot.table.indices(robot.free_default)
        poses = fk[cal] if fk is not None else m[cal]
        std = rec.noise.pose_std(robot.pose_units)
        J = pose_jacobian_of_parameters(robot, nominal, q[cal], poses)[:, :, free] / std[None, :, None]
        A = J.reshape(-1, free.size)
        norms = np.linalg.norm(A, axis=0)
        if np.all(norms > 0):
            sv = np.linalg.svd(A / norms, compute_uv=False)
            cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
        else:
            cond = float("inf")
        distinct = len({b.tobytes() for b in body[cal]})
        if cond > REFUSED_CONDITION:
            raise RecordingError(
                f"{path}: the {int(cal.sum())} calibration poses ({distinct} distinct) are too alike to identify "
                f"the {free.size} parameters: the identification is {_condition_in_words(cond)} (condition "
                f"number {cond:.2g}; poses spread over the workspace give 1e2 to 1e5); measure poses spread "
                "over the workspace")
        if cond > WARNED_CONDITION:
            warnings.append(f"{path}: the calibration poses excite the parameters poorly (condition number "
                            f"{cond:.2g}, {_condition_in_words(cond)}): expect large uncertainties")
    return warnings
