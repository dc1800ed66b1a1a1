"""Reflection models in the study grid: a 2-cell grid (UKF, MEKF) × reflection
Model 1 on the tiny scenario with the §10.1 truth perturbation ([reflection], 10 %).

Checks: every run finishes with a per-site bias state whose final 1σ is well below its eq. 8.10
prior (the state was estimated, not just carried), and the UKF's final bias follows the
lightcurve's actual reflection error — the mean of (truth magnitude with the perturbed shape −
magnitude of the nominal shape at the true attitude), recomputed here independently with
:func:`lightcurve.photometry.apparent_magnitude`. The simulated lightcurves do not depend on
the reflection model (common random numbers).
"""

from __future__ import annotations

import warnings

import numpy as np

from lightcurve.photometry import apparent_magnitude
from lightcurve.studies.runner import read_run, run_study
from lightcurve.studies.scenario import parse_scenario
from lightcurve.studies.simulate import simulate
from lightcurve.studies.study import Cell, load_study, run_seeds


def test_model1_grid_runs_and_estimates_the_bias(tmp_path, make_study):
    p = make_study(tmp_path, filters=("ukf", "mekf"), runs=4, reflection=["model1"])
    scen = tmp_path / "tiny-controlled-1site.toml"
    scen.write_text(scen.read_text() + "\n[reflection]\nsigma_frac = 0.1\n")
    study = load_study(p)
    assert [(c.filter, c.reflection) for c in study.cells] == [("ukf", "model1"), ("mekf", "model1")]
    s = run_study(study, tmp_path / "out", workers=1, progress=False, write_report=True)
    assert [(c["runs"], c["failures"], c["reflection"]) for c in s["cells"]] == [(4, 0, "model1")] * 2
    assert "reflection model1" not in (tmp_path / "out" / "report.html").read_text()  # one model

    sc = parse_scenario(scen.read_text(), file=scen)
    diffs, b_hat, b_true = [], [], []
    for t in study.tasks():
        r = read_run(tmp_path / "out" / "runs" / f"{t.run_id}.h5")
        m = r["metrics"]
        assert len(m["final_bias_mag"]) == 1 and len(m["final_bias_sigma_mag"]) == 1
        # eq. 8.10 prior σ_b of this 1U cube and geometry ≈ 0.18–0.22 mag (measured); a bias
        # state that saw 13 measurements of σ ≈ 0.05 mag ends near 0.05/√13 ≈ 0.014–0.025
        assert 0 < m["final_bias_sigma_mag"][0] < 0.06
        if t.cell.filter != "ukf":
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lc = simulate(sc, seed=t.sim_seed)
        assert lc.attrs.get("reflection_truth")  # the truth shape was perturbed
        m_nom = apparent_magnitude(sc.shape, lc.truth_q, lc.obj_to_sun_unit, lc.obj_to_obs_unit,
                                   lc.range_obs_m, lc.range_sun_m,
                                   sun_mag=float(lc.attrs.get("sun_mag", -26.74)))
        off = float(np.mean(np.asarray(lc.truth_mag) - m_nom))
        b_hat.append(m["final_bias_mag"][0])
        b_true.append(off)
        diffs.append(abs(m["final_bias_mag"][0] - off))
    # the offset varies along the pass (std 0.1–0.2 mag), so a constant bias matches its mean
    # only roughly: measured |b̂ − mean offset| ≤ 0.07 mag, correlation 0.97 over the 4 runs
    assert max(diffs) < 0.12, diffs
    assert np.corrcoef(b_hat, b_true)[0, 1] > 0.85, (b_hat, b_true)
    # common random numbers: the reflection model does not change the simulated lightcurve
    c_none = Cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "none")
    c_m1 = Cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "model1")
    assert run_seeds(7, c_none, 2)[0] == run_seeds(7, c_m1, 2)[0]
    assert run_seeds(7, c_none, 2)[1] != run_seeds(7, c_m1, 2)[1]
