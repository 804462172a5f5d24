"""crosssection: from a scan of a cut cross-section to the network of junctions,
stacks, branches and voids, then ensemble statistics.

>>> import crosssection
>>> res = crosssection.analyze("scan.png", px_per_mm=50, thickness_mm=0.1)  # doctest: +SKIP
>>> res.summary["n_branches"], res.branches.head()  # doctest: +SKIP
"""
from crosssection._version import __version__
from crosssection.core.errors import (AnalysisError, ConfigError, FoldstatError, ImageError,
                                      ParameterError)
from crosssection.params import AnalysisParams, ScanScale
from crosssection.pipeline import AnalysisResult, analyze
from crosssection.quality import QualityWarning

__all__ = ["__version__", "analyze", "AnalysisParams", "ScanScale", "AnalysisResult",
           "QualityWarning", "FoldstatError", "ImageError", "ParameterError", "AnalysisError",
           "ConfigError"]
