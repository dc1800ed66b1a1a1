"""Model 3 speed path: the one-pass numba partials and the scalar Joseph kernel of the MEKF
give the numbers of the NumPy path (the oracle: the NumPy algebra of tests/partials_oracle.py on a
shape copy, and :func:`lightcurve.estimation.joseph_update`) to ≤ 1e-10 relative, and the
Jacobians they return equal central finite differences to 1e-6 relative.

"Relative" for a vector or matrix quantity is norm-wise: ``max|new − old| ≤ 1e-10 · max|old|``
over the quantity at one epoch (per-element relative errors are meaningless for components
that vanish by cancellation, e.g. a ∂m/∂δθ component ≈ 0). Equivalence, not timing.
"""

from __future__ import annotations

import numpy as np
import pytest
from filters_synth import make_curve

from lightcurve.estimation.kalman import joseph_update
from lightcurve.filters import mekf as mekf_mod
from lightcurve.filters.facet_states import FacetParameterStates, mag_states_nb
from lightcurve.filters.invert import invert
from lightcurve.filters.models import MagnitudeModel
from lightcurve.photometry import AU_M, Material, Shape, apparent_magnitude, load_shape
from lightcurve.core.photometry import magnitude_partials_q_nb
from lightcurve.photometry.partials import MagnitudePartials, kernel_capable, magnitude_partials
from partials_oracle import magnitude_partials_numpy
from lightcurve.rotations import quat_mult, quat_rotate, rotvec_to_quat

REL = 1e-10


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _close(new, old, rel=REL, what=""):
    """Norm-wise relative closeness (module docstring) with identical NaN/inf patterns."""
    new, old = np.asarray(new, float), np.asarray(old, float)
    assert new.shape == old.shape, what
    np.testing.assert_array_equal(np.isnan(new), np.isnan(old), err_msg=what)
    np.testing.assert_array_equal(np.isinf(new), np.isinf(old), err_msg=what)
    fin = np.isfinite(old)
    if not fin.any():
        return
    scale = np.max(np.abs(old[fin]))
    err = np.max(np.abs(new[fin] - old[fin]))
    assert err <= rel * scale, f"{what}: max |Δ| {err:.3g} > {rel:g} × {scale:.3g}"


def _mixed_phong_lambert_ct():
    """rocket_body geometry (12 facets) with Phong, Lambert and Cook–Torrance facets."""
    base = load_shape("rocket_body")
    mats = [Material.create("p", "phong", Kd=0.2, Ks=0.5, n=7.5),
            Material.create("l", "lambert", albedo=0.4),
            Material.create("c", "cook_torrance", xi=0.3, a=0.6, m=0.25)]
    return Shape("mix3", base.areas_m2, base.normals_body, base.centers_body_m,
                 [mats[i % 3] for i in range(base.n_facets)], 1.0, np.eye(3))


SHAPES = ["cube_1u", "cube_geo", "box_wing", "rocket_body", "starlink_v15", "mix3"]


def _shape(name):
    return _mixed_phong_lambert_ct() if name == "mix3" else load_shape(name)


# --------------------------------------------------------------------------------------------
# photometry kernel vs the NumPy partials (oracle) and finite differences
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", SHAPES)
def test_numba_partials_equal_numpy_partials(name):
    """magnitude_partials: the one-pass kernel (backend numba) equals the NumPy algebra on
    500 random geometries (Sun and observer within ~35°: many lit facets and glints) and on
    a (N,S,4) batch — every field, NaN pattern included (NaN ∂m/∂ξ of non-CT facets)."""
    shape = _shape(name)
    assert kernel_capable(shape.model_ids)
    rng = np.random.default_rng(21)
    N = 500
    q = _unit(rng.normal(size=(N, 4)))
    s = _unit(rng.normal(size=(N, 3)))
    o = _unit(s + 0.6 * rng.normal(size=(N, 3)))
    ro, rs = rng.uniform(5e5, 4e7, N), np.full(N, AU_M)
    a = magnitude_partials_numpy(shape, q, s, o, ro, rs)
    b = magnitude_partials(shape, q, s, o, ro, rs)
    assert np.isfinite(a.m).sum() > 200 and np.isinf(a.m).sum() > 0   # both regimes occur
    for f in MagnitudePartials.__dataclass_fields__:
        x, y = getattr(b, f), getattr(a, f)
        for i in range(N):
            _close(x[i], y[i], what=f"{name} {f} row {i}")
    # states axis (N,S,4)
    q3 = _unit(rng.normal(size=(20, 3, 4)))
    a3 = magnitude_partials_numpy(shape, q3, s[:20], o[:20], ro[:20], rs[:20])
    b3 = magnitude_partials(shape, q3, s[:20], o[:20], ro[:20], rs[:20])
    assert b3.dm_dtheta.shape == (20, 3, 3)
    for f in MagnitudePartials.__dataclass_fields__:
        x, y = getattr(b3, f), getattr(a3, f)
        for i in range(20):
            for j in range(3):
                _close(x[i, j], y[i, j], what=f"{name} {f} [{i},{j}]")


def test_brdfs_without_analytic_partials_use_finite_differences():
    """Ashikhmin–Shirley has no analytic partials: its attitude partial is the central finite
    difference of the NumPy oracle, mixed shapes combine both (analytic facets by the kernel)."""
    base = load_shape("cube_1u")
    mat = Material.create("as", "ashikhmin_shirley", Rd=0.3, Rs=0.2, nu=30.0, nv=8.0)
    sh = Shape("as", base.areas_m2, base.normals_body, base.centers_body_m,
               [mat] * base.n_facets, 1.0, np.eye(3))
    assert not kernel_capable(sh.model_ids)
    q, s, o = np.array([[1.0, 0, 0, 0]]), _unit(np.array([[1.0, 0.4, 0.3]])), \
        _unit(np.array([[1.0, -0.3, 0.5]]))
    a = magnitude_partials(sh, q, s, o, [1e6], [AU_M])
    b = magnitude_partials_numpy(sh, q, s, o, [1e6], [AU_M])
    np.testing.assert_allclose(a.dm_dtheta, b.dm_dtheta, rtol=1e-9)
    assert np.all(np.isnan(a.dm_dxi))
    mixed = Shape("mix", base.areas_m2, base.normals_body, base.centers_body_m,
                  [mat if i % 2 else base.materials[i] for i in range(base.n_facets)], 1.0,
                  np.eye(3))
    qs = _unit(np.random.default_rng(4).normal(size=(30, 4)))
    ss, oo = np.repeat(s, 30, 0), np.repeat(o, 30, 0)
    a = magnitude_partials(mixed, qs, ss, oo, np.full(30, 1e6), np.full(30, AU_M))
    b = magnitude_partials_numpy(mixed, qs, ss, oo, np.full(30, 1e6), np.full(30, AU_M))
    for f in MagnitudePartials.__dataclass_fields__:
        for i in range(30):
            _close(getattr(a, f)[i], getattr(b, f)[i], rel=1e-8, what=f"mixed {f} row {i}")


def _central4(fun, h):
    """Fourth-order central difference (truncation O(h⁴)): a fair 1e-6 reference."""
    return (fun(-2 * h) - 8 * fun(-h) + 8 * fun(h) - fun(2 * h)) / (12 * h)


@pytest.mark.parametrize("name", ["cube_1u", "starlink_v15", "mix3"])
def test_single_attitude_kernel_against_finite_differences(name):
    """magnitude_partials_q_nb (the MEKF's attitude-only path): m equals apparent_magnitude
    (independent NumPy photometry) to 1e-12; ∂m/∂δθ for q = δq(δθ) ⊗ q̂, ∂m/∂A, ∂m/∂ξ, ∂m/∂a,
    ∂m/∂m equal 4th-order central differences of apparent_magnitude to 1e-6 relative
    (+1e-8 mag absolute round-off floor). Covers Cook–Torrance, Phong and Lambert facets."""
    shape = _shape(name)
    n, A, ids, prm = shape.kernel_arrays()
    n, A, prm = (np.ascontiguousarray(x, dtype=float) for x in (n, A, prm))
    ids = np.ascontiguousarray(ids, dtype=np.int64)
    F = shape.n_facets
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(60):
        q = _unit(rng.normal(size=4))
        s = _unit(rng.normal(size=3))
        o = _unit(s + 0.6 * rng.normal(size=3))
        ro, rs = 2e6, 1.01 * AU_M
        # stay away from the kinks of max(·,0) and of G = min(1, g1, g2) (one-sided
        # derivatives there; the FD stencil spans ±2e-4 rad, g changes O(1) per rad)
        sb, ob = quat_rotate(q, s), quat_rotate(q, o)
        ns, no = shape.normals_body @ sb, shape.normals_body @ ob
        if np.any(np.abs(ns) < 1e-3) or np.any(np.abs(no) < 1e-3):
            continue
        hh = _unit(sb + ob)
        nh, cc = shape.normals_body @ hh, ob @ hh
        g1, g2 = 2 * nh * no / cc, 2 * nh * ns / cc
        vis = (ns > 0) & (no > 0) & (ids == 1)
        if np.any(vis & ((np.abs(g1 - 1) < 1e-2) | (np.abs(g2 - 1) < 1e-2)
                         | (np.abs(g1 - g2) < 1e-2))):
            continue
        offset = -26.74 + 5 * np.log10(ro) + 5 * np.log10(rs / AU_M)
        dA, dxi, da, dmm = (np.empty(F) for _ in range(4))
        m, tx, ty, tz = magnitude_partials_q_nb(q, s, o, n, A, ids, prm, offset, dA, dxi, da, dmm)
        def mag(sh, qq=q, s=s, o=o):
            return apparent_magnitude(sh, qq[None], s[None], o[None], [ro], [rs])[0]

        if not np.isfinite(m):
            assert np.isinf(mag(shape))
            continue
        assert m == pytest.approx(mag(shape), rel=1e-12)
        fd = np.array([_central4(lambda t, e=e: mag(shape, quat_mult(rotvec_to_quat(t * e), q)),
                                 1e-4) for e in np.eye(3)])
        np.testing.assert_allclose([tx, ty, tz], fd, rtol=1e-6, atol=1e-8)
        fdA = np.array([_central4(lambda t, i=i: mag(shape.copy_with(
            areas_m2=A + t * np.eye(F)[i])), 1e-4 * A[i]) for i in range(F)])
        np.testing.assert_allclose(dA, fdA, rtol=1e-6, atol=1e-8)
        ct = ids == 1
        for col, pname, got in ((0, "xi", dxi), (1, "a", da), (2, "m", dmm)):
            assert np.all(np.isnan(got[~ct]))
            if not ct.any():
                continue
            base = shape.facet_params(pname)
            fdp = np.array([_central4(lambda t, i=i: mag(shape.copy_with(
                check=False, **{pname: base + t * np.eye(F)[i]})), 1e-4 * base[i])
                for i in np.flatnonzero(ct)])
            np.testing.assert_allclose(got[ct], fdp, rtol=1e-6, atol=1e-8)
        checked += 1
    assert checked >= 15


def test_facet_state_kernel_equals_numpy_partials():
    """FacetParameterStates.partials (one-pass kernel from plain arrays, no shape copy)
    equals partials_numpy (magnitude_partials on shape_at(z), the NumPy reference formula) to
    1e-10 at 60 random (q, z) with z spread over ±2σ of the prior; ∂m/∂z also equals
    central differences of the per-state magnitude (1e-6 relative)."""
    c = make_curve(n=30)
    cube = load_shape("cube_1u")
    mm = MagnitudeModel(cube, c)
    fs = FacetParameterStates(cube)
    rng = np.random.default_rng(8)
    h = 1e-6
    for j in range(60):
        k = j % 30
        z = fs.z0 + 2.0 * rng.uniform(-1, 1, fs.dim) * fs.prior_sd_z
        q = _unit(c.truth_q[k] + 0.05 * rng.normal(size=4))
        m1, th1, dz1 = fs.partials(mm, q, z, k)
        m0, th0, dz0 = fs.partials_numpy(mm, q, z, k)
        _close(m1, m0, what="m")
        _close(th1, th0, what="dm/dtheta")
        _close(dz1, dz0, what="dm/dz")
        if np.isfinite(m1) and j % 6 == 0:
            E = h * np.eye(fs.dim)
            mz = fs.magnitudes(mm, np.repeat(q[None], 2 * fs.dim, 0),
                               np.concatenate([z + E, z - E]), k)
            np.testing.assert_allclose(dz1, (mz[:fs.dim] - mz[fs.dim:]) / (2 * h),
                                       rtol=1e-6, atol=1e-8)
    # a subset of the states and kinds (other layout) goes through the same kernel
    fs2 = FacetParameterStates(cube, facets=[0, 4], kinds=("m", "xi"))
    z = fs2.z0 + 0.3
    for k in range(0, 30, 5):
        a, b = fs2.partials(mm, c.truth_q[k], z, k), fs2.partials_numpy(mm, c.truth_q[k], z, k)
        for x, y in zip(a, b):
            _close(x, y)


def _old_magnitudes(self, model, Q, Z, k):
    """Oracle FacetParameterStates.magnitudes (NumPy facet-array path): NumPy per-state facet
    arrays (facet_arrays) + mag_states_nb."""
    Q = np.ascontiguousarray(np.asarray(Q, float).reshape(-1, 4))
    Z = np.atleast_2d(np.asarray(Z, float))
    if Z.shape[0] == 1 and Q.shape[0] > 1:
        Z = np.repeat(Z, Q.shape[0], axis=0)
    areas, params = self.facet_arrays(Z)
    return mag_states_nb(Q, model.s_eci[k], model.o_eci[k], self.shape.normals_body, areas,
                         self.shape.model_ids.astype(np.int64), params, float(model.offset[k]))


def test_per_state_magnitude_kernel_equals_facet_array_path():
    """magnitudes() (facet arrays filled inside mag_z_states_nb) equals the NumPy facet-array
    path (facet_arrays in NumPy + mag_states_nb) to 1e-12 relative for 61 sigma-point-like states
    (z up to ±3σ) at every epoch, and one shared z broadcast over attitudes."""
    c = make_curve(n=20)
    cube = load_shape("cube_1u")
    mm = MagnitudeModel(cube, c)
    fs = FacetParameterStates(cube)
    rng = np.random.default_rng(9)
    for k in range(20):
        Z = fs.z0 + 3.0 * rng.uniform(-1, 1, (61, fs.dim)) * fs.prior_sd_z
        Q = _unit(c.truth_q[k] + 0.05 * rng.normal(size=(61, 4)))
        new, old = fs.magnitudes(mm, Q, Z, k), _old_magnitudes(fs, mm, Q, Z, k)
        np.testing.assert_array_equal(np.isinf(new), np.isinf(old))
        f = np.isfinite(old)
        np.testing.assert_allclose(new[f], old[f], rtol=1e-12)
        np.testing.assert_allclose(fs.magnitudes(mm, Q, Z[0], k),
                                   _old_magnitudes(fs, mm, Q, Z[0], k), rtol=1e-12)


def test_ukf_model3_equals_old_magnitude_path(m3curve, monkeypatch):
    """The UKF with Model 3 (which calls magnitudes() for its sigma points) reproduces the
    run with the NumPy facet-array magnitudes (monkeypatched oracle) to ≤ 1e-10 relative."""
    c = m3curve
    new = invert(c, "ukf", seed=4, reflection="model3", sigma_theta_deg=3.0)
    with monkeypatch.context() as mp:
        mp.setattr(FacetParameterStates, "magnitudes", _old_magnitudes)
        old = invert(c, "ukf", seed=4, reflection="model3", sigma_theta_deg=3.0)
    assert np.isfinite(new.innovations).sum() >= 60
    _compare_estimates(new, old, c.mag)


# --------------------------------------------------------------------------------------------
# the scalar Joseph kernel vs estimation.joseph_update
# --------------------------------------------------------------------------------------------

def test_scalar_joseph_kernel_equals_joseph_update():
    """joseph_scalar_nb equals joseph_update (two triangular solves, full (I−KH)P(I−KH)ᵀ +
    KRKᵀ) to 1e-12 relative for random SPD P of sizes 6–31, sparse and dense H; the failure
    statuses match joseph_update's refusals (S ≤ 0, non-finite ν)."""
    rng = np.random.default_rng(3)
    for n in (6, 7, 30, 31):
        for trial in range(20):
            G = rng.normal(size=(n, n)) * rng.uniform(1e-4, 1.0, n)
            P = G @ G.T + 1e-9 * np.eye(n)
            H = rng.normal(size=n) * 50.0
            if trial % 2:
                H[rng.random(n) < 0.6] = 0.0
            R = rng.uniform(1e-5, 1e-3)
            y, yhat = 10.0 + rng.normal() * 0.05, 10.0
            dx, Pn, nu, S, ok = mekf_mod._update(P, H, R, y, yhat)
            x0, P0, info = joseph_update(np.zeros(n), P, y, H[None, :], R, h=yhat)
            assert ok and info.ok
            _close(dx, x0, rel=1e-12, what="dx")
            _close(Pn, P0, rel=1e-12, what="P+")
            assert nu == info.innovation[0] and S == pytest.approx(info.S[0, 0], rel=1e-14)
            np.testing.assert_array_equal(Pn, Pn.T)
    P = np.eye(3)
    _, _, _, S, ok = mekf_mod._update(P, np.zeros(3), -1e-3, 1.0, 0.0)
    assert not ok and not joseph_update(np.zeros(3), P, 1.0, np.zeros((1, 3)), -1e-3, h=0.0)[2].ok
    dx, Pn = np.empty(3), np.empty((3, 3))
    assert mekf_mod.joseph_scalar_nb(P, np.ones(3), 1e-3, np.nan, dx, Pn)[1] == 1
    assert mekf_mod.joseph_scalar_nb(P, np.array([np.inf, 0, 0]), 1e-3, 0.1, dx, Pn)[1] == 2


# --------------------------------------------------------------------------------------------
# whole filter runs: new MEKF vs the old formulas (monkeypatched oracle)
# --------------------------------------------------------------------------------------------

def _old_update(P, h, R, y, yhat):
    """Oracle update: estimation.joseph_update from a zero error state."""
    dx, Pn, info = joseph_update(np.zeros(P.shape[0]), P, y, h[None, :], R, h=yhat)
    return dx, Pn, float(info.innovation[0]), float(info.S[0, 0]), info.ok


def _old_predict(m, facets, q, z, k, jacobian, ph=None, h=1e-6):
    """Oracle prediction: magnitude kernel + NumPy partials, or partials on shape_at(z)."""
    if facets is None:
        yhat = float(m.predict_q(q[None, :], k)[0])
        if not np.isfinite(yhat):
            return yhat, np.full(3, np.nan), np.zeros(0)
        with np.errstate(divide="ignore", invalid="ignore"):
            mp = magnitude_partials(m.shape, q[None, :], m.s_eci[k:k + 1], m.o_eci[k:k + 1],
                                    m.range_obs[k:k + 1], m.range_sun[k:k + 1],
                                    sun_mag=m.sun_mag)
        return yhat, np.asarray(mp.dm_dtheta, float).reshape(3), np.zeros(0)
    return facets.partials_numpy(m, q, z, k)


def _old_reset(q, dth, error):
    from lightcurve.filters._common import grp_to_dq

    dq = grp_to_dq(dth)[0]
    qn = quat_mult(dq, q)
    return qn / np.linalg.norm(qn)


def _compare_estimates(new, old, y, rel=REL):
    np.testing.assert_array_equal(new.flags, old.flags)
    assert new.diverged == old.diverged
    for k in range(len(new.t)):
        _close(new.q[k], old.q[k], rel, what=f"q[{k}]")
        _close(new.omega_rad_s[k], old.omega_rad_s[k], rel, what=f"omega[{k}]")
        _close(new.cov[k], old.cov[k], rel, what=f"P[{k}]")
        if new.refl_z is not None:
            _close(new.refl_z[k], old.refl_z[k], rel, what=f"z[{k}]")
            _close(new.refl_z_sigma[k], old.refl_z_sigma[k], rel, what=f"z sigma[{k}]")
            _close(new.refl_p[k], old.refl_p[k], rel, what=f"p[{k}]")
        if new.bias is not None:
            _close(new.bias[k], old.bias[k], rel, what=f"b[{k}]")
            _close(new.bias_sigma[k], old.bias_sigma[k], rel, what=f"b sigma[{k}]")
    # predicted magnitudes ŷ = y − ν (relative to the magnitude) and the innovations
    ok = np.isfinite(old.innovations)
    np.testing.assert_array_equal(np.isfinite(new.innovations), ok)
    y = np.asarray(y, float)
    yh_new, yh_old = y[ok] - new.innovations[ok], y[ok] - old.innovations[ok]
    assert np.max(np.abs(yh_new - yh_old) / np.abs(yh_old)) <= rel
    _close(new.innovations[ok], old.innovations[ok], rel=100 * rel, what="innovations")
    _close(new.innovation_var[ok], old.innovation_var[ok], rel, what="S")


@pytest.fixture(scope="module")
def m3curve():
    """make_curve's geometry/attitude with magnitudes of a 10 %-perturbed cube (§10.1)."""
    from lightcurve.studies.fit_reflection import perturb_reflection

    c = make_curve(n=80, dt=2.0)
    sh = load_shape("cube_1u")
    pert, _ = perturb_reflection(sh, np.random.default_rng(5))
    m = apparent_magnitude(pert, c.truth_q, c.obj_to_sun_unit, c.obj_to_obs_unit,
                           c.range_obs_m, c.range_sun_m)
    c.truth_mag = m
    c.mag = m + c.mag_sigma * np.random.default_rng(3).standard_normal(len(m))
    return c


@pytest.mark.parametrize("case", [
    dict(reflection="none"),
    dict(reflection="model1"),
    dict(reflection="model3"),
    dict(reflection="model3", attitude="truth"),
    dict(reflection="model3", error="small_angle"),
])
def test_mekf_new_path_equals_old_formulas(m3curve, monkeypatch, case):
    """The MEKF (numba partials + scalar Joseph kernel) reproduces the oracle MEKF (NumPy
    partials on a shape copy + estimation.joseph_update, monkeypatched in as the oracle) over
    80 epochs: attitude, rate, covariance, bias / Model 3 states and their σ, predicted
    magnitudes all to ≤ 1e-10 relative; identical flags. The new path never copies the shape."""
    c = m3curve
    kw = dict(seed=4, sigma_theta_deg=3.0, **case)
    with monkeypatch.context() as mp:
        # the new path must not build per-state shape copies or facet arrays
        def boom(*a, **k):
            raise AssertionError("shape copy on the fast path")
        mp.setattr(FacetParameterStates, "shape_at", boom)
        mp.setattr(FacetParameterStates, "facet_arrays", boom)
        new = invert(c, "mekf", **kw)
    with monkeypatch.context() as mp:
        mp.setattr(mekf_mod, "_update", _old_update)
        mp.setattr(mekf_mod, "_predict", _old_predict)
        if case.get("error", "grp") == "grp":
            mp.setattr(mekf_mod, "_reset", _old_reset)
        old = invert(c, "mekf", **kw)
    assert np.isfinite(new.innovations).sum() >= 60
    _compare_estimates(new, old, c.mag)


def test_mekf_numeric_jacobian_path_unchanged(m3curve, monkeypatch):
    """jacobian="numeric" (central differences) keeps its own path; only the update kernel
    changed: equal to the joseph_update oracle to 1e-7 (Model 3, 80 epochs). The bound is
    looser than the analytic path's 1e-10 on purpose: the FD Jacobian (step h = 1e-6 in δθ
    and in z) amplifies the last-bit differences of q, z between the two (algebraically
    equal) update formulas by ≈ |m|/h, i.e. ≈ 2e-16·10/1e-6 = 2e-9 relative per epoch, the
    FD Jacobian's own round-off level (measured worst over the run: q 2e-10, P 2e-9, σ_z
    1.6e-8; the analytic path of the same run agrees to 3e-14)."""
    c = m3curve
    new = invert(c, "mekf", seed=4, reflection="model3", jacobian="numeric")
    with monkeypatch.context() as mp:
        mp.setattr(mekf_mod, "_update", _old_update)
        old = invert(c, "mekf", seed=4, reflection="model3", jacobian="numeric")
    _compare_estimates(new, old, c.mag, rel=1e-7)
