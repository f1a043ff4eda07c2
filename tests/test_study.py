import json

import numpy as np
import pytest
from scipy.stats import chi2

from calib import paper
from calib.design import design_poses, full_workspace
from calib.hexapod import paper_hexapod
from calib.kinematics import forward_kinematics, inverse_kinematics
from calib.noise import SensorNoise
from calib.observability import analyze_observability
from pipeline.study import main, monte_carlo, trial_noise

NOMINAL = paper_hexapod()
TRUE = paper_hexapod(with_table3_errors=True)
NOISE = SensorNoise(position_mm=1e-3, orientation_rad=1e-6, distribution="normal")
POSES = design_poses(NOMINAL, 10, full_workspace(), NOISE, seed=2, n_candidates=300).poses
COMMANDED = inverse_kinematics(NOMINAL, POSES)


@pytest.fixture(autouse=True)
def _home(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))


def test_trial_noise_does_not_depend_on_chunking():
    whole = trial_noise(NOISE, 10, 7, np.arange(6))
    parts = np.concatenate([trial_noise(NOISE, 10, 7, np.arange(0, 2)), trial_noise(NOISE, 10, 7, np.arange(2, 6))])
    np.testing.assert_array_equal(whole, parts)
    assert not np.array_equal(whole, trial_noise(NOISE, 10, 8, np.arange(6)))
    assert whole.shape == (6, 10, 6)


def test_results_independent_of_worker_count():
    held = POSES[:3]
    a = monte_carlo(TRUE, COMMANDED, NOISE, 6, 5, methods=("forward", "paper"), heldout=held, workers=1)
    b = monte_carlo(TRUE, COMMANDED, NOISE, 6, 5, methods=("forward", "paper"), heldout=held, workers=2)
    for m in ("forward", "paper"):
        for k in a[m]:
            np.testing.assert_array_equal(a[m][k], b[m][k])


def test_forward_method_is_efficient_and_paper_method_is_not():
    """With Gaussian noise, e^T F e ~ chi-square(42) per trial for an efficient estimator."""
    trials = 60
    r = monte_carlo(TRUE, COMMANDED, NOISE, trials, 11, methods=("forward", "paper"), workers=2)
    reached = forward_kinematics(TRUE, COMMANDED)
    F = analyze_observability(TRUE, reached, NOISE).fisher
    lo, hi = chi2.ppf([0.0005, 0.9995], 42 * trials) / trials
    q_fwd = np.einsum("ti,ij,tj->t", r["forward"]["errors"], F, r["forward"]["errors"]).mean()
    q_pap = np.einsum("ti,ij,tj->t", r["paper"]["errors"], F, r["paper"]["errors"]).mean()
    assert lo < q_fwd < hi
    assert q_pap > hi
    assert r["forward"]["success"].all()


def test_monte_carlo_validation():
    with pytest.raises(ValueError, match="trials must be a positive integer, got 0"):
        monte_carlo(TRUE, COMMANDED, NOISE, 0, 0)
    with pytest.raises(ValueError, match="methods must be a non-empty subset"):
        monte_carlo(TRUE, COMMANDED, NOISE, 2, 0, methods=("magic",))
    with pytest.raises(ValueError, match="workers must be >= 1, got -1"):
        monte_carlo(TRUE, COMMANDED, NOISE, 2, 0, workers=-1)


def test_cli_writes_summary_and_rrd(tmp_path, capsys):
    summary, rrd = tmp_path / "s.json", tmp_path / "s.rrd"
    argv = ["--trials", "4", "--poses", "paper", "--workspace", "paper", "--heldout", "5", "--workers", "1",
            "--method", "both", "--summary-json", str(summary), "--rrd", str(rrd)]
    assert main(argv) == 0
    assert "study: 4/4 trials" in capsys.readouterr().err
    s = json.loads(summary.read_text())
    assert s["n_poses"] == 10 and s["trials"] == 4 and set(s["methods"]) >= {"forward", "paper"}
    f = s["methods"]["forward"]
    assert set(f["mse_over_crb"]) == set(s["crb_std_mm"]) and len(f["mse_over_crb"]) == 42
    assert 0 < f["heldout_position_mm"]["mean"] <= f["heldout_position_mm"]["rms"]
    assert s["predicted_heldout_position_rms_mm_at_crb"] > 0
    assert s["observability"]["scaled_condition_number"] > 1e3  # the paper's poses
    from rerun.chunk import RrdReader
    ents = {str(c.entity_path) for c in RrdReader(rrd).stream().to_chunks()}
    for e in ("/study/observability/singular_values", "/study/observability/crb_std_mm",
              "/study/forward/mse_over_crb", "/study/paper/empirical_std_mm",
              "/study/forward/heldout_position_um", "/study/summary"):
        assert e in ents, e
    with pytest.raises(SystemExit, match="exists; pass --overwrite"):
        main(argv)


def test_cli_reads_a_command_file(tmp_path):
    from pipeline.design import write_command_file

    cmd = tmp_path / "c.csv"
    write_command_file(cmd, paper.TABLE4_NOMINAL_POSES, inverse_kinematics(NOMINAL, paper.TABLE4_NOMINAL_POSES), {})
    summary = tmp_path / "s.json"
    assert main(["--trials", "2", "--poses", str(cmd), "--heldout", "0", "--workers", "1",
                 "--summary-json", str(summary)]) == 0
    s = json.loads(summary.read_text())
    assert s["n_poses"] == 10 and s["methods"]["forward"]["heldout_position_mm"] is None


def test_cli_random_poses_and_random_errors(tmp_path):
    summary = tmp_path / "s.json"
    assert main(["--trials", "3", "--poses", "random", "--n-poses", "8", "--workspace", "paper", "--errors", "random",
                 "--heldout", "3", "--workers", "1", "--summary-json", str(summary)]) == 0
    s = json.loads(summary.read_text())
    assert s["n_poses"] == 8 and s["true_errors"] == "random" and s["criterion"] is None


@pytest.mark.parametrize("argv, match", [
    (["--trials", "1"], "--trials must be >= 2"),
    (["--n-poses", "6"], "--n-poses must be >= 7"),
    (["--noise-mm", "-1"], "--noise-mm/--noise-rad: position_mm must be finite and >= 0"),
    (["--poses", "missing.csv"], "--poses: command file missing.csv not found"),
])
def test_cli_validation(argv, match):
    with pytest.raises(SystemExit, match=match):
        main(argv)
