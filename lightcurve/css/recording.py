"""CSS recordings on disk (HDF5): simulated or measured CSS outputs, gyro rates and, for
simulations, the truth.

Layout (root attributes ``format = "lightcurve-css"``, ``format_version = 1``,
``configuration`` (TOML-free JSON of the nominal sensor set), ``epoch_utc``):

* ``t`` (K,) s since the epoch;  ``y`` (K,N) CSS outputs (dimensionless, full scale 1);
* ``normals`` (N,3) nominal sensor normals, body axes;  ``fov_half_angle_rad`` (N,);
* ``gyro_rad_s`` (K,3) measured body rates (absent for gyro-less recordings);
* ``truth/s_body`` (K,3), ``truth/q`` (K,4), ``truth/omega_rad_s`` (K,3), ``truth/lit`` (K,),
  ``estimate/s_hat`` (K,3) for simulated data;
* optional (written by the diagnosis-capable writer; older files lack them and cannot be
  diagnosed): ``geometry/r_eci_m`` (K,3) spacecraft GCRS position, m, and
  ``geometry/sun_eci_unit`` (K,3) unit spacecraft→Sun direction, GCRS; ``horizon_normals``
  (N,3) nominal structure-horizon normals (zero rows: none); root attributes ``noise_sigma``
  (output noise 1σ, full scale 1) and ``outputs_clipped_at_zero`` (1: y = max(signal + noise, 0)).

Writes go through :func:`lightcurve.io.atomic.atomic_path`.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from ..errors import InputError
from ..geometry.time import epoch_iso
from ..io.atomic import atomic_path
from .sensors import CSSArray

__all__ = ["write_css_recording", "read_css_recording"]


def write_css_recording(path, result, css: CSSArray, epoch_utc: str, with_gyro: bool, *,
                    noise_sigma: float | None = None) -> Path:
    """Write a :class:`~lightcurve.css.truth.SimResult` of sensor set ``css`` to ``path``.

    ``noise_sigma``: the output noise 1σ to record (default: ``result.info["css_noise_sigma"]``
    when present, else not recorded). The orbit position and Sun direction
    (``result.info["r_I_m"]``, ``["sun_I_hat"]``) are stored under ``geometry/`` when present.
    """
    path = Path(path)
    info = getattr(result, "info", None) or {}
    if noise_sigma is None:
        noise_sigma = info.get("css_noise_sigma")
    with atomic_path(path, suffix=".h5") as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = "lightcurve-css"
            f.attrs["format_version"] = 1
            f.attrs["epoch_utc"] = epoch_utc if isinstance(epoch_utc, str) else epoch_iso(epoch_utc)
            f.attrs["configuration"] = css.name
            f["t"] = result.t
            f["y"] = result.y
            f["normals"] = css.normals
            f["fov_half_angle_rad"] = css.fov_half_angle_rad
            if with_gyro:
                f["gyro_rad_s"] = result.omega_used
            g = f.create_group("truth")
            g["s_body"] = result.s_true
            g["q"] = result.q
            g["omega_rad_s"] = result.omega
            g["lit"] = result.lit
            f.create_group("estimate")["s_hat"] = result.s_hat
            f.attrs["outputs_clipped_at_zero"] = 1
            if noise_sigma is not None:
                f.attrs["noise_sigma"] = float(noise_sigma)
            if css.horizon_normals is not None:
                f["horizon_normals"] = np.asarray(css.horizon_normals, float)
            if info.get("r_I_m") is not None and info.get("sun_I_hat") is not None:
                geo = f.create_group("geometry")
                geo["r_eci_m"] = np.asarray(info["r_I_m"], float)
                geo["sun_eci_unit"] = np.asarray(info["sun_I_hat"], float)
    return path


def read_css_recording(path) -> dict:
    """Read a CSS recording; :class:`InputError` naming the file and dataset when malformed.

    Returns a dict with ``t``, ``y``, ``normals``, ``fov_half_angle_rad``, ``gyro`` (or None)
    and ``truth`` (dict or None).
    """
    from ..io.safe_open import open_hdf5

    path = Path(path)
    try:
        with open_hdf5(path) as f:  # regular file; no external links/storage, no VDS
            out = _read_checked(f, path)
    except InputError:
        raise
    except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:  # damaged file
        raise InputError(f"corrupted or unexpected HDF5 content: {exc}", file=path) from None
    return out


_MAX_ELEMENTS = 200_000_000


def _read_checked(f, path) -> dict:
    """Validate and read the datasets of an open CSS recording (see :func:`read_css_recording`)."""
    if f.attrs.get("format") != "lightcurve-css":
        raise InputError("not a CSS recording", file=path, field="format",
                         value=f.attrs.get("format"), allowed="lightcurve-css")

    def ds(name):
        d = f.get(name)
        if d is None:
            raise InputError("missing dataset", file=path, field=name)
        if not isinstance(d, h5py.Dataset):
            raise InputError("expected a dataset", file=path, field=name)
        if d.size > _MAX_ELEMENTS:
            raise InputError("dataset too large", file=path, field=name, value=d.shape)
        if d.dtype.kind not in "fiub":
            raise InputError("expected real numbers", file=path, field=name, value=str(d.dtype))
        from ..io.safe_open import read_dataset

        v = np.asarray(read_dataset(f, name, max_elements=_MAX_ELEMENTS, file=path), dtype=float)
        if not np.all(np.isfinite(v)):
            raise InputError("contains NaN or infinite values", file=path, field=name)
        return v

    out = {name: ds(name) for name in ("t", "y", "normals", "fov_half_angle_rad")}
    if out["t"].ndim != 1 or out["t"].size == 0:
        raise InputError("expected a non-empty 1-D array of times", file=path, field="t",
                         value=out["t"].shape)
    K = out["t"].shape[0]
    if out["normals"].ndim != 2 or out["normals"].shape[1] != 3 or out["normals"].shape[0] == 0:
        raise InputError("normals has the wrong shape", file=path, field="normals",
                         value=out["normals"].shape, allowed="(N, 3), N >= 1")
    N = out["normals"].shape[0]
    if np.any(np.linalg.norm(out["normals"], axis=1) < 1e-12):
        raise InputError("zero-length sensor normal", file=path, field="normals")
    if out["fov_half_angle_rad"].shape != (N,) or np.any(out["fov_half_angle_rad"] <= 0) \
            or np.any(out["fov_half_angle_rad"] > np.pi / 2):
        raise InputError("fov_half_angle_rad must be N values in (0, pi/2]", file=path,
                         field="fov_half_angle_rad", value=out["fov_half_angle_rad"].shape,
                         allowed=f"({N},) in (0, pi/2] rad")
    if out["y"].shape != (K, N):
        raise InputError("y has the wrong shape", file=path, field="y",
                         value=out["y"].shape, allowed=f"({K}, {N})")
    if np.any(np.diff(out["t"]) <= 0):
        raise InputError("t must be strictly increasing", file=path, field="t")
    out["gyro"] = ds("gyro_rad_s") if "gyro_rad_s" in f else None
    if out["gyro"] is not None and out["gyro"].shape != (K, 3):
        raise InputError("gyro_rad_s has the wrong shape", file=path, field="gyro_rad_s",
                         value=out["gyro"].shape, allowed=f"({K}, 3)")
    truth = None
    if "truth" in f:
        if not isinstance(f["truth"], h5py.Group):
            raise InputError("expected a group", file=path, field="truth")
        truth = {k: ds(f"truth/{k}") for k in f["truth"]}
        for k, v in truth.items():
            if v.shape[:1] != (K,):
                raise InputError(f"truth/{k} must have {K} rows", file=path, field=f"truth/{k}",
                                 value=v.shape)
    out["truth"] = truth
    geometry = None
    if "geometry" in f:
        if not isinstance(f["geometry"], h5py.Group):
            raise InputError("expected a group", file=path, field="geometry")
        geometry = {k: ds(f"geometry/{k}") for k in ("r_eci_m", "sun_eci_unit")}
        for k, v in geometry.items():
            if v.shape != (K, 3):
                raise InputError("wrong shape", file=path, field=f"geometry/{k}", value=v.shape,
                                 allowed=f"({K}, 3)")
        if np.any(np.linalg.norm(geometry["r_eci_m"], axis=1) < 6.0e6):
            raise InputError("spacecraft position inside the Earth", file=path,
                             field="geometry/r_eci_m", allowed="|r| >= 6000 km")
        if np.any(np.abs(np.linalg.norm(geometry["sun_eci_unit"], axis=1) - 1.0) > 1e-6):
            raise InputError("Sun directions must be unit vectors", file=path,
                             field="geometry/sun_eci_unit")
    out["geometry"] = geometry
    out["horizon_normals"] = None
    if "horizon_normals" in f:
        h = ds("horizon_normals")
        if h.shape != (N, 3):
            raise InputError("wrong shape", file=path, field="horizon_normals", value=h.shape,
                             allowed=f"({N}, 3)")
        out["horizon_normals"] = h
    ns = f.attrs.get("noise_sigma")
    if ns is not None:
        try:
            ns = float(ns)
        except (TypeError, ValueError):
            raise InputError("expected a number", file=path, field="noise_sigma", value=ns) from None
        if not (np.isfinite(ns) and ns > 0):
            raise InputError("noise_sigma must be positive", file=path, field="noise_sigma",
                             value=ns, allowed="> 0")
    out["noise_sigma"] = ns
    out["clipped_at_zero"] = bool(int(f.attrs.get("outputs_clipped_at_zero", 0)))
    ep = f.attrs.get("epoch_utc", "")
    out["epoch_utc"] = ep.decode() if isinstance(ep, bytes) else str(ep)
    return out
