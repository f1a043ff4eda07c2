"""End-to-end Delta calibration loop: simulate, measure, identify (FKM and IKM), report.

Usage::

    python -m pipeline.delta_run --configs 20 --heldout 20 --seed 0
    python -m pipeline.run --robot delta ...      # same options

Steps: nominal Model 24 (paper geometry) -> injected uniform parameter errors (seeded) ->
MuJoCo Delta of the erroneous robot -> commanded configurations (nominal inverse kinematics of
seeded workspace targets) -> settled plate positions and joint readings with seeded noise ->
identification with both methods (``--solver`` LM or GN) -> calibration gain G (paper
Eq. 4.1) per parameter and averaged -> held-out position error before / after with the
``--method`` estimate.

Writes ``<out>/<name>.rrd`` (Rerun), ``<out>/<name>.csv`` (``t_s, q1_rad, q2_rad, q3_rad,
x_mm, y_mm, z_mm``, one row per measured configuration), ``<out>/<name>.json`` (sidecar) and
optionally ``--summary-json PATH``. Existing files are never overwritten unless
``--overwrite`` is given; every file is written to a temporary file first and moved into
place.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
import time
from pathlib import Path

import numpy as np

from calib.delta import (
    NOMINAL_GEOMETRY,
    PARAMETER_NAMES,
    PARAMETER_TABLE,
    PARAMETER_UNITS,
    DeltaParams,
    canonical_params,
    forward_kinematics,
    inverse_kinematics,
)
from calib.delta_identification import (
    DEFAULT_FREE,
    calibration_gain,
    identify_fkm,
    identify_ikm,
    null_space_combinations,
    perturb_params,
    random_workspace_positions,
)
from pipeline.delta_testbed import DeltaTestbed
from pipeline.recording import atomic_write
from pipeline.rerun_log import save_recording

__all__ = ["main", "build_parser"]

CSV_COLUMNS = ("t_s", "q1_rad", "q2_rad", "q3_rad", "x_mm", "y_mm", "z_mm")


def build_parser() -> argparse.ArgumentParser:
    """Argument parser of the Delta loop."""
    p = argparse.ArgumentParser(
        prog="python -m pipeline.delta_run",
        description="Delta robot calibration loop (MuJoCo testbed, FKM and IKM identification). "
        "Lengths mm, angles rad.",
    )
    p.add_argument("--configs", type=int, default=20, help="calibration configurations (>= 8, default 20)")
    p.add_argument("--heldout", type=int, default=20, help="held-out validation configurations (>= 1, default 20)")
    p.add_argument("--noise-mm", type=float, default=0.0, help="position noise std per coordinate, mm (default 0)")
    p.add_argument("--noise-rad", type=float, default=0.0, help="joint reading noise std, rad (default 0)")
    p.add_argument("--error-mm", type=float, default=1.0, help="half-width of the injected uniform length errors, mm (default 1)")
    p.add_argument(
        "--error-rad",
        type=float,
        default=None,
        help="half-width of the injected uniform angle errors, rad (default: the paper's "
        "'x mm / x degrees' convention, i.e. deg2rad(error-mm))",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of errors, configurations and noise (default 0)")
    p.add_argument("--method", choices=("ikm", "fkm"), default="ikm", help="estimate reported as identified_params (default ikm)")
    p.add_argument("--solver", choices=("lm", "gn"), default="lm", help="Levenberg-Marquardt or Gauss-Newton (default lm)")
    p.add_argument("--out", default="recordings", help="output folder (default recordings)")
    p.add_argument("--name", default="delta", help="base name of the output files (default delta)")
    p.add_argument("--summary-json", default=None, help="also write a summary JSON to this path")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")
    return p


# --------------------------------------------------------------------------- files


def _write_text(path: Path, text: str, overwrite: bool) -> None:
    atomic_write(path, text, overwrite=overwrite)


# --------------------------------------------------------------------------- rerun


def _write_rrd(path: Path, name: str, meas, gains: dict, before, after, summary_md: str, overwrite: bool) -> None:
    import rerun as rr
    import rerun.blueprint as rrb

    blueprint = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="delta", name="Delta (mm)"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="heldout", name="Held-out position error (mm)"),
                rrb.BarChartView(origin="gain/ikm", name="G per parameter, IKM (%)"),
                rrb.BarChartView(origin="gain/fkm", name="G per parameter, FKM (%)"),
                rrb.TextDocumentView(origin="summary", name="Summary"),
            ),
        )
    )

    def _log(rec) -> None:
        rec.log("delta", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rec.log("delta/shoulders", rr.Points3D(meas.shoulders, radii=4.0), static=True)
        for k in range(meas.t_s.size):
            rec.set_time("config", sequence=k)
            rec.set_time("sim_time", duration=float(meas.t_s[k]))
            arms = [np.stack([meas.shoulders[i], meas.elbows[k, i]]) for i in range(3)]
            fores = [np.stack([meas.elbows[k, i], meas.plate_attach[k, i]]) for i in range(3)]
            rec.log("delta/arms", rr.LineStrips3D(arms, radii=3.0, colors=[50, 100, 200]))
            rec.log("delta/forearms", rr.LineStrips3D(fores, radii=2.0, colors=[200, 120, 50]))
            rec.log("delta/plate", rr.Points3D(meas.positions_meas[k : k + 1], radii=5.0, colors=[60, 180, 60]))
            rec.log("delta/plate_attach", rr.LineStrips3D([np.vstack([meas.plate_attach[k], meas.plate_attach[k, :1]])], radii=1.5))
        for j in range(before.size):
            rec.set_time("heldout_index", sequence=j)
            rec.log("heldout/before", rr.Scalars(float(before[j])))
            rec.log("heldout/after", rr.Scalars(float(after[j])))
        for method, g in gains.items():
            vals = np.nan_to_num(np.asarray(g.per_parameter, dtype=np.float64), nan=0.0)
            rec.log(f"gain/{method}", rr.BarChart(vals), static=True)
        rec.log("summary", rr.TextDocument(summary_md, media_type=rr.MediaType.MARKDOWN), static=True)

    save_recording(path, _log, application_id=f"parallel_calib_delta_{name}", overwrite=overwrite, bp=blueprint)


# --------------------------------------------------------------------------- main


def _validate(args) -> str | None:
    if args.configs < 8:
        return f"--configs must be >= 8 (Model 24 needs 8), got {args.configs}"
    if args.heldout < 1:
        return f"--heldout must be >= 1, got {args.heldout}"
    for flag, val in (("--noise-mm", args.noise_mm), ("--noise-rad", args.noise_rad), ("--error-mm", args.error_mm)):
        if not (np.isfinite(val) and val >= 0):
            return f"{flag} must be finite and >= 0, got {val}"
    if args.error_rad is not None and not (np.isfinite(args.error_rad) and args.error_rad >= 0):
        return f"--error-rad must be finite and >= 0, got {args.error_rad}"
    if not args.name or any(c in args.name for c in "/\\") or args.name.startswith("."):
        return f"--name must be a plain file name, got {args.name!r}"
    return None


def _rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(v**2)))


def main(argv: list[str] | None = None) -> int:
    """Run the Delta calibration loop; returns a process exit code (0 ok, 1 failure, 2 usage)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help or usage error
        return int(exc.code or 0)
    problem = _validate(args)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    out = Path(args.out)
    paths = {ext: out / f"{args.name}.{ext}" for ext in ("rrd", "csv", "json")}
    summary_path = Path(args.summary_json) if args.summary_json else None
    targets = list(paths.values()) + ([summary_path] if summary_path else [])
    if not args.overwrite:
        existing = [str(p) for p in targets if p.exists()]
        if existing:
            print(f"error: refusing to overwrite existing file(s) {existing} (use --overwrite)", file=sys.stderr)
            return 1

    error_rad = float(np.deg2rad(args.error_mm)) if args.error_rad is None else float(args.error_rad)
    ss = np.random.SeedSequence(args.seed)
    seed_err, seed_cfg, seed_noise = ss.spawn(3)
    nominal = DeltaParams.nominal()
    true = perturb_params(nominal, args.error_mm, error_rad, seed_err)
    n_cal, n_val = args.configs, args.heldout
    try:
        x_target = random_workspace_positions(n_cal + n_val, seed_cfg)
        q_cmd = inverse_kinematics(nominal, x_target)
        bed = DeltaTestbed(true, noise_mm=args.noise_mm, noise_rad=args.noise_rad, seed=seed_noise)
        meas = bed.measure(q_cmd)
    except (ValueError, RuntimeError) as exc:
        print(f"error: simulation failed: {exc}", file=sys.stderr)
        return 1
    cal = slice(0, n_cal)
    val = slice(n_cal, n_cal + n_val)
    sig_mm = args.noise_mm if args.noise_mm > 0 else 1e-3
    sig_rad = args.noise_rad if args.noise_rad > 0 else float(np.deg2rad(0.01))
    results, gains, t_id = {}, {}, {}
    for method, fn in (("ikm", identify_ikm), ("fkm", identify_fkm)):
        t1 = time.perf_counter()
        try:
            res = fn(nominal, meas.q_meas[cal], meas.positions_meas[cal], solver=args.solver, sigma_mm=sig_mm, sigma_rad=sig_rad)
        except ValueError as exc:
            print(f"error: {method} identification failed: {exc}", file=sys.stderr)
            return 1
        t_id[method] = time.perf_counter() - t1
        results[method] = res
        gains[method] = calibration_gain(true, nominal, res.estimate)

    def heldout_err(params: DeltaParams) -> np.ndarray:
        try:
            pred = forward_kinematics(params, meas.q_true[val])
        except ValueError:
            return np.full(n_val, np.nan)
        return np.linalg.norm(pred - meas.positions_true[val], axis=1)

    before = heldout_err(nominal)
    after_by = {m: heldout_err(r.estimate) for m, r in results.items()}
    after = after_by[args.method]
    chosen = results[args.method]
    true_c = canonical_params(true).to_vector()
    is_mm = np.array([u == "mm" for u in PARAMETER_UNITS])
    free_idx = np.array([PARAMETER_NAMES.index(n) for n in DEFAULT_FREE])
    free_mask = np.zeros(24, bool)
    free_mask[free_idx] = True

    def param_err(est: DeltaParams) -> dict:
        e = np.abs(est.to_vector() - true_c)
        return {"max_abs_mm": float(e[is_mm & free_mask].max()), "max_abs_rad": float(e[~is_mm & free_mask].max())}

    summary = {
        "robot": "delta",
        "units": {"length": "mm", "angle": "rad", "gain": "percent"},
        "configs": n_cal,
        "heldout": n_val,
        "seed": args.seed,
        "noise": {"position_mm": args.noise_mm, "joint_rad": args.noise_rad},
        "declared_noise_for_weights": {"position_mm": sig_mm, "joint_rad": sig_rad},
        "initial_error_half_width": {"length_mm": args.error_mm, "angle_rad": error_rad},
        "method": args.method,
        "solver": args.solver,
        "fixed_parameters": [n for n in PARAMETER_NAMES if n not in DEFAULT_FREE],
        "non_identifiable": "per chain, arm direction (Lax_i, Lay_i) vs joint offset alpha_i; Lay_i held at 0, "
        "estimates compared with the canonical (Lay=0) equivalent of the injected parameters",
        "null_space_at_nominal": null_space_combinations(nominal, meas.q_meas[cal]),
        "gain_G": {m: g.as_dict() for m, g in gains.items()},
        "identified_params": chosen.estimate.to_dict(),
        "identified_params_by_method": {m: r.estimate.to_dict() for m, r in results.items()},
        "injected_params": true.to_dict(),
        "injected_errors": dict(zip(PARAMETER_NAMES, (true.to_vector() - nominal.to_vector()).tolist())),
        "injected_params_canonical": canonical_params(true).to_dict(),
        "parameter_error_after": {m: param_err(r.estimate) for m, r in results.items()},
        "solver_status": {
            m: {"success": r.success, "iterations": r.iterations, "message": r.message, "time_s": t_id[m]}
            for m, r in results.items()
        },
        "heldout_position_error_mm": {
            "statistic": "RMS over held-out configurations of the plate position error norm",
            "before": _rms(before),
            "after": _rms(after),
            "max_before": float(np.max(before)),
            "max_after": float(np.max(after)),
            "after_by_method": {m: {"rms": _rms(a), "max": float(np.max(a))} for m, a in after_by.items()},
        },
        "settle_steps_max": int(meas.steps.max()),
        "wall_time_s": None,
        "rrd": str(paths["rrd"]),
        "csv": str(paths["csv"]),
        "json": str(paths["json"]),
    }
    md = [
        f"# Delta calibration ({args.name})",
        f"{n_cal} configurations, {n_val} held out, seed {args.seed}, noise {args.noise_mm} mm / {args.noise_rad} rad, "
        f"solver {args.solver}.",
        "",
        "| method | mean G (%) | Eq. 4.1 norm G (%) | held-out RMS after (mm) | success |",
        "|---|---|---|---|---|",
    ]
    for m in ("ikm", "fkm"):
        md.append(
            f"| {m} | {gains[m].mean:.3f} | {gains[m].norm:.3f} | {_rms(after_by[m]):.3e} | {results[m].success} |"
        )
    md.append(f"\nHeld-out RMS before: {_rms(before):.3e} mm. Lay1..3 fixed (not identifiable).")
    summary_md = "\n".join(md)

    sidecar = {
        "robot": "delta",
        "columns": list(CSV_COLUMNS),
        "units": {"t_s": "s", "q_rad": "rad", "position": "mm", "frame": "base frame R0 (z up, plate below)"},
        "rows": {"calibration": [0, n_cal], "heldout": [n_cal, n_cal + n_val]},
        "nominal_geometry": {k: (list(v) if isinstance(v, tuple) else v) for k, v in NOMINAL_GEOMETRY.items()},
        "nominal_params": nominal.to_dict(),
        "parameter_table": [{"name": n, "index": i, "unit": u} for n, i, u in PARAMETER_TABLE],
        "declared_noise": {"position_mm": args.noise_mm, "joint_rad": args.noise_rad},
        "seed": args.seed,
        "q_columns": "measured joint readings (settled joint + noise)",
        "xyz_columns": "measured plate-centre position (settled + noise)",
    }
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for k in range(meas.t_s.size):
        w.writerow([repr(float(meas.t_s[k]))] + [repr(float(v)) for v in meas.q_meas[k]] + [repr(float(v)) for v in meas.positions_meas[k]])
    try:
        _write_text(paths["csv"], buf.getvalue(), args.overwrite)
        _write_text(paths["json"], json.dumps(sidecar, indent=2) + "\n", args.overwrite)
        _write_rrd(paths["rrd"], args.name, meas, gains, before, after, summary_md, args.overwrite)
        summary["wall_time_s"] = time.perf_counter() - t0
        if summary_path:
            _write_text(summary_path, json.dumps(summary, indent=2) + "\n", args.overwrite)
    except FileExistsError as exc:
        print(f"error: refusing to overwrite existing file {exc} (use --overwrite)", file=sys.stderr)
        return 1
    print(summary_md)
    print(f"wrote {paths['rrd']}, {paths['csv']}, {paths['json']}" + (f", {summary_path}" if summary_path else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
