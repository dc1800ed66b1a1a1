"""Per-epoch visibility: horizon (and horizon masks), twilight, airmass, illumination checks.

The flags are computed for every epoch by :func:`lightcurve.geometry.observation.compute_geometry`;
this module holds the elementary pieces and the *unlit-pass* check that the simulator calls:
an object in the Earth's shadow reflects no sunlight, so a simulated lightcurve there is
physically meaningless unless the user asks for it explicitly (``ignore_eclipse=True``, used
to reproduce Bernard's (2021) published cases, whose LEO pass lies inside the umbra).
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = [
    "DEFAULT_TWILIGHT_DEG",
    "UnlitPassWarning",
    "airmass_kasten_young",
    "above_horizon",
    "site_dark",
    "illumination_report",
    "check_illumination",
]

DEFAULT_TWILIGHT_DEG = -12.0
"""Sun altitude below which a site counts as dark (nautical twilight), degrees."""


class UnlitPassWarning(UserWarning):
    """Some or all measurement epochs have the object in the Earth's shadow."""


def airmass_kasten_young(elevation_rad) -> np.ndarray:
    """Relative optical air mass (Kasten & Young 1989, Applied Optics 28, 4735, eq. 3).

    ``X = 1 / (sin h + 0.50572 (h° + 6.07995)^−1.6364)`` with ``h`` the altitude (the formula
    is for apparent altitude; we feed the geometric one, the difference — refraction, ≈0.5° at
    the horizon — changes X by < 15 % at h = 0 and < 0.1 % above 20°). Valid down to the
    horizon (X(0) ≈ 38); NaN below it.
    """
    h = np.asarray(elevation_rad, dtype=float)
    hd = np.degrees(h)
    with np.errstate(invalid="ignore", divide="ignore"):
        x = 1.0 / (np.sin(h) + 0.50572 * np.power(np.maximum(hd, -6.0) + 6.07995, -1.6364))
    return np.where(h >= 0, x, np.nan)


def above_horizon(site, elevation_rad, azimuth_rad) -> np.ndarray:
    """True where the elevation exceeds the site's horizon mask (0 without a mask)."""
    return np.asarray(elevation_rad) > site.horizon_rad(azimuth_rad)


def site_dark(sun_elevation_rad, twilight_deg: float = DEFAULT_TWILIGHT_DEG) -> np.ndarray:
    """True where the Sun is below ``twilight_deg`` (default −12°, nautical twilight)."""
    return np.asarray(sun_elevation_rad) < np.radians(twilight_deg)


def illumination_report(geom) -> dict:
    """Counts of lit / penumbra / umbra epochs of an :class:`ObservationGeometry`."""
    lit = np.asarray(geom.lit_fraction)
    n = lit.size
    return {
        "n_epochs": int(n),
        "n_sunlit": int(np.sum(lit >= 1.0)),
        "n_penumbra": int(np.sum((lit > 0) & (lit < 1))),
        "n_umbra": int(np.sum(lit <= 0)),
        "min_lit_fraction": float(lit.min()) if n else float("nan"),
        "max_lit_fraction": float(lit.max()) if n else float("nan"),
    }


def check_illumination(geom, ignore_eclipse: bool = False, *, stacklevel: int = 2) -> np.ndarray:
    """Warn loudly when measurement epochs are unlit; return the lit fraction to use.

    Parameters
    ----------
    geom : ObservationGeometry
    ignore_eclipse : bool
        False (default): return ``geom.lit_fraction`` (a shadowed object is dark) and emit an
        :class:`UnlitPassWarning` if any epoch is not fully sunlit. True: return ones (pretend
        the object is sunlit everywhere — what the published thesis cases did) and still
        warn, saying the switch is on.

    Returns
    -------
    (N,) array of irradiance factors in [0, 1].
    """
    rep = illumination_report(geom)
    n, nu, npen = rep["n_epochs"], rep["n_umbra"], rep["n_penumbra"]
    if nu or npen:
        what = ("the WHOLE pass is in the Earth's umbra" if nu == n else
                f"{nu} of {n} epochs in umbra, {npen} in penumbra")
        if ignore_eclipse:
            msg = (f"UNLIT PASS: {what}; ignore_eclipse=True, so the object is treated as "
                   "fully sunlit (as in Bernard 2021's published cases) — the magnitudes are "
                   "not physical")
        else:
            msg = (f"UNLIT PASS: {what}; magnitudes there are infinite/absent. Set "
                   "ignore_eclipse = true to reproduce cases that ignore the Earth's shadow")
        warnings.warn(msg, UnlitPassWarning, stacklevel=stacklevel)
    if ignore_eclipse:
        return np.ones(n)
    return np.asarray(geom.lit_fraction, dtype=float).copy()
