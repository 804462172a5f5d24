"""The analyze/steps contract: files, columns, summary keys, exit status; the
Python API on several generated scenes; parameter validation."""
from __future__ import annotations

import json
import math
import subprocess
import sys
import warnings

import cv2
import numpy as np
import pandas as pd
import pytest

from crosssection import analyze
from crosssection.core import schema
from crosssection.cli import main
from crosssection.core.calibration import Calibration
from crosssection.core.errors import AnalysisError, ImageError, ParameterError
from crosssection.quality import NetworkWarning
from crosssection.truth.network import make_scene

#: width law of the drawn scans at the default h (0.1 mm): their bands are n h wide
DRAWN_CALIBRATION = Calibration.linear(0.1)


@pytest.fixture
def scene_dir(scene_folder):
    return scene_folder


def _params(folder):
    return json.loads((folder / "params.json").read_text())


def test_cli_analyze_contract(scene_dir, tmp_path):
    folder, scene = scene_dir
    p = _params(folder)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "crosssection", "analyze", str(folder / "image.png"),
           "--px-per-mm", "50", "--thickness-mm", "0.1",
           "--hole-radius-mm", str(p["hole_radius_mm"]),
           "--hole-center-px", *map(str, p["hole_center_px"]),
           "--calibration", str(folder / "calibration.csv"),
           "--rod-length-mm", str(p["rod_length_mm"]), "--out", str(out)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr
    for name in ("summary.json", "junctions.csv", "stacks.csv", "branches.csv", "voids.csv",
                 "overlay.png"):
        assert (out / name).is_file(), name
    summary = json.loads((out / "summary.json").read_text())
    for key in schema.SUMMARY_KEYS + schema.PROVENANCE_KEYS:
        assert key in summary
    assert len(summary["inputs"]["image"]["sha256"]) == 64
    for key in schema.HOLE_KEYS:
        assert key in summary["hole"]
    assert summary["hole"]["found_by"] == "given"
    assert set(summary["timings_s"]) >= {"load", "threshold", "hole", "clean", "skeleton",
                                         "graph", "widths", "linear_system", "curvature"}
    for name, cols in schema.TABLES.items():
        df = pd.read_csv(out / f"{name}.csv")
        assert list(df.columns[:len(cols)]) == cols, name
    stacks = pd.read_csv(out / "stacks.csv")
    branches = pd.read_csv(out / "branches.csv")
    junctions = pd.read_csv(out / "junctions.csv")
    assert summary["n_stacks"] == len(stacks) > 0
    assert summary["n_branches"] == len(branches) == stacks["n_br"].sum()
    assert summary["n_junctions"] == len(junctions)
    # the packs read back as text, whatever they hold (a "stack.end" code of one stack end
    # is read as a number)
    for side in ("pack_a", "pack_b"):
        assert junctions[side].map(type).eq(str).all(), junctions[side].tolist()
    assert summary["n_voids"] == len(pd.read_csv(out / "voids.csv"))
    # rod length = sum n_br l; epsilon with the given L and R
    assert math.isclose(summary["rod_length_mm"],
                        float((stacks["n_br"] * stacks["length_mm"]).sum()), rel_tol=1e-6)
    assert math.isclose(summary["epsilon"],
                        p["rod_length_mm"] / (2 * math.pi * p["hole_radius_mm"]), rel_tol=1e-6)
    assert set(stacks["region"]) <= {"bulk", "periphery"}
    # junction_a/b are junction ids or -1
    ids = set(junctions["junction_id"]) | {-1}
    assert set(stacks["junction_a"]) <= ids and set(stacks["junction_b"]) <= ids
    # n_stacks of a junction = number of stack ends there
    ends = pd.concat([stacks["junction_a"], stacks["junction_b"]]).value_counts()
    for _, row in junctions.iterrows():
        assert row["n_stacks"] == ends.get(row["junction_id"], 0)
    img = cv2.imread(str(out / "overlay.png"))
    assert img is not None and img.shape[0] > 100


def test_cli_steps_writes_four_images(scene_dir, tmp_path, capsys):
    folder, _ = scene_dir
    out = tmp_path / "steps"
    status = main(["steps", str(folder / "image.png"), "--px-per-mm", "50", "--out", str(out),
                   "--no-figure"])
    assert status == 0
    shapes = []
    for name in ("step1_raw", "step2_threshold", "step3_clean", "step4_skeleton"):
        img = cv2.imread(str(out / f"{name}.png"), cv2.IMREAD_UNCHANGED)
        assert img is not None, name
        shapes.append(img.shape[:2])
    assert len(set(shapes)) == 1
    # the skeleton image has red junction circles
    sk = cv2.imread(str(out / "step4_skeleton.png"))
    assert ((sk[..., 2] > 200) & (sk[..., 1] < 80)).any()


@pytest.mark.parametrize("seed,n_stacks,max_layers,extra", [
    (41, 25, 3, {}),
    (42, 40, 6, {"noise_sigma": 6.0}),
    (43, 30, 8, {"blur_px": 1.0, "jpeg_quality": 85}),
])
def test_api_on_generated_scenes(seed, n_stacks, max_layers, extra):
    scene = make_scene(seed=seed, n_stacks=n_stacks, max_layers=max_layers, **extra)
    p = scene.params
    res = analyze(scene.rgb, px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
                  hole_radius_mm=p["hole_radius_mm"], hole_center_px=p["hole_center_px"],
                  calibration=scene.calibration.to_frame(20))
    truth = scene.summary
    # stages 1-6 recover the network exactly on these scenes
    assert res.summary["n_junctions"] == truth["n_junctions"]
    assert res.summary["n_stacks"] == truth["n_stacks"]
    assert res.summary["n_voids"] == truth["n_voids"]
    from crosssection.truth.scoring import match_points

    a, b = match_points(res.junctions[["x_px", "y_px"]].to_numpy(float),
                        scene.tables["junctions"][["x_px", "y_px"]].to_numpy(float), 15.0)
    assert len(a) == truth["n_junctions"]
    # the summary's derived quantities are consistent with the tables
    st = res.stacks
    assert math.isclose(res.summary["rod_length_mm"], float((st.n_br * st.length_mm).sum()))
    assert res.summary["n_branches"] == len(res.branches) == int(st.n_br.sum())
    assert (st.n_br >= 1).all()
    assert np.all(np.abs(res.branches["length_mm"].to_numpy()
                         - st.length_mm.to_numpy()[res.branches["stack_id"]]) < 1e-12)
    # a stack's energy per branch is its branches' energy (the noise floor removed in both)
    per_stack = res.branches.groupby("stack_id").energy.first()
    np.testing.assert_allclose(st.set_index("stack_id").energy_per_branch.loc[per_stack.index],
                               per_stack.to_numpy(), rtol=1e-12)
    assert res.summary["total_energy"] == pytest.approx(
        float((st.n_br * st.energy_per_branch).sum()), rel=1e-9)
    # the share of the total resting on the fork zones and the noise floor: each stack's
    # uncertain share, capped at its energy, weighted by its energy
    e = st.n_br * st.energy_per_branch
    share = res.summary["total_energy_rel_uncertainty"]
    assert 0.0 < share < 1.0
    assert share == pytest.approx(float((e * st.energy_rel_uncertainty.clip(upper=1.0)).sum()
                                        / e.sum()), rel=1e-9)
    # stack lengths match truth (matched by mid point) within a few percent
    a, b = match_points(st[["mid_x_px", "mid_y_px"]].to_numpy(float),
                        scene.tables["stacks"][["mid_x_px", "mid_y_px"]].to_numpy(float), 20.0)
    rel = st.length_mm.to_numpy()[a] / scene.tables["stacks"]["length_mm"].to_numpy()[b] - 1
    assert np.median(np.abs(rel)) < 0.05
    # conservation columns agree with an independent count over the reported packs, and
    # layers are conserved at (nearly) every junction of these clean scenes
    n = st.set_index("stack_id").n_br
    jt = res.junctions
    for _, row in jt.iterrows():
        sums = [sum(int(n[int(e.split(":")[0])]) for e in str(side).split())
                for side in (row.pack_a, row.pack_b)]
        assert row.conservation_residual == sums[0] - sums[1]
        assert bool(row.conservation_ok) == (sums[0] == sums[1])
    assert jt.conservation_ok.mean() >= 0.9


def test_ring_only_image_is_not_an_error():
    img = np.full((300, 300, 3), 245, np.uint8)
    mask = np.zeros((300, 300), np.uint8)
    cv2.circle(mask, (150, 150), 100, 1, 6)
    img[mask > 0] = (40, 70, 190)
    with pytest.warns(NetworkWarning, match="no junction found"):
        res = analyze(img, calibration=DRAWN_CALIBRATION, px_per_mm=50)
    assert res.summary["n_junctions"] == 0
    assert res.summary["n_stacks"] == 1
    assert res.stacks["junction_a"].iloc[0] == -1
    assert any("no junction" in w for w in res.summary["warnings"])
    L = res.stacks["length_mm"].iloc[0]
    assert abs(L - 2 * math.pi * 100 / 50) / (2 * math.pi * 100 / 50) < 0.02


def test_warn_false_keeps_the_flags_in_the_result_only():
    img = np.full((300, 300, 3), 245, np.uint8)
    mask = np.zeros((300, 300), np.uint8)
    cv2.circle(mask, (150, 150), 100, 1, 6)
    img[mask > 0] = (40, 70, 190)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = analyze(img, calibration=DRAWN_CALIBRATION, warn=False)
    assert "no_junction" in res.summary["quality"]["codes"]
    assert any(f.code == "no_junction" for f in res.quality)


def test_thick_x_crossing_becomes_degree_4():
    img = np.full((400, 400, 3), 245, np.uint8)
    mask = np.zeros((400, 400), np.uint8)
    for a in (0.35, 0.35 + np.radians(50)):
        d = 180 * np.array([np.cos(a), np.sin(a)])
        cv2.line(mask, tuple((200 - d).astype(int)), tuple((200 + d).astype(int)), 1, 30)
    img[mask > 0] = (40, 70, 190)
    # the drawing has no hole: the one given holds the whole cross
    res = analyze(img, l_min_mm=0.5, calibration=DRAWN_CALIBRATION, hole_radius_mm=3.9,
                  hole_center_px=(200, 200), px_per_mm=50)
    assert res.summary["n_junctions"] == 1
    assert res.junctions["n_stacks"].iloc[0] == 4
    assert abs(res.junctions["x_px"].iloc[0] - 200) < 6
    assert abs(res.junctions["y_px"].iloc[0] - 200) < 6


def test_a_lens_below_s_min_keeps_its_two_stacks():
    # a single sheet across the hole parts into two for 3.2 mm and joins again: the paper
    # between them (about 2.5 h wide, 1300 px^2 < s_min = 2500 px^2) is a sliver, not noise
    img = np.full((420, 420, 3), 245, np.uint8)
    mask = np.zeros((420, 420), np.uint8)
    cv2.circle(mask, (210, 210), 190, 1, 8)
    x = np.arange(130, 291)
    bulge = 10.5 * np.sin(np.pi * (x - 130) / 160)
    for sign in (1, -1):
        pts = np.stack([x, 210 + sign * bulge], 1).round().astype(np.int32)
        cv2.polylines(mask, [pts], False, 1, thickness=5)
    cv2.line(mask, (22, 210), (130, 210), 1, 5)
    cv2.line(mask, (290, 210), (398, 210), 1, 5)
    img[mask > 0] = (40, 70, 190)
    tips = np.array([[130.0, 210.0], [290.0, 210.0]])
    kw = dict(px_per_mm=50.0, thickness_mm=0.1, hole_radius_mm=3.9, hole_center_px=(210, 210))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        kept = analyze(img, **kw)
        filled = analyze(img, **kw, sliver_width_h=0.0)

    def near_tips(res):
        xy = res.junctions[["x_px", "y_px"]].to_numpy(float)
        return [bool(len(xy)) and float(np.hypot(*(xy - t).T).min()) <= 15 for t in tips]

    assert near_tips(kept) == [True, True]
    assert near_tips(filled) == [False, False]
    assert kept.summary["n_stacks"] == filled.summary["n_stacks"] + 3
    assert kept.summary["n_voids"] == filled.summary["n_voids"]  # below s_min: not a void
    lens = kept.stacks[np.hypot(kept.stacks["mid_x_px"] - 210, kept.stacks["mid_y_px"] - 210) < 30]
    assert sorted(lens["n_br"]) == [1, 1]


@pytest.mark.parametrize("kwargs", [
    {"px_per_mm": 0}, {"px_per_mm": -5}, {"thickness_mm": 0}, {"thickness_mm": float("nan")},
    {"s_min_mm2": 1e6}, {"hole_radius_mm": -1}, {"rod_length_mm": 0},
    {"hole_center_px": (1, "a")}, {"threshold_method": "magic"}, {"thickness_mm": 50.0},
    {"l_min_mm": -1}, {"skeleton_method": "zhang"}, {"width_statistic": "mode"},
    {"integer_refinement": "no"},
])
def test_absurd_parameters_raise(kwargs):
    img = np.full((100, 100, 3), 245, np.uint8)
    img[40:60, 10:90] = (40, 70, 190)
    with pytest.raises(ParameterError):
        analyze(img, **kwargs)


@pytest.mark.parametrize("name,value,expected", [
    ("skeleton_method", "zhang", "skeleton_method must be one of thinning, skimage"),
    ("width_statistic", "mode", "width_statistic must be one of median, mean"),
    ("integer_refinement", 0, "integer_refinement must be true or false"),
])
def test_method_options_fail_in_one_line(name, value, expected):
    from crosssection.params import AnalysisParams

    with pytest.raises(ParameterError) as err:
        AnalysisParams.from_mapping({name: value}, path="scan.png")
    line = err.value.one_line()
    assert "\n" not in line and line.startswith("scan.png: ") and expected in line


def test_method_options_reach_their_stages():
    """Each option changes what it should on a generated scene (defaults recorded in the
    summary), and ``--no-integer-refinement`` sets its field."""
    import argparse

    from crosssection.params import AnalysisParams, add_analysis_arguments

    scene = make_scene(seed=42, n_stacks=30, max_layers=6, noise_sigma=6.0)
    p = scene.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              hole_radius_mm=p["hole_radius_mm"], hole_center_px=p["hole_center_px"],
              calibration=scene.calibration.to_frame(20))
    base = analyze(scene.rgb, **kw)
    assert {k: base.summary["parameters"][k] for k in
            ("skeleton_method", "width_statistic", "integer_refinement")} == {
        "skeleton_method": "thinning", "width_statistic": "median", "integer_refinement": True}
    skim = analyze(scene.rgb, skeleton_method="skimage", **kw)
    assert not np.array_equal(skim.skeleton, base.skeleton)
    assert skim.summary["n_junctions"] == base.summary["n_junctions"]
    mean = analyze(scene.rgb, width_statistic="mean", **kw)
    np.testing.assert_array_equal(mean.skeleton, base.skeleton)
    assert not np.allclose(mean.stacks.width_mm, base.stacks.width_mm)
    raw = analyze(scene.rgb, integer_refinement=False, **kw)
    assert {c.method for c in raw.linear_system.components} <= {"rounded", "width"}
    assert "rounded" in {c.method for c in raw.linear_system.components}
    assert "rounded" not in {c.method for c in base.linear_system.components}
    parser = argparse.ArgumentParser()
    add_analysis_arguments(parser)
    args = parser.parse_args(["--no-integer-refinement", "--skeleton-method", "skimage",
                              "--width-statistic", "mean", "--no-layer-steps"])
    cli = AnalysisParams.from_cli_args(args)
    assert (cli.integer_refinement, cli.skeleton_method, cli.width_statistic,
            cli.layer_steps, cli.merge_thick_crossings) == (False, "skimage", "mean", False,
                                                            True)


def test_the_walls_follow_the_thresholds_feature():
    """With a colour threshold (auto, Otsu) the centreline's walls are placed where its
    feature crosses the cut; the fixed thresholds cut three channels and keep the mask's."""
    from crosssection.pipeline import preprocess
    from crosssection.stages.curvature import stack_profiles

    scene = make_scene(seed=7, n_stacks=20, max_layers=4, noise_sigma=4.0)
    p = scene.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              hole_radius_mm=p["hole_radius_mm"], hole_center_px=p["hole_center_px"])
    rgb = scene.rgb.astype(int)
    for method in ("auto", "otsu"):
        pre = preprocess(scene.rgb, threshold_method=method, **kw)
        np.testing.assert_array_equal(pre.edge_feature,
                                      rgb[..., 2] - np.maximum(rgb[..., 0], rgb[..., 1]))
    assert preprocess(scene.rgb, threshold_method="fixed", **kw).edge_feature is None
    pre = preprocess(scene.rgb, **kw)
    n_br = np.ones(pre.graph.n_stacks, int)
    args = dict(thickness_px=p["thickness_mm"] * p["px_per_mm"], px_per_mm=p["px_per_mm"])
    mask_walls = stack_profiles(pre.graph, n_br, pre.distance_px, **args)
    feature_walls = stack_profiles(pre.graph, n_br, pre.distance_px, **args,
                                   edge=(pre.edge_feature, pre.threshold.dominance_min))
    moved = np.concatenate([np.hypot(*(a.rc_px - b.rc_px).T)
                            for a, b in zip(mask_walls, feature_walls)
                            if len(a.s_mm) == len(b.s_mm) and len(a.s_mm)])
    # a fraction of a pixel (measured: median 0.04 px, at most 0.3): the mask rounds each
    # wall to the grid
    assert 0.0 < np.median(moved) < 0.2 and moved.max() < 1.0


def test_centrelines_drawn_beforehand_on_a_thread_give_the_same_profiles():
    """The pipeline draws the stacks' centrelines (between the walls) on a thread while the
    branch counts are solved: the profiles are those drawn in one call, to the bit, and
    centrelines of other settings are refused."""
    from crosssection.core.parallel import in_background
    from crosssection.pipeline import preprocess
    from crosssection.stages.curvature import stack_centrelines, stack_profiles

    scene = make_scene(seed=5, n_stacks=25, max_layers=5, noise_sigma=4.0)
    p = scene.params
    pre = preprocess(scene.rgb, px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"])
    n_br = np.random.default_rng(5).integers(1, 5, pre.graph.n_stacks)
    edge = (pre.edge_feature, pre.threshold.dominance_min)
    args = dict(thickness_px=p["thickness_mm"] * p["px_per_mm"], edge=edge)
    for method in ("walls", "missing", "paper"):
        whole = stack_profiles(pre.graph, n_br, pre.distance_px, px_per_mm=p["px_per_mm"],
                               method=method, **args)
        lines = in_background(stack_centrelines, pre.graph, pre.distance_px, method=method,
                              **args)()
        parts = stack_profiles(pre.graph, n_br, pre.distance_px, px_per_mm=p["px_per_mm"],
                               method=method, centrelines=lines, **args)
        for a, b in zip(whole, parts, strict=True):
            np.testing.assert_array_equal(a.kappa_per_mm, b.kappa_per_mm)
            np.testing.assert_array_equal(a.rc_px, b.rc_px)
    for other in (dict(method="missing", edge=edge), dict(method="paper", edge=None)):
        with pytest.raises(ParameterError, match="other settings"):
            stack_profiles(pre.graph, n_br, pre.distance_px, px_per_mm=p["px_per_mm"],
                           thickness_px=args["thickness_px"], centrelines=lines, **other)


def test_a_failed_analysis_leaves_no_step_running_and_raises_the_first_error():
    """Steps run on a thread (the dark marks, the voids, the walls' midpoints) are waited for
    when the analysis fails: none runs on or warns after it has raised, and a caller who
    turns warnings into errors gets the error that comes first in the scan's order (the
    dark marks' median of an empty selection, before the cleaning finds nothing left)."""
    import threading

    img = np.full((300, 300, 3), 245, np.uint8)
    img[151, 151] = img[101, 101] = (40, 60, 170)
    kw = dict(threshold_method="fixed", hole_radius_mm=2, hole_center_px=[150, 150],
              hole_correction=False)
    for _ in range(3):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with pytest.raises(AnalysisError, match="nothing left after cleaning"):
                analyze(img, **kw)
            n_caught = len(caught)
        steps = [t for t in threading.enumerate() if t.name.startswith("foldstat-")
                 and t.name != "foldstat-sha256" and t.is_alive()]
        assert steps == []
        assert len(caught) == n_caught  # nothing more arrived after the analysis raised
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(RuntimeWarning, match="empty slice"):
            analyze(img, **kw)


def test_the_distances_error_comes_before_the_thinnings(monkeypatch, tmp_path):
    """The distances run beside the thinning: when both fail, the distances' error, first in
    the scan's order, is raised, and neither step runs on; a scan file that cannot be read
    leaves no hashing thread behind."""
    import threading

    import crosssection.pipeline as pipeline

    scene = make_scene(seed=3, n_stacks=12)

    def thin(*args, **kwargs):
        raise RuntimeError("the thinning failed")

    def distances(*args, **kwargs):
        raise ValueError("the distances failed")

    monkeypatch.setattr(pipeline, "skeletonize_mask", thin)
    monkeypatch.setattr(pipeline, "distance_map", distances)
    with pytest.raises(ValueError, match="the distances failed"):
        analyze(scene.rgb, px_per_mm=scene.params["px_per_mm"])
    monkeypatch.undo()
    monkeypatch.setattr(pipeline, "skeletonize_mask", thin)
    with pytest.raises(RuntimeError, match="the thinning failed"):
        analyze(scene.rgb, px_per_mm=scene.params["px_per_mm"])
    for _ in range(5):
        with pytest.raises(ImageError):
            analyze(tmp_path / "missing.png")
        assert [t for t in threading.enumerate() if t.name.startswith("foldstat-")
                and t.is_alive()] == []


def test_uniform_images_raise_analysis_error():
    with pytest.raises(AnalysisError, match="empty mask"):
        analyze(np.full((64, 64, 3), 250, np.uint8))
    with pytest.raises(AnalysisError):
        analyze(np.tile(np.array([40, 70, 190], np.uint8), (64, 64, 1)))


def test_an_empty_mask_names_the_option_that_emptied_it():
    # a given hole holding no ink, and bounds given to the automatic cut that exclude the
    # ink, were reported as a scan without blue ink
    from crosssection.core.errors import ParameterError

    scene = make_scene(seed=44, n_stacks=20, max_layers=3)
    p = scene.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"])
    empty = np.full(scene.rgb.shape, 245, np.uint8)
    empty[:40, :40] = (40, 70, 190)  # ink in a corner only, far from the hole
    with pytest.raises(ParameterError, match="no ink inside the given hole .* check "
                                             "hole_radius_mm and hole_center_px"):
        analyze(empty, hole_radius_mm=1.0, hole_center_px=tuple(p["hole_center_px"]), **kw)
    with pytest.raises(AnalysisError, match=r"the bounds given \(rg_max = 0\) exclude"):
        analyze(scene.rgb, rg_max=0, **kw)


def test_a_colourless_scan_says_so():
    # a colour scan made grey (channels equal, as a grayscale scan saved as RGB): no ink passes,
    # and the error names the cause with the cut that reads the grey marks; a scan whose ink
    # is of another colour says which
    scene = make_scene(seed=44, n_stacks=20, max_layers=3)
    grey = np.repeat(scene.rgb.mean(axis=2, keepdims=True).astype(np.uint8), 3, axis=2)
    with pytest.raises(AnalysisError, match="no colour.*scan in colour, or read its dark marks"
                       r".*--threshold-method fixed --blue-min 0 --rg-max \d+$") as err:
        analyze(grey)
    cut = int(str(err.value).rsplit("--rg-max ", 1)[1].split()[0])
    given = dict(hole_radius_mm=scene.params["hole_radius_mm"],
                 hole_center_px=scene.params["hole_center_px"], calibration=scene.calibration,
                 warn=False)
    read = analyze(grey, threshold_method="fixed", blue_min=0, rg_max=cut, **given).summary
    colour = analyze(scene.rgb, **given).summary
    assert (read["n_junctions"], read["n_branches"]) == (colour["n_junctions"],
                                                         colour["n_branches"])
    with pytest.raises(AnalysisError, match="no blue-dominant class.*marks are orange"):
        analyze(np.ascontiguousarray(scene.rgb[..., ::-1]))  # blue ink turned orange


def test_result_write_roundtrip(tmp_path):
    scene = make_scene(seed=44, n_stacks=20, max_layers=3)
    given = dict(hole_radius_mm=scene.params["hole_radius_mm"],
                 hole_center_px=scene.params["hole_center_px"], calibration=scene.calibration,
                 px_per_mm=scene.params["px_per_mm"])
    # rod lengths the hole cannot hold, far beyond the rod measured (both flagged); what is
    # checked is the scaling by L
    with pytest.warns(NetworkWarning) as caught:
        res = analyze(scene.rgb, **given, rod_length_mm=1000.0)
    assert {"packing", "rod_length"} <= set(res.summary["quality"]["codes"])
    assert any("is impossible for this hole" in str(w.message) for w in caught)
    res.write(tmp_path, figure=False)
    summary, tables = schema.read_tables(tmp_path)
    assert not (tmp_path / "overlay.png").exists()
    assert summary["rod_length_used_mm"] == 1000.0
    assert summary["rod_length_mm"] != 1000.0
    # energies scale with the L used: e = L int kappa^2 ds
    with pytest.warns(NetworkWarning):
        res2 = analyze(scene.rgb, **given, rod_length_mm=2000.0)
    assert math.isclose(res2.summary["total_energy"], 2 * summary["total_energy"], rel_tol=1e-9)
    assert len(tables["stacks"]) == summary["n_stacks"]


@pytest.mark.parametrize("axes_px", [(30, 12), (25, 14), (22, 10)])
def test_an_isolated_blob_pruned_below_l_min_is_dropped(axes_px):
    """A fat smear in a void keeps its area and extent through the cleaning but its skeleton
    is pruned to a stub shorter than l_min: it holds no measurable branch. Counted as a stack
    its parabola through a few pixels reads up to 70 % of this scan's energy."""
    from crosssection.truth.network import make_scene

    sc = make_scene(seed=21, n_stacks=30, max_layers=4)
    p = sc.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              calibration=sc.calibration, hole_radius_mm=p["hole_radius_mm"],
              hole_center_px=tuple(p["hole_center_px"]))
    ink = (sc.rgb[..., 2].astype(int) - sc.rgb[..., :2].max(-1)) > 40
    cx, cy = p["hole_center_px"]
    r = p["hole_radius_mm"] * p["px_per_mm"]
    yy, xx = np.indices(ink.shape)
    room = (~ink).astype(np.uint8)
    room[(yy - cy) ** 2 + (xx - cx) ** 2 > (0.9 * r) ** 2] = 0
    d = cv2.distanceTransform(room, cv2.DIST_L2, 5)
    y, x = np.unravel_index(np.argmax(d), d.shape)
    assert d[y, x] > 2 * axes_px[0]  # the blob lies in a void, touching nothing
    rgb = sc.rgb.copy()
    cv2.ellipse(rgb, (int(x), int(y)), axes_px, 30, 0, 360, (40, 70, 190), -1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        clean = analyze(sc.rgb, **kw)
        res = analyze(rgb, **kw)
    assert res.summary["n_stacks"] == clean.summary["n_stacks"]
    assert res.summary["total_energy"] == pytest.approx(clean.summary["total_energy"])
    assert res.summary["rod_length_mm"] == pytest.approx(clean.summary["rod_length_mm"])
    assert any("isolated piece" in w for w in res.summary["warnings"])
    assert not any("isolated piece" in w for w in clean.summary["warnings"])


def test_the_summary_says_how_the_hole_was_found(sample_dir):
    import warnings

    import crosssection

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = crosssection.analyze(str(sample_dir / "scan_01_sparse.png"),
                                   calibration=str(sample_dir / "calibration.csv"))
    # no plate on this scan: the wall is the ink's envelope, which a reader must be told
    assert "ink envelope" in res.summary["hole"]["found_by"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = crosssection.analyze(str(sample_dir / "scan_01_sparse.png"),
                                   calibration=str(sample_dir / "calibration.csv"),
                                   hole_radius_mm=res.summary["hole"]["radius_mm"])
    assert res.summary["hole"]["found_by"] == "radius given, centre fitted to the ink"


def test_a_calibration_far_from_the_thickness_names_both():
    # thickness_mm 10 with a calibration of 0.14 mm per layer blamed the (right) calibration
    from crosssection.core.errors import ParameterError

    scene = make_scene(seed=44, n_stacks=20, max_layers=3)
    with pytest.raises(ParameterError, match="not about the sheet thickness h = 10 mm "
                                             r"\(check its units and columns, and thickness_mm"):
        analyze(scene.rgb, px_per_mm=50, thickness_mm=10, calibration=scene.calibration)


def _walled_scan(plate, *, seed=0):
    """A 25 px/mm scan (h = 2.5 px): a wall band of 2 layers pressed against the hole's wall
    and two single-layer chords, blue ink (40, 60, 170) on paper inside the hole, the
    ``plate`` colour outside it, blur 1 px and noise 3. Returns (rgb, centre (row, col),
    radius px)."""
    rng = np.random.default_rng(seed)
    size, sub, h = 560, 4, 2.5
    c, R = (280.0, 280.0), 250.0
    big = np.zeros((size * sub, size * sub), np.uint8)
    cv2.circle(big, (int(c[1] * sub), int(c[0] * sub)), int((R - h) * sub), 1, int(2 * h * sub))
    for y in (200, 360):
        dx = np.sqrt((R - 2 * h) ** 2 - (y - c[0]) ** 2)
        cv2.line(big, (int((c[1] - dx) * sub), y * sub), (int((c[1] + dx) * sub), y * sub), 1,
                 int(h * sub))
    ink = cv2.resize(big.astype(np.float32), (size, size), interpolation=cv2.INTER_AREA)
    yy, xx = np.mgrid[:size, :size]
    inside = np.clip(R - np.hypot(yy - c[0], xx - c[1]) + 0.5, 0, 1)[..., None]
    back = inside * np.array([245.0, 245, 240]) + (1 - inside) * np.array(plate, float)
    rgb = back * (1 - ink[..., None]) + ink[..., None] * np.array([40.0, 60, 170])
    rgb = cv2.GaussianBlur(rgb, (0, 0), 1.0) + rng.normal(0, 3, rgb.shape)
    return np.clip(rgb, 0, 255).astype(np.uint8), c, R


def test_a_bluish_plate_does_not_widen_the_wall_band():
    """Beyond the wall the band's ink blurs into the plate, not into paper: a plate of blue
    dominance 52, near the cut's 56 (halfway from the ink's 110 to the paper's 4), let 2 px
    of the frame's margin in, 0.6 layer at 25 px/mm (every wall stack of an outside
    generator's scans one layer over, rod +19 %). The wall band reads as wide as on a grey
    plate or on paper."""
    widths = {}
    # "inky": a plate no colour tells from the ink (a dark-blue plate): the margin is dropped
    for name, plate in (("bluish", (97, 106, 158)), ("grey", (128, 125, 120)),
                        ("paper", (245, 245, 240)), ("inky", (50, 60, 140))):
        rgb, c, R = _walled_scan(plate)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = analyze(rgb, px_per_mm=25, thickness_mm=0.1, hole_radius_mm=R / 25,
                          hole_center_px=(c[1], c[0]), scale_given=True)
        st = res.stacks
        # the wall's stacks: those whose middle lies within 4 h of the wall
        mid_r = np.hypot(st["mid_y_px"] - c[0], st["mid_x_px"] - c[1])
        wall = st[mid_r > R - 10]
        assert len(wall) >= 4
        widths[name] = float(np.average(wall["layers_est"], weights=wall["length_mm"]))
    for name in ("bluish", "grey", "inky"):
        assert abs(widths[name] - widths["paper"]) < 0.15, widths
