"""Element-set files: TLEs (with or without name lines) and OMM (JSON, XML or CSV), many objects.

Formats (detected from the content; docs/formats.md "Element sets"):

* TLE text: any number of two-line element sets, each optionally preceded by a name line
  ("3LE"; a leading ``0 `` of the name line, as Space-Track writes it, is dropped). Blank lines
  and lines starting with ``#`` are ignored. Every line pair is checked (69 characters,
  checksums, matching catalogue numbers: :func:`lightcurve.geometry.orbits.check_tle`).
* OMM JSON: a list of objects (or one object) with the CCSDS OMM keyword names, as CelesTrak
  and Space-Track serve them (``OBJECT_NAME``, ``NORAD_CAT_ID``, ``EPOCH``, ``MEAN_MOTION`` …).
* OMM XML (CCSDS NDM/OMM, one ``<segment>`` per object) and OMM CSV (a header line with the
  keyword names).

The parsing is done by sgp4 (``sgp4.omm``) and skyfield (``EarthSatellite``, ``from_omm``);
propagation is SGP4 with skyfield's TEME → GCRS conversion
(:func:`lightcurve.geometry.orbits.satellite_positions`). An element set is found for an object
id by NORAD catalogue number or by name (case and surrounding blanks ignored).

A TLE is a mean-element fit valid near its epoch: SGP4 errors grow by roughly a kilometre per
day. :func:`check_element_age` warns (:class:`ElementAgeWarning`) when observations lie more
than :data:`MAX_AGE_DAYS` from the element epoch.

Hardening: the file is read through :func:`lightcurve.io.safe_open.read_text` (regular
files only, :data:`MAX_BYTES`), at most :data:`MAX_SETS` element sets, XML with a DOCTYPE or
entity declarations is refused; every problem is an :class:`~lightcurve.errors.InputError`
naming the file and the line or object.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from ..errors import InputError

__all__ = ["ElementSet", "load_element_sets", "find_element_set", "check_element_age",
           "ElementAgeWarning", "MAX_AGE_DAYS", "MAX_BYTES", "MAX_SETS"]

#: largest element-set file read (bytes); the full public catalogue is ≈ 10 MB as OMM JSON
MAX_BYTES = 64 * 1024 * 1024
#: most element sets in one file
MAX_SETS = 200_000
#: observations farther than this from the element epoch give an ElementAgeWarning (days)
MAX_AGE_DAYS = 3.0


class ElementAgeWarning(UserWarning):
    """Observations far from the epoch of the element set used for the object's position."""


@dataclass
class ElementSet:
    """One object's mean elements.

    Attributes
    ----------
    name : str — object name ('' when the file gives none)
    norad : int — NORAD catalogue number
    epoch_utc : datetime — element epoch (UTC)
    source : str — file and line/record the set comes from
    line1, line2 : str or None — the TLE lines (None for OMM)
    omm : dict or None — the OMM fields (None for TLEs)
    """

    name: str
    norad: int
    epoch_utc: datetime
    source: str
    line1: str | None = None
    line2: str | None = None
    omm: dict | None = None
    _sat: object = field(default=None, repr=False, compare=False)

    @property
    def label(self) -> str:
        """``NAME (NORAD)`` or the number alone."""
        return f"{self.name} ({self.norad})" if self.name else str(self.norad)

    def satellite(self):
        """The skyfield ``EarthSatellite`` (built once)."""
        if self._sat is None:
            self._sat = _build_satellite(self.line1, self.line2, self.omm, self.name,
                                         self.source)
        return self._sat

    def positions(self, epoch_utc, t_s):
        """GCRS position (m) and velocity (m/s), each ``(N, 3)``, at ``epoch_utc + t_s``."""
        from .orbits import satellite_positions

        try:
            return satellite_positions(self.satellite(), epoch_utc, t_s)
        except InputError as exc:
            raise InputError(exc.bare_message, file=self.source, field=self.label) from None


def _build_satellite(line1, line2, omm, name, source):
    from skyfield.api import EarthSatellite

    from .time import timescale

    try:
        if omm is not None:
            return EarthSatellite.from_omm(timescale(), omm)
        return EarthSatellite(line1, line2, name or None, ts=timescale())
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        what = f"missing OMM field {exc}" if isinstance(exc, KeyError) else str(exc)
        raise InputError(f"element set could not be parsed: {what}", file=source,
                         field=name or None) from None


def _jd_to_datetime(jd: float) -> datetime:
    from datetime import timedelta

    return datetime(2000, 1, 1, 12, tzinfo=timezone.utc) + timedelta(days=jd - 2451545.0)


def _from_satellite(sat, name, source, line1=None, line2=None, omm=None) -> ElementSet:
    m = sat.model
    epoch = _jd_to_datetime(float(m.jdsatepoch) + float(m.jdsatepochF))
    es = ElementSet(name=(name or "").strip(), norad=int(m.satnum), epoch_utc=epoch,
                    source=source, line1=line1, line2=line2, omm=omm)
    es._sat = sat
    return es


# ----------------------------------------------------------------------------------------
def _parse_tle_text(text: str, path) -> list:
    from .orbits import check_tle

    lines = [(no, ln.rstrip("\r\n")) for no, ln in enumerate(text.splitlines(), 1)]
    lines = [(no, ln) for no, ln in lines if ln.strip() and not ln.lstrip().startswith("#")]
    out = []
    i = 0
    while i < len(lines):
        no, ln = lines[i]
        name = ""
        if not ln.startswith("1 "):
            name = ln.strip()
            if name.startswith("0 "):
                name = name[2:].strip()
            i += 1
            if i >= len(lines):
                raise InputError("a name line without its two element lines", file=path,
                                 field=f"line {no}", value=ln.strip())
            no, ln = lines[i]
        if i + 1 >= len(lines) or not ln.startswith("1 ") or not lines[i + 1][1].startswith("2 "):
            raise InputError("expected a TLE line 1 followed by line 2 (optionally after a name "
                             "line)", file=path, field=f"line {no}", value=ln.strip(),
                             allowed="NAME / 1 ... / 2 ... (3LE) or 1 ... / 2 ... (2LE)")
        l1, l2 = ln.rstrip(), lines[i + 1][1].rstrip()
        try:
            check_tle(l1, l2)
        except InputError as exc:
            raise InputError(exc.bare_message, file=path, field=f"line {no}", value=exc.value,
                             allowed=exc.allowed) from None
        sat = _build_satellite(l1, l2, None, name, f"{path}:{no}")
        out.append(_from_satellite(sat, name, f"{path}:{no}", line1=l1, line2=l2))
        if len(out) > MAX_SETS:
            raise InputError("too many element sets", file=path, allowed=f"<= {MAX_SETS}")
        i += 2
    return out


def _omm_records_json(text, path) -> list:
    try:
        doc = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise InputError(f"not valid JSON: {exc}", file=path) from None
    if isinstance(doc, dict):
        doc = [doc]
    if not isinstance(doc, list) or not all(isinstance(r, dict) for r in doc):
        raise InputError("expected a list of OMM objects", file=path)
    return [{str(k): ("" if v is None else str(v)) for k, v in r.items()} for r in doc]


def _omm_records_xml(text, path) -> list:
    import io
    import xml.etree.ElementTree as ET

    from sgp4 import omm

    head = text[:4096].upper()
    if "<!DOCTYPE" in head or "<!ENTITY" in text.upper():
        raise InputError("XML with a DOCTYPE or entity declarations is refused", file=path)
    try:
        return list(omm.parse_xml(io.StringIO(text)))
    except (ET.ParseError, AttributeError) as exc:
        raise InputError(f"not an OMM XML file: {exc}", file=path) from None


def _omm_records_csv(text, path) -> list:
    import csv
    import io

    try:
        return [dict(r) for r in csv.DictReader(io.StringIO(text))]
    except csv.Error as exc:
        raise InputError(f"not an OMM CSV file: {exc}", file=path) from None


def load_element_sets(path) -> list:
    """Every element set in a TLE or OMM file (module docstring), in file order.

    Raises
    ------
    InputError
        An unreadable or special file, a file above :data:`MAX_BYTES`, a malformed TLE line
        (naming the line), a missing OMM field (naming the record), no element set at all.
    """
    from ..io.safe_open import read_text

    path = Path(path)
    text = read_text(path, max_bytes=MAX_BYTES, what="element-set file")
    head = text.lstrip()[:1]
    first = text.lstrip().splitlines()[0] if text.strip() else ""
    if head in ("[", "{"):
        kind, recs = "OMM JSON", _omm_records_json(text, path)
    elif head == "<":
        kind, recs = "OMM XML", _omm_records_xml(text, path)
    elif "NORAD_CAT_ID" in first:
        kind, recs = "OMM CSV", _omm_records_csv(text, path)
    else:
        kind, recs = "TLE", None
    if recs is None:
        out = _parse_tle_text(text, path)
    else:
        if len(recs) > MAX_SETS:
            raise InputError("too many element sets", file=path, value=len(recs),
                             allowed=f"<= {MAX_SETS}")
        out = []
        for k, r in enumerate(recs):
            src = f"{path}:record {k + 1}"
            sat = _build_satellite(None, None, r, r.get("OBJECT_NAME", ""), src)
            out.append(_from_satellite(sat, r.get("OBJECT_NAME", ""), src, omm=r))
    if not out:
        raise InputError(f"no element set found ({kind} file)", file=path)
    return out


def _norm(name) -> str:
    return " ".join(str(name).split()).casefold()


def find_element_set(sets, object_id, *, file=None) -> ElementSet:
    """The element set of ``object_id``: its NORAD number (an integer or digits) or its name.

    Raises
    ------
    InputError
        No set matches, or several sets match a name (naming them).
    """
    oid = str(object_id).strip()
    if oid.isdigit():
        hits = [s for s in sets if s.norad == int(oid)]
    else:
        hits = [s for s in sets if s.name and _norm(s.name) == _norm(oid)]
    if not hits:
        known = ", ".join(s.label for s in sets[:20]) + (" ..." if len(sets) > 20 else "")
        raise InputError("no element set for this object", file=file, field="object",
                         value=oid, allowed=known)
    if len({(s.norad, s.epoch_utc) for s in hits}) > 1 and not oid.isdigit():
        raise InputError("several element sets carry this name; use the NORAD number",
                         file=file, field="object", value=oid,
                         allowed=", ".join(s.label for s in hits))
    if len(hits) > 1:  # the same object several times: the newest epoch
        hits.sort(key=lambda s: s.epoch_utc)
    return hits[-1]


def check_element_age(es: ElementSet, times_utc, *, max_age_days: float = MAX_AGE_DAYS,
                      stacklevel: int = 2) -> float:
    """Largest |observation − element epoch| in days; warns above ``max_age_days``."""
    ts = [t.timestamp() for t in times_utc]
    if not ts:
        return 0.0
    e = es.epoch_utc.timestamp()
    age = max(abs(min(ts) - e), abs(max(ts) - e)) / 86400.0
    if age > max_age_days:
        warnings.warn(f"{es.source}: element set of {es.label} (epoch "
                      f"{es.epoch_utc:%Y-%m-%dT%H:%M:%SZ}) is used {age:.1f} days from its "
                      f"epoch (> {max_age_days:g}): SGP4 positions may be kilometres off",
                      ElementAgeWarning, stacklevel=stacklevel)
    return float(age)
