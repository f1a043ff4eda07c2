"""The selection's evidence and the aliases it reports, typed (a room of
:mod:`calib.effects.discovery`): per candidate form alone, the steps of the stepwise selection,
the chosen model's cross-validated residual and each named effect's granularity
(:func:`selection_evidence`), the pairs the data could not tell apart (:class:`Alias`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

__all__ = ["Alias", "GeometryTest", "GeometryEvidence", "CandidateEvidence", "SelectionStep", "Evidence",
           "selection_evidence"]


@dataclass(frozen=True)
class Alias:
    """A pair the data could not tell apart: the effect ``named`` and its ``rival``, the BIC gap
    between them, the largest canonical correlation of their regressors; ``nested``: the rival
    generalises the effect named, which is named because the rival's extra parameters did not gain
    :data:`calib.effects.selection.MIN_NESTED_DELTA_BIC` (``delta_bic`` is then the rival's gain,
    positive)."""

    named: str
    rival: str
    delta_bic: float
    correlation: float
    nested: bool

    def to_dict(self) -> dict:
        """JSON-ready (an entry of the summary's ``aliases``)."""
        return {"named": self.named, "rival": self.rival, "delta_bic": self.delta_bic,
                "correlation": self.correlation, "nested": self.nested}


@dataclass(frozen=True)
class GeometryTest:
    """The geometry-only fit's chi-square test against the declared noise, at ``alpha``."""

    chi2: float
    dof: float
    p_value: float
    alpha: float


@dataclass(frozen=True)
class GeometryEvidence:
    """The reference (``none``: the geometry alone): its chi-square test, parameters, BIC and
    cross-validated whitened RMS."""

    chi2: float
    dof: float
    p_value: float
    n_params: int
    bic: float
    delta_bic_vs_none: float
    cv_whitened_rms: float


@dataclass(frozen=True)
class CandidateEvidence:
    """One candidate form's evidence (``form``: :func:`calib.effects.granularity.form_key`): alone
    against the geometry (linearised chi-square, parameters, BIC gain, cross-validated whitened
    RMS) and the BIC gain when it entered the model; None where not so (a form named but not
    fitted alone holds its entry's gain alone)."""

    form: str
    chi2_linearised: float | None = None
    n_params: int | None = None
    delta_bic_vs_none: float | None = None
    cv_whitened_rms: float | None = None
    delta_bic_when_added: float | None = None

    def to_dict(self) -> dict:
        """JSON-ready: the figures it holds."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name != "form" and getattr(self, f.name) is not None}


@dataclass(frozen=True)
class SelectionStep:
    """One step of the stepwise selection: the form ``added`` (None: none entered, the selection
    stopped), those ``dropped`` as redundant, and each tried form's BIC gain ``(form, gain)``."""

    added: str | None
    dropped: tuple
    delta_bic: tuple

    def to_dict(self) -> dict:
        return {"added": self.added, "dropped": list(self.dropped), "delta_bic": dict(self.delta_bic)}


@dataclass(frozen=True)
class Evidence:
    """The discovery's evidence (:func:`selection_evidence`).

    Attributes:
        geometry_test: the geometry-only chi-square test (:class:`GeometryTest`).
        geometry: the reference ``none`` (:class:`GeometryEvidence`).
        candidates: each candidate form's (:class:`CandidateEvidence`), in the order tried.
        steps: the selection's steps (:class:`SelectionStep`).
        cv_whitened_rms_chosen: the chosen model's cross-validated whitened RMS.
        granularity: ``(effect, granularity)`` of each named effect.
        nested_replaced: ``(form, form named in its place)`` of the nested reviews.
        dropped_not_significant: per round, the forms found not significant (Wald test).
    """

    geometry_test: GeometryTest
    geometry: GeometryEvidence
    candidates: tuple
    steps: tuple
    cv_whitened_rms_chosen: float
    granularity: tuple
    nested_replaced: tuple = ()
    dropped_not_significant: tuple = ()

    @property
    def forms(self) -> tuple:
        """``none`` and every candidate form with evidence."""
        return ("none",) + tuple(c.form for c in self.candidates)

    def of(self, form: str) -> CandidateEvidence | None:
        """The evidence of the candidate ``form`` (None: it has none)."""
        return next((c for c in self.candidates if c.form == form), None)

    def delta_bic_when_added(self, form: str) -> float | None:
        """The BIC gain of ``form`` when it entered the model (None: it did not, or has no evidence)."""
        c = self.of(form)
        return None if c is None else c.delta_bic_when_added

    def to_dict(self) -> dict:
        """JSON-ready (the summary's ``evidence``): ``geometry_chi2_test``, ``none``, each form's
        figures under its key, ``steps``, ``cv_whitened_rms_chosen``, ``granularity`` and, when
        any, ``nested_replaced`` and ``dropped_not_significant``."""
        out = {"geometry_chi2_test": vars(self.geometry_test).copy(), "none": vars(self.geometry).copy()}
        out.update((c.form, c.to_dict()) for c in self.candidates)
        out["steps"] = [s.to_dict() for s in self.steps]
        out["cv_whitened_rms_chosen"] = self.cv_whitened_rms_chosen
        out["granularity"] = dict(self.granularity)
        if self.nested_replaced:
            out["nested_replaced"] = [list(p) for p in self.nested_replaced]
        if self.dropped_not_significant:
            out["dropped_not_significant"] = [list(w) for w in self.dropped_not_significant]
        return out


def selection_evidence(geo, sel: dict, models: dict, fit, alpha: float) -> Evidence:
    """The discovery's evidence from the selection ``sel``
    (:func:`calib.effects.selection.choose_effects`): per candidate form alone (keys as in
    :func:`calib.effects.selection.candidate_forms`), the selection's steps, the chosen model's
    cross-validated residual and each named effect's granularity. ``geo``: the geometry-only fit;
    ``fit``: the chosen model's (:class:`calib.effects.EffectFit`)."""
    found = {name: {"chi2_linearised": e["chi2"], "n_params": e["n_params"],
                    "delta_bic_vs_none": e["delta_bic_vs_none"], "cv_whitened_rms": e["cv_whitened_rms"]}
             for name, e in sel["single"].items()}
    replaced = dict(sel.get("nested_replaced", []))
    for step in sel["steps"]:
        if step["added"] in found:
            found[step["added"]]["delta_bic_when_added"] = step["trials"][step["added"]]["delta_bic"]
        new = replaced.get(step["added"])
        if new in found and new in step["trials"]:  # named in its family member's place
            found[new]["delta_bic_when_added"] = step["trials"][new]["delta_bic"]
    for key, m in models.items():  # a per-chain form named: its evidence under the effect's name too
        if m in fit.models and key != m.name and "delta_bic_when_added" in found.get(key, {}):
            found.setdefault(m.name, {})["delta_bic_when_added"] = found[key]["delta_bic_when_added"]
    return Evidence(
        geometry_test=GeometryTest(geo.chi2, geo.dof, geo.p_value, alpha),
        geometry=GeometryEvidence(geo.chi2, geo.dof, geo.p_value, geo.n_params, geo.bic(), 0.0, sel["cv_geometry"]),
        candidates=tuple(CandidateEvidence(form, **e) for form, e in found.items()),
        steps=tuple(SelectionStep(s["added"], tuple(s["dropped"]),
                                  tuple((k, v["delta_bic"]) for k, v in s["trials"].items())) for s in sel["steps"]),
        cv_whitened_rms_chosen=sel["cv_chosen"],
        granularity=tuple((m.name, m.granularity) for m in fit.models),
        nested_replaced=tuple(replaced.items()),
        dropped_not_significant=tuple(tuple(w) for w in sel.get("insignificant", ())))
