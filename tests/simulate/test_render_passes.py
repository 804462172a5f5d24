"""The rod drawn itself (``render_configuration(draw="passes")``): every pass a stroke one
pass wide, the passes of a stack pressed into a band ``w(n)`` wide, reproducible."""
import cv2
import numpy as np
import pytest

from crosssection.core.errors import ParameterError
from simulate.contacts import analyze_rod
from simulate.render import PASS_OVERLAP_PX, PASS_WIDTH, render_configuration
from simulate.shapes import hairpin, resample, spiral

# short rods, below the segment count the renders' truth is validated from, on purpose
pytestmark = pytest.mark.filterwarnings(
    "ignore:.*the render's truth is validated from:simulate.render.ScanRangeWarning")

N = 300
DELTA = 0.5 / N
ROD_MM = 60.0  # h = 0.1 mm = 5 px at 50 px/mm; delta = 0.1 mm
STROKE_PX = PASS_WIDTH * 5.0
PITCH_PX = STROKE_PX - PASS_OVERLAP_PX


def _render(xy, **kw):
    an = analyze_rod(xy, lam=0.0)
    return an, render_configuration(xy, an, rod_length_mm=ROD_MM, clean=True, draw="passes",
                                    **kw)


def _to_px(sc, p):
    return (np.asarray(p, float) - np.array(sc.params["origin_xy"])) * ROD_MM * 50.0 \
        + sc.params["margin_px"]


def _runs(profile):
    """(start, stop) of the ink runs of a 1-D bool profile."""
    d = np.diff(np.r_[0, profile.astype(int), 0])
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _drawn_widths(sc, *, row=None, col=None):
    """Width of every ink run crossed by a row or a column, measured across the stroke, not
    along the transect: 2 max(distance transform) - 1 (the distance runs to the centre of the
    first paper pixel, half a pixel beyond the ink)."""
    ink = sc.ink_mask.astype(np.uint8)
    dt = cv2.distanceTransform(ink, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    line, prof = (dt[row], ink[row]) if row is not None else (dt[:, col], ink[:, col])
    return [2.0 * line[a:b].max() - 1.0 for a, b in _runs(prof)]


def test_pressed_stack_is_n_passes_wide_and_a_free_pass_one():
    """Hairpin arms about 0.3 delta apart (1.5 px, much closer than a pass is wide): drawn pressed to one
    band of two passes, w(2) = 2 pitch + overlap; beyond the junction each free arm is one
    stroke; the truth width is the drawn one."""
    xy = resample(hairpin(0.25 * DELTA, arm=0.3), N)
    an, sc = _render(xy)
    assert sorted(an.stacks["n_br"]) == [1, 1, 2]
    # across the contact region, half way along the arms (x > 0 before normalisation)
    arm = np.flatnonzero(an.multiplicity == 2)
    mid = xy[arm[len(arm) // 4]]
    col = int(round(_to_px(sc, mid)[0]))
    # the arms are horizontal: a column crosses the band square
    ((a, b),) = _runs(sc.ink_mask[:, col])
    w = b - a
    assert w == pytest.approx(2 * PITCH_PX + PASS_OVERLAP_PX, abs=1.0)
    assert sc.tables["stacks"]["width_mm"].max() * 50 == pytest.approx(2 * PITCH_PX
                                                                      + PASS_OVERLAP_PX)
    assert sc.calibration.layers(w / 50) == pytest.approx(2, abs=0.25)
    # across the diverging free arms, near the rod's ends: two strokes one pass wide
    col = int(round(_to_px(sc, xy[4])[0]))
    widths = _drawn_widths(sc, col=col)
    assert len(widths) == 2
    assert widths == pytest.approx([STROKE_PX] * 2, abs=1.0)


def test_wound_passes_are_pressed_into_one_band():
    """A spiral of three turns 0.25 delta apart is one stack of three passes: one band
    3 pitch + overlap wide, without paper between its passes."""
    xy = resample(spiral(3, 0.25 * DELTA), N)
    an, sc = _render(xy)
    assert list(an.stacks["n_br"]) == [3]
    centre = _to_px(sc, np.zeros(2))  # the spiral winds around the origin
    row = int(round(centre[1]))
    # the side opposite the turns' start (angle pi), away from where the passes are cut
    left = np.zeros(sc.ink_mask.shape[1], bool)
    left[: int(centre[0])] = True
    profile = sc.ink_mask[row] & left
    # the band is vertical there: the row crosses it square, in one run of ink
    ((a, b),) = _runs(profile)
    assert b - a == pytest.approx(3 * PITCH_PX + PASS_OVERLAP_PX, abs=1.0)


def test_passes_drawing_is_seeded_and_the_ink_does_not_depend_on_the_seed():
    """Scan defects follow the seed; the drawn rod does not (a small spiral: a fast scan)."""
    xy = resample(spiral(3, 0.25 * DELTA), N)
    an = analyze_rod(xy, lam=0.0)
    kw = dict(rod_length_mm=ROD_MM, draw="passes", hole_radius_mm="auto")
    a = render_configuration(xy, an, seed=3, **kw)
    b = render_configuration(xy, an, seed=3, **kw)
    c = render_configuration(xy, an, seed=4, **kw)
    assert np.array_equal(a.rgb, b.rgb)
    assert not np.array_equal(a.rgb, c.rgb)
    assert np.array_equal(a.ink_mask, c.ink_mask)
    # the bands drawing stays the default, with its own calibration
    d = render_configuration(xy, an, seed=3, rod_length_mm=ROD_MM, hole_radius_mm="auto")
    assert d.params["draw"] == "bands" and a.params["draw"] == "passes"
    assert d.calibration.width(2) != pytest.approx(a.calibration.width(2))
    assert a.calibration.width(2) * 50 == pytest.approx(2 * PITCH_PX + PASS_OVERLAP_PX)


def test_bad_draw_is_refused():
    xy = resample(hairpin(0.25 * DELTA, arm=0.3), N)
    with pytest.raises(ParameterError):
        render_configuration(xy, rod_length_mm=ROD_MM, draw="rod")
    with pytest.raises(ParameterError):
        render_configuration(xy, rod_length_mm=ROD_MM, draw="passes", pass_width=0.1)
