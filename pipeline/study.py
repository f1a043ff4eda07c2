"""``python -m pipeline.study --trials 200``: Monte Carlo study of the whole calibration loop,
errors against the Cramer-Rao bound.

Usage::

    python -m pipeline.study --trials 200 [--robot hexapod|delta|...] [--noise-mm 0.001]
        [--noise-rad 1e-6] [--noise-joint 0] [--poses designed|reference|random|FILE.csv]
        [--n-poses 10] [--workspace full|default] [--criterion d|e]
        [--method forward|chainwise|both] [--errors reference|random] [--error-mm 0.05]
        [--error-rad 0.001] [--heldout 100] [--seed 0] [--workers 2] [--scheduler ADDRESS] [--geometry ROBOT.json]
        [--summary-json FILE] [--rrd FILE] [--overwrite]

A thin front end of :func:`pipeline.workflows.study.run_study` (which says what a trial is and
what is reported): parse the flags, call it, print one line a method (stdout; progress on stderr).
"""

from __future__ import annotations

import argparse

from calib.design import CRITERIA, WORKSPACES
from calib.engine import METHODS
from calib.robots import ROBOTS
from pipeline.cli import (ArgumentParser, add_executor_arguments, add_noise_arguments, cli_main, noise_from_arguments,
                          nonnegative_int)
from pipeline.execution import ProgressDisplay
from pipeline.workflows.study import (DEFAULT_ERROR_MM, DEFAULT_ERROR_RAD, ERROR_KINDS, StudyOutcome, StudySettings,
                                      run_study)

__all__ = ["build_parser", "settings_from_args", "run", "main"]


def build_parser() -> argparse.ArgumentParser:
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


def settings_from_args(args: argparse.Namespace) -> StudySettings:
    """The :class:`StudySettings` of parsed flags."""
    return StudySettings(robot=args.robot, trials=args.trials, noise=noise_from_arguments(args), poses=args.poses,
                         n_poses=args.n_poses, workspace=args.workspace, criterion=args.criterion, method=args.method,
                         errors=args.errors, error_mm=args.error_mm, error_rad=args.error_rad, heldout=args.heldout,
                         seed=args.seed, workers=args.workers, scheduler=args.scheduler, geometry=args.geometry,
                         summary_json=args.summary_json, rrd=args.rrd, overwrite=args.overwrite)


def run(argv: list[str] | None = None) -> StudyOutcome:
    """Parse ``argv``, run the study, print one line a method; raises on bad input (see :func:`main`)."""
    outcome = run_study(settings_from_args(build_parser().parse_args(argv)), display=ProgressDisplay("study"))
    predicted = outcome.predicted_heldout_mm
    if "geometry_note" in outcome.summary:
        print(outcome.summary["geometry_note"])
    for m, f in outcome.figures.items():
        held = f["heldout_position_mm"]
        print(f"{m}: parameter error RMS {f['parameter_error_rms_mm']:.4g} mm (CRB {outcome.crb_rms_mm:.4g} mm); "
              f"MSE/CRB per parameter {f['mse_over_crb_min']:.3f}..{f['mse_over_crb_max']:.3f} "
              f"(mean {f['mse_over_crb_mean']:.3f})"
              + (f"; held-out position error mean {held['mean'] * 1e3:.4g} um, RMS {held['rms'] * 1e3:.4g} um"
                 + (f" (predicted at the CRB {predicted * 1e3:.4g} um)" if predicted is not None else "")
                 if held else ""))
    return outcome


def main(argv: list[str] | None = None) -> int:
    """Run; a refused input, output or flag ends with one line on stderr and exit status 2."""
    return cli_main(run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
