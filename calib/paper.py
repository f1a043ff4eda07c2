"""The hexapod paper's tables (Yang et al., Optik), transcribed; mm and rad.

Built-in defaults only. Tests compare against the independent hand transcription in
``shared/reference/hexapod_paper_tables.json``.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "TABLE2_BASE_JOINTS_MM",
    "TABLE2_PLATFORM_JOINTS_MM",
    "TABLE2_HOME_LENGTHS_MM",
    "TABLE2_HOME_POSE",
    "TABLE3_ERRORS",
    "TABLE4_NOMINAL_POSES",
    "TABLE4_MEASURED_POSES",
    "PAPER_NOISE_MM",
    "PAPER_EPSILON",
]

#: Table 2, base joints B_i in the base frame, (6, 3) mm.
TABLE2_BASE_JOINTS_MM = np.array([
    [120.0, -140.0, 0.0],
    [120.0, 140.0, 0.0],
    [61.243557, 173.92305, 0.0],
    [-181.24356, 33.92305, 0.0],
    [-181.24356, -33.92305, 0.0],
    [61.243557, -173.92305, 0.0],
])
#: Table 2, platform joints P_i in the platform frame, (6, 3) mm.
TABLE2_PLATFORM_JOINTS_MM = np.array([
    [120.0, -20.0, 0.0],
    [120.0, 20.0, 0.0],
    [-42.679489, 113.92304, 0.0],
    [-77.320511, 93.923042, 0.0],
    [-77.320511, -93.923042, 0.0],
    [-42.679489, -113.92304, 0.0],
])
#: Table 2, leg lengths at the home pose, (6,) mm.
TABLE2_HOME_LENGTHS_MM = np.full(6, 233.23808)
#: The home pose of Table 2's note: x = y = 0, z = 200 mm, angles 0. (6,) mm/rad.
TABLE2_HOME_POSE = np.array([0.0, 0.0, 200.0, 0.0, 0.0, 0.0])

#: Table 3, injected errors (6, 7) in column order dXB dYB dZB dl dXP dYP dZP, mm.
TABLE3_ERRORS = np.array([
    [0.02, 0.03, -0.05, -0.02, 0.04, 0.03, -0.01],
    [-0.03, 0.02, 0.04, 0.02, 0.05, -0.02, -0.03],
    [0.01, -0.05, 0.04, -0.01, -0.02, 0.01, 0.04],
    [-0.05, -0.02, 0.02, 0.04, -0.04, -0.04, 0.01],
    [-0.02, 0.05, -0.01, -0.05, 0.04, 0.02, -0.05],
    [0.05, -0.04, -0.02, 0.04, 0.02, 0.03, 0.04],
])

#: Table 4, nominal target poses P_T (10, 6), mm and rad.
TABLE4_NOMINAL_POSES = np.array([
    [10.0, 0.0, 200.0, 0.017453292, 0.034907, 0.05236],
    [10.0, 10.0, 200.0, 0.034906584, -0.03491, 0.017453],
    [0.0, 10.0, 200.0, 0.052359877, 0.034907, -0.01745],
    [-10.0, 10.0, 200.0, -0.05235988, -0.01745, 0.017453],
    [-10.0, 0.0, 200.0, -0.01745329, 0.017453, 0.034907],
    [-10.0, -10.0, 200.0, 0.017453292, -0.05236, 0.017453],
    [0.0, -10.0, 200.0, 0.034906584, 0.05236, -0.03491],
    [10.0, -10.0, 200.0, 0.052359877, 0.017453, 0.05236],
    [0.0, 0.0, 210.0, -0.03490658, 0.034907, -0.05236],
    [0.0, 0.0, 210.0, 0.034906584, -0.03491, 0.034907],
])
#: Table 4, printed actual (measured) poses P_P (10, 6), mm and rad. Row A2 is inconsistent.
TABLE4_MEASURED_POSES = np.array([
    [10.02907, -0.04008, 199.991, 0.017814, 0.034796, 0.051874],
    [10.0562, 9.9385, 199.9848, 0.0352, -0.035, 0.0174],
    [0.040607, 9.958774, 199.9928, 0.052729, 0.034775, -0.01794],
    [-9.96499, 9.955117, 199.9963, -0.05197, -0.0176, 0.016979],
    [-9.96692, -0.04496, 199.9954, -0.01707, 0.017326, 0.034433],
    [-9.96952, -10.0419, 199.9906, 0.01787, -0.05245, 0.016936],
    [0.03019, -10.0384, 199.9892, 0.035264, 0.052294, -0.03537],
    [10.02686, -10.0388, 199.9887, 0.052733, 0.017372, 0.051853],
    [0.031535, -0.04165, 209.9913, -0.03457, 0.034827, -0.05282],
    [0.034993, -0.04456, 209.9916, 0.035298, -0.03502, 0.034362],
])

#: The paper's measuring noise: uniform within +-0.001 mm on positions.
PAPER_NOISE_MM = 0.001
#: The paper's stopping tolerance on max dQint.
PAPER_EPSILON = 1e-6
