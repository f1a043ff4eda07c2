"""Design optimal calibration poses for any registered robot and write them as a command file.

Usage::

    python -m pipeline.design --poses 10 [--robot hexapod|delta|...] [--criterion d|e]
        [--workspace full|default] [--seed 0] [--out designed_poses.csv] [--noise-mm 0.001]
        [--noise-rad 1e-6] [--noise-joint 0] [--candidates 3000] [--starts 1] [--workers N]
        [--scheduler ADDRESS] [--geometry ROBOT.json] [--summary-json FILE] [--rrd FILE] [--overwrite]

The command file is a CSV whose header comes from the robot: its pose coordinates with their
units, then its joints with theirs, e.g. ``x_mm,y_mm,z_mm,alpha_rad,beta_rad,gamma_rad,l1_mm,...,
l6_mm`` (hexapod) or ``x_mm,y_mm,z_mm,q1_rad,q2_rad,q3_rad`` (Delta): one row per target pose
and the joints the nominal controller commands for it (what the testbed or a real machine
runs). A JSON sidecar (same name, ``.json``) records the robot, its description, the criterion,
the workspace, the declared noise, the seed and the observability figures of the design. Files
are written atomically and never overwrite an existing file unless ``--overwrite`` is given.

The search (:func:`calib.design.design_poses`: a seeded draw of feasible candidates, then greedy
selection and exchange passes) finds a local optimum of its candidates. ``--starts K`` runs ``K``
independent searches, each on its own candidate draw, and keeps the best design by the criterion
(D: ``log det F``; E: ``lambda_min(F)``; a tie goes to the lower start). Start 0 draws with
``--seed`` (the single search's draw: ``--starts 1``, the default, writes what it always did),
start ``k > 0`` with ``SeedSequence(seed, spawn_key=(k,))``: a start's numbers depend on the seed
and ``k`` only, so the design is the same whatever runs it. The starts run as tasks of
:mod:`pipeline.executor` (a local Dask cluster of ``--workers`` processes, default the cores but
at most ``K``; ``--workers 1`` here; ``--scheduler ADDRESS`` an existing cluster). With ``K > 1``
the sidecar and the summary record the starts and each start's criterion value (``starts``).

Python use (e.g. for ``pipeline.run --design optimal``)::

    from pipeline.design import optimal_poses, read_command_file
    poses = optimal_poses(robot, 10, criterion="d", workspace="full", seed=0)  # (10, D)
    poses = optimal_poses(robot, 10, starts=4, workers=2)  # best of 4 searches, on 2 workers
    poses, joints = read_command_file("designed_poses.csv")  # robot found from the header
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.design import (CRITERIA, WORKSPACES, DesignResult, Workspace, design_poses, minimum_poses,
                          robot_workspace, sample_feasible_poses)
from calib.noise import SensorNoise
from calib.observability import analyze_observability, pose_uncertainty
from calib.robot import Robot, check_joint_limits
from calib.robots import ROBOTS, default_robot, reference_poses, robot_from_description
from pipeline.cli import ArgumentParser, cli_main, nonnegative_int, positive_int
from pipeline.execution import ProgressDisplay, run_tasks, worker_count
from pipeline.cli import add_executor_arguments
from pipeline.formats import check_outputs, atomic_write, sidecar_path

__all__ = [
    "DEFAULT_NOISE",
    "DEFAULT_CANDIDATES",
    "PROBE_POSES",
    "command_columns",
    "command_csv",
    "optimal_poses",
    "DesignSearch",
    "criterion_value",
    "design_search",
    "design_start",
    "start_seed",
    "write_command_file",
    "read_command_file",
    "load_robot",
    "add_noise_arguments",
    "noise_from_arguments",
    "position_columns",
    "main",
]

#: Declared noise the designs are weighted with by default: Gaussian, 1 um on positions,
#: 1e-6 rad on angles (standard deviations), exact joints.
DEFAULT_NOISE = SensorNoise(position_mm=0.001, orientation_rad=1e-6, distribution="normal")
#: Feasible candidate poses drawn for a design by default.
DEFAULT_CANDIDATES = 3000
#: Feasible poses drawn over the workspace to predict the pose uncertainty after calibration.
PROBE_POSES = 200


def command_columns(robot: Robot) -> tuple[str, ...]:
    """Header of the robot's command file: pose coordinates then joints, each ``name_unit``."""
    return tuple(f"{n}_{u}" for n, u in zip(robot.pose_names, robot.pose_units)) + \
        tuple(f"{n}_{robot.joint_unit}" for n in robot.joint_names)


def _workspace(robot: Robot, workspace: str | Workspace) -> Workspace:
    return workspace if isinstance(workspace, Workspace) else robot_workspace(robot, workspace)


def start_seed(seed: int, start: int) -> int | np.random.Generator:
    """The candidate draw of start ``start`` of a search seeded ``seed``: ``seed`` itself for start
    0 (a single search's draw), ``SeedSequence(seed, spawn_key=(start,))`` for the others."""
    if start == 0:
        return seed
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(int(start),)))


def design_start(job: dict) -> DesignResult:
    """One start of a design search (a task of :mod:`pipeline.executor`; plain data in).

    Args:
        job: ``robot`` (registered name), ``description`` (its ``Robot.description()``), ``theta``
            (P,), ``n``, ``workspace`` (:meth:`Workspace.to_dict`), ``noise``
            (:meth:`SensorNoise.to_dict`), ``free`` (names or None), ``criterion``, ``seed``,
            ``start``, ``n_candidates``.

    Returns:
        :func:`calib.design.design_poses` on the start's candidate draw (:func:`start_seed`).
    """
    robot = robot_from_description(job["robot"], job["description"])
    return design_poses(robot, np.asarray(job["theta"], dtype=float), job["n"], Workspace.from_dict(job["workspace"]),
                        SensorNoise(**job["noise"]), free=job["free"], criterion=job["criterion"],
                        seed=start_seed(job["seed"], job["start"]), n_candidates=job["n_candidates"])


@dataclass(frozen=True, eq=False)
class DesignSearch:
    """The starts of a design search and the best of them.

    Attributes:
        results: one :class:`calib.design.DesignResult` per start, in start order.
        best: the start whose design is kept (highest criterion value, the lower start on a tie).
    """

    results: tuple
    best: int

    @property
    def design(self) -> DesignResult:
        """The design kept."""
        return self.results[self.best]

    @property
    def values(self) -> list[float]:
        """Each start's criterion value: ``log det F`` (D) or ``lambda_min(F)`` (E), 1/mm^2."""
        return [criterion_value(r) for r in self.results]

    def to_dict(self, seed: int) -> dict:
        """JSON-ready record of the starts (for the sidecar and the summary)."""
        key = "log_det_fisher" if self.design.criterion == "d" else "lambda_min_fisher"
        return {"count": len(self.results), "best": self.best,
                "seeds": f"start 0: seed {seed}; start k > 0: SeedSequence({seed}, spawn_key=(k,))",
                "criterion": key, "values": self.values}


def criterion_value(result: DesignResult) -> float:
    """The value a design maximises: ``log det F`` (D-optimal) or ``lambda_min(F)`` (E-optimal)."""
    return result.log_det if result.criterion == "d" else result.lambda_min


def design_search(robot: Robot, theta, n: int, workspace: Workspace, noise: SensorNoise, *, free=None,
                  criterion: str = "d", seed: int = 0, n_candidates: int = DEFAULT_CANDIDATES, starts: int = 1,
                  workers: int | None = None, scheduler: str | None = None, client=None,
                  display: ProgressDisplay | None = None) -> DesignSearch:
    """``starts`` independent design searches (:func:`design_start`), the best kept.

    Args:
        robot, theta, n, workspace, noise, free, criterion, n_candidates: as
            :func:`calib.design.design_poses`.
        seed: the search's seed; start ``k`` draws its candidates from :func:`start_seed`.
        starts: independent searches (1: the single search of ``design_poses`` with ``seed``).
        workers: processes of the local Dask cluster (default the cores, at most ``starts``;
            1 runs here). ``scheduler``, ``client``: as :func:`pipeline.execution.run_tasks`.
        display: a :class:`pipeline.execution.ProgressDisplay` showing the starts done, however they run.

    Returns:
        The :class:`DesignSearch`; the same whatever runs it.
    """
    if isinstance(starts, bool) or not isinstance(starts, (int, np.integer)) or starts < 1:
        raise ValueError(f"starts must be an integer >= 1, got {starts!r}")
    workers = worker_count(workers)
    if scheduler is None and client is None:
        workers = min(int(starts), workers)
    base = {"robot": robot.name, "description": robot.description(), "theta": np.asarray(theta, dtype=float),
            "n": n, "workspace": workspace.to_dict(), "noise": noise.to_dict(),
            "free": None if free is None else list(free), "criterion": criterion, "seed": seed,
            "n_candidates": n_candidates}
    from pipeline.design import design_start as entry  # by name in the workers (also when run as __main__)

    results = [None] * int(starts)
    for k, r in run_tasks(entry, [{**base, "start": k} for k in range(int(starts))], workers=workers,
                          scheduler=scheduler, client=client, display=display):
        results[k] = r
    values = [criterion_value(r) for r in results]
    best = max(range(len(results)), key=lambda k: (values[k], -k))
    return DesignSearch(results=tuple(results), best=best)


def optimal_poses(robot: Robot, n: int, criterion: str = "d", workspace: str | Workspace = "full",
                  seed: int = 0, *, theta=None, noise: SensorNoise = DEFAULT_NOISE, free=None,
                  n_candidates: int = DEFAULT_CANDIDATES, starts: int = 1, workers: int | None = None,
                  scheduler: str | None = None, client=None) -> np.ndarray:
    """``n`` optimal calibration poses for a machine of the robot's nominal geometry.

    Args:
        robot: the robot (e.g. ``calib.robots.default_robot("hexapod")``).
        n: number of poses, at least :func:`calib.design.minimum_poses` (7 for the hexapod and
            the Delta).
        criterion: ``"d"`` (D-optimal) or ``"e"`` (E-optimal).
        workspace: ``"full"``, ``"default"`` or a :class:`~calib.design.Workspace`.
        seed: seed of the candidate draw (same seed, same poses).
        theta: (P,) parameter set to linearise at; default the nominal one (the errors are
            unknown before calibration).
        noise: declared noise weighting the pose coordinates.
        free: parameters to determine; default ``robot.free_default``.
        n_candidates: feasible candidates drawn (each start).
        starts: independent searches, the best kept (:func:`design_search`; 1: one search).
        workers, scheduler, client: where the starts run (:func:`design_search`).

    Returns:
        (n, D) target poses, the robot's pose units, base frame; all inside ``workspace``.
    """
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be a calib.robot.Robot, got {type(robot).__name__}")
    theta = robot.table.nominal if theta is None else theta
    return design_search(robot, theta, n, _workspace(robot, workspace), noise, free=free, criterion=criterion,
                         seed=seed, n_candidates=n_candidates, starts=starts, workers=workers,
                         scheduler=scheduler, client=client).design.poses


def _check_rows(robot: Robot, poses, joints) -> tuple[np.ndarray, np.ndarray]:
    poses = np.asarray(poses, dtype=float)
    joints = np.asarray(joints, dtype=float)
    if poses.ndim != 2 or poses.shape[1] != robot.pose_dim:
        raise ValueError(f"poses must have shape (N, {robot.pose_dim}), got {poses.shape}")
    if joints.shape != (poses.shape[0], robot.n_chains):
        raise ValueError(f"joints must have shape {(poses.shape[0], robot.n_chains)}, got {joints.shape}")
    return poses, joints


def command_csv(robot: Robot, poses, joints) -> str:
    """CSV text of a command file (full float64 precision)."""
    poses, joints = _check_rows(robot, poses, joints)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(command_columns(robot))
    for p, q in zip(poses, joints):
        w.writerow([repr(float(v)) for v in np.r_[p, q]])
    return buf.getvalue()


def write_command_file(path: str | os.PathLike, robot: Robot, poses, joints, meta: dict, *,
                       overwrite: bool = False) -> tuple[Path, Path]:
    """Write the CSV command file and its JSON sidecar (``path`` with suffix ``.json``).

    Args:
        path: CSV path.
        robot: the robot (gives the columns).
        poses: (N, D) target poses, the robot's pose units.
        joints: (N, C) commanded joints, the robot's joint unit.
        meta: JSON-ready metadata for the sidecar (``robot`` is added).
        overwrite: replace existing files.

    Returns:
        ``(csv_path, json_path)``.

    Raises:
        FileExistsError: a file exists and ``overwrite`` is False (nothing is written).
    """
    text = command_csv(robot, poses, joints)
    path = Path(path)
    side = sidecar_path(path)
    if side == path:
        raise ValueError(f"command file must not have a .json suffix, got {path}")
    for p in (path, side):
        if p.exists() and not overwrite:
            raise FileExistsError(f"{p} exists; pass --overwrite (overwrite=True) to replace it")
    atomic_write(side, json.dumps({"robot": robot.name, **meta}, indent=2) + "\n", overwrite=overwrite)
    atomic_write(path, text, overwrite=overwrite)
    return path, side


def _robot_of_header(path: Path, header: tuple) -> Robot:
    known = {name: default_robot(name) for name in sorted(ROBOTS)}
    for robot in known.values():
        if command_columns(robot) == header:
            return robot
    expected = "; ".join(f"{name}: {','.join(command_columns(r))}" for name, r in known.items())
    raise ValueError(f"{path}: line 1: header {','.join(header)} is no registered robot's (expected {expected})")


def read_command_file(path: str | os.PathLike, robot: Robot | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Read a command file.

    Args:
        path: CSV written by :func:`write_command_file` (or by hand, same header).
        robot: the robot whose columns the header must have; default: the registered robot
            whose columns it has.

    Returns:
        ``(poses, joints)``: (N, D) target poses, (N, C) commanded joints, the robot's units.

    Raises:
        ValueError: naming the file, and the row (line number) and column of a bad value, or
            the header.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"command file {path} not found")
    rows = list(csv.reader(path.read_text().splitlines()))
    if not rows:
        kinds = [robot] if robot is not None else [default_robot(name) for name in sorted(ROBOTS)]
        raise ValueError(f"{path}: empty command file, expected a header such as "
                         f"{'; '.join(','.join(command_columns(r)) for r in kinds)}")
    header = tuple(h.strip() for h in rows[0])
    if robot is None:
        robot = _robot_of_header(path, header)
    columns = command_columns(robot)
    if header != columns:
        raise ValueError(f"{path}: line 1: header must be {','.join(columns)} (the {robot.name}'s), "
                         f"got {','.join(header)}")
    data = []
    for line, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(columns):
            raise ValueError(f"{path}: line {line}: expected {len(columns)} columns, got {len(row)}")
        values = []
        for col, cell in zip(columns, row):
            try:
                v = float(cell)
            except ValueError:
                raise ValueError(f"{path}: line {line}, column {col}: not a number: {cell!r}") from None
            if not np.isfinite(v):
                raise ValueError(f"{path}: line {line}, column {col}: not finite: {cell!r}")
            values.append(v)
        data.append(values)
    if not data:
        raise ValueError(f"{path}: no data rows after the header")
    a = np.array(data, dtype=float)
    d = robot.pose_dim
    return a[:, :d].copy(), a[:, d:].copy()


def load_robot(name: str, geometry: str | None) -> Robot:
    """The registered robot ``name``: its default machine, or the nominal geometry of a
    ``Robot.description()`` JSON file. Raises ``SystemExit`` naming the option at fault."""
    if name not in ROBOTS:
        raise SystemExit(f"--robot: unknown robot {name!r}; registered robots are {', '.join(sorted(ROBOTS))}")
    if geometry is None:
        return default_robot(name)
    try:
        return robot_from_description(name, json.loads(Path(geometry).read_text()))
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise SystemExit(f"--geometry {geometry}: cannot read a {name} description: {exc}") from None


def add_noise_arguments(p: argparse.ArgumentParser) -> None:
    """``--noise-mm``, ``--noise-rad``, ``--noise-joint`` (Gaussian standard deviations)."""
    p.add_argument("--noise-mm", type=float, default=DEFAULT_NOISE.position_mm, help="position noise std, mm")
    p.add_argument("--noise-rad", type=float, default=DEFAULT_NOISE.orientation_rad,
                   help="angle noise std, rad (robots with angle coordinates)")
    p.add_argument("--noise-joint", type=float, default=DEFAULT_NOISE.joint,
                   help="joint-reading noise std, the robot's joint unit (default 0: exact joints)")


def noise_from_arguments(args) -> SensorNoise:
    """The Gaussian :class:`SensorNoise` of :func:`add_noise_arguments`' options."""
    try:
        return SensorNoise(args.noise_mm, args.noise_rad, "normal", args.noise_joint)
    except ValueError as exc:
        raise SystemExit(f"--noise-mm/--noise-rad/--noise-joint: {exc}") from None


def _parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m pipeline.design", description=__doc__.split("\n\n")[0])
    p.add_argument("--poses", type=int, required=True, help="number of poses to design (7 for hexapod and Delta)")
    p.add_argument("--robot", default="hexapod", help=f"registered robot: {', '.join(sorted(ROBOTS))}")
    p.add_argument("--criterion", choices=CRITERIA, default="d", help="d: D-optimal, e: E-optimal")
    p.add_argument("--workspace", choices=WORKSPACES, default="full",
                   help="full: the robot's whole feasible workspace; default: its calibration workspace")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the candidate draw")
    p.add_argument("--out", default="designed_poses.csv", help="command file (CSV); sidecar .json beside it")
    add_noise_arguments(p)
    p.add_argument("--candidates", type=int, default=DEFAULT_CANDIDATES,
                   help="feasible candidate poses drawn (each start)")
    p.add_argument("--starts", type=positive_int, default=1,
                   help="independent searches, each on its own candidate draw; the best design is kept")
    add_executor_arguments(p)
    p.add_argument("--geometry", default=None, help="robot description JSON (Robot.description()); "
                                                    "default the registered robot's default machine")
    p.add_argument("--summary-json", default=None)
    p.add_argument("--rrd", default=None)
    p.add_argument("--overwrite", action="store_true")
    return p


def main(argv: list[str] | None = None) -> int:
    """Run; a refused input, output or flag ends with one line on stderr and exit status 2."""
    return cli_main(_main, argv)


def _main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    robot = load_robot(args.robot, args.geometry)
    fewest = minimum_poses(robot)
    if args.poses < fewest:
        raise SystemExit(f"--poses must be >= {fewest} ({len(robot.free_default)} parameters, "
                         f"{robot.pose_dim} equations per pose), got {args.poses}")
    if args.candidates < args.poses:
        raise SystemExit(f"--candidates must be >= --poses ({args.poses}), got {args.candidates}")
    outs = [Path(args.out), sidecar_path(args.out)] + [Path(p) for p in (args.summary_json, args.rrd) if p]
    for p in outs:
        if p.exists() and not args.overwrite:
            raise SystemExit(f"{p} exists; pass --overwrite to replace it")
    check_outputs({"--out": args.out, "--out (sidecar)": str(sidecar_path(args.out)),
                   "--summary-json": args.summary_json, "--rrd": args.rrd}, overwrite=args.overwrite)
    noise = noise_from_arguments(args)
    theta = robot.table.nominal
    ws = robot_workspace(robot, args.workspace)
    each = f" in each of {args.starts} starts" if args.starts > 1 else ""
    print(f"designing {args.poses} {args.criterion.upper()}-optimal poses for the {robot.name} in its "
          f"{ws.name} workspace from {args.candidates} candidates{each} (seed {args.seed})...", file=sys.stderr)
    search = design_search(robot, theta, args.poses, ws, noise, criterion=args.criterion, seed=args.seed,
                           n_candidates=args.candidates, starts=args.starts, workers=args.workers,
                           scheduler=args.scheduler, display=ProgressDisplay("design search", unit="starts"))
    res = search.design
    if args.starts > 1:
        values = search.values
        name = "log det F" if args.criterion == "d" else "lambda_min(F)"
        print(f"best of {args.starts} starts: start {search.best}, {name} {values[search.best]:.6g} "
              f"(starts from {min(values):.6g} to {max(values):.6g})")
    joints = robot.inverse_kinematics(theta, res.poses)
    check_joint_limits(robot, joints, "designed pose")
    analysis = analyze_observability(robot, theta, res.poses, noise, joints=joints)
    published = reference_poses(robot) if args.geometry is None else None
    reference = analyze_observability(robot, theta, published, noise) if published is not None else None
    # Predicted pose uncertainty after calibration with these poses, anywhere in the workspace
    # (seeded feasible poses), for a controller compensating with the identified parameters.
    probe = sample_feasible_poses(robot, theta, ws, PROBE_POSES, [args.seed, 1])
    pu = pose_uncertainty(robot, theta, probe, analysis.parameter_covariance())
    uncertainty = {"probe_poses": int(probe.shape[0]),
                   "position_rms_um": {"mean": float(pu.position_rms_mm.mean() * 1e3),
                                       "max": float(pu.position_rms_mm.max() * 1e3)}}
    if robot.angle_pose_mask.any():
        uncertainty["orientation_rms_urad"] = {"mean": float(pu.orientation_rms_rad.mean() * 1e6),
                                               "max": float(pu.orientation_rms_rad.max() * 1e6)}
    columns = command_columns(robot)
    meta = {
        "kind": "calibration command file",
        "columns": list(columns),
        "units": "pose and joint units in the column names; joints are the nominal controller's commands",
        "robot_description": robot.description(),
        "criterion": args.criterion,
        "workspace": ws.to_dict(),
        "noise": noise.to_dict(),
        "seed": args.seed,
        "n_candidates": res.n_candidates,
        "log_det_fisher": res.log_det,
        "lambda_min_fisher": res.lambda_min,
        "observability": analysis.summary(),
    }
    if args.starts > 1:
        meta["starts"] = search.to_dict(args.seed)
    summary = {
        "command": "pipeline.design",
        "robot": robot.name,
        "out": str(args.out),
        "n_poses": args.poses,
        "criterion": args.criterion,
        "workspace": ws.to_dict(),
        "seed": args.seed,
        "noise": noise.to_dict(),
        "observability": analysis.summary(),
        "predicted_pose_uncertainty": uncertainty,
    }
    if args.starts > 1:
        summary["starts"] = meta["starts"]
    if reference is not None:
        summary["reference_poses_observability"] = reference.summary()
        summary["crb_rms_gain_vs_reference_poses"] = reference.crb_rms / analysis.crb_rms
    try:
        csv_path, side = write_command_file(args.out, robot, res.poses, joints, meta, overwrite=args.overwrite)
    except FileExistsError as exc:
        raise SystemExit(str(exc)) from None
    if args.summary_json:
        atomic_write(args.summary_json, json.dumps(summary, indent=2) + "\n", overwrite=args.overwrite)
    if args.rrd:
        _write_rrd(args.rrd, robot, analysis, reference, res.poses, (probe, pu.position_rms_mm), args.overwrite)
    gain = (f" ({summary['crb_rms_gain_vs_reference_poses']:.3g}x lower than with its "
            f"{len(published)} reference poses)" if reference is not None else "")
    print(f"wrote {csv_path} and {side}: condition number {analysis.scaled_condition_number:.4g} "
          f"(column-scaled), CRB parameter RMS {analysis.crb_rms:.4g} mm{gain}; predicted position error "
          f"after calibration {uncertainty['position_rms_um']['mean']:.3g} um RMS (mean over the workspace)")
    return 0


def position_columns(robot: Robot, poses: np.ndarray) -> np.ndarray:
    """(N, 3) the position (mm) coordinates of poses, for drawing."""
    return np.asarray(poses)[:, ~robot.angle_pose_mask][:, :3]


def _write_rrd(path: str, robot: Robot, analysis, reference, poses: np.ndarray, probe, overwrite: bool) -> None:
    import rerun as rr
    import rerun.blueprint as rrb

    from pipeline.views import log_observability, observability_views
    from pipeline.views import application_id, save_recording

    views = [observability_views("design/observability", "Designed poses", per_parameter=True)]
    if reference is not None:
        views.append(observability_views("reference_poses/observability", "Reference poses", per_parameter=True))
    bp = rrb.Blueprint(rrb.Horizontal(
        rrb.Vertical(
            rrb.Spatial3DView(origin="design/poses", name="Designed pose positions (mm)"),
            rrb.Spatial3DView(origin="design/pose_uncertainty",
                              name="Predicted position error RMS after calibration (radius, um)"),
        ), *views), collapse_panels=True)

    def log(rec):
        rec.log("design/poses", rr.Points3D(position_columns(robot, poses), radii=2.0), static=True)
        probe_poses, pos_rms = probe
        # Radius in mm drawn as the predicted RMS position error in um (1 um -> 1 mm sphere).
        rec.log("design/pose_uncertainty", rr.Points3D(position_columns(robot, probe_poses), radii=pos_rms * 1e3,
                                                      labels=[f"{v * 1e3:.2f} um" for v in pos_rms]), static=True)
        log_observability(rec, analysis, "design/observability", title=f"Designed poses ({robot.name})")
        if reference is not None:
            log_observability(rec, reference, "reference_poses/observability",
                              title=f"Reference poses ({robot.name})")

    try:
        save_recording(path, log, application_id=application_id("design", robot.name), overwrite=overwrite, bp=bp)
    except FileExistsError as exc:
        raise SystemExit(str(exc)) from None


if __name__ == "__main__":
    sys.exit(main())
