"""``instrument_drift``: the measuring instrument's frame moves slowly: every measured position
is off by the same vector, growing linearly with time (the legs do not move)."""

from __future__ import annotations

import numpy as np

from ..robot import pose_jacobian_of_joints
from .base import Coefficient, Effect, EffectScenario, scale_to_magnitude

__all__ = ["EFFECT", "InstrumentDrift", "POSITION_NAMES"]

#: The pose coordinates the frame's drift moves.
POSITION_NAMES = ("x", "y", "z")


class InstrumentDrift(Effect):
    """The measured position is ``p_true + v t``: a translation of the measurement frame at a
    constant velocity ``v`` (a tracker's or a probe's stand settling, thermal growth of the
    instrument's mounting), the same for every pose; the machine itself is where its joints put it.

    Written in the joint space of the discovery: the machine at the measured pose would have its
    joints at ``q + dq`` with ``d pose / d q . dq = v t``, so the joint regressors are
    ``(d pose / d q)^-1 e_k t`` (the square pose Jacobian of a parallel robot, through the
    closure), exact to first order in ``v t``; unlike a growing leg (``thermal_drift``), the
    apparent displacement is the same at every pose.

    Applies to every robot whose pose has the coordinates ``x, y, z`` and as many pose
    coordinates as chains (the pose Jacobian is square).
    """

    name = "instrument_drift"
    physics = "the measurement frame moves at a constant velocity: every measured position drifts with time"
    follows = "time"
    not_compensable = "the instrument's frame drifts, not the machine: no command moves it"

    def applies_to(self, robot):
        return all(c in robot.pose_names for c in POSITION_NAMES) and robot.pose_dim == robot.n_chains

    def coefficients(self, robot):
        return tuple(Coefficient(f"drift_{c}", "mm/s") for c in POSITION_NAMES)

    def joint_regressors(self, robot, theta, data, extra=None):
        J = pose_jacobian_of_joints(robot, theta, data.joints, data.regressor_poses)  # (N, D, C)
        cols = [robot.pose_names.index(c) for c in POSITION_NAMES]
        return np.linalg.inv(J)[:, :, cols] * data.t_s[:, None, None]

    def machine_settings(self, coefficients, robot, context, extra=None):
        return {"options": {}, "effects": {"instrument_drift_mm_per_s": tuple(float(v) for v in coefficients)}}

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        direction = rng.standard_normal(len(POSITION_NAMES))
        X = self.regressors(robot, theta, data)
        return EffectScenario(scale_to_magnitude(X, direction / np.linalg.norm(direction), magnitude_mm), None,
                              context)


EFFECT = InstrumentDrift()
