"""Suite-wide pytest hooks, paths and shared worlds.

Paths: :data:`TESTS`, :data:`DATA` (the recording excerpts), :data:`ROOT` (the repository). Worlds, built directly
from ``slamcli.models`` with a seeded generator (the truth stays with the test, never goes to a solver):
:func:`drive_world` (the one generator), :func:`tiny_dataset`, :func:`car_world`, :func:`make_dataset` with
:func:`make_result`, and :func:`write_sweep_table` (a sweep's results table). Test modules import them with
``from conftest import ...`` (pytest puts ``tests/`` on ``sys.path`` when it loads this file).

The hooks: what a test reports is sent between pytest-xdist's processes as UTF-8, and the
bad-input tests make file names that are not UTF-8 (legal on Linux, ``\\udcXX`` in Python strings); a report or
warning naming one would otherwise end the whole run with an internal error. Such bytes are shown escaped."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from slamcli.models import motion, observation
from slamcli.models.ackermann import VICTORIA_PARK, VICTORIA_PARK_LASER_XY, integrate_ackermann
from slamcli.types import (
    Dataset,
    GroundTruth,
    IterationTrace,
    NoiseSpec,
    Observations,
    SlamInputs,
    SolverResult,
    Status,
)

TESTS = Path(__file__).resolve().parent
DATA = TESTS / "data"
ROOT = TESTS.parent


def _utf8(text: str) -> str:
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


@pytest.hookimpl(tryfirst=True)
def pytest_warning_recorded(warning_message, when, nodeid, location):
    text = str(warning_message.message)
    if _utf8(text) != text:
        category = type(warning_message.message)
        warning_message.message = category(_utf8(text)) if issubclass(category, Warning) else _utf8(text)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    report = (yield).get_result()
    if report.longrepr is not None and _utf8(str(report.longrepr)) != str(report.longrepr):
        report.longrepr = _utf8(str(report.longrepr))
    report.sections = [(title, _utf8(text)) for title, text in report.sections]


@pytest.fixture()
def shared_datasets(tmp_path, monkeypatch):
    """``lay_out({registry folder: tests/data excerpt})``: a shared datasets folder ``tmp_path/shared``
    (``$SLAMCLI_DATASETS``) holding copies of those excerpts under the registry's folder names, an empty data
    folder ``tmp_path/cache`` for the import cache, and no user registry; returns ``tmp_path``."""
    import shutil

    from slamcli.datasets import registry as reg

    def lay_out(folders: dict[str, str]):
        root = tmp_path / "shared"
        for folder, excerpt in folders.items():
            shutil.copytree(DATA / excerpt, root / folder)
        monkeypatch.setenv(reg.ENV_SHARED, str(root))
        monkeypatch.setenv(reg.ENV_DATA_DIR, str(tmp_path / "cache"))
        monkeypatch.delenv(reg.ENV_REGISTRY, raising=False)
        return tmp_path

    return lay_out


# ------------------------------------------------------------------------------------------------ worlds
def drive_world(
    seed: int,
    landmarks_xy,
    *,
    T: int,
    dt: float = 0.1,
    v: float = 1.0,
    omega: float,
    motion_std=(0.05, 0.02),
    odometry_std=(0.01, 0.01, 0.005),
    range_std: float = 0.05,
    bearing_std: float = 0.01,
    max_range: float = 6.0,
    clutter_per_step: float = 0.0,
    clutter_every: int = 0,
    report_ids: bool = True,
    gps_every: int = 0,
) -> Dataset:
    """A robot commanded ``[v, omega]`` for ``T`` steps of ``dt`` s from the origin among ``landmarks_xy (L, 2)``.

    Draws, in this order, from ``default_rng(seed)``: executed-control noise ``(T, 2)·motion_std``, odometry
    increment noise ``(T, 3)·odometry_std``, then per pose: range/bearing noise of each landmark within
    ``max_range``, Poisson(``clutter_per_step``) clutter returns, one clutter return when
    ``t % clutter_every == 3``; last, GPS fixes (σ 0.3 m) every ``gps_every`` poses. Clutter rows have true
    landmark −1; reported ids are the true ones when ``report_ids``, else −1. Metadata is empty.
    """
    rng = np.random.default_rng(seed)
    landmarks_xy = np.asarray(landmarks_xy, float)
    motion_std = np.asarray(motion_std, float)
    odometry_std = np.asarray(odometry_std, float)
    x0 = np.array([0.0, 0.0, 0.0])
    controls = np.tile([v, omega], (T, 1))
    poses = motion.integrate(x0, controls + rng.standard_normal((T, 2)) * motion_std, dt)
    increments = motion.odometry_increments(poses) + rng.standard_normal((T, 3)) * odometry_std
    odometry = motion.chain_increments(x0, increments)
    steps, z_rows, labels = [], [], []
    for t in range(T + 1):
        z = observation.range_bearing(poses[t], landmarks_xy)
        for j in np.flatnonzero(z[:, 0] <= max_range):
            steps.append(t)
            z_rows.append(z[j] + rng.standard_normal(2) * [range_std, bearing_std])
            labels.append(j)
        n_clutter = rng.poisson(clutter_per_step) if clutter_per_step else 0
        n_clutter += bool(clutter_every) and t % clutter_every == 3
        for _ in range(n_clutter):
            steps.append(t)
            z_rows.append([rng.uniform(0.5, max_range), rng.uniform(-np.pi, np.pi)])
            labels.append(-1)
    labels = np.asarray(labels, np.int64)
    obs = Observations.from_rows(steps, z_rows, T + 1, reported_id=labels if report_ids else None)
    gps_step = np.arange(0, T + 1, gps_every, dtype=np.int64) if gps_every else np.zeros(0, np.int64)
    gps_xy = poses[gps_step, :2] + rng.normal(0.0, 0.3, (len(gps_step), 2)) if gps_every else np.zeros((0, 2))
    inputs = SlamInputs(
        dt=dt,
        timestamps=np.arange(T + 1) * dt,
        x0=x0,
        controls=controls,
        odometry_xyt=odometry,
        observations=obs,
        noise=NoiseSpec(
            motion_std=motion_std, odometry_std=odometry_std, range_std=range_std, bearing_std=bearing_std
        ),
        max_range=max_range,
        gps_step=gps_step,
        gps_xy=gps_xy,
        gps_std=0.3 if gps_every else 0.0,
    )
    truth = GroundTruth(poses_xyt=poses, landmarks_xy=landmarks_xy, obs_landmark=labels)
    return Dataset(inputs=inputs, truth=truth, metadata={})


def tiny_dataset(
    T: int = 40,
    n_landmarks: int = 6,
    seed: int = 0,
    *,
    clutter_every: int = 7,
    report_ids: bool = False,
    gps_every: int = 0,
    max_range: float = 6.0,
) -> Dataset:
    """The tiny world of the io, solve, CLI and solver-contract tests: an arc at 1 m/s, 0.25 rad/s past
    ``n_landmarks`` on a 3 m circle around (2, 1), low noise, a clutter return every ``clutter_every`` poses."""
    ang = np.linspace(0.0, 2 * np.pi, n_landmarks, endpoint=False)
    landmarks = np.column_stack([2.0 + 3.0 * np.cos(ang), 1.0 + 3.0 * np.sin(ang)])
    ds = drive_world(
        seed, landmarks, T=T, omega=0.25, motion_std=(0.02, 0.01), odometry_std=(0.005, 0.005, 0.002),
        max_range=max_range, clutter_every=clutter_every, report_ids=report_ids, gps_every=gps_every,
    )
    metadata = {
        "seed": seed,
        "scenario": "tiny-test",
        "scenario_params": {"T": T, "n_landmarks": n_landmarks, "max_range": max_range},
        "sensor": {"kind": "point", "range_std": 0.05, "bearing_std": 0.01},
        "robot": {"v": 1.0, "omega": 0.25},
    }
    return dataclasses.replace(ds, metadata=metadata)


CAR_LASER_XY = np.array(VICTORIA_PARK_LASER_XY)  # the laser's mounting point on the car, body frame, m


def car_world(seed: int = 0, T: int = 600, dt: float = 0.025) -> Dataset:
    """A car (Victoria Park Ackermann model) at 4 m/s with a sinusoidal steer among 40 landmarks, seen every
    0.2 s by a forward laser mounted at :data:`CAR_LASER_XY` (range < 30 m, |bearing| < π/2), known ids."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) * dt
    cmd = np.column_stack([np.full(T, 4.0), 0.25 * np.sin(2 * np.pi * t / 10.0)])
    sv, sa = 0.05, 0.005
    executed = cmd + rng.normal(size=cmd.shape) * [sv, sa]
    x0 = np.array([0.0, 0.0, 0.3])
    true = integrate_ackermann(x0, executed, dt, VICTORIA_PARK)
    lo, hi = true[:, :2].min(0) - 20, true[:, :2].max(0) + 20
    lms = rng.uniform(lo, hi, size=(40, 2))
    steps, zs, ids = [], [], []
    for k in range(0, T + 1, 8):  # a scan every 0.2 s
        z = observation.range_bearing_offset(true[k], lms, CAR_LASER_XY)
        vis = np.flatnonzero((z[:, 0] < 30.0) & (np.abs(z[:, 1]) < np.pi / 2))
        for j in vis:
            steps.append(k)
            zs.append(z[j] + rng.normal(size=2) * [0.05, 0.005])
            ids.append(j)
    obs = Observations.from_rows(steps, np.array(zs), T + 1, reported_id=ids)
    odo = integrate_ackermann(x0, cmd, dt, VICTORIA_PARK)
    noise = NoiseSpec(motion_std=np.array([sv, sa]), odometry_std=np.array([0.003, 0.002, 0.0005]),
                      range_std=0.05, bearing_std=0.005)
    inp = SlamInputs(dt=dt, timestamps=np.asarray(t.tolist() + [T * dt]), x0=x0, controls=cmd, odometry_xyt=odo,
                     observations=obs, noise=noise, motion_model="ackermann", vehicle=VICTORIA_PARK,
                     sensor_offset_xy=CAR_LASER_XY.copy())
    return Dataset(inputs=inp, truth=GroundTruth(true, lms, np.asarray(ids)), metadata={})


def make_dataset(seed=0, T=40):
    """A circle-ish drive past 6 landmarks; every landmark within 8 m is observed without noise."""
    rng = np.random.default_rng(seed)
    dt = 0.5
    controls = np.column_stack([np.full(T, 1.0), np.full(T, 0.15)])
    true = motion.integrate(np.zeros(3), controls, dt)
    odo = motion.integrate(np.zeros(3), controls + rng.normal(0, [0.05, 0.02], (T, 2)), dt)
    lms = np.array([[2.0, 3.0], [6.0, -1.0], [8.0, 5.0], [3.0, 9.0], [-2.0, 6.0], [5.0, 12.0]])
    steps, z, ids = [], [], []
    for t in range(T + 1):
        zz = observation.range_bearing(true[t][None], lms)
        for j in np.flatnonzero(zz[:, 0] < 8.0):
            steps.append(t)
            z.append(zz[j])
            ids.append(j)
    steps = np.array(steps, np.int64)
    z = np.array(z)
    obs = Observations(steps, z[:, 0], z[:, 1], np.zeros(len(steps), np.int16), np.full(len(steps), -1, np.int64),
                       Observations.offsets_from_steps(steps, T + 1))
    noise = NoiseSpec(np.array([0.05, 0.02]), np.array([0.02, 0.02, 0.01]), 0.1, 0.02)
    inputs = SlamInputs(dt, np.arange(T + 1) * dt, np.zeros(3), controls, odo, obs, noise, 8.0)
    truth = GroundTruth(true, lms, np.array(ids, np.int64))
    return Dataset(inputs, truth, {"seed": seed, "scenario": "test-circle"})


def make_result(ds, data_path, *, offset=(0.0, 0.2), covariances=True, rng_seed=1):
    """A result for :func:`make_dataset`: the true poses shifted by ``offset`` m, landmarks 0-4 with 5 cm noise
    (landmark 5 missed), a three-iteration trace, constant covariances unless ``covariances=False``."""
    from slamcli.io import dataset_hash

    rng = np.random.default_rng(rng_seed)
    T1 = len(ds.truth.poses_xyt)
    est = ds.truth.poses_xyt.copy()
    est[:, :2] += offset
    lm = ds.truth.landmarks_xy[:5] + rng.normal(0, 0.05, (5, 2))  # landmark 5 missed
    trace = IterationTrace.from_lists([3.0, 2.0, 1.0], [0.0, 0.0, 0.0], [0.1, 0.1, 0.1],
                                      [lm + 0.4, lm + 0.1, lm])
    pc = lc = None
    if covariances:
        pc = np.broadcast_to(np.diag([0.04, 0.04, 0.01]), (T1, 3, 3)).copy()
        lc = np.broadcast_to(np.eye(2) * 0.0025, (5, 2, 2)).copy()
    return SolverResult("toy", "0", {}, Status.CONVERGED, "", est, lm, np.full(len(ds.inputs.observations), -1),
                        pose_cov=pc, landmark_cov=lc, trace=trace, dataset_hash=dataset_hash(ds),
                        extra={"dataset_path": str(data_path)})


def write_sweep_table(d):
    """``d/results.csv``, a hand-made sweep results table: ekf with an integer parameter (absent for odometry),
    one failed run; returns the typed frame."""
    from slamcli.metrics.aggregate import typed_frame

    rows = []
    ate = {("ekf", 2): [1.0, 2.0, 3.0, 4.0], ("ekf", 5): [0.5, 0.7], ("odometry", None): [10.0, 12.0, 14.0]}
    k = 0
    for (label, hits), values in ate.items():
        for v in values:
            row = {"run_id": f"r{k}", "label": label, "method": label, "replicate": k, "status": "completed",
                   "ate_rmse_m": v, "solve_time_s": 0.1 * k}
            if hits is not None:
                row["solver.ekf.provisional_min_hits"] = hits
            rows.append(row)
            k += 1
    rows.append({"run_id": "bad", "label": "ekf", "method": "ekf", "replicate": 99, "status": "failed",
                 "solver.ekf.provisional_min_hits": 2, "ate_rmse_m": None})
    df = typed_frame(rows)
    d.mkdir(parents=True, exist_ok=True)
    df.to_csv(d / "results.csv", index=False)
    return df
