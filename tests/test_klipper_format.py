"""pipeline.formats.klipper: Klipper's printer.cfg read into a Delta's geometry, step sizes and
probe data, on configs written as Klipper writes them (tests/data/klipper/), and every refusal."""

import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.formats.klipper import (SAVE_CONFIG_HEADER, KlipperDelta, KlipperError, KlipperRotaryDelta,
                                      klipper_printer, parse_klipper_text, read_klipper_config, read_klipper_printer)

DATA = Path(__file__).resolve().parent / "data" / "klipper"
LINEAR = DATA / "delta_printer.cfg"
ROTARY = DATA / "rotary_delta_printer.cfg"

#: A small linear Delta config every refusal below changes in one place.
SMALL = DATA / "small_delta.cfg"
BASE = SMALL.read_text()

END = "distance0_pos2: 1200,1000,800\n"

ROTARY_BASE = """[printer]
kinematics: rotary_delta
shoulder_radius: 33.9
shoulder_height: 412.9

[stepper_a]
microsteps: 16
gear_ratio: 107:20, 5:1
upper_arm_length: 170
lower_arm_length: 320
position_endstop: 252

[stepper_b]
microsteps: 16
gear_ratio: 107:20, 5:1

[stepper_c]
microsteps: 16
gear_ratio: 107:20, 5:1
"""


def written(tmp_path, text, name="printer.cfg"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_the_linear_fixture_is_read_with_its_save_config_block_overriding_the_sections_above():
    printer = read_klipper_printer(LINEAR)
    d = printer.machine
    assert printer.kinematics == "delta" and isinstance(d, KlipperDelta)
    assert d.radius_mm == 174.358713  # the SAVE_CONFIG block's, not [printer]'s 174.75
    np.testing.assert_array_equal(d.angles_rad, np.radians([210.512342, 329.679802, 90.0]))
    np.testing.assert_array_equal(d.arm_lengths_mm, [333.0] * 3)
    np.testing.assert_array_equal(d.endstops_mm, [297.482154, 296.805311, 297.211407])
    # rotation_distance / (full_steps_per_rotation x microsteps x gear_ratio), per tower
    np.testing.assert_array_equal(d.step_distances_mm, [40 / (200 * 16), 40 / (200 * 16 * (80 / 20 * 1 / 4)),
                                                        80 / (400 * 32)])
    assert d.print_radius_mm == d.radius_mm


def test_the_linear_fixture_s_delta_calibrate_block_is_read_with_the_radius_of_the_section_above():
    probe = read_klipper_printer(LINEAR).probe
    assert probe.touch_steps.shape == (7, 3) and probe.touch_z_mm.shape == (7,)
    np.testing.assert_array_equal(probe.touch_steps[1], [25893.5, 25893.75, 21969.125])
    np.testing.assert_array_equal(probe.touch_z_mm, [0.2] * 7)
    np.testing.assert_array_equal(probe.manual_steps, [[19893.0] * 3])
    np.testing.assert_array_equal(probe.manual_z_mm, [50.0])
    np.testing.assert_array_equal(probe.distance_mm, [64.823, 64.901])
    assert probe.distance_steps.shape == (2, 2, 3)
    np.testing.assert_array_equal(probe.distance_steps[0], [[23900.25, 23820, 23860], [27450, 24400, 20900]])
    assert probe.radius_mm == 50.0


def test_the_rotary_fixture_is_read_with_defaults_from_stepper_a():
    printer = read_klipper_printer(ROTARY)
    d = printer.machine
    assert printer.kinematics == "rotary_delta" and isinstance(d, KlipperRotaryDelta)
    assert (d.shoulder_radius_mm, d.shoulder_height_mm) == (33.9, 413.212004)
    np.testing.assert_array_equal(d.upper_arm_lengths_mm, [170.0] * 3)
    np.testing.assert_array_equal(d.lower_arm_lengths_mm, [320.0, 320.0, 321.5])
    np.testing.assert_array_equal(d.angles_rad, np.radians([30.0, 150.0, 270.0]))
    np.testing.assert_array_equal(d.endstops_mm, [252.143170, 251.902233, 252.308019])
    np.testing.assert_array_equal(d.step_angles_rad, [2 * math.pi / (200 * 16 * (107 / 20 * 5))] * 3)
    assert printer.probe.touch_steps.shape == (3, 3)


def test_linear_defaults_angles_arm_and_endstop_from_stepper_a(tmp_path):
    d = read_klipper_printer(written(tmp_path, BASE)).machine
    np.testing.assert_array_equal(d.angles_rad, np.radians([210.0, 330.0, 90.0]))
    np.testing.assert_array_equal(d.arm_lengths_mm, [250.0] * 3)
    np.testing.assert_array_equal(d.endstops_mm, [300.0] * 3)
    np.testing.assert_array_equal(d.step_distances_mm, [40 / 3200] * 3)


def test_the_syntax_comments_continuations_and_the_block_s_lines():
    cfg = read_klipper_config(LINEAR)
    assert cfg.sections["stepper_b"]["microsteps"].value == "16"  # '=' and a ';' comment
    assert cfg.sections["stepper_b"]["gear_ratio"].value == "80:20, 1:4"  # a '#' comment
    assert cfg.sections["gcode_macro START_PRINT"]["gcode"].value == "G28\nG1 Z10 F3000\nM117 Printing"
    points = cfg.sections["bed_mesh default"]["points"].value.split("\n")
    assert len(points) == 3 and points[2] == "0.001250, 0.008750, 0.020000"
    where = cfg.sections["printer"]["delta_radius"].where
    assert where.startswith(f"{LINEAR}: line ") and where.endswith("(SAVE_CONFIG)")
    assert cfg.sections["delta_calibrate"]["horizontal_move_z"].value == "5"


def test_a_later_key_overrides_an_earlier_one_and_keys_are_case_insensitive(tmp_path):
    text = BASE.replace("delta_radius: 140", "delta_radius: 140\nDELTA_RADIUS = 150") + "[printer]\nprint_radius: 90\n"
    d = read_klipper_printer(written(tmp_path, text)).machine
    assert (d.radius_mm, d.print_radius_mm) == (150.0, 90.0)


def test_a_block_pasted_without_its_header_is_read_as_the_block(tmp_path):
    text = LINEAR.read_text().replace(SAVE_CONFIG_HEADER + "\n", "")
    pasted = read_klipper_printer(written(tmp_path, text))
    whole = read_klipper_printer(LINEAR)
    assert pasted.machine.radius_mm == whole.machine.radius_mm
    np.testing.assert_array_equal(pasted.probe.touch_steps, whole.probe.touch_steps)


def test_includes_are_read_where_they_stand_relative_to_the_including_file(tmp_path):
    head, _, steppers = BASE.partition("[stepper_a]")
    steppers, _, calibrate = ("[stepper_a]" + steppers).partition("[delta_calibrate]")
    (tmp_path / "parts").mkdir()
    written(tmp_path / "parts", steppers, "steppers.cfg")
    written(tmp_path / "parts", "[printer]\ndelta_radius: 141\n", "override.cfg")
    path = written(tmp_path, head + "[include parts/steppers.cfg]\n[include parts/over*.cfg]\n[delta_calibrate]"
                   + calibrate)
    whole = read_klipper_printer(written(tmp_path, BASE, "whole.cfg"))
    included = read_klipper_printer(path)
    assert included.machine.radius_mm == 141.0
    np.testing.assert_array_equal(included.machine.endstops_mm, whole.machine.endstops_mm)
    np.testing.assert_array_equal(included.probe.distance_steps, whole.probe.distance_steps)


def test_a_config_without_delta_calibrate_has_no_probe_data(tmp_path):
    assert read_klipper_printer(written(tmp_path, BASE.partition("[delta_calibrate]")[0])).probe is None


def test_parse_klipper_text_names_the_path_it_is_given():
    with pytest.raises(KlipperError, match=r"^somewhere\.cfg: no \[printer\] section"):
        klipper_printer(parse_klipper_text("[stepper_a]\n", "somewhere.cfg"))


#: (what is wrong, the base config's text replaced, its replacement, the message's words).
REFUSALS = [
    ("not a delta", "kinematics: delta", "kinematics: corexy", ["line 2", "[printer] kinematics",
                                                                "'corexy' is not a Delta"]),
    ("no kinematics", "kinematics: delta\n", "", ["[printer] kinematics is missing"]),
    ("no printer", "[printer]\nkinematics: delta\ndelta_radius: 140\n", "", ["no [printer] section"]),
    ("no delta_radius", "delta_radius: 140\n", "", ["[printer] delta_radius is missing"]),
    ("delta_radius not a number", "delta_radius: 140", "delta_radius: 14O", ["line 3", "'14O' is not a number"]),
    ("delta_radius nan", "delta_radius: 140", "delta_radius: nan", ["'nan' is not a number"]),
    ("delta_radius negative", "delta_radius: 140", "delta_radius: -140", ["-140 must be greater than 0"]),
    ("no arm_length", "arm_length: 250\n", "", ["[stepper_a] arm_length is missing", "default to it"]),
    ("arm shorter than radius", "arm_length: 250", "arm_length: 130",
     ["[stepper_a] arm_length: 130 must be greater than delta_radius 140"]),
    ("b's arm shorter", "[stepper_b]\n", "[stepper_b]\narm_length: 120\n", ["[stepper_b] arm_length: 120"]),
    ("no stepper_c", "[stepper_c]\nmicrosteps: 16\nrotation_distance: 40\n", "", ["no [stepper_c] section"]),
    ("no position_endstop", "position_endstop: 300\n", "", ["[stepper_a] position_endstop is missing"]),
    ("angle not a number", "[stepper_b]\n", "[stepper_b]\nangle: 33O\n", ["[stepper_b] angle", "'33O'"]),
    ("no rotation_distance", "[stepper_b]\nmicrosteps: 16\nrotation_distance: 40\n", "[stepper_b]\nmicrosteps: 16\n",
     ["[stepper_b] rotation_distance is missing"]),
    ("old step_distance", "[stepper_b]\nmicrosteps: 16\nrotation_distance: 40\n",
     "[stepper_b]\nmicrosteps: 16\nstep_distance: 0.0125\n", ["[stepper_b] step_distance", "rotation_distance ="]),
    ("no microsteps", "[stepper_c]\nmicrosteps: 16\n", "[stepper_c]\n", ["[stepper_c] microsteps is missing"]),
    ("microsteps not whole", "[stepper_c]\nmicrosteps: 16", "[stepper_c]\nmicrosteps: 16.5",
     ["[stepper_c] microsteps", "'16.5' is not a whole number"]),
    ("full steps not a multiple of 4", "[stepper_c]\n", "[stepper_c]\nfull_steps_per_rotation: 201\n",
     ["full_steps_per_rotation: 201 is not a multiple of 4"]),
    ("gear ratio not a pair", "[stepper_c]\n", "[stepper_c]\ngear_ratio: 3\n", ["[stepper_c] gear_ratio", "'3'"]),
    ("gear ratio zero", "[stepper_c]\n", "[stepper_c]\ngear_ratio: 80:20, 1:0\n", ["'1:0' is not a pair of positive"]),
    ("height pos two numbers", "height1_pos: 1100,1000,900", "height1_pos: 1100,1000",
     ["[delta_calibrate] height1_pos", "'1100,1000' is not three numbers"]),
    ("height pos not numbers", "height1_pos: 1100,1000,900", "height1_pos: 1100,1000,x", ["is not three numbers"]),
    ("height without pos", "height1_pos: 1100,1000,900\n", "", ["[delta_calibrate] height1_pos is missing"]),
    ("height not a number", "height1: 0.2", "height1: high", ["[delta_calibrate] height1", "'high'"]),
    ("a gap in the heights", "height1: 0.2\nheight1_pos", "height2: 0.2\nheight2_pos",
     ["[delta_calibrate] height2", "height1 is missing"]),
    ("a position without its height", "radius: 60", "radius: 60\nheight5_pos: 1,2,3",
     ["height5_pos", "there is no height5"]),
    ("a manual position without its height", "radius: 60", "radius: 60\nmanual_height0_pos: 1,2,3",
     ["manual_height0_pos", "there is no manual_height0"]),
    ("distance without pos2", "distance0_pos2: 1200,1000,800\n", "", ["distance0_pos2 is missing"]),
    ("distance negative", "distance0: 60.5", "distance0: -60.5", ["[delta_calibrate] distance0", "greater than 0"]),
    ("key before any section", "[printer]\n", "delta_radius: 1\n[printer]\n", ["line 1", "before any [section]"]),
    ("a line that is nothing", "[stepper_a]\n", "[stepper_a]\njust words\n", ["line 6", "'just words' is neither"]),
    ("a broken header", "[stepper_c]", "[stepper_c", ["'[stepper_c' is not a [section] header"]),
    ("block edited below its header", END, f"{END}{SAVE_CONFIG_HEADER}\n#*# [printer]\ndelta_radius: 1\n",
     ["line 30: not prefixed '#*# '", "(line 28)"]),
    ("block line above its header", END, f"{END}#*# [printer]\n{SAVE_CONFIG_HEADER}\n",
     ["line 28: a '#*#' line above the SAVE_CONFIG header (line 29)"]),
    ("a missing include", "[stepper_a]\n", "[include nothere.cfg]\n[stepper_a]\n", ["[include nothere.cfg]",
                                                                                    "does not exist"]),
    ("an include of itself", "[stepper_a]\n", "[include printer.cfg]\n[stepper_a]\n", ["includes itself"]),
    ("an error in the block", END, f"{END}{SAVE_CONFIG_HEADER}\n#*# [printer]\n#*# delta_radius = x\n",
     ["line 30 (SAVE_CONFIG): [printer] delta_radius: 'x' is not a number"]),
]


def assert_refused(tmp_path, base, old, new, words):
    """``base`` with ``old`` replaced by ``new`` is refused in one line naming the file, with ``words``."""
    assert old in base
    path = written(tmp_path, base.replace(old, new, 1))
    with pytest.raises(KlipperError) as caught:
        read_klipper_printer(path)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(str(path))
    for w in words:
        assert w in message


@pytest.mark.parametrize("old, new, words", [r[1:] for r in REFUSALS], ids=[r[0] for r in REFUSALS])
def test_every_refusal_is_one_line_naming_the_file_and_what_is_wrong(tmp_path, old, new, words):
    assert_refused(tmp_path, BASE, old, new, words)


ROTARY_REFUSALS = [
    ("no shoulder_radius", "shoulder_radius: 33.9\n", "", ["[printer] shoulder_radius is missing"]),
    ("no upper arm", "upper_arm_length: 170\n", "", ["[stepper_a] upper_arm_length is missing"]),
    ("no lower arm", "lower_arm_length: 320\n", "", ["[stepper_a] lower_arm_length is missing"]),
    ("no gear ratio", "[stepper_b]\nmicrosteps: 16\ngear_ratio: 107:20, 5:1\n", "[stepper_b]\nmicrosteps: 16\n",
     ["[stepper_b] gear_ratio is missing", "rotary"]),
    ("no position_endstop", "position_endstop: 252\n", "", ["[stepper_a] position_endstop is missing"]),
]


@pytest.mark.parametrize("old, new, words", [r[1:] for r in ROTARY_REFUSALS], ids=[r[0] for r in ROTARY_REFUSALS])
def test_every_rotary_refusal_is_one_line(tmp_path, old, new, words):
    assert_refused(tmp_path, ROTARY_BASE, old, new, words)


def test_the_rotary_base_is_read(tmp_path):
    assert read_klipper_printer(written(tmp_path, ROTARY_BASE)).probe is None


@pytest.mark.parametrize("fixture", [LINEAR, ROTARY], ids=["delta", "rotary_delta"])
def test_a_file_that_is_not_there_or_not_text_is_refused_by_name(tmp_path, fixture):
    with pytest.raises(KlipperError, match="not found"):
        read_klipper_printer(tmp_path / fixture.name)
    binary = shutil.copy(fixture, tmp_path / fixture.name)
    Path(binary).write_bytes(fixture.read_bytes() + b"\0")
    with pytest.raises(KlipperError, match="NUL"):
        read_klipper_printer(binary)


@pytest.mark.parametrize("fixture", [LINEAR, ROTARY], ids=["delta", "rotary_delta"])
def test_windows_line_ends_and_a_byte_order_mark_read_the_same(tmp_path, fixture):
    path = tmp_path / fixture.name
    path.write_bytes(b"\xef\xbb\xbf" + fixture.read_bytes().replace(b"\n", b"\r\n"))
    a, b = read_klipper_printer(path), read_klipper_printer(fixture)
    np.testing.assert_array_equal(a.machine.angles_rad, b.machine.angles_rad)
    np.testing.assert_array_equal(a.machine.endstops_mm, b.machine.endstops_mm)
    np.testing.assert_array_equal(a.probe.touch_steps, b.probe.touch_steps)


def test_the_machine_as_built_is_the_sections_above_the_block_with_what_save_config_commented_out(tmp_path):
    """The prior's centre (pipeline.convert --klipper): the owner's values above the block, those
    Klipper's SAVE_CONFIG commented out (``#key: value``) read again, Klipper's defaults where the
    owner wrote none, not the block's fit; the machine as Klipper runs it is the block's."""
    fixture = read_klipper_printer(LINEAR)
    assert fixture.built.radius_mm == 174.75  # [printer]'s, not the old '#delta_radius: 180' below it
    np.testing.assert_array_equal(fixture.built.endstops_mm, [297.05] * 3)  # stepper_a's, the default
    text = LINEAR.read_text().replace("delta_radius: 174.75\n", "#delta_radius: 174.5\n", 1)
    # two commented-out values of one key: which was the owner's is not known, none is read, and
    # without a delta_radius above the block the machine as built is the machine as run
    both = read_klipper_printer(written(tmp_path, text, "both.cfg"))
    assert both.built is both.machine and both.machine.radius_mm == 174.358713
    text = text.replace("#delta_radius: 180", "# delta_radius was 180", 1)
    printer = read_klipper_printer(written(tmp_path, text))
    assert printer.built.radius_mm == 174.5 and printer.machine.radius_mm == 174.358713
    plain = read_klipper_printer(written(tmp_path, LINEAR.read_text().split(SAVE_CONFIG_HEADER)[0], "plain.cfg"))
    assert plain.built is plain.machine and plain.machine.radius_mm == 174.75  # no block: the config itself
