"""Union-find: grouping items joined by pairs, in one place for the whole toolkit.

Three forms, for three kinds of caller:

* :func:`group_labels` -- all pairs known up front: connected components of the pair graph
  (``scipy.sparse.csgraph.connected_components``), labels numbered in order of first item.
* :class:`DisjointSet` -- pairs arrive one by one and the caller asks ``connected`` in between
  (``scipy.cluster.hierarchy.DisjointSet``, imported on first use: ``scipy.cluster`` takes
  0.15 s to import and the analysis does not need it).
* :func:`find_root` / :func:`union_roots` -- inside a caller's loop, on a parent list or
  int array (path halving; ``parent[i] == i`` marks a root).
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

__all__ = ["group_labels", "DisjointSet", "find_root", "union_roots"]


def __getattr__(name):
    if name == "DisjointSet":
        from scipy.cluster.hierarchy import DisjointSet

        return DisjointSet
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def group_labels(n: int, pairs) -> np.ndarray:
    """Label ``n`` items so that the two items of every pair share a label.

    Parameters
    ----------
    n : int
        Number of items, numbered ``0 .. n-1``.
    pairs : array_like of shape (P, 2)
        Item pairs to join.

    Returns
    -------
    labels : (n,) int64 array
        Component label of every item, ``0 .. C-1``, numbered in order of each component's
        smallest item.
    """
    if n == 0:
        return np.zeros(0, np.int64)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    g = coo_matrix((np.ones(len(pairs), np.int8), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    # renumber by first occurrence so labels do not depend on scipy's traversal order
    _, first = np.unique(lab, return_index=True)
    order = np.argsort(first)
    remap = np.empty_like(order)
    remap[order] = np.arange(len(order))
    return remap[lab].astype(np.int64)


def find_root(parent, i):
    """Root of ``i`` in the ``parent`` list or array (path halving)."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


def union_roots(parent, a, b):
    """Join the sets of ``a`` and ``b``; the smaller root becomes the root. Returns it."""
    ra = find_root(parent, a)
    rb = find_root(parent, b)
    if ra == rb:
        return ra
    if ra < rb:
        parent[rb] = ra
        return ra
    parent[ra] = rb
    return rb
