"""Shared and per-chain forms of an effect (calib.effects.granularity): the per-chain regressors,
the machine settings joint by joint, the scenarios' per-joint spread, and discovery's choice."""

import numpy as np
import pytest

from calib.effects import EFFECTS, MachineContext, discover_effects, effects_for
from calib.effects.base import SPREAD_RANGE
from calib.effects.discovery import candidate_forms
from calib.effects.granularity import PER_CHAIN, SHARED, merge_chain_settings, per_chain_form
from tests.joint_space_truth import HEXAPOD, THETA, moved_legs

CONTEXT = MachineContext(moving_mass_kg=3.0, platform_mass_kg=2.0, payload_height_m=0.05, gravity_m_s2=9.81,
                         m_per_mm=1e-3, servo_stiffness=2e5)
CAPABLE = [n for n, e in EFFECTS.items() if e.per_chain_capable]


def measurements(eff, coef, n=100, seed=0, extra=None, noise=True):
    """Exact truth on the calib machine: the joints moved by ``eff``'s regressors times ``coef``
    (see :mod:`tests.joint_space_truth`)."""
    coef = np.asarray(coef, dtype=float)
    return moved_legs(lambda data: eff.joint_regressors(HEXAPOD, THETA, data, extra) @ coef, n, seed, iterations=6,
                      noise=noise)


@pytest.mark.parametrize("name", CAPABLE)
def test_the_per_chain_form_with_equal_coefficients_is_the_shared_form(name):
    eff = EFFECTS[name]
    pc = per_chain_form(eff)
    assert pc is per_chain_form(eff) and pc.name == name and pc.granularity == PER_CHAIN and eff.granularity == SHARED
    extra = 4.3 if name == "periodic_screw_error" else 30.0 if name == "thermal_warmup" else None
    data = measurements(EFFECTS["none"], [], n=20, noise=False)
    shared = np.arange(1.0, len(eff.coefficients(HEXAPOD)) + 1)
    rows = np.tile(shared, (6, 1))
    np.testing.assert_allclose(pc.joint_regressors(HEXAPOD, THETA, data, extra) @ pc.flat_coefficients(rows, HEXAPOD),
                               eff.joint_regressors(HEXAPOD, THETA, data, extra) @ shared, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(pc.chain_coefficients(pc.flat_coefficients(rows, HEXAPOD), HEXAPOD), rows)
    names = [c.name for c in pc.coefficients(HEXAPOD)]
    assert f"{eff.per_chain_capable[0]}[leg 3]" in names


def test_chain_settings_merge_field_by_field():
    merged = merge_chain_settings([{"options": {"joint_friction": 0.1 * (i + 1), "gravity": True},
                                    "effects": {"screw_amplitude": (float(i),) * 3}} for i in range(3)], 3)
    assert merged == {"options": {"joint_friction": (0.1, 0.2, 0.30000000000000004), "gravity": True},
                      "effects": {"screw_amplitude": (0.0, 1.0, 2.0)}}


def test_per_chain_friction_is_a_friction_force_per_joint():
    pc = per_chain_form(EFFECTS["joint_friction"])
    band = np.array([1e-3, 2e-3, 3e-3, 4e-3, 5e-3, 6e-3])
    s = pc.machine_settings(band, HEXAPOD, CONTEXT)["options"]
    assert s["joint_friction"] == pytest.approx(tuple(band * 1e-3 * 2e5))
    assert s["actuator_stiffness"] == 2e5
    assert pc.physical_parameter(HEXAPOD) is None  # a vector: simulated as fitted


@pytest.mark.parametrize("name", CAPABLE)
def test_a_per_chain_scenario_spreads_each_joint_within_the_range_and_keeps_the_largest_contribution(name):
    eff, pc = EFFECTS[name], per_chain_form(EFFECTS[name])
    data = measurements(EFFECTS["none"], [], n=30, noise=False)
    sc_shared = eff.scenario(HEXAPOD, THETA, data, 0.005, np.random.default_rng(4), CONTEXT)
    sc = pc.scenario(HEXAPOD, THETA, data, 0.005, np.random.default_rng(4), CONTEXT)
    raw = np.abs(eff.regressors(HEXAPOD, THETA, data, sc_shared.extra) @ sc_shared.coefficients).max()
    assert np.abs(pc.regressors(HEXAPOD, THETA, data, sc.extra) @ sc.coefficients).max() == pytest.approx(raw)
    rows = pc.chain_coefficients(sc.coefficients, HEXAPOD)[:, pc.capable(HEXAPOD)]
    size = np.linalg.norm(rows, axis=1)
    ratio = size / size.max()
    assert ratio.min() >= SPREAD_RANGE[0] - 1e-12 and np.ptp(ratio) > 0.05


def test_candidate_forms_add_a_per_chain_form_to_each_capable_effect_only():
    forms = candidate_forms(effects_for(HEXAPOD))
    assert set(forms) == set(effects_for(HEXAPOD)) - {"none"} | {f"{n}[per_chain]" for n in CAPABLE}
    assert set(candidate_forms(effects_for(HEXAPOD), per_chain=False)) == set(effects_for(HEXAPOD)) - {"none"}


@pytest.mark.parametrize("granularity", [SHARED, PER_CHAIN])
def test_discovery_names_the_dead_band_alone_and_says_whether_each_joint_has_its_own(granularity):
    band = np.array([4e-3, 2e-3, 3.5e-3, 1.5e-3, 3e-3, 4e-3]) if granularity == PER_CHAIN else np.full(6, 3e-3)
    d = discover_effects(measurements(per_chain_form(EFFECTS["joint_friction"]), band, seed=7))
    assert d.effects == ("joint_friction",) and d.explained
    p = d.chosen.parameters()["joint_friction"]
    assert p["granularity"] == granularity and dict(d.evidence.granularity) == {"joint_friction": granularity}
    if granularity == SHARED:
        assert p["dead_band"]["value"] == pytest.approx(3e-3, abs=5 * p["dead_band"]["std"])
    else:
        for i, b in enumerate(band):
            v = p[f"dead_band[leg {i + 1}]"]
            assert v["value"] == pytest.approx(b, abs=5 * v["std"]) and v["unit"] == "mm"
