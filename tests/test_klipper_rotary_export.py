"""pipeline.deliveries.klipper for the rotary Delta (``python -m pipeline.export --to klipper`` of a
``delta`` calibration): Klipper's rotary parameters fitted to the identified machine, written with
at least %.6f, read back by pipeline.formats.klipper and moved by the independent implementation
(tests/klipper_rotary_reference.py) onto the identified machine: the residual NOTES.md states."""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

import klipper_rotary_reference as ref
from calib.calibration import Calibration, validity_domain
from calib.klipper_rotary import delta_params_of_klipper
from pipeline.export import main as export_main
from pipeline.formats.klipper import parse_klipper_text, rotary_delta
from test_klipper_rotary import CONFIGS, HELD_ERROR, grid_of, kappa_of, robot_of

DATA = Path(__file__).parent / "data" / "klipper"
#: %.6f rounding of the written parameters moves the tool by ~1e-6 x the arms' lever ratio (~10).
READ_BACK_MM = 1e-4
#: A shoulder moved across its arm's plane (mm): what Klipper cannot hold.
ACROSS_MM = 0.8


def identified_calibration(name: str) -> Calibration:
    """A calibration of the config's Delta whose machine is off by an error Klipper holds and a
    shoulder moved across its plane (Klipper cannot hold it)."""
    p = CONFIGS[name]
    robot = robot_of(p)
    params = delta_params_of_klipper(kappa_of(p) + HELD_ERROR, p.shoulder_height)
    a = params.theta[2]
    params = dataclasses.replace(params, Dx=params.Dx - ACROSS_MM * np.sin(a) * np.array([0, 0, 1.0]),
                                 Dy=params.Dy + ACROSS_MM * np.cos(a) * np.array([0, 0, 1.0]))
    theta = params.to_vector()
    poses = grid_of(robot) - [0.0, 0.0, p.shoulder_height]
    joints = robot.inverse_kinematics(theta, poses)
    n = robot.n_parameters
    return Calibration(robot=robot, theta=theta, std=np.full(n, 1e-3), free=robot.table.names,
                       covariance=np.eye(n) * 1e-6, validity=validity_domain(robot, poses, joints, np.zeros(len(poses))),
                       produced_by="tests/test_klipper_rotary_export.py")


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    d = tmp_path_factory.mktemp("rotary")
    cal = identified_calibration("example")
    cal.write(d / "delta.calibration.json")
    assert export_main(["--calibration", str(d / "delta.calibration.json"), "--to", "klipper",
                        "--out", str(d / "out")]) == 0
    return d, cal


def read_back(d):
    """The example printer.cfg with the export's SAVE_CONFIG block in place of its own, as Klipper reads it."""
    head = (DATA / "rotary_delta_printer.cfg").read_text().split("#*# <")[0]
    return parse_klipper_text(head + (d / "out" / "save_config.cfg").read_text(), d / "printer.cfg")


def test_every_value_is_written_with_at_least_klippers_precision(exported):
    d, _ = exported
    values = re.findall(r"^#\*# \w+ = (.*)$", (d / "out" / "save_config.cfg").read_text(), flags=re.M)
    assert len(values) == 2 + 3 * 4
    assert all(re.fullmatch(r"-?\d+\.\d{6,}", v) for v in values)


def test_the_block_read_back_by_klippers_formulas_leaves_the_residual_notes_states(exported):
    d, cal = exported
    cfg = read_back(d)
    machine = rotary_delta(cfg)  # the workbench's reader accepts it
    p = ref.read_params(cfg)
    assert np.allclose(np.radians(p.angles), machine.angles_rad)
    depth = -cal.robot.workspace_bounds()[2, 0]
    targets = grid_of(cal.robot)
    reached = cal.robot.forward_kinematics(cal.theta, ref.turns_below_endstops(p, targets)) + [0.0, 0.0, depth]
    error = np.linalg.norm(reached - targets, axis=1)
    notes = (d / "out" / "NOTES.md").read_text()
    rms, worst = map(float, re.search(r"\| fitted \(this block\) \| ([\d.]+) \| ([\d.]+) \|\n", notes).groups())
    assert abs(np.sqrt(np.mean(error ** 2)) - rms) < READ_BACK_MM + 5e-5  # NOTES prints 4 decimals
    assert abs(error.max() - worst) < READ_BACK_MM + 5e-5
    assert rms > 10 * READ_BACK_MM  # the shoulder across its plane is not held
    unfitted = float(re.search(r"\| read off the identified ones one by one \(no fit\) \| ([\d.]+) \|", notes).group(1))
    assert rms < unfitted  # the fit gives up less than Klipper's parameters read off one by one


def test_the_notes_name_what_klipper_cannot_hold(exported):
    d, _ = exported
    notes = (d / "out" / "NOTES.md").read_text()
    across = re.search(r"offset across it, mm\): a ([-+\d.]+), b ([-+\d.]+), c ([-+]?\d+\.\d+)", notes).groups()
    np.testing.assert_allclose([float(v) for v in across], [0.0, 0.0, ACROSS_MM], atol=5e-4)
    assert "Klipper has no term for them" in notes


def test_an_existing_export_is_refused_in_one_line(exported, capsys):
    d, _ = exported
    before = (d / "out" / "save_config.cfg").read_text()
    capsys.readouterr()
    assert export_main(["--calibration", str(d / "delta.calibration.json"), "--to", "klipper",
                        "--out", str(d / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "save_config.cfg" in err
    assert (d / "out" / "save_config.cfg").read_text() == before
