"""pipeline.convert printer.cfg --klipper on a rotary Delta's config (pipeline.workflows.klipper_rotary):
the Delta robot Klipper believes in, written as a description the workbench reads, moving as the
independent implementation of Klipper's formulas (tests/klipper_rotary_reference.py) does; the
touches it cannot fit said, a config it cannot hold refused in one line with nothing written."""

import json
from pathlib import Path

import numpy as np
import pytest

import klipper_rotary_reference as ref
from calib.robots import robot_from_description
from pipeline.convert import main as convert_main
from pipeline.probe import main as probe_main
from pipeline.formats.klipper import read_klipper_config
from pipeline.workflows.design import load_robot
from test_klipper_rotary import SAME_FORMULAS, grid_of

FIXTURE = Path(__file__).parent / "data" / "klipper" / "rotary_delta_printer.cfg"


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    d = tmp_path_factory.mktemp("rotary_convert")
    assert convert_main([str(FIXTURE), "--klipper", "--out", str(d / "rotary")]) == 0
    return d / "rotary.json"


def test_the_description_moves_as_klipper_does(converted):
    description = json.loads(converted.read_text())
    robot = robot_from_description("delta", description)
    p = ref.read_params(read_klipper_config(FIXTURE))
    targets = grid_of(robot)
    turns = ref.turns_below_endstops(p, targets)
    np.testing.assert_allclose(robot.forward_kinematics(robot.table.nominal, turns),
                               targets - [0.0, 0.0, p.shoulder_height], rtol=0, atol=SAME_FORMULAS * 1e3)
    assert description["klipper"]["kinematics"] == "rotary_delta"
    assert np.allclose(description["klipper"]["step_angles_rad"], 2 * np.pi / (200 * 16 * 107 / 20 * 5))


def test_the_description_is_what_geometry_flags_read(converted):
    """``--geometry`` (pipeline.design, pipeline.study) reads it: the bed at the bottom of the workspace."""
    robot, _ = load_robot("delta", str(converted))
    np.testing.assert_array_equal(robot.table.nominal,
                                  robot_from_description("delta", json.loads(converted.read_text())).table.nominal)
    assert robot.workspace_bounds()[2, 0] == -ref.read_params(read_klipper_config(FIXTURE)).shoulder_height


def test_the_touches_are_converted_and_too_few_for_the_fit_are_refused(tmp_path, capsys):
    assert convert_main([str(FIXTURE), "--klipper", "--out", str(tmp_path / "r")]) == 0
    out, err = capsys.readouterr()
    assert out.startswith(f"wrote {tmp_path / 'r.json'}: the delta robot of the rotary_delta config")
    assert f"wrote {tmp_path / 'r.probe.json'}: 3 touches, 0 manual heights, 0 distances" in out and not err
    assert probe_main([str(tmp_path / "r.probe.json"), "--out", str(tmp_path / "cal")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "3 measurements (3 touches, 0 manual heights, 0 distances) for 24 parameters" in err
    assert not (tmp_path / "cal" / "r.calibration.json").exists()


def test_a_touch_the_robot_cannot_assemble_is_refused_in_one_line(tmp_path, capsys):
    cfg = tmp_path / "printer.cfg"
    cfg.write_text(FIXTURE.read_text().replace("height1_pos = 4620.500,4618.250,3880.000",
                                               "height1_pos = 4620.500,4618.250,-30000.000"))
    assert convert_main([str(cfg), "--klipper", "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(cfg) in err and "[delta_calibrate] height1_pos" in err and "do not assemble" in err
    assert not (tmp_path / "r.json").exists() and not (tmp_path / "r.probe.json").exists()


@pytest.mark.parametrize("old, new, words", [
    ("position_endstop: 252\n", "position_endstop: 1000\n", "[stepper_a] position_endstop: arm a: position_endstop 1000"),
    ("shoulder_radius: 33.900\n", "", "[printer] shoulder_radius is missing"),
])
def test_a_config_it_cannot_hold_is_refused_in_one_line(tmp_path, capsys, old, new, words):
    text = FIXTURE.read_text().split("#*# <")[0]  # the saved block would override the change
    cfg = tmp_path / "printer.cfg"
    cfg.write_text(text.replace(old, new))
    assert convert_main([str(cfg), "--klipper", "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and words in err and str(cfg) in err
    assert not (tmp_path / "r.json").exists()
