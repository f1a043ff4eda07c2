"""The words of a calibration's verdict: one table of words per cause (:data:`CAUSE_WORDS`), as
scipy's ``least_squares`` words its status codes.

calib returns a :class:`calib.identification.Verdict`: a cause code and typed evidence (the
figures every verdict rests on, :class:`calib.identification.VerdictEvidence`, and the cause's own
``detail``), no sentence. :func:`verdict_sentence` composes the sentence the summary's
``verdict.words`` carries and the reports print, command-line advice included; the diagnosis'
causes (a conversion, an unmeasured column) are said by the diagnosis' own message.

Pure text: no NumPy.
"""

from __future__ import annotations

from dataclasses import asdict

__all__ = ["CAUSE_WORDS", "NOT_CALIBRATED", "CALIBRATED_PREDICTED", "verdict_sentence", "no_motion_words",
           "implausible_sentence"]

#: What every failed verdict's sentence begins with.
NOT_CALIBRATED = "not calibrated: "
#: Added to the success's sentence where rows the fit did not use were predicted.
CALIBRATED_PREDICTED = " and the {what} are predicted to it"

#: The sentence of each cause (None: the success), formatted with the verdict's evidence
#: (:meth:`calib.identification.VerdictEvidence.to_dict`), its ``detail``'s fields and the
#: phrases :func:`verdict_fields` derives; failures are prefixed :data:`NOT_CALIBRATED`.
CAUSE_WORDS = {
    None: "calibrated: the rows fit to the declared noise{predicted}",
    "no_motion": "the {what} do not move the machine: {rows} of {rows} rows are the same pose (the same joint "
                 "readings), so they say nothing of the {robot}'s geometry; measure poses spread over the workspace",
    "no_information": "the rows determine nothing beyond the tolerance: of the {free} parameters none has its "
                      "standard deviation below half its tolerance, none moved beyond 3 tolerances, and all together "
                      "they determine {determined:.2g} of the {free} directions (noise standard deviation "
                      "{noise:.3g} {noise_unit} against a tolerance of {tolerance}{same}): the geometry reported is "
                      "the prior's, not a measurement; measure more poses, spread over the workspace, or with less "
                      "noise",
    "description": "the fitted errors are a pattern of the description, not physics: {pattern}: the nominal "
                   "geometry{described_in} seems to be another machine's; give this machine's nominal geometry",
    "no_convergence": "the fit did not converge ({message})",
    "gross_search_failed": "the gross-row search could not judge the rows ({message}), and the fit on every row is "
                           "{fit_ratio:.3g} times the declared noise off the model",
    "model_misfit": "the model misfits most rows ({beyond} of {rows} beyond the declared noise even after the "
                    "trimmed fits), so no row can be called gross: physics the geometric model leaves out (run "
                    "python -m pipeline.discover --real {where}) or a mistake in the file",
    "unpredictable_rows": "the model cannot predict the {what} (it cannot reach their joints): a geometry far from "
                          "the nominal one",
    "left_out_physics": "the {what} are {ratio:.3g} times the declared noise off the model: physics the geometric "
                        "model leaves out (run python -m pipeline.discover --real {where}), or noise declared too "
                        "small",
    "conversion": "{diagnosis}",
    "unmeasured column": "{diagnosis}",
}


def verdict_fields(verdict) -> dict:
    """The fields :data:`CAUSE_WORDS` formats: the evidence's figures, the ``detail``'s fields and
    the phrases derived from them (``predicted``, ``what`` of a motionless recording, ``tolerance``,
    ``same``, ``pattern``, ``described_in``, ``diagnosis``)."""
    fields = verdict.evidence.to_dict()
    checked = fields["predictions"]
    fields["predicted"] = CALIBRATED_PREDICTED.format(what=checked["what"]) if checked else ""
    fields["what"] = "calibration rows"
    if verdict.detail is not None:
        fields.update(asdict(verdict.detail))
    if verdict.cause == "no_information":
        detail = verdict.detail
        fields["tolerance"] = ", ".join(f"{value:.3g} {unit}" for value, unit in detail.tolerances)
        fields["same"] = (f"; {detail.same_pose_rows} of {detail.rows} rows are the same pose"
                          if detail.same_pose_rows > 1 else "")
    if verdict.cause == "description":
        fields["pattern"] = "; ".join(p.words() for p in verdict.detail.patterns)
        source = verdict.detail.geometry_source
        fields["described_in"] = f" in {source}" if source else ""
    if verdict.diagnosis is not None:
        fields["diagnosis"] = verdict.diagnosis.message
    return fields


def verdict_sentence(verdict) -> str:
    """The sentence of a :class:`calib.identification.Verdict`, from its cause's row of
    :data:`CAUSE_WORDS` and its evidence."""
    words = CAUSE_WORDS[verdict.cause].format(**verdict_fields(verdict))
    return words if verdict.success else NOT_CALIBRATED + words


def no_motion_words(rows: int, robot: str, what: str = "calibration rows") -> str:
    """The words of ``rows`` rows at one pose (:func:`calib.diagnosis.motionless_rows`) of a ``robot``
    (its name): :data:`CAUSE_WORDS`'s ``"no_motion"``, the ``what`` naming the rows."""
    return CAUSE_WORDS["no_motion"].format(what=what, rows=rows, robot=robot)


def implausible_sentence(e) -> str:
    """An implausible identified error (:class:`calib.prior.ImplausibleError`) in words: its value
    from nominal and how many times its tolerance it is."""
    return (f"{e.name} = {e.error:+.4g} {e.unit} from nominal, {abs(e.error) / e.tolerance:.3g} times its tolerance "
            f"{e.tolerance:.4g} {e.unit}")
