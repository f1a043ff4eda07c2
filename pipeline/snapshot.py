"""``python -m pipeline.snapshot FILE.rrd [FILE.rrd ...] --out FILE.png``: the default view of a
recording as a PNG, rendered headless.

A thin front end of :func:`pipeline.views.headless.snapshot` (which says what it needs and does):
with several files the viewer shows the last one opened, the others loaded beside it. Exit 2 and
one line when the file is missing or no renderer is available.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.views.headless import DEFAULT_SIZE, SnapshotError, snapshot

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m pipeline.snapshot",
                                description="Render the default view of Rerun recordings to a PNG, headless.")
    p.add_argument("rrd", nargs="+", type=Path, help="recording(s); the last one is shown")
    p.add_argument("--out", type=Path, required=True, help="PNG to write")
    p.add_argument("--size", default=DEFAULT_SIZE, help="viewer window size in points, WIDTHxHEIGHT")
    p.add_argument("--timeout", type=float, default=60.0, help="seconds to wait for the viewer")
    args = p.parse_args(argv)
    try:
        out = snapshot(args.rrd, args.out, size=args.size, timeout_s=args.timeout)
    except (FileNotFoundError, SnapshotError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
