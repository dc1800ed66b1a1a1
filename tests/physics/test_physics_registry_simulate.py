"""Registry contents, [effects] TOML validation, and the round trip through `lightcurve simulate`."""

import json
import warnings

import numpy as np
import pytest

from lightcurve.errors import InputError
from lightcurve.physics import available_effects, get_effect, parse_effects
from lightcurve.studies.scenario import parse_scenario

REQUIRED = {"extinction", "earthshine", "penumbra", "self_shadowing", "light_time",
            "exposure_smearing", "clock_offset", "zero_point", "specular_glint",
            "css_albedo", "css_misalignment", "css_scale_factor", "css_fault"}


def test_registry_has_issue_effects_with_descriptions_and_priors():
    names = set(available_effects())
    assert REQUIRED <= names
    assert set(available_effects("css")) == {n for n in names if n.startswith("css_")}
    for n in names:
        e = get_effect(n)
        assert e.description.endswith(".") and len(e.description.split()) >= 10, n
        for p in e.params:
            assert p.unit and p.min <= p.default <= p.max, (n, p.name)


class _Ctx:
    n_sites = 2
    n_sensors = 6
    t = np.arange(10.0)

    def __len__(self):
        return 10


def test_sample_params_in_range_and_reproducible():
    for n in available_effects():
        e = get_effect(n)
        a = e.sample_params(np.random.default_rng(5), _Ctx())
        b = e.sample_params(np.random.default_rng(5), _Ctx())
        assert json.dumps({k: np.asarray(v).tolist() for k, v in a.items()}) == \
            json.dumps({k: np.asarray(v).tolist() for k, v in b.items()})
        e.check_params(a, _Ctx())  # ValueError if outside the allowed range
    # the signed prior never gives a zero-point offset smaller than 0.1 mag
    zp = [get_effect("zero_point").sample_params(np.random.default_rng(s), _Ctx())["offset_mag"]
          for s in range(50)]
    assert np.all(np.abs(zp) >= 0.1)


def test_parse_effects_values_and_errors():
    sites = ["socorro", "maui"]
    cfg = parse_effects({"extinction": {"k_mag_per_airmass": {"maui": 0.1}},
                         "clock_offset": {"dt_s": 0.5}, "penumbra": {}}, "s.toml", sites)
    assert [c.name for c in cfg] == ["penumbra", "clock_offset", "extinction"]  # ORDER
    np.testing.assert_allclose(cfg[2].params["k_mag_per_airmass"], [0.2, 0.1])
    np.testing.assert_allclose(cfg[1].params["dt_s"], [0.5, 0.5])
    with pytest.raises(InputError, match=r"effects\.no_such.*allowed: .*extinction"):
        parse_effects({"no_such": {}}, "s.toml", sites)
    with pytest.raises(InputError, match=r"effects\.extinction\.k_mag_per_airmass.*out of range"):
        parse_effects({"extinction": {"k_mag_per_airmass": -1.0}}, "s.toml", sites)
    with pytest.raises(InputError, match=r"effects\.extinction\.k_mag_per_airmass\.paris"):
        parse_effects({"extinction": {"k_mag_per_airmass": {"paris": 0.1}}}, "s.toml", sites)
    with pytest.raises(InputError, match=r"effects\.zero_point.*unknown key"):
        parse_effects({"zero_point": {"offset": 0.1}}, "s.toml", sites)
    with pytest.raises(InputError, match=r"effects\.exposure_smearing\.n_nodes"):
        parse_effects({"exposure_smearing": {"n_nodes": 0}}, "s.toml", sites)
    with pytest.raises(InputError, match=r"effects\.earthshine\.albedo"):
        parse_effects({"earthshine": {"albedo": "missing.csv"}}, "s.toml", sites)
    with pytest.raises(InputError, match="unknown effect"):   # CSS effects are not for magnitudes
        parse_effects({"css_fault": {}}, "s.toml", sites)
    assert parse_effects({"zero_point": {"enabled": False, "offset_mag": 0.3}}, "s.toml", sites) == []


def _default_text():
    from lightcurve._paths import data_dir

    text = (data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml").read_text()
    assert "[effects" not in text
    return text + "\n[effects]\n"


def test_scenario_rejects_bad_effects():
    text = _default_text()
    with pytest.raises(InputError, match=r"effects\.zero_point\.offset_mag"):
        parse_scenario(text.replace("[effects]", "[effects.zero_point]\noffset_mag = 9.0"), file="x.toml")
    with pytest.raises(InputError, match="ignore_eclipse"):
        parse_scenario(text.replace("[effects]", "[effects.penumbra]"), file="x.toml")


def test_simulate_round_trip_through_cli(tmp_path):
    """`lightcurve simulate` with [effects]: truth/mag = baseline + k X + δ, attrs record them."""
    from lightcurve.cli import main
    from lightcurve.io.lightcurve_h5 import read_lightcurve
    from lightcurve.studies.simulate import simulate

    text = _default_text()
    eff = ("[effects.extinction]\nk_mag_per_airmass = {socorro = 0.25}\n"
           "[effects.zero_point]\noffset_mag = 0.1\n")
    p = tmp_path / "s.toml"
    p.write_text(text.replace("[effects]", eff))
    out = tmp_path / "lc.h5"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["simulate", str(p), "-o", str(out)]) == 0
        base = simulate(parse_scenario(text))
    lc = read_lightcurve(out)
    h = lc.elevation_rad
    X = 1.0 / (np.sin(h) + 0.50572 * (np.degrees(h) + 6.07995) ** -1.6364)  # Kasten & Young
    np.testing.assert_allclose(lc.truth_mag - base.truth_mag, 0.25 * X + 0.1, atol=1e-9)
    rec = json.loads(lc.attrs["effects"])
    assert rec["extinction"]["params"]["k_mag_per_airmass"] == {"socorro": 0.25}
    assert rec["zero_point"]["params"]["offset_mag"] == {"socorro": 0.1}
    # noise is drawn after the effects: σ = m r/3 of the affected magnitude (Bernard eq. 9.3)
    np.testing.assert_allclose(lc.mag_sigma, lc.truth_mag * 0.01 / 3, rtol=1e-12)
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("[effects]", "[effects.extinktion]"))
    assert main(["simulate", str(bad), "-o", str(tmp_path / "x.h5")]) == 2


def test_simulator_baseline_equals_model_context():
    """The context's magnitude without effects reproduces the simulator's truth magnitudes."""
    from lightcurve.photometry import load_shape
    from lightcurve.physics import ModelContext
    from lightcurve.studies.simulate import simulate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lc = simulate(parse_scenario(_default_text()))
    ctx = ModelContext.from_lightcurve(lc, load_shape("cube_1u"))
    np.testing.assert_allclose(ctx.magnitude(), lc.truth_mag, atol=1e-9)
    # clock offset through the simulator = the context evaluated at t + δ
    text = _default_text().replace("[effects]", "[effects.clock_offset]\ndt_s = 0.8")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lc2 = simulate(parse_scenario(text))
    np.testing.assert_allclose(lc2.truth_mag, ctx.magnitude(t_shift=0.8), atol=1e-6)


def test_typical_params_for_every_effect_and_prior_kind():
    # regression: uniform priors with a negative lower end used to hit sqrt(a*b) of the
    # log-uniform branch (math domain error); every registered effect must give finite values
    import math

    from lightcurve.physics import available_effects, get_effect

    for name in available_effects(kind="magnitude"):
        eff = get_effect(name)
        vals = eff.typical_params(None) if not eff.params or all(p.per is None for p in eff.params) else None
        if vals is None:
            continue
        for k, v in vals.items():
            assert all(math.isfinite(x) for x in np.ravel(v)), (name, k, v)
