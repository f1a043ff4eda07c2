"""Speed of the law search (docs/discovery.md, "Proposed laws"): 120 poses of the hexapod with a
law outside the library injected (kinematic recordings: the exact forward kinematics of the legs
moved by the law, 1 um noise), one core:
``OPENBLAS_NUM_THREADS=1 PYTHONPATH=. taskset -c 0 python benchmarks/law_speed.py``.

Timed, best of ``--repeat``: the library's search (:func:`calib.effects.discover_effects` with
``laws=False``: selection, joint fit, remainder tests, outlier rounds) and the law search on what it
leaves (:func:`calib.effects.propose_law`: the dictionary, the greedy selection with its
cross-validation, the exact refit and the remainder tests), their ratio in the same run, and what
the law search found against the truth.
"""

from __future__ import annotations

import argparse

import numpy as np

from timing import best_time, print_table_head  # benchmarks/timing.py

from calib.effects import EffectData, discover_effects, propose_law
from calib.effects.laws import joint_quantities
from tests.joint_space_truth import moved_legs

#: name: (the law dq(q, c), each leg's constant).
LAWS = {"settle lag (last move)": (lambda q, c: c * q["last move"], -1.3e-4 * np.linspace(0.9, 1.1, 6)),
        "dead band growing with time": (lambda q, c: c * q["sign(last move)"] * q["t"], -4e-5 * np.linspace(0.3, 1, 6)),
        "scale quadratic in stroke": (lambda q, c: c * q["stroke"] ** 2, 2e-5 * np.linspace(0.3, 1, 6))}


def law_recording(law, n: int, seed: int) -> EffectData:
    """The hexapod with Table 3's errors, its legs moved by ``law`` (tests/joint_space_truth.py)."""
    return moved_legs(lambda data: law(joint_quantities(data)), n, seed)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--poses", type=int, default=120)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    print_table_head(f"{a.poses} poses, hexapod, seed {a.seed}",
                     ["law (truth)", "library named", "law found", "granularity", "constants found / truth (min-max)",
                      "CV residual before -> after (um)", "floor (um)", "library search (s)", "law search (s)", "ratio"])
    for name, (law, c) in LAWS.items():
        data = law_recording(lambda q: law(q, c), a.poses, a.seed)
        t_lib, disc = best_time(lambda: discover_effects(data, laws=False), a.repeat)
        sub = data.subset(disc.kept)
        t_law, found = best_time(lambda: propose_law(sub, disc.chosen), a.repeat)
        if found is None:
            print(f"| {name} | {disc.effect} | none | | | | | {t_lib:.2f} | {t_law:.2f} | {t_law / t_lib:.2f} |")
            continue
        s = found.summary()
        ratio = np.array(next(iter(s["constants"].values()))) / c
        print(f"| {name} | {disc.effect} | {' + '.join(s['terms'])} | {s['granularity']} | "
              f"{ratio.min():.3f}-{ratio.max():.3f} | {1e3 * s['cv_rms_before_mm']:.2f} -> {1e3 * s['cv_rms_after_mm']:.2f} | "
              f"{1e3 * s['noise_floor_mm']:.2f} | {t_lib:.2f} | {t_law:.2f} | {t_law / t_lib:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
