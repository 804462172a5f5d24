"""Stage 14: the whole per-image analysis, ``analyze(image) -> AnalysisResult``.

Paper, section "Image analysis procedure", stages in order (module = stage):
load (io) -> threshold -> clean -> skeleton -> junctions -> graph -> packs -> widths ->
linear system (linsys) -> curvature -> hole and regions -> voids -> branches and energies.

Orchestration choices (documented here, tested in tests/test_pipeline_contract.py):

- Thick crossings: after the first graph, junctions joined by a stack shorter than the sum of
  the inscribed ink radii at both ends (distance transform) are merged with that stack's pixels
  (``graph.short_junction_links``, ``junctions.merge_junctions``); the skeleton of an X of thick
  stacks becomes one junction of degree 4 instead of two Y joined by a bridge.
- Stack length: the node-to-node length of the skeleton path after a sliding average of
  ``smooth_px`` points (``StackGraph.length_px``; junction centre to junction centre, so the
  junction blob is not lost). Branch lengths in ``branches.csv`` are the same values, so that
  ``rod_length_mm = sum n_br * length_mm`` holds in both tables.
- Rod length L (paper: ``L = sum n_br l``) is measured; when ``rod_length_mm`` is given it is
  the L used for the dimensionless energies ``e = L int kappa^2 ds`` and for epsilon
  ``= L / (2 pi R)`` (R the hole radius in mm); the measured value stays in the summary.
- A scan without junction but with stacks (one closed loop) is analysed with a warning; an empty
  mask, nothing left after cleaning, or an empty skeleton raise ``AnalysisError``.
"""
from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core import schema
from crosssection._version import __version__
from crosssection.core.errors import AnalysisError, ConfigError, ImageError, ParameterError

__all__ = ["analyze", "AnalysisResult", "preprocess", "Preprocessed"]


# --------------------------------------------------------------------------- result
@dataclass
class AnalysisResult:
    """Everything ``analyze`` computed for one scan.

    Attributes
    ----------
    summary : dict
        ``schema.SUMMARY_KEYS`` plus thresholds, linear-system diagnostics, parameters,
        warnings, version, image info and per-stage ``timings_s``.
    junctions, stacks, branches, voids : DataFrame
        The tables (``schema`` columns first, extra columns after).
    graph : StackGraph
        Junctions and stacks with their pixel paths.
    hole : Hole
        Container wall (given or fitted).
    rgb : ndarray
        The scan.
    mask_threshold, mask_clean, skeleton : bool ndarrays
        Intermediate images (paper Fig. 2).
    junction_clusters : Junctions
        Junction pixels and label image.
    packs : dict
        Junction node -> Pack.
    linear_system : LinearSystemResult or None
    profiles : list of CurvatureProfile
    params : dict
        The parameters used (after defaults).
    path : str or None
        Image file.
    """

    summary: dict
    junctions: pd.DataFrame
    stacks: pd.DataFrame
    branches: pd.DataFrame
    voids: pd.DataFrame
    graph: object
    hole: object
    rgb: np.ndarray
    mask_threshold: np.ndarray
    mask_clean: np.ndarray
    skeleton: np.ndarray
    junction_clusters: object = None
    packs: dict = field(default_factory=dict)
    linear_system: object = None
    profiles: list = field(default_factory=list)
    params: dict = field(default_factory=dict)
    path: str | None = None

    @property
    def tables(self) -> dict:
        """``{"junctions", "stacks", "branches", "voids"}`` -> DataFrame."""
        return {"junctions": self.junctions, "stacks": self.stacks,
                "branches": self.branches, "voids": self.voids}

    @property
    def thickness_px(self) -> float:
        return float(self.params["thickness_mm"]) * float(self.params["px_per_mm"])

    def write(self, out_dir, figure: bool = True, *, steps: bool = False) -> dict:
        """Write ``summary.json``, the four CSV tables and (optionally) ``overlay.png``.

        Parameters
        ----------
        out_dir : str or Path
            Created if needed. Files are written atomically; ``summary.json`` last.
        figure : bool
            Also write ``overlay.png`` (paper Figs. 1c and 9a).
        steps : bool
            Also write the step images of paper Fig. 2 (see :meth:`write_steps`).

        Returns
        -------
        dict
            Name -> written path.
        """
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {}
        if figure:
            from crosssection.figures import overlay_figure
            from crosssection.core.fileio import save_figure

            t0 = time.perf_counter()
            fig = overlay_figure(self.rgb, self, thickness_px=self.thickness_px)
            paths["overlay"] = save_figure(fig, out / "overlay.png")
            self.summary.setdefault("output_timings_s", {})["overlay_figure"] = \
                time.perf_counter() - t0
        if steps:
            paths.update(self.write_steps(out))
        paths.update(schema.write_tables(out, self.summary, self.tables))
        return paths

    def write_steps(self, out_dir, *, figure: bool = True) -> dict:
        """Save the processing steps of paper Fig. 2 as PNG images.

        Writes ``step1_raw.png`` (the scan), ``step2_threshold.png``, ``step3_clean.png``
        (ink black on white), ``step4_skeleton.png`` (skeleton black, junctions as red
        circles), all at the scan's resolution, and ``steps.png`` (the four side by side,
        ``figures.steps_figure``) when ``figure``.
        """
        return write_step_images(out_dir, self.rgb, self.mask_threshold, self.mask_clean,
                                 self.skeleton, self.graph_junction_centers(), figure=figure)

    def graph_junction_centers(self) -> np.ndarray:
        if self.junction_clusters is not None:
            return np.asarray(self.junction_clusters.centers_rc, float).reshape(-1, 2)
        return np.zeros((0, 2))


def write_step_images(out_dir, rgb, mask_threshold, mask_clean, skeleton, junction_centers_rc,
                      *, figure: bool = True) -> dict:
    """Write the four step images of paper Fig. 2 (see ``AnalysisResult.write_steps``)."""
    import cv2

    from crosssection.core.fileio import atomic_path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}

    def save(name, img):
        p = out / name
        with atomic_path(p) as tmp:
            if not cv2.imwrite(str(tmp), img):
                raise ImageError("cannot write image", p)
        paths[name[:-4]] = p

    raw = np.asarray(rgb)
    save("step1_raw.png", np.ascontiguousarray(raw[..., ::-1]))
    save("step2_threshold.png", np.where(mask_threshold, 0, 255).astype(np.uint8))
    save("step3_clean.png", np.where(mask_clean, 0, 255).astype(np.uint8))
    sk = np.full(skeleton.shape + (3,), 255, np.uint8)
    sk[np.asarray(skeleton, bool)] = 0
    rad = max(3, int(round(max(skeleton.shape) / 300)))
    for r, c in np.asarray(junction_centers_rc, float).reshape(-1, 2):
        cv2.circle(sk, (int(round(c)), int(round(r))), rad, (0, 0, 255), 1, cv2.LINE_AA)
    save("step4_skeleton.png", sk)
    if figure:
        from crosssection.figures import steps_figure
        from crosssection.core.fileio import save_figure

        fig = steps_figure(raw, mask_threshold, mask_clean, skeleton, junction_centers_rc)
        paths["steps"] = save_figure(fig, out / "steps.png")
    return paths


# --------------------------------------------------------------------------- helpers
class _Timer:
    def __init__(self):
        self.t = {}

    @contextmanager
    def __call__(self, name):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.t[name] = self.t.get(name, 0.0) + time.perf_counter() - t0


def _positive(name, value, *, allow_none=True, allow_zero=False, path=None):
    if value is None:
        if allow_none:
            return None
        raise ParameterError(f"{name} is required", path)
    if isinstance(value, bool):
        raise ParameterError(f"{name} must be a number, got {value!r}", path)
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number, got {value!r}", path) from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ParameterError(f"{name} must be a finite number {'>=' if allow_zero else '>'} 0, "
                             f"got {value!r}", path)
    return v


def _load_calibration(calibration, thickness_mm):
    from crosssection.stages.widths import Calibration

    if calibration is None:
        return Calibration.linear(thickness_mm, n_max=50), "linear n*h"
    if isinstance(calibration, (str, Path)):
        return Calibration.from_csv(calibration), str(calibration)
    if hasattr(calibration, "layers"):
        return calibration, type(calibration).__name__
    if not isinstance(calibration, pd.DataFrame) and hasattr(calibration, "to_frame"):
        calibration = calibration.to_frame()  # e.g. synthetic.SyntheticCalibration
    if isinstance(calibration, pd.DataFrame):
        cols = {str(c).strip().lower(): c for c in calibration.columns}
        if "n_layers" in cols and "width_mm" in cols:
            return Calibration(tuple(calibration[cols["n_layers"]].astype(float)),
                               tuple(calibration[cols["width_mm"]].astype(float))), "DataFrame"
    raise ConfigError(f"calibration must be a CSV path or a Calibration, got "
                      f"{type(calibration).__name__}")


@dataclass
class Preprocessed:
    """Stages 1-6 of one scan (what the ``steps`` command needs)."""

    rgb: np.ndarray
    threshold: object
    mask_clean: np.ndarray
    skeleton: np.ndarray
    junctions: object
    graph: object
    distance_px: np.ndarray
    path: str | None
    s_min_px: float
    speck_px: float
    l_min_px: float
    warnings: list
    merged_links: int


def _image_and_path(image):
    from crosssection.stages.load import as_rgb, load_image

    if isinstance(image, (str, Path)):
        return load_image(image), str(image)
    if isinstance(image, np.ndarray):
        return as_rgb(image), None
    raise ImageError(f"image must be a file path or an RGB array, got {type(image).__name__}")


def preprocess(image, *, px_per_mm: float = 50.0, thickness_mm: float = 0.1,
               blue_min=None, rg_max=None, threshold_method: str = "fixed",
               s_min_mm2=None, l_min_mm: float = 1.0, merge_px: float = 2.0,
               merge_thick_crossings: bool = True, timer=None) -> Preprocessed:
    """Stages 1-6: load, threshold, clean, skeleton, junctions and stack graph.

    Parameters are those of :func:`analyze`. Raises ``ImageError``, ``ParameterError`` or
    ``AnalysisError`` (empty mask, nothing left after cleaning, empty skeleton).
    """
    import cv2

    from crosssection.stages.clean import clean_mask
    from crosssection.stages.graph import build_stack_graph, short_junction_links
    from crosssection.stages.junctions import find_junctions, merge_junctions
    from crosssection.stages.skeleton import skeletonize_mask
    from crosssection.stages.threshold import threshold_rgb

    timer = timer or _Timer()
    px_per_mm = _positive("px_per_mm", px_per_mm, allow_none=False)
    thickness_mm = _positive("thickness_mm", thickness_mm, allow_none=False)
    l_min_mm = _positive("l_min_mm", l_min_mm, allow_none=False, allow_zero=True)
    s_min_mm2 = _positive("s_min_mm2", s_min_mm2, allow_zero=True)
    merge_px = _positive("merge_px", merge_px, allow_none=False, allow_zero=True)
    warnings = []
    with timer("load"):
        rgb, path = _image_and_path(image)
    h, w = rgb.shape[:2]
    thickness_px = thickness_mm * px_per_mm
    if s_min_mm2 is None:
        s_min_mm2 = (10.0 * thickness_mm) ** 2  # paper: s_min = (10 h)^2
    s_min_px = s_min_mm2 * px_per_mm ** 2
    l_min_px = l_min_mm * px_per_mm
    if s_min_px >= h * w:
        raise ParameterError(f"s_min = {s_min_mm2:g} mm^2 = {s_min_px:.0f} px is not smaller "
                             f"than the image ({w}x{h} px = {h * w} px)", path)
    if thickness_px >= min(h, w) / 2:
        raise ParameterError(f"sheet thickness {thickness_mm:g} mm = {thickness_px:.1f} px is "
                             f"not small against the image ({w}x{h} px); check px_per_mm and "
                             "thickness_mm", path)
    if l_min_px >= max(h, w):
        raise ParameterError(f"l_min = {l_min_mm:g} mm = {l_min_px:.0f} px exceeds the image "
                             f"size ({w}x{h} px)", path)
    if thickness_px < 2:
        warnings.append(f"sheet thickness is {thickness_px:.2f} px: layer counts from widths "
                        "will be unreliable")
    with timer("threshold"):
        thr = threshold_rgb(rgb, blue_min=blue_min, rg_max=rg_max, method=threshold_method)
    frac = np.count_nonzero(thr.mask) / thr.mask.size
    if frac == 0:
        raise AnalysisError(
            f"empty mask: no pixel has blue >= {thr.blue_min} and red, green <= {thr.rg_max} "
            f"({thr.method} threshold); not a blue-ink scan, or adjust blue_min/rg_max", path)
    if frac > 0.95:
        raise AnalysisError(f"{100 * frac:.0f} % of the image passes the threshold: no "
                            "background to separate stacks (all-ink image?)", path)
    speck_px = min(s_min_px, l_min_px * thickness_px) if l_min_px > 0 else s_min_px
    with timer("clean"):
        mask = clean_mask(thr.mask, s_min_px=s_min_px, speck_px=speck_px)
    n_ink = np.count_nonzero(mask)
    if n_ink == 0:
        raise AnalysisError(f"nothing left after cleaning: every ink component is smaller than "
                            f"{speck_px:.0f} px", path)
    if n_ink > 0.95 * mask.size:
        raise AnalysisError("the cleaned mask covers the whole image: no void or background "
                            "to delimit stacks", path)
    with timer("skeleton"):
        skel = skeletonize_mask(mask, l_min_px=l_min_px)
    if not skel.any():
        raise AnalysisError("empty skeleton", path)
    with timer("junctions"):
        junc = find_junctions(skel, merge_px=merge_px)
    with timer("graph"):
        sg = build_stack_graph(skel, junc)
    with timer("distance"):
        dist = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    merged = 0
    if merge_thick_crossings and len(junc):
        with timer("graph"):
            for _ in range(3):
                radius = np.array([float(dist[p[:, 0], p[:, 1]].max()) for p in junc.pixels])
                links = short_junction_links(sg, radius)
                if not links:
                    break
                groups = [sg.ends[s] for s in links]
                junc = merge_junctions(junc, groups, [sg.paths[s] for s in links])
                sg = build_stack_graph(skel, junc)
                merged += len(links)
    if sg.n_stacks == 0:
        raise AnalysisError("the skeleton has no stack (only isolated points)", path)
    if len(junc) == 0:
        warnings.append("no junction found: every stack is a closed loop or a free segment")
    return Preprocessed(rgb=rgb, threshold=thr, mask_clean=mask, skeleton=skel, junctions=junc,
                        graph=sg, distance_px=dist, path=path, s_min_px=s_min_px,
                        speck_px=speck_px, l_min_px=l_min_px, warnings=warnings,
                        merged_links=merged)


def _mid_points(paths) -> np.ndarray:
    out = np.full((len(paths), 2), np.nan)
    for i, p in enumerate(paths):
        if len(p) == 0:
            continue
        p = np.asarray(p, float)
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
        k = int(np.searchsorted(s, 0.5 * s[-1]))
        out[i] = p[min(k, len(p) - 1)]
    return out


# --------------------------------------------------------------------------- analyze
def analyze(image, *, px_per_mm: float = 50.0, thickness_mm: float = 0.1,
            hole_radius_mm=None, hole_center_px=None, calibration=None, rod_length_mm=None,
            blue_min=None, rg_max=None, threshold_method: str = "fixed", s_min_mm2=None,
            l_min_mm: float = 1.0, kappa_c_per_mm=None, tangent_mm=None,
            bending_rigidity_J=None, smooth_px=None, merge_px: float = 2.0,
            merge_thick_crossings: bool = True, seed=None) -> AnalysisResult:
    """Analyse one scan of a cut cross-section (paper, "Image analysis procedure").

    Parameters
    ----------
    image : str, Path or ndarray
        Image file (PNG, TIFF 8/16-bit, JPEG) or an (H, W, 3) RGB array.
    px_per_mm : float
        Scan resolution (paper: 50).
    thickness_mm : float
        Sheet thickness h (paper: 0.1).
    hole_radius_mm : float, optional
        Radius R of the hole; fitted to the outer envelope of the ink when not given.
    hole_center_px : (x, y), optional
        Hole centre in pixels (x = column, y = row); fitted when not given.
    calibration : str, Path or Calibration, optional
        Width of a stack of n layers (CSV ``n_layers,width_mm``); default width = n h.
    rod_length_mm : float, optional
        Known rod length L, used for the dimensionless energies and epsilon instead of the
        measured ``sum n_br l``.
    blue_min, rg_max : float, optional
        Threshold values in the image's native units (defaults: 100 and 130 for uint8).
    threshold_method : {"fixed", "otsu"}
    s_min_mm2 : float, optional
        Smallest void, mm^2 (default (10 h)^2).
    l_min_mm : float
        Detection limit of branch length (paper: 1 mm): spurs shorter than this are pruned.
    kappa_c_per_mm : float, optional
        Plastic threshold of the bending energy (branches.energy_density).
    tangent_mm : float, optional
        Length over which stack tangents are fitted at a junction (packs); default
        ``3 h`` (measured, see the code).
    bending_rigidity_J : float, optional
        B (J m); adds ``total_energy_J = e B / (2 L)`` to the summary (paper: E = B/2 int
        kappa^2 ds, e = E / (B / 2L)).
    smooth_px : int, optional
        Sliding-average window (points) for centerlines (default curvature.default_smooth_px).
    merge_px : float
        Junction pixels closer than this are one junction (junctions.find_junctions).
    merge_thick_crossings : bool
        Merge junctions joined by a stack inside one ink blob (module docstring).
    seed : int, optional
        Accepted for batch reproducibility records; the analysis is deterministic.

    Returns
    -------
    AnalysisResult

    Raises
    ------
    ImageError, ParameterError, ConfigError, AnalysisError
        One-line cause naming the file.
    """
    from crosssection.stages import branches as br
    from crosssection.stages import curvature as cv
    from crosssection.stages.hole import classify_regions, fit_hole, wall_tolerance_px
    from crosssection.linsys import solve_branch_counts
    from crosssection.stages.packs import compute_packs
    from crosssection.stages.voids import find_voids
    from crosssection.stages.widths import stack_widths_px

    t_start = time.perf_counter()
    timer = _Timer()
    path_hint = str(image) if isinstance(image, (str, Path)) else None
    hole_radius_mm = _positive("hole_radius_mm", hole_radius_mm, path=path_hint)
    rod_length_given = _positive("rod_length_mm", rod_length_mm, path=path_hint)
    kappa_c_per_mm = _positive("kappa_c_per_mm", kappa_c_per_mm, path=path_hint)
    tangent_mm = _positive("tangent_mm", tangent_mm, path=path_hint)
    bending_rigidity_J = _positive("bending_rigidity_J", bending_rigidity_J, path=path_hint)
    if hole_center_px is not None:
        try:
            hx, hy = (float(v) for v in hole_center_px)
        except (TypeError, ValueError):
            raise ParameterError(f"hole_center_px must be two numbers (x, y), got "
                                 f"{hole_center_px!r}", path_hint) from None
        if not (math.isfinite(hx) and math.isfinite(hy)):
            raise ParameterError(f"hole_center_px must be finite, got {hole_center_px!r}",
                                 path_hint)
        hole_center_px = (hx, hy)
    if smooth_px is not None:
        smooth_px = int(_positive("smooth_px", smooth_px, allow_none=False, path=path_hint))
    _positive("px_per_mm", px_per_mm, allow_none=False, path=path_hint)
    thickness_mm = _positive("thickness_mm", thickness_mm, allow_none=False, path=path_hint)
    cal, cal_source = _load_calibration(calibration, thickness_mm)

    pre = preprocess(image, px_per_mm=px_per_mm, thickness_mm=thickness_mm, blue_min=blue_min,
                     rg_max=rg_max, threshold_method=threshold_method, s_min_mm2=s_min_mm2,
                     l_min_mm=l_min_mm, merge_px=merge_px,
                     merge_thick_crossings=merge_thick_crossings, timer=timer)
    px_per_mm = float(px_per_mm)
    thickness_mm = float(thickness_mm)
    h_px = thickness_mm * px_per_mm
    path = pre.path
    rgb = pre.rgb
    H, W = rgb.shape[:2]
    sg, junc, mask = pre.graph, pre.junctions, pre.mask_clean
    warnings = list(pre.warnings)
    m = sg.n_stacks
    K = len(junc)

    # 8. widths -> continuous layer estimates (calibration, paper: nonlinear thickening)
    with timer("widths"):
        width_px = stack_widths_px(sg, pre.distance_px, junction_margin_px=2.0 * h_px)
        width_mm = width_px / px_per_mm
        layers_est = np.asarray(cal.layers(width_mm), dtype=float)
    # 7. packs
    with timer("packs"):
        if tangent_mm is not None:
            tangent_px = tangent_mm * px_per_mm
        else:
            # 3 h: measured best of 1.5-12 h on 6 generated scenes (1-12 layers, noise, blur,
            # JPEG): exact n_br on 100 % of the stack length, against 82-93 % at 2 h and
            # 60-84 % with twice the median width
            tangent_px = 3.0 * h_px
        packs = compute_packs(sg, tangent_px=tangent_px)
    # 9. linear system
    with timer("linear_system"):
        lin = solve_branch_counts(sg, packs, layers_est)
        n_br = np.asarray(lin.n_br, dtype=np.int64)
    # 10. curvature along the smoothed centerline, window 5 n_br h (paper)
    with timer("curvature"):
        profiles = []
        dist = pre.distance_px
        H, W = dist.shape

        def fork_radius(node):
            # inscribed ink radius at a junction: inside the fork the bands overlap and the
            # skeleton hooks into the junction, so its curvature there is not the sheet's.
            # Measured: total energy vs truth on simulator renders +225 % -> +34 % (mean of 3),
            # on generated Bezier networks -24 % -> -29 % (6 scenes)
            if sg.node_kind[node] != "junction":
                return 0.0
            r, c = np.round(sg.node_rc[node]).astype(int)
            return float(dist[min(max(r, 0), H - 1), min(max(c, 0), W - 1)])

        for sid in range(m):
            u, v = sg.ends[sid]
            trim = max(int(n_br[sid]) * h_px, fork_radius(u), fork_radius(v))
            profiles.append(cv.stack_curvature(
                sg.paths[sid], n_br=int(n_br[sid]), thickness_px=h_px, px_per_mm=px_per_mm,
                smooth_px=smooth_px, closed=(sg.node_kind[u] == "loop"), trim_px=trim))
        length_mm = np.asarray(sg.length_px, dtype=float) / px_per_mm
    rod_measured = float(np.sum(n_br * length_mm))
    L = rod_length_given if rod_length_given is not None else rod_measured
    # 12. hole and regions
    with timer("hole"):
        center_rc = None if hole_center_px is None else (hole_center_px[1], hole_center_px[0])
        radius_px = None if hole_radius_mm is None else hole_radius_mm * px_per_mm
        hole = fit_hole(mask, center_rc=center_rc, radius_px=radius_px, path=path)
        tol = wall_tolerance_px(sg, width_px, h_px)
        regions = classify_regions(sg, junc.centers_rc, hole, tol_px=tol)
    # 13. voids
    with timer("voids"):
        node_w = np.zeros(K)
        for sid, (u, v) in enumerate(sg.ends):
            wv = width_px[sid] if np.isfinite(width_px[sid]) else 0.0
            for node in (u, v):
                if node < K:
                    node_w[node] = max(node_w[node], wv)
        touch_px = (0.5 * float(np.percentile(node_w, 90)) if K else 0.0) + h_px
        voids = find_voids(mask, hole=hole, s_min_px=pre.s_min_px, px_per_mm=px_per_mm,
                           junction_centers_rc=junc.centers_rc, touch_px=touch_px)
    # 11. branches and energies
    with timer("branches"):
        branches = br.branch_table(np.arange(m), profiles, n_br, regions, rod_length_mm=L,
                                   kappa_c_per_mm=kappa_c_per_mm)
        # one length per stack in both tables (module docstring)
        branches["length_mm"] = length_mm[branches["stack_id"].to_numpy()] if len(branches) \
            else branches["length_mm"]
        stack_energy = np.array([br.bending_energy(p.kappa_per_mm, p.s_mm, rod_length_mm=L,
                                                   kappa_c_per_mm=kappa_c_per_mm)
                                 for p in profiles]) if m else np.zeros(0)
    # tables
    with timer("tables"):
        mids = _mid_points(sg.paths)
        ja = np.array([u if sg.node_kind[u] == "junction" else schema.NO_JUNCTION
                       for u, _ in sg.ends], dtype=np.int64)
        jb = np.array([v if sg.node_kind[v] == "junction" else schema.NO_JUNCTION
                       for _, v in sg.ends], dtype=np.int64)
        kind = ["loop" if sg.node_kind[u] == "loop" else
                ("junction" if (ja[i] >= 0 and jb[i] >= 0) else "free_end")
                for i, (u, _v) in enumerate(sg.ends)]
        stacks = pd.DataFrame({
            "stack_id": np.arange(m, dtype=np.int64),
            "junction_a": ja, "junction_b": jb,
            "length_mm": length_mm,
            "width_mm": width_mm,
            "n_br": n_br,
            "region": list(regions),
            "mid_x_px": mids[:, 1], "mid_y_px": mids[:, 0],
            "layers_est": layers_est,
            "fixed_by_width": np.asarray(lin.fixed_by_width, bool),
            "kappa_pm": [p.kappa_pm for p in profiles],
            "kappa_plus": [p.kappa_plus for p in profiles],
            "kappa_m": [p.kappa_m for p in profiles],
            "energy_per_branch": stack_energy,
            "kind": kind,
            "n_pixels": [len(p) for p in sg.paths],
        })
        deg = np.array([sg.degree(j) for j in range(K)], dtype=np.int64)
        pk_amb = [bool(getattr(packs.get(j), "ambiguous", False)) for j in range(K)]
        pk_ref = [bool(getattr(packs.get(j), "reference_dependent", False)) for j in range(K)]

        def side(j, name):
            p = packs.get(j)
            return " ".join(f"{s}.{e}" for s, e in getattr(p, name, [])) if p else ""

        # layer conservation under the geometric packs reported here (paper's junction
        # equation); the solve may have repartitioned a junction the widths contradict
        def residual(j):
            p = packs.get(j)
            if p is None:
                return 0
            return int(sum(n_br[s] for s, _ in p.side_a) - sum(n_br[s] for s, _ in p.side_b))

        comps = getattr(lin, "components", None) or []
        repart = {int(j) for c in comps for j in getattr(c, "repartitioned_junctions", [])}
        cons_res = [residual(j) for j in range(K)]
        junctions = pd.DataFrame({
            "junction_id": np.arange(K, dtype=np.int64),
            "x_px": junc.centers_rc[:, 1] if K else np.zeros(0),
            "y_px": junc.centers_rc[:, 0] if K else np.zeros(0),
            "n_stacks": deg,
            "pack_a": [side(j, "side_a") for j in range(K)],
            "pack_b": [side(j, "side_b") for j in range(K)],
            "ambiguous": pk_amb,
            "reference_dependent": pk_ref,
            "conservation_residual": cons_res,
            "conservation_ok": [r == 0 for r in cons_res],
            "repartitioned": [j in repart for j in range(K)],
            "n_pixels": [len(p) for p in junc.pixels],
        })
    n_branches = int(n_br.sum())
    total_energy = float(branches["energy"].sum()) if len(branches) else 0.0
    hole_radius_used_mm = hole.radius_px / px_per_mm
    epsilon = L / (2.0 * math.pi * hole_radius_used_mm) if hole_radius_used_mm > 0 else None
    if m and K and (deg >= 4).mean() > 0.2:
        warnings.append(f"{int((deg >= 4).sum())} of {K} junctions have degree >= 4 (paper: "
                        "about 1 %); check the threshold and the cleaning")
    if any(pk_amb):
        warnings.append(f"{sum(pk_amb)} junction(s) with ambiguous packs")
    if any(pk_ref):
        warnings.append(f"{sum(pk_ref)} junction(s) whose packs depend on the reference tangent")
    for f in lin.flags:
        if not str(f).startswith("disconnected"):
            warnings.append(f"linear system: {f}")
    if hole.fitted and hole_radius_mm is None:
        warnings.append("hole radius fitted to the ink envelope (pass hole_radius_mm to fix it)")
    timings = {k: round(v, 6) for k, v in timer.t.items()}
    lin_summary = lin.summary() if hasattr(lin, "summary") else {}
    summary = {
        "n_junctions": int(K),
        "n_stacks": int(m),
        "n_branches": n_branches,
        "n_voids": int(len(voids)),
        "mean_branches_per_stack": float(n_br.mean()) if m else 0.0,
        "rod_length_mm": rod_measured,
        "rod_length_used_mm": float(L),
        "rod_length_given": rod_length_given is not None,
        "epsilon": epsilon,
        "total_energy": total_energy,
        "hole": {**hole.as_summary(), "fitted": bool(hole.fitted),
                 "radius_mm": float(hole_radius_used_mm)},
        "timings_s": timings,
        "total_time_s": round(time.perf_counter() - t_start, 6),
        "n_junctions_by_degree": {str(int(d)): int(c) for d, c in
                                  zip(*np.unique(deg, return_counts=True))} if K else {},
        "n_loops": int(sum(1 for k in kind if k == "loop")),
        "n_free_end_stacks": int(sum(1 for k in kind if k == "free_end")),
        "thresholds": pre.threshold.as_summary(),
        "cleaning": {"s_min_px": pre.s_min_px, "speck_px": pre.speck_px,
                     "foreground_fraction": float(mask.mean())},
        "skeleton": {"l_min_px": pre.l_min_px, "n_pixels": int(pre.skeleton.sum()),
                     "merged_crossing_links": int(pre.merged_links)},
        "linear_system": lin_summary,
        "calibration": cal_source,
        "parameters": {
            "px_per_mm": px_per_mm, "thickness_mm": thickness_mm,
            "hole_radius_mm": hole_radius_mm,
            "hole_center_px": list(hole_center_px) if hole_center_px is not None else None,
            "calibration": cal_source, "rod_length_mm": rod_length_given,
            "blue_min": blue_min, "rg_max": rg_max, "threshold_method": threshold_method,
            "s_min_mm2": pre.s_min_px / px_per_mm ** 2, "l_min_mm": float(l_min_mm),
            "kappa_c_per_mm": kappa_c_per_mm, "tangent_mm": tangent_px / px_per_mm,
            "bending_rigidity_J": bending_rigidity_J, "smooth_px": smooth_px,
            "merge_px": float(merge_px), "merge_thick_crossings": bool(merge_thick_crossings),
            "seed": seed,
        },
        "warnings": warnings,
        "version": __version__,
        "image": {"path": path, "height_px": int(H), "width_px": int(W),
                  "dtype": str(rgb.dtype)},
    }
    if bending_rigidity_J is not None and L > 0:
        summary["total_energy_J"] = total_energy * bending_rigidity_J / (2.0 * L * 1e-3)
    params = dict(summary["parameters"])
    return AnalysisResult(
        summary=summary, junctions=junctions, stacks=stacks,
        branches=schema.check_table("branches", branches),
        voids=schema.check_table("voids", voids) if len(voids.columns) else
        schema.empty_table("voids"),
        graph=sg, hole=hole, rgb=rgb, mask_threshold=pre.threshold.mask, mask_clean=mask,
        skeleton=pre.skeleton, junction_clusters=junc, packs=packs, linear_system=lin,
        profiles=profiles, params=params, path=path)
