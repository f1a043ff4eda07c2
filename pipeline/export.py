"""``python -m pipeline.export --calibration C.calibration.json --to FORMAT --out DIR``: a
calibration delivered where it is used.

A thin front end of :func:`pipeline.workflows.export.run_export`; the formats are the deliveries
of :data:`pipeline.deliveries.DELIVERIES`, the one registry ``Calibration.deliver`` uses too.
``--to linuxcnc``: the robot's LinuxCNC kinematics with its identified parameters (HAL file), an
INI fragment, one compensation file per joint, and a NOTES.md; what LinuxCNC cannot hold is named on stderr with the accuracy given up. A bad file or
flag, or a robot the format has no kinematics for: exit 2 and one line.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.cli import ArgumentParser, cli_main
from pipeline.deliveries import DELIVERIES
from pipeline.workflows.export import ExportReport, ExportSettings, run_export

__all__ = ["build_parser", "settings_from_args", "run", "main"]


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m pipeline.export",
                       description="Deliver a calibration where it is used: a controller's kinematics and compensation "
                                   "tables.")
    p.add_argument("--calibration", required=True, help="calibration file (NAME.calibration.json, written by "
                                                          "pipeline.run or pipeline.discover)")
    p.add_argument("--to", required=True, choices=list(DELIVERIES), help="the format to write")
    p.add_argument("--out", required=True, help="where to write (linuxcnc: a folder, created if missing; mjcf: the .xml file)")
    p.add_argument("--summary", default=None, type=Path,
                   help="report: the summary JSON of the run that wrote the calibration (--summary-json): its "
                        "verdict, held-out figures and flagged rows join the report (default: the calibration file "
                        "alone)")
    p.add_argument("--overwrite", action="store_true", help="allow replacing existing files")
    return p


def settings_from_args(args: argparse.Namespace) -> ExportSettings:
    """The :class:`ExportSettings` of parsed flags."""
    if args.summary is not None and args.to != "report":
        raise ValueError(f"--summary {args.summary}: only --to report reads a run's summary")
    return ExportSettings(calibration=args.calibration, to=args.to, out=args.out, overwrite=args.overwrite,
                          summary=args.summary)


def run(argv: list[str] | None = None) -> ExportReport:
    """Parse ``argv``, export, print what was written (what the target cannot hold on stderr)."""
    report = run_export(settings_from_args(build_parser().parse_args(argv)))
    for line in report.messages:
        print(f"warning: {line}", file=sys.stderr)
    print(f"wrote {len(report.paths)} files of the {report.robot}'s {report.format} export: "
          + ", ".join(report.paths.values()))
    return report


def main(argv: list[str] | None = None) -> int:
    """Run; a refused input, output or flag ends with one line on stderr and exit status 2."""
    return cli_main(run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
