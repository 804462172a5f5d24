"""Abstract stack networks with exact layer counts, for the linear system (stage 9).

A network is generated without pixels: junction stubs are paired at random (configuration
model, so self-loops and parallel stacks occur) or arranged as a tree, every junction gets a
random pack partition, and the branches are random walks ("strands") that cross every junction
from one pack to the other; n_br of a stack is the number of strand passages. Conservation then
holds by construction, for any pack geometry.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import networkx as nx
import numpy as np

from crosssection.stages.packs import Pack

__all__ = ["NetworkGraph", "random_network"]


@dataclass
class NetworkGraph:
    """A ``StackGraph``-shaped network with packs and the true layer counts ``n_true``."""

    graph: nx.MultiGraph
    node_rc: dict
    node_kind: dict
    paths: list
    ends: list
    packs: dict = field(default_factory=dict)
    n_true: np.ndarray | None = None


def _stub_network(rng, n_junctions, n_free, p_deg4=0.05, tree=False):
    """Junction stubs paired into stacks: returns (ends list, node_kind dict, degrees)."""
    deg = {j: (4 if rng.random() < p_deg4 else 3) for j in range(n_junctions)}
    kind = {j: "junction" for j in range(n_junctions)}
    ends = []
    if tree:
        t = nx.random_labeled_tree(n_junctions, seed=int(rng.integers(2**31))) \
            if n_junctions > 1 else nx.empty_graph(1)
        used = {j: 0 for j in range(n_junctions)}
        for u, v in t.edges:
            ends.append((u, v))
            used[u] += 1
            used[v] += 1
        nxt = n_junctions
        for j in range(n_junctions):
            deg[j] = max(deg[j], used[j] + 1)
            for _ in range(deg[j] - used[j]):
                kind[nxt] = "end"
                ends.append((j, nxt))
                nxt += 1
        return ends, kind
    stubs = [j for j in range(n_junctions) for _ in range(deg[j])]
    for f in range(n_free):
        kind[n_junctions + f] = "end"
        stubs.append(n_junctions + f)
    if len(stubs) % 2:
        kind[n_junctions + n_free] = "end"
        stubs.append(n_junctions + n_free)
    stubs = list(rng.permutation(stubs))
    for i in range(0, len(stubs), 2):
        u, v = int(stubs[i]), int(stubs[i + 1])
        if kind[u] == "end" and kind[v] == "end":  # a free segment: fine, keep
            pass
        ends.append((u, v))
    return ends, kind


def random_network(seed, *, n_junctions=30, n_free=6, tree=False, mean_n=2.5,
                   p_deg4=0.05, max_steps=None):
    """A random stack network with packs and the true integer n_br (module docstring).

    Parameters
    ----------
    seed : int
        Seed of every random choice.
    n_junctions, n_free : int
        Junctions and free ends before strands are laid.
    tree : bool
        Tree topology instead of the configuration model.
    mean_n : float
        Target mean number of layers per stack.
    p_deg4 : float
        Probability that a junction has degree 4.
    max_steps : int, optional
        Longest strand walk.

    Returns
    -------
    NetworkGraph
    """
    rng = np.random.default_rng(seed)
    ends, kind = _stub_network(rng, n_junctions, n_free, p_deg4=p_deg4, tree=tree)
    M = len(ends)
    # incidences per node: list of (stack, end)
    inc = {nd: [] for nd in kind}
    for s, (u, v) in enumerate(ends):
        inc[u].append((s, 0))
        inc[v].append((s, 1))
    side = {}  # (stack, end) -> 0/1 pack at a junction
    for nd, lst in inc.items():
        if kind[nd] != "junction" or len(lst) < 2:
            continue
        k = len(lst)
        n_a = 1 if k == 3 else int(rng.integers(1, k // 2 + 1))
        perm = rng.permutation(k)
        for i, p in enumerate(perm):
            side[lst[p]] = 0 if i < n_a else 1
    counts = np.zeros(M, int)
    max_steps = max_steps or 6 * M + 20
    target = mean_n * M
    free_starts = [(s, e) for s, (u, v) in enumerate(ends) for e, nd in ((0, u), (1, v))
                   if kind[nd] == "end"]
    tries = 0
    while counts.sum() < target and tries < 50 * M:
        tries += 1
        if free_starts and rng.random() < 0.5:
            s, e = free_starts[rng.integers(len(free_starts))]
        else:
            s, e = int(rng.integers(M)), int(rng.integers(2))
        start = (s, e)
        walk = []
        cur = start
        ok = False
        for _ in range(max_steps):
            s, e = cur
            walk.append(s)
            arr_end = 1 - e
            nd = ends[s][arr_end]
            if kind[nd] != "junction" or (s, arr_end) not in side:
                ok = kind[ends[start[0]][start[1]]] == "end" and kind[nd] == "end"
                break
            opp = [x for x in inc[nd] if x in side and side[x] != side[(s, arr_end)]]
            cur = opp[rng.integers(len(opp))]
            if cur == start:
                ok = True
                break
        if ok:
            np.add.at(counts, walk, 1)
    keep = np.flatnonzero(counts > 0)
    remap = {int(s): i for i, s in enumerate(keep)}
    G = nx.MultiGraph()
    new_ends = []
    for s in keep:
        u, v = ends[s]
        new_ends.append((u, v))
    used_nodes = sorted({nd for uv in new_ends for nd in uv})
    G.add_nodes_from(used_nodes)
    for i, (u, v) in enumerate(new_ends):
        G.add_edge(u, v, stack_id=i)
    node_rc = {nd: rng.uniform(0, 1000, 2) for nd in used_nodes}
    paths = [np.array([np.round(node_rc[u]), np.round(node_rc[v])], int) for u, v in new_ends]
    packs = {}
    for nd in used_nodes:
        if kind[nd] != "junction":
            continue
        a = [(remap[s], e) for (s, e) in inc[nd] if s in remap and side.get((s, e)) == 0]
        b = [(remap[s], e) for (s, e) in inc[nd] if s in remap and side.get((s, e)) == 1]
        packs[nd] = Pack(nd, a, b, ambiguous=not (a and b))
    fg = NetworkGraph(G, node_rc, {nd: kind[nd] for nd in used_nodes}, paths, new_ends, packs,
                   counts[keep])
    return fg
