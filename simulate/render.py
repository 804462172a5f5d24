"""Render simulated rods into synthetic scans with exact ground truth (``render`` subcommand).

Each stack of :func:`simulate.contacts.analyze_rod` is drawn as one blue band of width
``w(n_br)`` along the mean line of its passes, joined to its junctions (paper, section "Image
analysis procedure": branches in contact closer than the resolution form one band whose width
counts them). Voids show a light receding surface; the outside of the hole is the plate.
Colours, scan defects and the truth voids are those of every scene generator
(:mod:`crosssection.truth.ink`, :mod:`crosssection.truth.degrade`,
:mod:`crosssection.truth.backdrop`, :func:`crosssection.truth.voids.truth_voids`), and the
result is a :class:`crosssection.truth.scene.Scene`.

Scale and hole. A rod of finite thickness (``python -m simulate compact``: ``thickness`` and
``wall_radius`` in units of L in its params.json) is scanned as the experiment's sheet: the
thickness maps to ``thickness_mm`` (h = 0.1 mm, 5 px at 50 px/mm, paper "Image analysis
procedure"), so ``rod_length_mm = thickness_mm / thickness``, and the hole is the wall, centred
on the origin, of radius ``wall_radius * rod_length_mm``. With the compaction's default
h = 0.005 R this gives R = 20 mm (the experiments' R ~ 2 cm), images of about 2195 x 2195 px,
and h/L = 0.005 / (2 pi epsilon) = 4.2e-5 at epsilon = 19 (experiments 2.6e-5 to 2.1e-4,
paper Table 1). A rod without thickness (quench) has no physical scale: ``rod_length_mm`` is
the smallest for which passes farther apart than the contact cut-off delta show a gap, which
holds when ``delta * rod_length_mm >= (w(1) + w(n_max)) / 2 + gap_px / px_per_mm`` (worst
case: a single pass at distance delta from a stack of n_max coincident passes; about 150-250 mm
for N = 300 and the default delta = 0.5/N, images under ~2500 px), and its hole is the
smallest disk around the rod plus half the thickest band and 2 h.

Wall. Nothing lies beyond the wall, but a band drawn along the mean line of its passes at the
calibrated width (wider than n h) can cross it, and a junction where a pass leaves a band
pressed against the wall lies on the band's outer layer: a thick band ending there would poke
its round end out of the hole (up to 13 h at epsilon = 30). When the hole is the wall, every
junction is therefore kept half the widest band meeting there inside the wall, and every line
half its own band: the ink ends at the wall, as the cut sheets do.

Scan defects. Unless ``clean``, a render has the defects of a real scan at the middle of the
ranges of the typical scans the pipeline is validated on (:func:`simulate.atlas.typical_options`,
``benchmarks/robust_sweep.py``: noise 0-10, blur 0-1.5 px, JPEG 75/90/none, 0-20 specks,
0-5 smears, 0-10 pinholes, illumination gradient 0-15 %, colour cast 0-6 %, a plate with a
0 or 2 px rim): see :data:`SCAN_DEFECTS`. ``clean`` draws ink, paper and receding surfaces
only (:data:`CLEAN`); any single defect can be set either way. A render beyond those ranges
(a sheet thinner in pixels, or blur, noise or JPEG compression stronger than the typical
scans': :data:`VALIDATED_SHEET_PX` and the other ``VALIDATED_`` limits) is drawn with a
:class:`ScanRangeWarning`: the analysis is not validated there. So is a rod of fewer segments
than the renders' truth is validated from (:data:`VALIDATED_COMPACT_SEGMENTS` on a compaction,
:data:`VALIDATED_QUENCH_SEGMENTS` on a quench): on coarser compactions the drawn bands, and
with them the truth's stacks, hold another rod than the rod's.

Lines and energy. The rod is a chain of straight segments; its energy is that of the smooth
sheet it discretises (:func:`smooth_line`). A stack's band is drawn along the smooth curve
through its line (knots one segment apart), not along that polyline, whose corners (one per
segment: every 12 h at N = 2000 with the default h = 0.005 R) an image reads as concentrated
bending (the pipeline measures 2-6 times more energy on polylines at epsilon = 14-19); links
shorter than two segments are parabolas through their ends and middle (``smooth="long"``
leaves them polylines, ``"none"`` draws every polyline). The truth ``energy`` of a branch is
the rod's: its discrete ``sum dtheta^2 / ds``, the ``int kappa^2 ds`` of a curve turning by
dtheta over each segment, which the smooth curve reproduces along an arc (the tests). A
node that folds the rod back within one segment (turning by more than
:data:`simulate.ensemble.HAIRPIN_NODE_DEG`) is the exception: the discrete energy prices it at
up to ``4 / ds`` and no drawing shows it (the band ends where the fold lies). The scene's
summary records that share of its energy (``hairpin_energy_share``, :func:`hairpin_nodes`;
one quenched rod of 300 segments holds 44 % of its energy at one node).

Joining bands to junctions. A stack's line is the mean of its passes with the junction points
first and last, and a junction point, the mean of the run ends meeting there, lies at a band's
side: smoothed as it is (``join="junction"``), the line hooks into it, and the wandering
centroid near the junction adds cusps. On compacted rods the drawn curves' ``n_br int
kappa^2 ds`` is then 2.5e3 to 8e3 times the rod's energy at epsilon = 14-19 (1.1 to 1200 times
outside discs of the widest band's width around the junctions). ``join="hook"`` draws each
band along its own mean line, cleaned of those jumps and cut back half the widest band's width
at each junction, and smooths it into the junction point (:func:`_hooked_lines`): 3 to 8 times
the rod's energy in all, 1.05 to 1.8 times outside the discs, the bands still overlapping at
every junction, and the drawn rod (``sum n_br x length``) 1.02-1.16 L instead of 1.09-1.45 L.
A band is not joined to a junction point that its straight join would reach only across
more than :data:`PAPER_JOIN` of its own widths of paper (outside every band meeting there),
and an end not joined is not cut back: it ends where its passes end, inside the band they run
into when they do (cut back, such a one-pass band stopped 9 px short of the band it ends in,
and the two voids it closes opened into each other; 3 of 22 quench renders of 300 segments):
the mean of run ends lying far apart can sit where no pass of the band goes (400 segments,
seed 2: the drawn lines bend 78, 82 and 1.2 times as much as the rod at epsilon = 4, 6 and 8
when joined there, 24, 1.3 and 0.9 times when not; at epsilon = 19 a two-layer link drawn
across a thick band to its junction point read 95 000 against the rod's 330). A junction
point that only one band would still reach is not joined either: the hook would only curl
that band's end (a three-layer band's end curled into a point its neighbours no longer reach
read 3 200 against the rod's 86). ``join="hook"`` is the default for every rod. On 104
quench renders (N = 300; the robust sweep's renders, seeds 1-40, 100-131 and 200-231) the
analysis reads a median |energy error| of 14.8 % with it, 13.6 % with ``join="junction"``,
with half the outliers (9 beyond 50 % against 17, worst +372 % against +586 %; rod length
wrong by more than 5 % on 13 against 17; docs/validation/README.md, "The renders'
outliers"). The stacks shorter than their width still sit inside junction zones: neither
drawing is a usable truth for the energy, which stays the rod's.

Rod ends. A free end of the rod can lie inside a band: the band holds n passes on one side
of it and n - 1 on the other, and the contact analysis makes the two parts one stack of n
branches (:func:`simulate.contacts.analyze_rod`, two-ended junctions). Such a band is drawn
with the passes present (:func:`_rod_end_cuts`): the pass holding the rod end is laid along
the stack's line from the end its other end lies at, over its own length, and the band is
``w(n)`` wide there and ``w(n - 1)`` beyond, the wider piece cut square at the step (the last
layer ends at the rod end, not half a band width further). A band without a rod end inside
is drawn as it would be without this rule, bit for bit, and so is every scene without one.
The truth keeps the contact analysis' stack: ``n_br`` its branches (the rod pieces in the
band, so that ``n_branches`` is the branch table's length), ``width_mm`` ``w(n_br)`` (the
band's widest), its mid point the drawn line's; its ``length_mm`` is the mean drawn length
of its passes, which is the line's length for every band whose passes all run its whole
length (the contact analysis' own stack length is the mean of its branches'), so that
``sum(n_br * length_mm)`` is the rod drawn (1.003-1.012 L on the robust sweep's renders,
against 1.13 and 1.28 at two of them with the band drawn at n over its whole length;
docs/validation/compact.md, "A rod end inside a band"). The image analysis cuts such a
band at its layer step into two stacks; the truth's ``layer_pieces`` table holds the bands as
drawn, such a band as its pieces of one pass count (:data:`crosssection.truth.scene.LAYER_PIECES`),
against which :func:`crosssection.truth.scoring.score` matches the analysis' stacks. A fold inside a band (the same merge, a pass folding back
within the band) is not cut: that band is drawn at its larger count over its whole length.

Calibration. The generators' nonlinear law ``w(n) = h (n + 0.4 sqrt(n))``
(:meth:`crosssection.core.calibration.Calibration.nonlinear`), of the cutting tool's kind:
the paper calibrates the hot wire's nonlinear thickening of a stack by cutting stacks of
sheets ("Image analysis procedure"). It is written to ``calibration.csv`` so that the pipeline
inverts the law the bands were drawn with, as a user passes the tool's calibration.

Scene folders. :func:`render_directory` writes each scene with its ``set.toml``
(:func:`write_set_file`): the scale, ``calibration.csv`` and the hole its ``params.json``
records, in the form of :mod:`crosssection.setconfig`, so that ``foldstat batch SCENES``
analyses every scene as ``validate`` does; the scenes of one render are one set, named after
its folder (:func:`render_set_name`), each with its own hole.
The scoring reads ``params.json`` and ignores it.

Drawing the rod itself (``draw="passes"``, experimental). The bands drawing draws the truth's
stacks, not the rod: mean lines joined to junction points at a band's side, a band holding a
fold drawn at its larger layer count over its whole length, lumps where junctions cluster
(docs/validation/compact.md). ``draw="passes"`` draws each pass of the rod as a stroke
``pass_width`` h wide along the smooth curve through the rod's nodes (:func:`smooth_line`, one
knot per node), so that what is drawn is the rod and its length. The passes of a compacted
rod's stack lie 1.2-3 h apart (frictionless hard core): drawn as they lie they would show
paper between them, and a band's width would not count its passes. Every stack is therefore
pressed, cross-section by cross-section, into a band of touching strokes centred where its
passes were (:func:`_press_stack`); a pass occupies only the part of a stack it covers, so the
band narrows where a rod end lies inside it or a pass leaves it. Beyond its stack a pass returns
to its own position over ``pass_taper`` pass widths (raised cosine), and the displacements are
smoothed along the rod over one pitch (``pass_smooth`` rod segments when given) so that a
change of the passes present leaves no step.
Adjacent pressed strokes overlap by :data:`PASS_OVERLAP_PX` so that their rasterisation leaves
no paper line between them; the calibration is the drawing's own, linear law
``w(n) = n pitch + overlap`` with ``pitch = pass_width h - overlap``
(:func:`passes_calibration`; at 5 px per h: 6.25 px for one pass, 5.25 px per further pass).
The truth tables are the contact analysis' (stacks, junctions, branches, voids, the rod's
energy). A junction point, the mean of the run ends meeting there, lies where the pressed
passes part (the tip of the paper wedge between them), about half the trunk's width ahead of
the skeleton fork an image analysis finds there: with junctions matched within 3 h the mode
scores poorly on junctions for that reason, not for want of forks
(docs/validation/compact.md). A stack's truth line is its mean line, which can cover only part
of its passes, and its mid point is that line's; its length is the mean length of its passes
(the analysis'), each drawn at its own length, so that ``sum(n_br x length_mm)`` is the rod.

Truth checks. Every scene checks its truth against its drawing (:class:`TruthWarning`, also
listed as ``truth_warnings`` in its summary): a truth junction farther from the ink than the
scoring's match radius (3 h) or the widest band there is moved onto the ink of its stacks
(:func:`_junctions_onto_ink`; a loop stack's junction point, the mean of run ends lying far
apart, can sit on the paper); the bands of a junction that do not touch (the hook rules left
the rod cut there, :func:`_disconnected_junctions`) or that join elsewhere but do not all
touch at the junction (within the widest band's width of its point or of their ends there,
:func:`_apart_junctions`: the image has no junction there and the voids they bound open into
each other); a truth whose void count is not the rod's (the contact analysis' voids of at
least s_min, allowing for the bands' width, :func:`_void_count_check`); a truth whose stacks
hold a rod
``sum(n_br x length_mm)`` more than :data:`TRUTH_LENGTH_TOLERANCE` away from the rod's length;
a truth stack of length 0; pieces the truth holds apart whose bands touch in the drawing
(:func:`_touching_pieces`: passes closer than delta over a contact shorter than the contact
analysis' shortest run, such as a rod end brushing the rod, are no stack and are drawn at their
distance). ``gap_guaranteed`` in a scene's params.json promises that passes farther apart than
delta show a gap (the scale, above) and that no such pieces touch; it is false otherwise.

Coordinates: column = x, row = y (no flip), so the image is the mirror image of a plot with y
up; signed curvatures therefore compare in absolute value.
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from crosssection.core import polyline, schema
from crosssection.core.calibration import Calibration
from crosssection.core.errors import ConfigError, ParameterError
from crosssection.core.unionfind import group_labels
from crosssection.quality import QualityWarning
from crosssection.truth import degrade, ink
from crosssection.truth.backdrop import PLATE_NAMES, apply_backdrop, plate_rgb
from crosssection.truth.scene import (LAYER_PIECE_COLUMNS, LAYER_PIECES, Scene, read_scene_params,
                                      write_scene, write_set_file)
from crosssection.truth.voids import truth_voids

from simulate.checks import check_real
from simulate.contacts import RodAnalysis, analyze_rod
from simulate.energy import LAMBDA
from simulate.geometry import checked_rod, is_point
from simulate.noise import VALIDATED_QUENCH_SEGMENTS as _VALIDATED_QUENCH_SEGMENTS

__all__ = ["render_configuration", "render_directory", "write_set_file", "add_subparser",
           "smooth_line",
           "passes_calibration", "ScanRangeWarning", "TruthWarning", "SCAN_DEFECTS", "CLEAN",
           "DRAW", "JOIN",
           "PX_PER_MM", "THICKNESS_MM", "VALIDATED_SHEET_PX", "VALIDATED_BLUR_PX",
           "VALIDATED_NOISE_SIGMA", "VALIDATED_JPEG_QUALITY", "VALIDATED_COMPACT_SEGMENTS",
           "VALIDATED_QUENCH_SEGMENTS", "SCALE_TOLERANCE", "MAX_BLUR_PX", "MAX_ROD_COORD",
           "not_npz"]

#: Scan resolution and sheet thickness h of a render: the paper's sheet at the typical scans'
#: resolution (h = 5 px).
PX_PER_MM = 50.0
THICKNESS_MM = 0.1

#: Scan defects of a render unless ``clean`` (module docstring): the middle of the typical
#: scans' ranges. Blur, noise and JPEG are applied last, after the plate
#: (:func:`crosssection.truth.degrade.finish_scan`); ``rim_px`` is the plate's dark rim just
#: outside the hole (real scans: 1-3 px).
SCAN_DEFECTS = {"noise_sigma": 5.0, "blur_px": 0.75, "jpeg_quality": 90, "smears": 2,
                "specks": 10, "pinholes": 5, "plate": "grey", "rim_px": 2.0,
                "illumination": 0.075, "cast": 0.03}
#: Ranges of the typical scans the image analysis is validated on
#: (:func:`simulate.atlas.typical_options`, ``benchmarks/robust_sweep.py``): a sheet at least
#: this many px thick (``px_per_mm * thickness_mm``; 25 px/mm at h = 0.1 mm), Gaussian blur
#: sigma at most this many px, noise sigma at most this many grey levels, a JPEG round trip at
#: this quality or above. A render beyond them is drawn, with a :class:`ScanRangeWarning`.
VALIDATED_SHEET_PX = 2.5
VALIDATED_BLUR_PX = 1.5
VALIDATED_NOISE_SIGMA = 10.0
VALIDATED_JPEG_QUALITY = 75
#: Fewest rod segments a render's truth is validated from: compactions are rendered and scored
#: at 2000 segments (docs/validation/compact.md), quenches at 300 (the robust sweep). At
#: 400-800 segments compaction renders have truth rods 36 % longer than the rod, stacks of
#: zero length and energy errors of +65 to +300 %. A rod with fewer is drawn, with a
#: :class:`ScanRangeWarning`.
VALIDATED_COMPACT_SEGMENTS = 2000
#: (the quench's own: :data:`simulate.noise.VALIDATED_QUENCH_SEGMENTS`)
VALIDATED_QUENCH_SEGMENTS = _VALIDATED_QUENCH_SEGMENTS
#: The clean drawing: no defect, white paper around the hole.
CLEAN = {"noise_sigma": 0.0, "blur_px": 0.0, "jpeg_quality": None, "smears": 0, "specks": 0,
         "pinholes": 0, "plate": None, "rim_px": 0.0, "illumination": 0.0, "cast": 0.0}
SMOOTH = ("all", "long", "none")
#: What is drawn: one band per stack (``"bands"``) or the rod itself (``"passes"``).
DRAW = ("bands", "passes")
#: How a band of the bands drawing joins its junctions: along its own mean line, cleaned and
#: cut back near the junction, then smoothed into the junction point (``"hook"``,
#: :func:`_hooked_lines`), or the analysis' line, the junction points first and last, smoothed
#: as it is (``"junction"``; module docstring, "Lines and energy").
JOIN = ("hook", "junction")
#: ``join="hook"``: length of a mean line dropped at a junction, in widths of the widest band
#: there (at most a third of the line at each end).
HOOK_TRIM = 0.5
#: ``join="hook"``: a junction point is not joined to a band whose straight join to it would
#: cross more paper (outside every band meeting there) than this many of the band's own widths
#: (at epsilon = 14 and 19 the joins within a junction's ink cross at most 1.7 widths, those
#: across the paper 4.2 (two at 19) and 17.6 (one at 14); docs/validation/compact.md).
PAPER_JOIN = 3.0
#: ``draw="passes"``: ink width of one pass, in units of the sheet thickness h.
PASS_WIDTH = 1.25
#: ``draw="passes"``: length over which a pressed pass returns to its own position, in units
#: of the pass width.
PASS_TAPER = 4.0
#: ``draw="passes"``: the pressing displacements are smoothed along the rod over this many
#: rod segments (0: over one pitch, the pressing exact at every cross-section). Over one
#: pitch the pressed passes follow their neighbours' segment-scale wiggles and carry 62-88
#: times the rod's bending energy (four rods at epsilon = 19; the rod's own smooth curve
#: 1.00 times); over half a segment 1.17-1.26 times, over one segment, the rod's own
#: resolution, 1.00-1.01 times, but the pressing is then loose where a stack's spacing
#: changes within a segment (docs/validation/compact.md, "Drawing the rod itself").
PASS_SMOOTH = 0.0
#: largest ``pass_smooth``, in rod segments: beyond a few segments the pressing is smoothed
#: away from the stacks it holds together (and the kernel's length grows without bound)
PASS_SMOOTH_MAX = 50.0
#: ``draw="passes"``: adjacent pressed passes overlap by this much so that the rasterised
#: strokes leave no paper line between them.
PASS_OVERLAP_PX = 1.0
#: Truth self-check: largest relative difference between the rod the truth's stacks hold
#: (``sum(n_br x length_mm)``) and the rod's length before a scene is flagged
#: (:class:`TruthWarning`). The bands drawing holds 1.001-1.11 L on quenched rods of 120-200
#: segments and 1.02-1.16 L on compacted rods (module docstring, "Joining bands to
#: junctions"); the passes drawing the rod exactly.
TRUTH_LENGTH_TOLERANCE = 0.2
#: Truth self-check: a truth junction farther than this many sheet thicknesses h from the
#: drawn ink is moved onto it (:func:`_junctions_onto_ink`): the scoring matches junctions
#: within 3 h (:func:`crosssection.truth.scoring.score`).
JUNCTION_INK_H = 3.0
#: Largest relative difference between a given rod length and the one a compaction's thickness
#: sets (``thickness_mm / rod_thickness``): beyond it the bands would be drawn thicker or
#: thinner than the rod the compaction packed (a pass ``thickness_mm`` wide on a rod
#: ``rod_thickness`` thick), so the rod would overlap itself or show gaps it does not have.
SCALE_TOLERANCE = 0.01
#: Largest scene drawn, in pixels (10 000 x 10 000): the drawing holds several float images
#: of this size (a 1e8 px scene needs several GB); the defaults give about 2500 x 2500 px.
MAX_SCENE_PX = 10_000 * 10_000
#: Thinnest sheet drawn, px (the analysis' own limit, ``crosssection.params``).
MIN_SHEET_PX = 1.0
#: thickest sheet a render draws, px: its bands (n h wide, dozens of layers on a wall) must
#: stay below the widest line OpenCV draws (32767 px: 700 mm sheets at 50 px/mm fail inside
#: OpenCV); a scan's sheet is 2-10 px
MAX_SHEET_PX = 1000.0
#: Widest Gaussian blur drawn, sigma in px: ten sheet thicknesses at the defaults (h = 5 px).
#: A band h wide blurred with sigma keeps about h / (sqrt(2 pi) sigma) of its contrast, 4 %
#: here, so no scan is blurrier. Far wider blurs cost more than any scene: measured at the
#: defaults, sigma 1000 px runs for minutes and 1e4 px crashes OpenCV's filter.
MAX_BLUR_PX = 50.0
#: Largest scan noise (grey levels of 8 bits): the contrast between the ink and the paper.
MAX_NOISE_SIGMA = 255.0
#: Most smears, specks or pinholes of one scene: a hundred times the defaults' largest count
#: (each is drawn in turn: 1e8 smears take minutes).
MAX_MARKS = 1000
#: Largest |coordinate| of a rod, in units of the rod length L: a rod's nodes lie within L of
#: one another and the simulations centre it on the origin or its wall, so |x| is of order 1;
#: a thousand times that still leaves the squared distances of the analysis and of the
#: drawing far from floating-point overflow.
MAX_ROD_COORD = 1e3


class ScanRangeWarning(QualityWarning):
    """A render's resolution or scan defects lie beyond the ranges the image analysis is
    validated on (:data:`VALIDATED_SHEET_PX` and the other ``VALIDATED_`` limits): scores of
    its scenes say how the analysis fares there, not how it fares on the typical scans."""


def _beyond_validated(defects: dict, sheet_px: float, name=str) -> str | None:
    """What of a render lies beyond the validated ranges, in one phrase, or None.

    Parameters
    ----------
    defects : dict
        The scan defects as :func:`_defects` resolves them.
    sheet_px : float
        Sheet thickness in the image, ``px_per_mm * thickness_mm``.
    name : callable
        Shows a keyword (the API's) as the caller names it (the CLI's options).

    Returns
    -------
    str or None
    """
    out = []
    if sheet_px < VALIDATED_SHEET_PX:
        out.append(f"a sheet {sheet_px:.3g} px thick ({name('px_per_mm')} x "
                   f"{name('thickness_mm')}) is below {VALIDATED_SHEET_PX:g} px")
    if defects["blur_px"] > VALIDATED_BLUR_PX:
        out.append(f"{name('blur_px')} {defects['blur_px']:g} is above "
                   f"{VALIDATED_BLUR_PX:g} px")
    if defects["noise_sigma"] > VALIDATED_NOISE_SIGMA:
        out.append(f"{name('noise_sigma')} {defects['noise_sigma']:g} is above "
                   f"{VALIDATED_NOISE_SIGMA:g} grey levels")
    q = defects["jpeg_quality"]
    if q is not None and q < VALIDATED_JPEG_QUALITY:
        out.append(f"{name('jpeg_quality')} {q} is below {VALIDATED_JPEG_QUALITY}")
    if not out:
        return None
    return ("scans beyond the range the image analysis is validated on: " + "; ".join(out))


def _rod_beyond_validated(n_segments: int, compaction: bool) -> str | None:
    """A phrase when a rod of ``n_segments`` has fewer segments than its renders' truth is
    validated from (:data:`VALIDATED_COMPACT_SEGMENTS`, :data:`VALIDATED_QUENCH_SEGMENTS`),
    else None."""
    least = VALIDATED_COMPACT_SEGMENTS if compaction else VALIDATED_QUENCH_SEGMENTS
    if n_segments >= least:
        return None
    kind = "compaction" if compaction else "quench"
    return (f"the render's truth is validated from {least} segments on a {kind}'s rod, this "
            f"one has {n_segments}: its truth's stacks may hold another rod length than the "
            "rod's, with stacks of zero length, and its energy errors are not the analysis'")


class TruthWarning(QualityWarning):
    """A scene's truth disagrees with its own drawing (a junction off the ink, junction bands
    that do not touch there, voids the drawing opens or closes, a drawn rod of another length
    than the rod's): scores of that scene
    measure the render as much as the image analysis. The scene's ``truth/summary.json``
    lists the same messages (``truth_warnings``)."""


def _stack_components(labels, comp, n_stacks: int) -> np.ndarray:
    """The ink component (of ``comp``, 0: none) holding most of every stack's labelled ink
    (``labels``: ``k + 1`` on stack ``k``); 0 for a stack without labelled ink."""
    on = (labels > 0) & (comp > 0)
    n_comp = int(comp.max()) + 1
    counts = np.bincount((labels[on].astype(np.int64) - 1) * n_comp + comp[on],
                         minlength=n_stacks * n_comp).reshape(n_stacks, n_comp)
    main = counts.argmax(axis=1)
    return np.where(counts.max(axis=1) > 0, main, 0)


def _junction_stacks(stacks: pd.DataFrame) -> dict:
    """Junction id -> the stacks with an end there."""
    out = {}
    for sid, a, b in stacks[["stack_id", "junction_a", "junction_b"]].to_numpy(int):
        for j in {int(a), int(b)} - {-1}:
            out.setdefault(j, []).append(int(sid))
    return out


def _disconnected_junctions(stacks: pd.DataFrame, labels, ink_mask) -> list[int]:
    """The junctions whose stacks' drawn bands do not touch: their inks lie in different
    connected components of ``ink_mask`` (8-connected), so that an image analysis reads two
    networks where the truth has one."""
    n, comp = cv2.connectedComponents(ink_mask.astype(np.uint8), connectivity=8)
    if n <= 2 or not len(stacks):
        return []
    main = _stack_components(labels, comp, len(stacks))
    out = []
    for j, sids in sorted(_junction_stacks(stacks).items()):
        seen = {int(main[sid]) for sid in sids} - {0}
        if len(seen) > 1:
            out.append(j)
    return out


def _band_masks_near(centre, radius_px: float, bands: list, shape) -> tuple:
    """The ink of every band (a list of pieces: a line and its width, :func:`_draw_bands`)
    within ``radius_px`` of ``centre`` (x, y px), each band drawn on its own.

    Returns
    -------
    masks : list of (h, w) bool arrays
        One per band, in a window around ``centre`` wide enough that every band pixel inside
        the disc is drawn from all of its line (the window's pad holds half the widest band).
    disc : (h, w) bool array
        The pixels of the window within ``radius_px`` of ``centre``.
    """
    pad = radius_px + 0.5 * max((w for pieces in bands for _, w in pieces), default=0.0) + 2.0
    lo = np.maximum(np.floor(np.asarray(centre, float) - pad), 0).astype(int)
    hi = np.minimum(np.ceil(np.asarray(centre, float) + pad) + 1, [shape[1], shape[0]]).astype(int)
    wshape = (max(int(hi[1] - lo[1]), 1), max(int(hi[0] - lo[0]), 1))
    rr, cc = np.mgrid[lo[1]:lo[1] + wshape[0], lo[0]:lo[0] + wshape[1]]
    disc = (cc - centre[0]) ** 2 + (rr - centre[1]) ** 2 <= radius_px ** 2
    masks = []
    for pieces in bands:
        mask = np.zeros(wshape, bool)
        for i, (piece, width) in enumerate(pieces):
            q = np.asarray(piece, float) - lo
            reach = 0.5 * width + 2.0
            if not len(q) or np.any(q.min(axis=0) - reach >= [wshape[1], wshape[0]]) \
                    or np.any(q.max(axis=0) + reach < 0):
                continue  # the piece lies outside the window
            win, cov = _piece_coverage(q, width, wshape, _flat_ends(pieces, i))
            mask[win] |= cov >= 0.5
        masks.append(mask)
    return masks, disc


def _apart_junctions(ends, lines_px, bands: list, junction_xy: dict, shape,
                     least_radius_px: float) -> list[int]:
    """The junctions whose drawn bands do not all touch there.

    Around a truth junction the bands of its stacks must form one piece of ink: touching
    (8-connected, as the image analysis' ink) within the widest band's width (at least
    ``least_radius_px``) of the junction point or of one of the bands' ends there. A band
    drawn short of the others (its end not joined to the junction point and its passes
    ending away from the other bands) leaves paper there: the image has no junction where the
    truth has one, and the voids it bounds open into each other, even when the bands join
    elsewhere (so that :func:`_disconnected_junctions` finds the ink in one piece).

    Parameters
    ----------
    ends : (M, 2) int array
        Junctions at the two ends of every stack (-1: a free end).
    lines_px : list of (P, 2) arrays
        The drawn line of every stack (x, y px); its first / last point is its end at
        ``junction_a`` / ``junction_b``.
    bands : list of lists of (line, width_px)
        Every stack as drawn: its pieces (one, the line at its width, unless a rod end inside
        narrows it, :func:`_draw_stacks`).
    junction_xy : dict
        Junction id -> its drawn point (x, y px).
    shape : (int, int)
        Image shape.
    least_radius_px : float
        Smallest neighbourhood radius.

    Returns
    -------
    list of int
        Junction ids, ascending.
    """
    at = {}
    for sid, pair in enumerate(np.asarray(ends, int).reshape(-1, 2)):
        for e, j in ((0, int(pair[0])), (-1, int(pair[1]))):
            if j >= 0 and len(lines_px[sid]):
                at.setdefault(j, []).append((sid, e))
    kernel = np.ones((3, 3), np.uint8)
    out = []
    for j, members in sorted(at.items()):
        sids = sorted({sid for sid, _ in members})
        if len(sids) < 2 or j not in junction_xy:
            continue
        radius = max(max(w for sid in sids for _, w in bands[sid]), least_radius_px)
        centres = [np.asarray(junction_xy[j], float)]
        centres += [np.asarray(lines_px[sid][e], float) for sid, e in members]
        touching = []
        for centre in centres:
            masks, disc = _band_masks_near(centre, radius, [bands[sid] for sid in sids], shape)
            grown = [cv2.dilate((m & disc).astype(np.uint8), kernel).astype(bool) for m in masks]
            touching += [(a, b) for a in range(len(sids)) for b in range(a + 1, len(sids))
                         if (grown[a] & masks[b] & disc).any()]
        if group_labels(len(sids), touching).max() > 0:
            out.append(j)
    return out


def _void_count_check(n_truth: int, rod_voids: pd.DataFrame, rod_length_mm: float,
                      s_min_mm2: float, widest_mm: float, delta_mm: float) -> str | None:
    """A message when the truth's void count is not the rod's, else None.

    The rod's voids (the contact analysis', areas and perimeters at the centre line) of area
    ``A`` and perimeter ``P`` are drawn bounded by band edges: smaller by about ``P`` times
    half the bounding bands' width, or larger by up to ``P`` times half the contact distance
    where a band is narrower than the spread of its passes. The truth must hold at least the
    rod's voids with ``A - P widest / 2 >= s_min`` and at most those with
    ``A + P delta / 2 >= s_min``: outside that range the drawing opened voids into each
    other (bands that do not touch where the rod's passes do) or closed ones the rod does
    not have.
    """
    if rod_voids is None:
        return None
    area = rod_voids["area"].to_numpy(float) * rod_length_mm ** 2
    per = rod_voids["perimeter"].to_numpy(float) * rod_length_mm
    n_rod = int(np.sum(area >= s_min_mm2))
    least = int(np.sum(area - 0.5 * widest_mm * per >= s_min_mm2))
    most = int(np.sum(area + 0.5 * delta_mm * per >= s_min_mm2))
    if least <= n_truth <= most:
        return None
    return (f"the truth has {n_truth} void{'s' if n_truth != 1 else ''}, the rod {n_rod} of at "
            f"least s_min = {s_min_mm2:g} mm^2 ({least}-{most} allowing for the bands' width): "
            "the drawing " + ("opens voids into each other or into the outside where the rod "
                              "closes them" if n_truth < least else
                              "closes voids the rod does not have"))


def _junctions_onto_ink(junctions: pd.DataFrame, stacks: pd.DataFrame, labels, ink_mask,
                        limit_px: float, *, px_per_mm: float) -> tuple[pd.DataFrame, list[str]]:
    """Truth junctions farther than ``limit_px`` from the drawn ink moved onto it.

    A junction point is the mean of the run ends meeting there
    (:func:`simulate.contacts.analyze_rod`); when those ends lie far apart (a loop stack
    whose ends are one junction) it can lie on the paper, where no skeleton fork can be
    matched to it. Such a point is moved to the nearest ink of its stacks (of any ink when
    none of theirs is drawn), or to the nearest pixel where the inks of two of its stacks
    touch when that lies at most two ``limit_px`` farther.

    Parameters
    ----------
    junctions, stacks : DataFrame
        Truth tables (pixels).
    labels : (H, W) int array
        ``k + 1`` on the ink of stack ``k``.
    ink_mask : (H, W) bool array
    limit_px : float
        Largest distance of a junction from the ink (the scoring's junction match radius),
        or the width of the widest band there when larger: a junction point lies at a band's
        side (module docstring, "Joining bands to junctions").
    px_per_mm : float
        Scale of the stacks' ``width_mm``.

    Returns
    -------
    junctions : DataFrame
        A copy, the moved junctions at their new points.
    messages : list of str
        One per moved junction: where it was, how far from the ink, how far it moved.
    """
    if not len(junctions) or not ink_mask.any():
        return junctions, []
    h_px, w_px = ink_mask.shape

    def distance_to(mask):
        return cv2.distanceTransform(np.where(mask, 0, 255).astype(np.uint8), cv2.DIST_L2,
                                     cv2.DIST_MASK_PRECISE)

    def nearest(mask, x, y):
        rr, cc = np.nonzero(mask)
        k = int(np.argmin((cc - x) ** 2 + (rr - y) ** 2))
        return float(cc[k]), float(rr[k])

    d_ink = distance_to(ink_mask)
    by_junction = _junction_stacks(stacks)
    out = junctions.copy()
    messages = []
    for i, row in junctions.iterrows():
        x, y = float(row.x_px), float(row.y_px)
        c = int(np.clip(round(x), 0, w_px - 1))
        r = int(np.clip(round(y), 0, h_px - 1))
        off = float(d_ink[r, c]) if (c, r) == (round(x), round(y)) else math.inf
        sids = by_junction.get(int(row.junction_id), [])
        widest = float(stacks["width_mm"].to_numpy()[sids].max()) * px_per_mm if sids else 0.0
        if off <= max(limit_px, widest):
            continue
        own = [labels == sid + 1 for sid in sids]
        own = [m for m in own if m.any()]
        nx, ny = nearest(np.any(own, axis=0) if own else ink_mask, x, y)
        if len(own) >= 2:
            meet = (np.sum([distance_to(m) <= 1.5 for m in own], axis=0) >= 2) & ink_mask
            if meet.any():
                mx, my = nearest(meet, x, y)
                # a meeting of its stacks near their nearest ink, not one across the scan
                if math.hypot(mx - x, my - y) <= math.hypot(nx - x, ny - y) + 2 * limit_px:
                    nx, ny = mx, my
        out.loc[i, ["x_px", "y_px"]] = [nx, ny]
        messages.append(f"junction {int(row.junction_id)} ({int(row.n_stacks)} stacks) lay "
                        f"{off:.0f} px from the drawn ink (at ({x:.0f}, {y:.0f}) px): moved "
                        f"{math.hypot(nx - x, ny - y):.0f} px onto the ink of its stacks")
    return out, messages


def _rod_drawn_check(stacks: pd.DataFrame, rod_length_mm: float) -> str | None:
    """A message when the truth's rod, ``sum(n_br x length_mm)`` of its stacks, differs from
    the rod's length by more than :data:`TRUTH_LENGTH_TOLERANCE`, else None."""
    if not len(stacks) or not rod_length_mm > 0:
        return None
    drawn = float((stacks["n_br"] * stacks["length_mm"]).sum())
    rel = drawn / rod_length_mm - 1.0
    if abs(rel) <= TRUTH_LENGTH_TOLERANCE:
        return None
    return (f"the truth's stacks hold {drawn:.4g} mm of rod (sum of n_br x length_mm), the rod "
            f"is {rod_length_mm:.4g} mm ({100 * rel:+.0f} %, more than "
            f"{100 * TRUTH_LENGTH_TOLERANCE:g} %): the truth's stack lengths are not the rod's")


def _zero_length_check(stacks: pd.DataFrame) -> str | None:
    """A message when a truth stack has no length (its branches are then no rod), else
    None."""
    if not len(stacks):
        return None
    empty = stacks[~(stacks["length_mm"] > 0)]
    if not len(empty):
        return None
    shown = ", ".join(f"{int(r.stack_id)} (n_br {int(r.n_br)})" for r in empty.itertuples())
    return (f"truth stack{'s' if len(empty) > 1 else ''} {shown} "
            f"{'have' if len(empty) > 1 else 'has'} length 0: branches without rod, which "
            "no image shows")


def _resampled(line: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points of ``line`` (x, y px) at most ``step`` apart along it, and their arc lengths."""
    seg = np.hypot(*np.diff(line, axis=0).T)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    if arc[-1] <= 0:
        return line[:1].astype(float), np.zeros(1)
    s = np.linspace(0.0, arc[-1], int(np.ceil(arc[-1] / step)) + 1)
    return np.column_stack([np.interp(s, arc, line[:, 0]), np.interp(s, arc, line[:, 1])]), s


def _touching_pieces(stacks: pd.DataFrame, lines_px, widths_px, gap_px: float) -> list[tuple]:
    """Where the drawn bands of pieces the truth holds apart come closer than ``gap_px``.

    Two bands touch when their lines come closer than half their widths plus ``gap_px``
    (less paper than the smallest visible gap). Pieces the truth holds apart: two stacks
    whose junctions are neither shared nor linked by one stack (bands of one junction
    cluster meet there), two stacks that are, where they touch away from the ends of both
    at junctions (a rod end curled back onto its neighbour), and two parts of a one-pass
    stack more than three of its widths
    apart along it, both away from its ends at junctions (where its line is hooked into the
    junction point and may curl over its own ink; the line of a band of several passes ending
    in a fold runs out to the fold and back over itself). The contact
    analysis leaves apart passes closer than delta whose contact is shorter than its
    shortest run (a rod end brushing the rod): drawn at their distance they touch.

    Parameters
    ----------
    stacks : DataFrame
        The analysis' stacks (``junction_a``, ``junction_b``, ``n_br``).
    lines_px : list of ndarray
        The drawn line of every stack, (x, y) px.
    widths_px : array
        Every stack's band width, px.
    gap_px : float
        Smallest visible gap, px.

    Returns
    -------
    list of (int, int, float, float)
        ``(stack_a, stack_b, x_px, y_px)`` per touching pair (``a == b``: a stack touching
        itself), at the closest point of ``a``'s line.
    """
    from scipy.spatial import cKDTree

    if not len(stacks):
        return []
    ends = stacks[["junction_a", "junction_b"]].to_numpy(int)
    junctions = [set(map(int, e)) - {-1} for e in ends]
    # junctions linked by one stack: its two ends
    linked = {}
    for js in junctions:
        for j in js:
            linked.setdefault(j, set()).update(js)
    near = [set().union(*(linked[j] for j in js)) if js else set() for js in junctions]
    pts, owner, arc = [], [], []
    for k, line in enumerate(lines_px):
        line = np.asarray(line, float)
        if len(line) < 1:
            continue
        p, s = _resampled(line, step=1.0)
        pts.append(p)
        owner.append(np.full(len(p), k))
        arc.append(s)
    if not pts:
        return []
    pts, owner, arc = np.concatenate(pts), np.concatenate(owner), np.concatenate(arc)
    widths_px = np.asarray(widths_px, float)
    reach = float(widths_px.max()) + gap_px
    pairs = cKDTree(pts).query_pairs(reach, output_type="ndarray")
    if not len(pairs):
        return []
    i, j = pairs[:, 0], pairs[:, 1]
    a, b = owner[i], owner[j]
    touch = (np.hypot(*(pts[i] - pts[j]).T) < 0.5 * (widths_px[a] + widths_px[b]) + gap_px)
    i, j, a, b = i[touch], j[touch], a[touch], b[touch]
    same = a == b
    far = np.abs(arc[i] - arc[j]) > 3.0 * (widths_px[a] + gap_px)
    length = np.zeros(len(lines_px))
    np.maximum.at(length, owner, arc)
    # a band's line is hooked into its junction points (start: junction_a, end: junction_b)
    # and can curl there over its own ink: no piece apart
    end_zone = 3.0 * (reach + gap_px)

    def at_junction(idx, k):
        return (((arc[idx] < end_zone) & (ends[k, 0] >= 0))
                | ((arc[idx] > length[k] - end_zone) & (ends[k, 1] >= 0)))

    # a band of several passes ending in a fold is drawn along a line that runs out to the
    # fold and back over itself: only a single pass touching itself is pieces apart
    single = stacks["n_br"].to_numpy(int) == 1
    self_touch = same & single[a] & far & ~at_junction(i, a) & ~at_junction(j, a)
    # stacks near each other in the junction graph (a stack is near itself), once per pair
    n = len(lines_px)
    codes, inverse = np.unique(a.astype(np.int64) * n + b, return_inverse=True)
    related = np.array([c // n == c % n or bool(junctions[c // n] & near[c % n])
                        for c in codes], bool)
    # related stacks meet at their junctions: a touch far from any junction of either (a rod
    # end curled back onto its neighbour's band) is pieces apart as well
    near_junction = at_junction(i, a) | at_junction(j, b)
    hit = self_touch | (~same & ~(related[inverse.ravel()] & near_junction))
    out, seen = [], set()
    for n in np.flatnonzero(hit):
        key = (int(min(a[n], b[n])), int(max(a[n], b[n])))
        if key in seen:
            continue
        seen.add(key)
        x, y = pts[i[n]]
        out.append((key[0], key[1], float(x), float(y)))
    return out


def _touching_message(touching: list[tuple], stack_ids) -> str:
    """The truth warning of :func:`_touching_pieces`' pairs."""
    shown = []
    for a, b, x, y in touching[:5]:
        sa, sb = int(stack_ids[a]), int(stack_ids[b])
        what = f"stack {sa} touches itself" if a == b else f"stacks {sa} and {sb} touch"
        shown.append(f"{what} at ({x:.0f}, {y:.0f}) px")
    more = f" and {len(touching) - 5} more" if len(touching) > 5 else ""
    return ("pieces the truth holds apart touch in the drawing (" + "; ".join(shown) + more
            + "): passes closer than the contact distance that the contact analysis leaves "
            "apart are drawn without a gap, and an image analysis joins them")


def passes_calibration(stroke_mm: float, pitch_mm: float, n_max: int = 60) -> Calibration:
    """The width law of ``draw="passes"``: ``w(n) = n pitch + (stroke - pitch)``.

    ``n`` strokes ``stroke`` wide whose axes lie ``pitch`` apart cover ``(n - 1) pitch +
    stroke``.
    """
    n = np.arange(1, int(n_max) + 1, dtype=float)
    return Calibration(tuple(n), tuple(n * pitch_mm + (stroke_mm - pitch_mm)))


@dataclass(frozen=True)
class _Frame:
    """Where the configuration lands in the image: scale, margins, hole."""

    origin_xy: np.ndarray         # lower corner of the configuration (units of L)
    scale: float                  # px per unit L
    margin_px: float
    shape: tuple                  # (H, W)
    rod_length_mm: float
    gap_ok: bool                  # passes beyond delta are guaranteed a visible gap
    hole_radius_mm: float | None
    hole_xy: np.ndarray | None    # hole centre (x, y) px
    hole_px: float | None
    hole_is_wall: bool = False    # the hole is the wall the rod was compacted in

    def to_px(self, p) -> np.ndarray:
        """(x, y) in units of L -> (x = column, y = row) float pixels."""
        return (np.asarray(p, float) - self.origin_xy) * self.scale + self.margin_px


def _rod_length_mm(xy, delta, cal, n_max, *, rod_length_mm, px_per_mm, gap_px, margin_mm,
                   max_size_px):
    """Rod length (mm) and whether passes beyond delta keep a visible gap (module docstring)."""
    extent = float(np.max(xy.max(axis=0) - xy.min(axis=0)))
    need_mm = 0.5 * (float(cal.width(1)) + float(cal.width(n_max))) + gap_px / px_per_mm
    if rod_length_mm is not None:
        widest = float(cal.width(n_max))
        if extent * rod_length_mm < 2.0 * widest:
            # the rod's whole drawing narrower than two of its bands: one blot, no network
            least = 2.0 * widest / max(extent, 1e-9)
            raise ParameterError(f"{rod_length_mm:.4g} mm draws the whole rod within "
                                 f"{extent * rod_length_mm:.3g} mm, less than two of its "
                                 f"widest bands ({widest:.3g} mm wide): give at least "
                                 f"{least:.4g} mm", "rod_length_mm")
        return rod_length_mm, delta * rod_length_mm >= need_mm
    rod_length_mm = need_mm / delta
    cap = ((max_size_px - 2) / px_per_mm - 2 * margin_mm) / max(extent, 1e-9)
    # max_size_px is a soft cap on the rod length chosen here (a given rod length or rod
    # thickness ignores it); the hard limit is MAX_SCENE_PX, refused by _check_scene_size.
    # Both warnings say the pixel budget does not fit the resolution: ResolutionWarning
    from crosssection.quality import ResolutionWarning

    if cap <= 0:
        # the margins alone exceed max_size_px: no rod length keeps the image under it, and a
        # negative one would mirror the drawing; the pixel budget of render_configuration
        # refuses the scene if it is too large
        warnings.warn(f"the {margin_mm:g} mm margins alone exceed {max_size_px} px at "
                      f"{px_per_mm:g} px/mm: rod length not capped, the image is larger "
                      "than max_size_px", ResolutionWarning, stacklevel=4)
        return rod_length_mm, True
    if rod_length_mm > cap:
        warnings.warn(f"rod length capped at {cap:.1f} mm to keep the image under "
                      f"{max_size_px} px: passes just beyond the contact distance (the "
                      "ensemble's, in units of L) may touch in the image",
                      ResolutionWarning, stacklevel=4)
        return cap, False
    return rod_length_mm, True


def _frame(xy, analysis, cal, *, px_per_mm, thickness_mm, rod_length_mm, hole_radius_mm,
           margin_mm, gap_px, max_size_px, rod_thickness=None, wall_radius=None,
           wall_center_xy=(0.0, 0.0)) -> _Frame:
    """Scale, margins and hole of the rendering."""
    st = analysis.stacks
    n_max = int(st["n_br"].max()) if len(st) else 1
    if rod_length_mm is None and rod_thickness is not None:
        # the rod's thickness is the sheet's: one physical scale
        rod_length_mm = thickness_mm / rod_thickness
    rod_length_mm, gap_ok = _rod_length_mm(
        xy, analysis.contact_distance, cal, n_max, rod_length_mm=rod_length_mm,
        px_per_mm=px_per_mm, gap_px=gap_px, margin_mm=margin_mm, max_size_px=max_size_px)
    scale = rod_length_mm * px_per_mm
    lo = xy.min(axis=0)
    margin_px = margin_mm * px_per_mm
    hole_center_l = np.average(xy, axis=0)
    hole_is_wall = False
    if isinstance(hole_radius_mm, str):
        if hole_radius_mm != "auto":
            raise ParameterError(f"hole_radius_mm must be a number, None or 'auto', got "
                                 f"{hole_radius_mm!r}")
        if wall_radius is not None:
            # the hard wall the rod was compacted in is the experiment's hole
            hole_center_l = np.asarray(wall_center_xy, float)
            hole_radius_mm = float(wall_radius * rod_length_mm)
            hole_is_wall = True
        else:
            # the experiment's container: the smallest disk holding the rod, plus the half
            # width of the thickest band and 2 h of clearance (the pipeline then uses the
            # known hole instead of fitting one to the ink envelope)
            (cx, cy), r_l = cv2.minEnclosingCircle(xy.astype(np.float32))
            hole_center_l = np.array([cx, cy], float)
            hole_radius_mm = float(r_l * rod_length_mm + 0.5 * float(cal.width(n_max))
                                   + 2 * thickness_mm)
    elif hole_radius_mm is not None and wall_radius is not None:
        hole_center_l = np.asarray(wall_center_xy, float)
    hole_px = None if hole_radius_mm is None else hole_radius_mm * px_per_mm
    if wall_radius is not None:
        reach_l = float(np.hypot(*(xy - np.asarray(wall_center_xy, float)).T).max())
        if reach_l > wall_radius + max(float(rod_thickness or 0.0), 0.05 * wall_radius):
            # a rod beyond its wall is no configuration of it (the hole, when it is the wall,
            # would cut it)
            raise ParameterError(f"the rod reaches {reach_l:.4g} L from the wall's centre, "
                                 f"beyond the wall (radius {wall_radius:.4g} L): not a "
                                 "configuration of that wall", "wall_radius")
    if hole_px is not None and not hole_is_wall:
        # the hole holds the cut: a rod reaching beyond it is no scan of one
        reach_mm = float(np.hypot(*(xy - hole_center_l).T).max()) * rod_length_mm
        if reach_mm > hole_radius_mm:
            # the least radius to 4 digits, rounded up: a radius given as printed holds it
            step = 10.0 ** (math.floor(math.log10(reach_mm)) - 3)
            least = math.ceil(reach_mm / step) * step
            raise ParameterError(f"{hole_radius_mm:.4g} mm is smaller than "
                                 f"the rod, which reaches {reach_mm:.4g} mm from the hole's "
                                 "centre (a given hole is centred on the rod's centroid): "
                                 f"give at least {least:.4g} mm, or 'auto', the smallest "
                                 "disk holding the rod", "hole_radius_mm")
    if hole_px is not None:
        c_off = (hole_center_l - lo) * scale
        far = (xy.max(axis=0) - hole_center_l) * scale
        need = hole_px + 2 * thickness_mm * px_per_mm - np.minimum(c_off, far)
        margin_px = max(margin_px, float(need.max()))
    # in floats: an absurd scale would overflow integers before _check_scene_size sees it
    size = np.ceil((xy.max(axis=0) - lo) * scale + 2 * margin_px) + 1
    fits = bool(np.isfinite(size).all()) and float(size[0]) * float(size[1]) <= MAX_SCENE_PX
    shape = ((int(size[1]), int(size[0])) if fits else (float(size[1]), float(size[0])))
    hole_xy = None if hole_px is None else (hole_center_l - lo) * scale + margin_px
    return _Frame(lo, scale, margin_px, shape, rod_length_mm, gap_ok,
                  hole_radius_mm, hole_xy, hole_px, hole_is_wall)


def _px_count(v) -> str:
    """A scene side in px as a message shows it: whole up to a billion, else in powers of
    ten."""
    return f"{int(v)}" if math.isfinite(v) and v < 1e9 else f"{v:.3g}"


def _check_scene_size(frame: _Frame, px_per_mm: float) -> None:
    """Refuse a scene larger than :data:`MAX_SCENE_PX` before anything is drawn.

    Raises
    ------
    ParameterError
        Naming ``px_per_mm`` (every pixel size scales with it) and the sizes in mm that set
        the image: the rod length and the hole.
    """
    h_px, w_px = frame.shape
    if isinstance(h_px, int) and isinstance(w_px, int) and h_px * w_px <= MAX_SCENE_PX:
        return
    side = math.isqrt(MAX_SCENE_PX)
    hole = ("" if frame.hole_radius_mm is None
            else f" in a hole of radius {frame.hole_radius_mm:.4g} mm")
    raise ParameterError(
        f"the scene would be {_px_count(w_px)} x {_px_count(h_px)} px (> {side} x {side} "
        f"px): a rod of {frame.rod_length_mm:.4g} mm{hole} at {px_per_mm:g} px/mm; lower "
        "px_per_mm, thickness_mm, rod_length_mm or hole_radius_mm", "px_per_mm")


def _arc_px(line) -> np.ndarray:
    """Arc length (px) at every point of a polyline, from 0 at its first point."""
    return np.r_[0.0, np.cumsum(np.hypot(*np.diff(line, axis=0).T))]


def _fixed_point(line, shift: int) -> np.ndarray:
    """A polyline (x, y) as OpenCV draws it with sub-pixel precision: coordinates times
    ``2^shift``, int32, shape (P, 1, 2)."""
    return np.round(line * (1 << shift)).astype(np.int32).reshape(-1, 1, 2)


def _distance_band(shape, pts, width_px: float, shift: int) -> np.ndarray:
    """Anti-aliased coverage of a band ``width_px`` wide around polylines (:func:`_fixed_point`):
    1 within ``width_px / 2`` of a line, falling to 0 over one pixel (exact distance)."""
    canvas = np.full(shape, 255, np.uint8)
    cv2.polylines(canvas, pts, False, 0, 1, cv2.LINE_8, shift)
    d = cv2.distanceTransform(canvas, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.clip(0.5 * width_px - d + 0.5, 0, 1)


def smooth_line(line_xy, knot_spacing_px: float, step_px: float = 1.0, *,
                short: bool = False) -> np.ndarray:
    """The smooth curve of a stack through the rod's discretisation, sampled every ``step_px``.

    The rod is a chain of straight segments of length ``ds`` (``knot_spacing_px``), and its
    energy is that of the smooth sheet it discretises: sum (d theta_i)^2 / ds, the
    ``int kappa^2 ds`` of a curve turning by d theta_i over each segment. Drawn as a polyline,
    the same turns sit in corners a few pixels wide and an image measures several times that
    energy. Here the stack's line is resampled at the segment length along its arc (which cuts
    the corners and the short hooks where a line joins its junction) and an interpolating cubic
    spline through those knots (periodic for a closed line) turns gradually between them.
    A line shorter than two segments has no knot inside; with ``short`` it is drawn as the
    parabola through its ends and its middle point (such a line is a link between two
    junctions, whose hooks would otherwise be corners).

    Parameters
    ----------
    line_xy : (P, 2) array
        The stack's line in pixels (x, y), sampled at least once per segment.
    knot_spacing_px : float
        The rod's segment length in pixels (rod length / N).
    step_px : float
        Sampling step along the curve.
    short : bool
        Smooth lines shorter than two segments too (longer than a pixel, three points or
        more).

    Returns
    -------
    (Q, 2) array
        The curve from the line's first to its last point; lines shorter than two segments
        are returned as they are unless ``short``.
    """
    from scipy.interpolate import CubicSpline

    p = np.asarray(line_xy, float)
    keep = np.r_[True, np.hypot(*np.diff(p, axis=0).T) > 1e-9]
    p = p[keep]
    u = _arc_px(p)
    if len(p) < 3 or u[-1] < 2.0 * knot_spacing_px:
        if not (short and len(p) >= 3 and u[-1] > 1.0):
            return p
        uk = np.linspace(0.0, u[-1], 3)
        knots = np.c_[np.interp(uk, u, p[:, 0]), np.interp(uk, u, p[:, 1])]
        n = max(int(np.ceil(u[-1] / step_px)), 2)
        return CubicSpline(uk, knots, axis=0)(np.linspace(0.0, u[-1], n + 1))
    closed = np.hypot(*(p[0] - p[-1])) <= 1e-6 * max(1.0, u[-1])
    n_knots = max(int(round(u[-1] / knot_spacing_px)), 3)
    uk = np.linspace(0.0, u[-1], n_knots + 1)
    knots = np.c_[np.interp(uk, u, p[:, 0]), np.interp(uk, u, p[:, 1])]
    if closed:
        knots[-1] = knots[0]
    spline = CubicSpline(uk, knots, axis=0, bc_type="periodic" if closed else "not-a-knot")
    n = max(int(np.ceil(u[-1] / step_px)), n_knots)
    return spline(np.linspace(0.0, u[-1], n + 1))


def _inside_wall(points, centre_xy, limit_px):
    """``points`` with those farther than ``limit_px`` from ``centre_xy`` moved radially onto
    that circle."""
    d = points - np.asarray(centre_xy, float)
    r = np.hypot(d[:, 0], d[:, 1])
    far = r > limit_px
    if not far.any():
        return points
    out = points.copy()
    out[far] = np.asarray(centre_xy, float) + d[far] * (limit_px / r[far])[:, None]
    return out


def _widest(analysis, widths_px):
    """The junctions at both ends of every stack, and the widest band at every junction."""
    st = analysis.stacks
    ends = st[["junction_a", "junction_b"]].to_numpy(int) if len(st) else np.zeros((0, 2), int)
    widest = {}
    for sid, pair in enumerate(ends):
        for j in pair:
            if j >= 0:
                widest[j] = max(widest.get(j, 0.0), float(widths_px[sid]))
    return ends, widest


def _junctions_px(analysis, frame, widths_px) -> np.ndarray:
    """Junction positions (x, y) px, as drawn (kept inside the wall like the lines' ends)."""
    jt = analysis.junctions
    if not len(jt):
        return np.zeros((0, 2))
    jpx = frame.to_px(jt[["x", "y"]].to_numpy(float))
    if frame.hole_is_wall and frame.hole_px is not None:
        _, widest = _widest(analysis, widths_px)
        for i, j in enumerate(jt["junction_id"].to_numpy(int)):
            if j in widest:
                jpx[[i]] = _inside_wall(jpx[[i]], frame.hole_xy, frame.hole_px - 0.5 * widest[j])
    return jpx


def _pass_junctions_px(analysis, frame, stroke_px) -> np.ndarray:
    """Junction positions (x, y) px of the passes drawing: the analysis' points, kept half a
    stroke inside the wall like the drawn rod.

    Not moved with the pressing: the mean of the pressed run ends that meet at a junction
    lies a median 1 px from the analysis' point (at most 5 px at epsilon = 19), and matching
    against it did not bring the junctions closer to the forks an image analysis finds.
    """
    jt = analysis.junctions
    if not len(jt):
        return np.zeros((0, 2))
    jpx = frame.to_px(jt[["x", "y"]].to_numpy(float))
    if frame.hole_is_wall and frame.hole_px is not None:
        jpx = _inside_wall(jpx, frame.hole_xy, frame.hole_px - 0.5 * stroke_px)
    return jpx


def _stack_lines(analysis, frame, widths_px, *, segment_px, smooth):
    """The drawn centreline of every stack: its line, junctions included, smoothed
    (:func:`smooth_line`; ``smooth`` of :func:`render_configuration`).

    When the hole is the wall, no ink lies beyond it (module docstring, "Wall"): a junction
    is kept half the widest band meeting there inside the wall, every line half its own band.
    """
    ends, widest = _widest(analysis, widths_px)
    wall = frame.hole_is_wall and frame.hole_px is not None
    lines = []
    for sid, line_l in enumerate(analysis.stack_lines):
        line = frame.to_px(line_l)
        if wall:
            # the analysis puts the junction first / last on the lines that meet there
            for i, j in ((0, ends[sid][0]), (-1, ends[sid][1])):
                if j >= 0:
                    line[[i]] = _inside_wall(line[[i]], frame.hole_xy,
                                             frame.hole_px - 0.5 * widest[j])
        if smooth != "none":
            line = smooth_line(line, segment_px, short=smooth == "all")
        if wall:
            line = _inside_wall(line, frame.hole_xy, frame.hole_px - 0.5 * float(widths_px[sid]))
        lines.append(line)
    return lines


def _clean_mean_line(line, factor: float = 3.0) -> np.ndarray:
    """A stack's own mean line (junction points excluded) without its glitches.

    The centroid of a stack's passes jumps where a sample's contact cluster holds passes of
    another stack (typically the last sample of the longest run, which is the first of the
    next run; jumps of 15-80 px at epsilon = 19): single points standing off the line (farther
    than ``factor`` times the median step from the middle of their neighbours, which lie close
    together) are removed, and end points reached by a step longer than ``factor`` times the
    median step are dropped.

    Parameters
    ----------
    line : (Q, 2) array
        Mean line (px).
    factor : float
        Jump threshold in median steps.

    Returns
    -------
    (Q', 2) array
    """
    p = np.asarray(line, float)
    if len(p) < 4:
        return p
    thr = factor * max(float(np.median(np.hypot(*np.diff(p, axis=0).T))), 1e-9)
    off = np.hypot(*(p[1:-1] - 0.5 * (p[:-2] + p[2:])).T)
    gap = np.hypot(*(p[2:] - p[:-2]).T)
    keep = np.ones(len(p), bool)
    keep[1:-1] = ~((off > thr) & (gap < thr))
    p = p[keep]
    while len(p) > 2 and np.hypot(*(p[-1] - p[-2])) > thr:
        p = p[:-1]
    while len(p) > 2 and np.hypot(*(p[1] - p[0])) > thr:
        p = p[1:]
    return p


def _trim_range(own, trim_a_px: float, trim_b_px: float) -> tuple[int, int]:
    """The points ``own[i0:i1]`` left without the first ``trim_a_px`` and last ``trim_b_px``
    of arc length (at most a third of it per end; all of them when fewer than two would
    remain)."""
    if len(own) < 3:
        return 0, len(own)
    u = _arc_px(own)
    keep = np.flatnonzero((u >= min(trim_a_px, u[-1] / 3))
                          & (u <= u[-1] - min(trim_b_px, u[-1] / 3)))
    return (int(keep[0]), int(keep[-1]) + 1) if len(keep) >= 2 else (0, len(own))


def _untrimmed_ends(own, full, i0: int, i1: int, hooks) -> np.ndarray:
    """``own``, trimmed from ``full[i0:i1]``, with the trimmed arc given back at every end
    that is not hooked and still ends where the trim left it (no lump, no :func:`_beside`
    cut): the trim only makes room for the hook, and without one it would leave the band
    short of where its passes reach (of the band they join, when they end inside it)."""
    if len(own) < 2:
        return own
    head = full[:i0] if not hooks[0] and np.array_equal(own[0], full[i0]) else full[:0]
    tail = full[i1:] if not hooks[1] and np.array_equal(own[-1], full[i1 - 1]) else full[:0]
    return np.concatenate([head, own, tail]) if len(head) or len(tail) else own


def _loop_hooks(own, jp, reach_px: float, half_px: float) -> tuple[bool, bool]:
    """Which ends of a stack with both ends at one junction (point ``jp``) are hooked to it:
    those within ``reach_px`` of it (a loop closing there); if none is, none when the band
    (half width ``half_px``) covers the point, else the nearer end."""
    d0, d1 = np.hypot(*(jp - own[0])), np.hypot(*(jp - own[-1]))
    if d0 <= reach_px or d1 <= reach_px:
        return bool(d0 <= reach_px), bool(d1 <= reach_px)
    if np.min(np.hypot(*(own - jp).T)) <= half_px:
        return False, False
    return bool(d0 <= d1), bool(d0 > d1)


def _beside(own, jp, end: int, half_px: float, reach_px: float):
    """A junction point ``jp`` beside the line rather than ahead of its ``end`` (0 or 1).

    Not joined when the band (half width ``half_px``) covers the point and the line's point
    nearest to it is not an end. Otherwise the line is cut at its point nearest the junction
    among those within ``reach_px`` of arc from that end (at most a third of the line: a long
    stack can pass by its own junction further on), so that it is joined there.

    Returns
    -------
    own : (Q', 2) array
    hooked : bool
    """
    d_all = np.hypot(*(own - jp).T)
    k = int(np.argmin(d_all))
    if k in (0, len(own) - 1):
        return own, True
    if d_all[k] <= half_px:
        return own, False
    u = _arc_px(own)
    reach = min(reach_px, u[-1] / 3)
    near = np.flatnonzero(u <= reach) if end == 0 else np.flatnonzero(u >= u[-1] - reach)
    k = int(near[np.argmin(d_all[near])])
    if end == 0 and 0 < k < len(own) - 2:
        return own[k:], True
    if end == 1 and 1 < k < len(own) - 1:
        return own[:k + 1], True
    return own, True


def _distance_to_line(points, line) -> np.ndarray:
    """Distance (px) of every point (M, 2) to the polyline ``line`` (Q, 2)."""
    p = np.asarray(points, float)[:, None, :]
    q = np.asarray(line, float)
    if len(q) == 1:
        return np.hypot(*(p[:, 0] - q[0]).T)
    a, d = q[:-1][None], np.diff(q, axis=0)[None]
    t = np.clip(np.sum((p - a) * d, axis=2) / np.maximum(np.sum(d * d, axis=2), 1e-12), 0, 1)
    return np.min(np.hypot(*np.moveaxis(p - a - t[..., None] * d, 2, 0)), axis=1)


def _paper_px(start, end, bands, step_px: float = 2.0) -> float:
    """Length (px) of the straight join from ``start`` to ``end`` that lies outside every band
    of ``bands`` (pairs of a line and its half width): the join would draw ink on paper."""
    n = max(int(np.ceil(np.hypot(*(end - start)) / step_px)), 1)
    pts = start + np.outer((np.arange(n) + 0.5) / n, end - start)
    inside = np.zeros(n, bool)
    for line, half in bands:
        if len(line):
            inside |= _distance_to_line(pts, line) <= half + 1.0
    return float((~inside).sum()) * np.hypot(*(end - start)) / n


def _joined_hooks(hooks, ends):
    """The hooks that join a junction point reached by at least two band ends.

    A junction point that only one band end would reach (the others' joins cross the paper
    or were cut) joins nothing: the hook would only curl that band's end.

    Parameters
    ----------
    hooks : list of [bool, bool]
        Per stack, whether its first / last point is to be joined to its junction.
    ends : (S, 2) int array
        Junctions at the stacks' ends (-1: a free end).

    Returns
    -------
    list of [bool, bool]
    """
    joined = {}
    for pair, (a, b) in zip(hooks, ends):
        for hooked, j in zip(pair, (int(a), int(b))):
            if hooked:
                joined[j] = joined.get(j, 0) + 1
    return [[bool(h) and joined[int(j)] >= 2 for h, j in zip(pair, js)]
            for pair, js in zip(hooks, ends)]


def _hooked_lines(analysis, frame, widths_px, *, segment_px, smooth, trim=HOOK_TRIM):
    """The drawn centreline of every stack, ``join="hook"`` (:func:`render_configuration`).

    The analysis' line of a stack is the centroid of its passes along its longest run with the
    junction points prepended / appended (:func:`simulate.contacts._mean_line`). Near a
    junction that centroid wanders (passes join or leave, the cluster of the run's last sample
    holds another stack's passes), and the junction point, the mean of the run ends meeting
    there, lies at a band's side: smoothed as it is (``join="junction"``), the line hooks into
    the point with a curvature the rod does not have. Here every line is

    * its own mean line, glitches removed (:func:`_clean_mean_line`), cut back by ``trim``
      widths of the widest band at each end joined to its junction (at most a third of it
      per end); an end not joined keeps its whole length (:func:`_untrimmed_ends`), so that a
      pass ending inside another band of the junction is drawn into it;
    * joined to the junction point by the smooth curve (:func:`smooth_line`) through it: the
      line turns over the cut length plus up to one rod segment instead of within the last
      sample, and the bands still meet (overlap) at the junction point, the truth's;
    * not joined to a junction point that the straight join from the line's end would reach
      across more than :data:`PAPER_JOIN` of the band's widths of paper (outside every band
      meeting there, :func:`_paper_px`): none of the band's passes goes there;
    * a junction point beside the band rather than ahead of it is not joined when the band
      covers it, else the line is cut at its point nearest the junction within ``trim + 2``
      widest widths of arc from the end (:func:`_beside`);
    * a stack with both ends at one junction is joined at the ends lying within ``trim + 2``
      widest widths of its point (:func:`_loop_hooks`);
    * a junction point that only one band end would still reach is not joined
      (:func:`_joined_hooks`);
    * a stack shorter than two segments between two junctions (a link between close
      junctions, or a lump) is its centroid only (joined once to a junction holding both its
      ends), and a line through it shorter than two segments is the straight chord between
      its ends.

    When the hole is the wall, lines are kept half their band inside it, the junction points
    half the widest band (as :func:`_stack_lines`).

    Returns
    -------
    list of (Q, 2) arrays
        The drawn lines (px).
    """
    ends, widest = _widest(analysis, widths_px)
    wall = frame.hole_is_wall and frame.hole_px is not None
    jpx = _junctions_px(analysis, frame, widths_px)
    jt = analysis.junctions
    row_of = {int(j): i for i, j in enumerate(jt["junction_id"].to_numpy(int))} if len(jt) else {}
    owns = [_clean_mean_line(frame.to_px(line_l)[int(a >= 0):len(line_l) - int(b >= 0)])
            for line_l, (a, b) in zip(analysis.stack_lines, ends)]
    bands = {}  # junction -> (own line, half width) of every band meeting there
    for sid, (a, b) in enumerate(ends):
        for j in {int(a), int(b)} - {-1}:
            bands.setdefault(j, []).append((owns[sid], 0.5 * float(widths_px[sid])))
    # (own line, [hook at start, hook at end], untrimmed line, kept range) of every stack
    plans = []
    for sid, own in enumerate(owns):
        a, b = (int(x) for x in ends[sid])
        half = 0.5 * float(widths_px[sid]) - 1.0
        # a junction point where none of the band's passes goes (the mean of run ends lying
        # far apart) is not joined: the join would draw the band across the paper
        limit_px = PAPER_JOIN * float(widths_px[sid])
        far = [j >= 0 and len(own) > 0 and _paper_px(own[e], jpx[row_of[j]], bands[j]) > limit_px
               for e, j in ((0, a), (-1, b))]
        full = own
        i0, i1 = _trim_range(own, trim * widest[a] if a >= 0 else 0.0,
                             trim * widest[b] if b >= 0 else 0.0)
        own = own[i0:i1]
        hooks = [a >= 0 and not far[0], b >= 0 and not far[1]]
        if a >= 0 and a == b and len(own) >= 2:
            hooks = [h and not f for h, f in
                     zip(_loop_hooks(own, jpx[row_of[a]], (trim + 2.0) * widest[a], half), far)]
        if a >= 0 and b >= 0 and len(own) >= 2 and polyline.length(own) < 2.0 * segment_px:
            own = own.mean(axis=0)[None]
            # a lump at one junction: from its point to the lump, no hairpin
            hooks[1] = hooks[1] and a != b
        if len(own) >= 3:
            for end, j in ((0, a), (1, b)):
                if hooks[end]:
                    own, hooks[end] = _beside(own, jpx[row_of[j]], end, half,
                                              (trim + 2.0) * widest[j])
        plans.append((own, hooks, full, i0, i1))
    kept = _joined_hooks([plan[1] for plan in plans], ends)
    lines = []
    for sid, ((own, _, full, i0, i1), hooks) in enumerate(zip(plans, kept)):
        a, b = (int(x) for x in ends[sid])
        own = _untrimmed_ends(own, full, i0, i1, hooks)
        line = np.concatenate([jpx[[row_of[a]]] if hooks[0] else np.zeros((0, 2)), own,
                               jpx[[row_of[b]]] if hooks[1] else np.zeros((0, 2))])
        if a >= 0 and b >= 0 and len(line) >= 2 and polyline.length(line) < 2.0 * segment_px:
            n = max(int(np.ceil(np.hypot(*(line[-1] - line[0])))), 1)
            line = line[0] + np.outer(np.linspace(0.0, 1.0, n + 1), line[-1] - line[0])
        elif smooth != "none":
            line = smooth_line(line, segment_px, short=smooth == "all")
        if wall:
            line = _inside_wall(line, frame.hole_xy, frame.hole_px - 0.5 * float(widths_px[sid]))
        lines.append(line)
    return lines


def _rod_end_cuts(analysis, frame, lines_px, widths_px):
    """Where a rod end lies inside a band, along the drawn line of its stack.

    A pass of a stack runs from one end of the stack to the other (a run ends where the set
    of passes in contact changes: a junction, a fold cap, a loop cut), except a pass holding a
    free end of the rod inside the band or folding back within it, which the contact analysis
    merges with the band it continues (:func:`simulate.contacts._merge_two_ended_junctions`);
    only the first is cut here. Such a pass runs from
    the end of the line its other end lies at over its own length; the cut is there. Measured
    along the line rather than by projecting the rod end onto it: a band that bends back
    (a teardrop loop closing on itself) can pass closer to the rod end than the part of the
    line the pass runs along, and the pass lengths then sum to the rod exactly. A cut within
    one band width of an end of the line is the band's end: no cut. On a closed line (a loop
    stack whose two ends are one junction: a teardrop whose neck holds the rod end) both ends
    are the pass's junction; the pass runs along the side of the loop nearer its own samples
    (:func:`_closed_line_side`).

    Returns
    -------
    dict
        Stack id -> list of ``(u, before)``: arc length of the cut along the drawn line (px)
        and whether the pass is present before it (``u`` smaller) rather than after.
    """
    br = analysis.branches
    st = analysis.stacks
    if not len(br) or analysis.samples_xy is None:
        return {}
    cuts = {}
    for b, far_col in ((0, "s_end"), (len(br) - 1, "s_start")):
        sid = int(br["stack_id"].iloc[b])
        line = lines_px[sid]
        n = int(st["n_br"].iloc[sid])
        if n < 2 or len(line) < 2:
            continue
        u_len = polyline.length(line)
        k_far = min(int(np.searchsorted(analysis.samples_s, float(br[far_col].iloc[b]))),
                    len(analysis.samples_s) - 1)
        far = frame.to_px(analysis.samples_xy[k_far])
        d0, d1 = np.hypot(*(far - line[0])), np.hypot(*(far - line[-1]))
        # the pass's other end is an end of its stack, within the band's reach of the line's
        # end (passes chained at most delta apart); otherwise it is not a pass to cut
        if min(d0, d1) > n * analysis.contact_distance * frame.scale + float(widths_px[sid]):
            continue
        length = float(br["length"].iloc[b]) * frame.scale
        if np.hypot(*(line[0] - line[-1])) < 1e-6 * max(u_len, 1.0):
            s0, s1 = (float(br[c].iloc[b]) for c in ("s_start", "s_end"))
            inside = (analysis.samples_s >= s0) & (analysis.samples_s <= s1)
            before = _closed_line_side(line, frame.to_px(analysis.samples_xy[inside]), length)
        else:
            before = bool(d0 <= d1)
        u = length if before else u_len - length
        if float(widths_px[sid]) < u < u_len - float(widths_px[sid]):
            cuts.setdefault(sid, []).append((u, before))
    return cuts


def _closed_line_side(line, pass_px, length_px: float) -> bool:
    """Whether a pass of ``length_px`` starting at the junction of a closed line runs along
    its start (True) rather than its end: the side whose first ``length_px`` of arc lies
    nearer the pass's own samples ``pass_px`` (mean distance). Near the junction both sides
    are within a band's width of the pass, so its samples are compared over its whole
    length, not at its rod end alone."""
    u = _arc_px(line)
    sides = []
    for a, b in ((0.0, length_px), (u[-1] - length_px, u[-1])):
        keep = (u >= a) & (u <= b)
        ends = np.c_[np.interp([a, b], u, line[:, 0]), np.interp([a, b], u, line[:, 1])]
        piece = np.concatenate([ends[:1], line[keep], ends[1:]])
        sides.append(float(np.mean(_distance_to_line(pass_px, piece))) if len(pass_px)
                     else np.inf)
    return bool(sides[0] <= sides[1])


def _layer_pieces(line, n, cuts):
    """The drawn line of a stack of ``n`` passes cut where rod ends lie inside it.

    Returns
    -------
    list of ((P, 2) array, int)
        Consecutive pieces of the line and the number of passes present along each: ``n``
        minus the passes holding a rod end that lie on the other side of their cut.
    """
    u = _arc_px(line)
    edges = np.unique([c for c, _ in cuts])
    pieces = []
    for a, b in zip(np.r_[0.0, edges], np.r_[edges, u[-1]]):
        ends = np.c_[np.interp([a, b], u, line[:, 0]), np.interp([a, b], u, line[:, 1])]
        piece = np.concatenate([ends[:1], line[(u > a) & (u < b)], ends[1:]])
        mid = 0.5 * (a + b)
        absent = sum(1 for c, before in cuts if (mid > c) == before)
        pieces.append((piece, max(n - absent, 1)))
    return pieces


def _piece_coverage(piece, width_px, shape, flat_ends, shift=4):
    """Anti-aliased coverage of one band piece, in the window around it.

    The distance band of :func:`_draw_bands` around the piece, its round cap cut square at the
    ends listed in ``flat_ends`` (0: first point, -1: last): where the band narrows at a rod
    end, the last layer ends there, not half a band width beyond.

    Returns
    -------
    (slice, slice), (h, w) array
    """
    pad = 0.5 * width_px + 2.0
    lo = np.maximum(np.floor(piece.min(axis=0) - pad), 0).astype(int)
    hi = np.minimum(np.ceil(piece.max(axis=0) + pad) + 1, [shape[1], shape[0]]).astype(int)
    win = (slice(lo[1], hi[1]), slice(lo[0], hi[0]))
    cov = _distance_band((hi[1] - lo[1], hi[0] - lo[0]), [_fixed_point(piece - lo, shift)],
                         width_px, shift)
    if flat_ends:
        rr, cc = np.mgrid[lo[1]:hi[1], lo[0]:hi[0]]
        u = _arc_px(piece)
        for e in flat_ends:
            p = piece[e]
            # the direction in which the piece leaves through this end, over half a width
            back = np.interp(u[-1] - 0.5 * width_px if e == -1 else 0.5 * width_px, u,
                             np.arange(len(piece)))
            q = np.array([np.interp(back, np.arange(len(piece)), piece[:, i]) for i in (0, 1)])
            t = p - q
            norm = np.hypot(*t)
            if norm < 1e-9:
                continue
            t /= norm
            ahead = (cc - p[0]) * t[0] + (rr - p[1]) * t[1]
            # only the cap: a band bending back elsewhere in the window keeps its ink
            cap = np.hypot(cc - p[0], rr - p[1]) <= 0.5 * width_px + 1.5
            cov = np.where(cap, cov * np.clip(0.5 - ahead, 0, 1), cov)
    return win, cov


def _flat_ends(pieces, i: int) -> list[int]:
    """The ends of piece ``i`` of a band (pairs of a line and its width) cut square: those
    where it narrows into the next piece (0: first point, -1: last)."""
    return [e for e, j in ((0, i - 1), (-1, i + 1))
            if 0 <= j < len(pieces) and pieces[j][1] < pieces[i][1]]


def _draw_bands(lines_px, n_br, widths_px, shape, steps=None):
    """Anti-aliased ink coverage (exact distance bands) and the stack label image.

    Parameters
    ----------
    lines_px : list of (P, 2) arrays
    n_br : (M,) int array
    widths_px : (M,) array
        Width of every band, ``w(n_br)``.
    shape : (int, int)
    steps : dict, optional
        Stack id -> list of (piece, width_px) of a band whose width changes along it (a rod
        end inside it, :func:`_layer_pieces`); those stacks are drawn piece by piece, a piece
        narrowing into the next cut square.

    Returns
    -------
    coverage : (H, W) float32 in [0, 1]
    labels : (H, W) int32, ``k + 1`` on the ink of stack ``k`` (band drawn at its width)
    """
    steps = steps or {}
    coverage = np.zeros(shape, np.float32)
    labels = np.zeros(shape, np.int32)
    shift = 4
    pts = [_fixed_point(line, shift) for line in lines_px]
    plain = np.array([sid not in steps for sid in range(len(lines_px))], bool)
    for n in sorted(set(n_br[plain].tolist())):
        members = np.flatnonzero((n_br == n) & plain)
        coverage = np.maximum(coverage, _distance_band(shape, [pts[sid] for sid in members],
                                                       widths_px[members[0]], shift))
    # the coverage is the largest over the bands, so a band drawn on its own adds to it as it
    # would in its width's canvas
    for sid, pieces in steps.items():
        for i, (piece, width) in enumerate(pieces):
            win, cov = _piece_coverage(piece, width, shape, _flat_ends(pieces, i), shift)
            coverage[win] = np.maximum(coverage[win], cov)
    for sid, p in enumerate(pts):
        if sid in steps:
            for piece, width in steps[sid]:
                cv2.polylines(labels, [_fixed_point(piece, shift)], False, sid + 1,
                              max(1, int(round(width))), cv2.LINE_8, shift)
            continue
        cv2.polylines(labels, [p], False, sid + 1, max(1, int(round(widths_px[sid]))),
                      cv2.LINE_8, shift)
    labels[coverage < 0.5] = 0
    return coverage, labels


def _draw_stacks(analysis, frame, lines_px, n_br, widths_px, cal, px_per_mm):
    """The bands drawing of the stacks' lines: coverage and labels (:func:`_draw_bands`),
    the drawn length of the passes of every band that narrows at a rod end, and its pieces
    with their pass counts (:func:`_layer_pieces`; module docstring, "Rod ends")."""
    pieces = {sid: _layer_pieces(lines_px[sid], int(n_br[sid]), cuts)
              for sid, cuts in _rod_end_cuts(analysis, frame, lines_px, widths_px).items()}
    layer_px = {sid: sum(c * polyline.length(q) for q, c in pp) for sid, pp in pieces.items()}
    steps = {sid: [(q, float(cal.width(c)) * px_per_mm) for q, c in pp]
             for sid, pp in pieces.items()}
    coverage, labels = _draw_bands(lines_px, n_br, widths_px, frame.shape, steps)
    return coverage, labels, layer_px, pieces


def _press_stack(curve, normals, members, pitch_px, reach_px, sub=4):
    """Displacements that press the passes of one stack together, cross-section by
    cross-section.

    At a sample of a pass, the cross-section of the stack is the normal of that pass there:
    every other pass of the stack whose nearest sample lies within ``reach_px`` and is not
    one of its two ends (a pass that ends before the cross-section is not in it) is taken at
    its signed offset along that normal. With ``m`` passes present, their centroid ``c`` and
    the pass the ``k``-th of them across the section, the pass is moved along the normal to
    ``c + (k - (m - 1) / 2) * pitch_px``: adjacent passes touch, the band is centred where
    the passes were, and narrows where one of them ends or leaves. No axis of the stack is
    needed, so a mean line that covers only part of its passes does not bend them.

    Parameters
    ----------
    curve, normals : (Q, 2) arrays
        The rod's smooth curve in px and its unit normals.
    members : list of int arrays
        Indices into ``curve`` of every pass of the stack (each contiguous).
    pitch_px : float
        Distance between the axes of adjacent pressed passes.
    reach_px : float
        Farthest a pass of the same cross-section can lie.
    sub : int
        The sections are computed every ``sub`` samples and interpolated between.

    Returns
    -------
    list of (len(members[k]), 2) arrays
        The displacement of every sample of every pass.
    """
    from scipy.spatial import cKDTree

    trees = [cKDTree(curve[idx]) for idx in members]
    out = []
    for k, idx in enumerate(members):
        at = np.unique(np.r_[np.arange(0, len(idx), sub), len(idx) - 1])
        p, nrm = curve[idx[at]], normals[idx[at]]
        total = np.zeros(len(at))
        count = np.ones(len(at))
        below = np.zeros(len(at))
        for j, tree in enumerate(trees):
            if j == k:
                continue
            dist, nn = tree.query(p, distance_upper_bound=reach_px)
            ok = np.isfinite(dist) & (nn > 0) & (nn < len(members[j]) - 1)
            nn = np.where(ok, nn, 0)
            off = np.einsum("ij,ij->i", curve[members[j][nn]] - p, nrm)
            total += np.where(ok, off, 0.0)
            count += ok
            below += ok & (off < 0)
        shift = total / count + (below - 0.5 * (count - 1)) * pitch_px
        shift = np.interp(np.arange(len(idx)), at, shift)
        out.append(shift[:, None] * normals[idx])
    return out


def _split_folds(idx, tan, window):
    """The samples ``idx`` of a pass cut at its collapsed folds.

    A fold tighter than the contact distance is one pass at its apex for the contact analysis
    (:mod:`simulate.contacts`), so a run can hold both arms of a fold; pressed as one pass, its
    arms would keep their gap. A fold is where the tangent turns by more than 150 degrees
    within ``window`` samples either side; the pass is cut where it turns most.
    """
    if len(idx) <= 2 * window + 2:
        return [idx]
    t = tan[idx]
    dot = np.full(len(idx), 1.0)
    dot[window:-window] = np.einsum("ij,ij->i", t[:-2 * window], t[2 * window:])
    fold = dot < -0.87
    if not fold.any():
        return [idx]
    edges = np.diff(np.r_[0, fold.astype(int), 0])
    cuts = [a + int(np.argmin(dot[a:b])) for a, b in zip(np.flatnonzero(edges == 1),
                                                          np.flatnonzero(edges == -1))]
    return np.split(idx, cuts)


def _taper_fill(disp, pressed, taper_samples):
    """Displacements along the rod: those of the pressed samples, blended to zero over
    ``taper_samples`` samples (a raised cosine) on the unpressed samples beyond them."""
    n = len(disp)
    out = np.where(pressed[:, None], disp, 0.0)
    if taper_samples <= 0 or pressed.all() or not pressed.any():
        return out
    idx = np.arange(n)
    # nearest pressed sample before and after every sample
    prev = np.maximum.accumulate(np.where(pressed, idx, -1))
    nxt = np.minimum.accumulate(np.where(pressed, idx, n)[::-1])[::-1]
    free = ~pressed
    for near in (prev, nxt):
        ok = free & (near >= 0) & (near < n)
        dist = np.abs(idx[ok] - near[ok])
        w = np.where(dist < taper_samples, 0.5 * (1 + np.cos(np.pi * dist / taper_samples)), 0.0)
        out[ok] += w[:, None] * disp[near[ok]]
    return out


def _pass_curves(xy, analysis, frame, *, segment_px, pitch_px, stroke_px, taper_px,
                 smooth_px=0.0, step_px=0.5):
    """The drawn rod: its smooth curve with the passes of every stack pressed together.

    Returns
    -------
    curve : (Q, 2) array
        The pressed curve in px, sampled every ``step_px`` along the rod.
    branch_of : (Q,) int array
        The branch of every sample.
    disp : (Q, 2) array
        The displacement applied to every sample (pressing and taper).
    """
    from scipy.ndimage import gaussian_filter1d

    base = smooth_line(frame.to_px(xy), segment_px, step_px)
    s = np.linspace(0.0, 1.0, len(base))
    br = analysis.branches
    s0 = br["s_start"].to_numpy(float)
    branch_of = np.clip(np.searchsorted(s0, s, side="right") - 1, 0, len(br) - 1)
    stack_of_branch = br["stack_id"].to_numpy(int)
    n_br = analysis.stacks["n_br"].to_numpy(int)
    tan = np.gradient(base, axis=0)
    tan /= np.maximum(np.hypot(tan[:, 0], tan[:, 1]), 1e-12)[:, None]
    normals = np.c_[-tan[:, 1], tan[:, 0]]
    # passes of one stack are chained within the contact distance
    reach = analysis.contact_distance * frame.scale
    disp = np.zeros_like(base)
    pressed = np.zeros(len(base), bool)
    fold_window = max(int(round(reach / step_px)), 1)
    for sid in np.flatnonzero(n_br >= 2):
        members = [piece for b in np.flatnonzero(stack_of_branch == sid)
                   for piece in _split_folds(np.flatnonzero(branch_of == b), tan, fold_window)]
        members = [m for m in members if len(m) > 2]
        if len(members) < 2:
            continue
        for idx, dd in zip(members, _press_stack(base, normals, members, pitch_px,
                                                 reach * len(members))):
            disp[idx] = dd
            pressed[idx] = True
    arc_step = float(np.hypot(*np.diff(base, axis=0).T).mean()) if len(base) > 1 else 1.0
    disp = _taper_fill(disp, pressed, taper_px / arc_step)
    # the order of the passes present changes where one ends or leaves: no step in the drawing
    sigma = max(pitch_px, smooth_px) / arc_step
    if sigma > 0:
        disp = gaussian_filter1d(disp, sigma, axis=0, mode="nearest")
    curve = base + disp
    if frame.hole_is_wall and frame.hole_px is not None:
        curve = _inside_wall(curve, frame.hole_xy, frame.hole_px - 0.5 * stroke_px)
    return curve, branch_of, curve - base


def _draw_passes(curve, branch_of, stack_of_branch, stroke_px, shape):
    """Anti-aliased ink of the rod drawn as one stroke ``stroke_px`` wide, and the stack label
    image (``k + 1`` on the ink of stack ``k``)."""
    shift = 4
    canvas = np.full(shape, 255, np.uint8)
    labels = np.zeros(shape, np.int32)
    cuts = np.flatnonzero(np.diff(branch_of)) + 1
    starts = np.r_[0, cuts]
    ends = np.r_[cuts, len(curve)]
    thick = max(1, int(round(stroke_px)))
    for a, b in zip(starts, ends):
        # one sample into the next branch: no hole at the boundary
        p = np.round(curve[a:min(b + 1, len(curve))] * (1 << shift)).astype(np.int32)
        p = p.reshape(-1, 1, 2)
        cv2.polylines(canvas, [p], False, 0, 1, cv2.LINE_8, shift)
        cv2.polylines(labels, [p], False, int(stack_of_branch[branch_of[a]]) + 1, thick,
                      cv2.LINE_8, shift)
    d = cv2.distanceTransform(canvas, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    # the rasterised line sits up to half a pixel off the curve, which would make strokes and
    # pressed bands up to a pixel wider than w(n): near the ink, measure from the curve itself
    # (samples half a pixel apart)
    from scipy.spatial import cKDTree

    rr, cc = np.nonzero(d <= 0.5 * stroke_px + 1.5)
    exact, _ = cKDTree(curve).query(np.c_[cc, rr].astype(float))
    d[rr, cc] = exact
    coverage = np.clip(0.5 * stroke_px - d + 0.5, 0, 1).astype(np.float32)
    labels[coverage < 0.5] = 0
    return coverage, labels


def _draw_scan(rng, coverage, enclosed, frame, lines_px, widths_px, *, smears, specks, pinholes):
    """The noise-free float32 scan: paper, receding surfaces, smears, ink, specks, pinholes."""
    h_px, w_px = frame.shape
    ink_mask = coverage >= 0.5
    img = np.empty((h_px, w_px, 3), np.float32)
    img[:] = ink.paper_rgb(rng)
    img[enclosed] = ink.receding_rgb(rng)
    if frame.hole_px is not None:
        rr, cc = np.mgrid[0:h_px, 0:w_px]
        outside = (rr - frame.hole_xy[1]) ** 2 + (cc - frame.hole_xy[0]) ** 2 > frame.hole_px ** 2
        img[outside & ~ink_mask] = ink.PAPER_RGB * 0.97
        centre_xy, radius_px = frame.hole_xy, frame.hole_px
    else:
        centre_xy, radius_px = (0.5 * w_px, 0.5 * h_px), 0.5 * min(h_px, w_px)
    degrade.add_smears(img, rng, count=smears, centre_xy=centre_xy, radius_px=radius_px)
    ink_rgb = ink.ink_rgb(rng)
    # a per-pixel shade: the ink of a real scan is not flat
    ink_jit = rng.normal(0, 6, size=(h_px, w_px, 1)).astype(np.float32)
    a = coverage[..., None]
    img = img * (1 - a) + (ink_rgb + ink_jit) * a
    degrade.add_specks(img, rng, count=specks, background=coverage == 0, ink_rgb=ink_rgb)
    degrade.add_pinholes(img, rng, count=pinholes, paths_xy=lines_px, widths_px=widths_px)
    return img


def _finish(img, rng, frame, ink_mask, d):
    """Plate, illumination and colour cast (when asked), then blur, noise, uint8 and JPEG."""
    if d["plate"] is not None or d["illumination"] > 0 or d["cast"] > 0:
        hole_rc = ((frame.hole_xy[1], frame.hole_xy[0]) if frame.hole_xy is not None
                   else (0.5 * frame.shape[0], 0.5 * frame.shape[1]))
        radius = frame.hole_px if frame.hole_px is not None else float(max(frame.shape))
        rgb = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        img = apply_backdrop(rgb, ink_mask=ink_mask, hole_center_rc=hole_rc,
                             hole_radius_px=radius, rng=rng, plate=d["plate"],
                             rim_px=d["rim_px"], illumination=d["illumination"],
                             cast=d["cast"]).astype(np.float32)
    return degrade.finish_scan(img, rng, blur_px=d["blur_px"], noise_sigma=d["noise_sigma"],
                               jpeg_quality=d["jpeg_quality"])


def _defects(clean: bool, given: dict, has_hole: bool) -> dict:
    """The scan defects: :data:`SCAN_DEFECTS` (or :data:`CLEAN`) overridden by ``given``
    (None: keep the default), checked."""
    d = dict(CLEAN if clean else SCAN_DEFECTS)
    d.update({k: v for k, v in given.items() if v is not None})
    if isinstance(d["plate"], str) and d["plate"].lower() == "none":
        d["plate"] = None
    for k in ("noise_sigma", "blur_px", "rim_px", "illumination", "cast"):
        v = d[k]
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ParameterError(f"{k} must be a finite number >= 0, got {v!r}")
    if d["noise_sigma"] > MAX_NOISE_SIGMA:
        raise ParameterError(f"noise_sigma must be at most {MAX_NOISE_SIGMA:g} grey levels "
                             "(the ink's contrast with the paper: beyond, the scan is noise), "
                             f"got {d['noise_sigma']:g}")
    if d["blur_px"] > MAX_BLUR_PX:
        raise ParameterError(f"blur_px must be at most {MAX_BLUR_PX:g} px (ten sheet "
                             "thicknesses at the defaults: a band keeps 4 % of its contrast), "
                             f"got {d['blur_px']:g}")
    for k in ("illumination", "cast"):
        if d[k] >= 1:
            raise ParameterError(f"{k} must be below 1 (a relative deviation), got {d[k]!r}")
    for k in ("smears", "specks", "pinholes"):
        v = d[k]
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ParameterError(f"{k} must be a whole number >= 0, got {v!r}")
        if v > MAX_MARKS:
            raise ParameterError(f"{k} must be at most {MAX_MARKS} (a hundred times the "
                                 f"scan defaults' largest count), got {v!r}")
    q = d["jpeg_quality"]
    if q is not None and (isinstance(q, bool) or not isinstance(q, (int, np.integer))
                          or not 0 <= q <= 100):
        raise ParameterError(f"jpeg_quality must be a whole number 1-100 (0: none), got {q!r}")
    if q == 0:
        d["jpeg_quality"] = None
    if d["plate"] is not None:
        plate_rgb(d["plate"], np.random.default_rng(0))  # raises on an unknown plate
        if not has_hole:
            if "plate" in given and given["plate"] is not None:
                raise ParameterError("a plate needs a hole (hole_radius_mm or a wall)")
            # the default plate lies around a hole; without one there is nothing to frame
            d["plate"] = None
    return d


def _loop_mid_rc(line_rc):
    """Mid point of a closed line (first point repeated last) started at its raster-first
    point (min row, then min column): the start the pipeline gives a junction-free loop
    (``crosssection.stages.graph``), so the two mid points agree and scoring matches them."""
    q = line_rc[:-1]
    row = np.round(q[:, 0])
    cand = np.flatnonzero(row == row.min())
    i0 = int(cand[np.argmin(q[cand, 1])])
    return polyline.mid_point(np.concatenate([q[i0:], q[:i0]]), closed=True)


def _stack_table(st, lines_px, frame, cal, *, px_per_mm, thickness_mm, layer_px=None):
    """stacks.csv of the truth (schema order) and the region of every stack.

    ``layer_px``: stack id -> drawn length of its passes summed (px), for the bands that
    narrow at a rod end (:func:`_layer_pieces`); their length is that over ``n_br``, the mean
    length of their passes (module docstring, "Rod ends").
    """
    layer_px = layer_px or {}
    rows = []
    for sid, row in st.iterrows():
        line_rc = lines_px[sid][:, ::-1]
        width_mm = float(cal.width(row.n_br))
        region = "bulk"
        if frame.hole_px is not None:
            r = np.hypot(line_rc[:, 1] - frame.hole_xy[0], line_rc[:, 0] - frame.hole_xy[1])
            if np.any(r >= frame.hole_px - width_mm * px_per_mm - 2 * thickness_mm * px_per_mm):
                region = "periphery"
        closed = (row.junction_a < 0 and row.junction_b < 0 and len(line_rc) > 3
                  and np.allclose(line_rc[0], line_rc[-1]))
        mid_rc = _loop_mid_rc(line_rc) if closed else polyline.mid_point(line_rc)
        rows.append({"stack_id": int(sid), "junction_a": int(row.junction_a),
                     "junction_b": int(row.junction_b),
                     "length_mm": (layer_px[sid] / row.n_br if sid in layer_px
                                   else polyline.length(line_rc)) / px_per_mm,
                     "width_mm": width_mm,
                     "n_br": int(row.n_br), "region": region, "mid_x_px": float(mid_rc[1]),
                     "mid_y_px": float(mid_rc[0])})
    return pd.DataFrame(rows, columns=schema.STACK_COLUMNS)


def _layer_piece_table(stacks: pd.DataFrame, pieces: dict, px_per_mm: float) -> pd.DataFrame:
    """The truth's stacks as the bands are drawn: a band narrowing at a rod end as its
    pieces of constant pass count (:func:`_layer_pieces`), every other stack as it is.

    An image shows such a band as two runs of different widths and the analysis reads them
    as two stacks cut at the layer step (``kind`` ``step``); the contact analysis' stack
    holds both under one count. :func:`crosssection.truth.scoring.score` matches the
    analysis' stacks against these rows.

    Returns
    -------
    DataFrame
        Columns stack_id (the truth stack the piece belongs to), n_br (passes present along
        the piece), length_mm, mid_x_px, mid_y_px.
    """
    rows = []
    for _, row in stacks.iterrows():
        sid = int(row.stack_id)
        if sid not in pieces:
            rows.append({"stack_id": sid, "n_br": int(row.n_br), "length_mm": row.length_mm,
                         "mid_x_px": row.mid_x_px, "mid_y_px": row.mid_y_px})
            continue
        for line, n in pieces[sid]:
            mid = polyline.mid_point(line[:, ::-1])
            rows.append({"stack_id": sid, "n_br": int(n),
                         "length_mm": polyline.length(line) / px_per_mm,
                         "mid_x_px": float(mid[1]), "mid_y_px": float(mid[0])})
    return pd.DataFrame(rows, columns=list(LAYER_PIECE_COLUMNS))


def _truth_tables(analysis, frame, lines_px, cal, voids, *, px_per_mm, thickness_mm,
                  junctions_px=None, layer_px=None):
    """The four truth tables (crosssection.core.schema), lengths in mm, curvatures in 1/mm;
    ``junctions_px`` replaces the junction points of the bands drawing, ``layer_px`` the
    lengths of the bands that narrow at a rod end (:func:`_stack_table`)."""
    mm_per_l = frame.rod_length_mm
    jt = analysis.junctions
    jpx = junctions_px if junctions_px is not None else _junctions_px(
        analysis, frame, cal.width(analysis.stacks["n_br"].to_numpy(int)) * px_per_mm
        if len(analysis.stacks) else np.zeros(0))
    junctions = pd.DataFrame({"junction_id": jt["junction_id"].astype(int) if len(jt) else [],
                              "x_px": jpx[:, 0], "y_px": jpx[:, 1],
                              "n_stacks": jt["n_stacks"].astype(int) if len(jt) else []})
    stacks = _stack_table(analysis.stacks, lines_px, frame, cal, px_per_mm=px_per_mm,
                          thickness_mm=thickness_mm, layer_px=layer_px)
    br = analysis.branches
    branches = pd.DataFrame({
        "branch_id": br["branch_id"].astype(int), "stack_id": br["stack_id"].astype(int),
        "length_mm": br["length"] * mm_per_l, "kappa_pm": br["kappa_pm"] / mm_per_l,
        "kappa_plus": br["kappa_plus"] / mm_per_l, "kappa_m": br["kappa_pm"].abs() / mm_per_l,
        # e = L int kappa^2 ds is scale free: the simulation's bending energy of the branch
        "energy": br["energy_bending"],
        "region": stacks["region"].to_numpy()[br["stack_id"].to_numpy(int)],
        "energy_confinement": br["energy_confinement"], "s_start": br["s_start"],
        "s_end": br["s_end"]})
    return {"junctions": junctions, "stacks": stacks, "branches": branches, "voids": voids}


def hairpin_nodes(xy) -> tuple[int, float]:
    """The rod's nodes that fold it back within one node, and their share of its bending
    energy.

    A node turning by more than :data:`simulate.ensemble.HAIRPIN_NODE_DEG` is a fold tighter
    than one segment, which the discrete energy prices at up to ``4 / ds`` (a quenched rod of
    300 segments: 1200 of a bending energy of about 2700 at one node, seed 2). No drawing
    shows such a fold: the smooth curve through the nodes turns by a fraction of it, and the
    band ends where the fold lies. The truth's energy counts it all the same, so a scene's
    energy error holds it (docs/validation/README.md, "Resolution: one scene from 20 to 100
    px/mm").

    Parameters
    ----------
    xy : (N+1, 2) array
        The rod's nodes.

    Returns
    -------
    n : int
        Nodes turning by more than the limit.
    share : float
        Their share of the rod's bending energy (0 when there are none).
    """
    from simulate.energy import node_curvature
    from simulate.ensemble import HAIRPIN_NODE_DEG
    from simulate.geometry import angles

    theta, _ = angles(xy)
    sharp = np.abs(np.diff(theta)) > math.radians(HAIRPIN_NODE_DEG)
    if not sharp.any():
        return 0, 0.0
    bending = node_curvature(xy)[1:-1] ** 2  # the interior nodes, as the turns
    total = float(bending.sum())
    return int(sharp.sum()), float(bending[sharp].sum()) / total if total > 0 else 0.0


def _summary(analysis, frame, tables, ink_mask, *, px_per_mm):
    """summary.json of the truth: counts, rod length, compaction, energy, hole."""
    stacks = tables["stacks"]
    if frame.hole_px is not None:
        hole = {"center_x_px": float(frame.hole_xy[0]), "center_y_px": float(frame.hole_xy[1]),
                "radius_px": float(frame.hole_px)}
    else:
        ys, xs = np.nonzero(ink_mask)
        (ccx, ccy), rad = (cv2.minEnclosingCircle(np.c_[xs, ys].astype(np.float32)) if len(xs)
                           else ((0.0, 0.0), 0.0))
        hole = {"center_x_px": float(ccx), "center_y_px": float(ccy), "radius_px": float(rad)}
    n_branches = int(stacks["n_br"].sum()) if len(stacks) else 0
    rod_length_mm = frame.rod_length_mm
    return {
        "n_junctions": int(len(tables["junctions"])), "n_stacks": int(len(stacks)),
        "n_branches": n_branches, "n_voids": int(len(tables["voids"])),
        "mean_branches_per_stack": n_branches / len(stacks) if len(stacks) else 0.0,
        "rod_length_mm": float(rod_length_mm),
        # the scan's compaction rate L / (2 pi R), R the hole (or the enclosing disk of the ink)
        "epsilon": float(rod_length_mm / (2 * np.pi * hole["radius_px"] / px_per_mm))
        if hole["radius_px"] > 0 else None,
        # bending only: the confinement term has no counterpart in a scan
        "total_energy": float(analysis.energy_bending),
        "hole": hole, "timings_s": {},
        "epsilon_rg": analysis.epsilon, "epsilon_rg_sqrt2": analysis.epsilon_sqrt2,
        "rg": analysis.rg, "energy_confinement": analysis.energy_confinement,
        "contact_distance": analysis.contact_distance,
    }


def render_configuration(xy, analysis: RodAnalysis | None = None, *, lam: float = LAMBDA,
                         px_per_mm: float = PX_PER_MM, thickness_mm: float = THICKNESS_MM,
                         rod_length_mm: float | None = None,
                         rod_thickness: float | None = None,
                         wall_radius: float | None = None, wall_center_xy=(0.0, 0.0),
                         calibration: Calibration | None = None,
                         contact_distance: float | None = None, clean: bool = False,
                         noise_sigma: float | None = None, blur_px: float | None = None,
                         jpeg_quality: int | None = None, smears: int | None = None,
                         specks: int | None = None, pinholes: int | None = None,
                         plate=None, rim_px: float | None = None,
                         illumination: float | None = None, cast: float | None = None,
                         smooth: str = "all", draw: str = "bands", join: str = "hook",
                         pass_width: float = PASS_WIDTH, pass_taper: float = PASS_TAPER,
                         pass_smooth: float = PASS_SMOOTH,
                         seed: int = 0, margin_mm: float = 2.0,
                         gap_px: float = 2.0, max_size_px: int = 2500,
                         hole_radius_mm: float | str | None = None) -> Scene:
    """Render one rod configuration into an RGB scan with exact truth tables.

    Parameters
    ----------
    xy : (N+1, 2) array
        Rod node positions (units of L), finite, N >= 2.
    analysis : RodAnalysis, optional
        Result of :func:`simulate.contacts.analyze_rod` (computed when omitted).
    lam : float
        Lambda for the analysis when computed here.
    px_per_mm, thickness_mm : float
        Scan resolution and sheet thickness h.
    rod_length_mm : float, optional
        Length of the rod in mm; default ``thickness_mm / rod_thickness`` when the rod has a
        thickness, else the smallest that keeps a visible gap of ``gap_px`` between passes
        farther apart than delta (module docstring), capped so the image stays under
        ``max_size_px``.
    rod_thickness : float, optional
        The rod's thickness h (units of L; ``python -m simulate compact``).
    wall_radius : float, optional
        Radius of the hard wall the rod was compacted in (units of L), centred on
        ``wall_center_xy``: with ``hole_radius_mm="auto"`` it is the hole.
    wall_center_xy : (float, float)
        Centre of the wall (units of L; the compaction's is the origin).
    calibration : Calibration, optional
        Width law; default :meth:`Calibration.nonlinear`.
    contact_distance : float, optional
        delta for the analysis when computed here.
    clean : bool
        Start from no defect (:data:`CLEAN`) instead of a real scan's (:data:`SCAN_DEFECTS`).
    noise_sigma, blur_px : float, optional
        Gaussian noise (grey levels) and Gaussian blur sigma (px, at most
        :data:`MAX_BLUR_PX`).
    jpeg_quality : int, optional
        JPEG round trip at this quality (1-100; 0: none).
    smears, specks, pinholes : int, optional
        Numbers of light-blue smears (rejected by the threshold), small ink specks in the
        paper and paper-coloured pinholes in wide bands (both removed by cleaning); see
        :mod:`crosssection.truth.degrade`.
    plate : str or (3,) float, optional
        Plate around the hole (:data:`crosssection.truth.backdrop.PLATES`, ``"coloured"``,
        an RGB triple, or ``"none"``); needs a hole.
    rim_px, illumination, cast : float, optional
        Dark rim outside the hole, illumination gradient and colour cast
        (:func:`crosssection.truth.backdrop.apply_backdrop`).
    smooth : {"all", "long", "none"}
        Draw every stack along its smooth curve (:func:`smooth_line`, short links included),
        only the stacks of two segments or more (the drawing of :mod:`simulate.atlas`), or
        none: the polylines of the analysis, with their corners. Bands drawing only.
    join : {"hook", "junction"}
        Bands drawing: how a band joins its junctions (:data:`JOIN`): its own mean line, cleaned
        and cut back near the junction, smoothed into the junction point (``"hook"``, the
        default, :func:`_hooked_lines`), or the analysis' line through the junction points as
        it is (``"junction"``; also whenever ``smooth="none"``, which draws the analysis'
        polylines).
    draw : {"bands", "passes"}
        One band of the calibrated width per stack, along its mean line (default), or the rod
        itself: every pass a stroke along the smooth curve through the nodes, the passes of
        every stack pressed into touching strokes (module docstring, "Drawing the rod
        itself"). With ``"passes"`` the default calibration is :func:`passes_calibration`.
    pass_width : float
        ``draw="passes"``: ink width of one pass, in units of h (default :data:`PASS_WIDTH`;
        more than :data:`PASS_OVERLAP_PX`).
    pass_taper : float
        ``draw="passes"``: length, in pass widths, over which a pass pressed into a stack
        returns to its own position outside it (default :data:`PASS_TAPER`).
    pass_smooth : float
        ``draw="passes"``: the pressing displacements smoothed along the rod over this many
        rod segments; 0 (default, :data:`PASS_SMOOTH`): over one pitch.
    seed : int
        Seed of every random choice (colours, noise, defects).
    margin_mm : float
        Paper around the configuration.
    gap_px : float
        Smallest visible gap between passes farther apart than delta.
    max_size_px : int
        Largest side of the rod's drawing when ``rod_length_mm`` is chosen here from the gap:
        a soft cap (a warning when it cannot be kept; the hard limit is
        :data:`MAX_SCENE_PX`). The hole around the rod and its margins widen the image
        beyond it (a default render of a quench at the paper's parameters: 3022 x 2080 px
        under the default 2500).
    hole_radius_mm : float, "auto" or None
        Draw a hard-wall disk of this radius centred on the wall's centre, or without a wall on
        the rod's centre of mass (stacks touching it are "periphery"); ``"auto"``: the wall,
        or without one the smallest disk enclosing the rod plus the half width of the thickest
        band and 2 h, centred on it (the CLI default: a scan always has its container); None:
        no hole (all "bulk").

    Defects left at None take the value of :data:`SCAN_DEFECTS`, or of :data:`CLEAN` when
    ``clean``.

    Returns
    -------
    Scene
        With ``paths_rc`` (the drawn centrelines) and ``ink_mask``; no ``packs``.

    Raises
    ------
    ParameterError
        An absurd option, a rod with a segment of zero length or a coordinate beyond
        :data:`MAX_ROD_COORD`, a scene that would exceed :data:`MAX_SCENE_PX` pixels (checked
        before anything is drawn), or a ``rod_length_mm`` that contradicts ``rod_thickness``
        (``thickness_mm / rod_length_mm`` off by more than :data:`SCALE_TOLERANCE`).

    Warns
    -----
    crosssection.quality.ResolutionWarning
        ``max_size_px`` is not kept: the rod length was capped to it (passes just beyond delta
        may touch), or the margins alone exceed it (the image is larger).
    ScanRangeWarning
        The sheet is thinner in the image, or the blur, noise or JPEG compression stronger,
        than on the scans the image analysis is validated on (:data:`VALIDATED_SHEET_PX`
        and the other ``VALIDATED_`` limits), or the rod has fewer segments than the renders'
        truth is validated from (:data:`VALIDATED_COMPACT_SEGMENTS` with ``rod_thickness``,
        else :data:`VALIDATED_QUENCH_SEGMENTS`).
    TruthWarning
        The truth disagrees with the drawing (module docstring, "Truth checks"); the
        messages are also the summary's ``truth_warnings``.
    """
    xy = _checked_rod(xy)
    if analysis is not None and not isinstance(analysis, RodAnalysis):
        raise ParameterError(f"analysis must be a RodAnalysis (simulate.contacts.analyze_rod) "
                             f"or None, got {type(analysis).__name__}")
    _check_seed(seed)
    if smooth not in SMOOTH:
        raise ParameterError(f"smooth must be one of {SMOOTH}, got {smooth!r}")
    for name, v in (("px_per_mm", px_per_mm), ("thickness_mm", thickness_mm),
                    ("max_size_px", max_size_px)):
        check_real(name, v, low=0.0, low_open=True)
    for name, v in (("margin_mm", margin_mm), ("gap_px", gap_px)):
        check_real(name, v, low=0.0)
    if analysis is None:
        # only the analysis computed here reads them
        check_real("lam", lam, low=0.0)
        if contact_distance is not None:
            check_real("contact_distance", contact_distance, low=0.0, low_open=True)
    if not (hole_radius_mm is None or isinstance(hole_radius_mm, str)
            and hole_radius_mm == "auto"):
        check_real("hole_radius_mm", hole_radius_mm, low=0.0, low_open=True,
                   also="'auto' or None")
    if wall_radius is not None and not is_point(wall_center_xy):
        raise ParameterError(f"wall_center_xy must be two finite numbers (x, y), got "
                             f"{wall_center_xy!r}")
    if px_per_mm * thickness_mm < MIN_SHEET_PX:
        # the analysis refuses such a scan: a sheet thinner than a pixel cannot be resolved
        raise ParameterError(f"a sheet would be {px_per_mm * thickness_mm:.3g} px thick (< "
                             f"{MIN_SHEET_PX:g} px at {px_per_mm:g} px/mm and h = "
                             f"{thickness_mm:g} mm): no scan to analyse", "px_per_mm")
    for name, v in (("rod_thickness", rod_thickness), ("wall_radius", wall_radius),
                    ("rod_length_mm", rod_length_mm)):
        if v is not None:
            check_real(name, v, low=0.0, low_open=True)
    _check_scale(rod_length_mm, thickness_mm, rod_thickness)
    if calibration is not None and not isinstance(calibration, Calibration):
        raise ParameterError(f"calibration must be a Calibration, got {type(calibration).__name__}")
    if draw not in DRAW:
        raise ParameterError(f"draw must be one of {DRAW}, got {draw!r}")
    if join not in JOIN:
        raise ParameterError(f"join must be one of {JOIN}, got {join!r}")
    for name, v in (("pass_width", pass_width), ("pass_taper", pass_taper),
                    ("pass_smooth", pass_smooth)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ParameterError(f"{name} must be a finite number >= 0, got {v!r}")
    _check_pass_smooth(pass_smooth)
    if draw == "passes" and not pass_width * thickness_mm * px_per_mm > PASS_OVERLAP_PX:
        raise ParameterError(f"pass_width must exceed {PASS_OVERLAP_PX} px, got "
                             f"{pass_width * thickness_mm * px_per_mm:g} px")
    if analysis is None:
        analysis = analyze_rod(xy, lam=lam, contact_distance=contact_distance)
    if draw == "passes":
        stroke_px = pass_width * thickness_mm * px_per_mm
        pitch_px = stroke_px - PASS_OVERLAP_PX
        cal = calibration or passes_calibration(stroke_px / px_per_mm, pitch_px / px_per_mm)
    else:
        cal = calibration or Calibration.nonlinear(thickness_mm)
    frame = _frame(xy, analysis, cal, px_per_mm=px_per_mm, thickness_mm=thickness_mm,
                   rod_length_mm=rod_length_mm, hole_radius_mm=hole_radius_mm,
                   margin_mm=margin_mm, gap_px=gap_px, max_size_px=max_size_px,
                   rod_thickness=rod_thickness, wall_radius=wall_radius,
                   wall_center_xy=wall_center_xy)
    _check_scene_size(frame, px_per_mm)
    if px_per_mm * thickness_mm > MAX_SHEET_PX:
        raise ParameterError(f"a sheet would be {px_per_mm * thickness_mm:.3g} px thick (> "
                             f"{MAX_SHEET_PX:g} px at {px_per_mm:g} px/mm and h = "
                             f"{thickness_mm:g} mm): lower px_per_mm or thickness_mm",
                             "thickness_mm")
    given = {"noise_sigma": noise_sigma, "blur_px": blur_px, "jpeg_quality": jpeg_quality,
             "smears": smears, "specks": specks, "pinholes": pinholes, "plate": plate,
             "rim_px": rim_px, "illumination": illumination, "cast": cast}
    d = _defects(clean, given, frame.hole_px is not None)
    beyond = _beyond_validated(d, px_per_mm * thickness_mm)
    if beyond:
        warnings.warn(beyond, ScanRangeWarning, stacklevel=2)
    short = _rod_beyond_validated(len(xy) - 1, rod_thickness is not None)
    if short:
        warnings.warn(short, ScanRangeWarning, stacklevel=2)
    rng = np.random.default_rng(seed)
    st = analysis.stacks
    segment_px = frame.scale / (len(xy) - 1)
    n_br = st["n_br"].to_numpy(int)
    widths_px = cal.width(n_br) * px_per_mm
    if smooth == "none":
        join = "junction"  # the analysis' polylines as they are
    if draw == "bands" and join == "hook":
        lines_px = _hooked_lines(analysis, frame, widths_px, segment_px=segment_px,
                                 smooth=smooth)
    else:
        lines_px = _stack_lines(analysis, frame, widths_px, segment_px=segment_px,
                                smooth=smooth)
    truth_warnings = []
    touching = []
    pieces = {}
    if draw == "passes":
        curve, branch_of, _ = _pass_curves(
            xy, analysis, frame, segment_px=segment_px, pitch_px=pitch_px, stroke_px=stroke_px,
            taper_px=pass_taper * stroke_px, smooth_px=pass_smooth * segment_px)
        junctions_px = _pass_junctions_px(analysis, frame, stroke_px)
        # every pass is drawn at its own length: a stack's is the mean of its passes' (the
        # analysis'), not its mean line's, which runs between junction points that can lie
        # far from where its passes end
        layer_px = {sid: float(row.n_br * row.length * frame.scale)
                    for sid, row in st.iterrows()}
        coverage, labels = _draw_passes(curve, branch_of,
                                        analysis.branches["stack_id"].to_numpy(int), stroke_px,
                                        frame.shape)
    else:
        junctions_px = None
        coverage, labels, layer_px, pieces = _draw_stacks(analysis, frame, lines_px, n_br,
                                                          widths_px, cal, px_per_mm)
        # joining every band to its junction point would connect them, but across the paper
        # to a point none of its passes reaches (bending the drawn lines tens of times as much
        # as the rod, and lengthening the truth's rod): the scene says so instead
        cut = _disconnected_junctions(st, labels, coverage >= 0.5)
        if cut:
            truth_warnings.append(
                f"the bands of junction{'s' if len(cut) > 1 else ''} "
                f"{', '.join(str(j) for j in cut)} do not touch: the drawn rod is cut where "
                "the truth holds it together")
        # bands joined elsewhere can still stand apart at their junction
        drawn = [[(q, float(cal.width(c)) * px_per_mm) for q, c in pieces[sid]] if sid in pieces
                 else [(lines_px[sid], float(widths_px[sid]))] for sid in range(len(lines_px))]
        jt = analysis.junctions
        apart = [j for j in _apart_junctions(
            st[["junction_a", "junction_b"]].to_numpy(int), lines_px, drawn,
            dict(zip(jt["junction_id"].to_numpy(int).tolist(),
                     _junctions_px(analysis, frame, widths_px))) if len(jt) else {},
            frame.shape, JUNCTION_INK_H * thickness_mm * px_per_mm) if j not in cut]
        if apart:
            truth_warnings.append(
                f"the bands of junction{'s' if len(apart) > 1 else ''} "
                f"{', '.join(str(j) for j in apart)} do not all touch there: the image shows "
                "no junction where the truth has one, and the voids they bound open into "
                "each other")
        touching = _touching_pieces(st, lines_px, widths_px, gap_px)
        if touching:
            truth_warnings.append(_touching_message(touching, st["stack_id"].to_numpy(int)))
    ink_mask = coverage >= 0.5
    voids = truth_voids(ink_mask, hole_center_xy=frame.hole_xy, hole_radius_px=frame.hole_px,
                        s_min_px=(10 * thickness_mm * px_per_mm) ** 2, px_per_mm=px_per_mm,
                        stack_labels=labels,
                        stack_ends=st[["junction_a", "junction_b"]].to_numpy(int),
                        stack_widths_px=widths_px, min_contact_px=2 * thickness_mm * px_per_mm)
    void_count = _void_count_check(
        len(voids.table), analysis.voids, frame.rod_length_mm, (10 * thickness_mm) ** 2,
        float(np.max(widths_px, initial=0.0)) / px_per_mm,
        analysis.contact_distance * frame.rod_length_mm)
    if void_count:
        truth_warnings.append(void_count)
    img = _draw_scan(rng, coverage, voids.enclosed, frame, lines_px, widths_px,
                     smears=d["smears"], specks=d["specks"], pinholes=d["pinholes"])
    rgb = _finish(img, rng, frame, ink_mask, d)
    tables = _truth_tables(analysis, frame, lines_px, cal, voids.table, px_per_mm=px_per_mm,
                           thickness_mm=thickness_mm, junctions_px=junctions_px,
                           layer_px=layer_px)
    tables["junctions"], moved = _junctions_onto_ink(
        tables["junctions"], tables["stacks"], labels, ink_mask,
        JUNCTION_INK_H * thickness_mm * px_per_mm, px_per_mm=px_per_mm)
    truth_warnings += moved
    rod_drawn = _rod_drawn_check(tables["stacks"], frame.rod_length_mm)
    if rod_drawn:
        truth_warnings.append(rod_drawn)
    empty = _zero_length_check(tables["stacks"])
    if empty:
        truth_warnings.append(empty)
    tables[LAYER_PIECES] = _layer_piece_table(tables["stacks"], pieces, px_per_mm)
    for message in truth_warnings:
        warnings.warn(message, TruthWarning, stacklevel=2)
    if rod_length_mm is None and rod_thickness is None and not frame.gap_ok:
        # the scale chosen here was capped by max_size_px (the ResolutionWarning above says
        # so): passes the truth keeps apart may be drawn merged, and validate must not count
        # the scene as a truth
        truth_warnings.append(
            f"rod length capped at {frame.rod_length_mm:.1f} mm by max_size_px = "
            f"{max_size_px}: passes farther apart than the contact distance are not "
            "guaranteed a visible gap, and the drawn bands may merge stacks the truth keeps "
            "apart (a thinner sheet, a lower px_per_mm or a larger max_size_px keeps them)")
    summary = _summary(analysis, frame, tables, ink_mask, px_per_mm=px_per_mm)
    summary["truth_warnings"] = truth_warnings
    # a fold within one node: its energy is the discretisation's, and no drawing shows it
    summary["hairpin_energy_share"] = hairpin_nodes(xy)[1]
    # a rod coarser than the truth is validated from: warned above as a range, and recorded
    # with the scene so that validate names it (its truth is not known to be wrong)
    summary["truth_range"] = short
    params = {"px_per_mm": float(px_per_mm), "thickness_mm": float(thickness_mm),
              "hole_radius_mm": frame.hole_radius_mm,
              "hole_center_px": None if frame.hole_xy is None else
              [float(frame.hole_xy[0]), float(frame.hole_xy[1])],
              "seed": int(seed), "rod_length_mm": float(frame.rod_length_mm),
              "contact_distance": analysis.contact_distance,
              # passes beyond delta show a gap, and no pieces the truth holds apart touch
              "gap_guaranteed": bool(frame.gap_ok and not touching),
              "rod_thickness": rod_thickness, "wall_radius": wall_radius, "clean": bool(clean),
              **{k: (v if not isinstance(v, np.ndarray) else v.tolist()) for k, v in d.items()},
              "smooth": smooth, "draw": draw, **({"join": join} if draw == "bands" else {}),
              **({"pass_width": float(pass_width), "pass_taper": float(pass_taper),
                  "pass_smooth": float(pass_smooth)}
                 if draw == "passes" else {}),
              "origin_xy": frame.origin_xy.tolist(), "margin_px": float(frame.margin_px)}
    return Scene(rgb, summary, tables, params, cal,
                 paths_rc=[line[:, ::-1] for line in lines_px], ink_mask=ink_mask)


#: Scan defect keywords of :func:`render_configuration`.
_DEFECT_NAMES = ("noise_sigma", "blur_px", "jpeg_quality", "smears", "specks", "pinholes",
                 "plate", "rim_px", "illumination", "cast")
#: The record of a render in its output folder: its parameters, source and the package
#: version; a re-run into the folder resumes only when they agree (:func:`_claim_out`).
RENDER_RECORD = "render.json"
#: Entries of a simulation's params.json a render does not depend on: a re-run of the
#: ensemble adds configurations and records the versions it ran with.
_SOURCE_IGNORED = ("n_configs", "version", "libraries", "versions")


def _checked_rod(xy) -> np.ndarray:
    """``xy`` as an (N+1, 2) float array of finite numbers with N >= 2 (the contact analysis
    needs two segments) and a rod of non-zero length, else a :class:`ParameterError` naming
    ``xy`` or the rod's length.

    A rod whose nodes all coincide has no scale: its image would be a blank scan of the
    margins alone, with truth tables of a rod that is not drawn.
    """
    arr = checked_rod(xy, min_segments=2)
    cause = _rod_defect(arr)
    if cause:
        raise ParameterError(f"xy {cause}")
    check_real("rod length", float(np.sum(np.hypot(*np.diff(arr, axis=0).T))), low=0.0,
               low_open=True, why="the sum of the segments of xy; a rod whose nodes all "
               "coincide has nothing to draw")
    return arr


def _rod_defect(xy: np.ndarray) -> str | None:
    """Why the finite (N+1, 2) rod ``xy`` cannot be drawn with an exact truth, or None.

    Parameters
    ----------
    xy : (N+1, 2) float array

    Returns
    -------
    str or None
        A coordinate beyond :data:`MAX_ROD_COORD`, or a segment of zero length (two
        consecutive nodes at the same place), in a phrase following the rod's name.
    """
    far = float(np.abs(xy).max())
    if far > MAX_ROD_COORD:
        return (f"has a coordinate of {far:.3g}, beyond {MAX_ROD_COORD:g} (rods are in units "
                "of the rod length L, centred near the origin)")
    zero = np.flatnonzero(~np.any(np.diff(xy, axis=0), axis=1))
    if len(zero) and len(zero) < len(xy) - 1:
        return (f"has {len(zero)} segment(s) of zero length (nodes {zero[0]} and {zero[0] + 1} "
                "at the same place): a rod's energy is that of its segments, and a repeated "
                "node gives a bend of no length")
    return None


def _check_scale(rod_length_mm, thickness_mm, rod_thickness, where=None) -> None:
    """Refuse a rod length that contradicts a compaction's thickness.

    Parameters
    ----------
    rod_length_mm : float or None
        The rod length asked for (None: the one the thickness sets).
    thickness_mm : float
        Sheet thickness h of the scan.
    rod_thickness : float or None
        The compaction's rod thickness, units of L (None: a rod without thickness).
    where : str, optional
        Where the rod thickness comes from, for the message (default: ``rod_thickness``).

    Raises
    ------
    ParameterError
        ``thickness_mm / rod_length_mm`` differs from ``rod_thickness`` by more than
        :data:`SCALE_TOLERANCE`: the passes would be drawn thicker or thinner than the rod.
    """
    if rod_length_mm is None or rod_thickness is None:
        return
    drawn = thickness_mm / rod_length_mm
    if abs(drawn / rod_thickness - 1.0) <= SCALE_TOLERANCE:
        return
    raise ParameterError(
        f"{rod_length_mm:g} with thickness_mm {thickness_mm:g} draws passes {drawn:.4g} L "
        f"thick, but {where or 'rod_thickness'} is {rod_thickness:.4g} L "
        f"({drawn / rod_thickness:.3g} times): the drawn rod would not be the compacted one; "
        f"leave rod_length_mm out (it is thickness_mm / {rod_thickness:.4g} = "
        f"{thickness_mm / rod_thickness:.4g} mm) or change thickness_mm", "rod_length_mm")


def _check_seed(seed) -> None:
    """Refuse a seed numpy's generators do not take (they need a whole number >= 0)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError(f"seed must be a whole number >= 0, got {seed!r}")


def _check_pass_smooth(v) -> None:
    """``pass_smooth`` is a number of rod segments in [0, :data:`PASS_SMOOTH_MAX`]."""
    if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= PASS_SMOOTH_MAX):
        raise ParameterError(f"pass_smooth must be a number in [0, {PASS_SMOOTH_MAX:g}] rod "
                             f"segments, got {v!r}")


def _check_options(kwargs: dict) -> dict:
    """Check the scan options of :func:`render_directory` before any configuration is
    analysed (a bad value fails at once, not after the first analysis); return the scan
    defects they give (:func:`_defects`)."""
    given = {k: kwargs[k] for k in _DEFECT_NAMES if k in kwargs}
    has_hole = kwargs.get("hole_radius_mm", None) is not None
    defects = _defects(bool(kwargs.get("clean", False)), given,
                       has_hole or "plate" not in given)
    if kwargs.get("smooth", "all") not in SMOOTH:
        raise ParameterError(f"smooth must be one of {SMOOTH}, got {kwargs['smooth']!r}")
    if kwargs.get("draw", "bands") not in DRAW:
        raise ParameterError(f"draw must be one of {DRAW}, got {kwargs['draw']!r}")
    if kwargs.get("join", "hook") not in JOIN:
        raise ParameterError(f"join must be one of {JOIN}, got {kwargs['join']!r}")
    if "pass_smooth" in kwargs:
        if kwargs.get("draw", "bands") != "passes":
            raise ParameterError("pass_smooth applies only to draw 'passes'")
        _check_pass_smooth(kwargs["pass_smooth"])
    for k in ("px_per_mm", "thickness_mm", "rod_length_mm"):
        v = kwargs.get(k)
        if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ParameterError(f"{k} must be a finite number > 0, got {v!r}")
    h = kwargs.get("hole_radius_mm")
    if h is not None and h != "auto" and not (isinstance(h, (int, float)) and math.isfinite(h)
                                              and h > 0):
        raise ParameterError(f"hole_radius_mm must be a finite number > 0, 'auto' or None, "
                             f"got {h!r}")
    _check_seed(kwargs.get("seed", 0))
    return defects


def _scene_whole(folder: Path) -> bool:
    """Whether a scene folder a render finished is still whole: its image ends (a PNG with
    its closing chunk), its truth tables and records are there. A scene damaged since (a
    file cut short or removed) is rendered again on resume, as a batch redoes a scan whose
    output lost a table."""
    from crosssection.core import schema

    image = folder / "image.png"
    try:
        with open(image, "rb") as fh:
            fh.seek(-12, 2)
            if fh.read(12)[4:8] != b"IEND":
                return False
    except OSError:
        return False
    needed = [folder / "params.json", folder / "calibration.csv",
              *(folder / "truth" / f"{t}.csv" for t in schema.TABLES)]
    return all(p.is_file() and p.stat().st_size > 0 for p in needed)


def _failed_count(sim_dir: Path) -> int:
    """Rows of a simulation's ``failures.csv`` (configurations that stored no rod)."""
    try:
        with open(sim_dir / "failures.csv", encoding="utf-8", errors="replace") as fh:
            return max(sum(1 for line in fh if line.strip()) - 1, 0)
    except OSError:
        return 0


def _rods_path(sim_dir: Path) -> Path:
    """``sim_dir/rods.npz``, once ``sim_dir`` is known to be a folder holding it."""
    if sim_dir.exists() and not sim_dir.is_dir():
        raise ConfigError("not a simulation folder (a file; give the folder holding rods.npz)",
                          sim_dir)
    rods_path = sim_dir / "rods.npz"
    if not rods_path.exists():
        raise ConfigError("no rods.npz (run `python -m simulate quench` first)", rods_path)
    return rods_path


#: The first bytes of what ``np.load`` reads: a zip archive (``.npz``; an empty one starts with
#: its end record) and an ``.npy`` array. Anything else numpy takes for a pickle.
_NPZ_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")
_NPY_MAGIC = b"\x93NUMPY"


def not_npz(path: Path) -> str | None:
    """Why ``path`` is no NumPy archive at all, from its first bytes, or None.

    ``np.load`` takes any other file for a pickle and refuses it with advice to load it
    unsafely, which says nothing of what is wrong with the file: a caller names this cause
    instead.

    Parameters
    ----------
    path : Path
        An existing file.

    Returns
    -------
    str or None
        ``"empty file, not a NumPy .npz archive"``, ``"not a NumPy .npz archive"``, why a
        named pipe or a device is no file to read, or None when the file starts as a zip
        archive or an ``.npy`` array does.

    Raises
    ------
    OSError
        The file cannot be read.
    """
    from crosssection.core.fileio import special_file_reason

    special = special_file_reason(path)
    if special:
        return special
    with open(path, "rb") as fh:
        head = fh.read(len(_NPY_MAGIC))
    if not head:
        return "empty file, not a NumPy .npz archive"
    if head.startswith(_NPZ_MAGIC) or head.startswith(_NPY_MAGIC):
        return None
    return "not a NumPy .npz archive"


def _open_rods(rods_path: Path):
    """The configurations archive, opened lazily (arrays are read on access)."""
    try:
        cause = not_npz(rods_path)
        if cause is not None:
            raise ConfigError(f"unreadable rods file ({cause})", rods_path)
        rods = np.load(rods_path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ConfigError(f"unreadable rods file ({' '.join(str(exc).split())})",
                          rods_path) from None
    if not isinstance(rods, np.lib.npyio.NpzFile):
        # a bare .npy array under the archive's name
        raise ConfigError("unreadable rods file (one array, not an .npz archive of "
                          "configurations)", rods_path)
    return rods


def _jsonable(obj):
    """JSON form of the keyword values a record may hold (numpy scalars and arrays exactly,
    anything else by its repr)."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return repr(obj)


def _used_kwargs(kwargs: dict, lam: float, delta) -> dict:
    """The keywords of :func:`render_configuration` a directory render draws its scenes with:
    ``kwargs`` (the caller's with the compaction's wall and scale, :func:`_render_directory`)
    and the source's ``lam`` and ``contact_distance``, which the contact analysis of every
    scene takes (None: the analysis' default for the rod's N).

    A compaction's rod length is ``thickness_mm / rod_thickness`` unless given (one scale for
    every scene); without a thickness it depends on each rod (its scene's params.json)."""
    used = {**kwargs, "lam": float(lam), "contact_distance": delta}
    if used.get("rod_length_mm") is None and used.get("rod_thickness") is not None:
        used["rod_length_mm"] = (float(used.get("thickness_mm", THICKNESS_MM))
                                 / float(used["rod_thickness"]))
    return used


def _render_record(sim_dir: Path, source_params: dict | None, kwargs: dict) -> dict:
    """The content of ``render.json``: every keyword of :func:`render_configuration` as
    this render uses it (defaults filled in, scan defects resolved; ``seed`` the base seed),
    the source folder, its parameters and the package version."""
    import inspect

    from crosssection._version import __version__

    params = {k: p.default for k, p in inspect.signature(render_configuration).parameters.items()
              if p.kind is p.KEYWORD_ONLY}
    params.update(kwargs)
    # an option left at None and the same defect given explicitly draw the same scans
    params.update(_defects(bool(params["clean"]),
                           {k: params[k] for k in _DEFECT_NAMES}, True))
    source = _source_record(source_params)
    # the scan options as given (None: the default), so that a difference of clean is
    # reported as such rather than as every defect it changes
    given = {k: kwargs.get(k) for k in ("clean", *_DEFECT_NAMES)}
    return json.loads(json.dumps({"command": "render", "params": params, "given": given,
                                  "source": str(sim_dir.resolve()), "source_params": source,
                                  "version": __version__}, default=_jsonable))


def _source_record(source_params: dict | None) -> dict | None:
    """The source ensemble's parameters as render.json records and compares them: every
    default written out (:func:`simulate.ensemble.resolve_defaults`: an ensemble folder that
    recorded None for a default and the same folder resumed, which writes the value out, are
    one source), without :data:`_SOURCE_IGNORED`."""
    if not isinstance(source_params, dict):
        return None
    from simulate.ensemble import resolve_defaults

    return json.loads(json.dumps({k: v for k, v in resolve_defaults(source_params).items()
                                  if k not in _SOURCE_IGNORED}, default=_jsonable))


def _foreign_entry(out_dir: Path, keys) -> str | None:
    """The first entry of ``out_dir`` that no render writes, or None.

    A render writes ``render.json`` and one folder per configuration (named by its key in
    ``rods.npz``, ``keys``; a folder a killed render left half written holds no scene yet,
    nor does the hidden folder a scene is written into, :func:`_write_scene_whole`);
    a scene folder of the same render is kept whatever its name (an earlier ``--limit`` or
    configurations of another count), and so is a ``validate`` report written inside
    (:func:`simulate.validate.is_report_folder`). Anything else (an ensemble's tables, a
    user's notes) would end up mixed with the scenes.
    """
    from crosssection.core.fileio import foreign_entry
    from simulate.validate import is_report_folder

    keys = set(keys)

    def scene_or_report(p):
        # an empty folder: a validate report begun (validate makes its folder first)
        own = (p.name in keys or (p / "params.json").exists() or (p / "truth").exists()
               or is_report_folder(p) or _is_partial_folder(p) or not any(p.iterdir()))
        return None if own else p.name

    return foreign_entry(out_dir, (RENDER_RECORD,), scene_or_report)


def _holds_scenes(out_dir: Path) -> bool:
    """Whether ``out_dir`` holds a scene folder, finished or not."""
    return out_dir.is_dir() and any(
        p.is_dir() and ((p / "params.json").exists() or (p / "truth").exists())
        for p in out_dir.iterdir())


#: Keywords whose values a directory render takes from its source ensemble (its params.json,
#: compared on its own): a record that left them at their defaults (None, or the API's
#: lambda) describes the same render.
_FROM_SOURCE = ("lam", "contact_distance", "rod_thickness", "wall_radius")


def _follows_source(key: str, recorded) -> bool:
    """Whether a difference in ``key`` between two records of one source is no difference:
    the keywords taken from the source, and a compaction's rod length recorded unset (it
    follows from the source's thickness)."""
    return key in _FROM_SOURCE or (key == "rod_length_mm" and recorded is None)


def _claim_out(out_dir: Path, record: dict, name=str, keys=()) -> bool:
    """Refuse an output folder whose scenes were rendered otherwise, or that holds anything
    a render does not write.

    A re-run resumes (finished scenes are skipped), so the scenes there must have been
    rendered with the same parameters from the same ensemble: otherwise the folder would mix
    scans of two renders. A folder without scenes is free when it is empty (or holds only
    the half-written folders of a killed render): other files there (an ensemble, a user's
    notes) are refused, as ``quench`` and ``compact`` refuse them.

    Parameters
    ----------
    out_dir : Path
    record : dict
        This render's :func:`_render_record`.
    name : callable
        Keyword -> the name shown for it (the CLI's options).
    keys : iterable of str
        The configurations of the source's ``rods.npz`` (the names of the scene folders).

    Returns
    -------
    bool
        Whether the folder holds scenes of this render (its render.json is kept as it is).

    Raises
    ------
    ConfigError
        The folder holds an entry no render writes (:func:`_foreign_entry`, naming it),
        scenes without ``render.json`` (parameters unknown), an unreadable one, or one of
        another render (the parameters that differ are listed).
    """
    if out_dir.is_dir():
        foreign = _foreign_entry(out_dir, keys)
        if foreign is not None:
            raise ConfigError(f"holds {foreign}, which is no part of a render output: give a "
                              "new folder, an empty one or one an earlier render wrote",
                              out_dir)
    if not _holds_scenes(out_dir):
        return False
    path = out_dir / RENDER_RECORD
    if not path.exists():
        raise ConfigError(f"output folder holds scenes but no {RENDER_RECORD} (rendered by an "
                          "older version: their parameters are unknown); use another --out",
                          out_dir)
    try:
        old = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"unreadable {RENDER_RECORD} ({' '.join(str(exc).split())})",
                          path) from None
    if not isinstance(old, dict) or not isinstance(old.get("params"), dict):
        raise ConfigError("malformed (expected a JSON object with params)", path)
    new = record["params"]
    keys = [k for k in sorted(set(old["params"]) | set(new)) if old["params"].get(k) != new.get(k)
            and not _follows_source(k, old["params"].get(k))]
    if "clean" in keys:
        # a defect left at its default changes with clean: clean is the difference
        was, now = old.get("given") or {}, record["given"]
        keys = [k for k in keys if k not in _DEFECT_NAMES or was.get(k) != now.get(k)]
    diff = [name(k) for k in keys]
    if old.get("source") != record["source"]:
        diff.append(f"source folder (was {old.get('source')})")
    elif _source_record(old.get("source_params")) != record["source_params"]:
        diff.append("source ensemble (its params.json)")
    if diff:
        raise ConfigError("output folder holds scenes of another render (parameters differ: "
                          + ", ".join(diff) + "); use another --out", out_dir)
    return True


def render_directory(sim_dir, out_dir, *, configs=None, progress: bool | None = False,
                     **kwargs) -> list[Path]:
    """Render every configuration of ``sim_dir/rods.npz`` into ``out_dir/<key>/``.

    ``sim_dir/params.json`` gives ``lambda`` (default :data:`simulate.energy.LAMBDA`; 0 for
    a compaction, whose hard wall stores no energy) and optionally ``contact_distance``; a compaction's ``thickness`` and
    ``wall_radius`` (units of L) set the scale and, unless ``hole_radius_mm`` is given, the
    hole (module docstring). Without params.json the rods are drawn as a quench's (a
    :class:`~crosssection.quality.QualityWarning` says so).

    Each scene folder holds a ``set.toml`` (:func:`write_set_file`): ``foldstat batch
    out_dir`` analyses the scenes with their scale, calibration and hole.
    ``out_dir/render.json`` records the render's parameters, its source folder and the
    package version. A re-run into the same folder resumes: scenes already complete
    (truth/summary.json present) are skipped, provided the folder's render.json has the same
    parameters and source.

    Parameters
    ----------
    sim_dir, out_dir : str or Path
        ``out_dir`` is not ``sim_dir`` itself.
    configs : sequence of str, optional
        Keys of ``rods.npz`` to render (default: all).
    progress : bool or None
        A tqdm bar on stderr, one step per configuration; None shows it only when stderr is a
        terminal.
    **kwargs
        Keywords of :func:`render_configuration` (``seed`` is the base seed: configuration
        ``i`` uses ``seed + i``).

    Returns
    -------
    list of Path
        The scene folders, rendered now or before.

    Raises
    ------
    ParameterError
        An absurd option or output folder, a scene over :data:`MAX_SCENE_PX` pixels, or a
        ``rod_length_mm`` that contradicts the compaction's thickness.
    ConfigError
        ``sim_dir`` is not a readable simulation folder or its ``rods.npz`` holds no
        configuration (every one failed), or ``out_dir`` holds scenes of another render (or
        of one that recorded no parameters) or files no render writes.

    Warns
    -----
    ScanRangeWarning
        Once per call, naming ``out_dir``, when the options lie beyond the ranges the image
        analysis is validated on, and once per segment count below the one the renders' truth
        is validated from (the scenes' own warnings are silenced).
    TruthWarning
        Per scene whose truth disagrees with its drawing, naming the scene folder.
    crosssection.quality.QualityWarning
        ``sim_dir`` has no params.json.
    """
    return _render_directory(sim_dir, out_dir, configs=configs, progress=progress,
                             kwargs=kwargs)


def _render_directory(sim_dir, out_dir, *, configs=None, limit=None, progress=False, kwargs,
                      name=str) -> list[Path]:
    """:func:`render_directory`, the first ``limit`` configurations only when given; the
    keywords of the messages shown as ``name(keyword)``.

    One render at a time writes into ``out_dir``: two with other options each took the
    folder for theirs (render.json of one, scenes of the other). The lock is
    :func:`~crosssection.core.fileio.exclusive_lock` on ``.<name>.render.lock`` beside it."""
    from crosssection.core.fileio import folder_lock

    if not str(out_dir).strip():
        # Path("") is the current folder
        raise ParameterError("empty path: give the output folder", name("out_dir"))
    # nothing is created before the folder is checked (a folder inside the simulation is
    # refused): a render into a new parent runs unlocked
    with folder_lock(out_dir, "render", where=out_dir, busy="another render is writing into it"):
        return _render_directory_locked(sim_dir, out_dir, configs=configs, limit=limit,
                                        progress=progress, kwargs=kwargs, name=name)


def _render_directory_locked(sim_dir, out_dir, *, configs=None, limit=None, progress=False,
                             kwargs, name=str) -> list[Path]:
    """:func:`_render_directory` holding the folder's lock."""
    from tqdm import tqdm

    from crosssection.core.fileio import write_json

    defects = _check_options(kwargs)
    sim_dir, out_dir = Path(sim_dir), Path(out_dir)
    rods_path = _rods_path(sim_dir)
    if out_dir.resolve() == sim_dir.resolve():
        raise ParameterError(f"{out_dir} is the simulation folder being rendered: the scenes "
                             "go to another folder", name("out_dir"))
    if sim_dir.resolve() in out_dir.resolve().parents:
        # a simulation folder holds only its own outputs: scenes inside it stop a later run
        # of the simulation from extending it
        raise ParameterError(f"{out_dir} is inside the simulation folder {sim_dir} being "
                             "rendered: give a folder outside it", name("out_dir"))
    lam = LAMBDA
    delta = None
    p = None
    pj = sim_dir / "params.json"
    if pj.exists():
        try:
            p = json.loads(pj.read_text())
        except json.JSONDecodeError as exc:
            raise ConfigError(f"malformed JSON ({exc.msg})", pj) from None
        if not isinstance(p, dict):
            raise ConfigError("expected a JSON object", pj)
        wall = {"rod_thickness": p.get("thickness"), "wall_radius": p.get("wall_radius")}
        # a compaction's rod has a thickness; a quench held by a static wall (--wall-radius)
        # has none, and is drawn as any quench, in the smallest disk holding it
        if p.get("thickness") is not None:
            for k, v in wall.items():
                if not (isinstance(v, (int, float)) and not isinstance(v, bool)
                        and math.isfinite(v) and v > 0):
                    raise ConfigError(f"{'thickness' if k == 'rod_thickness' else k} must be a "
                                      f"number > 0 (units of L), got {v!r}", pj)
            # the wall is the hole unless the caller draws another (or none)
            kwargs = {**wall, "hole_radius_mm": "auto", **kwargs}
            lam = 0.0
            _check_scale(kwargs.get("rod_length_mm"), kwargs.get("thickness_mm", THICKNESS_MM),
                         kwargs["rod_thickness"], f"the thickness of {pj}")
        try:
            lam = float(p.get("lambda", p.get("lam", lam)))
        except (TypeError, ValueError):
            raise ConfigError(f"lambda must be a number, got {p.get('lambda')!r}", pj) from None
        delta = p.get("contact_distance")
    written = []
    rods = _open_rods(rods_path)
    with rods:
        keys = sorted(rods.files) if configs is None else [k for k in sorted(rods.files)
                                                           if k in set(configs)]
        if not rods.files:
            # an ensemble whose every configuration failed stores none: rendering nothing
            # would look like a finished render of an empty folder
            failed = sim_dir / "failures.csv"
            why = f" (see {failed})" if failed.is_file() else ""
            raise ConfigError(f"no finished configuration to render in rods.npz{why}", sim_dir)
        asked = (p or {}).get("n_configs")
        if configs is None and isinstance(asked, int) \
                and len(rods.files) + _failed_count(sim_dir) < asked:
            # a run stopped before the end: its rods.npz holds the last finished run's
            warnings.warn(f"{sim_dir}: rods.npz holds {len(rods.files)} of the {asked} "
                          "configurations params.json asks for (a run stopped before the end: "
                          "re-run it to finish it)", TruthWarning, stacklevel=3)
        n_failed = _failed_count(sim_dir)
        if configs is None and n_failed:
            # the scenes are the ensemble's finished configurations: said, as stats says it
            warnings.warn(f"{sim_dir}: {n_failed} configuration(s) of the simulation failed "
                          f"and are not rendered (see {sim_dir / 'failures.csv'})",
                          TruthWarning, stacklevel=3)
        if limit is not None:
            keys = keys[:limit]
        # an ensemble that recorded None for its default delta analyses with that default
        record = _render_record(sim_dir, p, _used_kwargs(
            kwargs, lam, delta if delta is not None
            else (_source_record(p) or {}).get("contact_distance")))
        # a resumed render keeps the record of the render that made the folder's scenes
        recorded = _claim_out(out_dir, record, name, rods.files)
        if p is None:
            # a compaction's wall and scale are in its params.json: without it the rods are
            # drawn with no wall at the gap's scale, which is silently wrong for a compaction
            warnings.warn(f"{pj}: missing: the rods are drawn as a quench's (no wall, default "
                          f"scale, lambda {lam:g})", QualityWarning, stacklevel=3)
        beyond = _beyond_validated(defects, kwargs.get("px_per_mm", PX_PER_MM)
                                   * kwargs.get("thickness_mm", THICKNESS_MM), name)
        if beyond:
            # once for the run: every scene has the same options (per scene it is silenced)
            warnings.warn(f"{out_dir}: {beyond}", ScanRangeWarning, stacklevel=3)
        base_seed = int(kwargs.pop("seed", 0))
        set_name = render_set_name(out_dir)
        short_seen = set()
        # disable=None is tqdm's "only on a terminal"
        with tqdm(keys, desc="render", unit="config",
                  disable=None if progress is None else not progress) as bar:
            for i, key in enumerate(bar):
                folder = out_dir / key
                if (folder / "truth" / "summary.json").exists() and _scene_whole(folder):
                    if not (folder / "set.toml").exists():
                        # a scene an older version rendered: made batch-ready from its record
                        try:
                            write_set_file(folder, read_scene_params(folder),
                                           set_name=set_name)
                        except ConfigError:
                            pass  # a damaged record: validate names the scene
                    written.append(folder)
                    continue
                try:
                    xy = np.asarray(rods[key], float)
                except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
                    raise ConfigError(f"array {key!r} unreadable ({exc})", rods_path) from None
                if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) < 4:
                    raise ConfigError(f"array {key!r} has shape {xy.shape}, expected (N+1, 2) "
                                      "with N >= 3", rods_path)
                if not np.isfinite(xy).all():
                    raise ConfigError(f"array {key!r} has non-finite coordinates", rods_path)
                if not np.any(np.diff(xy, axis=0)):
                    raise ConfigError(f"array {key!r} is a rod of zero length (its nodes all "
                                      "coincide)", rods_path)
                cause = _rod_defect(xy)
                if cause:
                    raise ConfigError(f"array {key!r} {cause}", rods_path)
                an = analyze_rod(xy, lam=lam, contact_distance=delta)
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    scene = render_configuration(xy, an, seed=base_seed + i, **kwargs)
                short = _rod_beyond_validated(len(xy) - 1,
                                              kwargs.get("rod_thickness") is not None)
                if short and short not in short_seen:
                    # once per segment count (an ensemble's rods share theirs), not per scene
                    short_seen.add(short)
                    warnings.warn(f"{out_dir}: {short}", ScanRangeWarning, stacklevel=3)
                for w in caught:
                    # the scan and rod ranges are the run's (warned once); a truth check or
                    # the scale of the drawing is the scene's own
                    if issubclass(w.category, QualityWarning) \
                            and not issubclass(w.category, ScanRangeWarning):
                        warnings.warn(f"{folder}: {w.message}", w.category, stacklevel=3)
                if not recorded:
                    # before the first scene: a folder never holds scenes without their record
                    write_json(out_dir / RENDER_RECORD, record)
                    recorded = True
                # before the scene, whose truth/summary.json marks it complete
                written.append(_write_scene_whole(scene, folder, set_name))
    return written


#: Suffix of the hidden folder a scene is written into before it takes its name
#: (:func:`_write_scene_whole`).
_PARTIAL = ".partial"


def _partial_folder(folder: Path) -> Path:
    """The hidden sibling in which the scene ``folder`` is written before it takes its name."""
    return folder.with_name(f".{folder.name}{_PARTIAL}")


def _is_partial_folder(p: Path) -> bool:
    """Whether ``p`` is a scene a render began and never finished (:func:`_partial_folder`)."""
    return p.name.startswith(".") and p.name.endswith(_PARTIAL)


def render_set_name(out_dir) -> str:
    """The set name of a render's scenes: the name batch gives its folder
    (:func:`crosssection.setconfig.default_set_name`). Every scene of one render is then one
    set of a batch, one ensemble for ``stats`` beside the simulation it was drawn from.

    Parameters
    ----------
    out_dir : str or Path

    Returns
    -------
    str
    """
    from crosssection.setconfig import default_set_name

    return default_set_name(Path(out_dir).resolve())


def _write_scene_whole(scene: Scene, folder: Path, set_name: str | None = None) -> Path:
    """Write ``scene`` into ``folder`` whole or not at all.

    The scene is written into a hidden sibling (:func:`_partial_folder`) that is then renamed:
    writing the image takes seconds, and a render stopped meanwhile would otherwise leave a
    scene folder without its files (validate takes every folder for a scene). A stop removes
    the sibling; one left by a killed render is replaced by the next run. A ``folder`` an
    older version left half written (files but no ``truth/summary.json``) is written into as
    it is: it may hold files the render did not write, which a rename cannot replace.

    Parameters
    ----------
    scene : Scene
    folder : Path
        The scene folder; absent, empty or half written.

    Returns
    -------
    Path
        ``folder``.
    """
    if folder.is_dir() and any(folder.iterdir()):
        return write_scene(scene, folder, set_name=set_name)
    tmp = _partial_folder(folder)
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        write_scene(scene, tmp, set_name=set_name)
        # an empty folder is replaced: one a stopped render of an older version left
        tmp.replace(folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return folder


def add_subparser(sub) -> None:
    """Register ``render``: ``python -m simulate render DIR --out SCENES [...]``."""
    p = sub.add_parser("render", help="render simulated configurations into synthetic scans",
                       description="Render DIR/rods.npz (one scene per configuration) into "
                                   "scene folders with exact truth. Scans have the defects "
                                   "of a real scan unless --clean.")
    p.add_argument("sim_dir", metavar="DIR",
                   help="simulation ensemble folder holding rods.npz (from quench, anneal or "
                        "compact)")
    p.add_argument("--out", required=True, metavar="SCENES",
                   help="folder of the scene folders (created; its render.json records the "
                        "parameters: a re-run with the same ones resumes, skipping finished "
                        "scenes; a folder holding other files is refused)")
    p.add_argument("--px-per-mm", type=float, default=PX_PER_MM,
                   help=f"scan resolution in px/mm (default {PX_PER_MM:g}; a sheet under "
                        f"{VALIDATED_SHEET_PX:g} px, --px-per-mm x --thickness-mm, is beyond "
                        "the validated range: a warning)")
    p.add_argument("--thickness-mm", type=float, default=THICKNESS_MM,
                   help=f"sheet thickness h in mm (default {THICKNESS_MM:g})")
    p.add_argument("--rod-length-mm", type=float, default=None,
                   help="rod length L in mm (default: thickness-mm over the rod's thickness "
                        "for a compaction, else the smallest keeping a visible gap between "
                        "passes farther apart than the contact distance)")
    p.add_argument("--clean", action="store_true",
                   help="no scan defect, no plate: the clean drawing (each option below "
                        "still sets its defect)")
    d = SCAN_DEFECTS
    p.add_argument("--noise", type=float, default=None,
                   help=f"Gaussian noise sigma in grey levels (default {d['noise_sigma']:g}, "
                        f"0 with --clean; above {VALIDATED_NOISE_SIGMA:g}: a warning)")
    p.add_argument("--blur", type=float, default=None,
                   help=f"Gaussian blur sigma in px (default {d['blur_px']:g}, 0 with --clean; "
                        f"above {VALIDATED_BLUR_PX:g}: a warning; at most {MAX_BLUR_PX:g})")
    p.add_argument("--jpeg", type=_jpeg_arg, default=None,
                   help=f"JPEG quality 1-100 of a round trip, or 0 or 'none' (default "
                        f"{d['jpeg_quality']}, none with --clean; below "
                        f"{VALIDATED_JPEG_QUALITY}: a warning)")
    p.add_argument("--smears", type=int, default=None,
                   help=f"number of light-blue smears, rejected by the threshold (default "
                        f"{d['smears']}, 0 with --clean; at most {MAX_MARKS})")
    p.add_argument("--specks", type=int, default=None,
                   help=f"number of small ink specks in the paper, removed by cleaning "
                        f"(default {d['specks']}, 0 with --clean; at most {MAX_MARKS})")
    p.add_argument("--pinholes", type=int, default=None,
                   help=f"number of paper-coloured pinholes in wide bands (default "
                        f"{d['pinholes']}, 0 with --clean; at most {MAX_MARKS})")
    p.add_argument("--plate", default=None, type=_plate_arg,
                   help=f"plate around the hole: {', '.join(PLATE_NAMES)}, an RGB triple R,G,B "
                        "(0-255) or none (default "
                        f"{d['plate']} with a {d['rim_px']:g} px dark rim, none with --clean)")
    p.add_argument("--illumination", type=float, default=None,
                   help=f"largest relative deviation of an illumination gradient (default "
                        f"{d['illumination']:g}, 0 with --clean)")
    p.add_argument("--cast", type=float, default=None,
                   help=f"largest relative colour cast per channel (default {d['cast']:g}, "
                        "0 with --clean)")
    p.add_argument("--smooth", choices=SMOOTH, default="all",
                   help="draw every stack along its smooth curve (all, default), leave the "
                        "links shorter than two rod segments polylines (long), or draw the "
                        "polylines of the analysis (none)")
    p.add_argument("--join", choices=JOIN, default="hook",
                   help="bands drawing: join every band to its junctions along its own mean "
                        "line, cleaned and cut back near the junction, smoothed into the "
                        "junction point (hook, default), or through the analysis' line as it "
                        "is (junction)")
    p.add_argument("--draw", choices=DRAW, default="bands",
                   help="draw one band of the calibrated width per stack (bands, default) or "
                        "the rod itself, every pass a stroke and the passes of a stack "
                        "pressed together (passes; its calibration w(n) is linear in n)")
    p.add_argument("--pass-smooth", type=float, default=None, metavar="S",
                   help="--draw passes: smooth the passes' pressing along the rod over S rod "
                        "segments (0 <= S <= 50; default: over one pitch); 1 draws the rods "
                        "whose energy and layers read best (docs/validation/compact.md); "
                        "their truth junctions lie at the tips of the paper's wedges, where "
                        "no skeleton forks, so validate's junction F1 does not score the "
                        "pipeline on them")
    p.add_argument("--hole", default="auto",
                   help="hole radius in mm, 'auto' (default: the wall of a compaction, else "
                        "the smallest disk around the rod) or 'none' (the pipeline then fits "
                        "one)")
    p.add_argument("--limit", type=int, default=None,
                   help="render only the first K configurations, K >= 1 (default: all)")
    p.add_argument("--seed", type=int, default=0,
                   help="base seed of colours, noise and defects; configuration i uses "
                        "seed + i (default 0)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: only when stderr is a terminal)")
    p.set_defaults(func=_run)


def _jpeg_arg(text):
    # 0 is none, as for render_configuration's jpeg_quality
    if str(text).strip().lower() in ("none", "off", "0"):
        return "none"
    try:
        q = int(text)
    except ValueError:
        q = -1
    if not 1 <= q <= 100:
        raise argparse.ArgumentTypeError(f"expected a whole number 1-100, or 0 or 'none' for "
                                         f"no JPEG, got {text!r}")
    return q


#: API keyword -> CLI option, for error messages
_OPTION = {"noise_sigma": "--noise", "blur_px": "--blur", "jpeg_quality": "--jpeg",
           "smears": "--smears", "specks": "--specks", "pinholes": "--pinholes",
           "plate": "--plate", "illumination": "--illumination", "cast": "--cast",
           "px_per_mm": "--px-per-mm", "thickness_mm": "--thickness-mm",
           "rod_length_mm": "--rod-length-mm", "hole_radius_mm": "--hole", "seed": "--seed",
           "clean": "--clean", "smooth": "--smooth", "draw": "--draw", "join": "--join",
           "pass_smooth": "--pass-smooth", "out_dir": "--out"}


def _cli_names(message: str) -> str:
    """``message`` with the API's keyword names replaced by the CLI's options."""
    import re

    message = message.replace("or None", "or 'none'")  # the CLI's spelling of no value
    return re.sub(r"\b(" + "|".join(_OPTION) + r")\b", lambda m: _OPTION[m.group(1)], message)


def _cli_error(exc: ParameterError) -> ParameterError:
    """``exc`` as the CLI shows it: options instead of keywords, the option a message starts
    with as the one it is about (``error: --seed: must be ...``)."""
    import re

    cause, where = _cli_names(exc.cause), _OPTION.get(exc.path, exc.path)
    lead = re.match(r"(--[a-z][a-z-]*) (.+)", cause, re.S)
    if where is None and lead:
        where, cause = lead.groups()
    return ParameterError(cause, where)


def _plate_arg(text):
    """``--plate``: a name, ``none``, or ``R,G,B`` (0-255) as a tuple of three numbers."""
    parts = str(text).split(",")
    if len(parts) == 1:
        return text
    try:
        return tuple(float(v) for v in parts)
    except ValueError:
        raise ParameterError(f"an RGB triple is three numbers R,G,B (0-255), got {text!r}",
                             "--plate") from None


def _hole_arg(text):
    if text is None or str(text).lower() in ("none", "null", ""):
        return None
    if str(text).lower() == "auto":
        return "auto"
    try:
        return float(text)
    except ValueError:
        raise ParameterError(f"must be a number, 'auto' or 'none', got {text!r}",
                             "--hole") from None


def _run(args) -> int:
    opts = {"noise_sigma": args.noise, "blur_px": args.blur, "smears": args.smears,
            "specks": args.specks, "pinholes": args.pinholes, "plate": args.plate,
            "illumination": args.illumination, "cast": args.cast}
    if args.jpeg is not None:
        opts["jpeg_quality"] = 0 if args.jpeg == "none" else args.jpeg
    if args.pass_smooth is not None:
        opts["pass_smooth"] = args.pass_smooth
    kwargs = dict(px_per_mm=args.px_per_mm, thickness_mm=args.thickness_mm,
                  rod_length_mm=args.rod_length_mm, clean=args.clean, seed=args.seed,
                  smooth=args.smooth, draw=args.draw, join=args.join,
                  hole_radius_mm=_hole_arg(args.hole),
                  **{k: v for k, v in opts.items() if v is not None})
    if args.limit is not None and args.limit < 1:
        # 0 would render nothing and create no folder, yet read as a finished render
        raise ParameterError(f"must be >= 1, got {args.limit}", "--limit")
    try:
        _check_options(kwargs)
        out = _render_directory(args.sim_dir, args.out, limit=args.limit,
                                progress=args.progress, kwargs=kwargs,
                                name=lambda k: _OPTION.get(k, k))
    except ParameterError as exc:
        # the API names keywords; the user typed options
        raise _cli_error(exc) from None
    print(f"{len(out)} scenes in {args.out}")
    return 0
