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


@njit(cache=True)
def _find(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def _junction_labels(img, rows, cols, merge_px):
    """Label junction clusters of the padded uint8 skeleton ``img``.

    ``rows``, ``cols``: the skeleton pixels (padded coordinates, raster order). Returns the
    unpadded int32 label image (0 none, j+1 junction j), the number of clusters, and the
    junction pixels (unpadded row, col) with their cluster ids.
    """
    h, w = img.shape
    # junction pixels: >= 3 neighbours
    jr = []
    jc = []
    for i in range(rows.shape[0]):
        r = rows[i]
        c = cols[i]
        nb = (img[r - 1, c - 1] + img[r - 1, c] + img[r - 1, c + 1] + img[r, c - 1]
              + img[r, c + 1] + img[r + 1, c - 1] + img[r + 1, c] + img[r + 1, c + 1])
        if nb >= 3:
            jr.append(r)
            jc.append(c)
    n = len(jr)
    lab = np.zeros((h, w), np.int32)
    if n == 0:
        e = np.zeros(0, np.int64)
        return lab[1:-1, 1:-1], 0, e, e.copy(), e.copy()
    idx = np.zeros((h, w), np.int32)  # 1 + junction pixel index
    for i in range(n):
        idx[jr[i], jc[i]] = i + 1
    parent = np.arange(n)
    rad = max(1, int(np.ceil(merge_px)))
    m2 = max(merge_px * merge_px, 2.0)  # touching pixels always merge
    for i in range(n):
        r = jr[i]
        c = jc[i]
        for dr in range(-rad, rad + 1):
            rr = r + dr
            if rr < 0 or rr >= h:
                continue
            for dc in range(-rad, rad + 1):
                cc = c + dc
                if cc < 0 or cc >= w or (dr == 0 and dc == 0):
                    continue
                k = idx[rr, cc]
                if k > 0 and dr * dr + dc * dc <= m2:
                    a = _find(parent, i)
                    b = _find(parent, k - 1)
                    if a != b:
                        parent[a] = b
    # cluster ids in order of first pixel (raster order)
    cid = -np.ones(n, np.int64)
    k = 0
    for i in range(n):
        root = _find(parent, i)
        if cid[root] < 0:
            cid[root] = k
            k += 1
        lab[jr[i], jc[i]] = cid[root] + 1
    # skeleton pixels between two pixels of the same cluster join it
    changed = True
    while changed:
        changed = False
        for i in range(n):
            r = jr[i]
            c = jc[i]
            j = lab[r, c]
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    rr = r + dr
                    cc = c + dc
                    if img[rr, cc] and lab[rr, cc] == 0:
                        # all skeleton neighbours of (rr, cc) in cluster j (at least 2)?
                        n_in = 0
                        n_out = 0
                        for er in range(-1, 2):
                            for ec in range(-1, 2):
                                if er == 0 and ec == 0:
                                    continue
                                if img[rr + er, cc + ec]:
                                    if lab[rr + er, cc + ec] == j:
                                        n_in += 1
                                    else:
                                        n_out += 1
                        if n_in >= 2 and n_out == 0:
                            lab[rr, cc] = j
                            jr.append(rr)
                            jc.append(cc)
                            n += 1
                            changed = True
    out_r = np.empty(n, np.int64)
    out_c = np.empty(n, np.int64)
    out_id = np.empty(n, np.int64)
    for i in range(n):
        out_r[i] = jr[i] - 1
        out_c[i] = jc[i] - 1
        out_id[i] = lab[jr[i], jc[i]] - 1
    return lab[1:-1, 1:-1], k, out_r, out_c, out_id


def _from_pixels(rr, cc, ids, k, lab) -> Junctions:
    order = np.argsort(ids, kind="stable")
    rr, cc, ids = rr[order], cc[order], ids[order]
    bounds = np.searchsorted(ids, np.arange(k + 1))
    pixels = [np.stack([rr[bounds[j]:bounds[j + 1]], cc[bounds[j]:bounds[j + 1]]], axis=1)
              for j in range(k)]
    centers = (np.array([p.mean(axis=0) for p in pixels], dtype=float) if k
               else np.zeros((0, 2), float))
    return Junctions(centers_rc=centers, pixels=pixels, label_image=lab)


def _from_labels(lab, k) -> Junctions:
    rr, cc = np.nonzero(lab)
    return _from_pixels(rr, cc, lab[rr, cc].astype(np.int64) - 1, k, lab)


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
        pix = np.unique(np.concatenate(parts), axis=0)
        clusters.append((int((pix[:, 0] * w + pix[:, 1]).min()), pix))
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
