"""simulate: the quench simulator of a confined inextensible rod (paper "Statistical
distributions in the folding of elastic structures", section "Numerical simulations"), the
ground truth of its contacts, and renders of its configurations as scans.

Lengths are in units of the rod length L. See ``python -m simulate --help``.

>>> import simulate
>>> sim = simulate.load_ensemble("sim/")  # doctest: +SKIP
>>> sim.configs.head()  # doctest: +SKIP

The public names are loaded on first use (PEP 562), as in :mod:`crosssection`.
"""
import pkgutil

import lazy_loader

from crosssection._version import __version__

_LAZY = {
    "load": ["load_ensemble", "SimulationEnsemble", "plot_configuration"],
    "contacts": ["analyze_rod"],
    "compact": ["CompactParams", "CompactResult", "compact_rod"],
    "render": ["render_configuration", "render_directory"],
    "validate": ["validate_scenes"],
}

#: submodules reachable as ``simulate.<name>`` after ``import simulate`` alone
_SUBMODULES = tuple(sorted(m.name for m in pkgutil.iter_modules(__path__)
                           if not m.name.startswith("_")))

__getattr__, __dir__, _ = lazy_loader.attach(__name__, _SUBMODULES, _LAZY)
__all__ = ["__version__", *(name for names in _LAZY.values() for name in names)]
