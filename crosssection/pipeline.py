"""The per-image analysis, ``analyze(image) -> AnalysisResult``: the stages of the paper's
"Image analysis procedure" (Adda-Bedia, Boudaoud, Boué, Deboeuf, "Statistical distributions in
the folding of elastic structures") composed in their order.

load -> threshold -> frame (hole) -> clean -> skeleton -> junctions and stack graph ->
widths -> packs -> linear system -> curvature -> regions -> voids -> branches -> tables ->
quality.

Each stage is a function of :mod:`crosssection.stages` (or :mod:`crosssection.linsys`) on
numpy arrays; parameters come from one :class:`~crosssection.params.AnalysisParams`. Choices
made here:

- The scan's frame: nothing outside the hole enters cleaning, skeleton or voids. The hole is
  the given one, or found in the scan (:mod:`crosssection.stages.hole`).
- Rod length L (paper: ``L = sum n_br l``) is measured; when ``rod_length_mm`` is given it is
  the L of the dimensionless energies ``e = L int kappa^2 ds`` and of epsilon ``= L / (2 pi
  R)``; the measured value stays in the summary.
- A scan without junction but with stacks (one closed loop) is analysed with a warning; an
  empty mask, nothing left after cleaning, or an empty skeleton raise ``AnalysisError``.
"""
from __future__ import annotations

import dataclasses
import functools
import time
import warnings as _warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from crosssection import quality
from crosssection import tables as tb
from crosssection._version import __version__
from crosssection.core.errors import AnalysisError, FoldstatError, ImageError, ParameterError
from crosssection.core.parallel import in_background, wait_all
from crosssection.core.provenance import input_record, library_versions, sha256_in_background
from crosssection.linsys import solve_branch_counts
from crosssection.params import LINEAR_CALIBRATION, AnalysisParams, scale_left_out
from crosssection.result import AnalysisResult, write_step_images
from crosssection.stages import curvature, hole as hole_stage, voids as void_stage
from crosssection.stages.clean import clean_mask, filled_in_discs
from crosssection.stages.graph import split_stacks, stack_graph, with_multigraph, without_stacks
from crosssection.stages.load import (Header, exif_orientation, load_image_oriented,
                                      recorded_header, rgb_and_opacity)
from crosssection.linsys.equations import conservation_equations
from crosssection.stages.packs import compute_packs
from crosssection.stages.skeleton import skeletonize_mask
from crosssection.stages.threshold import (BRIDGE_MAX_H_PX, bridge_broken_lines,
                                           colour_features, dark_marks, faint_band_ends,
                                           missed_ink,
                                           passes_at, threshold_rgb, _range_note)
from crosssection.stages.widthlaw import fit_width_law
from crosssection.stages.widths import (distance_map, layer_steps, stack_widths_px,
                                        width_profiles_px)

__all__ = ["analyze", "preprocess", "Preprocessed", "AnalysisResult", "write_step_images"]


class StageTimer:
    """Wall time per stage name (``summary.json`` ``timings_s``)."""

    def __init__(self):
        self.t: dict[str, float] = {}

    @contextmanager
    def __call__(self, name):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.t[name] = self.t.get(name, 0.0) + time.perf_counter() - t0


@dataclass
class Preprocessed:
    """Stages 1-6 of one scan (what the ``steps`` command needs)."""

    rgb: np.ndarray
    threshold: object
    hole: object
    hole_confidence: float | None
    ink_outside_fraction: float
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
    file_px_per_mm: float | None = None
    file_pages: int = 1
    #: the file's recorded resolutions (dpi) along x and y, when they differ (not square)
    file_dpi_xy: tuple | None = None
    exif_orientation: int = 1
    #: The threshold's feature (``blue - max(red, green)``) whose cut places the walls to a
    #: fraction of a pixel (None with the fixed thresholds, which cut several features).
    edge_feature: np.ndarray | None = None
    #: Ink that the scan's cut leaves out and a cut chosen on each part of the frame takes in
    #: (:func:`~crosssection.stages.threshold.missed_ink`; added to the threshold's mask),
    #: over the ink the scan's cut took in.
    ink_missed_fraction: float = 0.0
    #: Pixels inside the frame as dark as the ink in red and green but not ink (another
    #: pen, pencil, a shadow), in pieces, over the ink's
    #: (:func:`~crosssection.stages.threshold.dark_marks`).
    dark_marks_fraction: float = 0.0
    #: Pixels beside the ink darker than the ink, over the ink's (``marks_on_ink``).
    marks_on_ink_fraction: float = 0.0
    #: The pixels an alpha channel made transparent or partly, composited over white (None:
    #: every pixel opaque).
    see_through: np.ndarray | None = None
    #: Called without argument: waits for the voids of ``mask_clean``
    #: (:func:`~crosssection.stages.voids.scan_voids`, scanned on a thread; None: scan
    #: them when needed).
    void_scan: object = None
    #: Ink area (px, voids below s_min filled) of every isolated piece dropped for a skeleton
    #: shorter than l_min (``dropped_pieces``).
    dropped_piece_px: tuple = ()


def _read(image):
    """The scan, its path (None for an array), the EXIF orientation read with a PNG's
    pixels (None otherwise: :func:`~crosssection.stages.load.exif_orientation` reads it) and
    the mask of the pixels an alpha channel made see-through (None: all opaque)."""
    if isinstance(image, str) and not image.strip():
        # Path("") is the working folder, which the loader would name as a folder
        raise ImageError("empty image path: give the scan's file")
    if isinstance(image, (str, Path)):
        rgb, orientation, see_through = load_image_oriented(image, opacity=True)
        return rgb, str(image), orientation, see_through
    if isinstance(image, np.ndarray):
        rgb, see_through = rgb_and_opacity(image)
        # the result keeps the scan: never the caller's own array, which the caller may draw on
        return (rgb.copy() if np.shares_memory(rgb, image) else rgb), None, None, see_through
    hint = (" (an image object: pass numpy.asarray(image))"
            if hasattr(image, "__array_interface__") or hasattr(image, "__array__") else "")
    raise ImageError(f"image must be a file path or an RGB array, got {type(image).__name__}"
                     f"{hint}")


def _resolve_params(params, overrides, path) -> AnalysisParams:
    if params is None:
        return AnalysisParams.from_mapping(overrides, path=path)
    if isinstance(params, dict):
        return AnalysisParams.from_mapping({**params, **overrides}, path=path)
    if not isinstance(params, AnalysisParams):
        raise ParameterError(f"params must be an AnalysisParams or a dict of parameters, got "
                             f"{type(params).__name__} (keyword parameters go as px_per_mm=50)",
                             path)
    return AnalysisParams.from_mapping(overrides, path=path, base=params)


def _threshold_in_frame(rgb, p: AnalysisParams, path, timer, min_piece_px: float = 0.0):
    """Threshold, hole and frame: the ink inside the hole, the hole, the ink fraction left
    outside, the threshold's feature (the blue dominance, for the centreline's walls) and the
    fraction of ink the cut misses in pieces of ``min_piece_px`` or more where a cut chosen
    locally takes it in (where there are such pieces, what the local cuts take in is added
    to the ink: ``local_px``).

    A given hole frames the threshold directly; otherwise the whole scan is thresholded, the
    hole found (plate edge or ink envelope, with a confidence), and the threshold redone
    inside it, so a plate or a shadow around the hole never chooses the ink's cut.
    """
    given = p.hole_given and p.hole_center_px is not None
    with timer("threshold"):
        # the features of the scan, computed once for both thresholds
        m = dict(method=p.threshold_method, blue_min=p.blue_min, rg_max=p.rg_max,
                 features=colour_features(rgb))
        if not given:
            whole = threshold_rgb(rgb, **m)
    bounds = {k: v for k, v in (("blue_min", p.blue_min), ("rg_max", p.rg_max))
              if v is not None}
    if not given:
        _check_fraction(whole, path, rgb, bounds)
    with timer("hole"):
        if given:
            x, y = p.hole_center_px
            hole = hole_stage.Hole(np.array([y, x], float),
                                   float(p.scale.to_px(p.hole_radius_mm)), False)
        elif p.hole_given:
            hole = hole_stage.fit_hole(whole.mask, path=path,
                                       radius_px=p.scale.to_px(p.hole_radius_mm))
        else:
            hole = hole_stage.find_hole(rgb, whole.mask, path=path)
        try:
            inside = hole_stage.frame_mask(rgb.shape[:2], hole)
        except ParameterError as exc:
            if given:
                raise
            # the hole the scan was searched for: no option of the user's is at fault
            raise AnalysisError(f"the hole {'fitted' if p.hole_given else 'found'} in the "
                                f"scan is no hole of it ({exc.cause.split(': check')[0]}): "
                                "the scan may not hold the whole hole (a crop); give the hole "
                                "(hole_radius_mm and hole_center_px), or check px_per_mm",
                                path) from None
    with timer("threshold"):
        thr = threshold_rgb(rgb, region=inside, **m)
    with timer("hole"):
        if p.hole_given:
            # a radius given alone is fitted to the ink: a radius too short cuts the wall
            # band as a whole hole given off does
            hole, inside, thr = _checked_given_hole(rgb, hole, inside, thr, m, path,
                                                    correct=p.hole_correction)
            if not hole.replaced:
                hole, inside, thr = _checked_wide_hole(rgb, hole, inside, thr, m, path,
                                                       thickness_px=p.thickness_px,
                                                       correct=p.hole_correction)
        else:
            hole, inside, thr = _checked_found_hole(rgb, hole, inside, thr,
                                                    thickness_px=p.thickness_px)
    with timer("threshold"):
        n_px = 0
        if p.thickness_px < BRIDGE_MAX_H_PX:
            bridged, n_px = bridge_broken_lines(thr, m["features"], inside,
                                                min_piece_px=3.0 * p.thickness_px ** 2)
        if n_px:
            thr = dataclasses.replace(thr, mask=bridged, bridged_px=n_px)
        # the frame's margin holds the wall band's edge, not a plate the colour rule passed
        trimmed, n_cut = hole_stage.trim_margin(thr.mask, hole, features=m["features"],
                                                levels=(thr.ink_level, thr.paper_level))
        if n_cut:
            thr = dataclasses.replace(thr, mask=trimmed, n_outside=thr.n_outside + n_cut)
    if p.hole_given and not thr.mask.any() and threshold_rgb(rgb, **m).mask.any():
        (r0, c0), rad = hole.center_rc, p.scale.to_mm(hole.radius_px)
        raise ParameterError(f"no ink inside the given hole (radius {rad:.4g} mm, centre x = "
                             f"{c0:.0f}, y = {r0:.0f} px) while the scan holds some: check "
                             "hole_radius_mm and hole_center_px, and px_per_mm", path)
    _check_fraction(thr, path, rgb, bounds)
    n_in = np.count_nonzero(thr.mask)
    outside = thr.n_outside / (thr.n_outside + n_in) if n_in else 0.0
    with timer("threshold"):
        taken, missed = missed_ink(thr, m["features"], inside, thickness_px=p.thickness_px,
                                   min_piece_px=min_piece_px,
                                   disc=(*hole.center_rc, hole.radius_px))
        fraction = missed / n_in if n_in else 0.0
        # ink below the scan's cut where a local cut takes it in (the dark side of an unevenly
        # lit scan): the rest of the pipeline reads it as ink, where the ink_missed check
        # says so (below its limit the scan's cut is kept, pixel for pixel)
        if taken is not None and fraction > quality.INK_MISSED_LIMIT:
            thr = dataclasses.replace(thr, mask=thr.mask | taken,
                                      local_px=int(np.count_nonzero(taken)))
        # read by the quality checks alone: measured beside the cleaning
        marks = in_background(dark_marks, thr, m["features"], inside,
                              thickness_px=p.thickness_px)
    return thr, hole, outside, m["features"].dominance, fraction, marks


def _checked_given_hole(rgb, hole, inside, thr, m, path, *, correct=True):
    """A given hole that cuts the rod, replaced by the hole found in the scan when near it.

    A hole given by hand (a radius measured with a rule, a centre clicked on the scan) can be
    off by a millimetre; its circle then cuts the wall band, and every stack pressed against
    the wall is lost beyond it (an independent generator's scans with the radius 3 % short:
    rod length -12 %, exact n_br on 0.80 of the stack length). When ink lies beyond the
    given circle on more than :data:`~crosssection.stages.hole.GIVEN_CROSSED_LIMIT` of it
    (:func:`~crosssection.stages.hole.ink_across_circle`), the hole is looked for in the scan
    (:func:`~crosssection.stages.hole.find_hole`). One found with confidence, near the given
    one (:data:`~crosssection.stages.hole.GIVEN_NEAR_FRACTION`), crossed at most half as
    much and taking in beyond the given circle ink of the rod inside it
    (:func:`_beyond_joins_rod`) frames the ink better: it replaces the given hole (with
    ``correct`` False the given one is kept), and the ``hole_crossed`` check names both.
    Returns ``(hole, frame, threshold)``.
    """
    feats = m["features"]

    def crossed(h, t):
        return hole_stage.ink_across_circle(lambda r, c: passes_at(t, feats, r, c),
                                            rgb.shape, h)

    cut = crossed(hole, thr)
    if cut <= hole_stage.GIVEN_CROSSED_LIMIT:
        return hole, inside, thr
    whole = threshold_rgb(rgb, **m)
    if not whole.mask.any():
        return hole, inside, thr
    try:
        found = hole_stage.find_hole(rgb, whole.mask, path=path)
    except FoldstatError:
        return hole, inside, thr
    near = hole_stage.GIVEN_NEAR_FRACTION * hole.radius_px
    if (found.confidence < 0.5 or abs(found.radius_px - hole.radius_px) > near
            or np.hypot(*(found.center_rc - hole.center_rc)) > near):
        return hole, inside, thr
    frame = hole_stage.frame_mask(rgb.shape[:2], found)
    thr_found = threshold_rgb(rgb, region=frame, **m)
    if crossed(found, thr_found) > 0.5 * cut or not _beyond_joins_rod(thr_found.mask, hole):
        return hole, inside, thr
    if not correct:
        return (dataclasses.replace(hole, given_crossed=cut,
                                    alternative=(found.center_rc, float(found.radius_px))),
                inside, thr)
    found = dataclasses.replace(found, given_crossed=cut, replaced=True,
                                alternative=(hole.center_rc.copy(), float(hole.radius_px)))
    return found, frame, thr_found


def _checked_found_hole(rgb, hole, inside, thr, *, thickness_px):
    """A plate's edge found beyond the circle the ink is pressed against, across a surface
    darker than the paper: flagged (``hole_wide``), kept.

    A light rim or a bevel round the hole, paler than the plate, reads as paper: the plate's
    edge is then found at the rim's outer side (a light ring 20 px wide: a radius 19 px, 2.5 %,
    too large, at full confidence), while the ink is pressed against a circle 2 h or more
    inside it (:func:`~crosssection.stages.hole.given_hole_wide`) across a ring darker than
    the paper (:func:`~crosssection.stages.hole.rim_inside`). That circle is not the wall
    either where the wall band's thin stretches lie inside its widest ones (an independent
    generator's scans: 15 px inside the wall), so the hole found is kept and its
    ``envelope`` set, which the ``hole_wide`` check names. Paper in that ring is a rod lying
    away from its wall: nothing is flagged, as for a given hole with a plate's edge at its
    circle. Returns ``(hole, frame, threshold)``.
    """
    if not hole.reason.startswith("plate edge"):
        return hole, inside, thr
    env = hole_stage.given_hole_wide(thr.mask, hole, thickness_px=thickness_px)
    if env is None or not hole_stage.rim_inside(rgb, thr.mask, hole, env,
                                                thickness_px=thickness_px):
        return hole, inside, thr
    return dataclasses.replace(hole, envelope=env), inside, thr


def _checked_wide_hole(rgb, hole, inside, thr, m, path, *, thickness_px, correct=True):
    """A given hole wider than the wall the rod is pressed against, replaced by the plate's
    edge found there.

    A radius given too large reads epsilon low, and by more than the periphery's gap
    (:func:`~crosssection.stages.hole.wall_gap_max_px`) it leaves the wall band's junctions
    beyond the periphery's tolerance: every stack reads as bulk (a sample scan given 7 % too
    large and kept: 26 periphery stacks of 57 -> 0, epsilon 5.78 -> 5.39).
    :func:`~crosssection.stages.hole.given_hole_wide` tells such a hole by the ink's
    envelope. A plate's edge found in the scan (:func:`~crosssection.stages.hole.find_hole`)
    at that envelope is the wall: it replaces the given hole (with ``correct`` False the
    given one is kept). A plate's edge at the given circle makes it right (a loose rod, away
    from the wall). Without a plate, an envelope the ink lines on
    :data:`~crosssection.stages.hole.WIDE_LINED_MIN` of it is the wall and replaces the
    given hole; one lined less tells a hole given too wide from a rod lying away from its
    wall no better than the given one: it is kept. The ``hole_wide`` check names both.
    Returns ``(hole, frame, threshold)``.
    """
    env = hole_stage.given_hole_wide(thr.mask, hole, thickness_px=thickness_px)
    if env is None:
        return hole, inside, thr
    within = hole_stage.wide_tolerance_px(thickness_px)
    found = None
    try:
        whole = threshold_rgb(rgb, **m)
        if whole.mask.any():
            found = hole_stage.find_hole(rgb, whole.mask, path=path)
    except FoldstatError:
        found = None
    plate = (found is not None and found.confidence >= 0.5
             and found.reason.startswith("plate edge"))
    if plate and abs(found.radius_px - hole.radius_px) <= within \
            and np.hypot(*(found.center_rc - hole.center_rc)) <= within:
        return hole, inside, thr
    hole = dataclasses.replace(hole, envelope=env)
    at_envelope = plate and (abs(found.radius_px - env[1]) <= within
                             and np.hypot(*(found.center_rc - env[0])) <= within)
    # without a plate, ink lining a circle all round is pressed against the wall: that
    # circle is the wall (a loose rod lines no circle)
    lined = not plate and env[3] >= hole_stage.WIDE_LINED_MIN
    if not correct or not (at_envelope or lined):
        return hole, inside, thr
    if lined:
        found = hole_stage.Hole(np.asarray(env[0], float).copy(), float(env[1]), True,
                                float(env[3]), f"ink envelope, ink lines {100 * env[3]:.0f} % "
                                "of it")
    found = dataclasses.replace(found, replaced=True, envelope=env,
                                alternative=(hole.center_rc.copy(), float(hole.radius_px)))
    frame = hole_stage.frame_mask(rgb.shape[:2], found)
    return found, frame, threshold_rgb(rgb, region=frame, **m)


def _beyond_joins_rod(mask, hole) -> bool:
    """Whether most of the ink of ``mask`` beyond the circle of ``hole`` belongs to the rod
    inside it (the same 8-connected piece as ink within 0.8 of its radius).

    The rod is one sheet: a wall band that a circle drawn too small cuts goes on into the
    stacks that meet the wall, while a ring drawn round a right hole (a marker's, a plate's
    edge) lies apart from the rod, beyond paper.
    """
    n, labels = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
    rr, cc = np.nonzero(mask)
    if n < 2 or not len(rr):
        return True
    r0, c0 = (float(v) for v in hole.center_rc)
    d = np.hypot(rr - r0, cc - c0)
    lab = labels[rr, cc]
    beyond = lab[d > float(hole.radius_px) + hole_stage.FRAME_MARGIN_PX]
    if not len(beyond):
        return True
    rod = np.zeros(n, bool)
    rod[lab[d < 0.8 * float(hole.radius_px)]] = True
    return float(np.mean(rod[beyond])) >= 0.5


def preprocess(image, params: AnalysisParams | None = None, *, timer=None,
               **overrides) -> Preprocessed:
    """Stages 1-6: load, threshold, frame, clean, skeleton, junctions and stack graph.

    Parameters are those of :func:`analyze`. Raises ``ImageError``, ``ParameterError`` or
    ``AnalysisError`` (empty mask, nothing left after cleaning, empty skeleton).
    """
    path_hint = str(image) if isinstance(image, (str, Path)) else None
    p = _bounds_in_16_bits(_resolve_params(params, overrides, path_hint), image)
    try:
        pre = _preprocess(image, p, timer or StageTimer())
    except FoldstatError as exc:
        if exc.path is None and path_hint is not None:
            raise type(exc)(exc.cause, path_hint) from None
        raise
    # nothing of it runs on after it returns: the voids scanned on a thread are waited for
    scanned = pre.void_scan()
    return dataclasses.replace(pre, void_scan=lambda: scanned)


def _preprocess(image, p: AnalysisParams, timer) -> Preprocessed:
    with timer("load"):
        rgb, path, orientation, see_through = _read(image)
        header = recorded_header(path) if path is not None else Header(None, 1)
        if orientation is None:
            orientation = exif_orientation(path) if path is not None else 1
    try:
        return _preprocess_read(rgb, path, header, orientation, p, timer, see_through)
    except AnalysisError as exc:
        if header.pages <= 1:
            raise
        # a blank first page (a scanner's preview, a cover sheet) fails as an empty scan
        raise type(exc)(f"{exc.cause} (the file holds {header.pages} images and only the first "
                        "is read: save each scan as its own file)", exc.path) from None


def _preprocess_read(rgb, path, header: Header, orientation, p: AnalysisParams, timer,
                     see_through=None) -> Preprocessed:
    p.check_image(rgb.shape, path, file_px_per_mm=header.px_per_mm)
    s_min_px = p.scale.area_to_px2(p.s_min_used_mm2)
    l_min_px = p.scale.to_px(p.l_min_mm)
    speck_px = min(s_min_px, l_min_px * p.thickness_px) if l_min_px > 0 else s_min_px
    # missed ink counts in pieces of 10 h^2 or more (the cleaning's default speck, l_min h at
    # h = 0.1 mm), however small the cleaning is set: below that the rim of half-covered
    # pixels along every band counts (s_min_mm2 = 0 read 0.03-0.26 % on the sample scans)
    thr, hole, outside, dominance, missed, marks_later = _threshold_in_frame(
        rgb, p, path, timer, min_piece_px=max(speck_px, 10.0 * p.thickness_px ** 2))
    running = []  # the steps on a thread, waited for if this fails
    try:
        confidence = None if p.hole_given else hole.confidence
        with timer("clean"):
            # a blob too small to hold a branch of length l_min goes whatever its area
            mask = clean_mask(thr.mask, s_min_px=s_min_px, speck_px=speck_px,
                              min_extent_px=l_min_px,
                              sliver_length_px=l_min_px,
                              sliver_width_px=p.sliver_width_h * p.thickness_px)
        _check_clean(mask, speck_px, path)
        marks = marks_later()
        # the voids need the mask alone, the distances too, and the thinning needs no
        # distance (only the spurs' pruning after it): the three side by side
        voids = in_background(void_stage.scan_voids, mask, hole=hole, s_min_px=s_min_px)
        running.append(voids)
        with timer("distance"):
            distances = in_background(distance_map, mask)
        running.append(distances)
        with timer("skeleton"):
            try:
                skel = skeletonize_mask(mask, l_min_px=l_min_px, method=p.skeleton_method,
                                        distance_px=distances)
            except BaseException:
                distances()  # its error, first in the scan's order, is the one raised
                raise
        dist = distances()
        if not skel.any():
            raise AnalysisError("empty skeleton", path)
        with timer("graph"):
            # (the MultiGraph of the graph kept only: isolated pieces dropped make another)
            junc, sg, merged = stack_graph(skel, dist, merge_px=p.merge_px,
                                           merge_thick_crossings=p.merge_thick_crossings,
                                           thickness_px=p.thickness_px, with_graph=False)
        # unless they are all the ink (then the scan is refused as it stands, empty of stacks
        # after the cleaning or not)
        short = _isolated_short_pieces(sg, l_min_px)
        short = short if len(short) < sg.n_stacks else []
        dropped = ()
        with timer("graph"):
            if short:
                seeds = [tuple(sg.paths[sid][0]) for sid in short]
                mask = mask.copy()  # the voids are scanned on the mask as it was
                dropped = _drop_pieces(sg, short, skel, mask, dist)
                sg = without_stacks(sg, short)
                voids = functools.partial(_voids_without, voids, mask, seeds)
            else:
                sg = with_multigraph(sg)
        if sg.n_stacks == 0:
            raise AnalysisError("the skeleton has no stack (only isolated points)", path)
        notes = [] if len(junc) else ["no junction found: every stack is a closed loop or a band "
                                      "between two ends (on the wall or free)"]
        if short:
            notes.append(f"{len(short)} isolated piece(s) of ink whose skeleton is shorter than "
                         "l_min dropped (specks: no branch of the detection limit's length)")
        return Preprocessed(rgb=rgb, threshold=thr, hole=hole, hole_confidence=confidence,
                            ink_outside_fraction=float(outside), mask_clean=mask, skeleton=skel,
                            junctions=junc, graph=sg, distance_px=dist, path=path,
                            s_min_px=s_min_px, speck_px=speck_px, l_min_px=l_min_px,
                            warnings=notes, merged_links=merged,
                            file_px_per_mm=header.px_per_mm, file_pages=header.pages,
                            exif_orientation=orientation,
                            edge_feature=dominance if thr.dominance_min is not None else None,
                            ink_missed_fraction=float(missed), see_through=see_through,
                            file_dpi_xy=header.dpi_xy, dark_marks_fraction=marks.apart,
                            marks_on_ink_fraction=marks.on_ink, void_scan=voids,
                            dropped_piece_px=dropped)
    except BaseException as exc:
        wait_all(*running)
        try:
            marks_later()
        except BaseException as first:
            if first is not exc:  # the marks come first in the scan's order: so does their error
                raise first from None
        raise


#: the quality checks decided before the network is read: those ``steps`` reports
FRAME_CHECKS = ("pages", "see_through", "scale_assumed", "scale_mismatch", "non_square",
                "low_resolution", "ink_missed", "dark_marks", "marks_on_ink", "hole_fitted",
                "ink_outside_hole", "hole_crossed", "hole_wide", "hole_cut")


def _scale_assumed(pre: Preprocessed, scale_given: bool) -> bool:
    """A scan read at the default scale: no resolution given, none recorded in the file (an
    array records none)."""
    return not scale_given and pre.file_px_per_mm is None


def frame_flags(pre: Preprocessed, params: AnalysisParams, *, scale_given: bool = True) -> list:
    """The quality checks of :data:`FRAME_CHECKS` on stages 1-6 alone (``steps``): the
    file, the scale, the threshold and the hole, as :func:`analyze` reports them
    (``scale_given`` as there).

    Returns
    -------
    list of :class:`~crosssection.quality.QualityFlag`
    """
    from crosssection.core import schema

    flags = quality.assess(
        params=params, hole=pre.hole, hole_confidence=pre.hole_confidence,
        ink_outside_fraction=pre.ink_outside_fraction,
        ink_missed_fraction=pre.ink_missed_fraction, degrees=np.zeros(0, np.int64),
        stacks=schema.empty_table("stacks"), dark_marks_fraction=pre.dark_marks_fraction,
        marks_on_ink_fraction=pre.marks_on_ink_fraction,
        rod_length_mm=0.0, rod_measured_mm=0.0, ink_area_in_hole_mm2=0.0,
        calibration_max_width_mm=None, junctions=schema.empty_table("junctions"),
        image_shape=pre.rgb.shape, file_px_per_mm=pre.file_px_per_mm,
        file_pages=pre.file_pages, file_dpi_xy=pre.file_dpi_xy,
        border_ink_rc=_border_pixels(pre.mask_clean), see_through=pre.see_through,
        scale_assumed=_scale_assumed(pre, scale_given), scale_given=scale_given)
    return [f for f in flags if f.code in FRAME_CHECKS]


def _isolated_short_pieces(sg, l_min_px) -> list[int]:
    """Stacks with two free ends (an ink piece touching no other) shorter than ``l_min_px``.

    The rod's cross-section is one connected curve, and a branch shorter than the detection
    limit l_min is not measured (the paper's l_min = 1 mm): such a piece is a speck, a
    smear or a stain the cleaning kept for its area or extent, its skeleton pruned to a stub.
    Counted as a stack, its curvature is a parabola through a few pixels: one light-blue smear
    11 px across gave a 0.2 mm stack of two layers holding 49 % of a scan's bending energy.
    """
    if l_min_px <= 0:
        return []
    kind = sg.node_kind
    return [sid for sid, (u, v) in enumerate(sg.ends)
            if kind[u] == "end" and kind[v] == "end" and sg.length_px[sid] < l_min_px]


def _voids_without(scanned, mask, seeds):
    """The voids of ``mask``: those ``scanned`` (waited for) without the pieces dropped."""
    return void_stage.without_pieces(scanned(), mask, seeds)


def _drop_pieces(sg, stacks, skel, mask, dist) -> tuple:
    """Remove the ink pieces of ``stacks`` from the skeleton, the mask and the distance map,
    in place (the arrays this analysis made): each is its own connected piece of ink, a stack
    with two free ends being all the skeleton of its piece. Returns each piece's area, px."""
    areas = []
    for sid in stacks:
        path = sg.paths[sid]
        skel[path[:, 0], path[:, 1]] = False
        r, c = (int(v) for v in path[0])
        # the piece's 8-connected ink, as the skeleton's connectivity; its box bounds the rest
        area, _, _, (x, y, w, h) = cv2.floodFill(mask.view(np.uint8), None, (c, r), 0, flags=8)
        box = (slice(y, y + h), slice(x, x + w))
        dist[box][~mask[box]] = 0.0
        areas.append(int(area))
    return tuple(areas)


def _check_fraction(thr, path, rgb=None, given_bounds=None):
    frac = np.count_nonzero(thr.mask) / thr.mask.size
    if frac == 0:
        why = getattr(thr, "note", "") or "not a blue-ink scan, or adjust the threshold"
        if not getattr(thr, "note", "") and thr.method == "auto" and given_bounds:
            # the bounds the user gave the automatic cut are the likelier cause
            named = ", ".join(f"{k} = {v:g}" for k, v in given_bounds.items())
            why = f"not a blue-ink scan, or the bounds given ({named}) exclude its ink"
        elif not getattr(thr, "note", "") and thr.method != "auto" and thr.rg_max is not None:
            bounds = ", ".join(f"{k} = {v:g}" for k, v in (("blue_min", thr.blue_min),
                                                            ("rg_max", thr.rg_max))
                               if v is not None)
            units = ("16-bit units, 8-bit values times 257" if rgb is not None
                     and rgb.dtype == np.uint16 else "8-bit units")
            why = (f"not a blue-ink scan, or the threshold's bounds ({bounds}) exclude its ink "
                   f"(bounds in {units})")
        blue = _blue_share(rgb) if rgb is not None else 0.0
        # data of fewer bits than their type (9-bit values in uint16) look grey at 8 bits:
        # the threshold's note names the range, the likelier cause
        narrow = rgb is not None and bool(_range_note(rgb, None))
        if rgb is not None and not narrow and _achromatic(rgb):
            why = ("the image has no colour (red, green and blue equal to within 2 levels on "
                   "99.9 % of the pixels): a grayscale scan saved as RGB, or no ink at all? "
                   "scan in colour")
            # grey marks on lighter paper: the cut the threshold found for them reads them
            if getattr(thr, "options", ""):
                why += (", or read its dark marks with the paper's rule without its blue "
                        f"bound: {thr.options}")
        elif blue > 0.95:
            why = (f"{100 * blue:.0f} % of the image is ink-coloured (blue above red and "
                   "green): no paper around the ink to set the cut against (all-ink image?)")
        raise AnalysisError(f"empty mask: no pixel passes the {thr.method} threshold: {why}",
                            path)
    if frac > 0.95:
        raise AnalysisError(f"{100 * frac:.0f} % of the image passes the threshold: no "
                            "background to separate stacks (all-ink image?)", path)


def _blue_share(rgb) -> float:
    """Share of the pixels (every fourth row and column) whose blue exceeds both red and
    green by a tenth of the image's range: ink-coloured."""
    a = np.asarray(rgb)[::4, ::4].astype(np.float32)
    margin = 0.1 * (65535.0 if np.asarray(rgb).dtype == np.uint16 else 255.0)
    return float(np.mean(a[..., 2] - np.maximum(a[..., 0], a[..., 1]) > margin))


def _achromatic(rgb) -> bool:
    """Whether a scan carries no colour: its channels within 2 levels of each other on
    99.9 % of a sample of its pixels (only asked once the threshold found no ink)."""
    a = np.asarray(rgb)
    if a.ndim != 3 or not np.issubdtype(a.dtype, np.integer):
        return False
    step = max(1, int(np.sqrt(a.shape[0] * a.shape[1] / 250_000)))
    sub = a[::step, ::step].reshape(-1, a.shape[-1])[:, :3].astype(np.float64)
    if a.dtype.itemsize > 1:
        sub *= 255.0 / np.iinfo(a.dtype).max
    spread = sub.max(axis=1) - sub.min(axis=1)
    return bool(np.mean(spread <= 2.0) >= 0.999)


def _check_clean(mask, speck_px, path):
    n_ink = np.count_nonzero(mask)
    if n_ink == 0:
        raise AnalysisError(f"nothing left after cleaning: every ink component inside the hole "
                            f"is smaller than {speck_px:.0f} px", path)
    if n_ink > 0.95 * mask.size:
        raise AnalysisError("the cleaned mask covers the whole image: no void or background "
                            "to delimit stacks", path)


def _calibration(p: AnalysisParams):
    """The width law of the parameters: a CSV path, a Calibration, a table or the default
    n h (flagged by the quality checks)."""
    from crosssection.core.calibration import Calibration

    if p.calibration is None:
        return Calibration.linear(p.thickness_mm, n_max=50)
    # an object with a ``layers`` method serves as given (a law that is no table)
    cal = (p.calibration if hasattr(p.calibration, "layers")
           and not isinstance(p.calibration, (str, Path)) else Calibration.of(p.calibration))
    # a cut stack of one layer is about one sheet thick (the paper's calibration: 1.1-1.4 h);
    # a width law off by a factor of 10 is a unit or column error, not a calibration
    w1 = float(np.asarray(cal.width(1.0)).reshape(-1)[0])
    if not 0.1 * p.thickness_mm <= w1 <= 10.0 * p.thickness_mm:
        raise ParameterError(f"calibration {p.calibration_source()}: one layer is {w1:.3g} mm "
                             f"wide, not about the sheet thickness h = {p.thickness_mm:g} mm "
                             "(check its units and columns, and thickness_mm)")
    return cal


def analyze(image, params: AnalysisParams | None = None, *, warn: bool = True,
            image_sha256: str | None = None, scale_given: bool | None = None,
            **overrides) -> AnalysisResult:
    """Analyse one scan of a cut cross-section (paper, "Image analysis procedure").

    Parameters
    ----------
    image : str, Path or ndarray
        Image file (PNG, TIFF, JPEG, BMP or WebP: ``crosssection.core.schema.IMAGE_FORMATS``)
        or an RGB array: (H, W, 3), or (H, W, 4) with alpha (composited over white); uint8,
        uint16, float in [0, 1], or another integer type with values within 0..65535 (within
        0..255: read as 8-bit); any strides (:func:`~crosssection.stages.load.rgb_and_opacity`).
        The array is not modified.
    params : AnalysisParams or dict, optional
        Parameters (default: :class:`~crosssection.params.AnalysisParams` defaults).
    warn : bool
        Issue a warning per failed quality check (default). False leaves them in the result
        only (``result.quality``, ``summary["quality"]``): for callers that report the flags
        themselves, without ``warnings.catch_warnings``, whose filters are shared by all the
        threads of a process.
    image_sha256 : str, optional
        The file's SHA-256 when the caller has it (a batch hashes every scan as it plans):
        recorded in ``summary["inputs"]`` as given instead of hashed again.
    scale_given : bool, optional
        Whether the user gave the scan's resolution (the command line's ``--px-per-mm``, a
        set's ``px_per_mm``). By default: ``px_per_mm`` among ``overrides`` or in a dict
        ``params``, and an :class:`~crosssection.params.AnalysisParams` ``params`` built with
        a ``px_per_mm`` (any value, the default's included; one built from a mapping or a
        TOML file that holds it). A file that records no resolution read at the default scale
        is flagged (``scale_assumed``).
    **overrides
        Fields of :class:`~crosssection.params.AnalysisParams` overriding ``params``, e.g.
        ``px_per_mm=50, thickness_mm=0.1, calibration="cal.csv", hole_radius_mm=20``.

    Returns
    -------
    AnalysisResult

    Raises
    ------
    ImageError, ParameterError, ConfigError, AnalysisError
        One-line cause naming the file.

    Warns
    -----
    QualityWarning
        One warning (of a subclass naming the check) per failed quality check
        (:mod:`crosssection.quality`), unless ``warn`` is False.
    SetWarning
        The set the file belongs to (the nearest ``set.toml`` in its folder or above, or a
        ``calibration.csv`` beside an uncalibrated scan) holds a calibration, scale or hole
        other than the ones used, unless ``warn`` is False (the note is in
        ``summary["warnings"]`` either way): ``batch`` reads the set, this function only its
        parameters.
    """
    path_hint = str(image) if isinstance(image, (str, Path)) else None
    if not isinstance(warn, (bool, np.bool_)):
        raise ParameterError(f"warn must be True or False, got {warn!r}", path_hint)
    if scale_given is None:
        scale_given = (overrides.get("px_per_mm") is not None
                       or (isinstance(params, AnalysisParams) and not scale_left_out(params))
                       or (isinstance(params, dict) and params.get("px_per_mm") is not None))
    elif not isinstance(scale_given, (bool, np.bool_)):
        raise ParameterError(f"scale_given must be True, False or None, got {scale_given!r}",
                             path_hint)
    try:
        return _analyze(image, params, overrides, warn=warn, image_sha256=image_sha256,
                        scale_given=bool(scale_given))
    except FoldstatError as exc:
        if exc.path is None and path_hint is not None:
            raise type(exc)(exc.cause, path_hint) from None
        raise


def _analyze(image, params, overrides, *, warn: bool = True,
             image_sha256: str | None = None, scale_given: bool = True) -> AnalysisResult:
    t_start = time.perf_counter()
    timer = StageTimer()
    p = _bounds_in_16_bits(
        _resolve_params(params, overrides, str(image) if isinstance(image, (str, Path)) else None),
        image)
    cal = _calibration(p)  # a bad calibration file fails before any image work
    # hashed while it is analysed: the record names the content the results come from
    is_file = isinstance(image, (str, Path))
    hashing = sha256_in_background(image) if is_file and image_sha256 is None else None
    try:
        pre = _preprocess(image, p, timer)
    except BaseException:
        wait_all(hashing)
        raise
    running = [pre.void_scan, hashing]  # the steps on a thread, waited for if this fails
    try:
        if is_file:  # named once the scan is read: a file that is not fails alone
            from crosssection.setconfig import set_not_read

            note = set_not_read(image, p)
            if note:  # the same scan would read other numbers in a batch of its set
                pre = dataclasses.replace(pre, warnings=[*pre.warnings, note])
                if warn:
                    _warnings.warn(note, quality.SetWarning, stacklevel=3)
        hash_note = None
        if hashing is not None:
            image_sha256, hash_note = hashing()
        inputs = input_record(image, p.calibration, image_sha256=image_sha256,
                              image_hashed=is_file,
                              table=cal if p.calibration is not None else None)
        if hash_note:
            note = f"SHA-256 not recorded: {hash_note}"
            pre = dataclasses.replace(pre, warnings=[*pre.warnings, note])
            if warn:
                # user -> analyze -> _analyze: the warning points at the user's call
                _warnings.warn(f"{image}: {note}", quality.InputWarning, stacklevel=3)
        sg, h_px, scale = pre.graph, p.thickness_px, p.scale
        law, packs, width_mm = None, None, None
        edge = (None if pre.edge_feature is None else
                (pre.edge_feature, float(pre.threshold.dominance_min)))
        # the centrelines need no branch count: drawn beside the widths, the packs and the
        # linear system (again if the widths cut the graph's bands)
        lines_of = functools.partial(curvature.stack_centrelines, distance_px=pre.distance_px,
                                     thickness_px=h_px, smooth_px=p.smooth_px,
                                     method=p.curvature_method, edge=edge)
        lines = in_background(lines_of, sg)
        running.append(lines)
        with timer("widths"):
            # layers ending inside a band leave no junction: the band is cut where its width steps
            profiles = width_profiles_px(sg.paths, pre.distance_px)
            if p.calibration is None and p.width_law == "fitted":
                width_mm = _stack_widths_mm(sg, pre.distance_px, profiles, p)
                law, packs = _fitted_law(sg, width_mm, p)
                if law.ok:
                    cal = law.calibration()
            cuts = layer_steps(sg, pre.distance_px, lambda w: cal.layers(scale.to_mm(w)),
                               thickness_px=h_px, profiles=profiles) if p.layer_steps else {}
            if cuts:
                sg, profiles, packs, width_mm = split_stacks(sg, cuts), None, None, None
                pre = dataclasses.replace(pre, graph=sg)
                wait_all(lines)
                lines = in_background(lines_of, sg)
                running.append(lines)
            if width_mm is None:
                width_mm = _stack_widths_mm(sg, pre.distance_px, profiles, p)
            layers_est = np.asarray(cal.layers(width_mm), dtype=float)
        with timer("packs"):
            if packs is None:
                packs = compute_packs(sg, tangent_px=scale.to_px(p.tangent_used_mm))
        with timer("linear_system"):
            lin = solve_branch_counts(sg, packs, layers_est,
                                      integer_refinement=p.integer_refinement)
            n_br = np.asarray(lin.n_br, dtype=np.int64)
        with timer("curvature"):
            profiles = curvature.stack_profiles(sg, n_br, pre.distance_px, thickness_px=h_px,
                                                px_per_mm=p.px_per_mm, smooth_px=p.smooth_px,
                                                method=p.curvature_method, edge=edge,
                                                centrelines=lines())
        length_mm = scale.to_mm(np.asarray(sg.length_px, dtype=float))
        rod_mm = float(np.sum(n_br * length_mm))
        L = p.rod_length_mm if p.rod_length_mm is not None else rod_mm
        with timer("regions"):
            width_px = scale.to_px(width_mm)
            tol = hole_stage.wall_tolerance_px(sg, width_px, h_px)
            regions = hole_stage.classify_regions(sg, pre.junctions.centers_rc, pre.hole,
                                                  tol_px=tol, mask=pre.mask_clean,
                                                  gap_max_px=hole_stage.wall_gap_max_px(
                                                      width_px, h_px))
        faint = []
        thr = pre.threshold
        if pre.edge_feature is not None and thr.paper_level is not None:
            with timer("regions"):
                faint = faint_band_ends(sg, pre.edge_feature, paper_level=thr.paper_level[0],
                                        cut=thr.dominance_min, mask=pre.mask_clean, hole=pre.hole,
                                        width_px=width_px, thickness_px=h_px)
        with timer("voids"):
            scanned = (pre.void_scan() if pre.void_scan is not None else
                       void_stage.scan_voids(pre.mask_clean, hole=pre.hole, s_min_px=pre.s_min_px))
            voids = void_stage.void_table(scanned, px_per_mm=p.px_per_mm,
                                          junction_centers_rc=pre.junctions.centers_rc,
                                          touch_px=_touch_px(sg, width_px, h_px))
        with timer("branches"):
            branches, stack_energy = tb.branch_table(profiles, n_br, regions, length_mm,
                                                     rod_length_mm=L,
                                                     kappa_c_per_mm=p.kappa_c_per_mm)
        with timer("tables"):
            stacks = tb.stack_table(sg, length_mm=length_mm, width_mm=width_mm,
                                    layers_est=layers_est, n_br=n_br,
                                    fixed_by_width=lin.fixed_by_width, regions=regions,
                                    profiles=profiles, stack_energy=stack_energy)
            junctions = tb.junction_table(pre.junctions, sg, packs, n_br, lin)
        return _result(pre, p, cal, lin, packs, profiles, junctions, stacks, branches, voids, warn,
                       rod_mm, L, timer, t_start, inputs, law, faint, scale_given)
    except BaseException:
        wait_all(*running)
        raise


def _bounds_in_16_bits(p: AnalysisParams, image) -> AnalysisParams:
    """The threshold's bounds given in a float image's own scale (at most 1, as its values)
    in the 16-bit units the image is read in (:mod:`crosssection.stages.load`)."""
    if not (isinstance(image, np.ndarray) and image.dtype.kind == "f"):
        return p
    scaled = {k: v * 65535.0 for k, v in (("blue_min", p.blue_min), ("rg_max", p.rg_max))
              if v is not None and 0 <= v <= 1}
    return dataclasses.replace(p, **scaled) if scaled else p


def _stack_widths_mm(sg, distance_px, profiles, p: AnalysisParams) -> np.ndarray:
    """Each stack's width (mm) away from its ends."""
    return p.scale.to_mm(stack_widths_px(sg, distance_px, junction_margin_px=2 * p.thickness_px,
                                         statistic=p.width_statistic, profiles=profiles))


def _fitted_law(sg, width_mm, p: AnalysisParams):
    """The width law read from the scan's stacks and clear junctions
    (:mod:`crosssection.stages.widthlaw`), and the packs it read them from (kept, with the
    widths, when no stack is cut at a layer step)."""
    scale = p.scale
    packs = compute_packs(sg, tangent_px=scale.to_px(p.tangent_used_mm))
    hard, _, _, _ = conservation_equations(sg, packs)
    law = fit_width_law(width_mm, scale.to_mm(np.asarray(sg.length_px, dtype=float)),
                        [row for _, row in hard], thickness_mm=p.thickness_mm)
    return law, packs


def _inscribed_radius_px(distance_px, junctions) -> np.ndarray:
    """Radius of the ink disc inscribed at each junction: the largest distance to the paper
    within 2 px of its centre (the centre is a mean of junction pixels)."""
    out = np.zeros(len(junctions))
    rows, cols = distance_px.shape
    for i, (x, y) in enumerate(zip(junctions["x_px"].to_numpy(), junctions["y_px"].to_numpy())):
        r, c = int(round(y)), int(round(x))
        win = distance_px[max(r - 2, 0):min(r + 3, rows), max(c - 2, 0):min(c + 3, cols)]
        out[i] = float(win.max()) if win.size else 0.0
    return out


def _touch_px(sg, width_px, h_px) -> float:
    """How close a void's border must pass to a junction to count it (half the widest stack
    at the junction, 90th percentile over junctions, plus h)."""
    k = sum(1 for kind in sg.node_kind.values() if kind == "junction")
    node_w = np.zeros(k)
    for sid, (u, v) in enumerate(sg.ends):
        wv = width_px[sid] if np.isfinite(width_px[sid]) else 0.0
        for node in (u, v):
            if node < k:
                node_w[node] = max(node_w[node], wv)
    return (0.5 * float(np.percentile(node_w, 90)) if k else 0.0) + h_px


def _network_shares(lin, stacks) -> list[float]:
    """Each connected network's share of the measured rod ``sum n_br l`` (the linear
    system's components; the ``networks`` quality check)."""
    rod = (stacks["n_br"] * stacks["length_mm"]).to_numpy(float)
    total = float(rod.sum())
    if not total > 0:
        return []
    return [float(rod[np.asarray(info.stacks, np.int64)].sum()) / total
            for info in lin.components]


def _border_pixels(mask) -> np.ndarray:
    """(row, col) of the pixels set on the outermost rows and columns of a mask, (K, 2), in
    raster order (``np.argwhere`` of the mask on its frame).

    Only the four edges are read: 0.06 ms on a 2000x2000 mask, against 7 ms for
    ``np.argwhere`` over the whole mask and its frame.
    """
    m = np.asarray(mask, bool)
    H, W = m.shape
    if H < 3 or W < 3:  # every pixel is on an edge
        return np.argwhere(m)
    side = np.argwhere(m[1:-1, [0, -1]])  # the first and last columns of the rows between
    side[:, 0] += 1
    side[:, 1] *= W - 1
    top, bottom = np.flatnonzero(m[0]), np.flatnonzero(m[-1])
    return np.concatenate([np.column_stack([np.zeros_like(top), top]), side,
                           np.column_stack([np.full_like(bottom, H - 1), bottom])])


def _odd_steps(graph, n_br) -> list:
    """(row, col) of the layer steps where an odd number of layers ends: a rod end there."""
    at = {}
    for sid, (u, v) in enumerate(graph.ends):
        for node in (u, v):
            if graph.node_kind[node] == "step":
                at.setdefault(node, []).append(int(n_br[sid]))
    # layers ending at a step: the count on one side less the other's (sum of the sides'
    # counts, odd with them)
    return [tuple(float(x) for x in graph.node_rc[node]) for node, ns in sorted(at.items())
            if sum(ns) % 2]


def _result(pre, p, cal, lin, packs, profiles, junctions, stacks, branches, voids, warn,
            rod_mm, L, timer, t_start, inputs=None, law=None, faint=None,
            scale_given=True) -> AnalysisResult:
    """Summary, quality checks and warnings: the :class:`AnalysisResult` built in one place."""
    from crosssection.core import schema

    degrees = junctions["n_stacks"].to_numpy()
    ink_area_mm2 = p.scale.area_to_mm2(float(np.count_nonzero(pre.mask_clean)))
    radius_px = _inscribed_radius_px(pre.distance_px, junctions)
    flags = quality.assess(
        params=p, hole=pre.hole, hole_confidence=pre.hole_confidence,
        ink_outside_fraction=pre.ink_outside_fraction,
        ink_missed_fraction=pre.ink_missed_fraction, degrees=degrees, stacks=stacks,
        dark_marks_fraction=pre.dark_marks_fraction,
        marks_on_ink_fraction=pre.marks_on_ink_fraction,
        rod_length_mm=L, rod_measured_mm=rod_mm, ink_area_in_hole_mm2=ink_area_mm2,
        calibration_max_width_mm=_max_width_mm(cal, p), junctions=junctions,
        image_shape=pre.rgb.shape, file_px_per_mm=pre.file_px_per_mm,
        file_pages=pre.file_pages, file_dpi_xy=pre.file_dpi_xy,
        network_shares=_network_shares(lin, stacks),
        border_ink_rc=_border_pixels(pre.mask_clean), width_law=law,
        junction_radius_px=radius_px,
        junction_filled_px=filled_in_discs(
            pre.mask_clean, pre.threshold.mask,
            np.column_stack([junctions["y_px"].to_numpy(float),
                             junctions["x_px"].to_numpy(float)]), radius_px),
        see_through=pre.see_through, faint_ends=faint,
        calibration_one_layer_mm=_one_layer_mm(cal, p),
        void_areas_mm2=voids["area_mm2"].to_numpy() if "area_mm2" in voids else None,
        odd_steps=_odd_steps(pre.graph, stacks["n_br"].to_numpy()),
        dropped_pieces_mm2=[p.scale.area_to_mm2(a) for a in pre.dropped_piece_px],
        scale_assumed=_scale_assumed(pre, scale_given), scale_given=scale_given)
    notes = list(pre.warnings) + [f"linear system: {f}" for f in lin.flags
                                  if not str(f).startswith("disconnected")]
    summary = tb.summary(pre=pre, params=p, linear_system=lin, junctions=junctions,
                         stacks=stacks, branches=branches, voids=voids, rod_measured_mm=rod_mm,
                         rod_used_mm=L,
                         calibration_source=_calibration_source(p, law),
                         timings=timer.t, total_time_s=time.perf_counter() - t_start,
                         version=__version__, inputs=inputs, libraries=library_versions())
    if law is not None:
        summary["width_law"] = law.record()
    summary["quality"] = quality.quality_block(flags)
    summary["warnings"] = notes + [f.message for f in flags]
    where = pre.path or "<array>"
    for f in flags if warn else ():
        # user -> analyze -> _analyze -> _result: the warning points at the user's call
        _warnings.warn(f"{where}: {f.message}", f.category, stacklevel=4)
    return AnalysisResult(
        summary=summary, junctions=junctions, stacks=stacks, branches=branches,
        voids=schema.check_table("voids", voids) if len(voids.columns) else
        schema.empty_table("voids"),
        graph=pre.graph, hole=pre.hole, rgb=pre.rgb, mask_threshold=pre.threshold.mask,
        mask_clean=pre.mask_clean, skeleton=pre.skeleton, junction_clusters=pre.junctions,
        packs=packs, linear_system=lin, profiles=profiles, params=p, path=pre.path,
        quality=tuple(flags))


def _calibration_source(p: AnalysisParams, law) -> object:
    """``summary.json`` ``calibration``: the given one's record, or the law used without."""
    if p.calibration is not None:
        return p.calibration_record()
    if law is not None and law.ok:
        return f"fitted to the scan: {law.describe()}"
    return LINEAR_CALIBRATION


def _one_layer_mm(cal, p) -> float | None:
    """The given calibration's width of one layer (None without one, or for an object that
    is no table)."""
    if p.calibration is None or not hasattr(cal, "width"):
        return None
    try:
        w = float(np.asarray(cal.width(1.0), float).reshape(-1)[0])
    except (TypeError, ValueError, IndexError):
        return None
    return w if np.isfinite(w) and w > 0 else None


def _max_width_mm(cal, p) -> float | None:
    """Widest stack the calibration was measured on (None for the default law)."""
    if p.calibration is None or not hasattr(cal, "width_mm"):
        return None
    return float(np.max(cal.width_mm))


