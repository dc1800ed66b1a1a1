"""Rigid-body rotational dynamics: Euler's equations (Bernard 2021 eq. 4.13).

    J ω̇ = −ω × (J ω) + T

with ``J`` the inertia tensor about the centre of mass in body axes (kg m²), ``ω`` the body
angular velocity in body axes (rad/s) and ``T`` the external torque in body axes (N m).
The full attitude state is ``x = [q (4), ω (3)]`` with ``q`` scalar first, inertial→body; its
derivative is ``[½ [0, ω] ⊗ q, ω̇]`` (eq. 4.12–4.13).

Conserved quantities of torque-free motion (used by the tests): the inertial angular momentum
``H_I = A(q)ᵀ J ω`` and the rotational kinetic energy ``E = ½ ωᵀ J ω``.
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot
from ..core.dynamics import omega_dot_batch_nb, quat_rate_batch_nb
from .kinematics import check_omega

__all__ = [
    "check_inertia",
    "euler_omega_dot",
    "state_derivative",
    "angular_momentum_inertial",
    "rotational_energy",
]


def check_inertia(J, name: str = "J") -> np.ndarray:
    """Validate an inertia tensor (kg m², body axes) and return it as a (3, 3) float array.

    Raises ``ValueError`` for a wrong shape, NaN/inf, asymmetry (relative 1e-9) or a matrix
    that is not positive definite. A length-3 vector is taken as the principal moments.
    """
    try:
        a = np.asarray(J, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a 3x3 inertia matrix of numbers") from None
    if a.shape == (3,):
        a = np.diag(a)
    if a.shape != (3, 3):
        raise ValueError(f"{name}: expected shape (3, 3) or (3,) principal moments, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    scale = np.max(np.abs(a))
    if scale == 0 or np.max(np.abs(a - a.T)) > 1e-9 * scale:
        raise ValueError(f"{name}: inertia matrix must be symmetric and nonzero")
    ev = np.linalg.eigvalsh(a)
    if ev[0] <= 1e-12 * ev[-1]:
        raise ValueError(f"{name}: inertia matrix is not positive definite (eigenvalues {ev})")
    return a


def euler_omega_dot(omega, J, torque=None, J_inv=None):
    """Angular acceleration ``ω̇ = J⁻¹(−ω × Jω + T)`` (rad/s², body axes; Bernard eq. 4.13).

    Parameters
    ----------
    omega : array (..., 3)
        Body rate in body axes, rad/s.
    J : array (3, 3)
        Inertia tensor about the centre of mass, body axes, kg m².
    torque : array (..., 3), optional
        External torque in body axes, N m (default zero).
    J_inv : array (3, 3), optional
        Precomputed inverse of ``J`` (not re-validated).
    """
    J = check_inertia(J)
    w = check_omega(omega)
    Ji = np.linalg.inv(J) if J_inv is None else np.asarray(J_inv, dtype=float)
    T = np.zeros(3) if torque is None else check_omega(torque, "torque")
    w, T = np.broadcast_arrays(w, T)
    lead = w.shape[:-1]
    out = np.empty((int(np.prod(lead, dtype=int)), 3))
    omega_dot_batch_nb(np.ascontiguousarray(w.reshape(-1, 3)), np.ascontiguousarray(J),
                       np.ascontiguousarray(Ji), np.ascontiguousarray(T.reshape(-1, 3)), out)
    return out.reshape(lead + (3,))


def state_derivative(t, x, J, torque_fn=None, J_inv=None):
    """Time derivative of ``x = [q (4), ω (3)]`` (Bernard eq. 4.12–4.13), for ``solve_ivp``.

    Parameters
    ----------
    t : float
        Time, s (passed to ``torque_fn``).
    x : array (7,)
        Quaternion (scalar first, inertial→body) and body rate (rad/s, body axes). The
        quaternion is used as given (an integrator drifts it slightly off unit norm); the
        torque is evaluated with the normalised quaternion.
    J : array (3, 3)
        Inertia, kg m², body axes.
    torque_fn : callable ``(t, q, omega) -> (3,)``, optional
        External torque in body axes, N m.
    """
    x = np.asarray(x, dtype=float)
    if x.shape != (7,):
        raise ValueError(f"x: expected shape (7,) = [q(4), omega(3)], got {x.shape}")
    q, w = x[None, :4], x[None, 4:]
    J = check_inertia(J)
    Ji = np.linalg.inv(J) if J_inv is None else np.asarray(J_inv, dtype=float)
    T = np.zeros((1, 3))
    if torque_fn is not None:
        T[0] = np.asarray(torque_fn(t, x[:4] / np.linalg.norm(x[:4]), x[4:]), dtype=float)
    out = np.empty(7)
    quat_rate_batch_nb(q, w, out[None, :4])
    omega_dot_batch_nb(w, J, Ji, T, out[None, 4:])
    return out


def angular_momentum_inertial(q, omega, J):
    """Inertial angular momentum ``H_I = A(q)ᵀ J ω`` (kg m²/s, inertial axes); stacks allowed."""
    J = check_inertia(J)
    w = check_omega(omega)
    return rot.quat_rotate_inv(q, w @ J.T)


def rotational_energy(omega, J):
    """Rotational kinetic energy ``½ ωᵀ J ω`` (J); stacks allowed."""
    J = check_inertia(J)
    w = check_omega(omega)
    return 0.5 * np.sum(w * (w @ J.T), axis=-1)
