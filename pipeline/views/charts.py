"""Drawing primitives shared by every view (rerun-sdk 0.41 API): the colours, named bar charts,
x-y plots and residual scatters drawn in 2D, and writing an ``.rrd`` atomically.

Charts drawn in 2D (:func:`log_named_bars`, :func:`log_plot`, :func:`log_residual_scatter`) are
static, so they show whatever timeline is active; their bars and points carry the names
(parameters, candidates) as labels. Text is ASCII plus a few Latin/Greek signs: the headless
viewer's only font has no emoji and it stops on a missing glyph.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from pipeline.formats import writing

__all__ = ["TOOLS", "application_id", "MACHINE_COLORS", "FLAG_COLOR", "chain_color", "chain_colors", "magnitude_colors",
           "magnification", "nice_step", "log_named_bars", "log_plot", "log_residual_scatter",
           "log_series_by_pose", "chart_view", "save_recording"]


#: The tools that write Rerun files; each file's application id names its tool and robot.
TOOLS = ("run", "discover", "design", "study")
#: Machine colours of the 3D view (and of the parameter bars: injected = actual, identified = calibrated).
MACHINE_COLORS = {"nominal": (150, 150, 150), "actual": (235, 130, 35), "calibrated": (50, 150, 235)}


#: One colour per chain, the same in every view (none is grey, orange or blue, the machines' colours).
CHAIN_PALETTE = ((230, 75, 75), (110, 200, 80), (190, 110, 230), (235, 205, 60), (70, 205, 200),
                 (240, 130, 185), (160, 160, 90), (140, 220, 160))


TEXT_COLOR = (215, 215, 215)


GRID_COLOR = (70, 70, 70)


FLAG_COLOR = (255, 40, 40)


#: Pixel-like units of the 2D charts (the views frame them; 1 unit is about 1 pixel at 1600x900).
ROW_PX = 16.0


NAME_PX = 56.0


#: Width of a named bar chart (about its view's width at 1600x900).
CHART_PX = 400.0


def application_id(tool: str, robot: str) -> str:
    """The application id of a Rerun file written by ``tool`` (one of :data:`TOOLS`) for a
    ``robot`` (its registered name): ``parallel-calib-run-delta``. The viewer keeps one default
    blueprint (layout, camera, titles) per application id, so files of different tools or robots
    opened together each keep their own.

    Raises:
        ValueError: an unknown tool, or a robot name that is not one word of ``[a-z0-9_]``.
    """
    if tool not in TOOLS:
        raise ValueError(f"unknown tool {tool!r}: one of {', '.join(TOOLS)}")
    if not re.fullmatch(r"[a-z0-9_]+", robot):
        raise ValueError(f"robot name {robot!r} is not a word of [a-z0-9_]")
    return f"parallel-calib-{tool}-{robot}"


def chain_color(c: int) -> tuple[int, int, int]:
    """The colour of chain ``c`` (0-based) in every view."""
    return CHAIN_PALETTE[c % len(CHAIN_PALETTE)]


def chain_colors(n: int) -> list[tuple[int, int, int]]:
    return [chain_color(c) for c in range(n)]


def magnitude_colors(values, vmax: float) -> np.ndarray:
    """(N, 3) uint8: green (0) through yellow to red (``vmax`` and above)."""
    t = np.clip(np.asarray(values, dtype=float) / (vmax if vmax > 0 else 1.0), 0.0, 1.0)
    stops = np.array([[60, 200, 90], [240, 220, 60], [240, 50, 40]], dtype=float)
    lo = np.where(t < 0.5, 0, 1)
    f = np.where(t < 0.5, t * 2, t * 2 - 1)[:, None]
    return (stops[lo] * (1 - f) + stops[lo + 1] * f).astype(np.uint8)


def nice_step(span: float, n: int = 2) -> float:
    """A 1-2-5 step giving about ``n`` steps over ``span``."""
    if not span > 0 or not np.isfinite(span):
        return 1.0
    raw = span / n
    base = 10 ** np.floor(np.log10(raw))
    return float(min((m * base for m in (1, 2, 5, 10) if m * base >= raw), default=10 * base))


def magnification(departure_mm: float, size_mm: float) -> float:
    """A round factor drawing the largest departure at about 5% of the machine's size."""
    if not departure_mm > 0:
        return 1.0
    raw = 0.05 * size_mm / departure_mm
    base = 10 ** np.floor(np.log10(raw))
    return float(max(m * base for m in (1, 2, 5) if m * base <= raw))


def _fmt(v: float) -> str:
    return f"{v:.4g}" if 1e-3 <= abs(v) < 1e5 or v == 0 else f"{v:.2e}"


def _slug(label: str) -> str:
    """An entity path part from a label (``delta BIC`` -> ``delta_BIC``)."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", label).strip("_") or "series"


def _text(rec: rr.RecordingStream, path: str, xy, labels, color=TEXT_COLOR) -> None:
    """Text drawn centred on 2D points (the label of an invisible point)."""
    xy = np.atleast_2d(np.asarray(xy, dtype=float))
    rec.log(path, rr.Points2D(xy, radii=0.01, colors=color, labels=[str(s) for s in labels], show_labels=True),
            static=True)


def _frame(rec, path, x0, y0, x1, y1) -> None:
    """A faint rectangle that sets what the 2D view frames (labels are centred on points and
    would otherwise fall off the edge)."""
    rec.log(path, rr.LineStrips2D([[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]], colors=(40, 40, 40),
                                  radii=0.5), static=True)


# -- named horizontal bar chart -----------------------------------------------------------------
def _columns_of(groups: list[int], rows_per_column: int) -> list[list[int]]:
    """Row indices split into columns of whole groups (a group bigger than a column stays whole)."""
    cols, cur = [], []
    for g in dict.fromkeys(groups):
        rows = [i for i, h in enumerate(groups) if h == g]
        if cur and len(cur) + len(rows) > rows_per_column:
            cols.append(cur)
            cur = []
        cur += rows
    return cols + ([cur] if cur else [])


@dataclass(frozen=True)
class _BarRows:
    """What a named bar chart draws, one entry a row: ``names`` (R,), ``vals`` [(R,)] one array a
    series (value unit), ``sig`` (R,) or None (value unit), ``groups`` (R,) int."""

    names: list[str]
    vals: list[np.ndarray]
    sig: np.ndarray | None
    groups: list[int]
    group_names: list[str] | None
    names_above: bool


@dataclass(frozen=True)
class _BarLayout:
    """Where a named bar chart's parts go, in the pixel-like units of :data:`ROW_PX`: ``cols``,
    the row indices of each column; ``col_w``, a column's width; ``name_px``, the width kept for
    the names; ``half``, the bars' half-width (``full`` value units); ``px``, units a value unit;
    ``step``, the grid step (value unit); ``n_rows``, the rows of the longest column (headers
    and key included); ``thick``, a bar's thickness."""

    cols: list[list[int]]
    col_w: float
    name_px: float
    half: float
    px: float
    step: float
    full: float
    n_rows: float
    thick: float


@dataclass
class _BarMarks:
    """The pieces of a named bar chart before they are logged: per series the bars (strips
    ``[[(x, y), (x, y)]]`` and their row names), the row names and group headers (points, text,
    colours), grid lines, tick points and text, +-2 sigma whiskers."""

    bars: list[tuple[list, list]]
    name_xy: list = field(default_factory=list)
    name_lab: list = field(default_factory=list)
    name_col: list = field(default_factory=list)
    head_xy: list = field(default_factory=list)
    head_lab: list = field(default_factory=list)
    head_col: list = field(default_factory=list)
    grid: list = field(default_factory=list)
    tick_xy: list = field(default_factory=list)
    ticks: list = field(default_factory=list)
    whisk: list = field(default_factory=list)


def _bar_extent(rows: _BarRows) -> float:
    """The largest |value| drawn, whiskers (+-2 sigma of the first series) included (value unit)."""
    ext = [np.abs(v[np.isfinite(v)]) for v in rows.vals]
    if rows.sig is not None:
        ok = np.isfinite(rows.vals[0]) & np.isfinite(rows.sig)
        ext.append(np.abs(rows.vals[0][ok]) + 2 * rows.sig[ok])
    return max((float(e.max()) for e in ext if e.size), default=0.0)


#: Rows of a chart with names above their bars take this many row heights (name, gap, bars): a
#: label keeps its size in screen pixels while a small view scales the chart down, so the name
#: needs room of its own above the bars.
NAMES_ABOVE_PITCH = 2.8


def _bar_layout(rows: _BarRows, rows_per_column: int, name_px: float) -> _BarLayout:
    """The scale (a 1-2-5 step, the ends at whole steps) and the columns of a named bar chart."""
    vmax = _bar_extent(rows)
    step = nice_step(vmax, 2)
    full = step * max(1, int(np.ceil(vmax / step - 1e-9)))
    cols = _columns_of(rows.groups, rows_per_column)
    name_px = 0.0 if rows.names_above else name_px
    col_w = CHART_PX / len(cols)
    half = (col_w - name_px - 16) / 2
    n_rows = (max(len(c) for c in cols) * (NAMES_ABOVE_PITCH if rows.names_above else 1.0)
              + (len(set(rows.groups)) // len(cols) if rows.group_names is not None else 0) + 1)
    return _BarLayout(cols=cols, col_w=col_w, name_px=name_px, half=half, px=half / full, step=step, full=full,
                      n_rows=n_rows, thick=min(7.0, 0.75 * ROW_PX / len(rows.vals)))


def _draw_bar_row(m: _BarMarks, rows: _BarRows, lay: _BarLayout, i: int, x0: float, y: float) -> float:
    """Row ``i`` of the column starting at ``x0``, at height ``y``: its group's header when the
    group starts here, its name, one bar a series, the whiskers. Returns the next row's height."""
    zx = x0 + lay.name_px + lay.half
    k = len(rows.vals)
    if rows.names_above:
        m.name_xy.append((zx, y - 0.3 * ROW_PX))
        y += (NAMES_ABOVE_PITCH - 1.0) * ROW_PX  # the bars well below their name: labels keep their size on screen
    else:
        m.name_xy.append((x0 + lay.name_px / 2, y))
    m.name_lab.append(rows.names[i])
    m.name_col.append(chain_color(rows.groups[i]) if rows.group_names is not None else TEXT_COLOR)
    for s in range(k):
        v = rows.vals[s][i]
        ys = y + (s - (k - 1) / 2) * lay.thick * 1.15
        v = 0.0 if not np.isfinite(v) else v
        m.bars[s][0].append([[zx, ys], [zx + v * lay.px, ys]])
        m.bars[s][1].append(rows.names[i])
    sig = rows.sig
    if sig is not None and np.isfinite(sig[i]) and np.isfinite(rows.vals[0][i]):
        ys = y + (0 - (k - 1) / 2) * lay.thick * 1.15
        a, b = zx + (rows.vals[0][i] - 2 * sig[i]) * lay.px, zx + (rows.vals[0][i] + 2 * sig[i]) * lay.px
        m.whisk += [[[a, ys], [b, ys]], [[a, ys - 3], [a, ys + 3]], [[b, ys - 3], [b, ys + 3]]]
    return y + ROW_PX


def _draw_bar_column(m: _BarMarks, rows: _BarRows, lay: _BarLayout, ci: int) -> None:
    """Column ``ci``: its rows (a header above each group's first row), then its grid and the
    ticks at the ends and zero."""
    x0 = ci * lay.col_w
    zx = x0 + lay.name_px + lay.half
    y = 0.0
    last = None
    for i in lay.cols[ci]:
        if rows.group_names is not None and rows.groups[i] != last:
            m.head_xy.append((x0 + lay.name_px / 2, y))
            m.head_lab.append(rows.group_names[rows.groups[i]])
            m.head_col.append(chain_color(rows.groups[i]))
            y += ROW_PX
            last = rows.groups[i]
        y = _draw_bar_row(m, rows, lay, i, x0, y)
    full, step = lay.full, lay.step
    for t in np.arange(-full, full + step / 2, step):
        gx = zx + t * lay.px
        m.grid.append([[gx, -0.6 * ROW_PX], [gx, y - 0.4 * ROW_PX]])
        if abs(abs(t) - full) < 1e-9 * full or abs(t) < 1e-9 * full:  # the ends and zero only
            m.tick_xy.append((gx, -1.2 * ROW_PX))
            m.ticks.append(("+" if t > 0 else "") + _fmt(t) if abs(t) > 1e-12 * full else "0")


def _log_bar_marks(rec: rr.RecordingStream, path: str, m: _BarMarks, series, lay: _BarLayout, *, unit: str,
                   title: str, note: str, with_sigma: bool) -> None:
    """Log the drawn pieces under ``path``, then the title, the key, the note and the frame."""
    for s, (label, _, color) in enumerate(series):
        strips, labels = m.bars[s]
        rec.log(f"{path}/bars/{_slug(label)}", rr.LineStrips2D(strips, radii=lay.thick / 2, colors=color,
                labels=labels, show_labels=False), static=True)
    rec.log(f"{path}/grid", rr.LineStrips2D(m.grid, radii=0.5, colors=GRID_COLOR), static=True)
    if m.whisk:
        rec.log(f"{path}/sigma2", rr.LineStrips2D(m.whisk, radii=0.9, colors=(240, 240, 240)), static=True)
    _text(rec, f"{path}/names", m.name_xy, m.name_lab, m.name_col)
    if m.head_xy:
        _text(rec, f"{path}/groups", m.head_xy, m.head_lab, m.head_col)
    _text(rec, f"{path}/ticks", m.tick_xy, m.ticks, (160, 160, 160))
    width = len(lay.cols) * lay.col_w
    scale = f"[{unit}, grid step {_fmt(lay.step)}]"
    _text(rec, f"{path}/title", [(width / 2, -2.3 * ROW_PX)], [f"{title}  {scale}" if title else scale])
    key = [lab + (" +-2 sigma" if (s == 0 and with_sigma) else "") for s, (lab, _, _) in enumerate(series)]
    kx = width / (len(key) + 1)
    key_y = (lay.n_rows + 0.6) * ROW_PX
    rec.log(f"{path}/key", rr.Points2D([(kx * (s + 1), key_y) for s in range(len(key))], radii=0.01,
                                      colors=[c for _, _, c in series], labels=key, show_labels=True), static=True)
    if note:
        _text(rec, f"{path}/note", [(width / 2, key_y + ROW_PX)], [note], (160, 160, 160))
    top, bottom = -3.0 * ROW_PX, (lay.n_rows + 2.5) * ROW_PX
    _frame(rec, f"{path}/frame", -6, top, width - 6, max(bottom, key_y + 1.6 * ROW_PX))


def log_named_bars(rec: rr.RecordingStream, path: str, names, series, *, unit: str, sigma=None,
                   groups=None, group_names=None, title: str = "", rows_per_column: int = 24,
                   note: str = "", name_px: float = NAME_PX, names_above: bool = False) -> None:
    """A static horizontal bar chart with a NAME on every row, drawn in 2D (view: :func:`chart_view`).

    Args:
        rec: the recording stream.
        path: entity path; ``{path}/bars/{label}`` (LineStrips2D labelled by the row names),
            ``{path}/names``, ``{path}/grid``, ``{path}/ticks``, ``{path}/key`` are written.
        names: (R,) row names (``B3.y``, ``dl4``, a candidate's name).
        series: ``[(label, values (R,), rgb), ...]`` drawn side by side in each row, one scale.
        unit: unit of the values, written on the chart.
        sigma: (R,) standard uncertainty of the first series: whiskers at +-2 sigma (NaN: none).
        groups: (R,) group (chain) of each row; rows of one group share a colour and a column.
        group_names: name of each group, written above its rows.
        title: first line of the chart.
        rows_per_column: the rows are split into columns of whole groups beyond this.
        note: a second line under the key (e.g. how angles are drawn).
        name_px: width kept for the names.
        names_above: write each name above its bars (long names, e.g. parameter combinations).
    """
    names = [str(n) for n in names]
    r = len(names)
    rows = _BarRows(names=names, vals=[np.asarray(v, dtype=float).reshape(r) for _, v, _ in series],
                    sig=None if sigma is None else np.asarray(sigma, dtype=float).reshape(r),
                    groups=[0] * r if groups is None else [int(g) for g in groups], group_names=group_names,
                    names_above=names_above)
    lay = _bar_layout(rows, rows_per_column, name_px)
    marks = _BarMarks(bars=[([], []) for _ in series])
    for ci in range(len(lay.cols)):
        _draw_bar_column(marks, rows, lay, ci)
    _log_bar_marks(rec, path, marks, series, lay, unit=unit, title=title, note=note, with_sigma=rows.sig is not None)


def chart_view(origin: str, name: str) -> rrb.Spatial2DView:
    """The view of a chart drawn by :func:`log_named_bars`, :func:`log_plot` or :func:`log_residual_scatter`."""
    return rrb.Spatial2DView(origin=origin, name=name, background=(18, 18, 18))


# -- x-y plot (log scale optional) ------------------------------------------------------------
def log_plot(rec: rr.RecordingStream, path: str, series, *, x_label: str, y_label: str, log_y: bool = False,
             title: str = "", marks=(), y_range=None, width: float = 420.0, height: float = 220.0,
             origin=(0.0, 0.0), lines: bool = True) -> None:
    """A static x-y chart in 2D, axes labelled with values (log10 decades when ``log_y``).

    Args:
        series: ``[(label, x (N,), y (N,), rgb or (N, 3)), ...]``; ``{path}/series/{label}`` holds
            the points (labelled ``label``).
        marks: ``[(x, y, text), ...]`` points ringed in red and labelled (flagged rows, outliers).
        y_range: (low, high) in data units (shared by charts drawn side by side); default the data's.
        origin: where the chart's top-left corner is drawn (to stack charts in one view).
        lines: join each series' points (sorted by x).
    """
    ox, oy = origin
    tr = (lambda v: np.log10(np.maximum(np.asarray(v, dtype=float), 1e-300))) if log_y else \
        (lambda v: np.asarray(v, dtype=float))
    xs = np.concatenate([np.asarray(s[1], dtype=float) for s in series]) if series else np.zeros(1)
    ys = np.concatenate([tr(s[2]) for s in series]) if series else np.zeros(1)
    ok = np.isfinite(xs) & np.isfinite(ys)
    xlo, xhi = (float(xs[ok].min()), float(xs[ok].max())) if ok.any() else (0.0, 1.0)
    if y_range is not None:
        ylo, yhi = (float(v) for v in tr(np.asarray(y_range)))
    else:
        ylo, yhi = (float(ys[ok].min()), float(ys[ok].max())) if ok.any() else (0.0, 1.0)
    if log_y:
        ylo, yhi = np.floor(ylo), np.ceil(yhi)
    if not yhi > ylo:
        ylo, yhi = ylo - 1, yhi + 1
    if not xhi > xlo:
        xlo, xhi = xlo - 1, xhi + 1
    left, right, up, low = 48.0, 10.0, 30.0, 30.0
    pw, ph = width - left - right, height - up - low

    def to_px(x, y):
        return np.c_[ox + left + (np.asarray(x, float) - xlo) / (xhi - xlo) * pw,
                     oy + up + (yhi - np.asarray(y, float)) / (yhi - ylo) * ph]

    grid, tick_xy, ticks = [], [], []
    ystep = 1.0 if log_y else nice_step(yhi - ylo, 3)
    yticks = (np.arange(np.ceil(ylo / ystep) * ystep, yhi + 1e-9 * ystep, ystep) if (yhi - ylo) / ystep < 40
              else [ylo, yhi])  # ticks inside the axes
    for t in yticks:
        p = to_px([xlo, xhi], [t, t])
        grid.append(p)
        tick_xy.append((ox + left / 2, p[0, 1]))
        ticks.append(f"1e{int(round(t))}" if log_y else _fmt(0.0 if abs(t) < 1e-9 * (yhi - ylo) else t))
    xstep = nice_step(xhi - xlo, 4)
    for t in np.arange(np.ceil(xlo / xstep) * xstep, xhi + 1e-9 * xstep, xstep):  # ticks inside the axes
        p = to_px([t, t], [ylo, yhi])
        grid.append(p)
        tick_xy.append((p[0, 0], oy + up + ph + 10))
        ticks.append(_fmt(0.0 if abs(t) < 1e-9 * (xhi - xlo) else t))
    rec.log(f"{path}/grid", rr.LineStrips2D(grid, radii=0.5, colors=GRID_COLOR), static=True)
    _text(rec, f"{path}/ticks", tick_xy, ticks, (160, 160, 160))
    _text(rec, f"{path}/labels", [(ox + left + pw / 2, oy + up + ph + 25), (ox + left + pw / 2, oy + 8)],
          [x_label, (f"{title}: " if title else "") + y_label + (" (log scale)" if log_y else "")])
    rec.log(f"{path}/axes", rr.LineStrips2D([to_px([xlo, xlo, xhi], [yhi, ylo, ylo])], radii=0.8,
                                           colors=(120, 120, 120)), static=True)
    for label, x, y, color in series:
        pts = to_px(x, tr(y))
        keep = np.all(np.isfinite(pts), axis=1)
        col = np.asarray(color)
        col = col[keep] if col.ndim == 2 else col
        rec.log(f"{path}/series/{_slug(label)}",
                rr.Points2D(pts[keep], radii=2.5, colors=col, labels=[label] * int(keep.sum()), show_labels=False),
                static=True)
        if lines and keep.sum() > 1:
            order = np.argsort(np.asarray(x, float)[keep])
            rec.log(f"{path}/series/{_slug(label)}/line",
                    rr.LineStrips2D([pts[keep][order]], radii=0.8, colors=col if col.ndim == 1 else TEXT_COLOR),
                    static=True)
    if len(marks):
        mp = to_px([m[0] for m in marks], tr([m[1] for m in marks]))
        rec.log(f"{path}/marks", rr.Points2D(mp, radii=6.0, colors=FLAG_COLOR, labels=[m[2] for m in marks],
                                            show_labels=True), static=True)
    _frame(rec, f"{path}/frame", ox, oy, ox + width, oy + height)


def log_residual_scatter(rec: rr.RecordingStream, path: str, x, before, after, *, x_label: str,
                         chain_names, flagged=(), unit: str = "um", title: str = "", rows=None,
                         models=("before", "after"), width: float = 420.0, height: float = 220.0,
                         same_scale: bool = True) -> None:
    """Residuals of each chain against a quantity, before (top) and after (bottom), one y scale.

    For the discovery file: residuals against time, stroke, direction of the last move, or the
    quantity the verdict names. ``before``/``after``: (N, C) in ``unit``; ``x``: (N,) or (N, C)
    (per chain, e.g. the stroke of each chain); ``flagged``: row indices to mark; ``rows``: (N,)
    the number written on a marked row (default its index + 1); ``models``: what the top and
    the bottom residuals are of (their y labels); ``width``, ``height``: of each of the two plots
    (drawn ``height + 20`` apart); ``same_scale``: one y scale for both (else each its own, so
    that a remainder much smaller than the residual before still shows its shape).
    """
    before, after = np.asarray(before, float), np.asarray(after, float)
    n, c = before.shape
    xx = np.broadcast_to(np.asarray(x, float).reshape(n, -1), (n, c))
    both = np.concatenate([before.ravel(), after.ravel()])
    both = both[np.isfinite(both)]
    lim = float(np.abs(both).max()) if both.size else 1.0
    lims = {"before": lim, "after": lim}
    if not same_scale:
        for name, res in (("before", before), ("after", after)):
            v = np.abs(res[np.isfinite(res)])
            lims[name] = float(v.max()) if v.size and v.max() > 0 else 1.0
    for name, v in lims.items():  # up to log_plot's tick step when that is larger (else no tick but 0)
        lims[name] = max(v, nice_step(2 * v, 3))
    number = np.arange(1, n + 1) if rows is None else np.asarray(rows, dtype=int).reshape(n)
    for k, (name, res) in enumerate((("before", before), ("after", after))):
        series = [(chain_names[j], xx[:, j], res[:, j], chain_color(j)) for j in range(c)]
        marks = [(xx[i, int(np.nanargmax(np.abs(res[i])))], res[i, int(np.nanargmax(np.abs(res[i])))],
                  f"flagged row {number[i]}") for i in flagged]
        log_plot(rec, f"{path}/{name}", series, x_label=x_label, y_label=f"residual {models[k]} ({unit})",
                 title=title, marks=marks, y_range=(-lims[name], lims[name]), origin=(0.0, k * (height + 20.0)),
                 lines=False, width=width, height=height)


def log_series_by_pose(rec: rr.RecordingStream, path: str, values, names, colors=None, *, start: int = 0) -> None:
    """(N, K) values as K named lines on the ``pose`` timeline (sent as columns, one call)."""
    v = np.asarray(values, dtype=float)
    v = v.reshape(v.shape[0], -1)
    rec.log(path, rr.SeriesLines(names=list(names), colors=colors if colors is not None else None), static=True)
    rec.send_columns(path, indexes=[rr.TimeColumn("pose", sequence=np.arange(start, start + v.shape[0]))],
                     columns=rr.Scalars.columns(scalars=v))


# -- files ---------------------------------------------------------------------------------------
def save_recording(path: str | Path, log_fn, *, application_id: str, bp: rrb.Blueprint,
                   overwrite: bool = False) -> Path:
    """Write an ``.rrd`` atomically: ``log_fn(rec)`` logs into a temporary file, then rename.

    ``application_id``: :func:`application_id` of the tool and robot, so that the viewer keeps each
    tool's and robot's layout when several files are open.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    path = Path(path)
    with writing(path, overwrite=overwrite) as tmp:
        rec = rr.RecordingStream(application_id)
        rec.set_log_time_enabled(False)  # no wall-clock timeline: nothing here depends on it
        rec.save(str(tmp), default_blueprint=bp)
        log_fn(rec)
        rec.flush()
        rec.disconnect()
    return path
