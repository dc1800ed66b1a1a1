"""Ground observing sites: the catalog in ``observatories/*.toml`` and their ECI positions.

A site file (one site per file, UTF-8 TOML)::

    id = "socorro"                    # [a-z0-9_-]+, how scenarios refer to the site
    name = "Socorro, New Mexico"
    lat_deg = 33.8173                 # WGS84 geodetic latitude, degrees north, [-90, 90]
    lon_deg = -106.66                 # WGS84 longitude, degrees east, [-180, 360)
    height_m = 1500.0                 # height above the WGS84 ellipsoid, metres, [-500, 9000]
    band = "V"                        # photometric band (optional, default "V")
    source = "Bernard (2021) table 9.3"   # optional free text
    [horizon_mask]                    # optional: minimum altitude versus azimuth
    az_deg = [0, 90, 180, 270]        # azimuth from north through east, strictly increasing in [0, 360)
    alt_deg = [10, 15, 10, 5]         # minimum altitude there, degrees, [-5, 90]

The mask is linearly interpolated in azimuth, wrapping through north. Without a mask the
horizon is the astronomical horizon (altitude 0).

The bundled catalog is searched first, then each user folder in order; a later folder may
redefine an id (user folders override the bundled catalog). Two files defining the same id in
one folder are an error.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._paths import data_dir
from ..errors import InputError
from ..io.tomlio import Section, load_toml

__all__ = [
    "itrs_to_geodetic",
    "Site",
    "load_sites",
    "get_site",
    "site_from_section",
    "inline_site_id",
    "site_position_gcrs",
    "site_position_velocity_gcrs",
    "site_itrs_m",
    "enu_matrix",
]

_ID_RE = re.compile(r"^[a-z0-9][a-z0-9_\-]*$")

# WGS84 ellipsoid (NIMA TR8350.2)
WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563


@dataclass(frozen=True)
class Site:
    """A ground observatory.

    Attributes
    ----------
    id : str
        Catalog identifier (``"socorro"``).
    name : str
        Human-readable name.
    lat_deg, lon_deg : float
        WGS84 geodetic latitude and longitude, degrees (north, east positive).
    height_m : float
        Height above the WGS84 ellipsoid, metres.
    horizon_mask : tuple of (az_deg, alt_deg) pairs or None
        Minimum observable altitude versus azimuth (degrees), azimuth strictly increasing in
        [0, 360); linearly interpolated with wrap-around. None means altitude 0 everywhere.
    band : str
        Photometric band the site observes in.
    source : str
        Where the coordinates come from (free text).
    """

    id: str
    name: str
    lat_deg: float
    lon_deg: float
    height_m: float
    horizon_mask: tuple | None = None
    band: str = "V"
    source: str = ""
    file: str | None = field(default=None, compare=False)

    def __post_init__(self):
        for key, lo, hi in (("lat_deg", -90.0, 90.0), ("lon_deg", -180.0, 360.0),
                            ("height_m", -500.0, 9000.0)):
            v = getattr(self, key)
            if not np.isfinite(v) or not (lo <= v <= hi):
                raise InputError("site coordinate out of range", file=self.file,
                                 field=key, value=v, allowed=f"[{lo}, {hi}]")
        if self.horizon_mask is not None:
            az = np.array([p[0] for p in self.horizon_mask], dtype=float)
            alt = np.array([p[1] for p in self.horizon_mask], dtype=float)
            if az.size < 1 or np.any(np.diff(az) <= 0) or az[0] < 0 or az[-1] >= 360:
                raise InputError("horizon mask azimuths must be strictly increasing in [0, 360)",
                                 file=self.file, field="horizon_mask.az_deg",
                                 value=az.tolist())
            if np.any(alt < -5) or np.any(alt > 90):
                raise InputError("horizon mask altitude out of range", file=self.file,
                                 field="horizon_mask.alt_deg", value=alt.tolist(),
                                 allowed="[-5, 90] degrees")

    @property
    def lat_rad(self) -> float:
        return float(np.radians(self.lat_deg))

    @property
    def lon_rad(self) -> float:
        return float(np.radians(self.lon_deg))

    def horizon_rad(self, az_rad) -> np.ndarray:
        """Minimum observable altitude (rad) at azimuth(s) ``az_rad`` (rad, from north via east)."""
        az = np.asarray(az_rad, dtype=float)
        if self.horizon_mask is None:
            return np.zeros_like(az)
        maz = np.array([p[0] for p in self.horizon_mask], dtype=float)
        malt = np.array([p[1] for p in self.horizon_mask], dtype=float)
        return np.radians(np.interp(np.degrees(az) % 360.0, maz, malt, period=360.0))

    def describe(self) -> str:
        """Multi-line human-readable description (for ``lightcurve sites show``)."""
        lines = [f"id:        {self.id}", f"name:      {self.name}",
                 f"latitude:  {self.lat_deg:.6f} deg (WGS84 geodetic)",
                 f"longitude: {self.lon_deg:.6f} deg east",
                 f"height:    {self.height_m:.1f} m above the WGS84 ellipsoid",
                 f"band:      {self.band}"]
        if self.horizon_mask:
            mask = ", ".join(f"{a:g}:{h:g}" for a, h in self.horizon_mask)
            lines.append(f"horizon:   az:alt deg {mask}")
        else:
            lines.append("horizon:   0 deg (no mask)")
        if self.source:
            lines.append(f"source:    {self.source}")
        if self.file:
            lines.append(f"file:      {self.file}")
        return "\n".join(lines)


def itrs_to_geodetic(r_itrs_m):
    """WGS84 geodetic latitude (rad), longitude (rad) and height (m) of ITRS point(s) (m),
    ``(N, 3)`` → three ``(N,)`` arrays.

    Fixed-point iteration of ``φ = atan2(z, p (1 − e² N/(N + h)))`` with the height in the form
    ``h = p cos φ + z sin φ − N (1 − e² sin²φ)`` (valid at all latitudes); ten iterations reach
    < 1e-12 rad for any point above the Earth's centre region.
    """
    r = np.atleast_2d(np.asarray(r_itrs_m, dtype=float))
    e2 = WGS84_F * (2.0 - WGS84_F)
    p = np.hypot(r[:, 0], r[:, 1])
    z = r[:, 2]
    lat = np.arctan2(z, p * (1.0 - e2))
    for _ in range(10):
        n = WGS84_A_M / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
        h = p * np.cos(lat) + z * np.sin(lat) - n * (1.0 - e2 * np.sin(lat) ** 2)
        lat = np.arctan2(z, p * (1.0 - e2 * n / (n + h)))
    n = WGS84_A_M / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
    h = p * np.cos(lat) + z * np.sin(lat) - n * (1.0 - e2 * np.sin(lat) ** 2)
    return lat, np.arctan2(r[:, 1], r[:, 0]), h


def inline_site_id(table, position: int | None = None) -> str:
    """The id of an inline site table (the id rule, docs/formats.md "Sites").

    1. its ``id`` key when given (validated by :func:`site_from_section`);
    2. else its ``name`` turned into an id: lower case, every run of characters other than
       ``a-z``, ``0-9``, ``_`` and ``-`` replaced by one ``-``, leading/trailing ``-`` removed
       (``"My Site 2"`` → ``"my-site-2"``);
    3. else ``site-<k>`` for the k-th (1-based) ``[[sites]]`` entry of a scenario
       (``position`` = k − 1), or ``"inline"`` for a table outside a scenario.
    """
    data = table.data if isinstance(table, Section) else dict(table)
    sid = data.get("id")
    if isinstance(sid, str):
        return sid
    name = data.get("name")
    if isinstance(name, str):
        slug = re.sub(r"[^a-z0-9_\-]+", "-", name.strip().lower()).strip("-")
        if slug and _ID_RE.match(slug):
            return slug
    return "inline" if position is None else f"site-{int(position) + 1}"


def site_from_section(sec: Section, *, site_id: str | None = None) -> Site:
    """Build a :class:`Site` from a validated TOML table (a site file or an inline table).

    Inline tables need only ``lat_deg``, ``lon_deg``, ``height_m``; without ``id`` the id is
    ``site_id`` (callers pass :func:`inline_site_id`; a site file passes its file stem) or
    ``"inline"``.
    """
    sid = sec.str("id", site_id or "inline")
    if not _ID_RE.match(sid):
        raise InputError("bad site id", file=sec.file, field=sec.field_name("id"), value=sid,
                         allowed="lower-case letters, digits, '_' and '-'")
    name = sec.str("name", sid)
    lat = sec.float("lat_deg", min=-90.0, max=90.0)
    lon = sec.float("lon_deg", min=-180.0, max=360.0, max_open=True)
    h = sec.float("height_m", min=-500.0, max=9000.0)
    band = sec.str("band", "V")
    source = sec.str("source", "")
    mask = None
    msec = sec.section("horizon_mask", None)
    if msec is not None:
        az = msec.vector("az_deg", min=0.0, max=360.0, max_open=True)
        alt = msec.vector("alt_deg", min=-5.0, max=90.0)
        msec.check_unknown()
        if az.size != alt.size or az.size == 0:
            raise InputError("az_deg and alt_deg must have the same, non-zero length",
                             file=sec.file, field=msec.name, value=(az.size, alt.size))
        mask = tuple((float(a), float(b)) for a, b in zip(az, alt))
    sec.check_unknown()
    return Site(sid, name, lat, lon, h, mask, band, source,
                file=None if sec.file is None else str(sec.file))


def _bundled_dir() -> Path | None:
    try:
        return data_dir("observatories")
    except FileNotFoundError:
        return None


def _load_dir(d: Path) -> dict[str, Site]:
    out: dict[str, Site] = {}
    for f in sorted(d.glob("*.toml")):
        site = site_from_section(Section(load_toml(f), file=f), site_id=f.stem)
        if site.id in out:
            raise InputError(f"site id '{site.id}' defined twice in one folder (also in "
                             f"{out[site.id].file})", file=f, field="id", value=site.id)
        out[site.id] = site
    return out


@functools.lru_cache(maxsize=8)
def _load_cached(dirs: tuple) -> dict:
    sites: dict[str, Site] = {}
    for d in dirs:
        sites.update(_load_dir(Path(d)))
    return sites


def load_sites(dirs=None) -> dict[str, Site]:
    """Load the site catalog: the bundled ``observatories/`` folder, then each of ``dirs``.

    Parameters
    ----------
    dirs : path or list of paths, optional
        Extra folders of ``*.toml`` site files; later folders override earlier ones and the
        bundled catalog.

    Returns
    -------
    dict mapping id → :class:`Site` (a fresh dict; the parsed files are cached).

    Raises
    ------
    InputError
        A folder that does not exist, or a bad site file (names file and key).
    """
    if dirs is None:
        dirs = []
    elif isinstance(dirs, (str, Path)):
        dirs = [dirs]
    paths = []
    b = _bundled_dir()
    if b is not None:
        paths.append(str(b.resolve()))
    for d in dirs:
        p = Path(d)
        if not p.is_dir():
            raise InputError("site folder not found", file=p, allowed="a folder of *.toml files")
        paths.append(str(p.resolve()))
    return dict(_load_cached(tuple(paths)))


def get_site(spec, dirs=None) -> Site:
    """Resolve a site specification.

    Parameters
    ----------
    spec : str or dict or Section or Site
        A catalog id (``"socorro"``), an inline table with ``lat_deg``, ``lon_deg``,
        ``height_m`` (optional ``id``, ``name``, ``band``, ``horizon_mask``), or a Site.
    dirs : optional
        Extra catalog folders, as for :func:`load_sites`.

    Raises
    ------
    InputError
        Unknown id (the message lists the known ids) or a bad inline table.
    """
    if isinstance(spec, Site):
        return spec
    if isinstance(spec, str):
        sites = load_sites(dirs)
        if spec not in sites:
            raise InputError("unknown site", field="site", value=spec,
                             allowed=", ".join(sorted(sites)) or "(no sites in the catalog)")
        return sites[spec]
    if isinstance(spec, Section):
        return site_from_section(spec, site_id=inline_site_id(spec))
    if isinstance(spec, dict):
        return site_from_section(Section(spec, name="site"), site_id=inline_site_id(spec))
    raise InputError("expected a site id or a table with lat_deg, lon_deg, height_m",
                     field="site", value=spec)


def site_itrs_m(site: Site) -> np.ndarray:
    """Earth-fixed (ITRS/WGS84 ECEF) position of the site, metres, shape (3,)."""
    lat, lon, h = site.lat_rad, site.lon_rad, site.height_m
    e2 = WGS84_F * (2.0 - WGS84_F)
    n = WGS84_A_M / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
    return np.array([(n + h) * np.cos(lat) * np.cos(lon),
                     (n + h) * np.cos(lat) * np.sin(lon),
                     (n * (1.0 - e2) + h) * np.sin(lat)])


def enu_matrix(lat_rad: float, lon_rad: float) -> np.ndarray:
    """Rotation ITRS → local East-North-Up at geodetic (lat, lon): rows are E, N, U in ITRS."""
    sl, cl = np.sin(lat_rad), np.cos(lat_rad)
    so, co = np.sin(lon_rad), np.cos(lon_rad)
    return np.array([[-so, co, 0.0],
                     [-sl * co, -sl * so, cl],
                     [cl * co, cl * so, sl]])


def _topos(site: Site):
    from skyfield.api import wgs84

    return wgs84.latlon(site.lat_deg, site.lon_deg, elevation_m=site.height_m)


def site_position_velocity_gcrs(site: Site, epoch_utc, t_s=0.0):
    """GCRS position (m) and velocity (m/s) of a site, each shape ``(N, 3)`` (via skyfield).

    ``epoch_utc`` may be a skyfield ``Time`` array, in which case ``t_s`` is ignored.
    """
    from .time import is_time, skyfield_times

    t = epoch_utc if is_time(epoch_utc) else skyfield_times(epoch_utc, t_s)
    p = _topos(site).at(t)
    r = np.asarray(p.position.m, dtype=float).reshape(3, -1).T
    v = np.asarray(p.velocity.m_per_s, dtype=float).reshape(3, -1).T
    return np.ascontiguousarray(r), np.ascontiguousarray(v)


def site_position_gcrs(site: Site, epoch_utc, t_s=0.0) -> np.ndarray:
    """GCRS (ECI) position of a site at ``epoch_utc + t_s``, metres, shape ``(N, 3)``.

    Computed by skyfield (WGS84 geodetic → ITRS → GCRS with IAU 2000A nutation, builtin UT1;
    no polar motion). ``site`` may be any spec accepted by :func:`get_site`.
    """
    return site_position_velocity_gcrs(get_site(site), epoch_utc, t_s)[0]
