"""Synthetic geometry for the physics-effect tests (no ephemeris needed).

A circular equatorial orbit of radius 7000 km, a site on the equator turning with the Earth,
the Sun fixed at 1 au along a chosen direction, and a constant-rate attitude. Every quantity
is also available analytically at any time, so tests can re-evaluate the model at shifted
times independently of lightcurve.physics.
"""

import numpy as np

from lightcurve.physics import ModelContext

AU = 149_597_870_700.0
MU = 3.986004418e14
R_ORB = 7000e3
R_SITE = 6378137.0
W_E = 7.292115e-5
N_ORB = np.sqrt(MU / R_ORB**3)


def qmul(q, p):
    """Hamilton-form product in Bernard's convention (eq. 3.20), written out by hand."""
    q1, qv = q[..., :1], q[..., 1:]
    p1, pv = p[..., :1], p[..., 1:]
    s = q1 * p1 - np.sum(qv * pv, -1, keepdims=True)
    v = q1 * pv + p1 * qv - np.cross(qv, pv)
    return np.concatenate([s, v], -1)


def q_const_rate(q0, w, t):
    """exp(ω t) ⊗ q0 for body rate ω (body axes): the kinematics of Bernard eq. 4.12."""
    t = np.asarray(t, float)[..., None]
    wn = np.linalg.norm(w)
    ang = wn * t
    dq = np.concatenate([np.cos(ang / 2), np.sin(ang / 2) * (np.asarray(w) / wn)], -1)
    return qmul(dq, np.broadcast_to(q0, dq.shape))


def orbit(t):
    t = np.asarray(t, float)
    c, s = np.cos(N_ORB * t), np.sin(N_ORB * t)
    r = R_ORB * np.stack([c, s, np.zeros_like(c)], -1)
    v = R_ORB * N_ORB * np.stack([-s, c, np.zeros_like(c)], -1)
    return r, v


def site(t, lon0=-0.05):
    a = lon0 + W_E * np.asarray(t, float)
    return R_SITE * np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], -1)


Q0 = np.array([0.8, 0.2, -0.3, 0.4]) / np.linalg.norm([0.8, 0.2, -0.3, 0.4])
W = np.array([0.05, -0.03, 0.12])  # rad/s body


def make_ctx(shape, n=25, t_end=60.0, sun_dir=(-1.0, 0.4, 0.3), w=W, n_sites=1,
             ignore_eclipse=True, **kw):
    """Context of ``n`` epochs; the default Sun is 27° from the observer (low phase) and the
    eclipse is ignored (the Sun is on the far side of the Earth for this toy geometry)."""
    t = np.linspace(0.0, t_end, n)
    r, v = orbit(t)
    rs = site(t)
    sd = np.asarray(sun_dir, float)
    r_sun = np.broadcast_to(AU * sd / np.linalg.norm(sd), (n, 3)).copy()
    q = q_const_rate(Q0, w, t)
    d = r - rs
    el = np.arcsin(np.sum(d * rs, 1) / (np.linalg.norm(d, axis=1) * np.linalg.norm(rs, axis=1)))
    site_index = np.arange(n) % n_sites
    names = [f"s{k}" for k in range(n_sites)]
    return ModelContext(epoch_utc="2024-03-20T00:00:00Z", t=t, site_index=site_index,
                        site_names=names, shape=shape, q=q, omega=np.broadcast_to(w, (n, 3)),
                        r_obj_eci_m=r, v_obj_eci_m_s=v, r_site_eci_m=rs, r_sun_eci_m=r_sun,
                        elevation_rad=el, ignore_eclipse=ignore_eclipse, **kw)
