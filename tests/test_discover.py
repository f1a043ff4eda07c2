"""Acceptance tests of effect discovery through the MuJoCo machine."""

import json

import numpy as np
import pytest

from calib.effects import effects_for
from calib.robots import ROBOTS, default_robot
from calib.robots.hexapod import Hexapod, paper_hexapod
from calib.rotation import rotation_matrix
from pipeline.workflows.blind import run_blind_suite
from pipeline.discover import main
from pipeline.workflows.discovery import discover
from pipeline.formats import read_recording, write_recording
from pipeline.views import rrd_entities
from pipeline.simulation import effect_recording

#: Robots whose blind suite runs in the tests (the Delta's and the third robot's single-effect
#: rates are measured by benchmarks/blind_rates.py: their MuJoCo recordings take several times
#: longer).
BLIND_ROBOTS = ("hexapod",)
HEXAPOD_EFFECTS = effects_for(default_robot("hexapod"))
#: Few seeds here; the rates over many are measured by benchmarks/blind_rates.py (docs/discovery.md).
SEEDS = range(2)
#: Workers of the blind suites here: one (the recordings analysed in this process, one after
#: another). pytest-xdist already keeps every core busy, and a local Dask cluster of its own per
#: suite would add its workers' start (about 4 s of CPU) and more processes than cores. The
#: cluster path is tested by test_executor, test_fleet and test_study; each recording's analysis
#: is the same either way (deterministic per case).
BLIND_WORKERS = 1


def _failures(results, criterion):
    return [(r["kind"], r["effects"], r["seed"], r["named"], r["explained"], r["follows"][:3], r["flagged"])
            for r in results if not r["criteria"].get(criterion, True)]


@pytest.mark.slow
@pytest.mark.parametrize("effect", HEXAPOD_EFFECTS)
def test_blind_recordings_of_one_effect(effect):
    """Seeded recordings with this effect (or none), each analysed as it is, with its effect left
    out of the candidates, and with three gross rows added; discovery is not told the truth. One
    test an effect, so that pytest-xdist spreads the recordings over the cores."""
    rs = run_blind_suite((effect,), SEEDS, robot="hexapod", kinds=("single", "leave_one_out", "gross3"),
                         workers=BLIND_WORKERS)
    truth = [] if effect == "none" else [effect]
    assert all(r["effects"] == truth for r in rs)
    # Analysed as it is: named and explained.
    single = [r for r in rs if r["kind"] == "single"]
    assert len(single) == len(SEEDS)
    assert all(60 <= r["rows"] <= 120 for r in single)
    assert all(3 <= m <= 10 for r in single for m in r["magnitude_noise"].values())  # concealed: 3-10 x the noise
    assert not _failures(single, "named")
    for r in single:
        assert r["heldout_after_mm"] <= 1.5 * r["noise_floor_mm"], r
    # Its effect left out of the candidates: said to be unknown, the remainder pointing at what it follows.
    left_out = [r for r in rs if r["kind"] == "leave_one_out"]
    assert [r["left_out"] for r in left_out] == ([] if effect == "none" else [effect] * len(SEEDS))
    assert not _failures(left_out, "unknown")
    assert not _failures(left_out, "points")
    # Rows: <= 2% flagged without gross rows; exactly the three gross rows where they were added
    # (to the recordings with an effect).
    assert len([r for r in rs if r["kind"] == "gross3"]) == (0 if effect == "none" else len(SEEDS))
    assert not _failures(rs, "rows")
    assert not _failures(rs, "consistent")


@pytest.mark.slow
def test_blind_pairs_of_effects_are_both_named():
    rs = run_blind_suite(None, range(1), robot="hexapod", kinds=("pair",),
                         pairs=[("joint_friction", "thermal_drift"), ("compliance", "joint_friction"),
                                ("thermal_drift", "periodic_screw_error")], workers=BLIND_WORKERS)
    assert not _failures(rs, "named")
    assert not _failures(rs, "rows")


@pytest.mark.slow
def test_blind_verdict_never_contradicts_its_tests_under_stress():
    rs = run_blind_suite(("none", "joint_friction"), range(1), robot="hexapod",
                         kinds=("noise10", "noise100", "gross30", "geometry_off"), workers=BLIND_WORKERS)
    assert len(rs) == 8
    assert not _failures(rs, "consistent")
    for r in rs:
        if r["kind"] != "geometry_off":
            assert not r["explained"], r
    assert not _failures(rs, "rows")


#: One short recording per effect on the robots other than the hexapod (their rates over many
#: seeds are measured by benchmarks/blind_rates.py and written in docs/discovery.md).
OTHER_ROBOT_CASES = [(r, e) for r in ("delta", "rus") for e in effects_for(default_robot(r))]


@pytest.mark.parametrize("robot_name,effect", OTHER_ROBOT_CASES)
def test_every_effect_of_the_delta_and_the_rus_is_named_through_mujoco(robot_name, effect):
    # 60 poses at 10 x the noise: on the Delta the geometry absorbs 90% of the compliance (a
    # translating platform), fewer poses or smaller sizes miss it now and then.
    rec = effect_recording(effect, 3, robot=robot_name, n_poses=60, magnitude_noise=10.0)
    s = discover(rec, resim=False).summary
    assert s["effects"] == ([] if effect == "none" else [effect]), s["verdict"]
    assert s["explained"], s["verdict"]
    assert len(s["flagged_poses"]) <= 1


def other_hexapod() -> Hexapod:
    """A hexapod the tool did not build: larger base, smaller rotated platform, higher home."""
    paper = paper_hexapod()
    Rz = rotation_matrix(np.array([0.0, 0.0, 0.2]))
    B = paper.base_joints * 1.2
    P = (paper.platform_joints * 0.85) @ Rz.T
    home = np.array([0.0, 0.0, 260.0, 0.0, 0.0, 0.0])
    first = Hexapod(B, P, np.full(6, 260.0), home)
    return Hexapod(B, P, first.inverse_kinematics(first.table.nominal, home[None])[0], home)


@pytest.mark.slow
@pytest.mark.parametrize("effect", HEXAPOD_EFFECTS)
def test_recordings_of_another_hexapod_work_the_same(effect, tmp_path):
    robot = other_hexapod()
    rng = np.random.default_rng(7)
    theta = robot.table.nominal + rng.uniform(-0.05, 0.05, (6, 7)).ravel()
    rec = effect_recording(effect, 11, robot=robot, theta=theta)
    path, _ = write_recording(tmp_path / "other.csv", rec)
    back = read_recording(path)  # the geometry travels in the sidecar only
    np.testing.assert_array_equal(back.robot.base_joints, robot.base_joints)
    rep = discover(back, resim=False)
    assert rep.summary["effects"] == ([] if effect == "none" else [effect])
    assert rep.summary["heldout_rms_after_mm"] <= 1.5 * rep.summary["noise_floor_mm"]
    # Individual errors are poorly determined along known combinations (dl against B.z), but the
    # identified machine must move like the true one over the recorded workspace.
    cmd = rec.joints[::5]
    diff = robot.forward_kinematics(rep.discovery.chosen.theta, cmd) - robot.forward_kinematics(theta, cmd)
    assert np.abs(diff[:, :3]).max() < 0.003  # mm


@pytest.mark.slow
def test_cli_names_fits_resimulates_and_logs(tmp_path, capsys):
    rec = effect_recording("joint_friction", 2)
    path, _ = write_recording(tmp_path / "friction.csv", rec)
    summary = tmp_path / "summary.json"
    assert main(["--real", str(path), "--out", str(tmp_path), "--summary-json", str(summary)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("Explained: geometry + joint_friction")  # the verdict first
    assert "Left-out physics: joint_friction" in out
    s = json.loads(summary.read_text())
    for key in ("effects", "explained", "remaining", "evidence", "heldout_rms_before_mm", "heldout_rms_after_mm",
                "noise_floor_mm", "effect_parameters", "flagged_poses", "located"):
        assert key in s
    assert "effect" not in s
    assert s["effects"] == ["joint_friction"] and s["explained"] and s["flagged_poses"] == []
    truth = rec.meta["simulation"]["coefficients"]["dead_band"]
    p = s["effect_parameters"]["joint_friction"]["dead_band"]
    assert abs(p["value"] - truth) < 5 * p["std"] + 1e-5
    assert s["heldout_rms_after_mm"] < s["heldout_rms_before_mm"]
    r = s["mujoco_resimulation"]
    assert r["after"]["position_um"] < r["before"]["position_um"]
    assert r["sysid"]["parameter"] == "joint_friction"
    friction_n = rec.meta["simulation"]["machine"]["options"]["joint_friction"]
    assert abs(r["sysid"]["value"] - friction_n) < r["sysid"]["interval_95"] + 0.01
    ents = rrd_entities(tmp_path / "friction_discover.rrd")
    assert {"/vs/time/before/series/leg_1", "/vs/stroke/after/series/leg_6", "/evidence/names", "/per_row/rms_um",
            "/vs/direction_of_the_last_move/before/grid", "/summary", "/verdict", "/remaining"} <= ents


def test_cli_bad_file(tmp_path, capsys):
    (tmp_path / "x.csv").write_text("t_s\n1\n")
    assert main(["--real", str(tmp_path / "x.csv"), "--out", str(tmp_path)]) == 2
    assert "sidecar not found" in capsys.readouterr().err


def test_cli_refuses_a_recording_of_another_robot(tmp_path, capsys):
    rec = effect_recording("none", 1, n_poses=12)
    path, _ = write_recording(tmp_path / "hexapod.csv", rec)
    assert main(["--real", str(path), "--robot", "delta", "--out", str(tmp_path)]) == 2
    assert "is a recording of the hexapod, not of the delta" in capsys.readouterr().err


def test_cli_runs_a_seeded_scenario(tmp_path, capsys):
    summary = tmp_path / "s.json"
    assert main(["--scenario", "thermal_drift", "--scenario-seed", "3", "--no-resim", "--out", str(tmp_path),
                 "--summary-json", str(summary)]) == 0
    s = json.loads(summary.read_text())
    assert s["robot"] == "hexapod" and s["effects"] == ["thermal_drift"]
    assert s["candidates"] == list(effects_for(default_robot("hexapod")))[1:]
    assert (tmp_path / "hexapod_thermal_drift_3_discover.rrd").exists()


def test_cli_candidates_narrow_the_library_and_the_unknown_is_said_first(tmp_path, capsys):
    summary = tmp_path / "s.json"
    assert main(["--scenario", "thermal_drift", "--scenario-seed", "3", "--no-resim", "--out", str(tmp_path),
                 "--candidates", "joint_friction,actuator_scale", "--summary-json", str(summary)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("NOT explained")
    assert "explains the recording to the noise" not in out
    s = json.loads(summary.read_text())
    assert s["candidates"] == ["joint_friction", "actuator_scale"]
    assert not s["explained"] and s["remaining"]["follows"][0] == "time"
    assert "thermal_drift" not in s["effects"]


def test_cli_refuses_an_unknown_candidate(tmp_path, capsys):
    assert main(["--scenario", "none", "--no-resim", "--out", str(tmp_path), "--candidates", "magic"]) == 2
    assert "unknown effect 'magic'" in capsys.readouterr().err


def test_cli_never_replaces_a_summary_and_checks_outputs_before_the_analysis(tmp_path, capsys, monkeypatch):
    import pipeline.workflows.discovery

    summary = tmp_path / "s.json"
    summary.write_text("{}")
    monkeypatch.setattr(pipeline.workflows.discovery, "effect_recording", lambda *a, **k: pytest.fail("analysis started"))
    assert main(["--scenario", "none", "--no-resim", "--out", str(tmp_path), "--summary-json", str(summary)]) == 2
    assert "--summary-json" in capsys.readouterr().err and summary.read_text() == "{}"


def test_a_run_recording_with_few_calibration_rows_is_analysed_whole(tmp_path):
    """A pipeline.run recording (10 calibration + 50 validation rows): every row is evidence."""
    from pipeline.run import run

    run(["--heldout", "20", "--out", str(tmp_path), "--name", "r", "--quiet"])
    rep = discover(read_recording(tmp_path / "r.csv"), resim=False)
    assert rep.summary["explained"] and rep.summary["effects"] == []
    assert "every row analysed" in rep.summary["heldout_basis"]


FAR_FRAME = np.array([500.0, -300.0, 150.0, 0.4, -0.2, 0.3])  # 0.5 m away, turned 0.4 rad


@pytest.mark.slow
@pytest.mark.parametrize("robot", sorted(ROBOTS))
@pytest.mark.parametrize("effect", ["none", "joint_friction"])
def test_discovery_reads_a_recording_in_an_instrument_frame_as_the_run_does(robot, effect, tmp_path):
    """pipeline.discover --real registers the instrument frame as pipeline.run --real does (the
    same code): a recording measured 0.5 m away and turned 0.4 rad gets the base frame's answer."""
    from dataclasses import replace as with_fields

    from calib.measurement import compose
    from pipeline.formats import write_recording
    from pipeline.simulation import effect_recording
    from pipeline.workflows import DiscoverySettings, run_discovery

    rec = effect_recording(effect, 4, robot=robot, n_poses=80)
    far = with_fields(rec, measured=compose(FAR_FRAME, rec.robot, rec.measured))
    answers = {}
    for name, r in (("base", rec), ("far", far)):
        write_recording(tmp_path / f"{name}.csv", r)
        s = run_discovery(DiscoverySettings(real=tmp_path / f"{name}.csv", resim=False, out=tmp_path)).summary
        answers[name] = (s["explained"], s["effects"])
        # No validation rows: a cross-validated figure, as pipeline.run --real gives (at the noise here).
        assert s["crossvalidation"]["scheme"] == "leave-one-out" and s["crossvalidated_position_error_mm"]["rms"] > 0
        if name == "far":
            assert "measurement_frame" in s
        else:
            assert "measurement_frame" not in s
    assert answers["far"] == answers["base"]
    if effect == "none":
        assert answers["far"] == (True, [])
    # Targets given in the instrument's frame, commanded through the calibration file the far
    # recording's discovery wrote (its frame, geometry and effects): the machine lands on them
    # to the noise (1.5 times the declared position noise, mean over 30 targets).
    from pipeline.formats import read_command_file
    from pipeline.simulation import command_scenario_machine, heldout_targets
    from pipeline.workflows.compensate import CompensateSettings, run_compensation

    targets, t_s = heldout_targets(rec, 30, 7)
    seen = compose(FAR_FRAME, rec.robot, targets)
    names = [f"{n}_{u}" for n, u in zip(rec.robot.pose_names, rec.robot.pose_units)]
    (tmp_path / "targets.csv").write_text(",".join(names) + "\n" + "\n".join(",".join(map(repr, map(float, p)))
                                                                          for p in seen) + "\n")
    report = run_compensation(CompensateSettings(calibration=tmp_path / "far_discover.calibration.json",
                                                 targets=tmp_path / "targets.csv", out=tmp_path / "cmd.csv",
                                                 frame="instrument"))
    assert report.summary["compensated"] == answers["far"][1]
    _, commands = read_command_file(tmp_path / "cmd.csv", rec.robot)
    pos = ~rec.robot.angle_pose_mask
    error = np.mean(np.linalg.norm((command_scenario_machine(rec, commands, t_s) - targets)[:, pos], axis=1))
    assert error <= 1.5 * rec.noise.pose_std(("mm",))[0], error
