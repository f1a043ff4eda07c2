"""Benchmark of :func:`calib.probe.fit_probe` (run by hand): ``python benchmarks/probe_speed.py``.

Times the MAP fit of the default linear Delta to 100 probe touches (and to 100 touches plus 200
manual heights), and of the rotary Delta of tests/data/klipper/rotary_delta_printer.cfg to 100
touches (its errors drawn from its tolerances), the observability statement included, in CPU
seconds (best of 5). Target: 100 touches calibrate in under 1 s of work (issue 49).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from calib.prior import ParameterPrior
from calib.probe import ProbeData, fit_probe
from calib.robots.linear_delta import LinearDelta


def touches(robot, truth, rng, n, gauges=()):
    a, r = rng.uniform(0, 2 * np.pi, n), 90.0 * np.sqrt(rng.uniform(0, 1, n))
    bed = np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros(n)])
    gauge = np.concatenate([bed + [0, 0, h] for h in gauges]) if gauges else np.zeros((0, 3))
    return ProbeData(robot.inverse_kinematics(truth, bed), rng.normal(0, 0.01, n),
                     robot.inverse_kinematics(truth, gauge), np.repeat(np.asarray(gauges, float), n))


def rotary_case(rng):
    """``(robot, data)``: the rotary Delta of the reader's fixture and 100 touches within 50 mm."""
    from calib.klipper_rotary import delta_from_klipper_rotary
    from calib.probe import nominal_bed
    from pipeline.formats.klipper import klipper_printer, read_klipper_config

    cfg = Path(__file__).resolve().parents[1] / "tests" / "data" / "klipper" / "rotary_delta_printer.cfg"
    m = klipper_printer(read_klipper_config(cfg)).machine
    robot = delta_from_klipper_rotary(m.shoulder_radius_mm, m.shoulder_height_mm, m.angles_rad,
                                      m.upper_arm_lengths_mm, m.lower_arm_lengths_mm, m.endstops_mm)
    truth = robot.table.nominal + rng.normal(size=robot.n_parameters) * ParameterPrior.default(robot).std
    held = robot.table.indices(robot.gauge_fixed)
    truth[held] = robot.table.nominal[held]
    a, r = rng.uniform(0, 2 * np.pi, 100), 50.0 * np.sqrt(rng.uniform(0, 1, 100))
    bed = np.column_stack([r * np.cos(a), r * np.sin(a), np.full(100, nominal_bed(robot)[0])])
    return robot, ProbeData(robot.inverse_kinematics(truth, bed), rng.normal(0, 0.01, 100))


def timed(robot, data, repeat):
    best = np.inf
    for _ in range(repeat):
        t = time.process_time()
        fit = fit_probe(robot, data)
        best = min(best, time.process_time() - t)
    return best, fit


def main(repeat: int = 5) -> None:
    robot = LinearDelta.default()
    rng = np.random.default_rng(0)
    prior = ParameterPrior.default(robot)
    truth = robot.table.nominal + rng.normal(size=robot.n_parameters) * prior.std
    truth[robot.table.indices(robot.machine_only)] = robot.table.nominal[robot.table.indices(robot.machine_only)]
    for label, gauges in (("100 touches", ()), ("100 touches + 200 manual heights", (50.0, 100.0))):
        best, fit = timed(robot, touches(robot, truth, rng, 100, gauges), repeat)
        print(f"{label}: {best:.3f} s CPU (best of {repeat}), {fit.iterations} Gauss-Newton iterations, "
              f"{fit.directions_determined:.1f} of 24 directions determined")
    best, fit = timed(*rotary_case(rng), repeat)
    print(f"rotary Delta, 100 touches: {best:.3f} s CPU (best of {repeat}), {fit.iterations} Gauss-Newton iterations, "
          f"{fit.directions_determined:.1f} of 24 directions determined")


if __name__ == "__main__":
    main()
