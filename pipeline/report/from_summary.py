"""Transitional: a discovery's report parsed from its summary dict (what :mod:`pipeline.report.model`
was built from before its builders): ``build_report(summary)``, ``summary_document(summary)``. It
goes once the builders make the report from the discovery's objects (a calibration's report is made
from its run's: :mod:`pipeline.report.calibration`)."""

from __future__ import annotations

import math

from .model import (REPORT_KEY, OUTPUT_KEYS, Alias, Candidate, Coefficient, CompensationTable, CrossValidation, EffectRow, Effects, FigureRow, Figures, Flagged, FrameRow, Frames, GeometryTest, Heldout, Implausible, Law, LawConstant, Noise, Outputs, ParameterRow, Parameters, PerPose, PoseFamily, Remaining, Report, Resimulation, Search, Separation, Source, SysId, Timing, Unseparated, Verdict)

__all__ = ["build_report", "report_kind", "summary_document"]


def report_kind(summary: dict) -> str:
    """``discovery`` for a summary of ``pipeline.discover`` (it says whether the data are
    ``explained``), else ``calibration``."""
    return "discovery" if "explained" in summary else "calibration"


def _finite(v) -> float | None:
    """``v`` as a float, None when missing or not finite."""
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _chain_word(robot: str) -> str:
    from calib.robots import ROBOTS

    entry = ROBOTS.get(robot)
    return getattr(entry.cls, "chain_word", "chain") if entry is not None else "chain"


def _source(s: dict) -> Source:
    n = s.get("declared_noise")
    noise = None if not n else Noise(float(n.get("position_mm") or 0.0), float(n.get("orientation_rad") or 0.0),
                                      float(n.get("joint") or 0.0), str(n.get("distribution") or ""))
    recording = s.get("recording") or ""
    rows = s.get("rows")
    return Source(robot=s["robot"], chain_word=_chain_word(s["robot"]), recording=str(recording),
                  rows=None if rows is None else int(rows), noise=noise, seed=s.get("seed"))


def _discovery_parameters(s: dict) -> Parameters | None:
    errors = s.get("identified_errors") or {}
    if not errors:
        return None
    imp = s.get("implausible_parameters") or {}
    std = s.get("identified_std") or {}
    tolerance = imp.get("tolerance") or {}
    units = s.get("parameter_units") or {}
    still = {d["name"] for d in imp.get("with_effects") or ()}
    rows = []
    for name in s.get("free_parameters") or errors:
        e = errors[name]
        sd = std.get(name)
        unit = units.get(name) or next((d["unit"] for d in (imp.get("geometry_alone") or ()) if d["name"] == name), "")
        rows.append(ParameterRow(name=name, unit=unit, value=None, error=e, two_sigma=None if sd is None else 2.0 * sd,
                                 tolerance=tolerance.get(name), source=None, implausible=name in still))
    return Parameters(rows=tuple(rows), prior=imp.get("tolerance_source") or "not stated")


def _implausible(s: dict) -> Implausible:
    imp = s.get("implausible_parameters") or {}
    return Implausible(words=tuple(imp.get("words") or ()),
                       with_effects=tuple(d["words"] for d in imp.get("with_effects") or ()))


def _crossvalidation(s: dict) -> CrossValidation | None:
    info = s.get("crossvalidation")
    if not info:
        return None
    return CrossValidation(scheme=str(info.get("scheme", "")), fits=info.get("fits"), model=info.get("model"),
                           message=info.get("message", ""))


def _discovery_heldout(s: dict) -> Heldout:
    before, after = s["heldout_rms_before_mm"], s["heldout_rms_after_mm"]
    per = s.get("heldout_per_row")
    if per:
        per_pose = (PerPose("closure", "mm", tuple(per["before_mm"]), tuple(per["after_mm"]), tuple(per["rows"])),)
        rows = [FigureRow("closure", "mm", Figures(before, per.get("before_mean_mm"), per.get("before_max_mm")),
                          Figures(after, per.get("after_mean_mm"), per.get("after_max_mm")))]
    else:
        per_pose, rows = (), [FigureRow("closure", "mm", Figures(before, None, None), Figures(after, None, None))]
    cv = s.get("crossvalidated_position_error_mm")
    info = None
    if cv and cv.get("rms") is not None:
        rows.append(FigureRow("position", "mm", Figures.of(cv), None, crossvalidated=True))
        info = _crossvalidation(s)
    shifts = tuple(v["words"] for v in (s.get("session_shifts") or {}).values())
    raw = s.get("heldout_rms_as_predicted_mm")
    return Heldout(basis=s.get("heldout_basis") or "", poses=len(per["rows"]) if per else 0, figures=tuple(rows),
                   per_pose=per_pose, noise_floor_mm=s.get("noise_floor_mm"), crossvalidation=info,
                   session_shifts=shifts,
                   as_predicted_mm=None if not raw else (raw["before"], raw["after"]))


def _frames(s: dict) -> Frames | None:
    def row(session, f, sd):
        return FrameRow(session, tuple(f["translation_mm"]), tuple(f["rotation_rad"]),
                        None if sd is None else tuple(sd["translation_mm"]),
                        None if sd is None else tuple(sd["rotation_rad"]))

    if s.get("measurement_frames"):
        stds = s.get("measurement_frames_std") or {}
        rows, sessions = tuple(row(k, f, stds.get(k)) for k, f in s["measurement_frames"].items()), True
    elif s.get("measurement_frame"):
        rows, sessions = (row("the recording", s["measurement_frame"], s.get("measurement_frame_std")),), False
    else:
        return None
    return Frames(rows=rows, held=tuple(s.get("measurement_frame_held") or ()), sessions=sessions)


def _coefficients(params: dict) -> tuple[Coefficient, ...]:
    return tuple(Coefficient(k, float(v["value"]), _finite(v.get("std")), v.get("unit", ""))
                 for k, v in params.items() if k not in ("significance", "granularity"))


def _aliases(s: dict) -> tuple[Alias, ...]:
    out = []
    for a in s.get("aliases") or ():
        nested = bool(a.get("nested"))
        threshold = None
        if nested:  # the discovery's own bound (loaded with the discovery that wrote the alias)
            from calib.effects.discovery import MIN_NESTED_DELTA_BIC

            threshold = float(MIN_NESTED_DELTA_BIC)
        out.append(Alias(named=a["named"], rival=a["rival"], delta_bic=float(a["delta_bic"]),
                         correlation=_finite(a.get("correlation")), nested=nested, nested_min_delta_bic=threshold))
    return tuple(out)


def _separation(s: dict) -> Separation | None:
    sep = s.get("separation")
    if not sep:
        return None
    unseparated = tuple(Unseparated(effect=u["effect"], form=u["form"], combination=u["combinations"][0]["combination"],
                                    geometry=u["combinations"][0]["geometry"], more=len(u["combinations"]) - 1,
                                    separated_by=tuple(u["separated_by"])) for u in sep["unseparated"])
    families = tuple(PoseFamily(family=k, reachable=v["reachable"], tried=v["tried"], determines=v["determines"],
                                separates=tuple(v["separates"])) for k, v in sep["poses"].items())
    return Separation(determined=sep["determined"], free=sep["free"], prior_source=sep["prior_source"],
                      left_to_prior=tuple(c["combination"] for c in sep["left_to_prior"]), unseparated=unseparated,
                      families=families)


def _law(law: dict | None) -> Law | None:
    if not law:
        return None
    stds, units = law.get("constants_std") or {}, law.get("units") or {}
    forms = law.get("constant_granularity") or {}
    constants = tuple(LawConstant(name=k, values=tuple(v), std=tuple(stds[k]) if stds.get(k) else None,
                                  unit=units.get(k, ""), granularity=forms.get(k, law.get("granularity", "shared")))
                      for k, v in law["constants"].items())
    return Law(formula=law["formula"], constants=constants, cv_before_mm=law.get("cv_rms_before_mm"),
               cv_after_mm=law.get("cv_rms_after_mm"), noise_floor_mm=law.get("noise_floor_mm"),
               explained=bool(law.get("explained_with_law")), remaining=law.get("remaining_with_law") or "",
               library_effects=tuple(law.get("library_effects") or ()),
               library_effects_dropped=tuple(law.get("library_effects_dropped") or ()))


def _search(s: dict) -> Search | None:
    x = s.get("search") or {}
    if x.get("form") != "subsample":
        return None
    return Search(rows=x["rows"], subsample_rows=x["subsample_rows"], threshold=x["threshold"],
                  effects=tuple(x.get("effects") or ()))


def _resimulation(s: dict) -> Resimulation | None:
    r = s.get("mujoco_resimulation")
    if not r:
        return None
    y = r.get("sysid")
    sysid = None if not y else SysId(y["parameter"], y["start"], y["value"], y["interval_95"], y["unit"])
    return Resimulation(r["before"]["position_um"], r["after"]["position_um"], sysid)


def _effects(s: dict) -> Effects:
    ev = s.get("evidence") or {}
    partial = set(s.get("partial") or ())
    rows = []
    for name in s.get("effects") or ():
        params = (s.get("effect_parameters") or {}).get(name, {})
        sig, e = params.get("significance") or {}, ev.get(name) or {}
        rows.append(EffectRow(name=name, granularity=str(params.get("granularity", "shared")),
                              coefficients=_coefficients(params), delta_bic_when_added=e.get("delta_bic_when_added"),
                              wald_chi2=sig.get("wald_chi2"), dof=sig.get("dof"), p_value=sig.get("p_value"),
                              cv_whitened_rms=e.get("cv_whitened_rms"), partial=name in partial))
    named = set(s.get("effects") or ())
    candidates = tuple(Candidate(c, (ev.get(c) or {}).get("delta_bic_vs_none"), (ev.get(c) or {}).get("cv_whitened_rms"),
                                 c in named) for c in s.get("candidates") or ())
    rem = s.get("remaining") or {}
    remaining = Remaining(present=bool(rem.get("present")), summary=rem.get("summary", ""), rms_mm=rem.get("rms_mm"),
                          noise_floor_mm=rem.get("noise_floor_mm"), noise_ratio=rem.get("noise_ratio"),
                          follows=tuple(rem.get("follows") or ()), chains=tuple(rem.get("chains") or ()))
    t = ev.get("geometry_chi2_test")
    test = None if not t else GeometryTest(t["chi2"], t["dof"], t["p_value"], t["alpha"])
    return Effects(effects=tuple(rows), candidates=candidates, remaining=remaining, geometry_test=test,
                   located=tuple((s.get("located") or {}).get("summary") or ()),
                   cv_whitened_rms_geometry=(ev.get("none") or {}).get("cv_whitened_rms"),
                   cv_whitened_rms_chosen=ev.get("cv_whitened_rms_chosen"), aliases=_aliases(s),
                   separation=_separation(s), law=_law(s.get("proposed_law")), resimulation=_resimulation(s),
                   search=_search(s), not_named=tuple(r["words"] for r in s.get("not_named") or ()))


def _flagged(s: dict) -> Flagged:
    rows = tuple(s.get("flagged_poses") or ())
    g = s.get("gross_rows") or {}
    out = s.get("outliers") or {}
    common = dict(rows=rows, gross=tuple(g.get("rows") or ()), gross_left_out=bool(g.get("left_out")),
                  numbering=s.get("row_numbering"))
    return Flagged(**common, left_out=bool(rows), bad_rows=tuple(out.get("bad_rows") or ()),
                   model_wrong=bool(out.get("model_wrong")),
                   shared=tuple((k, tuple(v)) for k, v in (out.get("shared") or {}).items()),
                   total_rows=s.get("rows"))


def _compensation(s: dict) -> CompensationTable | None:
    c = s.get("compensation")
    if not c:
        return None
    return CompensationTable(what=c.get("what", ""), compensated=tuple(c.get("compensated") or ()),
                             not_compensated=tuple((c.get("not_compensated") or {}).items()),
                             columns=tuple(c.get("columns") or ()), rows=tuple(tuple(r) for r in c.get("rows") or ()))


def _timing(s: dict) -> Timing | None:
    if s.get("wall_time_s") is None:
        return None
    return Timing(float(s["wall_time_s"]), tuple((k, float(v)) for k, v in (s.get("wall_time_split_s") or {}).items()))


def _outputs(s: dict) -> Outputs:
    return Outputs(files=tuple((k, str(s[k])) for k in OUTPUT_KEYS if s.get(k)), law_asked="law_kept" in s,
                   law_kept=s.get("law_kept"))


def build_report(summary: dict) -> Report:
    """The report of a ``pipeline.discover`` summary (a calibration's is built from its run's objects:
    :func:`pipeline.report.calibration.calibration_report`, ``RunResult.report``).

    Raises:
        KeyError: a summary lacking a key every discovery's summary has (``robot``, ``verdict``,
            ``explained``, held-out RMS).
        ValueError: a calibration's summary (:func:`report_kind`).
    """
    s = summary
    if report_kind(s) != "discovery":
        raise ValueError("a calibration's report is built from its run (RunResult.report), not parsed from its summary")
    return Report(kind="discovery", source=_source(s), verdict=Verdict(bool(s["explained"]), s["verdict"], None),
                  fit=None, truth=None, parameters=_discovery_parameters(s), determination=None,
                  implausible=_implausible(s), heldout=_discovery_heldout(s), frames=_frames(s), effects=_effects(s),
                  flagged=_flagged(s), compensation=_compensation(s), warnings=tuple(s.get("warnings") or ()),
                  timing=_timing(s), outputs=_outputs(s))


def summary_document(summary: dict) -> dict:
    """What ``--summary-json`` writes: the summary's keys and, under :data:`REPORT_KEY`, its
    report (:meth:`Report.to_dict`)."""
    return {**summary, REPORT_KEY: build_report(summary).to_dict()}
