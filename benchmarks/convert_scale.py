"""``python -m pipeline.convert`` on a large motion-capture export: wall time and peak memory.

    PYTHONPATH=. python benchmarks/convert_scale.py [--rows 10000 100000 300000 1000000] [--out /tmp/convert_scale]

The export: ``tests/test_convert.py``'s :func:`write_motion_capture_export` (its lab style "metres,
quaternion scalar last, revolutions" for ``--rows`` reachable poses of the hexapod, with the tests'
0.01 mm / 0.1 mrad normal noise, written in blocks) and its map.

Each size is converted once by ``python -m pipeline.convert`` in a child process; its wall time,
CPU time and peak resident memory (``ru_maxrss`` of that child alone, :func:`os.wait4`) are
printed, with the size of the export and the command's line saying which rows the map was checked
on. Figures are of one run on a shared machine (noise: the load of the other sessions).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

from tests.test_convert import write_motion_capture_export


def timed_convert(csv_path: Path, map_path: Path, out: Path) -> dict:
    """Run the command once in a child process, reaped by :func:`os.wait4` for its own resource
    usage: wall s, CPU s, peak resident MB (``ru_maxrss`` is in kB on Linux), its output."""
    cmd = [sys.executable, "-m", "pipeline.convert", str(csv_path), "--map", str(map_path), "--out", str(out),
           "--overwrite"]
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    log = out.with_name(out.name + ".log")
    with open(log, "w+") as stdout, open(log.with_suffix(".err"), "w+") as stderr:
        t = time.perf_counter()
        child = subprocess.Popen(cmd, stdout=stdout, stderr=stderr, env=env)
        _, status, usage = os.wait4(child.pid, 0)
        wall = time.perf_counter() - t
        stdout.seek(0), stderr.seek(0)
        stdout, stderr = stdout.read(), stderr.read()
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"{' '.join(cmd)} failed ({os.waitstatus_to_exitcode(status)}):\n{stderr[-3000:]}")
    return {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime, "peak_mb": usage.ru_maxrss / 1024.0,
            "stdout": stdout, "stderr": stderr}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rows", type=int, nargs="+", default=[10_000, 100_000, 300_000, 1_000_000])
    p.add_argument("--out", type=Path, default=Path("/tmp/convert_scale"))
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"{'rows':>9} {'export MB':>9} {'wall s':>7} {'CPU s':>6} {'peak MB':>8}  checked on")
    for rows in args.rows:
        csv_path, map_path = write_motion_capture_export(args.out, rows)
        r = timed_convert(csv_path, map_path, args.out / f"rec{rows}")
        checked = next((ln.strip() for ln in r["stdout"].splitlines() if "checked" in ln), "")
        print(f"{rows:>9} {csv_path.stat().st_size / 1e6:>9.1f} {r['wall_s']:>7.2f} {r['cpu_s']:>6.2f} "
              f"{r['peak_mb']:>8.0f}  {checked}", flush=True)
        if r["stderr"].strip():
            print(f"          stderr: {r['stderr'].strip()}")
        csv_path.unlink()


if __name__ == "__main__":
    main()
