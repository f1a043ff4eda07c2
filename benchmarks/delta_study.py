"""Seed-averaged study of the Delta calibration gain G against the number of configurations.

Acceptance point 3 of issue #4 (paper Sections 4.2 and 5): position noise 1 um, joint noise
0.01 degree, G for 8, 20, 40 and 60 configurations, both methods, averaged over seeds.
Pure kinematic simulation (calib package; the MuJoCo testbed reproduces the same kinematics
to about 1e-10 mm, see tests/test_mjcf_delta.py), so the study takes seconds.

Run::

    python -m benchmarks.delta_study                      # 20 seeds, 1 mm / 1 deg, r = 250 mm
    python -m benchmarks.delta_study --seeds 50 --configs 8 20 40 50 60 100 150
    python -m benchmarks.delta_study --seeds 50 --error-mm 0.1 --weighting position --solver gn
    python -m benchmarks.delta_study --convergence --configs 8 --seeds 50

For every seed: real robot = nominal + uniform errors (half-width ``--error-mm`` on lengths,
``--error-deg`` on angles), configurations = nominal IK of uniform workspace targets, data =
real FK + Gaussian noise, both methods start from the nominal. Reported per (method, N):
mean over seeds of the paper's "average of the per-parameter gains" (mean G), its median
over seeds, the Eq. 4.1 norm gain (mm and degrees), the held-out RMS position error after
calibration, and the fraction of converged runs.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from calib.delta import DeltaParams, forward_kinematics
from calib.delta_identification import (
    calibration_gain,
    identify_fkm,
    identify_ikm,
    make_dataset,
    perturb_params,
)


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
    radius_mm: float = 250.0,
    z_range_mm: tuple[float, float] = (-600.0, -300.0),
    weighting: str = "declared",
) -> list[dict]:
    """Run the study; returns one dict per (method, N) with the aggregated figures.

    ``weighting="declared"`` weights residuals by the true noise (1 um, 0.01 deg);
    ``"position"`` declares the joints noise-free (plain least squares on the raw mm
    residuals, as the paper does), which is what lets the methods differ.
    """
    if weighting not in ("declared", "position"):
        raise ValueError(f"weighting must be 'declared' or 'position', got {weighting!r}")
    nominal = DeltaParams.nominal()
    noise_rad = float(np.deg2rad(noise_deg))
    w_mm = max(noise_mm, 1e-6)
    w_rad = max(noise_rad, 1e-12) if weighting == "declared" else 1e-12
    ws = {"radius_mm": radius_mm, "z_range_mm": z_range_mm}
    error_rad = float(np.deg2rad(error_mm if error_deg is None else error_deg))
    rows = []
    for n in configs:
        acc = {m: {"mean": [], "norm": [], "rms": [], "ok": [], "t": []} for m in ("fkm", "ikm")}
        before = []
        for s in range(seeds):
            ss = np.random.SeedSequence([base_seed, n, s])
            s_err, s_data, s_val = ss.spawn(3)
            true = perturb_params(nominal, error_mm, error_rad, s_err)
            data = make_dataset(true, nominal, n, s_data, noise_mm=noise_mm, noise_rad=noise_rad, **ws)
            val = make_dataset(true, nominal, heldout, s_val, **ws)
            before.append(np.sqrt(np.mean(np.sum((forward_kinematics(nominal, val.q_cmd) - val.positions_true) ** 2, 1))))
            for m, fn in (("fkm", identify_fkm), ("ikm", identify_ikm)):
                t0 = time.perf_counter()
                res = fn(nominal, data.q_meas, data.positions_meas, solver=solver, sigma_mm=w_mm, sigma_rad=w_rad)
                acc[m]["t"].append(time.perf_counter() - t0)
                g = calibration_gain(true, nominal, res.estimate)
                acc[m]["mean"].append(g.mean)
                acc[m]["norm"].append(g.norm)
                acc[m]["ok"].append(res.success)
                try:
                    pred = forward_kinematics(res.estimate, val.q_cmd)
                    acc[m]["rms"].append(np.sqrt(np.mean(np.sum((pred - val.positions_true) ** 2, 1))))
                except ValueError:
                    acc[m]["rms"].append(np.nan)
        for m in ("ikm", "fkm"):
            a = {k: np.asarray(v, dtype=float) for k, v in acc[m].items()}
            rows.append(
                {
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
                }
            )
    return rows


def convergence_study(
    errors_mm=(1.0, 10.0, 20.0, 30.0, 50.0),
    seeds: int = 20,
    configs: int = 8,
    base_seed: int = 0,
) -> str:
    """Noise-free radius of convergence: share of seeds with G > 99% per method and solver.

    Initial error half-width ``e`` mm on lengths and ``e`` degrees on angles; ``configs``
    configurations; workspace as :func:`calib.delta_identification.make_dataset` defaults.
    Returns a markdown table.
    """
    nominal = DeltaParams.nominal()
    lines = [
        "| initial error (mm / deg) | FKM-LM | FKM-GN | IKM-LM | IKM-GN |",
        "|---|---|---|---|---|",
    ]
    for e in errors_mm:
        ok = {k: 0 for k in ("fkm-lm", "fkm-gn", "ikm-lm", "ikm-gn")}
        n_done = 0
        for s in range(seeds):
            ss = np.random.SeedSequence([base_seed, 7, s])
            s_err, s_data = ss.spawn(2)
            true = perturb_params(nominal, e, float(np.deg2rad(e)), s_err)
            try:
                data = make_dataset(true, nominal, configs, s_data)
            except ValueError:
                continue
            n_done += 1
            for m, fn in (("fkm", identify_fkm), ("ikm", identify_ikm)):
                for solver in ("lm", "gn"):
                    res = fn(nominal, data.q_meas, data.positions_meas, solver=solver, max_iter=200)
                    if res.success and calibration_gain(true, nominal, res.estimate).mean > 99.0:
                        ok[f"{m}-{solver}"] += 1
        lines.append(f"| {e:g} | " + " | ".join(f"{ok[k]}/{n_done}" for k in ok) + " |")
    return "\n".join(lines)


def format_table(rows: list[dict]) -> str:
    """Markdown table of :func:`run_study` rows."""
    head = (
        "| method | N | mean G, mean over seeds (%) | mean G, median (%) | Eq.4.1 norm G, mean (%) | "
        "norm G, median (%) | held-out RMS before (mm) | after (mm) | converged | time/run (s) |\n"
        "|---|---|---|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for r in rows:
        lines.append(
            f"| {r['method'].upper()} | {r['configs']} | {r['G_mean']:.1f} | {r['G_mean_median']:.1f} | "
            f"{r['G_norm']:.1f} | {r['G_norm_median']:.1f} | {r['heldout_rms_before_mm']:.4f} | "
            f"{r['heldout_rms_after_mm']:.4f} | {r['converged']:.2f} | {r['time_s']:.3f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.delta_study", description=__doc__.split("\n\n")[0])
    p.add_argument("--configs", type=int, nargs="+", default=[8, 20, 40, 60])
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--noise-mm", type=float, default=1e-3)
    p.add_argument("--noise-deg", type=float, default=0.01)
    p.add_argument("--error-mm", type=float, default=1.0, help="initial length error half-width, mm (default 1)")
    p.add_argument("--error-deg", type=float, default=None, help="initial angle error half-width, deg (default = error-mm)")
    p.add_argument("--solver", choices=("lm", "gn"), default="lm")
    p.add_argument("--heldout", type=int, default=50)
    p.add_argument("--base-seed", type=int, default=0)
    p.add_argument("--radius-mm", type=float, default=250.0, help="workspace cylinder radius, mm (default 250)")
    p.add_argument("--z-range-mm", type=float, nargs=2, default=[-600.0, -300.0], help="workspace cylinder z range, mm (default -600 -300)")
    p.add_argument("--weighting", choices=("declared", "position"), default="declared")
    p.add_argument("--convergence", action="store_true", help="noise-free radius-of-convergence table instead")
    a = p.parse_args(argv)
    if a.convergence:
        t0 = time.perf_counter()
        print(f"Delta convergence study: noise-free, {min(a.configs)} configurations, {a.seeds} seeds, G > 99% counts")
        print(convergence_study(seeds=a.seeds, configs=min(a.configs), base_seed=a.base_seed))
        print(f"total {time.perf_counter() - t0:.1f} s")
        return 0
    if a.seeds < 1 or min(a.configs) < 8:
        print("error: --seeds must be >= 1 and every --configs value >= 8", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    rows = run_study(
        a.configs, a.seeds, a.noise_mm, a.noise_deg, a.error_mm, a.error_deg, a.solver, a.heldout, a.base_seed,
        a.radius_mm, tuple(a.z_range_mm), a.weighting,
    )
    print(
        f"Delta study: {a.seeds} seeds, noise {a.noise_mm} mm / {a.noise_deg} deg, initial error "
        f"{a.error_mm} mm / {a.error_mm if a.error_deg is None else a.error_deg} deg, solver {a.solver}, "
        f"weighting {a.weighting}, workspace r={a.radius_mm} mm z={a.z_range_mm} mm"
    )
    print(format_table(rows))
    print(f"total {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
