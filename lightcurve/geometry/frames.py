"""Reference frames: GCRS (our ECI) ↔ ITRS (ECEF), orbit frames (LVLH, RSW) and topocentric alt/az.

Every DCM here is *passive*, like the attitude matrices of :mod:`lightcurve.rotations`:
``v_F = C v_ECI``, so the **rows** of ``C`` are the frame's unit axes expressed in ECI.
Arrays of N epochs have shape ``(N, 3, 3)``.

GCRS ↔ ITRS uses skyfield's ``framelib.itrs`` rotation (IAU 2000A precession–nutation,
Greenwich apparent sidereal time from skyfield's builtin UT1; polar motion is not applied —
the builtin timescale carries no polar-motion table; its effect is < 15 m at the surface).
"""

from __future__ import annotations

import numpy as np

from .sites import enu_matrix, get_site, site_itrs_m
from .time import is_time, skyfield_times

__all__ = [
    "OMEGA_EARTH_RAD_S",
    "itrs_rotation",
    "gcrs_to_itrs",
    "itrs_to_gcrs",
    "gcrs_to_itrs_state",
    "itrs_to_gcrs_state",
    "earth_pole_gcrs",
    "lvlh_dcm",
    "nadir_dcm",
    "rsw_dcm",
    "topocentric_enu",
    "altaz",
    "enu_to_altaz",
    "altaz_to_enu",
]

OMEGA_EARTH_RAD_S = 7.292115e-5
"""Earth rotation rate (rad/s), the constant skyfield uses for ITRS velocities (IERS conventions)."""


def _times(epoch_utc, t_s):
    return epoch_utc if is_time(epoch_utc) else skyfield_times(epoch_utc, t_s)


_INTERP_MIN_N = 64
_INTERP_NODE_S = 3600.0


def itrs_rotation(epoch_utc, t_s=0.0, *, exact: bool = False) -> np.ndarray:
    """Rotation matrices GCRS → ITRS, shape ``(N, 3, 3)``: ``r_itrs = R r_gcrs``.

    ``epoch_utc`` may be a skyfield ``Time`` (then ``t_s`` is ignored).

    ``R = R3(GAST) · M`` with ``M`` skyfield's precession–nutation–frame-bias matrix. The IAU
    2000A nutation series dominates the cost (≈0.2 ms per epoch), so for more than 64 epochs
    (unless ``exact=True``) ``M`` and the equation of the equinoxes are evaluated exactly at
    nodes one hour apart and interpolated linearly, while Greenwich *mean* sidereal time
    (cheap) is computed at every epoch. The shortest nutation terms with any amplitude have
    periods of days, so the interpolation error is < 1e-10 rad (< 1 mm at the Earth's
    surface); tests compare against the exact matrices.
    """
    from skyfield.framelib import itrs

    t = _times(epoch_utc, t_s)
    n = np.size(t.tt)
    if exact or n < _INTERP_MIN_N or t.ts.polar_motion_table is not None:
        R = np.asarray(itrs.rotation_at(t), dtype=float)
        if R.ndim == 2:
            R = R[:, :, None]
        return np.ascontiguousarray(np.moveaxis(R, -1, 0))
    tt = np.atleast_1d(t.tt)
    tt0 = tt.min()
    x = (tt - tt0) * 86400.0                               # s since the first epoch (TT)
    span = x.max()
    k = max(2, int(np.ceil(span / _INTERP_NODE_S)) + 1)
    xn = np.linspace(0.0, span, k) if span > 0 else np.array([0.0, 1.0])
    tn = t.ts.tt_jd(tt0 + xn / 86400.0)
    Mn = np.asarray(tn.M, dtype=float)                     # (3, 3, K)
    eqeq_n = ((tn.gast - tn.gmst + 12.0) % 24.0) - 12.0     # hours, small
    M = np.empty((n, 3, 3))
    for i in range(3):
        for j in range(3):
            M[:, i, j] = np.interp(x, xn, Mn[i, j])
    gast = np.atleast_1d(t.gmst) + np.interp(x, xn, eqeq_n)
    th = gast * (2 * np.pi / 24.0)
    c, s = np.cos(th), np.sin(th)
    # rot_z(-θ) in skyfield's convention = passive rotation by θ about z
    Rz = np.zeros((n, 3, 3))
    Rz[:, 0, 0] = c
    Rz[:, 0, 1] = s
    Rz[:, 1, 0] = -s
    Rz[:, 1, 1] = c
    Rz[:, 2, 2] = 1.0
    return np.einsum("nij,njk->nik", Rz, M)


def _rows(x, name):
    a = np.asarray(x, dtype=float)
    if a.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (3,) or (N, 3), got {a.shape}")
    return np.atleast_2d(a)


def gcrs_to_itrs(r_gcrs_m, epoch_utc, t_s=0.0) -> np.ndarray:
    """GCRS position(s) → ITRS, metres, ``(N, 3)`` (one epoch per row, or one epoch for all)."""
    r = _rows(r_gcrs_m, "r_gcrs_m")
    R = itrs_rotation(epoch_utc, t_s)
    return np.einsum("nij,nj->ni", R, np.broadcast_to(r, (max(len(R), len(r)), 3)))


def itrs_to_gcrs(r_itrs_m, epoch_utc, t_s=0.0) -> np.ndarray:
    """ITRS position(s) → GCRS, metres, ``(N, 3)``."""
    r = _rows(r_itrs_m, "r_itrs_m")
    R = itrs_rotation(epoch_utc, t_s)
    return np.einsum("nji,nj->ni", R, np.broadcast_to(r, (max(len(R), len(r)), 3)))


def _omega_itrs():
    return np.array([0.0, 0.0, OMEGA_EARTH_RAD_S])


def gcrs_to_itrs_state(r_gcrs_m, v_gcrs_m_s, epoch_utc, t_s=0.0):
    """GCRS state → ITRS state: ``r_F = R r``, ``v_F = R v − ω⊕ × r_F`` (m, m/s)."""
    r_f = gcrs_to_itrs(r_gcrs_m, epoch_utc, t_s)
    v_f = gcrs_to_itrs(v_gcrs_m_s, epoch_utc, t_s) - np.cross(_omega_itrs(), r_f)
    return r_f, v_f


def itrs_to_gcrs_state(r_itrs_m, v_itrs_m_s, epoch_utc, t_s=0.0):
    """ITRS state → GCRS state: ``r = Rᵀ r_F``, ``v = Rᵀ (v_F + ω⊕ × r_F)`` (m, m/s)."""
    r_f = _rows(r_itrs_m, "r_itrs_m")
    v_f = _rows(v_itrs_m_s, "v_itrs_m_s") + np.cross(_omega_itrs(), r_f)
    return itrs_to_gcrs(r_f, epoch_utc, t_s), itrs_to_gcrs(v_f, epoch_utc, t_s)


def earth_pole_gcrs(epoch_utc, t_s=0.0) -> np.ndarray:
    """Unit vector of the Earth's rotation pole (ITRS z axis = CIP) in GCRS, ``(N, 3)``.

    Differs from GCRS z by precession–nutation (≈0.1° in 2020). Zonal gravity uses it.
    """
    return itrs_rotation(epoch_utc, t_s)[:, 2, :]


def _unit(x):
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def lvlh_dcm(r_m, v_m_s) -> np.ndarray:
    """ECI → LVLH (local-vertical/local-horizontal) DCM, shape ``(..., 3, 3)``.

    Axes (Markley & Crassidis 2014, eq. 2.77; the nadir-pointing orbit frame):
    ``o3 = −r/|r|`` (nadir), ``o2 = −(r × v)/|r × v|`` (negative orbit normal),
    ``o1 = o2 × o3`` (along-track, equal to v̂ on a circular orbit).
    Rows of the result are ``o1, o2, o3`` in ECI: ``v_LVLH = C v_ECI``.
    """
    r = np.asarray(r_m, dtype=float)
    v = np.asarray(v_m_s, dtype=float)
    o3 = -_unit(r)
    o2 = -_unit(np.cross(r, v))
    o1 = np.cross(o2, o3)
    return np.stack([o1, o2, o3], axis=-2)


def nadir_dcm(r_m, v_m_s) -> np.ndarray:
    """ECI → nadir frame DCM, Bernard (2021) eq. 4.6, ``(..., 3, 3)``.

    Eq. 4.2–4.4: ``i_x = (h × r)/|h × r|``, ``i_y = h/|h|``, ``i_z = r/|r|``; eq. 4.6 stacks the
    rows ``[i_x, −i_y, −i_z]``: z = nadir ``−r̂``, y = negative orbit normal, x = y × z
    (along-track) — the same frame as :func:`lvlh_dcm` (Markley & Crassidis 2014). A body with
    identity attitude relative to this frame points its +z at the Earth's centre.
    """
    return lvlh_dcm(r_m, v_m_s)


def rsw_dcm(r_m, v_m_s) -> np.ndarray:
    """ECI → RSW (radial, along-track, cross-track; Vallado 2013 §3.3) DCM, ``(..., 3, 3)``.

    ``R = r̂``, ``W = (r × v)/|r × v|`` (orbit normal), ``S = W × R``. Rows are R, S, W in ECI.
    """
    r = np.asarray(r_m, dtype=float)
    v = np.asarray(v_m_s, dtype=float)
    R = _unit(r)
    W = _unit(np.cross(r, v))
    S = np.cross(W, R)
    return np.stack([R, S, W], axis=-2)


def topocentric_enu(site, r_gcrs_m, epoch_utc, t_s=0.0, *, rotation=None) -> np.ndarray:
    """East-North-Up components (m) of the vector site → point, ``(N, 3)``.

    Parameters
    ----------
    site : Site or spec
        Observer (WGS84 geodetic).
    r_gcrs_m : array (N, 3) or (3,)
        Point position in GCRS, metres.
    rotation : array (N, 3, 3), optional
        Precomputed :func:`itrs_rotation` for the same epochs (saves recomputing it).
    """
    site = get_site(site)
    R = itrs_rotation(epoch_utc, t_s) if rotation is None else rotation
    r = _rows(r_gcrs_m, "r_gcrs_m")
    r_itrs = np.einsum("nij,nj->ni", R, np.broadcast_to(r, (max(len(R), len(r)), 3)))
    rho = r_itrs - site_itrs_m(site)
    return rho @ enu_matrix(site.lat_rad, site.lon_rad).T


def enu_to_altaz(enu):
    """ENU vectors ``(N, 3)`` → (altitude rad, azimuth rad in [0, 2π) from north via east, range m)."""
    enu = np.atleast_2d(np.asarray(enu, dtype=float))
    rng = np.linalg.norm(enu, axis=-1)
    alt = np.arcsin(np.clip(enu[:, 2] / rng, -1.0, 1.0))
    az = np.mod(np.arctan2(enu[:, 0], enu[:, 1]), 2 * np.pi)
    return alt, az, rng


def altaz_to_enu(alt_rad, az_rad) -> np.ndarray:
    """Unit line-of-sight vectors in ENU for altitude/azimuth (rad), ``(N, 3)``."""
    alt = np.atleast_1d(np.asarray(alt_rad, dtype=float))
    az = np.atleast_1d(np.asarray(az_rad, dtype=float))
    ca = np.cos(alt)
    return np.stack([ca * np.sin(az), ca * np.cos(az), np.sin(alt)], axis=-1)


def altaz(site, r_gcrs_m, epoch_utc, t_s=0.0, *, rotation=None):
    """Geometric topocentric altitude, azimuth and range of GCRS point(s) seen from a site.

    Returns ``(alt_rad (N,), az_rad (N,), range_m (N,))``; altitude above the plane normal to
    the WGS84 geodetic vertical, azimuth from north through east in [0, 2π). No refraction.
    """
    return enu_to_altaz(topocentric_enu(site, r_gcrs_m, epoch_utc, t_s, rotation=rotation))
