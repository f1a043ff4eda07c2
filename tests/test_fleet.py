"""Fleet calibration (pipeline.fleet): a folder of recordings of mixed robots, two of them broken."""

import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.workflows.calibration import RunSettings, run_calibration
from pipeline.fleet import main
from pipeline.workflows.fleet import TABLE_COLUMNS, input_hash, run_fleet
from pipeline.formats import read_recording, sidecar_path, write_recording

#: Calibration poses simulated per robot (the rus has 66 parameters: 20 poses, twice its fewest).
POSES = {"hexapod": 12, "delta": 12, "rus": 20}
PER_ROBOT = 6


@pytest.fixture(autouse=True)
def _home(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))


@pytest.fixture(scope="module")
def fleet_folder(tmp_path_factory):
    """20 recordings: 6 machines of each robot (one simulated in MuJoCo by pipeline.run's library,
    five more with other sensor noise), a CSV without its sidecar and one with a broken cell."""
    sims = tmp_path_factory.mktemp("sims")
    folder = tmp_path_factory.mktemp("fleet")
    for robot, n in POSES.items():
        run_calibration(RunSettings(robot=robot, poses=str(n), heldout=5, seed=3, out=sims, name=robot))
        rec = read_recording(sims / f"{robot}.csv")
        for k in range(PER_ROBOT):
            measured = rec.measured.copy()
            measured[:, :3] += np.random.default_rng([k, 1]).uniform(-3e-4, 3e-4, (len(measured), 3))
            write_recording(folder / f"{robot}_{k:02d}.csv", dataclasses.replace(rec, measured=measured))
    # Broken: a CSV whose sidecar is missing, and a row with a cell that is not a number.
    (folder / "orphan.csv").write_text((folder / "hexapod_00.csv").read_text())
    lines = (folder / "delta_00.csv").read_text().splitlines()
    cells = lines[3].split(",")
    cells[2] = "12.3.4"
    lines[3] = ",".join(cells)
    (folder / "garbled.csv").write_text("\n".join(lines) + "\n")
    sidecar_path(folder / "garbled.csv").write_text(sidecar_path(folder / "delta_00.csv").read_text())
    return folder


@pytest.mark.slow
def test_fleet_of_twenty_calibrates_eighteen_and_names_two_broken_files(fleet_folder, tmp_path, dask_two_workers,
                                                                          capsys):
    out = tmp_path / "out"
    seen = []
    rep = run_fleet(fleet_folder, out, client=dask_two_workers, progress=lambda row, d, t: seen.append(d))
    assert len(rep.rows) == 20 and len(rep.ran) == 20 and not rep.skipped and seen == list(range(1, 21))
    ok = [r for r in rep.rows if r["status"] == "calibrated"]
    bad = {r["machine"]: r for r in rep.rows if r["status"] == "error"}
    assert len(ok) == 18 and sorted(bad) == ["garbled", "orphan"]
    assert "orphan.json: sidecar not found" in bad["orphan"]["error"]
    assert "garbled.csv: row 3 (line 4)" in bad["garbled"]["error"] and "'12.3.4' is not a number" in bad["garbled"]["error"]
    assert bad["garbled"]["robot"] == "delta" and bad["orphan"]["robot"] is None
    assert {r["robot"] for r in ok} == set(POSES)
    for r in ok:
        # Simulated with the geometric errors and sensor noise only: geometry explains each one.
        assert r["poses"] == POSES[r["robot"]] and r["explained"] == "yes: geometry alone", r
        assert json.loads(Path(r["discovery"]).read_text())["explained"] is True
        assert 0 < r["heldout_after_um"] < r["heldout_before_um"]  # calibration helped on held-out rows
        assert (out / f"{r['machine']}.rrd").is_file()
        assert json.loads((out / f"{r['machine']}.summary.json").read_text())["robot"] == r["robot"]
    # One table, CSV and markdown, a row per machine.
    lines = (out / "fleet.csv").read_text().splitlines()
    assert lines[0] == ",".join(TABLE_COLUMNS) and len(lines) == 21
    md = (out / "fleet.md").read_text()
    assert md.count("| calibrated |") == 18 and md.count("| error: ") == 2
    assert not list(out.glob(".*.lock"))

    # A second run with the folder unchanged redoes nothing (here in this process: --workers 1).
    stamp = {p.name: p.stat().st_mtime_ns for p in out.glob("*.rrd")}
    assert main([str(fleet_folder), "--out", str(out), "--workers", "1"]) == 1  # rows in error: status 1
    text = capsys.readouterr()
    assert "ran 0, skipped 20 already done" in text.out and "[1/" not in text.err
    assert stamp == {p.name: p.stat().st_mtime_ns for p in out.glob("*.rrd")}

    # A recording that changes is calibrated again, alone.
    side = sidecar_path(fleet_folder / "orphan.csv")
    side.write_text(sidecar_path(fleet_folder / "hexapod_00.csv").read_text())
    try:
        rep = run_fleet(fleet_folder, out, workers=1)
    finally:
        side.unlink()
    assert rep.ran == ["orphan"] and len(rep.skipped) == 19
    assert {r["machine"]: r["status"] for r in rep.rows}["orphan"] == "calibrated"


@pytest.mark.slow
def test_fleet_on_a_cluster_prints_rows_and_dask_s_progress_on_stderr(fleet_folder, tmp_path, dask_two_workers,
                                                                     capsys):
    folder = some_machines(fleet_folder, tmp_path / "three", "hexapod_00", "delta_00", "rus_00")
    assert main([str(folder), "--scheduler", dask_two_workers.scheduler.address]) == 0
    out, err = capsys.readouterr()
    assert out.startswith(f"fleet {folder}: 3 machines, 3 calibrated") and "fleet: " not in out
    lines = err.splitlines()
    assert lines[0].startswith("fleet: 0/3 machines") and re.fullmatch(r"fleet: 3/3 machines \(.*\), done", lines[-1])
    assert sorted(line.split()[0] for line in lines if line.startswith("  [")) == ["[1/3]", "[2/3]", "[3/3]"]


@pytest.mark.slow
def test_interrupted_fleet_keeps_what_finished(fleet_folder, tmp_path):
    """Rows land as each machine finishes: a fleet stopped after two keeps them, and the rerun does the rest."""
    out = tmp_path / "out"

    class Stop(Exception):
        pass

    def stop_after_two(row, done, total):
        if done == 2:
            raise Stop

    with pytest.raises(Stop):
        run_fleet(fleet_folder, out, workers=1, progress=stop_after_two)
    state = json.loads((out / "fleet.json").read_text())
    assert len(state["rows"]) == 2 and not (out / ".fleet.lock").exists()
    rep = run_fleet(fleet_folder, out, workers=1)
    assert len(rep.skipped) == 2 and len(rep.ran) == 18


def test_input_hash_covers_the_sidecar(fleet_folder, tmp_path):
    csv = tmp_path / "m.csv"
    csv.write_text((fleet_folder / "rus_00.csv").read_text())
    h0 = input_hash(csv)
    sidecar_path(csv).write_text("{}")
    assert input_hash(csv) != h0


def test_fleet_refusals(tmp_path, capsys):
    assert main([str(tmp_path / "nowhere")]) == 2
    assert "folder not found" in capsys.readouterr().err
    (tmp_path / "f").write_text("x")
    assert main([str(tmp_path), "--out", str(tmp_path / "f")]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err


def test_recordings_named_in_upper_case_are_machines_too(fleet_folder, tmp_path, capsys):
    """An instrument's software that writes ``.CSV``: still a recording (its sidecar found by stem);
    two names equal but for case are refused before any work, naming both (their outputs would be
    the same files on a file system that ignores case)."""
    folder = tmp_path / "in"
    folder.mkdir()
    for name, source in (("LAB_A.CSV", "hexapod_01"), ("lab_b.csv", "rus_01")):
        shutil.copy(fleet_folder / f"{source}.csv", folder / name)
        shutil.copy(sidecar_path(fleet_folder / f"{source}.csv"), sidecar_path(folder / name))
    (folder / "notes.csv.txt").write_text("not a recording")
    (folder / "sub.csv").mkdir()  # a folder, not a recording
    rep = run_fleet(folder, tmp_path / "out", workers=1)
    assert [(r["machine"], r["robot"], r["status"]) for r in rep.rows] == [
        ("LAB_A", "hexapod", "calibrated"), ("lab_b", "rus", "calibrated")]
    shutil.copy(folder / "lab_b.csv", folder / "LAB_B.csv")
    shutil.copy(sidecar_path(folder / "lab_b.csv"), folder / "LAB_B.json")
    before = sorted(p.name for p in (tmp_path / "out").iterdir())
    capsys.readouterr()
    assert main([str(folder), "--out", str(tmp_path / "out"), "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{folder / 'LAB_B.csv'} and {folder / 'lab_b.csv'}: two recordings of one machine" \
        in err[0], err
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == before


@pytest.mark.slow
@pytest.mark.parametrize("address", ["tcp://127.0.0.1:1", "127.0.0.1:1"])  # nothing listens on port 1
def test_unreachable_scheduler_is_refused_before_any_output(fleet_folder, tmp_path, capsys, address):
    """``--scheduler`` where no scheduler answers: exit 2, one line naming the flag, and no output
    folder (the fleet writes its table as machines land, so it connects first)."""
    import dask

    folder = some_machines(fleet_folder, tmp_path / "one", "hexapod_00")
    capsys.readouterr()
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        assert main([str(folder), "--scheduler", address]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"--scheduler {address}: cannot connect to a Dask scheduler" in err[0], err
    assert "Timed out trying to connect" in err[0], err
    assert sorted(p.name for p in folder.iterdir()) == ["hexapod_00.csv", "hexapod_00.json"]


#: Another process holding an output folder's fleet lock as a fleet does (``flock`` on
#: ``.fleet.lock``), with its process id written or, as a fleet that has just taken it, not yet.
HOLD_LOCK = """
import fcntl, os, sys
fd = os.open(sys.argv[1], os.O_CREAT | os.O_RDWR, 0o644)
fcntl.flock(fd, fcntl.LOCK_EX)
if sys.argv[2] == "pid":
    os.write(fd, str(os.getpid()).encode())
print("held", flush=True)
sys.stdin.read()
"""


def some_machines(fleet_folder, folder, *stems):
    """``folder`` (created) holding the recordings ``stems`` of the fleet, with their sidecars."""
    folder.mkdir()
    for stem in stems:
        for p in (fleet_folder / f"{stem}.csv", sidecar_path(fleet_folder / f"{stem}.csv")):
            shutil.copy(p, folder / p.name)
    return folder


def hold_lock(out, written):
    """A process holding ``out``'s fleet lock (see :data:`HOLD_LOCK`), once it holds it."""
    holder = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(out / ".fleet.lock"), written],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "held"
    return holder


@pytest.mark.parametrize("written", ["pid", "nothing yet"])
def test_a_second_fleet_on_one_output_folder_is_refused(fleet_folder, tmp_path, capsys, written):
    """While another process holds the folder's lock: exit 2, one line (naming the holder when its id
    is in the file), nothing written. Before the lock was a kernel lock, a lock file still empty was
    read as stale and taken over: two fleets wrote one folder."""
    folder = some_machines(fleet_folder, tmp_path / "one", "rus_00")
    out = tmp_path / "out"
    out.mkdir()
    holder = hold_lock(out, written)
    try:
        capsys.readouterr()
        assert main([str(folder), "--out", str(out), "--workers", "1"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        who = f" (process {holder.pid})" if written == "pid" else ""
        assert err == [f"error: --out {out}: another fleet{who} is writing this folder now"], err
        assert [p.name for p in out.iterdir()] == [".fleet.lock"]
    finally:
        holder.stdin.close()
        holder.wait(timeout=30)
    rep = run_fleet(folder, out, workers=1)  # the holder has ended: its lock went with it
    assert [r["status"] for r in rep.rows] == ["calibrated"] and not (out / ".fleet.lock").exists()


def test_a_lock_file_left_by_a_killed_fleet_blocks_nothing(fleet_folder, tmp_path):
    """A fleet killed outright leaves its lock file (with its process id) but not its lock."""
    folder = some_machines(fleet_folder, tmp_path / "one", "hexapod_00")
    out = tmp_path / "out"
    out.mkdir()
    killed = hold_lock(out, "pid")
    killed.kill()
    killed.wait(timeout=30)
    assert (out / ".fleet.lock").read_text() == str(killed.pid)
    rep = run_fleet(folder, out, workers=1)
    assert [r["status"] for r in rep.rows] == ["calibrated"] and not (out / ".fleet.lock").exists()


@pytest.mark.slow
def test_fleet_says_which_machines_the_model_explains(tmp_path, capsys):
    """``explained``: effect discovery on each calibrated machine, against what was injected: an
    effect of the library (named), none (geometry alone), a distortion outside the library (not
    explained), too few measurements (refused, the calibration stands). Rerun without the search:
    every machine redone, ``n/a``; with it again: redone once, then skipped."""
    from pipeline.simulation import effect_recording

    folder = tmp_path / "in"
    machines = {"scaled": ("actuator_scale", "hexapod", 1, 40), "plain": ("none", "delta", 1, 40),
                "drifting": ("instrument_drift", "rus", 1, 40), "bent": ("none", "hexapod", 2, 40),
                "short": ("none", "delta", 3, 9)}
    for machine, (effect, robot, seed, n) in machines.items():
        rec = effect_recording(effect, seed, robot=robot, n_poses=n)
        if machine == "bent":  # a smooth distortion of the measured heights: no effect of the library
            m = rec.measured.copy()
            m[:, 2] += 0.01 * np.sin(m[:, 0] / 7.0) * np.cos(m[:, 1] / 9.0)
            rec = dataclasses.replace(rec, measured=m)
        write_recording(folder / f"{machine}.csv", rec)
    out = tmp_path / "out"
    rep = run_fleet(folder, out, workers=1)
    assert {r["machine"]: r["explained"] for r in rep.rows} == {
        "scaled": "yes: geometry + actuator_scale", "plain": "yes: geometry alone",
        "drifting": "yes: geometry + instrument_drift", "bent": "no: geometry alone",
        "short": "n/a: effect discovery needs at least 12 measurements, got 9"}
    assert all(r["status"] == "calibrated" for r in rep.rows)
    # The run's own verdict: the plain machine fits; the scaled, drifting and bent ones do not fit the
    # geometric model to the noise, and the table says so rather than "calibrated" alone.
    verdicts = {r["machine"]: r["verdict"] for r in rep.rows}
    assert verdicts["plain"] == "success", verdicts
    assert all(verdicts[m].startswith("no: ") for m in ("scaled", "drifting", "bent")), verdicts
    for r in rep.rows:
        if r["machine"] != "short":
            verdict = json.loads(Path(r["discovery"]).read_text())
            assert verdict["explained"] == r["explained"].startswith("yes") and verdict["robot"] == r["robot"]
    md = (out / "fleet.md").read_text()
    assert "| yes: geometry + actuator_scale |" in md and "| no: geometry alone |" in md

    assert main([str(folder), "--out", str(out), "--workers", "1", "--no-discover", "--quiet"]) == 0
    rows = json.loads((out / "fleet.json").read_text())["rows"]
    assert {r["explained"] for r in rows} == {"n/a"} and {r["discovery"] for r in rows} == {None}
    assert "ran 5, skipped 0" in capsys.readouterr().out
    assert len(run_fleet(folder, out, workers=1).ran) == 5
    assert len(run_fleet(folder, out, workers=1).skipped) == 5


def test_a_failed_discovery_leaves_the_calibration_standing(fleet_folder, tmp_path, monkeypatch):
    """The search failing on a machine (here made to) is said on its row; the calibration stands."""
    import pipeline.workflows.discovery

    def broken(rec, **options):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(pipeline.workflows.discovery, "discover", broken)
    rep = run_fleet(some_machines(fleet_folder, tmp_path / "one", "delta_01"), tmp_path / "out", workers=1)
    assert [(r["status"], r["explained"]) for r in rep.rows] == [
        ("calibrated", "n/a: discovery failed: LinAlgError: Singular matrix")]


def test_links_that_lead_nowhere_and_command_files(fleet_folder, tmp_path):
    """A dangling link and a link loop named *.csv are machines whose row says why they cannot be
    read (they were left out silently); a command file (poses to measure, its sidecar's kind says
    so) is not a machine."""
    from calib.robots import default_robot
    from pipeline.formats import write_command_file

    folder = some_machines(fleet_folder, tmp_path / "in", "hexapod_01")
    os.symlink(folder / "gone.csv", folder / "dangling.csv")
    os.symlink(folder / "loop.csv", folder / "loop.csv")
    robot = default_robot("hexapod")
    write_command_file(folder / "next_poses.csv", robot, robot.home_pose[None], robot.inverse_kinematics(
        robot.table.nominal, robot.home_pose[None]), {"kind": "calibration command file"})
    rep = run_fleet(folder, tmp_path / "out", workers=1, discover=False)
    rows = {r["machine"]: r for r in rep.rows}
    assert set(rows) == {"hexapod_01", "dangling", "loop"}
    assert rows["hexapod_01"]["status"] == "calibrated"
    for machine in ("dangling", "loop"):
        assert rows[machine]["status"] == "error" and rows[machine]["error"], rows[machine]
