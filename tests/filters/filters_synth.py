"""Helpers of the filter tests: a hand-made LEO lightcurve that needs no ephemeris.

Geometry (fixed, ECI, metres): object at 500 km altitude over the site, the site 2,000 km
away on the ground side, the Sun in a direction giving a ~60° phase angle; the truth is the
controlled constant-rate model of :class:`lightcurve.dynamics.truth.ControlledTruth`, the
noise σ = m·r/3 of Bernard eq. 9.3 with r = 1 %.
"""

from __future__ import annotations

import numpy as np
from lightcurve import rotations as rot

R_E = 6_378_137.0
AU = 149_597_870_700.0


def make_curve(n=60, dt=5.0, seed=1, r_percent=1.0, acs_sigma_deg=0.1, omega_deg_s=(2.0, 1.0, 3.6),
               euler_deg=(-42.4122, 59.1601, 48.9897), shape="cube_1u_mixed", acs_mode="random_walk",
               dynamics="controlled", inertia=(0.002, 0.003, 0.004), eta_deg=1e-3,
               two_sites=False):
    """A synthetic lightcurve (module docstring) as a Lightcurve with truth.

    ``dynamics="uncontrolled"``: torque-free Euler's equations with the diagonal ``inertia``
    (kg m²) and white angular-acceleration noise of PSD root ``eta_deg`` (deg/s^{3/2}).
    ``two_sites``: every epoch is measured from two sites (rows interleaved, equal times).
    """
    from lightcurve.dynamics.truth import ControlledTruth, UncontrolledTruth
    from lightcurve.io.lightcurve_h5 import Lightcurve
    from lightcurve.photometry import apparent_magnitude, load_shape

    sh = load_shape(shape)
    t = np.arange(n) * dt
    site = np.zeros(n, dtype=np.int64)
    if two_sites:
        t = np.repeat(np.arange((n + 1) // 2) * dt, 2)[:n]
        site = np.arange(n) % 2
    rng = np.random.default_rng(seed)
    q0 = rot.euler321_to_quat(np.radians(euler_deg))
    if dynamics == "controlled":
        truth = ControlledTruth(q0, np.radians(omega_deg_s), np.radians(acs_sigma_deg), rng,
                                mode=acs_mode)
    else:
        truth = UncontrolledTruth(q0, np.radians(omega_deg_s), np.diag(inertia),
                                  eta_sigma_rad_s2=np.radians(eta_deg), rng=rng)
    q, w = truth.simulate(t)
    r_obj = np.tile([R_E + 500e3, 0.0, 0.0], (n, 1)) + np.outer(t, [0.0, 7.6e3, 0.0])
    r_site = np.tile([R_E * np.cos(0.25), R_E * np.sin(0.25), 0.0], (n, 1))
    if two_sites:
        r_site[site == 1] = [R_E * np.cos(-0.2), R_E * np.sin(-0.2) * 0.8, R_E * 0.6 * np.sin(0.2)]
    sun_dir = np.array([np.cos(np.radians(200.0)), np.sin(np.radians(200.0)), 0.3])
    sun_dir /= np.linalg.norm(sun_dir)
    r_sun = np.tile(sun_dir * AU, (n, 1))
    d_s = r_sun - r_obj
    d_o = r_site - r_obj
    m = apparent_magnitude(sh, q, d_s / np.linalg.norm(d_s, axis=1, keepdims=True),
                           d_o / np.linalg.norm(d_o, axis=1, keepdims=True),
                           np.linalg.norm(d_o, axis=1), np.linalg.norm(d_s, axis=1))
    sigma = m * r_percent / 100.0 / 3.0
    y = m + sigma * rng.standard_normal(n)
    if dynamics == "controlled":
        toml = f'[attitude]\ndynamics = "controlled"\nacs_sigma_deg = {acs_sigma_deg}\n'
    else:
        J = [[inertia[0], 0, 0], [0, inertia[1], 0], [0, 0, inertia[2]]]
        toml = (f'[attitude]\ndynamics = "uncontrolled"\neta_sigma_deg_s2 = {eta_deg}\n'
                f'inertia_kg_m2 = {J}\n')
    return Lightcurve(epoch_utc="2020-03-01T08:08:40Z", t=t, mag=y, mag_sigma=sigma,
                      site=site, site_names=["test", "test2"] if two_sites else ["test"],
                      site_lla_deg_m=(np.array([[0.0, 14.3, 0.0], [6.9, -11.5, 0.0]]) if two_sites
                                      else np.array([[0.0, 14.3, 0.0]])), r_obj_eci_m=r_obj,
                      r_site_eci_m=r_site, r_sun_eci_m=r_sun, truth_q=q, truth_omega_rad_s=w,
                      truth_mag=m, scenario_toml=toml,
                      attrs={"shape": shape, "r_percent": r_percent, "sun_mag": -26.74,
                             "ignore_eclipse": 1})
