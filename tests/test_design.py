import itertools

import numpy as np
import pytest

from calib import paper
from calib.design import (
    FULL_WORKSPACE_BOUNDS,
    Workspace,
    design_poses,
    feasibility,
    full_workspace,
    joint_cone_angles,
    paper_workspace,
    sample_feasible_poses,
    scaled_condition,
    select_poses,
    workspace_by_name,
)
from calib.hexapod import paper_hexapod
from calib.kinematics import inverse_kinematics, pose_jacobian
from calib.noise import SensorNoise
from calib.observability import analyze_observability, identification_jacobian

NOMINAL = paper_hexapod()
NOISE = SensorNoise(position_mm=1e-3, orientation_rad=1e-6, distribution="normal")
HOME = NOMINAL.geometry.home_pose[None]


def test_workspace_defaults_and_round_trip():
    ws = full_workspace()
    np.testing.assert_array_equal(ws.bounds, FULL_WORKSPACE_BOUNDS)
    assert ws.stroke_mm == 50.0 and ws.cone_limit_rad == pytest.approx(np.deg2rad(45.0))
    back = Workspace.from_dict(ws.to_dict())
    np.testing.assert_array_equal(back.bounds, ws.bounds)
    assert back.to_dict() == ws.to_dict()
    assert workspace_by_name("paper").to_dict() == paper_workspace().to_dict()
    with pytest.raises(ValueError):
        ws.bounds[0, 0] = 1.0  # frozen array


@pytest.mark.parametrize("kwargs, match", [
    ({"bounds": np.zeros((5, 2))}, r"bounds must have shape \(6, 2\), got \(5, 2\)"),
    ({"bounds": FULL_WORKSPACE_BOUNDS[:, ::-1]}, "bounds must have low <= high, got row 0"),
    ({"stroke_mm": 0.0}, "stroke_mm must be a finite number"),
    ({"cone_limit_rad": 2.0}, "cone_limit_rad must be a finite number"),
    ({"max_condition": 0.5}, "max_condition must be a finite number"),
    ({"max_condition": float("nan")}, "max_condition must be a finite number"),
])
def test_workspace_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Workspace(**kwargs)


def test_workspace_by_name_rejects_unknown():
    with pytest.raises(ValueError, match="workspace must be 'full' or 'paper', got 'huge'"):
        workspace_by_name("huge")


def test_cone_angles_at_home_match_geometry():
    g = NOMINAL.geometry
    d = g.platform_joints + g.home_pose[:3] - g.base_joints
    expected = np.arctan2(np.linalg.norm(d[:, :2], axis=1), d[:, 2])
    a = joint_cone_angles(NOMINAL, HOME)[0]
    np.testing.assert_allclose(a[:, 0], expected, atol=1e-12)
    np.testing.assert_allclose(a[:, 1], expected, atol=1e-12)  # platform parallel to base


def test_platform_cone_angle_follows_tilt():
    tilt = 0.1
    pose = HOME.copy()
    pose[0, 4] = tilt
    a = joint_cone_angles(NOMINAL, pose)[0]
    Ry = np.array([[np.cos(tilt), 0, np.sin(tilt)], [0, 1, 0], [-np.sin(tilt), 0, np.cos(tilt)]])
    u = NOMINAL.platform_joints @ Ry.T + pose[0, :3] - NOMINAL.base_joints
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    normal = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    np.testing.assert_allclose(a[:, 1], np.arccos(u @ normal), atol=1e-12)


def test_scaled_condition_uses_platform_radius():
    poses = paper.TABLE4_NOMINAL_POSES
    r = np.linalg.norm(NOMINAL.platform_joints, axis=1).mean()
    expected = np.linalg.cond(pose_jacobian(NOMINAL, poses) * np.r_[1, 1, 1, 1 / r, 1 / r, 1 / r])
    np.testing.assert_allclose(scaled_condition(NOMINAL, poses), expected)


def test_paper_poses_feasible_in_paper_workspace():
    f = feasibility(NOMINAL, paper.TABLE4_NOMINAL_POSES, paper_workspace())
    assert all(v.all() for v in f.values())


@pytest.mark.parametrize("pose, failing", [
    ([0, 0, 200, 0, 0, 0.2], "bounds"),          # outside the paper box
    ([0, 0, 270, 0, 0, 0], "stroke"),            # legs too long
    ([60, 0, 170, 0, 0, 0], "cone"),             # legs steeply inclined
])
def test_feasibility_names_the_limit(pose, failing):
    ws = paper_workspace() if failing == "bounds" else Workspace(bounds=np.c_[np.full(6, -1e3), np.full(6, 1e3)])
    f = feasibility(NOMINAL, np.array([pose], float), ws)
    assert not f[failing][0] and not f["feasible"][0]


def test_singularity_limit():
    ws = Workspace(bounds=np.c_[np.full(6, -1e3), np.full(6, 1e3)], max_condition=2.0)
    f = feasibility(NOMINAL, HOME, ws)  # home has a scaled condition number of about 2.4
    assert scaled_condition(NOMINAL, HOME)[0] > 2.0
    assert not f["singularity"][0] and f["stroke"][0]


@pytest.mark.parametrize("name", ["full", "paper"])
def test_sampled_poses_feasible_and_seeded(name):
    ws = workspace_by_name(name)
    a = sample_feasible_poses(NOMINAL, ws, 50, 3)
    b = sample_feasible_poses(NOMINAL, ws, 50, 3)
    c = sample_feasible_poses(NOMINAL, ws, 50, 4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert a.shape == (50, 6) and feasibility(NOMINAL, a, ws)["feasible"].all()
    inverse_kinematics(NOMINAL, a, stroke_mm=ws.stroke_mm)  # within the stroke


def test_empty_workspace_raises():
    ws = Workspace(bounds=np.array([[0, 0], [0, 0], [400, 410], [0, 0], [0, 0], [0, 0]], float))
    with pytest.raises(ValueError, match="only 0 of 5 feasible poses"):
        sample_feasible_poses(NOMINAL, ws, 5, 0, max_draws=5000)


CANDIDATES = sample_feasible_poses(NOMINAL, full_workspace(), 40, 11)


def _logdet(poses):
    A = identification_jacobian(NOMINAL, poses, NOISE)
    return np.linalg.slogdet(A.T @ A)[1]


def test_d_optimal_no_single_exchange_improves():
    res = select_poses(NOMINAL, CANDIDATES, 8, NOISE, criterion="d")
    assert res.log_det == pytest.approx(_logdet(res.poses), rel=1e-9)
    others = [c for c in range(len(CANDIDATES)) if c not in set(res.indices)]
    for k, c in itertools.product(range(8), others):
        idx = res.indices.copy()
        idx[k] = c
        assert _logdet(CANDIDATES[idx]) <= res.log_det + 1e-7
    assert len(set(res.indices.tolist())) == 8


def test_d_optimal_beats_random_subsets():
    res = select_poses(NOMINAL, CANDIDATES, 8, NOISE, criterion="d")
    rng = np.random.default_rng(0)
    for _ in range(30):
        assert _logdet(CANDIDATES[rng.choice(len(CANDIDATES), 8, replace=False)]) < res.log_det


def test_e_optimal_improves_lambda_min_over_d():
    d = select_poses(NOMINAL, CANDIDATES, 8, NOISE, criterion="d")
    e = select_poses(NOMINAL, CANDIDATES, 8, NOISE, criterion="e")
    assert e.lambda_min >= d.lambda_min
    a = analyze_observability(NOMINAL, e.poses, NOISE)
    assert a.o3 ** 2 == pytest.approx(e.lambda_min, rel=1e-6)


@pytest.mark.parametrize("criterion", ["d", "e"])
def test_design_is_seeded_and_feasible(criterion):
    a = design_poses(NOMINAL, 10, full_workspace(), NOISE, criterion=criterion, seed=5, n_candidates=300)
    b = design_poses(NOMINAL, 10, full_workspace(), NOISE, criterion=criterion, seed=5, n_candidates=300)
    np.testing.assert_array_equal(a.poses, b.poses)
    assert feasibility(NOMINAL, a.poses, full_workspace())["feasible"].all()


def test_full_workspace_design_beats_paper_poses_tenfold():
    design = design_poses(NOMINAL, 10, full_workspace(), NOISE, seed=0, n_candidates=1000)
    rms_design = analyze_observability(NOMINAL, design.poses, NOISE).crb_rms
    rms_paper = analyze_observability(NOMINAL, paper.TABLE4_NOMINAL_POSES, NOISE).crb_rms
    assert rms_paper / rms_design >= 10.0


@pytest.mark.parametrize("call, match", [
    (lambda: select_poses(NOMINAL, CANDIDATES, 8, NOISE, criterion="a"), "criterion must be one of"),
    (lambda: select_poses(NOMINAL, CANDIDATES, 6, NOISE), "n must be an integer >= 7, got 6"),
    (lambda: select_poses(NOMINAL, CANDIDATES, 8.0, NOISE), "n must be an integer >= 7"),
    (lambda: select_poses(NOMINAL, CANDIDATES[:7], 8, NOISE), "candidates must have at least n = 8 rows, got 7"),
    (lambda: select_poses(NOMINAL, CANDIDATES[:, :5], 8, NOISE), r"candidates must have shape \(N, 6\)"),
    (lambda: select_poses(NOMINAL, CANDIDATES, 8, NOISE, screen=0), "screen must be an integer >= 1"),
    (lambda: design_poses(NOMINAL, 10, full_workspace(), NOISE, n_candidates=5), "n_candidates must be an integer >= 10"),
    (lambda: sample_feasible_poses(NOMINAL, full_workspace(), -1, 0), "n must be an integer >= 0"),
    (lambda: feasibility(NOMINAL, np.zeros(6), full_workspace()), r"poses must have shape \(N, 6\), got \(6,\)"),
])
def test_selection_validation(call, match):
    with pytest.raises(ValueError, match=match):
        call()


@pytest.mark.parametrize("call, match", [
    (lambda: feasibility("hexapod", HOME, full_workspace()), "hexapod must be a Hexapod"),
    (lambda: feasibility(NOMINAL, HOME, "full"), "workspace must be a Workspace"),
    (lambda: joint_cone_angles(None, HOME), "hexapod must be a Hexapod"),
    (lambda: scaled_condition(None, HOME), "hexapod must be a Hexapod"),
])
def test_type_validation(call, match):
    with pytest.raises(TypeError, match=match):
        call()
