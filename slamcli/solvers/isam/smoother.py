"""The update loop of the incremental smoother (:class:`IncrementalSmoother`): one update per keyframe —
new pose and odometry factor, association against the current estimate, sightings into the window (or, for a
marginalised landmark, into the store until the next batch step), one window step, marginalisation of what
left the lag, and the periodic batch step.
"""

from __future__ import annotations

import time

import numpy as np

from slamcli.models import observation, se2
from slamcli.solvers import frontend, nls
from slamcli.solvers.isam.associate import CANDIDATE_MARGIN_M, detections, gate_and_match
from slamcli.solvers.isam.factors import FactorStore, keyframe_odometry, keyframe_problem
from slamcli.solvers.isam.params import IsamParams
from slamcli.solvers.isam.window import Window
from slamcli.types import SlamInputs

#: σ of the prior on keyframe 0 (m, m, rad): graph's default prior_std
PRIOR_STD = (1e-4, 1e-4, 1e-4)


class IncrementalSmoother:
    """Runs the smoother over ``inputs`` (see :mod:`slamcli.solvers.isam`). ``association`` is ``reported`` or
    ``nn``; ``robust`` the kernel on the sightings with scale ``kernel_k``.

    After :meth:`run`: ``poses()`` ``(T+1, 3)``, ``landmarks()`` ``(L, 2)``, ``assoc (N,)``, and the
    bookkeeping ``step_cpu`` (CPU seconds of every update), ``n_batches``, ``n_deferred``, ``n_relinearized``.
    """

    def __init__(self, inputs: SlamInputs, params: IsamParams, association: str, robust: str, kernel_k: float):
        self.inputs, self.p, self.mode = inputs, params, association
        self.robust, self.kernel_k = robust, kernel_k
        obs = inputs.observations
        T = inputs.n_poses - 1
        steps = np.unique(np.concatenate([[0, T], np.asarray(obs.step, np.int64)]))
        self.kf_steps = steps
        self.kf_meas, self.kf_cov = keyframe_odometry(inputs.odometry_xyt, steps, inputs.noise.odometry_std)
        self.fs = FactorStore(inputs.x0, PRIOR_STD, inputs.noise.obs_cov)
        self.win = Window(self.fs, np.asarray(inputs.x0, float), robust, kernel_k, params.relin_threshold)
        self.assoc = np.full(len(obs), -1, np.int64)
        self.reported = frontend.associate_reported(obs) if association == "reported" else None
        self.thr = frontend.gate_threshold(params.gate_prob)
        self.R = np.asarray(inputs.noise.obs_cov, float)
        self.step_cpu: list[float] = []
        self.n_batches = 0
        self.n_deferred = 0
        self.n_reactivated = 0
        self.batch_cpu = 0.0  # CPU s spent in batch steps
        self.batch_updates: list[int] = []  # updates that ended with a batch step
        self.pending = False
        self.t_batch = float(inputs.timestamps[0])

    # -- loop -----------------------------------------------------------------------------------------------
    def run(self, progress=None) -> IncrementalSmoother:
        n = self.kf_steps.size
        for i in range(n):
            c0 = time.process_time()
            self.update(i)
            self.step_cpu.append(time.process_time() - c0)
            if progress is not None and (i % 200 == 0 or i == n - 1):
                progress(i + 1, n)
        if self.pending or self.p.end_batch:
            self.batch_step()
        return self

    def update(self, i: int) -> None:
        """Keyframe ``i``: add it, associate its rows, one window step, marginalise, maybe a batch step."""
        w, t = self.win, int(self.kf_steps[i])
        if i > 0:
            w.add_keyframe(self.kf_meas[i - 1], self.kf_cov[i - 1])
        rows = self.inputs.observations.at(t)
        if rows.stop > rows.start:
            self._sightings(i, rows)
        for _ in range(self.p.iterations):
            w.step()
        ts = self.inputs.timestamps
        while w.K - w.w0 > 2 and ts[self.kf_steps[w.K - 1]] - ts[self.kf_steps[w.w0]] > self.p.lag_s:
            w.marginalize_oldest()
        now = float(ts[t])
        if self.pending and now - self.t_batch >= self.p.batch_every_s:
            self.batch_updates.append(i)
            self.batch_step()
            self.t_batch = now

    # -- association ----------------------------------------------------------------------------------------
    def _sightings(self, k: int, rows: slice) -> None:
        """Detections of keyframe ``k`` (rows ``rows``) → labels → bearing-range factors."""
        w = self.win
        z_rows = self.inputs.observations.z[rows]
        if self.reported is not None:
            lab_rows = self.reported[rows]
            ok = lab_rows >= 0
            if not ok.any():
                return
            labels, seg = np.unique(lab_rows[ok], return_inverse=True)
            cnt = np.bincount(seg).astype(float)
            zr = np.bincount(seg, z_rows[ok, 0]) / cnt
            zb = np.arctan2(np.bincount(seg, np.sin(z_rows[ok, 1])), np.bincount(seg, np.cos(z_rows[ok, 1])))
            z = np.stack([zr, zb], -1)
            new = labels[labels >= w.lm_x.n]
            if new.size:
                w.add_landmarks(observation.inverse_range_bearing(np.broadcast_to(w.kf_x.a[k], (new.size, 3)),
                                                                  z[labels >= w.lm_x.n]))
            self.assoc[rows] = lab_rows
        else:
            seg, z = detections(w.kf_x.a[k], z_rows, self.p.segment_dist)
            labels = self._gate(k, z)
            fresh = labels < 0
            if fresh.any():
                labels[fresh] = w.add_landmarks(observation.inverse_range_bearing(
                    np.broadcast_to(w.kf_x.a[k], (int(fresh.sum()), 3)), z[fresh]))
            self.assoc[rows] = labels[seg]
        ids = self.fs.add_sightings(k, labels, z)
        act = w.lm_active.a[labels]
        if self.p.reactivate and not act.all():
            w.reactivate(labels[~act])
            self.pending = True
            self.n_reactivated += int((~act).sum())
            act = w.lm_active.a[labels]
        if act.any():
            w.add_window_sightings(ids[act])
        if not act.all():
            self.pending = True
            self.n_deferred += int((~act).sum())

    def _gate(self, k: int, z: np.ndarray) -> np.ndarray:
        """Nearest-neighbour labels of detections ``z`` at keyframe ``k`` (−1 = new landmark)."""
        w = self.win
        L = w.lm_x.n
        if L == 0:
            return np.full(z.shape[0], -1, np.int64)
        pose = w.kf_x.a[k]
        dist = np.linalg.norm(w.lm_x.view - pose[:2], axis=1)
        cand = np.flatnonzero(dist <= z[:, 0].max() + CANDIDATE_MARGIN_M)
        if not cand.size:
            return np.full(z.shape[0], -1, np.int64)
        _, lm_pos = w.factorize()
        act = w.lm_active.a[cand]
        pc = w.pose_cols(np.array([k]))[0]
        ca = cand[act]
        cols = np.concatenate([pc, w.lm_cols(ca, lm_pos).ravel()])
        C = w.covariance_columns(cols)  # (n, 3 + 2a)
        cov_xx = C[pc, :3]
        cov_xm = np.zeros((cand.size, 3, 2))
        cov_mm = w.lm_cov.a[cand].copy()
        if ca.size:
            blk = C[:, 3:].reshape(-1, ca.size, 2)  # (n, a, 2)
            cov_xm[act] = np.transpose(blk[pc], (1, 0, 2))
            cov_mm[act] = blk[w.lm_cols(ca, lm_pos), np.arange(ca.size)[:, None]]
        return gate_and_match(pose, z, cand, w.lm_x.a[cand], cov_xx, cov_xm, cov_mm, self.R, self.thr)

    # -- batch step -----------------------------------------------------------------------------------------
    def batch_step(self) -> None:
        """LM over the whole keyframe graph from the current estimate, then the window is rebuilt: its
        factors relinearised at the new estimate and its prior the Schur complement of every other factor."""
        c0 = time.process_time()
        w, fs = self.win, self.fs
        K, L = w.K, w.lm_x.n
        prob = keyframe_problem(fs, K, L, np.arange(K - 1), np.arange(fs.br_z.n), True)
        x = np.concatenate([w.kf_x.view.ravel(), w.lm_x.view.ravel()])
        nparams = nls.NlsParams(max_iterations=self.p.batch_iterations, robust=self.robust, huber_k=self.kernel_k,
                                pose_chart="world", rel_cost_tol=1e-6)
        res = nls.solve(prob, x, nparams)
        x = res.x
        w.kf_x.a[:K] = x[: 3 * K].reshape(-1, 3)
        w.lm_x.a[:L] = x[3 * K :].reshape(-1, 2)
        self._rebuild(x, nparams)
        self.pending = False
        self.n_batches += 1
        self.batch_cpu += time.process_time() - c0

    def _rebuild(self, x: np.ndarray, nparams: nls.NlsParams) -> None:
        w, fs = self.win, self.fs
        K, L, w0 = w.K, w.lm_x.n, w.w0
        br = np.arange(fs.br_z.n)
        in_win = fs.br_k.view >= w0
        w.w_br = br[in_win]
        w.act_lm = np.unique(fs.br_j.view[w.w_br])
        w.lm_active.a[:L] = False
        w.lm_active.a[w.act_lm] = True
        rest = keyframe_problem(fs, K, L, np.arange(w0), br[~in_win], True)
        asm = nls.Assembler(rest)
        _, data, g = asm.linearize(x, nparams)
        H = asm.matrix(data).tocsc()
        p_lm = np.intersect1d(w.act_lm, fs.br_j.view[br[~in_win]])
        a_cols = np.concatenate([3 * w0 + np.arange(3), 3 * K + 2 * p_lm[:, None].repeat(2, 1).ravel()
                                 + np.tile(np.arange(2), p_lm.size)])
        is_a = np.zeros(rest.n_vars, bool)
        is_a[3 * w0 :] = True  # the whole window is kept (only a_cols carry the prior)
        is_a[3 * K :] = False
        is_a[3 * K + 2 * np.repeat(w.act_lm, 2) + np.tile(np.arange(2), w.act_lm.size)] = True
        o_cols = np.flatnonzero(~is_a)
        S = H[a_cols][:, a_cols].toarray()
        gS = g[a_cols].copy()
        if o_cols.size:
            lu = nls.factorize_symmetric(H[o_cols][:, o_cols].tocsc())
            Hoa = H[o_cols][:, a_cols].toarray()
            X = lu.solve(np.column_stack([Hoa, g[o_cols]]))
            S -= Hoa.T @ X[:, :-1]
            gS -= Hoa.T @ X[:, -1]
        w.set_prior(np.array([w0], np.int64), p_lm, 0.5 * (S + S.T), gS)
        w.relinearize_all()

    # -- output ---------------------------------------------------------------------------------------------
    def poses(self) -> np.ndarray:
        """All ``T+1`` poses: keyframes as estimated, the others by odometry from the previous keyframe."""
        odo = np.asarray(self.inputs.odometry_xyt, float)
        T1 = odo.shape[0]
        k = np.searchsorted(self.kf_steps, np.arange(T1), side="right") - 1
        rel = se2.between(odo[self.kf_steps[k]], odo)
        return se2.compose(self.win.kf_x.view[k], rel)

    def landmarks(self) -> np.ndarray:
        return self.win.lm_x.view.copy()
