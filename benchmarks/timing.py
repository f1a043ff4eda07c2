"""Timing helpers the benchmark scripts share (run as ``python benchmarks/<script>.py``: this folder
is then on the import path)."""

import time


def best_time(call, repeat: int) -> tuple[float, object]:
    """``(best wall time over repeat calls of call(), the last call's result)``, seconds."""
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = call()
        times.append(time.perf_counter() - t)
    return min(times), out
