"""``lightcurve import`` (observatory CSV recordings → lightcurve files) and ``lightcurve passes``
(visible, sunlit passes of TLE/OMM objects over a site)."""

from __future__ import annotations

import functools
import sys
import warnings
from pathlib import Path

from ..errors import InputError
from ._args import add_command, add_model_options, add_output, add_quiet, number, report_written

__all__ = ["register", "output_paths", "find_passes"]


def _say_warnings(caught) -> None:
    for w in caught:
        print(f"WARNING: {w.message}", file=sys.stderr)


def _scenarios(args, shape):
    """(default scenario or None, {object id: scenario}) from the --scenario options."""
    from ..studies.scenario import load_scenario

    default, per = None, {}
    for item in args.scenario or []:
        oid, sep, path = item.partition("=")
        if not sep or not oid.strip():
            oid, path = None, item
        sc = load_scenario(path, library_dirs=args.library, site_dirs=args.sites, shape=shape)
        if oid is None:
            if default is not None:
                raise InputError("give one default --scenario (others as OBJECT=FILE.toml)",
                                 field="--scenario", value=item)
            default = sc
        else:
            per[oid.strip()] = sc
    return default, per


def output_paths(out, keys) -> dict:
    """Output file per ``(object, band)`` key (docs/formats.md "lightcurve import").

    One group and ``out`` not an existing folder: ``out`` itself. An existing folder:
    ``out/<object>[.<band>].h5``. Several groups: ``<out stem>.<object>[.<band>].h5`` beside
    ``out``. Names come from the data and pass :func:`lightcurve.io.paths.safe_output_path`.
    """
    from ..io.paths import safe_output_path

    out = Path(out)
    keys = list(keys)
    if len(keys) == 1 and not out.is_dir():
        return {keys[0]: out}
    bands = {b for _, b in keys}
    res = {}
    for obj, band in keys:
        name = obj + (f".{band}" if band and len(bands) > 1 else "")
        if out.is_dir():
            res[(obj, band)] = safe_output_path(out, name, ".h5", field="object")
        else:
            stem = out.name.removesuffix(".h5")
            res[(obj, band)] = safe_output_path(out.parent, f"{stem}.{name}", ".h5", field="object")
    if len(set(res.values())) != len(res):
        raise InputError("two objects give the same output file name", field="-o", value=str(out))
    return res


def _cmd_import(args) -> int:
    """Read a CSV recording (docs/formats.md 'Recordings (CSV)': UTC or JD times, magnitudes,
    sigma, band, exposure start/end or duration, object, camera, site; geometry from alt/az +
    range or height, from range + solar phase angle, or from the object's TLE/OMM element set or
    the model scenario's orbit) and write one lightcurve HDF5 per object and band, carrying the
    model scenario and its shape so that every later command works on it without further
    options.
    """
    from ..io.recording import read_recordings, recording_spec_from_section
    from ..io.tomlio import Section, load_toml

    src = Path(args.recording)
    shape = None
    if args.shape is not None:
        from ..photometry import load_shape

        shape = load_shape(args.shape, library_dirs=args.library)
    default, per = _scenarios(args, shape)
    spec = None
    if args.columns is not None:
        doc = load_toml(args.columns)
        table = doc.get("recording", doc)
        spec = recording_spec_from_section(Section(table, file=args.columns, name="recording"))
    elements = None
    if args.tle is not None:
        from ..geometry.tle import load_element_sets

        elements = load_element_sets(args.tle)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        groups = read_recordings(src, default, site_dirs=args.sites, unlit=args.unlit,
                                 element_sets=elements, scenarios=per, shape=shape,
                                 objects=args.object, recording=spec)
    _say_warnings(caught)
    paths = output_paths(args.output, groups)
    for p in paths.values():
        try:
            same = p.exists() and p.resolve() == src.resolve()
        except OSError:
            same = False
        if same:
            raise InputError("the output would overwrite the recording", field="-o", value=str(p))
    for key, lc in groups.items():
        p = lc.write(paths[key])
        obj, band = key
        ncam = len(lc.camera_names) if lc.camera_names else 0
        print(f"wrote {p}: {len(lc)} measurements of {obj} from {len(lc.site_names)} site(s)"
              + (f", {ncam} camera(s)" if ncam else "")
              + (f", band {band} (Sun {lc.attrs['sun_mag']:.3f} mag)" if band else "")
              + f"; geometry {lc.attrs['geometry_source']}"
              + ("" if lc.shape is None else f"; shape {lc.shape.name}")
              + f"; skipped {lc.attrs['skipped_below_horizon']} below the horizon, "
              f"{lc.attrs['skipped_unlit']} unlit, {lc.attrs['skipped_duplicate']} duplicate(s)")
    return 0


# ----------------------------------------------------------------------------------------
def _site_arg(text, dirs):
    """A catalogue id, or ``LAT,LON,HEIGHT_M`` (degrees, degrees, metres) for an inline site."""
    from ..geometry.sites import get_site

    parts = [x.strip() for x in str(text).split(",")]
    if len(parts) == 3:
        try:
            lat, lon, h = (float(x) for x in parts)
        except ValueError:
            pass
        else:
            return get_site({"id": "inline", "lat_deg": lat, "lon_deg": lon, "height_m": h})
    return get_site(str(text), dirs=dirs)


def _utc(text, option):
    from ..geometry.time import parse_epoch

    try:
        return parse_epoch(text)
    except InputError as exc:
        raise InputError(exc.bare_message, field=option, value=text, allowed=exc.allowed) from None


def _after(start, seconds) -> str:
    """ISO UTC text of ``start + seconds`` (whole seconds)."""
    from datetime import timedelta

    return (start + timedelta(seconds=float(seconds))).strftime("%Y-%m-%dT%H:%M:%SZ")


#: longest time span ``lightcurve passes`` searches (days)
MAX_PASS_SPAN_DAYS = 31.0
#: most samples evaluated in one pass (bounded memory: ~1 kB per sample in the geometry)
MAX_PASS_SAMPLES = 1_000_000


def find_passes(element_sets, site, start, end, *, min_elevation_deg=10.0, twilight_deg=-12.0,
                step_s=10.0, progress=None) -> list:
    """Visible, sunlit passes of each element set over ``site`` between two UTC datetimes.

    Rise/culmination/set above ``min_elevation_deg`` come from skyfield's
    ``EarthSatellite.find_events``; each pass is then sampled every ``step_s`` seconds
    (and at its ends) and a sample is *visible* when the object is above the elevation limit,
    at least partly sunlit (:func:`lightcurve.geometry.eclipse.lit_fraction` > 0, the
    package's conical shadow) and the Sun is below ``twilight_deg`` at the site. Passes with no
    visible sample are left out. A pass already in progress at ``start`` (or still at ``end``)
    is cut there; an object above the limit during the whole span (no rise or set, e.g. a
    geostationary one) is one pass from ``start`` to ``end``. More than
    :data:`MAX_PASS_SAMPLES` samples in one pass is an InputError naming ``--step-s``.

    Returns
    -------
    list of dict
        Sorted by rise time: ``object``, ``norad``, ``rise_utc``, ``culmination_utc``,
        ``set_utc``, ``max_elevation_deg``, ``visible_start_utc``, ``visible_end_utc``,
        ``visible_s`` (sampled duration, s).
    """
    import numpy as np
    from skyfield.api import wgs84

    from ..geometry.observation import compute_geometry
    from ..geometry.time import timescale

    ts = timescale()
    t0, t1 = ts.from_datetime(start), ts.from_datetime(end)
    topos = wgs84.latlon(site.lat_deg, site.lon_deg, elevation_m=site.height_m)
    out = []
    for es in element_sets:
        sat = es.satellite()
        times, events = sat.find_events(topos, t0, t1, altitude_degrees=float(min_elevation_deg))
        passes, cur = [], None
        if len(events) == 0:  # no rise or set: above the limit all the time (e.g. GEO), or never
            alt = (sat - topos).at(t0).altaz()[0].degrees
            if alt >= min_elevation_deg:
                passes.append({"rise": start, "culm": None, "set": end})
        for t, e in zip(times, events):
            if e == 0:
                cur = {"rise": t.utc_datetime(), "culm": None}
            elif e == 1:
                if cur is None:
                    cur = {"rise": start, "culm": None}
                cur["culm"] = t.utc_datetime()
            else:
                if cur is None:
                    cur = {"rise": start, "culm": None}
                cur["set"] = t.utc_datetime()
                passes.append(cur)
                cur = None
        if cur is not None:
            cur["set"] = end
            passes.append(cur)
        for ps in passes:
            dur = (ps["set"] - ps["rise"]).total_seconds()
            if dur <= 0:
                continue
            if dur / step_s > MAX_PASS_SAMPLES:
                raise InputError(f"a pass of {es.label} lasts {dur:.0f} s: too many samples at "
                                 f"this step", field="--step-s", value=step_s,
                                 allowed=f">= {dur / MAX_PASS_SAMPLES:.3g} s "
                                 f"(at most {MAX_PASS_SAMPLES} samples per pass)")
            tt = np.unique(np.concatenate([np.arange(0.0, dur, float(step_s)), [dur]]))
            epoch = ps["rise"].strftime("%Y-%m-%dT%H:%M:%S.%fZ")
            r, _ = es.positions(epoch, tt)
            geo = compute_geometry(epoch, tt, 0, [site], r, twilight_deg=twilight_deg)
            el = np.degrees(geo.elevation_rad)
            vis = (el >= min_elevation_deg - 1e-6) & (geo.lit_fraction > 0) & geo.site_dark
            if not np.any(vis):
                continue
            k = int(np.argmax(el))
            iv = np.flatnonzero(vis)
            at = functools.partial(_after, ps["rise"])
            out.append({"object": es.name or str(es.norad), "norad": es.norad,
                        "rise_utc": at(0.0), "culmination_utc": at(tt[k]), "set_utc": at(dur),
                        "max_elevation_deg": round(float(el[k]), 2),
                        "visible_start_utc": at(tt[iv[0]]), "visible_end_utc": at(tt[iv[-1]]),
                        "visible_s": round(float(np.sum(np.diff(tt)[vis[:-1]])), 1)})
        if progress is not None:
            progress()
    out.sort(key=lambda p: (p["rise_utc"], p["norad"]))
    return out


def _cmd_passes(args) -> int:
    """Search the time span for passes of every object in a TLE/OMM file above --min-elevation-deg
    at the site (skyfield find_events) and keep those with the object sunlit while the site is
    dark. Prints CSV (or writes -o FILE.csv).
    """
    import csv
    import io

    from ..geometry.tle import find_element_set, load_element_sets

    sets = load_element_sets(args.elements)
    if args.object:
        sets = [find_element_set(sets, o, file=args.elements) for o in args.object]
    site = _site_arg(args.site, args.sites)
    start, end = _utc(getattr(args, "from"), "--from"), _utc(args.to, "--to")
    span = (end - start).total_seconds() / 86400.0
    if not 0 < span <= MAX_PASS_SPAN_DAYS:
        raise InputError("--to must come after --from, within the search limit", field="--to",
                         value=args.to, allowed=f"0 < to - from <= {MAX_PASS_SPAN_DAYS:g} days")
    bar = None
    if not args.quiet and len(sets) > 1:
        from tqdm import tqdm

        bar = tqdm(total=len(sets), desc="passes", unit="object", file=sys.stderr)
    try:
        rows = find_passes(sets, site, start, end, min_elevation_deg=args.min_elevation_deg,
                           twilight_deg=args.twilight_deg, step_s=args.step_s,
                           progress=None if bar is None else (lambda: bar.update(1)))
    finally:
        if bar is not None:
            bar.close()
    cols = ("object", "norad", "rise_utc", "culmination_utc", "set_utc", "max_elevation_deg",
            "visible_start_utc", "visible_end_utc", "visible_s")
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    if args.output:
        from ..io.atomic import atomic_write_text

        atomic_write_text(args.output, buf.getvalue())
        report_written(args.output, detail=f": {len(rows)} visible pass(es) over {site.id}")
    else:
        sys.stdout.write(buf.getvalue())
        print(f"{len(rows)} visible pass(es) over {site.id} (object sunlit, Sun below "
              f"{args.twilight_deg:g} deg at the site, elevation >= "
              f"{args.min_elevation_deg:g} deg)", file=sys.stderr)
    return 0


def register(sub) -> None:
    p = add_command(
        sub, "import", _cmd_import,
        help="import an observatory CSV recording into self-contained lightcurve files")
    p.add_argument("recording", metavar="RECORDING.csv", help="the CSV recording")
    add_output(p, what="file", required=True,
               help="output file OUT.h5 (one object and band), or the stem of "
               "OUT.<object>.h5 files (several), or an existing folder")
    p.add_argument("--scenario", action="append", default=None, metavar="[OBJECT=]MODEL.toml",
                   help="model scenario (shape, attitude, sites, epoch, [recording] columns); "
                   "OBJECT=FILE gives one object its own (repeatable)")
    p.add_argument("--columns", default=None, metavar="MAP.toml",
                   help="column mapping: a TOML with a [recording] table (replaces the "
                   "scenario's)")
    p.add_argument("--tle", default=None, metavar="ELEMENTS",
                   help="TLE (2- or 3-line) or OMM (JSON, XML, CSV) file with the objects' "
                   "element sets, matched by NORAD number or name")
    p.add_argument("--object", action="append", default=None, metavar="ID",
                   help="import only this object (repeatable)")
    p.add_argument("--unlit", choices=("skip", "keep"), default=None,
                   help="rows with the object in the Earth's shadow: skip (default) or keep "
                   "(default keep when the scenario ignores the eclipse)")
    add_quiet(p, help="accepted for consistency (import prints one line per written file)")
    add_model_options(p)

    p = add_command(
        sub, "passes", _cmd_passes,
        help="list visible, sunlit passes of TLE/OMM objects over a site")
    p.add_argument("elements", metavar="ELEMENTS", help="TLE or OMM file")
    p.add_argument("--site", required=True, metavar="ID|LAT,LON,H",
                   help="catalogue site id, or an inline site as latitude,longitude (deg, "
                   "WGS84) and height (m)")
    p.add_argument("--from", required=True, metavar="UTC", help="start, ISO 8601 UTC")
    p.add_argument("--to", required=True, metavar="UTC",
                   help=f"end, ISO 8601 UTC (at most {MAX_PASS_SPAN_DAYS:g} days after --from)")
    p.add_argument("--object", action="append", default=None, metavar="ID",
                   help="only this object (NORAD number or name; repeatable)")
    p.add_argument("--min-elevation-deg", type=number(-5.0, 90.0), default=10.0,
                   help="lowest elevation of a pass, deg (default 10)")
    p.add_argument("--twilight-deg", type=number(-90.0, 10.0), default=-12.0,
                   help="the site is dark when the Sun is below this altitude, deg (default -12)")
    p.add_argument("--step-s", type=number(0.1, 600.0), default=10.0,
                   help="sampling step within a pass, s (default 10)")
    add_output(p, what="file", help="write the CSV to this file instead of stdout")
    add_quiet(p)
    add_model_options(p, shape=False, library=False)
