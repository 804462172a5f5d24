"""The stack tracing of the graph stage against the pixel-by-pixel walk it replaced.

The reference below is that walk, as it was compiled before (the same loops, run by Python).
The vectorised tracing must give the same paths in the same order (the stack ids), the same
pixel order in every path and the same nodes, on generated scans, on random skeletons with
the junctions the pipeline finds or merges, and on random junction labellings that make every
corner case of the walk frequent.
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from crosssection.core.errors import ParameterError
from crosssection.stages import graph as gr
from crosssection.stages.junctions import Junctions, find_junctions, merge_junctions
from crosssection.stages.skeleton import skeletonize_mask, thin_mask

_JUNCTION, _END, _LOOP = 0, 1, 2


# ----------------------------------------------------------------------------- reference
def _walk(f, lab, visited, p, prev, offs, out, n):
    """Follow the skeleton from flat pixel ``p`` (coming from ``prev``) until a junction or a
    free end, appending the pixels to ``out`` from position ``n``; return the (kind, id) of
    the node reached (a junction's label, or the flat index of the end pixel) and the new
    ``n``. Non-junction pixels have at most two neighbours: the next pixel is the first
    neighbour (clockwise from north) other than ``prev``."""
    while True:
        out[n] = p
        n += 1
        if lab[p] != 0:
            return _JUNCTION, lab[p] - 1, n
        visited[p] = 1
        nxt = -1
        for k in range(8):
            q = p + offs[k]
            if f[q] and q != prev:
                nxt = q
                break
        # a visited non-junction neighbour cannot happen on a clean skeleton: stop safely
        if nxt < 0 or (lab[nxt] == 0 and visited[nxt]):
            return _END, p, n
        prev = p
        p = nxt


def _trace_loops(f, lab, offs, jp, sp, visited, out, path_offs, meta):
    """Trace all stacks of the flat padded skeleton ``f`` with padded junction labels ``lab``;
    returns the number of paths (see :func:`_reference_trace`)."""
    n = 0
    m = 0
    path_offs[0] = 0
    # 1. from every junction pixel, every unvisited non-junction neighbour starts a stack
    for i in range(jp.shape[0]):
        p0 = jp[i]
        for k in range(8):
            p = p0 + offs[k]
            if not f[p] or lab[p] != 0 or visited[p]:
                continue
            out[n] = p0
            n += 1
            kind_v, id_v, n = _walk(f, lab, visited, p, p0, offs, out, n)
            path_offs[m + 1] = n
            meta[m, 0] = _JUNCTION
            meta[m, 1] = lab[p0] - 1
            meta[m, 2] = kind_v
            meta[m, 3] = id_v
            m += 1
    # 2. junction-free segments, from a free end to the other
    for i0 in range(sp.shape[0]):
        p0 = sp[i0]
        if lab[p0] != 0 or visited[p0]:
            continue
        nb = 0
        for k in range(8):
            nb += f[p0 + offs[k]]
        if nb != 1:
            continue
        kind_v, id_v, n = _walk(f, lab, visited, p0, -1, offs, out, n)
        path_offs[m + 1] = n
        meta[m, 0] = _END
        meta[m, 1] = p0
        meta[m, 2] = kind_v
        meta[m, 3] = id_v
        m += 1
    # 3. closed loops without junction: every remaining pixel has two neighbours
    for i0 in range(sp.shape[0]):
        p0 = sp[i0]
        if lab[p0] != 0 or visited[p0]:
            continue
        nb = 0
        for k in range(8):
            nb += f[p0 + offs[k]]
        if nb == 0:
            visited[p0] = 1  # isolated pixel: no stack
            continue
        p = p0
        prev = -1
        while True:
            out[n] = p
            n += 1
            visited[p] = 1
            nxt = -1
            for k in range(8):
                q = p + offs[k]
                if f[q] and q != prev:
                    nxt = q
                    break
            if nxt < 0:
                break
            if nxt == p0:
                out[n] = p0
                n += 1
                break
            if visited[nxt]:
                break
            prev = p
            p = nxt
        path_offs[m + 1] = n
        meta[m, 0] = _LOOP
        meta[m, 1] = p0
        meta[m, 2] = _LOOP
        meta[m, 3] = p0
        m += 1
    return m


class _Seq(list):
    """A list with the ``shape`` the loops read."""

    @property
    def shape(self):
        return (len(self),)


def _reference_trace(sk, sp_lab, jflat, j_lab):
    """:func:`crosssection.stages.graph._trace` by the pixel-by-pixel walk, on the label
    array the walk read (labels on skeleton and junction pixels, zero elsewhere)."""
    f, w, sp = sk.img.reshape(-1), sk.img.shape[1], sk.sp
    lab = np.zeros(len(f), np.int64)
    lab[sp] = sp_lab
    lab[jflat] = j_lab
    visited = np.zeros(len(f), np.int64)
    cap_paths = 8 * len(jflat) + len(sp) + 1
    out = [0] * (len(sp) + 2 * cap_paths)
    path_offs = [0] * (cap_paths + 1)
    meta = np.empty((cap_paths, 4), np.int64)
    offs8 = [-w, -w + 1, 1, w + 1, w, w - 1, -1, -w - 1]
    # Python lists: the loops index them element by element, much faster than arrays
    m = _trace_loops(f.tolist(), lab.tolist(), offs8, _Seq(jflat.tolist()), _Seq(sp.tolist()),
                     visited.tolist(), out, path_offs, meta)
    offs = np.array(path_offs[:m + 1], np.int64)
    return np.array(out[:offs[-1]], np.int64), offs, meta[:m].copy()


# ----------------------------------------------------------------------------- comparison
def _traces(skel, junc):
    """(new, reference) tracings of a skeleton with its junctions, as the graph stage sets
    them up."""
    runs = []
    for trace in (gr._trace, _reference_trace):
        runs.append(trace(*_trace_args(skel, junc)))
    return runs


def _trace_args(skel, junc):
    """The arguments of the tracing, as the graph stage makes them."""
    sk = gr._padded(np.asarray(skel, bool))
    wp = sk.img.shape[1]
    jp = (np.concatenate(junc.pixels).astype(np.int64) + 1 if junc.pixels
          else np.zeros((0, 2), np.int64))
    lab = junc.label_image
    return (sk, lab[sk.sr - 1, sk.sc - 1], jp[:, 0] * wp + jp[:, 1],
            lab[jp[:, 0] - 1, jp[:, 1] - 1])


def _assert_same_tracing(skel, junc):
    """The two tracings are equal; returns the reference's (pix, offs, meta)."""
    (pix, offs, meta), (rpix, roffs, rmeta) = _traces(skel, junc)
    assert pix.dtype == offs.dtype == meta.dtype == np.int64
    assert np.array_equal(offs, roffs)
    assert np.array_equal(pix, rpix)
    assert np.array_equal(meta, rmeta)
    return rpix, roffs, rmeta


def _assert_same_graph(a, b):
    assert a.ends == b.ends
    assert a.node_kind == b.node_kind
    assert a.node_rc.keys() == b.node_rc.keys()
    assert all(np.array_equal(a.node_rc[k], b.node_rc[k]) for k in a.node_rc)
    assert len(a.paths) == len(b.paths)
    assert all(p.dtype == q.dtype and np.array_equal(p, q) for p, q in zip(a.paths, b.paths))
    assert np.array_equal(a.length_px, b.length_px)
    assert sorted(a.graph.edges(keys=True, data=True)) == \
        sorted(b.graph.edges(keys=True, data=True))


class _Tally:
    """Counts the corner cases of the walk met by the compared tracings."""

    def __init__(self):
        self.n = {}

    def add(self, skel, pix, offs, meta):
        w = skel.shape[1] + 2
        for i, (ku, iu, kv, iv) in enumerate(meta.tolist()):
            p = pix[offs[i]:offs[i + 1]]
            if ku == _JUNCTION and kv == _JUNCTION:
                self._inc("junction-junction")
                if iu == iv:
                    self._inc("self-loop")
                if len(p) == 3:
                    self._inc("one pixel between junction pixels")
                if iu != iv and len(p) == 3:
                    self._inc("one pixel between two junctions")
            elif ku == _JUNCTION:
                self._inc("junction-end")
                if len(p) == 2:
                    self._inc("one-pixel spur")
            elif ku == _END:
                self._inc("end-end")
            else:
                self._inc("loop")
                # the loop's first pixel has its two neighbours E, SE, S or SW (none before it
                # in raster order): the walk leaves it towards the first of them clockwise
                self._inc({1: "loop E", w + 1: "loop SE", w: "loop S"}[int(p[1] - p[0])])
        img = np.zeros((skel.shape[0] + 2, w), np.uint8)
        img[1:-1, 1:-1] = skel
        nb = cv2.filter2D(img, -1, np.ones((3, 3), np.float32), borderType=cv2.BORDER_CONSTANT)
        if ((nb == 1) & (img == 1)).any():
            self._inc("isolated pixel")

    def _inc(self, key):
        self.n[key] = self.n.get(key, 0) + 1


def _random_mask(rng, shape):
    """A random binary image: sparse dots, dense noise, or blobs closed by a 3x3 square."""
    kind = int(rng.integers(3))
    if kind == 0:
        return rng.random(shape) < rng.uniform(0.05, 0.35)
    m = rng.random(shape) < rng.uniform(0.3, 0.6)
    if kind == 2:
        m = cv2.morphologyEx(m.view(np.uint8), cv2.MORPH_CLOSE,
                             np.ones((3, 3), np.uint8)).view(bool)
    return m


def _random_shape(rng):
    return tuple(int(v) for v in rng.choice([1, 2, 3, 5, 9, 17, 40, 71], 2))


def _random_labelling(rng, skel):
    """Junctions over the pixels with three or more neighbours and a random share of the
    others, grouped at random into junctions (so that junctions touch, two pixels of
    different junctions hold one pixel between them, a pixel lies between two junction
    pixels, ...), each junction's pixels in random order."""
    s = skel.view(np.uint8)
    nb = cv2.filter2D(s, -1, np.ones((3, 3), np.float32), borderType=cv2.BORDER_CONSTANT) - s
    pix = np.argwhere(skel & ((nb >= 3) | (rng.random(skel.shape) < rng.uniform(0, 0.4))))
    k = int(rng.integers(1, max(2, len(pix) // 2 + 1))) if len(pix) else 0
    ids = rng.integers(0, k, len(pix)) if k else np.zeros(0, np.int64)
    lab = np.zeros(skel.shape, np.int32)
    pixels = []
    for j in range(k):
        p = pix[ids == j]
        if len(p) == 0:
            continue
        p = p[rng.permutation(len(p))]
        lab[p[:, 0], p[:, 1]] = len(pixels) + 1
        pixels.append(p)
    order = rng.permutation(len(pixels))
    relab = np.zeros(len(pixels) + 1, np.int32)
    relab[order + 1] = np.arange(1, len(pixels) + 1)
    pixels = [pixels[i] for i in order]
    centers = (np.array([p.mean(axis=0) for p in pixels]) if pixels else np.zeros((0, 2)))
    return Junctions(centers_rc=centers, pixels=pixels, label_image=relab[lab])


# ----------------------------------------------------------------------------- tests
def test_small_cases_by_hand():
    cases = {
        "isolated pixel": ["...", ".x.", "..."],
        "two pixels": ["xx"],
        "free segment": [".x...", "..x..", "...xx"],
        "triangle": ["xx", "x."],
        "ring leaving south-east": ["..x..", ".x.x.", "x...x", ".x.x.", "..x.."],
        "ring leaving east": [".xx.", "x..x", ".xx."],
        "ring leaving south": ["..x..", "..x..", ".x.x.", "..x.."],
        "ring with its first pixel above a corner": ["..x", ".x.", "x.x", ".xx"],
        "Y": ["x...x", ".x.x.", "..x..", "..x..", "..x.."],
        "X": ["x...x", ".x.x.", "..x..", ".x.x.", "x...x"],
        "lollipop": [".xxx.", "x...x", ".x.x.", "..x..", "..x..", "..x.."],
        "theta": [".xxxxx.", "x..x..x", "x..x..x", "x..x..x", ".xxxxx."],
        "empty": ["...", "..."],
    }
    counts = {}
    for name, rows in cases.items():
        skel = np.array([[c == "x" for c in r] for r in rows])
        for merge_px in (0.0, 2.0):
            pix, offs, meta = _assert_same_tracing(skel, find_junctions(skel, merge_px=merge_px))
            counts[name] = len(meta)
            _assert_same_graph(gr.build_stack_graph(skel, find_junctions(skel)),
                               _reference_graph(skel, find_junctions(skel)))
    assert counts["isolated pixel"] == counts["empty"] == 0
    assert counts["two pixels"] == counts["free segment"] == 1
    assert counts["triangle"] == 1 and counts["Y"] == 3 and counts["X"] == 4


def _reference_graph(skel, junc):
    """build_stack_graph with the reference tracing."""
    new = gr._trace
    gr._trace = _reference_trace
    try:
        return gr.build_stack_graph(skel, junc)
    finally:
        gr._trace = new


@pytest.mark.parametrize("source", ["raw", "thinned", "skeleton"])
def test_random_skeletons_with_found_junctions(source):
    rng = np.random.default_rng({"raw": 10, "thinned": 11, "skeleton": 12}[source])
    tally = _Tally()
    for _ in range(250):
        m = _random_mask(rng, _random_shape(rng))
        if source == "thinned":
            m = thin_mask(m)
        elif source == "skeleton":
            m = skeletonize_mask(m, l_min_px=float(rng.choice([0, 3, 8])))
        junc = find_junctions(m, merge_px=float(rng.choice([0.0, 1.0, 2.0, 3.5])))
        tally.add(m, *_assert_same_tracing(m, junc))
    assert tally.n.get("junction-junction", 0) > 50 and tally.n.get("junction-end", 0) > 50
    assert tally.n.get("end-end", 0) > 20 and tally.n.get("loop", 0) > 5


def test_random_junction_labellings():
    """Every corner case of the walk, many times over."""
    rng = np.random.default_rng(13)
    tally = _Tally()
    for it in range(400):
        m = _random_mask(rng, _random_shape(rng))
        if it % 2:
            m = thin_mask(m)
        junc = _random_labelling(rng, m)
        tally.add(m, *_assert_same_tracing(m, junc))
        if it % 20 == 0:
            _assert_same_graph(gr.build_stack_graph(m, junc), _reference_graph(m, junc))
    for case in ("self-loop", "one pixel between junction pixels",
                 "one pixel between two junctions", "one-pixel spur", "end-end", "loop E",
                 "loop SE", "loop S", "isolated pixel"):
        assert tally.n.get(case, 0) >= 3, (case, tally.n)


def test_merged_junctions():
    """The tracings after the thick-crossing merges of ``stack_graph``, with random radii
    so that many short links merge."""
    rng = np.random.default_rng(14)
    n_merged = 0
    for _ in range(60):
        m = cv2.morphologyEx((rng.random((60, 70)) < 0.5).view(np.uint8), cv2.MORPH_CLOSE,
                             np.ones((3, 3), np.uint8)).view(bool)
        skel = skeletonize_mask(m, l_min_px=float(rng.choice([0, 3, 8])))
        junc = find_junctions(skel)
        for _round in range(3):
            sg = gr.build_stack_graph(skel, junc)
            _assert_same_graph(sg, _reference_graph(skel, junc))
            links = gr.short_junction_links(sg, rng.uniform(0, 6, len(junc)))
            if not links:
                break
            junc = merge_junctions(junc, [sg.ends[s] for s in links],
                                   [sg.paths[s] for s in links])
            n_merged += len(links)
            _assert_same_tracing(skel, junc)
    assert n_merged > 100


@pytest.fixture(scope="module")
def scene_skeletons():
    """Skeletons of generated scans, as the pipeline makes them."""
    from crosssection.stages.clean import clean_mask
    from crosssection.stages.threshold import threshold_rgb
    from crosssection.truth.network import make_scene

    out = []
    for seed, n_stacks, layers, size in ((4, 50, 5, None), (21, 120, 4, 800), (22, 30, 5, 400)):
        sc = make_scene(seed=seed, n_stacks=n_stacks, max_layers=layers, noise_sigma=4.0,
                        specks=5, image_size=size)
        h = sc.params["thickness_mm"] * sc.params["px_per_mm"]
        mask = clean_mask(threshold_rgb(sc.rgb).mask, s_min_px=(10 * h) ** 2,
                          speck_px=10 * h * h)
        skel = skeletonize_mask(mask, l_min_px=10 * h)
        dist = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        out.append((skel, dist, h))
    return out


def test_generated_scans(scene_skeletons):
    for skel, dist, h in scene_skeletons:
        pix, offs, meta = _assert_same_tracing(skel, find_junctions(skel))
        assert len(meta) > 20
        junc, sg, merged = gr.stack_graph(skel, dist, thickness_px=h)
        new = gr._trace
        gr._trace = _reference_trace
        try:
            rjunc, rsg, rmerged = gr.stack_graph(skel, dist, thickness_px=h)
        finally:
            gr._trace = new
        assert merged == rmerged
        assert np.array_equal(junc.centers_rc, rjunc.centers_rc)
        _assert_same_graph(sg, rsg)


def test_scratch_array_is_used_on_skeleton_pixels_only():
    """The graph stage never clears the tracing's scratch array: whatever it holds, the
    tracing is the same, and it changes only on skeleton pixels."""
    rng = np.random.default_rng(15)
    for _ in range(60):
        m = thin_mask(_random_mask(rng, (40, 50)))
        junc = _random_labelling(rng, m) if rng.random() < 0.5 else find_junctions(m)
        args = _trace_args(m, junc)
        f, code = args[0].img.reshape(-1), args[0].code
        runs = []
        for garbage in (False, True):
            code[:] = rng.integers(-50, 50, code.size) if garbage else 0
            before = code.copy()
            runs.append(gr._trace(*args))
            assert np.array_equal(code[f == 0], before[f == 0])
        assert all(np.array_equal(a, b) for a, b in zip(*runs))


def test_junctions_of_another_skeleton_are_refused():
    skel = np.zeros((9, 9), bool)
    skel[4, 1:8] = True
    skel[1:8, 4] = True
    junc = find_junctions(skel)
    assert len(junc) == 1 and gr.build_stack_graph(skel, junc).n_stacks == 4
    # a pixel with three neighbours left out of every junction
    none = Junctions(np.zeros((0, 2)), [], np.zeros(skel.shape, np.int32))
    with pytest.raises(ParameterError, match="do not match the skeleton"):
        gr.build_stack_graph(skel, none)
    # a junction pixel off the skeleton
    off = skel.copy()
    off[4, 4] = False
    with pytest.raises(ParameterError, match="do not match the skeleton"):
        gr.build_stack_graph(off, junc)
    # a labelled pixel in no junction's pixel list
    lab = junc.label_image.copy()
    lab[4, 1] = 1
    with pytest.raises(ParameterError, match="do not match the skeleton"):
        gr.build_stack_graph(skel, Junctions(junc.centers_rc, junc.pixels, lab))


def test_without_stacks_drops_free_pieces_and_renumbers_the_rest():
    """Two isolated segments and a Y: dropping one segment leaves the others in their order,
    renumbered, with their end nodes; a stack meeting a junction cannot be dropped."""
    from crosssection.stages.graph import build_stack_graph, without_stacks
    from crosssection.stages.junctions import find_junctions

    skel = np.zeros((40, 60), bool)
    skel[5, 5:25] = True
    skel[30, 5:25] = True
    skel[10:30, 45] = True
    skel[10, 35:45] = True
    skel[10, 46:56] = True
    sg = build_stack_graph(skel, find_junctions(skel))
    free = [sid for sid, (u, v) in enumerate(sg.ends)
            if sg.node_kind[u] == "end" and sg.node_kind[v] == "end"]
    assert len(free) == 2
    out = without_stacks(sg, free[:1])
    assert out.n_stacks == sg.n_stacks - 1
    kept = [sid for sid in range(sg.n_stacks) if sid != free[0]]
    for k, sid in enumerate(kept):
        assert np.array_equal(out.paths[k], sg.paths[sid]) and out.ends[k] == sg.ends[sid]
        assert out.length_px[k] == sg.length_px[sid]
    assert sorted(d["stack_id"] for *_, d in out.graph.edges(data=True)) == list(range(len(kept)))
    assert all(n in out.node_kind for e in out.ends for n in e)
    assert not set(sg.ends[free[0]]) & set(out.node_kind)
    junction_stack = next(sid for sid, (u, v) in enumerate(sg.ends)
                          if "junction" in (sg.node_kind[u], sg.node_kind[v]))
    with pytest.raises(ValueError):
        without_stacks(sg, [junction_stack])
