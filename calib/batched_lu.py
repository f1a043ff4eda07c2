"""LU factorisation of a stack of small square matrices: factor once, solve many times.

The forward kinematics' Newton iteration solves one small (6 x 6 for the hexapod) system per
pose per step, for thousands of poses, and its chord steps solve again with the same matrices.
``numpy.linalg.solve`` hands each matrix to LAPACK on its own (about 1 us a 6 x 6 system here,
most of it per-matrix overhead) and keeps no factors. :class:`BatchedLU` eliminates all the
matrices at once, structure-of-arrays (each entry of every matrix one contiguous row of M
values, so that numpy's inner loops run over the M matrices), and keeps the factors for every
later right-hand side.

Pivoting matrix by matrix would cost a gather per step, so every matrix is eliminated in one
row order: the partial-pivoting order of the stack's first matrix (the matrices of one Newton
block are Jacobians of one machine and mostly share it). A matrix whose multipliers in that
order exceed :data:`LARGEST_MULTIPLIER` is handed to ``numpy.linalg.solve`` instead (LAPACK,
partial pivoting); with multipliers at most ``m`` the entries of ``U`` grow at most ``(1 + m) **
(n - 1)`` times over their column of ``A``, so the kept factors are backward stable (about
``n (1 + m) ** n`` unit round-offs relative to the columns of ``A``: 5e-13 for n = 6 and m = 2).
A singular matrix raises ``numpy.linalg.LinAlgError``, as ``numpy.linalg.solve`` does.
"""

from __future__ import annotations

import numpy as np

__all__ = ["BatchedLU", "solve_stacked", "inverse_stacked", "LARGEST_MULTIPLIER", "SMALLEST_BATCH_ENTRIES"]

#: Largest multiplier of the elimination (in absolute value) for which a matrix's factors are
#: kept; partial pivoting keeps them at most 1. Larger: the matrix is solved by LAPACK.
LARGEST_MULTIPLIER = 2.0

#: Fewest matrix entries (M n n) of a stack that is eliminated here; a smaller stack goes to
#: LAPACK whole (numpy's per-call cost outweighs LAPACK's per-matrix cost below about 450 6 x 6
#: matrices, measured with a factorisation and two solves).
SMALLEST_BATCH_ENTRIES = 2 ** 14


class BatchedLU:
    """LU factors of M square (n, n) matrices, for solving with any number of right-hand sides.

    Args:
        A: (M, n, n) float64 matrices, any strides (not modified; kept by reference for the
            matrices solved by LAPACK).
        inverse: the caller will ask for :meth:`inverse_columns` too. A stack of fewer than
            :data:`SMALLEST_BATCH_ENTRIES` entries is then inverted by LAPACK once
            (``numpy.linalg.inv``) and :meth:`solve` multiplies by that inverse (one LAPACK
            call for the stack, not one per solve: a small stack's cost is the calls').

    Attributes:
        fallback: (M,) bool, the matrices that ``solve`` hands to ``numpy.linalg.solve``
            (multipliers above :data:`LARGEST_MULTIPLIER` in the shared row order, or a zero
            pivot; all of them in a stack of fewer than :data:`SMALLEST_BATCH_ENTRIES` entries,
            where they are multiplied by their inverse instead if ``inverse``).
    """

    def __init__(self, A: np.ndarray, inverse: bool = False):
        m, n, n2 = A.shape
        if n != n2:
            raise ValueError(f"A must be a stack of square matrices, got shape {A.shape}")
        self._A = A
        self._inverse = None
        if m * n * n < SMALLEST_BATCH_ENTRIES:
            self.fallback = np.ones(m, dtype=bool)
            self._lu = None
            if inverse:
                self._inverse = np.linalg.inv(A)
            return
        order = _pivot_order(A[0])
        self._order = order
        # (n, n, M), a C-ordered copy (indexing a strided view would keep its strides): lu[i, j] entries
        lu = np.ascontiguousarray(A.transpose(1, 2, 0), dtype=float)[order]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for k in range(n - 1):
                f = lu[k + 1:, k] / lu[k, k]  # (n-k-1, M) multipliers of column k
                lu[k + 1:, k] = f
                lu[k + 1:, k + 1:] -= f[:, None, :] * lu[k, None, k + 1:]
            self._inverse_diagonal = 1.0 / np.einsum("iim->im", lu)  # (n, M)
            multipliers = np.abs(lu[np.tril_indices(n, -1)])  # (n (n-1) / 2, M)
            kept = (multipliers.max(axis=0, initial=0.0) <= LARGEST_MULTIPLIER) & \
                np.isfinite(self._inverse_diagonal[n - 1])
        self.fallback = ~kept  # a NaN multiplier (0 / 0) compares False: LAPACK decides
        self._lu = lu

    def solve(self, b: np.ndarray) -> np.ndarray:
        """(M, n) ``x`` with ``A x = b`` for every matrix, ``b`` (M, n).

        Raises:
            numpy.linalg.LinAlgError: a matrix is singular.
        """
        if self._inverse is not None:
            return np.einsum("mij,mj->mi", self._inverse, b)
        if self._lu is None:
            return np.linalg.solve(self._A, b[..., None])[..., 0]
        lu, n = self._lu, self._lu.shape[0]
        y = np.asarray(b.T, dtype=float)[self._order]  # (n, M), a copy
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for k in range(n - 1):  # L y = P b (unit diagonal)
                y[k + 1:] -= lu[k + 1:, k] * y[k]
            for k in range(n - 1, -1, -1):  # U x = y
                y[k] *= self._inverse_diagonal[k]
                if k:
                    y[:k] -= lu[:k, k] * y[k]
        x = y.T
        if self.fallback.any():
            rows = self.fallback
            x[rows] = np.linalg.solve(self._A[rows], b[rows][..., None])[..., 0]
        return x

    def inverse_columns(self) -> np.ndarray:
        """(n, n, M) the inverse of every matrix (a new array), column-major and structure-of-arrays:
        ``X[j, i]`` (M,) holds entry ``(i, j)`` of each inverse (``X[j]`` the solutions of
        ``A x = e_j``), each a contiguous row of M values.

        The n right-hand sides ``e_j`` are solved together with the kept factors (the inverse to
        the same backward error as :meth:`solve`); the fallback matrices by
        ``numpy.linalg.inv``.

        Raises:
            numpy.linalg.LinAlgError: a matrix is singular.
        """
        m, n = self._A.shape[0], self._A.shape[1]
        if self._lu is None:
            inverse = np.linalg.inv(self._A) if self._inverse is None else self._inverse
            return np.ascontiguousarray(inverse.transpose(2, 1, 0))
        lu = self._lu
        # y[j] = P e_j for every matrix: (n, n, M), y[j, i] = 1 where order[i] == j
        y = np.zeros((n, n, m))
        y[self._order, np.arange(n)] = 1.0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for k in range(n - 1):  # L y = P e_j (unit diagonal), every j at once
                y[:, k + 1:] -= lu[None, k + 1:, k] * y[:, k, None]
            for k in range(n - 1, -1, -1):  # U x = y
                y[:, k] *= self._inverse_diagonal[k]
                if k:
                    y[:, :k] -= lu[None, :k, k] * y[:, k, None]
        if self.fallback.any():
            rows = self.fallback
            y[:, :, rows] = np.linalg.inv(self._A[rows]).transpose(2, 1, 0)
        return y


def solve_stacked(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """(M, n, k) ``X`` with ``A_m X_m = B_m`` for every matrix: ``A`` (M, n, n), ``B`` (M, n, k)
    (a pose Jacobian's systems with one right-hand side per parameter: ``d pose / d theta``).

    A stack of at least :data:`SMALLEST_BATCH_ENTRIES` entries is inverted with the kept factors
    (:meth:`BatchedLU.inverse_columns`) and multiplied by ``B`` in one batched product: at 100,000
    6 x 6 systems with 42 right-hand sides 0.12 s, against 0.64 s for ``numpy.linalg.solve``, which
    hands every matrix to LAPACK on its own (one BLAS thread). The solution through the inverse has
    the forward error of a backward-stable solve, ``cond(A_m)`` unit round-offs relative to
    ``|X_m|`` (not its small residual: the callers want ``X``). A smaller stack goes to
    ``numpy.linalg.solve`` whole.

    Raises:
        numpy.linalg.LinAlgError: a matrix is singular.
    """
    m, n, _ = A.shape
    if m * n * n < SMALLEST_BATCH_ENTRIES:
        return np.linalg.solve(A, B)
    return np.matmul(inverse_stacked(A), B)


def inverse_stacked(A: np.ndarray) -> np.ndarray:
    """(M, n, n) the inverse of every matrix of ``A`` (M, n, n), C-ordered: by the kept factors
    (:meth:`BatchedLU.inverse_columns`) for a stack of at least :data:`SMALLEST_BATCH_ENTRIES`
    entries (100,000 6 x 6 matrices: 0.05 s), ``numpy.linalg.inv`` below.

    Raises:
        numpy.linalg.LinAlgError: a matrix is singular.
    """
    m, n, _ = A.shape
    if m * n * n < SMALLEST_BATCH_ENTRIES:
        return np.linalg.inv(A)
    return np.ascontiguousarray(BatchedLU(A).inverse_columns().transpose(2, 1, 0))


def _pivot_order(a: np.ndarray) -> np.ndarray:
    """(n,) the row order of partial pivoting (Gaussian elimination) of one (n, n) matrix (plain
    Python floats: several times faster than numpy calls on a matrix this small)."""
    rows = a.tolist()
    n = len(rows)
    order = list(range(n))
    for k in range(n - 1):
        p = max(range(k, n), key=lambda i: abs(rows[i][k]))
        rows[k], rows[p] = rows[p], rows[k]
        order[k], order[p] = order[p], order[k]
        pivot = rows[k]
        if pivot[k] != 0.0:
            for i in range(k + 1, n):
                f = rows[i][k] / pivot[k]
                rows[i] = [x - f * y for x, y in zip(rows[i], pivot)]
    return np.array(order)
