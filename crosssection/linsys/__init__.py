"""Stage 9: the number of branches per stack, from conservation and widths.

Paper ("Statistical distributions in the folding of elastic structures", Adda-Bedia,
Boudaoud, Boué, Deboeuf), section "Image analysis procedure": the number of branches is
conserved at every junction,

    sum_{stacks s in pack A} n_s = sum_{stacks s in pack B} n_s        (2M/3 equations),

and the remaining M/3 equations ``n_s = round(e_s)`` come from the stacks whose thickness
gives the best layer estimate ``e_s`` (in general thin stacks).  The solution of this
M x M system is n_br, an integer >= 1.  Here every width contributes with its weight
``w_s = 1 / sigma_s^2`` and the integer problem is solved exactly or nearly so:

    minimise  sum_s w_s (n_s - e_s)^2 + sum_j pen_j |(C n)_j|,   n_s >= 1 integer.

Modules, in the order of the paper's system:

* :mod:`~crosssection.linsys.equations` -- the rows: junction conservation ``C n = 0`` from
  the packs (uncertain junctions decided by the widths; junctions where a rod end lies left
  out), the width equations ``I_S n = round(e_S)`` and the assembled ``[C; I_S]``.
* :mod:`~crosssection.linsys.rank` -- rank of ``C`` (signed-graph incidence), the stacks ``S``
  fixed by width (matroid greedy), condition number and residual of ``[C; I_S]``.
* :mod:`~crosssection.linsys.noise` -- width error model ``sigma_s``, weights ``w_s`` and the
  noise scale measured on the data.
* :mod:`~crosssection.linsys.search` -- integer search by exact balanced moves (numpy).
* :mod:`~crosssection.linsys.milp` -- exact MILP (HiGHS), reference and fallback.
* :mod:`~crosssection.linsys.solve` -- :func:`solve_branch_counts`, per connected component,
  and its result types.
"""
from crosssection.linsys.equations import (conservation_equations, reliability_score,
                                           rod_end_junctions)
from crosssection.linsys.noise import estimate_noise_scale
from crosssection.linsys.rank import incidence_rank, width_fixed_stacks
from crosssection.linsys.search import integer_refine
from crosssection.linsys.solve import ComponentInfo, LinearSystemResult, solve_branch_counts

__all__ = ["LinearSystemResult", "ComponentInfo", "solve_branch_counts",
           "conservation_equations", "rod_end_junctions", "incidence_rank", "width_fixed_stacks",
           "reliability_score", "estimate_noise_scale", "integer_refine"]
