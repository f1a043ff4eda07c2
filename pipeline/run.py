"""``python -m pipeline.run``: calibrate a hexapod end to end.

Default scenario = the paper: Table 2 nominal geometry, Table 3 errors injected into the
simulated MuJoCo machine, Table 4 target poses, 50 extra held-out poses. The pipeline commands
the nominal leg lengths, measures, identifies, compensates, validates on the held-out poses,
prints a summary and writes ``<out>/<name>.rrd``, ``<out>/<name>.csv`` + ``.json`` and, if
asked, a summary JSON. ``--real FILE`` runs the same analysis on a recording file instead.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib import paper
from calib.hexapod import Hexapod, paper_hexapod
from calib.identification import IdentificationResult, identify_forward, identify_paper
from calib.kinematics import KinematicsError, forward_kinematics, inverse_kinematics
from calib.metrics import integrated_error
from calib.noise import SensorNoise
from calib.outliers import find_outliers
from calib.workspace import random_poses

__all__ = ["main", "build_parser", "RunOutput"]

DEFAULT_NAME = "hexapod_paper"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m pipeline.run",
        description="Calibrate a hexapod: simulate (MuJoCo) or read measurements, identify the 42 "
                    "geometric errors, compensate, validate on held-out poses, and write a Rerun "
                    "recording (.rrd), the measurements (.csv + .json) and a summary. Lengths in mm, "
                    "angles in rad.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--robot", choices=["hexapod", "delta"], default="hexapod",
                   help="robot to calibrate; 'delta' runs the Delta loop (see python -m pipeline.delta_run --help)")
    p.add_argument("--poses", default="paper",
                   help="calibration poses: 'paper' (the 10 poses of Table 4), a number N of poses "
                        "(see --design), or a command file written by python -m pipeline.design")
    p.add_argument("--design", choices=["random", "optimal"], default="random",
                   help="with --poses N: draw poses at random in the paper's workspace (+-10 mm, z 200..210 mm, "
                        "+-3 deg), or choose them D-optimally over the machine's whole workspace (calib.design)")
    p.add_argument("--heldout", type=int, default=50, help="held-out validation poses (same workspace)")
    p.add_argument("--noise-mm", type=float, default=paper.PAPER_NOISE_MM,
                   help="sensor noise on each position coordinate, mm (half-width if uniform, std if normal)")
    p.add_argument("--noise-rad", type=float, default=0.0,
                   help="sensor noise on each angle, rad (half-width if uniform, std if normal)")
    p.add_argument("--noise-dist", choices=["uniform", "normal"], default="uniform",
                   help="noise distribution; the paper's is uniform")
    p.add_argument("--seed", type=int, default=0, help="seed of poses and sensor noise")
    p.add_argument("--method", choices=["paper", "forward"], default="paper",
                   help="identification: the paper's per-leg least squares, or the forward method (LM, all 42)")
    p.add_argument("--gravity", action="store_true", help="simulate with gravity (default off)")
    p.add_argument("--payload-kg", type=float, default=0.0, help="payload on the platform, kg")
    p.add_argument("--stiffness", type=float, default=2e5, help="leg servo stiffness, N/m")
    p.add_argument("--friction", type=float, default=0.0, help="friction loss on each leg's slide, N")
    p.add_argument("--out", type=Path, default=Path("recordings"), help="output folder")
    p.add_argument("--name", default=None,
                   help=f"base name of the output files (default '{DEFAULT_NAME}', numbered if taken)")
    p.add_argument("--overwrite", action="store_true", help="allow replacing existing output files")
    p.add_argument("--summary-json", type=Path, default=None, help="write the summary as JSON to this path")
    p.add_argument("--real", type=Path, default=None,
                   help="analyse this recording (.csv with its .json sidecar) instead of simulating")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    return p


@dataclass
class RunOutput:
    """Everything a run produced (for tests and callers from Python)."""

    summary: dict
    result: IdentificationResult
    paths: dict


def _progress(enabled: bool):
    state = {"last": -1.0}

    def report(label: str, done: int, total: int) -> None:
        if not enabled:
            return
        frac = done / total
        if done == total or frac - state["last"] >= 0.25:
            state["last"] = frac if done < total else -1.0
            sys.stderr.write(f"  {label}: {done}/{total}\n")
            sys.stderr.flush()

    return report


def _free_name(out: Path, name: str | None, overwrite: bool) -> str:
    """The default name is numbered rather than overwritten; an explicit name is never changed."""
    if name is not None or overwrite:
        return name or DEFAULT_NAME
    base, k = DEFAULT_NAME, 1
    cand = base
    while any((out / f"{cand}{ext}").exists() for ext in (".rrd", ".csv", ".json")):
        k += 1
        cand = f"{base}_{k}"
    return cand


def _identify(method: str, nominal: Hexapod, commanded, measured, noise: SensorNoise) -> IdentificationResult:
    if method == "paper":
        return identify_paper(nominal, commanded, measured, epsilon=paper.PAPER_EPSILON)
    return identify_forward(nominal, commanded, measured, noise)


def _errors_stats(err: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pos = np.linalg.norm(err[:, :3], axis=1)
    ang = np.linalg.norm(err[:, 3:], axis=1)
    return pos, ang


def _heldout_block(before: np.ndarray, after: np.ndarray) -> dict:
    pb, ab = _errors_stats(before)
    pa, aa = _errors_stats(after)
    return {
        "heldout_position_error_mm": {"before": float(pb.mean()), "after": float(pa.mean()),
                                      "max_after": float(pa.max())},
        "heldout_orientation_error_rad": {"before": float(ab.mean()), "after": float(aa.mean()),
                                          "max_after": float(aa.max())},
    }


def _markdown(summary: dict) -> str:
    h = summary.get("heldout_position_error_mm")
    o = summary.get("heldout_orientation_error_rad")
    lines = [
        f"# Hexapod calibration: {summary['scenario']}",
        "",
        f"- method: **{summary['method']}**, {summary['calibration_poses']} calibration poses, "
        f"{summary['heldout_poses']} held-out",
        f"- declared noise: {summary['declared_noise']}",
        f"- iterations: {summary['iterations']} ({summary['message']})",
        f"- max dQint per iteration: {', '.join(f'{v:.3g}' for v in summary['max_dqint_history'])}",
    ]
    if h:
        lines += [
            "",
            "| held-out | before | after (mean) | after (max) |",
            "|---|---|---|---|",
            f"| position, um | {1e3 * h['before']:.3f} | {1e3 * h['after']:.3f} | {1e3 * h['max_after']:.3f} |",
            f"| orientation, urad | {1e6 * o['before']:.3f} | {1e6 * o['after']:.3f} | {1e6 * o['max_after']:.3f} |",
            "",
            f"Held-out basis: {summary['heldout_basis']}",
        ]
    if summary.get("parameter_error_rms_mm") is not None:
        lines.append(f"\nParameter error RMS (identified - injected): {1e3 * summary['parameter_error_rms_mm']:.3f} um")
    lines.append(f"\nCondition numbers of the identification Jacobians: "
                 f"{', '.join(f'{c:.0f}' for c in summary['condition_numbers'])}")
    fl = summary["flagged_poses"]
    lines.append(f"\nFlagged (outlier) poses: {', '.join(str(i) for i in fl) if fl else 'none'}")
    return "\n".join(lines)


def _print_summary(s: dict) -> None:
    print(f"Hexapod calibration - {s['scenario']}")
    print(f"  method {s['method']}: {s['iterations']} iterations; {s['message']}")
    print(f"  max dQint per iteration: {', '.join(f'{v:.3g}' for v in s['max_dqint_history'])}")
    h, o = s.get("heldout_position_error_mm"), s.get("heldout_orientation_error_rad")
    if h:
        print(f"  {'held-out (' + str(s['heldout_poses']) + ' poses)':<28}{'before':>12}{'after':>12}{'max after':>12}")
        print(f"  {'position error, um':<28}{1e3 * h['before']:>12.3f}{1e3 * h['after']:>12.3f}{1e3 * h['max_after']:>12.3f}")
        print(f"  {'orientation error, urad':<28}{1e6 * o['before']:>12.3f}{1e6 * o['after']:>12.3f}{1e6 * o['max_after']:>12.3f}")
        print(f"  improvement of mean position error: {h['before'] / h['after']:.1f}x  ({s['heldout_basis']})")
    if s.get("parameter_error_rms_mm") is not None:
        print(f"  parameter error RMS (identified - injected): {1e3 * s['parameter_error_rms_mm']:.3f} um")
    print(f"  condition numbers: {', '.join(f'{c:.0f}' for c in s['condition_numbers'])}")
    fl = s["flagged_poses"]
    print(f"  flagged poses: {', '.join(str(i) for i in fl) if fl else 'none'}")
    print(f"  wall time {s['wall_time_s']:.2f} s  (" + ", ".join(f"{k} {v:.2f} s" for k, v in s["wall_time_split_s"].items()) + ")")
    for k in ("rrd", "csv", "json"):
        if s.get(k):
            print(f"  wrote {s[k]}")


def _simulate(args, report):
    from mjcf.hexapod import HexapodModelOptions
    from pipeline.testbed import HexapodTestbed

    nominal, actual = paper_hexapod(), paper_hexapod(with_table3_errors=True)
    seeds = np.random.SeedSequence(args.seed).spawn(3)
    if args.poses == "paper":
        targets, scenario = paper.TABLE4_NOMINAL_POSES.copy(), "paper (Table 2 nominal, Table 3 injected, Table 4 poses)"
    elif args.poses.endswith(".csv"):
        from pipeline.design import read_command_file
        targets, _ = read_command_file(args.poses)
        scenario = f"{len(targets)} poses from {args.poses} (Table 2 nominal, Table 3 injected)"
    else:
        n = int(args.poses)
        if args.design == "optimal":
            from pipeline.design import optimal_poses
            targets = optimal_poses(nominal.geometry, n, seed=args.seed)
        else:
            targets = random_poses(n, np.random.default_rng(seeds[0]))
        scenario = f"{n} {args.design} poses (Table 2 nominal, Table 3 injected)"
    heldout = random_poses(args.heldout, np.random.default_rng(seeds[1]))
    noise = SensorNoise(args.noise_mm, args.noise_rad, args.noise_dist)
    options = HexapodModelOptions(gravity=args.gravity, payload_kg=args.payload_kg,
                                  actuator_stiffness=args.stiffness, joint_friction=args.friction)
    bed = HexapodTestbed(actual, options, noise, seed=int(seeds[2].generate_state(1)[0]))
    commanded = inverse_kinematics(nominal, targets)
    cal = bed.measure(commanded, progress=lambda d, t: report("measuring calibration poses", d, t))
    val = None
    if args.heldout:
        val = bed.measure(inverse_kinematics(nominal, heldout),
                          progress=lambda d, t: report("measuring held-out poses (nominal commands)", d, t))
    return dict(nominal=nominal, actual=actual, targets=targets, heldout=heldout, noise=noise,
                options=options, bed=bed, cal=cal, val=val, scenario=scenario)


def run(argv: list[str] | None = None) -> RunOutput:
    """Run the pipeline with command-line arguments ``argv``; see ``--help``."""
    args = build_parser().parse_args(argv)
    if args.heldout < 0:
        raise SystemExit("--heldout must be >= 0")
    if args.poses != "paper" and not args.poses.endswith(".csv"):
        try:
            if int(args.poses) < 7:
                raise ValueError
        except ValueError:
            raise SystemExit(f"--poses must be 'paper' or an integer >= 7, got {args.poses!r}") from None
    report = _progress(not args.quiet)
    t0 = time.perf_counter()
    split = {}
    from pipeline.recording import Recording, read_recording, write_recording

    if args.real is not None:
        rec = read_recording(args.real)
        nominal = Hexapod(rec.geometry)
        sim_truth = rec.meta.get("simulation", {}).get("injected_errors")
        actual = nominal.with_errors(np.asarray(sim_truth)) if sim_truth is not None else None
        commanded, measured = rec.subset("calibration")
        val_cmd, val_meas = rec.subset("validation")
        noise = rec.noise
        targets = forward_kinematics(nominal, commanded, initial=measured, stroke_mm=None)
        scenario = f"recording {args.real}"
        sim = None
    else:
        sim = _simulate(args, report)
        nominal, actual, noise = sim["nominal"], sim["actual"], sim["noise"]
        commanded, measured, targets = sim["cal"].commanded, sim["cal"].measured, sim["targets"]
        scenario = sim["scenario"]
    split["simulate"] = time.perf_counter() - t0

    # The measurements are written before any analysis, so that nothing is lost if it fails.
    out = args.out
    name = _free_name(out, args.name, args.overwrite)
    paths = {}
    if sim is not None:
        cal, val = sim["cal"], sim["val"]
        parts = [cal] + ([val] if val is not None else [])
        sim_meta = {"gravity": args.gravity, "payload_kg": args.payload_kg,
                    "stiffness_n_per_m": args.stiffness, "friction_n": args.friction}
        recording = Recording(
            geometry=nominal.geometry, noise=noise,
            t_s=np.concatenate([p.t_s for p in parts]),
            commanded=np.vstack([p.commanded for p in parts]),
            measured=np.vstack([p.measured for p in parts]),
            sets=np.array(["calibration"] * len(cal.t_s) + (["validation"] * len(val.t_s) if val is not None else [])),
            meta={"scenario": scenario, "seed": args.seed,
                  "simulation": {"injected_errors": actual.errors.tolist(), **sim_meta}},
        )
        csv_path, json_path = write_recording(out / f"{name}.csv", recording, overwrite=args.overwrite)
        paths.update(csv=str(csv_path), json=str(json_path))

    t1 = time.perf_counter()
    result = _identify(args.method, nominal, commanded, measured, noise)
    flagged = list(find_outliers(nominal, commanded, measured, noise).flagged) if len(measured) >= 8 else []
    predicted = forward_kinematics(result.hexapod, commanded, initial=measured, stroke_mm=None)
    split["identify"] = time.perf_counter() - t1

    heldout_before = heldout_after = None
    heldout_basis = None
    n_heldout = 0
    if sim is not None and sim["val"] is not None:
        t2 = time.perf_counter()
        bed, heldout = sim["bed"], sim["heldout"]
        try:
            compensated = inverse_kinematics(result.hexapod, heldout)
        except KinematicsError as exc:
            raise KinematicsError(
                f"the identified model cannot command the held-out poses ({exc}); its geometry is "
                "implausible: the measurements carry effects the geometric model lacks (gravity, "
                "payload, compliance; see python -m pipeline.discover)", exc.index) from exc
        after = bed.measure(compensated,
                            progress=lambda d, t: report("measuring held-out poses (compensated commands)", d, t))
        heldout_before = sim["val"].true_poses - heldout
        heldout_after = after.true_poses - heldout
        n_heldout = len(heldout)
        heldout_basis = ("simulated machine, compensated commands, noise-free settled poses "
                         "(before: nominal commands)")
        split["simulate"] += time.perf_counter() - t2
    elif sim is None and len(val_cmd):
        # A recording holds the validation poses measured under nominal commands only: the
        # identified model's prediction error there stands for the compensated error (equal to
        # first order), and includes the sensor noise.
        val_targets = forward_kinematics(nominal, val_cmd, initial=val_meas, stroke_mm=None)
        heldout_before = val_meas - val_targets
        heldout_after = val_meas - forward_kinematics(result.hexapod, val_cmd, initial=val_meas, stroke_mm=None)
        n_heldout = len(val_cmd)
        heldout_basis = "recorded validation rows: measured minus model prediction (includes sensor noise)"

    summary = {
        "robot": "hexapod",
        "scenario": scenario,
        "method": args.method,
        "calibration_poses": int(len(measured)),
        "heldout_poses": n_heldout,
        "declared_noise": noise.to_dict(),
        "seed": args.seed,
        "injected_errors": actual.errors.tolist() if actual is not None else None,
        "identified_errors": result.errors.tolist(),
        "identified_std_mm": result.std.reshape(6, 7).tolist(),
        "parameter_error_rms_mm": float(np.sqrt(np.mean((result.errors - actual.errors) ** 2))) if actual is not None else None,
        "iterations": result.iterations,
        "success": result.success,
        "message": result.message,
        "max_dqint_history": list(result.history) if args.method == "paper" else
            [float(integrated_error(result.pose_residuals)[2].max())],
        "condition_numbers": result.condition_numbers.tolist(),
        "flagged_poses": flagged,
        "heldout_basis": heldout_basis,
    }
    if heldout_before is not None:
        summary.update(_heldout_block(heldout_before, heldout_after))
    if sim is not None:
        summary["settle_steps_per_pose"] = {"mean": float(sim["cal"].steps.mean()), "max": int(sim["cal"].steps.max())}
        summary["simulation"] = sim_meta
        # How far the settled machine departs from its own kinematics (load, compliance...).
        dep = sim["cal"].true_poses - forward_kinematics(actual, commanded, initial=sim["cal"].true_poses)
        summary["kinematic_departure"] = {
            "position_mm": {"mean": float(np.linalg.norm(dep[:, :3], axis=1).mean()),
                            "max": float(np.linalg.norm(dep[:, :3], axis=1).max())},
            "orientation_rad": {"mean": float(np.linalg.norm(dep[:, 3:], axis=1).mean()),
                                "max": float(np.linalg.norm(dep[:, 3:], axis=1).max())},
        }

    t3 = time.perf_counter()
    from pipeline.rerun_log import log_calibration_run, save_recording

    from calib.observability import analyze_observability
    from pipeline.obs_log import log_observability

    analysis = analyze_observability(nominal, measured, noise)
    summary["observability"] = {"condition_number": float(analysis.condition_number),
                                "crb_std_mm": analysis.crb_std.tolist()}

    def log(rec):
        log_calibration_run(rec, nominal=nominal, actual=actual, identified=result.hexapod, targets=targets,
                            measured=measured, predicted=predicted, history=result.history,
                            heldout_before=heldout_before, heldout_after=heldout_after,
                            summary_markdown=_markdown(summary))
        log_observability(rec, analysis, "observability", title="Observability of the calibration poses")

    rrd = save_recording(out / f"{name}.rrd", log, overwrite=args.overwrite)
    paths["rrd"] = str(rrd)
    split["log"] = time.perf_counter() - t3
    summary.update(paths)
    summary["wall_time_s"] = time.perf_counter() - t0
    summary["wall_time_split_s"] = split
    if args.summary_json is not None:
        from pipeline.recording import atomic_write
        atomic_write(args.summary_json, json.dumps(summary, indent=1), overwrite=True)
        paths["summary_json"] = str(args.summary_json)
    if not args.quiet:
        _print_summary(summary)
    return RunOutput(summary=summary, result=result, paths=paths)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--robot" in argv and argv[argv.index("--robot") + 1:argv.index("--robot") + 2] == ["delta"]:
        i = argv.index("--robot")
        from pipeline import delta_run
        return delta_run.main(argv[:i] + argv[i + 2:])
    if "--robot=delta" in argv:
        from pipeline import delta_run
        return delta_run.main([a for a in argv if a != "--robot=delta"])
    try:
        run(argv)
    except (FileExistsError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
