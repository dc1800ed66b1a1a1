"""Configuration objects of the filters (lightcurve.filters.config): validation, the three ways
of building them (Python keywords, objects, CLI options, study TOML) giving the same run."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from lightcurve.errors import InputError
from lightcurve.filters import MEKFConfig, ProblemConfig, UKFConfig, build_problem, invert
from lightcurve.filters.config import split_options


def test_defaults_and_validation_name_the_field():
    p = ProblemConfig()
    assert (p.seed, p.sigma_theta_deg, p.sigma_omega_deg_s) == (0, 3.0, 0.02)   # Bernard ch. 9
    assert MEKFConfig().variant == "robust" and UKFConfig().alpha == 1.0
    cases = [(ProblemConfig, {"sigma_theta_deg": 0.0}, "sigma_theta_deg"),
             (ProblemConfig, {"seed": -1}, "seed"),
             (ProblemConfig, {"acs_mode": "wobble"}, "acs_mode"),
             (ProblemConfig, {"initial_q": (1.0, 0.1, 0.0, 0.0)}, "initial_q"),
             (ProblemConfig, {"attitude": "truth"}, "reflection"),
             (ProblemConfig, {"reflection_kinds": ("xi", "q")}, "reflection_kinds"),
             (MEKFConfig, {"error": "euler"}, "error"),
             (MEKFConfig, {"variant": "paper"}, "variant"),
             (UKFConfig, {"alpha": 0.0}, "alpha"),
             (UKFConfig, {"beta": float("nan")}, "beta")]
    for cls, kw, fieldname in cases:
        with pytest.raises(InputError) as err:
            cls(**kw)
        assert err.value.field == fieldname, (cls, kw)
    with pytest.raises(InputError, match="filters.ukf.gamma"):
        UKFConfig.from_mapping({"gamma": 1.0}, file="s.toml", table="filters.ukf")
    with pytest.raises(InputError) as err:
        UKFConfig.from_mapping({"alpha": -2}, file="s.toml", table="filters.ukf")
    assert err.value.file == "s.toml" and err.value.field == "filters.ukf.alpha"
    with pytest.raises(TypeError, match="bogus"):
        split_options("mekf", {"bogus": 1})
    # another filter's keyword is ignored, as the keyword form always did
    prob, filt = split_options("mekf", {"particles": 5, "seed": 2, "error": "grp"})
    assert prob == {"seed": 2} and filt == {"error": "grp"}


@pytest.mark.parametrize("method", ["mekf", "ukf"])
def test_object_and_keyword_calls_give_the_same_estimate(curve, method):
    kw = dict(seed=4, sigma_theta_deg=5.0, sigma_omega_deg_s=0.05)
    filt = {"mekf": dict(error="small_angle"), "ukf": dict(alpha=0.8, kappa=1.0)}[method]
    a = invert(curve, method, **kw, **filt)
    np.testing.assert_array_equal(invert(curve, method=method, **kw, **filt).q, a.q)
    cfg = (MEKFConfig if method == "mekf" else UKFConfig)(**filt)
    b = invert(curve, cfg, problem=ProblemConfig(**kw))
    c = invert(curve, cfg, problem=ProblemConfig(seed=9, **{k: v for k, v in kw.items()
                                                            if k != "seed"}), seed=4)
    for e in (b, c):
        np.testing.assert_array_equal(a.q, e.q)
        np.testing.assert_array_equal(a.cov, e.cov)
    assert a.meta["variant"] == "robust"
    t = invert(curve, cfg.replace(variant="thesis"), problem=ProblemConfig(**kw))
    assert t.meta["variant"] == "thesis"
    # build_problem accepts the same object and keywords
    p1 = build_problem(curve, ProblemConfig(**kw))
    p2 = build_problem(curve, **kw)
    np.testing.assert_array_equal(p1.q0, p2.q0)


def test_changing_the_variant_moves_the_variant_defaults(curve, monkeypatch):
    # a configuration built for one variant and switched with replace(variant=...) (or with
    # invert(..., config, variant=...)) runs the other variant's algorithm, not a mix: the
    # fields at the old variant's default take the new one's, a departure is kept
    import importlib

    from lightcurve.filters.bpf import BPFConfig

    inv = importlib.import_module("lightcurve.filters.invert")   # the package exports invert()

    assert BPFConfig().replace(variant="thesis") == BPFConfig.thesis()
    assert BPFConfig.thesis(particles=50).replace(variant="robust") == BPFConfig.robust(particles=50)
    assert BPFConfig.robust(rejuvenation="joint").replace(variant="thesis").rejuvenation == "joint"
    assert BPFConfig.robust().replace(particles=50).resampling == "systematic"
    assert MEKFConfig(error="small_angle").replace(variant="thesis").error == "small_angle"
    seen = {}
    monkeypatch.setitem(inv._RUNNERS, "bpf", lambda fp, cfg, **kw: seen.setdefault("cfg", cfg))
    monkeypatch.setattr(inv, "attach_measurements", lambda *a: None)
    invert(curve, BPFConfig(particles=50), variant="thesis", seed=1)
    assert seen["cfg"] == BPFConfig.thesis(particles=50)


def test_cli_options_build_the_same_configs():
    from lightcurve.cli import invert as cli_invert

    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    cli_invert.register(sub)
    args = parser.parse_args(["invert", "x.h5", "-o", "out", "--method", "ukf", "--alpha", "0.7",
                              "--seed", "3", "--variant", "thesis", "--sigma-theta-deg", "4"])
    problem, opts = cli_invert.configs_from_args(args)
    assert problem.seed == 3 and problem.sigma_theta_deg == 4.0
    assert UKFConfig(**opts) == UKFConfig(alpha=0.7, variant="thesis")
    # without --alpha the variant chooses: thesis 0.25, robust 1, and a file's own variant
    # (no --variant) is not overridden by a robust default
    for variant, alpha in (("thesis", 0.25), ("robust", 1.0), (None, None)):
        argv = ["invert", "x.h5", "-o", "out", "--method", "ukf"]
        args = parser.parse_args(argv + (["--variant", variant] if variant else []))
        _, opts = cli_invert.configs_from_args(args)
        assert "alpha" not in opts
        if variant:
            assert UKFConfig(**opts).alpha == alpha


def test_ukf_alpha_default_follows_the_variant(monkeypatch):
    # Bernard §6.2.2 leaves α open: the thesis variant's one value is 0.25, the robust one's 1;
    # an α given is kept whatever the variant; the thesis runner's own default is the thesis's
    from lightcurve.filters import ukf_thesis
    from lightcurve.filters.config import UKF_DEFAULT_ALPHA

    assert UKF_DEFAULT_ALPHA == {"robust": 1.0, "thesis": 0.25}
    assert UKFConfig(variant="thesis").alpha == 0.25 and UKFConfig().alpha == 1.0
    assert UKFConfig(variant="thesis", alpha=1.0).alpha == 1.0
    assert UKFConfig().replace(variant="thesis").alpha == 0.25
    assert UKFConfig(alpha=0.5).replace(variant="thesis").alpha == 0.5
    assert UKFConfig.from_mapping({"variant": "thesis"}).alpha == 0.25
    seen = {}
    monkeypatch.setattr(ukf_thesis, "_run", lambda p, L, a, b, k, *r: seen.update(a=a, b=b, k=k))
    monkeypatch.setattr(ukf_thesis, "StateLayout", lambda *a: type("L", (), {"nx": 6})())

    class P:
        meta, attitude_known = {}, False
    ukf_thesis.run_ukf_thesis(P())
    assert seen == {"a": 0.25, "b": 2.0, "k": 0.0}
    ukf_thesis.run_ukf_thesis(P(), alpha=0.5)
    assert seen["a"] == 0.5


def test_study_toml_filter_tables(tmp_path):
    from lightcurve._paths import data_dir
    from lightcurve.studies.study import load_study

    scen = data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-{dynamics}-{sites}site.toml"
    text = f"""
[study]
name = "t"
runs = 1
scenario = "{scen.as_posix()}"
[grid]
filter = ["ukf"]
dynamics = ["controlled"]
sites = [1]
sigma_theta_deg = [3.0]
sigma_omega_deg_s = [0.02]
r_percent = [1.0]
[filters.ukf]
variant = "thesis"
alpha = 0.5
"""
    f = tmp_path / "s.toml"
    f.write_text(text)
    st = load_study(f)
    ukf = dict(dict(st.options["filters"])["ukf"])
    assert UKFConfig(**ukf) == UKFConfig(alpha=0.5, variant="thesis")
    f.write_text(text.replace("alpha = 0.5", "alpha = 0.5\nlambda = 2"))
    with pytest.raises(InputError, match="filters.ukf.lambda"):
        load_study(f)


def test_study_filter_table_keeps_the_study_variant(tmp_path, monkeypatch):
    # a per-filter table that does not name a variant changes only the fields it gives: the
    # runs keep [options] variant = "thesis" and that variant's defaults (multinomial
    # resampling, no progressive correction, no gate: Bernard ch. 6-7), not the robust ones
    import lightcurve.filters as filters_pkg
    from lightcurve._paths import data_dir
    from lightcurve.filters.bpf import BPFConfig
    from lightcurve.studies.runner import execute_task
    from lightcurve.studies.study import load_study

    scen = data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-{dynamics}-{sites}site.toml"
    f = tmp_path / "s.toml"
    f.write_text(f"""
[study]
name = "t"
runs = 1
scenario = "{scen.as_posix()}"
[grid]
filter = ["bpf", "ukf"]
dynamics = ["controlled"]
sites = [1]
sigma_theta_deg = [60.0]
sigma_omega_deg_s = [0.02]
r_percent = [1.0]
[options]
variant = "thesis"
particles = 100
[filters.bpf]
roughening = 0.1
[filters.ukf]
alpha = 0.5
""")
    st = load_study(f)
    assert dict(st.options["filters"]) == {"bpf": (("roughening", 0.1),),
                                           "ukf": (("alpha", 0.5),)}
    seen = {}

    def capture(curve, method, **kw):
        seen[method] = kw
        raise RuntimeError("captured")

    monkeypatch.setattr(filters_pkg, "invert", capture)
    for task in st.tasks():
        assert execute_task(task)["status"] == "failed"
    assert seen["bpf"]["variant"] == "thesis" and seen["bpf"]["roughening"] == 0.1
    cfg = BPFConfig(**{k: v for k, v in seen["bpf"].items() if k in ("variant", "roughening",
                                                                    "particles")})
    assert (cfg.resampling, cfg.progressive, cfg.gating) == ("multinomial", False, False)
    assert UKFConfig(variant=seen["ukf"]["variant"], alpha=seen["ukf"]["alpha"]) == \
        UKFConfig(variant="thesis", alpha=0.5)
    # still validated, under the study's variant
    f.write_text(f.read_text().replace("roughening = 0.1", "roughening = -1.0"))
    with pytest.raises(InputError, match="filters.bpf.roughening"):
        load_study(f)


@pytest.mark.parametrize("cls", ["MEKFConfig", "UKFConfig", "BPFConfig"])
def test_an_unknown_variant_is_one_error_naming_the_field_value_and_allowed_variants(cls):
    """Every filter configuration refuses a variant other than robust / thesis with the same
    InputError (field, value, allowed), before any variant default is filled in."""
    from lightcurve.filters import config as C
    from lightcurve.filters.bpf import BPFConfig

    klass = BPFConfig if cls == "BPFConfig" else getattr(C, cls)
    with pytest.raises(InputError) as exc:
        klass(variant="thesys")
    assert (exc.value.field, exc.value.value) == ("variant", "thesys")
    assert exc.value.allowed == "robust, thesis"
