"""``cuik``: CuikSLAM with unknown correspondence (paper 004) — interval constraint propagation over many
kinematic graphs, on codac (optional extra ``slamcli[interval]``).

Modules: ``contractors`` (one narrowing operator per kinematic-graph edge), ``propagate`` (chaotic
iteration to a fixpoint, 3B shaving, the branch-and-bound hull pass), ``linear`` (an LP contractor: affine
relaxation of the whole graph with rigorous dual bounds), ``hypotheses`` (branching, merging up to
relabelling), ``solver``.
"""

from slamcli.solvers.cuik.solver import CuikParams, CuikSlam

__all__ = ["CuikParams", "CuikSlam"]
