"""Rerun logging of observability figures (rerun-sdk 0.41 API), for any robot.

Reusable by every pipeline command: :func:`log_observability` writes, under ``prefix``:

* ``{prefix}/singular_values`` and ``{prefix}/log10_singular_values``: bar charts of the
  singular values of the scaled noise-whitened identification Jacobian (1/mm), largest first;
* ``{prefix}/crb_std_mm``: bar chart of the Cramer-Rao standard deviation of each free
  parameter (mm; an angle as the length it moves at the machine's size), table order; an
  undetermined parameter is logged as 0 and named in the report. Rerun's bar charts carry no
  per-bar labels, so the entity also holds a ``parameter_names`` component (the bars' names, in
  order; shown in the viewer's selection panel);
* ``{prefix}/combinations``: the worst-determined parameter combinations, each bar NAMED by its
  combination (``0.71 B1.z - 0.70 dl1``), length its standard deviation (um); the combinations
  that are not identifiable at all are named in the report;
* every bar chart logged with names (:func:`log_bars`) is also drawn as a named chart in 2D
  (``{path}/bars``, ``{path}/names``...; see :func:`pipeline.views.charts.log_named_bars`);
* ``{prefix}/report``: a markdown document with the indices, the condition numbers, the weakest
  and the not identifiable parameter combinations and the per-parameter table.

All entities are static (they describe a pose set, not a moment in time).
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from calib.observability import ObservabilityAnalysis

from .charts import chart_view, log_named_bars

__all__ = ["log_observability", "log_bars", "bar_values", "log_combinations", "observability_markdown",
           "observability_views"]


def _fmt(x: float) -> str:
    return "inf" if not np.isfinite(x) else f"{x:.4g}"


def observability_markdown(analysis: ObservabilityAnalysis, *, title: str = "Observability", k: int = 5) -> str:
    """Markdown report of an :class:`~calib.observability.ObservabilityAnalysis`."""
    n = analysis.noise
    lines = [
        f"# {title}",
        "",
        f"{analysis.n_poses} poses; declared noise ({n.distribution}): position {n.position_mm:g} mm, "
        f"orientation {n.orientation_rad:g} rad, joints {n.joint:g} (joint unit).",
        "",
        "| figure | value |", "|---|---|",
        f"| rank | {analysis.rank} / {analysis.n_free} |",
        f"| condition number (noise-whitened, angles scaled to mm) | {_fmt(analysis.condition_number)} |",
        f"| condition number (column-scaled) | {_fmt(analysis.scaled_condition_number)} |",
        f"| O1 (D) | {_fmt(analysis.o1)} 1/mm |",
        f"| O2 (inverse condition) | {_fmt(analysis.o2)} |",
        f"| O3 (E, sigma_min) | {_fmt(analysis.o3)} 1/mm |",
        f"| O4 (noise amplification) | {_fmt(analysis.o4)} 1/mm |",
        f"| CRB parameter RMS | {_fmt(analysis.crb_rms)} mm |",
        "",
        "## Worst-determined parameter combinations",
        "",
        "| std (mm) | combination |", "|---|---|",
    ]
    for c in analysis.weakest_combinations(min(k, analysis.n_free)):
        lines.append(f"| {_fmt(c['std_mm'])} | {c['combination']} |")
    if analysis.not_identifiable:
        lines += ["", "## Not identifiable (a change along these leaves every pose unchanged)", "",
                  "| chain | combination (parameter units) |", "|---|---|"]
        lines += [f"| {'-' if c['chain'] is None else c['chain'] + 1} | {c['combination']} |"
                  for c in analysis.not_identifiable]
    lines += ["", "## Cramer-Rao standard deviation per parameter", "",
              "| parameter | std | unit | std as mm |", "|---|---|---|---|"]
    lines += [f"| {nm} | {_fmt(s)} | {u} | {_fmt(m)} |"
              for nm, s, u, m in zip(analysis.names, analysis.crb_std, analysis.units, analysis.crb_std_mm)]
    return "\n".join(lines) + "\n"


def bar_values(values) -> object:
    """A bar chart's (N,) float64 values as Rerun's tensor component, built directly in Arrow.

    ``rr.BarChart(numpy_array)`` builds the same Arrow array through ``pyarrow.compute`` (a cast),
    whose import is about 0.1 s of a default run that needs nothing else from it. The array is
    assembled here from the component's own Arrow type (``rr.components.TensorData.arrow_type()``);
    if that layout ever changes, the values are returned as they are and Rerun converts them.
    """
    import pyarrow as pa

    v = np.ascontiguousarray(values, dtype=np.float64).reshape(-1)
    try:
        t = rr.components.TensorData.arrow_type()
        union = t.field("buffer").type
        k = [f.name for f in union].index("F64")
        children = [pa.nulls(0, type=f.type) for f in union]
        children[k] = pa.array([v], type=union.field(k).type)
        buffer = pa.Array.from_buffers(union, 1, [None, pa.array([union.type_codes[k]], pa.int8()).buffers()[1],
                                                  pa.array([0], pa.int32()).buffers()[1]], children=children)
        return pa.StructArray.from_arrays([pa.array([[v.size]], type=t.field("shape").type),
                                           pa.nulls(1, type=t.field("names").type), buffer], fields=list(t))
    except (KeyError, ValueError, TypeError, pa.ArrowException):
        return v


def log_bars(rec: rr.RecordingStream, path: str, values: np.ndarray, names=None, *, unit: str = "",
             title: str = "", groups=None, group_names=None) -> None:
    """A static bar chart of finite values (non-finite entries logged as 0); ``names`` (one per
    bar) are logged beside it as a ``parameter_names`` component, and the bars are drawn again,
    named, under ``path`` for a :func:`pipeline.views.charts.chart_view`."""
    v = np.asarray(values, dtype=float)
    extra = []
    if names is not None:
        names = [str(n) for n in names]
        if len(names) != v.size:
            raise ValueError(f"names must have one entry per bar ({v.size}), got {len(names)}")
        extra.append(rr.AnyValues(parameter_names=names))
    rec.log(path, rr.BarChart(bar_values(np.where(np.isfinite(v), v, 0.0))), *extra, static=True)
    if names is not None:
        log_named_bars(rec, path, names, [("value", v, (50, 150, 235))], unit=unit, title=title,
                       groups=groups, group_names=group_names)


def log_observability(rec: rr.RecordingStream, analysis: ObservabilityAnalysis, prefix: str = "observability",
                      *, title: str = "Observability") -> None:
    """Log the singular value spectrum, per-parameter CRB bars and a markdown report.

    Args:
        rec: an open recording stream.
        analysis: from :func:`calib.observability.analyze_observability`.
        prefix: entity path prefix.
        title: heading of the markdown report.
    """
    if not isinstance(analysis, ObservabilityAnalysis):
        raise TypeError(f"analysis must be an ObservabilityAnalysis, got {type(analysis).__name__}")
    s = analysis.singular_values
    log_bars(rec, f"{prefix}/singular_values", s)
    with np.errstate(divide="ignore"):
        log_bars(rec, f"{prefix}/log10_singular_values", np.log10(s))
    log_bars(rec, f"{prefix}/crb_std_mm", analysis.crb_std_mm, analysis.names, unit="mm",
             title="Cramer-Rao std per parameter")
    log_combinations(rec, f"{prefix}/combinations", analysis)
    rec.log(f"{prefix}/report",
            rr.TextDocument(observability_markdown(analysis, title=title), media_type=rr.MediaType.MARKDOWN),
            static=True)


#: Width kept left of the bars for a combination's name ("0.56 B3.z + 0.55 P3.z + 0.31 B2.z + ..."):
#: names beside their bars, on their own row, never across another row's bar whatever the view's zoom.
COMBINATION_NAME_PX = 250.0


def log_combinations(rec: rr.RecordingStream, path: str, analysis: ObservabilityAnalysis, k: int = 6) -> None:
    """The ``k`` worst-determined combinations as bars named by the combination (std in um)."""

    combos = analysis.weakest_combinations(min(k, analysis.n_free), n_terms=3)[::-1]  # best of them first
    names = [c["combination"] + ("" if c["determined"] else " (not identifiable)") for c in combos]
    std = np.array([c["std_mm"] * 1e3 if c["determined"] else np.nan for c in combos])
    log_named_bars(rec, path, names, [("std", std, (235, 205, 60))], unit="um",
                   title="worst-determined combinations (std)", name_px=COMBINATION_NAME_PX, rows_per_column=k)


def observability_views(prefix: str = "observability", name: str = "Observability", *,
                        per_parameter: bool = False) -> rrb.Container:
    """Blueprint views of what :func:`log_observability` writes: the named weakest combinations
    (and with ``per_parameter`` the named CRB bars) above the report."""

    views = [chart_view(f"{prefix}/combinations", f"{name}: worst-determined parameter combinations")]
    if per_parameter:
        views.append(chart_view(f"{prefix}/crb_std_mm", f"{name}: Cramer-Rao std per parameter (mm)"))
    views.append(rrb.TextDocumentView(origin=f"{prefix}/report", name=f"{name}: report"))
    return rrb.Vertical(*views)
