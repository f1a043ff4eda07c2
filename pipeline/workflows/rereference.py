"""``python -m pipeline.run --real TODAY.csv --from CAL.calibration.json``: a calibration
re-referenced to a later session, as a library function.

:func:`run_rereference` reads the calibration held (``--from``) and the session's recording
(``--real``), refuses a calibration of another robot or nominal geometry, a recording without
calibration rows, several sessions or target data (one line each, nothing written), calls
:func:`calib.rereference.rereference` (the geometry and effects held, the joint zeros and/or the
instrument frame estimated from the calibration rows, chosen by evidence) and writes the session's
calibration ``NAME.calibration.json`` (``rereferenced_from``: the held file's path and SHA-256)
and, when asked, the summary JSON. :func:`summary_lines` is the summary for the terminal.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.calibration import CALIBRATION_SUFFIX
from calib.measurement import measurement_settings
from calib.rereference import MIN_REREFERENCE_ROWS, Rereference, check_same_machine, held_frame, rereference
from calib.robot import KinematicsError
from pipeline.formats import (NameReservation, ResultSet, calibration_text, check_plausible_parameters, output_folder,
                              read_calibration, read_recording, recording_source, row_message, session_measurement)

__all__ = ["RereferenceSettings", "RereferenceResult", "run_rereference", "summary_lines", "PRODUCED_BY"]

#: The command a re-referenced calibration names as its producer.
PRODUCED_BY = "pipeline.run --from"


@dataclass(frozen=True)
class RereferenceSettings:
    """What :func:`run_rereference` does (``python -m pipeline.run --help``: ``--real``, ``--from``,
    ``--out``, ``--name``, ``--overwrite``, ``--summary-json``)."""

    real: Path
    calibration: Path
    out: Path = Path("recordings")
    name: str | None = None
    overwrite: bool = False
    summary_json: Path | None = None


@dataclass
class RereferenceResult:
    """What a re-reference produced: the summary (JSON-ready), the library's result, the paths written."""

    summary: dict
    rereference: Rereference
    paths: dict


def _held(path: Path):
    if not path.is_file():
        raise ValueError(f"--from {path}: " + ("is a folder, not a calibration file" if path.is_dir()
                                               else "file not found"))
    cal = read_calibration(path)
    check_plausible_parameters(cal, path)
    return cal


def _session(rec, where: str) -> str:
    """The recording's one session (refusing several: each would have its own shift)."""
    if len(rec.session_names) > 1:
        raise ValueError(f"{where}, column 'session': sessions {', '.join(map(repr, rec.session_names))}: --from "
                         "re-references one session (each session re-homed has its own shift): give one session's rows")
    return rec.session_names[0]


def _inputs(settings: RereferenceSettings):
    """The held calibration and the recording, checked (every refusal before anything is written)."""
    cal = _held(Path(settings.calibration))
    rec = read_recording(settings.real)
    where = str(settings.real)
    check_same_machine(cal, rec.robot, f"--from {settings.calibration}")
    if measurement_settings(rec.meta.get("measurement")).n_targets or cal.targets is not None:
        raise ValueError(f"{where if cal.targets is None else '--from ' + str(settings.calibration)}: target positions "
                         "(meta.measurement.targets): --from re-references full poses")
    session = _session(rec, where)
    if not len(rec.rows("calibration")):
        raise ValueError(f"{where}, column 'set': no calibration rows: --from estimates the session's shift from its "
                         f"calibration rows (at least {MIN_REREFERENCE_ROWS} poses spread over the workspace)")
    return cal, rec, session


def _rows(rec, name: str) -> tuple:
    k = rec.rows(name)
    return rec.joints[k], rec.measured[k], rec.t_s[k], {c: v[k] for c, v in rec.extras.items()}


def run_rereference(settings: RereferenceSettings) -> RereferenceResult:
    """Re-reference ``settings.calibration`` to the recording ``settings.real`` (module docstring).

    Raises:
        ValueError: bad input, one line naming the file, key, column or flag (nothing written).
        FileExistsError: an output exists and ``overwrite`` is off.
    """
    t0 = time.perf_counter()
    cal, rec, session = _inputs(settings)
    base = session_measurement(rec, session).frame == "base"
    joints, measured, t_s, channels = _rows(rec, "calibration")
    origin = {"path": str(settings.calibration),
              "sha256": hashlib.sha256(Path(settings.calibration).read_bytes()).hexdigest()}
    try:
        rr = rereference(cal, joints, measured, rec.noise, session=session,
                         frame_session=None if base else held_frame(cal, session), t_s=t_s, channels=channels,
                         origin=origin, recording=recording_source(settings.real), produced_by=PRODUCED_BY)
    except KinematicsError as exc:
        raise ValueError(row_message(exc, settings.real, rec.rows("calibration"))) from None
    try:
        rr = rr.with_validation(*_rows(rec, "validation"))
    except KinematicsError as exc:
        raise ValueError(row_message(exc, settings.real, rec.rows("validation"))) from None
    out = Path(settings.out)
    output_folder(out)
    base_name = settings.name if settings.name is not None else Path(settings.real).stem + "_rereferenced"
    reservation = NameReservation(out, base_name, explicit=settings.name is not None, overwrite=settings.overwrite,
                                  extensions=(CALIBRATION_SUFFIX,))
    try:
        targets = {"calibration": out / f"{reservation.name}{CALIBRATION_SUFFIX}"}
        if settings.summary_json is not None:
            targets["summary_json"] = Path(settings.summary_json)
        paths = {k: str(v) for k, v in targets.items()}
        summary = {"robot": cal.robot.name, "recording": str(settings.real), "session": session,
                   "rereference": rr.to_dict(), "calibration": paths["calibration"],
                   "joint_unit": cal.robot.joint_unit, "wall_time_s": time.perf_counter() - t0}
        with ResultSet(targets, overwrite=settings.overwrite,
                       flags={"calibration": "--out", "summary_json": "--summary-json"}) as outputs:
            outputs.temp("calibration").write_text(calibration_text(rr.calibration))
            if "summary_json" in targets:
                outputs.temp("summary_json").write_text(json.dumps(summary, indent=1))
            outputs.publish()
    finally:
        reservation.release()
    return RereferenceResult(summary=summary, rereference=rr, paths=paths)


def _figure_line(label: str, block: dict, floor: dict) -> str:
    before, after = block["before"], block["after"]
    if before is None:
        return f"{label}: none"
    p0, p1 = before["position_mm"], after["position_mm"]
    text = (f"{label} ({after['rows']}): position error mean {p0['mean']:.3g} -> {p1['mean']:.3g} mm, max "
            f"{p0['max']:.3g} -> {p1['max']:.3g} mm, RMS {p1['rms']:.3g} mm against a noise floor of "
            f"{floor['position_mm']:.3g} mm")
    if after["orientation_rad"] is not None:
        o0, o1 = before["orientation_rad"], after["orientation_rad"]
        text += (f"; orientation mean {o0['mean']:.3g} -> {o1['mean']:.3g} rad, max {o0['max']:.3g} -> "
                 f"{o1['max']:.3g} rad (floor {floor['orientation_rad']:.3g} rad)")
    return text


def summary_lines(summary: dict) -> list[str]:
    """The re-reference's summary (:func:`run_rereference`'s) in plain words, for the terminal."""
    r = summary["rereference"]
    shift, origin = r["shift"], r["rereferenced_from"]
    evidence = shift["log_evidence"]
    lines = [f"Re-referenced {origin['path']} (SHA-256 {origin['sha256'][:12]}...) to {summary['recording']}, "
             f"session {summary['session']!r}, read in {r['frame_source']}",
             f"Shift chosen by evidence: {shift['model']} (log evidence against none: "
             f"{evidence[shift['model']] - evidence['none']:+.3g} nats; {shift['rows']} calibration rows; "
             f"p(no shift) = {shift['p_no_shift']:.3g})"]
    for name, v in shift["shift"].items():
        lines.append(f"  {name}: {v['value']:+.4g} +- {v['std']:.2g} {v['unit']}")
    lines += [f"warning: {w}" for w in r["warnings"]]
    floor = r["noise_floor"]
    lines.append(_figure_line("Calibration rows", r["calibration_rows"], floor))
    lines.append(_figure_line("Validation rows", r["validation_rows"], floor))
    lines.append(f"Wrote {summary['calibration']} ({np.round(r['seconds'], 3)} s of work)")
    return lines
