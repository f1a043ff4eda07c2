"""Compensated commands (calib.compensation), the effect records and the calibration file
(pipeline.formats.calibration_file), and python -m pipeline.compensate: the commands invert the
fitted model exactly, and on the MuJoCo machines that made the recordings they land closer."""

import json

import numpy as np
import pytest

from calib.compensation import COMPENSATION_TOLERANCE, compensated_commands, effect_displacement
from calib.effects import EFFECTS, EffectData, effects_for, per_chain_form
from calib.effects.records import EffectRecord, FittedEffect
from calib.robots import ROBOTS, default_robot
from pipeline.compensate import main as compensate_main
from pipeline.formats import CALIBRATION_VERSION, read_calibration, read_command_file
from pipeline.simulation import (DISCOVERY_NOISE, command_scenario_machine, effect_recording, heldout_targets,
                                 law_recording, machine_context)
from pipeline.workflows.compensate import proof_in_the_testbed

#: Effects whose model the commands invert (the others say why not).
COMPENSABLE = [n for n, e in EFFECTS.items() if n != "none" and not e.not_compensable]


def drawn_effects(robot, seed=0, names=None, magnitude_mm=0.01):
    """Every applicable effect (or ``names``), in its per-chain form where it has one, drawn by its
    own scenario at ``magnitude_mm`` on an effect recording's commands: ``(effects, data)``."""
    rec = effect_recording("none", seed, robot=robot, n_poses=40)
    data = EffectData(robot, robot.table.nominal, rec.joints, rec.measured, rec.t_s, DISCOVERY_NOISE)
    rng = np.random.default_rng(seed)
    out = []
    for name in names or effects_for(robot):
        eff = EFFECTS[name]
        if name == "none":
            continue
        form = per_chain_form(eff) or eff
        sc = form.scenario(robot, robot.table.nominal, data, magnitude_mm, rng, machine_context(robot))
        out.append(FittedEffect(form, np.asarray(sc.coefficients, float), np.full(len(sc.coefficients), 1e-6), sc.extra))
    return out, data


@pytest.mark.parametrize("robot_name", sorted(ROBOTS))
def test_records_rebuild_the_same_effect(robot_name):
    """Each effect (shared and per-chain form) through its JSON record: the same coefficients and
    the same joint regressors, bit for bit."""
    robot = default_robot(robot_name)
    effects, data = drawn_effects(robot)
    shared = [FittedEffect(EFFECTS[fe.name], fe.coefficients[:len(EFFECTS[fe.name].coefficients(robot))],
                           fe.std[:len(EFFECTS[fe.name].coefficients(robot))], fe.extra) for fe in effects]
    for fe in effects + shared:
        back = EffectRecord.from_dict(json.loads(json.dumps(EffectRecord.from_fitted(fe, robot).to_dict()))).fitted(robot)
        assert back.effect.granularity == fe.effect.granularity and back.name == fe.name
        np.testing.assert_array_equal(back.coefficients, fe.coefficients)
        np.testing.assert_array_equal(back.effect.joint_regressors(robot, data.theta, data, back.extra),
                                      fe.effect.joint_regressors(robot, data.theta, data, fe.extra))


@pytest.mark.parametrize("robot_name", sorted(ROBOTS))
def test_commands_put_the_modelled_joints_where_the_geometry_needs_them(robot_name):
    """Every compensable effect of the robot at once (per joint, 10 um each): the joints the model
    says the commands reach (commands + the effects' displacement at those commands, the history
    they make) are the identified geometry's inverse kinematics of the targets, to the fixed
    point's tolerance (a relative step of 1e-12 of the travel; the map contracts by the effects'
    size, about 1e-4, so the error left is below that step)."""
    robot = default_robot(robot_name)
    effects, data = drawn_effects(robot, names=[n for n in effects_for(robot) if n in COMPENSABLE])
    theta = robot.table.nominal
    c = compensated_commands(robot, theta, data.measured, effects, t_s=data.t_s)
    assert c.converged and set(c.compensated) == {fe.name for fe in effects} and not c.left_out
    reached = c.commands + effect_displacement(robot, theta, effects, c.commands, data.measured, data.t_s)
    travel = np.max(np.ptp(robot.joint_limits(), axis=1))
    assert np.max(np.abs(reached - c.geometric)) <= COMPENSATION_TOLERANCE * travel
    assert np.max(np.abs(c.commands - c.geometric)) > 1e3 * COMPENSATION_TOLERANCE * travel  # it did something


def test_what_cannot_be_compensated_is_named_with_why():
    robot = default_robot("hexapod")
    effects, data = drawn_effects(robot, names=["instrument_drift", "lost_count", "thermal_drift", "joint_friction"])
    c = compensated_commands(robot, robot.table.nominal, data.measured, effects)  # no t_s
    assert c.compensated == ("joint_friction",)
    assert "instrument" in c.left_out["instrument_drift"] and "re-home" in c.left_out["lost_count"]
    assert "t_s" in c.left_out["thermal_drift"]


@pytest.mark.parametrize("robot_name", sorted(ROBOTS))
def test_the_machine_lands_closer_with_the_physics_compensated(robot_name):
    """Each robot's MuJoCo machine with its hidden geometric errors and a dead band of its own in
    every joint (3-10 um): recorded, discovered, then commanded on 50 held-out targets. With the
    physics compensated the mean position error is at most 1.5 times the noise floor and at most
    half the geometry-only error (measured here: 0.35-0.45 um against 11-15 um)."""
    rec = effect_recording("joint_friction", 3, robot=robot_name, granularity="per_chain")
    e = proof_in_the_testbed(rec, 50, 1003)
    assert e["summary"]["effects"] == ["joint_friction"] and e["compensation"].converged
    assert e["compensation"].compensated == ("joint_friction",)
    assert e["physics"] <= 1.5 * e["floor"] and e["physics"] <= 0.5 * e["geometry"] < e["nominal"], e


def test_a_proposed_law_is_compensated_through_the_command_line(tmp_path, capsys):
    """A law outside the library (each leg short of its target by a fraction of its last move,
    its own constant per leg): pipeline.discover --real proposes it and stores it in the
    calibration file; pipeline.compensate inverts it from the command sequence; the machine that
    made the recording, commanded on 50 held-out targets, lands within 1.5 times the noise floor
    and within half the error of the commands from pipeline.run --real's calibration file (the
    geometry alone)."""
    from pipeline.discover import main as discover_main
    from pipeline.formats import write_recording

    rec = law_recording("settle lag", 2, robot="hexapod")
    write_recording(tmp_path / "lag.csv", rec)
    assert discover_main(["--real", str(tmp_path / "lag.csv"), "--no-resim", "--out", str(tmp_path)]) == 0
    cal_path = tmp_path / "lag_discover.calibration.json"
    cal = read_calibration(cal_path, "hexapod")
    law = [e for e in cal.effects if e.law is not None]
    assert len(law) == 1 and [t.family.key for t in law[0].law.terms] == ["last move"]
    targets, t_s = heldout_targets(rec, 50, 1002)
    names = ["x_mm", "y_mm", "z_mm", "alpha_rad", "beta_rad", "gamma_rad"]
    (tmp_path / "targets.csv").write_text(",".join(names) + "\n" + "\n".join(",".join(repr(float(v)) for v in p)
                                                                            for p in targets) + "\n")
    from pipeline.run import main as run_main

    assert run_main(["--real", str(tmp_path / "lag.csv"), "--out", str(tmp_path), "--name", "run", "--quiet"]) == 0
    errors = {}
    for path, key in ((cal_path, "physics"), (tmp_path / "run.calibration.json", "geometry")):
        out = tmp_path / f"{key}.csv"
        assert compensate_main(["--calibration", str(path), "--targets", str(tmp_path / "targets.csv"),
                                "--out", str(out)]) == 0
        poses, commands = read_command_file(out, rec.robot)
        np.testing.assert_array_equal(poses, targets)
        reached = command_scenario_machine(rec, commands, t_s)
        errors[key] = float(np.mean(np.linalg.norm((reached - targets)[:, :3], axis=1)))
    side = json.loads((tmp_path / "physics.json").read_text())
    assert "proposed_law" in side["compensated"]
    floor = float(cal.noise.pose_std(("mm",))[0])  # the declared position noise, 1 um
    assert errors["physics"] <= 1.5 * floor and errors["physics"] <= 0.5 * errors["geometry"], errors
    assert "physics compensated:" in capsys.readouterr().out


# ----------------------------------------------------------------------------- hostile input


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """A default hexapod run's calibration file and a valid target file."""
    from pipeline.run import main as run_main

    folder = tmp_path_factory.mktemp("calibrated")
    assert run_main(["--out", str(folder), "--name", "r", "--quiet"]) == 0
    targets = folder / "targets.csv"
    targets.write_text("x_mm,y_mm,z_mm,alpha_rad,beta_rad,gamma_rad,t_s\n0,0,205,0,0,0,1\n2,-1,203,0.01,0,0.02,2\n")
    return folder


def _edited(folder, tmp_path, edit):
    d = json.loads((folder / "r.calibration.json").read_text())
    edit(d)
    path = tmp_path / "c.calibration.json"
    path.write_text(json.dumps(d))
    return path


BAD_FILES = {
    "another version": (lambda d: d.update(version=CALIBRATION_VERSION + 1), "key 'version' is 2"),
    "another format": (lambda d: d.update(format="something"), "key 'format'"),
    "a key missing": (lambda d: d.pop("validity"), "key 'validity' missing"),
    "another robot's parameters": (lambda d: d.update(robot="delta"), "nominal_geometry"),
    "an unknown effect": (lambda d: d["effects"].append({"name": "magic", "granularity": "shared", "coefficients": {},
                                                        "std": {}, "units": {}, "searched": None}),
                          "effects[0].name: 'magic'"),
    "a coefficient renamed": (lambda d: d["effects"].append({"name": "joint_friction", "granularity": "shared",
                                                             "coefficients": {"friction": 1e-3}, "std": {"friction": 0},
                                                             "units": {"friction": "mm"}, "searched": None}),
                              "effects[0].coefficients: expected the coefficients ['dead_band']"),
    "a parameter not a number": (lambda d: d["parameters"]["by_name"]["B1.x"].update(identified="x"),
                                 "parameters.by_name.B1.x"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_a_bad_calibration_file_is_refused_in_one_line(case, calibrated, tmp_path, capsys):
    edit, words = BAD_FILES[case]
    path = _edited(calibrated, tmp_path, edit)
    out = tmp_path / "cmd.csv"
    assert compensate_main(["--calibration", str(path), "--targets", str(calibrated / "targets.csv"),
                            "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and str(path) in err and "Traceback" not in err
    assert not out.exists()


BAD_TARGETS = {
    "a cell": ("x_mm,y_mm,z_mm,alpha_rad,beta_rad,gamma_rad\n0,0,205,0,0,0\n0,zero,205,0,0,0\n",
               "row 2 (line 3), column 'y_mm': 'zero' is not a number"),
    "a column missing": ("x_mm,y_mm,z_mm,alpha_rad,beta_rad\n0,0,205,0,0\n", "lacks column(s) gamma_rad"),
    "time backwards": ("x_mm,y_mm,z_mm,alpha_rad,beta_rad,gamma_rad,t_s\n0,0,205,0,0,0,2\n0,0,205,0,0,0,1\n",
                       "row 2 (line 3), column 't_s': time goes backwards"),
    "a joint column": ("x_mm,y_mm,z_mm,alpha_rad,beta_rad,gamma_rad,l1_mm\n0,0,205,0,0,0,1\n", "column 'l1_mm'"),
    "unreachable": ("x_mm,y_mm,z_mm,alpha_rad,beta_rad,gamma_rad\n0,0,205,0,0,0\n0,0,2050,0,0,0\n", "row 2 (line 3)"),
    "no rows": ("x_mm,y_mm,z_mm,alpha_rad,beta_rad,gamma_rad\n", "no data rows"),
}


@pytest.mark.parametrize("case", sorted(BAD_TARGETS))
def test_a_bad_target_file_is_refused_naming_row_and_column(case, calibrated, tmp_path, capsys):
    text, words = BAD_TARGETS[case]
    targets = tmp_path / "t.csv"
    targets.write_text(text)
    out = tmp_path / "cmd.csv"
    assert compensate_main(["--calibration", str(calibrated / "r.calibration.json"), "--targets", str(targets),
                            "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and str(targets) in err and "Traceback" not in err
    assert not out.exists()


def test_commands_are_not_overwritten_and_flags_are_checked(calibrated, tmp_path, capsys):
    args = ["--calibration", str(calibrated / "r.calibration.json"), "--targets", str(calibrated / "targets.csv")]
    out = tmp_path / "cmd.csv"
    assert compensate_main(args + ["--out", str(out)]) == 0
    first = out.read_text()
    side = json.loads((tmp_path / "cmd.json").read_text())
    assert side["produced_by"] == "pipeline.compensate" and side["compensated"] == [] and side["targets"] == 2
    poses, joints = read_command_file(out)  # the robot found from the header, t_s column and all
    assert poses.shape == (2, 6) and joints.shape == (2, 6) and first.splitlines()[0].endswith(",t_s")
    capsys.readouterr()
    assert compensate_main(args + ["--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err and out.read_text() == first
    for flags, words in ((["--frame", "instrument"], "has no instrument frame"), (["--session", "a"], "--session"),
                         (["--out", str(tmp_path / "c.json")], "a command file is a CSV")):
        assert compensate_main(args + (["--out", str(tmp_path / "other.csv")] if "--out" not in flags else []) + flags) == 2
        assert words in capsys.readouterr().err


def test_a_run_calibration_file_reads_back_as_the_run_found_it(calibrated):
    """The file pipeline.run wrote: the free parameters' covariance with their std on its diagonal
    (the fixed ones' std zero), the recording's hash, no effect, no frame."""
    import hashlib

    cal = read_calibration(calibrated / "r.calibration.json", "hexapod")
    s = json.loads((calibrated / "r.calibration.json").read_text())
    robot = cal.robot
    free = robot.table.indices(cal.free)
    np.testing.assert_array_equal(np.sqrt(np.diag(cal.covariance)), cal.std[free])  # the same numbers, as written
    assert np.all(cal.std[np.setdiff1d(np.arange(robot.n_parameters), free)] == 0)
    assert s["recording"]["sha256"] == hashlib.sha256((calibrated / "r.csv").read_bytes()).hexdigest()
    assert cal.effects == () and cal.frames == {} and cal.produced_by == "pipeline.run"
    with pytest.raises(ValueError, match="another robot"):
        read_calibration(calibrated / "r.calibration.json", "delta")


@pytest.mark.slow
def test_a_compliance_found_at_two_payloads_is_compensated_at_each_targets_payload():
    """A Delta recorded at two payloads (its compliance separates from its geometry only so): the
    calibration keeps the compliance with its payload terms and the payload they stand for (the
    recording's mean); commands for targets at the light and the heavy payload land within 1.5
    times the noise floor and half the geometry-alone error. Without the targets' payloads the
    compliance is named as not compensated."""
    rec = effect_recording("compliance", 3, robot="delta", payloads=2, granularity="per_chain")
    e = proof_in_the_testbed(rec, 30, 1003)
    assert e["summary"]["effects"] == ["compliance"] and e["compensation"].compensated == ("compliance",)
    assert e["physics"] <= 1.5 * e["floor"] and e["physics"] <= 0.5 * e["geometry"], e
    cal = e["calibration"]
    (record,) = cal.effects
    assert record.reference_payload_kg == np.mean(rec.extras["payload_kg"])
    assert any(name.startswith("payload_over_stiffness") for name in record.coefficient_names)
    targets = rec.measured[:5]
    c = compensated_commands(rec.robot, cal.theta, targets, cal.fitted_effects())
    assert "payload_kg" in c.left_out["compliance"] and c.compensated == ()


# ----------------------------------------------------------------------------- inputs checked on evidence


@pytest.fixture(scope="module")
def robot_runs(tmp_path_factory):
    """A default run of each robot: its calibration file, and targets inside what it saw (each
    calibration row's pose pulled halfway to the middle of the box of its poses)."""
    from pipeline.formats import read_recording
    from pipeline.run import main as run_main

    out = {}
    for name in sorted(ROBOTS):
        folder = tmp_path_factory.mktemp(name)
        assert run_main(["--robot", name, "--out", str(folder), "--name", "r", "--quiet"]) == 0
        rec = read_recording(folder / "r.csv")
        v = read_calibration(folder / "r.calibration.json").validity
        middle = (np.array(v["pose_min"]) + np.array(v["pose_max"])) / 2
        out[name] = (folder, 0.5 * (rec.measured[rec.sets == "calibration"][:6] + middle))
    return out


def _targets_file(path, robot, poses, names=None):
    from pipeline.formats import columns

    names = list(names or columns(robot)[1])
    path.write_text(",".join(names) + "\n" + "".join(",".join(repr(float(v)) for v in p) + "\n" for p in poses))
    return path


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_right_targets_of_a_right_calibration_pass_without_a_warning(name, robot_runs, tmp_path, capsys):
    folder, poses = robot_runs[name]
    targets = _targets_file(tmp_path / "t.csv", default_robot(name), poses)
    assert compensate_main(["--calibration", str(folder / "r.calibration.json"), "--targets", str(targets),
                            "--out", str(tmp_path / "c.csv")]) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_an_absurd_parameter_is_named_as_the_calibration_files(name, robot_runs, tmp_path, capsys):
    """dl1 (or the robot's first length parameter) 1000 mm off: refused naming the file and the
    parameter, not a row of the targets."""
    folder, poses = robot_runs[name]
    robot = default_robot(name)
    d = json.loads((folder / "r.calibration.json").read_text())
    k = next(n for n, u in zip(robot.table.names, robot.table.units) if u == "mm" and n in d["parameters"]["free"])
    d["parameters"]["by_name"][k]["identified"] += 1000.0
    path = tmp_path / "off.calibration.json"
    path.write_text(json.dumps(d))
    targets = _targets_file(tmp_path / "t.csv", robot, poses)
    assert compensate_main(["--calibration", str(path), "--targets", str(targets), "--out", str(tmp_path / "c.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    offset = d["parameters"]["by_name"][k]["identified"] - d["parameters"]["by_name"][k]["nominal"]
    for needle in (f"{path}: parameter {k}: identified", f"{offset:+.4g} mm from nominal", "calibration file's "
                   "parameter is implausible", "beyond"):
        assert needle in err, (needle, err)
    assert "t.csv" not in err and not (tmp_path / "c.csv").exists()


TARGET_MISTAKES = {  # case: (change of the right targets, the robots, the column named, the unit it seems to be)
    "angles in degrees": (lambda p: np.hstack([p[:, :3], np.rad2deg(p[:, 3:])]), "angles", "rad", "degrees",
                          "times pi / 180"),
    "positions in metres": (lambda p: np.hstack([p[:, :3] / 1000.0, p[:, 3:]]), "all", "mm", "metres", "times 1000"),
}


def _reaches_near_its_origin(name: str) -> bool:
    """Whether the robot reaches the pose 0.1 mm above its base frame's origin (a printer's bed
    centre): targets written in metres then lie where it reaches, and nothing refuses them."""
    from calib.robot import KinematicsError, check_joint_limits

    robot = default_robot(name)
    near = np.zeros((1, robot.pose_dim))
    near[0, 2] = 0.1
    try:
        check_joint_limits(robot, robot.inverse_kinematics(robot.table.nominal, near), "pose")
    except KinematicsError:
        return False
    return True


@pytest.mark.parametrize("case,name", [(c, n) for c in TARGET_MISTAKES for n in sorted(ROBOTS)
                                       if (TARGET_MISTAKES[c][1] == "all" or default_robot(n).angle_pose_mask.any())
                                       and not (c == "positions in metres" and _reaches_near_its_origin(n))])
def test_targets_in_the_wrong_unit_are_named_by_column_with_the_conversion(case, name, robot_runs, tmp_path, capsys):
    folder, poses = robot_runs[name]
    change, _, unit, seems, fix = TARGET_MISTAKES[case]
    robot = default_robot(name)
    wrong = change(poses)
    targets = _targets_file(tmp_path / "t.csv", robot, wrong)
    assert compensate_main(["--calibration", str(folder / "r.calibration.json"), "--targets", str(targets),
                            "--out", str(tmp_path / "c.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    mask = robot.angle_pose_mask if unit == "rad" else ~robot.angle_pose_mask
    k = int(np.argmax(np.where(mask, np.abs(wrong).max(axis=0), -np.inf)))
    column = f"{robot.pose_names[k]}_{unit}"
    for needle in (f"{targets}, column {column}: values up to {np.abs(wrong[:, k]).max():.4g} look like {seems}",
                   f"as {seems} ({fix}) every target is reachable", "unreachable as written"):
        assert needle in err, (needle, err)
    assert not (tmp_path / "c.csv").exists()


@pytest.mark.parametrize("name", [n for n in sorted(ROBOTS) if _reaches_near_its_origin(n)])
def test_targets_in_metres_the_machine_reaches_are_compensated_with_the_box_warning(name, robot_runs, tmp_path, capsys):
    """A printer's targets in metres lie just above its bed's centre, which it reaches: nothing
    refuses them on evidence, and the warning names every row outside the calibration's box."""
    folder, poses = robot_runs[name]
    wrong = np.hstack([poses[:, :3] / 1000.0, poses[:, 3:]])
    targets = _targets_file(tmp_path / "t.csv", default_robot(name), wrong)
    assert compensate_main(["--calibration", str(folder / "r.calibration.json"), "--targets", str(targets),
                            "--out", str(tmp_path / "c.csv")]) == 0
    err = capsys.readouterr().err
    rows = ", ".join(str(k) for k in range(1, len(wrong) + 1))
    assert f"row(s) {rows}: outside the box of the calibration poses" in err, err


@pytest.mark.parametrize("name,other", [(n, o) for n in sorted(ROBOTS) for o in sorted(ROBOTS) if o != n])
def test_targets_of_another_robot_are_refused_by_column(name, other, robot_runs, tmp_path, capsys):
    """A calibration of one robot given another's targets: a column of the other's (its pose or
    joint columns beyond this robot's pose columns) is refused by name, not taken as a channel."""
    from pipeline.formats import columns

    folder, poses = robot_runs[name]
    robot = default_robot(name)
    own = columns(robot)[1]
    joints, theirs = columns(default_robot(other))
    extra = [c for c in theirs if c not in own] or [joints[0]]
    targets = _targets_file(tmp_path / "t.csv", robot, np.hstack([poses, np.zeros((len(poses), len(extra)))]),
                            list(own) + extra)
    assert compensate_main(["--calibration", str(folder / "r.calibration.json"), "--targets", str(targets),
                            "--out", str(tmp_path / "c.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"column {extra[0]!r}" in err and f"the {robot.name} ({', '.join(own)})" in err, err
    assert not (tmp_path / "c.csv").exists()
