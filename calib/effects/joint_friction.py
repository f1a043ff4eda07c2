"""``joint_friction``: a dead band; each actuated joint stops short of its target against the
direction in which it last moved (Coulomb friction against a position servo of finite stiffness)."""

from __future__ import annotations

import numpy as np

from .base import Coefficient, Effect, EffectScenario, PhysicalParameter, scale_to_magnitude

__all__ = ["EFFECT", "JointFriction"]


class JointFriction(Effect):
    """Dead band ``delta``: the joint comes to rest where its servo force ``k (q_cmd - q)``
    equals the Coulomb friction ``F``, i.e. ``dq = -delta * direction``, ``delta = F / k``.

    Applies to every robot: any actuated joint, prismatic or revolute, held by a servo of finite
    stiffness has one (the dead band in mm or rad).
    """

    name = "joint_friction"
    physics = "a dead band: each actuator stops short of its target against the direction it last moved"
    history_dependent = True
    follows = "direction of the last move"
    per_chain_capable = ("dead_band",)

    def coefficients(self, robot):
        return (Coefficient("dead_band", robot.joint_unit),)

    def joint_regressors(self, robot, theta, data, extra=None):
        return -data.direction[..., None]

    def machine_settings(self, coefficients, robot, context, extra=None):
        # Friction force = dead band x servo stiffness (SI: N for a prismatic joint, N m for a
        # revolute one); the stiffness is set too, so that the mapping holds on any machine. A
        # stiffness per chain gives a friction force per chain.
        dead_band_si = max(float(coefficients[0]), 0.0) * context.si_per_joint_unit(robot)
        k = context.servo_stiffness
        friction = dead_band_si * k if np.isscalar(k) else tuple(dead_band_si * float(v) for v in k)
        return {"options": {"joint_friction": friction, "actuator_stiffness": k}, "effects": {}}

    def physical_parameter(self, robot):
        return PhysicalParameter("options", "joint_friction", "N" if robot.joint_unit == "mm" else "N m")

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        X = self.regressors(robot, theta, data)
        return EffectScenario(scale_to_magnitude(X, np.ones(1), magnitude_mm), None, context)


EFFECT = JointFriction()
