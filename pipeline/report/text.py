"""The words of a report (:mod:`pipeline.report.model`): every sentence a person reads of a
calibration or a discovery is composed here, from the typed model.

- :func:`terminal_lines`: the summary ``python -m pipeline.run`` and ``python -m pipeline.discover``
  print;
- :func:`report_markdown`: the summary panel of their Rerun files (the views only log it);
- the phrases the HTML report (:mod:`pipeline.report.html`) lays out: :func:`report_title`,
  :func:`verdict_text`, :func:`machine_facts`, :func:`figure_label`, :func:`tolerance_verdict`,
  :func:`determined_by`, :func:`heldout_basis`, :func:`implausible_notes`, :func:`effect_evidence`,
  :func:`effect_notes`, :func:`law_words`, :func:`no_effect_words`, :func:`remaining_words`,
  :func:`search_words`, :func:`flagged_words`;
- the words a discovery's summary carries (:func:`verdict_words`, :func:`model_words`).

Pure text: no Rerun, no NumPy; the fleet's workers and the discovery's workflow word a verdict
with it without loading a viewer.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .model import Effects, EffectRow, FigureRow, Flagged, Heldout, Law, Noise, ParameterRow, Report, Search

__all__ = ["terminal_lines", "report_markdown", "verdict_words", "model_words", "report_title", "verdict_text",
           "machine_facts", "noise_words", "figure_label", "per_pose_label", "heldout_basis", "implausible_notes",
           "tolerance_verdict", "determined_by", "effect_evidence", "effect_notes", "law_words", "no_effect_words",
           "remaining_words", "search_words", "shift_words",
           "flagged_words", "DISPLAY_SCALE",
           "IMPLAUSIBLE_LINES", "DISCOVERY_IMPLAUSIBLE_LINES", "COMBINATION_LINES", "PRIOR_NAMES",
           "MARKDOWN_PRIOR_NAMES", "SEPARATION_LINES"]

#: Displayed unit and scale of each model unit (figures are kept in mm and rad, shown in um and urad).
DISPLAY_SCALE = {"mm": ("um", 1e3), "rad": ("urad", 1e6)}
#: A calibration's implausible parameters shown one a line; the rest are counted (the summary JSON lists them all).
IMPLAUSIBLE_LINES = 3
#: A discovery's parameters back within tolerance with the effects shown one a line; the rest counted.
DISCOVERY_IMPLAUSIBLE_LINES = 5
#: Combinations left to the prior shown one a line on the terminal; the rest counted.
COMBINATION_LINES = 3
#: Names of the parameters left to the prior listed on the terminal, and in the Rerun panel.
PRIOR_NAMES, MARKDOWN_PRIOR_NAMES = 8, 10
#: A discovery's geometric combinations left to the prior named in its separation line.
SEPARATION_LINES = 3
#: How a parameter's source reads.
DETERMINED_BY = {"data": "the data", "prior": "the prior (tolerance)", "held": "held at nominal"}


def _display(unit: str) -> tuple[str, float]:
    return DISPLAY_SCALE.get(unit, (unit, 1.0))


def _f(value: float | None, spec: str, scale: float = 1.0) -> str:
    """``value * scale`` formatted, ``-`` for none."""
    return "-" if value is None else format(scale * value, spec)


def _finite(value: float | None) -> bool:
    return value is not None and math.isfinite(value)


# ------------------------------------------------------------------------- a discovery's verdict

def model_words(effects) -> str:
    """``geometry alone`` or ``geometry + a + b``."""
    return "geometry + " + " + ".join(effects) if effects else "geometry alone"


def verdict_words(explained: bool, effects: list, remaining: dict) -> str:
    """A discovery's verdict in one sentence (its summary's ``verdict``, the first line printed)."""
    model = model_words(effects)
    if explained:
        return f"Explained: {model} leaves {remaining['summary']}."
    partial = (f" Named but partial: {', '.join(effects)} (structure remains)." if effects and remaining.get("follows")
               else "")
    return f"NOT explained: {model} leaves {remaining['summary']}.{partial}"


# ----------------------------------------------------------------------------------- the phrases

def shift_words(session: str, shift, unit: str) -> str:
    """A session's shift (:class:`calib.session_shift.SessionShift`) said as a person sees it: how
    far its rows sit from the prediction and which way, what moved, and what to do."""
    e = [float(v) for v in shift.mean_position_error_mm]
    size = math.sqrt(sum(v * v for v in e))
    axis = max(range(3), key=lambda k: abs(e[k]))
    way = ("below the prediction" if e[2] < 0 else "above the prediction") if axis == 2 else \
        f"off the prediction along {'+-'[int(e[axis] < 0)]}{'xyz'[axis]}"
    way += f" (mean error {', '.join(f'{v:+.2f}' for v in e)} mm in x, y, z)"
    p = f"p = {shift.p_no_shift:.2g}" if shift.p_no_shift > 0 else "p < 1e-300"
    what = {"joint zeros": "the machine re-homed (each joint's zero moved: "
                           + ", ".join(f"{v:+.3g} +- {s:.2g}" for v, s in zip(shift.zeros, shift.zeros_std))
                           + f" {unit})",
            "instrument frame": "the instrument moved or was re-calibrated (its frame moved by "
                                + ", ".join(f"{v:+.3g}" for v in shift.frame_motion[:3]) + " mm)",
            "joint zeros and instrument frame": "the machine re-homed and the instrument moved"}[shift.chosen]
    return (f"the rows of session {session!r} sit {size:.2f} mm {way}, uniformly ({p} that nothing "
            f"moved): {what} between sessions; re-measure at least 6 poses at "
            f"the start of a session and re-reference (pipeline.run --from)")


def report_title(r: Report) -> str:
    """``Calibration of the hexapod`` / ``Discovery on the delta``."""
    return f"{'Calibration of' if r.kind == 'calibration' else 'Discovery on'} the {r.source.robot}"


#: The verdict of a calibration file alone (no run judged it here).
FILE_VERDICT = ("from the calibration file alone: its verdict, held-out figures and flagged rows are in the summary "
                "of the run that wrote it (pipeline.export --summary S.json)")


def verdict_text(r: Report) -> str:
    """The verdict's words (where the analysis states none: whether the fit converged; of a
    calibration file alone, not judged: :data:`FILE_VERDICT`)."""
    if r.verdict.words is not None:
        return r.verdict.words
    if r.verdict.success is None:
        return FILE_VERDICT
    return "converged" if r.verdict.success else "not a success"


def noise_words(noise: Noise | None) -> str:
    """The declared noise in words (``0.001 mm on positions (uniform, half-width)``)."""
    if noise is None:
        return "not stated"
    how = "half-width" if noise.distribution == "uniform" else "standard deviation"
    parts = [f"{noise.position_mm:g} mm on positions"]
    if noise.orientation_rad:
        parts.append(f"{noise.orientation_rad:g} rad on angles")
    if noise.joint:
        parts.append(f"{noise.joint:g} on joint readings")
    return f"{', '.join(parts)} ({noise.distribution}, {how})"


def machine_facts(r: Report) -> list[tuple[str, str]]:
    """The machine-and-recording section: ``(label, value)`` pairs."""
    src = r.source
    facts = [("robot", src.robot), ("recording", src.recording)]
    if r.kind == "calibration":
        f = r.fit
        if f is not None:  # a summary of a run (a calibration file alone has none of these)
            facts.append(("method", f"{f.method} ({f.solver}), {f.iterations} iterations"))
            facts.append(("calibration rows", f"{f.rows} ({f.rows_used} used)"))
            facts.append(("held-out poses", str(f.heldout_poses)))
    else:
        facts.append(("rows", str(src.rows)))
        facts.append(("candidate effects", ", ".join(c.name for c in r.effects.candidates) or "none"))
    facts.append(("declared noise", noise_words(src.noise)))
    if src.seed is not None:
        facts.append(("seed", str(src.seed)))
    files = dict(r.outputs.files)
    for key, label in (("calibration", "calibration file"), ("rrd", "Rerun recording")):
        if files.get(key):
            facts.append((label, files[key]))
    return facts


def figure_label(r: Report, row: FigureRow) -> str:
    """What a held-out figure row is (``position error``, ``cross-validated position error``,
    ``held-out closure residual (geometry alone -> with the effects)``)."""
    if row.quantity == "closure":
        return "held-out closure residual (geometry alone -> with the effects)"
    if r.kind == "discovery" and row.crossvalidated:
        return f"cross-validated {row.quantity} error, geometry alone"
    return f"{'cross-validated ' if row.crossvalidated else ''}{row.quantity} error"


def per_pose_label(quantity: str) -> str:
    """What a per-pose plot shows."""
    return "closure residual RMS over the joints" if quantity == "closure" else f"{quantity} error"


def tolerance_verdict(row: ParameterRow) -> str:
    """A parameter's error against its tolerance, in words."""
    if row.tolerance is None or not row.tolerance > 0:
        return "no tolerance declared"
    ratio = abs(row.error) / row.tolerance
    if row.implausible:
        return f"implausible: {ratio:.3g} x its tolerance"
    return f"within tolerance ({ratio:.2g} x)"


def determined_by(row: ParameterRow) -> str | None:
    """What determined a parameter, in words (None: not known)."""
    return DETERMINED_BY.get(row.source, row.source)


def effect_evidence(row: EffectRow) -> str:
    """An effect's evidence in one line: BIC drop, Wald test, cross-validated RMS, partial."""
    parts = []
    if row.delta_bic_when_added is not None:
        parts.append(f"BIC lower by {row.delta_bic_when_added:.4g} when it entered")
    if row.p_value is not None:
        parts.append(f"non-zero at p = {row.p_value:.2g} (Wald chi-square {row.wald_chi2:.4g} on {row.dof})")
    if row.cv_whitened_rms is not None:
        parts.append(f"cross-validated whitened RMS with it alone {row.cv_whitened_rms:.3g}")
    if row.partial:
        parts.append("partial: structure remains")
    return "; ".join(parts)


def search_words(search: Search | None) -> str | None:
    """How a discovery searched its nonlinear parameters, when not on every row (None then)."""
    if search is None:
        return None
    which = f" ({', '.join(search.effects)})" if search.effects else ""
    return (f"searched parameters{which} scanned on a seeded subsample of {search.subsample_rows:,} of the "
            f"{search.rows:,} rows, stratified in time (above {search.threshold:,} rows), then confirmed and refined "
            f"on every row")


def effect_notes(x: Effects) -> list[str]:
    """A discovery's findings beside its effects: the cross-validated RMS, the aliases, the re-simulation."""
    notes = []
    if x.effects and x.cv_whitened_rms_geometry is not None and x.cv_whitened_rms_chosen is not None:
        notes.append(f"cross-validated whitened RMS, geometry alone {x.cv_whitened_rms_geometry:.3g} -> with the "
                     f"effects {x.cv_whitened_rms_chosen:.3g} (1 is the declared noise)")
    for a in x.aliases:
        notes.append(f"cannot tell apart on this recording: {a.named} and {a.rival} ({a.named} fitted)")
    if x.resimulation is not None:
        notes.append(f"MuJoCo machine re-simulated: position RMS {x.resimulation.before_um:.4g} um -> "
                     f"{x.resimulation.after_um:.4g} um")
    words = search_words(x.search)
    if words is not None:
        notes.append(words[0].upper() + words[1:])
    return notes


def heldout_basis(r: Report) -> str:
    """What the held-out figures are (a calibration without held-out poses: its cross-validation)."""
    h = r.heldout
    if r.kind == "calibration" and h.crossvalidation is not None:
        return f"no held-out poses: {h.basis}"
    return h.basis


def implausible_notes(r: Report) -> list[str]:
    """The implausible parameters, one sentence each (a discovery's: those the effects bring back
    within tolerance, then those still implausible with them)."""
    imp = r.implausible
    return list(imp.words) + [f"still implausible with the effects: {w}" for w in imp.with_effects]


def law_words(law: Law) -> str:
    """What a proposed law leaves."""
    return "with it the recording is explained" if law.explained else f"with it: {law.remaining}"


def no_effect_words(x: Effects) -> str:
    """That no candidate effect was named."""
    return f"none of the candidates ({', '.join(c.name for c in x.candidates) or 'none given'}) earns its place"


def remaining_words(x: Effects) -> str:
    """What the discovery's model leaves."""
    return x.remaining.summary if x.remaining.present else "nothing beyond the declared noise"


def flagged_words(r: Report) -> list[str]:
    """The flagged rows' notes: the outlier test, what was done with them, how rows are numbered."""
    f, words = r.flagged, []
    if r.kind == "calibration":
        if f.outlier_verdict:
            words.append(f"outlier test: {f.outlier_verdict}")
        if f.rows:
            words.append("left out of the fit" if f.left_out or f.gross_left_out else "kept in the fit")
    else:
        if f.bad_rows:
            words.append(f"rows that look bad: {', '.join(map(str, f.bad_rows))}"
                         + (" (the model is wrong, not the data: none left out)" if f.model_wrong else ""))
        if f.rows:
            words.append("flagged rows are left out of the analysis")
    if f.numbering:
        words.append(f"rows: {f.numbering}")
    return words


def _flagged_state(f: Flagged) -> str:
    """What was done with a calibration's flagged rows (gross rows are left out before any fit
    unless every row is kept; the outlier test's unless ``--keep-outliers``)."""
    if f.left_out:
        return "left out"
    gross = [k for k in f.rows if k in set(f.gross)] if f.gross_left_out else []
    if not gross:
        return "kept"
    if len(gross) == len(f.rows):
        return "gross: left out before any fit"
    return f"gross rows {', '.join(map(str, gross))} left out before any fit, the others kept"


def _implausible_lines(words, indent: str) -> list[str]:
    if not words:
        return []
    n = len(words)
    lines = [f"{indent}implausible: {n} parameter{'s' if n > 1 else ''} far beyond the tolerance: the geometry may "
             "be absorbing unmodelled physics (python -m pipeline.discover) or the declared tolerance is too tight"]
    lines += [f"{indent}  {w}" for w in words[:IMPLAUSIBLE_LINES]]
    if n > IMPLAUSIBLE_LINES:
        lines.append(f"{indent}  ... {n - IMPLAUSIBLE_LINES} more in the summary JSON (implausible_parameters)")
    return lines


# ------------------------------------------------------------------------------ the terminal

def terminal_lines(r: Report) -> list[str]:
    """The summary ``pipeline.run`` (a calibration) or ``pipeline.discover`` (a discovery) prints,
    one line each: the verdict first, every figure with its unit."""
    return _calibration_lines(r) if r.kind == "calibration" else _discovery_lines(r)


def _calibration_lines(r: Report) -> list[str]:
    lines = [f"{report_title(r)} - {r.source.recording}"]
    if r.verdict.words is not None:
        word = {True: "SUCCESS", False: "NOT A SUCCESS", None: "NOT JUDGED"}[r.verdict.success]
        lines.append(f"  {word}: {r.verdict.words}")
    f = r.fit
    if f is not None:
        lines.append(f"  method {f.method} ({f.solver}): {f.iterations} iterations; {f.message}")
        lines.append(f"  max dQint per iteration: {', '.join(f'{v:.3g}' for v in f.history)}")
    lines += _heldout_lines(r.heldout)
    t = r.truth
    if t is not None and (t.rms_mm is not None or t.rms_rad is not None):
        parts = [f"{1e3 * t.rms_mm:.3f} um" if t.rms_mm is not None else None,
                 f"{t.rms_rad:.3g} rad" if t.rms_rad is not None else None]
        lines.append(f"  parameter error RMS (identified - injected): {', '.join(p for p in parts if p)}")
    if t is not None and t.gain_mean_percent is not None:
        lines.append(f"  calibration gain G: mean over parameters {t.gain_mean_percent:.4f}%, on the error norm "
                     f"{t.gain_norm_percent:.4f}%")
    if f is not None:
        lines.append(f"  condition numbers: {', '.join(f'{c:.0f}' for c in f.condition_numbers)}")
    fl = r.flagged
    state = ""
    if fl.rows:
        state = _flagged_state(fl)
        state = f" ({state}{'; --keep-outliers keeps them' if fl.left_out else ''})"
    lines.append(f"  flagged data rows (row k = file line k + 1): {', '.join(map(str, fl.rows)) or 'none'}{state}")
    if fl.outlier_verdict:
        lines.append(f"  outlier test: {fl.outlier_verdict}")
    if fl.heldout_after_without_mm is not None and fl.heldout_after_with_mm is not None:
        lines.append(f"  held-out position error after: {1e3 * fl.heldout_after_without_mm:.3f} um without the flagged "
                     f"rows, {1e3 * fl.heldout_after_with_mm:.3f} um with them")
    lines += _determination_lines(r)
    fr = r.frames
    if fr is not None:
        for row in fr.rows:
            which = f" of session {row.session}" if fr.sessions else ""
            lines.append(f"  instrument frame{which}: translation {', '.join(f'{v:.4g}' for v in row.translation_mm)} mm, "
                         f"rotation {', '.join(f'{v:.4g}' for v in row.rotation_rad)} rad")
        lines += [f"    {w}" for w in fr.held]
    lines += _implausible_lines(r.implausible.words, "  ")
    lines += [f"  warning: {w}" for w in r.warnings]
    if r.timing is not None:
        lines.append(f"  wall time {r.timing.total_s:.2f} s  (" + ", ".join(f"{k} {v:.2f} s" for k, v in r.timing.stages)
                     + ")")
    lines += [f"  wrote {path}" for _, path in r.outputs.files]
    return lines


def _heldout_lines(h: Heldout | None) -> list[str]:
    """The held-out errors: mean, RMS and max, before and after; without held-out poses the
    cross-validated prediction error."""
    if h is None:
        return []
    if h.crossvalidation is not None and all(row.crossvalidated for row in h.figures):
        cv = h.crossvalidation
        lines = [f"  no held-out poses: cross-validated prediction error ({cv.scheme}, {cv.fits} fits), measured minus "
                 "the prediction of a fit without the row (includes sensor noise)"]
        for row in h.figures:
            shown, scale = _display(row.unit)
            lines.append(f"  {row.quantity + ' error, ' + shown:<28}"
                         + "  ".join(f"{fig} {_f(getattr(row.after, fig), '.3f', scale)}" for fig in ("rms", "mean", "max")))
        return lines
    lines = [f"  {'held-out (' + str(h.poses) + ' poses)':<28}{'before':>12}{'after':>12}"]
    for row in h.figures:
        shown, scale = _display(row.unit)
        for fig in ("mean", "rms", "max"):
            b, a = getattr(row.before, fig), getattr(row.after, fig)
            lines.append(f"  {row.quantity + ' error, ' + shown + ' ' + fig:<28}{_f(b, '>12.3f', scale)}"
                         f"{_f(a, '>12.3f', scale)}")
    pos = h.figures[0]
    if pos.after.mean and pos.before.mean is not None:
        lines.append(f"  improvement of mean position error: {pos.before.mean / pos.after.mean:.1f}x  ({h.basis})")
    lines += [f"  shift between sessions: {w}" for w in h.session_shifts]
    return lines


def _determination_lines(r: Report) -> list[str]:
    """What the data determined and what they left to the prior."""
    d = r.determination
    if d is None:
        return []
    if not d.prior_used:
        return ["  prior: none (--no-prior: plain least squares)"]
    left, n_data = d.by_prior, len(d.by_data)
    names = f" ({', '.join(left[:PRIOR_NAMES])}{', ...' if len(left) > PRIOR_NAMES else ''})" if left else ""
    seen = (f" (the rows determine about {d.directions:.0f} of the {n_data + len(left)} free directions, singly or "
            "in combinations)") if d.directions is not None else ""
    lines = [f"  prior: {d.prior}",
             f"  determined by the data: {n_data} parameters{seen}; left to the prior: {len(left)}{names}"]
    lines += [f"    left to the prior: {w}" for w in d.combinations[:COMBINATION_LINES]]
    if len(d.combinations) > COMBINATION_LINES:
        lines.append(f"    ... {len(d.combinations) - COMBINATION_LINES} more combination(s) in the summary JSON")
    if d.suggested is not None:
        sp = d.suggested
        lines.append(f"  suggested: measure {sp.poses} more poses ({sp.what}): {sp.path}" if sp.poses else
                     f"  suggested: no poses: {sp.what}")
    return lines


def _discovery_lines(r: Report) -> list[str]:
    x, fl, h = r.effects, r.flagged, r.heldout
    lines = [r.verdict.words]
    t = x.geometry_test
    if t is not None:
        lines.append(f"Geometry alone: chi-square {t.chi2:.0f} on {t.dof} degrees of freedom, p = {t.p_value:.3g} "
                     f"({'consistent with' if t.p_value > t.alpha else 'NOT explained by'} the declared noise by this "
                     f"omnibus test).")
    lines += ["Where the geometry-only mismatch is: " + w for w in x.located]
    lines += _flagged_discovery_lines(fl)
    lines += _named_effect_lines(r)
    for a in x.aliases:
        if a.nested:
            lines.append(f"Cannot tell apart on this recording: {a.named} and {a.rival}, which contains it (its extra "
                         f"parameters gain {a.delta_bic:.1f} BIC, less than {_f(a.nested_min_delta_bic, '.0f')}); the "
                         f"simpler {a.named} fitted.")
        else:
            lines.append(f"Cannot tell apart on this recording: {a.named} and {a.rival} (evidence within "
                         f"{a.delta_bic:.1f} BIC, regressor correlation {_f(a.correlation, '.2f')}); {a.named} fitted.")
    lines += _separation_lines(x)
    lines += _law_lines(x.law)
    words = search_words(x.search)
    if words is not None:
        lines.append(f"Search: {words}.")
    lines += _discovery_heldout_lines(h, x.resimulation)
    cv = [row for row in h.figures if row.crossvalidated]
    if cv and h.crossvalidation is not None:
        b = cv[0].before
        lines.append(f"Cross-validated prediction error ({h.crossvalidation.scheme}, {h.crossvalidation.model}): position "
                     f"RMS {_f(b.rms, '.3f', 1e3)} um, mean {_f(b.mean, '.3f', 1e3)} um, max {_f(b.max, '.3f', 1e3)} um")
    imp = r.implausible
    lines += [f"Implausible with the geometry alone, back within tolerance with the effects: {w}"
              for w in imp.words[:DISCOVERY_IMPLAUSIBLE_LINES]]
    if len(imp.words) > DISCOVERY_IMPLAUSIBLE_LINES:
        lines.append(f"... and {len(imp.words) - DISCOVERY_IMPLAUSIBLE_LINES} more parameters (summary JSON: "
                     "implausible_parameters)")
    lines += [f"Still implausible with the effects: {w}" for w in imp.with_effects]
    if r.outputs.law_asked:
        lines.append(f"kept the proposed law in {r.outputs.law_kept}" if r.outputs.law_kept
                     else "no law proposed: nothing kept (--law)")
    lines += [f"wrote {path}" for _, path in r.outputs.files]
    return lines


def _flagged_discovery_lines(fl) -> list[str]:
    """A discovery's outlier rows, its bad rows, the large residuals kept."""
    lines: list[str] = []
    if fl.rows:
        lines.append(f"Outlier rows (gross and isolated: not shared by neighbours in time, workspace or direction), "
                     f"left out: {', '.join(map(str, fl.rows))} (1-based data rows)")
    if fl.model_wrong:
        lines.append(f"{len(fl.bad_rows)} of {fl.total_rows} rows look bad (more than 5%): the model is wrong, not the "
                     f"data; no row is left out.")
    elif fl.shared:
        lines.append("Rows with large residuals kept as evidence (shared by their neighbours): "
                     + "; ".join(f"{k} ({', '.join(v)})" for k, v in fl.shared))
    return lines


def _named_effect_lines(r: Report) -> list[str]:
    """The effects named (each with its evidence and coefficients), or why none is."""
    x = r.effects
    lines: list[str] = []
    if not x.effects:
        if r.verdict.success:
            lines.append("Left-out physics: none. The geometric model explains the recording to the noise.")
        else:
            lines.append(f"Left-out physics: {no_effect_words(x)}; what remains is not explained (see the verdict).")
    else:
        status = "" if r.verdict.success else " (partial: the remainder is not explained)"
        lines.append(f"Left-out physics: {' + '.join(e.name for e in x.effects)}{status}; cross-validated whitened RMS "
                     f"{_f(x.cv_whitened_rms_geometry, '.2f')} -> {_f(x.cv_whitened_rms_chosen, '.2f')}.")
        for e in x.effects:
            lines.append(f"  {e.name} ({e.granularity.replace('_', ' ')}): BIC lower by {_f(e.delta_bic_when_added, '.0f')} "
                         f"when it entered; non-zero at p = {_f(e.p_value, '.2g')} (Wald chi-square "
                         f"{_f(e.wald_chi2, '.0f')} on {e.dof})")
            for c in e.coefficients:
                if c.name == "from_row":  # a step placed by row, never by a time the recording may not have
                    lines.append(f"    from row {c.value:.0f}" if math.isfinite(c.value) else "    after the last row")
                    continue
                unc = f" +- {c.std:.2g}" if _finite(c.std) else ""
                lines.append(f"    {c.name} = {c.value:.6g}{unc} {c.unit}")
    lines += [f"Not named: {w}." for w in x.not_named]
    return lines


def _discovery_heldout_lines(h, rs) -> list[str]:
    """The held-out residual RMS (as predicted, the shifts between sessions) and the MuJoCo
    re-simulation."""
    lines: list[str] = []
    closure = h.figures[0]
    lines.append(f"Held-out residual RMS: {_f(closure.before.rms, '.3f', 1e3)} um -> {_f(closure.after.rms, '.3f', 1e3)} "
                 f"um (noise floor {_f(h.noise_floor_mm, '.3f', 1e3)} um; {h.basis}).")
    if h.as_predicted_mm is not None:
        lines.append(f"  as predicted, the sessions' shifts left in: {_f(h.as_predicted_mm[0], '.3f', 1e3)} um -> "
                     f"{_f(h.as_predicted_mm[1], '.3f', 1e3)} um; the figures above take each shifted session's shift out")
    if closure.before.mean is not None:
        lines.append(f"  mean {_f(closure.before.mean, '.3f', 1e3)} um -> {_f(closure.after.mean, '.3f', 1e3)} um, "
                     f"max {_f(closure.before.max, '.3f', 1e3)} um -> {_f(closure.after.max, '.3f', 1e3)} um "
                     f"(RMS over the joints, per held-out row)")
    lines += [f"Shift between sessions: {w}." for w in h.session_shifts]
    if rs is not None:
        lines.append(f"MuJoCo machine re-simulated: position RMS {rs.before_um:.3f} um -> {rs.after_um:.3f} um")
        if rs.sysid is not None:
            y = rs.sysid
            lines.append(f"  mujoco.sysid re-fit {y.parameter}: {y.start:.6g} -> {y.value:.6g} +- {y.interval_95:.2g} "
                         f"{y.unit} (95%)")
    return lines


def _separation_lines(x: Effects) -> list[str]:
    """What the poses cannot separate, in a few lines: the geometric combinations left to the
    prior (the first :data:`SEPARATION_LINES`; all in the JSON), each effect that cannot be
    separated from them with the combination that mimics it, the poses that would separate them."""
    sep = x.separation
    if sep is None:
        return []
    left = sep.left_to_prior
    shown = "; ".join(left[:SEPARATION_LINES]) + ("; ..." if len(left) > SEPARATION_LINES else "")
    lines = [f"Geometry: the rows determine {sep.determined} of its {sep.free} combinations; {len(left)} are left "
             f"to the prior ({sep.prior_source}) and held at their nominal values: {shown} (summary JSON: "
             f"separation.left_to_prior)."]
    for u in sep.unseparated:
        more = f" and {u.more} more combinations" if u.more else ""
        by = ", ".join(u.separated_by) or "none of the poses tried"
        lines.append(f"Cannot be separated on this pose set: {u.effect} ({u.form}): {u.combination}{more} acts "
                     f"on these poses as the geometry's {u.geometry}; not named. Poses that would separate it: {by}.")
    for p in sep.families:
        separates = f"; separates {', '.join(p.separates)}" if p.separates else ""
        lines.append(f"  poses with {p.family} ({p.reachable} of {p.tried} reachable): would determine "
                     f"{p.determines} of the {len(left)} combinations left to the prior{separates}")
    return lines


def _law_lines(law: Law | None) -> list[str]:
    """A proposed law in words: the formula, its constants joint by joint with their standard
    deviations, the cross-validated residual before and after."""
    if law is None:
        return []
    after = "explained" if law.explained else "still NOT explained: " + law.remaining
    lines = [f"Proposed law, not in the library: {law.formula}",
             f"  cross-validated residual RMS {_f(law.cv_before_mm, '.2f', 1e3)} um -> {_f(law.cv_after_mm, '.2f', 1e3)} "
             f"um (noise floor {_f(law.noise_floor_mm, '.2f', 1e3)} um); with it: {after}"]
    for c in law.constants:
        std = c.std or (None,) * len(c.values)
        if c.granularity == "per_chain":
            each = ", ".join(f"{v:.4g} +- {_f(sd, '.2g')}" for v, sd in zip(c.values, std))
        else:
            each = f"{c.values[0]:.4g} +- {_f(std[0], '.2g')}"
        lines.append(f"  [{c.name}] ({c.granularity.replace('_', ' ')}): {each} {c.unit}")
    if law.library_effects_dropped:
        model = " + ".join(["geometry", *law.library_effects, "the law"])
        lines.append(f"  with the law in, the library's {', '.join(law.library_effects_dropped)} no longer earns its "
                     f"place (re-examined: the BIC rises by less than an effect needs to enter); the law's model: "
                     f"{model}")
    return lines


# ------------------------------------------------------------------------------ the markdown

def report_markdown(r: Report) -> str:
    """The summary panel of the Rerun file: the verdict first, then short lines and tables
    (every table row under 90 characters)."""
    return "\n".join(_calibration_markdown(r) if r.kind == "calibration" else _discovery_markdown(r))


def _calibration_markdown(r: Report) -> list[str]:
    f, n, fl = r.fit, r.source.noise, r.flagged
    lines = [f"## {r.source.robot}: calibration", r.source.recording, ""]
    if r.verdict.words is not None:
        lines += [f"**{'Success' if r.verdict.success else 'Not a success'}**: {r.verdict.words}", ""]
    lines += ["| run | |", "|---|---|"]
    if f is not None:
        lines += [f"| method | {f.method} ({f.solver}) |",
                  f"| poses | {f.rows} calibration, {f.heldout_poses} held-out |"]
    if n is not None:
        lines.append(f"| noise | {n.position_mm:g} mm, {n.orientation_rad:g} rad, joints {n.joint:g} ({n.distribution}) |")
    if f is not None:
        lines.append(f"| iterations | {f.iterations} ({'converged' if f.converged else 'not converged'}) |")
    lines.append(f"| flagged rows | {', '.join(map(str, fl.rows)) or 'none'}"
                 f"{f' (data rows; {_flagged_state(fl)})' if fl.rows else ''} |")
    lines += _error_table(r.heldout)
    t = r.truth
    if t is not None and t.rms_mm is not None:
        lines += ["", "| parameters | |", "|---|---|", f"| error RMS, lengths | {1e3 * t.rms_mm:.2f} um |"]
        if t.rms_rad is not None:
            lines.append(f"| error RMS, angles | {1e6 * t.rms_rad:.2f} urad |")
        if t.gain_norm_percent is not None:
            lines.append(f"| gain G (norm) | {t.gain_norm_percent:.2f} % |")
    d = r.determination
    if d is not None and d.prior_used and (d.by_data or d.by_prior):
        left = d.by_prior
        names = (f" ({', '.join(left[:MARKDOWN_PRIOR_NAMES])}{', ...' if len(left) > MARKDOWN_PRIOR_NAMES else ''})"
                 if left else "")
        lines += ["", f"Determined by the data: {len(d.by_data)} parameters; left to the prior: {len(left)}{names}"]
    lines += _implausible_markdown(r.implausible.words, "Implausible", IMPLAUSIBLE_LINES)
    if f is not None:
        cn = f.condition_numbers
        lines += ["", f"Condition number{'s' if len(cn) > 1 else ''}: " + ", ".join(f"{c:.0f}" for c in cn)]
    h = r.heldout
    if h is not None and h.crossvalidation is None:
        lines += ["", f"Held-out basis: {h.basis}."]
    if f is not None:
        lines += ["", f"Stop: {f.message}"]
    if fl.outlier_verdict:
        lines += ["", f"Outlier test: {fl.outlier_verdict}"]
    for w in r.warnings:
        lines += ["", f"Warning: {w}"]
    return lines


def _implausible_markdown(words, lead: str, shown: int) -> list[str]:
    """Implausible parameters as a headline and the first ``shown`` sentences (as the terminal shows them)."""
    if not words:
        return []
    n = len(words)
    lines = ["", f"**{lead}**: {n} parameter{'s' if n > 1 else ''} far beyond the tolerance:"]
    lines += [f"- {w}" for w in words[:shown]]
    if n > shown:
        lines.append(f"- ... {n - shown} more in the summary JSON (implausible_parameters)")
    return lines


def _error_table(h: Heldout | None) -> list[str]:
    """Markdown rows of the held-out errors (RMS, mean and max, before and after), or of the
    cross-validated prediction error where there are no held-out poses."""
    if h is None:
        return []
    if h.crossvalidation is not None and all(row.crossvalidated for row in h.figures):
        rows = ["", f"| cross-validated ({h.crossvalidation.scheme}) | RMS | mean | max |", "|---|---|---|---|"]
        for row in h.figures:
            shown, scale = _display(row.unit)
            a = row.after
            rows.append(f"| {row.quantity}, {shown} | {_f(a.rms, '.3f', scale)} | {_f(a.mean, '.3f', scale)} | "
                        f"{_f(a.max, '.3f', scale)} |")
        return rows
    rows = ["", f"| held-out ({h.poses} poses) | before | after |", "|---|---|---|"]
    for row in h.figures:
        shown, scale = _display(row.unit)
        for fig, word in (("rms", "RMS"), ("mean", "mean"), ("max", "max")):
            rows.append(f"| {row.quantity} {word}, {shown} | {_f(getattr(row.before, fig), '.3f', scale)} | "
                        f"{_f(getattr(row.after, fig), '.3f', scale)} |")
    return rows


def _discovery_markdown(r: Report) -> list[str]:
    x, fl, h = r.effects, r.flagged, r.heldout
    rem = x.remaining
    closure = h.figures[0]
    lines = [f"# {'Explained' if r.verdict.success else 'NOT explained'}", "", r.verdict.words, ""]
    lines += [f"**Shift between sessions**: {w}." for w in h.session_shifts] + [""] * bool(h.session_shifts)
    lines += ["| what remains | |", "|---|---|",
             f"| model | {model_words([e.name for e in x.effects])} |",
             f"| residual RMS | {_f(rem.rms_mm, '.2f', 1e3)} um (noise floor {_f(rem.noise_floor_mm, '.2f', 1e3)} um) |",
             f"| whitened | {_f(rem.noise_ratio, '.2f')} x the declared noise |",
             f"| follows | {', '.join(rem.follows) or 'none of the quantities tested'} |",
             f"| on {r.source.chain_word}s | {', '.join(map(str, rem.chains)) or 'none'} |",
             f"| held-out RMS | {_f(closure.before.rms, '.3f', 1e3)} -> {_f(closure.after.rms, '.3f', 1e3)} um |"]
    if closure.before.mean is not None:
        lines += [f"| held-out mean | {_f(closure.before.mean, '.3f', 1e3)} -> {_f(closure.after.mean, '.3f', 1e3)} um |",
                  f"| held-out max | {_f(closure.before.max, '.3f', 1e3)} -> {_f(closure.after.max, '.3f', 1e3)} um |"]
    if h.noise_floor_mm is not None:
        lines.append(f"| noise floor | {_f(h.noise_floor_mm, '.3f', 1e3)} um |")
    cv = [row for row in h.figures if row.crossvalidated]
    if cv and h.crossvalidation is not None:
        b = cv[0].before
        lines.append(f"| CV error ({h.crossvalidation.scheme}) | RMS {_f(b.rms, '.3f', 1e3)}, mean "
                     f"{_f(b.mean, '.3f', 1e3)}, max {_f(b.max, '.3f', 1e3)} um |")
    lines.append(f"| flagged rows | {', '.join(map(str, fl.rows)) or 'none'} |")
    if fl.model_wrong:
        lines.append(f"| bad rows | {len(fl.bad_rows)} of {fl.total_rows}: model wrong, none left out |")
    if x.effects:
        lines += ["", "| effect | coefficient | value | +- | unit |", "|---|---|---|---|---|"]
        for e in x.effects:
            for c in e.coefficients:
                unc = f"{c.std:.2g}" if _finite(c.std) else ""
                lines.append(f"| {e.name} | {c.name} | {c.value:.4g} | {unc} | {c.unit} |")
    law = x.law
    if law is not None:
        lines += ["", f"**Proposed law, not in the library**: `{law.formula}`; cross-validated residual "
                      f"{_f(law.cv_before_mm, '.2f', 1e3)} -> {_f(law.cv_after_mm, '.2f', 1e3)} um.", "",
                  f"| term | constant per {r.source.chain_word} | unit |", "|---|---|---|"]
        lines += [f"| {c.name} | {', '.join(f'{v:.4g}' for v in c.values)} | {c.unit} |" for c in law.constants]
    lines += ["", "| candidate | BIC drop alone | CV RMS | named |", "|---|---|---|---|",
              f"| (geometry) | 0 | {_f(x.cv_whitened_rms_geometry, '.2f')} | |"]
    for c in x.candidates:
        lines.append(f"| {c.name} | {_f(c.delta_bic_vs_none, '.0f')} | {_f(c.cv_whitened_rms, '.2f')} | "
                     f"{'yes' if c.named else ''} |")
    lines += ["", "BIC drop: evidence against geometry alone (an effect needs 10 to enter); CV RMS: "
              "cross-validated whitened residual (1 = the noise)."]
    for a in x.aliases:
        within = "contains it; the simpler one named" if a.nested else f"within {a.delta_bic:.1f} BIC"
        lines += ["", f"Cannot tell apart: {a.named} and {a.rival} ({within})."]
    lines += [f"\nNot named: {w}." for w in x.not_named]
    if x.resimulation is not None:
        lines += ["", f"MuJoCo re-simulation, position RMS: {x.resimulation.before_um:.2f} -> "
                      f"{x.resimulation.after_um:.2f} um."]
    lines += _implausible_markdown(r.implausible.words, "Implausible with the geometry alone, back within tolerance "
                                   "with the effects", DISCOVERY_IMPLAUSIBLE_LINES)
    lines += _implausible_markdown(r.implausible.with_effects, "Still implausible with the effects",
                                   len(r.implausible.with_effects))
    words = search_words(x.search)
    if words is not None:
        lines += ["", f"Search: {words}."]
    lines += ["", "Geometry alone, where the mismatch is:"] + [f"- {w}" for w in x.located]
    return lines
