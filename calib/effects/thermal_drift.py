"""``thermal_drift``: every leg grows at a constant rate with time (prismatic legs only)."""

from __future__ import annotations

import numpy as np

from .base import Coefficient, Effect, EffectScenario, PhysicalParameter, scale_to_magnitude

__all__ = ["EFFECT", "ThermalDrift"]


class ThermalDrift(Effect):
    """Each actuated length grows at the same rate ``g``: ``dq = g t``.

    Applies to robots whose actuated joints are lengths (``joint_unit == "mm"``): a leg (screw,
    tube, rod) warming up grows along its axis, which is exactly a drift of the actuated length.
    On a revolute actuator warming lengthens the links (crank, rod, arm), which changes the
    geometry's parameters, not the joint angle; a drifting joint angle has no thermal cause,
    so this joint-space effect does not describe it.
    """

    name = "thermal_drift"
    physics = "every leg grows at a constant rate with time"
    follows = "time"
    per_chain_capable = ("growth_rate",)

    def applies_to(self, robot):
        return robot.joint_unit == "mm"

    def coefficients(self, robot):
        return (Coefficient("growth_rate", f"{robot.joint_unit}/s"),)

    def joint_regressors(self, robot, theta, data, extra=None):
        return np.broadcast_to(data.t_s[:, None, None], (data.n, robot.n_chains, 1)).copy()

    def machine_settings(self, coefficients, robot, context, extra=None):
        return {"options": {}, "effects": {"joint_drift_per_s": float(coefficients[0])}}

    def physical_parameter(self, robot):
        return PhysicalParameter("effects", "joint_drift_per_s", f"{robot.joint_unit}/s")

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        X = self.regressors(robot, theta, data)
        return EffectScenario(scale_to_magnitude(X, np.ones(1), magnitude_mm), None, context)


EFFECT = ThermalDrift()
