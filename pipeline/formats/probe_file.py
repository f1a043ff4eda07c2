"""The probe-data file: a Delta printer's probe touches, manual heights and distances
(``NAME.probe.json``; docs/klipper.md).

A recording (``NAME.csv`` + ``NAME.json``) holds full poses or positions at joints; a printer
owner's data are heights and distances, which are not poses: they get their own file type next to
the recording rather than pose columns left empty. ``python -m pipeline.convert printer.cfg
--klipper --out NAME`` writes it; ``python -m pipeline.probe NAME.probe.json --out DIR`` fits it.

Keys: ``format`` (:data:`PROBE_FORMAT`), ``version`` (:data:`PROBE_VERSION`), ``robot``
(``linear_delta`` or ``delta``, :data:`PROBE_ROBOTS`) and ``nominal_geometry`` (the robot's
description, mm and rad); ``bed`` (``estimated`` or ``flat``); ``noise_mm`` (``touch``, ``manual``,
``distance``: standard deviations); the steps the joints were counted with: the linear Delta's
``step_distances_mm``, the rotary Delta's ``step_angles_rad`` (:data:`STEP_KEYS`); ``touches``
(``joints_mm``: N rows of three carriage travels below the endstops, or ``joints_rad``: the arms'
turns below their endstops; ``z_mm``), ``manual_heights`` (the same), ``distances`` (the joints:
K pairs of rows, ``mm``); ``source`` (the file converted, its name and SHA-256, and what it said in
words).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from calib.files import atomic_write, read_json_file
from calib.probe import ProbeData, ProbeNoise
from calib.robot import Robot
from calib.robots.delta import Delta
from calib.robots.linear_delta import LinearDelta

__all__ = ["PROBE_FORMAT", "PROBE_VERSION", "PROBE_SUFFIX", "PROBE_ROBOTS", "STEP_KEYS", "ProbeFileError",
           "joints_key", "step_key", "probe_file_text", "write_probe_file",
           "read_probe_file"]

PROBE_FORMAT = "workbench-probe-data"
PROBE_VERSION = 1
PROBE_SUFFIX = ".probe.json"
KEYS = ("format", "version", "robot", "nominal_geometry", "bed", "noise_mm", "touches", "manual_heights",
        "distances", "source")
#: The robots whose probe data the file holds, by the ``robot`` key.
PROBE_ROBOTS = {LinearDelta.name: LinearDelta, Delta.name: Delta}
#: The key of the steps the joints were counted with, by the joints' unit.
STEP_KEYS = {"mm": "step_distances_mm", "rad": "step_angles_rad"}


def joints_key(robot: Robot) -> str:
    """The key of the joints in ``touches``, ``manual_heights`` and ``distances``: ``joints_`` and their unit."""
    return f"joints_{robot.joint_unit}"


def step_key(robot: Robot) -> str:
    """The key of the steps the joints were counted with (:data:`STEP_KEYS`)."""
    return STEP_KEYS[robot.joint_unit]


class ProbeFileError(ValueError):
    """A probe-data file that cannot be read; the message names the file and the key."""


def probe_file_text(robot: Robot, data: ProbeData, noise: ProbeNoise, steps, source: dict) -> str:
    """The file's JSON text (module docstring); ``steps`` the step distances or angles."""
    j = joints_key(robot)
    d = {"format": PROBE_FORMAT, "version": PROBE_VERSION, "robot": robot.name,
         "nominal_geometry": robot.description(), "bed": data.bed,
         "noise_mm": {"touch": noise.touch_mm, "manual": noise.manual_mm, "distance": noise.distance_mm},
         step_key(robot): [float(v) for v in steps],
         "touches": {j: data.touch_joints.tolist(), "z_mm": data.touch_z_mm.tolist()},
         "manual_heights": {j: data.manual_joints.tolist(), "z_mm": data.manual_z_mm.tolist()},
         "distances": {j: data.distance_joints.tolist(), "mm": data.distance_mm.tolist()},
         "source": source}
    return json.dumps(d, indent=1) + "\n"


def write_probe_file(path, robot, data, noise, steps, source, *, overwrite: bool = False) -> Path:
    """Write the file ``path`` atomically (an existing one refused without ``overwrite``)."""
    return atomic_write(path, probe_file_text(robot, data, noise, steps, source), overwrite=overwrite)


def read_probe_file(path) -> tuple[Robot, ProbeData, ProbeNoise, dict]:
    """``(robot, data, noise, file)``: the file ``path`` read and checked (``file`` its JSON object).

    Raises:
        ProbeFileError: one line naming the file and the key.
    """
    path = Path(path)
    d = read_json_file(path, "probe-data file", ProbeFileError)
    if not isinstance(d, dict) or d.get("format") != PROBE_FORMAT:
        raise ProbeFileError(f"{path}: key 'format' is not {PROBE_FORMAT!r}: not a probe-data file written by "
                             "python -m pipeline.convert --klipper")
    missing = [k for k in KEYS if k not in d]
    if missing:
        raise ProbeFileError(f"{path}: key {missing[0]!r} is missing")
    if d["version"] != PROBE_VERSION:
        raise ProbeFileError(f"{path}: key 'version' is {d['version']!r}; this reader reads version {PROBE_VERSION}")
    if d["robot"] not in PROBE_ROBOTS:
        raise ProbeFileError(f"{path}: key 'robot' is {d['robot']!r}; probe data are read for the "
                             f"{', '.join(PROBE_ROBOTS)}")
    cls = PROBE_ROBOTS[d["robot"]]
    if STEP_KEYS[cls.joint_unit] not in d:
        raise ProbeFileError(f"{path}: key {STEP_KEYS[cls.joint_unit]!r} is missing")
    try:
        robot = cls.from_description(d["nominal_geometry"])
        n = d["noise_mm"]
        noise = ProbeNoise(float(n["touch"]), float(n["manual"]), float(n["distance"]))
        t, m, k = d["touches"], d["manual_heights"], d["distances"]
        j = joints_key(robot)
        data = ProbeData(np.asarray(t[j], float).reshape(-1, 3), t["z_mm"],
                         np.asarray(m[j], float).reshape(-1, 3), m["z_mm"],
                         np.asarray(k[j], float).reshape(-1, 2, 3), k["mm"], bed=d["bed"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ProbeFileError(f"{path}: {' '.join(str(exc).split())}") from None
    return robot, data, noise, d
