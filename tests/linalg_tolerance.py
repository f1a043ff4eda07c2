"""Tolerances for tests that compare two computations of a linear-algebra result.

Two float64 computations of the same ill-conditioned quantity (an inverse, a covariance, a
smallest eigenvalue) agree to about ``cond * eps`` in a norm, not element by element: an element
that is a near-cancelling sum carries an absolute error of the size of the norm's, which relative
to itself can be anything, and which the BLAS kernel (summation order, FMA, blocking) decides.
So these tests compare norm-wise, or compare well-conditioned quantities, with bounds from
first-order perturbation theory (N. J. Higham, *Accuracy and Stability of Numerical Algorithms*,
2nd ed., SIAM 2002; cited below as Higham).
"""

from __future__ import annotations

import numpy as np

EPS = np.finfo(float).eps  # unit roundoff of float64 is EPS / 2; the bounds below use EPS


def column_norms(A: np.ndarray) -> np.ndarray:
    """(K,) the 2-norms of the columns of ``A`` (N, K) (1 for a zero column)."""
    norms = np.linalg.norm(A, axis=0)
    return np.where(norms > 0, norms, 1.0)


def column_scaled_condition(A: np.ndarray) -> float:
    """2-norm condition number of ``A`` with unit-norm columns: within ``sqrt(K)`` of the best
    over all column scalings (van der Sluis, Higham Sec. 7.3), the conditioning that decides how
    accurately ``(A^T A)^-1`` can be computed in any parameter units."""
    return float(np.linalg.cond(A / column_norms(A)))


def gram_inverse_tolerance(cond_scaled: float, k: int) -> float:
    """Norm-wise relative accuracy of ``(A^T A)^-1`` (a covariance, a Cramer-Rao bound) of an
    (N, K) system of column-scaled condition ``cond_scaled``, whichever stable method computes it.

    The matrix inverted, the column-scaled Gram matrix ``Gs``, has condition ``cond_scaled^2``.
    Its rounding (forming it, then an LU, Cholesky, eigen- or singular value decomposition) is a
    backward error of about ``c_K eps ||Gs||``, ``c_K`` a low-degree polynomial in K that is
    about K in practice (Higham Ch. 14 for the inverse by LU, Ch. 10 for Cholesky, Sec. 20.4 for
    the normal equations; forming the Gram product adds ``gamma_N |A^T| |A|``, in practice
    ``sqrt(N) eps`` relative as rounding errors partly cancel), which the inverse amplifies by
    ``cond(Gs)``. A small eigenvalue of ``Gs``, hence the condition
    number ``sqrt(lambda_max / lambda_min)`` taken from it, has the same relative accuracy
    (Weyl: absolute error ``c_K eps lambda_max``). Hence ``K * eps * cond_scaled^2``.
    """
    return k * EPS * cond_scaled ** 2


def scaled_relative_gap(C: np.ndarray, reference: np.ndarray, norms: np.ndarray) -> float:
    """``||D (C - reference) D||_2 / ||D reference D||_2``, ``D = diag(norms)``: the norm-wise
    relative difference of two (K, K) covariances in the coordinates of the column-scaled system
    whose Gram matrix they invert (``norms`` its column norms), where the bound of
    :func:`gram_inverse_tolerance` holds. In parameter units the same difference is dominated by
    the largest variances and says nothing about the others."""
    S = np.outer(norms, norms)
    return float(np.linalg.norm((C - reference) * S, 2) / np.linalg.norm(reference * S, 2))
