"""Publication plots. Functions in :mod:`~slamcli.plots.maps` and :mod:`~slamcli.plots.curves` draw
pre-computed arrays into a given matplotlib ``ax`` and compute no metric (the evo convention); this module
only creates figures on the non-interactive Agg backend and saves them atomically.
"""

from __future__ import annotations

import os
from pathlib import Path

FORMATS = (".png", ".pdf")


def new_figure(width_in: float = 6.4, height_in: float = 4.8):
    """A figure with one axis on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    ax = fig.add_subplot(1, 1, 1)
    return fig, ax


def save_figure(fig, path: str | os.PathLike, dpi: int = 200) -> Path:
    """Save ``fig`` to ``path`` (``.png`` or ``.pdf``) atomically: temp file in the same directory, then
    ``os.replace``, so a crash never leaves a half-written image."""
    from slamcli.errors import ConfigError
    from slamcli.io import atomic_path

    final = Path(path)
    fmt = final.suffix.lower()
    if fmt not in FORMATS:
        raise ConfigError(f"{final}: unsupported image format {final.suffix or '(none)'!r}; use .png or .pdf")
    with atomic_path(final) as tmp:
        fig.savefig(tmp, format=fmt[1:], dpi=dpi)
    return final
