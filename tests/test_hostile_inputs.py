"""Every bad file, sidecar, flag and output path is refused clearly by ``python -m pipeline.run``.

Each hostile case goes through ``main()`` and must end with exit status 2 and ONE line on stderr
naming the file, row, column, key or flag and what is wrong: no traceback, nothing written in the
output folder, nothing written earlier replaced. Legitimate variations (a UTF-8 byte-order mark,
CRLF line ends, trailing blank lines, columns in another order) are accepted and give the same
result as the clean file. The cases are listed in docs/real_data.md.
"""

import json
import os
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from calib import paper
from calib.noise import SensorNoise
from calib.robots import paper_hexapod
from calib.rotation import euler_from_matrix, rotation_matrix
from calib.workspace import reachable_poses
from pipeline.formats import Recording, read_recording, write_recording
from pipeline.run import main, run

ROBOT = paper_hexapod()
NOMINAL = ROBOT.table.nominal
ACTUAL = NOMINAL + paper.TABLE3_ERRORS.ravel()


def clean_recording(n_cal: int = 12, n_val: int = 5, seed: int = 0) -> Recording:
    """A small noise-free hexapod recording of the Table 3 machine (no MuJoCo: fast)."""
    targets = reachable_poses(ROBOT, n_cal + n_val, np.random.default_rng(seed))
    joints = ROBOT.inverse_kinematics(NOMINAL, targets)
    measured = ROBOT.forward_kinematics(ACTUAL, joints, initial=targets)
    return Recording(robot=ROBOT, noise=SensorNoise(paper.PAPER_NOISE_MM, 1e-5), t_s=np.arange(n_cal + n_val, dtype=float),
                     joints=joints, measured=measured, sets=np.array(["calibration"] * n_cal + ["validation"] * n_val),
                     meta={"scenario": "hostile-input base"})


@pytest.fixture
def work(tmp_path):
    """``(csv_path, out_folder)``: a clean recording and an output folder holding an earlier result."""
    csv_path, _ = write_recording(tmp_path / "rec.csv", clean_recording())
    out = tmp_path / "out"
    out.mkdir()
    (out / "earlier.rrd").write_text("an earlier result")
    (out / "earlier_summary.json").write_text("{}")
    return csv_path, out


def snapshot(folder: Path) -> dict:
    return {p.name: p.read_bytes() if p.is_file() else "folder" for p in sorted(folder.iterdir())}


def refused(argv, out: Path, capsys, *needles) -> str:
    """Run ``main(argv)``: exit 2, one line on stderr holding every needle, the folder unchanged."""
    before = snapshot(out)
    capsys.readouterr()
    code = main(argv + ([] if "--out" in argv else ["--out", str(out)]) + ["--quiet"])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in lines[0], lines[0]
    assert snapshot(out) == before  # nothing written, nothing earlier replaced, no temporary file left
    if os.environ.get("HOSTILE_LOG"):  # collect the messages (docs/real_data.md lists them)
        with open(os.environ["HOSTILE_LOG"], "a") as log:
            log.write(f"{os.environ.get('PYTEST_CURRENT_TEST', '').rsplit(' ', 1)[0]}\t{lines[0]}\n")
    return lines[0]


# --------------------------------------------------------------------------- the CSV

def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def _write_lines(path: Path, lines: list[str]) -> None:
    path.write_text("\n".join(lines) + "\n")


def _cell(path: Path, row: int, column: str, value: str) -> None:
    """Set data row ``row`` (1-based) of ``column`` to ``value``."""
    lines = _lines(path)
    header = lines[0].split(",")
    cells = lines[row].split(",")
    cells[header.index(column)] = value
    lines[row] = ",".join(cells)
    _write_lines(path, lines)


def _scale_columns(path: Path, columns, factor: float) -> None:
    rec = read_recording(path)
    joints, measured = rec.joints.copy(), rec.measured.copy()
    names_j = [f"l{i + 1}_mm" for i in range(6)]
    names_p = ["x_mm", "y_mm", "z_mm", "alpha_rad", "beta_rad", "gamma_rad"]
    for c in columns:
        if c in names_j:
            joints[:, names_j.index(c)] *= factor
        else:
            measured[:, names_p.index(c)] *= factor
    write_recording(path, replace(rec, joints=joints, measured=measured), overwrite=True)


def _convert_angles(path: Path, convert) -> None:
    """Rewrite the measured angles as ``convert(R)`` gives them from the true rotations (N, 3, 3)."""
    rec = read_recording(path)
    measured = rec.measured.copy()
    measured[:, 3:] = convert(rotation_matrix(measured[:, 3:]))
    write_recording(path, replace(rec, measured=measured), overwrite=True)


CSV_CASES = {
    "empty file": (lambda p: p.write_text(""), ["rec.csv", "empty file"]),
    "header only": (lambda p: _write_lines(p, _lines(p)[:1]), ["rec.csv", "no data rows"]),
    "missing column": (lambda p: _write_lines(p, [",".join(c for i, c in enumerate(ln.split(",")) if i != 12)
                                                  for ln in _lines(p)]),
                       ["rec.csv", "header lacks column(s) gamma_rad"]),
    "extra column": (lambda p: _write_lines(p, [ln + (",temperature_C" if k == 0 else ",21.5")
                                                for k, ln in enumerate(_lines(p))]),
                     ["rec.csv", "unknown column(s) temperature_C"]),
    "column named twice": (lambda p: _write_lines(p, [_lines(p)[0].replace("y_mm", "x_mm")] + _lines(p)[1:]),
                           ["rec.csv", "x_mm appear more than once"]),
    "NaN cell": (lambda p: _cell(p, 4, "l4_mm", "nan"), ["rec.csv: row 4 (line 5), column 'l4_mm'", "not finite"]),
    "inf cell": (lambda p: _cell(p, 2, "z_mm", "inf"), ["rec.csv: row 2 (line 3), column 'z_mm'", "not finite"]),
    "text cell": (lambda p: _cell(p, 3, "y_mm", "abc"), ["rec.csv: row 3 (line 4), column 'y_mm'", "not a number"]),
    "empty cell": (lambda p: _cell(p, 6, "alpha_rad", ""), ["row 6 (line 7), column 'alpha_rad'", "not a number"]),
    "short row": (lambda p: _write_lines(p, _lines(p)[:5] + [_lines(p)[5].rsplit(",", 1)[0]] + _lines(p)[6:]),
                  ["rec.csv: row 5 (line 6)", "expected 14 fields, got 13"]),
    "unknown set": (lambda p: _cell(p, 2, "set", "test"), ["row 2 (line 3), column 'set'", "'test' is not one of"]),
    "time backwards": (lambda p: _cell(p, 4, "t_s", "0.5"), ["row 4 (line 5), column 't_s'", "time goes backwards"]),
    "blank line inside": (lambda p: _write_lines(p, _lines(p)[:4] + [""] + _lines(p)[4:]),
                          ["rec.csv: row 4 (line 5)", "blank line inside the data"]),
    "semicolons": (lambda p: _write_lines(p, [ln.replace(",", ";") for ln in _lines(p)]),
                   ["rec.csv", "separated by ';'"]),
    "tabs": (lambda p: _write_lines(p, [ln.replace(",", "\t") for ln in _lines(p)]), ["rec.csv", "separated by tabs"]),
    "binary file": (lambda p: p.write_bytes(bytes(range(256)) * 4), ["rec.csv", "not a text file"]),
    "latin-1 text": (lambda p: p.write_bytes("t_s,l1_mm\n0,233\xb5\n".encode("latin-1")), ["rec.csv", "not UTF-8"]),
    "copied row": (lambda p: _write_lines(p, _lines(p)[:6] + [_lines(p)[3]] + _lines(p)[6:]),
                   ["rec.csv: row 6 (line 7)", "repeats row 3 exactly"]),
    "no calibration rows": (lambda p: _write_lines(p, [ln.replace(",calibration", ",validation") for ln in _lines(p)]),
                            ["rec.csv", "no calibration rows"]),
    "unreachable leg length": (lambda p: _cell(p, 5, "l3_mm", "512.0"),
                               ["rec.csv: row 5 (line 6), column 'l3_mm'", "outside the range", "cannot reach"]),
    "1e300 leg length": (lambda p: _cell(p, 2, "l1_mm", "1e300"), ["row 2 (line 3), column 'l1_mm'", "outside the range"]),
    "1e300 position": (lambda p: _cell(p, 7, "x_mm", "1e300"), ["row 7 (line 8), column 'x_mm'", "far beyond"]),
    "1e300 angle": (lambda p: _cell(p, 7, "beta_rad", "1e300"), ["row 7 (line 8), column 'beta_rad'", "not an angle"]),
    "leg lengths in metres": (lambda p: _scale_columns(p, [f"l{i}_mm" for i in range(1, 7)], 1e-3),
                              ["rec.csv", "joint values seem to be in metres"]),
    "positions in metres": (lambda p: _scale_columns(p, ["x_mm", "y_mm", "z_mm"], 1e-3),
                            ["rec.csv", "positions seem to be in metres"]),
    "angles in degrees": (lambda p: _scale_columns(p, ["alpha_rad", "beta_rad", "gamma_rad"], 180 / np.pi),
                          ["rec.csv", "angles seem to be in degrees"]),
    "angles as R = Rx Ry Rz": (lambda p: _convert_angles(p, lambda R: Rotation.from_matrix(R).as_euler("XYZ")),
                               ["rec.csv", "angles seem to follow R = Rx(alpha) Ry(beta) Rz(gamma)"]),
    "angles of the inverse rotation": (lambda p: _convert_angles(p, lambda R: euler_from_matrix(np.swapaxes(R, 1, 2))),
                                       ["rec.csv", "angles seem to follow the inverse rotation"]),
    "angles in reversed columns": (lambda p: _convert_angles(p, lambda R: euler_from_matrix(R)[:, ::-1]),
                                   ["rec.csv", "angles seem to follow the columns in the order gamma, beta, alpha"]),
}


@pytest.mark.parametrize("case", list(CSV_CASES))
def test_bad_csv_is_refused(case, work, capsys):
    csv_path, out = work
    edit, needles = CSV_CASES[case]
    edit(csv_path)
    refused(["--real", str(csv_path)], out, capsys, *needles)


def test_identical_poses_are_refused_without_a_prior_and_warned_of_with_one(work, capsys):
    """Thirty measurements of one pose: plain least squares cannot identify anything from them and
    refuses; with the tolerances as a prior the one pose determines what it can, the rest is held
    by the tolerances and the run says so (a warning naming the condition, left_to_prior)."""
    csv_path, out = work
    _write_lines(csv_path, _lines(csv_path)[:1] + [",".join([f"{k}.0"] + _lines(csv_path)[1].split(",")[1:])
                                                   for k in range(30)])
    refused(["--real", str(csv_path), "--no-prior"], out, capsys, "rec.csv",
            "30 calibration poses (1 distinct) are too alike", "numerically singular", "condition number")
    s = run(["--real", str(csv_path), "--out", str(out), "--quiet"]).summary
    assert any("leave parameter combinations undetermined" in w for w in s["warnings"])
    assert len(s["determined_by"]["data"]) <= 6 / 0.75 and s["left_to_prior"]  # one pose: 6 directions at most


def test_too_few_rows_are_refused_without_a_prior_and_left_to_it_with_one(work, capsys):
    """Three rows cannot determine the 42 parameters: plain least squares refuses them; with the
    tolerances as a prior (the default) the data determine what they can and the summary names
    what is left to the prior, with poses suggested to measure next."""
    csv_path, out = work
    _write_lines(csv_path, _lines(csv_path)[:4])
    refused(["--real", str(csv_path), "--no-prior"], out, capsys, "rec.csv", "3 calibration rows are too few",
            "at least 7")
    s = run(["--real", str(csv_path), "--out", str(out), "--quiet"]).summary
    assert s["prior"]["used"] and len(s["determined_by"]["prior"]) > 0 and s["left_to_prior"]
    # Three poses determine at most 18 directions: in prior-whitened coordinates the posterior
    # variance falls by a rank-18 amount (trace <= 18), and a parameter counts as "data" only where
    # its variance fell by more than 3/4 (std below half the prior's): at most 18 / 0.75 = 24 of them.
    assert len(s["determined_by"]["data"]) <= 24
    assert Path(s["suggested_poses_path"]).is_file()


# --------------------------------------------------------------------------- the sidecar

def _side(edit):
    def apply(json_path: Path):
        side = json.loads(json_path.read_text())
        edit(side)
        json_path.write_text(json.dumps(side))
    return apply


def _metres(side):
    g = side["nominal_geometry"]
    for k in ("base_joints_mm", "platform_joints_mm"):
        g[k] = (np.array(g[k]) / 1000).tolist()
    g["home_lengths_mm"] = (np.array(g["home_lengths_mm"]) / 1000).tolist()
    g["home_pose"] = (np.array(g["home_pose"]) * [1e-3, 1e-3, 1e-3, 1, 1, 1]).tolist()
    if "stroke_mm" in g:
        g["stroke_mm"] = g["stroke_mm"] / 1000


SIDECAR_CASES = {
    "sidecar missing": (lambda j: j.unlink(), ["rec.json", "sidecar not found"]),
    "sidecar a folder": (lambda j: (j.unlink(), j.mkdir()), ["rec.json", "is a folder"]),
    "sidecar malformed": (lambda j: j.write_text('{"robot": "hexapod",'), ["rec.json", "not valid JSON"]),
    "sidecar binary": (lambda j: j.write_bytes(b"\x00\x01\xff" * 10), ["rec.json", "not a text file"]),
    "sidecar a list": (lambda j: j.write_text("[1, 2]"), ["rec.json", "top level must be an object, got list"]),
    "missing key": (_side(lambda s: s.pop("declared_noise")), ["rec.json", "missing field 'declared_noise'"]),
    "unknown key": (_side(lambda s: s.update(instrument="laser")), ["rec.json", "unknown field(s) 'instrument'"]),
    "format wrong": (_side(lambda s: s.update(format="my lab csv")), ["rec.json", "field 'format' must be"]),
    "format missing": (_side(lambda s: s.pop("format")), ["rec.json", "missing field 'format'"]),
    "version wrong": (_side(lambda s: s.update(version=99)), ["rec.json", "field 'version' must be one of", "99"]),
    "version a string": (_side(lambda s: s.update(version="2")), ["rec.json", "field 'version'", "'2'"]),
    "unknown robot": (_side(lambda s: s.update(robot="tripod")), ["rec.json", "field 'robot' must be one of"]),
    "robot not a string": (_side(lambda s: s.update(robot=["hexapod"])), ["rec.json", "field 'robot'"]),
    "units in metres": (_side(lambda s: s["units"].update(length="m")), ["rec.json", "field 'units' must be"]),
    "noise a string": (_side(lambda s: s.update(declared_noise="0.001")),
                       ["rec.json", "field 'declared_noise' must be an object, got str"]),
    "noise of wrong type": (_side(lambda s: s["declared_noise"].update(position_mm="small")),
                            ["rec.json", "field 'declared_noise.position_mm' must be a number, got 'small'"]),
    "noise negative": (_side(lambda s: s["declared_noise"].update(position_mm=-1)),
                       ["rec.json", "field 'declared_noise': position_mm must be finite and >= 0"]),
    "noise unknown key": (_side(lambda s: s["declared_noise"].update(temperature=3)),
                          ["rec.json", "field 'declared_noise': unknown key 'temperature'"]),
    "geometry a list": (_side(lambda s: s.update(nominal_geometry=[1, 2, 3])),
                        ["rec.json", "field 'nominal_geometry' must be an object, got list"]),
    "geometry wrong shape": (_side(lambda s: s["nominal_geometry"].update(base_joints_mm=[[0, 0, 0]])),
                             ["rec.json", "field 'nominal_geometry'"]),
    "geometry wrong type": (_side(lambda s: s["nominal_geometry"].update(base_joints_mm="abc")),
                            ["rec.json", "field 'nominal_geometry'"]),
    "geometry in metres": (_side(_metres), ["rec.json", "seems to be in metres"]),
    "meta not an object": (_side(lambda s: s.update(meta=[1])), ["rec.json", "field 'meta' must be an object"]),
    "meta.simulation not an object": (_side(lambda s: s["meta"].update(simulation="yes")),
                                      ["rec.json", "field 'meta.simulation' must be an object"]),
    "injected errors of unknown parameters": (_side(lambda s: s["meta"].update(simulation={"injected_errors": {"B9.q": 1}})),
                                              ["rec.json", "meta.simulation.injected_errors"]),
    "sidecar of another robot": (_side(lambda s: s.update(robot="delta")), ["rec.csv", "header lacks column(s)",
                                                                            "a delta recording"]),
}


@pytest.mark.parametrize("case", list(SIDECAR_CASES))
def test_bad_sidecar_is_refused(case, work, capsys):
    csv_path, out = work
    edit, needles = SIDECAR_CASES[case]
    json_path = csv_path.with_suffix(".json")
    if case == "sidecar of another robot":
        from calib.robots import default_robot

        side = json.loads(json_path.read_text())
        side.update(robot="delta", nominal_geometry=default_robot("delta").description())
        json_path.write_text(json.dumps(side))
    else:
        edit(json_path)
    refused(["--real", str(csv_path)], out, capsys, *needles)


# --------------------------------------------------------------------------- paths and flags

def test_a_folder_as_the_recording(work, capsys):
    csv_path, out = work
    folder = csv_path.parent / "folder.csv"
    folder.mkdir()
    refused(["--real", str(folder)], out, capsys, "--real", "folder.csv", "is a folder")


def test_a_missing_recording(work, capsys):
    _, out = work
    refused(["--real", str(out.parent / "none.csv")], out, capsys, "--real", "none.csv", "file not found")


def test_an_unreadable_recording(work, capsys, monkeypatch):
    csv_path, out = work
    if os.geteuid() == 0:  # root reads anything: make the read itself fail as it would for a user
        real = Path.read_bytes

        def deny(self):
            if self.name == csv_path.name:
                raise PermissionError(13, "Permission denied", str(self))
            return real(self)
        monkeypatch.setattr(Path, "read_bytes", deny)
    else:
        csv_path.chmod(0)
    refused(["--real", str(csv_path)], out, capsys, "rec.csv", "cannot read", "Permission denied")


def test_a_recording_of_another_robot_than_named(work, capsys):
    csv_path, out = work
    refused(["--real", str(csv_path), "--robot", "delta"], out, capsys, "--robot delta", "rec.csv", "is of a hexapod")


@pytest.mark.parametrize("argv,needles", [
    (["--poses", "0"], ["--poses must be a positive integer"]),
    (["--poses", "abc"], ["--poses must be 'reference', an integer or a .csv command file"]),
    (["--poses", "-3"], ["--poses must be a positive integer"]),
    (["--poses", "missing.csv"], ["--poses missing.csv", "file not found"]),
    (["--noise-mm", "-1"], ["--noise-mm must be >= 0"]),
    (["--noise-mm", "nan"], ["--noise-mm must be >= 0 and finite"]),
    (["--noise-rad", "-0.1"], ["--noise-rad must be >= 0"]),
    (["--noise-mm", "abc"], ["--noise-mm", "invalid float value"]),
    (["--seed", "-1"], ["--seed must be >= 0"]),
    (["--seed", "1.5"], ["--seed", "invalid int value"]),
    (["--heldout", "-1"], ["--heldout must be >= 0"]),
    (["--stiffness", "0"], ["--stiffness must be finite and > 0"]),
    (["--robot", "tripod"], ["--robot", "invalid choice"]),
    (["--method", "magic"], ["--method", "invalid choice"]),
    (["--bogus"], ["unrecognized arguments: --bogus"]),
])
def test_bad_flags_are_refused(argv, needles, work, capsys):
    _, out = work
    refused(argv, out, capsys, *needles)


def test_out_is_a_file(work, capsys):
    csv_path, out = work
    refused(["--real", str(csv_path), "--out", str(out / "earlier.rrd")], out, capsys, "--out", "is a file, not a folder")


def test_out_cannot_be_created(work, capsys):
    csv_path, out = work
    refused(["--real", str(csv_path), "--out", str(out / "earlier.rrd" / "sub")], out, capsys, "--out", "cannot create")


def test_summary_json_exists(work, capsys):
    csv_path, out = work
    refused(["--real", str(csv_path), "--summary-json", str(out / "earlier_summary.json")], out, capsys,
            "--summary-json", "earlier_summary.json exists; pass --overwrite")


def test_summary_json_in_a_missing_folder(work, capsys):
    csv_path, out = work
    refused(["--real", str(csv_path), "--summary-json", str(out / "nowhere" / "s.json")], out, capsys,
            "--summary-json", "the folder", "does not exist")


def test_summary_json_is_a_folder(work, capsys):
    csv_path, out = work
    (out / "sdir").mkdir()
    refused(["--real", str(csv_path), "--summary-json", str(out / "sdir")], out, capsys, "--summary-json", "is a folder")


def test_summary_json_cannot_be_written(work, capsys):
    csv_path, out = work
    refused(["--real", str(csv_path), "--summary-json", "/proc/summary.json"], out, capsys,
            "--summary-json", "cannot write in the folder /proc")


def test_an_explicit_name_taken_is_refused_before_any_work(work, capsys):
    """A refused re-run publishes nothing (no new .csv/.json beside the old .rrd)."""
    _, out = work
    refused(["--heldout", "0", "--name", "earlier"], out, capsys, "--out", "earlier.rrd exists; pass --overwrite")


@pytest.mark.slow
def test_an_interrupted_run_leaves_nothing_that_looks_complete(work, capsys, monkeypatch):
    import calib.identification as calibration

    csv_path, out = work

    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(calibration, "find_outliers", interrupt)
    before = snapshot(out)
    assert main(["--real", str(csv_path), "--out", str(out), "--summary-json", str(out / "s.json"), "--quiet"]) == 130
    assert "interrupted" in capsys.readouterr().err
    assert snapshot(out) == before


def test_concurrent_runs_into_one_folder_get_their_own_names(work):
    from pipeline.formats import NameReservation
    from pipeline.workflows.calibration import OUTPUT_EXTENSIONS, RunSettings, default_name

    csv_path, out = work
    base = default_name(RunSettings(real=csv_path, out=out))
    first, second = (NameReservation(out, base, explicit=False, overwrite=False, extensions=OUTPUT_EXTENSIONS)
                     for _ in range(2))
    try:
        assert first.name == "rec_calibrated" and second.name == "rec_calibrated_2"
    finally:
        first.release()
        second.release()
    assert not list(out.glob(".*lock"))


# --------------------------------------------------------------------------- accepted variations

ACCEPTED = {
    "UTF-8 byte-order mark": lambda p: p.write_bytes(b"\xef\xbb\xbf" + p.read_bytes()),
    "CRLF line ends": lambda p: p.write_bytes(p.read_bytes().replace(b"\n", b"\r\n")),
    "trailing blank lines": lambda p: p.write_text(p.read_text() + "\n\n  \n"),
    "columns in another order": lambda p: _write_lines(p, [",".join(reversed(ln.split(","))) for ln in _lines(p)]),
}


@pytest.fixture(scope="module")
def clean_result(tmp_path_factory):
    folder = tmp_path_factory.mktemp("clean")
    csv_path, _ = write_recording(folder / "rec.csv", clean_recording())
    return run(["--real", str(csv_path), "--out", str(folder), "--quiet"]).summary


@pytest.mark.parametrize("case", list(ACCEPTED))
def test_legitimate_variations_are_accepted(case, work, clean_result):
    csv_path, out = work
    ACCEPTED[case](csv_path)
    s = run(["--real", str(csv_path), "--out", str(out), "--quiet"]).summary
    assert s["identified_errors"] == clean_result["identified_errors"]
    assert s["flagged_poses"] == [] and s["warnings"] == []


def test_repeated_measurements_are_reported(work):
    csv_path, out = work
    lines = _lines(csv_path)
    repeat = lines[3].split(",")
    repeat[0] = "99.0"
    _write_lines(csv_path, lines + [",".join(repeat)])
    s = run(["--real", str(csv_path), "--out", str(out), "--quiet"]).summary
    assert any("rows 18 (= 3) repeat the joints and pose" in w for w in s["warnings"])


def test_flagged_rows_are_named_by_their_data_row_whatever_the_order_of_sets(work):
    """Validation rows first, then calibration rows: the flagged row is still the data row number."""
    csv_path, out = work
    rec = read_recording(csv_path)
    order = np.r_[12:17, 0:12]  # 5 validation rows, then the 12 calibration rows
    measured = rec.measured[order].copy()
    measured[9, :3] += [0.05, -0.05, 0.0]  # data row 10 (file line 11): the 5th calibration row
    shuffled = replace(rec, joints=rec.joints[order], measured=measured, sets=rec.sets[order])
    write_recording(csv_path, shuffled, overwrite=True)
    s = run(["--real", str(csv_path), "--out", str(out), "--quiet"]).summary
    assert s["flagged_poses"] == [10] and s["outliers"]["left_out"]


# --------------------------------------------------------------------------- the other command lines


@pytest.mark.parametrize("module,argv,needle", [
    ("pipeline.blind", ["--seeds", "0"], "--seeds: expected an integer >= 1, got 0"),
    ("pipeline.blind", ["--seeds", "-1"], "--seeds: expected an integer >= 1, got -1"),
    ("pipeline.blind", ["--first-seed", "-1"], "--first-seed: expected an integer >= 0, got -1"),
    ("pipeline.blind", ["--workers", "0"], "--workers: expected an integer >= 1, got 0"),
    ("pipeline.study", ["--trials", "2", "--workers", "0"], "--workers: expected an integer >= 1, got 0"),
    ("pipeline.fleet", ["FOLDER", "--workers", "-1"], "--workers: expected an integer >= 1, got -1"),
    ("pipeline.design", ["--poses", "8", "--workers", "two"], "--workers: expected an integer >= 1, got 'two'"),
    ("pipeline.study", ["--trials", "2", "--scheduler", "nonsense"],
     "--scheduler: not a Dask scheduler address: missing port number in address 'nonsense'"),
    ("pipeline.blind", ["--seeds", "1", "--scheduler", "tcp://host:port"], "--scheduler: not a Dask scheduler address"),
    ("pipeline.design", ["--poses", "8", "--scheduler", "foo://host:8786"],
     "--scheduler: not a Dask scheduler address: unknown address scheme 'foo'"),
    ("pipeline.fleet", ["FOLDER", "--scheduler", "host:"], "--scheduler: not a Dask scheduler address"),
    ("pipeline.discover", ["--real", "MISSING"], "file not found"),
    ("pipeline.discover", ["--real", "FOLDER"], "is a folder"),
    ("pipeline.discover", ["--real", "REC", "--candidates", "moon_phase"], "unknown effect 'moon_phase'"),
    # Each message names its own cause (before: "--out recordings: cannot write in this folder" and
    # "the workspace 'full' is (nearly) empty").
    ("pipeline.run", ["--name", "../x", "--out", "FOLDER"], "--name ../x: a file name, not a path"),
])
def test_other_command_lines_refuse_bad_input(module, argv, needle, work, capsys):
    """Exit 2, one line, no traceback, before any work (the blind suite would otherwise run)."""
    import importlib

    csv_path, out = work
    argv = [{"MISSING": str(out / "none.csv"), "FOLDER": str(out), "REC": str(csv_path)}.get(a, a) for a in argv]
    before = snapshot(out)
    capsys.readouterr()
    code = importlib.import_module(module).main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err and needle in lines[0], err
    assert snapshot(out) == before


HOLD_NAME = """
import sys, time
from pathlib import Path
from pipeline.formats import NameReservation
out, name = Path(sys.argv[1]), sys.argv[2]
held = NameReservation(out, name, explicit=True, overwrite=True, extensions=(".rrd",))
(out / f".{name}.rrd.killed.tmp").write_bytes(b"x" * 1000)  # what a run killed while writing leaves
print("held", flush=True)
time.sleep(60)
"""


@pytest.mark.slow
def test_a_killed_run_blocks_no_rerun_and_its_temporary_files_go(work, capsys):
    import subprocess
    import sys

    csv_path, out = work
    holder = subprocess.Popen([sys.executable, "-c", HOLD_NAME, str(out), "x"], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        # While the holder lives, the name is refused, naming the process.
        assert main(["--real", str(csv_path), "--out", str(out), "--name", "x", "--overwrite", "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"another run (process {holder.pid}) is writing" in err[0]
    finally:
        holder.kill()
        holder.wait()
    assert (out / ".x.lock").exists() and (out / ".x.rrd.killed.tmp").exists()  # left by the kill
    assert main(["--real", str(csv_path), "--out", str(out), "--name", "x", "--overwrite", "--quiet"]) == 0
    assert (out / "x.rrd").exists()
    assert not list(out.glob(".x*"))  # the lock released, the killed run's temporary file removed


def test_a_sidecar_naming_another_robot_says_so(work, capsys):
    """A hexapod's geometry under 'robot': 'delta': the message names both (before: a bare
    KeyError: 'parameters')."""
    csv_path, out = work
    side_path = csv_path.with_suffix(".json")
    side = json.loads(side_path.read_text())
    side["robot"] = "delta"
    side_path.write_text(json.dumps(side))
    refused(["--real", str(csv_path)], out, capsys, "rec.json", "field 'nominal_geometry' is not a delta description",
            "it is a description of a hexapod")


def test_too_many_design_candidates_names_the_flag(work, capsys):
    """More candidates than the workspace gives at the draw limit: found during the search (after
    the announcement and its progress), the error line names --candidates and how many it can give
    (before: "the workspace 'full' is (nearly) empty")."""
    from pipeline.design import main as design_main

    _, out = work
    assert design_main(["--poses", "10", "--candidates", "60000", "--out", str(out / "d.csv")]) == 2
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]
    assert "Traceback" not in err and last.startswith("error: --candidates 60000: only") and "ask for at most" in last
    assert not (out / "d.csv").exists()


# --------------------------------------------------------------------------- mistakes in the data

def _flip_last_position(m):
    m = m.copy()
    m[:, 2] = -m[:, 2]
    return m


MISTAKES = {
    # name: (how the file is spoiled, words of the cause each command names)
    "x and y swapped": (lambda j, m: (j, m[:, [1, 0] + list(range(2, m.shape[1]))]), "swapped"),
    "z sign flipped": (lambda j, m: (j, _flip_last_position(m)), "sign flipped"),
    "positions in metres": (lambda j, m: (j, np.c_[m[:, :3] / 1000.0, m[:, 3:]]), "metres"),
    "a joint read backwards": (None, "count the other way"),
    "every pose at z = 0": (lambda j, m: (j, np.c_[m[:, :2], np.zeros(len(m)), m[:, 3:]]), "not measured"),
}


def _spoiled_recording(robot_name, mistake, folder):
    """A clean kinematic recording of ``robot_name`` (40 rows, 1 um / 1 urad noise) with one mistake."""
    from calib.noise import SensorNoise
    from calib.robots import default_robot
    from calib.workspace import reachable_poses

    robot = default_robot(robot_name)
    rng = np.random.default_rng(2)
    poses = reachable_poses(robot, 40, rng)
    joints = robot.inverse_kinematics(robot.table.nominal, poses)
    noise = SensorNoise(0.001, 1e-6, "normal")
    measured = poses + noise.sample(len(poses), rng, robot.pose_units)
    spoil = MISTAKES[mistake][0]
    if spoil is None:  # chain 2's reading counts the other way: about its zero (a motor) or its stroke's middle
        lim = robot.joint_limits()[1]
        joints = joints.copy()
        joints[:, 1] = -joints[:, 1] if robot.joint_unit == "rad" else lim.sum() - joints[:, 1]
    else:
        joints, measured = spoil(joints, measured)
    rec = Recording(robot=robot, noise=noise, t_s=np.arange(40.0), joints=joints, measured=measured,
                    sets=np.array(["calibration"] * 40), meta={})
    path = folder / f"{robot_name}.csv"
    write_recording(path, rec, overwrite=True)
    return path


@pytest.mark.parametrize("command", ["pipeline.run", "pipeline.discover"])
@pytest.mark.parametrize("robot_name", ["hexapod", "delta", "rus"])
@pytest.mark.parametrize("mistake", list(MISTAKES))
def test_a_mistake_in_the_data_is_refused_naming_its_cause(command, robot_name, mistake, tmp_path, capsys):
    """Every robot and command that reads a recording: a file spoiled by a units, axis, sign or
    joint-direction mistake is no success: exit 2, one line naming the file and the cause (the
    conversion that makes it fit, with both chi-squares), no traceback, nothing written."""
    import importlib

    path = _spoiled_recording(robot_name, mistake, tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    code = importlib.import_module(command).main(["--real", str(path), "--out", str(out)])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    cause = MISTAKES[mistake][1]
    # On the Delta (positions alone, an instrument frame allowed) every mirror image fits as well, a
    # rotation apart: the one named needs no frame, the mistake itself.
    assert cause in lines[0], lines[0]
    assert str(path) in lines[0] and ("chi-square" in lines[0] or mistake == "every pose at z = 0"), lines[0]
    assert list(out.iterdir()) == []


# --------------------------------------------------------------------------- verdicts without information

ROBOT_NAMES = ["hexapod", "delta", "rus"]


def _kinematic_recording(robot_name, n=24, *, same=False, seed=2):
    """A clean kinematic recording of ``robot_name`` (1 um / 1 urad noise, calibration rows only),
    every row at the first pose with ``same`` (a machine that never moved)."""
    from calib.noise import SensorNoise
    from calib.robots import default_robot

    robot = default_robot(robot_name)
    rng = np.random.default_rng(seed)
    poses = reachable_poses(robot, n, rng)
    if same:
        poses = np.repeat(poses[:1], n, axis=0)
    joints = robot.inverse_kinematics(robot.table.nominal, poses)
    noise = SensorNoise(0.001, 1e-6, "normal")
    measured = poses + noise.sample(n, rng, robot.pose_units)
    return Recording(robot=robot, noise=noise, t_s=np.arange(float(n)), joints=joints, measured=measured,
                     sets=np.array(["calibration"] * n), meta={})


@pytest.mark.parametrize("robot_name", ROBOT_NAMES)
def test_rows_that_never_move_the_machine_are_no_success(robot_name, tmp_path, capsys):
    """Every row at one pose (the measurements differ by the noise alone): the run fits them within
    the noise, and that is no calibration: not a success, the cause in words; discovery refuses
    them (before: a Delta "SUCCESS" with a held-out error of 1049 um, a discovery "NOT explained")."""
    import pipeline.discover

    path, _ = write_recording(tmp_path / "still.csv", _kinematic_recording(robot_name, same=True))
    s = run(["--real", str(path), "--out", str(tmp_path / "out"), "--quiet"]).summary
    assert not s["success"] and s["verdict"]["cause"] == "no_motion"
    assert "do not move the machine: 24 of 24 rows are the same pose" in s["verdict"]["words"]
    out = tmp_path / "d"
    assert pipeline.discover.main(["--real", str(path), "--out", str(out), "--no-resim"]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err and "RuntimeWarning" not in err, err
    assert str(path) in lines[0] and "do not move the machine: 24 of 24 rows are the same pose" in lines[0]
    assert not out.exists()  # refused: no folder left


def test_the_fleet_lists_a_machine_that_never_moved_as_no_success(tmp_path):
    from pipeline.workflows.fleet import run_fleet

    write_recording(tmp_path / "in" / "still.csv", _kinematic_recording("delta", same=True))
    rep = run_fleet(tmp_path / "in", tmp_path / "out", workers=1)
    (row,) = rep.rows
    assert row["status"] == "calibrated" and row["verdict"] == "no: no_motion", row
    assert row["explained"].startswith("n/a: the calibration rows do not move the machine: 24 of 24"), row


@pytest.mark.parametrize("robot_name", ROBOT_NAMES)
def test_noise_that_drowns_the_geometry_is_no_success(robot_name, tmp_path):
    """A simulated run whose declared (and simulated) noise is 1000 mm: the rows fit to it, yet no
    parameter's uncertainty fell below half its tolerance and none moved beyond 3 of them: the
    identified geometry is the prior's, and the verdict says so (before: SUCCESS)."""
    s = run(["--robot", robot_name, "--noise-mm", "1000", "--heldout", "3", "--out", str(tmp_path),
             "--quiet"]).summary
    assert s["determined_by"]["data"] == []
    assert not s["success"] and s["verdict"]["cause"] == "no_information", s["verdict"]
    assert "the rows determine nothing beyond the tolerance" in s["verdict"]["words"]


@pytest.mark.parametrize("robot_name", ROBOT_NAMES)
def test_poses_suggested_under_noise_that_drowns_the_geometry_are_said_rightly(robot_name, tmp_path):
    """1000 mm of noise: the poses suggested must determine at least one direction more than the
    measured ones (calib's effective number of parameters), else none is suggested and the line
    says why in a whole sentence; a suggestion names its file (before, on the Delta: "suggested:
    measure 0 more poses (none suggested: configuration 0: position [825.87, -102.24, -201.78] is
    outside the workspace (chain 2 cannot reach it)): ", the noisy measured pose taken for the
    machine's)."""
    from pipeline.report import terminal_lines
    from pipeline.workflows.calibration import DETERMINED_DIRECTION

    res = run(["--robot", robot_name, "--noise-mm", "1000", "--heldout", "3", "--out", str(tmp_path), "--quiet"])
    s = res.summary
    sp = s["suggested_poses"]
    (line,) = [ln for ln in terminal_lines(res.report) if ln.strip().startswith("suggested:")]
    if sp["poses"] == 0:
        added = float(re.search(r"would determine (\S+) more of the", sp["what"]).group(1))
        assert added < DETERMINED_DIRECTION and sp["what"].endswith("measure with less noise"), sp
        assert line == f"  suggested: no poses: {sp['what']}" and "suggested_poses_path" not in s, line
        assert not list(tmp_path.glob("*.suggested_poses.*"))
    else:  # the hexapod's angles, declared exact (--noise-rad 0), still determine directions
        assert sp["poses"] > 0 and line.endswith(f": {s['suggested_poses_path']}"), line
        assert Path(s["suggested_poses_path"]).is_file()
    assert "none suggested" not in line and "failed" not in line and not line.endswith(": "), line


def _another_machines_description(side_path, robot_name, factor=1.1):
    """Scale the sidecar's base joints (their x and y) by ``factor``: another machine's description."""
    side = json.loads(side_path.read_text())
    g = side["nominal_geometry"]
    if "base_joints_mm" in g:
        g["base_joints_mm"] = [[factor * v for v in b] for b in g["base_joints_mm"]]
    else:
        prefix = {"delta": "D", "rus": "M"}[robot_name]
        for k in g["parameters"]:
            if k.startswith(prefix) and k[-2:] in (".x", ".y"):
                g["parameters"][k] *= factor
    side_path.write_text(json.dumps(side))


@pytest.mark.parametrize("robot_name", ROBOT_NAMES)
def test_another_machines_nominal_geometry_is_named_as_the_description(robot_name, tmp_path):
    """The rows of one machine under a sidecar whose base joints are 1.1 times its own: the fitted
    errors are -1/11 of the base joints' nominal coordinates, a pattern of the description, and the
    verdict says so with the scale (before: "unmodelled physics", or a SUCCESS once the tolerance
    learnt from the rows grew to hold them)."""
    from calib.diagnosis import description_pattern

    path, side = write_recording(tmp_path / "rec.csv", _kinematic_recording(robot_name, 40))
    _another_machines_description(side, robot_name)
    s = run(["--real", str(path), "--out", str(tmp_path / "out"), "--quiet"]).summary
    assert not s["success"] and s["verdict"]["cause"] == "description", s["verdict"]
    words = s["verdict"]["words"]
    assert "a pattern of the description, not physics" in words and "another machine's" in words, words
    assert "1.1 times this machine's" in words and "physics the geometric model leaves out" not in words, words
    # The clean description: no pattern in the same rows' fit.
    clean = run(["--real", str(write_recording(tmp_path / "clean.csv", _kinematic_recording(robot_name, 40))[0]),
                 "--out", str(tmp_path / "out"), "--quiet"]).summary
    robot = read_recording(tmp_path / "clean.csv").robot
    errors = robot.table.vector(clean["identified_errors"], base=np.zeros(robot.n_parameters))
    assert description_pattern(robot, errors, np.full(robot.n_parameters, 0.01)) == [] or clean["success"]


@pytest.mark.parametrize("robot_name", ROBOT_NAMES)
def test_joints_far_past_their_range_are_named_with_their_rows(robot_name, tmp_path, capsys):
    """Three rows whose every joint reads a whole range past the nominal one (3.1 rad on the
    Delta, 2.8 rad on the 6-RUS, 100 mm on the hexapod): out of range, the rows named (before: "the
    joint values seem to be in degrees")."""
    rec = _kinematic_recording(robot_name, 20)
    limits = rec.robot.joint_limits()
    joints = rec.joints.copy()
    joints[[2, 6, 11]] += limits[:, 1] - limits[:, 0]
    path, _ = write_recording(tmp_path / "rec.csv", replace(rec, joints=joints))
    out = tmp_path / "out"
    out.mkdir()
    line = refused(["--real", str(path)], out, capsys, "rec.csv: row 3 (line 4), column",
                   "is outside the range", "the machine cannot reach it",
                   "out of range too: rows 7 (line 8), 12 (line 13) (3 of 20 rows)")
    assert "degrees" not in line and "metres" not in line


@pytest.mark.parametrize("mistake", ["x sign flipped", "y sign flipped", "z sign flipped", "x and y swapped",
                                     "x and z swapped", "y and z swapped"])
def test_a_delta_reflection_is_named_by_the_axis_flipped(mistake):
    """Positions alone with an instrument frame allowed: every mirror image fits (a rotation turns
    one into another), and the one named is the one that needs no frame: the axis flipped or the
    axes swapped (before: a z flip named as an x flip, an x/y swap as a z flip)."""
    from calib.diagnosis import conversion_registry, diagnose

    rec = _kinematic_recording("delta", 30)
    (conv,) = [c for c in conversion_registry(rec.robot) if c.name == mistake]
    joints, measured = conv.apply(rec.joints, rec.measured)  # each of these is its own inverse
    d = diagnose(rec.robot, joints, measured, rec.noise)
    assert d.cause == "conversion" and d.conversion.name == mistake, (d.message, d.alternatives)
    assert not d.converted.frame_estimated


@pytest.mark.parametrize("robot_name", ROBOT_NAMES)
def test_one_data_row_is_refused_in_a_sentence(robot_name, tmp_path, capsys):
    path, _ = write_recording(tmp_path / "rec.csv", _kinematic_recording(robot_name, 1))
    out = tmp_path / "out"
    out.mkdir()
    line = refused(["--real", str(path)], out, capsys, "rec.csv", "the recording holds one data row",
                   "judged by predicting rows it did not use")
    assert "folds" not in line


# --------------------------------------------------------------------------- files

def test_an_overwriting_rerun_leaves_no_earlier_suggested_poses(work):
    """A run that suggested poses, then one of the same name that suggests none (--overwrite, no
    prior: nothing left to it): the
    outputs of a name are replaced together, the earlier suggestion goes with the rest."""
    csv_path, out = work
    few = csv_path.with_name("few.csv")
    write_recording(few, replace(clean_recording(3, 0), meta={}))
    s = run(["--real", str(few), "--out", str(out), "--name", "x", "--quiet"]).summary
    assert Path(s["suggested_poses_path"]).is_file()
    s = run(["--real", str(csv_path), "--out", str(out), "--name", "x", "--overwrite", "--no-prior", "--quiet"]).summary
    assert "suggested_poses_path" not in s
    assert not list(out.glob("x.suggested_poses.*")) and (out / "x.rrd").is_file()
    assert not list(out.glob(".x*"))  # no backup or temporary left


def _dead_pid() -> int:
    import subprocess
    import sys

    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_a_killed_writers_temporaries_go_at_the_next_write_and_a_live_ones_stay(tmp_path):
    """What a writer killed while writing leaves (``.NAME.PID-XXXX.tmp``, ``.bak``) is removed by
    the next writer of that path, whichever command it is (atomic_write, ResultSet); a running
    writer's stay."""
    from pipeline.formats import ResultSet, atomic_write

    dead, alive = _dead_pid(), os.getppid()
    for name in ("a.json", "b.csv"):
        (tmp_path / f".{name}.{dead}-killed.tmp").write_bytes(b"x" * 100)
        (tmp_path / f".{name}.{dead}-killed.bak").write_bytes(b"x" * 100)
        (tmp_path / f".{name}.{alive}-writing.tmp").write_bytes(b"x")
    atomic_write(tmp_path / "a.json", "{}")
    with ResultSet({"b": tmp_path / "b.csv"}) as files:
        files.temp("b").write_text("b")
        files.publish()
    hidden = sorted(p.name for p in tmp_path.glob(".*"))
    assert hidden == sorted(f".{n}.{alive}-writing.tmp" for n in ("a.json", "b.csv")), hidden


def test_a_killed_convert_leaves_nothing_for_long_and_a_refused_one_no_folder(tmp_path, capsys):
    """pipeline.convert: the temporaries a killed conversion left beside its outputs are gone
    after the next conversion to that name; a refused conversion leaves no folder it created
    (before: an empty output folder)."""
    from pipeline.convert import main as convert_main
    from tests.test_convert import style_two_sessions

    from calib.robots import default_robot

    _, mapping, files, _ = style_two_sessions(default_robot("hexapod"), tmp_path)
    (tmp_path / "map.toml").write_text(mapping)
    for n, text in files.items():
        (tmp_path / n).write_text(text)
    lab = [str(tmp_path / n) for n in files]
    out = tmp_path / "new" / "deeper"
    (tmp_path / "bad.toml").write_text('robot = "hexapod"\n')
    assert convert_main(lab + ["--map", str(tmp_path / "bad.toml"), "--out", str(out / "rec")]) == 2
    assert "Traceback" not in capsys.readouterr().err
    assert not (tmp_path / "new").exists()
    out.mkdir(parents=True)
    dead = _dead_pid()
    for name in ("rec.csv", "rec.json"):
        (out / f".{name}.{dead}-killed.tmp").write_bytes(b"x" * 1000)
    assert convert_main(lab + ["--map", str(tmp_path / "map.toml"), "--out", str(out / "rec")]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["rec.csv", "rec.json"]


@pytest.mark.parametrize("argv", [["--summary-json", "{folder}/missing/s.json"], ["--name", "x/y"]])
def test_a_refused_run_leaves_no_folder_it_created(argv, work, capsys):
    csv_path, out = work
    folder = out / "new"
    argv = [a.replace("{folder}", str(folder)) for a in argv]
    assert main(["--real", str(csv_path), "--out", str(folder / "deeper"), "--quiet"] + argv) == 2
    assert "Traceback" not in capsys.readouterr().err
    assert not folder.exists()


def test_a_closing_cluster_prints_no_closed_connection(capsys):
    """quiet_shutdown: a CommClosedError logged or raised while a finished job's cluster closes is
    not shown, nor a late report of one on asyncio's logger; any other error still is."""
    import logging

    from distributed.comm.core import CommClosedError

    from pipeline.execution.executor import quiet_shutdown

    handler = logging.StreamHandler()
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        with quiet_shutdown():
            logging.getLogger("distributed.core").error("closing", exc_info=CommClosedError("in: closed"))
            raise CommClosedError("in: closed")
        logging.getLogger("asyncio").error("Task exception was never retrieved", exc_info=CommClosedError("late"))
        assert capsys.readouterr().err == ""
        logging.getLogger("asyncio").error("something else")
        assert "something else" in capsys.readouterr().err
        with pytest.raises(ValueError), quiet_shutdown():
            raise ValueError("not a closed connection")
    finally:
        root.removeHandler(handler)


# --------------------------------------------------------------------------- metres, off the nominal geometry

def _reference_machine_recording(robot_name, seed=0):
    """A recording of ``robot_name`` as ``pipeline.run --robot NAME`` makes it, kinematically (no
    MuJoCo): the reference errors injected (up to 2.5 tolerances on the 6-RUS), the reference
    experiment's calibration poses and 50 held-out ones, 1 um position noise, commands of the nominal
    geometry."""
    from calib.robots import default_robot, reference_errors

    robot = default_robot(robot_name)
    seeds = np.random.SeedSequence(seed).spawn(4)
    actual = robot.table.nominal + reference_errors(robot, int(seeds[3].generate_state(1)[0]))
    targets = np.vstack([reachable_poses(robot, 20, seeds[0]), reachable_poses(robot, 50, seeds[1])])
    joints = robot.inverse_kinematics(robot.table.nominal, targets)
    noise = SensorNoise(0.001, 0.0)
    rng = np.random.default_rng(seeds[2])
    measured = robot.forward_kinematics(actual, joints, initial=targets) + noise.sample(len(targets), rng,
                                                                                       robot.pose_units)
    return Recording(robot=robot, noise=noise, t_s=np.arange(70.0), joints=joints, measured=measured,
                     sets=np.array(["calibration"] * 20 + ["validation"] * 50), meta={})


@pytest.mark.parametrize("robot_name", ROBOT_NAMES)
def test_positions_in_metres_off_the_nominal_geometry_are_refused_before_any_fit(robot_name, tmp_path, capsys,
                                                                                 monkeypatch):
    """A machine off its nominal geometry (the reference errors) with its positions in metres: refused
    by the checks, naming the columns and the unit, before the run's first fit (before: the 6-RUS
    went on to the instrument fit, "forward kinematics met a singular configuration at row 12").
    On the Delta and the 6-RUS (revolute joints) a machine a thousand times smaller fits the file
    as written: the message says it fits only implausibly, its chi-square within the limit beside
    that claim, never "it does not" beside a chi-square that fits."""
    import calib.identification

    def no_fit(*args, **kwargs):
        raise AssertionError("the run fitted the file before its checks refused it")

    monkeypatch.setattr(calib.identification, "instrument_fit", no_fit)
    rec = _reference_machine_recording(robot_name)
    measured = rec.measured.copy()
    measured[:, :3] /= 1000.0
    path, _ = write_recording(tmp_path / "rec.csv", replace(rec, measured=measured))
    out = tmp_path / "out"
    out.mkdir()
    line = refused(["--real", str(path)], out, capsys, "rec.csv: columns x_mm, y_mm, z_mm",
                   "the positions seem to be in metres", "(positions times 1000)", "a recording holds mm")
    written = line.split(" and as written ", 1)[1]
    chi2, limit = (float(v) for v in
                   re.search(r"chi-square (\S+) per degree of freedom \(limit ([^)]+)\)", written).groups())
    assert written.startswith("it does not (" if chi2 > limit else "it fits only implausibly ("), line
    assert chi2 > limit or "moved" in written, line


# --------------------------------------------------------------------------- absurd noise flags

NOISE_COMMANDS = {"pipeline.run": lambda out: ["--out", str(out), "--quiet"],
                  "pipeline.study": lambda out: ["--trials", "2", "--summary-json", str(out / "s.json")],
                  "pipeline.design": lambda out: ["--poses", "12", "--out", str(out / "d.csv")]}


@pytest.mark.parametrize("command", list(NOISE_COMMANDS))
@pytest.mark.parametrize("robot_name", ROBOT_NAMES)
@pytest.mark.parametrize("flag", ["--noise-mm", "--noise-rad", "--noise-joint"])
@pytest.mark.parametrize("value", ["1e300", "above"])
def test_an_absurd_noise_flag_is_refused_naming_the_range_that_fits(command, robot_name, flag, value, tmp_path,
                                                                   capsys):
    """A sensor noise no measurement of the machine can have (1e300; just above the bound of
    :func:`pipeline.workflows.options.noise_limits`): exit 2, one line naming the flag and the
    range that would fit, nothing written (before, ``pipeline.run --noise-mm 1e300``: LAPACK's
    "illegal value" twice on stdout, an overflow warning, "SVD did not converge"; ``--noise-joint
    1e300``: an OverflowError's traceback)."""
    import importlib

    from calib.robots import default_robot
    from pipeline.workflows.options import noise_limits

    limit, unit, _ = noise_limits(default_robot(robot_name))[flag]
    text = value if value == "1e300" else repr(limit * (1 + 1e-9))
    out = tmp_path / "out"
    out.mkdir()
    code = importlib.import_module(command).main(["--robot", robot_name, flag, text] + NOISE_COMMANDS[command](out))
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in captured.err, captured.err
    assert "DLASCL" not in captured.out and "Warning" not in captured.err
    assert lines[0].startswith(f"error: {flag} {float(text):g}: ") and f"between 0 and {limit:.4g} {unit} would fit" \
        in lines[0], lines[0]
    assert list(out.iterdir()) == []


@pytest.mark.parametrize("robot_name", ROBOT_NAMES)
def test_noise_at_its_bound_is_accepted(robot_name):
    """The bound itself is no refusal: every flag at its limit passes the check."""
    from calib.robots import default_robot
    from pipeline.workflows.options import check_noise_flags, noise_limits

    robot = default_robot(robot_name)
    limits = {flag: lim for flag, (lim, _, _) in noise_limits(robot).items()}
    check_noise_flags(robot, SensorNoise(limits["--noise-mm"], limits["--noise-rad"], joint=limits["--noise-joint"]))
