"""The calibration: what a calibration found, one object from the fit to the controller.

:class:`Calibration` bundles the robot, the identified parameters with their covariance, the
instrument frames, the targets, the effects found (:class:`calib.effects.records.EffectRecord`
objects, rebuilt as :class:`calib.effects.records.FittedEffect` ones by
:meth:`Calibration.fitted_effects`), the validity domain, the declared noise and the provenance. ``pipeline.run`` and ``pipeline.discover`` make it; it gives the compensated
commands (:meth:`Calibration.commands`), where the identified machine goes
(:meth:`Calibration.predict`), and its deliveries (:meth:`Calibration.to_linuxcnc`,
:meth:`Calibration.to_mjcf`, :meth:`Calibration.report`: :data:`DELIVERY_PACKAGE`).

The file edge (:meth:`Calibration.read`, :meth:`Calibration.write`): ``NAME.calibration.json``,
which holds

- ``format`` (:data:`CALIBRATION_FORMAT`) and ``version`` (:data:`CALIBRATION_VERSION`);
- ``robot`` and its ``nominal_geometry`` (``Robot.description()``, mm and rad);
- ``parameters``: every parameter of the robot's table by name: ``nominal``, ``identified``,
  ``error`` (identified minus nominal), ``std`` and ``unit``; ``free`` (the names identified) and
  ``covariance`` (free by free, parameter units, in the order of ``free``);
- ``measurement_frames``: each session's instrument frame relative to the base
  (``{"translation_mm", "rotation_rad"}``, with ``std``), empty when the data were in the base
  frame; ``targets``: the target offsets on the platform (mm) or null;
- ``effects``: the effects found with their coefficients (a record each,
  :meth:`calib.effects.records.EffectRecord.to_dict`: name, granularity, coefficients by name
  with std and unit, searched parameter, a compliance's reference payload, and a law's terms for
  a proposed or kept law); empty for a run;
- ``validity``: the domain the calibration saw: pose box (``pose_min``/``pose_max`` by pose
  coordinate: the platform poses of the calibration rows in the base frame, by the identified
  model's forward kinematics, not what the instrument reported), joint ranges (``joint_min``/``joint_max``), time span ``t_s``;
- ``declared_noise``; ``recording``: the input's file name and SHA-256 (CSV and sidecar), or the
  simulated scenario in words; ``produced_by``: the command; ``rereferenced_from`` (only in a
  calibration re-referenced from another, :mod:`calib.rereference`): the calibration it holds the
  geometry of, ``{"path", "sha256"}`` (a file without the key reads as before).

A file of another format, version or robot, or one lacking a key, is refused with one line
naming the file and the key (:class:`CalibrationFileError`). Floats are written with ``repr``'s
precision: a file read and written again is the same text.

Deliveries (:meth:`Calibration.deliver`, ``to_linuxcnc``, ``to_mjcf``, ``report``) are written by
the one registry of deliveries, :data:`DELIVERY_PACKAGE` (``pipeline.deliveries``, which
``python -m pipeline.export`` uses too), looked up by that name when a delivery is asked for:
calib imports nothing of pipeline, and says so in one line where pipeline is not installed. The
controllers' mathematics stays in calib (:mod:`calib.linuxcnc`).
"""

from __future__ import annotations

import json
import re
import warnings
from dataclasses import dataclass, field
from importlib import import_module
from pathlib import Path

import numpy as np

# calib.compensation and calib.effects.records (the effects' registry, SciPy's statistics behind
# discovery) are imported where a calibration file is read, its effects rebuilt or its commands
# computed: writing a calibration file loads neither (its effects' records write themselves).
from .files import atomic_write, read_json_file
from .measurement import frame_from_dict, frame_to_dict
from .noise import SensorNoise
from .robot import KinematicsError, Robot
from .robots import ROBOTS, robot_from_description

__all__ = ["CALIBRATION_FORMAT", "CALIBRATION_VERSION", "CALIBRATION_SUFFIX", "Calibration", "CalibrationFileError",
           "write_calibration", "read_calibration", "calibration_text", "validity_domain",
           "DELIVERY_PACKAGE", "delivery_registry"]

#: The format's name, written and checked.
CALIBRATION_FORMAT = "parallel-calib calibration"
#: The format's version: a reader refuses any other.
CALIBRATION_VERSION = 1
#: A calibration file's name is the run's name with this suffix.
CALIBRATION_SUFFIX = ".calibration.json"
#: The keys every calibration file has.
KEYS = ("format", "version", "robot", "nominal_geometry", "produced_by", "recording", "declared_noise", "parameters",
        "measurement_frames", "targets", "effects", "validity")
#: The package holding the one registry of deliveries, looked up by name when a delivery is asked
#: for (:func:`delivery_registry`): the one name of pipeline in calib (tests/test_architecture.py).
DELIVERY_PACKAGE = "pipeline.deliveries"


class CalibrationFileError(ValueError):
    """A calibration file cannot be used; the message names the file and the key."""


def delivery_registry():
    """The package of the deliveries' registry (:data:`DELIVERY_PACKAGE`), imported by name: its
    ``DELIVERIES`` and ``deliver_calibration(cal, to, out, overwrite=...)``.

    Raises:
        ValueError: pipeline, which holds the deliveries, is not installed (one line saying so).
    """
    try:
        return import_module(DELIVERY_PACKAGE)
    except ModuleNotFoundError as exc:
        if exc.name not in ("pipeline", DELIVERY_PACKAGE):
            raise
        raise ValueError(f"the deliveries of a calibration are written by {DELIVERY_PACKAGE}, which is not "
                         "installed (calib alone computes commands and predictions; pip install parallel-calib "
                         "installs both)") from None


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
        effects: the effects found (:class:`calib.effects.records.EffectRecord`, each with its
            granularity, coefficients with std and unit, searched parameter, law's terms);
            :meth:`fitted_effects` rebuilds them.
        validity: the domain the calibration saw (``pose_min``, ``pose_max``, ``joint_min``,
            ``joint_max``: lists in the robot's order; ``t_s``: ``[first, last]``).
        noise: the declared noise of the recording.
        recording: where the data came from.
        produced_by: the command that wrote it.
        rereferenced_from: ``{"path", "sha256"}`` of the calibration whose geometry and effects
            this one holds with its joint zeros and frames re-referenced to a later session
            (:mod:`calib.rereference`); None for a calibration of its own.
        source: the file it was read from (None: made in memory); not written to the file.
    """

    robot: Robot
    theta: np.ndarray
    std: np.ndarray
    free: tuple
    covariance: np.ndarray
    frames: dict = field(default_factory=dict)
    frames_std: dict = field(default_factory=dict)
    targets: np.ndarray | None = None
    effects: tuple = ()
    validity: dict = field(default_factory=dict)
    noise: SensorNoise = field(default_factory=SensorNoise)
    recording: dict = field(default_factory=dict)
    produced_by: str = ""
    rereferenced_from: dict | None = None
    source: Path | None = None

    # ------------------------------------------------------------------ the file edge

    @classmethod
    def read(cls, path, robot: str | None = None) -> "Calibration":
        """Read and check a calibration file (of ``robot`` when given).

        Raises:
            CalibrationFileError: the file cannot be read, is not a calibration file of this
                format and version, is another robot's, or a key is missing or wrong (the
                message names the file and the key).
        """
        return read_calibration(path, robot)

    def write(self, path, *, overwrite: bool = False) -> Path:
        """Write the calibration file ``path`` atomically (an existing file refused without
        ``overwrite``); returns ``path``.

        Raises:
            FileExistsError: ``path`` exists and ``overwrite`` is False.
        """
        return write_calibration(path, self, overwrite=overwrite)

    def fitted_effects(self, channels: dict | None = None, where: str = "effects") -> list:
        """The effects found, rebuilt (:meth:`calib.effects.records.EffectRecord.fitted`):
        :class:`calib.effects.records.FittedEffect` s on the calibration's robot, a law bound to
        its recorded ``channels`` (``{name: (N,)}``, one value per row acted on).

        Raises:
            ValueError: a record that does not fit the robot (names ``where[k]`` and the key).
        """
        return [e.fitted(self.robot, channels, where=f"{where}[{k}]") for k, e in enumerate(self.effects)]

    def to_dict(self) -> dict:
        """The calibration file's JSON object (see the module docstring)."""
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
                "effects": [e.to_dict() for e in self.effects], "validity": self.validity,
                **({} if self.rereferenced_from is None else {"rereferenced_from": self.rereferenced_from})}


    # ------------------------------------------------------------------ the machine

    def compensation(self, targets, t_s=None, previous=None, *, channels: dict | None = None,
                     geometry_only: bool = False):
        """The compensation of ``targets`` (:func:`calib.compensation.compensated_commands`: the
        identified geometry and every effect found that the command sequence lets it invert),
        with what was compensated and what not, and why. :meth:`commands` is its commands.

        Args:
            targets: (N, D) target poses in the base frame, the robot's pose units, in the order
                they will be commanded.
            t_s: (N,) each target's time since the machine started, s (None: effects that
                follow time are left out).
            previous: (M, C) the commands given before these since the machine started (the
                history a dead band follows); None: the machine starts at its home pose.
            channels: ``{name: (N,)}`` recorded channels a law or a compliance follows
                (``payload_kg``).
            geometry_only: the identified geometry alone (the effects left out).
        """
        channels = dict(channels or {})
        effects = [] if geometry_only else self.fitted_effects(channels)
        from .compensation import compensated_commands

        return compensated_commands(self.robot, self.theta, targets, effects, t_s=t_s, channels=channels,
                                    previous=previous)

    def commands(self, targets, /, t_s=None, previous=None, **channels) -> np.ndarray:
        """(N, C) the joint commands (the robot's joint unit) that put the identified machine at
        ``targets``: the numbers ``python -m pipeline.compensate`` writes for base-frame targets.

        Args:
            targets: (N, D) target poses in the base frame, the robot's pose units, in order.
            t_s: (N,) their times since the machine started, s (None: effects that follow time
                are not compensated).
            previous: (M, C) the commands given before since the machine started (pass the
                last call's commands to go on from them); None: from the home pose.
            **channels: recorded channels by name, (N,) each: ``payload_kg=...`` for a compliance
                fitted at several payloads, a law's channel.

        An effect left out (its reason in :meth:`compensation`'s ``left_out``) is said in a
        :class:`UserWarning`.

        Raises:
            KinematicsError: a target the identified machine cannot reach, or a command past a
                joint's stroke (names the row).
            ValueError: arrays of the wrong shape.
        """
        comp = self.compensation(targets, t_s, previous, channels=channels)
        for name, why in comp.left_out.items():
            warnings.warn(f"{name} not compensated: {why}", stacklevel=2)
        if not comp.converged:
            warnings.warn(f"the compensation did not converge in {comp.iterations} iterations (last change "
                          f"{comp.largest_step:.3g} {self.robot.joint_unit})", stacklevel=2)
        return comp.commands

    def predict(self, joints, /, t_s=None, previous=None, **channels) -> np.ndarray:
        """(N, D) where the identified machine goes when ``joints`` (N, C) are commanded in this
        order: the forward kinematics of the identified parameters at the joints the effects
        displace them to (:func:`calib.compensation.machine_poses`), base frame, the robot's
        pose units. The effects acted on are those :meth:`commands` compensates with the same
        ``t_s``, ``previous`` and ``channels``, so ``predict(commands(targets))`` is
        ``targets``.

        Raises:
            KinematicsError: joints the identified geometry cannot assemble at (names the row).
            ValueError: arrays of the wrong shape.
        """
        channels = dict(channels)
        from .compensation import machine_poses

        return machine_poses(self.robot, self.theta, joints, self.fitted_effects(channels), t_s=t_s,
                             channels=channels, previous=previous)

    # ------------------------------------------------------------------ deliveries

    def deliver(self, to: str, out, *, overwrite: bool = False):
        """Write the delivery ``to`` (a name in ``pipeline.deliveries.DELIVERIES``, the registry
        ``python -m pipeline.export`` offers: ``linuxcnc``, ``mjcf``, ``report``) of the
        calibration to ``out``; returns the delivery's report (the files ``pipeline.export --to
        TO`` writes of the file it was read from).

        Raises:
            ValueError: no delivery ``to`` is registered (names it and the ones installed), the
                delivery refuses the calibration (a robot it does not accept, in its one line), or
                pipeline is not installed.
            FileExistsError: an output exists and ``overwrite`` is False.
        """
        return delivery_registry().deliver_calibration(self, to, out, overwrite=overwrite)

    def to_linuxcnc(self, folder, *, overwrite: bool = False):
        """The LinuxCNC configuration in ``folder`` (the files ``python -m pipeline.export --to
        linuxcnc`` writes): :meth:`deliver` ``("linuxcnc", folder)``."""
        return self.deliver("linuxcnc", folder, overwrite=overwrite)

    def to_mjcf(self, path, *, overwrite: bool = False):
        """The identified machine as a MuJoCo model file ``path``: :meth:`deliver` ``("mjcf", path)``."""
        return self.deliver("mjcf", path, overwrite=overwrite)

    def report(self, path, *, overwrite: bool = False):
        """The lab's report of the calibration at ``path``: :meth:`deliver` ``("report", path)``."""
        return self.deliver("report", path, overwrite=overwrite)


#: A JSON list of numbers spread over lines (each number on its own, as ``json.dumps`` indents it).
NUMBER_LIST = re.compile(r"\[\s+((?:-?[0-9][0-9.eE+-]*,\s+)*-?[0-9][0-9.eE+-]*)\s+\]")


def calibration_text(cal: Calibration) -> str:
    """The JSON text of a calibration file (indented; a list of numbers on one line)."""
    text = json.dumps(cal.to_dict(), indent=1)
    return NUMBER_LIST.sub(lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]", text) + "\n"


def write_calibration(path, cal: Calibration, *, overwrite: bool = False) -> Path:
    """Write ``cal`` to ``path`` atomically (an existing file refused without ``overwrite``)."""
    return atomic_write(path, calibration_text(cal), overwrite=overwrite)


def validity_domain(robot: Robot, poses, joints, t_s, theta=None) -> dict:
    """The domain a calibration saw: the box of its platform poses in the base frame, its joints'
    ranges and its time span.

    Args:
        poses: (N, D) the calibration rows' poses in the base frame (the measured ones taken out
            of the instrument frame), mm and rad.
        joints: (N, C) their joints; t_s: (N,) their times, s.
        theta: (P,) the identified parameters: the box is then over the platform poses the
            identified model puts at ``joints`` (its forward kinematics, the poses compensation's
            targets are commanded in): what the instrument reports beyond the platform's pose (a
            capture body's constant tilt, the noise) is not the platform's. A row it cannot reach
            keeps its ``poses`` row. The box also spans the nominal model's forward kinematics at
            ``joints``: the poses the lab commanded (exactly so where its commands came from the
            nominal inverse kinematics), in the terms its later targets are given. Level poses
            cannot tell a capture body's constant tilt from the platform's, so the fit may put some
            of it into the geometry; the commanded level poses keep level targets inside the box.
            None: the box of ``poses``. Likewise the joints' ranges span the recorded joints and
            the identified model's inverse kinematics of the commanded poses (the commands
            compensation gives for what the lab commanded).
    """
    poses, joints, t_s = (np.asarray(a, dtype=float) for a in (poses, joints, t_s))
    commands = joints
    if theta is not None:
        identified = platform_poses(robot, theta, joints, poses)
        commanded = platform_poses(robot, robot.table.nominal, joints, identified)
        poses = np.vstack([identified, commanded])
        commands = np.vstack([joints, compensated_joints(robot, theta, commanded)])
    return {"pose_names": list(robot.pose_names), "pose_min": poses.min(axis=0).tolist(),
            "pose_max": poses.max(axis=0).tolist(), "joint_names": list(robot.joint_names),
            "joint_min": commands.min(axis=0).tolist(), "joint_max": commands.max(axis=0).tolist(),
            "t_s": [float(t_s.min()), float(t_s.max())]}


def compensated_joints(robot: Robot, theta, poses) -> np.ndarray:
    """(M, C) the identified model's inverse kinematics of ``poses`` (N, D), the rows it cannot
    reach left out."""
    try:
        return robot.inverse_kinematics(theta, poses)
    except KinematicsError:
        rows = []
        for k in range(len(poses)):
            try:
                rows.append(robot.inverse_kinematics(theta, poses[k:k + 1])[0])
            except KinematicsError:
                pass
        return np.array(rows).reshape(-1, robot.n_chains)


def platform_poses(robot: Robot, theta, joints, poses) -> np.ndarray:
    """(N, D) the identified model's forward kinematics at ``joints`` (N, C), started at ``poses``
    (N, D, base frame), a row it cannot reach keeping its ``poses`` row."""
    try:
        return robot.forward_kinematics(theta, joints, initial=poses)
    except KinematicsError:
        out = np.array(poses, dtype=float)
        for k in range(len(out)):
            try:
                out[k] = robot.forward_kinematics(theta, joints[k:k + 1], initial=poses[k:k + 1])[0]
            except KinematicsError:
                pass
        return out


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
    from .effects.records import EffectRecord

    try:
        effects = tuple(EffectRecord.from_dict(e, f"effects[{k}]") for k, e in enumerate(d["effects"]))
    except ValueError as exc:
        raise CalibrationFileError(f"{path}: key {exc}") from None
    cal = Calibration(robot=rob, theta=theta, std=std, free=free, covariance=cov, frames=frames, frames_std=frames_std,
                      targets=targets, effects=effects, validity=d["validity"], noise=noise,
                      recording=d["recording"], produced_by=str(d["produced_by"]),
                      rereferenced_from=_origin(d, path), source=path)
    try:  # every record rebuilt once on the robot (a law's channels are not needed to check its terms)
        cal.fitted_effects(where="effects")
    except ValueError as exc:
        raise CalibrationFileError(f"{path}: key {exc}") from None
    _validity(cal, path)
    return cal


def _origin(d: dict, path: Path) -> dict | None:
    """The optional key ``rereferenced_from``: ``{"path", "sha256"}`` strings, or absent."""
    origin = d.get("rereferenced_from")
    if origin is None:
        return None
    if not isinstance(origin, dict) or not all(isinstance(origin.get(k), str) for k in ("path", "sha256")):
        raise CalibrationFileError(f"{path}: key 'rereferenced_from': expected an object with the strings path and "
                                   "sha256 (the calibration re-referenced)")
    return origin


def _validity(cal: Calibration, path: Path) -> None:
    v, r = cal.validity, cal.robot
    if not isinstance(v, dict):
        raise CalibrationFileError(f"{path}: key 'validity': expected an object")
    for key, n in (("pose_min", r.pose_dim), ("pose_max", r.pose_dim), ("joint_min", r.n_chains),
                   ("joint_max", r.n_chains), ("t_s", 2)):
        _numbers(_key(v, key, f"{path}: key 'validity'"), (n,), f"{path}: key 'validity.{key}'")
