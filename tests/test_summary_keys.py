"""The summary keys docs/commands.md documents (scripts read them), held against a run, a real run,
a discovery and a fleet: each key the docs name is there, with the meaning they give it (issue 47,
point 2: the report built from the objects must keep every documented key's name and meaning).

The keys are read from the docs' own paragraphs; a key the docs add or drop makes
:func:`test_the_docs_name_the_keys_held_here` fail until it is held here too.
"""

from __future__ import annotations

import csv
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from calib.robots import default_robot
from pipeline.discover import main as discover_main
from pipeline.formats import sidecar_path
from pipeline.run import main as run_main
from pipeline.workflows.fleet import run_fleet

ROOT = Path(__file__).resolve().parent.parent
COMMANDS = (ROOT / "docs" / "commands.md").read_text()

#: Where docs/commands.md documents each summary: ``(first words, words after the paragraph)``.
PARAGRAPHS = {
    "run": ("The summary\n(printed, and with `--summary-json`", "Calibrate a real machine"),
    "real": ("**Instrument frames and trackers.**", "**Tolerances as priors."),
    "discover": ("The summary (`--summary-json`) has `explained`", "The `.rrd` (`recordings/<name>_discover.rrd`"),
    "fleet": ("`python -m pipeline.fleet FOLDER --out DIR` calibrates", "## Layout"),
}

#: pipeline.run's top-level summary keys the docs name; with a simulated machine (truth known,
#: held-out poses simulated) all but the cross-validated ones, the recording's and the shift's.
RUN_KEYS = {"success", "verdict", "identified_errors", "identified_std", "parameter_determination", "left_to_prior",
            "heldout_position_error_mm", "heldout_orientation_error_rad", "gross_rows", "flagged_poses",
            "implausible_parameters", "parameter_error", "gain_G_percent", "condition_numbers", "message",
            "wall_time_split_s"}
#: Only a recording without validation rows has these (instead of the held-out ones).
CROSSVALIDATED_KEYS = {"crossvalidated_position_error_mm", "crossvalidated_orientation_error_rad"}
#: Keys inside the held-out blocks (``before_figures``/``after_figures``: RMS, mean and max).
HELDOUT_KEYS = {"before", "after", "max_after", "before_figures", "after_figures"}
FIGURE_KEYS = {"rms", "mean", "max"}
#: A parameter's determination: its posterior std and what determined it.
DETERMINATION_SOURCES = {"data", "prior"}
#: A session's shift (``session_shifts``), and the keys of each unknown of its ``shift``.
SHIFT_KEYS = {"model", "shift", "undetermined", "log_evidence", "chi2", "p_no_shift", "mean_position_error_mm",
              "words"}
SHIFT_VALUE_KEYS = {"value", "std", "unit"}
SHIFT_MODELS = {"joint zeros", "instrument frame"}
#: The instrument frame a recording was registered in.
FRAME_KEYS = {"translation_mm", "rotation_rad"}
#: pipeline.discover's top-level summary keys, and those of its ``remaining``.
DISCOVER_KEYS = {"explained", "verdict", "remaining", "effects", "partial", "aliases", "effect_parameters",
                 "flagged_poses", "outliers", "evidence", "heldout_rms_before_mm", "heldout_rms_after_mm",
                 "noise_floor_mm", "tests", "located", "mujoco_resimulation"}
REMAINING_KEYS = {"rms_mm", "noise_floor_mm", "noise_ratio", "chains", "follows", "does_not_follow", "summary"}
#: fleet.csv's columns the docs name, and the words of its ``verdict`` and ``explained``.
FLEET_COLUMNS = {"machine", "robot", "verdict", "poses", "heldout_before_um", "heldout_after_um", "flagged_rows",
                 "explained", "wall_s"}


def documented(kind: str) -> set[str]:
    """Every ``code`` span of the docs' paragraph on the summary of ``kind`` (newlines as spaces)."""
    start, end = PARAGRAPHS[kind]
    i = COMMANDS.index(start)
    text = COMMANDS[i:COMMANDS.index(end, i)]
    return {" ".join(s.split()) for s in re.findall(r"`([^`]+)`", text)}


def test_the_docs_name_the_keys_held_here():
    """Every key the docs name is one this module holds against a real summary (flags, values and
    file names aside)."""
    run_words = (RUN_KEYS | CROSSVALIDATED_KEYS | HELDOUT_KEYS | DETERMINATION_SOURCES | SHIFT_KEYS | SHIFT_VALUE_KEYS
                 | SHIFT_MODELS | {"session_shifts"})
    assert documented("run") - {"--summary-json"} == run_words
    assert {"gross_rows", "measurement_frame"} <= documented("real")
    assert documented("discover") - {"--summary-json", "Explained: geometry + joint_friction", "[]",
                                     "mujoco.sysid"} == DISCOVER_KEYS | REMAINING_KEYS
    assert {"verdict", "explained", "success", "fleet.csv"} <= documented("fleet")


def is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def hold_figures(block: dict):
    assert set(block) >= FIGURE_KEYS, block
    assert all(is_number(block[k]) and block[k] >= 0 for k in FIGURE_KEYS), block
    assert block["mean"] <= block["max"] and block["rms"] <= block["max"]


def hold_heldout(block: dict):
    assert set(block) >= HELDOUT_KEYS, block
    hold_figures(block["before_figures"])
    hold_figures(block["after_figures"])
    assert block["before"] == block["before_figures"]["mean"] and block["after"] == block["after_figures"]["mean"]
    assert block["max_after"] == block["after_figures"]["max"]


def hold_run(s: dict, robot_name: str, *, truth: bool, heldout: bool = True):
    """The documented keys of a ``pipeline.run`` summary, with their documented meaning."""
    names = set(default_robot(robot_name).table.names)
    expected = RUN_KEYS - ({"heldout_position_error_mm", "heldout_orientation_error_rad"} if not heldout else set())
    assert expected <= set(s), expected - set(s)
    assert isinstance(s["success"], bool)
    assert isinstance(s["verdict"]["words"], str) and s["verdict"]["words"]
    assert isinstance(s["verdict"]["evidence"], dict)
    for key in ("identified_errors", "identified_std"):
        assert set(s[key]) == names and all(is_number(v) for v in s[key].values()), key
    det = s["parameter_determination"]
    assert set(det) <= names and det
    for d in det.values():
        assert d["source"] in DETERMINATION_SOURCES | {"held"}, d
        assert d["posterior_std"] is None or d["posterior_std"] >= 0, d
    assert isinstance(s["left_to_prior"], list) and all(isinstance(c, str) for c in s["left_to_prior"])
    if heldout:
        hold_heldout(s["heldout_position_error_mm"])
        if s["heldout_orientation_error_rad"] is not None:
            hold_heldout(s["heldout_orientation_error_rad"])
    assert all(isinstance(r, int) and r >= 1 for r in s["flagged_poses"])  # 1-based data rows
    assert isinstance(s["implausible_parameters"], list)
    assert all({"name", "words"} <= set(d) for d in s["implausible_parameters"])
    if truth:
        assert {"rms_mm", "rms_rad"} <= set(s["parameter_error"]) and {"mean", "norm"} <= set(s["gain_G_percent"])
    else:
        assert s["parameter_error"] is None and s["gain_G_percent"] is None, "no truth, no error against it"
    assert s["condition_numbers"] and all(is_number(c) and c >= 1 for c in s["condition_numbers"])
    assert isinstance(s["message"], str)
    assert s["wall_time_split_s"] and all(is_number(v) and v >= 0 for v in s["wall_time_split_s"].values())


@pytest.mark.parametrize("robot_name", ["hexapod", "delta"])
def test_a_simulated_run_has_every_documented_key(robot_name, tmp_path):
    path = tmp_path / "s.json"
    argv = ["--out", str(tmp_path), "--summary-json", str(path), "--quiet"]
    assert run_main(argv + ([] if robot_name == "hexapod" else ["--robot", robot_name])) == 0
    s = json.loads(path.read_text())
    hold_run(s, robot_name, truth=True)
    assert s["gross_rows"] is None, "a simulated run searches no gross rows"
    assert not CROSSVALIDATED_KEYS & set(s), "held-out poses, no cross-validation"


def test_a_recording_without_validation_rows_has_the_crossvalidated_keys(tmp_path):
    """A recording of calibration rows only: the cross-validated prediction errors (RMS, mean, max)
    stand for the held-out ones; its gross rows are named (none here) as 1-based rows."""
    assert run_main(["--poses", "30", "--heldout", "0", "--out", str(tmp_path), "--name", "cal", "--quiet"]) == 0
    path = tmp_path / "s.json"
    assert run_main(["--real", str(tmp_path / "cal.csv"), "--out", str(tmp_path), "--summary-json", str(path),
                     "--quiet"]) == 0
    s = json.loads(path.read_text())
    hold_run(s, "hexapod", truth=True, heldout=False)
    assert s["heldout_position_error_mm"] is None
    hold_figures(s["crossvalidated_position_error_mm"])
    hold_figures(s["crossvalidated_orientation_error_rad"])
    assert s["gross_rows"]["rows"] == [] and not s["flagged_poses"]


def test_a_recording_in_an_instrument_frame_has_its_measurement_frame(tmp_path):
    """A recording measured in an instrument's frame (examples/two_days, converted): the frame
    registered, ``{"translation_mm": [x, y, z], "rotation_rad": [a, b, c]}``."""
    from pipeline.convert import main as convert_main

    days = ROOT / "examples" / "two_days"
    assert convert_main([str(days / "grid.csv"), str(days / "feb12.csv"), "--map", str(days / "map.toml"),
                         "--out", str(tmp_path / "days")]) == 0
    path = tmp_path / "s.json"
    assert run_main(["--real", str(tmp_path / "days.csv"), "--out", str(tmp_path), "--summary-json", str(path),
                     "--quiet"]) == 0
    s = json.loads(path.read_text())
    hold_run(s, "hexapod", truth=False)
    frame = s["measurement_frame"]
    assert set(frame) == FRAME_KEYS and all(len(frame[k]) == 3 for k in FRAME_KEYS)
    assert np.linalg.norm(frame["translation_mm"]) > 1.0, "the example's instrument sits tens of mm away"


@pytest.mark.slow
def test_a_session_shifted_as_a_whole_has_its_session_shifts(tmp_path):
    """The re-homed twin (tests/rehomed_twin.py): day 2's validation rows sit shifted; pipeline.run
    names the shift by session, its model, each unknown's value, std and unit."""
    from tests.rehomed_twin import rehomed_twin

    twin = rehomed_twin(tmp_path)
    path = tmp_path / "s.json"
    assert run_main(["--real", str(twin.csv), "--out", str(tmp_path), "--summary-json", str(path), "--quiet"]) == 0
    s = json.loads(path.read_text())
    hold_run(s, "hexapod", truth=True)
    shift = s["session_shifts"]["day2"]
    assert set(shift) >= SHIFT_KEYS and shift["model"] in SHIFT_MODELS | {"both"}
    assert all(set(v) >= SHIFT_VALUE_KEYS for v in shift["shift"].values())
    assert 0.0 <= shift["p_no_shift"] <= 1.0 and "day2" in shift["words"]


def test_a_discovery_has_every_documented_key(tmp_path):
    path = tmp_path / "s.json"
    assert discover_main(["--scenario", "joint_friction", "--out", str(tmp_path), "--summary-json", str(path),
                          "--no-resim"]) == 0
    s = json.loads(path.read_text())
    assert DISCOVER_KEYS - {"mujoco_resimulation"} <= set(s), DISCOVER_KEYS - set(s)
    assert REMAINING_KEYS <= set(s["remaining"])
    assert isinstance(s["explained"], bool) and isinstance(s["verdict"], str)
    assert isinstance(s["effects"], list) and set(s["effect_parameters"]) == set(s["effects"])
    for params in s["effect_parameters"].values():
        assert "significance" in params
        assert all({"value", "std"} <= set(v) for k, v in params.items() if k not in ("significance", "granularity"))
    assert all(isinstance(r, int) and r >= 1 for r in s["flagged_poses"])
    assert is_number(s["heldout_rms_before_mm"]) and is_number(s["heldout_rms_after_mm"])
    assert is_number(s["noise_floor_mm"]) and s["noise_floor_mm"] > 0
    assert "mujoco_resimulation" not in s, "--no-resim: nothing re-simulated"


def test_a_fleet_has_the_documented_columns_and_each_machine_its_run_summary(tmp_path):
    """fleet.csv's columns, a calibrated machine's ``verdict`` (``success`` or ``no: CAUSE``) and
    ``explained``, and its summary with the run's documented keys."""
    folder = tmp_path / "in"
    folder.mkdir()
    shutil.copy(ROOT / "examples" / "table4.csv", folder / "table4.csv")
    shutil.copy(sidecar_path(ROOT / "examples" / "table4.csv"), folder / "table4.json")
    rep = run_fleet(folder, tmp_path / "out", workers=1)
    with open(tmp_path / "out" / "fleet.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert FLEET_COLUMNS <= set(rows[0]) and len(rows) == 1
    row = rows[0]
    assert row["verdict"] == "success" or row["verdict"].startswith("no: "), row
    assert re.match(r"(yes|no|n/a): ", row["explained"]), row
    s = json.loads(Path(rep.rows[0]["summary"]).read_text())
    hold_run(s, "hexapod", truth=False)
    assert float(row["heldout_after_um"]) == pytest.approx(1000 * s["heldout_position_error_mm"]["after"], rel=1e-5)


@pytest.mark.parametrize("robot_name", ["hexapod", "rus"])
def test_the_documented_keys_say_what_the_report_says(robot_name, tmp_path):
    """The keys a run's summary shares with its report (pipeline.report.calibration) hold the
    report's figures: the verdict, the fit's stop and conditioning, the flagged rows, what the
    rows left to the prior, the held-out figures (RMS, mean, max before and after)."""
    from pipeline.run import run

    res = run(["--robot", robot_name, "--out", str(tmp_path), "--quiet"])
    s, r = res.summary, res.report
    assert (s["success"], s["verdict"]["words"], s["verdict"]["cause"]) == (r.verdict.success, r.verdict.words,
                                                                           r.verdict.cause)
    assert s["condition_numbers"] == list(r.fit.condition_numbers) and s["iterations"] == r.fit.iterations
    assert s["flagged_poses"] == list(r.flagged.rows) and s["left_to_prior"] == list(r.parameters.left_to_prior)
    rows = {row.quantity: row for row in r.heldout.figures}
    for key, quantity in (("heldout_position_error_mm", "position"), ("heldout_orientation_error_rad", "orientation")):
        if s[key] is None:
            assert quantity not in rows
            continue
        for when in ("before", "after"):
            figures = getattr(rows[quantity], when)
            assert s[key][f"{when}_figures"] == {"rms": figures.rms, "mean": figures.mean, "max": figures.max}
            assert s[key][when] == figures.mean
    assert [p.name for p in r.parameters.rows] == s["free_parameters"]  # the free ones, in table order
    for row in r.parameters.rows:
        d = s["parameter_determination"][row.name]
        assert (row.error, row.source, row.two_sigma) == (d["error"], d["source"], 2 * d["posterior_std"]), row.name
