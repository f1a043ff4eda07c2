"""Monte Carlo study of the whole calibration loop for any registered robot: errors against the CRB
(:func:`run_study`; the command ``python -m pipeline.study``).

Each trial: the simulated machine (the robot's nominal parameters plus the true errors: the
robot's reference errors, e.g. the hexapod paper's Table 3, or errors drawn uniformly within
``+-error_mm`` / ``+-error_rad`` on the free parameters) is commanded the nominal inverse
kinematics of the calibration poses; it reaches the poses given by the robot's forward
kinematics (MuJoCo is not needed: the testbed's MuJoCo model settles to exactly these kinematic
poses, and the study needs thousands of runs); the sensor adds Gaussian noise (declared
standard deviations ``--noise-mm``, ``--noise-rad``; ``--noise-joint`` on the joint readings);
the parameters are identified by :func:`calib.engine.identify_forward` (weighted
Levenberg-Marquardt, the maximum-likelihood estimator) and/or
:func:`calib.engine.identify_chainwise` (chain by chain, unweighted Gauss-Newton: the hexapod
paper's per-leg least squares); the identified model then commands held-out poses drawn in the
workspace and the reached poses are compared with the targets.

Reported: per-parameter mean squared error and its ratio to the Cramer-Rao bound (the CRB is
computed at the true parameters and the reached poses), parameter error RMS (an angle counted as
the length it moves at the machine's size), bias, held-out position and orientation errors
(measured, and predicted from the CRB), written to ``--summary-json`` and ``--rrd``.

Trial ``k`` draws its pose noise from ``SeedSequence(seed, spawn_key=(k,))`` (joint noise from
``spawn_key=(k, 1)``), so the figures for a given seed are the same whatever ``--workers`` is.
Trials run in chunks on a Dask cluster (:mod:`pipeline.execution`: a local cluster of
``--workers`` processes, default the number of cores, one BLAS thread each; ``--workers 1`` runs
here; ``--scheduler ADDRESS`` runs on an existing cluster); the simulation of a chunk is
vectorised (one forward-kinematics solve for all its trials). Progress goes to stderr: the chunks
done, however they run (:class:`pipeline.execution.ProgressDisplay`).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

import numpy as np

from calib.design import design_poses, minimum_poses, robot_workspace, sample_feasible_poses
from calib.engine import METHODS, identify, integrated_error
from calib.noise import SensorNoise
from calib.observability import analyze_observability, free_indices, parameter_scale, pose_uncertainty
from calib.robot import KinematicsError, Robot, check_joint_limits
from calib.robots import ROBOTS, reference_errors, reference_poses, robot_from_description
from pipeline.execution import run_tasks, worker_count
from pipeline.formats import atomic_write, check_outputs, read_command_file

from .design import DEFAULT_NOISE, load_robot
from .options import ToolOptions, check_noise_flags

__all__ = ["METHODS", "ERROR_KINDS", "DEFAULT_ERROR_MM", "DEFAULT_ERROR_RAD", "trial_noise", "true_errors",
           "compensation_errors", "run_trials", "monte_carlo", "summarize", "StudySettings", "StudyOutcome",
           "run_study", "study_poses", "check_study_settings"]

#: Where the simulated machine's errors come from.
ERROR_KINDS = ("reference", "random")
#: Half-width of random errors on length parameters, mm.
DEFAULT_ERROR_MM = 0.05
#: Half-width of random errors on angle parameters, rad.
DEFAULT_ERROR_RAD = 0.001


def trial_noise(robot: Robot, noise: SensorNoise, n_poses: int, seed: int, trials) -> tuple[np.ndarray, np.ndarray]:
    """Noise of the given trials, independent of how trials are split over workers.

    Returns:
        ``(pose_noise, joint_noise)``: (T, n_poses, D) in the robot's pose units, and
        (T, n_poses, C) in its joint unit (zero when ``noise.joint`` is 0).
    """
    trials = [int(k) for k in trials]
    d, c = robot.pose_dim, robot.n_chains
    pose = np.zeros((len(trials), n_poses, d))
    joint = np.zeros((len(trials), n_poses, c))
    for t, k in enumerate(trials):
        pose[t] = noise.sample(n_poses, np.random.SeedSequence(seed, spawn_key=(k,)), robot.pose_units)
        if noise.joint > 0:
            joint[t] = noise.sample_joints(n_poses, c, np.random.SeedSequence(seed, spawn_key=(k, 1)))
    return pose, joint


def true_errors(robot: Robot, kind: str, seed: int, *, error_mm: float = DEFAULT_ERROR_MM,
                error_rad: float = DEFAULT_ERROR_RAD) -> np.ndarray:
    """(P,) errors of the simulated machine, ``theta_true - nominal``.

    ``"reference"``: the errors of the robot's reference experiment (:func:`calib.robots.reference_errors`, seeded by ``seed``); ``"random"``: uniform
    within ``+-error_mm`` (lengths) and ``+-error_rad`` (angles) on the free parameters, zero on
    the fixed ones, drawn from ``default_rng([seed, 7])``.

    Raises:
        ValueError: an unknown kind, or a robot without reference errors.
    """
    if kind == "reference":
        return reference_errors(robot, seed)
    if kind != "random":
        raise ValueError(f"kind must be one of {ERROR_KINDS}, got {kind!r}")
    half = np.where(robot.table.angle_mask(), error_rad, error_mm)
    _, idx = free_indices(robot)
    errors = np.zeros(robot.n_parameters)
    errors[idx] = np.random.default_rng([seed, 7]).uniform(-1.0, 1.0, idx.size) * half[idx]
    return errors


def compensation_errors(robot: Robot, theta_true, theta_identified, targets) -> tuple[np.ndarray, np.ndarray]:
    """Pose errors of the true machine commanded by the identified model.

    The controller commands ``q = IK(theta_identified, target)`` (within the joint limits); the
    machine reaches ``FK(theta_true, q)``.

    Returns:
        ``(position_mm, orientation_rad)``, each (H,): the norm of the position and of the angle
        part of ``reached - target`` (zero angles for a translating platform).

    Raises:
        KinematicsError: a target the identified model cannot command or the machine cannot reach.
    """
    q = robot.inverse_kinematics(theta_identified, targets)
    check_joint_limits(robot, q, "held-out pose")
    reached = robot.forward_kinematics(theta_true, q, initial=targets)
    position, orientation, _ = integrated_error(robot, reached - targets)
    return position, orientation


def run_trials(job: dict) -> dict:
    """Run a chunk of trials (executed in a worker process; plain data in and out).

    Args:
        job: ``robot`` (registered name), ``description`` (its ``Robot.description()``),
            ``theta_true`` (P,), ``commanded`` (N, C) joints, ``reached`` (N, D) the poses the
            machine reaches there, ``noise`` (dict), ``seed``, ``trials`` (list of trial
            numbers), ``methods``, ``heldout`` (H, D) target poses or None.

    Returns:
        ``trials`` and per method ``{method: {"errors": (T, F) estimate - truth of the free
        parameters (their units), "success": (T,) bool, "heldout_position_mm": (T,),
        "heldout_position_rms_mm": (T,), "heldout_orientation_rad": (T,)}}`` (held-out figures:
        mean, and RMS, over the held-out poses of the per-pose error norms; NaN where the
        identified model cannot reach them).
    """
    robot = robot_from_description(job["robot"], job["description"])
    theta_true = np.asarray(job["theta_true"], dtype=float)
    commanded = np.asarray(job["commanded"], dtype=float)
    reached = np.asarray(job["reached"], dtype=float)
    noise = SensorNoise(**job["noise"])
    trials = np.asarray(job["trials"], dtype=int)
    heldout = job.get("heldout")
    _, idx = free_indices(robot)
    # Vectorised simulation: the machine reaches the same poses in every trial; only the noise
    # differs.
    pose_noise, joint_noise = trial_noise(robot, noise, commanded.shape[0], job["seed"], trials)
    measured = reached[None] + pose_noise
    read = commanded[None] + joint_noise
    out = {"trials": trials.tolist()}
    for method in job["methods"]:
        errs = np.empty((trials.size, idx.size))
        ok = np.empty(trials.size, bool)
        hp, hr, ho = (np.full(trials.size, np.nan) for _ in range(3))
        for t in range(trials.size):
            res = identify(robot, read[t], measured[t], noise, method=method)
            errs[t] = res.theta[idx] - theta_true[idx]
            ok[t] = res.success
            if heldout is not None:
                try:
                    pos, ori = compensation_errors(robot, theta_true, res.theta, heldout)
                except KinematicsError:  # a wild estimate can leave the joint range: counted as NaN
                    continue
                hp[t], hr[t], ho[t] = pos.mean(), np.sqrt(np.mean(pos ** 2)), ori.mean()
        out[method] = {"errors": errs, "success": ok, "heldout_position_mm": hp,
                       "heldout_position_rms_mm": hr, "heldout_orientation_rad": ho}
    return out


def _merge(parts: list[dict], methods) -> dict:
    order = np.argsort(np.concatenate([p["trials"] for p in parts]))
    return {m: {k: np.concatenate([np.asarray(p[m][k]) for p in parts])[order] for k in parts[0][m]}
            for m in methods}


def monte_carlo(robot: Robot, theta_true, commanded, noise: SensorNoise, trials: int, seed: int, *,
                methods=("forward",), heldout=None, workers: int | None = None, progress=None,
                initial=None, scheduler: str | None = None, client=None, display=None) -> dict:
    """Run ``trials`` Monte Carlo trials, in parallel, deterministically for a given seed.

    Args:
        robot: a registered robot (rebuilt in the workers from its description).
        theta_true: (P,) the simulated machine's parameters.
        commanded: (N, C) commanded joints (N >= :func:`calib.design.minimum_poses`).
        noise: sensor noise (simulated and declared; ``distribution="normal"`` for ML).
        trials: number of trials.
        seed: master seed.
        methods: subset of :data:`METHODS`.
        heldout: (H, D) held-out target poses, or None.
        workers: processes of the local Dask cluster (default the cores, one BLAS
            thread each); 1 runs in this process (set ``OPENBLAS_NUM_THREADS=1`` for speed).
        progress: callable ``(done, total)`` or None.
        initial: (N, D) start of the forward kinematics (e.g. the target poses); default home.
        scheduler: address of an existing Dask cluster to run on instead (``--scheduler``).
        client: an open ``distributed.Client`` to run on (left open).
        display: a :class:`pipeline.execution.ProgressDisplay` showing the chunks done, however they run.

    The trials run in chunks (:func:`run_trials`, eight a worker) on the executor of
    :mod:`pipeline.execution`; trial ``k``'s noise depends on ``seed`` and ``k`` only, so the
    figures are the same whatever runs them.

    Returns:
        ``{method: {"errors": (T, F), "success": (T,), "heldout_position_mm": (T,),
        "heldout_position_rms_mm": (T,), "heldout_orientation_rad": (T,)}}``, F the free
        parameters (``robot.free_default``) in table order.
    """
    if not isinstance(robot, Robot) or robot.name not in ROBOTS:
        raise TypeError(f"robot must be a registered calib.robot.Robot, got {robot!r}")
    if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials < 1:
        raise ValueError(f"trials must be a positive integer, got {trials!r}")
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise ValueError(f"methods must be a non-empty subset of {METHODS}, got {methods!r}")
    workers = worker_count(workers)
    if client is not None:
        workers = max(1, sum(client.nthreads().values()))
    theta_true = np.asarray(theta_true, dtype=float)
    commanded = np.asarray(commanded, dtype=float)
    reached = robot.forward_kinematics(theta_true, commanded, initial=initial)
    n_chunks = min(trials, max(1, 8 * workers))
    chunks = [c.tolist() for c in np.array_split(np.arange(trials), n_chunks)]
    base = {"robot": robot.name, "description": robot.description(), "theta_true": theta_true,
            "commanded": commanded, "reached": reached, "noise": noise.to_dict(), "seed": int(seed),
            "methods": tuple(methods), "heldout": None if heldout is None else np.asarray(heldout, float)}
    # By name, so the workers import it (not pickled by value when this module runs as __main__).
    from pipeline.workflows.study import run_trials as entry

    parts, done = [], 0

    for _, part in run_tasks(entry, [{**base, "trials": c} for c in chunks], workers=workers,
                             scheduler=scheduler, client=client, display=display):
        parts.append(part)
        done += len(part["trials"])
        if progress:
            progress(done, trials)
    return _merge(parts, methods)


def summarize(results: dict, names, scale: np.ndarray, crb_var: np.ndarray, trials: int) -> dict:
    """Per-method figures: MSE/CRB per parameter, RMS errors (mm), bias and held-out errors.

    Args:
        results: from :func:`monte_carlo`.
        names: (F,) free parameter names.
        scale: (F,) mm per parameter unit (:func:`calib.observability.parameter_scale`).
        crb_var: (F,) Cramer-Rao variances, parameter units squared.
        trials: number of trials.
    """
    from scipy.stats import chi2

    names = list(names)
    # Under efficiency and unbiasedness, T * MSE / CRB ~ chi-square with T degrees of freedom.
    q_hi = float(chi2.ppf(0.995, trials) / trials)
    out = {}
    for m, r in results.items():
        e = r["errors"]
        mse = np.mean(e ** 2, axis=0)
        ratio = mse / crb_var
        bias = e.mean(axis=0)
        se = e.std(axis=0, ddof=1) / np.sqrt(trials) if trials > 1 else np.full(len(names), np.nan)
        hp = r["heldout_position_mm"]
        out[m] = {
            "trials": trials,
            "success_rate": float(np.mean(r["success"])),
            "parameter_error_rms_mm": float(np.sqrt(np.mean(mse * scale ** 2))),
            "mse_over_crb": {n: float(v) for n, v in zip(names, ratio)},
            "mse_over_crb_max": float(ratio.max()),
            "mse_over_crb_max_parameter": names[int(np.argmax(ratio))],
            "mse_over_crb_min": float(ratio.min()),
            "mse_over_crb_mean": float(ratio.mean()),
            "mse_over_crb_99_5pct_sampling_limit": q_hi,
            "empirical_std": {n: float(v) for n, v in zip(names, e.std(axis=0))},
            "bias": {n: float(v) for n, v in zip(names, bias)},
            "max_abs_bias_over_standard_error": float(np.nanmax(np.abs(bias) / se)),
            "heldout_position_mm": None if np.all(np.isnan(hp)) else {
                "mean": float(np.nanmean(hp)), "median": float(np.nanmedian(hp)),
                "rms": float(np.sqrt(np.nanmean(r["heldout_position_rms_mm"] ** 2))),
                "p95": float(np.nanpercentile(hp, 95)), "failed_trials": int(np.isnan(hp).sum())},
            "heldout_orientation_rad": None if np.all(np.isnan(hp)) else {
                "mean": float(np.nanmean(r["heldout_orientation_rad"]))},
        }
    return out


@dataclass(frozen=True, kw_only=True)
class StudySettings(ToolOptions):
    """What :func:`run_study` does (``python -m pipeline.study --help`` describes each field).

    ``poses``: ``designed``, ``reference`` (the robot's published poses), ``random`` or a command
    file (CSV; its commanded joints are used); ``errors``: ``reference`` or ``random`` (None: the
    robot's reference errors where it has them, random ones otherwise); ``method``: one of
    :data:`calib.engine.METHODS` or ``both``.
    """

    robot: str = "hexapod"
    trials: int = 200
    noise: SensorNoise = DEFAULT_NOISE
    poses: str = "designed"
    n_poses: int = 10
    workspace: str = "full"
    criterion: str = "d"
    method: str = "forward"
    errors: str | None = None
    error_mm: float = DEFAULT_ERROR_MM
    error_rad: float = DEFAULT_ERROR_RAD
    heldout: int = 100
    seed: int = 0


@dataclass
class StudyOutcome:
    """What :func:`run_study` found: the ``summary`` (as ``--summary-json``), the per-method
    ``figures`` (its ``methods`` entry) and the CRB parameter RMS and held-out prediction (mm)."""

    summary: dict
    figures: dict
    crb_rms_mm: float
    predicted_heldout_mm: float | None


def study_poses(settings: StudySettings, robot: Robot, ws) -> tuple[np.ndarray, np.ndarray | None]:
    """``(targets (N, D), commanded joints (N, C) or None)`` of the study's calibration poses."""
    nominal = robot.table.nominal
    if settings.poses == "reference":
        poses = reference_poses(robot)
        if poses is None:
            raise ValueError(f"--poses reference: the {robot.name} has no reference poses")
        return np.asarray(poses, dtype=float), None
    if settings.poses == "designed":
        design = design_poses(robot, nominal, settings.n_poses, ws, settings.noise, criterion=settings.criterion,
                              seed=settings.seed)
        return design.poses, None
    if settings.poses == "random":
        return sample_feasible_poses(robot, nominal, ws, settings.n_poses, settings.seed), None
    try:
        return read_command_file(settings.poses, robot)
    except (OSError, ValueError) as exc:
        raise ValueError(f"--poses: {exc}") from None


#: Bisection steps of the largest random errors that fit (:func:`true_machine_poses`): the
#: scale to 2**-12 of the asked one.
FITTING_SCALE_STEPS = 12


def true_machine_poses(robot: Robot, errors, kind: str, settings: StudySettings, commanded, targets,
                       heldout) -> np.ndarray:
    """(N, D) the poses the true machine (nominal + ``errors``) reaches at the ``commanded`` joints.

    Random errors this large may make no machine (a Delta's arm of negative length) or one that
    cannot reach the study's poses (calibration or held-out, commanded by the nominal model, and
    the held-out targets themselves, where the prediction takes the true machine):
    refused naming ``--error-mm`` and ``--error-rad``, with the largest errors of the same draw
    that fit (the draw scaled down, by bisection to 2**-:data:`FITTING_SCALE_STEPS`).

    Raises:
        ValueError: naming the flags and the errors that would fit.
    """
    nominal = robot.table.nominal
    check = [commanded] if heldout is None else [commanded, robot.inverse_kinematics(nominal, heldout)]

    def reached(scale: float) -> np.ndarray:
        theta = nominal + scale * errors
        for q in check[1:]:
            robot.forward_kinematics(theta, q)
        if heldout is not None:  # the held-out prediction takes the true machine there
            robot.inverse_kinematics(theta, heldout)
        return robot.forward_kinematics(theta, check[0], initial=targets)

    try:
        return reached(1.0)
    except ValueError as exc:
        if kind != "random":
            raise ValueError(f"--errors {kind}: the {robot.name} with its reference errors cannot reach the study's "
                             f"poses: {exc}") from None
        reason = exc
    fits, fails = 0.0, 1.0
    for _ in range(FITTING_SCALE_STEPS):
        mid = (fits + fails) / 2
        try:
            reached(mid)
            fits = mid
        except ValueError:
            fails = mid
    raise ValueError(f"--error-mm {settings.error_mm:g}, --error-rad {settings.error_rad:g}: the {robot.name} with "
                     f"random errors this large (--seed {settings.seed}) cannot reach the study's poses ({reason}); "
                     f"errors up to --error-mm {fits * settings.error_mm:.3g} --error-rad "
                     f"{fits * settings.error_rad:.3g} would fit (this draw scaled by {fits:.3g})")


def check_study_settings(settings: StudySettings, robot: Robot) -> None:
    """Refuse, naming the flag, a study that cannot run or write its outputs, before any work."""
    check_outputs({"--summary-json": settings.summary_json, "--rrd": settings.rrd}, overwrite=settings.overwrite)
    if settings.trials < 2:
        raise ValueError(f"--trials must be >= 2, got {settings.trials}")
    check_noise_flags(robot, settings.noise)
    fewest = minimum_poses(robot)
    if settings.poses in ("designed", "random") and settings.n_poses < fewest:
        raise ValueError(f"--n-poses must be >= {fewest}, got {settings.n_poses}")


def run_study(settings: StudySettings, display=None) -> StudyOutcome:
    """Run the Monte Carlo study (see the module docstring) and write its summary JSON and
    ``.rrd`` where asked; ``display`` shows the trials' progress (a
    :class:`pipeline.execution.ProgressDisplay`, or None).

    Raises:
        ValueError: a refused setting (the message names the flag); FileExistsError: an output
            exists and ``overwrite`` is off.
    """
    robot, note = load_robot(settings.robot, settings.geometry)
    check_study_settings(settings, robot)
    nominal, noise = robot.table.nominal, settings.noise
    kind = settings.errors or ("reference" if reference_poses(robot) is not None else "random")
    try:
        theta_true = nominal + true_errors(robot, kind, settings.seed, error_mm=settings.error_mm,
                                           error_rad=settings.error_rad)
    except ValueError as exc:
        raise ValueError(f"--errors: {exc}") from None
    ws = robot_workspace(robot, settings.workspace)
    targets, commanded = study_poses(settings, robot, ws)
    if commanded is None:
        commanded = robot.inverse_kinematics(nominal, targets)
    heldout = sample_feasible_poses(robot, nominal, ws, settings.heldout, [settings.seed, 1]) if settings.heldout \
        else None
    reached = true_machine_poses(robot, theta_true - nominal, kind, settings, commanded, targets, heldout)
    analysis = analyze_observability(robot, theta_true, reached, noise, joints=commanded)
    predicted = None
    if heldout is not None:
        pu = pose_uncertainty(robot, theta_true, heldout, analysis.parameter_covariance())
        predicted = float(np.sqrt(np.mean(pu.position_rms_mm ** 2)))
    methods = METHODS if settings.method == "both" else (settings.method,)
    t0 = time.perf_counter()
    results = monte_carlo(robot, theta_true, commanded, noise, settings.trials, settings.seed, methods=methods,
                          heldout=heldout, workers=settings.workers, initial=targets, scheduler=settings.scheduler,
                          display=display)
    figures = summarize(results, analysis.names, parameter_scale(robot)[analysis.indices], analysis.crb_std ** 2,
                        settings.trials)
    summary = {
        "command": "pipeline.study",
        "robot": robot.name,
        "trials": settings.trials, "seed": settings.seed, "noise": noise.to_dict(),
        "poses": settings.poses, "n_poses": int(targets.shape[0]), "workspace": ws.to_dict(),
        "criterion": settings.criterion if settings.poses == "designed" else None,
        "true_errors": kind, "heldout_poses": settings.heldout,
        "simulated_machine": f"calib.robots {robot.name} forward kinematics (no MuJoCo)",
        "parameter_units": dict(zip(analysis.names, analysis.units)),
        "observability": analysis.summary(),
        "crb_std": {n: float(v) for n, v in zip(analysis.names, analysis.crb_std)},
        "crb_rms_mm": analysis.crb_rms,
        "predicted_heldout_position_rms_mm_at_crb": predicted,
        "methods": figures,
        "elapsed_s": time.perf_counter() - t0,
    }
    if note:
        summary["geometry_note"] = note
    if settings.summary_json:
        atomic_write(settings.summary_json, json.dumps(summary, indent=2) + "\n", overwrite=settings.overwrite)
    if settings.rrd:
        from pipeline.views import write_study_rrd

        write_study_rrd(settings.rrd, analysis, results, figures, summary, settings.overwrite)
    return StudyOutcome(summary=summary, figures=figures, crb_rms_mm=analysis.crb_rms, predicted_heldout_mm=predicted)
