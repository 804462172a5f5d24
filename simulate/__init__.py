"""simulate: the quench simulator of a confined inextensible rod (paper "Statistical
distributions in the folding of elastic structures", section "Numerical simulations"), the
ground truth of its contacts, and renders of its configurations as scans.

Lengths are in units of the rod length L. See ``python -m simulate --help``.
"""
from crosssection._version import __version__

__all__ = ["__version__"]
