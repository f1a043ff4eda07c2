"""A machine built by hand, calibrated with the defaults: the simulated twin of a hobby Stewart
platform (issue 37).

The MuJoCo hexapod of a hand-built size (base joints on a 300 mm circle, platform joints on a 150 mm
one, home 700 mm up: legs of about 720 mm), built with geometry errors of 1 to 3 mm on every
parameter, legs with one-sided strokes (0 to 280 mm from fully retracted, home 100 mm above
retracted), measured by a motion capture of 0.3 mm / 1.5 mrad (normal) in its own frame (574.3 mm
below the base, turned 2 degrees): a 10 x 10 level grid at the home height (the calibration rows,
commanded with the nominal inverse kinematics, as a lab does) and 40 runs off it (tilted up to
4.6 degrees, 50 mm above and below the grid; validation rows). No tolerance is declared.

Independent truths: the errors injected (their RMS is the tolerance to learn), a fit told that
tolerance (``--tolerance``), the off-plane rows the fit never saw.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from calib.measurement import compose
from pipeline.formats.recording import Recording, write_recording
from pipeline.run import run
from pipeline.simulation.testbed import Testbed
from tests.rehomed_twin import CAPTURE_FRAME, CAPTURE_NOISE, hand_built_hexapod, level_grid, off_plane_runs

#: The acceptance of issue 37, point 7: within 1.5 times the fit told the true tolerance.
TOLD_RATIO = 1.5


#: The runs off the grid (validation rows).
OFF_PLANE_ROWS = 40


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    """The recording of the twin (MuJoCo), and the RMS of its injected errors."""
    robot = hand_built_hexapod()
    rng = np.random.default_rng(37)
    errors = rng.uniform(1.0, 3.0, robot.n_parameters) * rng.choice([-1.0, 1.0], robot.n_parameters)
    theta = robot.table.nominal + errors
    poses = np.vstack([level_grid(), off_plane_runs(rng, OFF_PLANE_ROWS)])
    commands = robot.inverse_kinematics(robot.table.nominal, poses)
    limits = robot.joint_limits()
    assert np.all((commands > limits[:, 0]) & (commands < limits[:, 1])), "the runs stay inside the legs' ranges"
    measured = Testbed(robot, theta, noise=CAPTURE_NOISE, seed=5).measure(commands).measured
    sets = np.array(["calibration"] * 100 + ["validation"] * 40)
    rec = Recording(robot=robot, noise=CAPTURE_NOISE, t_s=np.arange(len(poses), dtype=float), joints=commands,
                    measured=compose(CAPTURE_FRAME, robot, measured), sets=sets,
                    meta={"simulation": {"injected_errors": robot.table.to_dict(errors)}})
    folder = tmp_path_factory.mktemp("hand_built")
    csv, _ = write_recording(folder / "hand.csv", rec)
    k = slice(0, 100)
    grid = Recording(robot=robot, noise=CAPTURE_NOISE, t_s=rec.t_s[k], joints=rec.joints[k], measured=rec.measured[k],
                     sets=rec.sets[k], meta=rec.meta)
    write_recording(folder / "grid.csv", grid)
    return csv, float(np.sqrt(np.mean(errors ** 2)))


def _run(csv, out, *flags):
    summary = out / "summary.json"
    run(["--real", str(csv), "--out", str(out), "--quiet", "--summary-json", str(summary), *flags])
    return json.loads(summary.read_text())


def test_the_defaults_learn_the_tolerance_and_match_a_fit_told_it(twin, tmp_path):
    csv, rms = twin
    learnt = _run(csv, tmp_path / "defaults")
    told = _run(csv, tmp_path / "told", "--tolerance", f"mm={rms:.6g}")
    prior = learnt["prior"]
    assert prior["source"].startswith("tolerance estimated from the data")
    assert "default 0.1 mm is contradicted" in prior["source"]
    assert rms / 2 < prior["learnt"]["tolerance"]["mm"] < 2 * rms
    assert learnt["success"], learnt["verdict"]["words"]
    assert learnt["parameter_error"]["rms_mm"] <= TOLD_RATIO * told["parameter_error"]["rms_mm"]
    held, held_told = learnt["heldout_position_error_mm"], told["heldout_position_error_mm"]
    assert held["after"] <= TOLD_RATIO * held_told["after"]
    assert held["after"] < held["before"] / 3, "the off-plane runs are predicted far better than nominal"
    # the verdict agrees with its numbers: parameters the data moved are the data's, few implausible
    assert learnt["directions_determined"] >= 10, "the grid determines combinations, and the summary says how many"
    assert len(learnt["implausible_parameters"]) <= 3


def test_the_old_default_declared_is_said_contradicted_with_figures(twin, tmp_path):
    csv, rms = twin
    s = _run(csv, tmp_path, "--tolerance", "mm=0.1")
    words = [w for w in s["warnings"] if w.startswith("the declared tolerance (0.1 mm) is contradicted")]
    assert words and "nats" in words[0] and "the rows support" in words[0]
    assert s["prior"]["learnt"]["contradicted"] and s["prior"]["learnt"]["wider_than_reference"] == ["mm"]


def test_level_targets_inside_the_grid_are_inside_the_domain_with_a_tilted_capture_body(tmp_path):
    """The capture body is mounted on the platform turned 2 degrees about x (every measured
    orientation carries it, the platform is level): the calibration's domain is the platform's,
    so level targets inside the grid compensate without a domain warning, and a target tilted by
    0.2 rad (far beyond anything the grid saw) is still warned of. Kinematic model, 0.3 mm / 1.5
    mrad capture noise."""
    from calib.rotation import euler_from_matrix, rotation_matrix
    from pipeline.workflows.compensate import CompensateSettings, run_compensation

    robot = hand_built_hexapod()
    rng = np.random.default_rng(8)
    errors = rng.uniform(1.0, 3.0, robot.n_parameters) * rng.choice([-1.0, 1.0], robot.n_parameters)
    theta = robot.table.nominal + errors
    grid = level_grid()
    commands = robot.inverse_kinematics(robot.table.nominal, grid)
    platform = robot.forward_kinematics(theta, commands, initial=grid)
    body = rotation_matrix(np.array([np.deg2rad(2.0), 0.0, 0.0]))
    seen = platform.copy()
    seen[:, 3:] = euler_from_matrix(rotation_matrix(platform[:, 3:]) @ body)
    seen += rng.normal(size=seen.shape) * CAPTURE_NOISE.pose_std(robot.pose_units)
    rec = Recording(robot=robot, noise=CAPTURE_NOISE, t_s=np.arange(100.0), joints=commands,
                    measured=compose(CAPTURE_FRAME, robot, seen), sets=np.array(["calibration"] * 100), meta={})
    csv, _ = write_recording(tmp_path / "tilted.csv", rec)
    run(["--real", str(csv), "--out", str(tmp_path), "--quiet", "--name", "tilted"])
    targets = grid[(np.abs(grid[:, 0]) < 100) & (np.abs(grid[:, 1]) < 100)][::4]
    tilted = np.r_[0.0, 0.0, 700.0, 0.2, 0.0, 0.0]
    names = ["x_mm", "y_mm", "z_mm", "alpha_rad", "beta_rad", "gamma_rad"]
    for label, rows in (("level", targets), ("tilted", np.vstack([targets, tilted]))):
        (tmp_path / f"{label}.csv").write_text(",".join(names) + "\n" + "\n".join(
            ",".join(repr(float(v)) for v in p) for p in rows) + "\n")
    level = run_compensation(CompensateSettings(calibration=tmp_path / "tilted.calibration.json",
                                                targets=tmp_path / "level.csv", out=tmp_path / "level_cmd.csv"))
    assert not [w for w in level.warnings if "outside" in w], level.warnings
    far = run_compensation(CompensateSettings(calibration=tmp_path / "tilted.calibration.json",
                                              targets=tmp_path / "tilted.csv", out=tmp_path / "tilted_cmd.csv"))
    assert any("alpha" in w for w in far.warnings), far.warnings


def test_discovery_runs_on_the_level_grid_with_the_defaults(twin, tmp_path):
    """``pipeline.discover --real`` on the 100 level poses alone, no tolerance declared: exit 0
    with its held-out figure, the geometry under the tolerance learnt from the rows, and what the
    plane cannot separate named with the poses that would."""
    from pipeline.discover import main as discover_main

    csv, _ = twin
    summary = tmp_path / "discovery.json"
    assert discover_main(["--real", str(csv.parent / "grid.csv"), "--no-resim", "--out", str(tmp_path),
                          "--summary-json", str(summary)]) == 0
    s = json.loads(summary.read_text())
    assert 0 < s["heldout_rms_after_mm"] < 3 * s["noise_floor_mm"], "the held-out figure, near the capture's noise"
    sep = s["separation"]
    assert sep["left_to_prior"], "a plane leaves heights and tilts to the prior, named"
    assert sep["poses"], "with the poses that would determine them"
    assert sep["prior_source"].startswith("tolerance estimated from the data")
