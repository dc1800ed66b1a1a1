"""Numba kernels of the filters' error-state transition (Φ, Q_d) — the hot path of the MEKF and
UKF time updates (one call per measurement step).

Same mathematics as the NumPy reference path in :mod:`lightcurve.filters.models`
(``ControlledDynamics.transition_numpy``, ``UncontrolledDynamics.transition_numpy``,
:func:`~lightcurve.filters.models.error_F`, :func:`~lightcurve.filters.models.discretize`),
which stays as the test oracle (tests/studies/test_studies_speed_kernels.py: agreement to 1e-12).

Conventions: error state ``δx = [δθ (3), δω (3)]`` (body axes, rad and rad/s), ``ω`` body rate
(rad/s), ``J`` inertia (kg m², body axes), ``J_inv`` its inverse, times in s, PSDs in the
units of :class:`~lightcurve.filters.models.UncontrolledDynamics`.

The matrix exponential of the Van Loan block matrix ``M = [[−F, Qc], [0, Fᵀ]] Δt`` is a Taylor
series with scaling and squaring, evaluated block-wise (``M`` is block upper triangular, so
``Mᵏ = [[Xᵏ, Yₖ], [0, Zᵏ]]`` with ``Yₖ = Xᵏ⁻¹ Y + Yₖ₋₁ Z``); the series is summed until the
next term is below 1e-20 in every entry after scaling ``‖M‖₁ ≤ 1/2`` (truncation error far
below the 1e-16 rounding of the result). SciPy's ``expm`` (Padé) gives the same matrix to
rounding.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._kernels import euler_wdot as _wdot   # ω̇ = J⁻¹(−ω × Jω), shared with the particle kernels

__all__ = ["error_F_nb", "van_loan_nb", "uncontrolled_transition_nb",
           "controlled_transition_nb"]


@njit(cache=True)
def _mm(A, B, out):
    """``out = A @ B`` for square matrices of equal size (out must not alias A or B)."""
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += A[i, k] * B[k, j]
            out[i, j] = s


@njit(cache=True)
def _mmt(A, B, out):
    """``out = A @ Bᵀ`` (square, no aliasing)."""
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += A[i, k] * B[j, k]
            out[i, j] = s


@njit(cache=True)
def error_F_nb(w, J, J_inv, uncontrolled, F):
    """Fill ``F`` (6, 6) with the continuous error-dynamics matrix at the rate ``w`` (3,) rad/s.

    ``[[−[ω×], I], [0, Fωω]]``; ``Fωω = J⁻¹([(Jω)×] − [ω×] J)`` (Bernard eq. 7.37, torque free)
    when ``uncontrolled`` is true, else 0 (eq. 7.24). ``J`` and ``J_inv`` are ignored then.
    """
    for i in range(6):
        for j in range(6):
            F[i, j] = 0.0
    F[0, 1] = w[2]
    F[0, 2] = -w[1]
    F[1, 0] = -w[2]
    F[1, 2] = w[0]
    F[2, 0] = w[1]
    F[2, 1] = -w[0]
    for i in range(3):
        F[i, 3 + i] = 1.0
    if uncontrolled:
        h0 = J[0, 0] * w[0] + J[0, 1] * w[1] + J[0, 2] * w[2]
        h1 = J[1, 0] * w[0] + J[1, 1] * w[1] + J[1, 2] * w[2]
        h2 = J[2, 0] * w[0] + J[2, 1] * w[1] + J[2, 2] * w[2]
        S = np.empty((3, 3))
        # S = [h×] − [ω×] J with h = J ω
        Sh = np.array([[0.0, -h2, h1], [h2, 0.0, -h0], [-h1, h0, 0.0]])
        Sw = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
        for i in range(3):
            for j in range(3):
                s = 0.0
                for k in range(3):
                    s += Sw[i, k] * J[k, j]
                S[i, j] = Sh[i, j] - s
        for i in range(3):
            for j in range(3):
                s = 0.0
                for k in range(3):
                    s += J_inv[i, k] * S[k, j]
                F[3 + i, 3 + j] = s


@njit(cache=True)
def van_loan_nb(F, Qc, dt, Phi, Qd):
    """Van Loan discretisation into ``Phi`` = exp(F Δt) and ``Qd`` = ∫₀^Δt Φ(s) Qc Φ(s)ᵀ ds.

    ``F``, ``Qc`` (n, n); ``dt`` s (any sign; ``dt = 0`` gives I and 0). ``Qd`` is symmetrised
    as in :func:`lightcurve.filters.models.discretize`.
    """
    n = F.shape[0]
    if dt == 0.0:
        for i in range(n):
            for j in range(n):
                Phi[i, j] = 1.0 if i == j else 0.0
                Qd[i, j] = 0.0
        return
    X = np.empty((n, n))
    Y = np.empty((n, n))
    Z = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            X[i, j] = -F[i, j] * dt
            Y[i, j] = Qc[i, j] * dt
            Z[i, j] = F[j, i] * dt
    # 1-norm of M (largest column sum) → scaling 2^-s so that ‖M‖₁ ≤ 1/2
    nrm = 0.0
    for j in range(n):
        c1 = 0.0
        c2 = 0.0
        for i in range(n):
            c1 += abs(X[i, j])
            c2 += abs(Y[i, j]) + abs(Z[i, j])
        nrm = max(nrm, c1, c2)
    s = 0
    while nrm > 0.5 and s < 64:
        nrm *= 0.5
        s += 1
    sc = 0.5 ** s
    for i in range(n):
        for j in range(n):
            X[i, j] *= sc
            Y[i, j] *= sc
            Z[i, j] *= sc
    # Taylor series, block-wise: terms TX = Xᵏ/k!, TY = Yₖ/k!, TZ = Zᵏ/k! = (−1)ᵏ TXᵀ
    # (Z = −Xᵀ, so no product is needed for it); with Qc = 0 the Y block stays 0 and only
    # one 6×6 product per term remains
    qzero = True
    for i in range(n):
        for j in range(n):
            if Y[i, j] != 0.0:
                qzero = False
    EX = np.eye(n)
    EY = np.zeros((n, n))
    EZ = np.eye(n)
    TX = np.eye(n)
    TY = np.zeros((n, n))
    NX = np.empty((n, n))
    NY = np.empty((n, n))
    NZ = np.empty((n, n))
    W = np.empty((n, n))
    sign = 1.0
    for k in range(1, 60):
        if not qzero:
            _mm(TX, Y, NY)
            _mm(TY, Z, W)
        _mm(TX, X, NX)
        inv_k = 1.0 / k
        sign = -sign
        big = 0.0
        for i in range(n):
            for j in range(n):
                TX[i, j] = NX[i, j] * inv_k
                EX[i, j] += TX[i, j]
                big = max(big, abs(TX[i, j]))
                if not qzero:
                    TY[i, j] = (NY[i, j] + W[i, j]) * inv_k
                    EY[i, j] += TY[i, j]
                    big = max(big, abs(TY[i, j]))
        for i in range(n):
            for j in range(n):
                EZ[i, j] += sign * TX[j, i]
        if big < 1e-20:
            break
    # squaring: [[A, B], [0, C]]² = [[A², A B + B C], [0, C²]]
    for _ in range(s):
        _mm(EZ, EZ, NZ)
        if not qzero:
            _mm(EX, EY, NY)
            _mm(EY, EZ, W)
            _mm(EX, EX, NX)
        for i in range(n):
            for j in range(n):
                EZ[i, j] = NZ[i, j]
                if not qzero:
                    EX[i, j] = NX[i, j]
                    EY[i, j] = NY[i, j] + W[i, j]
    for i in range(n):
        for j in range(n):
            Phi[i, j] = EZ[j, i]
    _mm(Phi, EY, W)
    for i in range(n):
        for j in range(n):
            Qd[i, j] = 0.5 * (W[i, j] + W[j, i])


@njit(cache=True)
def uncontrolled_transition_nb(w0, J, J_inv, eta_psd, dt, nsub):
    """``(Φ, Q_d)`` (6, 6) of the torque-free error dynamics over ``dt`` s in ``nsub`` sub-steps.

    Same algorithm as :meth:`lightcurve.filters.models.UncontrolledDynamics.transition_numpy`:
    on each sub-step ``h = dt/nsub`` the rate is advanced by RK4; Φ_h, Q_h are the Van Loan
    discretisation of ``F(ω_mid)`` (``ω_mid = ω + h/2 k₂``) with ``Qc = diag(0, 0, 0, η, η, η)``
    (``eta_psd`` rad²/s³); ``Φ ← Φ_h Φ``, ``Q ← Φ_h Q Φ_hᵀ + Q_h``; Q symmetrised at the end.
    """
    Phi = np.eye(6)
    Qd = np.zeros((6, 6))
    if dt == 0.0:
        return Phi, Qd
    h = dt / nsub
    Qc = np.zeros((6, 6))
    for i in range(3, 6):
        Qc[i, i] = eta_psd
    F = np.empty((6, 6))
    Ph = np.empty((6, 6))
    Qh = np.empty((6, 6))
    T1 = np.empty((6, 6))
    T2 = np.empty((6, 6))
    w = np.empty(3)
    for i in range(3):
        w[i] = w0[i]
    k1 = np.empty(3)
    k2 = np.empty(3)
    k3 = np.empty(3)
    k4 = np.empty(3)
    x = np.empty(3)
    wm = np.empty(3)
    for _ in range(nsub):
        _wdot(w, J, J_inv, k1)
        for i in range(3):
            x[i] = w[i] + 0.5 * h * k1[i]
        _wdot(x, J, J_inv, k2)
        for i in range(3):
            wm[i] = w[i] + 0.5 * h * k2[i]
        error_F_nb(wm, J, J_inv, True, F)
        van_loan_nb(F, Qc, h, Ph, Qh)
        _mm(Ph, Phi, T1)
        Phi[:, :] = T1
        _mm(Ph, Qd, T1)
        _mmt(T1, Ph, T2)
        for i in range(6):
            for j in range(6):
                Qd[i, j] = T2[i, j] + Qh[i, j]
        _wdot(wm, J, J_inv, k3)  # wm = w + h/2 k2
        for i in range(3):
            x[i] = w[i] + h * k3[i]
        _wdot(x, J, J_inv, k4)
        for i in range(3):
            w[i] = w[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    out = np.empty((6, 6))
    for i in range(6):
        for j in range(6):
            out[i, j] = 0.5 * (Qd[i, j] + Qd[j, i])
    return Phi, out


@njit(cache=True)
def controlled_transition_nb(w, dt):
    """Closed-form Φ (6, 6) of the constant-rate error dynamics (Bernard eq. 7.24) over ``dt`` s.

    ``Φθθ = exp(−[ω×]Δt)``, ``Φθω = I Δt − (1 − cos φ)/|ω|² [ω×] + (Δt − sin φ/|ω|)/|ω|² [ω×]²``
    (φ = |ω| Δt; series ``I Δt − ½ [ω×] Δt²`` and ``I − [ω×]Δt`` for |ω Δt| < 1e-8), ``Φωω = I``.
    Same branches as :meth:`lightcurve.filters.models.ControlledDynamics.transition_numpy`.
    """
    Phi = np.eye(6)
    S = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    S2 = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            s = 0.0
            for k in range(3):
                s += S[i, k] * S[k, j]
            S2[i, j] = s
    nw = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if nw * abs(dt) < 1e-8:
        for i in range(3):
            for j in range(3):
                e = 1.0 if i == j else 0.0
                Phi[i, j] = e - S[i, j] * dt
                Phi[i, 3 + j] = e * dt - 0.5 * S[i, j] * dt * dt
        return Phi
    phi = nw * dt
    # exp(−[θ×]) with θ = ω Δt (rotations.rotvec_to_dcm, Bernard eq. 3.13): I − s K + c K²,
    # K = [θ×] = Δt S, K² = Δt² S²
    ph = abs(phi)
    if ph > 1e-6:
        sa = np.sin(ph) / ph
        ca = (1.0 - np.cos(ph)) / ph ** 2
    else:
        sa = 1.0 - ph ** 2 / 6.0
        ca = 0.5 - ph ** 2 / 24.0
    a1 = (1.0 - np.cos(phi)) / nw ** 2
    a2 = (dt - np.sin(phi) / nw) / nw ** 2
    for i in range(3):
        for j in range(3):
            e = 1.0 if i == j else 0.0
            Phi[i, j] = e - sa * (S[i, j] * dt) + ca * (S2[i, j] * dt * dt)
            Phi[i, 3 + j] = e * dt - a1 * S[i, j] + a2 * S2[i, j]
    return Phi
