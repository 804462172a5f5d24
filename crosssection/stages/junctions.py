"""Stage 5: junctions, the skeleton pixels with at least three neighbours, merged into clusters.

Paper, section "Image analysis procedure": "Junction points are then defined as pixels with at
least 3 neighbours". On a digital skeleton one physical junction often gives several such
pixels (a 2x2 block where two lines cross, two pixels one gap apart where a crossing is
resolved into two branch points). Choices, each tested:

- junction pixels that touch (8-connectivity) form one junction;
- junction pixels closer than ``merge_px`` (Euclidean, default 2 px, i.e. one skeleton pixel
  in between) are merged too, and the skeleton pixels between them (both neighbours in the same
  merged cluster) join the cluster, so that an X crossing (paper: about 1 % of the junctions
  have degree 4) becomes one junction of degree 4 instead of two of degree 3;
- the junction position is the mean of its cluster pixels.

Junctions further apart but joined by a stack shorter than the ink blob they sit in (thick
X crossings) are merged later, by :func:`merge_junctions`, once the stack graph is known
(see ``pipeline.analyze``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from crosssection.core.errors import ParameterError
from crosssection.core.unionfind import group_labels
from crosssection.stages.skeleton import nonzero_rc


@dataclass
class Junctions:
    """Junction clusters of a skeleton.

    Attributes
    ----------
    centers_rc : (K, 2) float array
        (row, col) centre of every junction (mean of its pixels).
    pixels : list of (P, 2) int arrays
        The skeleton pixels of every junction.
    label_image : (H, W) int32 array
        0 off junctions, ``j + 1`` on the pixels of junction ``j``.
    """

    centers_rc: np.ndarray
    pixels: list
    label_image: np.ndarray

    def __len__(self) -> int:
        return len(self.pixels)


# the 8 neighbours in raster order (row by row), as the cluster growth visits them
_NB_DR = np.array([-1, -1, -1, 0, 0, 1, 1, 1])
_NB_DC = np.array([-1, 0, 1, -1, 1, -1, 0, 1])


def _junction_labels(img, rows, cols, merge_px):
    """Label junction clusters of the padded uint8 skeleton ``img``.

    ``rows``, ``cols``: the skeleton pixels (padded coordinates, raster order). Returns the
    unpadded int32 label image (0 none, j+1 junction j), the number of clusters, and the
    junction pixels (unpadded row, col) with their cluster ids.

    Vectorised: the pixel pairs closer than ``merge_px`` are joined by connected components,
    and the growth of the clusters (see :func:`_grow`) runs pass by pass.
    """
    h, w = img.shape
    f = img.reshape(-1)
    flat = rows * w + cols
    nb = np.zeros(len(flat), np.int64)
    for dr, dc in zip(_NB_DR, _NB_DC):
        nb += f[flat + dr * w + dc]
    jp = flat[nb >= 3]  # junction pixels: >= 3 neighbours, raster order
    n = len(jp)
    lab = np.zeros((h, w), np.int32)
    if n == 0:
        e = np.zeros(0, np.int64)
        return lab[1:-1, 1:-1], 0, e, e.copy(), e.copy()
    idx = np.zeros((h, w), np.int64)  # 1 + junction pixel index
    idx.reshape(-1)[jp] = np.arange(1, n + 1)
    jr, jc = jp // w, jp % w
    rad = max(1, int(np.ceil(merge_px)))
    m2 = max(merge_px * merge_px, 2.0)  # touching pixels always merge
    pairs = [np.zeros((0, 2), np.int64)]
    for dr in range(-rad, rad + 1):
        for dc in range(-rad, rad + 1):
            if (dr == 0 and dc == 0) or dr * dr + dc * dc > m2:
                continue
            rr, cc = jr + dr, jc + dc
            ok = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
            i = np.flatnonzero(ok)
            k = idx[rr[i], cc[i]]
            pairs.append(np.stack([i[k > 0], k[k > 0] - 1], axis=1))
    # cluster ids in order of first pixel (raster order)
    cid = group_labels(n, np.concatenate(pairs))
    k = int(cid.max()) + 1
    labf = lab.reshape(-1)
    labf[jp] = cid + 1
    members = _grow(f, labf, jp, w)
    return lab[1:-1, 1:-1], k, members // w - 1, members % w - 1, labf[members].astype(np.int64) - 1


def _grow(f, labf, members, w):
    """Skeleton pixels between two pixels of the same cluster join it.

    Passes over the cluster pixels (in order; pixels added during a pass are visited from the
    next one): every unlabelled skeleton neighbour (raster order) whose skeleton neighbours
    are all in the cluster, at least two, joins it, until a pass adds nothing. ``labf`` is
    updated in place; returns the cluster pixels, the added ones appended in order.

    A pass is evaluated on all candidates at once. That is what the pixel-by-pixel pass gives
    unless a pixel added in the pass touches another candidate, whose test it could change;
    such a pass (rare) is run pixel by pixel.
    """
    noff = _NB_DR * w + _NB_DC
    while True:
        lab_of = labf[members].astype(np.int64)
        cand = (members[:, None] + noff[None, :]).reshape(-1)  # encounter order
        want = np.repeat(lab_of, 8)
        ok = (f[cand] != 0) & (labf[cand] == 0)
        cand, want = cand[ok], want[ok]
        if len(cand) == 0:
            return members
        n_in = np.zeros(len(cand), np.int64)
        n_out = np.zeros(len(cand), np.int64)
        for o in noff:
            q = cand + o
            on = f[q] != 0
            same = labf[q] == want
            n_in += on & same
            n_out += on & ~same
        good = (n_in >= 2) & (n_out == 0)
        if not good.any():
            return members
        new, first = np.unique(cand[good], return_index=True)
        new = new[np.argsort(first, kind="stable")]
        new_lab = want[good][np.sort(first)]
        touched = np.zeros(len(f), np.bool_)
        for o in noff:
            touched[new + o] = True
        if touched[cand[~np.isin(cand, new)]].any():
            members = _grow_pass(f, labf, members, noff)
            continue
        labf[new] = new_lab
        members = np.concatenate([members, new])


def _grow_pass(f, labf, members, noff):
    """One pass of :func:`_grow`, pixel by pixel."""
    added = []
    for p in members.tolist():
        j = labf[p]
        for o in noff.tolist():
            q = p + o
            if f[q] and labf[q] == 0:
                n_in = n_out = 0
                for o2 in noff.tolist():
                    if f[q + o2]:
                        if labf[q + o2] == j:
                            n_in += 1
                        else:
                            n_out += 1
                if n_in >= 2 and n_out == 0:
                    labf[q] = j
                    added.append(q)
    return np.concatenate([members, np.asarray(added, np.int64)])


def _from_pixels(rr, cc, ids, k, lab) -> Junctions:
    order = np.argsort(ids, kind="stable")
    rr, cc, ids = rr[order], cc[order], ids[order]
    bounds = np.searchsorted(ids, np.arange(k + 1))
    pixels = [np.stack([rr[bounds[j]:bounds[j + 1]], cc[bounds[j]:bounds[j + 1]]], axis=1)
              for j in range(k)]
    centers = (np.array([p.mean(axis=0) for p in pixels], dtype=float) if k
               else np.zeros((0, 2), float))
    return Junctions(centers_rc=centers, pixels=pixels, label_image=lab)


def find_junctions(skel, *, merge_px: float = 2.0) -> Junctions:
    """Junction clusters of a one-pixel skeleton.

    Parameters
    ----------
    skel : (H, W) bool array
        Skeleton from :func:`crosssection.stages.skeleton.skeletonize_mask`.
    merge_px : float, optional
        Junction pixels closer than this (Euclidean, pixels) belong to the same junction;
        touching pixels always do. Default 2 (one skeleton pixel in between).

    Returns
    -------
    Junctions
        Centres, pixels and label image; junction ids in raster order of their first pixel.
    """
    skel = np.asarray(skel)
    if skel.ndim != 2:
        raise ParameterError(f"skeleton must be a 2-D array, got shape {skel.shape}")
    if not np.isfinite(merge_px) or merge_px < 0:
        raise ParameterError(f"merge_px must be >= 0, got {merge_px}")
    h, w = skel.shape
    img = np.zeros((h + 2, w + 2), np.uint8)
    img[1:-1, 1:-1] = skel
    rows, cols = nonzero_rc(img)
    lab, k, rr, cc, ids = _junction_labels(img, rows, cols, float(merge_px))
    return _from_pixels(rr, cc, ids, k, lab)


def merge_junctions(junctions: Junctions, groups, extra_pixels=()) -> Junctions:
    """Merge junctions into one, adding skeleton pixels (the short stacks joining them).

    Parameters
    ----------
    junctions : Junctions
    groups : iterable of (a, b)
        Pairs of junction ids to merge (transitively).
    extra_pixels : iterable of (P, 2) int arrays
        Pixels that join the merged junctions (e.g. the path of the stack between them).
        Each array is attached to the junction its first touching cluster belongs to.

    Returns
    -------
    Junctions
        Renumbered in raster order of the first pixel; centres are the mean of all pixels.
    """
    k = len(junctions)
    parent = list(range(k))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in groups:
        ra, rb = find(int(a)), find(int(b))
        if ra != rb:
            parent[ra] = rb
    lab = junctions.label_image
    members: dict[int, list] = {}
    for j, pix in enumerate(junctions.pixels):
        members.setdefault(find(j), []).append(np.asarray(pix, np.int64).reshape(-1, 2))
    for (a, _b), pix in zip(groups, extra_pixels):
        pix = np.asarray(pix, dtype=np.int64).reshape(-1, 2)
        if len(pix):
            pix = pix[lab[pix[:, 0], pix[:, 1]] == 0]  # not yet a junction pixel
            members[find(int(a))].append(pix)
    w = lab.shape[1]
    clusters = []
    for root, parts in members.items():
        # unique flat indices: the same raster order as np.unique(axis=0) on (row, col)
        # pairs, which sorts a structured view (24 of 35 ms on a dense 2000x2000 scan)
        p = np.concatenate(parts)
        flat = np.unique(p[:, 0] * w + p[:, 1])
        pix = np.stack([flat // w, flat % w], axis=1)
        clusters.append((int(flat[0]), pix))
    clusters.sort(key=lambda t: t[0])  # raster order of the first pixel
    new_lab = lab.copy()
    rr, cc, ids = [], [], []
    for j, (_first, pix) in enumerate(clusters):
        new_lab[pix[:, 0], pix[:, 1]] = j + 1
        rr.append(pix[:, 0])
        cc.append(pix[:, 1])
        ids.append(np.full(len(pix), j, np.int64))
    if not clusters:
        return _from_pixels(np.zeros(0, np.int64), np.zeros(0, np.int64),
                            np.zeros(0, np.int64), 0, new_lab)
    return _from_pixels(np.concatenate(rr), np.concatenate(cc), np.concatenate(ids),
                        len(clusters), new_lab)


def _walk_points(offs, sids, rev):
    """Points of the stack ends, each walked from its junction outwards: (end of every
    point, its position along the walk, its index in the flat path arrays)."""
    a = offs[sids]
    lens = offs[sids + 1] - a
    end = np.repeat(np.arange(len(sids)), lens)
    pos = np.arange(len(end)) - np.repeat(np.cumsum(lens) - lens, lens)
    ii = a[end] + np.where(rev[end], lens[end] - 1 - pos, pos)
    return end, pos, ii, lens


def _end_lines(pr, pc, offs, sids, rev, c0r, c0c, skip, fit):
    """Centreline line of every stack end: mean point and unit direction (PCA) of the path
    pixels between ``skip`` and ``skip + fit`` from the junction's skeleton centre, walked
    from the junction outwards until the path first leaves that annulus. ``n`` = 0 when
    fewer than three pixels qualify.

    Vectorised over all ends; the per-end sums are ``np.bincount`` sums, which add in the
    walk order as a loop would.
    """
    q = sids.shape[0]
    mean = np.zeros((q, 2))
    direc = np.zeros((q, 2))
    cnt = np.zeros(q, np.int64)
    end, pos, ii, lens = _walk_points(offs, sids, rev)
    if len(end) == 0:
        return mean, direc, cnt
    d = np.hypot(pr[ii] - c0r[end], pc[ii] - c0c[end])
    stop = lens.copy()  # first point beyond the annulus, per end
    out = d > skip[end] + fit[end]
    np.minimum.at(stop, end[out], pos[out])
    sel = (pos < stop[end]) & (d >= skip[end])
    e, ii_s, pos_s = end[sel], ii[sel], pos[sel]
    m = np.bincount(e, minlength=q)
    ok = m >= 3
    mm = np.maximum(m, 1)
    mr = np.bincount(e, weights=pr[ii_s], minlength=q) / mm
    mc = np.bincount(e, weights=pc[ii_s], minlength=q) / mm
    dr = pr[ii_s] - mr[e]
    dc = pc[ii_s] - mc[e]
    vrr = np.bincount(e, weights=dr * dr, minlength=q)
    vcc = np.bincount(e, weights=dc * dc, minlength=q)
    vrc = np.bincount(e, weights=dr * dc, minlength=q)
    first = np.full(q, np.iinfo(np.int64).max)
    last = np.full(q, -1)
    np.minimum.at(first, e, pos_s)
    np.maximum.at(last, e, pos_s)
    ang = 0.5 * np.arctan2(2.0 * vrc[ok], vrr[ok] - vcc[ok])
    tr = np.cos(ang)
    tc = np.sin(ang)
    a = offs[sids[ok]]
    n = lens[ok]
    r_ = rev[ok]
    i0 = a + np.where(r_, n - 1 - first[ok], first[ok])
    i1 = a + np.where(r_, n - 1 - last[ok], last[ok])
    flip = tr * (pr[i1] - pr[i0]) + tc * (pc[i1] - pc[i0]) < 0
    tr[flip] = -tr[flip]
    tc[flip] = -tc[flip]
    mean[ok, 0] = mr[ok]
    mean[ok, 1] = mc[ok]
    direc[ok, 0] = tr
    direc[ok, 1] = tc
    cnt[ok] = m[ok]
    return mean, direc, cnt


def fork_points(centers_rc, radius_px, end_paths, end_junction, *, thickness_px: float,
                skip_factor: float = 0.7, fit_h: float = 2.0, prior_weight: float = 0.05,
                max_shift_factor: float = 1.0, skip_px=None, distance_px=None) -> np.ndarray:
    """Junction positions where the centrelines of the stacks meeting there intersect.

    The skeleton of thick bands forks where the medial axis does, which is not where the
    stacks' centrelines meet: at a T where a thin stack meets a thick one the medial-axis fork
    is displaced towards the thin stack by about an eighth of the thick band's width, and
    digital thinning adds its own bias at the crotch (on generated thick forks, 3 to 8 sheet
    thicknesses away). Each stack's centreline is the skeleton beyond the junction's ink blob;
    its straight extension into the blob is a line, and the junction is the least-squares
    point of those lines (paper, "Image analysis procedure": the junction is where two
    neighbouring stacks are delimited).

    Where two branches leave side by side (a tangential fork, 30-35 degrees between them),
    the lines meet at a small angle and the branches bend apart beyond the blob, so their
    tangents, extended back, meet the trunk too far out (on generated 30 degree forks about
    a quarter of the trunk's width). Given ``distance_px``, the point is then held back to
    where the ink's width first departs from the trunk's (:func:`_limit_to_band_end`).

    Parameters
    ----------
    centers_rc : (K, 2) float array
        Skeleton-based junction centres.
    radius_px : (K,) float array
        Inscribed radius of each junction's ink blob (distance transform at the junction).
    end_paths : list of (P, 2) int arrays
        One path per stack end, ordered from the junction outwards.
    end_junction : (Q,) int array
        Junction id of every entry of ``end_paths``.
    thickness_px : float
        Sheet thickness h in px.
    skip_factor : float
        Path pixels closer than ``skip_factor * radius`` to the centre (inside the blob, where
        the skeleton bends towards the medial-axis fork) are ignored.
    fit_h : float
        Length of path fitted beyond the skipped part, in units of h (short: stacks curve).
    prior_weight : float
        Weight (per line) of the skeleton centre, which keeps nearly parallel lines in place.
    max_shift_factor : float
        A solution farther than ``max_shift_factor * radius + h`` from the skeleton centre
        is rejected (the junction stays on the skeleton).
    skip_px : (Q,) float array, optional
        Per stack end, a distance from the centre within which its path is ignored too
        (where a thin stack crosses a thicker band;
        :func:`crosssection.stages.graph._own_band_span`).
    distance_px : (H, W) array, optional
        Distance of every ink pixel to the background (0 off the ink). When given, a
        junction whose widest band is its trunk is not placed beyond the point where the
        ink's width first departs from that band's (:func:`_limit_to_band_end`).

    Returns
    -------
    (K, 2) float array
        Refined centres; unchanged where fewer than two lines were fitted.
    """
    centers = np.asarray(centers_rc, float).reshape(-1, 2)
    out = centers.copy()
    q = len(end_paths)
    if q == 0:
        return out
    end_junction = np.asarray(end_junction, np.int64)
    lens = np.fromiter((len(p) for p in end_paths), np.int64, count=q)
    offs = np.zeros(q + 1, np.int64)
    np.cumsum(lens, out=offs[1:])
    flat = (np.concatenate([np.asarray(p, float).reshape(-1, 2) for p in end_paths])
            if offs[-1] else np.zeros((0, 2)))
    rad = np.asarray(radius_px, float)[end_junction]
    skip = np.maximum(skip_factor * rad, 2.0)
    if skip_px is not None:
        skip = np.maximum(skip, np.asarray(skip_px, float))
    fit = np.full(q, max(fit_h * thickness_px, 4.0))
    c0 = centers[end_junction]
    mean, direc, cnt = _end_lines(np.ascontiguousarray(flat[:, 0]),
                                  np.ascontiguousarray(flat[:, 1]), offs,
                                  np.arange(q, dtype=np.int64), np.zeros(q, np.bool_),
                                  np.ascontiguousarray(c0[:, 0]), np.ascontiguousarray(c0[:, 1]),
                                  skip, fit)
    ok = cnt > 0
    # normal equations of sum_i |(I - t_i t_i^T)(p - m_i)|^2 + w |p - c0|^2, per junction
    proj = np.eye(2)[None] - direc[:, :, None] * direc[:, None, :]
    k = len(centers)
    a_mat = np.zeros((k, 2, 2))
    b_vec = np.zeros((k, 2))
    n_lines = np.bincount(end_junction[ok], minlength=k)
    np.add.at(a_mat, end_junction[ok], proj[ok])
    np.add.at(b_vec, end_junction[ok], np.einsum("qij,qj->qi", proj[ok], mean[ok]))
    prior = prior_weight * np.maximum(n_lines, 1)
    a_mat += prior[:, None, None] * np.eye(2)[None]
    b_vec += prior[:, None] * centers
    sol = np.linalg.solve(a_mat, b_vec[..., None])[..., 0]
    if distance_px is not None:
        # each end's band half width (the median ignores the blobs at its ends)
        half_width = median_radii_px(end_paths, np.asarray(distance_px))
        sol = _limit_to_band_end(sol, np.asarray(distance_px) > 0, end_junction, mean, direc, ok,
                                 half_width, fit)
    radius = np.asarray(radius_px, float)
    shift = np.hypot(*(sol - centers).T)
    good = (n_lines >= 2) & (shift <= max_shift_factor * radius + thickness_px)
    out[good] = sol[good]
    return out


def median_radii_px(paths, distance_px) -> np.ndarray:
    """Median inscribed ink radius along every skeleton path, px (half each band's width),
    from one gather and one sort (one ``np.median`` per path took 30 ms for the 244 stacks of
    a 2000x2000 scan)."""
    n = np.array([len(p) for p in paths], np.int64)
    out = np.zeros(len(paths))
    if not n.sum():
        return out
    rc = np.round(np.concatenate([np.asarray(p, float).reshape(-1, 2) for p in paths if len(p)]))
    rc = np.clip(rc.astype(np.int64), 0, np.array(distance_px.shape) - 1)
    vals = distance_px[rc[:, 0], rc[:, 1]].astype(np.float64)
    gid = np.repeat(np.arange(len(paths)), n)
    order = np.lexsort((vals, gid))
    v = vals[order]
    start = np.concatenate([[0], np.cumsum(n)[:-1]])
    ok = n > 0
    lo = start[ok] + (n[ok] - 1) // 2
    hi = start[ok] + n[ok] // 2
    out[ok] = 0.5 * (v[lo] + v[hi])
    return out


_RAY_STEP_PX = 0.25  # sample spacing of the rays that measure a band's extents


@njit(cache=True)
def _first_background(ink, pr, pc, nr, nc, t):  # pragma: no cover - numba
    """Per point (``pr``, ``pc``) and side (row 0: ``+normal``, row 1: ``-normal``), the index
    of the first sample ``point + (side t) normal``, rounded to the pixel grid, off ``ink``
    or off the image (``len(t) - 1`` when every sample is ink).

    Compiled, each ray stopping at its first background sample: 1.3 ms against 14-24 ms for
    all samples of all rays in numpy (132 junctions of a dense 2000x2000 scan).
    """
    h, w = ink.shape
    n = pr.shape[0]
    out = np.empty((2, n), np.int64)
    for i in range(n):
        for side in range(2):
            sign = 1.0 if side == 0 else -1.0
            first = t.shape[0] - 1
            for j in range(t.shape[0]):
                st = sign * t[j]
                r = np.rint(pr[i] + st * nr)
                c = np.rint(pc[i] + st * nc)
                if not (0.0 <= r < h and 0.0 <= c < w and ink[int(r), int(c)]):
                    first = j
                    break
            out[side, i] = first
    return out


def _side_extents_px(ink, points_rc, normal_rc, max_px, step_px=_RAY_STEP_PX):
    """Distance from each point to the first background sample along ``+normal`` and along
    ``-normal`` (``max_px`` when none is met): the ink's extent on either side of a line.

    Returns two (N,) float arrays (left = ``+normal``, right = ``-normal``)."""
    t = np.arange(step_px, max_px + step_px, step_px)
    pts = np.asarray(points_rc, np.float64).reshape(-1, 2)
    first_bg = _first_background(ink, np.ascontiguousarray(pts[:, 0]),
                                 np.ascontiguousarray(pts[:, 1]), float(normal_rc[0]),
                                 float(normal_rc[1]), t)
    ext = t[first_bg] - 0.5 * step_px  # the edge lies between two samples
    return ext[0], ext[1]


def _median3(v):
    """Running median of three (ends repeated): removes one-sample jitter of a binary edge.

    The middle value as ``max(min(a, b), min(max(a, b), c))``, which is ``np.median`` of the
    three for finite values (the extents always are) at a tenth of its cost.
    """
    if len(v) < 3:
        return v
    nxt = np.empty_like(v)
    nxt[:-1] = v[1:]
    nxt[-1] = v[-1]
    prv = np.empty_like(v)
    prv[1:] = v[:-1]
    prv[0] = v[0]
    return np.maximum(np.minimum(v, nxt), np.minimum(np.maximum(v, nxt), prv))


def _median_finite(v):
    """``np.median`` of a non-empty 1-D array of finite values (the middle one, or the mean
    of the two middle ones, bit for bit), without its overhead (80 us a call)."""
    s = np.sort(v)
    m = len(s) // 2
    return s[m] if len(s) % 2 else (s[m - 1] + s[m]) / 2


def _limit_to_band_end(sol, ink, end_junction, mean, direc, ok, half_width_px, fit_px,
                       tol_px=None):
    """Junction points held back to where the ink stops being the trunk's band.

    The trunk of a fork (its widest band, which splits into the narrower branches) keeps its
    width up to the junction: its edges run parallel until a branch peels off (the ink grows
    on one side) or the band ends (it shrinks on one side). The junction cannot lie beyond
    the first point where the width departs from the trunk's, so a point found beyond it
    (branches bending apart make their tangents meet the trunk too far out) is moved back
    along the trunk's centreline to it; its position across the trunk is kept. Walking from
    the trunk's fitted stretch towards the junction, the ink's width across the trunk's line
    (extent on one side plus extent on the other: a line a little off the centreline or
    turned by a degree or two moves one edge out and the other in, and leaves the width) is
    compared with its median on that stretch; a departure is a change by more than ``tol_px``.
    The measured width of a straight binary band wanders by up to 1 px + 2 ray steps (each
    edge is quantised to the pixel grid, +-0.5 px, and found to within one ray step), hence
    the default 1.5 px; a running median of three samples removes one-sample jitter.

    The bound holds only where no other band reaches across the trunk's edge before the
    junction. A band of half width ``w_c`` leaving at an angle ``phi`` to the trunk's
    continuation reaches at most ``w_c / cos(phi)`` from the trunk's centreline behind the
    junction, so every other band must satisfy ``w_c <= w_trunk cos(phi)`` (tangential forks
    of a wider trunk; not T junctions, nor the wide-angle departures at the hole's wall);
    otherwise the point is kept.

    Parameters
    ----------
    sol : (K, 2) float array
        Junction points (row, col) from the centreline intersection.
    ink : (H, W) bool array
        Cleaned ink mask.
    end_junction : (Q,) int array
        Junction of every stack end.
    mean, direc : (Q, 2) float arrays
        Centre and unit direction (pointing away from the junction) of each end's fitted line.
    ok : (Q,) bool array
        Ends with a fitted line.
    half_width_px : (Q,) float array
        Half width of each end's band.
    fit_px : (Q,) float array
        Length of each end's fitted stretch (centred on ``mean``).
    tol_px : float, optional
        Change of the width that counts as a departure (default 1 px + 2 ray steps).

    Returns
    -------
    (K, 2) float array
    """
    if tol_px is None:
        tol_px = 1.0 + 2 * _RAY_STEP_PX
    out = sol.copy()
    order = np.argsort(end_junction, kind="stable")
    bounds = np.searchsorted(end_junction[order], np.arange(len(sol) + 1))
    for j in range(len(sol)):
        ends = order[bounds[j]:bounds[j + 1]]
        if len(ends) < 3 or not ok[ends].all():
            continue
        trunk = ends[int(np.argmax(half_width_px[ends]))]
        others = ends[ends != trunk]
        d = direc[trunk]
        cos_phi = -(direc[others] @ d)  # angle to the trunk's continuation through j
        if np.any(half_width_px[others] > half_width_px[trunk] * cos_phi):
            continue
        half_fit = 0.5 * fit_px[trunk]
        x_sol = float((sol[j] - mean[trunk]) @ d)  # < 0: the junction is behind the stretch
        x_walk = np.arange(-half_fit, x_sol, -1.0)
        if len(x_walk) == 0:
            continue
        normal = np.array([-d[1], d[0]])
        max_px = 2.0 * half_width_px[trunk] + 2.0 * tol_px + 2.0
        x_ref = np.arange(-half_fit, half_fit + 0.5, 1.0)
        # the fitted stretch and the walk in one call (the call's overhead dominates)
        x_all = np.concatenate([x_ref, x_walk])
        left, right = _side_extents_px(ink, mean[trunk] + x_all[:, None] * d, normal, max_px)
        both = left + right
        width = _median3(both[len(x_ref):])
        departs = np.abs(width - _median_finite(both[:len(x_ref)])) > tol_px
        if departs.any():
            x_end = x_walk[int(np.argmax(departs))]
            out[j] = sol[j] + (x_end - x_sol) * d
    return out
