"""NumPy oracles of the error-state transition kernels (test references, not production code).

Plain NumPy/SciPy versions of :func:`lightcurve.core.dynamics.error_F_nb`,
:func:`~lightcurve.core.dynamics.van_loan_nb`,
:func:`~lightcurve.core.dynamics.controlled_transition_nb` and
:func:`~lightcurve.core.dynamics.uncontrolled_transition_nb` (Bernard 2021 eq. 7.24, 7.37; Van
Loan 1978), with SciPy's Padé ``expm`` instead of the kernels' Taylor series.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from lightcurve import rotations as rot


def error_F(omega, J=None):
    """6×6 continuous error-dynamics matrix ``F`` at the rate ``omega`` (rad/s, body axes).

    ``[[−[ω×], I], [0, Fωω]]`` with ``Fωω = 0`` (controlled, Bernard eq. 7.24) or
    ``J⁻¹([(Jω)×] − [ω×] J)`` (torque-free uncontrolled, eq. 7.37) when ``J`` (kg m²) is given.
    """
    w = np.asarray(omega, float).reshape(3)
    F = np.zeros((6, 6))
    F[:3, :3] = -rot.skew(w)
    F[:3, 3:] = np.eye(3)
    if J is not None:
        J = np.asarray(J, float)
        F[3:, 3:] = np.linalg.solve(J, rot.skew(J @ w) - rot.skew(w) @ J)
    return F


def discretize(F, Qc, dt):
    """Van Loan discretisation: ``Φ = exp(F Δt)`` and ``Q_d = ∫₀^Δt Φ(s) Qc Φ(s)ᵀ ds``.

    F (n,n) continuous dynamics, Qc (n,n) continuous process-noise PSD, dt ≥ 0 s.
    """
    n = F.shape[0]
    if dt == 0.0:
        return np.eye(n), np.zeros((n, n))
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -F
    M[:n, n:] = Qc
    M[n:, n:] = F.T
    E = expm(M * dt)
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    return Phi, 0.5 * (Qd + Qd.T)


def controlled_transition_numpy(omega, dt, pseudo_noise=0.0):
    """NumPy reference of ``ControlledDynamics.transition`` (Bernard eq. 7.24; closed form, or
    Van Loan with rate pseudo-noise)."""
    dt = float(dt)
    w = np.asarray(omega, float).reshape(3)
    if pseudo_noise == 0.0:
        Phi = np.eye(6)
        nw = float(np.linalg.norm(w))
        S = rot.skew(w)
        S2 = S @ S
        if nw * abs(dt) < 1e-8:
            Phi[:3, :3] = np.eye(3) - S * dt
            Phi[:3, 3:] = np.eye(3) * dt - 0.5 * S * dt * dt
        else:
            phi = nw * dt
            Phi[:3, :3] = rot.rotvec_to_dcm(w * dt)
            Phi[:3, 3:] = (np.eye(3) * dt - (1.0 - np.cos(phi)) / nw**2 * S
                           + (dt - np.sin(phi) / nw) / nw**2 * S2)
        return Phi, np.zeros((6, 6))
    Qc = np.zeros((6, 6))
    Qc[3:, 3:] = pseudo_noise * np.eye(3)
    return discretize(error_F(w), Qc, dt)


def uncontrolled_transition_numpy(J, eta_psd, substep, omega, dt):
    """NumPy reference of ``UncontrolledDynamics.transition`` (Bernard eq. 7.37 on RK4 sub-steps,
    Van Loan per sub-step with SciPy's ``expm``)."""
    dt = float(dt)
    if dt == 0.0:
        return np.eye(6), np.zeros((6, 6))
    n = max(1, int(np.ceil(abs(dt) / substep)))
    h = dt / n
    Qc = np.zeros((6, 6))
    Qc[3:, 3:] = eta_psd * np.eye(3)
    Phi = np.eye(6)
    Qd = np.zeros((6, 6))
    w = np.asarray(omega, float).reshape(3).copy()
    J = np.asarray(J, float)
    Ji = np.linalg.inv(J)

    def wdot(x):
        return Ji @ (-np.cross(x, J @ x))

    for _ in range(n):
        k1 = wdot(w)
        k2 = wdot(w + 0.5 * h * k1)
        wmid = w + 0.5 * h * k2
        Ph, Qh = discretize(error_F(wmid, J), Qc, h)
        Phi = Ph @ Phi
        Qd = Ph @ Qd @ Ph.T + Qh
        k3 = wdot(w + 0.5 * h * k2)
        k4 = wdot(w + h * k3)
        w = w + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return Phi, 0.5 * (Qd + Qd.T)
