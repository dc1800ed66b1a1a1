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

The ``*_nb`` functions are ``numba.njit(cache=True)`` kernels with the same algebra on plain
float64 arrays, for filters whose whole trajectory loop is compiled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy.linalg import solve_triangular

__all__ = [
    "UpdateInfo",
    "symmetrize",
    "safe_cholesky",
    "kf_predict",
    "joseph_update",
    "standard_update",
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
    try:
        L = np.linalg.cholesky(0.5 * (P + P.T))
    except np.linalg.LinAlgError:
        return None, False
    if not np.all(np.isfinite(L)) or np.any(np.diag(L) <= 0.0):
        return None, False
    return L, True


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


def _gain(P, H, R, nu):
    """Shared part of every update: S, its Cholesky factor, K, NIS (or a refusal reason)."""
    S = H @ P @ H.T + R
    S = 0.5 * (S + S.T)
    if not np.all(np.isfinite(nu)):
        return S, None, np.nan, "non-finite innovation"
    L, ok = safe_cholesky(S)
    if not ok:
        return S, None, np.nan, "innovation covariance S is not positive definite"
    PHt = P @ H.T
    if L.shape[0] == 1:
        # scalar measurement (a magnitude, one CSS voltage): the triangular solves are two
        # divisions. Same arithmetic as the general branch; it avoids SciPy's BLAS call, whose
        # thread-pool wake-up costs milliseconds per 1×1 solve on a loaded machine.
        ell = L[0, 0]
        return S, (PHt / ell) / ell, float((nu[0] / ell) ** 2), ""
    # K = P Hᵀ S⁻¹, from S Kᵀ = H P  (two triangular solves with L)
    Kt = solve_triangular(L.T, solve_triangular(L, PHt.T, lower=True), lower=False)
    w = solve_triangular(L, nu, lower=True)
    return S, Kt.T, float(w @ w), ""


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
    """
    x, P, y, H, R, h = _prepare_update(x, P, y, H, R, h)
    mask = _consider_mask(consider, x.shape[0])
    nu = y - h
    S, K, nis, reason = _gain(P, H, R, nu)
    if K is None:
        return _refused(x, P, nu, S, reason)
    if mask is not None:
        K = K.copy()
        K[mask, :] = 0.0
    IKH = np.eye(x.shape[0]) - K @ H
    P_new = IKH @ P @ IKH.T + K @ R @ K.T
    P_new = 0.5 * (P_new + P_new.T)
    x_new = x + K @ nu
    if not (np.all(np.isfinite(x_new)) and np.all(np.isfinite(P_new))):
        return _refused(x, P, nu, S, "non-finite posterior")
    return x_new, P_new, UpdateInfo(innovation=nu, S=S, nis=nis, ok=True, gain=K)


def consider_update(x, P, y, H, R, consider, *, h=None):
    """Schmidt consider update: :func:`joseph_update` with the ``consider`` states frozen.

    The considered states (e.g. a CSS albedo bias in O'Keefe's reduced calibration filter,
    §4.3, or the consider parameters of the sun-line ECKF, §3.2.2) keep their estimate and
    covariance block; their cross-covariances with the estimated states are updated
    consistently (the Joseph form is exact for this sub-optimal gain).
    """
    return joseph_update(x, P, y, H, R, h=h, consider=consider)


def standard_update(x, P, y, H, R, *, h=None):
    """Kalman update with the short covariance form ``P⁺ = (I − K H) P`` (symmetrised).

    Equal to the Joseph form for the optimal gain (Bar-Shalom et al. 2001 §5.2.3); less robust
    to round-off. Kept as a reference for tests and for speed comparisons. Same returns and
    failure path as :func:`joseph_update`.
    """
    x, P, y, H, R, h = _prepare_update(x, P, y, H, R, h)
    nu = y - h
    S, K, nis, reason = _gain(P, H, R, nu)
    if K is None:
        return _refused(x, P, nu, S, reason)
    P_new = (np.eye(x.shape[0]) - K @ H) @ P
    P_new = 0.5 * (P_new + P_new.T)
    x_new = x + K @ nu
    if not (np.all(np.isfinite(x_new)) and np.all(np.isfinite(P_new))):
        return _refused(x, P, nu, S, "non-finite posterior")
    return x_new, P_new, UpdateInfo(innovation=nu, S=S, nis=nis, ok=True, gain=K)


# --------------------------------------------------------------------------------------------
# Numba kernels
# --------------------------------------------------------------------------------------------

@numba.njit(cache=True)
def cholesky_nb(A):
    """Lower Cholesky factor of symmetric ``A`` (n, n) → ``(L, ok)``; never raises.

    Uses only the lower triangle of ``A``. ``ok`` is False (and ``L`` zero) when a pivot is
    not strictly positive or not finite.
    """
    n = A.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not (s > 0.0) or not np.isfinite(s):
            return np.zeros((n, n)), False
        d = np.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / d
    return L, True


@numba.njit(cache=True)
def _forward_nb(L, b):
    n = L.shape[0]
    z = np.empty(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * z[k]
        z[i] = s / L[i, i]
    return z


@numba.njit(cache=True)
def _backward_nb(L, z):
    # solves Lᵀ v = z
    n = L.shape[0]
    v = np.empty(n)
    for i in range(n - 1, -1, -1):
        s = z[i]
        for k in range(i + 1, n):
            s -= L[k, i] * v[k]
        v[i] = s / L[i, i]
    return v


@numba.njit(cache=True)
def joseph_update_nb(x, P, nu, H, R, consider):
    """Compiled Joseph-form update on plain float64 arrays.

    Parameters
    ----------
    x (n,), P (n, n), nu (m,) innovation ``y − h``, H (m, n), R (m, m),
    consider (n,) boolean: states whose gain row is zeroed (all False for a plain update).

    Returns
    -------
    x_post (n,), P_post (n, n), nis (float, NaN when refused), ok (bool).
    On failure ``x_post`` and ``P_post`` are copies of the prior.
    """
    n = x.shape[0]
    m = nu.shape[0]
    PHt = P @ H.T
    S = H @ PHt + R
    for i in range(m):
        for j in range(i):
            a = 0.5 * (S[i, j] + S[j, i])
            S[i, j] = a
            S[j, i] = a
    finite = True
    for i in range(m):
        if not np.isfinite(nu[i]):
            finite = False
    if not finite:
        return x.copy(), P.copy(), np.nan, False
    L, ok = cholesky_nb(S)
    if not ok:
        return x.copy(), P.copy(), np.nan, False
    K = np.empty((n, m))
    for r in range(n):
        kr = _backward_nb(L, _forward_nb(L, PHt[r, :].copy()))
        for c in range(m):
            K[r, c] = 0.0 if consider[r] else kr[c]
    w = _forward_nb(L, nu)
    nis = 0.0
    for i in range(m):
        nis += w[i] * w[i]
    IKH = np.eye(n) - K @ H
    Pn = IKH @ P @ IKH.T + K @ R @ K.T
    xn = x + K @ nu
    for i in range(n):
        if not np.isfinite(xn[i]):
            return x.copy(), P.copy(), np.nan, False
        for j in range(n):
            if not np.isfinite(Pn[i, j]):
                return x.copy(), P.copy(), np.nan, False
    for i in range(n):
        for j in range(i):
            a = 0.5 * (Pn[i, j] + Pn[j, i])
            Pn[i, j] = a
            Pn[j, i] = a
    return xn, Pn, nis, True
