"""Fixed costs of a default graph solve (issue 25 item 1): no scipy.stats / scipy.special import, and the χ²
quantile that replaced scipy.stats.chi2.ppf against scipy itself."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import DATA

from slamcli.solvers.graph.solver import chi2_cdf, chi2_quantile


@pytest.mark.parametrize("k", [1, 2, 3, 4, 5, 6])
def test_chi2_quantile_matches_scipy(k):
    from scipy.stats import chi2

    for p in (0.5, 0.9, 0.95, 0.99, 0.999):
        assert chi2_quantile(p, k) == pytest.approx(chi2.ppf(p, k), rel=1e-10)
    for x in (0.1, 1.0, 3.0, 12.0):
        assert chi2_cdf(x, k) == pytest.approx(chi2.cdf(x, k), rel=1e-12, abs=1e-15)


@pytest.mark.slow
def test_default_graph_solve_imports_no_scipy_stats(tmp_path):
    """`slamcli import g2o` + `slamcli solve --method graph` (defaults, χ² outlier counts included) in a
    fresh interpreter: scipy.stats and scipy.special stay unimported."""
    ds, res = tmp_path / "g.h5", tmp_path / "r.h5"
    code = (
        "import sys\n"
        "from slamcli.cli import main\n"
        f"for argv in (['import', 'g2o', {str(DATA / 'intel_excerpt.g2o')!r}, '-o', {str(ds)!r}],\n"
        f"             ['solve', {str(ds)!r}, '--method', 'graph', '-q', '-o', {str(res)!r}]):\n"
        "    sys.argv = ['slamcli', *argv]\n"
        "    try:\n"
        "        main()\n"
        "    except SystemExit as e:\n"
        "        assert not e.code, e.code\n"
        "print('stats' if 'scipy.stats' in sys.modules else '-', 'special' if 'scipy.special' in sys.modules else '-')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert res.exists()
    assert out.stdout.split()[-2:] == ["-", "-"]
