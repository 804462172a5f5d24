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

The integer problem is solved exactly by mixed-integer programming (``scipy.optimize.milp``,
HiGHS): ``n_i = lo_i + sum_k y_ik + up_i - down_i`` with binary unit increments ``y_ik`` whose
costs ``w_i[(lo+k-e)^2 - (lo+k-1-e)^2]`` increase with ``k`` (the convex quadratic is exact at
integers); ``lo_i, hi_i`` bracket ``e_i`` and the continuous solution by ``window`` layers and
``up_i, down_i`` extend linearly beyond.  Junction equations get slack variables with a large
penalty, so an inconsistent system (no integer n >= 1 satisfies every junction) still returns
the solution violating the fewest branch units, and is flagged.  The conservation matrix is
not totally unimodular in general (a void bounded by an odd number of cusps makes the packs
non-orientable), so rounding a continuous solution is not enough; on a network of Y
junctions the MILP stays small (about 10 variables per stack) and solves in milliseconds to
a fraction of a second (benchmarks/bench_linsys.py).

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

__all__ = ["LinearSystemResult", "ComponentInfo", "solve_branch_counts",
           "conservation_equations", "incidence_rank", "width_fixed_stacks",
           "reliability_score"]


@dataclass
class ComponentInfo:
    """Diagnostics of one connected component."""

    stacks: np.ndarray
    junctions: list
    n_equations: int
    rank: int
    condition_number: float
    residual: float
    method: str                      # "milp" | "width"
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
def _ends_at(graph, node) -> list:
    from .packs import junction_edge_ends  # light module, no cycle
    return junction_edge_ends(graph, node)


def _row(side_a, side_b) -> dict:
    row: dict[int, int] = {}
    for sid, _ in side_a:
        row[int(sid)] = row.get(int(sid), 0) + 1
    for sid, _ in side_b:
        row[int(sid)] = row.get(int(sid), 0) - 1
    return {k: v for k, v in row.items() if v != 0}  # a loop on opposite packs cancels


def conservation_equations(graph, packs: dict, layers_est=None, sigma=None, *,
                           z_max: float = 4.0, z_gap: float = 2.0):
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
    for node, pack in packs.items():
        ends = set(_ends_at(graph, node)) if graph is not None else None
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


def reliability_score(layers_est: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``w * (1 - 2 |e - round(e)|)``: thin (large weight) and close to an integer."""
    e = np.asarray(layers_est, float)
    close = 1.0 - 2.0 * np.abs(e - np.round(e))
    score = np.asarray(weights, float) * close
    return np.where(np.isfinite(score), score, -np.inf)


# --------------------------------------------------------------------------- solver
def _sparse_rows(rows, col_index, m) -> sp.csr_matrix:
    data, ri, ci = [], [], []
    for j, (_, r) in enumerate(rows):
        for s, c in r.items():
            ri.append(j)
            ci.append(col_index[s])
            data.append(float(c))
    return sp.csr_matrix((data, (ri, ci)), shape=(len(rows), m))


def _condition(A: sp.csr_matrix, dense_max: int) -> float:
    m = A.shape[1]
    if m == 0:
        return 1.0
    if m <= dense_max:
        s = np.linalg.svd(A.toarray(), compute_uv=False)
        if len(s) < m or s[-1] <= s[0] * 1e-12:
            return float("inf")
        return float(s[0] / s[-1])
    from scipy.sparse.linalg import eigsh
    G = (A.T @ A).tocsc()
    try:
        lmax = float(eigsh(G, k=1, which="LA", return_eigenvectors=False)[0])
        lmin = float(eigsh(G, k=1, sigma=-1e-6 * lmax, which="LM",
                           return_eigenvectors=False)[0])
    except Exception:  # no convergence: report unknown as inf rather than crash
        return float("inf")
    if lmin <= lmax * 1e-20:
        return float("inf")
    return float(math.sqrt(lmax / lmin))


def _milp_solve(C: sp.csr_matrix, penalties: np.ndarray, e: np.ndarray, w: np.ndarray,
                x: np.ndarray, sigma: np.ndarray, *, window: int, time_limit_s: float):
    """Exact integer least squares with penalised conservation; see module docstring."""
    from scipy.optimize import LinearConstraint, milp

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
    from scipy.optimize import Bounds
    res = milp(c, integrality=integrality, bounds=Bounds(lb, ub),
               constraints=LinearConstraint(A, rhs, rhs),
               options={"time_limit": float(time_limit_s), "disp": False})
    if res.x is None:
        return None, res.status
    z = np.round(res.x).astype(np.int64)
    n = lo + np.bincount(owner, weights=z[:n_y], minlength=m).astype(np.int64) \
        + z[n_y:n_y + m] - z[n_y + m:n_y + 2 * m]
    return np.maximum(n, 1), res.status


def solve_branch_counts(graph, packs: dict, layers_est, *, reliability=None,
                        noise_layers: float = 0.3, noise_growth: float = 0.05,
                        width_fraction: float = 1.0 / 3.0, window: int = 3,
                        z_max: float = 4.0, soft_penalty: float = 4.0,
                        time_limit_s: float = 20.0, dense_max: int = 50,
                        compute_residual: bool = True) -> LinearSystemResult:
    """Integer number of branches per stack (paper, "Image analysis procedure").

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
        Exact quadratic cost within ``window + 2 sigma`` layers of the estimate, linear beyond.
    z_max : float
        Uncertain junctions whose best partition disagrees with the widths by more than this
        many sigma are dropped.
    soft_penalty : float
        Penalty per violated branch at a soft (uncertain) junction, in units of the median
        weight.
    time_limit_s : float
        Time limit of each MILP; on expiry the best integer solution found is used
        (flag ``not-optimal``).
    dense_max : int
        Components up to this many stacks get a dense condition number, larger ones a
        sparse eigenvalue estimate.
    compute_residual : bool
        Compute the least-squares residual of the paper's system (sparse LSQR).

    Returns
    -------
    LinearSystemResult
        Never raises on singular, inconsistent or disconnected systems: they are flagged.
    """
    import networkx as nx

    M = len(graph.paths)
    e_raw = np.asarray(layers_est, dtype=float).reshape(-1)
    if len(e_raw) != M:
        raise ValueError(f"layers_est has {len(e_raw)} values for {M} stacks")
    finite = np.isfinite(e_raw)
    e = np.where(finite, e_raw, 1.0)
    sigma = noise_layers + noise_growth * np.maximum(e - 1.0, 0.0)
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
                                                         z_max=z_max)
    hard_nodes = {nd for nd, _ in hard}

    # components of the stack graph (edges carry stack ids)
    G = graph.graph
    comp_of_node = {}
    comps = []
    for ci, nodes in enumerate(sorted(nx.connected_components(G), key=lambda s: min(s))):
        stacks = sorted({int(d) for _, _, d in G.subgraph(nodes).edges(data="stack_id")})
        comps.append((sorted(nodes), stacks))
        for nd in nodes:
            comp_of_node[nd] = ci
    covered = set(s for _, st in comps for s in st)
    for s in range(M):  # stacks missing from the graph: alone
        if s not in covered:
            comps.append(([], [s]))

    n_br = np.maximum(np.round(e), 1).astype(np.int64)
    fixed = np.zeros(M, bool)
    infos = []
    flags = []
    total_rank = 0
    res_sq = 0.0
    cond_max = 1.0
    cons_res = 0
    med_w = float(np.median(w_eff))
    for ci, (nodes, stacks) in enumerate(comps):
        idx = np.asarray(stacks, dtype=int)
        m = len(idx)
        col = {s: i for i, s in enumerate(stacks)}
        nodeset = set(nodes)
        h_rows = [(nd, r) for nd, r in hard if nd in nodeset]
        s_rows = [(nd, r) for nd, r in soft if nd in nodeset]
        d_nodes = [nd for nd in dropped if nd in nodeset]
        rows = h_rows + s_rows
        info = ComponentInfo(stacks=idx, junctions=[nd for nd in nodes if nd in packs],
                             n_equations=len(rows), rank=0, condition_number=1.0,
                             residual=0.0, method="milp",
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
        rank = m  # [C; I_S] is non-singular by construction
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
        info.rank = int(rank)
        info.condition_number = _condition(A, dense_max)
        if compute_residual and A.shape[0]:
            from scipy.sparse.linalg import lsqr
            sol = lsqr(A, b, atol=1e-10, btol=1e-10, iter_lim=20 * m + 100)
            info.residual = float(np.linalg.norm(A @ sol[0] - b))
        total_rank += info.rank
        res_sq += info.residual ** 2
        cond_max = max(cond_max, info.condition_number)
        if d_nodes:
            info.flags.append("dropped-junctions")
        if s_rows:
            info.flags.append("soft-junctions")
        info.repartitioned_junctions = [nd for nd in repart if nd in nodeset]
        if info.repartitioned_junctions:
            info.flags.append("repartitioned-junctions")
        if not rows:
            info.method = "width"
            info.flags.append("fallback-to-width")
            n_br[idx] = np.maximum(np.round(ee), 1)
            infos.append(info)
            continue
        # ---- continuous weighted least squares (penalised conservation), sparse and PD
        pen = np.concatenate([np.full(len(h_rows), 1e4 * float(np.max(ww))),
                              np.full(len(s_rows), soft_penalty * med_w)])
        P = sp.diags(np.concatenate([np.full(len(h_rows), 1e3 * float(np.max(ww))),
                                     np.full(len(s_rows), soft_penalty * med_w)]))
        N = (C.T @ P @ C + sp.diags(ww)).tocsc()
        from scipy.sparse.linalg import spsolve
        try:
            x = np.asarray(spsolve(N, ww * ee)).reshape(-1)
            if not np.all(np.isfinite(x)):
                raise ValueError
        except Exception:
            x = ee.copy()
        # ---- exact integer refinement
        n_loc, status = None, None
        try:
            n_loc, status = _milp_solve(C, pen, ee, ww, x, sg, window=window,
                                        time_limit_s=time_limit_s)
        except Exception as exc:  # pragma: no cover - solver failure must not crash
            info.flags.append(f"milp-error:{type(exc).__name__}")
        if n_loc is None:
            info.method = "width"
            info.flags.append("fallback-to-width")
            n_loc = np.maximum(np.round(x), 1).astype(np.int64)
        elif status != 0:
            info.flags.append("not-optimal")
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
    del hard_nodes, comp_of_node
    return LinearSystemResult(n_br=n_br, rank=int(total_rank), residual=float(math.sqrt(res_sq)),
                              condition_number=float(cond_max), fixed_by_width=fixed,
                              n_components=len(comps), flags=flags, components=infos,
                              conservation_residual=int(cons_res), changed_from_width=changed)
