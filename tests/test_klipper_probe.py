"""python -m pipeline.convert printer.cfg --klipper and python -m pipeline.probe: a printer.cfg
whose [delta_calibrate] block tests/klipper_reference.py wrote (touches, gauge heights and the
calibration object's distances of a machine off the config's nominal) converted, calibrated, and
every refusal in one line with nothing written."""

import numpy as np
import pytest

import klipper_reference as kr
from calib.calibration import Calibration
from pipeline.convert import main as convert_main
from pipeline.formats.probe_file import read_probe_file
from pipeline.probe import main as probe_main

#: Step distance of the config's steppers: rotation_distance 40 / (200 full steps x 16 microsteps).
STEP_MM = 40.0 / (200 * 16)
NOMINAL = kr.DeltaParams(140.0, (210.0, 330.0, 90.0), (250.0,) * 3, (303.9,) * 3, (STEP_MM,) * 3)
TRUTH = kr.DeltaParams(140.6, (210.3, 329.8, 90.0), (250.2, 249.9, 250.3), (304.5, 303.2, 303.7), (STEP_MM,) * 3)


def config_text(n_touches=61, kinematics="delta", microsteps=16, gauges=True):
    rng = np.random.default_rng(0)
    a, r = rng.uniform(0, 2 * np.pi, n_touches), 90 * np.sqrt(rng.uniform(0, 1, n_touches))
    xy = np.column_stack([r * np.cos(a), r * np.sin(a)])
    touch = kr.stable_from_position(TRUTH, np.column_stack([xy, np.zeros(n_touches)]))
    g = np.column_stack([np.tile(xy[:10], (2, 1)), np.repeat([50.0, 100.0], 10)]) if gauges else np.zeros((0, 3))
    ends = kr.calibration_object_points()
    m = kr.Measurements(np.zeros(n_touches), touch, g[:, 2], kr.stable_from_position(TRUTH, g),
                        np.linalg.norm(ends[:, 0] - ends[:, 1], axis=1), kr.stable_from_position(TRUTH, ends))
    head = f"[printer]\nkinematics: {kinematics}\ndelta_radius: 140\n\n"
    for t in "abc":
        head += f"[stepper_{t}]\nmicrosteps: {microsteps}\nrotation_distance: 40\n"
        head += "arm_length: 250\nposition_endstop: 303.9\n\n" if t == "a" else "\n"
    return head + kr.save_config_text(NOMINAL, m)


def convert(tmp_path, text, capsys):
    cfg = tmp_path / "printer.cfg"
    cfg.write_text(text)
    code = convert_main([str(cfg), "--klipper", "--out", str(tmp_path / "p")])
    return code, capsys.readouterr()


def test_convert_then_calibrate(tmp_path, capsys):
    code, out = convert(tmp_path, config_text(), capsys)
    assert code == 0, out.err
    assert "61 touches, 20 manual heights, 12 distances" in out.out
    robot, data, noise, _ = read_probe_file(tmp_path / "p.probe.json")
    assert np.allclose(data.touch_joints / STEP_MM, np.round(data.touch_joints / STEP_MM * 1000) / 1000)
    code = probe_main([str(tmp_path / "p.probe.json"), "--out", str(tmp_path / "cal")])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "Left to the tolerances" in out.out or "No combination" in out.out
    cal = Calibration.read(tmp_path / "cal" / "p.calibration.json")
    assert (tmp_path / "cal" / "p.observability.txt").read_text().strip() in out.out
    held = kr.stable_from_position(TRUTH, np.array([[30.0, -40.0, 0.0], [-50.0, 10.0, 80.0], [0.0, 60.0, 140.0]]))
    got = robot.forward_kinematics(cal.theta, held * STEP_MM)
    bed = cal.recording["bed"]  # the bed estimated: heights are above it
    got[:, 2] -= bed["z_mm"] + got[:, 0] * bed["tilt_x_rad"] + got[:, 1] * bed["tilt_y_rad"]
    want = kr.position_from_stable(TRUTH, held)
    nominal = robot.forward_kinematics(robot.table.nominal, held * STEP_MM)
    assert np.max(np.abs(got[:, 2] - want[:, 2])) < 0.1 * np.max(np.abs(nominal[:, 2] - want[:, 2]))


@pytest.mark.parametrize("text, words", [
    (config_text(kinematics="cartesian"), "[printer] kinematics: 'cartesian' is not a Delta"),
    (config_text(kinematics="rotary_delta"), "[printer] shoulder_radius is missing"),
    (config_text(microsteps=32), "counted with another one; 2.00"),
])
def test_convert_refusals(tmp_path, capsys, text, words):
    code, out = convert(tmp_path, text, capsys)
    assert code == 2 and words in out.err and len(out.err.strip().splitlines()) == 1, out.err
    assert not (tmp_path / "p.probe.json").exists()


def test_fewer_touches_than_parameters_refused(tmp_path, capsys):
    code, out = convert(tmp_path, config_text(n_touches=7, gauges=False).replace("#*# distance", "#*# x_distance"),
                        capsys)
    assert code == 0, out.err
    code = probe_main([str(tmp_path / "p.probe.json"), "--out", str(tmp_path / "cal")])
    err = capsys.readouterr().err
    assert code == 2 and "7 measurements (7 touches, 0 manual heights, 0 distances) for 27 parameters" in err
    assert not (tmp_path / "cal" / "p.calibration.json").exists()
