"""Manufacturing tolerances as a Gaussian prior on a robot's parameters.

Every parameter of a machine is built to a drawing within a tolerance: before any measurement
its value is the nominal one give or take that tolerance. :class:`ParameterPrior` holds this as
independent Gaussians, mean (P,) the nominal vector and standard deviation (P,) the tolerance,
each in its parameter's unit (mm or rad). Given to :func:`calib.engine.identify_forward` or
:func:`calib.engine.identify_chainwise` (``prior=``), the fit is the maximum a posteriori
estimate: the whitened prior rows ``(theta_k - mean_k) / std_k`` are appended to the whitened
measurement rows of the Gauss-Newton / Levenberg-Marquardt systems. Where the poses determine a
parameter combination well (posterior standard deviation far below the tolerance) the prior
changes nothing that matters; where they do not (poses on one plane leave the heights and tilts
of the joints undetermined) the answer keeps the nominal value there instead of a wild one, and
the result says which parameters and combinations were left to the prior
(:meth:`calib.engine.IdentificationResult.parameter_sources`,
:meth:`calib.engine.IdentificationResult.left_to_prior`).

Where the tolerances come from (:meth:`ParameterPrior.from_tolerance`): a recording sidecar's
``parameter_tolerance`` mapping, by parameter name (``{"B3.z": 0.2}``) and/or one value per unit
(``{"mm": 0.05, "rad": 0.001}``; a name overrides its unit's value), and for every parameter it
does not cover the robot class's documented ``default_parameter_tolerance``
(:data:`calib.robots.hexapod.Hexapod.default_parameter_tolerance`, ...).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .robot import Robot
from .validation import as_array, frozen_array

__all__ = ["ParameterPrior", "PARAMETER_UNITS", "DATA_SOURCE_RATIO", "MOVED_BY_DATA", "parameter_sources",
           "IMPLAUSIBLE_TOLERANCES", "ImplausibleError", "implausible_errors"]

#: The units a ``parameter_tolerance`` mapping may name as keys (one value for every parameter
#: in that unit).
PARAMETER_UNITS = ("mm", "rad")

#: A parameter counts as determined by the data when its posterior standard deviation is below
#: this fraction of its prior's (the data shrank the tolerance at least twofold, i.e. they carry
#: at least three times the prior's information on it); else as left to the prior.
DATA_SOURCE_RATIO = 0.5
#: A parameter the fit placed beyond this many prior standard deviations from the prior's mean was
#: moved there by the data (under the prior alone that is a 1-in-370 event), so it counts as
#: determined by the data even where the posterior is not much narrower than the prior.
MOVED_BY_DATA = 3.0


@dataclass(frozen=True, eq=False)
class ParameterPrior:
    """Independent Gaussian prior on a robot's parameter vector.

    Attributes:
        mean: (P,) prior mean, each parameter's unit (the nominal vector, usually).
        std: (P,) prior standard deviation (the manufacturing tolerance), each parameter's unit,
            every entry finite and > 0.
    """

    mean: np.ndarray
    std: np.ndarray

    def __post_init__(self) -> None:
        mean = as_array(self.mean, "mean", (-1,))
        std = as_array(self.std, "std", (mean.size,))
        if not np.all(std > 0):
            k = int(np.argmin(std > 0))
            raise ValueError(f"std must be > 0 everywhere, got {std[k]!r} at index {k}")
        object.__setattr__(self, "mean", frozen_array(mean))
        object.__setattr__(self, "std", frozen_array(std))

    @property
    def n_parameters(self) -> int:
        return int(self.mean.size)

    @classmethod
    def from_tolerance(cls, robot: Robot, tolerance: Mapping[str, float] | None = None, *,
                       mean=None) -> "ParameterPrior":
        """The prior of ``robot`` from a ``parameter_tolerance`` mapping.

        Args:
            robot: the robot (its parameter table names and units the parameters).
            tolerance: ``{parameter name or unit: standard deviation}``, values in the
                parameter's unit; a unit key (``"mm"``, ``"rad"``) sets every parameter of that
                unit, a name key one parameter (names override units). Parameters it does not
                cover take the robot class's ``default_parameter_tolerance``. None: the default
                alone.
            mean: (P,) prior mean; default ``robot.table.nominal``.

        Raises:
            ValueError: a key that is neither a parameter name nor a unit, or a value that is not
                a finite number > 0 (naming the key).
        """
        if not isinstance(robot, Robot):
            raise TypeError(f"robot must be a calib.robot.Robot, got {type(robot).__name__}")
        std = _tolerance_vector(robot, robot.default_parameter_tolerance, "default_parameter_tolerance")
        if tolerance is not None:
            if not isinstance(tolerance, Mapping):
                raise TypeError(f"tolerance must be a mapping of names or units to values, got "
                                f"{type(tolerance).__name__}")
            std = _tolerance_vector(robot, tolerance, "parameter_tolerance", std)
        mean = robot.table.nominal if mean is None else as_array(mean, "mean", (robot.n_parameters,))
        return cls(mean=mean, std=std)

    @classmethod
    def default(cls, robot: Robot) -> "ParameterPrior":
        """The robot class's documented default: nominal mean, ``default_parameter_tolerance`` std."""
        return cls.from_tolerance(robot, None)

    def tolerance_by_name(self, robot: Robot) -> dict[str, float]:
        """``{parameter name: std}`` (JSON-ready; the form a sidecar's ``parameter_tolerance`` takes)."""
        self.check(robot)
        return robot.table.to_dict(self.std)

    def check(self, robot: Robot) -> None:
        """ValueError unless the prior has one entry per parameter of ``robot``."""
        if self.n_parameters != robot.n_parameters:
            raise ValueError(f"prior has {self.n_parameters} parameters, the {robot.name} has "
                             f"{robot.n_parameters}")


def _tolerance_vector(robot: Robot, tolerance: Mapping, what: str, base=None) -> np.ndarray:
    """(P,) standard deviations: ``base`` (default NaN) with the mapping's unit keys applied, then
    its name keys. ValueError naming a bad key or value; also where a parameter is left without
    one (a robot class whose default misses a unit)."""
    std = np.full(robot.n_parameters, np.nan) if base is None else np.array(base, dtype=float)
    units = np.array(robot.table.units)
    names = set(robot.table.names)
    for key, value in tolerance.items():
        if key not in names and key not in PARAMETER_UNITS:
            raise ValueError(f"{what}: unknown key {key!r}: neither a parameter of the {robot.name} "
                             f"(e.g. {', '.join(robot.table.names[:3])}) nor a unit ({', '.join(PARAMETER_UNITS)})")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{what}: {key!r} must be a number, got {value!r}") from None
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{what}: {key!r} must be a finite standard deviation > 0, got {value!r}")
    for key, value in tolerance.items():
        if key in PARAMETER_UNITS and key not in names:
            std[units == key] = float(value)
    for key, value in tolerance.items():
        if key in names:
            std[robot.table.index(key)] = float(value)
    if np.any(np.isnan(std)):
        missing = robot.table.names[int(np.argmax(np.isnan(std)))]
        raise ValueError(f"{what} of the {robot.name} gives no tolerance for {missing!r}")
    return std


def parameter_sources(posterior_std, prior_std, moved=None) -> np.ndarray:
    """(K,) ``"data"`` where the posterior standard deviation is below :data:`DATA_SOURCE_RATIO`
    times the prior's, or where the data moved the parameter beyond :data:`MOVED_BY_DATA` prior
    standard deviations from the prior's mean (``moved`` (K,): estimate minus prior mean; a prior
    that far off was overruled by the rows, whatever the posterior's width); else ``"prior"``.
    All (K,) in each parameter's unit."""
    post = np.asarray(posterior_std, dtype=float)
    prior = np.asarray(prior_std, dtype=float)
    data = post < DATA_SOURCE_RATIO * prior
    if moved is not None:
        data |= np.abs(np.asarray(moved, dtype=float)) > MOVED_BY_DATA * prior
    return np.where(data, "data", "prior")


#: An identified error beyond this many tolerances is physically implausible.
IMPLAUSIBLE_TOLERANCES = 3.0


@dataclass(frozen=True)
class ImplausibleError:
    """An identified error from nominal beyond :data:`IMPLAUSIBLE_TOLERANCES` times its tolerance
    (one standard deviation), both in the parameter's ``unit``."""

    name: str
    error: float
    tolerance: float
    unit: str


def implausible_errors(robot: Robot, errors, tolerance: ParameterPrior, names) -> list[ImplausibleError]:
    """The identified errors (P,) beyond :data:`IMPLAUSIBLE_TOLERANCES` times their ``tolerance``,
    of the parameters ``names``, the farthest (in tolerances) first."""
    out = []
    for name in names:
        k = robot.table.index(name)
        tol, err = float(tolerance.std[k]), float(errors[k])
        if abs(err) > IMPLAUSIBLE_TOLERANCES * tol:
            out.append(ImplausibleError(name, err, tol, robot.table.units[k]))
    return sorted(out, key=lambda e: -abs(e.error) / e.tolerance)
