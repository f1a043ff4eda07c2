"""Error metrics: the paper's integrated error (Eqs. 15-17) and held-out evaluation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._validate import as_poses
from .hexapod import Hexapod
from .kinematics import forward_kinematics, inverse_kinematics

__all__ = [
    "integrated_error",
    "CompensationEvaluation",
    "evaluate_compensation",
    "ConsistencyCheck",
    "consistency_check",
]


def integrated_error(dQ: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The paper's position, orientation and integrated errors.

    Args:
        dQ: (N, 6) pose errors, mm and rad.

    Returns:
        ``(dQ1, dQ2, dQint)``, each (N,): ``|dXYZ|`` in mm (Eq. 15), ``|d angles|`` in rad
        (Eq. 16) and their plain sum (Eq. 17, mixing units as the paper does; used only for
        its stopping rule).
    """
    dQ = as_poses(dQ, "dQ")
    dQ1 = np.linalg.norm(dQ[:, :3], axis=1)
    dQ2 = np.linalg.norm(dQ[:, 3:], axis=1)
    return dQ1, dQ2, dQ1 + dQ2


@dataclass(frozen=True, eq=False)
class CompensationEvaluation:
    """Pose errors a controller makes on target poses, before and after compensation.

    Attributes:
        targets: (N, 6) target poses, mm and rad.
        reached_before: (N, 6) poses the machine reaches when the nominal model commands it.
        reached_after: (N, 6) poses reached when the identified model commands it.
        position_before / position_after: (N,) mm, |reached - target| of the positions.
        orientation_before / orientation_after: (N,) rad, norm of the angle errors.
    """

    targets: np.ndarray
    reached_before: np.ndarray
    reached_after: np.ndarray
    position_before: np.ndarray
    position_after: np.ndarray
    orientation_before: np.ndarray
    orientation_after: np.ndarray

    @property
    def improvement(self) -> float:
        """Ratio of mean position error before to after compensation."""
        return float(self.position_before.mean() / self.position_after.mean())

    def summary(self) -> dict:
        """Mean before/after and max after, position (mm) and orientation (rad)."""
        return {
            "position_mm": {"before": float(self.position_before.mean()),
                            "after": float(self.position_after.mean()),
                            "max_after": float(self.position_after.max())},
            "orientation_rad": {"before": float(self.orientation_before.mean()),
                                "after": float(self.orientation_after.mean()),
                                "max_after": float(self.orientation_after.max())},
        }


def evaluate_compensation(true: Hexapod, identified: Hexapod, targets: np.ndarray) -> CompensationEvaluation:
    """Errors on (held-out) target poses of the machine ``true`` commanded by two models.

    Before: the controller uses the nominal geometry (``identified.nominal()``); after: it
    uses ``identified``. The machine always moves as ``true`` (forward kinematics).

    Args:
        true: the machine's actual parameter set.
        identified: the parameter set found by calibration (same nominal geometry).
        targets: (N, 6) target poses, mm and rad.
    """
    targets = as_poses(targets, "targets")
    before = forward_kinematics(true, inverse_kinematics(identified.nominal(), targets), initial=targets)
    after = forward_kinematics(true, inverse_kinematics(identified, targets), initial=targets)
    db, da = before - targets, after - targets
    return CompensationEvaluation(
        targets=targets, reached_before=before, reached_after=after,
        position_before=np.linalg.norm(db[:, :3], axis=1),
        position_after=np.linalg.norm(da[:, :3], axis=1),
        orientation_before=np.linalg.norm(db[:, 3:], axis=1),
        orientation_after=np.linalg.norm(da[:, 3:], axis=1),
    )


@dataclass(frozen=True, eq=False)
class ConsistencyCheck:
    """Measured poses compared with what a model of the machine predicts.

    Attributes:
        predicted: (N, 6) predicted poses, mm and rad.
        position_deviation: (N,) mm, max abs coordinate deviation of position.
        orientation_deviation: (N,) rad, max abs deviation of the angles.
        consistent: (N,) bool, both deviations within the tolerances.
    """

    predicted: np.ndarray
    position_deviation: np.ndarray
    orientation_deviation: np.ndarray
    consistent: np.ndarray

    @property
    def flagged(self) -> list[int]:
        """Indices of inconsistent rows."""
        return [int(i) for i in np.flatnonzero(~self.consistent)]


def consistency_check(
    model: Hexapod, commanded: np.ndarray, measured: np.ndarray, *, tol_mm: float, tol_rad: float
) -> ConsistencyCheck:
    """Which measured rows the model of the machine cannot reproduce.

    Used to reproduce Table 4 of the paper: the model there is Table 2 + Table 3, the
    commanded lengths the nominal inverse kinematics of the target poses.

    Args:
        model: parameter set believed to describe the machine.
        commanded: (N, 6) commanded leg lengths, mm.
        measured: (N, 6) measured poses, mm and rad.
        tol_mm, tol_rad: tolerances on each coordinate.
    """
    measured = as_poses(measured, "measured")
    predicted = forward_kinematics(model, commanded, initial=measured)
    d = np.abs(predicted - measured)
    pos, ang = d[:, :3].max(axis=1), d[:, 3:].max(axis=1)
    return ConsistencyCheck(predicted, pos, ang, (pos <= tol_mm) & (ang <= tol_rad))
