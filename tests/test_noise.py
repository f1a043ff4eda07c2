"""calib.noise: the chi-square quantile every verdict judges against, against closed forms."""

import math

import numpy as np
import pytest

from calib.noise import chi2_quantile

EPS = np.finfo(float).eps


def _input_error(p: float) -> float:
    """Relative error of a quantile at ``p`` from ``1 - p`` rounded to eps: the quantile moves by
    d(1-p)/(1-p) divided by |ln(1-p)| (closed form for two degrees of freedom, the same order for
    others), plus the function's own few ulps."""
    return 16.0 * EPS * (1.0 + 1.0 / ((1.0 - p) * abs(math.log1p(-p))))


@pytest.mark.parametrize("p", [0.5, 0.9, 0.99, 0.999, 1.0 - 1e-6])
def test_two_degrees_of_freedom_is_the_exponential_quantile(p):
    # chi-square(2) is the exponential with mean 2: its quantile is -2 ln(1 - p).
    exact = -2.0 * math.log1p(-p)
    assert abs(chi2_quantile(p, 2) - exact) <= _input_error(p) * exact


@pytest.mark.parametrize("p", [0.5, 0.9, 0.99, 0.999, 1.0 - 1e-6])
def test_one_degree_of_freedom_is_the_squared_normal_quantile(p):
    # chi-square(1) is a squared standard normal: P(Z^2 <= q) = erf(sqrt(q / 2)) = p.
    from scipy.special import erfinv

    exact = 2.0 * float(erfinv(p)) ** 2
    # erfinv near 1 carries the same 1 - p rounding, twice through the square.
    assert abs(chi2_quantile(p, 1) - exact) <= 2.0 * _input_error(p) * exact


@pytest.mark.parametrize("dof", [3, 6, 41, 600, 100_000])
def test_the_quantile_is_where_the_distribution_function_reaches_p(dof):
    from scipy.special import gammainc

    p = 0.999
    q = chi2_quantile(p, dof)
    # P(chi2 <= q) = gammainc(dof / 2, q / 2); its slope in q is the density f(q) (relative slope
    # q f(q)), so an error of e relative in q moves P by e q f(q): bounded by the input's rounding.
    density = math.exp((dof / 2 - 1) * math.log(q / 2) - q / 2 - math.lgamma(dof / 2)) / 2
    assert abs(gammainc(dof / 2, q / 2) - p) <= _input_error(p) * q * density + 16 * EPS
