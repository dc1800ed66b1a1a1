"""Self-shadowing (hand-computed occluded fraction), Earthshine (Lambert-sphere Earth) and
the CSS effects (independent evaluation through lightcurve.css)."""

import numpy as np
import pytest

from lightcurve.earth.albedo import AUTHALIC_RADIUS_M, AlbedoMap, albedo_cells_in_view
from lightcurve.errors import InputError
from lightcurve.photometry import Shape, get_brdf, load_shape
from lightcurve.photometry.materials import Material
from lightcurve.physics import CSSContext, get_effect
from lightcurve.physics.earthshine import earthshine_cells
from lightcurve.physics.self_shadowing import SelfShadowing

LAMB = Material("white", get_brdf("lambert"), {"albedo": 0.5})


def _mesh_shape(V, tris, name):
    V = np.asarray(V, float)
    F = np.asarray(tris, np.int64)
    tri = V[F]
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    # one facet per pair of triangles (quads listed as two triangles in order)
    areas, normals, centers = [], [], []
    for k in range(0, len(F), 2):
        a = 0.5 * (np.linalg.norm(cr[k]) + np.linalg.norm(cr[k + 1]))
        areas.append(a)
        normals.append(cr[k] / np.linalg.norm(cr[k]))
        centers.append(tri[k:k + 2].reshape(-1, 3).mean(0))
    return Shape(name, areas, normals, centers, [LAMB] * len(areas), 1.0, np.eye(3),
                 vertices_m=V, faces=F)


def l_shape():
    """Floor [0,1]² at z=0 (normal +z) and a wall at x=0, y∈[0,1], z∈[0,1], two-sided."""
    V = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],      # floor 0-3
         [0, 0, 1], [0, 1, 1]]                             # wall top 4-5
    tris = [[0, 1, 2], [0, 2, 3],                          # floor +z
            [0, 3, 5], [0, 5, 4],                          # wall +x side
            [0, 4, 5], [0, 5, 3]]                          # wall −x side
    return _mesh_shape(V, tris, "l_shape")


def _fractions(shape, s, o, sub=16):
    model = SelfShadowing(subdivisions=sub, skip_convex=False).model(shape)
    return model.fractions(shape, np.atleast_2d(s), np.atleast_2d(o))[0]


def test_l_shape_shadow_fraction_hand_computed():
    sh = l_shape()
    assert not sh.convex
    np.testing.assert_allclose(sh.normals_body, [[0, 0, 1], [1, 0, 0], [-1, 0, 0]], atol=1e-12)
    o = np.array([0.0, 0.0, 1.0])  # observer straight above: the wall hides nothing
    for tan_e, expect in [(2.0, 0.5), (4.0, 0.75), (1 / np.sqrt(3), 0.0)]:
        # Sun from −x at elevation e: the 1 m wall casts a shadow 1/tan e long on the floor
        s = np.array([-1.0, 0.0, tan_e]) / np.hypot(1.0, tan_e)
        v = _fractions(sh, s, o)
        # sample points sit at sub-triangle centroids: edge error ≲ 1/16 of the floor
        assert abs(v[0] - expect) < 0.04, (tan_e, v[0])
    # Sun overhead, observer low over the wall from −x: the wall hides x < 1/tan of the floor
    s = np.array([0.0, 0.0, 1.0])
    o = np.array([-1.0, 0.0, 2.0]) / np.sqrt(5.0)
    assert abs(_fractions(sh, s, o)[0] - 0.5) < 0.04


def test_self_shadowing_effect_scales_flux_and_convex_is_unchanged():
    from physics_synth import make_ctx

    cube = load_shape("cube_1u")
    eff = get_effect("self_shadowing")
    ctx = make_ctx(cube, n=5)
    np.testing.assert_array_equal(eff.apply(ctx, {}), ctx.magnitude())  # convex: skipped
    box = load_shape("rocket_body")  # closed convex prism mesh: rays find no blocker
    ctx2 = make_ctx(box, n=5)
    m = get_effect("self_shadowing", skip_convex=False, subdivisions=2).apply(ctx2, {})
    np.testing.assert_allclose(m, ctx2.magnitude(), atol=1e-12)
    with pytest.raises(InputError, match="mesh"):
        get_effect("self_shadowing").apply(make_ctx(load_shape("box_wing"), n=2), {})


def test_earthshine_lambert_sphere():
    """Uniform ρ = 0.3 map, object on the Sun–Earth line above the subsolar point.

    Independent: the irradiance on a plate facing the Earth from a Lambertian sphere lit at
    zero phase, E/E_sun = ∫ ρ/π cos i cos e cos θ dA / d² (1-D quadrature over the angle
    from the subsolar point), and its far-field limit (2/3) ρ (R/r)² (Lambert sphere
    geometric albedo 2ρ/3).
    """
    rho = 0.3
    grid = AlbedoMap.regular(np.full((180, 360), rho)).grid()
    R = AUTHALIC_RADIUS_M
    sun = np.array([1.0, 0.0, 0.0]) * 1.496e11

    def cells_total(r):
        dirs, ratio = earthshine_cells(grid, np.array([r, 0.0, 0.0]), sun, 0.0)
        return np.sum(ratio * np.maximum(dirs @ np.array([-1.0, 0.0, 0.0]), 0.0))

    def sphere(r):
        g = np.linspace(0, np.pi / 2, 20001)
        P = R * np.stack([np.cos(g), np.sin(g)], 1)           # (along axis, radial)
        d = np.stack([r - P[:, 0], -P[:, 1]], 1)
        dn = np.linalg.norm(d, axis=1)
        cos_e = np.sum(d * P / R, 1) / dn
        cos_p = (r - P[:, 0]) / dn
        f = np.where(cos_e > 0, rho / np.pi * np.cos(g) * cos_e * cos_p / dn**2, 0.0)
        return np.trapezoid(f * 2 * np.pi * R**2 * np.sin(g), g)

    for h in (600e3, 5000e3, 39 * R):
        r = R + h
        assert abs(cells_total(r) / sphere(r) - 1) < 0.01
    # the quadrature itself tends to the far-field Lambert-sphere value (O(R/r) corrections)
    r = 2000 * R
    assert abs(sphere(r) / (2 / 3 * rho * (R / r) ** 2) - 1) < 2e-3
    assert abs(cells_total(40 * R) / (2 / 3 * rho / 1600) - 1) < 0.03


def test_earthshine_effect_on_a_nadir_plate():
    """A Lambert plate facing the Earth, Sun behind it: all its light is Earthshine."""
    from lightcurve.physics import ModelContext

    rho = 0.3
    grid = AlbedoMap.regular(np.full((36, 72), rho)).grid()
    plate = Shape("plate", [2.0], [[-1.0, 0.0, 0.0]], [[0, 0, 0]], [LAMB], 1.0, np.eye(3))
    r = np.array([[7000e3, 0.0, 0.0]])
    ctx = ModelContext(epoch_utc="2024-03-20T00:00:00Z", t=[0.0], site_index=[0], site_names=["g"],
                       shape=plate, q=[[1.0, 0, 0, 0]], omega=[[0, 0, 0]], r_obj_eci_m=r,
                       v_obj_eci_m_s=[[0, 7.5e3, 0]], r_site_eci_m=[[6378137.0, 0, 0]],
                       r_sun_eci_m=[[1.496e11, 0, 0]], elevation_rad=[np.pi / 2])
    assert np.isinf(ctx.magnitude()[0])                       # sunlight hits the back only
    eff = get_effect("earthshine")
    eff.grid = lambda: grid
    m = eff.apply(ctx, {"albedo_scale": 1.0})
    # E from the cells (validated against the Lambert sphere above) at the epoch's GMST
    from lightcurve.earth.albedo import earth_rotation_angle

    th = float(earth_rotation_angle(ctx.epoch_utc, 0.0))
    dirs, ratio = earthshine_cells(grid, r[0], np.array([1.496e11, 0, 0]), th)
    E = np.sum(ratio * np.maximum(dirs @ np.array([-1.0, 0, 0]), 0))
    F = 2.0 * 0.5 / np.pi * E                                  # A ρ_p/π (n·o = 1) E
    ro, rs = 7000e3 - 6378137.0, 1.496e11 - 7000e3
    ref = -26.74 - 2.5 * np.log10(F / ro**2 * (149_597_870_700.0 / rs) ** 2)
    assert abs(m[0] - ref) < 1e-9
    m2 = eff.apply(ctx, {"albedo_scale": 0.5})
    assert abs(m2[0] - m[0] - 2.5 * np.log10(2)) < 1e-9


# ------------------------------------------------------------------------------------------
def _css_ctx():
    from lightcurve.css.sensors import CSSArray

    normals = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]])
    arr = CSSArray(normals, np.radians(80.0))
    K = 12
    ang = np.linspace(0, 2 * np.pi, K, endpoint=False)
    r = 6878e3 * np.stack([np.cos(ang), np.sin(ang), np.zeros(K)], 1)
    sun = np.tile([1.0, 0.3, 0.1], (K, 1))
    q = np.tile([1.0, 0, 0, 0], (K, 1))
    return CSSContext(arr, np.arange(K) * 60.0, "2024-03-20T00:00:00Z", q, r, sun, np.ones(K))


def test_css_scale_misalignment_fault_against_cssarray():
    ctx = _css_ctx()
    s_b = ctx.sun_eci_unit
    base = ctx.evaluate()
    np.testing.assert_allclose(base, ctx.array.signals(s_b), atol=1e-12)
    ind = np.array([1.0, 0.9, 1.1, 1.0, 0.8, 1.0])
    y = get_effect("css_scale_factor").apply(ctx, {"common": 0.9, "individual": ind})
    np.testing.assert_allclose(y, base * 0.9 * ind, atol=1e-12)
    daz, delv = np.linspace(-2, 2, 6), np.linspace(1, -1, 6)
    y = get_effect("css_misalignment").apply(ctx, {"d_az_deg": daz, "d_el_deg": delv})
    ref = ctx.array.with_errors(misalignment_rad=np.radians(np.stack([daz, delv], 1))).signals(s_b)
    np.testing.assert_allclose(y, ref, atol=1e-12)
    y = get_effect("css_fault").apply(ctx, {"sensor": 2, "gain": 0.0, "t_start_s": 300.0})
    late = ctx.t >= 300
    assert np.all(y[late, 2] == 0) and np.allclose(y[~late], base[~late], atol=1e-12)
    np.testing.assert_allclose(np.delete(y, 2, 1), np.delete(base, 2, 1), atol=1e-12)


def test_css_albedo_against_css_albedo_module():
    from lightcurve.earth.albedo import builtin_albedo_map, earth_rotation_angle
    from lightcurve.physics.context import rotate_z

    ctx = _css_ctx()
    y = get_effect("css_albedo").apply(ctx, {"albedo_scale": 1.0})
    grid = builtin_albedo_map(10.0).grid()
    theta = earth_rotation_angle(ctx.epoch_utc, ctx.t)
    for i in range(len(ctx)):
        d, a = albedo_cells_in_view(grid, rotate_z(ctx.r_eci_m[i][None], -theta[i])[0],
                                    rotate_z(ctx.sun_eci_unit[i][None], -theta[i])[0])
        d_b = rotate_z(d, theta[i])  # identity attitude: body = ECI
        ref = ctx.array.signals(ctx.sun_eci_unit[i], 1.0, d_b, a)
        np.testing.assert_allclose(y[i], ref, atol=1e-12)
    assert np.max(y - ctx.evaluate()) > 0.01   # albedo adds a visible bias somewhere
