"""Time scales and solar-system ephemeris, strictly offline.

Everything here goes through skyfield with the files shipped by the ``skyfield-data`` package:
the JPL ephemeris ``de421.bsp`` (valid 1899-07-29 to 2053-10-09) and skyfield's *builtin*
timescale (leap seconds and ΔT tables bundled with skyfield itself). Nothing is ever
downloaded; a missing file raises :class:`FileNotFoundError` with the path that was searched.

Conventions
-----------
* A scenario has an epoch ``epoch_utc`` (ISO 8601 text, UTC) and times ``t_s`` in SI seconds
  since that epoch. :func:`skyfield_times` turns the pair into one vectorised skyfield ``Time``.
  The seconds are added on the UTC scale (``ts.utc(..., second + t_s)``); across a leap second
  this follows skyfield's UTC arithmetic.
* Positions are geocentric **GCRS** (our ECI), in metres, shape ``(N, 3)``. skyfield's
  geocentric positions are expressed in ICRS-aligned axes, which is the GCRS axis set.
"""

from __future__ import annotations

import atexit
import functools
import os
import warnings
from datetime import datetime, timedelta, timezone

import numpy as np

from ..errors import InputError

__all__ = [
    "AU_M",
    "DE421_START_UTC",
    "DE421_END_UTC",
    "ephemeris_dir",
    "loader",
    "timescale",
    "ephemeris",
    "parse_epoch",
    "epoch_iso",
    "skyfield_times",
    "sun_position_gcrs",
    "moon_position_gcrs",
]

AU_M = 149_597_870_700.0
"""Astronomical unit in metres (IAU 2012 Resolution B2, exact)."""

# de421.bsp coverage (JPL header: JED 2414864.5 to 2471184.5); a day of margin either side
# keeps skyfield's interpolation away from the segment edges.
DE421_START_UTC = datetime(1899, 7, 30, tzinfo=timezone.utc)
DE421_END_UTC = datetime(2053, 10, 8, tzinfo=timezone.utc)


def ephemeris_dir() -> str:
    """Folder of the ``skyfield-data`` package's data files (``de421.bsp`` ...).

    We locate the folder directly instead of calling ``skyfield_data.get_skyfield_data_path()``,
    because that function emits a ``RuntimeWarning`` once ``finals2000A.all`` (the IERS Earth
    orientation table the package also ships) passes its expiry date. We never read that
    file: timescales come from skyfield's builtin tables and the ephemeris ``de421.bsp``
    itself does not expire (it is valid until 2053), so the warning does not apply to us.
    """
    try:
        import skyfield_data
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise FileNotFoundError("the 'skyfield-data' package is not installed; it ships "
                                "de421.bsp (pip install skyfield-data)") from exc
    path = os.path.join(os.path.dirname(os.path.abspath(skyfield_data.__file__)), "data")
    if not os.path.isdir(path):  # pragma: no cover - fall back to the package's own function
        with warnings.catch_warnings():
            # expiry of finals2000A.all is irrelevant to us (see above)
            warnings.simplefilter("ignore", RuntimeWarning)
            path = skyfield_data.get_skyfield_data_path()
    return path


@functools.lru_cache(maxsize=1)
def loader():
    """A skyfield ``Loader`` on :func:`ephemeris_dir`, never downloading (cached)."""
    from skyfield.api import Loader

    return Loader(ephemeris_dir(), verbose=False, expire=False)


@functools.lru_cache(maxsize=1)
def timescale():
    """skyfield's builtin ``Timescale`` (bundled leap seconds and ΔT; no download; cached)."""
    return loader().timescale(builtin=True)


@functools.lru_cache(maxsize=1)
def ephemeris():
    """The JPL DE421 ephemeris from ``skyfield-data`` (cached).

    Raises
    ------
    FileNotFoundError
        If ``de421.bsp`` is not in :func:`ephemeris_dir` (we never download it).
    """
    path = os.path.join(ephemeris_dir(), "de421.bsp")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"ephemeris file {path} is missing; reinstall 'skyfield-data' "
                                "(lightcurve never downloads ephemerides)")
    eph = loader()("de421.bsp")
    atexit.register(eph.close)  # close the memory-mapped file at exit (no ResourceWarning)
    return eph


def parse_epoch(epoch_utc) -> datetime:
    """Parse an ISO 8601 UTC epoch into a timezone-aware :class:`datetime` in UTC.

    Accepts ``"2020-03-01T08:08:40"``, ``"2020-03-01 08:08:40.5Z"``, ``"...+00:00"`` (any
    explicit offset is converted to UTC; text without an offset is taken as UTC), a
    ``datetime`` (naive = UTC; pandas ``Timestamp`` included), a ``numpy.datetime64`` (UTC), a
    scalar skyfield ``Time`` or a scalar astropy ``Time`` (any scale; converted to UTC).
    Sub-microsecond digits are dropped (``datetime`` resolution).

    Raises
    ------
    InputError
        Text that is not ISO 8601, or an epoch outside the DE421 range (1899-07-30 to
        2053-10-08).
    """
    if isinstance(epoch_utc, datetime):
        dt = epoch_utc
    elif isinstance(epoch_utc, np.datetime64):
        if np.isnat(epoch_utc):
            raise InputError("not a date-time (NaT)", field="epoch_utc", value=str(epoch_utc))
        us = int(epoch_utc.astype("datetime64[us]").astype("int64"))
        dt = datetime(1970, 1, 1, tzinfo=timezone.utc) + timedelta(microseconds=us)
    elif _is_skyfield_time(epoch_utc) or _is_astropy_time(epoch_utc):
        dt = _time_object_to_datetime(epoch_utc)
    elif isinstance(epoch_utc, str):
        text = epoch_utc.strip()
        if text.endswith(("Z", "z")):
            text = text[:-1] + "+00:00"
        try:
            dt = datetime.fromisoformat(text)
        except ValueError:
            raise InputError("not an ISO 8601 date-time", field="epoch_utc", value=epoch_utc,
                             allowed="e.g. 2020-03-01T08:08:40Z") from None
    else:
        raise InputError("expected an ISO 8601 UTC text, a datetime or a Time",
                         field="epoch_utc", value=epoch_utc)
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=timezone.utc)
    try:
        dt = dt.astimezone(timezone.utc)
    except (OverflowError, ValueError):  # e.g. 0001-01-01T00:00:00+01:00 is before year 1 UTC
        raise InputError("epoch outside the DE421 ephemeris range", field="epoch_utc",
                         value=epoch_utc, allowed="1899-07-30 to 2053-10-08 UTC") from None
    if not (DE421_START_UTC <= dt <= DE421_END_UTC):
        raise InputError("epoch outside the DE421 ephemeris range", field="epoch_utc",
                         value=epoch_utc, allowed="1899-07-30 to 2053-10-08 UTC")
    return dt


def epoch_iso(epoch_utc) -> str:
    """The epoch as ISO 8601 UTC text with a ``Z`` (what files and scenarios store).

    Takes anything :func:`parse_epoch` accepts; whole seconds print without a fraction,
    otherwise microseconds are kept (``"2020-03-01T08:08:40.250000Z"``).
    """
    dt = parse_epoch(epoch_utc)
    spec = "seconds" if dt.microsecond == 0 else "microseconds"
    return dt.replace(tzinfo=None).isoformat(timespec=spec) + "Z"


def _is_astropy_time(x) -> bool:
    return type(x).__name__ == "Time" and type(x).__module__.startswith("astropy")


def _time_object_to_datetime(t) -> datetime:
    """A scalar skyfield or astropy ``Time`` as an aware UTC datetime (InputError otherwise)."""
    if np.ndim(getattr(t, "tt", getattr(t, "jd", 0.0))) != 0 or getattr(t, "shape", ()) != ():
        raise InputError("an epoch must be one time, not an array of times", field="epoch_utc",
                         value=str(t))
    if _is_astropy_time(t):
        dt = t.utc.to_datetime(timezone=timezone.utc)
    else:  # skyfield: utc_datetime() rounds to the microsecond and handles leap seconds
        dt = t.utc_datetime()
    return dt


def _as_times(t_s) -> np.ndarray:
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    if t.ndim != 1:
        raise ValueError(f"t_s must be a scalar or 1-D array, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("t_s contains NaN or infinite values")
    return t


def skyfield_times(epoch_utc, t_s):
    """skyfield ``Time`` array for ``epoch_utc + t_s`` (``t_s`` seconds, scalar or 1-D).

    Always returns a vector ``Time`` of length N (a scalar ``t_s`` gives N = 1).

    Raises
    ------
    InputError
        Bad epoch, or an epoch + offset outside the DE421 range.
    """
    dt = parse_epoch(epoch_utc)
    t = _as_times(t_s)
    span = (t.min(), t.max()) if t.size else (0.0, 0.0)
    lo = (DE421_START_UTC - dt).total_seconds()
    hi = (DE421_END_UTC - dt).total_seconds()
    if span[0] < lo or span[1] > hi:
        raise InputError("times reach outside the DE421 ephemeris range", field="t_s",
                         value=(float(span[0]), float(span[1])),
                         allowed="1899-07-30 to 2053-10-08 UTC")
    sec = dt.second + dt.microsecond * 1e-6
    return timescale().utc(dt.year, dt.month, dt.day, dt.hour, dt.minute, sec + t)


def _body_gcrs(name: str, epoch_utc, t_s, light_time: bool) -> np.ndarray:
    eph = ephemeris()
    t = epoch_utc if is_time(epoch_utc) else skyfield_times(epoch_utc, t_s)
    earth, body = eph["earth"], eph[name]
    if light_time:
        pos = earth.at(t).observe(body).position.m
    else:
        pos = (body - earth).at(t).position.m
    return np.ascontiguousarray(np.asarray(pos, dtype=float).reshape(3, -1).T)


def _is_skyfield_time(x) -> bool:
    return type(x).__name__ == "Time" and hasattr(x, "tt") and hasattr(x, "ts")


def is_time(x) -> bool:
    """True for a skyfield ``Time`` *array* (the explicit-times form of the geometry
    functions, ``t_s`` ignored); a scalar ``Time`` is an epoch like any other."""
    return _is_skyfield_time(x) and np.ndim(x.tt) > 0


def sun_position_gcrs(epoch_utc, t_s=0.0, *, light_time: bool = True) -> np.ndarray:
    """Geocentric position of the Sun, GCRS axes, metres, shape ``(N, 3)``.

    Parameters
    ----------
    epoch_utc : str, datetime, numpy.datetime64, skyfield or astropy Time
        Scenario epoch (:func:`parse_epoch`). A skyfield ``Time`` *array* may be passed
        instead, in which case ``t_s`` is ignored.
    t_s : float or array (N,)
        Seconds since the epoch.
    light_time : bool
        True (default): astrometric position, where the Sun was when the light now arriving
        at the Earth left it (~499 s light time); False: geometric (instantaneous) position.
        They differ by only ~5 km (the Sun's barycentric motion during the light time).
        Annual aberration (≈20", the apparent direction for an observer moving with the
        Earth) is not applied; it is irrelevant for illumination and eclipse geometry.
    """
    return _body_gcrs("sun", epoch_utc, t_s, light_time)


def moon_position_gcrs(epoch_utc, t_s=0.0, *, light_time: bool = True) -> np.ndarray:
    """Geocentric position of the Moon, GCRS axes, metres, shape ``(N, 3)``.

    Same arguments as :func:`sun_position_gcrs` (astrometric by default, ~1.3 s light time).
    """
    return _body_gcrs("moon", epoch_utc, t_s, light_time)
