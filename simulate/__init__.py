"""foldstat.simulate: the quench simulator of a confined inextensible rod.

Lengths are in units of the rod length L. See ``python -m simulate --help``.
"""
from crosssection._version import __version__

__all__ = ["__version__"]
