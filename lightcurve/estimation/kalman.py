"""Kalman-filter building blocks: prediction, Joseph-form and consider updates, safe Cholesky.

Generic linear-algebra steps shared by every Kalman-type filter of the package (MEKF, sun-line
EKF, consider EKF, calibration filter). They know nothing about attitude: an error-state filter
(MEKF) calls :func:`joseph_update` with ``x = 0`` and applies the correction itself.

Conventions
-----------
* ``x`` (n,) state (any units), ``P`` (n, n) its covariance; ``y`` (m,) measurement,
  ``h`` (m,) predicted measurement, ``H`` (m, n) measurement Jacobian ∂h/∂x, ``R`` (m, m)
  measurement-noise covariance, all in the units of the model that built them.
* Innovation ``ν = y − h``, its covariance ``S = H P Hᵀ + R``, gain ``K = P Hᵀ S⁻¹``.
* Covariance update in Joseph form (Bucy & Joseph 1968; Bar-Shalom, Li & Kirubarajan 2001,
  §5.2.3) ``P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ``, valid for *any* gain, which is what
  makes the Schmidt consider update (gain rows of the considered states set to zero; O'Keefe
  2015 §3.2.2, Woodbury & Junkins 2010) exact.
* Every returned covariance is symmetrised, ``(P + Pᵀ)/2``.

Failure path (DESIGN.md, "Numerics"): a factorisation of ``S`` that fails, or any non-finite
intermediate, leaves ``x`` and ``P`` unchanged and reports ``ok = False`` in the returned
:class:`UpdateInfo`; never a silent NaN.

The algebra is done once, by the kernels of :mod:`lightcurve.core.kalman` (``cholesky_nb``,
``joseph_update_nb`` are re-exported here for compiled filter loops); this module validates
shapes and packages the diagnostics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.kalman import cholesky_nb, joseph_apply_nb, joseph_update_nb, kalman_gain_nb

__all__ = [
    "UpdateInfo",
    "symmetrize",
    "safe_cholesky",
    "kf_predict",
    "joseph_update",
    "consider_update",
    "cholesky_nb",
    "joseph_update_nb",
]


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------

def symmetrize(P):
    """Return ``(P + Pᵀ)/2`` over the last two axes (float64; works on stacks (..., n, n))."""
    P = np.asarray(P, dtype=float)
    if P.ndim < 2 or P.shape[-1] != P.shape[-2]:
        raise ValueError(f"symmetrize needs square matrices (..., n, n), got shape {P.shape}")
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def safe_cholesky(P):
    """Lower Cholesky factor of a symmetric positive-definite matrix, with a failure flag.

    Parameters
    ----------
    P : array_like (n, n)
        Symmetric matrix (it is symmetrised first, so tiny asymmetries from round-off are
        harmless).

    Returns
    -------
    L : ndarray (n, n) or None
        Lower-triangular with ``L Lᵀ = P``; ``None`` when the factorisation failed.
    ok : bool
        ``False`` when ``P`` has a non-finite entry or is not positive definite (a zero or
        negative pivot). No exception is raised for a bad matrix and no NaN is returned.

    Raises
    ------
    ValueError
        If ``P`` is not a square 2-D array (programmer error, not a numerical failure).
    """
    P = np.asarray(P, dtype=float)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        raise ValueError(f"safe_cholesky needs a square 2-D matrix, got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        return None, False
    L, ok = cholesky_nb(np.ascontiguousarray(0.5 * (P + P.T)))
    return (L, True) if ok else (None, False)


def _as_vector(a, name):
    a = np.asarray(a, dtype=float)
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1:
        raise ValueError(f"{name} must be a scalar or a 1-D array, got shape {a.shape}")
    return a


def _check_state(x, P):
    x = _as_vector(x, "x")
    P = np.asarray(P, dtype=float)
    n = x.shape[0]
    if P.shape != (n, n):
        raise ValueError(f"P must have shape ({n}, {n}) to match x, got {P.shape}")
    return x, P


def _as_matrix_H(H, n, m=None):
    H = np.asarray(H, dtype=float)
    if H.ndim == 1:
        H = H.reshape(1, -1)
    if H.ndim != 2 or H.shape[1] != n:
        raise ValueError(f"H must have shape (m, {n}) (or ({n},) for m = 1), got {H.shape}")
    if m is not None and H.shape[0] != m:
        raise ValueError(f"H has {H.shape[0]} rows but the measurement has {m} components")
    return H


def _as_matrix_R(R, m):
    R = np.asarray(R, dtype=float)
    if R.ndim == 0:
        return float(R) * np.eye(m)
    if R.ndim == 1:
        if R.shape[0] != m:
            raise ValueError(f"diagonal R must have {m} entries, got {R.shape[0]}")
        return np.diag(R)
    if R.shape != (m, m):
        raise ValueError(f"R must be a scalar, ({m},) diagonal or ({m}, {m}), got {R.shape}")
    return R


def _consider_mask(consider, n):
    if consider is None:
        return None
    c = np.asarray(consider)
    if c.dtype == bool:
        if c.shape != (n,):
            raise ValueError(f"boolean consider mask must have shape ({n},), got {c.shape}")
        return c
    c = c.astype(int).ravel()
    if np.any((c < 0) | (c >= n)):
        raise ValueError(f"consider indices must lie in [0, {n}), got {c.tolist()}")
    mask = np.zeros(n, dtype=bool)
    mask[c] = True
    return mask


@dataclass(frozen=True)
class UpdateInfo:
    """Diagnostics of one measurement update.

    Attributes
    ----------
    innovation : ndarray (m,)
        ``ν = y − h`` in measurement units.
    S : ndarray (m, m)
        Innovation covariance ``H P Hᵀ + R`` (symmetrised).
    nis : float
        Normalised innovation squared ``νᵀ S⁻¹ ν`` (chi-square with m degrees of freedom for
        a consistent filter); NaN only when ``ok`` is False.
    ok : bool
        False when the update was refused (``x``, ``P`` returned unchanged).
    gain : ndarray (n, m) or None
        Kalman gain used (consider rows zeroed); None when refused.
    reason : str
        Empty when ok; otherwise why the update was refused.
    """

    innovation: np.ndarray
    S: np.ndarray
    nis: float
    ok: bool
    gain: np.ndarray | None = None
    reason: str = ""


# --------------------------------------------------------------------------------------------
# Prediction
# --------------------------------------------------------------------------------------------

def kf_predict(x, P, F, Q, G=None, u=None, B=None):
    """Linear (or linearised) covariance prediction.

    ``x⁻ = F x (+ B u)``,  ``P⁻ = F P Fᵀ + G Q Gᵀ`` (``G = I`` when omitted), symmetrised.

    Parameters
    ----------
    x : (n,) state; P : (n, n) covariance; F : (n, n) state-transition matrix Φ(t_{k+1}, t_k);
    Q : (q, q) process-noise covariance (discrete); G : (n, q) noise-input matrix, optional;
    u, B : optional known input and its input matrix.

    Returns
    -------
    x_pred : ndarray (n,), P_pred : ndarray (n, n)
    """
    x, P = _check_state(x, P)
    n = x.shape[0]
    F = np.asarray(F, dtype=float)
    if F.shape != (n, n):
        raise ValueError(f"F must have shape ({n}, {n}), got {F.shape}")
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    if G is None:
        if Q.shape != (n, n):
            raise ValueError(f"Q must have shape ({n}, {n}) when G is omitted, got {Q.shape}")
        GQG = Q
    else:
        G = np.asarray(G, dtype=float).reshape(n, -1)
        if Q.shape != (G.shape[1], G.shape[1]):
            raise ValueError(f"Q must have shape {(G.shape[1],) * 2} to match G, got {Q.shape}")
        GQG = G @ Q @ G.T
    x_pred = F @ x
    if u is not None:
        if B is None:
            raise ValueError("u given without its input matrix B")
        x_pred = x_pred + np.asarray(B, dtype=float) @ _as_vector(u, "u")
    return x_pred, symmetrize(F @ P @ F.T + GQG)


# --------------------------------------------------------------------------------------------
# Updates
# --------------------------------------------------------------------------------------------

def _prepare_update(x, P, y, H, R, h):
    x, P = _check_state(x, P)
    n = x.shape[0]
    y = _as_vector(y, "y")
    m = y.shape[0]
    H = _as_matrix_H(H, n, m)
    R = _as_matrix_R(R, m)
    h = H @ x if h is None else _as_vector(h, "h")
    if h.shape != (m,):
        raise ValueError(f"h must have shape ({m},) like y, got {h.shape}")
    return x, P, y, H, R, h


def _refused(x, P, nu, S, reason):
    return x.copy(), P.copy(), UpdateInfo(innovation=nu, S=S, nis=np.nan, ok=False,
                                          gain=None, reason=reason)


def joseph_update(x, P, y, H, R, *, h=None, consider=None):
    """Kalman measurement update with the Joseph-form covariance.

    Parameters
    ----------
    x : array_like (n,)
        Prior state (an error state is simply ``zeros(n)``).
    P : array_like (n, n)
        Prior covariance.
    y : float or array_like (m,)
        Measurement.
    H : array_like (m, n) or (n,) for m = 1
        Measurement Jacobian ∂h/∂x at the prior.
    R : float, array_like (m,) (diagonal) or (m, m)
        Measurement-noise covariance, in measurement units squared.
    h : float or array_like (m,), optional
        Predicted measurement ``h(x)`` of a nonlinear model; defaults to ``H x`` (linear).
    consider : bool mask (n,) or sequence of int, optional
        States treated as *considered* parameters (Schmidt): their gain rows are zero, so they
        are not updated, but their uncertainty enters ``S`` and the cross-covariances.

    Returns
    -------
    x_post : ndarray (n,)
    P_post : ndarray (n, n)
        ``(I − K H) P (I − K H)ᵀ + K R Kᵀ``, symmetrised.
    info : UpdateInfo
        Innovation, S, NIS, gain and the ``ok`` flag. When ``ok`` is False the returned
        ``x_post``, ``P_post`` are copies of the prior.

    The arithmetic is :func:`lightcurve.core.kalman.kalman_gain_nb` and
    :func:`lightcurve.core.kalman.joseph_apply_nb`.
    """
    x, P, y, H, R, h = _prepare_update(x, P, y, H, R, h)
    n = x.shape[0]
    mask = _consider_mask(consider, n)
    mask = np.zeros(n, dtype=np.bool_) if mask is None else mask
    nu = y - h
    x, P, H, R = (np.ascontiguousarray(a) for a in (x, P, H, R))
    K, S, nis, ok = kalman_gain_nb(P, H, R, np.ascontiguousarray(nu), mask)
    if not ok:
        reason = ("non-finite innovation" if not np.all(np.isfinite(nu))
                  else "innovation covariance S is not positive definite")
        return _refused(x, P, nu, S, reason)
    x_new, P_new, ok = joseph_apply_nb(x, P, np.ascontiguousarray(nu), H, R, K)
    if not ok:
        return _refused(x, P, nu, S, "non-finite posterior")
    return x_new, P_new, UpdateInfo(innovation=nu, S=S, nis=float(nis), ok=True, gain=K)


def consider_update(x, P, y, H, R, consider, *, h=None):
    """Schmidt consider update: :func:`joseph_update` with the ``consider`` states frozen.

    The considered states (e.g. a CSS albedo bias in O'Keefe's reduced calibration filter,
    §4.3, or the consider parameters of the sun-line ECKF, §3.2.2) keep their estimate and
    covariance block; their cross-covariances with the estimated states are updated
    consistently (the Joseph form is exact for this sub-optimal gain).
    """
    return joseph_update(x, P, y, H, R, h=h, consider=consider)
