"""Solvers use the motion the dataset holds (``SlamInputs.motion_source``, ``motion_input="auto"``).

A graph file's odometry edges are full SE(2) increments; the controls the importer derives from them
(``[d_x, d_θ]/dt``) lose the sideways part. On a simulated landmark graph whose turns include a 1 m sideways
step, EKF, FastSLAM and ICM (defaults and ``preset=real``) must beat dead reckoning against the simulator's
truth — the reference is that truth, never our own output. Also: ICM's odometry-driven motion terms against
``se2.compose`` and finite differences, the schema round trip of ``motion_source``, and explicit ICM weights
under ``preset=real``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from slamcli.api.solve import solve_dataset
from slamcli.datasets.g2o import import_graph
from slamcli.errors import ConfigError
from slamcli.io import dataset_hash, read_dataset, write_dataset
from slamcli.models import motion, se2
from slamcli.solvers.icm import energy as en

#: odometry increment noise [m, m, rad] and sighting noise (range m, bearing rad) of the simulated graph
ODO_STD = (0.05, 0.05, 0.01)
RANGE_STD, BEARING_STD = 0.1, 0.02
SENSOR_RANGE = 6.0
#: a solver "beats dead reckoning" when its position RMSE is below this fraction of the chain's
BEAT_FRACTION = 0.5


def _num(*values) -> str:
    """Numbers as a g2o line writes them (shortest round-trip decimal)."""
    return " ".join(repr(float(v)) for v in values)


def _sideways_graph(path, seed: int = 0, laps: int = 2, side: int = 10):
    """Write a g2o landmark graph of a robot driving ``laps`` squares of ``side`` m whose every turn is a 1 m
    sideways step with a 90° turn; noisy odometry edges, Cartesian sightings (from noisy range and bearing)
    of 25 landmarks within :data:`SENSOR_RANGE`. Returns the true poses ``(T+1, 3)``."""
    rng = np.random.default_rng(seed)
    inc = np.array(([(1.0, 0.0, 0.0)] * (side - 1) + [(0.0, 1.0, np.pi / 2)]) * (4 * laps))
    T = len(inc)
    truth = motion.chain_increments(np.zeros(3), inc)
    odo = inc + rng.normal(size=inc.shape) * np.asarray(ODO_STD)
    chain = motion.chain_increments(np.zeros(3), odo)
    grid = np.arange(-3.0, 15.0, 4.0)
    lms = np.array([[x, y] for x in grid for y in grid]) + rng.normal(scale=0.5, size=(len(grid) ** 2, 2))
    info = 1.0 / np.square(ODO_STD)
    lines = [f"VERTEX_SE2 {k} {_num(*p)}" for k, p in enumerate(chain)]
    lines += [f"VERTEX_XY {1000 + k} {_num(*m)}" for k, m in enumerate(lms)]
    lines += [f"EDGE_SE2 {t} {t + 1} {_num(*d)} {_num(info[0], 0, 0, info[1], 0, info[2])}"
              for t, d in enumerate(odo)]
    for t in range(T + 1):
        for k, m in enumerate(lms):
            d = m - truth[t, :2]
            r = float(np.hypot(*d))
            if r > SENSOR_RANGE:
                continue
            b = np.arctan2(d[1], d[0]) - truth[t, 2] + BEARING_STD * rng.normal()
            r += RANGE_STD * rng.normal()
            q = 2.0 / (RANGE_STD**2 + (r * BEARING_STD) ** 2)
            lines.append(f"EDGE_SE2_XY {t} {1000 + k} {_num(r * np.cos(b), r * np.sin(b), q, 0, q)}")
    path.write_text("\n".join(lines) + "\n")
    return truth


@pytest.fixture(scope="module")
def sideways(tmp_path_factory):
    path = tmp_path_factory.mktemp("sideways") / "sideways.g2o"
    truth = _sideways_graph(path)
    return import_graph(path).inputs, truth


def _rmse(poses, truth) -> float:
    return float(np.sqrt(np.mean(np.sum((poses[:, :2] - truth[:, :2]) ** 2, axis=1))))


@pytest.mark.parametrize(("method", "params"), [
    ("ekf", {}), ("fastslam", {}), ("icm", {}), ("icm", {"preset": "real"}),
])
def test_odometry_driven_solvers_beat_dead_reckoning_with_sideways_steps(sideways, method, params):
    inputs, truth = sideways
    assert inputs.motion_source == "odometry"
    dead = _rmse(inputs.odometry_xyt, truth)
    res = solve_dataset(inputs, method, params)
    assert res.extra["motion_input"] == "odometry"
    assert _rmse(res.poses_xyt, truth) < BEAT_FRACTION * dead, res.message


@pytest.mark.parametrize(("method", "key"), [("ekf", "motion_input"), ("fastslam", "motion_source")])
def test_the_controls_lose_the_sideways_steps(sideways, method, key):
    """What the default avoids: the controls ``[d_x, d_θ]/dt`` drop every 1 m sideways step, and the filters
    driven by them end worse than the dead-reckoned odometry itself."""
    inputs, truth = sideways
    res = solve_dataset(inputs, method, {key: "controls"})
    assert res.extra["motion_input"] == "controls"
    assert _rmse(res.poses_xyt, truth) > _rmse(inputs.odometry_xyt, truth)


def test_simulated_datasets_keep_their_controls():
    from conftest import tiny_dataset

    inputs = tiny_dataset(T=20).inputs
    assert inputs.motion_source == "controls"
    assert solve_dataset(inputs, "ekf").extra["motion_input"] == "controls"


# -- ICM's motion terms from the odometry increments ------------------------------------------------------------
def test_icm_odometry_motion_terms_are_the_se2_composition(sideways):
    """``g(x, u)`` with ``motion_input=odometry`` is ``x ⊕ d`` (se2.compose), the kinematic init is the
    odometry chain, the sweep's chain energy equals the reference energy, and the joint Jacobian of the
    motion rows matches central finite differences."""
    inputs, _ = sideways
    prob = en.Problem.from_inputs(inputs, motion_input="odometry")
    d = se2.between(inputs.odometry_xyt[:-1], inputs.odometry_xyt[1:])
    rng = np.random.default_rng(3)
    x = inputs.odometry_xyt + rng.normal(scale=0.1, size=inputs.odometry_xyt.shape)
    g = prob.motion_prediction(x[:-1])
    np.testing.assert_allclose(g[:, :2], se2.compose(x[:-1], d)[:, :2], atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (g[:, 2] - se2.compose(x[:-1], d)[:, 2]))), 0, atol=1e-12)
    np.testing.assert_allclose(prob.kinematic_poses()[:, :2], inputs.odometry_xyt[:, :2], atol=1e-9)
    W = en.Weights.from_params((2.0, 3.0, 5.0), (0.0,), (1.0,), 0.0)
    none = np.full(prob.n_obs, -1)
    ref = en.energy_terms(prob, W, x, np.zeros((0, 2)), none)["motion"]
    assert en.chain_energy(prob, W, x) == pytest.approx(ref, rel=1e-12)
    _, J = en.joint_residuals(prob, W, x, np.zeros((0, 2)), none)
    flat, h = x[1:].ravel(), 1e-6
    num = np.empty((J.shape[0], flat.size))
    for k in range(flat.size):
        hi, lo = flat.copy(), flat.copy()
        hi[k] += h
        lo[k] -= h
        r_hi = en.joint_residuals(prob, W, np.vstack([x[:1], hi.reshape(-1, 3)]), np.zeros((0, 2)), none,
                                  jacobian=False)[0]
        r_lo = en.joint_residuals(prob, W, np.vstack([x[:1], lo.reshape(-1, 3)]), np.zeros((0, 2)), none,
                                  jacobian=False)[0]
        num[:, k] = (r_hi - r_lo) / (2 * h)
    np.testing.assert_allclose(J.toarray(), num, atol=1e-6)


# -- explicit parameters under a preset -------------------------------------------------------------------------
def test_icm_preset_keeps_explicit_weights_and_says_so(sideways):
    """``preset=real`` on data with ids sets weights=information, which would replace R and S by the noise
    model; given explicitly they are kept (the motion potential then has weight 0) and the result says so."""
    inputs, _ = sideways
    res = solve_dataset(inputs, "icm", {"preset": "real", "R": [0.0], "S": [1.0]})
    assert res.extra["weights"] == "design"
    assert res.extra["weights_used"]["R"] == [0.0, 0.0, 0.0] and res.extra["weights_used"]["S"] == [1.0, 1.0, 1.0]
    assert res.extra["energy_motion"] == 0.0 and res.extra["energy_odometry"] > 0.0
    assert "weights=information not applied, R, S given explicitly" in res.message
    plain = solve_dataset(inputs, "icm", {"preset": "real"})
    assert plain.extra["weights"] == "information" and "preset_note" not in plain.extra


def test_icm_preset_keeps_a_value_given_equal_to_the_paper_default(sideways, tmp_path):
    """``-p preset=real -p accelerate=none``: the given value is the paper default and still wins over the
    preset, through the API and the command line; what was left unset still comes from the preset and its
    rule for data with ids."""
    from typer.testing import CliRunner

    from slamcli.cli import app
    from slamcli.io import read_result
    from slamcli.solvers.icm.presets import PRESETS, WITH_IDS
    from slamcli.types import Dataset

    inputs, _ = sideways
    given = {"preset": "real", "accelerate": "none", "max_sweeps": 3}
    res = solve_dataset(inputs, "icm", given)
    assert PRESETS["real"]["accelerate"] != "none" and res.extra["accelerate"] == "none"
    assert res.params["accelerate"] == "none" and res.params["max_sweeps"] == 3
    assert res.params["merge"] == PRESETS["real"]["merge"]  # unset: from the preset
    assert res.params["correspondences"] == WITH_IDS["real"]["correspondences"]  # unset: the ids rule
    data = write_dataset(tmp_path / "odo.h5", Dataset(inputs=inputs, truth=None, metadata={}))
    out = tmp_path / "icm.h5"
    args = ["solve", str(data), "-m", "icm", "-o", str(out)] + [x for k, v in given.items() for x in ("-p", f"{k}={v}")]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    cli = read_result(out)
    assert cli.params["accelerate"] == "none" and cli.extra["accelerate"] == "none"
    assert cli.params["correspondences"] == "reported"


def test_icm_explicit_weights_with_information_weights_is_one_line_error(sideways):
    inputs, _ = sideways
    with pytest.raises(ConfigError) as exc:
        solve_dataset(inputs, "icm", {"weights": "information", "R": [0.0]})
    assert "R given with weights=information" in str(exc.value) and "\n" not in str(exc.value)


# -- the dataset field ------------------------------------------------------------------------------------------
def test_motion_source_round_trips_and_enters_the_hash(sideways, tmp_path):
    inputs, _ = sideways
    from slamcli.types import Dataset

    ds = Dataset(inputs=inputs, truth=None, metadata={"scenario": "sideways"})
    back = read_dataset(write_dataset(tmp_path / "odo.h5", ds))
    assert back.inputs.motion_source == "odometry" and dataset_hash(back) == dataset_hash(ds)
    as_controls = Dataset(inputs=dataclasses.replace(inputs, motion_source="controls"), truth=None,
                          metadata={"scenario": "sideways"})
    assert dataset_hash(as_controls) != dataset_hash(ds)
    import h5py

    plain = write_dataset(tmp_path / "ctl.h5", as_controls)
    with h5py.File(plain, "r") as f:
        assert "motion_source" not in f["inputs"].attrs  # older readers see the file they know
    assert read_dataset(plain).inputs.motion_source == "controls"
