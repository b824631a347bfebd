"""Curves: landmark error per iteration (paper 000 Figs 5e/f), map change per iteration (Fig. 9d), and the
Monte-Carlo average NEES with its χ² band. Each function draws pre-computed arrays into a given axis."""

from __future__ import annotations

import numpy as np


def legend_below(ax, ncol: int = 3):
    """Legend under the axis so it never hides data (constrained layout makes room)."""
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=ncol, fontsize="small", frameon=False)


def plot_error_curves(ax, iterations, err_min_m, err_mean_m, err_max_m, title: str | None = None):
    """Minimum / mean / maximum nearest-true-landmark error per iteration (paper convention)."""
    ax.plot(iterations, err_max_m, "-", color="tab:red", lw=1.2, label="Maximum error")
    ax.plot(iterations, err_mean_m, "-", color="black", lw=1.5, label="Mean error")
    ax.plot(iterations, err_min_m, "-", color="tab:blue", lw=1.2, label="Minimum error")
    ax.set_xlabel("Iteration (0 = initialisation)")
    ax.set_ylabel("Landmark error to nearest true landmark (m)")
    ax.set_ylim(bottom=0)
    ax.grid(True, lw=0.3, alpha=0.5)
    if title:
        ax.set_title(title)
    legend_below(ax, ncol=3)
    return ax


def plot_map_change(ax, iterations, map_change_m, title: str | None = None, label: str | None = None):
    """Mean norm of the landmark displacement between consecutive iterations (m), paper Fig. 9d."""
    it = np.asarray(iterations)
    mc = np.asarray(map_change_m, float)
    keep = it > 0  # iteration 0 has no predecessor
    ax.plot(it[keep], mc[keep] * 1000.0, "o-", ms=3, lw=1.2, label=label or "Map change")
    ax.set_xlabel("Iteration")
    ax.set_ylabel("Map change per iteration (mm)")
    # y from 0 to the largest value of every series drawn so far (several calls may overlay results)
    tops = [np.nanmax(np.asarray(ln.get_ydata(), float), initial=0.0) for ln in ax.lines]
    ax.set_ylim(0, 1.05 * max(max(tops, default=0.0), 1e-9))
    ax.grid(True, lw=0.3, alpha=0.5)
    if title:
        ax.set_title(title)
    legend_below(ax, ncol=2)
    return ax


def plot_nees(ax, steps, anees, lower: float, upper: float, dof: int, n_runs: int,
              fraction_inside: float | None = None, label: str | None = None, title: str | None = None):
    """Average NEES per step against the two-sided 95 % χ² band ``[lower, upper]`` (E[NEES] = d)."""
    ax.axhspan(lower, upper, color="tab:green", alpha=0.15, lw=0,
               label=f"95% χ² band [{lower:.2f}, {upper:.2f}] (N={n_runs})")
    ax.axhline(dof, color="tab:green", lw=0.8, ls="--", label=f"E[NEES] = d = {dof}")
    lab = label or "Average NEES"
    if fraction_inside is not None and np.isfinite(fraction_inside):
        lab += f" ({100 * fraction_inside:.0f}% of steps inside)"
    ax.plot(steps, anees, "-", color="tab:blue", lw=1.0, label=lab)
    ax.set_xlabel("Step")
    ax.set_ylabel(f"Average NEES over {n_runs} runs (d = {dof})")
    finite = np.asarray(anees, float)[np.isfinite(anees)]
    top = max(upper * 1.3, float(np.percentile(finite, 99)) * 1.1 if finite.size else upper * 1.3)
    ax.set_ylim(0, top)
    ax.grid(True, lw=0.3, alpha=0.5)
    if title:
        ax.set_title(title)
    legend_below(ax, ncol=2)
    return ax
