"""The terminal summary and the Rerun markdown are two renderings of one report
(pipeline.report.model, report_text): every figure a summary holds (the verdict's words, the
held-out RMS, mean and max before and after, the implausible parameters, the flagged rows, the
effects' coefficients) appears in both, as the summary dict has it (read from the dict here, not
from the model); the summary JSON carries the same model.

Summaries of real runs: a simulated hexapod's recording with two gross rows and a declared
tolerance its geometry errors exceed (``pipeline.run --real``), the same recording without its
validation rows (cross-validated figures), and a discovery on a recording with a dead band, two
gross rows and a tight declared tolerance."""

import json
from dataclasses import replace

import pytest

from pipeline.formats import read_recording, write_recording
from pipeline.report import REPORT_KEY, report_markdown, terminal_lines
from pipeline.report.calibration import without_file
from pipeline.report.text import DISCOVERY_IMPLAUSIBLE_LINES, IMPLAUSIBLE_LINES
from pipeline.run import run

#: Declared tolerance the simulated machine's errors (tens of um) exceed many times over.
TIGHT = "mm=0.0005,rad=0.000005"


@pytest.fixture(autouse=True)
def _home(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))  # rerun writes analytics under HOME


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A simulated hexapod's recording (30 calibration rows, 10 validation rows), rows 6 and 19
    (1-based) lifted by 5 mm: gross."""
    out = tmp_path_factory.mktemp("report_text")
    run(["--poses", "30", "--heldout", "10", "--seed", "3", "--out", str(out), "--name", "sim", "--quiet"])
    rec = read_recording(out / "sim.csv")
    measured = rec.measured.copy()
    measured[[5, 18], 2] += 5.0
    write_recording(out / "gross.csv", replace(rec, measured=measured))
    cal = rec.sets == "calibration"
    write_recording(out / "nocv.csv", replace(rec, t_s=rec.t_s[cal], joints=rec.joints[cal], measured=measured[cal],
                                              sets=rec.sets[cal], sessions=rec.sessions[cal]))
    return out


@pytest.fixture(scope="module")
def heldout_run(recording):
    out = recording
    summary_json = out / "gross.summary.json"
    res = run(["--real", str(out / "gross.csv"), "--tolerance", TIGHT, "--out", str(out), "--name", "g", "--quiet",
               "--summary-json", str(summary_json)])
    return res, json.loads(summary_json.read_text())


@pytest.fixture(scope="module")
def crossvalidated_run(recording):
    out = recording
    return run(["--real", str(out / "nocv.csv"), "--tolerance", TIGHT, "--out", str(out), "--name", "cv",
                "--quiet"])


@pytest.fixture(scope="module")
def discovery():
    from pipeline.simulation import effect_recording
    from pipeline.workflows.discovery import discover

    rec = effect_recording("joint_friction", 3, n_poses=60)
    measured = rec.measured.copy()
    measured[[7, 30], 2] += 0.5  # isolated gross rows 8 and 31
    rec = replace(rec, measured=measured, meta=dict(rec.meta, parameter_tolerance={"mm": 0.002, "rad": 2e-5}))
    return discover(rec, resim=False)


def renderings(report) -> tuple[str, str]:
    """The terminal's and the Rerun panel's renderings of a report."""
    return "\n".join(terminal_lines(report)), report_markdown(report)


def in_both(texts, value: str, what: str) -> None:
    for name, text in zip(("terminal", "markdown"), texts):
        assert value in text, f"{what} {value!r} is not in the {name} rendering"


def um(v_mm: float, scale: float = 1e3) -> str:
    return f"{scale * v_mm:.3f}"


def test_a_calibration_with_heldout_poses_says_every_figure_in_both(heldout_run):
    res, _ = heldout_run
    s = res.summary
    texts = renderings(res.report)
    assert s["verdict"]["words"] and not s["success"]  # the tolerance is contradicted: not calibrated
    in_both(texts, s["verdict"]["words"], "verdict")
    for key, scale in (("heldout_position_error_mm", 1e3), ("heldout_orientation_error_rad", 1e6)):
        for when in ("before", "after"):
            for fig in ("rms", "mean", "max"):
                in_both(texts, um(s[key][f"{when}_figures"][fig], scale), f"{key} {when} {fig}")
    assert s["flagged_poses"] == [6, 19]
    in_both(texts, "6, 19", "flagged rows")
    implausible = s["implausible_parameters"]
    assert len(implausible) > IMPLAUSIBLE_LINES  # a headline, a few, the count of the rest
    for item in implausible[:IMPLAUSIBLE_LINES]:
        in_both(texts, item["words"], "implausible parameter")
    in_both(texts, f"{len(implausible)} parameters far beyond the tolerance", "implausible count")
    in_both(texts, f"{len(implausible) - IMPLAUSIBLE_LINES} more in the summary JSON", "implausible rest")
    terminal = texts[0]
    assert terminal.splitlines()[1].lstrip().startswith("NOT A SUCCESS: ")  # the verdict first
    assert "6, 19 (gross: left out before any fit)" in terminal and s["gross_rows"]["left_out"]


def test_a_calibration_without_heldout_poses_says_its_crossvalidated_figures_in_both(crossvalidated_run):
    s = crossvalidated_run.summary
    assert s["heldout_position_error_mm"] is None and s["crossvalidation"]  # no held-out poses: cross-validated
    texts = renderings(crossvalidated_run.report)
    in_both(texts, s["verdict"]["words"], "verdict")
    in_both(texts, s["crossvalidation"]["scheme"], "cross-validation scheme")
    for key, scale in (("crossvalidated_position_error_mm", 1e3), ("crossvalidated_orientation_error_rad", 1e6)):
        for fig in ("rms", "mean", "max"):
            in_both(texts, um(s[key][fig], scale), f"{key} {fig}")
    for item in s["implausible_parameters"][:IMPLAUSIBLE_LINES]:
        in_both(texts, item["words"], "implausible parameter")


def test_a_discovery_says_every_figure_in_both(discovery):
    s = discovery.summary
    texts = renderings(discovery.report)
    terminal, markdown = texts
    assert terminal.splitlines()[0] == s["verdict"]  # the verdict first
    in_both(texts, s["verdict"], "verdict")
    in_both(texts, um(s["heldout_rms_before_mm"]), "held-out RMS before")
    in_both(texts, um(s["heldout_rms_after_mm"]), "held-out RMS after")
    per = s["heldout_per_row"]
    for key in ("before_mean_mm", "after_mean_mm", "before_max_mm", "after_max_mm"):
        in_both(texts, um(per[key]), f"held-out {key}")
    assert s["flagged_poses"] == [8, 31]
    in_both(texts, "8, 31", "flagged rows")
    imp = s["implausible_parameters"]
    assert imp["words"] and imp["with_effects"]
    for words in imp["words"][:DISCOVERY_IMPLAUSIBLE_LINES]:
        in_both(texts, words, "implausible with the geometry alone")
    for item in imp["with_effects"]:
        in_both(texts, item["words"], "still implausible with the effects")
    assert s["effects"] == ["joint_friction"]
    dead_band = s["effect_parameters"]["joint_friction"]["dead_band"]
    assert f"dead_band = {dead_band['value']:.6g} +- {dead_band['std']:.2g} mm" in terminal
    assert f"| joint_friction | dead_band | {dead_band['value']:.4g} | {dead_band['std']:.2g} | mm |" in markdown
    assert markdown.startswith("# NOT explained" if not s["explained"] else "# Explained")


def test_the_summary_json_carries_the_report(heldout_run):
    res, written = heldout_run
    s = res.summary
    model = written.pop(REPORT_KEY)
    assert written.keys() <= s.keys()  # today's keys kept; the model beside them
    # the report the run returns, but that the file does not list itself
    assert model == json.loads(json.dumps(without_file(res.report, "summary_json").to_dict()))
    figures = model["heldout"]["figures"][0]
    assert figures["quantity"] == "position" and not figures["crossvalidated"]
    for when in ("before", "after"):
        for fig in ("rms", "mean", "max"):
            assert figures[when][fig] == s["heldout_position_error_mm"][f"{when}_figures"][fig]
    assert model["flagged"]["rows"] == s["flagged_poses"] and model["verdict"]["words"] == s["verdict"]["words"]


def test_a_summary_without_a_verdict_or_a_fit_renders():
    """The report of a calibration file alone (pipeline.export --to report: no verdict judged, no
    fit): words for what there is, nothing invented."""
    from pipeline.report import model

    report = model.Report(kind="calibration", source=model.Source("delta", "chain", "a recording"),
                          verdict=model.Verdict(None, None), fit=None, truth=None, parameters=None, determination=None,
                          implausible=model.Implausible(), heldout=None, frames=None, effects=None,
                          flagged=model.Flagged(rows=()))
    terminal, markdown = renderings(report)
    assert terminal.splitlines() == ["Calibration of the delta - a recording",
                                     "  flagged data rows (row k = file line k + 1): none"]
    assert "method" not in markdown and "Stop:" not in markdown
