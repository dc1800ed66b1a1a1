"""Orbits of the observed object: element conversions, numerical propagation, TLEs, and
positions reconstructed from topocentric observations.

Frames and units: positions in GCRS (our ECI) metres, velocities m/s, angles radians.

Gravity models for :func:`propagate_orbit`
------------------------------------------
``"point"`` (two-body), ``"J2"`` … ``"J6"``: the zonal harmonics of EGM2008
(unnormalised J2 = 1.08262617e-3, J3 = −2.53241052e-6, J4 = −1.61989760e-6,
J5 = −2.27753591e-7, J6 = 5.40666576e-7 — Vallado, *Fundamentals of Astrodynamics and
Applications*, 4th ed., EGM-08 values; reference radius 6378136.3 m, GM = 3.986004418e14 m³/s²). Zonal terms are axisymmetric about the Earth's
rotation pole, so only the pole direction matters; we evaluate them about the true pole (CIP,
ITRS z) *at the scenario epoch*, expressed in GCRS (:func:`lightcurve.geometry.frames.earth_pole_gcrs`),
and hold it fixed over the arc (precession moves it by ~0.006° per year, negligible over a
pass). Called directly without ``pole``, :func:`propagate_orbit` uses GCRS z as the pole — an
approximation off by the precession–nutation angle (≈0.1° in 2020).
No drag, SRP or third bodies by default (the arcs we need are minutes to hours long);
:func:`propagate_orbit` adds any extra acceleration a caller passes (``accel``), e.g. the drag
and solar radiation pressure of O'Keefe (2015) §2.4 in :mod:`lightcurve.css.truth`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import njit

from ..errors import InputError
from .sites import enu_matrix, get_site, itrs_to_geodetic, site_itrs_m
from .time import is_time, parse_epoch, skyfield_times, timescale

__all__ = [
    "MU_EARTH",
    "R_EARTH_M",
    "R_EARTH_GRAVITY_M",
    "J2",
    "J3",
    "J4",
    "J5",
    "J6",
    "KeplerElements",
    "coe_to_rv",
    "rv_to_coe",
    "kepler_propagate",
    "zonal_acceleration",
    "propagate_orbit",
    "tle_positions",
    "satellite_positions",
    "check_tle",
    "geodetic_height_m",
    "positions_from_topocentric",
    "Orbit",
    "orbit_from_section",
]

MU_EARTH = 3.986004418e14
"""Earth's gravitational parameter GM, m³/s² (EGM2008 / WGS84 G1762)."""
R_EARTH_M = 6378137.0
"""WGS84 equatorial radius, m: the 'surface' for the perigee check (conservative at the poles)."""
R_EARTH_GRAVITY_M = 6378136.3
"""Reference radius of the EGM2008 zonal coefficients, m."""
J2 = 1.08262617385222e-3
J3 = -2.53241051856772e-6
J4 = -1.61989759991697e-6
J5 = -2.27753590730836e-7
J6 = 5.40666576283813e-7

_GRAVITY = {"point": (), "J2": (J2,), "J3": (J2, J3), "J4": (J2, J3, J4),
            "J5": (J2, J3, J4, J5), "J6": (J2, J3, J4, J5, J6)}


# ----------------------------------------------------------------------------------------
# classical elements
# ----------------------------------------------------------------------------------------
class KeplerElements(NamedTuple):
    """Osculating classical elements (metres, radians; arrays for stacked input).

    Special cases (Vallado 2013 algorithm 9): on a circular orbit (e < 1e-10) ``argp = 0`` and
    ``nu`` is the argument of latitude (inclined) or true longitude (equatorial); on an
    equatorial orbit (i < 1e-10 or > π − 1e-10) ``raan = 0`` and ``argp`` is the longitude of
    periapsis. ``arglat``, ``truelon`` and ``lonper`` are always filled.
    """

    p_m: np.ndarray
    a_m: np.ndarray
    e: np.ndarray
    i_rad: np.ndarray
    raan_rad: np.ndarray
    argp_rad: np.ndarray
    nu_rad: np.ndarray
    arglat_rad: np.ndarray
    truelon_rad: np.ndarray
    lonper_rad: np.ndarray


def coe_to_rv(a_m, e, i_rad, raan_rad, argp_rad, nu_rad, mu=MU_EARTH):
    """Classical elements → inertial position (m) and velocity (m/s) (Vallado algorithm 10).

    All element arguments broadcast; results have shape ``(..., 3)``. For e ≥ 1 pass the
    semi-latus rectum through ``a_m = p/(1 − e²)`` is not possible, so only 0 ≤ e < 1 is
    accepted (ValueError otherwise). The frame is whatever frame the angles refer to (GCRS).
    """
    a, e, i, O, w, nu = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in
                                               (a_m, e, i_rad, raan_rad, argp_rad, nu_rad)))
    if np.any(e < 0) or np.any(e >= 1) or np.any(a <= 0):
        raise ValueError("coe_to_rv needs 0 <= e < 1 and a > 0")
    p = a * (1.0 - e * e)
    cnu, snu = np.cos(nu), np.sin(nu)
    rpf = (p / (1.0 + e * cnu))[..., None] * np.stack([cnu, snu, np.zeros_like(nu)], -1)
    vpf = np.sqrt(mu / p)[..., None] * np.stack([-snu, e + cnu, np.zeros_like(nu)], -1)
    cO, sO, ci, si, cw, sw = np.cos(O), np.sin(O), np.cos(i), np.sin(i), np.cos(w), np.sin(w)
    # columns of the perifocal → inertial matrix R3(−Ω) R1(−i) R3(−ω)
    P = np.stack([cO * cw - sO * sw * ci, sO * cw + cO * sw * ci, sw * si], -1)
    Q = np.stack([-cO * sw - sO * cw * ci, -sO * sw + cO * cw * ci, cw * si], -1)
    r = rpf[..., :1] * P + rpf[..., 1:2] * Q
    v = vpf[..., :1] * P + vpf[..., 1:2] * Q
    return r, v


def _angle(a, b):
    """Angle in [0, π] between stacked vectors."""
    c = np.sum(a * b, -1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.arccos(np.clip(c, -1.0, 1.0))


def rv_to_coe(r_m, v_m_s, mu=MU_EARTH, tol=1e-10) -> KeplerElements:
    """Inertial position (m) and velocity (m/s) → osculating classical elements (Vallado alg. 9).

    Accepts ``(3,)`` or ``(N, 3)``; returns :class:`KeplerElements` of scalars or ``(N,)``.
    Angles in [0, 2π) (inclination in [0, π]). Hyperbolic/parabolic states give ``a_m <= 0``
    or inf (no error here; callers that need bound orbits check ``e < 1``).
    """
    r = np.asarray(r_m, dtype=float)
    v = np.asarray(v_m_s, dtype=float)
    scalar = r.ndim == 1
    r, v = np.atleast_2d(r), np.atleast_2d(v)
    rn = np.linalg.norm(r, axis=-1)
    vn2 = np.sum(v * v, -1)
    h = np.cross(r, v)
    hn = np.linalg.norm(h, axis=-1)
    k = np.array([0.0, 0.0, 1.0])
    n = np.cross(k, h)
    nn = np.linalg.norm(n, axis=-1)
    rv = np.sum(r * v, -1)
    evec = ((vn2 - mu / rn)[:, None] * r - rv[:, None] * v) / mu
    e = np.linalg.norm(evec, axis=-1)
    energy = vn2 / 2 - mu / rn
    with np.errstate(divide="ignore"):
        a = np.where(np.abs(1 - e) > 1e-12, -mu / (2 * energy), np.inf)
    p = hn * hn / mu
    i = np.arccos(np.clip(h[:, 2] / hn, -1, 1))
    two_pi = 2 * np.pi
    circ = e < tol
    equat = (i < tol) | (i > np.pi - tol)
    safe_n = np.where(nn[:, None] > 0, n, np.array([1.0, 0, 0]))
    safe_e = np.where(e[:, None] > 0, evec, np.array([1.0, 0, 0]))
    raan = np.where(safe_n[:, 1] >= 0, 1.0, -1.0) * np.arccos(
        np.clip(safe_n[:, 0] / np.linalg.norm(safe_n, axis=-1), -1, 1))
    raan = np.mod(raan, two_pi)
    argp = _angle(safe_n, safe_e)
    argp = np.where(safe_e[:, 2] < 0, two_pi - argp, argp)
    nu = _angle(safe_e, r)
    nu = np.where(rv < 0, two_pi - nu, nu)
    arglat = _angle(safe_n, r)
    arglat = np.where(r[:, 2] < 0, two_pi - arglat, arglat)
    truelon = np.arccos(np.clip(r[:, 0] / rn, -1, 1))
    truelon = np.where(r[:, 1] < 0, two_pi - truelon, truelon)
    lonper = np.arccos(np.clip(safe_e[:, 0] / np.linalg.norm(safe_e, axis=-1), -1, 1))
    lonper = np.where(safe_e[:, 1] < 0, two_pi - lonper, lonper)
    # retrograde equatorial: longitudes measured the other way (Vallado alg. 9 note)
    retro = i > np.pi / 2
    truelon = np.where(equat & retro, two_pi - truelon, truelon)
    lonper = np.where(equat & retro, two_pi - lonper, lonper)
    # special cases
    raan = np.where(equat, 0.0, raan)
    argp = np.where(circ, 0.0, np.where(equat, lonper, argp))
    nu = np.where(circ & ~equat, arglat, np.where(circ & equat, truelon, nu))
    out = KeplerElements(p, a, e, i, raan, argp, nu, arglat, truelon, lonper)
    if scalar:
        out = KeplerElements(*(float(x[0]) for x in out))
    return out


def _solve_kepler(M, e, tol=1e-14):
    """Eccentric anomaly E from mean anomaly M (rad), elliptic, vectorised Newton."""
    M = np.asarray(M, dtype=float)
    E = np.where(e < 0.8, M, np.pi * np.ones_like(M))
    for _ in range(50):
        f = E - e * np.sin(E) - M
        dE = f / (1 - e * np.cos(E))
        E = E - dE
        if np.all(np.abs(dE) < tol):
            break
    return E


def kepler_propagate(r0_m, v0_m_s, t_s, mu=MU_EARTH):
    """Analytic two-body propagation of an elliptic orbit via Kepler's equation.

    Returns ``(r (N, 3) m, v (N, 3) m/s)`` at ``t_s`` seconds after the state's epoch.
    """
    el = rv_to_coe(r0_m, v0_m_s, mu)
    if not el.e < 1:
        raise ValueError("kepler_propagate handles elliptic orbits only (e < 1)")
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    e, a = el.e, el.a_m
    nu0 = el.nu_rad
    E0 = 2 * np.arctan2(np.sqrt(1 - e) * np.sin(nu0 / 2), np.sqrt(1 + e) * np.cos(nu0 / 2))
    M0 = E0 - e * np.sin(E0)
    n = np.sqrt(mu / a ** 3)
    M = np.mod(M0 + n * t, 2 * np.pi)
    E = _solve_kepler(M, e)
    nu = 2 * np.arctan2(np.sqrt(1 + e) * np.sin(E / 2), np.sqrt(1 - e) * np.cos(E / 2))
    # circular/equatorial special cases put the angle into nu with argp/raan = 0: consistent
    return coe_to_rv(a, e, el.i_rad, el.raan_rad, el.argp_rad, nu, mu)


# ----------------------------------------------------------------------------------------
# numerical propagation
# ----------------------------------------------------------------------------------------
@njit(cache=True)
def _zonal_accel_nb(r, mu, re, jn, k):
    """Acceleration (m/s²) of point-mass + zonal gravity about unit pole ``k``.

    ``jn`` holds J2, J3, … (any length, may be empty). From the potential
    V = μ/r [1 − Σ J_n (R/r)^n P_n(s)], s = r̂·k:
    a_n = μ/r² (R/r)^n [(n+1) P_n(s) r̂ − P_n'(s) (k − s r̂)], with the Legendre recursions
    n P_n = (2n−1) s P_{n−1} − (n−1) P_{n−2} and P_n' = P_{n−2}' + (2n−1) P_{n−1} (regular at
    the poles, s = ±1).
    """
    rn = np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    out = np.empty(3)
    s = (r[0] * k[0] + r[1] * k[1] + r[2] * k[2]) / rn
    g = mu / (rn * rn)
    q = re / rn
    p_m2, p_m1 = 1.0, s          # P_0, P_1
    d_m2, d_m1 = 0.0, 1.0        # P_0', P_1'
    qn = q
    radial = -1.0
    polar = 0.0
    for i in range(jn.shape[0]):
        n = i + 2
        p = ((2 * n - 1) * s * p_m1 - (n - 1) * p_m2) / n
        d = d_m2 + (2 * n - 1) * p_m1
        qn *= q
        radial += jn[i] * qn * (n + 1) * p
        polar += jn[i] * qn * d
        p_m2, p_m1 = p_m1, p
        d_m2, d_m1 = d_m1, d
    for j in range(3):
        rh = r[j] / rn
        out[j] = g * (radial * rh - polar * (k[j] - s * rh))
    return out


@njit(cache=True)
def _rhs_nb(y, mu, re, jn, k):
    out = np.empty(6)
    a = _zonal_accel_nb(y[:3], mu, re, jn, k)
    out[0] = y[3]
    out[1] = y[4]
    out[2] = y[5]
    out[3] = a[0]
    out[4] = a[1]
    out[5] = a[2]
    return out


def _gravity_coeffs(gravity):
    if gravity not in _GRAVITY:
        raise ValueError(f"unknown gravity model {gravity!r}; allowed: {', '.join(_GRAVITY)}")
    return np.array(_GRAVITY[gravity], dtype=float)


def zonal_acceleration(r_m, gravity="J4", mu=MU_EARTH, pole=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Gravitational acceleration (m/s²) at position(s) ``r_m`` (m), shape like ``r_m``."""
    jn = _gravity_coeffs(gravity)
    k = np.asarray(pole, dtype=float)
    k = k / np.linalg.norm(k)
    r = np.asarray(r_m, dtype=float)
    flat = np.atleast_2d(r)
    out = np.array([_zonal_accel_nb(np.ascontiguousarray(x), mu, R_EARTH_GRAVITY_M, jn, k)
                    for x in flat])
    return out.reshape(r.shape)


def _check_bound_and_clear(r0, v0, mu, field_r="r0_m", field_v="v0_m_s", file=None,
                           scale=1.0, unit="m"):
    el = rv_to_coe(r0, v0, mu)
    if not el.e < 1.0:
        raise InputError("not a bound orbit (eccentricity >= 1)", file=file, field=field_v,
                         value=round(float(el.e), 6), allowed="e < 1")
    rp = el.a_m * (1 - el.e)
    if rp <= R_EARTH_M:
        raise InputError(f"perigee radius {rp / scale:.3f} {unit} is below the Earth's equatorial "
                         f"radius {R_EARTH_M / scale:.3f} {unit}: the orbit intersects the Earth",
                         file=file, field=field_r)
    return el


def propagate_orbit(r0_m, v0_m_s, t_s, gravity="J4", *, mu=MU_EARTH, pole=None,
                    rtol=1e-12, atol_m=1e-6, check=True, accel=None):
    """Numerically propagate an Earth orbit (scipy ``solve_ivp``, DOP853).

    Parameters
    ----------
    r0_m, v0_m_s : array (3,)
        GCRS position (m) and velocity (m/s) at ``t = 0``.
    t_s : array (N,)
        Output times, seconds from the state's epoch, any order, may be negative (the arc is
        integrated backwards and forwards from 0).
    gravity : {"point", "J2", "J3", "J4", "J5", "J6"}
        Gravity model (module docstring).
    pole : array (3,), optional
        Unit vector of the Earth's rotation pole in GCRS for the zonal terms; default GCRS z.
    rtol, atol_m : float
        Integrator tolerances; ``atol_m`` applies to position (m), ``atol_m * 1e-3`` to velocity.
    check : bool
        Reject unbound orbits and orbits whose perigee is below the Earth's surface
        (:class:`InputError`).
    accel : callable, optional
        ``accel(t, r, v) -> (3,)``: an extra acceleration (m/s², GCRS) added to the gravity,
        e.g. drag and solar radiation pressure.

    Returns
    -------
    r : (N, 3) m, v : (N, 3) m/s, GCRS.
    """
    from scipy.integrate import solve_ivp

    r0 = np.asarray(r0_m, dtype=float).reshape(3)
    v0 = np.asarray(v0_m_s, dtype=float).reshape(3)
    jn = _gravity_coeffs(gravity)
    if check:
        _check_bound_and_clear(r0, v0, mu)
    k = np.array([0.0, 0.0, 1.0]) if pole is None else np.asarray(pole, dtype=float).reshape(3)
    k = k / np.linalg.norm(k)
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ValueError("t_s must be a finite scalar or 1-D array")
    y0 = np.concatenate([r0, v0])
    atol = np.array([atol_m] * 3 + [atol_m * 1e-3] * 3)
    out = np.empty((t.size, 6))
    args = (mu, R_EARTH_GRAVITY_M, jn, k)

    def fun(_t, y):
        dy = _rhs_nb(y, *args)
        if accel is not None:
            dy[3:] += accel(_t, y[:3], y[3:])
        return dy

    for sign in (1.0, -1.0):
        sel = (t >= 0) if sign > 0 else (t < 0)
        if not np.any(sel):
            continue
        tt = np.unique(t[sel])
        tend = tt[-1] if sign > 0 else tt[0]
        if tend == 0.0:
            out[sel] = y0
            continue
        teval = tt if sign > 0 else tt[::-1]
        sol = solve_ivp(fun, (0.0, tend), y0, method="DOP853", t_eval=teval, rtol=rtol,
                        atol=atol)
        if not sol.success:  # pragma: no cover - would need a pathological state
            raise RuntimeError(f"orbit propagation failed: {sol.message}")
        ys = sol.y.T if sign > 0 else sol.y.T[::-1]
        idx = np.searchsorted(tt, t[sel])
        out[sel] = ys[idx]
    return out[:, :3].copy(), out[:, 3:].copy()


# ----------------------------------------------------------------------------------------
# TLE
# ----------------------------------------------------------------------------------------
def _tle_checksum(line: str) -> int:
    return sum(int(c) if c.isdigit() else (1 if c == "-" else 0) for c in line[:68]) % 10


def check_tle(line1: str, line2: str) -> None:
    """Validate the format and checksums of a two-line element set (InputError if bad)."""
    for n, line in ((1, line1), (2, line2)):
        if not isinstance(line, str):
            raise InputError("TLE line must be text", field=f"line{n}", value=line)
        s = line.rstrip()
        if len(s) != 69 or not s.startswith(f"{n} "):
            raise InputError(f"TLE line {n} must be 69 characters starting with '{n} '",
                             field=f"line{n}", value=line, allowed="standard NORAD TLE format")
        if not s[68].isdigit() or _tle_checksum(s) != int(s[68]):
            raise InputError(f"TLE line {n} checksum mismatch (computed {_tle_checksum(s)}, "
                             f"line says {s[68]!r}): probably a typo", field=f"line{n}",
                             value=line)
    if line1[2:7] != line2[2:7]:
        raise InputError("TLE lines have different catalog numbers", field="line2",
                         value=(line1[2:7], line2[2:7]))


def _earth_satellite(line1, line2):
    from skyfield.api import EarthSatellite

    check_tle(line1, line2)
    try:
        return EarthSatellite(line1.rstrip(), line2.rstrip(), ts=timescale())
    except Exception as exc:  # sgp4 raises ValueError / others on malformed fields
        raise InputError(f"TLE could not be parsed: {exc}", field="line1/line2") from None


_SGP4_ERRORS = {1: "mean eccentricity out of range", 2: "mean motion below zero",
                3: "perturbed eccentricity out of range", 4: "semi-latus rectum below zero",
                5: "(unused)", 6: "satellite has decayed"}


def tle_positions(line1: str, line2: str, epoch_utc, t_s):
    """GCRS position (m) and velocity (m/s) of a TLE object via skyfield/SGP4, each ``(N, 3)``.

    skyfield converts SGP4's TEME output to GCRS. Accuracy is that of the TLE (≈1 km near
    its epoch, growing by km per day). Raises :class:`InputError` for a malformed TLE or when
    SGP4 reports an error (e.g. decayed) at any requested time.
    """
    return satellite_positions(_earth_satellite(line1, line2), epoch_utc, t_s)


def satellite_positions(sat, epoch_utc, t_s):
    """GCRS position (m) and velocity (m/s), each ``(N, 3)``, of a skyfield ``EarthSatellite``
    (SGP4, TEME → GCRS by skyfield) at ``epoch_utc + t_s`` (or at a skyfield ``Time``).

    Raises :class:`InputError` when SGP4 reports an error (e.g. decayed) at any time.
    """
    t = epoch_utc if is_time(epoch_utc) else skyfield_times(epoch_utc, t_s)
    p = sat.at(t)
    r = np.asarray(p.position.m, dtype=float).reshape(3, -1).T
    v = np.asarray(p.velocity.m_per_s, dtype=float).reshape(3, -1).T
    if not np.all(np.isfinite(r)):
        bad = ~np.all(np.isfinite(r), axis=1)
        msg = getattr(p, "message", None)  # one entry per time, None where SGP4 succeeded
        if msg is None or isinstance(msg, str):
            texts = [str(msg)] if msg else []
        else:
            texts = sorted({str(m) for m, b in zip(np.atleast_1d(msg), bad) if b and m})
        k = int(np.argmax(bad))
        raise InputError(f"SGP4 failed for this TLE at {int(bad.sum())} of {bad.size} requested "
                         f"time(s), first at index {k}: "
                         f"{'; '.join(texts)[:300] or 'no position returned'}",
                         field="line1/line2")
    return np.ascontiguousarray(r), np.ascontiguousarray(v)


# ----------------------------------------------------------------------------------------
# positions from topocentric observations
# ----------------------------------------------------------------------------------------
def geodetic_height_m(r_itrs_m) -> np.ndarray:
    """Height above the WGS84 ellipsoid (m) of ITRS point(s), ``(N,)``
    (:func:`lightcurve.geometry.sites.itrs_to_geodetic`)."""
    return itrs_to_geodetic(r_itrs_m)[2]


def _as_time_list(utc_times):
    if is_time(utc_times):
        return utc_times
    vals = [utc_times] if isinstance(utc_times, str) else list(np.atleast_1d(utc_times))
    dts = [parse_epoch(x if not isinstance(x, np.str_) else str(x)) for x in vals]
    return timescale().from_datetimes(dts)


def positions_from_topocentric(site, utc_times, alt_deg, az_deg, range_m=None, height_m=None):
    """GCRS positions (m, ``(N, 3)``) of objects seen from a site at given alt/az.

    Parameters
    ----------
    site : Site or spec
        The observer.
    utc_times : skyfield Time, or sequence of ISO 8601 UTC texts / datetimes (N)
    alt_deg, az_deg : array (N,)
        Geometric topocentric altitude and azimuth (from north through east), degrees.
    range_m : array (N,), optional
        Slant range site → object (m).
    height_m : array (N,), optional
        Object height above the WGS84 ellipsoid (m); the range is solved for (bisection along
        the line of sight to 1e-4 m). Give exactly one of ``range_m`` / ``height_m``.

    Raises
    ------
    InputError
        Both or neither of range/height, mismatched lengths, a height the line of sight never
        reaches (or an altitude below the horizon), negative ranges.
    """
    from .frames import altaz_to_enu, itrs_rotation
    site = get_site(site)
    if (range_m is None) == (height_m is None):
        raise InputError("give exactly one of range_m or height_m", field="range_m/height_m")
    t = _as_time_list(utc_times)
    alt = np.radians(np.atleast_1d(np.asarray(alt_deg, dtype=float)))
    az = np.radians(np.atleast_1d(np.asarray(az_deg, dtype=float)))
    n = np.size(t.tt)
    if alt.size != n or az.size != n:
        raise InputError("times, alt_deg and az_deg must have the same length",
                         field="alt_deg/az_deg", value=(n, alt.size, az.size))
    if np.any(np.abs(alt) > np.pi / 2) or not np.all(np.isfinite(alt) & np.isfinite(az)):
        raise InputError("altitude must be finite and within [-90, 90] degrees", field="alt_deg")
    u_itrs = altaz_to_enu(alt, az) @ enu_matrix(site.lat_rad, site.lon_rad)  # ENU → ITRS
    s_itrs = site_itrs_m(site)
    if range_m is not None:
        rho = np.atleast_1d(np.asarray(range_m, dtype=float))
        if rho.size != n or np.any(~np.isfinite(rho)) or np.any(rho < 0):
            raise InputError("range_m must be finite, non-negative, one per time",
                             field="range_m", value=rho[:5].tolist())
    else:
        h = np.atleast_1d(np.asarray(height_m, dtype=float))
        if h.size != n or np.any(~np.isfinite(h)):
            raise InputError("height_m must be finite, one per time", field="height_m")
        lo = np.zeros(n)
        hi = np.full(n, 2.0e8)
        h_lo = geodetic_height_m(s_itrs[None, :] + lo[:, None] * u_itrs)
        h_hi = geodetic_height_m(s_itrs[None, :] + hi[:, None] * u_itrs)
        bad = (h < h_lo) | (h > h_hi) | (alt < 0)
        if np.any(bad):
            k = int(np.argmax(bad))
            raise InputError("the line of sight does not reach this height (need altitude >= 0 "
                             "and height above the site)", field="height_m",
                             value=(float(h[k]), float(np.degrees(alt[k]))))
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            hm = geodetic_height_m(s_itrs[None, :] + mid[:, None] * u_itrs)
            up = hm < h
            lo = np.where(up, mid, lo)
            hi = np.where(up, hi, mid)
            if np.max(hi - lo) < 1e-4:
                break
        rho = 0.5 * (lo + hi)
    r_itrs = s_itrs[None, :] + rho[:, None] * u_itrs
    R = itrs_rotation(t)
    return np.einsum("nji,nj->ni", R, r_itrs)


# ----------------------------------------------------------------------------------------
# scenario orbits
# ----------------------------------------------------------------------------------------
@dataclass
class Orbit:
    """An object's orbit as given in a scenario.

    ``kind`` is ``"keplerian"``/``"cartesian"`` (an osculating GCRS state at the scenario epoch,
    propagated numerically with ``gravity``) or ``"tle"`` (SGP4 from its own epoch).
    """

    kind: str
    gravity: str = "J4"
    r0_m: np.ndarray | None = None
    v0_m_s: np.ndarray | None = None
    line1: str | None = None
    line2: str | None = None
    #: where the orbit was read (file, and the TOML field of the TLE lines): an SGP4 failure
    #: found only while propagating (a TLE that decays during the scenario) names them
    source_file: str | None = field(default=None, repr=False, compare=False)
    source_field: str | None = field(default=None, repr=False, compare=False)

    @classmethod
    def from_elements(cls, a_m, e, i_rad, raan_rad, argp_rad, nu_rad, gravity="J4",
                      mu=MU_EARTH) -> "Orbit":
        """Orbit from osculating classical elements at the scenario epoch (GCRS angles)."""
        r, v = coe_to_rv(a_m, e, i_rad, raan_rad, argp_rad, nu_rad, mu)
        _check_bound_and_clear(r, v, mu)
        return cls("keplerian", gravity, r, v)

    def positions(self, epoch_utc, t_s):
        """GCRS position (m) and velocity (m/s), each ``(N, 3)``, at ``epoch_utc + t_s``."""
        if self.kind == "tle":
            try:
                return tle_positions(self.line1, self.line2, epoch_utc, t_s)
            except InputError as exc:
                if exc.file is not None or self.source_file is None:
                    raise
                raise InputError(exc.bare_message, file=self.source_file,
                                 field=self.source_field or exc.field, value=exc.value,
                                 allowed=exc.allowed) from None
        from .frames import earth_pole_gcrs

        pole = earth_pole_gcrs(epoch_utc, 0.0)[0]
        return propagate_orbit(self.r0_m, self.v0_m_s, t_s, self.gravity, pole=pole,
                               check=False)

    def elements(self) -> KeplerElements:
        """Osculating elements at the scenario epoch (not for TLE orbits)."""
        if self.kind == "tle":
            raise ValueError("a TLE orbit has mean SGP4 elements, not an osculating state")
        return rv_to_coe(self.r0_m, self.v0_m_s)


#: largest orbit size accepted (semi-major axis, or a position component), km: the radius of
#: the Earth's Hill sphere, a (m_E / 3 M_S)^(1/3) = 1.496e8 km x (3.0e-6 / 3)^(1/3) ~ 1.5e6 km,
#: beyond which the Sun, not the Earth, dominates the motion (and the two-body propagation
#: here is meaningless); velocity components at most 100 km/s (Earth escape at LEO ~ 11 km/s)
MAX_ORBIT_RADIUS_KM = 1.5e6


def orbit_from_section(section) -> Orbit:
    """Parse a scenario's ``[orbit]`` table (a :class:`~lightcurve.io.tomlio.Section`).

    Keys: ``type = "keplerian"`` (default) with ``a_km, e, i_deg, raan_deg, argp_deg, nu_deg``;
    ``type = "cartesian"`` with ``r_km = [x, y, z]``, ``v_km_s = [vx, vy, vz]`` (GCRS at the
    scenario epoch); ``type = "tle"`` with ``line1``, ``line2``. ``gravity = "point" | "J2" |
    "J3" | "J4"`` (default J4; ignored for TLEs, which use SGP4).

    Raises
    ------
    InputError
        Missing/out-of-range keys, unknown keys, a perigee below the Earth's surface (naming the
        field), an unbound orbit, or a TLE that does not parse.
    """
    from ..io.tomlio import Section

    sec = section if isinstance(section, Section) else Section(section, name="orbit")
    kind = sec.str("type", "keplerian", choices=("keplerian", "cartesian", "tle"))
    gravity = sec.str("gravity", "J4", choices=tuple(_GRAVITY))
    f = sec.field_name
    if kind == "keplerian":
        a_km = sec.float("a_km", min=0.0, min_open=True, max=MAX_ORBIT_RADIUS_KM)
        e = sec.float("e", min=0.0, max=1.0, max_open=True)
        i = sec.float("i_deg", min=0.0, max=180.0)
        raan = sec.float("raan_deg", 0.0)
        argp = sec.float("argp_deg", 0.0)
        nu = sec.float("nu_deg", 0.0)
        sec.check_unknown()
        rp_km = a_km * (1 - e)
        if rp_km * 1e3 <= R_EARTH_M:
            raise InputError(f"perigee radius a_km*(1-e) = {rp_km:.3f} km is below the Earth's "
                             f"equatorial radius {R_EARTH_M / 1e3:.3f} km: the orbit intersects "
                             "the Earth", file=sec.file, field=f("a_km"), value=a_km,
                             allowed=f"a_km*(1-e) > {R_EARTH_M / 1e3:.3f}")
        r, v = coe_to_rv(a_km * 1e3, e, *np.radians([i, raan, argp, nu]))
        return Orbit("keplerian", gravity, r, v)
    if kind == "cartesian":
        r = sec.vector("r_km", n=3, min=-MAX_ORBIT_RADIUS_KM, max=MAX_ORBIT_RADIUS_KM) * 1e3
        v = sec.vector("v_km_s", n=3, min=-100.0, max=100.0) * 1e3
        sec.check_unknown()
        if np.linalg.norm(r) <= R_EARTH_M:
            raise InputError("position is inside the Earth", file=sec.file, field=f("r_km"),
                             value=(r / 1e3).tolist(), allowed=f"|r| > {R_EARTH_M / 1e3} km")
        _check_bound_and_clear(r, v, MU_EARTH, field_r=f("r_km"), field_v=f("v_km_s"),
                               file=sec.file, scale=1e3, unit="km")
        return Orbit("cartesian", gravity, r, v)
    line1 = sec.str("line1")
    line2 = sec.str("line2")
    sec.check_unknown()
    try:
        _earth_satellite(line1, line2)
    except InputError as exc:
        raise InputError(exc.bare_message, file=sec.file, field=f(exc.field or "line1"),
                         value=exc.value) from None
    return Orbit("tle", gravity, line1=line1, line2=line2,
                 source_file=None if sec.file is None else str(sec.file),
                 source_field=f("line1") + "/line2")
