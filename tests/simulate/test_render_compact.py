"""Renders that look like scans (simulate.render): the wall is the hole, the thickness sets the
scale, scan defects by default, ``--clean`` for the clean drawing, one-line CLI errors."""
import json
from pathlib import Path

import numpy as np
import pytest

from crosssection.core.errors import ParameterError
from crosssection.truth.scene import read_scene
from simulate.cli import main
from simulate.contacts import analyze_rod
from simulate.render import CLEAN, SCAN_DEFECTS, render_configuration, render_directory
from simulate.shapes import resample, spiral, transform

PX_PER_MM = 20.0  # h = 2 px: small images, fast tests
# below the validated sheet thickness on purpose (these tests check the drawing, not the
# analysis of it): the warning saying so is tested with the render command line
pytestmark = [pytest.mark.filterwarnings("ignore::simulate.render.ScanRangeWarning"),
              # the truth checks (test_render_truth.py) are not what is tested here
              pytest.mark.filterwarnings("ignore::simulate.render.TruthWarning")]


@pytest.fixture(scope="module")
def compact_dir(tmp_path_factory):
    """One rod compacted to epsilon = 3 (200 segments): a compaction's output folder."""
    out = tmp_path_factory.mktemp("compact") / "sim"
    assert main(["compact", "--epsilon", "3", "--segments", "200", "--n-configs", "1",
                 "--seed", "2", "--out", str(out), "--no-progress"]) == 0
    return out


@pytest.fixture(scope="module")
def compact_scenes(compact_dir, tmp_path_factory):
    """The compaction rendered with the defaults and with --clean."""
    base = tmp_path_factory.mktemp("scenes")
    out = {}
    for name, flags in (("scan", []), ("clean", ["--clean"])):
        assert main(["render", str(compact_dir), "--out", str(base / name), "--px-per-mm",
                     str(PX_PER_MM), "--seed", "5", *flags]) == 0
        out[name] = read_scene(base / name / "config_00000")
    return out


def test_hole_is_the_wall_and_thickness_sets_the_scale(compact_dir, compact_scenes):
    p = json.loads((compact_dir / "params.json").read_text())
    xy = np.load(compact_dir / "rods.npz")["config_00000"]
    sc = compact_scenes["clean"]
    q = sc.params
    # h of the rod is the sheet's 0.1 mm: L = h_mm / h_L, R = wall_radius L
    assert q["rod_length_mm"] == pytest.approx(0.1 / p["thickness"], rel=1e-12)
    assert q["hole_radius_mm"] == pytest.approx(p["wall_radius"] * q["rod_length_mm"], rel=1e-12)
    assert sc.summary["epsilon"] == pytest.approx(3.0, rel=1e-9)
    # the hole is centred on the wall's centre, the origin of the rod's coordinates
    origin_px = (np.zeros(2) - np.array(q["origin_xy"])) * q["rod_length_mm"] * PX_PER_MM \
        + q["margin_px"]
    assert np.allclose(q["hole_center_px"], origin_px)
    # every node lies within R - h/2 of the wall centre: in pixels, inside the drawn hole
    nodes_px = (xy - np.array(q["origin_xy"])) * q["rod_length_mm"] * PX_PER_MM + q["margin_px"]
    r = np.hypot(*(nodes_px - np.array(q["hole_center_px"])).T)
    h_px = 0.1 * PX_PER_MM
    assert r.max() <= q["hole_radius_mm"] * PX_PER_MM - 0.5 * h_px + 1e-6
    # and the rod, pressed against the wall, reaches it (within a thickness)
    assert r.max() >= q["hole_radius_mm"] * PX_PER_MM - 1.5 * h_px
    # a hard wall stores no energy: the analysis ran with lambda = 0
    assert sc.tables["branches"]["energy_confinement"].abs().max() == 0.0
    assert sc.summary["total_energy"] == pytest.approx(
        analyze_rod(xy, lam=0.0, contact_distance=p["contact_distance"]).energy_bending)


def test_defaults_degrade_and_clean_does_not(compact_scenes):
    scan, clean = compact_scenes["scan"], compact_scenes["clean"]
    # same drawing and truth, different pixels
    for t in ("junctions", "stacks", "voids"):
        assert scan.tables[t].equals(clean.tables[t]), t
    for k, v in SCAN_DEFECTS.items():
        assert scan.params[k] == v, k
    for k, v in CLEAN.items():
        assert clean.params[k] == v, k
    rgb_s, rgb_c = scan.rgb.astype(float), clean.rgb.astype(float)
    h, w = rgb_c.shape[:2]
    cx, cy = scan.params["hole_center_px"]
    rr, cc = np.mgrid[0:h, 0:w]
    d = np.hypot(rr - cy, cc - cx)
    ring = d > scan.params["hole_radius_mm"] * PX_PER_MM + 6
    # outside the hole: white paper in the clean drawing, the grey plate in the scan
    assert rgb_c[ring].mean() > 220
    assert abs(rgb_s[ring].mean() - np.mean([128.0, 125.0, 120.0])) < 25
    # the commonest colour inside the hole (a void's receding surface): one flat colour in
    # the clean drawing, noisy in the scan
    inside = d < scan.params["hole_radius_mm"] * PX_PER_MM - 4
    colours, counts = np.unique(clean.rgb[inside].reshape(-1, 3), axis=0, return_counts=True)
    flat = inside & (clean.rgb == colours[np.argmax(counts)]).all(axis=2)
    assert flat.sum() > 1000
    assert rgb_s[flat].std(axis=0).min() > 2.0


def test_clean_is_the_drawing_without_defects():
    """clean=True is the same scene as every defect set to none by hand, and an explicit
    defect still applies on top of clean."""
    rng = np.random.default_rng(0)
    xy = transform(resample(spiral(3, 0.7 * 0.5 / 300)), rng)
    a = analyze_rod(xy, lam=7e5)
    clean = render_configuration(xy, a, seed=3, clean=True, hole_radius_mm="auto")
    by_hand = render_configuration(xy, a, seed=3, hole_radius_mm="auto",
                                   **{**CLEAN, "jpeg_quality": 0, "plate": "none"})
    assert np.array_equal(clean.rgb, by_hand.rgb)
    noisy = render_configuration(xy, a, seed=3, clean=True, hole_radius_mm="auto",
                                 noise_sigma=8.0)
    assert not np.array_equal(clean.rgb, noisy.rgb)
    assert noisy.params["noise_sigma"] == 8.0 and noisy.params["plate"] is None
    # without a hole the default plate has nothing to frame: none, and no error
    no_hole = render_configuration(xy, a, seed=3)
    assert no_hole.params["plate"] is None and no_hole.params["noise_sigma"] > 0


def test_smooth_none_draws_the_polylines():
    rng = np.random.default_rng(1)
    xy = transform(resample(spiral(3, 0.7 * 0.5 / 300)), rng)
    a = analyze_rod(xy, lam=7e5)
    poly = render_configuration(xy, a, seed=3, clean=True, smooth="none")
    smooth = render_configuration(xy, a, seed=3, clean=True)
    # the polyline paths are the analysis' lines in pixels; the smooth ones are resampled
    assert sum(len(p) for p in poly.paths_rc) == sum(len(line) for line in a.stack_lines)
    assert sum(len(p) for p in smooth.paths_rc) != sum(len(p) for p in poly.paths_rc)
    assert poly.summary["total_energy"] == smooth.summary["total_energy"]
    with pytest.raises(ParameterError, match="smooth"):
        render_configuration(xy, a, smooth=True)


def test_short_links_are_smoothed():
    """A link shorter than two segments with hooks to its junctions (a Z): kept as it is by
    default, a parabola through its ends and middle with ``short``."""
    from simulate.render import smooth_line

    z = np.array([[0.0, 0.0], [2.0, 10.0], [2.5, 20.0], [12.0, 21.0], [13.0, 30.0],
                  [15.0, 40.0]])
    assert np.array_equal(smooth_line(z, knot_spacing_px=60.0), z)
    curve = smooth_line(z, knot_spacing_px=60.0, short=True)
    assert np.allclose(curve[0], z[0]) and np.allclose(curve[-1], z[-1])
    d = np.diff(curve, axis=0)
    turn = np.abs(np.diff(np.unwrap(np.arctan2(d[:, 1], d[:, 0]))))
    d0 = np.diff(z, axis=0)
    corner = np.abs(np.diff(np.unwrap(np.arctan2(d0[:, 1], d0[:, 0])))).max()
    # no corner left: the largest turn per pixel step is a small fraction of the Z's corners
    assert turn.max() < 0.1 * corner
    # a parabola turns one way only
    cross = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
    assert np.all(cross >= -1e-9) or np.all(cross <= 1e-9)


@pytest.mark.parametrize("flags, names", [
    (["--noise", "-1"], "--noise"),
    (["--blur", "nan"], "--blur"),
    (["--jpeg", "101"], "--jpeg"),
    (["--jpeg", "-1"], "--jpeg"),
    (["--jpeg", "high"], "--jpeg"),
    (["--smears", "-2"], "--smears"),
    (["--plate", "purple"], "plate"),
    (["--illumination", "1.5"], "--illumination"),
    (["--plate", "grey", "--hole", "none"], "plate"),
    (["--px-per-mm", "0"], "--px-per-mm"),
    (["--smooth", "some"], "--smooth"),
    (["--join", "bridge"], "--join"),
])
def test_bad_options_exit_2_with_one_line(compact_dir, tmp_path, capsys, flags, names):
    try:
        status = main(["render", str(compact_dir), "--out", str(tmp_path / "s"), *flags])
    except SystemExit as exc:  # argparse's own checks (a value of the wrong type)
        status = exc.code
    err = capsys.readouterr().err
    assert status == 2
    assert len(err.strip().splitlines()) == 1 and err.startswith("error:"), err
    assert names in err and "Traceback" not in err
    assert not (tmp_path / "s").exists()


def test_bad_compaction_params_exit_2_naming_the_file(compact_dir, tmp_path, capsys):
    sim = tmp_path / "sim"
    sim.mkdir()
    (sim / "rods.npz").write_bytes((compact_dir / "rods.npz").read_bytes())
    p = json.loads((compact_dir / "params.json").read_text())
    p["thickness"] = -1.0
    (sim / "params.json").write_text(json.dumps(p))
    assert main(["render", str(sim), "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert "params.json" in err and "thickness" in err


def test_render_directory_api_checks_options_first(compact_dir, tmp_path):
    with pytest.raises(ParameterError, match="jpeg_quality"):
        render_directory(compact_dir, tmp_path / "s", jpeg_quality=500)
    assert not (tmp_path / "s").exists()


def test_no_ink_beyond_the_wall(compact_dir):
    """The wall is the hole: bands pressed against it end there. The same drawing around an
    explicit hole of the same radius (not the wall) pokes out of it."""
    p = json.loads((compact_dir / "params.json").read_text())
    xy = np.load(compact_dir / "rods.npz")["config_00000"]
    an = analyze_rod(xy, lam=0.0, contact_distance=p["contact_distance"])
    # h = 5 px: a one-layer band against the wall, drawn around its own line, pokes out by
    # 0.2 h (w(1) = 1.4 h), a pixel at this scale
    px_per_mm = 50.0
    kw = dict(px_per_mm=px_per_mm, clean=True, rod_thickness=p["thickness"],
              wall_radius=p["wall_radius"])
    wall = render_configuration(xy, an, hole_radius_mm="auto", **kw)
    free = render_configuration(xy, an, hole_radius_mm=wall.params["hole_radius_mm"], **kw)
    beyond = []
    for sc in (wall, free):
        cx, cy = sc.params["hole_center_px"]
        rr, cc = np.nonzero(sc.ink_mask)
        beyond.append(np.hypot(rr - cy, cc - cx).max()
                      - sc.params["hole_radius_mm"] * px_per_mm)
    # pixel centres of anti-aliased ink reach at most about half a pixel past the edge
    assert beyond[0] <= 0.75
    assert beyond[1] > 1.0


def test_render_directory_api_takes_the_wall_by_default(compact_dir, tmp_path):
    p = json.loads((compact_dir / "params.json").read_text())
    (folder,) = render_directory(compact_dir, tmp_path / "s", px_per_mm=PX_PER_MM, clean=True)
    q = json.loads((folder / "params.json").read_text())
    assert q["hole_radius_mm"] == pytest.approx(p["wall_radius"] * 0.1 / p["thickness"])
    (none,) = render_directory(compact_dir, tmp_path / "n", px_per_mm=PX_PER_MM, clean=True,
                               hole_radius_mm=None)
    assert json.loads((none / "params.json").read_text())["hole_radius_mm"] is None


def _drawn_energy(scene, rod_length_px: float) -> float:
    """``L sum n_br int kappa^2 ds`` of the drawn centrelines (turning angles at 1 px)."""
    total = 0.0
    for path, n in zip(scene.paths_rc, scene.tables["stacks"]["n_br"]):
        p = np.asarray(path, float)
        if len(p) < 3:
            continue
        u = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p, axis=0).T))]
        q = np.c_[np.interp(np.arange(0.0, u[-1], 1.0), u, p[:, 0]),
                  np.interp(np.arange(0.0, u[-1], 1.0), u, p[:, 1])]
        if len(q) < 3:
            continue
        d = np.diff(q, axis=0)
        total += n * rod_length_px * float(np.sum(np.diff(np.unwrap(np.arctan2(*d.T))) ** 2))
    return total


def _compacted(tmp_path, epsilon: float):
    """A rod of 400 segments compacted to ``epsilon`` (seed 2), its contact analysis, its
    energy and the render keywords of a clean scan of it."""
    out = tmp_path / "sim"
    assert main(["compact", "--epsilon", str(epsilon), "--segments", "400", "--n-configs", "1",
                 "--seed", "2", "--out", str(out), "--no-progress"]) == 0
    p = json.loads((out / "params.json").read_text())
    xy = np.load(out / "rods.npz")["config_00000"]
    a = analyze_rod(xy, lam=0.0, contact_distance=p["contact_distance"])
    kw = dict(px_per_mm=PX_PER_MM, rod_thickness=p["thickness"], wall_radius=p["wall_radius"],
              hole_radius_mm="auto", clean=True, seed=1)
    return xy, a, float(a.branches["energy_bending"].sum()), kw


def test_hooked_bands_bend_as_the_rod_and_stay_connected(tmp_path):
    """At epsilon = 8 the analysis' lines hooked into junction points at a band's side bend
    tens to hundreds of times more than the rod (the bound is loose: a compaction is chaotic,
    and this seed's rod moves with the numerical libraries' last bits); the bands joined
    along their own lines (the default for a compacted rod) bend about as much as it, and the
    drawing stays one piece."""
    import cv2

    xy, a, rod, kw = _compacted(tmp_path, 8)
    scenes = {join: render_configuration(xy, a, join=join, **kw) for join in ("hook", "junction")}
    default = render_configuration(xy, a, **kw)
    assert default.params["join"] == "hook"
    assert np.array_equal(default.rgb, scenes["hook"].rgb)
    length_px = scenes["hook"].params["rod_length_mm"] * PX_PER_MM
    hook, junction = (_drawn_energy(scenes[j], length_px) for j in ("hook", "junction"))
    assert junction > 10 * rod
    assert 0.3 * rod < hook < 3 * rod
    for join in ("hook", "junction"):
        rgb = scenes[join].rgb.astype(int)
        ink = ((rgb[..., 2] - rgb[..., 0] > 40) & (rgb[..., 2] > 100)).astype(np.uint8)
        n_parts = cv2.connectedComponents(ink, connectivity=8)[0] - 1
        assert n_parts == 1, join
    with pytest.raises(ParameterError, match="join"):
        render_configuration(xy, a, join="bridge", **kw)


def test_a_junction_beside_a_band_is_looked_for_near_its_end():
    """A stack leaving its junction and passing by it again further on (a teardrop) is joined
    at its end, not cut where it passes by; a junction point beside the band near its end is
    joined where the band passes it."""
    from simulate.render import _beside

    # out along y = 0, round a half circle, back along y = -40 past the start
    t = np.linspace(0.0, np.pi, 60)
    loop = np.concatenate([np.c_[np.linspace(0.0, 400.0, 201), np.zeros(201)],
                           np.c_[400.0 + 20.0 * np.sin(t), -20.0 + 20.0 * np.cos(t)][1:],
                           np.c_[np.linspace(400.0, -100.0, 251), np.full(251, -40.0)][1:]])
    jp = np.array([-20.0, -30.0])  # 36 px from the start, 10 px from the way back
    out, hooked = _beside(loop, jp, 0, 2.0, reach_px=60.0)
    assert hooked and len(out) == len(loop)
    line = np.c_[np.linspace(0.0, 400.0, 201), np.zeros(201)]
    out, hooked = _beside(line, np.array([40.0, 20.0]), 0, 2.0, reach_px=60.0)
    assert hooked and np.allclose(out[0], [40.0, 0.0])  # cut where it passes the point
    out, hooked = _beside(line, np.array([40.0, 1.0]), 0, 2.0, reach_px=60.0)
    assert not hooked and len(out) == len(line)  # the band covers the point


def test_junction_points_across_the_paper_are_not_joined(tmp_path, monkeypatch):
    """At low compaction a junction point (the mean of run ends lying far apart) can sit
    tens of band widths from where the stacks' passes end: joined to it, the bands would
    cross the paper and bend 80 times more than the rod; left free they bend about as it."""
    import simulate.render as render

    xy, a, rod, kw = _compacted(tmp_path, 6)
    kept = render_configuration(xy, a, **kw)
    length_px = kept.params["rod_length_mm"] * PX_PER_MM
    monkeypatch.setattr(render, "PAPER_JOIN", np.inf)
    joined = render_configuration(xy, a, **kw)
    assert _drawn_energy(kept, length_px) < 3 * rod
    assert _drawn_energy(joined, length_px) > 20 * rod


def test_paper_crossed_by_a_join():
    """The length of a straight join outside every band: none inside a band, the gap between
    two bands when it crosses one, all of it on bare paper."""
    from simulate.render import _distance_to_line, _paper_px

    line = np.c_[np.linspace(0.0, 100.0, 11), np.zeros(11)]
    assert np.allclose(_distance_to_line(np.array([[50.0, 7.0], [-3.0, 4.0], [130.0, 0.0]]),
                                         line), [7.0, 5.0, 30.0])
    left = (line, 5.0)
    right = (line + [0.0, 40.0], 5.0)
    start, end = np.array([50.0, 0.0]), np.array([50.0, 40.0])
    assert _paper_px(np.array([10.0, 0.0]), np.array([90.0, 2.0]), [left]) == 0.0
    # 40 px between the two lines, 6 px of each covered (half width 5 px + 1 px)
    assert abs(_paper_px(start, end, [left, right]) - 28.0) <= 2.0
    assert _paper_px(start, end, []) == 40.0


def test_a_junction_point_reached_by_one_band_is_not_joined():
    """Hooks are kept only at junction points that two band ends or more still reach."""
    from simulate.render import _joined_hooks

    ends = np.array([[0, 1], [1, 2], [2, -1], [3, 3]])
    hooks = [[True, True], [False, True], [True, False], [True, True]]
    # junction 0 and junction 1 are reached by one end each; 2 by two; the loop's two ends
    # meet at its own junction 3
    assert _joined_hooks(hooks, ends) == [[False, False], [False, True], [True, False],
                                          [True, True]]


def test_a_lone_hook_would_curl_a_band_end(monkeypatch):
    """A quenched rod (``simulate.atlas.quench_rod(5)``, stored: a quench is chaotic and its
    rod moves with the numerical libraries' last bits) holds a junction whose other bands end
    across the paper: the one band still joined there curled into the point, and the drawn
    lines bent 47 times the rod; ending on its own it bends 1.8 times the rod (the rest: fold
    caps and hooks)."""
    import simulate.render as render
    from simulate.atlas import render_rod

    xy = np.load(Path(__file__).parent / "data" / "quench_rod_5.npy")
    kept = render_rod(xy, 5)
    length_px = kept.params["rod_length_mm"] * kept.params["px_per_mm"]
    rod = float(kept.summary["total_energy"])
    monkeypatch.setattr(render, "_joined_hooks", lambda hooks, ends: hooks)
    joined = render_rod(xy, 5)
    assert _drawn_energy(kept, length_px) < 3 * rod
    assert _drawn_energy(joined, length_px) > 8 * rod
