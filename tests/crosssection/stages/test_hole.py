"""The scan's frame (crosssection.stages.hole: find_hole, frame_mask, check_hole) on generated
scans with a plate, a shadow rim, ink touching the wall, and without plate."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from crosssection.core.errors import ParameterError
from crosssection.quality import DarkMarksWarning, FrameWarning, MarksOnInkWarning
from crosssection.stages.hole import Hole, check_hole, find_hole, frame_mask, trim_margin
from crosssection.stages.threshold import threshold_rgb
from crosssection.truth.backdrop import apply_backdrop
from crosssection.truth.network import make_scene

PAPER_RGB = (246, 245, 240)


@pytest.fixture(scope="module")
def scene():
    sc = make_scene(seed=21, n_stacks=25, max_layers=5, receding_fraction=0.6, noise_sigma=4)
    c = np.array(sc.params["hole_center_px"][::-1])
    R = sc.params["hole_radius_mm"] * sc.params["px_per_mm"]
    return sc, c, R


def _leave_wall(rgb, c, R):
    """The rod leaves the wall on a quarter of the circle: paper instead of the wall ink."""
    out = rgb.copy()
    rr, cc = np.mgrid[:rgb.shape[0], :rgb.shape[1]]
    a = np.arctan2(rr - c[0], cc - c[1])
    out[(a > 0.3) & (a < 1.9) & (np.hypot(rr - c[0], cc - c[1]) > R - 25)] = PAPER_RGB
    return out


@pytest.mark.parametrize("plate,rim,gap", [("grey", 0, False), ("dark", 2, False),
                                           ("coloured", 0, True), ("bluish", 3, True),
                                           ("beige", 1, True)])
def test_find_hole_with_plate(scene, plate, rim, gap):
    sc, c, R = scene
    base = _leave_wall(sc.rgb, c, R) if gap else sc.rgb
    ink = threshold_rgb(base, method="fixed").mask
    img = apply_backdrop(base, ink_mask=ink, hole_center_rc=c, hole_radius_px=R,
                         rng=np.random.default_rng(len(plate)), plate=plate, rim_px=rim,
                         illumination=0.15, cast=0.06)
    hole = find_hole(img, threshold_rgb(img).mask)
    # measured: centre within 0.7 px (the generator's pixel grid is offset by 3/8 px from
    # pixel centres), radius within 0.15 px (each ray's crossing interpolated over its 1-px
    # step; over half of it the radius read 0.3 px short)
    assert np.hypot(*(hole.center_rc - c)) < 1.5
    assert abs(hole.radius_px - R) < 0.25
    assert hole.fitted and hole.confidence > 0.9 and "plate" in hole.reason


def test_without_plate_the_ink_envelope(scene):
    sc, c, R = scene
    full = find_hole(sc.rgb, threshold_rgb(sc.rgb).mask)
    assert np.hypot(*(full.center_rc - c)) < 1.5 and abs(full.radius_px - R) < 1.5
    assert full.confidence > 0.95 and "envelope" in full.reason
    gap = _leave_wall(sc.rgb, c, R)
    part = find_hole(gap, threshold_rgb(gap).mask)
    assert np.hypot(*(part.center_rc - c)) < 1.5 and abs(part.radius_px - R) < 1.5
    # ink reaches the circle on about 3/4 of it: a lower confidence
    assert 0.6 < part.confidence < 0.85


def test_without_plate_the_frame_holds_every_piece_of_the_rod():
    """A drawing without a wall (a rod in two pieces, specks around): the envelope of the
    largest piece must not cut the other off; specks may lie outside."""
    import cv2

    from crosssection.stages.hole import PIECE_FRACTION

    rgb = np.full((400, 600, 3), PAPER_RGB, np.uint8)
    blue = (40, 60, 200)
    cv2.ellipse(rgb, (200, 200), (150, 120), 0, 0, 360, blue, 6)  # the large piece: a loop
    cv2.polylines(rgb, [np.array([[420, 100], [500, 180], [560, 330]], np.int32)], False,
                  blue, 6)  # a piece of the rod off it
    for x, y in ((20, 20), (580, 20), (590, 390)):
        cv2.circle(rgb, (x, y), 2, blue, -1)  # specks
    ink = threshold_rgb(rgb).mask
    hole = find_hole(rgb, ink)
    inside = frame_mask(rgb.shape[:2], hole)
    piece = ink.copy()
    piece[:, :400] = False
    piece[:40] = piece[360:] = False
    piece[:, 570:] = False
    assert piece.sum() > PIECE_FRACTION * ink.sum()
    assert np.all(inside[piece])
    assert hole.confidence < 0.5  # nothing marks a wall


def test_without_plate_a_mark_beside_the_hole_lowers_the_confidence(scene):
    """A blue label and a filled mark on the paper beside the hole (no plate): the circle
    grows to hold them, and its confidence is the grown circle's, not the envelope's."""
    import cv2

    sc, c, R = scene
    h, w = sc.rgb.shape[:2]
    rgb = np.full((h + 200, w + 300, 3), PAPER_RGB, np.uint8)
    rgb[100:100 + h, 150:150 + w] = sc.rgb
    blue = (40, 70, 190)
    cv2.putText(rgb, "sample 12", (20, 60), cv2.FONT_HERSHEY_SIMPLEX, 1.5, blue, 4)
    cv2.rectangle(rgb, (w + 170, 200), (w + 280, 260), blue, -1)
    plain = np.full_like(rgb, PAPER_RGB)
    plain[100:100 + h, 150:150 + w] = sc.rgb
    clean = find_hole(plain, threshold_rgb(plain).mask)
    assert clean.confidence > 0.95
    marked = find_hole(rgb, threshold_rgb(rgb).mask)
    assert marked.radius_px > R + 50  # it holds the marks
    assert marked.confidence < 0.5 and "grown" in marked.reason


@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.55, -0.35), (-0.2, 0.75)])
def test_a_plate_edge_beyond_a_rod_that_does_not_reach_it(scene, offset):
    """A rod loosely packed, or a render of a free rod: the plate's edge lies far beyond the
    ink's envelope (here twice its radius, the rod off the hole's centre), where rays from
    the envelope out to 1.2 times its radius never reach it."""
    sc, c, R = scene
    h, w = sc.rgb.shape[:2]
    big = 2.0 * R
    size = int(2 * big + 120)
    centre = np.array([size / 2.0, size / 2.0])
    rgb = np.full((size, size, 3), PAPER_RGB, np.uint8)
    top, left = (centre + np.array(offset) * R - c).round().astype(int)
    rgb[top:top + h, left:left + w] = sc.rgb
    ink = threshold_rgb(rgb, method="fixed").mask
    img = apply_backdrop(rgb, ink_mask=ink, hole_center_rc=centre, hole_radius_px=big,
                         rng=np.random.default_rng(3), plate="grey", rim_px=2,
                         illumination=0.15, cast=0.06)
    hole = find_hole(img, threshold_rgb(img).mask)
    # measured: centre within 0.05 px, radius 0.57 px short (the dark rim); the rays from the
    # envelope alone found no edge and returned the envelope (radius off by about R)
    assert np.hypot(*(hole.center_rc - centre)) < 1.5
    assert abs(hole.radius_px - big) < 1.5
    assert hole.confidence > 0.9 and "plate" in hole.reason


def test_the_search_beyond_the_envelope_takes_no_scanner_lid_for_a_plate(scene):
    """The sheet on a dark scanner lid, no plate: the search out to the scan's border meets
    the paper's straight edges, which no circle fits; the ink's envelope is the hole."""
    sc, c, R = scene
    h, w = sc.rgb.shape[:2]
    rgb = np.full((h + 200, w + 200, 3), 20, np.uint8)
    rgb[100:100 + h, 100:100 + w] = sc.rgb
    hole = find_hole(rgb, threshold_rgb(rgb).mask)
    assert "envelope" in hole.reason and "beyond" not in hole.reason
    assert np.hypot(*(hole.center_rc - (c + 100))) < 1.5 and abs(hole.radius_px - R) < 1.5
    assert hole.confidence > 0.95


def test_frame_mask_area_and_margin():
    hole = Hole(np.array([40.0, 55.0]), 30.0, False)
    m0 = frame_mask((100, 120), hole, margin_px=0.0)
    m2 = frame_mask((100, 120, 3), hole)
    assert m0.shape == (100, 120) and m0.dtype == bool
    assert abs(m0.sum() - np.pi * 30 ** 2) < 0.01 * np.pi * 30 ** 2
    assert abs(m2.sum() - np.pi * 32 ** 2) < 0.01 * np.pi * 32 ** 2
    assert m0[40, 55] and not m0[40, 86] and m2[40, 86]


def test_trim_margin_keeps_the_wall_band_and_drops_a_ring():
    hole = Hole(np.array([60.0, 60.0]), 40.0, False)
    rr, cc = np.mgrid[:120, :120]
    d = np.hypot(rr - 60, cc - 60)
    ring = (d > 40) & (d <= 42)                       # a plate the colour rule passed
    band = (d > 34) & (d <= 40) & (cc > 60)           # a wall band on the right half only
    mask = (ring | band) & frame_mask((120, 120), hole)
    kept, n = trim_margin(mask, hole)
    # the ring beside paper, give or take the pixels where the band's edge meets it
    assert (np.count_nonzero(mask & (d > 40) & (cc < 59)) <= n
            <= np.count_nonzero(mask & (d > 40) & (cc < 62)))
    assert kept[band].all()                           # the band is never touched
    assert not (kept & (d > 40) & (cc < 59)).any()    # the ring beside paper goes
    assert (kept & (d > 40) & (cc > 61)).sum() > 0.9 * (ring & (cc > 61)).sum()
    same, n0 = trim_margin(band & frame_mask((120, 120), hole), hole)
    assert n0 == 0 and same[band].all()


def test_a_blue_plate_outside_a_given_hole_never_enters(scene):
    """A plate coloured like the ink passes any colour rule; the given hole keeps it out,
    margin included: the same network as on the scan without a plate."""
    from crosssection import analyze

    sc, c, R = scene
    base = _leave_wall(sc.rgb, c, R)
    ink = threshold_rgb(base, method="fixed").mask
    img = apply_backdrop(base, ink_mask=ink, hole_center_rc=c, hole_radius_px=R,
                         rng=np.random.default_rng(5), plate=(60, 90, 170), rim_px=0)
    p = sc.params
    # the paper painted over the wall cuts a two-layer wall band obliquely and leaves 1.5 mm
    # of it one layer wide, read as a layer step or not as the plate trims the band's outer
    # edge: the stacks are compared here as the paper delimits them
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              calibration=sc.calibration, hole_radius_mm=p["hole_radius_mm"],
              hole_center_px=tuple(p["hole_center_px"]), layer_steps=False)
    plain = analyze(base, **kw)
    # most of the scan's ink-coloured pixels lie outside
    with pytest.warns(FrameWarning, match="of the ink lies outside the hole"):
        plated = analyze(img, **kw)
    assert plated.summary["n_loops"] == plain.summary["n_loops"]
    assert abs(plated.summary["rod_length_mm"] / plain.summary["rod_length_mm"] - 1) < 0.01
    assert len(plated.stacks) == len(plain.stacks)


@pytest.mark.parametrize("plate", [(100, 120, 190), (150, 170, 215), (60, 90, 170)])
def test_a_plate_passed_as_ink_is_told_apart_by_its_colour(scene, plate):
    """A blue plate is ink to the colour rule; without the hole given, its own colour
    (hue and brightness, whatever the light) separates it from the rod's ink."""
    sc, c, R = scene
    base = _leave_wall(sc.rgb, c, R)
    ink = threshold_rgb(base, method="fixed").mask
    img = apply_backdrop(base, ink_mask=ink, hole_center_rc=c, hole_radius_px=R,
                         rng=np.random.default_rng(3), plate=plate, rim_px=0,
                         illumination=0.15, cast=0.06)
    passed = threshold_rgb(img).mask
    assert passed[:20].mean() > 0.9  # the plate passes the ink's colour rule
    hole = find_hole(img, passed)
    assert np.hypot(*(hole.center_rc - c)) < 1.5 and abs(hole.radius_px - R) < 1.5
    assert hole.confidence > 0.9 and "plate" in hole.reason


def test_a_plate_coloured_as_the_ink_is_flagged(scene):
    sc, c, R = scene
    ink = threshold_rgb(sc.rgb, method="fixed").mask
    ink_rgb = np.median(sc.rgb[ink], axis=0)
    img = apply_backdrop(sc.rgb, ink_mask=ink, hole_center_rc=c, hole_radius_px=R,
                         rng=np.random.default_rng(3), plate=tuple(ink_rgb), rim_px=0)
    hole = find_hole(img, threshold_rgb(img).mask)
    assert hole.confidence < 0.5  # nothing tells the two apart: the hole must be given


def test_absurd_holes_raise():
    check_hole((850, 850), (425, 425), 800)                      # large but possible
    with pytest.raises(ParameterError, match="twice"):
        check_hole((850, 850), (425, 425), 50_000)                # 1000 mm at 50 px/mm
    with pytest.raises(ParameterError, match="overlap"):
        frame_mask((100, 100), Hole(np.array([500.0, 500.0]), 50.0, False))
    with pytest.raises(ParameterError):
        check_hole((100, 100), None, -3)
    with pytest.raises(ParameterError):
        check_hole((100, 100), (np.nan, 3), 10)


def _ring_scan(R=300.0, band=12.0, size=760):
    """Paper with a blue wall band of ``band`` px inside a circle of radius ``R``."""
    rr, cc = np.mgrid[:size, :size]
    d = np.hypot(rr - size / 2, cc - size / 2)
    img = np.empty((size, size, 3), np.uint8)
    img[:] = PAPER_RGB
    img[(d <= R) & (d > R - band)] = (40, 70, 170)
    return img, np.array([size / 2, size / 2])


@pytest.mark.parametrize("radius_factor,shift_px,crossed", [(1.0, 0, False), (1.02, 0, False),
                                                            (0.97, 0, True), (1.0, 8, True)])
@pytest.mark.parametrize("band", [12.0, 3.0])
def test_ink_across_circle_finds_a_given_hole_that_cuts_the_wall_band(radius_factor, shift_px,
                                                                      crossed, band):
    """A circle 3 % short or 8 px off cuts a wall band 12 px wide, and leaves one of 3 px
    (a single sheet at 30 px/mm) wholly beyond it: both count."""
    from crosssection.stages.hole import GIVEN_CROSSED_LIMIT, ink_across_circle

    img, c = _ring_scan(band=band)
    ink = threshold_rgb(img).mask
    hole = Hole(c + [0, shift_px], 300.0 * radius_factor, False)
    frac = ink_across_circle(lambda r, cc: ink[r, cc], img.shape, hole)
    assert (frac > GIVEN_CROSSED_LIMIT) == crossed
    if crossed:
        assert frac > 0.1


def test_ink_across_circle_ignores_a_background_that_passes_everywhere():
    """A blue plate (or background) passing the ink's cut all round is not a cut band."""
    from crosssection.stages.hole import ink_across_circle

    img, c = _ring_scan()
    rr, cc = np.mgrid[:img.shape[0], :img.shape[1]]
    img[np.hypot(rr - c[0], cc - c[1]) > 300.0] = (60, 90, 170)
    ink = threshold_rgb(img, method="fixed").mask
    assert ink_across_circle(lambda r, q: ink[r, q], img.shape, Hole(c, 300.0, False)) == 0.0


@pytest.mark.parametrize("radius_factor,shift_mm", [(0.97, 0.0), (1.0, 0.5)])
def test_a_given_hole_a_little_off_is_replaced_by_the_hole_found(scene, radius_factor, shift_mm):
    """A hole given 3 % short, or its centre 0.5 mm off, cuts the wall band: the hole found in
    the scan replaces it (flagged), and the analysis is that of the right hole; without the
    correction the wall band is lost (flagged too)."""
    from crosssection import analyze
    from crosssection.quality import FrameWarning

    sc, c, R = scene
    ink = threshold_rgb(sc.rgb, method="fixed").mask
    img = apply_backdrop(sc.rgb, ink_mask=ink, hole_center_rc=c, hole_radius_px=R,
                         rng=np.random.default_rng(5), plate="grey", rim_px=0)
    p = sc.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              calibration=sc.calibration)
    exact = analyze(img, hole_radius_mm=p["hole_radius_mm"],
                    hole_center_px=tuple(p["hole_center_px"]), **kw)
    assert "hole_crossed" not in exact.summary["quality"]["codes"]
    off = dict(hole_radius_mm=p["hole_radius_mm"] * radius_factor,
               hole_center_px=(p["hole_center_px"][0] + shift_mm * p["px_per_mm"],
                               p["hole_center_px"][1]))
    with pytest.warns(FrameWarning, match="the hole found in the scan is used"):
        fixed = analyze(img, **off, **kw)
    assert abs(fixed.hole.radius_px - exact.hole.radius_px) < 2.0
    assert np.hypot(*(fixed.hole.center_rc - exact.hole.center_rc)) < 2.0
    assert abs(fixed.summary["rod_length_mm"] / exact.summary["rod_length_mm"] - 1) < 0.005
    assert len(fixed.stacks) == len(exact.stacks)
    # also: the ink left outside the hole, and (the wall band cut) counts that the widths
    # contradict
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        kept = analyze(img, **off, **kw, hole_correction=False)
    assert any(issubclass(w.category, FrameWarning)
               and "frames the ink; check hole_radius_mm" in str(w.message) for w in caught)
    assert kept.hole.radius_px == pytest.approx(off["hole_radius_mm"] * p["px_per_mm"])
    assert kept.summary["rod_length_mm"] < 0.99 * exact.summary["rod_length_mm"]


def test_a_radius_given_alone_and_short_is_replaced_by_the_hole_found(scene):
    """A radius given without its centre, 10 % short: the hole fitted to the ink with it cut
    the wall band (rod about half) and the warning blamed a plate; the hole found replaces
    it, as a whole hole given off."""
    from crosssection import analyze
    from crosssection.quality import FrameWarning

    sc, c, R = scene
    p = sc.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              calibration=sc.calibration)
    exact = analyze(sc.rgb, hole_radius_mm=p["hole_radius_mm"],
                    hole_center_px=tuple(p["hole_center_px"]), **kw)
    with pytest.warns(FrameWarning, match="its centre fitted at"):
        short = analyze(sc.rgb, hole_radius_mm=0.9 * p["hole_radius_mm"], **kw)
    assert abs(short.summary["rod_length_mm"] / exact.summary["rod_length_mm"] - 1) < 0.005
    assert "ink_outside_hole" not in short.summary["quality"]["codes"]


@pytest.mark.parametrize("gap_mm", [0.25, 0.5])
def test_a_ring_drawn_round_a_right_hole_does_not_replace_it(scene, gap_mm):
    """A marker's ring 0.25-0.5 mm outside a hole given right took its place, and counted as
    a stack (+18 % of rod): ink beyond the circle apart from the rod inside is not the rod."""
    import cv2

    from crosssection import analyze

    sc, c, R = scene
    p = sc.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              calibration=sc.calibration, hole_radius_mm=p["hole_radius_mm"],
              hole_center_px=tuple(p["hole_center_px"]))
    plain = analyze(sc.rgb, **kw)
    img = sc.rgb.copy()
    gap = gap_mm * p["px_per_mm"]
    cv2.circle(img, (int(round(c[1])), int(round(c[0]))), int(round(R + gap)), (40, 70, 170),
               4, lineType=cv2.LINE_AA)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ringed = analyze(img, **kw)
    assert ringed.hole.radius_px == pytest.approx(plain.hole.radius_px)
    assert "hole_crossed" not in ringed.summary["quality"]["codes"]
    assert "ink_outside_hole" in ringed.summary["quality"]["codes"]
    assert len(ringed.stacks) == len(plain.stacks)
    assert ringed.summary["rod_length_mm"] == pytest.approx(plain.summary["rod_length_mm"],
                                                            rel=0.005)
    assert caught


def test_frame_mask_is_the_distance_test_on_every_pixel():
    """The rows' runs are the pixels within radius + margin,
    with holes cut by the image's edges or lying partly outside it."""
    rng = np.random.default_rng(2)
    for _ in range(40):
        h, w = (int(v) for v in rng.integers(5, 120, 2))
        hole = Hole(rng.uniform(-20, 140, 2), float(rng.uniform(10, 90)), False)
        margin = float(rng.choice([0.0, 2.0, 3.5]))
        try:
            got = frame_mask((h, w), hole, margin_px=margin)
        except ParameterError:
            continue  # the hole does not overlap the image
        rr, cc = np.mgrid[:h, :w]
        r0, c0 = hole.center_rc
        want = (rr - r0) ** 2 + (cc - c0) ** 2 <= (hole.radius_px + margin) ** 2
        assert got.dtype == bool and np.array_equal(got, want)
def test_ray_grid_is_the_numpy_expression():
    from crosssection.stages.hole import _ray_grid

    rng = np.random.default_rng(4)
    for _ in range(50):
        h, w = (int(v) for v in rng.integers(10, 3000, 2))
        c0 = rng.uniform(-50, 3000, 2)
        r0 = float(rng.uniform(1, 2000))
        ang = np.linspace(-np.pi, np.pi, int(rng.integers(1, 800)), endpoint=False)
        rad = np.arange(0.7 * r0, 1.2 * r0 + 10.0, float(rng.choice([1.0, 2.0])))
        rr = c0[0] + np.sin(ang)[:, None] * rad[None, :]
        cc = c0[1] + np.cos(ang)[:, None] * rad[None, :]
        mr, mc, valid = _ray_grid(float(c0[0]), float(c0[1]), np.sin(ang), np.cos(ang), rad,
                                  h, w)
        assert mr.dtype == mc.dtype == np.float32
        assert np.array_equal(mr, rr.astype(np.float32))
        assert np.array_equal(mc, cc.astype(np.float32))
        assert np.array_equal(valid, (rr >= 0) & (rr <= h - 1) & (cc >= 0) & (cc <= w - 1))


def test_median_and_percentile_are_numpys():
    """Bit for bit and in the same type, on few and many values, with and without ties."""
    from crosssection.stages.hole import _median, _percentile

    rng = np.random.default_rng(6)
    for it in range(3000):
        n = int(rng.integers(1, 60)) if it % 3 else int(rng.integers(60, 5000))
        kind = it % 4
        if kind == 0:    # the 3 x 3 means of 8-bit samples
            x = (rng.integers(0, 2296, n) / 9.0).astype(np.float32)
        elif kind == 1:  # many ties
            x = rng.integers(0, 5, n).astype(np.float32) * np.float32(0.1)
        elif kind == 2:
            x = rng.normal(0.0, 100.0, n).astype(np.float32)
        else:
            x = rng.normal(0.0, 100.0, n)
        m = _median(x.copy())
        want = np.median(x)
        assert type(m) is type(want) and m == want
        for q in (80, 50, 0, 12.5, float(rng.uniform(0, 100))):
            p = _percentile(x.copy(), q)
            want = np.percentile(x, q)
            assert type(p) is type(want) and p == want, (n, q)


def test_a_lighting_ramp_is_no_plate_edge():
    """The bundled medium scan under the generator's uneven illumination (+-25 %, no plate):
    the far search reads the ramp as a nearly straight edge, whose circle lies 10^6 px off
    the scan; it is no candidate (sampling its rays overran OpenCV's remap), and the hole is
    the one found without the ramp."""
    from crosssection.samples import samples_path
    from crosssection.stages.load import load_image

    rgb = load_image(samples_path() / "scan_02_medium.png")
    plain = find_hole(rgb, threshold_rgb(rgb).mask)
    img = apply_backdrop(rgb, ink_mask=threshold_rgb(rgb).mask, hole_center_rc=plain.center_rc,
                         hole_radius_px=plain.radius_px, rng=np.random.default_rng(0),
                         plate=None, illumination=0.25)
    hole = find_hole(img, threshold_rgb(img).mask)
    assert np.hypot(*(hole.center_rc - plain.center_rc)) < 1.0
    assert abs(hole.radius_px - plain.radius_px) < 1.0
    assert hole.confidence > 0.95 and "envelope" in hole.reason


def test_remap_in_blocks_is_opencvs():
    """Maps and images beyond OpenCV's size limit are sampled block by block: the same values
    (checked here with a small limit)."""
    import cv2

    from crosssection.stages.hole import _ray_grid, _remap

    src = np.random.default_rng(0).integers(0, 256, (300, 500, 3), dtype=np.uint8)
    ang = np.linspace(-np.pi, np.pi, 90, endpoint=False)
    mr, mc, _ = _ray_grid(150.3, 240.7, np.sin(ang), np.cos(ang), np.arange(0.0, 700.0), 300,
                          500)
    for interp in (cv2.INTER_LINEAR, cv2.INTER_NEAREST):
        want = cv2.remap(src, mc, mr, interp, borderMode=cv2.BORDER_REPLICATE)
        for limit in (7, 64, 200):
            assert np.array_equal(_remap(src, mc, mr, interp, limit=limit), want)


def test_ink_on_one_line_is_one_plain_line():
    from crosssection.core.errors import AnalysisError
    from crosssection.stages.hole import fit_hole

    mask = np.zeros((40, 40), bool)
    mask[np.arange(5, 30), np.arange(5, 30)] = True  # a diagonal: collinear border points
    with pytest.raises(AnalysisError) as err:
        fit_hole(mask, path="scan.png")
    msg = err.value.one_line()
    assert msg.startswith("scan.png: cannot fit the hole: ") and "lie on one line" in msg
    assert "QH" not in msg and "Qhull" not in msg


@pytest.mark.parametrize("plate", ["grey", None, "none, off the wall"])
def test_a_given_hole_too_wide_is_flagged_and_a_plate_edge_replaces_it(scene, plate):
    """A radius given 6 % too large is flagged (epsilon low). The plate's edge, where the
    scan shows one, replaces it, and on bare paper the ink's envelope where the ink lines it
    all round; a rod off the wall on a quarter of it keeps the hole, flagged, and its wall
    band, 2.75 h inside the circle kept, still reads as periphery (a gap within
    ``wall_gap_max_px``)."""
    from crosssection import analyze

    sc, c, R = scene
    img = sc.rgb if plate is None else _leave_wall(sc.rgb, c, R)
    if plate == "grey":
        ink = threshold_rgb(sc.rgb, method="fixed").mask
        img = apply_backdrop(sc.rgb, ink_mask=ink, hole_center_rc=c, hole_radius_px=R,
                             rng=np.random.default_rng(5), plate=plate, rim_px=0)
    p = sc.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              calibration=sc.calibration, hole_center_px=tuple(p["hole_center_px"]))
    exact = analyze(img, hole_radius_mm=p["hole_radius_mm"], **kw)
    assert "hole_wide" not in exact.summary["quality"]["codes"]
    n_periphery = int((exact.tables["stacks"]["region"] == "periphery").sum())
    assert n_periphery > 0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        wide = analyze(img, hole_radius_mm=1.06 * p["hole_radius_mm"], **kw)
    assert "hole_wide" in wide.summary["quality"]["codes"]
    assert any(issubclass(w.category, FrameWarning) and "given hole's circle" in str(w.message)
               for w in caught)
    regions = wide.tables["stacks"]["region"]
    if plate == "none, off the wall":
        assert wide.hole.radius_px == pytest.approx(1.06 * R)
        # (one stack ends where the wall ink is taken away: paper beyond it, no gap)
        assert int((regions == "periphery").sum()) >= n_periphery - 1
        return
    assert wide.hole.replaced and wide.hole.radius_px == pytest.approx(R, abs=2.0)
    assert int((regions == "periphery").sum()) == n_periphery
    assert wide.summary["epsilon"] == pytest.approx(exact.summary["epsilon"], rel=0.01)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FrameWarning)
        warnings.simplefilter("ignore", DarkMarksWarning)
        warnings.simplefilter("ignore", MarksOnInkWarning)
        kept = analyze(img, hole_radius_mm=1.06 * p["hole_radius_mm"], hole_correction=False,
                       **kw)
    assert "hole_wide" in kept.summary["quality"]["codes"]
    # the grey plate inside the circle kept is dark and not ink, and lines the wall band:
    # named too
    assert ("dark_marks" in kept.summary["quality"]["codes"]) is (plate == "grey")
    assert ("marks_on_ink" in kept.summary["quality"]["codes"]) is (plate == "grey")
    assert kept.hole.radius_px == pytest.approx(1.06 * R)


def test_a_rod_away_from_a_right_wall_is_not_a_hole_too_wide(scene):
    """A plate's edge at the given circle makes the hole right, however far inside it the
    rod lies (a loose rod): the ink alone cannot tell."""
    from crosssection import analyze

    sc, c, R = scene
    ink = threshold_rgb(sc.rgb, method="fixed").mask
    p = sc.params
    wide_R = 1.06 * R
    img = apply_backdrop(sc.rgb, ink_mask=ink, hole_center_rc=c, hole_radius_px=wide_R,
                         rng=np.random.default_rng(5), plate="grey", rim_px=0)
    res = analyze(img, px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
                  calibration=sc.calibration, hole_center_px=tuple(p["hole_center_px"]),
                  hole_radius_mm=1.06 * p["hole_radius_mm"])
    assert "hole_wide" not in res.summary["quality"]["codes"]
    assert res.hole.radius_px == pytest.approx(wide_R)


@pytest.mark.parametrize("rim", ["light", None])
def test_a_plate_edge_found_beyond_a_light_rim_is_flagged(scene, rim):
    """A light ring of the plate round the hole (a bevel, paler than the plate) reads as paper:
    the plate's edge is found at its outer side, 20 px too wide at full confidence. The ink
    pressed against a circle inside it, across a surface darker than the paper, is flagged
    (``hole_wide``); a rod lying away from a right wall, paper between, is not."""
    from crosssection import analyze

    sc, c, R = scene
    ink = threshold_rgb(sc.rgb, method="fixed").mask
    p = sc.params
    plate_r = R if rim else 1.1 * R
    img = apply_backdrop(sc.rgb, ink_mask=ink, hole_center_rc=c, hole_radius_px=plate_r,
                         rng=np.random.default_rng(5), plate="grey", rim_px=0)
    if rim:
        rr, cc = np.mgrid[:img.shape[0], :img.shape[1]]
        d = np.hypot(rr - c[0], cc - c[1])
        img = img.copy()
        img[(d > R + 0.5) & (d < R + 20)] = (205, 200, 192)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = analyze(img, px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
                      calibration=sc.calibration)
    codes = res.summary["quality"]["codes"]
    if rim:
        assert res.hole.radius_px == pytest.approx(R + 20, abs=3)  # kept, flagged
        assert "hole_wide" in codes
        msg = [str(w.message) for w in caught if issubclass(w.category, FrameWarning)]
        assert any("light rim" in m and "give the hole" in m for m in msg)
    else:
        assert res.hole.radius_px == pytest.approx(plate_r, abs=3)
        assert "hole_wide" not in codes


def test_a_radius_given_alone_too_wide_is_replaced_by_the_lined_envelope():
    """A radius given alone 5-7 % too large (a sample scan, 8.3-8.5 mm for 7.94): the centre
    fitted with it hugs one side of the rod, which reaches that circle on 29 % of it (8.5
    mm), so no flag was raised while 17 of the 26 wall stacks read as bulk and epsilon 7 %
    low. The ink lines a smaller circle all round: that circle is the wall. (At 8.5 mm the
    fitted circle also cuts the rod on its far side, and the hole found replaces it first,
    ``hole_crossed``.)"""
    from pathlib import Path

    from crosssection import analyze

    root = Path(__file__).resolve().parents[3] / "sample_images"
    kw = dict(px_per_mm=50, thickness_mm=0.1, calibration=str(root / "calibration.csv"))
    scan = str(root / "scan_02_medium.png")
    exact = analyze(scan, hole_radius_mm=7.9351, hole_center_px=(428.75, 423.44), **kw)
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        crossed = analyze(scan, hole_radius_mm=8.5, **kw)
        wide = analyze(scan, hole_radius_mm=8.3, **kw)
    assert crossed.summary["quality"]["codes"] == ["hole_crossed"] and crossed.hole.replaced
    assert crossed.summary["epsilon"] == pytest.approx(exact.summary["epsilon"], rel=0.005)
    assert "hole_wide" in wide.summary["quality"]["codes"]
    # the flag records the limit of the rule that fired: its value lies beyond it
    flag = next(f for f in wide.quality if f.code == "hole_wide")
    assert flag.value < flag.limit == 0.5
    assert wide.hole.replaced
    assert wide.hole.radius_px == pytest.approx(exact.hole.radius_px, abs=1.0)
    assert wide.summary["epsilon"] == pytest.approx(exact.summary["epsilon"], rel=0.005)
    regions = [t.tables["stacks"]["region"] for t in (exact, wide)]
    assert list(regions[0]) == list(regions[1])


def test_a_given_radius_is_recorded_as_given():
    # not its round trip through pixels (7.574200000000001 in index.csv for 7.5742)
    from pathlib import Path

    from crosssection import analyze

    root = Path(__file__).resolve().parents[3] / "sample_images"
    assert 7.5742 * 50 / 50 != 7.5742
    res = analyze(str(root / "scan_01_sparse.png"), px_per_mm=50, thickness_mm=0.1,
                  calibration=str(root / "calibration.csv"), hole_radius_mm=7.5742,
                  hole_center_px=(428.06, 426.92))
    assert not res.hole.replaced and res.summary["hole"]["radius_mm"] == 7.5742


def test_border_points_on_one_line_name_a_plate_of_the_inks_colour():
    # a plate of the ink's colour around the hole left the ink's border on the scan's edge:
    # the message blamed too little ink alone
    from crosssection.core.errors import AnalysisError
    from crosssection.stages.hole import _fit_points

    pts = np.c_[np.zeros(74), np.arange(74.0)]
    with pytest.raises(AnalysisError, match="or a plate of the ink's colour around the hole"
                                            ".*give the hole"):
        _fit_points(pts, None, None, 2.0, "scan.png")


@pytest.mark.parametrize("fixed", [False, True])
def test_soft_l1_circle_is_scipys_least_squares(fixed):
    """The compiled circle fit lands where ``scipy.optimize.least_squares`` with the same
    soft-L1 loss does: arcs and whole circles, noisy, with points pulled inwards (gaps in
    the wall band) and a start off by several pixels."""
    from scipy.optimize import least_squares

    from crosssection.stages.hole import _soft_l1_circle

    rng = np.random.default_rng(11)
    for _ in range(60):
        n = int(rng.integers(20, 3000))
        r_true = float(rng.uniform(30, 2000))
        c_true = rng.uniform(-500, 2500, 2)
        span = float(rng.uniform(0.5, 2.0)) * np.pi
        t = rng.uniform(0.0, span, n)
        rr = c_true[0] + r_true * np.sin(t) + rng.normal(0, rng.uniform(0.1, 2.0), n)
        cc = c_true[1] + r_true * np.cos(t) + rng.normal(0, rng.uniform(0.1, 2.0), n)
        pulled = rng.random(n) < rng.uniform(0.0, 0.3)
        shrink = 1.0 - rng.uniform(0.0, 0.1, n) * pulled
        rr, cc = c_true[0] + (rr - c_true[0]) * shrink, c_true[1] + (cc - c_true[1]) * shrink
        x0 = np.r_[c_true + rng.normal(0, 5, 2), r_true + rng.normal(0, 5)]
        if fixed:
            rad = r_true
            want = least_squares(lambda x: np.hypot(rr - x[0], cc - x[1]) - rad, x0[:2],
                                 loss="soft_l1", f_scale=1.0).x
            got = _soft_l1_circle(rr, cc, x0, rad)
            assert got[2] == rad
            np.testing.assert_allclose(got[:2], want, atol=1e-5)
        else:
            want = least_squares(lambda x: np.hypot(rr - x[0], cc - x[1]) - x[2], x0,
                                 loss="soft_l1", f_scale=1.0).x
            got = _soft_l1_circle(rr, cc, x0, np.nan)
            np.testing.assert_allclose(got, want, atol=1e-5)
        # and it is a minimum of the loss: no nearby circle has a lower one
        def loss(x):
            f = np.hypot(rr - x[0], cc - x[1]) - x[2]
            return np.sum(2.0 * (np.sqrt(1.0 + f * f) - 1.0))
        for d in np.eye(3)[: 2 if fixed else 3]:
            assert loss(got + 1e-3 * d) >= loss(got) and loss(got - 1e-3 * d) >= loss(got)


def test_soft_l1_circle_where_the_data_do_not_fix_the_circle():
    """Points that leave the circle ill-determined (a short arc of a large circle, points
    on a line, one point repeated, a start far off, a fixed radius far from the data):
    the fit ends no worse than ``least_squares`` from the same start, never on its start
    unchanged when that start is not a minimum."""
    from scipy.optimize import least_squares

    from crosssection.stages.hole import _soft_l1_circle

    def loss(x, rr, cc, rad):
        f = np.hypot(rr - x[0], cc - x[1]) - rad
        return np.sum(2.0 * (np.sqrt(1.0 + f * f) - 1.0))

    a = np.linspace(-1e-3, 1e-3, 50)
    cases = [
        (1e4 * np.cos(a), 1e4 * np.sin(a), np.array([100.0, 3.0, 9800.0]), np.nan),
        (np.array([448.63091285067577, -34.85314427708451, -470.143254581899]),
         np.array([142.11733948813458, 469.46426051796914, 24.60884523717465]),
         np.array([-184.09301012565803, 100.07642703846467, 0.0]), 383.1636874786909),
        (np.linspace(0, 100, 40), np.full(40, 7.0), np.array([50.0, 500.0, 480.0]), np.nan),
        (np.full(10, 3.0), np.full(10, 4.0), np.array([0.0, 0.0, 1.0]), np.nan),
    ]
    rng = np.random.default_rng(2)
    for _ in range(20):
        r = 10.0 ** rng.uniform(3, 6)
        t = rng.uniform(0, rng.uniform(1e-3, 0.1), 30)
        cases.append((r * np.sin(t) + rng.normal(0, 0.5, 30), r * np.cos(t),
                      np.array([rng.normal(0, r), rng.normal(0, r), r * rng.uniform(0.5, 2)]),
                      np.nan))
    for rr, cc, x0, radius in cases:
        got = _soft_l1_circle(rr, cc, x0, radius)
        fixed = np.isfinite(radius)
        if fixed:
            ref = least_squares(lambda x: np.hypot(rr - x[0], cc - x[1]) - radius, x0[:2],
                                loss="soft_l1", f_scale=1.0).x
            ref, rad_got = np.r_[ref, radius], radius
        else:
            ref = least_squares(lambda x: np.hypot(rr - x[0], cc - x[1]) - x[2], x0,
                                loss="soft_l1", f_scale=1.0).x
            rad_got = got[2]
        assert np.all(np.isfinite(got))
        want = loss(ref, rr, cc, ref[2])
        assert loss(got, rr, cc, rad_got) <= want * (1 + 1e-9) + 1e-12



@pytest.mark.parametrize("rc", [(6, 6), (7, 7), (6, 7), (7, 6)])
def test_one_ink_pixel_on_the_paper_does_not_grow_a_plateless_hole(rc):
    # a pixel off the half-resolution lattice the specks are told on (an odd row or column)
    # grew the hole from the rod's envelope (7.96 mm) to a circle through it (12.35 mm)
    scene = make_scene(seed=18, n_stacks=30, max_layers=4)
    a = scene.rgb.astype(int)
    ink = (a[..., 2] - np.maximum(a[..., 0], a[..., 1])) > 60
    clean = find_hole(scene.rgb, ink)
    marked = ink.copy()
    marked[rc] = True
    hole = find_hole(scene.rgb, marked)
    assert hole.radius_px == pytest.approx(clean.radius_px, abs=0.5)
    np.testing.assert_allclose(hole.center_rc, clean.center_rc, atol=0.5)
