"""tests/klipper_reference.py, the independent implementation of Klipper's linear-Delta kinematics
and DELTA_CALIBRATE fit the workbench is compared against: checked on its own."""

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares

import klipper_reference as kr
from pipeline.formats.klipper import read_klipper_printer

EPS = np.finfo(float).eps
#: What the printer believes (a Klipper config's nominal values) and a machine off it by tenths.
NOMINAL = kr.DeltaParams(140.0, (210.0, 330.0, 90.0), (250.0,) * 3, (300.0,) * 3, (0.0125,) * 3)
TRUE = kr.DeltaParams(140.4, (210.3, 329.6, 90.0), (250.0,) * 3, (301.2, 299.5, 300.7), (0.0125,) * 3)
TRUE_ARMS = kr.DeltaParams(140.4, (210.3, 329.6, 90.0), (250.3, 249.8, 250.5), (301.2, 299.5, 300.7), (0.0125,) * 3)
PROBE_Z = 0.3
#: DELTA_CALIBRATE's probing radius, mm, and its default points' fractions of it (the centre, then
#: six at 90 + 60 i degrees).
PROBE_RADIUS = 80.0
PROBE_SCATTER = (0.95, 0.90, 0.85, 0.70, 0.75, 0.80)


def probe_points() -> np.ndarray:
    a = np.radians(90.0 + 60.0 * np.arange(6))
    ring = np.stack([np.cos(a), np.sin(a)], axis=1) * (PROBE_RADIUS * np.array(PROBE_SCATTER))[:, None]
    xy = np.vstack([[0.0, 0.0], ring])
    return np.column_stack([xy, np.full(len(xy), PROBE_Z)])


def volume_points(n: int, seed: int) -> np.ndarray:
    """Seeded tool points in the print volume: radius up to 100 mm, z 0 to 150 mm."""
    rng = np.random.default_rng(seed)
    r, a = 100.0 * np.sqrt(rng.uniform(size=n)), rng.uniform(0, 2 * math.pi, n)
    return np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(0, 150, n)])


def simulated(true: kr.DeltaParams, with_distances: bool) -> kr.Measurements:
    """Noise-free touches at the probe points of ``true``, and (with distances) DELTA_ANALYZE's
    twelve pairs commanded by the nominal printer, measured on the ``true`` one."""
    xyz = probe_points()
    m = kr.Measurements(np.full(len(xyz), PROBE_Z), kr.stable_from_position(true, xyz))
    if not with_distances:
        return m
    steps = kr.stable_from_position(NOMINAL, kr.calibration_object_points())
    ends = kr.position_from_stable(true, steps)
    return kr.Measurements(m.touch_z, m.touch_steps, distances=np.linalg.norm(ends[:, 0] - ends[:, 1], axis=-1),
                           distance_steps=steps)


def test_forward_kinematics_of_inverse_kinematics_is_the_point_to_rounding():
    xyz = volume_points(500, 1)
    back = kr.position_from_stable(TRUE_ARMS, kr.stable_from_position(TRUE_ARMS, xyz))
    # a few dozen roundings of the carriage heights' size (< 600 mm) through a Jacobian of a few
    tolerance = 100 * EPS * float(np.max(kr.absolute_endstops(TRUE_ARMS)))
    assert np.max(np.abs(back - xyz)) < tolerance


def test_the_lower_sphere_intersection_is_the_brute_force_one_below_the_carriages():
    heights = kr.carriage_heights(TRUE_ARMS, volume_points(20, 2))
    centres = np.concatenate([np.broadcast_to(kr.towers_xy(TRUE_ARMS), (20, 3, 2)), heights[..., None]], axis=-1)
    radii2 = np.asarray(TRUE_ARMS.arms) ** 2
    found = kr.lower_sphere_intersection(centres, radii2)
    for c, x in zip(centres, found):
        start = c.mean(axis=0) - [0.0, 0.0, 200.0]
        brute = least_squares(lambda q: np.linalg.norm(c - q, axis=1) ** 2 - radii2, start, xtol=1e-15, ftol=1e-15,
                              gtol=1e-15).x
        # the residual's gradient is 2 |q - c| (about 500 mm) per mm: rounding of arm^2 / 500
        assert np.max(np.abs(brute - x)) < 1e3 * EPS * float(np.max(radii2)) / float(np.min(TRUE_ARMS.arms))
        other = least_squares(lambda q: np.linalg.norm(c - q, axis=1) ** 2 - radii2, c.mean(axis=0) + [0, 0, 200.0],
                              xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        assert other[2] > c[:, 2].max() > x[2]


def test_stable_positions_are_steps_from_the_absolute_endstops():
    xyz = volume_points(5, 3)
    steps = kr.stable_from_position(TRUE_ARMS, xyz)
    np.testing.assert_allclose(kr.carriage_heights_from_stable(TRUE_ARMS, steps), kr.carriage_heights(TRUE_ARMS, xyz),
                               rtol=0, atol=1e3 * EPS * 600)
    at_endstops = kr.position_from_stable(TRUE_ARMS, np.zeros(3))
    np.testing.assert_allclose(kr.carriage_heights(TRUE_ARMS, at_endstops),
                               np.asarray(TRUE_ARMS.endstops) + np.sqrt(np.asarray(TRUE_ARMS.arms) ** 2
                                                                        - TRUE_ARMS.radius ** 2), rtol=0,
                               atol=1e3 * EPS * 600)


def test_coordinate_descent_follows_klipper_s_step_rules():
    seen = []

    def error(d):
        seen.append(d["x"])
        return (d["x"] - 5.0) ** 2

    kr.coordinate_descent(("x",), {"x": 0.0}, error)
    # successes at +1, +1.1, +1.21, +1.331 (each step 1.1 times the last), then +1.4641 overshoots
    # and -1.4641 too: the step shrinks by 0.9
    steps = kr.GROW ** np.arange(5)
    expected = np.concatenate([[0.0], np.cumsum(steps), [np.sum(steps[:4]) - steps[4]]])
    np.testing.assert_allclose(seen[:7], expected, rtol=0, atol=10 * EPS * 5)
    assert seen[7] == pytest.approx(np.sum(steps[:4]) + kr.SHRINK * steps[4], abs=10 * EPS * 5)


def test_coordinate_descent_stops_when_the_steps_sum_to_its_threshold():
    names = ("a", "b", "c")
    _, rounds = kr.coordinate_descent(names, dict.fromkeys(names, 0.0), lambda d: 1.0)
    # nothing improves a constant: every step shrinks each round
    assert rounds == math.ceil(math.log(kr.STOP_SUM / (len(names) * kr.FIRST_STEP)) / math.log(kr.SHRINK))


def descent_tolerance(p: kr.DeltaParams, m: kr.Measurements) -> np.ndarray:
    """How far from the minimum the descent may stop, per adjusted parameter: where it stops, a step
    of at most STOP_SUM either way did not lower the error, so each gradient component is at most
    H_ii STOP_SUM / 2 (H the Gauss-Newton Hessian of the residuals); the parameters' distance from
    the minimum is H^-1 times the gradient. Bounded without the half (a parameter whose last step
    succeeded moved by at most STOP_SUM more)."""
    names = kr.adjusted_params(m)
    base = p.as_dict()
    h = 1e-6
    columns = []
    for name in names:
        plus, minus = dict(base), dict(base)
        plus[name] += h
        minus[name] -= h
        columns.append((kr.calibration_residuals(kr.DeltaParams.from_dict(plus), m)
                        - kr.calibration_residuals(kr.DeltaParams.from_dict(minus), m)) / (2 * h))
    jac = np.stack(columns, axis=1)
    hessian = jac.T @ jac
    return np.abs(np.linalg.inv(hessian)) @ (np.diag(hessian) * kr.STOP_SUM)


def recovered(found: kr.DeltaParams, true: kr.DeltaParams, m: kr.Measurements) -> tuple[np.ndarray, np.ndarray]:
    names = kr.adjusted_params(m)
    error = np.array([found.as_dict()[n] - true.as_dict()[n] for n in names])
    return np.abs(error), descent_tolerance(found, m)


def test_delta_calibrate_recovers_radius_angles_and_endstops_from_noise_free_touches():
    m = simulated(TRUE, with_distances=False)
    found, _ = kr.delta_calibrate(NOMINAL, m)
    error, tolerance = recovered(found, TRUE, m)
    assert np.all(error <= tolerance), (error, tolerance)
    start, _ = recovered(NOMINAL, TRUE, m)
    assert np.all(error < start / 100)
    assert found.arms == NOMINAL.arms and found.angles[2] == NOMINAL.angles[2]


@pytest.mark.slow
def test_delta_analyze_recovers_the_arms_too_from_noise_free_touches_and_distances():
    m = simulated(TRUE_ARMS, with_distances=True)
    found, _ = kr.delta_calibrate(NOMINAL, m)
    error, tolerance = recovered(found, TRUE_ARMS, m)
    assert np.all(error <= tolerance), (error, tolerance)
    assert np.max(np.abs(np.subtract(found.arms, TRUE_ARMS.arms))) < 0.1 * np.max(np.abs(np.subtract(NOMINAL.arms,
                                                                                                      TRUE_ARMS.arms)))


def test_the_distances_weigh_the_heights_by_klipper_s_measure_weight():
    m = simulated(TRUE_ARMS, with_distances=True)
    plain = kr.calibration_residuals(NOMINAL, kr.Measurements(m.touch_z, m.touch_steps))
    weighted = kr.calibration_residuals(NOMINAL, m)
    ratio = weighted[:len(plain)] / plain
    np.testing.assert_allclose(ratio, math.sqrt(len(m.distances) / (kr.MEASURE_WEIGHT * len(m.touch_z))), rtol=1e-14)


#: A printer's hand-written config (tests/data/klipper/small_delta.cfg) and its own [delta_calibrate] radius.
REGULAR_CONFIG = ((Path(__file__).resolve().parent / "data" / "klipper" / "small_delta.cfg").read_text()
                  .partition("[delta_calibrate]")[0] + "[delta_calibrate]\nradius: 80\n")


def test_the_written_block_is_read_back_by_the_format_reader_as_written(tmp_path):
    m = simulated(TRUE_ARMS, with_distances=True)
    manual_xyz = np.array([[0.0, 0.0, 50.0], [10.0, -5.0, 100.0]])
    m = kr.Measurements(m.touch_z, m.touch_steps, np.array([50.0, 100.0]),
                        kr.stable_from_position(TRUE_ARMS, manual_xyz), m.distances, m.distance_steps)
    path = tmp_path / "printer.cfg"
    path.write_text(REGULAR_CONFIG + "\n" + kr.save_config_text(TRUE_ARMS, m))
    printer = read_klipper_printer(path)

    def as_written(values, form):
        return np.vectorize(lambda v: float(form % v))(np.asarray(values, dtype=float))

    d, probe = printer.machine, printer.probe
    assert d.radius_mm == float("%.6f" % TRUE_ARMS.radius)
    np.testing.assert_array_equal(d.angles_rad, np.radians(as_written(TRUE_ARMS.angles, "%.6f")))
    np.testing.assert_array_equal(d.arm_lengths_mm, as_written(TRUE_ARMS.arms, "%.6f"))
    np.testing.assert_array_equal(d.endstops_mm, as_written(TRUE_ARMS.endstops, "%.6f"))
    np.testing.assert_array_equal(d.step_distances_mm, TRUE_ARMS.stepdists)
    np.testing.assert_array_equal(probe.touch_steps, as_written(m.touch_steps, "%.3f"))
    np.testing.assert_array_equal(probe.touch_z_mm, as_written(m.touch_z, "%.6f"))
    np.testing.assert_array_equal(probe.manual_steps, as_written(m.manual_steps, "%.3f"))
    np.testing.assert_array_equal(probe.manual_z_mm, as_written(m.manual_z, "%.6f"))
    np.testing.assert_array_equal(probe.distance_steps, as_written(m.distance_steps, "%.3f"))
    np.testing.assert_array_equal(probe.distance_mm, as_written(m.distances, "%.6f"))
    assert probe.radius_mm == 80.0
