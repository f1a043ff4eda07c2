"""``python -m pipeline.run``: the hexapod paper's experiment end to end, files, names, bad input.
(What every robot must do through it is in tests/test_robot_contract.py.)"""

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calib import paper
from calib.robots import ROBOTS
from pipeline.formats import read_recording, write_recording
from pipeline.views import rrd_entities
from pipeline.run import main, run

EXPECTED_ENTITIES = {
    "/machine/nominal/chains", "/machine/actual/chains", "/machine/calibrated/chains", "/machine/actual/platform",
    "/machine/errors/before", "/machine/errors/after", "/convergence/log10", "/convergence/chart/series/max_dQint_mm",
    "/heldout/position_error_um", "/heldout/orientation_error_urad", "/residuals/before_um", "/residuals/after_um",
    "/parameters/chart/bars/injected", "/parameters/chart/bars/identified", "/summary", "/key",
    "/observability/singular_values", "/observability/crb_std_mm", "/observability/combinations/names",
}


ROOT = Path(__file__).resolve().parent.parent

#: Modules the default run has no use for. Before issue 40 it loaded each of them (the calibration
#: file's writer imported the effects' records, they the registry and discovery, discovery
#: scipy.stats and with it scipy.optimize; pipeline.formats imported the lab exports' reader):
#: 0.6 s of its 2 s.
NOT_FOR_THE_DEFAULT_RUN = ("scipy.stats", "scipy.optimize", "calib.effects", "calib.effects.discovery",
                           "calib.effects.records", "pipeline.formats.lab_export")
#: ``--help`` parses no recording and runs nothing: no SciPy, MuJoCo, Rerun or calibration workflow.
NOT_FOR_HELP = ("scipy", "mujoco", "rerun", "pipeline.workflows.calibration", "pipeline.formats.recording")


def modules_loaded(statements: str, names, *args: str) -> dict[str, bool]:
    """Which of the modules ``names`` a fresh Python process (this tree first on its path) has
    loaded after running ``statements`` (``sys.argv[1:]`` = ``args``)."""
    code = f"{statements}\nimport json\nprint(json.dumps({{n: n in sys.modules for n in {list(names)!r}}}))"
    res = subprocess.run([sys.executable, "-c", "import sys\n" + code, *args], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_the_default_run_loads_no_discovery_scipy_stats_or_lab_export_reader(tmp_path):
    loaded = modules_loaded("import pipeline.run\nassert pipeline.run.main(['--out', sys.argv[1], '--quiet']) == 0",
                            NOT_FOR_THE_DEFAULT_RUN, str(tmp_path))
    assert not any(loaded.values()), [n for n, yes in loaded.items() if yes]
    assert (tmp_path / "hexapod_paper.calibration.json").exists()  # written without the effects' registry


def test_help_loads_neither_scipy_mujoco_nor_rerun():
    loaded = modules_loaded("import pipeline.run\ntry:\n    pipeline.run.main(['--help'])\nexcept SystemExit:\n    pass",
                            NOT_FOR_HELP)
    assert not any(loaded.values()), [n for n, yes in loaded.items() if yes]


def test_the_deferred_names_still_load_their_modules():
    """The probe sees a module loaded, and the names made lazy still resolve: reading one loads it."""
    loaded = modules_loaded("from calib.effects import discover_effects\nfrom pipeline.formats import read_map",
                            NOT_FOR_THE_DEFAULT_RUN[:4] + ("pipeline.formats.lab_export",))
    assert all(loaded.values()), loaded


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
    # Plain least squares (--no-prior): what the poses alone determine, the design's criterion.
    from_file = run(["--poses", str(cmd), "--heldout", "5", "--out", str(tmp_path), "--name", "f", "--quiet",
                     "--no-prior"])
    paper_run = run(["--heldout", "5", "--out", str(tmp_path), "--name", "p", "--quiet", "--no-prior"])
    optimal = run(["--poses", "10", "--design", "optimal", "--heldout", "5", "--out", str(tmp_path), "--name", "o",
                   "--quiet", "--no-prior"])
    for r in (from_file, optimal):
        assert r.summary["calibration_poses"] == 10
        # designed poses determine the 42 parameters far better than the paper's
        assert r.summary["parameter_error"]["rms_mm"] < paper_run.summary["parameter_error"]["rms_mm"] / 10
        assert not r.summary["prior"]["used"] and set(r.summary["determined_by"]["prior"]) == set()


def table4_recording(path, heldout=50, seed=1):
    """The paper's Table 4 as a recording: the printed measured poses at the paper's commanded leg
    lengths (the nominal inverse kinematics of its target poses), and, since the paper gives no
    validation poses, ``heldout`` validation rows simulated noise-free from the Table 3 machine."""
    from calib.noise import SensorNoise
    from calib.robots import paper_hexapod
    from calib.workspace import reachable_poses
    from pipeline.formats import Recording

    robot = paper_hexapod()
    nominal = robot.table.nominal
    actual = nominal + paper.TABLE3_ERRORS.ravel()
    cal_joints = robot.inverse_kinematics(nominal, paper.TABLE4_NOMINAL_POSES)
    targets = reachable_poses(robot, heldout, np.random.default_rng(seed))
    val_joints = robot.inverse_kinematics(nominal, targets)
    val_meas = robot.forward_kinematics(actual, val_joints, initial=targets)
    n = 10 + heldout
    # Declared noise: the paper's 1 um on positions; 1e-5 rad on angles, the print resolution of
    # Table 4's angles (some are printed to 4 decimals).
    rec = Recording(robot=robot, noise=SensorNoise(paper.PAPER_NOISE_MM, 1e-5), t_s=np.arange(n, dtype=float),
                    joints=np.vstack([cal_joints, val_joints]),
                    measured=np.vstack([paper.TABLE4_MEASURED_POSES, val_meas]),
                    sets=np.array(["calibration"] * 10 + ["validation"] * heldout),
                    meta={"scenario": "the hexapod paper's Table 4 (printed poses) + noise-free validation rows"})
    return write_recording(path, rec)[0]


def test_paper_table4_as_a_real_recording_leaves_row_a2_out(tmp_path):
    csv_path = table4_recording(tmp_path / "table4.csv")
    res = run(["--real", str(csv_path), "--out", str(tmp_path), "--summary-json", str(tmp_path / "s.json"), "--quiet"])
    s = res.summary
    assert s["flagged_poses"] == [2]  # row A2: second data row, file line 3
    assert s["outliers"]["left_out"] and not s["model_misfit"] and s["calibration_poses_used"] == 9
    h = s["heldout_position_error_mm"]
    assert h["before"] > 0.04 and h["after"] <= 0.001  # 53.5 um -> 0.15 um (0.32 um with --no-prior)
    assert s["without_flagged"]["heldout_position_error_mm"]["after"] == h["after"]
    # A2 used: 7.3 um with the default prior (11.9 um plain), against 0.15 um without it (0.32 um plain)
    assert s["with_flagged"]["heldout_position_error_mm"]["after"] > 5 * h["after"]
    assert json.loads((tmp_path / "s.json").read_text())["flagged_poses"] == [2]
    kept = run(["--real", str(csv_path), "--keep-outliers", "--out", str(tmp_path), "--quiet"]).summary
    assert kept["calibration_poses_used"] == 10 and not kept["outliers"]["left_out"]
    assert kept["heldout_position_error_mm"]["after"] == s["with_flagged"]["heldout_position_error_mm"]["after"]


def test_real_model_misfit_is_reported_in_words_and_no_row_is_left_out(tmp_path):
    """An unmodelled sag 20 times the declared noise over 60 calibration rows."""
    from tests.test_hostile_inputs import clean_recording

    rec = clean_recording(60, 20)
    measured = rec.measured + rec.noise.sample(80, 2)
    r2 = measured[:, 0] ** 2 + measured[:, 1] ** 2
    measured[:, 2] += 20 * rec.noise.position_mm * (2 * r2 / r2.max() - 1)
    csv_path, _ = write_recording(tmp_path / "sag.csv", replace(rec, measured=measured))
    s = run(["--real", str(csv_path), "--out", str(tmp_path), "--quiet"]).summary
    assert s["model_misfit"] and s["outliers"]["model_misfit"] and s["flagged_poses"] == []
    assert "model misfit" in s["outliers"]["verdict"] and s["calibration_poses_used"] == 60
    assert "does not fit to the declared noise" in s["message"]


def test_a_run_returns_its_objects_and_its_summary_keeps_no_private_key(tmp_path):
    """``RunResult`` carries the calibration as written, the simulated recording, the suggested
    poses (their poses and joints as the command file holds them) and the report as objects
    (issue 47, point 1); the summary has no private (underscore) key."""
    from calib.calibration import Calibration
    from pipeline.workflows.calibration import RunSettings, run_calibration

    result = run_calibration(RunSettings(out=tmp_path, name="objects"))
    assert not [k for k in result.summary if k.startswith("_")]
    written = Calibration.read(tmp_path / "objects.calibration.json")
    assert np.array_equal(result.calibration.theta, written.theta)
    assert result.calibration.recording == written.recording and written.recording["name"] == "objects.csv"
    assert result.simulated is not None and result.simulated.robot.name == "hexapod"
    from pipeline.formats import read_recording

    assert np.array_equal(result.simulated.joints, read_recording(tmp_path / "objects.csv").joints)
    from pipeline.formats import read_command_file

    suggested = result.suggested_poses  # the reference poses leave combinations to the prior: poses suggested
    poses, joints = read_command_file(tmp_path / "objects.suggested_poses.csv", result.simulated.robot)
    assert np.array_equal(suggested.poses, poses) and np.array_equal(suggested.joints, joints)
    assert suggested.texts() == ((tmp_path / "objects.suggested_poses.csv").read_text(),
                                 (tmp_path / "objects.suggested_poses.json").read_text())
    assert result.report.determination.suggested.poses == len(poses)
