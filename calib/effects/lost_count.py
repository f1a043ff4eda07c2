"""``lost_count``: one joint's encoder loses (or gains) counts once, partway through the
recording: from that time on that joint sits a constant step away from where it reads."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Coefficient, Effect, EffectScenario, SearchedParameter, scale_to_magnitude

__all__ = ["EFFECT", "LostCount", "JointStep", "MIN_ROWS_EACH_SIDE"]

#: Measurements the step time leaves on each side at least (a step before the second or after
#: the last but one measurement is a single row's offset: an outlier, not a lost count).
MIN_ROWS_EACH_SIDE = 5
#: Where the scenario puts the step: within this fraction of the recording, centred.
SCENARIO_MIDDLE_FRACTION = 0.6


@dataclass(frozen=True)
class JointStep:
    """Where and when a count was lost: ``chain`` (0-based) and ``time_s``, the step time (s).
    ``float()`` of it is the step time (the searched parameter's value)."""

    chain: int
    time_s: float

    def __float__(self) -> float:
        return float(self.time_s)


class LostCount(Effect):
    """``dq_k = s H(t - t0)`` on one chain ``k``, nothing on the others: that joint's zero offset
    steps by ``s`` at time ``t0`` (an encoder that missed counts in a fast move, a motor that
    slipped a step), ``H`` the unit step. The joint and ``t0`` are searched together (a
    :class:`JointStep`) over every chain and the midpoints between consecutive measurement
    times (the fit is the same anywhere between two measurements, so it never sits on one).

    One joint, one coefficient: a step common to several chains at once is no lost count, and
    one chain's step cannot stand in for a trend that every chain shares (a drift, a warm-up).

    Applies to every robot: any actuator's position sensor can lose counts, whatever its unit.
    """

    name = "lost_count"
    physics = "one joint's zero offset steps once partway through the recording (lost encoder counts)"
    searched = SearchedParameter("step_time", "s")
    refine_search = False
    granularity = "per_chain"  # already one coefficient per chain (no shared form)
    follows = "time"
    not_compensable = ("a one-off loss of counts during the recording: re-home the machine (its zero is then "
                       "restored) rather than command around it")

    def coefficients(self, robot):
        return (Coefficient("step", robot.joint_unit),)

    def joint_regressors(self, robot, theta, data, extra=None):
        if not isinstance(extra, JointStep):
            raise ValueError("lost_count needs the joint and the step time (extra, a JointStep)")
        X = np.zeros((data.n, robot.n_chains, 1))
        X[:, extra.chain, 0] = (data.t_s > extra.time_s).astype(float)
        return X

    def search_grid(self, data):
        """Every chain with every midpoint between consecutive measurement times,
        :data:`MIN_ROWS_EACH_SIDE` rows kept on each side."""
        t = np.sort(data.t_s)
        mid = (t[1:] + t[:-1]) / 2
        k = min(MIN_ROWS_EACH_SIDE, max((t.size - 1) // 2, 1))
        times = mid[k - 1:mid.size - k + 1] if mid.size > 2 * (k - 1) else mid
        return [JointStep(c, float(t0)) for c in range(data.robot.n_chains) for t0 in times]

    def searched_value(self, u):
        return u

    def searched_values(self, extra):
        return {"step_time": (float(extra.time_s), "s"), "joint": (float(extra.chain + 1), "")}

    def machine_settings(self, coefficients, robot, context, extra=None):
        step = np.zeros(robot.n_chains)
        step[extra.chain] = float(coefficients[0])
        return {"options": {}, "effects": {"joint_offset_step": tuple(float(v) for v in step),
                                           "joint_offset_step_time_s": float(extra.time_s)}}

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        t = data.t_s
        n = t.size
        margin = (1 - SCENARIO_MIDDLE_FRACTION) / 2
        k = int(rng.integers(int(margin * n), max(int((1 - margin) * n), int(margin * n) + 1)))
        k = min(max(k, 0), n - 2)
        step = JointStep(int(rng.integers(robot.n_chains)), float((t[k] + t[k + 1]) / 2))
        X = self.regressors(robot, theta, data, step)
        return EffectScenario(scale_to_magnitude(X, np.array([rng.choice([-1.0, 1.0])]), magnitude_mm), step, context)


EFFECT = LostCount()
