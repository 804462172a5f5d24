"""crosssection: from a scan of a cut cross-section to the network of junctions,
stacks, branches and voids, then ensemble statistics.

>>> import crosssection
>>> res = crosssection.analyze("scan.png", px_per_mm=50, thickness_mm=0.1)  # doctest: +SKIP
>>> res.summary["n_branches"], res.branches.head()  # doctest: +SKIP

The public names are loaded on first use (PEP 562), so that ``import crosssection`` (and the
simulator, which imports the shared core) does not pay for the whole pipeline's imports.
"""
import importlib
import pkgutil

from crosssection._version import __version__
from crosssection.core.numbacache import use_writable_cache

# before numba is imported: a read-only install run from a read-only home has no cache
# folder otherwise, and every compiled kernel fails (crosssection.core.numbacache)
use_writable_cache()

_LAZY = {
    "analyze": "crosssection.pipeline",
    "AnalysisResult": "crosssection.result",
    "AnalysisParams": "crosssection.params",
    "ScanScale": "crosssection.params",
    "QualityWarning": "crosssection.quality",
    "FoldstatError": "crosssection.core.errors",
    "ImageError": "crosssection.core.errors",
    "ParameterError": "crosssection.core.errors",
    "AnalysisError": "crosssection.core.errors",
    "ConfigError": "crosssection.core.errors",
    "OutputError": "crosssection.core.errors",
}

#: submodules reachable as ``crosssection.<name>`` after ``import crosssection`` alone (the
#: README's ``crosssection.quality.NoCalibrationWarning``), imported on first use
_SUBMODULES = tuple(sorted(m.name for m in pkgutil.iter_modules(__path__)
                           if not m.name.startswith("_")))

__all__ = ["__version__", *_LAZY]


def __getattr__(name):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f"crosssection.{name}")
    raise AttributeError(f"module 'crosssection' has no attribute {name!r}")


def __dir__():
    return sorted([*__all__, *_SUBMODULES])
