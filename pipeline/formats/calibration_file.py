"""The calibration file: what a calibration found, in one JSON file a controller can be fed from.

``pipeline.run`` and ``pipeline.discover`` write ``<name>.calibration.json`` beside their other
outputs; ``pipeline.compensate`` reads it. It holds:

- ``format`` (:data:`CALIBRATION_FORMAT`) and ``version`` (:data:`CALIBRATION_VERSION`);
- ``robot`` and its ``nominal_geometry`` (``Robot.description()``, mm and rad);
- ``parameters``: every parameter of the robot's table by name: ``nominal``, ``identified``,
  ``error`` (identified minus nominal), ``std`` and ``unit``; ``free`` (the names identified) and
  ``covariance`` (free by free, parameter units, in the order of ``free``);
- ``measurement_frames``: each session's instrument frame relative to the base
  (``{"translation_mm", "rotation_rad"}``, with ``std``), empty when the data were in the base
  frame; ``targets``: the target offsets on the platform (mm) or null;
- ``effects``: the effects found with their coefficients (a record each,
  :mod:`calib.effects.records`: name, granularity, coefficients by name with std and unit,
  searched parameter, and a law's terms for a proposed or kept law); empty for a run;
- ``validity``: the domain the calibration saw: pose box (``pose_min``/``pose_max`` by pose
  coordinate, base frame), joint ranges (``joint_min``/``joint_max``), time span ``t_s``;
- ``declared_noise``; ``recording``: the input's file name and SHA-256 (CSV and sidecar), or the
  simulated scenario in words; ``produced_by``: the command.

A file of another format, version or robot, or one lacking a key, is refused with one line
naming the file and the key (:class:`CalibrationFileError`).
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from calib.measurement import frame_from_dict, frame_to_dict
from calib.noise import SensorNoise
from calib.robot import Robot
from calib.robots import ROBOTS, robot_from_description

from .outputs import atomic_write
from .recording import read_json_file, sidecar_path

if TYPE_CHECKING:
    from calib.effects.records import FittedEffect

__all__ = ["CALIBRATION_FORMAT", "CALIBRATION_VERSION", "CALIBRATION_SUFFIX", "Calibration", "CalibrationFileError",
           "write_calibration", "read_calibration", "calibration_text", "recording_source", "validity_domain"]

#: The format's name, written and checked.
CALIBRATION_FORMAT = "parallel-calib calibration"
#: The format's version: a reader refuses any other.
CALIBRATION_VERSION = 1
#: A calibration file's name is the run's name with this suffix.
CALIBRATION_SUFFIX = ".calibration.json"
#: The keys every calibration file has.
KEYS = ("format", "version", "robot", "nominal_geometry", "produced_by", "recording", "declared_noise", "parameters",
        "measurement_frames", "targets", "effects", "validity")


class CalibrationFileError(ValueError):
    """A calibration file cannot be used; the message names the file and the key."""


@dataclass(frozen=True, eq=False)
class Calibration:
    """What a calibration found (see the module docstring for the file).

    Attributes:
        robot: the robot, with its nominal geometry.
        theta: (P,) identified parameters (mm, rad).
        std: (P,) their standard uncertainties (0 for the fixed ones).
        free: names of the parameters identified.
        covariance: (F, F) their covariance, in the order of ``free``.
        frames: ``{session: (6,) frame}``, each session's instrument frame (base frame: empty).
        frames_std: ``{session: (6,) std}``.
        targets: (K, 3) target offsets on the platform, mm, or None.
        records: the effects found, as records (:func:`calib.effects.records.effect_record`).
        validity: the domain the calibration saw (``pose_min``, ``pose_max``, ``joint_min``,
            ``joint_max``: lists in the robot's order; ``t_s``: ``[first, last]``).
        noise: the declared noise of the recording.
        recording: where the data came from.
        produced_by: the command that wrote it.
    """

    robot: Robot
    theta: np.ndarray
    std: np.ndarray
    free: tuple
    covariance: np.ndarray
    frames: dict = field(default_factory=dict)
    frames_std: dict = field(default_factory=dict)
    targets: np.ndarray | None = None
    records: tuple = ()
    validity: dict = field(default_factory=dict)
    noise: SensorNoise = field(default_factory=SensorNoise)
    recording: dict = field(default_factory=dict)
    produced_by: str = ""

    def effects(self, channels: dict | None = None, where: str = "effects") -> list[FittedEffect]:
        """The effects found, rebuilt (a law's recorded ``channels`` one value per row acted on)."""
        # Imported here: the effects' registry is for a file that has effects, not for writing one.
        from calib.effects.records import effect_from_record

        return [effect_from_record(d, self.robot, channels=channels, where=f"{where}[{k}]")
                for k, d in enumerate(self.records)]

    def to_dict(self) -> dict:
        r = self.robot
        table = r.table
        k = {n: i for i, n in enumerate(table.names)}
        params = {n: {"nominal": float(table.nominal[i]), "identified": float(self.theta[i]),
                      "error": float(self.theta[i] - table.nominal[i]), "std": float(self.std[i]),
                      "unit": table.units[i]} for n, i in k.items()}
        return {"format": CALIBRATION_FORMAT, "version": CALIBRATION_VERSION, "robot": r.name,
                "nominal_geometry": r.description(), "produced_by": self.produced_by, "recording": self.recording,
                "declared_noise": self.noise.to_dict(),
                "parameters": {"by_name": params, "free": list(self.free),
                               "covariance": np.asarray(self.covariance, dtype=float).tolist()},
                "measurement_frames": {s: {**frame_to_dict(f), "std": frame_to_dict(self.frames_std.get(s, np.zeros(6)))}
                                       for s, f in self.frames.items()},
                "targets": None if self.targets is None else np.asarray(self.targets, dtype=float).tolist(),
                "effects": list(self.records), "validity": self.validity}


#: A JSON list of numbers spread over lines (each number on its own, as ``json.dumps`` indents it).
NUMBER_LIST = re.compile(r"\[\s+((?:-?[0-9][0-9.eE+-]*,\s+)*-?[0-9][0-9.eE+-]*)\s+\]")


def calibration_text(cal: Calibration) -> str:
    """The JSON text of a calibration file (indented; a list of numbers on one line)."""
    text = json.dumps(cal.to_dict(), indent=1)
    return NUMBER_LIST.sub(lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]", text) + "\n"


def write_calibration(path, cal: Calibration, *, overwrite: bool = False) -> Path:
    """Write ``cal`` to ``path`` atomically (an existing file refused without ``overwrite``)."""
    return atomic_write(path, calibration_text(cal), overwrite=overwrite)


def recording_source(csv_path) -> dict:
    """``{"name", "sha256", "sidecar_sha256"}`` of a recording's files (the sidecar's hash None
    when it has none)."""
    csv_path = Path(csv_path)
    side = sidecar_path(csv_path)
    return {"name": csv_path.name, "sha256": hashlib.sha256(csv_path.read_bytes()).hexdigest(),
            "sidecar_sha256": hashlib.sha256(side.read_bytes()).hexdigest() if side.is_file() else None}


def validity_domain(robot: Robot, poses, joints, t_s) -> dict:
    """The domain a calibration saw: the box of its poses (base frame), its joints' ranges and
    its time span."""
    poses, joints, t_s = (np.asarray(a, dtype=float) for a in (poses, joints, t_s))
    return {"pose_names": list(robot.pose_names), "pose_min": poses.min(axis=0).tolist(),
            "pose_max": poses.max(axis=0).tolist(), "joint_names": list(robot.joint_names),
            "joint_min": joints.min(axis=0).tolist(), "joint_max": joints.max(axis=0).tolist(),
            "t_s": [float(t_s.min()), float(t_s.max())]}


def _key(d: dict, key: str, where: str):
    if not isinstance(d, dict) or key not in d:
        raise CalibrationFileError(f"{where}: key {key!r} missing")
    return d[key]


def _numbers(value, shape: tuple, where: str) -> np.ndarray:
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise CalibrationFileError(f"{where}: not an array of numbers") from None
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise CalibrationFileError(f"{where}: expected {shape} finite numbers, got shape {a.shape}")
    return a


def _parameters(robot: Robot, block, path: Path) -> tuple:
    names = robot.table.names
    by_name = _key(block, "by_name", f"{path}: key 'parameters'")
    if not isinstance(by_name, dict) or list(by_name) != list(names):
        got = list(by_name) if isinstance(by_name, dict) else by_name
        raise CalibrationFileError(f"{path}: key 'parameters.by_name': expected the {robot.name}'s parameters "
                                   f"{', '.join(names[:3])}, ... ({len(names)}), got {len(got)} names")
    theta, std = np.empty(len(names)), np.empty(len(names))
    for i, n in enumerate(names):
        where = f"{path}: key 'parameters.by_name.{n}'"
        theta[i] = _numbers(_key(by_name[n], "identified", where), (), f"{where}.identified")
        std[i] = _numbers(_key(by_name[n], "std", where), (), f"{where}.std")
    free = _key(block, "free", f"{path}: key 'parameters'")
    if not isinstance(free, list) or not set(free) <= set(names) or len(set(free)) != len(free):
        raise CalibrationFileError(f"{path}: key 'parameters.free': expected distinct names of the {robot.name}'s "
                                   "parameters")
    cov = _numbers(_key(block, "covariance", f"{path}: key 'parameters'"), (len(free), len(free)),
                   f"{path}: key 'parameters.covariance'")
    return theta, std, tuple(free), cov


def read_calibration(path, robot: str | None = None) -> Calibration:
    """Read and check a calibration file (of ``robot`` when given).

    Raises:
        CalibrationFileError: the file cannot be read, is not a calibration file of this format
            and version, is another robot's, or a key is missing or wrong (the message names it).
    """
    path = Path(path)
    d = read_json_file(path, "calibration file", CalibrationFileError)
    if not isinstance(d, dict):
        raise CalibrationFileError(f"{path}: not a calibration file (a JSON object with key 'format')")
    if d.get("format") != CALIBRATION_FORMAT:
        raise CalibrationFileError(f"{path}: key 'format' is {d.get('format')!r}, not {CALIBRATION_FORMAT!r}: not a "
                                   "calibration file written by pipeline.run or pipeline.discover")
    if d.get("version") != CALIBRATION_VERSION:
        raise CalibrationFileError(f"{path}: key 'version' is {d.get('version')!r}; this reader reads version "
                                   f"{CALIBRATION_VERSION} only")
    for key in KEYS:
        _key(d, key, str(path))
    name = d["robot"]
    if name not in ROBOTS:
        raise CalibrationFileError(f"{path}: key 'robot': {name!r} is no registered robot ({', '.join(ROBOTS)})")
    if robot is not None and name != robot:
        raise CalibrationFileError(f"{path}: key 'robot' is {name!r}, a calibration of another robot than the {robot}")
    try:
        rob = robot_from_description(name, d["nominal_geometry"])
    except (KeyError, TypeError, ValueError) as exc:
        raise CalibrationFileError(f"{path}: key 'nominal_geometry' is not a {name} description ({exc})") from None
    theta, std, free, cov = _parameters(rob, d["parameters"], path)
    frames, frames_std = {}, {}
    if not isinstance(d["measurement_frames"], dict):
        raise CalibrationFileError(f"{path}: key 'measurement_frames': expected an object of sessions")
    for s, block in d["measurement_frames"].items():
        what = f"key 'measurement_frames.{s}'"
        if not isinstance(block, dict):
            raise CalibrationFileError(f"{path}: {what}: expected an object with keys translation_mm, rotation_rad")
        try:
            frames[s] = frame_from_dict({k: v for k, v in block.items() if k != "std"}, what)
            frames_std[s] = frame_from_dict(block.get("std", frame_to_dict(np.zeros(6))), f"{what[:-1]}.std'")
        except ValueError as exc:
            raise CalibrationFileError(f"{path}: {exc}") from None
    targets = None if d["targets"] is None else _numbers(d["targets"], (len(d["targets"]), 3), f"{path}: key 'targets'")
    try:
        noise = SensorNoise(**d["declared_noise"])
    except (TypeError, ValueError) as exc:
        raise CalibrationFileError(f"{path}: key 'declared_noise': {exc}") from None
    if not isinstance(d["effects"], list):
        raise CalibrationFileError(f"{path}: key 'effects': expected a list of effect records")
    cal = Calibration(robot=rob, theta=theta, std=std, free=free, covariance=cov, frames=frames, frames_std=frames_std,
                      targets=targets, records=tuple(d["effects"]), validity=d["validity"], noise=noise,
                      recording=d["recording"], produced_by=str(d["produced_by"]))
    try:  # every record rebuilt once (a law's channels are not needed to check its terms)
        cal.effects(where="effects")
    except ValueError as exc:
        raise CalibrationFileError(f"{path}: key {exc}") from None
    _validity(cal, path)
    return cal


def _validity(cal: Calibration, path: Path) -> None:
    v, r = cal.validity, cal.robot
    if not isinstance(v, dict):
        raise CalibrationFileError(f"{path}: key 'validity': expected an object")
    for key, n in (("pose_min", r.pose_dim), ("pose_max", r.pose_dim), ("joint_min", r.n_chains),
                   ("joint_max", r.n_chains), ("t_s", 2)):
        _numbers(_key(v, key, f"{path}: key 'validity'"), (n,), f"{path}: key 'validity.{key}'")
