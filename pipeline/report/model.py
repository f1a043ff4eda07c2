"""The report of a calibration or a discovery: one typed model of its outcome, built from a
run's objects (:mod:`pipeline.report.calibration`) or a discovery's (:mod:`pipeline.report.discovery`),
in sections: the machine and recording, the verdict, how the fit ran,
the parameters and what determined them, the implausible ones, the held-out figures, the
instrument frames, the effects found, the flagged rows, the compensation, the warnings, the timing
and the files written.

The model holds figures, names and the sentences the analysis itself wrote (a verdict, a held-out
basis, a warning); it composes no words. :mod:`pipeline.report.text` words it (the
terminal summary, the Rerun markdown, the phrases of the HTML report), :mod:`pipeline.report.html`
lays it out as one HTML file, and :meth:`Report.to_dict` is its JSON form (the summary JSON's
``report_model``). Every figure keeps the summary's unit (mm, rad; um where the name says so).
"""

from __future__ import annotations

import dataclasses
import types
import typing
from dataclasses import dataclass, field

__all__ = ["Report", "Source", "Noise", "Verdict", "Fit", "Truth", "ParameterRow", "Parameters", "Suggested",
           "Determination", "Implausible", "Figures", "FigureRow", "PerPose", "IsoPose", "CrossValidation", "Heldout",
           "FrameRow", "Frames", "Coefficient", "EffectRow", "Candidate", "Remaining", "GeometryTest", "Alias",
           "Unseparated", "PoseFamily", "Separation", "LawConstant", "Law", "SysId", "Resimulation", "Search", "Effects",
           "Flagged", "CompensationTable", "Timing", "Outputs", "Variant", "Outliers", "GrossStage", "InstrumentFit",
           "PriorUsed", "ImplausibleParameter", "Simulation", "RunRecord", "DiscoveryRecord",
           "REPORT_KEY", "OUTPUT_KEYS"]

#: The key of the report model in a summary JSON (what ``--summary-json`` writes beside the summary's keys).
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


#: ``(name, value)`` of each parameter, in the robot's table order (a summary's ``{name: value}``).
Named = tuple[tuple[str, float], ...]


@dataclass(frozen=True)
class Variant:
    """One identification of a calibration's rows, for the with/without-flagged-rows comparison:
    the rows used, the identified errors from nominal, chi-square and degrees of freedom, whether
    it converged and the solver's message, the held-out figures (none: no held-out poses), the
    parameter error against a known truth (``rms_mm``, ``rms_rad``, ``max_abs_mm``,
    ``max_abs_rad``; None: unknown)."""

    rows_used: int
    identified_errors: Named
    chi2: float
    dof: int
    success: bool
    message: str | None
    heldout: tuple[FigureRow, ...] = ()
    parameter_error: dict | None = None


@dataclass(frozen=True)
class Outliers:
    """The outlier test after the fit: what it is (words), its verdict (words), the rows it flagged
    (1-based), whether they were left out, whether the residuals say the model misfits, how it
    searched (words; None: not searched)."""

    test: str
    verdict: str | None
    flagged_rows: tuple[int, ...]
    left_out: bool
    model_misfit: bool
    search: str | None


@dataclass(frozen=True)
class GrossStage:
    """The gross-row stage before any fit (a recording's): what it is (words), the rows named
    (1-based), whether they were left out, whether an instrument frame was inferred from the rest,
    whether the search succeeded and its message, how it searched (words)."""

    test: str
    rows: tuple[int, ...]
    left_out: bool
    frame_estimated: bool
    success: bool
    message: str
    search: str


@dataclass(frozen=True)
class InstrumentFit:
    """The instrument frame or target fit of a recording's run: its notes and gauge (words), the
    frame and its standard uncertainty (``{"translation_mm", "rotation_rad"}``; None: not
    estimated) and the components held (words), the targets (mm; None: poses measured) and
    whether they were estimated; with several sessions each session's frame, its standard
    uncertainty and its motion from the first (``{session: {"motion", "std"}}``; None: one)."""

    notes: tuple[str, ...]
    gauge: tuple[str, ...]
    frame: dict | None = None
    frame_std: dict | None = None
    frame_held: tuple[str, ...] = ()
    targets_mm: tuple | None = None
    targets_estimated: bool | None = None
    session_frames: dict | None = None
    session_frames_std: dict | None = None
    session_motion: dict | None = None


@dataclass(frozen=True)
class PriorUsed:
    """The prior of a calibration beyond :class:`Determination`: each parameter's tolerance (its
    unit; None: no prior), whether one was declared, the tolerance learnt from the rows (its
    summary; None: none learnt), per parameter what determined it (value, error, posterior std,
    source: :meth:`calib.engine.IdentificationResult.determination`), the parameters held."""

    tolerance: dict | None
    declared: bool
    learnt: dict | None
    determination: dict
    by_held: tuple[str, ...] = ()


@dataclass(frozen=True)
class ImplausibleParameter:
    """An identified error beyond its tolerance's multiple: its name, error and tolerance (its
    unit), the sentence."""

    name: str
    error: float
    tolerance: float
    unit: str
    words: str


@dataclass(frozen=True)
class Simulation:
    """A simulated run's machine: settle steps per pose (``{"mean", "max"}``), its options (gravity,
    payload, stiffness, friction), how far the settled machine departs from its own kinematics
    (``{"position_mm", "orientation_rad"}``, each ``{"mean", "max"}``)."""

    settle_steps: dict
    options: dict
    departure: dict


@dataclass(frozen=True)
class RunRecord:
    """What a calibration run's summary holds beyond the other sections (the keys
    :func:`pipeline.report.summary.summary_keys` writes from it): the settings (method, solver,
    weighting, seed, the declared noise), the parameters (units, free and fixed, injected,
    identified and their std), the figures against a known truth, the fit's chi-square, the outlier
    test, the gross-row stage, the with/without-flagged comparison, the held-out rows, the
    instrument fit, the prior, the implausible parameters, the simulation, and what the later
    steps found (checks, cross-validation, diagnosis, verdict evidence, session shifts, suggested
    poses, observability, the 3D drawing, the suggested poses' sidecar)."""

    method: str
    solver: str | None
    weighted: bool
    declared_noise: dict
    parameter_units: tuple[tuple[str, str], ...]
    free: tuple[str, ...]
    fixed: tuple[str, ...]
    injected_errors: Named | None
    identified_errors: Named
    identified_std: Named
    parameter_error: dict | None
    gain_percent: dict | None
    message: str | None
    chi2: float
    dof: int
    outliers: Outliers
    gross: GrossStage | None
    with_flagged: Variant | None
    without_flagged: Variant | None
    heldout_rows: tuple[int, ...] | None
    heldout_targets: bool
    instrument: InstrumentFit | None
    prior: PriorUsed
    implausible: tuple[ImplausibleParameter, ...]
    simulation: Simulation | None
    checks: dict | None = None
    crossvalidation: dict | None = None
    diagnosis: dict | None = None
    evidence: dict | None = None
    session_shifts: dict | None = None
    suggested_poses: dict | None = None
    observability: dict | None = None
    drawn: dict | None = None
    suggested_poses_json: str | None = None


@dataclass(frozen=True)
class DiscoveryRecord:
    """What a discovery's summary holds beyond the other sections (the keys
    :func:`pipeline.report.summary.discovery_summary_keys` writes from it), JSON-ready as the
    summary gives them: what remains, the effects named, partial and aliased, the candidates, the
    effect parameters placed by row, the held-out figures (``heldout``: the summary's
    ``heldout_*``, ``noise_floor_mm``, ``per_row``, ``not_named``) and their basis, the sessions
    shifted, the outliers, the tests and evidence, the identified errors, their std and units, the
    free parameters, the declared noise, where the residuals concentrate, the proposed law, the
    search, the implausible errors, the time's kind, the separation, a simulation's truth, the
    MuJoCo re-simulation's keys; then what the read found (its keys, warnings, cross-validation)
    and the compensation table."""

    remaining: dict
    effects: tuple[str, ...]
    partial: tuple[str, ...]
    aliases: tuple[dict, ...]
    candidates: tuple[str, ...]
    effect_parameters: dict
    heldout: dict
    heldout_basis: str | None
    session_shifts: dict
    outliers: dict
    tests: dict
    evidence: dict
    identified_errors: dict
    identified_std: dict
    parameter_units: dict
    free_parameters: tuple[str, ...]
    declared_noise: dict
    located: dict
    proposed_law: dict | None
    search: dict
    implausible: dict
    time: str
    separation: dict
    simulated_truth: dict | None
    resimulated: dict | None
    read: dict | None = None
    warnings: tuple[str, ...] | None = None
    crossvalidation: dict | None = None
    compensation: dict | None = None


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
    #: A calibration run's record of what its summary holds beyond the sections above (None: not a run's).
    run: RunRecord | None = None
    #: A discovery's record of what its summary holds beyond the sections above (None: not a discovery's).
    discovery: DiscoveryRecord | None = None

    def to_dict(self) -> dict:
        """The report as JSON-ready nested dicts and lists (field names as keys), but its ``run`` and
        ``discovery`` records: a summary JSON holds those as its own keys
        (:func:`pipeline.report.summary.summary_keys`,
        :func:`~pipeline.report.summary.discovery_summary_keys`), once."""
        plain = dataclasses.asdict(dataclasses.replace(self, run=None, discovery=None))
        del plain["run"], plain["discovery"]
        return _plain(plain)

    @classmethod
    def from_dict(cls, d: dict) -> "Report":
        """The report :meth:`to_dict` wrote (a summary JSON's :data:`REPORT_KEY`).

        Raises:
            KeyError, TypeError, ValueError: not such a report (a section or field missing or of
                another type).
        """
        return _typed(cls, d)


def _typed(kind, value):
    """``value`` (JSON-ready, as :func:`_plain` wrote it) as the type ``kind`` of a report's field."""
    if value is None:
        return None
    if dataclasses.is_dataclass(kind):
        if not isinstance(value, dict):
            raise TypeError(f"{kind.__name__}: expected an object, got {type(value).__name__}")
        hints = typing.get_type_hints(kind)
        return kind(**{f.name: _typed(hints[f.name], value[f.name]) for f in dataclasses.fields(kind) if f.name in value})
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (typing.Union, types.UnionType):
        return _typed(next(a for a in args if a is not type(None)), value)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise TypeError(f"expected a list, got {type(value).__name__}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_typed(args[0], v) for v in value)
        return tuple(_typed(a, v) for a, v in zip(args, value, strict=True))
    return value


def _plain(value):
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value
