"""The validation atlas (``benchmark`` subcommand): accuracy and speed of the scan pipeline
charted against the scene, the scan and the method, on scenes with exact truth.

``python -m simulate benchmark --out REPORT [--quick] [--workers W] [--seed S]`` generates
scenes from both generators (the network generator :func:`crosssection.truth.network.make_scene`
and simulator rods rendered by :func:`simulate.render.render_configuration`: short quenches,
and rods compacted by a shrinking wall to the experiments' epsilon), degrades them,
analyses each with :func:`crosssection.analyze` and scores it against its truth with
:func:`crosssection.truth.scoring.score` (junctions matched within 3 h). It writes into REPORT:

- one tidy CSV per sweep (``SWEEP.csv``): the swept parameters, the scene, the accuracy
  (rod length error, junction F1, exact n_br length fraction, mean |n_br error|, void count
  error, total energy error) and the time (analysis wall time, per-stage times of the result's
  ``timings_s``); ``failures.csv`` lists scenes that could not be generated or analysed;
- one chart per sweep (``SWEEP.png``): line charts for the one-dimensional sweeps, stability
  maps (two swept parameters, failure boundary drawn) and accuracy against time for the
  pipeline variants (Pareto front drawn, default marked); ``stage_times.png``;
- ``index.md``: every chart with a one-line reading computed from the numbers, after the
  command line and the package and library versions the numbers were computed with.

Sweeps (every random choice seeded from ``--seed``):

============== ===========================================================================
resolution     sheet thickness h = 2-10 px in the scan (px_per_mm = h / thickness_mm); the
               same physical scene at every h
noise, blur,   pixel noise sigma, Gaussian blur, JPEG quality, plate around the hole,
jpeg, plate,   illumination gradient, colour cast: one at a time on clean scenes
illumination,
cast
layers         mean layers per stack 1-12 (network generator)
stacks         stacks per scene 15-300 (network generator; the largest only in the full run)
epsilon        compaction rate epsilon = L / (2 pi R) = 4-30 (rods of 2000 segments compacted
               by :func:`simulate.compact.compact_rod`, rendered as ``python -m simulate
               render`` renders a compaction: clean, the wall is the hole, h = 5 px)
variants       pipeline options (threshold, curvature, calibration, hole, smoothing, tangent
               length, l_min, thick-crossing merge, skeleton thinning, width statistic,
               integer refinement) one at a time, on the same scenes
               (typical scans: plates, illumination, noise, blur, JPEG, specks, smears)
map_h_layers   h x mean layers (network generator)
map_h_blur     h x blur (both generators)
fits           no scenes: samples of the paper's laws fitted by ``crosssection.stats``, the
               sample size each law needs for a stable model selection and the bias of naive
               fits under l_min and s_min (:mod:`simulate.atlas_fits`, into ``REPORT/fits/``)
============== ===========================================================================

A scene that cannot be analysed (the pipeline raised) is scored as an empty result: rod
length, energy and void count -100 %, junction F1 and exact n_br 0. A scene the generator
cannot build is left out (``failures.csv``).
"""
from __future__ import annotations

import math
import sys
import time
import warnings
import zlib
from concurrent.futures import as_completed
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core.errors import FoldstatError, ParameterError
from crosssection.core.fileio import save_figure, write_csv, write_text

__all__ = ["AtlasConfig", "Variant", "VARIANTS", "SWEEPS", "Rod", "Base", "Treatment",
           "run_atlas", "write_report", "draw_chart", "reading", "plan", "run_base",
           "quench_rod", "render_rod", "compact_scene", "typical_options", "with_backdrop",
           "pareto_front", "add_subparser", "PLATES", "THICKNESS_MM"]

THICKNESS_MM = 0.1  # the paper's sheet; every scene of the atlas uses it
PLATES = ("grey", "dark", "brown", "beige", "bluish", "coloured", None)

# Failure limits of the stability maps and line charts: (column, label, test of failure)
FAILURE = (
    ("n_br_exact_length_fraction", "exact n_br < 0.8", lambda v: v < 0.8),
    ("junction_f1", "junction F1 < 0.9", lambda v: v < 0.9),
    ("total_energy_rel_error", "|energy error| > 20 %", lambda v: abs(v) > 0.2),
)
LIMIT = {"n_br_exact_length_fraction": 0.8, "junction_f1": 0.9, "total_energy_rel_error": 0.2,
         # targets of typical scans (benchmarks/robust_sweep.py)
         "rod_length_rel_error": 0.03, "n_voids_rel_error": 0.05}

# accuracy columns of every sweep CSV (crosssection.truth.scoring names)
METRICS = ("rod_length_rel_error", "junction_f1", "junction_precision", "junction_recall",
           "n_br_exact_length_fraction", "n_br_within1_length_fraction", "n_br_mean_abs_error",
           "n_voids_rel_error", "total_energy_rel_error", "n_stacks_rel_error",
           "stack_match_fraction")


# ----------------------------------------------------------------------------- variants
@dataclass(frozen=True)
class Variant:
    """A pipeline variant: the default with some options changed.

    Attributes
    ----------
    name : str
    overrides : tuple of (str, object)
        Fields of :class:`crosssection.params.AnalysisParams`.
    hole_given : bool
        Pass the scene's hole (False: the pipeline finds it).
    calibration : bool
        Pass the scene's width law (False: the default n h).
    smooth_h, tangent_h : float, optional
        Centreline smoothing window and junction tangent length in units of h (converted to
        ``smooth_px`` and ``tangent_mm`` per scene).
    """

    name: str
    overrides: tuple = ()
    hole_given: bool = True
    calibration: bool = True
    smooth_h: float | None = None
    tangent_h: float | None = None

    def analysis_kwargs(self, h_px: float) -> dict:
        """The AnalysisParams overrides of this variant for a scene of h = ``h_px``."""
        kw = dict(self.overrides)
        if self.smooth_h is not None:
            kw["smooth_px"] = int(max(1, round(self.smooth_h * h_px)) // 2 * 2 + 1)
        if self.tangent_h is not None:
            kw["tangent_mm"] = self.tangent_h * THICKNESS_MM
        return kw


DEFAULT = Variant("default")
# one option changed at a time (plus the paper's own combination); defaults: auto threshold,
# missing-data curvature, calibration and hole given, smoothing 2 h + 1, tangent 3 h,
# l_min 1 mm, thick crossings merged, the package's thinning, median width, integer
# refinement on
VARIANTS = (
    DEFAULT,
    Variant("threshold otsu", (("threshold_method", "otsu"),)),
    Variant("threshold fixed", (("threshold_method", "fixed"),)),
    Variant("curvature paper", (("curvature_method", "paper"),)),
    Variant("paper method", (("threshold_method", "fixed"), ("curvature_method", "paper"))),
    Variant("no calibration", calibration=False),
    Variant("hole fitted", hole_given=False),
    Variant("smoothing 1 h", smooth_h=1.0),
    Variant("smoothing 4 h", smooth_h=4.0),
    Variant("tangent 1.5 h", tangent_h=1.5),
    Variant("tangent 6 h", tangent_h=6.0),
    Variant("l_min 0.5 mm", (("l_min_mm", 0.5),)),
    Variant("l_min 2 mm", (("l_min_mm", 2.0),)),
    Variant("thick crossings kept", (("merge_thick_crossings", False),)),
    Variant("skeleton skimage", (("skeleton_method", "skimage"),)),
    Variant("width mean", (("width_statistic", "mean"),)),
    Variant("no integer refinement", (("integer_refinement", False),)),
)
VARIANT_NAMES = tuple(v.name for v in VARIANTS)


# ----------------------------------------------------------------------------- sweeps
@dataclass(frozen=True)
class SweepInfo:
    """How a sweep is charted: its kind, axes and title."""

    kind: str                      # "line", "map" or "variants"
    x: str = ""                    # swept column
    xlabel: str = ""
    title: str = ""
    y: str = ""                    # second swept column (maps)
    ylabel: str = ""
    plot_x: str = ""               # column plotted on x instead of x (realised values)
    log_x: bool = False
    reverse_x: bool = False
    categorical: bool = False
    scale: float = 1.0             # x display factor (fractions shown in %)


SWEEPS = {
    "resolution": SweepInfo("line", "h_px", "sheet thickness h in the scan (px)",
                            "Resolution: accuracy and time against the sheet thickness in "
                            "pixels"),
    "noise": SweepInfo("line", "noise_sigma", "pixel noise sigma (grey levels of 255)",
                       "Pixel noise: accuracy and time against the noise level"),
    "blur": SweepInfo("line", "blur_px", "Gaussian blur sigma (px)",
                      "Blur: accuracy and time against the blur of the scan"),
    "jpeg": SweepInfo("line", "jpeg_quality", "JPEG quality (100 = lossless PNG)",
                      "JPEG compression: accuracy and time against the JPEG quality",
                      reverse_x=True),
    "plate": SweepInfo("line", "plate", "plate around the hole",
                       "Plate around the hole: accuracy and time for each plate colour",
                       categorical=True),
    "illumination": SweepInfo("line", "illumination",
                              "illumination gradient (largest deviation, %)",
                              "Uneven illumination: accuracy and time against its amplitude",
                              scale=100.0),
    "cast": SweepInfo("line", "cast", "colour cast (largest gain deviation per channel, %)",
                      "Colour cast: accuracy and time against its amplitude", scale=100.0),
    "layers": SweepInfo("line", "mean_layers", "mean layers per stack (realised, truth)",
                        "Stack thickness: accuracy and time against the mean number of "
                        "layers per stack", plot_x="truth_mean_n_br"),
    "stacks": SweepInfo("line", "n_stacks", "stacks per scene (realised, truth)",
                        "Scene size: accuracy and time against the number of stacks",
                        plot_x="truth_n_stacks", log_x=True),
    "epsilon": SweepInfo("line", "epsilon", "compaction rate epsilon = L / (2 pi R)",
                         "Compaction rate: accuracy and time against epsilon (simulator rods "
                         "compacted in a shrinking wall)"),
    "variants": SweepInfo("variants", "variant", "",
                          "Pipeline variants: accuracy against analysis time on the same "
                          "scans"),
    "map_h_layers": SweepInfo("map", "h_px", "sheet thickness h (px)",
                              "Stability map: resolution x layers per stack (median per cell; "
                              "failing cells hatched, boundary drawn)",
                              y="mean_layers", ylabel="mean layers per stack (target)"),
    "map_h_blur": SweepInfo("map", "h_px", "sheet thickness h (px)",
                            "Stability map: resolution x blur (median per cell; failing cells "
                            "hatched, boundary drawn)", y="blur_px",
                            ylabel="Gaussian blur sigma (px)"),
}
DEGRADATIONS = ("noise", "blur", "jpeg", "plate", "illumination", "cast")
FITS = "fits"  # the statistics sweep (simulate/atlas_fits.py): no scenes
ALL_SWEEPS = (*SWEEPS, FITS)


@dataclass(frozen=True)
class AtlasConfig:
    """Sizes of the atlas: swept values and scenes per value.

    ``rods`` quenched rods (``rod_segments`` segments, ``rod_runs`` Powell runs of at most
    ``rod_maxiter`` iterations) are rendered wherever a sweep uses the simulator; the other
    counts are network scenes (seeds) or rods per swept value. The ``epsilon`` sweep compacts
    ``epsilon_configs`` rods of ``epsilon_segments`` segments to every value of ``epsilon``
    (the same initial shapes at every epsilon).
    """

    name: str
    rods: int = 4
    rod_segments: int = 300
    rod_runs: int = 10
    rod_maxiter: int = 30
    base_stacks: int = 40
    base_max_layers: int = 6
    resolution_h: tuple = (2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0)
    resolution_seeds: int = 5
    resolution_rods: int = 4
    noise: tuple = (0.0, 5.0, 10.0, 20.0, 30.0, 45.0)
    blur: tuple = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0)
    jpeg: tuple = (None, 95, 85, 75, 60, 45, 30)
    plates: tuple = (None, "grey", "dark", "brown", "beige", "bluish", "coloured")
    illumination: tuple = (0.0, 0.05, 0.1, 0.15, 0.2, 0.3)
    cast: tuple = (0.0, 0.03, 0.06, 0.1)
    degradation_seeds: int = 6
    degradation_rods: int = 4
    layers: tuple = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0)
    layers_seeds: int = 4
    layers_stacks: int = 30
    stacks: tuple = (15, 20, 40, 80, 150, 300)
    stacks_seeds: int = 4
    large_stacks: int = 150          # from this size on, only large_seeds scenes
    large_seeds: int = 2
    # the experiments' sets sit at epsilon 8-19 (Table 1 of the paper); 4 is as far as the
    # quench gets, 30 beyond any set. 2000 segments is the compaction's default (its
    # energies converged); fewer run into a level's iteration cap more often (N = 1000 at
    # epsilon 8, 400-800 at epsilon 4).
    epsilon: tuple = (4.0, 8.0, 14.0, 19.0, 30.0)
    epsilon_configs: int = 3
    epsilon_segments: int = 2000
    variant_seeds: int = 8
    variant_rods: int = 4
    variant_max_stacks: int = 100
    variant_names: tuple | None = None   # None: every variant of VARIANTS
    map_h: tuple = (2.0, 2.5, 3.0, 4.0, 6.0)
    map_layers: tuple = (1.5, 3.0, 6.0, 12.0)
    map_blur: tuple = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0)
    map_seeds: int = 3
    map_rods: int = 3
    map_stacks: int = 30

    @classmethod
    def full(cls) -> "AtlasConfig":
        """The atlas of ``docs/validation/atlas``: about 20-30 minutes on 2 cores for the
        scene sweeps, plus about 5 minutes for the compactions of the epsilon sweep and about
        an hour for the fits sweep (``--sweeps`` picks)."""
        return cls("full")

    @classmethod
    def quick(cls) -> "AtlasConfig":
        """A handful of small scenes per sweep: every CSV and chart in a few minutes at most."""
        return cls("quick", rods=1, rod_segments=200, rod_runs=4, rod_maxiter=20,
                   base_stacks=15, base_max_layers=4, resolution_h=(2.0, 3.0, 5.0, 8.0),
                   resolution_seeds=1, resolution_rods=1, noise=(0.0, 20.0, 45.0),
                   blur=(0.0, 1.5, 3.0), jpeg=(None, 60, 30), plates=(None, "grey", "dark"),
                   illumination=(0.0, 0.15, 0.3), cast=(0.0, 0.1), degradation_seeds=1,
                   degradation_rods=1, layers=(1.5, 4.0, 8.0), layers_seeds=1,
                   layers_stacks=15, stacks=(15, 20, 40), stacks_seeds=1, large_stacks=1000,
                   epsilon=(4.0,), epsilon_configs=1, epsilon_segments=600, variant_seeds=2,
                   variant_rods=1, variant_max_stacks=25, map_h=(2.0, 4.0),
                   map_layers=(1.5, 4.0), map_blur=(0.0, 2.0), map_seeds=1, map_rods=1,
                   map_stacks=15)

    @classmethod
    def tiny(cls) -> "AtlasConfig":
        """The smallest atlas that still draws every chart (tests)."""
        return replace(cls.quick(), name="tiny", rod_segments=150, rod_runs=4, rod_maxiter=10,
                       resolution_h=(2.0, 5.0), noise=(0.0, 45.0), blur=(0.0, 3.0),
                       jpeg=(None, 30), plates=(None, "dark"), illumination=(0.0, 0.3),
                       cast=(0.0, 0.1), layers=(1.5, 4.0), stacks=(15, 20),
                       epsilon=(3.0,), epsilon_segments=300, variant_seeds=1,
                       variant_names=("default", "threshold otsu", "curvature paper",
                                      "hole fitted"), degradation_rods=0, map_rods=0)


# ----------------------------------------------------------------------------- scenes
def typical_options(rng: np.random.Generator) -> dict:
    """Generator and backdrop options of a typical scan (benchmarks/robust_sweep.py).

    20-150 stacks, 3-12 layers at most, noise <= 10, blur <= 1.5 px, JPEG 75, 90 or none,
    specks, smears, pinholes; a plate (or none), illumination gradient <= 15 %, colour cast
    <= 6 %, a dark rim or none. The draws are in a fixed order so a seed gives one scene.

    Parameters
    ----------
    rng : numpy.random.Generator

    Returns
    -------
    dict
        ``scene`` (keyword arguments of :func:`crosssection.truth.network.make_scene`, with
        ``px_per_mm`` 50) and ``backdrop`` (of
        :func:`crosssection.truth.backdrop.apply_backdrop`, ``plate`` included).
    """
    # these ranges are the validated ones a render is checked against: one source
    from simulate.render import VALIDATED_BLUR_PX, VALIDATED_JPEG_QUALITY, VALIDATED_NOISE_SIGMA

    opts = dict(n_stacks=int(rng.integers(20, 151)), max_layers=int(rng.choice([3, 6, 9, 12])),
                noise_sigma=float(rng.uniform(0, VALIDATED_NOISE_SIGMA)),
                blur_px=float(rng.uniform(0, VALIDATED_BLUR_PX)),
                jpeg_quality=[None, VALIDATED_JPEG_QUALITY, 90][int(rng.integers(3))],
                specks=int(rng.integers(0, 20)), smears=int(rng.integers(0, 5)),
                pinholes=int(rng.integers(0, 10)), px_per_mm=50.0)
    backdrop = dict(plate=PLATES[int(rng.integers(len(PLATES)))],
                    illumination=float(rng.uniform(0, 0.15)), cast=float(rng.uniform(0, 0.06)),
                    rim_px=float(rng.choice([0.0, 2.0])))
    return {"scene": opts, "backdrop": backdrop}


def with_backdrop(scene, rng: np.random.Generator, *, plate=None, illumination: float = 0.0,
                  cast: float = 0.0, rim_px: float = 0.0):
    """The scene with a plate around its hole, uneven illumination and a colour cast.

    Parameters
    ----------
    scene : crosssection.truth.scene.Scene
        Must have a hole (``params["hole_radius_mm"]``).
    rng : numpy.random.Generator
    plate, illumination, cast, rim_px
        As :func:`crosssection.truth.backdrop.apply_backdrop`.

    Returns
    -------
    Scene
        A copy with the new ``rgb``.
    """
    from crosssection.truth.backdrop import apply_backdrop

    p = scene.params
    cx, cy = p["hole_center_px"]
    ink = scene.ink_mask
    if ink is None:
        # the network generator keeps no ink mask; its ink lies inside the hole, which the
        # plate never covers
        ink = np.zeros(scene.rgb.shape[:2], bool)
    rgb = apply_backdrop(scene.rgb, ink_mask=ink, hole_center_rc=(cy, cx),
                         hole_radius_px=p["hole_radius_mm"] * p["px_per_mm"], rng=rng,
                         plate=plate, illumination=illumination, cast=cast, rim_px=rim_px)
    return replace(scene, rgb=rgb)


def quench_rod(seed: int, *, n_segments: int = 300, n_runs: int = 10, maxiter: int = 30):
    """A short quench of one random rod (the Powell protocol, Lambda = 7e5).

    Parameters
    ----------
    seed : int
        Seed of the initial shape and of the minimiser.
    n_segments, n_runs, maxiter : int
        Rod discretisation and the protocol's length (the paper's runs are much longer: these
        configurations are folded enough to have junctions and stacks of several layers).

    Returns
    -------
    (N+1, 2) array
        Node positions, units of the rod length.
    """
    from simulate.ensemble import minimize_config
    from simulate.noise import initial_shape

    from simulate.energy import LAMBDA
    from simulate.noise import NOISE
    from simulate.optimize import FTOL, NEMATIC_RUNS, NEMATIC_U, XTOL

    params = dict(command="quench", n_runs=n_runs, maxiter=maxiter,
                  nematic_runs=list(NEMATIC_RUNS), u=NEMATIC_U, ftol=FTOL, xtol=XTOL,
                  wall_radius=None, lam=LAMBDA, method="powell", parametrization=None)
    xy0 = initial_shape(n_segments, NOISE, seed=np.random.default_rng(seed))
    return minimize_config(xy0, params, seed).xy


#: The atlas's renders: clean drawings (it adds its own defects and plates), stacks shorter
#: than two rod segments drawn as the analysis' polylines.
RENDER_STYLE = {"clean": True, "smooth": "long"}


def render_rod(xy, seed: int, analysis=None, **kwargs):
    """Render a rod configuration as a scan (warnings of the renderer silenced).

    :data:`RENDER_STYLE` unless ``kwargs`` say otherwise.

    Parameters
    ----------
    xy : (N+1, 2) array
    seed : int
        Seed of the rendering's random choices.
    analysis : simulate.contacts.RodAnalysis, optional
        Contact analysis (computed when omitted).
    **kwargs
        Of :func:`simulate.render.render_configuration`.

    Returns
    -------
    Scene
    """
    from simulate.render import render_configuration

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return render_configuration(xy, analysis, seed=seed, **{**RENDER_STYLE, **kwargs})


@dataclass(frozen=True)
class Rod:
    """A quenched rod, its contact analysis and the rod length of its scans.

    ``rod_length_mm`` is chosen by the renderer at 50 px/mm (a visible gap between passes
    beyond contact) and then kept at every resolution: one physical sheet, scanned coarser or
    finer.
    """

    index: int
    seed: int
    xy: np.ndarray = field(repr=False)
    analysis: object = field(repr=False)
    rod_length_mm: float


def make_rod(index: int, seed: int, config: AtlasConfig, xy=None) -> Rod:
    """Quench rod ``index`` (or take the given node positions ``xy``) and fix its scan scale
    (a worker task)."""
    from simulate.contacts import analyze_rod
    from simulate.energy import LAMBDA

    if xy is None:
        xy = quench_rod(seed, n_segments=config.rod_segments, n_runs=config.rod_runs,
                        maxiter=config.rod_maxiter)
    xy = np.asarray(xy, float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        analysis = analyze_rod(xy, lam=LAMBDA)
    ref = render_rod(xy, seed, analysis, px_per_mm=50.0, thickness_mm=THICKNESS_MM,
                     hole_radius_mm="auto")
    return Rod(index, seed, xy, analysis, float(ref.params["rod_length_mm"]))


def compact_scene(epsilon: float, n_segments: int, seed: int, *, px_per_mm: float = 50.0):
    """A rod compacted to ``epsilon`` by a shrinking wall, rendered as a clean scan.

    The conventions of ``python -m simulate render`` on a compaction folder
    (:func:`simulate.render.render_directory`): contact analysis with ``lam = 0`` (a hard wall
    stores no energy) and contact distance :data:`simulate.compact.CONTACT_DISTANCE` h, the
    scale set by the rod's thickness (h = ``THICKNESS_MM``), the wall drawn as the hole,
    every stack along its smooth curve (short links included).

    Parameters
    ----------
    epsilon : float
        Compaction rate ``L / (2 pi R)``.
    n_segments : int
        Segments of the rod.
    seed : int
        Seed of the initial shape and of the rendering.
    px_per_mm : float
        Scan resolution.

    Returns
    -------
    Scene
        ``params["hold_force"]``: the compaction's final largest node force over
        ``2 ds / R^3`` (the hold converged when it is below ``CompactParams.ftol``).

    Raises
    ------
    AnalysisError
        If the compaction did not converge (:func:`simulate.compact.compact_rod`).
    """
    from simulate.compact import CONTACT_DISTANCE, CompactParams, compact_rod
    from simulate.contacts import analyze_rod

    with warnings.catch_warnings():
        # an unconverged final hold is recorded with the scene (params "hold_force", the
        # atlas table's column) rather than printed by a worker
        warnings.simplefilter("ignore", RuntimeWarning)
        res = compact_rod(CompactParams(epsilon=float(epsilon), n_segments=int(n_segments)),
                          np.random.default_rng(seed))
    h = res.thickness
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        analysis = analyze_rod(res.xy, lam=0.0, contact_distance=CONTACT_DISTANCE * h)
    # smooth="all": the short links between close junctions drawn as parabolas, as the
    # renders of compactions are drawn and measured (docs/validation/compact.md)
    scene = render_rod(res.xy, seed, analysis, rod_thickness=h, wall_radius=res.wall_radius,
                       hole_radius_mm="auto", px_per_mm=px_per_mm, thickness_mm=THICKNESS_MM,
                       smooth="all")
    # the final hold's largest force over its scale (converged below CompactParams.ftol)
    scene.params["hold_force"] = float(res.stats["force"])
    return scene


@dataclass(frozen=True)
class Base:
    """One generated scene, before the treatments (degradations, variants) applied to it.

    Attributes
    ----------
    sweep : str
        The sweep it belongs to (the degradation sweeps share their bases).
    generator : str
        ``"network"``, ``"render"`` (a quenched rod) or ``"compact"`` (a rod compacted in the
        task, :func:`compact_scene`).
    seed : int
    h_px : float
        Sheet thickness in pixels (px_per_mm = h_px / THICKNESS_MM).
    options : tuple of (str, object)
        Network: keyword arguments of ``make_scene``; render: ``smears``, ``specks``,
        ``pinholes``; compact: ``epsilon``, ``n_segments``.
    rod : int
        Rod index (renders).
    labels : tuple of (str, object)
        Swept values fixed by the base (h_px, mean_layers, n_stacks).
    """

    sweep: str
    generator: str
    seed: int
    h_px: float
    options: tuple = ()
    rod: int = -1
    labels: tuple = ()

    @property
    def px_per_mm(self) -> float:
        return self.h_px / THICKNESS_MM

    def cost(self) -> float:
        """Rough generation cost (to start the longest tasks first)."""
        o = dict(self.options)
        area = (self.h_px / 5.0) ** 2
        if self.generator == "render":
            return 40.0 * area
        if self.generator == "compact":
            # 10-20 CPU s of compaction at N = 2000, then 0.3-4 s of contact analysis and 1-5 s
            # of rendering, growing with epsilon: far above any other scene
            return 0.5 * o.get("n_segments", 2000) * (1.0 + o.get("epsilon", 10.0) / 20.0)
        return area * o.get("n_stacks", 40) * (1.0 + (o.get("mean_layers") or 2.0))


@dataclass(frozen=True)
class Treatment:
    """What is done to a base scene before and during its analysis.

    Attributes
    ----------
    sweep : str
        The sweep (CSV) its row goes to.
    labels : tuple of (str, object)
        Swept values it sets.
    plate, illumination, cast, rim_px
        Backdrop (:func:`with_backdrop`); nothing when all are unset.
    noise_sigma, blur_px, jpeg_quality
        Scan degradations after the backdrop (:func:`crosssection.truth.degrade.finish_scan`).
    variant : Variant
    """

    sweep: str
    labels: tuple = ()
    plate: str | None = None
    illumination: float = 0.0
    cast: float = 0.0
    rim_px: float = 0.0
    noise_sigma: float = 0.0
    blur_px: float = 0.0
    jpeg_quality: int | None = None
    variant: Variant = DEFAULT

    def key(self) -> int:
        """A stable integer naming this treatment (seeds its noise)."""
        return zlib.crc32(repr((self.sweep, self.labels, self.plate, self.illumination,
                                self.cast, self.noise_sigma, self.blur_px, self.jpeg_quality,
                                self.variant.name)).encode())


def _seed(seed: int, sweep: str, i: int) -> int:
    """Seed of scene ``i`` of a sweep (independent of worker count and order)."""
    ss = np.random.SeedSequence([seed, zlib.crc32(sweep.encode()), i])
    return int(ss.generate_state(1, dtype=np.uint32)[0] % 2**31)


# ----------------------------------------------------------------------------- plan
def plan(config: AtlasConfig, seed: int, sweeps=None):
    """The work of the atlas: rods to quench and (base, treatments) tasks.

    Parameters
    ----------
    config : AtlasConfig
    seed : int
    sweeps : iterable of str, optional
        Sweep names (default: all of :data:`SWEEPS`).

    Returns
    -------
    (list of (int, int), list of (Base, tuple of Treatment))
        Rod (index, seed) pairs, and the tasks.
    """
    sweeps = tuple(SWEEPS) if sweeps is None else tuple(sweeps)
    c = config
    tasks = []
    n_rods = 0

    def network(sweep, i, h_px, labels=(), **opts):
        opts = {"n_stacks": c.base_stacks, "max_layers": c.base_max_layers, **opts}
        return Base(sweep, "network", _seed(seed, sweep, i), float(h_px),
                    tuple(sorted(opts.items())), labels=labels)

    def render(sweep, r, h_px, labels=(), **opts):
        return Base(sweep, "render", _seed(seed, sweep + "-render", r), float(h_px),
                    tuple(sorted(opts.items())), rod=r, labels=labels)

    if "resolution" in sweeps:
        for h in c.resolution_h:
            lab = (("h_px", h),)
            t = (Treatment("resolution", lab),)
            tasks += [(network("resolution", i, h, lab), t) for i in range(c.resolution_seeds)]
            tasks += [(render("resolution", r, h, lab), t) for r in range(c.resolution_rods)]
        n_rods = max(n_rods, c.resolution_rods)
    deg = [s for s in DEGRADATIONS if s in sweeps]
    if deg:
        treats = []
        if "noise" in deg:
            treats += [Treatment("noise", (("noise_sigma", v),), noise_sigma=v) for v in c.noise]
        if "blur" in deg:
            treats += [Treatment("blur", (("blur_px", v),), blur_px=v) for v in c.blur]
        if "jpeg" in deg:
            treats += [Treatment("jpeg", (("jpeg_quality", v),), jpeg_quality=v) for v in c.jpeg]
        if "plate" in deg:
            # a plate comes with the dark rim of the hole's edge (real scans: 1-3 px)
            treats += [Treatment("plate", (("plate", v or "none"),), plate=v,
                                 rim_px=0.0 if v is None else 2.0) for v in c.plates]
        if "illumination" in deg:
            treats += [Treatment("illumination", (("illumination", v),), illumination=v)
                       for v in c.illumination]
        if "cast" in deg:
            treats += [Treatment("cast", (("cast", v),), cast=v) for v in c.cast]
        treats = tuple(treats)
        tasks += [(network("degradations", i, 5.0), treats) for i in range(c.degradation_seeds)]
        tasks += [(render("degradations", r, 5.0), treats) for r in range(c.degradation_rods)]
        n_rods = max(n_rods, c.degradation_rods)
    if "layers" in sweeps:
        for m in c.layers:
            lab = (("mean_layers", m),)
            t = (Treatment("layers", lab),)
            tasks += [(network("layers", i, 5.0, lab, n_stacks=c.layers_stacks, mean_layers=m,
                               max_layers=max(3, math.ceil(2.5 * m))), t)
                      for i in range(c.layers_seeds)]
    if "stacks" in sweeps:
        for n in c.stacks:
            lab = (("n_stacks", n),)
            k = c.stacks_seeds if n < c.large_stacks else c.large_seeds
            tasks += [(network("stacks", i, 5.0, lab, n_stacks=n), (Treatment("stacks", lab),))
                      for i in range(k)]
    if "epsilon" in sweeps:
        for e in c.epsilon:
            lab = (("epsilon", float(e)),)
            # seeded by configuration only: the same initial shapes compacted further
            tasks += [(Base("epsilon", "compact", _seed(seed, "epsilon", i), 5.0,
                            (("epsilon", float(e)), ("n_segments", int(c.epsilon_segments))),
                            labels=lab), (Treatment("epsilon", lab),))
                      for i in range(c.epsilon_configs)]
    if "variants" in sweeps:
        treats = tuple(Treatment("variants", (("variant", v.name),), variant=v)
                       for v in VARIANTS if c.variant_names is None
                       or v.name in c.variant_names)
        for i in range(c.variant_seeds):
            s = _seed(seed, "variants", i)
            o = typical_options(np.random.default_rng(s))
            scene = {**o["scene"], "n_stacks": min(o["scene"]["n_stacks"], c.variant_max_stacks)}
            scene.pop("px_per_mm")
            tasks.append((Base("variants", "network", s, 5.0, tuple(sorted(
                {**scene, **{f"backdrop_{k}": v for k, v in o["backdrop"].items()}}.items()))),
                treats))
        for r in range(c.variant_rods):
            s = _seed(seed, "variants-render", r)
            o = typical_options(np.random.default_rng(s))
            keep = {k: o["scene"][k] for k in ("noise_sigma", "blur_px", "jpeg_quality",
                                                "specks", "smears", "pinholes")}
            tasks.append((Base("variants", "render", s, 5.0, tuple(sorted(
                {**keep, **{f"backdrop_{k}": v for k, v in o["backdrop"].items()}}.items())),
                rod=r), treats))
        n_rods = max(n_rods, c.variant_rods)
    if "map_h_layers" in sweeps:
        for h in c.map_h:
            for m in c.map_layers:
                lab = (("h_px", h), ("mean_layers", m))
                tasks += [(network("map_h_layers", i, h, lab, n_stacks=c.map_stacks,
                                   mean_layers=m, max_layers=max(3, math.ceil(2.5 * m))),
                           (Treatment("map_h_layers", lab),)) for i in range(c.map_seeds)]
    if "map_h_blur" in sweeps:
        for h in c.map_h:
            lab = (("h_px", h),)
            treats = tuple(Treatment("map_h_blur", (("blur_px", b),), blur_px=b)
                           for b in c.map_blur)
            tasks += [(network("map_h_blur", i, h, lab, n_stacks=c.map_stacks), treats)
                      for i in range(c.map_seeds)]
            tasks += [(render("map_h_blur", r, h, lab), treats) for r in range(c.map_rods)]
        n_rods = max(n_rods, c.map_rods)
    n_rods = min(n_rods, c.rods) if n_rods else 0
    tasks = [(b, t) for b, t in tasks if b.generator != "render" or b.rod < n_rods]
    rods = [(r, _seed(seed, "rod", r)) for r in range(n_rods)]
    return rods, tasks


# ----------------------------------------------------------------------------- one base
_WARM = False


def _warm_up() -> None:
    """Analyse one tiny scene so compiled kernels are loaded before anything is timed."""
    global _WARM
    if _WARM:
        return
    import crosssection
    from crosssection.truth.network import make_scene

    scene = make_scene(seed=1, n_stacks=15, max_layers=3, px_per_mm=30.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        crosssection.analyze(scene.rgb, px_per_mm=30.0, thickness_mm=THICKNESS_MM,
                             calibration=scene.calibration)
    _WARM = True


def _generate(base: Base, rod: Rod | None):
    """The base scene (typical backdrop and degradations included for the variants)."""
    from crosssection.truth import degrade
    from crosssection.truth.network import make_scene

    o = dict(base.options)
    backdrop = {k[len("backdrop_"):]: o.pop(k) for k in list(o) if k.startswith("backdrop_")}
    finish = {k: o.pop(k) for k in ("noise_sigma", "blur_px", "jpeg_quality") if k in o}
    if base.generator == "network":
        scene = make_scene(seed=base.seed, px_per_mm=base.px_per_mm, thickness_mm=THICKNESS_MM,
                           **o)
    elif base.generator == "compact":
        scene = compact_scene(o["epsilon"], o["n_segments"], base.seed,
                              px_per_mm=base.px_per_mm)
    else:
        scene = render_rod(rod.xy, base.seed, rod.analysis, px_per_mm=base.px_per_mm,
                           thickness_mm=THICKNESS_MM, rod_length_mm=rod.rod_length_mm,
                           hole_radius_mm="auto", **o)
    if backdrop or finish:
        # a typical scan: backdrop first, then the scanner's blur, noise and JPEG
        rng = np.random.default_rng([base.seed, 7])
        if backdrop:
            scene = with_backdrop(scene, rng, **backdrop)
        if finish:
            scene = replace(scene, rgb=degrade.finish_scan(scene.rgb.astype(np.float32), rng,
                                                           **finish))
    return scene


def _treat(scene, base: Base, t: Treatment) -> np.ndarray:
    """The scan of a treatment: backdrop, then blur, noise and JPEG (seeded per treatment)."""
    from crosssection.truth import degrade

    rng = np.random.default_rng([base.seed, t.key()])
    if t.plate is not None or t.illumination > 0 or t.cast > 0:
        scene = with_backdrop(scene, rng, plate=t.plate, illumination=t.illumination,
                              cast=t.cast, rim_px=t.rim_px)
    if t.noise_sigma > 0 or t.blur_px > 0 or t.jpeg_quality is not None:
        return degrade.finish_scan(scene.rgb.astype(np.float32), rng, blur_px=t.blur_px,
                                   noise_sigma=t.noise_sigma, jpeg_quality=t.jpeg_quality)
    return scene.rgb


def _empty_result(h_px):
    """What an analysis that produced nothing is scored as."""
    from crosssection.core import schema

    tables = {name: schema.empty_table(name) for name in schema.TABLES}
    return {"rod_length_mm": 0.0, "n_branches": 0, "total_energy": 0.0}, tables


def run_base(base: Base, treatments, rod: Rod | None = None) -> list:
    """Generate one base scene, apply each treatment, analyse and score (a worker task).

    Parameters
    ----------
    base : Base
    treatments : sequence of Treatment
    rod : Rod, optional
        The quenched rod of a render base.

    Returns
    -------
    list of dict
        One row per treatment (one row with ``error`` when the scene cannot be generated).
    """
    import crosssection
    from crosssection.truth.scoring import score

    _warm_up()
    head = {"generator": base.generator, "seed": base.seed, "h_px": base.h_px,
            "px_per_mm": base.px_per_mm}
    head.update(dict(base.labels))
    t0 = time.perf_counter()
    try:
        scene = _generate(base, rod)
    except FoldstatError as exc:
        return [{"sweep": t.sweep, **head, **dict(t.labels), "stage": "generate",
                 "error": exc.one_line()} for t in treatments]
    gen_s = time.perf_counter() - t0
    p = scene.params
    nbr = scene.tables["stacks"]["n_br"].to_numpy(float)
    head.update(truth_n_stacks=len(nbr), truth_mean_n_br=float(nbr.mean()) if len(nbr) else 0.0,
                truth_max_n_br=int(nbr.max()) if len(nbr) else 0,
                truth_n_junctions=len(scene.tables["junctions"]),
                image_px=int(scene.rgb.shape[0] * scene.rgb.shape[1]), generate_s=gen_s)
    opts = dict(base.options)
    head.update({k: opts[k] for k in ("n_stacks", "mean_layers", "max_layers", "n_segments")
                 if k in opts})
    if "hold_force" in p:
        head["hold_force"] = float(p["hold_force"])
    base_kw = dict(px_per_mm=base.px_per_mm, thickness_mm=THICKNESS_MM,
                   calibration=scene.calibration)
    try:
        # one untimed analysis of this image size first: the first analysis of a new size
        # pays for fresh memory, which would bias whichever treatment comes first
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            crosssection.analyze(scene.rgb, **base_kw)
    except FoldstatError:
        pass
    rows = []
    for t in treatments:
        v = t.variant
        row = {"sweep": t.sweep, **head, "variant": v.name,
               "noise_sigma": opts.get("noise_sigma", t.noise_sigma),
               "blur_px": opts.get("blur_px", t.blur_px),
               "jpeg_quality": opts.get("jpeg_quality", t.jpeg_quality),
               "plate": opts.get("backdrop_plate", t.plate) or "none",
               "illumination": opts.get("backdrop_illumination", t.illumination),
               "cast": opts.get("backdrop_cast", t.cast)}
        row.update(dict(t.labels))
        rgb = _treat(scene, base, t)
        kw = dict(px_per_mm=base.px_per_mm, thickness_mm=THICKNESS_MM,
                  **v.analysis_kwargs(base.h_px))
        if v.calibration:
            kw["calibration"] = scene.calibration
        if v.hole_given and p.get("hole_radius_mm"):
            kw.update(hole_radius_mm=p["hole_radius_mm"], hole_center_px=tuple(p["hole_center_px"]))
        t1 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = crosssection.analyze(rgb, **kw)
            result, err = res, ""
            row["analyze_s"] = time.perf_counter() - t1
            row.update({f"t_{k}_s": float(s) for k, s in res.summary["timings_s"].items()})
            row["quality"] = ";".join(res.summary["quality"]["codes"])
        except FoldstatError as exc:
            row["analyze_s"] = time.perf_counter() - t1
            result, err = _empty_result(base.h_px), exc.one_line()
        s = score(result, (scene.summary, scene.tables), match_px=3 * base.h_px,
                  px_per_mm=base.px_per_mm, thickness_mm=THICKNESS_MM)
        row.update({k: s.get(k, np.nan) for k in METRICS})
        row.update(stage="analyze" if err else "", error=err)
        rows.append(row)
    return rows


# ----------------------------------------------------------------------------- the run
def run_atlas(out, config: AtlasConfig | None = None, *, seed: int = 1, workers: int = 1,
              sweeps=None, progress: bool = False, rods=None) -> dict:
    """Run the atlas and write its tables, charts and ``index.md`` into ``out``.

    Parameters
    ----------
    out : str or Path
        Report folder (created).
    config : AtlasConfig, optional
        Sizes (default :meth:`AtlasConfig.full`).
    seed : int
        Seed of every scene.
    workers : int
        Local worker processes (1: inline).
    sweeps : iterable of str, optional
        Sweeps to run (default all).
    progress : bool
        Show a progress bar.
    rods : str or Path, optional
        A ``rods.npz`` written by an earlier run (key ``rod_<index>_<seed>``): its rods are
        rendered instead of quenching them again. The quench is chaotic, so another build of
        numba or numpy gives other rods from the same seeds; this reproduces a report's render
        points whatever the build. Every run writes the rods it used to ``out/rods.npz``.

    Returns
    -------
    dict
        ``tables`` (sweep -> DataFrame), ``failures`` (DataFrame), ``charts`` (sweep -> path),
        ``elapsed_s``.
    """
    from crosssection.core.parallel import get_executor

    config = config or AtlasConfig.full()
    sweeps = _check_sweeps(sweeps)
    scene_sweeps = tuple(s for s in sweeps if s in SWEEPS)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError(f"seed must be a whole number >= 0, got {seed!r}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ParameterError("the report folder is a file", out)
    _check_report_folder(out)
    t_start = time.perf_counter()
    rod_jobs, tasks = plan(config, int(seed), scene_sweeps)
    given = _read_rods(rods, rod_jobs) if rods is not None else {}
    # the longest tasks first so the pool ends together
    tasks.sort(key=lambda bt: -bt[0].cost() * (1 + 0.1 * len(bt[1])))
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(rod_jobs) + len(tasks), unit="scene", desc="atlas")
    rows = []
    try:
        with get_executor(workers) as ex:
            rods_used = {}
            for fut in as_completed([ex.submit(make_rod, i, s, config, given.get(i))
                                     for i, s in rod_jobs]):
                rod = fut.result()
                rods_used[rod.index] = rod
                if bar is not None:
                    bar.update(1)
            futs = [ex.submit(run_base, b, t, rods_used.get(b.rod)) for b, t in tasks]
            for fut in as_completed(futs):
                rows.extend(fut.result())
                if bar is not None:
                    bar.update(1)
            tables, failures = _tables(rows, scene_sweeps)
            out.mkdir(parents=True, exist_ok=True)
            for name, df in tables.items():
                write_csv(out / f"{name}.csv", df)
            if rods_used:
                _write_rods(out / "rods.npz", rods_used)
            write_csv(out / "failures.csv", failures)
            command = _command(config, seed, workers, sweeps)
            fits = None
            if FITS in sweeps:
                from simulate.atlas_fits import SUBDIR, FitsConfig, run_fits

                fits = run_fits(out / SUBDIR, FitsConfig.for_atlas(config.name), seed=int(seed),
                                executor=ex, command=command)
            elapsed = time.perf_counter() - t_start
            report = write_report(out, tables, failures, command=command,
                                  elapsed_s=elapsed, executor=ex, fits=fits)
    finally:
        if bar is not None:
            bar.close()
    return {"tables": tables, "failures": failures, "elapsed_s": elapsed, "fits": fits,
            **report}


def _rod_key(index: int, seed: int) -> str:
    return f"rod_{index}_{seed}"


def _write_rods(path: Path, rods: dict) -> None:
    """The node positions of every rod used, atomically (temp file, then rename)."""
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, **{_rod_key(r.index, r.seed): r.xy for r in rods.values()})
    tmp.replace(path)


def _read_rods(path, rod_jobs) -> dict:
    """Rod index -> node positions, from a report's ``rods.npz`` (see :func:`run_atlas`)."""
    import zipfile

    from simulate.render import not_npz

    path = Path(path)
    try:
        cause = not_npz(path)
        if cause is not None:
            raise ParameterError(f"unreadable rods file ({cause})", path)
        with np.load(path, allow_pickle=False) as f:
            stored = {k: np.asarray(f[k], float) for k in f.files}
    except FileNotFoundError:
        raise ParameterError("rods file not found", path) from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ParameterError(f"unreadable rods file ({' '.join(str(exc).split())})",
                             path) from None
    out = {}
    for i, s in rod_jobs:
        xy = stored.get(_rod_key(i, s))
        if xy is None:
            raise ParameterError(f"no rod {_rod_key(i, s)} (rods of another seed or size?)",
                                 path)
        if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) < 4 or not np.isfinite(xy).all():
            raise ParameterError(f"rod {_rod_key(i, s)} is not an (N+1, 2) finite array", path)
        out[i] = xy
    return out


def _command(config, seed, workers, sweeps) -> str:
    size = {"quick": " --quick", "full": ""}.get(config.name, f" ({config.name} sizes)")
    only = "" if tuple(sweeps) == ALL_SWEEPS else f" --sweeps {','.join(sweeps)}"
    return (f"python -m simulate benchmark --out REPORT{size} --seed {seed} "
            f"--workers {workers}{only}")


def write_report(out, tables: dict, failures: pd.DataFrame, *, command: str,
                 elapsed_s: float | None = None, executor=None, fits=None) -> dict:
    """Draw the charts of ``tables`` and write ``index.md`` (readings from the numbers).

    Parameters
    ----------
    out : str or Path
        Report folder.
    tables : dict of DataFrame
        Sweep name -> its table (as written to ``SWEEP.csv``).
    failures : DataFrame
    command : str
        The command line named in ``index.md``.
    elapsed_s : float, optional
        Run time named in ``index.md``.
    executor : concurrent.futures.Executor, optional
        Draws the charts in parallel (default: one after the other).
    fits : dict, optional
        What :func:`simulate.atlas_fits.run_fits` returned: its section goes into
        ``index.md``.

    Returns
    -------
    dict
        ``charts`` (name -> PNG path) and ``readings`` (name -> one line).
    """
    out = Path(out)
    jobs = [(name, df) for name, df in tables.items()]
    if "stacks" in tables:
        jobs.append(("stage_times", tables["stacks"]))
    if executor is None:
        charts = {name: draw_chart(name, df, out) for name, df in jobs}
    else:
        futs = {name: executor.submit(draw_chart, name, df, out) for name, df in jobs}
        charts = {name: f.result() for name, f in futs.items()}
    readings = {name: reading(name, df) for name, df in tables.items()}
    if "stacks" in tables:
        readings["stage_times"] = _stage_reading(tables["stacks"])
    text = _index(command, tables, failures, charts, readings, elapsed_s)
    if fits is not None:
        from simulate.atlas_fits import index_section

        text += "\n" + index_section(fits)
    write_text(out / "index.md", text)
    return {"charts": charts, "readings": readings}


def _check_sweeps(sweeps):
    if sweeps is None:
        return ALL_SWEEPS
    if isinstance(sweeps, str):
        sweeps = [s.strip() for s in sweeps.split(",") if s.strip()]
    bad = [s for s in sweeps if s not in ALL_SWEEPS]
    if bad or not sweeps:
        raise ParameterError(f"unknown sweep {bad[0] if bad else '(none given)'!r}; known: "
                             f"{', '.join(ALL_SWEEPS)}")
    return tuple(dict.fromkeys(sweeps))


_FIRST = ("sweep", "generator", "seed", "variant", "h_px", "mean_layers", "n_stacks",
          "noise_sigma", "blur_px", "jpeg_quality", "plate", "illumination", "cast")


def _tables(rows, sweeps):
    """One tidy table per sweep (swept columns first) and the failures table."""
    df = pd.DataFrame(rows)
    fail_cols = ["sweep", "generator", "seed", "h_px", "variant", "stage", "error"]
    if not len(df):
        return {}, pd.DataFrame(columns=fail_cols)
    if "error" not in df:
        df["error"] = ""
    df["error"] = df["error"].fillna("")
    failures = df[df["error"] != ""].reindex(columns=fail_cols)
    ok = df[df.get("stage", pd.Series("", index=df.index)).fillna("") != "generate"]
    tables = {}
    stage_cols = sorted(c for c in df.columns if c.startswith("t_") and c.endswith("_s"))
    for name in sweeps:
        g = ok[ok["sweep"] == name].copy()
        if not len(g):
            continue
        g[stage_cols] = g[stage_cols].fillna(0.0)  # a stage that did not run took no time
        info = SWEEPS[name]
        swept = [c for c in (info.x, info.y) if c]
        first = swept + [c for c in _FIRST if c not in swept]
        cols = first + [c for c in g.columns if c not in first and c not in stage_cols
                        and c not in ("stage",)] + stage_cols
        g = g.reindex(columns=cols)
        if name != "variants":
            g = g.drop(columns=["variant"])
        sort = [c for c in swept if c in g] + ["generator", "seed"]
        g = g.sort_values(sort, key=lambda s: s.astype(str) if s.dtype == object else s,
                          kind="stable")
        tables[name] = g.reset_index(drop=True)
    return tables, failures.reset_index(drop=True)


# ----------------------------------------------------------------------------- numbers
def _x_value(df: pd.DataFrame, info: SweepInfo) -> pd.Series:
    """The swept value of every row as a plottable number (or a category)."""
    x = df[info.x]
    if info.x == "jpeg_quality":
        return x.fillna(100).astype(float)  # no JPEG: lossless, shown as quality 100
    if info.categorical:
        return x.astype(str)
    return x.astype(float) * info.scale


def summarize(df: pd.DataFrame, by) -> pd.DataFrame:
    """Median and quartiles of the accuracy and time columns per group.

    Absolute errors are taken per scene before the median (``abs_`` columns).
    """
    d = df.copy()
    for c in ("rod_length_rel_error", "n_voids_rel_error", "total_energy_rel_error"):
        d["abs_" + c] = d[c].abs()
    cols = [c for c in ("n_br_exact_length_fraction", "n_br_within1_length_fraction",
                        "junction_f1", "abs_rod_length_rel_error",
                        "total_energy_rel_error", "abs_total_energy_rel_error",
                        "abs_n_voids_rel_error", "n_br_mean_abs_error", "analyze_s")
            if c in d]
    g = d.groupby(by, sort=False, dropna=False)[cols]
    med = g.median().add_suffix("_med")
    lo = g.quantile(0.25).add_suffix("_q25")
    hi = g.quantile(0.75).add_suffix("_q75")
    n = g.size().rename("n_scenes")
    return pd.concat([med, lo, hi, n], axis=1).reset_index()


def fails(row, metric: str) -> bool:
    """Whether a median row fails the limit of ``metric`` (see :data:`FAILURE`)."""
    for col, _, test in FAILURE:
        if col == metric:
            key = ("abs_" + col if col == "total_energy_rel_error" else col) + "_med"
            v = row[key]
            return bool(np.isfinite(v) and test(v))
    raise KeyError(metric)


def pareto_front(x, y, *, maximize: bool = True) -> np.ndarray:
    """Indices of the points no other point beats in both ``x`` (smaller better) and ``y``.

    Parameters
    ----------
    x, y : array-like
        Cost (time) and accuracy of each point.
    maximize : bool
        True when a larger ``y`` is better.

    Returns
    -------
    int array
        The front's points, by increasing ``x``.
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float) * (1 if maximize else -1)
    order = np.lexsort((-y, x))
    front, best = [], -np.inf
    for i in order:
        if np.isfinite(x[i]) and np.isfinite(y[i]) and y[i] > best:
            front.append(i)
            best = y[i]
    return np.array(front, int)


def variant_summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per generator and variant: medians, and the analysis time relative to the default on
    the same scans (the ratio is robust to how busy the machine was)."""
    d = df.copy()
    ref = d[d["variant"] == DEFAULT.name].set_index(["generator", "seed"])["analyze_s"]
    key = pd.MultiIndex.from_frame(d[["generator", "seed"]])
    d["time_ratio"] = d["analyze_s"].to_numpy() / ref.reindex(key).to_numpy()
    s = summarize(d, ["generator", "variant"])
    s["time_ratio_med"] = d.groupby(["generator", "variant"], sort=False)["time_ratio"] \
        .median().to_numpy()
    return s


# ----------------------------------------------------------------------------- charts
PANELS = (  # (column, y label, limit line, limit label, is an error in %)
    ("n_br_exact_length_fraction", "exact n_br (fraction of stack length)", 0.8,
     "failure limit 0.8", False),
    ("junction_f1", "junction F1", 0.9, "failure limit 0.9", False),
    ("abs_rod_length_rel_error", "|rod length error| (%)", 3.0, "target 3 %", True),
    ("total_energy_rel_error", "total energy error (%)", 20.0, "failure limit +-20 %", True),
    ("abs_n_voids_rel_error", "|void count error| (%)", 5.0, "target 5 %", True),
    ("analyze_s", "analysis time per scan (s)", None, "", False),
)
GEN_STYLE = {"network": ("tab:blue", "o", "network generator"),
             "render": ("tab:orange", "s", "simulator renders"),
             "compact": ("tab:green", "D", "compacted simulator rods")}


def _figure(w, h):
    from matplotlib.figure import Figure

    return Figure(figsize=(w, h), layout="constrained")


def draw_chart(name: str, df: pd.DataFrame, out) -> Path:
    """Draw the chart of one sweep (or ``stage_times`` from the stacks sweep) into
    ``out/NAME.png``; return its path."""
    if name == "stage_times":
        fig = _stage_chart(df)
    else:
        info = SWEEPS[name]
        if info.kind == "line":
            fig = _line_chart(df, info)
        elif info.kind == "map":
            fig = _map_chart(df, info)
        else:
            fig = _variants_chart(df, info)
    return save_figure(fig, Path(out) / f"{name}.png")


def _line_chart(df, info: SweepInfo):
    fig = _figure(13, 7.2)
    axes = fig.subplots(2, 3).ravel()
    d = df.assign(_x=_x_value(df, info))
    cats = None
    if info.categorical:
        # the reference (no plate) first, then the others in the order of the table
        cats = sorted(dict.fromkeys(d["_x"]), key=lambda v: v != "none")
    n_by, ticks_x = {}, []
    for gen, g in d.groupby("generator", sort=False):
        s = summarize(g, ["_x"])
        if info.plot_x:
            s["_px"] = g.groupby("_x", sort=False)[info.plot_x].median().reindex(s["_x"]) \
                .to_numpy()
        else:
            s["_px"] = s["_x"]
        if cats is not None:
            s["_px"] = [cats.index(v) for v in s["_x"]]
        s = s.sort_values("_px")
        ticks_x.extend(s["_px"].to_numpy(float))
        n_by[gen] = int(s["n_scenes"].median())
        color, marker, label = GEN_STYLE.get(gen, ("tab:grey", "^", gen))
        for ax, (col, _, _, _, pct) in zip(axes, PANELS):
            f = 100.0 if pct else 1.0
            x = s["_px"].to_numpy(float)
            med = s[col + "_med"].to_numpy(float) * f
            if cats is not None:
                # categories: no line between them; the bar is the interquartile range
                err = [med - s[col + "_q25"].to_numpy(float) * f,
                       s[col + "_q75"].to_numpy(float) * f - med]
                ax.errorbar(x, med, yerr=np.clip(err, 0, None), marker=marker, color=color,
                            linestyle="", capsize=3, label=label)
                continue
            ax.plot(x, med, marker=marker, color=color, label=label)
            ax.fill_between(x, s[col + "_q25"] * f, s[col + "_q75"] * f, color=color,
                            alpha=0.18, linewidth=0)
    for ax, (col, ylabel, lim, lim_label, _) in zip(axes, PANELS):
        if lim is not None:
            ax.axhline(lim, color="crimson", linestyle="--", linewidth=1, label=lim_label)
            if col == "total_energy_rel_error":
                ax.axhline(-lim, color="crimson", linestyle="--", linewidth=1)
        ax.set_ylabel(ylabel)
        ax.set_xlabel(info.xlabel)
        if info.log_x:
            from matplotlib.ticker import NullFormatter

            # label the swept values only (the default log labels collide at 2x10^1, ...)
            ax.set_xscale("log")
            ticks = sorted(set(np.round(ticks_x, 0)))
            ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
            ax.xaxis.set_minor_formatter(NullFormatter())
        if info.reverse_x:
            ax.invert_xaxis()
        if cats is not None:
            ax.set_xticks(range(len(cats)), cats, rotation=30)
        if col in ("n_br_exact_length_fraction", "junction_f1"):
            ax.set_ylim(min(0.5, ax.get_ylim()[0]), 1.03)
        ax.grid(alpha=0.3)
    axes[-1].set_ylim(bottom=0)
    e = axes[3]
    if max(abs(v) for v in e.get_ylim()) > 150:
        # renders overestimate the energy several fold: linear within +-100 %, logarithmic
        # beyond, so the +-20 % limit stays readable
        lo, hi = e.get_ylim()
        e.set_yscale("symlog", linthresh=100)
        e.set_ylim(min(lo, -100) * 1.3, hi * 1.5)
        ticks = [t for t in (-1000, -300, -100, -20, 0, 20, 100, 300, 1000, 3000, 10000)
                 if min(lo, -100) * 1.3 <= t <= hi * 1.5]
        e.set_yticks(ticks, [f"{t:g}" for t in ticks])
        e.set_ylabel("total energy error (%; log beyond +-100)")
    # one legend for the figure: the generators and the limit lines (each panel's limit is
    # named on its axis label's panel by the line's position; colours are shared)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=GEN_STYLE.get(g, ("tab:grey",))[0],
                      marker=GEN_STYLE.get(g, (0, "^"))[1], label=GEN_STYLE.get(g, (0, 0, g))[2])
               for g in n_by]
    handles.append(Line2D([], [], color="crimson", linestyle="--",
                          label="failure limit (exact n_br 0.8, F1 0.9, energy +-20 %) or "
                                "target (rod length 3 %, void count 5 %)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=9)
    ns = ", ".join(f"{GEN_STYLE.get(g, (0, 0, g))[2]}: {n} per point" for g, n in n_by.items())
    what = "median (marker) and interquartile range (bar)" if cats is not None else \
        "median (line) and interquartile range (band)"
    fig.suptitle(f"{info.title}\n{what} over scenes ({ns})", fontsize=11)
    return fig


def _cell_edges(fail: np.ndarray):
    """Segments (x0, x1, y0, y1) between failing and passing cells of a grid (index coords;
    cell (i, j) spans [j-0.5, j+0.5] x [i-0.5, i+0.5])."""
    segs = []
    ny, nx = fail.shape
    for i in range(ny):
        for j in range(nx):
            if j + 1 < nx and fail[i, j] != fail[i, j + 1]:
                segs.append(((j + 0.5, j + 0.5), (i - 0.5, i + 0.5)))
            if i + 1 < ny and fail[i, j] != fail[i + 1, j]:
                segs.append(((j - 0.5, j + 0.5), (i + 0.5, i + 0.5)))
    return segs


MAP_PANELS = (("n_br_exact_length_fraction", "exact n_br", "viridis", (0.5, 1.0)),
              ("junction_f1", "junction F1", "viridis", (0.5, 1.0)),
              ("total_energy_rel_error", "|energy error|", "magma_r", (0.0, 1.0)))


def map_grid(df: pd.DataFrame, info: SweepInfo, metric: str):
    """Median of ``metric`` (absolute for the energy) on the (y, x) grid of a map sweep.

    Returns
    -------
    (xs, ys, values, fail) : values and fail are (len(ys), len(xs)) arrays
    """
    s = summarize(df, [info.y, info.x])
    xs = sorted(df[info.x].unique())
    ys = sorted(df[info.y].unique())
    vals = np.full((len(ys), len(xs)), np.nan)
    fail = np.zeros_like(vals, bool)
    key = ("abs_" + metric if metric == "total_energy_rel_error" else metric) + "_med"
    for _, r in s.iterrows():
        i, j = ys.index(r[info.y]), xs.index(r[info.x])
        vals[i, j] = r[key]
        fail[i, j] = fails(r, metric)
    return xs, ys, vals, fail


def _map_chart(df, info: SweepInfo):
    gens = list(dict.fromkeys(df["generator"]))
    fig = _figure(13, 3.9 * len(gens) + 0.8)
    axes = np.atleast_2d(fig.subplots(len(gens), 3, squeeze=False))
    for gi, gen in enumerate(gens):
        g = df[df["generator"] == gen]
        n = int(g.groupby([info.x, info.y]).size().median())
        for ax, (metric, label, cmap, (vmin, vmax)) in zip(axes[gi], MAP_PANELS):
            xs, ys, vals, fail = map_grid(g, info, metric)
            pct = metric.startswith("total")
            if pct:
                vals, vmin, vmax = 100 * vals, 100 * vmin, 100 * vmax
            im = ax.imshow(vals, origin="lower", cmap=cmap, vmin=vmin, vmax=vmax, aspect="auto")
            for i in range(len(ys)):
                for j in range(len(xs)):
                    if np.isfinite(vals[i, j]):
                        txt = f"{vals[i, j]:.0f} %" if pct else f"{vals[i, j]:.2f}"
                        # white on dark cells (luminance of the cell's colour)
                        r, gg, b, _ = im.cmap(im.norm(vals[i, j]))
                        dark = 0.299 * r + 0.587 * gg + 0.114 * b < 0.5
                        ax.text(j, i, txt, ha="center", va="center", fontsize=8,
                                color="white" if dark else "black")
                    if fail[i, j]:
                        ax.add_patch(_hatch(j, i))
            for xseg, yseg in _cell_edges(fail):
                ax.plot(xseg, yseg, color="crimson", linewidth=2.5)
            ax.set_xticks(range(len(xs)), [f"{v:g}" for v in xs])
            ax.set_yticks(range(len(ys)), [f"{v:g}" for v in ys])
            ax.set_xlabel(info.xlabel)
            ax.set_ylabel(info.ylabel)
            crit = next(lbl for c, lbl, _ in FAILURE if c == metric)
            ax.set_title(f"{GEN_STYLE.get(gen, (0, 0, gen))[2]}: {label}\n"
                         f"(hatched: {crit}; scenes per cell: {n})", fontsize=9)
            fig.colorbar(im, ax=ax, shrink=0.85, label=label + (" (%, capped at 100)" if pct
                                                              else ""))
    fig.suptitle(info.title, fontsize=11)
    return fig


def _hatch(j, i):
    from matplotlib.patches import Rectangle

    return Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="///", edgecolor="crimson",
                     linewidth=0)


VARIANT_PANELS = (("n_br_exact_length_fraction", "exact n_br (median)", True),
                  ("junction_f1", "junction F1 (median)", True),
                  ("abs_rod_length_rel_error", "|rod length error| (median, %)", False),
                  ("abs_total_energy_rel_error", "|total energy error| (median, %)", False))


def _variants_chart(df, info: SweepInfo):
    from matplotlib.lines import Line2D

    s = variant_summary(df)
    gens = list(dict.fromkeys(s["generator"]))
    fig = _figure(15, 3.9 * len(gens) + 1.0)
    axes = fig.subplots(len(gens), len(VARIANT_PANELS), squeeze=False)
    colors = {v: _VARIANT_COLORS[i % len(_VARIANT_COLORS)] for i, v in enumerate(VARIANT_NAMES)}
    markers = {v: _VARIANT_MARKERS[i % len(_VARIANT_MARKERS)]
               for i, v in enumerate(VARIANT_NAMES)}
    for gi, gen in enumerate(gens):
        g = s[s["generator"] == gen].reset_index(drop=True)
        n = int(g["n_scenes"].median())
        for ax, (col, ylabel, larger_better) in zip(axes[gi], VARIANT_PANELS):
            pct = 100.0 if not larger_better else 1.0
            x = g["time_ratio_med"].to_numpy(float)
            y = g[col + "_med"].to_numpy(float) * pct
            for k, v in enumerate(g["variant"]):
                ax.scatter(x[k], y[k], color=colors.get(v, "grey"), marker=markers.get(v, "o"),
                           s=55, zorder=3)
                if v == DEFAULT.name:
                    ax.scatter(x[k], y[k], s=260, facecolor="none", edgecolor="black",
                               linewidth=2, zorder=4)
            front = pareto_front(x, y, maximize=larger_better)
            if len(front):
                fx, fy = x[front], y[front]
                ax.step(fx, fy, where="post", color="black", linewidth=1, alpha=0.6, zorder=2)
            ax.set_xlabel("time / default's time (median)")
            ax.set_ylabel(ylabel)
            ax.set_title(f"{GEN_STYLE.get(gen, (0, 0, gen))[2]} ({n} scans)", fontsize=9)
            ax.grid(alpha=0.3)
    handles = [Line2D([], [], color=colors[v], marker=markers[v], linestyle="", label=v)
               for v in VARIANT_NAMES if v in set(s["variant"])]
    handles += [Line2D([], [], marker="o", markersize=13, markerfacecolor="none",
                       markeredgecolor="black", markeredgewidth=2, linestyle="",
                       label="default (ringed)"),
                Line2D([], [], color="black", alpha=0.6, label="Pareto front")]
    fig.legend(handles=handles, loc="outside right center", fontsize=8)
    fig.suptitle(f"{info.title}\n(each point: median over scans of the accuracy and of the "
                 "analysis time divided by the default's on the same scan; left = faster; "
                 "black line = Pareto front)", fontsize=11)
    return fig


_VARIANT_COLORS = ("black", "tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple",
                   "tab:brown", "tab:pink", "tab:olive", "tab:cyan", "navy", "gold", "teal",
                   "grey", "lime", "magenta", "sienna")
# as many as colours, so that no variant repeats the default's black circle
_VARIANT_MARKERS = "os^Dvp<>hX*Pd8HDs"


def _stage_columns(df):
    cols = [c for c in df.columns if c.startswith("t_") and c.endswith("_s")]
    return sorted(cols, key=lambda c: -df[c].median())


def _stage_chart(df):
    fig = _figure(10, 5.2)
    ax = fig.subplots()
    cols = _stage_columns(df)
    d = df[df["error"].fillna("") == ""]
    g = d.groupby("n_stacks")
    x = g["truth_n_stacks"].median().to_numpy(float)
    med = g[cols].median()
    bottom = np.zeros(len(med))
    cmap = __import__("matplotlib").colormaps["tab20"]
    pos = np.arange(len(med))
    for k, c in enumerate(cols):
        ax.bar(pos, med[c].to_numpy(), bottom=bottom, color=cmap(k % 20),
               label=c[2:-2].replace("_", " "))
        bottom += med[c].to_numpy()
    ax.plot(pos, g["analyze_s"].median().to_numpy(), "k_", markersize=30, mew=2,
            label="whole analysis (wall)")
    ax.set_xticks(pos, [f"{v:.0f}" for v in x])
    ax.set_xlabel("stacks per scene (realised, network generator, h = 5 px)")
    ax.set_ylabel("median time per scan (s)")
    fig.legend(fontsize=8, loc="outside right upper")
    ax.grid(alpha=0.3, axis="y")
    ax.set_title("Speed: where the analysis time goes as scenes grow (median per-stage time)",
                 fontsize=11)
    return fig


# ----------------------------------------------------------------------------- readings
_SHORT = {"h_px": ("h", " px"), "noise_sigma": ("noise sigma", ""), "blur_px": ("blur", " px"),
          "jpeg_quality": ("JPEG quality", ""), "plate": ("plate", ""),
          "illumination": ("illumination", " %"), "cast": ("cast", " %"),
          "mean_layers": ("mean layers", ""), "n_stacks": ("stacks", ""),
          "epsilon": ("epsilon", "")}


def _where(values, failing, info: SweepInfo, only: str = " only") -> str:
    """'at h <= 2.5 px', 'at noise sigma >= 30', 'at every h' or a list, for the failing
    swept values."""
    name, unit = _SHORT.get(info.x, (info.x, ""))
    vals = list(values)
    bad = [v for v, f in zip(vals, failing) if f]
    if info.categorical:
        return f"with {name} " + ", ".join(str(v) for v in bad)

    def fmt(v):
        return "none" if info.x == "jpeg_quality" and v == 100 else f"{v:g}"
    order = sorted(range(len(vals)), key=lambda k: vals[k])
    flags = [failing[k] for k in order]
    sv = [vals[k] for k in order]
    if len(bad) == len(vals):
        return f"at every {name}"
    if len(bad) == 1:
        return f"at {name} = {fmt(bad[0])}{unit}{only}"
    if all(flags[: sum(flags)]):
        return f"at {name} <= {fmt(sv[sum(flags) - 1])}{unit}"
    if all(flags[len(flags) - sum(flags):]):
        return f"at {name} >= {fmt(sv[len(flags) - sum(flags)])}{unit}"
    return f"at {name} = " + ", ".join(fmt(v) for v in sorted(bad)) + unit


def reading(name: str, df: pd.DataFrame) -> str:
    """A one-line reading of a sweep's chart, computed from its table."""
    info = SWEEPS[name]
    if info.kind == "variants":
        return _variants_reading(df)
    if info.kind == "map":
        return _map_reading(df, info)
    parts = []
    d = df.assign(_x=_x_value(df, info))
    for gen, g in d.groupby("generator", sort=False):
        s = summarize(g, ["_x"])
        label = GEN_STYLE.get(gen, (0, 0, gen))[2]
        bits = []
        for col, crit, _ in FAILURE:
            failing = [fails(r, col) for _, r in s.iterrows()]
            what = crit.split(" <")[0].split(" >")[0]
            if not any(failing):
                lo = s[("abs_" + col if "energy" in col else col) + "_med"]
                worst = lo.max() if "energy" in col else lo.min()
                bits.append(f"{what} holds everywhere (worst median "
                            f"{_fmt_metric(col, worst)})")
            elif all(failing):
                bits.append(f"{crit} everywhere")
            else:
                bits.append(f"{crit} {_where(s['_x'], failing, info)}")
        t = s["analyze_s_med"]
        bits.append(f"time {t.min():.2f}-{t.max():.2f} s")
        parts.append(f"{label}: " + "; ".join(bits))
    return ". ".join(parts) + "."


def _fmt_metric(col, v):
    return f"{100 * v:.0f} %" if "energy" in col else f"{v:.2f}"


def _map_reading(df, info: SweepInfo) -> str:
    parts = []
    yname, yunit = _SHORT.get(info.y, (info.y, ""))
    for gen, g in df.groupby("generator", sort=False):
        label = GEN_STYLE.get(gen, (0, 0, gen))[2]
        bits = []
        for col, crit, _ in FAILURE:
            xs, ys, _, fail = map_grid(g, info, col)
            if not fail.any():
                bits.append(f"no cell with {crit}")
                continue
            if fail.all():
                bits.append(f"{crit} in every cell")
                continue
            rows = []
            for i, yv in enumerate(ys):
                if fail[i].any():
                    sub = SweepInfo("line", "h_px")
                    rows.append(f"{_where(xs, list(fail[i]), sub, only='')} for {yname} "
                                f"{yv:g}{yunit}")
            bits.append(f"{crit} " + ", ".join(rows))
        parts.append(f"{label}: " + "; ".join(bits))
    return ". ".join(parts) + "."


def _variants_reading(df) -> str:
    s = variant_summary(df)
    parts = []
    for gen, g in s.groupby("generator", sort=False):
        g = g.reset_index(drop=True)
        label = GEN_STYLE.get(gen, (0, 0, gen))[2]
        x = g["time_ratio_med"].to_numpy(float)
        on = []
        for col, name, larger in (("n_br_exact_length_fraction", "exact n_br", True),
                                  ("abs_total_energy_rel_error", "|energy error|", False)):
            y = g[col + "_med"].to_numpy(float)
            best = int(np.nanargmax(y) if larger else np.nanargmin(y))
            front = set(pareto_front(x, y, maximize=larger).tolist())
            d = int(np.flatnonzero(g["variant"] == DEFAULT.name)[0])
            on.append(f"best {name}: {g['variant'][best]} ({_fmt_metric(col, y[best])}; "
                      f"default {_fmt_metric(col, y[d])}, "
                      f"{'on' if d in front else 'off'} the front)")
        fast = int(np.nanargmin(x))
        parts.append(f"{label}: " + "; ".join(on)
                     + f"; fastest: {g['variant'][fast]} ({x[fast]:.2f} x default)")
    return ". ".join(parts) + "."


def _stage_reading(df) -> str:
    d = df[df["error"].fillna("") == ""]
    g = d.groupby("n_stacks")
    big = max(g.groups)
    m = g.get_group(big)
    cols = _stage_columns(m)
    top = sorted(((m[c].median(), c[2:-2].replace("_", " ")) for c in cols), reverse=True)[:3]
    small = min(g.groups)
    return (f"median analysis {g.get_group(small)['analyze_s'].median():.2f} s at "
            f"{g.get_group(small)['truth_n_stacks'].median():.0f} stacks, "
            f"{m['analyze_s'].median():.2f} s at {m['truth_n_stacks'].median():.0f}; "
            "largest stages there: " + ", ".join(f"{n} {t:.2f} s" for t, n in top) + ".")


def versions_line() -> str:
    """The package and library versions of this process, as ``index.md`` names them.

    The quenched rods are chaotic (another numba, llvmlite or numpy build ends on other
    rods) and a new release of an analysis library can move the scores' last bits: a report
    read later must say which code computed it.

    Returns
    -------
    str
        ``Versions: foldstat X; numpy Y, scipy Z, ...`` (``not installed`` for a library
        that is not).
    """
    from crosssection._version import __version__
    from crosssection.core.provenance import ANALYSIS_LIBRARIES, library_versions

    libs = library_versions(ANALYSIS_LIBRARIES + ("llvmlite",))
    return (f"Versions: foldstat {__version__}; "
            + ", ".join(f"{k} {v or 'not installed'}" for k, v in libs.items()) + ".")


def _index(command, tables, failures, charts, readings, elapsed) -> str:
    took = "" if elapsed is None else f" ({elapsed / 60:.1f} min)"
    lines = [ATLAS_TITLE, "",
             f"Command: `{command}`{took}. Scenes with exact truth from "
             "the network generator and from simulator rods (quenched, or compacted by a "
             "shrinking wall) rendered as scans, "
             "analysed with the default settings unless a sweep says otherwise (scale, "
             "calibration and hole given) and scored against their truth (junctions matched "
             "within 3 h). Failure limits: exact n_br < 0.8, junction F1 < 0.9, |total "
             "energy error| > 20 %. Medians over scenes. Times are wall times of one "
             "analysis in a warm worker process (the same image analysed once before, "
             "untimed), with as many workers as the command says sharing the machine.", "",
             versions_line(), ""]
    for name in list(tables) + (["stage_times"] if "stage_times" in charts else []):
        if name not in charts:
            continue
        n = len(tables[name]) if name in tables else len(tables["stacks"])
        csv = f"{name}.csv" if name in tables else "stacks.csv"
        lines += [f"## {name}", "", f"![{name}]({charts[name].name})", "",
                  f"{readings.get(name, '')}", "", f"Table: [{csv}]({csv}) ({n} rows).", ""]
    lines += [f"Failures: [failures.csv](failures.csv) ({len(failures)} rows: scenes the "
              "generator could not build, or analyses that raised; the latter are scored as "
              "empty results).", ""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- CLI
def add_subparser(sub) -> None:
    """Register ``benchmark``: ``python -m simulate benchmark --out REPORT [--quick]``."""
    p = sub.add_parser("benchmark", help="the validation atlas: accuracy and speed charts",
                       description="Regenerate every chart and CSV of the validation atlas: "
                                   "scenes with exact truth from both generators, swept over "
                                   "resolution, degradations, compaction and pipeline "
                                   "variants; REPORT/index.md lists the charts with a reading.")
    p.add_argument("--out", required=True, metavar="REPORT", help="report folder (created)")
    p.add_argument("--quick", action="store_true",
                   help="a handful of small scenes per sweep: every table and chart in a few "
                        "minutes at most on 2 cores")
    p.add_argument("--workers", type=int, default=1, metavar="W",
                   help="worker processes (default 1)")
    p.add_argument("--seed", type=int, default=1, metavar="S", help="seed of every scene "
                   "(default 1)")
    p.add_argument("--sweeps", default=None, metavar="NAMES",
                   help="comma-separated sweeps to run (default all: " + ", ".join(ALL_SWEEPS)
                        + ")")
    p.add_argument("--rods", default=None, metavar="FILE",
                   help="render the quenched rods of an earlier report (its rods.npz) instead "
                        "of quenching them again: the quench is chaotic, so another build of "
                        "numba or numpy gives other rods from the same seeds")
    p.set_defaults(func=_run)


#: The first line of an atlas' ``index.md``: a folder holding it is a report this command wrote
ATLAS_TITLE = "# Validation atlas"


def _check_report_folder(out: Path) -> None:
    """Refuse a folder that holds files and no atlas' ``index.md``: a run replaces the
    report's files (index.md, the sweeps' tables and charts, failures.csv, rods.npz), which
    would overwrite the user's own files of those names.

    Raises
    ------
    ParameterError
        Naming the folder and one of its entries.
    """
    if not out.is_dir():
        return
    entries = sorted(p.name for p in out.iterdir())
    if not entries:
        return
    index = out / "index.md"
    try:
        ours = index.is_file() and index.read_text(encoding="utf-8").startswith(ATLAS_TITLE)
    except (OSError, UnicodeDecodeError):
        ours = False
    if not ours:
        raise ParameterError(f"holds {entries[0]}, and no atlas report: a run replaces the "
                             "report's files there; give a new folder, an empty one or one an "
                             "earlier benchmark wrote", out)


def _run(args) -> int:
    from crosssection.core.fileio import check_out
    from crosssection.core.parallel import capped_workers

    check_out(args.out)
    if args.workers < 1:
        raise ParameterError(f"--workers must be >= 1, got {args.workers}")
    if args.seed < 0:
        raise ParameterError(f"--seed must be >= 0, got {args.seed}")
    workers, lowered = capped_workers(args.workers)
    if lowered:
        print(f"warning: {lowered}", file=sys.stderr)
    config = AtlasConfig.quick() if args.quick else AtlasConfig.full()
    res = run_atlas(args.out, config, seed=args.seed, workers=workers,
                    sweeps=args.sweeps, progress=sys.stderr.isatty(), rods=args.rods)
    n = sum(len(t) for t in res["tables"].values())
    # the fits sweep draws its own charts, in its subfolder: they are charts of the report too
    fits = list(((res.get("fits") or {}).get("charts") or {}).values())
    where = f" ({len(fits)} under {Path(fits[0]).parent})" if fits else ""
    print(f"{n} analyses in {res['elapsed_s']:.0f} s; {len(res['charts']) + len(fits)} "
          f"charts{where}, index in {Path(args.out) / 'index.md'}")
    return 0
