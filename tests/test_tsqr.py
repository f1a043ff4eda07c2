"""calib.tsqr: the triangular factor of a tall matrix block by block against LAPACK's SVD and QR."""

import numpy as np
import pytest

from calib.tsqr import TSQR_BLOCK_ROWS, triangular_factor, triangular_update

EPS = np.finfo(float).eps


@pytest.mark.parametrize("rows", [7, TSQR_BLOCK_ROWS, 20 * TSQR_BLOCK_ROWS + 13])
def test_singular_values_are_the_whole_matrixs(rows):
    """Columns scaled over six decades (condition about 1e6): R's singular values are A's within
    the backward error of Householder QR accumulated over the blocks (a few K eps |A| per block,
    K columns), and R^T R is A^T A to the same order relative to |A|^2."""
    rng = np.random.default_rng(rows)
    k = 20
    A = rng.normal(size=(rows, k)) * np.logspace(0, -6, k)
    R = triangular_factor(A)
    assert R.shape == (min(rows, k), k)
    blocks = -(-rows // TSQR_BLOCK_ROWS)
    s_ref = np.linalg.svd(A, compute_uv=False)
    tol = 10 * k * blocks * EPS * s_ref[0]
    assert np.max(np.abs(np.linalg.svd(R, compute_uv=False) - s_ref)) <= tol
    assert np.max(np.abs(R.T @ R - A.T @ A)) <= 2 * tol * s_ref[0]


def test_blocks_of_any_size_give_one_factor_up_to_row_signs():
    """The factor is unique up to the sign of each row: |R| from blocks of 1, 100 or every row."""
    rng = np.random.default_rng(1)
    A = rng.normal(size=(3000, 12))
    whole = np.abs(np.linalg.qr(A, mode="r"))
    for block in (1, 100, 3000):
        np.testing.assert_allclose(np.abs(triangular_factor(A, block)), whole, rtol=0,
                                   atol=10 * 12 * (3000 // block) * EPS * whole.max())


def test_update_stacks_on_a_previous_factor():
    rng = np.random.default_rng(2)
    A, B = rng.normal(size=(50, 6)), rng.normal(size=(40, 6))
    R = triangular_update(triangular_update(None, A), B)
    both = np.vstack([A, B])
    s0 = np.linalg.norm(both, 2)
    assert R.shape == (6, 6)
    assert np.max(np.abs(R.T @ R - both.T @ both)) <= 2 * 10 * 6 * 2 * EPS * s0 ** 2  # two blocks


def test_a_column_scale_gives_the_factor_of_the_scaled_matrix_bit_for_bit():
    """``column_scale`` divides each block as it is taken: the factor of ``A / scale`` formed whole,
    to the bit (the same divisions, the same blocks), over several blocks and a ragged last one."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(2500, 9)) * np.logspace(-3, 3, 9)
    scale = np.logspace(-3, 3, 9)
    np.testing.assert_array_equal(triangular_factor(A, 1024, column_scale=scale), triangular_factor(A / scale, 1024))
    assert not np.array_equal(triangular_factor(A, 1024, column_scale=scale), triangular_factor(A, 1024))
