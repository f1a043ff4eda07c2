import json

import numpy as np
import pytest

from calib.design import feasibility, full_workspace, paper_workspace
from calib.hexapod import HexapodGeometry, paper_geometry, paper_hexapod
from calib.kinematics import inverse_kinematics
from pipeline.design import (
    COMMAND_COLUMNS,
    main,
    optimal_poses,
    read_command_file,
    write_command_file,
)

NOMINAL = paper_hexapod()


@pytest.fixture(autouse=True)
def _home(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))  # rerun writes analytics under HOME


def _entities(path):
    from rerun.chunk import RrdReader

    return {str(c.entity_path): c for c in RrdReader(path).stream().to_chunks()}


def bar_values(chunk):
    """The values of a static BarChart chunk (a tensor: shape + buffer)."""
    batch = chunk.to_record_batch()
    col = [n for n in batch.schema.names if n.startswith("BarChart:values")][0]
    tensor = batch.column(col).to_pylist()[0][0]
    return np.asarray(tensor["buffer"], dtype=float).reshape(tensor["shape"])


def test_cli_writes_command_file_sidecar_summary_and_rrd(tmp_path):
    out = tmp_path / "poses.csv"
    summary = tmp_path / "summary.json"
    rrd = tmp_path / "design.rrd"
    argv = ["--poses", "8", "--seed", "3", "--candidates", "300", "--out", str(out),
            "--summary-json", str(summary), "--rrd", str(rrd)]
    assert main(argv) == 0
    poses, lengths = read_command_file(out)
    assert poses.shape == (8, 6) and lengths.shape == (8, 6)
    np.testing.assert_allclose(lengths, inverse_kinematics(NOMINAL, poses), rtol=0, atol=1e-12)
    assert feasibility(NOMINAL, poses, full_workspace())["feasible"].all()
    np.testing.assert_array_equal(poses, optimal_poses(paper_geometry(), 8, "d", "full", 3, n_candidates=300))
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["criterion"] == "d" and side["seed"] == 3 and side["workspace"]["name"] == "full"
    assert HexapodGeometry.from_dict(side["geometry"]).home_lengths.tolist() == NOMINAL.geometry.home_lengths.tolist()
    s = json.loads(summary.read_text())
    assert s["observability"]["rank"] == 42 and len(s["observability"]["singular_values"]) == 42
    assert s["crb_rms_gain_vs_paper_poses"] > 1.0
    u = s["predicted_pose_uncertainty"]
    assert 0 < u["position_rms_um"]["mean"] <= u["position_rms_um"]["max"]
    ents = _entities(rrd)
    for e in ("/design/observability/singular_values", "/design/observability/crb_std_mm",
              "/design/observability/report", "/paper_poses/observability/singular_values", "/design/poses",
              "/design/pose_uncertainty"):
        assert e in ents, e
    np.testing.assert_allclose(bar_values(ents["/design/observability/crb_std_mm"]),
                               [s["observability"]["crb_std_mm"][n] for n in s["observability"]["crb_std_mm"]])


def test_cli_refuses_to_overwrite(tmp_path):
    out = tmp_path / "poses.csv"
    argv = ["--poses", "7", "--candidates", "100", "--out", str(out), "--workspace", "paper"]
    assert main(argv) == 0
    before = out.read_text()
    with pytest.raises(SystemExit, match="exists; pass --overwrite"):
        main(argv + ["--seed", "1"])
    assert out.read_text() == before
    assert main(argv + ["--seed", "1", "--overwrite"]) == 0
    assert out.read_text() != before
    poses, _ = read_command_file(out)
    assert feasibility(NOMINAL, poses, paper_workspace())["feasible"].all()
    assert not list(tmp_path.glob(".*tmp"))


def test_cli_rejects_too_few_poses(tmp_path):
    with pytest.raises(SystemExit, match="--poses must be >= 7"):
        main(["--poses", "5", "--out", str(tmp_path / "p.csv")])


def test_write_refuses_existing_sidecar(tmp_path):
    out = tmp_path / "p.csv"
    out.with_suffix(".json").write_text("{}")
    with pytest.raises(FileExistsError, match="p.json exists"):
        write_command_file(out, np.zeros((1, 6)), np.zeros((1, 6)), {})
    assert not out.exists()


@pytest.mark.parametrize("poses, lengths, match", [
    (np.zeros(6), np.zeros(6), r"poses must have shape \(N, 6\), got \(6,\)"),
    (np.zeros((2, 6)), np.zeros((3, 6)), r"lengths must have shape \(2, 6\), got \(3, 6\)"),
])
def test_write_validation(tmp_path, poses, lengths, match):
    with pytest.raises(ValueError, match=match):
        write_command_file(tmp_path / "p.csv", poses, lengths, {})


def _csv(tmp_path, text):
    p = tmp_path / "cmd.csv"
    p.write_text(text)
    return p


HEADER = ",".join(COMMAND_COLUMNS)


@pytest.mark.parametrize("text, match", [
    ("", r"cmd.csv: empty command file"),
    ("x,y\n1,2\n", r"cmd.csv: line 1: header must be x_mm"),
    (HEADER + "\n" + ",".join(["1"] * 11) + "\n", r"cmd.csv: line 2: expected 12 columns, got 11"),
    (HEADER + "\n" + ",".join(["1"] * 12) + "\n" + ",".join(["1"] * 4 + ["abc"] + ["1"] * 7) + "\n",
     r"cmd.csv: line 3, column beta_rad: not a number: 'abc'"),
    (HEADER + "\n" + ",".join(["1"] * 7 + ["nan"] + ["1"] * 4) + "\n", r"cmd.csv: line 2, column l2_mm: not finite"),
    (HEADER + "\n", r"cmd.csv: no data rows"),
])
def test_read_command_file_validation(tmp_path, text, match):
    with pytest.raises(ValueError, match=match):
        read_command_file(_csv(tmp_path, text))


def test_read_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="command file .*nope.csv not found"):
        read_command_file(tmp_path / "nope.csv")


def test_round_trip_full_precision(tmp_path):
    rng = np.random.default_rng(0)
    poses, lengths = rng.standard_normal((5, 6)), rng.standard_normal((5, 6))
    write_command_file(tmp_path / "c.csv", poses, lengths, {"k": 1})
    p, l = read_command_file(tmp_path / "c.csv")
    np.testing.assert_array_equal(p, poses)
    np.testing.assert_array_equal(l, lengths)


def test_optimal_poses_validation():
    with pytest.raises(TypeError, match="geometry must be a HexapodGeometry"):
        optimal_poses(NOMINAL, 10)
    with pytest.raises(ValueError, match="workspace must be 'full' or 'paper'"):
        optimal_poses(paper_geometry(), 10, workspace="moon")


def test_cli_e_optimal_paper_workspace(tmp_path):
    out = tmp_path / "e.csv"
    assert main(["--poses", "8", "--criterion", "e", "--workspace", "paper", "--candidates", "200",
                 "--out", str(out)]) == 0
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["criterion"] == "e" and side["workspace"]["name"] == "paper"
    poses, _ = read_command_file(out)
    assert feasibility(NOMINAL, poses, paper_workspace())["feasible"].all()


def test_observability_markdown_and_type_check():
    import rerun as rr

    from calib import paper
    from calib.noise import SensorNoise
    from calib.observability import analyze_observability
    from pipeline.obs_log import log_observability, observability_markdown

    a = analyze_observability(NOMINAL, paper.TABLE4_NOMINAL_POSES, SensorNoise(1e-3, 1e-6, "normal"))
    md = observability_markdown(a, title="Paper poses")
    assert md.startswith("# Paper poses") and "| dZP6 |" in md and "O4 (noise amplification)" in md
    assert a.weakest_combinations(1)[0]["combination"] in md
    with pytest.raises(TypeError, match="analysis must be an ObservabilityAnalysis, got dict"):
        log_observability(rr.RecordingStream("t"), {}, "x")
