"""The report of a discovery (``python -m pipeline.discover``), made from its objects: the recording
analysed, the discovery policy's outcome (:class:`calib.discovery.DiscoveryOutcome`: the
:class:`calib.effects.Discovery` and its held-out judgement), and the figures the workflow made of
them (the implausible errors, the effect parameters placed by row, the MuJoCo re-simulation); then
what the read of a recording found (:func:`with_read`: its one dict, typed here) and the files
written (:func:`with_files`). As a calibration run's (:mod:`pipeline.report.calibration`), no
section is parsed from the summary dict.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from calib.effects.session_zeros import SessionZeros

if TYPE_CHECKING:
    from calib.effects.heldout import HeldoutJudgement
    from pipeline.formats import Recording

from .model import (OUTPUT_KEYS, Alias, Candidate, Coefficient, CompensationTable, CrossValidation, DiscoveryRecord,
                    EffectRow, Effects, FigureRow, Figures, Flagged, FrameRow, Frames, GeometryTest, Heldout,
                    Implausible, Law, LawConstant, Noise, Outputs, ParameterRow, Parameters, PerPose, PoseFamily,
                    Remaining, Report, Resimulation, Search, Separation, Source, SysId, Timing, Unseparated, Verdict)

__all__ = ["discovery_report", "discovery_record", "with_read", "with_files", "outlier_keys", "not_named_words",
           "heldout_block", "calibration_session_shifts", "row_order", "placed_by_row"]


def _finite(v) -> float | None:
    """``v`` as a float, None when missing or not finite."""
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _source(rec) -> Source:
    from calib.robots import ROBOTS

    entry = ROBOTS.get(rec.robot.name)
    n = rec.noise.to_dict()
    noise = None if not n else Noise(float(n.get("position_mm") or 0.0), float(n.get("orientation_rad") or 0.0),
                                      float(n.get("joint") or 0.0), str(n.get("distribution") or ""))
    return Source(robot=rec.robot.name, chain_word=getattr(entry.cls, "chain_word", "chain") if entry is not None
                  else "chain", recording="", rows=int(rec.joints.shape[0]), noise=noise, seed=None)


def _parameters(robot, chosen, implausible: dict) -> Parameters | None:
    """The identified errors with the effects (``chosen``, the discovery's fit), their two sigma,
    tolerance and whether still implausible (``implausible``: the workflow's implausibility)."""
    errors = robot.table.to_dict(chosen.errors)
    if not errors:
        return None
    std = robot.table.to_dict(np.sqrt(np.clip(np.diag(chosen.geometry_covariance()), 0.0, None)))
    tolerance = implausible.get("tolerance") or {}
    units = dict(zip(robot.table.names, robot.table.units))
    still = {d["name"] for d in implausible.get("with_effects") or ()}
    rows = []
    for name in list(robot.free_default) or errors:
        sd = std.get(name)
        unit = units.get(name) or next((d["unit"] for d in implausible.get("geometry_alone") or () if d["name"] == name),
                                       "")
        rows.append(ParameterRow(name=name, unit=unit, value=None, error=errors[name],
                                 two_sigma=None if sd is None else 2.0 * sd, tolerance=tolerance.get(name), source=None,
                                 implausible=name in still))
    return Parameters(rows=tuple(rows), prior=implausible.get("tolerance_source") or "not stated")


def _heldout(judgement, basis: str, session_shifts: dict) -> Heldout:
    """The held-out closure residuals of the geometry alone and of the effects (``judgement``:
    :class:`calib.effects.heldout.HeldoutJudgement`), per row, the floor, the shifts' words."""
    g, m, held = judgement.geometry, judgement.model, judgement.fold.held
    rows = tuple(int(i) + 1 for i in held)
    per_pose = (PerPose("closure", "mm", tuple(g.per_row_mm.tolist()), tuple(m.per_row_mm.tolist()), rows),)
    figures = (FigureRow("closure", "mm", Figures(g.unshifted_rms_mm, float(g.per_row_mm.mean()),
                                                  float(g.per_row_mm.max())),
                         Figures(m.unshifted_rms_mm, float(m.per_row_mm.mean()), float(m.per_row_mm.max()))),)
    shifted = any(s.shifted for s in judgement.shifts.values())
    return Heldout(basis=basis or "", poses=len(rows), figures=figures, per_pose=per_pose,
                   noise_floor_mm=judgement.floor_mm, session_shifts=tuple(v["words"] for v in session_shifts.values()),
                   as_predicted_mm=(g.rms_mm, m.rms_mm) if shifted else None)


def _coefficients(params: dict) -> tuple[Coefficient, ...]:
    return tuple(Coefficient(k, float(v["value"]), _finite(v.get("std")), v.get("unit", ""))
                 for k, v in params.items() if k not in ("significance", "granularity"))


def _aliases(disc) -> tuple[Alias, ...]:
    from calib.effects.discovery import MIN_NESTED_DELTA_BIC

    return tuple(Alias(named=a.named, rival=a.rival, delta_bic=float(a.delta_bic), correlation=_finite(a.correlation),
                       nested=bool(a.nested), nested_min_delta_bic=float(MIN_NESTED_DELTA_BIC) if a.nested else None)
                 for a in disc.aliases)


def _separation(disc, prior_source: str) -> Separation | None:
    if disc.separation is None:
        return None
    sep = disc.separation.to_dict()
    unseparated = tuple(Unseparated(effect=u["effect"], form=u["form"], combination=u["combinations"][0]["combination"],
                                    geometry=u["combinations"][0]["geometry"], more=len(u["combinations"]) - 1,
                                    separated_by=tuple(u["separated_by"])) for u in sep["unseparated"])
    families = tuple(PoseFamily(family=k, reachable=v["reachable"], tried=v["tried"], determines=v["determines"],
                                separates=tuple(v["separates"])) for k, v in sep["poses"].items())
    return Separation(determined=sep["determined"], free=sep["free"], prior_source=prior_source,
                      left_to_prior=tuple(c["combination"] for c in sep["left_to_prior"]), unseparated=unseparated,
                      families=families)


def _law(proposed) -> Law | None:
    if proposed is None:
        return None
    law = proposed.summary()
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


def _search(form) -> Search | None:
    if form.form != "subsample":
        return None
    return Search(rows=form.rows, subsample_rows=form.subsample_rows, threshold=form.threshold,
                  effects=tuple(form.effects or ()))


def _resimulation(resimulated: dict | None) -> Resimulation | None:
    """The re-simulation section of the workflow's ``mujoco_resimulation`` (its one dict)."""
    r = (resimulated or {}).get("mujoco_resimulation")
    if not r:
        return None
    y = r.get("sysid")
    sysid = None if not y else SysId(y["parameter"], y["start"], y["value"], y["interval_95"], y["unit"])
    return Resimulation(r["before"]["position_um"], r["after"]["position_um"], sysid)


def _remaining(rem) -> Remaining:
    return Remaining(present=bool(rem.present), summary=rem.summary, rms_mm=rem.rms_mm,
                     noise_floor_mm=rem.noise_floor_mm, noise_ratio=rem.noise_ratio, follows=tuple(rem.follows),
                     chains=tuple(rem.chains))


def _effects(outcome, effect_parameters: dict, prior_source: str, resimulated: dict | None) -> Effects:
    """What the discovery found (``outcome.discovery``) with its evidence; ``effect_parameters``:
    the effects' coefficients as the summary gives them (placed by row)."""
    disc = outcome.discovery
    ev = disc.evidence
    partial = set(disc.partial)
    rows = []
    for name in disc.effects:
        params = effect_parameters.get(name, {})
        sig, e = params.get("significance") or {}, ev.of(name)
        rows.append(EffectRow(name=name, granularity=str(params.get("granularity", "shared")),
                              coefficients=_coefficients(params),
                              delta_bic_when_added=None if e is None else e.delta_bic_when_added,
                              wald_chi2=sig.get("wald_chi2"), dof=sig.get("dof"), p_value=sig.get("p_value"),
                              cv_whitened_rms=None if e is None else e.cv_whitened_rms, partial=name in partial))
    named = set(disc.effects)
    candidates = tuple(Candidate(c, None if ev.of(c) is None else ev.of(c).delta_bic_vs_none,
                                 None if ev.of(c) is None else ev.of(c).cv_whitened_rms, c in named)
                       for c in outcome.names if c != "none")
    t = ev.geometry_test
    return Effects(effects=tuple(rows), candidates=candidates, remaining=_remaining(disc.remaining),
                   geometry_test=GeometryTest(t.chi2, t.dof, t.p_value, t.alpha),
                   located=tuple(disc.located.summary or ()), cv_whitened_rms_geometry=ev.geometry.cv_whitened_rms,
                   cv_whitened_rms_chosen=ev.cv_whitened_rms_chosen, aliases=_aliases(disc),
                   separation=_separation(disc, prior_source), law=_law(disc.proposed_law),
                   resimulation=_resimulation(resimulated), search=_search(disc.search),
                   not_named=tuple(not_named_words(r) for r in outcome.judgement.rejected))


def not_named_words(r) -> str:
    """Why an effect the calibration rows chose is not named, with its figures (``r``:
    :class:`calib.effects.heldout.RejectedEffect`)."""
    bic = "" if r.delta_bic is None else f" (BIC {r.delta_bic:+.0f})"
    rows = "the validation rows" if r.fold == "validation" else f"rows held out ({r.fold})"
    if r.why == "not separable":
        return (f"{r.name} fits the calibration rows{bic} but cannot be separated from the geometry on this pose set: "
                f"not named")
    if r.why == "worse re-simulated":
        return (f"{r.name} fits the calibration rows{bic} but its MuJoCo re-simulation fits worse than the geometry "
                f"alone ({1e3 * r.geometry_mm:.1f} -> {1e3 * r.with_effect_mm:.1f} um): not named")
    return (f"{r.name} fits the calibration rows{bic} but predicts {rows} worse ({r.geometry_mm:.3g} -> "
            f"{r.with_effect_mm:.3g} mm): not named")


def outlier_keys(disc) -> dict:
    """The summary's ``outliers``: the rows that look bad (1-based data rows), whether they say the
    model is wrong, the large residuals kept because neighbours share them, the test's threshold and scale."""
    scan = disc.outliers
    return {"bad_rows": sorted(int(disc.kept[j]) + 1 for j in scan.bad), "model_wrong": bool(scan.model_wrong),
            "shared": {str(int(disc.kept[r.row]) + 1): dict(r.by) for r in scan.shared},
            "threshold": scan.threshold, "scale": scan.scale}


def _flagged(disc, total_rows: int) -> Flagged:
    rows = tuple(i + 1 for i in disc.flagged)
    out = outlier_keys(disc)
    return Flagged(rows=rows, gross=(), gross_left_out=False, numbering=None, left_out=bool(rows),
                   bad_rows=tuple(out["bad_rows"]), model_wrong=out["model_wrong"],
                   shared=tuple((k, tuple(v)) for k, v in out["shared"].items()), total_rows=total_rows)


def heldout_block(judgement: HeldoutJudgement) -> dict:
    """The summary's held-out figures (closure residual RMS, mm) of the geometry alone and of the
    effects named, both fitted on the training rows, with each shifted session's shift taken out;
    the noise floor; each row's RMS over the joints; the shifts found by session; the effects the
    held-out rows did not confirm; every fold's figures."""
    g, m = judgement.geometry, judgement.model
    held = judgement.fold.held
    per_row = {"rows": [int(i) + 1 for i in held], "before_mm": g.per_row_mm.tolist(),
               "after_mm": m.per_row_mm.tolist(),
               "before_mean_mm": float(g.per_row_mm.mean()), "before_max_mm": float(g.per_row_mm.max()),
               "after_mean_mm": float(m.per_row_mm.mean()), "after_max_mm": float(m.per_row_mm.max()),
               "what": "closure residual RMS over the joints of each held-out row (1-based data rows), each shifted "
                       "session's shift taken out"}
    return {"heldout_rms_before_mm": g.unshifted_rms_mm, "heldout_rms_after_mm": m.unshifted_rms_mm,
            # as predicted, a shifted session's shift left in: said only where a session shifted
            "heldout_rms_as_predicted_mm": {"before": g.rms_mm, "after": m.rms_mm}
            if any(s.shifted for s in judgement.shifts.values()) else None,
            "noise_floor_mm": judgement.floor_mm, "after_over_floor": m.unshifted_rms_mm / judgement.floor_mm,
            "heldout_rows": [int(i) for i in held], "per_row": per_row,
            "heldout_folds": [{"kind": k, "rows": n, "geometry_rms_mm": gb, "model_rms_mm": mb}
                              for k, n, gb, mb in judgement.folds],
            "not_named": [{"effect": r.name, "delta_bic": r.delta_bic, "geometry_rms_mm": r.geometry_mm,
                           "with_effect_rms_mm": r.with_effect_mm, "judged_on": r.fold, "why": r.why,
                           "words": not_named_words(r)} for r in judgement.rejected]}


def calibration_session_shifts(rec: Recording, fit) -> dict:
    """``{session: {shift, words}}`` of the later sessions a named ``session_zeros`` moved (fitted
    with the geometry from the calibration rows of every session)."""
    for m in fit.models:
        if isinstance(m, SessionZeros):
            sl = fit.slices()[m.name]
            zeros, stds = m.zeros(fit.coefficients[sl], rec.robot), m.zeros(fit.coefficient_std[sl], rec.robot)
            unit = rec.robot.joint_unit
            return {s: {"model": "joint zeros", "fitted_with": "the geometry, on the calibration rows of every session",
                        "shift": {f"zero.{j}": {"value": float(v), "std": float(e), "unit": unit}
                                  for j, v, e in zip(rec.robot.joint_names, d, stds[s])},
                        "words": f"the machine re-homed before session {s!r}: each joint's zero moved by "
                                 + ", ".join(f"{v:+.3g} +- {e:.2g}" for v, e in zip(d, stds[s]))
                                 + f" {unit} (fitted with the geometry); the calibration file holds the first "
                                   f"session's zeros: re-reference a later session (pipeline.run --from)"}
                    for s, d in zeros.items()}
    return {}


def row_order(rec: Recording) -> bool:
    """Whether the recording's time is only its rows' order (every session's ``time`` is ``"row
    order"``: a lab export with ``[time] format = "none"``, ``t_s`` = 0, 1, 2, ...)."""
    return all(rec.session_info.get(s, {}).get("time") == "row order" for s in rec.session_names)


def placed_by_row(params: dict, rec: Recording, kept: np.ndarray, by_row: bool) -> dict:
    """``effect_parameters`` with each step in time (a lost count's ``step_time``) placed by the
    first row after it (``from_row``, 1-based data row); on a recording whose time is the rows'
    order the step time itself is dropped (it is no time), and rates per second are per row."""
    out = {}
    for name, p in params.items():
        p = dict(p)
        if "step_time" in p:
            t0 = p["step_time"]["value"]
            after = kept[rec.t_s[kept] > t0]
            p["from_row"] = {"value": float(after[0] + 1) if after.size else float("nan"), "std": float("nan"),
                             "unit": "row"}
            if by_row:
                del p["step_time"]
        if by_row:
            p = {k: (dict(v, unit=v["unit"].replace("/s", "/row")) if isinstance(v, dict) and "unit" in v else v)
                 for k, v in p.items()}
        out[name] = p
    return out


def discovery_record(rec, outcome, *, implausible: dict, effect_parameters: dict, prior_source: str,
                     session_shifts: dict, resimulated: dict | None) -> DiscoveryRecord:
    """The record of what a discovery's summary holds beyond the report's sections, made from its
    objects (the arguments as :func:`discovery_report`'s)."""
    robot = rec.robot
    disc = outcome.discovery
    simulated = rec.meta.get("simulation", {})
    return DiscoveryRecord(
        remaining=disc.remaining.to_dict(), effects=tuple(disc.effects), partial=tuple(disc.partial),
        aliases=tuple(a.to_dict() for a in disc.aliases), candidates=tuple(n for n in outcome.names if n != "none"),
        effect_parameters=effect_parameters, heldout=heldout_block(outcome.judgement), heldout_basis=outcome.basis,
        session_shifts=session_shifts, outliers=outlier_keys(disc), tests=disc.tests.to_dict(),
        evidence=disc.evidence.to_dict(), identified_errors=robot.table.to_dict(disc.chosen.errors),
        identified_std=robot.table.to_dict(np.sqrt(np.clip(np.diag(disc.chosen.geometry_covariance()), 0.0, None))),
        parameter_units=dict(zip(robot.table.names, robot.table.units)), free_parameters=tuple(robot.free_default),
        declared_noise=rec.noise.to_dict(), located=disc.located.to_dict(),
        proposed_law=None if disc.proposed_law is None else disc.proposed_law.summary(), search=disc.search.to_dict(),
        implausible=implausible, time="row order" if row_order(rec) else "measured",
        separation={} if disc.separation is None else dict(disc.separation.to_dict(), prior_source=prior_source),
        simulated_truth={k: v for k, v in simulated.items() if k != "injected_errors"}
        if simulated.get("effect") is not None else None, resimulated=resimulated)


def discovery_report(rec, outcome, *, verdict: str, implausible: dict, effect_parameters: dict, prior_source: str,
                     session_shifts: dict, resimulated: dict | None, wall_time_s: float) -> Report:
    """The report of a discovery of ``rec`` (the recording as analysed) judged by its held-out rows
    (``outcome``: :class:`calib.discovery.DiscoveryOutcome`), before the read's findings and the files.

    Args:
        verdict: the verdict in words; implausible: the identified errors beyond their tolerances
            (:func:`pipeline.workflows.discovery.implausibility`); effect_parameters: the effects'
            coefficients placed by row; prior_source: the tolerances' source, in words;
            session_shifts: ``{session: {..., words}}`` of the sessions shifted; resimulated: the
            MuJoCo re-simulation (``{"mujoco_resimulation": ...}``, None: not made);
            wall_time_s: the discovery's wall time.
    """
    disc = outcome.discovery
    return Report(kind="discovery", source=_source(rec), verdict=Verdict(bool(disc.explained), verdict, None),
                  fit=None, truth=None, parameters=_parameters(rec.robot, disc.chosen, implausible), determination=None,
                  implausible=Implausible(words=tuple(implausible.get("words") or ()),
                                          with_effects=tuple(d["words"] for d in implausible.get("with_effects") or ())),
                  heldout=_heldout(outcome.judgement, outcome.basis, session_shifts), frames=None,
                  effects=_effects(outcome, effect_parameters, prior_source, resimulated),
                  flagged=_flagged(disc, int(rec.joints.shape[0])), timing=Timing(float(wall_time_s), ()),
                  discovery=discovery_record(rec, outcome, implausible=implausible, effect_parameters=effect_parameters,
                                             prior_source=prior_source, session_shifts=session_shifts,
                                             resimulated=resimulated))


def _frames(block: dict) -> Frames | None:
    def row(session, f, sd):
        return FrameRow(session, tuple(f["translation_mm"]), tuple(f["rotation_rad"]),
                        None if sd is None else tuple(sd["translation_mm"]),
                        None if sd is None else tuple(sd["rotation_rad"]))

    if block.get("measurement_frames"):
        stds = block.get("measurement_frames_std") or {}
        rows, sessions = tuple(row(k, f, stds.get(k)) for k, f in block["measurement_frames"].items()), True
    elif block.get("measurement_frame"):
        rows, sessions = (row("the recording", block["measurement_frame"], block.get("measurement_frame_std")),), False
    else:
        return None
    return Frames(rows=rows, held=tuple(block.get("measurement_frame_held") or ()), sessions=sessions)


def with_read(report: Report, block: dict, warnings, crossvalidation: dict | None) -> Report:
    """``report`` with what the read of its recording found (``block``: the read's one dict, its
    gross rows and instrument frames; :class:`pipeline.workflows.calibration.AsRead`), the
    recording's warnings (None: none checked, the summary names none) and, without validation
    rows, the geometry's cross-validated prediction error (``crossvalidation``:
    :meth:`calib.crossval.CrossValidationResult.summary`, None: none)."""
    g = block.get("gross_rows") or {}
    flagged = replace(report.flagged, gross=tuple(g.get("rows") or ()), gross_left_out=bool(g.get("left_out")))
    heldout = report.heldout
    cv = (crossvalidation or {}).get("crossvalidated_position_error_mm")
    if cv and cv.get("rms") is not None:
        info = crossvalidation.get("crossvalidation")
        heldout = replace(heldout, figures=heldout.figures + (FigureRow("position", "mm", Figures.of(cv), None,
                                                                        crossvalidated=True),),
                          crossvalidation=None if not info else CrossValidation(
                              scheme=str(info.get("scheme", "")), fits=info.get("fits"), model=info.get("model"),
                              message=info.get("message", "")))
    record = None if report.discovery is None else replace(
        report.discovery, read=dict(block), warnings=None if warnings is None else tuple(warnings),
        crossvalidation=crossvalidation)
    return replace(report, frames=_frames(block), flagged=flagged, heldout=heldout, warnings=tuple(warnings or ()),
                   discovery=record)


def with_files(report: Report, *, recording: str, files: dict, law_asked: bool, law_kept: str | None,
               compensation: dict | None) -> Report:
    """``report`` with the recording's name (a file, or the scenario in words), the files written
    (``{summary key: path}``, :data:`OUTPUT_KEYS`), the kept law (``law_asked``: ``--law`` given)
    and the compensation table (:func:`pipeline.workflows.discovery.compensation_table`)."""
    c = compensation
    table = None if not c else CompensationTable(
        what=c.get("what", ""), compensated=tuple(c.get("compensated") or ()),
        not_compensated=tuple((c.get("not_compensated") or {}).items()), columns=tuple(c.get("columns") or ()),
        rows=tuple(tuple(r) for r in c.get("rows") or ()))
    record = None if report.discovery is None else replace(report.discovery, compensation=compensation)
    return replace(report, source=replace(report.source, recording=str(recording or "")), compensation=table,
                   discovery=record,
                   outputs=Outputs(files=tuple((k, str(files[k])) for k in OUTPUT_KEYS if files.get(k)),
                                   law_asked=law_asked, law_kept=law_kept))
