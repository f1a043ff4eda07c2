"""The discovery's Rerun view (rerun-sdk 0.41 API): residuals against time, stroke, the direction
of the last move and the verdict's quantity, candidate evidence bars named by effect, and the
report's markdown (:func:`pipeline.report.text.report_markdown`) as its summary panel; read from
the discovery's :class:`pipeline.report.Report` and its :class:`calib.effects.Discovery`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from calib.effects import EFFECTS, EffectData
from calib.effects.base import PAYLOAD_CHANNEL
from calib.robot import Robot
from pipeline.formats import Recording
from pipeline.report.text import model_words, report_markdown

from .charts import (FLAG_COLOR, MACHINE_COLORS, application_id, chain_colors, chart_view, log_named_bars,
                     log_residual_scatter, save_recording)

#: Size of each residual chart, chart units (about pixels at 1600x900).
CHART_W, CHART_H = 600.0, 160.0

__all__ = ["PLOTTED_QUANTITIES", "quantity_values", "verdict_quantity", "write_discovery_rrd"]


#: The quantities the discovery file always plots the residuals against (the fourth chart is the
#: one the verdict names); names as in :data:`calib.effects.FOLLOWED_QUANTITIES`.
PLOTTED_QUANTITIES = ("time", "stroke", "direction of the last move")


def quantity_values(data: EffectData, name: str) -> tuple[np.ndarray, str]:
    """(N, C) values of a quantity the remainder is tested against (``remaining['follows']``,
    an effect's ``follows``: time, the direction or size of each joint's last move, its stroke,
    the load it carries, ``position <coordinate>``) and the axis label that says its unit."""
    robot, n, c = data.robot, data.n, data.robot.n_chains
    unit = robot.joint_unit
    if name == "time":
        span = float(np.ptp(data.t_s)) if n else 0.0
        scale, word = (60.0, "min") if span > 600 else (1.0, "s")
        return np.broadcast_to(data.t_s[:, None] / scale, (n, c)), f"time ({word})"
    if name == "direction of the last move":
        # -1 decreasing, +1 increasing; each side spread by row order so that the points do not pile up.
        spread = 0.6 * (np.arange(n) / max(n - 1, 1) - 0.5)
        return data.direction + spread[:, None], "last move: -1 decreasing, +1 increasing (spread by row)"
    if name == "size of the last move":
        return np.abs(data.last_move), f"size of the last move ({unit})"
    if name == "stroke":
        return data.stroke, f"stroke from the centre of travel ({unit})"
    if name == "load":
        load = EFFECTS["compliance"].joint_regressors(robot, data.theta, data)[..., 0]
        what = "axial share of the platform's weight" if unit == "mm" else "joint torque per unit platform weight (mm)"
        return load, f"load: {what}"
    if name.startswith("position "):
        k = robot.pose_names.index(name.split(" ", 1)[1])
        unit_k = "rad" if robot.angle_pose_mask[k] else "mm"
        return np.broadcast_to(data.measured[:, k:k + 1], (n, c)), f"{name} ({unit_k})"
    raise ValueError(f"unknown quantity {name!r}")


def verdict_quantity(report, tests) -> tuple[str, str]:
    """The quantity the discovery file plots beside time, stroke and direction, and why: what the
    remainder follows, else what a named effect follows, else the quantity whose structure test is
    the strongest (the size of the last move or the load before a pose coordinate). ``report``: the
    discovery's :class:`pipeline.report.Report`; ``tests``: its remainder's structure tests
    (:class:`calib.effects.remainder.RemainderTests`)."""
    fixed = set(PLOTTED_QUANTITIES)
    for q in report.effects.remaining.follows:
        if q not in fixed:
            return q, "the remainder follows it"
    for e in (row.name for row in report.effects.effects):
        q = EFFECTS[e].follows if e in EFFECTS else None  # a kept law (pipeline.discover --use-law) follows its terms
        if q and q not in fixed:
            return q, f"{e} follows it"
    structure = {t.quantity: t for t in tests.structure}  # the physical quantities first, then the pose coordinates
    rest = sorted((q for q in structure if q not in fixed), key=lambda q: (q.startswith("position "),
                                                                         -structure[q].score))
    if rest:
        p = structure[rest[0]].p_value
        return rest[0], f"strongest test left, p = {p:.2g}"
    return "stroke", "no other quantity tested"


def write_discovery_rrd(path: Path, robot: Robot, rec: Recording, report, *, overwrite: bool = False) -> Path:
    """The discovery file of ``report`` (a :class:`pipeline.workflows.discovery.DiscoveryReport`):
    the verdict first, the residuals before and after against time, stroke, the direction of the
    last move and the quantity the verdict names, the candidates' evidence by name, flagged rows
    marked (see docs/rerun_views.md)."""
    disc, found = report.discovery, report.report
    rows = np.union1d(disc.kept, np.asarray(disc.flagged, dtype=int))  # flagged rows drawn too, marked
    data = EffectData(robot, robot.table.nominal, rec.joints, rec.measured, rec.t_s, rec.noise,
                      payload_kg=rec.extras.get(PAYLOAD_CHANNEL)).subset(rows)
    before = 1e3 * disc.geometry.predict(data)[0]
    after = 1e3 * disc.chosen.predict(data)[0]
    flagged = [int(i) for i in np.flatnonzero(np.isin(rows, disc.flagged))]
    chains = [f"{robot.chain_word} {i + 1}" for i in range(robot.n_chains)]
    named = [e.name for e in found.effects.effects]
    model = model_words(named)
    models = ("geometry alone", f"{model}, own scale")
    follows = set(found.effects.remaining.follows)
    extra, why = verdict_quantity(found, disc.tests)
    charts = [(q, "the remainder follows it" if q in follows else "") for q in PLOTTED_QUANTITIES] + [(extra, why)]
    candidates = [c.name for c in found.effects.candidates]
    alone_bic = {c.name: c.delta_bic_vs_none for c in found.effects.candidates}

    def log(r):
        for q, _ in charts:
            x, label = quantity_values(data, q)
            path = f"vs/{q.replace(' ', '_')}"
            log_residual_scatter(r, path, x, before, after, x_label=label, chain_names=chains,
                                 flagged=flagged, rows=rows + 1, models=models, width=CHART_W, height=CHART_H,
                                 same_scale=False)
            # The colour key of the chains under the charts (the same colours as in the run file).
            r.log(f"{path}/chain_key", rr.Points2D([(60 + (CHART_W - 120) * j / max(len(chains) - 1, 1),
                                                     2 * CHART_H + 38)
                                                    for j in range(len(chains))], radii=3.0,
                                                   colors=chain_colors(len(chains)), labels=chains,
                                                   show_labels=True), static=True)
        order = [c for c in candidates if c in named] + [c for c in candidates if c not in named]
        alone = [np.nan if alone_bic[c] is None else alone_bic[c] for c in order]
        entered = [np.nan if (b := disc.evidence.delta_bic_when_added(c)) is None else b for c in order]
        log_named_bars(r, "evidence", order, [("alone (vs geometry)", signed_log(alone), (235, 205, 60)),
                                              ("when it entered", signed_log(entered), MACHINE_COLORS["calibrated"])],
                       unit="signed log10(1 + |BIC drop|)", groups=[1 if c in named else 0 for c in order],
                       group_names=["not named", "named (in the model)"], title="Evidence per candidate",
                       note="an effect needs a BIC drop of 10 (1.04 here) and a lower CV residual", name_px=130.0)
        r.log("summary", rr.TextDocument(report_markdown(found), media_type=rr.MediaType.MARKDOWN),
              static=True)
        r.log("verdict", rr.TextDocument(found.verdict.words), static=True)
        r.log("remaining", rr.TextDocument(json.dumps(disc.remaining.to_dict(), indent=1)), static=True)
        # The RMS of each row's residual on the `measurement` timeline (the recording's 1-based row).
        grey, blue = MACHINE_COLORS["nominal"], MACHINE_COLORS["calibrated"]
        r.log("per_row/rms_um", rr.SeriesLines(names=["geometry alone", model], colors=[grey, blue]), static=True)
        rms = np.c_[np.sqrt(np.mean(before ** 2, axis=1)), np.sqrt(np.mean(after ** 2, axis=1))]
        r.send_columns("per_row/rms_um", indexes=[rr.TimeColumn("measurement", sequence=rows + 1)],
                       columns=rr.Scalars.columns(scalars=rms))
        if flagged:
            r.log("per_row/rms_um/flagged", rr.SeriesPoints(colors=FLAG_COLOR, names="flagged row", marker_sizes=6.0),
                  static=True)
            r.send_columns("per_row/rms_um/flagged", indexes=[rr.TimeColumn("measurement", sequence=rows[flagged] + 1)],
                           columns=rr.Scalars.columns(scalars=rms[flagged, 0]))

    bp = discovery_blueprint(charts)
    return save_recording(path, log, application_id=application_id("discover", robot.name), overwrite=overwrite, bp=bp)


def signed_log(v) -> np.ndarray:
    """``sign(v) log10(1 + |v|)``: BIC drops of any size on one bar scale."""
    v = np.asarray(v, dtype=float)
    return np.sign(v) * np.log10(1.0 + np.abs(v))


def discovery_blueprint(charts: list) -> rrb.Blueprint:
    """The discovery file's layout: the verdict and the evidence on the left, the four residual
    charts (``charts``: ``(quantity, note)`` pairs) on the right, the ``measurement`` timeline."""

    def view(q, note):  # framed on the two plots and the key (the default bounds leave wide margins)
        return rrb.Spatial2DView(origin=f"vs/{q.replace(' ', '_')}",
                                 name=f"Closure residual vs {q}" + (f" ({note})" if note else ""),
                                 background=(18, 18, 18),
                                 visual_bounds=rrb.VisualBounds2D(x_range=[-5.0, CHART_W + 5.0],
                                                                  y_range=[-10.0, 2 * CHART_H + 55.0]))

    views = [view(q, note) for q, note in charts]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(rrb.TextDocumentView(origin="summary", name="Verdict and summary"),
                         rrb.Tabs(chart_view("evidence", "Evidence per candidate (BIC drop, named)"),
                                  rrb.TimeSeriesView(origin="per_row/rms_um",
                                                     name="Residual RMS per row (um) vs measurement row")),
                         row_shares=[2, 1]),
            rrb.Vertical(rrb.Horizontal(views[0], views[1]), rrb.Horizontal(views[2], views[3])),
            column_shares=[1.2, 2.6]),
        rrb.TimePanel(timeline="measurement", play_state="paused", state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        collapse_panels=True)
