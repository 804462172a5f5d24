"""Stage 4's redundant-pixel removal and spur pruning against the sequential loops they
replace.

The references below are the compiled loops the stage used before, kept as plain Python: one
pixel after the other, each decided on the image as the loop has left it. The vectorised
code must give the same image bit for bit and the same number of pruned pixels, on generated
skeletons and on raw binary images (where far more decisions depend on the order).
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy import ndimage as ndi

from crosssection.core.errors import ParameterError
from crosssection.stages import skeleton as sk


# ----------------------------------------------------------------------------- references
def _ref_remove_redundant(f, offs, idx, m, simple, count):
    """Delete simple non-end pixels of ``f`` (flat indices ``idx[:m]``, in order) sequentially
    until none is left; compact the survivors to the front of ``idx`` and return their
    number."""
    changed = True
    while changed:
        changed = False
        for i in range(m):
            p = idx[i]
            if f[p]:
                code = 0
                for k in range(8):
                    code |= f[p + offs[k]] << k
                if count[code] >= 2 and simple[code]:
                    f[p] = 0
                    changed = True
    k = 0
    for i in range(m):
        if f[idx[i]]:
            idx[k] = idx[i]
            k += 1
    return k


def _ref_spurs(f, offs, idx, m, l_min, count, buf, ends, lens, cut):
    """Free ends whose walk reaches a junction pixel before ``l_min`` (``cut`` False: store
    them in ``ends``, ``lens`` and return their number; ``cut`` True: delete those of
    ``idx[:m]`` still spurs, in order, and return the number of pixels deleted)."""
    nk = 0
    removed = 0
    for i in range(m):
        p0 = idx[i]
        if not f[p0]:
            continue
        code = 0
        for k in range(8):
            code |= f[p0 + offs[k]] << k
        if count[code] != 1:
            continue
        prev = -1
        p = p0
        length = 0.0
        n = 0
        junction = False
        while True:
            code = 0
            for k in range(8):
                code |= f[p + offs[k]] << k
            nb = count[code]
            if n > 0 and nb >= 3:
                junction = True
                break
            if n > 0 and nb <= 1:
                break  # another free end: a junction-free segment
            buf[n] = p
            n += 1
            nxt = -1
            step = 1.0
            for k in range(8):  # even k axial, odd k diagonal
                q = p + offs[k]
                if f[q] and q != prev:
                    nxt = q
                    step = 1.0 if k % 2 == 0 else 1.4142135623730951
                    break
            if nxt < 0:
                break
            length += step
            if length >= l_min or n >= buf.shape[0]:
                break
            prev = p
            p = nxt
        if junction and length < l_min:
            if cut:
                for j in range(n):
                    f[buf[j]] = 0
                removed += n
            else:
                ends[nk] = p0
                lens[nk] = length
                nk += 1
    return removed if cut else nk


def _ref_prune(f, offs, idx, m, l_min):
    """Delete spurs shorter than ``l_min``, shortest first, until none is left; returns the
    number of pixels left (compacted in ``idx``) and of pixels deleted."""
    buf = np.empty(int(l_min) * 2 + 8, np.int64)
    ends = np.empty(max(m, 1), np.int64)
    lens = np.empty(max(m, 1), np.float64)
    n_removed = 0
    while True:
        k = _ref_spurs(f, offs, idx, m, l_min, sk._COUNT, buf, ends, lens, False)
        if k == 0:
            break
        order = ends[:k][sk._quicksort_order(lens[:k])]
        removed = _ref_spurs(f, offs, order, k, l_min, sk._COUNT, buf, ends, lens, True)
        if removed == 0:
            break
        n_removed += removed
        m = _ref_remove_redundant(f, offs, idx, m, sk._SIMPLE, sk._COUNT)
    return m, n_removed


# ----------------------------------------------------------------------------- inputs
def _padded(img):
    """Flat padded 0/1 uint8 copy of a 2-D image, and its row length."""
    h, w = img.shape
    out = np.zeros((h + 2, w + 2), np.uint8)
    out[1:-1, 1:-1] = img != 0
    return out.reshape(-1), w + 2


def _thinned(mask):
    """The stage's thinning (before redundant pixels are removed) of a mask, flat padded."""
    f, w = _padded(mask)
    img = f.reshape(-1, w)
    start = sk._border_pixels(img)
    cap = max(int(np.count_nonzero(f)), 1)
    lst = np.empty(cap, np.int64)
    lst[:len(start)] = start
    sk._zhang_suen(f, sk._offsets(w), lst, len(start), np.zeros(f.shape[0], np.uint8),
                   np.empty(cap, np.int64), sk._ZS1, sk._ZS2, sk._SIMPLE, sk._COUNT,
                   sk._thin_lines(img).reshape(-1), sk._CORNER1, sk._CORNER2)
    return f, w


def _lines(rng, shape, n, width):
    img = np.zeros(shape, np.uint8)
    for _ in range(n):
        (c0, c1), (r0, r1) = rng.integers(-5, shape[1] + 5, 2), rng.integers(-5, shape[0] + 5, 2)
        cv2.line(img, (int(c0), int(r0)), (int(c1), int(r1)), 1, int(width))
    return img


def _edge_cases():
    """Small images with the configurations where the order of deletion matters."""
    out = {}
    sq = np.zeros((12, 14), np.uint8)
    sq[2:4, 2:4] = 1  # 2x2 square
    sq[6:8, 9:11] = 1
    sq[0:2, 12:14] = 1  # at the image corner
    out["squares"] = sq
    diag = np.zeros((30, 30), np.uint8)
    for i in range(24):  # two-pixel-thick diagonals, both ways
        diag[i + 3, i + 1:i + 3] = 1
        diag[i + 1, 28 - i:30 - i] = 1
    out["thick_diagonals"] = diag
    stair = np.zeros((20, 40), np.uint8)
    for i in range(18):
        stair[i + 1, 2 * i:2 * i + 3] = 1  # staircase with corners
    out["staircase"] = stair
    ring = np.zeros((40, 40), np.uint8)
    cv2.circle(ring, (20, 20), 12, 1, 1)
    cv2.circle(ring, (20, 20), 5, 1, 2)
    out["loops"] = ring
    tree = np.zeros((60, 60), np.uint8)
    cv2.line(tree, (5, 30), (55, 30), 1, 1)
    cv2.line(tree, (30, 30), (30, 10), 1, 1)  # a branch
    cv2.line(tree, (30, 18), (38, 12), 1, 1)  # a spur on the branch
    cv2.line(tree, (30, 14), (24, 9), 1, 1)
    cv2.line(tree, (45, 30), (45, 36), 1, 1)  # short spurs on the main line
    cv2.line(tree, (12, 30), (8, 34), 1, 1)
    cv2.line(tree, (20, 30), (20, 26), 1, 1)
    cv2.line(tree, (20, 30), (20, 34), 1, 1)  # equal spurs on both sides: a tie
    out["spurs_on_spurs"] = tree
    dots = np.zeros((15, 15), np.uint8)
    dots[::3, ::4] = 1  # isolated pixels
    dots[7, 3:10] = 1
    out["isolated"] = dots
    border = np.zeros((25, 25), np.uint8)
    border[0, :] = 1
    border[:, -1] = 1
    border[:, 0] = 1
    border[-2:, 5:20] = 1
    border[10, 0:12] = 1
    out["borders"] = border
    out["full"] = np.ones((9, 7), np.uint8)
    out["row"] = np.ones((1, 17), np.uint8)
    out["column"] = np.ones((13, 1), np.uint8)
    out["empty"] = np.zeros((6, 8), np.uint8)
    out["single"] = np.ones((1, 1), np.uint8)
    return out


def _masks(seed, n):
    """Generated masks: bands of several widths, noise blobs, the edge cases."""
    rng = np.random.default_rng(seed)
    out = list(_edge_cases().values())
    for i in range(n):
        h, w = (int(v) for v in rng.integers(8, 90, 2))
        kind = i % 4
        if kind == 0:
            m = _lines(rng, (h, w), int(rng.integers(1, 8)), int(rng.integers(1, 9)))
        elif kind == 1:
            m = (rng.random((h, w)) < rng.uniform(0.3, 0.7)).astype(np.uint8)
            m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
        elif kind == 2:
            m = (rng.random((h, w)) < rng.uniform(0.2, 0.8)).astype(np.uint8)
        else:
            m = _lines(rng, (h, w), int(rng.integers(2, 6)), 1)
            m |= _lines(rng, (h, w), 2, int(rng.integers(3, 12)))
        out.append(m)
    return out


def _vec_redundant(f, w):
    hc = f.copy()
    idx = np.flatnonzero(hc).astype(np.intp)
    sk._to_row_codes(hc, idx)
    left = sk._remove_redundant(hc, w, idx)
    sk._from_row_codes(hc, left)
    return hc, left


def _seq_redundant(f, w):
    f = f.copy()
    idx = np.flatnonzero(f).astype(np.int64)
    m = _ref_remove_redundant(f, sk._offsets(w), idx, len(idx), sk._SIMPLE, sk._COUNT)
    return f, idx[:m]


def _vec_prune(f, w, l_min):
    hc = f.copy()
    idx = np.flatnonzero(hc).astype(np.intp)
    sk._to_row_codes(hc, idx)
    left, n = sk._prune(hc, w, idx, l_min)
    sk._from_row_codes(hc, left)
    return hc, left, n


def _seq_prune(f, w, l_min):
    f = f.copy()
    idx = np.flatnonzero(f).astype(np.int64)
    m, n = _ref_prune(f, sk._offsets(w), idx, len(idx), l_min)
    return f, idx[:m], n


# ----------------------------------------------------------------------------- tables
def test_row_codes_give_the_8_neighbour_codes():
    rng = np.random.default_rng(0)
    for _ in range(20):
        h, w0 = (int(v) for v in rng.integers(1, 30, 2))
        f, w = _padded(rng.random((h, w0)) < 0.5)
        idx = np.flatnonzero(f).astype(np.intp)
        offs = sk._offsets(w)
        rr, cc = np.mgrid[1:h + 1, 1:w0 + 1]
        p = (rr * w + cc).ravel()  # every pixel of the image
        ref = sum(f[p + offs[k]].astype(np.int64) << k for k in range(8))
        hc = f.copy()
        sk._to_row_codes(hc, idx)
        c9 = sk._code9(hc, p, w)
        assert np.array_equal(sk._TO8[c9], ref)
        assert np.array_equal((c9 & sk._CENTRE) != 0, f[p] != 0)
        sk._from_row_codes(hc, idx)
        assert np.array_equal(hc, f)


def test_subset_tables_against_enumeration():
    dele = sk._SIMPLE & (sk._COUNT >= 2)
    rng = np.random.default_rng(1)
    for code in range(256):
        for m in [0, 255, *rng.integers(0, 256, 6).tolist()]:
            sub = m & code
            vals = [dele[code & ~s] for s in range(256) if s & ~sub == 0]
            assert sk._ALLDEL[code * 256 + m] == all(vals)
            assert sk._ANYDEL[code * 256 + m] == any(vals)
    # the order table: earlier neighbours deleted, kept (or not changing) or undecided
    prev = [1 << k for k in sk._PREV]
    for s in range(256):
        digits = [(s >> (2 * i)) & 3 for i in range(4)]
        gone = sum(b for b, d in zip(prev, digits) if d == sk._GONE)
        pending = sum(b for b, d in zip(prev, digits) if d == sk._OPEN)
        for code in rng.integers(0, 256, 12).tolist():
            vals = [dele[code & ~gone & ~sub] for sub in range(256) if sub & ~pending == 0]
            want = sk._GONE if all(vals) else (sk._KEPT if not any(vals) else sk._OPEN)
            assert sk._ORDER_LUT[code * 256 + s] == want


# ----------------------------------------------------------------------------- redundant
@pytest.mark.parametrize("raw", [False, True], ids=["thinned", "raw"])
def test_remove_redundant_matches_sequential_loop(raw):
    n_diff = 0
    for mask in _masks(seed=2 + raw, n=60):
        f, w = _padded(mask) if raw else _thinned(mask)
        new, left = _vec_redundant(f, w)
        old, left_ref = _seq_redundant(f, w)
        assert np.array_equal(new, old)
        assert np.array_equal(left, left_ref)
        n_diff += int((new != f).sum())
    assert n_diff > 100  # the inputs did have redundant pixels


@pytest.mark.parametrize("few", [0, 10**9], ids=["rounds", "one_by_one"])
def test_remove_redundant_order_resolution_both_ways(monkeypatch, few):
    """Staircases resolved in vectorised rounds or pixel by pixel give the same image."""
    monkeypatch.setattr(sk, "_FEW_ORDERED", few)
    rng = np.random.default_rng(4)
    for _ in range(25):
        f, w = _padded(rng.random(tuple(rng.integers(10, 60, 2))) < rng.uniform(0.3, 0.8))
        new, _ = _vec_redundant(f, w)
        old, _ = _seq_redundant(f, w)
        assert np.array_equal(new, old)


# ----------------------------------------------------------------------------- spurs
def test_walks_find_the_same_spurs_and_lengths():
    """Spur ends and lengths of one scan, to the last bit of the lengths (their tie order
    decides which of two equal spurs is pruned)."""
    rng = np.random.default_rng(5)
    n_spurs = 0
    for mask in _masks(seed=6, n=40):
        f, w = _thinned(mask)
        f, _ = _seq_redundant(f, w)
        offs = sk._offsets(w)
        idx = np.flatnonzero(f).astype(np.int64)
        for l_min in (2.0, 4.5, float(rng.uniform(5, 40))):
            buf_len = int(l_min) * 2 + 8
            ends = np.empty(max(len(idx), 1), np.int64)
            lens = np.empty(max(len(idx), 1))
            k = _ref_spurs(f, offs, idx, len(idx), l_min, sk._COUNT, np.empty(buf_len, np.int64),
                           ends, lens, False)
            hc = f.copy()
            sk._to_row_codes(hc, idx)
            free = idx[sk._END9[sk._code9(hc, idx, w)]]
            spur, length, walker, pixel, stop = sk._walk_all(hc, w, free, l_min, buf_len, offs)
            assert np.array_equal(free[spur], ends[:k])
            assert np.array_equal(length[spur], lens[:k])
            n_spurs += k
    assert n_spurs > 50


@pytest.mark.parametrize("few", [0, 10**9], ids=["vectorised", "one_by_one"])
@pytest.mark.parametrize("raw", [False, True], ids=["skeleton", "raw"])
def test_prune_matches_sequential_loop(monkeypatch, few, raw):
    monkeypatch.setattr(sk, "_FEW_WALKERS", few)
    scans = []
    walk_all = sk._walk_all
    monkeypatch.setattr(sk, "_walk_all", lambda *a: scans.append(1) or walk_all(*a))
    rng = np.random.default_rng(7 + raw)
    total = 0
    rounds = 0
    for mask in _masks(seed=8 + raw, n=40):
        # pruning starts from an image without redundant pixels
        f, w = _padded(mask) if raw else _thinned(mask)
        f, _ = _seq_redundant(f, w)
        for l_min in (1.0, 3.0, float(rng.uniform(4, 30))):
            scans.clear()
            new, left, n = _vec_prune(f, w, l_min)
            old, left_ref, n_ref = _seq_prune(f, w, l_min)
            assert n == n_ref
            assert np.array_equal(new, old)
            assert np.array_equal(left, left_ref)
            total += n
            rounds = max(rounds, len(scans) - 1)
    assert total > 200  # spurs were pruned
    assert rounds >= 2  # some spurs only became spurs once others were cut


def test_conflicting_spurs_are_walked_again(monkeypatch):
    """Equal spurs forking at one junction: once one is cut the other is no longer a spur,
    and which one survives is the tie order's."""
    monkeypatch.setattr(sk, "_FEW_WALKERS", 0)  # every walk in Python is a walk again
    walks = []
    walk_on = sk._walk_on
    monkeypatch.setattr(sk, "_walk_on", lambda *a: walks.append(a[2]) or walk_on(*a))
    img = np.zeros((40, 60), np.uint8)
    cv2.line(img, (5, 20), (40, 20), 1, 1)
    cv2.line(img, (40, 20), (46, 14), 1, 1)  # a fork at the end of a line
    cv2.line(img, (40, 20), (46, 26), 1, 1)
    cv2.line(img, (20, 20), (20, 15), 1, 1)  # a cross of two equal spurs
    cv2.line(img, (20, 20), (20, 25), 1, 1)
    f, w = _padded(img)
    f, _ = _seq_redundant(f, w)
    new, _, n = _vec_prune(f, w, 10.0)
    old, _, n_ref = _seq_prune(f, w, 10.0)
    assert n == n_ref > 0
    assert np.array_equal(new, old)
    assert walks  # the second arm of the fork was walked again on the pruned image
    # one arm of the fork at the end of the line survives, the cross loses both arms
    fork = new.reshape(-1, w)[1:-1, 1:-1][10:31, 41:50]
    assert 5 <= fork.sum() <= 8
    assert not new.reshape(-1, w)[1:-1, 1:-1][12:19, 19:22].any()


def test_spurs_on_a_spur_go_with_it():
    """Once the spurs at its end are cut, a branch shorter than ``l_min`` is a spur too."""
    tree = _edge_cases()["spurs_on_spurs"]
    f, w = _padded(tree)
    f, _ = _seq_redundant(f, w)
    new, _, n = _vec_prune(f, w, 25.0)
    old, _, n_ref = _seq_prune(f, w, 25.0)
    assert n == n_ref
    assert np.array_equal(new, old)
    img = new.reshape(-1, w)[1:-1, 1:-1]
    assert not img[8:28, 22:40].any()  # the branch went with its spurs
    assert img[30, 21:54].sum() >= 30  # the main line stays from the first junction on


# ----------------------------------------------------------------------------- whole stage
def _ref_skeleton(mask, l_min):
    f, w = _thinned(mask)
    offs = sk._offsets(w)
    idx = np.flatnonzero(f).astype(np.int64)
    m = _ref_remove_redundant(f, offs, idx, len(idx), sk._SIMPLE, sk._COUNT)
    n = 0
    if l_min > 0:
        m, n = _ref_prune(f, offs, idx, m, l_min)
    return f.reshape(-1, w)[1:-1, 1:-1].astype(bool), n


def test_skeletonize_mask_matches_sequential_loops():
    rng = np.random.default_rng(9)
    for mask in _masks(seed=10, n=40):
        l_min = float(rng.choice([0.0, 2.0, 6.5, 25.0]))
        ref, n_ref = _ref_skeleton(mask, l_min)
        assert np.array_equal(sk.skeletonize_mask(mask.astype(bool), l_min_px=l_min), ref)
        img, n = sk._skeleton_padded(mask.astype(bool), l_min_px=l_min)
        assert n == n_ref
        assert np.array_equal(img[1:-1, 1:-1].astype(bool), ref)
        if l_min == 0:
            assert np.array_equal(sk.thin_mask(mask), ref)



def _codes(skel):
    """8-neighbour code of every pixel of a bool image (bit k = neighbour k of ``sk._DR``,
    ``sk._DC``)."""
    p = np.pad(skel.astype(np.uint8), 1)
    h, w = skel.shape
    code = np.zeros((h, w), np.intp)
    for k in range(8):
        code |= p[1 + sk._DR[k]:1 + sk._DR[k] + h, 1 + sk._DC[k]:1 + sk._DC[k] + w].astype(
            np.intp) << k
    return code


def _topology(skel):
    """(free ends, junction clusters, connected components) of a skeleton."""
    n = sk.neighbour_count(skel)
    eight = np.ones((3, 3), int)
    return (int(np.count_nonzero(n == 1)), ndi.label(n >= 3, structure=eight)[1],
            ndi.label(skel, structure=eight)[1])


@pytest.mark.parametrize("seed", [1, 3])
def test_skimage_thinning_gives_the_same_topology(seed):
    """The skimage thinning followed by the same redundant-pixel removal and pruning: other
    pixels, the same junctions, ends and components, and no redundant pixel left."""
    from crosssection.truth.network import make_scene

    rgb = make_scene(seed=seed, n_stacks=30, max_layers=6).rgb.astype(int)
    mask = (rgb[..., 2] > rgb[..., 0] + 40) & (rgb.sum(-1) < 600)
    ours = sk.skeletonize_mask(mask, l_min_px=25.0)
    ref = sk.skeletonize_mask(mask, l_min_px=25.0, method="skimage")
    assert np.count_nonzero(ours != ref) > 0  # the option does change the thinning
    assert _topology(ref) == _topology(ours)
    assert _topology(ours)[1] >= 10
    code = _codes(ref)[ref]
    assert not np.any(sk._SIMPLE[code].astype(bool) & (sk._COUNT[code] >= 2))


def test_unknown_skeleton_method_raises():
    with pytest.raises(ParameterError, match="skeleton method"):
        sk.skeletonize_mask(np.ones((5, 5), bool), l_min_px=0.0, method="thin")


def _wide_band_with_branches():
    """A band 120 px wide (half width 60) along the columns, with a 6-px bump on its lower
    edge, a thin band leaving its upper edge for 70 px and another for 30 px."""
    mask = np.zeros((320, 600), bool)
    mask[120:240, 20:580] = True
    mask[240:246, 300:306] = True           # edge bump: a spur ending on the band's edge
    mask[50:120, 150:158] = True            # a branch reaching 70 px beyond the band
    mask[90:120, 450:458] = True            # a branch reaching 30 px beyond it (< l_min)
    return mask


def test_spurs_are_measured_beyond_the_band_they_leave():
    """With the distance map, a terminal branch is a spur when it reaches less than l_min
    beyond its band: the bump's spur (66 px from the axis, 6 beyond the edge) and the 30-px
    branch go, the 70-px branch stays. Measured from the junction pixel alone (no distance
    map) all three exceed l_min = 50 px and stay."""
    mask = _wide_band_with_branches()
    dist = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    plain = sk.skeletonize_mask(mask, l_min_px=50.0)
    wide = sk.skeletonize_mask(mask, l_min_px=50.0, distance_px=dist)
    bump = (slice(200, 246), slice(290, 316))
    long_branch = (slice(50, 110), slice(148, 160))
    short_branch = (slice(90, 115), slice(448, 460))
    assert plain[bump].any() and plain[long_branch].any() and plain[short_branch].any()
    assert not wide[bump].any()
    assert not wide[short_branch].any()
    assert wide[long_branch].sum() >= 50
    # the band's axis is kept whole either way, and nothing but spurs is removed
    assert wide[180, 100:500].any() or wide[179, 100:500].any()
    assert not (wide & ~plain).any()
    assert ndi.label(wide, np.ones((3, 3)))[1] == 1


def _ref_front(f, w, j, path, depth):
    """The last level of a breadth-first search from ``j`` on the 8-connected pixels of the
    flat padded image ``f``, the pixels of ``path`` left out (sets, in Python)."""
    offs = sk._offsets(w).tolist()
    seen = set(path) | {j}
    front = {j}
    for _ in range(depth):
        nxt = {q + d for q in front for d in offs if f[q + d] and q + d not in seen}
        if not nxt:
            break
        seen |= nxt
        front = nxt
    return front


@pytest.mark.parametrize("seed", range(6))
def test_band_front_search_matches_a_set_search(seed):
    """The compiled search that measures a spur's band (its last level of pixels, the spur's
    own pixels left out) reaches the same pixels as a search on Python sets, on thinned random
    ink (meshes with many junctions), from several pixels, to several depths."""
    rng = np.random.default_rng(seed)
    mask = ndi.binary_opening(rng.random((90, 120)) < 0.55 + 0.05 * seed)
    skel = sk.skeletonize_mask(mask, l_min_px=0.0)
    f, w = _padded(skel)
    idx = np.flatnonzero(f).astype(np.int64)
    assert idx.size > 50
    hc = f.copy()
    sk._to_row_codes(hc, idx)
    search = sk._FrontSearch(hc, w, sk._offsets(w), idx.size)
    for j in rng.choice(idx, 8, replace=False).tolist():
        # a piece of skeleton next to j stands for the spur
        path = sorted(_ref_front(f, w, j, [], 1))[:1]
        for depth in (0, 1, 3, 12, 400):
            got = search.front(j, path, depth)
            assert set(got.tolist()) == _ref_front(f, w, j, path, depth)
            assert len(got) == len(set(got.tolist()))
        assert not search.seen.any()  # the scratch image is left clean for the next search


def test_distance_map_of_another_shape_is_refused():
    mask = _wide_band_with_branches()
    with pytest.raises(ParameterError, match="distance_px"):
        sk.skeletonize_mask(mask, l_min_px=50.0, distance_px=np.zeros((10, 10)))
    # also when it comes later, from a callable
    with pytest.raises(ParameterError, match="distance_px"):
        sk.skeletonize_mask(mask, l_min_px=50.0, distance_px=lambda: np.zeros((10, 10)))


@pytest.mark.parametrize("l_min_px", [0.0, 50.0])
def test_a_distance_map_given_later_is_the_same_skeleton(l_min_px):
    """A callable returning the distances (a step on another thread) is called once, after
    the thinning, and gives the skeleton the array itself gives."""
    mask = _wide_band_with_branches()
    dist = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    calls = []

    def later():
        calls.append(1)
        return dist

    got = sk.skeletonize_mask(mask, l_min_px=l_min_px, distance_px=later)
    assert calls == [1]
    assert np.array_equal(got, sk.skeletonize_mask(mask, l_min_px=l_min_px, distance_px=dist))


def _thin_band_with_fat_stub(reach_px):
    """A 10-px band (2 layers at h = 5 px) along row 60 and a 40-px wide stub (8 layers)
    with a round end, its ink reaching ``reach_px`` beyond the band's lower edge."""
    m = np.zeros((260, 400), np.uint8)
    m[55:65, 20:380] = 1
    tip = 65 + reach_px
    cv2.rectangle(m, (180, 60), (220, tip - 20), 1, -1)
    cv2.circle(m, (200, tip - 20), 20, 1, -1)
    return m.astype(bool)


@pytest.mark.parametrize("reach_px, kept", [(40, False), (70, True), (90, True)])
def test_a_fat_stub_is_measured_beyond_the_thin_band_it_leaves(reach_px, kept):
    """The fork of a stub wider than its band lies inside the stub's own ink, 20 px from
    the background where the band is 5 px half wide: measured there, a stub of 8 layers
    reaching 70 px (1.4 mm) beyond a 2-layer band read 50 px and was pruned as a spur, its
    layers lost from the rod length. Read on the band past the fork, it stays when it
    reaches more than l_min = 50 px, and goes when it does not."""
    mask = _thin_band_with_fat_stub(reach_px)
    dist = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    skel = sk.skeletonize_mask(mask, l_min_px=50.0, distance_px=dist)
    assert skel[90:, 190:211].any() == kept
    assert skel[60, 30:170].any() or skel[59, 30:170].any()  # the band stays either way


@pytest.mark.parametrize("width", [2.0, 2.4, 2.8, 3.2])
@pytest.mark.parametrize("angle_deg", [40.0, 45.0, 135.0, 140.0])
def test_thin_diagonal_bands_with_free_ends_keep_their_length(width, angle_deg):
    # straight bands 2-3 px wide drawn as polygons (60 px long, both ends free) in every
    # orientation: a staircase is not eaten from its free end pixel after pixel (a band
    # 2.8 px wide at 135 degrees keeps 3 pixels under plain sequential deletion)
    from skimage.draw import polygon

    L, size = 30.0, 80
    t = np.radians(angle_deg)
    d, c = np.array([np.sin(t), np.cos(t)]), np.array([size / 2 + 0.5, size / 2])
    n = np.array([d[1], -d[0]])
    pts = np.array([c - L * d - width / 2 * n, c + L * d - width / 2 * n,
                    c + L * d + width / 2 * n, c - L * d + width / 2 * n])
    band = np.zeros((size, size), bool)
    rr, cc = polygon(pts[:, 0], pts[:, 1], band.shape)
    band[rr, cc] = True
    for b in (band, band.T, band[::-1], band[:, ::-1]):
        skel = sk.skeletonize_mask(b, l_min_px=0)
        # a diagonal line of 2 L px holds about 2 L / sqrt(2) pixels
        assert skel.sum() >= 0.85 * 2 * L / np.sqrt(2), (width, angle_deg, skel.sum())


def test_a_staircase_two_pixels_wide_keeps_its_length():
    a = np.zeros((40, 40), bool)
    for i in range(5, 35):
        a[i, i] = a[i, i + 1] = True
    for band in (a, a.T, a[::-1], a[:, ::-1]):
        assert sk.thin_mask(band).sum() >= 29
    # an arm of 2 px at 45 degrees leaving a trunk keeps its pixels and its junction
    from crosssection.stages.junctions import find_junctions

    trunk = np.zeros((60, 60), bool)
    trunk[10:14, 5:55] = True
    for i in range(25):
        trunk[14 + i, 30 + i] = trunk[14 + i, 31 + i] = True
    skel = sk.skeletonize_mask(trunk, l_min_px=0)
    assert skel[14:].sum() >= 22 and len(find_junctions(skel)) == 1
