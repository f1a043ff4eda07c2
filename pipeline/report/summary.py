"""A calibration run's summary (the keys ``python -m pipeline.run --summary-json`` writes, documented
in docs/commands.md), written from its report: :func:`run_record` makes the report's
:class:`~pipeline.report.model.RunRecord` from the run's objects (what the summary holds beyond
the report's other sections), :func:`summary_keys` writes every key from the report. A
discovery's summary (``python -m pipeline.discover --summary-json``, a fleet's
``<machine>.discovery.json``) likewise: :func:`discovery_summary_keys` writes it from the
discovery's report and its :class:`~pipeline.report.model.DiscoveryRecord`
(:func:`pipeline.report.discovery.discovery_record` makes that one from the objects).
"""

from __future__ import annotations

from dataclasses import asdict

from calib.measurement import frame_to_dict
from calib.metrics import pose_error_norms
from calib.robust import GROSS_ALPHA

from .calibration import (gross_rows, heldout_figure_rows, heldout_keys, iso_keys, parameter_error, per_pose_keys,
                          frame_held_words)
from .model import (GrossStage, ImplausibleParameter, InstrumentFit, Outliers, PriorUsed, Report, RunRecord,
                    Simulation, Variant)

__all__ = ["run_record", "summary_keys", "discovery_summary_keys", "gross_stage", "gross_keys", "instrument_fit",
           "session_keys", "diagnosis_summary", "OUTLIER_TEST"]

#: What the outlier test after the fit is.
OUTLIER_TEST = ("closed-form leave-one-out (hat matrix, studentized deleted residuals, chi-square "
                "against the declared noise), forward model")


#: The summary keys of a run's files, in the order the summary lists them (the suggested poses'
#: command file is ``suggested_poses_path``; the summary JSON names itself nowhere).
RUN_FILES = ("rrd", "calibration", "suggested_poses_json", "csv", "json", "mjcf", "report")


def _named(table, values) -> tuple[tuple[str, float], ...]:
    return tuple(table.to_dict(values).items())


def run_record(inp, outcome, settings, *, truth, figures: dict | None, implausible: list[dict]) -> RunRecord:
    """The record of one calibration run (``inp``: its input, ``outcome``: what
    :func:`calib.identification.calibrate` found, ``settings``: its
    :class:`pipeline.workflows.calibration.RunSettings`; ``truth``: the true parameters in the fit's
    gauge or None; ``figures``: ``{"parameter_error", "gain_G_percent"}`` against it or None;
    ``implausible``: the implausible parameters, ``{"name", "error", "tolerance", "unit", "words"}``)."""
    ident, data = outcome.identification, outcome.data
    robot, result, table = inp.data.robot, ident.result, inp.data.robot.table
    free = result.free_names
    comparison = (None, None)
    if ident.result_kept is not None:
        comparison = (variant(robot, ident.result_all, list(ident.kept), outcome.heldout_with_flagged, truth, free),
                      variant(robot, ident.result_kept, list(ident.keep), outcome.heldout_without_flagged, truth, free))
    misfit = bool(ident.report is not None and ident.report.misfit)
    outliers = Outliers(test=OUTLIER_TEST, verdict=ident.outlier_verdict,
                        flagged_rows=tuple(int(inp.data.rows[i]) + 1 for i in ident.flagged_idx),
                        left_out=ident.left_out,
                        model_misfit=misfit, search=None if ident.report is None else ident.report.search)
    held = outcome.heldout
    return RunRecord(
        method=settings.method, solver=ident.solver,
        weighted=(settings.weighted or data.prior is not None) if settings.method == "chainwise" else True,
        declared_noise=inp.data.noise.to_dict(), parameter_units=tuple(zip(table.names, table.units)), free=tuple(free),
        fixed=tuple(n for n in table.names if n not in free),
        injected_errors=None if inp.injected is None else _named(table, inp.injected),
        identified_errors=_named(table, result.errors), identified_std=_named(table, result.std),
        parameter_error=None if figures is None else figures["parameter_error"],
        gain_percent=None if figures is None else figures["gain_G_percent"], message=result.message,
        chi2=result.chi2, dof=result.dof, outliers=outliers,
        gross=gross_stage(inp, ident), with_flagged=comparison[0], without_flagged=comparison[1],
        heldout_rows=None if inp.rec is None else tuple(int(r) + 1 for r in inp.rec.rows("validation")),
        heldout_targets=held is not None and held[0].shape[1] != robot.pose_dim,
        instrument=None if ident.instrument is None else instrument_fit(inp, ident.instrument),
        prior=prior_used(outcome), implausible=tuple(ImplausibleParameter(**d) for d in implausible),
        simulation=simulation(inp, settings) if inp.sim is not None else None)


def variant(robot, result, rows: list[int], held: tuple | None, truth, free) -> Variant:
    """One identification's outcome, for the with/without-flagged-rows comparison (``held``: its
    held-out errors before and after, or None; ``truth``: the true parameters, or None)."""
    return Variant(rows_used=len(rows), identified_errors=_named(robot.table, result.errors), chi2=result.chi2,
                   dof=result.dof, success=result.success, message=result.message,
                   heldout=() if held is None else heldout_figure_rows(robot, *held),
                   parameter_error=None if truth is None else parameter_error(robot, result.theta, truth, free))


def gross_stage(inp, ident) -> GrossStage | None:
    """The gross-row stage of a recording's run (None for a simulated run, which has none)."""
    from calib.identification import SessionSearch

    search = ident.gross
    if search is None:
        return None
    rows, left_out = gross_rows(inp, ident)
    return GrossStage(
        test="trimmed fits (random subsets and concentration steps), then rows beyond the chi-square "
             f"{1 - GROSS_ALPHA:g} quantile of their coordinates named gross",
        rows=tuple(rows), left_out=left_out, frame_estimated=bool(search.frame_estimated),
        success=bool(search.success), message=search.message,
        search=getattr(search, "search", "every row") if not isinstance(search, SessionSearch) else
        "; ".join(f"session {s + 1}: {one.search}" for s, one in enumerate(search.searches)))


def gross_keys(stage: GrossStage | None) -> dict | None:
    """Summary key ``gross_rows`` of :func:`gross_stage`."""
    return None if stage is None else dict(asdict(stage), rows=list(stage.rows))


def instrument_fit(inp, fit) -> InstrumentFit:
    """The instrument frame or target fit ``fit`` of a recording's run (``inp``: its input)."""
    sessions = {}
    if inp.n_sessions > 1:
        names = inp.data.session_names
        motion = {}
        for s in range(1, len(names)):
            m, sd = fit.session_motion(s, 0)
            motion[names[s]] = {"motion": frame_to_dict(m), "std": frame_to_dict(sd)}
        sessions = dict(session_frames={names[s]: d for s, d in fit.frames_dict().items()},
                        session_frames_std={names[s]: frame_to_dict(fit.frames_std[s]) for s in range(len(names))},
                        session_motion=motion)
    frame = {}
    if fit.frame_estimated:
        frame = dict(frame=fit.frame_dict(), frame_std=frame_to_dict(fit.frame_std),
                     frame_held=tuple(frame_held_words(fit)))
    if fit.targets is not None:
        frame.update(targets_mm=tuple(fit.targets.tolist()), targets_estimated=fit.targets_estimated)
    return InstrumentFit(notes=tuple(fit.notes), gauge=tuple(fit.gauge), **frame, **sessions)


def session_keys(fit: InstrumentFit) -> dict:
    """Summary keys of a recording with several sessions (``fit``: :func:`instrument_fit`): each
    session's instrument frame and its standard uncertainty, how each moved from the first (the
    gauge-free figure); empty with one session."""
    if fit.session_frames is None:
        return {}
    return {"measurement_frames": fit.session_frames, "measurement_frames_std": fit.session_frames_std,
            "session_motion": fit.session_motion}


def _instrument_keys(fit: InstrumentFit) -> dict:
    keys = {"method": "forward", "solver": "lm", "weighted": True, "measurement_notes": list(fit.notes),
            "measurement_gauge": list(fit.gauge)}
    if fit.frame is not None:
        keys.update(measurement_frame=fit.frame, measurement_frame_std=fit.frame_std,
                    measurement_frame_held=list(fit.frame_held))
    if fit.targets_mm is not None:
        keys.update(measurement_targets_mm=list(fit.targets_mm), measurement_targets_estimated=fit.targets_estimated)
    return keys | session_keys(fit)


def prior_used(outcome) -> PriorUsed:
    """The prior a calibration used beyond :class:`~pipeline.report.model.Determination`."""
    data, result = outcome.data, outcome.identification.result
    est = data.tolerance_estimate
    return PriorUsed(tolerance=None if data.prior is None else data.prior.tolerance_by_name(data.robot),
                     declared=data.tolerance_declared, learnt=None if est is None else est.summary(),
                     determination=result.determination(),
                     by_held=tuple(n for n, v in result.parameter_sources().items() if v == "held"))


def simulation(inp, settings) -> Simulation:
    """A simulated run's settling, its machine's options, how far the settled machine departs from
    its own kinematics (load, compliance, ...)."""
    robot, cal = inp.data.robot, inp.sim["cal"]
    options = {"gravity": settings.gravity, "payload_kg": settings.payload_kg, "stiffness": settings.stiffness,
               "friction": settings.friction}
    dep = cal.true_poses - robot.forward_kinematics(inp.actual, cal.commanded, initial=cal.true_poses)
    pos, ang = pose_error_norms(robot, dep)
    return Simulation(settle_steps={"mean": float(cal.steps.mean()), "max": int(cal.steps.max())}, options=options,
                      departure={"position_mm": {"mean": float(pos.mean()), "max": float(pos.max())},
                                 "orientation_rad": {"mean": float(ang.mean()), "max": float(ang.max())}})


def diagnosis_summary(diagnosis, inp) -> dict:
    """The diagnosis' summary with its gross rows as 1-based data rows of the recording."""
    out = diagnosis.summary()
    if "gross_rows" in out:
        out["gross_rows"] = [int(r) + 1 for r in out["gross_rows"]]
    return out


def _variant_keys(v: Variant | None) -> dict | None:
    if v is None:
        return None
    keys = {"rows_used": v.rows_used, "identified_errors": dict(v.identified_errors), "chi2": v.chi2, "dof": v.dof,
            "success": v.success, "message": v.message, "heldout_position_error_mm": None,
            "heldout_orientation_error_rad": None, "parameter_error": v.parameter_error}
    if v.heldout:
        keys.update(heldout_keys(v.heldout))
    return keys


def _parameter_keys(report: Report) -> dict:
    r, fit = report.run, report.fit
    return {"parameter_units": dict(r.parameter_units), "free_parameters": list(r.free),
            "fixed_parameters": list(r.fixed),
            "injected_errors": None if r.injected_errors is None else dict(r.injected_errors),
            "identified_errors": dict(r.identified_errors), "identified_std": dict(r.identified_std),
            "parameter_error": r.parameter_error, "gain_G_percent": r.gain_percent, "iterations": fit.iterations,
            "converged": fit.converged, "success": report.verdict.success, "message": r.message, "chi2": r.chi2,
            "dof": r.dof, "max_dqint_history": list(fit.history), "condition_numbers": list(fit.condition_numbers)}


def _flagged_keys(report: Report) -> dict:
    r = report.run
    o = r.outliers
    return {"row_numbering": report.flagged.numbering, "flagged_poses": list(report.flagged.rows),
            "outliers": {"test": o.test, "verdict": o.verdict, "flagged_rows": list(o.flagged_rows),
                         "left_out": o.left_out, "model_misfit": o.model_misfit, "search": o.search},
            "model_misfit": o.model_misfit, "gross_rows": gross_keys(r.gross),
            "with_flagged": _variant_keys(r.with_flagged), "without_flagged": _variant_keys(r.without_flagged),
            "warnings": list(report.warnings)}


def _heldout_keys(report: Report) -> dict:
    r, h = report.run, report.heldout
    if h is None or h.crossvalidation is not None:  # no held-out poses (cross-validated figures are their own keys)
        return {"heldout_basis": None, "heldout_position_error_mm": None, "heldout_orientation_error_rad": None}
    rows = None if r.heldout_rows is None else list(r.heldout_rows)
    return {"heldout_basis": h.basis, **heldout_keys(h.figures),
            "heldout_per_pose": per_pose_keys(h.per_pose, rows, r.heldout_targets), "iso9283": iso_keys(h.iso9283)}


def _prior_keys(report: Report) -> dict:
    r, det, p = report.run, report.determination, report.run.prior
    keys = {"prior": {"used": det.prior_used, "source": report.parameters.prior, "tolerance": p.tolerance,
                      "declared": p.declared, "learnt": p.learnt},
            "parameter_determination": p.determination,
            "determined_by": {"data": list(det.by_data), "prior": list(det.by_prior), "held": list(p.by_held)},
            "directions_determined": det.directions, "left_to_prior": list(report.parameters.left_to_prior),
            "implausible_parameters": [asdict(i) for i in r.implausible]}
    if r.simulation is not None:
        keys.update(settle_steps_per_pose=r.simulation.settle_steps, simulation=r.simulation.options,
                    kinematic_departure=r.simulation.departure)
    return keys


def _later_keys(report: Report) -> dict:
    """The keys of what the run's later steps found, its files and its wall time."""
    r = report.run
    keys = {} if r.checks is None else {"checks": r.checks}
    keys.update(r.crossvalidation or {})
    keys.update(diagnosis=r.diagnosis, success=report.verdict.success,
                verdict={"words": report.verdict.words, "cause": report.verdict.cause, "evidence": r.evidence})
    if r.session_shifts:
        keys["session_shifts"] = r.session_shifts
    if r.suggested_poses is not None:
        keys["suggested_poses"] = r.suggested_poses
    keys.update(observability=r.observability, rerun=r.drawn)
    files = dict(report.outputs.files, suggested_poses_json=r.suggested_poses_json)
    keys.update((k, files[k]) for k in RUN_FILES if files.get(k) is not None)
    suggested = report.determination.suggested
    if suggested is not None and suggested.path:
        keys["suggested_poses_path"] = suggested.path
    if report.timing is not None:
        keys.update(wall_time_s=report.timing.total_s, wall_time_split_s=dict(report.timing.stages))
    return keys


def summary_keys(report: Report) -> dict:
    """The run's summary (the same keys for every robot; docs/commands.md) from its ``report``
    (with its :class:`~pipeline.report.model.RunRecord`, files and timing)."""
    r, fit = report.run, report.fit
    keys = {"robot": report.source.robot, "scenario": report.source.recording, "method": r.method,
            "solver": r.solver, "weighted": r.weighted, "calibration_poses": fit.rows,
            "calibration_poses_used": fit.rows_used, "heldout_poses": fit.heldout_poses,
            "declared_noise": r.declared_noise, "seed": report.source.seed}
    keys.update(_parameter_keys(report))
    keys.update(_flagged_keys(report))
    keys.update(_heldout_keys(report))
    if r.instrument is not None:
        keys.update(_instrument_keys(r.instrument))
    keys.update(_prior_keys(report))
    keys.update(_later_keys(report))
    return keys


def _discovery_found_keys(report: Report) -> dict:
    """The discovery's keys of what it found, up to the MuJoCo re-simulation (its record's)."""
    r, h = report.discovery, report.discovery.heldout
    keys = {"robot": report.source.robot, "explained": report.verdict.success, "verdict": report.verdict.words,
            "remaining": r.remaining, "effects": list(r.effects), "partial": list(r.partial),
            "aliases": list(r.aliases), "candidates": list(r.candidates), "effect_parameters": r.effect_parameters,
            "heldout_rms_before_mm": h["heldout_rms_before_mm"], "heldout_rms_after_mm": h["heldout_rms_after_mm"],
            "noise_floor_mm": h["noise_floor_mm"], "heldout_basis": r.heldout_basis, "heldout_per_row": h["per_row"],
            "heldout_rms_as_predicted_mm": h["heldout_rms_as_predicted_mm"], "heldout_folds": h["heldout_folds"],
            "not_named": h["not_named"], "session_shifts": r.session_shifts,
            "flagged_poses": list(report.flagged.rows), "outliers": r.outliers, "tests": r.tests,
            "evidence": r.evidence, "identified_errors": r.identified_errors, "identified_std": r.identified_std,
            "parameter_units": r.parameter_units, "free_parameters": list(r.free_parameters),
            "declared_noise": r.declared_noise, "located": r.located, "rows": report.source.rows,
            "proposed_law": r.proposed_law, "search": r.search, "implausible_parameters": r.implausible,
            "time": r.time, "separation": r.separation}
    if r.simulated_truth is not None:
        keys["simulated_truth"] = r.simulated_truth
    keys.update(r.resimulated or {})
    return keys


def discovery_summary_keys(report: Report) -> dict:
    """A discovery's summary (``--summary-json``, a fleet's ``<machine>.discovery.json``; the keys
    docs/commands.md lists) from its ``report`` (with its
    :class:`~pipeline.report.model.DiscoveryRecord`, the read's findings, files and timing where
    they entered it)."""
    r, files = report.discovery, dict(report.outputs.files)
    keys = _discovery_found_keys(report)
    keys["wall_time_s"] = report.timing.total_s
    if r.read is not None:
        keys.update(r.read)
    if r.warnings is not None:
        keys["warnings"] = list(r.warnings)
    keys.update(r.crossvalidation or {})
    if "rrd" not in files:  # the files not written yet
        return keys
    keys.update((k, files[k]) for k in ("rrd", "calibration", "mjcf") if k in files)
    if report.outputs.law_asked:
        keys["law_kept"] = report.outputs.law_kept
    keys["recording"] = report.source.recording
    if "report" in files:
        keys.update(report=files["report"], compensation=r.compensation)
    return keys
