"""Make docs/klipper.md's worked example: ``examples/klipper/printer.cfg``, a linear Delta
printer's Klipper config after ``DELTA_CALIBRATE`` and ``DELTA_ANALYZE``, as Klipper leaves it
(seeded: the same file every time).

    python examples/make_klipper_example.py     # from the repository's root; make_examples.py calls it too

The printer is the MuJoCo linear Delta of issue 49's comparison (``tests/klipper_comparison.py``,
seed :data:`SEED`): configured with a 140 mm delta_radius, 250 mm arms, endstops at 303.9 mm and 16
microsteps of a 40 mm rotation_distance, built with towers off by tenths of a millimetre and
degree, leaning by tenths of a degree, one rod pair a millimetre unequal, step distances 0.3 % off
and the bed 0.2 mm high and tilted. Probed at 61 points (0.01 mm noise) within 90 mm and the
calibration object's 12 distances measured (0.02 mm); the SAVE_CONFIG block holds Klipper's
DELTA_CALIBRATE fit of them (the tests' independent implementation, ``tests/klipper_reference.py``)
and the ``[delta_calibrate]`` block of stable positions, written as Klipper writes it.
"""
from __future__ import annotations

import sys
from pathlib import Path

#: The folder the example is written to, beside this script.
FOLDER = Path(__file__).resolve().parent / "klipper"
TESTS = Path(__file__).resolve().parent.parent / "tests"
#: The MuJoCo printer's seed and whether gauge heights were measured (Klipper's own data: no).
SEED, GAUGES = 1, False


def write_klipper_example(folder: Path = FOLDER) -> Path:
    """Write ``folder/printer.cfg`` and return its path."""
    sys.path.insert(0, str(TESTS))
    import klipper_comparison

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "printer.cfg"
    path.write_text(klipper_comparison.printer_cfg_text(SEED, GAUGES))
    return path


if __name__ == "__main__":
    print(f"wrote {write_klipper_example()}")
