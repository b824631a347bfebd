"""Sydney Victoria Park importer (ACFR utility car, SICK laser, tree trunks as landmarks) → slamcli dataset.

Source: Guivant & Nebot, IEEE T-RA 17(3), 2001; the ASCII conversion shipped with K. Leung's RFS-SLAM
(``data/VictoriaPark``). Files read (whitespace separated, seconds since the start): ``inputs.dat`` (time,
rear-left encoder speed v_e [m/s], steering α [rad]; 40 Hz, uniform), ``measurements.dat`` (time, range [m],
bearing [rad] in the laser frame, 0..π with π/2 ahead, trunk diameter [m]; no identities) and ``gps.dat``
(time, x [m], y [m]; position only, gaps up to 58 s).

* **Poses** at the input stamps (uniform ``dt``, zero-order hold); ``controls = [v_e, α]`` with
  ``motion_model = "ackermann"`` and :data:`slamcli.models.ackermann.VICTORIA_PARK`; body frame = rear-axle
  centre, laser at ``sensor_offset_xy``; ``x0 = 0`` (the GPS frame's heading is unknown, so GPS ATE is
  SE(2)-aligned); ``odometry_xyt`` integrates the car model (:func:`slamcli.models.ackermann.integrate_ackermann`).
* **Measurements**: a scan goes to the nearest pose, ``k = round((t − t_0)/dt)`` (the largest timing error is
  in ``metadata["max_timing_error_s"]``); bearing ``b = b_laser − π/2``; ``reported_id = −1``; the trunk
  diameter per row in ``observations.diameter_m`` (ranges behave as centre ranges, so no offset is added).
* **Reference**: GPS fixes as a position-only truth of the laser point (``GroundTruth.ref_time_s/ref_xy``,
  ``ref_offset_xy``); no true poses, landmarks or association exist.

Noise defaults (σ_v 0.5 m/s, σ_α 3°, σ_r 0.5 m, σ_b 0.5°) are deliberately conservative: they also set the
association gate, and calibrated values split trees into many landmarks (chosen by measurement:
benchmarks/results/design_notes.md, benchmarks/results/vp_noise.md; procedure: :mod:`slamcli.api.calibrate`).
``--range-std``/``--bearing-std`` choose others; ``isam -p noise=vce`` calibrates after associating.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from slamcli.datasets import DatasetImportError
from slamcli.metrics.reference import gaps as reference_gaps
from slamcli.models.ackermann import VICTORIA_PARK, VICTORIA_PARK_LASER_XY, integrate_ackermann
from slamcli.types import Dataset, GroundTruth, NoiseSpec, Observations, SlamInputs

#: Noise a solver may assume. Controls: σ_v 0.5 m/s, σ_α 3° (the values commonly used with this run);
#: laser: σ_r 0.5 m, σ_b 0.5°. Per-step odometry σ follows from them at dt = 0.025 s and a typical 4 m/s:
#: x ≈ σ_v dt, θ ≈ dt v σ_α / L, lateral 5 mm.
DEFAULT_MOTION_STD = (0.5, math.radians(3.0))
DEFAULT_ODOMETRY_STD = (0.0125, 0.005, 0.002)
DEFAULT_RANGE_STD = 0.5
DEFAULT_BEARING_STD = math.radians(0.5)
GPS_GAP_S = 1.0  # a GPS gap is a pause longer than this between fixes (the receiver logs at ~5 Hz)


def default_noise(*, range_std: float | None = None, bearing_std: float | None = None,
                  v_std: float | None = None, steer_std: float | None = None) -> NoiseSpec:
    """The defaults, with any σ replaced; the per-step odometry σ scale with the control σ they follow from
    (x and lateral with σ_v, heading with σ_α)."""
    return car_noise(DEFAULT_MOTION_STD, DEFAULT_ODOMETRY_STD, DEFAULT_RANGE_STD, DEFAULT_BEARING_STD,
                     range_std=range_std, bearing_std=bearing_std, v_std=v_std, steer_std=steer_std)


def car_noise(motion0, odometry0, range0, bearing0, *, range_std=None, bearing_std=None, v_std=None,
              steer_std=None) -> NoiseSpec:
    """A car recording's :class:`NoiseSpec` from its defaults with any σ replaced (shared with the car park)."""
    for name, v in (("range_std", range_std), ("bearing_std", bearing_std), ("v_std", v_std),
                    ("steer_std", steer_std)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise DatasetImportError(f"--{name.replace('_', '-')}: must be a finite number > 0, got {v}")
    m = np.array(motion0, float)
    o = np.array(odometry0, float)
    if v_std is not None:
        o[:2] *= v_std / m[0]
        m[0] = v_std
    if steer_std is not None:
        o[2] *= steer_std / m[1]
        m[1] = steer_std
    return NoiseSpec(motion_std=m, odometry_std=o, range_std=float(range0 if range_std is None else range_std),
                     bearing_std=float(bearing0 if bearing_std is None else bearing_std))


def _load(path: Path, ncol: int) -> np.ndarray:
    if not path.is_file():
        raise DatasetImportError(f"{path}: file not found (expected a Victoria Park ASCII directory)")
    try:
        a = np.loadtxt(path, ndmin=2)
    except ValueError as exc:
        raise DatasetImportError(f"{path}: malformed row ({str(exc).splitlines()[0]})") from None
    if a.size == 0:
        raise DatasetImportError(f"{path}: no rows")
    if a.shape[1] != ncol:
        raise DatasetImportError(f"{path}: expected {ncol} columns, got {a.shape[1]}")
    if not np.isfinite(a).all():
        raise DatasetImportError(f"{path}: non-finite value in row {int(np.argmax(~np.isfinite(a).all(1))) + 1}")
    return a


#: the SICK laser's field of view in its own frame: bearings 0..π (π/2 straight ahead), rad
LASER_FOV_RAD = (0.0, math.pi)
#: slack on the field-of-view bounds for values printed with 5 decimals, rad
FOV_SLACK_RAD = 1e-5


def data_line(path: Path, row: int) -> int:
    """1-based line number in ``path`` of data row ``row`` (0-based; blank and ``#`` lines are skipped)."""
    n = -1
    with open(path, encoding="utf-8", errors="replace") as fh:
        for i, line in enumerate(fh, 1):
            if line.strip() and not line.lstrip().startswith("#"):
                n += 1
                if n == row:
                    return i
    return row + 1


def check_readings(path: Path, meas: np.ndarray) -> None:
    """Refuse physically impossible detections (one line naming the file, line and field).

    Ranges must be > 0 (a trunk at the sensor is not a detection), bearings inside the laser's field of view
    :data:`LASER_FOV_RAD`, trunk diameters >= 0.
    """
    lo, hi = LASER_FOV_RAD
    checks = (("range", 1, meas[:, 1] > 0, "must be > 0 m"),
              ("bearing", 2, (meas[:, 2] >= lo - FOV_SLACK_RAD) & (meas[:, 2] <= hi + FOV_SLACK_RAD),
               f"must lie in the laser's field of view [{lo:g}, {hi:.5f}] rad"),
              ("diameter", 3, meas[:, 3] >= 0, "must be >= 0 m"))
    for field_name, col, ok, what in checks:
        if not ok.all():
            row = int(np.argmax(~ok))
            raise DatasetImportError(f"{path}: line {data_line(path, row)}: {field_name} {meas[row, col]:g} {what}")


def import_victoria_park(directory, *, start: float = 0.0, duration: float | None = None,
                         max_range: float = float("inf"), noise: NoiseSpec | None = None) -> Dataset:
    """Read a Victoria Park ASCII directory (see the module docstring) into a :class:`Dataset`.

    Parameters
    ----------
    start : window start, s after the first input row.
    duration : window length, s (None = to the end).
    max_range : sensor max range to store, m.
    noise : noise to store (None = the defaults above, see "Noise").
    """
    d = Path(directory)
    if not d.is_dir():
        raise DatasetImportError(f"{d}: not a directory")
    inputs = _load(d / "inputs.dat", 3)
    meas = _load(d / "measurements.dat", 4)
    check_readings(d / "measurements.dat", meas)
    if not (max_range > 0):  # nan, 0 and negative; inf = unlimited
        raise DatasetImportError(f"--max-range: must be > 0 (or inf), got {max_range}")
    gps = _load(d / "gps.dat", 3)
    if (back := np.flatnonzero(np.diff(gps[:, 0]) < 0)).size:  # (equal stamps are repeats, dropped below)
        k = int(back[0]) + 1
        raise DatasetImportError(f"{d / 'gps.dat'}: row {k + 1}: time {gps[k, 0]:g} s runs backwards (previous row "
                                 f"{gps[k - 1, 0]:g} s)")
    t_in = inputs[:, 0]
    if len(t_in) < 2 or not (np.diff(t_in) > 0).all():
        raise DatasetImportError(f"{d / 'inputs.dat'}: times must be strictly increasing with >= 2 rows")
    dt = float(np.median(np.diff(t_in)))
    if np.abs(np.diff(t_in) - dt).max() > 1e-3:
        k = int(np.argmax(np.abs(np.diff(t_in) - dt)))
        raise DatasetImportError(f"{d / 'inputs.dat'}: not a uniform log (dt {dt:g} s, but row {k + 2} is "
                                 f"{t_in[k + 1] - t_in[k]:g} s after the previous)")
    if not (start >= 0 and math.isfinite(start)):
        raise DatasetImportError(f"--start: must be a finite number >= 0, got {start}")
    if duration is not None and not (duration > 0 and math.isfinite(duration)):
        raise DatasetImportError(f"--duration: must be a finite number > 0, got {duration}")
    t_lo = t_in[0] + start
    t_hi = t_in[-1] if duration is None else t_lo + duration
    keep = (t_in >= t_lo - 1e-9) & (t_in <= t_hi + 1e-9)
    if keep.sum() < 2:
        raise DatasetImportError(f"{d / 'inputs.dat'}: window [{t_lo:g}, {t_hi:g}] s holds fewer than 2 input rows")
    rows = inputs[keep]
    ts = rows[:, 0].copy()
    T = len(ts) - 1
    controls = rows[:-1, 1:3].copy()

    k = np.rint((meas[:, 0] - ts[0]) / dt).astype(np.int64)
    in_win = (k >= 0) & (k <= T)
    m = meas[in_win]
    k = k[in_win]
    order = np.argsort(k, kind="stable")
    m, k = m[order], k[order]
    timing_err = np.abs(m[:, 0] - ts[k]) if len(k) else np.zeros(0)
    z = np.column_stack([m[:, 1], m[:, 2] - np.pi / 2])
    observations = Observations.from_rows(k, z, T + 1)
    import dataclasses

    observations = dataclasses.replace(observations, diameter_m=m[:, 3].copy())

    x0 = np.zeros(3)
    odo = integrate_ackermann(x0, controls, dt, VICTORIA_PARK)
    if noise is None:
        noise = default_noise()
    inp = SlamInputs(dt=dt, timestamps=ts, x0=x0, controls=controls, odometry_xyt=odo, observations=observations,
                     noise=noise, max_range=float(max_range), motion_model="ackermann", vehicle=VICTORIA_PARK,
                     sensor_offset_xy=np.array(VICTORIA_PARK_LASER_XY, float))
    g_in = (gps[:, 0] >= ts[0]) & (gps[:, 0] <= ts[-1])
    gps = gps[g_in]
    # gps.dat may repeat a stamp; keep the first of equal stamps so reference times increase strictly
    if len(gps):
        first = np.concatenate([[True], np.diff(gps[:, 0]) > 0])
        gps = gps[first]
    # GPS positions are compared with the laser point, as on the car park (where the laser point fits the GPS
    # to 0.13 m, the rear axle to 3.4 m); here dead reckoning over the first 60 s: laser 1.4 m, rear axle 2.1 m
    truth = GroundTruth(poses_xyt=None, landmarks_xy=None, obs_landmark=None, ref_time_s=gps[:, 0].copy(),
                        ref_xy=gps[:, 1:3].copy(), ref_offset_xy=np.array(VICTORIA_PARK_LASER_XY, float))
    gaps = reference_gaps(truth.ref_time_s, float(ts[0]), float(ts[-1]), GPS_GAP_S)
    meta = {
        "source": "victoria_park",
        "source_dir": str(d.resolve()),
        "scenario": "victoria_park",
        "motion_model": "ackermann",
        "vehicle": {"wheelbase_m": VICTORIA_PARK.wheelbase_m, "encoder_offset_m": VICTORIA_PARK.encoder_offset_m,
                    "laser_xy_m": list(VICTORIA_PARK_LASER_XY)},
        "window_s": [float(ts[0]), float(ts[-1])],
        "n_scans": int(len(np.unique(m[:, 0]))),
        "max_timing_error_s": float(timing_err.max()) if len(timing_err) else 0.0,
        "n_gps_fixes": int(len(gps)),
        "gps_gaps_over_1s": len(gaps),
        "gps_longest_gap_s": max((b - a for a, b in gaps), default=0.0),
        "truth": "GPS positions only (no true poses, landmarks or association)",
    }
    return Dataset(inputs=inp, truth=truth, metadata=meta)
