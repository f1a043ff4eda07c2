"""Joint ranges as built (issue 37, point 5): a robot description may declare each joint's range
(``joint_ranges``, one ``[low, high]`` pair per joint, joint unit), read back by
``robot_from_description`` and used, through :meth:`calib.robot.Robot.joint_limits`, by the
checks of recordings, pose design, the suggested poses of ``pipeline.run`` and compensation; with
none declared every robot keeps its own default range (the hexapod's ``home +- stroke_mm``).

The one-sided hexapod is the paper's Table 2 machine with legs from 10 mm below their home length
(fully retracted) to 90 mm above it: the symmetric default (+-50 mm) would command legs down to
40 mm below the retracted length."""

import json

import numpy as np
import pytest

from calib import paper
from calib.design import design_poses, feasibility, robot_workspace
from calib.noise import SensorNoise
from calib.robot import JOINT_RANGES_KEY, KinematicsError, check_joint_limits
from calib.robots import ROBOTS, default_robot, paper_hexapod, reference_errors, robot_from_description
from calib.workspace import reachable_poses
from pipeline.compensate import main as compensate_main
from pipeline.formats import (JOINT_LIMIT_TOLERANCE, Recording, RecordingError, read_command_file, read_recording,
                              recording_checks, write_recording)
from pipeline.run import main as run_main

NAMES = sorted(ROBOTS)
NOISE = SensorNoise(paper.PAPER_NOISE_MM, 1e-5)
#: The one-sided legs: from RETRACTED_MM below the home length to EXTENDED_MM above it.
RETRACTED_MM, EXTENDED_MM = 10.0, 90.0


def asymmetric_ranges(robot) -> np.ndarray:
    """(C, 2) ranges unlike the robot's default: each joint's own, shifted towards the high end."""
    lim = robot.joint_limits()
    mid, width = lim.mean(axis=1), np.ptp(lim, axis=1)
    k = np.arange(robot.n_chains)
    return np.stack([mid - (0.1 + 0.01 * k) * width, mid + (0.7 + 0.02 * k) * width], axis=1)


def with_ranges(robot, ranges):
    """The robot of ``robot``'s description with ``ranges`` declared (through JSON, as a file has it)."""
    d = json.loads(json.dumps({**robot.description(), JOINT_RANGES_KEY: np.asarray(ranges).tolist()}))
    return robot_from_description(robot.name, d)


HEXAPOD = paper_hexapod()
ONE_SIDED = with_ranges(HEXAPOD, np.stack([HEXAPOD.home_lengths - RETRACTED_MM,
                                           HEXAPOD.home_lengths + EXTENDED_MM], axis=1))
LOW, HIGH = ONE_SIDED.joint_limits().T


# ----------------------------------------------------------------------------- the description

@pytest.mark.parametrize("name", NAMES)
def test_declared_ranges_round_trip_through_the_description(name):
    robot = default_robot(name)
    ranges = asymmetric_ranges(robot)
    declared = with_ranges(robot, ranges)
    np.testing.assert_array_equal(declared.joint_limits(), ranges)
    np.testing.assert_array_equal(declared.joint_ranges, ranges)
    d = declared.description()
    assert d[JOINT_RANGES_KEY] == ranges.tolist()
    again = robot_from_description(name, json.loads(json.dumps(d)))
    np.testing.assert_array_equal(again.joint_limits(), ranges)
    assert again.description() == d
    # the rest of the geometry is untouched, and so is the robot's own default
    np.testing.assert_array_equal(declared.table.nominal, robot.table.nominal)
    np.testing.assert_array_equal(declared.default_joint_limits(), robot.joint_limits())


@pytest.mark.parametrize("name", NAMES)
def test_without_ranges_the_default_holds_and_nothing_is_written(name):
    robot = default_robot(name)
    assert robot.joint_ranges is None and JOINT_RANGES_KEY not in robot.description()
    np.testing.assert_array_equal(robot.joint_limits(), robot.default_joint_limits())
    again = robot_from_description(name, robot.description())
    assert again.joint_ranges is None and again.description() == robot.description()
    lim = ONE_SIDED.joint_limits()
    lim[:] = 0.0  # a copy: the robot's ranges cannot be changed through it
    np.testing.assert_array_equal(ONE_SIDED.joint_limits()[:, 0], HEXAPOD.home_lengths - RETRACTED_MM)


def test_the_hexapod_default_is_its_stroke_about_home():
    np.testing.assert_array_equal(HEXAPOD.joint_limits(),
                                  np.stack([HEXAPOD.home_lengths - HEXAPOD.stroke_mm,
                                            HEXAPOD.home_lengths + HEXAPOD.stroke_mm], axis=1))
    np.testing.assert_array_equal(ONE_SIDED.joint_limits()[:, 1], HEXAPOD.home_lengths + EXTENDED_MM)


def _malformed(robot) -> dict:
    """case -> (the ``joint_ranges`` value, words the one-line message must hold)."""
    good = asymmetric_ranges(robot).tolist()
    c, second, unit = robot.n_chains, f"{robot.chain_word} 2, {robot.joint_names[1]}", robot.joint_unit

    def at(k, pair):
        out = [list(p) for p in good]
        out[k] = pair
        return out

    return {
        "one pair short": (good[:-1], f"per {robot.chain_word} ({c}), got {c - 1} entries"),
        "one pair too many": (good + [good[0]], f"got {c + 1} entries"),
        "not a list": ("0 to 280", "got '0 to 280'"),
        "an object": ({"low": 0, "high": 1}, "joint_ranges: expected one [low, high] pair"),
        "low above high": (at(1, [good[1][1], good[1][0]]), f"[1] ({second}): low must be below high"),
        "low equal to high": (at(1, [good[1][0], good[1][0]]), f"[1] ({second}): low must be below high"),
        "a word": (at(1, ["low", good[1][1]]), f"[1] ({second}): low must be a finite number ({unit}), got 'low'"),
        "null": (at(1, [good[1][0], None]), f"[1] ({second}): high must be a finite number ({unit}), got None"),
        "a boolean": (at(1, [True, good[1][1]]), f"[1] ({second}): low must be a finite number ({unit}), got True"),
        "infinite": (at(1, [good[1][0], float("inf")]), f"[1] ({second}): high must be a finite number ({unit}), got inf"),
        "three numbers": (at(1, [0.0, 1.0, 2.0]), f"[1] ({second}): expected [low, high]"),
        "a number for a pair": (at(1, 5.0), f"[1] ({second}): expected [low, high]"),
    }


MALFORMED_CASES = sorted(_malformed(HEXAPOD))


@pytest.mark.parametrize("case", MALFORMED_CASES)
@pytest.mark.parametrize("name", NAMES)
def test_malformed_ranges_are_refused_in_one_line_naming_the_key(name, case):
    robot = default_robot(name)
    value, words = _malformed(robot)[case]
    with pytest.raises(ValueError) as info:
        robot_from_description(name, {**robot.description(), JOINT_RANGES_KEY: value})
    message = str(info.value)
    assert "\n" not in message and message.startswith(JOINT_RANGES_KEY) and words in message, message


def small_recording(robot, n_cal: int, n_val: int = 3, seed: int = 0) -> Recording:
    """A noise-free recording of ``robot`` with the paper's Table 3 errors (no MuJoCo)."""
    nominal = robot.table.nominal
    targets = reachable_poses(robot, n_cal + n_val, np.random.default_rng(seed))
    joints = robot.inverse_kinematics(nominal, targets)
    measured = robot.forward_kinematics(nominal + reference_errors(robot), joints, initial=targets)
    return Recording(robot=robot, noise=NOISE, t_s=np.arange(n_cal + n_val, dtype=float), joints=joints,
                     measured=measured, sets=np.array(["calibration"] * n_cal + ["validation"] * n_val),
                     meta={"scenario": "one-sided legs"})


def test_a_sidecar_with_malformed_ranges_is_refused_by_run(tmp_path, capsys):
    csv_path, json_path = write_recording(tmp_path / "rec.csv", small_recording(ONE_SIDED, 12))
    side = json.loads(json_path.read_text())
    side["nominal_geometry"][JOINT_RANGES_KEY][2] = [300.0, 200.0]
    json_path.write_text(json.dumps(side))
    out = tmp_path / "out"
    assert run_main(["--real", str(csv_path), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert "rec.json" in err and "nominal_geometry" in err and "joint_ranges[2] (leg 3, l3): low must be below high" \
        in err, err
    assert not out.exists() or not any(out.iterdir())


# ----------------------------------------------------------------------------- pose design

def test_feasibility_names_the_declared_range():
    """A level pose 15 mm below home: inside the default stroke, below the retracted legs."""
    pose = HEXAPOD.home_pose + [0, 0, -15.0, 0, 0, 0]
    legs = HEXAPOD.inverse_kinematics(HEXAPOD.table.nominal, pose[None])[0]
    assert np.all(legs < LOW) and np.all(legs > HEXAPOD.joint_limits()[:, 0])
    for robot, ok in ((HEXAPOD, True), (ONE_SIDED, False)):
        f = feasibility(robot, robot.table.nominal, pose[None], robot_workspace(robot, "full"))
        assert f["joint_limits"][0] == ok and f["feasible"][0] == ok
    check_joint_limits(HEXAPOD, legs[None])
    with pytest.raises(KinematicsError, match=r"leg 1 needs .* outside its range \[223\.238, 323\.238\] mm"):
        check_joint_limits(ONE_SIDED, legs[None])


def test_designed_poses_keep_the_legs_in_the_declared_ranges():
    """D-optimal poses over the full workspace push the legs to their ends: with the declared
    ranges to the retracted length (within 5% of the range) and never below it; with the
    symmetric default the same design goes below the retracted length."""
    q = {}
    for key, robot in (("default", HEXAPOD), ("declared", ONE_SIDED)):
        poses = design_poses(robot, robot.table.nominal, 30, robot_workspace(robot, "full"), NOISE, seed=0).poses
        q[key] = robot.inverse_kinematics(robot.table.nominal, poses)
    assert np.all(q["declared"] >= LOW) and np.all(q["declared"] <= HIGH)
    assert np.min(q["declared"] - LOW) < 0.05 * (RETRACTED_MM + EXTENDED_MM)
    assert np.min(q["default"] - LOW) < -RETRACTED_MM  # the symmetric stroke would go well below


# ----------------------------------------------------------------------------- the checks

@pytest.mark.parametrize("fraction, refused", [(0.5 * JOINT_LIMIT_TOLERANCE, False), (5 * JOINT_LIMIT_TOLERANCE, True)])
def test_a_reading_below_the_declared_range_is_named(tmp_path, fraction, refused):
    """Leg 2 of row 4 read ``fraction`` of the range below the retracted length (well inside the
    symmetric default): named in a warning within the tolerance, refused beyond it."""
    rec = small_recording(ONE_SIDED, 30)
    q = rec.joints.copy()
    q[3, 1] = LOW[1] - fraction * (HIGH[1] - LOW[1])
    assert q[3, 1] > HEXAPOD.joint_limits()[1, 0]
    theta = ONE_SIDED.table.nominal + reference_errors(ONE_SIDED)
    measured = rec.measured.copy()
    measured[3] = ONE_SIDED.forward_kinematics(theta, q[3:4], initial=rec.measured[3:4])[0]
    for robot in (HEXAPOD, ONE_SIDED):
        path, _ = write_recording(tmp_path / f"{robot is ONE_SIDED}.csv",
                                  Recording(robot=robot, noise=rec.noise, t_s=rec.t_s, joints=q, measured=measured,
                                            sets=rec.sets, meta=rec.meta))
        back = read_recording(path)
        assert back.robot.joint_ranges is None if robot is HEXAPOD else np.array_equal(back.robot.joint_ranges,
                                                                                        ONE_SIDED.joint_ranges)
        if robot is HEXAPOD:  # the default stroke holds the reading: nothing said
            assert not [w for w in recording_checks(back, path).warnings if "past the range" in w]
        elif refused:
            with pytest.raises(RecordingError, match=r"row 4 \(line 5\), column 'l2_mm': .* outside the range "
                                                     r"\[223\.238, 323\.238\] mm declared in the nominal geometry's "
                                                     r"joint_ranges by more than the tolerance"):
                recording_checks(back, path)
        else:
            warned = [w for w in recording_checks(back, path).warnings if "past the range" in w]
            assert len(warned) == 1 and "rows 4 (line 5), column(s) l2_mm" in warned[0], warned
            assert "declared in the nominal geometry's joint_ranges" in warned[0] and "accepted as read" in warned[0]


# ----------------------------------------------------------------------------- run and compensate

@pytest.fixture(scope="module")
def one_sided_run(tmp_path_factory):
    """``pipeline.run --real`` on four calibration rows of the one-sided hexapod: most of the
    geometry is left to the prior, so the run suggests poses to measure next."""
    folder = tmp_path_factory.mktemp("one_sided")
    csv_path, _ = write_recording(folder / "rec.csv", small_recording(ONE_SIDED, 4))
    assert run_main(["--real", str(csv_path), "--out", str(folder), "--name", "r", "--quiet"]) == 0
    return folder


def test_run_suggests_poses_inside_the_declared_ranges(one_sided_run):
    poses, joints = read_command_file(one_sided_run / "r.suggested_poses.csv", ONE_SIDED)
    assert len(poses) > 0
    assert np.all(joints >= LOW) and np.all(joints <= HIGH)
    assert np.min(joints - LOW) < 0.05 * (RETRACTED_MM + EXTENDED_MM)  # the design goes to the retracted end
    np.testing.assert_allclose(joints, ONE_SIDED.inverse_kinematics(ONE_SIDED.table.nominal, poses),
                               rtol=0, atol=1e-9 * np.max(HIGH))
    cal = json.loads((one_sided_run / "r.calibration.json").read_text())
    assert cal["nominal_geometry"][JOINT_RANGES_KEY] == ONE_SIDED.joint_ranges.tolist()


def test_compensation_refuses_a_target_below_the_retracted_legs(one_sided_run, tmp_path, capsys):
    """Row 2 is 15 mm below home, level: inside the symmetric stroke, below the retracted legs."""
    targets = tmp_path / "targets.csv"
    targets.write_text("x_mm,y_mm,z_mm,alpha_rad,beta_rad,gamma_rad\n0,0,205,0,0,0\n0,0,185,0,0,0\n")
    cal = one_sided_run / "r.calibration.json"
    out = tmp_path / "cmd.csv"
    assert compensate_main(["--calibration", str(cal), "--targets", str(targets), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert "targets.csv: row 2 (line 3)" in err and "outside its range [223.238, 323.238] mm" in err, err
    assert not out.exists()
    # the same calibration without the declared ranges (the symmetric default) commands row 2
    d = json.loads(cal.read_text())
    del d["nominal_geometry"][JOINT_RANGES_KEY]
    (tmp_path / "default.calibration.json").write_text(json.dumps(d))
    assert compensate_main(["--calibration", str(tmp_path / "default.calibration.json"), "--targets", str(targets),
                            "--out", str(out)]) == 0
    _, commands = read_command_file(out, HEXAPOD)
    assert np.all(commands[1] < LOW) and np.all(commands[0] >= LOW)
