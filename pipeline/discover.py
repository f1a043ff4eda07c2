"""``python -m pipeline.discover --real FILE``: find the physics the geometric model left out.

Calibrates the geometry, locates where the residuals concentrate, names the left-out effects
(up to three together) from the registry of physical candidates (:mod:`calib.effects`;
``--candidates`` narrows it), fits them jointly with the geometry, says first whether what
remains is consistent with the declared noise and, if not, what it is, where and what it follows;
shows the held-out fit improve, and re-simulates the MuJoCo machine with the effects added (their
own :meth:`~calib.effects.Effect.machine_settings`), re-fitting a physical parameter there with
``mujoco.sysid``. ``--robot NAME --scenario EFFECT[,EFFECT]`` runs it on a seeded simulated
recording instead (:func:`pipeline.simulation.effect_recording`).

Callable from Python as :func:`discover`. Nothing here depends on the robot or the effect.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from calib.effects import (EFFECTS, Discovery, EffectData, EffectFit, closure_noise_std, discover_effects, effect as
                           registered_effect, effects_for, fit_effects)
from calib.robot import Robot
from calib.robots import ROBOTS

from calib.effects.discovery import MIN_NESTED_DELTA_BIC, MIN_ROWS

from .cli import ArgumentParser, check_outputs, cli_main, nonnegative_int
from pipeline.formats import Recording, atomic_write, output_folder, read_recording
from pipeline.simulation import effect_recording, effects_settings, machine_context, merged_settings, simulate

__all__ = ["discover", "DiscoveryReport", "resimulate", "run", "main", "RESIMULATION_SETTLE_VELOCITY",
           "PLOTTED_QUANTITIES", "quantity_values", "verdict_quantity", "discovery_markdown", "verdict_words",
           "report_lines", "write_rrd", "model_words"]

#: At rest to 1e-7 m/s (or rad/s) is ample for micrometre comparisons (the settled pose is then
#: within about 1e-10 m), and several times faster than the testbed's default.
RESIMULATION_SETTLE_VELOCITY = 1e-7


@dataclass
class DiscoveryReport:
    """What :func:`discover` found (``summary`` is the JSON written by ``--summary-json``)."""

    discovery: Discovery
    summary: dict


def _heldout(data: EffectData, chosen: EffectFit, heldout_rows: np.ndarray, train_rows: np.ndarray) -> dict:
    """Held-out closure residual RMS (mm) of geometry only and geometry + the chosen effects,
    both fitted on ``train_rows``, and the noise floor of the held-out residuals."""
    train, test = data.subset(train_rows), data.subset(heldout_rows)
    geo = fit_effects(train, ())
    before = geo.predict(test)[0]
    if chosen.models:
        extras = {m.name: e for m, e in zip(chosen.models, chosen.extras) if e is not None}
        after = fit_effects(train, chosen.models, extras=extras, start=geo.theta).predict(test)[0]
    else:
        after = before
    floor = float(np.sqrt(np.mean(closure_noise_std(data.robot, data.theta, test) ** 2)))
    rms_b = float(np.sqrt(np.mean(before ** 2)))
    rms_a = float(np.sqrt(np.mean(after ** 2)))
    return {"heldout_rms_before_mm": rms_b, "heldout_rms_after_mm": rms_a, "noise_floor_mm": floor,
            "after_over_floor": rms_a / floor, "heldout_rows": [int(i) for i in heldout_rows]}


def _with(settings: dict, section: str, field: str, value: float) -> dict:
    out = {k: dict(v) for k, v in settings.items()}
    out[section][field] = value
    return out


def resimulate(rec: Recording, disc: Discovery, *, sysid: bool = True, max_nfev: int = 5,
               sysid_rows: int = 20, seed: int = 0) -> dict:
    """Re-simulate the recorded commands on MuJoCo machines and compare with the recording.

    Before: the machine with the geometry identified alone. After: the machine with the
    geometry identified jointly with the named effects, and their physics added (their
    ``machine_settings``, together: :func:`pipeline.simulation.effects_settings`); the first
    named effect that names a physical parameter (``physical_parameter``: servo stiffness,
    friction force, drift rate) has it re-fitted in MuJoCo with ``mujoco.sysid`` (confidence
    interval from its Jacobian). The transmission
    effects (scale, screw) enter the joints directly, so their calib-level fit already is the
    machine's parameter and they are simulated as fitted. The re-fit uses at most
    ``sysid_rows`` rows (every row for an effect that depends on the motion history, such as
    friction), since each evaluation re-simulates them.

    Returns:
        JSON-ready dict: task-space RMS of simulated minus recorded poses (um for positions,
        urad for angles), before and after, the machine settings and the re-fitted parameter
        with its 95% interval.
    """
    robot = rec.robot
    rows = disc.kept
    std = rec.noise.pose_std(robot.pose_units)
    angle = robot.angle_pose_mask
    meas = rec.measured[rows]
    context = machine_context(robot, rec.meta.get("moving_mass_kg"))

    def run(theta, settings, which=rows, history=True):
        kw = dict(settle_velocity=RESIMULATION_SETTLE_VELOCITY)
        if not history:
            return simulate(robot, theta, rec.joints[which], settings, times_s=rec.t_s[which], **kw).true_poses
        # Replay the whole record in order (the state may depend on the motion history), keep rows.
        return simulate(robot, theta, rec.joints, settings, times_s=rec.t_s, **kw).true_poses[which]

    def rms(sim):
        d = meas - sim
        return {"position_um": float(1e3 * np.sqrt(np.mean(np.sum(d[:, ~angle] ** 2, axis=1)))),
                "orientation_urad": float(1e6 * np.sqrt(np.mean(np.sum(d[:, angle] ** 2, axis=1))))}

    out = {"before": rms(run(disc.geometry.theta, merged_settings(context)))}
    if not disc.effects:
        out["after"] = out["before"]
        return out
    fit = disc.chosen
    sl = fit.slices()
    settings = effects_settings(robot, context, [(m, fit.coefficients[sl[m.name]], e)
                                                 for m, e in zip(fit.models, fit.extras)])
    after = run(fit.theta, settings)
    out["after_calib_fit"] = rms(after)
    # The first named effect that carries a machine parameter is re-fitted there.
    eff, param = next(((m, m.physical_parameter(robot)) for m in fit.models if m.physical_parameter(robot)),
                      (None, None))
    if sysid and param is not None:
        import mujoco.sysid as sysid_mod

        name = param.field
        hist = eff.history_dependent
        sub = rows if hist or rows.size <= sysid_rows else np.sort(
            np.random.default_rng(seed).choice(rows, sysid_rows, replace=False))
        meas_sub = rec.measured[sub]
        x0 = float(settings[param.section][name])
        low, high = (x0 / 10, x0 * 10) if x0 > 0 else (-10 * abs(x0) - 1e-9, 10 * abs(x0) + 1e-9)
        params = sysid_mod.ParameterDict({name: sysid_mod.Parameter(name, x0, low, high)})

        def residual_fn(x, _params):
            sim = run(fit.theta, _with(settings, param.section, name, float(x[0])), sub, history=hist)
            return [((meas_sub - sim) / std).ravel()], None, None

        with contextlib.redirect_stdout(io.StringIO()):  # the scipy backend prints its iterations
            opt, res = sysid_mod.optimize(params, residual_fn, optimizer="scipy", verbose=False,
                                          max_iters=max_nfev, diff_step=1e-3, x_scale="jac")
        xs = float(np.ravel(opt[name].value)[0])
        r_star = residual_fn(np.array([xs]), opt)[0]
        _, intervals = sysid_mod.calculate_intervals(r_star, res.jac)
        settings = _with(settings, param.section, name, xs)
        after = run(fit.theta, settings)
        out["sysid"] = {"parameter": name, "unit": param.unit, "start": x0, "value": xs,
                        "interval_95": float(np.ravel(intervals)[0]), "evaluations": int(res.nfev),
                        "rows": int(sub.size)}
    out["after"] = rms(after)
    out["machine"] = {section: {k: (list(v) if isinstance(v, tuple) else v) for k, v in values.items()}
                      for section, values in settings.items()}
    return out


def discover(rec: Recording, *, seed: int = 0, heldout_fraction: float = 0.25, resim: bool = True,
             sysid: bool = True, candidates=None) -> DiscoveryReport:
    """Run the whole discovery on a recording (see the module docstring).

    Args:
        rec: the recording.
        seed: seed of the held-out split and of the cross-validation folds.
        heldout_fraction: rows held out when the recording has no ``validation`` rows.
        resim, sysid: re-simulate on the MuJoCo machine, and re-fit there with ``mujoco.sysid``.
        candidates: effect names (or :class:`calib.effects.Effect` objects) to consider; default
            every effect that applies to the robot.

    The summary's ``flagged_poses`` and ``outliers.bad_rows`` are 1-based data rows of the
    recording (the first measurement is row 1).
    """
    t0 = time.perf_counter()
    robot = rec.robot
    if candidates is None:
        candidates = effects_for(robot)
    names = [registered_effect(c).name for c in candidates]
    cal = np.flatnonzero(rec.sets == "calibration")
    val = np.flatnonzero(rec.sets == "validation")
    analysed_all = cal.size < MIN_ROWS <= len(rec.sets)
    if analysed_all:  # too few calibration rows alone: every measured row is evidence of the physics
        cal, val = np.arange(len(rec.sets)), np.zeros(0, dtype=int)
    data = EffectData(robot, robot.table.nominal, rec.joints, rec.measured, rec.t_s, rec.noise)
    disc = discover_effects(data.subset(cal), candidates=candidates, seed=seed)
    kept = cal[disc.kept]
    flagged = [int(cal[i]) for i in disc.flagged]
    disc = replace(disc, kept=kept, flagged=tuple(flagged))
    if val.size:
        held, train = val, kept
        basis = "recorded validation rows"
    else:
        order = np.random.default_rng(seed).permutation(kept.size)
        n_held = max(1, int(round(heldout_fraction * kept.size)))
        held, train = np.sort(kept[order[:n_held]]), np.sort(kept[order[n_held:]])
        basis = f"{int(round(100 * heldout_fraction))}% of the rows held out at random (seed {seed})"
        if analysed_all:
            basis += (f"; every row analysed, calibration and validation alike (the {int((rec.sets == 'calibration').sum())} "
                      f"calibration rows alone are fewer than the {MIN_ROWS} discovery needs)")
    h = _heldout(data, disc.chosen, held, train)
    scan = disc.outliers
    summary = {
        "robot": robot.name,
        "explained": disc.explained,
        "verdict": verdict_words(disc.explained, list(disc.effects), disc.remaining),
        "remaining": disc.remaining,
        "effects": list(disc.effects),
        "partial": list(disc.partial),
        "aliases": disc.aliases,
        "candidates": [n for n in names if n != "none"],
        "effect_parameters": disc.chosen.parameters(),
        "heldout_rms_before_mm": h["heldout_rms_before_mm"],
        "heldout_rms_after_mm": h["heldout_rms_after_mm"],
        "noise_floor_mm": h["noise_floor_mm"],
        "heldout_basis": basis,
        "flagged_poses": [i + 1 for i in flagged],
        "outliers": {"bad_rows": sorted(int(disc.kept[j]) + 1 for j in scan["bad"]),
                     "model_wrong": bool(scan["model_wrong"]),
                     "shared": {str(int(disc.kept[int(j)]) + 1): v for j, v in scan["shared"].items()},
                     "threshold": scan["threshold"], "scale": scan["scale"]},
        "tests": {"noise": disc.tests["noise"], "structure": disc.tests["structure"]},
        "evidence": disc.evidence,
        "identified_errors": robot.table.to_dict(disc.chosen.errors),
        "located": disc.located,
        "rows": int(rec.joints.shape[0]),
    }
    if rec.meta.get("simulation", {}).get("effect") is not None:
        summary["simulated_truth"] = {k: v for k, v in rec.meta["simulation"].items() if k != "injected_errors"}
    if resim:
        t1 = time.perf_counter()
        summary["mujoco_resimulation"] = resimulate(rec, disc, sysid=sysid, seed=seed)
        summary["mujoco_resimulation"]["wall_time_s"] = time.perf_counter() - t1
    summary["wall_time_s"] = time.perf_counter() - t0
    return DiscoveryReport(discovery=disc, summary=summary)


def model_words(effects) -> str:
    """``geometry alone`` or ``geometry + a + b``."""
    return "geometry + " + " + ".join(effects) if effects else "geometry alone"


def verdict_words(explained: bool, effects: list, remaining: dict) -> str:
    """The verdict in one sentence (the first line the terminal prints)."""
    model = model_words(effects)
    if explained:
        return f"Explained: {model} leaves {remaining['summary']}."
    partial = (f" Named but partial: {', '.join(effects)} (structure remains)." if effects and remaining.get("follows")
               else "")
    return f"NOT explained: {model} leaves {remaining['summary']}.{partial}"


def report_lines(s: dict) -> list[str]:
    """The summary in plain words, one finding per line; the verdict first."""
    lines = [s["verdict"]]
    ev = s["evidence"]["geometry_chi2_test"]
    lines.append(f"Geometry alone: chi-square {ev['chi2']:.0f} on {ev['dof']} degrees of freedom, p = {ev['p_value']:.3g} "
                 f"({'consistent with' if ev['p_value'] > ev['alpha'] else 'NOT explained by'} the declared noise "
                 f"by this omnibus test).")
    lines += ["Where the geometry-only mismatch is: " + t for t in s["located"]["summary"]]
    o = s["outliers"]
    if s["flagged_poses"]:
        lines.append(f"Outlier rows (gross and isolated: not shared by neighbours in time, workspace or direction), "
                     f"left out: {', '.join(map(str, s['flagged_poses']))} (1-based data rows)")
    if o["model_wrong"]:
        lines.append(f"{len(o['bad_rows'])} of {s['rows']} rows look bad (more than 5%): the model is wrong, not the "
                     f"data; no row is left out.")
    elif o["shared"]:
        lines.append(f"Rows with large residuals kept as evidence (shared by their neighbours): "
                     f"{'; '.join(k + ' (' + ', '.join(v) + ')' for k, v in o['shared'].items())}")
    named = s["effects"]
    if not named:
        if s["explained"]:
            lines.append("Left-out physics: none. The geometric model explains the recording to the noise.")
        else:
            lines.append(f"Left-out physics: none of the candidates ({', '.join(s['candidates']) or 'none given'}) earns "
                         f"its place; what remains is not explained (see the verdict).")
    else:
        status = "" if s["explained"] else " (partial: the remainder is not explained)"
        lines.append(f"Left-out physics: {' + '.join(named)}{status}; cross-validated whitened RMS "
                     f"{s['evidence']['none']['cv_whitened_rms']:.2f} -> {s['evidence']['cv_whitened_rms_chosen']:.2f}.")
        for name in named:
            params = s["effect_parameters"][name]
            sig = params["significance"]
            e = s["evidence"].get(name, {})
            lines.append(f"  {name}: BIC lower by {e.get('delta_bic_when_added', float('nan')):.0f} when it entered; "
                         f"non-zero at p = {sig['p_value']:.2g} (Wald chi-square {sig['wald_chi2']:.0f} on {sig['dof']})")
            for k, v in params.items():
                if k == "significance":
                    continue
                unc = f" +- {v['std']:.2g}" if np.isfinite(v["std"]) else ""
                lines.append(f"    {k} = {v['value']:.6g}{unc} {v['unit']}")
    for a in s["aliases"]:
        if a.get("nested"):
            lines.append(f"Cannot tell apart on this recording: {a['named']} and {a['rival']}, which contains it "
                         f"(its extra parameters gain {a['delta_bic']:.1f} BIC, less than {MIN_NESTED_DELTA_BIC:.0f}); "
                         f"the simpler {a['named']} fitted.")
            continue
        lines.append(f"Cannot tell apart on this recording: {a['named']} and {a['rival']} (evidence within "
                     f"{a['delta_bic']:.1f} BIC, regressor correlation {a['correlation']:.2f}); {a['named']} fitted.")
    lines.append(f"Held-out residual RMS: {1e3 * s['heldout_rms_before_mm']:.3f} um -> {1e3 * s['heldout_rms_after_mm']:.3f} um "
                 f"(noise floor {1e3 * s['noise_floor_mm']:.3f} um; {s['heldout_basis']}).")
    r = s.get("mujoco_resimulation")
    if r:
        lines.append(f"MuJoCo machine re-simulated: position RMS {r['before']['position_um']:.3f} um -> {r['after']['position_um']:.3f} um")
        if "sysid" in r:
            y = r["sysid"]
            lines.append(f"  mujoco.sysid re-fit {y['parameter']}: {y['start']:.6g} -> {y['value']:.6g} +- {y['interval_95']:.2g} {y['unit']} (95%)")
    return lines


#: The quantities the discovery file always plots the residuals against (the fourth chart is the
#: one the verdict names); names as in :data:`calib.effects.FOLLOWED_QUANTITIES`.
PLOTTED_QUANTITIES = ("time", "stroke", "direction of the last move")


#: Size of each residual plot of the discovery file (2D view units, about pixels at 1600x900).
CHART_W, CHART_H = 600.0, 160.0


def quantity_values(data: EffectData, name: str) -> tuple[np.ndarray, str]:
    """(N, C) values of a quantity the remainder is tested against (``remaining['follows']``,
    an effect's ``follows``: time, the direction or size of each joint's last move, its stroke,
    the load it carries, ``position <coordinate>``) and the axis label that says its unit."""
    robot, n, c = data.robot, data.n, data.robot.n_chains
    unit = robot.joint_unit
    if name == "time":
        span = float(np.ptp(data.t_s)) if n else 0.0
        scale, word = (60.0, "min") if span > 600 else (1.0, "s")
        return np.broadcast_to(data.t_s[:, None] / scale, (n, c)), f"time ({word})"
    if name == "direction of the last move":
        # -1 decreasing, +1 increasing; each side spread by row order so that the points do not pile up.
        spread = 0.6 * (np.arange(n) / max(n - 1, 1) - 0.5)
        return data.direction + spread[:, None], "last move: -1 decreasing, +1 increasing (spread by row)"
    if name == "size of the last move":
        return np.abs(data.last_move), f"size of the last move ({unit})"
    if name == "stroke":
        return data.stroke, f"stroke from the centre of travel ({unit})"
    if name == "load":
        load = EFFECTS["compliance"].joint_regressors(robot, data.theta, data)[..., 0]
        what = "axial share of the platform's weight" if unit == "mm" else "joint torque per unit platform weight (mm)"
        return load, f"load: {what}"
    if name.startswith("position "):
        k = robot.pose_names.index(name.split(" ", 1)[1])
        unit_k = "rad" if robot.angle_pose_mask[k] else "mm"
        return np.broadcast_to(data.measured[:, k:k + 1], (n, c)), f"{name} ({unit_k})"
    raise ValueError(f"unknown quantity {name!r}")


def verdict_quantity(s: dict) -> tuple[str, str]:
    """The quantity the discovery file plots beside time, stroke and direction, and why: what the
    remainder follows, else what a named effect follows, else the quantity whose structure test is
    the strongest (the size of the last move or the load before a pose coordinate)."""
    fixed = set(PLOTTED_QUANTITIES)
    for q in s["remaining"].get("follows", []):
        if q not in fixed:
            return q, "the remainder follows it"
    for e in s["effects"]:
        q = EFFECTS[e].follows
        if q and q not in fixed:
            return q, f"{e} follows it"
    structure = s["tests"]["structure"]  # the physical quantities first, then the pose coordinates
    rest = sorted((q for q in structure if q not in fixed), key=lambda q: (q.startswith("position "),
                                                                         -structure[q]["score"]))
    if rest:
        p = structure[rest[0]]["p_value"]
        return rest[0], f"strongest test left, p = {p:.2g}"
    return "stroke", "no other quantity tested"


def _um(v_mm: float) -> str:
    return f"{1e3 * v_mm:.2f}"


def discovery_markdown(s: dict, chain_word: str = "chain") -> str:
    """The discovery file's summary panel: the verdict first, then short tables."""
    rem = s["remaining"]
    model = model_words(s["effects"])
    lines = [f"# {'Explained' if s['explained'] else 'NOT explained'}", "", s["verdict"], "",
             "| what remains | |", "|---|---|",
             f"| model | {model} |",
             f"| residual RMS | {_um(rem['rms_mm'])} um (noise floor {_um(rem['noise_floor_mm'])} um) |",
             f"| whitened | {rem['noise_ratio']:.2f} x the declared noise |",
             f"| follows | {', '.join(rem['follows']) or 'none of the quantities tested'} |",
             f"| on {chain_word}s | {', '.join(map(str, rem['chains'])) or 'none'} |",
             f"| held-out RMS | {_um(s['heldout_rms_before_mm'])} -> {_um(s['heldout_rms_after_mm'])} um |",
             f"| flagged rows | {', '.join(map(str, s['flagged_poses'])) or 'none'} |"]
    if s["outliers"]["model_wrong"]:
        lines.append(f"| bad rows | {len(s['outliers']['bad_rows'])} of {s['rows']}: model wrong, none left out |")
    if s["effects"]:
        lines += ["", "| effect | coefficient | value | +- | unit |", "|---|---|---|---|---|"]
        for e in s["effects"]:
            for k, v in s["effect_parameters"][e].items():
                if k != "significance":
                    unc = f"{v['std']:.2g}" if np.isfinite(v["std"]) else ""
                    lines.append(f"| {e} | {k} | {v['value']:.4g} | {unc} | {v['unit']} |")
    ev = s["evidence"]
    lines += ["", "| candidate | BIC drop alone | CV RMS | named |", "|---|---|---|---|",
              f"| (geometry) | 0 | {ev['none']['cv_whitened_rms']:.2f} | |"]
    for c in s["candidates"]:
        e = ev.get(c, {})
        lines.append(f"| {c} | {e.get('delta_bic_vs_none', float('nan')):.0f} | "
                     f"{e.get('cv_whitened_rms', float('nan')):.2f} | {'yes' if c in s['effects'] else ''} |")
    lines += ["", "BIC drop: evidence against geometry alone (an effect needs 10 to enter); CV RMS: "
              "cross-validated whitened residual (1 = the noise)."]
    for a in s["aliases"]:
        within = "contains it; the simpler one named" if a.get("nested") else f"within {a['delta_bic']:.1f} BIC"
        lines += ["", f"Cannot tell apart: {a['named']} and {a['rival']} ({within})."]
    r = s.get("mujoco_resimulation")
    if r:
        lines += ["", f"MuJoCo re-simulation, position RMS: {r['before']['position_um']:.2f} -> "
                      f"{r['after']['position_um']:.2f} um."]
    lines += ["", "Geometry alone, where the mismatch is:"] + [f"- {t}" for t in s["located"]["summary"]]
    return "\n".join(lines)


def write_rrd(path: Path, robot: Robot, rec: Recording, report: DiscoveryReport, *, overwrite: bool = False) -> Path:
    """The discovery file: the verdict first, the residuals before and after against time, stroke,
    the direction of the last move and the quantity the verdict names, the candidates' evidence
    by name, flagged rows marked (see docs/rerun_views.md)."""
    import rerun as rr
    import rerun.blueprint as rrb

    from pipeline.views import (application_id, FLAG_COLOR, MACHINE_COLORS, chain_colors, chart_view,
                                log_named_bars, log_residual_scatter, save_recording)

    disc, s = report.discovery, report.summary
    rows = np.union1d(disc.kept, np.asarray(disc.flagged, dtype=int))  # flagged rows drawn too, marked
    data = EffectData(robot, robot.table.nominal, rec.joints, rec.measured, rec.t_s, rec.noise).subset(rows)
    before = 1e3 * disc.geometry.predict(data)[0]
    after = 1e3 * disc.chosen.predict(data)[0]
    flagged = [int(i) for i in np.flatnonzero(np.isin(rows, disc.flagged))]
    chains = [f"{robot.chain_word} {i + 1}" for i in range(robot.n_chains)]
    model = model_words(s["effects"])
    models = ("geometry alone", f"{model}, own scale")
    follows = set(s["remaining"].get("follows", []))
    extra, why = verdict_quantity(s)
    charts = [(q, "the remainder follows it" if q in follows else "") for q in PLOTTED_QUANTITIES] + [(extra, why)]
    candidates = s["candidates"]
    ev = s["evidence"]

    def signed_log(v):
        v = np.asarray(v, dtype=float)
        return np.sign(v) * np.log10(1.0 + np.abs(v))

    def log(r):
        for q, _ in charts:
            x, label = quantity_values(data, q)
            path = f"vs/{q.replace(' ', '_')}"
            log_residual_scatter(r, path, x, before, after, x_label=label, chain_names=chains,
                                 flagged=flagged, rows=rows + 1, models=models, width=CHART_W, height=CHART_H,
                                 same_scale=False)
            # The colour key of the chains under the charts (the same colours as in the run file).
            r.log(f"{path}/chain_key", rr.Points2D([(60 + (CHART_W - 120) * j / max(len(chains) - 1, 1),
                                                     2 * CHART_H + 38)
                                                    for j in range(len(chains))], radii=3.0,
                                                   colors=chain_colors(len(chains)), labels=chains,
                                                   show_labels=True), static=True)
        named = set(s["effects"])
        order = [c for c in candidates if c in named] + [c for c in candidates if c not in named]
        alone = [ev.get(c, {}).get("delta_bic_vs_none", np.nan) for c in order]
        entered = [ev.get(c, {}).get("delta_bic_when_added", np.nan) for c in order]
        log_named_bars(r, "evidence", order, [("alone (vs geometry)", signed_log(alone), (235, 205, 60)),
                                              ("when it entered", signed_log(entered), MACHINE_COLORS["calibrated"])],
                       unit="signed log10(1 + |BIC drop|)", groups=[1 if c in named else 0 for c in order],
                       group_names=["not named", "named (in the model)"], title="Evidence per candidate",
                       note="an effect needs a BIC drop of 10 (1.04 here) and a lower CV residual", name_px=130.0)
        r.log("summary", rr.TextDocument(discovery_markdown(s, robot.chain_word), media_type=rr.MediaType.MARKDOWN),
              static=True)
        r.log("verdict", rr.TextDocument(s["verdict"]), static=True)
        r.log("remaining", rr.TextDocument(json.dumps(s["remaining"], indent=1)), static=True)
        # The RMS of each row's residual on the `measurement` timeline (the recording's 1-based row).
        grey, blue = MACHINE_COLORS["nominal"], MACHINE_COLORS["calibrated"]
        r.log("per_row/rms_um", rr.SeriesLines(names=["geometry alone", model], colors=[grey, blue]), static=True)
        rms = np.c_[np.sqrt(np.mean(before ** 2, axis=1)), np.sqrt(np.mean(after ** 2, axis=1))]
        r.send_columns("per_row/rms_um", indexes=[rr.TimeColumn("measurement", sequence=rows + 1)],
                       columns=rr.Scalars.columns(scalars=rms))
        if flagged:
            r.log("per_row/rms_um/flagged", rr.SeriesPoints(colors=FLAG_COLOR, names="flagged row", marker_sizes=6.0),
                  static=True)
            r.send_columns("per_row/rms_um/flagged", indexes=[rr.TimeColumn("measurement", sequence=rows[flagged] + 1)],
                           columns=rr.Scalars.columns(scalars=rms[flagged, 0]))

    def view(q, note):  # framed on the two plots and the key (the default bounds leave wide margins)
        return rrb.Spatial2DView(origin=f"vs/{q.replace(' ', '_')}",
                                 name=f"Closure residual vs {q}" + (f" ({note})" if note else ""),
                                 background=(18, 18, 18),
                                 visual_bounds=rrb.VisualBounds2D(x_range=[-5.0, CHART_W + 5.0],
                                                                  y_range=[-10.0, 2 * CHART_H + 55.0]))

    views = [view(q, note) for q, note in charts]
    bp = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(rrb.TextDocumentView(origin="summary", name="Verdict and summary"),
                         rrb.Tabs(chart_view("evidence", "Evidence per candidate (BIC drop, named)"),
                                  rrb.TimeSeriesView(origin="per_row/rms_um",
                                                     name="Residual RMS per row (um) vs measurement row")),
                         row_shares=[2, 1]),
            rrb.Vertical(rrb.Horizontal(views[0], views[1]), rrb.Horizontal(views[2], views[3])),
            column_shares=[1.2, 2.6]),
        rrb.TimePanel(timeline="measurement", play_state="paused", state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        collapse_panels=True)
    return save_recording(path, log, application_id=application_id("discover", robot.name), overwrite=overwrite, bp=bp)


def _names(text: str) -> tuple[str, ...]:
    """``"a,b"`` -> ``("a", "b")``, each a registered effect."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    for n in names:
        if n not in EFFECTS:
            raise argparse.ArgumentTypeError(f"unknown effect {n!r}: expected one of {', '.join(EFFECTS)}")
    return names


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="python -m pipeline.discover",
        description="Find the physics a robot's geometric model leaves out: calibrate the geometry, locate "
                    f"the mismatch, name the effect ({', '.join(EFFECTS)}; those that apply to the robot), fit it, "
                    "and show the held-out fit improve.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--real", type=Path, help="recording to analyse (.csv with its .json sidecar)")
    src.add_argument("--scenario", type=_names, metavar="EFFECT[,EFFECT...]",
                     help="analyse a seeded simulated recording of --robot carrying these effects (pipeline.scenarios; "
                          f"comma-separated, from {', '.join(EFFECTS)})")
    p.add_argument("--robot", choices=tuple(ROBOTS), default=None,
                   help="the robot of --scenario (default hexapod); with --real, the robot the file must be of "
                        "(default: the one its sidecar names)")
    p.add_argument("--scenario-seed", type=nonnegative_int, default=0, help="seed of the --scenario recording")
    p.add_argument("--candidates", type=_names, default=None, metavar="EFFECT[,EFFECT...]",
                   help="narrow the library to these effects (comma-separated; default every effect that applies to "
                        "the robot)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the held-out split and cross-validation folds")
    p.add_argument("--no-resim", action="store_true", help="skip the MuJoCo re-simulation")
    p.add_argument("--no-sysid", action="store_true", help="re-simulate without the mujoco.sysid re-fit")
    p.add_argument("--out", type=Path, default=Path("recordings"), help="folder of the .rrd")
    p.add_argument("--name", default=None, help="base name of the .rrd (default <recording>_discover)")
    p.add_argument("--overwrite", action="store_true", help="allow replacing existing output files")
    p.add_argument("--summary-json", type=Path, default=None, help="write the summary as JSON")
    return p


def run(argv: list[str] | None = None) -> DiscoveryReport:
    """Parse ``argv``, analyse, write the ``.rrd`` (and ``--summary-json``), print the report;
    raises on bad input (see :func:`main`)."""
    args = build_parser().parse_args(argv)
    if args.real is not None:
        rec = read_recording(args.real)
        stem = args.real.stem
    else:
        robot_name = args.robot or "hexapod"
        stem = f"{robot_name}_{'+'.join(args.scenario)}_{args.scenario_seed}"
        rec = None
    name = args.name or f"{stem}_discover"
    rrd_path = args.out / f"{name}.rrd"
    # Every output is checked before the analysis (which can take a minute with re-simulation).
    output_folder(args.out)
    check_outputs({"--out": rrd_path, "--summary-json": args.summary_json}, overwrite=args.overwrite)
    if rec is None:
        rec = effect_recording(args.scenario, args.scenario_seed, robot=robot_name)
    robot = rec.robot
    if args.robot is not None and robot.name != args.robot:
        raise ValueError(f"{args.real} is a recording of the {robot.name}, not of the {args.robot} (--robot)")
    report = discover(rec, seed=args.seed, resim=not args.no_resim, sysid=not args.no_sysid,
                      candidates=args.candidates)
    rrd = write_rrd(rrd_path, robot, rec, report, overwrite=args.overwrite)
    report.summary["rrd"] = str(rrd)
    if args.summary_json is not None:
        atomic_write(args.summary_json, json.dumps(report.summary, indent=1), overwrite=args.overwrite)
    for line in report_lines(report.summary):
        print(line)
    print(f"wrote {report.summary['rrd']}")
    return report


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.discover``: exit 2 and one line on a bad input or output."""
    return cli_main(run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
