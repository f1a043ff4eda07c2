"""Rerun recordings of the pipeline's tools, for any robot (rerun-sdk 0.41 API).

Each tool writes with its own application id (:data:`APP_IDS`) and its own default blueprint,
so that files of different tools opened together keep their layouts. What a calibration run
(:func:`log_calibration_run`) writes, all lengths in mm unless the name says um:

* ``machine/{nominal,actual,calibrated}/chains|platform``: the machine at each calibration pose
  (timeline ``pose``): nominal geometry at the intended pose, actual geometry (or, for a real
  machine, the identified one) at the measured pose, identified geometry at the pose it predicts.
  Departures from the nominal machine are drawn magnified (:func:`magnification`, written in the
  view's key ``machine/key``); ``machine/chain_labels``: one colour per chain.
* ``machine/errors/{before,after}``: static arrows at every calibration pose, position error
  before (measured - intended) and after (measured - calibrated prediction), same magnification,
  coloured by magnitude (the scale is in the key); ``machine/flagged``: outlier poses.
* ``residuals/{before,after}_um``: closure (joint-space) residual of each chain per calibration
  pose (timeline ``pose``) with the nominal and the identified model; ``residuals/flagged``.
* ``heldout/position_error_um``, ``heldout/orientation_error_urad``: per held-out pose (timeline
  ``pose``), before and after compensation.
* ``convergence/chart``: log-scale chart of max dQint (or cost) per iteration (static; the same
  values as ``convergence/log10`` on timeline ``iteration``).
* ``parameters/chart``: named bars, identified (+-2 sigma) beside injected, one scale.
* ``observability``: see :mod:`pipeline.obs_log`; ``summary``: markdown tables.

Charts drawn in 2D (:func:`log_named_bars`, :func:`log_plot`, :func:`log_residual_scatter`) are
static, so they show whatever timeline is active; their bars and points carry the names
(parameters, candidates) as labels. Text is ASCII plus a few Latin/Greek signs: the headless
viewer's only font has no emoji and it stops on a missing glyph.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from calib.robot import Robot

from .obs_log import log_observability, observability_views
from .recording import writing

__all__ = [
    "APP_IDS", "MACHINE_COLORS", "chain_color", "chain_colors", "magnitude_colors", "magnification",
    "log_named_bars", "log_plot", "log_residual_scatter", "log_series_by_pose", "chart_view",
    "log_calibration_run", "blueprint", "summary_markdown", "save_recording", "rrd_entities",
    "rrd_application_ids", "rrd_blueprint", "empty_views", "rrd_labels", "run_eye", "run_magnification",
]

#: One application id per tool: the viewer keeps one layout per application id.
APP_IDS = {"run": "parallel-calib-run", "discover": "parallel-calib-discover",
           "design": "parallel-calib-design", "study": "parallel-calib-study"}
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
    vals = [np.asarray(v, dtype=float).reshape(r) for _, v, _ in series]
    groups = [0] * r if groups is None else [int(g) for g in groups]
    sig = None if sigma is None else np.asarray(sigma, dtype=float).reshape(r)
    ext = [np.abs(v[np.isfinite(v)]) for v in vals]
    if sig is not None:
        ok = np.isfinite(vals[0]) & np.isfinite(sig)
        ext.append(np.abs(vals[0][ok]) + 2 * sig[ok])
    vmax = max((float(e.max()) for e in ext if e.size), default=0.0)
    step = nice_step(vmax, 2)
    full = step * max(1, int(np.ceil(vmax / step - 1e-9)))
    cols = _columns_of(groups, rows_per_column)
    name_px = 0.0 if names_above else name_px
    col_w = CHART_PX / len(cols)
    half = (col_w - name_px - 16) / 2
    px = half / full
    n_rows = (max(len(c) for c in cols) * (1.9 if names_above else 1.0)
              + (len(set(groups)) // len(cols) if group_names is not None else 0) + 1)
    top, bottom = -3.0 * ROW_PX, (n_rows + 2.5) * ROW_PX
    k = len(series)
    thick = min(7.0, 0.75 * ROW_PX / k)
    bars = {i: ([], [], []) for i in range(k)}  # strips, labels, colours
    name_xy, name_lab, name_col, grid, ticks, tick_xy, whisk = [], [], [], [], [], [], []
    head_xy, head_lab, head_col = [], [], []
    for ci, rows in enumerate(cols):
        x0 = ci * col_w
        zx = x0 + name_px + half
        y = 0.0
        last = None
        for i in rows:
            if group_names is not None and groups[i] != last:
                head_xy.append((x0 + name_px / 2, y))
                head_lab.append(group_names[groups[i]])
                head_col.append(chain_color(groups[i]))
                y += ROW_PX
                last = groups[i]
            if names_above:
                name_xy.append((zx, y - 0.1 * ROW_PX))
                y += 0.9 * ROW_PX
            else:
                name_xy.append((x0 + name_px / 2, y))
            name_lab.append(names[i])
            name_col.append(chain_color(groups[i]) if group_names is not None else TEXT_COLOR)
            for s in range(k):
                v = vals[s][i]
                ys = y + (s - (k - 1) / 2) * thick * 1.15
                v = 0.0 if not np.isfinite(v) else v
                bars[s][0].append([[zx, ys], [zx + v * px, ys]])
                bars[s][1].append(names[i])
            if sig is not None and np.isfinite(sig[i]) and np.isfinite(vals[0][i]):
                ys = y + (0 - (k - 1) / 2) * thick * 1.15
                a, b = zx + (vals[0][i] - 2 * sig[i]) * px, zx + (vals[0][i] + 2 * sig[i]) * px
                whisk += [[[a, ys], [b, ys]], [[a, ys - 3], [a, ys + 3]], [[b, ys - 3], [b, ys + 3]]]
            y += ROW_PX
        for t in np.arange(-full, full + step / 2, step):
            gx = zx + t * px
            grid.append([[gx, -0.6 * ROW_PX], [gx, y - 0.4 * ROW_PX]])
            if abs(abs(t) - full) < 1e-9 * full or abs(t) < 1e-9 * full:  # the ends and zero only
                tick_xy.append((gx, -1.2 * ROW_PX))
                ticks.append(("+" if t > 0 else "") + _fmt(t) if abs(t) > 1e-12 * full else "0")
    for s, (label, _, color) in enumerate(series):
        strips, labels, _ = bars[s]
        rec.log(f"{path}/bars/{_slug(label)}", rr.LineStrips2D(strips, radii=thick / 2, colors=color,
                labels=labels, show_labels=False), static=True)
    rec.log(f"{path}/grid", rr.LineStrips2D(grid, radii=0.5, colors=GRID_COLOR), static=True)
    if whisk:
        rec.log(f"{path}/sigma2", rr.LineStrips2D(whisk, radii=0.9, colors=(240, 240, 240)), static=True)
    _text(rec, f"{path}/names", name_xy, name_lab, name_col)
    if head_xy:
        _text(rec, f"{path}/groups", head_xy, head_lab, head_col)
    _text(rec, f"{path}/ticks", tick_xy, ticks, (160, 160, 160))
    width = len(cols) * col_w
    title_line = f"{title}  [{unit}, grid step {_fmt(step)}]" if title else f"[{unit}, grid step {_fmt(step)}]"
    _text(rec, f"{path}/title", [(width / 2, -2.3 * ROW_PX)], [title_line])
    key = [lab + (" +-2 sigma" if (s == 0 and sig is not None) else "") for s, (lab, _, _) in enumerate(series)]
    kx = width / (len(key) + 1)
    key_y = (n_rows + 0.6) * ROW_PX
    rec.log(f"{path}/key", rr.Points2D([(kx * (s + 1), key_y) for s in range(len(key))], radii=0.01,
                                      colors=[c for _, _, c in series], labels=key, show_labels=True), static=True)
    if note:
        _text(rec, f"{path}/note", [(width / 2, key_y + ROW_PX)], [note], (160, 160, 160))
    _frame(rec, f"{path}/frame", -6, top, width - 6, max(bottom, key_y + 1.6 * ROW_PX))


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


# -- the calibration run -------------------------------------------------------------------------
def _log_machine(rec: rr.RecordingStream, path: str, points: np.ndarray, color, radius: float) -> None:
    """``points``: (N, C, K, 3) chain polylines of N poses, one pose a step of the ``pose``
    timeline (sent as columns: one call per entity, not one per pose); the platform joins the
    chains' last points."""
    n, c = points.shape[:2]
    tips = points[:, :, -1]
    platform = np.concatenate([tips, tips[:, :1]], axis=1)  # (N, C + 1, 3): one closed strip a pose
    index = [rr.TimeColumn("pose", sequence=np.arange(n))]
    style = rr.LineStrips3D.columns(colors=[color] * n, radii=[radius] * n)
    for part, strips, per_pose in (("chains", points.reshape(n * c, *points.shape[2:]), c), ("platform", platform, 1)):
        rec.send_columns(f"{path}/{part}", indexes=index,
                         columns=[*rr.LineStrips3D.columns(strips=strips).partition([per_pose] * n), *style])


def _eye(points: np.ndarray) -> rrb.EyeControls3D:
    """A camera that frames every point (from the front-right, slightly above)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    c = (lo + hi) / 2
    r = float(np.linalg.norm(hi - lo)) / 2
    d = np.array([1.0, -1.6, 0.9])
    return rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=c + 3.0 * r * d / np.linalg.norm(d),
                             look_target=c, eye_up=(0.0, 0.0, 1.0))


def _scene(robot: Robot, nominal, targets) -> np.ndarray:
    joints = robot.inverse_kinematics(nominal, targets)
    return robot.chain_points(nominal, joints, targets)


def blueprint(robot: Robot | None = None, *, eye: rrb.EyeControls3D | None = None, magnified: float = 1.0,
              has_heldout: bool = True, history_label: str = "max dQint") -> rrb.Blueprint:
    """The run file's layout: machine | per-chain residuals, held-out, convergence | parameters |
    summary, observability. Every view shows data on the ``pose`` timeline, active at open."""
    word = robot.chain_word if robot is not None else "chain"
    angles = robot is None or bool(robot.angle_pose_mask.any())
    series = [
        rrb.TimeSeriesView(origin="residuals/before_um", name=f"Closure residual per {word}, nominal model (um) vs pose",
                           plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop)),
        rrb.TimeSeriesView(origin="residuals/after_um", name=f"Closure residual per {word}, identified model (um) vs pose",
                           plot_legend=rrb.PlotLegend(visible=False)),
    ]
    if has_heldout:
        held = [rrb.TimeSeriesView(origin="heldout/position_error_um",
                                   name="Held-out position error (um) vs held-out pose")]
        if angles:
            held.append(rrb.TimeSeriesView(origin="heldout/orientation_error_urad",
                                           name="Held-out orientation error (urad) vs held-out pose"))
        series.append(rrb.Tabs(*held) if len(held) > 1 else held[0])
    series.append(chart_view("convergence/chart", f"Convergence: {history_label} per iteration (log)"))
    machine = rrb.Spatial3DView(origin="machine", name=f"Machine at the pose (departures from nominal x{magnified:g})",
                                eye_controls=eye, line_grid=rrb.LineGrid3D(visible=False))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(machine, rrb.TextDocumentView(origin="key", name="Key"), row_shares=[5, 1]),
            rrb.Vertical(*series),
            chart_view("parameters/chart", "Parameter errors: identified vs injected"),
            rrb.Vertical(
                rrb.TextDocumentView(origin="summary", name="Summary"),
                observability_views("observability", "Observability"),
                row_shares=[1, 1],
            ),
            column_shares=[2.6, 2.0, 2.4, 2.0],
        ),
        rrb.TimePanel(timeline="pose", play_state="paused", state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        collapse_panels=True,
    )


def _flagged_state(summary: dict) -> str:
    left_out = (summary.get("outliers") or {}).get("left_out")
    return " (data rows; left out)" if left_out else " (data rows; kept)"


def summary_markdown(summary: dict) -> str:
    """The run summary as a markdown panel: short lines and tables."""
    h = summary.get("heldout_position_error_mm")
    o = summary.get("heldout_orientation_error_rad")
    n = summary["declared_noise"]
    lines = [
        f"## {summary['robot']}: calibration",
        f"{summary['scenario']}",
        "",
        "| run | |", "|---|---|",
        f"| method | {summary['method']} ({summary['solver']}) |",
        f"| poses | {summary['calibration_poses']} calibration, {summary['heldout_poses']} held-out |",
        f"| noise | {n.get('position_mm', 0):g} mm, {n.get('orientation_rad', 0):g} rad, "
        f"joints {n.get('joint', 0):g} ({n.get('distribution', '')}) |",
        f"| iterations | {summary['iterations']} ({'converged' if summary.get('success') else 'not converged'}) |",
        f"| flagged rows | {', '.join(str(i) for i in summary['flagged_poses']) or 'none'}"
        f"{_flagged_state(summary) if summary['flagged_poses'] else ''} |",
    ]
    if h:
        lines += ["", "| held-out | before | after | max after |", "|---|---|---|---|",
                  f"| position, um | {1e3 * h['before']:.2f} | {1e3 * h['after']:.3f} | {1e3 * h['max_after']:.3f} |"]
        if o:
            lines.append(f"| orientation, urad | {1e6 * o['before']:.1f} | {1e6 * o['after']:.2f} | "
                         f"{1e6 * o['max_after']:.2f} |")
    pe = summary.get("parameter_error")
    g = summary.get("gain_G_percent")
    if pe and pe.get("rms_mm") is not None:
        lines += ["", "| parameters | |", "|---|---|",
                  f"| error RMS, lengths | {1e3 * pe['rms_mm']:.2f} um |"]
        if pe.get("rms_rad") is not None:
            lines.append(f"| error RMS, angles | {1e6 * pe['rms_rad']:.2f} urad |")
        if g:
            lines.append(f"| gain G (norm) | {g['norm']:.2f} % |")
    cn = summary["condition_numbers"]
    lines += ["", f"Condition number{'s' if len(cn) > 1 else ''}: " + ", ".join(f"{c:.0f}" for c in cn)]
    if h:
        lines += ["", f"Held-out basis: {summary['heldout_basis']}."]
    lines += ["", f"Stop: {summary['message']}"]
    out = summary.get("outliers") or {}
    if out.get("verdict"):
        lines += ["", f"Outlier test: {out['verdict']}"]
    for w in summary.get("warnings") or ():
        lines += ["", f"Warning: {w}"]
    return "\n".join(lines)


def _bar_unit(robot: Robot):
    """Parameter errors drawn in um; an angle as the arc it makes at the machine's size."""
    angle = robot.table.angle_mask()
    return np.where(angle, 1e3 * robot.length_scale_mm, 1e3), angle.any()


def log_calibration_run(
    rec: rr.RecordingStream, *, robot: Robot, nominal: np.ndarray, actual: np.ndarray | None,
    identified: np.ndarray, std: np.ndarray, joints: np.ndarray, targets: np.ndarray, measured: np.ndarray,
    predicted: np.ndarray, history, heldout_before: np.ndarray | None,
    heldout_after: np.ndarray | None, summary_markdown: str, observability=None, flagged=(),
    history_label: str = "max dQint", magnified: float | None = None,
) -> None:
    """Log one calibration run (see the module docstring for the entities).

    Args:
        rec: the recording stream.
        robot: the robot.
        nominal, actual, identified: (P,) parameter vectors (``actual`` None for a real machine).
        std: (P,) standard uncertainty of the identified parameters.
        joints: (N, C) commanded joints of the calibration poses.
        targets: (N, D) poses the controller intended.
        measured: (N, D) measured poses.
        predicted: (N, D) poses the identified model predicts at the commanded joints.
        history: max dQint (or cost) per iteration.
        heldout_before, heldout_after: (M, D) held-out pose errors (reached - target), or None.
        summary_markdown: text of the summary panel.
        observability: a :class:`calib.observability.ObservabilityAnalysis` to log, or None.
        flagged: 0-based indices of the calibration poses flagged as outliers.
        history_label: what ``history`` holds.
        magnified: factor of the drawn departures from nominal (default :func:`run_magnification`).
    """
    angle = robot.angle_pose_mask
    n, c = joints.shape
    names = list(robot.table.names)
    chains = [f"{robot.chain_word} {i + 1}" for i in range(c)]
    colors = chain_colors(c)
    flagged = [int(i) for i in flagged]
    m = magnified if magnified is not None else run_magnification(robot, nominal, actual, identified, targets,
                                                                  measured)

    # 3D machine, one pose a step of the `pose` timeline.
    rec.log("machine", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    nominal_joints = robot.inverse_kinematics(nominal, targets)
    nom = robot.chain_points(nominal, nominal_joints, targets)
    drawn = actual if actual is not None else identified
    act = robot.chain_points(drawn, joints, measured)
    cal = robot.chain_points(identified, joints, predicted)
    size = float(np.ptp(nom.reshape(-1, 3), axis=0).max())
    _log_machine(rec, "machine/nominal", nom, MACHINE_COLORS["nominal"], size * 0.006)
    _log_machine(rec, "machine/actual", nom + m * (act - nom), MACHINE_COLORS["actual"], size * 0.004)
    _log_machine(rec, "machine/calibrated", nom + m * (cal - nom), MACHINE_COLORS["calibrated"], size * 0.0022)
    per_chain = rr.Points3D.columns(positions=nom[:, :, 0].reshape(-1, 3), labels=chains * n,
                                    colors=np.tile(np.asarray(colors, dtype=np.uint8), (n, 1))).partition([c] * n)
    rec.send_columns("machine/chain_labels", indexes=[rr.TimeColumn("pose", sequence=np.arange(n))],
                     columns=[*per_chain, *rr.Points3D.columns(radii=[size * 0.012] * n, show_labels=[True] * n)])
    pos = ~angle
    centre = targets[:, pos][:, :3]
    before = (measured - targets)[:, pos][:, :3]
    after = (measured - predicted)[:, pos][:, :3]
    mag_b, mag_a = np.linalg.norm(before, axis=1) * 1e3, np.linalg.norm(after, axis=1) * 1e3
    vmax = float(np.nanmax(mag_b)) if n else 1.0
    rec.log("machine/errors/before", rr.Arrows3D(origins=centre, vectors=m * before, colors=magnitude_colors(mag_b, vmax),
                                                 radii=size * 0.004, labels=[f"pose {k + 1}: {v:.0f} um" for k, v in
                                                                              enumerate(mag_b)], show_labels=False),
            static=True)
    rec.log("machine/errors/after", rr.Arrows3D(origins=centre, vectors=m * after, colors=magnitude_colors(mag_a, vmax),
                                                radii=size * 0.002), static=True)
    if flagged:
        rec.log("machine/flagged", rr.Points3D(centre[flagged], radii=size * 0.02, colors=FLAG_COLOR,
                                               labels=[f"flagged pose {k + 1}" for k in flagged], show_labels=True),
                static=True)
    what = "actual" if actual is not None else "measured (identified geometry)"
    key = (f"**grey** nominal, **orange** {what}, **blue** calibrated model; departures from nominal and "
           f"error arrows drawn **x{m:g}**. Arrows: position error at each calibration pose, thick before "
           f"(measured - intended), thin after (measured - calibrated), colour green 0 to red {vmax:.0f} um. "
           + ("Red ring: flagged pose. " if flagged else "") + f"Labels: one colour per {robot.chain_word}.")
    rec.log("key", rr.TextDocument(key, media_type=rr.MediaType.MARKDOWN), static=True)

    # Joint-space (closure) residual of each chain per pose, nominal and identified model.
    for name, theta in (("before", nominal), ("after", identified)):
        res = robot.closure(theta, joints, measured) * 1e3
        log_series_by_pose(rec, f"residuals/{name}_um", res, chains, colors)
        if flagged:
            rec.log(f"residuals/{name}_um/flagged", rr.SeriesPoints(colors=FLAG_COLOR, names="flagged pose",
                                                                    marker_sizes=6.0), static=True)
            rec.send_columns(f"residuals/{name}_um/flagged", indexes=[rr.TimeColumn("pose", sequence=flagged)],
                             columns=rr.Scalars.columns(scalars=np.abs(res[flagged]).max(axis=1)))

    # Held-out poses, on the same `pose` timeline (numbered within their own set).
    if heldout_before is not None and heldout_after is not None:
        hb = np.linalg.norm(heldout_before[:, pos], axis=1) * 1e3
        ha = np.linalg.norm(heldout_after[:, pos], axis=1) * 1e3
        grey, blue = MACHINE_COLORS["nominal"], MACHINE_COLORS["calibrated"]
        log_series_by_pose(rec, "heldout/position_error_um", np.c_[hb, ha],
                           ["before (nominal commands)", "after (compensated)"], [grey, blue])
        if angle.any():
            ob = np.linalg.norm(heldout_before[:, angle], axis=1) * 1e6
            oa = np.linalg.norm(heldout_after[:, angle], axis=1) * 1e6
            log_series_by_pose(rec, "heldout/orientation_error_urad", np.c_[ob, oa],
                               ["before (nominal commands)", "after (compensated)"], [grey, blue])

    # Convergence: a static log chart (any timeline) and the `iteration` timeline.
    hist = np.asarray(history, dtype=float)
    if hist.size:
        it = np.arange(1, hist.size + 1)
        log_plot(rec, "convergence/chart", [(history_label, it, hist, (240, 200, 60))], x_label="iteration",
                 y_label=history_label, log_y=True, width=340.0, height=150.0)
        with np.errstate(divide="ignore"):
            rec.send_columns("convergence/log10", indexes=[rr.TimeColumn("iteration", sequence=it)],
                             columns=rr.Scalars.columns(scalars=np.log10(hist)))

    # Parameters by name: identified +-2 sigma beside injected, one scale.
    to_um, has_angles = _bar_unit(robot)
    series = [("identified", to_um * (identified - nominal), MACHINE_COLORS["calibrated"])]
    if actual is not None:
        series.append(("injected", to_um * (actual - nominal), MACHINE_COLORS["actual"]))
    note = (f"angles drawn as the arc they make at {robot.length_scale_mm:.0f} mm (1 urad = "
            f"{robot.length_scale_mm / 1e3:.3g} um)") if has_angles else ""
    log_named_bars(rec, "parameters/chart", names, series, unit="um", sigma=to_um * std,
                   groups=[p.chain for p in robot.table], group_names=chains, title="identified - nominal",
                   note=note, rows_per_column=48)
    if observability is not None:
        log_observability(rec, observability, "observability", title="Observability of the calibration poses")
    rec.log("summary", rr.TextDocument(summary_markdown, media_type=rr.MediaType.MARKDOWN), static=True)


def run_magnification(robot: Robot, nominal, actual, identified, targets, measured) -> float:
    """The factor a run draws departures from nominal with (:func:`magnification`)."""
    nom = _scene(robot, nominal, targets)
    pos = ~robot.angle_pose_mask
    dep = float(np.abs((measured - targets)[:, pos]).max()) if len(targets) else 0.0
    theta = actual if actual is not None else identified
    dep = max(dep, float(np.abs(robot.chain_points(theta, robot.inverse_kinematics(nominal, targets), targets)
                                - nom).max()))
    return magnification(dep, float(np.ptp(nom.reshape(-1, 3), axis=0).max()))


def run_eye(robot: Robot, nominal, targets) -> rrb.EyeControls3D:
    """The run view's camera: frames the nominal machine at every calibration pose."""
    return _eye(_scene(robot, nominal, targets).reshape(-1, 3))


# -- files ---------------------------------------------------------------------------------------
def save_recording(path: str | Path, log_fn, *, application_id: str = APP_IDS["run"],
                   overwrite: bool = False, bp: rrb.Blueprint | None = None) -> Path:
    """Write an ``.rrd`` atomically: ``log_fn(rec)`` logs into a temporary file, then rename.

    ``application_id``: one of :data:`APP_IDS` (the tool's), so that the viewer keeps each tool's
    layout when files of several tools are open.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    path = Path(path)
    with writing(path, overwrite=overwrite) as tmp:
        rec = rr.RecordingStream(application_id)
        rec.set_log_time_enabled(False)  # no wall-clock timeline: nothing here depends on it
        rec.save(str(tmp), default_blueprint=bp if bp is not None else blueprint())
        log_fn(rec)
        rec.flush()
        rec.disconnect()
    return path


def rrd_entities(path: str | Path) -> set[str]:
    """Entity paths present in an ``.rrd`` file (reads it back with ``rerun.chunk.RrdReader``)."""
    from rerun.chunk import RrdReader

    return {c.entity_path for c in RrdReader(str(path)).stream().to_chunks()}


def rrd_application_ids(path: str | Path) -> set[str]:
    """Application ids of the recordings and blueprints in an ``.rrd`` file."""
    from rerun.chunk import RrdReader

    r = RrdReader(str(path))
    return {x.application_id for x in list(r.recordings()) + list(r.blueprints())}


# -- reading a file back (tests, checks) -----------------------------------------------------------
def _timelines(batch) -> set[str]:
    return {n for n in batch.schema.names if ":" not in n and not n.startswith("rerun.")}


def rrd_blueprint(path: str | Path) -> dict:
    """The default blueprint of an ``.rrd``: ``{"views": [{"class", "name", "origin"}], "timeline"}``
    (``timeline``: the one active at open, or None)."""
    from rerun.chunk import RrdReader

    r = RrdReader(str(path))
    views, timeline = {}, None
    for bp in r.blueprints():
        for c in r.stream(store=bp).to_chunks():
            b = c.to_record_batch()
            ep = str(c.entity_path)
            cols = set(b.schema.names)
            if "TimePanelBlueprint:timeline" in cols:
                timeline = b.column("TimePanelBlueprint:timeline").to_pylist()[-1][0]
            if "ViewBlueprint:class_identifier" in cols:
                last = lambda n: b.column(n).to_pylist()[-1][0]  # noqa: E731
                views[ep] = {"class": last("ViewBlueprint:class_identifier"),
                             "name": last("ViewBlueprint:display_name"),
                             "origin": last("ViewBlueprint:space_origin")}
    return {"views": list(views.values()), "timeline": timeline}


#: Components that style a view's data but are no data themselves.
STYLE_ONLY = ("SeriesLines:", "SeriesPoints:", "ViewCoordinates:")


def empty_views(path: str | Path) -> list[str]:
    """Names of the blueprint's views that show nothing when the file opens: no data under their
    origin that is static or on the timeline active at open (a time series needs scalars on it)."""
    from rerun.chunk import RrdReader

    bp = rrd_blueprint(path)
    tl = bp["timeline"]
    chunks = []
    for c in RrdReader(str(path)).stream().to_chunks():
        b = c.to_record_batch()
        comps = [n for n in b.schema.names if ":" in n and not n.startswith(STYLE_ONLY)]
        if comps and b.num_rows:
            chunks.append((str(c.entity_path), c.is_static, _timelines(b), comps))
    out = []
    for v in bp["views"]:
        root = "/" + v["origin"].strip("/")
        mine = [ch for ch in chunks if ch[0] == root or ch[0].startswith(root + "/") or root == "/"]
        if v["class"] == "TimeSeries":
            ok = any(not st and tl in tls and any(x.startswith("Scalars:") for x in comps)
                     for _, st, tls, comps in mine)
        else:
            ok = any(st or tl in tls for _, st, tls, _ in mine)
        if not ok:
            out.append(v["name"])
    return out


def rrd_labels(path: str | Path, entity: str) -> list[str]:
    """The labels logged on ``entity`` (e.g. the names on a chart's bars)."""
    from rerun.chunk import RrdReader

    for c in RrdReader(str(path)).stream().to_chunks():
        if str(c.entity_path) == entity:
            b = c.to_record_batch()
            for n in b.schema.names:
                if n.endswith(":labels"):
                    return [str(x) for x in b.column(n).to_pylist()[-1]]
    raise KeyError(f"no labels on {entity} in {path}")
