"""The blind suite: can discovery name an effect it is not told about?

``python -m pipeline.blind --robot NAME --seeds 20`` simulates, for each effect that applies to
the robot and for ``none``, seeded recordings of its MuJoCo machine
(:func:`pipeline.scenarios.effect_recording`: 60-120 poses in random order, the scenario
machine's geometric errors, 1 um noise, the effect's largest contribution 3-10 times the
noise), runs :func:`calib.effects.discover_effect` on each without telling it the effect, and
reports the rate of correct names and the held-out residual RMS after modelling against the
noise floor. Recordings run in parallel over the cores.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from calib.effects import effects_for
from calib.robots import ROBOTS, default_robot

from .parallel import spawn_pool

__all__ = ["blind_case", "run_blind_suite", "main"]


def blind_case(args: tuple) -> dict:
    """One recording: ``(robot name, effect, seed, gross_row)`` -> what discovery said about it."""
    robot, effect, seed, gross = args
    from pipeline.discover import discover
    from pipeline.scenarios import effect_recording

    rec = effect_recording(effect, seed, robot=robot)
    bad = None
    if gross:
        # A row like the paper's A2: tens of micrometres off, not physics.
        bad = int(np.random.default_rng(seed + 10_000).integers(rec.measured.shape[0]))
        rec.measured[bad, :3] += [0.02, -0.02, 0.0]
    rep = discover(rec, seed=seed, resim=False)
    s = rep.summary
    return {"robot": robot, "effect": effect, "seed": seed, "named": s["effect"], "poses": s["rows"],
            "magnitude_noise": rec.meta["simulation"]["largest_contribution_mm"] / rec.noise.pose_std(("mm",))[0],
            "heldout_before_mm": s["heldout_rms_before_mm"], "heldout_after_mm": s["heldout_rms_after_mm"],
            "noise_floor_mm": s["noise_floor_mm"], "flagged": s["flagged_poses"], "gross_row": bad}


def run_blind_suite(effects=None, seeds=range(20), *, robot: str = "hexapod", gross: bool = False,
                    workers: int | None = None, progress=None) -> list[dict]:
    """Run :func:`blind_case` for every effect and seed (in parallel; deterministic per case).

    Args:
        effects: effect names; default every effect that applies to ``robot`` (``none`` first).
        seeds: recording seeds.
        robot: a registered robot name.
    """
    effects = effects_for(default_robot(robot)) if effects is None else tuple(effects)
    cases = [(robot, e, int(s), gross) for e in effects for s in seeds]
    workers = workers or min(len(cases), os.cpu_count() or 1)
    out = []
    if workers == 1:
        for k, c in enumerate(cases):
            out.append(blind_case(c))
            if progress:
                progress(k + 1, len(cases))
        return out
    with spawn_pool(workers) as pool:
        for k, r in enumerate(pool.map(blind_case, cases)):
            out.append(r)
            if progress:
                progress(k + 1, len(cases))
    return out


def table(results: list[dict]) -> str:
    rows = ["| effect | recordings | named right | held-out RMS before (um) | after (um) | noise floor (um) | worst after / floor |",
            "|---|---|---|---|---|---|---|"]
    for e in dict.fromkeys(r["effect"] for r in results):
        rs = [r for r in results if r["effect"] == e]
        ok = sum(r["named"] == e for r in rs)
        ratio = max(r["heldout_after_mm"] / r["noise_floor_mm"] for r in rs)
        rows.append(f"| {e} | {len(rs)} | {ok}/{len(rs)} ({100 * ok / len(rs):.0f}%) | "
                    f"{1e3 * np.mean([r['heldout_before_mm'] for r in rs]):.3f} | "
                    f"{1e3 * np.mean([r['heldout_after_mm'] for r in rs]):.3f} | "
                    f"{1e3 * np.mean([r['noise_floor_mm'] for r in rs]):.3f} | {ratio:.2f} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pipeline.blind", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", choices=tuple(ROBOTS), default="hexapod", help="the robot simulated")
    ap.add_argument("--effects", nargs="+", default=None,
                    help="effects to simulate (default every effect that applies to the robot)")
    ap.add_argument("--seeds", type=int, default=20, help="recordings per effect")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--gross", action="store_true", help="add one grossly wrong row to every recording")
    ap.add_argument("--workers", type=int, default=None)
    a = ap.parse_args(argv)

    def progress(done, total):
        if done == total or done % max(1, total // 10) == 0:
            print(f"  {done}/{total} recordings", file=sys.stderr, flush=True)

    try:
        res = run_blind_suite(a.effects, range(a.first_seed, a.first_seed + a.seeds), robot=a.robot, gross=a.gross,
                              workers=a.workers, progress=progress)
    except (ValueError, NotImplementedError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"robot: {a.robot}")
    print(table(res))
    wrong = [r for r in res if r["named"] != r["effect"]]
    for r in wrong:
        print(f"  wrong: {r['effect']} seed {r['seed']} named {r['named']} (magnitude {r['magnitude_noise']:.1f} x noise)")
    if a.gross:
        hit = sum(r["gross_row"] in r["flagged"] for r in res)
        print(f"gross row flagged in {hit}/{len(res)} recordings")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
