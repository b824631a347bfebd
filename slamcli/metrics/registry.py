"""Names and units of the metrics: the one place a column such as ``ate_rmse_m`` becomes "ATE RMSE (m)".

Every axis, terminal table and LaTeX table takes its wording from here (``slamcli evaluate``, ``aggregate``,
``plot compare``, the reproduce report's compare figure), so a metric is called the same everywhere.

**One angle unit: radians.** The stored metrics are in radians (``*_rad``) and every table and figure shows
them in radians, unconverted (``heading RMSE (rad)``, the heading panel of ``plot errors``).

A column that is not listed gets a name and unit from its suffix (``_m`` → m, ``_rad`` → rad, ``_s`` → s) and
is not assumed non-negative. Pure Python; imports nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

#: the one angle unit of tables and figures
ANGLE_UNIT = "rad"

#: plain-text unit → siunitx unit macro (``\si{...}``)
_SI = {"m": r"\metre", "rad": r"\radian", "s": r"\second", "mm": r"\milli\metre", "m/s": r"\metre\per\second"}
#: suffix of a column name → unit
_SUFFIX_UNITS = (("_mm", "mm"), ("_m", "m"), ("_rad", "rad"), ("_s", "s"))


@dataclass(frozen=True)
class MetricInfo:
    """One metric's display wording.

    key : column / metrics.json key.     name : short human name ("ATE RMSE").
    unit : plain-text unit ("m", "rad", "s"; "" for counts and ratios).
    nonnegative : the metric cannot be below 0 (an interval's lower end is clipped at 0 and flagged).
    """

    key: str
    name: str
    unit: str = ""
    nonnegative: bool = True

    def __post_init__(self):
        if not self.key or not self.name:
            raise ValueError("MetricInfo needs a key and a name")
        if self.unit and self.unit not in _SI:
            raise ValueError(f"{self.key}: unit {self.unit!r} has no siunitx form; add it to _SI")

    @property
    def label(self) -> str:
        """Axis / table label: ``"ATE RMSE (m)"``, or the bare name for a unitless metric."""
        return f"{self.name} ({self.unit})" if self.unit else self.name

    @property
    def si_unit(self) -> str:
        """siunitx unit macro, e.g. ``\\metre`` (empty for a unitless metric)."""
        return _SI.get(self.unit, "")

    @property
    def tex_label(self) -> str:
        """LaTeX header: the name escaped, the unit as ``[\\si{\\metre}]`` (siunitx)."""
        name = tex_escape(self.name)
        return f"{name} [\\si{{{self.si_unit}}}]" if self.unit else name


def _m(key: str, name: str, unit: str = "", nonnegative: bool = True) -> MetricInfo:
    return MetricInfo(key, name, unit, nonnegative)


_METRICS = [
    # trajectory
    _m("ate_rmse_m", "ATE RMSE", "m"),
    _m("aligned_ate_rmse_m", "aligned ATE RMSE", "m"),
    _m("ate_mean_m", "ATE mean", "m"),
    _m("ate_max_m", "ATE max", "m"),
    _m("heading_rmse_rad", "heading RMSE", "rad"),
    _m("aligned_heading_rmse_rad", "aligned heading RMSE", "rad"),
    _m("odometry_ate_rmse_m", "odometry ATE RMSE", "m"),
    _m("rpe_trans_rmse_m", "RPE translation RMSE", "m"),
    _m("rpe_rot_rmse_rad", "RPE rotation RMSE", "rad"),
    # landmarks
    _m("n_landmarks_true", "true landmarks"),
    _m("n_landmarks_est", "estimated landmarks"),
    _m("paper_err_min_m", "landmark error min", "m"),
    _m("paper_err_mean_m", "landmark error mean", "m"),
    _m("paper_err_max_m", "landmark error max", "m"),
    _m("paper_err_mean_near_path_m", "landmark error near path", "m"),
    _m("lm_n_matched", "matched landmarks"),
    _m("lm_n_missed", "missed landmarks"),
    _m("lm_n_spurious", "spurious landmarks"),
    _m("lm_rmse_matched_m", "matched landmark RMSE", "m"),
    _m("lm_aligned_rmse_matched_m", "aligned matched landmark RMSE", "m"),
    _m("lm_ospa_m", "landmark OSPA", "m"),
    _m("lm_gospa_m", "landmark GOSPA", "m"),
    # consistency
    _m("pose_nees_mean", "pose NEES"),
    _m("landmark_nees_mean", "landmark NEES"),
    _m("nis_mean", "NIS"),
    _m("nis_band_lo", "NIS band low"),
    _m("nis_band_hi", "NIS band high"),
    # iterations, cost, time
    _m("n_iterations", "iterations"),
    _m("final_cost", "final cost"),
    _m("solve_time_s", "solve time", "s"),
    _m("ate_reference_m", "ATE vs reference", "m"),
    _m("lm_reference_m", "landmark RMSE vs reference", "m"),
    _m("lm_reference_matched", "landmarks matched"),
    _m("wall_time_s", "wall time", "s"),
    _m("metric.wall_time_s", "solver wall time", "s"),
    # occupancy grids (paper 001)
    _m("grid_frequentist_n_observed", "observed cells"),
    _m("grid_frequentist_mean_abs_error", "map error per cell, frequentist"),
    _m("grid_logodds_mean_abs_error", "map error per cell, log-odds"),
    _m("grid_frequentist_total_abs_error", "total map error, frequentist"),
    _m("grid_logodds_total_abs_error", "total map error, log-odds"),
    _m("grid_frequentist_accuracy", "cell accuracy, frequentist"),
    _m("grid_logodds_accuracy", "cell accuracy, log-odds"),
    # GPS / surveyed references (no ground truth)
    _m("gps_ate_aligned_rmse_m", "GPS ATE RMSE, aligned", "m"),
    _m("gps_ate_rmse_m", "GPS ATE RMSE", "m"),
    _m("gps_ate_aligned_raw_rmse_m", "GPS ATE RMSE, aligned, glitches kept", "m"),
    _m("gps_ate_raw_rmse_m", "GPS ATE RMSE, glitches kept", "m"),
    _m("gps_n_rejected", "GPS glitches rejected"),
    _m("gps_glitch_max_speed_mps", "GPS glitch gate speed", "m/s"),
    _m("gps_glitch_tol_m", "GPS glitch gate tolerance", "m"),
    _m("odometry_gps_ate_aligned_rmse_m", "odometry GPS ATE, aligned", "m"),
    _m("gps_n_matched", "GPS fixes matched"),
    _m("gps_gap_count", "GPS gaps"),
    _m("gps_longest_gap_s", "longest GPS gap", "s"),
    _m("survey_lm_matched", "surveyed landmarks matched"),
    _m("survey_lm_rmse_m", "surveyed landmark RMSE", "m"),
    # against another result
    _m("against_ate_rmse_m", "ATE against other", "m"),
    _m("against_ate_aligned_rmse_m", "aligned ATE against other", "m"),
    _m("against_lm_matched", "landmarks matched to other"),
    _m("against_lm_rmse_m", "landmark RMSE against other", "m"),
    # set-membership (paper 004)
    _m("set_soundness", "soundness"),
    _m("set_n_hypotheses", "hypotheses"),
    _m("set_n_hypotheses_distinct", "distinct hypotheses"),
    _m("set_true_correspondence_survived", "true correspondence survived"),
    _m("set_true_pose_width_x_mean", "pose box width x", "m"),
    _m("set_true_pose_width_y_mean", "pose box width y", "m"),
    _m("set_true_pose_width_t_mean", "pose box width θ", "rad"),
    _m("set_true_landmark_width_mean", "landmark box width", "m"),
]

METRICS: dict[str, MetricInfo] = {m.key: m for m in _METRICS}


def metric_info(key: str) -> MetricInfo:
    """The registered :class:`MetricInfo` of ``key``; an unlisted column gets its unit from its suffix, its
    name from the rest (underscores as spaces) and ``nonnegative=False``."""
    if key in METRICS:
        return METRICS[key]
    base = key.rsplit(".", 1)[-1]
    for suffix, unit in _SUFFIX_UNITS:
        if base.endswith(suffix) and len(base) > len(suffix):
            return MetricInfo(key, base[: -len(suffix)].replace("_", " "), unit, nonnegative=False)
    return MetricInfo(key, base.replace("_", " "), "", nonnegative=False)


def metric_label(key: str) -> str:
    """``"ATE RMSE (m)"`` for ``ate_rmse_m``: the axis / table label of a metric column."""
    return metric_info(key).label


def column_label(col: str) -> str:
    """Display name of a grouping column: ``label`` → ``solver``; a sweep axis ``solver.ekf.gate_prob`` →
    ``gate_prob``; any other column unchanged."""
    if col == "label":
        return "solver"
    return col.rsplit(".", 1)[-1]


def tex_escape(s: str) -> str:
    """Text for a LaTeX table cell (``_ % & # \\`` escaped; ``± — − † < >``, θ and Δ as LaTeX)."""
    for a, b in (("\\", r"\textbackslash{}"), ("_", r"\_"), ("%", r"\%"), ("&", r"\&"), ("#", r"\#"),
                 ("±", r"$\pm$"), ("—", "--"), ("θ", r"$\theta$"), ("Δ", r"$\Delta$"), ("−", "$-$"),
                 ("†", r"\textdagger{}"), ("<", "$<$"), (">", "$>$")):
        s = s.replace(a, b)
    return s
