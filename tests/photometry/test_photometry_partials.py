"""Analytic magnitude partials vs central finite differences (1e-6 relative)."""

import numpy as np
import pytest

from lightcurve.photometry import AU_M, Material, Shape, load_shape, magnitude_partials, apparent_magnitude
from lightcurve.rotations import quat_mult, rotvec_to_quat

SEED = 11


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _geometry(rng, N, spread=0.6):
    """Random attitudes with Sun and observer within ~35° of each other (many lit facets,
    glints present), away from the kinks of max(·,0) by construction of the check below."""
    q = _unit(rng.normal(size=(N, 4)))
    s = _unit(rng.normal(size=(N, 3)))
    o = _unit(s + spread * rng.normal(size=(N, 3)))
    return q, s, o, rng.uniform(5e5, 3e6, N), np.full(N, AU_M)


def _away_from_kinks(shape, q, s, o, tol=1e-3):
    from lightcurve.rotations import quat_rotate

    sb, ob = quat_rotate(q, s), quat_rotate(q, o)
    ns, no = sb @ shape.normals_body.T, ob @ shape.normals_body.T
    return np.all((np.abs(ns) > tol) & (np.abs(no) > tol), axis=1)


def _check(fd, an, rel=1e-6):
    """|fd − an| ≤ rel·|an| + 1e-8. The absolute 1e-8 is the round-off floor of the FD
    reference (ε·|m|/h ≈ 2e-16 · 10 mag / 1e-5 ≈ 2e-10, with margin); the bulk of the
    entries are ≥ 1e-2 in size, where the 1e-6 relative bound is what is tested."""
    assert np.max(np.abs(an)) > 1e-2
    assert np.all(np.isfinite(an)) and np.all(np.isfinite(fd))
    np.testing.assert_allclose(fd, an, rtol=rel, atol=1e-8)


def _central(fun, h):
    """Fourth-order central difference (f(−2h) − 8f(−h) + 8f(h) − f(2h))/(12h): truncation
    O(h⁴), so the FD reference itself is good to ~1e-10 and a 1e-6 relative test is fair."""
    return (fun(-2 * h) - 8 * fun(-h) + 8 * fun(h) - fun(2 * h)) / (12 * h)


def _fd_theta(shape, q, s, o, ro, rs, h=1e-4):
    out = np.zeros((len(q), 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        # q = δq(δθ) ⊗ q̂  (body-frame error rotation)
        out[:, k] = _central(lambda t: apparent_magnitude(
            shape, quat_mult(rotvec_to_quat(t * e), q), s, o, ro, rs), h)
    return out


@pytest.mark.parametrize("name", ["cube_1u", "rocket_body"])
def test_cook_torrance_partials_vs_finite_differences(name):
    rng = np.random.default_rng(SEED)
    shape = load_shape(name)
    q, s, o, ro, rs = _geometry(rng, 40)
    keep = _away_from_kinks(shape, q, s, o)
    q, s, o, ro, rs = q[keep], s[keep], o[keep], ro[keep], rs[keep]
    d = magnitude_partials(shape, q, s, o, ro, rs)
    ok = np.isfinite(d.m)
    assert ok.sum() >= 15
    q, s, o, ro, rs = q[ok], s[ok], o[ok], ro[ok], rs[ok]
    d = magnitude_partials(shape, q, s, o, ro, rs)
    np.testing.assert_allclose(d.m, apparent_magnitude(shape, q, s, o, ro, rs), atol=1e-12)

    _check(_fd_theta(shape, q, s, o, ro, rs), d.dm_dtheta)

    F = shape.n_facets
    for pname, an in (("xi", d.dm_dxi), ("a", d.dm_da), ("m", d.dm_dm)):
        base = shape.facet_params(pname)
        fd = np.zeros_like(an)
        for i in range(F):
            e = np.zeros(F)
            e[i] = 1.0
            fd[:, i] = _central(lambda t: apparent_magnitude(
                shape.copy_with(check=False, **{pname: base + t * e}), q, s, o, ro, rs),
                1e-4 * base[i])
        _check(fd, an)

    fd = np.zeros_like(d.dm_dA)
    for i in range(F):
        e = np.zeros(F)
        e[i] = 1.0
        fd[:, i] = _central(lambda t: apparent_magnitude(
            shape.copy_with(areas_m2=shape.areas_m2 + t * e), q, s, o, ro, rs), 1e-4 * shape.areas_m2[i])
    _check(fd, d.dm_dA)


def test_specular_glint_attitude_partial():
    # Near a glint of the +X facet the attitude partial is large and must still match FD.
    shape = load_shape("cube_1u")
    s = _unit(np.array([[1.0, 0.3, 0.05]]))
    o = _unit(np.array([[1.0, -0.28, 0.08]]))
    q = np.array([[1.0, 0.0, 0.0, 0.0]])
    d = magnitude_partials(shape, q, s, o, [1e6], [AU_M])
    fd = _fd_theta(shape, q, s, o, [1e6], [AU_M])
    assert np.max(np.abs(d.dm_dtheta)) > 1.0  # mag/rad: a strong, non-trivial derivative
    _check(fd, d.dm_dtheta)


def test_phong_lambert_and_fallback_attitude_partials():
    # Phong (Starlink) and Lambert are analytic; Ashikhmin–Shirley goes through the
    # documented finite-difference fallback — all three must agree with FD of the magnitude.
    rng = np.random.default_rng(SEED + 1)
    base = load_shape("rocket_body")
    mats = [Material.create("p", "phong", Kd=0.2, Ks=0.5, n=7.5),
            Material.create("l", "lambert", albedo=0.4),
            Material.create("as", "ashikhmin_shirley", Rd=0.3, Rs=0.2, nu=30.0, nv=8.0)]
    shape = Shape("mix", base.areas_m2, base.normals_body, base.centers_body_m,
                  [mats[i % 3] for i in range(base.n_facets)], 1.0, np.eye(3))
    q, s, o, ro, rs = _geometry(rng, 30)
    keep = _away_from_kinks(shape, q, s, o)
    q, s, o, ro, rs = q[keep], s[keep], o[keep], ro[keep], rs[keep]
    d = magnitude_partials(shape, q, s, o, ro, rs)
    ok = np.isfinite(d.m)
    q, s, o, ro, rs = q[ok], s[ok], o[ok], ro[ok], rs[ok]
    d = magnitude_partials(shape, q, s, o, ro, rs)
    fd = _fd_theta(shape, q, s, o, ro, rs)
    # the fallback is itself a FD (step 1e-6): allow 1e-5 relative for the mixed shape
    _check(fd, d.dm_dtheta, rel=1e-5)
    assert np.all(np.isnan(d.dm_dxi))  # no Cook–Torrance facet: CT partials are NaN


def test_partials_with_states_axis_and_invisible():
    shape = load_shape("cube_1u")
    rng = np.random.default_rng(SEED + 2)
    q = _unit(rng.normal(size=(4, 3, 4)))
    s = _unit(rng.normal(size=(4, 3)))
    o = s.copy()
    d = magnitude_partials(shape, q, s, o, np.full(4, 1e6), np.full(4, AU_M))
    assert d.m.shape == (4, 3) and d.dm_dtheta.shape == (4, 3, 3) and d.dm_dA.shape == (4, 3, 6)
    for j in range(3):
        dj = magnitude_partials(shape, q[:, j], s, o, np.full(4, 1e6), np.full(4, AU_M))
        np.testing.assert_allclose(d.dm_dtheta[:, j], dj.dm_dtheta, rtol=1e-12, atol=1e-15)
    # Sun behind the observer-facing hemisphere of a single facet: m = inf, partials NaN
    one = Shape("one", [1.0], [[0, 0, 1.0]], [[0, 0, 0.0]],
                [Material.create("c", "cook_torrance", xi=0.5, a=0.5, m=0.3)], 1.0, np.eye(3))
    d = magnitude_partials(one, [[1.0, 0, 0, 0]], [[0, 0, -1.0]], [[0, 0, 1.0]], [1e6], [AU_M])
    assert np.isposinf(d.m[0]) and np.all(np.isnan(d.dm_dtheta))


def test_blocked_evaluation_equals_single_block(monkeypatch):
    from lightcurve.photometry import partials as P

    shape = load_shape("rocket_body")
    rng = np.random.default_rng(SEED + 3)
    q, s, o, ro, rs = _geometry(rng, 25)
    full = magnitude_partials(shape, q, s, o, ro, rs)
    monkeypatch.setattr(P, "_CHUNK_ELEMENTS", 12 * 4)  # 4 epochs per block
    blk = magnitude_partials(shape, q, s, o, ro, rs)
    for f in ("m", "dm_dA", "dm_dxi", "dm_da", "dm_dm", "dm_dtheta"):
        np.testing.assert_allclose(getattr(blk, f), getattr(full, f), rtol=1e-12, atol=1e-15)
