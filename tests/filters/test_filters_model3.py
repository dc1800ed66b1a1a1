"""Model 3 (Bernard 2021 eq. 8.39–8.44): facet reflection parameters as MEKF/UKF states."""

from __future__ import annotations

import json

import numpy as np
import pytest
from filters_synth import make_curve
from scipy import stats

from lightcurve.core import rotations as CR
from lightcurve.errors import InputError
from lightcurve.filters.facet_states import (FacetParameterStates, dp_dz, from_unbounded,
                                             mag_states_nb, to_unbounded)
from lightcurve.filters.invert import invert
from lightcurve.filters.models import MagnitudeModel
from lightcurve.photometry import apparent_magnitude, load_shape
from lightcurve.studies.fit_reflection import perturb_reflection


@pytest.fixture(scope="module")
def cube():
    return load_shape("cube_1u_mixed")


def _perturbed_curve(n=120, dt=2.0, refl_seed=5, noise_seed=3):
    """make_curve's geometry and attitude, magnitudes from a §10.1-perturbed cube (10 %)."""
    c = make_curve(n=n, dt=dt)
    sh = load_shape("cube_1u_mixed")
    pert, new = perturb_reflection(sh, np.random.default_rng(refl_seed))
    m = apparent_magnitude(pert, c.truth_q, c.obj_to_sun_unit, c.obj_to_obs_unit, c.range_obs_m,
                           c.range_sun_m)
    c.truth_mag = m
    c.mag = m + c.mag_sigma * np.random.default_rng(noise_seed).standard_normal(len(m))
    return c, new


def _truth(names, new):
    return np.array([new[n[:-1].split("[")[0]][int(n[:-1].split("[")[1])] for n in names])


@pytest.fixture(scope="module")
def pcurve():
    return _perturbed_curve()


def test_transforms_round_trip_jacobian_and_single_implementation(cube):
    """logit/ln maps invert each other; dp/dz equals central differences of z → p; the
    batch posterior (fit_reflection) uses the very same functions."""
    rng = np.random.default_rng(0)
    logit = np.array([True, True, False, False])
    p = np.column_stack([rng.uniform(0.01, 0.99, 50), rng.uniform(0.01, 0.99, 50),
                         rng.uniform(0.01, 2.0, 50), rng.uniform(1e-4, 60.0, 50)])
    z = to_unbounded(p, logit)
    np.testing.assert_allclose(from_unbounded(z, logit), p, rtol=1e-12)
    h = 1e-6
    fd = (from_unbounded(z + h, logit) - from_unbounded(z - h, logit)) / (2 * h)
    np.testing.assert_allclose(dp_dz(z, logit), fd, rtol=1e-7)
    # closed forms: logit → p(1−p); ln → p
    np.testing.assert_allclose(dp_dz(z, logit)[:, 0], p[:, 0] * (1 - p[:, 0]), rtol=1e-12)
    np.testing.assert_allclose(dp_dz(z, logit)[:, 3], p[:, 3], rtol=1e-12)
    # ranges are kept for any z (a sigma point / particle never leaves them)
    zz = np.array([[-40.0, 40.0, -40.0, 40.0]])
    pp = from_unbounded(zz, logit)
    assert 0 < pp[0, 0] < 1 and 0 < pp[0, 1] <= 1 and pp[0, 2] > 0 and pp[0, 3] > 0

    from filters_synth import make_curve as mk

    from lightcurve.studies.fit_reflection import ReflectionPosteriorModel

    c = mk(n=8)
    post = ReflectionPosteriorModel(cube, c, c.truth_q)
    fs = FacetParameterStates(cube)
    assert post.names == fs.names            # same state order
    np.testing.assert_array_equal(post.to_z(fs.p_nominal), fs.z0)
    np.testing.assert_array_equal(post.to_p(fs.z0 + 0.3), fs.to_p(fs.z0 + 0.3))


def test_layout_prior_mapping_and_dynamics(cube):
    """24 states for the 6-facet cube, kind-major; σ_z = 0.1 p₀ dz/dp = 0.1/(1−p₀) (logit),
    0.1 (ln) (§10.1 prior mapped by the transform's derivative); a Monte Carlo of the physical
    prior with a small fraction (1 %) has that z spread (linearisation check, 20 000 draws:
    sd error ≈ 0.5 % at 1σ); Φ = I, Q_d = q|Δt| I (eq. 8.39)."""
    fs = FacetParameterStates(cube)
    assert fs.dim == 24 and fs.names[0] == "xi[0]" and fs.names[6] == "a[0]" and fs.names[-1] == "A[5]"
    xi = cube.params[:, 0]
    np.testing.assert_allclose(fs.p_nominal[:6], xi)
    np.testing.assert_allclose(fs.p_nominal[18:], cube.areas_m2)
    np.testing.assert_allclose(fs.prior_sd_z[:6], 0.1 / (1 - xi), rtol=1e-12)
    np.testing.assert_allclose(fs.prior_sd_z[12:], 0.1, rtol=1e-12)
    np.testing.assert_allclose(fs.P0, np.diag(fs.prior_sd_z ** 2))
    small = FacetParameterStates(cube, prior_frac=0.01)
    rng = np.random.default_rng(1)
    draws = small.p_nominal + small.prior_sd_p * rng.standard_normal((20000, small.dim))
    sd = np.std(small.to_z(draws), axis=0)
    np.testing.assert_allclose(sd, small.prior_sd_z, rtol=0.03)
    # sigma_p maps back to the physical prior σ
    np.testing.assert_allclose(fs.sigma_p(fs.z0, fs.P0), fs.prior_sd_p, rtol=1e-12)
    Phi, Qd = FacetParameterStates(cube, process_noise=1e-4).transition(-5.0)
    np.testing.assert_array_equal(Phi, np.eye(24))
    np.testing.assert_allclose(Qd, 5e-4 * np.eye(24))
    sub = FacetParameterStates(cube, facets=[5, 0], kinds=("a", "xi"))
    assert sub.names == ["xi[0]", "xi[5]", "a[0]", "a[5]"]
    with pytest.raises(InputError):
        FacetParameterStates(cube, kinds=("xi", "q"))
    with pytest.raises(InputError):
        FacetParameterStates(cube, facets=[9])
    d = json.loads(json.dumps(fs.describe()))
    assert d["model"] == "model3" and len(d["prior_sigma_z"]) == 24


def test_per_state_magnitudes_against_apparent_magnitude(cube):
    """mag_states_nb with per-state facet arrays equals apparent_magnitude on the shape
    copy with p(z) (independent numpy path), and the filters' own kernel at z₀."""
    c = make_curve(n=10)
    mm = MagnitudeModel(cube, c)
    fs = FacetParameterStates(cube)
    rng = np.random.default_rng(2)
    Z = fs.z0 + 0.5 * rng.standard_normal((5, fs.dim)) * fs.prior_sd_z
    for k in (0, 4, 9):
        Q = np.repeat(c.truth_q[k][None, :], 5, axis=0)
        got = fs.magnitudes(mm, Q, Z, k)
        ref = [apparent_magnitude(fs.shape_at(Z[i]), c.truth_q[k][None, :],
                                  c.obj_to_sun_unit[k:k + 1], c.obj_to_obs_unit[k:k + 1],
                                  c.range_obs_m[k:k + 1], c.range_sun_m[k:k + 1])[0] for i in range(5)]
        np.testing.assert_allclose(got, np.ravel(ref), rtol=1e-12)
        np.testing.assert_allclose(fs.magnitudes(mm, c.truth_q[k:k + 1], fs.z0, k),
                                   mm.predict_q(c.truth_q[k:k + 1], k), rtol=1e-13)
    areas, params = fs.facet_arrays(Z)
    m2 = mag_states_nb(np.ascontiguousarray(np.repeat(c.truth_q[3][None], 5, 0)),
                       mm.s_eci[3], mm.o_eci[3], cube.normals_body, areas,
                       cube.model_ids.astype(np.int64), params, float(mm.offset[3]))
    np.testing.assert_allclose(m2, fs.magnitudes(mm, np.repeat(c.truth_q[3][None], 5, 0), Z, 3))


def test_partials_against_central_differences(cube):
    """∂m/∂z = ∂m/∂p · dp/dz (analytic photometry partials) and ∂m/∂δθ equal central finite
    differences of the per-state magnitude (step 1e-6) to 1e-6 relative."""
    c = make_curve(n=30)
    mm = MagnitudeModel(cube, c)
    fs = FacetParameterStates(cube)
    rng = np.random.default_rng(4)
    h = 1e-6
    checked = 0
    for k in range(0, 30, 3):
        z = fs.z0 + rng.standard_normal(fs.dim) * fs.prior_sd_z
        q = c.truth_q[k]
        m, dth, dz = fs.partials(mm, q, z, k)
        if not np.isfinite(m):
            continue
        assert m == pytest.approx(float(fs.magnitudes(mm, q[None], z, k)[0]), rel=1e-12)
        E = h * np.eye(fs.dim)
        Qs = np.repeat(q[None], 2 * fs.dim, axis=0)
        mz = fs.magnitudes(mm, Qs, np.concatenate([z + E, z - E]), k)
        fd = (mz[:fs.dim] - mz[fs.dim:]) / (2 * h)
        np.testing.assert_allclose(dz, fd, rtol=1e-6, atol=1e-8)
        d = np.concatenate([h * np.eye(3), -h * np.eye(3)])
        Qp = CR.perturb_rotvec_nb(np.ascontiguousarray(np.tile(q, (6, 1))), d)
        mq = fs.magnitudes(mm, Qp, z, k)
        np.testing.assert_allclose(dth, (mq[:3] - mq[3:]) / (2 * h), rtol=1e-6, atol=1e-8)
        checked += 1
        assert np.count_nonzero(dz) >= 4      # lit-and-visible facets carry information
    assert checked >= 8


@pytest.mark.parametrize("method", ["ukf", "mekf"])
def test_attitude_known_parameters_converge(pcurve, method):
    """§10.7-style parameter-only run on a perturbed-truth cube (attitude known): the strongly
    observable parameters (σ shrinking ≥ 2× — e.g. m and ξ of the glinting facets) end within
    3σ of the truth (all of them: at 3σ the chance of any of ~6 missing is ≈ 1.6 %), and m[1]
    (the −X facet's Beckmann slope, the brightest glint in this geometry) shrinks ≥ 5×;
    unobservable parameters (facets never lit and visible) keep their prior."""
    c, new = pcurve
    e = invert(c, method, reflection="model3", attitude="truth")
    assert not e.diverged and e.meta["attitude"] == "truth"
    tv = _truth(e.refl_names, new)
    prior = np.array(e.meta["reflection"]["prior_sigma_p"])
    shrink = prior / e.refl_p_sigma[-1]
    strong = shrink >= 2.0
    assert strong.sum() >= 3
    assert shrink[e.refl_names.index("m[1]")] >= 5.0
    err = np.abs(e.refl_p[-1] - tv) / e.refl_p_sigma[-1]
    assert np.all(err[strong] <= 3.0), dict(zip(np.array(e.refl_names)[strong], err[strong]))
    # the attitude is the truth: zero error, zero covariance
    assert np.max(np.abs(e.att_error_deg)) < 1e-9 and np.all(e.cov == 0)
    # innovations consistent with their predicted variance: mean NIS over 120 epochs in the
    # chi-square(120)/120 99.9 % band
    nis = e.innovations ** 2 / e.innovation_var
    n = np.isfinite(nis).sum()
    assert stats.chi2.ppf(0.0005, n) / n < np.nanmean(nis) < stats.chi2.ppf(0.9995, n) / n


def test_model3_with_attitude_and_hdf5_round_trip(pcurve, tmp_path):
    """Combined attitude + Model 3 (σθ = 3°): the UKF ends with the attitude inside 3σ; the
    z/p histories and 1σ survive the HDF5 round trip; p = p(z) and σ_p = |dp/dz| σ_z."""
    from lightcurve.filters.result import read_estimate

    c, _ = pcurve
    e = invert(c, "ukf", reflection="model3", sigma_theta_deg=3.0, seed=2)
    s = e.summary()
    assert s["inside_3sigma"] and not e.diverged
    fs = FacetParameterStates(load_shape("cube_1u_mixed"))
    np.testing.assert_allclose(e.refl_p, fs.to_p(e.refl_z), rtol=1e-12)
    np.testing.assert_allclose(e.refl_p_sigma, fs.jacobian(e.refl_z) * e.refl_z_sigma, rtol=1e-12)
    assert set(s["final_reflection"]) == set(fs.names)
    e.write(tmp_path / "e.h5")
    r = read_estimate(tmp_path / "e.h5")
    assert r.refl_names == e.refl_names
    for name in ("refl_z", "refl_z_sigma", "refl_p", "refl_p_sigma"):
        np.testing.assert_array_equal(getattr(r, name), getattr(e, name))
    assert r.meta["reflection"]["p_final"] == e.refl_p[-1].tolist()


def test_invert_refusals(pcurve):
    c, _ = pcurve
    with pytest.raises(InputError, match="nothing to estimate"):
        invert(c, "ukf", attitude="truth")
    with pytest.raises(InputError, match="attitude"):
        invert(c, "ukf", reflection="model3", attitude="guess")
    with pytest.raises(InputError, match="reflection"):
        invert(c, "ukf", reflection="model3", reflection_frac=0.0)


def test_cli_invert_model3_attitude_known(tmp_path, pcurve):
    """`lightcurve invert --reflection model3 [--attitude-known]` end to end on a small file."""
    from lightcurve.cli import main
    from lightcurve.filters.result import read_estimate

    c, _ = _perturbed_curve(n=30, dt=4.0)
    f = tmp_path / "m3.h5"
    c.write(f)
    out = tmp_path / "o"
    rc = main(["invert", str(f), "--method", "ukf", "--reflection", "model3", "--attitude-known",
               "-o", str(out)])
    assert rc == 0
    js = json.loads((out / "summary.json").read_text())
    est = read_estimate(js["m3"]["result"])
    assert est.meta["attitude"] == "truth" and est.refl_p.shape == (30, 24)
    assert js["m3"]["final_reflection"]["m[1]"]["sigma"] < js["m3"]["final_reflection"]["m[1]"]["prior_sigma"]
    rc = main(["invert", str(f), "--method", "mekf", "--reflection", "model3", "-o", str(out)])
    assert rc == 0
    rc = main(["invert", str(f), "--attitude-known", "-o", str(tmp_path / "o2")])
    assert rc == 2                          # nothing to estimate: InputError → exit 2


def test_cli_invert_model3_parameter_and_facet_selection(tmp_path):
    """`--reflection-params`, `--reflection-facets` and `--reflection-frac` reach Model 3: the
    state holds exactly the chosen kinds × facets (canonical kind order ξ, a, m, A), the prior σ
    follows the fraction (σ_p = frac · p₀ in the physical parameter, Bernard §10.1), and a bad
    list is rejected before anything is written (exit 2)."""
    from lightcurve.cli import main

    c, _ = _perturbed_curve(n=30, dt=4.0)
    f = tmp_path / "m3.h5"
    c.write(f)
    out = tmp_path / "o"
    rc = main(["invert", str(f), "--method", "ukf", "--reflection", "model3", "--attitude-known",
               "--reflection-params", "m,xi", "--reflection-facets", "0,2",
               "--reflection-frac", "0.2", "-o", str(out)])
    assert rc == 0
    fr = json.loads((out / "summary.json").read_text())["m3"]["final_reflection"]
    assert sorted(fr) == ["m[0]", "m[2]", "xi[0]", "xi[2]"]
    xi0 = load_shape("cube_1u_mixed").facet_params("xi")[0]      # 0.2 in shapes/cube_1u_mixed.toml
    assert fr["xi[0]"]["prior_sigma"] == pytest.approx(0.2 * xi0, rel=1e-9)
    for bad in (["--reflection-params", "xi,q"], ["--reflection-facets", "0,x"],
                ["--reflection-facets", "-1"]):
        o = tmp_path / f"bad{len(list(tmp_path.iterdir()))}"
        rc = main(["invert", str(f), "--method", "ukf", "--reflection", "model3",
                   "--attitude-known", *bad, "-o", str(o)])
        assert rc == 2, bad
        assert not (o / "m3.ukf.h5").exists()


def test_parameter_on_its_bound_is_held_fixed():
    """Table 9.2's −Z facet is fully diffuse (ξ = 1): no logit reaches 1, so Model 3 holds ξ[5]
    fixed (23 states, listed as held) and the §10.1 truth draw leaves it at 1, while every other
    parameter of the facet is estimated / perturbed."""
    cube = load_shape("cube_1u")
    assert cube.params[5, 0] == 1.0
    fs = FacetParameterStates(cube)
    assert fs.dim == 23 and "xi[5]" not in fs.names and fs.held == ["xi[5]"]
    assert {"a[5]", "m[5]", "A[5]"} <= set(fs.names) and np.all(np.isfinite(fs.z0))
    assert fs.describe()["held_fixed"] == ["xi[5]"]
    rng = np.random.default_rng(3)
    for _ in range(20):
        _, new = perturb_reflection(cube, rng)
        assert new["xi"][5] == 1.0 and new["a"][5] != cube.params[5, 1]
    with pytest.raises(InputError, match="bound"):
        FacetParameterStates(cube, facets=[5], kinds=("xi",))
