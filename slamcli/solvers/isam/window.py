"""The fixed-lag window of the incremental smoother: cached whitened linearisations of the window's factors,
a dense Schur-complement prior on the variables the marginalised part touches, one Gauss-Newton step per
update, relinearisation of the variables that moved past the threshold, and marginalisation of the oldest
keyframe (and of the landmarks no window pose sees any more).

Linear model (``δ`` relative to each variable's linearisation point ``x̄``, world coordinates, θ wrapped)::

    ½ Σ_f ‖J_f δ + r_f‖²  +  ½ δ_Pᵀ H_P δ_P + g_Pᵀ δ_P            H δ = −g  (dense Cholesky)

The prior ``(H_P, g_P)`` is a quadratic in ``δ`` of its variables ``P``; when a variable of ``P`` is
relinearised by ``Δ`` (``x̄ ← x̄ + Δ``) the prior is re-expanded at the new point: ``g_P ← g_P + H_P Δ``.
Marginalising a set ``E`` out of the factors that touch it (and the prior) gives the new prior on the rest
``R``: ``H_R − H_RE H_EE⁻¹ H_ER``, ``g_R − H_RE H_EE⁻¹ g_E`` (Schur complement), at the linearisation points
of that moment (their Jacobians are never recomputed afterwards, as in every fixed-lag smoother).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from slamcli.models import se2
from slamcli.models.angles import wrap_angle
from slamcli.solvers.isam.factors import (
    FactorStore,
    Rows,
    linearize_between,
    linearize_prior,
    linearize_sightings,
)


class Window:
    """State of the smoother: every keyframe and landmark estimate, the active window and its prior."""

    def __init__(self, fs: FactorStore, x0: np.ndarray, robust: str, kernel_k: float, relin: float) -> None:
        self.fs, self.robust, self.kernel_k, self.relin = fs, robust, kernel_k, relin
        self.kf_x, self.kf_lin = Rows((3,)), Rows((3,))
        self.lm_x, self.lm_lin, self.lm_cov = Rows((2,)), Rows((2,)), Rows((2, 2))
        self.lm_active = Rows((), bool)
        self.bt_r, self.bt_J = Rows((3,)), Rows((3, 6))
        self.br_r, self.br_J = Rows((2,)), Rows((2, 5))
        self.w0 = 0
        self.w_br = np.zeros(0, np.int64)  # bearing-range factor ids in the window (sorted by keyframe)
        self.act_lm = np.zeros(0, np.int64)  # active landmark ids
        self.kf_x.extend(x0)
        self.kf_lin.extend(x0)
        r, J = linearize_prior(fs, np.asarray(x0, float))  # the prior on keyframe 0 starts the Schur prior
        self.p_kf, self.p_lm = np.zeros(1, np.int64), np.zeros(0, np.int64)
        self.p_H, self.p_g = J.T @ J, J.T @ r
        self.cf = None

    # -- layout ---------------------------------------------------------------------------------------------
    @property
    def K(self) -> int:
        return self.kf_x.n

    def layout(self):
        """``(n, lm_pos)``: window dimension and the local slot of every landmark (−1 = inactive)."""
        npw = self.K - self.w0
        lm_pos = np.full(self.lm_x.n, -1, np.int64)
        lm_pos[self.act_lm] = np.arange(self.act_lm.size)
        return 3 * npw + 2 * self.act_lm.size, lm_pos

    def pose_cols(self, k: np.ndarray) -> np.ndarray:
        return 3 * (np.asarray(k, np.int64)[:, None] - self.w0) + np.arange(3)

    def lm_cols(self, j: np.ndarray, lm_pos: np.ndarray) -> np.ndarray:
        return 3 * (self.K - self.w0) + 2 * lm_pos[np.asarray(j, np.int64)][:, None] + np.arange(2)

    def prior_cols(self, lm_pos: np.ndarray) -> np.ndarray:
        return np.concatenate([self.pose_cols(self.p_kf).ravel(), self.lm_cols(self.p_lm, lm_pos).ravel()])

    # -- growth ---------------------------------------------------------------------------------------------
    def add_keyframe(self, meas: np.ndarray, cov: np.ndarray) -> int:
        """Append keyframe ``K`` at ``x_{K−1} ⊕ meas`` with its between factor; returns its index."""
        x = se2.compose(self.kf_x.view[-1], meas)
        i = self.fs.add_between(meas, cov)
        self.kf_x.extend(x)
        self.kf_lin.extend(x)
        r, J = linearize_between(self.fs, np.array([i]), self.kf_lin.view)
        self.bt_r.extend(r)
        self.bt_J.extend(J)
        return self.K - 1

    def add_landmarks(self, m: np.ndarray) -> np.ndarray:
        m = np.asarray(m, float).reshape(-1, 2)
        ids = self.lm_x.extend(m)
        self.lm_lin.extend(m)
        self.lm_cov.extend(np.zeros((m.shape[0], 2, 2)))
        self.lm_active.extend(np.ones(m.shape[0], bool))
        self.act_lm = np.concatenate([self.act_lm, ids])
        return ids

    def add_window_sightings(self, ids: np.ndarray) -> None:
        """Linearise the bearing-range factors ``ids`` (active landmarks, newest keyframe) into the window."""
        r, J = linearize_sightings(self.fs, ids, self.kf_lin.view, self.lm_lin.view, self.robust, self.kernel_k)
        self._store_br(ids, r, J)
        self.w_br = np.concatenate([self.w_br, ids])

    def _store_br(self, ids, r, J) -> None:
        while self.br_r.n < self.fs.br_z.n:
            self.br_r.extend(np.zeros((1, 2)))
            self.br_J.extend(np.zeros((1, 2, 5)))
        self.br_r.a[ids], self.br_J.a[ids] = r, J

    # -- the linear system ----------------------------------------------------------------------------------
    def assemble(self, bt_ids=None, br_ids=None, with_prior=True, n_lm_pos=None):
        """Dense ``H (n, n)``, ``g (n,)`` of the window's cached factors (or of the factors given) + prior."""
        n, lm_pos = self.layout() if n_lm_pos is None else n_lm_pos
        bt = np.arange(self.w0, self.K - 1) if bt_ids is None else bt_ids
        br = self.w_br if br_ids is None else br_ids
        idx, vals, gi, gv = [], [], [], []
        if bt.size:
            c = np.concatenate([self.pose_cols(bt), self.pose_cols(bt + 1)], 1)
            J, r = self.bt_J.a[bt], self.bt_r.a[bt]
            idx.append((c[:, :, None] * n + c[:, None, :]).ravel())
            vals.append(np.einsum("fki,fkj->fij", J, J).ravel())
            gi.append(c.ravel())
            gv.append(np.einsum("fki,fk->fi", J, r).ravel())
        if br.size:
            c = np.concatenate([self.pose_cols(self.fs.br_k.a[br]), self.lm_cols(self.fs.br_j.a[br], lm_pos)], 1)
            J, r = self.br_J.a[br], self.br_r.a[br]
            idx.append((c[:, :, None] * n + c[:, None, :]).ravel())
            vals.append(np.einsum("fki,fkj->fij", J, J).ravel())
            gi.append(c.ravel())
            gv.append(np.einsum("fki,fk->fi", J, r).ravel())
        if with_prior and self.p_g.size:
            pc = self.prior_cols(lm_pos)
            idx.append((pc[:, None] * n + pc[None, :]).ravel())
            vals.append(self.p_H.ravel())
            gi.append(pc)
            gv.append(self.p_g)
        H = np.bincount(np.concatenate(idx), np.concatenate(vals), n * n).reshape(n, n) if idx else np.zeros((n, n))
        g = np.bincount(np.concatenate(gi), np.concatenate(gv), n) if gi else np.zeros(n)
        return H, g

    def factorize(self):
        """Assemble and Cholesky-factorise the window system; returns ``(g, lm_pos)``."""
        H, g = self.assemble()
        self.cf = sla.cho_factor(H, lower=False, check_finite=False)
        return g, self.layout()[1]

    def covariance_columns(self, cols: np.ndarray) -> np.ndarray:
        """Columns ``cols`` of ``H⁻¹`` (the window's joint covariance), from the last factorisation."""
        E = np.zeros((self.cf[0].shape[0], cols.size))
        E[cols, np.arange(cols.size)] = 1.0
        return sla.cho_solve(self.cf, E, check_finite=False)

    def step(self) -> None:
        """One Gauss-Newton step of the window, then relinearisation of the variables that moved."""
        g, lm_pos = self.factorize()
        d = sla.cho_solve(self.cf, -g, check_finite=False)
        npw = self.K - self.w0
        dp = d[: 3 * npw].reshape(-1, 3)
        dl = d[3 * npw :].reshape(-1, 2)
        kf = np.arange(self.w0, self.K)
        self.kf_x.a[kf] = self.kf_lin.a[kf] + dp
        self.kf_x.a[kf, 2] = wrap_angle(self.kf_x.a[kf, 2])
        self.lm_x.a[self.act_lm] = self.lm_lin.a[self.act_lm] + dl
        moved_kf = kf[np.max(np.abs(dp), axis=1) > self.relin]
        moved_lm = self.act_lm[np.max(np.abs(dl), axis=1) > self.relin] if dl.size else np.zeros(0, np.int64)
        if moved_kf.size or moved_lm.size:
            self.relinearize(moved_kf, moved_lm, lm_pos, d)

    def relinearize(self, kf: np.ndarray, lm: np.ndarray, lm_pos: np.ndarray, d: np.ndarray) -> None:
        """Move the linearisation points of keyframes ``kf`` and landmarks ``lm`` to their estimates,
        re-expand the prior there and recompute the Jacobians of every window factor that touches them."""
        pc = self.prior_cols(lm_pos)
        moved = np.zeros(d.size, bool)
        moved[self.pose_cols(kf).ravel()] = True
        if lm.size:
            moved[self.lm_cols(lm, lm_pos).ravel()] = True
        shift = np.where(moved[pc], d[pc], 0.0)
        self.p_g = self.p_g + self.p_H @ shift
        self.kf_lin.a[kf] = self.kf_x.a[kf]
        self.lm_lin.a[lm] = self.lm_x.a[lm]
        kf_mask = np.zeros(self.K + 1, bool)
        kf_mask[kf] = True
        bt = np.arange(self.w0, self.K - 1)
        bt = bt[kf_mask[bt] | kf_mask[bt + 1]]
        if bt.size:
            self.bt_r.a[bt], self.bt_J.a[bt] = linearize_between(self.fs, bt, self.kf_lin.view)
        lm_mask = np.zeros(self.lm_x.n, bool)
        lm_mask[lm] = True
        br = self.w_br[kf_mask[self.fs.br_k.a[self.w_br]] | lm_mask[self.fs.br_j.a[self.w_br]]]
        if br.size:
            r, J = linearize_sightings(self.fs, br, self.kf_lin.view, self.lm_lin.view, self.robust, self.kernel_k)
            self._store_br(br, r, J)

    # -- marginalisation ------------------------------------------------------------------------------------
    def marginalize_oldest(self) -> None:
        """Marginalise keyframe ``w0`` and the landmarks that only its sightings kept in the window."""
        p = self.w0
        n, lm_pos = self.layout()
        own = self.fs.br_k.a[self.w_br] == p
        br_p, br_rest = self.w_br[own], self.w_br[~own]
        js = np.unique(self.fs.br_j.a[br_p])
        still = np.zeros(self.lm_x.n, bool)
        still[self.fs.br_j.a[br_rest]] = True
        drop = js[~still[js]]
        if drop.size:  # frozen marginals of the dropped landmarks, for the association
            C = self.covariance_columns(self.lm_cols(drop, lm_pos).ravel())
            rows = self.lm_cols(drop, lm_pos)
            for i, j in enumerate(drop):
                self.lm_cov.a[j] = C[rows[i], 2 * i : 2 * i + 2]
        H, g = self.assemble(np.array([p]) if p < self.K - 1 else np.zeros(0, np.int64), br_p, True, (n, lm_pos))
        kf_keep = np.union1d(self.p_kf[self.p_kf != p], [p + 1] if p + 1 < self.K else [])
        lm_keep = np.setdiff1d(np.union1d(self.p_lm, js), drop)
        keep = np.concatenate([self.pose_cols(kf_keep.astype(np.int64)).ravel(),
                               self.lm_cols(lm_keep, lm_pos).ravel()])
        elim = np.concatenate([self.pose_cols(np.array([p])).ravel(), self.lm_cols(drop, lm_pos).ravel()])
        Hee = H[np.ix_(elim, elim)]
        Hke = H[np.ix_(keep, elim)]
        cf = sla.cho_factor(Hee, check_finite=False)
        X = sla.cho_solve(cf, np.column_stack([Hke.T, g[elim]]), check_finite=False)
        self.p_H = H[np.ix_(keep, keep)] - Hke @ X[:, :-1]
        self.p_H = 0.5 * (self.p_H + self.p_H.T)
        self.p_g = g[keep] - Hke @ X[:, -1]
        self.p_kf, self.p_lm = kf_keep.astype(np.int64), lm_keep
        self.w_br = br_rest
        self.w0 = p + 1
        self.lm_active.a[drop] = False
        self.act_lm = self.act_lm[~np.isin(self.act_lm, drop)]

    def reactivate(self, lm: np.ndarray) -> None:
        """Bring marginalised landmarks ``lm`` back into the window, at their frozen estimates, with their
        frozen marginals ``N(μ_j, P_j)`` appended to the prior (an approximation: the sightings behind ``P_j``
        also informed the poses through the prior; the next batch step rebuilds the prior from the factors)."""
        lm = np.asarray(lm, np.int64)
        self.lm_active.a[lm] = True
        self.act_lm = np.concatenate([self.act_lm, lm])
        self.lm_lin.a[lm] = self.lm_x.a[lm]
        n0, k = self.p_g.size, 2 * lm.size
        H = np.zeros((n0 + k, n0 + k))
        H[:n0, :n0] = self.p_H
        for i, j in enumerate(lm):
            H[n0 + 2 * i : n0 + 2 * i + 2, n0 + 2 * i : n0 + 2 * i + 2] = np.linalg.inv(self.lm_cov.a[j])
        self.p_H, self.p_g = H, np.concatenate([self.p_g, np.zeros(k)])
        self.p_lm = np.concatenate([self.p_lm, lm])

    def set_prior(self, kf: np.ndarray, lm: np.ndarray, H: np.ndarray, g: np.ndarray) -> None:
        self.p_kf, self.p_lm, self.p_H, self.p_g = kf, lm, H, g

    def relinearize_all(self) -> None:
        """Linearisation point = estimate for every window variable; recompute every window Jacobian."""
        kf = np.arange(self.w0, self.K)
        self.kf_lin.a[kf] = self.kf_x.a[kf]
        self.lm_lin.a[self.act_lm] = self.lm_x.a[self.act_lm]
        bt = np.arange(self.w0, self.K - 1)
        if bt.size:
            self.bt_r.a[bt], self.bt_J.a[bt] = linearize_between(self.fs, bt, self.kf_lin.view)
        if self.w_br.size:
            r, J = linearize_sightings(self.fs, self.w_br, self.kf_lin.view, self.lm_lin.view, self.robust,
                                       self.kernel_k)
            self._store_br(self.w_br, r, J)
