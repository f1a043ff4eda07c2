"""``none``: the geometric model explains the data; no effect (the reference of every comparison)."""

from __future__ import annotations

import numpy as np

from .base import Effect, EffectScenario

__all__ = ["EFFECT", "NoEffect"]


class NoEffect(Effect):
    """Geometry alone. Applies to every robot."""

    name = "none"
    physics = "geometry explains the data"

    def coefficients(self, robot):
        return ()

    def joint_regressors(self, robot, theta, data, extra=None):
        return np.zeros((data.n, robot.n_chains, 0))

    def machine_settings(self, coefficients, robot, context, extra=None):
        return {"options": {}, "effects": {}}

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        return EffectScenario(np.zeros(0), None, context)


EFFECT = NoEffect()
