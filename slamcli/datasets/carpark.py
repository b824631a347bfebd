"""ACFR car-park importer (the Victoria Park utility car in a car park with 15 retro-reflective beacons).

Files (MATLAB v5, read with ``scipy.io.loadmat``; see the dataset's PROVENANCE.txt): ``data_set.mat`` with
``Velocity``/``Steering``/``Time_VS`` (40 Hz encoder speed and steering), ``Laser``/``Intensity``/``TimeLaser``
(361 beams over 0..180°, 90° ahead; 81.91 m = no return) and ``GPSLon``/``GPSLat``/``TimeGPS`` (already a
local metric frame); ``beac_juan3.mat`` with ``estbeac (15, 2)``, the surveyed beacons in the GPS frame.

* **Poses** at the ``Time_VS`` stamps (uniform dt), controls ``[v_e, α]`` held per step, ``motion_model =
  "ackermann"`` with the Victoria Park geometry and laser mount; ``x0 = 0`` (evaluation aligns SE(2));
  odometry = the integrated car model.
* **Beacons** (:func:`extract_beacons`): a beam is a beacon return when ``Intensity ≥ INTENSITY_THRESHOLD``
  (any non-zero reflectivity; values are multiples of 2¹³) and it has a return; consecutive such beams whose
  ranges differ by ≤ 0.5 m form one beacon, observed at their mean range and mean angle (``b = angle − π/2``).
  Each scan goes to the nearest pose (timing error ≤ dt/2).
* **Truth**: the surveyed beacons as landmark truth (no association), GPS as a position-only reference.

Noise defaults σ_v 0.5 m/s, σ_α 3°, σ_r 0.1 m, σ_b 0.5° are conservative on purpose (chosen by measurement:
benchmarks/results/design_notes.md); ``--range-std``, ``--bearing-std``, ``--v-std``, ``--steer-std`` set others.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from slamcli.datasets import DatasetImportError
from slamcli.models.ackermann import VICTORIA_PARK, VICTORIA_PARK_LASER_XY, integrate_ackermann
from slamcli.types import Dataset, GroundTruth, NoiseSpec, Observations, SlamInputs

INTENSITY_THRESHOLD = 8192  # lowest non-zero reflectivity level of the scanner (values are multiples of 2**13)
NO_RETURN_M = 81.0  # ranges at/above this are "no return" (the scanner reports 81.91 m)
GROUP_RANGE_JUMP_M = 0.5  # consecutive bright beams further apart in range are different beacons
BEAM_ANGLES_RAD = np.deg2rad(np.arange(361) * 0.5)  # 0..180°, 90° = straight ahead

#: noise a solver may assume: controls as for Victoria Park; beacon centre σ_r 0.1 m, σ_b 0.5°
DEFAULT_MOTION_STD = (0.5, math.radians(3.0))
DEFAULT_ODOMETRY_STD = (0.0125, 0.005, 0.002)
DEFAULT_RANGE_STD = 0.1
DEFAULT_BEARING_STD = math.radians(0.5)


def extract_beacons(ranges_m, intensity, *, threshold: int = INTENSITY_THRESHOLD) -> np.ndarray:
    """Beacon observations ``(K, 2)`` = ``[range, bearing]`` of one 361-beam scan (see the module docstring)."""
    r = np.asarray(ranges_m, float).reshape(-1)
    bright = np.flatnonzero((np.asarray(intensity).reshape(-1) >= threshold) & (r < NO_RETURN_M))
    if bright.size == 0:
        return np.zeros((0, 2))
    groups, cur = [], [bright[0]]
    for i in bright[1:]:
        if i - cur[-1] <= 1 and abs(r[i] - r[cur[-1]]) <= GROUP_RANGE_JUMP_M:
            cur.append(i)
        else:
            groups.append(cur)
            cur = [i]
    groups.append(cur)
    return np.array([[r[g].mean(), BEAM_ANGLES_RAD[g].mean() - np.pi / 2] for g in groups])


def _get(m: dict, key: str, path: Path) -> np.ndarray:
    if key not in m:
        raise DatasetImportError(f"{path}: field {key!r} missing")
    a = np.asarray(m[key])
    if a.size == 0:
        raise DatasetImportError(f"{path}: field {key!r} is empty")
    if a.dtype.kind not in "biuf":  # MATLAB strings, cells or structs where numbers belong
        raise DatasetImportError(f"{path}: field {key!r}: expected a numeric array, got MATLAB {a.dtype.kind!r} "
                                 f"data ({a.dtype})")
    return a


#: bound on the bytes the variables of one .mat file hold once inflated: about 20× the published recording's
#: size; loadmat then holds at most this much
MAX_MAT_BYTES = 80 << 20
#: a MAT 5 data element whose payload is one zlib stream
_MI_COMPRESSED = 15
#: bytes read or inflated at a time while measuring a compressed variable
_PIECE = 1 << 16


def _inflated_bytes(fh, nbytes: int, budget: int) -> int:
    """Bytes that the zlib stream of ``nbytes`` at ``fh``'s position inflates to, counted piece by piece and
    nothing kept; stops once past ``budget``. Leaves ``fh`` at the end of the stream."""
    import zlib

    z, left, out = zlib.decompressobj(), nbytes, 0
    while left > 0 and out <= budget:
        piece = fh.read(min(left, _PIECE))
        if not piece:
            break
        left -= len(piece)
        out += len(z.decompress(piece, _PIECE))
        while z.unconsumed_tail and out <= budget:
            out += len(z.decompress(z.unconsumed_tail, _PIECE))
    fh.seek(left, 1)
    return out


def _check_inflated_size(path: Path) -> None:
    """Refuse a MAT 5 file whose variables would hold more than :data:`MAX_MAT_BYTES` once inflated — measured
    by inflating each compressed variable in pieces and keeping none, so a small zlib bomb costs at most
    :data:`MAX_MAT_BYTES` of work and one piece of memory, never its inflated size. Other MAT versions (v4
    stores arrays uncompressed; v7.3 is HDF5, which loadmat refuses) are left to loadmat."""
    import struct

    with open(path, "rb") as fh:
        header = fh.read(128)
        order = {b"IM": "<", b"MI": ">"}.get(header[126:128]) if len(header) == 128 else None
        total = 0
        while order is not None and len(tag := fh.read(8)) == 8:
            mdtype, nbytes = struct.unpack(order + "II", tag)
            if mdtype == _MI_COMPRESSED:
                total += _inflated_bytes(fh, nbytes, MAX_MAT_BYTES - total)
            else:
                total += nbytes
                fh.seek(nbytes + (-nbytes) % 8, 1)
            if total > MAX_MAT_BYTES:
                raise DatasetImportError(f"{path}: its variables hold more than {MAX_MAT_BYTES >> 20} MB once "
                                         f"inflated (the limit; the published recording holds 3.6 MB)")


def _loadmat(path: Path) -> dict:
    """``scipy.io.loadmat(path)`` once :func:`_check_inflated_size` has bounded what it will inflate; failures
    are one line naming the file."""
    import scipy.io as sio

    try:
        _check_inflated_size(path)
        return sio.loadmat(path)
    except DatasetImportError:
        raise
    except Exception as exc:  # noqa: BLE001 - any loadmat failure is a bad file
        raise DatasetImportError(f"{path}: not a readable MATLAB file ({str(exc).splitlines()[0][:120]})") from None


def default_noise(*, range_std: float | None = None, bearing_std: float | None = None,
                  v_std: float | None = None, steer_std: float | None = None) -> NoiseSpec:
    """The defaults with any σ replaced (see :func:`slamcli.datasets.victoria_park.car_noise`)."""
    from slamcli.datasets.victoria_park import car_noise

    return car_noise(DEFAULT_MOTION_STD, DEFAULT_ODOMETRY_STD, DEFAULT_RANGE_STD, DEFAULT_BEARING_STD,
                     range_std=range_std, bearing_std=bearing_std, v_std=v_std, steer_std=steer_std)


def import_carpark(directory, *, max_range: float = NO_RETURN_M, noise: NoiseSpec | None = None) -> Dataset:
    """Read ``data_set.mat`` and ``beac_juan3.mat`` from ``directory`` into a :class:`Dataset` (``noise``: None =
    the defaults, see "Noise")."""
    d = Path(directory)
    if not (max_range > 0):  # negative, zero and nan keep no beacon (or every one): a mistyped option
        raise DatasetImportError(f"--max-range: must be > 0 m (or inf), got {max_range}")
    if not d.is_dir():
        raise DatasetImportError(f"{d}: not a directory")
    p_data, p_beac = d / "data_set.mat", d / "beac_juan3.mat"
    mats = {}
    for p in (p_data, p_beac):
        if not p.is_file():
            raise DatasetImportError(f"{p}: file not found (expected the ACFR car-park .mat files)")
        mats[p] = _loadmat(p)
    m = mats[p_data]
    t_vs = _get(m, "Time_VS", p_data).ravel().astype(float)
    vel = _get(m, "Velocity", p_data).ravel().astype(float)
    steer = _get(m, "Steering", p_data).ravel().astype(float)
    laser = _get(m, "Laser", p_data).astype(float)
    inten = _get(m, "Intensity", p_data)
    t_l = _get(m, "TimeLaser", p_data).ravel().astype(float)
    gx = _get(m, "GPSLon", p_data).ravel().astype(float)
    gy = _get(m, "GPSLat", p_data).ravel().astype(float)
    t_g = _get(m, "TimeGPS", p_data).ravel().astype(float)
    beacons = _get(mats[p_beac], "estbeac", p_beac).astype(float)
    if not (len(vel) == len(steer) == len(t_vs)):
        raise DatasetImportError(f"{p_data}: Velocity/Steering/Time_VS lengths differ")
    if laser.shape != inten.shape or laser.shape != (len(t_l), 361):
        raise DatasetImportError(f"{p_data}: Laser/Intensity must be (len(TimeLaser), 361), got {laser.shape}")
    if beacons.ndim != 2 or beacons.shape[1] != 2:
        raise DatasetImportError(f"{p_beac}: estbeac must be (L, 2), got {beacons.shape}")
    for key, a in (("Laser", laser), ("Time_VS", t_vs), ("Velocity", vel), ("Steering", steer), ("TimeLaser", t_l)):
        if not np.isfinite(a).all():
            raise DatasetImportError(f"{p_data}: field {key!r}: non-finite value at index {int(np.argmax(~np.isfinite(a)))}")
    if (laser < 0).any():
        i, j = np.argwhere(laser < 0)[0]
        raise DatasetImportError(f"{p_data}: field 'Laser': range {laser[i, j]:g} m at scan {i}, beam {j} must be >= 0")
    if not (np.diff(t_vs) > 0).all():
        raise DatasetImportError(f"{p_data}: Time_VS not strictly increasing")
    dt = float(np.median(np.diff(t_vs)))
    if np.abs(np.diff(t_vs) - dt).max() > 1e-3:
        raise DatasetImportError(f"{p_data}: Time_VS is not a uniform log (dt {dt:g} s)")

    T = len(t_vs) - 1
    controls = np.column_stack([vel[:-1], steer[:-1]])
    steps, zs, n_beac = [], [], []
    for i in range(len(t_l)):
        k = int(round((t_l[i] - t_vs[0]) / dt))
        if not 0 <= k <= T:
            continue
        z = extract_beacons(laser[i], inten[i])
        z = z[z[:, 0] <= max_range]
        n_beac.append(len(z))
        steps += [k] * len(z)
        zs.append(z)
    z_all = np.concatenate(zs) if zs else np.zeros((0, 2))
    order = np.argsort(np.asarray(steps, np.int64), kind="stable")
    observations = Observations.from_rows(np.asarray(steps, np.int64)[order], z_all[order], T + 1)
    x0 = np.zeros(3)
    inp = SlamInputs(dt=dt, timestamps=t_vs.copy(), x0=x0, controls=controls,
                     odometry_xyt=integrate_ackermann(x0, controls, dt, VICTORIA_PARK), observations=observations,
                     noise=default_noise() if noise is None else noise,
                     max_range=float(max_range), motion_model="ackermann", vehicle=VICTORIA_PARK,
                     sensor_offset_xy=np.array(VICTORIA_PARK_LASER_XY, float))
    g_in = (t_g >= t_vs[0]) & (t_g <= t_vs[-1])
    tg, gxy = t_g[g_in], np.column_stack([gx, gy])[g_in]
    first = np.concatenate([[True], np.diff(tg) > 0]) if len(tg) else np.zeros(0, bool)
    # GPS positions refer to the laser point: over the first 32 s the car-model dead reckoning of the laser
    # fits the GPS to 0.13 m RMS (SE(2)-aligned), that of the rear axle to 3.4 m
    truth = GroundTruth(poses_xyt=None, landmarks_xy=beacons, obs_landmark=None, ref_time_s=tg[first],
                        ref_xy=gxy[first], ref_offset_xy=np.array(VICTORIA_PARK_LASER_XY, float))
    meta = {"source": "acfr_carpark", "source_dir": str(d.resolve()), "scenario": "acfr_carpark",
            "motion_model": "ackermann", "n_scans": int(len(n_beac)),
            "beacon_intensity_threshold": INTENSITY_THRESHOLD, "n_beacon_observations": int(len(z_all)),
            "n_surveyed_beacons": int(len(beacons)), "n_gps_fixes": int(first.sum()),
            "truth": "surveyed beacons (no association) + GPS positions"}
    return Dataset(inputs=inp, truth=truth, metadata=meta)
