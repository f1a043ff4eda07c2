"""An independent implementation, in plain numpy, of Klipper's documented linear-Delta kinematics
and of its calibration fit, for the tests to compare the workbench against (docs/klipper.md).

Klipper's units and conventions throughout: lengths in mm, tower angles in degrees (the fit's
steps are in these units), stable positions in steps counted from each tower's endstop.

- Towers at ``radius * (cos angle_i, sin angle_i)`` (Klipper's klippy/kinematics/delta.py).
- A carriage's height: ``position_endstop_i + sqrt(arm_i^2 - radius^2)`` (its absolute endstop)
  minus the stable position times the step distance.
- The tool point: the intersection of the three spheres about the carriages' joints (radius the
  arm length) on the side opposite to ``(c_b - c_a) x (c_c - c_a)`` (klippy/mathutil.py's
  trilateration: its lower solution for towers a, b, c counter-clockwise).
- DELTA_CALIBRATE / DELTA_ANALYZE (klippy/extras/delta_calibrate.py): coordinate descent
  (klippy/mathutil.py) on ``z_weight * sum (z - height)^2 + sum (distance - measured)^2``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

TOWERS = "abc"
#: The parameters DELTA_CALIBRATE adjusts, in its order; DELTA_ANALYZE's distances add the arms.
CALIBRATE_PARAMS = ("radius", "angle_a", "angle_b", "endstop_a", "endstop_b", "endstop_c")
EXTENDED_PARAMS = ("arm_a", "arm_b", "arm_c")
#: How much a distance is preferred over a height (Klipper's MEASURE_WEIGHT).
MEASURE_WEIGHT = 0.5
#: Coordinate descent: each parameter's first step, the factors a step grows by after a success
#: and shrinks by after a failure, the sum of the steps that stops it, and its most rounds.
FIRST_STEP, GROW, SHRINK, STOP_SUM, MAX_ROUNDS = 1.0, 1.1, 0.9, 1e-5, 10000
#: DELTA_ANALYZE's calibration object: the ridges' angles (degrees), the outer pillars' distance
#: from the centre and the ridges' distance from a pillar's centre, mm.
OBJECT_ANGLES_DEG = (210.0, 270.0, 330.0, 30.0, 90.0, 150.0)
OBJECT_OUTER_RADIUS, OBJECT_RIDGE_RADIUS = 65.0, 4.5
SAVE_CONFIG_LINES = ("#*# <---------------------- SAVE_CONFIG ---------------------->",
                     "#*# DO NOT EDIT THIS BLOCK OR BELOW. The contents are auto-generated.", "#*#")


@dataclass(frozen=True)
class DeltaParams:
    """A linear Delta in Klipper's terms (angles in degrees)."""

    radius: float
    angles: tuple
    arms: tuple
    endstops: tuple
    stepdists: tuple

    def as_dict(self) -> dict:
        d = {"radius": self.radius}
        for i, t in enumerate(TOWERS):
            d |= {f"angle_{t}": self.angles[i], f"arm_{t}": self.arms[i], f"endstop_{t}": self.endstops[i],
                  f"stepdist_{t}": self.stepdists[i]}
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "DeltaParams":
        return cls(d["radius"], *(tuple(float(d[f"{k}_{t}"]) for t in TOWERS)
                                  for k in ("angle", "arm", "endstop", "stepdist")))


def towers_xy(p: DeltaParams) -> np.ndarray:
    """(3, 2) the towers' x, y."""
    a = np.radians(p.angles)
    return p.radius * np.stack([np.cos(a), np.sin(a)], axis=1)


def absolute_endstops(p: DeltaParams) -> np.ndarray:
    """(3,) the carriages' heights at the endstops."""
    return np.asarray(p.endstops) + np.sqrt(np.asarray(p.arms) ** 2 - p.radius ** 2)


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(..., 3) ``u x v`` (numpy's own is slow on small arrays)."""
    return np.stack([u[..., 1] * v[..., 2] - u[..., 2] * v[..., 1], u[..., 2] * v[..., 0] - u[..., 0] * v[..., 2],
                     u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]], axis=-1)


def lower_sphere_intersection(centres: np.ndarray, radii2: np.ndarray) -> np.ndarray:
    """(..., 3) the intersection of three spheres (centres (..., 3, 3), squared radii (3,)) on the
    side opposite to ``(c1 - c0) x (c2 - c0)``: the plane through the centres cuts the line of the
    two solutions at the point solving the two differences of the sphere equations (Cramer's rule)."""
    c0, c1, c2 = centres[..., 0, :], centres[..., 1, :], centres[..., 2, :]
    normal = cross(c1 - c0, c2 - c0)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    sq = np.sum(centres ** 2, axis=-1)
    rows = np.stack([2 * (c1 - c0), 2 * (c2 - c0), normal], axis=-2)
    rhs = np.stack([radii2[0] - radii2[1] + sq[..., 1] - sq[..., 0], radii2[0] - radii2[2] + sq[..., 2] - sq[..., 0],
                    np.sum(normal * c0, axis=-1)], axis=-1)
    r0, r1, r2 = rows[..., 0, :], rows[..., 1, :], rows[..., 2, :]
    cofactors = (cross(r1, r2), cross(r2, r0), cross(r0, r1))
    foot = sum(rhs[..., k, None] * c for k, c in enumerate(cofactors)) / np.sum(r0 * cofactors[0], axis=-1)[..., None]
    height2 = radii2[0] - np.sum((foot - c0) ** 2, axis=-1)
    return foot - normal * np.sqrt(height2)[..., None]


def carriage_heights_from_stable(p: DeltaParams, steps: np.ndarray) -> np.ndarray:
    """(..., 3) the carriages' heights at stable positions ``steps`` (..., 3)."""
    return absolute_endstops(p) - np.asarray(steps, dtype=float) * np.asarray(p.stepdists)


def position_from_stable(p: DeltaParams, steps: np.ndarray) -> np.ndarray:
    """(..., 3) the tool point at stable positions ``steps`` (..., 3): forward kinematics."""
    heights = carriage_heights_from_stable(p, steps)
    xy = np.broadcast_to(towers_xy(p), heights.shape[:-1] + (3, 2))
    return lower_sphere_intersection(np.concatenate([xy, heights[..., None]], axis=-1), np.asarray(p.arms) ** 2)


def carriage_heights(p: DeltaParams, xyz: np.ndarray) -> np.ndarray:
    """(..., 3) the carriages' heights that put the tool point at ``xyz`` (..., 3): inverse kinematics."""
    xyz = np.asarray(xyz, dtype=float)
    horizontal2 = np.sum((towers_xy(p) - xyz[..., None, :2]) ** 2, axis=-1)
    return xyz[..., 2:3] + np.sqrt(np.asarray(p.arms) ** 2 - horizontal2)


def stable_from_position(p: DeltaParams, xyz: np.ndarray) -> np.ndarray:
    """(..., 3) the stable positions (steps) of the tool point ``xyz`` (..., 3)."""
    return (absolute_endstops(p) - carriage_heights(p, xyz)) / np.asarray(p.stepdists)


def coordinate_descent(names: tuple, params: dict, error) -> tuple[dict, int]:
    """Klipper's coordinate descent: each named parameter in turn tries ``+step`` then ``-step``,
    keeps the first that lowers ``error(params)`` and grows its step by :data:`GROW`, else stays and
    shrinks its step by :data:`SHRINK`; rounds until the steps sum to :data:`STOP_SUM` or less (at
    most :data:`MAX_ROUNDS`). The parameters found and the rounds run."""
    params = dict(params)
    step = dict.fromkeys(names, FIRST_STEP)
    best = error(params)
    rounds = 0
    while sum(step.values()) > STOP_SUM and rounds < MAX_ROUNDS:
        rounds += 1
        for name in names:
            start = params[name]
            for trial in (start + step[name], start - step[name]):
                params[name] = trial
                value = error(params)
                if value < best:
                    best = value
                    step[name] *= GROW
                    break
            else:
                params[name] = start
                step[name] *= SHRINK
    return params, rounds


@dataclass(frozen=True, eq=False)
class Measurements:
    """What DELTA_CALIBRATE and DELTA_ANALYZE fit: probe touches, manual heights, distances."""

    touch_z: np.ndarray
    touch_steps: np.ndarray
    manual_z: np.ndarray = field(default_factory=lambda: np.zeros(0))
    manual_steps: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    distances: np.ndarray = field(default_factory=lambda: np.zeros(0))
    distance_steps: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))


def calibration_residuals(p: DeltaParams, m: Measurements) -> np.ndarray:
    """The residuals whose squares DELTA_CALIBRATE sums: the height errors of the manual heights and
    touches, times the square root of ``len(distances) / (MEASURE_WEIGHT * len(touches))`` when
    there are distances (1 without), then the distance errors."""
    z = np.concatenate([m.manual_z, m.touch_z])
    steps = np.concatenate([m.manual_steps, m.touch_steps]).reshape(-1, 3)
    heights = position_from_stable(p, steps)[:, 2] - z
    if not len(m.distances):
        return heights
    ends = position_from_stable(p, m.distance_steps)
    lengths = np.linalg.norm(ends[:, 0] - ends[:, 1], axis=-1)
    weight = len(m.distances) / (MEASURE_WEIGHT * len(m.touch_z))
    return np.concatenate([np.sqrt(weight) * heights, lengths - m.distances])


def calibration_error(p: DeltaParams, m: Measurements) -> float:
    """DELTA_CALIBRATE's error: the sum of the squared :func:`calibration_residuals`."""
    return float(np.sum(calibration_residuals(p, m) ** 2))


def adjusted_params(m: Measurements) -> tuple:
    """The parameters Klipper's fit adjusts: radius, angles a and b, the three endstops, and the
    three arms when there are distances."""
    return CALIBRATE_PARAMS + (EXTENDED_PARAMS if len(m.distances) else ())


def delta_calibrate(p: DeltaParams, m: Measurements) -> tuple[DeltaParams, int]:
    """Klipper's fit from ``p`` (:func:`adjusted_params`): the parameters found and the descent's
    rounds."""
    names = adjusted_params(m)
    found, rounds = coordinate_descent(names, p.as_dict(), lambda d: calibration_error(DeltaParams.from_dict(d), m))
    return DeltaParams.from_dict(found), rounds


def calibration_object_points(scale: float = 1.0) -> np.ndarray:
    """(12, 2, 3) DELTA_ANALYZE's twelve measured pairs on its calibration object at z = 0: six from
    a ridge next to the centre to one at an outer pillar, then six across the outer pillars."""
    a = np.radians(OBJECT_ANGLES_DEG)
    u = np.stack([np.cos(a), np.sin(a), np.zeros(6)], axis=1)
    inner, outer = OBJECT_RIDGE_RADIUS * scale, (OBJECT_OUTER_RADIUS + OBJECT_RIDGE_RADIUS) * scale
    centre_pairs = np.stack([u * inner, u * outer], axis=1)
    start = u * OBJECT_OUTER_RADIUS * scale
    shifted = np.roll(u, -2, axis=0)
    outer_pairs = np.stack([start + shifted * inner, start + shifted * outer], axis=1)
    return np.concatenate([centre_pairs, outer_pairs])


def save_config_text(p: DeltaParams, m: Measurements) -> str:
    """The SAVE_CONFIG block DELTA_CALIBRATE leaves: the parameters (``%.6f``) and the
    ``[delta_calibrate]`` block (values ``%.6f``, stable positions ``%.3f``), every line ``#*# ``."""
    lines = ["[printer]", f"delta_radius = {p.radius:.6f}", ""]
    for i, t in enumerate(TOWERS):
        lines += [f"[stepper_{t}]", f"angle = {p.angles[i]:.6f}", f"arm_length = {p.arms[i]:.6f}",
                  f"position_endstop = {p.endstops[i]:.6f}", ""]
    lines.append("[delta_calibrate]")
    series = [("height", ("pos",), m.touch_z, m.touch_steps[:, None]),
              ("manual_height", ("pos",), m.manual_z, m.manual_steps[:, None]),
              ("distance", ("pos1", "pos2"), m.distances, m.distance_steps)]
    for stem, suffixes, values, steps in series:
        for n, (v, ends) in enumerate(zip(values, steps)):
            lines.append(f"{stem}{n} = {v:.6f}")
            lines += [f"{stem}{n}_{s} = " + ",".join(f"{x:.3f}" for x in e) for s, e in zip(suffixes, ends)]
    return "\n".join(SAVE_CONFIG_LINES + tuple(f"#*# {line}".rstrip() for line in lines)) + "\n"
