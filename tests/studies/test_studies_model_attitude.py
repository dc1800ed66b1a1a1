"""The model attitude of a scenario is defined at the scenario epoch (``model_attitude``).

A recording simulated from the very scenario it is checked against must be consistent with
it whatever rows it has: here the noise-free truth of the simulation is the oracle (the
simulator integrates from the epoch, t = 0), and dropping the first 10 epochs must not move
the model attitude (before the fix it restarted at the first row: up to 149° off).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lightcurve import InputError
from lightcurve._paths import data_dir
from lightcurve.rotations import attitude_error_rotvec
from lightcurve.studies.evaluate import model_attitude
from lightcurve.studies.scenario import load_scenario
from lightcurve.studies.simulate import initial_attitude, simulate

pytestmark = pytest.mark.filterwarnings("ignore:.*Earth's shadow")


def _quiet(path):
    sc = load_scenario(path)
    return replace(sc, attitude=replace(sc.attitude, acs_sigma_deg=0.0, eta_sigma_deg_s2=0.0))


@pytest.mark.parametrize("case", ["default.toml", "thesis/leo-ic1-fast-spin-uncontrolled-1site.toml"])
def test_dropping_the_first_epochs_keeps_the_model_attitude(case):
    sc = _quiet(data_dir("pipelines") / case)
    lc = simulate(sc)
    late = lc.subset(np.arange(10, len(lc)))
    assert late.t[0] > 0
    for curve in (lc, late):
        q, w = model_attitude(sc, curve, return_omega=True)
        err = np.degrees(np.linalg.norm(attitude_error_rotvec(curve.truth_q, q), axis=1))
        assert err.max() < 1e-6, err.max()
        np.testing.assert_allclose(w, curve.truth_omega_rad_s, atol=1e-10)


def test_rows_before_the_epoch():
    """Controlled model: exact backwards propagation q(t) = exp(ω t) ⊗ q0 (the truth model's
    constant-rate step, Bernard eq. 7.8 without noise); uncontrolled: refused."""
    sc = _quiet(data_dir("pipelines") / "default.toml")
    lc = simulate(sc).subset(np.arange(5))
    early = replace(lc, t=lc.t - 100.0)            # the same rows, 100 s earlier
    q = model_attitude(sc, early)
    from lightcurve.rotations import quat_mult, rotvec_to_quat

    q0, w0 = initial_attitude(sc)
    want = np.array([quat_mult(rotvec_to_quat(w0 * t), q0) for t in early.t])
    err = np.degrees(np.linalg.norm(attitude_error_rotvec(want, q), axis=1))
    assert err.max() < 1e-9
    unc = _quiet(data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-uncontrolled-1site.toml")
    lcu = simulate(unc).subset(np.arange(3))
    with pytest.raises(InputError, match="before the scenario epoch"):
        model_attitude(unc, replace(lcu, t=lcu.t - 100.0))
