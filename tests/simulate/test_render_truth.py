"""The truth of a render agrees with its drawing and with the rod: junctions on the ink, the
bands a junction holds together touching, the rod's length in the stacks, and render.json
recording what the scenes were drawn with."""
import json
import warnings
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import ParameterError
from crosssection.quality import QualityWarning
from simulate.cli import main
from simulate.contacts import analyze_rod
from simulate.energy import LAMBDA
from simulate.shapes import hairpin, resample
from simulate import render
from simulate.render import (JUNCTION_INK_H, TRUTH_LENGTH_TOLERANCE, TruthWarning,
                             _apart_junctions, _disconnected_junctions, _junctions_onto_ink,
                             _rod_drawn_check, _void_count_check, render_configuration,
                             render_directory)

# short rods, below the segment count the renders' truth is validated from, on purpose
pytestmark = pytest.mark.filterwarnings(
    "ignore:.*the render's truth is validated from:simulate.render.ScanRangeWarning")

DATA = Path(__file__).parent / "data"
H_PX = 5.0  # the default sheet: 0.1 mm at 50 px/mm


def _ink_distance(sc):
    return cv2.distanceTransform(np.where(sc.ink_mask, 0, 255).astype(np.uint8), cv2.DIST_L2,
                                 cv2.DIST_MASK_PRECISE)


def _render(xy, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sc = render_configuration(xy, clean=True, **kw)
    return sc, [str(w.message) for w in caught if issubclass(w.category, TruthWarning)]


def test_a_rod_of_zero_length_is_refused():
    with pytest.raises(ParameterError, match=r"rod length must be a finite number > 0.*xy"):
        render_configuration(np.zeros((101, 2)), clean=True)
    # one node off the others is a rod, but one of zero-length segments
    xy = np.zeros((101, 2))
    xy[50:, 0] = 1.0
    with pytest.raises(ParameterError, match="segment.s. of zero length"):
        render_configuration(xy, clean=True)
    render_configuration(np.c_[np.linspace(0.0, 1.0, 101), np.zeros(101)], clean=True)


def test_a_rods_file_holding_a_zero_length_rod_exits_2_naming_it(tmp_path, capsys):
    sim = tmp_path / "sim"
    sim.mkdir()
    np.savez(sim / "rods.npz", config_00000=np.zeros((101, 2)))
    (sim / "params.json").write_text(json.dumps({"command": "quench", "lam": 3e4}))
    assert main(["render", str(sim), "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "rods.npz" in err[0] and "zero length" in err[0]


def test_passes_truth_holds_the_rod_and_its_junctions_lie_on_the_ink():
    """An annealed rod of 80 segments with a loop stack, whose junction point (the mean of run
    ends far apart) can lie on the paper: every truth junction is on the ink (moved there,
    and said, when it is not), and every stack is as long as its passes, so the stacks hold
    the rod."""
    xy = np.load(DATA / "anneal_rod_loop_junction.npy")
    sc, said = _render(xy, draw="passes", lam=5e4)
    d = _ink_distance(sc)
    for x, y in sc.tables["junctions"][["x_px", "y_px"]].to_numpy():
        assert d[int(round(y)), int(round(x))] <= JUNCTION_INK_H * H_PX
    assert sc.summary["truth_warnings"] == said
    st = sc.tables["stacks"]
    an = analyze_rod(xy, lam=5e4)
    np.testing.assert_allclose(st["length_mm"], an.stacks["length"] * sc.summary["rod_length_mm"])
    assert (st["n_br"] * st["length_mm"]).sum() == pytest.approx(sc.summary["rod_length_mm"],
                                                                 rel=1e-9)


def test_a_junction_on_the_paper_is_moved_where_its_stacks_meet():
    """Two bands meeting at (20, 10) and a third apart; the junction point of the three lies
    on the paper 30 px away: it goes to where two of its stacks' inks touch, and one message
    says how far it lay and moved."""
    stacks = pd.DataFrame({"stack_id": [0, 1, 2], "junction_a": [0, 0, 0],
                           "junction_b": [-1, -1, -1], "n_br": [1, 1, 1],
                           "width_mm": [0.1, 0.1, 0.1]})
    junctions = pd.DataFrame({"junction_id": [0], "x_px": [20.0], "y_px": [40.0],
                              "n_stacks": [3]})
    labels = np.zeros((60, 60), np.int32)
    labels[8:12, 2:20] = 1
    labels[8:12, 20:40] = 2
    labels[30:34, 50:58] = 3
    moved, said = _junctions_onto_ink(junctions, stacks, labels, labels > 0, 15.0,
                                      px_per_mm=50.0)
    x, y = moved.loc[0, ["x_px", "y_px"]]
    assert abs(x - 19.5) <= 1.5 and 8 <= y <= 12
    assert len(said) == 1 and said[0].startswith("junction 0 (3 stacks) lay 29 px")
    near, none = _junctions_onto_ink(junctions.assign(y_px=14.0), stacks, labels, labels > 0,
                                     15.0, px_per_mm=50.0)
    assert none == [] and near.equals(junctions.assign(y_px=14.0))


def test_a_render_without_a_defect_of_its_truth_says_nothing():
    n = 300
    xy = resample(hairpin(0.25 * 0.5 / n, arm=0.3), n)
    sc, said = _render(xy, draw="passes", rod_length_mm=60.0)
    assert said == [] and sc.summary["truth_warnings"] == []
    # its fold lies within one node: the truth's energy there is recorded as such
    assert sc.summary["hairpin_energy_share"] == pytest.approx(render.hairpin_nodes(xy)[1])


def test_a_fold_within_one_node_holds_its_share_of_the_truths_energy():
    """A fold tighter than one segment turns the rod by nearly pi at one node, which the
    discrete energy prices at up to 4 / ds and no drawing shows (a quenched rod: 44 % of its
    energy at one node); a fold resolved over many nodes has none."""
    n = 300
    count, share = render.hairpin_nodes(resample(hairpin(0.25 * 0.5 / n, arm=0.3), n))
    assert count == 1 and 0.8 < share <= 1.0
    assert render.hairpin_nodes(resample(hairpin(0.02, arm=0.3), n)) == (0, 0.0)
    t = np.linspace(0.0, np.pi, n + 1)
    assert render.hairpin_nodes(np.c_[np.cos(t), np.sin(t)] / np.pi) == (0, 0.0)


def _trimmed_short(monkeypatch):
    """Band ends left unjoined keep the hook's trim: drawn short of where their passes end."""
    monkeypatch.setattr(render, "_untrimmed_ends", lambda own, full, i0, i1, hooks: own)


def test_bands_a_junction_holds_together_that_do_not_touch_are_flagged(monkeypatch):
    """A quenched rod of 300 segments, drawn in one piece of ink; with its unjoined band ends
    trimmed, the bands of two of its junctions stop short of each other (three networks for
    the analysis)."""
    xy = np.load(DATA / "quench_rod_5.npy")
    sc, said = _render(xy, lam=3e4, seed=2)
    assert cv2.connectedComponents(sc.ink_mask.astype(np.uint8), connectivity=8)[0] - 1 == 1
    assert not any("drawn rod is cut" in m for m in said)
    _trimmed_short(monkeypatch)
    sc, said = _render(xy, lam=3e4, seed=2)
    n, _ = cv2.connectedComponents(sc.ink_mask.astype(np.uint8), connectivity=8)
    assert n - 1 == 3
    assert any("junctions 1, 6 do not touch: the drawn rod is cut" in m for m in said)
    assert said == sc.summary["truth_warnings"]


def test_an_unjoined_band_end_reaches_the_band_its_pass_ends_in():
    """A quenched rod of 60 segments: a stack's tip is not joined to its junction point
    (across the paper) and keeps its whole length, into the arm that continues it: one piece
    of ink. Its three-layer band (a pass and a hairpin lying along it) goes on as the single
    pass beyond the hairpin's fold; such a band is drawn at its larger count over its whole
    length (simulate.render, "Rod ends"), more rod than the rod, and the render says so."""
    xy = np.load(DATA / "quench_rod_cut_join.npy")
    sc, said = _render(xy, lam=3e4, seed=2)
    n, _ = cv2.connectedComponents(sc.ink_mask.astype(np.uint8), connectivity=8)
    assert n - 1 == 1
    assert sorted(sc.tables["stacks"]["n_br"]) == [1, 1, 2, 3]
    assert len(said) == 1 and "the truth's stack lengths are not the rod's" in said[0]


@pytest.fixture(scope="module")
def quench_n300_seed1():
    """The first rod of ``quench --n-configs 6 --seed 1``: five voids above s_min, the line
    of its one-pass stack 14 ending inside the three-layer band of stack 8 at junction 3,
    112 px from the junction point (not joined: its join would cross 58 px of paper)."""
    xy = np.load(DATA / "quench_rod_n300_seed1.npy")
    return xy, analyze_rod(xy, lam=LAMBDA)


def _rod_voids(analysis, sc, s_min_mm2=1.0):
    return int(np.sum(analysis.voids["area"] * sc.params["rod_length_mm"] ** 2 >= s_min_mm2))


def test_an_unjoined_band_end_keeps_the_voids_it_closes(quench_n300_seed1):
    xy, an = quench_n300_seed1
    sc, said = _render(xy, analysis=an, hole_radius_mm="auto")
    assert _rod_voids(an, sc) == 5
    assert sc.summary["n_voids"] == 5
    assert said == []


def test_bands_apart_at_their_junction_and_lost_voids_are_flagged(quench_n300_seed1,
                                                                   monkeypatch):
    """Drawn 9 px short of the band it ends in, stack 14 joins the network elsewhere (one
    ink component) but not at junction 3: two voids open into their neighbours."""
    _trimmed_short(monkeypatch)
    xy, an = quench_n300_seed1
    sc, said = _render(xy, analysis=an, hole_radius_mm="auto")
    n, _ = cv2.connectedComponents(sc.ink_mask.astype(np.uint8), connectivity=8)
    assert n - 1 == 1 and sc.summary["n_voids"] == 3
    assert any("bands of junction 3 do not all touch there" in m for m in said)
    assert any("the truth has 3 voids, the rod 5" in m for m in said)
    assert said == sc.summary["truth_warnings"]


def test_apart_junctions_are_those_whose_bands_do_not_touch_there():
    """Stacks 0 and 1 meet at junction 0; stack 2 (also ending there) stops 6 px short of
    them, its other end joining stack 1's far end at junction 1: one piece of ink."""
    ends = np.array([[-1, 0], [0, 1], [0, 1]])
    lines = [np.array([[10.0, 20.0], [40.0, 20.0]]), np.array([[40.0, 20.0], [80.0, 20.0]]),
             np.array([[40.0, 33.0], [80.0, 33.0], [80.0, 20.0]])]
    bands = [[(line, 7.0)] for line in lines]
    points = {0: (40.0, 20.0), 1: (80.0, 20.0)}
    assert _apart_junctions(ends, lines, bands, points, (60, 100), 15.0) == [0]
    lines[2] = np.array([[40.0, 26.0], [80.0, 26.0], [80.0, 20.0]])  # 1 px of overlap
    bands = [[(line, 7.0)] for line in lines]
    assert _apart_junctions(ends, lines, bands, points, (60, 100), 15.0) == []


def test_a_truth_void_count_outside_the_rods_is_flagged():
    # areas and perimeters in units of L; a rod of 10 mm: 2 and 4 mm^2, 5 mm around
    voids = pd.DataFrame({"area": [0.02, 0.04], "perimeter": [0.5, 0.5]})
    assert _void_count_check(2, voids, 10.0, 1.0, 0.14, 0.2) is None
    assert "the truth has 1 void, the rod 2" in _void_count_check(1, voids, 10.0, 1.0, 0.14, 0.2)
    assert "closes voids" in _void_count_check(3, voids, 10.0, 1.0, 0.14, 0.2)
    # a void that the bands' width can take below s_min may be missing
    assert _void_count_check(1, voids, 10.0, 1.0, 0.6, 0.2) is None


def test_disconnected_junctions_are_those_whose_bands_do_not_touch():
    stacks = pd.DataFrame({"stack_id": [0, 1, 2], "junction_a": [-1, 0, 0],
                           "junction_b": [0, 1, -1], "n_br": [1, 1, 1]})
    labels = np.zeros((20, 40), np.int32)
    labels[5:8, 2:12] = 1
    labels[5:8, 12:20] = 2  # touches stack 0
    labels[5:8, 30:38] = 3  # a gap of paper from both
    assert _disconnected_junctions(stacks, labels, labels > 0) == [0]
    labels[5:8, 20:30] = 3
    assert _disconnected_junctions(stacks, labels, labels > 0) == []


def test_a_truth_holding_another_rod_length_is_flagged():
    stacks = pd.DataFrame({"n_br": [1, 3], "length_mm": [10.0, 30.0]})
    assert _rod_drawn_check(stacks, 100.0) is None
    over = 100.0 / (1 + TRUTH_LENGTH_TOLERANCE) * 0.99
    assert "+21 %" in _rod_drawn_check(stacks, over)
    assert issubclass(TruthWarning, QualityWarning)


def _sim(tmp_path, xy, params):
    sim = tmp_path / "sim"
    sim.mkdir()
    np.savez(sim / "rods.npz", config_00000=xy)
    (sim / "params.json").write_text(json.dumps(params))
    return sim


def test_cli_names_the_scene_of_a_truth_warning(tmp_path, capsys, monkeypatch):
    _trimmed_short(monkeypatch)  # a drawing cut at a junction
    sim = _sim(tmp_path, np.load(DATA / "quench_rod_5.npy"),
               {"command": "quench", "lam": 3e4})
    out = tmp_path / "s"
    assert main(["render", str(sim), "--out", str(out), "--clean", "--seed", "2"]) == 0
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if "do not touch" in ln]
    assert len(err) == 1
    assert err[0].startswith(f"warning: {out / 'config_00000'}: the bands of junction")
    summary = json.loads((out / "config_00000" / "truth" / "summary.json").read_text())
    assert any("do not touch" in m for m in summary["truth_warnings"])


@pytest.mark.filterwarnings("ignore::simulate.render.TruthWarning")
def test_render_json_records_the_sources_lambda_and_delta(tmp_path):
    sim = _sim(tmp_path, np.load(DATA / "quench_rod_5.npy"),
               {"command": "quench", "lam": 3e4, "contact_distance": 0.002})
    render_directory(sim, tmp_path / "s", clean=True)
    p = json.loads((tmp_path / "s" / "render.json").read_text())["params"]
    assert p["lam"] == 3e4 and p["contact_distance"] == 0.002
    assert p["rod_length_mm"] is None  # a quench's depends on each rod: its scene's params


@pytest.mark.filterwarnings("ignore::simulate.render.TruthWarning")
def test_render_json_records_the_compactions_wall_and_scale(tmp_path):
    xy = np.load(DATA / "quench_rod_5.npy")
    sim = _sim(tmp_path, xy, {"command": "compact", "thickness": 2e-3, "wall_radius": 0.1})
    render_directory(sim, tmp_path / "s", clean=True)
    p = json.loads((tmp_path / "s" / "render.json").read_text())["params"]
    scene = json.loads((tmp_path / "s" / "config_00000" / "params.json").read_text())
    assert p["lam"] == 0.0
    assert p["rod_thickness"] == 2e-3 and p["wall_radius"] == 0.1
    assert p["rod_length_mm"] == pytest.approx(scene["rod_length_mm"]) == pytest.approx(50.0)


@pytest.mark.filterwarnings("ignore::simulate.render.TruthWarning")
def test_a_render_recorded_with_the_sources_values_unset_resumes(tmp_path):
    """A render.json that recorded lambda at the API's default and delta unset (the values
    come from the source's params.json, compared on their own) is the same render."""
    xy = np.load(DATA / "quench_rod_5.npy")
    sim = tmp_path / "sim"
    sim.mkdir()
    np.savez(sim / "rods.npz", config_00000=xy, config_00001=xy[::-1].copy())
    (sim / "params.json").write_text(json.dumps({"command": "quench", "lam": 3e4}))
    out = tmp_path / "s"
    render_directory(sim, out, clean=True, configs=["config_00000"])
    rec = json.loads((out / "render.json").read_text())
    rec["params"].update(lam=7e5, contact_distance=None, rod_length_mm=None)
    (out / "render.json").write_text(json.dumps(rec))
    render_directory(sim, out, clean=True)
    assert sorted(p.name for p in out.glob("config_*")) == ["config_00000", "config_00001"]
    rec["params"].update(px_per_mm=40.0)
    (out / "render.json").write_text(json.dumps(rec))
    with pytest.raises(Exception, match="px-per-mm|px_per_mm"):
        render_directory(sim, out, clean=True)
