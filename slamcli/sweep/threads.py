"""One BLAS/OpenMP thread per run: a sweep's parallelism is over runs, and a run's numbers must not depend on
how many threads its linear algebra had (``-j 1``, ``-j N`` and Dask give the same numbers).

The thread counts are read when NumPy (and CVXOPT's OpenBLAS) load, so the variables must be set before that:
in the command's own process by :func:`one_blas_thread`, in spawned workers by :func:`single_threaded_blas`
around their start. A value the user exported is kept. Numpy-free.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

#: the thread-count variables of OpenMP, OpenBLAS and MKL
BLAS_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def one_blas_thread() -> None:
    """Set each of :data:`BLAS_THREAD_VARS` to 1 in this process's environment unless already set."""
    for key in BLAS_THREAD_VARS:
        os.environ.setdefault(key, "1")


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """:func:`one_blas_thread` for the processes started inside the block; the environment is given back after."""
    old = {k: os.environ.get(k) for k in BLAS_THREAD_VARS}
    one_blas_thread()
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
