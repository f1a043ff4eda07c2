"""What a pose set cannot separate: the geometry's combinations it leaves to the prior, and the
effects it cannot tell from the geometry (a level grid at one height, without tilt, is the case
in point: it never moves a platform joint relative to its base joint other than by translation,
and it shows each leg length only as a smooth function of two coordinates).

Geometry (:func:`geometry_basis`). In tolerance units (each free parameter over its tolerance,
:attr:`calib.effects.EffectData.tolerance`) the rows' information on the geometry is
``Gs^T Gs``, ``Gs`` the whitened closure Jacobian times the tolerances. Along an eigenvector with
eigenvalue ``d`` a maximum a posteriori fit has standard deviation ``1 / sqrt(1 + d)``
tolerances; where that is at least :data:`calib.prior.DATA_SOURCE_RATIO` (``d <= 3``: the rows
did not halve the tolerance, the rule :mod:`calib.prior` reports by) the combination is *left to
the prior*. The discovery's fits hold those combinations at the prior mean and fit the others
freely, without the prior: the limit of the maximum a posteriori fit that keeps the rows'
determination whole where it is strong and takes none of it where it is weak (a maximum a
posteriori fit moves a left-to-prior combination by at most ``d / (1 + d) <= 3/4`` of what the
rows alone say), so that every fit stays plain weighted least squares (chi-square, BIC, hat
matrix as before) over ``g`` determined geometric coordinates. The held combinations keep the
prior's covariance.

Effects (:func:`unseparated_combinations`). An effect's whitened closure columns with the
determined geometry projected out carry information ``I_held`` on its coefficients; with every
free geometric combination projected out (the held ones too) ``I_free <= I_held``. Along a
coefficient combination ``v`` with ``v^T I_free v < DATA_SOURCE_RATIO^2 v^T I_held v``, what a
fit would learn of it comes from holding the geometry at its prior, not from the rows (its
standard deviation with the geometry free is more than twice that with the geometry held): the
effect cannot be separated from the geometry on this pose set, is not a candidate, and the
geometric combination that mimics it is named.

Poses (:func:`pose_families`): the recorded poses moved, one pose coordinate at a time, to the
two ends of the robot's workspace about their mean (other heights, tilts, turns), and all such
coordinates at once; the discovery reports which of the combinations above each family would
determine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..observability import describe_combination
from ..prior import DATA_SOURCE_RATIO

__all__ = ["HELD_INFORMATION", "GRAM_MIN_RESIDUALS", "IN_CHAIN_COSINE", "FLAT_FRACTION", "HeldCombination",
           "UnseparatedCombination", "UnseparatedForm", "PoseFamilyReach", "Separation", "GeometryBasis", "geometry_basis",
           "unseparated_combinations", "unseparated_information", "flat_indices", "flat_coordinates", "pose_families"]

#: A geometric combination is left to the prior (held at its mean) when the rows' information
#: along it, in tolerance units, is at most this: its maximum a posteriori standard deviation
#: ``1 / sqrt(1 + d)`` is then at least :data:`calib.prior.DATA_SOURCE_RATIO` of the tolerance.
HELD_INFORMATION = 1.0 / DATA_SOURCE_RATIO ** 2 - 1.0
#: Whitened residuals above which a least-squares problem of the discovery (a Gauss-Newton step,
#: a chi-square, an F test; :mod:`calib.effects.discovery`) and the geometry's basis
#: (:func:`geometry_basis`) are solved through its normal equations (columns scaled to unit norm,
#: a symmetric eigendecomposition of the small Gram matrix) instead of an SVD of the tall matrix:
#: 600,000 x 42 at 100,000 hexapod rows is 0.6 s by SVD, a tenth of that by the Gram matrix.
#: The hexapod's whitened geometry columns, scaled, have condition numbers of 1e3 to 1e4: the
#: Gram matrix squares it, which leaves 8 digits of a step that Gauss-Newton then iterates on
#: (the next step corrects the last). 20,000 hexapod rows
#: (:data:`calib.effects.search.SEARCH_ROWS_MAX`); below it the SVD, as always: nothing changes.
GRAM_MIN_RESIDUALS = 120_000
#: A direction of one chain's parameters counts as lying in the held space (and is named as that
#: chain's combination) when its cosine with that space is at least this.
IN_CHAIN_COSINE = 0.99
#: A pose coordinate whose recorded spread is below this fraction of the robot's workspace span
#: in it is one the poses did not vary (a level grid: the height, the tilts, the turn).
FLAT_FRACTION = 0.1


@dataclass(frozen=True)
class HeldCombination:
    """A geometric combination left to the prior (:meth:`GeometryBasis.combinations`): its
    ``chain`` (1-based; None: across chains), the ``combination`` in words (a unit vector in
    tolerance units, :func:`calib.observability.describe_combination`) and its maximum a
    posteriori standard deviation over the tolerance (``std_ratio``)."""

    chain: int | None
    combination: str
    std_ratio: float

    def to_dict(self) -> dict:
        return {"chain": self.chain, "combination": self.combination, "std_ratio": self.std_ratio}


@dataclass(frozen=True)
class UnseparatedCombination:
    """A coefficient combination of an effect the rows cannot separate from the geometry's held
    combinations (:meth:`calib.effects.search.LinearisedFit.unseparated`): in words, the ratio of
    its standard deviations with the geometry held and free (:func:`unseparated_combinations`),
    and the geometric combination that mimics it in words (empty: none)."""

    combination: str
    ratio: float
    geometry: str

    def to_dict(self) -> dict:
        return {"combination": self.combination, "ratio": self.ratio, "geometry": self.geometry}


@dataclass(frozen=True)
class UnseparatedForm:
    """A candidate form the selection set aside as not separable from the geometry: its
    ``effect`` and ``form`` (:func:`calib.effects.granularity.form_key`), its unseparated
    ``combinations`` (:class:`UnseparatedCombination`), and the pose families that would separate
    it (``separated_by``)."""

    effect: str
    form: str
    combinations: tuple
    separated_by: tuple = ()

    def to_dict(self) -> dict:
        return {"effect": self.effect, "form": self.form, "combinations": [c.to_dict() for c in self.combinations],
                "separated_by": list(self.separated_by)}


@dataclass(frozen=True)
class PoseFamilyReach:
    """A family of added poses (:func:`pose_families`): how many are ``reachable`` of those
    ``tried``, how many of the held combinations they would determine (``determines``), and the
    forms they would separate (``separates``)."""

    family: str
    reachable: int
    tried: int
    determines: int
    separates: tuple = ()

    def to_dict(self) -> dict:
        return {"reachable": self.reachable, "tried": self.tried, "determines": self.determines,
                "separates": list(self.separates)}


@dataclass(frozen=True)
class Separation:
    """What a discovery's rows cannot separate, and the poses that would
    (:func:`calib.effects.discovery.separation`): the geometric combinations ``determined`` (fitted)
    of the ``free`` ones, those left to the prior (:class:`HeldCombination`), the candidate forms
    set aside (:class:`UnseparatedForm`), each family of added poses (:class:`PoseFamilyReach`)."""

    determined: int
    free: int
    left_to_prior: tuple
    unseparated: tuple
    poses: tuple

    def to_dict(self) -> dict:
        """JSON-ready (the discovery summary's ``separation``, less its ``prior_source``)."""
        return {"determined": self.determined, "free": self.free,
                "left_to_prior": [c.to_dict() for c in self.left_to_prior],
                "unseparated": [u.to_dict() for u in self.unseparated],
                "poses": {p.family: p.to_dict() for p in self.poses}}


@dataclass(frozen=True, eq=False)
class GeometryBasis:
    """The free geometric combinations a set of rows determines, and those it leaves to the prior.

    Attributes:
        free: (F,) flat indices of the free parameters (table order).
        std: (F,) their tolerances (prior standard deviations), each parameter's unit.
        determined: (F, g) orthonormal basis, in tolerance units, of the combinations the rows
            determine (fitted).
        held: (F, F - g) orthonormal basis, tolerance units, of those left to the prior (held at
            the prior mean).
        information: (F, F) the rows' information on the free parameters, tolerance units.
    """

    free: np.ndarray
    std: np.ndarray
    determined: np.ndarray
    held: np.ndarray
    information: np.ndarray

    @property
    def size(self) -> int:
        """g, the determined (fitted) geometric coordinates."""
        return int(self.determined.shape[1])

    @property
    def step(self) -> np.ndarray:
        """(F, g) change of the free parameters (their units) per unit of each determined coordinate."""
        return self.std[:, None] * self.determined

    @property
    def held_step(self) -> np.ndarray:
        """(F, F - g) change of the free parameters per unit (one tolerance) of each held combination."""
        return self.std[:, None] * self.held

    def hold(self, theta: np.ndarray, mean: np.ndarray) -> np.ndarray:
        """(P,) ``theta`` with its held combinations put at ``mean``'s (the prior mean)."""
        out = np.array(theta, dtype=float)
        u = (out[self.free] - mean[self.free]) / self.std
        out[self.free] = mean[self.free] + self.std * (self.determined @ (self.determined.T @ u))
        return out

    def covariance(self, cov: np.ndarray) -> np.ndarray:
        """(F, F) covariance of the free parameters from ``cov`` (g, g) of the determined
        coordinates, the held combinations with the prior's."""
        step, held = self.step, self.held_step
        return step @ cov @ step.T + held @ held.T

    def std_ratio(self, v: np.ndarray) -> float:
        """Maximum a posteriori standard deviation over the tolerance along the unit direction
        ``v`` (F,) in tolerance units."""
        return float(1.0 / np.sqrt(1.0 + max(float(v @ self.information @ v), 0.0)))

    def combinations(self, names, chains, *, n_terms: int = 4) -> tuple[HeldCombination, ...]:
        """The held combinations in words, chain by chain where the held space contains a
        chain's own directions (a plane's ``0.71 B3.x + 0.71 P3.x``), then those across chains.

        Args:
            names: (F,) the free parameters' names; chains: (F,) their chains (0-based).

        Returns:
            One :class:`HeldCombination` per combination, least determined first.
        """
        names, chains = tuple(names), np.asarray(chains)
        found, out = [], []
        for c in np.unique(chains):
            cols = np.flatnonzero(chains == c)
            if self.held.shape[1] == 0:
                break
            _, s, vt = np.linalg.svd(self.held[cols].T, full_matrices=True)
            for k in np.flatnonzero(s >= IN_CHAIN_COSINE):
                v = np.zeros(self.free.size)
                v[cols] = vt[k]
                found.append(v)
                out.append((int(c) + 1, v))
        rest = self.held
        if found:  # the held space less the chains' own directions
            F = np.array(found).T
            rest = self.held - F @ np.linalg.lstsq(F, self.held, rcond=None)[0]
        if rest.size:
            u, s, _ = np.linalg.svd(rest, full_matrices=False)
            out += [(None, u[:, k]) for k in np.flatnonzero(s > 1 - IN_CHAIN_COSINE)]
        held = [HeldCombination(chain, describe_combination(v, names, n_terms=n_terms),
                                self.std_ratio(v / np.linalg.norm(v))) for chain, v in out]
        return tuple(sorted(held, key=lambda h: -h.std_ratio))


def geometry_basis(G: np.ndarray, std: np.ndarray, free: np.ndarray) -> GeometryBasis:
    """The combinations the rows determine and those they leave to the prior.

    Args:
        G: (M, F) whitened closure Jacobian of the free parameters (per parameter unit).
        std: (F,) the free parameters' tolerances.
        free: (F,) their flat indices.
    """
    Gs = G * std[None, :]
    information = Gs.T @ Gs
    if Gs.shape[0] > GRAM_MIN_RESIDUALS:
        # The information's eigenvectors are the right singular vectors, its eigenvalues the
        # squared singular values (largest first, as the SVD's): without a pass of an SVD over
        # the tall Gs. Eigenvalues to about 1e-16 of the largest, far below HELD_INFORMATION's
        # distance from it.
        lam, V = np.linalg.eigh(0.5 * (information + information.T))
        order = np.argsort(-lam, kind="stable")
        d, vt = lam[order], V[:, order].T
    else:
        # Every right vector: the thin SVD has them all once M >= F (the full one's M x M U would not fit)
        _, s, vt = np.linalg.svd(Gs, full_matrices=Gs.shape[0] < Gs.shape[1])
        d = np.zeros(std.size)
        d[:s.size] = s ** 2
    det = d > HELD_INFORMATION
    return GeometryBasis(free=np.asarray(free), std=np.asarray(std, dtype=float), determined=vt[det].T,
                         held=vt[~det].T, information=information)


def unseparated_combinations(X_held: np.ndarray, X_free: np.ndarray, rtol: float = 1e-9) -> list[tuple[np.ndarray, float]]:
    """The coefficient combinations of an effect that cannot be separated from the geometry.

    Args:
        X_held: (M, p) the effect's whitened closure columns, the determined geometry projected out.
        X_free: (M, p) the same with every free geometric combination projected out.

    Returns:
        ``[(v (p,) unit combination, ratio)]``: each combination whose standard deviation with the
        geometry held is less than :data:`calib.prior.DATA_SOURCE_RATIO` times that with the
        geometry free (``ratio``, the two's quotient), least separable first. Combinations the
        rows do not determine even with the geometry held are no concern here.
    """
    return unseparated_information(X_held.T @ X_held, X_free.T @ X_free, rtol)


def unseparated_information(I_held: np.ndarray, I_free: np.ndarray, rtol: float = 1e-9) -> list[tuple[np.ndarray, float]]:
    """:func:`unseparated_combinations` from the informations ``I_held`` and ``I_free`` (p, p) of
    the effect's coefficients (``X_held^T X_held``, ``X_free^T X_free``): where the tall columns'
    products are formed otherwise (:meth:`calib.effects.remainder._Remainder.f_test`)."""
    lam, V = np.linalg.eigh(0.5 * (I_held + I_held.T))
    keep = lam > rtol * max(float(lam.max(initial=0.0)), 1e-300)
    if not keep.any():
        return []
    W = V[:, keep] / np.sqrt(lam[keep])  # I_held^(-1/2) on its range
    mu, U = np.linalg.eigh(W.T @ I_free @ W)
    out = []
    for k in np.argsort(mu):
        if mu[k] >= DATA_SOURCE_RATIO ** 2:
            break
        v = W @ U[:, k]
        out.append((v / np.linalg.norm(v), float(np.sqrt(max(mu[k], 0.0)))))
    return out


def flat_indices(measured: np.ndarray, bounds: np.ndarray) -> list[int]:
    """The pose coordinates the poses ``measured`` (N, D) did not vary: standard deviation below
    :data:`FLAT_FRACTION` of the workspace's span ``bounds`` (D, 2) in it."""
    span = np.ptp(bounds, axis=1)
    return [k for k in range(measured.shape[1]) if span[k] > 0 and measured[:, k].std() < FLAT_FRACTION * span[k]]


def flat_coordinates(data) -> tuple[str, ...]:
    """Names of the pose coordinates an :class:`calib.effects.EffectData`'s poses did not vary
    (:func:`flat_indices` over the robot's workspace)."""
    names = data.robot.pose_names
    return tuple(names[k] for k in flat_indices(data.measured, data.robot.workspace_bounds()))


def pose_families(measured: np.ndarray, bounds: np.ndarray, names, units, *, n_rows: int = 30) -> dict:
    """Poses that would vary what the recorded ones keep constant.

    Args:
        measured: (N, D) the recorded poses (base frame).
        bounds: (D, 2) the robot's workspace, low/high per pose coordinate.
        names, units: (D,) the pose coordinates' names and units.
        n_rows: recorded poses each family moves (evenly spaced over the rows).

    Returns:
        ``{family in words: (n_rows, D) poses}``: for each coordinate the poses did not vary
        (standard deviation below :data:`FLAT_FRACTION` of the workspace's span in it), the recorded poses
        with that coordinate at its mean +- half the span, alternately; and, when there are
        several such coordinates, all of them so at once (alternating independently).
    """
    span = np.ptp(bounds, axis=1)
    flat = flat_indices(measured, bounds)
    rows = np.unique(np.linspace(0, measured.shape[0] - 1, min(n_rows, measured.shape[0])).round().astype(int))
    base = measured[rows]
    signs = np.where(np.arange(rows.size) % 2 == 0, 1.0, -1.0)
    out = {}
    for k in flat:
        p = base.copy()
        p[:, k] = measured[:, k].mean() + signs * span[k] / 2
        out[f"{names[k]} varied ({measured[:, k].mean():.4g} +- {span[k] / 2:.3g} {units[k]})"] = p
    if len(flat) > 1:
        p = base.copy()
        for j, k in enumerate(flat):
            s = np.where((np.arange(rows.size) >> j) % 2 == 0, 1.0, -1.0)
            p[:, k] = measured[:, k].mean() + s * span[k] / 2
        out[f"{', '.join(names[k] for k in flat)} varied together"] = p
    return out
