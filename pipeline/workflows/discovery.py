"""Discovery of the physics a robot's geometric model left out, as a library function.

Calibrates the geometry, locates where the residuals concentrate, names the left-out effects
(up to three together) from the registry of physical candidates (:mod:`calib.effects`;
``candidates`` narrows it), fits them jointly with the geometry, says first whether what remains
is consistent with the declared noise and, if not, what it is, where and what it follows; shows
the held-out fit improve, and re-simulates the MuJoCo machine with the effects added (their own
:meth:`~calib.effects.Effect.machine_settings`), re-fitting a physical parameter there with
``mujoco.sysid``. The policy (which rows, the held-out judgement, the re-discoveries, the
calibration found) is calib's (:func:`calib.discovery.discover_machine`); here are the recording's
edge, the MuJoCo witness and the files. :func:`run_discovery` does what ``python -m pipeline.discover``
does (a recording or a seeded scenario in, the ``.rrd``, the calibration and the summary out);
:func:`discover` analyses a recording in memory. Its report is :mod:`pipeline.report.discovery`'s,
its summary written from that report (:func:`pipeline.report.summary.discovery_summary_keys`), a
kept law's file :mod:`.kept_law`'s. Nothing here depends on the robot or the effect.
"""

from __future__ import annotations

import contextlib
import io
import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from calib.discovery import HELDOUT_FRACTION, DiscoveryOutcome, DiscoveryRows, MotionlessRows, discover_machine
from calib.effects import Discovery
from calib.effects.base import PAYLOAD_CHANNEL
from calib.effects.session_zeros import SessionZeros
from calib.effects.heldout import HeldoutJudgement, RejectedEffect
from calib.compensation import compensated_commands
from calib.crossval import crossvalidate
from calib.diagnosis import motionless_rows
from mjcf.simulator import SettleError
from pipeline.formats import (CALIBRATION_SUFFIX, Calibration, Recording, atomic_write, check_outputs, output_folder, read_recording, recording_checks, recording_source, write_calibration)
from pipeline.report import REPORT_KEY, Report, write_report
from pipeline.report.discovery import (calibration_session_shifts, discovery_report, placed_by_row, row_order,
                                       with_files, with_read)
from pipeline.report.summary import discovery_summary_keys
from pipeline.report.text import shift_words, verdict_words
from pipeline.simulation import effect_recording, effects_settings, machine_context, merged_settings, simulate
from pipeline.simulation.mjcf_export import export_mjcf
from pipeline.report.verdict_words import no_motion_words

from .calibration import IMPLAUSIBLE_TOLERANCES, implausible_parameters, machine_tolerance, read_as_a_run_does
from .kept_law import KEPT_LAW_NAME, keep_law, kept_law_effect, read_kept_law

__all__ = ["DiscoverySettings", "DiscoveryReport", "run_discovery", "discover", "resimulate",
           "RESIMULATION_SETTLE_VELOCITY", "DEFAULT_SCENARIO_ROBOT", "KEPT_LAW_NAME", "keep_law", "read_kept_law",
           "kept_law_effect"]


#: At rest to 1e-7 m/s (or rad/s) is ample for micrometre comparisons (the settled pose is then
#: within about 1e-10 m), and several times faster than the testbed's default.
RESIMULATION_SETTLE_VELOCITY = 1e-7


@dataclass
class DiscoveryReport:
    """What :func:`discover` found.

    Attributes:
        discovery: the discovery judged (its ``outcome``'s).
        summary: the JSON written by ``--summary-json``.
        outcome: the discovery policy's outcome (:class:`calib.discovery.DiscoveryOutcome`).
        recording: the recording analysed (as read: poses in the base frame).
        calibration: what the discovery found, as a calibration file holds it.
        report: the report of it (:class:`pipeline.report.Report`): of the summary so far, and
            of every file written once :func:`run_discovery` has written them.
    """

    discovery: Discovery
    summary: dict
    outcome: DiscoveryOutcome | None = None
    recording: Recording | None = None
    calibration: Calibration | None = None
    report: Report | None = None


def _with(settings: dict, section: str, field: str, value: float) -> dict:
    out = {k: dict(v) for k, v in settings.items()}
    out[section][field] = value
    return out


def resimulate(rec: Recording, disc: Discovery, *, sysid: bool = True, max_nfev: int = 5,
               sysid_rows: int = 20, seed: int = 0) -> dict:
    """Re-simulate the recorded commands on MuJoCo machines and compare with the recording.

    Before: the machine with the geometry identified alone. After: the machine with the
    geometry identified jointly with the named effects, and their physics added (their
    ``machine_settings``, together: :func:`pipeline.simulation.effects_settings`); the first
    named effect that names a physical parameter (``physical_parameter``: servo stiffness,
    friction force, drift rate) has it re-fitted in MuJoCo with ``mujoco.sysid`` (confidence
    interval from its Jacobian). The transmission
    effects (scale, screw) enter the joints directly, so their calib-level fit already is the
    machine's parameter and they are simulated as fitted. The re-fit uses at most
    ``sysid_rows`` rows (every row for an effect that depends on the motion history, such as
    friction), since each evaluation re-simulates them.

    Returns:
        JSON-ready dict: task-space RMS of simulated minus recorded poses (um for positions,
        urad for angles), before and after, the machine settings and the re-fitted parameter
        with its 95% interval.
    """
    robot = rec.robot
    rows = disc.kept
    angle = robot.angle_pose_mask
    meas = rec.measured[rows]
    context = machine_context(robot, rec.meta.get("moving_mass_kg"))

    def rms(sim):
        d = meas - sim
        return {"position_um": float(1e3 * np.sqrt(np.mean(np.sum(d[:, ~angle] ** 2, axis=1)))),
                "orientation_urad": float(1e6 * np.sqrt(np.mean(np.sum(d[:, angle] ** 2, axis=1))))}

    out = {"before": rms(replay(rec, disc.geometry.theta, merged_settings(context), rows))}
    if not disc.effects:
        out["after"] = out["before"]
        return out
    fit = disc.chosen
    sl = fit.slices()
    settings = effects_settings(robot, context, [(m, fit.coefficients[sl[m.name]], e)
                                                 for m, e in zip(fit.models, fit.extras)])
    rec = rehomed(rec, fit)  # a re-homing is in the readings: each session's joints moved by its zeros
    after = replay(rec, fit.theta, settings, rows)
    out["after_calib_fit"] = rms(after)
    # The first named effect that carries a machine parameter is re-fitted there.
    eff, param = next(((m, m.physical_parameter(robot)) for m in fit.models if m.physical_parameter(robot)),
                      (None, None))
    if sysid and param is not None:
        settings, out["sysid"] = sysid_refit(rec, fit.theta, settings, eff, param, rows, max_nfev=max_nfev,
                                             sysid_rows=sysid_rows, seed=seed)
        after = replay(rec, fit.theta, settings, rows)
    out["after"] = rms(after)
    out["machine"] = {section: {k: (list(v) if isinstance(v, tuple) else v) for k, v in values.items()}
                      for section, values in settings.items()}
    return out


def rehomed(rec: Recording, fit) -> Recording:
    """``rec`` with each later session's joints moved by the zeros a named
    :class:`calib.effects.session_zeros.SessionZeros` found (``rec`` itself without one)."""
    for m in fit.models:
        if isinstance(m, SessionZeros):
            zeros = m.zeros(fit.coefficients[fit.slices()[m.name]], rec.robot)
            moved = rec.joints.copy()
            for session, d in zeros.items():
                moved[rec.sessions == session] += d
            return replace(rec, joints=moved)
    return rec


def replay(rec: Recording, theta: np.ndarray, settings: dict, which: np.ndarray, history: bool = True) -> np.ndarray:
    """(len(which), D) the true poses of the MuJoCo machine ``theta`` with ``settings`` commanded the
    recording's joints at its times, rows ``which``: the whole record replayed in order (the state
    may depend on the motion history) or, without ``history``, those rows alone."""
    kw = dict(settle_velocity=RESIMULATION_SETTLE_VELOCITY)
    payload = rec.extras.get(PAYLOAD_CHANNEL)  # a recording at several payloads: each row's own
    if not history:
        return simulate(rec.robot, theta, rec.joints[which], settings, times_s=rec.t_s[which],
                        payload_kg=None if payload is None else payload[which], **kw).true_poses
    return simulate(rec.robot, theta, rec.joints, settings, times_s=rec.t_s, payload_kg=payload, **kw).true_poses[which]


def sysid_refit(rec: Recording, theta: np.ndarray, settings: dict, eff, param, rows: np.ndarray, *, max_nfev: int,
                sysid_rows: int, seed: int) -> tuple[dict, dict]:
    """Re-fit the machine parameter ``param`` of effect ``eff`` with ``mujoco.sysid`` on at most
    ``sysid_rows`` seeded rows (every row for an effect that depends on the motion history):
    ``(settings with the value found, JSON-ready report with its 95% interval)``."""
    import mujoco.sysid as sysid_mod

    name, hist = param.field, eff.history_dependent
    std = rec.noise.pose_std(rec.robot.pose_units)
    sub = rows if hist or rows.size <= sysid_rows else np.sort(
        np.random.default_rng(seed).choice(rows, sysid_rows, replace=False))
    meas_sub = rec.measured[sub]
    start = settings[param.section][name]
    per_joint = np.ndim(start) > 0  # one value per joint: one common scale of them is re-fitted

    def value_of(x: float):
        return tuple(float(v) * x for v in start) if per_joint else x

    x0 = 1.0 if per_joint else float(start)
    low, high = (x0 / 10, x0 * 10) if x0 > 0 else (-10 * abs(x0) - 1e-9, 10 * abs(x0) + 1e-9)
    params = sysid_mod.ParameterDict({name: sysid_mod.Parameter(name, x0, low, high)})

    def residual_fn(x, _params):
        sim = replay(rec, theta, _with(settings, param.section, name, value_of(float(x[0]))), sub, history=hist)
        return [((meas_sub - sim) / std).ravel()], None, None

    with contextlib.redirect_stdout(io.StringIO()):  # the scipy backend prints its iterations
        opt, res = sysid_mod.optimize(params, residual_fn, optimizer="scipy", verbose=False,
                                      max_iters=max_nfev, diff_step=1e-3, x_scale="jac")
    xs = float(np.ravel(opt[name].value)[0])
    r_star = residual_fn(np.array([xs]), opt)[0]
    _, intervals = sysid_mod.calculate_intervals(r_star, res.jac)
    report = {"parameter": name + (" (a common scale of the per-joint values)" if per_joint else ""),
              "unit": "1" if per_joint else param.unit, "start": x0, "value": xs,
              "interval_95": float(np.ravel(intervals)[0]), "evaluations": int(res.nfev), "rows": int(sub.size)}
    xs = value_of(xs)
    return _with(settings, param.section, name, xs), report


def witnessed(outcome: DiscoveryOutcome, resimulated: dict) -> tuple[DiscoveryOutcome, dict]:
    """``(outcome, resimulation block)`` after the MuJoCo re-simulation's word: where the machine
    with the effects named fits the recording worse than the machine with the geometry alone, the
    effects are reported (both figures) and not named: the discovery falls back to the geometry
    alone (:meth:`calib.discovery.DiscoveryOutcome.geometry_alone`), whose re-simulation is the one
    already made."""
    disc = outcome.discovery
    sim = resimulated.get("mujoco_resimulation")
    if not disc.effects or sim is None or sim["after"]["position_um"] <= sim["before"]["position_um"]:
        return outcome, resimulated
    before, after = 1e-3 * sim["before"]["position_um"], 1e-3 * sim["after"]["position_um"]
    rejected = tuple(RejectedEffect(n, disc.evidence.delta_bic_when_added(n), before, after,
                                    "MuJoCo re-simulation", "worse re-simulated") for n in disc.effects)
    kept = {"before": sim["before"], "after": sim["before"], "wall_time_s": sim.get("wall_time_s"),
            "with_effects_not_named": {k: v for k, v in sim.items() if k != "wall_time_s"}}
    return outcome.geometry_alone(rejected), {"mujoco_resimulation": kept}


def discover(rec: Recording, *, seed: int = 0, heldout_fraction: float = HELDOUT_FRACTION, resim: bool = True,
             sysid: bool = True, candidates=None, exclude=(), kept_law: dict | None = None,
             frames: tuple[dict, dict] = ({}, {}), source: dict | None = None) -> DiscoveryReport:
    """Run the whole discovery on a recording (see the module docstring): the policy
    (:func:`calib.discovery.discover_machine`), the MuJoCo re-simulation's word, the summary and
    the calibration.

    Args:
        rec: the recording.
        seed: seed of the held-out split and of the cross-validation folds.
        heldout_fraction: rows held out when the recording has no ``validation`` rows.
        resim, sysid: re-simulate on the MuJoCo machine, and re-fit there with ``mujoco.sysid``.
        candidates: effect names (or :class:`calib.effects.Effect` objects) to consider; default
            every effect that applies to the robot.
        exclude: 0-based rows left out of every fit (the gross rows a run named); the motion
            history still counts them.
        kept_law: a law kept from an earlier recording (:func:`read_kept_law`'s data): one more
            candidate effect, called :data:`KEPT_LAW_NAME`, its constants refitted here.
        frames: ``({session: (6,) frame}, {session: (6,) std})`` the read of ``rec`` registered
            (the calibration's instrument frames; empty: the poses were in the base frame).
        source: the recording the calibration names (:func:`pipeline.formats.recording_source`).

    The recording's extra channels (``rec.extras``: a temperature) are quantities a proposed law
    may use.

    The summary's ``flagged_poses`` and ``outliers.bad_rows`` are 1-based data rows of the
    recording (the first measurement is row 1).

    Raises:
        ValueError: the rows analysed never move the machine (in words).
    """
    t0 = time.perf_counter()
    robot = rec.robot
    tolerance, tolerance_source = machine_tolerance(robot, rec.meta, "the recording's sidecar")
    rows = DiscoveryRows(robot, rec.joints, rec.measured, rec.t_s, rec.noise, rec.sets, rec.sessions, rec.extras)
    try:
        outcome = discover_machine(rows, tolerance=tolerance, seed=seed, heldout_fraction=heldout_fraction,
                                   candidates=candidates, exclude=exclude,
                                   kept_law=None if kept_law is None else kept_law_effect(kept_law, rec))
    except MotionlessRows as exc:
        raise ValueError(f"{no_motion_words(exc.rows, robot.name)}: nothing to discover") from None
    resimulated = None
    if resim:  # the second witness: an effect whose MuJoCo machine fits worse is not presented as found
        resimulated = resimulation_block(rec, outcome.discovery, sysid, seed)
        outcome, resimulated = witnessed(outcome, resimulated)
    parts = discovery_parts(rec, outcome)
    wall = time.perf_counter() - t0
    calibration = outcome.calibration(frames=frames[0], frames_std=frames[1], recording=source or {})
    report = discovery_report(rec, outcome, **parts, prior_source=tolerance_source, resimulated=resimulated,
                              wall_time_s=wall)
    return DiscoveryReport(discovery=outcome.discovery, summary=discovery_summary_keys(report), outcome=outcome,
                           recording=rec, calibration=calibration, report=report)


def discovery_parts(rec: Recording, outcome: DiscoveryOutcome) -> dict:
    """What the summary and the report of a discovery both hold, made once from its objects: the
    verdict in words, the implausible errors (:func:`implausibility`), the effect parameters placed
    by row (:func:`placed_by_row`), the sessions shifted (``{session: {..., words}}``)."""
    disc, judgement, robot = outcome.discovery, outcome.judgement, rec.robot
    return {"verdict": verdict_words(disc.explained, list(disc.effects), disc.remaining.to_dict()),
            "implausible": implausibility(rec, disc),
            "effect_parameters": placed_by_row(disc.chosen.parameters(), rec, disc.kept, row_order(rec)),
            "session_shifts": {s: dict(shift.to_dict(), words=shift_words(s, shift, robot.joint_unit))
                               for s, shift in judgement.shifts.items() if shift.shifted}
            | calibration_session_shifts(rec, disc.chosen)}


def implausibility(rec: Recording, disc: Discovery) -> dict:
    """The identified errors beyond three tolerances (the sidecar's ``meta.parameter_tolerance`` or
    the robot's default) with the geometry alone and with the effects found, and those the effects
    bring back within tolerance: a geometry that had absorbed physics."""
    robot = rec.robot
    tolerance, source = machine_tolerance(robot, rec.meta, "the recording's sidecar")
    names = robot.free_default
    alone = implausible_parameters(robot, disc.geometry.errors, tolerance, names)
    with_effects = implausible_parameters(robot, disc.chosen.errors, tolerance, names)
    still = {d["name"] for d in with_effects}
    back = [d for d in alone if d["name"] not in still]
    k = {n: robot.table.index(n) for n in names}
    words = [f"{d['name']}: {d['error']:+.4g} {d['unit']} with the geometry alone, "
             f"{disc.chosen.errors[k[d['name']]]:+.4g} {d['unit']} with {', '.join(disc.effects) or 'no effect'}: back "
             f"within {IMPLAUSIBLE_TOLERANCES:g} tolerances ({d['tolerance']:.4g} {d['unit']})" for d in back]
    return {"tolerance_source": source, "tolerance": tolerance.tolerance_by_name(robot),
            "geometry_alone": alone, "with_effects": with_effects,
            "back_within_tolerance": [d["name"] for d in back], "words": words}


def resimulation_block(rec: Recording, disc: Discovery, sysid: bool, seed: int) -> dict:
    """``mujoco_resimulation`` (:func:`resimulate`, with its wall time), or why it is skipped: a kept
    law has no MuJoCo machine field."""
    if KEPT_LAW_NAME in disc.effects:
        return {"mujoco_resimulation_skipped": f"{KEPT_LAW_NAME} has no MuJoCo machine field (a law, not in the library)"}
    t1 = time.perf_counter()
    out = resimulate(rec, disc, sysid=sysid, seed=seed)
    out["wall_time_s"] = time.perf_counter() - t1
    return {"mujoco_resimulation": out}


#: The robot of a scenario that names none.
DEFAULT_SCENARIO_ROBOT = "hexapod"


@dataclass(frozen=True)
class DiscoverySettings:
    """What :func:`run_discovery` does (``python -m pipeline.discover --help`` describes each field).

    Attributes:
        real: recording to analyse (``.csv`` with its ``.json`` sidecar); or None with ``scenario``.
        scenario: effect names of a seeded simulated recording of ``robot`` (None with ``real``).
        robot: the scenario's robot (default :data:`DEFAULT_SCENARIO_ROBOT`); with ``real``, the
            robot the file must be of (None: the one its sidecar names).
        scenario_seed: seed of the scenario recording.
        scenario_granularity: ``shared`` (one value of each effect for every joint) or ``per_chain``
            (each joint its own, 0.3 to 1.0 times the largest).
        candidates: effect names narrowing the library (None: every effect that applies).
        seed: seed of the held-out split and cross-validation folds.
        resim, sysid: re-simulate on the MuJoCo machine; re-fit there with ``mujoco.sysid``.
        out, name: folder and base name of the ``.rrd`` (default ``<recording>_discover``).
        overwrite: allow replacing existing outputs.
        summary_json: write the summary as JSON there.
        law_out: keep the proposed law in this JSON file (:func:`keep_law`).
        use_law: a kept law's file: one more candidate effect (:data:`KEPT_LAW_NAME`, refitted).
        export_mjcf: write the identified machine, with the effects MuJoCo can hold, as an MJCF file
            there (:func:`pipeline.simulation.mjcf_export.export_mjcf`).
        report: write the report a lab keeps there (HTML, :func:`pipeline.formats.write_report`).
    """

    real: Path | None = None
    scenario: tuple[str, ...] | None = None
    robot: str | None = None
    scenario_seed: int = 0
    scenario_granularity: str = "shared"
    candidates: tuple[str, ...] | None = None
    seed: int = 0
    resim: bool = True
    sysid: bool = True
    out: Path = Path("recordings")
    name: str | None = None
    overwrite: bool = False
    summary_json: Path | None = None
    law_out: Path | None = None
    use_law: Path | None = None
    export_mjcf: Path | None = None
    report: Path | None = None


def geometry_crossvalidation(rec: Recording, read, seed: int) -> dict:
    """The cross-validated prediction error of a recording without validation rows, as
    ``pipeline.run --real`` reports it for its forward fit (leave-one-out, the default prior): the
    geometry alone, on the rows the run would use (the gross rows left out), base frame."""
    rows = np.setdiff1d(np.arange(len(rec.sets)), read.gross_rows)
    cv = crossvalidate(rec.robot, rec.joints[rows], rec.measured[rows], rec.noise, method="forward",
                       prior=machine_tolerance(rec.robot, rec.meta, "the recording's sidecar")[0], seed=seed)
    out = cv.summary()
    out["crossvalidation"]["model"] = "the geometry alone (forward fit with the tolerances as prior)"
    return out


def discover_in_words(rec: Recording, settings: DiscoverySettings, read, source: dict) -> DiscoveryReport:
    """:func:`discover` with its numerical failures said as causes, naming the file: a singular
    fit (the rows do not determine geometry and effects together), a re-simulation that does not
    settle. ``read``: the recording as a run read it (its gross rows and instrument frames), or
    None (a scenario); ``source``: the recording the calibration names.

    Raises:
        ValueError: the cause in words.
    """
    where = settings.real if settings.real is not None else "the scenario recording"
    try:
        return discover(rec, seed=settings.seed, resim=settings.resim, sysid=settings.sysid,
                        candidates=settings.candidates, exclude=() if read is None else read.gross_rows,
                        kept_law=None if settings.use_law is None else read_kept_law(settings.use_law),
                        frames=({}, {}) if read is None else (read.frames, read.frames_std), source=source)
    except np.linalg.LinAlgError:
        raise ValueError(f"{where}: the rows do not determine the geometry and the candidate effects together "
                         "(a singular fit: too few distinct poses, or a machine that barely moved); measure poses "
                         "spread over the workspace") from None
    except SettleError as exc:
        raise ValueError(f"{where}: the MuJoCo re-simulation did not settle ({exc}); the identified machine may be "
                         "implausible; rerun with --no-resim") from None


def run_discovery(settings: DiscoverySettings) -> DiscoveryReport:
    """Read (or simulate) the recording, check every output before the analysis (which can take
    a minute with re-simulation), :func:`discover`, write the ``.rrd`` (and the summary JSON).

    Raises:
        ValueError: neither or both of ``real`` and ``scenario``; a recording of another robot
            than ``robot``; a file that cannot be read (the message names it).
        FileExistsError: an output exists and ``overwrite`` is off.
    """
    if (settings.real is None) == (settings.scenario is None):
        raise ValueError("give one of a recording (--real) and a scenario (--scenario)")
    read = None
    if settings.real is not None:
        rec = read_recording(settings.real)
        stem = Path(settings.real).stem
        warnings = recording_checks(rec, settings.real).warnings  # the checks every command reading a recording makes
        still = motionless_rows(rec.robot, rec.joints, rec.noise.joint_std)
        if still is not None:  # no geometry, so no physics, to tell from one pose
            raise ValueError(f"{settings.real}: {no_motion_words(still, rec.robot.name, 'rows')}: nothing to discover")
    else:
        robot_name = settings.robot or DEFAULT_SCENARIO_ROBOT
        stem = f"{robot_name}_{'+'.join(settings.scenario)}_{settings.scenario_seed}"
        rec = None
    out = Path(settings.out)
    rrd_path = out / f"{settings.name or f'{stem}_discover'}.rrd"
    calibration_path = out / f"{settings.name or f'{stem}_discover'}{CALIBRATION_SUFFIX}"
    output_folder(out)
    check_outputs({"--out": rrd_path, "--out (calibration file)": calibration_path,
                   "--summary-json": settings.summary_json, "--law": settings.law_out,
                   "--export-mjcf": settings.export_mjcf, "--report": settings.report}, overwrite=settings.overwrite)
    if rec is None:
        rec = effect_recording(settings.scenario, settings.scenario_seed, robot=robot_name,
                               granularity=settings.scenario_granularity)
    robot = rec.robot
    if settings.robot is not None and robot.name != settings.robot:
        raise ValueError(f"{settings.real} is a recording of the {robot.name}, not of the {settings.robot} (--robot)")
    if settings.use_law is not None:  # a bad or another robot's file refused before the analysis
        read_kept_law(settings.use_law, robot.name)
    if settings.real is not None:  # as pipeline.run --real reads it: gross rows named, instrument frame taken out
        read = read_as_a_run_does(settings.real, rec, seed=settings.seed)
        rec = read.recording
    source = recording_source(settings.real) if settings.real is not None else \
        {"name": None, "simulated": f"scenario {'+'.join(settings.scenario)}, seed {settings.scenario_seed}, "
                                    f"{settings.scenario_granularity}"}
    report = discover_in_words(rec, settings, read, source)
    if read is not None:
        cv = None if np.any(rec.sets == "validation") else geometry_crossvalidation(rec, read, settings.seed)
        report.report = with_read(report.report, read.block, warnings, cv)
        report.summary = discovery_summary_keys(report.report)
    return write_discovery_files(report, settings, rrd_path, calibration_path,
                                 recording=str(settings.real) if settings.real is not None else source["simulated"],
                                 law_source=str(settings.real or stem))


def write_discovery_files(report: DiscoveryReport, settings: DiscoverySettings, rrd_path: Path, calibration_path: Path,
                          *, recording: str, law_source: str) -> DiscoveryReport:
    """Write what ``settings`` asks of ``report`` (the ``.rrd``, the calibration; the MJCF, the kept
    law, the summary JSON, the HTML report where asked), each named in its summary and report
    (``recording``: the recording in words; ``law_source``: where a kept law was found)."""
    from pipeline.views import write_discovery_rrd  # Rerun for the file alone: the analysis and its words load none

    rec, cal, overwrite = report.recording, report.calibration, settings.overwrite
    files = {"rrd": str(write_discovery_rrd(rrd_path, rec.robot, rec, report, overwrite=overwrite))}
    files["calibration"] = str(write_calibration(calibration_path, cal, overwrite=overwrite))
    if settings.export_mjcf is not None:
        files["mjcf"] = str(export_mjcf(cal, settings.export_mjcf, overwrite=overwrite))
    law_kept = None
    if settings.law_out is not None:
        kept = keep_law(settings.law_out, dict(report.summary, source=law_source), overwrite=overwrite)
        law_kept = None if kept is None else str(kept)
    compensation = None
    if settings.report is not None:
        files["report"] = str(settings.report)
        compensation = compensation_table(rec, cal, report.outcome.judgement)
    report.report = with_files(report.report, recording=recording, files=files, law_asked=settings.law_out is not None,
                               law_kept=law_kept, compensation=compensation)  # every file named
    report.summary = discovery_summary_keys(report.report)
    if settings.summary_json is not None:
        atomic_write(settings.summary_json, json.dumps({**report.summary, REPORT_KEY: report.report.to_dict()},
                                                       indent=1), overwrite=overwrite)
    if settings.report is not None:
        write_report(report.report, settings.report, overwrite=overwrite)
    return report


#: Targets of the report's compensation table at most (the first held-out rows, in order).
COMPENSATION_TARGETS = 20


def compensation_table(rec: Recording, cal: Calibration, judgement: HeldoutJudgement) -> dict | None:
    """The summary's ``compensation`` (for the report): the commands ``pipeline.compensate`` gives
    for the first :data:`COMPENSATION_TARGETS` held-out rows' measured poses as targets, commanded in
    the recording's order at its times (:func:`calib.compensation.compensated_commands` with the
    calibration's effects): per target its data row, the pose and each joint's physics correction
    (command minus the geometry's joint, joint unit), what was compensated and what not (why).
    None without an effect found, or where the identified machine cannot reach the targets."""
    if not cal.effects:
        return None
    robot = rec.robot
    rows = np.asarray([int(i) for i in judgement.fold.held[:COMPENSATION_TARGETS]], dtype=int)
    channels = {k: v[rows] for k, v in rec.extras.items()}
    try:
        comp = compensated_commands(robot, cal.theta, rec.measured[rows], cal.fitted_effects(channels),
                                    t_s=rec.t_s[rows], channels=channels)
    except ValueError:  # KinematicsError: a target out of reach of the identified machine
        return None
    correction = comp.commands - comp.geometric
    unit = robot.joint_unit
    return {"what": f"commands for the first {rows.size} held-out rows' measured poses as targets, in the recording's "
                    f"order and times: each joint's correction for the physics found (command minus the identified "
                    f"geometry's joint, {unit})",
            "compensated": list(comp.compensated), "not_compensated": dict(comp.left_out),
            "columns": ["row", *robot.pose_names[:3], *(f"{j} correction, {unit}" for j in robot.joint_names)],
            "rows": [[int(r) + 1, *rec.measured[r, :3].tolist(), *correction[k].tolist()] for k, r in enumerate(rows)]}
