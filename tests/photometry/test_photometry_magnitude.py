"""Apparent magnitude: independent plain-numpy re-implementation, shapes of inputs, invisibility,
mixed kernel/numpy BRDFs, noise model."""

import math

import numpy as np
import pytest

from lightcurve.photometry import (AU_M, Material, Shape, add_noise, apparent_magnitude, get_brdf,
                                   load_shape, magnitude_sigma, register_brdf, unregister_brdf)

SEED = 7


def _rand_quats(rng, shape):
    q = rng.normal(size=shape + (4,))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _rand_units(rng, shape):
    v = rng.normal(size=shape + (3,))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _dcm_bernard(q):
    """A(q) of Bernard eq. 3.16 (scalar first q = [q1, q2, q3, q4], inertial→body), written out."""
    q1, q2, q3, q4 = q
    return np.array([
        [q1**2 + q2**2 - q3**2 - q4**2, 2 * (q2 * q3 + q1 * q4), 2 * (q2 * q4 - q1 * q3)],
        [2 * (q2 * q3 - q1 * q4), q1**2 - q2**2 + q3**2 - q4**2, 2 * (q3 * q4 + q1 * q2)],
        [2 * (q2 * q4 + q1 * q3), 2 * (q3 * q4 - q1 * q2), q1**2 - q2**2 - q3**2 + q4**2],
    ])


def _reference_magnitude(shape, q, s_eci, o_eci, r_obs, r_sun):
    """Plain-numpy, per-epoch loop: DESIGN.md's magnitude equation with Cook–Torrance facets."""
    out = []
    for k in range(len(q)):
        A = _dcm_bernard(q[k])
        s = A @ s_eci[k]
        o = A @ o_eci[k]
        total = 0.0
        for i in range(shape.n_facets):
            n = shape.normals_body[i]
            ns, no = n @ s, n @ o
            if ns <= 0 or no <= 0:
                continue
            xi, a, m = (shape.materials[i].params[x] for x in ("xi", "a", "m"))
            h = (s + o) / np.linalg.norm(s + o)
            cosa = n @ h
            c = o @ h
            D = math.exp(-(1 - cosa**2) / (cosa**2 * m * m)) / (math.pi * m * m * cosa**4)
            G = min(1.0, 2 * cosa * no / c, 2 * cosa * ns / c)
            nr = (1 + math.sqrt(a)) / (1 - math.sqrt(a))
            g = math.sqrt(nr * nr + c * c - 1)
            F = 0.5 * ((g - c) / (g + c)) ** 2 * (1 + ((c * (g + c) - 1) / (c * (g - c) + 1)) ** 2)
            fr = xi * a / math.pi + (1 - xi) * F * D * G / (4 * ns * no)
            total += shape.areas_m2[i] * ns * no * fr
        out.append(-26.74 - 2.5 * math.log10(total / r_obs[k] ** 2) + 5 * math.log10(r_sun[k] / AU_M)
                   if total > 0 else math.inf)
    return np.array(out)


@pytest.mark.parametrize("name", ["cube_1u", "rocket_body", "box_wing"])
def test_magnitude_matches_independent_numpy(name):
    rng = np.random.default_rng(SEED)
    shape = load_shape(name)
    N = 60
    q = _rand_quats(rng, (N,))
    s = _rand_units(rng, (N,))
    o = _rand_units(rng, (N,))
    r_obs = rng.uniform(5e5, 4e7, N)
    r_sun = rng.uniform(0.98, 1.02, N) * AU_M
    got = apparent_magnitude(shape, q, s, o, r_obs, r_sun)
    ref = _reference_magnitude(shape, q, s, o, r_obs, r_sun)
    fin = np.isfinite(ref)
    assert fin.sum() > N // 2
    np.testing.assert_array_equal(np.isfinite(got), fin)
    np.testing.assert_allclose(got[fin], ref[fin], rtol=0, atol=1e-9)


def test_states_axis_and_invariance():
    rng = np.random.default_rng(SEED + 1)
    shape = load_shape("cube_1u")
    N, S = 8, 5
    q = _rand_quats(rng, (N, S))
    s = _rand_units(rng, (N,))
    o = _rand_units(rng, (N,))
    r = np.full(N, 1e6)
    rs = np.full(N, AU_M)
    m = apparent_magnitude(shape, q, s, o, r, rs)
    assert m.shape == (N, S)
    for j in range(S):
        np.testing.assert_allclose(m[:, j], apparent_magnitude(shape, q[:, j], s, o, r, rs), atol=1e-12)
    # q and −q are the same attitude
    np.testing.assert_allclose(apparent_magnitude(shape, -q[:, 0], s, o, r, rs), m[:, 0], atol=1e-12)


def test_invisible_object_is_plus_infinity():
    # A single facet facing +Z lit from −Z: zero flux → m = +inf (documented).
    mat = Material.create("w", "lambert", albedo=0.5)
    shape = Shape("one", [1.0], [[0, 0, 1.0]], [[0, 0, 0.0]], [mat], 1.0, np.eye(3))
    m = apparent_magnitude(shape, [[1.0, 0, 0, 0]] * 2, [[0, 0, -1.0], [0, 0, 1.0]],
                           [[0, 0, 1.0], [0, 0, -1.0]], [1e6, 1e6], [AU_M, AU_M])
    assert np.all(np.isposinf(m))


def test_bad_direction_inputs():
    shape = load_shape("cube_1u")
    with pytest.raises(ValueError, match="unit"):
        apparent_magnitude(shape, [[1.0, 0, 0, 0]], [[2.0, 0, 0]], [[1.0, 0, 0]], [1e6], [AU_M])
    with pytest.raises(ValueError, match="positive"):
        apparent_magnitude(shape, [[1.0, 0, 0, 0]], [[1.0, 0, 0]], [[1.0, 0, 0]], [-1.0], [AU_M])


def test_numpy_brdf_path_equals_kernel_path():
    # A user BRDF identical to Lambert must give the kernel's Lambert magnitudes exactly
    # (checks the numpy evaluation path used for tabulated and user models).
    try:
        @register_brdf("test_user_lambert")
        def ul(n, s, o, *, albedo=0.5):
            shape = np.broadcast_shapes(n.shape, s.shape, o.shape)[:-1]
            return np.broadcast_to(np.asarray(albedo) / np.pi, shape)

        rng = np.random.default_rng(SEED + 2)
        base = load_shape("rocket_body")
        lam = Material.create("l", "lambert", albedo=0.4)
        usr = Material.create("u", "test_user_lambert", albedo=0.4)
        mk = lambda mats: Shape("x", base.areas_m2, base.normals_body, base.centers_body_m, mats,
                                1.0, np.eye(3))
        a = mk([lam] * base.n_facets)
        b = mk([usr if i % 2 else lam for i in range(base.n_facets)])
        N = 30
        q = _rand_quats(rng, (N, 3))
        s, o = _rand_units(rng, (N,)), _rand_units(rng, (N,))
        ma = apparent_magnitude(a, q, s, o, np.full(N, 1e6), np.full(N, AU_M))
        mb = apparent_magnitude(b, q, s, o, np.full(N, 1e6), np.full(N, AU_M))
        np.testing.assert_allclose(mb, ma, atol=1e-12)
    finally:
        unregister_brdf("test_user_lambert")


def test_noise_model_eq_9_3():
    # σ = |m| (r/100)/3: r = 1 %, m = 9 → σ = 0.03 mag (3σ = 1 % of m).
    assert magnitude_sigma(9.0, 1.0) == pytest.approx(0.03)
    assert magnitude_sigma(-3.0, 1.0) == pytest.approx(0.01)
    with pytest.raises(ValueError):
        magnitude_sigma(9.0, -1.0)
    m = np.full(20000, 9.0)
    m[5] = np.inf
    y1, sig = add_noise(m, 1.0, 42)
    y2, _ = add_noise(m, 1.0, np.random.default_rng(42))
    np.testing.assert_array_equal(y1, y2)  # seed or Generator, bit-for-bit
    assert np.isposinf(y1[5]) and np.isposinf(sig[5])
    r = (y1[np.isfinite(y1)] - 9.0) / 0.03
    # sample variance of n = 19999 N(0,1) draws: (n−1)s² ~ χ²(n−1); ±5·sqrt(2/n) bounds the
    # relative error of s² with false-alarm rate ≈ 6e-7; the mean within 5/sqrt(n).
    n = r.size
    assert abs(r.var(ddof=1) - 1.0) < 5 * math.sqrt(2.0 / n)
    assert abs(r.mean()) < 5 / math.sqrt(n)


def test_brdf_value_is_zero_outside_the_lit_visible_hemisphere():
    # documented: values where n·s ≤ 0 or n·o ≤ 0 are 0 (finite), here grazing n·s = 0
    b = get_brdf("phong")
    v = b.evaluate(np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]),
                   {"Kd": 0.3, "Ks": 0.3, "n": 5.0})
    assert v == 0.0
