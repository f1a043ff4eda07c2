"""The simulated machine, in one place: MuJoCo machines of the robots composed with
``mujoco.MjSpec`` from ``calib`` parameter vectors (:mod:`mjcf.machine` and one builder module a
robot), commanded, settled and read by :class:`mjcf.simulator.MachineSimulator` (MuJoCo in SI
metres; the conversion lives in :mod:`mjcf.units`).

Adding a robot: write its builder module (``build_spec(robot, theta, options) -> MjSpec``, the
uncompiled machine with its keyframe, and ``build_machine(robot, theta, options) -> Machine``, its
compiled form: the contract of :mod:`mjcf.machine`) and add one line to :data:`MACHINES`.

MuJoCo and the builder modules are imported when first used: ``import mjcf.units`` does not load
MuJoCo.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING

from .units import M_PER_MM, m_to_mm, mm_to_m

if TYPE_CHECKING:
    from calib.robot import Robot

    from .machine import Machine, MachineOptions

__all__ = ["MACHINES", "build_machine", "build_spec", "Machine", "MachineOptions", "MachineEffects", "GRAVITY_M_S2",
           "MachineSimulator", "SettleError", "M_PER_MM", "m_to_mm", "mm_to_m"]


class _Builders(Mapping):
    """robot name -> builder function, each builder module imported on first use."""

    def __init__(self, modules: dict[str, str]):
        self._modules = dict(modules)

    def __getitem__(self, name: str):
        return self.module(name).build_machine

    def module(self, name: str):
        """The builder module of robot ``name`` (``KeyError`` for an unknown one)."""
        return importlib.import_module(f".{self._modules[name]}", __name__)

    def __iter__(self) -> Iterator[str]:
        return iter(self._modules)

    def __len__(self) -> int:
        return len(self._modules)


#: robot name -> its builder ``build_machine(robot, theta, options) -> Machine`` (module ``mjcf.<name>``,
#: which also has ``build_spec``: :func:`build_spec`).
MACHINES: Mapping = _Builders({
    "hexapod": "hexapod",
    "delta": "delta",
    "rus": "rus",
    "linear_delta": "linear_delta",
})


def _builder_module(robot: Robot):
    try:
        return MACHINES.module(robot.name)
    except KeyError:
        raise KeyError(f"no MuJoCo machine for robot {robot.name!r}: machines exist for "
                       f"{', '.join(sorted(MACHINES))}") from None


def _options(options: MachineOptions | None) -> MachineOptions:
    if options is None:
        from .machine import MachineOptions

        options = MachineOptions()
    return options


def build_spec(robot: Robot, theta, options: MachineOptions | None = None):
    """The machine of ``robot`` with parameters ``theta`` ((P,), mm and rad) as an uncompiled
    ``mujoco.MjSpec`` with its keyframe ``home``: what :func:`build_machine` compiles (the same
    builder module, the same options; default: the defaults).

    Raises:
        KeyError: no builder for this robot (the message lists the registered ones).
    """
    return _builder_module(robot).build_spec(robot, theta, _options(options))


def build_machine(robot: Robot, theta, options: MachineOptions | None = None) -> Machine:
    """The compiled machine of ``robot`` (a :class:`calib.robot.Robot`) with parameters ``theta``
    ((P,), mm and rad), built by the builder registered under ``robot.name``; ``options`` a
    :class:`mjcf.machine.MachineOptions` (default: the defaults).

    Raises:
        KeyError: no builder for this robot (the message lists the registered ones).
    """
    return _builder_module(robot).build_machine(robot, theta, _options(options))


def __getattr__(name: str):
    module = {"Machine": "machine", "MachineOptions": "machine", "MachineEffects": "machine",
              "GRAVITY_M_S2": "machine", "MachineSimulator": "simulator", "SettleError": "simulator"}.get(name)
    if module is not None:
        value = getattr(importlib.import_module(f".{module}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'mjcf' has no attribute {name!r}")
