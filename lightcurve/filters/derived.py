"""Quantities an analyst reads off an :class:`~lightcurve.filters.result.Estimate`.

All derived from the posterior ``q̂`` (inertial→body, scalar first), ``ω̂`` (rad/s, body axes)
and the 6×6 covariance ``P`` of ``[δθ (rad, body axes), δω (rad/s)]`` with
``q_true = δq(δθ) ⊗ q̂`` (module docstring of :mod:`lightcurve.filters.result`), by first-order
(linear) propagation of ``P``:

* :func:`euler321_with_sigma` — 3-2-1 Euler angles ``(φ, θ, ψ)`` (Bernard eq. 3.7, inertial→body)
  and their 1σ, ``Σ_e = J P_θθ Jᵀ`` with ``J = ∂e/∂δθ`` by central differences. Invalid near the
  gimbal lock ``|θ| → 90°`` where φ and ψ are not defined (σ grows without bound there).
* :func:`spin_axis` — the angular-velocity vector in inertial axes ``ω_I = A(q̂)ᵀ ω̂``
  (GCRS), its direction as right ascension / declination (deg) and rate (deg/s), with the 1σ
  of the direction (deg, largest axis) and of the rate from
  ``δω_I = A(q̂)ᵀ (δω − [ω̂×] δθ)`` (``A_true ≈ (I − [δθ×]) A(q̂)``).
* :func:`fitted_magnitudes` — the magnitudes predicted from the posterior attitude at each
  epoch (the fitted lightcurve), with the measurement model of the filters
  (:class:`lightcurve.filters.models.MagnitudeModel`).
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot

__all__ = ["euler321_with_sigma", "spin_axis", "fitted_magnitudes"]


def _wrap_pi(x):
    return (x + np.pi) % (2 * np.pi) - np.pi


def euler321_with_sigma(q, cov=None, h=1e-5):
    """3-2-1 angles (deg, ``(N,3)``: φ about z, θ about y, ψ about x) and their 1σ (deg).

    ``cov`` is the ``(N,6,6)`` (or ``(N,3,3)``) covariance whose leading 3×3 block is the
    attitude error δθ (rad², body axes); without it the σ are NaN. σ of an angle is capped at
    180° (gimbal lock).
    """
    q = rot.quat_normalize(np.asarray(q, float).reshape(-1, 4))
    e = rot.quat_to_euler321(q)
    sig = np.full_like(e, np.nan)
    if cov is not None:
        P = np.asarray(cov, float)[:, :3, :3]
        J = np.empty((q.shape[0], 3, 3))
        for j in range(3):
            d = np.zeros(3)
            d[j] = h
            qp = rot.quat_mult(rot.rotvec_to_quat(d), q)
            qm = rot.quat_mult(rot.rotvec_to_quat(-d), q)
            J[:, :, j] = _wrap_pi(rot.quat_to_euler321(qp) - rot.quat_to_euler321(qm)) / (2 * h)
        S = np.einsum("nij,njk,nlk->nil", J, P, J)
        sig = np.sqrt(np.clip(np.diagonal(S, axis1=1, axis2=2), 0, None))
        sig = np.minimum(np.degrees(sig), 180.0)
    return np.degrees(e), sig


def spin_axis(q, omega_rad_s, cov=None):
    """Spin axis on the sky from the posterior (module docstring).

    Returns a dict of ``(N,)`` arrays: ``ra_deg`` ∈ [0, 360), ``dec_deg``, ``rate_deg_s``
    (|ω|), ``axis_sigma_deg`` (1σ of the direction along its worst axis; NaN without ``cov``),
    ``rate_sigma_deg_s``, and ``omega_eci_rad_s`` ``(N,3)``.
    """
    q = rot.quat_normalize(np.asarray(q, float).reshape(-1, 4))
    w = np.asarray(omega_rad_s, float).reshape(-1, 3)
    wI = rot.quat_rotate_inv(q, w)
    rate = np.linalg.norm(wI, axis=1)
    u = wI / np.where(rate > 0, rate, 1.0)[:, None]
    ra = np.degrees(np.arctan2(u[:, 1], u[:, 0])) % 360.0
    dec = np.degrees(np.arcsin(np.clip(u[:, 2], -1, 1)))
    out = {"ra_deg": ra, "dec_deg": dec, "rate_deg_s": np.degrees(rate),
           "axis_sigma_deg": np.full(rate.shape, np.nan),
           "rate_sigma_deg_s": np.full(rate.shape, np.nan), "omega_eci_rad_s": wI}
    if cov is not None:
        P = np.asarray(cov, float)
        A_T = np.swapaxes(rot.quat_to_dcm(q), -1, -2)           # body -> inertial
        wx = np.zeros((len(w), 3, 3))
        wx[:, 0, 1], wx[:, 0, 2], wx[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
        wx[:, 1, 0], wx[:, 2, 0], wx[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
        J = np.concatenate([-A_T @ wx, A_T], axis=2)             # (N,3,6)
        C = J @ P @ np.swapaxes(J, -1, -2)                       # cov of ω_I, (rad/s)²
        proj = np.eye(3)[None] - u[:, :, None] * u[:, None, :]
        Cp = proj @ C @ proj
        lam = np.linalg.eigvalsh(0.5 * (Cp + np.swapaxes(Cp, -1, -2)))[:, -1]
        with np.errstate(divide="ignore", invalid="ignore"):
            out["axis_sigma_deg"] = np.degrees(np.sqrt(np.clip(lam, 0, None)) / rate)
        out["rate_sigma_deg_s"] = np.degrees(np.sqrt(np.clip(
            np.einsum("ni,nij,nj->n", u, C, u), 0, None)))
    return out


def fitted_magnitudes(q, curve, shape=None):
    """Magnitudes predicted from attitudes ``q`` (N,4) at the N epochs of ``curve`` (mag).

    ``shape`` defaults to the lightcurve's own (the shape stored in the file, else its
    ``attrs["shape"]`` library name). Epochs where no lit facet faces the observer are NaN.
    """
    from .models import MagnitudeModel

    if shape is None:
        shape = _curve_shape(curve)
    elif isinstance(shape, str):
        from ..photometry import load_shape

        shape = load_shape(shape)
    model = MagnitudeModel(shape, curve)
    q = np.asarray(q, float).reshape(-1, 4)
    out = np.full(len(model), np.nan)
    for k in range(len(model)):
        if np.all(np.isfinite(q[k])):
            out[k] = float(model.predict_q(q[k][None, :], k)[0])
    out[~np.isfinite(out)] = np.nan
    return out


def _curve_shape(curve):
    """The shape a lightcurve was made with: the stored one, else the named library shape."""
    stored = getattr(curve, "shape", None)
    if stored is not None and hasattr(stored, "kernel_arrays"):
        return stored
    from ..errors import InputError
    from ..photometry import load_shape

    name = (curve.attrs or {}).get("shape", "")
    if not name:
        raise InputError("the lightcurve names no shape (attrs['shape'])", field="attrs.shape")
    return load_shape(str(name))
