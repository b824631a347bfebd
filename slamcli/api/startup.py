"""Start-up of the processes slamcli owns (the ``slamcli`` command, sweep workers): NumPy submodules that SciPy
makes every process execute and that no slamcli command uses are registered as lazily executed modules.

SciPy's vendored ``array_api_compat`` runs ``from numpy import *`` whenever ``scipy.sparse`` is imported (SciPy
1.14 to 1.17 at least), and since NumPy 2.0 ``numpy.__all__`` names the lazily loaded submodules, so that
statement executes ``numpy.f2py``, ``numpy.testing`` (with ``unittest``, ``argparse``, ``logging``,
``importlib.metadata``, …), ``numpy.ma``, ``numpy.polynomial`` and others: 306 M of the 1722 M instructions
of a 1k-pose default ``slamcli solve --method graph`` (valgrind callgrind, ``benchmarks/bench_graph_startup.py``).
:func:`defer_unused_numpy_submodules` gives each of them a module object whose code runs on its first attribute
access (the standard library's :class:`importlib.util.LazyLoader`): ``from numpy import *`` binds the object,
and code that really uses ``numpy.testing`` or ``numpy.f2py`` gets the real module — also when its first use is
the import of a submodule (:class:`_LoadedByParent`). Importing this module, or ``slamcli``, changes nothing;
only the command-line entry point and sweep workers call the function. (Python 3.11's LazyLoader takes no lock:
two threads touching a deferred module for the first time at the same instant could both execute it; no
slamcli code uses these modules.)
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys
from types import ModuleType

#: ``numpy.__all__`` submodules that ``from numpy import *`` executes and that a default graph solve never uses
#: (with every lazily loaded submodule deferred, a solve touches only ``numpy.random``, ``numpy.fft`` and
#: ``numpy.typing``, which SciPy imports itself)
UNUSED_NUMPY_SUBMODULES = ("char", "core", "ctypeslib", "f2py", "ma", "polynomial", "rec", "strings", "testing")


def defer_unused_numpy_submodules(names: tuple[str, ...] = UNUSED_NUMPY_SUBMODULES) -> None:
    """Register ``numpy.<name>`` for each of ``names`` as a lazily executed module (module docstring).

    NumPy is not imported for this: when it is not imported yet, a one-shot finder at the front of
    ``sys.meta_path`` registers the modules right after NumPy's own ``__init__`` has run (``slamcli --help``
    never imports NumPy). A submodule already imported, or absent from the installed NumPy, is left alone.
    """
    numpy = sys.modules.get("numpy")
    if numpy is not None:
        _register_lazy(numpy, names)
    elif not any(isinstance(f, _AfterNumpy) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterNumpy(names))


def _register_lazy(numpy: ModuleType, names: tuple[str, ...]) -> None:
    deferred = []
    for name in names:
        full = f"numpy.{name}"
        # ``numpy.__dict__``, not hasattr: NumPy's module __getattr__ would import the submodule
        if full in sys.modules or name in numpy.__dict__:
            continue
        spec = importlib.machinery.PathFinder.find_spec(full, numpy.__path__)
        if spec is None or spec.loader is None:
            continue
        spec.loader = importlib.util.LazyLoader(spec.loader)
        module = importlib.util.module_from_spec(spec)
        sys.modules[full] = module
        spec.loader.exec_module(module)
        setattr(numpy, name, module)  # as the import system does for a submodule it loads
        deferred.append(full + ".")
    if deferred:
        sys.meta_path.insert(0, _LoadedByParent(tuple(deferred)))


class _LoadedByParent:
    """A meta path finder for the submodules of the deferred packages: it hands back the module their package
    has just imported.

    ``import numpy.ma.core`` as the first touch of the lazy ``numpy.ma`` reads ``numpy.ma.__path__``, which
    executes ``numpy/ma/__init__.py`` — and that imports ``numpy.ma.core`` itself. The import system has
    already decided to load ``numpy.ma.core`` (it was not in ``sys.modules`` a moment before), so without
    this finder it would execute it a second time: two module objects and two ``MaskedArray`` classes.
    """

    def __init__(self, prefixes: tuple[str, ...]) -> None:
        self.prefixes = prefixes

    def find_spec(self, fullname, path=None, target=None):
        if not fullname.startswith(self.prefixes) or fullname not in sys.modules:
            return None
        return importlib.util.spec_from_loader(fullname, _Loaded(sys.modules[fullname]))


class _Loaded:
    """Loader of a module that is in ``sys.modules`` already: returns it, executes nothing and gives it back
    its own ``__spec__`` (the import system sets the spec it loads with)."""

    def __init__(self, module: ModuleType) -> None:
        self.module, self.spec = module, module.__spec__

    def create_module(self, spec):
        return self.module

    def exec_module(self, module: ModuleType) -> None:
        module.__spec__ = self.spec


class _AfterNumpy:
    """A meta path finder (duck-typed: ``importlib.abc`` is slow to import) that finds nothing itself: on
    the import of ``numpy`` it removes itself, lets the other finders locate NumPy, and wraps the loader so that
    :func:`_register_lazy` runs right after NumPy's ``__init__``."""

    def __init__(self, names: tuple[str, ...]) -> None:
        self.names = names

    def find_spec(self, fullname, path=None, target=None):
        if fullname != "numpy":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(fullname)
        if spec is not None and spec.loader is not None:
            spec.loader = _ThenDefer(spec.loader, self.names)
        return spec


class _ThenDefer:
    """NumPy's own loader, then :func:`_register_lazy`; the module keeps NumPy's loader as ``__loader__``."""

    def __init__(self, loader, names: tuple[str, ...]) -> None:
        self.loader, self.names = loader, names

    def create_module(self, spec):
        return self.loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        module.__spec__.loader = module.__loader__ = self.loader
        self.loader.exec_module(module)
        _register_lazy(module, self.names)
