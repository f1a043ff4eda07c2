"""The simulated testbed: command leg lengths, let the MuJoCo machine settle, read the
platform pose sensors, add seeded sensor noise.

This is the boundary between the project's units (mm, rad) and MuJoCo's (m): conversions go
through :mod:`mjcf.units` and happen here only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from calib._validate import as_array
from calib.hexapod import Hexapod
from calib.noise import SensorNoise
from calib.rotation import euler_from_quaternion
from mjcf.hexapod import SENSOR_POS, SENSOR_QUAT, HexapodModelOptions, build_hexapod
from mjcf.units import m_to_mm, mm_to_m

__all__ = ["SettleError", "Measurements", "MachineEffects", "HexapodTestbed"]


class SettleError(RuntimeError):
    """The machine did not come to rest within the step cap."""


@dataclass(frozen=True, eq=False)
class Measurements:
    """What the testbed returns for N commanded leg-length sets.

    Attributes:
        t_s: (N,) simulated time at each measurement, s.
        commanded: (N, 6) commanded leg lengths, mm.
        true_poses: (N, 6) settled platform poses before sensor noise, mm and rad.
        measured: (N, 6) measured poses (true + seeded noise), mm and rad.
        steps: (N,) simulation steps each pose took to settle.
    """

    t_s: np.ndarray
    commanded: np.ndarray
    true_poses: np.ndarray
    measured: np.ndarray
    steps: np.ndarray


@dataclass(frozen=True)
class MachineEffects:
    """Non-geometric effects of the simulated machine beyond those of the MJCF options.

    (Gravity, payload, servo stiffness, joint friction and transmission scale are options of
    the model, :class:`mjcf.hexapod.HexapodModelOptions`.)

    Attributes:
        leg_growth_mm_per_s: every leg's body grows at this rate over the simulated time (a
            thermal drift), mm/s; the leg tip in the model moves out by rate x time at the start of
            each move.
        screw_amplitude_mm: (6,) amplitude of each leg's lead-screw error, mm: the nut sits
            ``A_i sin(2 pi stroke / pitch + phase_i)`` from where the encoder says. MuJoCo has no
            periodic transmission element, so the error enters the leg's servo reference.
        screw_phase_rad: (6,) phase of each screw's error, rad.
        screw_pitch_mm: period of the screw error in stroke, mm.
    """

    leg_growth_mm_per_s: float = 0.0
    screw_amplitude_mm: tuple = (0.0,) * 6
    screw_phase_rad: tuple = (0.0,) * 6
    screw_pitch_mm: float = 5.0

    def __post_init__(self) -> None:
        for name in ("screw_amplitude_mm", "screw_phase_rad"):
            v = tuple(float(x) for x in getattr(self, name))
            if len(v) != 6:
                raise ValueError(f"{name} must have 6 values, got {len(v)}")
            object.__setattr__(self, name, v)
        if not self.screw_pitch_mm > 0:
            raise ValueError(f"screw_pitch_mm must be > 0, got {self.screw_pitch_mm!r}")

    def to_dict(self) -> dict:
        return {"leg_growth_mm_per_s": self.leg_growth_mm_per_s, "screw_amplitude_mm": list(self.screw_amplitude_mm),
                "screw_phase_rad": list(self.screw_phase_rad), "screw_pitch_mm": self.screw_pitch_mm}


@dataclass
class HexapodTestbed:
    """A perturbed hexapod simulated in MuJoCo, measured like a metrology lab would.

    Args:
        actual: the machine's true parameter set (nominal geometry + errors), mm.
        options: MuJoCo physics options (gravity, payload, stiffness, friction).
        noise: sensor noise added to the measured poses.
        seed: seed of the sensor noise; the same seed gives the same numbers.
        settle_velocity: at rest when every joint speed is below this, m/s or rad/s.
        max_steps: step cap per pose; beyond it :class:`SettleError` is raised.
        effects: further non-geometric effects (thermal growth, screw error).

    Joint friction is simulated in its quasi-static limit: while a leg moves to a new command
    the Coulomb friction force ``options.joint_friction`` opposes its motion, and a leg
    approached monotonically comes to rest where its servo force equals that friction, short
    of the target by friction / stiffness: a dead band whose sign is the direction in which the
    leg last moved (hysteresis). The force is applied as a joint force in MuJoCo. (MuJoCo's own
    ``frictionloss`` is a soft constraint: it creeps to the target and leaves no dead band.)
    """

    actual: Hexapod
    options: HexapodModelOptions = field(default_factory=HexapodModelOptions)
    noise: SensorNoise = field(default_factory=SensorNoise)
    seed: int = 0
    settle_velocity: float = 1e-9
    max_steps: int = 20000
    effects: MachineEffects = field(default_factory=MachineEffects)

    def __post_init__(self) -> None:
        self.model = build_hexapod(self.actual, self.options)
        self.data = mujoco.MjData(self.model)
        self._rng = np.random.default_rng(self.seed)
        self._home = self.actual.geometry.home_lengths
        self._pos = self.model.sensor(SENSOR_POS)
        self._quat = self.model.sensor(SENSOR_QUAT)
        m = self.model
        self._slide_dof = np.array([m.joint(f"leg{i + 1}_slide").dofadr[0] for i in range(6)])
        self._tip = np.array([m.site(f"leg{i + 1}_tip").id for i in range(6)])
        self._tip_z0 = m.site_pos[self._tip, 2].copy()
        self._last_ctrl = np.zeros(6)
        self._direction = np.zeros(6)
        mujoco.mj_forward(self.model, self.data)

    def _read_pose(self) -> np.ndarray:
        s = self.data.sensordata
        pos = s[self._pos.adr[0]:self._pos.adr[0] + 3]
        quat = s[self._quat.adr[0]:self._quat.adr[0] + 4]
        return np.r_[m_to_mm(pos), euler_from_quaternion(quat)]

    def settle(self, lengths_mm: np.ndarray, at_time_s: float | None = None) -> tuple[np.ndarray, int]:
        """Command one set of leg lengths and step until at rest.

        Args:
            lengths_mm: (6,) commanded leg lengths, mm.
            at_time_s: the (lab) time of this measurement for time-dependent effects; default
                the simulated time.

        Returns:
            ``(pose, steps)``: (6,) settled true pose (mm, rad) and steps taken.

        Raises:
            SettleError: not at rest after ``max_steps`` steps.
        """
        m, d, fx = self.model, self.data, self.effects
        stroke = np.asarray(lengths_mm, dtype=float) - self._home
        screw = np.asarray(fx.screw_amplitude_mm) * np.sin(
            2 * np.pi * stroke / fx.screw_pitch_mm + np.asarray(fx.screw_phase_rad))
        d.ctrl[:] = mm_to_m(stroke + screw)
        move = np.sign(d.ctrl - self._last_ctrl)
        self._direction = np.where(move != 0, move, self._direction)
        self._last_ctrl = d.ctrl.copy()
        d.qfrc_applied[self._slide_dof] = -self.options.joint_friction * self._direction
        # Thermal growth is slow next to settling: the legs take their length at the time the
        # move starts and keep it while the machine settles.
        t = d.time if at_time_s is None else at_time_s
        m.site_pos[self._tip, 2] = self._tip_z0 + mm_to_m(fx.leg_growth_mm_per_s * t)
        for step in range(1, self.max_steps + 1):
            mujoco.mj_step(m, d)
            if step > 5 and np.max(np.abs(d.qvel)) < self.settle_velocity:
                return self._read_pose(), step
        raise SettleError(
            f"the machine did not settle within {self.max_steps} steps "
            f"({self.max_steps * m.opt.timestep:g} s) for commanded lengths "
            f"{np.array2string(np.asarray(lengths_mm), precision=4)} mm: max joint speed "
            f"{np.max(np.abs(d.qvel)):.3g} > {self.settle_velocity:g}")

    def measure(self, commanded: np.ndarray, progress=None, times_s: np.ndarray | None = None) -> Measurements:
        """Command each row of leg lengths in turn, settle, read the sensors, add noise.

        Args:
            commanded: (N, 6) commanded leg lengths, mm.
            progress: optional callable ``progress(done, total)``.
            times_s: (N,) lab times of the measurements (to replay a recording's time axis);
                default the simulated time.
        """
        commanded = as_array(commanded, "commanded", (-1, 6))
        if times_s is not None:
            times_s = as_array(times_s, "times_s", (commanded.shape[0],))
        n = commanded.shape[0]
        true = np.empty((n, 6))
        t = np.empty(n)
        steps = np.empty(n, dtype=int)
        for k in range(n):
            true[k], steps[k] = self.settle(commanded[k], None if times_s is None else times_s[k])
            t[k] = self.data.time if times_s is None else times_s[k]
            if progress is not None:
                progress(k + 1, n)
        measured = true + self.noise.sample(n, self._rng)
        return Measurements(t, commanded.copy(), true, measured, steps)
