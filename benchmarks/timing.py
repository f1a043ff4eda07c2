"""Timing helpers the benchmark scripts share (run as ``python benchmarks/<script>.py``: this folder
is then on the import path)."""

import os
import time


def best_time(call, repeat: int) -> tuple[float, object]:
    """``(best wall time over repeat calls of call(), the last call's result)``, seconds."""
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = call()
        times.append(time.perf_counter() - t)
    return min(times), out


def print_table_head(setup: str, columns: list[str]) -> None:
    """Print the run's set-up (the BLAS threads first) and a markdown table's header row."""
    print(f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}, {setup}")
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
