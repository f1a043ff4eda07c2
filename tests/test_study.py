import json
import re

import numpy as np
import pytest
from scipy.stats import chi2

import calib.robots
from calib.design import design_poses, minimum_poses, robot_workspace
from calib.noise import SensorNoise
from calib.observability import analyze_observability, free_indices
from calib.robot import KinematicsError
from calib.robots import default_robot, reference_errors, reference_poses
from pipeline.study import main
from pipeline.workflows.study import compensation_errors, monte_carlo, trial_noise, true_errors

ROBOTS = sorted(calib.robots.ROBOTS)
NOISE = SensorNoise(position_mm=1e-3, orientation_rad=1e-6, distribution="normal")
HEXAPOD = default_robot("hexapod")


def setup(name):
    """(robot, true parameters, designed poses, commanded joints) of a robot."""
    robot = default_robot(name)
    kind = "reference" if reference_poses(robot) is not None else "random"
    theta = robot.table.nominal + true_errors(robot, kind, 0)
    # Twice the fewest poses that determine the robot: exactly determined, the rus's weak
    # combinations (docs/rus.md) make the estimate non-linear in the noise and the forward
    # method's spread 3x its bound (measured); with twice as many, it meets it.
    poses = design_poses(robot, robot.table.nominal, max(10, 2 * minimum_poses(robot)), robot_workspace(robot, "full"),
                         NOISE, seed=2, n_candidates=300).poses
    return robot, theta, poses, robot.inverse_kinematics(robot.table.nominal, poses)


@pytest.fixture(autouse=True)
def _home(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))


@pytest.mark.parametrize("name", ROBOTS)
def test_trial_noise_does_not_depend_on_chunking(name):
    robot = default_robot(name)
    noise = SensorNoise(1e-3, 1e-6, "normal", joint=1e-4)
    whole = trial_noise(robot, noise, 10, 7, np.arange(6))
    parts = [trial_noise(robot, noise, 10, 7, np.arange(0, 2)), trial_noise(robot, noise, 10, 7, np.arange(2, 6))]
    for k in range(2):
        np.testing.assert_array_equal(whole[k], np.concatenate([parts[0][k], parts[1][k]]))
        assert not np.array_equal(whole[k], trial_noise(robot, noise, 10, 8, np.arange(6))[k])
    assert whole[0].shape == (6, 10, robot.pose_dim) and whole[1].shape == (6, 10, robot.n_chains)
    # the pose noise stream does not depend on whether joint noise is simulated
    np.testing.assert_array_equal(whole[0], trial_noise(robot, NOISE, 10, 7, np.arange(6))[0])
    assert not np.any(trial_noise(robot, NOISE, 10, 7, np.arange(6))[1])


@pytest.mark.parametrize("name", ROBOTS)
def test_true_errors(name):
    robot = default_robot(name)
    e = true_errors(robot, "random", 3, error_mm=0.05, error_rad=1e-3)
    _, idx = free_indices(robot)
    fixed = np.setdiff1d(np.arange(robot.n_parameters), idx)
    assert np.all(e[fixed] == 0) and np.all(e[idx] != 0)
    angle = robot.table.angle_mask()
    assert np.all(np.abs(e[angle]) <= 1e-3) and np.all(np.abs(e[~angle]) <= 0.05)
    np.testing.assert_array_equal(e, true_errors(robot, "random", 3, error_mm=0.05, error_rad=1e-3))
    np.testing.assert_array_equal(true_errors(robot, "reference", 4), reference_errors(robot, 4))


@pytest.mark.slow
@pytest.mark.parametrize("name", ROBOTS)
def test_results_independent_of_worker_count(name, dask_two_workers):
    """The study on a local Dask cluster of two workers gives the numbers of one worker (same seed)."""
    assert len(dask_two_workers.nthreads()) == 2
    robot, theta, poses, commanded = setup(name)
    held = poses[:3]
    a = monte_carlo(robot, theta, commanded, NOISE, 6, 5, methods=("forward", "chainwise"), heldout=held,
                    workers=1, initial=poses)
    b = monte_carlo(robot, theta, commanded, NOISE, 6, 5, methods=("forward", "chainwise"), heldout=held,
                    client=dask_two_workers, initial=poses)
    for m in ("forward", "chainwise"):
        for k in a[m]:
            np.testing.assert_array_equal(a[m][k], b[m][k])
        assert a[m]["errors"].shape == (6, len(robot.free_default))


@pytest.mark.slow  # starts a Dask cluster (kernel-independent: once, in CI's README run)
def test_study_on_its_own_local_cluster():
    """A local cluster started by the study itself (``workers=2``), and the study here, agree."""
    robot, theta, poses, commanded = setup("hexapod")
    a = monte_carlo(robot, theta, commanded, NOISE, 4, 9, workers=1, initial=poses)
    b = monte_carlo(robot, theta, commanded, NOISE, 4, 9, workers=2, initial=poses)
    np.testing.assert_array_equal(a["forward"]["errors"], b["forward"]["errors"])


@pytest.mark.parametrize("name", ROBOTS)
def test_forward_method_is_efficient(name):
    """With Gaussian noise, e^T F e ~ chi-square(F) per trial for an efficient estimator; the
    hexapod paper's per-leg least squares is not efficient (its leg residuals' noise depends on
    the pose and is shared between legs)."""
    robot, theta, poses, commanded = setup(name)
    trials = 60
    r = monte_carlo(robot, theta, commanded, NOISE, trials, 11, methods=("forward", "chainwise"), workers=1,
                    initial=poses)
    reached = robot.forward_kinematics(theta, commanded, initial=poses)
    a = analyze_observability(robot, theta, reached, NOISE, joints=commanded)
    lo, hi = chi2.ppf([0.0005, 0.9995], a.n_free * trials) / trials
    q = {m: np.einsum("ti,ij,tj->t", r[m]["errors"], a.fisher, r[m]["errors"]).mean() for m in r}
    assert lo < q["forward"] < hi
    assert r["forward"]["success"].all()
    if name == "hexapod":
        assert q["chainwise"] > hi


def test_forward_method_is_efficient_with_joint_noise():
    robot, theta, poses, commanded = setup("delta")
    noise = SensorNoise(1e-3, 0.0, "normal", joint=2e-5)
    trials = 60
    r = monte_carlo(robot, theta, commanded, noise, trials, 12, workers=1, initial=poses)
    reached = robot.forward_kinematics(theta, commanded, initial=poses)
    a = analyze_observability(robot, theta, reached, noise, joints=commanded)
    b = analyze_observability(robot, theta, reached, NOISE, joints=commanded)
    assert a.crb_rms > 1.2 * b.crb_rms  # the joint noise counts
    lo, hi = chi2.ppf([0.0005, 0.9995], a.n_free * trials) / trials
    assert lo < np.einsum("ti,ij,tj->t", r["forward"]["errors"], a.fisher, r["forward"]["errors"]).mean() < hi


@pytest.mark.parametrize("name", ROBOTS)
def test_compensation_errors(name):
    robot, theta, poses, _ = setup(name)
    pos, ori = compensation_errors(robot, theta, theta, poses)
    assert np.abs(pos).max() < 1e-9 and np.abs(ori).max() < 1e-12
    pos, _ = compensation_errors(robot, theta, robot.table.nominal, poses)
    q = robot.inverse_kinematics(robot.table.nominal, poses)
    expected = robot.forward_kinematics(theta, q, initial=poses) - poses
    np.testing.assert_allclose(pos, np.linalg.norm(expected[:, ~robot.angle_pose_mask], axis=1), rtol=1e-12)
    far = robot.full_workspace_bounds()[:, 1] * 10 + 1e3
    with pytest.raises(KinematicsError):
        compensation_errors(robot, theta, theta, far[None])


def test_monte_carlo_validation():
    robot, theta, poses, commanded = setup("hexapod")
    with pytest.raises(ValueError, match="trials must be a positive integer, got 0"):
        monte_carlo(robot, theta, commanded, NOISE, 0, 0)
    with pytest.raises(ValueError, match="methods must be a non-empty subset"):
        monte_carlo(robot, theta, commanded, NOISE, 2, 0, methods=("paper",))
    for workers in (-1, 0):  # 0 is no worker, not the default
        with pytest.raises(ValueError, match=f"workers must be >= 1, got {workers}"):
            monte_carlo(robot, theta, commanded, NOISE, 2, 0, workers=workers)
    with pytest.raises(TypeError, match="robot must be a registered calib.robot.Robot"):
        monte_carlo("hexapod", theta, commanded, NOISE, 2, 0)


def _entities(path):
    from rerun.chunk import RrdReader

    return {str(c.entity_path): c for c in RrdReader(path).stream().to_chunks()}


@pytest.mark.parametrize("name, poses", [("hexapod", "reference"), ("delta", "designed")])
def test_cli_writes_summary_and_rrd(tmp_path, capsys, name, poses):
    robot = default_robot(name)
    summary, rrd = tmp_path / "s.json", tmp_path / "s.rrd"
    argv = ["--robot", name, "--trials", "4", "--poses", poses, "--workspace", "default", "--heldout", "5",
            "--workers", "1", "--method", "both", "--summary-json", str(summary), "--rrd", str(rrd)]
    if poses == "designed":
        argv += ["--n-poses", "8"]
    assert main(argv) == 0
    out, err = capsys.readouterr()  # --workers 1: the four chunks (one trial each) counted here, on stderr
    assert err.startswith("study: 0/4 tasks") and re.search(r"^study: 4/4 tasks \(.* s\), done$", err, re.M)
    assert "parameter error RMS" not in err  # the result is on stdout, a line a method
    assert [line.split(":")[0] for line in out.splitlines()] == ["forward", "chainwise"]
    assert all("parameter error RMS" in line and "MSE/CRB per parameter" in line for line in out.splitlines())
    s = json.loads(summary.read_text())
    assert s["robot"] == name and s["trials"] == 4 and set(s["methods"]) == {"forward", "chainwise"}
    assert s["n_poses"] == (10 if poses == "reference" else 8)
    assert s["true_errors"] == ("reference" if name == "hexapod" else "random")
    f = s["methods"]["forward"]
    assert list(f["mse_over_crb"]) == list(s["crb_std"]) == list(robot.free_default)
    assert 0 < f["heldout_position_mm"]["mean"] <= f["heldout_position_mm"]["rms"]
    assert s["predicted_heldout_position_rms_mm_at_crb"] > 0
    if name == "hexapod":
        assert s["observability"]["scaled_condition_number"] > 1e3  # the paper's poses
    ents = _entities(rrd)
    for e in ("/study/observability/singular_values", "/study/observability/crb_std_mm",
              "/study/forward/mse_over_crb", "/study/chainwise/empirical_std_mm",
              "/study/forward/heldout_position_um", "/study/summary"):
        assert e in ents, e
    batch = ents["/study/forward/mse_over_crb"].to_record_batch()
    assert batch.column("parameter_names").to_pylist()[0] == list(robot.free_default)
    assert main(argv) == 2


@pytest.mark.parametrize("name", ROBOTS)
def test_cli_reads_a_command_file(tmp_path, name):
    from pipeline.formats import write_command_file

    robot, _, poses, commanded = setup(name)
    cmd = tmp_path / "c.csv"
    write_command_file(cmd, robot, poses, commanded, {})
    summary = tmp_path / "s.json"
    assert main(["--robot", name, "--trials", "2", "--poses", str(cmd), "--heldout", "0", "--workers", "1",
                 "--summary-json", str(summary)]) == 0
    s = json.loads(summary.read_text())
    assert s["n_poses"] == len(poses) and s["methods"]["forward"]["heldout_position_mm"] is None
    other = "delta" if name != "delta" else "hexapod"
    assert main(["--robot", other, "--trials", "2", "--poses", str(cmd), "--workers", "1"]) == 2


def test_cli_random_poses_and_random_errors(tmp_path):
    summary = tmp_path / "s.json"
    assert main(["--trials", "3", "--poses", "random", "--n-poses", "8", "--workspace", "default", "--errors", "random",
                 "--heldout", "3", "--workers", "1", "--summary-json", str(summary)]) == 0
    s = json.loads(summary.read_text())
    assert s["n_poses"] == 8 and s["true_errors"] == "random" and s["criterion"] is None


@pytest.mark.parametrize("name", ROBOTS)
def test_random_errors_no_machine_can_have_name_their_flags_and_what_fits(name, tmp_path, capsys):
    """Random errors of 1000 mm make no machine (a Delta's arm of negative length) or one that
    cannot reach the study's poses: exit 2, one line naming --error-mm and --error-rad and the
    errors that fit, nothing written (before: "error: Lb must be positive, got [...]"); the study
    with the errors named runs."""
    summary = tmp_path / "s.json"
    n_poses = str(max(10, minimum_poses(default_robot(name))))
    argv = ["--robot", name, "--errors", "random", "--trials", "2", "--heldout", "5", "--n-poses", n_poses,
            "--poses", "random", "--workers", "1", "--summary-json", str(summary)]
    assert main(argv + ["--error-mm", "1000"]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("error: --error-mm 1000, --error-rad 0.001: ") and "would fit" in lines[0], lines[0]
    assert not summary.exists()
    fits = re.search(r"errors up to --error-mm (\S+) --error-rad (\S+) would fit", lines[0]).groups()
    assert 0 < float(fits[0]) < 1000
    assert main(argv + ["--error-mm", fits[0], "--error-rad", fits[1]]) == 0, capsys.readouterr().err
    assert json.loads(summary.read_text())["true_errors"] == "random"


@pytest.mark.parametrize("argv, match", [
    (["--trials", "1"], "--trials must be >= 2"),
    (["--n-poses", "6"], "--n-poses must be >= 7"),
    (["--noise-mm", "-1"], "--noise-mm/--noise-rad/--noise-joint: position_mm must be finite and >= 0"),
    (["--poses", "missing.csv"], "--poses: command file missing.csv not found"),
    (["--robot", "delta", "--poses", "reference"], "--poses reference: the delta has no reference poses"),
    (["--robot", "moon"], "--robot: unknown robot 'moon'"),
])
def test_cli_validation(argv, match, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert match in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.slow
def test_study_on_an_existing_cluster_by_address(dask_two_workers):
    """--scheduler ADDRESS: the same numbers on a cluster the study did not start."""
    robot, theta, poses, commanded = setup("delta")
    a = monte_carlo(robot, theta, commanded, NOISE, 4, 3, workers=1, initial=poses)
    b = monte_carlo(robot, theta, commanded, NOISE, 4, 3, scheduler=dask_two_workers.scheduler.address, initial=poses)
    np.testing.assert_array_equal(a["forward"]["errors"], b["forward"]["errors"])


@pytest.mark.parametrize("name", ROBOTS)
def test_a_recordings_sidecar_as_geometry_is_read_and_said(name, tmp_path, capsys):
    """``--geometry REC.json``, a recording's sidecar: the study reads its nominal geometry and
    says so (before: "cannot read a hexapod description: 'base_joints_mm'")."""
    from pipeline.formats import Recording, write_recording

    robot = default_robot(name)
    poses = np.repeat(robot.home_pose[None], 2, axis=0)
    rec = Recording(robot=robot, noise=NOISE, t_s=np.arange(2.0), joints=robot.inverse_kinematics(robot.table.nominal,
                                                                                                 poses),
                    measured=poses, sets=np.array(["calibration"] * 2), meta={})
    _, side = write_recording(tmp_path / "rec.csv", rec)
    summary = tmp_path / "s.json"
    assert main(["--robot", name, "--trials", "2", "--poses", "random", "--n-poses", str(max(10, minimum_poses(robot))),
                 "--heldout", "3", "--workers", "1", "--geometry", str(side), "--summary-json", str(summary)]) == 0
    note = f"--geometry {side} is a recording's sidecar: read the {name} its field 'nominal_geometry' describes"
    assert note in capsys.readouterr().out and json.loads(summary.read_text())["geometry_note"] == note
