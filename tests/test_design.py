import itertools

import numpy as np
import pytest

import calib.robots
from calib import paper
from calib.design import (
    DEFAULT_PASSIVE_JOINT_LIMIT_RAD,
    Workspace,
    design_poses,
    feasibility,
    minimum_poses,
    reachable_joints,
    robot_workspace,
    sample_feasible_poses,
    scaled_condition,
    select_poses,
)
from calib.noise import SensorNoise
from calib.observability import analyze_observability, identification_jacobian, parameter_scale
from calib.robot import check_joint_limits
from calib.robots import default_robot, reference_poses
from calib.robots.hexapod import FULL_WORKSPACE_OFFSETS

from linalg_tolerance import column_scaled_condition, gram_inverse_tolerance

NOISE = SensorNoise(position_mm=1e-3, orientation_rad=1e-6, distribution="normal")
ROBOTS = sorted(calib.robots.ROBOTS)
HEXAPOD = default_robot("hexapod")
DELTA = default_robot("delta")
HOME = HEXAPOD.home_pose[None]


def test_hexapod_workspaces():
    full, default = robot_workspace(HEXAPOD, "full"), robot_workspace(HEXAPOD, "default")
    np.testing.assert_array_equal(full.bounds, [[-80, 80], [-80, 80], [150, 260], [-np.deg2rad(25), np.deg2rad(25)],
                                                [-np.deg2rad(25), np.deg2rad(25)], [-np.deg2rad(25), np.deg2rad(25)]])
    np.testing.assert_array_equal(full.bounds, HEXAPOD.home_pose[:, None] + FULL_WORKSPACE_OFFSETS)
    np.testing.assert_allclose(default.bounds, [[-10, 10], [-10, 10], [200, 210], [-np.deg2rad(3), np.deg2rad(3)],
                                                [-np.deg2rad(3), np.deg2rad(3)], [-np.deg2rad(3), np.deg2rad(3)]])
    assert full.passive_joint_limit_rad == pytest.approx(np.deg2rad(45.0)) and full.max_condition == 10.0
    np.testing.assert_allclose(HEXAPOD.joint_limits(), HEXAPOD.home_lengths[:, None] + [-50.0, 50.0])


@pytest.mark.parametrize("name", ROBOTS)
def test_workspace_round_trip_and_names(name):
    robot = default_robot(name)
    ws = robot_workspace(robot, "full")
    assert ws.name == "full" and ws.bounds.shape == (robot.pose_dim, 2)
    np.testing.assert_array_equal(robot_workspace(robot, "default").bounds, robot.workspace_bounds())
    np.testing.assert_array_equal(ws.bounds, robot.full_workspace_bounds())
    back = Workspace.from_dict(ws.to_dict())
    np.testing.assert_array_equal(back.bounds, ws.bounds)
    assert back.to_dict() == ws.to_dict()
    with pytest.raises(ValueError):
        ws.bounds[0, 0] = 1.0  # frozen array


@pytest.mark.parametrize("kwargs, match", [
    ({"bounds": np.zeros(5)}, r"bounds must have shape \(N, 2\), got \(5,\)"),
    ({"bounds": HEXAPOD.full_workspace_bounds()[:, ::-1]}, "bounds must have low <= high, got row 0"),
    ({"bounds": np.zeros((3, 2)), "passive_joint_limit_rad": 4.0}, "passive_joint_limit_rad must be a finite number"),
    ({"bounds": np.zeros((3, 2)), "max_condition": 0.5}, "max_condition must be a finite number"),
    ({"bounds": np.zeros((3, 2)), "max_condition": float("nan")}, "max_condition must be a finite number"),
])
def test_workspace_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Workspace(**kwargs)


def test_workspace_names_and_dimensions_are_checked():
    with pytest.raises(ValueError, match="workspace must be one of full, default, got 'huge'"):
        robot_workspace(HEXAPOD, "huge")
    with pytest.raises(ValueError, match=r"workspace bounds must have 3 rows \(x, y, z\) for the delta, got 6"):
        feasibility(DELTA, DELTA.table.nominal, np.zeros((1, 3)), robot_workspace(HEXAPOD, "full"))


def test_hexapod_cone_angles_at_home_match_geometry():
    d = HEXAPOD.platform_joints + HEXAPOD.home_pose[:3] - HEXAPOD.base_joints
    expected = np.arctan2(np.linalg.norm(d[:, :2], axis=1), d[:, 2])
    a = HEXAPOD.passive_joint_angles(HEXAPOD.table.nominal, HOME)[0].reshape(6, 2)
    np.testing.assert_allclose(a[:, 0], expected, atol=1e-12)
    np.testing.assert_allclose(a[:, 1], expected, atol=1e-12)  # platform parallel to base


def test_hexapod_platform_cone_angle_follows_tilt():
    tilt = 0.1
    pose = HOME.copy()
    pose[0, 4] = tilt
    a = HEXAPOD.passive_joint_angles(HEXAPOD.table.nominal, pose)[0].reshape(6, 2)
    Ry = np.array([[np.cos(tilt), 0, np.sin(tilt)], [0, 1, 0], [-np.sin(tilt), 0, np.cos(tilt)]])
    u = HEXAPOD.platform_joints @ Ry.T + pose[0, :3] - HEXAPOD.base_joints
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    normal = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    np.testing.assert_allclose(a[:, 1], np.arccos(u @ normal), atol=1e-12)
    np.testing.assert_allclose(a[:, 0], np.arccos(u[:, 2]), atol=1e-12)


def test_robots_without_passive_joint_limits_report_none():
    assert DELTA.passive_joint_angles(DELTA.table.nominal, DELTA.home_pose[None]).shape == (1, 0)


@pytest.mark.parametrize("name", ROBOTS)
def test_scaled_condition_of_the_finite_difference_pose_jacobian(name):
    robot = default_robot(name)
    theta = robot.table.nominal
    poses = sample_feasible_poses(robot, theta, robot_workspace(robot, "default"), 4, 0)
    q = robot.inverse_kinematics(theta, poses)
    h = 1e-6
    J = np.stack([(robot.closure(theta, q, poses + h * e) - robot.closure(theta, q, poses - h * e)) / (2 * h)
                  for e in np.eye(robot.pose_dim)], axis=-1)
    scale = np.where(robot.angle_pose_mask, robot.length_scale_mm, 1.0)
    # central differences, h = 1e-6: rounding eps |pose| / h ~ 1e-8 relative to J, amplified by
    # 2 cond (1.1 to 7 here) in the condition number; truncation ~h^2
    np.testing.assert_allclose(scaled_condition(robot, theta, poses), np.linalg.cond(J / scale), rtol=1e-6)


def test_reference_poses_feasible_in_the_default_workspace():
    f = feasibility(HEXAPOD, HEXAPOD.table.nominal, paper.TABLE4_NOMINAL_POSES, robot_workspace(HEXAPOD, "default"))
    assert all(v.all() for v in f.values())
    np.testing.assert_array_equal(reference_poses(HEXAPOD), paper.TABLE4_NOMINAL_POSES)


EVERYWHERE = Workspace(bounds=np.c_[np.full(6, -1e3), np.full(6, 1e3)])


@pytest.mark.parametrize("pose, failing, workspace", [
    ([0, 0, 200, 0, 0, 0.2], "bounds", robot_workspace(HEXAPOD, "default")),  # outside the paper's box
    ([0, 0, 270, 0, 0, 0], "joint_limits", EVERYWHERE),                        # legs too long
    ([60, 0, 170, 0, 0, 0], "passive_joints", EVERYWHERE),                     # legs steeply inclined
])
def test_hexapod_feasibility_names_the_limit(pose, failing, workspace):
    f = feasibility(HEXAPOD, HEXAPOD.table.nominal, np.array([pose], float), workspace)
    assert not f[failing][0] and not f["feasible"][0]
    assert sum(not v[0] for k, v in f.items() if k != "feasible") == 1


def test_delta_feasibility_names_reach_and_joint_limits():
    ws = Workspace(bounds=np.c_[np.full(3, -1e4), np.full(3, 1e4)])
    poses = np.array([[0, 0, -420.0], [0, 0, -1000.0], [0, 0, 200.0]])
    f = feasibility(DELTA, DELTA.table.nominal, poses, ws)
    np.testing.assert_array_equal(f["reach"], [True, False, True])
    q = DELTA.inverse_kinematics(DELTA.table.nominal, poses[2:])
    assert np.all(q > DELTA.joint_limits()[:, 1])  # the plate above the base: arms beyond 90 degrees
    np.testing.assert_array_equal(f["joint_limits"], [True, False, False])
    np.testing.assert_array_equal(f["feasible"], [True, False, False])


def test_reachable_joints_skips_the_unreachable_rows():
    rng = np.random.default_rng(0)
    poses = rng.uniform([-300, -300, -900], [300, 300, -200], (700, 3))
    ok, q = reachable_joints(DELTA, DELTA.table.nominal, poses)
    assert 0 < ok.sum() < len(ok)
    for k in range(0, 700, 7):
        try:
            np.testing.assert_allclose(q[k], DELTA.inverse_kinematics(DELTA.table.nominal, poses[k:k + 1])[0], atol=0)
            assert ok[k]
        except ValueError:
            assert not ok[k] and np.all(np.isnan(q[k]))


@pytest.mark.parametrize("name", ROBOTS)
def test_singularity_limit(name):
    robot = default_robot(name)
    home = robot.home_pose[None]
    cond = scaled_condition(robot, robot.table.nominal, home)[0]
    ws = Workspace(bounds=np.c_[np.full(robot.pose_dim, -1e4), np.full(robot.pose_dim, 1e4)],
                   max_condition=max(1.0 + 1e-9, 0.99 * cond))
    f = feasibility(robot, robot.table.nominal, home, ws)
    assert not f["singularity"][0] and f["joint_limits"][0] and f["reach"][0]


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("workspace", ["full", "default"])
def test_sampled_poses_feasible_and_seeded(name, workspace):
    robot = default_robot(name)
    ws = robot_workspace(robot, workspace)
    theta = robot.table.nominal
    a = sample_feasible_poses(robot, theta, ws, 50, 3)
    b = sample_feasible_poses(robot, theta, ws, 50, 3)
    c = sample_feasible_poses(robot, theta, ws, 50, 4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert a.shape == (50, robot.pose_dim) and feasibility(robot, theta, a, ws)["feasible"].all()
    assert np.all((a >= ws.bounds[:, 0]) & (a <= ws.bounds[:, 1]))
    check_joint_limits(robot, robot.inverse_kinematics(theta, a))
    assert np.all(robot.passive_joint_angles(theta, a) <= DEFAULT_PASSIVE_JOINT_LIMIT_RAD)


@pytest.mark.parametrize("name", ROBOTS)
def test_empty_workspace_raises(name):
    robot = default_robot(name)
    far = robot.full_workspace_bounds()[:, :1] + 1e4 + np.zeros((robot.pose_dim, 2))
    with pytest.raises(ValueError, match="only 0 of 5 feasible poses"):
        sample_feasible_poses(robot, robot.table.nominal, Workspace(bounds=far), 5, 0, max_draws=1500)


CANDIDATES = {name: sample_feasible_poses(default_robot(name), default_robot(name).table.nominal,
                                          robot_workspace(default_robot(name), "full"), 40, 11) for name in ROBOTS}


def _logdet(robot, poses):
    A = identification_jacobian(robot, robot.table.nominal, poses, NOISE)
    return np.linalg.slogdet(A.T @ A)[1]


def _n_design(robot):
    return minimum_poses(robot) + 1


@pytest.mark.parametrize("name", ROBOTS)
def test_d_optimal_no_single_exchange_improves(name):
    robot, cands = default_robot(name), CANDIDATES[name]
    n = _n_design(robot)
    res = select_poses(robot, robot.table.nominal, cands, n, NOISE, criterion="d")
    # log det of the scaled information = log det of the raw one minus the scale's
    offset = 2 * np.sum(np.log(parameter_scale(robot)[[robot.table.index(k) for k in robot.free_default]]))
    # log det F to an absolute |tr(F^-1 dF)| <~ K eps cond(F scaled) (tests/linalg_tolerance.py):
    # the rus's design, cond(F scaled) ~ 4e10, gets 1.4e-7 between two computations
    A = identification_jacobian(robot, robot.table.nominal, res.poses, NOISE)
    tol = gram_inverse_tolerance(column_scaled_condition(A), A.shape[1])
    assert res.log_det == pytest.approx(_logdet(robot, res.poses) - offset, abs=tol)
    best = _logdet(robot, res.poses)
    others = [c for c in range(len(cands)) if c not in set(res.indices)]
    for k, c in itertools.product(range(n), others):
        idx = res.indices.copy()
        idx[k] = c
        assert _logdet(robot, cands[idx]) <= best + tol
    assert len(set(res.indices.tolist())) == n


@pytest.mark.parametrize("name", ROBOTS)
def test_d_optimal_beats_random_subsets(name):
    robot, cands = default_robot(name), CANDIDATES[name]
    n = _n_design(robot)
    best = _logdet(robot, select_poses(robot, robot.table.nominal, cands, n, NOISE, criterion="d").poses)
    rng = np.random.default_rng(0)
    for _ in range(30):
        assert _logdet(robot, cands[rng.choice(len(cands), n, replace=False)]) < best


@pytest.mark.parametrize("name", ROBOTS)
def test_e_optimal_improves_lambda_min_over_d(name):
    robot, cands = default_robot(name), CANDIDATES[name]
    n = _n_design(robot)
    d = select_poses(robot, robot.table.nominal, cands, n, NOISE, criterion="d")
    e = select_poses(robot, robot.table.nominal, cands, n, NOISE, criterion="e")
    assert e.lambda_min >= d.lambda_min
    a = analyze_observability(robot, robot.table.nominal, e.poses, NOISE)
    # lambda_min by eigvalsh vs sigma_min^2 by SVD: each to ~K eps lambda_max absolute (Weyl)
    assert a.o3 ** 2 == pytest.approx(e.lambda_min, rel=gram_inverse_tolerance(a.condition_number, a.n_free))


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("criterion", ["d", "e"])
def test_design_is_seeded_and_feasible(name, criterion):
    robot = default_robot(name)
    ws = robot_workspace(robot, "full")
    n = max(10, minimum_poses(robot))
    a = design_poses(robot, robot.table.nominal, n, ws, NOISE, criterion=criterion, seed=5, n_candidates=300)
    b = design_poses(robot, robot.table.nominal, n, ws, NOISE, criterion=criterion, seed=5, n_candidates=300)
    np.testing.assert_array_equal(a.poses, b.poses)
    assert feasibility(robot, robot.table.nominal, a.poses, ws)["feasible"].all()


def test_full_workspace_design_beats_paper_poses_tenfold():
    design = design_poses(HEXAPOD, HEXAPOD.table.nominal, 10, robot_workspace(HEXAPOD, "full"), NOISE, seed=0,
                          n_candidates=1000)
    rms_design = analyze_observability(HEXAPOD, HEXAPOD.table.nominal, design.poses, NOISE).crb_rms
    rms_paper = analyze_observability(HEXAPOD, HEXAPOD.table.nominal, paper.TABLE4_NOMINAL_POSES, NOISE).crb_rms
    assert rms_paper / rms_design >= 10.0


def test_delta_full_workspace_design_beats_random_poses():
    ws = robot_workspace(DELTA, "full")
    design = design_poses(DELTA, DELTA.table.nominal, 10, ws, NOISE, seed=0, n_candidates=1000)
    rms_design = analyze_observability(DELTA, DELTA.table.nominal, design.poses, NOISE).crb_rms
    for seed in range(5):
        random = sample_feasible_poses(DELTA, DELTA.table.nominal, ws, 10, seed)
        assert analyze_observability(DELTA, DELTA.table.nominal, random, NOISE).crb_rms > 2 * rms_design


NOM = HEXAPOD.table.nominal
CANDS = CANDIDATES["hexapod"]


@pytest.mark.parametrize("call, match", [
    (lambda: select_poses(HEXAPOD, NOM, CANDS, 8, NOISE, criterion="a"), "criterion must be one of"),
    (lambda: select_poses(HEXAPOD, NOM, CANDS, 6, NOISE), "n must be an integer >= 7, got 6"),
    (lambda: select_poses(HEXAPOD, NOM, CANDS, 8.0, NOISE), "n must be an integer >= 7"),
    (lambda: select_poses(HEXAPOD, NOM, CANDS[:7], 8, NOISE), "candidates must have at least n = 8 rows, got 7"),
    (lambda: select_poses(HEXAPOD, NOM, CANDS[:, :5], 8, NOISE), r"candidates must have shape \(N, 6\)"),
    (lambda: select_poses(HEXAPOD, NOM, CANDS, 8, NOISE, screen=0), "screen must be an integer >= 1"),
    (lambda: select_poses(DELTA, DELTA.table.nominal, CANDIDATES["delta"], 6, NOISE), "n must be an integer >= 7"),
    (lambda: design_poses(HEXAPOD, NOM, 10, robot_workspace(HEXAPOD, "full"), NOISE, n_candidates=5),
     "n_candidates must be an integer >= 10"),
    (lambda: sample_feasible_poses(HEXAPOD, NOM, robot_workspace(HEXAPOD, "full"), -1, 0), "n must be an integer >= 0"),
    (lambda: feasibility(HEXAPOD, NOM, np.zeros(6), robot_workspace(HEXAPOD, "full")),
     r"poses must have shape \(N, 6\), got \(6,\)"),
    (lambda: feasibility(HEXAPOD, np.zeros(24), HOME, robot_workspace(HEXAPOD, "full")),
     r"theta must have shape \(42,\), got \(24,\)"),
])
def test_selection_validation(call, match):
    with pytest.raises(ValueError, match=match):
        call()


@pytest.mark.parametrize("call, match", [
    (lambda: feasibility("hexapod", NOM, HOME, robot_workspace(HEXAPOD, "full")), "robot must be a calib.robot.Robot"),
    (lambda: feasibility(HEXAPOD, NOM, HOME, "full"), "workspace must be a Workspace"),
    (lambda: robot_workspace(None, "full"), "robot must be a calib.robot.Robot"),
    (lambda: scaled_condition(None, NOM, HOME), "robot must be a calib.robot.Robot"),
])
def test_type_validation(call, match):
    with pytest.raises(TypeError, match=match):
        call()


def _with_ranges(robot, low, high):
    """``robot`` with its joints' ranges declared as ``home joint value + [low, high]`` (joint unit)."""
    home = robot.inverse_kinematics(robot.table.nominal, robot.home_pose[None])[0]
    description = dict(robot.description(), joint_ranges=np.stack([home + low, home + high], axis=1).tolist())
    return type(robot).from_description(description)


def test_the_full_workspace_reaches_as_far_as_legs_declared_longer_allow():
    """Legs that extend 150 mm above home (one-sided, as a machine built by hand): the "full" box
    widens along each coordinate to the last feasible pose through home; the pose one grid step
    further out is not feasible (or the widening's cap was reached)."""
    from calib.design import WIDENING_FACTOR, WIDENING_STEPS, widened_to_joint_ranges

    plain = default_robot("hexapod")
    robot = _with_ranges(plain, -20.0, 150.0)
    box = plain.full_workspace_bounds()
    wide = robot_workspace(robot, "full").bounds
    assert np.all(wide[:, 0] <= box[:, 0]) and np.all(wide[:, 1] >= box[:, 1])  # never narrower
    assert wide[2, 1] > box[2, 1] + 50.0  # the platform goes higher than the default box allows
    np.testing.assert_array_equal(widened_to_joint_ranges(robot, box), wide)
    home, half = robot.home_pose, 0.5 * np.ptp(box, axis=1)
    step = WIDENING_FACTOR / WIDENING_STEPS * half
    ws = Workspace(bounds=home[:, None] + WIDENING_FACTOR * np.stack([-half, half], axis=1) + [-1.0, 1.0])
    for k in range(robot.pose_dim):
        for end, side in ((0, -1.0), (1, 1.0)):
            if wide[k, end] == box[k, end]:
                continue
            at = np.tile(home, (2, 1))
            at[:, k] = [wide[k, end], wide[k, end] + side * step[k]]
            ok = feasibility(robot, robot.table.nominal, at, ws)["feasible"]
            capped = abs(wide[k, end] - home[k]) >= WIDENING_FACTOR * half[k] * (1 - 1e-12)
            assert ok[0] and (capped or not ok[1]), (robot.pose_names[k], end, wide[k, end], ok)


def test_the_full_workspace_is_the_robots_box_without_declared_ranges_or_with_narrow_ones():
    for name in ("hexapod", "delta", "rus"):
        robot = default_robot(name)
        np.testing.assert_array_equal(robot_workspace(robot, "full").bounds, robot.full_workspace_bounds())
    # Ranges that stop short of the box: the box stays (the design's checks cut it).
    narrow = _with_ranges(default_robot("hexapod"), -5.0, 5.0)
    np.testing.assert_array_equal(robot_workspace(narrow, "full").bounds, narrow.full_workspace_bounds())
