"""Figures: overlay (paper Figs. 1c, 9a) and processing steps (Fig. 2)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from crosssection.core.fileio import save_figure
from crosssection.figures import (BULK_COLOR, PANEL_MAX_PX, PERIPHERY_COLOR, overlay_figure,
                                  overlay_window, panel_image, steps_figure)
from crosssection.stages.hole import Hole


def _network(seed, m=40, size=400):
    rng = np.random.default_rng(seed)
    paths, rows = [], []
    for i in range(m):
        a = rng.uniform(40, size - 40, 2)
        b = a + rng.uniform(-80, 80, 2)
        b = np.clip(b, 5, size - 5)
        t = np.linspace(0, 1, int(np.hypot(*(b - a))) + 2)[:, None]
        p = np.round(a + t * (b - a)).astype(int)
        paths.append(p)
        mid = p[len(p) // 2]
        rows.append(dict(stack_id=i, n_br=int(rng.integers(1, 6)),
                         region=("periphery" if i % 2 else "bulk"),
                         mid_x_px=mid[1], mid_y_px=mid[0]))
    stacks = pd.DataFrame(rows)
    jc = rng.uniform(20, size - 20, (15, 2))
    junctions = pd.DataFrame(dict(junction_id=np.arange(15), x_px=jc[:, 1], y_px=jc[:, 0]))
    rgb = np.full((size, size, 3), 245, np.uint8)
    return rgb, stacks, junctions, paths


def _hex(c):
    return np.array([int(c[i:i + 2], 16) for i in (1, 3, 5)])


@pytest.mark.parametrize("seed", [0, 1])
def test_overlay_draws_regions_and_saves(tmp_path, seed):
    rgb, stacks, junctions, paths = _network(seed)
    hole = Hole(np.array([200.0, 200.0]), 190.0, False)
    fig = overlay_figure(rgb, junctions_df=junctions, stacks_df=stacks, paths=paths, hole=hole)
    ax = fig.axes[0]
    lc = ax.collections[0]
    assert len(lc.get_segments()) == len(paths)
    lw = np.asarray(lc.get_linewidths())
    ratio = lw / stacks.n_br.to_numpy()
    assert np.allclose(ratio, ratio[0])                     # width proportional to n_br
    labels = [t.get_text() for t in ax.texts]
    assert len(labels) > 0 and set(labels) <= {str(n) for n in stacks.n_br}
    out = save_figure(fig, tmp_path / "overlay.png")
    img = np.asarray(Image.open(out).convert("RGB")).astype(int)
    for col in (BULK_COLOR, PERIPHERY_COLOR):
        close = np.abs(img - _hex(col)).sum(axis=2) < 60
        assert close.sum() > 50, col                         # both regions visible


def test_overlay_from_result_object_and_uint16():
    rgb, stacks, junctions, paths = _network(3, m=5)

    class G:
        pass

    class R:
        pass

    r = R()
    r.junctions, r.stacks, r.graph, r.hole = junctions, stacks, G(), None
    r.graph.paths = paths
    fig = overlay_figure(rgb.astype(np.uint16) * 257, r)
    assert len(fig.axes[0].collections[0].get_segments()) == 5


def test_overlay_many_stacks(tmp_path):
    rgb, stacks, junctions, paths = _network(4, m=3000, size=1500)
    fig = overlay_figure(rgb, junctions_df=junctions, stacks_df=stacks, paths=paths)
    save_figure(fig, tmp_path / "big.png", dpi=60)
    assert (tmp_path / "big.png").stat().st_size > 1000


def test_steps_figure(tmp_path):
    rng = np.random.default_rng(5)
    rgb = rng.integers(0, 255, (120, 160, 3), dtype=np.uint8)
    m = rgb[..., 2] > 128
    fig = steps_figure(rgb, m, m, m & (rng.random(m.shape) > 0.5), np.array([[10.0, 20.0]]))
    assert len(fig.axes) == 4
    assert all(ax.get_title() for ax in fig.axes)
    out = save_figure(fig, tmp_path / "steps.png")
    assert Image.open(out).size[0] > Image.open(out).size[1]


def test_the_steps_of_a_result_have_a_scale_bar_at_its_scale(tmp_path):
    # the four panels share one scale: one bar, on the raw scan, in mm at the scan's px_per_mm
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    from crosssection import analyze
    from crosssection.truth.network import make_scene

    sc = make_scene(seed=3, n_stacks=12, max_layers=3)
    for ppm in (50.0, 25.0):
        res = analyze(sc.rgb, px_per_mm=ppm, thickness_mm=0.1 * 50.0 / ppm,
                      calibration=sc.calibration if ppm == 50.0 else None, warn=False)
        fig = res.plot("steps")
        bars = [[a for a in ax.artists if isinstance(a, AnchoredSizeBar)] for ax in fig.axes]
        assert [len(b) for b in bars] == [1, 0, 0, 0]
        mm = float(bars[0][0].txt_label.get_text().split()[0])
        assert 0.08 <= mm * ppm / sc.rgb.shape[1] <= 0.2
    paths = res.write_steps(tmp_path / "steps")
    assert paths["steps"].is_file()


@pytest.mark.parametrize("method", ["auto", "fixed"])
def test_steps_figure_names_the_threshold_used(method):
    # the threshold panel's title is the rule and cuts of this analysis, not a fixed text
    import matplotlib.pyplot as plt

    from crosssection import analyze
    from crosssection.truth.network import make_scene

    sc = make_scene(seed=3, n_stacks=12, max_layers=3)
    res = analyze(sc.rgb, px_per_mm=50.0, thickness_mm=0.1, calibration=sc.calibration,
                  threshold_method=method)
    t = res.summary["thresholds"]
    fig = res.plot("steps")
    title = fig.axes[1].get_title()
    plt.close(fig)
    if method == "fixed":
        assert title == "threshold: B \u2265 100, R, G \u2264 130"
    else:
        assert title.startswith("threshold (auto): B \u2212 max(R, G) \u2265 ")
        assert f"{t['cut']:.1f}".rstrip("0").rstrip(".") in title


@pytest.mark.parametrize("shape", [(400, 400), (1300, 300), (300, 1300), (2000, 760)])
def test_overlay_title_and_legend_stay_clear_of_each_other_and_the_scan(shape):
    # a tall scan makes a narrow figure: the title and the legend must neither cover each
    # other nor the scan, nor leave the figure
    rgb, stacks, junctions, paths = _network(5, m=30, size=min(shape))
    rgb = np.full(shape + (3,), 245, np.uint8)
    fig = overlay_figure(rgb, junctions_df=junctions, stacks_df=stacks, paths=paths,
                         title="a long title naming the scan and the settings it used")
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    title = fig._suptitle.get_window_extent(renderer)
    legend = fig.legends[0].get_window_extent(renderer)
    scan = fig.axes[0].get_window_extent(renderer)
    frame = fig.bbox
    assert not title.overlaps(legend)
    assert not title.overlaps(scan) and not legend.overlaps(scan)
    for box in (title, legend):
        assert box.x0 >= frame.x0 - 1 and box.x1 <= frame.x1 + 1
        assert box.y0 >= frame.y0 - 1 and box.y1 <= frame.y1 + 1


def test_overlay_frames_the_hole_of_a_page_scan():
    # a hole of 80 px on a 1500-px page: the overlay shows the hole, in the scan's own
    # coordinates, and the stacks are drawn as wide as on a scan cropped to the hole
    rgb, stacks, junctions, paths = _network(6, m=10, size=160)
    page = np.full((1500, 1200, 3), 245, np.uint8)
    offset = np.array([900, 300])
    page[900:1060, 300:460] = rgb
    moved = [p + offset for p in paths]
    stacks = stacks.assign(mid_x_px=stacks.mid_x_px + 300, mid_y_px=stacks.mid_y_px + 900)
    junctions = junctions.assign(x_px=junctions.x_px + 300, y_px=junctions.y_px + 900)
    hole = Hole(np.array([980.0, 380.0]), 80.0, False)
    fig = overlay_figure(page, junctions_df=junctions, stacks_df=stacks, paths=moved, hole=hole)
    ax = fig.axes[0]
    x0, x1 = sorted(ax.get_xlim())
    y0, y1 = sorted(ax.get_ylim())
    r = 80.0 * 1.08
    assert x0 == pytest.approx(380 - r, abs=1.5) and x1 == pytest.approx(380 + r, abs=1.5)
    assert y0 == pytest.approx(980 - r, abs=1.5) and y1 == pytest.approx(980 + r, abs=1.5)
    r0, r1, c0, c1 = overlay_window(page.shape, hole)
    alone = overlay_figure(page[r0:r1, c0:c1],
                           junctions_df=junctions.assign(x_px=junctions.x_px - c0,
                                                         y_px=junctions.y_px - r0),
                           stacks_df=stacks, paths=[p - [r0, c0] for p in moved])
    lw_page = np.asarray(ax.collections[0].get_linewidths())
    lw_alone = np.asarray(alone.axes[0].collections[0].get_linewidths())
    assert lw_page == pytest.approx(lw_alone, rel=0.05)
    # without a hole the whole page is shown
    whole = overlay_figure(page, junctions_df=junctions, stacks_df=stacks, paths=moved)
    assert sorted(whole.axes[0].get_xlim()) == pytest.approx([-0.5, 1199.5])


def test_a_large_scan_is_drawn_shrunk_in_its_own_coordinates():
    """A 5000-px scan is handed to matplotlib at most PANEL_MAX_PX on a side (whole, it is
    resampled in float64 copies: 1.24 GB peak for a 4000-px scan's analysis), placed over
    the same pixel coordinates; a one-pixel line of a mask stays visible."""
    big = np.full((5000, 2500, 3), 245, np.uint8)
    big[:, 1000:1003] = (40, 70, 190)
    small = panel_image(big)
    assert small.shape == (PANEL_MAX_PX, PANEL_MAX_PX // 2, 3) and small.dtype == np.uint8
    assert small[:, 480].min() < 160  # the line, averaged with the paper around it
    line = np.zeros((5000, 5000), bool)
    line[:, 2500] = True
    shrunk = panel_image(line)
    assert shrunk.shape == (PANEL_MAX_PX, PANEL_MAX_PX) and shrunk.max() > 0.4
    assert panel_image(big[:100, :2000]).shape == (100, 2000, 3)  # small enough: as it is
    fig = overlay_figure(big, paths=[np.array([[10, 1001], [4990, 1001]])], stacks_df=None)
    im = fig.axes[0].get_images()[0]
    assert max(im.get_array().shape[:2]) <= PANEL_MAX_PX
    assert im.get_extent() == pytest.approx([-0.5, 2499.5, 4999.5, -0.5])
    steps = steps_figure(big, line[:, :2500], line[:, :2500], line[:, :2500],
                         np.zeros((0, 2)))
    for ax in steps.axes:
        im = ax.get_images()[0]
        assert max(im.get_array().shape[:2]) <= PANEL_MAX_PX
        assert im.get_extent() == pytest.approx([-0.5, 2499.5, 4999.5, -0.5])


def test_the_overlay_of_a_result_names_its_scan_and_draws_a_scale_bar():
    from pathlib import Path

    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    from crosssection import analyze

    scan = Path(__file__).resolve().parents[2] / "sample_images" / "scan_01_sparse.png"
    res = analyze(scan, calibration=scan.parent / "calibration.csv", warn=False)
    fig = overlay_figure(res.rgb, res)
    assert fig._suptitle.get_text().startswith("scan_01_sparse.png: stacks")
    bars = [a for a in fig.axes[0].artists if isinstance(a, AnchoredSizeBar)]
    assert len(bars) == 1
    label = bars[0].txt_label.get_text()
    mm = float(label.split()[0])
    # a round length of about a fifth of the view, at the scan's scale
    r0, r1, c0, c1 = overlay_window(res.rgb.shape, res.hole)
    assert label.endswith(" mm") and 0.08 <= mm * res.params.px_per_mm / (c1 - c0) <= 0.2
    assert res.path is not None and overlay_figure(res.rgb)._suptitle.get_text().startswith(
        "stacks")


def test_the_legend_holds_what_the_overlay_draws_and_a_generic_name_its_folder(tmp_path):
    import shutil
    from pathlib import Path

    from crosssection import analyze

    scan = Path(__file__).resolve().parents[2] / "sample_images" / "scan_01_sparse.png"
    (tmp_path / "scene_7").mkdir()
    copy = shutil.copy(scan, tmp_path / "scene_7" / "image.png")
    res = analyze(copy, calibration=scan.parent / "calibration.csv", warn=False)
    fig = overlay_figure(res.rgb, res)
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "hole" in labels and "junction" in labels
    assert ("periphery" in labels) == ("periphery" in set(res.stacks["region"]))
    assert fig._suptitle.get_text().startswith("scene_7/image.png: stacks")
    bulk_only = res.stacks.assign(region="bulk")
    fig = overlay_figure(res.rgb, res, stacks_df=bulk_only)
    assert "periphery" not in [t.get_text() for t in fig.legends[0].get_texts()]


@pytest.mark.parametrize("dtype, top", [(np.uint8, 255), (np.uint16, 65535)])
def test_the_scale_bar_goes_to_a_corner_without_ink(dtype, top):
    """On a scan cropped through its hole the bar in the lower left lay over a stack."""
    import matplotlib.pyplot as plt
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    from crosssection.figures import _scale_bar

    def loc_of(img):
        fig, ax = plt.subplots()
        ax.imshow(img.astype(float) / top)
        _scale_bar(ax, 50.0, img.shape[1], img)
        bar = next(a for a in ax.artists if isinstance(a, AnchoredSizeBar))
        plt.close(fig)
        return bar.loc

    img = np.full((400, 400, 3), top, dtype)
    assert loc_of(img) == 3  # lower left, where it always was
    img[360:, :150] = np.array([40, 70, 170]) * (top // 255)  # a stack across that corner
    assert loc_of(img) == 4  # lower right
    img[360:, 250:] = np.array([40, 70, 170]) * (top // 255)
    assert loc_of(img) in (1, 2)  # an upper corner


def test_a_label_on_the_hole_circle_is_outlined_and_one_inside_is_not():
    # a wall stack's n_br label sits on the dashed circle: outlined in white to stay read
    size = 400
    ang = np.linspace(0.2, 1.2, 200)
    on_wall = np.stack([200 + 150 * np.sin(ang), 200 + 150 * np.cos(ang)], 1).round()
    inside = np.stack([np.full(200, 200.0), np.linspace(100, 300, 200)], 1)
    paths = [on_wall.astype(int), inside.astype(int)]
    stacks = pd.DataFrame(dict(n_br=[1, 2], region=["periphery", "bulk"]))
    fig = overlay_figure(np.full((size, size, 3), 245, np.uint8), stacks_df=stacks,
                         paths=paths, hole=Hole(np.array([200.0, 200.0]), 150.0, False))
    texts = {t.get_text(): t for t in fig.axes[0].texts}
    assert texts["1"].get_path_effects() and not texts["2"].get_path_effects()


def test_a_lone_ring_is_counted_in_the_singular_and_shows_no_junction_key():
    # one closed ring of ink: "1 stack, 1 branch", no junction in the legend, and the
    # curvature figure's title speaks of the stack
    import cv2

    from crosssection import analyze

    rgb = np.full((400, 400, 3), 245, np.uint8)
    cv2.circle(rgb, (200, 200), 150, (190, 50, 40), 6)  # BGR order is not read: blue ink
    rgb = rgb[..., ::-1].copy()
    res = analyze(rgb, px_per_mm=50.0, warn=False)
    fig = res.plot("overlay")
    title = fig._suptitle.get_text()
    assert "0 junctions, 1 stack, 1 branch)" in title
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "junction" not in labels
    assert res.plot("curvature").axes[0].get_title().startswith("curvature along the stack ")


def test_the_steps_show_the_hole_as_the_overlay_does():
    # a wide page with the cut in one part: the steps' panels show the hole and its margin,
    # the overlay's window, not the whole page (where the network is a strip in each panel)
    from crosssection import analyze
    from crosssection.truth.network import make_scene

    sc = make_scene(seed=3, n_stacks=12, max_layers=3)
    h, w = sc.rgb.shape[:2]
    page = np.full((h, 3 * w, 3), 245, np.uint8)
    page[:, w:2 * w] = sc.rgb
    p = sc.params
    cx, cy = p["hole_center_px"]
    res = analyze(page, px_per_mm=50.0, thickness_mm=0.1, calibration=sc.calibration,
                  hole_radius_mm=p["hole_radius_mm"], hole_center_px=(cx + w, cy), warn=False)
    r0, r1, c0, c1 = overlay_window(page.shape, res.hole)
    assert c1 - c0 < 0.5 * page.shape[1]
    fig = res.plot("steps")
    for ax in fig.axes:
        left, right, bottom, top = ax.images[0].get_extent()
        assert (right - left, bottom - top) == (c1 - c0, r1 - r0)
    # the junctions drawn where the skeleton panel shows them
    (pts,) = fig.axes[3].collections
    xy = pts.get_offsets()
    assert len(xy) == len(res.junctions)
    assert np.all((xy[:, 0] >= 0) & (xy[:, 0] < c1 - c0))
