"""One calibration run for any registered robot: simulate (or read) measurements, identify,
compensate, validate on held-out poses, write the recording, the summary and the ``.rrd``.

``python -m pipeline.run`` parses its flags into :class:`RunSettings`, calls
:func:`run_calibration` and prints the :class:`RunResult`'s report (made from the run's objects:
:func:`pipeline.report.calibration.calibration_report`). The summary has the same keys for every
robot, written from the report (:func:`pipeline.report.summary.summary_keys`).
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from calib import paper
from calib.calibration import Calibration
from calib.design import augment_poses
from calib.engine import IdentificationResult, gauge_representative
from calib.identification import (BASE_FRAME, CalibrationData, CalibrationOutcome, Identification, UnreachableRows,
                                  calibrate_checked, checked_data, checked_options)
from calib.measurement import frame_to_dict, measured_gauge_representative
from calib.metrics import calibration_gain
from calib.noise import SensorNoise
from calib.observability import identification_jacobian
from calib.prior import DATA_SOURCE_RATIO, IMPLAUSIBLE_TOLERANCES, ParameterPrior, implausible_errors
from calib.robot import KinematicsError, Robot, check_joint_limits
from calib.robots import default_robot, reference_errors, reference_poses
from calib.workspace import reachable_poses
from pipeline.formats import (CALIBRATION_SUFFIX, NameReservation, Recording, command_columns, command_csv, output_folder,
                              frame_session, row_message, session_measurement)
from pipeline.report import Report, render_html
from pipeline.report.calibration import (ROW_NUMBERING, calibration_report, finished_report, parameter_error,
                                         with_suggested, without_file)
from pipeline.report.summary import (diagnosis_summary, gross_keys, gross_stage, instrument_fit, run_record,
                                     session_keys, summary_keys)
from pipeline.report.verdict_words import implausible_sentence

from .options import check_noise_flags

__all__ = ["RunSettings", "RunResult", "SuggestedPoses", "AsRead", "run_calibration", "read_as_a_run_does", "machine_tolerance",
           "implausible_parameters", "IMPLAUSIBLE_TOLERANCES", "DEFAULT_CONFIGURATIONS", "DEFAULT_ROBOT", "ROW_NUMBERING",
           "default_name", "OUTPUT_EXTENSIONS", "DETERMINED_DIRECTION", "directions_added"]

#: Calibration poses of a robot whose reference experiment names none.
DEFAULT_CONFIGURATIONS = 20
#: The robot simulated when none is named.
DEFAULT_ROBOT = "hexapod"


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
        frames, frames_std: ``{session: (6,) frame}`` the instrument frames registered and their
            standard uncertainties (:func:`instrument_frames`; empty: the base frame).
    """

    recording: Recording
    gross_rows: list
    block: dict
    frames: dict = field(default_factory=dict)
    frames_std: dict = field(default_factory=dict)


@dataclass
class RunResult:
    """Everything a run produced: its summary (the keys ``--summary-json`` writes), its report (the
    typed model every rendering reads; its files include the summary JSON's), the identification."""

    summary: dict
    result: IdentificationResult
    report: Report
    paths: dict = field(default_factory=dict)
    #: The recording read from ``RunSettings.real`` (None for a simulated run).
    recording: Recording | None = None
    #: The recording as the run read it (None for a simulated run): what discovery analyses.
    as_read: AsRead | None = None
    #: The calibration the run made, as its file holds it (its recording named and hashed).
    calibration: Calibration | None = None
    #: The recording a simulated run made (None for a recording read).
    simulated: Recording | None = None
    #: The poses suggested to measure next (None: none suggested).
    suggested_poses: SuggestedPoses | None = None


@dataclass(frozen=True, eq=False)
class SuggestedPoses:
    """Poses suggested to measure next (:func:`suggested_poses`): (K, D) poses, (K, C) the joints
    the nominal controller commands for them, and what their command file's sidecar says (``meta``:
    robot, kind, purpose, columns, units, why, what, left_to_prior)."""

    robot: Robot
    poses: np.ndarray
    joints: np.ndarray
    meta: dict

    def texts(self) -> tuple[str, str]:
        """``(command file CSV text, its sidecar JSON text)``, as the run writes them."""
        return command_csv(self.robot, self.poses, self.joints), json.dumps(self.meta, indent=2) + "\n"


@dataclass(frozen=True)
class RunObjects:
    """What a run's analysis made besides its summary: its report (before its files and timing are
    known), the calibration (before its provenance is set), the simulated recording, the suggested
    poses, the recording as read."""

    report: Report
    calibration: Calibration
    simulated: Recording | None = None
    suggested_poses: SuggestedPoses | None = None
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
#: The output keys of the suggested poses' command file and its sidecar.
SUGGESTED_KEYS = ("suggested_poses", "suggested_poses_json")


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


def in_base_frame(fit, measured, groups, several: bool) -> np.ndarray:
    """(N, D) full poses ``measured`` taken out of their rows' instrument frames (``groups``: each
    row's frame group, :func:`frame_groups`; rows in :data:`calib.identification.BASE_FRAME` as they
    are; ``several``: the fit has several frames)."""
    out = np.array(measured, dtype=float)
    at = groups != BASE_FRAME
    out[at] = fit.to_base(out[at], sessions=groups[at] if several else None)
    return out


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
    rec = diagnosis = checks = None
    if settings.real is None:
        check_noise_flags(default_robot(settings.robot or DEFAULT_ROBOT), simulated_noise(settings))
    else:
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
            result, made = _run(settings, rec, warnings, progress, split, t0, outputs, diagnosis,
                                None if checks is None else {"excitation": checks.excitation})
            if made.suggested_poses is None:
                for key in SUGGESTED_KEYS:
                    outputs.drop(key)
                    targets_out.pop(key)
            paths = {k: str(v) for k, v in targets_out.items()}
            report = finished_report(made.report, paths, time.perf_counter() - t0, split)
            report = replace(report, run=replace(report.run, suggested_poses_json=paths.get("suggested_poses_json")))
            calibration = write_data_files(outputs, report, settings, targets_out, made)
            outputs.publish()
    finally:
        reservation.release()
    return RunResult(summary=summary_keys(report), result=result, report=report, paths=paths, recording=rec, as_read=made.as_read,
                     calibration=calibration, simulated=made.simulated, suggested_poses=made.suggested_poses)


def write_data_files(outputs, report: Report, settings: RunSettings, targets_out: dict,
                     made: RunObjects) -> Calibration:
    """Write the summary JSON (when asked: the summary's keys written from ``report``,
    :func:`pipeline.report.summary.summary_keys`, and its model), the HTML
    report (when asked), the simulated recording (when simulating), the calibration file (its
    recording named and hashed) and the identified machine's MJCF (when asked,
    :func:`pipeline.simulation.mjcf_export.mjcf_text`) to their temporary files in ``outputs``;
    returns the calibration as written; the suggested poses' command file and sidecar (when
    suggested). The summary JSON and the page list the files but the summary JSON itself."""
    from pipeline.formats import calibration_text, recording_source, recording_texts
    from pipeline.report import REPORT_KEY

    report = without_file(report, "summary_json")
    recording, calibration = made.simulated, made.calibration
    if made.suggested_poses is not None:
        for key, text in zip(SUGGESTED_KEYS, made.suggested_poses.texts()):
            outputs.temp(key).write_text(text)
    if "summary_json" in targets_out:
        outputs.temp("summary_json").write_text(json.dumps({**summary_keys(report), REPORT_KEY: report.to_dict()},
                                                           indent=1))
    if "report" in targets_out:
        outputs.temp("report").write_text(render_html(report))
    if recording is not None:
        csv_text, json_text = recording_texts(recording)
        outputs.temp("csv").write_text(csv_text)
        outputs.temp("json").write_text(json_text)
        source = {"name": Path(targets_out["csv"]).name, "simulated": report.source.recording,
                  "sha256": sha256_text(csv_text), "sidecar_sha256": sha256_text(json_text)}
    else:
        source = recording_source(settings.real)
    calibration = replace(calibration, recording=source, produced_by="pipeline.run")
    outputs.temp("calibration").write_text(calibration_text(calibration))
    if "mjcf" in targets_out:
        from pipeline.simulation.mjcf_export import mjcf_text

        outputs.temp("mjcf").write_text(mjcf_text(calibration))
    return calibration




@dataclass(frozen=True, eq=False)
class CalibrationInput:
    """The measurements a run calibrates from, simulated or read (the first step of a run): the
    checked data of :func:`calib.identification.calibrate_checked` (:func:`calibrate_input`) and
    what the run knows about them besides.

    Attributes:
        data: the rows, noise, frame groups, validation rows and declared tolerance, checked
            (:func:`calib.identification.checked_data`; :attr:`CalibrationData.where` names the file,
            or the simulated poses). Its ``tolerance`` is the one declared
            (:func:`declared_tolerance`): the prior (unless --no-prior), and the yardstick of
            :func:`implausible_parameters`; where none is declared the run may learn one from the rows
            (:func:`calib.identification.learn_tolerance`, :attr:`calib.identification.CalibrationOutcome.data`
            holds the one used). A simulated run's data have no validation rows, one frame group and
            poses in the base frame.
        scenario: the run's scenario in words.
        actual, injected: the true parameter vector and its errors, when known (else None).
        rec: the recording read (None when simulating); sim: the simulation's parts (None when reading).
    """

    data: CalibrationData
    scenario: str
    actual: np.ndarray | None
    injected: np.ndarray | None
    rec: Recording | None = None
    sim: dict | None = None

    @property
    def n_sessions(self) -> int:
        """Instrument frames of the recording: its sessions with a frame of their own and
        calibration rows (:func:`frame_groups`; 1 for a simulated run)."""
        return 1 if self.rec is None else len(self.data.session_names)


def calibrate_input(inp: CalibrationInput, settings: RunSettings, *, diagnosis=None, progress=None,
                    assess: bool = True) -> CalibrationOutcome:
    """The identification policy (:func:`calib.identification.calibrate_checked`) on ``inp`` as
    ``settings`` ask: a recording's rows searched for gross rows and cross-validated where it has no
    validation rows; a simulated run's held-out errors measured on its machine (:func:`simulated_heldout`).

    Raises:
        ValueError: rows that cannot be calibrated; a row the model cannot reach named by its data
            row in the recording (:func:`pipeline.formats.row_message`).
    """
    sim = inp.sim
    heldout = simulated_heldout(inp, progress) if sim is not None and sim["val"] is not None else None
    recorded = inp.rec is not None
    options = checked_options(method=settings.method, solver=settings.solver, weighted=settings.weighted,
                              keep_outliers=settings.keep_outliers, search_gross_rows=recorded,
                              cross_validate=recorded, seed=settings.seed)
    try:
        return calibrate_checked(inp.data, options, heldout=heldout, diagnosis=diagnosis, assess=assess)
    except UnreachableRows as exc:
        raise ValueError(f"{row_message(exc.kinematics, exc.where, exc.rows)} ({exc.what})") from None


def simulated_heldout(inp: CalibrationInput, progress):
    """``errors(theta) -> (before, after)``: the simulated machine's held-out poses (N, D), measured
    noise-free under nominal commands (before) and under the model ``theta``'s compensated commands
    (after), minus the targets.

    Raises (from ``errors``):
        ValueError: the model cannot command a held-out pose (its geometry is implausible).
    """
    robot, sim = inp.data.robot, inp.sim
    progress = progress or (lambda label, done, total: None)

    def errors(theta):
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

    return errors


#: The key of a recording-as-read's meta saying where its ``parameter_tolerance`` came from when a
#: run learnt it from the rows (:func:`calib.identification.learn_tolerance`; never written to a file).
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


def implausible_parameters(robot: Robot, errors: np.ndarray, tolerance: ParameterPrior, names) -> list[dict]:
    """The identified errors (P,) beyond :data:`calib.prior.IMPLAUSIBLE_TOLERANCES` times their
    tolerance, of the parameters ``names`` (:func:`calib.prior.implausible_errors`): ``{"name",
    "error", "tolerance", "unit", "words"}`` each, largest first."""
    return [dict(asdict(e), words=implausible_sentence(e)) for e in implausible_errors(robot, errors, tolerance, names)]


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
    tolerance, source = declared_tolerance(robot, rec.meta, sidecar_name(settings.real), settings.tolerance)
    groups, index = frame_groups(rec, where)
    cal_rows, val_rows = rec.rows("calibration"), rec.rows("validation")
    # every session's frame group (a session captured in another's frame too), as the calibration names them
    session_frames = {name: int(index[rec.session_rows(name)[0]]) for name in rec.session_names}
    data = checked_data(robot, joints, measured, rec.noise,
                        measurement=tuple(session_measurement(rec, name) for name in groups),
                        sessions=index[cal_rows], session_names=groups, session_frames=session_frames,
                        validation_joints=val_joints, validation_measured=val_meas,
                        validation_sessions=index[val_rows], validation_rows=val_rows, tolerance=tolerance,
                        tolerance_declared="parameter_tolerance" in rec.meta or settings.tolerance is not None,
                        tolerance_source=source, prior=settings.prior, rows=cal_rows, t_s=rec.t_s[cal_rows],
                        where=where, geometry_source=sidecar_name(settings.real))
    return CalibrationInput(data=data, scenario=f"recording {settings.real}",
                            actual=None if injected is None else robot.table.nominal + injected, injected=injected,
                            rec=rec)


def frame_groups(rec: Recording, where: str = "the recording") -> tuple[tuple[str, ...], np.ndarray]:
    """``(frame sessions, (N,) int)``: the sessions whose instrument frame the run fits (those with
    a frame of their own whose rows, or the rows of the sessions captured in it, include
    calibration rows; in order), and each row's place among them
    (:data:`calib.identification.BASE_FRAME` for the rows of a session without calibration rows
    declared in the base frame).

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


def simulated_noise(settings: RunSettings) -> SensorNoise:
    """The sensor noise of a simulated run (``--noise-mm``, ``--noise-rad``, ``--noise-dist``, ``--noise-joint``)."""
    return SensorNoise(settings.noise_mm, settings.noise_rad, settings.noise_dist, joint=settings.noise_joint)


def simulate_input(settings: RunSettings, progress) -> CalibrationInput:
    """The calibration input of a simulated machine (the reference errors injected, MuJoCo)."""
    robot = default_robot(settings.robot or DEFAULT_ROBOT)
    noise = simulated_noise(settings)
    sim = _simulate(robot, settings, noise, progress)
    cal = sim["cal"]
    tolerance, source = declared_tolerance(robot, None, "", settings.tolerance)
    data = checked_data(robot, cal.encoders, cal.measured, noise, tolerance=tolerance,
                        tolerance_declared=settings.tolerance is not None, tolerance_source=source,
                        prior=settings.prior, rows=np.arange(len(cal.measured)), t_s=cal.t_s,
                        where="the simulated calibration poses")
    return CalibrationInput(data=data, scenario=sim["scenario"], actual=sim["actual"], injected=sim["errors"], sim=sim)


def truth_in_gauge(inp: CalibrationInput, ident: Identification) -> np.ndarray | None:
    """(P,) the true parameters (a simulated machine's, or those a recording's sidecar names) in the
    fit's gauge (:func:`calib.engine.gauge_representative`, or with an instrument fit
    :func:`calib.measurement.measured_gauge_representative`), or None where unknown."""
    if inp.actual is None:
        return None
    robot, result, instrument = inp.data.robot, ident.result, ident.instrument
    if instrument is None:
        return gauge_representative(robot, inp.actual, result.start)
    return measured_gauge_representative(robot, inp.actual, estimate_frame=instrument.frame_estimated,
                                         targets=instrument.targets if instrument.targets_estimated else None,
                                         start=result.start)


def validation_session_shifts(inp: CalibrationInput, outcome: CalibrationOutcome) -> dict:
    """``{session: shift}`` of each recorded session with validation rows and no calibration rows
    (at least :data:`calib.effects.heldout.MIN_SESSION_ROWS`) whose rows show a shift against the
    calibration (:func:`calib.session_shift.fit_session_shift`: each joint's zero and the
    instrument frame, by evidence), with its words; empty when none shifted or nothing was read."""
    cal, rec, data = outcome.calibration, inp.rec, inp.data
    if rec is None or cal is None or not len(data.validation_joints) \
            or any(m.n_targets for m in data.measurement or ()):
        return {}
    from calib.effects.heldout import MIN_SESSION_ROWS  # a recording's run only: the default run loads no discovery
    from calib.session_shift import fit_session_shift
    from pipeline.report.text import shift_words
    robot = rec.robot
    val_rows = rec.rows("validation")
    trained = set(rec.sessions[rec.rows("calibration")].tolist())
    out = {}
    for name in dict.fromkeys(rec.sessions[val_rows].tolist()):
        at = rec.sessions[val_rows] == name
        if name in trained or at.sum() < MIN_SESSION_ROWS:
            continue
        group = int(data.validation_sessions[at][0])
        frame = cal.frames.get(data.session_names[group]) if 0 <= group < len(data.session_names) else None
        try:
            shift = fit_session_shift(robot, lambda q: robot.forward_kinematics(cal.theta, q),
                                      data.validation_joints[at], data.validation_measured[at], data.noise,
                                      frame=frame)
        except KinematicsError:  # a row the identified machine cannot reach: said by the held-out figures
            continue
        if shift.shifted:
            out[str(name)] = dict(shift.to_dict(), words=shift_words(str(name), shift, robot.joint_unit))
    return out


def truth_figures(inp: CalibrationInput, ident: Identification, truth: np.ndarray | None) -> dict | None:
    """``{"parameter_error", "gain_G_percent"}`` of the identification against ``truth``
    (:func:`truth_in_gauge`; None where unknown)."""
    if truth is None:
        return None
    robot, result = inp.data.robot, ident.result
    free = result.free_names
    return {"parameter_error": parameter_error(robot, result.theta, truth, free),
            "gain_G_percent": {k: v for k, v in calibration_gain(robot, truth, result.start, result.theta,
                                                                 free).as_dict().items() if k != "per_parameter"}}


def as_read(inp: CalibrationInput, outcome: CalibrationOutcome) -> AsRead:
    """The recording as the run read it (see :class:`AsRead`).

    Raises:
        ValueError: position-only target data (their poses are the model's, not measurements).
    """
    ident, data = outcome.identification, outcome.data
    rec, instrument = inp.rec, ident.instrument
    block = {"gross_rows": gross_keys(gross_stage(inp, ident))}
    measured, frames, frames_std = rec.measured, {}, {}
    if instrument is not None:
        if instrument.targets is not None:
            raise ValueError(f"{inp.data.where}: position-only target data (meta.measurement.targets): the analysis "
                             "needs full poses")
        several = inp.n_sessions > 1
        measured = in_base_frame(instrument, rec.measured, session_index(rec), several)
        block["measurement_frame"] = instrument.frame_dict()
        block["measurement_frame_std"] = frame_to_dict(instrument.frame_std)
        if several:
            block.update(session_keys(instrument_fit(inp, instrument)))
        frames, frames_std = instrument_frames(inp, instrument, several)
    gross = [int(inp.data.rows[i]) for i in ident.gross_idx]
    meta = rec.meta
    if not data.tolerance_declared and data.tolerance_estimate is not None:
        # The tolerance learnt from the rows travels with the recording as read: every later fit of it
        # (discovery's) takes it as the run did, and says where it came from.
        meta = {**rec.meta, "parameter_tolerance": data.tolerance.tolerance_by_name(inp.data.robot),
                TOLERANCE_SOURCE_KEY: data.tolerance_source}
    return AsRead(recording=replace(rec, measured=measured, meta=meta), gross_rows=gross, block=block, frames=frames,
                  frames_std=frames_std)


def instrument_frames(inp: CalibrationInput, fit, several: bool) -> tuple[dict, dict]:
    """``({session: (6,) frame}, {session: (6,) std})`` the instrument fit ``fit`` registered: every
    frame session's (``several``), else the recording's first session's."""
    if several:
        names = inp.data.session_names
        return ({names[s]: np.array(f, dtype=float) for s, f in enumerate(fit.frames)},
                {names[s]: np.array(sd, dtype=float) for s, sd in enumerate(fit.frames_std)})
    first = inp.rec.session_names[0]
    return {first: np.array(fit.frame, dtype=float)}, {first: np.array(fit.frame_std, dtype=float)}


def read_as_a_run_does(path, rec: Recording, *, seed: int = 0) -> AsRead:
    """``rec`` (read from ``path``) as :func:`run_calibration` reads it, without calibrating: the
    same gross-row stage and instrument frame registration (one code path for every command that
    reads a recording)."""
    settings = RunSettings(real=Path(path), seed=seed)
    inp = read_input(settings, rec)
    return as_read(inp, calibrate_input(inp, settings, assess=False))


def suggested_poses(inp: CalibrationInput, outcome: CalibrationOutcome, settings: RunSettings, left: list[str]):
    """``(suggested, block)``: ``suggested`` (:class:`SuggestedPoses`), :data:`SUGGESTED_POSES`
    poses that determine what the measured ones left to the prior (``left``, in words;
    :func:`calib.design.augment_poses`, over the robot's full workspace), with the joints the
    nominal controller commands for them, ready to measure; ``block`` the summary's
    ``suggested_poses`` (``poses``, ``what``: which kind of pose they are, in words, ``why``).
    ``suggested`` None where they would determine less than one direction more
    (:func:`directions_added`: noise that drowns the geometry), ``block`` saying so with its figures.

    The measured rows inform at the configurations the machine was in: the identified geometry's
    poses at the joints read (a measured pose carries its noise: 1000 mm puts a Delta's outside
    its workspace, where no Jacobian is)."""
    ident = outcome.identification
    robot, result = inp.data.robot, ident.result
    measured = ident.measured[ident.used]
    at = machine_poses(robot, result.theta, inp.data.joints[ident.used], measured)
    prior_std = outcome.data.prior.std
    poses = augment_poses(robot, result.theta, at, SUGGESTED_POSES, inp.data.noise, prior_std,
                          free=result.free_names, seed=settings.seed)
    why = f"the measured poses leave {len(left)} parameter combination(s) to the prior"
    added = directions_added(robot, result, at, poses, inp.data.noise, prior_std)
    if added < DETERMINED_DIRECTION:
        return None, {
            "poses": 0, "why": why,
            "what": (f"{len(poses)} more poses at the declared noise would determine {added:.2g} more of the "
                     f"{len(result.free_names)} free directions, not one (a direction determined counts "
                     f"{DETERMINED_DIRECTION:g} at least): measure with less noise")}
    joints = robot.inverse_kinematics(robot.table.nominal, poses)
    words = pose_kind_words(robot, measured, poses)
    block = {"poses": int(len(poses)), "what": words, "why": why}
    meta = {"robot": robot.name, "kind": "calibration command file", "purpose": "suggested calibration poses",
            "columns": list(command_columns(robot)),
            "units": "pose and joint units in the column names; joints are the nominal controller's commands",
            "why": why, "what": words, "left_to_prior": left}
    return SuggestedPoses(robot, poses, joints, meta), block


def machine_poses(robot: Robot, theta, joints, measured) -> np.ndarray:
    """(N, D) the poses the machine ``theta`` is in at ``joints``: its forward kinematics from the
    measured poses, or from home where a measurement is too far off to start from (its noise)."""
    try:
        return robot.forward_kinematics(theta, joints, initial=measured)
    except KinematicsError:
        return robot.forward_kinematics(theta, joints, initial=np.repeat(robot.home_pose[None], len(joints), axis=0))


#: A direction of the parameters counts as determined when the data shrink its variance below
#: ``DATA_SOURCE_RATIO ** 2`` of the prior's (:data:`calib.prior.DATA_SOURCE_RATIO`): it then adds
#: at least ``1 - DATA_SOURCE_RATIO ** 2`` to MacKay's effective number of parameters.
DETERMINED_DIRECTION = 1.0 - DATA_SOURCE_RATIO ** 2


def directions_added(robot: Robot, result, measured_at, suggested, noise: SensorNoise, prior_std) -> float:
    """How many more directions of the free parameters the ``suggested`` poses (K, D) determine
    beside the measured ones (at ``measured_at`` (N, D)): the rise of MacKay's effective number of
    parameters ``trace(I - S^-1 Sigma_post)`` (``S`` the prior's covariance) they bring."""
    idx = result.free_indices
    whitened = np.diag(prior_std[idx])  # the information in the prior's units: the prior is I

    def effective(poses) -> float:
        A = identification_jacobian(robot, result.theta, poses, noise, free=result.free_names) @ whitened
        return float(np.trace(np.linalg.solve(np.eye(idx.size) + A.T @ A, A.T @ A)))

    return effective(np.vstack([measured_at, suggested])) - effective(measured_at)


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


def simulated_recording(inp: CalibrationInput, settings: RunSettings) -> Recording:
    """The recording of a simulated run (calibration rows, then the held-out rows measured under
    nominal commands)."""
    robot, sim = inp.data.robot, inp.sim
    parts = [sim["cal"]] + ([sim["val"]] if sim["val"] is not None else [])
    simulation = {"injected_errors": robot.table.to_dict(inp.injected), "gravity": settings.gravity,
                  "payload_kg": settings.payload_kg, "stiffness": settings.stiffness, "friction": settings.friction}
    return Recording(
        robot=robot, noise=inp.data.noise, t_s=np.concatenate([p.t_s for p in parts]),
        joints=np.vstack([p.encoders for p in parts]), measured=np.vstack([p.measured for p in parts]),
        sets=np.array(["calibration"] * len(parts[0].t_s) + ["validation"] * sum(len(p.t_s) for p in parts[1:])),
        meta={"scenario": inp.scenario, "seed": settings.seed, "simulation": simulation})


def log_step(inp: CalibrationInput, ident: Identification, held, report: Report, settings: RunSettings,
             rrd_path: Path) -> dict:
    """Write the run's ``.rrd`` (its default layout, the robot's application id; its summary panel
    ``report`` as markdown); returns the summary keys of what it drew: ``observability`` (the pose
    set's condition number and Cramer-Rao std per parameter) and ``rerun`` (the poses drawn in 3D)."""
    from calib.observability import analyze_observability
    from pipeline.report import report_markdown
    from pipeline.views import application_id, blueprint, log_calibration_run, run_eye, run_magnification, save_recording
    from pipeline.views.run_view import MAX_MACHINE_POSES, drawn_poses

    robot, joints, noise = inp.data.robot, inp.data.joints, inp.data.noise
    result, measured = ident.result, ident.measured
    nominal = robot.table.nominal
    analysis = analyze_observability(robot, result.start, measured[ident.used], noise, joints=joints[ident.used])
    observability = {"condition_number": float(analysis.condition_number),
                     "crb_std": robot.table.to_dict(analysis.crb_std)}
    targets = inp.sim["targets"] if inp.sim is not None else _predicted_or(robot, nominal, joints, measured)
    predicted = _predicted_or(robot, result.theta, joints, measured)
    magnified = run_magnification(robot, nominal, inp.actual, result.theta, targets, measured)
    history_label = "max dQint (mm)" if (settings.method == "chainwise" and ident.solver == "gn") else "cost"
    heldout_before, heldout_after = (None, None) if held is None else held
    n, shown = len(joints), drawn_poses(len(joints)).size
    drawn = {"machine_poses_drawn": shown, "form": "every calibration pose drawn in 3D" if shown == n else
             f"the 3D machines and arrows at {shown:,} evenly spaced poses of the {n:,} ({n:,} rows > "
             f"MAX_MACHINE_POSES = {MAX_MACHINE_POSES}); every pose's residuals on the pose timeline"}
    if heldout_before is not None and heldout_before.shape[1] != robot.pose_dim:  # target positions
        heldout_before = heldout_after = None

    def log(stream):
        log_calibration_run(stream, robot=robot, nominal=nominal, actual=inp.actual, identified=result.theta,
                            std=result.std, joints=joints, targets=targets, measured=measured,
                            predicted=predicted, history=result.history, heldout_before=heldout_before,
                            heldout_after=heldout_after, summary_markdown=report_markdown(report),
                            observability=analysis, flagged=ident.flagged_idx, history_label=history_label,
                            magnified=magnified)

    bp = blueprint(robot, eye=run_eye(robot, nominal, targets), magnified=magnified,
                   has_heldout=heldout_before is not None, history_label=history_label, has_truth=inp.actual is not None)
    save_recording(rrd_path, log, application_id=application_id("run", robot.name), overwrite=True, bp=bp)
    return {"observability": observability, "rerun": drawn}


def _run(settings: RunSettings, rec, warnings: list, progress, split: dict, t0: float, outputs, diagnosis=None,
         checks: dict | None = None):
    """The analysis of :func:`run_calibration`, in its named steps: simulate or read, calibrate
    (:func:`calibrate_input`: identify, validate, verdict), summarise, log (the ``.rrd`` to its
    temporary file); the caller publishes. ``checks``: the summary's ``checks`` block (the
    recording checks' forms, e.g. ``{"excitation": rows in words}``), None when simulating."""
    inp = read_input(settings, rec) if rec is not None else simulate_input(settings, progress)
    split["simulate"] = time.perf_counter() - t0
    outcome = calibrate_input(inp, settings, diagnosis=diagnosis, progress=progress)
    ident, seconds = outcome.identification, outcome.seconds
    warnings += outcome.warnings
    split["identify"] = seconds["identify"]
    split["simulate"] += seconds["heldout"]  # a simulated run measures its held-out poses
    truth = truth_in_gauge(inp, ident)
    figures = truth_figures(inp, ident, truth)
    result = ident.result
    implausible = implausible_parameters(inp.data.robot, result.errors, outcome.data.tolerance, result.free_names)
    shifts = validation_session_shifts(inp, outcome)
    report = calibration_report(inp, outcome, method=settings.method, seed=settings.seed, truth=figures,
                                implausible=implausible, warnings=warnings,
                                shift_words=tuple(v["words"] for v in shifts.values()))
    record = run_record(inp, outcome, settings, truth=truth, figures=figures, implausible=implausible)
    split.update(gross_rows=seconds["gross_rows"], outlier_test=seconds["outlier_test"])
    if outcome.crossvalidation is not None:
        split["crossvalidation"] = seconds["crossvalidation"]
    split["verdict"] = seconds["verdict"]
    verdict = outcome.verdict
    record = replace(record, checks=checks,
                     crossvalidation=None if outcome.crossvalidation is None else outcome.crossvalidation.summary(),
                     diagnosis=None if verdict.diagnosis is None else diagnosis_summary(verdict.diagnosis, inp),
                     evidence=verdict.evidence.to_dict(), session_shifts=shifts)
    simulated = simulated_recording(inp, settings) if inp.sim is not None else None
    t_s = time.perf_counter()
    suggestion = read = None
    if report.parameters.left_to_prior:
        try:
            suggestion, suggested = suggested_poses(inp, outcome, settings, list(report.parameters.left_to_prior))
        except (ValueError, ArithmeticError) as exc:  # KinematicsError and LinAlgError are ValueErrors
            suggested = {"poses": 0, "what": f"the suggestion failed: {exc}", "why": ""}
        record = replace(record, suggested_poses=suggested)
        report = with_suggested(report, suggested)
    if inp.rec is not None:
        try:
            read = as_read(inp, outcome)
        except ValueError:  # position-only targets: nothing for a pose analysis to read
            pass
    split["summary"] = time.perf_counter() - t_s
    t3 = time.perf_counter()
    drawn = log_step(inp, ident, outcome.heldout, report, settings, outputs.temp("rrd"))
    split["log"] = time.perf_counter() - t3
    report = replace(report, run=replace(record, observability=drawn["observability"], drawn=drawn["rerun"]))
    return ident.result, RunObjects(report, outcome.calibration, simulated, suggestion, read)


def sha256_text(text: str) -> str:
    """The SHA-256 of ``text`` as written (UTF-8)."""
    return hashlib.sha256(text.encode()).hexdigest()


def _predicted_or(robot: Robot, theta, joints, measured) -> np.ndarray:
    """The forward kinematics of ``theta`` at ``joints``, or the measured poses where it fails."""
    try:
        return robot.forward_kinematics(theta, joints, initial=measured)
    except KinematicsError:
        return measured


def sidecar_name(csv_path) -> str:
    from pipeline.formats import sidecar_path

    return str(sidecar_path(csv_path))
