"""BRDF models: hand values, independent numpy re-implementations, physical properties, registry."""

import math

import numpy as np
import pytest

from lightcurve.errors import InputError
from lightcurve.photometry import (AU_M, Material, Shape, apparent_magnitude, available_brdfs,
                                   get_brdf, register_brdf, unregister_brdf)
from lightcurve.core.photometry import brightness_kernel

RNG_SEED = 20240601


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _single_facet(material, area=1.0):
    return Shape("one", [area], [[0.0, 0.0, 1.0]], [[0.0, 0.0, 0.0]], [material], 1.0, np.eye(3))


# ---------------------------------------------------------------------------------------
# hand values
# ---------------------------------------------------------------------------------------
def test_single_facet_specular_peak_hand_value():
    # One 1 m² Cook–Torrance facet, normal +Z, Sun and observer both along +Z (mirror/peak):
    #   n·s = n·o = 1, ĥ = n̂ so n·h = 1, c = o·h = 1, tan α = 0.
    #   D = exp(0)/(π m² · 1) = 1/(π·0.01) = 31.830988618379067
    #   G = min(1, 2·1·1/1, 2·1·1/1) = 1
    #   F at c = 1: g = n_r, B = 1, F = ((n_r−1)/(n_r+1))² = F0 = a = 0.6
    #   f_r = ξ a/π + (1−ξ) F D G/(4·1·1) = 0.2·0.6/π + 0.8·0.6·31.830988618379067/4
    #       = 0.03819718634205488 + 3.819718634205488 = 3.857915820547543 sr⁻¹
    #   Φ = A·1·1·f_r = 3.857915820547543 m² sr⁻¹;  r_obs = 1000 km, r_sun = 1 au
    #   m = −26.74 − 2.5 log10(3.857915820547543 / 1e12)
    #     log10(3.857915820547543) = 0.5863527; −2.5·(0.5863527 − 12) = 28.5341181
    #   m = −26.74 + 28.5341181 = 1.7941181
    expected_fr = 0.2 * 0.6 / math.pi + 0.8 * 0.6 / (math.pi * 0.01) / 4.0
    assert expected_fr == pytest.approx(3.857915820547543, rel=1e-15)
    expected_m = -26.74 - 2.5 * (math.log10(3.857915820547543) - 12.0)
    assert expected_m == pytest.approx(1.7941181, abs=1e-7)
    mat = Material.create("ct", "cook_torrance", xi=0.2, a=0.6, m=0.1)
    shape = _single_facet(mat)
    z = np.array([[0.0, 0.0, 1.0]])
    m = apparent_magnitude(shape, [[1.0, 0, 0, 0]], z, z, [1e6], [AU_M])
    assert m[0] == pytest.approx(1.7941181, abs=1e-7)
    # the peak is a maximum: tilting the observer by 20° (α = 10°, D falls by exp(−3.1)) dims it
    o = np.array([[0.0, math.sin(0.349), math.cos(0.349)]])
    assert apparent_magnitude(shape, [[1.0, 0, 0, 0]], z, o, [1e6], [AU_M])[0] > m[0] + 2.0


def test_lambert_hand_value_and_distance_laws():
    # 2 m² Lambert facet, albedo 0.5, Sun at 60° from the normal, observer on the normal:
    #   P = albedo/π · cos60 · cos0 = 0.5/π · 0.5 = 0.07957747154594767
    #   Φ = 2 · P = 0.15915494309189535 m² sr⁻¹; r_obs = 1000 km, r_sun = 1 au
    #   m = −26.74 − 2.5 (log10(0.15915494309189535) − 12)
    #     = −26.74 − 2.5 (−0.798179868 − 12) = −26.74 + 31.99544967 = 5.25544967
    mat = Material.create("white", "lambert", albedo=0.5)
    shape = _single_facet(mat, area=2.0)
    s = np.array([[math.sin(math.radians(60)), 0.0, 0.5]])
    o = np.array([[0.0, 0.0, 1.0]])
    q = [[1.0, 0, 0, 0]]
    m = apparent_magnitude(shape, q, s, o, [1e6], [AU_M])[0]
    assert m == pytest.approx(5.25544967, abs=1e-7)
    # inverse-square laws: 2× observer range → +5 log10 2; Sun at 2 au → +5 log10 2
    assert apparent_magnitude(shape, q, s, o, [2e6], [AU_M])[0] - m == pytest.approx(5 * math.log10(2))
    assert apparent_magnitude(shape, q, s, o, [1e6], [2 * AU_M])[0] - m == pytest.approx(5 * math.log10(2))
    # sun_mag is a parameter (other bands)
    assert apparent_magnitude(shape, q, s, o, [1e6], [AU_M], sun_mag=-27.0)[0] == pytest.approx(m - 0.26)


def test_phong_hand_value():
    # Phong, Kd 0.34, Ks 0.40, n 8.9 (Starlink chassis). Sun at 30° in the x–z plane,
    # observer at the mirror direction rotated by 10°: r̂ = (−sin30, 0, cos30) mirrored →
    # r̂·ô = cos 10°. f = 0.34/π + 0.40 (10.9)/(2π) cos(10°)^8.9
    #   = 0.108225361 + 0.693915552 · 0.873636... (cos10°^8.9 = exp(8.9 ln 0.98480775))
    s = np.array([math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))])
    o = np.array([-math.sin(math.radians(40)), 0.0, math.cos(math.radians(40))])
    n = np.array([0.0, 0.0, 1.0])
    expected = 0.34 / math.pi + 0.40 * 10.9 / (2 * math.pi) * math.cos(math.radians(10)) ** 8.9
    assert expected == pytest.approx(0.108225361 + 0.693915552 * 0.98480775301 ** 8.9, rel=1e-8)
    got = get_brdf("phong").evaluate(n, s, o, {"Kd": 0.34, "Ks": 0.40, "n": 8.9})
    assert got == pytest.approx(expected, rel=1e-12)
    # lobe is zero past 90° from the mirror direction: only Kd/π remains
    o2 = _unit([0.9, 0.0, 0.1])  # same side as the Sun, r̂·ô < 0
    assert get_brdf("phong").evaluate(n, s, o2, {"Kd": 0.34, "Ks": 0.40, "n": 8.9}) == \
        pytest.approx(0.34 / math.pi, rel=1e-12)


# ---------------------------------------------------------------------------------------
# Cook–Torrance kernel vs an independent plain-numpy implementation
# ---------------------------------------------------------------------------------------
def _ct_reference(n, s, o, xi, a, m):
    """Plain numpy Cook–Torrance per DESIGN.md, written independently of the package."""
    ns = np.sum(n * s, -1)
    no = np.sum(n * o, -1)
    h = s + o
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    nh = np.sum(n * h, -1)
    c = np.sum(o * h, -1)
    alpha = np.arccos(np.clip(nh, -1, 1))
    D = np.exp(-(np.tan(alpha) / m) ** 2) / (np.pi * m**2 * np.cos(alpha) ** 4)
    G = np.minimum(1.0, np.minimum(2 * nh * no / c, 2 * nh * ns / c))
    nr = (1 + np.sqrt(a)) / (1 - np.sqrt(a))
    g = np.sqrt(nr**2 + c**2 - 1)
    F = 0.5 * (g - c) ** 2 / (g + c) ** 2 * (1 + (c * (g + c) - 1) ** 2 / (c * (g - c) + 1) ** 2)
    fr = xi * a / np.pi + (1 - xi) * F * D * G / (4 * ns * no)
    return np.where((ns > 0) & (no > 0), fr, 0.0)


def test_cook_torrance_kernel_matches_numpy_reference():
    rng = np.random.default_rng(RNG_SEED)
    F, N, S = 7, 40, 3
    normals = _unit(rng.normal(size=(F, 3)))
    areas = rng.uniform(0.1, 2.0, F)
    xi = rng.uniform(0, 1, F)
    a = rng.uniform(0.02, 0.95, F)
    m = rng.uniform(0.05, 1.0, F)
    params = np.zeros((F, 7))
    params[:, 0], params[:, 1], params[:, 2] = xi, a, m
    ids = np.ones(F, dtype=np.int64)
    sb = _unit(rng.normal(size=(N, S, 3)))
    ob = _unit(rng.normal(size=(N, S, 3)))
    got = brightness_kernel(normals, areas, ids, params, sb, ob)
    ref = np.zeros((N, S))
    for i in range(F):
        fr = _ct_reference(normals[i], sb, ob, xi[i], a[i], m[i])
        ns = np.maximum(sb @ normals[i], 0)
        no = np.maximum(ob @ normals[i], 0)
        ref += areas[i] * ns * no * fr
    assert np.count_nonzero(ref) > N * S // 2  # the comparison is not vacuous
    np.testing.assert_allclose(got, ref, rtol=1e-11, atol=1e-14)
    # and the per-value API
    n1 = np.broadcast_to(normals[0], sb.shape)
    vals = get_brdf("cook_torrance").evaluate(n1, sb, ob, {"xi": xi[0], "a": a[0], "m": m[0]})
    np.testing.assert_allclose(vals, _ct_reference(n1, sb, ob, xi[0], a[0], m[0]), rtol=1e-11)


# ---------------------------------------------------------------------------------------
# Ashikhmin–Shirley vs an independent implementation; physical properties
# ---------------------------------------------------------------------------------------
def _as_reference(n, u, s, o, Rd, Rs, nu, nv):
    """Ashikhmin & Shirley (2000) eq. (4), (5) written out in numpy (independent)."""
    v = np.cross(n, u)
    h = _unit(s + o)
    nh, hu, hv = h @ n, h @ u, h @ v
    kh = np.sum(o * h, -1)
    ns, no = s @ n, o @ n
    expo = (nu * hu**2 + nv * hv**2) / (1 - nh**2)
    spec = (math.sqrt((nu + 1) * (nv + 1)) / (8 * math.pi) * nh**expo / (kh * np.maximum(ns, no))
            * (Rs + (1 - Rs) * (1 - kh) ** 5))
    diff = 28 * Rd / (23 * math.pi) * (1 - Rs) * (1 - (1 - ns / 2) ** 5) * (1 - (1 - no / 2) ** 5)
    return spec + diff


def test_ashikhmin_shirley_matches_reference_with_anisotropy():
    rng = np.random.default_rng(RNG_SEED + 1)
    n = np.array([0.0, 0.0, 1.0])
    u = np.array([1.0, 0.0, 0.0])
    s = _unit(rng.normal(size=(200, 3)) + [0, 0, 2.0])
    o = _unit(rng.normal(size=(200, 3)) + [0, 0, 2.0])
    ok = (s @ n > 0) & (o @ n > 0)
    s, o = s[ok], o[ok]
    p = {"Rd": 0.3, "Rs": 0.2, "nu": 50.0, "nv": 5.0, "tangent": u}
    got = get_brdf("ashikhmin_shirley").evaluate(n, s, o, p)
    np.testing.assert_allclose(got, _as_reference(n, u, s, o, 0.3, 0.2, 50.0, 5.0), rtol=1e-11)
    # anisotropy is real: swapping the tangent changes the value
    p2 = dict(p, tangent=np.array([0.0, 1.0, 0.0]))
    assert not np.allclose(get_brdf("ashikhmin_shirley").evaluate(n, s, o, p2), got)


@pytest.mark.parametrize("name,params", [
    ("lambert", {"albedo": 0.7}),
    ("cook_torrance", {"xi": 0.3, "a": 0.4, "m": 0.3}),
    ("phong", {"Kd": 0.2, "Ks": 0.5, "n": 12.0}),
    ("ashikhmin_shirley", {"Rd": 0.4, "Rs": 0.3, "nu": 20.0, "nv": 20.0}),
])
def test_helmholtz_reciprocity(name, params):
    # A physical BRDF is symmetric in its two directions (Helmholtz reciprocity);
    # all four analytic models are reciprocal by construction.
    rng = np.random.default_rng(RNG_SEED + 2)
    n = np.array([0.0, 0.0, 1.0])
    s = _unit(rng.normal(size=(100, 3)) + [0, 0, 1.5])
    o = _unit(rng.normal(size=(100, 3)) + [0, 0, 1.5])
    ok = (s @ n > 0.05) & (o @ n > 0.05)
    b = get_brdf(name)
    np.testing.assert_allclose(b.evaluate(n, s[ok], o[ok], params), b.evaluate(n, o[ok], s[ok], params),
                               rtol=1e-12)


def _hemispherical_reflectance(name, params, theta_i, n_mu=400, n_phi=400):
    # ρ(θ_i) = ∫_hemisphere f_r cos θ_o dω_o, midpoint rule in (μ = cos θ_o, φ_o).
    mu = (np.arange(n_mu) + 0.5) / n_mu
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    MU, PHI = np.meshgrid(mu, phi, indexing="ij")
    st = np.sqrt(1 - MU**2)
    o = np.stack([st * np.cos(PHI), st * np.sin(PHI), MU], -1)
    s = np.array([math.sin(theta_i), 0.0, math.cos(theta_i)])
    f = get_brdf(name).evaluate(np.array([0.0, 0.0, 1.0]), s, o, params)
    return float(np.sum(f * MU) * (1.0 / n_mu) * (2 * np.pi / n_phi))


def test_energy_normalisations():
    # Lambert: ρ = albedo exactly; normalised Phong lobe at normal incidence:
    # ∫ (n+2)/(2π) cos^n θ cos θ dω = (n+2)/(n+2) = 1 (Lewis 1994), so Ks=1, Kd=0 → ρ = 1.
    assert _hemispherical_reflectance("lambert", {"albedo": 0.7}, 0.3) == pytest.approx(0.7, rel=1e-4)
    assert _hemispherical_reflectance("phong", {"Kd": 0.0, "Ks": 1.0, "n": 20.0}, 0.0) == \
        pytest.approx(1.0, rel=2e-3)
    # Ashikhmin–Shirley is energy conserving (paper §3): ρ ≤ 1 for Rd = Rs = 1... ≤ 1 + quadrature
    for th in (0.0, 0.6, 1.2):
        assert _hemispherical_reflectance("ashikhmin_shirley",
                                          {"Rd": 1.0, "Rs": 0.0, "nu": 10.0, "nv": 10.0}, th) <= 1.0 + 1e-3
    # Cook–Torrance with ξ = 1 is Lambert with albedo a
    assert _hemispherical_reflectance("cook_torrance", {"xi": 1.0, "a": 0.4, "m": 0.3}, 0.5) == \
        pytest.approx(0.4, rel=1e-4)


# ---------------------------------------------------------------------------------------
# registry
# ---------------------------------------------------------------------------------------
def test_registry_builtins_and_errors():
    assert {"lambert", "cook_torrance", "phong", "ashikhmin_shirley"} <= set(available_brdfs())
    with pytest.raises(InputError, match="unknown BRDF"):
        get_brdf("no_such_brdf")
    with pytest.raises(InputError, match=r"field 'mat\.a'.*out of range.*\(0\.0, 1\.0\)"):
        Material.create("x", "cook_torrance", field="mat", xi=0.5, a=1.0, m=0.3)
    with pytest.raises(InputError, match="unknown parameter"):
        Material.create("x", "lambert", albedo=0.3, shininess=3)
    with pytest.raises(InputError, match="missing parameter"):
        Material.create("x", "phong", Kd=0.3, Ks=0.3)


def test_register_function_and_class_and_entry_point(monkeypatch):
    from lightcurve.photometry import BRDF
    from lightcurve.photometry import brdf as brdf_mod

    try:
        @register_brdf("test_flat", bounds={"rho": (0.0, 1.0)})
        def flat(n, s, o, *, rho=0.2):
            return np.full(np.broadcast_shapes(n.shape, s.shape, o.shape)[:-1], rho / np.pi)

        assert flat(np.zeros(3), np.zeros(3), np.zeros(3)) == pytest.approx(0.2 / np.pi)  # unchanged
        assert get_brdf("test_flat").param_names == ("rho",)
        with pytest.raises(InputError, match="out of range"):
            Material.create("x", "test_flat", rho=2.0)
        with pytest.raises(ValueError, match="already registered"):
            register_brdf("test_flat")(flat)

        @register_brdf("test_cls")
        class Half(BRDF):
            param_names = ("k",)
            defaults = {"k": 1.0}

            def evaluate(self, n, s, o, params):
                return 0.5 * np.asarray(params["k"]) * np.ones(np.broadcast_shapes(n.shape, s.shape)[:-1])

        assert isinstance(Half, type)
        assert get_brdf("test_cls").evaluate(np.ones(3), np.ones(3), np.ones(3), {"k": 2.0}) == 1.0

        # entry point group lightcurve.brdfs (importlib.metadata patched to offer one)
        class FakeEP:
            name = "test_ep"
            value = "somewhere:thing"

            def load(self):
                def ep_brdf(n, s, o, *, q=0.1):
                    return q * np.ones(np.broadcast_shapes(n.shape, s.shape)[:-1])
                return ep_brdf

        import importlib.metadata as md

        monkeypatch.setattr(md, "entry_points",
                            lambda group=None: [FakeEP()] if group == "lightcurve.brdfs" else [])
        monkeypatch.setattr(brdf_mod, "_ENTRY_POINTS_LOADED", False)
        assert get_brdf("test_ep").evaluate(np.ones(3), np.ones(3), np.ones(3), {"q": 0.3}) == \
            pytest.approx(0.3)
        assert "test_ep" in available_brdfs()
    finally:
        for name in ("test_flat", "test_cls", "test_ep"):
            unregister_brdf(name)
