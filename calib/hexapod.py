"""Hexapod (Stewart-Gough platform) parameter sets and the table of its 42 parameters.

A parameter set is a nominal geometry plus the (6, 7) array of its errors, in the paper's
column order ``dXB dYB dZB dl dXP dYP dZP``. The leg-length error ``dl`` is additive: leg i
of the machine is ``commanded length + dl_i`` long (an offset in the zero of its scale).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import paper
from ._validate import as_array, frozen_array

__all__ = [
    "ERROR_COLUMNS",
    "N_PARAMETERS",
    "HexapodGeometry",
    "Hexapod",
    "parameter_table",
    "parameter_index",
    "paper_geometry",
    "paper_hexapod",
]

#: Column order of a (6, 7) hexapod error array (Table 3 of the paper).
ERROR_COLUMNS = ("dXB", "dYB", "dZB", "dl", "dXP", "dYP", "dZP")
#: Number of geometric parameters of the hexapod.
N_PARAMETERS = 42


def parameter_table() -> list[tuple[str, int, str]]:
    """The one table of the 42 identified parameters.

    Returns:
        ``[(name, index, unit), ...]`` with names ``dXB1 .. dZP6`` (legs numbered from 1) and
        index into the flat vector ``errors.ravel()`` (leg-major, Table 3 column order).
    """
    return [
        (f"{col}{leg + 1}", leg * 7 + k, "mm")
        for leg in range(6)
        for k, col in enumerate(ERROR_COLUMNS)
    ]


def parameter_index(name: str) -> int:
    """Flat index of a parameter name such as ``"dXB3"`` or ``"dl5"``.

    Raises:
        KeyError: the name is not one of the 42 (the message lists the valid pattern).
    """
    for n, i, _ in parameter_table():
        if n == name:
            return i
    raise KeyError(
        f"unknown hexapod parameter {name!r}: expected one of {', '.join(ERROR_COLUMNS)} "
        "followed by a leg number 1..6, e.g. 'dXB3' or 'dl5'"
    )


@dataclass(frozen=True, eq=False)
class HexapodGeometry:
    """Nominal hexapod geometry.

    Attributes:
        base_joints: (6, 3) mm, joint centres B_i in the base frame.
        platform_joints: (6, 3) mm, joint centres P_i in the platform frame.
        home_lengths: (6,) mm, leg lengths at ``home_pose``.
        home_pose: (6,) mm/rad, the pose the legs' home lengths refer to; also the starting
            guess of the forward kinematics.
    """

    base_joints: np.ndarray
    platform_joints: np.ndarray
    home_lengths: np.ndarray
    home_pose: np.ndarray = field(default_factory=lambda: paper.TABLE2_HOME_POSE.copy())

    def __post_init__(self) -> None:
        for name, shape in (("base_joints", (6, 3)), ("platform_joints", (6, 3)),
                            ("home_lengths", (6,)), ("home_pose", (6,))):
            object.__setattr__(self, name, frozen_array(as_array(getattr(self, name), name, shape)))

    def to_dict(self) -> dict:
        """JSON-ready dict (lists of floats, mm and rad)."""
        return {
            "base_joints_mm": self.base_joints.tolist(),
            "platform_joints_mm": self.platform_joints.tolist(),
            "home_lengths_mm": self.home_lengths.tolist(),
            "home_pose": self.home_pose.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "HexapodGeometry":
        """Inverse of :meth:`to_dict`; missing ``home_pose`` defaults to the paper's."""
        return cls(
            base_joints=d["base_joints_mm"],
            platform_joints=d["platform_joints_mm"],
            home_lengths=d["home_lengths_mm"],
            home_pose=d.get("home_pose", paper.TABLE2_HOME_POSE),
        )


@dataclass(frozen=True, eq=False)
class Hexapod:
    """A hexapod parameter set: nominal geometry plus geometric errors.

    Attributes:
        geometry: the nominal geometry.
        errors: (6, 7) mm, per leg ``dXB dYB dZB dl dXP dYP dZP``.
    """

    geometry: HexapodGeometry
    errors: np.ndarray = field(default_factory=lambda: np.zeros((6, 7)))

    def __post_init__(self) -> None:
        object.__setattr__(self, "errors", frozen_array(as_array(self.errors, "errors", (6, 7))))

    @property
    def base_joints(self) -> np.ndarray:
        """(6, 3) mm, actual base joint centres, base frame."""
        return self.geometry.base_joints + self.errors[:, 0:3]

    @property
    def platform_joints(self) -> np.ndarray:
        """(6, 3) mm, actual platform joint centres, platform frame."""
        return self.geometry.platform_joints + self.errors[:, 4:7]

    @property
    def leg_offsets(self) -> np.ndarray:
        """(6,) mm, actual leg length minus commanded length (``dl``)."""
        return self.errors[:, 3].copy()

    @property
    def home_lengths(self) -> np.ndarray:
        """(6,) mm, actual leg lengths when the nominal home lengths are commanded."""
        return self.geometry.home_lengths + self.errors[:, 3]

    @property
    def vector(self) -> np.ndarray:
        """(42,) mm, the flat error vector (see :func:`parameter_table`)."""
        return self.errors.ravel().copy()

    def with_errors(self, errors: np.ndarray) -> "Hexapod":
        """The same geometry with other errors ((6, 7) or flat (42,), mm)."""
        e = np.asarray(errors, dtype=float)
        if e.shape == (N_PARAMETERS,):
            e = e.reshape(6, 7)
        return Hexapod(self.geometry, e)

    def nominal(self) -> "Hexapod":
        """The error-free parameter set of the same geometry."""
        return Hexapod(self.geometry)


def paper_geometry() -> HexapodGeometry:
    """Table 2 of the hexapod paper."""
    return HexapodGeometry(
        base_joints=paper.TABLE2_BASE_JOINTS_MM,
        platform_joints=paper.TABLE2_PLATFORM_JOINTS_MM,
        home_lengths=paper.TABLE2_HOME_LENGTHS_MM,
        home_pose=paper.TABLE2_HOME_POSE,
    )


def paper_hexapod(with_table3_errors: bool = False) -> Hexapod:
    """Table 2 nominal hexapod, optionally carrying Table 3's errors (the paper's machine)."""
    errors = paper.TABLE3_ERRORS if with_table3_errors else np.zeros((6, 7))
    return Hexapod(paper_geometry(), errors)
