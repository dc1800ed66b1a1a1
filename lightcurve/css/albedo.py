"""Earth albedo on coarse sun sensors (O'Keefe 2015, eq. 2.15-2.21).

The Earth map, its cells and their irradiance at the spacecraft (eq. 2.15-2.18), the TOMS
maps and their random draws live in :mod:`lightcurve.earth.albedo` (re-exported here); this
module adds what the sensors see of them: a CSS with normal ``n̂`` receives
``Σ_j a_j f(−û_j)`` (see :mod:`lightcurve.css.sensors`), the filters' expected-albedo models
in the Sun frame, and the windowed cell sums of the truth simulation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..earth.albedo import (AUTHALIC_RADIUS_M, TOMS_GRIDS, WGS84_A_M, WGS84_F,
                            ZONAL_LEGENDRE_COEFFS, AlbedoGrid, AlbedoMap, albedo_cells_in_view,
                            albedo_cells_nb, authalic_latitude, builtin_albedo_map,
                            cell_areas_m2, cell_centers_ecef, cell_irradiance_nb,
                            draw_albedo_map, earth_rotation_angle, fit_zonal_coefficients,
                            load_albedo_map, load_toms, zonal_albedo)

__all__ = [
    "WGS84_A_M", "WGS84_F", "ZONAL_LEGENDRE_COEFFS", "AUTHALIC_RADIUS_M", "AlbedoMap",
    "AlbedoGrid", "authalic_latitude", "cell_areas_m2", "cell_centers_ecef", "zonal_albedo",
    "builtin_albedo_map", "load_albedo_map", "fit_zonal_coefficients", "albedo_cells_in_view",
    "albedo_on_sensors_nb", "albedo_cells_nb", "cell_irradiance_nb", "earth_rotation_angle",
    "albedo_sun_frame_nb", "expected_albedo_nb", "albedo_phi_nb", "sun_nadir_axis_nb",
    "TOMS_GRIDS", "load_toms", "draw_albedo_map", "AlbedoCells", "albedo_vectors_nb",
    "albedo_coefficient_cov_nb", "cap_cells_nb", "cells_vectors_nb", "cells_coefficient_cov_nb",
]


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


# ---------------------------------------------------------------------------------------
# albedo grid with row/column structure (window search)
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AlbedoCells:
    """Earth-fixed cell geometry of a regular albedo map, kept on its (nlat, nlon) grid.

    centers_m (nlat·nlon, 3) m, normals (nlat·nlon, 3) unit geodetic normals, rho_area_m2
    (nlat·nlon,) = ρ A (m²), lat_c (nlat,) rad cell-centre latitudes, lon_w0 rad west edge of
    column 0, dlon rad column width, dlat_max rad largest row height.
    """

    centers_m: np.ndarray
    normals: np.ndarray
    rho_area_m2: np.ndarray
    lat_c: np.ndarray
    nlat: int
    nlon: int
    lon_w0: float
    dlon: float
    dlat_max: float
    source: str = "map"

    @classmethod
    def from_map(cls, amap: AlbedoMap) -> "AlbedoCells":
        lat_e, lon_e = np.asarray(amap.lat_edges_rad), np.asarray(amap.lon_edges_rad)
        # cell centres at the authalic-latitude midpoint, as AlbedoGrid (the truth model)
        centers, normals, lat_c, lon_c = cell_centers_ecef(lat_e, lon_e)
        ra = (cell_areas_m2(lat_e, lon_e) * amap.values).reshape(-1)
        dlon = float(np.mean(np.diff(lon_e)))
        if not np.allclose(np.diff(lon_e), dlon):
            raise ValueError("AlbedoCells needs equal-width longitude columns")
        return cls(np.ascontiguousarray(centers), np.ascontiguousarray(normals),
                   np.ascontiguousarray(ra), lat_c, lat_c.size, lon_c.size, float(lon_e[0]),
                   dlon, float(np.max(np.diff(lat_e))), amap.source)

    @classmethod
    def none(cls) -> "AlbedoCells":
        """An empty grid (no albedo)."""
        z = np.zeros((0, 3))
        return cls(z, z.copy(), np.zeros(0), np.zeros(0), 0, 0, -np.pi, 2 * np.pi, np.pi, "none")

    def args(self):
        return (self.centers_m, self.normals, self.rho_area_m2, self.lat_c, self.nlat, self.nlon,
                self.lon_w0, self.dlon, self.dlat_max)


@numba.njit(cache=True, inline="always")
def _cap_row_columns(lat_i, phi, lon, cos_l, nlon, lon_w0, dlon):
    """First column and number of columns of one grid row (latitude ``lat_i``) that can lie
    in the spherical cap of angular radius arccos(``cos_l``) centred at (``phi``, ``lon``):
    the cap's longitude half-width at that latitude, cos Δλ = (cos λ − sin φᵢ sin φ)/(cos φᵢ
    cos φ), widened by one column.  (0, 0) when the row misses the cap."""
    den = np.cos(lat_i) * np.cos(phi)
    cl = (cos_l - np.sin(lat_i) * np.sin(phi)) / den if den > 1e-12 else -2.0
    if cl >= 1.0:
        return 0, 0
    if cl <= -1.0:
        return 0, nlon
    half = np.arccos(cl) + dlon
    c0 = int(np.floor((lon - half - lon_w0) / dlon))
    ncol = int(np.ceil(2.0 * half / dlon)) + 2
    if ncol > nlon:
        return 0, nlon
    return c0, ncol


@numba.njit(cache=True)
def cap_cells_nb(centers, cnormals, rho_area, lat_c, nlat, nlon, lon_w0, dlon, dlat_max, r_E,
                 s_E, sig_area=np.zeros(0)):
    """The cells of a gridded map (:class:`AlbedoCells`) that are sunlit and in view of the
    spacecraft at ``r_E`` (m) with the unit Sun direction ``s_E`` (both Earth-fixed): their
    irradiance ratios a_j (eq. 2.15) and unit spacecraft→cell directions, in grid order.

    Only the rows and columns of the cap visible from ``r_E`` are visited
    (:func:`_cap_row_columns`).  ``sig_area`` (cells,): σ_j A_j of the map's spread (m²),
    optional; gives ``w_j = a_j σ_j / ρ_j`` (the irradiance per unit albedo times σ_j; 0
    where σ_j A_j ≤ 0).  Returns (U (m,3), a (m,), w (m,), m, number of cells evaluated:
    those of the cap with ρ_j A_j > 0)."""
    n_cap = 0
    if nlat == 0:
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0), 0, 0
    rn = np.sqrt(r_E[0] ** 2 + r_E[1] ** 2 + r_E[2] ** 2)
    lam0 = np.arccos(min(1.0, 6356752.0 / rn))  # visible cap half angle (polar radius: safe)
    phi = np.arcsin(r_E[2] / rn)
    lon = np.arctan2(r_E[1], r_E[0])
    lo = phi - lam0 - dlat_max
    hi = phi + lam0 + dlat_max
    cos_l = np.cos(min(np.pi, lam0 + dlat_max + 0.01))
    for i in range(nlat):
        if lat_c[i] < lo or lat_c[i] > hi:
            continue
        c0, ncol = _cap_row_columns(lat_c[i], phi, lon, cos_l, nlon, lon_w0, dlon)
        n_cap += ncol
    U = np.empty((n_cap, 3))
    a_out = np.empty(n_cap)
    w_out = np.zeros(n_cap)
    with_sig = sig_area.shape[0] == rho_area.shape[0]
    m = 0
    count = 0
    for i in range(nlat):
        if lat_c[i] < lo or lat_c[i] > hi:
            continue
        c0, ncol = _cap_row_columns(lat_c[i], phi, lon, cos_l, nlon, lon_w0, dlon)
        for cc in range(ncol):
            j = i * nlon + (c0 + cc) % nlon
            if rho_area[j] <= 0.0:
                continue
            count += 1
            a, ux, uy, uz = cell_irradiance_nb(centers, cnormals, rho_area, j, r_E, s_E)
            if a == 0.0:
                continue
            U[m, 0] = ux
            U[m, 1] = uy
            U[m, 2] = uz
            a_out[m] = a
            if with_sig and sig_area[j] > 0.0:
                w_out[m] = a / rho_area[j] * sig_area[j]
            m += 1
    return U, a_out, w_out, m, count


@numba.njit(cache=True, inline="always")
def _columns_nb(v):
    """The three columns of an (N,3) array as contiguous (N,) arrays (the layout of the
    sensor loops below)."""
    return (np.ascontiguousarray(v[:, 0]), np.ascontiguousarray(v[:, 1]),
            np.ascontiguousarray(v[:, 2]))


@numba.njit(cache=True)
def cells_vectors_nb(U, a, m, nE, cos_fov, hE, edge_m):
    """Per-sensor albedo vector sums V_κ = Σ a_j û_j (N,3) over the first ``m`` cells of
    :func:`cap_cells_nb` that lie inside sensor κ's FOV (cosine above ``cos_fov[κ]`` and
    positive) and in front of its structure horizon (``hE[κ]·û ≥ 0``; a zero row: none),
    and ``A_edge`` (N,): Σ a_j c_j of the cells whose cosine lies within ``edge_m[κ]`` of the
    cut-off (their FOV membership is uncertain).  Normals ``nE`` and horizons ``hE`` in the
    cells' axes.  The sensors are the inner loop (vectorised); each sum runs over the cells
    in grid order."""
    N = nE.shape[0]
    nx, ny, nz = _columns_nb(nE)
    hx, hy, hz = _columns_nb(hE)
    vx = np.zeros(N)
    vy = np.zeros(N)
    vz = np.zeros(N)
    ae = np.zeros(N)
    for j in range(m):
        ux, uy, uz, aj = U[j, 0], U[j, 1], U[j, 2], a[j]
        for k in range(N):
            c = nx[k] * ux + ny[k] * uy + nz[k] * uz
            hd = hx[k] * ux + hy[k] * uy + hz[k] * uz
            # bitwise & (no short circuit) keeps the sensor loop branch-free
            ae[k] += aj * c if (c > 0.0) & (abs(c - cos_fov[k]) < edge_m[k]) else 0.0
            w = aj if (c >= cos_fov[k]) & (c > 0.0) & (hd >= 0.0) else 0.0
            vx[k] += w * ux
            vy[k] += w * uy
            vz[k] += w * uz
    V = np.empty((N, 3))
    for k in range(N):
        V[k, 0] = vx[k]
        V[k, 1] = vy[k]
        V[k, 2] = vz[k]
    return V, ae


@numba.njit(cache=True)
def cells_coefficient_cov_nb(U, w, m, nE, cos_fov, hE, diag_only=False):
    """Covariance (N,N) of the albedo irradiance on the sensors from the spread of the
    cells' albedo coefficients (O'Keefe 2015 eq. 4.27 ν_α, eq. 4.30b), ``Σ_j w_j² c_ij c_kj``
    over the first ``m`` cells of :func:`cap_cells_nb` (``w`` its σ-weighted irradiance per
    unit albedo) inside both sensors' FOV and in front of their structure horizons (as
    :func:`cells_vectors_nb`); c_ij the cosine on sensor i.  ``diag_only``: the variances
    only.  The sensors are the inner loops; each sum runs over the cells in grid order."""
    N = nE.shape[0]
    Ra = np.zeros((N, N))
    nx, ny, nz = _columns_nb(nE)
    hx, hy, hz = _columns_nb(hE)
    cvec = np.zeros(N)
    for j in range(m):
        wj = w[j]
        if wj == 0.0:
            continue
        ux, uy, uz = U[j, 0], U[j, 1], U[j, 2]
        anyc = False
        for k in range(N):
            c = nx[k] * ux + ny[k] * uy + nz[k] * uz
            hd = hx[k] * ux + hy[k] * uy + hz[k] * uz
            ok = (c >= cos_fov[k]) & (c > 0.0) & (hd >= 0.0)
            cvec[k] = wj * c if ok else 0.0
            anyc = anyc | ok
        if not anyc:
            continue
        if diag_only:
            for k in range(N):
                Ra[k, k] += cvec[k] * cvec[k]
        else:
            for k in range(N):
                ck = cvec[k]
                if ck != 0.0:
                    for mm in range(N):
                        Ra[k, mm] += ck * cvec[mm]
    return Ra


@numba.njit(cache=True)
def albedo_vectors_nb(centers, cnormals, rho_area, lat_c, nlat, nlon, lon_w0, dlon, dlat_max,
                      r_E, s_E, nE, cos_fov, hE, edge_m):
    """Per-sensor albedo vector sums V_κ = Σ a_j ĉ_j (Earth-fixed, (N,3)) over the cells that
    are sunlit, in view of the spacecraft and inside sensor κ's FOV (normals nE (N,3),
    structure-horizon normals hE (N,3), Earth-fixed): :func:`cap_cells_nb` then
    :func:`cells_vectors_nb`.  ``edge_m`` (N,): cosine margin about each FOV cut-off; the
    irradiance Σ a_j c_j of the cells inside that band (whose membership is uncertain) is
    returned as ``A_edge``.  Returns (V (N,3), A_edge (N,), number of cells evaluated)."""
    U, a, _, m, count = cap_cells_nb(centers, cnormals, rho_area, lat_c, nlat, nlon, lon_w0,
                                     dlon, dlat_max, r_E, s_E)
    V, Aedge = cells_vectors_nb(U, a, m, nE, cos_fov, hE, edge_m)
    return V, Aedge, count


@numba.njit(cache=True)
def albedo_coefficient_cov_nb(centers, cnormals, rho_area, sig_area, lat_c, nlat, nlon, lon_w0,
                              dlon, dlat_max, r_E, s_E, nE, cos_fov, hE, diag_only=False):
    """Covariance (N,N) of the albedo irradiance on the sensors caused by the uncertainty of
    the cells' albedo coefficients (O'Keefe 2015 eq. 4.27 ν_α, eq. 4.30b): with the TOMS
    standard deviation σ_j of cell j (``sig_area`` = σ_j A_j, m²) and its irradiance per unit
    albedo cos(sun) cos(view)/(π d²), :func:`cells_coefficient_cov_nb` over the sunlit cells
    in view (:func:`cap_cells_nb`).  Units of the solar irradiance squared, before the sensor
    scale factors.  ``diag_only``: only the variances (the diagonal; the rest stays zero)."""
    U, _, w, m, _ = cap_cells_nb(centers, cnormals, rho_area, lat_c, nlat, nlon, lon_w0, dlon,
                                 dlat_max, r_E, s_E, sig_area)
    return cells_coefficient_cov_nb(U, w, m, nE, cos_fov, hE, diag_only)
    rn = np.sqrt(r_E[0] ** 2 + r_E[1] ** 2 + r_E[2] ** 2)
    lam0 = np.arccos(min(1.0, 6356752.0 / rn))
    phi = np.arcsin(r_E[2] / rn)
    lon = np.arctan2(r_E[1], r_E[0])
    lo = phi - lam0 - dlat_max
    hi = phi + lam0 + dlat_max
    cos_l = np.cos(min(np.pi, lam0 + dlat_max + 0.01))
    cvec = np.zeros(N)
    for i in range(nlat):
        if lat_c[i] < lo or lat_c[i] > hi:
            continue
        c0, ncol = _cap_row_columns(lat_c[i], phi, lon, cos_l, nlon, lon_w0, dlon)
        for cc in range(ncol):
            j = i * nlon + (c0 + cc) % nlon
            if rho_area[j] <= 0.0 or sig_area[j] <= 0.0:
                continue
            a, ux, uy, uz = cell_irradiance_nb(centers, cnormals, rho_area, j, r_E, s_E)
            if a == 0.0:
                continue
            w = a / rho_area[j] * sig_area[j]
            anyc = False
            for k in range(N):
                c = nE[k, 0] * ux + nE[k, 1] * uy + nE[k, 2] * uz
                cvec[k] = 0.0
                if c < cos_fov[k] or c <= 0.0:
                    continue
                if hE[k, 0] * ux + hE[k, 1] * uy + hE[k, 2] * uz < 0.0:
                    continue
                cvec[k] = w * c
                anyc = True
            if anyc:
                for k in range(N):
                    if cvec[k] != 0.0:
                        if diag_only:
                            Ra[k, k] += cvec[k] * cvec[k]
                            continue
                        for m in range(N):
                            Ra[k, m] += cvec[k] * cvec[m]
    return Ra
