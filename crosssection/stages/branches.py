"""Stage 11: branches and their bending energy (paper, sections "Energetical properties" and
"Curvature of branches").

A stack of ``n_br`` layers carries ``n_br`` branches; each branch gets the stack's centerline
length and curvature (paper: "Branches that are in close contact and delimited by the same
junction points define a multi-branched stack"). The layers of a stack have slightly different
radii (offset by h each); like the paper we neglect that.

Energy of a branch, dimensionless (paper, "Expression of energy"; e = L int kappa^2 ds with L
the rod length, so that a rod of unit length has e = int kappa~^2 ds~):

    e = L * int_0^l f(kappa) ds,   f(kappa) = kappa^2                      if |kappa| <= kappa_c
                                            = kappa_c (2 |kappa| - kappa_c) otherwise

The linear branch beyond the plastic threshold kappa_c is the paper's plastic softening; it is
continuous with the same slope at |kappa| = kappa_c. Integrals use the trapezoid rule on the
centerline samples. The curvature noise of the window fit adds its variance v to the mean of
kappa^2 wherever f is quadratic; v is measured on the scan
(:func:`crosssection.stages.curvature.noise_variance`) and removed there, the energy never
going below zero.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd

from crosssection.core.errors import ParameterError
from crosssection.core.schema import BRANCH_COLUMNS
from crosssection.params import _number

__all__ = ["bending_energy", "energy_density", "stack_energies", "branch_table",
           "rod_length_mm"]


def energy_density(kappa_per_mm, kappa_c_per_mm=None) -> np.ndarray:
    """Integrand f(kappa) of the bending energy, 1/mm^2.

    Parameters
    ----------
    kappa_per_mm : array
        Local curvature.
    kappa_c_per_mm : float, optional
        Plastic threshold; ``None`` (or inf) for purely elastic.

    Returns
    -------
    ndarray
        ``kappa^2``, replaced by ``kappa_c (2 |kappa| - kappa_c)`` where ``|kappa| > kappa_c``.
    """
    k = np.abs(np.asarray(kappa_per_mm, dtype=np.float64))
    f = k * k
    if kappa_c_per_mm is not None and np.isnan(kappa_c_per_mm):
        raise ParameterError("plastic threshold kappa_c is NaN (None or inf: purely elastic)")
    if kappa_c_per_mm is not None and np.isfinite(kappa_c_per_mm):
        kc = float(kappa_c_per_mm)
        if kc <= 0:
            raise ParameterError(f"plastic threshold kappa_c must be > 0, got {kc}")
        f = np.where(k > kc, kc * (2.0 * k - kc), f)
    return f


def bending_energy(kappa_per_mm, s_mm, *, rod_length_mm, kappa_c_per_mm=None,
                   noise_var_per_mm2: float = 0.0) -> float:
    """Dimensionless bending energy ``e = L int f(kappa) ds`` of one branch.

    Parameters
    ----------
    kappa_per_mm : array (n,)
        Local curvature along the branch, 1/mm.
    s_mm : array (n,)
        Arc length of the samples, mm (increasing).
    rod_length_mm : float
        Rod length L, mm (the pipeline's ``rod_length_used_mm``: the given
        ``rod_length_mm``, else the measured sum of n_br * length over stacks).
    kappa_c_per_mm : float, optional
        Plastic threshold (paper: 0.54 or 0.24 1/mm depending on the sheets).
    noise_var_per_mm2 : float
        Variance of the curvature noise, 1/mm^2 (module docstring): removed from ``kappa^2``
        where ``f`` is quadratic.

    Returns
    -------
    float
        e (0 for fewer than two samples).
    """
    k = np.asarray(kappa_per_mm, dtype=np.float64)
    s = np.asarray(s_mm, dtype=np.float64)
    if k.shape != s.shape:
        raise ParameterError(f"kappa and s have different shapes {k.shape} != {s.shape}")
    _number("rod_length_mm", rod_length_mm, allow_equal=True)
    if len(s) < 2:
        return 0.0
    if np.any(s[1:] < s[:-1]):
        raise ParameterError("s_mm must be increasing along the branch")
    f = energy_density(k, kappa_c_per_mm)
    v = float(noise_var_per_mm2)
    if not np.isfinite(v) or v < 0:
        raise ParameterError(f"noise variance must be finite and >= 0, got {v}")
    ds = s[1:] - s[:-1]  # np.diff(s)
    if v > 0:
        quadratic = (np.ones_like(k) if kappa_c_per_mm is None
                     else (np.abs(k) <= float(kappa_c_per_mm)).astype(np.float64))
        integral = float(_trapezoid(f, ds)) - v * float(_trapezoid(quadratic, ds))
        return float(rod_length_mm) * max(integral, 0.0)
    return float(rod_length_mm) * float(_trapezoid(f, ds))


def _trapezoid(y, ds):
    """``np.trapezoid(y, s)`` of 1-D arrays, given ``ds = np.diff(s)``: numpy's arithmetic
    (``ds * (y[1:] + y[:-1]) / 2.0``, summed) without its handling of any axis, which costs
    as much as the sum on a stack's samples (the energies of the 245 stacks of the dense
    2000x2000 benchmark scan: 2.6 ms, against 3.9 ms with ``np.trapezoid``)."""
    return (ds * (y[1:] + y[:-1]) / 2.0).sum()


def rod_length_mm(lengths_mm, n_br) -> float:
    """Rod length ``L = sum n_br * length`` over stacks, mm."""
    n, ln = np.asarray(n_br, dtype=np.float64), np.asarray(lengths_mm, float)
    if n.shape != ln.shape:
        raise ParameterError(f"lengths_mm and n_br have different shapes {ln.shape} != "
                             f"{n.shape}")
    return float(np.sum(n * ln))


def _stack_ids(stacks, m):
    if stacks is None:
        return np.arange(m)
    if isinstance(stacks, pd.DataFrame):
        return stacks["stack_id"].to_numpy()
    return np.asarray(stacks)


def stack_energies(profiles: Sequence, *, rod_length_mm, kappa_c_per_mm=None) -> np.ndarray:
    """The energy ``e`` of one branch of every stack (:func:`bending_energy` of its profile,
    the scan's noise floor removed), in profile order.

    All profiles at once, to the bit of :func:`bending_energy` profile by profile: the
    integrands element by element on the profiles one after the other, and every trapezoid
    sum by numpy's own summation (:func:`crosssection.stages.curvature._trapz_ranges`); the
    same errors, raised for the first profile that has one. A dozen numpy calls per stack
    cost more than their arithmetic: 0.8 ms for the 245 stacks of the dense 2000 x 2000
    benchmark scan, against 2.7 ms stack by stack.
    """
    from crosssection.stages.curvature import _pymax, _trapz_ranges

    ks, ss, vs = [], [], []
    kc_bad = (kappa_c_per_mm is not None and np.isfinite(kappa_c_per_mm)
              and float(kappa_c_per_mm) <= 0)
    for p in profiles:
        k = np.asarray(p.kappa_per_mm, dtype=np.float64)
        s = np.asarray(p.s_mm, dtype=np.float64)
        if k.shape != s.shape:
            raise ParameterError(f"kappa and s have different shapes {k.shape} != {s.shape}")
        v = 0.0
        if len(s) >= 2:
            if kc_bad:
                energy_density(k[:0], kappa_c_per_mm)  # raises bending_energy's error
            v = float(getattr(p, "noise_var_per_mm2", 0.0))
            if not math.isfinite(v) or v < 0:
                raise ParameterError(f"noise variance must be finite and >= 0, got {v}")
        ks.append(k)
        ss.append(s)
        vs.append(v)
    if any(k.ndim != 1 for k in ks):  # (not profiles: one by one)
        return np.array([bending_energy(p.kappa_per_mm, p.s_mm, rod_length_mm=rod_length_mm,
                                        kappa_c_per_mm=kappa_c_per_mm,
                                        noise_var_per_mm2=getattr(p, "noise_var_per_mm2", 0.0))
                         for p in profiles], dtype=np.float64).reshape(-1)
    m = len(ks)
    if m == 0:
        return np.zeros(0)
    n = np.fromiter((len(s) for s in ss), np.int64, count=m)
    offs = np.zeros(m + 1, np.int64)
    np.cumsum(n, out=offs[1:])
    k, s = np.concatenate(ks), np.concatenate(ss)
    L = _number("rod_length_mm", rod_length_mm, allow_equal=True)
    tf = _trapz_ranges(energy_density(k, kappa_c_per_mm), s, offs[:-1], offs[1:])
    e = L * tf
    v = np.array(vs)
    noisy = (v > 0) & (n >= 2)
    if noisy.any():
        quadratic = (np.ones_like(k) if kappa_c_per_mm is None
                     else (np.abs(k) <= float(kappa_c_per_mm)).astype(np.float64))
        integral = tf - v * _trapz_ranges(quadratic, s, offs[:-1], offs[1:])
        e = np.where(noisy, L * _pymax(integral, 0.0), e)
    e[n < 2] = 0.0
    return e


def branch_table(stacks, profiles: Sequence, n_br, regions, *, rod_length_mm=None,
                 kappa_c_per_mm=None, energies=None) -> pd.DataFrame:
    """One row per branch: every stack of ``n_br`` layers contributes ``n_br`` branches.

    Parameters
    ----------
    stacks : DataFrame with ``stack_id``, array of stack ids, or None
        Stack ids in the order of ``profiles`` (None: 0..M-1).
    profiles : sequence of CurvatureProfile
        One per stack (``crosssection.stages.curvature.stack_curvature``).
    n_br : array (M,) int
        Branches per stack (values < 1 contribute no branch).
    regions : sequence of str (M,)
        ``"bulk"`` / ``"periphery"`` per stack (``crosssection.stages.hole.classify_regions``).
    rod_length_mm : float, optional
        L; default ``sum n_br * length_mm``.
    kappa_c_per_mm : float, optional
        Plastic threshold.
    energies : array (M,), optional
        :func:`stack_energies` of ``profiles`` when already computed (with the same L).

    Returns
    -------
    DataFrame
        Columns :data:`crosssection.core.schema.BRANCH_COLUMNS`: ``branch_id`` sequential in
        stack order, ``stack_id``, ``length_mm``, ``kappa_pm``, ``kappa_plus``, ``kappa_m``
        (1/mm), ``energy`` (dimensionless), ``region``.
    """
    m = len(profiles)
    ids = _stack_ids(stacks, m)
    n_br = np.asarray(n_br, dtype=np.int64).reshape(-1)
    regions = list(regions) if regions is not None else ["bulk"] * m
    if not (len(ids) == len(n_br) == len(regions) == m):
        raise ParameterError(
            f"branch_table: {m} profiles, {len(ids)} stack ids, {len(n_br)} n_br, "
            f"{len(regions)} regions")
    lengths = np.array([p.length_mm for p in profiles], dtype=np.float64)
    if rod_length_mm is None:
        rod_length_mm = float(np.sum(np.clip(n_br, 0, None) * lengths))
    if energies is None:
        energies = stack_energies(profiles, rod_length_mm=rod_length_mm,
                                  kappa_c_per_mm=kappa_c_per_mm)
    energies = np.asarray(energies, dtype=np.float64)
    reps = np.clip(n_br, 0, None)
    idx = np.repeat(np.arange(m), reps)
    df = pd.DataFrame({
        "branch_id": np.arange(len(idx), dtype=np.int64),
        "stack_id": ids[idx].astype(np.int64) if len(idx) else np.zeros(0, np.int64),
        "length_mm": lengths[idx],
        "kappa_pm": np.array([p.kappa_pm for p in profiles], float)[idx],
        "kappa_plus": np.array([p.kappa_plus for p in profiles], float)[idx],
        "kappa_m": np.array([p.kappa_m for p in profiles], float)[idx],
        "energy": energies[idx],
        "region": np.array(regions, dtype=object)[idx] if len(idx) else np.array([], object),
    })
    return df[BRANCH_COLUMNS]
