"""The lightcurve HDF5 file (layout in docs/formats.md) and its in-memory object.

A :class:`Lightcurve` holds apparent magnitudes of one object measured (or simulated) from one
or more ground sites, the geometry needed to model them (object, site and Sun positions in ECI =
GCRS, metres) and, for simulated data, the truth attitude and the noise-free magnitudes.
Writes are atomic (temporary file + rename); reads validate every dataset and raise
:class:`~lightcurve.errors.InputError` naming the file and the dataset.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..report.views import LightcurveViews
from .atomic import atomic_path

__all__ = ["Lightcurve", "read_lightcurve", "FORMAT_VERSION", "MAG_RANGE", "MIN_OBJECT_RADIUS_M"]

FORMAT_VERSION = 1
#: apparent magnitudes accepted from any source (open interval): the Sun is −26.7, the
#: faintest objects measured (Hubble deep fields) about +31; beyond this a value is a unit or
#: parsing error, not a measurement (1e300 overflowed the filters' likelihoods)
MAG_RANGE = (-30.0, 40.0)
#: an observed object is outside the Earth: its distance from the centre exceeds the polar
#: radius, WGS84 b = 6356752.3 m (an object at the Earth's centre used to be inverted)
MIN_OBJECT_RADIUS_M = 6_356_752.3


@dataclass(repr=False)
class Lightcurve(LightcurveViews):
    """Apparent-magnitude time series with its observation geometry.

    Attributes (N measurements, K sites)
    ------------------------------------
    epoch_utc : str
        ISO 8601 UTC epoch; ``t`` counts seconds from it.
    t : (N,) float, s
    mag : (N,) float, apparent magnitude (NaN where not measured)
    mag_sigma : (N,) float, 1σ magnitude noise
    site : (N,) int, index into ``site_names``
    site_names : list[str] (K)
    site_lla_deg_m : (K, 3) geodetic latitude (deg), longitude (deg), height (m), WGS84
    r_obj_eci_m, r_site_eci_m, r_sun_eci_m : (N, 3) GCRS positions, m
    lit_fraction : (N,) fraction of the solar disc seen from the object (1 = full Sun)
    elevation_rad : (N,) object elevation above the site's horizon, rad
    truth_q : (N, 4) or None, inertial→body quaternion (scalar first)
    truth_omega_rad_s : (N, 3) or None, body angular velocity in body axes
    truth_mag : (N,) or None, noise-free magnitude
    scenario_toml : str, the scenario that produced (or models) the file ('' when none)
    attrs : dict, further metadata (e.g. shape name, r_percent, band, sun_mag, object_id)
    camera : (N,) int or None, index into ``camera_names`` (None: one camera per site)
    camera_names : list[str] or None, camera ids (each belongs to one site)
    exposure_s : (N,) float or None, exposure duration (s; NaN where unknown); ``t`` is then
        the mid-exposure time
    shape : Shape or None, the resolved shape (facets, materials, mesh) the file carries
        (:mod:`lightcurve.io.shape_h5`); every command uses it unless told otherwise
    """

    epoch_utc: str
    t: np.ndarray
    mag: np.ndarray
    mag_sigma: np.ndarray
    site: np.ndarray
    site_names: list
    site_lla_deg_m: np.ndarray
    r_obj_eci_m: np.ndarray
    r_site_eci_m: np.ndarray
    r_sun_eci_m: np.ndarray
    lit_fraction: np.ndarray | None = None
    elevation_rad: np.ndarray | None = None
    truth_q: np.ndarray | None = None
    truth_omega_rad_s: np.ndarray | None = None
    truth_mag: np.ndarray | None = None
    scenario_toml: str = ""
    attrs: dict = field(default_factory=dict)
    camera: np.ndarray | None = None
    camera_names: list | None = None
    exposure_s: np.ndarray | None = None
    shape: object = None

    def __post_init__(self):
        if not isinstance(self.epoch_utc, str):  # datetime, numpy.datetime64, skyfield/astropy Time
            from ..geometry.time import epoch_iso

            self.epoch_utc = epoch_iso(self.epoch_utc)
        self.validate()

    # ------------------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(np.asarray(self.t).shape[0])

    @property
    def has_truth(self) -> bool:
        """True when the file carries the truth attitude (simulated data)."""
        return self.truth_q is not None

    @property
    def camera_index(self) -> np.ndarray | None:
        """Alias of :attr:`camera` (per-row camera index, or None)."""
        return self.camera

    @property
    def obj_to_sun_unit(self) -> np.ndarray:
        """(N,3) unit vector from the object to the Sun, ECI."""
        d = self.r_sun_eci_m - self.r_obj_eci_m
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    @property
    def obj_to_obs_unit(self) -> np.ndarray:
        """(N,3) unit vector from the object to the observing site, ECI."""
        d = self.r_site_eci_m - self.r_obj_eci_m
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    @property
    def range_obs_m(self) -> np.ndarray:
        """(N,) object–observer distance, m."""
        return np.linalg.norm(self.r_site_eci_m - self.r_obj_eci_m, axis=1)

    @property
    def range_sun_m(self) -> np.ndarray:
        """(N,) object–Sun distance, m."""
        return np.linalg.norm(self.r_sun_eci_m - self.r_obj_eci_m, axis=1)

    @property
    def phase_angle_rad(self) -> np.ndarray:
        """(N,) Sun–object–observer angle, rad."""
        c = np.sum(self.obj_to_sun_unit * self.obj_to_obs_unit, axis=1)
        return np.arccos(np.clip(c, -1.0, 1.0))

    def subset(self, mask) -> "Lightcurve":
        """A new Lightcurve with only the rows where ``mask`` is true (or the given indices)."""
        idx = np.arange(len(self))[mask]
        kw = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray) and f.name not in ("site_lla_deg_m",) and v.shape[:1] == (len(self),):
                kw[f.name] = v[idx]
        return replace(self, **kw)

    # ------------------------------------------------------------------------------------
    def validate(self, file=None) -> None:
        """Check shapes, finiteness and ordering; raise InputError naming the field."""
        n = np.asarray(self.t).shape[0] if np.ndim(self.t) == 1 else -1

        def err(fieldname, msg, value=None, allowed=None):
            return InputError(msg, file=file, field=fieldname, value=value, allowed=allowed)

        if n < 0:
            raise err("t", "expected a 1-D array of times")
        self.t = np.asarray(self.t, dtype=float)
        if not np.all(np.isfinite(self.t)):
            raise err("t", "times must be finite")
        if n > 1 and np.any(np.diff(self.t) < 0):
            k = int(np.argmax(np.diff(self.t) < 0))
            raise err("t", f"times must be non-decreasing (row {k + 1} goes back in time)")
        for name, shape in (("mag", (n,)), ("mag_sigma", (n,)), ("site", (n,)),
                            ("r_obj_eci_m", (n, 3)), ("r_site_eci_m", (n, 3)), ("r_sun_eci_m", (n, 3)),
                            ("lit_fraction", (n,)), ("elevation_rad", (n,)), ("truth_q", (n, 4)),
                            ("truth_omega_rad_s", (n, 3)), ("truth_mag", (n,))):
            v = getattr(self, name)
            if v is None:
                continue
            if name == "site":  # integer indices: refuse NaN/fractions before the cast
                f = np.asarray(v, dtype=float)
                if not np.all(np.isfinite(f) & (f == np.round(f)) & (np.abs(f) < 2**31)):
                    raise err(name, "site indices must be integers", allowed="0..K-1")
            v = np.asarray(v, dtype=np.int64 if name == "site" else float)
            if v.shape != shape:
                raise err(name, f"expected shape {shape}, got {v.shape}")
            if name in ("r_obj_eci_m", "r_site_eci_m", "r_sun_eci_m", "truth_q", "truth_omega_rad_s") \
                    and not np.all(np.isfinite(v)):
                raise err(name, "contains NaN or infinite values")
            setattr(self, name, v)
        # NaN marks "not measured" (skipped by the filters, counted by count_unusable); an
        # infinite magnitude is never a measurement
        if np.any(np.isinf(self.mag)):
            k = int(np.argmax(np.isinf(self.mag)))
            raise err("mag", f"infinite magnitude at row {k}", value=float(self.mag[k]),
                      allowed="finite, or NaN for not measured")
        lo, hi = MAG_RANGE
        out = np.isfinite(self.mag) & ~((self.mag > lo) & (self.mag < hi))
        if np.any(out):
            k = int(np.argmax(out))
            raise err("mag", f"magnitude out of range at row {k}", value=float(self.mag[k]),
                      allowed=f"({lo:g}, {hi:g}), or NaN for not measured")
        bad_sig = ~((self.mag_sigma > 0) & np.isfinite(self.mag_sigma)) & np.isfinite(self.mag)
        if np.any(bad_sig):
            k = int(np.argmax(bad_sig))
            raise err("mag_sigma", f"measurement sigmas must be positive and finite (row {k})",
                      value=float(self.mag_sigma[k]), allowed="> 0")
        for name, lo, hi in (("lit_fraction", 0.0, 1.0), ("elevation_rad", -np.pi / 2, np.pi / 2)):
            v = getattr(self, name)
            if v is not None and not np.all((v >= lo) & (v <= hi)):
                raise err(name, "values must be finite and in range", allowed=f"[{lo:g}, {hi:g}]")
        k = len(self.site_names)
        self.site_names = [str(s) for s in self.site_names]
        if n and (self.site.min() < 0 or self.site.max() >= k):
            raise err("site", "site index out of range", allowed=f"0..{k - 1}")
        self._validate_cameras(err, n)
        if n > 1:  # the same camera measuring twice at one instant: a duplicated row
            same = (np.diff(self.t) == 0)
            if np.any(same):
                cam = self.camera if self.camera is not None else np.zeros(n, np.int64)
                order = np.lexsort((cam, self.site, self.t))
                dup = ((np.diff(self.t[order]) == 0) & (np.diff(self.site[order]) == 0)
                       & (np.diff(cam[order]) == 0))
                if np.any(dup):
                    j = int(order[int(np.argmax(dup)) + 1])
                    raise err("t", f"duplicated measurement: row {j} repeats the time, site and "
                              "camera of another row", value=float(self.t[j]),
                              allowed="one measurement per (time, site, camera)")
        try:
            self.site_lla_deg_m = np.asarray(self.site_lla_deg_m, dtype=float).reshape(k, 3)
        except ValueError:
            raise err("sites/lla_deg_m", f"expected shape ({k}, 3) for {k} site name(s)",
                      value=np.shape(self.site_lla_deg_m)) from None
        lla = self.site_lla_deg_m
        if not (np.all(np.isfinite(lla)) and np.all(np.abs(lla[:, 0]) <= 90)
                and np.all((lla[:, 1] >= -180) & (lla[:, 1] <= 360))):
            raise err("sites/lla_deg_m", "site latitude/longitude not finite or out of range",
                      allowed="lat in [-90, 90] deg, lon in [-180, 360] deg")
        self._check_geometry(err)
        self._check_time_span(err)
        if self.truth_q is not None:
            nq = np.linalg.norm(self.truth_q, axis=1)
            if np.any(np.abs(nq - 1) > 1e-6):
                raise err("truth_q", "quaternions must have unit norm")

    def _check_geometry(self, err) -> None:
        """The object is outside the Earth (|r_obj| > :data:`MIN_OBJECT_RADIUS_M`) and apart
        from the site and the Sun (an inversion needs the object-to-observer and
        object-to-Sun directions)."""
        if not len(self):
            return
        r = np.linalg.norm(self.r_obj_eci_m, axis=1)
        bad = ~(r > MIN_OBJECT_RADIUS_M)
        if np.any(bad):
            k = int(np.argmax(bad))
            raise err("geometry/r_obj_eci_m", f"object inside the Earth at row {k}",
                      value=float(r[k]), allowed=f"|r| > {MIN_OBJECT_RADIUS_M:.1f} m (WGS84 "
                      "polar radius)")
        for name, other in (("geometry/r_site_eci_m", self.r_site_eci_m),
                            ("geometry/r_sun_eci_m", self.r_sun_eci_m)):
            d = np.linalg.norm(other - self.r_obj_eci_m, axis=1)
            if not np.all(d > 0):
                k = int(np.argmax(~(d > 0)))
                raise err(name, f"object and {name.split('_')[1]} at the same place at row {k}",
                          allowed="distinct positions")
    def _validate_cameras(self, err, n) -> None:
        """Camera indices, names and exposure times (all optional)."""
        if (self.camera is None) != (self.camera_names is None):
            raise err("camera", "camera and cameras/name must both be present or both absent")
        if self.camera is not None:
            f = np.asarray(self.camera, dtype=float)
            if f.shape != (n,) or not np.all(np.isfinite(f) & (f == np.round(f))):
                raise err("camera", f"expected ({n},) integer camera indices", value=f.shape)
            self.camera = f.astype(np.int64)
            self.camera_names = [str(c) for c in self.camera_names]
            kc = len(self.camera_names)
            if n and (self.camera.min() < 0 or self.camera.max() >= kc):
                raise err("camera", "camera index out of range", allowed=f"0..{kc - 1}")
            if len(set(self.camera_names)) != kc:
                raise err("cameras/name", "camera ids must be distinct", value=self.camera_names)
            for c in range(kc):  # a camera belongs to one site
                sites = np.unique(self.site[self.camera == c])
                if sites.size > 1:
                    raise err("camera", f"camera {self.camera_names[c]!r} appears at several sites",
                              value=[self.site_names[i] for i in sites],
                              allowed="one site per camera id")
        if self.exposure_s is not None:
            e = np.asarray(self.exposure_s, dtype=float)
            if e.shape != (n,):
                raise err("exposure_s", f"expected shape ({n},), got {e.shape}")
            if np.any(np.isinf(e) | (e < 0)) or np.any(e > 3600.0):
                raise err("exposure_s", "exposure times must be in [0, 3600] s (NaN = unknown)")
            self.exposure_s = e

    def _check_time_span(self, err) -> None:
        """The epoch parses and every time lies inside the DE421 ephemeris (1899-07-30 to
        2053-10-08 UTC, the package's conservative bounds of JPL's 1899-07-29 .. 2053-10-09)."""
        from ..geometry.time import DE421_END_UTC, DE421_START_UTC, parse_epoch

        try:
            ep = parse_epoch(self.epoch_utc)
        except InputError as exc:
            raise err("epoch_utc", exc.bare_message, value=self.epoch_utc, allowed=exc.allowed) from None
        if len(self):
            lo = (DE421_START_UTC - ep).total_seconds()
            hi = (DE421_END_UTC - ep).total_seconds()
            if self.t[0] < lo or self.t[-1] > hi:
                k = 0 if self.t[0] < lo else len(self) - 1
                raise err("t", f"time at row {k} is outside the DE421 ephemeris",
                          value=float(self.t[k]), allowed=f"[{lo:.0f}, {hi:.0f}] s from epoch_utc "
                          "(1899-07-30 to 2053-10-08 UTC)")

    def resolve_shape(self, shape=None, library_dirs=None):
        """The shape to model this lightcurve with.

        In this order: ``shape`` when given (a :class:`Shape`, a library name or a shape TOML
        path, looked up in ``library_dirs`` then the bundled library); else the shape the file
        carries (:attr:`shape`); else the library shape named by ``attrs["shape"]``.

        Raises
        ------
        InputError
            No shape given, stored or named; or the named shape cannot be loaded.
        """
        from ..photometry import load_shape

        if shape is not None:
            return shape if not isinstance(shape, (str, Path, tuple)) else \
                load_shape(shape if isinstance(shape, tuple) else str(shape),
                           library_dirs=library_dirs)
        if self.shape is not None:
            return self.shape
        name = (self.attrs or {}).get("shape", "")
        if not name:
            raise InputError("the lightcurve carries no shape and names none: give a shape "
                             "(--shape NAME|FILE.toml, with --library DIR for a user library)",
                             field="shape")
        return load_shape(str(name), library_dirs=library_dirs, library_only=True)  # a name from data

    def count_unusable(self) -> dict:
        """Counts of rows a filter must skip: ``{"nan_mag": ...}`` (NaN = not measured)."""
        return {"nan_mag": int(np.sum(np.isnan(self.mag)))}

    # ------------------------------------------------------------------------------------
    def write(self, path) -> Path:
        """Write the HDF5 file atomically (temporary file, then rename); return the path."""
        import h5py

        path = Path(path)
        with atomic_path(path, suffix=".h5.tmp") as tmp:
            with h5py.File(tmp, "w") as h:
                h.attrs["format_version"] = FORMAT_VERSION
                h.attrs["epoch_utc"] = self.epoch_utc
                h.attrs["scenario"] = self.scenario_toml
                for k, v in self.attrs.items():
                    h.attrs[f"meta_{k}"] = v
                h["t"] = self.t
                h["t"].attrs["units"] = "s since epoch_utc"
                h["mag"] = self.mag
                h["mag_sigma"] = self.mag_sigma
                h["site"] = self.site.astype(np.int32)
                g = h.create_group("sites")
                g["name"] = np.array(self.site_names, dtype=h5py.string_dtype())
                g["lla_deg_m"] = self.site_lla_deg_m
                g = h.create_group("geometry")
                g["r_obj_eci_m"] = self.r_obj_eci_m
                g["r_site_eci_m"] = self.r_site_eci_m
                g["r_sun_eci_m"] = self.r_sun_eci_m
                if self.lit_fraction is not None:
                    g["lit_fraction"] = self.lit_fraction
                if self.elevation_rad is not None:
                    g["elevation_rad"] = self.elevation_rad
                if self.camera is not None:
                    h["camera"] = self.camera.astype(np.int32)
                    h.create_group("cameras")["name"] = np.array(self.camera_names,
                                                                 dtype=h5py.string_dtype())
                if self.exposure_s is not None:
                    h["exposure_s"] = self.exposure_s
                    h["exposure_s"].attrs["units"] = "s (NaN = unknown); t is mid-exposure"
                if self.shape is not None:
                    from .shape_h5 import write_shape

                    write_shape(h.create_group("shape"), self.shape)
                if self.truth_q is not None:
                    g = h.create_group("truth")
                    g["q"] = self.truth_q
                    g["omega_rad_s"] = self.truth_omega_rad_s
                    if self.truth_mag is not None:
                        g["mag"] = self.truth_mag
        return path


_MAX_ROWS = 50_000_000


def read_lightcurve(path) -> Lightcurve:
    """Read and validate a lightcurve HDF5 file written by :meth:`Lightcurve.write`.

    The file is opened through :func:`lightcurve.io.safe_open.open_hdf5` (regular file only;
    external links, external storage, virtual datasets and never-written datasets refused).
    Every dataset's declared shape is checked against the row count of ``t`` and the total
    against the memory limit (:func:`lightcurve.memory.check_allocation`) before any of them
    is read.

    Raises :class:`InputError` (naming the file and dataset) for a missing, truncated or
    corrupted file, a wrong format version, missing datasets or inconsistent shapes.
    """
    from .safe_open import open_hdf5, read_attr, read_dataset

    path = Path(path)
    try:
        with open_hdf5(path) as h:
            ver = h.attrs.get("format_version")
            if ver is None:
                raise InputError("missing root attribute", file=path, field="format_version")
            if int(ver) != FORMAT_VERSION:
                raise InputError("unsupported format version", file=path, field="format_version",
                                 value=int(ver), allowed=str(FORMAT_VERSION))
            _check_declared_shapes(h, path)

            def ds(name, required=True):
                return read_dataset(h, name, max_elements=_MAX_ROWS * 4, file=path,
                                    required=required)

            names = ds("sites/name")
            names = [n.decode() if isinstance(n, bytes) else str(n) for n in np.atleast_1d(names)]
            meta = {}
            for k in h.attrs:
                if k.startswith("meta_"):
                    meta[k[5:]] = read_attr(h, k, file=path)
            epoch = read_attr(h, "epoch_utc", file=path)
            if epoch is None:
                raise InputError("missing root attribute", file=path, field="epoch_utc")
            scen = read_attr(h, "scenario", "", file=path)
            kw = dict(
                epoch_utc=str(epoch),
                t=ds("t"), mag=ds("mag"), mag_sigma=ds("mag_sigma"), site=ds("site"),
                site_names=names, site_lla_deg_m=ds("sites/lla_deg_m"),
                r_obj_eci_m=ds("geometry/r_obj_eci_m"), r_site_eci_m=ds("geometry/r_site_eci_m"),
                r_sun_eci_m=ds("geometry/r_sun_eci_m"),
                lit_fraction=ds("geometry/lit_fraction", False),
                elevation_rad=ds("geometry/elevation_rad", False),
                truth_q=ds("truth/q", False), truth_omega_rad_s=ds("truth/omega_rad_s", False),
                truth_mag=ds("truth/mag", False),
                scenario_toml=str(scen),
                attrs=meta,
                camera=ds("camera", False), exposure_s=ds("exposure_s", False),
            )
            cams = ds("cameras/name", False)
            kw["camera_names"] = None if cams is None else [
                c.decode() if isinstance(c, bytes) else str(c) for c in np.atleast_1d(cams)]
            if "shape" in h:
                import h5py

                from .shape_h5 import read_shape

                if not isinstance(h["shape"], h5py.Group):
                    raise InputError("expected a group", file=path, field="shape")
                kw["shape"] = read_shape(h["shape"], file=path)
            else:
                kw["shape"] = None
    except InputError as exc:
        if exc.bare_message.startswith("not a readable HDF5") and \
                path.suffix.lower() in (".csv", ".txt", ".tsv", ".dat"):
            raise InputError("not an HDF5 lightcurve: a CSV recording is imported first "
                             "('lightcurve import RECORDING.csv -o OUT.h5 --scenario MODEL.toml', "
                             "docs/formats.md)", file=path) from None
        raise
    except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:  # h5py: damaged file
        raise InputError(f"corrupted or unexpected HDF5 content: {exc}", file=path) from None
    if (kw["truth_q"] is None) != (kw["truth_omega_rad_s"] is None):
        raise InputError("truth/q and truth/omega_rad_s must both be present or both absent",
                         file=path, field="truth")
    try:
        lc = Lightcurve.__new__(Lightcurve)
        for k, v in kw.items():
            setattr(lc, k, v)
        lc.validate(file=path)
    except InputError:
        raise
    except (ValueError, TypeError) as exc:
        raise InputError(f"inconsistent datasets: {exc}", file=path) from None
    return lc


#: per-row datasets and their trailing shapes (checked against ``t`` before any is read)
_ROW_DATASETS = (("t", ()), ("mag", ()), ("mag_sigma", ()), ("site", ()),
                 ("geometry/r_obj_eci_m", (3,)), ("geometry/r_site_eci_m", (3,)),
                 ("geometry/r_sun_eci_m", (3,)), ("geometry/lit_fraction", ()),
                 ("geometry/elevation_rad", ()), ("truth/q", (4,)), ("truth/omega_rad_s", (3,)),
                 ("truth/mag", ()))


def _check_declared_shapes(h, path) -> None:
    """Every per-row dataset declares (N, ...) with N = rows of ``t`` <= the row cap, and all
    of them together fit the memory limit — checked from the declared shapes, nothing read."""
    import h5py

    from ..memory import check_allocation

    t = h.get("t")
    if not isinstance(t, h5py.Dataset):
        raise InputError("missing dataset" if t is None else "expected a dataset", file=path,
                         field="t")
    if len(t.shape) != 1:
        raise InputError("expected a 1-D array of times", file=path, field="t",
                         value=tuple(int(x) for x in t.shape))
    n = int(t.shape[0])
    if n > _MAX_ROWS:
        raise InputError("too many rows", file=path, field="t", value=n,
                         allowed=f"<= {_MAX_ROWS} rows")
    total = 0
    for name, tail in _ROW_DATASETS:
        d = h.get(name)
        if not isinstance(d, h5py.Dataset):
            continue  # missing or wrong kind: reported when read
        if tuple(int(x) for x in d.shape) != (n, *tail):
            raise InputError(f"expected shape {(n, *tail)} (rows of t), got "
                             f"{tuple(int(x) for x in d.shape)}", file=path, field=name)
        total += n * int(np.prod(tail, dtype=np.int64)) * 8  # read as float64 / int64
    check_allocation(2 * total, f"reading {n} rows", file=path, field="t", value=n)
