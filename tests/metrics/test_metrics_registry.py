"""One metric registry (issue 24 items 4-5): every table and axis names a metric the same way, with the unit its
column name declares, and angles in one unit (radians)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.metrics.registry import ANGLE_UNIT, METRICS, MetricInfo, column_label, metric_info, metric_label

runner = CliRunner()
SUFFIX_UNIT = {"_m": "m", "_rad": "rad", "_s": "s"}


def test_registered_units_agree_with_the_column_suffix():
    """The unit is the one the stored column declares (``*_m`` in metres, ``*_rad`` in radians ...)."""
    for key, info in METRICS.items():
        suffix = next((s for s in SUFFIX_UNIT if key.endswith(s)), None)
        if suffix:
            assert info.unit == SUFFIX_UNIT[suffix], key
        assert "_" not in info.name, key  # a human name, not a column name


def test_one_angle_unit():
    assert ANGLE_UNIT == "rad"
    assert {i.unit for i in METRICS.values() if "heading" in i.key or i.key.endswith("_rad")} == {"rad"}


def test_labels_and_fallback():
    assert metric_label("ate_rmse_m") == "ATE RMSE (m)"
    assert metric_label("pose_nees_mean") == "pose NEES"  # unitless: no empty parentheses
    assert metric_info("ate_rmse_m").tex_label == r"ATE RMSE [\si{\metre}]"
    other = metric_info("my_new_error_m")  # not registered: name and unit from the column name
    assert other.label == "my new error (m)" and not other.nonnegative
    assert metric_info("solver.ekf.gate_prob").name == "gate prob"
    assert column_label("label") == "solver" and column_label("solver.ekf.gate_prob") == "gate_prob"
    with pytest.raises(ValueError, match="siunitx"):
        MetricInfo("x_ft", "x", "ft")


def test_evaluate_table_units_come_from_the_registry(tmp_path):
    from conftest import make_dataset, make_result

    from slamcli.cli.evaluate_cmd import _ROWS
    from slamcli.io import write_dataset, write_result

    for _, key in _ROWS:  # every metric the table shows is registered (no fallback wording)
        for k in key if isinstance(key, tuple) else (key,):
            assert k in METRICS, k
    ds = make_dataset()
    d = tmp_path / "d.h5"
    write_dataset(d, ds)
    r = tmp_path / "r.h5"
    write_result(r, make_result(ds, d))
    out = runner.invoke(app, ["evaluate", str(r), "-o", str(tmp_path / "ev")], env={"COLUMNS": "120"})
    assert out.exit_code == 0, out.output
    rows = {line.split("│")[1].strip(): line.split("│")[3].strip() for line in out.output.splitlines()
            if line.count("│") == 4}
    assert rows["heading RMSE (unaligned)"] == "rad" and rows["RPE rotation RMSE"] == "rad"
    assert rows["ATE RMSE (unaligned)"] == "m" and rows["landmark OSPA"] == "m"
    assert rows["landmarks matched / missed / spurious"] == ""
