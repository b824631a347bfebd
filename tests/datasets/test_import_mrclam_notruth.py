"""``import mrclam --no-truth`` (issue 14 item 5): a copy without the Groundtruth files imports, solves and
evaluates with the no-truth metrics."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.datasets.mrclam import import_mrclam
from slamcli.io import read_dataset
from slamcli.models.motion import integrate

EXCERPT = DATA / "mrclam_excerpt"
runner = CliRunner()


def _copy_without_truth(tmp_path: Path) -> Path:
    d = tmp_path / "mrclam_notruth"
    d.mkdir()
    for f in ("Barcodes.dat", "Robot1_Odometry.dat", "Robot1_Measurement.dat"):
        shutil.copy(EXCERPT / f, d / f)
    return d


def test_no_truth_import_matches_the_full_import_up_to_the_frame(tmp_path):
    d = _copy_without_truth(tmp_path)
    nt = import_mrclam(d, 1, dt=0.1, no_truth=True)
    assert nt.truth is None and (nt.inputs.x0 == 0).all()
    # the excerpt's odometry and truth start together, so both imports share the time axis: identical inputs
    # except the start frame
    full = import_mrclam(EXCERPT, 1, dt=0.1)
    assert full.metadata["time_origin_unix_s"] == nt.metadata["time_origin_unix_s"]
    np.testing.assert_array_equal(nt.inputs.controls, full.inputs.controls)
    np.testing.assert_allclose(nt.inputs.odometry_xyt, integrate(np.zeros(3), nt.inputs.controls, 0.1))
    a, b = nt.inputs.observations, full.inputs.observations
    np.testing.assert_array_equal(a.step, b.step)
    np.testing.assert_array_equal(a.reported_id, b.reported_id)  # subjects >= 6 = the landmark file's subjects
    np.testing.assert_array_equal(a.z, b.z)

@pytest.mark.slow
def test_no_truth_cli_solve_evaluate(tmp_path):
    d = _copy_without_truth(tmp_path)
    data = tmp_path / "nt.h5"
    r = runner.invoke(app, ["import", "mrclam", str(d), "--no-truth", "-o", str(data)])
    assert r.exit_code == 0 and "no ground truth" in r.stdout, r.output
    assert read_dataset(data).truth is None
    r = runner.invoke(app, ["import", "mrclam", str(d), "-o", str(tmp_path / "x.h5")])
    assert r.exit_code == 1 and "Landmark_Groundtruth.dat" in r.stderr and not (tmp_path / "x.h5").exists()
    for m in ("graph", "ekf"):
        r = runner.invoke(app, ["solve", str(data), "-m", m, "-q", "-o", str(tmp_path / f"{m}.h5")])
        assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["evaluate", str(tmp_path / "ekf.h5"), "--against", str(tmp_path / "graph.h5"),
                            "-o", str(tmp_path / "ev")])
    assert r.exit_code == 0, r.output
    m = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert m["truth"] == "none" and m["nis_n"] > 0 and m["nis_band_lo"] < m["nis_band_hi"]
    assert 0 <= m["against_ate_rmse_m"] < 1.0 and m["against_lm_matched"] >= 1
    assert "ate_rmse_m (true poses)" in m["not_available"]
    assert "mean NIS / 95 % band" in r.stdout
