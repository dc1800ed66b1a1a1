"""Linearised attitude error dynamics ``F`` (Bernard 2021 eq. 7.24, 7.37 and appendix A); the
torques' attitude partials are defined next to the torques (:mod:`lightcurve.dynamics.torques`)
and re-exported here.

Error state ``δx = [δθ (3), δω (3)]``: ``δθ`` is the small rotation (rad, body axes) with
``q_true = δq(δθ) ⊗ q̂``, ``δq ≈ [1, δθ/2]`` (so ``A(q_true) ≈ (I − [δθ×]) A(q̂)``), and
``δω = ω_true − ω̂`` (rad/s, body axes). To first order ``δẋ = F δx`` with

* controlled model (constant rate, Bernard eq. 7.24)::

      F = [[−[ω̂×], I],
           [   0 ,  0]]

* uncontrolled model (Euler's equations + torques, Bernard eq. 7.37, appendix A)::

      F = [[−[ω̂×],                         I                    ],
           [J⁻¹ ∂T/∂δθ,   J⁻¹([(Jω̂)×] − [ω̂×] J) + J⁻¹ ∂T/∂δω]]

  (the environmental torques here do not depend on ω, so ``∂T/∂δω = 0`` for them).

Derivation of the attitude block: ``δq = q ⊗ q̂⁻¹`` obeys ``δq̇ = ½ (ω ⊗ δq − δq ⊗ ω̂)`` (pure
quaternions); to first order its vector part gives ``δθ̇ = −ω̂ × δθ + δω``. A body-frame vector
``u_b = A(q) u_I`` varies as ``∂u_b/∂δθ = [u_b×]``; this gives the torque partials:

* gravity gradient (``u = r̂_b``, ``k = 3μ/|r|³``): ``∂T/∂δθ = k ([u×] J − [(J u)×]) [u×]``;
* SRP: ``∂T/∂δθ = Σ_lit [c_i×] ∂F_i/∂ŝ [ŝ×]`` with
  ``∂F_i/∂ŝ = −P A_i [(1 − C_s)(ŝ n̂ᵀ + cos θ I) + 2 (2 C_s cos θ + C_d/3) n̂ n̂ᵀ]``;
* drag: ``∂T/∂δθ = Σ_wetted [c_i×] ∂F_i/∂v [v_b×]`` with
  ``∂F_i/∂v = −½ ρ C_D A_i (v_b n̂ᵀ + (n̂·v_b) I)`` (from ``F_i = −½ ρ C_D A_i (n̂·v_b) v_b``).

All are verified against central finite differences of the nonlinear model in the tests. The
facet torques have kinks where a facet's ``n̂·ŝ`` or ``n̂·v`` crosses zero; there the one-sided
derivative of the lit/wetted set is returned.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from .. import rotations as rot
from ..core.dynamics import error_F_nb
from . import _checks as ck
from .rigid_body import check_inertia, euler_omega_dot
from .torques import drag_torque_jacobian, gravity_gradient_jacobian, srp_torque_jacobian

__all__ = [
    "gravity_gradient_jacobian",
    "srp_torque_jacobian",
    "drag_torque_jacobian",
    "controlled_F",
    "uncontrolled_F",
    "uncontrolled_F_models",
    "nonlinear_error_rate",
    "transition_matrix",
    "acs_noise_covariance",
    "eta_noise_covariance",
]


def controlled_F(omega) -> np.ndarray:
    """6×6 error-dynamics matrix of the controlled (constant-rate) model (Bernard eq. 7.24).

    ``[[−[ω×], I], [0, 0]]`` for the state ``[δθ, δω]``; ``omega`` is the body rate (rad/s, body
    axes). The attitude-only model (rate known) is the upper-left block ``−[ω×]``.
    """
    w = ck.single_vec(omega, "omega")
    F = np.empty((6, 6))
    error_F_nb(np.ascontiguousarray(w), np.eye(3), np.eye(3), False, F)
    return F


def uncontrolled_F(omega, J, dT_dtheta=None, dT_domega=None, J_inv=None) -> np.ndarray:
    """6×6 error-dynamics matrix of the uncontrolled model (Bernard eq. 7.37, appendix A).

    Parameters
    ----------
    omega : array (3,)
        Estimated body rate, rad/s, body axes.
    J : array (3, 3)
        Inertia, kg m², body axes.
    dT_dtheta : array (3, 3), optional
        Attitude partial of the total external torque, N m/rad (e.g. from
        :func:`gravity_gradient_jacobian`); default zero (torque-free).
    dT_domega : array (3, 3), optional
        Rate partial of the torque, N m s/rad; default zero.
    """
    w = ck.single_vec(omega, "omega")
    J = check_inertia(J)
    Ji = np.linalg.inv(J) if J_inv is None else np.asarray(J_inv, dtype=float)
    F = np.empty((6, 6))
    error_F_nb(np.ascontiguousarray(w), np.ascontiguousarray(J), np.ascontiguousarray(Ji), True, F)
    if dT_domega is not None:
        F[3:, 3:] += Ji @ np.asarray(dT_domega, dtype=float).reshape(3, 3)
    if dT_dtheta is not None:
        F[3:, :3] = Ji @ np.asarray(dT_dtheta, dtype=float).reshape(3, 3)
    return F


def uncontrolled_F_models(t, q, omega, J, torque_models=()) -> np.ndarray:
    """:func:`uncontrolled_F` with ``∂T/∂δθ`` summed from torque models' ``dtheta(t, q, omega)``."""
    q = ck.single_quat(q)
    dT = np.zeros((3, 3))
    for m in torque_models:
        dT = dT + np.asarray(m.dtheta(t, q, omega), dtype=float)
    return uncontrolled_F(omega, J, dT_dtheta=dT)


def nonlinear_error_rate(dx, q_hat, omega_hat, J=None, torque_fn=None, t: float = 0.0) -> np.ndarray:
    """Exact (nonlinear) rate of the error state, for checking ``F`` by finite differences.

    The true state is ``q = exp(δθ) ⊗ q̂``, ``ω = ω̂ + δω``; both true and estimated states move
    with the nonlinear model (Euler's equations with ``torque_fn(t, q, ω)`` when ``J`` is given,
    otherwise constant rate). The attitude error is charted as ``p = 2 δq_v`` with
    ``δq = q ⊗ q̂⁻¹``, which agrees with ``δθ`` to first order, so ``∂(ṗ, δω̇)/∂δx`` at 0 is ``F``.
    Returns ``[ṗ (3), δω̇ (3)]``.
    """
    dx = np.asarray(dx, dtype=float)
    q_hat = ck.single_quat(q_hat, "q_hat")
    w_hat = ck.single_vec(omega_hat, "omega_hat")
    q = rot.quat_mult(rot.rotvec_to_quat(dx[:3]), q_hat)
    w = w_hat + dx[3:]

    def qdot(qq, ww):
        return 0.5 * rot.quat_mult(np.concatenate([[0.0], ww]), qq)

    def wdot(qq, ww):
        if J is None:
            return np.zeros(3)
        T = np.zeros(3) if torque_fn is None else np.asarray(torque_fn(t, qq, ww), dtype=float)
        return euler_omega_dot(ww, J, T)

    qd, qhd = qdot(q, w), qdot(q_hat, w_hat)
    dqd = rot.quat_mult(qd, rot.quat_conj(q_hat)) + rot.quat_mult(q, rot.quat_conj(qhd))
    return np.concatenate([2.0 * dqd[1:], wdot(q, w) - wdot(q_hat, w_hat)])


def transition_matrix(F, dt: float) -> np.ndarray:
    """Discrete state-transition matrix ``Φ = exp(F Δt)`` (``F`` held constant over ``Δt`` s)."""
    F = np.asarray(F, dtype=float)
    if F.ndim != 2 or F.shape[0] != F.shape[1] or not np.all(np.isfinite(F)):
        raise ValueError(f"F: expected a finite square matrix, got shape {F.shape}")
    return expm(F * ck.finite_scalar(dt, "dt"))


def acs_noise_covariance(acs_sigma_rad: float, with_rate: bool = True) -> np.ndarray:
    """Covariance of the ACS noise ζ applied at a measurement time (controlled model).

    ζ is a rotation vector with independent N(0, σ²) components (rad, body axes); returns
    ``σ² I₃`` (or the 6×6 ``diag(σ² I₃, 0)`` for the state ``[δθ, δω]`` when ``with_rate``).
    """
    s = ck.finite_scalar(acs_sigma_rad, "acs_sigma_rad", nonneg=True)
    Q = np.zeros((6, 6)) if with_rate else np.zeros((3, 3))
    Q[:3, :3] = s * s * np.eye(3)
    return Q


def eta_noise_covariance(dt: float, eta_sigma: float, kind: str = "piecewise_constant") -> np.ndarray:
    """6×6 discrete covariance of ``[δθ, δω]`` from angular-acceleration noise η over ``dt`` s.

    ``kind="piecewise_constant"``: η is constant over the interval, ``η ~ N(0, σ² I)`` with σ
    in rad/s², so ``δω = η Δt``, ``δθ = η Δt²/2``:
    ``Q = σ² [[Δt⁴/4, Δt³/2], [Δt³/2, Δt²]] ⊗ I₃``.
    ``kind="continuous"``: η is white with power spectral density σ² (σ in rad/s^{3/2}):
    ``Q = σ² [[Δt³/3, Δt²/2], [Δt²/2, Δt]] ⊗ I₃``.
    Both neglect the rotation of the error by ``−[ω×]`` within the interval.
    """
    dt = ck.finite_scalar(dt, "dt", nonneg=True)
    s2 = ck.finite_scalar(eta_sigma, "eta_sigma", nonneg=True) ** 2
    if kind == "piecewise_constant":
        B = np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
    elif kind == "continuous":
        B = np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    else:
        raise ValueError(f"kind: expected 'piecewise_constant' or 'continuous', got {kind!r}")
    return s2 * np.kron(B, np.eye(3))
