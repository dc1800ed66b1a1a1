"""Sun-direction reference models for on-board filters (O'Keefe 2015, eq. 4.39, table 4.5).

Models of the inertial Sun direction used as the reference ``ŝ_N`` of the calibration and
attitude filters:

* ``"de421"`` — skyfield with the offline JPL DE421 ephemeris
  (:func:`lightcurve.geometry.time.sun_position_gcrs`), GCRS axes: the truth of this package;
* ``"vallado"`` — the Astronomical Almanac low-precision formula as given by Vallado
  (*Fundamentals of Astrodynamics and Applications*, 4th ed. 2013, algorithm 29, p. 279),
  quoted by O'Keefe as eq. 4.39, valid 1950-2050, ~0.01° in its own (mean-of-date) frame::

      T = (JD_UT1 − 2451545.0)/36525                     (T_TDB ≈ T_UT1 is used for M and ε)
      λ_M = 280.460° + 36000.771° T                    mean longitude
      M   = 357.5277233° + 35999.05034° T              mean anomaly (O'Keefe eq. 4.39c;
                                                       Vallado 2013 prints 357.5291092°,
                                                       1e-4° apart in the direction)
      λ   = λ_M + 1.914666471° sin M + 0.019994643° sin 2M     ecliptic longitude
      r   = 1.000140612 − 0.016708617 cos M − 0.000139589 cos 2M   (AU)
      ε   = 23.439291° − 0.0130042° T                  obliquity of the ecliptic
      r⃗☉ = r [cos λ, cos ε sin λ, sin ε sin λ]

  The formula's axes are the mean equator and equinox *of date*; used as if it were GCRS
  (what a flight computer with only this formula does) its direction differs from DE421 by
  the accumulated precession (≈ 50.3″/yr × years since J2000 along the ecliptic) plus the
  formula's own error — :func:`compare_models` reports both parts (table 4.5's comparison);
* ``"erfa"`` — the ERFA/SOFA routine ``epv00`` (pyerfa, installed with astropy): the Earth's
  heliocentric position from a series fitted to the planetary theory VSOP2000/DE405, BCRS
  (= GCRS) axes, quoted accuracy a few km (1900–2100). It stands where O'Keefe's table 4.5
  has Meeus's abbreviated VSOP87 and the full VSOP87B (eq. 4.40–4.42): a periodic-series
  model of the same class, from a maintained library, since the VSOP87 tables are not
  shipped here.

:func:`sun_model_table` measures table 4.5: each model's angle to DE421 (the SPICE truth
of the thesis; geometric positions, GCRS axes) over a year, also with a 6 h clock error, and
the time per call relative to the almanac formula.
"""

from __future__ import annotations

import numpy as np

from ..core.constants import AU_M
from .okeefe2015 import THESIS_RESULTS

__all__ = ["vallado_sun_eci", "erfa_sun_eci", "sun_direction", "compare_models",
           "sun_model_table", "SUN_MODELS", "THESIS_TABLE_4_5", "THESIS_ROW"]

SUN_MODELS = ("de421", "vallado", "erfa")

#: O'Keefe (2015) table 4.5 (``okeefe2015.THESIS_RESULTS["table4_5"]``): normalised mean
#: computation time and angular error vs SPICE, mean / max (deg); Meeus and VSOP87B are the
#: thesis's series models.
THESIS_TABLE_4_5 = THESIS_RESULTS["table4_5"]
#: the thesis row each row of :func:`sun_model_table` is compared with
THESIS_ROW = {"DE421 (skyfield)": "SPICE", "Vallado": "Vallado", "Vallado +6 h": "Vallado +6 h",
              "ERFA epv00": "VSOP87B", "ERFA epv00 +6 h": "Meeus +6 h"}


def vallado_sun_eci(jd_ut1, jd_tdb=None) -> np.ndarray:
    """Sun position (m) of the almanac formula (module docstring), mean-of-date axes, for
    Julian date(s) ``jd_ut1`` (UT1); ``jd_tdb`` (optional) is used for M and ε.  Returns
    (..., 3)."""
    jd_ut1 = np.asarray(jd_ut1, dtype=float)
    T = (jd_ut1 - 2451545.0) / 36525.0
    Tt = T if jd_tdb is None else (np.asarray(jd_tdb, dtype=float) - 2451545.0) / 36525.0
    lam_m = np.radians(np.mod(280.460 + 36000.771 * T, 360.0))
    M = np.radians(np.mod(357.5277233 + 35999.05034 * Tt, 360.0))
    lam = lam_m + np.radians(1.914666471 * np.sin(M) + 0.019994643 * np.sin(2.0 * M))
    r = 1.000140612 - 0.016708617 * np.cos(M) - 0.000139589 * np.cos(2.0 * M)
    eps = np.radians(23.439291 - 0.0130042 * Tt)
    return AU_M * r[..., None] * np.stack([np.cos(lam), np.cos(eps) * np.sin(lam),
                                           np.sin(eps) * np.sin(lam)], axis=-1)


def erfa_sun_eci(jd_tdb) -> np.ndarray:
    """Geometric geocentric Sun position (m), BCRS/GCRS axes, from ERFA ``epv00`` (the negated
    heliocentric Earth position) at TDB Julian date(s) ``jd_tdb``. Returns (..., 3)."""
    import erfa

    jd = np.asarray(jd_tdb, dtype=float)
    whole = np.floor(jd)
    pvh, _ = erfa.epv00(whole, jd - whole)
    return -AU_M * np.asarray(pvh["p"], dtype=float)


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
    elif model == "erfa":
        r = erfa_sun_eci(_times(epoch_utc, t_s).tdb)
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


def sun_model_table(start_utc="2015-06-01T00:00:00Z", days=365.25, step_h=1.0,
                    clock_error_h=6.0, timing_calls=2000) -> dict:
    """O'Keefe (2015) table 4.5 measured: for each model the angle (deg) between its Sun
    direction and DE421's (geometric, GCRS) sampled every ``step_h`` hours over ``days``
    from ``start_utc`` (default: the §2.4 epoch and one year, the errors' half-year period
    twice), as mean and max; the same with the model evaluated ``clock_error_h`` late (the
    thesis's "+6 h" rows); and the time per single-date call (``timing_calls`` calls,
    median of 5 repeats) relative to the almanac formula. The almanac's mean-of-date axes
    are taken as GCRS, as the thesis's comparison with SPICE does (its 0.23° is the
    precession since J2000 plus the formula's error).

    Returns ``{"rows": [{model, time_rel, mean_deg, max_deg}...], "start_utc", "days",
    "step_h", "us_per_call": {...}}``; the thesis's numbers are :data:`THESIS_TABLE_4_5`.
    The times are of Python calls (numpy scalars, pyerfa, skyfield), not of the thesis's C.
    """
    import time

    from ..geometry.time import sun_position_gcrs

    t = np.arange(0.0, days * 86400.0 + 1.0, step_h * 3600.0)
    truth = sun_position_gcrs(start_utc, t, light_time=False)
    ts = _times(start_utc, t)
    late = _times(start_utc, t + clock_error_h * 3600.0)
    cand = {"Vallado": vallado_sun_eci(ts.ut1, ts.tdb),
            f"Vallado +{clock_error_h:g} h": vallado_sun_eci(late.ut1, late.tdb),
            "ERFA epv00": erfa_sun_eci(ts.tdb),
            f"ERFA epv00 +{clock_error_h:g} h": erfa_sun_eci(late.tdb)}
    one = _times(start_utc, np.array([0.0]))
    jd_u, jd_t = float(one.ut1[0]), float(one.tdb[0])
    calls = {"Vallado": lambda: vallado_sun_eci(jd_u, jd_t),
             "ERFA epv00": lambda: erfa_sun_eci(jd_t),
             "DE421 (skyfield)": lambda: sun_position_gcrs(start_utc, 0.0, light_time=False)}
    us = {}
    for name, f in calls.items():
        f()
        n = timing_calls if name != "DE421 (skyfield)" else max(timing_calls // 20, 10)
        reps = []
        for _ in range(5):
            t0 = time.perf_counter()
            for _ in range(n):
                f()
            reps.append((time.perf_counter() - t0) / n * 1e6)
        us[name] = float(np.median(reps))
    rows = [{"model": "DE421 (skyfield)", "time_rel": us["DE421 (skyfield)"] / us["Vallado"],
             "mean_deg": None, "max_deg": None}]
    for name, r in cand.items():
        err = _angle_deg(r, truth)
        base = name.split(" +")[0]
        rows.append({"model": name, "time_rel": us[base] / us["Vallado"],
                     "mean_deg": float(np.mean(err)), "max_deg": float(np.max(err))})
    return {"rows": rows, "start_utc": str(start_utc), "days": float(days),
            "step_h": float(step_h), "us_per_call": us}
