"""What the held-out judgement adds to discovery (issue 46: at most 1.5x on the 100-pose grid).

``OPENBLAS_NUM_THREADS=1 python benchmarks/heldout_judgement.py [--repeat 3]``

On the 100-pose level grid of the re-homed twin (tests/rehomed_twin.py, day 1 alone: no validation
rows, so every effect is judged on folds at random, in four blocks of time), best of ``--repeat``
in process time: ``choice`` the calibration rows' choice (:func:`calib.effects.discovery.discover_effects`)
and ``judged`` the same followed by the judgement (the discovery policy,
:func:`calib.discovery.discover_machine`, on the same rows); printed with their ratio, measured in one
run. Also the same on both days (day 2 as validation rows: one fold, the shift by session).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calib.discovery import DiscoveryRows, discover_machine  # noqa: E402
from calib.effects import EffectData, discover_effects  # noqa: E402
from pipeline.workflows.calibration import machine_tolerance  # noqa: E402
from calib.measurement import compose, invert_frame  # noqa: E402
from tests.rehomed_twin import CAPTURE_FRAME, GRID_ROWS, rehomed_twin  # noqa: E402


def timed(rec, rows, val, repeat: int) -> tuple[float, float]:
    robot = rec.robot
    tolerance, _ = machine_tolerance(robot, rec.meta, "sidecar")
    data = EffectData(robot, robot.table.nominal, rec.joints, rec.measured, rec.t_s, rec.noise, tolerance=tolerance.std)
    sets = np.full(len(rec.sets), "calibration")
    sets[val] = "validation"
    rest = np.setdiff1d(np.arange(len(sets)), np.union1d(rows, val))  # neither analysed nor held out
    taken = DiscoveryRows(robot, rec.joints, rec.measured, rec.t_s, rec.noise, sets, rec.sessions, rec.extras)
    choice, judged = [], []
    for _ in range(repeat):
        t0 = time.process_time()
        discover_effects(data.subset(rows), seed=0)
        t1 = time.process_time()
        discover_machine(taken, tolerance=tolerance, seed=0, exclude=rest)
        t2 = time.process_time()
        choice.append(t1 - t0)
        judged.append(t2 - t1)
    return min(choice), min(judged)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rec = rehomed_twin(Path(tmp)).recording
    # the capture's frame taken out, as pipeline.discover --real registers it
    rec = replace(rec, measured=compose(invert_frame(CAPTURE_FRAME), rec.robot, rec.measured))
    grid = np.arange(GRID_ROWS)
    for label, val in (("grid alone (folds)", np.zeros(0, int)), ("grid + day 2 as validation", np.arange(GRID_ROWS, len(rec.sets)))):
        choice, judged = timed(rec, grid, val, args.repeat)
        print(f"{label}: choice {choice:.2f} s, choice + judgement {judged:.2f} s, ratio {judged / choice:.2f}")
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
