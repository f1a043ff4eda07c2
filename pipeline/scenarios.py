"""Seeded recordings of the simulated hexapod carrying one physical effect (for discovery).

Each recording: Table 3 geometric errors in the machine, 60 to 120 poses drawn in random order
over :data:`DISCOVERY_WORKSPACE`, sensor noise of 1 um (normal, and 1 urad on angles), and at
most one effect whose largest leg-length contribution is 3 to 10 times the position noise:
small enough that the geometric errors absorb part of it (concealed).
"""

from __future__ import annotations

import numpy as np

from calib.effects import _compliance_regressors
from calib.hexapod import Hexapod, paper_hexapod, robot_and_theta
from calib.kinematics import inverse_kinematics, leg_vectors
from calib.noise import SensorNoise
from calib.workspace import random_poses
from mjcf.hexapod import DEFAULT_STIFFNESS_N_PER_M, LEG_MASS_KG
from mjcf.machine import GRAVITY_M_S2, MachineEffects, MachineOptions
from mjcf.units import M_PER_MM

from .recording import Recording
from .testbed import Testbed

__all__ = ["DISCOVERY_WORKSPACE", "DISCOVERY_NOISE", "effect_recording"]

#: Workspace of the discovery recordings about the geometry's home pose: +-25 mm in x and y,
#: -10..+15 mm in z, +-0.1 rad tilt, +-0.15 rad yaw (for the paper's machine z is 190..215 mm).
DISCOVERY_WORKSPACE = np.array([[-25, 25], [-25, 25], [-10, 15], [-0.1, 0.1], [-0.1, 0.1], [-0.15, 0.15]], dtype=float)
#: 1 um on positions, 1 urad on angles (standard deviations).
DISCOVERY_NOISE = SensorNoise(position_mm=0.001, orientation_rad=1e-6, distribution="normal")
# Mean simulated time a pose takes to settle, s (used to size the thermal drift beforehand).
_SETTLE_S = 0.35


def effect_recording(effect: str, seed: int, *, nominal: Hexapod | None = None, errors: np.ndarray | None = None,
                     n_poses: int | None = None, magnitude_noise: float | None = None,
                     noise: SensorNoise = DISCOVERY_NOISE) -> Recording:
    """Simulate a blind recording of the MuJoCo hexapod with one effect.

    Args:
        effect: ``none``, ``leg_compliance``, ``joint_friction``, ``thermal_drift``,
            ``actuator_scale`` or ``periodic_screw_error``.
        seed: seeds everything (poses, effect size, noise).
        nominal: nominal parameter set (default the paper's Table 2).
        errors: (6, 7) geometric errors of the machine (default Table 3).
        n_poses: number of poses (default drawn in 60..120).
        magnitude_noise: the effect's largest leg-length contribution in units of the position
            noise (default drawn in 3..10).
        noise: sensor noise.

    Returns:
        The recording; its ``meta["simulation"]`` holds the truth (effect and its size).
    """
    rng = np.random.default_rng(seed)
    nominal = nominal if nominal is not None else paper_hexapod()
    actual = nominal.with_errors(errors if errors is not None else paper_hexapod(with_table3_errors=True).errors)
    n = int(n_poses) if n_poses is not None else int(rng.integers(60, 121))
    mag = float(magnitude_noise if magnitude_noise is not None else rng.uniform(3.0, 10.0)) * noise.std[0]
    targets = nominal.geometry.home_pose + random_poses(n, rng, DISCOVERY_WORKSPACE)
    commanded = inverse_kinematics(nominal, targets)
    stroke = commanded - nominal.geometry.home_lengths
    opts: dict = {}
    fx: dict = {}
    truth: dict = {"effect": effect, "largest_contribution_mm": mag}
    platform_kg = 2.0
    base = MachineOptions()
    if effect == "leg_compliance":
        payload = float(rng.uniform(0.0, 5.0))
        W = (platform_kg + payload) * GRAVITY_M_S2
        # Axial forces at the targets (platform + payload at its height, legs' own weight).
        X = _compliance_regressors(actual, targets)
        h = base.payload_height_m / M_PER_MM / 100.0 * payload / (platform_kg + payload)
        # Legs' own weight along their axes (-u_z per unit weight) adds to their compression.
        legs = leg_vectors(actual, targets)
        uz = legs[..., 2] / np.linalg.norm(legs, axis=-1)
        force = -W * (X[..., 0] + h * X[..., 1]) + LEG_MASS_KG * GRAVITY_M_S2 * uz  # N, compression positive
        k = float(np.abs(force).max() / (mag * M_PER_MM))
        opts = dict(gravity=True, payload_kg=payload, actuator_stiffness=k)
        truth.update(payload_kg=payload, stiffness_n_per_m=k)
    elif effect == "joint_friction":
        F = mag * M_PER_MM * DEFAULT_STIFFNESS_N_PER_M
        opts = dict(joint_friction=F)
        truth.update(friction_n=F, dead_band_mm=mag)
    elif effect == "thermal_drift":
        rate = mag / (n * _SETTLE_S)
        fx = dict(joint_drift_per_s=rate)
        truth.update(growth_rate_mm_per_s=rate)
    elif effect == "actuator_scale":
        u = rng.uniform(0.3, 1.0, 6) * rng.choice([-1.0, 1.0], 6)
        s = u / np.abs(stroke).max(axis=0)
        s *= mag / np.max(np.abs(stroke * s))
        opts = dict(transmission_scale=tuple(s))
        truth.update(scale=s.tolist())
    elif effect == "periodic_screw_error":
        pitch = float(rng.uniform(2.0, 10.0))
        amp = rng.uniform(0.5, 1.0, 6)
        amp *= mag / amp.max()
        phase = rng.uniform(0, 2 * np.pi, 6)
        fx = dict(screw_amplitude=tuple(amp), screw_phase_rad=tuple(phase), screw_pitch=pitch)
        truth.update(pitch_mm=pitch, amplitude_mm=amp.tolist(), phase_rad=phase.tolist())
    elif effect != "none":
        raise ValueError(f"unknown effect {effect!r}")
    options = MachineOptions(platform_mass_kg=platform_kg, **opts)
    robot, theta = robot_and_theta(actual)
    bed = Testbed(robot, theta, options=options, effects=MachineEffects(**fx), noise=noise,
                  seed=int(rng.integers(2**31)))
    m = bed.measure(commanded)
    return Recording(
        geometry=nominal.geometry, noise=noise, t_s=m.t_s, commanded=m.commanded, measured=m.measured,
        sets=np.array(["calibration"] * n),
        meta={"moving_mass_kg": platform_kg + options.payload_kg, "seed": seed,
              "simulation": {"injected_errors": actual.errors.tolist(), **truth}},
    )
