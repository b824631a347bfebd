"""The one figure style of slamcli: sizes for paper columns, fonts, one colour cycle.

Every figure that ``slamcli plot`` and ``slamcli reproduce`` write goes through :func:`apply_style` (called by
:func:`slamcli.plots.save_figure`), so they share:

* **fonts** embedded as TrueType (``pdf.fonttype`` 42; IEEE PDF eXpress rejects matplotlib's default Type 3),
  DejaVu Sans (ships with matplotlib), 8 pt labels and titles, 7 pt ticks, legends and annotations (the
  size of a caption in a two-column paper at 100 % scale);
* **sizes**: :data:`COLUMN_IN` (3.5 in, one IEEE column) and :data:`PAGE_IN` (7.16 in, both columns);
  ``constrained_layout`` fits labels, legends and colorbars inside the figure (tested at 3.5 × 2.6 in);
* **one colour cycle**, :data:`CYCLE` (Okabe–Ito, readable by colour-blind readers and in grey print), with
  fixed roles for the recurring artists (:data:`ESTIMATE`, :data:`TRUTH`, :data:`ODOMETRY`, ...).

Names and units on axes come from :mod:`slamcli.metrics.registry` (one angle unit: radians).
"""

from __future__ import annotations

#: width of one column of a two-column paper (IEEE), inches
COLUMN_IN = 3.5
#: width of a figure spanning both columns (IEEE ``figure*``), inches
PAGE_IN = 7.16
#: named sizes accepted by ``--size`` (width × height, inches)
NAMED_SIZES = {"column": (COLUMN_IN, 2.6), "page": (PAGE_IN, 3.2)}

#: labels and titles, points
FONT_PT = 8.0
#: ticks, legends, annotations, points
SMALL_PT = 7.0
FONT_FAMILY = "DejaVu Sans"

#: Okabe & Ito (2008) colour-blind-safe palette, in cycle order
CYCLE = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#F0E442")
#: colour roles (one meaning per colour across every figure)
ESTIMATE = CYCLE[0]
EST_LANDMARK = CYCLE[1]
BAND = CYCLE[2]
ACCENT = CYCLE[4]
TRUTH = "black"
ODOMETRY = "0.45"
#: line widths, points
LINE_PT = 1.0
THIN_PT = 0.6
GRID = {"lw": 0.3, "alpha": 0.5}

#: matplotlib rc settings of the style (fonts embedded as TrueType, sizes, colour cycle)
RC = {
    "pdf.fonttype": 42, "ps.fonttype": 42, "svg.fonttype": "path",
    "font.family": "sans-serif", "font.sans-serif": [FONT_FAMILY], "mathtext.fontset": "dejavusans",
    "font.size": FONT_PT, "axes.titlesize": FONT_PT, "axes.labelsize": FONT_PT, "xtick.labelsize": SMALL_PT,
    "ytick.labelsize": SMALL_PT, "legend.fontsize": SMALL_PT, "lines.linewidth": LINE_PT,
    "axes.linewidth": THIN_PT, "figure.constrained_layout.h_pad": 0.02, "figure.constrained_layout.w_pad": 0.02,
}


def series_colours(n: int) -> list[str]:
    """``n`` colours for series of one kind (robots of a team, solvers of an overlay): the :data:`CYCLE`
    without :data:`EST_LANDMARK` (kept for landmark markers), repeated when ``n`` exceeds it."""
    free = [c for c in CYCLE if c != EST_LANDMARK]
    return [free[k % len(free)] for k in range(n)]


def prop_cycle():
    """The colour cycle as a matplotlib ``cycler`` (for ``ax.set_prop_cycle``)."""
    from cycler import cycler

    return cycler(color=list(CYCLE))


def style_axes(ax) -> None:
    """Give an axis the style's colour cycle (before anything is drawn into it)."""
    ax.set_prop_cycle(prop_cycle())


def _texts_of_axes(ax):
    yield from (ax.title, getattr(ax, "_left_title", None), getattr(ax, "_right_title", None))
    yield from (ax.xaxis.label, ax.yaxis.label)


def apply_style(fig) -> None:
    """Set the style's font family and sizes on every text of ``fig`` (titles and labels :data:`FONT_PT`;
    ticks, offsets, legends, annotations :data:`SMALL_PT`), whatever rc settings it was drawn under; inset
    axes (a colorbar beside a map) included."""
    for ax in _all_axes(fig.axes):
        for t in _texts_of_axes(ax):
            if t is not None:
                t.set_fontsize(FONT_PT)
                t.set_fontfamily("sans-serif")
        for t in (ax.title, getattr(ax, "_left_title", None), getattr(ax, "_right_title", None)):
            if t is not None:
                t.set_wrap(True)  # a long --title breaks into lines instead of leaving a one-column figure
        ax.tick_params(which="both", labelsize=SMALL_PT)  # minor labels of a short log axis too
        for t in (*ax.get_xticklabels(), *ax.get_yticklabels()):
            t.set_fontfamily("sans-serif")
        for axis in (ax.xaxis, ax.yaxis):
            axis.get_offset_text().set_fontsize(SMALL_PT)
        for t in ax.texts:
            t.set_fontsize(min(t.get_fontsize(), SMALL_PT))
        leg = ax.get_legend()
        if leg is not None:
            _style_legend(leg)
    for leg in fig.legends:
        _style_legend(leg)
    if getattr(fig, "_suptitle", None) is not None:
        fig._suptitle.set_fontsize(FONT_PT)


def _all_axes(axes):
    for ax in axes:
        yield ax
        yield from _all_axes(getattr(ax, "child_axes", ()))


def _style_legend(leg) -> None:
    for t in leg.get_texts():
        t.set_fontsize(SMALL_PT)
    if leg.get_title().get_text():
        leg.get_title().set_fontsize(SMALL_PT)


def legend_columns(labels, width_in: float, max_cols: int = 3) -> int:
    """Columns of a legend of ``labels`` that fits ``width_in`` inches at :data:`SMALL_PT`: each column is
    a handle with its pad and the column gap (3.6 em, as :func:`~slamcli.plots.curves.legend_below` sets them)
    and the longest label (0.62 em per character, DejaVu Sans' mean advance, rounded up)."""
    em_in = SMALL_PT / 72.0
    longest = max((len(s) for s in labels), default=0)
    col_in = em_in * (3.6 + 0.62 * longest)
    fit = int((0.95 * width_in) // col_in) if col_in > 0 else max_cols
    return max(1, min(max_cols, fit, len(labels) or 1))


def labels_collide(labels, width_in: float) -> bool:
    """Would ``labels`` (possibly of several lines), set side by side as tick labels at :data:`SMALL_PT` over
    ``width_in`` inches (80 % of it for the axis), touch? (0.6 em per character of the longest line, 1 em
    between labels.)"""
    em_in = SMALL_PT / 72.0
    need = sum(em_in * (0.6 * max(len(x) for x in str(s).split("\n")) + 1.0) for s in labels)
    return need > 0.8 * width_in


def below_axis_in(ax) -> float:
    """Height (inches) taken under an axis by its x tick labels and x label at the style's sizes: where a
    legend below the axis starts (tick 3.5 pt + pad 3.5 pt + a 1.2-line tick label, + 4 pt and a 1.2-line
    label when the axis has one, + 3 pt)."""
    pt = 3.5 + 3.5 + 1.2 * SMALL_PT + 3.0
    if ax.get_xlabel():
        pt += 4.0 + 1.2 * FONT_PT * (1 + ax.get_xlabel().count("\n"))
    return pt / 72.0
