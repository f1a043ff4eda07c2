"""A lab's export checked on evidence before it is written as a recording: the converted poses and
joints are fitted to the nominal machine as the map reads them and as the map would read them
with one key changed, by the diagnosis ``pipeline.run`` makes (:func:`calib.diagnosis.compare_readings`,
the fits and the rule of :func:`calib.diagnosis.diagnose`).

The rows judged are a seeded subsample of the rows kept (:class:`pipeline.formats.lab_export.LabSample`,
at most about :data:`pipeline.formats.lab_export.CHECK_ROWS`; every row of a smaller export), as the
lab wrote them. The other readings (:func:`map_readings`) are the mapping file re-read with one key
changed, those rows converted again through it: ``position.unit`` (m, mm, in), ``joints.unit`` (and a
session's own ``sessions.NAME.joints.unit``: metres for mm, degrees for rad...),
``orientation.unit`` (deg, rad), ``orientation.sequence`` (fixed axes for moving ones),
``orientation.scalar`` (first, last), ``orientation.order`` (row, column), ``orientation.rotation``
(the inverse rotation: a quaternion's conjugate), and ``orientation.columns`` with two of the
rotation's vector columns exchanged (a quaternion's x and y). Building them from the map (not by
transforming the converted data) is what lets a message name the key.

Verdicts (:func:`lab_checks`): a key is **refused** (:class:`LabExportError`, one line naming the
map, the key as written and the value that fits, with both figures) when the data as the map
reads them do not fit the machine (or fit only with a parameter moved implausibly far) and
with that key changed they fit plausibly, by :func:`calib.diagnosis.diagnose`'s evidence.
Otherwise a **warning** with the figures when the evidence is weak: the data fit as read and
with a key changed as well (too few rows to tell), a reading fits where the data as read do not
without the evidence that names it, or nothing fits (the run will diagnose). Nothing that fits
as read is refused.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from calib.robot import KinematicsError

from .lab_export import ANGLE_UNITS, LENGTH_UNITS, ROTATION_DIRECTIONS, LabExportError, LabMap, LabSample
from .recording import Recording, row_frame_groups

__all__ = ["MapReading", "map_readings", "lab_checks", "TOO_FEW_ROWS"]

#: How :func:`calib.measurement.identify_measured` says rows are too few to identify the unknowns.
TOO_FEW_ROWS = "rows to identify"


@dataclass(frozen=True, eq=False)
class MapReading:
    """The mapping file with one key changed.

    Attributes:
        key: the key (``"position.unit"``, ``"sessions.feb12.joints.unit"``).
        written: its value as the map has it (its default where the map leaves it out).
        value: the value tried instead.
        lab_map: the map with ``key = value``.
        only: the sessions whose rows the key converts (None: every session but ``besides``).
        besides: sessions the key leaves alone (their own mapping sets it).
    """

    key: str
    written: object
    value: object
    lab_map: LabMap
    only: tuple | None = None
    besides: tuple = ()

    @property
    def name(self) -> str:
        return f"{self.key} = {self.value!r}"


def _with(lab_map: LabMap, edit) -> LabMap:
    tables = copy.deepcopy(lab_map.tables)
    edit(tables)
    return LabMap(path=lab_map.path, robot=lab_map.robot, noise=lab_map.noise, tables=tables)


def _set(table: str, key: str, value):
    def edit(tables):
        tables[table][key] = value
    return edit


def _joint_readings(lab_map: LabMap) -> list[MapReading]:
    """Other units of ``[joints]`` (the sessions that keep its unit follow it) and of each
    session's own ``[sessions.NAME.joints]`` unit."""
    units = LENGTH_UNITS if lab_map.robot.joint_unit == "mm" else ANGLE_UNITS
    base = lab_map.tables["joints"]["unit"]
    own = lab_map.tables["sessions"].get("joints", {})
    follow = tuple(n for n, spec in own.items() if spec["unit"] == base)
    out = []
    for u in units:
        if u == base:
            continue

        def edit(tables, u=u):
            tables["joints"]["unit"] = u
            for n in follow:
                tables["sessions"]["joints"][n]["unit"] = u
        others = tuple(n for n in own if n not in follow)
        out.append(MapReading("joints.unit", base, u, _with(lab_map, edit), besides=others))
    for name, spec in own.items():
        if spec["unit"] == base:
            continue
        for u in units:
            if u != spec["unit"]:
                def edit(tables, u=u, name=name):
                    tables["sessions"]["joints"][name]["unit"] = u
                out.append(MapReading(f"sessions.{name}.joints.unit", spec["unit"], u, _with(lab_map, edit), only=(name,)))
    return out


def _orientation_readings(lab_map: LabMap) -> list[MapReading]:
    t = lab_map.tables["orientation"]
    if not t:
        return []
    out = []
    kind, cols = t["kind"], list(t["columns"])
    if kind == "quaternion":
        other = "last" if t["scalar"] == "first" else "first"
        out.append(MapReading("orientation.scalar", t["scalar"], other, _with(lab_map, _set("orientation", "scalar",
                                                                                                other))))
        vector = [1, 2, 3] if t["scalar"] == "first" else [0, 1, 2]
    elif kind == "matrix":
        other = "column" if t["order"] == "row" else "row"
        out.append(MapReading("orientation.order", t["order"], other, _with(lab_map, _set("orientation", "order",
                                                                                             other))))
        vector = []
    else:
        for u in ANGLE_UNITS:
            if u != t["unit"]:
                out.append(MapReading("orientation.unit", t["unit"], u, _with(lab_map, _set("orientation", "unit", u))))
        seq = t["sequence"]
        swapped = seq.lower() if seq.isupper() else seq.upper()
        out.append(MapReading("orientation.sequence", seq, swapped,
                              _with(lab_map, _set("orientation", "sequence", swapped))))
        vector = []
    if kind != "matrix":  # a matrix's transpose is its order
        other = [d for d in ROTATION_DIRECTIONS if d != t["rotation"]][0]
        out.append(MapReading("orientation.rotation", t["rotation"], other,
                              _with(lab_map, _set("orientation", "rotation", other))))
    for a, b in ((0, 1), (0, 2), (1, 2)):
        if vector:
            swapped = list(cols)
            swapped[vector[a]], swapped[vector[b]] = swapped[vector[b]], swapped[vector[a]]
            out.append(MapReading("orientation.columns", cols, swapped,
                                  _with(lab_map, _set("orientation", "columns", tuple(swapped)))))
    return out


def map_readings(lab_map: LabMap) -> list[MapReading]:
    """Every other reading :func:`lab_checks` tries (module doc), in order: positions, joints,
    orientation."""
    unit = lab_map.tables["position"]["unit"]
    out = [MapReading("position.unit", unit, u, _with(lab_map, _set("position", "unit", u)))
           for u in LENGTH_UNITS if u != unit]
    return out + _joint_readings(lab_map) + _orientation_readings(lab_map)


# --------------------------------------------------------------------------- figures in words


def _length(mm: float) -> str:
    """A length in the unit that reads best (um, mm, m)."""
    if not np.isfinite(mm):
        return f"{mm} mm"
    if abs(mm) >= 1e4:
        return f"{mm / 1000.0:.3g} m"
    if abs(mm) < 0.1:
        return f"{mm * 1000.0:.3g} um"
    return f"{mm:.3g} mm"


def _residual_words(robot, figures) -> str:
    """``RMS 0.4 um and 1e-05 rad`` of a fit's residuals (what it fits the data to)."""
    if figures.error or figures.fit is None:
        return f"no fit ({figures.error})"
    r = np.asarray(figures.fit.result.pose_residuals, dtype=float).reshape(-1, robot.pose_dim)
    angle = robot.angle_pose_mask
    pos = float(np.sqrt(np.mean(r[:, ~angle] ** 2)))
    words = f"RMS {_length(pos)}"
    if angle.any():
        words += f" and {float(np.sqrt(np.mean(r[:, angle] ** 2))):.3g} rad"
    return words


def _rows(rec: Recording, reading: MapReading) -> np.ndarray:
    """(N,) bool: the rows the reading's key converts."""
    if reading.only is not None:
        return np.isin(rec.sessions, list(reading.only))
    return ~np.isin(rec.sessions, list(reading.besides))


def _what_it_makes(reading: MapReading, rec: Recording) -> str:
    """What a unit key as written makes of the data, in figures ('' for the other keys: the fit's
    residuals say it)."""
    robot = rec.robot
    rows = _rows(rec, reading)
    if reading.key == "position.unit":
        d = float(np.median(np.linalg.norm(rec.measured[:, ~robot.angle_pose_mask], axis=1)))
        try:
            fk = robot.forward_kinematics(robot.table.nominal, rec.joints,
                                          initial=np.repeat(robot.home_pose[None], len(rec.joints), axis=0))
            near = f" (the joints put it {_length(float(np.median(np.linalg.norm(fk[:, ~robot.angle_pose_mask], axis=1))))})"
        except KinematicsError:
            near = ""
        return f"puts the platform a median {_length(d)} from the base{near}"
    if reading.key.endswith("joints.unit"):
        q, limits, unit = rec.joints[rows], robot.joint_limits(), robot.joint_unit
        return (f"makes the joints {q.min():.4g} to {q.max():.4g} {unit} (the {robot.name}'s range "
                f"{limits[:, 0].min():.4g} to {limits[:, 1].max():.4g} {unit})")
    if reading.key == "orientation.unit":
        return f"makes the angles up to {float(np.max(np.abs(rec.measured[:, robot.angle_pose_mask]))):.3g} rad"
    return ""


# --------------------------------------------------------------------------- the checks


def _same_within_noise(rec: Recording, joints: np.ndarray, measured: np.ndarray) -> bool:
    """Whether another reading (``joints``, ``measured``) changes no pose value by more than its
    declared standard deviation and no joint by more than its own (or 1e-9 of its magnitude)."""
    std = rec.noise.pose_std(rec.robot.pose_units)
    joint = max(rec.noise.joint_std, 1e-9 * float(np.max(np.abs(rec.joints), initial=1.0)))
    return bool(np.all(np.abs(measured - rec.measured) <= std) and np.all(np.abs(joints - rec.joints) <= joint))


def _rows_words(sample: LabSample) -> str:
    """``12 rows``, or ``2000 rows (a seeded subsample of the 300000)``: the rows judged."""
    n = len(sample.recording.t_s)
    return f"{n} rows" + ("" if sample.all_rows else f" (a seeded subsample of the {sample.rows})")


def lab_checks(lab_map: LabMap, sample: LabSample) -> list[str]:
    """Check the rows ``sample`` of the recording ``lab_map`` made of a lab's files on evidence
    (module doc): each other reading of the map converts the same rows again.

    Returns:
        Warnings, one line each, naming the map and the key.

    Raises:
        LabExportError: a key as written the data cannot fit where another value fits (naming the
            map, the key, both values and their figures).
    """
    from calib.diagnosis import compare_readings

    rec = sample.recording
    robot = rec.robot
    sessions, frame = row_frame_groups(rec)
    readings, alternatives = {}, {}
    for reading in map_readings(lab_map):
        try:
            joints, measured = sample.read_as(reading.lab_map)
        except LabExportError:  # the files cannot be read so: not a reading of them
            continue
        if _same_within_noise(rec, joints, measured):  # the key makes no difference these rows could show
            continue
        readings[reading.name] = (joints, measured)
        alternatives[reading.name] = reading
    c = compare_readings(rec.robot, rec.joints, rec.measured, rec.noise, readings, frame=frame, sessions=sessions,
                         tolerance=rec.meta.get("parameter_tolerance"))
    path, written = lab_map.path, c.written
    judged = "" if sample.all_rows else f" (judged on a seeded subsample of {len(rec.t_s)} of the {sample.rows} rows)"
    if TOO_FEW_ROWS in written.error or (not written.error and written.dof <= 0):
        few = written.words() if written.error else "a fit of the geometry leaves no degree of freedom"
        return [f"{path}: {_rows_words(sample)} ({len(rec.t_s) * robot.pose_dim} pose values) are too few to "
                f"check the map's units and conventions against the {robot.name} ({few}): converted as written, "
                "unchecked"]
    as_read = written.words() if written.error else f"{_residual_words(robot, written)}; {written.words()}"
    if c.named:
        r, f = alternatives[c.named[0]], c.figures[c.named[0]]
        effect = _what_it_makes(r, rec)
        how = f"do not fit the {robot.name}" if not written.fits else f"fit the {robot.name} only implausibly"
        raise LabExportError(
            f"{path}: key {r.key} = {r.written!r}{' ' + effect if effect else ''}: as the map reads them the data "
            f"{how} ({as_read}); as {r.value!r} they fit to {_residual_words(robot, f)} ({f.words()}): did you mean "
            f"{r.key} = {r.value!r}?{judged}")
    if c.also_fit:
        r, f = alternatives[c.also_fit[0]], c.figures[c.also_fit[0]]
        return [f"{path}: key {r.key} = {r.written!r}: the {_rows_words(sample)} fit the {robot.name} as the map reads "
                f"them ({as_read}) and with {r.key} = {r.value!r} as well ({_residual_words(robot, f)}; {f.words()}): "
                "too few or too alike to tell; converted as written, check the key"]
    if written.fits:
        return []
    fitting = [n for n, f in c.figures.items() if f.fits and f.plausible]
    if fitting:
        r, f = alternatives[fitting[0]], c.figures[fitting[0]]
        return [f"{path}: key {r.key} = {r.written!r}: as the map reads them the data do not fit the {robot.name} "
                f"({as_read}); with {r.key} = {r.value!r} they do ({_residual_words(robot, f)}; {f.words()}), but not "
                f"by enough to be sure{judged}: converted as written, check the key"]
    best = f"; the best other reading, {c.screened[0][0]}, screens at chi-square {c.screened[0][1]:.3g} per degree " \
           "of freedom" if c.screened else ""
    return [f"{path}: the converted data do not fit the {robot.name} at the declared noise ({as_read}), nor with any "
            f"of {len(readings)} map keys changed{best}{judged}: converted as written (pipeline.run --real diagnoses "
            "the recording)"]
