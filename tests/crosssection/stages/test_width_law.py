"""The width law read from a scan without a calibration (crosssection.stages.widthlaw)."""
from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import crosssection
from crosssection.core.calibration import Calibration
from crosssection.stages.widthlaw import (FAINT_MARGIN, MIN_CONTRAST, ONE_LAYER_RANGE_H,
                                          STEP_RANGE_H, fit_width_law, junction_closure,
                                          junction_offsets_mm)
from crosssection.truth.network import make_scene
from crosssection.truth.scoring import score

H = 0.1


def _network(rng, n_junctions: int):
    """Stack counts conserved at Y junctions: each junction splits a trunk of n into two of
    k and n - k. Returns the counts and the conservation rows (trunk - branches)."""
    counts, rows = [], []
    for _ in range(n_junctions):
        n = int(rng.integers(2, 9))
        k = int(rng.integers(1, n))
        base = len(counts)
        counts += [n, k, n - k]
        rows.append({base: 1, base + 1: -1, base + 2: -1})
    return np.array(counts, float), rows


@settings(max_examples=60, deadline=None)
@given(a=st.floats(-0.6, 2.0), b=st.floats(STEP_RANGE_H[0] + 0.02, STEP_RANGE_H[1] - 0.02),
       noise=st.floats(0.0, 0.12), seed=st.integers(0, 2**31 - 1))
def test_an_affine_law_is_recovered(a, b, noise, seed):
    rng = np.random.default_rng(seed)
    n, rows = _network(rng, 20)
    width = H * (a + b * n) + rng.normal(0.0, noise * H, len(n))
    fit = fit_width_law(width, rng.uniform(1.0, 10.0, len(n)), rows, thickness_mm=H)
    lo, hi = ONE_LAYER_RANGE_H
    if not lo + 0.05 < a + b < hi - 0.05:  # one layer beyond the accepted range: refused
        if not lo - 0.05 < a + b < hi + 0.05:
            assert not fit.ok
        return
    assert fit.ok, fit.reason
    # the law itself, over the counts drawn, to a fraction of a layer that grows with the widths'
    # scatter (a step and a bend trade off against each other)
    tolerance_layers = 0.1 + 2.0 * noise / b
    k = np.arange(1.0, n.max() + 1)
    assert np.max(np.abs(fit.width_mm(k) - H * (a + b * k))) < tolerance_layers * b * H
    # the counts read back through the law fitted are those the true law reads, wherever a
    # width is further from a half-layer than that tolerance
    layers = np.asarray(fit.calibration().layers(np.clip(width, 1e-6, None)))
    true = (width / H - a) / b
    clear = np.abs(true - np.round(true)) < 0.5 - tolerance_layers
    assert np.array_equal(np.round(layers)[clear], np.round(true)[clear])


def test_the_law_is_followed_out_to_thick_stacks():
    # the hot-wire cut's rim grows as sqrt(n): the thin stacks' line reads 17 layers as 16.3
    rng = np.random.default_rng(11)
    counts, rows = [], []
    for _ in range(25):
        n = int(rng.integers(2, 30))
        k = int(rng.integers(1, n))
        base = len(counts)
        counts += [n, k, n - k]
        rows.append({base: 1, base + 1: -1, base + 2: -1})
    n = np.array(counts, float)
    width = H * (n + 0.4 * np.sqrt(n)) + rng.normal(0.0, 0.03 * H, len(n))
    fit = fit_width_law(width, np.ones(len(n)), rows, thickness_mm=H)
    # bent below the thin stacks' line, by the root that the rim grows as
    assert fit.ok and fit.quadratic_mm == 0 and fit.root_mm == pytest.approx(0.4 * H, rel=0.2)
    layers = np.asarray(fit.calibration().layers(width))
    assert np.array_equal(np.round(layers), n)
    # the premise: the line through the thin stacks alone misreads thick ones
    thin = n <= 6
    b, a = np.polyfit(n[thin], width[thin], 1)
    assert not np.array_equal(np.round((width - a) / b), n)


def test_a_wide_step_is_not_taken_for_its_half():
    # b = 1.8 h: b / 2 = 0.9 h lies in the range searched and fits the lattice as well
    rng = np.random.default_rng(3)
    n, rows = _network(rng, 15)
    fit = fit_width_law(H * (0.2 + 1.8 * n), np.ones(len(n)), rows, thickness_mm=H)
    assert fit.ok and fit.step_mm == pytest.approx(0.18, rel=1e-6)
    assert fit.offset_mm == pytest.approx(0.02, abs=1e-9)


def test_the_junctions_choose_which_lattice_point_is_one_layer():
    # the lattice alone allows offsets 0.3 h, 1.4 h, -0.8 h...: the junctions measure 0.3 h
    rng = np.random.default_rng(5)
    n, rows = _network(rng, 12)
    width = H * (0.3 + 1.1 * n)
    assert np.median(junction_offsets_mm(width, rows)) == pytest.approx(0.03)
    fit = fit_width_law(width, np.ones(len(n)), rows, thickness_mm=H)
    assert fit.one_layer_mm == pytest.approx(0.14)


@pytest.mark.parametrize("seed", range(6))
def test_a_lattice_the_junctions_contradict_is_refused(seed):
    # widths on the clear lattice of w = h (0.3 + 1.1 m), but junctions that conserve the
    # counts w = n h reads and not those of the lattice: the junctions win
    rng = np.random.default_rng(seed)
    m = rng.integers(1, 9, 40).astype(float)
    width = H * (0.3 + 1.1 * m)
    k = np.round(width / H)
    triples = [(i, j, l) for i, j, l in itertools.permutations(range(40), 3)
               if j < l and k[i] == k[j] + k[l] and m[i] != m[j] + m[l]]
    rows = [{i: 1, j: -1, l: -1} for i, j, l in
            (triples[t] for t in rng.choice(len(triples), 20, replace=False))]
    fit = fit_width_law(width, np.ones(40), rows, thickness_mm=H)
    assert not fit.ok
    if "one layer" not in fit.reason:
        assert "junctions confirm" in fit.reason
        assert fit.closure == junction_closure(fit.calibration().layers(width), rows)
        assert fit.closure_linear == junction_closure(width / H, rows) == 1.0
        margin = (fit.closure - fit.closure_linear) * len(rows)
        assert fit.closure < fit.closure_linear or (
            fit.contrast < MIN_CONTRAST and margin < FAINT_MARGIN)


def test_widths_without_layers_read_as_none_are_refused():
    rng = np.random.default_rng(7)
    n, rows = _network(rng, 20)
    for seed in range(10):
        width = np.random.default_rng(seed).uniform(0.1, 0.9, len(n))
        fit = fit_width_law(width, np.ones(len(n)), rows, thickness_mm=H)
        assert not fit.ok, fit


def test_a_faint_lattice_the_junctions_confirm_is_kept():
    # widths scattered by 10 % from stack to stack (a cut's rim varies along the sheet)
    rng = np.random.default_rng(8)
    n, rows = _network(rng, 30)
    width = H * (0.3 + 1.15 * n) * (1.0 + 0.10 * np.clip(rng.normal(size=len(n)), -2.5, 2.5))
    fit = fit_width_law(width, np.ones(len(n)), rows, thickness_mm=H)
    assert fit.contrast < 0.75
    assert fit.ok and fit.closure > fit.closure_linear
    assert fit.one_layer_mm == pytest.approx(0.145, abs=0.03)


def test_too_few_junctions_are_refused():
    fit = fit_width_law(H * (0.3 + 1.1 * np.array([1, 2, 3.0])), np.ones(3),
                        [{0: 1, 1: -1}], thickness_mm=H)
    assert not fit.ok and "junctions" in fit.reason


def test_a_row_with_equal_packs_measures_no_offset():
    assert junction_offsets_mm([0.1, 0.2, 0.3, 0.4], [{0: 1, 1: 1, 2: -1, 3: -1}]).size == 0


def _scene_kw(scene, **extra):
    p = scene.params
    return dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
                hole_radius_mm=p["hole_radius_mm"], hole_center_px=tuple(p["hole_center_px"]),
                **extra)


def _analyze(rgb, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        return crosssection.analyze(rgb, **kw), caught


@pytest.mark.parametrize("law", ["generator", "wide step"])
def test_a_scan_without_its_calibration_is_counted_as_with_it(law):
    n = np.arange(1, 41.0)
    cal = None if law == "generator" else Calibration(tuple(n), tuple(0.02 + 0.13 * n))
    scene = make_scene(seed=12, n_stacks=40, max_layers=6, calibration=cal)
    res, caught = _analyze(scene.rgb, **_scene_kw(scene))
    given, _ = _analyze(scene.rgb, **_scene_kw(scene, calibration=scene.calibration))
    assert np.array_equal(res.stacks["n_br"], given.stacks["n_br"])
    s = score((res.summary, res.tables), (scene.summary, scene.tables), match_px=15)
    assert s["n_br_exact_length_fraction"] == 1.0
    assert abs(s["rod_length_rel_error"]) < 0.01
    law_record = res.summary["width_law"]
    assert law_record["ok"] and law_record["n_junctions"] >= 3
    w1 = float(scene.calibration.width(1.0))
    assert law_record["offset_mm"] + law_record["step_mm"] == pytest.approx(w1, rel=0.05)
    assert res.summary["calibration"].startswith("fitted to the scan")
    # still flagged: the counts rest on a law nobody measured
    flag = next(f for f in res.quality if f.code == "no_calibration")
    assert "read from this scan" in flag.message
    assert any(w.category is crosssection.quality.NoCalibrationWarning for w in caught)


def test_the_linear_law_stays_an_option():
    scene = make_scene(seed=12, n_stacks=40, max_layers=6)
    res, _ = _analyze(scene.rgb, **_scene_kw(scene, width_law="linear"))
    assert "width_law" not in res.summary
    assert res.summary["calibration"] == "linear n*h"
    # w = n h reads the generator's 2-layer stacks (2.57 h) as 3: the rod comes out long
    s = score((res.summary, res.tables), (scene.summary, scene.tables), match_px=15)
    assert s["rod_length_rel_error"] > 0.1


def test_a_given_calibration_is_used_whatever_the_width_law():
    scene = make_scene(seed=12, n_stacks=40, max_layers=6)
    a, _ = _analyze(scene.rgb, **_scene_kw(scene, calibration=scene.calibration))
    b, _ = _analyze(scene.rgb, **_scene_kw(scene, calibration=scene.calibration,
                                           width_law="linear"))
    assert "width_law" not in a.summary
    assert np.array_equal(a.stacks["n_br"], b.stacks["n_br"])


def test_widths_scattered_from_stack_to_stack_are_counted_as_with_the_calibration():
    # a cut's rim varies: 10 % scatter fades the lattice to a contrast about 0.5, and the
    # junctions keep the law found
    scene = make_scene(seed=12, n_stacks=40, max_layers=6, width_scatter=0.10)
    res, _ = _analyze(scene.rgb, **_scene_kw(scene))
    given, _ = _analyze(scene.rgb, **_scene_kw(scene, calibration=scene.calibration))
    law = res.summary["width_law"]
    assert law["ok"] and law["contrast"] < 0.6
    assert law["closure"] > law["closure_linear"]
    assert np.array_equal(res.stacks["n_br"], given.stacks["n_br"])


def test_a_scale_given_wrong_is_named_in_the_flag():
    # px_per_mm given 1.4 times too large: every width reads 1.4 times too narrow in mm, and
    # a layer adds less than a sheet's thickness to a stack
    scene = make_scene(seed=12, n_stacks=40, max_layers=6)
    kw = _scene_kw(scene)
    kw.update(px_per_mm=70.0, hole_radius_mm=kw["hole_radius_mm"] * 50.0 / 70.0)
    res, _ = _analyze(scene.rgb, **kw)
    flag = next(f for f in res.quality if f.code == "no_calibration")
    assert res.summary["width_law"]["ok"]
    assert "less than a sheet" in flag.message and "px_per_mm" in flag.message


def test_the_law_is_written_with_spaced_signs():
    from crosssection.stages.widthlaw import WidthLawFit

    fit = WidthLawFit(ok=True, offset_mm=-0.0038, step_mm=0.0976, contrast=0.9, n_stacks=30,
                      n_junctions=10, root_mm=0.0495)
    assert fit.formula() == "w = -0.0038 + 0.0976 n + 0.0495 sqrt(n) mm"
    fit = WidthLawFit(ok=True, offset_mm=0.01, step_mm=0.1, contrast=0.9, n_stacks=30,
                      n_junctions=10, quadratic_mm=-0.001)
    assert fit.formula() == "w = 0.0100 + 0.1000 n - 1.00e-03 n^2 mm"
