"""The searched parameters' subsampled search (calib.effects.search.SEARCH_ROWS_MAX): above the
threshold a searched parameter's grid is scanned on a seeded subsample stratified in time and
confirmed and refined on every row. Here the threshold is lowered through ``discover_effects``'s
``search_rows_max`` (and the subsample through ``search_subsample_rows``) on a few hundred rows:
the subsampled search must find what the search on every row finds (within one grid step, the
search's own resolution before its refinement) and the injected truth, and say that it ran; below
the threshold nothing changes."""

import numpy as np
import pytest

from calib.effects import EFFECTS, EffectData, discover_effects
from calib.effects.discovery import SEARCH_ROWS_MAX, search_subsample
from calib.effects.lost_count import JointStep
from calib.effects.search import SearchForm
from calib.noise import SensorNoise
from calib.robots import default_robot

NOISE = SensorNoise(0.001, 1e-6, "normal")
#: A wide hexapod workspace (mm, rad), where the effects and the geometry separate.
WORKSPACE = np.array([[-25, 25], [-25, 25], [190, 215], [-0.1, 0.1], [-0.1, 0.1], [-0.15, 0.15]], dtype=float)
#: Rows of the recordings; the threshold and the subsample lowered below them.
ROWS, THRESHOLD, SUBSAMPLE = 900, 400, 300


def recording(effect: str, coef, extra, seed: int = 3) -> EffectData:
    """The nominal hexapod with its joints moved by ``effect``'s regressors times ``coef`` (the
    measured poses the forward kinematics at the displaced joints, exact), 1 um / 1 urad noise."""
    robot = default_robot("hexapod")
    rng = np.random.default_rng(seed)
    targets = WORKSPACE[:, 0] + rng.uniform(size=(ROWS, 6)) * np.ptp(WORKSPACE, axis=1)
    joints = robot.inverse_kinematics(robot.table.nominal, targets)
    t = np.cumsum(rng.uniform(0.5, 1.5, ROWS))
    Xq = EFFECTS[effect].joint_regressors(robot, robot.table.nominal,
                                          EffectData(robot, robot.table.nominal, joints, targets, t, NOISE), extra)
    reached = robot.forward_kinematics(robot.table.nominal, joints + Xq @ np.asarray(coef, dtype=float), initial=targets)
    reached = reached + NOISE.sample(ROWS, seed + 1, robot.pose_units)
    return EffectData(robot, robot.table.nominal, joints, reached, t, NOISE)


def both(data: EffectData, effect: str):
    """The discovery with every row searched and with the subsampled search."""
    full = discover_effects(data, candidates=[effect], laws=False)
    sub = discover_effects(data, candidates=[effect], laws=False, search_rows_max=THRESHOLD,
                           search_subsample_rows=SUBSAMPLE)
    return full, sub


@pytest.mark.parametrize("effect, coef, truth", [("periodic_screw_error", [0.003, -0.002], 7.3),
                                                 ("thermal_warmup", [2e-5], 250.0)])
def test_a_refined_searched_value_is_found_on_the_subsample_as_on_every_row(effect, coef, truth):
    data = recording(effect, coef, truth)
    full, sub = both(data, effect)
    assert full.search == SearchForm("every row")
    assert sub.search == SearchForm("subsample", ROWS, SUBSAMPLE, THRESHOLD, (effect,))
    assert full.effects == sub.effects == (effect,) and sub.explained, sub.remaining.summary
    eff = EFFECTS[effect]
    grid = eff.search_grid(data)
    step = float(np.diff(grid).mean())
    # The search coordinate (1 / pitch, log tau) within one grid step of every row's search.
    u = {"periodic_screw_error": lambda v: 1.0 / v, "thermal_warmup": np.log}[effect]
    assert abs(u(sub.chosen.extra) - u(full.chosen.extra)) < step
    assert abs(u(sub.chosen.extra) - u(truth)) < step
    # The same fit, then, to well within the chi-square's own spread (sqrt(2 dof)).
    assert abs(sub.chosen.chi2 - full.chosen.chi2) < 0.01 * np.sqrt(2 * full.chosen.dof)


def test_a_step_time_is_found_on_the_subsample_as_on_every_row():
    t = recording("none", [], None).t_s
    truth = JointStep(4, float((t[611] + t[612]) / 2))
    data = recording("lost_count", [0.004], truth)
    full, sub = both(data, "lost_count")
    assert sub.search.form == "subsample" and sub.search.effects == ("lost_count",)
    # Not refined: the step lies between two measurements, and every row's window around the
    # subsample's best finds the very step every row's search finds, the one made.
    assert full.chosen.extra == sub.chosen.extra == truth
    assert full.effects == sub.effects == ("lost_count",)


def test_below_the_threshold_the_search_is_that_on_every_row():
    """At the threshold itself (``search_rows_max`` = the rows) and with the default (far above the
    rows) the discovery is the same to the last bit: the subsample path is not taken."""
    data = recording("periodic_screw_error", [0.003, -0.002], 7.3)
    default = discover_effects(data, candidates=["periodic_screw_error"], laws=False)
    at = discover_effects(data, candidates=["periodic_screw_error"], laws=False, search_rows_max=ROWS,
                          search_subsample_rows=SUBSAMPLE)
    assert ROWS < SEARCH_ROWS_MAX
    assert default.search == at.search == SearchForm("every row")
    assert at.chosen.extras == default.chosen.extras
    assert at.chosen.chi2 == default.chosen.chi2
    np.testing.assert_array_equal(at.chosen.coefficients, default.chosen.coefficients)


def test_the_subsample_is_seeded_and_stratified_in_time():
    t = np.cumsum(np.random.default_rng(0).uniform(0.5, 1.5, 1000))[::-1].copy()  # rows not in time order
    rows = search_subsample(t, 100, 7)
    assert rows.size == 100 and np.all(np.diff(rows) > 0)
    np.testing.assert_array_equal(rows, search_subsample(t, 100, 7))
    assert not np.array_equal(rows, search_subsample(t, 100, 8))
    # One row from each stratum of 10 consecutive rows in time.
    rank = np.argsort(np.argsort(t))
    np.testing.assert_array_equal(np.sort(rank[rows]) // 10, np.arange(100))
    np.testing.assert_array_equal(search_subsample(t, 5000, 7), np.arange(1000))


def test_the_blocked_crossvalidation_above_the_threshold_is_the_closed_form_one():
    """Above the threshold the closed-form cross-validation keeps each fold's geometry block
    (the same Woodbury algebra): the same cross-validated RMS to rounding (1e-9, far below any
    difference between candidates), on a step the two searches find alike (a refined value differs
    within its refinement, and its cross-validated RMS with it)."""
    t = recording("none", [], None).t_s
    data = recording("lost_count", [0.004], JointStep(2, float((t[300] + t[301]) / 2)))
    full, sub = both(data, "lost_count")
    assert sub.chosen.extra == full.chosen.extra
    assert sub.evidence.geometry.cv_whitened_rms == pytest.approx(full.evidence.geometry.cv_whitened_rms, rel=1e-9)
    assert sub.evidence.of("lost_count").cv_whitened_rms == pytest.approx(full.evidence.of("lost_count").cv_whitened_rms,
                                                                          rel=1e-9)
    assert sub.evidence.cv_whitened_rms_chosen == pytest.approx(full.evidence.cv_whitened_rms_chosen, rel=1e-9)


#: The discovery's rooms that read calib.effects.separability.GRAM_MIN_RESIDUALS (each holds the
#: name: monkeypatch.setattr refuses one that does not).
GRAM_ROOMS = ("whitening", "joint_fit", "remainder")


def lower_the_gram_threshold(monkeypatch):
    """GRAM_MIN_RESIDUALS lowered to 0 in every room of the discovery that reads it."""
    import importlib

    for room in GRAM_ROOMS:
        monkeypatch.setattr(importlib.import_module(f"calib.effects.{room}"), "GRAM_MIN_RESIDUALS", 0)


def test_the_normal_equations_of_a_tall_fit_give_the_svd_fit(monkeypatch):
    """The discovery's GRAM_MIN_RESIDUALS lowered to 0 (every fit through the Gram
    matrix): the joint fit of the geometry and a screw error is the SVD's to 1e-8 relative
    (the Gram matrix squares the scaled columns' condition number, 1e3 to 1e4 here; Gauss-Newton
    corrects each step's error on the next)."""
    from calib.effects import fit_effects

    data = recording("periodic_screw_error", [0.003, -0.002], 7.3)
    svd = fit_effects(data, ["periodic_screw_error"], extras={"periodic_screw_error": 7.3})
    lower_the_gram_threshold(monkeypatch)
    gram = fit_effects(data, ["periodic_screw_error"], extras={"periodic_screw_error": 7.3})
    assert gram.chi2 == pytest.approx(svd.chi2, rel=1e-8)
    np.testing.assert_allclose(gram.coefficients, svd.coefficients, rtol=1e-6, atol=1e-8 * np.abs(svd.coefficients).max())
    np.testing.assert_allclose(gram.theta, svd.theta, rtol=0, atol=1e-8 * np.abs(svd.theta).max())


def test_the_geometry_basis_of_a_tall_jacobian_from_its_information_is_the_svds(monkeypatch):
    """calib.effects.separability.GRAM_MIN_RESIDUALS lowered to 0: the determined and held
    combinations from the information's eigenvectors span what the SVD's right vectors span
    (projectors equal to 1e-9; the information's eigenvalues lie far from HELD_INFORMATION here:
    a column scaled by 1e-3 is held, the others determined)."""
    import calib.effects.separability as sep

    rng = np.random.default_rng(5)
    G = rng.normal(size=(600, 8)) * np.array([1, 1, 1, 1, 1, 1, 1, 1e-3])
    std, free = np.full(8, 1.0), np.arange(8)
    svd = sep.geometry_basis(G, std, free)
    monkeypatch.setattr(sep, "GRAM_MIN_RESIDUALS", 0)
    gram = sep.geometry_basis(G, std, free)
    assert svd.determined.shape == gram.determined.shape == (8, 7) and gram.held.shape == (8, 1)
    for a, b in ((svd.determined, gram.determined), (svd.held, gram.held)):
        np.testing.assert_allclose(a @ a.T, b @ b.T, atol=1e-9)


def test_the_report_says_when_the_search_ran_on_a_subsample():
    from pipeline.report.model import Search
    from pipeline.report.text import search_words

    assert search_words(None) is None  # every row searched: nothing said
    words = search_words(Search(rows=99893, subsample_rows=10000, threshold=20000,
                                effects=("lost_count", "thermal_warmup")))
    assert "(lost_count, thermal_warmup)" in words and "10,000 of the 99,893 rows" in words
    assert "above 20,000 rows" in words and "every row" in words


def test_the_gram_form_of_an_orthonormal_basis_spans_what_the_svds_spans(monkeypatch):
    """calib.effects.base's Gram form (above GRAM_MIN_RESIDUALS rows), the threshold lowered to 0:
    orthonormal columns to rounding, the same span as the SVD's basis (projectors equal to
    10 k eps cond, cond the scaled columns' condition number: Q = A W lies in A's span exactly, the
    products' rounding amplified by the conditioning), and a dependent column dropped alike."""
    import calib.effects.base as base
    from linalg_tolerance import EPS, column_scaled_condition

    rng = np.random.default_rng(11)
    A = rng.normal(size=(3000, 8)) * np.logspace(0, -4, 8)
    A[:, 3] = A[:, 2] - 2 * A[:, 5]  # rank 7
    cond = column_scaled_condition(np.delete(A, 3, axis=1))
    svd = base.orthonormal_columns(A)
    monkeypatch.setattr(base, "GRAM_MIN_RESIDUALS", 0)
    gram = base.orthonormal_columns(A)
    assert svd.shape == gram.shape == (3000, 7)
    np.testing.assert_allclose(gram.T @ gram, np.eye(7), atol=10 * 7 * EPS)
    np.testing.assert_allclose(gram @ gram.T, svd @ svd.T, atol=10 * 7 * EPS * cond)


def test_the_remainder_tests_in_the_gram_form_are_the_svds(monkeypatch):
    """The remainder's F tests through the normal equations (GRAM_MIN_RESIDUALS lowered to 0 in
    the discovery's rooms and calib.effects.base: span bases as [design, held remainder], one
    product with them per test) give the SVD form's p-values and t statistics: relative 1e-6, the
    Gram matrices' squared conditioning (1e3 to 1e4 scaled, the docstring of GRAM_MIN_RESIDUALS)
    times eps, far below any decision (alpha 0.01 Bonferroni-corrected)."""
    import calib.effects.base as base
    from calib.effects import fit_effects, remainder_tests

    data = recording("periodic_screw_error", [0.003, -0.002], 7.3)
    fit = fit_effects(data, ["periodic_screw_error"], extras={"periodic_screw_error": 7.3})
    svd = remainder_tests(data, fit)
    lower_the_gram_threshold(monkeypatch)
    monkeypatch.setattr(base, "GRAM_MIN_RESIDUALS", 0)
    gram = remainder_tests(data, fit_effects(data, ["periodic_screw_error"], extras={"periodic_screw_error": 7.3}))
    assert gram.explained == svd.explained
    for v in svd.structure:
        g = gram.quantity(v.quantity)
        for key in ("p_value_proportional", "p_value_common_smooth", "p_value"):
            assert getattr(g, key) == pytest.approx(getattr(v, key), rel=1e-6, abs=1e-12), (v.quantity, key)
        np.testing.assert_allclose(g.t_per_chain, v.t_per_chain, rtol=1e-6, atol=1e-9)


def test_a_step_times_window_updated_row_by_row_is_every_rows_chi_square(monkeypatch):
    """The subsampled search's window of step times on every row, each point's chi-square updated
    from the point before on the row that changes (``SEARCH_UPDATE_ROWS``), finds what the same
    window finds with a full pass at every point (``SEARCH_UPDATE_ROWS`` below one row): the same
    step, and the same fit at it to the bit (the update's rounding, relative 1e-12 on sums of
    products, is far below the gap between two step times' chi-squares)."""
    import calib.effects.search as search_mod

    t = recording("none", [], None).t_s
    truth = JointStep(2, float((t[300] + t[301]) / 2))
    data = recording("lost_count", [0.004], truth)
    kw = dict(candidates=["lost_count"], laws=False, search_rows_max=THRESHOLD, search_subsample_rows=SUBSAMPLE)
    updated = discover_effects(data, **kw)
    monkeypatch.setattr(search_mod, "SEARCH_UPDATE_ROWS", -1)
    full = discover_effects(data, **kw)
    assert updated.search.form == full.search.form == "subsample"
    assert updated.chosen.extras == full.chosen.extras
    assert updated.chosen.extra == truth
    assert updated.chosen.chi2 == full.chosen.chi2
    np.testing.assert_array_equal(updated.chosen.coefficients, full.chosen.coefficients)