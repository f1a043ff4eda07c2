"""Tests of calib.delta_identification: FKM / IKM (LM and GN), identifiability, gain G."""

import dataclasses

import numpy as np
import pytest

from calib.delta import (
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    DeltaParams,
    canonical_params,
    constraint_jacobian_params,
    fk_jacobian_params,
    forward_kinematics,
)
from calib.delta_identification import (
    DEFAULT_FREE,
    DeltaIdentificationResult,
    calibration_gain,
    identify_fkm,
    identify_ikm,
    make_dataset,
    null_space_combinations,
    perturb_params,
    random_workspace_positions,
)

NOM = DeltaParams.nominal()
METHODS = {"fkm": identify_fkm, "ikm": identify_ikm}
IS_MM = np.array([u == "mm" for u in PARAMETER_UNITS])
FREE_IDX = np.array([PARAMETER_NAMES.index(n) for n in DEFAULT_FREE])


def _max_errors(est: DeltaParams, true: DeltaParams):
    e = np.abs(est.to_vector() - canonical_params(true).to_vector())[FREE_IDX]
    return e[IS_MM[FREE_IDX]].max(), e[~IS_MM[FREE_IDX]].max()


# --------------------------------------------------------------------------- identifiability


def test_default_free_excludes_lay():
    assert len(DEFAULT_FREE) == 21
    assert set(PARAMETER_NAMES) - set(DEFAULT_FREE) == {"Lay1", "Lay2", "Lay3"}


def test_svd_null_space_is_arm_direction_vs_offset():
    """Per chain exactly one null direction: (dalpha, dLax, dLay) = (1/Lax, -Lay/Lax, 1)."""
    true = perturb_params(NOM, 1.0, np.deg2rad(1.0), 4)
    d = make_dataset(true, NOM, 30, 5)
    jac = constraint_jacobian_params(true, d.q_cmd, d.positions_true)
    for i in range(3):
        s, vt = np.linalg.svd(jac[:, i, :])[1:]
        assert s[-1] < 1e-10 * s[0] and s[-2] > 1e-6 * s[0]
        null = vt[-1] / vt[-1][6]  # normalise on Lay
        expected = np.zeros(8)
        expected[6] = 1.0
        # Turning the arm vector (Lax, Lay) by d in the chain plane, (dLax, dLay) = d (-Lay, Lax),
        # and adding d to alpha leaves every elbow unchanged (the arm angle in the chain plane
        # is atan2(Lay, Lax) - phi).
        lax, lay = true.Lax[i], true.Lay[i]
        expected[4] = 1.0 / lax
        expected[5] = -lay / lax
        np.testing.assert_allclose(null, expected, atol=1e-8)
    # Forward method: rank 21 of 24; with Lay fixed the 21 columns have full rank.
    jf = fk_jacobian_params(true, d.q_cmd).reshape(-1, 24)
    s = np.linalg.svd(jf, compute_uv=False)
    assert np.sum(s > 1e-9 * s[0]) == 21
    s21 = np.linalg.svd(jf[:, FREE_IDX], compute_uv=False)
    assert s21[-1] > 1e-6 * s21[0]


def test_null_space_combinations_names_alpha_and_lay():
    d = make_dataset(NOM, NOM, 20, 0)
    combos = null_space_combinations(NOM, d.q_cmd)
    assert len(combos) == 3
    for i, c in enumerate(combos, start=1):
        assert set(c) == {f"alpha{i}", f"Lay{i}"}
        assert c[f"Lay{i}"] == pytest.approx(1.0)
        assert c[f"alpha{i}"] == pytest.approx(1.0 / 260.0, rel=1e-9)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"q": np.zeros((7, 3))}, "q must have at least 8 configurations, got 7"),
        ({"rel_tol": 0.0}, r"rel_tol must be in \(0, 1\), got 0.0"),
        ({"params": "x"}, "params must be a DeltaParams, got str"),
    ],
)
def test_null_space_validation(kwargs, match):
    args = {"params": NOM, "q": make_dataset(NOM, NOM, 8, 0).q_cmd}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        null_space_combinations(args.pop("params"), args.pop("q"), **args)


# --------------------------------------------------------------------------- noise-free recovery


@pytest.mark.parametrize("method", ["fkm", "ikm"])
@pytest.mark.parametrize("solver", ["lm", "gn"])
@pytest.mark.parametrize("seed", [0, 1])
def test_noise_free_8_configs_1mm(method, solver, seed):
    """Acceptance 1: 8 configurations, 1 mm / 1 deg initial error, no noise: G > 99%."""
    true = perturb_params(NOM, 1.0, np.deg2rad(1.0), seed)
    d = make_dataset(true, NOM, 8, seed + 100)
    res = METHODS[method](NOM, d.q_meas, d.positions_meas, solver=solver)
    assert isinstance(res, DeltaIdentificationResult)
    assert res.success, res.message
    g = calibration_gain(true, NOM, res.estimate)
    assert g.mean > 99.0 and g.norm > 99.0
    e_mm, e_rad = _max_errors(res.estimate, true)
    assert e_mm < 1e-6 and e_rad < 1e-8
    assert res.residuals.shape == (8, 3)
    np.testing.assert_allclose(res.residuals, 0.0, atol=1e-8)
    np.testing.assert_array_equal(res.estimate.Lay, NOM.Lay)  # fixed parameters untouched


@pytest.mark.parametrize("method", ["fkm", "ikm"])
@pytest.mark.parametrize("solver", ["lm", "gn"])
def test_noise_free_8_configs_1cm(method, solver):
    """Acceptance 2: 1 cm / 10 deg initial error, no noise (both methods converge here)."""
    true = perturb_params(NOM, 10.0, np.deg2rad(10.0), 7)
    d = make_dataset(true, NOM, 8, 8)
    res = METHODS[method](NOM, d.q_meas, d.positions_meas, solver=solver)
    assert res.success, res.message
    assert calibration_gain(true, NOM, res.estimate).mean > 99.0


def test_lay_injected_is_absorbed_by_alpha_and_lax():
    true = dataclasses.replace(perturb_params(NOM, 1.0, np.deg2rad(1.0), 2), Lay=np.array([2.0, -1.0, 0.5]))
    d = make_dataset(true, NOM, 10, 3)
    res = identify_ikm(NOM, d.q_meas, d.positions_meas)
    e_mm, e_rad = _max_errors(res.estimate, true)
    assert e_mm < 1e-6 and e_rad < 1e-8
    np.testing.assert_allclose(forward_kinematics(res.estimate, d.q_meas), d.positions_true, atol=1e-7)


# --------------------------------------------------------------------------- noise and covariance


def test_covariance_predicts_scatter():
    """Declared-noise covariance vs the scatter of estimates over seeds (IKM and FKM)."""
    sig_mm, sig_rad = 1e-3, np.deg2rad(0.01)
    true = perturb_params(NOM, 0.5, np.deg2rad(0.5), 11)
    clean = make_dataset(true, NOM, 40, 12)
    rng = np.random.default_rng(13)
    for fn in (identify_ikm, identify_fkm):
        ests, cov = [], None
        for _ in range(40):
            qn = clean.q_cmd + rng.normal(0, sig_rad, clean.q_cmd.shape)
            xn = clean.positions_true + rng.normal(0, sig_mm, clean.positions_true.shape)
            r = fn(NOM, qn, xn, sigma_mm=sig_mm, sigma_rad=sig_rad)
            assert r.success, r.message
            ests.append(r.estimate.to_vector()[FREE_IDX])
            cov = r.covariance
        assert cov.shape == (21, 21)
        np.testing.assert_allclose(cov, cov.T, atol=1e-12 * np.abs(cov).max())
        ratio = np.std(ests, axis=0) / np.sqrt(np.diag(cov))
        assert 0.6 < np.median(ratio) < 1.4


def test_noise_free_weights_do_not_change_solution():
    true = perturb_params(NOM, 1.0, np.deg2rad(1.0), 21)
    d = make_dataset(true, NOM, 12, 22)
    a = identify_fkm(NOM, d.q_meas, d.positions_meas, sigma_mm=1e-3, sigma_rad=1e-4)
    b = identify_fkm(NOM, d.q_meas, d.positions_meas, sigma_mm=1.0, sigma_rad=1e-9)
    np.testing.assert_allclose(a.estimate.to_vector(), b.estimate.to_vector(), atol=1e-7)


def test_non_convergence_returns_result():
    true = perturb_params(NOM, 1.0, np.deg2rad(1.0), 0)
    d = make_dataset(true, NOM, 8, 1)
    for fn in (identify_fkm, identify_ikm):
        res = fn(NOM, d.q_meas, d.positions_meas, max_iter=1)
        assert not res.success
        assert "did not converge in 1 iterations" in res.message
        assert res.iterations >= 1


def test_gauss_newton_leaving_workspace_is_reported():
    # Grossly wrong initial forearm lengths: the FKM initial estimate cannot close the chains.
    bad = dataclasses.replace(NOM, Lb=np.full(3, 300.0))
    d = make_dataset(NOM, NOM, 8, 1)
    with pytest.raises(ValueError, match="configuration 0: .*outside the workspace"):
        identify_fkm(bad, d.q_meas, d.positions_meas, solver="gn")


def test_result_is_frozen():
    d = make_dataset(NOM, NOM, 8, 1)
    res = identify_ikm(NOM, d.q_meas, d.positions_meas)
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.success = False


# --------------------------------------------------------------------------- validation

_D = make_dataset(NOM, NOM, 8, 1)


@pytest.mark.parametrize("method", ["fkm", "ikm"])
@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"solver": "newton"}, "solver must be one of \\('lm', 'gn'\\), got 'newton'"),
        ({"free": ["Dx1", "Lc2"]}, "free must name parameters of PARAMETER_NAMES, got unknown \\['Lc2'\\]"),
        ({"free": ["Dx1", "Dx1"]}, "free must be a non-empty list of distinct names"),
        ({"free": []}, "free must be a non-empty list of distinct names"),
        ({"sigma_mm": 0.0}, "sigma_mm must be positive"),
        ({"sigma_rad": -1.0}, "sigma_rad must be positive"),
        ({"max_iter": 0}, "max_iter must be a positive integer, got 0"),
        ({"q": np.zeros((8, 2))}, r"q must have shape \(N, 3\), got \(8, 2\)"),
        ({"positions": np.zeros(3)}, r"positions must have shape \(N, 3\), got \(3,\)"),
        ({"positions": np.zeros((7, 3))}, "same number of configurations, got 8 and 7"),
        ({"initial": "nominal"}, "params must be a DeltaParams, got str"),
    ],
)
def test_identify_validation(method, kwargs, match):
    args = {"initial": NOM, "q": _D.q_meas, "positions": _D.positions_meas}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        METHODS[method](args.pop("initial"), args.pop("q"), args.pop("positions"), **args)


def test_too_few_configurations():
    with pytest.raises(ValueError, match="q must have at least 7 configurations for 21 free parameters, got 6"):
        identify_fkm(NOM, _D.q_meas[:6], _D.positions_meas[:6])
    with pytest.raises(ValueError, match="q must have at least 7 configurations for chain 1, got 6"):
        identify_ikm(NOM, _D.q_meas[:6], _D.positions_meas[:6])


# --------------------------------------------------------------------------- gain G


def test_gain_definition():
    true = perturb_params(NOM, 1.0, np.deg2rad(1.0), 3)
    assert calibration_gain(true, NOM, true).mean == pytest.approx(100.0)
    assert calibration_gain(true, NOM, NOM).mean == pytest.approx(0.0)
    assert calibration_gain(true, NOM, NOM).norm == pytest.approx(0.0)
    # Halving every error gives 50% per parameter and on the norm.
    half = DeltaParams.from_vector(0.5 * (true.to_vector() + NOM.to_vector()))
    g = calibration_gain(true, NOM, half, canonical=False)
    np.testing.assert_allclose(g.per_parameter, 50.0)
    assert g.norm == pytest.approx(50.0)
    # Calibrated value as far from the truth as the nominal: 0%; twice as far: -100%.
    v = true.to_vector()
    k = PARAMETER_NAMES.index("Lb2")
    v[k] = true.Lb[1] + (true.Lb[1] - NOM.Lb[1])
    g = calibration_gain(true, NOM, DeltaParams.from_vector(v), names=["Lb2", "Dx1"], canonical=False)
    np.testing.assert_allclose(g.per_parameter, [0.0, 100.0], atol=1e-9)
    v[k] = true.Lb[1] + 2.0 * (true.Lb[1] - NOM.Lb[1])
    g = calibration_gain(true, NOM, DeltaParams.from_vector(v), names=["Lb2", "Dx1"], canonical=False)
    np.testing.assert_allclose(g.per_parameter, [-100.0, 100.0], atol=1e-9)
    assert g.mean == pytest.approx(0.0, abs=1e-9)
    d = g.as_dict()
    assert set(d) == {"per_parameter", "mean", "norm"} and list(d["per_parameter"]) == ["Lb2", "Dx1"]


def test_gain_zero_initial_error_is_nan():
    g = calibration_gain(NOM, NOM, NOM, names=["Dx1"])
    assert np.isnan(g.per_parameter[0]) and np.isnan(g.mean) and np.isnan(g.norm)
    assert g.as_dict()["per_parameter"]["Dx1"] is None


@pytest.mark.parametrize(
    "args, kwargs, match",
    [
        (("x", NOM, NOM), {}, "true must be a DeltaParams, got str"),
        ((NOM, NOM, 3), {}, "calibrated must be a DeltaParams, got int"),
        ((NOM, NOM, NOM), {"names": ["Dq1"]}, r"names must be a non-empty subset of PARAMETER_NAMES, got unknown \['Dq1'\]"),
        ((NOM, NOM, NOM), {"names": []}, "names must be a non-empty subset"),
    ],
)
def test_gain_validation(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        calibration_gain(*args, **kwargs)


# --------------------------------------------------------------------------- simulation helpers


def test_perturb_params_seeded_and_bounded():
    a = perturb_params(NOM, 1.0, 0.01, 5)
    b = perturb_params(NOM, 1.0, 0.01, 5)
    np.testing.assert_array_equal(a.to_vector(), b.to_vector())
    e = a.to_vector() - NOM.to_vector()
    assert np.all(np.abs(e[IS_MM]) <= 1.0) and np.all(np.abs(e[~IS_MM]) <= 0.01)
    assert not np.array_equal(a.to_vector(), perturb_params(NOM, 1.0, 0.01, 6).to_vector())


def test_workspace_positions_and_dataset():
    x = random_workspace_positions(50, 1, radius_mm=100.0, z_range_mm=(-450.0, -350.0))
    assert x.shape == (50, 3)
    assert np.all(np.hypot(x[:, 0], x[:, 1]) <= 100.0) and np.all((x[:, 2] >= -450) & (x[:, 2] <= -350))
    true = perturb_params(NOM, 1.0, 0.01, 2)
    d = make_dataset(true, NOM, 10, 3, noise_mm=1e-3, noise_rad=1e-4)
    np.testing.assert_allclose(forward_kinematics(true, d.q_cmd), d.positions_true, atol=1e-10)
    assert 0 < np.abs(d.q_meas - d.q_cmd).max() < 1e-3
    assert 0 < np.abs(d.positions_meas - d.positions_true).max() < 1e-2
    d2 = make_dataset(true, NOM, 10, 3, noise_mm=1e-3, noise_rad=1e-4)
    np.testing.assert_array_equal(d.positions_meas, d2.positions_meas)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: perturb_params(NOM, -1.0, 0.0, 0), "error_mm must be finite and >= 0, got -1.0"),
        (lambda: perturb_params(NOM, 1.0, np.nan, 0), "error_rad must be finite and >= 0"),
        (lambda: random_workspace_positions(0, 0), "n must be a positive integer, got 0"),
        (lambda: random_workspace_positions(5, 0, radius_mm=-1.0), "radius_mm must be > 0"),
        (lambda: make_dataset(NOM, NOM, 5, 0, noise_mm=-1.0), "noise_mm must be finite and >= 0"),
        (lambda: make_dataset(NOM, "nominal", 5, 0), "params must be a DeltaParams, got str"),
        (
            lambda: make_dataset(dataclasses.replace(NOM, Lb=np.full(3, 100.0)), NOM, 5, 0),
            "true: the real robot reaches fewer than n=5 workspace targets",
        ),
    ],
)
def test_helpers_validation(call, match):
    with pytest.raises(ValueError, match=match):
        call()
