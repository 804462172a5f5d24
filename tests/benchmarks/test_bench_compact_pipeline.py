"""The drawn bands' bending beside the rod's (``benchmarks/bench_compact_pipeline.py``,
``_drawn_energy``): an arc drawn as it bends reads the rod's energy, and the discs around the
junctions take out what lies within the widest band's width of them.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest


@pytest.fixture(scope="module")
def bench(load_script):
    return load_script("bench_compact_pipeline")


def _arc_scene(radius_px=200.0, n_br=3, width_mm=0.4, px=50.0, span=1.5):
    """One stack drawn as an arc, a junction at each end, the rod's energy that of the arc."""
    a = np.linspace(0.0, span, int(radius_px * span) + 1)
    path = 300.0 + radius_px * np.stack([np.sin(a), np.cos(a)], axis=1)  # (row, col)
    length_mm = radius_px * span / px
    rod_int = n_br * length_mm * (px / radius_px) ** 2  # sum n int kappa^2 ds, 1/mm
    L = 1000.0
    stacks = pd.DataFrame({"stack_id": [0], "junction_a": [0], "junction_b": [1],
                           "n_br": [n_br], "width_mm": [width_mm]})
    junctions = pd.DataFrame({"junction_id": [0, 1], "y_px": path[[0, -1], 0],
                              "x_px": path[[0, -1], 1]})
    return SimpleNamespace(tables={"stacks": stacks, "junctions": junctions},
                           params={"px_per_mm": px}, paths_rc=[path],
                           summary={"total_energy": rod_int * L, "rod_length_mm": L})


def test_an_arc_drawn_as_it_bends_reads_the_rods_energy(bench):
    scene = _arc_scene()
    total, outside = bench._drawn_energy(scene)
    assert total == pytest.approx(1.0, rel=0.02)
    # one width (20 px) of arc is inside each junction's disc: 40 of 300 px
    assert outside == pytest.approx(1.0 - 40.0 / 300.0, abs=0.02)


def test_a_hook_into_a_junction_point_is_inside_its_disc(bench):
    scene = _arc_scene()
    path = scene.paths_rc[0]
    # a hook: the last 15 px turn by a quarter turn into the junction point
    t = np.linspace(0.0, 0.5 * np.pi, 40)
    end, d = path[-1], path[-1] - path[-2]
    d /= np.hypot(*d)
    nrm = np.array([-d[1], d[0]])
    hook = end + 10.0 * (np.sin(t)[:, None] * d + (1 - np.cos(t))[:, None] * nrm)
    scene.paths_rc = [np.concatenate([path, hook[1:]])]
    scene.tables["junctions"].loc[1, ["y_px", "x_px"]] = hook[-1]
    total, outside = bench._drawn_energy(scene)
    assert total > 1.5  # the hook bends far more than the arc
    assert outside < 1.0  # and it lies within the junction's disc


def test_the_rod_and_the_analysis_outside_the_discs(bench):
    # the rod itself placed along the drawn arc, and an analysis reading the arc's curvature:
    # both hold the arc's share outside the two junction discs (40 of 300 px inside)
    scene = _arc_scene()
    path = scene.paths_rc[0]
    px, L = scene.params["px_per_mm"], scene.summary["rod_length_mm"]
    scene.params.update(origin_xy=[0.0, 0.0], margin_px=0.0, rod_length_mm=L)
    xy = path[::5, ::-1] / (L * px)  # nodes every 5 px, units of L, (x, y)
    assert bench._rod_outside(xy, scene) == pytest.approx(1.0 - 40.0 / 300.0, abs=0.03)
    s_mm = np.r_[0.0, np.cumsum(np.hypot(*np.diff(path, axis=0).T))] / px
    prof = SimpleNamespace(s_mm=s_mm, kappa_per_mm=np.full(len(path), px / 200.0), rc_px=path)
    result = SimpleNamespace(profiles=[prof], stacks=pd.DataFrame({"n_br": [3]}))
    assert bench._measured_outside(scene, result) == pytest.approx(1.0 - 40.0 / 300.0,
                                                                   abs=0.02)
    # a rod bent only at its ends, inside the discs, holds nothing outside them
    straight = np.stack([np.linspace(0, 5e-3, 60), np.zeros(60)], axis=1)  # 250 px
    bent = np.concatenate([[[0.0, 2e-4]], straight, [[5e-3, 2e-4]]])  # 10-px hooks
    scene.tables["junctions"][["y_px", "x_px"]] = (bent[[0, -1]] * L * px)[:, ::-1]
    assert bench._rod_outside(bent, scene) == pytest.approx(0.0, abs=1e-9)


def test_the_drawn_truths_forks_ignore_one_pixel_gaps_between_strokes(bench):
    # a Y of 12-px bands: one fork where the arms part; a one-pixel slit inside the trunk (two
    # touching strokes a rasterised pixel apart) is ink, a three-pixel one is paper
    import cv2

    ink = np.zeros((300, 300), np.uint8)
    for a, b in (((150, 280), (150, 150)), ((150, 150), (60, 30)), ((150, 150), (240, 30))):
        cv2.line(ink, a, b, 1, 12)
    slit = ink.astype(bool).copy()
    slit[200:260, 150] = False
    forks = bench._skeleton_forks(slit)
    assert len(forks) == 1
    assert np.hypot(*(forks[0] - [150, 150])) < 12
    wide = ink.astype(bool).copy()
    wide[200:260, 149:152] = False
    assert len(bench._skeleton_forks(wide)) > 1  # the slit's loop forks twice more
