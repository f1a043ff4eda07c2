"""The outlier scan: rows that are gross and isolated, closed-form leave-one-out (a room of
:mod:`calib.effects.discovery`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import chi2 as chi2_dist

from .base import EffectData
from .joint_fit import EffectFit, span_bases

__all__ = ["OUTLIER_ALPHA", "MAX_BAD_FRACTION", "NEIGHBOURS", "SHARED_Z", "SharedRow", "OutlierScan", "outlier_scan"]

#: Family-wise significance of the outlier test (Bonferroni over the rows).
OUTLIER_ALPHA = 1e-3
#: More rows than this fraction looking bad: the model is wrong, not the data.
MAX_BAD_FRACTION = 0.05
#: Neighbours a row is compared with (in time, in the workspace, in the direction of motion).
NEIGHBOURS = 6
#: A row's residual is shared by its neighbours when their mean residual along it is this many
#: standard errors from zero.
SHARED_Z = 3.0


@dataclass(frozen=True)
class SharedRow:
    """A bad row that is not isolated: ``row`` (0-based, of the rows scanned) and ``by``, per
    neighbourhood that shares it (``time``, ``workspace``, ``direction of motion``) ``(label,
    score)``, the neighbours' summed residual along the row's, in standard errors."""

    row: int
    by: tuple


@dataclass(frozen=True, eq=False)
class OutlierScan:
    """The outlier scan (:func:`outlier_scan`).

    Attributes:
        statistic: (N,) each row's statistic over the robust scale.
        threshold: the Bonferroni-corrected threshold; scale: the robust scale (at least 1).
        bad: rows (0-based) beyond the threshold; flagged: those of them that are isolated.
        shared: the bad rows their neighbours share (:class:`SharedRow`).
        model_wrong: more rows than the limit looked bad: the model is wrong, nothing flagged.
    """

    statistic: np.ndarray
    threshold: float
    scale: float
    bad: tuple
    flagged: tuple = ()
    shared: tuple = ()
    model_wrong: bool = False

    def cleared(self, *, model_wrong: bool | None = None) -> "OutlierScan":
        """This scan with no row flagged (and ``model_wrong`` said, when given)."""
        return replace(self, flagged=(), model_wrong=self.model_wrong if model_wrong is None else model_wrong)


def _neighbour_sets(data: EffectData) -> list[np.ndarray]:
    """(N, K) indices of each row's nearest neighbours in time, in the workspace (pose
    coordinates scaled by their spread) and in the direction of motion (fewest joints moving
    the other way, then nearest in the workspace)."""
    n = data.n
    k = min(NEIGHBOURS, n - 1)
    t = data.t_s
    dt = np.abs(t[:, None] - t[None, :])
    np.fill_diagonal(dt, np.inf)
    spread = data.measured.std(axis=0)
    spread[spread == 0] = 1.0
    p = data.measured / spread
    dp = np.sqrt(((p[:, None, :] - p[None, :, :]) ** 2).sum(-1))
    np.fill_diagonal(dp, np.inf)
    dd = (data.direction[:, None, :] != data.direction[None, :, :]).sum(-1) + dp / (dp[np.isfinite(dp)].max() + 1)
    np.fill_diagonal(dd, np.inf)
    return [np.argsort(d, axis=1, kind="stable")[:, :k] for d in (dt, dp, dd)]


def _deleted(Q: np.ndarray, w: np.ndarray, bad: np.ndarray):
    """Leave-one-out statistics with the rows ``bad`` left out of the fit, closed form.

    ``Q`` (N C, r) orthonormal basis of the whitened design, ``w`` (N, C) whitened residuals.
    With ``G = (I - H_BB)^-1`` the bad rows' joint deleted residuals are ``u = G w_B``
    (covariance ``G``), the other rows' residuals of the fit without them
    ``e = w + Q Q_B^T u``, and that fit's hat matrix ``Q (I + Q_B^T G Q_B) Q^T``.

    Returns:
        ``(statistic (N,), e (N, C), u (|B|, C))``: each row's chi-square(C) statistic (a
        kept row's studentized deleted residual, a bad row's deleted residual against the fit
        without every bad row).
    """
    n, C = w.shape
    r = Q.shape[1]
    idx = (bad[:, None] * C + np.arange(C)).ravel()
    if idx.size:
        QB = Q[idx]
        G = np.linalg.inv(np.eye(idx.size) - QB @ QB.T)
        u = G @ w.ravel()[idx]
        e = (w.ravel() + Q @ (QB.T @ u)).reshape(n, C)
        K = np.eye(r) + QB.T @ G @ QB
    else:
        G = u = np.zeros(0)
        e, K = w, np.eye(r)
    Qr = Q.reshape(n, C, r)
    H = Qr @ K @ np.swapaxes(Qr, 1, 2)
    d = np.linalg.solve(np.eye(C)[None] - H, e[..., None])[..., 0]
    stat = np.einsum("ni,ni->n", e, d)
    u = np.asarray(u).reshape(-1, C)
    for b, j in enumerate(bad):
        blk = G[b * C:(b + 1) * C, b * C:(b + 1) * C]
        stat[j] = float(u[b] @ np.linalg.solve(blk, u[b]))
    return stat, e, u


def outlier_scan(data: EffectData, fit: EffectFit, *, alpha: float = OUTLIER_ALPHA,
                 max_bad_fraction: float = MAX_BAD_FRACTION) -> OutlierScan:
    """Rows that are gross and isolated (closed-form leave-one-out, no refits).

    With ``Q`` an orthonormal basis of the fit's whitened design (the columns it fitted: a
    combination held at its prior is not fitted and lends no row leverage; with its small column
    made a unit vector, a row it alone moves, the first row of a level grid, the move from home,
    had leverage near one and a 2 mm dead band's first row was flagged, and the dead band lost),
    the hat matrix's block of row j is ``H_jj = Q_j Q_j^T`` (C x C); the row's deleted residual (predicted by the model fitted
    without it) is ``d_j = (I - H_jj)^-1 w_j`` and ``t_j = w_j^T (I - H_jj)^-1 w_j`` is
    chi-square with C degrees of freedom for a consistent row. ``t`` is divided by a robust
    scale (its median over the median of chi-square(C), at least 1), so that "gross" means
    gross against the remainder's own spread. A row is bad when ``t`` exceeds the
    Bonferroni-corrected ``alpha``, the statistics being recomputed with the bad rows left out
    of the fit until the set settles (:func:`_deleted`, against masking and swamping). A bad row
    is an outlier only when it is isolated: the sum of its good neighbours' residuals (the fit
    without every bad row) along its own deleted residual, over the square root of their
    number, stays below :data:`SHARED_Z` (in time, in the workspace, in the direction of
    motion). When more than ``max_bad_fraction`` of the rows are
    bad, the model is wrong, not the data: nothing is flagged.

    Returns:
        :class:`OutlierScan`: ``statistic`` (N,), ``threshold``, ``scale``, ``bad`` and ``flagged``
        (0-based indices), ``shared`` (bad rows not flagged, with the neighbourhood that shares
        them), ``model_wrong``.
    """
    n, C = data.n, data.robot.n_chains
    Q, Q_det = span_bases(fit)
    Q = Q if Q_det is None else Q_det
    w = fit.whitened
    stat, clean, u = _deleted(Q, w, np.zeros(0, dtype=int))
    scale = max(1.0, float(np.median(stat) / chi2_dist.median(C)))
    thr = float(chi2_dist.isf(alpha / n, C))
    bad = np.flatnonzero(stat / scale > thr)
    # Masking and swamping: the statistics again with the bad rows left out of the fit, until the
    # set of bad rows settles (closed form each time).
    for _ in range(10):
        if bad.size == 0 or bad.size > max(1, max_bad_fraction * n):
            break
        stat, clean, u = _deleted(Q, w, bad)
        again = np.flatnonzero(stat / scale > thr)
        if np.array_equal(again, bad):
            break
        bad = again
    out = OutlierScan(stat / scale, thr, scale, tuple(bad.tolist()))
    if bad.size > max(1, max_bad_fraction * n):
        return replace(out, model_wrong=True)
    if bad.size == 0:
        return out
    stat, clean, u = _deleted(Q, w, bad)
    clean = clean / np.sqrt(scale)
    bad_set = set(bad.tolist())
    flagged, shared_rows = [], []
    for b, j in enumerate(bad):
        unit = u[b] / np.linalg.norm(u[b])
        shared = []
        for label, nb in zip(("time", "workspace", "direction of motion"), _neighbour_sets(data)):
            others = [i for i in nb[j] if i not in bad_set]
            if not others:
                continue
            score = float((clean[others] @ unit).sum() / np.sqrt(len(others)))
            if score > SHARED_Z:
                shared.append((label, score))
        if shared:
            shared_rows.append(SharedRow(int(j), tuple(shared)))
        else:
            flagged.append(int(j))
    return replace(out, flagged=tuple(flagged), shared=tuple(shared_rows))
