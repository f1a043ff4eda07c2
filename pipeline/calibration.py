"""One calibration run for any registered robot: simulate (or read) measurements, identify,
compensate, validate on held-out poses, write the recording, the summary and the ``.rrd``.

``python -m pipeline.run`` parses its flags into :class:`RunSettings`, calls
:func:`run_calibration` and prints the :class:`RunResult`'s summary. The summary has the same
keys for every robot.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib import paper
from calib.engine import IdentificationResult, gauge_representative, identify, integrated_error
from calib.measurement import frame_to_dict, identify_as_measured, instrument_measurements, \
    measured_gauge_representative, measurement_residuals, measurement_settings
from calib.metrics import calibration_gain, pose_error_norms
from calib.noise import SensorNoise
from calib.outliers import find_outliers
from calib.robot import KinematicsError, Robot, check_joint_limits
from calib.robots import default_robot, reference_errors, reference_poses
from calib.workspace import reachable_poses

__all__ = ["RunSettings", "RunResult", "run_calibration", "DEFAULT_CONFIGURATIONS"]

#: Calibration poses of a robot whose reference experiment names none.
DEFAULT_CONFIGURATIONS = 20


@dataclass(frozen=True)
class RunSettings:
    """What a run does (see ``python -m pipeline.run --help`` for each field)."""

    robot: str = "hexapod"
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


@dataclass
class RunResult:
    """Everything a run produced."""

    summary: dict
    result: IdentificationResult
    paths: dict = field(default_factory=dict)


def default_name(settings: RunSettings) -> str:
    """``hexapod_paper`` for the hexapod's reference run, else ``<robot>_<poses>``, or the input's stem."""
    if settings.real is not None:
        return Path(settings.real).stem + "_calibrated"
    if settings.robot == "hexapod" and settings.poses == "reference":
        return "hexapod_paper"
    return f"{settings.robot}_{Path(settings.poses).stem}"


def _free_name(out: Path, settings: RunSettings) -> str:
    """The default name is numbered rather than overwritten; an explicit name is never changed."""
    if settings.name is not None:
        return settings.name
    base = default_name(settings)
    if settings.overwrite:
        return base
    cand, k = base, 1
    while any((out / f"{cand}{ext}").exists() for ext in (".rrd", ".csv", ".json")):
        k += 1
        cand = f"{base}_{k}"
    return cand


def _targets(robot: Robot, settings: RunSettings, seed) -> tuple[np.ndarray, str]:
    if settings.poses == "reference":
        poses = reference_poses(robot)
        if poses is not None:
            return poses, "the reference poses"
        return reachable_poses(robot, DEFAULT_CONFIGURATIONS, seed), f"{DEFAULT_CONFIGURATIONS} random poses"
    if settings.poses.endswith(".csv"):
        from pipeline.design import read_command_file

        poses, _ = read_command_file(settings.poses, robot)
        return poses, f"{len(poses)} poses from {settings.poses}"
    n = int(settings.poses)
    if settings.design == "optimal":
        from pipeline.design import optimal_poses

        return optimal_poses(robot, n, seed=settings.seed), f"{n} D-optimal poses"
    return reachable_poses(robot, n, seed), f"{n} random poses"


def _simulate(robot: Robot, settings: RunSettings, noise: SensorNoise, progress):
    from mjcf.machine import MachineOptions
    from pipeline.testbed import Testbed

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


def _heldout_block(robot: Robot, before: np.ndarray, after: np.ndarray) -> dict:
    pb, ob = pose_error_norms(robot, before)
    pa, oa = pose_error_norms(robot, after)
    block = {"heldout_position_error_mm": {"before": float(pb.mean()), "after": float(pa.mean()),
                                           "max_after": float(pa.max())}}
    block["heldout_orientation_error_rad"] = (
        {"before": float(ob.mean()), "after": float(oa.mean()), "max_after": float(oa.max())}
        if robot.angle_pose_mask.any() else None)
    return block


def _parameter_error(robot: Robot, identified: np.ndarray, true: np.ndarray, free) -> dict:
    idx = robot.table.indices(free)
    err = (identified - true)[idx]
    angle = robot.table.angle_mask()[idx]
    rms = lambda v: float(np.sqrt(np.mean(v ** 2))) if v.size else None  # noqa: E731
    return {"rms_mm": rms(err[~angle]), "rms_rad": rms(err[angle]),
            "max_abs_mm": float(np.abs(err[~angle]).max()) if (~angle).any() else None,
            "max_abs_rad": float(np.abs(err[angle]).max()) if angle.any() else None}


def _instrument_heldout(robot: Robot, fit, val_joints, val_meas):
    """Held-out errors of a recording in an instrument frame or of targets: measured minus the
    prediction, before (nominal geometry, the registered frame, the start offsets) and after."""
    k = fit.n_targets
    start_frame = fit.registration.frame if (fit.frame_estimated and fit.registration is not None) else np.zeros(6)
    start_targets = None if k == 0 else (fit.registration.targets if fit.registration is not None and fit.frame_estimated
                                         else fit.targets)
    nominal = robot.forward_kinematics(robot.table.nominal, val_joints)
    before = measurement_residuals(robot, val_meas, instrument_measurements(robot, nominal, start_frame, start_targets), k)
    after = measurement_residuals(robot, val_meas, fit.predict(val_joints), k)
    what = "target positions" if k else "poses"
    return before, after, len(val_joints), (f"recorded validation rows: measured {what} minus model prediction, "
                                            "instrument frame (includes sensor noise)")


def _instrument_block(fit, before, after) -> dict:
    """Summary keys of an instrument frame or target fit."""
    block = {"method": "forward", "solver": "lm", "weighted": True,
             "measurement_notes": list(fit.notes), "measurement_gauge": list(fit.gauge)}
    if fit.frame_estimated:
        block["measurement_frame"] = fit.frame_dict()
        block["measurement_frame_std"] = frame_to_dict(fit.frame_std)
    if fit.targets is not None:
        block["measurement_targets_mm"] = fit.targets.tolist()
        block["measurement_targets_estimated"] = fit.targets_estimated
        if before is not None:  # one position error per target and row
            b, a = (np.linalg.norm(e.reshape(len(e), -1, 3), axis=2) for e in (before, after))
            block["heldout_position_error_mm"] = {"before": float(b.mean()), "after": float(a.mean()),
                                                  "max_after": float(a.max())}
            block["heldout_orientation_error_rad"] = None
    return block


def run_calibration(settings: RunSettings, progress=lambda label, done, total: None) -> RunResult:
    """Run one calibration (see the module docstring).

    Args:
        settings: what to do.
        progress: ``progress(label, done, total)`` called while simulating.

    Raises:
        FileExistsError: an output exists and ``overwrite`` is off.
        ValueError: bad settings or a recording that cannot be analysed (the message names it).
    """
    from pipeline.recording import Recording, atomic_write, read_recording, write_recording

    t0 = time.perf_counter()
    split: dict[str, float] = {}
    sim = None
    instrument = None  # the fit of an instrument frame or targets, when the recording needs one
    if settings.real is not None:
        rec = read_recording(settings.real)
        robot, noise = rec.robot, rec.noise
        truth = rec.meta.get("simulation", {}).get("injected_errors")
        injected = robot.table.vector(truth, base=np.zeros(robot.n_parameters)) if isinstance(truth, dict) else None
        actual = None if injected is None else robot.table.nominal + injected
        joints, measured = rec.subset("calibration")
        val_joints, val_meas = rec.subset("validation")
        cal_rows = rec.rows("calibration")
        scenario = f"recording {settings.real}"
    else:
        robot = default_robot(settings.robot)
        noise = SensorNoise(settings.noise_mm, settings.noise_rad, settings.noise_dist, joint=settings.noise_joint)
        sim = _simulate(robot, settings, noise, progress)
        actual, injected, scenario = sim["actual"], sim["errors"], sim["scenario"]
        joints, measured = sim["cal"].encoders, sim["cal"].measured
        cal_rows = np.arange(len(measured))
    nominal = robot.table.nominal
    split["simulate"] = time.perf_counter() - t0

    # The measurements are written before any analysis, so that nothing is lost if it fails.
    out = Path(settings.out)
    name = _free_name(out, settings)
    paths: dict[str, str] = {}
    if sim is not None:
        parts = [sim["cal"]] + ([sim["val"]] if sim["val"] is not None else [])
        simulation = {"injected_errors": robot.table.to_dict(injected),
                      "gravity": settings.gravity, "payload_kg": settings.payload_kg,
                      "stiffness": settings.stiffness, "friction": settings.friction}
        recording = Recording(
            robot=robot, noise=noise, t_s=np.concatenate([p.t_s for p in parts]),
            joints=np.vstack([p.encoders for p in parts]), measured=np.vstack([p.measured for p in parts]),
            sets=np.array(["calibration"] * len(parts[0].t_s) + ["validation"] * sum(len(p.t_s) for p in parts[1:])),
            meta={"scenario": scenario, "seed": settings.seed, "simulation": simulation})
        csv_path, json_path = write_recording(out / f"{name}.csv", recording, overwrite=settings.overwrite)
        paths.update(csv=str(csv_path), json=str(json_path))

    t1 = time.perf_counter()
    solver = settings.solver or ("gn" if settings.method == "chainwise" else "lm")
    options = {"solver": solver}
    if settings.method == "chainwise":
        options.update(weighted=settings.weighted, epsilon=paper.PAPER_EPSILON)
    if sim is None:
        instrument = identify_as_measured(robot, joints, measured, noise, measurement_settings(rec.meta.get("measurement")))
    if instrument is not None:  # the forward method with the frame and targets; poses in the base frame below
        result, solver = instrument.result, "lm"
        measured_raw, measured = measured, instrument.base_poses(joints, measured)
    else:
        result = identify(robot, joints, measured, noise, method=settings.method, **options)
    try:
        report = find_outliers(robot, joints, measured, noise)
        flagged = [int(cal_rows[i]) + 1 for i in report.flagged]
    except ValueError:
        flagged = []
    split["identify"] = time.perf_counter() - t1

    heldout_before = heldout_after = None
    heldout_basis, n_heldout = None, 0
    if sim is not None and sim["val"] is not None:
        t2 = time.perf_counter()
        try:
            compensated = robot.inverse_kinematics(result.theta, sim["heldout"])
            check_joint_limits(robot, compensated, "held-out pose")
        except KinematicsError as exc:
            raise ValueError(
                f"the identified model cannot command the held-out poses ({exc}); its geometry is "
                "implausible: the measurements carry effects the geometric model lacks (gravity, "
                "payload, compliance; see python -m pipeline.discover)") from exc
        after = sim["bed"].measure(compensated, progress=lambda d, t: progress(
            "measuring held-out poses (compensated commands)", d, t))
        heldout_before = sim["val"].true_poses - sim["heldout"]
        heldout_after = after.true_poses - sim["heldout"]
        n_heldout = len(sim["heldout"])
        heldout_basis = ("simulated machine, compensated commands, noise-free settled poses "
                         "(before: nominal commands)")
        split["simulate"] += time.perf_counter() - t2
    elif instrument is not None and len(val_joints):
        heldout_before, heldout_after, n_heldout, heldout_basis = _instrument_heldout(
            robot, instrument, val_joints, val_meas)
    elif sim is None and len(val_joints):
        # A recording holds the validation poses measured under nominal commands only: the
        # identified model's prediction error there stands for the compensated error (equal to
        # first order), and includes the sensor noise.
        heldout_before = val_meas - robot.forward_kinematics(nominal, val_joints, initial=val_meas)
        heldout_after = val_meas - robot.forward_kinematics(result.theta, val_joints, initial=val_meas)
        n_heldout = len(val_joints)
        heldout_basis = "recorded validation rows: measured minus model prediction (includes sensor noise)"

    free = result.free_names
    truth_in_gauge = None if actual is None else gauge_representative(robot, actual, result.start) \
        if instrument is None else measured_gauge_representative(
            robot, actual, estimate_frame=instrument.frame_estimated,
            targets=instrument.targets if instrument.targets_estimated else None, start=result.start)
    history = list(result.history) if (settings.method == "chainwise" and solver == "gn" and instrument is None) \
        else [float(integrated_error(robot, result.pose_residuals if instrument is None else
                                     measured - robot.forward_kinematics(result.theta, joints))[2].max())]
    summary = {
        "robot": robot.name,
        "scenario": scenario,
        "method": settings.method,
        "solver": solver,
        "weighted": settings.weighted if settings.method == "chainwise" else True,
        "calibration_poses": int(len(measured)),
        "heldout_poses": n_heldout,
        "declared_noise": noise.to_dict(),
        "seed": settings.seed,
        "parameter_units": dict(zip(robot.table.names, robot.table.units)),
        "free_parameters": list(free),
        "fixed_parameters": [n for n in robot.table.names if n not in free],
        "injected_errors": None if injected is None else robot.table.to_dict(injected),
        "identified_errors": robot.table.to_dict(result.errors),
        "identified_std": robot.table.to_dict(result.std),
        "parameter_error": None if truth_in_gauge is None else
            _parameter_error(robot, result.theta, truth_in_gauge, free),
        "gain_G_percent": None if truth_in_gauge is None else {
            k: v for k, v in calibration_gain(robot, truth_in_gauge, result.start, result.theta,
                                              free).as_dict().items() if k != "per_parameter"},
        "iterations": result.iterations,
        "success": result.success,
        "message": result.message,
        "chi2": result.chi2,
        "dof": result.dof,
        "max_dqint_history": history,
        "condition_numbers": result.condition_numbers.tolist(),
        "flagged_poses": flagged,
        "heldout_basis": heldout_basis,
        "heldout_position_error_mm": None,
        "heldout_orientation_error_rad": None,
    }
    if heldout_before is not None and (instrument is None or instrument.targets is None):
        summary.update(_heldout_block(robot, heldout_before, heldout_after))
    if instrument is not None:
        summary.update(_instrument_block(instrument, heldout_before, heldout_after))
    if sim is not None:
        cal = sim["cal"]
        summary["settle_steps_per_pose"] = {"mean": float(cal.steps.mean()), "max": int(cal.steps.max())}
        summary["simulation"] = {"gravity": settings.gravity, "payload_kg": settings.payload_kg,
                                 "stiffness": settings.stiffness, "friction": settings.friction}
        # How far the settled machine departs from its own kinematics (load, compliance...).
        dep = cal.true_poses - robot.forward_kinematics(actual, cal.commanded, initial=cal.true_poses)
        pos, ang = pose_error_norms(robot, dep)
        summary["kinematic_departure"] = {"position_mm": {"mean": float(pos.mean()), "max": float(pos.max())},
                                          "orientation_rad": {"mean": float(ang.mean()), "max": float(ang.max())}}

    t3 = time.perf_counter()
    from calib.observability import analyze_observability
    from pipeline.rerun_log import (APP_IDS, blueprint, log_calibration_run, run_eye, run_magnification,
                                    save_recording, summary_markdown)

    analysis = analyze_observability(robot, result.start, measured, noise)
    summary["observability"] = {"condition_number": float(analysis.condition_number),
                                "crb_std": robot.table.to_dict(analysis.crb_std)}
    targets = sim["targets"] if sim is not None else robot.forward_kinematics(nominal, joints, initial=measured)
    try:
        predicted = robot.forward_kinematics(result.theta, joints, initial=measured)
    except KinematicsError:
        predicted = measured

    magnified = run_magnification(robot, nominal, actual, result.theta, targets, measured)
    history_label = "max dQint (mm)" if (settings.method == "chainwise" and solver == "gn") else "cost"
    flagged_index = [int(np.flatnonzero(cal_rows == f - 1)[0]) for f in flagged]

    def log(stream):
        log_calibration_run(stream, robot=robot, nominal=nominal, actual=actual, identified=result.theta,
                            std=result.std, joints=joints, targets=targets, measured=measured,
                            predicted=predicted, history=result.history,
                            heldout_before=None if heldout_before is not None and heldout_before.shape[1] != robot.pose_dim
                            else heldout_before, heldout_after=heldout_after, summary_markdown=summary_markdown(summary),
                            observability=analysis, flagged=flagged_index, history_label=history_label,
                            magnified=magnified)

    bp = blueprint(robot, eye=run_eye(robot, nominal, targets), magnified=magnified,
                   has_heldout=heldout_before is not None, history_label=history_label)
    paths["rrd"] = str(save_recording(out / f"{name}.rrd", log, application_id=APP_IDS["run"],
                                      overwrite=settings.overwrite, bp=bp))
    split["log"] = time.perf_counter() - t3
    summary.update(paths)
    summary["wall_time_s"] = time.perf_counter() - t0
    summary["wall_time_split_s"] = split
    if settings.summary_json is not None:
        atomic_write(settings.summary_json, json.dumps(summary, indent=1), overwrite=settings.overwrite)
        paths["summary_json"] = str(settings.summary_json)
    return RunResult(summary=summary, result=result, paths=paths)
