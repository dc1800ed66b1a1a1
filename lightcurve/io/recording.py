"""Recording import: real apparent-magnitude measurements from CSV files.

The default layout (docs/formats.md, "Recordings (CSV)") is a header line and the columns
``utc, mag[, mag_sigma], site[, alt_deg, az_deg, range_m | height_m]``. Other layouts are read
as shipped through a scenario's ``[recording]`` table (:class:`RecordingSpec`), which names or
numbers the columns, sets a fixed site or a default sigma, the units of range/height, the
comment character, the delimiter and the time format.

Geometry (object GCRS position) comes from the topocentric columns (alt/az + range or height,
via :func:`lightcurve.geometry.orbits.positions_from_topocentric`) or, when those columns are
absent, from the scenario's ``[orbit]`` (Kepler/TLE). Site and Sun positions, elevations and
lit fractions come from :func:`lightcurve.geometry.observation.compute_geometry`. The result
is a :class:`~lightcurve.io.lightcurve_h5.Lightcurve` without truth.

Row handling (documented, counted in ``Lightcurve.attrs``):

* blank lines and text after the comment character are ignored;
* an empty or ``nan`` magnitude skips the row (``attrs["skipped_nan_mag"]``);
* rows not in time order are sorted (stable); ``attrs["sorted_by_time"] = 1`` and
  ``attrs["n_out_of_order"]`` say so;
* an exact copy of a row (same time, site and values) is skipped
  (``attrs["skipped_duplicate"]``); two different values at the same time and site are an
  error naming both lines;
* rows with the object below the site's geometric horizon are skipped
  (``attrs["skipped_below_horizon"]``);
* rows with the object in the Earth's full shadow (lit fraction 0: it reflects no sunlight,
  so the model cannot have produced the measurement) are skipped by default and counted
  (``attrs["skipped_unlit"]``). ``unlit="keep"`` keeps them — counted in ``attrs["n_unlit"]``
  and announced with an ``UnlitPassWarning`` — for diagnosing shadow effects (an object
  measured where the model puts it in the umbra points at a mis-modelled shadow or clock) and
  for scenarios with ``measurement.ignore_eclipse = true`` (Bernard's published cases model
  umbral passes as if sunlit; that is the default when such a scenario is given). Partly lit
  rows (penumbra, 0 < lit fraction < 1) are always kept. The attitude filters skip, flag and
  count any unlit row that reaches them (:mod:`lightcurve.filters.gating`);
* every other bad value (wrong number of fields, unparsable time or number, altitude out of
  [-90, 90] / below 0 with a height, azimuth not finite, negative sigma/range, a height below
  the site, an unknown site) raises :class:`~lightcurve.errors.InputError` naming the file, the
  line number and the column.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from ..errors import InputError
from .lightcurve_h5 import Lightcurve
from .tomlio import Section

__all__ = ["RecordingSpec", "recording_spec_from_section", "read_recording", "TIME_FORMATS"]

#: Accepted ``time_format`` values: ISO 8601 UTC text, Unix seconds (UTC), MJD and JD (UTC).
TIME_FORMATS = ("iso", "unix_s", "mjd_utc", "jd_utc")
_UNITS = {"m": 1.0, "km": 1000.0}
_UNIX0 = datetime(1970, 1, 1, tzinfo=timezone.utc)
_MJD0 = datetime(1858, 11, 17, tzinfo=timezone.utc)
_JD_MJD = 2400000.5


@dataclass
class RecordingSpec:
    """How to read one CSV layout (the scenario's ``[recording]`` table).

    Column references are header names (str) or 0-based indices (int); ``None`` = absent.

    Attributes
    ----------
    time_column, mag_column : str | int
        Measurement time (format ``time_format``) and apparent magnitude.
    sigma_column : str | int | None
        1σ magnitude noise; when absent ``default_sigma_mag`` is used.
    default_sigma_mag : float | None
        σ (mag) for every row when there is no sigma column (> 0).
    site_column : str | int | None
        Site id per row (observatories/ catalog); or ``site`` fixes one site for all rows.
    site : str | None
        Fixed site id.
    alt_column, az_column : str | int | None
        Geometric topocentric altitude and azimuth (north through east), degrees.
    range_column / height_column : str | int | None
        Slant range site→object, or object height above the WGS84 ellipsoid; with
        ``range_unit`` / ``height_unit`` ("m" or "km"). At most one of the two.
    comment : str
        Comment character (text after it on a line is ignored); "" for none.
    delimiter : str
        Field separator (one character).
    header : bool
        Whether the first non-comment line holds column names (needed for named columns).
    time_format : str
        One of :data:`TIME_FORMATS`.
    epoch_utc : str | None
        Epoch that ``t`` counts from; default the scenario's epoch, else the first time.
    """

    time_column: object = "utc"
    mag_column: object = "mag"
    sigma_column: object = "mag_sigma"
    default_sigma_mag: float | None = None
    site_column: object = "site"
    site: str | None = None
    alt_column: object = "alt_deg"
    az_column: object = "az_deg"
    range_column: object = "range_m"
    height_column: object = "height_m"
    range_unit: str = "m"
    height_unit: str = "m"
    comment: str = "#"
    delimiter: str = ","
    header: bool = True
    time_format: str = "iso"
    epoch_utc: str | None = None
    #: True for the built-in default layout: optional columns may be missing from the file.
    defaults: bool = True


_COLUMN_KEYS = ("time_column", "mag_column", "sigma_column", "site_column", "alt_column",
                "az_column", "range_column", "height_column")


def recording_spec_from_section(sec) -> RecordingSpec:
    """Validate a ``[recording]`` table (a :class:`Section` or dict) into a :class:`RecordingSpec`.

    Keys: ``time_column`` (default "utc"), ``mag_column`` ("mag"), ``sigma_column`` or
    ``default_sigma_mag``, ``site_column`` or ``site``, ``alt_column``, ``az_column``,
    ``range_column`` or ``height_column`` (columns absent unless given), ``range_unit`` /
    ``height_unit`` ("m" | "km"), ``comment`` ("#"), ``delimiter`` (","), ``header`` (true),
    ``time_format`` ("iso" | "unix_s" | "mjd_utc" | "jd_utc"), ``epoch_utc``.
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
                             field=sec._field(key), value=v)
        return v.strip() if isinstance(v, str) else v

    spec = RecordingSpec(
        time_column=col("time_column", "utc"),
        mag_column=col("mag_column", "mag"),
        sigma_column=col("sigma_column", None),
        default_sigma_mag=sec.float("default_sigma_mag", None, min=0.0, min_open=True, max=10.0),
        site_column=col("site_column", None),
        site=sec.str("site", None),
        alt_column=col("alt_column", None),
        az_column=col("az_column", None),
        range_column=col("range_column", None),
        height_column=col("height_column", None),
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
        return InputError(msg, file=sec.file, field=sec._field(key), value=value, allowed=allowed)

    if spec.time_column is None or spec.mag_column is None:
        raise err("time_column", "time_column and mag_column are required")
    if spec.sigma_column is not None and spec.default_sigma_mag is not None:
        raise err("default_sigma_mag", "give sigma_column or default_sigma_mag, not both")
    if spec.site_column is not None and spec.site is not None:
        raise err("site", "give site_column or a fixed site, not both")
    if spec.range_column is not None and spec.height_column is not None:
        raise err("height_column", "give range_column or height_column, not both")
    if (spec.alt_column is None) != (spec.az_column is None):
        raise err("alt_column", "give both alt_column and az_column, or neither")
    if (spec.range_column is not None or spec.height_column is not None) and spec.alt_column is None:
        raise err("alt_column", "range/height columns need alt_column and az_column")
    if len(spec.delimiter) != 1 or spec.delimiter in "\r\n\"":
        raise err("delimiter", "expected one character (not a quote or newline)", spec.delimiter)
    if len(spec.comment) > 1 or (spec.comment and spec.comment == spec.delimiter):
        raise err("comment", "expected one character (or \"\" for none), different from the delimiter",
                  spec.comment)
    if not spec.header:
        named = [k for k in _COLUMN_KEYS if isinstance(getattr(spec, k), str)]
        if named:
            raise err(named[0], "header = false: columns must be 0-based indices", getattr(spec, named[0]))
    if spec.epoch_utc is not None:
        from ..geometry.time import parse_epoch

        try:
            parse_epoch(spec.epoch_utc)
        except InputError as exc:
            raise err("epoch_utc", exc.bare_message, spec.epoch_utc, exc.allowed) from None
    return spec


# ----------------------------------------------------------------------------------------
def _read_rows(path: Path, spec: RecordingSpec):
    """(header or None, list of (line_no, fields)) with comments and blank lines removed."""
    from .safe_open import CSV_MAX_BYTES, read_text

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
    if spec.header and header is None:
        raise InputError("no header line (and no data)", file=path)
    return header, rows


def _resolve(path, header, spec: RecordingSpec, key: str, required: bool):
    """Column index of ``spec.<key>`` (None if absent and optional)."""
    ref = getattr(spec, key)
    if ref is None:
        return None
    if isinstance(ref, int):
        return ref
    names = header[1] if header else []
    if ref in names:
        return names.index(ref)
    if required or not spec.defaults:
        raise InputError(f"column {ref!r} not found in the header (line {header[0] if header else '?'})",
                         file=path, field=f"recording.{key}", value=ref,
                         allowed=", ".join(names) or "(no header)")
    return None


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


def read_recording(csv_path, scenario_or_recording_section=None, *, site_dirs=None,
                   unlit=None) -> Lightcurve:
    """Read a CSV recording into a :class:`Lightcurve` (no truth).

    Parameters
    ----------
    csv_path : path-like
        The CSV file.
    scenario_or_recording_section : Scenario, RecordingSpec, Section, dict or None
        A :class:`~lightcurve.studies.scenario.Scenario` (its ``recording`` spec, its epoch, its
        orbit for geometry when the file has no topocentric columns, and its site when the
        file names none), a ``[recording]`` table, a :class:`RecordingSpec`, or None for the
        default layout (docs/formats.md).
    site_dirs : optional
        Extra observatory catalog folders.
    unlit : {"skip", "keep"} or None
        Rows with the object in the Earth's full shadow (module docstring): skipped and counted
        in ``attrs["skipped_unlit"]``, or kept, counted in ``attrs["n_unlit"]`` and warned.
        None: "keep" for a scenario with ``measurement.ignore_eclipse = true``, else "skip".

    Returns
    -------
    Lightcurve
        ``t`` in s since ``epoch_utc`` (the spec's, else the scenario's, else the first time),
        sorted; ``mag``, ``mag_sigma``; GCRS geometry (m); ``elevation_rad`` and
        ``lit_fraction``; ``attrs`` with ``source = "recording"``, ``file``, ``n_rows``,
        ``skipped_nan_mag``, ``sorted_by_time``, ``n_out_of_order``, ``geometry_source``
        (``"topocentric"`` or ``"orbit"``), ``skipped_below_horizon``, ``unlit_policy``,
        ``skipped_unlit`` and ``n_unlit`` (unlit rows kept).

    Raises
    ------
    InputError
        Naming the file, line and column of every bad value (see the module docstring).
    """
    from ..geometry.sites import get_site

    path = Path(csv_path)
    if unlit not in (None, "skip", "keep"):
        raise InputError("unknown policy for rows in the Earth's shadow", file=path, field="unlit",
                         value=unlit, allowed="skip, keep")
    scenario = None
    spec = scenario_or_recording_section
    if spec is not None and hasattr(spec, "attitude") and hasattr(spec, "measurement"):
        scenario = spec
        spec = getattr(scenario, "recording", None)
    if spec is None:
        spec = RecordingSpec()
    elif isinstance(spec, (dict, Section)):
        spec = recording_spec_from_section(spec)
    elif not isinstance(spec, RecordingSpec):
        raise TypeError("read_recording: expected a Scenario, RecordingSpec, Section, dict or None")

    header, rows = _read_rows(path, spec)
    ci = {
        "time": _resolve(path, header, spec, "time_column", True),
        "mag": _resolve(path, header, spec, "mag_column", True),
        "sigma": _resolve(path, header, spec, "sigma_column", False),
        "site": _resolve(path, header, spec, "site_column", False),
        "alt": _resolve(path, header, spec, "alt_column", False),
        "az": _resolve(path, header, spec, "az_column", False),
        "range": _resolve(path, header, spec, "range_column", False),
        "height": _resolve(path, header, spec, "height_column", False),
    }
    if spec.defaults:
        # default layout: range_m and height_m are alternatives; alt/az go together
        if ci["range"] is not None and ci["height"] is not None:
            raise InputError("both range_m and height_m columns present; keep one", file=path,
                             field="range_m/height_m")
        if (ci["alt"] is None) != (ci["az"] is None):
            raise InputError("alt_deg and az_deg columns must both be present or both absent",
                             file=path, field="alt_deg/az_deg")
        if ci["alt"] is None:
            ci["range"] = ci["height"] = None
    colname = {k: (header[1][v] if header and v is not None and v < len(header[1]) else
                   (f"column {v}" if v is not None else None)) for k, v in ci.items()}
    if header is not None:
        for k, v in ci.items():
            if v is not None and v >= len(header[1]):
                raise InputError(f"column index {v} beyond the {len(header[1])} header columns",
                                 file=path, field=f"recording.{k}", value=v)
    topo = ci["alt"] is not None and (ci["range"] is not None or ci["height"] is not None)
    if ci["alt"] is not None and not topo:
        raise InputError("alt/az columns need a range or a height column", file=path,
                         field="range_m/height_m")
    if ci["sigma"] is None and spec.default_sigma_mag is None:
        raise InputError("no magnitude-sigma column; set default_sigma_mag in [recording]", file=path,
                         field=str(spec.sigma_column or "mag_sigma"))

    # fixed site / per-row site
    fixed_site = None
    if ci["site"] is None:
        sid = spec.site
        if sid is None and scenario is not None and len(scenario.sites) == 1:
            fixed_site = scenario.sites[0].site
        elif sid is None:
            raise InputError("no site column; set site = \"<id>\" in [recording]", file=path,
                             field=str(spec.site_column or "site"))
        else:
            try:
                fixed_site = get_site(sid, dirs=site_dirs)
            except InputError as exc:
                raise InputError(exc.bare_message, file=path, field="recording.site", value=sid,
                                 allowed=exc.allowed) from None

    ncols = max(v for v in ci.values() if v is not None) + 1
    nexp = len(header[1]) if header else None
    times, mags, sigmas, site_ids, alts, azs, dists, lines = [], [], [], [], [], [], [], []
    skipped_nan = 0
    skipped_below = 0
    dscale = _UNITS[spec.range_unit] if ci["range"] is not None else _UNITS[spec.height_unit]

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

        ms = f[ci["mag"]]
        if ms == "" or ms.lower() == "nan":
            skipped_nan += 1
            continue
        try:
            m = float(ms)
        except ValueError:
            raise bad("mag", "not a number") from None
        if not math.isfinite(m) or not (-30.0 < m < 40.0):
            raise bad("mag", "magnitude out of range", "(-30, 40), or empty/nan to skip the row")
        try:
            dt = _parse_time(f[ci["time"]], spec.time_format)
        except (ValueError, OverflowError):
            raise bad("time", f"not a {spec.time_format} UTC time",
                      "e.g. 2022-01-25T13:28:39" if spec.time_format == "iso" else "a number") from None
        if ci["sigma"] is not None:
            s = num("sigma")
            if s <= 0:
                raise bad("sigma", "sigma must be positive", "> 0")
        else:
            s = spec.default_sigma_mag
        if ci["site"] is not None:
            sid = f[ci["site"]]
            if not sid:
                raise bad("site", "empty site id")
            site_ids.append(sid)
        if topo:
            a = num("alt")
            z = num("az")
            if not -90.0 <= a <= 90.0:
                raise bad("alt", "altitude out of range", "[-90, 90] deg")
            key = "range" if ci["range"] is not None else "height"
            d = num(key) * dscale
            if key == "range" and d < 0:
                raise bad(key, "negative range", ">= 0")
            if key == "height" and a < 0:
                raise bad("alt", "altitude below the horizon: no line of sight reaches a height",
                          "[0, 90] deg with a height column")
            if a < 0:  # below the geometric horizon: not observable; skipped and counted
                skipped_below += 1
                if ci["site"] is not None:
                    site_ids.pop()
                continue
            alts.append(a)
            azs.append(z)
            dists.append(d)
        times.append(dt)
        mags.append(m)
        sigmas.append(s)
        lines.append(no)

    n = len(times)
    if n == 0:
        raise InputError(f"no measurement rows ({skipped_nan} skipped for a missing magnitude, "
                         f"{skipped_below} below the horizon)", file=path)

    # sites
    if fixed_site is not None:
        sites = [fixed_site]
        sidx = np.zeros(n, dtype=np.int64)
    else:
        ids = list(dict.fromkeys(site_ids))
        sites = []
        for sid in ids:
            try:
                sites.append(get_site(sid, dirs=site_dirs))
            except InputError as exc:
                k = site_ids.index(sid)
                raise InputError(f"line {lines[k]}, column {colname['site']!r}: {exc.bare_message}",
                                 file=path, field=f"line {lines[k]}, column {colname['site']}",
                                 value=sid, allowed=exc.allowed) from None
        pos = {sid: i for i, sid in enumerate(ids)}
        sidx = np.array([pos[s] for s in site_ids], dtype=np.int64)

    # sort by time (stable)
    ts = np.array([d.timestamp() for d in times])
    order = np.argsort(ts, kind="stable")
    # rows earlier than some row above them in the file
    n_out = int(np.sum(ts[1:] < np.maximum.accumulate(ts)[:-1])) if n > 1 else 0
    was_sorted = bool(np.all(order == np.arange(n)))
    # the same site twice at one instant: an identical copy is dropped (counted in
    # attrs["skipped_duplicate"]); two different values are an error naming both lines
    skipped_dup = 0
    if n > 1:
        by = np.lexsort((sidx, ts))
        rep = (np.diff(ts[by]) == 0) & (np.diff(sidx[by]) == 0)
        if np.any(rep):
            vals = np.column_stack([mags, sigmas] + ([alts, azs, dists] if topo else []))
            drop = np.zeros(n, bool)
            for j in np.flatnonzero(rep):  # consecutive pairs: a run of copies chains up
                a_, b_ = int(by[j]), int(by[j + 1])
                if np.array_equal(vals[a_], vals[b_]):
                    drop[b_] = True
                else:
                    raise InputError(f"lines {lines[a_]} and {lines[b_]}: two different measurements "
                                     "at the same time from the same site", file=path,
                                     field=f"line {lines[b_]}, column {colname['time']}",
                                     value=str(times[b_]),
                                     allowed="one measurement per (time, site); identical copies "
                                     "are skipped")
            skipped_dup = int(drop.sum())
            order = order[~drop[order]]
            n = order.size
    times = [times[k] for k in order]
    mag = np.asarray(mags, float)[order]
    sig = np.asarray(sigmas, float)[order]
    sidx = sidx[order]
    lines_s = np.asarray(lines)[order]

    from ..geometry.time import parse_epoch

    epoch = spec.epoch_utc or (scenario.epoch_utc if scenario is not None else None)
    if epoch is None:
        epoch = times[0].strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    try:
        ep = parse_epoch(epoch)
    except InputError as exc:
        raise InputError(exc.bare_message, file=path, field="epoch_utc", value=epoch) from None
    t = np.array([(d - ep).total_seconds() for d in times])
    # validate the time range against the ephemeris (names the first bad line)
    from ..geometry.time import DE421_END_UTC, DE421_START_UTC

    for k, d in enumerate(times):
        if not DE421_START_UTC <= d <= DE421_END_UTC:
            raise InputError(f"line {lines_s[k]}: time outside the DE421 ephemeris range", file=path,
                             field=f"line {lines_s[k]}, column {colname['time']}", value=str(d),
                             allowed="1899-07-30 to 2053-10-08 UTC")

    from ..geometry.observation import compute_geometry
    from ..geometry.orbits import positions_from_topocentric
    from ..geometry.time import skyfield_times

    if topo:
        alt = np.asarray(alts)[order]
        az = np.asarray(azs)[order]
        dist = np.asarray(dists)[order]
        r_obj = np.empty((n, 3))
        for k, site in enumerate(sites):
            m_k = sidx == k
            if ci["height"] is not None:
                low = m_k & (dist <= site.height_m)
                if np.any(low):
                    j = int(np.argmax(low))
                    raise InputError(f"line {lines_s[j]}, column {colname['height']!r}: height not above "
                                     f"the site ({site.height_m:.0f} m)", file=path,
                                     field=f"line {lines_s[j]}, column {colname['height']}",
                                     value=float(dist[j]), allowed=f"> {site.height_m} m")
            tk = skyfield_times(epoch, t[m_k])
            try:
                r_obj[m_k] = positions_from_topocentric(
                    site, tk, alt[m_k], az[m_k],
                    range_m=dist[m_k] if ci["range"] is not None else None,
                    height_m=dist[m_k] if ci["height"] is not None else None)
            except InputError as exc:
                raise InputError(exc.bare_message, file=path, field=exc.field, value=exc.value,
                                 allowed=exc.allowed) from None
        from ..geometry.eclipse import R_EARTH_SHADOW_M

        inside = np.linalg.norm(r_obj, axis=1) <= R_EARTH_SHADOW_M
        if np.any(inside):
            j = int(np.argmax(inside))
            key = "range" if ci["range"] is not None else "height"
            raise InputError(f"line {lines_s[j]}: the line of sight ends inside the Earth (range "
                             "too short for this altitude?)", file=path,
                             field=f"line {lines_s[j]}, column {colname[key]}", value=float(dist[j]),
                             allowed=f"a position above the Earth's equatorial radius "
                             f"({R_EARTH_SHADOW_M:.0f} m from its centre)")
        geometry_source = "topocentric"
    else:
        orbit = getattr(scenario, "orbit", None) if scenario is not None else None
        if orbit is None:
            raise InputError("no topocentric columns (alt/az + range or height) and no scenario "
                             "[orbit] to compute the object's position", file=path,
                             field="alt_deg/az_deg")
        tu, inv = np.unique(t, return_inverse=True)
        r_u, _ = orbit.positions(epoch, tu)
        r_obj = r_u[inv]
        geometry_source = "orbit"

    geo = compute_geometry(epoch, t, sidx, sites, r_obj)
    lla = np.array([[s.lat_deg, s.lon_deg, s.height_m] for s in sites])
    try:
        lc = Lightcurve(
            epoch_utc=str(epoch), t=t, mag=mag, mag_sigma=sig, site=sidx,
            site_names=[s.id for s in sites], site_lla_deg_m=lla,
            r_obj_eci_m=geo.r_obj_eci_m, r_site_eci_m=geo.r_site_eci_m, r_sun_eci_m=geo.r_sun_eci_m,
            lit_fraction=geo.lit_fraction, elevation_rad=geo.elevation_rad,
            scenario_toml=getattr(scenario, "text", "") if scenario is not None else "",
            attrs={"source": "recording", "file": str(path), "n_rows": len(rows),
                   "skipped_nan_mag": int(skipped_nan), "sorted_by_time": int(not was_sorted),
                   "n_out_of_order": n_out, "geometry_source": geometry_source,
                   "time_format": spec.time_format, "skipped_duplicate": skipped_dup},
        )
    except InputError as exc:  # name the CSV file
        raise InputError(exc.bare_message, file=path, field=exc.field, value=exc.value,
                         allowed=exc.allowed) from None
    # rows the model cannot have produced. Below the site's geometric horizon there is no line
    # of sight: skipped and counted. In the Earth's full shadow the object reflects no sunlight:
    # skipped and counted by default; kept on request (diagnosis, ignore_eclipse scenarios),
    # counted in attrs["n_unlit"] and announced with a warning -- never silently used.
    if unlit is None:
        ms = getattr(scenario, "measurement", None)
        unlit = "keep" if bool(getattr(ms, "ignore_eclipse", False)) else "skip"
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
        import warnings

        from ..geometry.visibility import UnlitPassWarning

        warnings.warn(f"{path}: the object is in the Earth's shadow at {int(dark.sum())} of "
                      f"{dark.size} measurement epochs (kept; counted in attrs['n_unlit'])",
                      UnlitPassWarning, stacklevel=2)
    return lc
