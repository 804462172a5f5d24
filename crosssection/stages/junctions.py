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

import math
from dataclasses import dataclass

import numpy as np

from crosssection.core.errors import ParameterError
from crosssection.core.polyline import grouped_axes, walk_ends
from crosssection.core.unionfind import group_labels
from crosssection.params import _number
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

#: Farthest a junction of nearly parallel stacks (a tangential fork) moves from the
#: skeleton's fork toward their centreline intersection, in sheet thicknesses h: it is
#: placed where the bands separate, within 3 h of the medial-axis fork. The tangents of
#: branches that bend apart beyond a thick trunk's blob meet inside the trunk, where no
#: image shows them apart (docs/validation/README.md, "Junctions where the bands separate").
FORK_REACH_H = 3.0
#: Lines count as nearly parallel when the mean squared sine of their angles to the common
#: direction (the smallest eigenvalue of the sum of their normal projectors, per line) is
#: below this: within about 18 degrees. A T (a sheet leaving a trunk at a right angle) has
#: 1/3: its lines meet where the centrelines do, and the skeleton's fork lies off that point.
PARALLEL_SPREAD = 0.1


def _junction_labels(img, flat, n_nb, merge_px):
    """Label junction clusters of the padded uint8 skeleton ``img``.

    ``flat``: the skeleton pixels (flat padded indices, raster order); ``n_nb``: their numbers
    of skeleton neighbours. Returns the unpadded int32 label image (0 none, j+1 junction j),
    the number of clusters, and the junction pixels (unpadded row, col) with their cluster ids.

    Vectorised: the pixel pairs closer than ``merge_px`` are joined by connected components,
    and the growth of the clusters (see :func:`_grow`) runs pass by pass. The neighbours of a
    junction pixel are looked up among the junction pixels by binary search: an image of
    their indices (32 MB of int64 to clear on a 2000x2000 scan) took 1.1 ms of the 3 ms.
    """
    h, w = img.shape
    f = img.reshape(-1)
    jp = flat[n_nb >= 3]  # junction pixels: >= 3 neighbours, raster order
    n = len(jp)
    lab = np.zeros((h, w), np.int32)
    if n == 0:
        e = np.zeros(0, np.int64)
        return lab[1:-1, 1:-1], 0, e, e.copy(), e.copy()
    jr, jc = jp // w, jp % w
    rad = max(1, int(np.ceil(merge_px)))
    m2 = max(merge_px * merge_px, 2.0)  # touching pixels always merge
    pairs = [np.zeros((0, 2), np.int64)]
    if (2 * rad + 1) ** 2 > 81:
        # a wide merge: pairs from a k-d tree, not one pass over the junction pixels per
        # offset of the disc ((2 merge_px + 1)^2 passes: minutes at merge_px = 1000)
        from scipy.spatial import cKDTree

        ij = cKDTree(np.stack([jr, jc], axis=1)).query_pairs(math.sqrt(m2) + 1e-6,
                                                             output_type="ndarray")
        d2 = (jr[ij[:, 0]] - jr[ij[:, 1]]) ** 2 + (jc[ij[:, 0]] - jc[ij[:, 1]]) ** 2
        pairs.append(ij[d2 <= m2].astype(np.int64))
    else:
        for dr in range(-rad, rad + 1):
            for dc in range(-rad, rad + 1):
                if (dr == 0 and dc == 0) or dr * dr + dc * dc > m2:
                    continue
                rr, cc = jr + dr, jc + dc
                i = np.flatnonzero((rr >= 0) & (rr < h) & (cc >= 0) & (cc < w))
                q = rr[i] * w + cc[i]
                k = np.searchsorted(jp, q)
                hit = jp[np.minimum(k, n - 1)] == q
                pairs.append(np.stack([i[hit], k[hit]], axis=1))
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
    """Junctions from their pixels (any order; kept within each junction) and label image.

    The pixel lists are views of one array, and the centres ``np.bincount`` sums over the
    counts: integer coordinates add exactly, so these are the per-junction ``mean`` to the
    bit (one stack and one mean per junction took 0.8 ms for the 160 junctions of a dense
    2000x2000 scan).
    """
    order = np.argsort(ids, kind="stable")
    ids = ids[order]
    rc = np.stack([rr[order], cc[order]], axis=1)
    bounds = np.searchsorted(ids, np.arange(k + 1)).tolist()
    pixels = [rc[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
    if not k:
        return Junctions(centers_rc=np.zeros((0, 2), float), pixels=pixels, label_image=lab)
    n = np.diff(bounds)
    centers = np.stack([np.bincount(ids, weights=rc[:, 0], minlength=k) / n,
                        np.bincount(ids, weights=rc[:, 1], minlength=k) / n], axis=1)
    return Junctions(centers_rc=centers, pixels=pixels, label_image=lab)


def _check_merge_px(merge_px):
    """Raise ``ParameterError`` unless ``merge_px`` is a finite number >= 0."""
    _number("merge_px", merge_px, allow_equal=True)


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
    _check_merge_px(merge_px)
    h, w = skel.shape
    img = np.zeros((h + 2, w + 2), np.uint8)
    img[1:-1, 1:-1] = skel
    rows, cols = nonzero_rc(img)
    f = img.reshape(-1)
    flat = rows * (w + 2) + cols
    n_nb = np.zeros(len(flat), np.int64)
    for dr, dc in zip(_NB_DR, _NB_DC):
        n_nb += f[flat + dr * (w + 2) + dc]
    return padded_junctions(img, flat, n_nb, merge_px=merge_px)


def padded_junctions(img, flat, n_neighbours, *, merge_px: float = 2.0) -> Junctions:
    """:func:`find_junctions` of a skeleton whose padded image and pixels are already known.

    Parameters
    ----------
    img : (H + 2, W + 2) uint8 array
        The skeleton (0 or 1) with a border of one background pixel; not modified.
    flat : (P,) int64 array
        Flat indices in ``img`` of the skeleton pixels, in raster order.
    n_neighbours : (P,) int array
        Number of skeleton 8-neighbours of every pixel of ``flat``.
    merge_px : float, optional
        As :func:`find_junctions`.

    Returns
    -------
    Junctions
        As :func:`find_junctions` on ``img[1:-1, 1:-1]``.
    """
    _check_merge_px(merge_px)
    lab, k, rr, cc, ids = _junction_labels(np.asarray(img, np.uint8), flat, n_neighbours,
                                           float(merge_px))
    return _from_pixels(rr, cc, ids, k, lab)


def merge_junctions(junctions: Junctions, groups, extra_pixels=(), *,
                    reuse_label_image: bool = False) -> Junctions:
    """Merge junctions into one, adding skeleton pixels (the short stacks joining them).

    Parameters
    ----------
    junctions : Junctions
    groups : iterable of (a, b)
        Pairs of junction ids to merge (transitively).
    extra_pixels : iterable of (P, 2) int arrays
        Pixels that join the merged junctions (e.g. the path of the stack between them).
        Each array is attached to the junction its first touching cluster belongs to.
    reuse_label_image : bool
        Write the merged labels into ``junctions.label_image`` itself (which ``junctions``
        then no longer describes) instead of a new image: for a caller that drops
        ``junctions``. Every pixel it labels is a pixel of a merged junction, so the image
        is the same (in the analysis of the dense 2000x2000 benchmark scan a new one cost
        2.6 ms, its pages faulted in for a few thousand pixels written, against 0.1 ms).

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
    w = lab.shape[1]
    root = np.array([find(j) for j in range(k)], np.int64)
    parts = [np.asarray(pix, np.int64).reshape(-1, 2) for pix in junctions.pixels]
    owner = [np.repeat(root, [len(p) for p in parts])]
    for (a, _b), pix in zip(groups, extra_pixels):
        pix = np.asarray(pix, dtype=np.int64).reshape(-1, 2)
        if len(pix):
            pix = pix[lab[pix[:, 0], pix[:, 1]] == 0]  # not yet a junction pixel
            parts.append(pix)
            owner.append(np.full(len(pix), find(int(a)), np.int64))
    p = np.concatenate(parts) if parts else np.zeros((0, 2), np.int64)
    flat = p[:, 0] * w + p[:, 1]
    own = np.concatenate(owner)
    # every merged junction's pixels: unique flat indices in raster order, all junctions by
    # one sort (one np.unique per merged junction took 1.6 ms on a dense 2000x2000 scan)
    order = np.lexsort((flat, own))
    flat, own = flat[order], own[order]
    keep = np.ones(len(flat), bool)
    keep[1:] = (flat[1:] != flat[:-1]) | (own[1:] != own[:-1])
    flat, own = flat[keep], own[keep]
    start = np.flatnonzero(np.r_[True, own[1:] != own[:-1]]) if len(own) else own
    # renumbered in raster order of the first pixel, ties in order of the first junction
    first_j = np.full(k, k, np.int64)
    np.minimum.at(first_j, root, np.arange(k))
    runs = np.lexsort((first_j[own[start]], flat[start]))
    new_id = np.empty(len(start), np.int64)
    new_id[runs] = np.arange(len(start))
    ids = np.repeat(new_id, np.diff(np.r_[start, len(flat)]))
    rr, cc = flat // w, flat % w
    # the label image marks exactly the junctions' pixels: rebuilt from them on np.zeros,
    # whose pages the system supplies zeroed on first use, where a copy (or np.zeros_like,
    # which fills) writes all 16 MB of a 2000x2000 scan (3 ms); a pixel in two merged
    # junctions gets the last one
    new_lab = lab if reuse_label_image else np.zeros(lab.shape, lab.dtype)
    o = np.lexsort((ids, flat))
    last = o[np.r_[flat[o[1:]] != flat[o[:-1]], True]] if len(o) else o
    new_lab[rr[last], cc[last]] = ids[last] + 1
    return _from_pixels(rr, cc, ids, len(start), new_lab)


def _end_lines(pr, pc, offs, sids, rev, c0r, c0c, skip, fit):
    """Centreline line of every stack end: mean point and unit direction (PCA) of the path
    pixels between ``skip`` and ``skip + fit`` from the junction's skeleton centre, walked
    from the junction outwards until the path first leaves that annulus. ``n`` = 0 when
    fewer than three pixels qualify. Also returns, per end, the position of the first point
    beyond the annulus (the path's length when none is).

    Vectorised over all ends; the per-end sums are ``np.bincount`` sums, which add in the
    walk order as a loop would.
    """
    q = sids.shape[0]
    mean = np.zeros((q, 2))
    direc = np.zeros((q, 2))
    cnt = np.zeros(q, np.int64)
    end, pos, ii, lens = walk_ends(offs, sids, rev)
    if len(end) == 0:
        return mean, direc, cnt, lens
    d = np.hypot(pr[ii] - c0r[end], pc[ii] - c0c[end])
    stop = lens.copy()  # first point beyond the annulus, per end
    out = d > skip[end] + fit[end]
    np.minimum.at(stop, end[out], pos[out])
    sel = (pos < stop[end]) & (d >= skip[end])
    m, mr, mc, ang, first, last = grouped_axes(end[sel], pr[ii[sel]], pc[ii[sel]], pos[sel], q)
    ok = m >= 3
    tr = np.cos(ang[ok])
    tc = np.sin(ang[ok])
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
    return mean, direc, cnt, stop


def _prefix_lines(paths, cap, c0, skip, fit):
    """:func:`_end_lines` of the first ``cap[i]`` points of every path ``paths[i]`` (from
    the junction outwards), ``c0`` their junctions' centres."""
    q = len(paths)
    offs = np.zeros(q + 1, np.int64)
    np.cumsum(cap, out=offs[1:])
    flat = (np.concatenate([p[:c] for p, c in zip(paths, cap.tolist())]).astype(float)
            if offs[-1] else np.zeros((0, 2)))
    return _end_lines(np.ascontiguousarray(flat[:, 0]), np.ascontiguousarray(flat[:, 1]), offs,
                      np.arange(q, dtype=np.int64), np.zeros(q, np.bool_),
                      np.ascontiguousarray(c0[:, 0]), np.ascontiguousarray(c0[:, 1]), skip, fit)


def fork_points(centers_rc, radius_px, end_paths, end_junction, *, thickness_px: float,
                skip_factor: float = 0.7, fit_h: float = 2.0, prior_weight: float = 0.05,
                max_shift_factor: float = 1.0, reach_h: float = FORK_REACH_H,
                skip_px=None) -> np.ndarray:
    """Junction positions where the centrelines of the stacks meeting there intersect.

    The skeleton of thick bands forks where the medial axis does, which is not where the
    stacks' centrelines meet: at a T where a thin stack meets a thick one the medial-axis fork
    is displaced towards the thin stack by about an eighth of the thick band's width, and
    digital thinning adds its own bias at the crotch (on generated thick forks, 3 to 8 sheet
    thicknesses away). Each stack's centreline is the skeleton beyond the junction's ink blob;
    its straight extension into the blob is a line, and the junction is the least-squares
    point of those lines (paper, "Image analysis procedure": the junction is where two
    neighbouring stacks are delimited).

    Where two branches leave side by side (a tangential fork) and bend apart beyond the blob,
    their tangents, extended back, meet where the bands separate, near the medial-axis fork
    (the paper's junction is a skeleton pixel with three neighbours, "Image analysis
    procedure"), not at a node inside the merged band where no image shows the branches
    apart. It is not held back to where the ink's width first departs from the trunk's: that
    moves it towards such nodes and away from the medial-axis forks of thick trunks
    (docs/validation/README.md, "Junctions where the bands separate").

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
    reach_h : float
        Where the lines are nearly parallel (:data:`PARALLEL_SPREAD`), an accepted solution
        is moved from the skeleton centre toward the intersection by at most ``reach_h`` h
        (:data:`FORK_REACH_H`).
    skip_px : (Q,) float array, optional
        Per stack end, a distance from the centre within which its path is ignored too
        (where a thin stack crosses a thicker band;
        :func:`crosssection.stages.graph._own_band_span`).

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
    paths = [np.asarray(p).reshape(-1, 2) for p in end_paths]
    lens = np.fromiter((len(p) for p in paths), np.int64, count=q)
    rad = np.asarray(radius_px, float)[end_junction]
    skip = np.maximum(skip_factor * rad, 2.0)
    if skip_px is not None:
        skip = np.maximum(skip, np.asarray(skip_px, float))
    fit = np.full(q, max(fit_h * thickness_px, 4.0))
    c0 = centers[end_junction]
    # a line is fitted on its path up to where the path first leaves the annulus: within as
    # many pixels as the annulus' outer radius, and 8 more, unless the path winds there. The
    # paths are read that far, then those that stay inside are read whole (the same lines:
    # on the dense 2000x2000 benchmark scan, whose 488 end paths run 114 px on average and
    # leave after 13, 1.2 ms against 2.5 for the whole paths)
    reach = skip + fit
    cap = lens.copy()
    short = np.isfinite(reach) & (reach + 8 < lens)
    cap[short] = np.ceil(reach[short]).astype(np.int64) + 8
    mean, direc, cnt, stop = _prefix_lines(paths, cap, c0, skip, fit)
    redo = np.flatnonzero((stop >= cap) & (cap < lens))
    if len(redo):
        out_r = _prefix_lines([paths[i] for i in redo], lens[redo], c0[redo], skip[redo],
                              fit[redo])
        mean[redo], direc[redo], cnt[redo] = out_r[:3]
    ok = cnt > 0
    # normal equations of sum_i |(I - t_i t_i^T)(p - m_i)|^2 + w |p - c0|^2, per junction
    proj = np.eye(2)[None] - direc[:, :, None] * direc[:, None, :]
    k = len(centers)
    a_mat = np.zeros((k, 2, 2))
    b_vec = np.zeros((k, 2))
    n_lines = np.bincount(end_junction[ok], minlength=k)
    np.add.at(a_mat, end_junction[ok], proj[ok])
    np.add.at(b_vec, end_junction[ok], np.einsum("qij,qj->qi", proj[ok], mean[ok]))
    # lines nearly parallel (a tangential fork): their meeting point along them is where
    # the bands' tangents, not the bands, converge
    spread = np.linalg.eigvalsh(a_mat)[:, 0] / np.maximum(n_lines, 1)
    prior = prior_weight * np.maximum(n_lines, 1)
    a_mat += prior[:, None, None] * np.eye(2)[None]
    b_vec += prior[:, None] * centers
    sol = np.linalg.solve(a_mat, b_vec[..., None])[..., 0]
    radius = np.asarray(radius_px, float)
    shift = np.hypot(*(sol - centers).T)
    good = (n_lines >= 2) & (shift <= max_shift_factor * radius + thickness_px)
    reach = np.where(spread < PARALLEL_SPREAD,
                     np.minimum(1.0, reach_h * thickness_px / np.maximum(shift, 1e-12)), 1.0)
    out[good] = centers[good] + (sol - centers)[good] * reach[good, None]
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
