"""Diagnosis machinery: residual tests, evidence, the Earthshine cache, reports, CLI, and a
reduced version of the concealed-effect proof (the full 10-seed matrix is in
benchmarks/diagnosis_confusion.py)."""

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "physics"))

from lightcurve.diagnosis.baseline import bic_gain, prior_bounds, typical_params  # noqa: E402
from lightcurve.diagnosis.residuals import (chi2_band, consistency, ljung_box,  # noqa: E402
                                            runs_test)


# ------------------------------------------------------------------------------------------
# residual statistics
# ------------------------------------------------------------------------------------------
def _lb_reference(x, h):
    """Ljung & Box (1978) eq. 2.1 written out with explicit loops (independent re-implementation)."""
    n = len(x)
    m = sum(x) / n
    c0 = sum((v - m) ** 2 for v in x)
    q = 0.0
    for k in range(1, h + 1):
        ck = sum((x[i] - m) * (x[i - k] - m) for i in range(k, n))
        q += (ck / c0) ** 2 / (n - k)
    return n * (n + 2) * q


def test_ljung_box_matches_reference_and_detects_ar1():
    rng = np.random.default_rng(0)
    x = rng.standard_normal(80)
    r = ljung_box(x, lags=10)
    assert r["q"] == pytest.approx(_lb_reference(list(x), 10), rel=1e-12)
    assert r["p_value"] == pytest.approx(stats.chi2.sf(r["q"], 10), rel=1e-12)
    # AR(1) with phi = 0.6, n = 200: rho_1 = 0.6 gives Q ~ 200*0.36 >> chi2(20) 0.1 % point
    e = rng.standard_normal(200)
    ar = np.zeros(200)
    for i in range(1, 200):
        ar[i] = 0.6 * ar[i - 1] + e[i]
    assert ljung_box(ar)["p_value"] < 1e-6


def test_ljung_box_false_alarm_rate_on_white_noise():
    # 300 white series: the fraction with p < 0.05 is Binomial(300, ~0.05); [0.01, 0.10] holds
    # with probability > 0.999 for a correct test (and an ~asymptotic chi-square at n = 100)
    rng = np.random.default_rng(1)
    p = np.array([ljung_box(rng.standard_normal(100))["p_value"] for _ in range(300)])
    assert 0.01 <= np.mean(p < 0.05) <= 0.10


def test_runs_test_counts_and_extremes():
    z = np.array([1, 2, -1, -3, 4, 5, 6, -1, 2.0])
    r = runs_test(z)
    assert r["runs"] == 5                      # ++ -- +++ - +
    n1, n2 = 6, 3
    assert r["expected"] == pytest.approx(2 * n1 * n2 / 9 + 1)
    alt = np.tile([1.0, -1.0], 30)             # 60 runs where ~31 are expected
    assert runs_test(alt)["p_value"] < 1e-5
    blocks = np.r_[np.ones(30), -np.ones(30)]  # 2 runs
    assert runs_test(blocks)["p_value"] < 1e-5


def test_chi2_band_coverage_and_consistency_false_alarm():
    lo, hi = chi2_band(50, 0.002)
    x = stats.chi2.rvs(50, size=20000, random_state=2) / 50
    assert abs(np.mean((x >= lo) & (x <= hi)) - 0.998) < 0.002
    # white N(0,1) residuals are declared consistent (false alarm <= 0.4 % per series; 30 series)
    rng = np.random.default_rng(3)
    ok = [consistency(rng.standard_normal(150), np.arange(150.0), 0)["consistent"] for _ in range(30)]
    assert sum(ok) >= 29


def test_bic_gain_is_the_gaussian_profile_likelihood_bic():
    # BIC = -2 ln L_max + k ln n with sigma^2 profiled (sigma^2 = RSS/n): Schwarz (1978)
    rng = np.random.default_rng(4)
    n = 120
    x = np.linspace(0, 1, n)
    y = 0.3 * x + rng.normal(0, 0.1, n)
    r0 = y - y.mean()
    A = np.c_[np.ones(n), x]
    r1 = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]

    def bic(r, k):
        s = math.sqrt(np.mean(r * r))
        return -2 * np.sum(stats.norm.logpdf(r, scale=s)) + k * math.log(n)

    ref = bic(r0, 1) - bic(r1, 2)
    assert bic_gain(float(r0 @ r0), float(r1 @ r1), n, 1) == pytest.approx(ref, rel=1e-10)


def test_prior_bounds_and_safe_typical_params():
    from lightcurve.physics import get_effect

    # fit bounds: the prior's support widened by a quarter of its span on each side
    ext = get_effect("extinction")
    assert prior_bounds(ext.params[0]) == pytest.approx((0.1 - 0.075, 0.4 + 0.075))
    co = get_effect("clock_offset")
    assert prior_bounds(co.params[0]) == pytest.approx((-3.0, 3.0))   # signed uniform: [-b, b] + 1
    # log-uniform: widened in log space, (b/a)**0.25 = 2 for 20..320
    gl = {p.name: p for p in get_effect("specular_glint").params}
    lo, hi = prior_bounds(gl["exponent"])
    assert lo * hi == pytest.approx(20.0 * 500.0) and hi / lo == pytest.approx((500 / 20) ** 1.5)
    # the allowed range clips: penumbra's shadow height cannot go below 0 m
    pen = get_effect("penumbra")
    assert prior_bounds(pen.params[0]) == pytest.approx((0.0, 62.5e3))
    # azimuth prior uniform(-180, 180): typical value 0 (the registry's method raises here)
    tp = typical_params(get_effect("specular_glint"))
    assert tp["az_deg"] == 0.0 and tp["exponent"] == 100.0


def test_cached_earthshine_equals_registry_earthshine():
    from physics_synth import make_ctx

    from lightcurve.diagnosis.fast import CachedEarthshine
    from lightcurve.photometry import load_shape
    from lightcurve.physics import get_effect

    ctx = make_ctx(load_shape("box_wing"), n=30, sun_dir=(0.3, 1.0, 0.2))
    a = get_effect("earthshine").apply(ctx, {"albedo_scale": 0.8})
    b = CachedEarthshine().apply(ctx, {"albedo_scale": 0.8})
    ok = np.isfinite(a)
    assert ok.sum() > 10
    np.testing.assert_allclose(b[ok], a[ok], rtol=0, atol=1e-10)
    assert np.array_equal(np.isfinite(b), ok)


# ------------------------------------------------------------------------------------------
# reduced concealed-effect proof (full matrix: benchmarks/diagnosis_confusion.py)
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("effect", ["extinction", "zero_point", "penumbra"])
def test_concealed_effect_ranks_first_and_fit_recovers(effect):
    """2 seeds per effect (1 for penumbra): the concealed effect must rank first and the
    final chi2/dof fall below 1.5 in every seed (issue 10 asks >= 9/10 seeds; the benchmark
    shows 10/10 for these effects, so a single failure here is a regression)."""
    from diag_synth import run_case

    seeds = (0,) if effect == "penumbra" else (0, 1)   # the shadow pass is the slowest case
    for seed in seeds:
        r = run_case(effect, seed)
        assert r["verdict"] == "mismatch", r
        assert r["top"] == effect, r
        assert r["chosen"][0] == effect, r
        assert r["final_chi2_dof"] < 1.5, r


def test_no_effect_is_consistent():
    """2 seeds with nothing concealed: verdict consistent (false alarm <= 0.4 % per seed by
    the chi-square band and whiteness levels, so a failure here has probability < 1 %)."""
    from diag_synth import run_case

    for seed in (0, 1):
        r = run_case("none", seed)
        assert r["verdict"] == "consistent", r
        assert r["chosen"] == [], r


# ------------------------------------------------------------------------------------------
# report + CLI
# ------------------------------------------------------------------------------------------
def test_cli_diagnose_writes_json_and_selfcontained_html(tmp_path):
    import warnings
    from dataclasses import replace

    from diag_synth import scenario

    from lightcurve.cli import main
    from lightcurve.studies.simulate import simulate

    sc = scenario("lit")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lc = simulate(replace(sc, effects={"zero_point": {"offset_mag": {"socorro": 0.3}}}), seed=5)
    h5 = tmp_path / "zp.h5"
    lc.write(h5)
    out = tmp_path / "dx"
    assert main(["diagnose", str(h5), "-o", str(out), "--quiet"]) == 0
    js = json.loads((out / "diagnosis.json").read_text())
    for key in ("verdict", "baseline", "segments", "candidates", "chosen", "final", "explanation"):
        assert key in js
    assert js["verdict"] == "mismatch" and js["chosen"][0] == "zero_point"
    zp = js["chosen_params"]["zero_point"]["offset_mag"]["values"]
    # the simulated offsets: +0.3 at socorro, 0 at bear_lake; 1 % noise at m ~ 5-8 mag, > 100
    # epochs per site: the fitted offsets are good to a few 0.001 mag (allow 6 sd + 0.01)
    assert abs(zp["socorro"]["value"] - 0.3) < 0.01 + 6 * zp["socorro"]["sd"]
    assert abs(zp["bear_lake"]["value"]) < 0.01 + 6 * zp["bear_lake"]["sd"]
    assert js["baseline"]["chi2_dof"] > 10 and js["final"]["chi2_dof"] < 1.5
    assert any(s["systematic"] and s["label"] == "socorro" for s in js["segments"])
    assert "zero-point" in js["explanation"].lower() or "zero point" in js["explanation"].lower()
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 2
    assert "http://" not in html and "https://" not in html and "<script" not in html
    # bad input: exit 2 with a clear message
    assert main(["diagnose", str(h5), "-o", str(out), "--free", "bogus", "--quiet"]) == 2
