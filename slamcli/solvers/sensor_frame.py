"""Motion-model dispatch and the sensor-frame change that gives every solver the sensor mounting offset.

A solver class declares the motion models it implements in ``motion_models`` (default ``("ddmr",)``);
:func:`check_motion_model` refuses a dataset with any other model in one line, instead of running the wrong
kinematics.

Sensor offset. A sensor mounted at ``o = (a, b)`` in the body frame sees range-bearing from the sensor pose
``s_t = x_t ⊕ [a, b, 0]`` (:func:`slamcli.models.observation.sensor_pose`). Rather than re-deriving every
solver's measurement Jacobians, :func:`to_sensor_frame` re-expresses the problem in the sensor's frame, as
Guivant & Nebot do for Victoria Park (their EKF state is the laser pose):

* ``x0 → x0 ⊕ o``, ``odometry_xyt → odometry_xyt ⊕ o`` (exact: ``between(s_{t-1}, s_t) = o⁻¹ ⊕ d_t ⊕ o``);
* the car model propagates the point ``(a, b)`` (``AckermannParams.ref_x_m/ref_y_m``);
* observations are then offset-free range-bearing from the state pose.

:func:`result_to_body` maps the estimate back: ``x_t = s_t ⊕ [−a, −b, 0]`` (same heading), pose covariances
``J P Jᵀ`` with ``J = ∂x/∂s``. Landmarks are world points and do not change.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from slamcli.errors import SolverError
from slamcli.models.observation import body_pose_from_sensor, sensor_pose, sensor_pose_jacobian
from slamcli.types import SlamInputs, SolverResult


def supported_motion_models(solver) -> tuple[str, ...]:
    """``solver.motion_models`` (class attribute), default ``("ddmr",)`` for plugins that do not declare it."""
    return tuple(getattr(solver, "motion_models", ("ddmr",)))


def check_motion_model(solver, method: str, inputs: SlamInputs) -> None:
    """One-line :class:`SolverError` when ``method`` does not implement ``inputs.motion_model``."""
    models = supported_motion_models(solver)
    if inputs.motion_model not in models:
        raise SolverError(f"solver {method!r} supports the motion model(s) {', '.join(models)}, but the dataset "
                          f"uses {inputs.motion_model!r}; it refuses rather than run the wrong kinematics")


def check_multi_robot(solver, method: str, inputs: SlamInputs) -> None:
    """One-line :class:`SolverError` when ``inputs`` is a multi-robot dataset (``inputs.robots``) and the solver
    does not declare ``multi_robot = True`` (it would chain odometry from one robot into the next)."""
    team = getattr(inputs, "robots", None)
    if team is not None and not getattr(solver, "multi_robot", False):
        raise SolverError(f"solver {method!r} does not support multi-robot data ({team.n_robots} robots in one "
                          "dataset); use graph or icm, or solve one robot alone (slamcli.datasets.team.solo_dataset)")


def to_sensor_frame(inputs: SlamInputs) -> SlamInputs:
    """The same problem with the state at the sensor (``sensor_offset_xy`` becomes zero); identity when the
    sensor already sits at the body origin."""
    off = np.asarray(inputs.sensor_offset_xy, float).reshape(2)
    if not off.any():
        return inputs
    if inputs.motion_model == "ddmr":
        raise SolverError("a sensor offset with the ddmr motion model is not supported (the DDMR controls drive "
                          "the body origin); use motion_model='ackermann' or a zero offset")
    if getattr(inputs, "constraints", None) is not None:
        raise SolverError("pose-pose constraints with a sensor offset are not supported (they relate body poses)")
    if len(inputs.gps_step):
        raise SolverError("GPS inputs with a sensor offset are not supported (the fixes refer to the body origin, "
                          "the solver state to the sensor)")
    vehicle = inputs.vehicle
    if vehicle is not None:
        vehicle = dataclasses.replace(vehicle, ref_x_m=float(off[0]), ref_y_m=float(off[1]))
    return dataclasses.replace(
        inputs,
        x0=sensor_pose(inputs.x0, off),
        odometry_xyt=sensor_pose(inputs.odometry_xyt, off),
        vehicle=vehicle,
        sensor_offset_xy=np.zeros(2),
    )


def result_to_body(result: SolverResult, offset_xy) -> SolverResult:
    """Map a result computed by :func:`to_sensor_frame` back to body poses (identity for a zero offset)."""
    off = np.asarray(offset_xy, float).reshape(2)
    if not off.any():
        return result
    s = np.asarray(result.poses_xyt, float)
    poses = body_pose_from_sensor(s, off)
    pose_cov = result.pose_cov
    if pose_cov is not None:
        J = sensor_pose_jacobian(s, -off)  # ∂(s ⊕ [−a, −b, 0])/∂s
        pose_cov = J @ np.asarray(pose_cov, float) @ np.swapaxes(J, -1, -2)
    trace = result.trace
    if trace is not None and trace.poses_xyt is not None:
        trace = dataclasses.replace(trace, poses_xyt=body_pose_from_sensor(trace.poses_xyt, off))
    extra = dict(result.extra)
    extra["solved_in_sensor_frame"] = [float(off[0]), float(off[1])]
    return dataclasses.replace(result, poses_xyt=poses, pose_cov=pose_cov, trace=trace, extra=extra)
