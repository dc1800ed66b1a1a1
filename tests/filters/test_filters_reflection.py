"""Reflection-bias states (Bernard ch. 8) in the MEKF and the UKF."""

from __future__ import annotations

import numpy as np
import pytest
from filters_synth import make_curve
from transition_oracle import discretize

from lightcurve.filters.invert import build_problem, invert
from lightcurve.filters.models import MagnitudeModel
from lightcurve.filters.reflection import SiteBias, reflection_prior_variance
from lightcurve.photometry import apparent_magnitude, load_shape


def test_model2_exact_discretisation_matches_van_loan():
    """Φ = e^{−Δt/τ}, Q_d = σ²(1 − e^{−2Δt/τ}) equal Van Loan's discretisation of ḃ = −b/τ + w
    with PSD 2σ²/τ (Bernard eq. 8.12–8.13); τ = 0.1·2π/|ω|, capped when ω → 0."""
    var0 = np.array([0.04, 0.01])
    bias = SiteBias("model2", np.array([0, 1, 0]), var0, duration_s=300.0)
    w = np.radians([2.0, 1.0, 3.6])
    tau = 0.1 * 2 * np.pi / np.linalg.norm(w)
    assert bias.tau(w) == pytest.approx(tau, rel=1e-14)
    for dt in (0.5, 5.0, 40.0):
        phi, qd = bias.transition(dt, w)
        for s in range(2):
            P, Q = discretize(np.array([[-1.0 / tau]]), np.array([[2 * var0[s] / tau]]), dt)
            assert phi[s] == pytest.approx(P[0, 0], rel=1e-10)
            assert qd[s] == pytest.approx(Q[0, 0], rel=1e-8)
    # ω → 0: τ capped at the duration (finite, not 0/0); stationary variance stays σ²
    assert bias.tau(np.zeros(3)) == 300.0 and bias.tau(np.full(3, 1e-12)) == 300.0
    phi, qd = bias.transition(1e6, np.zeros(3))
    np.testing.assert_allclose(qd, var0, rtol=1e-12)
    # random walk: Q_d = (σ²/T) Δt; model 1: constant
    rw = SiteBias("random-walk", np.zeros(3, int), np.array([0.04]), duration_s=200.0)
    assert rw.transition(10.0, w)[1][0] == pytest.approx(0.04 / 200.0 * 10.0)
    m1 = SiteBias("model1", np.zeros(3, int), np.array([0.04]), duration_s=200.0)
    assert m1.transition(10.0, w) == (np.ones(1), np.zeros(1))


def test_eq_8_10_prior_variance_against_finite_differences():
    """σ_b² = Σ_p (∂m/∂p · 0.1 p)² with the analytic partials equals the same sum with central
    finite differences of apparent_magnitude on perturbed shapes (independent path)."""
    curve = make_curve(n=12)
    shape = load_shape("cube_1u")
    model = MagnitudeModel(shape, curve)
    v = reflection_prior_variance(shape, curve.truth_q, model, frac=0.1)
    ref = np.zeros(len(curve))
    F = shape.n_facets

    def mag(sh):
        return apparent_magnitude(sh, curve.truth_q, curve.obj_to_sun_unit, curve.obj_to_obs_unit,
                                  curve.range_obs_m, curve.range_sun_m)

    for name, col in (("xi", 0), ("a", 1), ("m", 2), ("A", None)):
        base = shape.areas_m2 if col is None else shape.params[:, col]
        for i in range(F):
            h = 1e-6 * base[i]
            vals = []
            for sgn in (1, -1):
                x = base.copy()
                x[i] += sgn * h
                kw = {"areas_m2": x} if col is None else {name: x}
                vals.append(mag(shape.copy_with(check=False, **kw)))
            d = (vals[0] - vals[1]) / (2 * h)
            ref += (d * 0.1 * base[i]) ** 2
    np.testing.assert_allclose(v, ref, rtol=1e-5)
    assert np.all(v > 0)


@pytest.fixture(scope="module")
def biased_curve():
    """The filter tests' synthetic lightcurve with a +0.15 mag constant model error (what a
    reflection-parameter mismatch produces), 80 epochs."""
    c = make_curve(n=80, seed=3)
    c.mag = c.mag + 0.15
    return c


@pytest.mark.parametrize("method", ["mekf", "ukf"])
def test_model1_estimates_constant_bias(biased_curve, method):
    """Model 1 recovers a +0.15 mag bias: final estimate within 3σ of the truth and its σ shrunk
    below the eq. 8.10 prior σ; attitude errors stay inside 3σ at the end; the attitude-only
    filter is flagged divergent on the same data."""
    est = invert(biased_curve, method, seed=2, sigma_theta_deg=3.0, reflection="model1")
    assert not est.diverged, est.divergence_reason
    # without the bias state the same data trip the NIS divergence detector (99.9 % bound)
    assert invert(biased_curve, method, seed=2, sigma_theta_deg=3.0).diverged
    b, s = est.bias[-1, 0], est.bias_sigma[-1, 0]
    s0 = est.meta["reflection"]["prior_sigma_mag"][0]
    assert abs(b - 0.15) < 3 * s
    assert s < 0.5 * s0
    assert np.all(np.abs(est.att_error_deg[-1]) < 3 * est.att_sigma_deg[-1])


@pytest.mark.parametrize("method", ["mekf", "ukf"])
def test_bias_models_run_and_order_their_uncertainty(biased_curve, method):
    """Random walk and Model 2 keep the bias open: their final bias σ is at least Model 1's
    (process noise only adds variance); every result is finite."""
    sig = {}
    for kind in ("model1", "random-walk", "model2"):
        est = invert(biased_curve, method, seed=2, reflection=kind)
        assert np.all(np.isfinite(est.bias)) and np.all(np.isfinite(est.q))
        sig[kind] = est.bias_sigma[-1, 0]
    assert sig["random-walk"] >= sig["model1"] * 0.999
    assert sig["model2"] >= sig["model1"] * 0.999


def test_two_sites_get_two_biases():
    c = make_curve(n=40, two_sites=True)
    c.mag = c.mag + np.where(c.site == 1, 0.2, 0.0)
    est = invert(c, "mekf", seed=0, reflection="model1")
    assert est.bias.shape == (40, 2)
    b, s = est.bias[-1], est.bias_sigma[-1]
    assert abs(b[1] - 0.2) < 3 * s[1] and abs(b[0]) < 3 * s[0]


def test_bpf_and_bad_choice_refused(biased_curve):
    from lightcurve.errors import InputError

    # (the BPF now accepts bias states: invert routes them to run_bpf, no longer refused)
    with pytest.raises(InputError, match="reflection"):
        invert(biased_curve, "mekf", reflection="model9")
    p = build_problem(biased_curve)
    bias = SiteBias.from_problem("model2", p)
    assert bias.n_sites == 1 and bias.var0[0] > 0


def test_cli_invert_reflection(tmp_path, biased_curve):
    import json

    from lightcurve.cli import main

    f = tmp_path / "b.h5"
    biased_curve.write(f)
    rc = main(["invert", str(f), "--method", "mekf", "--reflection", "model1", "-o", str(tmp_path / "o")])
    assert rc == 0
    from lightcurve.filters.result import read_estimate

    js = json.loads((tmp_path / "o" / "summary.json").read_text())
    est = read_estimate(js["b"]["result"])
    r = est.meta["reflection"]
    assert r["model"] == "model1" and abs(r["bias_final_mag"][0] - 0.15) < 3 * r["bias_sigma_final_mag"][0]
    with pytest.raises(SystemExit) as ei:  # argparse usage error (unknown model)
        main(["invert", str(f), "--reflection", "model4", "-o", str(tmp_path / "o")])
    assert ei.value.code == 2
