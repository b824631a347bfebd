"""Curves: landmark error per iteration (paper 000 Figs 5e/f), map change per iteration (Fig. 9d), and the
Monte-Carlo average NEES with its χ² band. Each function draws pre-computed arrays into a given axis."""

from __future__ import annotations

import numpy as np

from slamcli.plots import style


def legend_below(ax, ncol: int = 3):
    """Legend under the axis, below its tick labels and x label, so it never hides data or the label
    (constrained layout makes room); at most ``ncol`` columns, fewer when the labels would not fit the
    figure's width (:func:`style.legend_columns`)."""
    _, labels = ax.get_legend_handles_labels()
    n = style.legend_columns(labels, ax.figure.get_figwidth(), max_cols=ncol)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=_below(ax), ncol=n, fontsize=style.SMALL_PT, frameon=False, borderaxespad=0.0, handlelength=1.8,
              columnspacing=1.0)


def _below(ax):
    """Axes coordinates shifted down past the x tick labels and x label (:func:`style.below_axis_in`)."""
    from matplotlib.transforms import ScaledTranslation

    return ax.transAxes + ScaledTranslation(0.0, -style.below_axis_in(ax), ax.figure.dpi_scale_trans)


def plot_error_curves(ax, iterations, err_min_m, err_mean_m, err_max_m, title: str | None = None):
    """Minimum / mean / maximum nearest-true-landmark error per iteration (paper convention)."""
    ax.plot(iterations, err_max_m, "-", color=style.EST_LANDMARK, lw=style.LINE_PT, label="Maximum error")
    ax.plot(iterations, err_mean_m, "-", color=style.TRUTH, lw=1.3, label="Mean error")
    ax.plot(iterations, err_min_m, "-", color=style.ESTIMATE, lw=style.LINE_PT, label="Minimum error")
    ax.set_xlabel("Iteration (0 = initialisation)")
    ax.set_ylabel("Landmark error (m)")
    ax.set_ylim(bottom=0)
    ax.grid(True, **style.GRID)
    if title:
        ax.set_title(title)
    legend_below(ax, ncol=3)
    return ax


def plot_map_change(ax, iterations, map_change_m, title: str | None = None, label: str | None = None,
                    log: bool = False):
    """Mean norm of the landmark displacement between consecutive iterations (m), paper Fig. 9d.

    ``log``: logarithmic y axis (zero changes, which a log axis cannot show, are left out), so several
    overlaid results that converge at different rates all stay readable.
    """
    it = np.asarray(iterations)
    mc = np.asarray(map_change_m, float)
    keep = it > 0  # iteration 0 has no predecessor
    if log:
        keep &= mc > 0
    ax.plot(it[keep], mc[keep] * 1000.0, "o-", ms=2.5, lw=style.LINE_PT, label=label or "Map change")
    ax.set_xlabel("Iteration")
    ax.set_ylabel("Map change (mm)")
    if log:
        ax.set_yscale("log")
    else:
        # y from 0 to the largest value of every series drawn so far (several calls may overlay results)
        tops = [np.nanmax(np.asarray(ln.get_ydata(), float), initial=0.0) for ln in ax.lines]
        ax.set_ylim(0, 1.05 * max(max(tops, default=0.0), 1e-9))
    ax.grid(True, which="both" if log else "major", **style.GRID)
    if title:
        ax.set_title(title)
    legend_below(ax, ncol=2)
    return ax


def plot_nees(ax, steps, anees, lower: float, upper: float, dof: int, n_runs: int,
              fraction_inside: float | None = None, label: str | None = None, title: str | None = None,
              log: bool = True):
    """Average NEES per step against the two-sided 95 % χ² band ``[lower, upper]`` (E[NEES] = d).

    ``log`` (default): logarithmic y axis whose limits include the band and every positive value, so an
    inconsistent filter (NEES in the hundreds), a near-zero step and the band are all visible.
    """
    ax.axhspan(lower, upper, color=style.BAND, alpha=0.2, lw=0,
               label=f"95% χ² band [{lower:.2f}, {upper:.2f}] (N={n_runs})")
    ax.axhline(dof, color=style.BAND, lw=0.8, ls="--", label=f"E[NEES] = d = {dof}")
    lab = label or "Average NEES"
    if fraction_inside is not None and np.isfinite(fraction_inside):
        lab += f" ({100 * fraction_inside:.0f}% of steps inside)"
    ax.plot(steps, anees, "-", color=style.ESTIMATE, lw=style.LINE_PT, label=lab)
    ax.set_xlabel("Step")
    ax.set_ylabel("Average NEES")  # N and d are in the legend (band and E[NEES] = d)
    a = np.asarray(anees, float)
    finite = a[np.isfinite(a) & (a > 0)] if log else a[np.isfinite(a)]
    if log:
        ax.set_yscale("log")
        lo = min(lower / 2, float(np.min(finite)) / 1.5) if finite.size else lower / 2  # every value shows
        hi = max(upper * 2, float(np.max(finite)) * 1.5) if finite.size else upper * 2
        ax.set_ylim(lo, hi)
    else:
        top = max(upper * 1.3, float(np.percentile(finite, 99)) * 1.1 if finite.size else upper * 1.3)
        ax.set_ylim(0, top)
    ax.grid(True, which="both" if log else "major", **style.GRID)
    if title:
        ax.set_title(title)
    legend_below(ax, ncol=2)
    return ax


def plot_pose_errors(axes, steps, err_xyt, sigma_xyt=None, n_sigma: float = 3.0, fraction_inside=None,
                     title: str | None = None):
    """Per-step signed pose error (estimate − truth; heading wrapped) in three stacked axes with the
    ``±n_sigma·σ`` band of the estimator's own marginal covariance (the ``evo_ape --plot`` view plus the
    filter's claimed uncertainty). Headings in radians, the one angle unit of tables and figures.

    Parameters
    ----------
    axes : 3 matplotlib Axes (x, y, θ).
    steps : (T+1,)     err_xyt : (T+1, 3)    sigma_xyt : (T+1, 3) | None   √diag of the pose covariance.
    fraction_inside : (3,) | None   share of steps whose error lies inside the band, per component (legend).
    """
    from slamcli.metrics.registry import ANGLE_UNIT

    names = ("Δx (m)", "Δy (m)", f"Δθ ({ANGLE_UNIT})")  # short: three panels fit one column
    steps = np.asarray(steps)
    err = np.asarray(err_xyt, float)
    band_label = f"±{n_sigma:g}σ"
    if fraction_inside is not None:
        band_label += " (inside: " + ", ".join(f"{c} {100 * f:.0f}%" for c, f in zip("xyθ", fraction_inside)) + ")"
    for k, ax in enumerate(axes):
        if sigma_xyt is not None:
            band = n_sigma * np.asarray(sigma_xyt, float)[:, k]
            ax.fill_between(steps, -band, band, color=style.ACCENT, alpha=0.3, lw=0,
                            label=band_label if k == 0 else None)
        ax.plot(steps, err[:, k], "-", color=style.ESTIMATE, lw=0.8, label="estimate − truth" if k == 0 else None)
        ax.axhline(0.0, color=style.TRUTH, lw=0.5)
        ax.set_ylabel(names[k])
        ax.grid(True, **style.GRID)
        ax.label_outer()
    axes[-1].set_xlabel("Step")
    handles, labels = axes[0].get_legend_handles_labels()
    axes[-1].legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0),
                    bbox_transform=_below(axes[-1]), ncol=style.legend_columns(labels, axes[-1].figure.get_figwidth(), 2),
                    fontsize=style.SMALL_PT, frameon=False, borderaxespad=0.0)
    if title:
        axes[0].set_title(title)
    return axes


def plot_compare(ax, labels, values, ylabel: str, xlabel: str = "", title: str | None = None,
                 nonnegative: bool = False, log: bool = False):
    """Box plot per group with every run drawn on top (strip plot; points spread evenly across the box
    width, no random jitter), e.g. ATE per solver over the replicates of a sweep. Boxes: median and
    quartiles, whiskers to the furthest run within 1.5 IQR. Group labels that would collide are slanted,
    and set upright when slanted ones still touch (:func:`tick_labels_overlap`, measured after a draw).

    Parameters
    ----------
    labels : list of str (G,)          values : list of (n_g,) arrays.
    ylabel, xlabel : axis labels (names and units from :mod:`slamcli.metrics.registry`).
    nonnegative : the metric cannot be negative: the y axis starts at 0 (unless ``log``).
    log : logarithmic y axis (values must be > 0).
    """
    pos = np.arange(1, len(labels) + 1)
    ax.boxplot([np.asarray(v, float) for v in values], positions=pos, widths=0.5, showfliers=False,
               medianprops={"color": style.TRUTH, "lw": style.LINE_PT},
               boxprops={"lw": style.THIN_PT}, whiskerprops={"lw": style.THIN_PT}, capprops={"lw": style.THIN_PT})
    for p, v in zip(pos, values):
        v = np.asarray(v, float)
        dx = np.linspace(-0.15, 0.15, len(v)) if len(v) > 1 else np.zeros(len(v))
        ax.plot(p + dx, v, "o", ms=2.5, alpha=0.75, color=style.ESTIMATE, ls="none")
    stacked = [lab.replace(", ", "\n") for lab in labels]  # "ekf, gate_prob=0.9" on two lines
    if not style.labels_collide(stacked, ax.figure.get_figwidth()):
        ax.set_xticks(pos, [f"{lab}\n(n={len(v)})" for lab, v in zip(stacked, values)])
    else:  # too many or too long: slanted, one line each
        ax.set_xticks(pos, [f"{lab} (n={len(v)})" for lab, v in zip(labels, values)], rotation=30, ha="right",
                      rotation_mode="anchor")
    ax.set_ylabel(ylabel)
    if xlabel:
        ax.set_xlabel(xlabel)
    if log:
        from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

        ax.set_yscale("log")
        ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))  # 0.1, 0.2, 0.5, 1, ...: labelled
        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.yaxis.set_minor_formatter(NullFormatter())
    elif nonnegative:
        ax.set_ylim(bottom=0)
    style.apply_style(ax.figure)  # measure at the sizes the figure is saved with
    if tick_labels_overlap(ax):
        ax.set_xticks(pos, [f"{lab} (n={len(v)})" for lab, v in zip(labels, values)], rotation=90, ha="center",
                      rotation_mode="default")
    ax.grid(True, axis="y", which="both" if log else "major", **style.GRID)
    if title:
        ax.set_title(title)
    return ax


def tick_labels_overlap(ax) -> bool:
    """Do two neighbouring x tick labels of ``ax`` touch on the canvas, measured after a draw of the figure?
    Upright labels: their window extents intersect. Labels rotated by θ (all alike): the gap between the
    parallel text lines, ``Δx·sin θ`` for anchors ``Δx`` pixels apart, is less than a line's height."""
    ax.figure.draw_without_rendering()
    ticks = [(x, t) for x, t in zip(ax.get_xticks(), ax.get_xticklabels()) if t.get_visible() and t.get_text()]
    for (xa, a), (xb, b) in zip(ticks, ticks[1:]):
        theta = np.radians(a.get_rotation() % 180.0)
        if abs(np.sin(theta)) < 1e-9:
            if a.get_window_extent().overlaps(b.get_window_extent()):
                return True
            continue
        dx_px = abs(ax.transData.transform((xb, 0.0))[0] - ax.transData.transform((xa, 0.0))[0])
        line_px = 1.2 * a.get_fontsize() * ax.figure.dpi / 72.0
        if dx_px * abs(np.sin(theta)) < line_px:
            return True
    return False
