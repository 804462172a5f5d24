"""crosssection: from a scan of a cut cross-section to the network of junctions,
stacks, branches and voids, then ensemble statistics.

>>> import crosssection
>>> res = crosssection.analyze("scan.png", px_per_mm=50, thickness_mm=0.1)  # doctest: +SKIP
>>> res.summary["n_branches"], res.branches.head()  # doctest: +SKIP

The public names are loaded on first use (PEP 562), so that ``import crosssection`` (and the
simulator, which imports the shared core) does not pay for the whole pipeline's imports.
"""
import pkgutil

import lazy_loader

from crosssection._version import __version__
from crosssection.core.numbacache import use_writable_cache

# before numba is imported: a read-only install run from a read-only home has no cache
# folder otherwise, and every compiled kernel fails (crosssection.core.numbacache)
use_writable_cache()

#: the public names, each imported from its module on first use
_LAZY = {
    "pipeline": ["analyze"],
    "result": ["AnalysisResult"],
    "params": ["AnalysisParams", "ScanScale"],
    "quality": ["QualityWarning"],
    "core.errors": ["FoldstatError", "ImageError", "ParameterError", "AnalysisError",
                    "ConfigError", "OutputError"],
}

#: submodules reachable as ``crosssection.<name>`` after ``import crosssection`` alone (the
#: README's ``crosssection.quality.NoCalibrationWarning``), imported on first use
_SUBMODULES = tuple(sorted(m.name for m in pkgutil.iter_modules(__path__)
                           if not m.name.startswith("_")))

# scikit-image's lazy loading (SPEC 1); ``import *`` takes the public names, not every module
__getattr__, __dir__, _ = lazy_loader.attach(__name__, _SUBMODULES, _LAZY)
__all__ = ["__version__", *(name for names in _LAZY.values() for name in names)]
