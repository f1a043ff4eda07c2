"""The probe-data file: a linear Delta's probe touches, manual heights and distances
(``NAME.probe.json``; docs/klipper.md).

A recording (``NAME.csv`` + ``NAME.json``) holds full poses or positions at joints; a printer
owner's data are heights and distances, which are not poses: they get their own file type next to
the recording rather than pose columns left empty. ``python -m pipeline.convert printer.cfg
--klipper --out NAME`` writes it; ``python -m pipeline.probe NAME.probe.json --out DIR`` fits it.

Keys: ``format`` (:data:`PROBE_FORMAT`), ``version`` (:data:`PROBE_VERSION`), ``robot``
(``linear_delta``) and ``nominal_geometry`` (the robot's description, mm and rad); ``bed``
(``estimated`` or ``flat``); ``noise_mm`` (``touch``, ``manual``, ``distance``: standard
deviations); ``step_distances_mm`` (each stepper's step distance the joints were counted with);
``touches`` (``joints_mm``: N rows of three carriage travels below the endstops, ``z_mm``),
``manual_heights`` (the same), ``distances`` (``joints_mm``: K pairs of rows, ``mm``); ``source``
(the file converted, its name and SHA-256, and what it said in words).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from calib.files import atomic_write, read_json_file
from calib.probe import ProbeData, ProbeNoise
from calib.robots.linear_delta import LinearDelta

__all__ = ["PROBE_FORMAT", "PROBE_VERSION", "PROBE_SUFFIX", "ProbeFileError", "probe_file_text", "write_probe_file",
           "read_probe_file"]

PROBE_FORMAT = "workbench-probe-data"
PROBE_VERSION = 1
PROBE_SUFFIX = ".probe.json"
KEYS = ("format", "version", "robot", "nominal_geometry", "bed", "noise_mm", "step_distances_mm", "touches",
        "manual_heights", "distances", "source")


class ProbeFileError(ValueError):
    """A probe-data file that cannot be read; the message names the file and the key."""


def probe_file_text(robot: LinearDelta, data: ProbeData, noise: ProbeNoise, step_distances_mm, source: dict) -> str:
    """The file's JSON text (module docstring)."""
    d = {"format": PROBE_FORMAT, "version": PROBE_VERSION, "robot": robot.name,
         "nominal_geometry": robot.description(), "bed": data.bed,
         "noise_mm": {"touch": noise.touch_mm, "manual": noise.manual_mm, "distance": noise.distance_mm},
         "step_distances_mm": [float(v) for v in step_distances_mm],
         "touches": {"joints_mm": data.touch_joints.tolist(), "z_mm": data.touch_z_mm.tolist()},
         "manual_heights": {"joints_mm": data.manual_joints.tolist(), "z_mm": data.manual_z_mm.tolist()},
         "distances": {"joints_mm": data.distance_joints.tolist(), "mm": data.distance_mm.tolist()},
         "source": source}
    return json.dumps(d, indent=1) + "\n"


def write_probe_file(path, robot, data, noise, step_distances_mm, source, *, overwrite: bool = False) -> Path:
    """Write the file ``path`` atomically (an existing one refused without ``overwrite``)."""
    return atomic_write(path, probe_file_text(robot, data, noise, step_distances_mm, source), overwrite=overwrite)


def read_probe_file(path) -> tuple[LinearDelta, ProbeData, ProbeNoise, dict]:
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
    if d["robot"] != LinearDelta.name:
        raise ProbeFileError(f"{path}: key 'robot' is {d['robot']!r}; probe data are read for the {LinearDelta.name}")
    try:
        robot = LinearDelta.from_description(d["nominal_geometry"])
        n = d["noise_mm"]
        noise = ProbeNoise(float(n["touch"]), float(n["manual"]), float(n["distance"]))
        t, m, k = d["touches"], d["manual_heights"], d["distances"]
        data = ProbeData(np.asarray(t["joints_mm"], float).reshape(-1, 3), t["z_mm"],
                         np.asarray(m["joints_mm"], float).reshape(-1, 3), m["z_mm"],
                         np.asarray(k["joints_mm"], float).reshape(-1, 2, 3), k["mm"], bed=d["bed"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ProbeFileError(f"{path}: {' '.join(str(exc).split())}") from None
    return robot, data, noise, d
