"""ICM on real recordings (issue 22 item 3): the gated init's χ² gate, the label merge, the cost per landmark,
the joint refinement and preset=real — each against a hand-built case, a closed form or the simulator's truth."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from slamcli.params import param_docs
from slamcli.sim import simulate_scenario
from slamcli.solvers.icm import IcmParams
from slamcli.solvers.icm import energy as en
from slamcli.solvers.icm.init_gated import _associate, _LabelIndex, chi2_2dof, gated_init, sighting_cov
from slamcli.solvers.icm.joint import joint_refine
from slamcli.solvers.icm.merge import label_covariances, merge_labels
from slamcli.solvers.icm.presets import PRESETS, expansion_text


def test_chi2_quantile_closed_form():
    # χ²₂ CDF is 1 − exp(−x/2): the 0.99 quantile is 2 ln 100 = 9.2103…
    assert chi2_2dof(0.99) == pytest.approx(2 * math.log(100.0), rel=1e-14)
    assert chi2_2dof(0.9999) == pytest.approx(18.420680743952367, rel=1e-12)


def _two_landmark_index():
    """Labels at (0, 0) and (3, 0), each seen 4 times, first-sight covariances diag(0.04, 0.04) and
    diag(0.25, 0.01)."""
    idx = _LabelIndex(10)
    idx.new(np.array([0.0, 0.0]), np.diag([0.04, 0.04]))
    idx.new(np.array([3.0, 0.0]), np.diag([0.25, 0.01]))
    for _ in range(3):
        idx.add(0, np.array([0.0, 0.0]))
        idx.add(1, np.array([3.0, 0.0]))
    return idx


def test_gate_two_landmarks_hand_built():
    idx = _two_landmark_index()
    # the sighting's own covariance: isotropic 0.01 m², the pose adds diag(0.05, 0.05) in J P Jᵀ
    Sz = np.tile(np.diag([0.01, 0.01]), (4, 1, 1))
    JPJ = np.tile(np.diag([0.05, 0.05]), (4, 1, 1))
    pts = np.array([[0.5, 0.0],   # label 0: S = 0.05 + 0.01·(1 + 1/4) + 0.04 = 0.1025 → d² = 0.25 / 0.1025
                    [3.0, 0.9],   # label 1: S_yy = 0.05 + 0.0125 + 0.01 = 0.0725 → d² = 0.81 / 0.0725 = 11.17
                    [1.5, 5.0],   # far from both: d² > 18.4 → a birth
                    [2.0, 0.0]])  # label 1 along x: S_xx = 0.3125 → d² = 1 / 0.3125 = 3.2 (label 0: 4 / 0.1025)
    match, d2 = _associate(idx, pts, Sz, JPJ, chi2_2dof(0.99), chi2_2dof(0.9999))
    assert d2[0] == pytest.approx(0.25 / 0.1025, rel=1e-12)
    assert d2[1] == pytest.approx(0.81 / 0.0725, rel=1e-12)
    assert d2[3] == pytest.approx(1.0 / 0.3125, rel=1e-12)
    # 11.17 is above the 9.21 gate and below the 18.4 birth threshold: ambiguous, left unlabelled
    assert match.tolist() == [0, -1, -2, 1]


def test_gate_one_label_per_scan():
    idx = _two_landmark_index()
    Sz = np.tile(np.diag([0.01, 0.01]), (2, 1, 1))
    JPJ = np.tile(np.diag([0.05, 0.05]), (2, 1, 1))
    # two sightings both within the gate of label 0: the nearer one gets it, the other is not matched to it
    match, _ = _associate(idx, np.array([[0.1, 0.0], [0.4, 0.0]]), Sz, JPJ, chi2_2dof(0.99), chi2_2dof(0.9999))
    assert match[0] == 0 and match[1] != 0


def test_sighting_cov_closed_form():
    # beam along +y (θ = π/2, b = 0): σ_r along y, r σ_b along x
    c = sighting_cov(math.pi / 2, np.array([[10.0, 0.0]]), 0.1, 0.01)[0]
    assert c == pytest.approx(np.diag([(10 * 0.01) ** 2, 0.01]), abs=1e-15)


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.slow
def test_merge_never_joins_two_true_landmarks_on_loop(seed):
    ds = simulate_scenario("loop", seed=seed)
    inp, truth = ds.inputs, ds.truth
    prob = en.Problem.from_inputs(inp)
    poses, _, _, _, _ = gated_init(prob, inp, gate_prob=0.99, birth_prob=0.9999)
    true = np.asarray(truth.obs_landmark, np.int64)
    # labels = the true landmarks, each split in two by time (first / second half of its sightings): the merge
    # must join every split pair back and never two different true landmarks
    order = np.argsort(prob.step, kind="stable")
    split = np.empty_like(true)
    for k in np.unique(true[true >= 0]):
        i = order[true[order] == k]
        split[i] = 2 * k + (np.arange(i.size) >= i.size // 2)
    split[true < 0] = -1
    pts = prob.landmark_points(poses)
    L = int(split.max()) + 1
    means = np.array([pts[split == j].mean(0) if np.any(split == j) else [np.nan, np.nan] for j in range(L)])
    keep = ~np.isnan(means[:, 0])
    remap = np.cumsum(keep) - 1
    labels = np.where(split >= 0, remap[np.maximum(split, 0)], -1)
    lm = means[keep]
    cov, _ = label_covariances(prob.step, prob.z, poses, labels, lm.shape[0], inp.noise.range_std,
                               inp.noise.bearing_std)
    merged, _, _ = merge_labels(lm, labels, prob.step, cov, merge_prob=0.999)
    for j in np.unique(merged[merged >= 0]):
        assert np.unique(true[merged == j]).size == 1, f"seed {seed}: label {j} joins true landmarks"


def test_merge_joins_a_split_landmark_and_respects_scans():
    rng = np.random.default_rng(0)
    pts = rng.normal([2.0, 1.0], 0.05, (20, 2))
    step = np.arange(20)
    labels = (np.arange(20) >= 10).astype(np.int64)  # one landmark split in two halves
    lm = np.array([pts[:10].mean(0), pts[10:].mean(0)])
    cov = np.tile(np.eye(2) * 0.05**2 / 10, (2, 1, 1))
    merged, k, _ = merge_labels(lm, labels, step, cov, merge_prob=0.999)
    assert k == 1 and np.all(merged == 0)
    step2 = step.copy()
    step2[10] = 0  # a sighting of each half in the same scan: two landmarks, never merged
    merged, k, _ = merge_labels(lm, labels, step2, cov, merge_prob=0.999)
    assert k == 0 and merged.tolist() == labels.tolist()


def test_label_cost_prefers_the_true_map_on_a_toy():
    """One landmark seen 12 times with σ = 0.1 m; the split map gives each half its own label. The paper's
    energy prefers the split map (each half fits its own sightings); with λ = χ²₂(0.999) per label and
    Q = Σ⁻¹ the true map is lower. Energies by hand (brute-force sums), and the closed form of the merge cost."""
    rng = np.random.default_rng(1)
    sigma = 0.1
    pts = rng.normal([5.0, -2.0], sigma, (12, 2))
    q = 1.0 / sigma**2

    def obs_energy(groups):
        return sum(q * float(((g - g.mean(0)) ** 2).sum()) for g in groups)

    lam = chi2_2dof(0.999)
    e_true, e_split = obs_energy([pts]), obs_energy([pts[:6], pts[6:]])
    assert e_split < e_true  # Φ_m without a per-landmark cost: the fragmented map is lower
    assert e_true + lam * 1 < e_split + lam * 2
    d = pts[:6].mean(0) - pts[6:].mean(0)
    assert e_true - e_split == pytest.approx(6 * 6 / 12 * q * float(d @ d), rel=1e-12)


@pytest.mark.slow
def test_joint_refine_reaches_a_stationary_point():
    """After the refinement the finite-difference gradient of the energy (independent of the Jacobian) is
    negligible against its value at the start."""
    ds = simulate_scenario("loop", seed=2)
    inp = ds.inputs
    prob = en.Problem.from_inputs(inp)
    W = en.Weights.from_params((1.0,), (0.0,), (1.0,))
    poses, labels, lm, _, _ = gated_init(prob, inp, gate_prob=0.99, birth_prob=0.9999)
    labels = np.where(labels >= 0, labels, 0)

    def fd_grad(p, m, h=1e-6):
        vec = en.pack(p, m)
        g = np.zeros(vec.size)
        for k in range(0, vec.size, max(1, vec.size // 60)):  # a spread of coordinates, poses and map
            e = np.zeros(vec.size)
            e[k] = h
            a = en.energy(prob, W, *en.unpack(prob, vec + e, m.shape[0]), labels)
            b = en.energy(prob, W, *en.unpack(prob, vec - e, m.shape[0]), labels)
            g[k] = (a - b) / (2 * h)
        return np.abs(g).max()

    g0 = fd_grad(poses, lm)
    p1, m1, out = joint_refine(prob, W, poses, lm, labels, max_iters=30, step_tol=1e-7)
    assert out.steps >= 1 and out.energy <= en.energy(prob, W, poses, lm, labels)
    assert fd_grad(p1, m1) < 1e-4 * g0


def test_preset_real_expansion_and_overrides():
    p = IcmParams.real()
    for k, v in PRESETS["real"].items():
        assert getattr(p, k) == v
    assert p.preset == "real" and IcmParams.paper() == IcmParams()
    assert IcmParams.real(weights="information").weights == "information"
    assert IcmParams.real(max_sweeps=9).max_sweeps == 9
    # a key given explicitly keeps its value even when that value is the paper default
    assert IcmParams.real(accelerate="none").accelerate == "none"
    assert IcmParams.real(merge=False, init="online").merge is False
    # the paper default stays the default
    base = IcmParams()
    defaults = {f.name: f.default for f in dataclasses.fields(IcmParams)}
    assert all(getattr(base, k) == defaults[k] for k in defaults)
    # the parameter doc lists the same expansion as the preset table
    doc = " ".join(param_docs(IcmParams)["preset"][1].split())
    assert expansion_text("real") in doc


def test_gated_init_reported_ids_and_refusals():
    ds = simulate_scenario("loop", seed=0)
    inp = ds.inputs
    prob = en.Problem.from_inputs(inp)
    fixed = np.asarray(ds.truth.obs_landmark, np.int64)
    _, labels, lm, _, covs = gated_init(prob, inp, gate_prob=0.99, birth_prob=0.9999, fixed_labels=fixed)
    assert labels.tolist() == fixed.tolist() and lm.shape == (12, 2)
    assert np.all(np.linalg.eigvalsh(covs[1:]) > 0)
    bad = dataclasses.replace(inp, noise=dataclasses.replace(inp.noise, motion_std=np.array([0.0, 0.1])))
    with pytest.raises(ValueError, match="noise.motion_std"):
        gated_init(prob, bad, gate_prob=0.99, birth_prob=0.9999)


# ---- null matching behind a k σ gate (solvers/icm/gate.py) and preset=real's rule for data with ids ----------
def test_null_cost_closed_form():
    from types import SimpleNamespace

    from slamcli.solvers.icm.gate import null_costs

    prob = SimpleNamespace(z=np.array([[2.0, 0.1], [10.0, -0.3]]))
    W = en.Weights.from_params((1.0,), (0.0,), (3.0, 5.0))
    tau = null_costs(prob, W, 0.1, 0.02, 7.0)
    # τ = k² · (σ_r² + r² σ_b²) / 2 · mean(Q): r = 2 → 49 · (0.01 + 0.0016) / 2 · 4; r = 10 → 49 · 0.05 / 2 · 4
    assert tau == pytest.approx([49 * 0.0116 / 2 * 4, 49 * 0.05 / 2 * 4], rel=1e-14)


def test_gate_labels_hand_built():
    from slamcli.solvers.icm.gate import gate_labels, null_energy

    lm = np.array([[0.0, 0.0], [5.0, 0.0]])
    pts = np.array([[0.3, 0.4], [5.0, 1.1], [9.0, 9.0], [0.0, 0.9]])
    cand = np.array([0, 1, -1, 0])
    tau = np.full(4, 2.0)
    # Q = diag(2, 2): costs 2·0.25 = 0.5 (keep), 2·1.21 = 2.42 (null), no candidate, 2·0.81 = 1.62 (keep)
    lab = gate_labels(pts, cand, lm, (2.0, 2.0), tau)
    assert lab.tolist() == [0, -1, -1, 0]
    assert null_energy(lab, cand, tau) == 2.0  # only the nulled observation with a candidate pays τ


def _loop_with_ids_and_outliers(seed: int, n_out: int):
    """``loop`` with the true landmarks as sensor-reported ids and ``n_out`` sightings moved 3 m along their beam
    (a misread: far beyond any noise), and the indices of the moved sightings."""
    ds = simulate_scenario("loop", seed=seed)
    inp = ds.inputs
    obs = inp.observations
    bad = np.random.default_rng(seed).choice(len(obs.range_m), n_out, replace=False)
    rng_m = obs.range_m.copy()
    rng_m[bad] += 3.0
    obs = dataclasses.replace(obs, range_m=rng_m, reported_id=np.asarray(ds.truth.obs_landmark, np.int64).copy())
    return dataclasses.replace(inp, observations=obs), np.sort(bad)


@pytest.mark.parametrize("seed", [0, 1])
def test_outlier_gate_nulls_the_misreads_and_reaches_the_clean_optimum(seed):
    """With a 7 σ gate ICM nulls exactly the planted misreads, and ends at the joint optimum of the energy
    without them (the reference: joint Gauss-Newton to convergence on the clean labels, from ICM's end)."""
    from slamcli.solvers.icm import IcmSlam
    from slamcli.solvers.icm.common import reported_labels

    inp, bad = _loop_with_ids_and_outliers(seed, 6)
    p = IcmParams(correspondences="reported", weights="information", outlier_sigma=7.0, accelerate="joint",
                  accelerate_every=1, joint_iters=20, max_sweeps=60, energy_rtol=1e-12)
    res = IcmSlam(p).solve(inp, rng=np.random.default_rng(0))
    lab = np.asarray(res.assoc)
    assert np.flatnonzero(lab < 0).tolist() == bad.tolist()
    clean = reported_labels(inp.observations.reported_id)
    clean[bad] = -1
    prob = en.Problem.from_inputs(inp)
    W = en.information_weights(inp)
    p_ref, m_ref, _, _ = en.map_energy_fixed_assoc(prob, W, np.asarray(res.poses_xyt), np.asarray(res.landmarks_xy),
                                                   clean)
    assert np.abs(np.asarray(res.poses_xyt)[:, :2] - p_ref[:, :2]).max() < 1e-3
    assert np.abs(np.asarray(res.landmarks_xy) - m_ref).max() < 1e-3


def test_preset_real_with_ids_polishes_every_sweep_to_the_clean_optimum():
    """preset=real on data with ids, with the paper's Cartesian observation potential (and its motion
    potential): no joint Gauss-Newton steps (the polish ends every sweep, at most 6 LM iterations each, all on
    one CHOLMOD analysis), yet the run stops converged at the joint optimum of the energy without the planted
    misreads (reference: joint Gauss-Newton to convergence on the clean labels, from ICM's end)."""
    from slamcli.solvers.icm import IcmSlam
    from slamcli.solvers.icm.common import reported_labels

    inp, bad = _loop_with_ids_and_outliers(0, 6)
    given = {"preset": "real", "observation": "cartesian", "odometry_only": False}
    res = IcmSlam(IcmParams.resolve(given, inp)).solve(inp, rng=np.random.default_rng(0))
    assert res.status.value == "converged"
    assert res.extra["joint_steps_accepted"] == 0 and res.extra["joint_refinements"] == []
    assert len(res.extra["polishes"]) == res.extra["sweeps"]
    assert all(p["iterations"] <= 6 for p in res.extra["polishes"])
    # every polish factorises on the one pattern of all the id'd sightings, analysed before the sweeps
    from slamcli.solvers.nls import cholmod_available

    assert res.extra["polish_factor_analyses"] == 1 or not cholmod_available()
    assert np.flatnonzero(np.asarray(res.assoc) < 0).tolist() == bad.tolist()
    clean = reported_labels(inp.observations.reported_id)
    clean[bad] = -1
    p_ref, m_ref, _, _ = en.map_energy_fixed_assoc(en.Problem.from_inputs(inp), en.information_weights(inp),
                                                   np.asarray(res.poses_xyt), np.asarray(res.landmarks_xy), clean)
    assert np.abs(np.asarray(res.poses_xyt)[:, :2] - p_ref[:, :2]).max() < 1e-3
    assert np.abs(np.asarray(res.landmarks_xy) - m_ref).max() < 1e-3


def test_preset_real_rule_for_data_with_ids():
    inp, _ = _loop_with_ids_and_outliers(0, 0)
    q = IcmParams.resolve({"preset": "real"}, inp)
    assert (q.correspondences, q.weights, q.outlier_sigma, q.max_sweeps, q.init) == (
        "reported", "information", 7.0, 30, "online")
    assert q.polish_rtol == 1.0 and q.polish_every_sweep and q.polish_iters == 6  # every sweep ends polished
    assert q.merge and q.accelerate == "joint"  # the rest of the preset is kept
    assert q.observation == "range_bearing" and q.odometry_only  # graph's observation factor and odometry
    # without ids nothing changes; an explicit value wins, also one equal to the preset's or the paper's value
    no_ids = dataclasses.replace(inp, observations=dataclasses.replace(
        inp.observations, reported_id=np.full(len(inp.observations.range_m), -1, np.int64)))
    assert IcmParams.resolve({"preset": "real"}, no_ids) == IcmParams.real()
    assert IcmParams.resolve({"preset": "real", "max_sweeps": 9}, inp).max_sweeps == 9
    assert IcmParams.resolve({"preset": "real", "outlier_sigma": 3.0}, inp).outlier_sigma == 3.0
    assert IcmParams.resolve({"preset": "real", "init": "gated"}, inp).init == "gated"
    assert IcmParams.resolve({"preset": "real", "max_sweeps": 100}, inp).max_sweeps == 100
    assert IcmParams.resolve({}, inp) == IcmParams()
