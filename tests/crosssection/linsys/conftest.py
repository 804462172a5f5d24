"""Fixtures of the linear-system tests: tiny hand-made stack networks."""
from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from crosssection.truth.graphs import NetworkGraph


@pytest.fixture
def tiny_graph():
    """Factory: ``tiny_graph(edges, kinds)`` -> NetworkGraph with stack ``s`` = ``edges[s]``."""
    def make(edges, kinds):
        G = nx.MultiGraph()
        G.add_nodes_from(kinds)
        for s, (u, v) in enumerate(edges):
            G.add_edge(u, v, stack_id=s)
        return NetworkGraph(G, {k: np.zeros(2) for k in kinds}, kinds,
                            [np.zeros((2, 2), int) for _ in edges], list(edges))
    return make


@pytest.fixture
def assert_conserved():
    """``assert_conserved(packs, n)``: sum over pack A == sum over pack B at every junction."""
    def check(packs, n):
        for nd, p in packs.items():
            if p.side_a and p.side_b:
                assert sum(n[s] for s, _ in p.side_a) == sum(n[s] for s, _ in p.side_b), nd
    return check


@pytest.fixture
def y_chain(tiny_graph):
    """Factory: ``y_chain(k)`` -> (graph, packs, n_true).

    Junctions 0..k-1 along a chain of stacks c_0..c_k (c_0, c_k to free ends), a free branch
    f_i at every junction; even junctions merge (c_i + f_i = c_{i+1}), odd ones split
    (c_i = c_{i+1} + f_i): n(c) alternates 1, 2 and n(f) = 1.
    """
    from crosssection.stages.packs import Pack

    def make(k):
        kinds = {i: "junction" for i in range(k)}
        edges, n = [], []
        nxt = k
        kinds[nxt] = "end"
        edges.append((nxt, 0))                      # c_0
        n.append(1)
        nxt += 1
        for i in range(k):
            kinds[nxt] = "end"
            edges.append((i, nxt))                  # f_i
            n.append(1)
            nxt += 1
            if i < k - 1:
                edges.append((i, i + 1))            # c_{i+1}
            else:
                kinds[nxt] = "end"
                edges.append((i, nxt))
                nxt += 1
            n.append(2 if i % 2 == 0 else 1)
        packs = {}
        c_in = 0
        for i in range(k):
            f, c_out = 2 * i + 1, 2 * i + 2
            if i % 2 == 0:
                packs[i] = Pack(i, [(c_out, 0)], [(c_in, 1), (f, 0)])
            else:
                packs[i] = Pack(i, [(c_in, 1)], [(c_out, 0), (f, 0)])
            c_in = c_out
        return tiny_graph(edges, kinds), packs, np.array(n)
    return make


@pytest.fixture
def dense_rows():
    """``dense_rows(rows, M)`` -> (K, M) array of the conservation row dicts."""
    def dense(rows, M):
        A = np.zeros((len(rows), M))
        for j, r in enumerate(rows):
            for s, v in r.items():
                A[j, s] = v
        return A
    return dense
