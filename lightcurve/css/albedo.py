"""Earth albedo irradiance at a spacecraft (O'Keefe 2015, eq. 2.15-2.18).

The Earth is divided into latitude/longitude cells on the WGS84 ellipsoid.  Cell ``j`` has
albedo ``ρ_j`` (fraction of the incident sunlight reflected, Lambertian), area ``A_j``,
centre ``r_j`` and outward geodetic normal ``n̂_j`` (Earth-fixed axes).  With ``ŝ`` the unit
Sun direction and ``r`` the spacecraft position (both Earth-fixed), the irradiance that the
cell produces at the spacecraft on a surface facing it, in units of the solar irradiance
(eq. 2.15)::

    a_j = ρ_j A_j (n̂_j·ŝ) (n̂_j·û_j) / (π d_j²),     û_j = (r − r_j)/d_j,  d_j = |r − r_j|

counted only for cells that are both sunlit (``n̂_j·ŝ > 0``) and in view (``n̂_j·û_j > 0``).
A CSS with normal ``n̂`` then receives ``Σ_j a_j f(−û_j)`` (see :mod:`lightcurve.css.sensors`).
The Sun is far enough that the solar irradiance at the cell equals that at the spacecraft.

Cell areas are exact ellipsoidal areas computed through the authalic latitude β
(eq. 2.16-2.18)::

    q(φ) = (1−e²) [ sinφ/(1−e² sin²φ) − 1/(2e) ln((1−e sinφ)/(1+e sinφ)) ]
    sin β = q(φ)/q_p,   q_p = q(π/2),   R_q = a √(q_p/2)
    A = R_q² (λ₂ − λ₁)(sin β₂ − sin β₁)

so the cells add up to the ellipsoid's surface area.

Maps: CERES 2018 albedo CSV files (rows latitude −90…90 south to north, columns longitude
−180…180; 18×36, 36×72 or 180×360) and the 10° TOMS mean reflectivity file (percent, 36
rows of longitude × 18 columns of latitude, i.e. transposed).  The default map is the
built-in zonal model :func:`zonal_albedo`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

from ..errors import InputError
from ..io.safe_open import ALBEDO_MAX_BYTES as _MAX_MAP_BYTES

__all__ = [
    "WGS84_A_M", "WGS84_F", "ZONAL_LEGENDRE_COEFFS", "AlbedoMap", "AlbedoGrid",
    "authalic_latitude", "cell_areas_m2", "zonal_albedo", "builtin_albedo_map",
    "load_albedo_map", "fit_zonal_coefficients", "albedo_cells_in_view",
    "albedo_on_sensors_nb", "albedo_cells_nb", "earth_rotation_angle",
    "albedo_sun_frame_nb", "expected_albedo_nb", "albedo_phi_nb", "sun_nadir_axis_nb",
]

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
_E2 = WGS84_F * (2.0 - WGS84_F)
_E = np.sqrt(_E2)
OMEGA_EARTH_RAD_S = 7.292115e-5

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


def load_albedo_map(path) -> AlbedoMap:
    """Load a CERES albedo CSV (shape 18×36, 36×72 or 180×360, values in [0, 1]) or the
    10° TOMS reflectivity ``.dat`` file (36×18 in percent; transposed to CERES layout).

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
        if raw.shape != (36, 18):
            raise InputError("TOMS reflectivity map has the wrong shape", file=path,
                             field="values", value=raw.shape,
                             allowed="36 rows (longitude) x 18 columns (latitude)")
        vals, scale_max = raw.T / 100.0, "0..100 percent"
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


@numba.njit(cache=True)
def albedo_on_sensors_nb(centers, cnormals, rho_area, r_sat, s_hat, sens_normals, cos_fov,
                         horizon):
    """Albedo irradiance (units of solar irradiance) on each sensor, Earth-fixed axes.

    sens_normals (N,3) and horizon (N,3) are the sensors' (true) normals and structure-horizon
    plane normals rotated into Earth-fixed axes; cos_fov (N,) FOV cosines.  Returns (N,).
    """
    n_s = sens_normals.shape[0]
    out = np.zeros(n_s)
    for j in range(centers.shape[0]):
        a, ux, uy, uz = cell_irradiance_nb(centers, cnormals, rho_area, j, r_sat, s_hat)
        if a == 0.0:
            continue
        for k in range(n_s):
            c = sens_normals[k, 0] * ux + sens_normals[k, 1] * uy + sens_normals[k, 2] * uz
            if c < cos_fov[k] or c <= 0.0:
                continue
            if horizon[k, 0] * ux + horizon[k, 1] * uy + horizon[k, 2] * uz < 0.0:
                continue
            out[k] += a * c
    return out


@numba.njit(cache=True)
def sun_nadir_axis_nb(r_sat, s_hat):
    """Unit component of the nadir direction ``−r̂`` perpendicular to the unit Sun direction
    ``s_hat`` (any perpendicular when nadir is parallel to the Sun line); any frame."""
    rn = np.sqrt(r_sat[0] ** 2 + r_sat[1] ** 2 + r_sat[2] ** 2)
    nad = -r_sat / rn
    c = nad[0] * s_hat[0] + nad[1] * s_hat[1] + nad[2] * s_hat[2]
    e2 = nad - c * s_hat
    n2 = np.sqrt(e2[0] ** 2 + e2[1] ** 2 + e2[2] ** 2)
    if n2 < 1e-9:
        k = 0 if abs(s_hat[0]) < 0.9 else 1
        ax = np.zeros(3)
        ax[k] = 1.0
        e2 = ax - s_hat[k] * s_hat
        n2 = np.sqrt(e2[0] ** 2 + e2[1] ** 2 + e2[2] ** 2)
    return e2 / n2


@numba.njit(cache=True)
def albedo_sun_frame_nb(centers, cnormals, rho_area, r_sat, s_hat):
    """Sunlit, in-view cells (eq. 2.15) with their directions in the Sun–nadir frame.

    The frame is attitude-free: ``e₁ = ŝ`` (unit Sun direction), ``e₂`` the unit component
    of the nadir direction ``−r̂`` perpendicular to ``ŝ`` (:func:`sun_nadir_axis_nb`),
    ``e₃ = e₁ × e₂``.  All inputs Earth-fixed; r_sat in m.
    Returns ``(coords (M,3), ratio (M,), m)``: the first ``m`` rows hold the components of the
    unit spacecraft→cell direction on (e₁, e₂, e₃) and the irradiance ratio a_j.
    """
    e1 = s_hat / np.sqrt(s_hat[0] ** 2 + s_hat[1] ** 2 + s_hat[2] ** 2)
    e2 = sun_nadir_axis_nb(r_sat, e1)
    e3 = np.array([e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                   e1[0] * e2[1] - e1[1] * e2[0]])
    M = centers.shape[0]
    coords = np.empty((M, 3))
    ratio = np.empty(M)
    m = 0
    for j in range(M):
        a, ux, uy, uz = cell_irradiance_nb(centers, cnormals, rho_area, j, r_sat, e1)
        if a == 0.0:
            continue
        coords[m, 0] = ux * e1[0] + uy * e1[1] + uz * e1[2]
        coords[m, 1] = ux * e2[0] + uy * e2[1] + uz * e2[2]
        coords[m, 2] = ux * e3[0] + uy * e3[1] + uz * e3[2]
        ratio[m] = a
        m += 1
    return coords, ratio, m


@numba.njit(cache=True)
def albedo_phi_nb(coords, ratio, m, s_b, ref_b, sens_normals, cos_fov, horizon, n_phi, out):
    """Albedo irradiance on each sensor for ``n_phi`` rotations φ about the Sun line.

    A sun-line estimator knows ``s_b`` (unit Sun direction, body axes) but not the rotation
    φ of the body about the Sun line, which fixes where the Earth is in body axes.  With
    ``b₁ = s_b``, ``b₂`` the unit part of ``ref_b`` perpendicular to ``b₁`` (any perpendicular
    if ``ref_b`` is zero or parallel) and ``b₃ = b₁ × b₂``, hypothesis ``i`` (φ_i = 2π i/n_phi)
    places the Sun–nadir frame of :func:`albedo_sun_frame_nb` in body axes as
    ``e₁ → b₁, e₂ → cos φ b₂ + sin φ b₃, e₃ → −sin φ b₂ + cos φ b₃`` and evaluates eq. 2.15's
    sensor sum ``Σ_j a_j f_κ(û_j)`` (cosine response, FOV, structure horizon as in
    :mod:`lightcurve.css.sensors`).  Writes ``out[i, κ]`` (n_phi, N), units of the solar
    irradiance at the spacecraft, nominal unit-gain sensors.
    """
    n_s = sens_normals.shape[0]
    b1 = s_b / np.sqrt(s_b[0] ** 2 + s_b[1] ** 2 + s_b[2] ** 2)
    c = ref_b[0] * b1[0] + ref_b[1] * b1[1] + ref_b[2] * b1[2]
    b2 = ref_b - c * b1
    n2 = np.sqrt(b2[0] ** 2 + b2[1] ** 2 + b2[2] ** 2)
    if n2 < 1e-9:
        k = 0 if abs(b1[0]) < 0.9 else 1
        b2 = -b1[k] * b1
        b2[k] += 1.0
        n2 = np.sqrt(b2[0] ** 2 + b2[1] ** 2 + b2[2] ** 2)
    b2 = b2 / n2
    b3 = np.array([b1[1] * b2[2] - b1[2] * b2[1], b1[2] * b2[0] - b1[0] * b2[2],
                   b1[0] * b2[1] - b1[1] * b2[0]])
    for kk in range(n_s):
        nv = sens_normals[kk]
        hv = horizon[kk]
        n1 = nv[0] * b1[0] + nv[1] * b1[1] + nv[2] * b1[2]
        nn2 = nv[0] * b2[0] + nv[1] * b2[1] + nv[2] * b2[2]
        n3 = nv[0] * b3[0] + nv[1] * b3[1] + nv[2] * b3[2]
        h1 = hv[0] * b1[0] + hv[1] * b1[1] + hv[2] * b1[2]
        h2 = hv[0] * b2[0] + hv[1] * b2[1] + hv[2] * b2[2]
        h3 = hv[0] * b3[0] + hv[1] * b3[1] + hv[2] * b3[2]
        cf = cos_fov[kk]
        for i in range(n_phi):
            ph = 2.0 * np.pi * i / n_phi
            cp = np.cos(ph)
            sp = np.sin(ph)
            A = nn2 * cp + n3 * sp
            B = n3 * cp - nn2 * sp
            Ah = h2 * cp + h3 * sp
            Bh = h3 * cp - h2 * sp
            acc = 0.0
            for j in range(m):
                cc = n1 * coords[j, 0] + A * coords[j, 1] + B * coords[j, 2]
                if cc < cf or cc <= 0.0:
                    continue
                if h1 * coords[j, 0] + Ah * coords[j, 1] + Bh * coords[j, 2] < 0.0:
                    continue
                acc += ratio[j] * cc
            out[i, kk] = acc


@numba.njit(cache=True)
def expected_albedo_nb(coords, ratio, m, s_b, sens_normals, cos_fov, horizon, n_phi,
                       mean_out, var_out):
    """Mean and variance over a uniform rotation φ about the Sun line (an uninformative
    prior on the unobservable rotation; our modelling choice for a tumbling spacecraft) of
    the albedo on each sensor (:func:`albedo_phi_nb`).  Writes (N,) into ``mean_out`` and
    ``var_out`` (units of the solar irradiance at the spacecraft)."""
    n_s = sens_normals.shape[0]
    for kk in range(n_s):
        mean_out[kk] = 0.0
        var_out[kk] = 0.0
    if m == 0:
        return
    tab = np.empty((n_phi, n_s))
    albedo_phi_nb(coords, ratio, m, s_b, np.zeros(3), sens_normals, cos_fov, horizon, n_phi,
                  tab)
    for kk in range(n_s):
        mu = 0.0
        for i in range(n_phi):
            mu += tab[i, kk]
        mu /= n_phi
        v = 0.0
        for i in range(n_phi):
            v += (tab[i, kk] - mu) ** 2
        mean_out[kk] = mu
        var_out[kk] = v / n_phi


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
    from ..geometry.time import parse_epoch, timescale  # builtin timescale, no download

    theta0 = timescale().from_datetime(parse_epoch(epoch_utc)).gmst / 24.0 * 2.0 * np.pi
    return theta0 + OMEGA_EARTH_RAD_S * np.asarray(t_s, dtype=float)
