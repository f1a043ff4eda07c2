"""A discovery's report is made from its objects (:mod:`pipeline.report.discovery`, issue 47
point 2), per robot: its sections hold what the discovery found (the Discovery, its held-out
judgement), the summary's keys say the same figures, and nothing in it is read from the summary
dict (changing the summary after the fact changes no section). The read's findings and the
files enter with :func:`with_read` and :func:`with_files`; the report survives its JSON form.
"""

from __future__ import annotations

import copy
import dataclasses

import pytest

from pipeline.report import Report
from pipeline.report.discovery import with_files, with_read

#: Robots and the effect each one's recording is made with.
CASES = [("hexapod", "joint_friction"), ("delta", "compliance"), ("rus", "actuator_scale")]


@pytest.fixture(scope="module", params=CASES, ids=[r for r, _ in CASES])
def found(request):
    from pipeline.simulation import effect_recording
    from pipeline.workflows.discovery import discover

    robot, effect = request.param
    return discover(effect_recording(effect, 1, robot=robot), resim=False)


def test_the_sections_hold_what_the_discovery_found(found):
    report, disc, judgement = found.report, found.discovery, found.outcome.judgement
    assert report.kind == "discovery" and report.source.robot == found.recording.robot.name
    assert report.verdict.success == bool(disc.explained)
    assert [e.name for e in report.effects.effects] == list(disc.effects)
    assert report.effects.remaining.follows == tuple(disc.remaining.follows)
    closure = report.heldout.figures[0]
    assert (closure.before.rms, closure.after.rms) == (judgement.geometry.unshifted_rms_mm,
                                                       judgement.model.unshifted_rms_mm)
    assert report.heldout.per_pose[0].rows == tuple(int(i) + 1 for i in judgement.fold.held)
    assert report.flagged.rows == tuple(i + 1 for i in disc.flagged)
    assert report.source.rows == found.recording.joints.shape[0]


def test_the_summary_says_the_reports_figures(found):
    s, report = found.summary, found.report
    assert s["verdict"] == report.verdict.words and s["explained"] == report.verdict.success
    assert s["effects"] == [e.name for e in report.effects.effects]
    assert (s["heldout_rms_before_mm"], s["heldout_rms_after_mm"]) == (report.heldout.figures[0].before.rms,
                                                                       report.heldout.figures[0].after.rms)
    assert s["flagged_poses"] == list(report.flagged.rows) and s["rows"] == report.source.rows


def test_no_section_is_read_from_the_summary(found):
    from pipeline.report.discovery import discovery_report
    from pipeline.workflows.discovery import discovery_parts

    before = found.report.to_dict()
    kept = copy.deepcopy(found.summary)
    found.summary.clear()  # the summary gone: the report made again from the objects is the same
    try:
        again = discovery_report(found.recording, found.outcome, **discovery_parts(found.recording, found.outcome),
                                 prior_source=found.report.parameters.prior, resimulated=None,
                                 wall_time_s=found.report.timing.total_s)
    finally:
        found.summary.update(kept)
    assert again.to_dict() == before


def test_the_read_and_the_files_enter_the_report(found):
    frame = {"translation_mm": [1.0, 2.0, 3.0], "rotation_rad": [0.0, 0.001, 0.0]}
    block = {"gross_rows": {"rows": [4, 9], "left_out": True}, "measurement_frame": frame,
             "measurement_frame_std": frame}
    cv = {"crossvalidated_position_error_mm": {"rms": 0.5, "mean": 0.4, "max": 0.9},
          "crossvalidation": {"scheme": "leave-one-out", "fits": 12, "model": "the geometry alone", "message": "ok"}}
    read = with_read(found.report, block, ["a warning"], cv)
    assert read.flagged.gross == (4, 9) and read.flagged.gross_left_out
    assert read.frames.rows[0].translation_mm == (1.0, 2.0, 3.0) and not read.frames.sessions
    assert read.heldout.figures[-1].crossvalidated and read.heldout.figures[-1].before.rms == 0.5
    assert read.heldout.crossvalidation.fits == 12 and read.warnings == ("a warning",)
    done = with_files(read, recording="r.csv", files={"rrd": "a.rrd", "report": "r.html", "other": "x"},
                      law_asked=True, law_kept=None, compensation=None)
    assert done.outputs.files == (("rrd", "a.rrd"), ("report", "r.html")) and done.outputs.law_asked
    assert done.source.recording == "r.csv" and done.compensation is None
    assert Report.from_dict(done.to_dict()) == dataclasses.replace(done, discovery=None)  # the record: summary keys
    assert done.discovery.read == block and done.discovery.warnings == ("a warning",)
    assert done.discovery.crossvalidation == cv
