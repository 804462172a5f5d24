"""Compaction of a rod of finite thickness by a shrinking hard wall: the ``compact`` subcommand.

``python -m simulate compact --epsilon E [--segments N] [--thickness H] [--n-configs K]
[--seed S] [--noise D] [--contact-distance DELTA] [--wall-rate RATE] [--max-iter M] [--workers W]
[--scheduler ADDR] [--progress | --no-progress] --out DIR``

The quench (:mod:`simulate.ensemble`) confines an infinitely thin rod by a soft quadratic
potential and reaches epsilon ~ 2-4; the experiments of the paper ("Statistical distributions
in the folding of elastic structures", Adda-Bedia, Boudaoud, Boue, Deboeuf) sit at
epsilon = L / (2 pi R) = 8-19 (Table 1). This protocol reaches them.

Protocol
--------
* The rod: open, length L = 1, N segments of fixed length 1/N (restored exactly after every
  step, so the final length is 1 to rounding), bending energy ``int (R'')^2 ds`` discretised
  as in :mod:`simulate.energy` (paper Eq. (8) without the confinement term), hard core
  of thickness h: non-adjacent segments stay at least h apart.
* A hard circular wall of radius R shrinks from around the initial shape to
  ``R = 1 / (2 pi epsilon)``; every node stays within ``R - h/2``. This is the experiment's
  geometric control ("compaction is geometrically controlled in experiments, through the
  available size R", paper section "Simulations vs experiments"): the sheet is pulled through a
  fixed hole, so in units of the rod length the hole shrinks while h/R stays fixed. The
  thickness is therefore ``h = (h/R) R`` at every wall radius and reaches the requested h at
  the end (a thinner rod earlier never creates an overlap). Feeding the rod into a fixed disk
  (injection) was not chosen: it folds the rod in the order it enters, the layered-loop
  geometry of Donato et al., which the paper contrasts with its pulling experiment.
* Default thickness ``h = 0.005 R = 0.005 / (2 pi epsilon)`` (units of L): the experiments'
  h/R is 0.003 (sets 1, 2, 4) to 0.011 (set 3) (Table 1: h/L over R = L/(2 pi epsilon)).
* Initial shapes: the paper's random shapes (white noise D = 750 on the curvature, drawn at
  its resolution of 300 segments, section "Initial configurations", then interpolated in
  tangent angle), centred; seeded per configuration.
* Each iteration is one FIRE step (Bitzek et al. 2006) on the bending force plus stiff springs
  between a node and the nearby segments of other passes (their shared joints subtracted, so
  that a node sliding along a pass feels it once), and between a node and the wall, acting
  within ``MARGIN h`` outside the hard core; forces are projected on
  the fixed segment lengths and the lengths restored by a tridiagonal SHAKE step; a step whose
  restoration does not converge is taken again at half its size (counter ``n_halved_steps``,
  see :func:`_compress`), so the lengths are exact after every step. Contacts come
  from a Verlet list of (node, segment) pairs built with a spatial hash (cell list), O(N).
  The wall moves by at most ``min(6.25e-5 R, h/8)`` per iteration (the step at which the
  ensemble statistics converge, ``docs/validation/compact.md``) and waits while any spring is
  compressed by half its range, so the rod is compacted quasi-statically and no pass ever
  comes closer than h to another; springs stiffen when the packing's pressure holds one at
  that threshold, and when stiffening leaves the compression where it was (the wall's
  position imposes it: a rod lining the wall end to end as a ring once 2 pi R nears L) the
  wall takes one step each time the rod is at rest instead of waiting (see
  :func:`_compress`). Nodes move at most h/4 per iteration.
* Multiresolution: the rod is compacted with N/2^k segments while the wall radius is above
  ``2^k R`` (at least :data:`RESOLUTION` segments per wall radius), each level's segments split
  in two at the next: early, loose stages need few segments and their long-wavelength
  relaxation is what takes a fine rod longest.
* The final relaxation ("hold") at the final wall radius stops when no node force exceeds
  ``ftol * 2 ds / R^3`` and no spring is compressed by half its range, within
  :attr:`CompactParams.hold_iter` iterations (springs left stiff by the compaction soften
  after :data:`HOLD_PATIENCE` of them, see :func:`_compress`); a hold ending at that cap
  unconverged keeps its rod and warns (:class:`HoldWarning`), and configs.csv records its force
  over that scale and its iterations (``n_force``, ``n_hold_iterations``).
* The final rod is checked: every pair of non-adjacent segments at least h apart, every node
  within ``R - h/2``, length 1 within 1e-3; a configuration failing a check is an error
  (never written). Nodes folded flat (a turn above :data:`FLAT_FOLD_DEG`, whose two
  segments come closer than h near the node) are counted (``n_flat_folds``) and warned of
  (:class:`FlatFoldWarning`): none at epsilon 19, a few per rod at 30.

Outputs (same layout as quench, :func:`simulate.ensemble.run_ensemble`): ``DIR/configs.csv``
(:data:`CONFIG_COLUMNS`: epsilon = 1/(2 pi R) of the wall, wall_radius, thickness,
contact_distance, rg (about the wall's centre, as the quench's Rg is taken about its
potential's, paper Eq. (11); a rod pressed to one side of the wall reads 1-2 % more than
about its own centroid) and epsilon_rg = 1/(2 pi Rg), energy_total = energy_bending (a hard wall
stores no confinement energy), N_l = n_stacks, N_br = n_branches, junctions, voids, the final
checks, wall_s, then counters ``n_*``), ``DIR/branches.csv``, ``stacks.csv``, ``voids.csv``
(:func:`simulate.contacts.analyze_rod` with ``lam = 0`` and contact distance 3 h, see
:func:`run_config`), ``DIR/rods.npz`` (key ``config_XXXXX``) and ``DIR/params.json`` (with
``wall_radius`` and ``thickness`` in units of L and the package version). Configuration i uses
the seed ``spawn_seeds(seed, K)[i]``; finished configurations are part files skipped on a
re-run.

Limits: the discretised rod cannot fold tighter than about one segment (ds/2 radius), while
the real sheet folds down to a few h; the rod is open (the experiment's cross-section is a
closed curve) and frictionless. A stretch of rod lining the wall carries the wall's pressure
as a compression along it; with many segments per wall radius (every level starts at
R/ds = N / (pi epsilon): 80 at epsilon 8 and N = 2000, 67 at epsilon 19 and N = 4000, 34 at
epsilon 19 and N = 2000) the compression passes the buckling load of a single segment,
8 N^2 for Eq. (8)'s bending energy on a zigzag of alternate nodes: the stretch buckles into a
zigzag of a few degrees per node, which the continuous rod does not have, and straightens
once the compression is released. The length restoration of those snapping steps is the one
that needs the halving.
Measured cost and statistics: ``docs/validation/compact.md``.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd
from numba import njit

from crosssection.core.errors import AnalysisError, ParameterError
from crosssection.quality import QualityWarning

from simulate.contacts import MIN_CONTACT_DISTANCE
from simulate.geometry import sharp_nodes
from simulate.noise import N_SEGMENTS, NOISE


class FlatFoldWarning(QualityWarning, RuntimeWarning):
    """Nodes of a compacted rod turn by more than :data:`FLAT_FOLD_DEG`: their two segments
    come closer than h within pi h / 2 of the node, the rod folding flat through itself
    there (configs.csv ``n_flat_folds``)."""


class HoldWarning(QualityWarning, RuntimeWarning):
    """The final hold of a compaction ended at its iteration cap unrelaxed: the rod passes its
    checks, with node forces or spring compressions above the tolerance (configs.csv
    ``n_force``, ``n_compression``)."""

#: thickness over hole radius of the default rod (experiments: h/R = 0.003-0.011, Table 1)
H_OVER_R = 0.005
#: contact and wall springs act within ``MARGIN * h`` outside the hard core
MARGIN = 0.25
#: spring stiffness in units of ``N^3`` (the bending stiffness at the scale of one segment)
STIFFNESS = 8.0
#: coarsest level: at least this many segments per wall radius at its end
RESOLUTION = 16.0
#: FIRE's largest time step in units of ``N^-3/2`` (stable below ~0.2 for these stiffnesses)
DT_MAX = 0.12
#: a step whose length restoration does not converge is retried at most this many times,
#: halved each time (see :func:`_compress`)
SHAKE_HALVINGS = 8
#: iterations of the final hold after which springs far below their range soften (see
#: :func:`_compress`): beyond the longest hold measured to converge with the compaction's
#: springs (154 000 at N = 2000, 178 000 at N = 4000, ``docs/validation/compact.md``)
HOLD_PATIENCE = 200_000
#: default contact distance of the analysis, in units of the thickness (see run_config)
CONTACT_DISTANCE = 3.0
#: A node turning by more than this folds flat through the hard core: its two segments, of
#: length ds >> h, lie ``2 s cos(theta / 2)`` apart at a distance s from it, below h at
#: ``s = pi h / 2`` (the half-turn of a fold of diameter h) once ``cos(theta / 2) < 1 / pi``.
#: The node-segment contacts hold only the next node, at ``ds sin(pi - theta)``; measured:
#: no node above 42 degrees at epsilon 19 (4 rods, N = 2000), 2-7 nodes at 176 degrees per
#: rod at epsilon 30 (3 rods), holding 8-18 % of the rod's bending energy; a fourth rod at 30
#: (seed 5) folds flat at 11 nodes (166-176 degrees) holding 35 % of it.
FLAT_FOLD_DEG = 2.0 * math.degrees(math.acos(1.0 / math.pi))
#: largest area fraction ``L h / (pi (R - h/2)^2)`` accepted (see :func:`check_params`)
MAX_AREA_FRACTION = 0.6

# ----------------------------------------------------------------------------------------
# numba kernels


@njit(cache=True, inline="always")
def _ptseg(px, py, ax, ay, bx, by):
    """Squared distance from P to segment A + t (B - A) and the parameter t of the closest
    point."""
    ux = bx - ax
    uy = by - ay
    l2 = ux * ux + uy * uy
    t = ((px - ax) * ux + (py - ay) * uy) / l2
    t = min(max(t, 0.0), 1.0)
    ex = ax + t * ux - px
    ey = ay + t * uy - py
    return ex * ex + ey * ey, t


@njit(cache=True)
def _near_pairs(x, cutoff):
    """(node, segment) pairs closer than ``cutoff``, the segment not holding the node, sorted
    by node then segment: a spatial hash of the segment midpoints (cells of side max segment
    length + cutoff), O(N). Returns ``(pairs (P, 2), start (N+2,))`` with the pairs of node
    ``i`` at ``start[i]:start[i+1]``."""
    n = x.shape[0] - 1
    lmax = 0.0
    for a in range(n):
        lmax = max(lmax, math.hypot(x[a + 1, 0] - x[a, 0], x[a + 1, 1] - x[a, 1]))
    cell = lmax + cutoff
    size = 1
    while size < 2 * n:
        size *= 2
    head = np.full(size, -1, np.int64)
    nxt = np.empty(n, np.int64)
    ci = np.empty(n, np.int64)
    cj = np.empty(n, np.int64)
    for a in range(n):
        ci[a] = int(math.floor(0.5 * (x[a, 0] + x[a + 1, 0]) / cell))
        cj[a] = int(math.floor(0.5 * (x[a, 1] + x[a + 1, 1]) / cell))
        h = ((ci[a] * 73856093) ^ (cj[a] * 19349663)) & (size - 1)
        nxt[a] = head[h]
        head[h] = a
    cap = 4 * n + 16
    pairs = np.empty((cap, 2), np.int64)
    start = np.zeros(n + 2, np.int64)
    m = 0
    c2 = cutoff * cutoff
    for i in range(n + 1):
        gi = int(math.floor(x[i, 0] / cell))
        gj = int(math.floor(x[i, 1] / cell))
        m0 = m
        for oi in range(-1, 2):
            for oj in range(-1, 2):
                ti = gi + oi
                tj = gj + oj
                b = head[((ti * 73856093) ^ (tj * 19349663)) & (size - 1)]
                while b >= 0:
                    if b != i and b != i - 1 and ci[b] == ti and cj[b] == tj:
                        d2, t = _ptseg(x[i, 0], x[i, 1], x[b, 0], x[b, 1], x[b + 1, 0],
                                       x[b + 1, 1])
                        if d2 < c2:
                            if m == cap:
                                bigger = np.empty((2 * cap, 2), np.int64)
                                bigger[:m] = pairs[:m]
                                pairs = bigger
                                cap *= 2
                            # insertion keeps the segments of node i sorted
                            q = m
                            while q > m0 and pairs[q - 1, 1] > b:
                                pairs[q, 0] = pairs[q - 1, 0]
                                pairs[q, 1] = pairs[q - 1, 1]
                                q -= 1
                            pairs[q, 0] = i
                            pairs[q, 1] = b
                            m += 1
                    b = nxt[b]
        start[i + 1] = m
    start[n + 1] = m
    return pairs[:m].copy(), start


@njit(cache=True)
def _tridiag(lo, di, up, rhs):
    """Thomas algorithm: solve the tridiagonal system (lo[j] x[j-1] + di[j] x[j] +
    up[j] x[j+1] = rhs[j]) in place of a copy; returns x."""
    m = di.shape[0]
    c = np.empty(m)
    d = np.empty(m)
    c[0] = up[0] / di[0]
    d[0] = rhs[0] / di[0]
    for j in range(1, m):
        w = di[j] - lo[j] * c[j - 1]
        c[j] = up[j] / w
        d[j] = (rhs[j] - lo[j] * d[j - 1]) / w
    for j in range(m - 2, -1, -1):
        d[j] -= c[j] * d[j + 1]
    return d


@njit(cache=True, inline="always")
def _chain_matrix(ax, ay, bx, by, lo, di, up):
    """The tridiagonal matrix ``M[j, k] = (2 if j == k else -1) a_j . b_k`` (|j - k| <= 1) of
    a chain's segment constraints, into ``lo``, ``di``, ``up``: with ``b = a`` the Gram matrix
    ``J J^T`` of the force projection, with ``b`` the directions before the step the Newton
    matrix of the length restoration."""
    n = ax.shape[0]
    for j in range(n):
        di[j] = 2.0 * (ax[j] * bx[j] + ay[j] * by[j])
        if j > 0:
            lo[j] = -(ax[j] * bx[j - 1] + ay[j] * by[j - 1])
        if j < n - 1:
            up[j] = -(ax[j] * bx[j + 1] + ay[j] * by[j + 1])


@njit(cache=True)
def _restore_lengths(x, rxs, rys, ds, dxs, dys, lo, di, up, rhs):
    """Restore every segment length of ``x`` (N+1, 2) to ``ds`` in place (SHAKE): Newton on
    ``|x_{j+1} - x_j|^2 = ds^2``, moving the ends of segment j along its direction before the
    step ``(rxs[j], rys[j])``; the chain makes the system tridiagonal. ``dxs`` to ``rhs`` are
    work arrays of length N. Returns whether the largest ``|l_j^2 - ds^2| / 2`` fell below
    ``1e-10 ds^2`` within 20 Newton steps."""
    n = x.shape[0] - 1
    for _k in range(21):
        err = 0.0
        for j in range(n):
            dxs[j] = x[j + 1, 0] - x[j, 0]
            dys[j] = x[j + 1, 1] - x[j, 1]
            rhs[j] = -0.5 * (dxs[j] * dxs[j] + dys[j] * dys[j] - ds * ds)
            err = max(err, abs(rhs[j]))
        if err < 1e-10 * ds * ds:
            return True
        if _k == 20 or not math.isfinite(err):
            return False
        _chain_matrix(dxs, dys, rxs, rys, lo, di, up)
        mu = _tridiag(lo, di, up, rhs)
        for j in range(n):
            x[j, 0] -= rxs[j] * mu[j]
            x[j, 1] -= rys[j] * mu[j]
            x[j + 1, 0] += rxs[j] * mu[j]
            x[j + 1, 1] += rys[j] * mu[j]
    return False


@njit(cache=True, nogil=True)
def _compress(x, r_start, r_end, h_ratio, margin, rate, k, dt_max, max_iter, ftol, k_min,
              patience=HOLD_PATIENCE, stop=None):
    """Shrink the wall from ``r_start`` to ``r_end`` while relaxing the rod, then relax it
    at ``r_end``. ``x`` (N+1, 2) is updated in place.

    The thickness is ``h = h_ratio R`` at every wall radius ``R`` (see the module docstring).
    Each iteration is one FIRE step (Bitzek et al., PRL 97, 170201, 2006; semi-implicit Euler,
    unit masses) on the bending energy plus stiff contact and wall springs acting within
    ``margin h`` of the hard core, with the forces projected onto the tangent space of the
    fixed segment lengths and the lengths restored exactly after the step (SHAKE solved as a
    tridiagonal Newton system: the rod is a chain). The wall moves by
    ``min(rate R, h / 8)`` per iteration, and only while no spring is compressed by more than
    half its range (it waits for the rod to relax: quasi-static). Nodes never move more than
    ``h / 4`` per iteration, so no pass can jump through another between two force
    evaluations, and the Verlet list of near (node, segment) pairs (skin ``2 h``) is rebuilt
    when a node has moved by more than half the skin.

    When the wall waits on a spring held at half its range by balanced forces (the largest
    node force is below 5 % of that spring's force: the packing's pressure, not a transient),
    the springs stiffen by 1.5 and the step shortens by sqrt(1.5), at most every 500
    iterations (the rod must respond before the next). A pressure then lets the spring
    relax to about 1/1.5 of its compression and the wall goes on. A compression imposed by
    the wall's position does not yield to stiffening: when the wall reaches 2 pi R = 1.004 L
    (the ring of nodes at the springs' reach, R - 0.625 h, with a gap below the contact
    range between the ends) the relaxed rod lines the wall as a ring whose two ends butt
    against each other, the end-to-end contact held at 0.6-0.8 of its range by the wall
    springs of all the nodes; every spring scales with ``k``, so the balance and the overlap
    stay where they are. Measured at epsilon 2-8 with N = 300-1000 (levels ending at
    epsilon 1) and at epsilon 19, N = 2000 for one seed of six tried (its first level passes
    epsilon 1): 15-27
    stiffenings raised ``k`` 440-fold (to the cap 1e4) with the overlap unchanged to 2 %,
    the rod then sat at an exact equilibrium (forces 5e-13 of a spring's, steps 1e-17 h,
    below rounding, a FIRE restart every iteration) for the rest of the level's 2e6
    iterations, and the stiff springs carried to the next levels left the final hold
    unconverged. A few more wall steps (two in the traced case) buckle the ring off the
    wall and release the contact. So when the last stiffening left a held compression
    above 0.9 of its value (or ``k`` is at its cap), the wall takes one step each time the
    rod is at rest (balanced forces, at most every 500 iterations) instead of stiffening.

    A step whose length restoration (:func:`_restore_lengths`) has not converged after 20
    Newton steps is taken again from its start at half its size, at most
    :data:`SHAKE_HALVINGS` times; the velocity follows the shorter displacement. The Newton
    system is nearly singular on a long stretch of rod lining the wall: its softest mode, a
    tension along the arc, has an eigenvalue ~ (ds / R)^2 (3e-4 against 4 for the stiffest at
    76 segments per wall radius), while a step of the zigzag that such a stretch takes when
    the wall's compression buckles it (module docstring, "Limits") leaves a length error of
    1e-4 to 1e-3 ds^2. Newton then cycles instead of converging; a step kept with wrong
    lengths passes them, and a velocity taken from them, to the next step, which can diverge
    outright (turning angles near 180 degrees appear then, after the lengths went wrong, not
    before). The restoration's error falls as the step squared: one halving made both traced
    steps converge in three Newton steps. The bending force is left as it is (Eq. (8), the
    energy :mod:`simulate.energy` reports).

    Springs stiffened during the compaction stay stiff in the final hold, where the wall no
    longer presses: the step shrinks as ``k^-1/2``, and so does the relaxation of the rod's
    bending. Springs at the cap (``k`` near 1e4, the step 38 times below its value at
    :data:`STIFFNESS`) relax a rod left with 3-9 times the bending energy of the others by
    about a decade of force per 150 000 iterations, steadily (no plateau, no oscillation,
    FIRE at its largest step between rare restarts), and a budget of 5e5 iterations ends
    them at 60-200 times ``ftol`` (epsilon 19 and 30, N = 2000). So a hold still running
    ``patience`` iterations after the wall reached ``r_end`` softens the springs by 1.5
    (the step lengthens by sqrt(1.5)) whenever the largest compression is below a fifth of
    the range, at most every 500 iterations and down to ``k_min``, the stiffness a level
    starts with (:func:`_stiffness`, for which ``dt_max`` is stable):
    a compression at equilibrium stays below 0.3 of the range, short of the 0.5 at which
    they stiffen again. A hold converging within ``patience`` iterations is unchanged.

    ``stop``, a one-element array or None, ends the loop before the next iteration once it
    holds a non-zero value (set from another thread: :func:`_compress_interruptibly`).

    Returns
    -------
    (wall radius, iterations, list builds, FIRE restarts, largest node force, largest
    spring compression / range, stiffenings, final stiffness, halved steps, softenings)
    """
    n = x.shape[0] - 1
    ds = 1.0 / n
    n3 = float(n) ** 3
    v = np.zeros_like(x)
    f = np.empty_like(x)
    xo = np.empty_like(x)
    xref = x.copy()
    dxs = np.empty(n)
    dys = np.empty(n)
    rxs = np.empty(n)
    rys = np.empty(n)
    lo = np.zeros(n)
    di = np.empty(n)
    up = np.zeros(n)
    rhs = np.empty(n)
    big_r = r_start
    skin = 2.0 * h_ratio * big_r
    pairs, start = _near_pairs(x, (1.0 + margin) * h_ratio * big_r + skin)
    n_build = 1
    dt = 0.1 * dt_max
    alpha = 0.1
    npos = 0
    n_restart = 0
    it = 0
    fmax = np.inf
    ovl = 0.0
    n_stiff = 0
    last_stiff = 0
    ovl_stiff = np.inf
    n_half = 0
    n_soft = 0
    # the iteration at which the wall reached r_end (-1: not yet)
    it_hold = 0 if r_start <= r_end else -1
    while it < max_iter:
        if stop is not None and stop[0]:
            break  # the caller was interrupted (:func:`_compress_interruptibly`)
        it += 1
        h = h_ratio * big_r
        if big_r > r_end and ovl < 0.5 * margin * h:
            big_r = max(r_end, big_r - min(rate * big_r, 0.125 * h))
            h = h_ratio * big_r
            ovl_stiff = np.inf
        elif (ovl >= 0.5 * margin * h and fmax < 0.05 * k * n3 * margin * h
              and it - last_stiff > 500):
            if big_r > r_end and (ovl > 0.9 * ovl_stiff or k >= 1e4):
                # the last stiffening left the held compression where it was (a pressure
                # would have yielded about 1/1.5 of it): the wall's position imposes it, as
                # on a rod lining the wall end to end, and only a further shrink (buckling
                # the rod off the wall) releases it. One wall step per rest of the rod.
                big_r = max(r_end, big_r - min(rate * big_r, 0.125 * h))
                h = h_ratio * big_r
                last_stiff = it
            elif k < 1e4:
                # a spring held at half its range by balanced forces (the packing's
                # pressure, not a transient the relaxation will remove): stiffer springs,
                # shorter step
                k *= 1.5
                dt_max /= math.sqrt(1.5)
                dt = min(dt, dt_max)
                n_stiff += 1
                last_stiff = it
                ovl_stiff = ovl
        elif (it_hold >= 0 and it - it_hold > patience and ovl < 0.2 * margin * h
              and k > k_min and it - last_stiff > 500):
            # a long hold on springs far below their range: stiffness only shortens the step
            k_soft = max(k / 1.5, k_min)
            dt_max *= math.sqrt(k / k_soft)
            k = k_soft
            n_soft += 1
            last_stiff = it
        if it_hold < 0 and big_r <= r_end:
            it_hold = it
        hc = (1.0 + margin) * h
        rw = big_r - 0.5 * hc
        ovl = 0.0
        # bending force: paper Eq. (8), finite differences (simulate.energy)
        f[:] = 0.0
        for i in range(1, n):
            wx = 2.0 * n3 * (x[i + 1, 0] - 2.0 * x[i, 0] + x[i - 1, 0])
            wy = 2.0 * n3 * (x[i + 1, 1] - 2.0 * x[i, 1] + x[i - 1, 1])
            f[i - 1, 0] -= wx
            f[i - 1, 1] -= wy
            f[i, 0] += 2.0 * wx
            f[i, 1] += 2.0 * wy
            f[i + 1, 0] -= wx
            f[i + 1, 1] -= wy
        # contacts: every node i against the nearby segments b of other passes, with the
        # energy sum_b phi(dist(x_i, seg b)) - sum_j phi(|x_i - x_j|) over the joints j shared
        # by two listed segments (inclusion-exclusion): a node meeting a pass at a joint counts
        # once, so sliding along a stack feels no corrugation, and a node in a concave corner
        # of another pass feels both segments smoothly (a min over segments would switch
        # between them, and FIRE chatters there). In 2D the distance of two segments is the
        # smallest of their four end-to-segment distances, so these pairs keep every pair of
        # non-adjacent segments apart.
        # the spring force 2 k N^3 (hc - d) hc / d grows without bound as d -> 0: a
        # harmonic spring saturates and a fold pressed at its apex (where the discrete
        # bending torque vanishes near 180 degrees) would collapse through it
        hc2 = hc * hc
        for i in range(n + 1):
            for p in range(start[i], start[i + 1]):
                b = pairs[p, 1]
                d2, t = _ptseg(x[i, 0], x[i, 1], x[b, 0], x[b, 1], x[b + 1, 0], x[b + 1, 1])
                if d2 < hc2 and d2 > 0.0:
                    d = math.sqrt(d2)
                    ovl = max(ovl, hc - d)
                    g = 2.0 * k * n3 * (hc - d) * hc / (d * d)
                    px = x[i, 0] - (x[b, 0] + t * (x[b + 1, 0] - x[b, 0]))
                    py = x[i, 1] - (x[b, 1] + t * (x[b + 1, 1] - x[b, 1]))
                    f[i, 0] += g * px
                    f[i, 1] += g * py
                    f[b, 0] -= (1.0 - t) * g * px
                    f[b, 1] -= (1.0 - t) * g * py
                    f[b + 1, 0] -= t * g * px
                    f[b + 1, 1] -= t * g * py
                if p + 1 < start[i + 1] and pairs[p + 1, 1] == b + 1:
                    j = b + 1
                    px = x[i, 0] - x[j, 0]
                    py = x[i, 1] - x[j, 1]
                    d2 = px * px + py * py
                    if d2 < hc2 and d2 > 0.0:
                        d = math.sqrt(d2)
                        g = 2.0 * k * n3 * (hc - d) * hc / (d * d)
                        f[i, 0] -= g * px
                        f[i, 1] -= g * py
                        f[j, 0] += g * px
                        f[j, 1] += g * py
        for i in range(n + 1):
            r = math.hypot(x[i, 0], x[i, 1])
            if r > rw:
                ovl = max(ovl, r - rw)
                g = 2.0 * k * n3 * (r - rw) / r
                f[i, 0] -= g * x[i, 0]
                f[i, 1] -= g * x[i, 1]
        # keep the forces tangent to the fixed segment lengths: f -= J^T (J J^T)^-1 J f
        for j in range(n):
            dxs[j] = x[j + 1, 0] - x[j, 0]
            dys[j] = x[j + 1, 1] - x[j, 1]
        _chain_matrix(dxs, dys, dxs, dys, lo, di, up)
        for j in range(n):
            rhs[j] = dxs[j] * (f[j + 1, 0] - f[j, 0]) + dys[j] * (f[j + 1, 1] - f[j, 1])
        mu = _tridiag(lo, di, up, rhs)
        for j in range(n):
            f[j, 0] += dxs[j] * mu[j]
            f[j, 1] += dys[j] * mu[j]
            f[j + 1, 0] -= dxs[j] * mu[j]
            f[j + 1, 1] -= dys[j] * mu[j]
        fmax2 = 0.0
        for i in range(n + 1):
            fmax2 = max(fmax2, f[i, 0] * f[i, 0] + f[i, 1] * f[i, 1])
        fmax = math.sqrt(fmax2)
        if big_r <= r_end and fmax < ftol and ovl < 0.5 * margin * h:
            break
        if not math.isfinite(fmax):
            break  # reported by the caller's checks
        # FIRE: mix the velocity towards the force while the power is positive, stop and
        # shorten the step when it is not (dt never below 2 % of dt_max, FIRE 2.0)
        pw = 0.0
        for i in range(n + 1):
            pw += f[i, 0] * v[i, 0] + f[i, 1] * v[i, 1]
        if pw > 0.0:
            npos += 1
            if npos > 5:
                dt = min(1.1 * dt, dt_max)
                alpha *= 0.99
        else:
            n_restart += 1
            npos = 0
            dt = max(0.5 * dt, 0.02 * dt_max)
            alpha = 0.1
            v[:] = 0.0
        vn = 0.0
        fn = 0.0
        for i in range(n + 1):
            v[i, 0] += dt * f[i, 0]
            v[i, 1] += dt * f[i, 1]
            vn += v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1]
            fn += f[i, 0] * f[i, 0] + f[i, 1] * f[i, 1]
        mix = alpha * math.sqrt(vn / fn) if fn > 0.0 else 0.0
        vmax2 = 0.0
        for i in range(n + 1):
            v[i, 0] = (1.0 - alpha) * v[i, 0] + mix * f[i, 0]
            v[i, 1] = (1.0 - alpha) * v[i, 1] + mix * f[i, 1]
            vmax2 = max(vmax2, v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1])
        step = dt
        if math.sqrt(vmax2) * dt > 0.25 * h:
            step = 0.25 * h / math.sqrt(vmax2)
        xo[:] = x
        for j in range(n):
            rxs[j] = xo[j + 1, 0] - xo[j, 0]
            rys[j] = xo[j + 1, 1] - xo[j, 1]
        # a step whose length restoration does not converge is taken again from xo at half
        # its size: the restoration's error grows as the step squared, and a long stretch of
        # rod lining the wall makes its Newton system nearly singular (see the docstring)
        for _half in range(SHAKE_HALVINGS + 1):
            for i in range(n + 1):
                x[i, 0] = xo[i, 0] + step * v[i, 0]
                x[i, 1] = xo[i, 1] + step * v[i, 1]
            if _restore_lengths(x, rxs, rys, ds, dxs, dys, lo, di, up, rhs):
                break
            if _half < SHAKE_HALVINGS:
                step *= 0.5
                n_half += 1
        moved2 = 0.0
        for i in range(n + 1):
            v[i, 0] = (x[i, 0] - xo[i, 0]) / dt
            v[i, 1] = (x[i, 1] - xo[i, 1]) / dt
            ddx = x[i, 0] - xref[i, 0]
            ddy = x[i, 1] - xref[i, 1]
            moved2 = max(moved2, ddx * ddx + ddy * ddy)
        if moved2 > 0.25 * skin * skin:
            skin = 2.0 * h_ratio * big_r
            pairs, start = _near_pairs(x, (1.0 + margin) * h_ratio * big_r + skin)
            xref[:] = x
            n_build += 1
    return (big_r, it, n_build, n_restart, fmax, ovl / (margin * h_ratio * big_r), n_stiff,
            k, n_half, n_soft)


# ----------------------------------------------------------------------------------------
# one configuration


def default_thickness(epsilon: float) -> float:
    """Default rod thickness ``h = 0.005 R`` with ``R = 1 / (2 pi epsilon)`` (units of L).

    Parameters
    ----------
    epsilon : float
        Compaction rate ``L / (2 pi R)``.

    Returns
    -------
    float
    """
    return H_OVER_R / (2.0 * math.pi * float(epsilon))


@dataclass(frozen=True)
class CompactParams:
    """Parameters of one compaction (lengths in units of L).

    Attributes
    ----------
    epsilon : float
        Compaction rate ``L / (2 pi R)`` reached at the end (paper Eq. (5)).
    n_segments : int
        Number of segments N of the final rod.
    thickness : float, optional
        Rod thickness h at the end; default :func:`default_thickness`.
    noise : float
        Curvature noise D of the initial shape, at the paper's resolution of 300 segments.
    rate : float
        Largest relative shrink of the wall per iteration; the shrink is also at most
        ``h / 8`` per iteration, which binds whenever ``rate > h / (8 R)`` (6.25e-4 at the
        default h = 0.005 R). Default 6.25e-5 (a shrink of R/16000 per iteration): the
        ensemble statistics at epsilon 19 agree with those of half that step, move by about
        two standard errors at twice it and beyond their errors from four times it
        (``docs/validation/compact.md``, "Protocol").
    max_iter : int
        Iterations allowed to each level of the compaction.
    hold_iter : int
        Iterations allowed to the final relaxation at the final wall radius. The hold relaxes
        the whole rod (the last level stops as soon as the wall reaches R): its largest node
        force falls slowly, in the sawtooth of FIRE's cycles (a restart every 360-910
        iterations, the force at its lowest 95-170 iterations after a restart and 1-3
        decades above it before the next), and the hold ends at the first of these minima
        below ``ftol``. Measured at epsilon 8 and 19 (N = 2000, ``default_rng(1)`` to
        ``default_rng(4)``): 21 000-105 000 iterations, 178 000 at epsilon 19 and N = 4000
        (``docs/validation/compact.md``); the default leaves about three times that, 120 s of
        one core at N = 2000 if a hold used all of it.
    ftol : float
        The final relaxation stops when no node force exceeds ``ftol * 2 ds / R^3`` (the
        force on one segment of a pressure ``B / R^3``, B = 2 in these units).
    """

    epsilon: float
    n_segments: int = 2000
    thickness: float | None = None
    noise: float = NOISE
    rate: float = 6.25e-5
    max_iter: int = 2_000_000
    hold_iter: int = 500_000
    ftol: float = 1.0

    @property
    def wall_radius(self) -> float:
        """Final wall radius ``R = 1 / (2 pi epsilon)``."""
        return 1.0 / (2.0 * math.pi * self.epsilon)

    @property
    def h(self) -> float:
        """Final rod thickness."""
        return default_thickness(self.epsilon) if self.thickness is None else self.thickness


@dataclass(frozen=True)
class CompactResult:
    """One compacted rod (units of L).

    Attributes
    ----------
    xy, xy0 : (N+1, 2) arrays
        Final node positions; the initial shape at the coarsest level.
    wall_radius, thickness : float
        Final wall radius R and thickness h.
    energy_bending : float
        ``int (R'')^2 ds`` (:func:`simulate.energy.bending_energy`).
    min_distance : float
        Smallest distance between non-adjacent segments (>= thickness).
    max_radius : float
        Largest node distance to the centre (<= R - h/2).
    length : float
        Sum of the segment lengths (1 up to rounding).
    stats : dict
        Counters: iterations, levels, list builds, FIRE restarts, spring stiffenings, steps
        halved for the length restoration, spring softenings of a long final hold
        (:func:`_compress`), iterations of the final hold
        (``hold_iterations``), final largest node force over ``2 ds / R^3`` (``force``: the
        hold converged when it is below ``ftol``), final largest spring compression over its
        range (``compression``: below 0.5 when converged), nodes folded flat
        (``flat_folds``, :func:`flat_folds`).
    wall_s : float
        Wall time of the compaction (s).
    """

    xy: np.ndarray
    xy0: np.ndarray
    wall_radius: float
    thickness: float
    energy_bending: float
    min_distance: float
    max_radius: float
    length: float
    stats: dict = field(default_factory=dict)
    wall_s: float = 0.0


def _compress_interruptibly(*args):
    """:func:`_compress` on a thread, the caller waiting in a way a signal interrupts.

    A level runs for up to a minute in compiled code, where Python's signal handlers wait
    for it to return (50 s at epsilon 50, N = 1258). Here the main thread waits on the
    thread, which a signal interrupts; the kernel is then told to stop (it checks a flag
    before each iteration), joined, and the interruption goes on (0.35 s in the same case).
    The results are :func:`_compress`'s to the bit.

    Returns
    -------
    tuple
        :func:`_compress`'s.
    """
    from crosssection.core.parallel import in_background, wait_all

    stop = np.zeros(1, np.int8)
    waiting = in_background(_compress, *args, HOLD_PATIENCE, stop)
    try:
        return waiting()
    except BaseException:
        stop[0] = 1
        wait_all(waiting)
        raise


def levels(n_segments: int, wall_radius: float) -> list[int]:
    """Segment counts of the successive levels, coarsest first.

    Every level halves the segments of the next one while its final wall radius keeps at
    least :data:`RESOLUTION` segments (or as many as the final rod, if fewer); levels end at
    ``R 2^k`` (k = 0 for the finest). Halving needs an even N, so an N with a large power of
    two (2000 = 16 x 125) gets more levels and runs faster.
    """
    out = [int(n_segments)]
    least = min(RESOLUTION, n_segments * wall_radius) * (1.0 - 1e-9)
    while (out[-1] % 2 == 0 and out[-1] // 2 >= 16
           and (out[-1] // 2) * wall_radius * 2 ** len(out) >= least):
        out.append(out[-1] // 2)
    return out[::-1]


def initial_rod(n_segments: int, noise: float, clearance: float, rng, *,
                max_tries: int = 1000) -> np.ndarray:
    """A random initial shape with N segments, centred, no two non-adjacent segments closer
    than ``clearance``.

    The shape is the paper's (white noise of amplitude D on the curvature, section "Initial
    configurations", :func:`simulate.noise.initial_shape`) drawn at its resolution of 300
    segments, and its tangent angle interpolated to N segments: the ensemble of initial
    shapes does not depend on N.

    Parameters
    ----------
    n_segments : int
    noise : float
        D at 300 segments (paper: 750).
    clearance : float
    rng : numpy.random.Generator
    max_tries : int

    Returns
    -------
    (N+1, 2) float64 array
    """
    from simulate.geometry import angles, center_of_mass, positions
    from simulate.intersect import close_pairs
    from simulate.noise import initial_shape

    s_ref = (np.arange(N_SEGMENTS) + 0.5) / N_SEGMENTS
    s_new = (np.arange(n_segments) + 0.5) / n_segments
    for _ in range(max_tries):
        theta, _ = angles(initial_shape(N_SEGMENTS, noise, seed=rng))
        xy = positions(np.interp(s_new, s_ref, theta))
        xy -= center_of_mass(xy)
        if len(close_pairs(xy, clearance, 2)) == 0:
            return xy
    raise ParameterError(f"no initial shape with clearance {clearance:.3g} in {max_tries} "
                         f"draws at noise D={noise}: lower --noise")


def _stiffness(n: int, radius: float) -> float:
    """Initial spring stiffness (units of N^3) at N segments and wall radius R.

    Forces at the wall scale as ``ds / R^3`` (bending to the wall's curvature), the springs'
    range as h ~ R: the springs need a stiffness ``~ (N R)^-4`` in units of N^3 to keep the
    compression within its range. :data:`STIFFNESS` suffices from :data:`RESOLUTION`
    segments per wall radius; coarser rods start with stiffer springs (and a shorter step).
    """
    return STIFFNESS * max(1.0, (RESOLUTION / (n * radius)) ** 4)


def _refine(xy):
    """Split every segment in two (exact lengths, same shape)."""
    out = np.empty((2 * xy.shape[0] - 1, 2))
    out[::2] = xy
    out[1::2] = 0.5 * (xy[:-1] + xy[1:])
    return out


def flat_folds(xy) -> int:
    """Nodes turning by more than :data:`FLAT_FOLD_DEG` (folded flat through the hard core).

    Parameters
    ----------
    xy : (N+1, 2) array

    Returns
    -------
    int
    """
    return sharp_nodes(xy, FLAT_FOLD_DEG)


def min_segment_distance(xy, cutoff: float) -> float:
    """Smallest distance between non-adjacent segments, or ``cutoff`` if none is closer.

    Parameters
    ----------
    xy : (N+1, 2) array
    cutoff : float

    Returns
    -------
    float
    """
    from simulate.intersect import close_pairs, seg_dist2

    xy = np.ascontiguousarray(xy, dtype=np.float64)
    best = cutoff * cutoff
    for i, j in close_pairs(xy, cutoff, 2):
        best = min(best, seg_dist2(*xy[i], *xy[i + 1], *xy[j], *xy[j + 1]))
    return float(np.sqrt(best))


def compact_rod(params: CompactParams, rng) -> CompactResult:
    """Compact one random rod to ``params.epsilon``.

    Parameters
    ----------
    params : CompactParams
    rng : numpy.random.Generator
        Draws the initial shape (the compaction itself is deterministic).

    Returns
    -------
    CompactResult

    Raises
    ------
    AnalysisError
        If the final rod overlaps itself, leaves the wall or changed length (the relaxation
        did not converge within its iterations).

    Warns
    -----
    HoldWarning
        If the final hold ends at ``params.hold_iter`` iterations with a node force above
        ``ftol`` or a spring compressed beyond half its range: the rod passes the checks but
        is not relaxed to the tolerance (``stats["force"]`` says by how much).
    """
    from simulate.energy import bending_energy

    t0 = time.perf_counter()
    r_end = params.wall_radius
    h_end = params.h
    h_ratio = h_end / r_end
    lev = levels(params.n_segments, r_end)
    n0 = lev[0]
    # thickness capped at 0.4 segment at every level: the contacts between segments two apart
    # need it below half a segment
    cap0 = 0.4 / n0
    xy = initial_rod(n0, params.noise, (1.0 + MARGIN) * cap0, rng)
    xy0 = xy.copy()
    big_r = max(float(np.hypot(xy[:, 0], xy[:, 1]).max()) + (1.0 + MARGIN) * cap0, r_end)
    stats = {"levels": len(lev), "iterations": 0, "builds": 0, "restarts": 0, "stiffenings": 0,
             "halved_steps": 0, "softenings": 0}
    k_phys = 0.0  # spring stiffness reached so far, in absolute units (carried across levels)

    def run(xy, n, r_from, r_to, ratio, max_iter, ftol):
        nonlocal k_phys
        k0 = _stiffness(n, r_to)
        k = max(k0, k_phys / float(n) ** 3)
        out = _compress_interruptibly(xy, r_from, r_to, ratio, MARGIN, params.rate, k,
                                      DT_MAX / n ** 1.5 / math.sqrt(k / STIFFNESS), max_iter,
                                      ftol, k0)
        for key, i in (("iterations", 1), ("builds", 2), ("restarts", 3), ("stiffenings", 6),
                       ("halved_steps", 8), ("softenings", 9)):
            stats[key] += int(out[i])
        k_phys = out[7] * float(n) ** 3
        if not (math.isfinite(out[4]) and np.isfinite(xy).all()):
            raise AnalysisError(f"the relaxation diverged at N = {n}, R = {out[0]:.5g} "
                                "(non-finite positions or forces)")
        return out

    for lvl, n in enumerate(lev):
        if lvl > 0:
            xy = _refine(xy)
        r_stop = r_end * 2.0 ** (len(lev) - 1 - lvl)
        if big_r > r_stop:
            ratio = min(h_ratio, 0.4 / n / big_r)
            big_r = run(xy, n, big_r, r_stop, ratio, params.max_iter, np.inf)[0]
    n = lev[-1]
    ds = 1.0 / n
    ftol = params.ftol * 2.0 * ds / r_end ** 3
    last = run(xy, n, big_r, r_end, h_ratio,
               params.max_iter if big_r > r_end else params.hold_iter, ftol)
    # the kernel's own stopping rule: it breaks on it, or runs out of iterations
    converged = last[4] < ftol and last[5] < 0.5
    stats["hold_iterations"] = int(last[1])
    stats["force"] = float(last[4] / (2.0 * ds / r_end ** 3))
    stats["compression"] = float(last[5])
    wall_s = time.perf_counter() - t0
    if not (np.isfinite(xy).all() and math.isfinite(last[4])):
        raise AnalysisError("the relaxation diverged (non-finite positions or forces)")
    if last[0] > r_end * (1 + 1e-12):
        raise AnalysisError(f"the wall stopped at R = {last[0]:.5g} before {r_end:.5g} "
                            "(relaxation too slow: raise --max-iter)")
    length = float(np.hypot(*np.diff(xy, axis=0).T).sum())
    max_radius = float(np.hypot(xy[:, 0], xy[:, 1]).max())
    min_dist = min_segment_distance(xy, 2.0 * h_end)
    if min_dist < h_end or max_radius > r_end - 0.5 * h_end or abs(length - 1.0) > 1e-3:
        raise AnalysisError(f"final rod invalid: min distance {min_dist:.4g} (h = {h_end:.4g}),"
                            f" max radius {max_radius:.6g} (limit {r_end - 0.5 * h_end:.6g}),"
                            f" length {length:.6g}")
    stats["flat_folds"] = flat_folds(xy)
    if stats["flat_folds"]:
        warnings.warn(f"{stats['flat_folds']} node(s) turn by more than {FLAT_FOLD_DEG:.0f} "
                      "degrees: their segments come closer than h within pi h / 2 of the "
                      "node, the rod folding flat through itself there", FlatFoldWarning,
                      stacklevel=2)
    if not converged:
        warnings.warn(f"final hold unconverged after {int(last[1])} iterations (hold_iter): "
                      f"largest node force {stats['force']:.3g} x 2 ds/R^3 (ftol "
                      f"{params.ftol:g}), spring compression {stats['compression']:.3g} of its "
                      "range (0.5); the rod passes its checks but is not relaxed",
                      HoldWarning, stacklevel=2)
    return CompactResult(xy=xy, xy0=xy0, wall_radius=r_end, thickness=h_end,
                         energy_bending=float(bending_energy(xy)), min_distance=min_dist,
                         max_radius=max_radius, length=length, stats=stats, wall_s=wall_s)


# ----------------------------------------------------------------------------------------
# ensembles and command line

CONFIG_COLUMNS = ["config_id", "seed", "epsilon", "wall_radius", "thickness",
                  "contact_distance", "rg", "epsilon_rg", "energy_total", "energy_bending",
                  "n_stacks", "n_branches", "n_junctions", "n_voids", "min_distance",
                  "max_radius", "length", "wall_s"]

# parameters that define the physics: a re-run into the same folder must agree on them
_PHYSICS_KEYS = ("command", "epsilon", "n_segments", "thickness", "wall_radius", "noise",
                 "seed", "rate", "max_iter", "hold_iter", "ftol", "contact_distance")

_PARAM_FIELDS = ("epsilon", "n_segments", "thickness", "noise", "rate", "max_iter",
                 "hold_iter", "ftol")


def wall_regions(xy, branches: pd.DataFrame, stacks: pd.DataFrame, *, wall_radius: float,
                 contact_distance: float) -> tuple[pd.Series, pd.Series]:
    """Bulk or periphery of every branch and stack (paper, "Two sub-systems": branches with an
    extremity in contact with the container form the periphery).

    A stack is in the periphery when one of its ends touches the wall, and its branches
    share its region. An end is a branch extremity (the rod at ``s_start`` or ``s_end``); it
    touches the wall when it lies within ``contact_distance (1 + n_br / 2)`` of it: the
    stack's passes are up to a contact distance apart, so the extremity of an inner pass of a
    stack pressed on the wall sits about half the stack's width away from it. The scans
    (:func:`crosssection.stages.hole.classify_regions`) take half the widest stack at the
    end's junction plus 2 h instead, so a single sheet leaving a thick wall band is periphery
    there and bulk here (docs/report.md: about a fifth more periphery stacks on scans).

    Parameters
    ----------
    xy : (N+1, 2) array
        Node positions (units of L, wall centred at the origin).
    branches, stacks : DataFrame
        Tables of :func:`simulate.contacts.analyze_rod` (branches with ``s_start``, ``s_end``
        and ``stack_id``; stacks with ``stack_id`` and ``n_br``).
    wall_radius, contact_distance : float
        Units of L.

    Returns
    -------
    branch_region, stack_region : Series of "bulk" / "periphery"
        Aligned with ``branches`` and ``stacks``.
    """
    s_node = np.linspace(0.0, 1.0, xy.shape[0])
    n_br = stacks.set_index(stacks["stack_id"].astype(int))["n_br"]
    sid = branches["stack_id"].astype(int).to_numpy()
    tol = contact_distance * (1.0 + 0.5 * n_br.reindex(sid).to_numpy(float))
    touching = set()
    for col in ("s_start", "s_end"):
        s_end = branches[col].to_numpy(float)
        p = np.column_stack([np.interp(s_end, s_node, xy[:, 0]),
                             np.interp(s_end, s_node, xy[:, 1])])
        gap = wall_radius - np.hypot(p[:, 0], p[:, 1])
        touching |= set(sid[gap <= tol])
    st = pd.Series(np.where(stacks["stack_id"].astype(int).isin(touching), "periphery", "bulk"),
                   index=stacks.index)
    br = pd.Series(np.where(np.isin(sid, list(touching)), "periphery", "bulk"),
                   index=branches.index)
    return br, st


def run_config(config_id: int, seed: int, params: dict, out: str) -> int:
    """Compact and analyse configuration ``config_id``; write its part file.

    The contact analysis (:func:`simulate.contacts.analyze_rod`) takes two passes as in
    contact when their centre lines are closer than ``params["contact_distance"]``, default
    :data:`CONTACT_DISTANCE` h = 3 h. Passes pressed together sit h to (1 + MARGIN) h apart,
    but nothing presses the passes of a stack away from the wall (no friction, no adhesion):
    they lie 1-3 h apart, and a scan sees them as one band (the cut sheets are inked and
    thickened by the hot wire, and voids below (10 h)^2 are filled, paper "Image analysis
    procedure"). At 1.5 h the stacks fall apart into thin slivers (docs/validation/compact.md);
    the quench's default (half a segment) would be ~6 h at N = 2000, epsilon = 19.

    Returns
    -------
    int
        ``config_id``.
    """
    from simulate.contacts import analyze_rod
    from simulate.ensemble import RUN_DIGEST, analysis_records, write_part
    from simulate.geometry import radius_of_gyration

    p = CompactParams(**{k: params[k] for k in _PARAM_FIELDS})
    with warnings.catch_warnings():
        # an unconverged hold is in configs.csv (n_force): the command reports it as one
        # warning line, a worker's own warning would print a traceback-style line
        warnings.simplefilter("ignore", HoldWarning)
        warnings.simplefilter("ignore", FlatFoldWarning)
        res = compact_rod(p, np.random.default_rng(seed))
    row = {"config_id": config_id, "seed": seed, "epsilon": p.epsilon,
           "wall_radius": res.wall_radius, "thickness": res.thickness,
           "contact_distance": params["contact_distance"], "wall_s": res.wall_s,
           "energy_total": res.energy_bending, "energy_bending": res.energy_bending,
           "min_distance": res.min_distance, "max_radius": res.max_radius,
           "length": res.length}
    rg = radius_of_gyration(res.xy)
    row.update(rg=rg, epsilon_rg=1.0 / (2.0 * np.pi * rg))
    branches, voids, stacks = [], [], []
    try:
        # hard wall: no confinement energy (lam = 0), branch energies are bending only
        an = analyze_rod(res.xy, lam=0.0, contact_distance=params["contact_distance"])
        row.update(n_stacks=int(an.n_stacks), n_branches=int(an.n_branches),
                   n_junctions=int(an.n_junctions), n_voids=int(an.n_voids))
        branches, voids, stacks = analysis_records(an)
        b_reg, s_reg = wall_regions(res.xy, an.branches, an.stacks,
                                    wall_radius=res.wall_radius,
                                    contact_distance=params["contact_distance"])
        for rec, reg in zip(branches, b_reg):
            rec["region"] = reg
        for rec, reg in zip(stacks, s_reg):
            rec["region"] = reg
    except Exception as exc:  # noqa: BLE001 - recorded per configuration, the ensemble goes on
        row["analysis_error"] = f"{type(exc).__name__}: {exc}"
    row.update({f"n_{k}": v for k, v in res.stats.items()})
    write_part(out, config_id, row, res.xy, res.xy0, branches, voids, stacks,
               digest=params.get(RUN_DIGEST))
    return config_id


def check_params(params: CompactParams) -> None:
    """Raise :class:`ParameterError` (naming the option) unless the compaction can run.

    * ``--epsilon`` finite, > 1 and <= 100 (at epsilon = L / (2 pi R) <= 1 the wall's
      circumference holds the whole rod: nothing is compacted, the rod relaxes into an arc
      along the wall);
    * ``--segments`` >= 8 pi epsilon (4 segments per wall radius: a rod cannot bend inside a
      wall spanned by fewer) and <= 100000;
    * ``--thickness`` finite, > 0 and below half a segment ``1/(2N)`` (contacts are kept
      between segments two apart, whose ends are one segment apart on a straight rod);
    * the rod fits: its area ``L h`` below :data:`MAX_AREA_FRACTION` of the disk
      ``pi (R - h/2)^2`` (a disordered packing jams long before filling the disk);
    * ``--noise`` in [0, 3000] (larger noise gives no self-avoiding initial shape);
    """
    eps = params.epsilon
    if not (math.isfinite(eps) and 1.0 < eps <= 100.0):
        raise ParameterError(f"--epsilon must be a finite number in (1, 100], got {eps!r}"
                             + (": at epsilon = L/(2 pi R) <= 1 the wall's circumference "
                                "holds the whole rod, which is not compacted"
                                if math.isfinite(eps) and 0.0 < eps <= 1.0 else ""))
    n = params.n_segments
    n_min = int(math.ceil(8.0 * math.pi * eps))
    if n < max(n_min, 16):
        raise ParameterError(f"--segments must be >= {max(n_min, 16)} at epsilon {eps:g} (four "
                             f"segments per wall radius), got {n}")
    if n > 100_000:
        raise ParameterError(f"--segments must be <= 100000, got {n}")
    h = params.h
    if not (math.isfinite(h) and h > 0.0):
        raise ParameterError(f"--thickness must be a finite number > 0, got {params.thickness!r}")
    # without --thickness, h follows from epsilon (h / R of the experiments): say so
    given = ("--thickness" if params.thickness is not None else
             f"the thickness that epsilon {eps:g} implies (h/R = {H_OVER_R:g})")
    if h >= 0.5 / n:
        n_max = math.ceil(0.5 / h) - 1
        if n_max < 3:
            raise ParameterError(f"{given} {h:.3g} is too thick for any rod of segments: "
                                 "a rod of 3 segments or more needs a thickness below 1/6 of "
                                 "its length (units of L); give a thinner rod (--thickness)")
        raise ParameterError(f"{given} {h:.3g} must be below half a segment 1/(2N) = "
                             f"{0.5 / n:.3g}: use at most {n_max} segments (--segments) or a "
                             "thinner rod (--thickness)")
    r = params.wall_radius
    frac = h / (math.pi * (r - 0.5 * h) ** 2) if r > 0.5 * h else math.inf
    if frac >= MAX_AREA_FRACTION:
        raise ParameterError(f"{given} {h:.3g} too large: the rod (area L h) would fill "
                             f"{frac:.0%} of the disk of radius R = {r:.4g} (at most "
                             f"{MAX_AREA_FRACTION:.0%})")
    if not (math.isfinite(params.noise) and 0.0 <= params.noise <= 3000.0):
        raise ParameterError(f"--noise must be a finite number in [0, 3000], got "
                             f"{params.noise!r}")
    if not (math.isfinite(params.rate) and 0.0 < params.rate <= 0.1):
        raise ParameterError(f"--wall-rate must be in (0, 0.1], got {params.rate!r}")
    if params.max_iter < 1 or params.hold_iter < 1:
        raise ParameterError("--max-iter must be >= 1")
    if not (math.isfinite(params.ftol) and params.ftol > 0.0):
        raise ParameterError(f"ftol must be a finite number > 0, got {params.ftol!r}")


def params_from_args(args) -> dict:
    """The parameter dict of :func:`simulate.ensemble.run_ensemble` from parsed CLI
    arguments, every value checked before anything is written."""
    for name, v, low in (("--n-configs", args.n_configs, 1), ("--seed", args.seed, 0),
                         ("--workers", args.workers, 1), ("--max-iter", args.max_iter, 1)):
        if v < low:
            raise ParameterError(f"{name} must be >= {low}, got {v}")
    if args.n_configs > 10_000_000:
        raise ParameterError("--n-configs must be <= 10000000")
    p = CompactParams(epsilon=float(args.epsilon), n_segments=int(args.segments),
                      thickness=None if args.thickness is None else float(args.thickness),
                      noise=float(args.noise), rate=float(args.wall_rate),
                      max_iter=int(args.max_iter))
    check_params(p)
    h = p.h
    delta = (CONTACT_DISTANCE * h if args.contact_distance is None
             else float(args.contact_distance))
    if not (math.isfinite(delta) and h < delta < 0.5 * p.wall_radius):
        raise ParameterError(f"--contact-distance must be a finite number between the "
                             f"thickness {h:.3g} and half the wall radius "
                             f"{0.5 * p.wall_radius:.3g}, got {args.contact_distance!r}")
    if delta < MIN_CONTACT_DISTANCE:
        # the contact analysis' own bound: refused here, before a compaction whose every
        # analysis would fail on it
        what = ("--contact-distance" if args.contact_distance is not None else
                f"the contact distance {CONTACT_DISTANCE:g} h of --thickness {h:.3g}")
        raise ParameterError(f"{what} must be at least {MIN_CONTACT_DISTANCE:g} (the contact "
                             f"analysis resamples the rod at a third of it), got {delta:.3g}")
    params = {k: v for k, v in asdict(p).items()}
    params.update(command="compact", n_configs=int(args.n_configs), seed=int(args.seed),
                  thickness=h, wall_radius=p.wall_radius, contact_distance=delta)
    return params


def run(args) -> int:
    """Entry point of ``compact``."""
    from crosssection.core.fileio import check_out
    from crosssection.core.parallel import capped_workers
    from simulate.ensemble import (CoarseRodWarning, coarse_rod_doubt, report_failures,
                                   run_ensemble, summary_head)

    check_out(args.out)
    try:
        params = params_from_args(args)
    except ParameterError as exc:
        raise ParameterError(exc.cause, args.out) from None
    workers, lowered = capped_workers(args.workers, args.scheduler)
    if lowered:
        print(f"warning: {lowered}", file=sys.stderr)
    tables = run_ensemble(params, args.out, workers=workers, scheduler=args.scheduler,
                          progress=args.progress, task=run_config,
                          columns=CONFIG_COLUMNS, physics_keys=_PHYSICS_KEYS,
                          on_wait=lambda message: print(f"warning: {message}", file=sys.stderr))
    head, c = summary_head(tables, args.out)
    if c.empty:
        print(head)
        return report_failures(tables, args.out)
    print(f"{head}: epsilon {params['epsilon']:g} (R = "
          f"{params['wall_radius']:.5f}, h = {params['thickness']:.3g}), <E> = "
          f"{c.energy_total.mean():.4g}, <N_l> = {c.n_stacks.mean():.1f}, <N_br> = "
          f"{c.n_branches.mean():.1f}, {c.wall_s.mean():.1f} s per configuration (wall clock)")
    coarse = coarse_rod_doubt(tables, params["n_segments"])
    if coarse:
        warnings.warn(f"{args.out}: {coarse}", CoarseRodWarning, stacklevel=2)
    if "n_force" in c:
        # a warning in a worker process is easily lost: count the unconverged holds here too
        loose = int(((c.n_force >= params["ftol"]) | (c.n_compression >= 0.5)).sum())
        if loose:
            print(f"warning: {args.out}: {loose} of {len(c)} configurations ended their final "
                  f"hold unconverged (n_force >= ftol {params['ftol']:g} or n_compression >= "
                  "0.5 in configs.csv)", file=sys.stderr)
    if "n_flat_folds" in c:
        flat = int((c.n_flat_folds > 0).sum())
        if flat:
            print(f"warning: {args.out}: {flat} of {len(c)} configurations fold flat through "
                  f"themselves at {int(c.n_flat_folds.sum())} node(s) (a turn above "
                  f"{FLAT_FOLD_DEG:.0f} degrees brings two segments closer than h near the "
                  "node; n_flat_folds in configs.csv)", file=sys.stderr)
    return report_failures(tables, args.out)


def add_subparser(sub):
    """Register the ``compact`` subcommand."""
    p = sub.add_parser("compact", help="compact rods of finite thickness in a shrinking "
                                       "hard wall (the experiments' epsilon)",
                       description=__doc__.split("\n\n")[0].replace("``", ""))
    p.add_argument("--epsilon", type=float, required=True,
                   help="compaction rate L/(2 pi R) reached, above 1 (at 1 the wall's "
                        "circumference holds the rod; experiments: 8-19); with the default "
                        "thickness (h = 0.005 R) the rod's segments must be more than 2 h "
                        "long: epsilon > 0.005 N / pi, 3.2 at N = 2000 (fewer --segments "
                        "below), and the rod fills 2 h/R epsilon of the disk, at most "
                        f"{100 * MAX_AREA_FRACTION:.0f} %%: epsilon below "
                        f"{MAX_AREA_FRACTION / (2 * H_OVER_R):.0f} (a thinner --thickness "
                        "above; at most 100)")
    p.add_argument("--segments", type=int, default=CompactParams.n_segments,
                   help="number of segments N of the rod of length L (default "
                        f"{CompactParams.n_segments})")
    p.add_argument("--thickness", type=float, default=None,
                   help="rod thickness h in units of L (default 0.005 R = 0.005/(2 pi eps))")
    p.add_argument("--n-configs", type=int, default=10,
                   help="number of configurations K (default 10)")
    p.add_argument("--seed", type=int, default=0, help="ensemble seed (default 0)")
    p.add_argument("--noise", type=float, default=CompactParams.noise,
                   help="curvature noise D of the initial shapes at 300 segments (default "
                        f"{CompactParams.noise:g}, the paper's)")
    p.add_argument("--contact-distance", type=float, default=None,
                   help="contact cut-off of the analysis in units of L (default 3 h)")
    p.add_argument("--wall-rate", type=float, default=CompactParams.rate,
                   help="largest relative shrink of the wall radius per iteration (default "
                        f"{CompactParams.rate:g}); the shrink is also at most h/8 per "
                        "iteration, which binds above h/(8R) = 6.25e-4 at the default "
                        "thickness: only smaller rates change the compaction; the ensemble "
                        "statistics converge at the default")
    p.add_argument("--max-iter", type=int, default=CompactParams.max_iter,
                   help="iterations allowed to each level of the compaction (default "
                        f"{CompactParams.max_iter:,})")
    p.add_argument("--workers", type=int, default=1, help="local worker processes (default 1)")
    p.add_argument("--scheduler", default=None,
                   help="Dask scheduler address, e.g. tcp://host:8786 (default: local workers)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: only when stderr is a terminal)")
    p.add_argument("--out", required=True,
                   help="output folder (created; a re-run with the same parameters resumes; "
                        "a folder holding other files is refused)")
    p.set_defaults(func=run, command="compact")


__all__ = ["CompactParams", "CompactResult", "FlatFoldWarning", "HoldWarning", "compact_rod",
           "default_thickness", "levels", "initial_rod", "flat_folds", "min_segment_distance",
           "check_params", "run_config",
           "params_from_args", "add_subparser", "CONFIG_COLUMNS"]
