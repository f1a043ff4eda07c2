"""The report a lab keeps: one typed model of a calibration's or a discovery's outcome, built from
the summary ``python -m pipeline.run`` or ``python -m pipeline.discover`` gives (the dict their
``--summary-json`` writes), in sections (verdict, machine and recording, parameters, held-out
figures, instrument frames, effects, flagged rows, compensation).

The wording lives here and nothing here imports Rerun or draws: :mod:`pipeline.formats.report_html`
renders the model as one self-contained HTML file. Every figure keeps the summary's unit (mm, rad);
a renderer scales it for display.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Report", "Verdict", "Fact", "ParameterRow", "Parameters", "Figures", "FigureRow", "PerPose", "IsoPose",
           "Heldout", "FrameRow", "Frames", "EffectRow", "Law", "Effects", "Flagged", "CompensationTable",
           "build_report", "report_kind"]


@dataclass(frozen=True)
class Verdict:
    """The outcome in one line: ``success`` (calibrated / explained), its words, the likely cause."""

    success: bool | None
    words: str
    cause: str | None = None


@dataclass(frozen=True)
class Fact:
    """One labelled line of the machine-and-recording section."""

    label: str
    value: str


@dataclass(frozen=True)
class ParameterRow:
    """One parameter: identified value and error from nominal (its unit), two standard
    uncertainties (``two_sigma``, None when unknown), its tolerance (one standard deviation about
    nominal, None when none is known), what determined it and the tolerance verdict in words."""

    name: str
    unit: str
    value: float | None
    error: float
    two_sigma: float | None
    tolerance: float | None
    determined_by: str | None
    implausible: bool
    verdict: str


@dataclass(frozen=True)
class Parameters:
    """The identified parameters, the prior they were fitted under, and what the data left to it."""

    rows: tuple[ParameterRow, ...]
    prior: str
    left_to_prior: tuple[str, ...] = ()
    implausible: tuple[str, ...] = ()


@dataclass(frozen=True)
class Figures:
    """RMS, mean and max of per-pose error norms (the unit of the row they belong to; None: not given)."""

    rms: float | None
    mean: float | None
    max: float | None

    @classmethod
    def of(cls, block: dict | None) -> "Figures | None":
        if not block:
            return None
        return cls(block.get("rms"), block.get("mean"), block.get("max"))


@dataclass(frozen=True)
class FigureRow:
    """A held-out quantity before and after calibration (``unit`` the summary's: mm or rad)."""

    label: str
    unit: str
    before: Figures | None
    after: Figures | None


@dataclass(frozen=True)
class PerPose:
    """Per held-out pose (or row) error norms before and after, for a plot (``unit`` mm or rad);
    ``rows``: their 1-based data rows, None for simulated poses."""

    label: str
    unit: str
    before: tuple[float, ...]
    after: tuple[float, ...]
    rows: tuple[int, ...] | None = None


@dataclass(frozen=True)
class IsoPose:
    """ISO 9283 figures of one repeated pose, mm: accuracy AP before and after, repeatability RP."""

    rows: tuple[int, ...]
    repeats: int
    ap_before: float
    ap_after: float
    rp: float


@dataclass(frozen=True)
class Heldout:
    """Errors on poses the fit did not use: what they are (``basis``), the figures, the per-pose
    errors, the ISO 9283 figures of repeated poses, the noise floor (mm) where known."""

    basis: str
    poses: int
    figures: tuple[FigureRow, ...]
    per_pose: tuple[PerPose, ...] = ()
    iso9283: tuple[IsoPose, ...] = ()
    iso_standard: str = ""
    noise_floor_mm: float | None = None


@dataclass(frozen=True)
class FrameRow:
    """One instrument frame (its session): translation mm, rotation rad, with standard uncertainties."""

    session: str
    translation_mm: tuple[float, ...]
    rotation_rad: tuple[float, ...]
    translation_std_mm: tuple[float, ...] | None
    rotation_std_rad: tuple[float, ...] | None


@dataclass(frozen=True)
class Frames:
    """The instrument frames the data were registered in, and the components the poses left to the geometry."""

    rows: tuple[FrameRow, ...]
    held: tuple[str, ...] = ()


@dataclass(frozen=True)
class EffectRow:
    """One effect found: its granularity, its coefficients ``(name, value, std, unit)``, its evidence in words."""

    name: str
    granularity: str
    coefficients: tuple[tuple[str, float, float | None, str], ...]
    evidence: str


@dataclass(frozen=True)
class Law:
    """A proposed law outside the library: formula, the constants per joint (``{name: values}``
    with their std and unit), the cross-validated residual RMS before and after (mm)."""

    formula: str
    constants: tuple[tuple[str, tuple[float, ...], tuple[float, ...] | None, str], ...]
    cv_before_mm: float | None
    cv_after_mm: float | None
    words: str


@dataclass(frozen=True)
class Effects:
    """What discovery found beyond the geometry: the effects with their evidence, what remains,
    the aliases, the parameters the effects bring back within tolerance, a proposed law."""

    effects: tuple[EffectRow, ...]
    candidates: tuple[str, ...]
    remaining: str
    notes: tuple[str, ...] = ()
    law: Law | None = None


@dataclass(frozen=True)
class Flagged:
    """Rows named by the gross-row search and the outlier test (1-based data rows) and what was done."""

    rows: tuple[int, ...]
    gross: tuple[int, ...]
    words: tuple[str, ...]


@dataclass(frozen=True)
class CompensationTable:
    """Compensated commands for a sequence of targets: what was compensated and what not (why),
    a table (``columns``, ``rows`` of numbers; ``unit`` of the correction columns)."""

    what: str
    compensated: tuple[str, ...]
    not_compensated: tuple[tuple[str, str], ...]
    columns: tuple[str, ...]
    rows: tuple[tuple[float, ...], ...]


@dataclass(frozen=True)
class Report:
    """One calibration's or discovery's report (``kind``: ``calibration`` or ``discovery``)."""

    kind: str
    title: str
    verdict: Verdict
    machine: tuple[Fact, ...]
    parameters: Parameters | None
    heldout: Heldout | None
    frames: Frames | None
    effects: Effects | None
    flagged: Flagged
    compensation: CompensationTable | None = None
    warnings: tuple[str, ...] = field(default_factory=tuple)


def report_kind(summary: dict) -> str:
    """``discovery`` for a summary of ``pipeline.discover`` (it says whether the data are
    ``explained``), else ``calibration``."""
    return "discovery" if "explained" in summary else "calibration"


def _noise_words(noise: dict | None) -> str:
    if not noise:
        return "not stated"
    dist = noise.get("distribution", "")
    how = "half-width" if dist == "uniform" else "standard deviation"
    parts = [f"{noise['position_mm']:g} mm on positions"]
    if noise.get("orientation_rad"):
        parts.append(f"{noise['orientation_rad']:g} rad on angles")
    if noise.get("joint"):
        parts.append(f"{noise['joint']:g} on joint readings")
    return f"{', '.join(parts)} ({dist}, {how})"


def _machine(s: dict, kind: str) -> tuple[Fact, ...]:
    facts = [Fact("robot", s["robot"])]
    if kind == "calibration":
        facts.append(Fact("recording", s.get("scenario", "")))
        if s.get("method") is not None:  # a summary of a run (a calibration file alone has none of these)
            facts.append(Fact("method", f"{s.get('method')} ({s.get('solver')}), {s.get('iterations')} iterations"))
            facts.append(Fact("calibration rows", f"{s.get('calibration_poses')} ({s.get('calibration_poses_used')} used)"))
            facts.append(Fact("held-out poses", str(s.get("heldout_poses", 0))))
    else:
        facts.append(Fact("recording", str(s.get("recording") or "")))
        facts.append(Fact("rows", str(s.get("rows"))))
        facts.append(Fact("candidate effects", ", ".join(s.get("candidates") or ()) or "none"))
    facts.append(Fact("declared noise", _noise_words(s.get("declared_noise"))))
    if s.get("seed") is not None:
        facts.append(Fact("seed", str(s["seed"])))
    for key, label in (("calibration", "calibration file"), ("rrd", "Rerun recording")):
        if s.get(key):
            facts.append(Fact(label, str(s[key])))
    return tuple(facts)


#: How a parameter's source reads in the report.
DETERMINED_BY = {"data": "the data", "prior": "the prior (tolerance)", "held": "held at nominal"}


def _tolerance_verdict(error: float, tolerance: float | None, implausible: bool) -> str:
    if tolerance is None or not tolerance > 0:
        return "no tolerance declared"
    ratio = abs(error) / tolerance
    if implausible:
        return f"implausible: {ratio:.3g} x its tolerance"
    return f"within tolerance ({ratio:.2g} x)"


def _calibration_parameters(s: dict) -> Parameters | None:
    det = s.get("parameter_determination") or {}
    if not det:
        return None
    prior = s.get("prior") or {}
    tolerance = prior.get("tolerance") or {}
    implausible = {d["name"]: d for d in s.get("implausible_parameters") or ()}
    free = set(s.get("free_parameters") or det)
    rows = []
    for name, d in det.items():
        if name not in free:
            continue
        std = d.get("posterior_std")
        rows.append(ParameterRow(name=name, unit=d["unit"], value=d["value"], error=d["error"],
                                 two_sigma=None if std is None else 2.0 * std, tolerance=tolerance.get(name),
                                 determined_by=DETERMINED_BY.get(d.get("source"), d.get("source")),
                                 implausible=name in implausible,
                                 verdict=_tolerance_verdict(d["error"], tolerance.get(name), name in implausible)))
    return Parameters(rows=tuple(rows), prior=prior.get("source") or "none",
                      left_to_prior=tuple(s.get("left_to_prior") or ()),
                      implausible=tuple(d["words"] for d in implausible.values()))


def _discovery_parameters(s: dict) -> Parameters | None:
    errors = s.get("identified_errors") or {}
    if not errors:
        return None
    imp = s.get("implausible_parameters") or {}
    std = s.get("identified_std") or {}
    tolerance = imp.get("tolerance") or {}
    units = s.get("parameter_units") or {}
    still = {d["name"]: d for d in imp.get("with_effects") or ()}
    rows = []
    for name in s.get("free_parameters") or errors:
        e = errors[name]
        sd = std.get(name)
        unit = units.get(name) or next((d["unit"] for d in (imp.get("geometry_alone") or ()) if d["name"] == name), "")
        rows.append(ParameterRow(name=name, unit=unit, value=None, error=e, two_sigma=None if sd is None else 2.0 * sd,
                                 tolerance=tolerance.get(name), determined_by=None, implausible=name in still,
                                 verdict=_tolerance_verdict(e, tolerance.get(name), name in still)))
    notes = tuple(imp.get("words") or ()) + tuple(f"still implausible with the effects: {d['words']}"
                                                  for d in still.values())
    return Parameters(rows=tuple(rows), prior=imp.get("tolerance_source") or "not stated", implausible=notes)


def _per_pose(s: dict) -> tuple[PerPose, ...]:
    per = s.get("heldout_per_pose")
    if not per:
        return ()
    rows = tuple(per["rows"]) if per.get("rows") else None
    out = [PerPose("position error", "mm", tuple(per["position_before_mm"]), tuple(per["position_after_mm"]),
                   rows if per.get("per") == "pose" else None)]
    if per.get("orientation_before_rad") is not None:
        out.append(PerPose("orientation error", "rad", tuple(per["orientation_before_rad"]),
                           tuple(per["orientation_after_rad"]), rows))
    return tuple(out)


def _iso(s: dict) -> tuple[tuple[IsoPose, ...], str]:
    iso = s.get("iso9283")
    if not iso:
        return (), ""
    poses = tuple(IsoPose(tuple(p["rows"]), p["repeats"], p["AP_before_mm"], p["AP_after_mm"], p["RP_mm"])
                  for p in iso["poses"])
    return poses, f"{iso['standard']}; {iso['basis']}"


def _calibration_heldout(s: dict) -> Heldout | None:
    h, o = s.get("heldout_position_error_mm"), s.get("heldout_orientation_error_rad")
    if h:
        rows = [FigureRow("position error", "mm", Figures.of(h["before_figures"]), Figures.of(h["after_figures"]))]
        if o:
            rows.append(FigureRow("orientation error", "rad", Figures.of(o["before_figures"]),
                                  Figures.of(o["after_figures"])))
        iso, standard = _iso(s)
        return Heldout(basis=s.get("heldout_basis") or "", poses=int(s.get("heldout_poses") or 0), figures=tuple(rows),
                       per_pose=_per_pose(s), iso9283=iso, iso_standard=standard)
    return _crossvalidated(s, "no held-out poses: ")


def _crossvalidated(s: dict, prefix: str) -> Heldout | None:
    cv, info = s.get("crossvalidated_position_error_mm"), s.get("crossvalidation")
    if not cv or cv.get("rms") is None or not info:
        return None
    rows = [FigureRow("cross-validated position error", "mm", None, Figures.of(cv))]
    o = s.get("crossvalidated_orientation_error_rad")
    if o and o.get("rms") is not None:
        rows.append(FigureRow("cross-validated orientation error", "rad", None, Figures.of(o)))
    return Heldout(basis=prefix + info.get("message", ""), poses=int(info.get("rows_predicted") or 0),
                   figures=tuple(rows))


def _discovery_heldout(s: dict) -> Heldout:
    before, after = s["heldout_rms_before_mm"], s["heldout_rms_after_mm"]
    rows = [FigureRow("held-out closure residual (geometry alone -> with the effects)", "mm",
                      Figures(before, None, None), Figures(after, None, None))]
    per = s.get("heldout_per_row")
    per_pose = ()
    if per:
        per_pose = (PerPose("closure residual RMS over the joints", "mm", tuple(per["before_mm"]), tuple(per["after_mm"]),
                            tuple(per["rows"])),)
        rows[0] = FigureRow(rows[0].label, "mm", Figures(before, per.get("before_mean_mm"), per.get("before_max_mm")),
                            Figures(after, per.get("after_mean_mm"), per.get("after_max_mm")))
    cv = s.get("crossvalidated_position_error_mm")
    if cv and cv.get("rms") is not None:
        rows.append(FigureRow("cross-validated position error, geometry alone", "mm", Figures.of(cv), None))
    n = len(per["rows"]) if per else 0
    return Heldout(basis=s.get("heldout_basis") or "", poses=n, figures=tuple(rows), per_pose=per_pose,
                   noise_floor_mm=s.get("noise_floor_mm"))


def _frames(s: dict) -> Frames | None:
    def row(session, f, sd):
        return FrameRow(session, tuple(f["translation_mm"]), tuple(f["rotation_rad"]),
                        None if sd is None else tuple(sd["translation_mm"]),
                        None if sd is None else tuple(sd["rotation_rad"]))

    if s.get("measurement_frames"):
        stds = s.get("measurement_frames_std") or {}
        rows = tuple(row(k, f, stds.get(k)) for k, f in s["measurement_frames"].items())
    elif s.get("measurement_frame"):
        rows = (row("the recording", s["measurement_frame"], s.get("measurement_frame_std")),)
    else:
        return None
    return Frames(rows=rows, held=tuple(s.get("measurement_frame_held") or ()))


def _effect_evidence(s: dict, name: str, params: dict) -> str:
    e = (s.get("evidence") or {}).get(name, {})
    sig = params.get("significance") or {}
    parts = []
    if e.get("delta_bic_when_added") is not None:
        parts.append(f"BIC lower by {e['delta_bic_when_added']:.4g} when it entered")
    if sig:
        parts.append(f"non-zero at p = {sig['p_value']:.2g} (Wald chi-square {sig['wald_chi2']:.4g} on {sig['dof']})")
    if e.get("cv_whitened_rms") is not None:
        parts.append(f"cross-validated whitened RMS with it alone {e['cv_whitened_rms']:.3g}")
    if name in (s.get("partial") or ()):
        parts.append("partial: structure remains")
    return "; ".join(parts)


def _effects(s: dict) -> Effects:
    rows = []
    for name in s.get("effects") or ():
        params = (s.get("effect_parameters") or {}).get(name, {})
        coefs = tuple((k, v["value"], v.get("std"), v.get("unit", "")) for k, v in params.items()
                      if k not in ("significance", "granularity"))
        rows.append(EffectRow(name=name, granularity=str(params.get("granularity", "shared")).replace("_", " "),
                              coefficients=coefs, evidence=_effect_evidence(s, name, params)))
    notes = []
    ev = s.get("evidence") or {}
    if s.get("effects") and ev.get("none", {}).get("cv_whitened_rms") is not None \
            and ev.get("cv_whitened_rms_chosen") is not None:
        notes.append(f"cross-validated whitened RMS, geometry alone {ev['none']['cv_whitened_rms']:.3g} -> with the "
                     f"effects {ev['cv_whitened_rms_chosen']:.3g} (1 is the declared noise)")
    for a in s.get("aliases") or ():
        notes.append(f"cannot tell apart on this recording: {a['named']} and {a['rival']} ({a['named']} fitted)")
    r = s.get("mujoco_resimulation")
    if r:
        notes.append(f"MuJoCo machine re-simulated: position RMS {r['before']['position_um']:.4g} um -> "
                     f"{r['after']['position_um']:.4g} um")
    law = s.get("proposed_law")
    return Effects(effects=tuple(rows), candidates=tuple(s.get("candidates") or ()),
                   remaining=(s.get("remaining") or {}).get("summary", "") if (s.get("remaining") or {}).get("present")
                   else "nothing beyond the declared noise", notes=tuple(notes),
                   law=None if not law else Law(
                       formula=law["formula"],
                       constants=tuple((k, tuple(v), tuple((law.get("constants_std") or {}).get(k) or ()) or None,
                                        (law.get("units") or {}).get(k, "")) for k, v in law["constants"].items()),
                       cv_before_mm=law.get("cv_rms_before_mm"), cv_after_mm=law.get("cv_rms_after_mm"),
                       words=("with it the recording is explained" if law.get("explained_with_law") else
                              f"with it: {law.get('remaining_with_law', '')}")))


def _flagged(s: dict, kind: str) -> Flagged:
    rows = tuple(s.get("flagged_poses") or ())
    gross = tuple((s.get("gross_rows") or {}).get("rows") or ())
    words = []
    out = s.get("outliers") or {}
    if kind == "calibration":
        if out.get("verdict"):
            words.append(f"outlier test: {out['verdict']}")
        if rows:
            words.append("left out of the fit" if out.get("left_out") or (s.get("gross_rows") or {}).get("left_out")
                         else "kept in the fit")
    else:
        if out.get("bad_rows"):
            words.append(f"rows that look bad: {', '.join(map(str, out['bad_rows']))}"
                         + (" (the model is wrong, not the data: none left out)" if out.get("model_wrong") else ""))
        if rows:
            words.append("flagged rows are left out of the analysis")
    if s.get("row_numbering"):
        words.append(f"rows: {s['row_numbering']}")
    return Flagged(rows=rows, gross=gross, words=tuple(words))


def _compensation(s: dict) -> CompensationTable | None:
    c = s.get("compensation")
    if not c:
        return None
    return CompensationTable(what=c.get("what", ""), compensated=tuple(c.get("compensated") or ()),
                             not_compensated=tuple((c.get("not_compensated") or {}).items()),
                             columns=tuple(c.get("columns") or ()), rows=tuple(tuple(r) for r in c.get("rows") or ()))


def build_report(summary: dict) -> Report:
    """The report of a ``pipeline.run`` or ``pipeline.discover`` summary (:func:`report_kind`).

    Raises:
        KeyError: a summary lacking a key every summary of its kind has (``robot``, and a
            discovery's ``verdict``, ``explained``, held-out RMS).
    """
    s, kind = summary, report_kind(summary)
    if kind == "calibration":
        v = s.get("verdict") or {}
        success = None if s.get("success") is None and "success" in s else bool(s.get("success"))
        verdict = Verdict(success, v.get("words") or ("converged" if s.get("success") else
                                                      "not a success"), v.get("cause"))
        title = f"Calibration of the {s['robot']}"
        parameters, heldout, effects = _calibration_parameters(s), _calibration_heldout(s), None
    else:
        verdict = Verdict(bool(s["explained"]), s["verdict"], None)
        title = f"Discovery on the {s['robot']}"
        parameters, heldout, effects = _discovery_parameters(s), _discovery_heldout(s), _effects(s)
    return Report(kind=kind, title=title, verdict=verdict, machine=_machine(s, kind), parameters=parameters,
                  heldout=heldout, frames=_frames(s), effects=effects, flagged=_flagged(s, kind),
                  compensation=_compensation(s), warnings=tuple(s.get("warnings") or ()))
