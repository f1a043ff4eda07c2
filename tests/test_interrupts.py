"""A command interrupted while it writes its outputs (SIGINT, SIGTERM, SIGKILL) leaves the outputs
of the run before it byte for byte, and no partial file under an output's name: every output is
written to a hidden temporary file beside it and renamed into place when complete
(:mod:`pipeline.formats.outputs`); SIGINT and SIGTERM remove the temporaries on the way out
(:func:`pipeline.cli.cli_main`), a SIGKILL may leave one (hidden), which the next writer of that
name removes.

The workloads are large enough for the signal to land while the output is being written: the
command runs as a subprocess, and the signal is sent once its temporary file has content (the
rows are streamed into it), before the command has finished.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from calib.robots import default_robot
from calib.workspace import reachable_poses
from pipeline.cli import EXIT_INTERRUPTED
from pipeline.compensate import main as compensate_main
from pipeline.convert import main as convert_main
from pipeline.run import main as run_main
from tests.test_convert import write_motion_capture_export

#: Rows of the lab's export converted (a few seconds of writing).
EXPORT_ROWS = 100_000
#: Targets compensated.
TARGETS = 100_000
#: Seconds a command may take to start writing, and to end after the signal.
PATIENCE_S = 120.0
SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGKILL]


def _temporaries(path):
    """The hidden temporaries and backups beside output ``path`` (``.NAME.PID-XXXX.tmp``)."""
    return sorted(path.parent.glob(f".{path.name}.*"))


def _writing(path) -> bool:
    """Whether a temporary file of output ``path`` has content."""
    for t in _temporaries(path):
        try:
            if t.suffix == ".tmp" and t.stat().st_size > 0:
                return True
        except FileNotFoundError:  # gone between the listing and now
            continue
    return False


def _interrupt_while_writing(argv: list[str], output, signum: int) -> subprocess.Popen:
    """Start ``python -m`` ``argv``, send ``signum`` once output ``output``'s temporary file has
    content, and wait for the process to end; fails if it ended before that."""
    proc = subprocess.Popen([sys.executable, "-m", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + PATIENCE_S
    while not _writing(output):
        assert proc.poll() is None, f"ended before writing: {proc.communicate()}"
        assert time.monotonic() < deadline, "did not start writing in time"
        time.sleep(0.005)
    proc.send_signal(signum)
    proc.stdout_text, proc.stderr_text = (b.decode() for b in proc.communicate(timeout=PATIENCE_S))
    return proc


def _check_left_as_before(proc, signum: int, before: dict) -> None:
    """The outputs are byte for byte the earlier run's; SIGINT and SIGTERM: the process said so and
    left no temporary (a SIGKILL may leave one, hidden, never under the output's name)."""
    said = (proc.returncode, proc.stdout_text, proc.stderr_text)
    for path, data in before.items():
        assert path.read_bytes() == data, (f"{path} changed", said)
    if signum == signal.SIGKILL:
        assert proc.returncode == -signal.SIGKILL, said
        return
    assert proc.returncode == EXIT_INTERRUPTED - signal.SIGINT + signum, said
    assert proc.stderr_text.startswith("error: interrupted") and proc.stderr_text.count("\n") == 1, said
    for path in before:
        assert _temporaries(path) == [], _temporaries(path)


@pytest.fixture(scope="module")
def export(tmp_path_factory):
    """A lab's export of :data:`EXPORT_ROWS` rows, its map, and a map that keeps one row fewer
    (a conversion through it would change the recording)."""
    folder = tmp_path_factory.mktemp("export")
    lab, mapping = write_motion_capture_export(folder, EXPORT_ROWS)
    (folder / "fewer.toml").write_text(mapping.read_text() + "[rows]\nfirst = 2\n")
    return folder, lab, mapping


@pytest.mark.slow
@pytest.mark.parametrize("signum", SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_an_interrupted_convert_leaves_the_earlier_recording(signum, export, tmp_path, capsys):
    folder, lab, mapping = export
    out = tmp_path / "rec"
    assert convert_main([str(lab), "--map", str(mapping), "--out", str(out)]) == 0
    before = {p: p.read_bytes() for p in (tmp_path / "rec.csv", tmp_path / "rec.json")}
    proc = _interrupt_while_writing(["pipeline.convert", str(lab), "--map", str(folder / "fewer.toml"),
                                     "--out", str(out), "--overwrite"], tmp_path / "rec.csv", signum)
    _check_left_as_before(proc, signum, before)
    assert convert_main([str(lab), "--map", str(folder / "fewer.toml"), "--out", str(out), "--overwrite"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.csv", "rec.json"]  # a killed one's temporaries gone
    assert (tmp_path / "rec.csv").read_bytes() != before[tmp_path / "rec.csv"]  # the interrupted run would change it


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """A hexapod's calibration file (a simulated run) and two target files of :data:`TARGETS` poses."""
    folder = tmp_path_factory.mktemp("calibrated")
    assert run_main(["--out", str(folder), "--name", "r", "--quiet"]) == 0
    robot = default_robot("hexapod")
    names = ",".join(f"{n}_{u}" for n, u in zip(robot.pose_names, robot.pose_units))
    for seed in (1, 2):
        np.savetxt(folder / f"targets{seed}.csv", reachable_poses(robot, TARGETS, seed), fmt="%.17g", delimiter=",",
                   header=names, comments="")
    return folder


@pytest.mark.slow
@pytest.mark.parametrize("signum", SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_an_interrupted_compensate_leaves_the_earlier_commands(signum, calibrated, tmp_path, capsys):
    out = tmp_path / "cmd.csv"
    args = ["--calibration", str(calibrated / "r.calibration.json"), "--out", str(out)]
    assert compensate_main(args + ["--targets", str(calibrated / "targets1.csv")]) == 0
    before = {p: p.read_bytes() for p in (out, tmp_path / "cmd.json")}
    proc = _interrupt_while_writing(["pipeline.compensate", *args, "--targets", str(calibrated / "targets2.csv"),
                                     "--overwrite"], out, signum)
    _check_left_as_before(proc, signum, before)
