"""Stage 8: widths from the distance transform, and the calibration table."""
from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
from scipy import ndimage
from skimage.draw import circle_perimeter, line
from skimage.morphology import skeletonize

from crosssection.core.errors import ConfigError, ParameterError
from crosssection.core.calibration import Calibration
from crosssection.stages.widths import path_width_profile_px, stack_widths, stack_widths_px
from crosssection.truth.graphs import NetworkGraph


def band_graph(width_px, theta, *, length=260, seed=0, skeleton=False):
    """A straight band of ``width_px`` (pixel centres within width/2 of the centre line) at
    angle ``theta``, sub-pixel offset at random, as a one-stack graph between two free ends
    whose path is the ideal centre line, or the skimage skeleton ordered along the band
    (``skeleton=True``; avoid exactly 45 degrees: both skimage's and the pipeline's thinning
    erase most of a perfect digital diagonal band)."""
    rng = np.random.default_rng(seed)
    size = int(length + 2 * width_px + 20)
    rr, cc = np.mgrid[:size, :size].astype(float)
    c0 = (size - 1) / 2 + rng.uniform(-0.5, 0.5, 2)
    t = np.array([np.sin(theta), np.cos(theta)])
    along = (rr - c0[0]) * t[0] + (cc - c0[1]) * t[1]
    perp = -(rr - c0[0]) * t[1] + (cc - c0[1]) * t[0]
    mask = (np.abs(perp) <= width_px / 2) & (np.abs(along) <= length / 2)
    if skeleton:
        pts = np.argwhere(skeletonize(mask))
        pts = pts[np.argsort(pts @ t)]
    else:  # the ideal centre line, rasterised (within half a pixel of the true centre)
        a = np.round(c0 - t * length / 2).astype(int)
        b = np.round(c0 + t * length / 2).astype(int)
        pts = np.column_stack(line(a[0], a[1], b[0], b[1]))
    G = nx.MultiGraph()
    G.add_edge(0, 1, stack_id=0)
    fg = NetworkGraph(G, {0: pts[0].astype(float), 1: pts[-1].astype(float)},
                   {0: "end", 1: "end"}, [pts], [(0, 1)])
    return fg, mask


@pytest.mark.parametrize("width_px", [5, 6, 7, 10, 15, 22, 31, 44, 60])
def test_band_width_within_half_pixel(width_px):
    rng = np.random.default_rng(width_px)
    errs = []
    for k, theta in enumerate(rng.uniform(0, np.pi, 4).tolist() + [0.0, np.pi / 2]):
        fg, mask = band_graph(width_px, theta, seed=k + width_px)
        w = stack_widths_px(fg, ndimage.distance_transform_edt(mask), junction_margin_px=10)
        errs.append(w[0] - width_px)
    # exactly 45 degrees the digital band's width is quantised in steps of 0.71 px (60 px
    # renders as 59.45 px of ink per unit length): compare with the ink area per length
    fg, mask = band_graph(width_px, np.pi / 4, seed=width_px)
    w = stack_widths_px(fg, ndimage.distance_transform_edt(mask), junction_margin_px=10)
    assert abs(w[0] - mask.sum() / 260) < 0.5
    for k, theta in enumerate(rng.uniform(0.1, 0.7, 2)):  # from a real skeleton too
        fg, mask = band_graph(width_px, theta, seed=k, skeleton=True)
        w = stack_widths_px(fg, ndimage.distance_transform_edt(mask), junction_margin_px=10)
        errs.append(w[0] - width_px)
    assert np.max(np.abs(errs)) < 0.5, errs


def test_naive_edt_reading_is_biased_ours_is_not():
    """The measurement behind the estimator: 2*EDT at the skeleton is off by up to 1.4 px
    depending on angle and parity; the 0.5-crossing width is not."""
    naive, ours = [], []
    for k, theta in enumerate(np.linspace(0.05, 1.5, 5)):
        fg, mask = band_graph(20, theta, seed=k)
        d = ndimage.distance_transform_edt(mask)
        p = fg.paths[0][40:-40]
        naive.append(np.median(2 * d[p[:, 0], p[:, 1]] - 1) - 20)
        ours.append(np.median(path_width_profile_px(p, d)) - 20)
    assert np.max(np.abs(naive)) > 0.5
    assert np.max(np.abs(ours)) < 0.4


@pytest.mark.parametrize("width_px,radius", [(5, 60), (12, 80), (30, 100)])
def test_ring_loop_width(width_px, radius):
    size = 2 * radius + 2 * width_px + 10
    rr, cc = np.mgrid[:size, :size]
    c = size / 2 + 0.3
    r = np.hypot(rr - c, cc - c)
    mask = np.abs(r - radius) <= width_px / 2
    pr, pc = circle_perimeter(int(round(c)), int(round(c)), radius, shape=mask.shape)
    order = np.argsort(np.arctan2(pr - c, pc - c))
    path = np.column_stack([pr, pc])[order]
    G = nx.MultiGraph()
    G.add_edge(0, 0, stack_id=0)
    fg = NetworkGraph(G, {0: path[0].astype(float)}, {0: "loop"}, [path], [(0, 0)])
    w = stack_widths(fg, ndimage.distance_transform_edt(mask), px_per_mm=50,
                     junction_margin_px=10)
    assert abs(w[0] * 50 - width_px) < 0.5


def test_junction_margin_excludes_blob_and_short_stack_fallback():
    fg, mask = band_graph(10, 0.3, length=200)
    blob = np.zeros_like(mask)
    p0 = fg.paths[0][0]
    rr, cc = np.mgrid[:mask.shape[0], :mask.shape[1]]
    blob = np.hypot(rr - p0[0], cc - p0[1]) < 20  # a thick junction blob at one end
    d = ndimage.distance_transform_edt(mask | blob)
    fg.node_kind = {0: "junction", 1: "end"}
    w = stack_widths_px(fg, d, junction_margin_px=25)
    assert abs(w[0] - 10) < 0.5
    w_nomargin = np.median(path_width_profile_px(fg.paths[0][:15], d))
    assert w_nomargin > 15  # the blob does inflate widths near the junction
    short = NetworkGraph(fg.graph, fg.node_rc, fg.node_kind, [fg.paths[0][90:100]], fg.ends)
    w = stack_widths_px(short, d, junction_margin_px=25)
    assert abs(w[0] - 10) < 0.6
    empty = NetworkGraph(fg.graph, fg.node_rc, fg.node_kind, [np.zeros((0, 2), int)], fg.ends)
    assert np.isnan(stack_widths_px(empty, d, junction_margin_px=5)[0])


def test_mean_width_statistic_follows_a_bump_the_median_ignores():
    """A band 10 px wide with a bump (a disc 30 px across) a quarter of the way along: the
    median ignores it, the mean of the same samples does not; on the plain band they agree."""
    fg, mask = band_graph(10, 0.3, length=200)
    d = ndimage.distance_transform_edt(mask)
    plain = {s: stack_widths_px(fg, d, junction_margin_px=5, statistic=s)[0]
             for s in ("median", "mean")}
    assert abs(plain["median"] - 10) < 0.5 and abs(plain["mean"] - plain["median"]) < 0.3
    p = fg.paths[0][len(fg.paths[0]) // 4]
    rr, cc = np.mgrid[:mask.shape[0], :mask.shape[1]]
    d = ndimage.distance_transform_edt(mask | (np.hypot(rr - p[0], cc - p[1]) < 15))
    bumped = {s: stack_widths_px(fg, d, junction_margin_px=5, statistic=s)[0]
              for s in ("median", "mean")}
    assert abs(bumped["median"] - 10) < 0.5
    assert bumped["mean"] > bumped["median"] + 1.0
    with pytest.raises(ParameterError, match="width statistic"):
        stack_widths_px(fg, d, junction_margin_px=5, statistic="mode")


# ------------------------------------------------------------------ calibration
def test_nonlinear_calibration_round_trip():
    h = 0.1
    n = np.arange(1, 31, dtype=float)
    cal = Calibration(tuple(n), tuple(h * n + 0.05 * np.sqrt(n)))
    np.testing.assert_allclose(cal.layers(cal.width(n)), n, atol=1e-9)
    x = np.random.default_rng(0).uniform(0.2, 45, 200)  # between rows and beyond the table
    np.testing.assert_allclose(cal.layers(cal.width(x)), x, atol=1e-9)
    # not linear: a linear calibration would misread a 20-layer stack by ~2 layers
    assert abs(Calibration.linear(h).layers(cal.width(20.0)) - 20) > 1.5
    assert np.all(np.diff(cal.width(np.linspace(0, 40, 500))) > 0)


def test_layers_bisects_the_interpolant_as_its_own_calls_do():
    """The compiled bisection evaluates the monotone interpolant as scipy does: the same
    counts, bit for bit, as 60 halvings on the interpolant's own calls, for widths between
    rows, on rows, a float beside a row, beyond the table, and not finite."""
    rng = np.random.default_rng(5)
    for it in range(200):
        h = float(rng.uniform(0.01, 0.3))
        if it % 2:
            cal = Calibration.nonlinear(h, int(rng.integers(3, 60)))
        else:
            n = np.unique(rng.integers(1, 80, int(rng.integers(3, 15)))).astype(float)
            if len(n) < 3:
                continue
            cal = Calibration(tuple(n), tuple(np.cumsum(rng.uniform(0.01, 0.5, len(n)))))
        tn, tw, interp = cal._interp
        y = np.r_[rng.uniform(-0.1, 1.2 * tw[-1], 300), tw, np.nextafter(tw, np.inf),
                  np.nextafter(tw, -np.inf), np.nan, np.inf, -np.inf]
        yc = np.clip(y, tw[0], tw[-1])
        k = np.clip(np.searchsorted(tw, yc, side="right") - 1, 0, len(tw) - 2)
        a, b = tn[k].copy(), tn[k + 1].copy()
        for _ in range(60):
            m = 0.5 * (a + b)
            below = interp(m) < yc
            a, b = np.where(below, m, a), np.where(below, b, m)
        got = cal.layers(y)
        inside = (y >= tw[0]) & (y <= tw[-1])
        assert np.array_equal(got[inside], (0.5 * (a + b))[inside])
        assert np.isnan(got[np.isnan(y)]).all()
        assert cal.layers(float(y[0])) == got[0]
        # any shape, in any memory order, as numpy's own elementwise calls
        grid = y[:300].reshape(20, 15)
        assert np.array_equal(cal.layers(grid), got[:300].reshape(20, 15), equal_nan=True)
        assert np.array_equal(cal.layers(np.asfortranarray(grid)), cal.layers(grid),
                              equal_nan=True)
        assert cal.layers(np.zeros((0, 2))).shape == (0, 2)
        assert cal.layers(grid.tolist()).shape == (20, 15)


def test_sparse_table_is_monotone_and_inverse():
    cal = Calibration((1, 2, 5, 10, 20), (0.13, 0.24, 0.58, 1.12, 2.3))
    x = np.linspace(0.3, 25, 300)
    w = cal.width(x)
    assert np.all(np.diff(w) > 0)
    np.testing.assert_allclose(cal.layers(w), x, atol=1e-9)
    assert cal.layers(0.24) == pytest.approx(2.0)


def test_linear_calibration():
    cal = Calibration.linear(0.1, n_max=10)
    np.testing.assert_allclose(cal.layers([0.1, 0.25, 1.5]), [1, 2.5, 15])
    assert cal.width(4) == pytest.approx(0.4)
    assert np.isnan(cal.layers(np.nan))
    with pytest.raises(ConfigError):
        Calibration.linear(0.0)


def test_from_csv_ok_and_errors(tmp_path):
    good = tmp_path / "cal.csv"
    good.write_text("n_layers,width_mm\n1,0.12\n2,0.23\n3,0.35\n5,0.56\n")
    cal = Calibration.from_csv(good)
    assert cal.layers(0.35) == pytest.approx(3.0)
    assert cal.source == str(good)
    bad = {
        "decreasing.csv": "n_layers,width_mm\n1,0.2\n2,0.1\n",
        "negative.csv": "n_layers,width_mm\n1,-0.1\n2,0.2\n",
        "columns.csv": "n,w\n1,0.1\n",
        "text.csv": "n_layers,width_mm\none,0.1\n",
        "empty.csv": "",
    }
    for name, text in bad.items():
        p = tmp_path / name
        p.write_text(text)
        with pytest.raises(ConfigError) as ei:
            Calibration.from_csv(p)
        assert name in ei.value.one_line()
    with pytest.raises(ConfigError) as ei:
        Calibration.from_csv(tmp_path / "missing.csv")
    assert "missing.csv" in ei.value.one_line()


def test_fractional_layer_counts_are_refused_naming_the_row(tmp_path):
    p = tmp_path / "half.csv"
    p.write_text("# measured on the test sheet\nn_layers,width_mm\n1,0.14\n1.5,0.2\n2,0.26\n")
    with pytest.raises(ConfigError) as ei:
        Calibration.from_csv(p)
    assert ei.value.one_line() == (f"{p}: calibration n_layers = 1.5 (row 2 of the table, "
                                   "below its header) is not a whole number of layers")
    with pytest.raises(ConfigError, match="row 1 of the table"):
        Calibration((0.5, 1, 2), (0.05, 0.1, 0.2))


def test_the_cli_refuses_fractional_layer_counts_in_one_line(tmp_path, capsys):
    from crosssection.cli import main
    from crosssection.samples import samples_path

    cal = tmp_path / "cal.csv"
    cal.write_text("n_layers,width_mm\n1,0.14\n1.5,0.2\n2,0.26\n3,0.37\n")
    assert main(["analyze", str(samples_path() / "scan_05_16bit.tif"), "--calibration",
                 str(cal), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {cal}: ") and "row 2" in err[0]


def test_single_row_is_proportional():
    cal = Calibration((1,), (0.12,))
    np.testing.assert_allclose(cal.layers([0.06, 0.24]), [0.5, 2.0])


# ---- a per-stack map_coordinates implementation, the reference of the numba kernel
# (same numbers, ~100x slower on a 2000^2 scan)
def _ref_unit_normals(path: np.ndarray, half_window: int = 3) -> np.ndarray:
    """Unit normals (row, col) of a pixel path from central differences over a window."""
    p = path.astype(float)
    n = len(p)
    if n < 2:
        return np.tile([1.0, 0.0], (n, 1))
    idx = np.arange(n)
    lo = np.clip(idx - half_window, 0, n - 1)
    hi = np.clip(idx + half_window, 0, n - 1)
    t = p[hi] - p[lo]
    norm = np.hypot(t[:, 0], t[:, 1])
    norm[norm == 0] = 1.0
    t /= norm[:, None]
    return np.column_stack([-t[:, 1], t[:, 0]])


def _reference_profile(path_rc: np.ndarray, distance_px: np.ndarray, *,
                          step_px: float = 0.25, normal_half_window: int | None = None
                          ) -> np.ndarray:
    """``path_width_profile_px`` by ``map_coordinates`` along each normal (same contract)."""
    path = np.asarray(path_rc).reshape(-1, 2).astype(int)
    if len(path) == 0:
        return np.zeros(0)
    dist = np.asarray(distance_px, dtype=float)
    d_centre = dist[path[:, 0], path[:, 1]]
    if normal_half_window is None:
        normal_half_window = int(np.clip(np.median(d_centre), 3, 15))
    nrm = _ref_unit_normals(path, normal_half_window)
    reach = float(np.max(d_centre)) + 2.0
    t = np.arange(-np.ceil(reach / step_px), np.ceil(reach / step_px) + 1) * step_px
    c0 = len(t) // 2
    pts = path[:, None, :].astype(float) + t[None, :, None] * nrm[:, None, :]
    mask = (dist > 0).astype(float)
    vals = ndimage.map_coordinates(mask, pts.reshape(-1, 2).T, order=1, mode="constant",
                                   cval=0.0).reshape(len(path), len(t))
    vals[np.abs(t)[None, :] > (d_centre[:, None] + 2.0)] = 0.0  # stay near this band
    inside = vals >= 0.5
    inside[:, c0] = True
    rows = np.arange(len(path))
    # right crossing: first outside sample after the centre
    right_out = ~inside[:, c0:]
    jr = np.where(right_out.any(axis=1), np.argmax(right_out, axis=1), right_out.shape[1] - 1)
    jr = c0 + np.maximum(jr, 1)
    left_out = ~inside[:, : c0 + 1][:, ::-1]
    jl = np.where(left_out.any(axis=1), np.argmax(left_out, axis=1), left_out.shape[1] - 1)
    jl = c0 - np.maximum(jl, 1)

    def crossing(j_in, j_out):
        a, b = vals[rows, j_in], vals[rows, j_out]
        frac = np.where(a - b > 1e-12, (a - 0.5) / np.maximum(a - b, 1e-12), 0.0)
        return t[j_in] + frac * (t[j_out] - t[j_in])

    return crossing(jr - 1, jr) - crossing(jl + 1, jl)


@pytest.mark.parametrize("seed", range(3))
def test_numba_kernel_matches_map_coordinates_reference(seed):
    """Curved bands of random width with pinholes: the vectorised kernel gives the values of
    the straightforward per-path ``map_coordinates`` version at every path pixel."""
    rng = np.random.default_rng(seed)
    size = 220
    rr, cc = np.mgrid[:size, :size].astype(float)
    radius = rng.uniform(50, 90)
    width = rng.uniform(4, 30)
    c0 = size / 2 + rng.uniform(-3, 3, 2)
    mask = np.abs(np.hypot(rr - c0[0], cc - c0[1]) - radius) <= width / 2
    mask[rng.integers(0, size, 30), rng.integers(0, size, 30)] = False  # pinholes
    d = ndimage.distance_transform_edt(mask)
    ang = np.linspace(0.2, 5.5, 400)
    path = np.unique(np.round(np.column_stack([c0[0] + radius * np.sin(ang),
                                               c0[1] + radius * np.cos(ang)])).astype(int),
                     axis=0)
    path = path[np.argsort(np.arctan2(path[:, 0] - c0[0], path[:, 1] - c0[1]) % (2 * np.pi))]
    path = path[mask[path[:, 0], path[:, 1]]]
    for dist in (d, d.astype(np.float32)):
        np.testing.assert_allclose(path_width_profile_px(path, dist),
                                   _reference_profile(path, dist.astype(float)), atol=1e-6)


def test_segment_medians_are_numpy_medians_of_each_run():
    """The compiled per-run selection gives ``np.median`` of every segment bit for bit (odd
    and even lengths, short and long runs, ties, empty segments: NaN)."""
    from crosssection.stages.widths import _segment_medians

    rng = np.random.default_rng(5)
    for trial in range(300):
        lens = rng.integers(0, 14 if trial % 3 else 400, int(rng.integers(1, 30)))
        lens[rng.random(len(lens)) < 0.2] = 0
        seg = np.repeat(np.arange(len(lens)), lens)
        values = rng.uniform(0, 40, len(seg))
        if trial % 2:  # few distinct values: ties at the middle
            values = rng.choice(values[:3], len(seg)) if len(seg) >= 3 else values
        got = _segment_medians(values, seg, len(lens))
        want = np.array([np.median(values[seg == k]) if n else np.nan
                         for k, n in enumerate(lens)])
        np.testing.assert_array_equal(got, want)
