"""Every command's library function, called from Python with the command's defaults: the same
result as the command line (each command only parses, calls it and prints)."""

import json

import numpy as np
import pytest

from pipeline.workflows import (DesignSettings, DiscoverySettings, RunSettings, StudySettings, run_blind_suite,
                                run_calibration, run_design, run_discovery, run_fleet, run_study)


@pytest.fixture(autouse=True)
def _home(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))  # rerun writes analytics under HOME


def test_calibration_from_python_equals_the_command(tmp_path):
    from pipeline.run import run

    lib = run_calibration(RunSettings(out=tmp_path / "a", heldout=5))
    cli = run(["--out", str(tmp_path / "b"), "--heldout", "5", "--quiet"])
    assert lib.paths["rrd"].endswith("hexapod_paper.rrd")
    for key in ("identified_errors", "identified_std", "heldout_position_error_mm", "parameter_error"):
        assert lib.summary[key] == cli.summary[key]


def test_discovery_from_python_equals_the_command(tmp_path, capsys):
    from pipeline.discover import run

    settings = DiscoverySettings(scenario=("thermal_drift",), scenario_seed=2, resim=False, out=tmp_path / "a")
    lib = run_discovery(settings)
    cli = run(["--scenario", "thermal_drift", "--scenario-seed", "2", "--no-resim", "--out", str(tmp_path / "b")])
    assert lib.summary["verdict"] == cli.summary["verdict"] and lib.summary["effects"] == cli.summary["effects"]
    assert (tmp_path / "a" / "hexapod_thermal_drift_2_discover.rrd").exists()
    assert lib.summary["verdict"] in capsys.readouterr().out  # the command printed the same report
    with pytest.raises(ValueError, match="give one of a recording"):
        run_discovery(DiscoverySettings())


def test_design_from_python_equals_the_command(tmp_path):
    from pipeline.design import run

    lib = run_design(DesignSettings(poses=7, candidates=150, out=str(tmp_path / "a.csv")))
    cli = run(["--poses", "7", "--candidates", "150", "--out", str(tmp_path / "b.csv")])
    np.testing.assert_array_equal(lib.search.design.poses, cli.search.design.poses)
    assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()
    with pytest.raises(ValueError, match="--poses must be >= 7"):
        run_design(DesignSettings(poses=3, out=str(tmp_path / "c.csv")))


def test_study_from_python_equals_the_command(tmp_path):
    from pipeline.study import run

    lib = run_study(StudySettings(trials=3, poses="reference", heldout=5, workers=1,
                                  summary_json=str(tmp_path / "a.json")))
    cli = run(["--trials", "3", "--poses", "reference", "--heldout", "5", "--workers", "1"])
    assert lib.figures == cli.figures
    assert json.loads((tmp_path / "a.json").read_text())["methods"] == json.loads(json.dumps(lib.figures))


def test_blind_suite_and_fleet_from_python(tmp_path):
    res = run_blind_suite(["none"], range(1), workers=1)
    assert len(res) == 1 and res[0]["criteria"]

    folder = tmp_path / "fleet"
    folder.mkdir()
    made = run_calibration(RunSettings(out=folder, name="m1", heldout=5))
    assert made.paths["csv"].endswith("m1.csv")
    report = run_fleet(folder, workers=1, discover=False)
    assert [r["status"] for r in report.rows] == ["calibrated"]
