"""Physical constants, each defined once (SI units).

Every module that needs one of these imports it from here (directly or through its
package's re-export); a value is never typed twice.
"""

from __future__ import annotations

__all__ = [
    "AU_M", "MU_EARTH", "R_EARTH_M", "R_EARTH_GRAVITY_M", "OMEGA_EARTH", "C_LIGHT_M_S",
    "P_SUN_1AU", "SUN_MAG_V", "R_SUN_M",
]

AU_M = 149_597_870_700.0
"""Astronomical unit, m (IAU 2012 Resolution B2, exact)."""

MU_EARTH = 3.986004418e14
"""Earth's gravitational parameter GM, m³/s² (WGS84 G1762 / EGM2008)."""

R_EARTH_M = 6_378_137.0
"""WGS84 equatorial radius, m."""

R_EARTH_GRAVITY_M = 6_378_136.3
"""Reference radius of the EGM2008 zonal coefficients, m."""

OMEGA_EARTH = 7.292115e-5
"""Earth's rotation rate, rad/s (IERS conventional mean; about the GCRS z axis, precession
and nutation neglected)."""

C_LIGHT_M_S = 299_792_458.0
"""Speed of light in vacuum, m/s (SI, exact)."""

P_SUN_1AU = 4.56e-6
"""Solar radiation pressure at 1 au on a perfect absorber, N/m² (Markley & Crassidis 2014,
§3.4 environmental torques)."""

SUN_MAG_V = -26.74
"""Apparent V magnitude of the Sun at 1 au (Bernard 2021 eq. 5.2)."""

R_SUN_M = 6.957e8
"""Nominal solar radius, m (IAU 2015 Resolution B3)."""
