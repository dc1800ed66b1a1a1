"""Observation geometry: time and ephemeris, sites, orbits, frames, eclipses, visibility,
schedules and the vectorised per-epoch geometry object (see DESIGN.md).

Conventions: GCRS is our ECI; SI units (m, m/s, rad, s); times are seconds since a scenario
epoch given as ISO 8601 UTC text; everything offline (skyfield + skyfield-data's de421.bsp +
skyfield's builtin timescale).

Submodules: :mod:`.time`, :mod:`.sites`, :mod:`.orbits`, :mod:`.frames`, :mod:`.eclipse`,
:mod:`.visibility`, :mod:`.schedules`, :mod:`.observation`.
"""

from .eclipse import lit_fraction, shadow_region
from .frames import (altaz, earth_pole_gcrs, gcrs_to_itrs, itrs_rotation, itrs_to_gcrs,
                     lvlh_dcm, nadir_dcm, rsw_dcm)
from .observation import ObservationGeometry, compute_geometry
from .orbits import (MU_EARTH, R_EARTH_M, KeplerElements, Orbit, coe_to_rv, kepler_propagate,
                     orbit_from_section, positions_from_topocentric, propagate_orbit, rv_to_coe,
                     tle_positions)
from .schedules import (bernard_switching_schedule, bernard_switching_windows, build_schedule,
                        cadence_grid, windows_from_flags)
from .sites import Site, get_site, load_sites, site_position_gcrs
from .time import (moon_position_gcrs, parse_epoch, skyfield_times, sun_position_gcrs,
                   timescale)
from .visibility import (UnlitPassWarning, airmass_kasten_young, check_illumination,
                         illumination_report)

__all__ = [
    "lit_fraction", "shadow_region",
    "altaz", "earth_pole_gcrs", "gcrs_to_itrs", "itrs_rotation", "itrs_to_gcrs", "lvlh_dcm",
    "nadir_dcm", "rsw_dcm",
    "ObservationGeometry", "compute_geometry",
    "MU_EARTH", "R_EARTH_M", "KeplerElements", "Orbit", "coe_to_rv", "kepler_propagate",
    "orbit_from_section", "positions_from_topocentric", "propagate_orbit", "rv_to_coe",
    "tle_positions",
    "bernard_switching_schedule", "bernard_switching_windows", "build_schedule", "cadence_grid",
    "windows_from_flags",
    "Site", "get_site", "load_sites", "site_position_gcrs",
    "moon_position_gcrs", "parse_epoch", "skyfield_times", "sun_position_gcrs", "timescale",
    "UnlitPassWarning", "airmass_kasten_young", "check_illumination", "illumination_report",
]
