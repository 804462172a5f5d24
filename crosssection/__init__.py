"""foldstat.crosssection: from a scan of a cut cross-section to the network of junctions,
stacks, branches and voids, then ensemble statistics.
"""
from ._version import __version__
from .errors import AnalysisError, ConfigError, FoldstatError, ImageError, ParameterError

__all__ = ["__version__", "FoldstatError", "ImageError", "ParameterError", "AnalysisError",
           "ConfigError"]

try:  # the pipeline entry point; kept importable while stages are developed
    from .pipeline import AnalysisResult, analyze  # noqa: F401

    __all__ += ["analyze", "AnalysisResult"]
except ImportError:  # pragma: no cover
    pass
