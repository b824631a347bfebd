"""Chaotic iteration of narrowing operators to a fixpoint (paper 004 §4) and an optional 3B shaving pass.

Paper 004's algorithm::

    X := D;  G := F
    while G ≠ ∅:  choose g ∈ G;  X' := g(X);  G := G ∪ {f ∈ F | f depends on a variable g modified};  X := X'

Here ``G`` is a FIFO queue without duplicates, "modified" means a bound moved by more than ``tol`` (the
width-change tolerance that makes the loop finite), and an empty variable ends the propagation: the
constraint network has no solution in the box (the hypothesis is refuted).
"""

from __future__ import annotations

import heapq
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from slamcli.solvers.cuik.contractors import Contractor, Interval

#: ``leaf_bound(leaf, target, side)``: a sound bound of one end of ``leaf[target]``, None = no solution
LeafBound = Callable[[list, int, int], "float | None"]


@dataclass
class Counter:
    """Work counters: contractor applications and propagation runs."""

    contractions: int = 0
    propagations: int = 0


def propagate(box: list, edges: list[Contractor], adj: dict[int, list[int]], start: list[int], *,
              narrow_theta: bool, tol: float, counter: Counter | None = None, max_contractions: int = 200_000
              ) -> bool:
    """Run the chaotic iteration from the edges ``start`` until no bound moves by more than ``tol``.

    Parameters
    ----------
    box : list of Interval   the variables; narrowed in place.
    edges : contractors of the kinematic graph; ``adj[v]`` lists the edges that depend on variable ``v``.
    start : indices into ``edges`` queued first.

    Returns
    -------
    bool : False when some variable became empty (no solution), else True.
    """
    queue = deque(dict.fromkeys(start))
    queued = set(queue)
    n = 0
    if counter is not None:
        counter.propagations += 1
    while queue:
        e = queue.popleft()
        queued.discard(e)
        changed = edges[e].contract(box, narrow_theta, tol)
        n += 1
        if changed is None:
            if counter is not None:
                counter.contractions += n
            return False
        for v in changed:
            for f in adj.get(v, ()):
                if f != e and f not in queued:
                    queue.append(f)
                    queued.add(f)
        if n >= max_contractions:  # a safety net; the tolerance ends the loop long before
            break
    if counter is not None:
        counter.contractions += n
    return True


def shave(box: list, edges: list[Contractor], adj: dict[int, list[int]], variables: list[int], *,
          narrow_theta: bool, tol: float, slices: int, counter: Counter | None = None, rounds: int = 2) -> bool:
    """3B-consistency by shaving: refute the outer ``1/slices`` of each variable's interval.

    For a variable ``v`` with ``[a, b]``: propagate a copy with ``v ∈ [a, a + w/slices]``; if it empties, no
    solution has ``v`` there and ``a`` moves up (repeat), likewise for the upper end; then propagate the
    narrowed box. Sound: only slices proved empty are removed. Returns False when the whole box is refuted.
    """
    all_edges = list(range(len(edges)))
    for _ in range(rounds):
        moved_any = False
        for v in variables:
            for side in (0, 1):
                for _k in range(slices):
                    iv = box[v]
                    if iv.is_empty():
                        return False
                    w = iv.diam()
                    if not (w > 10 * tol) or w == float("inf"):
                        break
                    cut = iv.lb() + w / slices if side == 0 else iv.ub() - w / slices
                    part = Interval(iv.lb(), cut) if side == 0 else Interval(cut, iv.ub())
                    trial = [Interval(x) for x in box]
                    trial[v] = part
                    if propagate(trial, edges, adj, adj.get(v, []), narrow_theta=narrow_theta, tol=tol,
                                 counter=counter):
                        break
                    box[v] = Interval(cut, iv.ub()) if side == 0 else Interval(iv.lb(), cut)
                    moved_any = True
            if not propagate(box, edges, adj, adj.get(v, []), narrow_theta=narrow_theta, tol=tol, counter=counter):
                return False
        if not moved_any:
            break
    return propagate(box, edges, adj, all_edges, narrow_theta=narrow_theta, tol=tol, counter=counter)


def bisect_hull(box: list, edges: list[Contractor], adj: dict[int, list[int]], split_vars: list[int], *,
                narrow_theta: bool, tol: float, max_leaves: int, counter: Counter | None = None) -> bool:
    """Bisection pass: split the widest of ``split_vars`` (headings, where the constraints are most
    non-linear) recursively, propagate each half, and replace ``box`` by the hull of the surviving leaves.

    Sound: the leaves cover the original box and each is only narrowed by correct operators, so every
    solution lies in some leaf, hence in the hull. At most ``max_leaves`` leaves (breadth-first on the
    widest split variable). Returns False when every leaf is refuted.
    """
    leaves = [[Interval(x) for x in box]]
    while len(leaves) < max_leaves:
        # split the leaf whose widest split variable is widest
        k, v, w = -1, -1, 0.0
        for i, leaf in enumerate(leaves):
            for u in split_vars:
                du = leaf[u].diam()
                if du > w and du != float("inf"):
                    k, v, w = i, u, du
        if k < 0 or w <= 10 * tol:
            break
        leaf = leaves.pop(k)
        mid = leaf[v].mid()
        for half in (Interval(leaf[v].lb(), mid), Interval(mid, leaf[v].ub())):
            child = [Interval(x) for x in leaf]
            child[v] = half
            if propagate(child, edges, adj, adj.get(v, []), narrow_theta=narrow_theta, tol=tol, counter=counter):
                leaves.append(child)
        if not leaves:
            return False
    for i in range(len(box)):
        h = leaves[0][i]
        for leaf in leaves[1:]:
            h = h | leaf[i]
        box[i] = box[i] & h
    return True


def _candidates(leaf: list, split_vars: list[int], scales: list[float], min_width: float, k: int) -> list[int]:
    """The ``k`` split variables of ``leaf`` with the largest scaled widths ``w·scale`` above ``min_width``
    (unbounded ones skipped)."""
    w = [(leaf[u].diam() * s, u) for u, s in zip(split_vars, scales)]
    return [u for wu, u in sorted(w, reverse=True)[:k] if min_width < wu < float("inf")]


def tighten_bound(box: list, edges: list[Contractor], adj: dict[int, list[int]], target: int, side: int,
                  split_vars: list[int], scales: list[float], *, narrow_theta: bool, tol: float, max_leaves: int,
                  min_width: float, n_candidates: int = 6, counter: Counter | None = None,
                  leaf_bound: LeafBound | None = None) -> float | None:
    """Interval branch and bound on one end of ``box[target]``: the smallest lower end (``side`` 0) or the
    largest upper end (``side`` 1) over a cover of the box by propagated leaves.

    Best first: the leaf holding the current extreme end is bisected, both halves propagated and refuted
    halves dropped. The split variable is chosen by strong branching: each of the ``n_candidates`` widest
    scaled split variables (:func:`_candidates`) is tried, and the one whose worse surviving half moves the end
    furthest inwards is kept. Every solution in ``box`` stays in some leaf, so the extreme end over the leaves
    is a sound new bound. Stops after ``max_leaves`` expansions or when the extreme leaf is narrower than
    ``min_width`` in every scaled split variable. Returns the new end, or None when every leaf is refuted (no
    solution in the box). ``box`` is not modified.

    ``leaf_bound(leaf, target, side)``, when given, is a further sound bound of the leaf's end (e.g. the LP
    relaxation of :mod:`~slamcli.solvers.cuik.linear`), applied to every propagated child; None refutes it.
    """
    sign = 1.0 if side == 0 else -1.0

    def end(leaf: list) -> float:  # the end in "smaller is more extreme" form
        return sign * (leaf[target].lb() if side == 0 else leaf[target].ub())

    heap = [(end(box), 0, [Interval(x) for x in box])]
    n_made = 1
    for _ in range(max_leaves):
        leaf = heap[0][2]
        best: tuple[float, list] | None = None
        for v in _candidates(leaf, split_vars, scales, min_width, n_candidates):
            mid, kids = leaf[v].mid(), []
            for half in (Interval(leaf[v].lb(), mid), Interval(mid, leaf[v].ub())):
                child = [Interval(x) for x in leaf]
                child[v] = half
                if propagate(child, edges, adj, adj.get(v, []), narrow_theta=narrow_theta, tol=tol,
                             counter=counter) and _bounded(child, target, side, leaf_bound):
                    kids.append(child)
            score = min((end(c) for c in kids), default=float("inf"))
            if best is None or score > best[0]:
                best = (score, kids)
        if best is None:  # the extreme leaf is too small to split: its end stands
            break
        heapq.heappop(heap)
        for child in best[1]:
            heapq.heappush(heap, (end(child), n_made, child))
            n_made += 1
        if not heap:
            return None
    return sign * heap[0][0]


def _bounded(leaf: list, target: int, side: int, leaf_bound: LeafBound | None) -> bool:
    """Narrow the leaf's ``side`` end of ``target`` by ``leaf_bound``; False when the leaf is refuted."""
    if leaf_bound is None:
        return True
    e = leaf_bound(leaf, target, side)
    if e is None:
        return False
    iv = leaf[target]
    if (e > iv.ub()) if side == 0 else (e < iv.lb()):
        return False
    leaf[target] = iv & (Interval(e, iv.ub()) if side == 0 else Interval(iv.lb(), e))
    return True


def hull_pass(box: list, edges: list[Contractor], adj: dict[int, list[int]], targets: list[int],
              split_vars: list[int], scales: list[float], *, narrow_theta: bool, tol: float, max_leaves: int,
              min_width: float, rounds: int = 1, counter: Counter | None = None, n_candidates: int = 6,
              leaf_bound: LeafBound | None = None) -> bool:
    """Tighten both ends of every ``targets`` variable by :func:`tighten_bound`, propagating the narrowed box
    after each end (so later targets start from the tighter box); ``rounds`` passes. Sound; returns False when
    the box is refuted."""
    for _ in range(rounds):
        for v in targets:
            for side in (0, 1):
                if not box[v].diam() > 10 * tol:
                    continue
                new = tighten_bound(box, edges, adj, v, side, split_vars, scales, narrow_theta=narrow_theta,
                                    tol=tol, max_leaves=max_leaves, min_width=min_width, counter=counter,
                                    n_candidates=n_candidates, leaf_bound=leaf_bound)
                if new is None:
                    return False
                lo, hi = (new, box[v].ub()) if side == 0 else (box[v].lb(), new)
                if lo > hi:
                    return False
                box[v] = box[v] & Interval(lo, hi)
                if not propagate(box, edges, adj, adj.get(v, []), narrow_theta=narrow_theta, tol=tol,
                                 counter=counter):
                    return False
    return True
