"""End-to-end tests of pipeline.delta_run (small runs into tmp_path)."""

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from calib.delta import PARAMETER_NAMES
from calib.delta_identification import DEFAULT_FREE
from pipeline.delta_run import CSV_COLUMNS, main

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("delta_run")
    rc = main(
        ["--configs", "10", "--heldout", "4", "--seed", "3", "--out", str(out), "--name", "t", "--summary-json", str(out / "summary.json")]
    )
    assert rc == 0
    return out


def test_outputs_exist(run_dir):
    for ext in ("rrd", "csv", "json"):
        assert (run_dir / f"t.{ext}").is_file()
    assert not list(run_dir.glob("*.tmp"))


def test_csv_and_sidecar(run_dir):
    with open(run_dir / "t.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == CSV_COLUMNS == ("t_s", "q1_rad", "q2_rad", "q3_rad", "x_mm", "y_mm", "z_mm")
    assert len(rows) == 1 + 10 + 4
    z = [float(r[6]) for r in rows[1:]]
    assert all(-600.0 < v < -300.0 for v in z)  # millimetres, plate below the base
    side = json.loads((run_dir / "t.json").read_text())
    assert side["robot"] == "delta"
    assert side["nominal_geometry"]["La_mm"] == 260.0 and side["nominal_geometry"]["Rb_mm"] == 194.0
    assert side["declared_noise"] == {"position_mm": 0.0, "joint_rad": 0.0}
    assert side["units"]["position"] == "mm"
    assert [p["name"] for p in side["parameter_table"]] == list(PARAMETER_NAMES)
    assert side["rows"] == {"calibration": [0, 10], "heldout": [10, 14]}


def test_summary_noise_free(run_dir):
    s = json.loads((run_dir / "summary.json").read_text())
    for method in ("ikm", "fkm"):
        g = s["gain_G"][method]
        assert set(g["per_parameter"]) == set(DEFAULT_FREE)
        assert g["mean"] > 99.99 and g["norm"] > 99.99
        assert s["parameter_error_after"][method]["max_abs_mm"] < 1e-5
        assert s["parameter_error_after"][method]["max_abs_rad"] < 1e-7
    assert set(s["identified_params"]) == set(PARAMETER_NAMES)
    assert set(s["injected_errors"]) == set(PARAMETER_NAMES)
    h = s["heldout_position_error_mm"]
    assert h["after"] < 1e-6 < 0.1 < h["before"] and h["max_after"] >= h["after"]
    assert s["fixed_parameters"] == ["Lay1", "Lay2", "Lay3"]
    assert [sorted(c) for c in s["null_space_at_nominal"]] == [[f"Lay{i}", f"alpha{i}"] for i in (1, 2, 3)]
    assert s["wall_time_s"] > 0 and s["rrd"].endswith("t.rrd")


def test_rrd_reads_back(run_dir):
    reader = RrdReader(run_dir / "t.rrd")
    assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 1
    entities = {c.entity_path for c in reader.stream()}
    for e in ("/delta/arms", "/delta/forearms", "/delta/plate", "/delta/shoulders", "/heldout/before", "/heldout/after", "/gain/ikm", "/gain/fkm", "/summary"):
        assert e in entities


def test_rrd_verify_cli(run_dir, tmp_path):
    """The rerun CLI ships with rerun-sdk; HOME points at a temporary folder (analytics)."""
    assert shutil.which("rerun") is not None
    env = dict(os.environ, HOME=str(tmp_path))
    r = subprocess.run(["rerun", "rrd", "verify", str(run_dir / "t.rrd")], env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr


def test_refuses_to_overwrite(run_dir, capsys):
    before = (run_dir / "t.csv").read_bytes()
    rc = main(["--configs", "8", "--heldout", "1", "--out", str(run_dir), "--name", "t"])
    assert rc == 1
    assert "refusing to overwrite existing file" in capsys.readouterr().err
    assert (run_dir / "t.csv").read_bytes() == before


def test_overwrite_flag_and_noise(tmp_path):
    args = ["--configs", "8", "--heldout", "2", "--out", str(tmp_path), "--name", "n", "--noise-mm", "0.001", "--noise-rad", "1e-4"]
    assert main(args + ["--summary-json", str(tmp_path / "s.json")]) == 0
    first = (tmp_path / "n.csv").read_text()
    assert main(args + ["--seed", "1", "--method", "fkm", "--solver", "gn", "--overwrite", "--summary-json", str(tmp_path / "s.json")]) == 0
    assert (tmp_path / "n.csv").read_text() != first
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["method"] == "fkm" and s["solver"] == "gn"
    assert s["noise"] == {"position_mm": 0.001, "joint_rad": 0.0001}
    assert s["identified_params"] == s["identified_params_by_method"]["fkm"]


@pytest.mark.parametrize(
    "argv, match",
    [
        (["--configs", "5"], "--configs must be >= 8"),
        (["--heldout", "0"], "--heldout must be >= 1"),
        (["--noise-mm", "-1"], "--noise-mm must be finite and >= 0"),
        (["--noise-rad", "nan"], "--noise-rad must be finite and >= 0"),
        (["--error-rad", "-0.1"], "--error-rad must be finite and >= 0"),
        (["--name", "../x"], "--name must be a plain file name"),
        (["--method", "xyz"], "invalid choice: 'xyz'"),
        (["--configs", "many"], "invalid int value: 'many'"),
    ],
)
def test_bad_arguments(argv, match, tmp_path, capsys):
    assert main(argv + ["--out", str(tmp_path)]) == 2
    assert match in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_help(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for opt in ("--configs", "--heldout", "--noise-mm", "--noise-rad", "--seed", "--method", "--out", "--name", "--summary-json"):
        assert opt in out


def test_module_entry_point(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""), HOME=str(tmp_path))
    r = subprocess.run([sys.executable, "-m", "pipeline.delta_run", "--help"], cwd=REPO, env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "--summary-json" in r.stdout
