"""The Python API of a calibration (calib.calibration): ``Calibration.read`` / ``write`` (the file
round trip, other versions refused), ``cal.commands`` (the numbers ``python -m
pipeline.compensate`` writes), ``cal.predict`` (where the identified machine goes: the commands
land on their targets; a dead band checked by hand), the deliveries (the files ``python -m
pipeline.export`` writes, through the one registry of deliveries; calib without pipeline), and
docs/api.md's example run as written.

The calibrations are made here (identified errors and effects drawn by the test, not fitted by the
product): a geometry off nominal, a dead band per joint, an actuator scale per joint, a
compliance fitted at several payloads (it follows the ``payload_kg`` channel) and, where the
robot has it, a thermal drift (it follows ``t_s``)."""

import json
import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from calib.calibration import CALIBRATION_VERSION, DELIVERY_PACKAGE, Calibration, CalibrationFileError, validity_domain
from calib.compensation import COMPENSATION_TOLERANCE
from calib.effects import EFFECTS, EffectData
from calib.effects.compliance import LoadedCompliance
from calib.effects.granularity import per_chain_form
from calib.effects.records import EffectRecord, FittedEffect
from calib.noise import SensorNoise
from calib.robot import FORWARD_KINEMATICS_TOL_MM, pose_jacobian_of_joints
from calib.robots import ROBOTS, default_robot
from calib.workspace import reachable_poses

ROOT = Path(__file__).resolve().parent.parent
ROBOT_NAMES = sorted(ROBOTS)
#: The payload the compliance's weight terms stand for, kg; the targets' payloads about it.
REFERENCE_PAYLOAD_KG = 2.0


def joint_size(robot) -> float:
    """Each effect's largest joint displacement: 5 um on a prismatic joint, 5e-5 rad on a revolute
    one (a few times the noise of the recordings)."""
    return 5e-3 if robot.joint_unit == "mm" else 5e-5


def made_effects(robot, theta, rng) -> list:
    """The effects of the machine made here, each scaled to :func:`joint_size` on 40 poses."""
    poses = reachable_poses(robot, 40, rng, theta=theta)
    data = EffectData(robot, theta, robot.inverse_kinematics(theta, poses), poses, np.linspace(0.0, 100.0, 40),
                      SensorNoise(), payload_kg=REFERENCE_PAYLOAD_KG + rng.uniform(-1.0, 1.0, 40))
    forms = [per_chain_form(EFFECTS["joint_friction"]), EFFECTS["actuator_scale"], LoadedCompliance(REFERENCE_PAYLOAD_KG)]
    if EFFECTS["thermal_drift"].applies_to(robot):
        forms.append(EFFECTS["thermal_drift"])
    out = []
    for eff in forms:
        shape = rng.uniform(0.5, 1.0, len(eff.coefficients(robot)))
        X = eff.joint_regressors(robot, theta, data)
        out.append(FittedEffect(eff, shape * joint_size(robot) / np.max(np.abs(X @ shape)), np.full(shape.size, 1e-7)))
    return out


def made_calibration(robot, seed: int = 0) -> Calibration:
    """A calibration of ``robot``: every field set (frames, targets, effects, validity)."""
    rng = np.random.default_rng(seed)
    theta = robot.table.nominal.copy()
    free = robot.table.indices(robot.free_default)
    theta[free] += rng.uniform(-1.0, 1.0, free.size) * np.where(robot.table.angle_mask()[free], 5e-4, 0.05)
    fitted = made_effects(robot, theta, rng)
    poses = reachable_poses(robot, 60, rng, theta=theta)
    joints = robot.inverse_kinematics(theta, poses)
    names = tuple(robot.table.names[i] for i in free)
    a = rng.normal(size=(free.size, free.size))
    frame = np.r_[rng.normal(size=3) * 100.0, rng.normal(size=3) * 0.1]
    return Calibration(
        robot=robot, theta=theta, std=np.where(np.isin(np.arange(theta.size), free), 1e-3, 0.0), free=names,
        covariance=a @ a.T * 1e-6, frames={"s1": frame, "s2": -frame}, frames_std={"s1": np.full(6, 1e-3),
                                                                                  "s2": np.full(6, 2e-3)},
        targets=rng.normal(size=(2, 3)) * 50.0,
        effects=tuple(EffectRecord.from_fitted(fe, robot, REFERENCE_PAYLOAD_KG if isinstance(fe.effect, LoadedCompliance)
                                               else None) for fe in fitted),
        validity=validity_domain(robot, poses, joints, np.linspace(0.0, 100.0, 60), theta),
        noise=SensorNoise(1e-3, 1e-6, "normal"), recording={"name": "made.csv", "sha256": "0" * 64},
        produced_by="tests/test_calibration_api.py")


def targets_of(cal: Calibration, n: int = 30, seed: int = 7):
    """``(targets (n, D), t_s (n,), payload_kg (n,))`` inside the calibrated workspace."""
    rng = np.random.default_rng(seed)
    poses = reachable_poses(cal.robot, n, rng, theta=cal.theta)
    return poses, np.sort(rng.uniform(1.0, 99.0, n)), REFERENCE_PAYLOAD_KG + rng.uniform(-1.0, 1.0, n)


@pytest.fixture(scope="module", params=ROBOT_NAMES)
def written(request, tmp_path_factory):
    """``(path, calibration read back)`` of each robot's made calibration."""
    folder = tmp_path_factory.mktemp(request.param)
    path = made_calibration(default_robot(request.param)).write(folder / f"{request.param}.calibration.json")
    return path, Calibration.read(path)


def write_targets(path, robot, targets, t_s, payload_kg) -> Path:
    header = [f"{n}_{u}" for n, u in zip(robot.pose_names, robot.pose_units)] + ["t_s", "payload_kg"]
    rows = [",".join(repr(float(v)) for v in row) for row in np.c_[targets, t_s, payload_kg]]
    path.write_text(",".join(header) + "\n" + "\n".join(rows) + "\n")
    return path


# ----------------------------------------------------------------------------- commands and predict


def test_commands_are_the_numbers_pipeline_compensate_writes(written, tmp_path):
    """The command file's numbers (written with repr: full precision) are ``cal.commands``' bit for
    bit, for the same targets, times and payloads; every effect made is compensated."""
    from pipeline.compensate import main as compensate_main
    from pipeline.formats import read_command_file

    path, cal = written
    targets, t_s, payload = targets_of(cal)
    target_file = write_targets(tmp_path / "targets.csv", cal.robot, targets, t_s, payload)
    assert compensate_main(["--calibration", str(path), "--targets", str(target_file),
                            "--out", str(tmp_path / "commands.csv")]) == 0
    poses, written_commands = read_command_file(tmp_path / "commands.csv", cal.robot)
    np.testing.assert_array_equal(poses, targets)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing left out: no warning
        commands = cal.commands(targets, t_s=t_s, payload_kg=payload)
    assert commands.shape == (len(targets), cal.robot.n_chains)
    np.testing.assert_array_equal(commands, written_commands)
    side = json.loads((tmp_path / "commands.json").read_text())
    assert sorted(side["compensated"]) == sorted(e.name for e in cal.effects) and not side["not_compensated"]


def test_what_the_commands_leave_out_is_warned(written):
    """Without the payloads the loaded compliance is left out, and said so."""
    _, cal = written
    targets, t_s, payload = targets_of(cal, 5)
    with pytest.warns(UserWarning, match="compliance not compensated: .*'payload_kg'"):
        without = cal.commands(targets, t_s=t_s)
    assert np.max(np.abs(without - cal.commands(targets, t_s=t_s, payload_kg=payload))) > 0.01 * joint_size(cal.robot)


def test_the_commands_land_on_their_targets(written):
    """``cal.predict(cal.commands(targets))`` is ``targets``: the fixed point leaves each joint
    within COMPENSATION_TOLERANCE of the travel of its solution and the forward kinematics each
    closure within FORWARD_KINEMATICS_TOL_MM, so each pose is within the manipulator Jacobian's
    norm times those (a factor 10 for the contraction's geometric tail); the effects move the
    platform many times that (the check can fail)."""
    _, cal = written
    robot = cal.robot
    targets, t_s, payload = targets_of(cal)
    commands = cal.commands(targets, t_s=t_s, payload_kg=payload)
    reached = cal.predict(commands, t_s=t_s, payload_kg=payload)
    assert reached.shape == targets.shape
    travel = float(np.max(np.ptp(robot.joint_limits(), axis=1)))
    J = pose_jacobian_of_joints(robot, cal.theta, commands, targets)  # (N, D, C) pose per joint
    gain = np.abs(J).sum(axis=2)  # (N, D): the infinity norm of each pose coordinate's row
    bound = 10.0 * gain * (COMPENSATION_TOLERANCE * travel + FORWARD_KINEMATICS_TOL_MM)
    assert np.all(np.abs(reached - targets) <= bound), np.max(np.abs(reached - targets) / bound)
    geometric = robot.forward_kinematics(cal.theta, commands)
    position = ~robot.angle_pose_mask
    assert np.min(np.max(np.abs(geometric - targets)[:, position], axis=1)) > 1e3 * np.max(bound[:, position])


def test_predict_applies_a_dead_band_as_worked_out_here():
    """A dead band alone: the joints sit short of each command by the band, against the
    direction of the joint's last move (found here by walking the sequence from the home pose);
    the platform goes where the identified geometry puts those joints."""
    robot = default_robot("hexapod")
    cal = made_calibration(robot)
    band = np.linspace(2e-3, 4e-3, robot.n_chains)
    dead_band = FittedEffect(per_chain_form(EFFECTS["joint_friction"]), band, np.zeros(robot.n_chains))
    cal = Calibration(robot=robot, theta=cal.theta, std=cal.std, free=cal.free, covariance=cal.covariance,
                      effects=(EffectRecord.from_fitted(dead_band, robot),), validity=cal.validity)
    targets, _, _ = targets_of(cal, 12)
    joints = robot.inverse_kinematics(cal.theta, targets)
    joints[4] = joints[3]  # a command unchanged keeps the last direction
    joints[7, 2] = joints[6, 2]
    last = robot.inverse_kinematics(cal.theta, robot.home_pose[None])[0]
    direction = np.zeros(robot.n_chains)
    sitting = []
    for q in joints:
        direction = np.where(q > last, 1.0, np.where(q < last, -1.0, direction))
        sitting.append(q - band * direction)
        last = q
    want = robot.forward_kinematics(cal.theta, np.array(sitting))
    np.testing.assert_allclose(cal.predict(joints), want, rtol=0, atol=1e-9)
    # After commands already given, ending on an unchanged one: the direction carries over.
    np.testing.assert_allclose(cal.predict(joints[5:], previous=joints[:5]), want[5:], rtol=0, atol=1e-9)
    assert np.max(np.abs(robot.forward_kinematics(cal.theta, joints) - want)) > 1e-3


def test_previous_commands_carry_the_history_on(written):
    """Commands asked in two batches, the second after the first's (``previous``), are the commands
    of the whole sequence asked at once (to the fixed point's tolerance: each batch stops on its
    own largest step), and predicting in batches is predicting at once; without ``previous`` the
    second batch starts from home and differs."""
    _, cal = written
    robot = cal.robot
    targets, t_s, payload = targets_of(cal, 20)
    whole = cal.commands(targets, t_s=t_s, payload_kg=payload)
    first = cal.commands(targets[:8], t_s=t_s[:8], payload_kg=payload[:8])
    second = cal.commands(targets[8:], t_s=t_s[8:], previous=first, payload_kg=payload[8:])
    travel = float(np.max(np.ptp(robot.joint_limits(), axis=1)))
    np.testing.assert_allclose(np.vstack([first, second]), whole, rtol=0, atol=10 * COMPENSATION_TOLERANCE * travel)
    fresh = cal.commands(targets[8:], t_s=t_s[8:], payload_kg=payload[8:])
    assert np.max(np.abs(fresh[0] - second[0])) > 0.1 * joint_size(robot)  # the first move's direction differs
    at_once = cal.predict(whole, t_s=t_s, payload_kg=payload)
    batched = cal.predict(whole[8:], t_s=t_s[8:], previous=whole[:8], payload_kg=payload[8:])
    np.testing.assert_allclose(batched, at_once[8:], rtol=0, atol=1e-9)


def test_commands_refuse_arrays_of_the_wrong_shape(written):
    _, cal = written
    with pytest.raises(ValueError, match="targets"):
        cal.commands(np.zeros((3, cal.robot.pose_dim + 1)))
    with pytest.raises(ValueError, match="previous"):
        cal.commands(targets_of(cal, 2)[0], previous=np.zeros((2, cal.robot.n_chains + 1)))


# ----------------------------------------------------------------------------- the file


def test_every_field_round_trips_through_the_file(written, tmp_path):
    path, back = written
    cal = made_calibration(back.robot)
    assert back.robot.name == cal.robot.name and back.robot.description() == cal.robot.description()
    for name in ("theta", "std", "covariance", "targets"):
        np.testing.assert_array_equal(getattr(back, name), getattr(cal, name), err_msg=name)
    assert back.free == cal.free and back.frames.keys() == cal.frames.keys() == back.frames_std.keys()
    for s in cal.frames:
        np.testing.assert_array_equal(back.frames[s], cal.frames[s])
        np.testing.assert_array_equal(back.frames_std[s], cal.frames_std[s])
    assert back.effects == cal.effects and back.validity == cal.validity
    assert back.noise == cal.noise and back.recording == cal.recording and back.produced_by == cal.produced_by
    assert back.source == path and cal.source is None
    for a, b in zip(back.fitted_effects(), cal.fitted_effects()):
        assert type(a.effect) is type(b.effect) and a.effect.granularity == b.effect.granularity
        np.testing.assert_array_equal(a.coefficients, b.coefficients)
    again = back.write(tmp_path / "again.calibration.json")
    assert again.read_text() == path.read_text()  # read and written again: the same text


def test_an_existing_file_is_kept_unless_overwrite(written, tmp_path):
    _, cal = written
    target = tmp_path / "c.calibration.json"
    target.write_text("keep me")
    with pytest.raises(FileExistsError, match="exists"):
        cal.write(target)
    assert target.read_text() == "keep me"
    cal.write(target, overwrite=True)
    assert Calibration.read(target).robot.name == cal.robot.name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.calibration.json"]  # no temporary file left


@pytest.mark.parametrize("key, value, words", [
    ("version", CALIBRATION_VERSION + 1, f"key 'version' is {CALIBRATION_VERSION + 1}; this reader reads version "
                                         f"{CALIBRATION_VERSION} only"),
    ("version", "1", "key 'version' is '1'"),
    ("format", "something else", "key 'format' is 'something else'"),
])
def test_a_file_of_another_version_or_format_is_refused_by_name(written, tmp_path, key, value, words):
    path, _ = written
    d = json.loads(path.read_text())
    d[key] = value
    other = tmp_path / "other.calibration.json"
    other.write_text(json.dumps(d))
    with pytest.raises(CalibrationFileError) as info:
        Calibration.read(other)
    message = str(info.value)
    assert message.startswith(f"{other}: ") and words in message and "\n" not in message


def test_a_calibration_of_another_robot_is_refused_by_name(written):
    path, cal = written
    other = next(n for n in ROBOT_NAMES if n != cal.robot.name)
    with pytest.raises(CalibrationFileError, match=re.escape(f"{path}: key 'robot' is '{cal.robot.name}'")):
        Calibration.read(path, other)


# ----------------------------------------------------------------------------- deliveries


def export_or_refusal(run):
    """``("files", {name: bytes})`` of the folder an export wrote, or ``("refused", message)``."""
    try:
        out = run()
    except ValueError as exc:
        return "refused", str(exc)
    return "files", out


def folder_bytes(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_to_linuxcnc_writes_what_pipeline_export_writes(written, tmp_path):
    """The same files byte for byte where LinuxCNC has the robot's kinematics, the same refusal
    where the export refuses it."""
    from pipeline.workflows.export import ExportSettings, run_export

    path, cal = written

    def cli():
        run_export(ExportSettings(calibration=str(path), to="linuxcnc", out=tmp_path / "cli"))
        return folder_bytes(tmp_path / "cli")

    def api():
        cal.to_linuxcnc(tmp_path / "api")
        return folder_bytes(tmp_path / "api")

    want, got = export_or_refusal(cli), export_or_refusal(api)
    assert got == want
    if cal.robot.name == "hexapod":  # LinuxCNC's genhexkins: the export exists
        assert want[0] == "files" and len(want[1]) == 4 + cal.robot.n_chains


def test_the_command_line_export_writes_what_to_linuxcnc_writes(tmp_path, capsys):
    """``python -m pipeline.export --to linuxcnc`` (its front end, as a lab runs it) and
    ``cal.to_linuxcnc`` on the same file: the same files."""
    from pipeline.export import main as export_main

    path = made_calibration(default_robot("hexapod")).write(tmp_path / "h.calibration.json")
    assert export_main(["--calibration", str(path), "--to", "linuxcnc", "--out", str(tmp_path / "cli")]) == 0
    report = Calibration.read(path).to_linuxcnc(tmp_path / "api")
    assert report.format == "linuxcnc" and folder_bytes(tmp_path / "api") == folder_bytes(tmp_path / "cli")


def test_to_mjcf_writes_what_pipeline_export_writes(written, tmp_path):
    from pipeline.workflows.export import ExportSettings, run_export

    path, cal = written
    run_export(ExportSettings(calibration=str(path), to="mjcf", out=tmp_path / "cli.xml"))
    cal.to_mjcf(tmp_path / "api.xml")
    assert (tmp_path / "api.xml").read_bytes() == (tmp_path / "cli.xml").read_bytes()
    with pytest.raises(FileExistsError, match="exists"):
        cal.to_mjcf(tmp_path / "api.xml")


def test_a_linuxcnc_export_of_a_calibration_made_in_memory_asks_for_its_file(tmp_path):
    cal = made_calibration(default_robot("hexapod"))
    with pytest.raises(ValueError, match=r"made in memory.*cal\.write"):
        cal.to_linuxcnc(tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_delivery_not_registered_is_refused_naming_it_and_the_registered_ones(tmp_path):
    import re

    from pipeline.deliveries import DELIVERIES

    cal = made_calibration(default_robot("delta"))
    assert {"linuxcnc", "mjcf", "report"} <= set(DELIVERIES)
    installed = re.escape(", ".join(DELIVERIES))
    with pytest.raises(ValueError, match=rf"no delivery 'pdf' is registered \(installed: {installed}\)"):
        cal.deliver("pdf", tmp_path / "x.pdf")
    assert list(tmp_path.iterdir()) == []


def test_without_pipeline_a_delivery_says_so_in_one_line(tmp_path, monkeypatch):
    """calib alone (the registry's package not importable, as where pipeline is not installed):
    the commands work, a delivery is refused in one line naming what is missing."""
    cal = made_calibration(default_robot("hexapod"))
    monkeypatch.setitem(sys.modules, DELIVERY_PACKAGE, None)  # an import of it fails as a missing one does
    with pytest.raises(ValueError, match=r"written by pipeline\.deliveries, which is not installed") as refused:
        cal.to_mjcf(tmp_path / "m.xml")
    assert "\n" not in str(refused.value) and list(tmp_path.iterdir()) == []
    targets, t_s, payload = targets_of(cal, 3)
    assert cal.commands(targets, t_s=t_s, payload_kg=payload).shape == (3, cal.robot.n_chains)


@pytest.mark.slow
def test_calib_imports_nothing_of_pipeline():
    """``from calib import Calibration`` and a compensation load no pipeline module (a fresh
    interpreter)."""
    import subprocess

    code = ("import sys, numpy as np; from calib import Calibration; from calib.robots import default_robot; "
            "r = default_robot('hexapod'); "
            "c = Calibration(robot=r, theta=r.table.nominal, std=0*r.table.nominal, free=(), covariance=np.zeros((0, 0)));"
            "c.commands(r.home_pose[None]); c.predict(r.home_lengths[None]); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'pipeline'))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


# ----------------------------------------------------------------------------- docs/api.md


def test_the_example_in_docs_api_runs_as_written(tmp_path, monkeypatch):
    """docs/api.md's example, exec'd as written in a folder holding the calibration file it names
    (a hexapod's, made here): it runs, and what it prints is what it says."""
    text = (ROOT / "docs" / "api.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 2, "docs/api.md has two python examples: Calibration, then calibrate"
    named = re.search(r'Calibration\.read\("([^"]+)"\)', blocks[0]).group(1)
    monkeypatch.chdir(tmp_path)
    made_calibration(default_robot("hexapod")).write(tmp_path / named)
    namespace = {"__name__": "docs_api_example"}
    exec(compile(blocks[0], "docs/api.md", "exec"), namespace)
    cal, commands = namespace["cal"], namespace["commands"]
    assert isinstance(cal, Calibration) and commands.shape[1] == cal.robot.n_chains
    assert (tmp_path / "linuxcnc").is_dir() and any((tmp_path / "linuxcnc").iterdir())
    assert (tmp_path / "identified.xml").is_file()


def test_the_calibrate_example_in_docs_api_runs_as_written(tmp_path, monkeypatch):
    """docs/api.md's second example (calib.calibrate on arrays), exec'd as written: the verdict
    is a success, the row it spoils by 0.5 mm (500 times the noise) is the one gross row, and the
    calibration file it writes reads back with the outcome's parameters."""
    text = (ROOT / "docs" / "api.md").read_text()
    block = re.findall(r"```python\n(.*?)```", text, re.S)[1]
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "docs_api_calibrate_example"}
    exec(compile(block, "docs/api.md", "exec"), namespace)
    outcome = namespace["outcome"]
    assert outcome.verdict.success
    assert outcome.identification.gross_idx == [17]
    back = Calibration.read(tmp_path / "lab.calibration.json")
    np.testing.assert_array_equal(back.theta, outcome.calibration.theta)
