"""The measured fits behind every ``--real`` run (run by hand; figures of docs/benchmarks.md).

``OPENBLAS_NUM_THREADS=1 python benchmarks/measured_fits.py [--repeat 3] [--out DIR]``

For each robot, a 60-row recording with 20 validation rows simulated by ``pipeline.run --seed 3``
(written to ``--out``, default a temporary folder), then, best of ``--repeat`` in process time:

* ``fit``: :func:`calib.measurement.identify_measured` (frame ``auto``: none here);
* ``fit_est``: the same with the instrument frame estimated (two gauge passes);
* ``diag_ok``: :func:`calib.diagnosis.diagnose` of the file as written (one fit);
* ``diag_m``: the positions in metres (the written fit misfits: conversions screened and fitted);
* ``diag_xy``: x and y swapped.

Prints each figure in ms and their total in s, with the load average. Compare two trees by running
it in each (``git stash`` or a ``git archive`` export) one after the other on a quiet machine.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calib.diagnosis import diagnose  # noqa: E402
from calib.measurement import identify_measured  # noqa: E402
from pipeline.formats import read_recording  # noqa: E402
from pipeline.run import run  # noqa: E402

ROBOTS = ("hexapod", "rus", "delta")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, default=None, help="folder for the recordings (default: a temporary one)")
    args = ap.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="measured_fits_"))
    print(f"load average {os.getloadavg()[0]:.2f}")
    figures = {}
    for name in ROBOTS:
        path = out / f"{name}.csv"
        if not path.exists():
            run(["--robot", name, "--poses", "60", "--heldout", "20", "--seed", "3", "--out", str(out),
                 "--name", name, "--quiet"])
        rec = read_recording(path)
        robot, q, m, noise = rec.robot, rec.joints, rec.measured, rec.noise
        metres = m.copy()
        metres[:, :3] /= 1000.0
        swapped = m.copy()
        swapped[:, [0, 1]] = swapped[:, [1, 0]]
        calls = {"fit": lambda: identify_measured(robot, q, m, noise),
                 "fit_est": lambda: identify_measured(robot, q, m, noise, frame="estimate"),
                 "diag_ok": lambda: diagnose(robot, q, m, noise),
                 "diag_m": lambda: diagnose(robot, q, metres, noise),
                 "diag_xy": lambda: diagnose(robot, q, swapped, noise)}
        for label, call in calls.items():
            best = np.inf
            for _ in range(args.repeat):
                t0 = time.process_time()
                call()
                best = min(best, time.process_time() - t0)
            figures[f"{name}.{label}"] = best
    for key, value in figures.items():
        print(f"{key:>16}: {value * 1000:7.0f} ms")
    print(f"{'total':>16}: {sum(figures.values()):7.2f} s  (load average {os.getloadavg()[0]:.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
