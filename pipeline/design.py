"""``python -m pipeline.design --poses N``: design optimal calibration poses and write them as a
command file.

Usage::

    python -m pipeline.design --poses 10 [--robot hexapod|delta|...] [--criterion d|e]
        [--workspace full|default] [--seed 0] [--out designed_poses.csv] [--noise-mm 0.001]
        [--noise-rad 1e-6] [--noise-joint 0] [--candidates 3000] [--starts 1] [--workers N]
        [--scheduler ADDRESS] [--geometry ROBOT.json] [--summary-json FILE] [--rrd FILE] [--overwrite]

A thin front end of :func:`pipeline.workflows.design.run_design` (which says what the search and
the files are): parse the flags, call it, print the result (stdout; the announcement and progress
on stderr).
"""

from __future__ import annotations

import argparse
import sys

from calib.design import CRITERIA, WORKSPACES
from calib.robots import ROBOTS
from pipeline.cli import (ArgumentParser, add_executor_arguments, add_noise_arguments, cli_main, noise_from_arguments,
                          nonnegative_int, positive_int)
from pipeline.execution import ProgressDisplay
from pipeline.workflows.design import DEFAULT_CANDIDATES, DesignOutcome, DesignSettings, run_design

__all__ = ["build_parser", "settings_from_args", "run", "main"]


def build_parser() -> argparse.ArgumentParser:
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


def settings_from_args(args: argparse.Namespace) -> DesignSettings:
    """The :class:`DesignSettings` of parsed flags."""
    return DesignSettings(poses=args.poses, robot=args.robot, criterion=args.criterion, workspace=args.workspace,
                          seed=args.seed, out=args.out, noise=noise_from_arguments(args), candidates=args.candidates,
                          starts=args.starts, workers=args.workers, scheduler=args.scheduler, geometry=args.geometry,
                          summary_json=args.summary_json, rrd=args.rrd, overwrite=args.overwrite)


def run(argv: list[str] | None = None) -> DesignOutcome:
    """Parse ``argv``, design, print the result; raises on bad input (see :func:`main`)."""
    settings = settings_from_args(build_parser().parse_args(argv))
    each = f" in each of {settings.starts} starts" if settings.starts > 1 else ""

    def announce(robot, ws, note):
        if note:
            print(note, file=sys.stderr)
        print(f"designing {settings.poses} {settings.criterion.upper()}-optimal poses for the {robot.name} in its "
              f"{ws.name} workspace from {settings.candidates} candidates{each} (seed {settings.seed})...",
              file=sys.stderr)

    outcome = run_design(settings, display=ProgressDisplay("design search", unit="starts"), announce=announce)
    search, summary, analysis = outcome.search, outcome.summary, outcome.analysis
    if settings.starts > 1:
        values = search.values
        name = "log det F" if settings.criterion == "d" else "lambda_min(F)"
        print(f"best of {settings.starts} starts: start {search.best}, {name} {values[search.best]:.6g} "
              f"(starts from {min(values):.6g} to {max(values):.6g})")
    reference = outcome.reference
    gain = (f" ({summary['crb_rms_gain_vs_reference_poses']:.3g}x lower than with its "
            f"{reference.n_poses} reference poses)" if reference is not None else "")
    uncertainty = summary["predicted_pose_uncertainty"]
    print(f"wrote {outcome.paths['csv']} and {outcome.paths['json']}: condition number "
          f"{analysis.scaled_condition_number:.4g} (column-scaled), CRB parameter RMS {analysis.crb_rms:.4g} mm{gain}; "
          f"predicted position error after calibration {uncertainty['position_rms_um']['mean']:.3g} um RMS (mean over "
          "the workspace)")
    return outcome


def main(argv: list[str] | None = None) -> int:
    """Run; a refused input, output or flag ends with one line on stderr and exit status 2."""
    return cli_main(run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
