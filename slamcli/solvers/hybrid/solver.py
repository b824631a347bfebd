"""Hybrid Bayesian/frequentist SLAM (paper 001, Chakravorty & Saha), the ``hybrid`` solver.

Algorithm "Hybrid SLAM" (§II.C), per step t:

1. **Bayesian**: EKF-SLAM on the sparse features (the rows of ``feature_sensor``, with their reported ids)
   forms ``b_t(s, Θ)`` (eq. 21) and, marginalised over the landmarks, the pose belief ``N(μ_t, Σ_t)``. This is
   the project's ``ekf`` solver (``slamcli.solvers.ekf.EkfSlam``, known association, stabilising noise
   ``obs_std_scale = stabilising_scale``, ≈10 in the paper). The EKF does not depend on the grid, so the
   filter runs first over all steps and its per-step marginals are handed to the mapper — the same beliefs
   as interleaving the two parts step by step ("open loop" in the paper's §IV wording).
2. **Frequentist**: the scan of ``scan_sensor`` updates the cells it crosses with estimator E2 (eq. 20),
   the belief represented by ``n_samples`` pose samples (sigma points or random draws) weighted by
   ``p(z|s) b(s)`` (eq. 14), observation matrices from eqs. (32)-(34) under the current map; see
   :mod:`slamcli.solvers.hybrid.frequentist`.
3. **Baseline** (optional, ``baseline = true``): the log-odds occupancy grid of eq. (24) updated from the
   belief *mean*, the "localise first, then map with a Bayesian grid" alternative of §II.D.

Output: EKF poses/covariances/landmarks and ``grids["frequentist"]`` (+ ``grids["logodds"]``) with
``n_snapshots`` snapshots at evenly spaced steps. A dataset without scan rows has nothing to map densely:
the result is then the EKF part alone, without grids, and its message says so.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from slamcli.errors import SolverError
from slamcli.models.occupancy import GridSpec
from slamcli.solvers.base import BaseSolver, params_to_dict
from slamcli.solvers.ekf import EkfParams, EkfSlam
from slamcli.solvers.hybrid.frequentist import (
    ScanGeometry,
    band_for,
    e2_update,
    logodds_update,
    scan_log_likelihood,
    segment_probs,
    sigma_points,
    trace_scan,
)
from slamcli.solvers.hybrid.params import HybridParams
from slamcli.types import Observations, OccupancyGrid, SlamInputs, SolverResult, Status


def grid_for_trajectory(poses_xyt: np.ndarray, reach: float, resolution: float, offset: float) -> GridSpec:
    """Grid covering the trajectory ± ``reach`` m, grid lines at ``(k + offset)·resolution``."""
    lo = poses_xyt[:, :2].min(axis=0) - reach
    hi = poses_xyt[:, :2].max(axis=0) + reach
    o = (np.floor(lo / resolution - offset) + offset) * resolution
    shape = np.ceil((hi - o) / resolution).astype(int)
    return GridSpec((float(o[0]), float(o[1])), float(resolution), (int(shape[1]), int(shape[0])))


def scan_geometry(inputs: SlamInputs, alphas: np.ndarray) -> ScanGeometry:
    """The scanner as the mapper sees it: beam bearings, max range and the dataset's declared noise."""
    return ScanGeometry(alphas=alphas, max_range=float(inputs.max_range), range_std=float(inputs.noise.range_std),
                        bearing_std=float(inputs.noise.bearing_std))


def _select_rows(obs: Observations, mask: np.ndarray, n_poses: int) -> Observations:
    return Observations.from_rows(obs.step[mask], np.column_stack([obs.range_m[mask], obs.bearing_rad[mask]]),
                                  n_poses, reported_id=obs.reported_id[mask], sensor=obs.sensor[mask])


def scan_table(inputs: SlamInputs, scan_sensor: int) -> tuple[np.ndarray, np.ndarray]:
    """The scan as ``(alphas (B,), ranges (T+1, B))``; every step must carry the same B beam bearings."""
    obs = inputs.observations
    sel = np.flatnonzero(np.asarray(obs.sensor) == scan_sensor)
    n_poses = inputs.n_poses
    if len(sel) == 0:
        raise SolverError(f"observations.sensor: no rows of scan sensor {scan_sensor}; the hybrid solver needs "
                          "a range scan (a wall-world dataset, e.g. -s hybrid-map1)")
    counts = np.bincount(obs.step[sel], minlength=n_poses)
    B = int(counts[0])
    if B < 1 or not np.all(counts == B):
        raise SolverError(f"observations: scan sensor {scan_sensor} must give the same number of beams at every "
                          f"step (found {int(counts.min())}..{int(counts.max())})")
    rng_m = obs.range_m[sel].reshape(n_poses, B)
    brg = obs.bearing_rad[sel].reshape(n_poses, B)
    if not np.allclose(brg, brg[0:1], atol=1e-9):
        raise SolverError("observations.bearing_rad: scan beams must use the same nominal bearings every step")
    return brg[0].copy(), rng_m


@dataclass
class MapperOutput:
    """The grids built by :func:`map_scans` (flat ``(H·W,)`` arrays) and per-run statistics."""

    P: np.ndarray  # E2 occupancy probabilities
    count: np.ndarray  # E2 update count per cell
    L: np.ndarray  # log-odds of the baseline (eq. 24)
    count_b: np.ndarray
    snap_steps: np.ndarray
    snaps: list
    snaps_b: list
    n_updated: int  # cell updates summed over the steps
    ess_sum: float  # Σ_t effective sample size of the weights p(z|s)b(s)
    band: int
    samples_kept: int  # Σ_t samples with weight ≥ ``weight_floor`` (the others are dropped before E2)
    clock: np.ndarray | None = None  # the per-cell clock n of γ = a·n^(−α) (``weighted_clock``), else None


def map_scans(mu: np.ndarray, cov: np.ndarray, ranges: np.ndarray, geo: ScanGeometry, spec: GridSpec,
              p: HybridParams, rng: np.random.Generator, progress=None, on_step=None,
              snap_at: np.ndarray | None = None) -> MapperOutput:
    """The frequentist part over all steps: E2 (and the log-odds baseline) from the pose beliefs
    ``N(mu[t], cov[t])`` — ``mu (T+1, 3)``, ``cov (T+1, 3, 3)`` — and the scans ``ranges (T+1, B)``.

    ``progress(done, n)`` after every T/200 steps; ``on_step(t, samples (S, 3), w (S,))`` (diagnostics) with
    the pose samples and their normalised weights ``∝ p(z|s) b(s)``; ``snap_at``: snapshot steps instead of
    ``n_snapshots`` evenly spaced ones (e.g. the lap ends).
    """
    n_poses = len(mu)
    T = n_poses - 1
    B = len(geo.alphas)
    sig_max = float(np.sqrt(geo.range_std**2 + (geo.max_range * geo.bearing_std) ** 2)) if p.bearing_in_range \
        else geo.range_std
    band = band_for(sig_max, p.resolution)
    P = np.full(spec.n_cells, p.prior, float)
    cnt = np.zeros(spec.n_cells, np.int32)
    clock = np.zeros(spec.n_cells) if p.weighted_clock else None
    L = np.full(spec.n_cells, math.log(p.prior / (1 - p.prior)))
    cnt_b = np.zeros(spec.n_cells, np.int32)
    snap_steps = (np.unique(np.round(np.linspace(0, T, p.n_snapshots + 1)[1:]).astype(np.int64)) if snap_at is None
                  else np.unique(np.clip(np.asarray(snap_at, np.int64), 0, T)))
    snaps, snaps_b = [], []
    min_trav = p.min_traversal * p.resolution
    n_upd, ess_sum, kept = 0, 0.0, 0
    report = max(1, n_poses // 200)
    single = p.map_poses != "belief"  # one pose per step: mu itself
    for t in range(n_poses):
        if single:
            samples, w0 = mu[t : t + 1], np.ones(1)
        elif p.samples == "sigma":
            samples, w0 = sigma_points(mu[t], cov[t], p.kappa)
        else:
            samples = rng.multivariate_normal(mu[t], cov[t] + 1e-12 * np.eye(3), size=p.n_samples)
            samples[:, 2] = np.mod(samples[:, 2] + np.pi, 2 * np.pi) - np.pi
            w0 = np.full(p.n_samples, 1.0 / p.n_samples)
        rb = trace_scan(spec, samples, ranges[t], geo, band, p.bearing_in_range)
        P_seg = segment_probs(P, rb)
        ll = scan_log_likelihood(rb, P_seg, geo.max_range, p.outlier_prob,
                                 free_margin=p.free_margin if p.thin_wall_likelihood else 0.0,
                                 resolution=spec.resolution).reshape(len(w0), -1).sum(axis=1)
        lw = np.log(w0) + ll
        w = np.exp(lw - lw.max())
        w /= w.sum()
        ess_sum += 1.0 / float(np.sum(w * w))
        if on_step is not None:
            on_step(t, samples, w)
        # samples whose weight is below the floor change c_i and A_i by less than S·floor: skip their rays
        keep = np.flatnonzero(w >= p.weight_floor)
        kept += len(keep)
        rb_e2 = rb if len(keep) == len(w) else rb.select_samples(keep, B)
        n_upd += e2_update(P, cnt, spec, rb_e2, np.repeat(w[keep], B), mu[t, :2], t + 1, a=p.a, alpha=p.alpha,
                           step_clock=p.step_clock, band=band, min_traversal=min_trav,
                           max_cell_dist=p.max_cell_dist, conditional=p.conditional_a, free_margin=p.free_margin,
                           clock=clock)
        if p.baseline:
            # the belief mean's rays: sigma point 0 is the mean itself
            rb0 = (rb.first_sample(B) if single or p.samples == "sigma"
                   else trace_scan(spec, mu[t : t + 1], ranges[t], geo, band, p.bearing_in_range))
            logodds_update(L, cnt_b, spec, rb0, mu[t, :2], eps=p.outlier_prob, max_range=geo.max_range,
                           min_traversal=min_trav, max_cell_dist=p.max_cell_dist, l_max=p.logodds_clamp,
                           free_margin=p.free_margin)
        if t in snap_steps:
            snaps.append(P.reshape(spec.shape).astype(np.float32))
            if p.baseline:
                snaps_b.append(_prob(L).reshape(spec.shape).astype(np.float32))
        if progress is not None and (t % report == 0 or t == T):
            progress(t + 1, n_poses)
    return MapperOutput(P, cnt, L, cnt_b, snap_steps, snaps, snaps_b, n_upd, ess_sum, band, kept, clock)


class HybridSlam(BaseSolver):
    """Hybrid Bayesian (EKF on features) / frequentist (E2 occupancy grid) SLAM — paper 001."""

    name = "hybrid"
    Params = HybridParams

    def bayesian_part(self, inputs: SlamInputs, rng: np.random.Generator, progress=None) -> SolverResult:
        """The EKF (``solvers.ekf``) on the feature rows alone: its ``poses_xyt``/``pose_cov`` are the beliefs
        ``N(μ_t, Σ_t)`` handed to :func:`map_scans`."""
        p: HybridParams = self.params
        obs = inputs.observations
        feat_mask = np.asarray(obs.sensor) == p.feature_sensor
        f_inputs = dataclasses.replace(inputs, observations=_select_rows(obs, feat_mask, inputs.n_poses))
        assoc_mode = p.association
        if assoc_mode == "auto":
            assoc_mode = "known" if np.any(f_inputs.observations.reported_id >= 0) else "ml"
        # the EKF's earlier defaults (provisional list, grouped returns, new-landmark threshold),
        # spelled out so that hybrid's results do not move with the ekf solver's defaults
        ekf = EkfSlam(EkfParams(association=assoc_mode, motion_input="controls", obs_std_scale=p.stabilising_scale,
                                motion_std_scale=p.motion_std_scale, use_gps=False, provisional=False, size_gate=False,
                                group_returns=False, new_landmark_prob=0.9999))
        return ekf.solve(f_inputs, rng=rng, progress=progress)

    def solve(self, inputs: SlamInputs, *, init=None, rng: np.random.Generator, progress=None) -> SolverResult:
        t_start = time.perf_counter()
        p: HybridParams = self.params
        n_poses = inputs.n_poses
        obs = inputs.observations
        has_scan = bool(np.any(np.asarray(obs.sensor) == p.scan_sensor))
        if has_scan:
            alphas, ranges = scan_table(inputs, p.scan_sensor)  # validates before any work
            if not math.isfinite(inputs.max_range):
                raise SolverError("max_range: the hybrid solver needs a finite sensor max range")
        # the grid covers at least the start pose ± (max range + margin): refuse before any work if even that
        # is too large (the exact extent, from the EKF trajectory, is checked again before the mapping)
        min_side = math.ceil(2 * (inputs.max_range + p.grid_margin) / p.resolution) if has_scan else 0
        if min_side * min_side > p.max_cells:
            raise SolverError(f"resolution={p.resolution}: the grid would have at least {min_side * min_side} cells, "
                              f"more than max_cells={p.max_cells}")
        feat_mask = np.asarray(obs.sensor) == p.feature_sensor
        total = 2 * n_poses

        # ---- Bayesian part: the project's EKF on the feature rows ----
        given = has_scan and p.mapping and p.map_poses == "odometry"  # mapping with given poses: no filter
        ekf_res = None if given else self.bayesian_part(
            inputs, rng, None if progress is None else (lambda d, n: progress(d, total)))
        if ekf_res is not None and ekf_res.status is Status.FAILED:
            return dataclasses.replace(ekf_res, solver=self.name, message=f"EKF part failed: {ekf_res.message}")
        if ekf_res is not None and (not has_scan or not p.mapping):  # the Bayesian part alone, no grids
            why = "mapping = false" if has_scan else f"no rows of scan sensor {p.scan_sensor}"
            return dataclasses.replace(ekf_res, solver=self.name, solver_version=self.version(),
                                       params=params_to_dict(p), wall_time_s=time.perf_counter() - t_start,
                                       assoc=_all_rows(len(obs), feat_mask, ekf_res.assoc),
                                       message=f"{why}: EKF part only, no grid; " + ekf_res.message)
        if ekf_res is None:  # the result's poses are the given ones (no covariance, no landmarks)
            mu, cov = np.asarray(inputs.odometry_xyt, float), np.zeros((n_poses, 3, 3))
        else:
            mu, cov = ekf_res.poses_xyt, ekf_res.pose_cov
        map_mu = np.asarray(inputs.odometry_xyt, float) if p.map_poses == "odometry" else mu

        # ---- the grid (checked before the mapping starts) ----
        spec = grid_for_trajectory(map_mu, inputs.max_range + p.grid_margin, p.resolution, p.grid_offset)
        if spec.n_cells > p.max_cells:
            raise SolverError(f"resolution={p.resolution}: the grid would have {spec.n_cells} cells "
                              f"({spec.shape[0]}x{spec.shape[1]}), more than max_cells={p.max_cells}")
        geo = scan_geometry(inputs, alphas)
        mp = map_scans(map_mu, cov, ranges, geo, spec, p, rng,
                       progress=None if progress is None else (lambda d, n: progress(n_poses + d, total)),
                       snap_at=np.asarray(p.snapshot_steps, np.int64) if p.snapshot_steps else None)
        P, cnt, L, cnt_b, snap_steps, snaps, snaps_b = (mp.P, mp.count, mp.L, mp.count_b, mp.snap_steps, mp.snaps,
                                                       mp.snaps_b)
        n_upd, ess_sum, band = mp.n_updated, mp.ess_sum, mp.band

        origin = np.asarray(spec.origin_xy, float)
        grids = {"frequentist": OccupancyGrid(origin, spec.resolution, P.reshape(spec.shape).astype(np.float32),
                                              cnt.reshape(spec.shape), snap_steps, np.stack(snaps))}
        if p.baseline:
            grids["logodds"] = OccupancyGrid(origin, spec.resolution, _prob(L).reshape(spec.shape).astype(np.float32),
                                             cnt_b.reshape(spec.shape), snap_steps, np.stack(snaps_b))
        assoc = _all_rows(len(obs), feat_mask, None if ekf_res is None else ekf_res.assoc)
        extra = {} if ekf_res is None else dict(ekf_res.extra)
        extra.update({"grid_cells": spec.n_cells, "grid_shape": list(spec.shape), "band": band,
                      "cells_updated_per_step": n_upd / n_poses, "mean_sample_ess": ess_sum / n_poses,
                      "mean_samples_kept": mp.samples_kept / n_poses,
                      "n_beams": int(len(alphas)), "clock_median": _clock_median(mp.clock)})
        res = self.make_result(
            status=Status.COMPLETED, poses_xyt=mu, assoc=assoc, t_start=t_start,
            landmarks_xy=np.zeros((0, 2)) if ekf_res is None else ekf_res.landmarks_xy,
            message=("given odometry poses, no filter" if ekf_res is None else
                     f"EKF on {int(feat_mask.sum())} feature rows") + f"; E2 over {n_poses} scans, grid "
                    f"{spec.shape[0]}x{spec.shape[1]} at {p.resolution} m",
            pose_cov=None if ekf_res is None else cov, landmark_cov=None if ekf_res is None else ekf_res.landmark_cov,
            extra=extra,
        )
        return dataclasses.replace(res, grids=grids)


def _all_rows(n_rows: int, feat_mask: np.ndarray, feat_assoc: np.ndarray | None) -> np.ndarray:
    """The association of every observation row ``(n_rows,)``: the EKF's labels on the feature rows, -1 elsewhere
    (everywhere when ``feat_assoc`` is None)."""
    assoc = np.full(n_rows, -1, np.int64)
    if feat_assoc is not None:
        assoc[np.flatnonzero(feat_mask)] = feat_assoc
    return assoc


def _clock_median(clock: np.ndarray | None) -> float | None:
    """Median of the per-cell clock n of γ = a·n^(−α) over the updated cells (None: no clock or no update)."""
    c = None if clock is None else clock[clock > 0]
    return None if c is None or not len(c) else float(np.median(c))


def _prob(L: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-L))
