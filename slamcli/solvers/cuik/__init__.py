"""``cuik``: CuikSLAM with unknown correspondence (paper 004) — interval constraint propagation over many
kinematic graphs, on codac (optional extra ``slamcli[interval]``).

Modules: ``contractors`` (one narrowing operator per kinematic-graph edge), ``propagate`` (chaotic
iteration to a fixpoint, 3B shaving, the branch-and-bound hull pass), ``linear`` (an LP contractor: affine
relaxation of the whole graph with rigorous dual bounds), ``hypotheses`` (branching, merging up to
relabelling), ``solver``.
"""

from slamcli.solvers.lazy import lazy_exports

_EXPORTS = {
    "CuikParams": "slamcli.solvers.cuik.params",
    "CuikSlam": "slamcli.solvers.cuik.solver",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
__all__ = ["CuikParams", "CuikSlam"]
