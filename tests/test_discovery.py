"""The discovery policy (calib.discovery): which rows are analysed, rows that never move refused,
the effect named and judged by the validation rows, the calibration it gives built from the
objects (no file, no dict)."""

from __future__ import annotations

import numpy as np
import pytest

from calib.discovery import DiscoveryRows, MotionlessRows, analysed_rows, discover_machine
from calib.effects.discovery import MIN_ROWS
from calib.prior import ParameterPrior
from tests.test_effects import NOISE, synthetic

#: One effect per robot that the rows name (tests/test_effects.py's discovery cases).
POLICY_CASES = [("hexapod", "thermal_drift", [5e-5]), ("delta", "joint_friction", [1e-5])]
#: Rows of the synthetic recordings, and the last of them held out as validation rows.
ROWS, VALIDATION_ROWS = 80, 20


def rows_of(data, sets: np.ndarray) -> DiscoveryRows:
    return DiscoveryRows(data.robot, data.joints, data.measured, data.t_s, data.noise, sets,
                         np.full(data.n, "day1"), {})


def test_too_few_calibration_rows_take_every_row_less_those_left_out():
    sets = np.array(["calibration"] * (MIN_ROWS - 1) + ["validation"] * 10)
    cal, val, every = analysed_rows(sets, exclude=[3])
    assert every and val.size == 0
    np.testing.assert_array_equal(cal, np.setdiff1d(np.arange(sets.size), [3]))
    sets = np.array(["calibration"] * MIN_ROWS + ["validation"] * 5)
    cal, val, every = analysed_rows(sets, exclude=[MIN_ROWS + 1])
    assert not every
    np.testing.assert_array_equal(cal, np.arange(MIN_ROWS))
    np.testing.assert_array_equal(val, [MIN_ROWS, MIN_ROWS + 2, MIN_ROWS + 3, MIN_ROWS + 4])


@pytest.mark.parametrize("robot_name", ["hexapod", "delta"])
def test_rows_at_one_pose_are_refused_with_their_count(robot_name):
    data = synthetic(robot_name, "none", [], n=MIN_ROWS)
    still = DiscoveryRows(data.robot, np.repeat(data.joints[:1], MIN_ROWS, axis=0),
                          np.repeat(data.measured[:1], MIN_ROWS, axis=0), data.t_s, data.noise,
                          np.full(MIN_ROWS, "calibration"), np.full(MIN_ROWS, "day1"), {})
    with pytest.raises(MotionlessRows) as refused:
        discover_machine(still, tolerance=ParameterPrior.default(data.robot))
    assert refused.value.rows == MIN_ROWS


@pytest.mark.parametrize("robot_name,effect,coef", POLICY_CASES)
def test_the_policy_names_the_effect_judges_it_on_the_validation_rows_and_gives_its_calibration(robot_name, effect,
                                                                                                 coef):
    data = synthetic(robot_name, effect, coef, seed=4, n=ROWS, noise=NOISE)
    sets = np.array(["calibration"] * (ROWS - VALIDATION_ROWS) + ["validation"] * VALIDATION_ROWS)
    outcome = discover_machine(rows_of(data, sets), tolerance=ParameterPrior.default(data.robot))
    np.testing.assert_array_equal(outcome.analysed, np.arange(ROWS - VALIDATION_ROWS))
    np.testing.assert_array_equal(outcome.validation, np.arange(ROWS - VALIDATION_ROWS, ROWS))
    assert outcome.discovery.effects == (effect,) and outcome.judgement.rejected == ()
    assert outcome.judgement.fold.kind == "validation" and outcome.basis == "recorded validation rows"
    assert outcome.judgement.model.unshifted_rms_mm < outcome.judgement.geometry.unshifted_rms_mm
    cal = outcome.calibration(frames={}, frames_std={}, recording={"name": "synthetic"})
    assert [e.name for e in cal.effects] == [effect] and cal.recording == {"name": "synthetic"}
    np.testing.assert_array_equal(cal.theta, outcome.discovery.chosen.theta)
    fitted = cal.effects[0].values
    np.testing.assert_array_equal(fitted, outcome.discovery.chosen.coefficients[outcome.discovery.chosen.slices()[effect]])
