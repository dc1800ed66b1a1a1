"""Diagnosis machinery: residual tests, evidence, the Earthshine cache, folds, identification,
reports and the CLI (the concealed-effect proofs are in test_diagnosis_concealed.py, the full
10-seed matrix in benchmarks/diagnosis_confusion.py)."""

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
    assert js["verdict"] == "mismatch" and js["chosen"] == ["zero_point"], js["verdict_line"]
    step = next(s for c in js["candidates"] if c["name"] == "zero_point" for s in c["steps"]
                if s.get("decision") == "added")
    zp = step["params"]
    # the simulated offsets: +0.3 at socorro, 0 at bear_lake; 1 % noise at m ~ 5-8 mag, > 100
    # epochs per site: the fitted offsets are good to a few 0.001 mag (allow 6 sd + 0.01)
    assert abs(zp["offset_mag[socorro]"]["value"] - 0.3) < 0.01 + 6 * zp["offset_mag[socorro]"]["sd"]
    assert abs(zp["offset_mag[bear_lake]"]["value"]) < 0.01 + 6 * zp["offset_mag[bear_lake]"]["sd"]
    assert step["identified"] and step["held_out"]["gain"] > 10
    assert js["model"]["effects"][0]["name"] == "zero_point"
    assert abs(js["model"]["effects"][0]["params"]["offset_mag"]["socorro"] - 0.3) < 0.02
    assert js["baseline"]["chi2_dof"] > 10 and js["final"]["chi2_dof"] < 1.5
    assert any(s["systematic"] and s["label"] == "socorro" for s in js["segments"])
    assert "zero-point" in js["explanation"].lower() or "zero point" in js["explanation"].lower()
    cv = js["cross_validation"]
    assert cv["possible"] and cv["selection"]["grouping"] == "blocks"
    assert cv["schemes"][0]["final"]["rms"] < cv["schemes"][0]["baseline"]["rms"]
    html = (out / "report.html").read_text()
    assert html.index("Verdict:") < html.index("<h2>")                  # verdict at the top
    assert "UTC" in html and html.count("data:image/png;base64,") >= 2
    assert "http://" not in html and "https://" not in html and "<script" not in html
    # the fitted model applied unchanged to a recording without the offset: it does not
    # transfer (the zero point is not there), and the report says so, component by component
    lc0 = simulate(sc, seed=6)
    h0 = tmp_path / "clean.h5"
    lc0.write(h0)
    out2 = tmp_path / "tr"
    assert main(["diagnose", str(h0), "--apply", str(out / "diagnosis.json"), "-o", str(out2),
                 "--quiet"]) == 0
    tr = json.loads((out2 / "transfer.json").read_text())
    comp = {r["component"]: r for r in tr["components"]}
    assert comp["model as given"]["chi2_dof"] < 1.5
    assert comp["zero_point"]["transfers"] is False and comp["zero_point"]["delta_rms"] > 0.05
    assert "NOT" in tr["verdict"] or "not" in tr["verdict"]
    # and to a second recording with the same offset: it transfers
    lc1 = simulate(replace(sc, effects={"zero_point": {"offset_mag": {"socorro": 0.3}}}), seed=7)
    h1 = tmp_path / "zp1.h5"
    lc1.write(h1)
    assert main(["diagnose", str(h1), "--apply", str(out / "diagnosis.json"), "-o", str(out2),
                 "--quiet"]) == 0
    tr = json.loads((out2 / "transfer.json").read_text())
    comp = {r["component"]: r for r in tr["components"]}
    assert comp["zero_point"]["transfers"] is True and comp["zero_point"]["chi2_dof"] < 1.5
    # a file that is not a diagnosis: exit 2
    assert main(["diagnose", str(h1), "--apply", str(h0), "-o", str(out2), "--quiet"]) == 2
    # bad input: exit 2 with a clear message
    assert main(["diagnose", str(h5), "-o", str(out), "--free", "bogus", "--quiet"]) == 2
