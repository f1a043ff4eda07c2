"""Reading an ``.rrd`` file back: its entities, application ids, default blueprint, the views
that would open empty, the labels of a chart (tests and checks; ``rerun.chunk.RrdReader``)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["rrd_entities", "rrd_application_ids", "rrd_blueprint", "empty_views", "rrd_labels"]


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
