"""Issue 49 point 4 on the MuJoCo linear Delta (tests/klipper_comparison.py): from Klipper's own
data (61 touches, the calibration object's 12 distances) the workbench's Klipper export should be
never worse over the print volume than Klipper's DELTA_CALIBRATE fit; with gauge heights at 50
and 100 mm it should leave at most 0.7 times Klipper's error.

Measured (held-out tool RMS, mm, workbench / Klipper): seed 1 (a) 0.225 / 0.415, (b) 0.135 / 0.386;
seed 2 (a) 0.165 / 0.475, (b) 0.130 / 0.366; seed 3 (a) 0.100 / 0.301, (b) 0.132 / 0.239. The
workbench's kinematics holds the effector's tilt from the 1 mm rod pair (calib.robots.linear_delta
.RodPairs), and the projection onto Klipper's parameters spends none on the print's shift in x, y
that the probe data do not fix (before both, seed 3 (a) was 0.337 against Klipper's 0.301).

The export read back by the reference implementation moves the MuJoCo machine's tool where
pipeline.compensate's commands do, within 1.5x (RMS over 300 held-out points of the volume), through
the files from a printer.cfg (measured ratios 1.05-1.42), but for seed 2 with the gauges: the
calibration's own commands reach 0.065 mm there, the export 0.130 (2.0x), and Klipper's parameters
cannot do better on that machine (their best projection of the true machine, the tilt and the leans
known exactly, leaves 0.116 mm): a strict expected failure, seen, of a bound that the workbench's own
accuracy outgrew. Through the files the export is never worse than Klipper's fit either (0.7x with
the gauges): the converted robot, the prior's centre, is the config as built (the sections above
the SAVE_CONFIG block), not Klipper's saved fit (which cost seed 2 0.673 mm against Klipper's 0.475).
"""

import tempfile
from functools import lru_cache
from pathlib import Path

import pytest

import klipper_comparison as kc

#: The issue's bound for (b): the export's held-out RMS at most this fraction of Klipper's.
GAUGED_RATIO = 0.7
#: The held-out bed's flatness under the export and its mesh "stays at the probe's noise": its RMS
#: within twice the touches' (the fit's own uncertainty and the mesh's interpolation add to it).
FLATNESS_NOISE_FACTOR = 2.0


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("gauges", [False, True])
def test_held_out_bed_flatness_stays_at_the_probe_noise(seed, gauges):
    flat = kc.compare(seed, gauges)["bed_flatness"]
    assert flat["rms_mm"] <= FLATNESS_NOISE_FACTOR * kc.NOISE.touch_mm, flat


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_never_worse_than_klipper_and_better_with_gauge_heights(seed):
    a = kc.compare(seed, gauges=False)
    assert a["workbench"]["rms_mm"] <= a["klipper"]["rms_mm"], a
    b = kc.compare(seed, gauges=True)
    assert b["workbench"]["rms_mm"] <= GAUGED_RATIO * min(a["klipper"]["rms_mm"], b["klipper"]["rms_mm"]), (a, b)


#: The issue's bound: the export read back by the reference implementation moves the tool no
#: further from the targets (RMS over the held-out volume) than this times pipeline.compensate's commands.
COMPENSATE_RATIO = 1.5


@lru_cache(maxsize=None)
def through_the_files(seed: int, gauges: bool) -> dict:
    """:func:`klipper_comparison.compare_with_compensate` in a folder of its own, once per case."""
    with tempfile.TemporaryDirectory() as folder:
        return kc.compare_with_compensate(seed, gauges, Path(folder))


@pytest.mark.slow
@pytest.mark.parametrize("seed, gauges", [(1, False), (1, True), (2, False), pytest.param(
    2, True, marks=pytest.mark.xfail(strict=True, reason="compensate 0.065 mm, the export 0.130 (2.0x): Klipper's "
                                     "parameters cannot hold this machine closer (their best projection of the true "
                                     "machine leaves 0.116 mm)")), (3, False), (3, True)])
def test_the_export_read_back_moves_the_tool_where_compensate_does(seed, gauges):
    r = through_the_files(seed, gauges)
    assert r["klipper_export"]["rms_mm"] <= COMPENSATE_RATIO * r["compensate"]["rms_mm"], r


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("gauges", [False, True])
def test_through_the_files_never_worse_than_klipper_and_better_with_gauge_heights(seed, gauges):
    """The converted robot, the prior's centre, is the config as built, not Klipper's saved fit:
    through the files too the export is never worse than Klipper's fit, at most 0.7x with the gauges."""
    r = through_the_files(seed, gauges)
    klipper = min(kc.compare(seed, g)["klipper"]["rms_mm"] for g in {False, gauges})
    assert r["klipper_export"]["rms_mm"] <= (GAUGED_RATIO if gauges else 1.0) * klipper, (r, klipper)
