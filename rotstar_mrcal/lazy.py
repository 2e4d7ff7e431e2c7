"""A package's short names, each imported from its module when first used (PEP 562, as scikit-image's lazy_loader)

SYNOPSIS

    # a package's __init__.py
    from rotstar_mrcal.lazy import attach
    __getattr__, __dir__, __all__ = attach(__name__, {"camera": ["preset_model"], "exposure": ["expose"]})

    >>> getattr_, dir_, names = attach("rotstar_mrcal.simulate", {"camera": ["fov_deg"]})
    >>> names, getattr_("fov_deg").__module__
    (['fov_deg'], 'rotstar_mrcal.simulate.camera')

Importing the package imports none of its modules, so a module that imports
a sibling (and with it the package) closes no circle, and a user of one
module does not pay for the others.
"""

from __future__ import annotations

import importlib
import sys


def attach(package: str, names_of: dict[str, list[str]]):
    """(__getattr__, __dir__, __all__) of the package: {module: [name, ...]} its modules' names it shows"""
    where = {name: module for module, names in names_of.items() for name in names}

    def __getattr__(name: str):
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{where[name]}"), name)
        setattr(sys.modules[package], name, value)  # (the next look-up does not come here)
        return value

    def __dir__():
        return sorted(set(where) | set(vars(sys.modules[package])))

    return __getattr__, __dir__, list(where)
