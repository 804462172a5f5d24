"""Stage 11: bending energy and the branch table (crosssection.stages.branches)."""
from __future__ import annotations

import numpy as np
import pytest

from crosssection.stages.branches import bending_energy, branch_table, energy_density
from crosssection.stages.curvature import CurvatureProfile, stack_curvature
from crosssection.core.errors import ParameterError
from crosssection.core.schema import BRANCH_COLUMNS


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_arc_energy_is_L_l_over_r2(seed):
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.5, 5.0)          # mm
    ell = rng.uniform(0.5, 2 * np.pi * r)
    L = rng.uniform(100, 2000)
    s = np.linspace(0, ell, int(rng.integers(20, 500)))
    k = np.full_like(s, 1 / r) * rng.choice([-1, 1])
    assert bending_energy(k, s, rod_length_mm=L) == pytest.approx(L * ell / r**2, rel=1e-12)


@pytest.mark.parametrize("seed", [4, 5, 6])
def test_plastic_threshold_formula(seed):
    rng = np.random.default_rng(seed)
    s = np.sort(rng.uniform(0, 10, 300))
    k = rng.normal(0, 2.0, 300)
    kc = rng.uniform(0.3, 1.5)
    L = 500.0
    e_el = bending_energy(k, s, rod_length_mm=L)
    e_pl = bending_energy(k, s, rod_length_mm=L, kappa_c_per_mm=kc)
    f = np.where(np.abs(k) > kc, kc * (2 * np.abs(k) - kc), k**2)
    assert e_pl == pytest.approx(L * np.trapezoid(f, s), rel=1e-12)
    assert e_pl < e_el            # kappa_c (2|k| - kappa_c) <= k^2 always
    # a constant arc above threshold: e = L l kc (2/r - kc) exactly
    r, ell = 0.5, 3.0
    ss = np.linspace(0, ell, 50)
    e = bending_energy(np.full(50, 1 / r), ss, rod_length_mm=L, kappa_c_per_mm=kc)
    if 1 / r > kc:
        assert e == pytest.approx(L * ell * kc * (2 / r - kc), rel=1e-12)


def test_density_continuous_at_threshold():
    kc = 0.54
    k = np.array([kc - 1e-9, kc, kc + 1e-9])
    f = energy_density(k, kc)
    assert np.allclose(f, kc**2, atol=1e-8)
    with pytest.raises(ParameterError):
        energy_density(k, -1.0)


def test_energy_from_measured_arc():
    """A rasterised circle of radius 100 px at 50 px/mm: e = L * 2 pi R / R^2 within 4 %."""
    R = 100.0
    t = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
    pts = np.round(np.c_[300.3 - R * np.sin(t), 300.7 + R * np.cos(t)]).astype(int)
    pts = pts[np.r_[True, np.any(np.diff(pts, axis=0) != 0, axis=1)]]
    prof = stack_curvature(pts[:-1], n_br=1, thickness_px=5, px_per_mm=50.0)
    L = 1000.0
    e = bending_energy(prof.kappa_per_mm, prof.s_mm, rod_length_mm=L)
    r_mm = R / 50
    assert e == pytest.approx(L * 2 * np.pi / r_mm, rel=0.04)


def _profile(length, kappa, n=30):
    s = np.linspace(0, length, n)
    k = np.full(n, kappa)
    return CurvatureProfile(s, k, length, kappa, abs(kappa), abs(kappa))


@pytest.mark.parametrize("seed", [0, 7])
def test_branch_table_expands_stacks(seed):
    rng = np.random.default_rng(seed)
    m = 6
    profs = [_profile(rng.uniform(1, 5), rng.uniform(-2, 2)) for _ in range(m)]
    n_br = rng.integers(1, 5, m)
    regions = list(rng.choice(["bulk", "periphery"], m))
    ids = np.arange(10, 10 + m)
    df = branch_table(ids, profs, n_br, regions, kappa_c_per_mm=None)
    assert list(df.columns) == BRANCH_COLUMNS
    assert len(df) == n_br.sum()
    assert list(df.branch_id) == list(range(n_br.sum()))
    L = sum(n * p.length_mm for n, p in zip(n_br, profs))
    for sid, g in df.groupby("stack_id"):
        i = sid - 10
        assert len(g) == n_br[i]
        assert np.all(g.region == regions[i])
        p = profs[i]
        assert np.allclose(g.energy, L * p.length_mm * p.kappa_pm**2)
        assert np.allclose(g.length_mm, p.length_mm)
    # total energy of the rod = sum over branches
    assert df.energy.sum() == pytest.approx(L * sum(n * p.length_mm * p.kappa_pm**2
                                                    for n, p in zip(n_br, profs)))


def test_branch_table_mismatch_and_empty():
    with pytest.raises(ParameterError):
        branch_table(None, [_profile(1, 1)], [1, 2], ["bulk"])
    df = branch_table(None, [], [], [])
    assert len(df) == 0 and list(df.columns) == BRANCH_COLUMNS
