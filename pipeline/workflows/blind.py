"""The blind suite: does discovery name what it is not told, and say what it cannot explain?

:func:`run_blind_suite` (``python -m pipeline.blind --robot NAME --seeds 20``) simulates seeded recordings of the robot's
MuJoCo machine (:func:`pipeline.simulation.effect_recording`: 60-120 poses in random order, the
scenario machine's geometric errors, 1 um noise, each effect's largest contribution 3-10 times
the noise) and runs :func:`pipeline.workflows.discovery.discover` on each without telling it the truth.
Kinds of recording (``--kinds``):

- ``single``: one effect, or none; every effect with a per-chain form
  (:mod:`calib.effects.granularity`) drawn with a per-joint spread (each joint 0.3 to 1.0 times
  the largest, random signs where physical: real joints differ), so is every kind below but
  ``shared``;
- ``shared``: one effect that has a per-chain form, drawn with one value for every joint (the
  discovery must name it alone and call it ``shared``);
- ``pair``: two effects at once (``--pairs``; default every pair that applies, but two nested
  effects: selection names one member of a family, the pair is inseparable by construction);
- ``leave_one_out``: a single effect's recording analysed with that effect's whole family
  removed from the candidates (the unknown must be said to be unknown, and what it follows
  named). The family (:func:`calib.effects.effect_family`) is the effect and every effect nested
  with it, either way (``thermal_drift`` and ``thermal_warmup``, which contains it as its
  long-time-constant limit): a model that contains the true one explains the recording
  correctly, so leaving out only one member would count a right answer as a failure;
- ``gross3``: three rows 28 um off (like the paper's row A2) added to a single-effect recording;
- ``noise10``, ``noise100``: the sensor noise 10 and 100 times the declared one;
- ``gross30``: 30% of the rows grossly off;
- ``geometry_off``: the recording's nominal geometry 10% off (base and platform joints scaled;
  hexapod only);
- ``law``: a recording whose joints follow a law outside the library
  (:data:`pipeline.simulation.LAW_CASES`: a settle lag, a dead band growing with time, a friction
  in proportion to the load, a scale quadratic in stroke, a drift following a recorded
  temperature), each joint its own constant (``--laws``; default every law the robot has): the
  law search must name the law's terms, per joint, and bring the cross-validated residual to the
  noise floor.

Every analysis records whether a law was proposed (``law_proposed``): on the recordings the
library explains (``single``, ``shared``, ``pair``, ``gross3``) and the effect-free ones, none
should be.

The derived kinds reuse the single-effect recordings (no further simulation). Each result says
whether its acceptance criterion holds (:func:`criteria`); :func:`rates_table` sums them up.
Recordings run in parallel on the Dask executor (:mod:`pipeline.execution`: a local cluster of
``--workers`` processes, ``--workers 1`` here, or ``--scheduler ADDRESS``); the rates go to
stdout, progress to stderr (the recordings done, however they run: :class:`pipeline.execution.ProgressDisplay`).
"""

from __future__ import annotations

from dataclasses import replace
from itertools import combinations

import numpy as np

from calib.effects import EFFECTS, effect_family, effects_for
from calib.effects.discovery import SIGNIFICANCE_ALPHA
from calib.effects.granularity import PER_CHAIN, SHARED, per_chain_form
from calib.robots import default_robot

from pipeline.execution import default_workers, run_tasks

__all__ = ["KINDS", "STRESS_KINDS", "LIBRARY_KINDS", "LAW_FLOOR_FACTOR", "GROSS_OFFSET_MM", "blind_case", "blind_cases", "run_blind_suite", "criteria",
           "failure_lines", "rates_table"]

#: The kinds of recording (see the module docstring).
KINDS = ("single", "shared", "pair", "leave_one_out", "gross3", "noise10", "noise100", "gross30", "geometry_off", "law")
#: Kinds whose recordings the library explains: no law may be proposed there.
LIBRARY_KINDS = ("single", "shared", "pair", "gross3")
#: A proposed law's cross-validated residual at the floor: within this factor of the noise floor.
LAW_FLOOR_FACTOR = 1.2
#: Kinds where only the verdict's consistency is asked for.
STRESS_KINDS = ("noise10", "noise100", "gross30", "geometry_off")
#: A gross row's position error, mm (like the paper's row A2: tens of micrometres).
GROSS_OFFSET_MM = np.array([0.02, -0.02, 0.0])
#: Most rows flagged in a recording without gross rows, as a fraction.
MAX_FLAGGED_FRACTION = 0.02
#: The nominal geometry's error in ``geometry_off``.
GEOMETRY_SCALE = 1.1


def _analyse(rec, candidates, seed: int) -> dict:
    from pipeline.report.text import terminal_lines
    from pipeline.workflows.discovery import discover

    found = discover(rec, seed=seed, resim=False, candidates=candidates)
    report, disc = found.report, found.discovery
    lines = terminal_lines(report)
    said_explained = any("explains the recording to the noise" in line for line in lines) or \
        lines[0].startswith("Explained")
    effects, remaining, heldout = report.effects.effects, report.effects.remaining, report.heldout
    tests_pass = disc.tests.noise.consistent and not remaining.follows
    insignificant = [e.name for e in effects if e.p_value > SIGNIFICANCE_ALPHA]
    law = None if disc.proposed_law is None else disc.proposed_law.summary()
    return {"named": [e.name for e in effects], "explained": report.verdict.success,
            "follows": list(remaining.follows),
            "law_proposed": law is not None, "law_terms": [] if law is None else law["terms"],
            "law_granularity": {} if law is None else law["term_granularity"],
            "law_cv_after_mm": None if law is None else law["cv_rms_after_mm"],
            "law_noise_floor_mm": None if law is None else law["noise_floor_mm"],
            "granularity": {e.name: e.granularity for e in effects},
            "flagged": list(report.flagged.rows), "rows": report.source.rows, "model_wrong": report.flagged.model_wrong,
            "heldout_before_mm": heldout.figures[0].before.rms, "heldout_after_mm": heldout.figures[0].after.rms,
            "noise_floor_mm": heldout.noise_floor_mm, "verdict": report.verdict.words,
            "consistent": bool(said_explained == report.verdict.success == tests_pass) and not insignificant,
            "insignificant": insignificant}


def _with_noise(rec, factor: float, rng: np.random.Generator):
    """The recording with its sensor noise ``factor`` times the declared one (the declared noise
    kept)."""
    robot = rec.robot
    std = rec.noise.pose_std(robot.pose_units) * np.sqrt(factor ** 2 - 1)
    return replace(rec, measured=rec.measured + rng.standard_normal(rec.measured.shape) * std)


def _with_gross(rec, rows: np.ndarray, rng: np.random.Generator):
    m = rec.measured.copy()
    signs = rng.choice([-1.0, 1.0], size=(rows.size, 1))
    m[rows, :3] += signs * GROSS_OFFSET_MM
    return replace(rec, measured=m)


def _geometry_off(rec):
    robot = rec.robot
    if robot.name != "hexapod":
        raise NotImplementedError(f"geometry_off scales a hexapod's joints; not written for the {robot.name}")
    d = robot.description()
    d["base_joints_mm"] = (np.asarray(d["base_joints_mm"]) * GEOMETRY_SCALE).tolist()
    d["platform_joints_mm"] = (np.asarray(d["platform_joints_mm"]) * GEOMETRY_SCALE).tolist()
    return replace(rec, robot=type(robot).from_description(d))


def blind_case(args: tuple) -> list[dict]:
    """One simulated recording and the analyses asked of it.

    Args:
        args: ``(robot name, effects (tuple, empty for none), seed, kinds[, payloads])``;
            ``kinds`` among :data:`KINDS` (``single`` and ``pair`` both mean the recording as
            simulated); ``payloads`` 1 (default) or 2: the recordings taken at two payloads
            (:func:`pipeline.simulation.effect_recording`, :func:`~pipeline.simulation.law_recording`).

    Returns:
        One dict per analysis: the truth, what discovery said, and :func:`criteria`.
    """
    robot_name, effects, seed, kinds, *rest = args
    payloads = int(rest[0]) if rest else 1
    from pipeline.simulation import effect_recording

    robot = default_robot(robot_name)
    everything = effects_for(robot)
    if tuple(kinds) == ("law",):
        return _with_criteria([_law_case(robot, effects[0], seed, everything, payloads)])
    out = []
    if "shared" in kinds:  # its own recording: every joint the same value
        rec = effect_recording(tuple(effects) or "none", seed, robot=robot, granularity=SHARED, payloads=payloads)
        out.append(dict(_truth(rec, robot_name, effects, seed), kind="shared", **_analyse(rec, everything, seed)))
        kinds = tuple(k for k in kinds if k != "shared")
        if not kinds:
            return _with_criteria(out)
    rec = effect_recording(tuple(effects) or "none", seed, robot=robot, granularity=PER_CHAIN, payloads=payloads)
    base = _truth(rec, robot_name, effects, seed)
    rng = np.random.default_rng(seed + 10_000)
    for kind in kinds:
        if kind in ("single", "pair"):
            out.append(dict(base, kind=kind, **_analyse(rec, everything, seed)))
        elif kind == "leave_one_out":
            for e in effects:
                family = effect_family(e)
                r = _analyse(rec, [c for c in everything if c not in family], seed)
                out.append(dict(base, kind=kind, left_out=e, left_out_family=list(family),
                                expected=EFFECTS[e].follows, **r))
        elif kind == "gross3":
            rows = np.sort(rng.choice(rec.measured.shape[0], 3, replace=False))
            r = _analyse(_with_gross(rec, rows, rng), everything, seed)
            out.append(dict(base, kind=kind, gross_rows=[int(i) + 1 for i in rows], **r))
        elif kind in ("noise10", "noise100"):
            r = _analyse(_with_noise(rec, float(kind[5:]), rng), everything, seed)
            out.append(dict(base, kind=kind, **r))
        elif kind == "gross30":
            rows = rng.choice(rec.measured.shape[0], int(round(0.3 * rec.measured.shape[0])), replace=False)
            out.append(dict(base, kind=kind, **_analyse(_with_gross(rec, rows, rng), everything, seed)))
        elif kind == "geometry_off":
            out.append(dict(base, kind=kind, **_analyse(_geometry_off(rec), everything, seed)))
        else:
            raise ValueError(f"unknown kind {kind!r}: expected one of {', '.join(KINDS)}")
    return _with_criteria(out)


def _law_case(robot, name: str, seed: int, everything, payloads: int = 1) -> dict:
    """The ``law`` kind: a recording following the law ``name`` (:func:`pipeline.simulation.law_recording`)."""
    from pipeline.simulation import law_recording

    rec = law_recording(name, seed, robot=robot, payloads=payloads)
    truth = rec.meta["simulation"]["law"]
    return dict(robot=robot.name, effects=[], seed=seed, kind="law", law=name, true_law_terms=truth["terms"],
                true_law_granularity=truth["granularity"],
                magnitude_noise=truth["largest_contribution_mm"] / rec.noise.pose_std(("mm",))[0],
                **_analyse(rec, everything, seed))


def _truth(rec, robot_name: str, effects, seed: int) -> dict:
    """What a result says of the recording's truth: effects, seed, sizes, each effect's granularity."""
    sim = rec.meta["simulation"]
    return {"robot": robot_name, "effects": list(effects), "seed": seed,
            "payloads_kg": sim.get("payloads_kg"),
            "magnitude_noise": {e: v / rec.noise.pose_std(("mm",))[0] for e, v in sim["contributions_mm"].items()},
            "true_granularity": dict(sim.get("granularity", {}))}


def _with_criteria(out: list[dict]) -> list[dict]:
    for r in out:
        r["criteria"] = criteria(r)
    return out


def criteria(r: dict) -> dict:
    """The acceptance criteria a result meets (``True``/``False`` per criterion that applies).

    - ``named``: single and shared: the effect named alone (none: nothing) and ``explained``;
      pair: both named and the held-out residual within 1.5 x the noise floor;
    - ``granularity``: single, shared and pair: every true effect named is given its true
      granularity (``shared`` or ``per_chain``);
    - ``unknown``: leave-one-out (the effect's family left out): ``explained`` false;
      ``points``: the remainder's strongest quantity is the one the left-out effect follows;
    - ``rows``: at most 2% of the rows flagged; gross3: exactly the three gross rows flagged;
    - ``consistent``: the verdict agrees with its own tests and every named effect is
      significantly non-zero;
    - ``law_terms``: law: the law proposed has exactly the true law's terms, each with its true
      granularity; ``law_floor``: its cross-validated residual within :data:`LAW_FLOOR_FACTOR`
      x the noise floor;
    - ``no_law``: the kinds the library explains (:data:`LIBRARY_KINDS`): no law proposed.
    """
    c = {"consistent": r["consistent"]}
    kind = r["kind"]
    if kind == "law":
        g = r["law_granularity"]
        c["law_terms"] = sorted(r["law_terms"]) == sorted(r["true_law_terms"]) \
            and all(g[t] == r["true_law_granularity"] for t in r["law_terms"])
        c["law_floor"] = r["law_proposed"] and r["law_cv_after_mm"] <= LAW_FLOOR_FACTOR * r["law_noise_floor_mm"]
        return c
    if kind in LIBRARY_KINDS:
        c["no_law"] = not r["law_proposed"]
    if kind in ("single", "shared", "pair") and r["effects"]:
        said = r.get("granularity", {})
        c["granularity"] = all(said.get(e) == g for e, g in r.get("true_granularity", {}).items() if e in said) \
            and any(e in said for e in r["effects"])
    if kind in ("single", "shared"):
        c["named"] = r["named"] == r["effects"] and r["explained"]
    elif kind == "pair":
        c["named"] = set(r["effects"]) <= set(r["named"]) and r["heldout_after_mm"] <= 1.5 * r["noise_floor_mm"]
    elif kind == "leave_one_out":
        c["unknown"] = not r["explained"]
        c["points"] = bool(r["follows"]) and r["follows"][0] == r["expected"]
        c["points_top3"] = r["expected"] in r["follows"][:3]
    if kind == "gross3":
        c["rows"] = sorted(r["flagged"]) == sorted(r["gross_rows"])
    elif kind != "gross30":
        c["rows"] = len(r["flagged"]) <= MAX_FLAGGED_FRACTION * r["rows"]
    return c


def blind_cases(effects=None, seeds=range(20), *, robot: str = "hexapod", kinds=("single",), pairs=None,
                laws=None, payloads: int = 1) -> list[tuple]:
    """The recordings :func:`run_blind_suite` runs, each the argument of one :func:`blind_case`:
    ``(robot, effects, seed, kinds)``, with ``payloads`` appended when it is 2 (arguments as
    :func:`run_blind_suite`'s; a ``law`` case: ``(robot, (law name,), seed, ("law",))``)."""
    if payloads not in (1, 2):
        raise ValueError(f"payloads must be 1 or 2, got {payloads!r}")
    more = () if payloads == 1 else (payloads,)
    from pipeline.simulation import LAW_CASES, law_cases_for

    names = effects_for(default_robot(robot)) if effects is None else tuple(effects)
    kinds = tuple(kinds)
    cases = []
    if "law" in kinds:
        for name in (law_cases_for(default_robot(robot)) if laws is None else tuple(laws)):
            if name not in LAW_CASES:
                raise ValueError(f"unknown law {name!r}: expected one of {', '.join(LAW_CASES)}")
            cases += [(robot, (name,), int(s), ("law",)) + more for s in seeds]
    single_kinds = [k for k in kinds if k not in ("pair", "law")]
    if single_kinds:
        for e in names:
            ks = [k for k in single_kinds if e != "none" or k in ("single",) + STRESS_KINDS]
            if e == "none" or per_chain_form(EFFECTS[e]) is None:  # no shared form to tell from a per-chain one
                ks = [k for k in ks if k != "shared"]
            if ks:
                cases += [(robot, () if e == "none" else (e,), int(s), tuple(ks)) + more for s in seeds]
    if "pair" in kinds:
        real = [e for e in effects_for(default_robot(robot)) if e != "none"]
        default = [(a, b) for a, b in combinations(real, 2) if b not in effect_family(a)]
        for p in (default if pairs is None else [tuple(p) for p in pairs]):
            cases += [(robot, p, int(s), ("pair",)) + more for s in seeds]
    return cases


def run_blind_suite(effects=None, seeds=range(20), *, robot: str = "hexapod", kinds=("single",), pairs=None,
                    laws=None, workers: int | None = None, scheduler: str | None = None, progress=None,
                    display=None, payloads: int = 1) -> list[dict]:
    """Run :func:`blind_case` for every recording asked (in parallel; deterministic per case).

    Args:
        effects: single-effect recordings: effect names (``none`` for none); default every
            effect that applies to ``robot``, ``none`` first.
        seeds: recording seeds.
        robot: a registered robot name.
        kinds: the analyses (:data:`KINDS`); every kind but ``pair`` is done on the single-effect
            recordings (``leave_one_out`` and the stress kinds skip ``none``).
        pairs: pairs of effects for ``pair`` (default every pair of applying effects but nested
            ones, e.g. ``thermal_drift`` and ``thermal_warmup``: a drift plus a warm-up is a
            warm-up with a drift, and selection names one member of a family, never two).
        laws: the laws of the ``law`` kind (:data:`pipeline.simulation.LAW_CASES` names); default
            every law the robot has.
        workers: processes of the local Dask cluster (:func:`pipeline.execution.run_tasks`);
            default the cores, at most one a recording; 1 runs here.
        scheduler: address of an existing Dask cluster to run on instead.
        progress: ``progress(done, total)`` after each recording.
        display: a :class:`pipeline.execution.ProgressDisplay` showing the recordings done, however they run.
        payloads: 1, or 2: every recording taken at two payloads (a light
            and a heavy one, swapped three times, recorded as the channel ``payload_kg``:
            :func:`pipeline.simulation.effect_recording`).
    """
    cases = blind_cases(effects, seeds, robot=robot, kinds=kinds, pairs=pairs, laws=laws, payloads=payloads)
    workers = max(1, min(len(cases), default_workers())) if workers is None else workers
    from pipeline.workflows.blind import blind_case as entry  # by name in the workers (also when run as __main__)

    done = [None] * len(cases)
    for k, r in run_tasks(entry, cases, workers=workers, scheduler=scheduler, progress=progress, display=display):
        done[k] = r
    return [r for rs in done for r in rs]


def _group(r: dict) -> str:
    if r["kind"] == "leave_one_out":
        return f"leave_one_out: {r['left_out']}"
    if r["kind"] == "law":
        return f"law: {r['law']}"
    return f"{r['kind']}: {' + '.join(r['effects']) or 'none'}"


def failure_lines(results: list[dict]) -> list[str]:
    """One line per recording that failed a criterion: what was expected, what was found."""
    lines = []
    for r in results:
        failed = [k for k, v in r["criteria"].items() if not v and k != "points_top3"]
        if failed:
            lines.append(f"  {_group(r)} seed {r['seed']}: {', '.join(failed)} failed; named {r['named'] or 'none'}, "
                         f"explained {r['explained']}, follows {r['follows'][:3]}, flagged {r['flagged']}"
                         + (f"; law proposed {r['law_terms']} {r['law_granularity']}" if r["law_proposed"] else ""))
    return lines


def rates_table(results: list[dict]) -> str:
    """Markdown table: per kind and truth, the rate of each criterion met."""
    names = ("named", "granularity", "unknown", "points", "points_top3", "rows", "consistent", "no_law", "law_terms",
             "law_floor")
    rows = ["| recordings | n | " + " | ".join(names) + " | held-out after / floor (worst) |",
            "|---|---|" + "---|" * len(names) + "---|"]
    for g in dict.fromkeys(_group(r) for r in results):
        rs = [r for r in results if _group(r) == g]
        cells = []
        for c in names:
            vals = [r["criteria"][c] for r in rs if c in r["criteria"]]
            cells.append(f"{sum(vals)}/{len(vals)}" if vals else "")
        worst = max(r["heldout_after_mm"] / r["noise_floor_mm"] for r in rs)
        rows.append(f"| {g} | {len(rs)} | " + " | ".join(cells) + f" | {worst:.2f} |")
    return "\n".join(rows)

