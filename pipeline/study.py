"""Monte Carlo study of the whole calibration loop: error distributions against the CRB.

Usage::

    python -m pipeline.study --trials 200 --noise-mm 0.001 [--noise-rad 1e-6]
        [--poses designed|paper|random|FILE.csv] [--n-poses 10] [--workspace full|paper]
        [--criterion d|e] [--method forward|paper|both] [--errors table3|random]
        [--heldout 100] [--seed 0] [--workers 2] [--summary-json FILE] [--rrd FILE] [--overwrite]

Each trial: the simulated machine (the true parameter set, Table 2 + Table 3 by default) is
commanded the nominal inverse kinematics of the calibration poses; it reaches the poses given
by the forward kinematics of :mod:`calib.kinematics` (MuJoCo is not needed: the testbed's
MuJoCo model settles to exactly these kinematic poses, and the study needs thousands of runs);
the sensor adds Gaussian noise (declared standard deviations ``--noise-mm``, ``--noise-rad``);
the errors are identified (``forward``: weighted Levenberg-Marquardt, the maximum-likelihood
estimator; ``paper``: the paper's per-leg least squares); the identified model then commands
held-out poses drawn in the workspace and the reached poses are compared with the targets.

Reported: per-parameter mean squared error and its ratio to the Cramer-Rao bound (the CRB is
computed at the true parameters and the reached poses), parameter error RMS, bias, held-out
position and orientation errors (measured, and predicted from the CRB), written to
``--summary-json`` and ``--rrd``.

Trial ``k`` draws its noise from ``SeedSequence(seed, spawn_key=(k,))``, so the figures for a
given seed are the same whatever ``--workers`` is. Trials run in chunks over a process pool
(``--workers``, default the number of cores); the simulation of a chunk is vectorised
(one forward-kinematics solve for all its trials), progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import as_completed
from pathlib import Path

import numpy as np

from calib import paper
from calib.design import (
    CRITERIA,
    Workspace,
    design_poses,
    sample_feasible_poses,
    workspace_by_name,
)
from calib.hexapod import Hexapod, HexapodGeometry, paper_hexapod, parameter_table
from calib.identification import identify_forward, identify_paper
from calib.kinematics import forward_kinematics, inverse_kinematics
from calib.metrics import evaluate_compensation
from calib.noise import SensorNoise
from calib.observability import analyze_observability, pose_uncertainty
from pipeline.design import read_command_file
from pipeline.parallel import spawn_pool
from pipeline.recording import atomic_write

__all__ = ["METHODS", "trial_noise", "run_trials", "monte_carlo", "main"]

METHODS = ("forward", "paper")
NAMES = [n for n, _, _ in parameter_table()]


def trial_noise(noise: SensorNoise, n_poses: int, seed: int, trials: np.ndarray) -> np.ndarray:
    """Noise of the given trials, independent of how trials are split over workers.

    Returns:
        (T, n_poses, 6) mm and rad.
    """
    return np.stack([noise.sample(n_poses, np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(int(k),))))
                     for k in trials]) if len(trials) else np.zeros((0, n_poses, 6))


def run_trials(job: dict) -> dict:
    """Run a chunk of trials (executed in a worker process; plain data in and out).

    Args:
        job: ``geometry`` (dict), ``true_errors`` (6, 7) mm, ``commanded`` (N, 6) mm,
            ``noise`` (dict), ``seed``, ``trials`` (list of trial numbers), ``methods``,
            ``heldout`` (H, 6) target poses or None.

    Returns:
        ``trials`` and per method ``{method: {"errors": (T, 42) mm estimate - truth,
        "success": (T,) bool, "heldout_position_mm": (T,), "heldout_position_rms_mm": (T,),
        "heldout_orientation_rad": (T,)}}`` (held-out figures: mean, and RMS, over the held-out
        poses of the per-pose error norms; NaN where the identified model cannot reach them).
    """
    geometry = HexapodGeometry.from_dict(job["geometry"])
    nominal = Hexapod(geometry)
    true = Hexapod(geometry, np.asarray(job["true_errors"]))
    commanded = np.asarray(job["commanded"], dtype=float)
    noise = SensorNoise(**job["noise"])
    trials = np.asarray(job["trials"], dtype=int)
    heldout = job.get("heldout")
    # Vectorised simulation: the machine reaches the same poses in every trial; only the
    # sensor noise differs.
    reached = forward_kinematics(true, commanded, stroke_mm=None)
    measured = reached[None] + trial_noise(noise, commanded.shape[0], job["seed"], trials)
    out = {"trials": trials.tolist()}
    for method in job["methods"]:
        errs = np.empty((trials.size, 42))
        ok = np.empty(trials.size, bool)
        hp = np.full(trials.size, np.nan)
        hr = np.full(trials.size, np.nan)
        ho = np.full(trials.size, np.nan)
        for t in range(trials.size):
            if method == "forward":
                res = identify_forward(nominal, commanded, measured[t], noise)
            else:
                res = identify_paper(nominal, commanded, measured[t])
            errs[t] = res.estimate - true.vector
            ok[t] = res.success
            if heldout is not None:
                try:
                    ev = evaluate_compensation(true, res.hexapod, heldout)
                    hp[t] = ev.position_after.mean()
                    hr[t] = np.sqrt(np.mean(ev.position_after ** 2))
                    ho[t] = ev.orientation_after.mean()
                except ValueError:  # a wild estimate can leave the stroke: counted as NaN
                    pass
        out[method] = {"errors": errs, "success": ok, "heldout_position_mm": hp,
                       "heldout_position_rms_mm": hr, "heldout_orientation_rad": ho}
    return out


def _merge(parts: list[dict], methods) -> dict:
    order = np.argsort(np.concatenate([p["trials"] for p in parts]))
    merged = {}
    for m in methods:
        merged[m] = {k: np.concatenate([np.asarray(p[m][k]) for p in parts])[order]
                     for k in parts[0][m]}
    return merged


def monte_carlo(
    true: Hexapod,
    commanded: np.ndarray,
    noise: SensorNoise,
    trials: int,
    seed: int,
    *,
    methods=("forward",),
    heldout: np.ndarray | None = None,
    workers: int | None = None,
    progress=None,
) -> dict:
    """Run ``trials`` Monte Carlo trials, in parallel, deterministically for a given seed.

    Args:
        true: the simulated machine's parameter set.
        commanded: (N, 6) commanded leg lengths, mm (N >= 7).
        noise: sensor noise (simulated and declared; use ``distribution="normal"`` for ML).
        trials: number of trials.
        seed: master seed.
        methods: subset of :data:`METHODS`.
        heldout: (H, 6) held-out target poses, mm and rad, or None.
        workers: processes (default ``os.cpu_count()``); 1 runs in this process (set
            ``OPENBLAS_NUM_THREADS=1`` for speed), more run in spawned processes with one BLAS
            thread each.
        progress: callable ``(done, total)`` or None.

    Returns:
        ``{method: {"errors": (T, 42), "success": (T,), "heldout_position_mm": (T,),
        "heldout_position_rms_mm": (T,), "heldout_orientation_rad": (T,)}}``.
    """
    if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials < 1:
        raise ValueError(f"trials must be a positive integer, got {trials!r}")
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise ValueError(f"methods must be a non-empty subset of {METHODS}, got {methods!r}")
    workers = int(workers or os.cpu_count() or 1)
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    n_chunks = min(trials, max(1, 8 * workers))
    chunks = [c.tolist() for c in np.array_split(np.arange(trials), n_chunks)]
    base = {"geometry": true.geometry.to_dict(), "true_errors": true.errors.tolist(),
            "commanded": np.asarray(commanded, dtype=float), "noise": noise.to_dict(), "seed": int(seed),
            "methods": tuple(methods), "heldout": None if heldout is None else np.asarray(heldout, float)}
    parts, done = [], 0
    if workers == 1:
        for c in chunks:
            parts.append(run_trials({**base, "trials": c}))
            done += len(c)
            if progress:
                progress(done, trials)
    else:
        # Spawned workers with one BLAS thread each (pipeline.parallel.spawn_pool).
        from pipeline.study import run_trials as entry  # importable by name in the workers

        with spawn_pool(workers) as ex:
            futs = [ex.submit(entry, {**base, "trials": c}) for c in chunks]
            for f in as_completed(futs):
                parts.append(f.result())
                done += len(parts[-1]["trials"])
                if progress:
                    progress(done, trials)
    return _merge(parts, methods)


def summarize(results: dict, crb_var: np.ndarray, trials: int) -> dict:
    """Per-method figures: MSE/CRB per parameter, RMS errors, bias and held-out errors (mm)."""
    out = {}
    # Under efficiency and unbiasedness, T * MSE / CRB ~ chi-square with T degrees of freedom.
    from scipy.stats import chi2
    q_hi = float(chi2.ppf(0.995, trials) / trials)
    for m, r in results.items():
        e = r["errors"]
        mse = np.mean(e ** 2, axis=0)
        ratio = mse / crb_var
        bias = e.mean(axis=0)
        se = e.std(axis=0, ddof=1) / np.sqrt(trials) if trials > 1 else np.full(42, np.nan)
        hp = r["heldout_position_mm"]
        out[m] = {
            "trials": trials,
            "success_rate": float(np.mean(r["success"])),
            "parameter_error_rms_mm": float(np.sqrt(mse.mean())),
            "mse_over_crb": {n: float(v) for n, v in zip(NAMES, ratio)},
            "mse_over_crb_max": float(ratio.max()),
            "mse_over_crb_max_parameter": NAMES[int(np.argmax(ratio))],
            "mse_over_crb_min": float(ratio.min()),
            "mse_over_crb_mean": float(ratio.mean()),
            "mse_over_crb_99_5pct_sampling_limit": q_hi,
            "empirical_std_mm": {n: float(v) for n, v in zip(NAMES, e.std(axis=0))},
            "bias_mm": {n: float(v) for n, v in zip(NAMES, bias)},
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
    p = argparse.ArgumentParser(prog="python -m pipeline.study", description=__doc__.split("\n\n")[0])
    p.add_argument("--trials", type=int, default=200)
    p.add_argument("--noise-mm", type=float, default=0.001, help="Gaussian position noise std, mm")
    p.add_argument("--noise-rad", type=float, default=1e-6, help="Gaussian angle noise std, rad")
    p.add_argument("--poses", default="designed",
                   help="designed | paper | random | a command file (CSV; its commanded lengths are used)")
    p.add_argument("--n-poses", type=int, default=10, help="for designed/random poses")
    p.add_argument("--workspace", choices=("full", "paper"), default="full",
                   help="workspace of designed/random poses and of the held-out poses")
    p.add_argument("--criterion", choices=CRITERIA, default="d")
    p.add_argument("--method", choices=("forward", "paper", "both"), default="forward")
    p.add_argument("--errors", choices=("table3", "random"), default="table3",
                   help="true errors: the paper's Table 3, or uniform +-0.05 mm drawn from the seed")
    p.add_argument("--heldout", type=int, default=100, help="held-out poses (0: none)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    p.add_argument("--summary-json", default=None)
    p.add_argument("--rrd", default=None)
    p.add_argument("--overwrite", action="store_true")
    return p


def _poses(args, nominal: Hexapod, ws: Workspace, noise: SensorNoise):
    if args.poses == "paper":
        return paper.TABLE4_NOMINAL_POSES.copy(), None
    if args.poses == "designed":
        return design_poses(nominal, args.n_poses, ws, noise, criterion=args.criterion, seed=args.seed).poses, None
    if args.poses == "random":
        return sample_feasible_poses(nominal, ws, args.n_poses, args.seed), None
    try:
        return read_command_file(args.poses)
    except (OSError, ValueError) as exc:
        raise SystemExit(f"--poses: {exc}") from None


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    for p in (args.summary_json, args.rrd):
        if p and Path(p).exists() and not args.overwrite:
            raise SystemExit(f"{p} exists; pass --overwrite to replace it")
    if args.trials < 2:
        raise SystemExit(f"--trials must be >= 2, got {args.trials}")
    if args.n_poses < 7:
        raise SystemExit(f"--n-poses must be >= 7, got {args.n_poses}")
    try:
        noise = SensorNoise(args.noise_mm, args.noise_rad, "normal")
    except ValueError as exc:
        raise SystemExit(f"--noise-mm/--noise-rad: {exc}") from None
    nominal = paper_hexapod()
    errors = paper.TABLE3_ERRORS if args.errors == "table3" else \
        np.random.default_rng([args.seed, 7]).uniform(-0.05, 0.05, (6, 7))
    true = nominal.with_errors(errors)
    ws = workspace_by_name(args.workspace)
    targets, commanded = _poses(args, nominal, ws, noise)
    if commanded is None:
        commanded = inverse_kinematics(nominal, targets, stroke_mm=None)
    heldout = sample_feasible_poses(nominal, ws, args.heldout, [args.seed, 1]) if args.heldout else None
    reached = forward_kinematics(true, commanded, stroke_mm=None)
    analysis = analyze_observability(true, reached, noise)
    crb_var = analysis.crb_std ** 2
    predicted = None
    if heldout is not None:
        pu = pose_uncertainty(true, heldout, analysis.crb)
        predicted = float(np.sqrt(np.mean(pu.position_rms_mm ** 2)))
    methods = ("forward", "paper") if args.method == "both" else (args.method,)
    t0 = time.perf_counter()

    def progress(done, total):
        print(f"\rstudy: {done}/{total} trials ({time.perf_counter() - t0:.1f} s)", end="",
              file=sys.stderr, flush=True)

    results = monte_carlo(true, commanded, noise, args.trials, args.seed, methods=methods, heldout=heldout,
                          workers=args.workers, progress=progress)
    print(file=sys.stderr)
    figures = summarize(results, crb_var, args.trials)
    summary = {
        "command": "pipeline.study",
        "trials": args.trials, "seed": args.seed, "noise": noise.to_dict(),
        "poses": args.poses, "n_poses": int(targets.shape[0]), "workspace": ws.to_dict(),
        "criterion": args.criterion if args.poses == "designed" else None,
        "true_errors": args.errors, "heldout_poses": args.heldout,
        "simulated_machine": "calib.kinematics forward kinematics (no MuJoCo)",
        "observability": analysis.summary(),
        "crb_std_mm": {n: float(v) for n, v in zip(NAMES, analysis.crb_std)},
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
                 if held else ""),
              file=sys.stderr)
    return 0


def _markdown(summary: dict) -> str:
    lines = ["# Monte Carlo study", "",
             f"{summary['trials']} trials, seed {summary['seed']}, {summary['n_poses']} {summary['poses']} poses "
             f"({summary['workspace']['name']} workspace), Gaussian noise std {summary['noise']['position_mm']:g} mm, "
             f"{summary['noise']['orientation_rad']:g} rad. Machine: {summary['simulated_machine']}.", "",
             f"CRB parameter RMS: {summary['crb_rms_mm']:.4g} mm", "",
             "| method | param. error RMS (mm) | MSE/CRB min | mean | max (param) | held-out position mean / RMS (um) |",
             "|---|---|---|---|---|---|"]
    for m, f in summary["methods"].items():
        h = f["heldout_position_mm"]
        lines.append(f"| {m} | {f['parameter_error_rms_mm']:.4g} | {f['mse_over_crb_min']:.3f} | "
                     f"{f['mse_over_crb_mean']:.3f} | {f['mse_over_crb_max']:.3f} ({f['mse_over_crb_max_parameter']}) | "
                     + (f"{h['mean'] * 1e3:.4g} / {h['rms'] * 1e3:.4g} |" if h else "- |"))
    if summary["predicted_heldout_position_rms_mm_at_crb"] is not None:
        lines += ["", f"Held-out position error RMS predicted at the CRB: "
                      f"{summary['predicted_heldout_position_rms_mm_at_crb'] * 1e3:.4g} um"]
    return "\n".join(lines) + "\n"


def _write_rrd(path, analysis, results, figures, summary, overwrite) -> None:
    import rerun as rr
    import rerun.blueprint as rrb

    from pipeline.obs_log import log_bars, log_observability, observability_views
    from pipeline.rerun_log import save_recording

    views = [observability_views("study/observability", "Calibration poses")]
    for m in results:
        views.append(rrb.Horizontal(
            rrb.BarChartView(origin=f"study/{m}/mse_over_crb", name=f"{m}: MSE / CRB per parameter"),
            rrb.BarChartView(origin=f"study/{m}/empirical_std_mm", name=f"{m}: empirical std per parameter (mm)"),
            rrb.TimeSeriesView(origin=f"study/{m}/heldout_position_um", name=f"{m}: held-out position error (um)"),
        ))
    bp = rrb.Blueprint(rrb.Vertical(rrb.TextDocumentView(origin="study/summary", name="Summary"), *views))

    def log(rec):
        log_observability(rec, analysis, "study/observability", title="Calibration poses")
        rec.log("study/summary", rr.TextDocument(_markdown(summary), media_type=rr.MediaType.MARKDOWN), static=True)
        for m, r in results.items():
            f = figures[m]
            log_bars(rec, f"study/{m}/mse_over_crb", np.array([f["mse_over_crb"][n] for n in NAMES]))
            log_bars(rec, f"study/{m}/empirical_std_mm", np.array([f["empirical_std_mm"][n] for n in NAMES]))
            hp = r["heldout_position_mm"]
            if not np.all(np.isnan(hp)):
                rec.send_columns(f"study/{m}/heldout_position_um",
                                 indexes=[rr.TimeColumn("trial", sequence=np.arange(hp.size))],
                                 columns=rr.Scalars.columns(scalars=hp * 1e3))

    try:
        save_recording(path, log, application_id="parallel-calib-study", overwrite=overwrite, bp=bp)
    except FileExistsError as exc:
        raise SystemExit(str(exc)) from None


if __name__ == "__main__":
    sys.exit(main())
