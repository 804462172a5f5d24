"""Generated scans with exact truth for tests: pytest fixtures, hypothesis strategies, and
scan folders for tests of the batch workflow.

For users' test suites
----------------------
Installing foldstat registers this module as a pytest plugin (entry point ``pytest11``), so
its fixtures are available in any test without an import; to load it explicitly instead, put
``pytest_plugins = ["crosssection.testing"]`` in a ``conftest.py``. Fixtures:

``foldstat_scan``
    A :class:`GeneratedScan` (a scan written with its truth, see :func:`make_generated_scan`):
    20 stacks of 1-4 layers, 50 px/mm, clean, seed 0 by default. Parametrise it indirectly
    with a dict of :func:`make_generated_scan` keywords, or with :func:`scan_grid` for a grid
    of resolutions, layer counts, densities and degradations.
``foldstat_scan_factory``
    ``make(**options) -> GeneratedScan``; scans are cached per session and options.

Hypothesis strategies (``pip install foldstat[test]``; hypothesis is imported only when a
strategy is built): :func:`scan_options`, :func:`scenes`, :func:`analysis_params`.

A test a user would write (analyse a generated scan and compare it with its truth)::

    import pytest

    from crosssection.testing import scan_grid
    from crosssection.truth.scoring import score


    @pytest.mark.parametrize("foldstat_scan", scan_grid(layers=[4], degradations=["clean",
                                                                                "noisy"]),
                             indirect=True)
    def test_my_settings_recover_the_network(foldstat_scan):
        result = foldstat_scan.analyze(curvature_method="missing")
        s = score(result, foldstat_scan.truth, px_per_mm=foldstat_scan.px_per_mm,
                  thickness_mm=foldstat_scan.thickness_mm)
        assert abs(s["rod_length_rel_error"]) < 0.03
        assert s["junction_f1"] >= 0.95
        assert s["n_br_exact_length_fraction"] >= 0.9

Batch workflow
--------------
``make_scan_tree`` lays out a folder the way a lab keeps scans (a set with ``set.toml``, a
calibration and a per-image override, loose images, and optionally broken inputs), so that a
test can run :func:`crosssection.batch.run_batch` on it and check what succeeded and failed.

Importing this module (as pytest does for every session once foldstat is installed) loads
neither numpy nor the pipeline: everything heavy is imported where it is used. It holds no
test assertion, so pytest need not rewrite it (PYTEST_DONT_REWRITE), which also spares a
warning when a test module imports it before pytest loads it as a plugin.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from pathlib import Path

try:  # the fixtures need pytest; the helpers and strategies do not
    import pytest
except ImportError:  # pragma: no cover - pytest is a test extra
    pytest = None

__all__ = ["GeneratedScan", "make_generated_scan", "scan_grid", "DEGRADATIONS",
           "DEFAULT_SCAN", "scan_options", "scenes", "analysis_params",
           "drawn_scan", "generated_scan", "write_png", "write_calibration", "make_scan_tree",
           "index_numbers", "partial_outputs"]

#: degradation presets: name -> keywords of ``crosssection.truth.network.make_scene``
DEGRADATIONS = {
    "clean": {},
    "noisy": {"noise_sigma": 4.0, "blur_px": 0.7},
    "jpeg": {"jpeg_quality": 80},
    "defects": {"smears": 3, "specks": 10, "pinholes": 6},
}

#: options of the ``foldstat_scan`` fixture when it is not parametrised
DEFAULT_SCAN = {"seed": 0, "px_per_mm": 50.0, "n_stacks": 20, "max_layers": 4,
                "degradation": "clean"}

#: documented ranges of :func:`make_generated_scan`: below them no layout exists (max_layers
#: 1: a junction of three stacks conserves layers only as a = b + c, so some stack holds two),
#: beyond them one scan takes tens of seconds or more (n_stacks 1000: 76 s; max_layers 100: 23 s)
N_STACKS_RANGE = (10, 300)
MAX_LAYERS_RANGE = (2, 12)


@dataclass(frozen=True)
class GeneratedScan:
    """A generated scan written as a scene folder, with its exact truth.

    Attributes
    ----------
    folder : Path
        Holds ``image.png``, ``params.json``, ``calibration.csv``, ``set.toml`` and
        ``truth/`` (the layout of :func:`crosssection.truth.scene.write_scene`); its
        ``set.toml`` (scale, calibration, hole) is the one ``foldstat batch`` reads for the
        scan, before any of a folder above.
    scene : crosssection.truth.scene.Scene
        The image (``rgb``), the truth ``summary`` and ``tables``, and the generator's
        ``params``.
    options : dict
        The options it was made with (:func:`make_generated_scan`).
    """

    folder: Path
    scene: object
    options: dict = field(default_factory=dict)

    @property
    def image(self) -> Path:
        """The scan file."""
        return self.folder / "image.png"

    @property
    def truth(self) -> tuple:
        """``(summary, tables)``, the pair :func:`crosssection.truth.scoring.score` takes."""
        return self.scene.summary, self.scene.tables

    @property
    def px_per_mm(self) -> float:
        return float(self.scene.params["px_per_mm"])

    @property
    def thickness_mm(self) -> float:
        return float(self.scene.params["thickness_mm"])

    def analyze(self, *, use_hole: bool = True, use_calibration: bool = True, **overrides):
        """Analyse the scan with the parameters it was made with.

        Parameters
        ----------
        use_hole, use_calibration : bool
            Give the pipeline the known hole and width calibration (otherwise it finds the
            hole and uses the linear law n h).
        **overrides
            Fields of :class:`crosssection.params.AnalysisParams`.

        Returns
        -------
        crosssection.result.AnalysisResult
        """
        from crosssection.truth.scoring import analyze_scene_folder

        result, _ = analyze_scene_folder(self.folder, use_hole=use_hole,
                                         use_calibration=use_calibration, **overrides)
        return result


def make_generated_scan(folder, *, seed: int = 0, px_per_mm: float = 50.0, n_stacks: int = 20,
                        max_layers: int = 4, degradation: str = "clean",
                        **scene_options) -> GeneratedScan:
    """Generate a scan with :func:`crosssection.truth.network.make_scene` and write it.

    Parameters
    ----------
    folder : str or Path
        Scene folder to write (created).
    seed : int
        Same seed and options, same scan.
    px_per_mm : float
        Resolution in px/mm (the sheet is h = 0.1 mm thick unless ``thickness_mm`` is given;
        below 30 px/mm the pipeline warns that h < 3 px).
    n_stacks : int
        Approximate number of stacks (density; 10-300). Below about 14 the disk holds 3-4
        Voronoi cells and some seeds (all at 10) find no layout.
    max_layers : int
        Largest number of layers in a stack (2-12: with one, no junction of three stacks
        conserves its layers, and no layout exists).
    degradation : str
        A key of :data:`DEGRADATIONS` (``clean``, ``noisy``, ``jpeg``, ``defects``).
    **scene_options
        Further keywords of ``make_scene`` (``noise_sigma``, ``image_size``, ...).

    Returns
    -------
    GeneratedScan

    Raises
    ------
    ParameterError
        An option of the wrong type or outside its range, or an unknown keyword.
    ConfigError
        ``folder`` is an existing file, or cannot be written.
    SceneGenerationError
        No layout found for these options (a :class:`ParameterError` naming them).
    """
    import inspect

    from crosssection.core.errors import ConfigError, ParameterError
    from crosssection.truth.network import SceneGenerationError, make_scene
    from crosssection.truth.scene import write_scene

    own = ("seed", "px_per_mm", "n_stacks", "max_layers")
    scene_keywords = [k for k in inspect.signature(make_scene).parameters if k not in own]
    unknown = sorted(set(scene_options) - set(scene_keywords))
    if unknown:
        import difflib

        near = difflib.get_close_matches(unknown[0], [*own, "degradation", *scene_keywords], 1)
        hint = f" (did you mean {near[0]}?)" if near else ""
        raise ParameterError(f"unknown keyword {', '.join(unknown)}{hint}: make_generated_scan "
                             f"takes {', '.join(own)}, degradation and make_scene's "
                             f"{', '.join(sorted(scene_keywords))}")
    _check_whole("seed", seed, 0)
    _check_positive("px_per_mm", px_per_mm)
    _check_whole("n_stacks", n_stacks, *N_STACKS_RANGE, floats=True)
    _check_whole("max_layers", max_layers, *MAX_LAYERS_RANGE, floats=True)
    _check_degradation(degradation)
    if scene_options.get("thickness_mm") is not None:
        _check_positive("thickness_mm", scene_options["thickness_mm"])
    if scene_options.get("image_size") is not None:
        _check_whole("image_size", scene_options["image_size"], 1)
    folder = _scene_folder(folder)
    options = dict(seed=seed, px_per_mm=px_per_mm, n_stacks=n_stacks, max_layers=max_layers,
                   degradation=degradation, **scene_options)
    kwargs = {**DEGRADATIONS[degradation], **scene_options}
    try:
        scene = make_scene(seed=seed, px_per_mm=px_per_mm, n_stacks=n_stacks,
                           max_layers=max_layers, **kwargs)
    except SceneGenerationError as exc:
        # the generator's cause (Voronoi cells, layer counts) does not say which option to
        # change: name them
        raise SceneGenerationError(f"no scan for n_stacks={n_stacks}, max_layers={max_layers}, "
                                   f"px_per_mm={px_per_mm:g}, seed={seed} ({exc.cause}); try "
                                   "more stacks, fewer layers or another seed") from None
    try:
        written = write_scene(scene, folder)
    except OSError as exc:
        raise ConfigError(f"cannot write the scene folder ({exc.strerror or exc})",
                          folder) from None
    return GeneratedScan(Path(written), scene, options)


def _scene_folder(folder) -> Path:
    """``folder`` as a Path a scene folder can be written to (checked before a scan is
    generated, which takes up to a minute)."""
    import os

    from crosssection.core.errors import ConfigError, ParameterError

    if not isinstance(folder, (str, os.PathLike)) or not str(folder).strip():
        # Path("") is the current folder: a scene would be written among the caller's files
        raise ParameterError(f"folder must be a non-empty path, got {folder!r}")
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise ConfigError("exists and is not a folder (a scene folder is written there)", folder)
    for parent in folder.parents:
        if parent.exists():
            if not parent.is_dir():
                raise ConfigError(f"{parent} is a file, not a folder", folder)
            break
    return folder


def _is_whole(value, *, floats: bool = False) -> bool:
    """Whether ``value`` is a whole number: an integer, or with ``floats`` also a whole float
    such as 20.0 (taken where the value is only counted with, refused where numpy needs an
    int: seeds and array sizes). A bool is not one: True would be read as 1."""
    kind = numbers.Real if floats else numbers.Integral
    return (isinstance(value, kind) and not isinstance(value, bool)
            and math.isfinite(value) and value == int(value))


def _check_whole(name: str, value, lo: int, hi: int | None = None, *,
                 floats: bool = False) -> None:
    """Refuse ``value`` unless it is a whole number (:func:`_is_whole`) in ``[lo, hi]``."""
    from crosssection.core.errors import ParameterError

    if not (_is_whole(value, floats=floats) and lo <= value and (hi is None or value <= hi)):
        where = f"in {lo}-{hi}" if hi is not None else f">= {lo}"
        raise ParameterError(f"{name} must be a whole number {where}, got {value!r}")


def _check_positive(name: str, value) -> None:
    """Refuse ``value`` unless it is a finite number > 0."""
    from crosssection.core.errors import ParameterError

    if not isinstance(value, numbers.Real) or isinstance(value, bool):
        raise ParameterError(f"{name} must be a finite number > 0, got {value!r}")
    try:
        ok = math.isfinite(value) and value > 0
    except OverflowError:  # an int beyond the float range: its repr may run to any length
        raise ParameterError(f"{name} must be a finite number > 0, got a number beyond the "
                             "floating-point range") from None
    if not ok:
        raise ParameterError(f"{name} must be a finite number > 0, got {value!r}")


def _check_degradation(name) -> None:
    """Refuse ``name`` unless it is a key of :data:`DEGRADATIONS`."""
    from crosssection.core.errors import ParameterError

    if not isinstance(name, str) or name not in DEGRADATIONS:
        raise ParameterError(f"degradation must be one of {sorted(DEGRADATIONS)}, got "
                             f"{name!r}")


def _sequence(name: str, values) -> list:
    """``values`` as a list, refusing a single value (a string would be read letter by
    letter, a number not at all)."""
    from crosssection.core.errors import ParameterError

    if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
        raise ParameterError(f"{name} must be a sequence (a list of values), got {values!r}")
    return list(values)


def scan_grid(*, resolutions=(50.0,), layers=(4,), densities=(20,),
              degradations=("clean",), seed: int = 0) -> list:
    """Every combination of the given conditions, as ``pytest.param`` values (readable ids)
    for an indirect parametrisation of ``foldstat_scan``.

    Parameters
    ----------
    resolutions : sequence of float
        px/mm.
    layers : sequence of int
        ``max_layers``.
    densities : sequence of int
        ``n_stacks``.
    degradations : sequence of str
        Keys of :data:`DEGRADATIONS`.
    seed : int

    Returns
    -------
    list of pytest.param

    Raises
    ------
    ParameterError
        A condition :func:`make_generated_scan` refuses (checked here, at collection, not
        when the first test runs).
    """
    resolutions, layers, densities, degradations = (
        _sequence(name, values) for name, values in
        (("resolutions", resolutions), ("layers", layers), ("densities", densities),
         ("degradations", degradations)))
    _check_whole("seed", seed, 0)
    for r in resolutions:
        _check_positive("resolutions", r)
    for m in layers:
        _check_whole("layers", m, *MAX_LAYERS_RANGE, floats=True)
    for n in densities:
        _check_whole("densities", n, *N_STACKS_RANGE, floats=True)
    for d in degradations:
        _check_degradation(d)
    return [pytest.param(dict(seed=seed, px_per_mm=float(r), max_layers=int(m),
                              n_stacks=int(n), degradation=d),
                         id=f"{r:g}pxmm-{m}layers-{n}stacks-{d}")
            for r in resolutions for m in layers for n in densities for d in degradations]


def _cache_key(options: dict) -> str:
    return repr(sorted(options.items()))


if pytest is not None:
    @pytest.fixture(scope="session")
    def foldstat_scan_factory(tmp_path_factory):
        """``make(**options) -> GeneratedScan`` (keywords of :func:`make_generated_scan`);
        each distinct set of options is generated once per session."""
        cache = {}

        def make(**options) -> GeneratedScan:
            options = {**DEFAULT_SCAN, **options}
            key = _cache_key(options)
            if key not in cache:
                folder = tmp_path_factory.mktemp("foldstat_scan")
                cache[key] = make_generated_scan(folder, **options)
            return cache[key]

        return make

    @pytest.fixture
    def foldstat_scan(request, foldstat_scan_factory) -> GeneratedScan:
        """A generated scan with its truth (:class:`GeneratedScan`); parametrise indirectly
        with a dict of :func:`make_generated_scan` keywords or with :func:`scan_grid`.
        Default: :data:`DEFAULT_SCAN`."""
        return foldstat_scan_factory(**getattr(request, "param", {}))


# --------------------------------------------------------------------------- hypothesis

def scan_options(*, resolutions=(25.0, 50.0), max_layers=(MAX_LAYERS_RANGE[0], 6),
                 n_stacks=(10, 40), degradations=tuple(DEGRADATIONS)):
    """Hypothesis strategy of :func:`make_generated_scan` keywords.

    Parameters
    ----------
    resolutions : sequence of float
        px/mm to sample from.
    max_layers, n_stacks : (int, int)
        Inclusive ranges.
    degradations : sequence of str
        Keys of :data:`DEGRADATIONS`.

    Returns
    -------
    hypothesis.strategies.SearchStrategy of dict
    """
    from hypothesis import strategies as st

    return st.fixed_dictionaries({
        "seed": st.integers(0, 2**31 - 1),
        "px_per_mm": st.sampled_from([float(r) for r in resolutions]),
        "max_layers": st.integers(*max_layers),
        "n_stacks": st.integers(*n_stacks),
        "degradation": st.sampled_from(list(degradations)),
    })


def scenes(**bounds):
    """Hypothesis strategy of generated scans in memory
    (:class:`crosssection.truth.scene.Scene`: ``rgb``, truth ``summary`` and ``tables``,
    ``params``); option draws for which no layout exists are rejected.

    Parameters
    ----------
    **bounds
        Keywords of :func:`scan_options`.

    Returns
    -------
    hypothesis.strategies.SearchStrategy of Scene
    """
    from hypothesis import reject

    def build(options):
        from crosssection.truth.network import SceneGenerationError, make_scene

        options = dict(options)
        kwargs = {**DEGRADATIONS[options.pop("degradation")], **options}
        try:
            return make_scene(max_tries=8, **kwargs)
        except SceneGenerationError:
            reject()

    return scan_options(**bounds).map(build)


def analysis_params(**fixed):
    """Hypothesis strategy of valid :class:`crosssection.params.AnalysisParams`.

    Resolution 20-100 px/mm, h 0.05-0.3 mm (at least 1 px), every threshold, curvature and
    skeleton method and width statistic, integer refinement on or off, l_min 0.2-3 mm, merge
    distance 0-6 px, optional tangent length, s_min and plastic threshold.

    Parameters
    ----------
    **fixed
        Fields held at a given value (e.g. ``calibration="cal.csv"``).

    Returns
    -------
    hypothesis.strategies.SearchStrategy of AnalysisParams
    """
    from hypothesis import strategies as st

    from crosssection.params import CHOICE_PARAMS, AnalysisParams

    def opt(strategy):
        return st.none() | strategy

    fields = {
        "px_per_mm": st.floats(20.0, 100.0),
        "thickness_mm": st.floats(0.05, 0.3),
        **{name: st.sampled_from(names) for name, names in CHOICE_PARAMS.items()},
        "integer_refinement": st.booleans(),
        "layer_steps": st.booleans(),
        "hole_correction": st.booleans(),
        "l_min_mm": st.floats(0.2, 3.0),
        "merge_px": st.floats(0.0, 6.0),
        "tangent_mm": opt(st.floats(0.1, 0.9)),
        "s_min_mm2": opt(st.floats(0.1, 4.0)),
        "kappa_c_per_mm": opt(st.floats(0.5, 20.0)),
    }
    fields.update({k: st.just(v) for k, v in fixed.items()})
    return (st.fixed_dictionaries(fields)
            .filter(lambda f: f["px_per_mm"] * f["thickness_mm"] >= 1.0)
            .map(lambda f: AnalysisParams(**f)))


# --------------------------------------------------------------------------- batch workflow

def drawn_scan(seed: int, size: int = 420, *, ring_frac: float = 0.45, ring_px: int = 10,
               chord_px: tuple = (5, 16)):
    """A drawn RGB scan, uint8 (size, size, 3): a ring of blue ink and four chords across it
    of random widths in ``chord_px`` (px, upper bound excluded), on white paper. Draws in
    milliseconds, for tests that need many scans.

    Parameters
    ----------
    seed : int
        Whole number >= 0.
    size : int
        Side in px (>= 1).
    ring_frac : float
        Ring radius over the side (> 0).
    ring_px : int
        Ring line width in px (>= 1).
    chord_px : (int, int)
        Chord widths drawn from ``low`` (>= 1) up to ``high`` (> low, excluded).

    Raises
    ------
    ParameterError
        An argument outside these ranges.
    """
    import cv2
    import numpy as np

    from crosssection.core.errors import ParameterError

    _check_whole("seed", seed, 0)
    _check_whole("size", size, 1)
    _check_positive("ring_frac", ring_frac)
    _check_whole("ring_px", ring_px, 1)
    if not (isinstance(chord_px, (tuple, list)) and len(chord_px) == 2
            and all(_is_whole(w) for w in chord_px) and 1 <= chord_px[0] < chord_px[1]):
        raise ParameterError(f"chord_px must be a pair (low, high) of whole numbers with "
                             f"1 <= low < high (px), got {chord_px!r}")

    rng = np.random.default_rng(seed)
    img = np.full((size, size, 3), 250, np.uint8)
    c = size // 2
    r = int(size * ring_frac)
    ink = (190, 70, 40)  # BGR for cv2
    cv2.circle(img, (c, c), r, ink, thickness=ring_px)
    for _ in range(4):
        a, b = rng.uniform(0, 2 * np.pi, 2)
        p = (int(c + r * np.cos(a)), int(c + r * np.sin(a)))
        q = (int(c + r * np.cos(b)), int(c + r * np.sin(b)))
        cv2.line(img, p, q, ink, thickness=int(rng.integers(*chord_px)))
    return np.ascontiguousarray(img[:, :, ::-1])


def generated_scan(seed: int, size: int = 420):
    """A small RGB scan (about 12 stacks of 1-4 layers in a disk), uint8 (size, size, 3).

    The network generator's scene when it finds a layout in 5 tries, else :func:`drawn_scan`.

    Raises
    ------
    ParameterError
        ``seed`` not a whole number >= 0, or ``size`` not one >= 1.
    """
    from crosssection.truth.network import SceneGenerationError, make_scene

    _check_whole("seed", seed, 0)
    _check_whole("size", size, 1)

    try:
        return make_scene(seed=seed, n_stacks=12, max_layers=4, image_size=size,
                          max_tries=5).rgb
    except SceneGenerationError:
        return drawn_scan(seed, size)


def write_png(path: Path, rgb):
    """Save an RGB (or grey) uint8 array as PNG, creating the folder."""
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(rgb).save(path)


def write_calibration(path: Path, h=0.1):
    """Write a calibration CSV (n_layers,width_mm) of width 1.1 n h for 1-12 layers."""
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = "\n".join(f"{n},{n * h * 1.1:.4f}" for n in range(1, 13))
    path.write_text("n_layers,width_mm\n" + rows + "\n")


def make_scan_tree(root: Path, seed: int, *, bad=True) -> dict:
    """An input tree: a good set (with calibration and an override), loose images, and
    (``bad``) a corrupt file, a grayscale scan, a set with a bad set.toml and a set whose
    calibration is missing."""
    import numpy as np

    rng = np.random.default_rng(seed)
    seeds = rng.integers(0, 2**31, 6)
    good = root / "setA"
    write_calibration(good / "cal.csv")
    (good / "set.toml").write_text(
        'name = "alpha"\npx_per_mm = 50\nthickness_mm = 0.1\ncalibration = "cal.csv"\n'
        'bending_rigidity_J = 1e-4\n\n[images."s1.png"]\nrod_length_mm = 200.0\n')
    write_png(good / "s0.png", generated_scan(int(seeds[0])))
    write_png(good / "s1.png", generated_scan(int(seeds[1])))
    write_png(good / "sub" / "s2.png", generated_scan(int(seeds[2])))
    write_png(root / "loose.png", generated_scan(int(seeds[3])))
    expect_ok = ["loose.png", "setA/s0.png", "setA/s1.png", "setA/sub/s2.png"]
    expect_failed = {}
    if bad:
        (root / "corrupt.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"garbage" * 20)
        expect_failed["corrupt.png"] = None
        gray = generated_scan(int(seeds[4]))[:, :, 2]
        from PIL import Image

        Image.fromarray(gray).save(root / "gray.png")
        expect_failed["gray.png"] = None
        (root / "badset").mkdir()
        (root / "badset" / "set.toml").write_text('name = "beta"\npx_per_mm = "fifty"\n')
        write_png(root / "badset" / "b0.png", generated_scan(int(seeds[5])))
        expect_failed["badset/b0.png"] = "px_per_mm"
        (root / "nocal").mkdir()
        (root / "nocal" / "set.toml").write_text('name = "gamma"\ncalibration = "missing.csv"\n')
        write_png(root / "nocal" / "c0.png", generated_scan(int(seeds[0]) + 1))
        expect_failed["nocal/c0.png"] = "calibration"
    return {"ok": expect_ok, "failed": expect_failed}


def index_numbers(index):
    """The finished rows of a batch ``index.csv`` table, by image, with the summary numbers
    (to compare two runs)."""
    from crosssection import batch as B

    ok = index[index["status"] != "failed"].set_index("image").sort_index()
    return ok[["set", "output"] + B.SUMMARY_NUMBERS]


def partial_outputs(out: Path) -> list[Path]:
    """Leftovers of interrupted writes under a batch output (staging folders, temp files)."""
    from crosssection.core.fileio import PARTIAL_TAG

    return [p for p in out.rglob("*") if PARTIAL_TAG in p.name or p.name.endswith(".tmp")
            or (p.name.startswith(".") and p.is_file())]
