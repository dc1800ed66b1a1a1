"""docs/example.py runs end to end (import, simulate, invert, to_pandas, plot, write)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def test_docs_example_runs_end_to_end(tmp_path):
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
           "MPLBACKEND": "Agg"}
    r = subprocess.run([sys.executable, str(ROOT / "docs" / "example.py"), str(out)], cwd=tmp_path,
                       env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "<Lightcurve 51 magnitudes" in r.stdout and "<Estimate UKF" in r.stdout
    for name in ("lightcurve.png", "estimate.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the table it wrote is the estimate file's content (independent read-back)
    import pandas as pd

    from lightcurve.filters.result import read_estimate

    table = pd.read_csv(out / "estimate.csv", index_col=0)
    est = read_estimate(out / "pass.ukf.h5")
    np.testing.assert_allclose(table[["q1", "q2", "q3", "q4"]].to_numpy(), est.q, atol=1e-12)
    np.testing.assert_allclose(table["att_error_x_deg"].to_numpy(), est.att_error_deg[:, 0],
                               atol=1e-12)
    # the UTC index starts at the scenario epoch
    assert str(table.index[0]).startswith("2008-09-21 01:55:00")
