"""Benchmark of the calib core (run by hand: ``python benchmarks/bench_calib.py``).

Identification from 100 poses with the paper's method and the forward method, and forward
kinematics of 10,000 poses; best of several repeats, ratios measured in the same run.
"""

from __future__ import annotations

import time

from calib import SensorNoise, forward_kinematics, identify_forward, identify_paper, inverse_kinematics, paper_hexapod, random_poses


def best(fn, repeat=5):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    nominal, actual = paper_hexapod(), paper_hexapod(with_table3_errors=True)
    noise = SensorNoise(0.001, 1e-6, "normal")
    targets = random_poses(100, 0)
    commanded = inverse_kinematics(nominal, targets)
    measured = forward_kinematics(actual, commanded) + noise.sample(100, 1)
    t_paper = best(lambda: identify_paper(nominal, commanded, measured))
    t_fwd = best(lambda: identify_forward(nominal, commanded, measured, noise))
    r_p = identify_paper(nominal, commanded, measured)
    r_f = identify_forward(nominal, commanded, measured, noise)
    lengths = inverse_kinematics(nominal, random_poses(10_000, 2))
    t_fk = best(lambda: forward_kinematics(actual, lengths))
    t_ik = best(lambda: inverse_kinematics(actual, random_poses(10_000, 2)))
    print("| task | paper method | forward method | ratio forward/paper |")
    print("|---|---|---|---|")
    print(f"| identify, 100 poses | {1e3 * t_paper:.1f} ms ({r_p.iterations} it) | {1e3 * t_fwd:.1f} ms "
          f"({r_f.iterations} jac) | {t_fwd / t_paper:.1f}x |")
    print(f"| forward kinematics, 10,000 poses | {1e3 * t_fk:.1f} ms ({1e6 * t_fk / 1e4:.2f} us/pose) | | |")
    print(f"| inverse kinematics, 10,000 poses | {1e3 * t_ik:.1f} ms | | |")


if __name__ == "__main__":
    main()
