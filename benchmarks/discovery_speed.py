"""Speed of discovery (docs/discovery.md): 120 poses, the full library with the per-chain forms,
subsets up to three effects, no re-simulation, one core:
``OPENBLAS_NUM_THREADS=1 PYTHONPATH=. taskset -c 0 python benchmarks/discovery_speed.py``.

The recordings (per-joint spreads: ``granularity="per_chain"``) are simulated first (not timed);
then :func:`calib.effects.discover_effects` (selection, joint fit, remainder tests, outlier
rounds) with the per-chain forms and with the shared forms only (``per_chain=False``, the search
before per-chain forms: the ratio of the two in the same run), and the whole
:func:`pipeline.workflows.discovery.discover` without re-simulation (adds the held-out fits and the
summary) are timed, best of ``--repeat``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from timing import print_table_head  # benchmarks/timing.py

from calib.effects import EffectData, discover_effects
from pipeline.workflows.discovery import discover
from pipeline.simulation import effect_recording

CASES = (("hexapod", ()), ("hexapod", ("joint_friction",)), ("hexapod", ("joint_friction", "thermal_drift")),
         ("hexapod", ("compliance", "joint_friction", "periodic_screw_error")), ("delta", ("joint_friction",)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--poses", type=int, default=120)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    print_table_head(f"{a.poses} poses, full library, up to three effects",
                     ["robot", "truth (per joint)", "named", "granularity", "explained", "discover_effects (s)",
                      "shared forms only (s)", "ratio", "pipeline discover, no resim (s)"])
    for robot, effects in CASES:
        rec = effect_recording(effects or "none", 5, robot=robot, n_poses=a.poses, granularity="per_chain")
        data = EffectData(rec.robot, rec.robot.table.nominal, rec.joints, rec.measured, rec.t_s, rec.noise)
        t_core, t_shared, t_all = [], [], []
        for _ in range(a.repeat):
            t0 = time.perf_counter()
            d = discover_effects(data)
            t_core.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            discover_effects(data, per_chain=False)
            t_shared.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            discover(rec, resim=False)
            t_all.append(time.perf_counter() - t0)
        forms = ", ".join(f"{k}: {v}" for k, v in d.evidence.granularity) or "-"
        print(f"| {robot} | {' + '.join(effects) or 'none'} | {' + '.join(d.effects) or 'none'} | {forms} | "
              f"{d.explained} | {np.min(t_core):.2f} | {np.min(t_shared):.2f} | "
              f"{np.min(t_core) / np.min(t_shared):.2f} | {np.min(t_all):.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
