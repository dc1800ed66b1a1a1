"""Recording import: real apparent-magnitude measurements from observatory CSV files.

The column mapping (docs/formats.md, "Recordings (CSV)") is a :class:`RecordingSpec`: the
built-in default layout (header names ``utc`` or ``jd``, ``mag``, ``mag_sigma``, ``site``,
``object``, ``camera``, ``band``, ``exposure_start``/``exposure_end`` or ``exposure_s``,
``alt_deg``/``az_deg`` with ``range_m`` or ``height_m``, ``phase_deg``; every column but time
and magnitude optional) or a ``[recording]`` table (a scenario's, or a mapping file of its
own) that names or numbers the columns and sets fixed values (one site, one object, one band,
a default σ), units, the comment character, the delimiter and the time format.

One CSV may hold several objects, sites, cameras and bands: two objects, or two cameras, at
one instant are ordinary data. :func:`read_recordings` returns one
:class:`~lightcurve.io.lightcurve_h5.Lightcurve` per (object, band); :func:`read_recording`
the only one (an error naming the groups when there are several).

Pipeline (one small function per step): read the text (bounded, regular files only) →
resolve the columns → parse the rows → group by object and band → per group: resolve the
sites, sort and drop exact copies, times since the epoch, geometry, build, screen.

Geometry (object GCRS position), per object, from the first that applies:

1. ``topocentric``: alt/az + range or height columns
   (:func:`lightcurve.geometry.orbits.positions_from_topocentric`);
2. ``range_phase``: a range column and a solar phase angle column without alt/az. The phase
   angle fixes the observer direction only up to a rotation about the Sun line, so the line
   of sight comes from the object's orbit (its element set, else the model scenario's
   ``[orbit]``) and the recorded range is placed along it; the recomputed phase angle must
   agree with the recorded one within ``phase_tolerance_deg`` (else the orbit is not this
   object's: InputError naming the line). Largest differences in ``attrs``
   (``max_phase_residual_deg``, ``max_range_residual_m``);
3. ``elements``: the object's TLE/OMM element set (``element_sets``, matched by NORAD number or
   name; :mod:`lightcurve.geometry.tle`), with an :class:`ElementAgeWarning` far from its epoch;
4. ``orbit``: the model scenario's ``[orbit]``.

Site and Sun positions, elevations and lit fractions come from
:func:`lightcurve.geometry.observation.compute_geometry`.

Sites: per-row ids (``site`` column) or one fixed site, resolved against the model scenario's
``[[sites]]`` (catalogue or inline entries, ids by the rule of
:func:`lightcurve.geometry.sites.inline_site_id`), then the ``site_dirs`` folders, then the
bundled catalogue. Cameras: ids per row; stored as ``<site>/<camera>`` (a camera belongs to one
site). Band: the ``band`` column, else ``[recording] band``; the Sun magnitude is that band's
(:mod:`lightcurve.photometry.bands`) or ``[recording] sun_mag``; without either the file has no
``band`` attribute and the model's ``measurement.sun_mag`` applies. Exposures: ``t`` is the
mid-exposure time — the midpoint of ``exposure_start``/``exposure_end``, or the time column
shifted by half of ``exposure_s`` when ``time_stamp = "start"``/``"end"``; the duration is
stored per row (``Lightcurve.exposure_s``).

Row handling (documented, counted in ``Lightcurve.attrs``):

* blank lines and text after the comment character are ignored;
* an empty or ``nan`` magnitude skips the row (``attrs["skipped_nan_mag"]``);
* rows not in time order are sorted (stable); ``attrs["sorted_by_time"] = 1`` and
  ``attrs["n_out_of_order"]`` say so;
* an exact copy of a row (same time, object, site, camera and values) is skipped
  (``attrs["skipped_duplicate"]``); two different values at the same time from the same camera
  of the same site for the same object are an error naming both lines;
* rows with the object below the site's geometric horizon are skipped
  (``attrs["skipped_below_horizon"]``);
* rows with the object in the Earth's full shadow (lit fraction 0: it reflects no sunlight,
  so the model cannot have produced the measurement) are skipped by default and counted
  (``attrs["skipped_unlit"]``). ``unlit="keep"`` keeps them — counted in ``attrs["n_unlit"]``
  and announced with an ``UnlitPassWarning`` — for diagnosing shadow effects and for scenarios
  with ``measurement.ignore_eclipse = true`` (the default when such a scenario is given).
  Partly lit rows (penumbra) are always kept. The attitude filters skip, flag and count any
  unlit row that reaches them (:mod:`lightcurve.filters.gating`);
* every other bad value (wrong number of fields, unparsable time or number, altitude out of
  [-90, 90] / below 0 with a height, azimuth not finite, negative sigma/range, a phase angle
  outside [0, 180], an exposure end before its start, a height below the site, an unknown
  site, an object without element set) raises :class:`~lightcurve.errors.InputError` naming
  the file, the line number and the column.

Hardening: the file is read through :func:`lightcurve.io.safe_open.read_text` (regular
files only, at most :data:`MAX_CSV_BYTES`), at most :data:`MAX_ROWS` data rows, fields longer
than the csv module's limit are refused with the line number.
"""

from __future__ import annotations

import csv
import math
import warnings
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from ..errors import InputError
from .lightcurve_h5 import MAG_RANGE, Lightcurve
from .safe_open import CSV_MAX_BYTES, read_text
from .tomlio import Section

__all__ = ["RecordingSpec", "recording_spec_from_section", "read_recording", "read_recordings",
           "TIME_FORMATS", "MAX_CSV_BYTES", "MAX_ROWS"]

#: Accepted ``time_format`` values: ISO 8601 UTC text, Unix seconds (UTC), MJD and JD (UTC).
TIME_FORMATS = ("iso", "unix_s", "mjd_utc", "jd_utc")
#: largest recording read (bytes)
MAX_CSV_BYTES = CSV_MAX_BYTES
#: most data rows in one recording
MAX_ROWS = 2_000_000
_UNITS = {"m": 1.0, "km": 1000.0}
_UNIX0 = datetime(1970, 1, 1, tzinfo=timezone.utc)
_MJD0 = datetime(1858, 11, 17, tzinfo=timezone.utc)
_JD_MJD = 2400000.5
_STAMPS = ("mid", "start", "end")


@dataclass
class RecordingSpec:
    """How to read one CSV layout (the ``[recording]`` table; docs/formats.md).

    Column references are header names (str) or 0-based indices (int); ``None`` = absent.

    Attributes
    ----------
    time_column, mag_column : str | int
        Measurement time (format ``time_format``) and apparent magnitude.
    sigma_column / default_sigma_mag
        1σ magnitude noise per row, or one σ (mag, > 0) for every row.
    site_column / site
        Site id per row, or one fixed site id for all rows.
    object_column / object
        Object id per row (NORAD number or name: how element sets are matched), or one fixed id.
    camera_column
        Camera id per row (stored as ``<site>/<camera>``).
    band_column / band / sun_mag
        Photometric band per row, or one band; or the Sun's apparent magnitude in the band
        directly (mag at 1 au).
    exposure_start_column, exposure_end_column
        Exposure start and end (same ``time_format``): ``t`` = their midpoint.
    exposure_column, time_stamp
        Exposure duration (s) and what the time column marks: "mid" (default), "start", "end".
    alt_column, az_column
        Geometric topocentric altitude and azimuth (north through east), degrees.
    range_column / height_column
        Slant range site→object, or object height above the WGS84 ellipsoid, with
        ``range_unit`` / ``height_unit`` ("m" or "km"). At most one of the two.
    phase_column, phase_tolerance_deg
        Solar phase angle (deg, [0, 180]) and the largest accepted difference from the phase
        angle recomputed from the orbit (range + phase recordings; deg).
    comment, delimiter, header, time_format, epoch_utc
        Comment character ("" for none), one-character field separator, whether the first
        non-comment line holds column names (needed for named columns), one of
        :data:`TIME_FORMATS`, and the epoch ``t`` counts from (default: the model scenario's,
        else the first time).
    """

    time_column: object = "utc"
    mag_column: object = "mag"
    sigma_column: object = "mag_sigma"
    default_sigma_mag: float | None = None
    site_column: object = "site"
    site: str | None = None
    object_column: object = "object"
    object: str | None = None
    camera_column: object = "camera"
    band_column: object = "band"
    band: str | None = None
    sun_mag: float | None = None
    exposure_start_column: object = "exposure_start"
    exposure_end_column: object = "exposure_end"
    exposure_column: object = "exposure_s"
    time_stamp: str = "mid"
    alt_column: object = "alt_deg"
    az_column: object = "az_deg"
    range_column: object = "range_m"
    height_column: object = "height_m"
    phase_column: object = "phase_deg"
    phase_tolerance_deg: float = 1.0
    range_unit: str = "m"
    height_unit: str = "m"
    comment: str = "#"
    delimiter: str = ","
    header: bool = True
    time_format: str = "iso"
    epoch_utc: str | None = None
    #: True for the built-in default layout: optional columns may be missing from the file.
    defaults: bool = True


_COLUMN_KEYS = ("time_column", "mag_column", "sigma_column", "site_column", "object_column",
                "camera_column", "band_column", "exposure_start_column", "exposure_end_column",
                "exposure_column", "alt_column", "az_column", "range_column", "height_column",
                "phase_column")
#: short names used internally and in messages for each column key
_SHORT = {k: k[:-len("_column")] for k in _COLUMN_KEYS}


def recording_spec_from_section(sec) -> RecordingSpec:
    """Validate a ``[recording]`` table (a :class:`Section` or dict) into a :class:`RecordingSpec`.

    Keys: every ``*_column`` of :class:`RecordingSpec` (absent unless given, except
    ``time_column = "utc"`` and ``mag_column = "mag"``), ``default_sigma_mag``, ``site``,
    ``object``, ``band``, ``sun_mag``, ``time_stamp``, ``phase_tolerance_deg``, ``range_unit``
    / ``height_unit`` ("m" | "km"), ``comment`` ("#"), ``delimiter`` (","), ``header`` (true),
    ``time_format``, ``epoch_utc``.
    """
    if not isinstance(sec, Section):
        sec = Section(sec, name="recording")

    def col(key, default):
        v = sec.raw(key, default)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (str, int)) or (isinstance(v, int) and v < 0) \
                or (isinstance(v, str) and not v.strip()):
            raise InputError("expected a column name (text) or a 0-based column index", file=sec.file,
                             field=sec.field_name(key), value=v)
        return v.strip() if isinstance(v, str) else v

    cols = {k: col(k, {"time_column": "utc", "mag_column": "mag"}.get(k)) for k in _COLUMN_KEYS}
    if cols["exposure_start_column"] is not None and "time_column" not in sec.data:
        cols["time_column"] = None  # the exposure midpoint is the time
    spec = RecordingSpec(
        **cols,
        default_sigma_mag=sec.float("default_sigma_mag", None, min=0.0, min_open=True, max=10.0),
        site=sec.str("site", None),
        object=sec.str("object", None),
        band=sec.str("band", None),
        sun_mag=sec.float("sun_mag", None, min=-30.0, max=-20.0),
        time_stamp=sec.str("time_stamp", "mid", choices=_STAMPS),
        phase_tolerance_deg=sec.float("phase_tolerance_deg", 1.0, min=0.0, min_open=True, max=180.0),
        range_unit=sec.str("range_unit", "m", choices=tuple(_UNITS)),
        height_unit=sec.str("height_unit", "m", choices=tuple(_UNITS)),
        comment=sec.str("comment", "#"),
        delimiter=sec.str("delimiter", ","),
        header=sec.bool("header", True),
        time_format=sec.str("time_format", "iso", choices=TIME_FORMATS),
        epoch_utc=sec.str("epoch_utc", None),
        defaults=False,
    )
    sec.check_unknown()

    def err(key, msg, value=None, allowed=None):
        return InputError(msg, file=sec.file, field=sec.field_name(key), value=value, allowed=allowed)

    pairs = (("sigma_column", "default_sigma_mag"), ("site_column", "site"),
             ("object_column", "object"), ("band_column", "band"), ("band", "sun_mag"),
             ("band_column", "sun_mag"), ("range_column", "height_column"),
             ("exposure_column", "exposure_start_column"))
    for a, b in pairs:
        if getattr(spec, a) is not None and getattr(spec, b) is not None:
            raise err(b, f"give {a} or {b}, not both")
    if spec.mag_column is None:
        raise err("mag_column", "mag_column is required")
    if (spec.exposure_start_column is None) != (spec.exposure_end_column is None):
        raise err("exposure_end_column", "give both exposure_start_column and exposure_end_column")
    if spec.time_column is None and spec.exposure_start_column is None:
        raise err("time_column", "time_column is required (or exposure_start/end columns)")
    if spec.time_stamp != "mid" and spec.exposure_column is None:
        raise err("time_stamp", "time_stamp start/end needs an exposure_column (duration, s)")
    if (spec.alt_column is None) != (spec.az_column is None):
        raise err("alt_column", "give both alt_column and az_column, or neither")
    if spec.height_column is not None and spec.alt_column is None:
        raise err("alt_column", "a height column needs alt_column and az_column")
    if spec.phase_column is not None and (spec.alt_column is not None or spec.range_column is None):
        raise err("phase_column", "a phase-angle column goes with a range column and no alt/az")
    if len(spec.delimiter) != 1 or spec.delimiter in "\r\n\"":
        raise err("delimiter", "expected one character (not a quote or newline)", spec.delimiter)
    if len(spec.comment) > 1 or (spec.comment and spec.comment == spec.delimiter):
        raise err("comment", "expected one character (or \"\" for none), different from the delimiter",
                  spec.comment)
    if not spec.header:
        named = [k for k in _COLUMN_KEYS if isinstance(getattr(spec, k), str)]
        if named:
            raise err(named[0], "header = false: columns must be 0-based indices", getattr(spec, named[0]))
    if spec.band is not None:
        from ..photometry.bands import sun_magnitude

        sun_magnitude(spec.band, file=sec.file, field=sec._field("band"))
    if spec.epoch_utc is not None:
        from ..geometry.time import parse_epoch

        try:
            parse_epoch(spec.epoch_utc)
        except InputError as exc:
            raise err("epoch_utc", exc.bare_message, spec.epoch_utc, exc.allowed) from None
    return spec


def _as_spec(spec) -> RecordingSpec:
    if spec is None:
        return RecordingSpec()
    if isinstance(spec, (dict, Section)):
        return recording_spec_from_section(spec)
    if isinstance(spec, RecordingSpec):
        return spec
    raise TypeError("expected a Scenario, RecordingSpec, Section, dict or None")


# ----------------------------------------------------------------------------------------
# step 1: text → rows
# ----------------------------------------------------------------------------------------
def _read_rows(path: Path, spec: RecordingSpec):
    """(header or None, list of (line_no, fields)) with comments and blank lines removed."""
    # a regular file of at most CSV_MAX_BYTES (no FIFO, device or endless file)
    text = read_text(path, max_bytes=CSV_MAX_BYTES, what="CSV recording", encoding="utf-8-sig")
    header = None
    rows = []
    for no, line in enumerate(text.splitlines(), start=1):
        if spec.comment and spec.comment in line:
            line = line[: line.index(spec.comment)]
        if not line.strip():
            continue
        try:
            fields = [f.strip() for f in next(csv.reader([line], delimiter=spec.delimiter))]
        except csv.Error as exc:  # e.g. a field over csv.field_size_limit() characters
            raise InputError(f"unreadable CSV line: {exc}", file=path, field=f"line {no}",
                             allowed=f"fields of at most {csv.field_size_limit()} characters") from None
        if spec.header and header is None:
            header = (no, fields)
            continue
        rows.append((no, fields))
        if len(rows) > MAX_ROWS:
            raise InputError("too many data rows", file=path, value=f"> {MAX_ROWS}",
                             allowed=f"<= {MAX_ROWS} rows per file (split the recording)")
    if spec.header and header is None:
        raise InputError("no header line (and no data)", file=path)
    return header, rows


# ----------------------------------------------------------------------------------------
# step 2: which column holds what
# ----------------------------------------------------------------------------------------
def _resolve_columns(path, header, spec: RecordingSpec):
    """``(ci, colname, spec)``: column index per short key (None = absent), display names, and
    the spec (the default layout switches to ``jd`` times when the header has ``jd`` and no
    ``utc``)."""
    names = header[1] if header else []
    if spec.defaults and "utc" not in names and "jd" in names:
        from dataclasses import replace

        spec = replace(spec, time_column="jd", time_format="jd_utc")
    if spec.defaults and spec.time_column == "utc" and "utc" not in names \
            and "exposure_start" in names:
        from dataclasses import replace

        spec = replace(spec, time_column=None)
    ci = {}
    for key in _COLUMN_KEYS:
        ref = getattr(spec, key)
        short = _SHORT[key]
        if ref is None:
            ci[short] = None
        elif isinstance(ref, int):
            ci[short] = ref
        elif ref in names:
            ci[short] = names.index(ref)
        elif key in ("time_column", "mag_column") or not spec.defaults:
            raise InputError(f"column {ref!r} not found in the header (line {header[0] if header else '?'})",
                             file=path, field=f"recording.{key}", value=ref,
                             allowed=", ".join(names) or "(no header)")
        else:
            ci[short] = None
    if header is not None:
        for k, v in ci.items():
            if v is not None and v >= len(names):
                raise InputError(f"column index {v} beyond the {len(names)} header columns",
                                 file=path, field=f"recording.{k}_column", value=v)
    colname = {k: (names[v] if header and v is not None else (f"column {v}" if v is not None else None))
               for k, v in ci.items()}
    if spec.defaults:  # the default layout: alternatives and pairs checked on the header
        for a, b in (("range", "height"), ("exposure", "exposure_start")):
            if ci[a] is not None and ci[b] is not None:
                raise InputError(f"both {colname[a]} and {colname[b]} columns present; keep one",
                                 file=path, field=f"{colname[a]}/{colname[b]}")
        for a, b in (("alt", "az"), ("exposure_start", "exposure_end")):
            if (ci[a] is None) != (ci[b] is None):
                raise InputError(f"{getattr(spec, a + '_column')} and {getattr(spec, b + '_column')} "
                                 "columns must both be present or both absent", file=path,
                                 field=f"{getattr(spec, a + '_column')}/{getattr(spec, b + '_column')}")
        if ci["alt"] is None:
            ci["height"] = None
        if ci["alt"] is not None:
            ci["phase"] = None
        if ci["range"] is None:
            ci["phase"] = None
    if ci["alt"] is not None and ci["range"] is None and ci["height"] is None:
        raise InputError("alt/az columns need a range or a height column", file=path,
                         field="range_m/height_m")
    if ci["sigma"] is None and spec.default_sigma_mag is None:
        raise InputError("no magnitude-sigma column; set default_sigma_mag in [recording]", file=path,
                         field=str(spec.sigma_column or "mag_sigma"))
    return ci, colname, spec


# ----------------------------------------------------------------------------------------
# step 3: fields → values
# ----------------------------------------------------------------------------------------
def _parse_time(text: str, fmt: str) -> datetime:
    if fmt == "iso":
        s = text.strip()
        if s.endswith(("Z", "z")):
            s = s[:-1] + "+00:00"
        dt = datetime.fromisoformat(s)
        return dt.replace(tzinfo=timezone.utc) if dt.tzinfo is None else dt.astimezone(timezone.utc)
    x = float(text)
    if not math.isfinite(x):
        raise ValueError("not finite")
    if fmt == "unix_s":
        return _UNIX0 + timedelta(seconds=x)
    if fmt == "jd_utc":
        x = x - _JD_MJD
    return _MJD0 + timedelta(days=x)


@dataclass
class _Rows:
    """Parsed rows (one entry per kept row, file order)."""

    times: list = field(default_factory=list)       # datetime (UTC), mid-exposure
    mag: list = field(default_factory=list)
    sigma: list = field(default_factory=list)
    site: list = field(default_factory=list)        # site id text
    obj: list = field(default_factory=list)         # object id text
    camera: list = field(default_factory=list)      # camera id text ('' = none)
    band: list = field(default_factory=list)        # band text ('' = none)
    exposure: list = field(default_factory=list)    # s, NaN = unknown
    alt: list = field(default_factory=list)
    az: list = field(default_factory=list)
    dist: list = field(default_factory=list)        # range or height, m
    phase: list = field(default_factory=list)       # deg
    line: list = field(default_factory=list)
    skipped_nan: int = 0
    skipped_below: int = 0
    below_keys: list = field(default_factory=list)  # (object, band) of each row skipped below


def _parse_rows(path, rows, header, ci, colname, spec: RecordingSpec, default_site) -> _Rows:
    """Values of every row (module docstring for the rules); InputError names line and column."""
    ncols = max(v for v in ci.values() if v is not None) + 1
    nexp = len(header[1]) if header else None
    out = _Rows()
    dkey = "range" if ci["range"] is not None else "height"
    dscale = _UNITS[spec.range_unit] if dkey == "range" else _UNITS[spec.height_unit]
    topo = ci["alt"] is not None
    for no, f in rows:
        if nexp is not None and len(f) != nexp:
            raise InputError(f"line {no}: expected {nexp} fields, got {len(f)}", file=path,
                             field=f"line {no}", value=f)
        if len(f) < ncols:
            raise InputError(f"line {no}: expected at least {ncols} fields, got {len(f)}", file=path,
                             field=f"line {no}", value=f)

        def bad(key, msg, allowed=None):
            return InputError(f"line {no}, column {colname[key]!r}: {msg}", file=path,
                              field=f"line {no}, column {colname[key]}", value=f[ci[key]],
                              allowed=allowed)

        def num(key):
            try:
                x = float(f[ci[key]])
            except ValueError:
                raise bad(key, "not a number") from None
            if not math.isfinite(x):
                raise bad(key, "not a finite number")
            return x

        def when(key):
            try:
                return _parse_time(f[ci[key]], spec.time_format)
            except (ValueError, OverflowError):
                raise bad(key, f"not a {spec.time_format} UTC time",
                          "e.g. 2022-01-25T13:28:39" if spec.time_format == "iso" else "a number") from None

        def text(key, fixed, default=""):
            if ci[key] is None:
                return fixed if fixed is not None else default
            v = f[ci[key]]
            if not v:
                raise bad(key, f"empty {key} id")
            return v

        ms = f[ci["mag"]]
        if ms == "" or ms.lower() == "nan":
            out.skipped_nan += 1
            continue
        try:
            m = float(ms)
        except ValueError:
            raise bad("mag", "not a number") from None
        if not math.isfinite(m) or not (MAG_RANGE[0] < m < MAG_RANGE[1]):
            raise bad("mag", "magnitude out of range",
                      f"({MAG_RANGE[0]:g}, {MAG_RANGE[1]:g}), or empty/nan to skip the row")
        expo = float("nan")
        if ci["exposure_start"] is not None:
            t0, t1 = when("exposure_start"), when("exposure_end")
            if t1 < t0:
                raise bad("exposure_end", "exposure ends before it starts", "end >= start")
            expo = (t1 - t0).total_seconds()
            dt = t0 + (t1 - t0) / 2
            if ci["time"] is not None:
                stamp = when("time")
                if not (t0 - timedelta(milliseconds=1) <= stamp <= t1 + timedelta(milliseconds=1)):
                    raise bad("time", "time stamp outside its exposure", "exposure_start <= t <= exposure_end")
        else:
            dt = when("time")
            if ci["exposure"] is not None:
                expo = num("exposure")
                if not 0.0 <= expo <= 3600.0:
                    raise bad("exposure", "exposure time out of range", "[0, 3600] s")
                if spec.time_stamp == "start":
                    dt = dt + timedelta(seconds=expo / 2)
                elif spec.time_stamp == "end":
                    dt = dt - timedelta(seconds=expo / 2)
        if ci["sigma"] is not None:
            s = num("sigma")
            if s <= 0:
                raise bad("sigma", "sigma must be positive", "> 0")
        else:
            s = spec.default_sigma_mag
        site = text("site", spec.site if spec.site is not None else default_site)
        if not site:
            raise InputError("no site column; set site = \"<id>\" in [recording]", file=path,
                             field=str(spec.site_column or "site"))
        obj = text("object", spec.object, "object")
        cam = text("camera", None, "")
        band = text("band", spec.band, "")
        if topo:
            a, z = num("alt"), num("az")
            if not -90.0 <= a <= 90.0:
                raise bad("alt", "altitude out of range", "[-90, 90] deg")
            d = num(dkey) * dscale
            if dkey == "range" and d < 0:
                raise bad(dkey, "negative range", ">= 0")
            if dkey == "height" and a < 0:
                raise bad("alt", "altitude below the horizon: no line of sight reaches a height",
                          "[0, 90] deg with a height column")
            if a < 0:  # below the geometric horizon: not observable; skipped and counted
                out.skipped_below += 1
                out.below_keys.append((obj, band))
                continue
            out.alt.append(a)
            out.az.append(z)
            out.dist.append(d)
        elif ci["range"] is not None:
            d = num("range") * dscale
            if d <= 0:
                raise bad("range", "range must be positive", "> 0")
            out.dist.append(d)
            if ci["phase"] is not None:
                ph = num("phase")
                if not 0.0 <= ph <= 180.0:
                    raise bad("phase", "phase angle out of range", "[0, 180] deg")
                out.phase.append(ph)
        out.times.append(dt)
        out.mag.append(m)
        out.sigma.append(s)
        out.site.append(site)
        out.obj.append(obj)
        out.camera.append(cam)
        out.band.append(band)
        out.exposure.append(expo)
        out.line.append(no)
    return out


# ----------------------------------------------------------------------------------------
# steps per group
# ----------------------------------------------------------------------------------------
def _resolve_sites(path, ids, lines, colname, scenario, site_dirs):
    """Site objects for the ids (scenario [[sites]] first, then the folders and catalogue)."""
    from ..geometry.sites import get_site

    known = {s.site.id: s.site for s in getattr(scenario, "sites", [])} if scenario is not None else {}
    out = []
    for sid in ids:
        if sid in known:
            out.append(known[sid])
            continue
        try:
            out.append(get_site(sid, dirs=site_dirs))
        except InputError as exc:
            k = lines[sid]
            where = f"line {k}, column {colname['site']!r}: " if colname.get("site") else ""
            allowed = exc.allowed
            if known:
                allowed = f"the scenario's sites {', '.join(sorted(known))}; " + (allowed or "")
            raise InputError(f"{where}{exc.bare_message}", file=path,
                             field=f"line {k}, column {colname['site']}" if colname.get("site")
                             else "recording.site", value=sid, allowed=allowed) from None
    return out


def _time_col(colname):
    return colname.get("time") or colname.get("exposure_start")


def _sort_and_dedupe(path, g: dict, colname, topo):
    """Stable time order; exact copies dropped; conflicting copies refused. Returns
    ``(order, n_out_of_order, was_sorted, n_duplicates)``."""
    ts = np.array([d.timestamp() for d in g["times"]])
    n = ts.size
    order = np.argsort(ts, kind="stable")
    n_out = int(np.sum(ts[1:] < np.maximum.accumulate(ts)[:-1])) if n > 1 else 0
    was_sorted = bool(np.all(order == np.arange(n)))
    skipped = 0
    if n > 1:
        sidx, cam = g["site_index"], g["camera_index"]
        by = np.lexsort((cam, sidx, ts))
        rep = (np.diff(ts[by]) == 0) & (np.diff(sidx[by]) == 0) & (np.diff(cam[by]) == 0)
        if np.any(rep):
            cols = [g["mag"], g["sigma"], g["exposure"]] + ([g["alt"], g["az"], g["dist"]] if topo else [])
            vals = np.column_stack(cols)
            drop = np.zeros(n, bool)
            for j in np.flatnonzero(rep):
                a_, b_ = int(by[j]), int(by[j + 1])
                if np.array_equal(vals[a_], vals[b_], equal_nan=True):
                    drop[b_] = True
                else:
                    raise InputError(f"lines {g['line'][a_]} and {g['line'][b_]}: two different "
                                     "measurements of one object at the same time from the same "
                                     "camera of the same site", file=path,
                                     field=f"line {g['line'][b_]}, column {_time_col(colname)}",
                                     value=str(g["times"][b_]),
                                     allowed="one measurement per (time, object, site, camera); "
                                     "identical copies are skipped")
            skipped = int(drop.sum())
            order = order[~drop[order]]
    return order, n_out, was_sorted, skipped


def _check_time_range(path, times, lines, colname):
    from ..geometry.time import DE421_END_UTC, DE421_START_UTC

    for d, no in zip(times, lines):
        if not DE421_START_UTC <= d <= DE421_END_UTC:
            raise InputError(f"line {no}: time outside the DE421 ephemeris range", file=path,
                             field=f"line {no}, column {_time_col(colname)}", value=str(d),
                             allowed="1899-07-30 to 2053-10-08 UTC")


def _topocentric_positions(path, epoch, t, g, sites, colname, height):
    from ..geometry.eclipse import R_EARTH_SHADOW_M
    from ..geometry.orbits import positions_from_topocentric
    from ..geometry.time import skyfield_times

    n = t.size
    r_obj = np.empty((n, 3))
    sidx, dist, lines = g["site_index"], g["dist"], g["line"]
    key = "height" if height else "range"
    for k, site in enumerate(sites):
        m_k = sidx == k
        if not np.any(m_k):
            continue
        if height:
            low = m_k & (dist <= site.height_m)
            if np.any(low):
                j = int(np.argmax(low))
                raise InputError(f"line {lines[j]}, column {colname['height']!r}: height not above "
                                 f"the site ({site.height_m:.0f} m)", file=path,
                                 field=f"line {lines[j]}, column {colname['height']}",
                                 value=float(dist[j]), allowed=f"> {site.height_m} m")
        tk = skyfield_times(epoch, t[m_k])
        try:
            r_obj[m_k] = positions_from_topocentric(
                site, tk, g["alt"][m_k], g["az"][m_k],
                range_m=None if height else dist[m_k], height_m=dist[m_k] if height else None)
        except InputError as exc:
            raise InputError(exc.bare_message, file=path, field=exc.field, value=exc.value,
                             allowed=exc.allowed) from None
    inside = np.linalg.norm(r_obj, axis=1) <= R_EARTH_SHADOW_M
    if np.any(inside):
        j = int(np.argmax(inside))
        raise InputError(f"line {lines[j]}: the line of sight ends inside the Earth (range "
                         "too short for this altitude?)", file=path,
                         field=f"line {lines[j]}, column {colname[key]}", value=float(dist[j]),
                         allowed=f"a position above the Earth's equatorial radius "
                         f"({R_EARTH_SHADOW_M:.0f} m from its centre)")
    return r_obj


def _orbit_source(path, object_id, scenario, element_sets, times):
    """``(positions(epoch, t) -> (r, v), label, attrs)`` of the object's orbit, or None."""
    if element_sets:
        from ..geometry.tle import check_element_age, find_element_set

        es = find_element_set(element_sets, object_id, file=path)
        age = check_element_age(es, times, stacklevel=5)
        return es.positions, "elements", {
            "element_set": es.label, "element_set_source": es.source,
            "element_epoch_utc": es.epoch_utc.strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
            "element_age_days_max": age}
    orbit = getattr(scenario, "orbit", None) if scenario is not None else None
    if orbit is None:
        return None
    return orbit.positions, "orbit", {}


def _orbit_positions(positions, epoch, t):
    tu, inv = np.unique(t, return_inverse=True)
    r_u, v_u = positions(epoch, tu)
    return r_u[inv], v_u[inv]


def _range_phase_positions(path, epoch, t, g, sites, r_orbit, colname, spec):
    """The recorded range placed along the orbit's line of sight; the recorded phase angle
    checked against the recomputed one. Returns ``(r_obj, attrs)``."""
    from ..geometry.sites import site_position_gcrs

    n = t.size
    r_site = np.empty((n, 3))
    for k, site in enumerate(sites):
        m_k = g["site_index"] == k
        if np.any(m_k):
            r_site[m_k] = site_position_gcrs(site, epoch, t[m_k])
    los = r_orbit - r_site
    rng_orbit = np.linalg.norm(los, axis=1)
    r_obj = r_site + los / rng_orbit[:, None] * g["dist"][:, None]
    attrs = {"max_range_residual_m": float(np.max(np.abs(rng_orbit - g["dist"])))}
    if g["phase"] is not None:
        from ..geometry.time import sun_position_gcrs

        r_sun = sun_position_gcrs(epoch, t)
        a = r_sun - r_obj
        b = r_site - r_obj
        c = np.sum(a * b, axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        ph = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
        res = np.abs(ph - g["phase"])
        attrs["max_phase_residual_deg"] = float(res.max())
        if np.any(res > spec.phase_tolerance_deg):
            j = int(np.argmax(res))
            raise InputError(f"line {g['line'][j]}, column {colname['phase']!r}: the recorded phase "
                             f"angle differs by {res[j]:.2f} deg from the one of the object's orbit "
                             "(wrong element set, object or time?)", file=path,
                             field=f"line {g['line'][j]}, column {colname['phase']}",
                             value=float(g["phase"][j]),
                             allowed=f"within {spec.phase_tolerance_deg:g} deg of {ph[j]:.2f} deg "
                             "(phase_tolerance_deg)")
    return r_obj, attrs


def _screen(path, lc: Lightcurve, skipped_below, unlit) -> Lightcurve:
    """Drop rows below the horizon and (by default) in the Earth's full shadow; count them."""
    below = ~(lc.elevation_rad >= 0.0)
    dark = ~(lc.lit_fraction > 0.0) & ~below
    drop = below | dark if unlit == "skip" else below
    lc.attrs["skipped_below_horizon"] = int(below.sum()) + skipped_below
    lc.attrs["unlit_policy"] = unlit
    lc.attrs["skipped_unlit"] = int(dark.sum()) if unlit == "skip" else 0
    lc.attrs["n_unlit"] = 0 if unlit == "skip" else int(dark.sum())
    if np.all(drop):
        why = "below the horizon" if np.all(below) else "below the horizon or in the Earth's shadow"
        raise InputError(f"no usable row: the object is {why} in all {drop.size}",
                         file=path, field="alt_deg / time",
                         allowed="altitude >= 0 deg" + (" and a sunlit object (or unlit='keep')"
                                                        if np.any(dark) else ""))
    if np.any(drop):
        lc = lc.subset(~drop)
    if unlit == "keep" and np.any(dark):
        from ..geometry.visibility import UnlitPassWarning

        warnings.warn(f"{path}: the object is in the Earth's shadow at {int(dark.sum())} of "
                      f"{dark.size} measurement epochs (kept; counted in attrs['n_unlit'])",
                      UnlitPassWarning, stacklevel=4)
    return lc


def _group_lightcurve(path, rows: _Rows, idx, *, ci, colname, spec, scenario, site_dirs,
                      element_sets, epoch, unlit, n_rows, shape) -> Lightcurve:
    """One (object, band) group of rows → a screened :class:`Lightcurve`."""
    from ..geometry.observation import compute_geometry

    lines = [rows.line[k] for k in idx]
    site_ids = [rows.site[k] for k in idx]
    ids = list(dict.fromkeys(site_ids))
    first_line = {sid: lines[site_ids.index(sid)] for sid in ids}
    sites = _resolve_sites(path, ids, first_line, colname, scenario, site_dirs)
    pos = {sid: i for i, sid in enumerate(ids)}
    cams = [rows.camera[k] for k in idx]
    has_cam = any(cams)
    cam_keys = [f"{s}/{c}" if c else s for s, c in zip(site_ids, cams)]
    cam_names = list(dict.fromkeys(cam_keys))
    cpos = {c: i for i, c in enumerate(cam_names)}
    topo = ci["alt"] is not None
    g = {"times": [rows.times[k] for k in idx], "line": np.asarray(lines),
         "mag": np.asarray([rows.mag[k] for k in idx], float),
         "sigma": np.asarray([rows.sigma[k] for k in idx], float),
         "exposure": np.asarray([rows.exposure[k] for k in idx], float),
         "site_index": np.asarray([pos[s] for s in site_ids], np.int64),
         "camera_index": np.asarray([cpos[c] for c in cam_keys], np.int64)}
    if rows.dist:
        g["dist"] = np.asarray([rows.dist[k] for k in idx], float)
    if topo:
        g["alt"] = np.asarray([rows.alt[k] for k in idx], float)
        g["az"] = np.asarray([rows.az[k] for k in idx], float)
    g["phase"] = np.asarray([rows.phase[k] for k in idx], float) if rows.phase else None
    order, n_out, was_sorted, n_dup = _sort_and_dedupe(path, g, colname, topo)
    for k in list(g):
        if isinstance(g[k], np.ndarray):
            g[k] = g[k][order]
    g["times"] = [g["times"][k] for k in order]
    _check_time_range(path, g["times"], g["line"], colname)

    from ..geometry.time import parse_epoch

    try:
        ep = parse_epoch(epoch)
    except InputError as exc:
        raise InputError(exc.bare_message, file=path, field="epoch_utc", value=epoch) from None
    t = np.array([(d - ep).total_seconds() for d in g["times"]])
    obj, band = rows.obj[idx[0]], rows.band[idx[0]]
    extra = {}
    v_obj = None
    if topo:
        r_obj = _topocentric_positions(path, epoch, t, g, sites, colname, ci["height"] is not None)
        source = "topocentric"
    else:
        src = _orbit_source(path, obj, scenario, element_sets, g["times"])
        if src is None:
            what = "a range + phase-angle" if ci["range"] is not None else "no topocentric (alt/az)"
            raise InputError(f"{what} recording needs the object's orbit for the line of sight: "
                             "give its element set (TLE/OMM file) or a model scenario with an "
                             "[orbit]", file=path, field="object", value=obj)
        positions, source, extra = src
        r_orbit, v_obj = _orbit_positions(positions, epoch, t)
        if ci["range"] is not None:
            r_obj, more = _range_phase_positions(path, epoch, t, g, sites, r_orbit, colname, spec)
            extra.update(more)
            source = f"range_phase+{source}"
        else:
            r_obj = r_orbit
    geo = compute_geometry(epoch, t, g["site_index"], sites, r_obj, v_obj)
    lla = np.array([[s.lat_deg, s.lon_deg, s.height_m] for s in sites])
    attrs = {"source": "recording", "file": str(path), "n_rows": n_rows, "object_id": obj,
             "n_rows_object": len(idx), "skipped_nan_mag": int(rows.skipped_nan),
             "sorted_by_time": int(not was_sorted), "n_out_of_order": n_out,
             "geometry_source": source, "time_format": spec.time_format,
             "skipped_duplicate": n_dup}
    attrs.update(extra)
    if band:
        from ..photometry.bands import sun_magnitude

        attrs["band"] = band
        attrs["sun_mag"] = sun_magnitude(band, file=path, field=f"column {colname.get('band') or 'band'}")
    elif spec.sun_mag is not None:
        attrs["band"] = "custom"
        attrs["sun_mag"] = float(spec.sun_mag)
    elif scenario is not None:
        attrs["sun_mag"] = float(scenario.measurement.sun_mag)
        attrs["ignore_eclipse"] = int(scenario.measurement.ignore_eclipse)
    if shape is not None or (scenario is not None and getattr(scenario, "shape", None) is not None):
        attrs["shape"] = getattr(shape if shape is not None else scenario.shape, "name", "")
    expo = g["exposure"] if np.any(np.isfinite(g["exposure"])) else None
    try:
        lc = Lightcurve(
            epoch_utc=str(epoch), t=t, mag=g["mag"], mag_sigma=g["sigma"], site=g["site_index"],
            site_names=[s.id for s in sites], site_lla_deg_m=lla,
            r_obj_eci_m=geo.r_obj_eci_m, r_site_eci_m=geo.r_site_eci_m, r_sun_eci_m=geo.r_sun_eci_m,
            lit_fraction=geo.lit_fraction, elevation_rad=geo.elevation_rad,
            scenario_toml=getattr(scenario, "text", "") if scenario is not None else "",
            attrs=attrs, exposure_s=expo,
            camera=g["camera_index"] if has_cam else None,
            camera_names=cam_names if has_cam else None,
            shape=shape if shape is not None else getattr(scenario, "shape", None),
        )
    except InputError as exc:  # name the CSV file
        raise InputError(exc.bare_message, file=path, field=exc.field, value=exc.value,
                         allowed=exc.allowed) from None
    return _screen(path, lc, rows.below_keys.count((obj, band)), unlit)


# ----------------------------------------------------------------------------------------
# public readers
# ----------------------------------------------------------------------------------------
def _split_model(model):
    """(scenario or None, spec source) from read_recording's second argument."""
    if model is not None and hasattr(model, "attitude") and hasattr(model, "measurement"):
        return model, getattr(model, "recording", None)
    return None, model


def read_recordings(csv_path, scenario_or_recording_section=None, *, site_dirs=None,
                    unlit=None, element_sets=None, scenarios=None, shape=None,
                    objects=None, recording=None) -> dict:
    """Read a CSV recording into one :class:`Lightcurve` (no truth) per (object, band).

    Parameters
    ----------
    csv_path : path-like
        The CSV file.
    scenario_or_recording_section : Scenario, RecordingSpec, Section, dict or None
        The model scenario (its ``recording`` spec, its epoch, its ``[[sites]]``, its orbit
        for geometry when the file has no topocentric columns and no element set is given,
        its shape), or only a ``[recording]`` column mapping, or None for the default layout.
    site_dirs : optional
        Extra observatory catalog folders.
    unlit : {"skip", "keep"} or None
        Rows with the object in the Earth's full shadow (module docstring). None: "keep"
        for a scenario with ``measurement.ignore_eclipse = true``, else "skip".
    element_sets : list of :class:`~lightcurve.geometry.tle.ElementSet`, optional
        TLE/OMM element sets; an object's set (by NORAD number or name) gives its orbit.
    scenarios : mapping object id -> Scenario, optional
        Per-object model scenarios (their epoch must match the default's when both exist);
        objects not listed use ``scenario_or_recording_section``.
    shape : Shape, optional
        The shape stored in every output (instead of the scenario's).
    objects : iterable of str, optional
        Only these object ids.
    recording : RecordingSpec, Section or dict, optional
        A column mapping replacing the scenario's ``[recording]``.

    Returns
    -------
    dict
        ``(object_id, band) -> Lightcurve`` in order of first appearance (band ``""`` when the
        recording gives none). Each has ``t`` in s since ``epoch_utc`` (the spec's, else the
        scenario's, else the first time in the file), sorted; GCRS geometry (m);
        ``elevation_rad``, ``lit_fraction``; ``camera``/``camera_names`` and ``exposure_s``
        when given; the model scenario's text and shape; ``attrs`` as in the module docstring
        (``source = "recording"``, ``file``, ``object_id``, ``geometry_source``, ``band``,
        ``sun_mag``, counts).

    Raises
    ------
    InputError
        Naming the file, line and column of every bad value (see the module docstring).
    """
    path = Path(csv_path)
    if unlit not in (None, "skip", "keep"):
        raise InputError("unknown policy for rows in the Earth's shadow", file=path, field="unlit",
                         value=unlit, allowed="skip, keep")
    scenario, spec = _split_model(scenario_or_recording_section)
    scenarios = dict(scenarios or {})
    if recording is None and spec is None:  # the per-object scenarios' common [recording]
        specs = [sc.recording for sc in scenarios.values() if getattr(sc, "recording", None)]
        if any(x != specs[0] for x in specs[1:]):
            raise InputError("the per-object scenarios map the columns differently; give one "
                             "[recording] mapping (lightcurve import --columns MAP.toml)",
                             file=path, field="recording")
        spec = specs[0] if specs else None
    spec = _as_spec(recording if recording is not None else spec)
    header, raw = _read_rows(path, spec)
    ci, colname, spec = _resolve_columns(path, header, spec)
    default_site = None
    if ci["site"] is None and spec.site is None and scenario is not None and len(scenario.sites) == 1:
        default_site = scenario.sites[0].site.id
    rows = _parse_rows(path, raw, header, ci, colname, spec, default_site)
    if not rows.times:
        raise InputError(f"no measurement rows ({rows.skipped_nan} skipped for a missing magnitude, "
                         f"{rows.skipped_below} below the horizon)", file=path)
    groups: dict = {}
    for k, key in enumerate(zip(rows.obj, rows.band)):
        groups.setdefault(key, []).append(k)
    if objects is not None:
        want = {str(o) for o in objects}
        missing = want - set(rows.obj)
        if missing:
            raise InputError("object not in the recording", file=path, field="object",
                             value=min(missing), allowed=", ".join(dict.fromkeys(rows.obj)))
        groups = {k: v for k, v in groups.items() if k[0] in want}
    base_epoch = spec.epoch_utc or (scenario.epoch_utc if scenario is not None else None)
    if base_epoch is None:
        for sc in scenarios.values():
            base_epoch = sc.epoch_utc
            break
    if base_epoch is None:
        base_epoch = min(rows.times).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    out = {}
    for (obj, band), idx in groups.items():
        sc = scenarios.get(obj, scenario)
        epoch = spec.epoch_utc or (sc.epoch_utc if sc is not None else base_epoch)
        pol = unlit
        if pol is None:
            pol = "keep" if bool(getattr(getattr(sc, "measurement", None), "ignore_eclipse", False)) \
                else "skip"
        lc = _group_lightcurve(path, rows, np.asarray(idx), ci=ci, colname=colname, spec=spec,
                               scenario=sc, site_dirs=site_dirs, element_sets=element_sets,
                               epoch=epoch, unlit=pol, n_rows=len(raw), shape=shape)
        out[(obj, band)] = lc
    return out


def read_recording(csv_path, scenario_or_recording_section=None, *, site_dirs=None,
                   unlit=None, element_sets=None, shape=None) -> Lightcurve:
    """Read a CSV recording of ONE object in one band into a :class:`Lightcurve` (no truth).

    Arguments as :func:`read_recordings`. A recording with several objects or bands raises an
    :class:`InputError` naming them (read it with :func:`read_recordings` or
    ``lightcurve import``, which writes one file per object and band).
    """
    out = read_recordings(csv_path, scenario_or_recording_section, site_dirs=site_dirs,
                          unlit=unlit, element_sets=element_sets, shape=shape)
    if len(out) > 1:
        names = ", ".join(f"{o}{' (' + b + ')' if b else ''}" for o, b in out)
        raise InputError(f"the recording holds {len(out)} objects/bands ({names}): import it with "
                         "'lightcurve import' (one file per object and band)", file=csv_path,
                         field="object/band")
    return next(iter(out.values()))
