"""slamcli: a command-line experiment runner for 2-D SLAM research — and a small Python API for notebooks::

    import slamcli as sc
    ds = sc.simulate("loop", seed=1)
    r = sc.solve(ds, "icm", R=(1,))
    m = sc.evaluate(r, ds)
    sc.plot.map(r, ds, ax=ax)

Importing this package is cheap on purpose (no numpy, no h5py): ``slamcli --help`` must answer fast. The
API (:mod:`slamcli.api.facade`, :mod:`slamcli.api.plot`) is loaded on first attribute access (PEP 562).
"""

__version__ = "0.1.0"

#: public attribute → module that defines it (imported on first use)
_LAZY = {
    "simulate": "slamcli.api.facade",
    "solve": "slamcli.api.facade",
    "evaluate": "slamcli.api.facade",
    "export": "slamcli.api.facade",
    "import_trajectory": "slamcli.api.facade",
    "aggregate": "slamcli.api.facade",
    "load": "slamcli.api.facade",
    "save": "slamcli.api.facade",
    "solver_names": "slamcli.api.facade",  # (slamcli.solvers is the solver package)
}
__all__ = ["__version__", "plot", *_LAZY]


def __getattr__(name: str):
    import importlib

    if name == "plot":
        return importlib.import_module("slamcli.api.plot")
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'slamcli' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
