"""Seed-averaged study of the Delta calibration gain G (the Delta paper's Sections 4.1, 4.2 and 5).

Pure kinematic simulation over the engine (:mod:`calib.engine`) and the Delta of
:mod:`calib.robots.delta`, no MuJoCo (the MuJoCo Delta reproduces the same kinematics within
1e-8 mm, see tests/test_mjcf_delta.py), so a study takes seconds to minutes.

Usage::

    python benchmarks/delta_study.py                      # 20 seeds, 1 mm / 1 deg, r = 250 mm
    python benchmarks/delta_study.py --seeds 20 --configs 8 20 40 50 60 100 150
    python benchmarks/delta_study.py --seeds 20 --error-mm 0.1 --weighting position --solver gn
    python benchmarks/delta_study.py --convergence --configs 8 --seeds 50
    python benchmarks/delta_study.py --paper --seeds 20   # the paper's setups against its figures

For every seed: real robot = nominal + uniform errors (half-width ``--error-mm`` on lengths,
``--error-deg`` on angles, :func:`calib.robots.uniform_errors`), configurations = nominal
inverse kinematics of targets drawn uniformly in the cylinder ``--radius-mm`` x
``--z-range-mm`` (redrawn when the nominal or the real robot cannot reach them), data = real
forward kinematics + noise (``--noise-dist``, default Gaussian of standard deviation
``--noise-mm`` on each coordinate and ``--noise-deg`` on each joint reading); both methods start
from the nominal and identify the 21 parameters of ``robot.free_default`` (``Lay1..3`` held):

* FKM: :func:`calib.engine.identify_forward` (all parameters through the forward kinematics);
* IKM: :func:`calib.engine.identify_chainwise` with ``weighted=True`` (chain by chain on the
  closure residuals). ``--solver lm``: each chain by Levenberg-Marquardt (the paper's IKM);
  ``--solver gn``: the engine's chain-wise Gauss-Newton (all chains stepped together, forward
  kinematics of the corrected model after each step, the hexapod paper's stopping rule).

The real parameters are compared in the identification's gauge
(:func:`calib.engine.gauge_representative`). Reported per (method, N), over seeds:
:func:`calib.metrics.calibration_gain`'s mean over the parameters (the paper's figure, "the
percentage average of the gain on all parameters") and its gain on the parameter-error norm
(Eq. 4.1 as printed, lengths in mm and angles in degrees), each as mean and median over seeds;
the held-out RMS position error of the model's prediction before and after calibration; the
share of converged runs; the time per identification.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calib.engine import gauge_representative, identify_chainwise, identify_forward  # noqa: E402
from calib.metrics import calibration_gain  # noqa: E402
from calib.noise import SensorNoise  # noqa: E402
from calib.robot import KinematicsError  # noqa: E402
from calib.robots import default_robot, uniform_errors  # noqa: E402

#: The Delta paper's two methods, as labelled in the tables (see :func:`identify_both`).
METHOD_LABELS = ("ikm", "fkm")
#: Default calibration workspace of the study: a vertical cylinder (radius, z range), mm.
STUDY_RADIUS_MM = 250.0
STUDY_Z_RANGE_MM = (-600.0, -300.0)
#: Workspace of the noise-free convergence table: the robot's default box has this size.
CONVERGENCE_RADIUS_MM = 150.0
CONVERGENCE_Z_RANGE_MM = (-500.0, -330.0)

#: The paper's simulations with their reported figures (Sections 4.2.1 and 4.2.2): label, method,
#: initial error (mm, deg), joint noise (deg), configurations and the paper's G (percent,
#: "percentage average of the gain on all parameters"). Position noise 1 um throughout.
PAPER_SETUPS = (
    ("FKM, 0.1 mm / 0.1 deg (4.2.1)", "fkm", 0.1, 0.1, 0.01, (8, 20, 40, 60), (-38.54, 20.0, 38.0, 45.38)),
    ("IKM, 1 mm / 1 deg (4.2.2)", "ikm", 1.0, 1.0, 0.01, (8, 20, 40, 60), (-6.17, 62.54, 87.58, 86.5)),
    ("IKM, 1 mm / 0.01 deg (4.2.2, literal)", "ikm", 1.0, 0.01, 0.01, (8, 20, 40, 60), (-6.17, 62.54, 87.58, 86.5)),
    ("IKM, 1 cm / 10 deg, noise 1 um / 0.001 deg (4.2.2)", "ikm", 10.0, 10.0, 0.001, (8,), (99.9,)),
)


def cylinder_targets(n: int, rng: np.random.Generator, radius_mm: float, z_range_mm) -> np.ndarray:
    """(n, 3) plate positions uniform in the vertical cylinder ``r <= radius_mm``, ``z`` in
    ``z_range_mm``, mm."""
    r = radius_mm * np.sqrt(rng.uniform(0.0, 1.0, n))
    a = rng.uniform(0.0, 2 * np.pi, n)
    z = rng.uniform(z_range_mm[0], z_range_mm[1], n)
    return np.stack([r * np.cos(a), r * np.sin(a), z], axis=1)


def configurations(robot, true: np.ndarray, n: int, rng: np.random.Generator, radius_mm: float,
                   z_range_mm, rounds: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """``(commanded joints (n, 3), true plate positions (n, 3))``: nominal inverse kinematics of
    cylinder targets and the real robot's forward kinematics of them; targets either cannot
    reach are redrawn."""
    nominal = robot.table.nominal
    qs, xs = [], []
    for _ in range(rounds):
        for t in cylinder_targets(n, rng, radius_mm, z_range_mm):
            try:
                q = robot.inverse_kinematics(nominal, t[None])
                x = robot.forward_kinematics(true, q)
            except KinematicsError:
                continue
            qs.append(q[0])
            xs.append(x[0])
        if len(qs) >= n:
            return np.array(qs[:n]), np.array(xs[:n])
    raise ValueError(f"the real robot reaches fewer than {n} targets of the cylinder r <= {radius_mm} mm, "
                     f"z in {tuple(z_range_mm)} mm")


def identify_both(robot, joints, measured, declared: SensorNoise, solver: str, **options) -> dict:
    """``{"ikm": result, "fkm": result}`` with their wall times: the two methods of the paper."""
    out = {}
    for m in METHOD_LABELS:
        t0 = time.perf_counter()
        if m == "fkm":
            res = identify_forward(robot, joints, measured, declared, solver=solver, **options)
        else:
            res = identify_chainwise(robot, joints, measured, declared, solver=solver, weighted=True, **options)
        out[m] = (res, time.perf_counter() - t0)
    return out


def _rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(d ** 2, axis=1))))


def run_study(
    configs=(8, 20, 40, 60),
    seeds: int = 20,
    noise_mm: float = 1e-3,
    noise_deg: float = 0.01,
    error_mm: float = 1.0,
    error_deg: float | None = None,
    solver: str = "lm",
    heldout: int = 50,
    base_seed: int = 0,
    radius_mm: float = STUDY_RADIUS_MM,
    z_range_mm: tuple[float, float] = STUDY_Z_RANGE_MM,
    weighting: str = "declared",
    noise_dist: str = "normal",
    methods=METHOD_LABELS,
) -> list[dict]:
    """Run the study; returns one dict per (method, N) with the aggregated figures.

    ``weighting="declared"`` weights the residuals by the simulated noise (position and joint
    noise propagated); ``"position"`` declares the joints noise-free (plain least squares on the
    raw mm residuals, as the paper does), which is what lets the methods differ.
    """
    if weighting not in ("declared", "position"):
        raise ValueError(f"weighting must be 'declared' or 'position', got {weighting!r}")
    robot = default_robot("delta")
    nominal = robot.table.nominal
    noise_rad = float(np.deg2rad(noise_deg))
    simulated = SensorNoise(noise_mm, distribution=noise_dist, joint=noise_rad)
    declared = simulated if weighting == "declared" else SensorNoise(noise_mm, distribution=noise_dist)
    error_rad = float(np.deg2rad(error_mm if error_deg is None else error_deg))
    units = robot.pose_units
    rows = []
    for n in configs:
        acc = {m: {"mean": [], "norm": [], "rms": [], "ok": [], "t": []} for m in methods}
        before = []
        for s in range(seeds):
            s_err, s_data, s_val = np.random.SeedSequence([base_seed, n, s]).spawn(3)
            true = nominal + uniform_errors(robot, s_err, error_mm, error_rad)
            rng = np.random.default_rng(s_data)  # targets, then joint noise, then position noise
            q_cmd, x_true = configurations(robot, true, n, rng, radius_mm, z_range_mm)
            q_meas = q_cmd + simulated.sample_joints(n, robot.n_chains, rng)
            x_meas = x_true + simulated.sample(n, rng, units)
            q_val, x_val = configurations(robot, true, heldout, np.random.default_rng(s_val), radius_mm, z_range_mm)
            before.append(_rms(robot.forward_kinematics(nominal, q_val) - x_val))
            truth = gauge_representative(robot, true, nominal)
            fits = identify_both(robot, q_meas, x_meas, declared, solver)
            for m in methods:
                res, dt = fits[m]
                g = calibration_gain(robot, truth, nominal, res.theta)
                acc[m]["mean"].append(g.mean)
                acc[m]["norm"].append(g.norm)
                acc[m]["ok"].append(res.success)
                acc[m]["t"].append(dt)
                try:
                    acc[m]["rms"].append(_rms(robot.forward_kinematics(res.theta, q_val) - x_val))
                except KinematicsError:
                    acc[m]["rms"].append(np.nan)
        for m in methods:
            a = {k: np.asarray(v, dtype=float) for k, v in acc[m].items()}
            rows.append({
                "method": m,
                "configs": n,
                "G_mean": float(np.mean(a["mean"])),
                "G_mean_median": float(np.median(a["mean"])),
                "G_norm": float(np.mean(a["norm"])),
                "G_norm_median": float(np.median(a["norm"])),
                "heldout_rms_before_mm": float(np.mean(before)),
                "heldout_rms_after_mm": float(np.nanmean(a["rms"])),
                "converged": float(np.mean(a["ok"])),
                "time_s": float(np.mean(a["t"])),
            })
    return rows


def convergence_study(
    errors_mm=(1.0, 10.0, 20.0, 30.0, 50.0),
    seeds: int = 20,
    configs: int = 8,
    base_seed: int = 0,
    radius_mm: float = CONVERGENCE_RADIUS_MM,
    z_range_mm: tuple[float, float] = CONVERGENCE_Z_RANGE_MM,
) -> str:
    """Noise-free radius of convergence: count of seeds whose run converged with G > 99% (mean
    over parameters), per method and solver. Initial error half-width ``e`` mm on lengths and
    ``e`` degrees on angles. Returns a markdown table."""
    robot = default_robot("delta")
    nominal = robot.table.nominal
    noise_free = SensorNoise()
    keys = ("fkm-lm", "fkm-gn", "ikm-lm", "ikm-gn")
    lines = ["| initial error (mm / deg) | FKM-LM | FKM-GN | IKM-LM | IKM-GN |", "|---|---|---|---|---|"]
    for e in errors_mm:
        ok = dict.fromkeys(keys, 0)
        n_done = 0
        for s in range(seeds):
            s_err, s_data = np.random.SeedSequence([base_seed, 7, s]).spawn(2)
            true = nominal + uniform_errors(robot, s_err, e, float(np.deg2rad(e)))
            try:
                q, x = configurations(robot, true, configs, np.random.default_rng(s_data), radius_mm, z_range_mm)
            except ValueError:
                continue
            n_done += 1
            truth = gauge_representative(robot, true, nominal)
            for solver in ("lm", "gn"):
                for m, (res, _) in identify_both(robot, q, x, noise_free, solver, max_iter=200).items():
                    if res.success and calibration_gain(robot, truth, nominal, res.theta).mean > 99.0:
                        ok[f"{m}-{solver}"] += 1
        lines.append(f"| {e:g} | " + " | ".join(f"{ok[k]}/{n_done}" for k in keys) + " |")
    return "\n".join(lines)


def paper_table(seeds: int = 20, base_seed: int = 0, noise_dist: str = "normal", heldout: int = 20,
                radius_mm: float = STUDY_RADIUS_MM, z_range_mm=STUDY_Z_RANGE_MM) -> str:
    """The paper's noisy setups (:data:`PAPER_SETUPS`) against its figures: our G as the mean
    over parameters (the paper's figure) and on the parameter-error norm, each the median and
    the mean over seeds. Returns a markdown table."""
    lines = ["| setup | N | paper's G (mean over parameters) | ours, mean over parameters: median / mean over seeds (%) "
             "| ours, on the norm: median / mean over seeds (%) |", "|---|---|---|---|---|"]
    for label, method, e_mm, e_deg, joint_deg, configs, figures in PAPER_SETUPS:
        rows = run_study(configs, seeds, 1e-3, joint_deg, e_mm, e_deg, "lm", heldout, base_seed, radius_mm,
                         tuple(z_range_mm), "declared", noise_dist, methods=(method,))
        for r, paper in zip(rows, figures):
            lines.append(f"| {label} | {r['configs']} | {paper:g} | {r['G_mean_median']:.1f} / {r['G_mean']:.1f} | "
                         f"{r['G_norm_median']:.1f} / {r['G_norm']:.1f} |")
    return "\n".join(lines)


def format_table(rows: list[dict]) -> str:
    """Markdown table of :func:`run_study` rows."""
    lines = [
        "| method | N | G mean over parameters: mean over seeds (%) | median (%) | G on the norm: mean (%) | "
        "median (%) | held-out RMS before (mm) | after (mm) | converged | time/run (s) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['method'].upper()} | {r['configs']} | {r['G_mean']:.1f} | {r['G_mean_median']:.1f} | "
            f"{r['G_norm']:.1f} | {r['G_norm_median']:.1f} | {r['heldout_rms_before_mm']:.4f} | "
            f"{r['heldout_rms_after_mm']:.4f} | {r['converged']:.2f} | {r['time_s']:.3f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python benchmarks/delta_study.py",
                                description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--configs", type=int, nargs="+", default=[8, 20, 40, 60],
                   help="numbers of calibration configurations (--convergence: the smallest is used)")
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--noise-mm", type=float, default=1e-3, help="position noise on each coordinate, mm")
    p.add_argument("--noise-deg", type=float, default=0.01, help="noise of each joint reading, deg")
    p.add_argument("--noise-dist", choices=("normal", "uniform"), default="normal",
                   help="noise distribution: standard deviation (normal) or half-width (uniform) as given")
    p.add_argument("--error-mm", type=float, default=1.0, help="initial length error half-width, mm")
    p.add_argument("--error-deg", type=float, default=None, help="initial angle error half-width, deg (default: --error-mm)")
    p.add_argument("--solver", choices=("lm", "gn"), default="lm")
    p.add_argument("--heldout", type=int, default=50, help="held-out configurations per seed")
    p.add_argument("--base-seed", type=int, default=0)
    p.add_argument("--radius-mm", type=float, default=None,
                   help=f"workspace cylinder radius, mm (default {STUDY_RADIUS_MM:g}; --convergence: "
                        f"{CONVERGENCE_RADIUS_MM:g})")
    p.add_argument("--z-range-mm", type=float, nargs=2, default=None,
                   help=f"workspace cylinder z range, mm (default {STUDY_Z_RANGE_MM[0]:g} {STUDY_Z_RANGE_MM[1]:g}; "
                        f"--convergence: {CONVERGENCE_Z_RANGE_MM[0]:g} {CONVERGENCE_Z_RANGE_MM[1]:g})")
    p.add_argument("--weighting", choices=("declared", "position"), default="declared",
                   help="weight residuals by the simulated noise, or declare the joints noise-free")
    p.add_argument("--convergence", action="store_true", help="noise-free radius-of-convergence table instead")
    p.add_argument("--paper", action="store_true",
                   help="the paper's noisy setups against its figures (uses --seeds, --base-seed, --noise-dist, "
                        "the workspace flags)")
    a = p.parse_args(argv)
    if a.seeds < 1 or min(a.configs) < 7:
        print("error: --seeds must be >= 1 and every --configs value >= 7 (21 parameters, 3 per configuration)",
              file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    if a.convergence:
        radius = CONVERGENCE_RADIUS_MM if a.radius_mm is None else a.radius_mm
        z_range = CONVERGENCE_Z_RANGE_MM if a.z_range_mm is None else tuple(a.z_range_mm)
        print(f"Delta convergence study: noise-free, {min(a.configs)} configurations, {a.seeds} seeds, "
              f"workspace r={radius:g} mm z={z_range} mm; runs with G > 99% (mean over parameters)")
        print(convergence_study(seeds=a.seeds, configs=min(a.configs), base_seed=a.base_seed,
                                radius_mm=radius, z_range_mm=z_range))
        print(f"total {time.perf_counter() - t0:.1f} s")
        return 0
    radius = STUDY_RADIUS_MM if a.radius_mm is None else a.radius_mm
    z_range = STUDY_Z_RANGE_MM if a.z_range_mm is None else tuple(a.z_range_mm)
    if a.paper:
        print(f"Delta paper setups: {a.seeds} seeds, position noise 1 um ({a.noise_dist}), LM, declared weights, "
              f"workspace r={radius:g} mm z={z_range} mm")
        print(paper_table(a.seeds, a.base_seed, a.noise_dist, radius_mm=radius, z_range_mm=z_range))
        print(f"total {time.perf_counter() - t0:.1f} s")
        return 0
    rows = run_study(a.configs, a.seeds, a.noise_mm, a.noise_deg, a.error_mm, a.error_deg, a.solver, a.heldout,
                     a.base_seed, radius, z_range, a.weighting, a.noise_dist)
    print(f"Delta study: {a.seeds} seeds, noise {a.noise_mm} mm / {a.noise_deg} deg ({a.noise_dist}), initial error "
          f"{a.error_mm} mm / {a.error_mm if a.error_deg is None else a.error_deg} deg, solver {a.solver}, "
          f"weighting {a.weighting}, workspace r={radius:g} mm z={z_range} mm")
    print(format_table(rows))
    print(f"total {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
