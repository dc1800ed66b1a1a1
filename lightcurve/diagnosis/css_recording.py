"""Diagnosis of a coarse-sun-sensor recording (HDF5 written by ``lightcurve css simulate``).

The model of a CSS recording is built from the file itself: the nominal sensor set (normals,
field-of-view half angles, structure horizons — or a CSS configuration TOML given by the
user), the attitude ``truth/q`` (inertial→body), the spacecraft position
``geometry/r_eci_m`` (GCRS, m), the unit Sun direction ``geometry/sun_eci_unit`` (GCRS) and
the lit fraction ``truth/lit`` (recomputed from the geometry with the conical Earth shadow
when absent). The baseline is the cosine response to the direct Sun only (O'Keefe 2015,
eq. 2.21 without albedo, nominal scale factors and normals); the ``css_*`` effects of the
registry are the candidates.

Noise: the file's ``noise_sigma`` attribute, else a robust estimate from the data
(:func:`estimate_noise_sigma`). Outputs recorded as max(signal + noise, 0) (attribute
``outputs_clipped_at_zero``) are compared with the mean of that clipped Gaussian
(:func:`~.problem.clipped_gaussian_mean`). Long recordings are thinned to at most
``max_epochs`` evenly spaced epochs (every k-th sample; the albedo model costs one
Earth-grid sum per epoch and effect evaluation) — the diagnosis notes say so.

Files written before the geometry was recorded cannot be diagnosed (InputError naming the
missing dataset).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["is_css_recording", "css_recording_problem", "estimate_noise_sigma"]

AU_M = 149_597_870_700.0


def is_css_recording(path) -> bool:
    """True when ``path`` is an HDF5 file with root attribute ``format = "lightcurve-css"``."""
    from ..io.safe_open import is_regular_file, open_hdf5

    p = Path(path)
    if not is_regular_file(p):
        return False
    try:
        with open_hdf5(p) as f:
            fmt = f.attrs.get("format", "")
    except (InputError, OSError):
        return False
    fmt = fmt.decode() if isinstance(fmt, bytes) else str(fmt)
    return fmt == "lightcurve-css"


def estimate_noise_sigma(y) -> float:
    """Robust 1σ of white output noise from second differences (same unit as ``y``).

    For samples close in time the signal is locally linear, so
    d_k = y_{k+1} − 2 y_k + y_{k−1} has variance 6σ² (white noise); σ = 1.4826 MAD(d)/√6
    over triples whose output (7-sample running mean) is well above zero, all sensors pooled:
    a first pass over positive ones gives σ₀ (biased low by dark sensors whose outputs are
    clipped noise), the second keeps those above max(5σ₀, 0.05). Biased high by the signal
    curvature (ω² Δt² per unit output: < 1e-4 for 1°/s at 0.5 s).
    """
    y = np.asarray(y, float)
    if y.ndim != 2 or y.shape[0] < 3:
        raise InputError("too few samples to estimate the output noise", field="y")
    d = y[2:] - 2.0 * y[1:-1] + y[:-2]
    # select on a 7-sample running mean (selecting on the noisy values themselves would
    # truncate the noise of samples near the threshold and bias σ low)
    k = np.ones(7) / 7.0
    sm = np.apply_along_axis(lambda c: np.convolve(c, k, mode="same"), 0, y)
    lo = sm[1:-1]

    def mad_sigma(ok):
        if ok.sum() < 20:
            raise InputError("too few unclipped samples to estimate the output noise; record "
                             "the noise_sigma attribute", field="noise_sigma")
        dd = d[ok]
        return float(1.4826 * np.median(np.abs(dd - np.median(dd))) / math.sqrt(6.0))

    s0 = mad_sigma(lo > 0)
    return mad_sigma(lo > max(5.0 * s0, 0.05))


def css_recording_problem(path, *, configuration=None, max_epochs: int = 400, label=None):
    """The CSS diagnosis :class:`~.problem.Problem` of a recording, and notes (list of str).

    ``configuration``: optional CSS configuration TOML (the model's nominal sensor set,
    :func:`lightcurve.css.configurations.load_configuration`); default: the file's normals,
    FOVs and horizons. ``max_epochs``: thinning limit (module docstring).
    """
    from ..css.recording import read_css_recording
    from ..css.sensors import CSSArray
    from ..physics import CSSContext
    from .problem import css_problem

    path = Path(path)
    rec = read_css_recording(path)
    notes = []
    if rec.get("geometry") is None:
        raise InputError("this CSS recording has no orbit geometry (written by an older version); "
                         "re-simulate it with 'lightcurve css simulate ... --out FILE'", file=path,
                         field="geometry/r_eci_m", allowed="datasets geometry/r_eci_m and "
                         "geometry/sun_eci_unit, (K, 3)")
    truth = rec.get("truth") or {}
    if "q" not in truth:
        raise InputError("diagnosing a CSS recording needs the attitude (truth/q, inertial→body, "
                         "scalar first)", file=path, field="truth/q")
    q = truth["q"]
    if q.shape != (rec["t"].size, 4) or np.any(np.abs(np.linalg.norm(q, axis=1) - 1) > 1e-6):
        raise InputError("truth/q must be (K, 4) unit quaternions", file=path, field="truth/q",
                         value=q.shape)
    r = rec["geometry"]["r_eci_m"]
    sun = rec["geometry"]["sun_eci_unit"]
    if "lit" in truth:
        lit = truth["lit"]
    else:
        from ..geometry.eclipse import lit_fraction

        lit = lit_fraction(r, sun * AU_M)
        notes.append("lit fraction recomputed from the geometry (conical shadow)")
    if configuration is not None:
        from ..css.configurations import load_configuration

        arr = load_configuration(configuration)
        if arr.n_sensors != rec["y"].shape[1]:
            raise InputError("the configuration's sensor count differs from the recording's",
                             file=configuration, field="sensor", value=arr.n_sensors,
                             allowed=str(rec["y"].shape[1]))
        arr = arr.with_errors(noise_sigma=0.0)
    else:
        arr = CSSArray(rec["normals"], rec["fov_half_angle_rad"],
                       horizon_normals=rec.get("horizon_normals"), name=f"{path.name} (nominal)")
    y = rec["y"]
    if rec.get("noise_sigma") is not None:
        sigma = float(rec["noise_sigma"])
    else:
        sigma = estimate_noise_sigma(y)
        notes.append(f"output noise 1σ estimated from second differences: {sigma:.4g} "
                     "(the file records no noise_sigma)")
    K = y.shape[0]
    stride = max(1, int(math.ceil(K / int(max_epochs))))
    idx = np.arange(0, K, stride)
    if stride > 1:
        notes.append(f"every {stride}th of {K} samples used ({idx.size} epochs)")
    ctx = CSSContext(arr, rec["t"][idx], rec["epoch_utc"], q[idx], r[idx], sun[idx], lit[idx])
    prob = css_problem(ctx, y[idx], sigma, label=label or path.name,
                       censored_at_zero=bool(rec.get("clipped_at_zero")))
    return prob, notes
