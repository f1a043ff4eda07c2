"""The report (:mod:`pipeline.report.model`) as one self-contained HTML file: no script, no
network, the plots inline SVG drawn here, every string escaped. The sentences are
:mod:`pipeline.report.text`'s; this module lays them out.

Figures are shown in um and urad (the model keeps mm and rad), four significant digits; each
figure's cell names what it is in a ``data-figure`` attribute (``heldout/position error/after/rms``)
and its displayed unit in ``data-unit``, so that a reader (or a test) can find it.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

from pipeline.formats.outputs import atomic_write
from .model import Report
from .text import (DISPLAY_SCALE, determined_by, effect_evidence, effect_notes, figure_label, flagged_words,
                          heldout_basis, implausible_notes, law_words, machine_facts, no_effect_words, per_pose_label,
                          remaining_words, report_title, tolerance_verdict, verdict_text)

__all__ = ["render_html", "write_report", "svg_dot_plot", "svg_parameter_plot"]
#: Significant digits of a displayed figure.
DIGITS = 4
#: Colours of before / after (the Rerun views' grey and blue) and of an implausible parameter.
BEFORE, AFTER, ALARM, BAND = "#9a9a9a", "#1f6fb4", "#c0392b", "#e7eef6"
#: Rows of a compensation table shown at most.
COMPENSATION_ROWS = 20

STYLE = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;margin:24px auto;max-width:1100px;color:#222;
line-height:1.35}
h1{font-size:1.6em;margin-bottom:.2em}h2{font-size:1.2em;border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;margin:.5em 0;font-size:.9em}th,td{border:1px solid #ddd;padding:2px 8px;text-align:left}
th{background:#f3f3f3}td.num{text-align:right;font-variant-numeric:tabular-nums}
.verdict{padding:10px 14px;border-radius:4px;font-weight:600}.ok{background:#e6f4ea;border:1px solid #7bbf8e}
.bad{background:#fbeaea;border:1px solid #d88}.implausible td{color:#c0392b}.note{color:#555;font-size:.9em}
.legend span{display:inline-block;margin-right:1.2em}.swatch{display:inline-block;width:10px;height:10px;margin-right:4px}
svg text{font-family:system-ui,sans-serif}
"""


def e(text) -> str:
    """``text`` escaped for HTML (quotes too)."""
    return html.escape(str(text), quote=True)


def fmt(value: float | None, scale: float = 1.0) -> str:
    """A figure in :data:`DIGITS` significant digits (a dash for none)."""
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value * scale:.{DIGITS}g}"


def display(unit: str) -> tuple[str, float]:
    """``(displayed unit, scale)`` of a model unit."""
    return DISPLAY_SCALE.get(unit, (unit, 1.0))


def num(value: float | None, unit: str, figure: str | None = None) -> str:
    """A table cell of a figure in its displayed unit."""
    shown, scale = display(unit)
    attrs = f' data-figure="{e(figure)}" data-unit="{e(shown)}"' if figure else ""
    return f'<td class="num"{attrs}>{e(fmt(value, scale))}</td>'


# ----------------------------------------------------------------------------------------- plots

def _ticks(lo: float, hi: float, log: bool) -> list[float]:
    if log:
        return [10.0 ** k for k in range(math.floor(math.log10(lo)), math.ceil(math.log10(hi)) + 1)]
    step = 10 ** math.floor(math.log10(max(hi - lo, 1e-300)))
    for m in (1, 2, 5, 10):
        if (hi - lo) / (m * step) <= 6:
            step *= m
            break
    return [k * step for k in range(math.ceil(lo / step), math.floor(hi / step) + 1)]


def svg_dot_plot(series: list[tuple[str, str, list[float]]], *, y_label: str, x_label: str, title: str,
                 width: int = 1000, height: int = 300) -> str:
    """An inline SVG of values per index (one dot per value, series side by side), log y where the
    values span more than a decade; ``series``: ``(name, colour, values)``, the values already in
    the unit of ``y_label``."""
    values = [v for _, _, vs in series for v in vs if v is not None and math.isfinite(v)]
    n = max((len(vs) for _, _, vs in series), default=0)
    if not values or n == 0:
        return ""
    positive = [v for v in values if v > 0]
    log = bool(positive) and max(positive) / min(positive) > 10 and len(positive) == len(values)
    left, right, top, bottom = 70, 20, 30, 45
    pw, ph = width - left - right, height - top - bottom
    if log:
        lo, hi = 10 ** math.floor(math.log10(min(positive))), 10 ** math.ceil(math.log10(max(positive)))
        to_y = lambda v: top + ph * (1 - (math.log10(v) - math.log10(lo)) / (math.log10(hi) - math.log10(lo)))  # noqa: E731
    else:
        lo, hi = min(0.0, min(values)), max(values) * 1.1 or 1.0
        to_y = lambda v: top + ph * (1 - (v - lo) / (hi - lo))  # noqa: E731
    to_x = lambda i: left + pw * (i + 0.5) / n  # noqa: E731
    out = [f'<svg width="{width}" height="{height}" viewBox="0 0 {width} {height}" role="img" '
           f'aria-label="{e(title)}">',
           f'<text x="{left}" y="18" font-size="13" font-weight="600">{e(title)}</text>']
    for t in _ticks(lo, hi, log):
        y = to_y(t)
        out.append(f'<line x1="{left}" x2="{left + pw}" y1="{y:.1f}" y2="{y:.1f}" stroke="#e5e5e5"/>'
                   f'<text x="{left - 6}" y="{y + 4:.1f}" font-size="11" text-anchor="end">{e(f"{t:g}")}</text>')
    out.append(f'<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="none" stroke="#999"/>')
    r = 3.0 if n <= 100 else 2.0
    for k, (name, colour, vs) in enumerate(series):
        dx = (k - (len(series) - 1) / 2) * min(6.0, 0.3 * pw / n)
        for i, v in enumerate(vs):
            if v is None or not math.isfinite(v) or (log and v <= 0):
                continue
            out.append(f'<circle cx="{to_x(i) + dx:.1f}" cy="{to_y(v):.1f}" r="{r}" fill="{colour}"/>')
    out.append(f'<text x="{left + pw / 2}" y="{height - 8}" font-size="12" text-anchor="middle">{e(x_label)}</text>')
    out.append(f'<text x="14" y="{top + ph / 2}" font-size="12" text-anchor="middle" '
               f'transform="rotate(-90 14 {top + ph / 2})">{e(y_label)}{" (log)" if log else ""}</text>')
    x = left + pw  # the legend right of the title, above the plot
    for name, colour, _ in reversed(series):
        out.append(f'<text x="{x}" y="18" font-size="12" text-anchor="end">{e(name)}</text>')
        x -= 7 * len(name) + 8
        out.append(f'<circle cx="{x}" cy="14" r="4" fill="{colour}"/>')
        x -= 16
    out.append("</svg>")
    return "".join(out)


def svg_parameter_plot(rows, *, width: int = 1000) -> str:
    """An inline SVG of each parameter's identified error in units of its tolerance, with its
    +-2 sigma bar, against the +-1 tolerance band (parameters without a tolerance left out)."""
    rows = [r for r in rows if r.tolerance]
    if not rows:
        return ""
    row_h, left, right, top = 14, 80, 20, 40
    height = top + row_h * len(rows) + 40
    extent = max(max((abs(r.error) + (r.two_sigma or 0.0)) / r.tolerance for r in rows), 1.5)
    extent = math.ceil(extent)
    pw = width - left - right
    to_x = lambda v: left + pw * (v + extent) / (2 * extent)  # noqa: E731
    out = [f'<svg width="{width}" height="{height}" viewBox="0 0 {width} {height}" role="img" '
           f'aria-label="identified errors in tolerances">',
           f'<text x="{left}" y="16" font-size="13" font-weight="600">identified error from nominal, in units of '
           f'its tolerance (bars: &#177;2&#963;; band: &#177;1 tolerance)</text>',
           f'<rect x="{to_x(-1):.1f}" y="{top}" width="{to_x(1) - to_x(-1):.1f}" height="{row_h * len(rows)}" '
           f'fill="{BAND}"/>']
    for t in _ticks(-extent, extent, False):
        x = to_x(t)
        out.append(f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{top}" y2="{top + row_h * len(rows)}" stroke="#ddd"/>'
                   f'<text x="{x:.1f}" y="{top - 4}" font-size="10" text-anchor="middle">{e(f"{t:g}")}</text>')
    for i, r in enumerate(rows):
        y = top + row_h * (i + 0.5)
        c = ALARM if r.implausible else AFTER
        v = r.error / r.tolerance
        out.append(f'<text x="{left - 6}" y="{y + 4:.1f}" font-size="10" text-anchor="end">{e(r.name)}</text>')
        if r.two_sigma:
            a, b = to_x(v - r.two_sigma / r.tolerance), to_x(v + r.two_sigma / r.tolerance)
            out.append(f'<line x1="{a:.1f}" x2="{b:.1f}" y1="{y:.1f}" y2="{y:.1f}" stroke="{c}" stroke-width="1.5"/>')
        out.append(f'<circle cx="{to_x(v):.1f}" cy="{y:.1f}" r="3" fill="{c}"/>')
    out.append(f'<text x="{left + pw / 2}" y="{height - 10}" font-size="12" text-anchor="middle">error / tolerance'
               f'</text></svg>')
    return "".join(out)


# -------------------------------------------------------------------------------------- sections

def _verdict(r: Report) -> str:
    ok = r.verdict.success
    label = "CALIBRATION FILE" if ok is None else {
        ("calibration", True): "CALIBRATED", ("calibration", False): "NOT A SUCCESS",
        ("discovery", True): "EXPLAINED", ("discovery", False): "NOT EXPLAINED"}[(r.kind, bool(ok))]
    cause = f" (cause: {r.verdict.cause})" if r.verdict.cause else ""
    words = verdict_text(r)
    said = words.lower().startswith(("calibrated", "not calibrated", "explained", "not explained"))
    lead = "" if said else f"{e(label)}: "
    return (f'<div class="verdict {"ok" if ok else ("" if ok is None else "bad")}" id="verdict">{lead}{e(words)}'
            f'{e(cause)}</div>')


def _machine(r: Report) -> str:
    rows = "".join(f"<tr><th>{e(label)}</th><td>{e(value)}</td></tr>" for label, value in machine_facts(r))
    return f'<h2>Machine and recording</h2><table id="machine">{rows}</table>'


def _parameters(r: Report) -> str:
    p = r.parameters
    if p is None:
        return ""
    head = ("<tr><th>parameter</th><th>identified</th><th>error from nominal</th><th>&plusmn;2&sigma;</th>"
            "<th>tolerance (1 sd)</th><th>unit</th><th>determined by</th><th>tolerance verdict</th></tr>")
    body = []
    for row in p.rows:
        cls = ' class="implausible"' if row.implausible else ""
        body.append(f'<tr{cls} data-parameter="{e(row.name)}"><td>{e(row.name)}</td>'
                    f'<td class="num" data-figure="parameter/{e(row.name)}/value">{e(fmt(row.value) if row.value is not None else "-")}</td>'
                    f'<td class="num" data-figure="parameter/{e(row.name)}/error">{e(fmt(row.error))}</td>'
                    f'<td class="num" data-figure="parameter/{e(row.name)}/two_sigma">{e(fmt(row.two_sigma))}</td>'
                    f'<td class="num" data-figure="parameter/{e(row.name)}/tolerance">{e(fmt(row.tolerance))}</td>'
                    f'<td>{e(row.unit)}</td><td>{e(determined_by(row) or "-")}</td><td>{e(tolerance_verdict(row))}</td>'
                    '</tr>')
    notes = [f"<p class=\"note\">Prior: {e(p.prior)}</p>"]
    implausible = implausible_notes(r)
    if implausible:
        notes.append("<ul>" + "".join(f"<li>{e(w)}</li>" for w in implausible) + "</ul>")
    if p.left_to_prior:
        notes.append("<p class=\"note\">Combinations the poses left to the prior:</p><ul>"
                     + "".join(f"<li>{e(w)}</li>" for w in p.left_to_prior) + "</ul>")
    return ("<h2>Identified parameters</h2>" + svg_parameter_plot(p.rows) + "".join(notes)
            + f'<table id="parameters">{head}{"".join(body)}</table>')


def _heldout(r: Report) -> str:
    h = r.heldout
    if h is None:
        return "<h2>Held-out errors</h2><p>No held-out poses and no cross-validation.</p>"
    rows = []
    for f in h.figures:
        shown, _ = display(f.unit)
        label = figure_label(r, f)
        for fig in ("rms", "mean", "max"):
            b = None if f.before is None else getattr(f.before, fig)
            a = None if f.after is None else getattr(f.after, fig)
            if a is None and b is None:
                continue
            rows.append(f"<tr><td>{e(label)}</td><td>{e(fig)}</td>"
                        + num(b, f.unit, f"heldout/{label}/before/{fig}")
                        + num(a, f.unit, f"heldout/{label}/after/{fig}") + f"<td>{e(shown)}</td></tr>")
    parts = [f"<h2>Held-out errors</h2><p class=\"note\">{e(heldout_basis(r))} ({h.poses} poses)</p>",
             "<table id=\"heldout\"><tr><th>quantity</th><th>figure</th><th>before</th><th>after</th><th>unit</th></tr>"
             + "".join(rows) + "</table>"]
    if h.noise_floor_mm is not None:
        parts.append(f'<p>noise floor: <span data-figure="heldout/noise floor" data-unit="um">'
                     f'{e(fmt(h.noise_floor_mm, 1e3))}</span> um</p>')
    if h.as_predicted_mm is not None:
        parts.append(f"<p>as predicted, the sessions' shifts left in: {e(fmt(h.as_predicted_mm[0], 1e3))} um -> "
                     f"{e(fmt(h.as_predicted_mm[1], 1e3))} um; the figures above take each shifted session's shift "
                     f"out</p>")
    parts += [f'<p class="shift"><b>Shift between sessions</b>: {e(w)}.</p>' for w in h.session_shifts]
    for pp in h.per_pose:
        shown, scale = display(pp.unit)
        label = per_pose_label(pp.quantity)
        parts.append(svg_dot_plot([("before", BEFORE, [v * scale for v in pp.before]),
                                   ("after", AFTER, [v * scale for v in pp.after])],
                                  y_label=f"{label}, {shown}", title=f"{label} per held-out pose",
                                  x_label="held-out pose (in the order measured)" if pp.rows is None else
                                  f"held-out row (data rows {pp.rows[0]} to {pp.rows[-1]})"))
    if h.iso9283:
        body = "".join(f"<tr><td>{e(', '.join(map(str, p.rows)))}</td><td class=\"num\">{p.repeats}</td>"
                       + num(p.ap_before, "mm", f"iso9283/{k}/AP_before") + num(p.ap_after, "mm", f"iso9283/{k}/AP_after")
                       + num(p.rp, "mm", f"iso9283/{k}/RP") + "</tr>" for k, p in enumerate(h.iso9283))
        parts.append(f"<h3>ISO 9283 accuracy and repeatability of the repeated poses</h3><p class=\"note\">"
                     f"{e(h.iso_standard)}</p><table id=\"iso9283\"><tr><th>rows</th><th>visits</th><th>AP before, um"
                     f"</th><th>AP after, um</th><th>RP, um</th></tr>{body}</table>")
    return "".join(parts)


def _frames(r: Report) -> str:
    f = r.frames
    if f is None:
        return "<h2>Instrument frames</h2><p>None: the poses were measured in the robot's base frame.</p>"
    body = []
    for row in f.rows:
        cells = "".join(f'<td class="num">{e(fmt(v))}</td>' for v in row.translation_mm + row.rotation_rad)
        std = "".join(f'<td class="num">{e(fmt(v))}</td>' for v in (row.translation_std_mm or ()) + (row.rotation_std_rad or ()))
        body.append(f"<tr><td>{e(row.session)}</td>{cells}</tr>")
        if std:
            body.append(f"<tr class=\"note\"><td>&plusmn;1 sd</td>{std}</tr>")
    held = "".join(f"<li>{e(w)}</li>" for w in f.held)
    return ("<h2>Instrument frames</h2><table id=\"frames\"><tr><th>session</th><th>x, mm</th><th>y, mm</th><th>z, mm</th>"
            "<th>rot x, rad</th><th>rot y, rad</th><th>rot z, rad</th></tr>" + "".join(body) + "</table>"
            + (f"<ul>{held}</ul>" if held else ""))


def _effects(r: Report) -> str:
    x = r.effects
    if x is None:
        return ""
    parts = ["<h2>Effects found</h2>"]
    if x.effects:
        body = []
        for row in x.effects:
            coefs = "<br>".join(f"{e(c.name)} = {e(fmt(c.value))}" + (f" &plusmn; {e(fmt(c.std))}" if c.std is not None
                                                                       else "") + f" {e(c.unit)}"
                                for c in row.coefficients)
            body.append(f"<tr><td>{e(row.name)}</td><td>{e(row.granularity.replace('_', ' '))}</td><td>{coefs}</td>"
                        f"<td>{e(effect_evidence(row))}</td></tr>")
        parts.append("<table id=\"effects\"><tr><th>effect</th><th>granularity</th><th>coefficients</th>"
                     "<th>evidence</th></tr>" + "".join(body) + "</table>")
    else:
        words = no_effect_words(x)
        parts.append(f"<p>{e(words[0].upper() + words[1:])}.</p>")
    parts.append(f"<p>What remains: {e(remaining_words(x))}</p>")
    if x.not_named:
        parts.append("<ul class=\"not-named\">" + "".join(f"<li>Not named: {e(w)}</li>" for w in x.not_named) + "</ul>")
    notes = effect_notes(x)
    if notes:
        parts.append("<ul>" + "".join(f"<li>{e(n)}</li>" for n in notes) + "</ul>")
    if x.law is not None:
        law = x.law
        n = max((len(c.values) for c in law.constants), default=0)
        head = "<tr><th>constant</th><th>unit</th>" + "".join(f"<th>joint {j + 1}</th>" for j in range(n)) + "</tr>"
        body = "".join(f"<tr><td>{e(c.name)}</td><td>{e(c.unit)}</td>" + "".join(
            f'<td class="num">{e(fmt(v))}' + (f" &plusmn; {e(fmt(c.std[j]))}" if c.std else "") + "</td>"
            for j, v in enumerate(c.values)) + "</tr>" for c in law.constants)
        parts.append(f"<h3>Proposed law, not in the library</h3><p><code>{e(law.formula)}</code></p>"
                     f"<p>cross-validated residual RMS <span data-figure=\"law/cv_before\" data-unit=\"um\">"
                     f"{e(fmt(law.cv_before_mm, 1e3))}</span> um -> <span data-figure=\"law/cv_after\" data-unit=\"um\">"
                     f"{e(fmt(law.cv_after_mm, 1e3))}</span> um; {e(law_words(law))}</p><table id=\"law\">{head}{body}</table>")
    return "".join(parts)


def _flagged(r: Report) -> str:
    f = r.flagged
    rows = ", ".join(map(str, f.rows)) or "none"
    gross = ", ".join(map(str, f.gross)) or "none"
    words = "".join(f"<li>{e(w)}</li>" for w in flagged_words(r))
    return (f"<h2>Flagged rows</h2><p id=\"flagged\">flagged: <span data-figure=\"flagged\">{e(rows)}</span>; named gross "
            f"before any fit: <span data-figure=\"gross\">{e(gross)}</span></p><ul>{words}</ul>")


def _compensation(r: Report) -> str:
    c = r.compensation
    if c is None:
        return ""
    head = "".join(f"<th>{e(col)}</th>" for col in c.columns)
    body = "".join("<tr>" + "".join(f'<td class="num">{e(fmt(v))}</td>' for v in row) + "</tr>"
                   for row in c.rows[:COMPENSATION_ROWS])
    more = f"<p class=\"note\">{len(c.rows) - COMPENSATION_ROWS} more rows not shown</p>" \
        if len(c.rows) > COMPENSATION_ROWS else ""
    left = "".join(f"<li>{e(name)}: {e(why)}</li>" for name, why in c.not_compensated)
    return (f"<h2>Compensation</h2><p>{e(c.what)}</p><p>compensated: {e(', '.join(c.compensated) or 'the geometry only')}"
            f"</p>" + (f"<p>not compensated:</p><ul>{left}</ul>" if left else "")
            + f"<table id=\"compensation\"><tr>{head}</tr>{body}</table>{more}")


def render_html(report: Report) -> str:
    """The report as one HTML document (a string; no external resource)."""
    warnings = "".join(f"<li>{e(w)}</li>" for w in report.warnings)
    title = report_title(report)
    body = [f"<h1>{e(title)}</h1>", _verdict(report), _machine(report), _heldout(report), _effects(report),
            _parameters(report), _frames(report), _flagged(report), _compensation(report),
            f"<h2>Warnings</h2><ul>{warnings}</ul>" if warnings else ""]
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{e(title)}</title><style>{STYLE}</style></head><body>" + "".join(body)
            + "</body></html>\n")


def write_report(report: Report, path: str | Path, *, overwrite: bool = False) -> Path:
    """Write ``report`` (:class:`~pipeline.report.model.Report`) to ``path`` as HTML, atomically.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is off.
    """
    return atomic_write(path, render_html(report), overwrite=overwrite)
