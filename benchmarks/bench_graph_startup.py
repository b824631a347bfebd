"""Start-up + solve of a 1k-pose pose graph, whole process: ``slamcli solve --method graph`` (defaults) vs a
Python script that reads the same g2o file with GTSAM and runs its LM (issue 25 item 1: within 1.5×).

The graph: 1000 poses on a seeded random walk around a square loop with a loop closure every 50 poses back to
the pose 200 steps earlier (noise from a seeded numpy Generator), written as a g2o file and imported once
(not timed). Each side runs in a fresh interpreter; CPU = user + system time of the child
(``resource.getrusage(RUSAGE_CHILDREN)``), single-threaded BLAS, median of ``REPEATS`` runs in alternating order.
Both sides run with their bytecode cached, as after any ``pip install`` (which byte-compiles what it installs):
the children write and read ``.pyc`` files under a throw-away ``PYTHONPYCACHEPREFIX`` and each command runs
once untimed first. Without that, an environment with ``PYTHONDONTWRITEBYTECODE=1`` and an editable install
re-compiled every slamcli module from source on every run (≈ 0.1 s CPU) while GTSAM's site-packages were
read from the ``.pyc`` files pip had written.
Columns: ``cpu_slamcli_s`` (defaults: certificate and marginals included), ``cpu_slamcli_nocov_s``
(``-p covariance=false``), ``cpu_gtsam_s`` and the ratios. The machine may be loaded: read the ratios.

Breakdown, measured in the same alternating rounds: ``cpu_imports_s`` is a process that only imports the
libraries a default solve needs (numpy, scipy.sparse, h5py, typer, and sksparse.cholmod when installed) the way
``slamcli`` imports them — the floor below which no change inside slamcli goes; ``cpu_gtsam_import_s`` the same
for ``import gtsam``; ``cpu_numpy_star_s`` is what ``from numpy import *`` adds to ``import numpy`` when nothing
is deferred. SciPy (1.14 to 1.17 at least) runs that statement in its vendored ``array_api_compat.numpy``
whenever ``scipy.sparse`` is imported, and since NumPy 2.0 ``numpy.__all__`` names the lazily loaded
submodules, so it would execute ``numpy.f2py`` and ``numpy.testing`` (argparse, logging, unittest,
importlib.metadata, …) in every process that uses ``scipy.sparse``; the ``slamcli`` command defers them
(:mod:`slamcli.api.startup`), so this column is what the deferral saves. ``cpu_scipy_linalg_s`` is what
``import scipy.linalg`` adds to the floor: a default solve imports it for LAPACK's triangular inverse in the
marginals (``solvers/nls/selinv.py``), the largest import above the floor.

CPU time on a shared machine moves with its load (the ratio of the same code ranged 1.48-1.75 between three
runs at load average 2-3), so where valgrind is installed the ``instr_*`` columns count the instructions of one
run of the main sides under callgrind (millions; ``instr_ratio`` = ours / GTSAM's, the load-independent ratio).
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

N_POSES = 1000
REPEATS = 7
GTSAM_SCRIPT = """
import sys, gtsam
graph, values = gtsam.readG2o(sys.argv[1], False)
graph.add(gtsam.PriorFactorPose2(0, values.atPose2(0), gtsam.noiseModel.Diagonal.Sigmas([1e-4, 1e-4, 1e-4])))
out = gtsam.LevenbergMarquardtOptimizer(graph, values, gtsam.LevenbergMarquardtParams()).optimize()
print(graph.error(out))
"""
#: what ``slamcli`` runs before anything imports SciPy (:func:`slamcli.api.startup.defer_unused_numpy_submodules`)
DEFER = "from slamcli.api.startup import defer_unused_numpy_submodules; defer_unused_numpy_submodules()"


def write_graph(path: Path, n: int = N_POSES, seed: int = 0) -> None:
    """Seeded synthetic pose graph (see module docstring) as EDGE_SE2 / VERTEX_SE2 lines."""
    from slamcli.models import se2

    rng = np.random.default_rng(seed)
    d_true = np.tile([1.0, 0.0, 0.0], (n - 1, 1))
    d_true[np.arange(n - 1) % 50 == 49, 2] = np.pi / 2  # a square every 200 steps
    poses = np.zeros((n, 3))
    for k in range(n - 1):
        poses[k + 1] = se2.compose(poses[k], d_true[k])
    sig = np.array([0.05, 0.05, 0.01])
    info = "{:.6g} 0 0 {:.6g} 0 {:.6g}".format(*(1 / sig**2))
    lines, odo = [], poses[:1].copy()
    for k in range(n - 1):
        m = d_true[k] + sig * rng.normal(size=3)
        odo = np.vstack([odo, se2.compose(odo[-1], m)])
        lines.append(f"EDGE_SE2 {k} {k + 1} {m[0]:.9g} {m[1]:.9g} {m[2]:.9g} {info}")
    for j in range(249, n, 50):
        i = j - 200
        m = se2.between(poses[i], poses[j]) + sig * rng.normal(size=3)
        lines.append(f"EDGE_SE2 {i} {j} {m[0]:.9g} {m[1]:.9g} {m[2]:.9g} {info}")
    verts = [f"VERTEX_SE2 {k} {p[0]:.9g} {p[1]:.9g} {p[2]:.9g}" for k, p in enumerate(odo)]
    path.write_text("\n".join(verts + lines) + "\n")


def _child_cpu(cmd: list[str], env: dict) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, env=env, check=True, capture_output=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def run(quick: bool = False) -> list[dict]:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    cli = [sys.executable, "-m", "slamcli"]
    with tempfile.TemporaryDirectory() as tmp:
        env["PYTHONPYCACHEPREFIX"] = str(Path(tmp) / "pycache")
        g2o, ds = Path(tmp) / "g.g2o", Path(tmp) / "g.h5"
        write_graph(g2o)
        subprocess.run(cli + ["import", "g2o", str(g2o), "-q", "-o", str(ds)], env=env, check=True)
        sides = {
            "ours": lambda out: cli + ["solve", str(ds), "--method", "graph", "-q", "-o", out],
            "nocov": lambda out: cli + ["solve", str(ds), "--method", "graph", "-p", "covariance=false", "-q",
                                        "-o", out],
            "gtsam": lambda out: [sys.executable, "-c", GTSAM_SCRIPT, str(g2o)],
            "imports": lambda out: [sys.executable, "-c", f"{DEFER}; import {', '.join(_solve_libraries())}"],
            "imports_linalg": lambda out: [sys.executable, "-c",
                                           f"{DEFER}; import {', '.join(_solve_libraries())}, scipy.linalg"],
            "gtsam_import": lambda out: [sys.executable, "-c", "import gtsam"],
            "numpy": lambda out: [sys.executable, "-c", "import numpy"],
            "numpy_star": lambda out: [sys.executable, "-c", "import numpy; from numpy import *"],
        }
        for name, cmd in sides.items():  # untimed: writes the bytecode caches (module docstring)
            _child_cpu(cmd(str(Path(tmp) / f"warm-{name}.h5")), env)
        cpu: dict[str, list[float]] = {name: [] for name in sides}
        for k in range(1 if quick else REPEATS):
            for name in list(sides) if k % 2 == 0 else list(sides)[::-1]:  # alternating order
                cpu[name].append(_child_cpu(sides[name](str(Path(tmp) / f"r{k}-{name}.h5")), env))
        instr = {name: _instructions(sides[name](str(Path(tmp) / f"cg-{name}.h5")), env, Path(tmp))
                 for name in INSTRUCTION_SIDES}
    med = {name: float(np.median(v)) for name, v in cpu.items()}
    return [{
        "poses": N_POSES,
        "repeats": len(cpu["ours"]),
        "cpu_slamcli_s": round(med["ours"], 3),
        "cpu_slamcli_nocov_s": round(med["nocov"], 3),
        "cpu_gtsam_s": round(med["gtsam"], 3),
        "ratio": round(med["ours"] / med["gtsam"], 2),
        "ratio_nocov": round(med["nocov"] / med["gtsam"], 2),
        "goal_ratio": 1.5,
        "cpu_imports_s": round(med["imports"], 3),
        "cpu_gtsam_import_s": round(med["gtsam_import"], 3),
        "cpu_numpy_star_s": round(med["numpy_star"] - med["numpy"], 3),
        "cpu_scipy_linalg_s": round(med["imports_linalg"] - med["imports"], 3),
        **_instruction_columns(instr),
    }]


#: the sides also counted in instructions (valgrind callgrind, when installed)
INSTRUCTION_SIDES = ("ours", "nocov", "gtsam", "imports", "imports_linalg")


def _instructions(cmd: list[str], env: dict, tmp: Path) -> float | None:
    """Instructions executed by ``cmd`` (millions) under valgrind's callgrind — independent of the machine's load,
    unlike CPU time; ``PYTHONHASHSEED=0`` so that both sides run the same instructions every time. None without
    valgrind."""
    import re
    import shutil

    if shutil.which("valgrind") is None:
        return None
    out = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={tmp / 'callgrind.%p'}", *cmd],
                         env=dict(env, PYTHONHASHSEED="0"), check=True, capture_output=True, text=True)
    m = re.search(r"Collected\s*:\s*(\d+)", out.stderr)
    return int(m.group(1)) / 1e6 if m else None


def _instruction_columns(instr: dict[str, float | None]) -> dict:
    if any(v is None for v in instr.values()):
        return {}
    return {
        "instr_slamcli_M": round(instr["ours"]),
        "instr_slamcli_nocov_M": round(instr["nocov"]),
        "instr_gtsam_M": round(instr["gtsam"]),
        "instr_ratio": round(instr["ours"] / instr["gtsam"], 2),
        "instr_ratio_nocov": round(instr["nocov"] / instr["gtsam"], 2),
        "instr_imports_M": round(instr["imports"]),
        "instr_scipy_linalg_M": round(instr["imports_linalg"] - instr["imports"]),
    }


def _solve_libraries() -> list[str]:
    """The third-party modules a default graph solve imports (sksparse.cholmod only where it is installed)."""
    import importlib.util

    libs = ["numpy", "scipy.sparse", "h5py", "typer"]
    return libs + (["sksparse.cholmod"] if importlib.util.find_spec("sksparse") is not None else [])
