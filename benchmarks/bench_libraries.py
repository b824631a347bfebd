"""Hand-written pieces against the libraries that could replace them: import cost in a fresh interpreter and
the agreement of the numbers (the table in ``benchmarks/results/libraries.md``).

Each row is one Python statement run by ``python -c`` in a fresh interpreter with single-threaded BLAS; CPU =
user + system time of the child (``resource.getrusage(RUSAGE_CHILDREN)``), median of ``REPEATS`` runs in
alternating order, bytecode cached (one untimed run first). ``cpu_s`` includes the interpreter's own start
(the ``python -c pass`` row); ``extra_s`` is the CPU above the row named in ``over`` (for a replacement:
what it adds to the process that the kept code runs in). Rows whose library is
not installed are reported with ``cpu_s`` empty. The machine may be loaded: read the differences.

Agreement rows (``max_abs_diff``): ``scipy.stats.chi2.ppf`` against :func:`slamcli.metrics.consistency.chi2_ppf`;
evo's ``file_interface`` TUM reader and its Umeyama alignment (``evo.core.geometry.umeyama_alignment``,
no scale) against :func:`slamcli.io.export.read_tum` and :func:`slamcli.metrics.trajectory.umeyama_se2`
on a seeded random SE(2) path.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPEATS = 7
DEFER = "from slamcli.api.startup import defer_unused_numpy_submodules; defer_unused_numpy_submodules(); "
#: (piece, side, statement, module that must be importable, row it is measured over)
STATEMENTS = [
    ("floor", "python", "pass", None, None),
    ("floor", "numpy", "import numpy", None, "python"),
    ("chi2 quantile", "scipy.special (kept)", "import scipy.special", None, "numpy"),
    ("chi2 quantile", "scipy.stats", "import scipy.stats", None, "scipy.special (kept)"),
    ("numpy LazyLoader", "scipy.sparse + h5py, deferred (kept)", DEFER + "import scipy.sparse, h5py", None, "numpy"),
    ("numpy LazyLoader", "scipy.sparse + h5py, plain", "import scipy.sparse, h5py", None,
     "scipy.sparse + h5py, deferred (kept)"),
    ("tables", "pandas (kept writers)", "import pandas", None, "numpy"),
    ("tables", "pandas + tabulate (to_markdown)", "import pandas, tabulate", "tabulate", "pandas (kept writers)"),
    ("tables", "pandas + Styler (to_latex)", "import pandas.io.formats.style", "jinja2", "pandas (kept writers)"),
    ("TUM/KITTI + SE(2) alignment", "slamcli.io.export + metrics.trajectory (kept)",
     "import slamcli.io.export, slamcli.metrics.trajectory", None, "numpy"),
    ("TUM/KITTI + SE(2) alignment", "the same + evo file_interface + core",
     "import slamcli.io.export, slamcli.metrics.trajectory; from evo.tools import file_interface; "
     "from evo.core import trajectory, geometry", "evo", "slamcli.io.export + metrics.trajectory (kept)"),
    ("local pool", "concurrent.futures + multiprocessing (kept)",
     "import concurrent.futures.process, multiprocessing", None, "python"),
    ("local pool", "loky", "import loky", "loky", "concurrent.futures + multiprocessing (kept)"),
]


def _installed(module: str | None) -> bool:
    if module is None:
        return True
    import importlib.util

    return importlib.util.find_spec(module) is not None


def _cpu(code: str, env: dict) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-c", code], env=env, check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def import_rows(repeats: int) -> list[dict]:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
           "PYTHONPYCACHEPREFIX": tempfile.mkdtemp(prefix="bench-libraries-pyc-")}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    todo = [s for s in STATEMENTS if _installed(s[3])]
    for s in todo:
        _cpu(s[2], env)  # untimed: bytecode written
    times: dict[str, list[float]] = {s[1]: [] for s in todo}
    for r in range(repeats):
        for s in (todo if r % 2 == 0 else todo[::-1]):
            times[s[1]].append(_cpu(s[2], env))
    med = {k: float(np.median(v)) for k, v in times.items()}
    rows = []
    for piece, side, code, _module, over in STATEMENTS:
        cpu = med.get(side)
        extra = "" if cpu is None or over is None else round(cpu - med[over], 3)
        rows.append({"piece": piece, "side": side, "statement": code.replace(DEFER, "<defer>; "),
                     "cpu_s": "" if cpu is None else round(cpu, 3), "over": over or "", "extra_s": extra,
                     "load_1min": round(os.getloadavg()[0], 1)})
    return rows


def agreement_rows(seed: int = 0) -> list[dict]:
    from scipy.stats import chi2

    from slamcli.io.export import read_tum, write_tum
    from slamcli.metrics.consistency import chi2_ppf
    from slamcli.metrics.trajectory import umeyama_se2

    rows = []
    q = np.array([1e-6, 0.025, 0.5, 0.95, 0.975, 0.9999])
    diffs = [np.max(np.abs(chi2_ppf(q, d) - chi2.ppf(q, d))) for d in (1, 2, 3, 6, 150, 2000)]
    rows.append({"piece": "chi2 quantile", "side": "chi2_ppf vs scipy.stats.chi2.ppf", "max_abs_diff": float(max(diffs))})
    if not _installed("evo"):
        return rows
    from evo.core.geometry import umeyama_alignment
    from evo.tools import file_interface

    rng = np.random.default_rng(seed)
    n = 500
    poses = np.column_stack([np.cumsum(rng.normal(0, 1, n)), np.cumsum(rng.normal(0, 1, n)),
                             rng.uniform(-np.pi, np.pi, n)])
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "t.tum"
        write_tum(path, np.arange(n) * 0.1, poses)
        t_ours, p_ours = read_tum(path)
        traj = file_interface.read_tum_trajectory_file(str(path))
    T = np.asarray(traj.poses_se3)
    yaw_evo = np.arctan2(T[:, 1, 0], T[:, 0, 0])
    d_read = max(np.max(np.abs(traj.timestamps - t_ours)), np.max(np.abs(traj.positions_xyz[:, :2] - p_ours[:, :2])),
                 np.max(np.abs(np.angle(np.exp(1j * (yaw_evo - p_ours[:, 2]))))))
    rows.append({"piece": "TUM/KITTI + SE(2) alignment", "side": "read_tum vs evo read_tum_trajectory_file",
                 "max_abs_diff": float(d_read)})
    th = 0.7
    R_true = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    dst = poses[:, :2] @ R_true.T + [3.0, -2.0] + rng.normal(0, 0.1, (n, 2))
    R, t = umeyama_se2(poses[:, :2], dst)
    lift = lambda a: np.vstack([a.T, np.zeros(len(a))])
    R3, t3, _ = umeyama_alignment(lift(poses[:, :2]), lift(dst), with_scale=False)
    rows.append({"piece": "TUM/KITTI + SE(2) alignment", "side": "umeyama_se2 vs evo umeyama_alignment",
                 "max_abs_diff": float(max(np.max(np.abs(R - R3[:2, :2])), np.max(np.abs(t - t3[:2]))))})
    return rows


def run(quick: bool = False) -> list[dict]:
    return import_rows(2 if quick else REPEATS) + agreement_rows()
