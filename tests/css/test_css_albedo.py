"""Earth albedo model (O'Keefe eq. 2.15-2.18) against inline numpy versions, quadrature and
the CERES files."""

import numpy as np
import pytest
from scipy.integrate import quad

from lightcurve._paths import shared_data_dir
from lightcurve.css import albedo as alb
from lightcurve.errors import InputError

SHARED = shared_data_dir()
ALB_DIR = None if SHARED is None else SHARED / "earth_albedo"
need_data = pytest.mark.skipif(ALB_DIR is None or not ALB_DIR.is_dir(),
                               reason="../shared/data/earth_albedo not present")


def test_authalic_cell_areas_sum_to_wgs84_surface():
    # WGS84 ellipsoid surface area 510 065 621.724 km^2 (NIMA TR8350.2, table 3.5 derived
    # constants; also Moritz, Geodetic Reference System 1980 gives 510 065 621.7 km^2).
    m = alb.builtin_albedo_map(10.0)
    A = alb.cell_areas_m2(m.lat_edges_rad, m.lon_edges_rad)
    assert A.sum() == pytest.approx(510065621.724e6, rel=1e-9)


def test_authalic_band_area_matches_direct_integration():
    # independent: band area = 2π ∫ M(φ) N(φ) cosφ dφ with M N cosφ = a²(1-e²)cosφ/(1-e²sin²φ)²
    a, e2 = alb.WGS84_A_M, alb.WGS84_F * (2 - alb.WGS84_F)
    f = lambda p: a * a * (1 - e2) * np.cos(p) / (1 - e2 * np.sin(p) ** 2) ** 2
    for lo, hi in ((0, 10), (40, 50), (80, 90), (-90, -60)):
        direct = 2 * np.pi * quad(f, np.radians(lo), np.radians(hi), epsabs=0, epsrel=1e-13)[0]
        ours = alb.cell_areas_m2(np.radians([lo, hi]), [-np.pi, np.pi])[0, 0]
        assert ours == pytest.approx(direct, rel=1e-10)
    assert alb.authalic_latitude(0.0) == 0.0
    assert alb.authalic_latitude(np.pi / 2) == pytest.approx(np.pi / 2)
    # authalic latitude is below geodetic at mid latitudes by ~0.128 deg at 45 deg (Snyder 1987,
    # Map Projections - A Working Manual, table 3: 45 deg -> 44.87170 deg on Clarke 1866;
    # WGS84 differs in the 4th decimal)
    assert np.degrees(alb.authalic_latitude(np.radians(45.0))) == pytest.approx(44.8717, abs=2e-3)


def _inline_cells(centers, normals, rho_area, r, s):
    u = r - centers
    d = np.linalg.norm(u, axis=1)
    u = u / d[:, None]
    cs = normals @ s
    cv = np.sum(normals * u, axis=1)
    ok = (cs > 0) & (cv > 0)
    return np.where(ok, rho_area * cs * cv / (np.pi * d ** 2), 0.0), -u


def test_cell_irradiance_matches_inline_eq_2_15():
    g = alb.builtin_albedo_map(5.0).grid()
    rng = np.random.default_rng(3)
    for _ in range(5):
        r = rng.normal(size=3)
        r *= 6.9e6 / np.linalg.norm(r)
        s = rng.normal(size=3)
        s /= np.linalg.norm(s)
        dirs, ratio = alb.albedo_cells_nb(g.centers_m, g.normals, g.rho_area_m2, r, s)
        exp, edirs = _inline_cells(g.centers_m, g.normals, g.rho_area_m2, r, s)
        assert np.allclose(ratio, exp, rtol=1e-13, atol=0)
        k = exp > 0
        assert np.allclose(dirs[k], edirs[k])
        d2, r2 = alb.albedo_cells_in_view(g, r, s)
        assert np.allclose(np.sort(r2), np.sort(exp[k]))


def test_nadir_plate_uniform_earth_matches_sphere_quadrature():
    # Independent 1-D quadrature over a spherical Earth of radius a, Sun at the zenith of the
    # sub-satellite point, uniform albedo rho, plate facing nadir (cosine response, 90 deg FOV):
    # E/E_sun = rho/pi ∫ cos(g) (r cos g - R)(r - R cos g)/d^4 2 pi R^2 sin g dg, r cos g > R.
    rho, R, h = 0.3, alb.WGS84_A_M, 400e3
    r = R + h

    def integrand(g):
        d2 = R * R + r * r - 2 * R * r * np.cos(g)
        return np.cos(g) * (r * np.cos(g) - R) * (r - R * np.cos(g)) / d2 ** 2 * 2 * np.pi * R * R * np.sin(g)

    gmax = np.arccos(R / r)
    expected = rho / np.pi * quad(integrand, 0, gmax, epsrel=1e-12)[0]
    m = alb.AlbedoMap.regular(np.full((180, 360), rho))
    g = m.grid()
    rs = np.array([r, 0, 0.0])
    out = alb.albedo_on_sensors_nb(g.centers_m, g.normals, g.rho_area_m2, rs, np.array([1.0, 0, 0]),
                                   np.array([[-1.0, 0, 0]]), np.array([0.0]), np.zeros((1, 3)))
    # 1 deg cells and the ellipsoid vs sphere: agree to 1 %
    assert out[0] == pytest.approx(expected, rel=1e-2)
    # hand check of magnitude: rho times the view factor (R/r)^2 = 0.885 is an upper bound
    assert 0.2 < expected < rho * (R / r) ** 2


def test_no_albedo_when_earth_behind_or_night():
    g = alb.builtin_albedo_map(10.0).grid()
    rs = np.array([6.8e6, 0, 0])
    # Sun behind the Earth: the visible cap is unlit
    out = alb.albedo_on_sensors_nb(g.centers_m, g.normals, g.rho_area_m2, rs, np.array([-1.0, 0, 0]),
                                   np.array([[-1.0, 0, 0]]), np.array([0.0]), np.zeros((1, 3)))
    assert out[0] == 0.0
    # sensor facing away from the Earth sees nothing
    out = alb.albedo_on_sensors_nb(g.centers_m, g.normals, g.rho_area_m2, rs, np.array([1.0, 0, 0]),
                                   np.array([[1.0, 0, 0]]), np.array([0.0]), np.zeros((1, 3)))
    assert out[0] == 0.0


@need_data
@pytest.mark.shared_data
def test_zonal_coefficients_rederived_from_ceres():
    v = np.loadtxt(ALB_DIR / "Earth_ALB_2018_CERES_All_1x1.csv", delimiter=",")
    c = alb.fit_zonal_coefficients(v, degree=6)
    assert np.allclose(c, alb.ZONAL_LEGENDRE_COEFFS, atol=1e-7)


@need_data
@pytest.mark.shared_data
@pytest.mark.parametrize("res,shape", [("1x1", (180, 360)), ("5x5", (36, 72)), ("10x10", (18, 36))])
def test_load_ceres_maps(res, shape):
    m = alb.load_albedo_map(ALB_DIR / f"Earth_ALB_2018_CERES_All_{res}.csv")
    assert m.values.shape == shape
    # global mean albedo of CERES 2018 all-sky ~0.29-0.32 (Earth's Bond albedo ~0.29-0.30;
    # surface-referenced CERES albedo slightly higher); the zonal model's c0 is 0.3166
    assert 0.28 < m.global_mean() < 0.34
    # Antarctica (first row) brighter than the tropics
    assert m.values[0].mean() > 0.5 > m.values[shape[0] // 2].mean()


@need_data
@pytest.mark.shared_data
def test_load_toms_transposed_percent():
    m = alb.load_albedo_map(ALB_DIR / "earthReflectivityMean_10x10.dat")
    raw = np.loadtxt(ALB_DIR / "earthReflectivityMean_10x10.dat")
    assert m.values.shape == (18, 36)
    # rows of longitude as written, listed east to west in the coarse files
    assert np.allclose(m.values, raw.T[:, ::-1] / 100)
    assert m.values[0].mean() > 0.8 and m.values[-1].mean() > 0.8  # polar bands


@need_data
@pytest.mark.shared_data
@pytest.mark.parametrize("grid,rows,cols", [("5x5", 5, 4), ("10x10", 10, 8)])
def test_toms_coarse_grids_are_the_fine_grid_averaged(grid, rows, cols):
    """The 5°×5° and 10°×10° TOMS maps as load_toms returns them are the 1°×1.25° map
    averaged over their cells (area-weighted), mean and standard-deviation files alike: an
    independent check of the longitude order (the coarse files list longitudes east to west;
    read as written, the RMS difference is 0.089-0.096 for the means, 0.043-0.049 for the
    standard deviations).  Bounds: about 1.5x the RMS measured with the reversal."""
    from lightcurve.earth.albedo import cell_areas_m2

    fine = alb.load_toms("1p25x1", ALB_DIR)
    coarse = alb.load_toms(grid, ALB_DIR)
    A = cell_areas_m2(fine[0].lat_edges_rad, fine[0].lon_edges_rad)
    nl, nn = coarse[0].values.shape
    w = A.reshape(nl, rows, nn, cols).sum(axis=(1, 3))
    for f, c, bound, as_written in ((fine[0], coarse[0], 0.04, 0.08),
                                    (fine[1], coarse[1], 0.025, 0.04)):
        agg = (f.values * A).reshape(nl, rows, nn, cols).sum(axis=(1, 3)) / w
        rms = np.sqrt(np.mean((c.values - agg) ** 2))
        assert rms < bound
        # the same map as the files are written (longitudes not reversed) disagrees
        assert np.sqrt(np.mean((c.values[:, ::-1] - agg) ** 2)) > as_written
    # the edges are unchanged: columns still run west to east from -180 deg
    assert np.isclose(coarse[0].lon_edges_rad[0], -np.pi)


@pytest.mark.parametrize("content,field", [
    ("0.1,0.2\n0.3,0.4\n", "values"),
    ("\n".join([",".join(["0.3"] * 36)] * 17 + [",".join(["nan"] + ["0.3"] * 35)]) + "\n", "values[row 17, column 0]"),
    ("\n".join([",".join(["1.3"] * 36)] * 18) + "\n", "values"),
])
def test_bad_albedo_maps(tmp_path, content, field):
    p = tmp_path / "bad.csv"
    p.write_text(content)
    with pytest.raises(InputError) as ei:
        alb.load_albedo_map(p)
    assert str(p) in str(ei.value) and field in str(ei.value)


def test_zonal_model_range():
    lat = np.radians(np.linspace(-90, 90, 181))
    z = alb.zonal_albedo(lat)
    assert np.all((z >= 0) & (z <= 1))
    assert z[0] > 0.5 and z[90] < 0.3
    assert alb.builtin_albedo_map(10).global_mean() == pytest.approx(0.3166, abs=5e-3)


def test_earth_rotation_angle_against_skyfield_gmst():
    # skyfield as the oracle: GMST at the epoch, then the sidereal rate
    from skyfield.api import load

    ts = load.timescale(builtin=True)
    th = alb.earth_rotation_angle("2015-03-01T00:00:00Z", [0.0, 3600.0])
    g0 = ts.utc(2015, 3, 1, 0, 0, 0).gmst / 24 * 2 * np.pi
    g1 = ts.utc(2015, 3, 1, 1, 0, 0).gmst / 24 * 2 * np.pi
    assert th[0] == pytest.approx(g0, abs=1e-9)
    assert np.mod(th[1] - g1 + np.pi, 2 * np.pi) - np.pi == pytest.approx(0, abs=1e-6)
