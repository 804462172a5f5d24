"""The scorer: perfect on the truth itself, and each metric reacts to its own kind of error."""
import copy
import shutil

import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import ConfigError
from crosssection.truth.scoring import (match_points, match_stacks, meets_targets, score,
                                        score_folder)
from crosssection.truth.network import make_scene
from crosssection.truth.scene import write_scene


@pytest.fixture(scope="module", params=[3, 12])
def truth(request):
    sc = make_scene(seed=request.param, n_stacks=40, max_layers=5)
    return sc.summary, sc.tables


def _copy(pair):
    return copy.deepcopy(pair[0]), {k: v.copy() for k, v in pair[1].items()}


def test_truth_scores_perfect(truth):
    s = score(truth, truth)
    assert s["junction_f1"] == 1.0
    assert s["rod_length_rel_error"] == 0.0
    assert s["n_br_exact_length_fraction"] == 1.0
    assert s["void_match_fraction"] == 1.0
    assert s["void_area_median_rel_error"] == 0.0
    assert s["total_energy_rel_error"] == 0.0
    assert all(meets_targets(s).values())


def test_junction_recall_and_precision(truth):
    rng = np.random.default_rng(1)
    summary, tables = _copy(truth)
    j = tables["junctions"]
    drop = rng.choice(len(j), 3, replace=False)
    tables["junctions"] = j.drop(index=drop).reset_index(drop=True)
    s = score((summary, tables), truth)
    assert s["junction_recall"] == pytest.approx((len(j) - 3) / len(j))
    assert s["junction_precision"] == 1.0
    # shifting by more than 3h unmatches; by less keeps the match
    summary, tables = _copy(truth)
    tables["junctions"].loc[:4, "x_px"] += 16.0  # > 15 px = 3h
    tables["junctions"].loc[5:9, "y_px"] += 10.0
    s = score((summary, tables), truth)
    assert s["junction_matched"] == len(j) - 5


def test_n_br_fraction_weighted_by_length(truth):
    summary, tables = _copy(truth)
    st = tables["stacks"]
    k = int(st["length_mm"].idxmax())
    tables["stacks"].loc[k, "n_br"] += 1
    s = score((summary, tables), truth)
    expected = 1 - st["length_mm"][k] / st["length_mm"].sum()
    assert s["n_br_exact_length_fraction"] == pytest.approx(expected)
    assert s["n_br_mean_abs_error"] == pytest.approx(1 / len(st))
    # one layer off is within +-1; two layers off is not
    assert s["n_br_within1_length_fraction"] == 1.0
    tables["stacks"].loc[k, "n_br"] += 1
    s = score((summary, tables), truth)
    assert s["n_br_within1_length_fraction"] == pytest.approx(expected)


def test_stacks_matched_by_mid_point_not_by_order(truth):
    summary, tables = _copy(truth)
    tables["stacks"] = tables["stacks"].sample(frac=1.0, random_state=4).reset_index(drop=True)
    s = score((summary, tables), truth)
    assert s["n_br_exact_length_fraction"] == 1.0
    summary, tables = _copy(truth)
    tables["stacks"]["mid_x_px"] += 2000.0  # far away: nothing matches
    s = score((summary, tables), truth)
    assert s["stack_match_fraction"] == 0.0
    assert s["n_br_exact_length_fraction"] == 0.0


def test_rod_length_voids_and_energy_errors(truth):
    summary, tables = _copy(truth)
    summary["rod_length_mm"] *= 1.05
    summary["total_energy"] *= 0.8
    v = tables["voids"]
    tables["voids"] = v.iloc[1:].reset_index(drop=True)
    tables["voids"]["area_mm2"] *= 1.1
    s = score((summary, tables), truth)
    assert s["rod_length_rel_error"] == pytest.approx(0.05)
    assert s["total_energy_rel_error"] == pytest.approx(-0.2)
    assert s["n_voids_rel_error"] == pytest.approx(-1 / len(v))
    assert s["void_area_median_rel_error"] == pytest.approx(0.1)
    assert not meets_targets(s)["rod_length"]


def test_match_points_respects_radius():
    rng = np.random.default_rng(0)
    t = rng.uniform(0, 500, (30, 2))
    o = t + rng.normal(0, 2, t.shape)
    r, c = match_points(o, t, 15.0)
    assert len(r) == 30 and np.array_equal(r, c)
    r, c = match_points(o + 100, t, 15.0)
    assert len(r) <= 2


def test_match_stacks_accepts_a_quarter_of_a_long_stacks_length():
    """A long stack's mid point moves with where its ends are placed: it is matched within
    a quarter of its length, a short one within ``match_px``."""
    truth = pd.DataFrame({"mid_x_px": [100.0, 400.0], "mid_y_px": [100.0, 100.0],
                          "length_mm": [10.0, 0.5]})
    out = truth.assign(mid_x_px=truth["mid_x_px"] + 60.0)  # 60 px off each
    r, c = match_stacks(out, truth, match_px=15.0, px_per_mm=50.0)
    assert r.tolist() == [0] and c.tolist() == [0]  # 10 mm: within 125 px; 0.5 mm: 15 px
    r, c = match_stacks(out, truth, match_px=70.0, px_per_mm=50.0)
    assert r.tolist() == [0, 1] and c.tolist() == [0, 1]


def test_score_folder(tmp_path):
    sc = make_scene(seed=9, n_stacks=25, max_layers=4)
    folder = write_scene(sc, tmp_path / "scene")
    s = score_folder(folder / "truth", folder)
    assert s["junction_f1"] == 1.0 and s["match_px"] == pytest.approx(15.0)


@pytest.mark.parametrize("file, content, cause", [
    ("branches.csv", None, "file not found"),
    ("stacks.csv", "", "empty file (no header line)"),
    ("stacks.csv", "x\n1\n", "not a stacks table (expected the header stack_id,"),
    ("junctions.csv", "junction_id,x_px\n0,1.0\n", "lacks column(s) y_px, n_stacks"),
    ("voids.csv", b"void_id,area_mm2\n\xff\xfe,1\n", "malformed CSV (not a text file)"),
    ("summary.json", None, "file not found"),
    ("summary.json", "{bad", "malformed JSON"),
    ("summary.json", "[1, 2]", "must hold a JSON object"),
])
def test_score_folder_names_the_damaged_file_of_the_output(tmp_path, file, content, cause):
    sc = make_scene(seed=9, n_stacks=25, max_layers=4)
    folder = write_scene(sc, tmp_path / "scene")
    out = tmp_path / "out"
    shutil.copytree(folder / "truth", out)
    if content is None:
        (out / file).unlink()
    elif isinstance(content, bytes):
        (out / file).write_bytes(content)
    else:
        (out / file).write_text(content)
    with pytest.raises(ConfigError) as err:
        score_folder(out, folder)
    assert err.value.path == str(out / file) and cause in err.value.cause


def test_score_folder_names_the_damaged_table_of_the_truth(tmp_path):
    sc = make_scene(seed=9, n_stacks=25, max_layers=4)
    folder = write_scene(sc, tmp_path / "scene")
    (folder / "truth" / "voids.csv").write_text("void_id,area_mm2\n0,1.0\n")
    with pytest.raises(ConfigError) as err:
        score_folder(folder / "truth", folder)
    assert err.value.path == str(folder / "truth" / "voids.csv")
    assert err.value.cause.startswith("lacks column(s) perimeter_mm, shape_ratio")


def _line(p0, p1, n=200):
    return np.linspace(p0, p1, n)


def test_medial_fork_points_where_the_bands_separate():
    from crosssection.truth.scoring import medial_fork_points

    node = np.array([150.0, 100.0])
    # a symmetric Y of thin bands at 120 degrees: the bands separate at the node
    arms = [node + 80 * np.array([np.sin(a), np.cos(a)]) for a in np.radians([180, 60, -60])]
    paths = [_line(node, a) for a in arms]
    out = medial_fork_points(paths, [8, 8, 8], [(0, -1)] * 3, [0], [node], (300, 300))
    assert np.hypot(*(out[0] - node)) <= 3.0
    # a trunk 30 px wide whose two 16-px branches leave the node side by side at +-15 degrees:
    # the bands part ahead of the node, on the trunk's axis
    branches = [node + 150 * np.array([np.sin(a), np.cos(a)]) for a in np.radians([15, -15])]
    paths = [_line(node - [0, 90], node)] + [_line(node, b) for b in branches]
    out = medial_fork_points(paths, [30, 16, 16], [(-1, 0)] * 3, [0], [node], (300, 300))
    assert out[0, 1] - node[1] > 10.0
    assert abs(out[0, 0] - node[0]) <= 2.0
    # a node with no fork within its widest band keeps its point
    far = np.array([[20.0, 20.0]])
    out = medial_fork_points(paths, [30, 16, 16], [(-1, 7)] * 3, [7], far, (300, 300))
    np.testing.assert_allclose(out, far)


@pytest.mark.parametrize("bad", [42, None, ({}, {}), ("summary", {})])
def test_score_names_a_wrong_argument(bad):
    from crosssection.core.errors import ParameterError
    from crosssection.truth.network import make_scene
    from crosssection.truth.scoring import score

    sc = make_scene(seed=1, n_stacks=20, max_layers=2)
    with pytest.raises(ParameterError, match="^truth must be"):
        score(sc, bad)
    with pytest.raises(ParameterError, match="^result must be"):
        score(bad, sc)
    assert score(sc, sc)["junction_f1"] == 1.0


def test_the_matching_radius_is_that_of_the_scale_the_analysis_recorded(truth):
    """A 25 px/mm analysis is matched within 3 h = 7.5 px, not the 15 px of 50 px/mm."""
    out = _copy(truth)
    out[0]["parameters"] = {"px_per_mm": 25.0, "thickness_mm": 0.1}
    assert score(out, truth)["match_px"] == pytest.approx(7.5)
    assert score(out, truth, px_per_mm=50.0)["match_px"] == pytest.approx(15.0)
    bare = _copy(truth)
    bare[0].pop("parameters", None)
    bare[0].pop("px_per_mm", None)
    t = _copy(truth)
    t[0].pop("px_per_mm", None)
    assert score(bare, t)["match_px"] == pytest.approx(15.0)
