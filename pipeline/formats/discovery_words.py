"""The words of a discovery: the verdict, the effects found with their evidence, a proposed law,
what a plane of poses cannot separate, the report's lines. Pure text, no Rerun: the commands, the
fleet's workers and the Rerun file (:mod:`pipeline.views.discovery_view`) word a discovery with it.
"""

from __future__ import annotations

import numpy as np

from calib.effects.discovery import MIN_NESTED_DELTA_BIC

__all__ = ["model_words", "verdict_words", "law_lines", "separation_lines", "report_lines"]


def model_words(effects) -> str:
    """``geometry alone`` or ``geometry + a + b``."""
    return "geometry + " + " + ".join(effects) if effects else "geometry alone"


def verdict_words(explained: bool, effects: list, remaining: dict) -> str:
    """The verdict in one sentence (the first line the terminal prints)."""
    model = model_words(effects)
    if explained:
        return f"Explained: {model} leaves {remaining['summary']}."
    partial = (f" Named but partial: {', '.join(effects)} (structure remains)." if effects and remaining.get("follows")
               else "")
    return f"NOT explained: {model} leaves {remaining['summary']}.{partial}"


def law_lines(law: dict | None) -> list[str]:
    """A proposed law (the summary's ``proposed_law``) in words: the formula, its constants joint
    by joint with their standard deviations, the cross-validated residual before and after."""
    if not law:
        return []
    after = "explained" if law["explained_with_law"] else "still NOT explained: " + law["remaining_with_law"]
    lines = [f"Proposed law, not in the library: {law['formula']}",
             f"  cross-validated residual RMS {1e3 * law['cv_rms_before_mm']:.2f} um -> "
             f"{1e3 * law['cv_rms_after_mm']:.2f} um (noise floor {1e3 * law['noise_floor_mm']:.2f} um); with it: {after}"]
    for name, values in law["constants"].items():
        std = law["constants_std"][name]
        form = law["constant_granularity"][name]
        each = ", ".join(f"{v:.4g} +- {sd:.2g}" for v, sd in zip(values, std))
        lines.append(f"  [{name}] ({form.replace('_', ' ')}): {each if form == 'per_chain' else f'{values[0]:.4g} +- {std[0]:.2g}'} "
                     f"{law['units'][name]}")
    if law.get("library_effects_dropped"):
        model = " + ".join(["geometry"] + law["library_effects"] + ["the law"])
        lines.append(f"  with the law in, the library's {', '.join(law['library_effects_dropped'])} no longer earns its "
                     f"place (re-examined: the BIC rises by less than an effect needs to enter); the law's model: "
                     f"{model}")
    return lines


def separation_lines(sep: dict | None, n_shown: int = 3) -> list[str]:
    """What the poses cannot separate (the summary's ``separation``), in a few lines: the geometric
    combinations left to the prior (the first ``n_shown``; all in the JSON), each effect that cannot
    be separated from them with the combination that mimics it, and the poses that would separate
    them."""
    if not sep:
        return []
    left = sep["left_to_prior"]
    shown = "; ".join(c["combination"] for c in left[:n_shown]) + ("; ..." if len(left) > n_shown else "")
    lines = [f"Geometry: the rows determine {sep['determined']} of its {sep['free']} combinations; {len(left)} are left "
             f"to the prior ({sep['prior_source']}) and held at their nominal values: {shown} (summary JSON: "
             f"separation.left_to_prior)."]
    for u in sep["unseparated"]:
        c = u["combinations"][0]
        more = f" and {len(u['combinations']) - 1} more combinations" if len(u["combinations"]) > 1 else ""
        by = ", ".join(u["separated_by"]) or "none of the poses tried"
        lines.append(f"Cannot be separated on this pose set: {u['effect']} ({u['form']}): {c['combination']}{more} acts "
                     f"on these poses as the geometry's {c['geometry']}; not named. Poses that would separate it: {by}.")
    for family, v in sep["poses"].items():
        sep_words = f"; separates {', '.join(v['separates'])}" if v["separates"] else ""
        lines.append(f"  poses with {family} ({v['reachable']} of {v['tried']} reachable): would determine "
                     f"{v['determines']} of the {len(left)} combinations left to the prior{sep_words}")
    return lines


def report_lines(s: dict) -> list[str]:
    """The summary in plain words, one finding per line; the verdict first."""
    lines = [s["verdict"]]
    ev = s["evidence"]["geometry_chi2_test"]
    lines.append(f"Geometry alone: chi-square {ev['chi2']:.0f} on {ev['dof']} degrees of freedom, p = {ev['p_value']:.3g} "
                 f"({'consistent with' if ev['p_value'] > ev['alpha'] else 'NOT explained by'} the declared noise "
                 f"by this omnibus test).")
    lines += ["Where the geometry-only mismatch is: " + t for t in s["located"]["summary"]]
    o = s["outliers"]
    if s["flagged_poses"]:
        lines.append(f"Outlier rows (gross and isolated: not shared by neighbours in time, workspace or direction), "
                     f"left out: {', '.join(map(str, s['flagged_poses']))} (1-based data rows)")
    if o["model_wrong"]:
        lines.append(f"{len(o['bad_rows'])} of {s['rows']} rows look bad (more than 5%): the model is wrong, not the "
                     f"data; no row is left out.")
    elif o["shared"]:
        lines.append(f"Rows with large residuals kept as evidence (shared by their neighbours): "
                     f"{'; '.join(k + ' (' + ', '.join(v) + ')' for k, v in o['shared'].items())}")
    named = s["effects"]
    if not named:
        if s["explained"]:
            lines.append("Left-out physics: none. The geometric model explains the recording to the noise.")
        else:
            lines.append(f"Left-out physics: none of the candidates ({', '.join(s['candidates']) or 'none given'}) earns "
                         f"its place; what remains is not explained (see the verdict).")
    else:
        status = "" if s["explained"] else " (partial: the remainder is not explained)"
        lines.append(f"Left-out physics: {' + '.join(named)}{status}; cross-validated whitened RMS "
                     f"{s['evidence']['none']['cv_whitened_rms']:.2f} -> {s['evidence']['cv_whitened_rms_chosen']:.2f}.")
        for name in named:
            params = s["effect_parameters"][name]
            sig = params["significance"]
            e = s["evidence"].get(name, {})
            form = params.get("granularity", "shared").replace("_", " ")
            lines.append(f"  {name} ({form}): BIC lower by {e.get('delta_bic_when_added', float('nan')):.0f} when it entered; "
                         f"non-zero at p = {sig['p_value']:.2g} (Wald chi-square {sig['wald_chi2']:.0f} on {sig['dof']})")
            for k, v in params.items():
                if k in ("significance", "granularity"):
                    continue
                if k == "from_row":  # a step placed by row, never by a time the recording may not have
                    lines.append(f"    from row {v['value']:.0f}" if np.isfinite(v["value"]) else "    after the last row")
                    continue
                unc = f" +- {v['std']:.2g}" if np.isfinite(v["std"]) else ""
                lines.append(f"    {k} = {v['value']:.6g}{unc} {v['unit']}")
    for a in s["aliases"]:
        if a.get("nested"):
            lines.append(f"Cannot tell apart on this recording: {a['named']} and {a['rival']}, which contains it "
                         f"(its extra parameters gain {a['delta_bic']:.1f} BIC, less than {MIN_NESTED_DELTA_BIC:.0f}); "
                         f"the simpler {a['named']} fitted.")
            continue
        lines.append(f"Cannot tell apart on this recording: {a['named']} and {a['rival']} (evidence within "
                     f"{a['delta_bic']:.1f} BIC, regressor correlation {a['correlation']:.2f}); {a['named']} fitted.")
    lines += separation_lines(s.get("separation"))
    lines += law_lines(s.get("proposed_law"))
    lines.append(f"Held-out residual RMS: {1e3 * s['heldout_rms_before_mm']:.3f} um -> {1e3 * s['heldout_rms_after_mm']:.3f} um "
                 f"(noise floor {1e3 * s['noise_floor_mm']:.3f} um; {s['heldout_basis']}).")
    r = s.get("mujoco_resimulation")
    if r:
        lines.append(f"MuJoCo machine re-simulated: position RMS {r['before']['position_um']:.3f} um -> {r['after']['position_um']:.3f} um")
        if "sysid" in r:
            y = r["sysid"]
            lines.append(f"  mujoco.sysid re-fit {y['parameter']}: {y['start']:.6g} -> {y['value']:.6g} +- {y['interval_95']:.2g} {y['unit']} (95%)")
    return lines
