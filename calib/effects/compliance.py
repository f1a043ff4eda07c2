"""``compliance``: each actuator gives way under the load it carries (servo of finite stiffness),
the loads following from the static equilibrium of the platform under its weight and of the
chains under their own weight."""

from __future__ import annotations

import numpy as np

from ..robot import Robot, pose_jacobian_of_joints
from ..rotation import rotation_matrix_derivatives
from .base import PAYLOAD_CHANNEL, Coefficient, Effect, EffectScenario, PhysicalParameter, scale_to_magnitude

__all__ = ["EFFECT", "Compliance", "LoadedCompliance", "LOADED", "COM_HEIGHT_REF_MM", "PAYLOAD_RANGE_KG",
           "TWO_PAYLOADS_KG", "interior_points", "chain_point_height_gradient", "payload_varies", "for_payload"]

#: Unit of the centre-of-mass height in the second coefficient, mm (conditioning).
COM_HEIGHT_REF_MM = 100.0
#: Payloads drawn by the scenarios, kg.
PAYLOAD_RANGE_KG = (0.0, 5.0)
#: A recording taken at two payloads (:func:`pipeline.simulation.effect_recording`,
#: ``payloads=2``): a light one drawn in the first range and a heavy one in the second, kg.
TWO_PAYLOADS_KG = ((0.0, 1.0), (3.0, 5.0))
#: Two rows' payloads differing by less than this are one payload, kg.
PAYLOAD_TOLERANCE_KG = 1e-6
#: Names of the orientation coordinates the centre-of-mass term understands
#: (``R = Rz(gamma) Ry(beta) Rx(alpha)``, :mod:`calib.rotation`).
EULER_ANGLES = ("alpha", "beta", "gamma")


#: Finite-difference steps of the chain points' heights: per joint or pose unit (mm, rad).
FD_STEP_MM, FD_STEP_RAD = 1e-4, 1e-6


def _angle_columns(robot: Robot) -> list[int]:
    return [robot.pose_names.index(a) for a in EULER_ANGLES if a in robot.pose_names]


def interior_points(robot: Robot) -> int:
    """Number of points of each chain between its base joint and its platform joint."""
    theta = robot.table.nominal
    home = robot.home_pose[None]
    return robot.chain_points(theta, robot.inverse_kinematics(theta, home), home).shape[2] - 2


def _step(unit: str) -> float:
    return FD_STEP_RAD if unit == "rad" else FD_STEP_MM


def chain_point_height_gradient(robot: Robot, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray,
                                pose_jacobian: np.ndarray) -> np.ndarray:
    """(N, C, K) ``sum_j d z_jk / d q_i`` along the mechanism (the pose following the joints):
    the height gradient of the chains' interior points k, mm per joint unit (central differences
    on :meth:`~calib.robot.Robot.chain_points`).

    Args:
        pose_jacobian: (N, D, C) ``d pose / d q`` at the same configurations.
    """
    def z(q, x):
        return robot.chain_points(theta, q, x)[:, :, 1:-1, 2].sum(axis=1)  # (N, K) summed over chains

    n, c = joints.shape
    k = interior_points(robot)
    hq = _step(robot.joint_unit)
    direct = np.empty((n, c, k))
    for i in range(c):
        e = np.zeros(c)
        e[i] = hq
        direct[:, i] = (z(joints + e, poses) - z(joints - e, poses)) / (2 * hq)
    via_pose = np.zeros((n, robot.pose_dim, k))
    for d, unit in enumerate(robot.pose_units):
        h = _step(unit)
        e = np.zeros(robot.pose_dim)
        e[d] = h
        via_pose[:, d] = (z(joints, poses + e) - z(joints, poses - e)) / (2 * h)
    return direct + np.einsum("ndc,ndk->nck", pose_jacobian, via_pose)


class Compliance(Effect):
    """Each actuated joint deflects by ``-tau_i / k``, ``tau`` the actuator forces that hold the
    platform's weight, ``k`` the servo stiffness.

    The forces come from the static equilibrium by virtual work, for any robot: with the pose
    as a function of the joints through the closure, ``J = d pose / d q = -(dF/dpose)^-1 dF/dq``,
    the weight's generalised force on the pose coordinates is ``Q = -grad_pose (m g z_com)``
    with ``z_com = z + (R c)_z`` for a centre of mass ``c = (0, 0, h)`` in the platform frame;
    equilibrium ``tau^T dq + Q^T J dq = 0`` for every virtual ``dq`` gives ``tau = -J^T Q``, so
    ``dq = J^T Q / k``. Linear in ``m g / k`` and ``m g h / k``: two coefficients (the second
    only for a platform that rotates; a translating platform's ``R`` is fixed).

    The chains' own weight (the legs' masses): lumped at the chain's points
    (:meth:`calib.robot.Robot.chain_points`), a mass ``m`` at an interior point ``p_ik`` (a
    Delta's elbow, a 6-RUS crank tip) adds ``m g p_ik,z`` to the potential energy, hence
    ``dq = -(m g / k) d p_ik,z / dq`` (total derivative, through the pose): one more coefficient
    per interior point, whose load follows the chain's own orientation, not the platform's.
    Masses lumped at the platform joints only add to the platform's weight. A hexapod leg has no
    interior point (base joint to platform joint): its weight along its axis is proportional to
    the leg's vertical direction cosine, exactly the derivative of the leg length with respect to
    its base joint's height, which the geometric errors absorb; it has no coefficient.

    Applies to robots whose pose has a height ``z`` along gravity (base z up) and, if it
    rotates, the Euler angles ``alpha, beta, gamma`` of :mod:`calib.rotation`: every robot of
    this package, prismatic (the legs shorten) or revolute (the motors turn back).
    """

    name = "compliance"
    physics = ("each actuator gives way by its load over its stiffness; the loads come from the static "
               "equilibrium of the platform under the weight of platform and payload")
    follows = "load"
    # One stiffness per chain divides every load term of that chain; the per-chain form gives
    # each chain its own weight terms and keeps the centre-of-mass height term shared (a lever
    # arm's correction: a chain of its own there would cost C - 1 parameters for a second-order
    # term, and the evidence would not pay for them).
    per_chain_capable = ("weight_over_stiffness", "chain_weight_over_stiffness", "chain_weight_over_stiffness1",
                         "chain_weight_over_stiffness2")

    def applies_to(self, robot):
        angles = [u == "rad" for u in robot.pose_units]
        return "z" in robot.pose_names and len(_angle_columns(robot)) in (0, 3) \
            and sum(angles) == len(_angle_columns(robot))

    def _rotates(self, robot: Robot) -> bool:
        return len(_angle_columns(robot)) == 3

    def coefficients(self, robot):
        # m g / k: N over N/mm is mm for a prismatic joint; N over N mm/rad is rad/mm for a
        # revolute one (times d z / d q in mm/rad gives rad).
        unit = "mm" if robot.joint_unit == "mm" else f"{robot.joint_unit}/mm"
        out = (Coefficient("weight_over_stiffness", unit),)
        if self._rotates(robot):
            out += (Coefficient("weight_x_com_height_over_stiffness", f"{unit} x {COM_HEIGHT_REF_MM:g} mm"),)
        k = interior_points(robot)
        out += tuple(Coefficient(f"chain_weight_over_stiffness{'' if k == 1 else j + 1}", unit) for j in range(k))
        return out

    def _n_platform(self, robot: Robot) -> int:
        return 2 if self._rotates(robot) else 1

    def generalised_weight(self, robot: Robot, poses: np.ndarray) -> np.ndarray:
        """(N, D, p) generalised force of a unit weight on the pose coordinates, per coefficient:
        at the platform origin (``-grad z``), and per :data:`COM_HEIGHT_REF_MM` of centre-of-mass
        height (``-grad (R e_z)_z``, mm per rad)."""
        n = poses.shape[0]
        Q = np.zeros((n, robot.pose_dim, self._n_platform(robot)))
        Q[:, robot.pose_names.index("z"), 0] = -1.0
        if self._rotates(robot):
            cols = _angle_columns(robot)
            dR = rotation_matrix_derivatives(poses[:, cols])  # (N, 3 angles, 3, 3)
            Q[:, cols, 1] = -COM_HEIGHT_REF_MM * dR[:, :, 2, 2]
        return Q

    def joint_regressors(self, robot, theta, data, extra=None):
        J = pose_jacobian_of_joints(robot, theta, data.joints, data.regressor_poses)  # (N, D, C)
        X = np.einsum("ndc,ndp->ncp", J, self.generalised_weight(robot, data.regressor_poses))
        if interior_points(robot) == 0:
            return X
        return np.concatenate([X, -chain_point_height_gradient(robot, theta, data.joints, data.regressor_poses, J)], axis=2)

    def machine_settings(self, coefficients, robot, context, extra=None):
        # dq [joint unit] = c0 * (J^T Q); in SI tau = W (J^T Q) m_per_mm / s and dq_SI = tau / k,
        # s the SI per joint unit: k = W m_per_mm / (s^2 c0). W: what the platform carries,
        # its payload and the chains' masses lumped at the platform joints.
        weight = _platform_load_kg(robot, context) * context.gravity_m_s2
        s = context.si_per_joint_unit(robot)
        c0 = max(float(coefficients[0]), 1e-12)
        return {"options": {"gravity": True, "payload_kg": context.payload_kg,
                            "payload_height_m": context.payload_height_m,
                            "platform_mass_kg": context.platform_mass_kg,
                            "actuator_stiffness": weight * context.m_per_mm / (s * s * c0)},
                "effects": {}}

    def physical_parameter(self, robot):
        return PhysicalParameter("options", "actuator_stiffness", "N/m" if robot.joint_unit == "mm" else "N m/rad")

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        loaded = context.with_payload(rng.uniform(*PAYLOAD_RANGE_KG))
        X = self.regressors(robot, theta, data)
        return EffectScenario(scale_to_magnitude(X, self._shape(robot, loaded), magnitude_mm), None, loaded)

    def _shape(self, robot: Robot, loaded) -> np.ndarray:
        """(p,) the coefficients' ratios on the machine ``loaded`` (every one a weight over the
        same stiffness: their ratios are the masses' and lever arms')."""
        shape = np.ones(len(Compliance.coefficients(self, robot)))
        load = _platform_load_kg(robot, loaded)
        if self._rotates(robot):
            # The platform's own centre of mass at its origin (the lumped joint masses too, the
            # joints about its origin), the payload's at payload_height_m.
            com_mm = loaded.payload_height_m / loaded.m_per_mm * loaded.payload_kg / load
            shape[1] = com_mm / COM_HEIGHT_REF_MM
        k = interior_points(robot)
        if k:
            masses = _chain_masses(robot, loaded)
            shape[self._n_platform(robot):] = masses[:k] / load
        return shape


def payload_varies(data) -> bool:
    """Whether ``data`` records the payload row by row and it is not the same at every row."""
    p = getattr(data, "payload_kg", None)
    return p is not None and p.size > 0 and float(np.ptp(p)) > PAYLOAD_TOLERANCE_KG


class LoadedCompliance(Compliance):
    """``compliance`` on a recording whose payload changes from row to row (a recorded
    ``payload_kg`` channel, :data:`calib.effects.base.PAYLOAD_CHANNEL`).

    The platform's load terms scale with what it carries: ``dq = (g / k) (M + p_n) J^T Q_unit``
    (and the centre-of-mass term with ``M h + p_n h_p``), ``M`` the platform's own mass, which
    the analysis does not know. Linear all the same: the shared coefficients keep their
    meaning at the recording's mean payload ``p̄`` (``weight_over_stiffness``: ``(M + p̄) g / k``,
    as on a recording at one payload), and each platform term gets a payload twin, its column
    times ``p_n - p̄``: ``payload_over_stiffness`` is ``g / k`` per kg of payload, the servo's
    compliance itself, with no mass to know (and ``payload_x_com_height_over_stiffness`` the
    payload's lever arm over the stiffness, on a rotating platform). The chains' own weight does
    not change with the payload.

    Why it matters: the geometric errors absorb most of a load pattern taken at one payload (on
    the Delta about 93% of it: a translating platform's weight pattern is close to what its
    crank lengths and offsets do), but not the change of the pattern between two payloads,
    which no geometry makes (on the Delta's scenario workspace 64% of the payload twin's column
    is left by the geometry, against 8% of the load column); and an actuator scale, fixed,
    cannot follow it either.

    Used in place of :data:`EFFECT` where the payload varies (:func:`for_payload`); same name.
    Its per-chain form gives every chain its own payload term (its own stiffness) and keeps the
    weight terms shared (see ``per_chain_capable``): a chain's own stiffness also scales its
    weight terms, but that pattern is what the chain's own geometric parameters absorb, and left
    free per chain it took an actuator scale's place.
    """

    # The per-chain form: each chain's own payload term (its own stiffness, seen in the change of
    # load no geometry makes); the weight terms at the mean payload stay shared. With them per
    # chain too (9 coefficients on the Delta) the per-chain weight columns, each 0.9 correlated
    # with that chain's actuator scale, took the scale's place: on the Delta's two-payload
    # compliance + actuator_scale recordings (seeds 100-107) both were named in 4 of 8, against
    # 8 of 8 with only the payload term per chain (and 6 of 8 against 8 of 8 single compliance
    # recordings named alone).
    per_chain_capable = ("payload_over_stiffness",)
    # Its evidence (the Wald test of discovery) is the payload terms: a servo's compliance gives
    # way more under the heavier payload; load terms without it are something else the load
    # pattern happens to resemble (a transmission error quadratic in the stroke, on a revolute
    # robot), which the geometry and the weight terms may fit.
    evidence_coefficients = ("payload_over_stiffness", "payload_x_com_height_over_stiffness")

    def __init__(self, reference_payload_kg: float | None = None):
        #: The payload the weight terms stand for, kg: the mean of the data the regressors are
        #: evaluated on (None, as when fitting), or, to act on other data (commands at other
        #: payloads), the mean of the recording the coefficients were fitted on.
        self.reference_payload_kg = None if reference_payload_kg is None else float(reference_payload_kg)

    def compensation_inputs(self):
        return (PAYLOAD_CHANNEL,)  # each command's payload: the load follows it

    def coefficients(self, robot):
        base = Compliance.coefficients(self, robot)
        unit = base[0].unit
        out = (Coefficient("payload_over_stiffness", f"{unit}/kg"),)
        if self._rotates(robot):
            out += (Coefficient("payload_x_com_height_over_stiffness", f"{unit}/kg x {COM_HEIGHT_REF_MM:g} mm"),)
        return base + out

    def joint_regressors(self, robot, theta, data, extra=None):
        X = Compliance.joint_regressors(self, robot, theta, data, extra)
        npl = self._n_platform(robot)
        if data.payload_kg is None:
            dp = np.zeros(data.n)
        else:
            reference = data.payload_kg.mean() if self.reference_payload_kg is None else self.reference_payload_kg
            dp = data.payload_kg - reference
        return np.concatenate([X, X[:, :, :npl] * dp[:, None, None]], axis=2)

    def machine_settings(self, coefficients, robot, context, extra=None):
        # The machine at the mean payload (the payload of each row is the recording's: the
        # simulation sets it run by run); the stiffness from the payload term, g / k per kg
        # (the weight term's own mass is unknown to the fit; on a drawn scenario the two agree).
        out = Compliance.machine_settings(self, coefficients, robot, context, extra)
        cp = max(float(coefficients[len(Compliance.coefficients(self, robot))]), 1e-12)
        s = context.si_per_joint_unit(robot)
        out["options"]["actuator_stiffness"] = context.gravity_m_s2 * context.m_per_mm / (s * s * cp)
        return out

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        """The payloads are the recording's (``data.payload_kg``, drawn by the experiment, not by
        the effect): the machine at their mean, each payload twin the platform term per kg."""
        if data.payload_kg is None:
            raise ValueError("a loaded compliance scenario needs the planned payload of every row")
        loaded = context.with_payload(float(data.payload_kg.mean()))
        shape = self._shape(robot, loaded)
        npl = self._n_platform(robot)
        load = _platform_load_kg(robot, loaded)
        twin = np.array([1.0 / load] + ([loaded.payload_height_m / loaded.m_per_mm / COM_HEIGHT_REF_MM / load]
                                        if self._rotates(robot) else []))[:npl]
        shape = np.concatenate([shape, twin])
        X = self.regressors(robot, theta, data)
        return EffectScenario(scale_to_magnitude(X, shape, magnitude_mm), None, loaded)


def _chain_masses(robot: Robot, context) -> np.ndarray:
    """(K + 1,) the chains' lumped masses at their interior points and platform joint, kg
    (zeros when the machine does not say)."""
    m = np.asarray(context.chain_point_masses_kg, dtype=float)
    k = interior_points(robot)
    return m if m.size == k + 1 else np.zeros(k + 1)


def _platform_load_kg(robot: Robot, context) -> float:
    """Mass the platform's weight coefficient stands for: platform, payload and every chain's
    mass lumped at its platform joint, kg."""
    return context.moving_mass_kg + robot.n_chains * float(_chain_masses(robot, context)[-1])


EFFECT = Compliance()
#: The payload-aware form (one object, so that caches keyed on it hold).
LOADED = LoadedCompliance()


def for_payload(eff, data):
    """``eff``, or its payload-aware form where ``data``'s payload varies (:class:`LoadedCompliance`
    in place of :class:`Compliance`; any other effect unchanged)."""
    if type(eff) is Compliance and payload_varies(data):
        return LOADED
    return eff
