"""``periodic_screw_error``: an error periodic in each leg's stroke, the same unknown pitch on
every lead screw (prismatic legs only); amplitude and phase shared, or each screw its own (the
per-chain form)."""

from __future__ import annotations

import numpy as np

from .base import SPREAD_RANGE, Coefficient, Effect, EffectScenario, SearchedParameter

__all__ = ["EFFECT", "PeriodicScrewError", "PITCH_RANGE_MM"]

#: Search range of the screw pitch, mm.
PITCH_RANGE_MM = (1.0, 30.0)
#: Grid points per period over the stroke span (the frequency grid's fineness).
GRID_POINTS_PER_SPAN = 6.0


class PeriodicScrewError(Effect):
    """``dq_i = a sin(2 pi s_i / p) + b cos(2 pi s_i / p)``, ``s_i`` the stroke from the
    centre of travel, ``p`` the screw pitch (searched in :data:`PITCH_RANGE_MM`): shared, the
    same amplitude and phase on every screw; its per-chain form
    (:func:`calib.effects.granularity.per_chain_form`) gives each screw its own ``a_i, b_i``
    (amplitude and phase), the pitch still shared (one screw model).

    Applies to robots whose actuators are lead screws, i.e. actuated lengths
    (``joint_unit == "mm"``). A revolute actuator's periodic transmission error (gear
    eccentricity, cogging) has a period in rad set by the gear train, not a screw pitch, and
    other search ranges; it is not this effect.
    """

    name = "periodic_screw_error"
    physics = "an error periodic in each leg's stroke, the same (unknown) pitch on every screw"
    searched = SearchedParameter("pitch", "mm")
    follows = "stroke"
    per_chain_capable = ("sin", "cos")

    def applies_to(self, robot):
        return robot.joint_unit == "mm"

    def coefficients(self, robot):
        return (Coefficient("sin", robot.joint_unit), Coefficient("cos", robot.joint_unit))

    def joint_regressors(self, robot, theta, data, extra=None):
        if extra is None:
            raise ValueError("periodic_screw_error needs the pitch (extra)")
        phase = 2 * np.pi * data.stroke / extra
        return np.stack([np.sin(phase), np.cos(phase)], axis=-1)

    def search_grid(self, data):
        """Frequencies ``1 / pitch`` over :data:`PITCH_RANGE_MM`, fine enough for the stroke span."""
        span = max(float(np.ptp(data.stroke)), 1.0)
        return np.arange(1.0 / PITCH_RANGE_MM[1], 1.0 / PITCH_RANGE_MM[0], 1.0 / (GRID_POINTS_PER_SPAN * span))

    def searched_value(self, u):
        return float(1.0 / u)

    def machine_settings(self, coefficients, robot, context, extra=None):
        # a sin + b cos = A sin(. + phase), A = hypot(a, b), phase = atan2(b, a).
        a, b = float(coefficients[0]), float(coefficients[1])
        c = robot.n_chains
        return {"options": {},
                "effects": {"screw_amplitude": (float(np.hypot(a, b)),) * c,
                            "screw_phase_rad": (float(np.arctan2(b, a)),) * c, "screw_pitch": float(extra)}}

    def per_chain_draw(self, robot, shared, capable, rng):
        """Each screw its own amplitude (the shared one times :data:`~calib.effects.base.SPREAD_RANGE`)
        and its own phase (uniform)."""
        c = robot.n_chains
        amplitude = np.hypot(*shared[:2]) * rng.uniform(*SPREAD_RANGE, c)
        phase = rng.uniform(0, 2 * np.pi, c)
        return np.column_stack([amplitude * np.cos(phase), amplitude * np.sin(phase)])

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        pitch = float(rng.uniform(2.0, 10.0))
        phase = rng.uniform(0, 2 * np.pi)
        # The largest possible contribution of chain i is |dF/dq_i| A.
        dF_dq = np.abs(np.diagonal(robot.closure_jacobians(theta, data.joints, data.regressor_poses).joints, axis1=1, axis2=2))
        amplitude = magnitude_mm / np.max(dF_dq)
        return EffectScenario(np.array([amplitude * np.cos(phase), amplitude * np.sin(phase)]), pitch, context)


EFFECT = PeriodicScrewError()
