"""The Dask executor (pipeline.executor): results as tasks finish, errors, the concurrent.futures pool."""

import asyncio
import io
import math
import os
import re
import threading
import time

import pytest

from pipeline.execution import (THREADS_VAR, WORKER_ENV, ProgressDisplay, default_workers, run_tasks,
                                runs_here, worker_count)


def worker_threads(_):
    from pipeline.execution import available_cores

    return {k: os.environ.get(k) for k in WORKER_ENV}, available_cores()


def fails_on_three(x):
    if x == 3:
        raise ValueError("three")
    return x


def slow_square(x):
    time.sleep(0.02)
    return x * x


@pytest.mark.slow
def test_run_tasks_here_and_on_a_cluster(dask_two_workers):
    seen = []
    here = list(run_tasks(math.sqrt, [1, 4, 9], workers=1, progress=lambda d, t: seen.append((d, t))))
    assert here == [(0, 1.0), (1, 2.0), (2, 3.0)] and seen == [(1, 3), (2, 3), (3, 3)]
    there = sorted(run_tasks(math.sqrt, [1, 4, 9, 16, 25], client=dask_two_workers))
    assert there == [(0, 1.0), (1, 2.0), (2, 3.0), (3, 4.0), (4, 5.0)]
    # By the scheduler's address, as --scheduler does.
    assert sorted(run_tasks(math.sqrt, [4, 9], scheduler=dask_two_workers.scheduler.address)) == [(0, 2.0), (1, 3.0)]
    # Every worker computes on one core: one BLAS thread, one thread of the testbed's rollout.
    for _, (env, cores) in run_tasks(worker_threads, range(4), client=dask_two_workers):
        assert env == WORKER_ENV and cores == 1


@pytest.mark.slow
def test_a_finished_job_sends_the_scheduler_no_cancel_request(dask_two_workers):
    """The scheduler tells every client of every cancel request, empty ones too, and a client
    connecting at that moment fails its handshake (distributed 2026.8: an AssertionError in
    ``Client._ensure_connected``): a job whose tasks all finished must not send one."""
    client = dask_two_workers
    before = len(client.get_events(client.id))
    assert sorted(run_tasks(math.sqrt, [1, 4], client=client)) == [(0, 1.0), (1, 2.0)]
    # A task submitted after it travels the same stream to the scheduler, behind any cancel request.
    assert client.submit(math.sqrt, 9.0, pure=False).result() == 3.0
    assert [e for _, e in client.get_events(client.id)[before:] if e.get("action") == "cancel"] == []


def test_available_cores_honours_the_thread_limit(monkeypatch):
    from pipeline.execution import available_cores

    monkeypatch.delenv(THREADS_VAR, raising=False)
    every = available_cores()
    monkeypatch.setenv(THREADS_VAR, "1")
    assert available_cores() == 1
    monkeypatch.setenv(THREADS_VAR, "64")
    assert available_cores() == every
    for bad in ("0", "two"):
        monkeypatch.setenv(THREADS_VAR, bad)
        with pytest.raises(ValueError, match=THREADS_VAR):
            available_cores()


def test_worker_count_checks_the_count_and_defaults_to_the_cores():
    assert worker_count() == default_workers() and worker_count(3) == 3
    for bad in (0, -1):  # 0 is no worker, not "the default"
        with pytest.raises(ValueError, match=f"workers must be >= 1, got {bad}"):
            worker_count(bad)
    with pytest.raises(ValueError, match="workers must be >= 1, got 0"):
        runs_here(0)


@pytest.mark.slow
def test_a_failing_task_stops_the_job(dask_two_workers):
    with pytest.raises(ValueError, match="three"):
        list(run_tasks(fails_on_three, range(6), client=dask_two_workers))
    with pytest.raises(ValueError, match="workers must be >= 1"):
        list(run_tasks(math.sqrt, [1], workers=0))


def _listening(client) -> list:
    """Progress listeners still running on the client's event loop."""
    async def tasks():
        return [t for t in asyncio.all_tasks() if t.get_coro().__qualname__.endswith("Progress._listen")]
    return client.sync(tasks)


def _progress_plugins(client) -> list:
    return client.run_on_scheduler(lambda dask_scheduler: [n for n in dask_scheduler.plugins if "progress" in n])


def _counts(err: str, label: str) -> list[tuple[int, int]]:
    lines = err.splitlines()
    assert lines and all(line.startswith(f"{label}: ") for line in lines), err
    return [tuple(map(int, re.match(rf"{label}: (\d+)/(\d+) tasks", line).groups())) for line in lines]


@pytest.fixture
def quiet_cluster(dask_two_workers):
    """The two-worker client, warm (Dask's own lazily started threads exist), and the threads then."""
    list(run_tasks(math.sqrt, [1, 4], client=dask_two_workers))
    return dask_two_workers, set(threading.enumerate())


@pytest.mark.slow
def test_progress_of_a_cluster_job_is_dask_s_on_stderr(quiet_cluster, capsys):
    client, threads = quiet_cluster
    capsys.readouterr()
    seen = []
    got = sorted(run_tasks(slow_square, range(12), client=client, display=ProgressDisplay("job"),
                           progress=lambda d, t: seen.append(d)))
    assert got == [(k, k * k) for k in range(12)] and seen == list(range(1, 13))
    out, err = capsys.readouterr()
    assert out == ""  # commands print their results on stdout: progress never goes there
    counts = _counts(err, "job")
    assert counts[0] == (0, 12) and counts[-1] == (12, 12) and err.rstrip().endswith(", done")
    assert [d for d, _ in counts] == sorted(d for d, _ in counts)
    assert len(counts) <= 12  # a line a tenth of the job at most (a log is not flooded)
    # Nothing left running: no listener on the client's loop, no plugin on the scheduler, no thread.
    assert _listening(client) == [] and _progress_plugins(client) == []
    assert set(threading.enumerate()) == threads


def test_a_failing_task_stops_the_progress_and_raises(quiet_cluster, capsys):
    client, threads = quiet_cluster
    capsys.readouterr()
    with pytest.raises(ValueError, match="three"):
        list(run_tasks(fails_on_three, range(6), client=client, display=ProgressDisplay("job")))
    out, err = capsys.readouterr()
    assert out == "" and err.splitlines()[-1].endswith(": stopped, a task failed")
    assert _listening(client) == [] and _progress_plugins(client) == []
    assert set(threading.enumerate()) == threads


def test_a_job_left_early_stops_the_progress(quiet_cluster, capsys):
    client, threads = quiet_cluster
    capsys.readouterr()
    job = run_tasks(slow_square, range(40), client=client, display=ProgressDisplay("job"))
    next(job)
    assert len(_listening(client)) == 1  # Dask's progress is listened to while the job runs
    job.close()  # the consumer stops (e.g. Ctrl-C): the tasks not done are cancelled
    out, err = capsys.readouterr()
    done, total = _counts(err, "job")[-1]
    assert out == "" and total == 40 and done < 40 and err.rstrip().endswith(": stopped, cancelled")
    assert _listening(client) == [] and _progress_plugins(client) == []
    assert set(threading.enumerate()) == threads


def test_progress_here_is_drawn_as_each_task_finishes(capsys):
    """Tasks run here draw the same display as on a cluster: the caller never asks where they run."""
    seen = []
    assert runs_here(1) and not runs_here(2) and not runs_here(1, "tcp://host:8786")
    job = run_tasks(math.sqrt, [1, 4, 9], workers=1, display=ProgressDisplay("job"),
                    progress=lambda d, t: seen.append((d, t)))
    assert next(job) == (0, 1.0)
    assert _counts(capsys.readouterr().err, "job") == [(0, 3), (1, 3)]  # drawn as the task finished
    assert list(job) == [(1, 2.0), (2, 3.0)] and seen == [(1, 3), (2, 3), (3, 3)]
    out, err = capsys.readouterr()
    assert out == "" and _counts(err, "job") == [(2, 3), (3, 3)] and err.rstrip().endswith(", done")
    # A task that raises, a job left early, a job of no tasks.
    with pytest.raises(ValueError, match="three"):
        list(run_tasks(fails_on_three, range(6), workers=1, display=ProgressDisplay("job")))
    out, err = capsys.readouterr()
    assert out == "" and err.splitlines()[-1].startswith("job: 3/6 tasks") \
        and err.splitlines()[-1].endswith(": stopped, a task failed")
    job = run_tasks(math.sqrt, range(5), workers=1, display=ProgressDisplay("job"))
    next(job)
    job.close()
    out, err = capsys.readouterr()
    assert out == "" and _counts(err, "job")[-1] == (1, 5) and err.rstrip().endswith(": stopped, cancelled")
    assert list(run_tasks(math.sqrt, [], workers=1, display=ProgressDisplay("job"))) == []
    assert capsys.readouterr() == ("", "")


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_display_on_a_terminal_and_in_a_log():
    tty = Terminal()
    d = ProgressDisplay("fleet", unit="machines", stream=tty)
    d.update(0, 4)
    d.update(1, 4)
    d.update(1, 4)  # unchanged: not redrawn
    d.echo("  [1/4] m1: calibrated")  # a result above the bar, the bar redrawn under it
    d.finish(4, 4)
    bar = "fleet: [{}] {}/4 machines (0 s)"
    assert tty.getvalue() == ("\r\x1b[2K" + bar.format(" " * 30, 0) + "\r\x1b[2K" + bar.format("#" * 7 + " " * 23, 1)
                              + "\r\x1b[2K  [1/4] m1: calibrated\n" + bar.format("#" * 7 + " " * 23, 1)
                              + "\r\x1b[2K" + bar.format("#" * 30, 4) + ", done\n")
    log = io.StringIO()
    d = ProgressDisplay("study", stream=log)
    for k in range(1001):
        d.update(k, 1000)
    d.finish(1000, 1000)
    lines = log.getvalue().splitlines()
    assert [int(re.match(r"study: (\d+)/1000", s).group(1)) for s in lines] == list(range(0, 1001, 100))
    assert lines[-1].endswith(", done")
    d = ProgressDisplay("study", stream=log, log_interval=0.0)  # a line at each change when asked
    log.truncate(0), log.seek(0)
    for k in (0, 1, 1, 2):
        d.update(k, 1000)
    assert len(log.getvalue().splitlines()) == 3


@pytest.mark.slow
def test_ctrl_c_at_the_terminal_stops_a_cluster_job_with_one_line(tmp_path):
    """Ctrl-C reaches the terminal's whole process group, the local cluster's workers included:
    they ignore it (started with SIGINT ignored), the job stops in the main process with exit 130
    and one error line, and no worker prints a traceback."""
    import os
    import signal
    import subprocess
    import sys
    import time

    env = {**os.environ, "HOME": str(tmp_path)}
    # As a terminal starts a command: SIGINT at its default (a test run launched in the background
    # of a non-interactive shell inherits it ignored, and so would the command, which then rightly
    # ignores a Ctrl-C meant for the foreground).
    proc = subprocess.Popen([sys.executable, "-m", "pipeline.blind", "--robot", "hexapod", "--seeds", "3",
                             "--workers", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=env,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    started = time.monotonic()
    while time.monotonic() - started < 60:  # until the cluster runs tasks (its first progress report)
        line = proc.stderr.readline()
        if "recordings" in line and "0/" not in line.split("recordings")[0][-6:]:
            break
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert err.strip().splitlines()[-1] == "error: interrupted; nothing was written"
