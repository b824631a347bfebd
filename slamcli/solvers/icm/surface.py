"""Surface-aware observations for ICM-SLAM (beyond paper 000): laser returns hit the surface of a disc landmark.

The paper's h⁻¹(x, z) = p + r·u (u = [cos(θ + b), sin(θ + b)]) puts every return on the centre; a beam meeting
a disc of radius ρ at lateral offset s stops q = √(ρ² − s²) short (:mod:`slamcli.models.observation`), so the
paper-exact map points lie π/4 · ρ nearer the robot on average and drag the poses with them.

``surface=true`` replaces each range r_i by r_i + δ_i before h⁻¹: δ_i = π/4 · ρ_i in the on-line init (no map
yet); before each sweep's c-step δ_i = √(ρ_i² − s_i²) from the current pose and the label's map point (π/4 · ρ_i
without a label), held fixed during the sweep so it minimises an energy of the paper's form (eq. 5).
ρ_i = diameter_m / 2 as the dataset declares it (``inputs/observations/diameter_m``).

``range_bias="estimate"`` adds a node, a common range bias b, visited before the c-step, in closed form::

    b* = Σ_i u_iᵀ Q (m_{c_i} − p_i − (r_i + δ_i) u_i) / Σ_i u_iᵀ Q u_i        (labelled returns i)

Without a declared radius it estimates the whole surface offset, but the init has then already placed the
map with biased ranges (measured: benchmarks/results/design_notes.md).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from slamcli.models.observation import mean_surface_offset, surface_centre_offset
from slamcli.solvers.icm import energy as en
from slamcli.solvers.surface import declared_radius  # noqa: F401 - re-exported for ICM's callers


def with_range_offsets(prob: en.Problem, base_z: np.ndarray, offsets: np.ndarray) -> en.Problem:
    """``prob`` with ranges ``base_z[:, 0] + offsets (N,)`` (and the matching robot-frame points ``v_body``)."""
    z = np.column_stack([base_z[:, 0] + offsets, base_z[:, 1]])
    v = np.stack([z[:, 0] * np.cos(z[:, 1]), z[:, 0] * np.sin(z[:, 1])], -1)
    return dataclasses.replace(prob, z=z, v_body=v)


def initial_offsets(rho: np.ndarray | None, n_obs: int) -> np.ndarray:
    """δ_i of the on-line init: π/4 · ρ_i (zeros without a declared radius)."""
    return np.zeros(n_obs) if rho is None else mean_surface_offset(rho)


def surface_offsets(prob: en.Problem, base_z, rho, poses, landmarks, labels) -> np.ndarray:
    """δ_i = √(ρ_i² − s_i²) ``(N,)`` of each labelled return from its current pose and map point; π/4 · ρ_i for a
    return without a label (or a map point the beam misses: then 0, the grazing limit)."""
    delta = mean_surface_offset(rho).copy()
    ok = (labels >= 0) & (labels < landmarks.shape[0])
    if ok.any():
        x = poses[prob.step[ok]]
        delta[ok] = surface_centre_offset(x, landmarks[labels[ok]], base_z[ok, 1], rho[ok])
    return delta


def range_bias_mode(prob: en.Problem, W: en.Weights, poses, landmarks, labels) -> float:
    """b*, the conditional mode of a common range bias added to ``prob``'s ranges (see the module docstring)."""
    ok = (labels >= 0) & (labels < landmarks.shape[0])
    if not ok.any():
        return 0.0
    x = poses[prob.step[ok]]
    phi = x[:, 2] + prob.z[ok, 1]
    u = np.stack([np.cos(phi), np.sin(phi)], -1)
    q = np.asarray(W.Q, float)
    q = np.full(2, q[0]) if q.size == 1 else q[:2]
    resid = landmarks[labels[ok]] - x[:, :2] - prob.z[ok, :1] * u
    den = float(((u * u) * q).sum())
    return float(((u * resid) * q).sum() / den) if den > 0 else 0.0


def refresh(prob: en.Problem, base_z, rho, bias: float, estimate_bias: bool, W, poses, landmarks, labels):
    """The sweep's observation model: surface offsets from the current estimate (when ``rho`` is given), then
    the range-bias node (when ``estimate_bias``). Returns ``(problem, bias)``."""
    delta = np.zeros(prob.n_obs) if rho is None else surface_offsets(prob, base_z, rho, poses, landmarks, labels)
    out = with_range_offsets(prob, base_z, delta + bias)
    if estimate_bias:
        bias = bias + range_bias_mode(out, W, poses, landmarks, labels)
        out = with_range_offsets(prob, base_z, delta + bias)
    return out, bias
