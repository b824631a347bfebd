"""Publication plots. Functions in :mod:`~slamcli.plots.maps` and :mod:`~slamcli.plots.curves` draw
pre-computed arrays into a given matplotlib ``ax`` and compute no metric (the evo convention); this module
only creates figures on the non-interactive Agg backend and saves them atomically, in the one style of
:mod:`~slamcli.plots.style` (column sizes, fonts, colour cycle).
"""

from __future__ import annotations

import os
from pathlib import Path

from slamcli.plots.style import COLUMN_IN, NAMED_SIZES, RC, apply_style, style_axes

FORMATS = (".png", ".pdf", ".svg")
#: fonts embedded as TrueType (Type 42), not matplotlib's default Type 3, which IEEE PDF eXpress rejects
FONT_RC = {"pdf.fonttype": RC["pdf.fonttype"], "ps.fonttype": RC["ps.fonttype"]}


def parse_size(text: str | None, default: tuple[float, float]) -> tuple[float, float]:
    """``"6.4x4.8"`` (inches, ``x`` or ``,``) → ``(6.4, 4.8)``; ``column`` / ``page`` → the style's paper
    sizes (3.5 × 2.6 and 7.16 × 3.2 in); None → ``default``. One-line ConfigError otherwise."""
    from slamcli.errors import ConfigError

    if text is None:
        return default
    if text.strip().lower() in NAMED_SIZES:
        return NAMED_SIZES[text.strip().lower()]
    parts = text.lower().replace(",", "x").split("x")
    try:
        w, h = (float(p) for p in parts)
    except ValueError:
        raise ConfigError(f"--size: expected WIDTHxHEIGHT in inches (e.g. 3.5x2.6), column or page, "
                          f"got {text!r}") from None
    if not (0 < w <= 100 and 0 < h <= 100):
        raise ConfigError(f"--size: width and height must be in (0, 100] inches, got {text!r}")
    return w, h


def new_figure(width_in: float = COLUMN_IN, height_in: float = 2.6, nrows: int = 1, ncols: int = 1,
               sharex: bool = False):
    """A figure on the Agg backend (no display needed) with constrained layout and the style's colour cycle:
    one axis, or an array of ``nrows`` × ``ncols`` axes (1-D when one of them is 1)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import numpy as np
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    axes = fig.subplots(nrows, ncols, sharex=sharex, squeeze=False)
    for ax in axes.flat:
        style_axes(ax)
    if nrows == ncols == 1:
        return fig, axes[0, 0]
    return fig, np.squeeze(axes) if 1 in (nrows, ncols) else axes


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
    raster resolution (PNG; PDF/SVG are vector). The style's font sizes are applied to every text
    (:func:`~slamcli.plots.style.apply_style`) and PDF fonts are embedded as TrueType (:data:`FONT_RC`)."""
    import io

    from slamcli.errors import ConfigError
    from slamcli.io.atomic import write_bytes_atomic

    final = Path(path)
    fmt = check_format(final)
    if not dpi > 0:
        raise ConfigError(f"--dpi: must be > 0, got {dpi}")
    import matplotlib

    buf = io.BytesIO()  # rendered in memory: matplotlib's PDF writer crashed on a full disk (AttributeError)
    apply_style(fig)
    with matplotlib.rc_context(RC):
        # one draw first: an equal-aspect axis changes its limits (and tick labels) while drawing, and
        # constrained layout needs the final labels to keep them inside the figure
        fig.draw_without_rendering()
        fig.savefig(buf, format=fmt, dpi=dpi)
    write_bytes_atomic(final, buf.getbuffer())
    return final
