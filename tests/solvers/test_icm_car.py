"""ICM-SLAM with the car model (issue 14 item 1): every motion term of the ICM energy is the Ackermann model of the
tracked point (slamcli.models.ackermann), the laser offset goes through api.solve's sensor-frame change.

Checks: the O(1) pose conditional and the joint Jacobian against the reference energy built on
``ackermann_step`` (and finite differences), an exact Gauss-Newton pose step on a noise-free car world, the
kinematic / on-line initialisation against ``integrate_ackermann`` of the laser point, ICM within 1 % of its own
MAP optimum, and ICM vs ``graph`` on the same association."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from test_ackermann_solvers import OFF, _errors, car_world

from slamcli.api.solve import solve_dataset
from slamcli.metrics.reference import trajectory_against
from slamcli.models.ackermann import VICTORIA_PARK, ackermann_jacobians, ackermann_step, integrate_ackermann
from slamcli.models.observation import body_pose_from_sensor, range_bearing, sensor_pose
from slamcli.solvers.icm import IcmParams, reported_labels
from slamcli.solvers.icm import energy as en
from slamcli.solvers.sensor_frame import to_sensor_frame
from slamcli.types import NoiseSpec, Observations, SlamInputs

VEH_LASER = dataclasses.replace(VICTORIA_PARK, ref_x_m=float(OFF[0]), ref_y_m=float(OFF[1]))
W3 = en.Weights.from_params((2.0, 1.5, 3.0), (0.7, 1.1, 0.4), (1.3, 0.8))


@pytest.fixture(scope="module")
def world():
    return car_world()


def exact_car_world(T: int = 240, dt: float = 0.025):
    """Noise-free car world in the laser frame: controls, odometry and observations all agree with the laser
    poses ``s`` (so every residual of the ICM energy is zero at the truth). Returns sensor-frame inputs, s,
    landmarks and the landmark index of every row."""
    rng = np.random.default_rng(7)
    t = np.arange(T) * dt
    u = np.column_stack([3.0 + 0.5 * np.sin(t), 0.3 * np.sin(2 * np.pi * t / 3.0)])
    s = integrate_ackermann(sensor_pose(np.array([1.0, -2.0, 0.4]), OFF), u, dt, VEH_LASER)
    lms = rng.uniform(s[:, :2].min(0) - 10, s[:, :2].max(0) + 10, size=(12, 2))
    steps, zs, ids = [], [], []
    for k in range(0, T + 1, 4):
        z = range_bearing(np.broadcast_to(s[k], (len(lms), 3)), lms)
        for j in np.flatnonzero(z[:, 0] < 25.0):
            steps.append(k)
            zs.append(z[j])
            ids.append(j)
    obs = Observations.from_rows(steps, np.array(zs), T + 1, reported_id=ids)
    inp = SlamInputs(dt=dt, timestamps=np.arange(T + 1) * dt, x0=s[0].copy(), controls=u, odometry_xyt=s.copy(),
                     observations=obs, noise=NoiseSpec(np.array([0.05, 0.005]), np.array([0.003, 0.002, 0.0005]),
                                                       0.05, 0.005),
                     motion_model="ackermann", vehicle=VEH_LASER)
    return inp, s, lms, np.asarray(ids)


def test_problem_motion_is_the_shared_car_model():
    """The twist form of every fast path (controls = [v_c − ω b, ω], lateral = ω a) equals ackermann_step."""
    rng = np.random.default_rng(0)
    inp, s, _lms, _ids = exact_car_world()
    prob = en.Problem.from_inputs(inp)
    x = s[:-1] + rng.normal(0, [1.0, 1.0, 0.5], s[:-1].shape)
    g_fast = en._motion(x, prob.controls, prob.dt, prob.lat)
    g_ref = ackermann_step(x, inp.controls, inp.dt, VEH_LASER)
    np.testing.assert_allclose(g_fast[:, :2], g_ref[:, :2], atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (g_fast[:, 2] - g_ref[:, 2]))), 0.0, atol=1e-12)
    assert np.abs(prob.lat).max() > 0.1  # the laser's lateral velocity is not negligible
    # chain energy (fast path) == motion + odometry of the reference energy
    lab = -np.ones(prob.n_obs, np.int64)
    terms = en.energy_terms(prob, W3, x_full := np.vstack([s[:1], x]), np.zeros((0, 2)), lab)
    assert en.chain_energy(prob, W3, x_full) == pytest.approx(terms["motion"] + terms["odometry"], rel=1e-12)


@pytest.mark.parametrize("t", [1, 100, 240])
def test_pose_conditional_equals_energy_difference_car(t):
    inp, s, lms, ids = exact_car_world()
    prob = en.Problem.from_inputs(inp)
    rng = np.random.default_rng(t)
    poses = s + rng.normal(0, [0.2, 0.2, 0.05], s.shape)
    poses[0] = s[0]
    lm = lms + rng.normal(0, 0.2, lms.shape)
    stats = en.step_stats(prob, ids, lm)
    ctx = tuple(a[0] for a in en.pose_contexts(prob, poses, np.array([t])))
    new = poses.copy()
    new[t] += [0.3, -0.4, 0.07]
    c0 = en.cond_cost(*poses[t], ctx, tuple(stats[:, t]), W3.flat, prob.dt, math.cos, math.sin)
    c1 = en.cond_cost(*new[t], ctx, tuple(stats[:, t]), W3.flat, prob.dt, math.cos, math.sin)
    dE = en.energy(prob, W3, new, lm, ids) - en.energy(prob, W3, poses, lm, ids)
    assert c1 - c0 == pytest.approx(dE, rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("t", [1, 57, 239, 240])
def test_gauss_newton_pose_step_is_exact_on_a_noise_free_car_world(t):
    """At the truth every residual is zero; from a pose moved by ε one Gauss-Newton step of the conditional
    (the lateral-speed Jacobian terms included) lands back on it to O(ε²) — a wrong Jacobian leaves O(ε)."""
    inp, s, lms, ids = exact_car_world()
    prob = en.Problem.from_inputs(inp)
    stats = en.step_stats(prob, ids, lms)
    ctx = tuple(a[0] for a in en.pose_contexts(prob, s, np.array([t])))
    st = tuple(stats[:, t])
    assert en.cond_cost(*s[t], ctx, st, W3.flat, prob.dt, math.cos, math.sin) < 1e-16
    eps = np.array([2e-4, -3e-4, 1e-4])
    x = s[t] + eps
    d = np.array(en.cond_step(*x, ctx, st, W3.flat, prob.dt, math.cos, math.sin))
    assert np.abs(x + d - s[t]).max() < 1e-6 * np.abs(eps).max() / 1e-4
    # the same with the lateral terms dropped is visibly wrong at poses with a next step
    if t < prob.T:
        bad = ctx[:-1] + (0.0,)
        d_bad = np.array(en.cond_step(*x, bad, st, W3.flat, prob.dt, math.cos, math.sin))
        assert np.abs(x + d_bad - s[t]).max() > 10 * np.abs(x + d - s[t]).max()


def test_joint_jacobian_car_vs_finite_differences():
    inp, s, lms, ids = exact_car_world()
    prob = en.Problem.from_inputs(inp)
    rng = np.random.default_rng(5)
    poses = s + rng.normal(0, [0.1, 0.1, 0.05], s.shape)
    poses[0] = s[0]
    r, J = en.joint_residuals(prob, W3, poses, lms, ids)
    assert float(r @ r) == pytest.approx(en.energy(prob, W3, poses, lms, ids), rel=1e-12)
    v0 = en.pack(poses, lms)
    dv = rng.normal(0, 1e-6, v0.shape)
    r1, _ = en.joint_residuals(prob, W3, *en.unpack(prob, v0 + dv, len(lms)), ids, jacobian=False)
    r2, _ = en.joint_residuals(prob, W3, *en.unpack(prob, v0 - dv, len(lms)), ids, jacobian=False)
    np.testing.assert_allclose((r1 - r2) / 2, J @ dv, atol=1e-11)
    # the motion block is ackermann_jacobians' G_x (the shared model's Jacobian, itself FD-tested)
    G_x = ackermann_jacobians(poses[:-1], inp.controls, inp.dt, VEH_LASER)[0]
    Jd = J.toarray()
    sw = math.sqrt(W3.R[0])
    np.testing.assert_allclose(Jd[3 * 5, 3 * 4:3 * 5], sw * G_x[5, 0], atol=1e-12)


def test_kinematic_and_online_init_use_the_car_model_of_the_laser_point(world):
    """No sweeps: the kinematic init is integrate_ackermann of the laser point, mapped back to the body; the
    on-line init with S = 0 and no observations is the same recursion (eq. 11 with only the motion term)."""
    laser = integrate_ackermann(sensor_pose(world.inputs.x0, OFF), world.inputs.controls, world.inputs.dt, VEH_LASER)
    kin = solve_dataset(world.inputs, "icm", {"init": "kinematic", "max_sweeps": 0})
    np.testing.assert_allclose(kin.poses_xyt, body_pose_from_sensor(laser, OFF), atol=1e-9)
    blind = dataclasses.replace(world.inputs, observations=Observations.from_rows([], np.zeros((0, 2)),
                                                                                  world.inputs.n_poses))
    onl = solve_dataset(blind, "icm", {"max_sweeps": 0})
    np.testing.assert_allclose(onl.poses_xyt, body_pose_from_sensor(laser, OFF), atol=1e-9)


def test_information_weights_car_model(world):
    """R from the car model: median over moving steps of G_u diag(σ²) G_uᵀ (hand-computed for one control)."""
    inp = to_sensor_frame(world.inputs)
    u = np.tile([4.0, 0.1], (inp.n_poses - 1, 1))
    inp = dataclasses.replace(inp, controls=u)
    W = en.information_weights(inp)
    _, G = ackermann_jacobians(np.zeros(3), u[0], inp.dt, inp.vehicle)
    C = G @ np.diag(np.asarray(inp.noise.motion_std) ** 2) @ G.T
    assert W.R[0] == pytest.approx(2.0 / (C[0, 0] + C[1, 1]), rel=1e-12)
    assert W.R[2] == pytest.approx(1.0 / C[2, 2], rel=1e-12)


def test_icm_car_reaches_its_map_optimum_and_agrees_with_graph(world):
    """Known association: ICM (car model, information weights) ends at the MAP energy of its own model, recovers the truth as well as graph, and graph's optimum on the same association is within 5 cm."""
    p = IcmParams(correspondences="reported", weights="information", max_sweeps=300, energy_rtol=1e-12,
                  accelerate="joint", accelerate_every=3)
    icm = solve_dataset(world.inputs, "icm", p)
    sf = to_sensor_frame(world.inputs)
    prob = en.Problem.from_inputs(sf)
    W = p.weights_for(sf)
    s = sensor_pose(icm.poses_xyt, OFF)
    _, _, E_map, _ = en.map_energy_fixed_assoc(prob, W, s.copy(), icm.landmarks_xy.copy(), icm.assoc)
    E_icm = icm.trace.objective[-1]
    assert E_icm == pytest.approx(en.energy(prob, W, s, icm.landmarks_xy, icm.assoc), rel=1e-9)
    assert E_icm == pytest.approx(E_map, rel=1e-9)  # the default polish ends at the optimum
    np.testing.assert_array_equal(icm.assoc, reported_labels(world.inputs.observations.reported_id))
    graph = solve_dataset(world.inputs, "graph", {"association": "init"}, init=icm)
    i_ate, i_lm = _errors(icm, world)
    g_ate, g_lm = _errors(graph, world)
    assert i_ate < 0.06 and i_lm < 0.12, (i_ate, i_lm)
    ag = trajectory_against(icm.poses_xyt, graph.poses_xyt, icm.landmarks_xy, graph.landmarks_xy, cutoff_m=1.0)
    assert ag["against_ate_rmse_m"] < 0.05 and ag["against_lm_matched"] == len(graph.landmarks_xy), ag
    assert ag["against_lm_rmse_m"] < 0.1, ag


@pytest.mark.slow
def test_icm_car_unknown_association(world):
    """Unknown association (the ICM machinery unchanged): every true landmark found once, poses as good as
    dead reckoning's class, and ignoring the 3.8 m laser offset fails visibly."""
    # ϑ = 0.5 m: two true landmarks of this world lie 0.81 m apart
    icm = solve_dataset(world.inputs, "icm", {"fusion_radius": 0.5, "max_sweeps": 30})
    ate, _ = _errors(icm, world)
    n_true = len(np.unique(world.truth.obs_landmark))
    ag = trajectory_against(icm.poses_xyt, world.truth.poses_xyt, icm.landmarks_xy,
                            world.truth.landmarks_xy[np.unique(world.truth.obs_landmark)], cutoff_m=1.0)
    assert ate < 0.08, ate
    assert len(icm.landmarks_xy) == n_true and ag["against_lm_matched"] == n_true, ag
    assert ag["against_lm_rmse_m"] < 0.15, ag
    wrong = dataclasses.replace(world.inputs, sensor_offset_xy=np.zeros(2))
    w = solve_dataset(wrong, "icm", {"fusion_radius": 0.5, "max_sweeps": 30})
    agw = trajectory_against(w.poses_xyt, world.truth.poses_xyt, w.landmarks_xy,
                             world.truth.landmarks_xy[np.unique(world.truth.obs_landmark)], cutoff_m=1.0)
    assert agw["against_lm_matched"] < n_true or agw["against_lm_rmse_m"] > 1.0, agw
