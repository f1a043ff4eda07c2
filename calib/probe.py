"""A Delta printer identified from what its owner can measure: probe touches, manual heights and
caliper distances (issue 49, point 2; docs/klipper.md).

The robot is any whose pose is its tool point ``(x, y, z)`` (mm, base frame) given by the forward
kinematics of its closure: the linear Delta (:class:`calib.robots.linear_delta.LinearDelta`, joints
the carriages' counted travel below their endstops, mm) and the rotary Delta
(:class:`calib.robots.delta.Delta` of a Klipper ``rotary_delta`` config, joints the arms' turns
below their endstops, rad). Measurements (mm), each at commanded joints:

* a *probe touch*: the tool point met the bed; ``z`` is the tool point's height above the bed
  there (Klipper's ``heightN``: the probe's z offset);
* a *manual height*: the nozzle rests on a gauge block of height ``z`` standing on the bed
  (Klipper's ``manual_heightN``);
* a *distance*: between the tool points at two commanded positions, measured with calipers on a
  printed object (Klipper's ``distanceN``).

The bed is the instrument's frame: the plane ``z = bed.z + bed.tilt_x x + bed.tilt_y y`` of the
robot's base frame, estimated along with the robot (a prior of :data:`BED_TOLERANCE` about
:func:`nominal_bed`: a bed placed and levelled by hand) or declared flat (held at
:func:`nominal_bed`). A touch's residual is the model's
tool height minus the bed's height under it minus ``z``.

The fit (:func:`fit_probe`) is the maximum a posteriori estimate: Gauss-Newton on the whitened
measurement rows and the prior rows ``(theta_k - mean_k) / std_k`` of the free parameters (the
robot's tolerances, :class:`calib.prior.ParameterPrior`), the tool point's derivatives from the
closure by the implicit function theorem ``dX/dtheta = -(dF/dX)^-1 dF/dtheta``. The result says
each parameter's posterior standard deviation, which parameters and combinations the data leave
to their tolerances (the posterior's eigenvectors in tolerance units whose standard deviation the
data did not halve, :data:`calib.prior.DATA_SOURCE_RATIO`) and which further measurement would
determine each of them (:data:`CANDIDATES`, per robot: :func:`candidates_of`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .observability import describe_combination
from .prior import DATA_SOURCE_RATIO, ParameterPrior, parameter_sources
from .robot import KinematicsError, Robot
from .robots.linear_delta import LinearDelta
from .validation import as_array

__all__ = ["ProbeData", "ProbeNoise", "ProbeFit", "ProbeError", "fit_probe", "tool_points_and_jacobian",
           "probe_rows", "nominal_bed", "candidates_of", "BED_PARAMETERS", "BED_TOLERANCE", "BED_MODES", "CANDIDATES", "GAUGE_HEIGHTS_MM",
           "CALIBRATION_OBJECT_ANGLES_RAD", "CALIBRATION_OBJECT_RADII_MM", "calibration_object_points"]

#: The bed plane's parameters: its height at the origin (mm) and its slopes along x and y (rad).
BED_PARAMETERS = ("bed.z", "bed.tilt_x", "bed.tilt_y")
#: Their prior standard deviations when estimated: a bed placed within 5 mm of the nominal height
#: and levelled by hand to 10 mrad (1 mm over 100 mm).
BED_TOLERANCE = (5.0, 0.01, 0.01)
#: How the bed is treated: estimated as the instrument's frame, or declared flat (held at zero).
BED_MODES = ("estimated", "flat")
#: The gauge blocks of the manual-height suggestion, mm above the bed.
GAUGE_HEIGHTS_MM = (50.0, 100.0)
#: Klipper's calibration object (its DELTA_ANALYZE): the ridges' directions about the centre
#: (210, 270, 330, 30, 90, 150 degrees) and the inner ridge's and outer pillar ridge's distances from
#: the centre (4.5 and 65 + 4.5 mm).
CALIBRATION_OBJECT_ANGLES_RAD = tuple(np.radians((210.0, 270.0, 330.0, 30.0, 90.0, 150.0)))
CALIBRATION_OBJECT_RADII_MM = (4.5, 65.0)
#: Further measurements the observability statement tries, in words.
CANDIDATES = {"manual": "manual heights on 50 and 100 mm gauge blocks at the touches",
              "distance": "the calibration object's 12 caliper distances",
              "position": "tool positions (x, y, z) measured at the touches"}
#: The rotary Delta's entries where they differ: its arms' lengths and its joint zeros move the tool
#: alike on the bed, and an arm's angle at its endstop is what a digital level on the arm reads.
ROTARY_CANDIDATES = {**CANDIDATES, "joint zero": "each arm's angle at its endstop (a digital level on the arm)"}
#: The standard deviation of an arm's angle read with a digital level (0.1 degree), rad.
JOINT_ZERO_STD_RAD = float(np.radians(0.1))
#: Gauss-Newton stops when the step changes no whitened residual by more than this.
STEP_TOL = 1e-9


class ProbeError(ValueError):
    """Probe data that cannot be fitted as asked; the message names what and what would fit."""


@dataclass(frozen=True)
class ProbeNoise:
    """Standard deviations, mm: a probe touch, a manual height (the gauge and the paper test), a
    caliper distance."""

    touch_mm: float = 0.01
    manual_mm: float = 0.02
    distance_mm: float = 0.02

    def __post_init__(self):
        for name in ("touch_mm", "manual_mm", "distance_mm"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"ProbeNoise.{name} must be a finite number > 0, got {v!r}")


@dataclass(frozen=True, eq=False)
class ProbeData:
    """Probe touches, manual heights and distances at commanded joints (mm; module docstring).

    Attributes:
        touch_joints: (N, 3), touch_z_mm: (N,).
        manual_joints: (M, 3), manual_z_mm: (M,).
        distance_joints: (K, 2, 3), distance_mm: (K,).
        bed: one of :data:`BED_MODES`.
    """

    touch_joints: np.ndarray
    touch_z_mm: np.ndarray
    manual_joints: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    manual_z_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    distance_joints: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    distance_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    bed: str = "estimated"

    def __post_init__(self):
        for joints, values, shape in (("touch_joints", "touch_z_mm", (-1, 3)), ("manual_joints", "manual_z_mm", (-1, 3)),
                                      ("distance_joints", "distance_mm", (-1, 2, 3))):
            j = as_array(getattr(self, joints), joints, shape)
            v = as_array(getattr(self, values), values, (j.shape[0],))
            object.__setattr__(self, joints, j)
            object.__setattr__(self, values, v)
        if self.bed not in BED_MODES:
            raise ValueError(f"bed must be one of {', '.join(BED_MODES)}, got {self.bed!r}")

    @property
    def counts(self) -> dict[str, int]:
        return {"touches": len(self.touch_z_mm), "manual heights": len(self.manual_z_mm),
                "distances": len(self.distance_mm)}

    def all_joints(self) -> np.ndarray:
        """(N + M + 2K, 3) the joints of the touches, manual heights and both ends of the distances."""
        return np.concatenate([self.touch_joints, self.manual_joints, self.distance_joints.reshape(-1, 3)])


def tool_points_and_jacobian(robot: Robot, theta, joints) -> tuple[np.ndarray, np.ndarray]:
    """``(X, dX/dtheta)``: (N, 3) tool points at ``joints`` (N, 3) and (N, 3, P) their derivatives
    with respect to the parameters, ``-(dF/dX)^-1 dF/dtheta`` of the closure ``F``."""
    X = robot.forward_kinematics(theta, joints)
    _, jac = robot.closure_with_jacobians(theta, joints, X)
    return X, -np.linalg.solve(jac.pose, jac.parameters)


def probe_rows(robot: Robot, theta, bed, data: ProbeData, noise: ProbeNoise) -> tuple[np.ndarray, np.ndarray,
                                                                                       np.ndarray]:
    """``(r, J, kinds)``: the whitened residuals (R,) of ``data`` (model minus measured), their
    Jacobian (R, P + 3) in the robot's parameters then :data:`BED_PARAMETERS`, and each row's kind
    (``"touch"``, ``"manual"``, ``"distance"``)."""
    n, m, k = (len(v) for v in (data.touch_z_mm, data.manual_z_mm, data.distance_mm))
    X, dX = tool_points_and_jacobian(robot, theta, data.all_joints())
    heights = X[:n + m]
    tilt = np.array([bed[1], bed[2]])
    r_h = heights[:, 2] - bed[0] - heights[:, :2] @ tilt - np.concatenate([data.touch_z_mm, data.manual_z_mm])
    j_h = np.concatenate([dX[:n + m, 2] - np.einsum("c,ncp->np", tilt, dX[:n + m, :2]),
                          -np.column_stack([np.ones(n + m), heights[:, :2]])], axis=1)
    ends, d_ends = X[n + m:].reshape(k, 2, 3), dX[n + m:].reshape(k, 2, 3, dX.shape[-1])
    span = ends[:, 0] - ends[:, 1]
    length = np.linalg.norm(span, axis=1)
    unit = span / np.where(length > 0, length, 1.0)[:, None]
    j_d = np.einsum("nc,ncp->np", unit, d_ends[:, 0] - d_ends[:, 1])
    j_d = np.concatenate([j_d, np.zeros((k, 3))], axis=1)
    sigma = np.concatenate([np.full(n, noise.touch_mm), np.full(m, noise.manual_mm), np.full(k, noise.distance_mm)])
    r = np.concatenate([r_h, length - data.distance_mm]) / sigma
    J = np.concatenate([j_h, j_d]) / sigma[:, None]
    return r, J, np.array(["touch"] * n + ["manual"] * m + ["distance"] * k)


@dataclass(frozen=True, eq=False)
class ProbeFit:
    """A Delta identified from probe data (:func:`fit_probe`).

    Attributes:
        robot: the robot (nominal) fitted.
        names: the robot's parameter names then :data:`BED_PARAMETERS`.
        values: (P + 3,) the identified values (held ones at their prior mean).
        std: (P + 3,) posterior standard deviations of the free ones; the tolerance of a held one.
        prior_std: (P + 3,) the tolerances.
        sources: ``{name: "data" | "prior" | "held"}``.
        left: the combinations left to their tolerances, least determined first: ``{"std_ratio",
            "combination", "determined_by": [candidate keys of :data:`CANDIDATES`]}``.
        residual_rms_mm: ``{kind: RMS of the residuals}`` (mm) of each kind present.
        counts: the data's counts by kind.
        bed: the bed mode.
        iterations: Gauss-Newton iterations.
        directions_determined: the effective number of free directions the data determine.
        covariance: (P + 3, P + 3) the posterior covariance, parameter units; zero rows and
            columns for the held ones.
    """

    robot: Robot
    names: tuple
    values: np.ndarray
    std: np.ndarray
    prior_std: np.ndarray
    sources: dict
    left: tuple
    residual_rms_mm: dict
    counts: dict
    bed: str
    iterations: int
    directions_determined: float
    covariance: np.ndarray

    @property
    def theta(self) -> np.ndarray:
        """(P,) the robot's identified parameters."""
        return self.values[:self.robot.n_parameters].copy()

    @property
    def bed_plane(self) -> np.ndarray:
        """(3,) ``bed.z`` (mm), ``bed.tilt_x``, ``bed.tilt_y`` (rad)."""
        return self.values[self.robot.n_parameters:].copy()

    def by_name(self) -> dict[str, dict]:
        """JSON-ready ``{name: {"value", "std", "tolerance", "source"}}``."""
        return {n: {"value": float(v), "std": float(s), "tolerance": float(t), "source": self.sources[n]}
                for n, v, s, t in zip(self.names, self.values, self.std, self.prior_std)}

    def statement(self) -> str:
        """The observability statement in words (docs/klipper.md)."""
        free = [n for n in self.names if self.sources[n] != "held"]
        data = [n for n in free if self.sources[n] == "data"]
        counts = ", ".join(f"{v} {k}" for k, v in self.counts.items())
        lines = [f"{counts}; bed {self.bed}. The data determine {self.directions_determined:.1f} of the "
                 f"{len(free)} free directions; determined singly: {', '.join(data) or 'none'}."]
        if not self.left:
            lines.append("No combination is left to its tolerance.")
        for c in self.left:
            words = candidates_of(self.robot)
            fix = " or ".join(words[k] for k in c["determined_by"]) or "none of " + ", ".join(words.values())
            lines.append(f"Left to the tolerances (posterior {c['std_ratio']:.2f} of the prior): {c['combination']}; "
                         f"determined by: {fix}.")
        held = [n for n in self.names if self.sources[n] == "held"]
        if held:
            why = "no measurement tells them from the towers" if isinstance(self.robot, LinearDelta) else \
                "a gauge choice: each with its arm's joint zero is one direction no measurement fixes"
            lines.append(f"Held at nominal ({why}): {', '.join(held)}.")
        return "\n".join(lines)


def fit_probe(robot: Robot, data: ProbeData, *, noise: ProbeNoise | None = None,
              prior: ParameterPrior | None = None, free=None, max_iter: int = 30) -> ProbeFit:
    """The maximum a posteriori fit of ``robot``'s parameters and the bed to ``data`` (module
    docstring).

    Args:
        robot: the nominal robot (the prior's mean by default).
        data: the measurements.
        noise: their standard deviations (default :class:`ProbeNoise`'s).
        prior: the tolerances (default the robot's ``default_parameter_tolerance``).
        free: names of the robot's parameters to fit (default all but ``robot.machine_only`` and
            ``robot.gauge_fixed``);
            the bed's are added unless ``data.bed`` is ``"flat"``.
        max_iter: Gauss-Newton iterations at most.

    Raises:
        ProbeError: fewer measurements than the parameters asked for, or a name that is no
            parameter.
    """
    noise = ProbeNoise() if noise is None else noise
    prior = ParameterPrior.default(robot) if prior is None else prior
    names = tuple(robot.table.names) + BED_PARAMETERS
    free_idx = free_indices(robot, data, free)
    rows = sum(data.counts.values())
    if rows < free_idx.size:
        raise ProbeError(f"{rows} measurements ({', '.join(f'{v} {k}' for k, v in data.counts.items())}) for "
                         f"{free_idx.size} parameters asked for: give at least {free_idx.size} or free fewer")
    mean = np.concatenate([prior.mean, nominal_bed(robot)])
    tol = np.concatenate([prior.std, BED_TOLERANCE])
    x, iterations = gauss_newton(robot, data, noise, mean, tol, free_idx, max_iter)
    r, J, kinds = probe_rows(robot, x[:-3], x[-3:], data, noise)
    return fit_result(robot, data, noise, names, x, tol, free_idx, r, J, kinds, iterations)


def nominal_bed(robot: Robot) -> np.ndarray:
    """(3,) the bed plane as built: level, at the linear Delta's base frame (its z is measured from
    the bed), at the bottom of any other robot's workspace (a rotary Delta's base frame is at its
    shoulders, the bed below: :func:`calib.klipper_rotary.bed_depth`)."""
    height = 0.0 if isinstance(robot, LinearDelta) else float(robot.workspace_bounds()[2, 0])
    return np.array([height, 0.0, 0.0])


def candidates_of(robot: Robot) -> dict[str, str]:
    """The further measurements the observability statement tries for ``robot``, in words."""
    return CANDIDATES if isinstance(robot, LinearDelta) else ROTARY_CANDIDATES


def free_indices(robot: Robot, data: ProbeData, free) -> np.ndarray:
    """(K,) the free parameters' indices in the robot's parameters then the bed's."""
    names = list(robot.table.names)
    held = set(robot.machine_only) | set(robot.gauge_fixed)
    chosen = [n for n in names if n not in held] if free is None else list(free)
    unknown = [n for n in chosen if n not in names]
    if unknown:
        raise ProbeError(f"free: {unknown[0]!r} is not a parameter of the {robot.name} (e.g. {', '.join(names[:3])})")
    idx = [names.index(n) for n in chosen]
    if data.bed == "estimated":
        idx += [len(names) + k for k in range(len(BED_PARAMETERS))]
    return np.array(sorted(set(idx)), dtype=int)


def gauss_newton(robot, data, noise, mean, tol, idx, max_iter) -> tuple[np.ndarray, int]:
    """The MAP estimate (P + 3,) by Gauss-Newton on the measurement and prior rows, and the
    iterations run."""
    x = mean.copy()
    p = robot.n_parameters
    for it in range(1, max_iter + 1):
        r, J, _ = probe_rows(robot, x[:p], x[p:], data, noise)
        A = np.concatenate([J[:, idx], np.diag(1.0 / tol[idx])])
        b = np.concatenate([r, (x[idx] - mean[idx]) / tol[idx]])
        step = np.linalg.lstsq(A, -b, rcond=None)[0]
        x[idx] += step
        if np.max(np.abs(A @ step)) < STEP_TOL:
            return x, it
    return x, max_iter


def fit_result(robot, data, noise, names, x, tol, idx, r, J, kinds, iterations) -> ProbeFit:
    """The :class:`ProbeFit` at the solution ``x`` with its rows ``r, J``."""
    Jw = J[:, idx] * tol[idx]  # tolerance units
    info = Jw.T @ Jw
    cov_w = np.linalg.inv(info + np.eye(idx.size))
    std = tol.copy()
    std[idx] = np.sqrt(np.diag(cov_w)) * tol[idx]
    covariance = np.zeros((tol.size, tol.size))
    covariance[np.ix_(idx, idx)] = cov_w * np.outer(tol[idx], tol[idx])
    sources = dict.fromkeys(names, "held")
    src = parameter_sources(std[idx], tol[idx], x[idx] - np.concatenate([robot.table.nominal, nominal_bed(robot)])[idx])
    sources.update({names[i]: str(s) for i, s in zip(idx, src)})
    sigma = {"touch": noise.touch_mm, "manual": noise.manual_mm, "distance": noise.distance_mm}
    rms = {k: float(np.sqrt(np.mean((r[kinds == k] * sigma[k]) ** 2))) for k in sigma if np.any(kinds == k)}
    candidates = candidate_information(robot, x, data, noise, tol, idx)
    left = left_combinations(cov_w, info, candidates, [names[i] for i in idx])
    return ProbeFit(robot=robot, names=names, values=x, std=std, prior_std=tol, sources=sources, left=left,
                    residual_rms_mm=rms, counts=data.counts, bed=data.bed, iterations=iterations,
                    directions_determined=float(np.sum(1.0 - np.diag(cov_w))), covariance=covariance)


def left_combinations(cov_w, info, candidates: dict, names: list) -> tuple[dict, ...]:
    """The eigenvectors of the posterior covariance in tolerance units ``cov_w`` whose standard
    deviation ratio is at least :data:`calib.prior.DATA_SOURCE_RATIO`, each with the candidates
    (``{key: information matrix in tolerance units}``) that would bring it below."""
    lam, V = np.linalg.eigh(cov_w)
    out = []
    for j in np.flatnonzero(lam >= DATA_SOURCE_RATIO ** 2)[::-1]:
        v = V[:, j] if V[np.argmax(np.abs(V[:, j])), j] >= 0 else -V[:, j]
        by = [key for key, extra in candidates.items()
              if v @ np.linalg.solve(info + extra + np.eye(v.size), v) < DATA_SOURCE_RATIO ** 2]
        out.append({"std_ratio": float(np.sqrt(lam[j])), "combination": describe_combination(v, names),
                    "determined_by": by})
    return tuple(out)


def calibration_object_points() -> np.ndarray:
    """(12, 2, 3) the tool points of the calibration object's twelve distances on the bed (z = 0):
    six from the inner ridge to the outer pillar's far ridge along each direction, six across the
    outer pillars (from each pillar to the one two directions on, along that direction)."""
    a = np.asarray(CALIBRATION_OBJECT_ANGLES_RAD)
    u = np.stack([np.cos(a), np.sin(a), np.zeros(a.size)], axis=1)
    ridge, outer = CALIBRATION_OBJECT_RADII_MM
    centre = np.stack([u * ridge, u * (outer + ridge)], axis=1)
    across = np.roll(u, -2, axis=0)
    pillars = np.stack([u * outer + across * ridge, u * outer + across * (outer + ridge)], axis=1)
    return np.concatenate([centre, pillars])


def candidate_information(robot, x, data: ProbeData, noise: ProbeNoise, tol, idx) -> dict[str, np.ndarray]:
    """``{key of candidates_of(robot): (K, K) information}`` each further measurement would add, in
    tolerance units, at the fitted machine (its joints from the fitted inverse kinematics); a
    measurement the robot cannot reach (a gauge block above a rotary Delta's workspace) is left out."""
    p = robot.n_parameters
    theta, bed = x[:p], x[p:]
    touch = robot.forward_kinematics(theta, data.touch_joints) if len(data.touch_z_mm) else np.zeros((0, 3))
    out = {}
    for key, extra in further_data(robot, theta, bed, touch, data.bed).items():
        J = probe_rows(robot, theta, bed, extra, noise)[1][:, idx] * tol[idx]
        out[key] = J.T @ J
    if len(touch):
        dX = tool_points_and_jacobian(robot, theta, data.touch_joints)[1].reshape(-1, p) / noise.touch_mm
        J = np.concatenate([dX, np.zeros((dX.shape[0], 3))], axis=1)[:, idx] * tol[idx]
        out["position"] = J.T @ J
    if "joint zero" in candidates_of(robot):
        J = np.zeros((len(robot.joint_zero_names), p + 3))
        J[np.arange(J.shape[0]), robot.table.indices(robot.joint_zero_names)] = 1.0 / JOINT_ZERO_STD_RAD
        J = J[:, idx] * tol[idx]
        out["joint zero"] = J.T @ J
    return out


def further_data(robot, theta, bed, touch, bed_mode) -> dict[str, ProbeData]:
    """``{"manual", "distance": ProbeData}``: the gauge blocks on the touches and the calibration
    object as the fitted machine would measure them, those it can reach."""
    gauge = np.concatenate([touch + [0.0, 0.0, h] for h in GAUGE_HEIGHTS_MM])
    ends = calibration_object_points()
    ends[..., 2] = bed[0] + ends[..., :2] @ bed[1:]
    out = {}
    try:
        out["manual"] = ProbeData(np.zeros((0, 3)), np.zeros(0), robot.inverse_kinematics(theta, gauge),
                                  gauge[:, 2] - bed[0] - gauge[:, :2] @ bed[1:], bed=bed_mode)
    except KinematicsError:
        pass
    try:
        out["distance"] = ProbeData(np.zeros((0, 3)), np.zeros(0), distance_joints=robot.inverse_kinematics(
            theta, ends.reshape(-1, 3)).reshape(-1, 2, 3), distance_mm=np.linalg.norm(ends[:, 0] - ends[:, 1], axis=1),
            bed=bed_mode)
    except KinematicsError:
        pass
    return out

