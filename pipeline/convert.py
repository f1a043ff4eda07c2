"""``python -m pipeline.convert LAB.csv [LAB2.csv ...] --map MAP.toml --out NAME``: a lab's export
as a recording (``NAME.csv`` + ``NAME.json``), one session per input file.

``python -m pipeline.convert printer.cfg --klipper --out NAME``: a Klipper linear Delta's
``[delta_calibrate]`` probe data as a probe-data file ``NAME.probe.json``
(:func:`pipeline.workflows.klipper.convert_klipper`; fitted by ``python -m pipeline.probe``); a
rotary Delta's config as its Delta robot's description ``NAME.json``.

A thin front end of :func:`pipeline.workflows.convert.run_convert`: the mapping file's keys are
described in ``docs/importer.md`` (and :mod:`pipeline.formats.lab_export`). A bad map, lab file or
output: exit 2 and one line naming the file and the key, or the row and column.
"""

from __future__ import annotations

import argparse
import sys

from pipeline.cli import ArgumentParser, cli_main
from pipeline.workflows.convert import ConvertResult, ConvertSettings, run_convert
from pipeline.workflows.klipper import KlipperConvertResult, convert_klipper
from pipeline.workflows.klipper_rotary import RotaryConvertResult

__all__ = ["build_parser", "settings_from_args", "run", "main"]


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m pipeline.convert",
                       description="Convert a lab's export (CSV files in its own units and conventions, "
                                   "described by a TOML mapping file) into a recording: one session per file.")
    p.add_argument("files", nargs="+", help="the lab's CSV files, one session each, in order; with --klipper "
                                            "one printer.cfg")
    p.add_argument("--map", help="mapping file (TOML, see docs/importer.md); required without --klipper")
    p.add_argument("--klipper", action="store_true", help="the file is a Klipper printer.cfg of a linear Delta: "
                   "write its [delta_calibrate] probe data as NAME.probe.json; of a rotary Delta: its Delta robot "
                   "as NAME.json (docs/klipper.md)")
    p.add_argument("--out", required=True, help="recording to write: NAME (or NAME.csv) and its NAME.json")
    p.add_argument("--overwrite", action="store_true", help="allow replacing an existing recording")
    return p


def settings_from_args(args: argparse.Namespace) -> ConvertSettings:
    """The :class:`ConvertSettings` of parsed flags."""
    return ConvertSettings(files=tuple(args.files), map=args.map, out=args.out, overwrite=args.overwrite)


def run(argv: list[str] | None = None) -> ConvertResult:
    """Parse ``argv``, convert, print what was written; raises on bad input (see :func:`main`)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.klipper:
        return run_klipper(parser, args)
    if args.map is None:
        parser.error("--map is required (or --klipper for a Klipper printer.cfg)")
    result = run_convert(settings_from_args(args))
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    extras = f"; extra channels {', '.join(result.extras)}" if result.extras else ""
    print(f"wrote {result.csv_path} and {result.json_path}: {result.robot}, {result.rows} rows in "
          f"{len(result.sessions)} session(s){extras}")
    for s in result.sessions:
        print(f"  session {s['session']}: {s['kept_rows']} of {s['data_rows']} rows of {s['file']} "
              f"({s['validation_rows']} validation), instrument frame: {s['frame']}")
    judged = "all" if result.checked_rows == result.rows else \
        f"a seeded subsample (seed {result.check_seed}) of {result.checked_rows} of the"
    print(f"map checked on evidence on {judged} {result.rows} rows")
    return result


def run_klipper(parser, args) -> KlipperConvertResult | RotaryConvertResult:
    """``--klipper``: one printer.cfg to NAME.probe.json (a rotary Delta's: its robot, NAME.json, too);
    print what was written."""
    if len(args.files) != 1 or args.map is not None:
        parser.error("--klipper converts one printer.cfg and takes no --map")
    result = convert_klipper(args.files[0], args.out, overwrite=args.overwrite)
    if isinstance(result, RotaryConvertResult):
        for w in result.warnings():
            print(f"warning: {w}", file=sys.stderr)
        print(result.line())
        return result
    print(f"wrote {result.path}: " + ", ".join(f"{v} {k}" for k, v in result.counts.items())
          + " (joints: stable positions x step distances " + ", ".join(f"{v:.6g}" for v in result.step_distances_mm)
          + " mm)")
    return result


def main(argv: list[str] | None = None) -> int:
    """Run; a refused input, output or flag ends with one line on stderr and exit status 2."""
    return cli_main(run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
