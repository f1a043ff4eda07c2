"""A run's summary written from its report (pipeline.report.summary): the summary JSON's keys are
:func:`summary_keys` of the run's Report, key for key, and its ``report_model`` leaves the run's
record out (the summary's own keys hold it, once)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipeline.report import REPORT_KEY
from pipeline.report.summary import summary_keys

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("argv", [["--robot", "hexapod"], ["--robot", "rus"],
                                  ["--real", str(ROOT / "examples" / "table4.csv")]], ids=["hexapod", "rus", "table4"])
def test_the_summary_json_is_the_reports_summary_keys(argv, tmp_path):
    from pipeline.run import run

    path = tmp_path / "s.json"
    res = run([*argv, "--out", str(tmp_path), "--summary-json", str(path), "--quiet"])
    written = json.loads(path.read_text())
    model = written.pop(REPORT_KEY)
    assert written == json.loads(json.dumps(summary_keys(res.report)))
    assert {k: v for k, v in res.summary.items() if k != "summary_json"} == summary_keys(res.report)
    assert res.report.run is not None and "run" not in model
    record = res.report.run
    assert written["identified_errors"] == dict(record.identified_errors)
    assert written["free_parameters"] == [p.name for p in res.report.parameters.rows]
    assert written["implausible_parameters"] == [{"name": i.name, "error": i.error, "tolerance": i.tolerance,
                                                  "unit": i.unit, "words": i.words} for i in record.implausible]


@pytest.mark.slow
@pytest.mark.parametrize("robot,effect", [("hexapod", "joint_friction"), ("rus", "actuator_scale")])
def test_a_discoverys_summary_json_is_its_reports_discovery_summary_keys(robot, effect, tmp_path):
    """``pipeline.discover --summary-json`` (a recording read as a run reads it, its report and
    kept law asked) writes :func:`discovery_summary_keys` of the discovery's Report, key for key
    and in order; its ``report_model`` leaves the discovery's record out."""
    from pipeline.discover import run
    from pipeline.formats import write_recording
    from pipeline.report.summary import discovery_summary_keys
    from pipeline.simulation import effect_recording

    path, _ = write_recording(tmp_path / "r.csv", effect_recording(effect, 1, robot=robot))
    summary = tmp_path / "s.json"
    res = run(["--real", str(path), "--no-resim", "--out", str(tmp_path), "--summary-json", str(summary),
               "--report", str(tmp_path / "r.html"), "--law", str(tmp_path / "law.json")])
    written = json.loads(summary.read_text())
    model = written.pop(REPORT_KEY)
    keys = discovery_summary_keys(res.report)
    assert list(written) == list(keys) and written == json.loads(json.dumps(keys))
    assert res.summary == keys and "discovery" not in model and res.report.discovery is not None
    assert written["effects"] == [e.name for e in res.report.effects.effects]
    assert written["recording"] == str(path) and written["report"] == str(tmp_path / "r.html")
    assert "warnings" in written and "law_kept" in written and "compensation" in written
