"""``compliance``: each actuator gives way under the load it carries (servo of finite stiffness),
the loads following from the static equilibrium of the platform under its weight."""

from __future__ import annotations

import numpy as np

from ..robot import Robot, pose_jacobian_of_joints
from ..rotation import rotation_matrix_derivatives
from .base import Coefficient, Effect, EffectScenario, PhysicalParameter, scale_to_magnitude

__all__ = ["EFFECT", "Compliance", "COM_HEIGHT_REF_MM", "PAYLOAD_RANGE_KG"]

#: Unit of the centre-of-mass height in the second coefficient, mm (conditioning).
COM_HEIGHT_REF_MM = 100.0
#: Payloads drawn by the scenarios, kg.
PAYLOAD_RANGE_KG = (0.0, 5.0)
#: Names of the orientation coordinates the centre-of-mass term understands
#: (``R = Rz(gamma) Ry(beta) Rx(alpha)``, :mod:`calib.rotation`).
EULER_ANGLES = ("alpha", "beta", "gamma")


def _angle_columns(robot: Robot) -> list[int]:
    return [robot.pose_names.index(a) for a in EULER_ANGLES if a in robot.pose_names]


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

    (A leg's own weight would add a regressor, but one the geometric errors absorb: on a
    hexapod it is exactly the derivative of the leg length with respect to its base joint's
    height. It is left out.)

    Applies to robots whose pose has a height ``z`` along gravity (base z up) and, if it
    rotates, the Euler angles ``alpha, beta, gamma`` of :mod:`calib.rotation`: every robot of
    this package, prismatic (the legs shorten) or revolute (the motors turn back).
    """

    name = "compliance"
    physics = ("each actuator gives way by its load over its stiffness; the loads come from the static "
               "equilibrium of the platform under the weight of platform and payload")
    follows = "load"

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
        return out

    def generalised_weight(self, robot: Robot, poses: np.ndarray) -> np.ndarray:
        """(N, D, p) generalised force of a unit weight on the pose coordinates, per coefficient:
        at the platform origin (``-grad z``), and per :data:`COM_HEIGHT_REF_MM` of centre-of-mass
        height (``-grad (R e_z)_z``, mm per rad)."""
        n = poses.shape[0]
        Q = np.zeros((n, robot.pose_dim, len(self.coefficients(robot))))
        Q[:, robot.pose_names.index("z"), 0] = -1.0
        if self._rotates(robot):
            cols = _angle_columns(robot)
            dR = rotation_matrix_derivatives(poses[:, cols])  # (N, 3 angles, 3, 3)
            Q[:, cols, 1] = -COM_HEIGHT_REF_MM * dR[:, :, 2, 2]
        return Q

    def joint_regressors(self, robot, theta, data, extra=None):
        J = pose_jacobian_of_joints(robot, theta, data.joints, data.measured)  # (N, D, C)
        return np.einsum("ndc,ndp->ncp", J, self.generalised_weight(robot, data.measured))

    def machine_settings(self, coefficients, robot, context, extra=None):
        # dq [joint unit] = c0 * (J^T Q); in SI tau = W (J^T Q) m_per_mm / s and dq_SI = tau / k,
        # s the SI per joint unit: k = W m_per_mm / (s^2 c0).
        weight = context.moving_mass_kg * context.gravity_m_s2
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
        shape = np.ones(len(self.coefficients(robot)))
        if self._rotates(robot):
            # The platform's own centre of mass at its origin, the payload's at payload_height_m.
            com_mm = loaded.payload_height_m / loaded.m_per_mm * loaded.payload_kg / loaded.moving_mass_kg
            shape[1] = com_mm / COM_HEIGHT_REF_MM
        X = self.regressors(robot, theta, data)
        return EffectScenario(scale_to_magnitude(X, shape, magnitude_mm), None, loaded)


EFFECT = Compliance()
