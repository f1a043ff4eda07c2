import json

import numpy as np
import pytest

from calib.noise import SensorNoise
from calib.robots import paper_hexapod
from pipeline.formats import Recording, RecordingError, read_recording, write_recording


def make_recording(n=8, seed=0):
    rng = np.random.default_rng(seed)
    return Recording(
        robot=paper_hexapod(), noise=SensorNoise(0.001, 1e-6, "normal"),
        t_s=np.cumsum(rng.uniform(0.1, 1, n)), joints=233 + rng.normal(size=(n, 6)),
        measured=np.column_stack([rng.normal(size=(n, 2)), 200 + rng.normal(size=n), 0.01 * rng.normal(size=(n, 3))]),
        sets=np.array(["calibration"] * (n - 2) + ["validation"] * 2), meta={"seed": seed},
    )


def test_round_trip_is_exact(tmp_path):
    rec = make_recording()
    csv_path, json_path = write_recording(tmp_path / "r.csv", rec)
    back = read_recording(csv_path)
    for f in ("t_s", "joints", "measured", "sets"):
        np.testing.assert_array_equal(getattr(back, f), getattr(rec, f))
    assert back.noise == rec.noise and back.meta == {"seed": 0}
    np.testing.assert_array_equal(back.robot.table.nominal, rec.robot.table.nominal)
    assert back.robot.name == "hexapod"
    side = json.loads(json_path.read_text())
    assert side["units"] == {"length": "mm", "angle": "rad", "time": "s"}


def test_never_overwrites_silently(tmp_path):
    rec = make_recording()
    write_recording(tmp_path / "r.csv", rec)
    before = (tmp_path / "r.csv").read_text()
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        write_recording(tmp_path / "r.csv", make_recording(seed=1))
    assert (tmp_path / "r.csv").read_text() == before
    write_recording(tmp_path / "r.csv", make_recording(seed=1), overwrite=True)
    assert (tmp_path / "r.csv").read_text() != before
    assert not list(tmp_path.glob(".*tmp"))  # no temporary files left behind


def _corrupt(tmp_path, edit):
    csv_path, _ = write_recording(tmp_path / "r.csv", make_recording())
    lines = csv_path.read_text().splitlines()
    edit(lines)
    csv_path.write_text("\n".join(lines) + "\n")
    return csv_path


def _set_cell(row, col, value):
    def edit(lines):
        header = lines[0].split(",")
        cells = lines[row].split(",")
        cells[header.index(col)] = value
        lines[row] = ",".join(cells)
    return edit


@pytest.mark.parametrize("edit,match", [
    (_set_cell(3, "y_mm", "abc"), r"r.csv: row 3 \(line 4\), column 'y_mm': 'abc' is not a number"),
    (_set_cell(5, "l4_mm", "nan"), r"row 5 \(line 6\), column 'l4_mm': 'nan' is not finite"),
    (_set_cell(2, "set", "test"), r"row 2 \(line 3\), column 'set': 'test' is not one of"),
    (_set_cell(4, "t_s", "0.0"), r"row 4 \(line 5\), column 't_s': time goes backwards"),
    (lambda lines: lines.__setitem__(0, lines[0].replace("gamma_rad", "gamma_deg")), "header lacks column.*gamma_rad"),
    (lambda lines: lines.__setitem__(2, lines[2] + ",1.0"), r"row 2 \(line 3\): expected 14 fields, got 15"),
    (lambda lines: lines.__delitem__(slice(1, None)), "no data rows"),
])
def test_bad_csv_names_file_row_and_column(tmp_path, edit, match):
    path = _corrupt(tmp_path, edit)
    with pytest.raises(RecordingError, match=match):
        read_recording(path)


@pytest.mark.parametrize("edit,match", [
    (lambda s: s.update(robot="tripod"), "field 'robot' must be one of"),
    (lambda s: s.update(units={"length": "m", "angle": "rad", "time": "s"}), "field 'units' must be"),
    (lambda s: s.pop("declared_noise"), "missing field 'declared_noise'"),
    (lambda s: s["nominal_geometry"].update(base_joints_mm=[[0, 0, 0]]), r"field 'nominal_geometry': base_joints must have shape \(6, 3\)"),
    (lambda s: s["declared_noise"].update(position_mm=-1), "field 'declared_noise': position_mm must be"),
])
def test_bad_sidecar_names_file_and_field(tmp_path, edit, match):
    csv_path, json_path = write_recording(tmp_path / "r.csv", make_recording())
    side = json.loads(json_path.read_text())
    edit(side)
    json_path.write_text(json.dumps(side))
    with pytest.raises(RecordingError, match=match):
        read_recording(csv_path)


def test_missing_files(tmp_path):
    with pytest.raises(RecordingError, match="file not found"):
        read_recording(tmp_path / "none.csv")
    (tmp_path / "a.csv").write_text("t_s,l1_mm\n")
    with pytest.raises(RecordingError, match="sidecar not found"):
        read_recording(tmp_path / "a.csv")


@pytest.mark.parametrize("calib_words, said", [
    ("forward kinematics met a singular configuration at row 1", "forward kinematics met a singular configuration"),
    ("forward kinematics did not converge for row 1 in 50 iterations", "forward kinematics did not converge in 50 iterations"),
    ("row 1 is unreachable: the rod of chain 2 cannot reach", "unreachable: the rod of chain 2 cannot reach"),
    ("configuration 1: position [8.0, 1.0, 2.0] is outside the workspace", "position [8.0, 1.0, 2.0] is outside the workspace"),
])
def test_a_kinematics_failure_is_said_in_the_recordings_row_numbering(calib_words, said):
    """One row numbering: calib names row 1 of the arrays it was given (0-based, a subset); the
    message names the file's data row and line of that row, and not calib's number."""
    from calib.robot import KinematicsError
    from pipeline.formats import row_message

    subset_rows = np.array([4, 10, 20])  # the subset's 0-based rows in the recording
    assert row_message(KinematicsError(calib_words, 1), "rec.csv", subset_rows) == f"rec.csv: row 11 (line 12): {said}"
