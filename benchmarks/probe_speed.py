"""Benchmark of :func:`calib.probe.fit_probe` (run by hand): ``python benchmarks/probe_speed.py``.

Times the MAP fit of the default linear Delta to 100 probe touches (and to 100 touches plus 200
manual heights), the observability statement included, in CPU seconds (best of 5). Target: 100
touches calibrate in under 1 s of work (issue 49).
"""

from __future__ import annotations

import time

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


def main(repeat: int = 5) -> None:
    robot = LinearDelta.default()
    rng = np.random.default_rng(0)
    prior = ParameterPrior.default(robot)
    truth = robot.table.nominal + rng.normal(size=robot.n_parameters) * prior.std
    truth[robot.table.indices(robot.machine_only)] = robot.table.nominal[robot.table.indices(robot.machine_only)]
    for label, gauges in (("100 touches", ()), ("100 touches + 200 manual heights", (50.0, 100.0))):
        data = touches(robot, truth, rng, 100, gauges)
        best = np.inf
        for _ in range(repeat):
            t = time.process_time()
            fit = fit_probe(robot, data)
            best = min(best, time.process_time() - t)
        print(f"{label}: {best:.3f} s CPU (best of {repeat}), {fit.iterations} Gauss-Newton iterations, "
              f"{fit.directions_determined:.1f} of 24 directions determined")


if __name__ == "__main__":
    main()
