"""The Earth albedo map and the irradiance its cells produce at a spacecraft (O'Keefe 2015,
eq. 2.15-2.18) — used by the coarse-sun-sensor models and by Earthshine on lightcurves.

The Earth is divided into latitude/longitude cells on the WGS84 ellipsoid.  Cell ``j`` has
albedo ``ρ_j`` (fraction of the incident sunlight reflected, Lambertian), area ``A_j``,
centre ``r_j`` and outward geodetic normal ``n̂_j`` (Earth-fixed axes).  With ``ŝ`` the unit
Sun direction and ``r`` the spacecraft position (both Earth-fixed), the irradiance that the
cell produces at the spacecraft on a surface facing it, in units of the solar irradiance
(eq. 2.15)::

    a_j = ρ_j A_j (n̂_j·ŝ) (n̂_j·û_j) / (π d_j²),     û_j = (r − r_j)/d_j,  d_j = |r − r_j|

counted only for cells that are both sunlit (``n̂_j·ŝ > 0``) and in view (``n̂_j·û_j > 0``).
A CSS with normal ``n̂`` then receives ``Σ_j a_j f(−û_j)`` (:mod:`lightcurve.css.albedo`);
Earthshine on a faceted object sums the cells the same way (:mod:`lightcurve.physics.earthshine`).
The Sun is far enough that the solar irradiance at the cell equals that at the spacecraft.

Cell areas are exact ellipsoidal areas computed through the authalic latitude β
(eq. 2.16-2.18)::

    q(φ) = (1−e²) [ sinφ/(1−e² sin²φ) − 1/(2e) ln((1−e sinφ)/(1+e sinφ)) ]
    sin β = q(φ)/q_p,   q_p = q(π/2),   R_q = a √(q_p/2)
    A = R_q² (λ₂ − λ₁)(sin β₂ − sin β₁)

so the cells add up to the ellipsoid's surface area.

Maps: CERES 2018 albedo CSV files (rows latitude −90…90 south to north, columns longitude
−180…180; 18×36, 36×72 or 180×360) and the TOMS 2000–2005 mean reflectivity and its standard
deviation that O'Keefe (2015) §2.1.2.1 uses (percent, rows of longitude × columns of latitude,
i.e. transposed, the coarse files' longitudes east to west; 10°×10° 36×18, 5°×5° 72×36,
1°×1.25° 288×180; :func:`load_albedo_map`, :func:`load_toms`).  The
default map is the built-in zonal model :func:`zonal_albedo`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

from .._paths import shared_data_dir
from ..core.constants import OMEGA_EARTH
from ..errors import InputError
from ..estimation.rng import as_generator
from ..geometry.time import parse_epoch, timescale
from ..io.safe_open import ALBEDO_MAX_BYTES as _MAX_MAP_BYTES

__all__ = [
    "WGS84_A_M", "WGS84_F", "ZONAL_LEGENDRE_COEFFS", "AUTHALIC_RADIUS_M", "AlbedoMap",
    "AlbedoGrid", "authalic_latitude", "cell_areas_m2", "cell_centers_ecef", "zonal_albedo",
    "builtin_albedo_map", "load_albedo_map", "fit_zonal_coefficients", "cell_irradiance_nb",
    "albedo_cells_nb", "albedo_cells_in_view", "earth_rotation_angle", "TOMS_GRIDS",
    "load_toms", "draw_albedo_map",
]

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
_E2 = WGS84_F * (2.0 - WGS84_F)
_E = np.sqrt(_E2)

# Built-in zonal albedo model: ρ(φ) = Σ_k c_k P_k(sin φ) (Legendre polynomials P_0..P_6 of
# the sine of geodetic latitude).  Derived by an area-weighted (cos φ) least-squares fit to
# the longitude-averaged zonal means of ../shared/data/earth_albedo/
# Earth_ALB_2018_CERES_All_1x1.csv (CERES 2018, all-sky, 1°), see fit_zonal_coefficients();
# tests/css/test_css_albedo.py re-derives these numbers from the file when it is present.
# RMS residual of the fit against the zonal means: 0.012; global mean (c_0): 0.3166.
ZONAL_LEGENDRE_COEFFS = np.array([
    0.31661599, -0.0120705, 0.24989466, -0.04124043, 0.08316421, -0.01023705, -0.00765326,
])


def fit_zonal_coefficients(values, degree=6) -> np.ndarray:
    """Fit Legendre coefficients in sin(latitude) to the zonal means of an albedo map.

    ``values`` is a (nlat, nlon) CERES-layout array (rows −90…90).  The fit is least squares
    weighted by cos(latitude) (i.e. by area on a sphere).  Returns ``degree+1`` coefficients.
    """
    v = np.asarray(values, dtype=float)
    nlat = v.shape[0]
    edges = np.linspace(-np.pi / 2, np.pi / 2, nlat + 1)
    lat = 0.5 * (edges[:-1] + edges[1:])
    z = v.mean(axis=1)
    w = np.sqrt(np.cos(lat))
    V = np.polynomial.legendre.legvander(np.sin(lat), degree)
    return np.linalg.lstsq(V * w[:, None], z * w, rcond=None)[0]


def zonal_albedo(lat_rad, coeffs=None):
    """Built-in zonal albedo ρ(φ) (dimensionless, clipped to [0, 1]) at geodetic latitude(s)
    ``lat_rad``."""
    c = ZONAL_LEGENDRE_COEFFS if coeffs is None else np.asarray(coeffs, dtype=float)
    return np.clip(np.polynomial.legendre.legval(np.sin(np.asarray(lat_rad, dtype=float)), c),
                   0.0, 1.0)


def _q(phi):
    s = np.sin(phi)
    return (1.0 - _E2) * (s / (1.0 - _E2 * s * s)
                          - 1.0 / (2.0 * _E) * np.log((1.0 - _E * s) / (1.0 + _E * s)))


_QP = float(_q(np.pi / 2))
AUTHALIC_RADIUS_M = WGS84_A_M * np.sqrt(_QP / 2.0)


def authalic_latitude(phi_rad):
    """Authalic latitude β (rad) of geodetic latitude φ (rad) on WGS84 (eq. 2.17)."""
    return np.arcsin(np.clip(_q(np.asarray(phi_rad, dtype=float)) / _QP, -1.0, 1.0))


def cell_areas_m2(lat_edges_rad, lon_edges_rad) -> np.ndarray:
    """Areas (m²) of ellipsoidal cells between the given geodetic latitude and longitude edges
    (eq. 2.16-2.18).  Returns (nlat, nlon)."""
    sb = np.sin(authalic_latitude(np.asarray(lat_edges_rad, dtype=float)))
    dl = np.diff(np.asarray(lon_edges_rad, dtype=float))
    return AUTHALIC_RADIUS_M ** 2 * np.outer(np.diff(sb), dl)


def cell_centers_ecef(lat_edges_rad, lon_edges_rad):
    """Centres and outward geodetic normals of the cells of a latitude/longitude grid (WGS-84).

    Each centre is on the ellipsoid at the authalic-latitude midpoint of its row (the
    equal-area centre, eq. 2.16–2.18) and the longitude midpoint. Edges in rad, ascending.
    Returns ``(centers (M,3) m ECEF, normals (M,3) unit ECEF, lat_c (nlat,) rad geodetic,
    lon_c (nlon,) rad)`` with M = nlat·nlon, rows in latitude-major order.
    """
    lat_e, lon_e = np.asarray(lat_edges_rad, float), np.asarray(lon_edges_rad, float)
    beta_e = authalic_latitude(lat_e)
    beta_c = np.arcsin(0.5 * (np.sin(beta_e[:-1]) + np.sin(beta_e[1:])))
    # invert β→φ on a fine grid by interpolation (monotonic)
    phi_f = np.linspace(-np.pi / 2, np.pi / 2, 20001)
    lat_c = np.interp(beta_c, authalic_latitude(phi_f), phi_f)
    lon_c = 0.5 * (lon_e[:-1] + lon_e[1:])
    LAT, LON = np.meshgrid(lat_c, lon_c, indexing="ij")
    sphi, cphi = np.sin(LAT), np.cos(LAT)
    N = WGS84_A_M / np.sqrt(1.0 - _E2 * sphi ** 2)
    centers = np.stack([N * cphi * np.cos(LON), N * cphi * np.sin(LON),
                        N * (1.0 - _E2) * sphi], axis=-1).reshape(-1, 3)
    normals = np.stack([cphi * np.cos(LON), cphi * np.sin(LON), sphi], axis=-1).reshape(-1, 3)
    return centers, normals, lat_c, lon_c


@dataclass(frozen=True)
class AlbedoMap:
    """An albedo map on a regular latitude/longitude grid.

    values: (nlat, nlon) albedo in [0, 1], rows south→north, columns west→east from −180°;
    lat_edges_rad (nlat+1), lon_edges_rad (nlon+1): geodetic cell edges; source: label.
    """

    values: np.ndarray
    lat_edges_rad: np.ndarray
    lon_edges_rad: np.ndarray
    source: str = "map"

    @classmethod
    def regular(cls, values, source="map") -> "AlbedoMap":
        """A map covering the globe with equal-angle cells (edges derived from the shape)."""
        v = np.asarray(values, dtype=float)
        return cls(v, np.linspace(-np.pi / 2, np.pi / 2, v.shape[0] + 1),
                   np.linspace(-np.pi, np.pi, v.shape[1] + 1), source)

    def grid(self) -> "AlbedoGrid":
        """Precomputed cell geometry (Earth-fixed) for the irradiance kernels."""
        return AlbedoGrid.from_map(self)

    def global_mean(self) -> float:
        """Area-weighted global mean albedo."""
        A = cell_areas_m2(self.lat_edges_rad, self.lon_edges_rad)
        return float(np.sum(A * self.values) / np.sum(A))

    def subdivided(self, n: int) -> "AlbedoMap":
        """The same map on cells split ``n`` × ``n`` (equal steps of geodetic latitude and
        of longitude), each sub-cell carrying its parent's value.

        The information is the parent map's (Σ value × area over a parent cell is kept
        exactly, :func:`cell_areas_m2` being additive); what changes is the quadrature of
        the irradiance integral (eq. 2.15 is evaluated at each cell's centre).  A cell as
        wide as the altitude is badly served by one centre: at 400 km a 10° cell spans
        ≈ 1100 km, over which the cell's distance and viewing and illumination angles vary
        by factors of several.  ``n`` = 1 returns this map."""
        n = int(n)
        if n < 1:
            raise ValueError(f"subdivision n must be a positive integer, got {n}")
        if n == 1:
            return self

        def split(e):
            e = np.asarray(e, dtype=float)
            f = np.linspace(0.0, 1.0, n + 1)[:-1]
            return np.append((e[:-1, None] + np.diff(e)[:, None] * f).ravel(), e[-1])

        v = np.repeat(np.repeat(np.asarray(self.values, dtype=float), n, axis=0), n, axis=1)
        return AlbedoMap(v, split(self.lat_edges_rad), split(self.lon_edges_rad),
                         f"{self.source}/{n}x{n}")


@dataclass(frozen=True)
class AlbedoGrid:
    """Earth-fixed cell geometry: centres (M,3) m, unit geodetic normals (M,3), and
    ``rho_area`` (M,) = ρ_j A_j in m²; only cells with non-zero albedo are kept."""

    centers_m: np.ndarray
    normals: np.ndarray
    rho_area_m2: np.ndarray

    @classmethod
    def from_map(cls, amap: AlbedoMap) -> "AlbedoGrid":
        lat_e, lon_e = amap.lat_edges_rad, amap.lon_edges_rad
        centers, normals, _, _ = cell_centers_ecef(lat_e, lon_e)
        ra = (cell_areas_m2(lat_e, lon_e) * amap.values).reshape(-1)
        keep = ra > 0
        return cls(np.ascontiguousarray(centers[keep]), np.ascontiguousarray(normals[keep]),
                   np.ascontiguousarray(ra[keep]))


def builtin_albedo_map(resolution_deg: float = 10.0) -> AlbedoMap:
    """The built-in zonal model sampled on a regular grid of ``resolution_deg`` degrees."""
    nlat = int(round(180.0 / resolution_deg))
    if nlat < 2 or abs(nlat * resolution_deg - 180.0) > 1e-9:
        raise ValueError("resolution_deg must divide 180 (e.g. 1, 5, 10)")
    m = AlbedoMap.regular(np.zeros((nlat, 2 * nlat)), source=f"zonal-{resolution_deg:g}deg")
    lat_c = 0.5 * (m.lat_edges_rad[:-1] + m.lat_edges_rad[1:])
    vals = np.repeat(zonal_albedo(lat_c)[:, None], 2 * nlat, axis=1)
    return AlbedoMap(vals, m.lat_edges_rad, m.lon_edges_rad, m.source)


_CERES_SHAPES = ((18, 36), (36, 72), (180, 360))
_TOMS_SHAPES = ((36, 18), (72, 36), (288, 180))
TOMS_GRIDS = {"10x10": "10x10", "5x5": "5x5", "1p25x1": "1p25x1"}
"""TOMS grid names of the files ``earthReflectivity{Mean,Std}_<grid>.dat``."""
# shapes (as written: longitude rows x latitude columns) of the TOMS files whose rows run
# east to west: the 5x5 and 10x10 grids (load_albedo_map reverses them)
_TOMS_EAST_TO_WEST = ((36, 18), (72, 36))


def load_albedo_map(path) -> AlbedoMap:
    """Load a CERES albedo CSV (shape 18×36, 36×72 or 180×360, values in [0, 1]) or a
    TOMS reflectivity ``.dat`` file (36×18, 72×36 or 288×180 in percent; transposed to the
    CERES layout — mean or standard-deviation files alike).

    TOMS longitude order: the rows of the 288×180 (1°×1.25°) files run west to east from
    −180°, those of the 72×36 (5°) and 36×18 (10°) files east to west; the coarse ones are
    reversed here, so that they are the 1°×1.25° map averaged over their cells (checked
    against the area-weighted 1°×1.25° map, docs/measurements.md "Coarse TOMS grids").
    O'Keefe (2015) §4.4 uses the three grids as one data set at three resolutions, so a
    coarse-grid filter must see the Earth its fine-grid truth flies over.

    Raises :class:`InputError` (naming the file and field) for a missing file, unparsable
    numbers, a wrong shape, NaN, or values outside [0, 1] (0–100 % for TOMS).
    """
    import io

    from ..io.safe_open import read_bytes

    path = Path(path)
    # a regular file of at most 16 MiB (a 1-degree CERES map is ~0.5 MB), size from the
    # opened descriptor, refused before reading
    data = io.BytesIO(read_bytes(path, max_bytes=_MAX_MAP_BYTES, what="albedo map file"))
    toms = path.suffix.lower() == ".dat"
    try:
        if toms:
            raw = np.loadtxt(data, dtype=float)
        else:
            raw = np.loadtxt(data, delimiter=",", dtype=float)
    except ValueError as exc:
        raise InputError(f"cannot parse numbers: {exc}", file=path, field="values") from None
    raw = np.atleast_2d(raw)
    if toms:
        if raw.shape not in _TOMS_SHAPES:
            raise InputError("TOMS reflectivity map has the wrong shape", file=path,
                             field="values", value=raw.shape,
                             allowed="36x18, 72x36 or 288x180 (rows longitude, columns latitude)")
        vals, scale_max = raw.T / 100.0, "0..100 percent"
        if raw.shape in _TOMS_EAST_TO_WEST:
            vals = np.ascontiguousarray(vals[:, ::-1])
    else:
        if raw.shape not in _CERES_SHAPES:
            raise InputError("albedo map has the wrong shape", file=path, field="values",
                             value=raw.shape,
                             allowed="18x36, 36x72 or 180x360 (rows latitude -90..90)")
        vals, scale_max = raw, "0..1"
    bad = ~np.isfinite(vals)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise InputError("albedo map contains NaN or infinite values", file=path,
                         field=f"values[row {r}, column {c}]" if not toms
                         else f"values[row {c}, column {r}]", allowed="finite numbers")
    if np.any(vals < 0) or np.any(vals > 1):
        raise InputError("albedo out of range", file=path, field="values",
                         value=float(vals.min() if vals.min() < 0 else vals.max()),
                         allowed=scale_max)
    return AlbedoMap.regular(vals, source=path.name)


@numba.njit(cache=True, inline="always")
def cell_irradiance_nb(centers, cnormals, rho_area, j, r_sat, s_hat):
    """Albedo irradiance ratio of grid cell ``j`` at ``r_sat`` and the unit direction to the cell.

    Eq. 2.15 for one cell: ``rho A cos(sun) cos(view) / (pi d^2)``, zero unless the cell is both
    sunlit and in view. Returns ``(ratio, ux, uy, uz)`` (Earth-fixed axes, u from the
    spacecraft towards the cell).
    """
    cs = cnormals[j, 0] * s_hat[0] + cnormals[j, 1] * s_hat[1] + cnormals[j, 2] * s_hat[2]
    if cs <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    dx = r_sat[0] - centers[j, 0]
    dy = r_sat[1] - centers[j, 1]
    dz = r_sat[2] - centers[j, 2]
    d2 = dx * dx + dy * dy + dz * dz
    d = np.sqrt(d2)
    cv = (cnormals[j, 0] * dx + cnormals[j, 1] * dy + cnormals[j, 2] * dz) / d
    if cv <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return rho_area[j] * cs * cv / (np.pi * d2), -dx / d, -dy / d, -dz / d


@numba.njit(cache=True)
def albedo_cells_nb(centers, cnormals, rho_area, r_sat, s_hat):
    """Per-cell irradiance ratios a_j (eq. 2.15) and unit spacecraft→cell directions.

    All vectors Earth-fixed; r_sat in m; s_hat unit Sun direction.  Returns (dirs (M,3),
    ratio (M,)) with ratio 0 for cells not both sunlit and in view.
    """
    M = centers.shape[0]
    dirs = np.zeros((M, 3))
    ratio = np.zeros(M)
    for j in range(M):
        a, ux, uy, uz = cell_irradiance_nb(centers, cnormals, rho_area, j, r_sat, s_hat)
        if a == 0.0:
            continue
        ratio[j] = a
        dirs[j, 0] = ux
        dirs[j, 1] = uy
        dirs[j, 2] = uz
    return dirs, ratio


def albedo_cells_in_view(grid: AlbedoGrid, r_sat_m, sun_hat):
    """Cells that are sunlit and in view, Earth-fixed axes.

    Returns ``(dirs, ratio)``: unit spacecraft→cell directions (M', 3) and irradiance ratios
    a_j (M',) in units of the solar irradiance at the spacecraft (eq. 2.15).
    """
    r = np.asarray(r_sat_m, dtype=float)
    s = np.asarray(sun_hat, dtype=float)
    s = s / np.linalg.norm(s)
    dirs, ratio = albedo_cells_nb(grid.centers_m, grid.normals, grid.rho_area_m2, r, s)
    keep = ratio > 0
    return dirs[keep], ratio[keep]


def earth_rotation_angle(epoch_utc: str, t_s):
    """Greenwich mean sidereal angle (rad) at ``t_s`` seconds after ``epoch_utc``.

    Used to rotate ECI (GCRS) vectors into the Earth-fixed frame of the albedo maps as
    ``r_E = R3(θ) r_I``; precession, nutation and polar motion (< 0.5° for current epochs)
    are neglected, which is far below the resolution of any albedo map.
    """
    theta0 = timescale().from_datetime(parse_epoch(epoch_utc)).gmst / 24.0 * 2.0 * np.pi
    return theta0 + OMEGA_EARTH * np.asarray(t_s, dtype=float)


def load_toms(grid: str = "1p25x1", directory=None):
    """The TOMS 2000–2005 mean reflectivity and its standard deviation (O'Keefe 2015 §2.1.2.1,
    fig. 2.4) on ``grid`` ("1p25x1" = 1°×1.25°, "5x5", "10x10"), as two :class:`AlbedoMap`
    (fractions, CERES layout).

    ``directory`` holds ``earthReflectivity{Mean,Std}_<grid>.dat`` (default
    ``../shared/data/earth_albedo`` beside the repository, or $LIGHTCURVE_SHARED_DATA);
    :class:`InputError` names the missing file.

    The longitude order of each file is :func:`load_albedo_map`'s (the coarse files list
    their longitudes the other way round from the 1°×1.25° ones).
    """
    if grid not in TOMS_GRIDS:
        raise InputError("unknown TOMS grid", field="grid", value=grid,
                         allowed=", ".join(TOMS_GRIDS))
    if directory is None:
        base = shared_data_dir()
        if base is None:
            raise InputError("TOMS albedo data not found: pass the folder or set "
                             "LIGHTCURVE_SHARED_DATA", field="albedo",
                             allowed="a folder with earthReflectivityMean_<grid>.dat")
        directory = base / "earth_albedo"
    d = Path(directory)
    mean = load_albedo_map(d / f"earthReflectivityMean_{grid}.dat")
    std = load_albedo_map(d / f"earthReflectivityStd_{grid}.dat")
    return mean, std


def draw_albedo_map(mean: AlbedoMap, std: AlbedoMap, rng) -> AlbedoMap:
    """One realisation of the albedo: every cell N(mean, std²) independently, clipped to
    [0, 1] (O'Keefe 2015 §2.1.2.1 uses the TOMS mean and standard deviation "to generate
    statistically accurate values"; how is left open — this is our choice, one draw per cell
    held over a run)."""
    g = as_generator(rng)
    v = np.clip(mean.values + std.values * g.standard_normal(mean.values.shape), 0.0, 1.0)
    return AlbedoMap(v, mean.lat_edges_rad, mean.lon_edges_rad, mean.source + "+draw")
