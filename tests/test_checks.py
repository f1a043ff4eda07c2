"""The plausibility checks of a recording (pipeline.formats.checks), every registered robot.

Recordings written and read back (CSV + sidecar) from the kinematic simulation of
tests/test_diagnosis.py (40 rows, 30 for calibration; noise +-1 um, +-1 urad). Independent truths:
which rows were read past the range (set by the test), what mistake was made to the file, and the
true machine (held-out predictions of the calibrated model against the true poses).

Joint readings. A reading 0.5 % of the range past the declared range (a leg 0.5 mm past a 100 mm
stroke; a Delta motor 0.9 degree past its 180 degrees) is within the default tolerance (1 % of the
range): accepted, the rows named in a warning. A reading 5 % past (ten times as far) is refused.

A capture body mounted turned on the platform (2 degrees roll, 1 degree pitch) over a nearly level
grid (every angle within +-0.2 degree) makes the angles look like degrees against the nominal
model (2 degrees read as degrees is nearer zero than 0.035 rad): a warning with its figures, no
refusal; the calibration absorbs the tilt in the platform joints' coordinates and predicts the
held-out capture-body poses to the noise (within 5 um and 5 urad RMS: the fit's prediction error
at 40 rows, about the noise's standard deviation, well inside).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from calib.measurement import identify_measured, instrument_measurements
from calib.robots import default_robot, reference_errors
from calib.workspace import reachable_poses
from pipeline.formats import (JOINT_LIMIT_TOLERANCE, Recording, RecordingError, read_recording, recording_checks,
                              write_recording)
from test_diagnosis import FAR_FRAME, NAMES, NOISE, N_ROWS, experiment, mistaken, tilted

N_CAL = 30
#: Half-width of the nearly level grid's angles.
LEVEL_RAD = np.deg2rad(0.2)


def write(tmp_path: Path, robot, joints, measured, meta=None) -> tuple[Path, Recording]:
    sets = np.array(["calibration"] * N_CAL + ["validation"] * (len(joints) - N_CAL))
    rec = Recording(robot=robot, noise=NOISE, t_s=np.arange(len(joints), dtype=float), joints=joints,
                    measured=measured, sets=sets, meta=dict(meta or {}))
    path, _ = write_recording(tmp_path / "rec.csv", rec, overwrite=True)
    return path, read_recording(path)


def past_the_range(name: str, fraction: float, rows=(3, 21)):
    """``(robot, joints, measured)``: in each of ``rows``, one joint read ``fraction`` of its range
    past the upper limit, the pose where the true machine goes at that reading (plus noise)."""
    robot, joints, true, noise = experiment(name)
    q, poses = joints.copy(), true.copy()
    limits = robot.joint_limits()
    theta = robot.table.nominal + reference_errors(robot, 0)
    for k, r in enumerate(rows):
        c = k % robot.n_chains
        q[r, c] = limits[c, 1] + fraction * (limits[c, 1] - limits[c, 0])
        poses[r] = robot.forward_kinematics(theta, q[r:r + 1], initial=true[r:r + 1])[0]
    return robot, q, poses + noise


@pytest.mark.parametrize("name", NAMES)
def test_readings_slightly_past_the_range_are_accepted_and_named(name, tmp_path):
    robot, q, m = past_the_range(name, 0.5 * JOINT_LIMIT_TOLERANCE)
    path, rec = write(tmp_path, robot, q, m)
    checks = recording_checks(rec, path)
    warned = [w for w in checks.warnings if "past the range" in w]
    assert len(warned) == 1, checks.warnings
    assert "rows 4 (line 5), 22 (line 23)" in warned[0] and "accepted as read" in warned[0]
    assert checks.diagnosis.success, checks.diagnosis.message


@pytest.mark.parametrize("name", NAMES)
def test_readings_far_past_the_range_are_refused(name, tmp_path):
    robot, q, m = past_the_range(name, 5 * JOINT_LIMIT_TOLERANCE)
    path, rec = write(tmp_path, robot, q, m)
    col = f"{robot.joint_symbol}1_{robot.joint_unit}"
    with pytest.raises(RecordingError, match=rf"rec.csv: row 4 \(line 5\), column '{col}': .* by more than the "
                                             "tolerance .* cannot reach it"):
        recording_checks(rec, path)


@pytest.mark.parametrize("name", NAMES)
def test_joints_in_another_unit_are_refused_as_such(name, tmp_path):
    robot, q, m = mistaken(name, "clean")
    other, factor = ("metres", 1e-3) if robot.joint_unit == "mm" else ("degrees", 180 / np.pi)
    path, rec = write(tmp_path, robot, q * factor, m)
    with pytest.raises(RecordingError, match=f"joint values seem to be in {other}"):
        recording_checks(rec, path)


def test_the_sidecar_tolerance_replaces_the_default(tmp_path):
    robot, q, m = past_the_range("hexapod", 0.005)  # 0.5 mm past a 100 mm range
    path, rec = write(tmp_path, robot, q, m, {"joint_limit_tolerance": 0.1})
    with pytest.raises(RecordingError, match=r"row 4 \(line 5\), column 'l1_mm'.*tolerance 0.1 mm"):
        recording_checks(rec, path)
    robot, q, m = past_the_range("hexapod", 0.015)
    path, rec = write(tmp_path, robot, q, m, {"joint_limit_tolerance": {"fraction": 0.02}})
    assert any("within the tolerance 2 mm" in w for w in recording_checks(rec, path).warnings)
    path, rec = write(tmp_path, robot, q, m, {"joint_limit_tolerance": "1 mm"})
    with pytest.raises(RecordingError, match=r"rec.json: field 'meta.joint_limit_tolerance' must be a finite number"):
        recording_checks(rec, path)


@lru_cache(maxsize=None)
def level_grid(name: str):
    """``(robot, joints (N, C), capture-body poses (N, D))``: a nearly level grid (angles within
    +-:data:`LEVEL_RAD`) seen through the tilted capture body, noise-free."""
    robot = default_robot(name)
    bounds = robot.workspace_bounds().copy()
    angle = robot.angle_pose_mask
    bounds[angle] = robot.home_pose[angle, None] + LEVEL_RAD * np.array([-1.0, 1.0])
    poses = reachable_poses(robot, N_ROWS, 1, bounds=bounds)
    joints = robot.inverse_kinematics(robot.table.nominal, poses)
    true = robot.forward_kinematics(robot.table.nominal + reference_errors(robot, 0), joints, initial=poses)
    return robot, joints, tilted(robot, true)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("far", [False, True], ids=["base_frame", "far_frame"])
def test_a_tilted_capture_body_is_accepted_and_calibrated(name, far, tmp_path):
    robot, joints, body = level_grid(name)
    _, _, _, noise = experiment(name)
    seen = instrument_measurements(robot, body, FAR_FRAME if far else None)
    path, rec = write(tmp_path, robot, joints, seen + noise)
    checks = recording_checks(rec, path)
    assert checks.diagnosis.success, checks.diagnosis.message
    looks = [w for w in checks.warnings if "look like degrees" in w]
    if robot.angle_pose_mask.any() and not far:
        assert len(looks) == 1 and "read as degrees" in looks[0] and "yet the file as written fits" in looks[0]
        assert "chi-square" in looks[0]
    else:
        assert looks == []
    fit = identify_measured(robot, joints[:N_CAL], rec.measured[:N_CAL], NOISE)
    error = fit.predict(joints[N_CAL:]) - seen[N_CAL:]
    pos = ~robot.angle_pose_mask
    assert np.sqrt(np.mean(error[:, pos] ** 2)) < 5e-3
    assert not robot.angle_pose_mask.any() or np.sqrt(np.mean(error[:, ~pos] ** 2)) < 5e-6


@pytest.mark.parametrize("name", NAMES)
def test_a_confirmed_mistake_is_refused_with_its_evidence(name, tmp_path):
    robot, q, m = mistaken(name, "x and y swapped")
    path, rec = write(tmp_path, robot, q, m)
    with pytest.raises(RecordingError) as err:
        recording_checks(rec, path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: columns x_mm, y_mm: the columns x and y seem to be swapped: converted")
    assert "chi-square" in msg and "as written it does not" in msg


@pytest.mark.parametrize("name", NAMES)
def test_a_column_never_measured_is_refused(name, tmp_path):
    robot, q, m = mistaken(name, "clean")
    m[:, 2] = 0.0
    path, rec = write(tmp_path, robot, q, m)
    with pytest.raises(RecordingError, match="column 'z_mm': the column z holds one value .* was not measured"):
        recording_checks(rec, path)
