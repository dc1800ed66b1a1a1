"""The vectorised observation geometry: everything the measurement models need per epoch.

:func:`compute_geometry` takes the measurement epochs (seconds since a UTC epoch), which site
measures at each epoch, the sites, and the object's GCRS positions, and returns an
:class:`ObservationGeometry` of arrays with one row per epoch. All vectors are GCRS (ECI),
metres; angles radians.

Approximations: geometric positions of object and site at the same instant (no light time
object→observer, ≤ 0.01 s for LEO-to-GEO; no aberration); the Sun astrometric (light-time
corrected) as seen from the geocentre, and the Sun direction from the object computed from
that geocentric Sun vector (parallax is exact since both are in metres). Topocentric angles
are geometric (no refraction).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .eclipse import lit_fraction as _lit_fraction
from .frames import enu_to_altaz, itrs_rotation
from .sites import enu_matrix, get_site, site_itrs_m
from .time import epoch_iso, skyfield_times, sun_position_gcrs
from .visibility import DEFAULT_TWILIGHT_DEG, airmass_kasten_young, check_illumination

__all__ = ["ObservationGeometry", "compute_geometry"]


@dataclass
class ObservationGeometry:
    """Geometry of N measurement epochs (GCRS, SI units).

    Attributes (arrays with N rows)
    -------------------------------
    t : (N,) s since ``epoch_utc``
    site_index : (N,) int, index into ``sites``
    r_obj_eci_m, r_site_eci_m, r_sun_eci_m : (N, 3) geocentric positions, m
    v_obj_eci_m_s : (N, 3) object velocity, m/s (NaN if not given)
    obj_to_sun_unit, obj_to_obs_unit : (N, 3) unit vectors from the object, ECI
    range_obs_m, range_sun_m : (N,) object→observer and object→Sun distances, m
    phase_angle_rad : (N,) angle between object→Sun and object→observer (0 = full phase)
    elevation_rad, azimuth_rad : (N,) geometric topocentric altitude and azimuth (from north
        through east) of the object at the measuring site
    airmass : (N,) Kasten & Young (1989) relative air mass; NaN below the horizon
    lit_fraction : (N,) visible fraction of the solar disc at the object (0 umbra … 1 lit)
    sun_elevation_rad : (N,) Sun altitude at the site
    above_horizon, site_dark, sunlit, visible : (N,) bool; ``sunlit = lit_fraction > 0``,
        ``visible = above_horizon & site_dark & sunlit``

    Scalars: ``epoch_utc`` (str), ``sites`` (list of Site), ``twilight_deg``, ``eclipse_model``.
    """

    epoch_utc: str
    sites: list
    twilight_deg: float
    eclipse_model: str
    t: np.ndarray
    site_index: np.ndarray
    r_obj_eci_m: np.ndarray
    v_obj_eci_m_s: np.ndarray
    r_site_eci_m: np.ndarray
    r_sun_eci_m: np.ndarray
    obj_to_sun_unit: np.ndarray
    obj_to_obs_unit: np.ndarray
    range_obs_m: np.ndarray
    range_sun_m: np.ndarray
    phase_angle_rad: np.ndarray
    elevation_rad: np.ndarray
    azimuth_rad: np.ndarray
    airmass: np.ndarray
    lit_fraction: np.ndarray
    sun_elevation_rad: np.ndarray
    above_horizon: np.ndarray
    site_dark: np.ndarray
    sunlit: np.ndarray
    visible: np.ndarray

    _SCALARS = ("epoch_utc", "sites", "twilight_deg", "eclipse_model")

    def __len__(self) -> int:
        return int(self.t.size)

    def subset(self, mask) -> "ObservationGeometry":
        """A new geometry with only the rows selected by a boolean mask or index array."""
        kw = {}
        for f in fields(self):
            v = getattr(self, f.name)
            kw[f.name] = v if f.name in self._SCALARS else v[mask]
        return ObservationGeometry(**kw)

    def check_illumination(self, ignore_eclipse: bool = False):
        """See :func:`lightcurve.geometry.visibility.check_illumination` (warns if unlit)."""
        return check_illumination(self, ignore_eclipse, stacklevel=3)

    def summary(self) -> dict:
        """Per-site counts of epochs, above-horizon, dark, sunlit, visible; min/max elevation."""
        out = {}
        for k, site in enumerate(self.sites):
            m = self.site_index == k
            el = np.degrees(self.elevation_rad[m])
            out[site.id] = {
                "n_epochs": int(m.sum()),
                "n_above_horizon": int(self.above_horizon[m].sum()),
                "n_dark": int(self.site_dark[m].sum()),
                "n_sunlit": int(self.sunlit[m].sum()),
                "n_umbra": int((self.lit_fraction[m] <= 0).sum()),
                "n_visible": int(self.visible[m].sum()),
                "elevation_deg_min": float(el.min()) if el.size else float("nan"),
                "elevation_deg_max": float(el.max()) if el.size else float("nan"),
            }
        return out


def _unit(x):
    n = np.linalg.norm(x, axis=-1, keepdims=True)
    return x / n, n[..., 0]


def compute_geometry(epoch_utc, t_s, site_index, sites, r_obj_eci_m, v_obj_eci_m=None, *,
                     twilight_deg: float = DEFAULT_TWILIGHT_DEG, eclipse_model: str = "conical",
                     sites_dirs=None) -> ObservationGeometry:
    """Evaluate the observation geometry at N epochs.

    Parameters
    ----------
    epoch_utc : str
        Scenario epoch, ISO 8601 UTC.
    t_s : (N,) float
        Measurement times, seconds since ``epoch_utc``.
    site_index : (N,) int or int
        Which entry of ``sites`` measures at each epoch (a scalar applies to all).
    sites : list of Site or site specs (ids / inline tables)
    r_obj_eci_m : (N, 3)
        Object GCRS positions at the same epochs, m.
    v_obj_eci_m : (N, 3), optional
        Object GCRS velocities, m/s (stored only).
    twilight_deg : float
        Sun altitude (deg) below which a site is dark; default −12 (nautical).
    eclipse_model : {"conical", "cylindrical"}
    sites_dirs : optional
        Extra site catalog folders for resolving ids.

    Raises
    ------
    ValueError
        Inconsistent shapes or a site index out of range.
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    n = t.size
    sites = [get_site(s, sites_dirs) for s in sites]
    if not sites:
        raise ValueError("compute_geometry needs at least one site")
    sidx = np.asarray(site_index)
    if sidx.ndim == 0:
        sidx = np.full(n, int(sidx), dtype=np.int64)
    sidx = sidx.astype(np.int64)
    if sidx.shape != (n,):
        raise ValueError(f"site_index must have shape ({n},), got {sidx.shape}")
    if n and (sidx.min() < 0 or sidx.max() >= len(sites)):
        raise ValueError(f"site_index out of range 0..{len(sites) - 1}")
    r_obj = np.asarray(r_obj_eci_m, dtype=float).reshape(-1, 3)
    if r_obj.shape != (n, 3):
        raise ValueError(f"r_obj_eci_m must have shape ({n}, 3), got {r_obj.shape}")
    if v_obj_eci_m is None:
        v_obj = np.full((n, 3), np.nan)
    else:
        v_obj = np.asarray(v_obj_eci_m, dtype=float).reshape(-1, 3)
        if v_obj.shape != (n, 3):
            raise ValueError(f"v_obj_eci_m must have shape ({n}, 3), got {v_obj.shape}")

    times = skyfield_times(epoch_utc, t)
    R = itrs_rotation(times)                                   # (N,3,3) GCRS → ITRS
    r_sun = sun_position_gcrs(times)                           # (N,3)
    s_itrs = np.array([site_itrs_m(s) for s in sites])          # (K,3)
    enu = np.array([enu_matrix(s.lat_rad, s.lon_rad) for s in sites])  # (K,3,3)
    r_site_itrs = s_itrs[sidx]
    r_site = np.einsum("nji,nj->ni", R, r_site_itrs)           # Rᵀ r_itrs
    M = np.einsum("nij,njk->nik", enu[sidx], R)                # GCRS → ENU at the site

    to_sun, range_sun = _unit(r_sun - r_obj)
    to_obs, range_obs = _unit(r_site - r_obj)
    phase = np.arccos(np.clip(np.sum(to_sun * to_obs, -1), -1.0, 1.0))
    el, az, _ = enu_to_altaz(np.einsum("nij,nj->ni", M, r_obj - r_site))
    sun_el, _, _ = enu_to_altaz(np.einsum("nij,nj->ni", M, r_sun - r_site))
    lit = _lit_fraction(r_obj, r_sun, eclipse_model)
    horizon = np.zeros(n)
    for k, s in enumerate(sites):
        m = sidx == k
        if s.horizon_mask is not None and np.any(m):
            horizon[m] = s.horizon_rad(az[m])
    above = el > horizon
    dark = sun_el < np.radians(twilight_deg)
    sunlit = lit > 0.0
    return ObservationGeometry(
        epoch_utc=epoch_utc if isinstance(epoch_utc, str) else epoch_iso(epoch_utc), sites=sites, twilight_deg=float(twilight_deg),
        eclipse_model=eclipse_model, t=t, site_index=sidx, r_obj_eci_m=r_obj,
        v_obj_eci_m_s=v_obj, r_site_eci_m=r_site, r_sun_eci_m=r_sun, obj_to_sun_unit=to_sun,
        obj_to_obs_unit=to_obs, range_obs_m=range_obs, range_sun_m=range_sun,
        phase_angle_rad=phase, elevation_rad=el, azimuth_rad=az,
        airmass=airmass_kasten_young(el), lit_fraction=lit, sun_elevation_rad=sun_el,
        above_horizon=above, site_dark=dark, sunlit=sunlit, visible=above & dark & sunlit)
