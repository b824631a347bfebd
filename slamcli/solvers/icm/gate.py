"""Null matching behind a gate (``outlier_prob > 0``, beyond the paper).

A real sensor reports some sightings far from where its own id puts them (MRCLAM: barcodes read off the wrong
landmark or another robot's tag, range outliers). Under the paper's quadratic Φ one such sighting drags its pose
and map point by its whole residual, and a chain of them bends the path (how far: benchmarks/results/design_notes.md).

The ICM answer is one more value of the matching node: ``c_{t,i} = ∅`` (no map point) at a constant cost τ_i.
The observation potential becomes the truncated quadratic ::

    ψ_i = min(‖h⁻¹(x_t, z_{t,i}) − m_{c_i}‖²_Q, τ_i),    τ_i = γ · σ̄_i² · q̄,

with γ = χ²₂(outlier_prob) (2 dof), σ̄_i² = (σ_r² + r_i² σ_b²) / 2 the noise model's mean variance of the sighting
in the world frame (σ_r along the beam, r_i σ_b across it) and q̄ the mean diagonal of Q. With the information
weights q̄σ̄² ≈ 1 at the median range, so τ_i is the χ² gate; with design weights the gate is the same distance in
metres. Each c-step takes, per observation, the cheaper of its candidate label and ∅ — the exact conditional mode
of c under ψ — so every sweep still lowers the (truncated) energy and the stopping rule is unchanged. A null-labelled
observation stays in the model: the next c-step looks at it again.
"""

from __future__ import annotations

import numpy as np

from slamcli.solvers.icm import energy as en


def null_costs(prob: en.Problem, W: en.Weights, range_std: float, bearing_std: float, k_sigma: float):
    """τ_i ``(N,)``: the cost of the null matching of each observation (module docstring), ``k_sigma`` = k."""
    r = np.asarray(prob.z[:, 0], float)
    var = 0.5 * (float(range_std) ** 2 + (r * float(bearing_std)) ** 2)
    return float(k_sigma) ** 2 * var * 0.5 * (W.Q[0] + W.Q[1])


def gate_labels(points_xy, candidate, landmarks_xy, Q, tau) -> np.ndarray:
    """The c-step with a null value: ``candidate`` where its weighted residual ``‖p_i − m_{c_i}‖²_Q ≤ τ_i``, else
    ``-1``; observations whose candidate is already ``-1`` stay ``-1``."""
    out = np.array(candidate, np.int64, copy=True)
    idx = np.flatnonzero(out >= 0)
    if not idx.size:
        return out
    d = points_xy[idx] - landmarks_xy[out[idx]]
    cost = Q[0] * d[:, 0] ** 2 + Q[1] * d[:, 1] ** 2
    out[idx[cost > tau[idx]]] = -1
    return out


def null_energy(labels, candidate, tau) -> float:
    """``Σ τ_i`` over the observations that have a candidate label but took the null matching."""
    nulled = (np.asarray(candidate) >= 0) & (np.asarray(labels) < 0)
    return float(np.sum(tau[nulled]))
