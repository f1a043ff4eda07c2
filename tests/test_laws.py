"""Proposed laws (calib.effects.laws): laws outside the library injected into kinematic recordings
of the hexapod (exact forward kinematics of the joints moved by the law, 1 um noise): the search
names the right terms with their constants per leg and brings the cross-validated residual to
the noise floor; where the library explains the recording, or nothing is there, no law."""

import numpy as np
import pytest

from calib import paper
from calib.effects import EFFECTS, EffectData, discover_effects
from calib.effects.laws import (LAW_NAME, LAW_WORDS, Term, TermFamily, joint_quantities, law_effect, law_from_dict,
                                law_to_dict)
from calib.noise import SensorNoise
from calib.robots import default_robot

NOISE = SensorNoise(0.001, 1e-6, "normal")
HEXAPOD = default_robot("hexapod")
THETA = HEXAPOD.table.nominal + paper.TABLE3_ERRORS.ravel()
WORKSPACE = np.array([[-25, 25], [-25, 25], [190, 215], [-0.1, 0.1], [-0.1, 0.1], [-0.15, 0.15]], dtype=float)
#: Poses of the recordings (the issue's 120).
N_POSES = 120


def recording(law, n=N_POSES, seed=0, channels=None):
    """Exact truth: the poses the forward kinematics reaches with each leg moved by ``law(q)``
    ((N, C) mm from :func:`joint_quantities` of the commands, a fixed point for load-dependent
    laws), plus seeded 1 um / 1 urad noise."""
    rng = np.random.default_rng(seed)
    targets = WORKSPACE[:, 0] + rng.uniform(size=(n, 6)) * np.ptp(WORKSPACE, axis=1)
    joints = HEXAPOD.inverse_kinematics(HEXAPOD.table.nominal, targets)
    t = np.cumsum(rng.uniform(0.5, 1.5, n))
    reached = targets
    for _ in range(4):
        data = EffectData(HEXAPOD, HEXAPOD.table.nominal, joints, reached, t, NOISE)
        reached = HEXAPOD.forward_kinematics(THETA, joints + law(joint_quantities(data, channels)), initial=reached)
    reached = reached + NOISE.sample(n, seed + 1, HEXAPOD.pose_units)
    return EffectData(HEXAPOD, HEXAPOD.table.nominal, joints, reached, t, NOISE)
