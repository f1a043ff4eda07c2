"""The report of a calibration run (``python -m pipeline.run``), made from the run's objects: the
input it calibrated (:class:`pipeline.workflows.calibration.CalibrationInput`), the outcome of
:func:`calib.identification.calibrate` (:class:`calib.identification.CalibrationOutcome`), its
settings; then its files and timing once they are known (:func:`finished_report`).

The figures a run's summary and its report share (held-out errors, per pose, ISO 9283, the errors
against a known truth) are made here once: :func:`heldout_keys` and friends write the summary's
keys from the report's sections.
"""

from __future__ import annotations

from dataclasses import asdict, replace

import numpy as np

from calib.engine import integrated_error
from calib.metrics import iso9283_position, pose_error_norms, repeated_poses

from .model import (OUTPUT_KEYS, CrossValidation, Determination, FigureRow, Figures, Fit, Flagged, FrameRow, Frames,
                    Heldout, Implausible, IsoPose, Noise, Outputs, ParameterRow, Parameters, PerPose, Report, Source,
                    Suggested, Timing, Truth, Verdict)
from .verdict_words import verdict_sentence

__all__ = ["calibration_report", "calibration_file_report", "with_suggested", "without_file", "finished_report", "outputs_of", "ROW_NUMBERING", "NO_PRIOR", "ISO_STANDARD",
           "ISO_BASIS", "error_figures", "parameter_error", "heldout_figure_rows", "heldout_keys", "per_pose_rows",
           "per_pose_keys", "iso_poses", "iso_keys", "heldout_basis", "frame_held_words", "flagged_rows", "gross_rows",
           "fit_history", "prior_source", "left_to_prior_words"]

#: How every message, summary and view names a recording's rows.
ROW_NUMBERING = ("1-based data row of the recording, as a spreadsheet shows it below the header "
                 "(row k is file line k + 1)")
#: What the summary says of the prior with --no-prior.
NO_PRIOR = "none (--no-prior: plain least squares)"
#: What the ISO 9283 figures are, and what they are taken on.
ISO_STANDARD = ("ISO 9283: AP = distance from the barycentre of the attained positions to the command, "
                "RP = mean distance to the barycentre + 3 sample standard deviations")
ISO_BASIS = ("validation rows repeating one joint command; the command's position is the model's "
             "prediction at it (before: nominal, after: identified)")
#: A frame component this many times less certain than one measurement (its noise) is said to be
#: held by the geometry's tolerances, not determined by the poses.
FRAME_HELD_RATIO = 10.0


def error_figures(norms: np.ndarray) -> dict:
    """``{"rms", "mean", "max"}`` of per-pose error norms (N,)."""
    return {"rms": float(np.sqrt(np.mean(norms ** 2))), "mean": float(norms.mean()), "max": float(norms.max())}


def _figures(norms: np.ndarray) -> Figures:
    return Figures(**error_figures(norms))


def parameter_error(robot, identified: np.ndarray, true: np.ndarray, free) -> dict:
    """Identified minus true over the ``free`` parameters: ``rms_mm``, ``rms_rad``, ``max_abs_mm``,
    ``max_abs_rad`` (None where there is no length or no angle)."""
    idx = robot.table.indices(free)
    err = (identified - true)[idx]
    angle = robot.table.angle_mask()[idx]
    rms = lambda v: float(np.sqrt(np.mean(v ** 2))) if v.size else None  # noqa: E731
    return {"rms_mm": rms(err[~angle]), "rms_rad": rms(err[angle]),
            "max_abs_mm": float(np.abs(err[~angle]).max()) if (~angle).any() else None,
            "max_abs_rad": float(np.abs(err[angle]).max()) if angle.any() else None}


def target_norms(errors: np.ndarray) -> np.ndarray:
    """(N K,) the position error norm of each target and row of (N, 3K) target position errors."""
    return np.linalg.norm(errors.reshape(len(errors), -1, 3), axis=2).ravel()


def heldout_figure_rows(robot, before: np.ndarray, after: np.ndarray, targets: bool = False) -> tuple[FigureRow, ...]:
    """Held-out errors before and after (N, D) poses (``targets``: (N, 3K) target positions, one
    position error per target and row): position (mm) and, where the poses have angles,
    orientation (rad), RMS, mean and max of the per-pose norms."""
    if targets:
        return (FigureRow("position", "mm", _figures(target_norms(before)), _figures(target_norms(after))),)
    pb, ob = pose_error_norms(robot, before)
    pa, oa = pose_error_norms(robot, after)
    rows = [FigureRow("position", "mm", _figures(pb), _figures(pa))]
    if robot.angle_pose_mask.any():
        rows.append(FigureRow("orientation", "rad", _figures(ob), _figures(oa)))
    return tuple(rows)


def heldout_keys(rows: tuple[FigureRow, ...]) -> dict:
    """Summary keys ``heldout_position_error_mm`` and ``heldout_orientation_error_rad`` (None
    without angles) of :func:`heldout_figure_rows`: the mean before and after (``before``,
    ``after``), the largest after (``max_after``), and all three figures of each
    (``before_figures``, ``after_figures``: RMS, mean, max)."""
    def block(row):
        return {"before": row.before.mean, "after": row.after.mean, "max_after": row.after.max,
                "before_figures": asdict(row.before), "after_figures": asdict(row.after)}

    by = {row.quantity: block(row) for row in rows}
    return {"heldout_position_error_mm": by["position"], "heldout_orientation_error_rad": by.get("orientation")}


def per_pose_rows(robot, before: np.ndarray, after: np.ndarray, rows) -> tuple[PerPose, ...]:
    """Each held-out pose's position (mm) and orientation (rad) error norms before and after
    (with target data one position per target and row, not numbered); ``rows``: the poses'
    1-based data rows (None: simulated poses)."""
    rows = tuple(rows) if rows else None
    if before.shape[1] != robot.pose_dim:  # target positions: one norm per target and row
        return (PerPose("position", "mm", tuple(target_norms(before).tolist()), tuple(target_norms(after).tolist())),)
    pb, ob = pose_error_norms(robot, before)
    pa, oa = pose_error_norms(robot, after)
    out = [PerPose("position", "mm", tuple(pb.tolist()), tuple(pa.tolist()), rows)]
    if robot.angle_pose_mask.any():
        out.append(PerPose("orientation", "rad", tuple(ob.tolist()), tuple(oa.tolist()), rows))
    return tuple(out)


def per_pose_keys(per_pose: tuple[PerPose, ...], rows, targets: bool) -> dict:
    """Summary key ``heldout_per_pose`` of :func:`per_pose_rows` (``rows``: the data rows, or None;
    ``targets``: one norm per target and row)."""
    by = {p.quantity: p for p in per_pose}
    o = by.get("orientation")
    return {"position_before_mm": list(by["position"].before), "position_after_mm": list(by["position"].after),
            "orientation_before_rad": None if o is None else list(o.before),
            "orientation_after_rad": None if o is None else list(o.after), "rows": rows,
            "per": "target and row" if targets else "pose"}


def iso_poses(robot, before: np.ndarray, after: np.ndarray, val_joints, joint_std, rows) -> tuple[IsoPose, ...]:
    """ISO 9283 figures of the validation rows repeating a commanded pose (the same joints within
    the declared joint noise; :func:`calib.metrics.iso9283_position` on attained minus predicted
    positions, before with the nominal model, after with the identified one); ``rows``: their
    1-based data rows."""
    groups = repeated_poses(val_joints, joint_std)
    position = ~robot.angle_pose_mask
    zero = np.zeros((len(before), 3))
    b, a = (iso9283_position(e[:, position], zero, groups) for e in (before, after))
    return tuple(IsoPose(tuple(rows[i] for i in r), int(len(r)), float(apb), float(apa), float(rp))
                 for r, apb, apa, rp in zip(b.rows, b.accuracy, a.accuracy, a.repeatability))


def iso_keys(poses: tuple[IsoPose, ...]) -> dict | None:
    """Summary key ``iso9283`` of :func:`iso_poses` (None where no pose repeats)."""
    if not poses:
        return None
    return {"standard": ISO_STANDARD, "basis": ISO_BASIS,
            "poses": [{"rows": list(p.rows), "repeats": p.repeats, "AP_before_mm": p.ap_before,
                       "AP_after_mm": p.ap_after, "RP_mm": p.rp} for p in poses]}


def _instrument_basis(fit) -> str:
    """What the held-out errors of :func:`calib.identification.instrument_heldout` are."""
    what = "target positions" if fit.n_targets else "poses"
    return (f"recorded validation rows: measured {what} minus model prediction, instrument frame "
            "(includes sensor noise)")


def heldout_basis(inp, ident) -> str:
    """What the held-out errors are, in words (``inp``: the run's input, ``ident``: its identification)."""
    if ident.instrument is not None:
        return _instrument_basis(ident.instrument)
    if inp.sim is not None:
        return "simulated machine, compensated commands, noise-free settled poses (before: nominal commands)"
    return "recorded validation rows: measured minus model prediction (includes sensor noise)"


def frame_held_words(fit) -> list[str]:
    """The instrument frame's components the poses cannot separate from the geometry, in words:
    those whose standard uncertainty is over :data:`FRAME_HELD_RATIO` times one measurement's noise
    as the data show it (the spread of the fit's residuals, positions and angles; the declared
    noise may call angles exact) (with the tolerances as a prior the geometry's tolerance holds
    them; without, the gauge)."""
    std = np.asarray(fit.frame_std, dtype=float)
    names = ("x", "y", "z", "rotation about x", "rotation about y", "rotation about z")
    units = ("mm",) * 3 + ("rad",) * 3
    res = np.asarray(fit.result.pose_residuals, dtype=float)
    spread = np.nanstd(res, axis=0) if res.size else np.zeros(6)
    scale = np.r_[np.full(3, max(np.nanmax(spread[:3]) if spread.size >= 3 else 0.0, 1e-6)),
                  np.full(3, max(np.nanmax(spread[3:6]) if spread.size >= 6 else 0.0, 1e-9))]
    held = "the geometry's tolerances" if fit.result.prior is not None else "the gauge"
    return [f"frame {name}: std {std[k]:.3g} {units[k]}, not separated from the geometry by the poses: held by {held}"
            for k, name in enumerate(names) if std[k] > FRAME_HELD_RATIO * scale[k]]


def flagged_rows(inp, ident) -> list[int]:
    """The rows named gross or flagged, as 1-based data rows (:data:`ROW_NUMBERING`)."""
    return [int(inp.data.rows[i]) + 1 for i in ident.flagged_idx]


def gross_rows(inp, ident) -> tuple[list[int], bool]:
    """The rows the gross-row stage named (1-based data rows) and whether they were left out."""
    return ([int(inp.data.rows[i]) + 1 for i in ident.gross_idx],
            bool(ident.gross_idx) and len(ident.kept) < len(inp.data.measured))


def fit_history(robot, inp, ident, method: str) -> list[float]:
    """Max dQint per iteration (mm) of a chain-wise Gauss-Newton fit, else the final one's."""
    result, instrument = ident.result, ident.instrument
    if method == "chainwise" and ident.solver == "gn" and instrument is None:
        return list(result.history)
    residuals = result.pose_residuals if instrument is None else \
        ident.measured - robot.forward_kinematics(result.theta, inp.data.joints)
    return [float(integrated_error(robot, residuals)[2].max())]


def prior_source(data) -> str:
    """The prior a calibration used, in words (:data:`NO_PRIOR` without one)."""
    return data.tolerance_source if data.prior is not None else NO_PRIOR


def left_to_prior_words(outcome) -> list[str]:
    """The parameter combinations the rows left to the prior, each in words with its posterior std."""
    robot = outcome.data.robot
    return [c["combination"] + (f" ({robot.chain_word} {c['chain'] + 1})" if c["chain"] is not None else "")
            + f": posterior {c['std_ratio']:.2f} x the prior" for c in outcome.identification.result.left_to_prior()]


def _source_of(robot, recording: str, noise, seed) -> Source:
    n = noise.to_dict()
    declared = Noise(float(n.get("position_mm") or 0.0), float(n.get("orientation_rad") or 0.0),
                     float(n.get("joint") or 0.0), str(n.get("distribution") or ""))
    return Source(robot=robot.name, chain_word=robot.chain_word, recording=recording, noise=declared, seed=seed)


def _fit(inp, outcome, method: str) -> Fit:
    ident = outcome.identification
    result, instrument = ident.result, ident.instrument
    return Fit(method="forward" if instrument is not None else method,
               solver="lm" if instrument is not None else ident.solver, iterations=result.iterations,
               converged=result.success, message=result.message or "",
               history=tuple(fit_history(inp.data.robot, inp, ident, method)),
               condition_numbers=tuple(result.condition_numbers.tolist()), rows=int(len(inp.data.measured)),
               rows_used=int(ident.used.size), heldout_poses=0 if outcome.heldout is None else len(outcome.heldout[0]))


def _parameters(outcome, implausible: list[dict]) -> tuple[Parameters, Determination]:
    data, result = outcome.data, outcome.identification.result
    tolerance = {} if data.prior is None else data.prior.tolerance_by_name(data.robot)
    named = {d["name"] for d in implausible}
    free = set(result.free_names)
    det = result.determination()
    rows = tuple(ParameterRow(name=name, unit=d["unit"], value=d["value"], error=d["error"],
                              two_sigma=None if d["posterior_std"] is None else 2.0 * d["posterior_std"],
                              tolerance=tolerance.get(name), source=d["source"], implausible=name in named)
                 for name, d in det.items() if name in free or not free)
    left = tuple(left_to_prior_words(outcome))
    sources = result.parameter_sources()
    by = {src: tuple(n for n, v in sources.items() if v == src) for src in ("data", "prior")}
    determination = Determination(prior_used=data.prior is not None, prior=prior_source(data), by_data=by["data"],
                                  by_prior=by["prior"], directions=result.directions_determined(), combinations=left)
    return Parameters(rows=rows, prior=prior_source(data), left_to_prior=left), determination


def _heldout(inp, outcome, shift_words: tuple[str, ...]) -> Heldout | None:
    ident, held = outcome.identification, outcome.heldout
    robot = inp.data.robot
    if held is None:
        return _crossvalidated(outcome.crossvalidation)
    before, after = held
    instrument = ident.instrument
    targets = instrument is not None and instrument.targets is not None
    rows = None if inp.rec is None else [int(r) + 1 for r in inp.rec.rows("validation")]
    iso = ()
    if inp.rec is not None and before.shape[1] == robot.pose_dim:
        iso = iso_poses(robot, before, after, inp.data.validation_joints, inp.data.noise.joint_std, rows)
    return Heldout(basis=heldout_basis(inp, ident), poses=len(before),
                   figures=heldout_figure_rows(robot, before, after, targets),
                   per_pose=per_pose_rows(robot, before, after, rows), iso9283=iso,
                   iso_standard=f"{ISO_STANDARD}; {ISO_BASIS}" if iso else "", session_shifts=shift_words)


def _crossvalidated(cv) -> Heldout | None:
    if cv is None or not cv.position_summary or cv.position_summary.get("rms") is None:
        return None
    rows = [FigureRow("position", "mm", None, Figures.of(cv.position_summary), crossvalidated=True)]
    o = cv.orientation_summary
    if o and o.get("rms") is not None:
        rows.append(FigureRow("orientation", "rad", None, Figures.of(o), crossvalidated=True))
    info = CrossValidation(scheme=str(cv.scheme), fits=cv.fits, model=None, message=cv.message)
    return Heldout(basis=cv.message, poses=int(cv.rows_predicted or 0), figures=tuple(rows), crossvalidation=info)


def _frames(inp, fit) -> Frames | None:
    """The instrument frames of an instrument fit (``fit``; None: poses in the base frame)."""
    from calib.measurement import frame_to_dict

    def row(session, f, sd):
        return FrameRow(session, tuple(f["translation_mm"]), tuple(f["rotation_rad"]), tuple(sd["translation_mm"]),
                        tuple(sd["rotation_rad"]))

    if fit is None:
        return None
    held = tuple(frame_held_words(fit)) if fit.frame_estimated else ()
    if inp.n_sessions > 1:
        names = inp.data.session_names
        rows = tuple(row(names[s], f, frame_to_dict(fit.frames_std[s])) for s, f in fit.frames_dict().items())
        return Frames(rows=rows, held=held, sessions=True)
    if not fit.frame_estimated:
        return None
    return Frames(rows=(row("the recording", fit.frame_dict(), frame_to_dict(fit.frame_std)),), held=held)


def _flagged(inp, outcome) -> Flagged:
    ident = outcome.identification
    gross, gross_out = gross_rows(inp, ident) if ident.gross is not None else ([], False)
    without = with_ = None
    if ident.result_kept is not None and outcome.heldout_with_flagged is not None \
            and outcome.heldout_without_flagged is not None:
        with_, without = (float(pose_error_norms(inp.data.robot, h[1])[0].mean())
                          for h in (outcome.heldout_with_flagged, outcome.heldout_without_flagged))
    return Flagged(rows=tuple(flagged_rows(inp, ident)), gross=tuple(gross), left_out=bool(ident.left_out),
                   gross_left_out=gross_out, outlier_verdict=ident.outlier_verdict, heldout_after_without_mm=without,
                   heldout_after_with_mm=with_, numbering=ROW_NUMBERING)


def calibration_report(inp, outcome, *, method: str, seed: int, truth: dict | None, implausible: list[dict],
                       warnings, shift_words: tuple[str, ...] = ()) -> Report:
    """The report of one calibration, from its objects.

    Args:
        inp: the run's input (:class:`pipeline.workflows.calibration.CalibrationInput`).
        outcome: what :func:`calib.identification.calibrate` found.
        method, seed: the run's settings.
        truth: ``{"parameter_error", "gain_G_percent"}`` against a known truth (None: unknown).
        implausible: the implausible parameters (``{"name", "words", ...}`` each).
        warnings: the run's warnings, in words.
        shift_words: each validation session's shift, in words.
    """
    parameters, determination = _parameters(outcome, implausible)
    pe, gain = (truth or {}).get("parameter_error"), (truth or {}).get("gain_G_percent")
    verdict = outcome.verdict
    return Report(kind="calibration", source=_source_of(inp.data.robot, str(inp.scenario), inp.data.noise, seed),
                  verdict=Verdict(bool(verdict.success), verdict_sentence(verdict), verdict.cause),
                  fit=_fit(inp, outcome, method),
                  truth=None if truth is None else Truth(pe["rms_mm"], pe["rms_rad"], gain.get("mean"), gain.get("norm")),
                  parameters=parameters, determination=determination,
                  implausible=Implausible(words=tuple(d["words"] for d in implausible)),
                  heldout=_heldout(inp, outcome, shift_words), frames=_frames(inp, outcome.identification.instrument),
                  effects=None, flagged=_flagged(inp, outcome), warnings=tuple(warnings))


#: The prior a calibration file alone names (the file keeps no tolerance).
FILE_PRIOR = "not stated in the calibration file"


def calibration_file_report(cal) -> Report:
    """The report of a calibration file alone (:class:`calib.calibration.Calibration`): the machine,
    the recording it names, every free parameter with its standard uncertainty, the instrument
    frames, the declared noise; no verdict (``success`` and ``words`` None: the run's summary holds
    it, with the held-out figures and flagged rows)."""
    from calib.measurement import frame_to_dict

    table = cal.robot.table
    free = set(cal.free)
    rows = tuple(ParameterRow(name=n, unit=table.units[k], value=float(cal.theta[k]),
                              error=float(cal.theta[k] - table.nominal[k]), two_sigma=2.0 * float(cal.std[k]),
                              tolerance=None, source=None if n in free else "held", implausible=False)
                 for k, n in enumerate(table.names) if n in free or not free)
    frames = None
    if cal.frames:
        frames = Frames(rows=tuple(FrameRow(name, tuple(d["translation_mm"]), tuple(d["rotation_rad"]), None, None)
                                   for name, d in ((s, frame_to_dict(f)) for s, f in cal.frames.items())),
                        sessions=True)
    recording = str(cal.recording.get("name") or cal.recording.get("simulated") or "")
    return Report(kind="calibration", source=_source_of(cal.robot, recording, cal.noise, None),
                  verdict=Verdict(None, None), fit=None, truth=None,
                  parameters=Parameters(rows=rows, prior=FILE_PRIOR), determination=None, implausible=Implausible(),
                  heldout=None, frames=frames, effects=None, flagged=Flagged(rows=()))


def with_suggested(report: Report, suggested: dict) -> Report:
    """``report`` with the poses suggested to determine what the rows left to the prior
    (``suggested``: ``{"poses", "what"}``, the summary's ``suggested_poses``; their file is named
    by :func:`finished_report`)."""
    found = Suggested(int(suggested["poses"]), suggested["what"], "")
    return replace(report, determination=replace(report.determination, suggested=found))


def outputs_of(paths: dict) -> Outputs:
    """The files a run wrote, ``paths`` by summary key (:data:`~pipeline.report.model.OUTPUT_KEYS`, in their order)."""
    return Outputs(files=tuple((k, str(paths[k])) for k in OUTPUT_KEYS if paths.get(k)))


def without_file(report: Report, key: str) -> Report:
    """``report`` without the file of summary key ``key`` among its outputs."""
    return replace(report, outputs=replace(report.outputs, files=tuple(f for f in report.outputs.files if f[0] != key)))


def finished_report(report: Report, paths: dict, wall_time_s: float, split: dict) -> Report:
    """``report`` with the files the run wrote (``paths`` by summary key; ``suggested_poses`` the
    suggested poses' file) and its wall time, in total and by stage (``split``, s)."""
    determination = report.determination
    if determination is not None and determination.suggested is not None and paths.get("suggested_poses"):
        determination = replace(determination,
                                suggested=replace(determination.suggested, path=str(paths["suggested_poses"])))
    return replace(report, determination=determination, outputs=outputs_of(paths),
                   timing=Timing(float(wall_time_s), tuple((k, float(v)) for k, v in split.items())))
