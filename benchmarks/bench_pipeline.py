"""Benchmark of the default ``python -m pipeline.run`` (run by hand).

``python benchmarks/bench_pipeline.py`` times the whole default run as a user starts it (a fresh
interpreter, imports included) and its split (simulate, identify, log) as the run reports it,
plus the simulation steps each pose needed to settle. Target: whole default run under 10 s on
2 cores.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main(repeat: int = 3) -> None:
    rows = []
    with tempfile.TemporaryDirectory() as out:
        for k in range(repeat):
            summary = Path(out) / f"s{k}.json"
            t = time.perf_counter()
            subprocess.run([sys.executable, "-m", "pipeline.run", "--out", out, "--name", f"b{k}", "--quiet",
                            "--summary-json", str(summary)], check=True)
            wall = time.perf_counter() - t
            rows.append((wall, json.loads(summary.read_text())))
    wall, s = min(rows, key=lambda r: r[0])
    split = s["wall_time_split_s"]
    n = s["calibration_poses"] + 2 * s["heldout_poses"]
    print(f"default run, best of {repeat}: {wall:.2f} s wall as a process (imports included); "
          f"{s['wall_time_s']:.2f} s inside run()")
    print("  split: " + ", ".join(f"{k} {v:.2f} s" for k, v in split.items()))
    print(f"  {n} poses settled ({s['calibration_poses']} calibration + 2 x {s['heldout_poses']} held-out): "
          f"{1e3 * split['simulate'] / n:.1f} ms per pose; steps to settle per pose: mean "
          f"{s['settle_steps_per_pose']['mean']:.0f}, max {s['settle_steps_per_pose']['max']}")


if __name__ == "__main__":
    main()
