"""``actuator_scale``: each actuator's stroke is scaled by ``1 + s_i`` (transmission error)."""

from __future__ import annotations

import numpy as np

from .base import Coefficient, Effect, EffectScenario, scale_to_magnitude, unabsorbed

__all__ = ["EFFECT", "ActuatorScale"]


class ActuatorScale(Effect):
    """Chain i's joint moves ``(1 + s_i)`` times its commanded stroke from the centre of travel:
    ``dq_i = s_i (q_i - q_centre_i)`` (a screw lead, gear ratio or encoder scale off by s_i; a
    different reference point only adds a constant the joint offsets absorb).

    Applies to every robot: prismatic and revolute actuators both have a transmission ratio.
    On a revolute actuator, though, a scale of the angle moves the crank tip nearly as a longer
    crank does (to first order in the swing about the centre of travel): on the Delta's and the
    6-RUS's scenario workspaces the geometric errors absorb 97-99% of its closure contribution
    (a gear ratio off by 1e-3 leaves a few micrometres). Its scenarios on such a robot size the
    part the geometry cannot absorb (:func:`~calib.effects.base.unabsorbed`), not the raw
    contribution, which is then 30-70 times larger.
    """

    name = "actuator_scale"
    physics = "each actuator's stroke is scaled by 1 + s_i (transmission error)"
    granularity = "per_chain"  # already one coefficient per chain (no shared form)
    follows = "stroke"

    def coefficients(self, robot):
        return tuple(Coefficient(f"scale{i + 1}", "1") for i in range(robot.n_chains))

    def joint_regressors(self, robot, theta, data, extra=None):
        c = robot.n_chains
        X = np.zeros((data.n, c, c))
        X[:, np.arange(c), np.arange(c)] = data.stroke
        return X

    def machine_settings(self, coefficients, robot, context, extra=None):
        return {"options": {"transmission_scale": tuple(float(v) for v in coefficients)}, "effects": {}}

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        c = robot.n_chains
        u = rng.uniform(0.3, 1.0, c) * rng.choice([-1.0, 1.0], c)
        shape = u / np.abs(data.stroke).max(axis=0)
        X = self.regressors(robot, theta, data)
        if robot.joint_unit != "mm":
            X = unabsorbed(robot, theta, data, X)
        return EffectScenario(scale_to_magnitude(X, shape, magnitude_mm), None, context)


EFFECT = ActuatorScale()
