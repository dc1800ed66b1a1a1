"""Sun-direction reference models for on-board filters (O'Keefe 2015, eq. 4.39, table 4.5).

Two models of the inertial Sun direction used as the reference ``ŝ_N`` of the calibration
and attitude filters:

* ``"de421"`` — skyfield with the offline JPL DE421 ephemeris
  (:func:`lightcurve.geometry.time.sun_position_gcrs`), GCRS axes: the truth of this package;
* ``"vallado"`` — the Astronomical Almanac low-precision formula as given by Vallado
  (*Fundamentals of Astrodynamics and Applications*, 4th ed. 2013, algorithm 29, p. 279),
  quoted by O'Keefe as eq. 4.39, valid 1950-2050, ~0.01° in its own (mean-of-date) frame::

      T = (JD_UT1 − 2451545.0)/36525                     (T_TDB ≈ T_UT1 is used for M and ε)
      λ_M = 280.460° + 36000.771° T                    mean longitude
      M   = 357.5291092° + 35999.05034° T              mean anomaly
      λ   = λ_M + 1.914666471° sin M + 0.019994643° sin 2M     ecliptic longitude
      r   = 1.000140612 − 0.016708617 cos M − 0.000139589 cos 2M   (AU)
      ε   = 23.439291° − 0.0130042° T                  obliquity of the ecliptic
      r⃗☉ = r [cos λ, cos ε sin λ, sin ε sin λ]

  The formula's axes are the mean equator and equinox *of date*; used as if it were GCRS
  (what a flight computer with only this formula does) its direction differs from DE421 by
  the accumulated precession (≈ 50.3″/yr × years since J2000 along the ecliptic) plus the
  formula's own error — :func:`compare_models` reports both parts (table 4.5's comparison).
"""

from __future__ import annotations

import numpy as np

from ..core.constants import AU_M

__all__ = ["vallado_sun_eci", "sun_direction", "compare_models", "SUN_MODELS"]

SUN_MODELS = ("de421", "vallado")


def vallado_sun_eci(jd_ut1, jd_tdb=None) -> np.ndarray:
    """Sun position (m) of the almanac formula (module docstring), mean-of-date axes, for
    Julian date(s) ``jd_ut1`` (UT1); ``jd_tdb`` (optional) is used for M and ε.  Returns
    (..., 3)."""
    jd_ut1 = np.asarray(jd_ut1, dtype=float)
    T = (jd_ut1 - 2451545.0) / 36525.0
    Tt = T if jd_tdb is None else (np.asarray(jd_tdb, dtype=float) - 2451545.0) / 36525.0
    lam_m = np.radians(np.mod(280.460 + 36000.771 * T, 360.0))
    M = np.radians(np.mod(357.5291092 + 35999.05034 * Tt, 360.0))
    lam = lam_m + np.radians(1.914666471 * np.sin(M) + 0.019994643 * np.sin(2.0 * M))
    r = 1.000140612 - 0.016708617 * np.cos(M) - 0.000139589 * np.cos(2.0 * M)
    eps = np.radians(23.439291 - 0.0130042 * Tt)
    return AU_M * r[..., None] * np.stack([np.cos(lam), np.cos(eps) * np.sin(lam),
                                           np.sin(eps) * np.sin(lam)], axis=-1)


def _times(epoch_utc, t_s):
    from ..geometry.time import skyfield_times

    return skyfield_times(epoch_utc, np.atleast_1d(np.asarray(t_s, dtype=float)))


def sun_direction(model: str, epoch_utc, t_s) -> np.ndarray:
    """Unit Sun direction(s) (N,3) from the Earth, ECI (GCRS for "de421"; the almanac's
    mean-of-date axes taken as ECI for "vallado"), at ``t_s`` s after ``epoch_utc``."""
    if model == "de421":
        from ..geometry.time import sun_position_gcrs

        r = sun_position_gcrs(epoch_utc, np.atleast_1d(np.asarray(t_s, dtype=float)))
    elif model == "vallado":
        ts = _times(epoch_utc, t_s)
        r = vallado_sun_eci(ts.ut1, ts.tdb)
    else:
        raise ValueError(f"unknown Sun model {model!r}; allowed: {', '.join(SUN_MODELS)}")
    return r / np.linalg.norm(r, axis=-1, keepdims=True)


def _angle_deg(a, b):
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    c = np.clip(np.sum(a * b, -1), -1.0, 1.0)
    s = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.degrees(np.arctan2(s, c))


def compare_models(dates_utc) -> list[dict]:
    """Angular differences (deg) between the almanac formula and DE421 at the given UTC dates.

    For each date: ``vs_gcrs_deg`` — almanac direction used as GCRS vs DE421 (GCRS), the
    error a filter makes when it takes the formula as ECI; ``vs_mean_of_date_deg`` — the
    almanac vs DE421 rotated into mean-of-date axes (skyfield's precession matrix; no
    nutation), the formula's intrinsic error; ``range_diff_km`` — difference in distance.
    """
    from ..geometry.time import sun_position_gcrs

    rows = []
    for d in dates_utc:
        ts = _times(d, 0.0)
        r_de = sun_position_gcrs(d, np.array([0.0]))[0]
        r_v = vallado_sun_eci(ts.ut1, ts.tdb)[0]
        P = np.asarray(ts.P)  # precession matrix GCRS(J2000) -> mean of date
        if P.ndim == 3:
            P = P[..., 0] if P.shape[-1] == 1 else P[0]
        r_de_mod = P @ r_de
        rows.append({"date_utc": str(d), "vs_gcrs_deg": float(_angle_deg(r_v, r_de)),
                     "vs_mean_of_date_deg": float(_angle_deg(r_v, r_de_mod)),
                     "range_diff_km": float((np.linalg.norm(r_v) - np.linalg.norm(r_de)) / 1e3)})
    return rows
