"""``python -m pipeline.fleet FOLDER``: calibrate every recording in a folder, one table for the fleet.

Usage::

    python -m pipeline.fleet FOLDER [--out DIR] [--method chainwise|forward] [--no-discover]
        [--workers N] [--scheduler ADDRESS] [--redo] [--quiet]

A thin front end of :func:`pipeline.workflows.fleet.run_fleet` (which says what is written where):
parse the flags, call it, print one line per machine as it lands and the summary. Exit status 0
when every row is calibrated, 1 when some row is an error, 2 for a refused input or output, 130
when interrupted.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from calib.engine import METHODS
from pipeline.cli import EXIT_INTERRUPTED, ArgumentParser, add_executor_arguments, cli_main
from pipeline.execution import ProgressDisplay
from pipeline.workflows.fleet import NOT_RUN, TABLE_NAMES, run_fleet

__all__ = ["main"]


def _parser():
    p = ArgumentParser(prog="python -m pipeline.fleet", description=__doc__.split("\n\n")[0])
    p.add_argument("folder", type=Path, help="folder of recordings (*.csv, each with its .json sidecar)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default FOLDER/calibrated)")
    p.add_argument("--method", choices=list(METHODS), default="chainwise",
                   help="identification method (as python -m pipeline.run --method)")
    p.add_argument("--no-discover", action="store_true",
                   help="do not search the residuals for left-out physics (the explained column: n/a)")
    add_executor_arguments(p)
    p.add_argument("--redo", action="store_true", help="calibrate every machine, even those already done")
    p.add_argument("--quiet", action="store_true", help="no line per machine")
    return p


def _report_line(row, done, total) -> str:
    if row["status"] == "calibrated":
        held = "" if row["heldout_after_um"] is None else \
            f", held-out {row['heldout_before_um']:.4g} -> {row['heldout_after_um']:.4g} um"
        found = "" if row["explained"] == NOT_RUN else f"; explained {row['explained']}"
        verdict = "" if row.get("verdict") in (None, "success") else f"; NOT a success: {row['verdict'][4:]}"
        what = f"calibrated ({row['robot']}, {row['poses']} poses{held}{found}{verdict})"
    else:
        what = f"error: {row['error']}"
    return f"  [{done}/{total}] {row['machine']}: {what} ({row['wall_s']:.2f} s)"


def _main(argv) -> int:
    args = _parser().parse_args(argv)

    # Each machine's line as it lands (a result, here or on a cluster), printed above the job's progress.
    display = ProgressDisplay("fleet", unit="machines")

    def progress(row, done, total):
        if not args.quiet:
            display.echo(_report_line(row, done, total))

    t0 = time.perf_counter()
    try:
        rep = run_fleet(args.folder, args.out, method=args.method, discover=not args.no_discover,
                        workers=args.workers, scheduler=args.scheduler,
                        redo=args.redo, progress=progress, display=display)
    except KeyboardInterrupt:
        out = args.out or args.folder / "calibrated"
        print(f"interrupted: the machines that had finished are in {out / TABLE_NAMES['md']}; "
              "run again to do the rest", file=sys.stderr)
        return EXIT_INTERRUPTED
    bad = [r for r in rep.rows if r["status"] != "calibrated"]
    print(f"fleet {args.folder}: {len(rep.rows)} machines, {len(rep.rows) - len(bad)} calibrated, {len(bad)} not; "
          f"ran {len(rep.ran)}, skipped {len(rep.skipped)} already done ({time.perf_counter() - t0:.1f} s)")
    for r in bad:
        print(f"  {r['machine']}: {r['error']}")
    print(f"  wrote {rep.table['md']}, {rep.table['csv']}")
    return 1 if bad else 0


def main(argv: list[str] | None = None) -> int:
    """Run; a refused input or output ends with one line on stderr and exit status 2."""
    status = [0]

    def run(a):
        status[0] = _main(a)

    return cli_main(run, argv) or status[0]


if __name__ == "__main__":
    raise SystemExit(main())
