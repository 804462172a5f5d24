"""A rod end inside a band (bands drawing): the band narrows where the rod ends, and the truth
counts the rod once.

The rod runs along a line, leaves it for a loop and comes back alongside its first pass, to
end half way along it. The contact analysis merges the one-pass and the two-pass parts into
one stack of two branches (:func:`simulate.contacts._merge_two_ended_junctions`); the drawing
shows two layers where the rod's end pass lies and one beyond.
"""
import cv2
import numpy as np
import pytest

from simulate.contacts import analyze_rod
from simulate.render import render_configuration
from simulate.shapes import hairpin, lines, resample

#: the truth checks of these scenes (test_render_truth.py) are not what is tested here
# short rods, below the segment count the renders' truth is validated from, on purpose
pytestmark = [pytest.mark.filterwarnings("ignore::simulate.render.TruthWarning"),
              pytest.mark.filterwarnings("ignore:.*the render's truth is validated from:"
                                         "simulate.render.ScanRangeWarning")]

N = 300
DELTA = 0.5 / N
ROD_MM = 60.0  # h = 0.1 mm = 5 px at 50 px/mm
PX_PER_MM = 50.0


@pytest.fixture(scope="module")
def rod_end_scene():
    # units before normalisation: the first pass spans x in [-0.3, 0.3], the end pass
    # returns 0.5 delta above it from x = 0.3 and ends at x = 0
    xy = resample(lines((-0.3, 0.0), (0.3, 0.0), (0.45, -0.08), (0.6, 0.05), (0.45, 0.12),
                        (0.3, 0.5 * DELTA), (0.0, 0.5 * DELTA)), N)
    an = analyze_rod(xy, lam=0.0)
    sc = render_configuration(xy, an, rod_length_mm=ROD_MM, clean=True)
    return xy, an, sc


def _to_px(sc, p):
    return (np.asarray(p, float) - np.array(sc.params["origin_xy"])) * ROD_MM * PX_PER_MM \
        + sc.params["margin_px"]


def _column_width(ink, col, row_near):
    """Width of the ink run that a column crosses near ``row_near`` (the band is horizontal
    there, so the column crosses it square)."""
    prof = ink[:, col].astype(int)
    d = np.diff(np.r_[0, prof, 0])
    runs = list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))
    near = [(a, b) for a, b in runs if a - 3 <= row_near <= b + 3]
    assert len(near) == 1
    a, b = near[0]
    return b - a


def test_band_narrows_beyond_the_rod_end(rod_end_scene):
    xy, an, sc = rod_end_scene
    end_branch = len(an.branches) - 1
    sid = int(an.branches["stack_id"].iloc[end_branch])
    assert int(an.stacks["n_br"].iloc[sid]) == 2
    assert int(an.branches["stack_id"].iloc[0]) == sid  # both passes: one merged stack
    ink = sc.ink_mask
    cal = sc.calibration
    w1, w2 = (float(cal.width(n)) * PX_PER_MM for n in (1, 2))
    start, end = _to_px(sc, xy[0]), _to_px(sc, xy[-1])
    junction = _to_px(sc, an.junctions[["x", "y"]].to_numpy(float)[0])
    row = int(round(start[1]))
    # columns of the one-pass part (start to rod end) and of the two-pass part (rod end to
    # the junction), away from the ends and the step
    one = np.linspace(start[0] + 3 * w2, end[0] - 3 * w2, 9).round().astype(int)
    two = np.linspace(end[0] + 3 * w2, junction[0] - 3 * w2, 9).round().astype(int)
    widths_one = [_column_width(ink, c, row) for c in one]
    widths_two = [_column_width(ink, c, row) for c in two]
    assert widths_one == pytest.approx([w1] * 9, abs=1.5)
    assert widths_two == pytest.approx([w2] * 9, abs=1.5)
    # the step lies at the rod end (the distance transform along the band's row band)
    dt = cv2.distanceTransform(ink.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    cols = np.arange(int(start[0] + 2 * w2), int(junction[0] - 2 * w2))
    drawn = 2.0 * dt[row - 10:row + 11, cols].max(axis=0) - 1.0
    step = cols[np.flatnonzero(drawn > 0.5 * (w1 + w2))[0]]
    assert step == pytest.approx(end[0], abs=w2)


def test_truth_and_ink_count_the_rod_once(rod_end_scene):
    xy, an, sc = rod_end_scene
    st = sc.tables["stacks"]
    rod_mm = sc.summary["rod_length_mm"]
    # the truth's stacks sum to the rod (one band at its larger count over its whole length
    # would be 1.18 times it)
    assert float((st["n_br"] * st["length_mm"]).sum()) == pytest.approx(rod_mm, rel=0.01)
    assert st["n_br"].tolist() == an.stacks["n_br"].tolist()
    # the ink's layer count integrated along the band: one layer from the free end to the rod
    # end, two from there to the junction
    ink, cal = sc.ink_mask, sc.calibration
    start, end = _to_px(sc, xy[0]), _to_px(sc, xy[-1])
    junction = _to_px(sc, an.junctions[["x", "y"]].to_numpy(float)[0])
    row = int(round(start[1]))
    margin = 3 * float(cal.width(2)) * PX_PER_MM
    cols = np.arange(int(start[0] + margin), int(junction[0] - margin))
    layers = np.array([np.rint(cal.layers(_column_width(ink, c, row) / PX_PER_MM))
                       for c in cols])
    expected = (end[0] - cols[0]) * 1 + (cols[-1] + 1 - end[0]) * 2
    assert layers.sum() == pytest.approx(expected, abs=2 * margin / 3)


def test_layer_pieces_are_the_band_as_drawn_and_score_the_analysis_exact(rod_end_scene):
    from crosssection import analyze
    from crosssection.quality import FrameWarning
    from crosssection.truth.scoring import score

    xy, an, sc = rod_end_scene
    sid = int(an.branches["stack_id"].iloc[-1])
    pieces = sc.tables["layer_pieces"]
    own = pieces[pieces["stack_id"] == sid]
    # one pass from the free end to the rod end, two from there to the junction
    assert sorted(own["n_br"]) == [1, 2]
    start, end = _to_px(sc, xy[0]), _to_px(sc, xy[-1])
    one = own[own["n_br"] == 1].iloc[0]
    assert one["length_mm"] * PX_PER_MM == pytest.approx(abs(end[0] - start[0]), rel=0.05)
    # the pieces hold the rod as the stacks do
    st = sc.tables["stacks"]
    assert float((pieces["n_br"] * pieces["length_mm"]).sum()) == pytest.approx(
        float((st["n_br"] * st["length_mm"]).sum()), rel=1e-6)
    # the analysis cuts the band at the step: scored against the pieces it is exact, against
    # the contact analysis' one stack of two branches it would be wrong along the narrow part
    import warnings

    with warnings.catch_warnings():
        # a rod drawn without a wall: no hole to find, which is not what is tested
        warnings.simplefilter("ignore", FrameWarning)
        res = analyze(sc.rgb, px_per_mm=PX_PER_MM, calibration=sc.calibration)
    assert score(res, sc)["n_br_exact_length_fraction"] == pytest.approx(1.0)
    whole = {k: v for k, v in sc.tables.items() if k != "layer_pieces"}
    assert score(res, (sc.summary, whole))["n_br_exact_length_fraction"] < 0.9


def _render_capturing(monkeypatch, xy, an):
    """Render, keeping the coverage and the stack label image the bands drawing made."""
    from simulate import render

    drawn = {}
    draw = render._draw_bands

    def capture(*args, **kwargs):
        drawn["coverage"], drawn["labels"] = draw(*args, **kwargs)
        return drawn["coverage"], drawn["labels"]

    monkeypatch.setattr(render, "_draw_bands", capture)
    sc = render_configuration(xy, an, rod_length_mm=ROD_MM, clean=True)
    return sc, drawn["labels"]


def test_labels_follow_the_narrowed_band(rod_end_scene, monkeypatch):
    """Every ink pixel carries a stack label and none lies off the ink; the one-pass part of
    the narrowed band carries its stack's."""
    xy, an, _ = rod_end_scene
    sc, labels = _render_capturing(monkeypatch, xy, an)
    ink = sc.ink_mask
    assert not np.any(labels[~ink])
    assert np.mean(labels[ink] > 0) > 0.999
    sid = int(an.branches["stack_id"].iloc[-1])
    start, end = _to_px(sc, xy[0]), _to_px(sc, xy[-1])
    row, col = int(round(start[1])), int(round(0.5 * (start[0] + end[0])))
    band = ink[row - 10:row + 11, col]
    assert band.any() and np.all(labels[row - 10:row + 11, col][band] == sid + 1)


def test_free_ends_at_a_band_end_leave_the_band_whole():
    """A hairpin's free ends end their stacks (the two-pass band ends at the fold and at the
    fork): every band is drawn at its width over its whole length."""
    xy = resample(hairpin(0.25 * DELTA, arm=0.3), N)
    an = analyze_rod(xy, lam=0.0)
    sc = render_configuration(xy, an, rod_length_mm=ROD_MM, clean=True)
    st = sc.tables["stacks"]
    lengths = [np.hypot(*np.diff(p, axis=0).T).sum() / PX_PER_MM for p in sc.paths_rc]
    assert st["length_mm"].to_numpy() == pytest.approx(lengths)


@pytest.mark.parametrize("side", ["start", "end"])
def test_rod_end_in_a_loop_stack_is_cut_on_its_own_side(side):
    """A teardrop loop whose two ends are one junction, with the rod's first pass lying along
    one of its sides from the junction: the band is cut where that pass ends, on that side
    (drawn two layers thick round the whole loop, its truth counted the loop twice)."""
    from types import SimpleNamespace

    import pandas as pd

    from simulate.render import _rod_end_cuts

    # the loop (px): up the right side from the junction at the origin, round the top, down
    # the left side back to the junction
    t = np.linspace(0.0, 1.0, 400)
    right = np.c_[40 * np.sin(np.pi * t), -300 * t]
    a = np.linspace(0, np.pi, 200)
    top = np.c_[40 * np.cos(a), -300 - 40 * np.sin(a)]
    left = np.c_[-40 * np.sin(np.pi * t[::-1]), -300 * t[::-1]]
    loop = np.concatenate([right, top, left])
    if side == "end":
        loop = loop[::-1]
    # the rod's first pass: 4 px outside the right side, from 120 px up to the junction
    u = np.r_[0.0, np.cumsum(np.hypot(*np.diff(right, axis=0).T))]
    k = np.flatnonzero(u <= 120.0)
    pass_px = right[k[::-1]] + np.array([4.0, 0.0])
    s = np.linspace(0.0, 1.0, len(pass_px))
    scale = 1000.0  # px per unit of rod length
    length = float(u[k[-1]]) / scale
    analysis = SimpleNamespace(
        branches=pd.DataFrame({"stack_id": [0, 1], "length": [length, 1.0 - length],
                               "s_start": [0.0, length], "s_end": [length, 1.0]}),
        stacks=pd.DataFrame({"n_br": [2, 1]}),
        samples_s=s * length, samples_xy=pass_px / scale, contact_distance=0.002)
    frame = SimpleNamespace(scale=scale, to_px=lambda p: np.asarray(p) * scale)
    cuts = _rod_end_cuts(analysis, frame, [loop, right[:2]], np.array([12.0, 6.0]))
    u_len = float(np.hypot(*np.diff(loop, axis=0).T).sum())
    (cut, before), = cuts[0]
    assert before == (side == "start")
    assert cut == pytest.approx(u[k[-1]] if before else u_len - u[k[-1]], abs=1e-6)
