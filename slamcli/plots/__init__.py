"""Publication plots. Functions in :mod:`~slamcli.plots.maps` and :mod:`~slamcli.plots.curves` draw
pre-computed arrays into a given matplotlib ``ax`` and compute no metric (the evo convention); this module
only creates figures on the non-interactive Agg backend and saves them atomically.
"""

from __future__ import annotations

import os
from pathlib import Path

FORMATS = (".png", ".pdf", ".svg")
#: fonts embedded as TrueType (Type 42), not matplotlib's default Type 3, which IEEE PDF eXpress rejects
FONT_RC = {"pdf.fonttype": 42, "ps.fonttype": 42}


def parse_size(text: str | None, default: tuple[float, float]) -> tuple[float, float]:
    """``"6.4x4.8"`` (inches, ``x`` or ``,``) → ``(6.4, 4.8)``; None → ``default``. One-line ConfigError otherwise."""
    from slamcli.errors import ConfigError

    if text is None:
        return default
    parts = text.lower().replace(",", "x").split("x")
    try:
        w, h = (float(p) for p in parts)
    except ValueError:
        raise ConfigError(f"--size: expected WIDTHxHEIGHT in inches, e.g. 6.4x4.8, got {text!r}") from None
    if not (0 < w <= 100 and 0 < h <= 100):
        raise ConfigError(f"--size: width and height must be in (0, 100] inches, got {text!r}")
    return w, h


def new_figure(width_in: float = 6.4, height_in: float = 4.8, nrows: int = 1, sharex: bool = False):
    """A figure on the Agg backend (no display needed) with one axis, or ``nrows`` stacked axes (array)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    if nrows == 1:
        return fig, fig.add_subplot(1, 1, 1)
    return fig, fig.subplots(nrows, 1, sharex=sharex)


def check_format(path: str | os.PathLike) -> str:
    """The image format of ``path`` from its extension (``png``, ``pdf`` or ``svg``); ConfigError otherwise."""
    from slamcli.errors import ConfigError

    fmt = Path(path).suffix.lower()
    if fmt not in FORMATS:
        raise ConfigError(f"{path}: unsupported image format {Path(path).suffix or '(none)'!r}; "
                          f"use .png, .pdf or .svg")
    return fmt[1:]


def save_figure(fig, path: str | os.PathLike, dpi: int = 200) -> Path:
    """Save ``fig`` to ``path`` (``.png``, ``.pdf`` or ``.svg``, by extension) atomically: temp file in the
    same directory, then ``os.replace``, so a crash never leaves a half-written image. ``dpi`` sets the
    raster resolution (PNG; PDF/SVG are vector). PDF fonts are embedded as TrueType (:data:`FONT_RC`)."""
    import io

    from slamcli.errors import ConfigError
    from slamcli.io.atomic import write_bytes_atomic

    final = Path(path)
    fmt = check_format(final)
    if not dpi > 0:
        raise ConfigError(f"--dpi: must be > 0, got {dpi}")
    import matplotlib

    buf = io.BytesIO()  # rendered in memory: matplotlib's PDF writer crashed on a full disk (AttributeError)
    with matplotlib.rc_context(FONT_RC):
        fig.savefig(buf, format=fmt, dpi=dpi)
    write_bytes_atomic(final, buf.getbuffer())
    return final
