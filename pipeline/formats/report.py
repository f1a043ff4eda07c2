"""The report of a calibration or a discovery: one typed model of its outcome, built from the
summary ``python -m pipeline.run`` or ``python -m pipeline.discover`` gives (the dict their
``--summary-json`` writes), in sections: the machine and recording, the verdict, how the fit ran,
the parameters and what determined them, the implausible ones, the held-out figures, the
instrument frames, the effects found, the flagged rows, the compensation, the warnings, the timing
and the files written.

The model holds figures, names and the sentences the analysis itself wrote (a verdict, a held-out
basis, a warning); it composes no words. :mod:`pipeline.formats.report_text` words it (the
terminal summary, the Rerun markdown, the phrases of the HTML report), :mod:`pipeline.formats.report_html`
lays it out as one HTML file, and :meth:`Report.to_dict` is its JSON form (the summary JSON's
``report_model``). Every figure keeps the summary's unit (mm, rad; um where the name says so).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

__all__ = ["Report", "Source", "Noise", "Verdict", "Fit", "Truth", "ParameterRow", "Parameters", "Suggested",
           "Determination", "Implausible", "Figures", "FigureRow", "PerPose", "IsoPose", "CrossValidation", "Heldout",
           "FrameRow", "Frames", "Coefficient", "EffectRow", "Candidate", "Remaining", "GeometryTest", "Alias",
           "Unseparated", "PoseFamily", "Separation", "LawConstant", "Law", "SysId", "Resimulation", "Search", "Effects",
           "Flagged", "CompensationTable", "Timing", "Outputs", "build_report", "report_kind", "summary_document",
           "REPORT_KEY", "OUTPUT_KEYS"]

#: The key of the report model in a summary JSON (:func:`summary_document`).
REPORT_KEY = "report_model"
#: The summary keys of the files a run or a discovery writes, in the order they are listed.
OUTPUT_KEYS = ("rrd", "csv", "json", "calibration", "mjcf", "summary_json", "report")


@dataclass(frozen=True)
class Noise:
    """The declared noise: on each position coordinate (mm), each angle (rad), each joint reading
    (the robot's joint unit); ``distribution`` ``uniform`` (the figures are half-widths) or ``normal``
    (standard deviations)."""

    position_mm: float
    orientation_rad: float
    joint: float
    distribution: str


@dataclass(frozen=True)
class Source:
    """The machine and the recording: the robot and what its chains are called, the recording (a
    file, or the simulated scenario in words), its rows (a discovery's), the declared noise, the seed."""

    robot: str
    chain_word: str
    recording: str
    rows: int | None = None
    noise: Noise | None = None
    seed: int | None = None


@dataclass(frozen=True)
class Verdict:
    """The outcome: ``success`` (calibrated / explained; None: not judged, a calibration file alone),
    the analysis's own words (None: it stated no verdict), the likely cause (a calibration's)."""

    success: bool | None
    words: str | None
    cause: str | None = None


@dataclass(frozen=True)
class Fit:
    """How a calibration's identification ran: method and solver, iterations, whether it converged,
    the solver's stop message, max dQint per iteration (mm), the condition numbers, the calibration
    rows and those used, the held-out poses."""

    method: str
    solver: str | None
    iterations: int | None
    converged: bool | None
    message: str
    history: tuple[float, ...]
    condition_numbers: tuple[float, ...]
    rows: int | None
    rows_used: int | None
    heldout_poses: int


@dataclass(frozen=True)
class Truth:
    """A simulated machine against its injected errors: RMS of identified - injected over the
    lengths (mm) and the angles (rad), None where there are none; the calibration gain G, percent
    (mean over the parameters, on the error norm), None when not computed."""

    rms_mm: float | None
    rms_rad: float | None
    gain_mean_percent: float | None = None
    gain_norm_percent: float | None = None


@dataclass(frozen=True)
class ParameterRow:
    """One parameter: identified value and error from nominal (its unit), two standard
    uncertainties (``two_sigma``, None when unknown), its tolerance (one standard deviation about
    nominal, None when none is known), what determined it (``source``: ``data``, ``prior``,
    ``held`` or None) and whether its error is implausible."""

    name: str
    unit: str
    value: float | None
    error: float
    two_sigma: float | None
    tolerance: float | None
    source: str | None
    implausible: bool


@dataclass(frozen=True)
class Parameters:
    """The identified parameters, the prior they were fitted under (in words, the analysis's), and
    the combinations the data left to it (each in words)."""

    rows: tuple[ParameterRow, ...]
    prior: str
    left_to_prior: tuple[str, ...] = ()


@dataclass(frozen=True)
class Suggested:
    """Poses suggested to determine what the data left to the prior: how many, where (words), the file."""

    poses: int
    what: str
    path: str


@dataclass(frozen=True)
class Determination:
    """What a calibration's rows determined: whether a prior was used and which (words), the
    parameters the data determined and those left to the prior (names), how many free directions
    the rows determine, the combinations left to the prior (words), suggested poses."""

    prior_used: bool
    prior: str
    by_data: tuple[str, ...]
    by_prior: tuple[str, ...]
    directions: float | None
    combinations: tuple[str, ...]
    suggested: Suggested | None = None


@dataclass(frozen=True)
class Implausible:
    """Identified errors far beyond their tolerance, one sentence each: a calibration's (``words``);
    a discovery's with the geometry alone that the effects bring back within tolerance (``words``)
    and those still implausible with the effects (``with_effects``)."""

    words: tuple[str, ...] = ()
    with_effects: tuple[str, ...] = ()


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
    """A quantity before and after (``unit`` the summary's: mm or rad): ``quantity`` ``position``,
    ``orientation`` (a calibration's pose errors) or ``closure`` (a discovery's closure residual,
    geometry alone -> with the effects); ``crossvalidated``: the cross-validated prediction error
    (of the calibration; of the geometry alone for a discovery) rather than held-out poses'."""

    quantity: str
    unit: str
    before: Figures | None
    after: Figures | None
    crossvalidated: bool = False


@dataclass(frozen=True)
class PerPose:
    """Per held-out pose (or row) error norms before and after, for a plot (``unit`` mm or rad);
    ``quantity`` as :class:`FigureRow`'s; ``rows``: their 1-based data rows, None for simulated poses."""

    quantity: str
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
class CrossValidation:
    """A cross-validation: its scheme (``10-fold``, ``leave-one-out``), fits, the model it fitted
    (a discovery's: words), what it did (the analysis's words)."""

    scheme: str
    fits: int | None
    model: str | None
    message: str


@dataclass(frozen=True)
class Heldout:
    """Errors on poses the fit did not use: what they are (``basis``, the analysis's words), how
    many, the figures, the per-pose errors, the ISO 9283 figures of repeated poses (and the
    standard in words), the noise floor (mm) where known, the cross-validation behind
    cross-validated figures."""

    basis: str
    poses: int
    figures: tuple[FigureRow, ...]
    per_pose: tuple[PerPose, ...] = ()
    iso9283: tuple[IsoPose, ...] = ()
    iso_standard: str = ""
    noise_floor_mm: float | None = None
    crossvalidation: CrossValidation | None = None
    session_shifts: tuple[str, ...] = ()
    as_predicted_mm: tuple[float, float] | None = None


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
    """The instrument frames the data were registered in (``sessions``: one per session, else the
    recording's one frame), and the components the poses left to the geometry (words)."""

    rows: tuple[FrameRow, ...]
    held: tuple[str, ...] = ()
    sessions: bool = False


@dataclass(frozen=True)
class Coefficient:
    """One fitted coefficient of an effect: value, standard deviation (None: not known), unit."""

    name: str
    value: float
    std: float | None
    unit: str


@dataclass(frozen=True)
class EffectRow:
    """One effect found: its granularity (``shared``, ``per_chain``), its coefficients, its evidence:
    the BIC drop when it entered, its Wald test (chi-square, degrees of freedom, p-value), the
    cross-validated whitened RMS with it alone, whether structure remains (``partial``)."""

    name: str
    granularity: str
    coefficients: tuple[Coefficient, ...]
    delta_bic_when_added: float | None = None
    wald_chi2: float | None = None
    dof: int | None = None
    p_value: float | None = None
    cv_whitened_rms: float | None = None
    partial: bool = False


@dataclass(frozen=True)
class Candidate:
    """One candidate effect's evidence: the BIC drop alone against the geometry, the cross-validated
    whitened RMS with it alone, whether it was named."""

    name: str
    delta_bic_vs_none: float | None
    cv_whitened_rms: float | None
    named: bool


@dataclass(frozen=True)
class Remaining:
    """What the model leaves: whether beyond the noise (``present``), the analysis's summary in
    words, the residual RMS and noise floor (mm), the whitened RMS (x the declared noise), the
    quantities it follows, the chains it is on (1-based)."""

    present: bool
    summary: str
    rms_mm: float | None
    noise_floor_mm: float | None
    noise_ratio: float | None
    follows: tuple[str, ...]
    chains: tuple[int, ...]


@dataclass(frozen=True)
class GeometryTest:
    """The omnibus chi-square test of the geometry alone against the declared noise."""

    chi2: float
    dof: int
    p_value: float
    alpha: float


@dataclass(frozen=True)
class Alias:
    """Two candidates the recording cannot tell apart (``named`` fitted): the BIC between them,
    the correlation of their regressors; ``nested``: ``rival`` contains ``named`` and its extra
    parameters gain less than ``nested_min_delta_bic``."""

    named: str
    rival: str
    delta_bic: float
    correlation: float | None
    nested: bool
    nested_min_delta_bic: float | None = None


@dataclass(frozen=True)
class Unseparated:
    """An effect the poses cannot separate from the geometry: its form, the first effect combination
    and the geometric one it acts as (words), how many more combinations, the pose families that
    would separate it."""

    effect: str
    form: str
    combination: str
    geometry: str
    more: int
    separated_by: tuple[str, ...]


@dataclass(frozen=True)
class PoseFamily:
    """A family of poses tried: how many reachable of those tried, how many of the combinations left
    to the prior it would determine, the effects it separates."""

    family: str
    reachable: int
    tried: int
    determines: int
    separates: tuple[str, ...]


@dataclass(frozen=True)
class Separation:
    """What the poses cannot separate: of the geometry's ``free`` combinations the rows determine
    ``determined``; those left to the prior (words; the prior's source in words), the effects not
    separated, the pose families that would separate them."""

    determined: int
    free: int
    prior_source: str
    left_to_prior: tuple[str, ...]
    unseparated: tuple[Unseparated, ...]
    families: tuple[PoseFamily, ...]


@dataclass(frozen=True)
class LawConstant:
    """A proposed law's constant: one value per joint (equal when ``granularity`` is ``shared``),
    their standard deviations (None: not known), its unit."""

    name: str
    values: tuple[float, ...]
    std: tuple[float, ...] | None
    unit: str
    granularity: str


@dataclass(frozen=True)
class Law:
    """A proposed law outside the library: the formula, its constants, the cross-validated residual
    RMS before and after and the noise floor (mm), whether it explains the recording (else what
    remains, in words), the library's effects in its model and those it made redundant."""

    formula: str
    constants: tuple[LawConstant, ...]
    cv_before_mm: float | None
    cv_after_mm: float | None
    noise_floor_mm: float | None
    explained: bool
    remaining: str
    library_effects: tuple[str, ...] = ()
    library_effects_dropped: tuple[str, ...] = ()


@dataclass(frozen=True)
class SysId:
    """The mujoco.sysid re-fit of one MuJoCo parameter: start, value, 95% half-interval, unit."""

    parameter: str
    start: float
    value: float
    interval_95: float
    unit: str


@dataclass(frozen=True)
class Resimulation:
    """The MuJoCo machine re-simulated: position RMS before and after (um), the sysid re-fit."""

    before_um: float
    after_um: float
    sysid: SysId | None = None


@dataclass(frozen=True)
class Search:
    """How a discovery searched its nonlinear parameters (a screw's pitch, a warm-up's time
    constant, a lost count's step time) above ``threshold`` measurements: each grid scanned on a
    seeded subsample of ``subsample_rows`` of the ``rows`` rows, stratified in time, then confirmed
    and refined on every row (:meth:`calib.effects.search.LinearisedFit.search`); ``effects`` those
    searched so."""

    rows: int
    subsample_rows: int
    threshold: int
    effects: tuple[str, ...] = ()


@dataclass(frozen=True)
class Effects:
    """What discovery found beyond the geometry: the geometry alone's test and where its mismatch
    is (words), the effects named, every candidate's evidence, the cross-validated whitened RMS of
    the geometry alone and of the model chosen, what remains, the aliases, what the poses cannot
    separate, a proposed law, the MuJoCo re-simulation."""

    effects: tuple[EffectRow, ...]
    candidates: tuple[Candidate, ...]
    remaining: Remaining
    geometry_test: GeometryTest | None = None
    located: tuple[str, ...] = ()
    cv_whitened_rms_geometry: float | None = None
    cv_whitened_rms_chosen: float | None = None
    aliases: tuple[Alias, ...] = ()
    separation: Separation | None = None
    law: Law | None = None
    resimulation: Resimulation | None = None
    search: Search | None = None
    not_named: tuple[str, ...] = ()


@dataclass(frozen=True)
class Flagged:
    """Rows flagged (1-based data rows): every one (``rows``), those named gross before any fit
    (``gross``); whether the outlier test's rows and the gross rows were left out of the fit; the
    outlier test's verdict (words); the held-out position error after (mm) without and with the
    flagged rows. A discovery's: the rows that look bad, whether they say the model is wrong, the
    large residuals kept because their neighbours share them (``(where, rows)``), the rows in all.
    ``numbering``: how rows are numbered (words)."""

    rows: tuple[int, ...]
    gross: tuple[int, ...] = ()
    left_out: bool = False
    gross_left_out: bool = False
    outlier_verdict: str | None = None
    heldout_after_without_mm: float | None = None
    heldout_after_with_mm: float | None = None
    bad_rows: tuple[int, ...] = ()
    model_wrong: bool = False
    shared: tuple[tuple[str, tuple[str, ...]], ...] = ()
    total_rows: int | None = None
    numbering: str | None = None


@dataclass(frozen=True)
class CompensationTable:
    """Compensated commands for a sequence of targets: what was compensated and what not (why),
    a table (``columns``, ``rows`` of numbers; the correction columns in the joints' units)."""

    what: str
    compensated: tuple[str, ...]
    not_compensated: tuple[tuple[str, str], ...]
    columns: tuple[str, ...]
    rows: tuple[tuple[float, ...], ...]


@dataclass(frozen=True)
class Timing:
    """Wall time of the run (s) and of its stages ``(stage, s)``, in order."""

    total_s: float
    stages: tuple[tuple[str, float], ...] = ()


@dataclass(frozen=True)
class Outputs:
    """The files written ``(summary key, path)`` (:data:`OUTPUT_KEYS`); a discovery's kept law:
    whether ``--law`` asked for it, the file (None: no law proposed, nothing kept)."""

    files: tuple[tuple[str, str], ...] = ()
    law_asked: bool = False
    law_kept: str | None = None


@dataclass(frozen=True)
class Report:
    """One calibration's or discovery's report (``kind``: ``calibration`` or ``discovery``); a
    section is None where the summary has none of it."""

    kind: str
    source: Source
    verdict: Verdict
    fit: Fit | None
    truth: Truth | None
    parameters: Parameters | None
    determination: Determination | None
    implausible: Implausible
    heldout: Heldout | None
    frames: Frames | None
    effects: Effects | None
    flagged: Flagged
    compensation: CompensationTable | None = None
    warnings: tuple[str, ...] = field(default_factory=tuple)
    timing: Timing | None = None
    outputs: Outputs = field(default_factory=Outputs)

    def to_dict(self) -> dict:
        """The report as JSON-ready nested dicts and lists (field names as keys)."""
        return _plain(dataclasses.asdict(self))


def _plain(value):
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def report_kind(summary: dict) -> str:
    """``discovery`` for a summary of ``pipeline.discover`` (it says whether the data are
    ``explained``), else ``calibration``."""
    return "discovery" if "explained" in summary else "calibration"


def _finite(v) -> float | None:
    """``v`` as a float, None when missing or not finite."""
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _chain_word(robot: str) -> str:
    from calib.robots import ROBOTS

    entry = ROBOTS.get(robot)
    return getattr(entry.cls, "chain_word", "chain") if entry is not None else "chain"


def _source(s: dict, kind: str) -> Source:
    n = s.get("declared_noise")
    noise = None if not n else Noise(float(n.get("position_mm") or 0.0), float(n.get("orientation_rad") or 0.0),
                                      float(n.get("joint") or 0.0), str(n.get("distribution") or ""))
    recording = s.get("scenario", "") if kind == "calibration" else s.get("recording") or ""
    rows = s.get("rows") if kind == "discovery" else None
    return Source(robot=s["robot"], chain_word=_chain_word(s["robot"]), recording=str(recording),
                  rows=None if rows is None else int(rows), noise=noise, seed=s.get("seed"))


def _fit(s: dict) -> Fit | None:
    if s.get("method") is None:  # a calibration file alone: no run
        return None
    used = s.get("calibration_poses_used")
    return Fit(method=s["method"], solver=s.get("solver"), iterations=s.get("iterations"),
               converged=s.get("converged", s.get("success")), message=s.get("message") or "",
               history=tuple(s.get("max_dqint_history") or ()), condition_numbers=tuple(s.get("condition_numbers") or ()),
               rows=s.get("calibration_poses"), rows_used=used, heldout_poses=int(s.get("heldout_poses") or 0))


def _truth(s: dict) -> Truth | None:
    pe, g = s.get("parameter_error") or {}, s.get("gain_G_percent") or {}
    if not pe and not g:
        return None
    return Truth(pe.get("rms_mm"), pe.get("rms_rad"), g.get("mean"), g.get("norm"))


def _calibration_parameters(s: dict) -> Parameters | None:
    det = s.get("parameter_determination") or {}
    if not det:
        return None
    prior = s.get("prior") or {}
    tolerance = prior.get("tolerance") or {}
    implausible = {d["name"] for d in s.get("implausible_parameters") or ()}
    free = set(s.get("free_parameters") or det)
    rows = []
    for name, d in det.items():
        if name not in free:
            continue
        std = d.get("posterior_std")
        rows.append(ParameterRow(name=name, unit=d["unit"], value=d["value"], error=d["error"],
                                 two_sigma=None if std is None else 2.0 * std, tolerance=tolerance.get(name),
                                 source=d.get("source"), implausible=name in implausible))
    return Parameters(rows=tuple(rows), prior=prior.get("source") or "none",
                      left_to_prior=tuple(s.get("left_to_prior") or ()))


def _determination(s: dict) -> Determination | None:
    prior = s.get("prior")
    if prior is None or ("used" not in prior and not s.get("determined_by")):
        return None
    by = s.get("determined_by") or {}
    sp = s.get("suggested_poses")
    suggested = None if not sp else Suggested(int(sp.get("poses") or 0), sp.get("what", ""),
                                              s.get("suggested_poses_path", ""))
    return Determination(prior_used=bool(prior.get("used")), prior=prior.get("source") or "",
                         by_data=tuple(by.get("data") or ()), by_prior=tuple(by.get("prior") or ()),
                         directions=s.get("directions_determined"),
                         combinations=tuple(s.get("left_to_prior") or ()), suggested=suggested)


def _discovery_parameters(s: dict) -> Parameters | None:
    errors = s.get("identified_errors") or {}
    if not errors:
        return None
    imp = s.get("implausible_parameters") or {}
    std = s.get("identified_std") or {}
    tolerance = imp.get("tolerance") or {}
    units = s.get("parameter_units") or {}
    still = {d["name"] for d in imp.get("with_effects") or ()}
    rows = []
    for name in s.get("free_parameters") or errors:
        e = errors[name]
        sd = std.get(name)
        unit = units.get(name) or next((d["unit"] for d in (imp.get("geometry_alone") or ()) if d["name"] == name), "")
        rows.append(ParameterRow(name=name, unit=unit, value=None, error=e, two_sigma=None if sd is None else 2.0 * sd,
                                 tolerance=tolerance.get(name), source=None, implausible=name in still))
    return Parameters(rows=tuple(rows), prior=imp.get("tolerance_source") or "not stated")


def _implausible(s: dict, kind: str) -> Implausible:
    imp = s.get("implausible_parameters") or ({} if kind == "discovery" else [])
    if kind == "calibration":
        return Implausible(words=tuple(d["words"] for d in imp))
    return Implausible(words=tuple(imp.get("words") or ()),
                       with_effects=tuple(d["words"] for d in imp.get("with_effects") or ()))


def _per_pose(s: dict) -> tuple[PerPose, ...]:
    per = s.get("heldout_per_pose")
    if not per:
        return ()
    rows = tuple(per["rows"]) if per.get("rows") else None
    out = [PerPose("position", "mm", tuple(per["position_before_mm"]), tuple(per["position_after_mm"]),
                   rows if per.get("per") == "pose" else None)]
    if per.get("orientation_before_rad") is not None:
        out.append(PerPose("orientation", "rad", tuple(per["orientation_before_rad"]),
                           tuple(per["orientation_after_rad"]), rows))
    return tuple(out)


def _iso(s: dict) -> tuple[tuple[IsoPose, ...], str]:
    iso = s.get("iso9283")
    if not iso:
        return (), ""
    poses = tuple(IsoPose(tuple(p["rows"]), p["repeats"], p["AP_before_mm"], p["AP_after_mm"], p["RP_mm"])
                  for p in iso["poses"])
    return poses, f"{iso['standard']}; {iso['basis']}"


def _crossvalidation(s: dict) -> CrossValidation | None:
    info = s.get("crossvalidation")
    if not info:
        return None
    return CrossValidation(scheme=str(info.get("scheme", "")), fits=info.get("fits"), model=info.get("model"),
                           message=info.get("message", ""))


def _calibration_heldout(s: dict) -> Heldout | None:
    h, o = s.get("heldout_position_error_mm"), s.get("heldout_orientation_error_rad")
    if h:
        rows = [FigureRow("position", "mm", Figures.of(h["before_figures"]), Figures.of(h["after_figures"]))]
        if o:
            rows.append(FigureRow("orientation", "rad", Figures.of(o["before_figures"]), Figures.of(o["after_figures"])))
        iso, standard = _iso(s)
        return Heldout(basis=s.get("heldout_basis") or "", poses=int(s.get("heldout_poses") or 0), figures=tuple(rows),
                       per_pose=_per_pose(s), iso9283=iso, iso_standard=standard,
                       session_shifts=tuple(v["words"] for v in (s.get("session_shifts") or {}).values()))
    cv, info = s.get("crossvalidated_position_error_mm"), _crossvalidation(s)
    if not cv or cv.get("rms") is None or info is None:
        return None
    rows = [FigureRow("position", "mm", None, Figures.of(cv), crossvalidated=True)]
    o = s.get("crossvalidated_orientation_error_rad")
    if o and o.get("rms") is not None:
        rows.append(FigureRow("orientation", "rad", None, Figures.of(o), crossvalidated=True))
    return Heldout(basis=info.message, poses=int(s["crossvalidation"].get("rows_predicted") or 0), figures=tuple(rows),
                   crossvalidation=info)


def _discovery_heldout(s: dict) -> Heldout:
    before, after = s["heldout_rms_before_mm"], s["heldout_rms_after_mm"]
    per = s.get("heldout_per_row")
    if per:
        per_pose = (PerPose("closure", "mm", tuple(per["before_mm"]), tuple(per["after_mm"]), tuple(per["rows"])),)
        rows = [FigureRow("closure", "mm", Figures(before, per.get("before_mean_mm"), per.get("before_max_mm")),
                          Figures(after, per.get("after_mean_mm"), per.get("after_max_mm")))]
    else:
        per_pose, rows = (), [FigureRow("closure", "mm", Figures(before, None, None), Figures(after, None, None))]
    cv = s.get("crossvalidated_position_error_mm")
    info = None
    if cv and cv.get("rms") is not None:
        rows.append(FigureRow("position", "mm", Figures.of(cv), None, crossvalidated=True))
        info = _crossvalidation(s)
    shifts = tuple(v["words"] for v in (s.get("session_shifts") or {}).values())
    raw = s.get("heldout_rms_as_predicted_mm")
    return Heldout(basis=s.get("heldout_basis") or "", poses=len(per["rows"]) if per else 0, figures=tuple(rows),
                   per_pose=per_pose, noise_floor_mm=s.get("noise_floor_mm"), crossvalidation=info,
                   session_shifts=shifts,
                   as_predicted_mm=None if not raw else (raw["before"], raw["after"]))


def _frames(s: dict) -> Frames | None:
    def row(session, f, sd):
        return FrameRow(session, tuple(f["translation_mm"]), tuple(f["rotation_rad"]),
                        None if sd is None else tuple(sd["translation_mm"]),
                        None if sd is None else tuple(sd["rotation_rad"]))

    if s.get("measurement_frames"):
        stds = s.get("measurement_frames_std") or {}
        rows, sessions = tuple(row(k, f, stds.get(k)) for k, f in s["measurement_frames"].items()), True
    elif s.get("measurement_frame"):
        rows, sessions = (row("the recording", s["measurement_frame"], s.get("measurement_frame_std")),), False
    else:
        return None
    return Frames(rows=rows, held=tuple(s.get("measurement_frame_held") or ()), sessions=sessions)


def _coefficients(params: dict) -> tuple[Coefficient, ...]:
    return tuple(Coefficient(k, float(v["value"]), _finite(v.get("std")), v.get("unit", ""))
                 for k, v in params.items() if k not in ("significance", "granularity"))


def _aliases(s: dict) -> tuple[Alias, ...]:
    out = []
    for a in s.get("aliases") or ():
        nested = bool(a.get("nested"))
        threshold = None
        if nested:  # the discovery's own bound (loaded with the discovery that wrote the alias)
            from calib.effects.discovery import MIN_NESTED_DELTA_BIC

            threshold = float(MIN_NESTED_DELTA_BIC)
        out.append(Alias(named=a["named"], rival=a["rival"], delta_bic=float(a["delta_bic"]),
                         correlation=_finite(a.get("correlation")), nested=nested, nested_min_delta_bic=threshold))
    return tuple(out)


def _separation(s: dict) -> Separation | None:
    sep = s.get("separation")
    if not sep:
        return None
    unseparated = tuple(Unseparated(effect=u["effect"], form=u["form"], combination=u["combinations"][0]["combination"],
                                    geometry=u["combinations"][0]["geometry"], more=len(u["combinations"]) - 1,
                                    separated_by=tuple(u["separated_by"])) for u in sep["unseparated"])
    families = tuple(PoseFamily(family=k, reachable=v["reachable"], tried=v["tried"], determines=v["determines"],
                                separates=tuple(v["separates"])) for k, v in sep["poses"].items())
    return Separation(determined=sep["determined"], free=sep["free"], prior_source=sep["prior_source"],
                      left_to_prior=tuple(c["combination"] for c in sep["left_to_prior"]), unseparated=unseparated,
                      families=families)


def _law(law: dict | None) -> Law | None:
    if not law:
        return None
    stds, units = law.get("constants_std") or {}, law.get("units") or {}
    forms = law.get("constant_granularity") or {}
    constants = tuple(LawConstant(name=k, values=tuple(v), std=tuple(stds[k]) if stds.get(k) else None,
                                  unit=units.get(k, ""), granularity=forms.get(k, law.get("granularity", "shared")))
                      for k, v in law["constants"].items())
    return Law(formula=law["formula"], constants=constants, cv_before_mm=law.get("cv_rms_before_mm"),
               cv_after_mm=law.get("cv_rms_after_mm"), noise_floor_mm=law.get("noise_floor_mm"),
               explained=bool(law.get("explained_with_law")), remaining=law.get("remaining_with_law") or "",
               library_effects=tuple(law.get("library_effects") or ()),
               library_effects_dropped=tuple(law.get("library_effects_dropped") or ()))


def _search(s: dict) -> Search | None:
    x = s.get("search") or {}
    if x.get("form") != "subsample":
        return None
    return Search(rows=x["rows"], subsample_rows=x["subsample_rows"], threshold=x["threshold"],
                  effects=tuple(x.get("effects") or ()))


def _resimulation(s: dict) -> Resimulation | None:
    r = s.get("mujoco_resimulation")
    if not r:
        return None
    y = r.get("sysid")
    sysid = None if not y else SysId(y["parameter"], y["start"], y["value"], y["interval_95"], y["unit"])
    return Resimulation(r["before"]["position_um"], r["after"]["position_um"], sysid)


def _effects(s: dict) -> Effects:
    ev = s.get("evidence") or {}
    partial = set(s.get("partial") or ())
    rows = []
    for name in s.get("effects") or ():
        params = (s.get("effect_parameters") or {}).get(name, {})
        sig, e = params.get("significance") or {}, ev.get(name) or {}
        rows.append(EffectRow(name=name, granularity=str(params.get("granularity", "shared")),
                              coefficients=_coefficients(params), delta_bic_when_added=e.get("delta_bic_when_added"),
                              wald_chi2=sig.get("wald_chi2"), dof=sig.get("dof"), p_value=sig.get("p_value"),
                              cv_whitened_rms=e.get("cv_whitened_rms"), partial=name in partial))
    named = set(s.get("effects") or ())
    candidates = tuple(Candidate(c, (ev.get(c) or {}).get("delta_bic_vs_none"), (ev.get(c) or {}).get("cv_whitened_rms"),
                                 c in named) for c in s.get("candidates") or ())
    rem = s.get("remaining") or {}
    remaining = Remaining(present=bool(rem.get("present")), summary=rem.get("summary", ""), rms_mm=rem.get("rms_mm"),
                          noise_floor_mm=rem.get("noise_floor_mm"), noise_ratio=rem.get("noise_ratio"),
                          follows=tuple(rem.get("follows") or ()), chains=tuple(rem.get("chains") or ()))
    t = ev.get("geometry_chi2_test")
    test = None if not t else GeometryTest(t["chi2"], t["dof"], t["p_value"], t["alpha"])
    return Effects(effects=tuple(rows), candidates=candidates, remaining=remaining, geometry_test=test,
                   located=tuple((s.get("located") or {}).get("summary") or ()),
                   cv_whitened_rms_geometry=(ev.get("none") or {}).get("cv_whitened_rms"),
                   cv_whitened_rms_chosen=ev.get("cv_whitened_rms_chosen"), aliases=_aliases(s),
                   separation=_separation(s), law=_law(s.get("proposed_law")), resimulation=_resimulation(s),
                   search=_search(s), not_named=tuple(r["words"] for r in s.get("not_named") or ()))


def _flagged(s: dict, kind: str) -> Flagged:
    rows = tuple(s.get("flagged_poses") or ())
    g = s.get("gross_rows") or {}
    out = s.get("outliers") or {}
    common = dict(rows=rows, gross=tuple(g.get("rows") or ()), gross_left_out=bool(g.get("left_out")),
                  numbering=s.get("row_numbering"))
    if kind == "calibration":
        w, wo = s.get("with_flagged") or {}, s.get("without_flagged") or {}
        hw, hwo = w.get("heldout_position_error_mm"), wo.get("heldout_position_error_mm")
        return Flagged(**common, left_out=bool(out.get("left_out")), outlier_verdict=out.get("verdict"),
                       heldout_after_without_mm=hwo["after"] if hw and hwo else None,
                       heldout_after_with_mm=hw["after"] if hw and hwo else None)
    return Flagged(**common, left_out=bool(rows), bad_rows=tuple(out.get("bad_rows") or ()),
                   model_wrong=bool(out.get("model_wrong")),
                   shared=tuple((k, tuple(v)) for k, v in (out.get("shared") or {}).items()),
                   total_rows=s.get("rows"))


def _compensation(s: dict) -> CompensationTable | None:
    c = s.get("compensation")
    if not c:
        return None
    return CompensationTable(what=c.get("what", ""), compensated=tuple(c.get("compensated") or ()),
                             not_compensated=tuple((c.get("not_compensated") or {}).items()),
                             columns=tuple(c.get("columns") or ()), rows=tuple(tuple(r) for r in c.get("rows") or ()))


def _timing(s: dict) -> Timing | None:
    if s.get("wall_time_s") is None:
        return None
    return Timing(float(s["wall_time_s"]), tuple((k, float(v)) for k, v in (s.get("wall_time_split_s") or {}).items()))


def _outputs(s: dict) -> Outputs:
    return Outputs(files=tuple((k, str(s[k])) for k in OUTPUT_KEYS if s.get(k)), law_asked="law_kept" in s,
                   law_kept=s.get("law_kept"))


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
        verdict = Verdict(success, v.get("words"), v.get("cause"))
        parameters, heldout, effects = _calibration_parameters(s), _calibration_heldout(s), None
        fit, truth, determination = _fit(s), _truth(s), _determination(s)
    else:
        verdict = Verdict(bool(s["explained"]), s["verdict"], None)
        parameters, heldout, effects = _discovery_parameters(s), _discovery_heldout(s), _effects(s)
        fit = truth = determination = None
    return Report(kind=kind, source=_source(s, kind), verdict=verdict, fit=fit, truth=truth, parameters=parameters,
                  determination=determination, implausible=_implausible(s, kind), heldout=heldout, frames=_frames(s),
                  effects=effects, flagged=_flagged(s, kind), compensation=_compensation(s),
                  warnings=tuple(s.get("warnings") or ()), timing=_timing(s), outputs=_outputs(s))


def summary_document(summary: dict) -> dict:
    """What ``--summary-json`` writes: the summary's keys and, under :data:`REPORT_KEY`, its
    report (:meth:`Report.to_dict`)."""
    return {**summary, REPORT_KEY: build_report(summary).to_dict()}
