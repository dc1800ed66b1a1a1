"""Filter runs: convergence, consistency over small seeded Monte Carlo sets, determinism, bad input."""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from filters_synth import make_curve
from lightcurve.errors import InputError
from lightcurve.filters import (FLAG_NAN, build_problem, invert, read_estimate, run_bpf,
                                run_bpf_numpy)


@pytest.fixture(scope="module")
def curves():
    """10 independent synthetic controlled lightcurves (truth seeds 11…20)."""
    return [make_curve(seed=11 + i) for i in range(10)]


@pytest.mark.parametrize("method", ["mekf", "ukf"])
def test_kalman_filters_converge_from_3deg(curve, method):
    # Bernard §9.3.3 set-up: σθ = 3°, σω = 0.02°/s; after 60 measurements of 1 % noise the
    # attitude is known to well under the initial 3° (thesis fig. 9.4: ~0.5° RSS)
    est = invert(curve, method, seed=4, sigma_theta_deg=3.0, sigma_omega_deg_s=0.02)
    s = est.summary()
    assert s["final_att_error_rss_deg"] < 1.5
    assert np.all(est.att_sigma_deg[-1] < est.att_sigma_deg[0])
    assert not est.diverged
    assert np.all(np.isfinite(est.q)) and np.all(np.isfinite(est.cov))
    assert np.all(np.isfinite(est.innovations))


def test_ukf_consistency_over_seeded_runs(curves):
    # 10 independent runs (truth and initial error both random). Each final component is
    # inside ±3σ with probability 0.9973 for a consistent Gaussian filter, all six with
    # ≥ 0.98; a count ≤ 7 of 10 has binomial probability 1e-3 at p = 0.95.
    inside = 0
    nees = []
    for i, c in enumerate(curves):
        est = invert(c, "ukf", seed=100 + i, sigma_theta_deg=3.0)
        inside += est.summary()["inside_3sigma"]
        nees.append(est.nees[-20:])
    assert inside >= 8
    # time- and ensemble-averaged NEES over the last 20 epochs of 10 runs (6 dof): a
    # consistent filter gives ~6; the 99.9 % chi-square band for 200 independent samples is
    # a loose bound here (epochs are correlated), so test the mean against [1.5, 12]
    m = float(np.mean(nees))
    assert 1.5 < m < 12.0, m


def test_mekf_and_ukf_agree_on_easy_case(curve):
    a = invert(curve, "mekf", seed=2)
    b = invert(curve, "ukf", seed=2)
    # same data, same initial estimate: final attitudes within 3 combined σ
    d = np.linalg.norm(a.att_error_deg[-1] - b.att_error_deg[-1])
    s = np.linalg.norm(np.hypot(a.att_sigma_deg[-1], b.att_sigma_deg[-1]))
    assert d < 3 * s


def test_bpf_converges_and_is_deterministic(curve):
    e1 = invert(curve, "bpf", seed=7, particles=2000, sigma_theta_deg=3.0)
    e2 = invert(curve, "bpf", seed=7, particles=2000, sigma_theta_deg=3.0)
    e3 = invert(curve, "bpf", seed=8, particles=2000, sigma_theta_deg=3.0)
    assert np.array_equal(e1.q, e2.q) and np.array_equal(e1.omega_rad_s, e2.omega_rad_s)
    assert np.array_equal(e1.n_eff, e2.n_eff)
    assert not np.array_equal(e1.q, e3.q)
    assert e1.summary()["final_att_error_rss_deg"] < 2.0
    assert np.all((e1.n_eff >= 1) & (e1.n_eff <= 2000))


def test_bpf_numba_matches_numpy_reference(curve):
    # the same algorithm and random draws in plain NumPy: equal up to round-off over the
    # first epochs (a late resampling decision may flip on a last-bit difference)
    p = build_problem(curve, seed=3, sigma_theta_deg=3.0)
    a = run_bpf(p, particles=500, seed=5)
    b = run_bpf_numpy(p, particles=500, seed=5)
    np.testing.assert_allclose(a.q[:10], b.q[:10], atol=1e-8)
    np.testing.assert_allclose(a.n_eff[:10], b.n_eff[:10], rtol=1e-6)


def test_bpf_multinomial_and_roughening_options(curve):
    e = invert(curve, "bpf", seed=1, particles=1000, resampling="multinomial", roughening=0.0)
    assert np.all(np.isfinite(e.q))
    with pytest.raises(ValueError):
        invert(curve, "bpf", seed=1, particles=1000, resampling="bogus")
    with pytest.raises(ValueError):
        invert(curve, "bpf", seed=1, particles=1, resampling="systematic")


# ---------------------------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------------------------

def test_no_visible_measurement_is_an_input_error():
    c = make_curve(n=10)
    c.mag[:] = np.nan
    with pytest.raises(InputError, match="no visible"):
        invert(c, "mekf")


@pytest.mark.parametrize("method", ["mekf", "ukf", "bpf"])
def test_nan_magnitudes_are_skipped_and_counted(method):
    c = make_curve(n=30, seed=5)
    c.mag[[3, 4, 10]] = np.nan
    est = invert(c, method, seed=1, particles=1000)
    assert est.skipped_nan == 3
    assert np.all((est.flags[[3, 4, 10]] & FLAG_NAN) > 0)
    assert np.all(np.isnan(est.innovations[[3, 4, 10]]))
    assert np.all(np.isfinite(est.q)) and np.all(np.isfinite(est.att_sigma_deg))


def test_inconsistent_shapes_are_input_errors():
    c = make_curve(n=12)
    bad = replace(c)  # shallow copy, validated on creation
    bad.mag_sigma = bad.mag_sigma[:5]
    with pytest.raises(InputError, match="mag_sigma"):
        invert(bad, "mekf")
    with pytest.raises(InputError, match="method"):
        invert(c, "kalman")


def test_wrong_model_is_flagged_as_diverged_not_crashed():
    # magnitudes 2 mag brighter than any attitude of the model can make them: the innovations
    # are ~40σ, the sliding-window NIS test flags the run; estimates stay finite
    c = make_curve(n=40, seed=2)
    c.mag = c.mag - 2.0
    for method in ("mekf", "ukf"):
        est = invert(c, method, seed=0)
        assert est.diverged and "NIS" in est.divergence_reason
        assert np.all(np.isfinite(est.q)) and np.all(np.isfinite(est.cov))
        assert est.summary()["diverged"] is True


def test_estimate_file_round_trip_and_summary_json(tmp_path, curve):
    est = invert(curve, "ukf", seed=3)
    path = est.write(tmp_path / "e.h5")
    back = read_estimate(path)
    for name in ("t", "q", "omega_rad_s", "cov", "att_sigma_deg", "nees", "flags"):
        np.testing.assert_array_equal(getattr(back, name), getattr(est, name))
    assert back.method == "ukf" and back.meta["seed"] == 3
    s = json.loads(json.dumps(est.summary()))
    assert set(s) >= {"method", "final_att_error_rss_deg", "final_omega_error_rss_deg_s",
                      "final_3sigma_att_deg", "inside_3sigma", "runtime_s", "diverged"}
    with pytest.raises(InputError):
        read_estimate(tmp_path / "missing.h5")


def test_cli_invert_writes_results_and_summary(tmp_path):
    from lightcurve.cli import main

    files = []
    for i in range(2):
        c = make_curve(n=20, seed=30 + i)
        files.append(str(c.write(tmp_path / f"lc{i}.h5")))
    out = tmp_path / "out"
    rc = main(["invert", *files, "--method", "mekf", "-o", str(out), "--plot"])
    assert rc == 0
    assert (out / "lc0.mekf.png").exists() and (out / "lc1.mekf.h5").exists()
    # bad input → exit code 2 with a one-line message, not a traceback
    c = make_curve(n=5, seed=1)
    c.mag[:] = np.nan
    bad = str(c.write(tmp_path / "bad.h5"))
    out2 = tmp_path / "out2"
    assert main(["invert", bad, files[0], "-o", str(out2), "--method", "mekf"]) == 2
    summ2 = json.loads((out2 / "summary.json").read_text())
    assert "no visible" in summ2["bad"]["error"] and "final_nees" in summ2["lc0"]
    summ = json.loads((out / "summary.json").read_text())
    assert set(summ) == {"lc0", "lc1"}
    for v in summ.values():
        assert v["method"] == "mekf" and os.path.exists(v["result"])
        assert v["final_att_error_rss_deg"] >= 0


def test_binomial_bound_used_above():
    # the acceptance bound of test_ukf_consistency_over_seeded_runs: P(X ≤ 7 | 10, 0.95)
    assert stats.binom.cdf(7, 10, 0.95) < 0.0125


# ---------------------------------------------------------------------------------------------
# uncontrolled (tumbling) variant
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tumbling():
    """Torque-free tumbling truth with an asymmetric inertia (so ω changes along the pass)."""
    return make_curve(n=50, seed=9, dynamics="uncontrolled", omega_deg_s=(2.0, -3.0, 4.0))


def test_tumbling_truth_really_tumbles(tumbling):
    # Euler's equations with J = diag(2, 3, 4) g m²: the body rate changes by degrees/s
    dw = np.degrees(np.ptp(tumbling.truth_omega_rad_s, axis=0))
    assert np.max(dw) > 0.5


@pytest.mark.parametrize("method", ["mekf", "ukf", "bpf"])
def test_uncontrolled_filters_track_a_tumbling_object(tumbling, method):
    est = invert(tumbling, method, seed=3, sigma_theta_deg=3.0, sigma_omega_deg_s=0.02,
                 particles=3000)
    assert est.meta["dynamics"] == "uncontrolled"
    s = est.summary()
    # 50 epochs of a tumbling cube leave ~1° (1σ) per axis and ~0.02-0.07 deg/s (1σ) rates
    assert s["final_att_error_rss_deg"] < 3.0
    assert s["final_omega_error_rss_deg_s"] < 0.2
    assert s["inside_3sigma"] and not s["diverged"]
    # the controlled (constant-rate) model cannot follow the tumbling rate: much worse
    if method == "ukf":
        wrong = invert(tumbling, method, seed=3, dynamics="controlled", acs_sigma_deg=0.0)
        assert wrong.summary()["final_att_error_rss_deg"] > 3 * s["final_att_error_rss_deg"]


def test_plots_and_particle_clouds(tmp_path, curve):
    from lightcurve.filters.plots import plot_estimate, plot_particle_clouds

    est = invert(curve, "bpf", seed=2, particles=1000, keep_clouds=(0, -1))
    assert set(est.clouds) == {0, len(curve) - 1}
    # the final cloud is concentrated near the truth, the first one is as wide as the prior
    spread0 = np.median(np.linalg.norm(est.clouds[0], axis=1))
    spread1 = np.median(np.linalg.norm(est.clouds[len(curve) - 1], axis=1))
    assert spread1 < spread0
    p1 = plot_estimate(est, tmp_path / "e.png")
    p2 = plot_particle_clouds(est, tmp_path / "c.png")
    for p in (p1, p2):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    back = read_estimate(est.write(tmp_path / "e.h5"))
    np.testing.assert_array_equal(back.clouds[0], est.clouds[0])
    with pytest.raises(ValueError):
        plot_particle_clouds(invert(curve, "ukf"), tmp_path / "x.png")


@pytest.mark.parametrize("method", ["mekf", "ukf", "bpf"])
def test_acs_jitter_model(method):
    # ACS noise as jitter about the nominal profile (Bernard eq. 7.27: mapped into R for the
    # MEKF, augmented sigma points for the UKF, prediction-only draws for the BPF)
    c = make_curve(n=40, seed=21, acs_sigma_deg=0.3, acs_mode="jitter")
    est = invert(c, method, seed=5, acs_mode="jitter", particles=2000)
    s = est.summary()
    assert s["final_att_error_rss_deg"] < 2.0 and not s["diverged"]
    # the reported attitude σ includes the jitter (0.3°): never below it
    assert np.all(est.att_sigma_deg >= 0.3 - 1e-12)
    if method == "mekf":
        ok = np.isfinite(est.innovation_var)
        assert np.all(est.innovation_var[ok] > c.mag_sigma[ok] ** 2)


@pytest.mark.parametrize("method", ["mekf", "ukf", "bpf"])
def test_geometry_with_no_reflected_light_is_flagged(method):
    # observer exactly opposite the Sun (phase angle 180°): no facet can face both, every
    # predicted magnitude is +inf. Kalman filters skip every update (FLAG_INVISIBLE); the BPF
    # loses every weight (FLAG_COLLAPSE, reported as diverged). No crash, no NaN.
    from lightcurve.filters import FLAG_COLLAPSE, FLAG_INVISIBLE

    c = make_curve(n=8, seed=3)
    d = c.r_sun_eci_m - c.r_obj_eci_m
    c.r_site_eci_m = c.r_obj_eci_m - 1e6 * d / np.linalg.norm(d, axis=1, keepdims=True)
    est = invert(c, method, seed=0, particles=500)
    assert np.all(np.isfinite(est.q)) and np.all(np.isfinite(est.att_sigma_deg))
    if method == "bpf":
        assert np.all(est.flags & FLAG_COLLAPSE) and est.diverged
    else:
        assert np.all(est.flags & FLAG_INVISIBLE)
        assert est.summary()["invisible_predictions"] == 8
        assert est.diverged and "no measurement update" in est.divergence_reason


def test_progressive_correction_keeps_the_cloud_alive():
    # From a 60° prior one measurement of σ ≈ 0.05 mag leaves a handful of effective
    # particles in the plain bootstrap filter; the progressive correction (bpf.py step 3b)
    # tempers the likelihood so that N_eff stays at the threshold (0.5 N) after the update.
    c = make_curve(n=3, seed=4)
    p = build_problem(c, seed=1, sigma_theta_deg=60.0)
    plain = run_bpf(p, particles=2000, seed=1, progressive=False)
    prog = run_bpf(p, particles=2000, seed=1, progressive=True)
    assert plain.n_eff[0] < 0.2 * 2000
    assert prog.n_eff[0] >= 0.5 * 2000 - 1e-6
    assert prog.meta["tempering_stages"][0] >= 1


@pytest.mark.parametrize("method", ["mekf", "ukf", "bpf"])
def test_two_sites_with_simultaneous_measurements(method):
    # two sites measuring at the same times (Δt = 0 between their rows): both rows update the
    # same attitude; the ACS noise is added once per epoch, like the truth model does
    c = make_curve(n=60, seed=6, two_sites=True)
    assert np.any(np.diff(c.t) == 0) and set(c.site.tolist()) == {0, 1}
    est = invert(c, method, seed=2, particles=2000)
    s = est.summary()
    assert s["final_att_error_rss_deg"] < 1.5 and not s["diverged"]
    assert np.all(np.isfinite(est.innovations))


def test_ukf_cholesky_failure_restores_prior_and_flags(curve, monkeypatch):
    # make the sigma-point factorisation fail once (the update of epoch 10): the prior is kept
    # (posterior = prior of that step), the step is flagged, the run goes on
    import lightcurve.filters.ukf as U
    from lightcurve.filters import FLAG_REFUSED

    good = invert(curve, "ukf", seed=1)
    calls = {"n": 0}
    orig = U.sigma_offsets

    def flaky(P, w):
        calls["n"] += 1
        if calls["n"] == 2 * 10 + 1:   # each epoch k ≥ 1: propagation, then update
            return None, False
        return orig(P, w)

    monkeypatch.setattr(U, "sigma_offsets", flaky)
    est = invert(curve, "ukf", seed=1)
    k = int(np.flatnonzero(est.flags & FLAG_REFUSED)[0])
    assert k == 10 and np.sum((est.flags & FLAG_REFUSED) > 0) == 1
    assert np.isnan(est.innovations[k])
    np.testing.assert_array_equal(est.q[:k], good.q[:k])
    assert not np.array_equal(est.q[k], good.q[k])  # no update at k: the prior was kept
    assert est.att_sigma_deg[k, 0] >= good.att_sigma_deg[k, 0]
    assert np.all(np.isfinite(est.q)) and not est.diverged


def test_bpf_from_60deg_converges_on_the_default_scenario():
    """Bernard fig. 9.5c–e: from a 60° initial attitude error the particle filter ends below 5°
    on the thesis LEO fast-spin case (pipelines/thesis/leo-ic1-fast-spin-controlled-1site.toml,
    Table 9.2 cube), 10⁴ particles as in benchmarks/filters_acceptance.py. Regression guard for
    the joint kernel: applied to the wide multimodal early cloud it merged the modes and 19 of
    20 such runs ended ≈ 170° off (module docstring of filters/bpf.py). Seeds 0–9: at least 7
    end below 5° (measured 9/10; at a true success rate of 0.9 the binomial false-alarm rate of
    this bound is 1.3 %), and every run that does not is flagged by the truth-free consistency
    tests (Estimate.consistency) — a failure is never reported as a confident answer."""
    from lightcurve._paths import data_dir
    from lightcurve.filters.invert import invert
    from lightcurve.studies.scenario import load_scenario
    from lightcurve.studies.simulate import simulate

    sc = load_scenario(data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml")
    good = 0
    for i in range(10):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lc = simulate(sc, i)
        e = invert(lc, "bpf", seed=i, sigma_theta_deg=60.0, sigma_omega_deg_s=0.02,
                   particles=10_000)
        s = e.summary()
        if s["final_att_error_rss_deg"] < 5.0:
            good += 1
        else:
            assert s["consistency"]["flags"], (i, s["final_att_error_rss_deg"])
    assert good >= 7, good
