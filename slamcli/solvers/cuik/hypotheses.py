"""Kinematic-graph hypotheses for unknown correspondence (paper 004 §5: "the correspondence is a
correspondence").

A hypothesis is one kinematic graph: the association of every processed observation with a landmark label,
the landmark type of each label, the graph's contractors and the box of all variables. An observation of
type k branches every live hypothesis into "landmark j" for each of its landmarks of type k plus "a new
landmark"; a branch whose propagation empties a box is discarded.

Labels are given in order of first appearance, so the *canonical key* — the association relabelled by first
appearance — is equal for two hypotheses exactly when they differ only by the labelling of landmarks
(paper 004 §6: "differed only in labeling"); such hypotheses describe the same constraint network and are
merged (their boxes intersected: both enclose the same solution set).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from slamcli.solvers.cuik.contractors import Contractor, Interval


@dataclass
class Hypothesis:
    """One kinematic graph.

    Attributes
    ----------
    box : list of Interval           pose variables ``3t..3t+2`` = (x, y, θ), then landmark ``j`` at
                                     ``base + 2j, base + 2j + 1``.
    assoc : list of int              landmark label of each processed observation (in order).
    landmark_type : list of int      type of each landmark label.
    edges : list of Contractor       the graph's contractors (odometry edges are shared objects).
    adj : dict var -> list of edge   which edges depend on a variable.
    reported : dict id -> label      sensor-reported id → landmark label (``association="reported"``).
    """

    box: list
    assoc: list[int] = field(default_factory=list)
    landmark_type: list[int] = field(default_factory=list)
    edges: list[Contractor] = field(default_factory=list)
    adj: dict[int, list[int]] = field(default_factory=dict)
    reported: dict[int, int] = field(default_factory=dict)

    @property
    def n_landmarks(self) -> int:
        return len(self.landmark_type)

    def copy(self) -> Hypothesis:
        return Hypothesis(box=[Interval(x) for x in self.box], assoc=list(self.assoc),
                          landmark_type=list(self.landmark_type), edges=list(self.edges),
                          adj={k: list(v) for k, v in self.adj.items()}, reported=dict(self.reported))

    def add_edge(self, edge: Contractor) -> int:
        """Append ``edge`` and register its variables; returns its index."""
        k = len(self.edges)
        self.edges.append(edge)
        for v in edge.vars:
            self.adj.setdefault(v, []).append(k)
        return k

    def total_width(self) -> float:
        """Sum of the (finite) widths of all bounded variables — the tie-breaker when the cap bites."""
        s = 0.0
        for x in self.box:
            w = x.diam()
            if w != float("inf"):
                s += w
        return s


    def landmark_area(self) -> float:
        """Sum of the landmark boxes' areas ``w_x·w_y`` (m²) — with the landmark count, the cap's ranking."""
        base = len(self.box) - 2 * self.n_landmarks
        s = 0.0
        for j in range(self.n_landmarks):
            a = self.box[base + 2 * j].diam() * self.box[base + 2 * j + 1].diam()
            if a != float("inf"):
                s += a
        return s


    def log_volume(self, n_fixed: int) -> float:
        """``Σ log(width)`` over the pose and landmark variables from index ``n_fixed`` on (skipping the known
        start and unbounded ones): the log-volume of the box. Under uniform errors the likelihood of an
        association is proportional to the volume of its feasible set, which the box encloses — a rough
        proxy, used to rank hypotheses with equally many landmarks (larger first)."""
        import math

        s = 0.0
        for x in self.box[n_fixed:]:
            w = x.diam()
            if 0.0 < w < float("inf"):
                s += math.log(w)
        return s


def canonical_key(assoc: list[int]) -> tuple[int, ...]:
    """The association relabelled by order of first appearance (equal ⇔ equal up to relabelling)."""
    first: dict[int, int] = {}
    return tuple(first.setdefault(a, len(first)) for a in assoc)


def merge_relabelled(hyps: list[Hypothesis]) -> tuple[list[Hypothesis], int]:
    """Merge hypotheses equal up to relabelling (intersecting their boxes); returns (kept, number merged)."""
    by_key: dict[tuple[int, ...], Hypothesis] = {}
    merged = 0
    for h in hyps:
        key = canonical_key(h.assoc)
        if key in by_key:
            keep = by_key[key]
            # same partition ⇒ same constraint network; relabel h's landmark variables onto keep's
            perm = _label_map(h.assoc, keep.assoc)
            base = len(keep.box) - 2 * keep.n_landmarks
            for i in range(base):
                keep.box[i] = keep.box[i] & h.box[i]
            for lh, lk in perm.items():
                for c in (0, 1):
                    keep.box[base + 2 * lk + c] = keep.box[base + 2 * lk + c] & h.box[base + 2 * lh + c]
            merged += 1
        else:
            by_key[key] = h
    return list(by_key.values()), merged


def _label_map(a: list[int], b: list[int]) -> dict[int, int]:
    out: dict[int, int] = {}
    for x, y in zip(a, b):
        out.setdefault(x, y)
    return out
