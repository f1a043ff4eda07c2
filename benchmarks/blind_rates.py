"""Rates of the blind suite (docs/discovery.md): ``PYTHONPATH=. python benchmarks/blind_rates.py``.

Hexapod: every single effect and none (``--seeds`` recordings each), each also analysed with its
effect left out of the candidates, with three gross rows, with the noise 10 and 100 times the
declared, with 30% gross rows and with the nominal geometry 10% off; every pair of effects but
nested ones (``--pair-seeds`` recordings each). Leave-one-out removes the effect's family
(:func:`calib.effects.effect_family`). The recordings carry per-joint spreads (each joint its own
dead band, growth rate, stiffness, screw phase); ``shared`` draws one value for every joint.
Delta and rus: single, shared, pair and leave-one-out (``--other-seeds``). Every robot: the laws
outside the library (kind ``law``, ``--law-seeds`` recordings each, from seed 700).
Prints one Markdown table per robot and the failures; ``--json FILE`` keeps every result.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from pipeline.workflows.blind import KINDS, failure_lines, rates_table, run_blind_suite


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--pair-seeds", type=int, default=10)
    ap.add_argument("--other-seeds", type=int, default=5)
    ap.add_argument("--law-seeds", type=int, default=6)
    ap.add_argument("--robots", nargs="+", default=["hexapod", "delta", "rus"])
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    everything = []
    for robot in a.robots:
        t0 = time.perf_counter()
        if robot == "hexapod":
            res = run_blind_suite(None, range(a.seeds), robot=robot, kinds=[k for k in KINDS if k != "pair"])
            res += run_blind_suite(None, range(a.pair_seeds), robot=robot, kinds=("pair",))
        else:
            res = run_blind_suite(None, range(a.other_seeds), robot=robot,
                                  kinds=("single", "shared", "pair", "leave_one_out"))
        res += run_blind_suite(None, range(700, 700 + a.law_seeds), robot=robot, kinds=("law",))
        print(f"\n## {robot} ({time.perf_counter() - t0:.0f} s)\n")
        print(rates_table(res))
        for line in failure_lines(res):
            print(line)
        sys.stdout.flush()
        everything += [dict(r, robot=robot) for r in res]
    if a.json:
        with open(a.json, "w") as f:
            json.dump(everything, f, indent=1, default=str)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
