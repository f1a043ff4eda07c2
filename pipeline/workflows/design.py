"""Design optimal calibration poses for any registered robot and write them as a command file
(:func:`run_design`; the command ``python -m pipeline.design``).

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
:mod:`pipeline.execution` (a local Dask cluster of ``--workers`` processes, default the cores but
at most ``K``; ``--workers 1`` here; ``--scheduler ADDRESS`` an existing cluster). With ``K > 1``
the sidecar and the summary record the starts and each start's criterion value (``starts``).

Python use (e.g. for ``pipeline.run --design optimal``)::

    from pipeline.formats import read_command_file
    from pipeline.workflows.design import optimal_poses
    poses = optimal_poses(robot, 10, criterion="d", workspace="full", seed=0)  # (10, D)
    poses = optimal_poses(robot, 10, starts=4, workers=2)  # best of 4 searches, on 2 workers
    poses, joints = read_command_file("designed_poses.csv")  # robot found from the header
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.design import (DesignResult, TooFewFeasiblePoses, Workspace, design_poses, minimum_poses,
                          robot_workspace, sample_feasible_poses)
from calib.noise import SensorNoise
from calib.observability import analyze_observability, pose_uncertainty
from calib.robot import Robot, check_joint_limits
from calib.robots import ROBOTS, default_robot, reference_poses, robot_from_description
from pipeline.execution import ProgressDisplay, run_tasks, worker_count
from pipeline.formats import FORMAT as RECORDING_FORMAT
from pipeline.formats import (RecordingError, atomic_write, check_outputs, command_columns, read_sidecar_geometry,
                              sidecar_path, write_command_file)

from .options import ToolOptions, check_noise_flags

__all__ = ["DEFAULT_NOISE", "DEFAULT_CANDIDATES", "PROBE_POSES", "optimal_poses", "DesignSearch", "criterion_value",
           "design_search", "design_start", "start_seed", "load_robot", "sidecar_robot", "DesignSettings",
           "DesignOutcome", "run_design", "check_design_settings", "predicted_uncertainty", "design_records"]

#: Declared noise the designs are weighted with by default: Gaussian, 1 um on positions,
#: 1e-6 rad on angles (standard deviations), exact joints.
DEFAULT_NOISE = SensorNoise(position_mm=0.001, orientation_rad=1e-6, distribution="normal")
#: Feasible candidate poses drawn for a design by default.
DEFAULT_CANDIDATES = 3000
#: Feasible poses drawn over the workspace to predict the pose uncertainty after calibration.
PROBE_POSES = 200


def _workspace(robot: Robot, workspace: str | Workspace) -> Workspace:
    return workspace if isinstance(workspace, Workspace) else robot_workspace(robot, workspace)


def start_seed(seed: int, start: int) -> int | np.random.Generator:
    """The candidate draw of start ``start`` of a search seeded ``seed``: ``seed`` itself for start
    0 (a single search's draw), ``SeedSequence(seed, spawn_key=(start,))`` for the others."""
    if start == 0:
        return seed
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(int(start),)))


def design_start(job: dict) -> DesignResult:
    """One start of a design search (a task of :mod:`pipeline.execution`; plain data in).

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
    from pipeline.workflows.design import design_start as entry  # by name in the workers (also when run as __main__)

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


def load_robot(name: str, geometry: str | None) -> tuple[Robot, str]:
    """``(robot, note)``: the registered robot ``name``'s default machine, or the nominal geometry
    of ``geometry``: a ``Robot.description()`` JSON file, or a recording's sidecar (its field
    ``nominal_geometry``, read as the recording reader reads it; ``note`` then says so, '' otherwise).

    Raises:
        ValueError: naming the option at fault (``--robot``, ``--geometry``).
    """
    if name not in ROBOTS:
        raise ValueError(f"--robot: unknown robot {name!r}; registered robots are {', '.join(sorted(ROBOTS))}")
    if geometry is None:
        return default_robot(name), ""
    try:
        description = json.loads(Path(geometry).read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"--geometry {geometry}: cannot read a {name} description: {exc}") from None
    if isinstance(description, dict) and description.get("format") == RECORDING_FORMAT:
        return sidecar_robot(name, geometry)
    try:
        return robot_from_description(name, description), ""
    except KeyError as exc:
        raise ValueError(f"--geometry {geometry}: not a {name} description (no key {exc.args[0]!r}; a description "
                         "is what Robot.description() writes, or a recording's sidecar)") from None
    except (ValueError, TypeError, IndexError, AttributeError) as exc:
        raise ValueError(f"--geometry {geometry}: cannot read a {name} description: {exc}") from None


def sidecar_robot(name: str, sidecar: str) -> tuple[Robot, str]:
    """``(robot, note)`` of a recording's sidecar given as ``--geometry``: its nominal geometry,
    read and checked as :func:`pipeline.formats.read_recording` does (its ``robot`` must be ``name``).

    Raises:
        ValueError: naming ``--geometry`` (and ``--robot`` when the sidecar is another robot's).
    """
    try:
        robot = read_sidecar_geometry(sidecar)
    except RecordingError as exc:
        raise ValueError(f"--geometry: {exc}") from None
    if robot.name != name:
        raise ValueError(f"--geometry {sidecar}: the sidecar of a {robot.name} recording, and --robot is {name}: "
                         f"give --robot {robot.name}")
    return robot, (f"--geometry {sidecar} is a recording's sidecar: read the {name} its field 'nominal_geometry' "
                   "describes")


@dataclass(frozen=True, kw_only=True)
class DesignSettings(ToolOptions):
    """What :func:`run_design` does (``python -m pipeline.design --help`` describes each field)."""

    poses: int
    robot: str = "hexapod"
    criterion: str = "d"
    workspace: str = "full"
    seed: int = 0
    out: str = "designed_poses.csv"
    noise: SensorNoise = DEFAULT_NOISE
    candidates: int = DEFAULT_CANDIDATES
    starts: int = 1


@dataclass
class DesignOutcome:
    """What :func:`run_design` made: the ``summary`` (as ``--summary-json``), the search, the
    observability of the designed poses (and of the reference poses, or None) and the paths
    written (``csv``, ``json``)."""

    summary: dict
    search: DesignSearch
    analysis: object
    reference: object
    paths: dict



def check_design_settings(settings: DesignSettings, robot: Robot) -> None:
    """Refuse, naming the flag, what cannot be designed or written, before any work.

    Raises:
        ValueError: too few poses or candidates, an output that cannot be written;
        FileExistsError: an output exists and ``overwrite`` is off.
    """
    check_noise_flags(robot, settings.noise)
    fewest = minimum_poses(robot)
    if settings.poses < fewest:
        raise ValueError(f"--poses must be >= {fewest} ({len(robot.free_default)} parameters, "
                         f"{robot.pose_dim} equations per pose), got {settings.poses}")
    if settings.candidates < settings.poses:
        raise ValueError(f"--candidates must be >= --poses ({settings.poses}), got {settings.candidates}")
    check_outputs({"--out": settings.out, "--out (sidecar)": str(sidecar_path(settings.out)),
                   "--summary-json": settings.summary_json, "--rrd": settings.rrd}, overwrite=settings.overwrite)


def predicted_uncertainty(robot: Robot, theta, ws: Workspace, analysis, seed: int):
    """Predicted pose uncertainty after calibration with the designed poses, anywhere in the
    workspace (:data:`PROBE_POSES` seeded feasible poses), for a controller compensating with the
    identified parameters: ``(probe (M, D), pose_uncertainty, summary dict in um / urad)``."""
    probe = sample_feasible_poses(robot, theta, ws, PROBE_POSES, [seed, 1])
    pu = pose_uncertainty(robot, theta, probe, analysis.parameter_covariance())
    uncertainty = {"probe_poses": int(probe.shape[0]),
                   "position_rms_um": {"mean": float(pu.position_rms_mm.mean() * 1e3),
                                       "max": float(pu.position_rms_mm.max() * 1e3)}}
    if robot.angle_pose_mask.any():
        uncertainty["orientation_rms_urad"] = {"mean": float(pu.orientation_rms_rad.mean() * 1e6),
                                               "max": float(pu.orientation_rms_rad.max() * 1e6)}
    return probe, pu, uncertainty


def design_records(settings: DesignSettings, robot: Robot, ws: Workspace, search: DesignSearch, analysis,
                   reference, uncertainty: dict) -> tuple[dict, dict]:
    """``(sidecar meta, summary)`` of a design."""
    res, noise = search.design, settings.noise
    meta = {
        "kind": "calibration command file",
        "columns": list(command_columns(robot)),
        "units": "pose and joint units in the column names; joints are the nominal controller's commands",
        "robot_description": robot.description(),
        "criterion": settings.criterion,
        "workspace": ws.to_dict(),
        "noise": noise.to_dict(),
        "seed": settings.seed,
        "n_candidates": res.n_candidates,
        "log_det_fisher": res.log_det,
        "lambda_min_fisher": res.lambda_min,
        "observability": analysis.summary(),
    }
    summary = {
        "command": "pipeline.design",
        "robot": robot.name,
        "out": str(settings.out),
        "n_poses": settings.poses,
        "criterion": settings.criterion,
        "workspace": ws.to_dict(),
        "seed": settings.seed,
        "noise": noise.to_dict(),
        "observability": analysis.summary(),
        "predicted_pose_uncertainty": uncertainty,
    }
    if settings.starts > 1:
        meta["starts"] = search.to_dict(settings.seed)
        summary["starts"] = meta["starts"]
    if reference is not None:
        summary["reference_poses_observability"] = reference.summary()
        summary["crb_rms_gain_vs_reference_poses"] = reference.crb_rms / analysis.crb_rms
    return meta, summary


def run_design(settings: DesignSettings, display=None, announce=None) -> DesignOutcome:
    """Design ``settings.poses`` optimal poses, write the command file (and the summary JSON and
    the ``.rrd`` where asked); ``display`` shows the search's progress (a
    :class:`pipeline.execution.ProgressDisplay`, or None); ``announce(robot, workspace, note)`` is
    called once the settings are accepted, before the search, with the note of a recording's sidecar
    read as ``--geometry`` (:func:`load_robot`; '' otherwise); the summary keeps it (``geometry_note``).

    Raises:
        ValueError: a refused setting (the message names the flag); FileExistsError: an output
            exists and ``overwrite`` is off.
    """
    robot, note = load_robot(settings.robot, settings.geometry)
    check_design_settings(settings, robot)
    theta = robot.table.nominal
    ws = robot_workspace(robot, settings.workspace)
    if announce is not None:
        announce(robot, ws, note)
    try:
        search = design_search(robot, theta, settings.poses, ws, settings.noise, criterion=settings.criterion,
                               seed=settings.seed, n_candidates=settings.candidates, starts=settings.starts,
                               workers=settings.workers, scheduler=settings.scheduler, display=display)
    except TooFewFeasiblePoses as exc:
        raise ValueError(f"--candidates {settings.candidates}: {exc}") from None
    poses = search.design.poses
    joints = robot.inverse_kinematics(theta, poses)
    check_joint_limits(robot, joints, "designed pose")
    analysis = analyze_observability(robot, theta, poses, settings.noise, joints=joints)
    published = reference_poses(robot) if settings.geometry is None else None
    reference = analyze_observability(robot, theta, published, settings.noise) if published is not None else None
    probe, pu, uncertainty = predicted_uncertainty(robot, theta, ws, analysis, settings.seed)
    meta, summary = design_records(settings, robot, ws, search, analysis, reference, uncertainty)
    if note:
        summary["geometry_note"] = note
    csv_path, side = write_command_file(settings.out, robot, poses, joints, meta, overwrite=settings.overwrite)
    if settings.summary_json:
        atomic_write(settings.summary_json, json.dumps(summary, indent=2) + "\n", overwrite=settings.overwrite)
    if settings.rrd:
        from pipeline.views import write_design_rrd

        write_design_rrd(settings.rrd, robot, analysis, reference, poses, (probe, pu.position_rms_mm),
                         settings.overwrite)
    return DesignOutcome(summary=summary, search=search, analysis=analysis, reference=reference,
                         paths={"csv": str(csv_path), "json": str(side)})
