"""pipeline.deliveries.klipper (python -m pipeline.export --to klipper): Klipper's parameters fitted
to a probe calibration, read back by pipeline.formats.klipper and moved by the independent Klipper
implementation (tests/klipper_reference.py) onto the identified machine: the residual NOTES.md
states, at least %.6f, a bed_mesh profile in Klipper's format."""

import re

import numpy as np
import pytest

import klipper_reference as kr
from calib.calibration import Calibration
from calib.klipper import bed_to_base, volume_grid
from pipeline.convert import main as convert_main
from pipeline.deliveries.klipper import MESH_COUNT, MESH_PROFILE, save_config_text
from pipeline.export import main as export_main
from pipeline.formats.klipper import parse_klipper_text
from pipeline.probe import main as probe_main
from test_klipper_probe import STEP_MM, config_text

#: Agreement of two implementations of the same double-precision formulas, mm (%.6f rounding of
#: the written parameters moves the tool by ~1e-6 mm x the lever arms' ratio ~10).
READ_BACK_MM = 1e-4


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    d = tmp_path_factory.mktemp("klipper")
    cfg = d / "printer.cfg"
    cfg.write_text(config_text())
    assert convert_main([str(cfg), "--klipper", "--out", str(d / "p")]) == 0
    assert probe_main([str(d / "p.probe.json"), "--out", str(d / "cal")]) == 0
    assert export_main(["--calibration", str(d / "cal" / "p.calibration.json"), "--to", "klipper",
                        "--out", str(d / "out")]) == 0
    return d


def read_back(d):
    """The printer.cfg with the export's SAVE_CONFIG block in place of the old one, as Klipper reads it."""
    head = (d / "printer.cfg").read_text().split("#*# <")[0]
    return parse_klipper_text(head + (d / "out" / "save_config.cfg").read_text(), d / "printer.cfg")


def test_klipper_reference_reproduces_the_stated_residual(exported):
    cfg = read_back(exported)
    from pipeline.formats.klipper import klipper_printer

    m = klipper_printer(cfg).machine
    params = kr.DeltaParams(m.radius_mm, tuple(np.degrees(m.angles_rad)), tuple(m.arm_lengths_mm),
                            tuple(m.endstops_mm), tuple(m.step_distances_mm))
    cal = Calibration.read(exported / "cal" / "p.calibration.json")
    bed = [cal.recording["bed"][k] for k in ("z_mm", "tilt_x_rad", "tilt_y_rad")]
    v = cal.validity
    grid = volume_grid(max(abs(v["pose_min"][0]), abs(v["pose_max"][0]), abs(v["pose_min"][1]),
                           abs(v["pose_max"][1])))
    steps = kr.stable_from_position(params, grid)  # Klipper's steps at its new step distances
    reached = cal.robot.forward_kinematics(cal.theta, steps * STEP_MM)  # counted at the old ones
    err = reached - bed_to_base(grid, bed)
    err[:, :2] -= err[:, :2].mean(axis=0)  # the best shift of the print in x, y (probe data fix none)
    err = np.linalg.norm(err, axis=1)
    notes = (exported / "out" / "NOTES.md").read_text()
    rms, mx = (float(x) for x in re.search(r"\| without mesh \| ([0-9.]+) \| ([0-9.]+) \|", notes).groups())
    assert abs(np.sqrt(np.mean(err ** 2)) - rms) < READ_BACK_MM + 5e-5  # the table's 4 decimals
    assert abs(err.max() - mx) < READ_BACK_MM + 5e-5
    nominal = kr.DeltaParams(140.0, (210.0, 330.0, 90.0), (250.0,) * 3, (303.9,) * 3, (STEP_MM,) * 3)
    before = cal.robot.forward_kinematics(cal.theta, kr.stable_from_position(nominal, grid) * STEP_MM)
    assert np.sqrt(np.mean(np.sum((before - bed_to_base(grid, bed)) ** 2, 1))) > 5 * rms


def test_save_config_precision_and_mesh_format(exported):
    text = (exported / "out" / "save_config.cfg").read_text()
    assert all(line.startswith("#*#") for line in text.splitlines())
    for key in ("delta_radius", "angle", "arm_length", "position_endstop", "rotation_distance"):
        values = re.findall(rf"^#\*# {key} = (-?[0-9]+\.[0-9]+)$", text, flags=re.M)
        assert values and all(len(v.split(".")[1]) >= 6 for v in values), key
    head = (exported / "printer.cfg").read_text().split("#*# <")[0]
    axis, points = np.linspace(-90.0, 90.0, MESH_COUNT), np.arange(MESH_COUNT ** 2).reshape(MESH_COUNT, -1) * 1e-3
    kappa = np.r_[140.0, np.radians([210.0, 330.0, 90.0]), [250.0] * 3, [303.9] * 3, [1.0] * 3]
    cfg = parse_klipper_text(head + save_config_text(kappa, [40.0] * 3, axis, points), exported / "printer.cfg")
    mesh = cfg.sections[f"bed_mesh {MESH_PROFILE}"]
    rows = [r for r in mesh["points"].value.split("\n") if r.strip()]
    assert len(rows) == int(mesh["y_count"].value) == int(mesh["x_count"].value) == MESH_COUNT
    assert [v.strip() for v in rows[1].split(",")] == [f"{v:.6f}" for v in points[1]]
    assert float(mesh["min_x"].value) == -float(mesh["max_x"].value) == -90.0
    assert f"bed_mesh {MESH_PROFILE}" not in parse_klipper_text(
        head + save_config_text(kappa, [40.0] * 3, axis, None), exported / "printer.cfg").sections
    notes = (exported / "out" / "NOTES.md").read_text()
    for words in ("Tower lean", "Unequal rods", "Thermal growth", "with mesh"):
        assert words in notes


def test_a_mesh_is_written_only_where_it_lowers_the_residual(exported):
    """The mesh removes the z error at the bed at every height (as Klipper applies it): written
    where that lowers the projection's RMS over the volume, else not, and NOTES.md says why."""
    notes = (exported / "out" / "NOTES.md").read_text()
    without, with_mesh = (float(re.search(rf"\| {k} \| ([0-9.]+) \|", notes).group(1))
                          for k in ("without mesh", "with mesh"))
    written = f"[bed_mesh {MESH_PROFILE}]" in (exported / "out" / "save_config.cfg").read_text()
    assert written == (with_mesh < without)
    assert ("no `[bed_mesh]` profile was written" in notes) == (not written)
