"""``lost_count``: one joint's encoder loses (or gains) counts once, partway through the
recording: from that time on the joint sits a constant step away from where it reads."""

from __future__ import annotations

import numpy as np

from .base import Coefficient, Effect, EffectScenario, SearchedParameter, scale_to_magnitude

__all__ = ["EFFECT", "LostCount", "MIN_ROWS_EACH_SIDE"]

#: Measurements the step time leaves on each side at least (a step before the second or after
#: the last but one measurement is a single row's offset: an outlier, not a lost count).
MIN_ROWS_EACH_SIDE = 5
#: Where the scenario puts the step: within this fraction of the recording, centred.
SCENARIO_MIDDLE_FRACTION = 0.6


class LostCount(Effect):
    """``dq_i = s_i H(t - t0)``: chain i's zero offset steps by ``s_i`` at time ``t0`` (an
    encoder that missed counts in a fast move, a motor that slipped a step), ``H`` the unit step.
    ``t0`` is searched among the midpoints between consecutive measurement times (the fit is
    the same anywhere between two measurements, so it never sits on one).

    Applies to every robot: any actuator's position sensor can lose counts, whatever its unit.
    """

    name = "lost_count"
    physics = "one joint's zero offset steps once partway through the recording (lost encoder counts)"
    searched = SearchedParameter("step_time", "s")
    refine_search = False
    follows = "time"

    def coefficients(self, robot):
        return tuple(Coefficient(f"step{i + 1}", robot.joint_unit) for i in range(robot.n_chains))

    def joint_regressors(self, robot, theta, data, extra=None):
        if extra is None:
            raise ValueError("lost_count needs the step time (extra)")
        c = robot.n_chains
        X = np.zeros((data.n, c, c))
        X[:, np.arange(c), np.arange(c)] = (data.t_s > extra).astype(float)[:, None]
        return X

    def search_grid(self, data):
        """Midpoints between consecutive measurement times, :data:`MIN_ROWS_EACH_SIDE` rows kept
        on each side."""
        t = np.sort(data.t_s)
        mid = (t[1:] + t[:-1]) / 2
        k = min(MIN_ROWS_EACH_SIDE, max((t.size - 1) // 2, 1))
        return mid[k - 1:mid.size - k + 1] if mid.size > 2 * (k - 1) else mid

    def searched_value(self, u):
        return float(u)

    def machine_settings(self, coefficients, robot, context, extra=None):
        return {"options": {}, "effects": {"joint_offset_step": tuple(float(v) for v in coefficients),
                                           "joint_offset_step_time_s": float(extra)}}

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        t = data.t_s
        n = t.size
        margin = (1 - SCENARIO_MIDDLE_FRACTION) / 2
        k = int(rng.integers(int(margin * n), max(int((1 - margin) * n), int(margin * n) + 1)))
        k = min(max(k, 0), n - 2)
        t0 = float((t[k] + t[k + 1]) / 2)
        shape = np.zeros(robot.n_chains)
        shape[int(rng.integers(robot.n_chains))] = rng.choice([-1.0, 1.0])
        X = self.regressors(robot, theta, data, t0)
        return EffectScenario(scale_to_magnitude(X, shape, magnitude_mm), t0, context)


EFFECT = LostCount()
