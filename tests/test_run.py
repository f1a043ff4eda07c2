"""``python -m pipeline.run``: the hexapod paper's experiment end to end, files, names, bad input.
(What every robot must do through it is in tests/test_robot_contract.py.)"""

import json
from dataclasses import replace

import numpy as np
import pytest

from calib import paper
from calib.robots import ROBOTS
from pipeline.recording import read_recording, write_recording
from pipeline.rerun_log import rrd_entities
from pipeline.run import main, run

EXPECTED_ENTITIES = {
    "/machine/nominal/chains", "/machine/actual/chains", "/machine/calibrated/chains", "/machine/actual/platform",
    "/machine/errors/before", "/machine/errors/after", "/convergence/log10", "/convergence/chart/series/max_dQint_mm",
    "/heldout/position_error_um", "/heldout/orientation_error_urad", "/residuals/before_um", "/residuals/after_um",
    "/parameters/chart/bars/injected", "/parameters/chart/bars/identified", "/summary", "/key",
    "/observability/singular_values", "/observability/crb_std_mm", "/observability/combinations/names",
}


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    res = run(["--out", str(out), "--summary-json", str(out / "summary.json"), "--quiet"])
    return out, res


def test_default_scenario_improves_heldout_error_30x(default_run):
    out, res = default_run
    s = json.loads((out / "summary.json").read_text())
    h = s["heldout_position_error_mm"]
    assert h["before"] / h["after"] >= 30
    assert s["heldout_orientation_error_rad"]["after"] < s["heldout_orientation_error_rad"]["before"]
    names = list(res.result.robot.table.names)
    assert list(s["identified_errors"]) == names and names[:7] == ["B1.x", "B1.y", "B1.z", "dl1", "P1.x", "P1.y", "P1.z"]
    np.testing.assert_array_equal([s["injected_errors"][n] for n in names], paper.TABLE3_ERRORS.ravel())
    assert s["flagged_poses"] == [] and s["calibration_poses"] == 10 and s["robot"] == "hexapod"


def test_default_run_writes_the_three_files_and_a_laid_out_rrd(default_run):
    out, _ = default_run
    for ext in ("rrd", "csv", "json"):
        assert (out / f"hexapod_paper.{ext}").stat().st_size > 0
    assert EXPECTED_ENTITIES <= rrd_entities(out / "hexapod_paper.rrd")
    from rerun.chunk import RrdReader
    assert RrdReader(str(out / "hexapod_paper.rrd")).blueprints()  # opens laid out


def test_real_on_the_pipelines_own_csv_gives_the_same_errors(default_run, tmp_path):
    out, res = default_run
    real = run(["--real", str(out / "hexapod_paper.csv"), "--out", str(tmp_path), "--quiet"])
    np.testing.assert_array_equal(real.result.errors, res.result.errors)
    assert real.summary["heldout_poses"] == 50
    assert real.summary["heldout_position_error_mm"]["before"] > 10 * real.summary["heldout_position_error_mm"]["after"]


@pytest.mark.parametrize("method", ["chainwise", "forward"])
def test_noise_free_through_mujoco_recovers_table3(method, tmp_path):
    res = run(["--noise-mm", "0", "--heldout", "0", "--method", method, "--out", str(tmp_path), "--quiet"])
    assert np.abs(res.result.errors - paper.TABLE3_ERRORS.ravel()).max() < 1e-5


def test_default_name_is_numbered_and_explicit_names_are_never_overwritten(tmp_path, capsys):
    args = ["--heldout", "0", "--out", str(tmp_path), "--quiet"]
    run(args)
    second = run(args)
    assert second.paths["rrd"].endswith("hexapod_paper_2.rrd")
    before = (tmp_path / "hexapod_paper.csv").read_text()
    assert main(args + ["--name", "hexapod_paper"]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert (tmp_path / "hexapod_paper.csv").read_text() == before


def test_paper_row_a2_style_outlier_is_flagged_by_its_1_based_data_row(tmp_path):
    res = run(["--heldout", "0", "--out", str(tmp_path), "--name", "clean", "--quiet"])
    rec = read_recording(tmp_path / "clean.csv")
    bad = rec.measured.copy()
    bad[1, :3] += [0.02, -0.02, 0.0]  # like row A2: tens of micrometres off, second data row
    write_recording(tmp_path / "bad.csv", replace(rec, measured=bad))
    out = run(["--real", str(tmp_path / "bad.csv"), "--out", str(tmp_path), "--name", "bad_run", "--quiet"])
    assert out.summary["flagged_poses"] == [2]
    assert res.summary["flagged_poses"] == []


@pytest.mark.parametrize("argv,match", [
    (["--poses", "0"], "--poses must be a positive integer"),
    (["--poses", "many"], "--poses must be 'reference', an integer or a .csv command file"),
    (["--heldout", "-1"], "--heldout must be >= 0"),
    (["--noise-mm", "-1"], "--noise-mm must be >= 0"),
])
def test_bad_arguments_exit_2_naming_the_flag(argv, match, tmp_path, capsys):
    assert main(argv + ["--out", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_help_explains_options(capsys):
    with pytest.raises(SystemExit):
        run(["--help"])
    text = capsys.readouterr().out
    for opt in ("--robot", "--poses", "--heldout", "--noise-mm", "--noise-rad", "--noise-joint", "--seed", "--method",
                "--solver", "--gravity", "--payload-kg", "--out", "--summary-json", "--real"):
        assert opt in text
    for name in ROBOTS:
        assert name in text


def test_design_optimal_and_command_files_feed_the_run(tmp_path):
    from pipeline.design import main as design_main
    cmd = tmp_path / "design.csv"
    assert design_main(["--poses", "10", "--out", str(cmd)]) == 0
    from_file = run(["--poses", str(cmd), "--heldout", "5", "--out", str(tmp_path), "--name", "f", "--quiet"])
    paper_run = run(["--heldout", "5", "--out", str(tmp_path), "--name", "p", "--quiet"])
    optimal = run(["--poses", "10", "--design", "optimal", "--heldout", "5", "--out", str(tmp_path), "--name", "o",
                   "--quiet"])
    for r in (from_file, optimal):
        assert r.summary["calibration_poses"] == 10
        # designed poses determine the 42 parameters far better than the paper's
        assert r.summary["parameter_error"]["rms_mm"] < paper_run.summary["parameter_error"]["rms_mm"] / 10
