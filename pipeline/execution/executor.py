"""The one executor of every job of many tasks: Dask (``dask.distributed``).

A job of many independent tasks (the Monte Carlo study's chunks of trials, a fleet's machines,
the blind suite's recordings) runs on a Dask cluster:

* by default a **local cluster** started for the job: ``workers`` processes on this machine, one
  thread each, each computing on one core (:data:`WORKER_ENV`, set before the worker starts:
  ``OPENBLAS_NUM_THREADS`` / ``OMP_NUM_THREADS`` / ``MKL_NUM_THREADS`` = 1 for BLAS, and
  :data:`THREADS_VAR` = 1 for this package's own threads, the MuJoCo testbed's ``mujoco.rollout``
  (:func:`available_cores`): a worker using every core would leave none to the
  others, and several multi-threaded workers on a few cores thrash);
* or an **existing cluster** (``scheduler="tcp://host:8786"``, the ``--scheduler`` flag), started
  with ``dask scheduler`` and ``dask worker ADDRESS --nthreads 1`` on machines where this package
  is installed (Dask's worker sets the BLAS variables to 1; set :data:`THREADS_VAR` = 1 in the
  workers' environment too, e.g. ``PARALLEL_CALIB_THREADS=1 dask worker ...``, when a node runs
  one worker per core);
* or, with one worker and no scheduler, **this process**, one task after another (no cluster to
  start: the cheapest for small jobs and the one debuggers and profilers see).

The tasks are plain functions of plain data, seeded by the task (never by the worker or the order
they finish in), so every way of running a job gives the same numbers. Results come back as each
task finishes (:func:`run_tasks`), which is what lets a fleet write each machine's row as it lands.

A job shows its progress on stderr (:class:`ProgressDisplay`) however it runs, and only
:func:`run_tasks` knows how that is (:func:`runs_here`), so a command hands it the display and
never decides itself: tasks run here are counted as each finishes; on a cluster the count is
Dask's own progress reporting, the scheduler-side ``Progress`` plugin that
``distributed.diagnostics.progressbar.ProgressBar`` listens to, here on the client's event loop
while this process consumes the results (``distributed.progress`` would block until the job ends
and write to stdout, where the commands print their results).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator

__all__ = ["BLAS_ENV", "THREADS_VAR", "WORKER_ENV", "dask_client", "run_tasks", "default_workers", "worker_count",
           "runs_here", "ProgressDisplay", "available_cores", "interrupts_ignored", "quiet_shutdown",
           "SHUTDOWN_LOGGERS"]

logger = logging.getLogger(__name__)

#: One BLAS thread.
BLAS_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
#: The threads this package's own multi-threaded code may run in this process (the testbed's
#: rollout; :func:`available_cores`); unset: every core the process may use.
THREADS_VAR = "PARALLEL_CALIB_THREADS"
#: Set in every local worker before it starts: each worker computes on one core.
WORKER_ENV = {**BLAS_ENV, THREADS_VAR: "1"}


def default_workers() -> int:
    """The local cluster's default size: the cores of this machine."""
    return os.cpu_count() or 1


def worker_count(workers: int | None = None) -> int:
    """``workers`` checked (an integer >= 1; ``ValueError`` otherwise, 0 included), or
    :func:`default_workers` for None."""
    count = default_workers() if workers is None else int(workers)
    if count < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    return count


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None):
    """A ``distributed.Client``: on the cluster at ``scheduler``, or on a local cluster started here.

    Args:
        workers: local cluster size (processes, one thread each, computing on one core); default the
            cores of this machine. Ignored with ``scheduler``.
        scheduler: address of a running Dask scheduler (``tcp://host:8786``), or None.

    Raises:
        ValueError: ``scheduler`` is not an address, or no scheduler answers there (within
            Dask's connect timeout, ``distributed.comm.timeouts.connect``); names the flag.

    The local cluster's logs are quiet; its dashboard (with ``bokeh`` installed) listens on a free
    port of this machine only (``client.dashboard_link``). It is closed, and this process's
    environment restored (Dask's nanny sets the worker variables in the parent before it
    spawns), when the block ends.
    """
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler)
        except (OSError, ValueError) as exc:  # unreachable (a timeout is an OSError), or not an address
            raise ValueError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler: {exc}") from None
        try:
            yield client
        finally:
            with quiet_shutdown():
                client.close()
        return
    workers = worker_count(workers)
    saved = dict(os.environ)
    try:
        environ = {f"distributed.nanny.pre-spawn-environ.{k}": v for k, v in WORKER_ENV.items()}
        with dask.config.set(environ), interrupts_ignored():
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)
        try:
            client = Client(cluster)
        except BaseException:
            with quiet_shutdown():
                cluster.close()
            raise
        try:
            yield client
        finally:
            with quiet_shutdown():
                client.close()
                cluster.close()
    finally:
        for k in set(os.environ) - set(saved):
            os.environ.pop(k, None)
        os.environ.update(saved)


def _comm_closed(record: logging.LogRecord) -> bool:
    """The record tells of a connection closed under a closing cluster (distributed's ``CommClosedError``)."""
    exc = record.exc_info[1] if record.exc_info else None
    return type(exc).__name__ == "CommClosedError" or "CommClosedError" in record.getMessage()


class _DropCommClosed(logging.Filter):
    """Drops :func:`_comm_closed` records (asyncio's "Task exception was never retrieved", tornado's
    "Exception in callback"): they come after a finished job's cluster closed, and say nothing."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not _comm_closed(record)


#: The loggers whose own records may carry a closed connection's traceback after the cluster closed.
SHUTDOWN_LOGGERS = ("asyncio", "tornado.application", "distributed")


@contextlib.contextmanager
def quiet_shutdown():
    """Close a finished job's cluster without a traceback: errors logged while the block runs are
    not shown (a connection closed under the closing cluster, ``CommClosedError``, once in a while
    under load), nor, afterwards, a late report of one (:class:`_DropCommClosed` stays on
    :data:`SHUTDOWN_LOGGERS`); a ``CommClosedError`` raised by the closing is swallowed."""
    for name in SHUTDOWN_LOGGERS:
        log = logging.getLogger(name)
        if not any(isinstance(f, _DropCommClosed) for f in log.filters):
            log.addFilter(_DropCommClosed())
    previous = logging.root.manager.disable
    logging.disable(logging.ERROR)
    try:
        yield
    except Exception as exc:  # noqa: BLE001 - only a closed connection is swallowed
        if type(exc).__name__ != "CommClosedError":
            raise
    finally:
        logging.disable(previous)


@contextlib.contextmanager
def interrupts_ignored():
    """SIGINT ignored while the local cluster's processes start: they inherit it (an ignored signal
    stays ignored across exec, and Python and asyncio leave it so), so a Ctrl-C at the terminal,
    which reaches the whole process group, stops the job in this process alone (one line, exit
    130) instead of printing a traceback from every worker; the cluster is closed with the job."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def runs_here(workers: int | None = None, scheduler: str | None = None, client=None) -> bool:
    """Whether :func:`run_tasks` with these arguments runs the tasks in this process (no cluster)."""
    return client is None and not scheduler and worker_count(workers) == 1


def run_tasks(fn: Callable, jobs: Iterable, *, workers: int | None = None, scheduler: str | None = None,
              client=None, progress: Callable[[int, int], None] | None = None,
              display: "ProgressDisplay | None" = None) -> Iterator[tuple[int, object]]:
    """Run ``fn(job)`` for every job; yield ``(index, result)`` as each task finishes.

    Args:
        fn: a function importable by name in the workers (a module-level function of this package).
        jobs: the tasks' plain-data arguments.
        workers: processes of the local cluster; 1 (and no ``scheduler`` nor ``client``) runs the
            tasks here, in order. Default: the cores of this machine.
        scheduler: address of an existing Dask cluster.
        client: an open ``distributed.Client`` to use (its cluster stays up afterwards).
        progress: ``progress(done, total)`` after each finished task (every way of running).
        display: the job's progress, drawn (on stderr) however the tasks run, while the results
            are consumed, and ended (the final count, or where the job stopped) before this
            generator returns or raises: for tasks run here (:func:`runs_here`), the tasks done as
            each finishes; on a cluster, the tasks done as Dask's scheduler reports them. Not
            drawn for a job of no tasks.

    A task that raises stops the job with its exception (the tasks not yet run are cancelled);
    a job that must go on past a bad input catches the error in ``fn`` and returns it as data.
    """
    jobs = list(jobs)
    total = len(jobs)
    worker_count(workers)  # checked before any task runs
    if runs_here(workers, scheduler, client):
        yield from _in_order(fn, jobs, progress, display if total else None)
        return
    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(dask_client(workers, scheduler))
        yield from _as_completed(client, fn, jobs, progress, display)


def _in_order(fn, jobs, progress, display):
    """The tasks run here, one after another; ``display`` (or None) counts them as each finishes."""
    total, done, stopped = len(jobs), 0, "cancelled"  # left early (e.g. Ctrl-C), as on a cluster
    if display is not None:
        display.update(0, total)
    try:
        for i, job in enumerate(jobs):
            try:
                result = fn(job)
            except Exception:
                stopped = "a task failed"
                raise
            done = i + 1
            if display is not None:
                display.update(done, total)
            if progress:
                progress(done, total)
            yield i, result
        stopped = None
    finally:
        if display is not None:
            display.finish(done, total, stopped)


def _as_completed(client, fn, jobs, progress, display):
    from distributed import as_completed

    # pure=False: two equal jobs are two tasks (a job's result is never shared by key).
    futures = client.map(fn, jobs, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    watch = _SchedulerProgress.start(client, futures, display) if display is not None and futures else None
    done, held = 0, []
    try:
        for future in as_completed(futures):
            result = future.result()
            done += 1
            if progress:
                progress(done, len(jobs))
            yield index[future.key], result
            # A result is released once consumed; while the scheduler-side progress is being set up
            # it must still find every key (it waits for them), so releases wait until it is.
            held.append(future)
            if watch is None or watch.ready:
                for f in held:
                    f.release()
                held.clear()
    finally:
        if watch is not None:
            watch.wait_ready()
        # Only tasks still pending: the scheduler reports every cancel request, empty or not, to
        # every client it has, and a report that reaches a client still connecting arrives in one
        # batch with the scheduler's greeting, which distributed's Client takes for a broken
        # handshake (AssertionError in Client._ensure_connected; a --scheduler run connecting then
        # failed).
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)
        if watch is not None:
            watch.stop()


class ProgressDisplay:
    """A job's progress on stderr: ``LABEL: [####      ] 12/40 tasks (5 s)``.

    On a terminal one line is redrawn in place (at most once a second unless the count changes);
    otherwise (a log) one plain line when a tenth more of the job is done or ``log_interval``
    seconds have passed since the last line, whichever comes first; a last line when the job ends,
    with its wall time, or where it stopped. Lines of results printed while the job runs go
    through :meth:`echo`, above the bar. Thread-safe: Dask's reports arrive on the client's event
    loop, results on the thread consuming them. Never writes to stdout.

    Args:
        label: what runs (``study``, ``fleet``, ...).
        unit: what is counted (Dask counts tasks).
        stream: where to draw; default ``sys.stderr`` at the time of drawing.
        log_interval: seconds between two plain lines at most (not on a terminal).
    """

    #: Seconds between two plain progress lines in a log, at most.
    LOG_INTERVAL = 60.0
    #: Characters of the bar on a terminal.
    WIDTH = 30

    def __init__(self, label: str, *, unit: str = "tasks", stream=None, log_interval: float = LOG_INTERVAL):
        self.label = label
        self.unit = unit
        self.log_interval = float(log_interval)
        self._stream = stream
        self._lock = threading.Lock()
        self._t0 = None
        self._shown = ""         # the bar's text on the terminal line ("" if none is shown)
        self._logged = None      # (done, time) of the last plain line
        self.last = None         # (done, total) last reported

    @property
    def stream(self):
        return sys.stderr if self._stream is None else self._stream

    def _terminal(self) -> bool:
        try:
            return bool(self.stream.isatty())
        except (AttributeError, ValueError):
            return False

    def _elapsed(self) -> float:
        now = time.monotonic()
        if self._t0 is None:
            self._t0 = now
        return now - self._t0

    def _text(self, done: int, total: int, elapsed: float, terminal: bool) -> str:
        if not terminal:
            return f"{self.label}: {done}/{total} {self.unit} ({elapsed:.1f} s)"
        filled = int(self.WIDTH * done / total) if total else self.WIDTH
        bar = "#" * filled + " " * (self.WIDTH - filled)
        return f"{self.label}: [{bar}] {done}/{total} {self.unit} ({elapsed:.0f} s)"

    def _write(self, text: str) -> None:
        with contextlib.suppress(ValueError, OSError):  # a closed stream ends the display, not the job
            self.stream.write(text)
            self.stream.flush()

    def update(self, done: int, total: int) -> None:
        """The job has ``done`` of ``total`` tasks finished."""
        with self._lock:
            elapsed = self._elapsed()
            self.last = (int(done), int(total))
            if self._terminal():
                text = self._text(done, total, elapsed, True)
                if text != self._shown:
                    self._write("\r\x1b[2K" + text)
                    self._shown = text
                return
            if done >= total:
                return  # the last line is :meth:`finish`'s
            if self._logged is not None:
                before, when = self._logged
                tenth = total and math.floor(10 * done / total) > math.floor(10 * before / total)
                if done == before or not (tenth or elapsed - when >= self.log_interval):
                    return
            self._write(self._text(done, total, elapsed, False) + "\n")
            self._logged = (int(done), elapsed)

    def finish(self, done: int, total: int, stopped: str | None = None) -> None:
        """The job ended: all done, or ``stopped`` (why) at ``done`` of ``total``."""
        with self._lock:
            elapsed = self._elapsed()
            self.last = (int(done), int(total))
            terminal = self._terminal()
            text = self._text(done, total, elapsed, terminal)
            text += f": stopped, {stopped}" if stopped else ", done"
            self._write(("\r\x1b[2K" if terminal else "") + text + "\n")
            self._shown, self._logged, self._t0 = "", None, None

    def echo(self, line: str) -> None:
        """Print a line (e.g. a result) on the display's stream, above the bar if one is drawn."""
        with self._lock:
            if self._shown:
                self._write("\r\x1b[2K" + line + "\n" + self._shown)
            else:
                self._write(line + "\n")


class _SchedulerProgress:
    """Dask's ``ProgressBar`` listening on the client's event loop, drawing on a :class:`ProgressDisplay`.

    ``ProgressBar.listen`` connects to the scheduler, which runs the ``Progress`` plugin on the
    job's keys and sends ``{all, remaining, status}`` every ``interval``; it returns when the
    status is ``finished`` or ``error`` (a task erred, or a task not yet done was cancelled).
    """

    #: Seconds between two of the scheduler's reports.
    INTERVAL = 0.1
    #: Seconds to wait for the scheduler's set-up, or its last report, before giving up on it.
    PATIENCE = 10.0

    def __init__(self, client, futures, display: ProgressDisplay):
        from distributed.diagnostics.progressbar import ProgressBar

        owner = self

        class Bar(ProgressBar):
            def _draw_bar(self, remaining, all, status=None, **kwargs):
                owner.ready_event.set()
                if status not in ("finished", "error"):
                    display.update(all - remaining, all)

            def _draw_stop(self, remaining, all, status=None, exception=None, **kwargs):
                # Kept for :meth:`stop`, which draws it on the consuming thread once the job's
                # last result has been handled (a result line printed then stays above it).
                why = None
                if status == "error":
                    why = "a task failed" if exception is not None else "cancelled"
                owner.last_report = (all - remaining, all, why)

        self.display = display
        self.total = len(futures)
        self.bar = Bar(futures, scheduler=client.scheduler.address, interval=self.INTERVAL, complete=True)
        self.ready_event = threading.Event()
        self.ended = threading.Event()
        self.last_report = None  # (done, total, why stopped or None): the scheduler's last report
        self.loop = client.loop.asyncio_loop
        self.future = None

    @classmethod
    def start(cls, client, futures, display: ProgressDisplay) -> "_SchedulerProgress":
        import asyncio  # imported here: every command imports this module (BLAS_ENV), few run Dask

        watch = cls(client, futures, display)
        display.update(0, watch.total)
        watch.future = asyncio.run_coroutine_threadsafe(watch._listen(), watch.loop)
        return watch

    async def _listen(self):
        try:
            await self.bar.listen()
        except Exception as exc:  # no progress display is no reason to fail the job
            logger.debug("progress display: %s", exc)
        finally:
            comm = getattr(self.bar, "comm", None)
            if comm is not None and not comm.closed():
                comm.abort()
            self.ended.set()

    @property
    def ready(self) -> bool:
        """The scheduler has set the job's progress up (or listening failed)."""
        return self.ready_event.is_set() or self.ended.is_set()

    def wait_ready(self) -> None:
        deadline = time.monotonic() + self.PATIENCE
        while not self.ready and time.monotonic() < deadline:
            self.ready_event.wait(0.02)

    def stop(self) -> None:
        """Wait for the scheduler's last report (the job ended), then stop listening."""
        if not self.ended.wait(self.PATIENCE):
            self.future.cancel()  # cancels the listening task on the event loop
            self.ended.wait(self.PATIENCE)
        if self.last_report is not None:
            self.display.finish(*self.last_report)
        else:
            done, total = self.display.last or (0, self.total)
            self.display.finish(done, total, "no report from the scheduler")




def available_cores() -> int:
    """CPU cores this process may run on, at most :data:`THREADS_VAR` when set
    (a Dask worker of the local cluster: 1, so that each worker computes on its own core)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    limit = os.environ.get(THREADS_VAR, "").strip()
    if limit:
        try:
            cores = min(cores, int(limit))
        except ValueError:
            raise ValueError(f"{THREADS_VAR} must be a positive integer, got {limit!r}") from None
        if cores < 1:
            raise ValueError(f"{THREADS_VAR} must be a positive integer, got {limit!r}")
    return cores
