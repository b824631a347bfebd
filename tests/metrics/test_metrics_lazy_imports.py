"""What a sweep worker pays to import: chi² quantiles without scipy.stats (issue 25 item 6).

The quantile helpers are checked against ``scipy.stats.chi2.ppf`` (the independent reference), and a fresh
interpreter that evaluates a result and runs the EKF with ML association must not have imported
``scipy.stats``.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.stats import chi2

from slamcli.metrics.consistency import chi2_band, chi2_ppf
from slamcli.solvers.ekf import _chi2_2dof_ppf

QUANTILE_RTOL = 1e-12


@pytest.mark.parametrize("dof", [1, 2, 3, 6, 150, 2000])
def test_chi2_ppf_equals_scipy_stats(dof):
    q = np.array([1e-6, 0.025, 0.5, 0.95, 0.975, 0.9999])
    np.testing.assert_allclose(chi2_ppf(q, dof), chi2.ppf(q, dof), rtol=QUANTILE_RTOL)


def test_chi2_band_known_value():
    lo, hi = chi2_band(50, 3, 0.95)  # EVALUATION-METHOD §A1: N = 50, d = 3 → [2.36, 3.72]
    assert round(lo, 2) == 2.36 and round(hi, 2) == 3.72


@pytest.mark.parametrize("q", [0.5, 0.9, 0.99, 0.9999])
def test_ekf_closed_form_gate_equals_scipy_stats(q):
    assert _chi2_2dof_ppf(q) == pytest.approx(chi2.ppf(q, 2), rel=QUANTILE_RTOL)


@pytest.mark.slow
def test_evaluate_and_ml_ekf_import_no_scipy_stats(tmp_path):
    code = f"""
import sys
from slamcli.api.simulate import simulate_to_file
from slamcli.api.solve import solve_file
from slamcli.api.evaluate import evaluate_files
d = {str(tmp_path)!r}
simulate_to_file(scenario="loop", seed=0, overrides={{"n_steps": 30}}, out_path=d + "/ds.h5")
solve_file(d + "/ds.h5", "ekf", {{"association": "ml"}}, d + "/r.h5", seed=0)
evaluate_files(d + "/r.h5", d + "/ds.h5", d + "/ev")
print("scipy.stats" in sys.modules)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "False"
