"""The one place where the project's units (mm, rad) meet MuJoCo's SI metres."""

from __future__ import annotations

import numpy as np

#: Metres per millimetre.
M_PER_MM = 1e-3


def mm_to_m(x):
    """mm -> m (arrays or floats)."""
    return np.asarray(x, dtype=float) * M_PER_MM


def m_to_mm(x):
    """m -> mm (arrays or floats)."""
    return np.asarray(x, dtype=float) / M_PER_MM
