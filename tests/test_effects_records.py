"""The typed record of a found effect (calib.effects.records.EffectRecord): through its JSON object
(``to_dict`` / ``from_dict``, the calibration file's ``effects[k]``) and back to the same record,
the same JSON text, and the same effect (:meth:`EffectRecord.fitted`: the same joint regressors,
bit for bit), for every registered effect on every robot it applies to, shared and per chain, a
compliance fitted at several payloads, a law with a recorded channel and a lost count's step; a
record lacking a key or naming an unknown effect is refused, naming the key or the name.

The coefficients, std and searched parameters are drawn here (not fitted by the product)."""

import json

import numpy as np
import pytest

from calib.effects import EFFECTS, EffectData, per_chain_form
from calib.effects.compliance import LoadedCompliance
from calib.effects.granularity import PER_CHAIN, SHARED
from calib.effects.laws import Term, TermFamily, law_effect
from calib.effects.lost_count import JointStep
from calib.effects.records import RECORD_KEYS, EffectRecord, FittedEffect
from calib.noise import SensorNoise
from calib.robots import ROBOTS, default_robot
from calib.workspace import reachable_poses

ROWS = 16
#: The payload a compliance at several payloads stands for, kg.
REFERENCE_PAYLOAD_KG = 2.0


def effect_data(robot, seed=0, channels=()):
    """``ROWS`` reachable poses of ``robot``'s nominal machine at increasing times, a payload per
    row about :data:`REFERENCE_PAYLOAD_KG`: ``(data, channels)`` with each named channel drawn."""
    rng = np.random.default_rng(seed)
    theta = robot.table.nominal
    poses = reachable_poses(robot, ROWS, rng, theta=theta)
    data = EffectData(robot, theta, robot.inverse_kinematics(theta, poses), poses, np.linspace(0.0, 90.0, ROWS),
                      SensorNoise(), payload_kg=REFERENCE_PAYLOAD_KG + rng.uniform(-1.0, 1.0, ROWS))
    return data, {name: rng.normal(size=ROWS) for name in channels}


def drawn(eff, robot, data, rng) -> FittedEffect:
    """``eff`` with coefficients and std drawn, its searched parameter the middle of its grid."""
    p = len(eff.coefficients(robot))
    extra = None
    base = getattr(eff, "base", eff)
    if base.searched:
        grid = base.search_grid(data)
        extra = base.searched_value(grid[len(grid) // 2])
    return FittedEffect(eff, rng.normal(size=p) * 1e-3, rng.uniform(1e-6, 1e-4, p), extra)


def forms(robot):
    """Every registered effect that applies to ``robot`` (not ``none``), shared and, where it
    has one, per chain; a compliance fitted at several payloads, shared and per chain."""
    out = []
    for name, eff in EFFECTS.items():
        if name == "none" or not eff.applies_to(robot):
            continue
        out.append(eff)
        if per_chain_form(eff) is not None:
            out.append(per_chain_form(eff))
    loaded = LoadedCompliance(REFERENCE_PAYLOAD_KG)
    return out + [loaded] + ([per_chain_form(loaded)] if per_chain_form(loaded) is not None else [])


CASES = [(r, k) for r in sorted(ROBOTS) for k in range(len(forms(default_robot(r))))]


def round_trip(record: EffectRecord) -> tuple[EffectRecord, str]:
    """The record through its JSON text and back, and that text."""
    text = json.dumps(record.to_dict(), indent=1)
    return EffectRecord.from_dict(json.loads(text), "effects[0]"), text


def assert_same_effect(back: FittedEffect, fe: FittedEffect, robot, data, channels=None):
    assert back.name == fe.name and back.effect.granularity == fe.effect.granularity
    assert type(getattr(back.effect, "base", back.effect)) is type(getattr(fe.effect, "base", fe.effect))
    np.testing.assert_array_equal(back.coefficients, fe.coefficients)
    np.testing.assert_array_equal(back.std, fe.std)
    assert back.extra == fe.extra
    np.testing.assert_array_equal(back.effect.joint_regressors(robot, data.theta, data, back.extra),
                                  fe.effect.joint_regressors(robot, data.theta, data, fe.extra))


@pytest.mark.parametrize("robot_name,k", CASES)
def test_every_registered_effect_round_trips_through_its_json_object(robot_name, k):
    robot = default_robot(robot_name)
    data, _ = effect_data(robot)
    eff = forms(robot)[k]
    fe = drawn(eff, robot, data, np.random.default_rng(k))
    record = EffectRecord.from_fitted(fe, robot)
    back, text = round_trip(record)
    assert back == record and json.dumps(back.to_dict(), indent=1) == text
    assert record.granularity == eff.granularity and record.coefficient_names == tuple(
        c.name for c in eff.coefficients(robot))
    assert [c.unit for c in record.coefficients] == [c.unit for c in eff.coefficients(robot)]
    is_loaded = isinstance(getattr(eff, "base", eff), LoadedCompliance)
    assert (record.reference_payload_kg == REFERENCE_PAYLOAD_KG) if is_loaded else record.reference_payload_kg is None
    assert record.law is None
    assert_same_effect(back.fitted(robot), fe, robot, data)


def test_a_per_chain_form_keeps_each_joints_coefficient():
    robot = default_robot("hexapod")
    data, _ = effect_data(robot)
    fe = drawn(per_chain_form(EFFECTS["joint_friction"]), robot, data, np.random.default_rng(1))
    d = EffectRecord.from_fitted(fe, robot).to_dict()
    assert d["granularity"] == PER_CHAIN and len(d["coefficients"]) == robot.n_chains
    assert list(d["coefficients"].values()) == fe.coefficients.tolist()
    back = EffectRecord.from_dict(d)
    assert back.granularity == PER_CHAIN and back.coefficient_names == tuple(d["coefficients"])
    np.testing.assert_array_equal(back.values, fe.coefficients)
    with pytest.raises(ValueError, match=r"effects\[0\]\.coefficients: expected the coefficients"):
        EffectRecord.from_dict({**d, "granularity": SHARED}, "effects[0]").fitted(robot, where="effects[0]")


def test_a_lost_count_keeps_its_joint_and_step_time():
    robot = default_robot("delta")
    data, _ = effect_data(robot)
    fe = FittedEffect(EFFECTS["lost_count"], np.array([3e-4]), np.array([1e-5]), JointStep(2, 41.25))
    record = EffectRecord.from_fitted(fe, robot)
    d = record.to_dict()
    assert d["searched"] == {"joint": 3, "step_time_s": 41.25}  # joints count from 1 in the file
    back, _ = round_trip(record)
    assert back.searched == JointStep(2, 41.25) and back == record
    assert_same_effect(back.fitted(robot), fe, robot, data)
    beyond = {**d, "searched": {"joint": robot.n_chains + 1, "step_time_s": 41.25}}
    with pytest.raises(ValueError, match=rf"effects\[2\]\.searched\.joint: {robot.n_chains + 1} is not a joint"):
        EffectRecord.from_dict(beyond, "effects[2]").fitted(robot, where="effects[2]")
    with pytest.raises(ValueError, match=r"effects\[2\]\.searched: expected a number or"):
        EffectRecord.from_dict({**d, "searched": {"joint": 1}}, "effects[2]")


def test_a_law_keeps_its_terms_and_binds_its_channel_when_rebuilt():
    """A law of three terms: the last move per joint, a saturating warm-up shared (its time
    constant searched), a recorded channel shared; rebuilt with the channel, it acts as the law
    built with it."""
    robot = default_robot("hexapod")
    data, channels = effect_data(robot, channels=("temperature_C",))
    terms = (Term(TermFamily("last move", ("last move",), unit=robot.joint_unit)),
             Term(TermFamily("1 - exp(-t/T)", (), "saturating"), 31.5),
             Term(TermFamily("temperature_C", ("temperature_C",), unit="channel unit")))
    law = law_effect(terms, {terms[0].name: PER_CHAIN}, channels, name="kept_law")
    fe = drawn(law, robot, data, np.random.default_rng(3))
    record = EffectRecord.from_fitted(fe, robot)
    assert record.law.terms == terms and record.law.granularity == (PER_CHAIN, SHARED, SHARED)
    assert record.name == "kept_law" and record.granularity == PER_CHAIN
    back, text = round_trip(record)
    assert back == record and json.dumps(back.to_dict(), indent=1) == text
    assert [t["key"] for t in back.to_dict()["law"]["terms"]] == ["last move", "1 - exp(-t/T)", "temperature_C"]
    assert_same_effect(back.fitted(robot, channels), fe, robot, data)


def some_record() -> dict:
    robot = default_robot("hexapod")
    fe = FittedEffect(EFFECTS["joint_friction"], np.array([2e-3]), np.array([1e-4]))
    return EffectRecord.from_fitted(fe, robot).to_dict()


@pytest.mark.parametrize("key", RECORD_KEYS)
def test_a_record_lacking_a_key_is_refused_naming_it(key):
    d = some_record()
    del d[key]
    with pytest.raises(ValueError, match=rf"^effects\[4\]: key '{key}' missing$"):
        EffectRecord.from_dict(d, "effects[4]")


BAD = {
    "an unknown effect": ({"name": "magic"}, r"effects\[0\]\.name: 'magic' is no registered effect"),
    "no effect": ({"name": "none"}, r"effects\[0\]\.name: 'none' is no registered effect"),
    "another granularity": ({"granularity": "per_leg"}, r"effects\[0\]\.granularity: 'per_leg'"),
    "a coefficient not a number": ({"coefficients": {"dead_band": "0.002"}}, r"effects\[0\]\.coefficients\.dead_band"),
    "std of other coefficients": ({"std": {"friction": 1e-4}}, r"effects\[0\]\.std: expected the coefficients"),
    "a unit missing": ({"units": {}}, r"effects\[0\]\.units: expected the coefficients \['dead_band'\]"),
    "a searched parameter not finite": ({"searched": float("inf")}, r"effects\[0\]\.searched: inf"),
    "a payload on a dead band": ({"reference_payload_kg": 2.0}, r"effects\[0\]\.reference_payload_kg"),
    "a law's terms unreadable": ({"law": {"terms": [{"key": "t"}]}}, r"effects\[0\]\.law: not a law's terms"),
    "not an object": (None, r"effects\[0\]: expected an object with keys name, granularity"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_record_is_refused_naming_the_key(case):
    change, words = BAD[case]
    d = None if change is None else {**some_record(), **change}
    with pytest.raises(ValueError, match=words):
        EffectRecord.from_dict(d, "effects[0]")


def test_an_effect_of_another_robot_is_refused_when_rebuilt():
    d = {**some_record(), "name": "thermal_drift", "coefficients": {}, "std": {}, "units": {}}
    record = EffectRecord.from_dict(d, "effects[1]")
    with pytest.raises(ValueError, match=r"effects\[1\]\.name: 'thermal_drift' does not apply to the delta"):
        record.fitted(default_robot("delta"), where="effects[1]")
