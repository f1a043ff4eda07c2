"""``thermal_warmup``: every leg grows as it warms up towards a steady temperature, with a time
constant (prismatic legs only)."""

from __future__ import annotations

import numpy as np

from .base import Coefficient, Effect, EffectScenario, SearchedParameter, scale_to_magnitude, unabsorbed
from .thermal_drift import EFFECT as THERMAL_DRIFT

__all__ = ["EFFECT", "ThermalWarmup", "TAU_RANGE_SPANS", "warmup_growth"]

#: Search range of the time constant, in units of the recording's time span (log grid).
TAU_RANGE_SPANS = (0.02, 5.0)
#: Grid points of the time constant's search (log-spaced).
TAU_GRID_POINTS = 60
#: Range of the scenario's time constant, in units of the recording's time span: well inside the
#: recording, so that the levelling off (what tells a warm-up from a constant drift) is measurable
#: at 3 times the noise: the part of the curve a straight line leaves is 12% (tau a quarter) to
#: 10% (a third) of its largest value, against 7% at half the recording.
SCENARIO_TAU_SPANS = (0.25, 1 / 3)


def warmup_growth(t_s, tau_s: float):
    """Growth per unit initial rate at times ``t_s``: ``tau (1 - exp(-t / tau))``, s."""
    return tau_s * -np.expm1(-np.asarray(t_s, dtype=float) / tau_s)


class ThermalWarmup(Effect):
    """Each actuated length grows as ``dq = g tau (1 - exp(-t / tau))``: first at the rate ``g``,
    then levelling off at ``g tau`` as the legs reach their steady temperature (``tau`` the
    thermal time constant, searched on a log grid). Much longer than the recording, it is
    ``thermal_drift``.

    Applies where ``thermal_drift`` does (actuated lengths, ``joint_unit == "mm"``), for the
    same reason.
    """

    name = "thermal_warmup"
    physics = "every leg grows with time, levelling off with a thermal time constant"
    searched = SearchedParameter("time_constant", "s")
    follows = "time"
    per_chain_capable = ("initial_growth_rate",)
    generalises = (THERMAL_DRIFT.name,)

    def applies_to(self, robot):
        return THERMAL_DRIFT.applies_to(robot)

    def coefficients(self, robot):
        return (Coefficient("initial_growth_rate", f"{robot.joint_unit}/s"),)

    def joint_regressors(self, robot, theta, data, extra=None):
        if extra is None:
            raise ValueError("thermal_warmup needs the time constant (extra)")
        return np.broadcast_to(warmup_growth(data.t_s, extra)[:, None, None], (data.n, robot.n_chains, 1)).copy()

    def search_grid(self, data):
        """``log(tau)`` over :data:`TAU_RANGE_SPANS` times the recording's last time."""
        span = max(float(np.max(data.t_s)), 1e-9)
        return np.linspace(np.log(TAU_RANGE_SPANS[0] * span), np.log(TAU_RANGE_SPANS[1] * span), TAU_GRID_POINTS)

    def searched_value(self, u):
        return float(np.exp(u))

    def machine_settings(self, coefficients, robot, context, extra=None):
        return {"options": {}, "effects": {"joint_warmup_per_s": float(coefficients[0]),
                                           "joint_warmup_tau_s": float(extra)}}

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        """Sized by what tells a warm-up from the drift it contains: the part of its closure
        contribution that the geometry and a constant drift cannot absorb has the largest value
        ``magnitude_mm`` (its raw contribution is then several times larger); sized on the raw
        contribution, a warm-up at 3 times the noise is a drift as far as the data can tell."""
        span = float(np.max(data.t_s))
        tau = float(span * np.exp(rng.uniform(*np.log(SCENARIO_TAU_SPANS))))
        X = unabsorbed(robot, theta, data, self.regressors(robot, theta, data, tau))[..., 0].ravel()
        D = unabsorbed(robot, theta, data, THERMAL_DRIFT.regressors(robot, theta, data))[..., 0].ravel()
        X = X - D * (D @ X) / (D @ D)
        return EffectScenario(scale_to_magnitude(X[:, None], np.ones(1), magnitude_mm), tau, context)


EFFECT = ThermalWarmup()
