"""Earth albedo on coarse sun sensors (O'Keefe 2015, eq. 2.15-2.21).

The Earth map, its cells and their irradiance at the spacecraft (eq. 2.15-2.18) live in
:mod:`lightcurve.earth.albedo` (re-exported here); this module adds what the sensors see of
them: a CSS with normal ``n̂`` receives ``Σ_j a_j f(−û_j)`` (see :mod:`lightcurve.css.sensors`),
and the filters' expected-albedo models in the Sun frame.
"""

from __future__ import annotations

import numba
import numpy as np

from ..earth.albedo import (AUTHALIC_RADIUS_M, WGS84_A_M, WGS84_F, ZONAL_LEGENDRE_COEFFS,
                            AlbedoGrid, AlbedoMap, albedo_cells_in_view, albedo_cells_nb,
                            authalic_latitude, builtin_albedo_map, cell_areas_m2,
                            cell_centers_ecef, cell_irradiance_nb, earth_rotation_angle,
                            fit_zonal_coefficients, load_albedo_map, zonal_albedo)

__all__ = [
    "WGS84_A_M", "WGS84_F", "ZONAL_LEGENDRE_COEFFS", "AUTHALIC_RADIUS_M", "AlbedoMap",
    "AlbedoGrid", "authalic_latitude", "cell_areas_m2", "cell_centers_ecef", "zonal_albedo",
    "builtin_albedo_map", "load_albedo_map", "fit_zonal_coefficients", "albedo_cells_in_view",
    "albedo_on_sensors_nb", "albedo_cells_nb", "cell_irradiance_nb", "earth_rotation_angle",
    "albedo_sun_frame_nb", "expected_albedo_nb", "albedo_phi_nb", "sun_nadir_axis_nb",
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
