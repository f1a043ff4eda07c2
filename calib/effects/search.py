"""The joint fit linearised at the geometry-only solution, and the search of the effects'
searched parameters (a pitch, a time constant, a step time) on it (a room of
:mod:`calib.effects.discovery`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..observability import describe_combination
from .base import Effect, EffectData, closure_regressors, orthonormal_columns
from .separability import UnseparatedCombination, unseparated_combinations
from .whitening import free_indices, noise_covariance, scaled_least_squares, whiten

__all__ = ["LinearisedFit", "SearchForm", "DENSE_FOLD_MAX", "SEARCH_GRID_MAX", "SEARCH_BEAM", "SEARCH_ROWS_MAX",
           "SEARCH_SUBSAMPLE_ROWS", "SEARCH_GOLDEN_ITERATIONS", "SEARCH_CONFIRMED", "SEARCH_REFINE_ITERATIONS",
           "SEARCH_WINDOW_SPACINGS", "SEARCH_UPDATE_ROWS", "search_subsample"]


@dataclass(frozen=True)
class SearchForm:
    """How the searched parameters (a pitch, a time constant, a step time) were searched
    (:meth:`LinearisedFit.search_form`): ``form`` ``every row``, or ``subsample`` above
    ``threshold`` measurements: ``rows`` measurements, the grid scanned on ``subsample_rows`` of
    them and confirmed on every row, for the ``effects`` named (sorted)."""

    form: str = "every row"
    rows: int | None = None
    subsample_rows: int | None = None
    threshold: int | None = None
    effects: tuple = ()

    def to_dict(self) -> dict:
        """JSON-ready (the discovery summary's ``search``)."""
        if self.form != "subsample":
            return {"form": self.form}
        return {"form": self.form, "rows": self.rows, "subsample_rows": self.subsample_rows,
                "threshold": self.threshold, "effects": list(self.effects)}


class LinearisedFit:
    """The joint fit linearised at the geometry-only solution: whitened residual ``b`` and
    effect columns with the geometry projected out, so that a subset's fit is one small
    least-squares problem and its cross-validation closed form. Every free geometric combination
    is projected out, those a prior holds too: an effect earns its place only by what no
    geometry explains. The columns are taken at ``data``'s regressor poses (on a plane of poses
    the model's: :func:`calib.effects.joint_fit.model_poses`). ``geometry``: the geometry-only
    fit (:class:`calib.effects.joint_fit.EffectFit`; its ``theta`` and ``basis`` are read)."""

    def __init__(self, data: EffectData, geometry, *, search_rows_max: int | None = None,
                 search_subsample_rows: int | None = None, seed: int = 0):
        robot = data.robot
        self.data, self.theta = data, geometry.theta
        self.search_rows_max = SEARCH_ROWS_MAX if search_rows_max is None else int(search_rows_max)
        self.search_subsample_rows = SEARCH_SUBSAMPLE_ROWS if search_subsample_rows is None else int(search_subsample_rows)
        self.seed = seed
        self.searches: list = []  # the subsampled searches made (:meth:`search_form`)
        self._spaces_for: tuple = ((), None)
        self._cv_folds: tuple = (None,)  # (key, ...) of _cv_rms_blocked's fold blocks
        self._M = None  # the whitened closure per joint displacement, made by _spaces when first asked
        jac = robot.closure_jacobians(self.theta, data.joints, data.regressor_poses)
        self.winv = np.linalg.inv(np.linalg.cholesky(noise_covariance(robot, jac, data)))
        self.dF_dq = jac.joints
        free = free_indices(robot)
        G = whiten(self.winv, jac.parameters[:, :, free]).reshape(-1, free.size)
        self.basis = geometry.basis
        self.Qg = orthonormal_columns(G)
        if self.basis is not None:  # for the separability screen: the determined combinations alone
            self.Q_det = orthonormal_columns(G @ self.basis.step)
            H = G @ self.basis.held_step
            self.G_held = H - self.Q_det @ (self.Q_det.T @ H)
        self.b = self.perp(-whiten(self.winv, robot.closure(self.theta, data.joints, data.measured)).ravel())
        self.n = self.b.size
        self.dof0 = self.n - self.Qg.shape[1]
        self.C = robot.n_chains
        self._cols: dict = {}

    def perp(self, M: np.ndarray) -> np.ndarray:
        return M - self.Qg @ (self.Qg.T @ M)

    def columns(self, eff: Effect, extra) -> np.ndarray:
        """(N C, p) whitened closure regressors of ``eff``, geometry projected out."""
        key = (eff.name, id(eff), extra)
        if key not in self._cols:
            robot = self.data.robot
            X = closure_regressors(self.dF_dq, eff.joint_regressors(robot, self.theta, self.data, extra))
            self._cols[key] = self.perp(whiten(self.winv, X).reshape(self.n, -1))
        return self._cols[key]

    def unseparated(self, eff: Effect, extra) -> tuple[UnseparatedCombination, ...]:
        """The coefficient combinations of ``eff`` the rows cannot separate from the geometry's
        held combinations (:func:`calib.effects.separability.unseparated_combinations`), each
        with the geometric combination that mimics it (:class:`calib.effects.separability.UnseparatedCombination`;
        empty without a held combination)."""
        if self.basis is None:
            return ()
        robot = self.data.robot
        X = whiten(self.winv, closure_regressors(self.dF_dq, eff.joint_regressors(robot, self.theta, self.data, extra)))
        X = X.reshape(self.n, -1)
        held = X - self.Q_det @ (self.Q_det.T @ X)
        found = unseparated_combinations(held, self.perp(X))
        if not found:
            return ()
        coef_names = [c.name for c in eff.coefficients(robot)]
        free_names = [robot.table.names[i] for i in self.basis.free]
        out = []
        for v, ratio in found:
            w, *_ = np.linalg.lstsq(self.G_held, held @ v, rcond=None)  # held combinations mimicking it
            u = self.basis.held @ w
            out.append(UnseparatedCombination(describe_combination(v, coef_names), ratio,
                                              describe_combination(u / np.linalg.norm(u), free_names)
                                              if np.any(u) else ""))
        return tuple(out)

    def chi2(self, blocks: list) -> float:
        if not blocks:
            return float(self.b @ self.b)
        A = np.hstack(blocks)
        e = self.b - A @ scaled_least_squares(A, self.b)
        return float(e @ e)

    @property
    def above_search_rows(self) -> bool:
        """More measurements than ``search_rows_max``: the searches on a subsample
        (:meth:`_subsampled_search`), the cross-validation by blocks (:meth:`_cv_rms_blocked`)."""
        return self.n // self.C > self.search_rows_max

    def search(self, eff: Effect, blocks: list) -> float:
        """The searched parameter minimising the chi-square with ``blocks`` fitted too: on the
        effect's grid of the search coordinate, refined by golden-section search between the
        best grid point's neighbours (unless the effect says its fit is constant between grid
        points: :attr:`Effect.refine_search`). Above ``search_rows_max`` measurements the grid is
        scanned on a subsample and confirmed and refined on every row (:meth:`_subsampled_search`)."""
        if self.above_search_rows:
            return self._subsampled_search(eff, blocks)
        Q = orthonormal_columns(np.hstack(blocks)) if blocks else np.zeros((self.n, 0))
        b = self.b - Q @ (Q.T @ self.b)
        robot = self.data.robot

        def cost(u):
            X = closure_regressors(self.dF_dq, eff.joint_regressors(robot, self.theta, self.data,
                                                                     eff.searched_value(u)))
            Xp = self.perp(whiten(self.winv, X).reshape(self.n, -1))
            Xp = Xp - Q @ (Q.T @ Xp)
            x, *_ = np.linalg.lstsq(Xp, b, rcond=None)
            e = b - Xp @ x
            return float(e @ e)

        grid = eff.search_grid(self.data)
        if not eff.refine_search and len(grid) > SEARCH_GRID_MAX:
            return eff.searched_value(grid[_coarse_to_fine(cost, grid)])
        costs = np.array([cost(u) for u in grid])
        k = int(np.argmin(costs))
        if not eff.refine_search:
            return eff.searched_value(grid[k])
        a, b_ = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        return eff.searched_value(_golden(cost, a, b_, SEARCH_GOLDEN_ITERATIONS))

    def _cv_rms_blocked(self, blocks: list, folds: int, seed: int) -> float:
        """:meth:`cv_rms` through the Woodbury identity with the geometry's part of each fold
        kept: the rows reordered fold by fold once (each fold a slice), and each fold's
        ``Qg_k^T Qg_k`` computed once for every call with the same ``folds`` and ``seed``; a call
        then costs a pass over the effects' few columns. The same deleted residuals."""
        key = (folds, seed)
        if self._cv_folds[0] != key:
            m = self.n // self.C
            order = np.random.default_rng(seed).permutation(m)
            parts = [np.sort(order[k::folds]) for k in range(folds)]
            idx = np.concatenate([(r[:, None] * self.C + np.arange(self.C)).ravel() for r in parts])
            bounds = np.cumsum([0] + [r.size * self.C for r in parts])
            Qg = self.Qg[idx]
            grams = [Qg[lo:hi].T @ Qg[lo:hi] for lo, hi in zip(bounds[:-1], bounds[1:])]
            self._cv_folds = (key, idx, bounds, Qg, grams)
        _, idx, bounds, Qg, grams = self._cv_folds
        Qb = orthonormal_columns(np.hstack(blocks)) if blocks else np.zeros((self.n, 0))
        e = (self.b - Qb @ (Qb.T @ self.b))[idx]  # b has the geometry projected out already
        Qb = Qb[idx]
        g = Qg.shape[1]
        ss = 0.0
        for (lo, hi), Gk in zip(zip(bounds[:-1], bounds[1:]), grams):
            Qgk, Qbk, ek = Qg[lo:hi], Qb[lo:hi], e[lo:hi]
            cross = Qgk.T @ Qbk
            K = np.eye(g + Qbk.shape[1]) - np.block([[Gk, cross], [cross.T, Qbk.T @ Qbk]])
            y = np.linalg.solve(K, np.concatenate([Qgk.T @ ek, Qbk.T @ ek]))
            d = ek + Qgk @ y[:g] + Qbk @ y[g:]
            ss += float(d @ d)
        return float(np.sqrt(ss / self.n))

    def _spaces(self, blocks: list) -> tuple["_SearchSpace", "_SearchSpace"]:
        """The subsample's and every row's :class:`_SearchSpace` with ``blocks`` fitted (the last
        ones kept: every candidate of a selection step is searched with the same blocks)."""
        kept, spaces = self._spaces_for
        if spaces is not None and len(kept) == len(blocks) and all(a is b for a, b in zip(kept, blocks)):
            return spaces
        C = self.C
        if self._M is None:
            self._M = -(self.winv @ self.dF_dq)  # whitened closure per joint displacement (closure_regressors)
        Qb = orthonormal_columns(np.hstack(blocks)) if blocks else np.zeros((self.n, 0))
        full = _SearchSpace(self.data, self.theta, self._M, np.hstack([self.Qg, Qb]), self.b - Qb @ (Qb.T @ self.b))
        rows = search_subsample(self.data.t_s, self.search_subsample_rows, self.seed)
        idx = (rows[:, None] * C + np.arange(C)).ravel()
        # Every row's geometry columns restricted to the subsample span the subsample's own; so do
        # the blocks and b (each every row's minus a geometric part): projected again on the
        # subsample they are the subsample's linearised fit.
        Qg = orthonormal_columns(self.Qg[idx])
        B = np.hstack([x[idx] for x in blocks]) if blocks else np.zeros((idx.size, 0))
        Q = np.hstack([Qg, orthonormal_columns(B - Qg @ (Qg.T @ B))])
        sub = _SearchSpace(self.data.subset(rows), self.theta, self._M[rows], Q, self.b[idx] - Q @ (Q.T @ self.b[idx]))
        self._spaces_for = (list(blocks), (sub, full))
        return sub, full

    def _subsampled_search(self, eff: Effect, blocks: list) -> float:
        """:meth:`search` above ``search_rows_max`` measurements: the effect's grid (every row's)
        scanned on ``search_subsample_rows`` rows (:func:`search_subsample`), then on every
        row the :data:`SEARCH_CONFIRMED` best local minima of the subsample's chi-square
        compared, the best followed down to a local minimum of every row's chi-square over the
        grid and refined by :data:`SEARCH_REFINE_ITERATIONS` golden-section steps between its
        grid neighbours; a search not refined (:attr:`Effect.refine_search`) tries
        every grid point within :data:`SEARCH_WINDOW_SPACINGS` subsample row spacings of the
        subsample's best on every row (coarse to fine past :data:`SEARCH_GRID_MAX`)."""
        sub, full = self._spaces(blocks)
        grid = eff.search_grid(self.data)
        m = sub.data.n
        self.searches.append(eff.name)
        if not eff.refine_search:
            if len(grid) > SEARCH_GRID_MAX:
                k = _coarse_to_fine(lambda u: sub.cost(eff, u), grid)
            else:
                k = int(np.argmin([sub.cost(eff, u) for u in grid]))
            w = int(np.ceil(SEARCH_WINDOW_SPACINGS * self.data.n / m))
            lo, hi = max(k - w, 0), min(k + w, len(grid) - 1)
            window = grid[lo:hi + 1]
            if len(window) > SEARCH_GRID_MAX:
                j = _coarse_to_fine(lambda u: full.cost(eff, u), window)
            else:  # consecutive points: each updated from the one before (a step time: one row changes)
                j = int(np.argmin(full.costs(eff, window)))
            return eff.searched_value(window[j])
        costs = np.array([sub.cost(eff, u) for u in grid])
        inner = np.r_[True, costs[1:] <= costs[:-1]] & np.r_[costs[:-1] <= costs[1:], True]
        minima = sorted(np.flatnonzero(inner), key=lambda i: (costs[i], i))[:SEARCH_CONFIRMED]
        known: dict[int, float] = {}

        def at(i: int) -> float:
            if i not in known:
                known[i] = full.cost(eff, grid[i])
            return known[i]

        k = min(minima, key=lambda i: (at(i), i))
        while True:  # down to a local minimum of every row's chi-square over the grid
            j = min((i for i in (k - 1, k + 1) if 0 <= i < len(grid)), key=lambda i: (at(i), i))
            if at(j) >= at(k):
                break
            k = j
        a, b_ = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        return eff.searched_value(_golden(lambda u: full.cost(eff, u), a, b_, SEARCH_REFINE_ITERATIONS))

    def search_form(self) -> SearchForm:
        """How the searched parameters were searched (:class:`SearchForm`): on every row or, when a
        search ran on a subsample, its figures and the effects so searched."""
        if not self.searches:
            return SearchForm()
        return SearchForm("subsample", int(self.data.n), int(min(self.search_subsample_rows, self.data.n)),
                          self.search_rows_max, tuple(sorted(set(self.searches))))

    def cv_rms(self, blocks: list, folds: int, seed: int) -> float:
        """Whitened RMS of the deleted residuals of ``folds``-fold cross-validation (whole
        measurements left out), closed form through the hat matrix. Above ``search_rows_max``
        measurements the folds' geometry blocks are computed once (:meth:`_cv_rms_blocked`)."""
        if self.above_search_rows:
            return self._cv_rms_blocked(blocks, folds, seed)
        Q = self.Qg if not blocks else np.hstack([self.Qg, orthonormal_columns(np.hstack(blocks))])
        e = self.b - Q @ (Q.T @ self.b)
        m = self.n // self.C
        order = np.random.default_rng(seed).permutation(m)
        ss = 0.0
        for k in range(folds):
            rows = np.sort(order[k::folds])
            idx = (rows[:, None] * self.C + np.arange(self.C)).ravel()
            Qi = Q[idx]
            if idx.size <= DENSE_FOLD_MAX:
                d = np.linalg.solve(np.eye(idx.size) - Qi @ Qi.T, e[idx])
            else:  # Woodbury: (I - Qi Qi^T)^-1 e = e + Qi (I - Qi^T Qi)^-1 Qi^T e, a (p, p) system
                d = e[idx] + Qi @ np.linalg.solve(np.eye(Qi.shape[1]) - Qi.T @ Qi, Qi.T @ e[idx])
            ss += float(d @ d)
        return float(np.sqrt(ss / self.n))


#: A search grid longer than this (a step's time: one point per row and chain, the search's cost
#: growing as the rows squared) is searched coarse to fine: this many evenly spaced points, then
#: as many across the coarse intervals around the :data:`SEARCH_BEAM` best, and so on down to
#: single points. Where the chi-square has a basin around its minimum wider than a coarse
#: interval (a step misplaced by d rows leaves d rows wrong: it rises with |d|) the search finds
#: the point trying every one would.
SEARCH_GRID_MAX = 200
#: The best points of a level of the coarse-to-fine search whose neighbourhoods the next refines.
SEARCH_BEAM = 3


def _coarse_to_fine(cost, grid) -> int:
    """The index into ``grid`` that the coarse-to-fine search finds (:data:`SEARCH_GRID_MAX`
    points a level, :data:`SEARCH_BEAM` windows refined; ``cost(grid[i])`` the chi-square of
    point i)."""
    known: dict[int, float] = {}

    def at(i: int) -> float:
        if i not in known:
            known[i] = cost(grid[i])
        return known[i]

    windows, last = [(0, len(grid) - 1)], len(grid)
    while True:
        per = max(2, SEARCH_GRID_MAX // len(windows))
        tried, step = set(), 1
        for lo, hi in windows:
            idx = np.unique(np.linspace(lo, hi, min(per, hi - lo + 1)).round().astype(int))
            tried.update(int(i) for i in idx)
            if idx.size > 1:
                step = max(step, int(np.max(np.diff(idx))))
        if step >= last:  # no finer than the level before: every point of the windows
            tried.update(i for lo, hi in windows for i in range(lo, hi + 1))
            step = 1
        best = sorted(tried, key=lambda i: (at(i), i))[:SEARCH_BEAM]
        if step == 1:  # every point of the windows tried
            return best[0]
        windows, last = [(max(k - step, 0), min(k + step, len(grid) - 1)) for k in best], step


#: A fold of the closed-form cross-validation (:meth:`cv_rms`) with more whitened residuals than
#: this is solved through the Woodbury identity (a P x P system, P the regressors) instead of
#: the dense (n_k x n_k) one of its rows: the same deleted residuals, without a matrix that
#: grows as the fold's rows squared (107 GiB at 100,000 hexapod rows in 5 folds).
DENSE_FOLD_MAX = 2000


#: Measurements above which a searched parameter's grid is scanned on a subsample
#: (:meth:`LinearisedFit.search`): one evaluation of the chi-square is a pass over every whitened
#: residual (0.22 s at 100,000 hexapod rows), and a selection step searches every candidate's grid
#: (about 1,300 evaluations on the full library). Below it nothing changes.
SEARCH_ROWS_MAX = 20_000
#: Rows of that subsample (:func:`search_subsample`). A searched value is located to within its
#: grid step when its effect's chi-square reduction on the subsample, ``S m / N`` for a
#: reduction ``S`` on every row, is some 44 or more (a screw's pitch: a grid step shifts the
#: phase by a sixth of a turn across the stroke, which costs ``S m / N`` times about 9%); every row
#: then confirms and refines it (:data:`SEARCH_CONFIRMED`, :data:`SEARCH_REFINE_ITERATIONS`).
SEARCH_SUBSAMPLE_ROWS = 10_000
#: Golden-section steps of the search between the best grid point's neighbours.
SEARCH_GOLDEN_ITERATIONS = 30
#: Local minima of the subsample's chi-square over the grid compared on every row.
SEARCH_CONFIRMED = 3
#: Golden-section steps on every row between the confirmed grid point's neighbours: the bracket
#: of two grid steps shrinks to 0.016 of one (:data:`SEARCH_GOLDEN_ITERATIONS` on every row take it to 1e-6 of one).
SEARCH_REFINE_ITERATIONS = 10
#: A search that is not refined (a step time between two measurements) tries, on every row,
#: the grid points within this many subsample row spacings (rows / subsample rows) of the
#: subsample's best: the subsample's chi-square is the same anywhere between two of its rows.
SEARCH_WINDOW_SPACINGS = 2


def search_subsample(t_s: np.ndarray, size: int, seed: int) -> np.ndarray:
    """Sorted indices of a seeded subsample of ``size`` rows stratified in time: the rows in time
    order cut into ``size`` consecutive strata, one row drawn from each (every row when there are
    no more than ``size``). ``t_s`` (N,) s."""
    n = t_s.size
    if n <= size:
        return np.arange(n)
    order = np.argsort(t_s, kind="stable")
    edges = np.linspace(0, n, size + 1).astype(int)
    rng = np.random.default_rng(seed)
    pick = edges[:-1] + (rng.random(size) * np.diff(edges)).astype(int)
    return np.sort(order[pick])


@dataclass(frozen=True, eq=False)
class _SearchSpace:
    """The linearised fit's whitened space on some rows, for a searched parameter's chi-square:
    ``data`` those rows, ``theta`` (P,) the linearisation point, ``M`` (n, C, C) the whitened
    closure per unit joint displacement, ``Q`` (n C, r) an orthonormal basis of what is fitted
    beside the effect (the geometry, the other effects' columns), ``b`` (n C,) the whitened
    residual with ``Q`` projected out."""

    data: EffectData
    theta: np.ndarray
    M: np.ndarray
    Q: np.ndarray
    b: np.ndarray

    def cost(self, eff: Effect, u) -> float:
        """The chi-square left with ``eff`` at search coordinate ``u`` fitted too."""
        Xq = eff.joint_regressors(self.data.robot, self.theta, self.data, eff.searched_value(u))
        X = (self.M @ Xq).reshape(self.b.size, -1)
        # One pass over Q, not two: with P = I - Q Q^T, (P X)^T (P X) = X^T X - (Q^T X)^T (Q^T X)
        # and (P X)^T b = X^T b (b has Q projected out). (X^T Q)^T: the product with the tall Q
        # as BLAS does it fastest (half the time of Q^T X for a few columns).
        return self._cost(X.T @ X, (X.T @ self.Q).T, X.T @ self.b)

    def _cost(self, XtX: np.ndarray, QX: np.ndarray, Xtb: np.ndarray) -> float:
        """The chi-square from the products of the effect's whitened columns ``X``: ``X^T X``,
        ``Q^T X`` and ``X^T b``. The chi-square's reduction is b^T P X ((P X)^T P X)^+ (P X)^T b,
        the columns scaled to unit norm first."""
        G = XtX - QX.T @ QX
        scale = np.sqrt(np.clip(np.diag(G), 0.0, None))
        scale[scale == 0] = 1.0
        Xb = Xtb / scale
        return float(self.b @ self.b - Xb @ np.linalg.pinv(G / np.outer(scale, scale), hermitian=True) @ Xb)

    def costs(self, eff: Effect, us) -> np.ndarray:
        """(len(us),) :meth:`cost` at each of ``us`` in turn, updated from the one before where
        the effect's joint regressors differ on at most :data:`SEARCH_UPDATE_ROWS` rows (a step
        time moved to the next midpoint changes one row): the products over every row are then
        corrected by the changed rows' alone. The same chi-squares to rounding."""
        robot, C = self.data.robot, self.M.shape[1]
        out, last = [], None
        for u in us:
            Xq = eff.joint_regressors(robot, self.theta, self.data, eff.searched_value(u))
            rows = None if last is None else np.flatnonzero(np.any(Xq != last[0], axis=(1, 2)))
            if rows is None or rows.size > SEARCH_UPDATE_ROWS:
                X = (self.M @ Xq).reshape(self.b.size, -1)
                XtX, QX, Xtb = X.T @ X, (X.T @ self.Q).T, X.T @ self.b
            else:
                _, XtX, QX, Xtb = last
                idx = (rows[:, None] * C + np.arange(C)).ravel()
                old = (self.M[rows] @ last[0][rows]).reshape(idx.size, -1)
                D = (self.M[rows] @ Xq[rows]).reshape(idx.size, -1) - old
                XtX = XtX + D.T @ old + old.T @ D + D.T @ D
                QX = QX + self.Q[idx].T @ D
                Xtb = Xtb + D.T @ self.b[idx]
            last = (Xq, XtX, QX, Xtb)
            out.append(self._cost(XtX, QX, Xtb))
        return np.array(out)


#: Rows on which two consecutive points of a search differ at most for :meth:`_SearchSpace.costs`
#: to update the chi-square from the point before rather than pass over every row.
SEARCH_UPDATE_ROWS = 1000


def _golden(cost, a: float, b: float, iterations: int) -> float:
    """The midpoint of the bracket golden-section search leaves of ``[a, b]`` after ``iterations`` steps."""
    g = (np.sqrt(5) - 1) / 2
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = cost(c), cost(d)
    for _ in range(iterations):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = cost(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = cost(d)
    return (a + b) / 2
