"""``periodic_screw_error``: an error periodic in each leg's stroke, the same unknown pitch on
every lead screw (prismatic legs only)."""

from __future__ import annotations

import numpy as np

from .base import Coefficient, Effect, EffectScenario, SearchedParameter

__all__ = ["EFFECT", "PeriodicScrewError", "PITCH_RANGE_MM"]

#: Search range of the screw pitch, mm.
PITCH_RANGE_MM = (1.0, 30.0)
#: Grid points per period over the stroke span (the frequency grid's fineness).
GRID_POINTS_PER_SPAN = 6.0


class PeriodicScrewError(Effect):
    """``dq_i = a_i sin(2 pi s_i / p) + b_i cos(2 pi s_i / p)``, ``s_i`` the stroke from the
    centre of travel, ``p`` the screw pitch (searched in :data:`PITCH_RANGE_MM`).

    Applies to robots whose actuators are lead screws, i.e. actuated lengths
    (``joint_unit == "mm"``). A revolute actuator's periodic transmission error (gear
    eccentricity, cogging) has a period in rad set by the gear train, not a screw pitch, and
    other search ranges; it is not this effect.
    """

    name = "periodic_screw_error"
    physics = "an error periodic in each leg's stroke, the same (unknown) pitch on every screw"
    searched = SearchedParameter("pitch", "mm")
    follows = "stroke"

    def applies_to(self, robot):
        return robot.joint_unit == "mm"

    def coefficients(self, robot):
        return tuple(Coefficient(f"{ab}{i + 1}", robot.joint_unit)
                     for i in range(robot.n_chains) for ab in ("sin", "cos"))

    def joint_regressors(self, robot, theta, data, extra=None):
        if extra is None:
            raise ValueError("periodic_screw_error needs the pitch (extra)")
        c = robot.n_chains
        phase = 2 * np.pi * data.stroke / extra
        X = np.zeros((data.n, c, 2 * c))
        X[:, np.arange(c), 2 * np.arange(c)] = np.sin(phase)
        X[:, np.arange(c), 2 * np.arange(c) + 1] = np.cos(phase)
        return X

    def search_grid(self, data):
        """Frequencies ``1 / pitch`` over :data:`PITCH_RANGE_MM`, fine enough for the stroke span."""
        span = max(float(np.ptp(data.stroke)), 1.0)
        return np.arange(1.0 / PITCH_RANGE_MM[1], 1.0 / PITCH_RANGE_MM[0], 1.0 / (GRID_POINTS_PER_SPAN * span))

    def searched_value(self, u):
        return float(1.0 / u)

    def machine_settings(self, coefficients, robot, context, extra=None):
        # a sin + b cos = A sin(. + phase), A = hypot(a, b), phase = atan2(b, a).
        a, b = np.asarray(coefficients[0::2], dtype=float), np.asarray(coefficients[1::2], dtype=float)
        return {"options": {},
                "effects": {"screw_amplitude": tuple(np.hypot(a, b)), "screw_phase_rad": tuple(np.arctan2(b, a)),
                            "screw_pitch": float(extra)}}

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        c = robot.n_chains
        pitch = float(rng.uniform(2.0, 10.0))
        amplitude = rng.uniform(0.5, 1.0, c)
        phase = rng.uniform(0, 2 * np.pi, c)
        # The largest possible contribution of chain i is |dF/dq_i| A_i.
        dF_dq = np.abs(np.diagonal(robot.closure_jacobians(theta, data.joints, data.measured).joints, axis1=1, axis2=2))
        amplitude *= magnitude_mm / np.max(amplitude * dF_dq.max(axis=0))
        coefficients = np.ravel(np.column_stack([amplitude * np.cos(phase), amplitude * np.sin(phase)]))
        return EffectScenario(coefficients, pitch, context)


EFFECT = PeriodicScrewError()
