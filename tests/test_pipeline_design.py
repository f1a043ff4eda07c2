import json
import re

import numpy as np
import pytest

import calib.robots
from calib import paper
from calib.design import design_poses, feasibility, minimum_poses, robot_workspace
from calib.noise import SensorNoise
from calib.observability import analyze_observability
from calib.robots import default_robot, reference_poses, robot_from_description
from pipeline.workflows.design import DEFAULT_NOISE, design_search, optimal_poses, start_seed
from pipeline.formats import command_columns, command_csv, read_command_file, write_command_file
from pipeline.design import main

ROBOTS = sorted(calib.robots.ROBOTS)
HEXAPOD = default_robot("hexapod")
DELTA = default_robot("delta")


@pytest.fixture(autouse=True)
def _home(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))  # rerun writes analytics under HOME


def _entities(path):
    from rerun.chunk import RrdReader

    return {str(c.entity_path): c for c in RrdReader(path).stream().to_chunks()}


def _column(chunk, prefix):
    batch = chunk.to_record_batch()
    col = [n for n in batch.schema.names if n.startswith(prefix)][0]
    return batch.column(col).to_pylist()[0]


def bar_values(chunk):
    """The values of a static BarChart chunk (a tensor: shape + buffer)."""
    tensor = _column(chunk, "BarChart:values")[0]
    return np.asarray(tensor["buffer"], dtype=float).reshape(tensor["shape"])


def test_command_columns_come_from_the_robot():
    assert ",".join(command_columns(HEXAPOD)) == \
        "x_mm,y_mm,z_mm,alpha_rad,beta_rad,gamma_rad,l1_mm,l2_mm,l3_mm,l4_mm,l5_mm,l6_mm"
    assert ",".join(command_columns(DELTA)) == "x_mm,y_mm,z_mm,q1_rad,q2_rad,q3_rad"


@pytest.mark.parametrize("name", ROBOTS)
def test_cli_writes_command_file_sidecar_summary_and_rrd(tmp_path, name):
    robot = default_robot(name)
    out, summary, rrd = tmp_path / "poses.csv", tmp_path / "summary.json", tmp_path / "design.rrd"
    n = max(8, minimum_poses(robot))
    argv = ["--robot", name, "--poses", str(n), "--seed", "3", "--candidates", "300", "--out", str(out),
            "--summary-json", str(summary), "--rrd", str(rrd)]
    assert main(argv) == 0
    assert out.read_text().splitlines()[0] == ",".join(command_columns(robot))
    poses, joints = read_command_file(out)  # the robot is found from the header
    np.testing.assert_array_equal((poses, joints), read_command_file(out, robot))
    assert poses.shape == (n, robot.pose_dim) and joints.shape == (n, robot.n_chains)
    np.testing.assert_allclose(joints, robot.inverse_kinematics(robot.table.nominal, poses), rtol=0, atol=1e-12)
    assert feasibility(robot, robot.table.nominal, poses, robot_workspace(robot, "full"))["feasible"].all()
    np.testing.assert_array_equal(poses, optimal_poses(robot, n, "d", "full", 3, n_candidates=300))
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["robot"] == name and side["criterion"] == "d" and side["seed"] == 3
    assert side["workspace"]["name"] == "full" and side["columns"] == list(command_columns(robot))
    np.testing.assert_array_equal(robot_from_description(name, side["robot_description"]).table.nominal,
                                  robot.table.nominal)
    s = json.loads(summary.read_text())
    n_free = len(robot.free_default)
    assert s["robot"] == name
    assert s["observability"]["rank"] == n_free and len(s["observability"]["singular_values"]) == n_free
    u = s["predicted_pose_uncertainty"]
    assert 0 < u["position_rms_um"]["mean"] <= u["position_rms_um"]["max"]
    assert ("orientation_rms_urad" in u) == bool(robot.angle_pose_mask.any())
    has_reference = reference_poses(robot) is not None
    assert ("crb_rms_gain_vs_reference_poses" in s) == has_reference
    if has_reference:
        assert s["crb_rms_gain_vs_reference_poses"] > 1.0
    ents = _entities(rrd)
    for e in ("/design/observability/singular_values", "/design/observability/crb_std_mm",
              "/design/observability/report", "/design/poses", "/design/pose_uncertainty"):
        assert e in ents, e
    assert ("/reference_poses/observability/singular_values" in ents) == has_reference
    bars = ents["/design/observability/crb_std_mm"]
    assert _column(bars, "parameter_names") == list(robot.free_default)
    np.testing.assert_allclose(bar_values(bars), [s["observability"]["crb_std_mm"][n] for n in robot.free_default])


def test_cli_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "poses.csv"
    argv = ["--poses", "7", "--candidates", "100", "--out", str(out), "--workspace", "default"]
    assert main(argv) == 0
    before = out.read_text()
    capsys.readouterr()
    assert main(argv + ["--seed", "1"]) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err
    assert out.read_text() == before
    assert main(argv + ["--seed", "1", "--overwrite"]) == 0
    assert out.read_text() != before
    poses, _ = read_command_file(out)
    assert feasibility(HEXAPOD, HEXAPOD.table.nominal, poses, robot_workspace(HEXAPOD, "default"))["feasible"].all()
    assert not list(tmp_path.glob(".*tmp"))


@pytest.mark.parametrize("argv, match", [
    (["--poses", "5"], "--poses must be >= 7"),
    (["--poses", "6", "--robot", "delta"], r"--poses must be >= 7 \(21 parameters, 3 equations per pose\)"),
    (["--poses", "8", "--robot", "moon"], "--robot: unknown robot 'moon'; registered robots are"),
    (["--poses", "8", "--candidates", "7"], "--candidates must be >= --poses"),
    (["--poses", "8", "--starts", "0"], "--starts: expected an integer >= 1, got 0"),
    (["--poses", "8", "--starts", "2", "--workers", "0"], "--workers: expected an integer >= 1, got 0"),
    (["--poses", "8", "--geometry", "missing.json"], "--geometry missing.json: cannot read a hexapod description"),
])
def test_cli_rejects_bad_arguments(tmp_path, argv, match, capsys):
    assert main(argv + ["--out", str(tmp_path / "p.csv")]) == 2
    err = capsys.readouterr().err
    assert re.search(match, err) and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_cli_geometry_file_gives_another_machine(tmp_path):
    desc = DELTA.description()
    desc["parameters"] = {k: v * (1.02 if k.startswith("Lb") else 1.0) for k, v in desc["parameters"].items()}
    geometry = tmp_path / "delta.json"
    geometry.write_text(json.dumps(desc))
    out = tmp_path / "p.csv"
    assert main(["--robot", "delta", "--poses", "7", "--candidates", "100", "--geometry", str(geometry),
                 "--out", str(out)]) == 0
    robot = robot_from_description("delta", desc)
    poses, joints = read_command_file(out, robot)
    np.testing.assert_allclose(joints, robot.inverse_kinematics(robot.table.nominal, poses), atol=1e-12)
    assert not np.allclose(joints, DELTA.inverse_kinematics(DELTA.table.nominal, poses), atol=1e-3)


def test_write_refuses_existing_sidecar(tmp_path):
    out = tmp_path / "p.csv"
    out.with_suffix(".json").write_text("{}")
    with pytest.raises(FileExistsError, match="p.json exists"):
        write_command_file(out, HEXAPOD, np.zeros((1, 6)), np.zeros((1, 6)), {})
    assert not out.exists()


@pytest.mark.parametrize("robot, poses, joints, match", [
    (HEXAPOD, np.zeros(6), np.zeros(6), r"poses must have shape \(N, 6\), got \(6,\)"),
    (HEXAPOD, np.zeros((2, 6)), np.zeros((3, 6)), r"joints must have shape \(2, 6\), got \(3, 6\)"),
    (DELTA, np.zeros((2, 6)), np.zeros((2, 3)), r"poses must have shape \(N, 3\), got \(2, 6\)"),
])
def test_write_validation(tmp_path, robot, poses, joints, match):
    with pytest.raises(ValueError, match=match):
        write_command_file(tmp_path / "p.csv", robot, poses, joints, {})


def _csv(tmp_path, text):
    p = tmp_path / "cmd.csv"
    p.write_text(text)
    return p


HEADER = ",".join(command_columns(HEXAPOD))


@pytest.mark.parametrize("text, robot, match", [
    ("", None, r"cmd.csv: empty command file"),
    ("x,y\n1,2\n", None, r"cmd.csv: line 1: header x,y is no registered robot's \(expected delta: x_mm"),
    ("x,y\n1,2\n", HEXAPOD, r"cmd.csv: line 1: header must be x_mm,.*,l6_mm \(the hexapod's\), got x,y"),
    (HEADER + "\n" + ",".join(["1"] * 12) + "\n", DELTA, r"header must be x_mm,y_mm,z_mm,q1_rad,q2_rad,q3_rad"),
    (HEADER + "\n" + ",".join(["1"] * 11) + "\n", None, r"cmd.csv: line 2: expected 12 columns, got 11"),
    (HEADER + "\n" + ",".join(["1"] * 12) + "\n" + ",".join(["1"] * 4 + ["abc"] + ["1"] * 7) + "\n", None,
     r"cmd.csv: line 3, column beta_rad: 'abc' is not a number"),
    (HEADER + "\n" + ",".join(["1"] * 7 + ["nan"] + ["1"] * 4) + "\n", None,
     r"cmd.csv: line 2, column l2_mm: 'nan' is not finite"),
    ("x_mm,y_mm,z_mm,q1_rad,q2_rad,q3_rad\n1,2,3,4,inf,6\n", None, r"line 2, column q2_rad: 'inf' is not finite"),
    (HEADER + "\n", None, r"cmd.csv: no data rows"),
])
def test_read_command_file_validation(tmp_path, text, robot, match):
    with pytest.raises(ValueError, match=match):
        read_command_file(_csv(tmp_path, text), robot)


def test_read_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="command file .*nope.csv not found"):
        read_command_file(tmp_path / "nope.csv")


@pytest.mark.parametrize("name", ROBOTS)
def test_round_trip_full_precision(tmp_path, name):
    robot = default_robot(name)
    rng = np.random.default_rng(0)
    poses, joints = rng.standard_normal((5, robot.pose_dim)), rng.standard_normal((5, robot.n_chains))
    write_command_file(tmp_path / "c.csv", robot, poses, joints, {"k": 1})
    p, q = read_command_file(tmp_path / "c.csv")
    np.testing.assert_array_equal(p, poses)
    np.testing.assert_array_equal(q, joints)
    assert json.loads((tmp_path / "c.json").read_text()) == {"robot": name, "k": 1}


#: The sidecar of a single search, as it always was (no record of starts).
SINGLE_SEARCH_KEYS = {"robot", "kind", "columns", "units", "robot_description", "criterion", "workspace", "noise",
                      "seed", "n_candidates", "log_det_fisher", "lambda_min_fisher", "observability"}


def test_one_start_writes_what_the_single_search_always_did(tmp_path):
    nominal = HEXAPOD.table.nominal
    argv = ["--poses", "8", "--seed", "3", "--candidates", "300"]
    assert main(argv + ["--out", str(tmp_path / "a.csv")]) == 0
    assert main(argv + ["--starts", "1", "--workers", "2", "--out", str(tmp_path / "b.csv")]) == 0
    single = design_poses(HEXAPOD, nominal, 8, robot_workspace(HEXAPOD, "full"), DEFAULT_NOISE, seed=3,
                          n_candidates=300)
    expected = command_csv(HEXAPOD, single.poses, HEXAPOD.inverse_kinematics(nominal, single.poses))
    for name in ("a", "b"):  # --starts 1 (the default) is the single search, never a cluster
        assert (tmp_path / f"{name}.csv").read_text() == expected
    side = json.loads((tmp_path / "a.json").read_text())
    assert set(side) == SINGLE_SEARCH_KEYS and side["log_det_fisher"] == single.log_det
    assert (tmp_path / "b.json").read_text() == (tmp_path / "a.json").read_text()


@pytest.mark.slow
def test_starts_give_the_same_files_on_one_and_two_workers(tmp_path, dask_two_workers, capsys):
    argv = ["--poses", "8", "--seed", "3", "--candidates", "300", "--starts", "4"]
    a, b = tmp_path / "one.csv", tmp_path / "two.csv"
    assert main(argv + ["--workers", "1", "--out", str(a), "--summary-json", str(tmp_path / "one.summary")]) == 0
    # Two workers: the tests' local cluster, by its address (as --scheduler gives it).
    assert main(argv + ["--scheduler", dask_two_workers.scheduler.address, "--out", str(b),
                        "--summary-json", str(tmp_path / "two.summary")]) == 0
    out, err = capsys.readouterr()
    assert "design search: 4/4 starts" in err  # Dask's progress of the starts, on stderr
    # The results on stdout, one search's after the other's: the best start, then what was written.
    lines = out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["best of 4 starts", f"wrote {a} and {a.with_suffix('.json')}"] + \
        ["best of 4 starts", f"wrote {b} and {b.with_suffix('.json')}"] and "best of" not in err
    assert a.read_bytes() == b.read_bytes()
    assert a.with_suffix(".json").read_bytes() == b.with_suffix(".json").read_bytes()
    one, two = (json.loads((tmp_path / f"{k}.summary").read_text()) for k in ("one", "two"))
    assert one.pop("out") == str(a) and two.pop("out") == str(b) and one == two
    # Each start is the single search on its own draw; the best of them is kept.
    ws = robot_workspace(HEXAPOD, "full")
    each = [design_poses(HEXAPOD, HEXAPOD.table.nominal, 8, ws, DEFAULT_NOISE, seed=start_seed(3, k),
                         n_candidates=300) for k in range(4)]
    starts = json.loads(a.with_suffix(".json").read_text())["starts"]
    assert starts["count"] == 4 and starts["criterion"] == "log_det_fisher"
    assert starts["values"] == [r.log_det for r in each]
    assert len(set(starts["values"])) == 4  # independent draws
    best = max(range(4), key=lambda k: (each[k].log_det, -k))
    assert starts["best"] == best and all(each[best].log_det >= r.log_det for r in each)
    np.testing.assert_array_equal(read_command_file(a)[0], each[best].poses)
    assert json.loads(a.with_suffix(".json").read_text())["log_det_fisher"] == each[best].log_det
    assert json.loads((tmp_path / "one.summary").read_text())["starts"] == starts


def test_e_optimal_best_of_starts():
    ws = robot_workspace(DELTA, "full")
    search = design_search(DELTA, DELTA.table.nominal, 7, ws, DEFAULT_NOISE, criterion="e", seed=5,
                           n_candidates=200, starts=3, workers=1)
    assert search.values == [r.lambda_min for r in search.results]
    assert all(search.design.lambda_min >= v for v in search.values)
    np.testing.assert_array_equal(search.results[0].poses, design_poses(
        DELTA, DELTA.table.nominal, 7, ws, DEFAULT_NOISE, criterion="e", seed=5, n_candidates=200).poses)
    np.testing.assert_array_equal(optimal_poses(DELTA, 7, "e", seed=5, n_candidates=200, starts=3, workers=1),
                                  search.design.poses)
    with pytest.raises(ValueError, match="starts must be an integer >= 1"):
        design_search(DELTA, DELTA.table.nominal, 7, ws, DEFAULT_NOISE, starts=0)


def test_optimal_poses_validation():
    with pytest.raises(TypeError, match="robot must be a calib.robot.Robot, got str"):
        optimal_poses("hexapod", 10)
    with pytest.raises(ValueError, match="workspace must be one of full, default, got 'moon'"):
        optimal_poses(HEXAPOD, 10, workspace="moon")


@pytest.mark.parametrize("name", ROBOTS)
def test_cli_e_optimal_default_workspace(tmp_path, name):
    robot = default_robot(name)
    out = tmp_path / "e.csv"
    n = max(8, minimum_poses(robot))
    assert main(["--robot", name, "--poses", str(n), "--criterion", "e", "--workspace", "default",
                 "--candidates", "200", "--out", str(out)]) == 0
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["criterion"] == "e" and side["workspace"]["name"] == "default"
    poses, _ = read_command_file(out, robot)
    assert feasibility(robot, robot.table.nominal, poses, robot_workspace(robot, "default"))["feasible"].all()


def test_observability_markdown_and_type_check():
    import rerun as rr

    from pipeline.views import log_observability, observability_markdown

    a = analyze_observability(HEXAPOD, HEXAPOD.table.nominal, paper.TABLE4_NOMINAL_POSES,
                              SensorNoise(1e-3, 1e-6, "normal"))
    md = observability_markdown(a, title="Paper poses")
    assert md.startswith("# Paper poses") and "| P6.z |" in md and "O4 (noise amplification)" in md
    assert a.weakest_combinations(1)[0]["combination"] in md and "Not identifiable" not in md
    with pytest.raises(TypeError, match="analysis must be an ObservabilityAnalysis, got dict"):
        log_observability(rr.RecordingStream("t"), {}, "x")


def test_observability_markdown_names_the_delta_null_directions():
    from pipeline.views import observability_markdown

    poses = optimal_poses(DELTA, 10, n_candidates=100)
    a = analyze_observability(DELTA, DELTA.table.nominal, poses, SensorNoise(1e-3, 0.0, "normal"),
                              free=DELTA.table.names)
    md = observability_markdown(a)
    assert "## Not identifiable" in md and "| 2 | 1 Lay2 + 0.00385 alpha2 |" in md
    assert "| rank | 21 / 24 |" in md and "| alpha1 |" in md


def _recording_sidecar(name, folder):
    """The sidecar of a recording of ``name`` whose nominal geometry is another machine's (the
    base joints' x and y, or the towers' radii, 1.02 times the default's), and that machine."""
    from pipeline.formats import Recording, read_sidecar_geometry, write_recording

    robot = default_robot(name)
    desc = robot.description()
    if "base_joints_mm" in desc:
        desc["base_joints_mm"] = [[1.02 * b[0], 1.02 * b[1], b[2]] for b in desc["base_joints_mm"]]
    else:  # the shoulders' or motors' x and y; the linear Delta's towers' radii
        prefix = {"delta": "D", "rus": "M", "linear_delta": "radius"}[name]
        desc["parameters"] = {k: v * (1.02 if k.startswith(prefix) and (k[-2:] in (".x", ".y") or prefix == "radius")
                                      else 1.0) for k, v in desc["parameters"].items()}
    other = robot_from_description(name, desc)
    poses = reference_poses(other)
    poses = np.repeat(other.home_pose[None], 2, axis=0) if poses is None else poses[:2]
    rec = Recording(robot=other, noise=SensorNoise(1e-3), t_s=np.arange(2.0),
                    joints=other.inverse_kinematics(other.table.nominal, poses), measured=poses,
                    sets=np.array(["calibration"] * 2), meta={})
    _, side = write_recording(folder / "rec.csv", rec)
    return side, read_sidecar_geometry(side)


@pytest.mark.parametrize("name", ROBOTS)
def test_a_recordings_sidecar_as_geometry_is_read_and_said(name, tmp_path, capsys):
    """``--geometry REC.json``, a recording's sidecar instead of a description: its field
    'nominal_geometry' is read, as the recording reader reads it, and the command says so (before:
    "cannot read a hexapod description: 'base_joints_mm'"); the commands are that machine's."""
    side, machine = _recording_sidecar(name, tmp_path)
    out = tmp_path / "p.csv"
    summary = tmp_path / "s.json"
    assert main(["--robot", name, "--poses", str(minimum_poses(machine)), "--candidates", "100", "--geometry",
                 str(side), "--out", str(out), "--summary-json", str(summary)]) == 0
    err = capsys.readouterr().err
    note = f"--geometry {side} is a recording's sidecar: read the {name} its field 'nominal_geometry' describes"
    assert note in err and json.loads(summary.read_text())["geometry_note"] == note
    poses, joints = read_command_file(out, machine)
    np.testing.assert_allclose(joints, machine.inverse_kinematics(machine.table.nominal, poses), atol=1e-9)
    default = default_robot(name)
    assert not np.allclose(joints, default.inverse_kinematics(default.table.nominal, poses), atol=1e-3)


@pytest.mark.parametrize("name", ROBOTS)
def test_another_robots_sidecar_as_geometry_names_the_robot(name, tmp_path, capsys):
    side, _ = _recording_sidecar(name, tmp_path)
    other = "delta" if name != "delta" else "hexapod"
    out = tmp_path / "p.csv"
    assert main(["--robot", other, "--poses", "12", "--geometry", str(side), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.strip() == (f"error: --geometry {side}: the sidecar of a {name} recording, and --robot is {other}: "
                           f"give --robot {name}"), err
    assert not out.exists()


def test_a_description_lacking_a_key_names_it(tmp_path, capsys):
    geometry = tmp_path / "g.json"
    geometry.write_text(json.dumps({"robot": "hexapod"}))
    assert main(["--poses", "8", "--geometry", str(geometry), "--out", str(tmp_path / "p.csv")]) == 2
    err = capsys.readouterr().err
    assert err.strip().startswith(f"error: --geometry {geometry}: not a hexapod description (no key "), err
