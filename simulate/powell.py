"""Powell's method for the confined rod, entirely in numba (paper, "Search for local minima").

A faithful port of ``scipy.optimize.minimize(method="Powell")`` (same bracketing, same Brent
line search with ``tol = 100 xtol``, same direction-set update) on the parameters
``p = (phi_0 .. phi_{N-1}, x0, y0)``, bend angles ``phi_k = theta_k - theta_{k-1}`` (``phi_0 =
theta_0``) and the start point, made fast by the structure of the rod:

* coordinates: the engine stores bend angles; a coordinate slot is either the bend angle
  ``phi_k`` (``tangent=False``) or the tangent angle ``theta_k`` (``tangent=True``, direction
  ``e_k - e_{k+1}`` in bend space; Powell's method is equivariant under this linear map, so this
  IS Powell on ``(theta, x0, y0)``, checked against scipy);
* along a tangent direction ``theta_k`` segment ``k`` turns about ``R_k`` and the tail
  translates by ``v`` (``|v| <= 2/N``): bending changes at two nodes, confinement by
  ``Lambda (2 v . sum_{j>k} w_j R_j + |v|^2 sum_{j>k} w_j)``, O(1); the hard-core test uses
  per-segment clearances to the head and to segment k (no test while ``|v|`` is below all);
* along a coordinate direction ``phi_k`` the tail (nodes ``j > k``) rotates rigidly about
  ``R_k``: the bending energy changes at one node and the confinement energy follows from
  suffix sums of ``w_j``, ``w_j R_j``, ``w_j |R_j|^2``, so one trial costs O(1); along ``x0``,
  ``y0`` the rod translates (O(1), no new contact possible);
* hard core: a trial is tested for self-intersection only when it would be accepted (its energy
  is not above the current best of the line search); otherwise its finite value only enters
  the parabolic interpolation. For a coordinate trial only head (segments < k) against rotated
  tail (segments >= k) is tested: each tail segment ``j`` has a precomputed clearance ``c_j`` to
  the head (grid, capped) and moves by at most ``2 |sin(alpha/2)| r_j``, so a trial with
  ``|alpha|`` below ``min_j c_j / r_j`` is admissible with no test at all, and otherwise only the
  tail segments that could reach the head are tested, through the head's grid;
* general directions (Powell's extrapolated ones) cost O(N) per trial and use the full grid test;
* the nematic self-contact term ``u sin^2 alpha`` (pairs of segments closer than a cut-off) uses
  the contact list of the configuration at the start of each Powell iteration, kept fixed during
  the iteration; along ``theta_k`` it is O(1) from ``sum cos 2phi``, ``sum sin 2phi`` of the
  head-tail pairs.

Inadmissible trials get the energy ``BIG`` (1e30), "a very large number" as in the paper; a
trial is inadmissible when two non-adjacent segments come closer than ``MARGIN`` (1e-9 L).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from simulate.intersect import close_pairs, has_contact_grid, seg_dist2

BIG = 1e30
# Clearance kept between non-adjacent segments (units of L). The hard core pushes contacts to
# the boundary of the admissible set: without a margin, contacts end ~1e-15 apart and the
# rounding of rebuilding positions from angles (or of the next stage's start) can turn them
# into crossings (measured: 2e-15 minimum gaps, and a crossing after an anneal stage).
MARGIN = 1e-9
_M2 = MARGIN * MARGIN
_GOLD = 1.618034
_CG = 0.3819660
_MINTOL = 1.0e-11


# ----------------------------------------------------------------------------- state
@njit(cache=True)
def _build_xy(p, n, xy):
    # p holds bend angles: theta_i = p_0 + ... + p_i
    ds = 1.0 / n
    xy[0, 0] = p[n]
    xy[0, 1] = p[n + 1]
    th = 0.0
    for i in range(n):
        th += p[i]
        xy[i + 1, 0] = xy[i, 0] + ds * math.cos(th)
        xy[i + 1, 1] = xy[i, 1] + ds * math.sin(th)


@njit(cache=True)
def _theta(p, n, th):
    t = 0.0
    for i in range(n):
        t += p[i]
        th[i] = t


@njit(cache=True)
def _suffix(xy, w, sw, spx, spy, sq):
    """Suffix sums over nodes j >= k of w, w x, w y, w |R|^2 (index N+1 holds zeros)."""
    n1 = xy.shape[0]
    sw[n1] = 0.0
    spx[n1] = 0.0
    spy[n1] = 0.0
    sq[n1] = 0.0
    for j in range(n1 - 1, -1, -1):
        x = xy[j, 0]
        y = xy[j, 1]
        sw[j] = sw[j + 1] + w[j]
        spx[j] = spx[j + 1] + w[j] * x
        spy[j] = spy[j + 1] + w[j] * y
        sq[j] = sq[j + 1] + w[j] * (x * x + y * y)


@njit(cache=True)
def _bending_p(p, n):
    e = 0.0
    for i in range(1, n):
        e += 2.0 - 2.0 * math.cos(p[i])
    return e * n


@njit(cache=True)
def _nematic_p(th, pairs, u):
    # th: tangent angles
    if u == 0.0:
        return 0.0
    e = 0.0
    for q in range(pairs.shape[0]):
        s = math.sin(th[pairs[q, 0]] - th[pairs[q, 1]])
        e += s * s
    return u * e


@njit(cache=True)
def _outside_wall(xy, wall2):
    for j in range(xy.shape[0]):
        if xy[j, 0] * xy[j, 0] + xy[j, 1] * xy[j, 1] > wall2:
            return True
    return False


# ----------------------------------------------------------------------------- head/tail test
@njit(cache=True)
def _head_grid(xy, k, hcell):
    """Grid (CSR) of head segments 0..k-1 over their bounding box."""
    xmin = xy[0, 0]
    xmax = xmin
    ymin = xy[0, 1]
    ymax = ymin
    for i in range(1, k + 1):
        xmin = min(xmin, xy[i, 0])
        xmax = max(xmax, xy[i, 0])
        ymin = min(ymin, xy[i, 1])
        ymax = max(ymax, xy[i, 1])
    h = max(hcell, max(xmax - xmin, ymax - ymin) / 40.0)
    nx = int((xmax - xmin) / h) + 1
    ny = int((ymax - ymin) / h) + 1
    ncell = nx * ny
    count = np.zeros(ncell + 1, np.int64)
    for s in range(k):
        x0 = int((min(xy[s, 0], xy[s + 1, 0]) - xmin) / h)
        x1 = int((max(xy[s, 0], xy[s + 1, 0]) - xmin) / h)
        y0 = int((min(xy[s, 1], xy[s + 1, 1]) - ymin) / h)
        y1 = int((max(xy[s, 1], xy[s + 1, 1]) - ymin) / h)
        for cx in range(x0, min(x1, nx - 1) + 1):
            for cy in range(y0, min(y1, ny - 1) + 1):
                count[cx * ny + cy + 1] += 1
    for c in range(ncell):
        count[c + 1] += count[c]
    items = np.empty(count[ncell], np.int64)
    fill = count[:-1].copy()
    for s in range(k):
        x0 = int((min(xy[s, 0], xy[s + 1, 0]) - xmin) / h)
        x1 = int((max(xy[s, 0], xy[s + 1, 0]) - xmin) / h)
        y0 = int((min(xy[s, 1], xy[s + 1, 1]) - ymin) / h)
        y1 = int((max(xy[s, 1], xy[s + 1, 1]) - ymin) / h)
        for cx in range(x0, min(x1, nx - 1) + 1):
            for cy in range(y0, min(y1, ny - 1) + 1):
                c = cx * ny + cy
                items[fill[c]] = s
                fill[c] += 1
    return xmin, ymin, h, nx, ny, count, items


@njit(cache=True)
def _seg_vs_head(ax, ay, bx, by, j, k, xy, xmin, ymin, h, nx, ny, start, items, pad):
    """Smallest squared distance (0 = touching) of segment a-b (index j) to head segments whose
    cells meet its bbox grown by ``pad``; returns early with 0 on contact."""
    x0 = int(math.floor((min(ax, bx) - pad - xmin) / h))
    x1 = int(math.floor((max(ax, bx) + pad - xmin) / h))
    y0 = int(math.floor((min(ay, by) - pad - ymin) / h))
    y1 = int(math.floor((max(ay, by) + pad - ymin) / h))
    best = math.inf
    if x1 < 0 or y1 < 0 or x0 > nx - 1 or y0 > ny - 1:
        return best
    for cx in range(max(x0, 0), min(x1, nx - 1) + 1):
        for cy in range(max(y0, 0), min(y1, ny - 1) + 1):
            c = cx * ny + cy
            for q in range(start[c], start[c + 1]):
                i = items[q]
                if i == j - 1:
                    continue
                d2 = seg_dist2(xy[i, 0], xy[i, 1], xy[i + 1, 0], xy[i + 1, 1], ax, ay, bx, by)
                if d2 < best:
                    best = d2
                    if best == 0.0:
                        return 0.0
    return best


@njit(cache=True)
def _seg_hits_head(ax, ay, bx, by, j, xy, xmin, ymin, h, nx, ny, start, items):
    x0 = int(math.floor((min(ax, bx) - MARGIN - xmin) / h))
    x1 = int(math.floor((max(ax, bx) + MARGIN - xmin) / h))
    y0 = int(math.floor((min(ay, by) - MARGIN - ymin) / h))
    y1 = int(math.floor((max(ay, by) + MARGIN - ymin) / h))
    if x1 < 0 or y1 < 0 or x0 > nx - 1 or y0 > ny - 1:
        return False
    for cx in range(max(x0, 0), min(x1, nx - 1) + 1):
        for cy in range(max(y0, 0), min(y1, ny - 1) + 1):
            c = cx * ny + cy
            for q in range(start[c], start[c + 1]):
                i = items[q]
                if i == j - 1:
                    continue
                if seg_dist2(xy[i, 0], xy[i, 1], xy[i + 1, 0], xy[i + 1, 1], ax, ay, bx,
                             by) < _M2:
                    return True
    return False


# ----------------------------------------------------------------------------- evaluation
# ctx (float64 array) for a line search:
#   mode 0 (theta_k): [0, k, s, cdot, ccrs, dkm, dkp, bkm, bkp, nc, nsn, f0, built, chord_safe]
#   mode 1 (x0 / y0): [1, axis, s, pw, W0, f0]
#   mode 2 (general): [2]
#   mode 3 (tangent theta_k, p holds bend angles: phi_k += x, phi_{k+1} -= x):
#          [3, k, s, Sx, Sy, phi_k, phi_k+1, b_k, b_k+1, nc, nsn, f0, built, safe, hc, -,
#           W, cos theta_k, sin theta_k]
_CTX = 24


@njit(cache=True)
def _energy_trial(a, ctx, p, d, pt, xyt, tht, lam, w, u, pairs):
    mode = int(ctx[0])
    n = p.shape[0] - 2
    if mode == 0:
        k = int(ctx[1])
        x = ctx[2] * a
        e = ctx[11]
        if k >= 1:
            e += n * (2.0 - 2.0 * math.cos(ctx[5] + x) - ctx[7])
        e += 2.0 * lam * ((math.cos(x) - 1.0) * ctx[3] + math.sin(x) * ctx[4])
        if u > 0.0:
            e += 0.5 * u * ((1.0 - math.cos(2.0 * x)) * ctx[9] - math.sin(2.0 * x) * ctx[10])
        return e
    if mode == 1:
        x = ctx[2] * a
        return ctx[5] + lam * (2.0 * x * ctx[3] + x * x * ctx[4])
    if mode == 3:
        k = int(ctx[1])
        x = ctx[2] * a
        c = math.cos(x)
        sn = math.sin(x)
        e = ctx[11]
        if k >= 1:
            e += n * (2.0 - 2.0 * math.cos(ctx[5] + x) - ctx[7])
        if k < n - 1:
            e += n * (2.0 - 2.0 * math.cos(ctx[6] - x) - ctx[8])
        ds = 1.0 / n
        # the tail (nodes j > k) translates by v = ds (t_k(theta + x) - t_k(theta))
        vx = ds * (ctx[17] * c - ctx[18] * sn - ctx[17])
        vy = ds * (ctx[18] * c + ctx[17] * sn - ctx[18])
        e += lam * (2.0 * (vx * ctx[3] + vy * ctx[4]) + (vx * vx + vy * vy) * ctx[16])
        if u > 0.0:
            e += 0.5 * u * ((1.0 - math.cos(2.0 * x)) * ctx[9] - math.sin(2.0 * x) * ctx[10])
        return e
    # general direction: O(N)
    m = p.shape[0]
    for i in range(m):
        pt[i] = p[i] + a * d[i]
    _build_xy(pt, n, xyt)
    eb = _bending_p(pt, n)
    ec = 0.0
    for j in range(n + 1):
        ec += w[j] * (xyt[j, 0] * xyt[j, 0] + xyt[j, 1] * xyt[j, 1])
    if u > 0.0:
        _theta(pt, n, tht)
    return eb + lam * ec + _nematic_p(tht, pairs, u)


@njit(cache=True)
def _prepare_head(ctx, xy, rj, clear2, gpar, gstart, gitems, n):
    """Head grid, per-tail-segment reach r_j and clearance c_j (capped), safe chord."""
    k = int(ctx[1])
    xmin, ymin, h, nx, ny, start, items = _head_grid(xy, k, 1.0 / n)
    gpar[0] = xmin
    gpar[1] = ymin
    gpar[2] = h
    gpar[3] = nx
    gpar[4] = ny
    nc = nx * ny + 1
    gstart[:nc] = start
    gitems[:items.shape[0]] = items
    rkx = xy[k, 0]
    rky = xy[k, 1]
    safe = math.inf
    pad = h
    for j in range(k, n):
        ax = xy[j, 0]
        ay = xy[j, 1]
        bx = xy[j + 1, 0]
        by = xy[j + 1, 1]
        r = max(math.hypot(ax - rkx, ay - rky), math.hypot(bx - rkx, by - rky))
        rj[j] = r
        c2 = _seg_vs_head(ax, ay, bx, by, j, k, xy, xmin, ymin, h, nx, ny, gstart, gitems, pad)
        c = max(math.sqrt(min(c2, pad * pad)) - MARGIN, 0.0)
        clear2[j] = c * c
        if r > 0.0:
            safe = min(safe, c / r)
    ctx[12] = 1.0
    ctx[13] = safe


@njit(cache=True)
def _prepare_tangent(ctx, xy, clear2, gpar, gstart, gitems, n):
    """Tangent move of segment k: head 0..k-1 fixed, segment k turns about R_k, the tail
    translates; every moving point moves by at most |v| relative to the head and to segment
    k. Clearance c_j of segment j >= k to the head (and, j >= k+2, to segment k), capped."""
    k = int(ctx[1])
    h = 1.0 / n
    if k >= 1:
        xmin, ymin, h, nx, ny, start, items = _head_grid(xy, k, 1.0 / n)
        gpar[0] = xmin
        gpar[1] = ymin
        gpar[2] = h
        gpar[3] = nx
        gpar[4] = ny
        gstart[:nx * ny + 1] = start
        gitems[:items.shape[0]] = items
    pad = h
    safe = math.inf
    kx0 = xy[k, 0]
    ky0 = xy[k, 1]
    kx1 = xy[k + 1, 0]
    ky1 = xy[k + 1, 1]
    for j in range(k, n):
        ax = xy[j, 0]
        ay = xy[j, 1]
        bx = xy[j + 1, 0]
        by = xy[j + 1, 1]
        c2 = pad * pad
        if k >= 1:
            c2 = min(c2, _seg_vs_head(ax, ay, bx, by, j, k, xy, gpar[0], gpar[1], h,
                                      int(gpar[3]), int(gpar[4]), gstart, gitems, pad))
        if j >= k + 2:
            c2 = min(c2, seg_dist2(kx0, ky0, kx1, ky1, ax, ay, bx, by))
        c = max(math.sqrt(c2) - MARGIN, 0.0)
        clear2[j] = c * c
        safe = min(safe, c)
    ctx[12] = 1.0
    ctx[13] = safe


@njit(cache=True)
def _admissible_tangent(a, ctx, xy, wall2, clear2, gpar, gstart, gitems, stats, n):
    k = int(ctx[1])
    x = ctx[2] * a
    c = math.cos(x)
    sn = math.sin(x)
    ds = 1.0 / n
    tx = ctx[17] * c - ctx[18] * sn
    ty = ctx[18] * c + ctx[17] * sn
    vx = ds * tx - ds * ctx[17]
    vy = ds * ty - ds * ctx[18]
    if wall2 < math.inf:
        for j in range(k + 1, n + 1):
            qx = xy[j, 0] + vx
            qy = xy[j, 1] + vy
            if qx * qx + qy * qy > wall2:
                return False
    if ctx[12] == 0.0:
        _prepare_tangent(ctx, xy, clear2, gpar, gstart, gitems, n)
    v2 = vx * vx + vy * vy
    if v2 < ctx[13] * ctx[13]:
        stats[5] += 1
        return True
    stats[4] += 1
    kx0 = xy[k, 0]
    ky0 = xy[k, 1]
    kx1 = kx0 + ds * tx
    ky1 = ky0 + ds * ty
    for j in range(k, n):
        if v2 < clear2[j]:
            continue
        if j == k:
            ax, ay, bx, by = kx0, ky0, kx1, ky1
        else:
            ax = xy[j, 0] + vx
            ay = xy[j, 1] + vy
            bx = xy[j + 1, 0] + vx
            by = xy[j + 1, 1] + vy
        if k >= 1:
            if _seg_hits_head(ax, ay, bx, by, j, xy, gpar[0], gpar[1], gpar[2], int(gpar[3]),
                              int(gpar[4]), gstart, gitems):
                return False
        if j >= k + 2 and seg_dist2(kx0, ky0, kx1, ky1, ax, ay, bx, by) < _M2:
            return False
    return True


@njit(cache=True)
def _admissible(a, ctx, p, d, xy, xyt, wall2, rj, clear2, gpar, gstart, gitems, stats):
    """Hard core (and wall) for the trial at step ``a``; ``xyt`` holds a general trial."""
    mode = int(ctx[0])
    n = p.shape[0] - 2
    stats[2] += 1
    if mode == 3:
        return _admissible_tangent(a, ctx, xy, wall2, clear2, gpar, gstart, gitems, stats, n)
    if mode == 0:
        k = int(ctx[1])
        x = ctx[2] * a
        c = math.cos(x)
        s = math.sin(x)
        rkx = xy[k, 0]
        rky = xy[k, 1]
        if wall2 < math.inf:
            for j in range(k + 1, n + 1):
                dx = xy[j, 0] - rkx
                dy = xy[j, 1] - rky
                qx = rkx + c * dx - s * dy
                qy = rky + s * dx + c * dy
                if qx * qx + qy * qy > wall2:
                    return False
        if k == 0:
            return True
        if ctx[12] == 0.0:
            _prepare_head(ctx, xy, rj, clear2, gpar, gstart, gitems, n)
        chord = 2.0 * abs(math.sin(0.5 * x))
        if chord < ctx[13]:
            stats[5] += 1
            return True
        stats[4] += 1
        xmin = gpar[0]
        ymin = gpar[1]
        h = gpar[2]
        nx = int(gpar[3])
        ny = int(gpar[4])
        for j in range(k, n):
            if chord * chord * rj[j] * rj[j] < clear2[j]:
                continue
            dx = xy[j, 0] - rkx
            dy = xy[j, 1] - rky
            ax = rkx + c * dx - s * dy
            ay = rky + s * dx + c * dy
            dx = xy[j + 1, 0] - rkx
            dy = xy[j + 1, 1] - rky
            bx = rkx + c * dx - s * dy
            by = rky + s * dx + c * dy
            if _seg_hits_head(ax, ay, bx, by, j, xy, xmin, ymin, h, nx, ny, gstart, gitems):
                return False
        return True
    if mode == 1:
        if wall2 < math.inf:
            axis = int(ctx[1])
            x = ctx[2] * a
            for j in range(n + 1):
                qx = xy[j, 0] + (x if axis == 0 else 0.0)
                qy = xy[j, 1] + (x if axis == 1 else 0.0)
                if qx * qx + qy * qy > wall2:
                    return False
        return True
    stats[4] += 1
    if wall2 < math.inf and _outside_wall(xyt, wall2):
        return False
    return not has_contact_grid(xyt, MARGIN)


@njit(cache=True)
def _ev(a, thresh, ctx, p, d, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2, gpar, gstart,
        gitems, stats):
    stats[0] += 1
    f = _energy_trial(a, ctx, p, d, pt, xyt, gpar[5:], lam, w, u, pairs)
    if f <= thresh and ctx[14] != 0.0:
        if not _admissible(a, ctx, p, d, xy, xyt, wall2, rj, clear2, gpar, gstart, gitems,
                           stats):
            return BIG
    return f


@njit(cache=True)
def _line_search(tol, ctx, p, d, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2, gpar,
                 gstart, gitems, stats):
    """scipy's ``bracket`` (xa=0, xb=1, grow_limit=110) then ``Brent`` (tol, maxiter 500).

    Returns (alpha_min, f_min). Trials are checked for admissibility only when they could
    become the best point (see module docstring).
    """
    md = int(ctx[0])
    f0 = ctx[11] if (md == 0 or md == 3) else (ctx[5] if md == 1 else ctx[15])
    xa = 0.0
    xb = 1.0
    fa = f0
    fb = _ev(xb, f0, ctx, p, d, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2, gpar, gstart,
             gitems, stats)
    if fa < fb:
        xa, xb = xb, xa
        fa, fb = fb, fa
    xc = xb + _GOLD * (xb - xa)
    fc = _ev(xc, f0, ctx, p, d, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2, gpar, gstart,
             gitems, stats)
    it = 0
    ok = True
    while fc < fb:
        tmp1 = (xb - xa) * (fb - fc)
        tmp2 = (xb - xc) * (fb - fa)
        val = tmp2 - tmp1
        if abs(val) < 1e-21:
            denom = 2.0e-21
        else:
            denom = 2.0 * val
        wv = xb - ((xb - xc) * tmp2 - (xb - xa) * tmp1) / denom
        wlim = xb + 110.0 * (xc - xb)
        if it > 1000:
            ok = False
            break
        it += 1
        if (wv - xc) * (xb - wv) > 0.0:
            fw = _ev(wv, f0, ctx, p, d, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2, gpar,
                     gstart, gitems, stats)
            if fw < fc:
                xa = xb
                xb = wv
                fa = fb
                fb = fw
                break
            elif fw > fb:
                xc = wv
                fc = fw
                break
            wv = xc + _GOLD * (xc - xb)
            fw = _ev(wv, f0, ctx, p, d, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2, gpar,
                     gstart, gitems, stats)
        elif (wv - wlim) * (wlim - xc) >= 0.0:
            wv = wlim
            fw = _ev(wv, f0, ctx, p, d, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2, gpar,
                     gstart, gitems, stats)
        elif (wv - wlim) * (xc - wv) > 0.0:
            fw = _ev(wv, f0, ctx, p, d, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2, gpar,
                     gstart, gitems, stats)
            if fw < fc:
                xb = xc
                xc = wv
                wv = xc + _GOLD * (xc - xb)
                fb = fc
                fc = fw
                fw = _ev(wv, f0, ctx, p, d, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2,
                         gpar, gstart, gitems, stats)
        else:
            wv = xc + _GOLD * (xc - xb)
            fw = _ev(wv, f0, ctx, p, d, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2, gpar,
                     gstart, gitems, stats)
        xa = xb
        xb = xc
        xc = wv
        fa = fb
        fb = fc
        fc = fw
    cond1 = (fb < fc and fb <= fa) or (fb < fa and fb <= fc)
    cond2 = (xa < xb < xc) or (xc < xb < xa)
    cond3 = math.isfinite(xa) and math.isfinite(xb) and math.isfinite(xc)
    if not (ok and cond1 and cond2 and cond3):
        # scipy's _recover_from_bracket_error: best of the three points
        if fb < fa and fb <= fc:
            return xb, fb
        if fc < fa:
            return xc, fc
        return xa, fa
    # Brent
    x = xb
    wb = xb
    v = xb
    fx = fb
    fw = fb
    fv = fb
    if xa < xc:
        a = xa
        b = xc
    else:
        a = xc
        b = xa
    deltax = 0.0
    rat = 0.0
    it = 0
    while it < 500:
        tol1 = tol * abs(x) + _MINTOL
        tol2 = 2.0 * tol1
        xmid = 0.5 * (a + b)
        if abs(x - xmid) < (tol2 - 0.5 * (b - a)):
            break
        if abs(deltax) <= tol1:
            if x >= xmid:
                deltax = a - x
            else:
                deltax = b - x
            rat = _CG * deltax
        else:
            tmp1 = (x - wb) * (fx - fv)
            tmp2 = (x - v) * (fx - fw)
            pp = (x - v) * tmp2 - (x - wb) * tmp1
            tmp2 = 2.0 * (tmp2 - tmp1)
            if tmp2 > 0.0:
                pp = -pp
            tmp2 = abs(tmp2)
            dx_temp = deltax
            deltax = rat
            if (pp > tmp2 * (a - x)) and (pp < tmp2 * (b - x)) and \
                    (abs(pp) < abs(0.5 * tmp2 * dx_temp)):
                rat = pp * 1.0 / tmp2
                uu = x + rat
                if (uu - a) < tol2 or (b - uu) < tol2:
                    if xmid - x >= 0:
                        rat = tol1
                    else:
                        rat = -tol1
            else:
                if x >= xmid:
                    deltax = a - x
                else:
                    deltax = b - x
                rat = _CG * deltax
        if abs(rat) < tol1:
            if rat >= 0:
                uu = x + tol1
            else:
                uu = x - tol1
        else:
            uu = x + rat
        fu = _ev(uu, fx, ctx, p, d, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2, gpar,
                 gstart, gitems, stats)
        if fu > fx:
            if uu < x:
                a = uu
            else:
                b = uu
            if (fu <= fw) or (wb == x):
                v = wb
                wb = uu
                fv = fw
                fw = fu
            elif (fu <= fv) or (v == x) or (v == wb):
                v = uu
                fv = fu
        else:
            if uu >= x:
                a = x
            else:
                b = x
            v = wb
            wb = x
            x = uu
            fv = fw
            fw = fx
            fx = fu
        it += 1
    return x, fx


# ----------------------------------------------------------------------------- Powell
@njit(cache=True)
def _refresh(p, n, xy, w, sw, spx, spy, sq):
    _build_xy(p, n, xy)
    _suffix(xy, w, sw, spx, spy, sq)


@njit(cache=True)
def powell_run(p, lam, kind, sgn, dirs, maxiter, xtol, ftol, u, cutoff, min_separation, wall,
               stats, hard_core=True, tangent=False):
    """One run of Powell's method from ``p`` (modified in place), as scipy's ``Powell``.

    Parameters
    ----------
    p : (N+2,) float64
        Bend angles ``phi_0 .. phi_{N-1}`` then ``x0, y0``; must be admissible.
    lam : float
        Confinement Lambda.
    kind : (N+2,) int64
        Per direction slot: the coordinate index (0..N+1), or -1 for a general direction held
        in ``dirs[slot]``. Updated in place by Powell's direction-set rule.
    sgn : (N+2,) float64
        Sign of each coordinate direction.
    dirs : (N+2, N+2) float64
        General direction vectors (rows where ``kind == -1``); updated in place.
    maxiter : int
        Powell iterations.
    xtol, ftol : float
        scipy's tolerances (line search ``tol = 100 xtol``; stop when ``2 (f_old - f) <=
        ftol (|f_old| + |f|)``).
    u : float
        Nematic self-contact strength; 0 disables the term.
    cutoff : float
        Contact distance of the nematic term (units of L).
    min_separation : int
        Segment pairs closer than this along the rod are not contacts.
    wall : float
        Hard-wall disk radius, ``inf`` for none.
    stats : (6,) int64
        Accumulates [evaluations, line searches, admissibility checks, iterations,
        explicit collision tests, checks settled by the clearance bound].
    hard_core : bool
        False disables the self-intersection test (for comparisons with scipy only).
    tangent : bool
        If true, coordinate slot ``k < N`` is the TANGENT angle ``theta_k`` (direction
        ``e_k - e_{k+1}`` in bend-angle space: segment k turns, the tail translates by at most
        ``2/N``); this is Powell's method in the parameters ``(theta, x0, y0)`` exactly (Powell
        is equivariant under the linear map theta <-> phi when the direction set is mapped).
        If false, slot ``k`` is the bend angle ``phi_k`` (the tail rotates about ``R_k``).

    Returns
    -------
    float
        Energy at the end (nematic term included when ``u > 0``).
    """
    m = p.shape[0]
    n = m - 2
    ds = 1.0 / n
    w = np.full(n + 1, ds)
    w[0] = 0.5 * ds
    w[n] = 0.5 * ds
    xy = np.empty((n + 1, 2))
    xyt = np.empty((n + 1, 2))
    pt = np.empty(m)
    sw = np.empty(n + 2)
    spx = np.empty(n + 2)
    spy = np.empty(n + 2)
    sq = np.empty(n + 2)
    clear2 = np.empty(n)
    rj = np.empty(n)
    gpar = np.empty(5 + n)
    th = np.empty(n)
    gstart = np.empty(41 * 41 + 2, np.int64)
    gitems = np.empty(4 * n + 4, np.int64)
    ctx = np.zeros(_CTX)
    ctx[14] = 1.0 if hard_core else 0.0
    zero_d = np.zeros(m)
    wall2 = wall * wall
    x1 = p.copy()
    d1 = np.empty(m)
    pairs = np.empty((0, 2), np.int64)

    _refresh(p, n, xy, w, sw, spx, spy, sq)
    _theta(p, n, th)
    if u > 0.0:
        pairs = close_pairs(xy, cutoff, min_separation)
    fval = _bending_p(p, n) + lam * sq[0] + _nematic_p(th, pairs, u)
    it = 0
    while True:
        fx = fval
        bigind = 0
        delta = 0.0
        for slot in range(m):
            fx2 = fval
            kk = kind[slot]
            stats[1] += 1
            if kk >= 0 and kk < n and tangent:
                k = kk
                ctx[0] = 3.0
                ctx[1] = k
                ctx[2] = sgn[slot]
                ctx[3] = spx[k + 1]
                ctx[4] = spy[k + 1]
                ctx[5] = p[k]
                ctx[6] = p[k + 1] if k < n - 1 else 0.0
                ctx[7] = 2.0 - 2.0 * math.cos(ctx[5])
                ctx[8] = 2.0 - 2.0 * math.cos(ctx[6])
                ctx[16] = sw[k + 1]
                ctx[17] = math.cos(th[k])
                ctx[18] = math.sin(th[k])
                nc = 0.0
                ns = 0.0
                if u > 0.0:
                    for q in range(pairs.shape[0]):
                        ia = pairs[q, 0]
                        ib = pairs[q, 1]
                        if ia == k or ib == k:
                            ph = 2.0 * (th[ia] - th[ib])
                            nc += math.cos(ph)
                            ns += math.sin(ph) if ib == k else -math.sin(ph)
                ctx[9] = nc
                ctx[10] = ns
                ctx[11] = fval
                ctx[12] = 0.0
                ctx[13] = 0.0
                amin, fnew = _line_search(xtol * 100.0, ctx, p, zero_d, pt, xy, xyt, lam, w, u,
                                          pairs, wall2, rj, clear2, gpar, gstart, gitems, stats)
                if amin != 0.0:
                    x = sgn[slot] * amin
                    p[k] += x
                    if k < n - 1:
                        p[k + 1] -= x
                    th[k] += x
                    ds = 1.0 / n
                    c = math.cos(x)
                    s = math.sin(x)
                    vx = ds * (ctx[17] * c - ctx[18] * s - ctx[17])
                    vy = ds * (ctx[18] * c + ctx[17] * s - ctx[18])
                    for j in range(k + 1, n + 1):
                        xy[j, 0] += vx
                        xy[j, 1] += vy
                    _suffix(xy, w, sw, spx, spy, sq)
                fval = fnew
            elif kk >= 0 and kk < n:
                k = kk
                rkx = xy[k, 0]
                rky = xy[k, 1]
                W1 = sw[k + 1]
                vx = spx[k + 1] - W1 * rkx
                vy = spy[k + 1] - W1 * rky
                ctx[0] = 0.0
                ctx[1] = k
                ctx[2] = sgn[slot]
                ctx[3] = rkx * vx + rky * vy
                ctx[4] = rky * vx - rkx * vy
                ctx[5] = p[k]
                ctx[7] = 2.0 - 2.0 * math.cos(ctx[5])
                nc = 0.0
                ns = 0.0
                if u > 0.0:
                    for q in range(pairs.shape[0]):
                        ia = pairs[q, 0]
                        ib = pairs[q, 1]
                        if ia < k <= ib:
                            ph = 2.0 * (th[ia] - th[ib])
                            nc += math.cos(ph)
                            ns += math.sin(ph)
                ctx[9] = nc
                ctx[10] = ns
                ctx[11] = fval
                ctx[12] = 0.0
                ctx[13] = 0.0
                amin, fnew = _line_search(xtol * 100.0, ctx, p, zero_d, pt, xy, xyt, lam, w, u,
                                          pairs, wall2, rj, clear2, gpar, gstart, gitems, stats)
                if amin != 0.0:
                    x = sgn[slot] * amin
                    p[k] += x
                    for j in range(k, n):
                        th[j] += x
                    c = math.cos(x)
                    s = math.sin(x)
                    for j in range(k + 1, n + 1):
                        dx = xy[j, 0] - rkx
                        dy = xy[j, 1] - rky
                        xy[j, 0] = rkx + c * dx - s * dy
                        xy[j, 1] = rky + s * dx + c * dy
                    _suffix(xy, w, sw, spx, spy, sq)
                fval = fnew
            elif kk >= n:
                ctx[0] = 1.0
                ctx[1] = kk - n
                ctx[2] = sgn[slot]
                ctx[3] = spx[0] if kk == n else spy[0]
                ctx[4] = sw[0]
                ctx[5] = fval
                amin, fnew = _line_search(xtol * 100.0, ctx, p, zero_d, pt, xy, xyt, lam, w, u,
                                          pairs, wall2, rj, clear2, gpar, gstart, gitems, stats)
                if amin != 0.0:
                    x = sgn[slot] * amin
                    p[kk] += x
                    for j in range(n + 1):
                        xy[j, kk - n] += x
                    _suffix(xy, w, sw, spx, spy, sq)
                fval = fnew
            else:
                ctx[0] = 2.0
                ctx[15] = fval
                amin, fnew = _line_search(xtol * 100.0, ctx, p, dirs[slot], pt, xy, xyt, lam, w,
                                          u, pairs, wall2, rj, clear2, gpar, gstart, gitems,
                                          stats)
                if amin != 0.0:
                    for i in range(m):
                        p[i] += amin * dirs[slot, i]
                    _refresh(p, n, xy, w, sw, spx, spy, sq)
                    _theta(p, n, th)
                fval = fnew
            if (fx2 - fval) > delta:
                delta = fx2 - fval
                bigind = slot
        it += 1
        stats[3] += 1
        # re-derive positions and energy from the parameters (no drift from rotations)
        _refresh(p, n, xy, w, sw, spx, spy, sq)
        _theta(p, n, th)
        fval = _bending_p(p, n) + lam * sq[0] + _nematic_p(th, pairs, u)
        bnd = ftol * (abs(fx) + abs(fval)) + 1e-20
        if 2.0 * (fx - fval) <= bnd or it >= maxiter:
            break
        # extrapolated point and Powell's direction-set update (as scipy)
        for i in range(m):
            d1[i] = p[i] - x1[i]
            x1[i] = p[i]
        ctx[0] = 2.0
        ctx[15] = fval
        fx2 = _ev(1.0, fx, ctx, p, d1, pt, xy, xyt, lam, w, u, pairs, wall2, rj, clear2, gpar,
                  gstart, gitems, stats)
        if fx > fx2:
            t = 2.0 * (fx + fx2 - 2.0 * fval)
            temp = fx - fval - delta
            t *= temp * temp
            temp = fx - fx2
            t -= delta * temp * temp
            if t < 0.0:
                stats[1] += 1
                amin, fnew = _line_search(xtol * 100.0, ctx, p, d1, pt, xy, xyt, lam, w, u,
                                          pairs, wall2, rj, clear2, gpar, gstart, gitems, stats)
                if amin != 0.0:
                    for i in range(m):
                        p[i] += amin * d1[i]
                    _refresh(p, n, xy, w, sw, spx, spy, sq)
                    _theta(p, n, th)
                    fval = fnew
                    kind[bigind] = kind[m - 1]
                    sgn[bigind] = sgn[m - 1]
                    for i in range(m):
                        dirs[bigind, i] = dirs[m - 1, i]
                    kind[m - 1] = -1
                    for i in range(m):
                        dirs[m - 1, i] = amin * d1[i]
                else:
                    fval = fnew
        if u > 0.0:
            pairs = close_pairs(xy, cutoff, min_separation)
            fval = _bending_p(p, n) + lam * sq[0] + _nematic_p(th, pairs, u)
    return fval
