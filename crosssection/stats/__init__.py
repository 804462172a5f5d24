"""Ensemble statistics of folded configurations (paper sections "Statistical distributions",
"General properties of the network", "Geometrical properties of branches", "Energetical
properties"): maximum-likelihood fits with detection limits, the paper's tables and
relations, and an HTML report (``python -m crosssection stats``).

From Python: ``load_any(folder)`` reads a batch output, an ``analyze`` output or a simulation
ensemble into an :class:`Ensemble` of DataFrames; ``load_report(folder)`` reads a report
folder back; ``plot_pdf(folder_or_ensemble, "e")`` draws a density with its fitted laws.
"""
from crosssection.stats.data import (DetectionLimitWarning, DuplicateScanWarning, Ensemble,
                                     FlaggedScanWarning, IncompleteBatchWarning,
                                     MixedParametersWarning, Report, detect_kind, load_any,
                                     load_batch, load_image_output, load_report,
                                     load_simulation)
from crosssection.stats.families import FAMILIES, Family, register
from crosssection.stats.fits import (PAPER_FAMILIES, FitResult, FitSummary, GoodnessOfFit,
                                     LeftOutWarning, SmallSampleWarning, bootstrap_ci,
                                     fit_all, fit_family, goodness_of_fit, select_model,
                                     truncation_bias)
from crosssection.stats.tables import StatsOptions, StatsResult, compute_stats

__all__ = ["Ensemble", "Report", "load_report", "plot_pdf", "detect_kind", "load_any",
           "load_batch", "load_image_output", "load_simulation", "FAMILIES", "Family", "register", "PAPER_FAMILIES", "FitResult",
           "FitSummary", "GoodnessOfFit", "SmallSampleWarning", "bootstrap_ci", "fit_all",
           "fit_family", "goodness_of_fit", "select_model", "truncation_bias", "StatsOptions",
           "StatsResult", "compute_stats", "DetectionLimitWarning", "DuplicateScanWarning",
           "FlaggedScanWarning", "IncompleteBatchWarning", "MixedParametersWarning",
           "LeftOutWarning"]


def __getattr__(name):
    # the figure function loads matplotlib: only when asked for
    if name == "plot_pdf":
        from crosssection.stats.report import plot_pdf

        return plot_pdf
    raise AttributeError(f"module 'crosssection.stats' has no attribute {name!r}")
