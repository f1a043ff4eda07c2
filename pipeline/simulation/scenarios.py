"""Seeded recordings of a simulated robot carrying physical effects (for discovery).

Each recording: the machine's geometric errors, 60 to 120 poses drawn in random order over the
discovery workspace, sensor noise of 1 um (normal, and 1 urad on angles), and effects
(:mod:`calib.effects`; none, one or several at once), each with its largest contribution to the
closure residuals 3 to 10 times the position noise: small enough that the geometric errors absorb
part of it (concealed). Each effect draws its own true instance (:meth:`calib.effects.Effect.scenario`) and says how the MuJoCo
machine produces it (:meth:`calib.effects.Effect.machine_settings`); nothing here depends on
which effect it is.

The MuJoCo machine is reached through one function, :func:`simulate`, and recordings are
made into a :class:`pipeline.recording.Recording` by :func:`make_recording` only (a recording
carries its robot, ``rec.robot``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from calib import paper
from calib.effects import EffectData, MachineContext, effect as registered_effect
from calib.effects.base import PAYLOAD_CHANNEL
from calib.effects.compliance import TWO_PAYLOADS_KG, for_payload
from calib.effects.granularity import GRANULARITIES, PER_CHAIN, per_chain_form
from calib.noise import SensorNoise
from calib.robot import KinematicsError, Robot, check_joint_limits
from calib.robots import default_robot
from mjcf.machine import GRAVITY_M_S2, MachineEffects, MachineOptions
from mjcf.units import M_PER_MM

from pipeline.formats import Recording

__all__ = ["DISCOVERY_NOISE", "ScenarioMachine", "SCENARIO_MACHINES", "scenario_machine",
           "machine_context", "merged_settings", "simulate", "make_recording",
           "effects_settings", "effect_recording", "LawCase", "LAW_CASES", "law_cases_for", "law_recording",
           "TEMPERATURE_CHANNEL", "heldout_targets", "command_scenario_machine", "heldout_payloads"]

#: 1 um on positions, 1 urad on angles (standard deviations).
DISCOVERY_NOISE = SensorNoise(position_mm=0.001, orientation_rad=1e-6, distribution="normal")
#: Time between measurements of the planned schedule, s: a time-dependent effect is drawn on it,
#: and a recording carrying one is measured on it (:func:`effect_recording`).
ESTIMATED_SETTLE_S = 0.35
#: Step cap per pose of a recording at several payloads (:func:`simulate`), 4 times the testbed's.
PAYLOAD_SETTLE_STEPS = 80000
#: Errors of a robot without a :data:`SCENARIO_MACHINES` entry: uniform within +- these on its
#: free parameters (mm, rad), seeded once (the same machine in every recording).
DEFAULT_ERROR_MM, DEFAULT_ERROR_RAD = 0.05, 5e-4


@dataclass(frozen=True)
class ScenarioMachine:
    """The simulated machine of a robot's scenarios.

    Attributes:
        errors: ``errors(robot) -> (P,)`` its geometric errors.
        workspace: ``workspace(robot) -> (D, 2)`` low/high of the poses drawn.
    """

    errors: Callable[[Robot], np.ndarray]
    workspace: Callable[[Robot], np.ndarray]


def _seeded_errors(robot: Robot) -> np.ndarray:
    theta = np.zeros(robot.n_parameters)
    free = robot.table.indices(robot.free_default)
    size = np.where(robot.table.angle_mask()[free], DEFAULT_ERROR_RAD, DEFAULT_ERROR_MM)
    theta[free] = np.random.default_rng(0).uniform(-1.0, 1.0, free.size) * size
    return theta


#: The hexapod of the README's figures: the paper's machine (Table 3 errors) over +-25 mm in x
#: and y, -10..+15 mm in z, +-0.1 rad tilt and +-0.15 rad yaw about its home pose (the paper's
#: own workspace is too narrow to tell effects from geometry). Robots not listed get
#: :func:`_seeded_errors` and their default calibration workspace.
SCENARIO_MACHINES: dict[str, ScenarioMachine] = {
    "hexapod": ScenarioMachine(
        errors=lambda robot: paper.TABLE3_ERRORS.ravel(),
        workspace=lambda robot: robot.home_pose[:, None] + np.array(
            [[-25, 25], [-25, 25], [-10, 15], [-0.1, 0.1], [-0.1, 0.1], [-0.15, 0.15]], dtype=float)),
}


def scenario_machine(robot: Robot) -> ScenarioMachine:
    """The scenario machine of ``robot`` (see :data:`SCENARIO_MACHINES`)."""
    return SCENARIO_MACHINES.get(robot.name, ScenarioMachine(_seeded_errors, lambda r: r.workspace_bounds()))


def machine_context(robot: Robot, moving_mass_kg: float | None = None) -> MachineContext:
    """The numbers that turn effect coefficients into the MuJoCo physics of ``robot``'s machine.

    Args:
        robot: the robot.
        moving_mass_kg: platform plus payload, kg; default the platform of ``robot``'s nominal
            MuJoCo machine (no payload).
    """
    from mjcf import build_machine

    nominal = build_machine(robot, robot.table.nominal)
    platform = nominal.platform_mass_kg
    return MachineContext(
        moving_mass_kg=float(platform if moving_mass_kg is None else moving_mass_kg),
        platform_mass_kg=platform, payload_height_m=MachineOptions().payload_height_m,
        gravity_m_s2=GRAVITY_M_S2, m_per_mm=M_PER_MM, servo_stiffness=float(nominal.servo_stiffness.mean()),
        chain_point_masses_kg=nominal.chain_point_masses_kg)


def merged_settings(context: MachineContext, settings: dict | None = None) -> dict:
    """The machine of ``context`` (its platform mass) with an effect's ``settings`` on top."""
    settings = settings or {}
    return {"options": {"platform_mass_kg": context.platform_mass_kg, **settings.get("options", {})},
            "effects": dict(settings.get("effects", {}))}


# ----------------------------------------------------------------------------- the MuJoCo boundary
# The functions below are the only ones that know the testbed and the recording type.


def simulate(robot: Robot, theta: np.ndarray, joints: np.ndarray, settings: dict, noise: SensorNoise = SensorNoise(),
             seed: int = 0, times_s: np.ndarray | None = None, *, settle_velocity: float | None = None,
             payload_kg: np.ndarray | None = None, max_steps: int | None = None):
    """Measure the MuJoCo machine ``theta`` of ``robot`` at commanded ``joints``.

    Args:
        robot: the robot; theta: (P,) the machine's parameters.
        joints: (N, C) commanded joint values, in order.
        settings: ``{"options": {MachineOptions field: value}, "effects": {MachineEffects
            field: value}}`` (e.g. from :meth:`calib.effects.Effect.machine_settings`).
        noise, seed: sensor noise added to the measured poses, and its seed.
        times_s: (N,) lab times of the measurements (to replay a recording's time axis);
            default the simulated time.
        settle_velocity: at rest below this joint speed (SI); default the testbed's.
        payload_kg: (N,) the payload carried at each row, kg (a payload swapped during the
            recording); default ``settings``' one payload throughout. Each run of rows at one
            payload is measured on the machine carrying it, starting from the previous run's
            last command (the motion history is the recording's), its times following on, and
            settled with :data:`PAYLOAD_SETTLE_STEPS` steps at most per pose (a heavy payload on
            a stiff servo rings longer: the Delta at 4 kg took more than the testbed's default on
            one pose of 1200; the settle velocity, what "at rest" means, is the testbed's).
        max_steps: the testbed's step cap per pose; default the testbed's.

    Returns:
        The testbed's :class:`pipeline.testbed.Measurements` (``t_s``, ``true_poses``, ``measured``, ...).
    """
    if payload_kg is not None:
        return _simulate_payloads(robot, theta, joints, settings, noise, seed, times_s, settle_velocity,
                                  np.asarray(payload_kg, dtype=float))
    from .testbed import Testbed

    options = MachineOptions(**settings.get("options", {}))
    effects = MachineEffects(**settings.get("effects", {}))
    extra = {} if settle_velocity is None else {"settle_velocity": settle_velocity}
    if max_steps is not None:
        extra["max_steps"] = int(max_steps)
    bed = Testbed(robot, theta, options=options, effects=effects, noise=noise, seed=seed, **extra)
    return bed.measure(joints, times_s=times_s)


def _simulate_payloads(robot, theta, joints, settings, noise, seed, times_s, settle_velocity, payload_kg):
    """:func:`simulate` with the payload changing between runs of rows (see its ``payload_kg``)."""
    from .testbed import Measurements

    joints = np.asarray(joints, dtype=float)
    n = joints.shape[0]
    if payload_kg.shape != (n,):
        raise ValueError(f"payload_kg must have shape ({n},), got {payload_kg.shape}")
    starts = np.flatnonzero(np.r_[True, np.abs(np.diff(payload_kg)) > 0])
    ends = np.r_[starts[1:], n]
    parts, t_end = [], 0.0
    for k, (a, b) in enumerate(zip(starts, ends)):
        lead = 1 if a > 0 else 0  # the previous run's last command first: the history carries on
        seg = {"options": {**settings.get("options", {}), "payload_kg": float(payload_kg[a])},
               "effects": dict(settings.get("effects", {}))}
        seg_t = None if times_s is None else np.asarray(times_s, dtype=float)[a - lead:b]
        m = simulate(robot, theta, joints[a - lead:b], seg, noise, seed=seed + k, times_s=seg_t,
                     settle_velocity=settle_velocity, max_steps=PAYLOAD_SETTLE_STEPS)
        t = m.t_s[lead:] if times_s is not None else m.t_s[lead:] - (m.t_s[0] if lead else 0.0) + t_end
        parts.append(Measurements(t, *(getattr(m, f)[lead:] for f in
                                       ("commanded", "settled_joints", "encoders", "true_poses", "measured", "steps"))))
        t_end = float(t[-1])
    return Measurements(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                          ("t_s", "commanded", "settled_joints", "encoders", "true_poses", "measured", "steps")))


def make_recording(robot: Robot, t_s: np.ndarray, joints: np.ndarray, measured: np.ndarray, noise: SensorNoise,
                   meta: dict, sets: np.ndarray | None = None, extras: dict | None = None) -> Recording:
    """A :class:`Recording` of ``robot``'s measurements (``sets`` default all calibration;
    ``extras`` the recorded channels, ``{"temperature_C": (N,)}``)."""
    n = np.asarray(joints).shape[0]
    return Recording(robot=robot, noise=noise, t_s=np.asarray(t_s, dtype=float), joints=np.asarray(joints, dtype=float),
                     measured=np.asarray(measured, dtype=float),
                     sets=np.array(["calibration"] * n) if sets is None else sets, meta=meta, extras=extras or {})


# ----------------------------------------------------------------------------- scenarios


def _draw_poses(robot: Robot, theta: np.ndarray, n: int, rng: np.random.Generator,
                workspace: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(targets, joints)``: n poses drawn uniformly in ``workspace``, each redrawn until the
    nominal inverse kinematics reaches it within the joint limits."""
    low, span = workspace[:, 0], np.ptp(workspace, axis=1)
    targets = low + rng.uniform(size=(n, robot.pose_dim)) * span
    for _ in range(100):
        bad = np.zeros(n, dtype=bool)
        joints = np.full((n, robot.n_chains), np.nan)
        for k in range(n):
            try:
                joints[k] = robot.inverse_kinematics(theta, targets[k:k + 1])[0]
                check_joint_limits(robot, joints[k:k + 1])
            except KinematicsError:
                bad[k] = True
        if not bad.any():
            return targets, joints
        targets[bad] = low + rng.uniform(size=(int(bad.sum()), robot.pose_dim)) * span
    raise ValueError(f"could not draw {n} reachable poses in the workspace {workspace.tolist()}")


def effects_settings(robot: Robot, context: MachineContext, drawn: list) -> dict:
    """The machine settings of several effects together, on the machine of ``context``.

    Args:
        drawn: ``[(effect, coefficients, extra), ...]``.

    An effect that sets the servo stiffness itself (compliance) sets it for every effect: those
    whose settings depend on it (a dead band is a friction force over the stiffness) are
    computed again on the machine with that stiffness.
    """
    def merged(ctx):
        out = {"options": {}, "effects": {}}
        for eff, coef, extra in drawn:
            s = eff.machine_settings(coef, robot, ctx, extra)
            out["options"].update(s.get("options", {}))
            out["effects"].update(s.get("effects", {}))
        return out

    own = [eff.machine_settings(coef, robot, context, extra).get("options", {}).get("actuator_stiffness")
           for eff, coef, extra in drawn]
    own = [k for k in own if k is not None and k != context.servo_stiffness]
    if own:  # one stiffness, or one per chain (a per-chain compliance)
        context = replace(context, servo_stiffness=own[0] if isinstance(own[0], tuple) else float(own[0]))
    return merged_settings(context, merged(context))


def effect_recording(effect, seed: int, *, robot: Robot | str = "hexapod", theta: np.ndarray | None = None,
                     n_poses: int | None = None, magnitude_noise: float | None = None,
                     noise: SensorNoise = DISCOVERY_NOISE, workspace: np.ndarray | None = None,
                     granularity: str = "shared", payloads: int = 1) -> Recording:
    """Simulate a blind recording of ``robot``'s MuJoCo machine with one effect or several.

    Args:
        effect: a registered effect name that applies to the robot, or a sequence of them
            (several effects at once; ``"none"`` or an empty sequence for none).
        seed: seeds everything (poses, effect sizes and instances, noise).
        robot: a robot or a registered name (its nominal geometry is what the recording carries).
        theta: (P,) the machine's true parameters; default the nominal plus the scenario
            machine's errors (:func:`scenario_machine`).
        n_poses: number of poses (default drawn in 60..120).
        magnitude_noise: each effect's largest closure contribution in units of the position
            noise (default drawn in 3..10 for each effect).
        noise: sensor noise.
        workspace: (D, 2) low/high of the poses; default the scenario machine's.
        granularity: ``"shared"`` (every joint the same value: one dead band, one growth rate,
            one stiffness) or ``"per_chain"``: each effect that has a per-chain form
            (:mod:`calib.effects.granularity`) drawn with a per-joint spread (each joint 0.3 to
            1.0 times the largest, random signs where physical) and simulated so, joint by joint.
        payloads: 1 (one payload throughout: the one compliance draws, else the bare platform)
            or 2: the recording is taken at two payloads, a light one and a heavy one
            (:data:`calib.effects.compliance.TWO_PAYLOADS_KG`) swapped three times (four runs of
            rows, light, heavy, light, heavy, so that the swap does not follow time), recorded
            row by row as the channel ``payload_kg`` (:data:`calib.effects.base.PAYLOAD_CHANNEL`);
            the payloads are drawn by their own generator (seeded by ``seed``), the rest as with
            one payload.

    Returns:
        The recording; its ``meta["simulation"]`` holds the truth (errors, each effect's
        coefficients and the machine settings that produced it; ``effect`` is the one effect's
        name, or the names joined by ``+``, ``effects`` the list).
    """
    robot = default_robot(robot) if isinstance(robot, str) else robot
    names = (effect,) if isinstance(effect, str) else tuple(effect)
    effs = [registered_effect(e) for e in names]
    effs = [e for e in effs if e.name != "none"] or [registered_effect("none")]
    for eff in effs:
        if not eff.applies_to(robot):
            raise ValueError(f"effect {eff.name!r} does not apply to the {robot.name}")
    if granularity not in GRANULARITIES:
        raise ValueError(f"granularity must be one of {', '.join(GRANULARITIES)}, got {granularity!r}")
    if payloads not in (1, 2):
        raise ValueError(f"payloads must be 1 or 2, got {payloads!r}")
    machine = scenario_machine(robot)
    nominal = robot.table.nominal
    theta = nominal + machine.errors(robot) if theta is None else np.asarray(theta, dtype=float)
    rng = np.random.default_rng(seed)
    n = int(n_poses) if n_poses is not None else int(rng.integers(60, 121))
    position_std = float(noise.pose_std(("mm",))[0])
    magnitudes = [float(magnitude_noise if magnitude_noise is not None else rng.uniform(3.0, 10.0)) * position_std
                  for _ in effs]
    targets, joints = _draw_poses(robot, nominal, n, rng, machine.workspace(robot) if workspace is None else workspace)
    payload = _two_payloads(n, seed) if payloads == 2 else None
    planned = EffectData(robot, nominal, joints, targets, ESTIMATED_SETTLE_S * np.arange(1, n + 1), noise,
                         payload_kg=payload)
    effs = [for_payload(e, planned) for e in effs]  # compliance with its payload terms
    if granularity == PER_CHAIN:
        effs = [per_chain_form(e) or e for e in effs]
    context = machine_context(robot)
    if payload is not None:
        context = context.with_payload(float(payload.mean()))
    drawn = []
    for eff, magnitude in zip(effs, magnitudes):
        sc = eff.scenario(robot, theta, planned, magnitude, rng, context)
        context = sc.context
        drawn.append((eff, sc.coefficients, sc.extra))
    settings = effects_settings(robot, context, drawn)
    # An effect that follows time was drawn on the planned schedule: the recording keeps it (the
    # simulated settling time differs from machine to machine, e.g. 3 times shorter with a
    # compliant servo, which would shrink a drift, or put a lost count after the last row).
    timed = any(e.follows == "time" for e in effs)
    m = simulate(robot, theta, joints, settings, noise, seed=int(rng.integers(2**31)),
                 times_s=planned.t_s if timed else None, payload_kg=payload)
    truth = _effects_truth(robot, theta - nominal, drawn, magnitudes, settings, payload)
    return make_recording(robot, m.t_s, joints, m.measured, noise,
                          extras=None if payload is None else {PAYLOAD_CHANNEL: payload},
                          meta={"moving_mass_kg": context.moving_mass_kg, "seed": seed, "simulation": truth})


def _effects_truth(robot: Robot, errors: np.ndarray, drawn: list, magnitudes: list, settings: dict,
                   payload: np.ndarray | None) -> dict:
    """An effect recording's ``meta["simulation"]``: the injected errors, each effect drawn
    (``(effect, coefficients, searched value)``) with its size and granularity, the machine's
    settings and the payloads."""
    effs = [eff for eff, _, _ in drawn]
    real = [e for e in effs if e.name != "none"]
    truth = {"robot": robot.name, "injected_errors": errors.tolist(),
             "effect": "+".join(e.name for e in real) or "none", "effects": [e.name for e in real],
             "largest_contribution_mm": max(magnitudes) if real else magnitudes[0],
             "contributions_mm": {e.name: mag for e, mag in zip(effs, magnitudes) if e.name != "none"},
             "coefficients": {c.name: float(v) for eff, coef, _ in drawn for c, v in zip(eff.coefficients(robot), coef)},
             "granularity": {e.name: e.granularity for e in real},
             "machine": settings}
    for eff, _, extra in drawn:
        if eff.searched is not None:
            truth.update({k: v for k, (v, _) in eff.searched_values(extra).items()})
    if payload is not None:
        truth["payloads_kg"] = sorted(set(payload.tolist()))
    return truth


def _two_payloads(n: int, seed: int) -> np.ndarray:
    """(n,) a light and a heavy payload (:data:`TWO_PAYLOADS_KG`) in four runs of rows: light,
    heavy, light, heavy (drawn by a generator of their own)."""
    rng = np.random.default_rng([seed, 2])
    light, heavy = (rng.uniform(*r) for r in TWO_PAYLOADS_KG)
    block = np.arange(n) * 4 // n
    return np.where(block % 2 == 0, light, heavy)


# ----------------------------------------------------------------------------- laws outside the library

#: The recorded channel of the temperature law (a word and its unit, as a recording names it).
TEMPERATURE_CHANNEL = "temperature_C"
#: The lab's air conditioner: mean temperature, range of the cycle's amplitude and period, and
#: the thermometer's noise (degC, s).
LAB_TEMPERATURE_C = 20.0
AIR_CONDITIONER_AMPLITUDE_C = (0.5, 2.0)
AIR_CONDITIONER_PERIOD_S = (12.0, 30.0)
THERMOMETER_NOISE_C = 0.005


def _air_conditioner(t_s: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``(true, recorded)`` temperature, degC: a cycle of seeded amplitude, period and phase."""
    a, p = rng.uniform(*AIR_CONDITIONER_AMPLITUDE_C), rng.uniform(*AIR_CONDITIONER_PERIOD_S)
    true = LAB_TEMPERATURE_C + a * np.sin(2 * np.pi * t_s / p + rng.uniform(0, 2 * np.pi))
    return true, true + THERMOMETER_NOISE_C * rng.standard_normal(t_s.size)


@dataclass(frozen=True)
class LawCase:
    """A law outside the library that a blind recording's joints follow, one constant per joint.

    Attributes:
        terms: the law search's names of its terms (:mod:`calib.effects.laws`): what it must name.
        shape: ``shape(q, centre) -> (N, C)`` each joint's offset per unit constant, joint unit,
            from :func:`calib.effects.laws.joint_quantities` of the commands (``load``: the joint
            force of the statics per unit platform weight; the recorded channels included) and the
            machine's ``centre`` (C,): the middle of the strokes its recording commanded, joint unit.
        physics: the law in words.
        short: every joint falls short of its target (a negative constant); else each joint's
            sign is drawn.
        needs: the quantities it needs (a robot without one of them has no such case).
    """

    terms: tuple
    shape: Callable[[dict, np.ndarray], np.ndarray]
    physics: str
    short: bool = False
    needs: tuple = ()


#: The laws of the blind suite's ``law`` kind (the issue's five): name -> :class:`LawCase`.
LAW_CASES: dict[str, LawCase] = {
    "settle lag": LawCase(("last move",), lambda q, centre: q["last move"],
                          "each joint measured short of its target by a fraction of its last move", short=True),
    "dead band growing with time": LawCase(
        ("sign(last move) * t",), lambda q, centre: q["sign(last move)"] * q["t"],
        "each joint short of its target by a dead band that grows in proportion to time", short=True),
    "friction proportional to load": LawCase(
        ("sign(last move) * load",), lambda q, centre: q["sign(last move)"] * np.abs(q["load"]),
        "each joint short of its target by a friction in proportion to the load it carries", short=True,
        needs=("load",)),
    "scale quadratic in stroke": LawCase(
        ("stroke^2",), lambda q, centre: (q["stroke"] - centre) ** 2,
        "each joint's transmission error quadratic in its stroke about the middle of the strokes commanded (the part "
        "an offset and a scale, which the geometry and the library take, cannot make)"),
    "drift following a recorded temperature": LawCase(
        (TEMPERATURE_CHANNEL,), lambda q, centre: q[TEMPERATURE_CHANNEL] - LAB_TEMPERATURE_C,
        "each joint grows in proportion to the recorded lab temperature (an air conditioner cycling)",
        needs=(TEMPERATURE_CHANNEL,)),
}


def law_cases_for(robot: Robot) -> tuple[str, ...]:
    """The :data:`LAW_CASES` ``robot`` has (the load's law where the statics give a load)."""
    from calib.effects.laws import joint_quantities

    data = EffectData(robot, robot.table.nominal, robot.inverse_kinematics(robot.table.nominal, robot.home_pose[None]),
                      robot.home_pose[None], np.zeros(1), DISCOVERY_NOISE)
    have = set(joint_quantities(data)) | {TEMPERATURE_CHANNEL}
    return tuple(n for n, c in LAW_CASES.items() if set(c.needs) <= have)


def law_recording(name: str, seed: int, *, robot: Robot | str = "hexapod", n_poses: int | None = None,
                  magnitude_noise: float | None = None, noise: SensorNoise = DISCOVERY_NOISE,
                  payloads: int = 1) -> Recording:
    """Simulate a blind recording of ``robot``'s MuJoCo machine whose joints follow the law
    ``name`` of :data:`LAW_CASES` (outside the library of effects), each joint its own constant.

    The poses, machine and noise are :func:`effect_recording`'s; each joint's constant is 0.3 to
    1.0 times the largest (:data:`calib.effects.granularity.SPREAD_RANGE`), scaled so that the
    law's largest closure contribution is ``magnitude_noise`` (default drawn in 3..10) times the
    position noise. The law's offset, computed from the command schedule (the planned times,
    which the recording keeps, and the recorded channels), enters the servo references: the
    machine is commanded to ``joints + offset``, settles under its own physics, and the
    recording holds the commands ``joints`` (the encoders read the command).

    ``payloads=2``: taken at two payloads as :func:`effect_recording`'s (channel ``payload_kg``);
    the law's quantities are the same (its ``load`` the load per unit platform weight, as the
    law search's term), only the machine carries the payloads.

    Returns:
        The recording (``extras`` its recorded channels); ``meta["simulation"]["law"]`` the truth:
        its name, terms, granularity, each joint's constant and its largest contribution.
    """
    from calib.effects.base import SPREAD_RANGE
    from calib.effects.laws import joint_quantities

    robot = default_robot(robot) if isinstance(robot, str) else robot
    if name not in LAW_CASES:
        raise ValueError(f"unknown law {name!r}: expected one of {', '.join(LAW_CASES)}")
    if name not in law_cases_for(robot):
        raise ValueError(f"the law {name!r} needs {', '.join(LAW_CASES[name].needs)}, which the {robot.name} lacks")
    case, machine, nominal = LAW_CASES[name], scenario_machine(robot), robot.table.nominal
    theta = nominal + machine.errors(robot)
    rng = np.random.default_rng(seed)
    n = int(n_poses) if n_poses is not None else int(rng.integers(60, 121))
    magnitude = float(magnitude_noise if magnitude_noise is not None else rng.uniform(3.0, 10.0)) \
        * float(noise.pose_std(("mm",))[0])
    targets, joints = _draw_poses(robot, nominal, n, rng, machine.workspace(robot))
    if payloads not in (1, 2):
        raise ValueError(f"payloads must be 1 or 2, got {payloads!r}")
    payload = _two_payloads(n, seed) if payloads == 2 else None
    planned = EffectData(robot, nominal, joints, targets, ESTIMATED_SETTLE_S * np.arange(1, n + 1), noise,
                         payload_kg=payload)
    temperature, recorded = _air_conditioner(planned.t_s, rng)
    quantities = joint_quantities(planned, {TEMPERATURE_CHANNEL: temperature})
    centre = quantities["stroke"].min(axis=0) + np.ptp(quantities["stroke"], axis=0) / 2
    shape = case.shape(quantities, centre)
    c = rng.uniform(*SPREAD_RANGE, robot.n_chains) * (-1.0 if case.short else rng.choice([-1.0, 1.0], robot.n_chains))
    dF_dq = robot.closure_jacobians(nominal, joints, targets).joints
    c = c * magnitude / np.max(np.abs(dF_dq @ (shape * c)[..., None]))
    context = machine_context(robot)
    m = simulate(robot, theta, joints + shape * c, merged_settings(context), noise, seed=int(rng.integers(2**31)),
                 payload_kg=payload)
    truth = {"robot": robot.name, "injected_errors": (theta - nominal).tolist(), "effect": f"law: {name}",
             "effects": [], "contributions_mm": {}, "granularity": {}, "machine": merged_settings(context),
             "law": {"name": name, "physics": case.physics, "terms": list(case.terms), "granularity": PER_CHAIN,
                     "constants": c.tolist(), "largest_contribution_mm": magnitude,
                     "stroke_centre": centre.tolist()}}
    extras = {TEMPERATURE_CHANNEL: recorded} if TEMPERATURE_CHANNEL in case.needs else {}
    if payload is not None:
        extras[PAYLOAD_CHANNEL] = payload
        truth["payloads_kg"] = sorted(set(payload.tolist()))
    return make_recording(robot, planned.t_s, joints, m.measured, noise, extras=extras,
                          meta={"moving_mass_kg": context.moving_mass_kg, "seed": seed, "simulation": truth})


# ----------------------------------------------------------------------------- commanding it again


def heldout_targets(rec: Recording, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``(targets (n, D), t_s (n,))``: poses drawn in the workspace of ``rec``'s scenario machine
    (other than the recording's: their own seed) and the times of a schedule continuing it."""
    robot = rec.robot
    rng = np.random.default_rng(seed)
    targets, _ = _draw_poses(robot, robot.table.nominal, n, rng, scenario_machine(robot).workspace(robot))
    return targets, ESTIMATED_SETTLE_S * np.arange(1, n + 1)


def command_scenario_machine(rec: Recording, commands: np.ndarray, t_s: np.ndarray,
                             channels: dict | None = None) -> np.ndarray:
    """(N, D) the settled poses (noise-free) of the machine that made the scenario recording
    ``rec`` (:func:`effect_recording` or :func:`law_recording`: its true geometry, effects and law,
    from ``meta["simulation"]``) when ``commands`` are given in order at times ``t_s`` from its
    home pose. A law's offset follows the commands as it did in the recording (its recorded
    ``channels``, one value per row, where it follows one); ``channels["payload_kg"]``: the
    payload the platform carries at each command."""
    from calib.effects.laws import joint_quantities

    robot, truth = rec.robot, rec.meta["simulation"]
    theta = robot.table.nominal + np.asarray(truth["injected_errors"], dtype=float)
    commands = np.asarray(commands, dtype=float)
    law = truth.get("law")
    if law is not None:
        data = EffectData(robot, robot.table.nominal, commands, robot.forward_kinematics(theta, commands), t_s,
                          rec.noise)
        shape = LAW_CASES[law["name"]].shape(joint_quantities(data, channels), np.asarray(law["stroke_centre"]))
        commands = commands + shape * np.asarray(law["constants"])
    timed = law is None and any(registered_effect(e).follows == "time" for e in truth["effects"])
    payload = (channels or {}).get(PAYLOAD_CHANNEL)
    return simulate(robot, theta, commands, truth["machine"], SensorNoise(),
                    times_s=np.asarray(t_s, dtype=float) if timed or payload is not None else None,
                    payload_kg=payload).true_poses


def heldout_payloads(rec: Recording, n: int) -> dict:
    """The channels of ``n`` held-out targets of a recording at several payloads: its lightest
    payload for the first half, its heaviest for the rest (``{"payload_kg": (n,)}``); empty for a
    recording at one payload."""
    payload = rec.extras.get(PAYLOAD_CHANNEL)
    if payload is None:
        return {}
    return {PAYLOAD_CHANNEL: np.where(np.arange(n) < n // 2, np.min(payload), np.max(payload))}
