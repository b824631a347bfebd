"""Multi-robot datasets (issue 14 item 7): the MRCLAM team import, the schema group, the inter-robot factor, the
joint graph solve against an independent least-squares fit, multi-robot ICM against the minimum of its own energy,
per-robot metrics and the refusal of solvers without multi-robot support.

Data: ``tests/data/mrclam_team_excerpt`` (30 s of all five robots of MRCLAM Dataset 7, see its PROVENANCE.txt) and
a hand-built two-robot world (:func:`two_robot_world`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import DATA
from scipy.optimize import least_squares

from slamcli.api.solve import solve_dataset
from slamcli.datasets.mrclam import import_mrclam_team
from slamcli.datasets.team import solo_dataset, without_robot_readings
from slamcli.errors import SolverError
from slamcli.io import dataset_hash, read_dataset, write_dataset
from slamcli.models.motion import integrate
from slamcli.solvers.graph import GraphParams, robot_range_bearing_error
from slamcli.solvers.icm.solver import IcmParams
from slamcli.types import Dataset, GroundTruth, NoiseSpec, Observations, RobotTeam, SlamInputs, solo_inputs

EXCERPT = DATA / "mrclam_team_excerpt"


# --------------------------------------------------------------------------------------------------------
# independent counting straight from the text files (no importer code)
# --------------------------------------------------------------------------------------------------------
def _robot_rows_in_files(robots=(1, 2, 3, 4, 5)):
    """``{observer: (t (n,), observed robot (n,))}`` of every measurement row whose barcode is a robot's."""
    bar = np.loadtxt(EXCERPT / "Barcodes.dat", comments="#").astype(int)
    robot_of_barcode = {int(b): int(s) for s, b in bar if 1 <= s <= 5}
    out = {}
    for r in robots:
        m = np.loadtxt(EXCERPT / f"Robot{r}_Measurement.dat", comments="#").reshape(-1, 4)
        sel = np.array([int(b) in robot_of_barcode for b in m[:, 1]], bool)
        out[r] = (m[sel, 0], np.array([robot_of_barcode[int(b)] for b in m[sel, 1]], int))
    return out


def test_import_count_equals_rows_with_a_robot_barcode():
    ds = import_mrclam_team(EXCERPT, [1, 2, 3, 4, 5])
    rows = _robot_rows_in_files()
    n_files = sum(len(t) for t, _ in rows.values())
    rr = ds.metadata["robot_rows"]
    team = ds.inputs.robots
    assert n_files == 207  # counted in the excerpt's files
    assert rr["n_rows_with_robot_barcode"] == n_files
    # every row has one fate; the readings kept are exactly the rows inside the common time base
    assert rr["kept"] + rr["dropped_outside_time_base"] + rr["dropped_robot_not_imported"] + rr["dropped_self"] == n_files
    assert len(team.range_m) == rr["kept"]
    t_ref, dt = ds.metadata["time_origin_unix_s"], ds.inputs.dt
    T = ds.inputs.n_poses // 5 - 1
    inside = sum(int(np.sum((np.rint((t - t_ref) / dt) >= 0) & (np.rint((t - t_ref) / dt) <= T))) for t, _ in rows.values())
    assert rr["kept"] == inside and rr["dropped_outside_time_base"] == n_files - inside == 2
    assert rr["dropped_robot_not_imported"] == 0 and rr["dropped_self"] == 0


def test_import_subset_and_window_drop_with_reasons():
    ds = import_mrclam_team(EXCERPT, [2, 3, 5], start=2.0, duration=25.0)
    rows = _robot_rows_in_files((2, 3, 5))
    rr = ds.metadata["robot_rows"]
    t_ref, dt = ds.metadata["time_origin_unix_s"], ds.inputs.dt
    T = round(25.0 / dt)
    n_in = n_out = n_not = 0
    for t, seen in rows.values():
        k = np.rint((t - t_ref - 2.0) / dt)
        outside = (k < 0) | (k > T)
        n_out += int(outside.sum())
        not_team = ~outside & ~np.isin(seen, [2, 3, 5])
        n_not += int(not_team.sum())
        n_in += int((~outside & ~not_team).sum())
    assert rr["n_rows_with_robot_barcode"] == sum(len(t) for t, _ in rows.values())
    assert (rr["kept"], rr["dropped_outside_time_base"], rr["dropped_robot_not_imported"]) == (n_in, n_out, n_not)
    assert n_not > 0 and n_out > 0 and n_in > 0  # the excerpt exercises every reason


def test_import_layout_start_poses_and_readings_against_truth():
    ds = import_mrclam_team(EXCERPT, [1, 2, 3, 4, 5])
    inp, team = ds.inputs, ds.inputs.robots
    fp = team.first_pose
    n1 = inp.n_poses // 5
    assert fp.tolist() == [k * n1 for k in range(6)]
    for r in range(5):  # one time base; start pose = motion capture at the first grid time; chains per robot
        assert np.array_equal(inp.timestamps[fp[r]:fp[r + 1]], inp.timestamps[:n1])
        assert np.allclose(team.x0_xyt[r], ds.truth.poses_xyt[fp[r]])
        assert np.allclose(inp.odometry_xyt[fp[r]], team.x0_xyt[r])
    assert np.all(inp.controls[fp[1:-1] - 1] == 0.0)  # the unused rows between two robots
    assert len(team.chain_pairs) == inp.n_poses - 5
    # readings link different robots at the same step, and agree with the motion capture
    assert np.all(team.pose_robot[team.observer_pose] != team.pose_robot[team.observed_pose])
    assert np.array_equal(team.observer_pose % n1, team.observed_pose % n1)
    e, _, _ = robot_range_bearing_error(ds.truth.poses_xyt[team.observer_pose], ds.truth.poses_xyt[team.observed_pose],
                                        team.z)
    assert np.median(np.abs(e[:, 0])) < 0.15 and np.median(np.abs(e[:, 1])) < 0.03
    # landmark rows per robot equal the single-robot importer's on the same grid
    for r in range(5):
        solo = solo_dataset(ds, r)
        assert len(solo.inputs.observations) == ds.metadata["per_robot"][r]["n_landmark_rows"]


def test_schema_round_trip_and_single_robot_files_unchanged(tmp_path):
    ds = import_mrclam_team(EXCERPT, [1, 3, 5], duration=10.0)
    p = write_dataset(tmp_path / "team.h5", ds)
    back = read_dataset(p)
    assert dataset_hash(back) == dataset_hash(ds)
    t0, t1 = ds.inputs.robots, back.inputs.robots
    for f in ("pose_robot", "robot_number", "x0_xyt", "observer_pose", "observed_pose", "range_m", "bearing_rad"):
        assert np.array_equal(getattr(t0, f), getattr(t1, f)), f
    solo = solo_dataset(ds, 1)
    q = write_dataset(tmp_path / "solo.h5", solo)
    assert read_dataset(q).inputs.robots is None
    import h5py

    with h5py.File(q) as f:
        assert "robots" not in f["inputs"] and "robot_observations" not in f["inputs"]
    # a corrupted team file fails with one line naming the field
    with h5py.File(p, "a") as f:
        f["inputs/robot_observations/observed_pose"][0] = f["inputs/robot_observations/observer_pose"][0]
    from slamcli.errors import SchemaError

    with pytest.raises(SchemaError, match="robot_observations/observed_pose: reading 0 links a robot to itself"):
        read_dataset(p)


# --------------------------------------------------------------------------------------------------------
# the inter-robot factor
# --------------------------------------------------------------------------------------------------------
def test_robot_range_bearing_jacobians_match_finite_differences():
    rng = np.random.default_rng(3)
    xi = np.column_stack([rng.uniform(-5, 5, (20, 2)), rng.uniform(-3, 3, 20)])
    xj = np.column_stack([rng.uniform(-5, 5, (20, 2)), rng.uniform(-3, 3, 20)])
    z = np.column_stack([rng.uniform(0.5, 4, 20), rng.uniform(-3, 3, 20)])
    e, Ji, Jj = robot_range_bearing_error(xi, xj, z)
    assert e.shape == (20, 2) and Ji.shape == Jj.shape == (20, 2, 3)
    h = 1e-6
    for k in range(3):
        d = np.zeros(3)
        d[k] = h
        for J, plus, minus in ((Ji, (xi + d, xj), (xi - d, xj)), (Jj, (xi, xj + d), (xi, xj - d))):
            num = (robot_range_bearing_error(*plus, z)[0] - robot_range_bearing_error(*minus, z)[0]) / (2 * h)
            num[:, 1] = (num[:, 1] + np.pi / h) % (2 * np.pi / h) - np.pi / h  # wrapped bearing differences
            assert np.allclose(J[:, :, k], num, atol=1e-6), k
    assert np.all(Jj[:, :, 2] == 0.0)  # the observed robot's heading does not enter


# --------------------------------------------------------------------------------------------------------
# a hand-built two-robot world
# --------------------------------------------------------------------------------------------------------
def two_robot_world(T: int = 12, seed: int = 7) -> Dataset:
    """Two robots driving arcs among 4 landmarks; robot 0 reads robot 1 at every third step."""
    rng = np.random.default_rng(seed)
    dt = 0.5
    noise = NoiseSpec(motion_std=np.array([0.05, 0.05]), odometry_std=np.array([0.03, 0.01, 0.02]),
                      range_std=0.05, bearing_std=0.02)
    lms = np.array([[2.0, 3.0], [5.0, -1.0], [0.0, -3.0], [6.0, 3.0]])
    x0s = np.array([[0.0, 0.0, 0.2], [4.0, -2.0, 1.5]])
    u = [np.column_stack([np.full(T, 0.6), np.full(T, 0.12)]), np.column_stack([np.full(T, 0.5), np.full(T, -0.1)])]
    true = [integrate(x0s[r], u[r], dt) for r in range(2)]
    odo = []
    for r in range(2):
        from slamcli.models import se2

        d = se2.between(true[r][:-1], true[r][1:]) + rng.normal(0, noise.odometry_std, (T, 3))
        p = [x0s[r]]
        for k in range(T):
            p.append(se2.compose(p[-1], d[k]))
        odo.append(np.array(p))
    steps, zs, ids = [], [], []
    from slamcli.models.observation import range_bearing

    for r in range(2):
        for t in range(T + 1):
            for j in (0, 1, 2, 3) if (t + r) % 2 == 0 else (r, 3 - r):
                zt = range_bearing(true[r][t][None], lms[j][None])[0]
                steps.append(r * (T + 1) + t)
                zs.append(zt + rng.normal(0, [noise.range_std, noise.bearing_std]))
                ids.append(j)
    order = np.argsort(steps, kind="stable")
    steps, zs, ids = np.array(steps)[order], np.array(zs)[order], np.array(ids)[order]
    obs = Observations.from_rows(steps, zs, 2 * (T + 1), reported_id=ids)
    k = np.arange(0, T + 1, 3)
    zr = range_bearing(true[0][k], true[1][k, :2]) + rng.normal(0, [noise.range_std, noise.bearing_std], (len(k), 2))
    team = RobotTeam(pose_robot=np.repeat([0, 1], T + 1), robot_number=np.array([1, 2]), x0_xyt=x0s,
                     observer_pose=k, observed_pose=(T + 1) + k, range_m=zr[:, 0], bearing_rad=zr[:, 1])
    inputs = SlamInputs(dt=dt, timestamps=np.tile(dt * np.arange(T + 1), 2), x0=x0s[0],
                        controls=np.concatenate([u[0], np.zeros((1, 2)), u[1]]),
                        odometry_xyt=np.concatenate(odo), observations=obs, noise=noise, robots=team)
    truth = GroundTruth(poses_xyt=np.concatenate(true), landmarks_xy=lms, obs_landmark=ids)
    return Dataset(inputs=inputs, truth=truth, metadata={"scenario": "two-robot toy"})


def _se2_log(p):
    x, y, th = p[..., 0], p[..., 1], np.arctan2(np.sin(p[..., 2]), np.cos(p[..., 2]))
    half = 0.5 * th
    a = np.where(np.abs(th) < 1e-9, 1.0, half * np.cos(half) / np.where(np.abs(th) < 1e-9, 1.0, np.sin(half)))
    return np.stack([a * x + half * y, -half * x + a * y, th], -1)


def _se2_between(a, b):
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, b[..., 2] - a[..., 2]], -1)


def _reference_residuals(ds: Dataset, prior_std=1e-4):
    """Whitened residuals of the joint problem, written from the model equations (GTSAM's factor errors)."""
    inp, team = ds.inputs, ds.inputs.robots
    n = inp.n_poses
    obs = inp.observations
    ids = obs.reported_id
    pairs = team.chain_pairs
    d = _se2_between(inp.odometry_xyt[pairs], inp.odometry_xyt[pairs + 1])
    so, sr, sb = inp.noise.odometry_std, inp.noise.range_std, inp.noise.bearing_std
    first = team.first_pose[:-1]

    def wrap(a):
        return (a + np.pi) % (2 * np.pi) - np.pi

    def rb(p, q, z):
        dxy = q - p[:, :2]
        return np.column_stack([(np.hypot(dxy[:, 0], dxy[:, 1]) - z[:, 0]) / sr,
                                wrap(np.arctan2(dxy[:, 1], dxy[:, 0]) - p[:, 2] - z[:, 1]) / sb])

    def fun(v):
        x, m = v[: 3 * n].reshape(-1, 3), v[3 * n:].reshape(-1, 2)
        rel = _se2_between(x[pairs], x[pairs + 1])
        e_odo = _se2_log(_se2_between(d, rel)) / so  # Log(d⁻¹ ⊕ x_i⁻¹ ⊕ x_j)
        e_pri = _se2_log(_se2_between(team.x0_xyt, x[first])) / prior_std
        return np.concatenate([e_pri.ravel(), e_odo.ravel(), rb(x[obs.step], m[ids], obs.z).ravel(),
                               rb(x[team.observer_pose], x[team.observed_pose, :2], team.z).ravel()])

    return fun


def test_joint_graph_equals_independent_least_squares():
    ds = two_robot_world()
    res = solve_dataset(ds.inputs, "graph", GraphParams(robust="none", covariance=False, rel_cost_tol=1e-15,
                                                        step_tol=1e-15))
    assert res.status.value == "converged"
    # graph numbers landmarks by first sighting; map them back to the reported ids for the reference
    order = np.full(4, -1)
    order[res.assoc] = ds.inputs.observations.reported_id
    lm = np.empty((4, 2))
    lm[order] = res.landmarks_xy
    fun = _reference_residuals(ds)
    start = np.concatenate([ds.inputs.odometry_xyt.ravel(), ds.truth.landmarks_xy.ravel() + 0.3])
    ref = least_squares(fun, start, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=20000)
    x_ref = ref.x[: 3 * ds.inputs.n_poses].reshape(-1, 3)
    assert np.max(np.abs(res.poses_xyt - x_ref)) < 1e-6
    assert np.max(np.abs(lm - ref.x[3 * ds.inputs.n_poses:].reshape(-1, 2))) < 1e-6
    assert res.extra["final_cost"] == pytest.approx(0.5 * np.sum(ref.fun**2), rel=1e-9)
    # the readings matter: without them the optimum moves (the factor is in the problem, not ignored)
    res0 = solve_dataset(without_robot_readings(ds.inputs), "graph", GraphParams(robust="none", covariance=False))
    assert np.max(np.abs(res0.poses_xyt - res.poses_xyt)) > 1e-3
    # odometry chains never connect the two robots: robot 2's first pose sits at its own start pose
    assert np.allclose(res.poses_xyt[ds.inputs.robots.first_pose[1]], ds.inputs.robots.x0_xyt[1], atol=1e-3)


def _icm_reference(ds: Dataset, W):
    """Minimum of the multi-robot ICM energy (module slamcli.solvers.icm.team), written from the potentials."""
    inp, team = ds.inputs, ds.inputs.robots
    n = inp.n_poses
    obs = inp.observations
    ids = obs.reported_id
    pairs = team.chain_pairs
    dt = inp.dt
    u = inp.controls[pairs]
    odo = _se2_between(inp.odometry_xyt[pairs], inp.odometry_xyt[pairs + 1])
    sqR, sqS, sqQ = np.sqrt(W.R), np.sqrt(W.S), np.sqrt(W.Q)
    first = team.first_pose[:-1]
    free = np.setdiff1d(np.arange(n), first)

    def wrap(a):
        return (a + np.pi) % (2 * np.pi) - np.pi

    def inv_obs(p, z):
        return p[:, :2] + z[:, :1] * np.column_stack([np.cos(p[:, 2] + z[:, 1]), np.sin(p[:, 2] + z[:, 1])])

    def unpack(v):
        x = np.empty((n, 3))
        x[first] = team.x0_xyt
        x[free] = v[: 3 * len(free)].reshape(-1, 3)
        return x, v[3 * len(free):].reshape(-1, 2)

    def fun(v):
        x, m = unpack(v)
        a, b = x[pairs], x[pairs + 1]
        g = np.column_stack([a[:, 0] + dt * u[:, 0] * np.cos(a[:, 2]), a[:, 1] + dt * u[:, 0] * np.sin(a[:, 2]),
                             a[:, 2] + dt * u[:, 1]])
        r_mot = g - b
        r_mot[:, 2] = wrap(r_mot[:, 2])
        r_odo = _se2_between(a, b) - odo
        r_odo[:, 2] = wrap(r_odo[:, 2])
        r_obs = inv_obs(x[obs.step], obs.z) - m[ids]
        r_rd = inv_obs(x[team.observer_pose], team.z) - x[team.observed_pose, :2]
        return np.concatenate([(r_mot * sqR).ravel(), (r_odo * sqS).ravel(), (r_obs * sqQ).ravel(),
                               (r_rd * sqQ).ravel()])

    return fun, unpack, free


def _reference_vector(res, ds, free):
    """``(order, v)``: the reference's landmark row of each of ICM's labels, and ICM's result as the reference's
    variable vector ``[free poses, landmarks by reported id]``."""
    lm = np.empty((4, 2))
    order = np.full(4, -1)
    order[res.assoc] = ds.inputs.observations.reported_id
    lm[order] = res.landmarks_xy
    return order, np.concatenate([res.poses_xyt[free].ravel(), lm.ravel()])


@pytest.mark.slow
def test_joint_icm_reaches_the_minimum_of_its_energy():
    ds = two_robot_world()
    p = IcmParams(correspondences="reported", R=(1.0,), S=(4.0,), Q=(1.0,), max_sweeps=3000, energy_rtol=1e-13,
                  trace_poses_every=0)
    res = solve_dataset(ds.inputs, "icm", p)
    E = np.asarray(res.trace.objective)
    assert np.all(np.diff(E) <= 1e-12 * E[0])  # ICM never raises the energy
    W = p.design_weights()
    fun, unpack, free = _icm_reference(ds, W)
    # the reported energy is the energy of the model equations at the result
    order, v_icm = _reference_vector(res, ds, free)
    assert res.extra["energy_total"] == pytest.approx(float(np.sum(fun(v_icm) ** 2)), rel=1e-10)
    ref = least_squares(fun, v_icm, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    E_min = float(np.sum(ref.fun**2))
    assert res.extra["energy_total"] <= E_min * (1 + 1e-6)
    assert np.max(np.abs(res.poses_xyt - unpack(ref.x)[0])) < 1e-3
    # the readings are in the energy: at the optimum without them the reading term is far from its minimum
    assert res.extra["energy_robot_readings"] > 0
    res0 = solve_dataset(without_robot_readings(ds.inputs), "icm", p)
    assert res0.extra["energy_robot_readings"] == 0.0
    assert np.max(np.abs(res0.poses_xyt - res.poses_xyt)) > 1e-3


# --------------------------------------------------------------------------------------------------------
# refusals, metrics, the excerpt end to end
# --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["ekf", "fastslam", "hybrid", "cuik", "odometry"])
def test_solvers_without_multi_robot_support_refuse_in_one_line(method):
    ds = two_robot_world(T=4)
    with pytest.raises(SolverError) as exc:
        solve_dataset(ds.inputs, method)
    msg = str(exc.value)
    assert "\n" not in msg and "does not support multi-robot data (2 robots" in msg


def test_icm_refuses_what_it_does_not_implement_for_teams():
    from slamcli.errors import ConfigError

    ds = two_robot_world(T=4)
    with pytest.raises(ConfigError, match="multi-robot data needs correspondences=reported"):
        solve_dataset(ds.inputs, "icm", IcmParams())


def test_per_robot_metrics_hand_computed():
    from slamcli.metrics.team import per_robot_trajectory_metrics

    true = np.zeros((6, 3))
    true[:, 0] = [0, 1, 2, 0, 1, 2]
    est = true.copy()
    est[1, 1] = 0.3  # robot 1: one pose 0.3 m off
    est[3:, 1] = 0.4  # robot 2: every pose 0.4 m off
    m = per_robot_trajectory_metrics(est, true, np.array([0, 3, 6]), np.array([1, 2]))
    assert m["robot1_ate_rmse_m"] == pytest.approx(np.sqrt(0.09 / 3))
    assert m["robot2_ate_rmse_m"] == pytest.approx(0.4)
    assert m["robot2_aligned_ate_rmse_m"] == pytest.approx(0.0, abs=1e-12)
    assert m["rpe_pairs"] == 4  # 2 per robot; never the pair (2, 3) across robots
    assert m["rpe_trans_rmse_m"] == pytest.approx(np.sqrt(2 * 0.09 / 4))


@pytest.mark.slow
def test_excerpt_joint_graph_and_evaluate(tmp_path):
    from slamcli.api.evaluate import evaluate_files
    from slamcli.api.solve import solve_file

    ds = import_mrclam_team(EXCERPT, [1, 2, 3, 4, 5])
    data = write_dataset(tmp_path / "team.h5", ds)
    solve_file(data, "graph", {"covariance": False}, tmp_path / "joint.h5")
    m = evaluate_files(tmp_path / "joint.h5", out_dir=tmp_path / "ev")
    assert m["robots"] == [1, 2, 3, 4, 5]
    fp = ds.inputs.robots.first_pose
    res = read_dataset(data)  # noqa: F841 - the file reads back
    from slamcli.io import read_result

    est = read_result(tmp_path / "joint.h5").poses_xyt
    for r, n in enumerate([1, 2, 3, 4, 5]):
        e = est[fp[r]:fp[r + 1], :2] - ds.truth.poses_xyt[fp[r]:fp[r + 1], :2]
        assert m[f"robot{n}_ate_rmse_m"] == pytest.approx(float(np.sqrt(np.mean(np.sum(e**2, 1)))), rel=1e-12)
        assert m[f"robot{n}_ate_rmse_m"] < m[f"robot{n}_odometry_ate_rmse_m"] + 0.05
    # per robot a solo solve is a proper single-robot problem on the same grid
    solo = solo_dataset(ds, 2)
    r_solo = solve_dataset(solo.inputs, "graph", GraphParams(covariance=False))
    assert r_solo.poses_xyt.shape == (fp[3] - fp[2], 3)
    assert dataclasses.replace(solo.inputs).robots is None


@pytest.mark.slow
def test_cli_import_all_robots_solo_dir_and_refusals(tmp_path):
    from typer.testing import CliRunner

    from slamcli.cli import app

    runner = CliRunner()

    def run(*args):
        return runner.invoke(app, [str(a) for a in args], terminal_width=200)

    data = tmp_path / "team.h5"
    res = run("import", "mrclam", EXCERPT, "--all-robots", "--solo-dir", tmp_path / "solo", "-o", data)
    assert res.exit_code == 0, res.output
    assert "205 inter-robot readings of 207 rows" in res.stdout and "2 outside" in res.stdout
    ds = read_dataset(data)
    assert dataset_hash(ds) == dataset_hash(import_mrclam_team(EXCERPT, [1, 2, 3, 4, 5]))
    for r in range(5):
        assert dataset_hash(read_dataset(tmp_path / "solo" / f"robot{r + 1}.h5")) == dataset_hash(solo_dataset(ds, r))
    res = run("import", "mrclam", EXCERPT, "--robots", "1,2", "--no-truth", "-o", tmp_path / "x.h5")
    assert res.exit_code == 1 and "--no-truth: a multi-robot import needs" in res.output
    assert not (tmp_path / "x.h5").exists()
    res = run("import", "mrclam", EXCERPT, "--robots", "1,x", "-o", tmp_path / "x.h5")
    assert res.exit_code == 1 and "--robots: expected comma-separated robot numbers" in res.output
    res = run("import", "mrclam", EXCERPT, "--robots", "2", "-o", tmp_path / "x.h5")
    assert res.exit_code == 1 and "need at least two distinct robot numbers" in res.output
    res = run("solve", data, "--method", "fastslam", "-o", tmp_path / "f.h5")
    assert res.exit_code == 1 and "does not support multi-robot data" in res.output
    assert "Traceback" not in res.output


def test_reproduce_outcome_sentences_follow_the_numbers():
    from slamcli.reproduce.real_multi import outcome_sentences
    from slamcli.reproduce.report import SECTIONS

    assert ("real-multi", "slamcli.reproduce.real_multi:run_section") in SECTIONS
    rows = [{"robot": 1, "odometry": 1.0, "graph_solo": 0.5, "graph_joint": 0.25, "icm_solo": 1.0, "icm_joint": 1.0},
            {"robot": 2, "odometry": 1.0, "graph_solo": 0.5, "graph_joint": 0.75, "icm_solo": 1.0, "icm_joint": 1.005}]
    s = outcome_sentences(rows)
    assert s[0].startswith("**graph**: the joint solve is better for 1 of 2 robots (ATE lower by more than 2 %: 1, "
                           "higher: 1, within ±2 %: 0); mean ATE 0.500 m solo → 0.500 m joint (+0.0 %)")
    assert s[1] == "graph joint mean ATE is 50 % below the dead-reckoning mean (1.000 m)."
    assert s[2].startswith("**icm**: the joint solve is better for no robot (ATE lower by more than 2 %: 0, higher: 0, "
                           "within ±2 %: 2)")
    assert s[3] == "icm joint mean ATE is within ±2 % of the dead-reckoning mean (1.000 m)."


@pytest.mark.slow
def test_team_joint_steps_converge_to_the_least_squares_optimum():
    """accelerate=joint on a team (issue 22 item 2): the team residuals square to the team energy, their Jacobian
    matches finite differences, and ICM with joint steps stops on its energy test, well before its sweep cap, at
    scipy's least-squares optimum of the same energy."""
    from slamcli.solvers.icm import energy as en
    from slamcli.solvers.icm.team import team_joint_residuals

    ds = two_robot_world()
    p = IcmParams(correspondences="reported", R=(1.0,), S=(4.0,), Q=(1.0,), accelerate="joint", accelerate_every=1,
                  joint_iters=20, max_sweeps=50, energy_rtol=1e-12, trace_poses_every=0)
    res = solve_dataset(ds.inputs, "icm", p)
    assert res.status.value == "converged" and res.extra["sweeps"] < 20
    W = p.design_weights()
    fun, unpack, free = _icm_reference(ds, W)
    order, v_icm = _reference_vector(res, ds, free)
    ref = least_squares(fun, v_icm, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert res.extra["energy_total"] <= float(np.sum(ref.fun**2)) * (1 + 1e-9)
    assert np.max(np.abs(res.poses_xyt - unpack(ref.x)[0])) < 1e-5
    # residuals and Jacobian of the joint step, at a perturbed point: ‖r‖² = the reference energy, J = FD of r
    team = ds.inputs.robots
    solos = [solo_inputs(ds.inputs, r) for r in range(team.n_robots)]
    probs = [en.Problem.from_inputs(s, use_gps=False) for s in solos]
    rng = np.random.default_rng(3)
    fm = np.zeros(len(res.poses_xyt), bool)
    fm[free] = True
    poses = np.asarray(res.poses_xyt) + np.where(fm[:, None], rng.normal(0, 0.05, res.poses_xyt.shape), 0.0)
    landmarks = np.asarray(res.landmarks_xy) + rng.normal(0, 0.05, np.shape(res.landmarks_xy))
    labels = np.asarray(res.assoc)
    r, J = team_joint_residuals(ds.inputs, W, probs, poses, landmarks, labels)
    lm2 = np.empty((4, 2))
    lm2[order] = landmarks
    assert float(r @ r) == pytest.approx(float(np.sum(fun(np.concatenate([poses[free].ravel(), lm2.ravel()])) ** 2)),
                                         rel=1e-12)
    x = np.concatenate([poses[free].ravel(), landmarks.ravel()])
    n_pose = 3 * len(free)
    h = 1e-6
    Jfd = np.empty((len(r), len(x)))
    for k in range(len(x)):
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        pp, pm = poses.copy(), poses.copy()
        pp[free], pm[free] = xp[:n_pose].reshape(-1, 3), xm[:n_pose].reshape(-1, 3)
        rp = team_joint_residuals(ds.inputs, W, probs, pp, xp[n_pose:].reshape(-1, 2), labels)[0]
        rm = team_joint_residuals(ds.inputs, W, probs, pm, xm[n_pose:].reshape(-1, 2), labels)[0]
        Jfd[:, k] = (rp - rm) / (2 * h)
    assert np.abs(J.toarray() - Jfd).max() < 1e-6 * max(1.0, np.abs(Jfd).max())


def test_team_icm_verdict_follows_the_numbers():
    from slamcli.reproduce.real_multi import team_icm_verdict

    rows = [{"icm_joint": 0.12, "graph_joint": 0.11}, {"icm_joint": 0.10, "graph_joint": 0.11}]
    assert "**met**" in team_icm_verdict(rows, "converged")  # 0.110 ≤ 1.1 · 0.110
    assert "**not met** (it stopped at its sweep cap)" in team_icm_verdict(rows, "max_iterations")
    rows[0]["icm_joint"] = 0.15  # mean 0.125 > 0.121
    assert "**not met** (ATE too high)" in team_icm_verdict(rows, "converged")


def test_team_null_matching_drops_a_misread_robot_reading():
    """A reading moved 3 m along its beam (60 σ_r) takes the null value; the clean readings never do."""
    ds = two_robot_world()
    team = ds.inputs.robots
    rng_m = np.array(team.range_m, float)
    rng_m[2] += 3.0
    bad = dataclasses.replace(ds.inputs, robots=dataclasses.replace(team, range_m=rng_m))
    p = IcmParams(correspondences="reported", weights="information", outlier_sigma=7.0, accelerate="joint",
                  accelerate_every=1, joint_iters=20, max_sweeps=30, trace_poses_every=0)
    assert solve_dataset(bad, "icm", p).extra["readings_nulled"] == 1
    assert solve_dataset(ds.inputs, "icm", p).extra["readings_nulled"] == 0


def test_team_cauchy_kernel_weights_match_scipy_cauchy_loss():
    # IRLS with kernel_cost's weights (the weighted mean, repeated) reaches scipy's Cauchy-loss location estimate
    from slamcli.solvers.icm.team import kernel_cost

    y, k = np.array([0.0, 0.1, -0.2, 0.15, 5.0, -4.0]), 0.3
    x = float(np.median(y))
    for _ in range(500):
        w = kernel_cost((x - y) ** 2, k)[1]
        x = float(np.sum(w * y) / np.sum(w))
    ref = least_squares(lambda v: v - y, [np.median(y)], loss="cauchy", f_scale=k, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert x == pytest.approx(ref.x[0], abs=1e-7)  # scipy stops within ~1e-8 of the minimiser
    # the cost is twice scipy's ½ Σ f² ρ(r²/f²) (ICM's energy is ‖r‖², not ½‖r‖²)
    c = kernel_cost((ref.x[0] - y) ** 2, k)[0]
    assert np.sum(c) == pytest.approx(2 * ref.cost, rel=1e-12)


@pytest.mark.slow
def test_team_robust_range_weighted_odometry_only_icm_reaches_its_minimum():
    """robust=cauchy, team_range_weights, team_odometry_only: ICM ends at the minimum of that energy, written here
    from the potentials and minimised by scipy (BFGS)."""
    from scipy.optimize import minimize

    from slamcli.solvers.icm import energy as en

    ds = two_robot_world()
    k = 1.0
    p = IcmParams(correspondences="reported", R=(1.0,), S=(4.0,), Q=(400.0,), max_sweeps=3000, energy_rtol=1e-14,
                  trace_poses_every=0, robust="cauchy", cauchy_k=k, team_range_weights=True,
                  team_odometry_only=True, accelerate="joint", joint_iters=20)
    res = solve_dataset(ds.inputs, "icm", p)
    E = np.asarray(res.trace.objective)
    assert np.all(np.diff(E) <= 1e-12 * E[0])  # still monotone
    assert res.extra["motion_potential"] is False and res.extra["team_range_weights"] is True
    W = en.Weights.from_params((0.0,), (4.0,), (400.0,))
    fun, unpack, free = _icm_reference(ds, W)
    inp, team = ds.inputs, ds.inputs.robots
    nz = inp.noise
    var = lambda r: nz.range_std**2 + (r * nz.bearing_std) ** 2
    r_med = np.median(inp.observations.z[:, 0])
    f = np.concatenate([var(r_med) / var(inp.observations.z[:, 0]), var(r_med) / var(team.range_m)])
    n_chain = 6 * len(team.chain_pairs)

    def energy(v):
        r = fun(v)
        s2 = f * np.sum(r[n_chain:].reshape(-1, 2) ** 2, axis=1)
        return float(np.sum(r[:n_chain] ** 2) + np.sum(k * k * np.log1p(s2 / (k * k))))

    order, v_icm = _reference_vector(res, ds, free)
    assert res.extra["energy_total"] == pytest.approx(energy(v_icm), rel=1e-10)
    ref = minimize(energy, v_icm + 1e-3, method="BFGS", options={"gtol": 1e-10, "maxiter": 20000})
    assert res.extra["energy_total"] <= ref.fun * (1 + 1e-6)
    assert np.max(np.abs(res.poses_xyt - unpack(ref.x)[0])) < 1e-3
