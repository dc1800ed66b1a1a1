"""Photometric bands and the apparent magnitude of the Sun (at 1 au) in each.

The magnitude equation (DESIGN.md; Bernard 2021 eq. 5.2) measures an object's brightness
against the Sun's apparent magnitude *in the band of the measurement*; a recording in another
band (or magnitude system) needs that band's value, not the V-band −26.74.

Values (mag, apparent, at 1 au):

* ``V`` = −26.74: Bernard (2021) eq. 5.2/8.15 (Johnson V, Vega system) — the package default,
  kept for reproducing the thesis. Willmer (2018) gives M_V = 4.81 (Vega), i.e. −26.76 at 1 au,
  the same within its stated 0.02-mag uncertainty.
* ``B`` = −26.13, ``V_AB`` = −26.77, ``B_AB`` = −26.26: Willmer (2018), ApJS 236, 47,
  "The Absolute Magnitude of the Sun in Several Filters", abstract: M_B = 5.44, M_V = 4.81
  (Vega) and M_B = 5.31, M_V = 4.80 (AB); apparent magnitude at 1 au m = M − 31.572
  (5 log10(10 pc / 1 au), 1 pc = 206 264.806 au).
* ``u``, ``g``, ``r``, ``i``, ``z`` (SDSS, AB-like): SDSS DR16 "Estimates for the u, g, r, i, z
  colors of Vega and the Sun" (sdss.org/dr16/algorithms/ugrizVegaSun): M(g) = +5.12,
  u−g = 1.43, g−r = 0.44, r−i = 0.11, i−z = 0.03, so M = 6.55, 5.12, 4.68, 4.57, 4.54 and
  m = −25.02, −26.45, −26.89, −27.00, −27.03.
* ``AB532`` = −27.056: the conversion of Fankhauser, Askari & Tyson (2023) used for the
  Pomenis Starlink AB magnitudes (solar irradiance 1360 W m⁻² read as a spectral flux density
  F·λ/c at 532 nm against the AB zero point 3631 Jy; pipelines/real/starlink_pomenis.toml).

A band not in the table is refused with the list of known bands; a recording can instead give
the Sun's magnitude directly (``[recording] sun_mag``).
"""

from __future__ import annotations

from ..errors import InputError

__all__ = ["SUN_MAGNITUDES", "sun_magnitude", "BAND_SOURCES"]

_DM_1AU_10PC = 31.572  # 5 log10(10 pc / 1 au)

#: band name -> apparent magnitude of the Sun at 1 au (module docstring for the sources)
SUN_MAGNITUDES = {
    "V": -26.74,
    "B": round(5.44 - _DM_1AU_10PC, 3),
    "V_AB": round(4.80 - _DM_1AU_10PC, 3),
    "B_AB": round(5.31 - _DM_1AU_10PC, 3),
    "u": round(6.55 - _DM_1AU_10PC, 3),
    "g": round(5.12 - _DM_1AU_10PC, 3),
    "r": round(4.68 - _DM_1AU_10PC, 3),
    "i": round(4.57 - _DM_1AU_10PC, 3),
    "z": round(4.54 - _DM_1AU_10PC, 3),
    "AB532": -27.056,
}

#: band name -> where its value comes from (one line each)
BAND_SOURCES = {
    "V": "Bernard (2021) eq. 5.2 (Johnson V, Vega)",
    "B": "Willmer (2018) ApJS 236, 47: M_B = 5.44 (Vega)",
    "V_AB": "Willmer (2018) ApJS 236, 47: M_V = 4.80 (AB)",
    "B_AB": "Willmer (2018) ApJS 236, 47: M_B = 5.31 (AB)",
    "u": "SDSS DR16 ugrizVegaSun: M(g) = 5.12, u-g = 1.43",
    "g": "SDSS DR16 ugrizVegaSun: M(g) = 5.12",
    "r": "SDSS DR16 ugrizVegaSun: M(g) = 5.12, g-r = 0.44",
    "i": "SDSS DR16 ugrizVegaSun: r-i = 0.11",
    "z": "SDSS DR16 ugrizVegaSun: i-z = 0.03",
    "AB532": "Fankhauser, Askari & Tyson (2023): 1360 W/m^2 at 532 nm vs 3631 Jy",
}


def sun_magnitude(band: str, *, file=None, field: str = "band") -> float:
    """Apparent magnitude of the Sun at 1 au in ``band`` (:data:`SUN_MAGNITUDES`).

    Raises
    ------
    InputError
        An unknown band (the message lists the known ones and the ``sun_mag`` alternative).
    """
    if isinstance(band, str) and band in SUN_MAGNITUDES:
        return float(SUN_MAGNITUDES[band])
    raise InputError("unknown photometric band", file=file, field=field, value=band,
                     allowed=", ".join(SUN_MAGNITUDES) + " (or give the Sun's magnitude in the "
                     "band with [recording] sun_mag)")
