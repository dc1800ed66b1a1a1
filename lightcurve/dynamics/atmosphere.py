"""Exponential (piecewise) atmosphere density model.

``ρ(h) = ρ0,i exp(−(h − h0,i)/H_i)`` for ``h0,i <= h < h0,i+1``, with the base altitude
``h0,i``, base density ``ρ0,i`` and scale height ``H_i`` of the band that contains ``h``.

Source of the table: the exponential atmosphere table reproduced in Markley & Crassidis,
*Fundamentals of Spacecraft Attitude Determination and Control* (2014), ch. 3 (aerodynamic
torque section), which is taken from Vallado, *Fundamentals of Astrodynamics and
Applications* (4th ed., 2013) Table 8-4 (originally Wertz 1978, CIRA-72 based). It is a static
mean atmosphere: no solar or geomagnetic activity, no diurnal bulge. Above 1000 km the last
band is extrapolated.

Altitude is measured above a spherical Earth of equatorial radius ``R_EARTH_M`` when computed
from a position by :func:`altitude_m` (the drag torque uses that); callers with geodetic
heights may pass them directly to :func:`density_kg_m3`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["R_EARTH_M", "EXPONENTIAL_TABLE", "density_kg_m3", "altitude_m"]

R_EARTH_M = 6378137.0
"""Equatorial radius of the Earth (WGS84), m."""

# columns: base altitude h0 (km), base density rho0 (kg/m^3), scale height H (km)
# Markley & Crassidis (2014) exponential atmosphere table = Vallado (2013) Table 8-4.
EXPONENTIAL_TABLE = np.array([
    [0.0, 1.225, 7.249],
    [25.0, 3.899e-2, 6.349],
    [30.0, 1.774e-2, 6.682],
    [40.0, 3.972e-3, 7.554],
    [50.0, 1.057e-3, 8.382],
    [60.0, 3.206e-4, 7.714],
    [70.0, 8.770e-5, 6.549],
    [80.0, 1.905e-5, 5.799],
    [90.0, 3.396e-6, 5.382],
    [100.0, 5.297e-7, 5.877],
    [110.0, 9.661e-8, 7.263],
    [120.0, 2.438e-8, 9.473],
    [130.0, 8.484e-9, 12.636],
    [140.0, 3.845e-9, 16.149],
    [150.0, 2.070e-9, 22.523],
    [180.0, 5.464e-10, 29.740],
    [200.0, 2.789e-10, 37.105],
    [250.0, 7.248e-11, 45.546],
    [300.0, 2.418e-11, 53.628],
    [350.0, 9.518e-12, 53.298],
    [400.0, 3.725e-12, 58.515],
    [450.0, 1.585e-12, 60.828],
    [500.0, 6.967e-13, 63.822],
    [600.0, 1.454e-13, 71.835],
    [700.0, 3.614e-14, 88.667],
    [800.0, 1.170e-14, 124.64],
    [900.0, 5.245e-15, 181.05],
    [1000.0, 3.019e-15, 268.00],
])
"""Exponential atmosphere table: rows ``[h0_km, rho0_kg_m3, H_km]``."""

_H0_M = EXPONENTIAL_TABLE[:, 0] * 1e3
_RHO0 = np.ascontiguousarray(EXPONENTIAL_TABLE[:, 1])
_H_M = EXPONENTIAL_TABLE[:, 2] * 1e3


def density_kg_m3(h_m):
    """Atmospheric density (kg/m³) at altitude ``h_m`` (m; scalar or array, vectorised).

    Piecewise exponential model (Markley & Crassidis 2014 table; Vallado Table 8-4): the band
    ``i`` with ``h0_i <= h < h0_{i+1}`` gives ``ρ = ρ0_i exp(−(h − h0_i)/H_i)``. Valid from 0 km
    upwards (bands above 1000 km use the 1000 km row). Raises ``ValueError`` for NaN or a
    negative altitude.
    """
    h = np.asarray(h_m, dtype=float)
    if not np.all(np.isfinite(h)):
        raise ValueError("h_m: contains NaN or infinite values")
    if np.any(h < 0.0):
        raise ValueError(f"h_m: altitude below 0 km is outside the exponential atmosphere table "
                         f"(min given {float(np.min(h)):.6g} m; allowed h_m >= 0)")
    i = np.searchsorted(_H0_M, h, side="right") - 1
    out = _RHO0[i] * np.exp(-(h - _H0_M[i]) / _H_M[i])
    return out if out.ndim else float(out)


def altitude_m(r_eci_m):
    """Altitude (m) above a spherical Earth of radius ``R_EARTH_M`` of position(s) ``r_eci_m`` (…,3)."""
    r = np.asarray(r_eci_m, dtype=float)
    if r.ndim == 0 or r.shape[-1] != 3:
        raise ValueError(f"r_eci_m: expected shape (..., 3), got {r.shape}")
    if not np.all(np.isfinite(r)):
        raise ValueError("r_eci_m: contains NaN or infinite values")
    return np.linalg.norm(r, axis=-1) - R_EARTH_M
