"""The equations of the paper's M x M system: conservation at junctions, widths elsewhere.

Paper, section "Image analysis procedure": the number of branches is conserved at every
junction, ``sum_{A} n = sum_{B} n`` over its two packs (2M/3 equations for Y junctions), and
the remaining M/3 equations ``n_i = round(e_i)`` come from the stacks whose thickness gives
the best layer estimate (in general thin stacks).

Junctions flagged ``reference_dependent`` or ``ambiguous`` by the packs stage are not trusted
as given: among the pack partitions listed in ``Pack.candidates`` the one whose conservation
residual with the width estimates is smallest (z-score ``|c.e| / sqrt(sum c^2 sigma^2)``) is
kept as a *soft* equation, provided that z-score is below ``z_max`` and clearly better than
the runner-up; otherwise the equation is dropped.  A *clear* junction whose geometric
partition the widths contradict, while another candidate fits clearly, is switched to that
candidate (soft, "repartitioned"); without such a candidate the geometry is kept (hard).  On
generated scenes this guards against the few junctions where the skeleton's tangents mislead
(one wrong hard equation otherwise shifts n_br along a whole chain of stacks).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

__all__ = ["conservation_equations", "rod_end_junctions", "sparse_rows", "reliability_score",
           "select_width_stacks", "paper_system", "pack_row", "candidate_partitions"]


def _ends_by_node(graph) -> dict:
    """node -> set of EdgeEnd, from ``graph.ends`` in one pass (no networkx calls)."""
    out: dict = {}
    for sid, (u, v) in enumerate(graph.ends):
        out.setdefault(u, set()).add((sid, 0))
        out.setdefault(v, set()).add((sid, 1))
    return out


def pack_row(side_a, side_b) -> dict:
    """Coefficients of ``sum_A n - sum_B n`` (a stack ending twice on one pack counts 2)."""
    row: dict[int, int] = {}
    for sid, _ in side_a:
        k = int(sid)
        row[k] = row.get(k, 0) + 1
    for sid, _ in side_b:
        k = int(sid)
        row[k] = row.get(k, 0) - 1
    if 0 in row.values():  # a loop on opposite packs cancels
        return {k: v for k, v in row.items() if v != 0}
    return row


def _covers(side_a, side_b, ends) -> bool:
    """Both packs non-empty, disjoint, and together every end at the junction."""
    if not side_a or not side_b:
        return False
    both = set(side_a)
    both.update(side_b)
    return (ends is None or both == ends) and len(side_a) + len(side_b) == len(both)


def _zscore(row: dict, est: list, sig: list) -> float:
    """Conservation residual of the width estimates in units of its standard deviation.

    ``est`` and ``sig`` are the estimates and errors as lists of floats: a row has three or
    four stacks, on which numpy's calls cost ten times the arithmetic. The sums run over the
    row in its order, from 0; from 8 terms on, numpy's pairwise sum takes the errors' sum.
    """
    if len(row) >= 8:
        ids = np.fromiter(row.keys(), int)
        c = np.fromiter(row.values(), float)
        e, s = np.take(est, ids), np.take(sig, ids)
        if not np.all(np.isfinite(e)):
            return np.inf
        return abs(c @ e) / math.sqrt(float(np.sum(c ** 2 * s ** 2)) + 1e-12)
    dot = var = 0.0
    for k, v in row.items():
        x = est[k]
        if not math.isfinite(x):
            return np.inf
        c = float(v)
        dot += c * x
        var += (c * c) * (sig[k] * sig[k])
    return abs(dot) / math.sqrt(var + 1e-12)


def candidate_partitions(pack) -> list:
    """The geometric partition of a junction's packs first, then ``pack.candidates``."""
    return [(list(pack.side_a), list(pack.side_b))] + \
        [(list(a), list(b)) for a, b in getattr(pack, "candidates", [])]


def _argmin(z: list) -> int:
    """``np.argmin`` of a list of floats: the first NaN, else the first smallest."""
    for i, x in enumerate(z):
        if x != x:
            return i
    return min(range(len(z)), key=z.__getitem__)


def _candidate_rows(pack, ends) -> list:
    """Distinct non-trivial rows of the geometric partition and of ``pack.candidates``.

    The partitions are read as they are, not copied side by side into lists as
    :func:`candidate_partitions` gives them, and :func:`_junction_equation` asks once: the
    equations of the 162 junctions of the dense 2000 x 2000 benchmark scan take 1.7 ms, 2.1
    with copies asked for twice."""
    rows = []
    for a, b in [(pack.side_a, pack.side_b)] + list(getattr(pack, "candidates", [])):
        if _covers(a, b, ends):
            r = pack_row(a, b)
            if r and r not in rows:
                rows.append(r)
    return rows


def _width_choice(rows, layers_est, sigma, z_max, z_gap):
    """Best row by z-score if clearly best and acceptable, else None."""
    if not rows or layers_est is None:
        return None
    z = [_zscore(r, layers_est, sigma) for r in rows]
    order = np.argsort(z)
    best = z[order[0]]
    runner = z[order[1]] if len(order) > 1 else np.inf
    if best <= z_max and runner - best >= z_gap:
        return rows[order[0]]
    return None


def _junction_equation(pack, ends, layers_est, sigma, *, z_max, z_gap, switch_llr):
    """Kind and row of one junction's equation.

    Returns
    -------
    kind : {"hard", "soft", "switch", "drop", "none"}
        "switch" is a clear junction repartitioned by the widths (used as a soft equation);
        "none" a junction whose packs cancel (no equation).
    row : dict or None
    """
    side_a, side_b = list(pack.side_a), list(pack.side_b)
    uncertain = bool(getattr(pack, "ambiguous", False)) or \
        bool(getattr(pack, "reference_dependent", False)) or not _covers(side_a, side_b, ends)
    if uncertain:
        choice = _width_choice(_candidate_rows(pack, ends), layers_est, sigma, z_max, z_gap)
        return ("drop", None) if choice is None else ("soft", choice)
    row = pack_row(side_a, side_b)
    if not row:
        return "none", None
    if layers_est is None:
        return "hard", row
    z_geo = _zscore(row, layers_est, sigma)
    rows = None
    if switch_llr is not None:
        rows = _candidate_rows(pack, ends)
        alts = [r for r in rows if r != row]
        if alts and math.isfinite(z_geo):
            za = [_zscore(r, layers_est, sigma) for r in alts]
            k = _argmin(za)
            if za[k] <= z_max and z_geo ** 2 - za[k] ** 2 >= switch_llr:
                return "switch", alts[k]
    if z_geo > z_max:
        # the widths flatly contradict the geometric packs: take the partition they clearly
        # support, if any; otherwise trust the geometry
        if rows is None:
            rows = _candidate_rows(pack, ends)
        alt = _width_choice(rows, layers_est, sigma, z_max, z_gap)
        if alt is not None and alt != row:
            return "switch", alt
    return "hard", row


def conservation_equations(graph, packs: dict, layers_est=None, sigma=None, *,
                           z_max: float = 4.0, z_gap: float = 2.0,
                           switch_llr: float | None = 9.0):
    """Junction conservation rows from the packs.

    Parameters
    ----------
    graph : StackGraph
    packs : dict node -> Pack
    layers_est, sigma : (M,) arrays, optional
        Width estimates and their errors, used to pick a partition at uncertain junctions.
    z_max, z_gap : float
        An uncertain junction keeps its best candidate partition when its z-score is below
        ``z_max`` and at least ``z_gap`` below the runner-up's.
    switch_llr : float or None
        A clear junction is switched to another candidate partition when the widths favour it
        by ``z_geo^2 - z_alt^2 >= switch_llr`` (twice the log-likelihood ratio; 9 = "three
        sigma") and ``z_alt <= z_max``: the geometric prior is worth that much.  On generated
        scenes the tangents mislead at a few junctions where a thin stack leaves a thick one
        (margin up to 50 degrees), and one wrong equation shifts a whole chain.

    Returns
    -------
    hard, soft : list of (node, dict stack_id -> coefficient)
    dropped : list of node
        Uncertain junctions without a clear partition (no equation).
    repartitioned : list of node
        Clear junctions whose geometric partition the widths contradict (z > ``z_max``)
        while another candidate fits clearly: that candidate is used as a soft equation.
    """
    hard, soft, dropped, repartitioned = [], [], [], []
    by_node = _ends_by_node(graph) if graph is not None else None
    if layers_est is not None:
        layers_est = np.asarray(layers_est, float).tolist()
    if sigma is not None:
        sigma = np.asarray(sigma, float).tolist()
    for node, pack in packs.items():
        ends = by_node.get(node, set()) if by_node is not None else None
        kind, row = _junction_equation(pack, ends, layers_est, sigma, z_max=z_max,
                                       z_gap=z_gap, switch_llr=switch_llr)
        if kind == "hard":
            hard.append((node, row))
        elif kind in ("soft", "switch"):
            soft.append((node, row))
            if kind == "switch":
                repartitioned.append(node)
        elif kind == "drop":
            dropped.append(node)
    return hard, soft, dropped, repartitioned


def rod_end_junctions(graph, packs: dict, layers_est, sigma, *, hidden_ends: int,
                      z_max: float = 4.0) -> list:
    """Junctions where a rod end lies: conservation holds there up to one layer.

    A rod has two ends. One that is not a free end of the skeleton lies in a band: a free end
    abutting another sheet draws a T that the skeleton reads as a junction of three stacks,
    and an end inside a band at a junction leaves one more layer on one side than on the other.
    Either way one layer ends there, so ``sum_A n - sum_B n = +-1``, and the hard equation
    ``= 0`` forces a wrong count on a whole chain of stacks (three single sheets meeting at
    a T: one of them counted as two, and every stack conservation ties to it).

    A junction is taken for a rod end when the widths say so under every pack partition:
    the conservation residual of the widths is beyond ``z_max`` sigma for every candidate
    partition (:func:`_zscore`), and that of the rounded widths is one layer for the best of
    them (an odd number of layer ends meet there; one rod end accounts for exactly one).
    Such junctions are kept only if there are no more of them than the rod ends not seen as
    free ends (``hidden_ends``): more contradictions than ends are width errors, not ends.

    Parameters
    ----------
    graph : StackGraph
    packs : dict node -> Pack
    layers_est, sigma : (M,) arrays
        Width estimates and their errors (layers).
    hidden_ends : int
        Rod ends that are not free ends of the skeleton (two per rod, minus the free ends).
    z_max : float
        Contradiction level of :func:`conservation_equations`.

    Returns
    -------
    list of node
        The junctions whose conservation equation is left out (the widths decide there).
    """
    if hidden_ends <= 0 or layers_est is None or sigma is None:
        return []
    e = np.asarray(layers_est, float)
    rounded = np.maximum(np.round(np.where(np.isfinite(e), e, 1.0)), 1.0).tolist()
    finite = np.isfinite(e).tolist()
    e, sig = e.tolist(), np.asarray(sigma, float).tolist()
    by_node = _ends_by_node(graph)
    found = []
    for node, pack in packs.items():
        ends = by_node.get(node, set())
        # every row has the parity of the sum over the stack ends (cheap: most junctions stop);
        # a stack without a width says nothing about where the rod ends
        if int(sum(rounded[s] for s, _ in ends)) % 2 == 0 \
                or not all(finite[s] for s, _ in ends):
            continue
        rows = _candidate_rows(pack, ends)
        if not rows or min(abs(sum(c * rounded[s] for s, c in r.items())) for r in rows) != 1:
            continue
        if min(_zscore(r, e, sig) for r in rows) > z_max:
            found.append(node)
    return found if len(found) <= hidden_ends else []


def sparse_rows(rows: list, col_index: dict, m: int) -> sp.csr_matrix:
    """Conservation matrix ``C`` (K x m) from ``(node, row dict)`` pairs.

    Parameters
    ----------
    rows : list of (node, dict stack_id -> coefficient)
    col_index : dict stack_id -> column
    m : int
        Number of columns.

    Returns
    -------
    scipy.sparse.csr_matrix
    """
    data, ri, ci = [], [], []
    for j, (_, r) in enumerate(rows):
        for s, c in r.items():
            ri.append(j)
            ci.append(col_index[s])
            data.append(float(c))
    return sp.csr_matrix((data, (ri, ci)), shape=(len(rows), m))


def reliability_score(layers_est: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Reliability of each width equation: thin (large weight) and close to an integer.

    Parameters
    ----------
    layers_est, weights : (M,) arrays

    Returns
    -------
    (M,) array
        ``w (1 - 2 |e - round(e)|)``; ``-inf`` where undefined (no estimate).
    """
    e = np.asarray(layers_est, float)
    close = 1.0 - 2.0 * np.abs(e - np.round(e))
    score = np.asarray(weights, float) * close
    return np.where(np.isfinite(score), score, -np.inf)


def select_width_stacks(needed: list, stacks: np.ndarray, score: np.ndarray,
                        n_paper: int) -> list:
    """The stacks whose widths enter the paper's system.

    Parameters
    ----------
    needed : list of int
        Stacks conservation cannot determine (:func:`~crosssection.linsys.rank.width_fixed_stacks`).
    stacks : (m,) int array
        Stacks of the component.
    score : (M,) array
        :func:`reliability_score`.
    n_paper : int
        The paper's count, ``ceil(M/3)``.

    Returns
    -------
    list of int
        ``needed``, then the most reliable other stacks up to ``n_paper`` in all.
    """
    sel = list(needed)
    if len(sel) < n_paper:
        chosen = set(sel)
        extra = [s for s in stacks[np.argsort(-score[stacks], kind="stable")] if s not in chosen]
        sel += extra[: n_paper - len(sel)]
    return sel


def paper_system(C: sp.csr_matrix, width_cols: np.ndarray, layers: np.ndarray):
    """The paper's system ``A = [C_hat; I_S]``, ``b = [0; max(round(e_S), 1)]``.

    Parameters
    ----------
    C : (K, m) sparse
        Conservation rows; scaled to unit norm in ``A`` so that the condition number
        compares junction and width equations on one footing.
    width_cols : (|S|,) int array
        Local columns of the stacks fixed by width.
    layers : (m,) array
        Width estimates of the component.

    Returns
    -------
    A : (K + |S|, m) csr_matrix
    b : (K + |S|,) array
    """
    m = C.shape[1]
    if C.shape[0]:
        norms = np.sqrt(np.asarray(C.multiply(C).sum(axis=1)).ravel())
        C_hat = sp.diags(1.0 / norms) @ C
    else:
        C_hat = sp.csr_matrix((0, m))
    E = sp.csr_matrix((np.ones(len(width_cols)), (np.arange(len(width_cols)), width_cols)),
                      shape=(len(width_cols), m))
    A = sp.vstack([C_hat, E], format="csr")
    b = np.concatenate([np.zeros(C.shape[0]), np.maximum(np.round(layers[width_cols]), 1)])
    return A, b
