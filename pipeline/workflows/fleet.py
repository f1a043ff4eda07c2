"""Calibrate every recording in a folder, one table for the fleet (:func:`run_fleet`; the
command ``python -m pipeline.fleet FOLDER``).

Every ``*.csv`` (``.CSV`` too) in ``FOLDER`` (not its sub-folders) is one machine's recording
(CSV + JSON sidecar, :mod:`pipeline.formats`; any registered robot, robots mixed). Each is
calibrated by :func:`pipeline.workflows.calibration.run_calibration` (``RunSettings(real=FILE)``: the
analysis of ``python -m pipeline.run --real FILE``), then its residuals searched for the physics the
geometric model left out (:func:`pipeline.workflows.discovery.discover`, without its MuJoCo re-simulation;
``--no-discover``: not searched), as one task of :mod:`pipeline.execution` (a local Dask
cluster of ``--workers`` processes, ``--workers 1`` here, or ``--scheduler ADDRESS``: a task
reads its recording and writes its outputs by path, so the workers of a remote cluster must see
``FOLDER`` and ``--out`` at the same paths, e.g. on a shared file system).

Written to ``--out`` (default ``FOLDER/calibrated``):

* ``<machine>.rrd``, ``<machine>.summary.json``, ``<machine>.calibration.json`` (the geometry
  identified, as ``python -m pipeline.run`` writes it: ``pipeline.compensate`` reads it) and
  ``<machine>.discovery.json`` (the discovery's summary, as ``python -m pipeline.discover
  --summary-json``) per machine (the machine is the CSV's stem);
* ``fleet.csv`` and ``fleet.md``: one row per machine (machine, robot, the run's verdict:
  ``success`` or ``no: CAUSE``, calibration poses used,
  held-out position error before/after in um, flagged rows, ``explained``, wall time, status);
  ``explained`` is whether the model the discovery chose explains the recording to its declared
  noise, and the model: ``yes: geometry alone``, ``yes: geometry + thermal_drift``, ``no:
  geometry + compliance`` (that effect named, structure left beyond it), ``no: geometry alone``
  (nothing in the library accounts for it); ``n/a`` with ``--no-discover``, ``n/a: REASON`` when
  the discovery refuses the recording (fewer than 12 measurements);
* ``fleet.json``: the same rows with each input's SHA-256 and the outputs' paths;
* ``.rows/<machine>.json``: each machine's row, written as soon as it finishes: a rerun skips a
  machine whose row is there with the same SHA-256 of its recording (CSV and sidecar) and method,
  and whose outputs are still there, searched or not as this run asks (``--redo``: run all).

A file that cannot be calibrated is reported on its row (``error``: the reason, one line) and the
others go on. The three table files are rewritten (each atomically) after each machine finishes
(less often when the table is so long that rewriting it would take more than a tenth of the
time; always at the end, an interruption included), so an interrupted fleet keeps every
machine that had finished, and a rerun does the rest. One fleet
at a time writes to an output folder (it holds a system lock on ``.fleet.lock``, which goes
with the process however it ends). Exit status 0 when every row is
calibrated, 1 when some row is an error, 2 for a refused input or output.

On stderr: one line per machine as it lands (``--quiet``: none) and the fleet's progress, however
it runs (:class:`pipeline.execution.ProgressDisplay`, the lines of the machines printed above it);
stdout gets the summary at the end.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import time
from dataclasses import dataclass
from pathlib import Path

from calib.engine import METHODS

from pipeline.execution import dask_client, run_tasks
from pipeline.formats import FileLock, LockHeld, OutputError, atomic_write, one_line, output_folder, sidecar_path

__all__ = ["FLEET_FORMAT", "TABLE_COLUMNS", "FleetReport", "fleet_inputs", "input_hash", "calibrate_machine",
           "run_fleet", "NOT_RUN", "TABLE_NAMES"]

#: The ``format`` of ``fleet.json``.
FLEET_FORMAT = "parallel-calib fleet"
#: Columns of ``fleet.csv`` (``fleet.json`` adds ``file``, ``sha256``, ``method`` and the outputs).
TABLE_COLUMNS = ("machine", "robot", "status", "verdict", "poses", "poses_used", "heldout_before_um",
                 "heldout_after_um", "flagged_rows", "explained", "wall_s", "error")
#: What the ``explained`` column holds when discovery is not run (``NOT_RUN: reason`` when it refused).
NOT_RUN = "n/a"
TABLE_NAMES = {"json": "fleet.json", "csv": "fleet.csv", "md": "fleet.md"}
LOCK_NAME = ".fleet.lock"
#: Each finished machine's row, written as it lands (the truth a rerun reads; the table is its view).
ROWS_DIR = ".rows"
#: The table is rewritten after each machine unless the last rewrite took more than this share of
#: the time since (then as soon as it does, and always at the end): a rewrite of 1,000 rows costs
#: 0.08 s (measured), too much after each of thousands of machines on a large cluster.
TABLE_SHARE = 0.1


@dataclass
class FleetReport:
    """A fleet's rows (sorted by machine) and what this run did."""

    rows: list[dict]
    ran: list[str]
    skipped: list[str]
    table: dict


def fleet_inputs(folder) -> list[Path]:
    """The recordings of a fleet: every file of ``folder`` (not its sub-folders) whose name ends in
    ``.csv``, in any case (``.CSV`` as written by some instruments' software), by name; a link
    that leads nowhere (dangling, a loop) is one too, so that its row says why it cannot be read.
    Command files (poses to measure, whose sidecar's ``kind`` says so: ``pipeline.design``'s, the
    poses a run suggests) are not recordings and are left out.

    Raises:
        ValueError: ``folder`` is not a folder, or two recordings would be one machine (their
            stems equal but for case: their outputs would be the same files on a file system
            that ignores case).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"{folder}: " + ("is a file, not a folder of recordings" if folder.exists()
                                          else "folder not found"))
    inputs = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".csv" and (p.is_file() or p.is_symlink())
                    and not is_command_file(p))
    seen: dict[str, Path] = {}
    for p in inputs:
        other = seen.setdefault(p.stem.casefold(), p)
        if other is not p:
            raise ValueError(f"{other} and {p}: two recordings of one machine name {p.stem!r} "
                             "(names that differ only in case give the same outputs); rename one")
    return inputs


def is_command_file(csv_path: Path) -> bool:
    """Whether ``csv_path``'s sidecar describes a command file (``"kind"`` ending in ``command
    file``), not a recording."""
    try:
        side = json.loads(sidecar_path(csv_path).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(side, dict) and str(side.get("kind", "")).endswith("command file")


def input_hash(csv_path) -> str:
    """SHA-256 of a recording's CSV and its sidecar (an absent sidecar counts as empty)."""
    h = hashlib.sha256()
    for p in (Path(csv_path), sidecar_path(csv_path)):
        h.update(p.name.encode() + b"\0")
        try:
            h.update(p.read_bytes())
        except OSError:
            h.update(b"\0missing")
    return h.hexdigest()


def _robot_named(csv_path) -> str | None:
    """The robot a sidecar names, read loosely (for a row whose file cannot be calibrated)."""
    try:
        name = json.loads(sidecar_path(csv_path).read_text()).get("robot")
    except Exception:  # noqa: BLE001 - any unreadable sidecar: no robot named
        return None
    return name if isinstance(name, str) else None


def calibrate_machine(job: dict) -> dict:
    """Calibrate one recording (a task of the fleet; plain data in and out).

    Args:
        job: ``machine``, ``file`` (the CSV), ``out`` (output folder), ``method``, ``sha256``,
            ``discover`` (search the residuals for left-out physics; default False).

    Returns:
        The machine's row (:data:`TABLE_COLUMNS` plus ``file``, ``sha256``, ``method``,
        ``discover``, ``rrd``, ``summary``, ``calibration`` (the run's calibration file),
        ``discovery``: the discovery's summary file, None when not searched); a file that cannot be calibrated gives ``status="error"`` and ``error``,
        the reason in one line.
    """
    from pipeline.workflows.calibration import RunSettings, run_calibration

    t0 = time.perf_counter()
    machine, out = job["machine"], Path(job["out"])
    searched = bool(job.get("discover", False))
    row = {"machine": machine, "file": job["file"], "sha256": job["sha256"], "method": job["method"],
           "discover": searched, "robot": None, "status": "error", "verdict": None, "poses": None, "poses_used": None,
           "heldout_before_um": None, "heldout_after_um": None, "flagged_rows": [], "explained": NOT_RUN,
           "wall_s": None, "error": None, "rrd": None, "summary": None, "calibration": None, "discovery": None}
    summary_path = out / f"{machine}.summary.json"
    try:
        result = run_calibration(RunSettings(real=Path(job["file"]), out=out, name=machine, overwrite=True,
                                             method=job["method"], summary_json=summary_path))
    except Exception as exc:  # noqa: BLE001 - a bad file is reported on its row, the fleet goes on
        row["robot"] = _robot_named(job["file"])
        text = one_line(exc)
        row["error"] = text if isinstance(exc, (ValueError, OSError, KeyError)) else f"{type(exc).__name__}: {text}"
    else:
        r = result.report
        held = heldout_position(r)
        files = dict(r.outputs.files)
        row.update(robot=r.source.robot, status="calibrated",
                   verdict="success" if r.verdict.success else f"no: {r.verdict.cause}", poses=r.fit.rows,
                   poses_used=r.fit.rows_used, flagged_rows=list(r.flagged.rows),
                   heldout_before_um=None if held is None else 1e3 * held.before.mean,
                   heldout_after_um=None if held is None else 1e3 * held.after.mean,
                   rrd=files.get("rrd"), summary=str(summary_path), calibration=files.get("calibration"))
        if searched:
            row.update(_discovered(result.as_read, out / f"{machine}.discovery.json"))
    row["wall_s"] = time.perf_counter() - t0
    return row


def heldout_position(report):
    """The held-out position errors of a run's report (:class:`pipeline.report.model.FigureRow`),
    None where it has none (a cross-validated figure is not a held-out one)."""
    rows = () if report.heldout is None else report.heldout.figures
    return next((f for f in rows if f.quantity == "position" and not f.crossvalidated), None)


def _discovered(read, summary_path: Path) -> dict:
    """``explained`` and ``discovery`` (the summary's path) of a calibrated recording's discovery
    (``read``: the :class:`pipeline.workflows.calibration.AsRead` of the calibration: its poses in
    the base frame, its gross rows left out)."""
    from numpy.linalg import LinAlgError

    from pipeline.report.discovery import with_read
    from pipeline.report.summary import discovery_summary_keys
    from pipeline.report.text import model_words
    from pipeline.workflows.discovery import discover

    if read is None:
        return {"explained": f"{NOT_RUN}: position-only target data: discovery needs full poses", "discovery": None}
    try:
        report = discover(read.recording, resim=False, exclude=read.gross_rows)
    except Exception as exc:  # noqa: BLE001 - refused (too few measurements) or failed: the calibration stands
        refused = isinstance(exc, ValueError) and not isinstance(exc, LinAlgError)  # LinAlgError is a ValueError
        why = one_line(exc) if refused else f"discovery failed: {type(exc).__name__}: {one_line(exc)}"
        return {"explained": f"{NOT_RUN}: {why}", "discovery": None}
    report.report = with_read(report.report, read.block, None, None)  # the read's gross rows and frames, no checks
    atomic_write(summary_path, json.dumps(discovery_summary_keys(report.report), indent=1) + "\n", overwrite=True)
    found = report.report  # the words and the file from the discovery's report
    return {"explained": f"{'yes' if found.verdict.success else 'no'}: "
                         f"{model_words([e.name for e in found.effects.effects])}",
            "discovery": str(summary_path)}


def _cell(v, digits=4) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    if isinstance(v, list):
        return " ".join(str(x) for x in v)
    return str(v)


def _csv_text(rows) -> str:
    buf = io.StringIO(newline="")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(TABLE_COLUMNS)
    for r in rows:
        w.writerow([_cell(r[c], 6) for c in TABLE_COLUMNS])
    return buf.getvalue()


def _md_text(rows, folder) -> str:
    ok = sum(r["status"] == "calibrated" for r in rows)
    lines = [f"# Fleet calibration of {folder}", "",
             f"{len(rows)} machines: {ok} calibrated, {len(rows) - ok} not. Held-out: position error of the "
             "recording's validation rows, before (nominal model) and after calibration. Flagged rows: "
             "1-based data rows of the recording. explained: whether the model effect discovery chose (geometry "
             "alone, or with the effects named) explains the recording to its declared noise (its verdict in "
             "<machine>.discovery.json; n/a: not searched). verdict: the run's (success, or no: its likely "
             "cause; <machine>.summary.json says why).", "",
             "| machine | robot | verdict | poses (used) | held-out before (um) | after (um) | flagged rows | "
             "explained | wall (s) | status |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        poses = "" if r["poses"] is None else f"{r['poses']}" + (
            f" ({r['poses_used']})" if r["poses_used"] != r["poses"] else "")
        status = r["status"] if r["status"] != "error" else f"error: {r['error']}"
        cells = [r["machine"], r["robot"] or "?", r.get("verdict") or "", poses, _cell(r["heldout_before_um"]),
                 _cell(r["heldout_after_um"]),
                 _cell(r["flagged_rows"]) or "none" if r["status"] == "calibrated" else "",
                 r["explained"], _cell(r["wall_s"], 3), status]
        lines.append("| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def _write_tables(out: Path, folder: Path, rows_by_machine: dict) -> None:
    rows = [rows_by_machine[m] for m in sorted(rows_by_machine)]
    state = {"format": FLEET_FORMAT, "version": 1, "folder": str(folder), "rows": rows}
    atomic_write(out / TABLE_NAMES["json"], json.dumps(state, indent=1) + "\n", overwrite=True)
    atomic_write(out / TABLE_NAMES["csv"], _csv_text(rows), overwrite=True)
    atomic_write(out / TABLE_NAMES["md"], _md_text(rows, folder), overwrite=True)


def _row_path(out: Path, machine: str) -> Path:
    return out / ROWS_DIR / f"{machine}.json"


def _previous_row(out: Path, machine: str) -> dict | None:
    """The row a previous run wrote for ``machine`` (None when absent or unreadable)."""
    try:
        row = json.loads(_row_path(out, machine).read_text())
    except (OSError, ValueError):
        return None
    return row if isinstance(row, dict) and row.get("machine") == machine else None


def _done(row: dict | None, sha: str, method: str, discover: bool) -> bool:
    """A previous row stands: same input, method and search, and its outputs are still there."""
    if row is None or row.get("sha256") != sha or row.get("method") != method or \
            bool(row.get("discover", False)) != discover:
        return False
    if row.get("status") == "calibrated":
        outputs = ("rrd", "summary", "calibration") + (("discovery",) if row.get("discovery") else ())
        return all(row.get(k) and Path(row[k]).is_file() for k in outputs)
    return row.get("status") == "error"


def lock_folder(out: Path) -> FileLock:
    """The fleet's lock on ``out/.fleet.lock`` (:class:`pipeline.formats.FileLock`): one fleet at a
    time writes to an output folder.

    Raises:
        OutputError: another fleet holds it, or the folder cannot be written or locked.
    """
    path = out / LOCK_NAME
    try:
        return FileLock(path)
    except LockHeld as exc:
        who = f" (process {exc.holder})" if exc.holder else ""
        raise OutputError(f"--out {out}: another fleet{who} is writing this folder now") from None
    except OSError as exc:
        if exc.filename is not None:  # the lock file cannot be created
            raise OutputError(f"--out {out}: cannot write in this folder: {exc.strerror or exc}") from None
        raise OutputError(f"--out {out}: cannot lock {path}: {exc.strerror or exc}") from None


def run_fleet(folder, out=None, *, method: str = "chainwise", discover: bool = True, workers: int | None = None,
              scheduler: str | None = None, client=None, redo: bool = False, progress=None,
              display=None) -> FleetReport:
    """Calibrate every recording of ``folder`` (see the module docstring).

    Args:
        folder: the folder of recordings.
        out: output folder (default ``folder/calibrated``).
        method: identification method (:data:`calib.engine.METHODS`).
        discover: search each calibrated machine's residuals for left-out physics (``explained``).
        workers, scheduler, client: the executor (:func:`pipeline.execution.run_tasks`).
        redo: calibrate every machine, even those whose row stands.
        progress: ``progress(row, done, total)`` after each machine finished here.
        display: a :class:`pipeline.execution.ProgressDisplay` showing the machines done, however they run.

    Raises:
        ValueError: ``folder`` is not a folder, ``method`` unknown, or ``out`` cannot be written
            (:class:`pipeline.recording.OutputError`).
    """
    if method not in METHODS:
        raise ValueError(f"--method must be one of {', '.join(METHODS)}, got {method!r}")
    folder = Path(folder)
    inputs = fleet_inputs(folder)
    out = Path(out) if out is not None else folder / "calibrated"
    if client is None and scheduler:  # an unreachable cluster is refused before any output is written
        with dask_client(scheduler=scheduler) as client:
            return run_fleet(folder, out, method=method, discover=discover, client=client, redo=redo,
                             progress=progress, display=display)
    output_folder(out)
    lock = lock_folder(out)
    rows, ran, skipped, dirty = {}, [], [], False
    try:
        (out / ROWS_DIR).mkdir(exist_ok=True)
        jobs = []
        for p in inputs:
            machine, sha = p.stem, input_hash(p)
            previous = None if redo else _previous_row(out, machine)
            if _done(previous, sha, method, discover):
                rows[machine] = previous
                skipped.append(machine)
                continue
            # A lock left by an interrupted run (this fleet holds the folder: no other run writes it).
            (out / f".{machine}.lock").unlink(missing_ok=True)
            jobs.append({"machine": machine, "file": str(p), "out": str(out), "method": method, "sha256": sha,
                         "discover": discover})
        dirty, last, cost = True, time.monotonic(), 0.0
        from pipeline.workflows.fleet import calibrate_machine as entry  # by name in the workers

        for k, (_, row) in enumerate(run_tasks(entry, jobs, workers=workers, scheduler=scheduler, client=client,
                                               display=display)):
            atomic_write(_row_path(out, row["machine"]), json.dumps(row, indent=1) + "\n", overwrite=True)
            rows[row["machine"]] = row
            ran.append(row["machine"])
            dirty = True
            if cost <= TABLE_SHARE * (time.monotonic() - last):
                t = time.monotonic()
                _write_tables(out, folder, rows)
                dirty, last = False, time.monotonic()
                cost = last - t
            if progress:
                progress(row, k + 1, len(jobs))
    finally:
        if dirty or not (out / TABLE_NAMES["json"]).exists():
            _write_tables(out, folder, rows)
        lock.release()
    return FleetReport(rows=[rows[m] for m in sorted(rows)], ran=ran, skipped=skipped,
                       table={k: str(out / v) for k, v in TABLE_NAMES.items()})

