"""Design optimal calibration poses and write them as a command file.

Usage::

    python -m pipeline.design --poses 10 [--criterion d|e] [--workspace full|paper]
        [--seed 0] [--out designed_poses.csv] [--noise-mm 0.001] [--noise-rad 1e-6]
        [--candidates 3000] [--geometry GEOMETRY.json] [--summary-json FILE] [--rrd FILE]
        [--overwrite]

The command file is a CSV with the header
``x_mm,y_mm,z_mm,alpha_rad,beta_rad,gamma_rad,l1_mm,...,l6_mm``: one row per target pose and
the leg lengths the nominal controller commands for it (what the testbed or a real machine
runs). A JSON sidecar (same name, ``.json``) records the geometry, the criterion, the
workspace, the declared noise, the seed and the observability figures of the design. Files are
written atomically and never overwrite an existing file unless ``--overwrite`` is given.

Python use (for ``pipeline.run --design optimal``)::

    from pipeline.design import optimal_poses
    poses = optimal_poses(geometry, 10, criterion="d", workspace="full", seed=0)  # (10, 6)
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import sys
from pathlib import Path

import numpy as np

from calib.design import CRITERIA, Workspace, design_poses, sample_feasible_poses, workspace_by_name
from calib.hexapod import Hexapod, HexapodGeometry, paper_geometry
from calib.kinematics import inverse_kinematics
from calib.noise import SensorNoise
from calib.observability import analyze_observability, pose_uncertainty
from calib import paper
from pipeline.recording import atomic_write

__all__ = [
    "COMMAND_COLUMNS",
    "DEFAULT_NOISE",
    "optimal_poses",
    "write_command_file",
    "read_command_file",
    "main",
]

#: Header of a command file: target pose (mm, rad) and nominal commanded leg lengths (mm).
COMMAND_COLUMNS = ("x_mm", "y_mm", "z_mm", "alpha_rad", "beta_rad", "gamma_rad",
                   "l1_mm", "l2_mm", "l3_mm", "l4_mm", "l5_mm", "l6_mm")
#: Declared noise the designs are weighted with by default: Gaussian, 1 um on positions,
#: 1e-6 rad on angles (standard deviations).
DEFAULT_NOISE = SensorNoise(position_mm=0.001, orientation_rad=1e-6, distribution="normal")


def _workspace(workspace: str | Workspace) -> Workspace:
    if isinstance(workspace, Workspace):
        return workspace
    return workspace_by_name(workspace)


def optimal_poses(
    geometry: HexapodGeometry,
    n: int,
    criterion: str = "d",
    workspace: str | Workspace = "full",
    seed: int = 0,
    *,
    noise: SensorNoise = DEFAULT_NOISE,
    n_candidates: int = 3000,
) -> np.ndarray:
    """``n`` optimal calibration poses for a machine of nominal ``geometry``.

    Args:
        geometry: nominal geometry (the design is linearised at zero errors).
        n: number of poses, >= 7.
        criterion: ``"d"`` (D-optimal) or ``"e"`` (E-optimal).
        workspace: ``"full"``, ``"paper"`` or a :class:`~calib.design.Workspace`.
        seed: seed of the candidate draw (same seed, same poses).
        noise: declared sensor noise weighting mm against rad.
        n_candidates: feasible candidates drawn.

    Returns:
        (n, 6) target poses, mm and rad, base frame; all inside ``workspace``.
    """
    if not isinstance(geometry, HexapodGeometry):
        raise TypeError(f"geometry must be a HexapodGeometry, got {type(geometry).__name__}")
    return design_poses(Hexapod(geometry), n, _workspace(workspace), noise, criterion=criterion,
                        seed=seed, n_candidates=n_candidates).poses


def command_csv(poses: np.ndarray, lengths: np.ndarray) -> str:
    """CSV text of a command file (full float64 precision)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COMMAND_COLUMNS)
    for p, l in zip(poses, lengths):
        w.writerow([repr(float(v)) for v in np.r_[p, l]])
    return buf.getvalue()


def write_command_file(path: str | os.PathLike, poses: np.ndarray, lengths: np.ndarray, meta: dict,
                       *, overwrite: bool = False) -> tuple[Path, Path]:
    """Write the CSV command file and its JSON sidecar (``path`` with suffix ``.json``).

    Args:
        path: CSV path.
        poses: (N, 6) target poses, mm and rad.
        lengths: (N, 6) commanded leg lengths, mm.
        meta: JSON-ready metadata for the sidecar.
        overwrite: replace existing files.

    Returns:
        ``(csv_path, json_path)``.

    Raises:
        FileExistsError: a file exists and ``overwrite`` is False (nothing is written).
    """
    poses = np.asarray(poses, dtype=float)
    lengths = np.asarray(lengths, dtype=float)
    if poses.ndim != 2 or poses.shape[1] != 6:
        raise ValueError(f"poses must have shape (N, 6), got {poses.shape}")
    if lengths.shape != poses.shape:
        raise ValueError(f"lengths must have shape {poses.shape}, got {lengths.shape}")
    path = Path(path)
    side = path.with_suffix(".json")
    if side == path:
        raise ValueError(f"command file must not have a .json suffix, got {path}")
    for p in (path, side):
        if p.exists() and not overwrite:
            raise FileExistsError(f"{p} exists; pass --overwrite (overwrite=True) to replace it")
    atomic_write(side, json.dumps(meta, indent=2) + "\n", overwrite=overwrite)
    atomic_write(path, command_csv(poses, lengths), overwrite=overwrite)
    return path, side


def read_command_file(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a command file.

    Args:
        path: CSV written by :func:`write_command_file` (or by hand, same header).

    Returns:
        ``(poses, lengths)``: (N, 6) target poses in mm and rad, (N, 6) commanded lengths in mm.

    Raises:
        ValueError: naming the file, and the row (line number) and column of a bad value, or
            the header or the missing columns.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"command file {path} not found")
    rows = list(csv.reader(path.read_text().splitlines()))
    if not rows:
        raise ValueError(f"{path}: empty command file, expected the header {','.join(COMMAND_COLUMNS)}")
    header = [h.strip() for h in rows[0]]
    if tuple(header) != COMMAND_COLUMNS:
        raise ValueError(f"{path}: line 1: header must be {','.join(COMMAND_COLUMNS)}, got {','.join(header)}")
    data = []
    for line, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(COMMAND_COLUMNS):
            raise ValueError(f"{path}: line {line}: expected {len(COMMAND_COLUMNS)} columns, got {len(row)}")
        vals = []
        for col, cell in zip(COMMAND_COLUMNS, row):
            try:
                v = float(cell)
            except ValueError:
                raise ValueError(f"{path}: line {line}, column {col}: not a number: {cell!r}") from None
            if not np.isfinite(v):
                raise ValueError(f"{path}: line {line}, column {col}: not finite: {cell!r}")
            vals.append(v)
        data.append(vals)
    if not data:
        raise ValueError(f"{path}: no data rows after the header")
    a = np.array(data, dtype=float)
    return a[:, :6].copy(), a[:, 6:].copy()


def _load_geometry(path: str | None) -> HexapodGeometry:
    if path is None:
        return paper_geometry()
    try:
        return HexapodGeometry.from_dict(json.loads(Path(path).read_text()))
    except (OSError, KeyError, ValueError) as exc:
        raise SystemExit(f"--geometry {path}: cannot read a geometry: {exc}") from None


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m pipeline.design", description=__doc__.split("\n\n")[0])
    p.add_argument("--poses", type=int, required=True, help="number of poses to design (>= 7)")
    p.add_argument("--criterion", choices=CRITERIA, default="d", help="d: D-optimal, e: E-optimal")
    p.add_argument("--workspace", choices=("full", "paper"), default="full")
    p.add_argument("--seed", type=int, default=0, help="seed of the candidate draw")
    p.add_argument("--out", default="designed_poses.csv", help="command file (CSV); sidecar .json beside it")
    p.add_argument("--noise-mm", type=float, default=DEFAULT_NOISE.position_mm, help="position noise std, mm")
    p.add_argument("--noise-rad", type=float, default=DEFAULT_NOISE.orientation_rad, help="angle noise std, rad")
    p.add_argument("--candidates", type=int, default=3000, help="feasible candidate poses drawn")
    p.add_argument("--geometry", default=None, help="geometry JSON (HexapodGeometry.to_dict); default the paper's")
    p.add_argument("--summary-json", default=None)
    p.add_argument("--rrd", default=None)
    p.add_argument("--overwrite", action="store_true")
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.poses < 7:
        raise SystemExit(f"--poses must be >= 7 (42 parameters, 6 equations per pose), got {args.poses}")
    outs = [Path(args.out), Path(args.out).with_suffix(".json")]
    outs += [Path(p) for p in (args.summary_json, args.rrd) if p]
    for p in outs:
        if p.exists() and not args.overwrite:
            raise SystemExit(f"{p} exists; pass --overwrite to replace it")
    try:
        noise = SensorNoise(args.noise_mm, args.noise_rad, "normal")
    except ValueError as exc:
        raise SystemExit(f"--noise-mm/--noise-rad: {exc}") from None
    geometry = _load_geometry(args.geometry)
    nominal = Hexapod(geometry)
    ws = workspace_by_name(args.workspace)
    print(f"designing {args.poses} {args.criterion.upper()}-optimal poses in the {ws.name} workspace "
          f"from {args.candidates} candidates (seed {args.seed})...", file=sys.stderr)
    res = design_poses(nominal, args.poses, ws, noise, criterion=args.criterion, seed=args.seed,
                       n_candidates=args.candidates)
    lengths = inverse_kinematics(nominal, res.poses, stroke_mm=ws.stroke_mm)
    analysis = analyze_observability(nominal, res.poses, noise)
    reference = analyze_observability(nominal, paper.TABLE4_NOMINAL_POSES, noise) \
        if args.geometry is None else None
    # Predicted pose uncertainty after calibration with these poses, anywhere in the workspace
    # (200 seeded feasible poses), for a controller compensating with the identified errors.
    probe = sample_feasible_poses(nominal, ws, 200, [args.seed, 1])
    pu = pose_uncertainty(nominal, probe, analysis.crb)
    uncertainty = {
        "probe_poses": int(probe.shape[0]),
        "position_rms_um": {"mean": float(pu.position_rms_mm.mean() * 1e3),
                            "max": float(pu.position_rms_mm.max() * 1e3)},
        "orientation_rms_urad": {"mean": float(pu.orientation_rms_rad.mean() * 1e6),
                                 "max": float(pu.orientation_rms_rad.max() * 1e6)},
    }
    meta = {
        "kind": "hexapod calibration command file",
        "columns": list(COMMAND_COLUMNS),
        "units": "mm and rad; lengths are the nominal controller's commanded leg lengths",
        "geometry": geometry.to_dict(),
        "criterion": args.criterion,
        "workspace": ws.to_dict(),
        "noise": noise.to_dict(),
        "seed": args.seed,
        "n_candidates": res.n_candidates,
        "log_det_fisher": res.log_det,
        "lambda_min_fisher": res.lambda_min,
        "observability": analysis.summary(),
    }
    summary = {
        "command": "pipeline.design",
        "out": str(args.out),
        "n_poses": args.poses,
        "criterion": args.criterion,
        "workspace": ws.to_dict(),
        "seed": args.seed,
        "noise": noise.to_dict(),
        "observability": analysis.summary(),
        "predicted_pose_uncertainty": uncertainty,
    }
    if reference is not None:
        summary["paper_poses_observability"] = reference.summary()
        summary["crb_rms_gain_vs_paper_poses"] = reference.crb_rms / analysis.crb_rms
    try:
        csv_path, side = write_command_file(args.out, res.poses, lengths, meta, overwrite=args.overwrite)
    except FileExistsError as exc:
        raise SystemExit(str(exc)) from None
    if args.summary_json:
        atomic_write(args.summary_json, json.dumps(summary, indent=2) + "\n", overwrite=args.overwrite)
    if args.rrd:
        _write_rrd(args.rrd, analysis, reference, res.poses, (probe, pu.position_rms_mm), args.overwrite)
    gain = (f" ({summary['crb_rms_gain_vs_paper_poses']:.3g}x lower than with the paper's 10 poses)"
            if reference is not None else "")
    print(f"wrote {csv_path} and {side}: condition number {analysis.scaled_condition_number:.4g} "
          f"(column-scaled), CRB parameter RMS {analysis.crb_rms:.4g} mm{gain}; predicted position error "
          f"after calibration {uncertainty['position_rms_um']['mean']:.3g} um RMS (mean over the workspace)",
          file=sys.stderr)
    return 0


def _write_rrd(path: str, analysis, reference, poses: np.ndarray, probe, overwrite: bool) -> None:
    import rerun as rr
    import rerun.blueprint as rrb

    from pipeline.obs_log import log_observability, observability_views
    from pipeline.rerun_log import save_recording

    views = [observability_views("design/observability", "Designed poses")]
    if reference is not None:
        views.append(observability_views("paper_poses/observability", "Paper's poses"))
    bp = rrb.Blueprint(rrb.Vertical(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="design/poses", name="Designed pose positions (mm)"),
            rrb.Spatial3DView(origin="design/pose_uncertainty",
                              name="Predicted position error RMS after calibration (radius, um)"),
        ), *views))

    def log(rec):
        rec.log("design/poses", rr.Points3D(poses[:, :3], radii=2.0), static=True)
        probe_poses, pos_rms = probe
        # Radius in mm drawn as the predicted RMS position error in um (1 um -> 1 mm sphere).
        rec.log("design/pose_uncertainty", rr.Points3D(probe_poses[:, :3], radii=pos_rms * 1e3,
                                                      labels=[f"{v * 1e3:.2f} um" for v in pos_rms]), static=True)
        log_observability(rec, analysis, "design/observability", title="Designed poses")
        if reference is not None:
            log_observability(rec, reference, "paper_poses/observability", title="Paper's 10 poses")

    try:
        save_recording(path, log, application_id="parallel-calib-design", overwrite=overwrite, bp=bp)
    except FileExistsError as exc:
        raise SystemExit(str(exc)) from None

if __name__ == "__main__":
    sys.exit(main())
