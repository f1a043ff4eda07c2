"""Orchestration and I/O: the simulated testbed, recordings, Rerun logging, command lines.

The names below are imported from their modules when first used, so that a command imports only
what it needs (``python -m pipeline.run --help`` loads neither MuJoCo nor Rerun).
"""

from __future__ import annotations

import importlib

__all__ = ["Recording", "RecordingError", "read_recording", "write_recording", "Testbed", "Measurements", "SettleError"]

#: submodule -> the names this package re-exports from it (imported on first use).
_EXPORTS = {
    "recording": ("Recording", "RecordingError", "read_recording", "write_recording"),
    "testbed": ("Testbed", "Measurements", "SettleError"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}


def __getattr__(name: str):
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'pipeline' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_MODULE_OF))
