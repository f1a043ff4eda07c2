"""Kinematic recordings with exact truth for the effect and law tests: the paper's hexapod with
Table 3's errors commanded to seeded poses in a small workspace, each leg moved by a joint-space
offset (an effect's regressors times its coefficients, or a law), the poses its forward
kinematics then reaches, plus seeded 1 um / 1 urad noise."""

import numpy as np

from calib import paper
from calib.effects import EffectData
from calib.noise import SensorNoise
from calib.robots import default_robot

NOISE = SensorNoise(0.001, 1e-6, "normal")
HEXAPOD = default_robot("hexapod")
THETA = HEXAPOD.table.nominal + paper.TABLE3_ERRORS.ravel()
WORKSPACE = np.array([[-25, 25], [-25, 25], [190, 215], [-0.1, 0.1], [-0.1, 0.1], [-0.15, 0.15]], dtype=float)


def moved_legs(offset, n: int, seed: int, *, iterations: int = 4, noise: bool = True) -> EffectData:
    """The recording of legs moved by ``offset(data)`` ((N, C) mm, from an :class:`EffectData` of
    the commands at the poses reached so far: a fixed point for pose-dependent offsets)."""
    rng = np.random.default_rng(seed)
    targets = WORKSPACE[:, 0] + rng.uniform(size=(n, 6)) * np.ptp(WORKSPACE, axis=1)
    joints = HEXAPOD.inverse_kinematics(HEXAPOD.table.nominal, targets)
    t = np.cumsum(rng.uniform(0.5, 1.5, n))
    reached = targets
    for _ in range(iterations):
        data = EffectData(HEXAPOD, HEXAPOD.table.nominal, joints, reached, t, NOISE)
        reached = HEXAPOD.forward_kinematics(THETA, joints + offset(data), initial=reached)
    if noise:
        reached = reached + NOISE.sample(n, seed + 1, HEXAPOD.pose_units)
    return EffectData(HEXAPOD, HEXAPOD.table.nominal, joints, reached, t, NOISE)
