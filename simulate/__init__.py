"""simulate: the quench simulator of a confined inextensible rod (paper "Statistical
distributions in the folding of elastic structures", section "Numerical simulations"), the
ground truth of its contacts, and renders of its configurations as scans.

Lengths are in units of the rod length L. See ``python -m simulate --help``.

>>> import simulate
>>> sim = simulate.load_ensemble("sim/")  # doctest: +SKIP
>>> sim.configs.head()  # doctest: +SKIP

The public names are loaded on first use (PEP 562), as in :mod:`crosssection`.
"""
import importlib
import pkgutil

from crosssection._version import __version__

_LAZY = {
    "load_ensemble": "simulate.load",
    "SimulationEnsemble": "simulate.load",
    "plot_configuration": "simulate.load",
    "analyze_rod": "simulate.contacts",
    "CompactParams": "simulate.compact",
    "CompactResult": "simulate.compact",
    "compact_rod": "simulate.compact",
    "render_configuration": "simulate.render",
    "render_directory": "simulate.render",
    "validate_scenes": "simulate.validate",
}

#: submodules reachable as ``simulate.<name>`` after ``import simulate`` alone
_SUBMODULES = tuple(sorted(m.name for m in pkgutil.iter_modules(__path__)
                           if not m.name.startswith("_")))

__all__ = ["__version__", *_LAZY]


def __getattr__(name):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f"simulate.{name}")
    raise AttributeError(f"module 'simulate' has no attribute {name!r}")


def __dir__():
    return sorted([*__all__, *_SUBMODULES])
