"""Package exports imported on first use, so that a command loads only what it needs
(``python -m pipeline.run --help`` loads neither MuJoCo nor Rerun; ``import calib`` loads no
module of it before one is used)."""

from __future__ import annotations

import importlib
import sys

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: dict[str, tuple[str, ...]]):
    """``(__all__, __getattr__, __dir__)`` for ``package``'s ``__init__``: each name of
    ``exports`` (submodule -> names) is imported from its submodule when first read.

    Usage, in a package's ``__init__.py``::

        __all__, __getattr__, __dir__ = lazy_exports(__name__, {"testbed": ("Testbed", ...)})
    """
    module_of = {name: module for module, names in exports.items() for name in names}

    def __getattr__(name: str):
        module = module_of.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__():
        return sorted(set(vars(sys.modules[package])) | set(module_of))

    return sorted(module_of), __getattr__, __dir__
