"""Kalman-filter linear algebra on plain float64 arrays (numba kernels, no validation).

* :func:`cholesky_nb` — lower Cholesky factor with a failure flag (never raises, never NaN);
* :func:`inverse_nb` — Gauss–Jordan inverse with partial pivoting and a failure flag;
* :func:`spd_solve_nb`, :func:`spd_inverse_nb` — solves with a symmetric positive-definite
  matrix through its Cholesky factor;
* :func:`joseph_update_nb` — vector measurement update, Joseph-form covariance, optional
  Schmidt consider states;
* :func:`joseph_scalar_nb` — the same for one scalar measurement in O(n²) (fast path);
* :func:`consider_update_nb` — the Schmidt consider update in block form, with consider
  parameters that also enter the measurement (O'Keefe 2015 eq. 3.47–3.52);
* :func:`symmetrize_nb`.

Conventions: ``x`` (n,) state, ``P`` (n, n) covariance; ``ν = y − h(x)`` (m,) innovation,
``H`` (m, n) Jacobian ∂h/∂x, ``R`` (m, m) measurement noise; ``S = H P Hᵀ + R``,
``K = P Hᵀ S⁻¹``; Joseph form ``P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`` (Bucy & Joseph 1968;
Bar-Shalom, Li & Kirubarajan 2001 §5.2.3), valid for any gain — which is what makes the
Schmidt consider update exact: the gain rows of considered states are set to zero (O'Keefe 2015
§3.2.2, §4.3; Woodbury & Junkins 2010). Every returned covariance is symmetrised.

Failure path (DESIGN.md "Numerics"): a non-finite innovation, an ``S`` that is not positive
definite, or a non-finite posterior returns the prior unchanged with ``ok = False`` (or a
non-zero status): the caller flags the step; never a silent NaN.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "cholesky_nb", "forward_nb", "backward_nb", "spd_solve_nb", "spd_inverse_nb", "inverse_nb",
    "symmetrize_nb", "kalman_gain_nb", "joseph_apply_nb", "joseph_update_nb", "joseph_scalar_nb",
    "consider_update_nb", "UPDATE_OK", "UPDATE_BAD_INNOVATION", "UPDATE_BAD_S",
    "UPDATE_BAD_POSTERIOR",
]

UPDATE_OK = 0
"""Status of :func:`joseph_scalar_nb`: update applied."""
UPDATE_BAD_INNOVATION = 1
"""Status: non-finite innovation (prior kept)."""
UPDATE_BAD_S = 2
"""Status: innovation covariance not positive (or not finite) (prior kept)."""
UPDATE_BAD_POSTERIOR = 3
"""Status: non-finite posterior (prior kept)."""


@njit(cache=True)
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


@njit(cache=True)
def forward_nb(L, b):
    """Solve ``L z = b`` for lower-triangular ``L`` (n, n), b (n,) → z (n,)."""
    n = L.shape[0]
    z = np.empty(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * z[k]
        z[i] = s / L[i, i]
    return z


@njit(cache=True)
def backward_nb(L, z):
    """Solve ``Lᵀ v = z`` for lower-triangular ``L`` (n, n), z (n,) → v (n,)."""
    n = L.shape[0]
    v = np.empty(n)
    for i in range(n - 1, -1, -1):
        s = z[i]
        for k in range(i + 1, n):
            s -= L[k, i] * v[k]
        v[i] = s / L[i, i]
    return v


@njit(cache=True)
def spd_solve_nb(A, B):
    """``A⁻¹ B`` for symmetric positive-definite ``A`` (n, n) and ``B`` (n, k) through the
    Cholesky factor → ``(X, ok)``; ``ok`` False (X zero) when ``A`` is not positive definite."""
    n = A.shape[0]
    L, ok = cholesky_nb(A)
    X = np.zeros((n, B.shape[1]))
    if not ok:
        return X, False
    for c in range(B.shape[1]):
        X[:, c] = backward_nb(L, forward_nb(L, B[:, c].copy()))
    return X, True


@njit(cache=True)
def spd_inverse_nb(A):
    """Inverse of a symmetric positive-definite ``A`` (Cholesky) → ``(A⁻¹, ok)``, symmetrised."""
    X, ok = spd_solve_nb(A, np.eye(A.shape[0]))
    if ok:
        symmetrize_nb(X)
    return X, ok


@njit(cache=True)
def inverse_nb(A):
    """Inverse of a square matrix by Gauss–Jordan elimination with partial pivoting.

    Returns ``(A⁻¹, ok)``; ``ok`` is False (and the first output undefined) when a pivot is
    below 1e-14 times the largest absolute entry of A (numerically singular) or A is zero.
    For the small matrices of the filters (n ≤ ~20) this is accurate and cheap to compile.
    """
    n = A.shape[0]
    M = A.copy()
    X = np.eye(n)
    scale = 0.0
    for i in range(n):
        for j in range(n):
            if abs(M[i, j]) > scale:
                scale = abs(M[i, j])
    if scale == 0.0:
        return X, False
    for c in range(n):
        p = c
        best = abs(M[c, c])
        for r in range(c + 1, n):
            if abs(M[r, c]) > best:
                best = abs(M[r, c])
                p = r
        if best <= 1e-14 * scale:
            return X, False
        if p != c:
            for j in range(n):
                tmp = M[c, j]
                M[c, j] = M[p, j]
                M[p, j] = tmp
                tmp = X[c, j]
                X[c, j] = X[p, j]
                X[p, j] = tmp
        piv = M[c, c]
        for j in range(n):
            M[c, j] /= piv
            X[c, j] /= piv
        for r in range(n):
            if r != c:
                f = M[r, c]
                if f != 0.0:
                    for j in range(n):
                        M[r, j] -= f * M[c, j]
                        X[r, j] -= f * X[c, j]
    return X, True


@njit(cache=True)
def symmetrize_nb(P):
    """In place ``P ← (P + Pᵀ)/2``."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i):
            a = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = a
            P[j, i] = a


@njit(cache=True)
def kalman_gain_nb(P, H, R, nu, consider):
    """Gain of a measurement update → ``(K (n,m), S (m,m), nis, ok)`` (Bernard eq. 7.30, 6.13).

    ``S = H P Hᵀ + R`` (symmetrised), ``K = P Hᵀ S⁻¹`` through the Cholesky factor of S, rows
    of ``consider`` states (bool (n,)) zeroed (Schmidt), ``nis = νᵀ S⁻¹ ν``. ``ok`` False (K
    zero, nis NaN) for a non-finite innovation or an S that is not positive definite.
    """
    n = P.shape[0]
    m = nu.shape[0]
    PHt = P @ H.T
    S = H @ PHt + R
    for i in range(m):
        for j in range(i):
            a = 0.5 * (S[i, j] + S[j, i])
            S[i, j] = a
            S[j, i] = a
    K = np.zeros((n, m))
    for i in range(m):
        if not np.isfinite(nu[i]):
            return K, S, np.nan, False
    L, ok = cholesky_nb(S)
    if not ok:
        return K, S, np.nan, False
    for r in range(n):
        kr = backward_nb(L, forward_nb(L, PHt[r, :].copy()))
        for c in range(m):
            K[r, c] = 0.0 if consider[r] else kr[c]
    w = forward_nb(L, nu)
    nis = 0.0
    for i in range(m):
        nis += w[i] * w[i]
    return K, S, nis, True


@njit(cache=True)
def joseph_apply_nb(x, P, nu, H, R, K):
    """``x⁺ = x + K ν`` and ``P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`` (Bernard eq. 7.31, 7.33;
    symmetrised) for any gain
    → ``(x⁺, P⁺, ok)``; ``ok`` False (prior copies returned) when the posterior is not finite."""
    n = x.shape[0]
    IKH = np.eye(n) - K @ H
    Pn = IKH @ P @ IKH.T + K @ R @ K.T
    xn = x + K @ nu
    for i in range(n):
        if not np.isfinite(xn[i]):
            return x.copy(), P.copy(), False
        for j in range(n):
            if not np.isfinite(Pn[i, j]):
                return x.copy(), P.copy(), False
    symmetrize_nb(Pn)
    return xn, Pn, True


@njit(cache=True)
def joseph_update_nb(x, P, nu, H, R, consider):
    """Kalman measurement update, Joseph-form covariance (Bernard eq. 7.30–7.33), optional
    Schmidt consider states (O'Keefe §3.2.2) — :func:`kalman_gain_nb` then
    :func:`joseph_apply_nb`.

    Parameters
    ----------
    x (n,) prior state, P (n, n) prior covariance, nu (m,) innovation ``y − h(x)``,
    H (m, n) Jacobian, R (m, m) measurement noise, consider (n,) bool: states whose gain row
    is zeroed (not updated; their uncertainty still enters S and the cross-covariances).

    Returns
    -------
    x_post (n,), P_post (n, n), nis ``νᵀ S⁻¹ ν`` (NaN when refused), ok (bool). On failure
    ``x_post`` and ``P_post`` are copies of the prior.
    """
    K, S, nis, ok = kalman_gain_nb(P, H, R, nu, consider)
    if not ok:
        return x.copy(), P.copy(), np.nan, False
    xn, Pn, ok = joseph_apply_nb(x, P, nu, H, R, K)
    if not ok:
        return xn, Pn, np.nan, False
    return xn, Pn, nis, True


@njit(cache=True)
def joseph_scalar_nb(P, H, R, nu, dx, Pn):
    """Joseph-form update (Bernard eq. 7.30–7.33) of ONE scalar measurement from a zero prior
    error state, in O(n²).

    P (n,n) prior covariance, H (n,) measurement row, R > 0 noise variance, ``nu = y − ŷ``.
    ``S = H P Hᵀ + R``, ``K = P Hᵀ / S``, ``δx⁺ = K ν`` into ``dx`` (n,) and
    ``P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`` into ``Pn`` (n,n), evaluated as
    ``B − (B Hᵀ) Kᵀ + R K Kᵀ`` with ``B = P − K (H P)`` (the same product), symmetrised. The
    algebra of :func:`joseph_update_nb` for m = 1 without its matrix products.

    Returns ``(S, status)``: :data:`UPDATE_OK`, :data:`UPDATE_BAD_INNOVATION`,
    :data:`UPDATE_BAD_S` or :data:`UPDATE_BAD_POSTERIOR` (then dx, Pn are undefined and the
    caller keeps the prior).
    """
    n = P.shape[0]
    PHt = np.zeros(n)
    HP = np.zeros(n)
    for j in range(n):
        hj = H[j]
        if hj != 0.0:
            for i in range(n):
                PHt[i] += P[i, j] * hj
                HP[i] += hj * P[j, i]
    hph = 0.0
    for i in range(n):
        hph += H[i] * PHt[i]
    S = hph + R
    if not math.isfinite(nu):
        return S, UPDATE_BAD_INNOVATION
    if not (S > 0.0 and math.isfinite(S)):
        return S, UPDATE_BAD_S
    Kg = PHt / S
    # B Hᵀ = P Hᵀ − K (H P Hᵀ)
    BH = PHt - Kg * hph
    bad = False
    for i in range(n):
        for j in range(n):
            Pn[i, j] = P[i, j] - Kg[i] * HP[j] - BH[i] * Kg[j] + R * Kg[i] * Kg[j]
    for i in range(n):
        dx[i] = Kg[i] * nu
        if not math.isfinite(dx[i]):
            bad = True
        for j in range(i + 1):
            v = 0.5 * (Pn[i, j] + Pn[j, i])
            Pn[i, j] = v
            Pn[j, i] = v
            if not math.isfinite(v):
                bad = True
    return S, UPDATE_BAD_POSTERIOR if bad else UPDATE_OK


@njit(cache=True)
def _matmul(A, B):
    """``A @ B`` by loops (any layout; the small matrices of the filters)."""
    out = np.zeros((A.shape[0], B.shape[1]))
    for i in range(A.shape[0]):
        for k in range(A.shape[1]):
            a = A[i, k]
            if a != 0.0:
                for j in range(B.shape[1]):
                    out[i, j] += a * B[k, j]
    return out


@njit(cache=True)
def consider_update_nb(x, P, C, B, nu, H, J, R, joseph):
    """Schmidt consider update in block form (O'Keefe 2015 §3.2.2.2, eq. 3.47–3.52; Woodbury
    & Junkins 2010).

    Estimated state ``x`` (n,) with covariance ``P`` (n, n); consider parameters β (p,), not
    estimated (their estimate stays), with covariance ``B`` (p, p) and cross-covariance
    ``C = E[δx δβᵀ]`` (n, p). Measurement ``y = h(x, β) + v``: innovation ``nu`` (m,),
    ``H = ∂h/∂x`` (m, n), ``J = ∂h/∂β`` (m, p), noise ``R`` (m, m)::

        W  = H P Hᵀ + H C Jᵀ + J Cᵀ Hᵀ + J B Jᵀ + R                     (eq. 3.47)
        K  = (P Hᵀ + C Jᵀ) W⁻¹                                           (eq. 3.51)
        x⁺ = x + K ν,   C⁺ = (I − K H) C − K J B                         (eq. 3.52)
        P⁺ = P − K W Kᵀ                                                  (eq. 3.52)

    or, with ``joseph`` true, the Joseph form of the same update, valid for any gain:
    ``P⁺ = (I − KH) P (I − KH)ᵀ − (I − KH) C Jᵀ Kᵀ − K J Cᵀ (I − KH)ᵀ + K (J B Jᵀ + R) Kᵀ``.
    ``B`` is unchanged. With ``J = 0`` this is :func:`joseph_update_nb` on the augmented
    state ``[x, β]`` with β as consider states (gain rows zero), written without the
    augmented matrices; with ``p = 0`` it is the plain Kalman update.

    Returns ``(x⁺, P⁺, C⁺, nis, ok)`` with ``nis = νᵀ W⁻¹ ν``; on failure (non-finite
    innovation, ``W`` not positive definite, non-finite posterior) copies of the prior and
    ``nis`` NaN, ``ok`` False. ``W`` is solved through its Cholesky factor; ``P⁺`` is
    symmetrised.
    """
    n = x.shape[0]
    p = B.shape[0]
    m = nu.shape[0]
    for i in range(m):
        if not np.isfinite(nu[i]):
            return x.copy(), P.copy(), C.copy(), np.nan, False
    CJt = _matmul(C, J.T)                       # C Jᵀ (n, m)
    A = _matmul(P, H.T) + CJt                   # P Hᵀ + C Jᵀ (n, m)
    HC = _matmul(H, C)                          # (m, p)
    JB = _matmul(J, B)                          # (m, p)
    V = _matmul(JB, J.T) + R                    # J B Jᵀ + R (m, m)
    W = _matmul(H, A) + _matmul(J, HC.T) + V    # eq. 3.47
    symmetrize_nb(W)
    L, ok = cholesky_nb(W)
    if not ok:
        return x.copy(), P.copy(), C.copy(), np.nan, False
    K = np.empty((n, m))
    for r in range(n):
        K[r, :] = backward_nb(L, forward_nb(L, A[r, :].copy()))
    w = forward_nb(L, nu)
    nis = 0.0
    for a in range(m):
        nis += w[a] * w[a]
    xn = x.copy()
    for i in range(n):
        for a in range(m):
            xn[i] += K[i, a] * nu[a]
    IKH = np.eye(n) - _matmul(K, H)
    Cn = _matmul(IKH, C) - _matmul(K, JB)      # eq. 3.52b-c
    if joseph:
        T = _matmul(IKH, CJt)
        Pn = (_matmul(_matmul(IKH, P), IKH.T) - _matmul(T, K.T) - _matmul(K, T.T)
              + _matmul(_matmul(K, V), K.T))
    else:
        Pn = P - _matmul(_matmul(K, W), K.T)    # eq. 3.52a
    for i in range(n):
        if not np.isfinite(xn[i]):
            return x.copy(), P.copy(), C.copy(), np.nan, False
        for j in range(n):
            if not np.isfinite(Pn[i, j]):
                return x.copy(), P.copy(), C.copy(), np.nan, False
        for k in range(p):
            if not np.isfinite(Cn[i, k]):
                return x.copy(), P.copy(), C.copy(), np.nan, False
    symmetrize_nb(Pn)
    return xn, Pn, Cn, nis, True
