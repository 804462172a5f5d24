"""Ensemble statistics of folded configurations (paper sections "Statistical distributions",
"General properties of the network", "Geometrical properties of branches", "Energetical
properties"): maximum-likelihood fits with detection limits, the paper's tables and
relations, and an HTML report (``python -m crosssection stats``).
"""
from crosssection.stats.data import Ensemble, detect_kind, load_any, load_batch, load_image_output, load_simulation
from crosssection.stats.families import FAMILIES, Family, register
from crosssection.stats.fits import (PAPER_FAMILIES, FitResult, FitSummary, GoodnessOfFit, bootstrap_ci,
                                     fit_all, fit_family, goodness_of_fit, select_model,
                                     truncation_bias)
from crosssection.stats.tables import StatsOptions, StatsResult, compute_stats

__all__ = ["Ensemble", "detect_kind", "load_any", "load_batch", "load_image_output",
           "load_simulation", "FAMILIES", "Family", "register", "PAPER_FAMILIES", "FitResult",
           "FitSummary", "GoodnessOfFit", "bootstrap_ci", "fit_all",
           "fit_family", "goodness_of_fit", "select_model", "truncation_bias", "StatsOptions",
           "StatsResult", "compute_stats"]
