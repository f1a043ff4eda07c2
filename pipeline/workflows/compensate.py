"""Compensated commands from a calibration file, as a library function.

:func:`run_compensation` does what ``python -m pipeline.compensate`` does: read the calibration
file (:meth:`calib.calibration.Calibration.read`) and the targets (:mod:`pipeline.formats.targets`),
take the targets out of the instrument's frame when asked, compute the commands
(:meth:`calib.calibration.Calibration.compensation`, whose commands ``Calibration.commands`` gives:
the identified geometry, and every found effect the command sequence lets it invert) and write
them as a command file (the targets in the base frame, the commands, ``t_s`` when the targets
have it; with a lab's mapping file the commands again in its joint readings, revolutions or
counts, ``reading = (joint / unit - zero) / scale`` by the map's ``[joints]`` (or a session's
``[sessions.NAME.joints]``); a JSON sidecar saying what was compensated and what not, and why).
Targets outside the domain the calibration saw (the box of its platform poses in the base frame,
and its joints' ranges) are named in warnings: the commands are extrapolations there.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib.calibration import Calibration
from calib.compensation import Compensation, compensated_commands
from calib.measurement import compose, invert_frame
from calib.robot import KinematicsError

from pipeline.formats import (TIME_COLUMN, ResultSet, Targets, TargetsError, check_outputs, check_plausible_parameters,
                              columns, command_columns, joint_readings, read_map, read_targets, row_message,
                              session_joint_mapping, sidecar_path, write_command_rows)

__all__ = ["TARGET_FRAMES", "CompensateSettings", "CompensationReport", "run_compensation", "domain_warnings",
           "controller_readings", "proof_in_the_testbed", "reachable_targets", "check_target_units", "TARGET_UNITS"]

#: The frames a target file may be in: the robot's base, or an instrument frame the calibration found.
TARGET_FRAMES = ("base", "instrument")
#: Rows listed in one warning at most.
ROWS_LISTED = 8


@dataclass(frozen=True)
class CompensateSettings:
    """What :func:`run_compensation` does (``python -m pipeline.compensate --help`` for each field).

    Attributes:
        calibration: the calibration file.
        targets: the target file.
        out: the command file to write (CSV; its sidecar beside it, ``.json``).
        frame: the targets' frame (:data:`TARGET_FRAMES`).
        session: with ``frame == "instrument"``, the session whose frame it is (needed when the
            calibration has several); with ``map``, the session whose joint mapping is used.
        geometry_only: compensate the geometry alone (the effects found left out).
        overwrite: allow replacing an existing command file.
        map: a lab's mapping file (TOML, :mod:`pipeline.formats.lab_export`): the commands also
            in its joint readings, in its joint columns (None: in the robot's unit alone).
    """

    calibration: Path
    targets: Path
    out: Path
    frame: str = "base"
    session: str | None = None
    geometry_only: bool = False
    overwrite: bool = False
    map: Path | None = None


@dataclass
class CompensationReport:
    """What :func:`run_compensation` did."""

    calibration: Calibration
    targets: Targets
    poses: np.ndarray
    compensation: Compensation
    warnings: list = field(default_factory=list)
    paths: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)


def _rows(mask: np.ndarray) -> str:
    rows = [int(i) + 1 for i in np.flatnonzero(mask)]
    more = f" and {len(rows) - ROWS_LISTED} more" if len(rows) > ROWS_LISTED else ""
    return ", ".join(map(str, rows[:ROWS_LISTED])) + more


def _outside(names, units, lows, highs, values) -> tuple[np.ndarray, list[str]]:
    """Rows with a value outside its range, and per name the count and the range, in words."""
    mask = np.zeros(len(values), dtype=bool)
    words = []
    for name, unit, lo, hi, col in zip(names, units, lows, highs, values.T):
        bad = (col < lo) | (col > hi)
        if bad.any():
            mask |= bad
            words.append(f"{name} in {int(bad.sum())} outside [{lo:.6g}, {hi:.6g}] {unit}")
    return mask, words


def domain_warnings(cal: Calibration, poses: np.ndarray, commands: np.ndarray, t_s, where) -> list[str]:
    """Warnings naming the targets outside the domain the calibration saw: a pose coordinate
    outside the box of the calibration poses, a command outside a joint's recorded range, a time
    past the recording's span (a drift extrapolated); one line each."""
    v, robot, out = cal.validity, cal.robot, []
    mask, words = _outside(robot.pose_names, robot.pose_units, v["pose_min"], v["pose_max"], poses)
    if mask.any():
        out.append(f"{where}: row(s) {_rows(mask)}: outside the box of the calibration poses ({'; '.join(words)}): "
                   "the commands extrapolate the calibration there")
    mask, words = _outside(robot.joint_names, [robot.joint_unit] * robot.n_chains, v["joint_min"], v["joint_max"],
                           commands)
    if mask.any():
        out.append(f"{where}: row(s) {_rows(mask)}: commands outside the joints' recorded ranges ({'; '.join(words)})")
    if t_s is not None:
        mask, words = _outside(["t_s"], ["s"], [v["t_s"][0]], [v["t_s"][1]], t_s[:, None])
        if mask.any():
            out.append(f"{where}: row(s) {_rows(mask)}: times outside the recording's span ({words[0]}): effects "
                       "that follow time are extrapolated")
    return out


def _base_poses(cal: Calibration, settings: CompensateSettings, poses: np.ndarray) -> tuple[np.ndarray, str]:
    if settings.frame not in TARGET_FRAMES:
        raise ValueError(f"--frame {settings.frame}: expected one of {', '.join(TARGET_FRAMES)}")
    if settings.frame == "base":
        if settings.session is not None and settings.map is None:
            raise ValueError("--session: only with --frame instrument or --map")
        return poses, "base frame"
    if not cal.frames:
        raise ValueError(f"--frame instrument: {settings.calibration} has no instrument frame (its recording was in "
                         "the base frame); use --frame base")
    session = settings.session
    if session is None:
        if len(cal.frames) > 1:
            raise ValueError(f"--frame instrument: {settings.calibration} has {len(cal.frames)} sessions' frames "
                             f"({', '.join(cal.frames)}); name one with --session")
        session = next(iter(cal.frames))
    if session not in cal.frames:
        raise ValueError(f"--session {session}: not a session of {settings.calibration} ({', '.join(cal.frames)})")
    return compose(invert_frame(cal.frames[session]), cal.robot, poses), f"instrument frame of session {session}"


def controller_readings(cal: Calibration, settings: CompensateSettings) -> tuple[dict, dict]:
    """``(readings, what the sidecar says of them)`` of ``settings.map`` (``(None, {})`` without
    one): ``readings(commands)`` gives ``{lab column: (N,) reading}`` of (N, C) commands by the
    map's checked joint mapping (``settings.session``'s own where it has one)."""
    if settings.map is None:
        return None, {}
    lab_map = read_map(settings.map)
    if lab_map.robot.name != cal.robot.name:
        raise ValueError(f"--map {settings.map}: maps a {lab_map.robot.name}; {settings.calibration} calibrates a "
                         f"{cal.robot.name}")
    names = lab_map.tables["sessions"].get("names")
    own = lab_map.tables["sessions"].get("joints", {})
    if settings.session is not None and settings.session not in own and names is not None \
            and settings.session not in names:
        raise ValueError(f"--session {settings.session}: not a session of {settings.map} ({', '.join(names)})")
    spec = session_joint_mapping(lab_map, settings.session)
    taken = set(command_columns(cal.robot)) | {TIME_COLUMN}
    clash = [c for c in spec["columns"] if c in taken]
    if clash:
        raise ValueError(f"--map {settings.map}: joint column {clash[0]!r} is one of the command file's own columns")
    about = {"map": str(settings.map), "session": settings.session, "columns": list(spec["columns"]),
             "reading": spec["reading"], "unit": spec["unit"], "scale": spec["scale"].tolist(),
             "zero": spec["zero"].tolist()}
    return (lambda commands: dict(zip(spec["columns"], joint_readings(spec, cal.robot, commands).T))), about


#: The unit mistakes a target file is checked for: (name, the columns' kind, factor to the
#: file's declared unit, what the columns then seem to hold).
TARGET_UNITS = (("degrees", "angles", np.pi / 180.0, "times pi / 180"),
                ("metres", "positions", 1000.0, "times 1000"))


def reachable_targets(robot, theta, poses: np.ndarray) -> np.ndarray:
    """(N,) bool: the targets (base frame) the machine ``theta`` reaches with every joint inside
    its range."""
    limits = robot.joint_limits()

    def ok(q):
        return np.all(np.isfinite(q) & (q >= limits[:, 0]) & (q <= limits[:, 1]), axis=1)
    try:
        return ok(robot.inverse_kinematics(theta, poses))
    except KinematicsError:
        out = np.zeros(len(poses), dtype=bool)
        for k in range(len(poses)):
            try:
                out[k] = ok(robot.inverse_kinematics(theta, poses[k:k + 1]))[0]
            except KinematicsError:
                pass
        return out


def check_target_units(cal: Calibration, settings: CompensateSettings, written: np.ndarray,
                       poses: np.ndarray) -> None:
    """Refuse targets in the wrong unit, diagnosed as a recording's are: some targets (``poses``,
    base frame, of ``written`` in the file's frame) the identified machine cannot reach, and
    every one reachable once the angle columns are read as degrees, or the position columns as
    metres (:data:`TARGET_UNITS`, each alone or both). Nothing is refused that is reachable as
    written, nor where no conversion makes every target reachable (the row is named then).

    Raises:
        TargetsError: naming the target file, the column of the largest value, the conversion and
            the counts of reachable targets.
    """
    robot = cal.robot
    if len(poses) == 0:
        return
    as_written = reachable_targets(robot, cal.theta, poses)
    if as_written.all():
        return
    angle = robot.angle_pose_mask
    names = columns(robot)[1]
    units = [u for u in TARGET_UNITS if u[1] == "positions" or angle.any()]
    for chosen in [[u] for u in units] + ([units] if len(units) > 1 else []):
        converted = np.array(written, dtype=float)
        for _, kind, factor, _ in chosen:
            mask = angle if kind == "angles" else ~angle
            converted[:, mask] *= factor
        base, _ = _base_poses(cal, settings, converted)
        if not reachable_targets(robot, cal.theta, base).all():
            continue
        words = []
        for name, kind, factor, fix in chosen:
            mask = angle if kind == "angles" else ~angle
            cols = [c for c, m in zip(names, mask) if m]
            k = int(np.argmax(np.where(mask, np.abs(written).max(axis=0), -np.inf)))
            value = float(np.abs(written[:, k]).max())
            unit = robot.pose_units[k]
            words.append(f"column {names[k]}: values up to {value:.4g} look like {name} (as {unit}, "
                         f"{value:.4g} {unit}; the columns {', '.join(cols)} hold {unit})")
        fixes = " and ".join(f"{c[0]} ({c[3]})" for c in chosen)
        raise TargetsError(f"{settings.targets}, {'; '.join(words)}: {int((~as_written).sum())} of {len(poses)} targets "
                           f"are unreachable as written (first row {int(np.argmin(as_written)) + 1}), and as {fixes} "
                           f"every target is reachable by the calibrated {robot.name}")


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def run_compensation(settings: CompensateSettings) -> CompensationReport:
    """Read, compensate, write (see the module docstring).

    Raises:
        ValueError: a bad calibration or target file, flag or target the machine cannot reach
            (the message names the file, the key, or the row and column).
        FileExistsError: the command file exists and ``overwrite`` is off.
    """
    cal = Calibration.read(settings.calibration)
    check_plausible_parameters(cal, settings.calibration)  # an absurd parameter is the calibration file's
    readings, readings_about = controller_readings(cal, settings)
    out = Path(settings.out)
    if out.suffix.lower() == ".json":
        raise ValueError(f"--out {out}: a command file is a CSV (its sidecar gets the .json)")
    check_outputs({"--out": out, "--out (sidecar)": sidecar_path(out)}, overwrite=settings.overwrite)
    tg = read_targets(settings.targets, cal.robot)
    poses, frame_words = _base_poses(cal, settings, tg.poses)
    check_target_units(cal, settings, tg.poses, poses)
    try:
        comp = cal.compensation(poses, tg.t_s, channels=tg.channels, geometry_only=settings.geometry_only)
    except KinematicsError as exc:
        raise ValueError(f"{row_message(exc, settings.targets, np.arange(len(poses)))}: the identified machine "
                         "cannot reach it") from None
    warnings = [f"{name} not compensated: {why}" for name, why in comp.left_out.items()]
    if not comp.converged:
        warnings.append(f"the compensation did not converge in {comp.iterations} iterations (last change "
                        f"{comp.largest_step:.3g} {cal.robot.joint_unit}): the effects found are too large to invert "
                        "this way")
    warnings += domain_warnings(cal, poses, comp.commands, tg.t_s, settings.targets)
    summary = {"robot": cal.robot.name, "targets": len(poses), "targets_frame": frame_words,
               "calibration": {"path": str(settings.calibration), "sha256": _sha256(settings.calibration),
                               "produced_by": cal.produced_by, "recording": cal.recording},
               "targets_file": {"path": str(settings.targets), "sha256": _sha256(settings.targets)},
               "geometry_only": settings.geometry_only, "compensated": list(comp.compensated),
               "not_compensated": comp.left_out, "iterations": comp.iterations, "converged": comp.converged,
               "largest_physics_correction": float(np.max(np.abs(comp.displacement))) if len(poses) else 0.0,
               "joint_unit": cal.robot.joint_unit, "warnings": warnings,
               **({"controller_readings": readings_about} if readings_about else {})}
    paths = {"commands": out, "sidecar": sidecar_path(out)}
    with ResultSet(paths, overwrite=settings.overwrite, flags={"commands": "--out", "sidecar": "--out"}) as files:
        with open(files.temp("commands"), "w", newline="") as commands:  # streamed: a large file grows
            write_command_rows(commands, cal.robot, poses, comp.commands, tg.t_s,
                               readings(comp.commands) if readings else None)
        files.temp("sidecar").write_text(json.dumps({"robot": cal.robot.name, "produced_by": "pipeline.compensate",
                                                     **summary}, indent=1) + "\n")
        files.publish()
    return CompensationReport(calibration=cal, targets=tg, poses=poses, compensation=comp, warnings=warnings,
                              paths={k: str(v) for k, v in paths.items()}, summary=summary)


def proof_in_the_testbed(rec, n_targets: int = 50, seed: int = 0) -> dict:
    """The proof in the testbed: discover on the scenario recording ``rec``
    (:func:`pipeline.workflows.discovery.discover`, no re-simulation), then command the MuJoCo
    machine that made it (:func:`pipeline.simulation.command_scenario_machine`) on ``n_targets``
    held-out targets of its workspace (``seed``; half at the recording's lightest payload and half
    at its heaviest where it has several) three ways: nominal commands, the geometry fitted
    alone compensated, the geometry and the physics found compensated (the calibration discovery
    gives, :attr:`pipeline.workflows.discovery.DiscoveryReport.calibration`).

    Returns:
        ``nominal``, ``geometry``, ``physics``: mean position error of the settled poses (noise-free),
        mm; ``floor``: the discovery's noise floor, mm; ``summary``: the discovery's summary;
        ``calibration``: the :class:`calib.calibration.Calibration` it gives;
        ``compensation``: the :class:`calib.compensation.Compensation` with physics.
    """
    from pipeline.simulation import command_scenario_machine, heldout_payloads, heldout_targets

    from .discovery import discover

    robot = rec.robot
    report = discover(rec, seed=0, resim=False)
    cal = report.calibration
    targets, t_s = heldout_targets(rec, n_targets, seed)
    channels = heldout_payloads(rec, n_targets)  # a recording at several payloads: the targets at two
    position = ~robot.angle_pose_mask

    def error(commands):
        reached = command_scenario_machine(rec, commands, t_s, channels)
        return float(np.mean(np.linalg.norm((reached - targets)[:, position], axis=1)))

    physics = cal.compensation(targets, t_s, channels=channels)
    geometry = compensated_commands(robot, report.discovery.geometry.theta, targets, [], t_s=t_s)
    return {"nominal": error(robot.inverse_kinematics(robot.table.nominal, targets)), "geometry": error(geometry.commands),
            "physics": error(physics.commands), "floor": report.summary["noise_floor_mm"], "summary": report.summary,
            "calibration": cal, "compensation": physics}
