"""Attitude laws: attitudes prescribed by geometry rather than integrated from dynamics.

A law maps the object's and the Sun's positions at each epoch straight to an attitude
quaternion (scalar first, inertial(GCRS)→body passive, ``v_b = A(q) v_I``). Used by
``[attitude] dynamics = "law"`` scenarios and by recordings, whose attitude is not measured.

Laws
----
``nadir_sun_yaw``
    The Starlink v1.5 "brightness regime" attitude of Fankhauser, Askari & Tyson (2023),
    ``../shared/data/starlink_pomenis/SOURCE.md``: body +Z = **geodetic** nadir (minus the
    WGS84 ellipsoid normal through the object), body +X = the object→Sun direction projected
    onto the plane perpendicular to +Z (the satellite's local horizontal plane), normalised;
    body +Y = Z × X completes a right-handed frame. With ``shapes/starlink_v15.toml`` this puts
    the chassis (+Z facet) on nadir and the solar-array normal (+X facet) horizontal towards
    the Sun's azimuth as seen from the satellite.
``nadir_sun_yaw_geocentric``
    The same with body +Z = geocentric nadir (−r̂). Fankhauser et al.'s own code uses a
    spherical Earth (radius 6378 km), so its "geodetic nadir" is in effect geocentric; the two
    differ by up to 0.19° (the geodetic–geocentric latitude difference at 45°).

When the Sun is exactly on the +Z axis (zenith or nadir of the object; a set of measure zero)
the projected direction is undefined: +X is then taken perpendicular to +Z via the ECI axis
least aligned with it.

Body rates: :func:`law_body_rates` differentiates the quaternion sequence (central
differences, one-sided at the ends); recordings use zero rates.
"""

from __future__ import annotations

import numpy as np

from ..geometry.frames import itrs_rotation
from ..geometry.sites import itrs_to_geodetic
from ..rotations import dcm_to_quat, quat_inv, quat_mult, quat_normalize, quat_to_rotvec

__all__ = ["LAWS", "attitude_law", "law_body_rates", "geodetic_up_itrs", "nadir_sun_yaw_dcm"]

#: Names accepted by :func:`attitude_law` (and by ``[attitude] law = ...``).
LAWS = ("nadir_sun_yaw", "nadir_sun_yaw_geocentric")


def _unit_rows(x):
    n = np.linalg.norm(x, axis=-1, keepdims=True)
    return x / n


def geodetic_up_itrs(r_itrs_m) -> np.ndarray:
    """Unit WGS84 ellipsoid normal (geodetic "up", ITRS) through point(s) ``r_itrs_m`` (m).

    ``(N, 3)`` → ``(N, 3)``: up = (cos φ cos λ, cos φ sin λ, sin φ) with the geodetic latitude
    φ and longitude λ of :func:`lightcurve.geometry.sites.itrs_to_geodetic`.
    """
    lat, lon, _ = itrs_to_geodetic(r_itrs_m)
    cl = np.cos(lat)
    return np.stack([cl * np.cos(lon), cl * np.sin(lon), np.sin(lat)], axis=-1)


def _perpendicular(z):
    """Unit vectors perpendicular to the unit rows of ``z`` (via the least-aligned ECI axis)."""
    k = np.argmin(np.abs(z), axis=-1)
    e = np.zeros_like(z)
    e[np.arange(len(z)), k] = 1.0
    return _unit_rows(e - np.sum(e * z, -1, keepdims=True) * z)


def nadir_sun_yaw_dcm(nadir_eci, sun_dir_eci) -> np.ndarray:
    """Inertial→body DCMs ``(N, 3, 3)``: rows = body X, Y, Z axes in ECI.

    ``nadir_eci`` (N,3): body +Z; ``sun_dir_eci`` (N,3): object→Sun direction (any length);
    X = the Sun direction with its Z component removed, normalised; Y = Z × X.
    """
    z = _unit_rows(np.atleast_2d(np.asarray(nadir_eci, dtype=float)))
    s = _unit_rows(np.atleast_2d(np.asarray(sun_dir_eci, dtype=float)))
    if z.shape != s.shape:
        raise ValueError(f"nadir_eci and sun_dir_eci must have the same shape, got {z.shape}, {s.shape}")
    xp = s - np.sum(s * z, -1, keepdims=True) * z
    nx = np.linalg.norm(xp, axis=-1)
    bad = nx < 1e-9
    x = np.empty_like(xp)
    x[~bad] = xp[~bad] / nx[~bad, None]
    if np.any(bad):
        x[bad] = _perpendicular(z[bad])
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-2)


def attitude_law(name: str, r_obj_eci_m, r_sun_eci_m, epoch_utc, t_s) -> np.ndarray:
    """Attitude quaternions ``(N, 4)`` (scalar first, GCRS→body) of the named law.

    Parameters
    ----------
    name : str
        One of :data:`LAWS`.
    r_obj_eci_m, r_sun_eci_m : (N, 3)
        Geocentric GCRS positions of the object and the Sun, m.
    epoch_utc : str or datetime
        Epoch (UTC) that ``t_s`` counts from; used for the GCRS→ITRS rotation (geodetic nadir).
    t_s : (N,)
        Seconds since ``epoch_utc``.

    Raises
    ------
    ValueError
        Unknown law, mismatched shapes, non-finite input.
    """
    if name not in LAWS:
        raise ValueError(f"unknown attitude law {name!r}; known: {', '.join(LAWS)}")
    r = np.atleast_2d(np.asarray(r_obj_eci_m, dtype=float))
    rs = np.atleast_2d(np.asarray(r_sun_eci_m, dtype=float))
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    if r.shape != rs.shape or r.shape[-1] != 3 or t.shape != (r.shape[0],):
        raise ValueError(f"r_obj_eci_m {r.shape}, r_sun_eci_m {rs.shape} and t_s {t.shape} must be "
                         "(N,3), (N,3), (N,)")
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(rs)) and np.all(np.isfinite(t))):
        raise ValueError("attitude_law: positions and times must be finite")
    if len(t) == 0:
        return np.zeros((0, 4))
    if name == "nadir_sun_yaw_geocentric":
        nadir = -_unit_rows(r)
    else:
        R = itrs_rotation(epoch_utc, t)                      # (N,3,3) GCRS→ITRS
        up_itrs = geodetic_up_itrs(np.einsum("nij,nj->ni", R, r))
        nadir = -np.einsum("nji,nj->ni", R, up_itrs)          # Rᵀ up → GCRS
    A = nadir_sun_yaw_dcm(nadir, rs - r)
    q = quat_normalize(dcm_to_quat(A))
    # a continuous sign (q and −q are the same attitude): first component non-negative is not
    # continuous, so flip each quaternion to the hemisphere of its predecessor
    if len(q) > 1:
        d = np.sum(q[1:] * q[:-1], -1)
        sgn = np.cumprod(np.where(d < 0, -1.0, 1.0))
        q[1:] *= sgn[:, None]
    return q


def law_body_rates(q, t_s) -> np.ndarray:
    """Body angular velocity ``(N, 3)`` (rad/s, body axes) of a quaternion sequence.

    ``ω ≈ θ/Δt`` with ``θ`` the rotation vector of ``q(t₂) ⊗ q(t₁)⁻¹`` (the body-frame
    increment, since ``q(t+Δt) = exp(ω Δt) ⊗ q(t)`` for inertial→body quaternions); central
    differences inside, one-sided at the ends; samples with equal times share the rate of their
    neighbours. One sample (or all at one time) → zeros.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    if q.shape != (t.size, 4):
        raise ValueError(f"q must be (N,4) matching t_s (N,), got {q.shape} and {t.shape}")
    n = len(t)
    w = np.zeros((n, 3))
    if n < 2:
        return w
    tu, first, inv = np.unique(t, return_index=True, return_inverse=True)
    if tu.size < 2:
        return w
    qu = q[first]
    dq = quat_mult(qu[1:], quat_inv(qu[:-1]))
    # shortest rotation (quat_to_rotvec is sign-independent)
    rates = quat_to_rotvec(dq) / np.diff(tu)[:, None]      # (M-1,3), rate on each interval
    wu = np.empty((tu.size, 3))
    wu[0] = rates[0]
    wu[-1] = rates[-1]
    if tu.size > 2:
        dt = np.diff(tu)
        a, b = dt[:-1, None], dt[1:, None]
        wu[1:-1] = (rates[:-1] * b + rates[1:] * a) / (a + b)   # time-weighted central difference
    return wu[inv]
