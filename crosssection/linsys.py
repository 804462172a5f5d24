"""Stage 9: the number of branches per stack from conservation and widths.

Paper, section "Image analysis procedure": the number of branches is conserved at every
junction (sum over one pack = sum over the other; 2M/3 equations for Y junctions), and the
remaining M/3 equations come from the stacks whose thickness gives the best layer estimate
(in general thin stacks).  The solution of this M x M system gives n_br, an integer.

What we solve
-------------
Per connected component of the stack graph (``networkx.connected_components``), with
``e_i`` the continuous layer estimate from the width (stage 8) and ``w_i = 1 / sigma_i^2``:

    minimise   sum_i w_i (n_i - e_i)^2
    subject to C n = 0 exactly (junction conservation),  n_i >= 1 integer.

``sigma_i = noise_layers + noise_growth * (e_i - 1)`` models the width error growing with the
stack thickness (the paper's thick stacks are the ones with +-1 errors); a user
``reliability`` array multiplies ``w``.  This is the integer version of the paper's weighted
least squares: every width contributes, in proportion to its reliability, and an estimate
half-way between two integers (e = 2.5) is automatically indifferent between them.

The integer problem: the continuous weighted least squares is rounded, then improved by
exact integer *moves* (:func:`integer_refine`, numba): +-1 changes along walks through the
junctions that keep every junction they pass balanced, found as negative cycles of a small
graph (Bellman-Ford), applied while they lower the objective; a rounding that breaks
conservation is repaired by the same moves.  The conservation matrix is not totally
unimodular in general (a void bounded by an odd number of cusps makes the packs
non-orientable), so this cycle cancelling is exact on balanced networks only: on 40 random
networks with degree-4 junctions it reached the MILP optimum on 37 with the same accuracy
against the truth (0.862 vs 0.863 of stacks), tests/test_linsys.py.  The exact MILP
(``scipy.optimize.milp``, HiGHS, binary unit increments) remains as ``method="milp"`` and as
a time-limited fallback for components of at most ``milp_max_stacks`` stacks whose hard
equations the search leaves violated.  Speed (benchmarks/bench_linsys.py): 6 ms for 100
stacks, 18 ms for 450, 74 ms for 1900; the MILP alone took 3-13 s on the 244-stack
benchmark scan.

Robustness to wrong equations (blurred junctions where the tangents mislead, paper's +-1
errors along chains): by default a junction equation is not hard but costs
``robust_penalty / (s sigma_0)^2`` per violated branch (about 1.5 confident thin-stack
errors), so a single wrong partition is violated (flag ``inconsistent``, listed in
``violated_junctions``) rather than shifting n_br along a whole chain of stacks; and a
clear junction is switched to another candidate partition when the widths favour it by a
likelihood ratio (``switch_llr``).  The width error scale ``s`` is measured on the data
(:func:`estimate_noise_scale`).  ``robust_penalty=None`` restores exact conservation.  On
30 generated scenes (10 conditions: 20-300 stacks, 1-12 layers, noise, blur up to 1.5 px,
JPEG 60-85) exact n_br went from 0.973 (mean; 0.80 worst) to 1.000 of stack length.

Diagnostics follow the paper's M x M system ``A = [C; I_S]`` (rows scaled to unit norm),
``S`` = the stacks fixed by width (``fixed_by_width``), right-hand side ``[0; round(e_S)]``:
its rank, its 2-norm condition number (dense ``np.linalg.cond``-equivalent SVD for small
components, a sparse eigenvalue estimate beyond ``dense_max``) and the least-squares residual
``min_x ||A x - b||`` (sparse LSQR).

Which stacks are fixed by width (the paper keeps "the M/3 stacks with the best estimation of
the thickness, in general thin stacks"): reliability ``score_i = w_i (1 - 2 |e_i - round(e_i)|)``
(thin, so large ``w_i``, and close to an integer).  First the stacks that conservation cannot
determine are found by a matroid greedy on the columns of ``C`` taken from the *least*
reliable (:func:`width_fixed_stacks`: the least reliable stacks are determined by
conservation, what is left is the minimal, most reliable set that makes ``[C; I_S]``
non-singular); then the most reliable remaining stacks are added up to ``ceil(M/3)``.  When
conservation leaves more than M/3 unknowns free the component is flagged
``underdetermined`` (the integer solution still uses every width with its weight).
``rank_conservation`` (the rank of ``C`` alone) is reported per component.

Junctions flagged ``reference_dependent`` or ``ambiguous`` by stage 7 are not trusted as
given: among the pack partitions listed in ``Pack.candidates`` the one whose conservation
residual with the width estimates is smallest (z-score ``|c.e| / sqrt(sum c^2 sigma^2)``)
is kept as a *soft* equation (penalty ``soft_penalty``), provided that z-score is below
``z_max`` and clearly better than the runner-up; otherwise the equation is dropped.  Both cases
are flagged.  A *clear* junction whose geometric partition the widths contradict by more than
``z_max`` sigma, while another candidate fits clearly, is switched to that candidate (soft,
flag ``repartitioned-junctions``); without such a candidate the geometry is kept (hard).
On generated scenes this guards against the few junctions where the skeleton's tangents
mislead (one wrong hard equation otherwise shifts n_br along a whole chain of stacks).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numba import njit

__all__ = ["LinearSystemResult", "ComponentInfo", "solve_branch_counts",
           "conservation_equations", "incidence_rank", "width_fixed_stacks",
           "reliability_score", "estimate_noise_scale", "integer_refine"]


@dataclass
class ComponentInfo:
    """Diagnostics of one connected component."""

    stacks: np.ndarray
    junctions: list
    n_equations: int
    rank: int
    condition_number: float
    residual: float
    method: str                      # "search" | "milp" | "width"
    rank_conservation: int = 0       # rank of the junction equations alone
    flags: list = field(default_factory=list)
    soft_junctions: list = field(default_factory=list)
    dropped_junctions: list = field(default_factory=list)
    violated_junctions: list = field(default_factory=list)
    repartitioned_junctions: list = field(default_factory=list)


@dataclass
class LinearSystemResult:
    """Result of :func:`solve_branch_counts`.

    Attributes
    ----------
    n_br : (M,) int array
        Branches per stack, >= 1.
    rank : int
        Sum over components of the rank of the paper's system ``[C; I_S]``.
    residual : float
        Least-squares residual of that system, ``sqrt(sum over components of r^2)``.
    condition_number : float
        Largest component condition number (``inf`` if one is singular).
    fixed_by_width : (M,) bool array
        Stacks whose width gave an equation of the paper's system (the reliable ones).
    n_components : int
    flags : list of str
        ``"disconnected"``, and ``"<flag>:component=<c>"`` for every component flag
        (``underdetermined``, ``inconsistent``, ``fallback-to-width``, ``soft-junctions``,
        ``dropped-junctions``, ``not-optimal``).
    components : list of ComponentInfo
    conservation_residual : int
        Max ``|sum_A n - sum_B n|`` over the hard junction equations (0 when exact).
    changed_from_width : (M,) bool array
        ``n_br != max(round(layers_est), 1)``.
    """

    n_br: np.ndarray
    rank: int
    residual: float
    condition_number: float
    fixed_by_width: np.ndarray
    n_components: int
    flags: list
    components: list
    conservation_residual: int = 0
    changed_from_width: np.ndarray | None = None

    def summary(self) -> dict:
        """JSON-friendly diagnostics for ``summary.json``."""
        return {
            "rank": int(self.rank),
            "n_unknowns": int(len(self.n_br)),
            "residual": float(self.residual),
            "condition_number": (float(self.condition_number)
                                 if np.isfinite(self.condition_number) else None),
            "n_fixed_by_width": int(np.sum(self.fixed_by_width)),
            "n_changed_from_width": int(np.sum(self.changed_from_width))
            if self.changed_from_width is not None else None,
            "n_components": int(self.n_components),
            "conservation_residual": int(self.conservation_residual),
            "flags": list(self.flags),
        }


# --------------------------------------------------------------------------- equations
def _ends_by_node(graph) -> dict:
    """node -> set of EdgeEnd, from ``graph.ends`` in one pass (no networkx calls)."""
    out: dict = {}
    for sid, (u, v) in enumerate(graph.ends):
        out.setdefault(u, set()).add((sid, 0))
        out.setdefault(v, set()).add((sid, 1))
    return out


def _row(side_a, side_b) -> dict:
    row: dict[int, int] = {}
    for sid, _ in side_a:
        row[int(sid)] = row.get(int(sid), 0) + 1
    for sid, _ in side_b:
        row[int(sid)] = row.get(int(sid), 0) - 1
    return {k: v for k, v in row.items() if v != 0}  # a loop on opposite packs cancels


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
    for node, pack in packs.items():
        ends = by_node.get(node, set()) if by_node is not None else None
        side_a, side_b = list(pack.side_a), list(pack.side_b)

        def covers(a, b):
            return bool(a) and bool(b) and (ends is None or set(a) | set(b) == ends) \
                and len(a) + len(b) == len(set(a) | set(b))

        def zscore(r):
            ids = np.fromiter(r.keys(), int)
            c = np.fromiter(r.values(), float)
            est, sig = layers_est[ids], sigma[ids]
            if not np.all(np.isfinite(est)):
                return np.inf
            return abs(c @ est) / math.sqrt(float(np.sum(c ** 2 * sig ** 2)) + 1e-12)

        def candidate_rows():
            cands = [(side_a, side_b)] + [tuple(c) for c in getattr(pack, "candidates", [])]
            rows = []
            for a, b in cands:
                if covers(list(a), list(b)):
                    r = _row(a, b)
                    if r and r not in rows:
                        rows.append(r)
            return rows

        def width_choice(rows):
            """Best row by z-score if clearly best and acceptable, else None."""
            if not rows or layers_est is None:
                return None
            z = [zscore(r) for r in rows]
            order = np.argsort(z)
            best = z[order[0]]
            runner = z[order[1]] if len(order) > 1 else np.inf
            if best <= z_max and runner - best >= z_gap:
                return rows[order[0]]
            return None

        uncertain = bool(getattr(pack, "ambiguous", False)) or \
            bool(getattr(pack, "reference_dependent", False)) or not covers(side_a, side_b)
        if not uncertain:
            row = _row(side_a, side_b)
            if not row:
                continue
            if layers_est is not None and switch_llr is not None:
                z_geo = zscore(row)
                alts = [r for r in candidate_rows() if r != row]
                if alts and np.isfinite(z_geo):
                    za = [zscore(r) for r in alts]
                    k = int(np.argmin(za))
                    if za[k] <= z_max and z_geo ** 2 - za[k] ** 2 >= switch_llr:
                        soft.append((node, alts[k]))
                        repartitioned.append(node)
                        continue
            if layers_est is not None and zscore(row) > z_max:
                # the widths flatly contradict the geometric packs: take the partition they
                # clearly support, if any (soft); otherwise trust the geometry
                alt = width_choice(candidate_rows())
                if alt is not None and alt != row:
                    soft.append((node, alt))
                    repartitioned.append(node)
                    continue
            hard.append((node, row))
            continue
        choice = width_choice(candidate_rows())
        if choice is None:
            dropped.append(node)
        else:
            soft.append((node, choice))
    return hard, soft, dropped, repartitioned


def incidence_rank(rows: list, columns) -> int:
    """Exact rank of a conservation matrix whose columns have at most two non-zeros.

    Every stack touches at most two junctions, so the matrix is the incidence matrix of a
    signed graph (rows = junctions).  A left null vector ``y`` obeys
    ``y_u c_us + y_v c_vs = 0`` along each two-junction stack, and ``y_u = 0`` at a junction
    with a one-junction column (a free end, or a loop on the same pack).  Hence
    ``rank = #rows - #(components that are balanced and have no one-junction column)``,
    found by parity propagation in O(M).  (Checked against ``np.linalg.matrix_rank`` in
    tests/test_linsys.py.)  Rows at the same node are not expected (one per junction).

    Parameters
    ----------
    rows : list of dict stack_id -> coefficient
    columns : iterable of stack ids
        Only these columns are kept.

    Returns
    -------
    int
    """
    keep = set(int(c) for c in columns)
    col_rows: dict[int, list] = {}
    for j, r in enumerate(rows):
        for s, c in r.items():
            if s in keep and c != 0:
                col_rows.setdefault(s, []).append((j, c))
    adj: list[list] = [[] for _ in rows]
    absorbing = [False] * len(rows)
    for s, lst in col_rows.items():
        if len(lst) == 1:
            absorbing[lst[0][0]] = True
        elif len(lst) == 2:
            (j1, c1), (j2, c2) = lst
            # y_j2 = -(c1/c2) y_j1 ; track magnitude ratio and sign
            adj[j1].append((j2, -c1 / c2))
            adj[j2].append((j1, -c2 / c1))
        else:  # more than two junctions: not a stack column; be conservative
            for j, _ in lst:
                absorbing[j] = True
    value = [None] * len(rows)
    null_dim = 0
    for start in range(len(rows)):
        if value[start] is not None:
            continue
        value[start] = 1.0
        stack = [start]
        ok = not absorbing[start]
        while stack:
            j = stack.pop()
            for k, ratio in adj[j]:
                want = value[j] * ratio
                if value[k] is None:
                    value[k] = want
                    ok = ok and not absorbing[k]
                    stack.append(k)
                elif abs(value[k] - want) > 1e-9 * max(1.0, abs(want)):
                    ok = False
        null_dim += ok
    return len(rows) - null_dim


def width_fixed_stacks(rows: list, stacks, score) -> tuple[list, int]:
    """Stacks that conservation cannot determine, choosing the least reliable to determine.

    Matroid greedy on the columns of the conservation matrix (a signed-graph incidence
    matrix): stacks are taken in order of *increasing* reliability and kept as "determined by
    conservation" while the kept columns stay linearly independent (each connected part of
    the kept stacks is a tree, or a tree plus one unbalanced cycle or one one-junction
    column; union-find with parity).  The rest must come from widths: it is the set of most
    reliable stacks of minimal size that makes ``[C; I_S]`` non-singular.

    Parameters
    ----------
    rows : list of dict stack_id -> coefficient
    stacks : list of int
    score : (M,) array
        Reliability (higher = better).

    Returns
    -------
    fixed : list of int
        Stacks to fix by width.
    rank_c : int
        Rank of the conservation matrix restricted to ``stacks``.
    """
    stacks = list(stacks)
    col_rows: dict[int, list] = {s: [] for s in stacks}
    for j, r in enumerate(rows):
        for s, c in r.items():
            if s in col_rows and c != 0:
                col_rows[s].append((j, c))
    if any(len(v) > 2 or (len(v) == 2 and abs(v[0][1]) != abs(v[1][1]))
           for v in col_rows.values()):
        # not a plain signed graph: slow but exact incremental rank
        fixed, kept = [], []
        for s in sorted(stacks, key=lambda s: score[s]):
            if incidence_rank(rows, kept + [s]) == len(kept) + 1:
                kept.append(s)
            else:
                fixed.append(s)
        return fixed, len(kept)
    parent = list(range(len(rows)))
    parity = [0] * len(rows)     # sign of y_j relative to its root (0: +, 1: -)
    full = [False] * len(rows)   # component already has an unbalanced cycle / half-edge

    def find(j):
        path = []
        while parent[j] != j:
            path.append(j)
            j = parent[j]
        root, acc = j, 0
        for k in reversed(path):  # path compression with parities
            acc ^= parity[k]
            parity[k] = acc
            parent[k] = root
        return root

    fixed, rank_c = [], 0
    for s in sorted(stacks, key=lambda s: score[s]):
        lst = col_rows[s]
        ok = False
        if len(lst) == 1:
            r = find(lst[0][0])
            if not full[r]:
                full[r] = ok = True
        elif len(lst) == 2:
            (j1, c1), (j2, c2) = lst
            rel = 0 if c1 * c2 < 0 else 1  # y_j2 = -(c1/c2) y_j1: same sign iff c1 c2 < 0
            r1, r2 = find(j1), find(j2)
            if r1 != r2:
                if not (full[r1] and full[r2]):
                    parent[r2] = r1
                    parity[r2] = parity[j1] ^ parity[j2] ^ rel
                    full[r1] = full[r1] or full[r2]
                    ok = True
            elif not full[r1] and (parity[j1] ^ parity[j2]) != rel:
                full[r1] = ok = True  # unbalanced cycle closes: still independent
        if ok:
            rank_c += 1
        else:
            fixed.append(s)
    return fixed, rank_c


def estimate_noise_scale(layers_est, sigma_model, *, lo: float = 0.25,
                         hi: float = 1.0) -> float:
    """Scale of the width error model measured on the data.

    The distance of each estimate to the nearest integer, ``r = e - round(e)``, is the width
    error wherever it is below half a layer.  ``1.4826 median(|r| / sigma_model)`` is 1 for
    Gaussian errors that follow the model and smaller for better widths (clean scans);
    systematic offsets count (``|r|`` about zero, not about its median), and errors of half
    a layer or more saturate it near 1, so the model is never trusted *more* than the data
    allow.  Clipped to ``[lo, hi]``; 1 with fewer than 5 finite estimates.

    Parameters
    ----------
    layers_est, sigma_model : (M,) arrays

    Returns
    -------
    float
    """
    e = np.asarray(layers_est, float)
    s = np.asarray(sigma_model, float)
    ok = np.isfinite(e) & np.isfinite(s) & (s > 0)
    if ok.sum() < 5:
        return 1.0
    r = np.abs(e[ok] - np.round(e[ok])) / s[ok]
    return float(np.clip(1.4826 * np.median(r), lo, hi))


def reliability_score(layers_est: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``w * (1 - 2 |e - round(e)|)``: thin (large weight) and close to an integer."""
    e = np.asarray(layers_est, float)
    close = 1.0 - 2.0 * np.abs(e - np.round(e))
    score = np.asarray(weights, float) * close
    return np.where(np.isfinite(score), score, -np.inf)




# --------------------------------------------------------------------------- integer search
# States of the walk graph used by _improve (see its docstring): 0 = ground; for row j,
# 1 + 8 j + k with k = 0..3 "the next stack must change R_j by rho = (-2, -1, 1, 2)[k]" and
# k = 4..7 "a stack arrived changing R_j by a = (-2, -1, 1, 2)[k - 4]".
@njit(cache=True)
def _ridx(v):  # pragma: no cover - numba
    return v + 2 if v < 0 else v + 1


@njit(cache=True)
def _tau(R, pen, j, a):  # pragma: no cover - numba
    return pen[j] * (abs(R[j] + a) - abs(R[j]))


@njit(cache=True)
def _dcost(n, e, w, s, d):  # pragma: no cover - numba
    v = n[s] + d
    if v < 1:
        return np.inf
    return w[s] * ((v - e[s]) ** 2 - (n[s] - e[s]) ** 2)


@njit(cache=True)
def _improve(n, e, w, ent_row, ent_coef, n_ent, R, pen, max_moves):  # pragma: no cover
    """Exact-move local search for min sum w (n - e)^2 + sum_j pen_j |R_j|, R = C n.

    A move changes stacks by +-1 along a walk through the junctions that keeps every
    junction it passes balanced (entering a junction on one pack with +d, leaving on the
    other pack with +d or on the same pack with -d) and ends at a free end, at a junction
    without equation, or at a junction whose residual it changes (cost ``pen_j`` per unit,
    negative when it repairs a violation); closed walks are moves too.  Every such walk is a
    cycle through the ground state of a small graph (8 states per junction), and an
    improving move is a negative cycle: Bellman-Ford rounds with a check of the parent
    graph after each round (its cycles are negative).  The move found is evaluated exactly
    (a stack used twice counts once with +-2) and applied if it lowers the objective.  This
    is cycle cancelling for a bidirected flow with convex costs: exact for balanced
    (orientable) networks, a strong local search otherwise.

    Returns
    -------
    moves : int
        Number of moves applied; ``-1`` if the last cycle found was not improving once
        evaluated exactly (the search stops there).
    """
    m = n.shape[0]
    K = R.shape[0]
    V = 1 + 8 * K
    INF = 1e300
    dist = np.zeros(V)
    par = np.full(V, -1, np.int64)
    par_s = np.full(V, -1, np.int64)   # stack of the edge into the state (-1: none)
    par_d = np.zeros(V, np.int64)
    mark = np.full(V, -1, np.int64)
    d = np.zeros(m, np.int64)
    rows = np.array([-2, -1, 1, 2])
    ban_start = np.zeros(K, np.bool_)
    ban_end = np.zeros(K, np.bool_)
    ban_stack = np.zeros(m, np.bool_)
    vis = np.zeros(m, np.int64)
    moves = 0
    while moves < max_moves:
        dist[:] = 0.0
        par[:] = -1
        found = -1
        for rnd in range(V + 1):
            changed = False
            # ground -> start at junction j
            for j in range(K):
                if ban_start[j]:
                    continue
                for k in range(4):
                    c = dist[0] + _tau(R, pen, j, rows[k])
                    st = 1 + 8 * j + k
                    if c < dist[st] - 1e-12:
                        dist[st] = c
                        par[st] = 0
                        par_s[st] = -1
                        changed = True
            # arrivals: pass through (balanced) or stop (unbalanced by a)
            for j in range(K):
                for k in range(4):
                    a = rows[k]
                    st = 1 + 8 * j + 4 + k
                    if dist[st] >= INF:
                        continue
                    nxt = 1 + 8 * j + _ridx(-a)
                    if dist[st] < dist[nxt] - 1e-12:
                        dist[nxt] = dist[st]
                        par[nxt] = st
                        par_s[nxt] = -1
                        changed = True
                    if ban_end[j]:
                        continue
                    c = dist[st] + _tau(R, pen, j, a)
                    if c < dist[0] - 1e-12:
                        dist[0] = c
                        par[0] = st
                        par_s[0] = -1
                        changed = True
            # stacks
            for s in range(m):
                ne = n_ent[s]
                if ne == 0 or ban_stack[s]:
                    continue
                for dd in (-1, 1):
                    cost = _dcost(n, e, w, s, dd)
                    if cost >= INF:
                        continue
                    for o in range(ne if ne == 2 else 2):
                        # o: which entry is the start (ne == 1: o = 0 from row, 1 from ground)
                        if ne == 2:
                            j0, c0 = ent_row[s, o], ent_coef[s, o]
                            j1, c1 = ent_row[s, 1 - o], ent_coef[s, 1 - o]
                        elif o == 0:
                            j0, c0 = ent_row[s, 0], ent_coef[s, 0]
                            j1, c1 = -1, 0
                        else:
                            j0, c0 = -1, 0
                            j1, c1 = ent_row[s, 0], ent_coef[s, 0]
                        if j0 >= 0:
                            rho = c0 * dd
                            if rho < -2 or rho > 2:
                                continue
                            src = 1 + 8 * j0 + _ridx(rho)
                        else:
                            src = 0
                        if dist[src] >= INF:
                            continue
                        if j1 >= 0:
                            a = c1 * dd
                            if a < -2 or a > 2:
                                continue
                            dst = 1 + 8 * j1 + 4 + _ridx(a)
                        else:
                            dst = 0
                        c = dist[src] + cost
                        if c < dist[dst] - 1e-12:
                            dist[dst] = c
                            par[dst] = src
                            par_s[dst] = s
                            par_d[dst] = dd
                            changed = True
            if not changed:
                break
            # a cycle in the parent graph is a negative cycle
            mark[:] = -1
            for v0 in range(V):
                if mark[v0] != -1:
                    continue
                v = v0
                while v != -1 and mark[v] == -1:
                    mark[v] = v0
                    v = par[v]
                if v != -1 and mark[v] == v0:
                    found = v
                    break
            if found >= 0:
                break
        if found < 0:
            return moves
        # the move: stacks on the cycle
        d[:] = 0
        vis[:] = 0
        v = found
        steps = 0
        while True:
            if par_s[v] >= 0:
                d[par_s[v]] += par_d[v]
                vis[par_s[v]] += 1
            v = par[v]
            steps += 1
            if v == found or steps > V + 1:
                break
        # exact change of the objective
        delta = 0.0
        for s in range(m):
            if d[s] != 0:
                delta += _dcost(n, e, w, s, d[s])
        dR = np.zeros(K, np.int64)
        for s in range(m):
            if d[s] != 0:
                for q in range(n_ent[s]):
                    dR[ent_row[s, q]] += ent_coef[s, q] * d[s]
        for j in range(K):
            if dR[j] != 0:
                delta += pen[j] * (abs(R[j] + dR[j]) - abs(R[j]))
        if not (delta < -1e-9):
            # typically a walk that starts and ends at the same violated junction, each end
            # claiming the same unit of repair: forbid starting (else ending) there, retry
            # or a walk that runs twice through a stack (around an unbalanced cycle), whose
            # convex cost is then underestimated: forbid that stack for this move, retry
            twice = -1
            for s in range(m):
                if vis[s] > 1:
                    twice = s
                    break
            if twice >= 0:
                ban_stack[twice] = True
                continue
            first, last = -1, par[0]
            v = found
            for _ in range(V + 1):
                if par[v] == 0:
                    first = v
                    break
                v = par[v]
                if v == found:
                    break
            if first > 0 and par_s[first] < 0 and not ban_start[(first - 1) // 8]:
                ban_start[(first - 1) // 8] = True
                continue
            if last > 0 and not ban_end[(last - 1) // 8]:
                ban_end[(last - 1) // 8] = True
                continue
            return -1
        for s in range(m):
            n[s] += d[s]
        for j in range(K):
            R[j] += dR[j]
        ban_start[:] = False
        ban_end[:] = False
        ban_stack[:] = False
        moves += 1
    return moves
# --------------------------------------------------------------------------- solver
def _sparse_rows(rows, col_index, m) -> sp.csr_matrix:
    data, ri, ci = [], [], []
    for j, (_, r) in enumerate(rows):
        for s, c in r.items():
            ri.append(j)
            ci.append(col_index[s])
            data.append(float(c))
    return sp.csr_matrix((data, (ri, ci)), shape=(len(rows), m))


def _diagnostics(A: sp.csr_matrix, b: np.ndarray, dense_max: int, *, residual: bool = True,
                 tol: float = 1e-10, max_iter: int = 500) -> tuple[float, float]:
    """2-norm condition number and least-squares residual of ``A x = b``.

    Dense SVD up to ``dense_max`` columns.  Beyond, from one sparse LU of ``G = A^T A``:
    the residual from the normal equations, ``lambda_max(G)`` by power iteration and
    ``lambda_min(G)`` by inverse iteration (Rayleigh quotients, relative change < ``tol``);
    ``cond = sqrt(lambda_max / lambda_min)``.  This replaced ARPACK and LSQR, which took
    ~45 ms on a 244-stack component, against ~2 ms.
    """
    m = A.shape[1]
    if m == 0 or A.shape[0] == 0:
        return (1.0 if m == 0 else float("inf")), 0.0
    if m <= dense_max:
        Ad = A.toarray()
        s = np.linalg.svd(Ad, compute_uv=False)
        cond = float("inf") if (len(s) < m or s[-1] <= s[0] * 1e-12) else float(s[0] / s[-1])
        res = 0.0
        if residual:
            x = np.linalg.lstsq(Ad, b, rcond=None)[0]
            res = float(np.linalg.norm(Ad @ x - b))
        return cond, res
    from scipy.sparse.linalg import splu
    G = (A.T @ A).tocsc()
    try:
        lu = splu(G)
    except RuntimeError:  # singular
        return float("inf"), float("nan")
    res = 0.0
    if residual:
        x = lu.solve(A.T @ b)
        res = float(np.linalg.norm(A @ x - b))
    rng = np.random.default_rng(0)
    v = rng.standard_normal(m)
    v /= np.linalg.norm(v)
    lmax = 0.0
    for _ in range(max_iter):
        g = G @ v
        new = float(v @ g)
        v = g / np.linalg.norm(g)
        if abs(new - lmax) <= tol * new:
            lmax = new
            break
        lmax = new
    v = rng.standard_normal(m)
    v /= np.linalg.norm(v)
    inv = 0.0
    for _ in range(max_iter):
        g = lu.solve(v)
        new = float(v @ g)          # Rayleigh quotient of G^-1
        nrm = np.linalg.norm(g)
        if not np.isfinite(nrm) or nrm == 0:
            return float("inf"), res
        v = g / nrm
        if abs(new - inv) <= tol * new:
            inv = new
            break
        inv = new
    if not inv > 0 or not np.isfinite(inv):
        return float("inf"), res
    return float(math.sqrt(lmax * inv)), res


def _milp_solve(C: sp.csr_matrix, penalties: np.ndarray, e: np.ndarray, w: np.ndarray,
                x: np.ndarray, sigma: np.ndarray, *, window: int, time_limit_s: float):
    """Exact integer least squares with penalised conservation (HiGHS MILP, the fallback).

    ``n_i = lo_i + sum_k y_ik + up_i - down_i`` with binary unit increments ``y_ik`` whose
    costs ``w_i[(lo+k-e)^2 - (lo+k-1-e)^2]`` increase with ``k`` (the convex quadratic is
    exact at integers), ``lo_i, hi_i`` bracketing ``e_i`` and ``x_i`` by ``window + 2 sigma``
    layers, ``up_i, down_i`` linear beyond; junction rows get slacks with penalty
    ``penalties``.
    """
    from scipy.optimize import Bounds, LinearConstraint, milp

    m = len(e)
    k = C.shape[0]
    reach = window + np.ceil(2.0 * sigma).astype(int)
    lo = np.maximum(1, np.floor(np.minimum(e, x)).astype(int) - reach)
    hi = np.maximum(np.ceil(np.maximum(e, x)).astype(int) + reach, lo + 1)
    W = hi - lo
    owner = np.repeat(np.arange(m), W)
    step = np.arange(W.sum()) - np.repeat(np.cumsum(W) - W, W) + 1       # k = 1..W_i
    level = lo[owner] + step                                            # value after step

    def f(i, n):
        return w[i] * (n - e[i]) ** 2

    c_y = f(owner, level) - f(owner, level - 1)
    c_up = f(np.arange(m), hi + 1) - f(np.arange(m), hi)
    c_down = f(np.arange(m), lo - 1) - f(np.arange(m), lo)
    c = np.concatenate([c_y, c_up, c_down, penalties, penalties])
    Ccsc = C.tocsc()
    A = sp.hstack([Ccsc[:, owner], Ccsc, -Ccsc, sp.identity(k), -sp.identity(k)], format="csr")
    rhs = -(C @ lo.astype(float))
    n_y = len(owner)
    lb = np.zeros(len(c))
    ub = np.concatenate([np.ones(n_y), np.full(m, np.inf), (lo - 1).astype(float),
                         np.full(2 * k, np.inf)])
    integrality = np.concatenate([np.ones(n_y + 2 * m), np.zeros(2 * k)])
    res = milp(c, integrality=integrality, bounds=Bounds(lb, ub),
               constraints=LinearConstraint(A, rhs, rhs),
               options={"time_limit": float(time_limit_s), "disp": False})
    if res.x is None:
        return None, res.status
    z = np.round(res.x).astype(np.int64)
    n = lo + np.bincount(owner, weights=z[:n_y], minlength=m).astype(np.int64) \
        + z[n_y:n_y + m] - z[n_y + m:n_y + 2 * m]
    return np.maximum(n, 1), res.status


def _objective(n, e, w, C, pen) -> float:
    return float(np.sum(w * (n - e) ** 2) + pen @ np.abs(C @ n.astype(float)))


def _entries(C: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column (stack) its <= 2 non-zero rows and coefficients (signed-graph columns)."""
    Cc = C.tocsc()
    Cc.sum_duplicates()
    m = C.shape[1]
    n_ent = np.diff(Cc.indptr).astype(np.int64)
    if np.any(n_ent > 2):  # cannot happen for stacks (two ends); keep the first two
        n_ent = np.minimum(n_ent, 2)
    ent_row = np.full((m, 2), -1, np.int64)
    ent_coef = np.zeros((m, 2), np.int64)
    for q in range(2):
        has = n_ent > q
        pos = Cc.indptr[:-1][has] + q
        ent_row[has, q] = Cc.indices[pos]
        ent_coef[has, q] = np.round(Cc.data[pos]).astype(np.int64)
    return ent_row, ent_coef, n_ent


def integer_refine(C: sp.csr_matrix, pen: np.ndarray, e: np.ndarray, w: np.ndarray,
                   n0: np.ndarray, *, max_moves: int = 100000) -> tuple[np.ndarray, int]:
    """Integer ``n >= 1`` minimising ``sum w (n - e)^2 + sum_j pen_j |(C n)_j|`` from ``n0``.

    Parameters
    ----------
    C : (K, m) sparse
        Conservation rows (one per junction; a column has at most two non-zeros).
    pen : (K,) float
        Penalty per branch of violation (large for hard junctions).
    e, w : (m,) float
        Width estimates and weights.
    n0 : (m,) int
        Start (the rounded continuous solution).
    max_moves : int

    Returns
    -------
    n : (m,) int64
    moves : int
        Moves applied; negative when the search stopped on a non-improving cycle (a walk
        using a stack twice; rare, see :func:`_improve`).
    """
    n = np.maximum(np.asarray(n0, np.int64), 1).copy()
    ent_row, ent_coef, n_ent = _entries(C)
    R = np.asarray(np.round(C @ n.astype(float)), np.int64).reshape(-1)
    moves = _improve(n, np.asarray(e, float), np.asarray(w, float), ent_row, ent_coef, n_ent,
                     R, np.asarray(pen, float), int(max_moves))
    return n, int(moves)


def _components(graph, M: int) -> list:
    """(nodes, stacks) of every connected component, from ``graph.ends`` (union-find)."""
    nodes = list(graph.graph.nodes) if hasattr(graph, "graph") else []
    for u, v in graph.ends:
        nodes.append(u)
        nodes.append(v)
    index = {}
    for nd in nodes:
        if nd not in index:
            index[nd] = len(index)
    parent = list(range(len(index)))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for u, v in graph.ends:
        ru, rv = find(index[u]), find(index[v])
        if ru != rv:
            parent[max(ru, rv)] = min(ru, rv)
    groups: dict = {}
    for nd, i in index.items():
        groups.setdefault(find(i), ([], []))[0].append(nd)
    for s, (u, _) in enumerate(graph.ends):
        groups[find(index[u])][1].append(s)
    comps = [(sorted(nd), sorted(st)) for nd, st in groups.values() if st]
    comps.sort(key=lambda c: min(c[0]))
    covered = set(s for _, st in comps for s in st)
    for s in range(M):  # stacks missing from the graph: alone
        if s not in covered:
            comps.append(([], [s]))
    return comps


def solve_branch_counts(graph, packs: dict, layers_est, *, reliability=None,
                        noise_layers: float = 0.3, noise_growth: float = 0.05,
                        width_fraction: float = 1.0 / 3.0, window: int = 3,
                        z_max: float = 4.0, soft_penalty: float = 4.0,
                        robust_penalty: float | None = 1.5, start: str = "wls",
                        noise_scale="auto", switch_llr: float | None = 9.0,
                        milp_max_stacks: int = 60, time_limit_s: float = 1.0,
                        dense_max: int = 50, compute_residual: bool = True,
                        method: str = "auto") -> LinearSystemResult:
    """Integer number of branches per stack (paper, "Image analysis procedure").

    Per connected component: the continuous weighted least squares (penalised conservation,
    one sparse solve) is rounded, then refined by exact integer moves
    (:func:`integer_refine`: walks through the junctions that keep them balanced, applied
    while they lower ``sum w (n - e)^2 + penalties``; a rounding that violates conservation
    is repaired by the same moves, a violated hard junction costing ``1e4 max(w)`` per
    branch).  Only if a hard junction is still violated afterwards, and the component has
    at most ``milp_max_stacks`` stacks, the exact MILP (HiGHS, ``time_limit_s``) is tried and
    kept if better.  On the 2000^2 benchmark scan (244 stacks) this takes ~10 ms against
    3-13 s for the MILP alone, and on random networks it reaches the MILP optimum
    (tests/test_linsys.py, benchmarks/bench_linsys.py).

    Parameters
    ----------
    graph : StackGraph
        Stage-6 graph; its connected components are solved separately.
    packs : dict node -> Pack
        Stage-7 packs (any object with ``side_a``, ``side_b``, optionally ``ambiguous``,
        ``reference_dependent``, ``candidates``).
    layers_est : (M,) array
        Continuous layer estimate per stack from the width calibration (NaN allowed: that
        stack is then fixed by conservation alone, or 1).
    reliability : (M,) array, optional
        Non-negative multiplier of each stack's weight (e.g. from the spread of its width
        profile); 0 means "ignore this width".
    noise_layers, noise_growth : float
        Width error model ``sigma = noise_layers + noise_growth * (e - 1)`` (layers).
    width_fraction : float
        Fraction of stacks fixed by width in the paper's system (1/3).
    window : int
        MILP fallback: exact quadratic cost within ``window + 2 sigma`` layers of the
        estimate, linear beyond.
    z_max : float
        Uncertain junctions whose best partition disagrees with the widths by more than this
        many sigma are dropped.
    soft_penalty : float
        Penalty per violated branch at a soft (uncertain) junction, in units of the median
        weight.
    milp_max_stacks, time_limit_s : int, float
        MILP fallback (see above); on expiry the best integer solution found is compared.
    dense_max : int
        Components up to this many stacks get a dense SVD condition number, larger ones a
        sparse estimate (:func:`_diagnostics`).
    compute_residual : bool
        Compute the least-squares residual of the paper's system.
    method : {"auto", "milp", "search"}
        "milp" solves every component with equations by the MILP (reference, slow);
        "search" never calls it.

    Returns
    -------
    LinearSystemResult
        Never raises on singular, inconsistent or disconnected systems: they are flagged.
    """
    if method not in ("auto", "milp", "search"):
        raise ValueError(f"method must be auto, milp or search, got {method!r}")
    M = len(graph.paths)
    e_raw = np.asarray(layers_est, dtype=float).reshape(-1)
    if len(e_raw) != M:
        raise ValueError(f"layers_est has {len(e_raw)} values for {M} stacks")
    finite = np.isfinite(e_raw)
    e = np.where(finite, e_raw, 1.0)
    sigma = noise_layers + noise_growth * np.maximum(e - 1.0, 0.0)
    if isinstance(noise_scale, str):
        if noise_scale != "auto":
            raise ValueError(f"noise_scale must be a number or 'auto', got {noise_scale!r}")
        noise_scale = estimate_noise_scale(e_raw, sigma)
    sigma = sigma * float(noise_scale)
    w = 1.0 / sigma ** 2
    if reliability is not None:
        r = np.asarray(reliability, dtype=float).reshape(-1)
        if len(r) != M:
            raise ValueError(f"reliability has {len(r)} values for {M} stacks")
        w = w * np.clip(np.where(np.isfinite(r), r, 0.0), 0.0, None)
    w = np.where(finite, w, 0.0)
    w_floor = 1e-6 * (np.max(w) if np.any(w > 0) else 1.0)
    w_eff = np.maximum(w, w_floor)  # keeps every problem bounded and the LS system PD
    score = reliability_score(e_raw, w)

    hard, soft, dropped, repart = conservation_equations(graph, packs, e_raw, sigma,
                                                         z_max=z_max, switch_llr=switch_llr)
    comps = _components(graph, M)
    comp_of_node = {nd: ci for ci, (nodes, _) in enumerate(comps) for nd in nodes}
    h_by, s_by, d_by, r_by = ([[] for _ in comps] for _ in range(4))
    for lst, out in ((hard, h_by), (soft, s_by)):
        for nd, r in lst:
            if nd in comp_of_node:
                out[comp_of_node[nd]].append((nd, r))
    for lst, out in ((dropped, d_by), (repart, r_by)):
        for nd in lst:
            if nd in comp_of_node:
                out[comp_of_node[nd]].append(nd)

    n_br = np.maximum(np.round(e), 1).astype(np.int64)
    fixed = np.zeros(M, bool)
    infos = []
    flags = []
    total_rank = 0
    res_sq = 0.0
    cond_max = 1.0
    cons_res = 0
    med_w = float(np.median(w_eff)) if M else 1.0
    from scipy.sparse.linalg import spsolve
    for ci, (nodes, stacks) in enumerate(comps):
        idx = np.asarray(stacks, dtype=int)
        m = len(idx)
        col = {s: i for i, s in enumerate(stacks)}
        h_rows, s_rows, d_nodes = h_by[ci], s_by[ci], d_by[ci]
        rows = h_rows + s_rows
        info = ComponentInfo(stacks=idx, junctions=[nd for nd in nodes if nd in packs],
                             n_equations=len(rows), rank=0, condition_number=1.0,
                             residual=0.0, method="search",
                             soft_junctions=[nd for nd, _ in s_rows],
                             dropped_junctions=d_nodes)
        ee, ww, sg = e[idx], w_eff[idx], sigma[idx]
        # ---- the paper's M x M system and its diagnostics
        r_dicts = [r for _, r in rows]
        needed, rank_c = width_fixed_stacks(r_dicts, stacks, score)
        n_paper = int(math.ceil(width_fraction * m))
        sel = list(needed)
        if len(sel) < n_paper:  # the paper's M/3 most reliable, on top of the needed ones
            chosen = set(sel)
            extra = [s for s in idx[np.argsort(-score[idx], kind="stable")] if s not in chosen]
            sel += extra[: n_paper - len(sel)]
        info.rank_conservation = int(rank_c)
        if len(needed) > n_paper and rows:
            info.flags.append("underdetermined")
        fixed[sel] = True
        C = _sparse_rows(rows, col, m)
        sel_local = np.array([col[s] for s in sel], dtype=int)
        if rows:
            norms = np.sqrt(np.asarray(C.multiply(C).sum(axis=1)).ravel())
            C_hat = sp.diags(1.0 / norms) @ C
        else:
            C_hat = sp.csr_matrix((0, m))
        E = sp.csr_matrix((np.ones(len(sel_local)), (np.arange(len(sel_local)), sel_local)),
                          shape=(len(sel_local), m))
        A = sp.vstack([C_hat, E], format="csr")
        b = np.concatenate([np.zeros(len(rows)), np.maximum(np.round(ee[sel_local]), 1)])
        info.rank = m  # [C; I_S] is non-singular by construction
        info.condition_number, info.residual = _diagnostics(
            A, b, dense_max, residual=compute_residual)
        total_rank += info.rank
        res_sq += info.residual ** 2
        cond_max = max(cond_max, info.condition_number)
        if d_nodes:
            info.flags.append("dropped-junctions")
        if s_rows:
            info.flags.append("soft-junctions")
        info.repartitioned_junctions = list(r_by[ci])
        if info.repartitioned_junctions:
            info.flags.append("repartitioned-junctions")
        if not rows:
            info.method = "width"
            info.flags.append("fallback-to-width")
            n_br[idx] = np.maximum(np.round(ee), 1)
            infos.append(info)
            continue
        # ---- continuous weighted least squares (penalised conservation), sparse and PD
        if robust_penalty is None:
            p_hard, p_soft = 1e4 * float(np.max(ww)), soft_penalty * med_w
        else:
            w_ref = 1.0 / (noise_layers * float(noise_scale)) ** 2
            p_hard = robust_penalty * w_ref
            p_soft = min(soft_penalty * med_w, p_hard)
        pen = np.concatenate([np.full(len(h_rows), p_hard), np.full(len(s_rows), p_soft)])
        P = sp.diags(np.concatenate([np.full(len(h_rows), 1e3 * float(np.max(ww))
                                             if robust_penalty is None else p_hard),
                                     np.full(len(s_rows), p_soft)]))
        N = (C.T @ P @ C + sp.diags(ww)).tocsc()
        try:
            x = np.asarray(spsolve(N, ww * ee)).reshape(-1)
            if not np.all(np.isfinite(x)):
                raise ValueError
        except Exception:
            x = ee.copy()
        # ---- integer refinement: exact moves from the rounding, MILP as a fallback
        n_loc = None
        if method != "milp":
            n_loc, moves = integer_refine(C, pen, ee, ww,
                                          np.round(x) if start == "wls" else np.round(ee))
            if moves < 0:
                info.flags.append("search-stopped")
        viol = np.abs(C @ n_loc.astype(float))[: len(h_rows)] if n_loc is not None else None
        use_milp = method == "milp" or (
            method == "auto" and viol is not None and np.any(viol > 0.5)
            and m <= milp_max_stacks)
        if use_milp:
            try:
                n_m, status = _milp_solve(C, pen, ee, ww, x, sg, window=window,
                                          time_limit_s=time_limit_s)
            except Exception as exc:  # pragma: no cover - solver failure must not crash
                n_m, status = None, None
                info.flags.append(f"milp-error:{type(exc).__name__}")
            if n_m is not None and (n_loc is None or _objective(n_m, ee, ww, C, pen)
                                    < _objective(n_loc, ee, ww, C, pen) - 1e-9):
                n_loc = n_m
                info.method = "milp"
                if status != 0:
                    info.flags.append("not-optimal")
        if n_loc is None:
            info.method = "width"
            info.flags.append("fallback-to-width")
            n_loc = np.maximum(np.round(x), 1).astype(np.int64)
        n_br[idx] = n_loc
        viol = np.abs(C @ n_loc.astype(float))
        hv = viol[: len(h_rows)]
        info.violated_junctions = [h_rows[j][0] for j in np.flatnonzero(hv > 0.5)]
        if info.violated_junctions:
            info.flags.append("inconsistent")
        if len(hv):
            cons_res = max(cons_res, int(round(hv.max())))
        infos.append(info)

    for ci, info in enumerate(infos):
        flags += [f"{f}:component={ci}" for f in info.flags]
    if len(comps) > 1:
        flags.insert(0, "disconnected")
    changed = n_br != np.maximum(np.round(e), 1)
    return LinearSystemResult(n_br=n_br, rank=int(total_rank), residual=float(math.sqrt(res_sq)),
                              condition_number=float(cond_max), fixed_by_width=fixed,
                              n_components=len(comps), flags=flags, components=infos,
                              conservation_residual=int(cons_res), changed_from_width=changed)
