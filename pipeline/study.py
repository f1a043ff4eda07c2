"""Monte Carlo study of the whole calibration loop for any registered robot: errors against the CRB.

Usage::

    python -m pipeline.study --trials 200 [--robot hexapod|delta|...] [--noise-mm 0.001]
        [--noise-rad 1e-6] [--noise-joint 0] [--poses designed|reference|random|FILE.csv]
        [--n-poses 10] [--workspace full|default] [--criterion d|e]
        [--method forward|chainwise|both] [--errors reference|random] [--error-mm 0.05]
        [--error-rad 0.001] [--heldout 100] [--seed 0] [--workers 2] [--scheduler ADDRESS] [--geometry ROBOT.json]
        [--summary-json FILE] [--rrd FILE] [--overwrite]

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
Trials run in chunks on a Dask cluster (:mod:`pipeline.executor`: a local cluster of
``--workers`` processes, default the number of cores, one BLAS thread each; ``--workers 1`` runs
here; ``--scheduler ADDRESS`` runs on an existing cluster); the simulation of a chunk is
vectorised (one forward-kinematics solve for all its trials). Progress goes to stderr: the chunks
done, however they run (:class:`pipeline.execution.ProgressDisplay`).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from calib.design import CRITERIA, WORKSPACES, design_poses, minimum_poses, robot_workspace, sample_feasible_poses
from calib.engine import METHODS, identify, integrated_error
from calib.noise import SensorNoise
from calib.observability import analyze_observability, free_indices, parameter_scale, pose_uncertainty
from calib.robot import KinematicsError, Robot, check_joint_limits
from calib.robots import ROBOTS, reference_errors, reference_poses, robot_from_description
from pipeline.cli import add_noise_arguments, noise_from_arguments
from pipeline.workflows.design import load_robot
from pipeline.formats import read_command_file
from pipeline.execution import ProgressDisplay, run_tasks, worker_count
from pipeline.cli import add_executor_arguments
from pipeline.cli import ArgumentParser, cli_main, nonnegative_int
from pipeline.formats import check_outputs, atomic_write

__all__ = ["METHODS", "ERROR_KINDS", "DEFAULT_ERROR_MM", "DEFAULT_ERROR_RAD", "trial_noise", "true_errors",
           "compensation_errors", "run_trials", "monte_carlo", "summarize", "main"]

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
    :mod:`pipeline.executor`; trial ``k``'s noise depends on ``seed`` and ``k`` only, so the
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
    from pipeline.study import run_trials as entry

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


def _parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m pipeline.study", description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default="hexapod", help=f"registered robot: {', '.join(sorted(ROBOTS))}")
    p.add_argument("--trials", type=int, default=200)
    add_noise_arguments(p)
    p.add_argument("--poses", default="designed",
                   help="designed | reference (the robot's published poses) | random | a command file "
                        "(CSV; its commanded joints are used)")
    p.add_argument("--n-poses", type=int, default=10, help="for designed/random poses")
    p.add_argument("--workspace", choices=WORKSPACES, default="full",
                   help="workspace of designed/random poses and of the held-out poses")
    p.add_argument("--criterion", choices=CRITERIA, default="d")
    p.add_argument("--method", choices=METHODS + ("both",), default="forward")
    p.add_argument("--errors", choices=ERROR_KINDS, default=None,
                   help="true errors: the robot's reference errors (default where it has them, e.g. the "
                        "hexapod paper's Table 3), or random ones drawn from the seed")
    p.add_argument("--error-mm", type=float, default=DEFAULT_ERROR_MM, help="random errors: half-width, mm")
    p.add_argument("--error-rad", type=float, default=DEFAULT_ERROR_RAD, help="random errors: half-width, rad")
    p.add_argument("--heldout", type=int, default=100, help="held-out poses (0: none)")
    p.add_argument("--seed", type=nonnegative_int, default=0)
    add_executor_arguments(p)
    p.add_argument("--geometry", default=None, help="robot description JSON (Robot.description())")
    p.add_argument("--summary-json", default=None)
    p.add_argument("--rrd", default=None)
    p.add_argument("--overwrite", action="store_true")
    return p


def _poses(args, robot: Robot, ws, noise: SensorNoise):
    nominal = robot.table.nominal
    if args.poses == "reference":
        poses = reference_poses(robot)
        if poses is None:
            raise SystemExit(f"--poses reference: the {robot.name} has no reference poses")
        return np.asarray(poses, dtype=float), None
    if args.poses == "designed":
        design = design_poses(robot, nominal, args.n_poses, ws, noise, criterion=args.criterion, seed=args.seed)
        return design.poses, None
    if args.poses == "random":
        return sample_feasible_poses(robot, nominal, ws, args.n_poses, args.seed), None
    try:
        return read_command_file(args.poses, robot)
    except (OSError, ValueError) as exc:
        raise SystemExit(f"--poses: {exc}") from None


def main(argv: list[str] | None = None) -> int:
    """Run; a refused input, output or flag ends with one line on stderr and exit status 2."""
    return cli_main(_main, argv)


def _main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    for p in (args.summary_json, args.rrd):
        if p and Path(p).exists() and not args.overwrite:
            raise SystemExit(f"{p} exists; pass --overwrite to replace it")
    check_outputs({"--summary-json": args.summary_json, "--rrd": args.rrd}, overwrite=args.overwrite)
    if args.trials < 2:
        raise SystemExit(f"--trials must be >= 2, got {args.trials}")
    robot = load_robot(args.robot, args.geometry)
    fewest = minimum_poses(robot)
    if args.poses in ("designed", "random") and args.n_poses < fewest:
        raise SystemExit(f"--n-poses must be >= {fewest}, got {args.n_poses}")
    noise = noise_from_arguments(args)
    nominal = robot.table.nominal
    kind = args.errors or ("reference" if reference_poses(robot) is not None else "random")
    try:
        theta_true = nominal + true_errors(robot, kind, args.seed, error_mm=args.error_mm, error_rad=args.error_rad)
    except ValueError as exc:
        raise SystemExit(f"--errors: {exc}") from None
    ws = robot_workspace(robot, args.workspace)
    targets, commanded = _poses(args, robot, ws, noise)
    if commanded is None:
        commanded = robot.inverse_kinematics(nominal, targets)
    heldout = sample_feasible_poses(robot, nominal, ws, args.heldout, [args.seed, 1]) if args.heldout else None
    reached = robot.forward_kinematics(theta_true, commanded, initial=targets)
    analysis = analyze_observability(robot, theta_true, reached, noise, joints=commanded)
    names = analysis.names
    crb_var = analysis.crb_std ** 2
    predicted = None
    if heldout is not None:
        pu = pose_uncertainty(robot, theta_true, heldout, analysis.parameter_covariance())
        predicted = float(np.sqrt(np.mean(pu.position_rms_mm ** 2)))
    methods = METHODS if args.method == "both" else (args.method,)
    t0 = time.perf_counter()
    results = monte_carlo(robot, theta_true, commanded, noise, args.trials, args.seed, methods=methods,
                          heldout=heldout, workers=args.workers, initial=targets, scheduler=args.scheduler,
                          display=ProgressDisplay("study"))
    figures = summarize(results, names, parameter_scale(robot)[analysis.indices], crb_var, args.trials)
    summary = {
        "command": "pipeline.study",
        "robot": robot.name,
        "trials": args.trials, "seed": args.seed, "noise": noise.to_dict(),
        "poses": args.poses, "n_poses": int(targets.shape[0]), "workspace": ws.to_dict(),
        "criterion": args.criterion if args.poses == "designed" else None,
        "true_errors": kind, "heldout_poses": args.heldout,
        "simulated_machine": f"calib.robots {robot.name} forward kinematics (no MuJoCo)",
        "parameter_units": dict(zip(names, analysis.units)),
        "observability": analysis.summary(),
        "crb_std": {n: float(v) for n, v in zip(names, analysis.crb_std)},
        "crb_rms_mm": analysis.crb_rms,
        "predicted_heldout_position_rms_mm_at_crb": predicted,
        "methods": figures,
        "elapsed_s": time.perf_counter() - t0,
    }
    if args.summary_json:
        atomic_write(args.summary_json, json.dumps(summary, indent=2) + "\n", overwrite=args.overwrite)
    if args.rrd:
        _write_rrd(args.rrd, analysis, results, figures, summary, args.overwrite)
    for m in methods:
        f = figures[m]
        held = f["heldout_position_mm"]
        print(f"{m}: parameter error RMS {f['parameter_error_rms_mm']:.4g} mm (CRB {analysis.crb_rms:.4g} mm); "
              f"MSE/CRB per parameter {f['mse_over_crb_min']:.3f}..{f['mse_over_crb_max']:.3f} "
              f"(mean {f['mse_over_crb_mean']:.3f})"
              + (f"; held-out position error mean {held['mean'] * 1e3:.4g} um, RMS {held['rms'] * 1e3:.4g} um"
                 + (f" (predicted at the CRB {predicted * 1e3:.4g} um)" if predicted is not None else "")
                 if held else ""))
    return 0


def _markdown(summary: dict) -> str:
    noise = summary["noise"]
    lines = ["# Monte Carlo study", "",
             f"{summary['robot']}: {summary['trials']} trials, seed {summary['seed']}, {summary['n_poses']} "
             f"{summary['poses']} poses ({summary['workspace']['name']} workspace), Gaussian noise std "
             f"{noise['position_mm']:g} mm, {noise['orientation_rad']:g} rad, joints {noise['joint']:g}. "
             f"Machine: {summary['simulated_machine']}.", "",
             f"CRB parameter RMS: {summary['crb_rms_mm']:.4g} mm", "",
             "| method | param. error RMS (mm) | MSE/CRB min | mean | max (param) "
             "| held-out position mean / RMS (um) |",
             "|---|---|---|---|---|---|"]
    for m, f in summary["methods"].items():
        h = f["heldout_position_mm"]
        lines.append(f"| {m} | {f['parameter_error_rms_mm']:.4g} | {f['mse_over_crb_min']:.3f} | "
                     f"{f['mse_over_crb_mean']:.3f} | {f['mse_over_crb_max']:.3f} "
                     f"({f['mse_over_crb_max_parameter']}) | "
                     + (f"{h['mean'] * 1e3:.4g} / {h['rms'] * 1e3:.4g} |" if h else "- |"))
    if summary["predicted_heldout_position_rms_mm_at_crb"] is not None:
        lines += ["", f"Held-out position error RMS predicted at the CRB: "
                      f"{summary['predicted_heldout_position_rms_mm_at_crb'] * 1e3:.4g} um"]
    return "\n".join(lines) + "\n"


def _write_rrd(path, analysis, results, figures, summary, overwrite) -> None:
    import rerun as rr
    import rerun.blueprint as rrb

    from pipeline.views import log_bars, log_observability, observability_views
    from pipeline.views import application_id, chart_view, save_recording

    names = list(analysis.names)
    views = [observability_views("study/observability", "Calibration poses", per_parameter=True)]
    for m in results:
        views.append(rrb.Vertical(
            chart_view(f"study/{m}/mse_over_crb", f"{m}: MSE / CRB per parameter"),
            chart_view(f"study/{m}/empirical_std_mm", f"{m}: empirical std per parameter (mm)"),
            rrb.TimeSeriesView(origin=f"study/{m}/heldout_position_um", name=f"{m}: held-out position error (um) per trial"),
            row_shares=[2, 2, 1],
        ))
    bp = rrb.Blueprint(rrb.Horizontal(rrb.TextDocumentView(origin="study/summary", name="Summary"), *views),
                       rrb.TimePanel(timeline="trial", play_state="paused", state="collapsed"), collapse_panels=True)

    def log(rec):
        log_observability(rec, analysis, "study/observability", title=f"Calibration poses ({summary['robot']})")
        rec.log("study/summary", rr.TextDocument(_markdown(summary), media_type=rr.MediaType.MARKDOWN), static=True)
        for m, r in results.items():
            f = figures[m]
            log_bars(rec, f"study/{m}/mse_over_crb", np.array([f["mse_over_crb"][n] for n in names]), names,
                     unit="1 (MSE / CRB)", title=f"{m}: MSE / CRB")
            # An angle's std as the length it moves at the machine's size, like crb_std_mm.
            log_bars(rec, f"study/{m}/empirical_std_mm",
                     np.array([f["empirical_std"][n] for n in names]) * analysis.scale, names, unit="mm",
                     title=f"{m}: empirical std")
            hp = r["heldout_position_mm"]
            if not np.all(np.isnan(hp)):
                rec.send_columns(f"study/{m}/heldout_position_um",
                                 indexes=[rr.TimeColumn("trial", sequence=np.arange(hp.size))],
                                 columns=rr.Scalars.columns(scalars=hp * 1e3))

    try:
        save_recording(path, log, application_id=application_id("study", summary["robot"]), overwrite=overwrite, bp=bp)
    except FileExistsError as exc:
        raise SystemExit(str(exc)) from None


if __name__ == "__main__":
    sys.exit(main())
