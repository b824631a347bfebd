"""UTIAS MRCLAM importer: one robot of a Multi-Robot Cooperative Localization and Mapping dataset → slamcli.

Source: Leung, Halpern, Barfoot & Liu, IJRR 30(8), 2011: five differential-drive robots whose cameras read
15 barcoded landmarks and each other, with motion-capture truth. Files read (``#`` comment lines, whitespace
separated, Unix seconds): ``Barcodes.dat`` (subject, barcode), ``Landmark_Groundtruth.dat`` (subject, x, y,
σ_x, σ_y), ``RobotN_Odometry.dat`` (time, v, ω; ~100 Hz with gaps and duplicate stamps),
``RobotN_Measurement.dat`` (time, barcode, range, bearing) and ``RobotN_Groundtruth.dat`` (time, x, y, θ).

On the fixed-rate schema (pose k at ``t_k = t_start + k·dt``):

* **Controls**: the velocity log as a zero-order hold, averaged over each step,
  ``u_k = (F(t_{k+1}) − F(t_k)) / dt`` with ``F`` its running integral (:func:`zoh_average`); the odometry is
  their dead reckoning (MRCLAM's "odometry" is this velocity log).
* **Measurements**: each row to the nearest step (timing error ≤ dt/2, the largest in
  ``metadata["max_timing_error_s"]``); landmark subjects become indices ``0..L-1`` and ``reported_id`` (the
  barcode is a sensor-reported identity); barcode misreads are −1 in ``truth.obs_landmark``; rows seeing a
  robot or an unknown barcode are dropped (``non_landmark="drop"``) or kept as clutter.
* **Stamp order**: isolated out-of-order rows are sorted into place and equal stamps keep the last row (listed
  in ``metadata["stamp_repairs"]``); disorder a local sort cannot explain is refused.
* **Start and truth**: ``x0`` is the truth at ``t_start``; true poses are the motion capture interpolated at
  ``t_k`` (heading on the circle); landmarks from ``Landmark_Groundtruth.dat``.

``timestamps`` count from ``t_ref = max(first odometry stamp + control_delay, first truth stamp)`` (Unix time
in ``metadata["time_origin_unix_s"]``). Noise defaults: :func:`default_noise`, :func:`residual_noise`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from slamcli.datasets import DatasetImportError
from slamcli.models.angles import angle_diff, wrap_angle
from slamcli.models.motion import integrate
from slamcli.models.observation import range_bearing
from slamcli.models.se2 import interpolate_poses
from slamcli.numerics import TIME_EPS_S
from slamcli.params import check_allocation
from slamcli.types import Dataset, GroundTruth, NoiseSpec, Observations, SlamInputs

#: Standard deviations a solver may assume for MRCLAM: the upper end of what :func:`residual_noise` finds
#: against the motion-capture truth of the five robots (chosen by measurement: benchmarks/results/design_notes.md).
DEFAULT_RANGE_STD = 0.15
DEFAULT_BEARING_STD = 0.02
DEFAULT_MOTION_STD = (0.015, 0.07)
DEFAULT_LATERAL_STD_PER_M = 0.05  # lateral slip σ per metre travelled, for odometry_std[1]


#: memory one resampled pose step takes while importing (stamps, controls, odometry, truth and temporaries), B
BYTES_PER_STEP = 256


def default_noise(dt: float) -> NoiseSpec:
    """The default :class:`NoiseSpec` for sampling period ``dt`` (see the module constants).

    ``odometry_std = [σ_v dt, λ·v_max dt, σ_ω dt]`` with v_max = 0.1 m/s (the Create's top speed in MRCLAM) and
    λ = :data:`DEFAULT_LATERAL_STD_PER_M`; the lateral term keeps the increment covariance positive definite.
    """
    sv, sw = DEFAULT_MOTION_STD
    return NoiseSpec(
        motion_std=np.array([sv, sw], float),
        odometry_std=np.array([sv * dt, DEFAULT_LATERAL_STD_PER_M * 0.1 * dt, sw * dt], float),
        range_std=DEFAULT_RANGE_STD,
        bearing_std=DEFAULT_BEARING_STD,
    )


def noise_from_options(dt: float, range_std: float | None = None, bearing_std: float | None = None,
                       v_std: float | None = None, omega_std: float | None = None) -> NoiseSpec | None:
    """The :class:`NoiseSpec` of ``slamcli import mrclam --range-std/--bearing-std/--v-std/--omega-std``:
    :func:`default_noise` ``(dt)`` with the given values (σ_v also sets the odometry's ``σ_v·dt``, σ_ω its
    ``σ_ω·dt``); ``None`` when none is given (the importer's default). One-line
    :class:`DatasetImportError` for a negative or non-finite value."""
    for name, v in (
        ("--range-std", range_std),
        ("--bearing-std", bearing_std),
        ("--v-std", v_std),
        ("--omega-std", omega_std),
    ):
        if v is not None and not (np.isfinite(v) and v >= 0):
            raise DatasetImportError(f"{name}: must be a finite number >= 0, got {v}")
    if all(v is None for v in (range_std, bearing_std, v_std, omega_std)):
        return None
    if not (np.isfinite(dt) and dt > 0):
        raise DatasetImportError(f"--dt: must be a finite number > 0, got {dt}")
    base = default_noise(dt)
    m = base.motion_std.copy()
    o = base.odometry_std.copy()
    if v_std is not None:
        m[0], o[0] = v_std, v_std * dt
    if omega_std is not None:
        m[1], o[2] = omega_std, omega_std * dt
    return dataclasses.replace(
        base,
        motion_std=m,
        odometry_std=o,
        range_std=base.range_std if range_std is None else float(range_std),
        bearing_std=base.bearing_std if bearing_std is None else float(bearing_std),
    )


# --------------------------------------------------------------------------------------------------------
# parsing
# --------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MrclamRaw:
    """The parsed text files of one robot (times in Unix seconds; the three time-stamped files' rows in time
    order, isolated disorder repaired by a stable sort and recorded in ``stamp_repairs``).

    Attributes
    ----------
    barcodes : ndarray (S, 2) int64        [subject, barcode] rows of Barcodes.dat.
    landmark_subjects : ndarray (L,) int64 landmark subject numbers, ascending (index = landmark index).
    landmarks_xy : ndarray (L, 2)          their surveyed positions, m.
    odometry : ndarray (K, 3)              [t, v, ω] rows.
    measurements : ndarray (M, 4)          [t, barcode, range, bearing] rows.
    groundtruth : ndarray (G, 4)           [t, x, y, θ] rows.
    stamp_repairs : dict                   file name → record of :func:`_time_order` (files with a repair only).
    """

    directory: Path
    robot: int
    barcodes: np.ndarray
    landmark_subjects: np.ndarray
    landmarks_xy: np.ndarray
    odometry: np.ndarray
    measurements: np.ndarray
    groundtruth: np.ndarray
    stamp_repairs: dict = dataclasses.field(default_factory=dict)


def read_table(path: Path, columns: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Read a whitespace-separated numeric table, skipping blank and ``#`` lines.

    Returns
    -------
    values : ndarray (rows, len(columns)) float64
    lines : ndarray (rows,) int64       1-based line number of each row in the file (for error messages).

    Raises
    ------
    DatasetImportError  missing file, wrong column count, non-numeric or non-finite value (names the line).
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetImportError(f"{path}: file not found")
    n = len(columns)
    values: list[float] = []
    lines: list[int] = []
    with open(path, encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            parts = s.split()
            if len(parts) != n:
                raise DatasetImportError(
                    f"{path}:{lineno}: expected {n} columns ({', '.join(columns)}), got {len(parts)}: {s[:60]!r}"
                )
            for name, p in zip(columns, parts):
                try:
                    v = float(p)
                except ValueError:
                    raise DatasetImportError(f"{path}:{lineno}: {name} is not a number: {p!r}") from None
                if not math.isfinite(v):
                    raise DatasetImportError(f"{path}:{lineno}: {name} is not finite: {p!r}")
                values.append(v)
            lines.append(lineno)
    return np.asarray(values, float).reshape(-1, n), np.asarray(lines, np.int64)


def _require_rows(arr: np.ndarray, path: Path, minimum: int = 1) -> None:
    if len(arr) < minimum:
        raise DatasetImportError(f"{path}: needs at least {minimum} data row(s), found {len(arr)}")


def _require_integers(col: np.ndarray, lines: np.ndarray, path: Path, name: str) -> np.ndarray:
    bad = np.flatnonzero(col != np.round(col))
    if bad.size:
        raise DatasetImportError(
            f"{path}:{lines[bad[0]]}: {name} must be an integer, got {float(col[bad[0]]):g}"
        )
    return col.astype(np.int64)


#: the most places a stable sort may move a row for a file's disorder to count as isolated (a swapped pair: 1)
MAX_REORDER_ROWS = 3
#: the most out-of-order rows a file may hold and still be repaired: this fraction of its rows ...
MAX_OUT_OF_ORDER_FRACTION = 0.01
#: ... but never fewer than this many rows
MIN_REPAIRABLE_ROWS = 4
#: line numbers listed per file and kind of repair in the metadata (the counts are complete)
MAX_LISTED_LINES = 20


def _n_out_of_order(t: np.ndarray) -> int:
    """The fewest rows whose stamps must be wrong for ``t`` to be in time order: ``len(t)`` minus the length of
    its longest non-decreasing subsequence (patience sorting, O(n log n)). One swapped pair gives 1."""
    import bisect

    tails: list[float] = []
    for v in t.tolist():
        i = bisect.bisect_right(tails, v)
        if i == len(tails):
            tails.append(v)
        else:
            tails[i] = v
    return len(t) - len(tails)


def _time_order(t: np.ndarray, lines: np.ndarray, path: Path, duplicates: bool = True) -> tuple[np.ndarray, dict]:
    """Stable time order of a file's rows, and the record of what that order repaired.

    Isolated disorder (no row more than :data:`MAX_REORDER_ROWS` places from its sorted place, at most
    ``max(MIN_REPAIRABLE_ROWS, MAX_OUT_OF_ORDER_FRACTION·rows)`` rows out of order) is repaired by the stable
    sort; anything else is refused. With ``duplicates`` the rows that share their stamp with the next row are
    counted as well (the importer keeps the last row of equal stamps).

    Returns
    -------
    order : ndarray (rows,) int64    row indices in time order.
    record : dict                    ``{}`` when nothing was repaired, else ``n_out_of_order``, ``reordered_lines``
                                     (1-based lines the sort moved), ``n_duplicate_stamps``, ``duplicate_lines``.

    Raises
    ------
    DatasetImportError  disorder beyond those bounds (names the first backward line and the counts).
    """
    order = np.argsort(t, kind="stable")
    moved = order != np.arange(len(t))
    n_bad = _n_out_of_order(t) if moved.any() else 0
    if n_bad:
        far = int(np.max(np.abs(order - np.arange(len(t)))))
        limit = max(MIN_REPAIRABLE_ROWS, int(MAX_OUT_OF_ORDER_FRACTION * len(t)))
        if far > MAX_REORDER_ROWS or n_bad > limit:
            i = int(np.flatnonzero(np.diff(t) < 0)[0]) + 1
            raise DatasetImportError(
                f"{path}:{lines[i]}: time goes backwards ({float(t[i]):.3f} after {float(t[i - 1]):.3f}); "
                f"{n_bad} row(s) out of time order, up to {far} rows from their place: only isolated disorder "
                f"(at most {limit} rows, each within {MAX_REORDER_ROWS} rows of its place) is repaired")
    dup = np.flatnonzero(np.diff(t[order]) == 0) if duplicates else np.zeros(0, np.int64)
    if not n_bad and not dup.size:
        return order, {}
    return order, {"n_out_of_order": n_bad, "reordered_lines": np.sort(lines[moved]).tolist()[:MAX_LISTED_LINES],
                   "n_duplicate_stamps": int(dup.size),
                   "duplicate_lines": np.sort(lines[order[dup]]).tolist()[:MAX_LISTED_LINES]}


def repair_summary(repairs: dict[str, dict]) -> str:
    """One phrase naming the stamp repairs of an import (``""`` when there were none), e.g.
    ``"repaired stamps: Robot1_Odometry.dat 1 out of order (lines 5, 6 sorted), 2 duplicates (last kept)"``."""
    parts = []
    for name, r in repairs.items():
        bits = []
        if r["n_out_of_order"]:
            bits.append(f"{r['n_out_of_order']} out of order (lines {', '.join(map(str, r['reordered_lines']))} "
                        "sorted)")
        if r["n_duplicate_stamps"]:
            bits.append(f"{r['n_duplicate_stamps']} duplicate(s) (last kept)")
        parts.append(f"{name} {', '.join(bits)}")
    return f"repaired stamps: {'; '.join(parts)}" if parts else ""


#: MRCLAM subject numbering (dataset documentation): subjects 1-5 are the robots, 6-20 the landmarks
FIRST_LANDMARK_SUBJECT = 6


def load_mrclam(directory: str | Path, robot: int, *, with_truth: bool = True) -> MrclamRaw:
    """Parse the five files that describe robot ``robot`` (1-based) in ``directory``.

    ``with_truth=False`` (copies without the Groundtruth files) reads neither ``Landmark_Groundtruth.dat`` nor
    ``RobotN_Groundtruth.dat``: the landmark subjects are then the Barcodes.dat subjects ≥ 6 (the documented
    numbering), their positions NaN, and ``groundtruth`` is None.

    Raises
    ------
    DatasetImportError  missing directory/file, malformed row, time order beyond isolated disorder (see
        :func:`_time_order`), duplicate barcode.
    """
    d = Path(directory)
    if not d.is_dir():
        raise DatasetImportError(f"{d}: not a directory (expected an MRCLAM dataset folder)")
    if int(robot) != robot or robot < 1:
        raise DatasetImportError(f"--robot: must be a positive robot number, got {robot}")

    p_bar = d / "Barcodes.dat"
    bar, ln = read_table(p_bar, ("subject", "barcode"))
    _require_rows(bar, p_bar)
    bar = np.stack(
        [
            _require_integers(bar[:, 0], ln, p_bar, "subject"),
            _require_integers(bar[:, 1], ln, p_bar, "barcode"),
        ],
        1,
    )
    for col, name in ((0, "subject"), (1, "barcode")):
        u, c = np.unique(bar[:, col], return_counts=True)
        if np.any(c > 1):
            raise DatasetImportError(f"{p_bar}: {name} {int(u[c > 1][0])} appears more than once")

    p_lm = d / "Landmark_Groundtruth.dat"
    if not with_truth:
        lm_subj = np.sort(bar[bar[:, 0] >= FIRST_LANDMARK_SUBJECT, 0])
        lm, ln = np.column_stack([lm_subj, np.full((len(lm_subj), 4), np.nan)]), None
    else:
        lm, ln = read_table(p_lm, ("subject", "x", "y", "x_std", "y_std"))
    _require_rows(lm, p_lm)
    lm_subj = _require_integers(lm[:, 0], ln, p_lm, "subject")
    order = np.argsort(lm_subj, kind="stable")
    lm_subj, lm_xy = lm_subj[order], lm[order, 1:3]
    if np.any(np.diff(lm_subj) == 0):
        raise DatasetImportError(f"{p_lm}: a landmark subject appears more than once")
    missing = np.setdiff1d(lm_subj, bar[:, 0])
    if missing.size:
        raise DatasetImportError(f"{p_lm}: landmark subject {int(missing[0])} has no barcode in {p_bar.name}")

    p_odo = d / f"Robot{robot}_Odometry.dat"
    p_meas = d / f"Robot{robot}_Measurement.dat"
    p_gt = d / f"Robot{robot}_Groundtruth.dat"
    if not p_odo.is_file():
        present = sorted(p.name.split("_")[0] for p in d.glob("Robot*_Odometry.dat"))
        raise DatasetImportError(f"{p_odo}: file not found (robots present: {', '.join(present) or 'none'})")
    odo, ln = read_table(p_odo, ("time", "v", "omega"))
    _require_rows(odo, p_odo)
    repairs: dict[str, dict] = {}
    odo = _sorted_rows(odo, ln, p_odo, repairs)
    meas, ln = read_table(p_meas, ("time", "barcode", "range", "bearing"))
    meas[:, 1] = _require_integers(meas[:, 1], ln, p_meas, "barcode")
    neg = np.flatnonzero(meas[:, 2] < 0)
    if neg.size:
        raise DatasetImportError(f"{p_meas}:{ln[neg[0]]}: range must be >= 0, got {float(meas[neg[0], 2]):g}")
    # bearings are radians; one just past ±pi is wrapped on import, but a value beyond ±2pi (degrees, a
    # corrupt row) is refused rather than wrapped to a plausible-looking angle (45 rad would become 1.018)
    far = np.flatnonzero(np.abs(meas[:, 3]) > 2 * np.pi)
    if far.size:
        raise DatasetImportError(f"{p_meas}:{ln[far[0]]}: bearing {float(meas[far[0], 3]):g} rad outside "
                                 "[-2pi, 2pi] (degrees? corrupt row?)")
    # several barcodes read in one image share a stamp: not a repair
    meas = _sorted_rows(meas, ln, p_meas, repairs, duplicates=False)
    if not with_truth:
        return MrclamRaw(d, int(robot), bar, lm_subj, lm_xy, odo, meas, None, repairs)
    gt, ln = read_table(p_gt, ("time", "x", "y", "theta"))
    _require_rows(gt, p_gt, 2)
    gt = _sorted_rows(gt, ln, p_gt, repairs)
    return MrclamRaw(d, int(robot), bar, lm_subj, lm_xy, odo, meas, gt, repairs)


def _sorted_rows(rows: np.ndarray, lines: np.ndarray, path: Path, repairs: dict[str, dict],
                 duplicates: bool = True) -> np.ndarray:
    """``rows`` (n, c) in time order (column 0) by :func:`_time_order`; a repair is recorded under the file's name
    in ``repairs``."""
    order, record = _time_order(rows[:, 0], lines, path, duplicates)
    if record:
        repairs[path.name] = record
    return rows[order]


# --------------------------------------------------------------------------------------------------------
# resampling (pure functions, tested against hand-computed cases)
# --------------------------------------------------------------------------------------------------------
def zoh_average(t_rows: np.ndarray, u_rows: np.ndarray, t_grid: np.ndarray) -> np.ndarray:
    """Time average of a zero-order-hold signal over each grid interval.

    ``u(t) = u_rows[i]`` for ``t ∈ [t_rows[i], t_rows[i+1])`` (the last row holds on; among equal stamps
    the last row wins). Returns ``(F(t_grid[k+1]) − F(t_grid[k])) / (t_grid[k+1] − t_grid[k])`` with
    ``F(t) = ∫_{t_rows[0]}^t u``.

    Parameters
    ----------
    t_rows : ndarray (K,)       non-decreasing row stamps.
    u_rows : ndarray (K, m)     row values.
    t_grid : ndarray (T+1,)     strictly increasing, ``t_grid[0] ≥ t_rows[0]``.

    Returns
    -------
    ndarray (T, m)
    """
    t_rows = np.asarray(t_rows, float)
    u_rows = np.asarray(u_rows, float).reshape(len(t_rows), -1)
    t_grid = np.asarray(t_grid, float)
    if t_grid[0] < t_rows[0]:
        raise ValueError("t_grid starts before the first row")
    F_rows = np.concatenate(
        [np.zeros((1, u_rows.shape[1])), np.cumsum(u_rows[:-1] * np.diff(t_rows)[:, None], 0)]
    )
    i = np.searchsorted(t_rows, t_grid, side="right") - 1
    F = F_rows[i] + u_rows[i] * (t_grid - t_rows[i])[:, None]
    return np.diff(F, axis=0) / np.diff(t_grid)[:, None]


def nearest_steps(t: np.ndarray, t_start: float, dt: float) -> np.ndarray:
    """Nearest pose step ``round((t − t_start)/dt)`` of each time (``|t − t_k| ≤ dt/2``), int64."""
    return np.rint((np.asarray(t, float) - t_start) / dt).astype(np.int64)


# --------------------------------------------------------------------------------------------------------
# import
# --------------------------------------------------------------------------------------------------------
def _check_arguments(dt: float, start: float, duration: float | None, non_landmark: str, max_range: float,
                     misread_gate: float, control_delay: float) -> None:
    """The argument checks of :func:`import_mrclam` (one-line :class:`DatasetImportError` naming the option)."""
    if not (math.isfinite(dt) and dt > 0):
        raise DatasetImportError(f"--dt: must be a finite number > 0, got {dt}")
    if not (math.isfinite(start) and start >= 0):
        raise DatasetImportError(f"--start: must be a finite number >= 0, got {start}")
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise DatasetImportError(f"--duration: must be a finite number > 0, got {duration}")
    if non_landmark not in ("drop", "clutter"):
        raise DatasetImportError(f"non_landmark: must be 'drop' or 'clutter', got {non_landmark!r}")
    if not max_range > 0:
        raise DatasetImportError(f"--max-range: must be > 0, got {max_range}")
    if not misread_gate > 0:
        raise DatasetImportError(f"misread_gate: must be > 0, got {misread_gate}")
    if not (math.isfinite(control_delay) and abs(control_delay) <= 5.0):
        raise DatasetImportError(
            f"--control-delay: must be a number of seconds in [-5, 5], got {control_delay}"
        )


def _landmark_rows(raw: MrclamRaw, t_ref: float, start: float, dt: float, T: int, timestamps: np.ndarray,
                   non_landmark: str) -> dict[str, np.ndarray]:
    """The measurement rows :func:`import_mrclam` keeps, in time order: ``step`` (n,) nearest pose step,
    ``m`` (n, 4) file rows, ``m_t`` (n,) s on the ``t_ref`` axis, ``lm_index`` (n,) landmark index or −1 —
    plus, over all rows, the masks ``in_window``, ``is_robot``, ``is_unknown`` and the kept rows'
    ``timing_err`` (n,) s, which the metadata counts."""
    m = raw.measurements
    order = np.argsort(m[:, 0], kind="stable")  # the files are time-sorted; be lenient
    m = m[order]
    m_t = m[:, 0] - t_ref
    step = nearest_steps(m_t, start, dt)
    in_window = (step >= 0) & (step <= T)
    barcode_to_subject = dict(zip(raw.barcodes[:, 1].tolist(), raw.barcodes[:, 0].tolist()))
    subject_to_index = {int(s): i for i, s in enumerate(raw.landmark_subjects)}
    subject = np.array([barcode_to_subject.get(int(b), -1) for b in m[:, 1]], dtype=np.int64)
    lm_index = np.array([subject_to_index.get(int(s), -1) for s in subject], dtype=np.int64)
    is_robot = (subject >= 0) & (lm_index < 0)
    is_unknown = subject < 0
    keep_row = in_window & ((lm_index >= 0) | (non_landmark == "clutter"))
    step, m, m_t, lm_index = step[keep_row], m[keep_row], m_t[keep_row], lm_index[keep_row]
    timing_err = np.abs(m_t - timestamps[step]) if len(step) else np.zeros(0)
    return {"step": step, "m": m, "m_t": m_t, "lm_index": lm_index, "in_window": in_window, "is_robot": is_robot,
            "is_unknown": is_unknown, "timing_err": timing_err}


def _provenance(d: Path, scenario: str, importer: str) -> dict[str, str]:
    """The provenance keys of an MRCLAM dataset's metadata."""
    return {"scenario": scenario, "source": "UTIAS MRCLAM (Leung et al., IJRR 2011)", "source_dir": str(d.resolve()),
            "importer": importer}


def _metadata(raw: MrclamRaw, robot: int, dt: float, start: float, T: int, non_landmark: str, control_delay: float,
              max_range: float, misread_gate: float, no_truth: bool, t_ref: float, timestamps: np.ndarray,
              truth_max_gap: float, rows: dict[str, np.ndarray], true_lm: np.ndarray) -> dict:
    """The dataset metadata of :func:`import_mrclam`: provenance, the import's parameters, the sensor and the
    row counts of :func:`_landmark_rows`."""
    d = raw.directory
    in_window, is_robot, is_unknown = rows["in_window"], rows["is_robot"], rows["is_unknown"]
    lm_index, timing_err = rows["lm_index"], rows["timing_err"]
    return {
        **_provenance(d, f"mrclam:{d.name}:robot{robot}", "slamcli.datasets.mrclam"),
        "scenario_params": {
            "robot": int(robot),
            "dt": float(dt),
            "start_s": float(start),
            "duration_s": float(T * dt),
            "non_landmark": non_landmark,
            "control_delay_s": float(control_delay),
            "controls": "zero-order-hold time average per step",
            "odometry": "integrate(x0, controls, dt)",
            "measurement_step": "nearest pose step",
        },
        "robot": {
            "number": int(robot),
            "platform": "iRobot Create (differential drive)",
            "odometry": "velocity log, ~100 Hz",
        },
        "sensor": {
            "type": "monocular camera reading barcoded cylinders",
            "reports_ids": True,
            "max_range": float(max_range),
            "landmark_subjects": raw.landmark_subjects.tolist(),
            # what the whole measurement file shows (the camera has no published range or field of view)
            "file_range_min_max_m": [float(raw.measurements[:, 2].min()), float(raw.measurements[:, 2].max())]
            if len(raw.measurements)
            else [],
            "file_abs_bearing_max_rad": float(np.abs(raw.measurements[:, 3]).max())
            if len(raw.measurements)
            else 0.0,
        },
        "time_origin_unix_s": float(t_ref),
        "window_unix_s": [float(t_ref + timestamps[0]), float(t_ref + timestamps[-1])],
        "max_timing_error_s": float(dt / 2),
        "observed_max_timing_error_s": float(timing_err.max()) if len(timing_err) else 0.0,
        "truth_max_gap_s": truth_max_gap,
        "n_rows_in_window": int(in_window.sum()),
        "n_landmark_rows": int(np.sum(lm_index >= 0)),
        "n_robot_rows_in_window": int(np.sum(is_robot & in_window)),
        "n_unknown_barcode_rows_in_window": int(np.sum(is_unknown & in_window)),
        "misread_gate_rad": float(misread_gate),
        "n_misread_rows": int(np.sum((lm_index >= 0) & (true_lm < 0))),
        "stamp_repairs": raw.stamp_repairs,
        "truth": "none (imported with no_truth: x0 = [0, 0, 0], the robot's own frame)" if no_truth else "motion capture",
    }


def _time_window(raw: MrclamRaw, robot: int, dt: float, start: float, duration: float | None,
                 control_delay: float, no_truth: bool, time_origin_unix: float | None):
    """The window of :func:`import_mrclam` on the axis ``t_ref = 0``: returns ``t_ref`` (Unix s), the
    odometry stamps ``(n_odo,)`` and ground-truth stamps ``(n_gt,)`` in Unix s (odometry shifted by
    ``control_delay``; without truth the odometry's two ends), ``T`` steps and ``timestamps (T+1,)``."""
    d = raw.directory
    p_odo, p_gt = d / f"Robot{robot}_Odometry.dat", d / f"Robot{robot}_Groundtruth.dat"

    odo_t_abs = raw.odometry[:, 0] + control_delay
    # without truth the odometry alone spans the window
    gt_t_abs = odo_t_abs[[0, -1]] if no_truth else raw.groundtruth[:, 0]
    t_ref = max(odo_t_abs[0], gt_t_abs[0])
    if time_origin_unix is not None:
        if time_origin_unix < t_ref - TIME_EPS_S:
            raise DatasetImportError(f"time origin {time_origin_unix:.3f} lies before robot {robot}'s first moment "
                                     f"with both odometry and ground truth ({t_ref:.3f})")
        t_ref = float(time_origin_unix)
    t_hi = min(odo_t_abs[-1], gt_t_abs[-1]) - t_ref
    if t_hi < dt:
        raise DatasetImportError(
            f"{p_odo.name} [{odo_t_abs[0]:.3f}, {odo_t_abs[-1]:.3f}] and {p_gt.name} [{gt_t_abs[0]:.3f}, "
            f"{gt_t_abs[-1]:.3f}] do not overlap in time by at least one step (dt = {dt:g} s)"
        )
    if start > t_hi - dt:
        raise DatasetImportError(
            f"--start: {start:g} s is past the last full step; odometry and ground truth "
            f"overlap for {t_hi:.3f} s"
        )
    avail = t_hi - start
    if duration is None:
        duration = avail
    elif duration > avail + TIME_EPS_S:
        raise DatasetImportError(
            f"--duration: {duration:g} s exceeds the {avail:.3f} s of overlapping odometry and "
            f"ground truth after --start {start:g}"
        )
    T = math.floor(duration / dt + TIME_EPS_S)
    if T < 1:
        raise DatasetImportError(f"--duration: {duration:g} s is shorter than one step (dt = {dt:g} s)")
    check_allocation("--dt", dt, (T + 1.0) * BYTES_PER_STEP, f"{T + 1} pose steps over {duration:g} s",
                     "use a larger --dt or a shorter --duration")
    timestamps = start + dt * np.arange(T + 1)
    return t_ref, odo_t_abs, gt_t_abs, T, timestamps


def import_mrclam(
    directory: str | Path,
    robot: int = 1,
    *,
    dt: float = 0.1,
    start: float = 0.0,
    duration: float | None = None,
    non_landmark: Literal["drop", "clutter"] = "drop",
    noise: NoiseSpec | None = None,
    max_range: float = float("inf"),
    control_delay: float = 0.0,
    misread_gate: float = 0.5,
    no_truth: bool = False,
    time_origin_unix: float | None = None,
    raw: MrclamRaw | None = None,
) -> Dataset:
    """Import robot ``robot`` of the MRCLAM dataset in ``directory`` as a slamcli :class:`Dataset`.

    Parameters
    ----------
    directory : folder with Barcodes.dat, Landmark_Groundtruth.dat and RobotN_{Odometry,Measurement,Groundtruth}.dat.
    robot : robot number N (1-based).
    dt : sampling period of the output, s (> 0).
    start : seconds after ``t_ref`` (first moment with both odometry and ground truth) where pose 0 lies.
    duration : length of the window, s (``T = floor(duration/dt)``); ``None`` = to the end of the shorter log.
    non_landmark : rows that see a robot or an unknown barcode: ``"drop"`` or ``"clutter"`` (``reported_id = −1``).
    noise : NoiseSpec to store; default :func:`default_noise` ``(dt)``.
    max_range : sensor max range to store, m (``inf`` = no limit).
    control_delay : s added to every odometry stamp before resampling; 0 = the log as recorded (the lag seen on
        Dataset 7: benchmarks/results/design_notes.md).
    misread_gate : rad; a landmark row whose bearing differs by more than this from its barcode's landmark seen
        from the motion-capture pose is a misread (``truth.obs_landmark = −1``); ``inf`` turns the check off.
    no_truth : for copies without the Groundtruth files: ``t_ref`` = first odometry stamp, ``x0 = 0``, no truth.
    time_origin_unix : Unix time to use as ``t_ref`` (the common base of :func:`import_mrclam_team`); not before
        this robot's own ``t_ref``.
    raw : the already parsed files of this robot (:func:`load_mrclam`), to avoid parsing them twice.

    Raises
    ------
    DatasetImportError  bad files (see :func:`load_mrclam`), bad arguments, or a window outside the overlap of
        odometry and ground truth.
    """
    _check_arguments(dt, start, duration, non_landmark, max_range, misread_gate, control_delay)
    if raw is None:
        raw = load_mrclam(directory, robot, with_truth=not no_truth)
    # --- time window on the axis t_ref = 0 ---------------------------------------------------------------
    t_ref, odo_t_abs, gt_t_abs, T, timestamps = _time_window(raw, robot, dt, start, duration, control_delay,
                                                             no_truth, time_origin_unix)

    # --- controls (ZOH time average) and dead-reckoned odometry ----------------------------------------------
    odo_t = odo_t_abs - t_ref
    controls = zoh_average(odo_t, raw.odometry[:, 1:3], timestamps)

    # --- truth poses (dedupe equal stamps: keep the last) and x0 ---------------------------------------------
    gt_t = gt_t_abs - t_ref
    keep = np.r_[np.diff(gt_t) > 0, True]
    gt_xyt = np.zeros((2, 3)) if no_truth else raw.groundtruth[keep, 1:4]
    gt_t = gt_t[keep]
    truth_xyt = interpolate_poses(gt_t, gt_xyt, timestamps)
    x0 = truth_xyt[0].copy()  # no_truth: zeros, the robot's own start frame
    odometry_xyt = integrate(x0, controls, dt)
    inside = (gt_t >= timestamps[0]) & (gt_t <= timestamps[-1])
    gt_in = np.r_[timestamps[0], gt_t[inside], timestamps[-1]]
    truth_max_gap = float(np.max(np.diff(gt_in)))

    # --- measurements ---------------------------------------------------------------------------------------
    rows = _landmark_rows(raw, t_ref, start, dt, T, timestamps, non_landmark)
    step, m, m_t, lm_index = rows["step"], rows["m"], rows["m_t"], rows["lm_index"]
    obs = Observations.from_rows(step, m[:, 2:4], T + 1, reported_id=lm_index)

    noise = default_noise(dt) if noise is None else noise
    inputs = SlamInputs(
        dt=float(dt),
        timestamps=timestamps,
        x0=x0,
        controls=controls,
        odometry_xyt=odometry_xyt,
        observations=obs,
        noise=noise,
        max_range=float(max_range),
        reported_id_source="sensor",  # barcodes read by a camera: can be misread (graph's robust=auto)
    )
    # truth association = the barcode's landmark, unless the row contradicts the motion capture (misread)
    true_lm = lm_index.copy()
    is_lm = true_lm >= 0
    if np.any(is_lm) and math.isfinite(misread_gate) and not no_truth:
        pose_at_row = interpolate_poses(gt_t, gt_xyt, np.clip(m_t[is_lm], gt_t[0], gt_t[-1]))
        b_true = range_bearing(pose_at_row, raw.landmarks_xy[true_lm[is_lm]])[:, 1]
        misread = np.abs(angle_diff(obs.bearing_rad[is_lm], b_true)) > misread_gate
        true_lm[np.flatnonzero(is_lm)[misread]] = -1
    truth = GroundTruth(poses_xyt=truth_xyt, landmarks_xy=raw.landmarks_xy.copy(), obs_landmark=true_lm)
    if no_truth:
        truth = None
    metadata = _metadata(raw, robot, dt, start, T, non_landmark, control_delay, max_range, misread_gate, no_truth,
                         t_ref, timestamps, truth_max_gap, rows, true_lm)
    return Dataset(inputs=inputs, truth=truth, metadata=metadata)


# --------------------------------------------------------------------------------------------------------
# noise calibration against ground truth (documentation / tuning tool, never used by the import itself)
# --------------------------------------------------------------------------------------------------------
def residual_noise(dataset: Dataset) -> dict[str, float]:
    """Robust noise levels of a dataset's inputs measured against its ground truth.

    * observations: ``z − h(x_true, m_true)`` for rows with a true landmark (bearing wrapped);
    * controls: ``u_k − u_true,k`` where the true velocities come from the truth increment of each step,
      ``v_true = ‖Δp‖/dt`` signed by the body-x component, ``ω_true = angle_diff(θ_{k+1}, θ_k)/dt``.

    Returns median and robust σ (1.4826·MAD) of each: ``range_median``, ``range_std``, ``bearing_median``,
    ``bearing_std``, ``v_median``, ``v_std``, ``omega_median``, ``omega_std``.
    """
    inp, tr = dataset.inputs, dataset.truth
    if tr is None:
        raise DatasetImportError("residual_noise needs a dataset with ground truth")
    obs = inp.observations
    ok = tr.obs_landmark >= 0
    zh = range_bearing(tr.poses_xyt[obs.step[ok]], tr.landmarks_xy[tr.obs_landmark[ok]])
    r_res = obs.range_m[ok] - zh[:, 0]
    b_res = angle_diff(obs.bearing_rad[ok], zh[:, 1])
    p = tr.poses_xyt
    dp = np.diff(p[:, :2], axis=0)
    fwd = np.cos(p[:-1, 2]) * dp[:, 0] + np.sin(p[:-1, 2]) * dp[:, 1]
    v_true = np.sign(fwd) * np.hypot(dp[:, 0], dp[:, 1]) / inp.dt
    w_true = angle_diff(p[1:, 2], p[:-1, 2]) / inp.dt
    out = {}
    for name, r in (
        ("range", r_res),
        ("bearing", b_res),
        ("v", inp.controls[:, 0] - v_true),
        ("omega", inp.controls[:, 1] - w_true),
    ):
        med = float(np.median(r)) if len(r) else float("nan")
        out[f"{name}_median"] = med
        out[f"{name}_std"] = float(1.4826 * np.median(np.abs(r - med))) if len(r) else float("nan")
    return out


# --------------------------------------------------------------------------------------------------------
# multi-robot import
# --------------------------------------------------------------------------------------------------------
def robot_rows(
    raw: MrclamRaw, team_numbers: list[int], t_ref: float, start: float, dt: float, T: int
) -> dict[str, np.ndarray]:
    """Classify the measurement rows of ``raw`` whose barcode is a robot's (subject 1..5).

    Every such row gets exactly one fate:

    * ``kept``           the observed robot is in the team and the row's nearest step lies in ``0..T``;
    * ``outside``        its nearest step ``round((t − t_ref − start)/dt)`` is outside the common time base;
    * ``not_in_team``    the observed robot was not imported;
    * ``self``           the barcode is the observer's own (never happens on Dataset 7; counted anyway).

    Returns
    -------
    dict with ``n_robot_rows`` (int), ``fate`` (n,) str, ``step`` (n,) int64, ``observed`` (n,) int64 robot
    number, ``z`` (n, 2) ``[range, bearing]`` and ``t`` (n,) seconds on the ``t_ref`` axis, for those rows in
    time order.
    """
    m = raw.measurements[np.argsort(raw.measurements[:, 0], kind="stable")]
    b2s = dict(zip(raw.barcodes[:, 1].tolist(), raw.barcodes[:, 0].tolist()))
    subject = np.array([b2s.get(int(b), -1) for b in m[:, 1]], dtype=np.int64)
    is_robot = (subject >= 1) & (subject < FIRST_LANDMARK_SUBJECT) & ~np.isin(subject, raw.landmark_subjects)
    m, subject = m[is_robot], subject[is_robot]
    t = m[:, 0] - t_ref
    step = nearest_steps(t, start, dt)
    fate = np.full(len(m), "kept", dtype=object)
    fate[~np.isin(subject, team_numbers)] = "not_in_team"
    fate[(step < 0) | (step > T)] = "outside"
    fate[subject == raw.robot] = "self"
    return {"n_robot_rows": int(is_robot.sum()), "fate": fate, "step": step, "observed": subject,
            "z": m[:, 2:4].copy(), "t": t}


def _team_readings(raws: list[MrclamRaw], numbers: list[int], t_ref: float, start: float, dt: float, T: int,
                   n1: int):
    """The inter-robot readings of :func:`import_mrclam_team`: every robot's :func:`robot_rows`, the kept
    readings' stacked observer / observed poses ``(K,)`` and ``[range, bearing]`` ``(K, 2)`` sorted by
    (observer, observed), and the count of rows per fate."""
    # inter-robot readings
    index_of = {n: k for k, n in enumerate(numbers)}
    rows = [robot_rows(rw, numbers, t_ref, start, dt, T) for rw in raws]
    oi, oj, oz, counts = [], [], [], {"kept": 0, "outside": 0, "not_in_team": 0, "self": 0}
    for k, rr in enumerate(rows):
        for f in counts:
            counts[f] += int(np.sum(rr["fate"] == f))
        keep = rr["fate"] == "kept"
        oi.append(k * n1 + rr["step"][keep])
        oj.append(np.array([index_of[int(s)] for s in rr["observed"][keep]], np.int64) * n1 + rr["step"][keep])
        oz.append(rr["z"][keep])
    oi, oj, oz = np.concatenate(oi), np.concatenate(oj), np.concatenate(oz)
    order = np.lexsort((oj, oi))
    oi, oj, oz = oi[order], oj[order], oz[order]
    return rows, oi, oj, oz, counts


def _reading_residual(truth_poses: np.ndarray, oi: np.ndarray, oj: np.ndarray, team) -> dict:
    """Median and robust σ of the kept readings' range and bearing against the motion capture."""
    resid = {}
    if len(oi):
        zh = range_bearing(truth_poses[oi], truth_poses[oj, :2])
        dr = team.range_m - zh[:, 0]
        db = angle_diff(team.bearing_rad, zh[:, 1])
        for name, r_ in (("range", dr), ("bearing", db)):
            med = float(np.median(r_))
            resid[f"{name}_median"] = med
            resid[f"{name}_robust_std"] = float(1.4826 * np.median(np.abs(r_ - med)))
        resid["n_bearing_over_0.5rad"] = int(np.sum(np.abs(db) > 0.5))
    return resid


def _team_metadata(directory: str | Path, numbers: list[int], dt: float, start: float, T: int, control_delay: float,
                   t_ref: float, ts: np.ndarray, solo: list[Dataset], rows: list[dict], counts: dict,
                   resid: dict) -> dict:
    """The dataset metadata of :func:`import_mrclam_team` (provenance, parameters, reading counts)."""
    d = Path(directory)
    return {
        **_provenance(d, f"mrclam:{d.name}:robots{'-'.join(map(str, numbers))}",
                      "slamcli.datasets.mrclam.import_mrclam_team"),
        "scenario_params": {
            "robots": numbers,
            "dt": float(dt),
            "start_s": float(start),
            "duration_s": float(T * dt),
            "control_delay_s": float(control_delay),
            "layout": "poses stacked robot-major; robot k owns stacked poses k*(T+1) .. k*(T+1)+T",
            "start_poses": "motion capture at the first grid time of each robot (one world frame)",
        },
        "robot": {"numbers": numbers, "platform": "iRobot Create (differential drive)"},
        "sensor": solo[0].metadata["sensor"],
        "time_origin_unix_s": t_ref,
        "window_unix_s": [float(t_ref + ts[0]), float(t_ref + ts[-1])],
        "max_timing_error_s": float(dt / 2),
        "robot_rows": {
            "n_rows_with_robot_barcode": int(sum(rr["n_robot_rows"] for rr in rows)),
            "kept": counts["kept"],
            "dropped_outside_time_base": counts["outside"],
            "dropped_robot_not_imported": counts["not_in_team"],
            "dropped_self": counts["self"],
            "truth_residual": resid,
        },
        "per_robot": [
            {k: ds.metadata[k] for k in ("n_landmark_rows", "n_misread_rows", "observed_max_timing_error_s",
                                         "truth_max_gap_s", "stamp_repairs")} | {"robot": n}
            for n, ds in zip(numbers, solo)
        ],
        "truth": "motion capture",
    }


def import_mrclam_team(
    directory: str | Path,
    robots: list[int] | tuple[int, ...] = (1, 2, 3, 4, 5),
    *,
    dt: float = 0.1,
    start: float = 0.0,
    duration: float | None = None,
    noise: NoiseSpec | None = None,
    max_range: float = float("inf"),
    control_delay: float = 0.0,
    misread_gate: float = 0.5,
) -> Dataset:
    """Import several robots of one MRCLAM dataset as ONE multi-robot :class:`Dataset` (:class:`RobotTeam`).

    * **One time base**: ``t_ref`` = the latest of the robots' own ``t_ref`` (first moment with odometry and
      ground truth), the window ends at the earliest of their ends; every robot is imported by
      :func:`import_mrclam` on that grid (``start``, ``duration`` on the common axis), so all have ``T+1``
      poses at the same ``timestamps``.
    * **Stacked poses**: robot-major, robot ``r`` owns stacked poses ``r·(T+1) .. r·(T+1)+T``; the odometry
      chain never links two robots (the control row between two robots is zero and unused).
    * **Start poses**: each robot's ``x0`` is its motion-capture pose at the first grid time, exactly as the
      single-robot importer does; the motion-capture frame is therefore the one world frame of the joint
      problem (a joint solve needs all start poses in one frame: the known start poses of paper 000 §3).
    * **Landmarks** (barcode subjects ≥ 6) are shared: one index space, ``reported_id`` = landmark index as
      for one robot (``reported_id_source = "sensor"``).
    * **Inter-robot readings**: every row whose barcode is a robot's becomes a range-bearing reading from the
      observer's pose to the observed robot's pose at the same step (nearest step, timing error ≤ dt/2); rows
      are dropped only for the reasons of :func:`robot_rows` and counted per reason in
      ``metadata["robot_rows"]``.
    * **Truth** (evaluation only): stacked motion-capture poses; ``metadata["robot_rows"]`` also records the
      residual of the kept readings against the truth (median and robust σ of range and bearing).

    Raises
    ------
    DatasetImportError  bad files or arguments (see :func:`import_mrclam`), fewer than two distinct robots.
    """
    from slamcli.types import RobotTeam

    numbers = [int(r) for r in robots]
    if len(numbers) < 2 or len(set(numbers)) != len(numbers):
        raise DatasetImportError(f"--robots: need at least two distinct robot numbers, got {numbers}")
    if not (math.isfinite(dt) and dt > 0):
        raise DatasetImportError(f"--dt: must be a finite number > 0, got {dt}")
    raws = [load_mrclam(directory, r) for r in numbers]
    t0s = [max(rw.odometry[0, 0] + control_delay, rw.groundtruth[0, 0]) for rw in raws]
    t1s = [min(rw.odometry[-1, 0] + control_delay, rw.groundtruth[-1, 0]) for rw in raws]
    t_ref = float(max(t0s))
    avail = float(min(t1s)) - t_ref - start
    if duration is None:
        if avail < dt:
            raise DatasetImportError(f"robots {numbers}: their odometry and ground truth share less than one step "
                                     f"(dt = {dt:g} s) after --start {start:g}")
        duration = avail
    solo = [
        import_mrclam(directory, r, dt=dt, start=start, duration=duration, noise=noise, max_range=max_range,
                      control_delay=control_delay, misread_gate=misread_gate, time_origin_unix=t_ref, raw=rw)
        for r, rw in zip(numbers, raws)
    ]
    n1 = solo[0].inputs.n_poses
    T = n1 - 1
    R = len(numbers)
    ts = solo[0].inputs.timestamps
    pose_robot = np.repeat(np.arange(R, dtype=np.int64), n1)
    controls = np.concatenate(
        [np.concatenate([ds.inputs.controls, np.zeros((1, 2))]) for ds in solo]
    )[:-1]
    obs_list = [ds.inputs.observations for ds in solo]
    steps = np.concatenate([o.step + k * n1 for k, o in enumerate(obs_list)])
    z = np.concatenate([o.z for o in obs_list])
    rid = np.concatenate([o.reported_id for o in obs_list])
    obs = Observations.from_rows(steps, z, R * n1, reported_id=rid)

    # inter-robot readings
    rows, oi, oj, oz, counts = _team_readings(raws, numbers, t_ref, start, dt, T, n1)
    x0s = np.stack([ds.inputs.x0 for ds in solo])
    team = RobotTeam(pose_robot=pose_robot, robot_number=np.asarray(numbers, np.int64), x0_xyt=x0s,
                     observer_pose=oi.astype(np.int64), observed_pose=oj.astype(np.int64),
                     range_m=oz[:, 0].copy(), bearing_rad=np.asarray(wrap_angle(oz[:, 1]), float).reshape(-1))
    inp0 = solo[0].inputs
    inputs = SlamInputs(
        dt=float(dt),
        timestamps=np.tile(ts, R),
        x0=x0s[0].copy(),
        controls=controls,
        odometry_xyt=np.concatenate([ds.inputs.odometry_xyt for ds in solo]),
        observations=obs,
        noise=inp0.noise,
        max_range=inp0.max_range,
        reported_id_source="sensor",
        robots=team,
    )
    truth_poses = np.concatenate([ds.truth.poses_xyt for ds in solo])
    truth = GroundTruth(poses_xyt=truth_poses, landmarks_xy=solo[0].truth.landmarks_xy.copy(),
                        obs_landmark=np.concatenate([ds.truth.obs_landmark for ds in solo]))
    # residual of the kept readings against the motion capture (documentation; solvers never see it)
    resid = _reading_residual(truth_poses, oi, oj, team)
    metadata = _team_metadata(directory, numbers, dt, start, T, control_delay, t_ref, ts, solo, rows, counts, resid)
    return Dataset(inputs=inputs, truth=truth, metadata=metadata)
