"""``python -m pipeline.compensate --calibration C.calibration.json --targets T.csv --out commands.csv``:
the joint commands that put the calibrated machine at each target.

A thin front end of :func:`pipeline.workflows.compensate.run_compensation`: the identified
geometry and every effect found that the command sequence lets it invert (dead band, actuator
scale, compliance, screw error, a kept law; drift and warm-up when the targets give ``t_s``).
What is not compensated, and targets outside what the calibration saw, are named on stderr; the
command file (the targets in the base frame, then the commands) and its ``.json`` sidecar are
written together; with ``--map MAP.toml`` (a lab's mapping file) the commands again in its joint
readings (revolutions or counts; ``--session`` picks a session's own mapping), after the mm
columns. A bad file or flag: exit 2 and one line naming the file and the key, or the row
and column.
"""

from __future__ import annotations

import argparse
import sys

from pipeline.cli import ArgumentParser, cli_main
from pipeline.workflows.compensate import TARGET_FRAMES, CompensateSettings, CompensationReport, run_compensation

__all__ = ["build_parser", "settings_from_args", "run", "main"]


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m pipeline.compensate",
                       description="Compute the joint commands that put a calibrated machine at target poses: the "
                                   "identified geometry and the physics discovery found.")
    p.add_argument("--calibration", required=True, help="calibration file (NAME.calibration.json, written by "
                                                          "pipeline.run or pipeline.discover)")
    p.add_argument("--targets", required=True, help="target poses (CSV: the robot's pose columns, x_mm ...; t_s "
                                                     "optional: time since the machine started; recorded channels "
                                                     "a kept law follows)")
    p.add_argument("--out", required=True, help="command file to write (CSV; its sidecar NAME.json beside it)")
    p.add_argument("--frame", choices=TARGET_FRAMES, default="base",
                   help="frame of the targets: the robot's base (default) or the instrument frame the calibration "
                        "found")
    p.add_argument("--session", help="with --frame instrument: the session whose instrument frame it is; with --map: "
                                      "the session whose joint mapping ([sessions.NAME.joints]) converts the commands")
    p.add_argument("--map", help="a lab's mapping file (TOML, see docs/importer.md): the commands also in its joint "
                                 "readings (revolutions or counts), in its joint columns")
    p.add_argument("--geometry-only", action="store_true", help="compensate the geometry alone")
    p.add_argument("--overwrite", action="store_true", help="allow replacing an existing command file")
    return p


def settings_from_args(args: argparse.Namespace) -> CompensateSettings:
    """The :class:`CompensateSettings` of parsed flags."""
    return CompensateSettings(calibration=args.calibration, targets=args.targets, out=args.out, frame=args.frame,
                              session=args.session, geometry_only=args.geometry_only, overwrite=args.overwrite,
                              map=args.map)


def run(argv: list[str] | None = None) -> CompensationReport:
    """Parse ``argv``, compensate, print what was written (warnings on stderr)."""
    report = run_compensation(settings_from_args(build_parser().parse_args(argv)))
    s = report.summary
    for w in report.warnings:
        print(f"warning: {w}", file=sys.stderr)
    physics = ", ".join(s["compensated"]) or "none"
    print(f"wrote {report.paths['commands']} and {report.paths['sidecar']}: {s['targets']} commands of the "
          f"{s['robot']} (targets in the {s['targets_frame']})")
    print(f"  geometry: the identified parameters of {s['calibration']['path']}; physics compensated: {physics}"
          + (f" (largest correction {s['largest_physics_correction']:.4g} {s['joint_unit']})" if s["compensated"] else ""))
    if "controller_readings" in s:
        r = s["controller_readings"]
        print(f"  the commands also in {r['reading']} ({', '.join(r['columns'])}) by {r['map']}"
              + (f", session {r['session']}" if r["session"] else ""))
    for name, why in s["not_compensated"].items():
        print(f"  not compensated: {name}: {why}")
    return report


def main(argv: list[str] | None = None) -> int:
    """Run; a refused input, output or flag ends with one line on stderr and exit status 2."""
    return cli_main(run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
