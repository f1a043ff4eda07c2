"""Settings the many-task tools share (pose design, Monte Carlo study)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ToolOptions"]


@dataclass(frozen=True, kw_only=True)
class ToolOptions:
    """Where a tool runs and what it writes.

    Attributes:
        workers: processes of the local Dask cluster (None: the cores; 1: here, no cluster).
        scheduler: address of an existing Dask scheduler instead of a local cluster.
        geometry: a robot description JSON (``Robot.description()``) instead of the registered
            robot's default machine.
        summary_json, rrd: where to write the summary and the Rerun file (None: not written).
        overwrite: allow replacing existing outputs.
    """

    workers: int | None = None
    scheduler: str | None = None
    geometry: str | None = None
    summary_json: str | None = None
    rrd: str | None = None
    overwrite: bool = False
