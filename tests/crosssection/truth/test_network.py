"""The synthetic scene generator: exact, physically consistent truth and a faithful image."""
import json

import cv2
import numpy as np
import pandas as pd
import pytest

from crosssection.core import schema
from crosssection.core.calibration import Calibration
from crosssection.core.errors import ParameterError
from crosssection.truth.network import make_scene
from crosssection.truth.scene import write_scene

SEEDS = [0, 7, 23]


@pytest.fixture(scope="module", params=[(s, n, L) for s, n, L in
                                        [(0, 25, 12), (7, 60, 6), (23, 110, 3)]],
                ids=lambda p: f"seed{p[0]}-n{p[1]}-L{p[2]}")
def scene(request):
    seed, n, L = request.param
    return make_scene(seed=seed, n_stacks=n, max_layers=L, mean_layers=max(1.5, L / 2.5))


def _mask(rgb):
    r, g, b = (rgb[..., i].astype(int) for i in range(3))
    return (b >= 100) & (r <= 130) & (g <= 130)


def test_pack_conservation_exact(scene):
    n = scene.tables["stacks"]["n_br"].to_numpy()
    assert (n >= 1).all()
    assert n.max() <= scene.params["options"]["max_layers"]
    assert len(scene.packs) == len(scene.tables["junctions"])
    for A, B in scene.packs:
        assert A and B
        assert n[A].sum() == n[B].sum()


def test_junction_degrees_match_stacks(scene):
    j = scene.tables["junctions"]
    st = scene.tables["stacks"]
    deg = np.bincount(np.concatenate([st["junction_a"], st["junction_b"]]), minlength=len(j))
    assert (deg == j["n_stacks"].to_numpy()).all()
    assert set(np.unique(deg)) <= {3, 4}
    assert (deg == 4).mean() <= 0.06  # paper: ~1 % crossings


def test_void_sides_are_the_faces_of_the_network(scene):
    """Every void is a face of the planar network: its junctions are those of the stacks
    around it, so each interior stack is counted by its two faces and each wall stack by one."""
    st = scene.tables["stacks"]
    expected = 2 * int((~st["wall"]).sum()) + int(st["wall"].sum())
    assert int(scene.tables["voids"]["n_edges"].sum()) == expected
    assert (scene.tables["voids"]["n_edges"] >= 2).all()


def test_stack_mid_points_halve_the_centrelines(scene):
    """The mid point of stacks.csv is half-way along the truth centreline (scoring matches
    stacks by it): the two halves of the centreline have equal lengths."""
    st = scene.tables["stacks"]
    for k, path in enumerate(scene.paths_rc):
        mid = np.array([st["mid_y_px"][k], st["mid_x_px"][k]])
        seg = np.hypot(*np.diff(path, axis=0).T)
        s = np.concatenate([[0], np.cumsum(seg)])
        i = int(np.argmin(np.hypot(*(path - mid).T)))
        assert abs(s[i] - s[-1] / 2) <= 1.0 + 1e-9  # samples are at most 1 px apart
        assert st["length_mm"][k] == pytest.approx(s[-1] / 50.0)


def test_summary_consistent_with_tables(scene):
    s, t = scene.summary, scene.tables
    assert set(schema.SUMMARY_KEYS) <= set(s)
    L = float((t["stacks"]["n_br"] * t["stacks"]["length_mm"]).sum())
    assert s["rod_length_mm"] == pytest.approx(L)
    assert s["n_branches"] == t["stacks"]["n_br"].sum() == len(t["branches"])
    R_mm = s["hole"]["radius_px"] / scene.params["px_per_mm"]
    assert s["epsilon"] == pytest.approx(L / (2 * np.pi * R_mm))
    assert s["total_energy"] == pytest.approx(t["branches"]["energy"].sum())
    # Euler: a connected planar network inside the disk has E - V + 1 bounded faces = voids
    assert s["n_voids"] == s["n_stacks"] - s["n_junctions"] + 1
    cal = scene.calibration
    assert np.allclose(t["stacks"]["width_mm"], cal.width(t["stacks"]["n_br"]), atol=0.021)


def test_threshold_mask_matches_truth(scene):
    """The default threshold separates ink from receding surfaces and paper; the mask encloses
    exactly the truth voids (no accidental contact, no broken band)."""
    m = _mask(scene.rgb).astype(np.uint8)
    inside = np.zeros_like(m)
    hole = scene.summary["hole"]
    cv2.circle(inside, (int(hole["center_x_px"]), int(hole["center_y_px"])),
               int(hole["radius_px"] - 2), 1, -1)
    bg = ((m == 0) & (inside > 0)).astype(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(bg, connectivity=4)
    s_min_px = (10 * 0.1 * 50) ** 2
    big = stats[1:, cv2.CC_STAT_AREA] >= s_min_px
    assert big.sum() == scene.summary["n_voids"]
    areas = np.sort(stats[1:, cv2.CC_STAT_AREA][big] / 50.0 ** 2)
    truth = np.sort(scene.tables["voids"]["area_mm2"].to_numpy())
    assert np.allclose(areas, truth, rtol=0.06)
    # one connected ink network
    nf, _ = cv2.connectedComponents(m, connectivity=8)
    assert nf - 1 == 1


def test_curvature_truth_against_finite_differences(scene):
    """kappa_plus of each stack agrees with a finite-difference estimate on its centreline."""
    st = scene.tables["stacks"]
    br = scene.tables["branches"].groupby("stack_id").first()
    errs = []
    for k, p in enumerate(scene.paths_rc):
        xy = p[:, ::-1]
        seg = np.hypot(*np.diff(xy, axis=0).T)
        s = np.concatenate([[0], np.cumsum(seg)])
        if s[-1] < 60 or st["wall"][k]:
            continue
        # resample uniformly and differentiate
        t = np.linspace(0, s[-1], 400)
        x, y = np.interp(t, s, xy[:, 0]), np.interp(t, s, xy[:, 1])
        dx, dy = np.gradient(x, t), np.gradient(y, t)
        ddx, ddy = np.gradient(dx, t), np.gradient(dy, t)
        kap = (dx * ddy - dy * ddx) / (dx * dx + dy * dy) ** 1.5 * 50.0
        kplus = np.trapezoid(np.abs(kap[3:-3]), t[3:-3]) / (t[-4] - t[3])
        if br.loc[k, "kappa_plus"] > 0.2:
            errs.append(abs(kplus / br.loc[k, "kappa_plus"] - 1))
    assert errs and np.median(errs) < 0.05


def test_wall_stacks_are_arcs_of_the_hole(scene):
    st = scene.tables["stacks"]
    br = scene.tables["branches"].groupby("stack_id").first()
    R = scene.summary["hole"]["radius_px"]
    wall = st[st["wall"]]
    assert len(wall) >= 3
    for k, row in wall.iterrows():
        expected = 50.0 / (R - row["width_mm"] * 50 / 2)
        assert br.loc[k, "kappa_plus"] == pytest.approx(expected, rel=0.08)
        assert row["region"] == "periphery"
    # bulk = no end on the wall
    jw = scene.tables["junctions"]["wall"].to_numpy()
    bulk = ~(jw[st["junction_a"]] | jw[st["junction_b"]])
    assert (st["region"][bulk] == "bulk").all()


@pytest.mark.parametrize("seed", SEEDS)
def test_deterministic_and_seed_dependent(seed):
    a = make_scene(seed=seed, n_stacks=20, max_layers=3)
    b = make_scene(seed=seed, n_stacks=20, max_layers=3)
    c = make_scene(seed=seed + 1, n_stacks=20, max_layers=3)
    assert np.array_equal(a.rgb, b.rgb)
    pd.testing.assert_frame_equal(a.tables["stacks"], b.tables["stacks"])
    assert a.rgb.shape != c.rgb.shape or not np.array_equal(a.rgb, c.rgb)


def test_degradations_change_image_not_truth():
    clean = make_scene(seed=5, n_stacks=30, max_layers=4)
    noisy = make_scene(seed=5, n_stacks=30, max_layers=4, noise_sigma=12, blur_px=1.0,
                       jpeg_quality=70, smears=6, specks=20, pinholes=10)
    pd.testing.assert_frame_equal(clean.tables["stacks"], noisy.tables["stacks"])
    assert clean.summary["rod_length_mm"] == noisy.summary["rod_length_mm"]
    diff = np.abs(clean.rgb.astype(int) - noisy.rgb.astype(int))
    assert diff.mean() > 3
    # the ink still thresholds to the same network (masks mostly agree)
    a, b = _mask(clean.rgb), _mask(noisy.rgb)
    assert (a & b).sum() / (a | b).sum() > 0.85


def test_custom_calibration_is_used():
    cal = Calibration.from_frame(pd.DataFrame({"n_layers": np.arange(1, 9),
                                               "width_mm": 0.1 * np.arange(1, 9) + 0.05}))
    sc = make_scene(seed=11, n_stacks=25, max_layers=5, calibration=cal)
    st = sc.tables["stacks"]
    assert np.allclose(st["width_mm"], 0.1 * st["n_br"] + 0.05, atol=0.021)
    assert sc.calibration is cal
    default = Calibration.nonlinear(0.1)
    n = np.arange(1, 13)
    w = default.width(n)
    assert np.all(np.diff(w) > 0.1 * 0.999)  # each layer adds at least h
    assert not np.allclose(w, 0.1 * n, atol=0.02)  # nonlinear (heating by the hot wire)


def test_write_scene_layout(tmp_path):
    sc = make_scene(seed=2, n_stacks=20, max_layers=4)
    folder = write_scene(sc, tmp_path / "scene")
    for name in ["image.png", "params.json", "calibration.csv", "truth/summary.json",
                 "truth/junctions.csv", "truth/stacks.csv", "truth/branches.csv", "truth/voids.csv"]:
        assert (folder / name).exists(), name
    params = json.loads((folder / "params.json").read_text())
    for key in ["px_per_mm", "thickness_mm", "hole_radius_mm", "hole_center_px", "seed",
                "rod_length_mm"]:
        assert key in params
    img = cv2.imread(str(folder / "image.png"))[..., ::-1]
    assert np.array_equal(img, sc.rgb)
    summary, tables = schema.read_tables(folder / "truth")
    assert summary["n_stacks"] == len(tables["stacks"]) == sc.summary["n_stacks"]
    cal = pd.read_csv(folder / "calibration.csv")
    assert list(cal.columns[:2]) == ["n_layers", "width_mm"]


def test_density_range():
    sparse = make_scene(seed=4, n_stacks=20, max_layers=4)
    dense = make_scene(seed=4, n_stacks=240, max_layers=3)
    assert 14 <= sparse.summary["n_stacks"] <= 30
    assert 190 <= dense.summary["n_stacks"] <= 290


def test_truth_junctions_sit_at_skeleton_branch_points(scene):
    """Convention check: the truth junction is the medial-axis branch point of the fork (the
    paper defines junctions on the skeleton), so a plain skimage skeleton of the clean mask
    branches within a few pixels of every truth junction."""
    from scipy import ndimage as ndi
    from scipy.spatial import cKDTree
    from skimage.morphology import skeletonize

    m = _mask(scene.rgb)
    m = m | ~_big_bg(m)  # fill background specks and pinholes smaller than s_min
    sk = skeletonize(m)
    nb = ndi.convolve(sk.astype(int), np.ones((3, 3), int), mode="constant") - 1
    jp = sk & (nb >= 3)
    lab, k = ndi.label(jp, np.ones((3, 3)))
    c = np.array(ndi.center_of_mass(jp, lab, range(1, k + 1)))[:, ::-1]
    t = scene.tables["junctions"][["x_px", "y_px"]].to_numpy()
    d, _ = cKDTree(c).query(t)
    assert np.mean(d <= 15) >= 0.97  # 3h
    assert np.median(d) < 4.0


def _big_bg(m, s_min_px=2500):
    """Background components of at least s_min_px (the voids kept by the paper's cleaning)."""
    from scipy import ndimage as ndi

    lab, n = ndi.label(~m)
    sizes = np.bincount(lab.ravel())
    keep = sizes >= s_min_px
    keep[0] = False
    return keep[lab]


def _pack_opening_deg(sc):
    """Per interior junction with a pack of two stacks, the angle between their departures."""
    st = sc.tables["stacks"]
    jt = sc.tables["junctions"]
    out = []
    for j, (a, b) in enumerate(sc.packs):
        if jt["wall"].iat[j]:
            continue
        for pack in (a, b):
            if len(pack) != 2:
                continue
            dirs = []
            for sid in pack:
                path = sc.paths_rc[sid]
                path = path if st["junction_a"].iat[sid] == j else path[::-1]
                d = path[1] - path[0]  # the Bezier leaves along its end tangent
                dirs.append(d / np.hypot(*d))
            out.append(np.degrees(np.arccos(np.clip(dirs[0] @ dirs[1], -1, 1))))
    return np.array(out)


def test_fan_angle_sets_the_fork_opening():
    default = make_scene(seed=2, n_stacks=20, max_layers=4)
    wide = make_scene(seed=2, n_stacks=20, max_layers=4, fan_deg=60.0)
    narrow = make_scene(seed=2, n_stacks=20, max_layers=4, fan_deg=30.0)
    # the default is the 60 degree fan, bit for bit
    assert np.array_equal(default.rgb, wide.rgb)
    np.testing.assert_allclose(np.median(_pack_opening_deg(wide)), 60.0, atol=2.0)
    np.testing.assert_allclose(np.median(_pack_opening_deg(narrow)), 30.0, atol=2.0)
    assert narrow.params["options"]["fan_deg"] == 30.0
    assert not (narrow.rgb.shape == wide.rgb.shape and np.array_equal(narrow.rgb, wide.rgb))
    # a tangential-fork layout is still valid: every face is one void
    faces = narrow.summary["n_stacks"] - narrow.summary["n_junctions"] + 1
    assert narrow.summary["n_voids"] == faces
    with pytest.raises(ParameterError):
        make_scene(seed=2, n_stacks=20, max_layers=4, fan_deg=0.0)


@pytest.mark.parametrize("option", [dict(noise_sigma=-5), dict(blur_px=float("nan")),
                                    dict(blur_px=-2), dict(smears=-1), dict(specks=-3),
                                    dict(pinholes=1.5), dict(jpeg_quality=0),
                                    dict(jpeg_quality=101), dict(jpeg_quality=90.0)])
def test_a_degradation_outside_its_range_is_refused(option):
    # out of range it was drawn as no degradation while the scene's options recorded it
    with pytest.raises(ParameterError, match=next(iter(option))):
        make_scene(seed=2, n_stacks=20, max_layers=3, **option)
