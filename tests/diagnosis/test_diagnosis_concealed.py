"""The diagnosis against an independent simulator (tests/diagnosis/concealed.py: plain NumPy,
no import of the package's photometry or physics; Bernard Table 9.2 cube).

1. The generator's model without effects equals the package's baseline model, and every
   registry effect's forward model equals the generator's independent version — exactly
   (to rounding) where both are exact, within a stated fraction of the 1 % noise where they
   discretise differently (Earth grids, shadow sampling, exposure quadrature).
2. A reduced concealed-effect matrix (one seed for a subset of the cases; the full 10-seed
   matrix over every effect is benchmarks/diagnosis_confusion.py): the concealed effect is
   named first, its held-out χ²/n is below 1.5, no named effect has an unidentified
   parameter; the no-effect recording is consistent.
3. A glint seen in a single unresolved flash yields "unidentifiable", not a named effect.
"""

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import concealed as G  # noqa: E402
import concealed_cases as C  # noqa: E402


def _noise_free(key, effect=None, per_site=None):
    geo, shape, t = C.scenario(key)
    rec = G.record(geo, shape, t, [{} for _ in geo.sites], np.random.default_rng(0))
    prob = C.magnitude_problem(rec, key, key)
    assert prob.n == rec["t"].size          # every generated row is modelled
    m = np.empty(prob.n)
    for k in range(len(geo.sites)):
        rows = rec["site"] == k
        eff = {} if effect is None else {effect: per_site[k]}
        m[rows] = G.magnitudes(geo, shape, k, rec["t"][rows], eff)
    return prob, m


@pytest.mark.parametrize("key", ["lit2", "mesh", "shadow", "earthshine", "spin", "fast", "smear"])
def test_generator_baseline_equals_package_model(key):
    """Independent geometry, attitude (Bernard eq. 3.16, 3.20), Cook–Torrance with Table 9.2
    materials and the magnitude equation agree with the package to rounding."""
    prob, m = _noise_free(key)
    np.testing.assert_allclose(prob.ctx.evaluate(), m, rtol=0, atol=1e-9)


_BIS = {"az_deg": -43.92, "el_deg": -26.57}   # a normal that flashes in the "spin" scenario
# effect, scenario, package parameters, generator parameters per site, options, tolerance:
# ("abs", mag) or ("sigma", max |Δ|/σ, rms |Δ|/σ) with σ the 1 % noise
FORWARD = [
    ("extinction", "lit2", {"k_mag_per_airmass": [0.2, 0.3]}, [{"k_mag_per_airmass": 0.2}, {"k_mag_per_airmass": 0.3}], {}, ("abs", 1e-9)),
    ("zero_point", "lit2", {"offset_mag": [0.2, -0.3]}, [{"offset_mag": 0.2}, {"offset_mag": -0.3}], {}, ("abs", 1e-9)),
    ("clock_offset", "fast", {"dt_s": [1.3]}, [{"dt_s": 1.3}], {}, ("abs", 1e-9)),
    ("light_time", "fast", {}, [{}], {}, ("abs", 1e-9)),
    # 64 Gauss-Legendre nodes against a 201-point Simpson rule over 5 s of a 4 deg/s rotator
    ("exposure_smearing", "smear", {"exposure_s": [5.0]}, [{"exposure_s": 5.0}], {"n_nodes": 64}, ("abs", 1e-4)),
    ("specular_glint", "spin", {**_BIS, "area_m2": 0.5, "exponent": 50.0}, [{**_BIS, "area_m2": 0.5, "exponent": 50.0}], {}, ("abs", 1e-9)),
    ("unmodelled_facet", "spin", {**_BIS, "area_m2": 0.5}, [{**_BIS, "area_m2": 0.5}], {}, ("abs", 1e-9)),
    ("penumbra", "shadow", {"shadow_height_m": 20e3}, [{"shadow_height_m": 20e3}] * 2, {}, ("abs", 1e-9)),
    # 2 deg ellipsoidal grid (package) against a 1.5 deg spherical one (generator)
    ("earthshine", "earthshine", {"albedo_scale": 1.0}, [{"albedo_scale": 1.0}] * 2, {"resolution_deg": 2.0}, ("sigma", 0.5, 0.15)),
    # 48x48 samples per triangle (package) against a 40x40 grid per face with exact box rays
    ("self_shadowing", "mesh", {}, [{}] * 2, {"subdivisions": 48}, ("sigma", 1.5, 0.3)),
]


@pytest.mark.parametrize("effect,key,pkg,gen,opts,tol", FORWARD, ids=[f[0] for f in FORWARD])
def test_registry_effect_equals_independent_forward_model(effect, key, pkg, gen, opts, tol):
    from lightcurve.physics import get_effect

    prob, m_gen = _noise_free(key, effect, gen)
    eff = get_effect(effect, **opts)
    params = {k: (np.asarray(v, float) if isinstance(v, list) else v) for k, v in pkg.items()}
    m_pkg = eff.apply(prob.ctx, params)
    m0 = prob.ctx.evaluate()
    # the same rows are dark (a larger shadow puts some in the umbra)
    np.testing.assert_array_equal(np.isfinite(m_pkg), np.isfinite(m_gen))
    ok = np.isfinite(m_gen)
    assert ok.sum() > 0.8 * ok.size
    m_pkg, m_gen, m0 = m_pkg[ok], m_gen[ok], m0[ok]
    sig = np.abs(m_gen) * 0.01 / 3
    assert np.max(np.abs(m_gen - m0) / sig) > 5          # the effect is visible here
    if tol[0] == "abs":
        np.testing.assert_allclose(m_pkg, m_gen, rtol=0, atol=tol[1])
    else:
        z = (m_pkg - m_gen) / sig
        assert np.max(np.abs(z)) < tol[1] and np.sqrt(np.mean(z * z)) < tol[2], (np.max(np.abs(z)),)


#: CSS output noise of the concealed cases (full scale 1)
SIG = C.CSS_SIGMA
CSS_FORWARD = [
    # grid cells straddling a sensor's field-of-view edge are in or out as a whole: the
    # albedo sums of a 2° ellipsoidal grid (package) and a 1.5° spherical one differ by
    # ~2 % of the albedo signal (first order in the cell size): < 3σ at worst, 0.3σ rms
    ("css_albedo", {"albedo_scale": 1.1}, {"resolution_deg": 2.0}, (3 * SIG, 0.3 * SIG)),
    ("css_misalignment", {"d_az_deg": np.linspace(-2, 2, 8), "d_el_deg": np.linspace(1.5, -1.5, 8)}, {}, 1e-12),
    ("css_scale_factor", {"common": 0.9, "individual": np.linspace(0.95, 1.05, 8)}, {}, 1e-12),
    ("css_fault", {"sensor": 3.0, "gain": 0.2, "t_start_s": 2000.0}, {}, 1e-12),
]


@pytest.mark.parametrize("effect,params,opts,atol", CSS_FORWARD, ids=[c[0] for c in CSS_FORWARD])
def test_css_effect_equals_independent_forward_model(effect, params, opts, atol):
    """O'Keefe eq. 2.19/2.21 written independently (exact), and the albedo sums."""
    from lightcurve.physics import get_effect

    geo, _, t = C.scenario("css")
    prob = C.css_model_problem(geo, t, np.zeros((t.size, 8)), 0.005, "css")
    np.testing.assert_allclose(prob.ctx.evaluate(), G.css_outputs(geo, t, {}), rtol=0, atol=1e-12)
    y_pkg = get_effect(effect, **opts).apply(prob.ctx, params)
    y_gen = G.css_outputs(geo, t, {effect: params})
    assert np.max(np.abs(y_gen - G.css_outputs(geo, t, {}))) > 0.02
    if isinstance(atol, tuple):
        d = y_pkg - y_gen
        assert np.max(np.abs(d)) < atol[0] and np.sqrt(np.mean(d * d)) < atol[1]
    else:
        np.testing.assert_allclose(y_pkg, y_gen, rtol=0, atol=atol)


# ------------------------------------------------------------------------------------------
# reduced concealed-effect matrix (full: benchmarks/diagnosis_confusion.py)
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("case", ["extinction", "specular_glint", "clock_offset", "light_time",
                                  "penumbra", "css_misalignment"])
def test_concealed_effect_is_named_first_and_predicts_held_out_data(case):
    """Seed 0: named first, held-out χ²/n < 1.5, nothing named unidentified (the acceptance
    asks ≥ 9/10 seeds; the benchmark's full matrix shows the rate, so a failure of seed 0
    here is a regression). light_time exercises the one-standard-error rule (a clock offset
    of −τ fits as well), css_misalignment the posterior-predictive held-out CSS outputs."""
    r = C.run_case(case, 0)
    assert r["verdict"] == "mismatch", r["json"]["verdict_line"]
    assert r["first"] == case, (r["chosen"], r["unidentified"])
    assert r["held_out_chi2_per_n"] < 1.5, r["held_out_chi2_per_n"]
    assert not r["named_unidentified"]
    js = r["json"]
    # in-sample and held-out numbers side by side for every evaluated candidate
    for c in js["candidates"]:
        for s in c["steps"]:
            if s.get("applicable"):
                assert "in_sample" in s and "held_out" in s and "identified" in s


def test_no_effect_is_consistent():
    """Nothing concealed: consistent (false alarm ≤ 0.3 % by the χ² band and whiteness levels)."""
    for case in ("none", "none@css"):
        r = C.run_case(case, 0)
        assert r["verdict"] == "consistent" and r["chosen"] == [], r["json"]["verdict_line"]


def test_unresolved_glint_is_unidentifiable():
    """A glint seen in one narrow flash (exponent 300, a few samples) cannot be identified:
    the diagnosis reports the mismatch and the glint as unidentifiable and names nothing."""
    from lightcurve.diagnosis.diagnose import diagnose

    prob, truth = C.single_flash_case(0)
    z = prob.standardized(prob.predict())
    assert np.sum(np.abs(z) > 3) >= 5            # the flash is plainly in the data
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(prob)
    js = d.summary()
    assert js["verdict"] == "mismatch"
    assert js["chosen"] == [], js["chosen"]
    assert "specular_glint" in [u["name"] for u in js["unidentified"]]
    assert "unidentifiable" in js["verdict_line"]


def test_geometric_penumbra_is_named_with_its_shadow_height_held():
    """Penumbra with no atmospheric enlargement (shadow height 0, at the edge of its range):
    the height is not identified (at its bound), so it is held at its reference value 0 (the
    geometric shadow, ParamSpec.fixable) and the penumbra is named with it held."""
    from lightcurve.diagnosis.diagnose import diagnose

    geo, shape, t = C.scenario("shadow")
    rec = G.record(geo, shape, t, [{"penumbra": {"shadow_height_m": 0.0}}] * 2,
                   np.random.default_rng(5))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        js = diagnose(C.magnitude_problem(rec, "shadow", "penumbra-h0")).summary()
    assert js["chosen"] == ["penumbra"], js["verdict_line"]
    eff = js["model"]["effects"][0]
    assert eff["held"] == ["shadow_height_m"] and eff["params"]["shadow_height_m"] == 0.0
    assert js["cross_validation"]["schemes"][0]["final"]["chi2_per_n"] < 1.5
