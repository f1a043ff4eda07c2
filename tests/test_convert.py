"""``python -m pipeline.convert``: a lab's export read through a mapping file gives back the
recording it was exported from, and the recording format's sessions and extra channels.

The lab files are written here, independently of the converter: orientations by SciPy's
``Rotation`` (``from_euler("xyz", [alpha, beta, gamma])`` is ``Rz(gamma) Ry(beta) Rx(alpha)``, the
project's convention), units by their definitions (1 in = 25.4 mm, 1 deg = pi/180 rad).

Bounds (u = 2^-53, the unit roundoff). Each conversion is a few correctly rounded operations,
each off by at most u relative to its result, so the round trip's error is bounded by counting
them (first order; a factor 1.01 covers the O(u^2) terms):

* a length exported as ``x / f`` and read back as ``x_lab * f``: 2 roundings, 2u|x|;
* a joint exported as ``(j / f - zero) / scale`` and read as ``(zero + scale * raw) * f``: 6
  roundings, at most 3u(|j| + |j - f zero|) (the terms around the offset, then the value);
* time in ms with an origin (``t * 1000 + 5000``, read ``(t_ms - 5000) / 1000``): u(3|t| + |t + 5 s|);
  ISO timestamps carry microseconds: 0.5 us + u|t|;
* angles: from angles to the lab's form (SciPy) and back (normalised quaternion or matrix,
  then ``atan2``): each entry of the rotation matrix is a sum of a few products of numbers of
  magnitude <= 1, within ANGLE_ROUNDINGS u; alpha and gamma are ``atan2`` of entries of size
  ``cos beta``, so their error is that divided by ``cos beta`` (the Euler sequence's own middle
  angle likewise for a lab's Euler angles).
"""

from __future__ import annotations

import json
import math
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from calib.measurement import instrument_measurements
from calib.noise import SensorNoise
from calib.robots import ROBOTS, default_robot
from calib.workspace import reachable_poses
from pipeline.convert import main
from pipeline.formats import DEFAULT_SESSION, Recording, RecordingError, read_recording, write_recording
from pipeline.formats.recording import recording_texts, session_measurement
from pipeline.workflows.convert import ConvertSettings, run_convert

#: Unit roundoff of float64.
U = 2.0 ** -53
#: Roundings of unit-magnitude terms from angles to a rotation matrix's entries and back (see above):
#: about ten sums and products, each within 4u, plus the normalisation.
ANGLE_ROUNDINGS = 64
#: First-order bounds hold to O(u^2): this factor covers it.
SECOND_ORDER = 1.01
MM_PER_INCH = 25.4
MM_PER_M = 1000.0
RAD_PER_DEG = math.pi / 180.0
NOISE = SensorNoise(0.01, 1e-4, "normal", 0.0)
ISO_ORIGIN = datetime(2024, 3, 1, 9, 30, tzinfo=timezone(timedelta(hours=1)))
ROWS = 12


# --------------------------------------------------------------------------- the original


def simulated(robot, n: int, seed: int, *, frame=None) -> tuple[np.ndarray, np.ndarray]:
    """``(joints, measured)``: the inverse kinematics of n reachable poses, seen in ``frame``."""
    poses = reachable_poses(robot, n, seed)
    joints = robot.inverse_kinematics(robot.table.nominal, poses)
    return joints, poses if frame is None else instrument_measurements(robot, poses, frame)


def original(robot, seed: int, *, t_s=None, sets=None, extras=None) -> Recording:
    joints, measured = simulated(robot, ROWS, seed)
    t = np.cumsum(np.random.default_rng(seed).uniform(0.2, 3.0, ROWS)) if t_s is None else t_s
    return Recording(robot=robot, noise=NOISE, t_s=t, joints=joints, measured=measured,
                     sets=np.array(["calibration"] * ROWS) if sets is None else sets, extras=extras or {})


def angles(rec: Recording) -> np.ndarray:
    return rec.measured[:, 3:]


def has_angles(robot) -> bool:
    return bool(robot.angle_pose_mask.any())


# --------------------------------------------------------------------------- the lab's side


def lab_csv(header, rows, delimiter=",", decimal=".", preamble=()) -> str:
    def cell(v):
        text = v if isinstance(v, str) else repr(float(v))
        return text.replace(".", ",") if decimal == "," and not isinstance(v, str) else text
    return "".join(f"{p}\n" for p in preamble) + delimiter.join(header) + "\n" + "".join(
        delimiter.join(cell(v) for v in row) + "\n" for row in rows)


def toml_list(values) -> str:
    return "[" + ", ".join(json.dumps(v) if isinstance(v, str) else repr(float(v)) for v in values) + "]"


def robot_table(robot, description: str | None = None) -> str:
    return (f'[robot]\nname = "{robot.name}"\n' + (f'description = "{description}"\n' if description else "")
            + f'[noise]\nposition_mm = {NOISE.position_mm}\norientation_rad = {NOISE.orientation_rad}\n'
              f'distribution = "{NOISE.distribution}"\n')


def joint_encoding(robot, reading: str):
    """``(unit, f, scale (C,), zero (C,))``: the lab's joint encoder; ``f`` converts its unit to
    the robot's."""
    k = np.arange(robot.n_chains)
    if robot.joint_unit == "mm":
        if reading == "revolutions":
            return "mm", 1.0, 2.0 + 0.05 * k, 180.0 + k
        return "m", MM_PER_M, 1e-6 * (1 + 0.1 * k), 0.18 + 0.001 * k
    if reading == "revolutions":
        return "rad", 1.0, 2 * math.pi / (50 + k), -0.1 * k
    return "deg", RAD_PER_DEG, 360.0 / (4096 * (10 + k)), 5.0 * k


def joint_bound(joints, f, zero) -> np.ndarray:
    return SECOND_ORDER * 3 * U * (np.abs(joints) + np.abs(joints - f * zero))


def angle_bound(rec: Recording, other_middle=None) -> np.ndarray:
    cos = np.cos(angles(rec)[:, 1]) if other_middle is None else np.minimum(np.cos(angles(rec)[:, 1]),
                                                                              np.cos(other_middle))
    return np.broadcast_to((ANGLE_ROUNDINGS * U / cos)[:, None], (len(cos), 3))


def metres_quaternion_revolutions_map(robot, description: str | None = None) -> tuple[list, str]:
    """``(header, map)`` of the lab style of metres, quaternions scalar last, motor revolutions."""
    unit, _, scale, zero = joint_encoding(robot, "revolutions")
    header = ["Time", "X", "Y", "Z"] + (["QX", "QY", "QZ", "QW"] if has_angles(robot) else []) + \
        [f"M{i + 1}" for i in range(robot.n_chains)]
    orientation = '[orientation]\nkind = "quaternion"\nscalar = "last"\ncolumns = ["QX", "QY", "QZ", "QW"]\n'
    mapping = (robot_table(robot, description) + '[time]\nformat = "seconds"\ncolumn = "Time"\n'
               '[position]\ncolumns = ["X", "Y", "Z"]\nunit = "m"\n' + (orientation if has_angles(robot) else "")
               + f'[joints]\ncolumns = {toml_list(header[-robot.n_chains:])}\nreading = "revolutions"\n'
                 f'unit = "{unit}"\nscale = {toml_list(scale)}\nzero = {toml_list(zero)}\n')
    return header, mapping


def style_metres_quaternion_revolutions(robot, tmp_path):
    """Metres, quaternions scalar last, motor revolutions; the geometry from a description file."""
    rec = original(robot, 1)
    _, f, scale, zero = joint_encoding(robot, "revolutions")
    (tmp_path / "geometry.json").write_text(json.dumps(robot.description()))
    header, mapping = metres_quaternion_revolutions_map(robot, "geometry.json")
    rows = []
    for k in range(ROWS):
        q = list(Rotation.from_euler("xyz", angles(rec)[k]).as_quat()) if has_angles(robot) else []
        rows.append([rec.t_s[k], *(rec.measured[k, :3] / MM_PER_M), *q, *((rec.joints[k] / f - zero) / scale)])
    bounds = {"t_s": np.zeros(ROWS), "joints": joint_bound(rec.joints, f, zero),
              "position": SECOND_ORDER * 2 * U * np.abs(rec.measured[:, :3])}
    return rec, mapping, {"lab.csv": lab_csv(header, rows)}, bounds


#: Rows a large export is generated and written at a time (:func:`write_motion_capture_export`).
EXPORT_BLOCK_ROWS = 50_000


def write_motion_capture_export(folder, rows: int, seed: int = 0, robot_name: str = "hexapod"):
    """A large motion-capture export in the lab style of :func:`style_metres_quaternion_revolutions`
    (positions in metres, quaternions scalar last, legs as motor revolutions, time in s, 10 ms
    apart): ``rows`` reachable poses of the nominal machine measured with :data:`NOISE`, written
    :data:`EXPORT_BLOCK_ROWS` at a time (the generator's memory does not grow with the rows), and
    its map. Returns ``(folder / f"lab{rows}.csv", folder / "map.toml")``."""
    robot = default_robot(robot_name)
    rng = np.random.default_rng(seed)
    _, f, scale, zero = joint_encoding(robot, "revolutions")
    header, mapping = metres_quaternion_revolutions_map(robot)
    csv_path, map_path = folder / f"lab{rows}.csv", folder / "map.toml"
    map_path.write_text(mapping)
    with open(csv_path, "w") as out:
        out.write(",".join(header) + "\n")
        for start in range(0, rows, EXPORT_BLOCK_ROWS):
            n = min(EXPORT_BLOCK_ROWS, rows - start)
            poses = reachable_poses(robot, n, rng)
            legs = robot.inverse_kinematics(robot.table.nominal, poses)
            seen = poses + NOISE.sample(n, rng, robot.pose_units)
            q = Rotation.from_euler("xyz", seen[:, 3:]).as_quat() if has_angles(robot) else np.zeros((n, 0))
            block = np.column_stack([0.01 * np.arange(start, start + n), seen[:, :3] / MM_PER_M, q,
                                     (legs / f - zero) / scale])
            np.savetxt(out, block, fmt="%.17g", delimiter=",")
    return csv_path, map_path


def style_inches_matrix_counts_iso(robot, tmp_path):
    """Inches, 9-column rotation matrices (row by row), encoder counts, ISO timestamps."""
    rec = original(robot, 2)
    unit, f, scale, zero = joint_encoding(robot, "counts")
    header = ["timestamp", "Px", "Py", "Pz"] + ([f"R{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]
                                                 if has_angles(robot) else []) + \
        [f"enc{i + 1}" for i in range(robot.n_chains)]
    rows = []
    for k in range(ROWS):
        stamp = (ISO_ORIGIN + timedelta(seconds=float(rec.t_s[k]))).isoformat(timespec="microseconds")
        R = list(Rotation.from_euler("xyz", angles(rec)[k]).as_matrix().ravel()) if has_angles(robot) else []
        rows.append([stamp, *(rec.measured[k, :3] / MM_PER_INCH), *R, *((rec.joints[k] / f - zero) / scale)])
    orientation = f'[orientation]\nkind = "matrix"\norder = "row"\ncolumns = {toml_list(header[4:13])}\n'
    mapping = (robot_table(robot) + f'[time]\nformat = "iso"\ncolumn = "timestamp"\norigin = "{ISO_ORIGIN.isoformat()}"\n'
               '[position]\ncolumns = ["Px", "Py", "Pz"]\nunit = "in"\n' + (orientation if has_angles(robot) else "")
               + f'[joints]\ncolumns = {toml_list(header[-robot.n_chains:])}\nreading = "counts"\n'
                 f'unit = "{unit}"\nscale = {toml_list(scale)}\nzero = {toml_list(zero)}\n')
    bounds = {"t_s": 0.5e-6 + U * np.abs(rec.t_s), "joints": joint_bound(rec.joints, f, zero),
              "position": SECOND_ORDER * 2 * U * np.abs(rec.measured[:, :3])}
    return rec, mapping, {"lab.csv": lab_csv(header, rows)}, bounds


def style_mm_degrees_euler(robot, tmp_path):
    """mm, Euler angles of the moving-axes sequence XYZ in degrees, joint values in inches or
    degrees, milliseconds from an origin; ';'-separated with decimal commas after a preamble."""
    rec = original(robot, 3)
    unit, f = ("in", MM_PER_INCH) if robot.joint_unit == "mm" else ("deg", RAD_PER_DEG)
    header = ["t_ms", "x", "y", "z"] + (["Rx", "Ry", "Rz"] if has_angles(robot) else []) + \
        [f"joint {i + 1}" for i in range(robot.n_chains)]
    euler = Rotation.from_euler("xyz", angles(rec)).as_euler("XYZ") if has_angles(robot) else np.zeros((ROWS, 0))
    rows = [[rec.t_s[k] * 1000 + 5000, *rec.measured[k, :3], *(euler[k] / RAD_PER_DEG), *(rec.joints[k] / f)]
            for k in range(ROWS)]
    orientation = '[orientation]\nkind = "euler"\nsequence = "XYZ"\nunit = "deg"\ncolumns = ["Rx", "Ry", "Rz"]\n'
    mapping = (robot_table(robot) + '[csv]\ndelimiter = ";"\ndecimal = ","\nskip_lines = 2\n'
               '[time]\nformat = "seconds"\ncolumn = "t_ms"\nunit = "ms"\norigin = 5000.0\n'
               '[position]\ncolumns = ["x", "y", "z"]\nunit = "mm"\n' + (orientation if has_angles(robot) else "")
               + f'[joints]\ncolumns = {toml_list(header[-robot.n_chains:])}\nreading = "value"\nunit = "{unit}"\n')
    t = np.abs(rec.t_s)
    bounds = {"t_s": SECOND_ORDER * U * (3 * t + np.abs(rec.t_s + 5.0)), "joints": SECOND_ORDER * 2 * U * np.abs(rec.joints),
              "position": np.zeros((ROWS, 3)),
              "angles_middle": euler[:, 1] if has_angles(robot) else None}
    text = lab_csv(header, rows, ";", ",", preamble=("Exported by LabTool 3.2", "units: mm, deg"))
    return rec, mapping, {"lab.csv": text}, bounds


def style_two_sessions(robot, tmp_path):
    """Two files, two sessions months apart: the capture frame moved by 45 mm and 0.6 degrees;
    quaternions scalar first; each session's time from 0."""
    moved = np.array([45.0, 0.0, 0.0, 0.0, 0.0, np.deg2rad(0.6)])
    parts = [simulated(robot, ROWS, 4), simulated(robot, ROWS, 5, frame=moved)]
    t = [np.cumsum(np.random.default_rng(s).uniform(0.2, 3.0, ROWS)) - 0.2 for s in (4, 5)]
    names = ["winter", "summer"]
    rec = Recording(robot=robot, noise=NOISE, t_s=np.concatenate(t), joints=np.vstack([p[0] for p in parts]),
                    measured=np.vstack([p[1] for p in parts]), sets=np.array(["calibration"] * 2 * ROWS),
                    sessions=np.repeat(names, ROWS),
                    session_info={n: {"measurement": {"frame": "estimate"}} for n in names})
    header = ["t", "x_m", "y_m", "z_m"] + (["qw", "qx", "qy", "qz"] if has_angles(robot) else []) + \
        [f"rev{i + 1}" for i in range(robot.n_chains)]
    unit, f, scale, zero = joint_encoding(robot, "revolutions")
    files = {}
    for s, name in enumerate(names):
        rows = []
        for k in range(s * ROWS, (s + 1) * ROWS):
            q = Rotation.from_euler("xyz", angles(rec)[k]).as_quat()[[3, 0, 1, 2]] if has_angles(robot) else []
            rows.append([rec.t_s[k], *(rec.measured[k, :3] / MM_PER_M), *q,
                         *((rec.joints[k] / f - zero) / scale)])
        files[f"{name}.csv"] = lab_csv(header, rows)
    orientation = '[orientation]\nkind = "quaternion"\nscalar = "first"\ncolumns = ["qw", "qx", "qy", "qz"]\n'
    mapping = (robot_table(robot) + '[time]\nformat = "seconds"\ncolumn = "t"\n'
               '[position]\ncolumns = ["x_m", "y_m", "z_m"]\nunit = "m"\n' + (orientation if has_angles(robot) else "")
               + f'[joints]\ncolumns = {toml_list(header[-robot.n_chains:])}\nreading = "revolutions"\n'
                 f'unit = "{unit}"\nscale = {toml_list(scale)}\nzero = {toml_list(zero)}\n'
                 '[sessions]\nnames = ["winter", "summer"]\nframe = "estimate"\n')
    bounds = {"t_s": np.zeros(2 * ROWS), "joints": joint_bound(rec.joints, f, zero),
              "position": SECOND_ORDER * 2 * U * np.abs(rec.measured[:, :3])}
    return rec, mapping, files, bounds


def style_extras_and_filter(robot, tmp_path):
    """A temperature channel, sets from a column, rows in order (no time), and rows to keep:
    two warm-up rows, rows the tracker lost (valid = 0, cells empty or text) and one dropped by
    number, all with junk that must not be read."""
    rng = np.random.default_rng(6)
    sets = np.where(np.arange(ROWS) % 4 == 3, "validation", "calibration")
    rec = original(robot, 6, t_s=np.arange(ROWS, dtype=float), sets=sets,
                   extras={"temperature_C": 20 + rng.uniform(0, 3, ROWS)})
    header = ["valid", "use", "Temp (C)", "X", "Y", "Z"] + (["a", "b", "c"] if has_angles(robot) else []) + \
        [f"L{i + 1}" for i in range(robot.n_chains)]
    width = len(header) - 3
    junk = [["1", "C", "nan"] + ["warm-up"] * width, ["0", "C", ""] + [""] * width]
    rows = [junk[0], junk[0]]
    for k in range(ROWS):
        rows.append(["1", "V" if sets[k] == "validation" else "C", rec.extras["temperature_C"][k], *rec.measured[k],
                     *rec.joints[k]])
        if k in (2, 7):
            rows.append(junk[1])
        if k == 4:
            rows.append(junk[0])  # data row 9 or 10: dropped by number
    dropped = next(i + 1 for i, r in enumerate(rows) if i > 2 and r is junk[0])
    orientation = '[orientation]\nkind = "euler"\nsequence = "xyz"\nunit = "rad"\ncolumns = ["a", "b", "c"]\n'
    mapping = (robot_table(robot) + '[time]\nformat = "none"\n[position]\ncolumns = ["X", "Y", "Z"]\nunit = "mm"\n'
               + (orientation if has_angles(robot) else "")
               + f'[joints]\ncolumns = {toml_list(header[-robot.n_chains:])}\nreading = "value"\n'
                 f'[rows]\nfirst = 3\ndrop = [{dropped}]\nkeep_column = "valid"\n'
                 '[set]\ncolumn = "use"\ncalibration = "C"\nvalidation = "V"\n[extra]\ntemperature_C = "Temp (C)"\n')
    bounds = {"t_s": np.zeros(ROWS), "joints": np.zeros_like(rec.joints), "position": np.zeros((ROWS, 3))}
    return rec, mapping, {"lab.csv": lab_csv(header, rows)}, bounds


STYLES = {"metres, quaternion scalar last, revolutions": style_metres_quaternion_revolutions,
          "inches, matrix, counts, ISO time": style_inches_matrix_counts_iso,
          "mm, degrees XYZ Euler, ';' and decimal commas": style_mm_degrees_euler,
          "two files, two sessions": style_two_sessions,
          "temperature, sets, rows kept": style_extras_and_filter}


def export_and_convert(robot, style, tmp_path):
    """``(original, converted, bounds)`` of a lab style."""
    rec, mapping, files, bounds = STYLES[style](robot, tmp_path)
    (tmp_path / "map.toml").write_text(mapping)
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    result = run_convert(ConvertSettings(files=tuple(str(tmp_path / n) for n in files), map=str(tmp_path / "map.toml"),
                                         out=str(tmp_path / "out" / "converted")))
    assert result.warnings == (), result.warnings  # a right map is not suspected: nothing refused that fits
    return rec, result.recording, bounds


def round_trip_errors(rec: Recording, back: Recording, bounds: dict) -> dict:
    """Largest error of each quantity and its ratio to the bound (<= 1 within the bound)."""
    pairs = {"t_s": (back.t_s - rec.t_s, bounds["t_s"]), "joints": (back.joints - rec.joints, bounds["joints"]),
             "position": (back.measured[:, :3] - rec.measured[:, :3], bounds["position"])}
    if has_angles(rec.robot):
        pairs["angles"] = (back.measured[:, 3:] - rec.measured[:, 3:], angle_bound(rec, bounds.get("angles_middle")))
    for name, values in rec.extras.items():
        pairs[name] = (back.extras[name] - values, np.zeros_like(values))
    return {k: (float(np.max(np.abs(e))), float(np.max(np.abs(e) / np.where(b > 0, b, np.inf), initial=0.0))
                if np.all(np.abs(e) <= b) else math.inf) for k, (e, b) in pairs.items()}


@pytest.mark.parametrize("style", list(STYLES))
@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_a_recording_exported_in_a_lab_style_converts_back(name, style, tmp_path):
    robot = default_robot(name)
    rec, back, bounds = export_and_convert(robot, style, tmp_path)
    assert back.robot.name == name and back.robot.description() == robot.description()
    assert back.noise == rec.noise
    np.testing.assert_array_equal(back.sets, rec.sets)
    assert back.session_names == (rec.session_names if len(rec.session_names) > 1 else (DEFAULT_SESSION,))
    np.testing.assert_array_equal(back.sessions, rec.sessions)
    assert set(back.extras) == set(rec.extras)
    for session in back.session_names:
        assert session_measurement(back, session).frame == session_measurement(rec, session).frame
    errors = round_trip_errors(rec, back, bounds)
    assert all(ratio <= 1 for _, ratio in errors.values()), errors


def test_the_command_writes_a_recording_and_refuses_to_overwrite_it(tmp_path, capsys):
    robot = default_robot("hexapod")
    rec, mapping, files, _ = style_two_sessions(robot, tmp_path)
    (tmp_path / "map.toml").write_text(mapping)
    for n, text in files.items():
        (tmp_path / n).write_text(text)
    argv = [str(tmp_path / n) for n in files] + ["--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "rec")]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "hexapod, 24 rows in 2 session(s)" in out and "session summer: 12 of 12 rows" in out
    back = read_recording(tmp_path / "rec.csv")
    assert back.session_info["summer"]["source"].endswith("summer.csv")
    assert back.session_info["summer"]["measurement"] == {"frame": "estimate"}
    before = (tmp_path / "rec.csv").read_text()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "rec.csv exists; pass --overwrite" in err
    assert (tmp_path / "rec.csv").read_text() == before
    assert main(argv + ["--overwrite"]) == 0


def test_a_changed_geometry_comes_from_the_description_file(tmp_path):
    robot = default_robot("hexapod")
    description = dict(robot.description(), stroke_mm=60.0)
    rec, mapping, files, _ = style_metres_quaternion_revolutions(robot, tmp_path)
    (tmp_path / "geometry.json").write_text(json.dumps({"nominal_geometry": description, "robot": "hexapod"}))
    (tmp_path / "map.toml").write_text(mapping)
    (tmp_path / "lab.csv").write_text(files["lab.csv"])
    back = run_convert(ConvertSettings(files=(str(tmp_path / "lab.csv"),), map=str(tmp_path / "map.toml"),
                                       out=str(tmp_path / "r"))).recording
    assert back.robot.description()["stroke_mm"] == 60.0


def test_time_from_the_first_iso_timestamp_and_time_zones(tmp_path):
    robot = default_robot("delta")
    rec, mapping, files, _ = style_inches_matrix_counts_iso(robot, tmp_path)
    mapping = "\n".join(ln for ln in mapping.splitlines() if not ln.startswith("origin"))
    (tmp_path / "map.toml").write_text(mapping)
    (tmp_path / "lab.csv").write_text(files["lab.csv"].replace("+01:00", "Z"))
    back = run_convert(ConvertSettings(files=(str(tmp_path / "lab.csv"),), map=str(tmp_path / "map.toml"),
                                       out=str(tmp_path / "r"))).recording
    assert back.t_s[0] == 0.0
    assert np.max(np.abs(back.t_s - (rec.t_s - rec.t_s[0]))) <= 1e-6 + U * np.max(rec.t_s)
    assert back.session_info[DEFAULT_SESSION]["time_origin"].startswith("2024-03-01T09:30")


# --------------------------------------------------------------------------- refused maps and files


def _edit_map(old, new):
    def edit(tmp_path):
        p = tmp_path / "map.toml"
        text = p.read_text()
        assert old in text, old
        p.write_text(text.replace(old, new, 1))
    return edit


def _edit_lab(row, column, value, name="lab.csv", delimiter=","):
    def edit(tmp_path):
        p = tmp_path / name
        lines = p.read_text().splitlines()
        header = lines[0].split(delimiter)
        cells = lines[row].split(delimiter)
        cells[header.index(column)] = value
        lines[row] = delimiter.join(cells)
        p.write_text("\n".join(lines) + "\n")
    return edit


def _swap_lab_rows(a, b):
    def edit(tmp_path):
        p = tmp_path / "lab.csv"
        lines = p.read_text().splitlines()
        lines[a], lines[b] = lines[b], lines[a]
        p.write_text("\n".join(lines) + "\n")
    return edit


REFUSED = {
    "unknown key": (_edit_map('unit = "m"', 'units = "m"'), ["map.toml", "key position.units", "unknown key"]),
    "unknown table": (_edit_map("[time]", "[clock]\n[time]"), ["map.toml", "unknown table(s) [clock]"]),
    "unknown unit": (_edit_map('unit = "m"', 'unit = "ft"'), ["map.toml", "key position.unit", "'ft'"]),
    "missing key": (_edit_map('reading = "revolutions"', ""), ["map.toml", "key joints.reading", "missing"]),
    "not TOML": (_edit_map("[time]", "[time"), ["map.toml", "not valid TOML", "line"]),
    "scale count": (_edit_map("scale = [", "scale = [1.0, "), ["map.toml", "key joints.scale", "one per joint"]),
    "zero scale": (_edit_map("scale = [2.0", "scale = [0.0"), ["map.toml", "key joints.scale", "must not be 0"]),
    "robot unknown": (_edit_map('name = "hexapod"', 'name = "tripod"'), ["map.toml", "key robot.name"]),
    "description missing": (_edit_map('geometry.json', 'nowhere.json'), ["key robot.description", "nowhere.json",
                                                                         "not found"]),
    "scalar missing": (_edit_map('scalar = "last"\n', ""), ["key orientation.scalar", "'first', 'last'"]),
    "euler key on a quaternion": (_edit_map('scalar = "last"\n', 'scalar = "last"\nsequence = "xyz"\n'),
                                  ["key orientation.sequence", "no meaning with orientation.kind = 'quaternion'"]),
    "sessions for one file": (_edit_map("[joints]", '[sessions]\nnames = ["a", "b"]\n[joints]'),
                              ["map.toml", "key sessions.names", "lists 2 sessions for 1 files"]),
    "bad session name": (_edit_map("[joints]", '[sessions]\nnames = ["a b"]\n[joints]'),
                         ["key sessions.names", "'a b' is not a session name"]),
    "column missing": (_edit_map('"QW"]', '"Qw"]'), ["lab.csv: line 1", "no column 'Qw'", "key orientation.columns"]),
    "text cell": (_edit_lab(3, "Y", "abc"), ["lab.csv: row 3 (line 4), column 'Y'", "'abc' is not a number"]),
    "empty cell": (_edit_lab(5, "M4", ""), ["lab.csv: row 5 (line 6), column 'M4'", "not a number"]),
    "not a quaternion": (_edit_lab(2, "QW", "3.0"), ["lab.csv: row 2 (line 3), columns QX, QY, QZ, QW",
                                                     "quaternion of norm"]),
    "time backwards": (_swap_lab_rows(4, 5), ["lab.csv: row 5 (line 6), column 'Time'", "time goes backwards"]),
    "short row": (lambda p: (p / "lab.csv").write_text((p / "lab.csv").read_text().replace("\n", ",7\n", 3)
                                                       .replace(",7\n", "\n", 2)),
                  ["lab.csv: row 2 (line 3)", "expected 14 fields", "got 15"]),
    "lab file missing": (lambda p: (p / "lab.csv").unlink(), ["lab.csv", "not found"]),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_a_bad_map_or_lab_file_is_refused_in_one_line(case, tmp_path, capsys):
    robot = default_robot("hexapod")
    _, mapping, files, _ = style_metres_quaternion_revolutions(robot, tmp_path)
    (tmp_path / "map.toml").write_text(mapping)
    (tmp_path / "lab.csv").write_text(files["lab.csv"])
    edit, needles = REFUSED[case]
    edit(tmp_path)
    code = main([str(tmp_path / "lab.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, (needle, err)
    assert not (tmp_path / "r.csv").exists() and not (tmp_path / "r.json").exists()


@pytest.mark.parametrize("edit,needles", [
    (_edit_lab(4, "valid", "maybe"), ["lab.csv: row 4 (line 5), column 'valid'", "not 1/true/yes", "rows.keep_column"]),
    (_edit_lab(4, "use", "X"), ["lab.csv: row 4 (line 5), column 'use'", "'X' is neither 'C'", "set.calibration"]),
    (_edit_lab(5, "Temp (C)", "warm"), ["lab.csv: row 5 (line 6), column 'Temp (C)'", "'warm' is not a number"]),
    (_edit_map("first = 3", "first = 300"), ["lab.csv: key rows.first = 300", "data rows"]),
    (_edit_map('temperature_C = "Temp (C)"', 't_s = "Temp (C)"'), ["key extra.t_s", "one of the recording's own"]),
])
def test_rows_sets_and_channels_are_refused_by_row_and_column(edit, needles, tmp_path, capsys):
    robot = default_robot("hexapod")
    _, mapping, files, _ = style_extras_and_filter(robot, tmp_path)
    (tmp_path / "map.toml").write_text(mapping)
    (tmp_path / "lab.csv").write_text(files["lab.csv"])
    edit(tmp_path)
    code = main([str(tmp_path / "lab.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    for needle in needles:
        assert needle in err, (needle, err)


def test_an_orientation_for_the_delta_is_refused(tmp_path, capsys):
    robot = default_robot("delta")
    _, mapping, files, _ = style_extras_and_filter(robot, tmp_path)
    (tmp_path / "map.toml").write_text(mapping + '[orientation]\nkind = "euler"\nsequence = "xyz"\nunit = "rad"\n'
                                                 'columns = ["a", "b", "c"]\n')
    (tmp_path / "lab.csv").write_text(files["lab.csv"])
    assert main([str(tmp_path / "lab.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "r")]) == 2
    assert "key orientation: the delta's pose has no angles" in capsys.readouterr().err


# --------------------------------------------------------------------------- the recording format


def sessions_recording(robot=None) -> Recording:
    robot = robot or default_robot("hexapod")
    joints, measured = simulated(robot, 6, 9)
    return Recording(robot=robot, noise=NOISE, t_s=np.array([0.0, 1.0, 2.5, 0.0, 0.5, 0.5]), joints=joints,
                     measured=measured, sets=np.array(["calibration"] * 5 + ["validation"]),
                     sessions=np.array(["A", "A", "A", "B", "B", "B"]),
                     session_info={"B": {"measurement": {"frame": "estimate"}, "source": "b.csv"}},
                     extras={"temperature_C": np.linspace(20, 21, 6), "load_N": np.arange(6.0)})


def test_sessions_and_extra_channels_round_trip_exactly(tmp_path):
    rec = sessions_recording()
    csv_path, json_path = write_recording(tmp_path / "r.csv", rec)
    back = read_recording(csv_path)
    assert csv_path.read_text().splitlines()[0].endswith("gamma_rad,temperature_C,load_N,set,session")
    for f in ("t_s", "joints", "measured", "sets", "sessions"):
        np.testing.assert_array_equal(getattr(back, f), getattr(rec, f))
    assert set(back.extras) == {"temperature_C", "load_N"}
    for k, v in rec.extras.items():
        np.testing.assert_array_equal(back.extras[k], v)
    assert back.session_names == ("A", "B") and back.session_rows("B").tolist() == [3, 4, 5]
    assert back.session_info == {"A": {}, "B": {"measurement": {"frame": "estimate"}, "source": "b.csv"}}
    assert session_measurement(back, "B").frame == "estimate" and session_measurement(back, "A").frame == "auto"
    side = json.loads(json_path.read_text())
    assert side["sessions"] == {"A": {}, "B": {"measurement": {"frame": "estimate"}, "source": "b.csv"}}


def test_one_default_session_without_extras_writes_as_before():
    """No session column, no sessions field: the CSV header and sidecar of the format before sessions."""
    robot = default_robot("delta")
    joints, measured = simulated(robot, 3, 1)
    rec = Recording(robot=robot, noise=NOISE, t_s=np.arange(3.0), joints=joints, measured=measured,
                    sets=np.array(["calibration"] * 3))
    csv_text, json_text = recording_texts(rec)
    assert csv_text.splitlines()[0] == "t_s,q1_rad,q2_rad,q3_rad,x_mm,y_mm,z_mm,set"
    assert all(line.endswith(",calibration") for line in csv_text.splitlines()[1:])
    assert list(json.loads(json_text)) == ["format", "version", "robot", "units", "columns", "nominal_geometry",
                                           "parameter_table", "declared_noise", "meta"]
    assert rec.session_names == (DEFAULT_SESSION,)


def _rewrite(path, edit):
    lines = path.read_text().splitlines()
    edit(lines)
    path.write_text("\n".join(lines) + "\n")


def _side_edit(path, edit):
    side = json.loads(path.read_text())
    edit(side)
    path.write_text(json.dumps(side))


@pytest.mark.parametrize("edit,match", [
    (lambda c, j: _rewrite(c, lambda ls: ls.__setitem__(6, ls[6].replace(",B", ",A"))),
     r"row 6 \(line 7\), column 'session': session 'A' resumes after session 'B' \(its rows ended at row 3\)"),
    (lambda c, j: _rewrite(c, lambda ls: ls.__setitem__(6, ls[6].replace(",B", ",my session"))),
     r"row 6 \(line 7\), column 'session': 'my session' is not a session name"),
    (lambda c, j: _rewrite(c, lambda ls: ls.__setitem__(2, "9.0" + ls[2][ls[2].index(","):])),
     r"row 3 \(line 4\), column 't_s': time goes backwards"),
    (lambda c, j: _side_edit(j, lambda s: s["sessions"].update(C={})),
     r"r.json: field 'sessions' declares session\(s\) 'C' that no row of r.csv is in"),
    (lambda c, j: _side_edit(j, lambda s: s["sessions"]["B"].update(frame="estimate")),
     r"r.json: field sessions.B: unknown key\(s\) 'frame'"),
    (lambda c, j: _side_edit(j, lambda s: s["sessions"]["B"]["measurement"].update(frame="guess")),
     r"field sessions.B.measurement.frame must be one of auto, base, estimate"),
    (lambda c, j: _side_edit(j, lambda s: s["sessions"]["B"]["measurement"].update(targets=2)),
     r"field sessions.B.measurement: unknown key\(s\) 'targets'"),
    (lambda c, j: _side_edit(j, lambda s: s["columns"].append("pressure_hPa")),
     r"header lacks column\(s\) pressure_hPa"),
    (lambda c, j: _side_edit(j, lambda s: s["columns"].append("bad name")),
     r"field 'columns': 'bad name' is not a channel name"),
    (lambda c, j: _rewrite(c, lambda ls: ls.__setitem__(2, ls[2].replace(ls[2].split(",")[13], "hot", 1))),
     r"row 2 \(line 3\), column 'temperature_C': 'hot' is not a number"),
])
def test_bad_sessions_and_channels_name_file_row_and_column(edit, match, tmp_path):
    csv_path, json_path = write_recording(tmp_path / "r.csv", sessions_recording())
    edit(csv_path, json_path)
    with pytest.raises(RecordingError, match=match):
        read_recording(csv_path)



# --------------------------------------------------------------------------- a lab's two days (issue 37)

from pipeline.run import run as run_main  # noqa: E402

# docs/importer.md's two days: the capture's frame and offset, each day's mapping, the noise, as
# examples/make_examples.py makes them (one recipe for the page and the tests).
from examples.make_examples import (CAPTURE_FRAME, DAY_MAPPINGS, LAB_NOISE,  # noqa: E402
                                    write_two_days)


def two_days(tmp_path, *, map_edit=lambda m: m, n_cal: int = 40, n_val: int = 15):
    """docs/importer.md's two days (examples/make_examples.py's recipe): a hexapod with geometry
    errors up to 1.5 mm, measured on two days in one capture frame: ``grid.csv`` (calibration) and
    ``feb12.csv`` (validation only), each with its own revolutions-to-mm mapping, positions in
    metres less the capture's offset; the map declares the per-day mappings, the offset, the
    shared frame, the sets and a tolerance. Returns the map's path and the true geometry."""
    return write_two_days(tmp_path, n_cal=n_cal, n_val=n_val, map_edit=map_edit)


def convert_two_days(tmp_path, out="days"):
    return main([str(tmp_path / "grid.csv"), str(tmp_path / "feb12.csv"), "--map", str(tmp_path / "map.toml"),
                 "--out", str(tmp_path / out)])


def test_two_days_convert_with_their_own_mappings_offset_sets_frame_and_tolerance(tmp_path):
    _, actual = two_days(tmp_path)
    assert convert_two_days(tmp_path) == 0
    rec = read_recording(tmp_path / "days.csv")
    robot = rec.robot
    grid, feb12 = rec.session_rows("grid"), rec.session_rows("feb12")
    assert (rec.sets[grid] == "calibration").all() and (rec.sets[feb12] == "validation").all()
    assert rec.meta["parameter_tolerance"] == {"mm": 2.0, "rad": 0.02}
    assert rec.session_info["feb12"]["measurement"] == {"frame": "grid"}
    assert session_measurement(rec, "feb12").frame == "estimate"  # the frame of the session it names
    for name, rows in (("grid", grid), ("feb12", feb12)):  # each day's legs by its own mapping: the truth's
        poses = reachable_poses(robot, len(rows), 1 if name == "grid" else 2)
        truth = robot.inverse_kinematics(actual, poses)
        assert np.allclose(rec.joints[rows], truth, rtol=0, atol=1e-9 * np.abs(truth).max())
        seen = instrument_measurements(robot, poses, CAPTURE_FRAME)  # offset undone: within the noise
        assert np.abs(rec.measured[rows, :3] - seen[:, :3]).max() < 6 * LAB_NOISE.position_mm


def heldout_after(tmp_path, name) -> dict:
    s = run_main(["--real", str(tmp_path / f"{name}.csv"), "--out", str(tmp_path), "--name", f"{name}_cal",
                  "--quiet"]).summary
    return s


def test_a_validation_only_day_is_predicted_in_the_first_days_frame_to_the_noise(tmp_path):
    two_days(tmp_path)
    assert convert_two_days(tmp_path) == 0
    s = heldout_after(tmp_path, "days")
    held = s["heldout_position_error_mm"]
    # 3-D Gaussian noise of sigma per coordinate: the error norm's mean is 1.6 sigma; the fit's own
    # uncertainty at 40 poses adds less than that; 4 sqrt(3) sigma bounds both.
    bound = 4 * math.sqrt(3) * LAB_NOISE.position_mm
    assert held["after"] < bound < held["before"], held
    assert "measurement_frames" not in s  # one frame, shared: fitted once
    frames = json.loads((tmp_path / "days_cal.calibration.json").read_text())["measurement_frames"]
    assert frames["feb12"] == frames["grid"], frames  # compensate --session feb12 finds its frame


def test_a_wrong_mapping_for_the_second_day_spoils_its_held_out_figure(tmp_path):
    """The per-session mapping is applied: the second day read with the first day's mapping (its
    [sessions.feb12.joints] left out) predicts far worse."""
    two_days(tmp_path)
    assert convert_two_days(tmp_path) == 0
    right = heldout_after(tmp_path, "days")["heldout_position_error_mm"]["after"]
    text = (tmp_path / "map.toml").read_text()
    (tmp_path / "map.toml").write_text(text[:text.index("[sessions.feb12.joints]")])
    assert convert_two_days(tmp_path, "wrong") == 0
    wrong = heldout_after(tmp_path, "wrong")["heldout_position_error_mm"]["after"]
    assert wrong > 20 * right, (wrong, right)


def test_a_validation_only_day_with_a_frame_of_its_own_is_refused(tmp_path, capsys):
    two_days(tmp_path, map_edit=lambda m: m.replace('frame = ["estimate", "grid"]', 'frame = "estimate"'))
    assert convert_two_days(tmp_path) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "map.toml: key sessions.frame" in err and "'feb12'" in err, err


def test_the_run_names_a_lost_session_as_written(tmp_path):
    """A recording whose validation-only session has its own estimated frame: the run refuses it
    naming the session as written ('feb12', not numpy's repr)."""
    two_days(tmp_path)
    assert convert_two_days(tmp_path) == 0
    side = json.loads((tmp_path / "days.json").read_text())
    side["sessions"]["feb12"]["measurement"] = {"frame": "estimate"}
    (tmp_path / "days.json").write_text(json.dumps(side))
    with pytest.raises(ValueError, match=r"session 'feb12' has validation rows but no calibration rows"):
        heldout_after(tmp_path, "days")


TWO_DAY_REFUSALS = {
    "frame names no session": (('frame = ["estimate", "grid"]', 'frame = ["estimate", "june"]'),
                               ["key sessions.frame", "'june'", "neither"]),
    "frame names itself": (('frame = ["estimate", "grid"]', 'frame = ["grid", "grid"]'), ["key sessions.frame"]),
    "frame names a validation session": (('set = ["calibration", "validation"]', 'set = ["validation", "calibration"]'),
                                         ["key sessions.frame", "'grid'"]),
    "bad set": (('set = ["calibration", "validation"]', 'set = ["calibration", "held-out"]'),
                ["key sessions.set", "'held-out'"]),
    "set count": (('set = ["calibration", "validation"]', 'set = ["calibration"]'),
                  ["key sessions.set", "lists 1 sessions for 2 files"]),
    "set twice": (("[sessions]\n", '[set]\ncolumn = "X"\ncalibration = "c"\nvalidation = "v"\n[sessions]\n'),
                  ["key sessions.set", "[set]"]),
    "session table of no session": (("[sessions.feb12.joints]", "[sessions.march.joints]"),
                                    ["key sessions.march", "names no session"]),
    "session joints unknown key": (("[sessions.feb12.joints]\n", "[sessions.feb12.joints]\npitch = 2.0\n"),
                                   ["key sessions.feb12.joints.pitch", "unknown key"]),
    "session joints bad scale": (("[sessions.feb12.joints]\nscale = [", "[sessions.feb12.joints]\nscale = [0.0, "),
                                 ["key sessions.feb12.joints.scale"]),
    "session joints bad column": (("[sessions.feb12.joints]\n", '[sessions.feb12.joints]\ncolumns = ["a"]\n'),
                                  ["key sessions.feb12.joints.columns", "list of 6 column names"]),
    "session table not joints": (("[sessions.feb12.joints]", "[sessions.feb12.legs]"),
                                 ["key sessions.feb12", "[sessions.feb12.joints]"]),
    "offset count": (("offset = [", "offset = [1.0, "), ["key position.offset", "[x, y, z]"]),
    "offset text": (("offset = [", 'offset = ["a", '), ["key position.offset"]),
    "offset infinite": (("offset = [", "offset = [inf, 0.0, 0.0]\n#"), ["key position.offset", "finite"]),
    "tolerance a number": (("tolerance = {mm = 2.0, rad = 0.02}", "tolerance = 2.0"),
                           ["key robot.tolerance", "a table by unit"]),
    "tolerance unknown unit": (("tolerance = {mm = 2.0, rad = 0.02}", "tolerance = {cm = 0.2}"),
                               ["key robot.tolerance", "unknown key 'cm'", "nor a unit"]),
    "tolerance negative": (("tolerance = {mm = 2.0, rad = 0.02}", 'tolerance = {"B3.y" = -1.0}'),
                           ["key robot.tolerance.B3.y", "> 0"]),
    "tolerance text": (("tolerance = {mm = 2.0, rad = 0.02}", 'tolerance = {mm = "big"}'),
                       ["key robot.tolerance.mm", "finite number"]),
    "tolerance nan": (("tolerance = {mm = 2.0, rad = 0.02}", "tolerance = {mm = nan}"),
                      ["key robot.tolerance.mm", "finite number"]),
}


@pytest.mark.parametrize("case", list(TWO_DAY_REFUSALS))
def test_hostile_two_day_map_keys_are_refused_in_one_line(case, tmp_path, capsys):
    (old, new), needles = TWO_DAY_REFUSALS[case]
    assert old in two_days(tmp_path, n_cal=8, n_val=4)[0].read_text()
    two_days(tmp_path, map_edit=lambda m: m.replace(old, new, 1), n_cal=8, n_val=4)
    assert convert_two_days(tmp_path) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and str(tmp_path / "map.toml") in err, err
    for needle in needles:
        assert needle in err, (needle, err)
    assert not (tmp_path / "days.csv").exists()


def test_compensate_writes_the_commands_in_each_days_revolutions(tmp_path, capsys):
    """``pipeline.compensate --map``: the commands again in the map's readings, by the session's own
    mapping; read back through the mapping they are the mm commands (a few roundings: 4u relative)."""
    from pipeline.compensate import main as compensate_main

    two_days(tmp_path)
    assert convert_two_days(tmp_path) == 0
    heldout_after(tmp_path, "days")
    names = ["x_mm", "y_mm", "z_mm", "alpha_rad", "beta_rad", "gamma_rad"]
    targets = reachable_poses(default_robot("hexapod"), 5, 9)
    (tmp_path / "targets.csv").write_text(",".join(names) + "\n" + "".join(
        ",".join(repr(float(v)) for v in p) + "\n" for p in targets))
    base = ["--calibration", str(tmp_path / "days_cal.calibration.json"), "--targets", str(tmp_path / "targets.csv"),
            "--map", str(tmp_path / "map.toml")]
    revs = [f"rev{i + 1}" for i in range(6)]
    for session, extra in (("grid", []), ("feb12", ["--session", "feb12"])):
        out = tmp_path / f"cmd_{session}.csv"
        assert compensate_main(base + ["--out", str(out)] + extra) == 0
        header, *rows = [line.split(",") for line in out.read_text().splitlines()]
        table = np.array(rows, dtype=float)
        mm = table[:, [header.index(f"l{i + 1}_mm") for i in range(6)]]
        rev = table[:, [header.index(c) for c in revs]]
        scale, zero = DAY_MAPPINGS[session]
        assert np.allclose(zero + scale * rev, mm, rtol=8 * U, atol=0), session
        side = json.loads(out.with_suffix(".json").read_text())["controller_readings"]
        assert side["reading"] == "revolutions" and side["columns"] == revs and np.allclose(side["scale"], scale)
    assert not np.allclose(np.loadtxt(tmp_path / "cmd_grid.csv", delimiter=",", skiprows=1)[:, -6:],
                           np.loadtxt(tmp_path / "cmd_feb12.csv", delimiter=",", skiprows=1)[:, -6:])
    capsys.readouterr()
    assert compensate_main(base + ["--out", str(tmp_path / "c.csv"), "--session", "march"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--session march" in err and "not a session" in err, err


# --------------------------------------------------------------------------- the map checked on evidence

#: A map key written wrong for the lab's file: (lab style, the key as the style writes it (right),
#: as a lab might write it (wrong), the key, its wrong value, the value that fits, which robots).
MAP_MISTAKES = {
    "positions in mm declared m": (style_mm_degrees_euler, 'unit = "mm"', 'unit = "m"', "position.unit", "m", "mm",
                                   "all"),
    "positions in m declared mm": (style_metres_quaternion_revolutions, 'unit = "m"', 'unit = "mm"', "position.unit",
                                   "mm", "m", "all"),
    "positions in inches declared mm": (style_inches_matrix_counts_iso, 'unit = "in"', 'unit = "mm"',
                                        "position.unit", "mm", "in", "all"),
    "leg lengths in m declared mm": (style_inches_matrix_counts_iso, 'reading = "counts"\nunit = "m"',
                                     'reading = "counts"\nunit = "mm"', "joints.unit", "mm", "m", "length joints"),
    "motor angles in deg declared rad": (style_inches_matrix_counts_iso, 'reading = "counts"\nunit = "deg"',
                                         'reading = "counts"\nunit = "rad"', "joints.unit", "rad", "deg",
                                         "angle joints"),
    "Euler angles in deg declared rad": (style_mm_degrees_euler, 'unit = "deg"\ncolumns', 'unit = "rad"\ncolumns',
                                         "orientation.unit", "rad", "deg", "angles"),
    "quaternion scalar last declared first": (style_metres_quaternion_revolutions, 'scalar = "last"',
                                              'scalar = "first"', "orientation.scalar", "first", "last", "angles"),
    "quaternion conjugate": (style_metres_quaternion_revolutions, 'scalar = "last"',
                             'scalar = "last"\nrotation = "instrument_to_platform"', "orientation.rotation",
                             "instrument_to_platform", "platform_to_instrument", "angles"),
    "quaternion columns x and y swapped": (style_metres_quaternion_revolutions, '["QX", "QY", "QZ", "QW"]',
                                           '["QY", "QX", "QZ", "QW"]', "orientation.columns",
                                           ["QY", "QX", "QZ", "QW"], ["QX", "QY", "QZ", "QW"], "angles"),
}


def _applies(robot, which: str) -> bool:
    return {"all": True, "angles": has_angles(robot), "length joints": robot.joint_unit == "mm",
            "angle joints": robot.joint_unit == "rad"}[which]


@pytest.mark.parametrize("case,name", [(c, n) for c in MAP_MISTAKES for n in sorted(ROBOTS)
                                       if _applies(default_robot(n), MAP_MISTAKES[c][-1])])
def test_a_map_key_the_data_prove_wrong_is_refused_by_name(case, name, tmp_path, capsys):
    """The lab's files written independently (SciPy's rotations, units by definition), the map
    with one key wrong: exit 2, one line naming the map, the key as written, the value that fits
    and both fits' figures; nothing written."""
    style, right, wrong, key, as_written, fits, _ = MAP_MISTAKES[case]
    _, mapping, files, _ = style(default_robot(name), tmp_path)
    assert right in mapping
    (tmp_path / "map.toml").write_text(mapping.replace(right, wrong, 1))
    for n, text in files.items():
        (tmp_path / n).write_text(text)
    code = main([str(tmp_path / n) for n in files] + ["--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    for needle in (f"{tmp_path / 'map.toml'}: key {key} = {as_written!r}", "as the map reads them the data",
                   f"as {fits!r} they fit to RMS", "chi-square", f"did you mean {key} = {fits!r}?"):
        assert needle in err, (needle, err)
    assert not (tmp_path / "r.csv").exists() and not (tmp_path / "r.json").exists()


def test_a_unit_key_is_named_with_where_it_puts_the_platform(tmp_path, capsys):
    """The issue's case: mm declared as metres puts the hexapod's platform some 200 m from the
    base, 1000 times where its joints put it."""
    _, mapping, files, _ = style_mm_degrees_euler(default_robot("hexapod"), tmp_path)
    (tmp_path / "map.toml").write_text(mapping.replace('unit = "mm"', 'unit = "m"', 1))
    (tmp_path / "lab.csv").write_text(files["lab.csv"])
    assert main([str(tmp_path / "lab.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    median = float(err.split("puts the platform a median ")[1].split(" m from the base")[0])
    near = float(err.split("(the joints put it ")[1].split(" mm)")[0])
    assert median == pytest.approx(near, rel=1e-2) and 100 < median < 1000, err


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_too_few_rows_to_judge_the_map_are_converted_with_a_warning(name, tmp_path, capsys):
    """Rows too few for a fit of the geometry and frame: the evidence is weak, the map's units are
    not refused (nothing that may fit is), the warning gives the figures."""
    robot = default_robot(name)
    _, mapping, files, _ = style_mm_degrees_euler(robot, tmp_path)
    keep = len(robot.free_default) // robot.pose_dim - 1  # fewer pose values than the geometry's unknowns
    lines = files["lab.csv"].splitlines(keepends=True)
    (tmp_path / "map.toml").write_text(mapping)
    (tmp_path / "lab.csv").write_text("".join(lines[:3 + keep]))  # preamble, header, rows
    assert main([str(tmp_path / "lab.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{keep} rows ({keep * robot.pose_dim} pose values) are too few" in err, err
    assert "rows to identify" in err and "converted as written" in err and (tmp_path / "r.csv").exists()


# --------------------------------------------------------------------------- streamed in chunks, judged on a subsample

def _convert_files(tmp_path, files, mapping, out) -> tuple[int, str, str]:
    """``(exit status, stdout, stderr)`` of the command on the files written in ``tmp_path``."""
    import contextlib
    import io

    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main([str(tmp_path / n) for n in files]
                    + ["--map", str(tmp_path / mapping), "--out", str(tmp_path / out)])
    return code, stdout.getvalue(), stderr.getvalue()


@pytest.mark.parametrize("style", ["inches, matrix, counts, ISO time", "two files, two sessions",
                                   "temperature, sets, rows kept"])
def test_chunks_of_any_size_write_the_same_recording(style, tmp_path, monkeypatch):
    """The files converted 1 and 5 rows at a time (ISO origin, time order, rows kept and dropped,
    sets and sessions carried across chunks): the same CSV and sidecar, byte for byte."""
    from pipeline.formats import lab_export

    _, mapping, files, _ = STYLES[style](default_robot("hexapod"), tmp_path)
    (tmp_path / "map.toml").write_text(mapping)
    for n, text in files.items():
        (tmp_path / n).write_text(text)
    assert _convert_files(tmp_path, files, "map.toml", "whole")[0] == 0
    for rows in (1, 5):
        monkeypatch.setattr(lab_export, "CHUNK_ROWS", rows)
        assert _convert_files(tmp_path, files, "map.toml", f"by{rows}")[0] == 0
        for ext in ("csv", "json"):
            assert (tmp_path / f"by{rows}.{ext}").read_bytes() == (tmp_path / f"whole.{ext}").read_bytes(), (rows, ext)


@pytest.mark.parametrize("case", ["text cell", "empty cell", "not a quaternion", "time backwards", "short row"])
def test_a_fault_is_named_alike_whatever_the_chunk(case, tmp_path, monkeypatch):
    """A lab file's fault met in a chunk of one row (time going back from the previous chunk's
    row): the same line as in one chunk."""
    from pipeline.formats import lab_export

    _, mapping, files, _ = style_metres_quaternion_revolutions(default_robot("hexapod"), tmp_path)
    (tmp_path / "map.toml").write_text(mapping)
    (tmp_path / "lab.csv").write_text(files["lab.csv"])
    REFUSED[case][0](tmp_path)
    code, _, whole = _convert_files(tmp_path, files, "map.toml", "r")
    monkeypatch.setattr(lab_export, "CHUNK_ROWS", 1)
    assert (code, whole) == _convert_files(tmp_path, files, "map.toml", "r")[::2] and code == 2


@pytest.mark.slow
def test_the_map_is_judged_on_a_seeded_subsample_said_in_the_output(tmp_path, monkeypatch):
    """500 rows, the checks' subsample 300 (seed 0): they judge 300 drawn, and say so; a wrong
    unit is refused on them as on every row, the refusal saying which rows it judged; the draw is
    the same however the file is chunked (the refusal's figures, of the rows drawn, too)."""
    from pipeline.formats import lab_export

    rows, drawn = 500, 300
    monkeypatch.setattr(lab_export, "CHECK_ROWS", drawn)
    lab, mapping = write_motion_capture_export(tmp_path, rows)
    code, out, err = _convert_files(tmp_path, [lab.name], mapping.name, "r")
    assert code == 0 and err == "", err
    assert f"map checked on evidence on a seeded subsample (seed 0) of {drawn} of the {rows} rows" in out, out
    (tmp_path / "wrong.toml").write_text(mapping.read_text().replace('unit = "m"', 'unit = "mm"', 1))
    code, _, err = _convert_files(tmp_path, [lab.name], "wrong.toml", "w")
    assert code == 2 and err.count("\n") == 1, err
    for needle in ("key position.unit = 'mm'", "did you mean position.unit = 'm'?",
                   f"(judged on a seeded subsample of {drawn} of the {rows} rows)"):
        assert needle in err, (needle, err)
    monkeypatch.setattr(lab_export, "CHUNK_ROWS", 70)
    assert _convert_files(tmp_path, [lab.name], "wrong.toml", "w") == (code, "", err)


def test_every_session_and_set_is_in_the_subsample(tmp_path, monkeypatch):
    """A subsample of 10 rows of the two days (40 calibration rows, 15 validation rows of another
    session): each (session, set) keeps at least CHECK_ROWS_PER_GROUP rows (or all), so that the
    second day, which names the first's frame, is judged in it."""
    from pipeline.formats import lab_export

    two_days(tmp_path)
    monkeypatch.setattr(lab_export, "CHECK_ROWS", 10)
    code, out, err = _convert_files(tmp_path, ["grid.csv", "feb12.csv"], "map.toml", "days")
    floor = lab_export.CHECK_ROWS_PER_GROUP
    assert code == 0, err
    assert f"a seeded subsample (seed 0) of {min(40, floor) + min(15, floor)} of the 55 rows" in out, out
