"""``python -m pipeline.blind --robot NAME --seeds 20``: the blind suite of discovery.

A thin front end of :func:`pipeline.workflows.blind.run_blind_suite` (its module says what the
kinds of recording are and what each must show): parse the flags, run the suite, print the rates
table on stdout (progress on stderr).
"""

from __future__ import annotations

import argparse

from calib.robots import ROBOTS
from pipeline.cli import ArgumentParser, add_executor_arguments, cli_main, nonnegative_int, positive_int
from pipeline.execution import ProgressDisplay
from pipeline.workflows.blind import KINDS, failure_lines, rates_table, run_blind_suite

__all__ = ["run", "main"]


def run(argv: list[str] | None = None) -> list[dict]:
    """Parse ``argv``, run the suite, print the rates; raises on bad input (see :func:`main`)."""
    ap = ArgumentParser(prog="python -m pipeline.blind", description=__doc__,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", choices=tuple(ROBOTS), default="hexapod", help="the robot simulated")
    ap.add_argument("--effects", nargs="+", default=None,
                    help="single-effect recordings (default every effect that applies to the robot, and none)")
    ap.add_argument("--kinds", nargs="+", default=["single"], choices=KINDS, help="analyses to run")
    ap.add_argument("--laws", nargs="+", default=None, metavar="LAW",
                    help="laws for --kinds law (names of pipeline.simulation.LAW_CASES, quoted; default every law the "
                         "robot has)")
    ap.add_argument("--pairs", nargs="+", default=None, metavar="A,B", help="pairs for --kinds pair (default all)")
    ap.add_argument("--seeds", type=positive_int, default=20, help="recordings per effect (or pair)")
    ap.add_argument("--first-seed", type=nonnegative_int, default=0)
    ap.add_argument("--payloads", type=int, choices=(1, 2), default=1,
                    help="recordings taken at one payload (default) or at two, a light and a heavy one recorded row by "
                         "row as the channel payload_kg")
    add_executor_arguments(ap)
    a = ap.parse_args(argv)
    pairs = None if a.pairs is None else [tuple(p.split(",")) for p in a.pairs]
    try:
        res = run_blind_suite(a.effects, range(a.first_seed, a.first_seed + a.seeds), robot=a.robot, kinds=a.kinds,
                              pairs=pairs, laws=a.laws, workers=a.workers, scheduler=a.scheduler, payloads=a.payloads,
                              display=ProgressDisplay("blind suite", unit="recordings"))
    except NotImplementedError as exc:
        raise ValueError(str(exc)) from None
    print(f"robot: {a.robot}" + ("; recordings at two payloads" if a.payloads == 2 else ""))
    print(rates_table(res))
    for line in failure_lines(res):
        print(line)
    return res


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.blind``: exit 2 and one line on a bad input."""
    return cli_main(run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
