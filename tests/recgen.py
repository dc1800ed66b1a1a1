"""Plain-NumPy generator of observatory CSV recordings: the oracle of the import tests.

Nothing here calls the lightcurve package. The physics is written out again from its sources:

* WGS84 geodetic → ITRS (NIMA TR8350.2), local East-North-Up axes; Earth orientation
  (GCRS → ITRS rotation) and the Sun's position come from skyfield (``framelib.itrs``, JPL
  DE421 from skyfield-data) — skyfield is the ephemeris oracle of the test suite (DESIGN.md);
* two-body orbits by Kepler's equation (Vallado, Algorithm 8 style f and g functions);
* the attitude: passive rotation matrices A (v_body = A v_inertial, Bernard eq. 3.16),
  3-2-1 Euler angles A = R1(ψ) R2(θ) R3(φ) (Bernard eq. 3.7), constant body rate
  A(t) = R(ω t) A(0) with R(θ) the passive rotation about θ̂ by |θ|;
* the magnitude equation of DESIGN.md (Bernard eq. 5.2–5.6 in consistent form) with the
  Cook–Torrance BRDF written out: f_r = ξ a/π + (1−ξ) F D G / (4 (n·s)(n·o)), Beckmann D,
  G = min(1, 2(n·h)(n·o)/(o·h), 2(n·h)(n·s)/(o·h)), standard Cook–Torrance Fresnel.
"""

from __future__ import annotations

import os
from datetime import datetime, timedelta

import numpy as np

MU = 3.986004418e14          # m^3/s^2 (WGS84)
AU = 1.495978707e11          # m (IAU 2012)
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
R_EARTH = 6378137.0


# ---------------------------------------------------------------------------------- time
def skyfield():
    """(timescale, ephemeris) from skyfield-data, builtin tables, no download."""
    import skyfield_data
    from skyfield.api import Loader

    path = os.path.join(os.path.dirname(os.path.abspath(skyfield_data.__file__)), "data")
    ld = Loader(path, verbose=False, expire=False)
    return ld.timescale(builtin=True), ld("de421.bsp")


def utc_times(epoch: datetime, t_s):
    return [epoch + timedelta(seconds=float(x)) for x in np.atleast_1d(t_s)]


def iso(dt: datetime) -> str:
    return dt.strftime("%Y-%m-%dT%H:%M:%S.%f") + "Z"


def gcrs_to_itrs(ts, times):
    """(N,3,3) rotation GCRS → ITRS (skyfield)."""
    from skyfield.framelib import itrs

    t = ts.from_datetimes(times)
    R = np.asarray(itrs.rotation_at(t))
    return np.moveaxis(R, -1, 0) if R.ndim == 3 else R[None]


def sun_gcrs(ts, eph, times):
    t = ts.from_datetimes(times)
    return np.asarray(eph["earth"].at(t).observe(eph["sun"]).position.m).reshape(3, -1).T


# ---------------------------------------------------------------------------------- sites
def site_itrs(lat_deg, lon_deg, h_m):
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    e2 = WGS84_F * (2 - WGS84_F)
    n = WGS84_A / np.sqrt(1 - e2 * np.sin(lat) ** 2)
    return np.array([(n + h_m) * np.cos(lat) * np.cos(lon), (n + h_m) * np.cos(lat) * np.sin(lon),
                     (n * (1 - e2) + h_m) * np.sin(lat)])


def enu_rows(lat_deg, lon_deg):
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    return np.array([[-np.sin(lon), np.cos(lon), 0.0],
                     [-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)],
                     [np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)]])


# ---------------------------------------------------------------------------------- orbits
def kepler(r0, v0, dt):
    """Two-body state after dt seconds (dt array) from (r0, v0), elliptic orbits."""
    r0, v0 = np.asarray(r0, float), np.asarray(v0, float)
    dt = np.atleast_1d(np.asarray(dt, float))
    rn, vn = np.linalg.norm(r0), np.linalg.norm(v0)
    a = 1.0 / (2.0 / rn - vn * vn / MU)
    n = np.sqrt(MU / a ** 3)
    h = np.cross(r0, v0)
    h_hat = h / np.linalg.norm(h)
    evec = np.cross(v0, h) / MU - r0 / rn
    evec = evec - np.dot(evec, h_hat) * h_hat          # rounding noise out of the plane
    e = np.linalg.norm(evec)
    p_hat = evec / e if e > 1e-10 else r0 / rn         # circular: any in-plane reference
    e = e if e > 1e-10 else 0.0
    q_hat = np.cross(h_hat, p_hat)
    nu0 = np.arctan2(np.dot(r0, q_hat), np.dot(r0, p_hat))
    E0 = 2 * np.arctan(np.sqrt((1 - e) / (1 + e)) * np.tan(nu0 / 2))
    M = E0 - e * np.sin(E0) + n * dt
    E = M.copy()
    for _ in range(50):
        E = E - (E - e * np.sin(E) - M) / (1 - e * np.cos(E))
    x = a * (np.cos(E) - e)
    y = a * np.sqrt(1 - e * e) * np.sin(E)
    rdot = np.sqrt(MU * a) / (a * (1 - e * np.cos(E)))
    vx = -rdot * np.sin(E)
    vy = rdot * np.sqrt(1 - e * e) * np.cos(E)
    r = x[:, None] * p_hat + y[:, None] * q_hat
    v = vx[:, None] * p_hat + vy[:, None] * q_hat
    return r, v


# ---------------------------------------------------------------------------------- attitude
def skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def passive_rotation(theta):
    """A(exp(θ)) = cos φ I + (1 − cos φ) e eᵀ − sin φ [e×], φ = |θ|."""
    phi = np.linalg.norm(theta)
    if phi == 0:
        return np.eye(3)
    e = theta / phi
    return np.cos(phi) * np.eye(3) + (1 - np.cos(phi)) * np.outer(e, e) - np.sin(phi) * skew(e)


def euler321(phi_deg, theta_deg, psi_deg):
    """A = R1(ψ) R2(θ) R3(φ), passive elementary rotations (Bernard eq. 3.7)."""
    f, t, p = np.radians([phi_deg, theta_deg, psi_deg])
    R3 = np.array([[np.cos(f), np.sin(f), 0], [-np.sin(f), np.cos(f), 0], [0, 0, 1]])
    R2 = np.array([[np.cos(t), 0, -np.sin(t)], [0, 1, 0], [np.sin(t), 0, np.cos(t)]])
    R1 = np.array([[1, 0, 0], [0, np.cos(p), np.sin(p)], [0, -np.sin(p), np.cos(p)]])
    return R1 @ R2 @ R3


def attitude(A0, omega_rad_s, t_s):
    """(N,3,3) A(t) = R(ω t) A0 (constant body rate from the epoch t = 0)."""
    return np.array([passive_rotation(np.asarray(omega_rad_s) * t) @ A0 for t in np.atleast_1d(t_s)])


def dcm_to_quat(A):
    """Scalar-first unit quaternion of a passive DCM (q0 > 0)."""
    q0 = 0.5 * np.sqrt(max(1.0 + np.trace(A), 1e-300))
    qv = np.array([A[1, 2] - A[2, 1], A[2, 0] - A[0, 2], A[0, 1] - A[1, 0]]) / (4 * q0)
    q = np.concatenate([[q0], qv])
    return q / np.linalg.norm(q)


def error_rotvec_deg(A_true, A_est):
    """δθ (deg, body axes) with A(δq) = A_true A_estᵀ (δq = q_true ⊗ q̂⁻¹)."""
    M = A_true @ A_est.T
    c = np.clip((np.trace(M) - 1) / 2, -1, 1)
    phi = np.arccos(c)
    w = -np.array([M[1, 2] - M[2, 1], M[2, 0] - M[0, 2], M[0, 1] - M[1, 0]]) / 2
    if phi < 1e-12:
        return np.degrees(-w)
    return np.degrees(-w * phi / np.sin(phi))


def quat_to_dcm(q):
    q = np.asarray(q, float) / np.linalg.norm(q)
    q0, v = q[0], q[1:]
    return (q0 * q0 - v @ v) * np.eye(3) + 2 * np.outer(v, v) - 2 * q0 * skew(v)


# ---------------------------------------------------------------------------------- photometry
def cook_torrance_product(ns, no, nh, c, xi, a, m):
    """(n·s)(n·o) f_r of Cook–Torrance (module docstring), arrays."""
    diff = xi * a / np.pi * ns * no
    sf = np.sqrt(a)
    nr = (1 + sf) / (1 - sf)
    g = np.sqrt(nr * nr + c * c - 1)
    F = 0.5 * ((g - c) / (g + c)) ** 2 * (1 + ((c * (g + c) - 1) / (c * (g - c) + 1)) ** 2)
    cos2 = nh * nh
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        D = np.exp((cos2 - 1) / (cos2 * m * m)) / (np.pi * m * m * cos2 * cos2)
        G = np.minimum(1.0, np.minimum(2 * nh * no / c, 2 * nh * ns / c))
        spec = (1 - xi) * 0.25 * F * D * G
    spec = np.where((nh > 0) & (c > 0), spec, 0.0)
    return diff + spec


def magnitudes(facets, A, s_unit, o_unit, range_obs, range_sun, sun_mag=-26.74):
    """Apparent magnitude per epoch. ``facets``: list of (normal, area, xi, a, m)."""
    flux = np.zeros(len(A))
    for n, area, xi, a, m in facets:
        # v_b = A v_I: the facet normal is fixed in the body, so n·s = n_b·(A s_I)
        sb = np.einsum("nij,nj->ni", A, s_unit)
        ob = np.einsum("nij,nj->ni", A, o_unit)
        nb = np.asarray(n, float)
        ns = sb @ nb
        no = ob @ nb
        h = sb + ob
        h = h / np.linalg.norm(h, axis=1, keepdims=True)
        nh = h @ nb
        c = np.sum(ob * h, axis=1)
        ok = (ns > 0) & (no > 0)
        val = cook_torrance_product(np.where(ok, ns, 1.0), np.where(ok, no, 1.0), nh, c, xi, a, m)
        flux += np.where(ok, area * val, 0.0)
    with np.errstate(divide="ignore"):   # no lit facet towards the observer: +inf
        return sun_mag - 2.5 * np.log10(flux / range_obs ** 2) + 5 * np.log10(range_sun / AU)


# ---------------------------------------------------------------------------------- the box
#: a 1.0 x 0.6 x 0.4 m box, distinct Cook–Torrance material per face: (normal, area, xi, a, m)
BOX = [((1, 0, 0), 0.24, 0.2, 0.6, 0.1), ((-1, 0, 0), 0.24, 0.3, 0.5, 0.15),
       ((0, 1, 0), 0.40, 0.5, 0.4, 0.2), ((0, -1, 0), 0.40, 0.6, 0.35, 0.25),
       ((0, 0, 1), 0.60, 0.8, 0.3, 0.3), ((0, 0, -1), 0.60, 0.9, 0.25, 0.4)]
BOX_HALF = (0.5, 0.3, 0.2)
BOX_MASS = 50.0


def write_box_library(folder, name="boxpanel"):
    """The box as a user library shape: an OBJ mesh (two triangles per face) + material TOML."""
    folder.mkdir(parents=True, exist_ok=True)
    hx, hy, hz = BOX_HALF
    v = [(sx * hx, sy * hy, sz * hz) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    idx = {p: k + 1 for k, p in enumerate(v)}

    def face(normal):
        ax = int(np.argmax(np.abs(normal)))
        sgn = np.sign(normal[ax])
        pts = [p for p in v if np.sign(p[ax]) == sgn]
        c = np.mean(pts, axis=0)
        u = [i for i in range(3) if i != ax]
        ang = [np.arctan2(p[u[1]] - c[u[1]], p[u[0]] - c[u[0]]) for p in pts]
        ring = [pts[k] for k in np.argsort(ang)]
        # counter-clockwise seen from outside: flip when the right-hand normal points inward
        n_rh = np.cross(np.subtract(ring[1], ring[0]), np.subtract(ring[2], ring[0]))
        if np.dot(n_rh, normal) < 0:
            ring = ring[::-1]
        a, b, c2, d = (idx[p] for p in ring)
        return [(a, b, c2), (a, c2, d)]

    lines = ["# box 1.0 x 0.6 x 0.4 m"] + [f"v {x} {y} {z}" for x, y, z in v]
    for n, *_ in BOX:
        for tri in face(np.asarray(n, float)):
            lines.append("f {} {} {}".format(*tri))
    (folder / f"{name}.obj").write_text("\n".join(lines) + "\n")
    ix = BOX_MASS * (0.6 ** 2 + 0.4 ** 2) / 12
    iy = BOX_MASS * (1.0 ** 2 + 0.4 ** 2) / 12
    iz = BOX_MASS * (1.0 ** 2 + 0.6 ** 2) / 12
    toml = [f'[shape]\nname = "{name}"\nmesh = "{name}.obj"\nmass_kg = {BOX_MASS}\n'
            f"inertia_diag_kg_m2 = [{ix}, {iy}, {iz}]\ndefault_material = \"f0\"\n"]
    for k, (n, _, xi, a, m) in enumerate(BOX):
        toml.append(f'[materials.f{k}]\nbrdf = "cook_torrance"\nxi = {xi}\na = {a}\nm = {m}\n')
        toml.append(f'[[material_map]]\nmaterial = "f{k}"\nnormal = [{n[0]}, {n[1]}, {n[2]}]\n')
    (folder / f"{name}.toml").write_text("\n".join(toml))
    return folder / f"{name}.toml"


# ---------------------------------------------------------------------------------- scenes
def overhead_state(ts, epoch, t_mid, lat, lon, h, altitude_m, offset_north_m=0.0, incl_turn=0.0):
    """A two-body (r, v) at the epoch for an object passing over the site at ``t_mid``."""
    R = gcrs_to_itrs(ts, utc_times(epoch, [t_mid]))[0]
    s = R.T @ site_itrs(lat, lon, h)
    E, N, U = (R.T @ row for row in enu_rows(lat, lon))
    p = s + altitude_m * U + offset_north_m * N
    vdir = np.cos(incl_turn) * E + np.sin(incl_turn) * N
    vdir = vdir - np.dot(vdir, p) / np.dot(p, p) * p
    v = np.sqrt(MU / np.linalg.norm(p)) * vdir / np.linalg.norm(vdir)
    r0, v0 = kepler(p, v, [-t_mid])
    return r0[0], v0[0]


def observe(ts, eph, epoch, t_s, r_obj, site_lla):
    """Per epoch: site GCRS, alt/az (deg), range (m), unit vectors object→Sun/observer,
    ranges, phase angle (deg) and a cylindrical-shadow lit flag."""
    times = utc_times(epoch, t_s)
    R = gcrs_to_itrs(ts, times)
    s_itrs = site_itrs(*site_lla)
    r_site = np.einsum("nji,j->ni", R, s_itrs)
    d_itrs = np.einsum("nij,nj->ni", R, r_obj - r_site)
    enu = d_itrs @ enu_rows(site_lla[0], site_lla[1]).T
    rng = np.linalg.norm(d_itrs, axis=1)
    alt = np.degrees(np.arcsin(enu[:, 2] / rng))
    az = np.degrees(np.arctan2(enu[:, 0], enu[:, 1])) % 360.0
    r_sun = sun_gcrs(ts, eph, times)
    to_sun = r_sun - r_obj
    to_obs = r_site - r_obj
    s_u = to_sun / np.linalg.norm(to_sun, axis=1, keepdims=True)
    o_u = to_obs / np.linalg.norm(to_obs, axis=1, keepdims=True)
    phase = np.degrees(np.arccos(np.clip(np.sum(s_u * o_u, axis=1), -1, 1)))
    sh = r_sun / np.linalg.norm(r_sun, axis=1, keepdims=True)
    along = np.sum(r_obj * sh, axis=1)
    perp = np.linalg.norm(r_obj - along[:, None] * sh, axis=1)
    lit = (along > 0) | (perp > R_EARTH)
    return {"alt": alt, "az": az, "range": rng, "s": s_u, "o": o_u,
            "range_sun": np.linalg.norm(to_sun, axis=1), "phase": phase, "lit": lit}


def rv_to_elements(r, v):
    """Osculating (a m, e, i, Ω, ω, M rad) of a two-body state (Vallado Algorithm 9 style)."""
    r, v = np.asarray(r, float), np.asarray(v, float)
    rn, vn = np.linalg.norm(r), np.linalg.norm(v)
    h = np.cross(r, v)
    nvec = np.cross([0, 0, 1.0], h)
    evec = np.cross(v, h) / MU - r / rn
    e = np.linalg.norm(evec)
    a = 1.0 / (2.0 / rn - vn * vn / MU)
    i = np.arccos(h[2] / np.linalg.norm(h))
    raan = np.arctan2(nvec[1], nvec[0]) % (2 * np.pi)
    if e < 1e-8:  # circular: perigee undefined; argument of latitude from the node
        e, argp = 0.0, 0.0
        nu = np.arccos(np.clip(np.dot(nvec, r) / (np.linalg.norm(nvec) * rn), -1, 1))
        if r[2] < 0:
            nu = 2 * np.pi - nu
    else:
        argp = np.arccos(np.clip(np.dot(nvec, evec) / (np.linalg.norm(nvec) * e), -1, 1))
        if evec[2] < 0:
            argp = 2 * np.pi - argp
        nu = np.arccos(np.clip(np.dot(evec, r) / (e * rn), -1, 1))
        if np.dot(r, v) < 0:
            nu = 2 * np.pi - nu
    E = 2 * np.arctan(np.sqrt((1 - e) / (1 + e)) * np.tan(nu / 2))
    M = (E - e * np.sin(E)) % (2 * np.pi)
    return a, e, i, raan, argp, M


def tle_lines(satnum, epoch: datetime, r, v, intldesg="22001A"):
    """TLE lines (sgp4's exporter) of mean elements set equal to the osculating elements of
    (r, v) at ``epoch`` (a test object: SGP4 then follows a nearby, slightly different path)."""
    from sgp4.api import WGS72, Satrec
    from sgp4.exporter import export_tle

    a, e, i, raan, argp, M = rv_to_elements(r, v)
    jd = 2440587.5 + epoch.timestamp() / 86400.0
    sat = Satrec()
    n_rad_min = np.sqrt(MU / a ** 3) * 60.0
    sat.sgp4init(WGS72, "i", int(satnum), jd - 2433281.5, 0.0, 0.0, 0.0, e, argp, i, M,
                 n_rad_min, raan)
    sat.classification = "U"
    sat.intldesg = intldesg
    return export_tle(sat)


def sgp4_gcrs(ts, line1, line2, times):
    """GCRS position (m) of a TLE object by skyfield (the SGP4/TEME oracle)."""
    from skyfield.api import EarthSatellite

    sat = EarthSatellite(line1, line2, ts=ts)
    return np.asarray(sat.at(ts.from_datetimes(times)).position.m).reshape(3, -1).T


def refused_without_blocking(fn, path, timeout_s: float = 10.0) -> str:
    """Run ``fn(path)`` in a thread; it must raise within ``timeout_s`` (a reader opening a
    FIFO without O_NONBLOCK would block for ever). Returns the exception text."""
    import threading

    box = {}

    def run():
        try:
            fn(path)
        except Exception as exc:  # noqa: BLE001 - the caller checks the type through the text
            box["msg"] = f"{type(exc).__name__}: {exc}"

    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.join(timeout_s)
    assert not th.is_alive(), f"reading {path} blocked"
    return box.get("msg", "")
