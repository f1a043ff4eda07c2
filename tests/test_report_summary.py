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
