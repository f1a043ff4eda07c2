"""One calibration run for any registered robot: simulate (or read) measurements, identify,
compensate, validate on held-out poses, write the recording, the summary and the ``.rrd``.

``python -m pipeline.run`` parses its flags into :class:`RunSettings`, calls
:func:`run_calibration` and prints the :class:`RunResult`'s summary. The summary has the same
keys for every robot.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.special import gammaincinv

from calib import paper
from calib.evidence import MIN_DETERMINED, ToleranceEstimate, tolerance_from_data
from calib.engine import IdentificationResult, gauge_representative, identify, integrated_error
from calib.measurement import frame_to_dict, identify_as_measured, identify_measured, instrument_measurements, \
    measured_gauge_representative, measurement_residuals
from calib.metrics import calibration_gain, iso9283_position, pose_error_norms, repeated_poses
from calib.noise import SensorNoise
from calib.outliers import find_outliers
from calib.robust import GROSS_ALPHA, find_gross_rows
from calib.crossval import crossvalidate
from calib.design import augment_poses
from calib.prior import ParameterPrior
from calib.robot import KinematicsError, Robot, check_joint_limits, pose_jacobian_of_parameters
from calib.robots import default_robot, reference_errors, reference_poses
from calib.workspace import reachable_poses
from pipeline.formats import (CALIBRATION_SUFFIX, Calibration, NameReservation, Recording, build_report, command_columns,
                              command_csv, output_folder, frame_session, render_html, row_message, session_measurement,
                              validity_domain)

__all__ = ["RunSettings", "RunResult", "AsRead", "run_calibration", "read_as_a_run_does", "machine_tolerance",
           "implausible_parameters", "IMPLAUSIBLE_TOLERANCES", "DEFAULT_CONFIGURATIONS", "DEFAULT_ROBOT", "ROW_NUMBERING",
           "default_name", "OUTPUT_EXTENSIONS"]

#: Calibration poses of a robot whose reference experiment names none.
DEFAULT_CONFIGURATIONS = 20
#: The robot simulated when none is named.
DEFAULT_ROBOT = "hexapod"
#: How every message, summary and view names a recording's rows.
ROW_NUMBERING = ("1-based data row of the recording, as a spreadsheet shows it below the header "
                 "(row k is file line k + 1)")


@dataclass(frozen=True)
class RunSettings:
    """What a run does (see ``python -m pipeline.run --help`` for each field)."""

    robot: str | None = None
    poses: str = "reference"
    design: str = "random"
    heldout: int = 50
    noise_mm: float = paper.PAPER_NOISE_MM
    noise_rad: float = 0.0
    noise_joint: float = 0.0
    noise_dist: str = "uniform"
    seed: int = 0
    method: str = "chainwise"
    solver: str | None = None
    weighted: bool = False
    gravity: bool = False
    payload_kg: float = 0.0
    stiffness: float | None = None
    friction: float = 0.0
    real: Path | None = None
    out: Path = Path("recordings")
    name: str | None = None
    overwrite: bool = False
    summary_json: Path | None = None
    report: Path | None = None
    keep_outliers: bool = False
    prior: bool = True
    tolerance: dict | None = None
    export_mjcf: Path | None = None


@dataclass
class AsRead:
    """A recording as a run reads it: the poses in the base frame (the instrument frame it
    registered taken out), the gross rows it named, what it found in summary keys.

    Attributes:
        recording: the recording with its poses in the (gauge) base frame, every row.
        gross_rows: 0-based rows of the recording named gross (left out of any fit).
        block: summary keys: ``gross_rows``, and ``measurement_frame``/``measurement_frame_std``
            where an instrument frame was registered.
    """

    recording: Recording
    gross_rows: list
    block: dict


@dataclass
class RunResult:
    """Everything a run produced."""

    summary: dict
    result: IdentificationResult
    paths: dict = field(default_factory=dict)
    #: The recording read from ``RunSettings.real`` (None for a simulated run).
    recording: Recording | None = None
    #: The recording as the run read it (None for a simulated run): what discovery analyses.
    as_read: AsRead | None = None


def default_name(settings: RunSettings) -> str:
    """``hexapod_paper`` for the hexapod's reference run, else ``<robot>_<poses>``, or the input's stem."""
    if settings.real is not None:
        return Path(settings.real).stem + "_calibrated"
    robot = settings.robot or DEFAULT_ROBOT
    if robot == "hexapod" and settings.poses == "reference":
        return "hexapod_paper"
    return f"{robot}_{Path(settings.poses).stem}"


OUTPUT_EXTENSIONS = (".rrd", ".csv", ".json", ".suggested_poses.csv", ".suggested_poses.json", CALIBRATION_SUFFIX)
#: Poses suggested when the measured ones leave parameter combinations to the prior.
SUGGESTED_POSES = 10


def _targets(robot: Robot, settings: RunSettings, seed) -> tuple[np.ndarray, str]:
    if settings.poses == "reference":
        poses = reference_poses(robot)
        if poses is not None:
            return poses, "the reference poses"
        return reachable_poses(robot, DEFAULT_CONFIGURATIONS, seed), f"{DEFAULT_CONFIGURATIONS} random poses"
    if settings.poses.endswith(".csv"):
        from pipeline.formats import read_command_file

        poses, _ = read_command_file(settings.poses, robot)
        return poses, f"{len(poses)} poses from {settings.poses}"
    n = int(settings.poses)
    if settings.design == "optimal":
        from pipeline.workflows.design import optimal_poses

        return optimal_poses(robot, n, seed=settings.seed), f"{n} D-optimal poses"
    return reachable_poses(robot, n, seed), f"{n} random poses"


def _simulate(robot: Robot, settings: RunSettings, noise: SensorNoise, progress):
    from mjcf.machine import MachineOptions
    from pipeline.simulation import Testbed

    seeds = np.random.SeedSequence(settings.seed).spawn(4)
    nominal = robot.table.nominal
    errors = reference_errors(robot, int(seeds[3].generate_state(1)[0]))
    actual = nominal + errors
    targets, what = _targets(robot, settings, seeds[0])
    heldout = reachable_poses(robot, settings.heldout, seeds[1]) if settings.heldout else np.zeros((0, robot.pose_dim))
    options = MachineOptions(gravity=settings.gravity, payload_kg=settings.payload_kg,
                             actuator_stiffness=settings.stiffness, joint_friction=settings.friction)
    bed = Testbed(robot, actual, options=options, noise=noise, seed=int(seeds[2].generate_state(1)[0]))
    cal = bed.measure(robot.inverse_kinematics(nominal, targets),
                      progress=lambda d, t: progress("measuring calibration poses", d, t))
    val = None
    if settings.heldout:
        val = bed.measure(robot.inverse_kinematics(nominal, heldout),
                          progress=lambda d, t: progress("measuring held-out poses (nominal commands)", d, t))
    scenario = f"{robot.name}: {what}, reference errors injected, simulated in MuJoCo"
    return dict(errors=errors, actual=actual, targets=targets, heldout=heldout, options=options, bed=bed, cal=cal, val=val,
                scenario=scenario)


def error_figures(norms: np.ndarray) -> dict:
    """``{"rms", "mean", "max"}`` of per-pose error norms (N,)."""
    return {"rms": float(np.sqrt(np.mean(norms ** 2))), "mean": float(norms.mean()), "max": float(norms.max())}


def _heldout_block(robot: Robot, before: np.ndarray, after: np.ndarray) -> dict:
    """Held-out position and orientation errors, before and after: the mean (``before``,
    ``after``), the largest after (``max_after``), and all three figures of each
    (``before_figures``, ``after_figures``: RMS, mean, max)."""
    pb, ob = pose_error_norms(robot, before)
    pa, oa = pose_error_norms(robot, after)

    def block(b, a):
        return {"before": float(b.mean()), "after": float(a.mean()), "max_after": float(a.max()),
                "before_figures": error_figures(b), "after_figures": error_figures(a)}

    return {"heldout_position_error_mm": block(pb, pa),
            "heldout_orientation_error_rad": block(ob, oa) if robot.angle_pose_mask.any() else None}


def _parameter_error(robot: Robot, identified: np.ndarray, true: np.ndarray, free) -> dict:
    idx = robot.table.indices(free)
    err = (identified - true)[idx]
    angle = robot.table.angle_mask()[idx]
    rms = lambda v: float(np.sqrt(np.mean(v ** 2))) if v.size else None  # noqa: E731
    return {"rms_mm": rms(err[~angle]), "rms_rad": rms(err[angle]),
            "max_abs_mm": float(np.abs(err[~angle]).max()) if (~angle).any() else None,
            "max_abs_rad": float(np.abs(err[angle]).max()) if angle.any() else None}


def _instrument_heldout(robot: Robot, fit, val_joints, val_meas, sessions=None):
    """Held-out errors of a recording in an instrument frame or of targets: measured minus the
    prediction, before (nominal geometry, the registered frame, the start offsets) and after;
    ``sessions``: (M,) each validation row's frame group (None: one; :data:`BASE_FRAME`: the
    base frame, the fit's targets)."""
    k = fit.n_targets
    nominal = robot.forward_kinematics(robot.table.nominal, val_joints)
    rows = np.zeros(len(val_joints), dtype=int) if sessions is None else np.asarray(sessions)
    several = fit.n_sessions > 1
    before = np.empty_like(np.asarray(val_meas, dtype=float))
    after = np.empty_like(before)
    for s in np.unique(rows):
        at = rows == s
        if s == BASE_FRAME:
            frame, targets = np.zeros(6), fit.targets
            predicted = instrument_measurements(robot, robot.forward_kinematics(fit.result.theta, val_joints[at]),
                                                None, fit.targets)
        else:
            reg = fit.registrations[s] if several else fit.registration
            estimated = fit.frames_estimated[s] if several else fit.frame_estimated
            frame = reg.frame if estimated and reg is not None else fit.frames[s]
            targets = None if k == 0 else (reg.targets if reg is not None and estimated else fit.targets)
            predicted = fit.predict(val_joints[at], sessions=s if several else None)
        before[at] = measurement_residuals(robot, val_meas[at], instrument_measurements(robot, nominal[at], frame,
                                                                                          targets), k)
        after[at] = measurement_residuals(robot, val_meas[at], predicted, k)
    return before, after


def in_base_frame(fit, measured, groups, several: bool) -> np.ndarray:
    """(N, D) full poses ``measured`` taken out of their rows' instrument frames (``groups``: each
    row's frame group, :func:`frame_groups`; rows in :data:`BASE_FRAME` as they are; ``several``:
    the fit has several frames)."""
    out = np.array(measured, dtype=float)
    at = groups != BASE_FRAME
    out[at] = fit.to_base(out[at], sessions=groups[at] if several else None)
    return out


def _instrument_basis(fit) -> str:
    """What the held-out errors of :func:`_instrument_heldout` are."""
    what = "target positions" if fit.n_targets else "poses"
    return (f"recorded validation rows: measured {what} minus model prediction, instrument frame "
            "(includes sensor noise)")


#: A frame component this many times less certain than one measurement (its noise) is said to be
#: held by the geometry's tolerances, not determined by the poses.
FRAME_HELD_RATIO = 10.0


def frame_held_words(fit) -> list[str]:
    """The instrument frame's components the poses cannot separate from the geometry, in words:
    those whose standard uncertainty is over :data:`FRAME_HELD_RATIO` times one measurement's noise
    as the data show it (the spread of the fit's residuals, positions and angles; the declared
    noise may call angles exact) (with the tolerances as a prior the geometry's tolerance holds
    them; without, the gauge)."""
    std = np.asarray(fit.frame_std, dtype=float)
    names = ("x", "y", "z", "rotation about x", "rotation about y", "rotation about z")
    units = ("mm",) * 3 + ("rad",) * 3
    res = np.asarray(fit.result.pose_residuals, dtype=float)
    spread = np.nanstd(res, axis=0) if res.size else np.zeros(6)
    scale = np.r_[np.full(3, max(np.nanmax(spread[:3]) if spread.size >= 3 else 0.0, 1e-6)),
                  np.full(3, max(np.nanmax(spread[3:6]) if spread.size >= 6 else 0.0, 1e-9))]
    held = "the geometry's tolerances" if fit.result.prior is not None else "the gauge"
    return [f"frame {name}: std {std[k]:.3g} {units[k]}, not separated from the geometry by the poses: held by {held}"
            for k, name in enumerate(names) if std[k] > FRAME_HELD_RATIO * scale[k]]


def _instrument_block(fit, before, after) -> dict:
    """Summary keys of an instrument frame or target fit."""
    block = {"method": "forward", "solver": "lm", "weighted": True,
             "measurement_notes": list(fit.notes), "measurement_gauge": list(fit.gauge)}
    if fit.frame_estimated:
        block["measurement_frame"] = fit.frame_dict()
        block["measurement_frame_std"] = frame_to_dict(fit.frame_std)
        block["measurement_frame_held"] = frame_held_words(fit)
    if fit.targets is not None:
        block["measurement_targets_mm"] = fit.targets.tolist()
        block["measurement_targets_estimated"] = fit.targets_estimated
        if before is not None:  # one position error per target and row
            b, a = (np.linalg.norm(e.reshape(len(e), -1, 3), axis=2).ravel() for e in (before, after))
            block["heldout_position_error_mm"] = {"before": float(b.mean()), "after": float(a.mean()),
                                                  "max_after": float(a.max()), "before_figures": error_figures(b),
                                                  "after_figures": error_figures(a)}
            block["heldout_orientation_error_rad"] = None
    return block


def _identify(robot: Robot, joints, measured, noise: SensorNoise, settings: RunSettings, where: str, prior=None,
              rows=None):
    """The run's identification of ``joints``/``measured`` (data rows ``rows`` of the recording,
    for the messages; default 0..N-1); a failure said with the file and its 1-based row."""
    solver = settings.solver or ("gn" if settings.method == "chainwise" else "lm")
    options = {"solver": solver}
    if settings.method == "chainwise":
        options.update(weighted=settings.weighted, epsilon=paper.PAPER_EPSILON)
    try:
        return identify(robot, joints, measured, noise, method=settings.method, prior=prior, **options), solver
    except KinematicsError as exc:
        rows = np.arange(len(joints)) if rows is None else rows
        raise ValueError(f"{row_message(exc, where, rows)} (the {robot.name} cannot reach the recorded joints)") from None
    except ValueError as exc:
        raise ValueError(f"{where}: {len(measured)} calibration rows are too few or unusable: {exc}") from None


def _variant(robot: Robot, result: IdentificationResult, rows: list[int], held: tuple | None, truth, free) -> dict:
    """One identification's outcome, for the with/without-flagged-rows comparison."""
    block = {"rows_used": len(rows), "identified_errors": robot.table.to_dict(result.errors),
             "chi2": result.chi2, "dof": result.dof, "success": result.success, "message": result.message,
             "heldout_position_error_mm": None, "heldout_orientation_error_rad": None,
             "parameter_error": None if truth is None else _parameter_error(robot, result.theta, truth, free)}
    if held is not None:
        block.update(_heldout_block(robot, *held))
    return block


def run_calibration(settings: RunSettings, progress=lambda label, done, total: None) -> RunResult:
    """Run one calibration (see the module docstring).

    Every output path is checked before any work; the outputs (recording ``.csv`` + ``.json``
    when simulating, ``.rrd``, ``summary_json``) are written to temporary files and published
    together at the end, or not at all. Rows flagged by the outlier test are left out of the
    identification unless ``keep_outliers``; the summary gives the result with and without them.
    Rows are named by their 1-based data row in the recording (row k is file line k + 1).

    Args:
        settings: what to do.
        progress: ``progress(label, done, total)`` called while simulating.

    Raises:
        FileExistsError: an output exists and ``overwrite`` is off.
        ValueError: bad settings or a recording that cannot be analysed (the message names it).
    """
    from pipeline.formats import ResultSet, read_recording, recording_checks

    t0 = time.perf_counter()
    split: dict[str, float] = {}
    warnings: list[str] = []
    rec = diagnosis = None
    if settings.real is not None:
        rec = read_recording(settings.real)
        split["read"] = time.perf_counter() - t0
        if settings.robot is not None and settings.robot != rec.robot.name:
            raise ValueError(f"--robot {settings.robot}: the recording {settings.real} is of a {rec.robot.name} "
                             "(its sidecar's 'robot'); leave --robot out with --real")
        t_checks = time.perf_counter()
        checks = recording_checks(rec, settings.real, prior=settings.prior)  # refuses a mistake it can prove
        warnings += checks.warnings
        diagnosis = checks.diagnosis
        split["checks"] = time.perf_counter() - t_checks
    # Every output is checked before any work, and the files are published together at the end.
    out = Path(settings.out)
    output_folder(out)
    reservation = NameReservation(out, settings.name if settings.name is not None else default_name(settings),
                                  explicit=settings.name is not None, overwrite=settings.overwrite,
                                  extensions=OUTPUT_EXTENSIONS)
    try:
        name = reservation.name
        targets_out = {"rrd": out / f"{name}.rrd", "calibration": out / f"{name}{CALIBRATION_SUFFIX}",
                       "suggested_poses": out / f"{name}.suggested_poses.csv",
                       "suggested_poses_json": out / f"{name}.suggested_poses.json"}
        if rec is None:
            targets_out.update(csv=out / f"{name}.csv", json=out / f"{name}.json")
        if settings.summary_json is not None:
            targets_out["summary_json"] = Path(settings.summary_json)
        if settings.export_mjcf is not None:
            targets_out["mjcf"] = Path(settings.export_mjcf)
        if settings.report is not None:
            targets_out["report"] = Path(settings.report)
        flags = {k: "--out" for k in targets_out} | {"summary_json": "--summary-json", "mjcf": "--export-mjcf",
                                                      "report": "--report"}
        with ResultSet(targets_out, overwrite=settings.overwrite, flags=flags) as outputs:
            summary, result = _run(settings, rec, warnings, progress, split, t0, outputs, diagnosis)
            suggestion = summary.pop("_suggested_poses", None)
            if suggestion is None:
                for key in ("suggested_poses", "suggested_poses_json"):
                    outputs.drop(key)
                    targets_out.pop(key)
            else:
                outputs.temp("suggested_poses").write_text(suggestion[0])
                outputs.temp("suggested_poses_json").write_text(suggestion[1])
            paths = {k: str(v) for k, v in targets_out.items()}
            summary.update({k: v for k, v in paths.items() if k not in ("summary_json", "suggested_poses")})
            if "suggested_poses" in paths:
                summary["suggested_poses_path"] = paths["suggested_poses"]
            summary["wall_time_s"] = time.perf_counter() - t0
            summary["wall_time_split_s"] = split
            as_read = summary.pop("_as_read", None)
            write_data_files(outputs, summary, settings, targets_out)
            outputs.publish()
    finally:
        reservation.release()
    return RunResult(summary=summary, result=result, paths=paths, recording=rec, as_read=as_read)


def write_data_files(outputs, summary: dict, settings: RunSettings, targets_out: dict) -> None:
    """Write the summary JSON (when asked), the simulated recording (when simulating), the
    calibration file (its recording named and hashed) and the identified machine's MJCF (when asked,
    :func:`pipeline.simulation.mjcf_export.mjcf_text`) to their temporary files in ``outputs``;
    the summary's private keys (``_recording``, ``_calibration``) are taken out of it first."""
    from pipeline.formats import calibration_text, recording_source, recording_texts, summary_document

    recording = summary.pop("_recording", None)
    calibration = summary.pop("_calibration")
    if "summary_json" in targets_out:
        outputs.temp("summary_json").write_text(json.dumps(summary_document(summary), indent=1))
    if "report" in targets_out:
        outputs.temp("report").write_text(render_html(build_report(summary)))
    if recording is not None:
        csv_text, json_text = recording_texts(recording)
        outputs.temp("csv").write_text(csv_text)
        outputs.temp("json").write_text(json_text)
        source = {"name": Path(targets_out["csv"]).name, "simulated": summary["scenario"],
                  "sha256": sha256_text(csv_text), "sidecar_sha256": sha256_text(json_text)}
    else:
        source = recording_source(settings.real)
    calibration = replace(calibration, recording=source)
    outputs.temp("calibration").write_text(calibration_text(calibration))
    if "mjcf" in targets_out:
        from pipeline.simulation.mjcf_export import mjcf_text

        outputs.temp("mjcf").write_text(mjcf_text(calibration))


#: What the summary says of the prior with --no-prior.
NO_PRIOR = "none (--no-prior: plain least squares)"


@dataclass
class CalibrationInput:
    """The measurements a run calibrates from, simulated or read (the first step of a run).

    Attributes:
        robot, noise: the robot and the declared noise.
        joints: (N, C) calibration joints; measured: (N, D) calibration poses (or target positions).
        rows: (N,) 0-based data rows of the calibration rows in the recording.
        where: how messages name the data (the file, or the simulated poses).
        scenario: the run's scenario in words.
        actual, injected: the true parameter vector and its errors, when known (else None).
        val_joints, val_meas: the recording's validation rows (empty when simulating).
        rec: the recording read (None when simulating); sim: the simulation's parts (None when reading).
        tolerance: each parameter's tolerance (:func:`machine_tolerance`): the prior, and the yardstick
            of :func:`implausible_parameters` with or without one; prior: it, or None with --no-prior.
            Where none is declared both become the tolerance learnt from the rows
            (:func:`learn_tolerance`) once the gross rows are out.
        tolerance_declared: the sidecar declares ``meta.parameter_tolerance``.
        tolerance_estimate: the tolerance the rows support (:class:`calib.evidence.ToleranceEstimate`),
            the prior where none is declared, a check of the declared one otherwise; None with
            --no-prior or before :func:`learn_tolerance`.
    """

    robot: Robot
    noise: SensorNoise
    joints: np.ndarray
    measured: np.ndarray
    rows: np.ndarray
    where: str
    scenario: str
    actual: np.ndarray | None
    injected: np.ndarray | None
    val_joints: np.ndarray
    val_meas: np.ndarray
    rec: Recording | None = None
    sim: dict | None = None
    tolerance: ParameterPrior | None = None
    prior: ParameterPrior | None = None
    prior_source: str = NO_PRIOR
    sessions: np.ndarray | None = None
    val_sessions: np.ndarray | None = None
    tolerance_declared: bool = False
    tolerance_estimate: ToleranceEstimate | None = None
    frame_sessions: tuple = ()

    @property
    def n_sessions(self) -> int:
        """Instrument frames of the recording: its sessions with a frame of their own and
        calibration rows (:func:`frame_groups`; 1 for a simulated run)."""
        return 1 if self.rec is None else len(self.frame_sessions)

    def measurement(self, s: int = 0):
        """How frame group ``s`` was measured (:func:`pipeline.formats.session_measurement` of the
        session that owns its frame)."""
        return session_measurement(self.rec, self.frame_sessions[s])


#: The key of a recording-as-read's meta saying where its ``parameter_tolerance`` came from when a
#: run learnt it from the rows (:func:`learn_tolerance`; never written to a file).
TOLERANCE_SOURCE_KEY = "parameter_tolerance_source"


def machine_tolerance(robot: Robot, meta: dict | None, where: str) -> tuple[ParameterPrior, str]:
    """``(tolerance, source in words)``: each parameter's manufacturing tolerance (one standard
    deviation about its nominal value) from the sidecar's ``meta.parameter_tolerance``, or the
    robot class's documented default (:attr:`calib.robot.Robot.default_parameter_tolerance`).

    Raises:
        ValueError: a tolerance naming no parameter or unit, or not a number > 0 (file and key named).
    """
    tolerance = (meta or {}).get("parameter_tolerance")
    learnt = (meta or {}).get(TOLERANCE_SOURCE_KEY)
    if tolerance is None:
        default = ", ".join(f"{v:g} {u}" for u, v in robot.default_parameter_tolerance.items())
        return ParameterPrior.default(robot), f"the {robot.name}'s default tolerance ({default}, one standard deviation)"
    try:
        prior = ParameterPrior.from_tolerance(robot, tolerance)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: field 'meta.parameter_tolerance': {exc}") from None
    return prior, learnt or f"the sidecar's parameter_tolerance ({where})"


def declared_tolerance(robot: Robot, meta: dict | None, where: str, flag: dict | None) -> tuple[ParameterPrior, str]:
    """:func:`machine_tolerance`, the command line's ``--tolerance`` (``flag``) overriding the sidecar's."""
    if flag is None:
        return machine_tolerance(robot, meta, where)
    try:
        return ParameterPrior.from_tolerance(robot, flag), "the tolerance declared with --tolerance"
    except (TypeError, ValueError) as exc:
        raise ValueError(f"--tolerance: {exc}") from None


#: An identified error beyond this many tolerances is physically implausible.
IMPLAUSIBLE_TOLERANCES = 3.0


def implausible_parameters(robot: Robot, errors: np.ndarray, tolerance: ParameterPrior, names) -> list[dict]:
    """The identified errors (P,) beyond :data:`IMPLAUSIBLE_TOLERANCES` times their tolerance, of the
    parameters ``names``: ``{"name", "error", "tolerance", "unit", "words"}`` each, largest first."""
    out = []
    for name in names:
        k = robot.table.index(name)
        tol, err, unit = float(tolerance.std[k]), float(errors[k]), robot.table.units[k]
        if abs(err) > IMPLAUSIBLE_TOLERANCES * tol:
            out.append({"name": name, "error": err, "tolerance": tol, "unit": unit,
                        "words": f"{name} = {err:+.4g} {unit} from nominal, {abs(err) / tol:.3g} times its tolerance "
                                 f"{tol:.4g} {unit}"})
    return sorted(out, key=lambda d: -abs(d["error"]) / d["tolerance"])


def read_input(settings: RunSettings, rec: Recording) -> CalibrationInput:
    """The calibration input of a recording (``settings.real``)."""
    robot = rec.robot
    truth = rec.meta.get("simulation", {}).get("injected_errors")
    try:
        injected = robot.table.vector(truth, base=np.zeros(robot.n_parameters)) if isinstance(truth, dict) else None
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{sidecar_name(settings.real)}: field 'meta.simulation.injected_errors': {exc}") from None
    joints, measured = rec.subset("calibration")
    val_joints, val_meas = rec.subset("validation")
    where = str(settings.real)
    if len(measured) == 0:
        raise ValueError(f"{where}, column 'set': no calibration rows (every row is 'validation')")
    tolerance, prior_source = declared_tolerance(robot, rec.meta, sidecar_name(settings.real), settings.tolerance)
    groups, index = frame_groups(rec, where)
    cal_rows, val_rows = rec.rows("calibration"), rec.rows("validation")
    return CalibrationInput(robot=robot, noise=rec.noise, joints=joints, measured=measured,
                            rows=cal_rows, where=where, scenario=f"recording {settings.real}",
                            actual=None if injected is None else robot.table.nominal + injected, injected=injected,
                            val_joints=val_joints, val_meas=val_meas, rec=rec, tolerance=tolerance,
                            prior=tolerance if settings.prior else None,
                            prior_source=prior_source if settings.prior else NO_PRIOR,
                            sessions=index[cal_rows], val_sessions=index[val_rows], frame_sessions=groups,
                            tolerance_declared="parameter_tolerance" in rec.meta or settings.tolerance is not None)


#: A row's frame group in :func:`frame_groups` when it is predicted in the base frame (a session
#: without calibration rows declared in the base frame).
BASE_FRAME = -1


def frame_groups(rec: Recording, where: str = "the recording") -> tuple[tuple[str, ...], np.ndarray]:
    """``(frame sessions, (N,) int)``: the sessions whose instrument frame the run fits (those with
    a frame of their own whose rows, or the rows of the sessions captured in it, include
    calibration rows; in order), and each row's place among them (:data:`BASE_FRAME` for the rows
    of a session without calibration rows declared in the base frame).

    Raises:
        ValueError: a session with validation rows and no calibration rows whose frame cannot be
            estimated (the session named as written).
    """
    owner = {name: frame_session(rec, name) for name in rec.session_names}
    calibrated = set(rec.sessions[rec.rows("calibration")].tolist())
    fitted = {owner[name] for name in calibrated}
    groups = tuple(name for name in rec.session_names if name in fitted)
    place = {name: groups.index(owner[name]) for name in rec.session_names if owner[name] in fitted}
    for name in rec.session_names:
        if name not in place:
            if len(rec.session_names) > 1 and session_measurement(rec, name).frame != "base":
                raise ValueError(f"{where}, column 'session': session {str(name)!r} has validation rows but no "
                                 "calibration rows: its instrument frame cannot be estimated (declare it in the frame "
                                 "of a session with calibration rows, or in the base frame)")
            place[name] = BASE_FRAME if len(rec.session_names) > 1 else 0
    return groups, np.array([place[name] for name in rec.sessions.tolist()], dtype=int)


def session_index(rec: Recording) -> np.ndarray:
    """(N,) int, each row's frame group (:func:`frame_groups`)."""
    return frame_groups(rec)[1]


def simulate_input(settings: RunSettings, progress) -> CalibrationInput:
    """The calibration input of a simulated machine (the reference errors injected, MuJoCo)."""
    robot = default_robot(settings.robot or DEFAULT_ROBOT)
    noise = SensorNoise(settings.noise_mm, settings.noise_rad, settings.noise_dist, joint=settings.noise_joint)
    sim = _simulate(robot, settings, noise, progress)
    cal = sim["cal"]
    empty = np.zeros((0, robot.pose_dim))
    tolerance, prior_source = declared_tolerance(robot, None, "", settings.tolerance)
    return CalibrationInput(robot=robot, noise=noise, joints=cal.encoders, measured=cal.measured,
                            rows=np.arange(len(cal.measured)), where="the simulated calibration poses",
                            scenario=sim["scenario"], actual=sim["actual"], injected=sim["errors"],
                            val_joints=np.zeros((0, robot.n_chains)), val_meas=empty, sim=sim, tolerance=tolerance,
                            prior=tolerance if settings.prior else None,
                            prior_source=prior_source if settings.prior else NO_PRIOR,
                            tolerance_declared=settings.tolerance is not None)


@dataclass
class Identification:
    """The identification step's outcome: the fit used (``result``), the fits with and without the
    flagged rows, the outlier test, the instrument frame fit (or None) and the rows used."""

    result: IdentificationResult
    result_all: IdentificationResult
    result_kept: IdentificationResult | None
    solver: str
    report: object
    outlier_verdict: str
    flagged_idx: list
    flagged: list
    keep: np.ndarray
    left_out: bool
    used: np.ndarray
    instrument: object
    measured: np.ndarray
    gross: object = None
    gross_idx: list = field(default_factory=list)
    kept: np.ndarray | None = None


def gross_row_stage(inp: CalibrationInput, settings: RunSettings):
    """``(search, kept rows)``: the gross rows of a recording found before anything is fitted to
    them (:func:`calib.robust.find_gross_rows`: trimmed fits, a row named only when no consistent
    fit explains it; the instrument frame inferred from the rows it makes consistent); simulated
    runs skip it: ``(None, every row)``. With ``keep_outliers`` the rows are named, not left out."""
    n = len(inp.measured)
    if inp.rec is None:
        return None, np.arange(n)
    if inp.n_sessions > 1:
        search = SessionSearch([session_search(inp, settings, s) for s in range(inp.n_sessions)], inp.sessions)
    else:
        ms = inp.measurement(0)
        search = find_gross_rows(inp.robot, inp.joints, inp.measured, inp.noise, frame=ms.frame, targets=ms.targets,
                                 estimate_targets=ms.estimate_targets if ms.targets is not None else None,
                                 seed=settings.seed)
    if not search.success or settings.keep_outliers:
        return search, np.arange(n)
    return search, np.flatnonzero(search.kept)


def session_search(inp: CalibrationInput, settings: RunSettings, s: int):
    """The gross-row search of session ``s``'s calibration rows, in its own instrument frame."""
    ms = inp.measurement(s)
    rows = np.flatnonzero(inp.sessions == s)
    return find_gross_rows(inp.robot, inp.joints[rows], inp.measured[rows], inp.noise, frame=ms.frame,
                           targets=ms.targets, estimate_targets=ms.estimate_targets if ms.targets is not None else None,
                           seed=settings.seed)


class SessionSearch:
    """The gross-row searches of a recording's sessions (one instrument frame each) read as one:
    ``gross``, ``kept``, ``statistic`` over the calibration rows; ``success`` where every session's
    search judged its rows; ``frame_estimated`` where any estimated a frame; ``searches`` each."""

    def __init__(self, searches: list, sessions: np.ndarray):
        self.searches, self.sessions = searches, sessions
        n = sessions.size
        self.kept, self.statistic = np.ones(n, dtype=bool), np.full(n, np.nan)
        for s, search in enumerate(searches):
            rows = np.flatnonzero(sessions == s)
            self.kept[rows] = search.kept
            self.statistic[rows] = search.statistic
        self.gross = tuple(int(i) for i in np.flatnonzero(~self.kept))
        self.success = all(search.success for search in searches)
        self.frame_estimated = any(search.frame_estimated for search in searches)
        self.cutoff = searches[0].cutoff
        self.fit = None
        self.message = "; ".join(f"session {s + 1}: {search.message}" for s, search in enumerate(searches))


def instrument_fit(inp: CalibrationInput, search, kept: np.ndarray):
    """The geometry fitted with the recording's instrument frame and target offsets, on the rows
    the gross-row stage kept, where the recording needs them (None: plain poses in the base frame)."""
    if inp.rec is None:
        return None
    if inp.n_sessions > 1:
        return sessions_fit(inp, search, kept)
    ms = inp.measurement(0)
    joints, measured = inp.joints[kept], inp.measured[kept]
    if search is None or not search.success:  # the search could not judge: the frame test on every row
        return identify_as_measured(inp.robot, joints, measured, inp.noise, ms, prior=inp.prior)
    if not search.frame_estimated and ms.n_targets == 0:
        return None
    start = search.fit.frame if search.frame_estimated and search.fit is not None else ms.initial_frame
    # "auto" on the rows kept: the frame test of every run, now on rows the frame makes consistent.
    return identify_measured(inp.robot, joints, measured, inp.noise,
                             frame="auto" if search.frame_estimated else "base", initial_frame=start,
                             targets=ms.targets, estimate_targets=ms.estimate_targets if ms.n_targets else None,
                             prior=inp.prior)


def sessions_fit(inp: CalibrationInput, search, kept: np.ndarray):
    """One geometry, an instrument frame for each session (estimated where its own search found one
    or its settings ask for it), fitted together on the rows kept (:func:`calib.measurement.identify_measured`
    with ``sessions``)."""
    names = inp.frame_sessions
    per = [inp.measurement(s) for s in range(len(names))]
    searches = search.searches if isinstance(search, SessionSearch) else [None] * len(names)
    frames, starts = [], []
    for ms, found in zip(per, searches):
        estimated = (found.frame_estimated if found is not None and found.success else ms.frame == "estimate")
        frames.append("auto" if estimated and ms.frame != "estimate" else ("estimate" if estimated else "base"))
        starts.append(found.fit.frame if estimated and found is not None and found.fit is not None
                      else ms.initial_frame)
    ms0 = per[0]
    return identify_measured(inp.robot, inp.joints[kept], inp.measured[kept], inp.noise, frame=frames,
                             initial_frame=starts, targets=ms0.targets,
                             estimate_targets=ms0.estimate_targets if ms0.n_targets else None, prior=inp.prior,
                             sessions=inp.sessions[kept])


def _first_fit(inp: CalibrationInput, settings: RunSettings, search, kept: np.ndarray):
    """``(instrument, measured, (result, solver))`` of the rows ``kept`` under ``inp.prior``: the
    instrument fit where the recording needs one (then ``measured`` the poses in the base frame
    and the result pair None), else the run's identification of the base-frame poses."""
    instrument = instrument_fit(inp, search, kept)
    measured = inp.measured if instrument is None else instrument.base_poses(
        inp.joints, inp.measured, sessions=inp.sessions if inp.n_sessions > 1 else None)
    if instrument is not None:
        return instrument, measured, None
    return None, measured, _identify(inp.robot, inp.joints[kept], measured[kept], inp.noise, settings, inp.where,
                                     inp.prior, inp.rows[kept])


def learn_tolerance(inp: CalibrationInput, fit) -> bool:
    """The tolerance the rows support (:func:`calib.evidence.tolerance_from_data`), from ``fit``
    (an identification result, or the ``(result, solver)`` pair, made under ``inp.prior``). Where
    the recording declares none and the rows show the robot's default too tight (the units of
    :attr:`calib.evidence.ToleranceEstimate.wider`), the learnt tolerance becomes the prior and the
    yardstick of the run (``inp`` is updated, its ``prior_source`` says so) and True is returned
    (refit under it); a default the rows do not contradict stays, with the estimate said; a declared one
    is kept and checked (``inp.tolerance_estimate`` says whether the rows contradict it). Without
    a prior (--no-prior) nothing is learnt."""
    result = fit[0] if isinstance(fit, tuple) else fit
    if inp.prior is None or result is None or result.prior is None:
        return False
    try:
        estimate = tolerance_from_data(result, reference=inp.prior)
    except (ValueError, np.linalg.LinAlgError) as exc:
        inp.prior_source += f" (no tolerance could be learnt from the rows: {exc})"
        return False
    inp.tolerance_estimate = estimate
    if inp.tolerance_declared:
        return False
    default = estimate.tolerance_words("reference")
    if all(f == 1.0 for f in estimate.factor.values()):
        inp.prior_source = (f"the {inp.robot.name}'s default tolerance ({default}, one standard deviation): the rows "
                            "determine too few parameters to learn one")
        return False
    if not estimate.wider:
        inp.prior_source = (f"the {inp.robot.name}'s default tolerance ({default}, one standard deviation), "
                            f"consistent with the rows or wider than they show (estimated from the data: "
                            f"{estimate.tolerance_words()}); a default wider than the machine costs nothing where "
                            "the rows determine the parameters")
        return False
    inp.prior = inp.tolerance = estimate.widened_prior()
    kept = [u for u in estimate.factor if u not in estimate.wider]
    inp.prior_source = (f"tolerance estimated from the data: "
                        f"{', '.join(f'{estimate.tolerance[u]:.3g} {u}' for u in estimate.wider)} (the "
                        f"{inp.robot.name}'s default {default} is contradicted: {estimate.evidence_words()})"
                        + (f"; the default kept for {', '.join(kept)}" if kept else ""))
    return True


def identify_step(inp: CalibrationInput, settings: RunSettings, warnings: list, split: dict | None = None) -> Identification:
    """Gross rows first (:func:`gross_row_stage`), then, on the rows kept, the instrument frame
    where the recording needs one (:func:`instrument_fit`), the outlier test (closed-form
    leave-one-out, forward model, poses in the base frame) and the identification from the rows it
    keeps; the one with its flagged rows is kept for the comparison."""
    robot, joints, noise = inp.robot, inp.joints, inp.noise
    split = {} if split is None else split
    t0 = time.perf_counter()
    search, kept = gross_row_stage(inp, settings)
    split["gross_rows"] = time.perf_counter() - t0
    gross_idx = [] if search is None or not search.success else [int(i) for i in search.gross]
    instrument, measured, first = _first_fit(inp, settings, search, kept)
    if learn_tolerance(inp, instrument.result if instrument is not None else first):
        instrument, measured, first = _first_fit(inp, settings, search, kept)  # under the learnt tolerance
    est = inp.tolerance_estimate
    if inp.tolerance_declared and est is not None and est.contradicted:
        warnings.append(f"the declared tolerance ({est.tolerance_words('reference')}) is contradicted by the rows: "
                        f"{est.evidence_words()}; the rows support {est.tolerance_words()} (declared, so obeyed)")
    t1 = time.perf_counter()
    try:
        report = find_outliers(robot, joints[kept], measured[kept], noise)
    except (ValueError, KinematicsError) as exc:
        report, outlier_verdict = None, f"outlier test not run: {exc}"
    else:
        outlier_verdict = report.verdict
    split["outlier_test"] = time.perf_counter() - t1
    loo_idx = [int(kept[i]) for i in report.flagged] if report is not None else []
    flagged_idx = sorted(set(gross_idx) | set(loo_idx))
    result_all, solver = (instrument.result, "lm") if instrument is not None else first
    keep = np.setdiff1d(kept, loo_idx)
    left_out = bool(loo_idx) and not settings.keep_outliers and instrument is None
    if loo_idx and instrument is not None:
        warnings.append("the rows the leave-one-out test flags are kept: leaving them out is not done with an "
                        "instrument frame or targets estimated (gross rows are left out before the frame is fitted)")
    result_kept = None
    if loo_idx and instrument is None:
        try:
            result_kept, _ = _identify(robot, joints[keep], measured[keep], noise, settings, inp.where, inp.prior,
                                       inp.rows[keep])
        except ValueError as exc:
            warnings.append(f"the flagged rows are kept: without them {exc}")
            left_out = False
    return Identification(result=result_kept if left_out else result_all, result_all=result_all,
                          result_kept=result_kept, solver=solver, report=report, outlier_verdict=outlier_verdict,
                          flagged_idx=flagged_idx, flagged=[int(inp.rows[i]) + 1 for i in flagged_idx], keep=keep,
                          left_out=left_out, used=keep if left_out else kept, instrument=instrument,
                          measured=measured, gross=search, gross_idx=gross_idx, kept=kept)


def heldout_errors(inp: CalibrationInput, ident: Identification, theta, progress):
    """``(before, after)`` held-out pose errors of the model ``theta``, or None: on the simulated
    machine, its compensated commands; on a recording, the validation rows' prediction errors."""
    robot, sim, instrument = inp.robot, inp.sim, ident.instrument
    if sim is not None and sim["val"] is not None:
        try:
            compensated = robot.inverse_kinematics(theta, sim["heldout"])
            check_joint_limits(robot, compensated, "held-out pose")
        except KinematicsError as exc:
            raise ValueError(
                f"the identified model cannot command the held-out poses ({exc}); its geometry is "
                "implausible: the measurements carry effects the geometric model lacks (gravity, "
                "payload, compliance; see python -m pipeline.discover)") from exc
        after = sim["bed"].measure(compensated, progress=lambda d, t: progress(
            "measuring held-out poses (compensated commands)", d, t))
        return sim["val"].true_poses - sim["heldout"], after.true_poses - sim["heldout"]
    if instrument is not None and len(inp.val_joints):
        return _instrument_heldout(robot, instrument, inp.val_joints, inp.val_meas, inp.val_sessions)
    if sim is None and len(inp.val_joints):
        # A recording holds the validation poses measured under nominal commands only: the
        # identified model's prediction error there stands for the compensated error (equal to
        # first order), and includes the sensor noise.
        nominal = robot.table.nominal
        try:
            before = inp.val_meas - robot.forward_kinematics(nominal, inp.val_joints, initial=inp.val_meas)
            after = inp.val_meas - robot.forward_kinematics(theta, inp.val_joints, initial=inp.val_meas)
        except KinematicsError as exc:
            raise ValueError(f"{row_message(exc, inp.where, inp.rec.rows('validation'))} (a validation row the model "
                             "cannot reach)") from None
        return before, after
    return None


def heldout_basis(inp: CalibrationInput, ident: Identification) -> str:
    """What the held-out errors are, in words."""
    if ident.instrument is not None:
        return _instrument_basis(ident.instrument)
    if inp.sim is not None:
        return "simulated machine, compensated commands, noise-free settled poses (before: nominal commands)"
    return "recorded validation rows: measured minus model prediction (includes sensor noise)"


def validate_step(inp: CalibrationInput, ident: Identification, settings: RunSettings, progress):
    """``(held, truth_in_gauge, with_flagged, without_flagged)``: the held-out errors of the fit
    used, the true parameters in the fit's gauge (or None) and the with/without-flagged-rows
    comparison (or None)."""
    robot, result, instrument = inp.robot, ident.result, ident.instrument
    held = heldout_errors(inp, ident, result.theta, progress)
    free = result.free_names
    truth_in_gauge = None
    if inp.actual is not None:
        truth_in_gauge = gauge_representative(robot, inp.actual, result.start) if instrument is None else \
            measured_gauge_representative(robot, inp.actual, estimate_frame=instrument.frame_estimated,
                                          targets=instrument.targets if instrument.targets_estimated else None,
                                          start=result.start)
    with_flagged = without_flagged = None
    if ident.result_kept is not None:
        other = ident.result_all if ident.left_out else ident.result_kept
        blocks = {id(result): held, id(other): heldout_errors(inp, ident, other.theta, progress)}
        with_flagged = _variant(robot, ident.result_all, list(ident.kept), blocks[id(ident.result_all)],
                                truth_in_gauge, free)
        without_flagged = _variant(robot, ident.result_kept, list(ident.keep), blocks[id(ident.result_kept)],
                                   truth_in_gauge, free)
    return held, truth_in_gauge, with_flagged, without_flagged


def summary_of(inp: CalibrationInput, ident: Identification, held, truth_in_gauge, comparison,
               settings: RunSettings, warnings: list) -> dict:
    """The run's summary (the same keys for every robot)."""
    robot, result, instrument = inp.robot, ident.result, ident.instrument
    free = result.free_names
    chainwise_gn = settings.method == "chainwise" and ident.solver == "gn"
    history = list(result.history) if (chainwise_gn and instrument is None) \
        else [float(integrated_error(robot, result.pose_residuals if instrument is None else
                                     ident.measured - robot.forward_kinematics(result.theta, inp.joints))[2].max())]
    misfit = bool(ident.report is not None and ident.report.misfit)
    summary = {
        "robot": robot.name,
        "scenario": inp.scenario,
        "method": settings.method,
        "solver": ident.solver,
        "weighted": (settings.weighted or inp.prior is not None) if settings.method == "chainwise" else True,
        "calibration_poses": int(len(inp.measured)),
        "calibration_poses_used": int(ident.used.size),
        "heldout_poses": 0 if held is None else len(held[0]),
        "declared_noise": inp.noise.to_dict(),
        "seed": settings.seed,
        "parameter_units": dict(zip(robot.table.names, robot.table.units)),
        "free_parameters": list(free),
        "fixed_parameters": [n for n in robot.table.names if n not in free],
        "injected_errors": None if inp.injected is None else robot.table.to_dict(inp.injected),
        "identified_errors": robot.table.to_dict(result.errors),
        "identified_std": robot.table.to_dict(result.std),
        "parameter_error": None if truth_in_gauge is None else
            _parameter_error(robot, result.theta, truth_in_gauge, free),
        "gain_G_percent": None if truth_in_gauge is None else {
            k: v for k, v in calibration_gain(robot, truth_in_gauge, result.start, result.theta,
                                              free).as_dict().items() if k != "per_parameter"},
        "iterations": result.iterations,
        "converged": result.success,
        "success": result.success,
        "message": result.message,
        "chi2": result.chi2,
        "dof": result.dof,
        "max_dqint_history": history,
        "condition_numbers": result.condition_numbers.tolist(),
        "row_numbering": ROW_NUMBERING,
        "flagged_poses": ident.flagged,
        "outliers": {"test": "closed-form leave-one-out (hat matrix, studentized deleted residuals, chi-square "
                             "against the declared noise), forward model",
                     "verdict": ident.outlier_verdict, "flagged_rows": ident.flagged, "left_out": ident.left_out,
                     "model_misfit": misfit,
                     "search": None if ident.report is None else ident.report.search},
        "model_misfit": misfit,
        "gross_rows": gross_block(inp, ident),
        "with_flagged": comparison[0],
        "without_flagged": comparison[1],
        "warnings": warnings,
        "heldout_basis": None if held is None else heldout_basis(inp, ident),
        "heldout_position_error_mm": None,
        "heldout_orientation_error_rad": None,
    }
    if held is not None and (instrument is None or instrument.targets is None):
        summary.update(_heldout_block(robot, *held))
    if held is not None:
        summary.update(heldout_detail(inp, *held))
    if instrument is not None:
        summary.update(_instrument_block(instrument, *(held if held is not None else (None, None))))
        if inp.n_sessions > 1:
            summary.update(sessions_block(inp, instrument))
    summary.update(prior_block(inp, result))
    summary["implausible_parameters"] = implausible_parameters(robot, result.errors, inp.tolerance, result.free_names)
    if inp.sim is not None:
        summary.update(simulation_block(inp, settings))
    return summary


def heldout_detail(inp: CalibrationInput, before: np.ndarray, after: np.ndarray) -> dict:
    """Summary keys of each held-out pose: ``heldout_per_pose`` (the position error norms before
    and after, mm, and the orientation's, rad; with target data one position per target and row;
    ``rows``: the 1-based data rows of a recording, None for simulated held-out poses) and
    ``iso9283`` where validation rows repeat a commanded pose (the same joints, within the declared
    joint noise; :func:`calib.metrics.iso9283_position` on attained minus predicted positions, before
    with the nominal model, after with the identified one; None otherwise)."""
    robot = inp.robot
    rows = None if inp.rec is None else [int(r) + 1 for r in inp.rec.rows("validation")]
    if before.shape[1] != robot.pose_dim:  # target positions: one norm per target and row
        b, a = (np.linalg.norm(e.reshape(len(e), -1, 3), axis=2).ravel() for e in (before, after))
        per = {"position_before_mm": b.tolist(), "position_after_mm": a.tolist(), "orientation_before_rad": None,
               "orientation_after_rad": None, "rows": rows, "per": "target and row"}
        return {"heldout_per_pose": per, "iso9283": None}
    pb, ob = pose_error_norms(robot, before)
    pa, oa = pose_error_norms(robot, after)
    angles = robot.angle_pose_mask.any()
    per = {"position_before_mm": pb.tolist(), "position_after_mm": pa.tolist(),
           "orientation_before_rad": ob.tolist() if angles else None,
           "orientation_after_rad": oa.tolist() if angles else None, "rows": rows, "per": "pose"}
    iso = None
    if inp.rec is not None:
        groups = repeated_poses(inp.val_joints, inp.noise.joint_std)
        position = ~robot.angle_pose_mask
        zero = np.zeros((len(before), 3))
        b, a = (iso9283_position(e[:, position], zero, groups) for e in (before, after))
        if len(b.rows):
            iso = {"standard": "ISO 9283: AP = distance from the barycentre of the attained positions to the command, "
                               "RP = mean distance to the barycentre + 3 sample standard deviations",
                   "basis": "validation rows repeating one joint command; the command's position is the model's "
                            "prediction at it (before: nominal, after: identified)",
                   "poses": [{"rows": [rows[i] for i in r], "repeats": int(len(r)), "AP_before_mm": float(apb),
                              "AP_after_mm": float(apa), "RP_mm": float(rp)}
                             for r, apb, apa, rp in zip(b.rows, b.accuracy, a.accuracy, a.repeatability)]}
    return {"heldout_per_pose": per, "iso9283": iso}


#: Folds of the cross-validation of an instrument-frame fit (each fold refits geometry and frame).
INSTRUMENT_FOLDS = 10


def crossvalidation_of(inp: CalibrationInput, ident: Identification, settings: RunSettings):
    """The cross-validated prediction error of a recording without validation rows
    (:func:`calib.crossval.crossvalidate` on the rows the fit used, fitted as the run fits them:
    leave-one-out for the forward method, 10-fold for the chain-wise one and with an instrument
    frame, each session's own with several sessions); its ``summary()`` gives
    ``crossvalidated_position_error_mm`` / ``crossvalidated_orientation_error_rad`` (RMS, mean,
    max) and ``crossvalidation``."""
    rows = ident.used
    if rows.size < 2:  # nothing to predict a row from: said in words, not as the folds' bounds
        total = len(inp.rec.sets)
        what = "the recording holds one data row" if total == 1 else \
            f"of its {total} rows one calibration row is left to fit once the gross rows are out"
        raise ValueError(f"{inp.where}: {what}: a calibration is judged by predicting rows it did not use, and one "
                         "row leaves none (add validation rows, or measure more poses spread over the workspace)")
    if ident.instrument is not None:
        several = inp.n_sessions > 1
        cv = crossvalidate(inp.robot, inp.joints[rows], inp.measured[rows], inp.noise, method="forward",
                           folds=min(INSTRUMENT_FOLDS, rows.size), prior=inp.prior,
                           measurement=crossvalidation_settings(inp, ident.instrument), seed=settings.seed,
                           sessions=inp.sessions[rows] if several else None)
    else:
        kw = {"solver": ident.solver}
        if settings.method == "chainwise":
            kw.update(weighted=settings.weighted, epsilon=paper.PAPER_EPSILON)
        cv = crossvalidate(inp.robot, inp.joints[rows], ident.measured[rows], inp.noise, method=settings.method,
                           prior=inp.prior, fit_kwargs=kw, seed=settings.seed)
    return cv


def crossvalidation_settings(inp: CalibrationInput, instrument):
    """How each fold fits the instrument: the frame estimated (from the run's) where the run
    estimated it, else the base frame; with several sessions one settings a session (its frame),
    the targets session 0's (as :func:`sessions_fit`)."""
    ms = inp.measurement(0)
    if inp.n_sessions == 1:
        return replace(ms, frame="estimate" if instrument.frame_estimated else "base",
                       initial_frame=instrument.frame if instrument.frame_estimated else None)
    per = [inp.measurement(s) for s in range(inp.n_sessions)]
    return [replace(one, frame="estimate" if estimated else "base", initial_frame=frame if estimated else None,
                    targets=per[0].targets, estimate_targets=per[0].estimate_targets)
            for one, frame, estimated in zip(per, instrument.frames, instrument.frames_estimated)]


#: False-alarm probability of the verdict's chi-square tests (the fit, the predictions).
VERDICT_ALPHA = 1e-3


def chi2_limit(dof: int) -> float:
    """The chi-square's ``1 - VERDICT_ALPHA`` quantile on ``dof`` degrees of freedom."""
    return float(2.0 * gammaincinv(dof / 2.0, 1.0 - VERDICT_ALPHA))


def prediction_check(inp: CalibrationInput, ident: Identification, held, cv) -> dict | None:
    """Whether the predictions of rows the fit did not use agree with what the fit says they can be:
    each row's prediction residual (validation rows, or the cross-validation's) whitened by its
    covariance, the declared noise plus the identified parameters' uncertainty carried to the pose
    (``S + J Sigma J^T``), summed against the chi-square on their coordinates. None where there is
    nothing to test (a simulated run's held-out errors are noise-free truths; target data)."""
    if inp.rec is None or ident.instrument is not None and ident.instrument.targets is not None:
        return None
    robot, result = inp.robot, ident.result
    if held is not None:
        joints, poses, residuals, what = inp.val_joints, inp.val_meas, held[1], "validation rows"
    elif cv is not None:
        joints, poses = inp.joints[ident.used], ident.measured[ident.used]
        residuals, what = cv.residuals, f"cross-validation ({cv.scheme})"
    else:
        return None
    ok = np.all(np.isfinite(residuals), axis=1)
    if not ok.any():
        return {"what": what, "agrees": False, "ratio": None, "rows": 0}
    joints, poses, residuals = joints[ok], poses[ok], residuals[ok]
    std = inp.noise.pose_std(robot.pose_units)
    try:
        groups = inp.val_sessions[ok] if ident.instrument is not None and held is not None else \
            np.full(len(joints), BASE_FRAME)
        cov = np.empty((len(joints), robot.pose_dim, robot.pose_dim))
        base = groups == BASE_FRAME  # in the base frame: the geometry's uncertainty alone
        if base.any():
            jac = pose_jacobian_of_parameters(robot, result.theta, joints[base], poses[base])
            # J Sigma J^T row by row: one (N D, P) x (P, P) product, then (D, P) x (P, D) per row
            # (a three-operand einsum without a contraction order loops over N D P P D terms)
            js = (jac.reshape(-1, jac.shape[2]) @ result.covariance).reshape(jac.shape)
            cov[base] = js @ np.swapaxes(jac, 1, 2)
        if (~base).any():  # geometry and frames' uncertainty together
            cov[~base] = ident.instrument.prediction_covariance(
                joints[~base], sessions=groups[~base] if inp.n_sessions > 1 else None)
        cov += np.diag(std ** 2)
    except KinematicsError:
        return {"what": what, "agrees": False, "ratio": None, "rows": 0}
    w = np.linalg.solve(np.linalg.cholesky(cov), residuals[:, :, None])[:, :, 0]
    chi2, dof = float(np.sum(w ** 2)), int(w.size)
    limit = chi2_limit(dof)
    return {"what": what, "agrees": bool(chi2 <= limit), "ratio": float(np.sqrt(chi2 / dof)),
            "limit_ratio": float(np.sqrt(limit / dof)), "rows": int(ok.sum())}


def verdict_block(inp: CalibrationInput, ident: Identification, held, cv, diagnosis=None) -> dict:
    """``success`` and ``verdict``: success only where the fit converged, the calibration rows it
    used (less the gross rows) fit within the declared noise and the predictions of rows it did not
    use agree (:func:`prediction_check`); otherwise the likely cause with its evidence: the
    recording's diagnosis (:func:`calib.diagnosis.diagnose`, made by the checks before any fit)
    where it names one, else :func:`likely_cause`. ``diagnosis``: the diagnosis' summary, rows
    1-based."""
    result = ident.result
    dof = max(int(result.dof), 1)
    fit_ok = bool(np.isfinite(result.chi2) and result.chi2 <= chi2_limit(dof))
    check = prediction_check(inp, ident, held, cv)
    success = bool(result.success and fit_ok and (check is None or check["agrees"]))
    evidence = {"converged": bool(result.success), "fit_ratio": float(np.sqrt(result.chi2 / dof)),
                "fit_limit_ratio": float(np.sqrt(chi2_limit(dof) / dof)), "fit_at_noise": fit_ok,
                "predictions": check}
    block = {"diagnosis": None if diagnosis is None else diagnosis_summary(diagnosis, inp)}
    uninformed = information_verdict(inp, ident) or description_verdict(inp, ident)
    if uninformed is not None:
        cause, words = uninformed
        return {**block, "success": False, "verdict": {"words": words, "cause": cause, "evidence": evidence}}
    if success:
        words = "calibrated: the rows fit to the declared noise" + (
            f" and the {check['what']} are predicted to it" if check else "")
        return {**block, "success": True, "verdict": {"words": words, "cause": None, "evidence": evidence}}
    if diagnosis is not None and diagnosis.cause in ("conversion", "unmeasured column"):
        cause, words = diagnosis.cause, f"not calibrated: {diagnosis.message}"
    else:
        cause, words = likely_cause(inp, ident, evidence)
    return {**block, "success": False, "verdict": {"words": words, "cause": cause, "evidence": evidence}}


def information_verdict(inp: CalibrationInput, ident: Identification) -> tuple[str, str] | None:
    """``(cause, words)`` of a fit that learnt nothing from its rows, else None: rows that do not
    move the machine (every calibration row used at one pose, :func:`calib.diagnosis.no_motion_words`:
    ``"no_motion"``), or, with the tolerances as a prior, no parameter determined by the data
    (:meth:`calib.engine.IdentificationResult.parameter_sources`: none whose posterior standard
    deviation fell below half the prior's, none moved beyond 3 prior standard deviations:
    ``"no_information"``), and fewer than one direction determined singly or in combinations
    (:meth:`calib.engine.IdentificationResult.directions_determined`: a plane of poses determines
    combinations, not single parameters). Such a fit is never a success, however well the rows fit."""
    from calib.diagnosis import no_motion_words, same_pose_rows

    robot, result = inp.robot, ident.result
    joints = inp.joints[ident.used]
    still = no_motion_words(robot, joints, inp.noise.joint_std)
    if still is not None:
        return "no_motion", f"not calibrated: {still}"
    sources = result.parameter_sources()
    seen = result.directions_determined()
    if seen is None or seen >= MIN_DETERMINED or any(v == "data" for v in sources.values()):
        return None
    free = [n for n, v in sources.items() if v != "held"]
    same = len(same_pose_rows(robot, joints, inp.noise.joint_std))
    rows = f"; {same} of {len(joints)} rows are the same pose" if same > 1 else ""
    noise = inp.noise.pose_std(robot.pose_units)
    idx = robot.table.indices(free)
    units = np.array(robot.table.units)[idx]
    tolerance = ", ".join(f"{np.median(result.prior.std[idx][units == u]):.3g} {u}" for u in dict.fromkeys(units))
    return "no_information", (
        f"not calibrated: the rows determine nothing beyond the tolerance: of the {len(free)} parameters none has "
        f"its standard deviation below half its tolerance, none moved beyond 3 tolerances, and all together they "
        f"determine {seen:.2g} of the {len(free)} directions (noise standard deviation "
        f"{noise[0]:.3g} {robot.pose_units[0]} against a tolerance of {tolerance}{rows}): the geometry reported "
        "is the prior's, not a measurement; measure more poses, spread over the workspace, or with less noise")


def description_verdict(inp: CalibrationInput, ident: Identification) -> tuple[str, str] | None:
    """``("description", words)`` where the fitted errors are a scale of the nominal geometry
    described (:func:`calib.diagnosis.description_pattern`, against the declared tolerance or the
    robot's default, not one learnt from these rows: the learnt one grows to hold the pattern):
    the sidecar describes another machine; else None."""
    from calib.diagnosis import description_pattern

    robot, result = inp.robot, ident.result
    reference = inp.tolerance if inp.tolerance_declared and inp.tolerance is not None else ParameterPrior.default(robot)
    pattern = description_pattern(robot, result.errors, reference.std, result.free_names)
    if not pattern:
        return None
    where = f" in {sidecar_name(inp.where)}" if inp.rec is not None else ""
    return "description", (f"not calibrated: the fitted errors are a pattern of the description, not physics: "
                           f"{'; '.join(p['words'] for p in pattern)}: the nominal geometry{where} seems to be another "
                           "machine's; give this machine's nominal geometry")


def diagnosis_summary(diagnosis, inp: CalibrationInput) -> dict:
    """The diagnosis' summary with its gross rows as 1-based data rows of the recording."""
    out = diagnosis.summary()
    if "gross_rows" in out:
        out["gross_rows"] = [int(r) + 1 for r in out["gross_rows"]]
    return out


def likely_cause(inp: CalibrationInput, ident: Identification, evidence: dict) -> tuple[str, str]:
    """``(cause, words)`` of a calibration that is no success: a diagnosed mistake in the file, gross
    rows, or physics the geometric model leaves out."""
    where = inp.where
    if not evidence["converged"]:
        return "no_convergence", f"not calibrated: the fit did not converge ({ident.result.message})"
    search = ident.gross
    if search is not None and not search.success:
        beyond = int(np.sum(search.statistic > search.cutoff))
        if 2 * beyond <= search.statistic.size:  # the search failed for another reason: say which
            return "gross_search_failed", (f"not calibrated: the gross-row search could not judge the rows "
                                           f"({search.message}), and the fit on every row is "
                                           f"{evidence['fit_ratio']:.3g} times the declared noise off the model")
        return "model_misfit", (f"not calibrated: the model misfits most rows ({beyond} of {search.statistic.size} "
                                f"beyond the declared noise even after the trimmed fits), so no row can be called "
                                f"gross: physics the geometric model leaves out (run python -m pipeline.discover "
                                f"--real {where}) or a mistake in the file")
    if evidence["fit_at_noise"] and evidence["predictions"]["ratio"] is None:
        return "unpredictable_rows", (f"not calibrated: the model cannot predict the {evidence['predictions']['what']} "
                                      "(it cannot reach their joints): a geometry far from the nominal one")
    ratio = evidence["fit_ratio"] if not evidence["fit_at_noise"] else evidence["predictions"]["ratio"]
    what = "the calibration rows" if not evidence["fit_at_noise"] else f"the {evidence['predictions']['what']}"
    return "left_out_physics", (f"not calibrated: {what} are {ratio:.3g} times the declared noise off the model: "
                                f"physics the geometric model leaves out (run python -m pipeline.discover --real "
                                f"{where}), or noise declared too small")


def as_read(inp: CalibrationInput, ident: Identification) -> AsRead:
    """The recording as the run read it (see :class:`AsRead`).

    Raises:
        ValueError: position-only target data (their poses are the model's, not measurements).
    """
    rec, instrument = inp.rec, ident.instrument
    block = {"gross_rows": gross_block(inp, ident)}
    measured = rec.measured
    if instrument is not None:
        if instrument.targets is not None:
            raise ValueError(f"{inp.where}: position-only target data (meta.measurement.targets): the analysis "
                             "needs full poses")
        several = inp.n_sessions > 1
        measured = in_base_frame(instrument, rec.measured, session_index(rec), several)
        block["measurement_frame"] = instrument.frame_dict()
        block["measurement_frame_std"] = frame_to_dict(instrument.frame_std)
        if several:
            block.update(sessions_block(inp, instrument))
    gross = [int(inp.rows[i]) for i in ident.gross_idx]
    meta = rec.meta
    if inp.tolerance is not None and not inp.tolerance_declared and inp.tolerance_estimate is not None:
        # The tolerance learnt from the rows travels with the recording as read: every later fit of it
        # (discovery's) takes it as the run did, and says where it came from.
        meta = {**rec.meta, "parameter_tolerance": inp.tolerance.tolerance_by_name(inp.robot),
                TOLERANCE_SOURCE_KEY: inp.prior_source}
    return AsRead(recording=replace(rec, measured=measured, meta=meta), gross_rows=gross, block=block)


def sessions_block(inp: CalibrationInput, fit) -> dict:
    """Summary keys of a recording with several sessions: each session's instrument frame and its
    standard uncertainty, and how each moved from the first (the gauge-free figure)."""
    names = inp.frame_sessions
    motion = {}
    for s in range(1, len(names)):
        m, sd = fit.session_motion(s, 0)
        motion[names[s]] = {"motion": frame_to_dict(m), "std": frame_to_dict(sd)}
    return {"measurement_frames": {names[s]: d for s, d in fit.frames_dict().items()},
            "measurement_frames_std": {names[s]: frame_to_dict(fit.frames_std[s]) for s in range(len(names))},
            "session_motion": motion}


def read_as_a_run_does(path, rec: Recording, *, seed: int = 0) -> AsRead:
    """``rec`` (read from ``path``) as :func:`run_calibration` reads it, without calibrating: the
    same gross-row stage and instrument frame registration (one code path for every command that
    reads a recording)."""
    settings = RunSettings(real=Path(path), seed=seed)
    inp = read_input(settings, rec)
    return as_read(inp, identify_step(inp, settings, []))


def gross_block(inp: CalibrationInput, ident: Identification) -> dict | None:
    """Summary key of the gross-row stage (None for a simulated run): the rows named (1-based data
    rows), whether they were left out, whether an instrument frame was inferred from the rest, the
    finding in words."""
    search = ident.gross
    if search is None:
        return None
    return {"test": "trimmed fits (random subsets and concentration steps), then rows beyond the chi-square "
                    f"{1 - GROSS_ALPHA:g} quantile of their coordinates named gross",
            "rows": [int(inp.rows[i]) + 1 for i in ident.gross_idx], "left_out": bool(ident.gross_idx) and
            len(ident.kept) < len(inp.measured), "frame_estimated": bool(search.frame_estimated),
            "success": bool(search.success), "message": search.message,
            "search": getattr(search, "search", "every row") if not isinstance(search, SessionSearch) else
            "; ".join(f"session {s + 1}: {one.search}" for s, one in enumerate(search.searches))}


def prior_block(inp: CalibrationInput, result: IdentificationResult) -> dict:
    """Summary keys of what the data determined: the prior used, per parameter its posterior
    standard deviation and source (``data`` below half the prior's, else ``prior``; ``held``),
    the combinations the poses left to the prior, in words."""
    left = [c["combination"] + (f" ({inp.robot.chain_word} {c['chain'] + 1})" if c["chain"] is not None else "")
            + f": posterior {c['std_ratio']:.2f} x the prior" for c in result.left_to_prior()]
    sources = result.parameter_sources()
    est = inp.tolerance_estimate
    seen = result.directions_determined()
    return {"prior": {"used": inp.prior is not None, "source": inp.prior_source,
                      "tolerance": None if inp.prior is None else inp.prior.tolerance_by_name(inp.robot),
                      "declared": inp.tolerance_declared,
                      "learnt": None if est is None else est.summary()},
            "parameter_determination": result.determination(),
            "determined_by": {src: [n for n, v in sources.items() if v == src] for src in ("data", "prior", "held")},
            "directions_determined": seen,
            "left_to_prior": left}


def suggested_poses(inp: CalibrationInput, ident: Identification, settings: RunSettings, summary: dict):
    """``(command file CSV text, its sidecar JSON text)``: :data:`SUGGESTED_POSES` poses that
    determine what the measured ones left to the prior (:func:`calib.design.augment_poses`, over
    the robot's full workspace), with the joints the nominal controller commands for them, ready to
    measure; ``summary["suggested_poses"]`` says which kind of pose they are, in words."""
    robot, result = inp.robot, ident.result
    measured = ident.measured[ident.used]
    poses = augment_poses(robot, result.theta, measured, SUGGESTED_POSES, inp.noise, inp.prior.std,
                          free=result.free_names, seed=settings.seed)
    joints = robot.inverse_kinematics(robot.table.nominal, poses)
    words = pose_kind_words(robot, measured, poses)
    summary["suggested_poses"] = {"poses": int(len(poses)), "what": words,
                                  "why": f"the measured poses leave {len(summary['left_to_prior'])} parameter "
                                         "combination(s) to the prior"}
    meta = {"robot": robot.name, "kind": "calibration command file", "purpose": "suggested calibration poses",
            "columns": list(command_columns(robot)),
            "units": "pose and joint units in the column names; joints are the nominal controller's commands",
            "why": summary["suggested_poses"]["why"], "what": words, "left_to_prior": summary["left_to_prior"]}
    return command_csv(robot, poses, joints), json.dumps(meta, indent=2) + "\n"


def pose_kind_words(robot: Robot, measured: np.ndarray, suggested: np.ndarray) -> str:
    """Which pose coordinates the suggested poses (K, D) explore beyond the measured ones (N, D),
    in words: ``"z from 240 to 280 mm (measured: 260 to 260 mm); ..."``."""
    lo, hi = robot.workspace_bounds()[:, 0], robot.workspace_bounds()[:, 1]
    span = np.where(hi > lo, hi - lo, 1.0)
    parts = []
    for d, (name, unit) in enumerate(zip(robot.pose_names, robot.pose_units)):
        m_lo, m_hi, s_lo, s_hi = measured[:, d].min(), measured[:, d].max(), suggested[:, d].min(), suggested[:, d].max()
        if (m_lo - s_lo) + (s_hi - m_hi) > 0.1 * span[d]:
            parts.append(f"{name} from {s_lo:.4g} to {s_hi:.4g} {unit} (measured: {m_lo:.4g} to {m_hi:.4g} {unit})")
    return "; ".join(parts) if parts else "poses like the measured ones, more of them"


def simulation_block(inp: CalibrationInput, settings: RunSettings) -> dict:
    """Summary keys of a simulated run: settling, the machine's options, how far the settled
    machine departs from its own kinematics (load, compliance, ...)."""
    robot, cal = inp.robot, inp.sim["cal"]
    options = {"gravity": settings.gravity, "payload_kg": settings.payload_kg, "stiffness": settings.stiffness,
               "friction": settings.friction}
    dep = cal.true_poses - robot.forward_kinematics(inp.actual, cal.commanded, initial=cal.true_poses)
    pos, ang = pose_error_norms(robot, dep)
    return {"settle_steps_per_pose": {"mean": float(cal.steps.mean()), "max": int(cal.steps.max())},
            "simulation": options,
            "kinematic_departure": {"position_mm": {"mean": float(pos.mean()), "max": float(pos.max())},
                                    "orientation_rad": {"mean": float(ang.mean()), "max": float(ang.max())}}}


def simulated_recording(inp: CalibrationInput, settings: RunSettings) -> Recording:
    """The recording of a simulated run (calibration rows, then the held-out rows measured under
    nominal commands)."""
    robot, sim = inp.robot, inp.sim
    parts = [sim["cal"]] + ([sim["val"]] if sim["val"] is not None else [])
    simulation = {"injected_errors": robot.table.to_dict(inp.injected), "gravity": settings.gravity,
                  "payload_kg": settings.payload_kg, "stiffness": settings.stiffness, "friction": settings.friction}
    return Recording(
        robot=robot, noise=inp.noise, t_s=np.concatenate([p.t_s for p in parts]),
        joints=np.vstack([p.encoders for p in parts]), measured=np.vstack([p.measured for p in parts]),
        sets=np.array(["calibration"] * len(parts[0].t_s) + ["validation"] * sum(len(p.t_s) for p in parts[1:])),
        meta={"scenario": inp.scenario, "seed": settings.seed, "simulation": simulation})


def log_step(inp: CalibrationInput, ident: Identification, held, summary: dict, settings: RunSettings,
             rrd_path: Path) -> None:
    """Write the run's ``.rrd`` (its default layout, the robot's application id)."""
    from calib.observability import analyze_observability
    from pipeline.formats import report_markdown
    from pipeline.views import application_id, blueprint, log_calibration_run, run_eye, run_magnification, save_recording
    from pipeline.views.run_view import MAX_MACHINE_POSES, drawn_poses

    robot, result, joints, measured = inp.robot, ident.result, inp.joints, ident.measured
    nominal = robot.table.nominal
    analysis = analyze_observability(robot, result.start, measured[ident.used], inp.noise, joints=joints[ident.used])
    summary["observability"] = {"condition_number": float(analysis.condition_number),
                                "crb_std": robot.table.to_dict(analysis.crb_std)}
    targets = inp.sim["targets"] if inp.sim is not None else _predicted_or(robot, nominal, joints, measured)
    predicted = _predicted_or(robot, result.theta, joints, measured)
    magnified = run_magnification(robot, nominal, inp.actual, result.theta, targets, measured)
    history_label = "max dQint (mm)" if (settings.method == "chainwise" and ident.solver == "gn") else "cost"
    heldout_before, heldout_after = (None, None) if held is None else held
    n, shown = len(joints), drawn_poses(len(joints)).size
    summary["rerun"] = {"machine_poses_drawn": shown, "form": "every calibration pose drawn in 3D" if shown == n else
                        f"the 3D machines and arrows at {shown:,} evenly spaced poses of the {n:,} ({n:,} rows > "
                        f"MAX_MACHINE_POSES = {MAX_MACHINE_POSES}); every pose's residuals on the pose timeline"}
    if heldout_before is not None and heldout_before.shape[1] != robot.pose_dim:  # target positions
        heldout_before = heldout_after = None

    def log(stream):
        log_calibration_run(stream, robot=robot, nominal=nominal, actual=inp.actual, identified=result.theta,
                            std=result.std, joints=joints, targets=targets, measured=measured,
                            predicted=predicted, history=result.history, heldout_before=heldout_before,
                            heldout_after=heldout_after, summary_markdown=report_markdown(build_report(summary)),
                            observability=analysis, flagged=ident.flagged_idx, history_label=history_label,
                            magnified=magnified)

    bp = blueprint(robot, eye=run_eye(robot, nominal, targets), magnified=magnified,
                   has_heldout=heldout_before is not None, history_label=history_label, has_truth=inp.actual is not None)
    save_recording(rrd_path, log, application_id=application_id("run", robot.name), overwrite=True, bp=bp)


def _run(settings: RunSettings, rec, warnings: list, progress, split: dict, t0: float, outputs, diagnosis=None):
    """The analysis of :func:`run_calibration`, in its named steps: simulate or read, identify,
    validate, summarise, log (the ``.rrd`` to its temporary file); the caller publishes."""
    inp = read_input(settings, rec) if rec is not None else simulate_input(settings, progress)
    split["simulate"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    ident = identify_step(inp, settings, warnings, stages := {})
    split["identify"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    held, truth_in_gauge, *comparison = validate_step(inp, ident, settings, progress)
    split["simulate"] += time.perf_counter() - t2
    summary = summary_of(inp, ident, held, truth_in_gauge, comparison, settings, warnings)
    cv = None
    split.update(stages)
    if inp.rec is not None and held is None:
        t_cv = time.perf_counter()
        cv = crossvalidation_of(inp, ident, settings)
        summary.update(cv.summary())
        split["crossvalidation"] = time.perf_counter() - t_cv
    t_v = time.perf_counter()
    summary.update(verdict_block(inp, ident, held, cv, diagnosis))
    split["verdict"] = time.perf_counter() - t_v
    if inp.sim is not None:
        summary["_recording"] = simulated_recording(inp, settings)
    summary["_calibration"] = calibration_of(inp, ident, summary.get("_recording"))
    t_s = time.perf_counter()
    if summary["left_to_prior"]:
        try:
            summary["_suggested_poses"] = suggested_poses(inp, ident, settings, summary)
        except (ValueError, ArithmeticError) as exc:  # KinematicsError and LinAlgError are ValueErrors
            summary["suggested_poses"] = {"poses": 0, "what": f"none suggested: {exc}", "why": ""}
    if inp.rec is not None:
        try:
            summary["_as_read"] = as_read(inp, ident)
        except ValueError:  # position-only targets: nothing for a pose analysis to read
            pass
    split["summary"] = time.perf_counter() - t_s
    t3 = time.perf_counter()
    log_step(inp, ident, held, summary, settings, outputs.temp("rrd"))
    split["log"] = time.perf_counter() - t3
    return summary, ident.result


def sha256_text(text: str) -> str:
    """The SHA-256 of ``text`` as written (UTF-8)."""
    return hashlib.sha256(text.encode()).hexdigest()


def instrument_frames(inp: CalibrationInput, instrument) -> tuple[dict, dict]:
    """``({session: (6,) frame}, {session: (6,) std})`` of a fit's instrument frames, empty when the
    data were in the base frame."""
    if instrument is None or not np.any(instrument.frames):
        return {}, {}
    if inp.rec is None:
        return {"session 1": np.array(instrument.frames[0])}, {"session 1": np.array(instrument.frames_std[0])}
    groups, index = frame_groups(inp.rec)  # every session (those captured in another's frame too)
    first = {name: int(index[inp.rec.session_rows(name)[0]]) for name in inp.rec.session_names}
    return ({n: np.array(instrument.frames[g]) for n, g in first.items() if g != BASE_FRAME},
            {n: np.array(instrument.frames_std[g]) for n, g in first.items() if g != BASE_FRAME})


def calibration_of(inp: CalibrationInput, ident: Identification, simulated: Recording | None) -> Calibration:
    """What the run found, as a calibration file holds it (:mod:`pipeline.formats.calibration_file`;
    the recording's name and hashes are added when the files are written): the identified
    geometry, the instrument frames, no effect, the domain of the rows used."""
    robot, result, used = inp.robot, ident.result, ident.used
    idx = robot.table.indices(result.free_names)
    rows = inp.rows[used]
    t_s = (inp.rec if inp.rec is not None else simulated).t_s[rows]
    frames, frames_std = instrument_frames(inp, ident.instrument)
    return Calibration(robot=robot, theta=result.theta, std=result.std, free=tuple(result.free_names),
                       covariance=result.covariance[np.ix_(idx, idx)], frames=frames, frames_std=frames_std,
                       targets=None if ident.instrument is None else ident.instrument.targets,
                       validity=validity_domain(robot, ident.measured[used], inp.joints[used], t_s, result.theta),
                       noise=inp.noise,
                       produced_by="pipeline.run")


def _predicted_or(robot: Robot, theta, joints, measured) -> np.ndarray:
    """The forward kinematics of ``theta`` at ``joints``, or the measured poses where it fails."""
    try:
        return robot.forward_kinematics(theta, joints, initial=measured)
    except KinematicsError:
        return measured


def sidecar_name(csv_path) -> str:
    from pipeline.formats import sidecar_path

    return str(sidecar_path(csv_path))
