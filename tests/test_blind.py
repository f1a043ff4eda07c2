"""The blind suite's bookkeeping without simulating (the recordings are stood in for): which
candidates each kind of analysis gets."""

import re
from types import SimpleNamespace

import numpy as np
import pytest

import pipeline.workflows.blind as blind
from pipeline.blind import run as blind_command
import pipeline.execution as executor
import pipeline.simulation as scenarios
from calib.effects import effect_family, effects_for
from calib.noise import SensorNoise
from calib.robots import default_robot


@pytest.fixture
def seen(monkeypatch):
    """The candidates of every analysis blind_case asks for (the recording is a stand-in)."""
    calls = []

    def fake_recording(effects, seed, robot=None, granularity="shared", payloads=1):
        names = () if effects == "none" else tuple(effects)
        return SimpleNamespace(noise=SensorNoise(0.001, 1e-6, "normal"), measured=np.zeros((60, 6)),
                               meta={"simulation": {"contributions_mm": {e: 0.005 for e in names}}})

    def fake_analyse(rec, candidates, seed):
        calls.append(tuple(candidates))
        return {"named": [], "explained": False, "follows": ["time"], "flagged": [], "rows": 60,
                "model_wrong": False, "heldout_before_mm": 0.002, "heldout_after_mm": 0.001,
                "noise_floor_mm": 0.001, "verdict": "", "consistent": True, "insignificant": [],
                "law_proposed": False}

    monkeypatch.setattr(scenarios, "effect_recording", fake_recording)
    monkeypatch.setattr(blind, "_analyse", fake_analyse)
    return calls


@pytest.mark.parametrize("left_out", ["thermal_drift", "thermal_warmup"])
def test_leave_one_out_removes_the_whole_family_of_nested_effects(seen, left_out):
    everything = effects_for(default_robot("hexapod"))
    (r,) = blind.blind_case(("hexapod", (left_out,), 0, ("leave_one_out",)))
    (candidates,) = seen
    assert "thermal_drift" not in candidates and "thermal_warmup" not in candidates
    assert set(candidates) == set(everything) - {"thermal_drift", "thermal_warmup"}
    assert r["left_out"] == left_out and r["left_out_family"] == ["thermal_drift", "thermal_warmup"]
    assert r["expected"] == "time" and r["criteria"]["unknown"] and r["criteria"]["points"]


def test_leave_one_out_of_an_effect_without_family_removes_it_alone(seen):
    assert effect_family("lost_count") == ("lost_count",)
    blind.blind_case(("hexapod", ("lost_count",), 0, ("leave_one_out",)))
    (candidates,) = seen
    assert set(candidates) == set(effects_for(default_robot("hexapod"))) - {"lost_count"}


def test_a_pair_recording_leaving_each_out_removes_each_family(seen):
    blind.blind_case(("hexapod", ("thermal_warmup", "joint_friction"), 0, ("leave_one_out", "single")))
    no_warmup, no_friction, everything = seen
    assert {"thermal_drift", "thermal_warmup"} & set(no_warmup) == set() and "joint_friction" in no_warmup
    assert "joint_friction" not in no_friction and {"thermal_drift", "thermal_warmup"} <= set(no_friction)
    assert everything == effects_for(default_robot("hexapod"))


@pytest.mark.slow
def test_one_recording_with_no_workers_reports_progress_on_stderr(monkeypatch, capsys):
    """With no --workers and no --scheduler, one recording runs here (the local cluster is at most a
    worker a recording): the command still shows its progress, on stderr, and stdout is the rates only.
    Several cores are claimed, so that a command deciding on its own that the job runs on a cluster
    (and leaving the count to it) would show nothing, whatever this machine has."""
    monkeypatch.setattr(executor, "default_workers", lambda: 4)
    res = blind_command(["--effects", "none", "--seeds", "1"])
    out, err = capsys.readouterr()
    assert len(res) == 1 and res[0]["kind"] == "single" and res[0]["effects"] == []
    assert out == "\n".join(["robot: hexapod", blind.rates_table(res), *blind.failure_lines(res)]) + "\n"
    lines = err.splitlines()
    assert lines[0].startswith("blind suite: 0/1 recordings") and len(lines) == 2
    assert re.fullmatch(r"blind suite: 1/1 recordings \(\d+\.\d s\), done", lines[-1])


@pytest.mark.parametrize("workers", [0, -2])
def test_no_worker_is_refused_not_taken_for_the_default(workers):
    """``workers=0`` is no worker at all: refused like any count below one, not read as "the default"."""
    with pytest.raises(ValueError, match=f"workers must be >= 1, got {workers}"):
        blind.run_blind_suite(["none"], range(1), workers=workers)


def test_a_suite_of_no_recordings_is_empty_not_an_error():
    """No case (an empty list of effects): the default worker count stays at least one."""
    assert blind.blind_cases([], range(3)) == [] and blind.run_blind_suite([], range(3)) == []


def test_criteria_judge_naming_and_granularity_of_single_shared_and_pair_results():
    base = {"named": ["joint_friction"], "effects": ["joint_friction"], "explained": True, "consistent": True,
            "flagged": [], "rows": 60, "heldout_after_mm": 0.0011, "noise_floor_mm": 0.001,
            "granularity": {"joint_friction": "per_chain"}, "true_granularity": {"joint_friction": "per_chain"},
            "law_proposed": False}
    assert blind.criteria(dict(base, kind="single")) == {"consistent": True, "granularity": True, "named": True,
                                                         "rows": True, "no_law": True}
    assert not blind.criteria(dict(base, kind="single", law_proposed=True))["no_law"]
    shared = blind.criteria(dict(base, kind="shared", true_granularity={"joint_friction": "shared"}))
    assert shared["named"] and not shared["granularity"]
    pair = dict(base, kind="pair", effects=["joint_friction", "thermal_drift"], named=["joint_friction"])
    assert not blind.criteria(pair)["named"]
    pair = dict(pair, named=["joint_friction", "thermal_drift"],
                granularity={"joint_friction": "per_chain", "thermal_drift": "shared"},
                true_granularity={"joint_friction": "per_chain", "thermal_drift": "per_chain"})
    c = blind.criteria(pair)
    assert c["named"] and not c["granularity"]
    assert not blind.criteria(dict(pair, heldout_after_mm=0.0016))["named"]  # more than 1.5 x the floor


def test_the_shared_kind_is_asked_only_of_effects_with_a_per_chain_form():
    cases = blind.blind_cases(seeds=range(1), robot="hexapod", kinds=("shared",))
    assert {c[1] for c in cases} == {("compliance",), ("joint_friction",), ("thermal_drift",),
                                     ("periodic_screw_error",), ("thermal_warmup",)}


def test_criteria_judge_a_law_by_its_terms_their_granularity_and_the_floor():
    base = {"kind": "law", "consistent": True, "law_proposed": True, "law_terms": ["stroke^2"],
            "law_granularity": {"stroke^2": "per_chain"}, "true_law_terms": ["stroke^2"],
            "true_law_granularity": "per_chain", "law_cv_after_mm": 0.00119, "law_noise_floor_mm": 0.001}
    assert blind.criteria(base) == {"consistent": True, "law_terms": True, "law_floor": True}
    assert not blind.criteria(dict(base, law_granularity={"stroke^2": "shared"}))["law_terms"]
    assert not blind.criteria(dict(base, law_terms=["stroke^2", "t"],
                                   law_granularity={"stroke^2": "per_chain", "t": "per_chain"}))["law_terms"]
    assert not blind.criteria(dict(base, law_cv_after_mm=0.00121))["law_floor"]  # beyond 1.2 x the floor
    none = dict(base, law_proposed=False, law_terms=[], law_granularity={}, law_cv_after_mm=None)
    assert blind.criteria(none) == {"consistent": True, "law_terms": False, "law_floor": False}


def test_the_law_kind_asks_every_law_the_robot_has_and_refuses_an_unknown_one():
    cases = blind.blind_cases(seeds=range(700, 702), robot="delta", kinds=("law", "single"), effects=["none"])
    laws = [c for c in cases if c[3] == ("law",)]
    assert {c[1][0] for c in laws} == set(scenarios.LAW_CASES) and len(laws) == 2 * len(scenarios.LAW_CASES)
    assert [c for c in cases if c[3] != ("law",)] == [("delta", (), 700, ("single",)), ("delta", (), 701, ("single",))]
    with pytest.raises(ValueError, match="unknown law 'creep'"):
        blind.blind_cases(seeds=range(1), kinds=("law",), laws=["creep"])


def test_a_law_recording_is_judged_by_the_law_search():
    """One simulated law recording of the hexapod, analysed blind: the law's term, per leg, at the floor."""
    (r,) = blind.blind_case(("hexapod", ("settle lag",), 3, ("law",)))
    assert r["kind"] == "law" and r["law"] == "settle lag" and 3 <= r["magnitude_noise"] <= 10
    assert r["criteria"]["law_terms"] and r["criteria"]["law_floor"], r
