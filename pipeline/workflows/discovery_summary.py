"""The summary (``--summary-json``) of a discovery and the figures its summary and its report share,
made once from the discovery's objects (:func:`discovery_parts`): the verdict in words, the
implausible errors, the effect parameters placed by row, the sessions shifted; the held-out
figures; the summary itself (:func:`discovery_summary`)."""

from __future__ import annotations

import numpy as np

from calib.discovery import DiscoveryOutcome
from calib.effects import Discovery
from calib.effects.heldout import HeldoutJudgement
from calib.effects.session_zeros import SessionZeros
from pipeline.formats import Recording
from pipeline.report.discovery import not_named_words, outlier_keys
from pipeline.report.text import shift_words, verdict_words

from .calibration import IMPLAUSIBLE_TOLERANCES, implausible_parameters, machine_tolerance

__all__ = ["discovery_parts", "discovery_summary", "heldout_block", "calibration_session_shifts", "row_order",
           "placed_by_row", "implausibility"]


def heldout_block(judgement: HeldoutJudgement) -> dict:
    """The summary's held-out figures (closure residual RMS, mm) of the geometry alone and of the
    effects named, both fitted on the training rows, with each shifted session's shift taken out;
    the noise floor; each row's RMS over the joints; the shifts found by session; the effects the
    held-out rows did not confirm; every fold's figures."""
    g, m = judgement.geometry, judgement.model
    held = judgement.fold.held
    per_row = {"rows": [int(i) + 1 for i in held], "before_mm": g.per_row_mm.tolist(), "after_mm": m.per_row_mm.tolist(),
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


def discovery_parts(rec: Recording, outcome: DiscoveryOutcome) -> dict:
    """What the summary and the report of a discovery both hold, made once from its objects: the
    verdict in words, the implausible errors (:func:`implausibility`), the effect parameters placed
    by row (:func:`placed_by_row`), the sessions shifted (``{session: {..., words}}``)."""
    disc, judgement, robot = outcome.discovery, outcome.judgement, rec.robot
    return {"verdict": verdict_words(disc.explained, list(disc.effects), disc.remaining.to_dict()),
            "implausible": implausibility(rec, disc),
            "effect_parameters": placed_by_row(disc.chosen.parameters(), rec, disc.kept, row_order(rec)),
            "session_shifts": {s: dict(shift.to_dict(), words=shift_words(s, shift, robot.joint_unit))
                               for s, shift in judgement.shifts.items() if shift.shifted}
            | calibration_session_shifts(rec, disc.chosen)}


def discovery_summary(rec: Recording, outcome: DiscoveryOutcome, tolerance_source: str,
                      resimulated: dict | None, parts: dict) -> dict:
    """The summary (``--summary-json``) of a discovery judged by its held-out rows (``parts``:
    :func:`discovery_parts`)."""
    robot = rec.robot
    disc, judgement, names = outcome.discovery, outcome.judgement, outcome.names
    flagged = list(disc.flagged)
    h = heldout_block(judgement)
    remaining = disc.remaining.to_dict()
    summary = {
        "robot": robot.name,
        "explained": disc.explained,
        "verdict": parts["verdict"],
        "remaining": remaining,
        "effects": list(disc.effects),
        "partial": list(disc.partial),
        "aliases": [a.to_dict() for a in disc.aliases],
        "candidates": [n for n in names if n != "none"],
        "effect_parameters": parts["effect_parameters"],
        "heldout_rms_before_mm": h["heldout_rms_before_mm"],
        "heldout_rms_after_mm": h["heldout_rms_after_mm"],
        "noise_floor_mm": h["noise_floor_mm"],
        "heldout_basis": outcome.basis,
        "heldout_per_row": h["per_row"],
        "heldout_rms_as_predicted_mm": h["heldout_rms_as_predicted_mm"],
        "heldout_folds": h["heldout_folds"],
        "not_named": h["not_named"],
        "session_shifts": parts["session_shifts"],
        "flagged_poses": [i + 1 for i in flagged],
        "outliers": outlier_keys(disc),
        "tests": disc.tests.to_dict(),
        "evidence": disc.evidence.to_dict(),
        "identified_errors": robot.table.to_dict(disc.chosen.errors),
        "identified_std": robot.table.to_dict(np.sqrt(np.clip(np.diag(disc.chosen.geometry_covariance()), 0.0, None))),
        "parameter_units": dict(zip(robot.table.names, robot.table.units)),
        "free_parameters": list(robot.free_default),
        "declared_noise": rec.noise.to_dict(),
        "located": disc.located.to_dict(),
        "rows": int(rec.joints.shape[0]),
        "proposed_law": None if disc.proposed_law is None else disc.proposed_law.summary(),
        "search": disc.search.to_dict(),
    }
    summary["implausible_parameters"] = parts["implausible"]
    summary["time"] = "row order" if row_order(rec) else "measured"
    summary["separation"] = {} if disc.separation is None else dict(disc.separation.to_dict(),
                                                                      prior_source=tolerance_source)
    if rec.meta.get("simulation", {}).get("effect") is not None:
        summary["simulated_truth"] = {k: v for k, v in rec.meta["simulation"].items() if k != "injected_errors"}
    if resimulated is not None:
        summary.update(resimulated)
    return summary


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


def implausibility(rec: Recording, disc: Discovery) -> dict:
    """The identified errors beyond three tolerances (the sidecar's ``meta.parameter_tolerance`` or
    the robot's default) with the geometry alone and with the effects found, and those the effects
    bring back within tolerance: a geometry that had absorbed physics."""
    robot = rec.robot
    tolerance, source = machine_tolerance(robot, rec.meta, "the recording's sidecar")
    names = robot.free_default
    alone = implausible_parameters(robot, disc.geometry.errors, tolerance, names)
    with_effects = implausible_parameters(robot, disc.chosen.errors, tolerance, names)
    still = {d["name"] for d in with_effects}
    back = [d for d in alone if d["name"] not in still]
    k = {n: robot.table.index(n) for n in names}
    words = [f"{d['name']}: {d['error']:+.4g} {d['unit']} with the geometry alone, "
             f"{disc.chosen.errors[k[d['name']]]:+.4g} {d['unit']} with {', '.join(disc.effects) or 'no effect'}: back "
             f"within {IMPLAUSIBLE_TOLERANCES:g} tolerances ({d['tolerance']:.4g} {d['unit']})" for d in back]
    return {"tolerance_source": source, "tolerance": tolerance.tolerance_by_name(robot),
            "geometry_alone": alone, "with_effects": with_effects,
            "back_within_tolerance": [d["name"] for d in back], "words": words}
