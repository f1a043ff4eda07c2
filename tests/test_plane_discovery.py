"""Discovery on a level grid of poses (one height, no tilt): the kinematic hexapod with geometric
errors of 1 to 3 mm, 0.3 mm / 1.5 mrad capture noise, a 5 mm tolerance declared (issue 37 point 3)."""

import json

import numpy as np
import pytest

from calib.effects import EffectData
from calib.effects.discovery import discover_effects, fit_effects, remainder_tests
from calib.noise import SensorNoise
from calib.robots import default_robot
from pipeline.discover import main
from pipeline.formats import write_recording
from pipeline.simulation import make_recording

ROBOT = default_robot("hexapod")
NOISE = SensorNoise(0.3, 1.5e-3, "normal")
TOLERANCE = {"mm": 5.0}


def level_grid_recording(noise_seed: int, *, dead_band: float = 0.0, lost: tuple | None = None,
                         row_order: bool = False):
    """A 10 x 10 level grid at z = 200 mm (x, y over +-20 mm, no tilt, raster order) measured on a
    machine with seeded errors of 1 to 3 mm on every parameter; optional dead band (mm, every leg:
    each leg stops ``dead_band`` short in the direction it moved) and lost count ``(leg, first
    row 0-based, step mm)``. ``row_order``: the sidecar says the time is the rows' order."""
    rng = np.random.default_rng(1)
    free = ROBOT.table.indices(ROBOT.free_default)
    theta = ROBOT.table.nominal.copy()
    theta[free] += rng.uniform(1, 3, free.size) * rng.choice([-1, 1], free.size)
    g = np.linspace(-20, 20, 10)
    X, Y = np.meshgrid(g, g)
    poses = np.zeros((X.size, 6))
    poses[:, 0], poses[:, 1], poses[:, 2] = X.ravel(), Y.ravel(), 200.0
    joints = ROBOT.inverse_kinematics(ROBOT.table.nominal, poses)
    t = np.arange(len(poses), dtype=float)
    shift = -dead_band * EffectData(ROBOT, ROBOT.table.nominal, joints, poses, t, NOISE).direction
    if lost is not None:
        leg, row, step = lost
        shift[row:, leg] += step
    true = ROBOT.forward_kinematics(theta, joints + shift, initial=poses)
    measured = true + NOISE.sample(len(poses), noise_seed, ROBOT.pose_units)
    rec = make_recording(ROBOT, t, joints, measured, NOISE, meta={"parameter_tolerance": TOLERANCE})
    if row_order:
        from dataclasses import replace
        rec = replace(rec, session_info={"1": {"time": "row order"}})
    return rec


def run(tmp_path, rec, capsys):
    path, _ = write_recording(tmp_path / "grid.csv", rec)
    summary = tmp_path / "s.json"
    assert main(["--real", str(path), "--out", str(tmp_path), "--no-resim", "--summary-json", str(summary)]) == 0
    return json.loads(summary.read_text()), capsys.readouterr().out


def test_a_level_grid_runs_names_what_it_cannot_separate_and_claims_no_effect(tmp_path, capsys):
    s, out = run(tmp_path, level_grid_recording(6), capsys)
    assert s["effects"] == []  # nothing injected, nothing claimed
    assert s["explained"] and out.startswith("Explained")  # and the verdict agrees with the remainder at the noise
    assert 0 < s["heldout_rms_after_mm"] < 2 * s["noise_floor_mm"]
    sep = s["separation"]
    # Per leg the plane shows only P - B in x and y and one mix of height and offset: 3 of 7.
    assert sep["free"] == 42 and sep["determined"] == 18 and len(sep["left_to_prior"]) == 24
    assert any("B1.z" in c["combination"] and "P1.z" in c["combination"] for c in sep["left_to_prior"])
    # An actuator scale acts on a plane as leg offsets and heights: named, never found.
    unsep = {u["effect"]: u for u in sep["unseparated"]}
    assert "actuator_scale" in unsep and unsep["actuator_scale"]["separated_by"]
    assert "Cannot be separated on this pose set: actuator_scale" in out
    assert "Held-out residual RMS" in out


@pytest.mark.parametrize("noise_seed", range(1, 11))
def test_on_a_level_grid_with_nothing_left_out_the_remainder_is_the_noise(noise_seed):
    """Geometry alone on a level grid whose rows are geometry and noise: the remainder's tests find
    no structure. The columns of the combinations held (and what the geometry leaves of a
    position or a load) are taken at the poses the model reaches: at the measured poses they were
    built of the measured tilt's noise and every seed's remainder 'followed' stroke, load or a
    position at p = 1e-9 to 1e-23 (the Bonferroni-corrected level is 0.01)."""
    rec = level_grid_recording(noise_seed)
    data = EffectData(ROBOT, ROBOT.table.nominal, rec.joints, rec.measured, rec.t_s, NOISE,
                      tolerance=np.full(ROBOT.n_parameters, TOLERANCE["mm"]))
    fit = fit_effects(data)
    assert fit.basis is not None and fit.held_design.shape[1] == 24  # the plane leaves 24 to the prior
    tests = remainder_tests(data, fit)
    assert tests.noise.consistent
    assert tests.explained, {q.quantity: q.p_value for q in tests.structure}


@pytest.mark.parametrize("noise_seed", [1, 3, 4, 5, 8])
def test_on_a_level_grid_with_nothing_left_out_discovery_names_nothing_and_explains_the_rows(noise_seed):
    """The whole search on the same grids: no effect named, the rows explained. With the effects'
    regressors and the position and load quantities taken at the measured poses (their noise in
    them) seeds 3, 4 and 8 were left 'NOT explained' (following a position or the load) and seed 5
    named a compliance."""
    rec = level_grid_recording(noise_seed)
    data = EffectData(ROBOT, ROBOT.table.nominal, rec.joints, rec.measured, rec.t_s, NOISE,
                      tolerance=np.full(ROBOT.n_parameters, TOLERANCE["mm"]))
    found = discover_effects(data, laws=False)
    assert found.effects == ()
    assert found.explained, found.remaining.summary


def test_a_dead_band_shows_on_a_plane_and_is_found(tmp_path, capsys):
    s, _ = run(tmp_path, level_grid_recording(6, dead_band=1.0), capsys)
    assert s["effects"] == ["joint_friction"]
    p = s["effect_parameters"]["joint_friction"]
    band = p.get("dead_band") or p[next(k for k in p if k.startswith("dead_band"))]
    assert abs(band["value"] - 1.0) < 5 * band["std"]
    assert s["heldout_rms_after_mm"] < s["heldout_rms_before_mm"]


@pytest.mark.parametrize("noise_seed", [3, 6, 8])
def test_a_two_millimetre_dead_band_on_a_plane_is_found_and_no_row_flagged(noise_seed):
    """The outlier scan's leverage from the columns fitted alone: with the held combinations'
    columns in its hat matrix, the grid's first row (the move from home, which a held column alone
    moves) had leverage near one, was flagged on these seeds, and without it the dead band was
    lost on seeds 3 and 8."""
    rec = level_grid_recording(noise_seed, dead_band=2.0)
    data = EffectData(ROBOT, ROBOT.table.nominal, rec.joints, rec.measured, rec.t_s, NOISE,
                      tolerance=np.full(ROBOT.n_parameters, TOLERANCE["mm"]))
    found = discover_effects(data, laws=False)
    assert found.effects == ("joint_friction",) and found.explained, found.remaining.summary
    assert found.flagged == ()


def test_a_lost_count_on_a_plane_is_found_with_its_leg_row_and_step(tmp_path, capsys):
    """3 mm lost on leg 3 from the 51st row of the grid (row 50, 0-based); before the columns were
    taken at the model's poses, the plane's remainder 'followed' position y, time and stroke and
    nothing was named."""
    s, _ = run(tmp_path, level_grid_recording(6, lost=(2, 50, 3.0)), capsys)
    assert s["effects"] == ["lost_count"] and s["explained"]
    p = s["effect_parameters"]["lost_count"]
    assert p["joint"]["value"] == 3 and p["from_row"]["value"] == 51
    assert abs(p["step"]["value"] - 3.0) < 5 * p["step"]["std"]


def test_a_lost_count_on_a_recording_without_time_is_placed_by_row(tmp_path, capsys):
    """A recording whose time is its rows' order (a lab export with ``[time] format = "none"``):
    the lost count is said from its row, never at a time."""
    from dataclasses import replace

    from pipeline.simulation import effect_recording

    rec = effect_recording("lost_count", 3, n_poses=120, magnitude_noise=10.0)
    first = int(np.argmax(rec.t_s > rec.meta["simulation"]["step_time"])) + 1  # 1-based: the first row after it
    rec = replace(rec, t_s=np.arange(len(rec.t_s), dtype=float), session_info={"1": {"time": "row order"}})
    s, out = run(tmp_path, rec, capsys)
    assert s["time"] == "row order" and s["effects"] == ["lost_count"]
    p = s["effect_parameters"]["lost_count"]
    assert "step_time" not in p
    assert p["from_row"]["value"] == first
    assert f"from row {p['from_row']['value']:.0f}" in out
    said = out.split("Left-out physics")[1].split("Held-out")[0]
    assert "step_time" not in said and not any(line.rstrip().endswith(" s") for line in said.splitlines())


@pytest.mark.parametrize("name", ["delta", "rus"])
def test_the_other_robots_level_grids_with_nothing_left_out_are_explained(name):
    """The same contract on the Delta's and the 6-RUS's level grids (10 x 10 over the middle 80% of
    the workspace's x and y at the home height; errors of 1 to 3 mm and 0.01 to 0.03 rad on every
    free parameter; tolerances 5 mm and 0.05 rad). Both were explained before the hexapod's fix as
    well (no tilt is read on the Delta; the 6-RUS's held columns were not the noise's): this holds
    the fix to them."""
    robot = default_robot(name)
    rng = np.random.default_rng(1)
    free = robot.table.indices(robot.free_default)
    angle = np.array([u == "rad" for u in robot.table.units])
    theta = robot.table.nominal.copy()
    theta[free] += rng.uniform(1, 3, free.size) * rng.choice([-1, 1], free.size) * np.where(angle[free], 0.01, 1.0)
    b = robot.workspace_bounds()
    g = np.linspace(-0.4, 0.4, 10)
    X, Y = np.meshgrid(b[0].mean() + g * np.ptp(b[0]), b[1].mean() + g * np.ptp(b[1]))
    poses = np.tile(robot.home_pose, (X.size, 1))
    poses[:, 0], poses[:, 1] = X.ravel(), Y.ravel()
    joints = robot.inverse_kinematics(robot.table.nominal, poses)
    measured = robot.forward_kinematics(theta, joints, initial=poses) + NOISE.sample(len(poses), 1, robot.pose_units)
    data = EffectData(robot, robot.table.nominal, joints, measured, np.arange(len(poses), dtype=float), NOISE,
                      tolerance=np.where(angle, 0.05, 5.0))
    found = discover_effects(data, laws=False)
    assert found.geometry.basis is not None and found.geometry.held_design.shape[1] > 0  # a plane holds some
    assert found.effects == () and found.explained, found.remaining.summary
