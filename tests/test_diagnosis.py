"""Why a data set does not fit its machine (calib.diagnosis), every registered robot.

Kinematic simulation, as tests/test_robust.py: the machine ``nominal + reference_errors(robot, 0)``
moves by its forward kinematics to the joints the nominal model commands for 40 seeded poses of
its calibration workspace; noise uniform within +-1 um on every position and +-1 urad on every
angle. The independent truth is the mistake made to the file (which conversion undoes it).

Bounds. A data set at the declared noise fits (chi-square within the 0.999 quantile, 1.3 per
degree of freedom here) with a geometry within the reference errors (2.5 tolerances at most); each
mistake below moves a position or angle by far more than the noise (a swapped x and y by up to
20 mm, a flipped gamma by up to 0.1 rad, a reversed joint by up to 1 rad), so the data as written
misfit by orders of magnitude, or (a 6-RUS motor read backwards) fit only with a motor axis turned
by pi, 600 tolerances. A constant tilt of the capture body on the platform (2 degrees roll, 1
degree pitch) is absorbed by the platform joints' coordinates: the data fit, nothing is wrong.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from calib.diagnosis import CAUSES, conversion_registry, diagnose
from calib.measurement import instrument_measurements
from calib.noise import SensorNoise
from calib.paper import PAPER_NOISE_MM
from calib.robots import ROBOTS, default_robot, reference_errors
from calib.rotation import euler_from_matrix, rotation_matrix
from calib.workspace import reachable_poses

NAMES = sorted(ROBOTS)
NOISE = SensorNoise(PAPER_NOISE_MM, 1e-6)
N_ROWS = 40
#: An instrument frame 0.5 m from the base origin, turned by 0.4 rad (about an oblique axis).
FAR_FRAME = np.array([500 / np.sqrt(3)] * 3 + [0.4 / np.sqrt(3)] * 3)
#: The capture body's constant tilt on the platform: 2 degrees roll, 1 degree pitch.
TILT_RAD = np.deg2rad([2.0, 1.0, 0.0])


@lru_cache(maxsize=None)
def experiment(name: str):
    """``(robot, joints (N, C), true poses (N, D), noise (N, D))``."""
    robot = default_robot(name)
    nominal = robot.table.nominal
    poses = reachable_poses(robot, N_ROWS, 1)
    joints = robot.inverse_kinematics(nominal, poses)
    true = robot.forward_kinematics(nominal + reference_errors(robot, 0), joints, initial=poses)
    return robot, joints, true, NOISE.sample(N_ROWS, 3, robot.pose_units)


def tilted(robot, poses: np.ndarray) -> np.ndarray:
    """The poses of a capture body turned by :data:`TILT_RAD` on the platform (a translating
    platform's positions do not change)."""
    if not robot.angle_pose_mask.any():
        return poses.copy()
    out = poses.copy()
    out[:, 3:] = euler_from_matrix(rotation_matrix(poses[:, 3:]) @ rotation_matrix(TILT_RAD))
    return out


def honest(name: str, case: str):
    """``(robot, joints, measured)`` of an honest data set: ``clean``, ``far`` (a far instrument
    frame), ``tilt`` (the tilted capture body), ``tilt far`` (both)."""
    robot, joints, true, noise = experiment(name)
    poses = tilted(robot, true) if "tilt" in case else true
    return robot, joints, instrument_measurements(robot, poses, FAR_FRAME if "far" in case else None) + noise


def mistaken(name: str, mistake: str):
    """``(robot, joints, measured)`` with ``mistake`` (a conversion's name) made to the clean
    data, written independently of the registry's conversions."""
    robot, joints, measured = honest(name, "clean")
    q, m = joints.copy(), measured.copy()
    pos = np.flatnonzero(~robot.angle_pose_mask)
    limits = robot.joint_limits()
    if mistake == "positions in metres":
        m[:, pos] /= 1000.0
    elif mistake == "angles in degrees":
        m[:, 3:] = np.rad2deg(m[:, 3:])
    elif mistake == "joints in degrees":
        q = np.rad2deg(q)
    elif mistake == "x and y swapped":
        m[:, [0, 1]] = m[:, [1, 0]]
    elif mistake == "z sign flipped":
        m[:, 2] = -m[:, 2]
    elif mistake == "gamma sign flipped":
        m[:, 5] = -m[:, 5]
    elif mistake == "joint 2 reversed":
        q[:, 1] = limits[1].sum() - q[:, 1] if robot.joint_unit == "mm" else -q[:, 1]
    return robot, q, m


#: Each robot's mistake classes (the report's): the Deltas have no angle columns, the rotary one's joints are
#: rad, the linear one's mm.
MISTAKES = {
    "delta": ("positions in metres", "joints in degrees", "x and y swapped", "z sign flipped", "joint 2 reversed"),
    "hexapod": ("positions in metres", "angles in degrees", "x and y swapped", "z sign flipped", "gamma sign flipped",
                "joint 2 reversed"),
    "rus": ("positions in metres", "angles in degrees", "joints in degrees", "x and y swapped", "z sign flipped",
            "gamma sign flipped", "joint 2 reversed"),
    "linear_delta": ("positions in metres", "x and y swapped", "z sign flipped", "joint 2 reversed"),
}
CASES = [(n, m) for n in NAMES for m in MISTAKES[n]]


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("case", ["clean", "far", "tilt", "tilt far"])
def test_honest_data_are_diagnosed_as_nothing_wrong(name, case):
    robot, joints, measured = honest(name, case)
    d = diagnose(robot, joints, measured, NOISE)
    assert d.success and d.cause == "none", d.message
    assert d.conversion is None and d.written.fits
    assert d.written.frame_estimated == ("far" in case)
    assert d.written.chi2_dof < 1.3, d.message
    if case == "clean":
        assert d.fits == 1 and d.written.plausible


@pytest.mark.parametrize("name,mistake", CASES)
def test_each_mistake_is_named_with_its_evidence(name, mistake):
    robot, joints, measured = mistaken(name, mistake)
    d = diagnose(robot, joints, measured, NOISE)
    assert not d.success
    assert d.cause == "conversion" and d.conversion.name == mistake, d.message
    assert d.converted.fits and d.converted.plausible and d.converted.chi2_dof < 1.3
    assert not d.converted.frame_estimated
    assert (not d.written.fits and d.written.chi2_dof > 1e3) or not d.written.plausible, d.message
    assert d.message.startswith(d.conversion.finding)
    assert d.summary()["conversion"] == mistake and d.summary()["success"] is False


@pytest.mark.parametrize("name", NAMES)
def test_a_column_never_measured_is_named(name):
    """Every pose at z = 0 (the report's hexapod file): the column was not measured."""
    robot, joints, measured = honest(name, "clean")
    measured[:, 2] = 0.0
    d = diagnose(robot, joints, measured, NOISE)
    assert d.cause == "unmeasured column" and d.column == "z", d.message
    assert not d.success


@pytest.mark.parametrize("name", NAMES)
def test_gross_rows_and_left_out_physics(name):
    """Three rows 1 mm off: gross rows, named; every row off by a smooth 50 um sag the model
    lacks (z proportional to x^2): left-out physics, no row and no conversion named."""
    robot, joints, measured = honest(name, "clean")
    spoiled = measured.copy()
    spoiled[[4, 17, 30], 0] += 1.0
    d = diagnose(robot, joints, spoiled, NOISE)
    assert d.cause == "gross rows" and d.gross_rows == (4, 17, 30), d.message
    sag = measured.copy()
    x = sag[:, 0] - sag[:, 0].mean()
    sag[:, 2] += 0.05 * (x / np.abs(x).max()) ** 2 - 0.05 * np.cos(3 * sag[:, 1] / np.abs(sag[:, 1]).max())
    d = diagnose(robot, joints, sag, NOISE)
    assert d.cause == "left-out physics" and d.conversion is None and d.gross_rows == (), d.message


@pytest.mark.parametrize("name", NAMES)
def test_the_registry_undoes_each_mistake(name):
    """Every conversion the tests name undoes the mistake made independently (the registry's
    arithmetic against the test's), and the registry names are distinct."""
    registry = {c.name: c for c in conversion_registry(default_robot(name))}
    assert len(registry) == len(conversion_registry(default_robot(name)))
    _, joints, clean = honest(name, "clean")
    for mistake in MISTAKES[name]:
        _, q, m = mistaken(name, mistake)
        q2, m2 = registry[mistake].apply(q, m)
        assert np.allclose(q2, joints, rtol=0, atol=1e-9) and np.allclose(m2, clean, rtol=0, atol=1e-9), mistake


def test_causes_are_the_documented_ones():
    assert CAUSES == ("none", "conversion", "unmeasured column", "gross rows", "left-out physics")


@pytest.mark.parametrize("name", NAMES)
def test_above_the_diagnosis_size_a_subsample_is_judged_and_said(name, monkeypatch):
    """With calib.diagnosis.DIAGNOSIS_MAX_ROWS lowered below the rows, a seeded subsample is
    diagnosed and ``rows`` says so: honest data nothing wrong, a unit mistake the same conversion
    as the exact diagnosis names, gross rows numbered in the input (those of the three the
    subsample holds, all three when it holds them)."""
    import calib.diagnosis

    robot, joints, measured = honest(name, "clean")
    mistake = mistaken(name, "positions in metres")
    spoiled = measured.copy()
    spoiled[[4, 17, 30], 0] += 1.0
    exact = diagnose(*mistake[:1], *mistake[1:], NOISE)
    assert exact.rows == "every row"
    size = N_ROWS - 10
    monkeypatch.setattr(calib.diagnosis, "DIAGNOSIS_MAX_ROWS", size)
    said = f"a seeded subsample of {size} of the {N_ROWS} rows ({N_ROWS} rows > DIAGNOSIS_MAX_ROWS = {size})"
    d = diagnose(robot, joints, measured, NOISE)
    assert d.success and d.cause == "none" and d.rows == said and d.summary()["rows"] == said, d.message
    d = diagnose(*mistake, NOISE)
    assert d.cause == exact.cause == "conversion" and d.conversion.name == exact.conversion.name, d.message
    d = diagnose(robot, joints, spoiled, NOISE)
    assert d.cause == "gross rows" and set(d.gross_rows) <= {4, 17, 30} and d.gross_rows, d.message


#: A second session's instrument frame: :data:`FAR_FRAME` moved 50 mm along x and turned 0.01 rad about z.
MOVED_FRAME = FAR_FRAME + np.array([50.0, 0.0, 0.0, 0.0, 0.0, 0.01])


@pytest.mark.parametrize("name", NAMES)
def test_two_sessions_are_judged_each_in_its_own_instrument_frame(name):
    """Rows 0-19 seen from FAR_FRAME, rows 20-39 from another frame (50 mm and 0.01 rad away): told
    the sessions, the diagnosis fits each row in its session's frame (two frames estimated) and
    finds nothing wrong in one fit (one frame for both sessions would be 50 mm, 5e4 times the
    noise, off for half the rows)."""
    robot, joints, true, noise = experiment(name)
    sessions = np.repeat([0, 1], N_ROWS // 2)
    measured = np.where(sessions[:, None] == 0, instrument_measurements(robot, true, FAR_FRAME),
                        instrument_measurements(robot, true, MOVED_FRAME)) + noise
    d = diagnose(robot, joints, measured, NOISE, frame=["auto", "auto"], sessions=sessions)
    assert d.success and d.cause == "none" and d.fits == 1, d.message
    assert d.written.fit.n_sessions == 2 and d.written.frame_estimated
