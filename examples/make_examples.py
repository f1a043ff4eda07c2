"""Make the example inputs the README and docs/ run their commands on (seeded: the same files every time).

    python examples/make_examples.py          # from the repository root; rewrites examples/*

Writes, beside this script:

- ``capture.csv``, ``stewart.toml``, ``targets.csv``: the README's loop. The lab's file is simulated:
  a MuJoCo hexapod with the paper's geometric errors and a 5 um dead band in every leg
  (``python -m pipeline.run --poses 60 --heldout 20 --friction 1.0 --seed 3 --name machine``), its
  recording rewritten as a motion-capture export (metres, quaternions scalar last, motor
  revolutions, a ``Phase`` column marking the 20 check poses); ``stewart.toml`` is its map and
  ``targets.csv`` five base-frame poses to command.
- ``table4.csv`` (+ ``.json``): the hexapod paper's Table 4 as a recording, with 50 noise-free
  validation rows from the Table 3 machine (docs/real_data.md; ``tests/test_run.py``'s recipe).
- ``two_days/grid.csv``, ``two_days/feb12.csv``, ``two_days/map.toml``: docs/importer.md's two days
  in one capture frame (a hexapod with geometry errors up to 1.5 mm; the second day's
  revolutions-to-mm constants changed, its poses validation only), the generator of
  ``tests/test_convert.py``'s ``two_days``.

- ``stewart/``: docs/importer.md's Example 1, a hobby Stewart platform captured in two sessions
  (``capture_march.csv``, ``capture_june.csv``: metres, quaternions scalar last, motor
  revolutions; the capture frame moved 45 mm and 0.6 degrees in between) and its map.
- ``delta_tracker/``: its Example 2, a Delta read by encoder counts and a laser tracker in inches
  (``delta_tracker.csv``: ``;`` and decimal commas after two preamble lines, ISO timestamps, a row
  where the tracker lost the reflector, three validation rows, the motor temperature), its map
  ``delta.toml`` and the broken copies the page's refusals read (``bad.toml``, ``bad2.toml``, ``bad.csv``).
- ``klipper/printer.cfg``: docs/klipper.md's worked example, a linear Delta printer's Klipper config
  after DELTA_CALIBRATE on the MuJoCo printer (``make_klipper_example.py``, which writes it alone too).

Every number comes from the product's own code (``pipeline.run`` simulates, ``calib`` draws the poses).
"""
from __future__ import annotations

import contextlib
import io
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from calib import paper
from calib.measurement import instrument_measurements
from calib.noise import SensorNoise
from calib.robots import default_robot, paper_hexapod
from calib.workspace import reachable_poses
from pipeline.formats import Recording, read_recording, write_recording
from pipeline.run import main as run_main

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_klipper_example import write_klipper_example  # noqa: E402

#: The folder the examples are written to: this script's.
EXAMPLES = Path(__file__).resolve().parent
MM_PER_M = 1000.0
#: The simulated lab machine of the README's loop (``pipeline.run``'s arguments).
LAB_RUN = ["--poses", "60", "--heldout", "20", "--friction", "1.0", "--seed", "3", "--name", "machine"]
#: The lab's motor mapping: leg length (mm) = zero + scale * revolutions, per leg.
MOTOR_SCALE_MM = [1.998, 2.003, 2.0, 1.997, 2.001, 2.002]
MOTOR_ZERO_MM = [183.2, 183.3, 183.1, 183.25, 183.2, 183.15]
#: The ``Phase`` column's words for the calibration and the check (validation) rows.
PHASES = {"calibration": "cal", "validation": "check"}
CAPTURE_HEADER = (["Frame", "Time", "Pos X", "Pos Y", "Pos Z", "Rot X", "Rot Y", "Rot Z", "Rot W"]
                  + [f"motor{i + 1}" for i in range(6)] + ["Phase"])
#: Seed and number of the poses ``targets.csv`` holds.
TARGETS_SEED, TARGETS = 11, 5

#: docs/importer.md's two days: the capture's frame (mm, rad), its position offset (mm), each day's
#: revolutions-to-mm mapping (mm per revolution, length at zero revolutions) and the capture noise.
CAPTURE_FRAME = np.array([30.0, -20.0, 15.0, 0.01, -0.02, 0.3])
CAPTURE_OFFSET = np.array([1.5, -2.0, 574.3])
DAY_MAPPINGS = {"grid": ([2.0, 2.01, 2.02, 2.03, 2.04, 2.05], [180.0, 181.0, 182.0, 183.0, 184.0, 185.0]),
                "feb12": ([2.02, 2.0301, 2.0402, 2.0503, 2.0604, 2.0705], [181.5, 182.5, 183.5, 184.5, 185.5, 186.5])}
DAYS = (("grid", 40, 1), ("feb12", 15, 2))
LAB_NOISE = SensorNoise(0.01, 1e-4, "normal", 0.0)


def toml_list(values) -> str:
    return "[" + ", ".join(repr(float(v)) if not isinstance(v, str) else f'"{v}"' for v in values) + "]"


def csv_text(header, rows) -> str:
    return "\n".join([",".join(header)] + [",".join(c if isinstance(c, str) else repr(float(c)) for c in row)
                                           for row in rows]) + "\n"


def stewart_map(noise: dict) -> str:
    """The README's map: metres, quaternions scalar last, motor revolutions, the ``Phase`` column."""
    return ("# The README's lab: motion capture in metres, quaternions scalar last, legs as motor revolutions.\n"
            '[robot]\nname = "hexapod"\n\n'
            f'[noise]\nposition_mm = {noise["position_mm"]}\norientation_rad = {noise["orientation_rad"]}\n'
            f'distribution = "{noise["distribution"]}"\n\n'
            '[time]\nformat = "seconds"\ncolumn = "Time"\n\n'
            '[position]\ncolumns = ["Pos X", "Pos Y", "Pos Z"]\nunit = "m"\n\n'
            '[orientation]\nkind = "quaternion"\nscalar = "last"\ncolumns = ["Rot X", "Rot Y", "Rot Z", "Rot W"]\n\n'
            f'[joints]\ncolumns = {toml_list(CAPTURE_HEADER[9:15])}\nreading = "revolutions"\nunit = "mm"\n'
            f'scale = {toml_list(MOTOR_SCALE_MM)}\nzero = {toml_list(MOTOR_ZERO_MM)}\n\n'
            f'[set]\ncolumn = "Phase"\ncalibration = "{PHASES["calibration"]}"\n'
            f'validation = "{PHASES["validation"]}"\n')


def write_readme_loop(folder: Path) -> None:
    """``capture.csv``, ``stewart.toml`` and ``targets.csv`` of the README's loop."""
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()), \
            contextlib.redirect_stderr(io.StringIO()):
        if run_main(LAB_RUN + ["--out", tmp]) != 0:
            sys.exit("the simulated lab run failed")
        rec = read_recording(Path(tmp) / "machine.csv")
    quaternions = Rotation.from_euler("xyz", rec.measured[:, 3:]).as_quat()  # x, y, z, w
    revolutions = (rec.joints - np.array(MOTOR_ZERO_MM)) / np.array(MOTOR_SCALE_MM)
    rows = [[str(k + 1), rec.t_s[k], *(rec.measured[k, :3] / MM_PER_M), *quaternions[k], *revolutions[k],
             PHASES[rec.sets[k]]] for k in range(len(rec.t_s))]
    (folder / "capture.csv").write_text(csv_text(CAPTURE_HEADER, rows))
    noise = rec.noise
    (folder / "stewart.toml").write_text(stewart_map({"position_mm": noise.position_mm,
                                                      "orientation_rad": noise.orientation_rad,
                                                      "distribution": noise.distribution}))
    targets = reachable_poses(default_robot("hexapod"), TARGETS, TARGETS_SEED)
    (folder / "targets.csv").write_text(csv_text(["x_mm", "y_mm", "z_mm", "alpha_rad", "beta_rad", "gamma_rad"],
                                                 targets))


def two_days_map() -> str:
    """docs/importer.md's map of the two days (printed there as it is here)."""
    grid, feb12 = DAY_MAPPINGS["grid"], DAY_MAPPINGS["feb12"]
    return ('[robot]\nname = "hexapod"\ntolerance = {mm = 2.0, rad = 0.02}\n'
            f'[noise]\nposition_mm = {LAB_NOISE.position_mm}\norientation_rad = {LAB_NOISE.orientation_rad}\n'
            'distribution = "normal"\n[time]\nformat = "none"\n'
            f'[position]\ncolumns = ["X", "Y", "Z"]\nunit = "m"\noffset = {toml_list(CAPTURE_OFFSET)}\n'
            '[orientation]\nkind = "quaternion"\nscalar = "last"\ncolumns = ["QX", "QY", "QZ", "QW"]\n'
            f'[joints]\ncolumns = {toml_list([f"rev{i + 1}" for i in range(6)])}\nreading = "revolutions"\n'
            f'unit = "mm"\nscale = {toml_list(grid[0])}\nzero = {toml_list(grid[1])}\n'
            '[sessions]\nnames = ["grid", "feb12"]\nframe = ["estimate", "grid"]\nset = ["calibration", "validation"]\n'
            f'[sessions.feb12.joints]\nscale = {toml_list(feb12[0])}\nzero = {toml_list(feb12[1])}\n')


def write_two_days(folder: Path, *, n_cal: int = DAYS[0][1], n_val: int = DAYS[1][1],
                   map_edit=lambda m: m) -> tuple[Path, np.ndarray]:
    """``grid.csv`` (calibration, ``n_cal`` rows), ``feb12.csv`` (validation only, ``n_val``) and
    ``map.toml`` (edited by ``map_edit``: tests/test_convert.py's mistakes); returns the map's path
    and the machine's true geometry (a hexapod with errors up to 1.5 mm, by hand)."""
    folder.mkdir(exist_ok=True)
    robot = default_robot("hexapod")
    rng = np.random.default_rng(37)
    actual = robot.table.nominal + rng.uniform(-1.5, 1.5, robot.n_parameters)  # mm errors, by hand
    header = ["X", "Y", "Z", "QX", "QY", "QZ", "QW"] + [f"rev{i + 1}" for i in range(6)]
    for (name, _, seed), n in zip(DAYS, (n_cal, n_val)):
        poses = reachable_poses(robot, n, seed)
        joints = robot.inverse_kinematics(actual, poses)  # the legs the machine really had
        seen = instrument_measurements(robot, poses, CAPTURE_FRAME)
        seen[:, :3] += rng.normal(0.0, LAB_NOISE.position_mm, (n, 3))
        seen[:, 3:] += rng.normal(0.0, LAB_NOISE.orientation_rad, (n, 3))
        scale, zero = DAY_MAPPINGS[name]
        rows = [[*((seen[k, :3] - CAPTURE_OFFSET) / MM_PER_M), *Rotation.from_euler("xyz", seen[k, 3:]).as_quat(),
                 *((joints[k] - np.array(zero)) / np.array(scale))] for k in range(n)]
        (folder / f"{name}.csv").write_text(csv_text(header, rows))
    (folder / "map.toml").write_text(map_edit(two_days_map()))
    return folder / "map.toml", actual


#: Example 1's map, as docs/importer.md prints it.
STEWART_TWO_SESSIONS_MAP = """# A hobby Stewart platform: motor revolutions per leg, poses from motion capture.
[robot]
name = "hexapod"                     # the registered hexapod's nominal geometry
# description = "my_platform.json"   # or its own: a Robot.description() JSON

[noise]
position_mm = 0.1                    # the capture system's noise (standard deviation)
orientation_rad = 0.001
distribution = "normal"

[time]
format = "seconds"
column = "Time"

[position]
columns = ["Pos X", "Pos Y", "Pos Z"]
unit = "m"

[orientation]
kind = "quaternion"
scalar = "last"                      # Rot X, Rot Y, Rot Z, Rot W
columns = ["Rot X", "Rot Y", "Rot Z", "Rot W"]

[joints]
columns = ["motor1", "motor2", "motor3", "motor4", "motor5", "motor6"]
reading = "revolutions"
unit = "mm"                          # scale in mm per revolution, zero in mm
scale = [1.998, 2.003, 2.0, 1.997, 2.001, 2.002]
zero = [183.2, 183.3, 183.1, 183.25, 183.2, 183.15]   # leg length at 0 revolutions

[sessions]                           # one per file, in the order given
names = ["march", "june"]
frame = "estimate"                   # the capture frame moved between them: one frame each
"""
#: Example 1: the capture frame of March (mm, rad) and how it moved by June (45 mm, 0.6 degrees).
MARCH_FRAME = np.array([2.0, -1.5, 0.5, 0.002, -0.001, 0.003])
JUNE_MOVE = np.array([45.0, 0.0, 0.0, 0.0, 0.0, np.deg2rad(0.6)])
STEWART_NOISE = SensorNoise(0.1, 0.001, "normal", 0.0)
STEWART_SCALE = [1.998, 2.003, 2.0, 1.997, 2.001, 2.002]
STEWART_ZERO = [183.2, 183.3, 183.1, 183.25, 183.2, 183.15]
STEWART_HEADER = (["Frame", "Time", "Pos X", "Pos Y", "Pos Z", "Rot X", "Rot Y", "Rot Z", "Rot W"]
                  + [f"motor{i + 1}" for i in range(6)])


def write_stewart(folder: Path) -> None:
    """Example 1: ``capture_march.csv``, ``capture_june.csv`` (20 poses each, 1.5 s apart) and ``stewart.toml``."""
    folder.mkdir(exist_ok=True)
    robot = default_robot("hexapod")
    rng = np.random.default_rng(41)
    for name, frame, seed in (("march", MARCH_FRAME, 1), ("june", MARCH_FRAME + JUNE_MOVE, 2)):
        poses = reachable_poses(robot, 20, seed)
        legs = robot.inverse_kinematics(robot.table.nominal, poses)
        seen = instrument_measurements(robot, poses, frame) + STEWART_NOISE.sample(20, rng, robot.pose_units)
        quaternions = Rotation.from_euler("xyz", seen[:, 3:]).as_quat()
        revolutions = (legs - np.array(STEWART_ZERO)) / np.array(STEWART_SCALE)
        rows = [[str(k + 1), f"{1.5 * k:.3f}", *(f"{v:.7f}" for v in seen[k, :3] / MM_PER_M),
                 *(f"{v:.7f}" for v in quaternions[k]), *(f"{v:.5f}" for v in revolutions[k])] for k in range(20)]
        (folder / f"capture_{name}.csv").write_text(csv_text(STEWART_HEADER, rows))
    (folder / "stewart.toml").write_text(STEWART_TWO_SESSIONS_MAP)


#: Example 2's map, as docs/importer.md prints it.
DELTA_MAP = """# A Delta robot: encoder counts, a laser tracker in inches, ISO timestamps, a motor temperature.
[robot]
name = "delta"

[noise]
position_mm = 0.02
distribution = "normal"

[csv]
delimiter = ";"
decimal = ","                        # 21,4 is 21.4
skip_lines = 2                       # the tracker's two preamble lines

[time]
format = "iso"
column = "timestamp"                 # t_s from the first kept row (or give origin = "...")

[position]
columns = ["X [in]", "Y [in]", "Z [in]"]
unit = "in"

[joints]
columns = ["enc_A", "enc_B", "enc_C"]
reading = "counts"
unit = "deg"                         # scale in degrees per count, zero in degrees
scale = 0.00274658203125             # 360 / 131072
zero = -90.0

[rows]
keep_column = "tracker_ok"           # 0: the tracker lost the reflector; the row is left out

[set]
column = "phase"
calibration = "cal"
validation = "val"

[extra]
temperature_C = "T_motor [C]"

[sessions]
frame = "base"                       # the tracker was registered to the robot's base
"""
DELTA_NOISE = SensorNoise(0.02, 0.0, "normal", 0.0)
DEG_PER_COUNT = 360.0 / 131072
DELTA_HEADER = ["timestamp", "tracker_ok", "phase", "X [in]", "Y [in]", "Z [in]", "enc_A", "enc_B", "enc_C", "T_motor [C]"]
#: Example 2's rows: seconds after 08:00:00, the phase, the tracker flag (the last row lost).
DELTA_SECONDS = [0, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30, 32, 34]
DELTA_PHASES = ["cal"] * 13 + ["val"] * 3 + ["cal"]


def decimal_comma(value: float, digits: int) -> str:
    return f"{value:.{digits}f}".replace(".", ",")


def write_delta_tracker(folder: Path) -> None:
    """Example 2: ``delta_tracker.csv``, ``delta.toml`` and the refusals' ``bad.toml``, ``bad2.toml``, ``bad.csv``."""
    folder.mkdir(exist_ok=True)
    robot = default_robot("delta")
    rng = np.random.default_rng(43)
    n = len(DELTA_SECONDS)
    poses = reachable_poses(robot, n, 3)
    joints_deg = np.rad2deg(robot.inverse_kinematics(robot.table.nominal, poses))
    seen = poses + DELTA_NOISE.sample(n, rng, robot.pose_units)
    counts = np.rint((joints_deg + 90.0) / DEG_PER_COUNT).astype(int)
    lines = ["Tracker export v2.1", "units: inch, counts", ";".join(DELTA_HEADER)]
    for k in range(n):
        lost = k == n - 1
        cells = ([""] * 3 + ["0"] * 3) if lost else ([decimal_comma(v / 25.4, 6) for v in seen[k]]
                                                     + [str(c) for c in counts[k]])
        lines.append(";".join([f"2024-05-14T08:00:{DELTA_SECONDS[k]:02d}.000", "0" if lost else "1",
                               DELTA_PHASES[k], *cells, decimal_comma(21.0 + 0.2 * k, 1)]))
    tracker = "\n".join(lines) + "\n"
    (folder / "delta_tracker.csv").write_text(tracker)
    (folder / "delta.toml").write_text(DELTA_MAP)
    (folder / "bad.toml").write_text(DELTA_MAP.replace('unit = "in"', 'unit = "inch"'))
    (folder / "bad2.toml").write_text(DELTA_MAP.replace('"enc_C"]', '"enc_c"]'))
    row3 = lines[5].split(";")
    row3[3] = row3[3][:-2] + "x" + row3[3][-1]  # a typing slip in row 3's X cell
    (folder / "bad.csv").write_text(tracker.replace(lines[5], ";".join(row3)))


def write_table4(folder: Path, heldout: int = 50, seed: int = 1) -> None:
    """``table4.csv``: the hexapod paper's Table 4 as a recording (docs/real_data.md): the printed
    measured poses at the paper's commanded leg lengths (the nominal inverse kinematics of its target
    poses) and, since the paper gives no validation poses, ``heldout`` validation rows simulated
    noise-free from the Table 3 machine; declared noise the paper's 1 um on positions and 1e-5 rad
    on angles (the print resolution of Table 4's angles)."""
    robot = paper_hexapod()
    nominal = robot.table.nominal
    targets = reachable_poses(robot, heldout, np.random.default_rng(seed))
    val_joints = robot.inverse_kinematics(nominal, targets)
    val_meas = robot.forward_kinematics(nominal + paper.TABLE3_ERRORS.ravel(), val_joints, initial=targets)
    n = 10 + heldout
    rec = Recording(robot=robot, noise=SensorNoise(paper.PAPER_NOISE_MM, 1e-5), t_s=np.arange(n, dtype=float),
                    joints=np.vstack([robot.inverse_kinematics(nominal, paper.TABLE4_NOMINAL_POSES), val_joints]),
                    measured=np.vstack([paper.TABLE4_MEASURED_POSES, val_meas]),
                    sets=np.array(["calibration"] * 10 + ["validation"] * heldout),
                    meta={"scenario": "the hexapod paper's Table 4 (printed poses) + noise-free validation rows"})
    write_recording(folder / "table4.csv", rec, overwrite=True)


def main() -> int:
    write_table4(EXAMPLES)
    write_readme_loop(EXAMPLES)
    write_two_days(EXAMPLES / "two_days")
    write_stewart(EXAMPLES / "stewart")
    write_delta_tracker(EXAMPLES / "delta_tracker")
    write_klipper_example(EXAMPLES / "klipper")
    return 0


if __name__ == "__main__":
    sys.exit(main())
