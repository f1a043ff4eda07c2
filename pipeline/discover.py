"""``python -m pipeline.discover --real FILE``: find the physics the geometric model left out.

Calibrates the geometry, locates where the residuals concentrate, names the left-out effect
from a library of physical candidates (:mod:`calib.effects`), fits it jointly with the
geometry, shows the held-out fit improve, and re-simulates the MuJoCo machine with the effect
added, re-fitting its physical parameter there with ``mujoco.sysid``.

Callable from Python as :func:`discover`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.effects import EFFECTS, Discovery, EffectData, discover_effect, fit_effect, joint_noise_std
from calib.hexapod import Hexapod, robot_and_theta
from mjcf.hexapod import DEFAULT_STIFFNESS_N_PER_M
from mjcf.machine import GRAVITY_M_S2
from mjcf.units import M_PER_MM

from .recording import Recording, atomic_write, read_recording

__all__ = ["discover", "DiscoveryReport", "resimulate", "main"]

DEFAULT_PLATFORM_KG = 2.0


@dataclass
class DiscoveryReport:
    """What :func:`discover` found (``summary`` is the JSON written by ``--summary-json``)."""

    discovery: Discovery
    summary: dict


def _heldout(data: EffectData, effect: str, heldout_rows: np.ndarray, train_rows: np.ndarray, pitch) -> dict:
    """Held-out joint-space residual RMS (mm) of geometry only and geometry + effect, both
    fitted on ``train_rows``, and the noise floor of the held-out residuals."""
    train, test = data.subset(train_rows), data.subset(heldout_rows)
    before = fit_effect(train, "none").predict(test)[0]
    after = fit_effect(train, effect, pitch_mm=pitch).predict(test)[0] if effect != "none" else before
    floor = float(np.sqrt(np.mean(joint_noise_std(data.nominal, test) ** 2)))
    rms_b = float(np.sqrt(np.mean(before ** 2)))
    rms_a = float(np.sqrt(np.mean(after ** 2)))
    return {"heldout_rms_before_mm": rms_b, "heldout_rms_after_mm": rms_a, "noise_floor_mm": floor,
            "after_over_floor": rms_a / floor, "heldout_rows": [int(i) for i in heldout_rows]}


def _physics(effect: str, fit, meta: dict) -> tuple[dict, dict]:
    """MuJoCo options and machine effects that reproduce a fitted effect, plus the names of
    the physical quantities (for the report)."""
    opts: dict = {}
    fx: dict = {}
    c = fit.coefficients
    moving = float(meta.get("moving_mass_kg", DEFAULT_PLATFORM_KG))
    if effect == "leg_compliance":
        weight = moving * GRAVITY_M_S2
        k = weight / max(c[0] * M_PER_MM, 1e-12)
        opts = dict(gravity=True, payload_kg=max(moving - DEFAULT_PLATFORM_KG, 0.0), actuator_stiffness=k)
    elif effect == "joint_friction":
        opts = dict(joint_friction=max(c[0], 0.0) * M_PER_MM * DEFAULT_STIFFNESS_N_PER_M)
    elif effect == "thermal_drift":
        fx = dict(joint_drift_per_s=float(c[0]))
    elif effect == "actuator_scale":
        opts = dict(transmission_scale=tuple(float(v) for v in c))
    elif effect == "periodic_screw_error":
        a, b = c[0::2], c[1::2]
        fx = dict(screw_amplitude=tuple(np.hypot(a, b)), screw_phase_rad=tuple(np.arctan2(b, a)),
                  screw_pitch=float(fit.pitch_mm))
    return opts, fx


# The one physical parameter re-fitted in MuJoCo through mujoco.sysid, per effect.
_SYSID_PARAMETER = {"leg_compliance": ("actuator_stiffness", "N/m"), "joint_friction": ("joint_friction", "N"),
                    "thermal_drift": ("joint_drift_per_s", "mm/s")}


def _simulate(hexapod: Hexapod, rec: Recording, rows: np.ndarray, opts: dict, fx: dict, *,
              history: bool = True) -> np.ndarray:
    from mjcf.machine import MachineEffects, MachineOptions
    from pipeline.testbed import Testbed

    o = MachineOptions(platform_mass_kg=DEFAULT_PLATFORM_KG, **opts)
    robot, theta = robot_and_theta(hexapod)
    # At rest to 1e-7 m/s is ample for micrometre comparisons (the settled pose is then within
    # about 1e-10 m), and several times faster than the testbed's default.
    bed = Testbed(robot, theta, options=o, effects=MachineEffects(**fx), settle_velocity=1e-7)
    if not history:
        return bed.measure(rec.commanded[rows], times_s=rec.t_s[rows]).true_poses
    # Replay the whole record in order (friction depends on the motion history), keep rows.
    m = bed.measure(rec.commanded, times_s=rec.t_s)
    return m.true_poses[rows]


def resimulate(rec: Recording, disc: Discovery, *, sysid: bool = True, max_nfev: int = 5,
               sysid_rows: int = 20, seed: int = 0) -> dict:
    """Re-simulate the recorded commands on MuJoCo machines and compare with the recording.

    Before: the machine with the geometry identified alone. After: the machine with the
    geometry identified jointly with the effect, and the effect's physics added
    (:func:`_physics`); for compliance, friction and thermal drift its physical parameter is then
    re-fitted in MuJoCo with ``mujoco.sysid`` (confidence interval from its Jacobian). For the
    transmission effects (scale, screw) the calib-level fit is already the physical parameter
    (they enter the leg length directly), so they are simulated as fitted. The re-fit uses at
    most ``sysid_rows`` rows (every row for friction, whose dead band depends on the whole
    motion history), since each evaluation re-simulates them.

    Returns:
        JSON-ready dict: task-space RMS (um, urad) of simulated minus recorded poses, before
        and after, and the re-fitted parameter with its 95% interval.
    """
    rows = disc.kept
    w = rec.noise.weights()
    meas = rec.measured[rows]

    def rms(sim):
        d = meas - sim
        return {"position_um": float(1e3 * np.sqrt(np.mean(np.sum(d[:, :3] ** 2, axis=1)))),
                "orientation_urad": float(1e6 * np.sqrt(np.mean(np.sum(d[:, 3:] ** 2, axis=1))))}

    before = _simulate(disc.fits["none"].hexapod, rec, rows, {}, {})
    out = {"before": rms(before)}
    effect = disc.effect
    if effect == "none":
        out["after"] = out["before"]
        return out
    fit = disc.chosen
    opts, fx = _physics(effect, fit, rec.meta)
    after = _simulate(fit.hexapod, rec, rows, opts, fx)
    out["after_calib_fit"] = rms(after)
    if sysid and effect in _SYSID_PARAMETER:
        import mujoco.sysid as sysid_mod

        name, unit = _SYSID_PARAMETER[effect]
        where = opts if name in opts else fx
        hist = effect == "joint_friction"
        sub = rows if hist or rows.size <= sysid_rows else np.sort(
            np.random.default_rng(seed).choice(rows, sysid_rows, replace=False))
        meas_sub = rec.measured[sub]
        x0 = float(where[name])
        params = sysid_mod.ParameterDict({name: sysid_mod.Parameter(name, x0, x0 / 10 if x0 > 0 else -10 * abs(x0) - 1e-9,
                                                                    x0 * 10 if x0 > 0 else 10 * abs(x0) + 1e-9)})

        def residual_fn(x, _params):
            trial = dict(where)
            trial[name] = float(x[0])
            sim = _simulate(fit.hexapod, rec, sub, trial if where is opts else opts, fx if where is opts else trial,
                            history=hist)
            return [((meas_sub - sim) * w).ravel()], None, None

        import contextlib
        import io

        with contextlib.redirect_stdout(io.StringIO()):  # the scipy backend prints its iterations
            opt, res = sysid_mod.optimize(params, residual_fn, optimizer="scipy", verbose=False,
                                          max_iters=max_nfev, diff_step=1e-3, x_scale="jac")
        xs = float(np.ravel(opt[name].value)[0])
        r_star = residual_fn(np.array([xs]), opt)[0]
        _, intervals = sysid_mod.calculate_intervals(r_star, res.jac)
        where[name] = xs
        after = _simulate(fit.hexapod, rec, rows, opts, fx)
        out["sysid"] = {"parameter": name, "unit": unit, "start": x0, "value": xs,
                        "interval_95": float(np.ravel(intervals)[0]), "evaluations": int(res.nfev),
                        "rows": int(sub.size)}
    out["after"] = rms(after)
    out["machine"] = {"options": {k: (list(v) if isinstance(v, tuple) else v) for k, v in opts.items()},
                      "effects": {k: (list(v) if isinstance(v, tuple) else v) for k, v in fx.items()}}
    return out


def discover(rec: Recording, *, seed: int = 0, heldout_fraction: float = 0.25, resim: bool = True,
             sysid: bool = True, candidates=EFFECTS) -> DiscoveryReport:
    """Run the whole discovery on a recording (see the module docstring)."""
    t0 = time.perf_counter()
    nominal = Hexapod(rec.geometry)
    cal = np.flatnonzero(rec.sets == "calibration")
    data = EffectData(nominal, rec.commanded, rec.measured, rec.t_s, rec.noise)
    disc = discover_effect(data.subset(cal), candidates=candidates, seed=seed)
    kept = cal[disc.kept]
    flagged = [int(cal[i]) for i in disc.flagged]
    disc = Discovery(**{**disc.__dict__, "kept": kept, "flagged": tuple(flagged)})
    val = np.flatnonzero(rec.sets == "validation")
    if val.size:
        held, train = val, kept
        basis = "recorded validation rows"
    else:
        order = np.random.default_rng(seed).permutation(kept.size)
        n_held = max(1, int(round(heldout_fraction * kept.size)))
        held, train = np.sort(kept[order[:n_held]]), np.sort(kept[order[n_held:]])
        basis = f"{int(round(100 * heldout_fraction))}% of the rows held out at random (seed {seed})"
    h = _heldout(data, disc.effect, held, train, disc.chosen.pitch_mm)
    summary = {
        "effect": disc.effect,
        "adequate": disc.adequate,
        "evidence": disc.evidence,
        "heldout_rms_before_mm": h["heldout_rms_before_mm"],
        "heldout_rms_after_mm": h["heldout_rms_after_mm"],
        "noise_floor_mm": h["noise_floor_mm"],
        "heldout_basis": basis,
        "effect_parameters": disc.chosen.named_coefficients(),
        "identified_errors": disc.chosen.hexapod.errors.tolist(),
        "located": disc.located,
        "flagged_poses": flagged,
        "rows": int(rec.commanded.shape[0]),
    }
    truth = rec.meta.get("simulation", {}).get("effect")
    if truth is not None:
        summary["simulated_truth"] = {k: v for k, v in rec.meta["simulation"].items() if k != "injected_errors"}
    if resim:
        t1 = time.perf_counter()
        summary["mujoco_resimulation"] = resimulate(rec, disc, sysid=sysid, seed=seed)
        summary["mujoco_resimulation"]["wall_time_s"] = time.perf_counter() - t1
    summary["wall_time_s"] = time.perf_counter() - t0
    return DiscoveryReport(discovery=disc, summary=summary)


def _words(s: dict) -> list[str]:
    ev = s["evidence"]["geometry_chi2_test"]
    lines = [f"Geometry alone: chi-square {ev['chi2']:.0f} on {ev['dof']} degrees of freedom, p = {ev['p_value']:.3g} "
             f"({'consistent with' if ev['p_value'] > ev['alpha'] else 'NOT explained by'} the declared noise "
             f"by this omnibus test)."]
    lines += ["Where the mismatch is: " + t for t in s["located"]["summary"]]
    if s["flagged_poses"]:
        lines.append(f"Outlier rows (gross errors, not physics), left out: {', '.join(map(str, s['flagged_poses']))}")
    if s["effect"] == "none":
        lines.append("Left-out physics: none. The geometric model explains the recording to the noise.")
    else:
        e = s["evidence"][s["effect"]]
        lines.append(f"Left-out physics: {s['effect']} (BIC {e['delta_bic_vs_none']:+.0f} vs geometry alone; "
                     f"cross-validated whitened RMS {s['evidence']['none']['cv_whitened_rms']:.2f} -> {e['cv_whitened_rms']:.2f}).")
        for k, v in s["effect_parameters"].items():
            lines.append(f"  {k} = {v['value']:.6g} +- {v['std']:.2g} {v['unit']}")
    lines.append(f"Held-out residual RMS: {1e3 * s['heldout_rms_before_mm']:.3f} um -> {1e3 * s['heldout_rms_after_mm']:.3f} um "
                 f"(noise floor {1e3 * s['noise_floor_mm']:.3f} um; {s['heldout_basis']}).")
    r = s.get("mujoco_resimulation")
    if r:
        lines.append(f"MuJoCo machine re-simulated: position RMS {r['before']['position_um']:.3f} um -> {r['after']['position_um']:.3f} um")
        if "sysid" in r:
            y = r["sysid"]
            lines.append(f"  mujoco.sysid re-fit {y['parameter']}: {y['start']:.6g} -> {y['value']:.6g} +- {y['interval_95']:.2g} {y['unit']} (95%)")
    return lines


def _log_rrd(path: Path, rec: Recording, report: DiscoveryReport, overwrite: bool) -> Path:
    import rerun as rr
    import rerun.blueprint as rrb

    from .rerun_log import save_recording

    disc, s = report.discovery, report.summary
    nominal = Hexapod(rec.geometry)
    data = EffectData(nominal, rec.commanded, rec.measured, rec.t_s, rec.noise).subset(disc.kept)
    before = disc.fits["none"].residuals
    after = disc.chosen.residuals

    def log(r):
        r.log("residuals/before_um", rr.SeriesLines(names=[f"leg {i + 1}" for i in range(6)]), static=True)
        r.log("residuals/after_um", rr.SeriesLines(names=[f"leg {i + 1}" for i in range(6)]), static=True)
        for k, j in enumerate(disc.kept):
            r.set_time("measurement", sequence=int(j))
            r.set_time("time", duration=float(rec.t_s[j]))
            r.log("residuals/before_um", rr.Scalars(1e3 * before[k]))
            r.log("residuals/after_um", rr.Scalars(1e3 * after[k]))
            r.log("residuals/rms_um/before", rr.Scalars(float(1e3 * np.sqrt(np.mean(before[k] ** 2)))))
            r.log("residuals/rms_um/after", rr.Scalars(float(1e3 * np.sqrt(np.mean(after[k] ** 2)))))
        r.log("per_leg/rms_before_um", rr.BarChart(1e3 * np.sqrt(np.mean(before ** 2, axis=0))), static=True)
        r.log("per_leg/rms_after_um", rr.BarChart(1e3 * np.sqrt(np.mean(after ** 2, axis=0))), static=True)
        bic = [s["evidence"][e]["delta_bic_vs_none"] for e in EFFECTS]
        r.log("evidence/delta_bic", rr.BarChart(np.array(bic)), static=True)
        r.log("evidence/candidates", rr.TextDocument(", ".join(EFFECTS)), static=True)
        md = "# Discovery\n\n" + "\n".join(f"- {line}" for line in _words(s))
        r.log("summary", rr.TextDocument(md, media_type=rr.MediaType.MARKDOWN), static=True)
        r.log("stroke/direction", rr.BarChart(data.direction.mean(axis=0)), static=True)

    bp = rrb.Blueprint(rrb.Horizontal(
        rrb.Vertical(rrb.TimeSeriesView(origin="residuals/before_um", name="Leg residuals before (um)"),
                     rrb.TimeSeriesView(origin="residuals/after_um", name="Leg residuals after (um)"),
                     rrb.TimeSeriesView(origin="residuals/rms_um", name="Per-measurement RMS (um)")),
        rrb.Vertical(rrb.BarChartView(origin="per_leg/rms_before_um", name="Per-leg RMS before (um)"),
                     rrb.BarChartView(origin="per_leg/rms_after_um", name="Per-leg RMS after (um)"),
                     rrb.BarChartView(origin="evidence/delta_bic", name="Delta BIC per candidate")),
        rrb.TextDocumentView(origin="summary", name="Summary")), collapse_panels=True)
    return save_recording(path, log, overwrite=overwrite, bp=bp)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m pipeline.discover",
        description="Find the physics a hexapod's geometric model leaves out: calibrate the geometry, locate "
                    "the mismatch, name the effect (leg_compliance, joint_friction, thermal_drift, actuator_scale, "
                    "periodic_screw_error or none), fit it, and show the held-out fit improve.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--real", type=Path, required=True, help="recording to analyse (.csv with its .json sidecar)")
    p.add_argument("--seed", type=int, default=0, help="seed of the held-out split and cross-validation folds")
    p.add_argument("--no-resim", action="store_true", help="skip the MuJoCo re-simulation")
    p.add_argument("--no-sysid", action="store_true", help="re-simulate without the mujoco.sysid re-fit")
    p.add_argument("--out", type=Path, default=Path("recordings"), help="folder of the .rrd")
    p.add_argument("--name", default=None, help="base name of the .rrd (default <recording>_discover)")
    p.add_argument("--overwrite", action="store_true", help="allow replacing existing output files")
    p.add_argument("--summary-json", type=Path, default=None, help="write the summary as JSON")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        rec = read_recording(args.real)
        report = discover(rec, seed=args.seed, resim=not args.no_resim, sysid=not args.no_sysid)
        name = args.name or f"{args.real.stem}_discover"
        rrd = _log_rrd(args.out / f"{name}.rrd", rec, report, args.overwrite)
        report.summary["rrd"] = str(rrd)
        if args.summary_json is not None:
            atomic_write(args.summary_json, json.dumps(report.summary, indent=1), overwrite=True)
    except (FileExistsError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for line in _words(report.summary):
        print(line)
    print(f"wrote {report.summary['rrd']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
