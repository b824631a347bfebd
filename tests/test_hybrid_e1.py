"""Estimator E1 (eq. 12 / E2 with the true pose as the only sample) recovers a known wall map."""

import numpy as np

from slamcli.metrics.occupancy import grid_errors
from slamcli.models.occupancy import band_for
from slamcli.sim.scenarios import resolve_scenario
from slamcli.sim.simulate import simulate
from slamcli.solvers.hybrid.frequentist import ScanGeometry, e2_update, trace_scan
from slamcli.solvers.hybrid.solver import grid_for_trajectory, scan_table
from slamcli.types import OccupancyGrid


def test_e1_with_known_pose_recovers_the_map():
    # a small square corridor (30 m, corridor 6 m), laser, one lap
    cfg = resolve_scenario("hybrid-map1", {"walls.width": 30, "walls.height": 30, "walls.corridor": 6,
                                           "walls.laps": 1, "sensor.n_beams": 90, "sensor.max_range": 15.0})
    ds = simulate(cfg, 0)
    alphas, ranges = scan_table(ds.inputs, 1)
    poses = ds.truth.poses_xyt  # E1: the pose is known (test only — a solver never sees it)
    spec = grid_for_trajectory(poses, 17.0, 0.5, 0.5)
    n = ds.inputs.noise
    geo = ScanGeometry(alphas, 15.0, n.range_std, n.bearing_std)
    band = band_for(np.hypot(n.range_std, 15 * n.bearing_std), 0.5)
    P = np.full(spec.n_cells, 0.5)
    cnt = np.zeros(spec.n_cells, np.int32)
    for t in range(len(poses)):
        rb = trace_scan(spec, poses[t : t + 1], ranges[t], geo, band, True)
        e2_update(P, cnt, spec, rb, np.ones(len(alphas)), poses[t, :2], t + 1, a=0.5, alpha=0.6, step_clock="cell",
                  band=band, min_traversal=0.05, max_cell_dist=40.0, free_margin=1.5)
    g = OccupancyGrid(np.asarray(spec.origin_xy), spec.resolution, P.reshape(spec.shape), cnt.reshape(spec.shape))
    e = grid_errors(g, ds.truth.occupancy)
    assert e["n_observed"] > 1500
    assert e["mean_abs_error"] < 0.02, e
    assert e["accuracy"] > 0.99, e
