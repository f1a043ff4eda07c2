"""``python -m pipeline.run``: calibrate any registered robot, simulated or from a recording.

Thin: parses the flags, calls :func:`pipeline.workflows.calibration.run_calibration`, prints the
summary's report (:mod:`pipeline.report.text`).
The calibration (and with it MuJoCo and Rerun) is imported when a run starts, not for ``--help``.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from calib import paper
from calib.engine import METHODS, SOLVERS
from calib.robots import ROBOTS

from .cli import ArgumentParser, cli_main, keep_freed_memory
from .report.model import Report
from .report.text import terminal_lines

if TYPE_CHECKING:
    from pipeline.workflows.calibration import RunResult, RunSettings

__all__ = ["main", "build_parser", "settings_from_args", "rereference_settings", "run", "print_summary", "NOT_WITH_FROM"]


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="python -m pipeline.run",
        description="Calibrate a parallel robot: simulate it in MuJoCo (or read a recording), identify "
                    "its geometric parameters, compensate, validate on held-out poses, and write a Rerun "
                    "recording (.rrd), the measurements (.csv + .json) and a summary. Lengths in mm, "
                    "angles in rad.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--robot", choices=sorted(ROBOTS), default=None,
                   help="robot to calibrate (default hexapod; with --real the recording's sidecar names it)")
    p.add_argument("--poses", default="reference",
                   help="calibration poses: 'reference' (the robot's reference experiment: the hexapod paper's "
                        "10 Table 4 poses; 20 random poses otherwise), a number N (see --design), or a command "
                        "file written by python -m pipeline.design")
    p.add_argument("--design", choices=["random", "optimal"], default="random",
                   help="with --poses N: random poses in the robot's workspace, or D-optimal ones (calib.design)")
    p.add_argument("--heldout", type=int, default=50, help="held-out validation poses (same workspace)")
    p.add_argument("--noise-mm", type=float, default=paper.PAPER_NOISE_MM,
                   help="sensor noise on each position coordinate, mm (half-width if uniform, std if normal)")
    p.add_argument("--noise-rad", type=float, default=0.0, help="sensor noise on each angle, rad")
    p.add_argument("--noise-joint", type=float, default=0.0,
                   help="noise of each joint reading, in the robot's joint unit (mm or rad)")
    p.add_argument("--noise-dist", choices=["uniform", "normal"], default="uniform",
                   help="noise distribution; the hexapod paper's is uniform")
    p.add_argument("--seed", type=int, default=0, help="seed of poses, injected errors and sensor noise")
    p.add_argument("--method", choices=list(METHODS), default="chainwise",
                   help="identification: chain by chain from the closure residuals (the hexapod paper's "
                        "per-leg method, the Delta paper's IKM), or forward (all parameters through the "
                        "forward kinematics, the Delta paper's FKM)")
    p.add_argument("--solver", choices=list(SOLVERS), default=None,
                   help="Gauss-Newton or Levenberg-Marquardt (default: gn for chainwise, lm for forward)")
    p.add_argument("--weighted", action="store_true",
                   help="chainwise: weight the closure residuals by the declared noise (the forward method always is)")
    p.add_argument("--gravity", action="store_true", help="simulate with gravity (default off)")
    p.add_argument("--payload-kg", type=float, default=0.0, help="payload on the platform, kg")
    p.add_argument("--stiffness", type=float, default=None,
                   help="actuator servo stiffness, N/m or N m/rad (default: the machine builder's)")
    p.add_argument("--friction", type=float, default=0.0, help="Coulomb friction of each actuated joint, N or N m")
    p.add_argument("--out", type=Path, default=Path("recordings"), help="output folder")
    p.add_argument("--name", default=None, help="base name of the output files (default from the robot and "
                                                "poses, numbered if taken)")
    p.add_argument("--overwrite", action="store_true", help="allow replacing existing output files")
    p.add_argument("--summary-json", type=Path, default=None, help="write the summary as JSON to this path")
    p.add_argument("--export-mjcf", type=Path, default=None, metavar="PATH",
                   help="also write the identified machine as a MuJoCo model (MJCF .xml) to this path "
                        "(docs/export_mjcf.md)")
    p.add_argument("--report", type=Path, default=None, metavar="PATH.html",
                   help="write the report a lab keeps: one self-contained HTML file (verdict, parameters with "
                        "+-2 sigma and their tolerance verdicts, held-out errors plotted, ISO 9283 figures of repeated "
                        "poses, flagged rows, instrument frames)")
    p.add_argument("--real", type=Path, default=None,
                   help="analyse this recording (.csv with its .json sidecar, any robot) instead of simulating")
    p.add_argument("--from", dest="from_calibration", type=Path, default=None, metavar="CAL.calibration.json",
                   help="with --real: re-reference this calibration to the recording (docs/commands.md): its geometry "
                        "and effects held, only what changes between sessions (each joint's zero, the instrument's "
                        "frame) estimated from the recording's calibration rows (as few as 6), its validation rows "
                        "predicted before and after; writes NAME.calibration.json (NAME: the recording's stem + "
                        "'_rereferenced') and --summary-json")
    p.add_argument("--keep-outliers", action="store_true",
                   help="identify from every calibration row, the ones the outlier test flags included "
                        "(default: flagged rows are left out; the summary gives both results)")
    p.add_argument("--no-prior", dest="prior", action="store_false",
                   help="plain least squares: no parameter prior (default: each parameter's nominal value with "
                        "the sidecar's meta.parameter_tolerance, or the robot's default tolerance, as its prior; "
                        "maximum a posteriori)")
    p.add_argument("--tolerance", default=None, metavar="KEY=VALUE[,KEY=VALUE...]",
                   help="declare the parameters' manufacturing tolerance (one standard deviation about nominal): "
                        "per unit ('mm=2,rad=0.02') and/or by parameter name ('B3.z=0.5'); overrides the sidecar's "
                        "meta.parameter_tolerance. Default: the sidecar's, else learnt from the rows (empirical "
                        "Bayes, calib.evidence)")
    p.add_argument("--quiet", action="store_true",
                   help="print nothing: no progress and no summary (the summary in --summary-json; errors still on stderr)")
    return p


def settings_from_args(args: argparse.Namespace) -> RunSettings:
    """Validate the parsed flags (``ValueError`` naming the flag) and build the settings."""
    if args.heldout < 0:
        raise ValueError(f"--heldout must be >= 0, got {args.heldout}")
    if args.poses not in ("reference",) and not args.poses.endswith(".csv"):
        try:
            n = int(args.poses)
        except ValueError:
            raise ValueError(f"--poses must be 'reference', an integer or a .csv command file, got {args.poses!r}") from None
        if n < 1:
            raise ValueError(f"--poses must be a positive integer, got {n}")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    if args.name is not None and (Path(args.name).name != args.name or args.name in ("", ".", "..")):
        raise ValueError(f"--name {args.name}: a file name, not a path (the files go into --out {args.out})")
    for flag in ("noise_mm", "noise_rad", "noise_joint", "payload_kg", "friction"):
        v = getattr(args, flag)
        if not (v >= 0 and math.isfinite(v)):
            raise ValueError(f"--{flag.replace('_', '-')} must be >= 0 and finite, got {v}")
    if args.stiffness is not None and not (args.stiffness > 0 and math.isfinite(args.stiffness)):
        raise ValueError(f"--stiffness must be finite and > 0, got {args.stiffness}")
    if args.poses.endswith(".csv") and not Path(args.poses).is_file():
        raise ValueError(f"--poses {args.poses}: " + ("is a folder, not a command file" if Path(args.poses).is_dir()
                                                       else "file not found"))
    if args.real is not None and not args.real.is_file():
        raise ValueError(f"--real {args.real}: " + ("is a folder, not a recording" if args.real.is_dir()
                                                     else "file not found"))
    from pipeline.workflows.calibration import RunSettings

    fields = {k: v for k, v in vars(args).items() if k not in ("quiet", "from_calibration")}
    fields["tolerance"] = None if args.tolerance is None else tolerance_argument(args.tolerance)
    return RunSettings(**fields)


def tolerance_argument(text: str) -> dict:
    """``{"mm": 2.0, "B3.z": 0.5}`` from ``--tolerance mm=2,B3.z=0.5`` (ValueError naming the flag;
    the keys and values are checked against the robot when the run reads it)."""
    out = {}
    for part in text.split(","):
        key, sep, value = part.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"--tolerance {text!r}: expected KEY=VALUE pairs separated by commas "
                             f"(e.g. mm=2,rad=0.02), got {part!r}")
        try:
            out[key.strip()] = float(value)
        except ValueError:
            raise ValueError(f"--tolerance {text!r}: {key.strip()!r} must be a number, got {value!r}") from None
    return out


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


def print_summary(report: Report) -> None:
    """A run's report in plain words, for the terminal (:func:`pipeline.report.text.terminal_lines`)."""
    for line in terminal_lines(report):
        print(line)


#: Flags a re-reference (``--from``) does not take, with their defaults.
NOT_WITH_FROM = ("report", "export_mjcf")


def rereference_settings(args: argparse.Namespace):
    """The settings of ``--from`` (``ValueError`` naming the flag)."""
    if args.real is None:
        raise ValueError(f"--from {args.from_calibration}: needs --real TODAY.csv, the session to re-reference to")
    for flag in NOT_WITH_FROM:
        if getattr(args, flag) is not None:
            raise ValueError(f"--{flag.replace('_', '-')} with --from: not written by a re-reference (run "
                             "python -m pipeline.export on the calibration it writes)")
    settings_from_args(args)  # the flags --real and --from share, checked as a run checks them
    from pipeline.workflows.rereference import RereferenceSettings

    return RereferenceSettings(real=args.real, calibration=args.from_calibration, out=args.out, name=args.name,
                               overwrite=args.overwrite, summary_json=args.summary_json)


def run(argv: list[str] | None = None):
    """Parse ``argv`` and run (for Python callers and tests); raises on bad input. Returns the
    :class:`pipeline.workflows.calibration.RunResult`, or with ``--from`` the
    :class:`pipeline.workflows.rereference.RereferenceResult`."""
    args = build_parser().parse_args(argv)
    if args.from_calibration is not None:
        from pipeline.workflows.rereference import run_rereference, summary_lines

        result = run_rereference(rereference_settings(args))
        if not args.quiet:
            print("\n".join(summary_lines(result.summary)))
        return result
    from pipeline.workflows.calibration import run_calibration

    result = run_calibration(settings_from_args(args), progress=_progress(not args.quiet))
    if args.summary_json is not None:
        result.summary["summary_json"] = str(args.summary_json)
    if not args.quiet:
        print_summary(result.report)
    return result


def main(argv: list[str] | None = None) -> int:
    """Run; a bad input or output ends with one line on stderr and exit status 2.

    The command renders nothing: unless ``MUJOCO_GL`` says otherwise, MuJoCo is imported without
    its OpenGL backend (a third of MuJoCo's import time). The process ends after its run: freed
    arrays' memory is reused, not handed back (:func:`pipeline.cli.keep_freed_memory`).
    """
    os.environ.setdefault("MUJOCO_GL", "disable")
    keep_freed_memory()
    return cli_main(run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
