"""Incremental smoothing for on-line SLAM (``--method isam``).

One update per keyframe (a pose with sightings; the odometry between keyframes is composed into one
between factor, :mod:`slamcli.solvers.isam.factors`):

1. the new pose, initialised by the composed odometry, and its between factor;
2. data association of the keyframe's detections against the *current* estimate
   (:mod:`slamcli.solvers.isam.associate`: ``graph``'s detections and χ² gate, with the smoother's joint
   covariance of pose and landmark) — or the sensor's ids;
3. bearing-range factors (``graph``'s GTSAM-exact errors) into the window;
4. one Gauss-Newton step of the window (:mod:`slamcli.solvers.isam.window`): cached whitened linearisations,
   a variable is relinearised only when its step exceeds ``relin_threshold`` (and then only the factors that
   touch it), the dense window system is re-factorised — the marginalised part never is;
5. keyframes older than ``lag_s`` and the landmarks no window pose sees are marginalised into the window's
   prior (Schur complement); a marginalised landmark seen again re-enters with its frozen marginal;
6. at such a loop closure, once ``batch_every_s`` seconds passed since the last one, a batch step: LM over the
   whole keyframe graph, then the window prior is rebuilt exactly from every other factor. The run ends with
   a batch step; ``final_batch`` adds ``graph``'s batch LM over the full graph (every pose).

``-p noise=vce`` (opt-in) re-estimates the noise σ from the smoother's own residuals afterwards (iterated
variance-component estimation, :func:`slamcli.solvers.graph.calibrate_noise`) and returns the batch optimum
under the σ found. The scheme (against GTSAM's iSAM2), its defaults and the noise study were chosen by
measurement: benchmarks/results/isam.md and benchmarks/results/design_notes.md.
"""

from slamcli.solvers.lazy import lazy_exports

_EXPORTS = {
    "IsamParams": "slamcli.solvers.isam.params",
    "IncrementalSmoother": "slamcli.solvers.isam.smoother",
    "IsamSlam": "slamcli.solvers.isam.solver",
    "per_step_slope": "slamcli.solvers.isam.solver",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
