"""Quaternion kinematics (Bernard 2021 eq. 4.12, scalar-first form).

Conventions: ``q`` scalar first, unit, inertial→body passive (``v_b = A(q) v_I``); ``ω`` is the
angular velocity of the body relative to inertial space, expressed in body axes (rad/s).

    q̇1 = −½ q_v·ω,      q̇_v = ½ (q1 ω − ω × q_v),      i.e.   q̇ = ½ [0, ω] ⊗ q

with :func:`lightcurve.rotations.quat_mult`'s ``⊗`` (``A(q ⊗ p) = A(q) A(p)``). For a constant
body rate the exact solution is ``q(t + Δt) = exp(ω Δt) ⊗ q(t)`` with ``exp(θ)`` the quaternion
of the rotation vector ``θ`` (:func:`lightcurve.rotations.rotvec_to_quat`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import rotations as rot

__all__ = ["quat_derivative", "propagate_constant_rate", "qdot_nb", "const_rate_step_nb"]


def _check_omega(omega, name="omega"):
    w = np.asarray(omega, dtype=float) if not isinstance(omega, np.ndarray) else omega.astype(float)
    if w.ndim == 0 or w.shape[-1] != 3:
        raise ValueError(f"{name}: expected shape (..., 3), got {np.shape(omega)}")
    if not np.all(np.isfinite(w)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return w


def quat_derivative(q, omega):
    """Quaternion rate ``q̇ = ½ [0, ω] ⊗ q`` (1/s; Bernard eq. 4.12).

    Parameters
    ----------
    q : array (..., 4)
        Unit attitude quaternion(s), scalar first, inertial→body.
    omega : array (..., 3)
        Body angular velocity in body axes, rad/s. Broadcasts against ``q``.

    Returns
    -------
    array (..., 4)
    """
    q = rot.check_unit_quat(q, "q")
    w = _check_omega(omega)
    shape = np.broadcast_shapes(q.shape[:-1], w.shape[:-1])
    q = np.broadcast_to(q, shape + (4,))
    w = np.broadcast_to(w, shape + (3,))
    q0, qv = q[..., :1], q[..., 1:]
    d0 = -0.5 * np.sum(qv * w, axis=-1, keepdims=True)
    dv = 0.5 * (q0 * w - np.cross(w, qv))
    return np.concatenate([d0, dv], axis=-1)


def propagate_constant_rate(q, omega, dt):
    """Exact attitude after ``dt`` seconds at constant body rate: ``exp(ω dt) ⊗ q``.

    Parameters
    ----------
    q : array (..., 4)
        Unit quaternion(s) at the start, inertial→body.
    omega : array (..., 3)
        Constant body rate in body axes, rad/s.
    dt : float or array (...)
        Time step(s), s (may be negative); broadcasts against the batch shape.

    Returns
    -------
    array (..., 4) unit quaternion(s) (sign continuous with ``q``, not forced to ``q1 >= 0``).
    """
    q = rot.check_unit_quat(q, "q")
    w = _check_omega(omega)
    dt = np.asarray(dt, dtype=float)
    if not np.all(np.isfinite(dt)):
        raise ValueError("dt: contains NaN or infinite values")
    dq = rot.rotvec_to_quat(w * dt[..., None])
    return rot.quat_mult(dq, q)


@njit(cache=True)
def qdot_nb(q, w):
    """``½ [0, ω] ⊗ q`` for 1-D float64 arrays (q: 4, ω: 3); no validation."""
    out = np.empty(4)
    out[0] = -0.5 * (q[1] * w[0] + q[2] * w[1] + q[3] * w[2])
    # ½ (q1 ω − ω × q_v)
    out[1] = 0.5 * (q[0] * w[0] - (w[1] * q[3] - w[2] * q[2]))
    out[2] = 0.5 * (q[0] * w[1] - (w[2] * q[1] - w[0] * q[3]))
    out[3] = 0.5 * (q[0] * w[2] - (w[0] * q[2] - w[1] * q[1]))
    return out


@njit(cache=True)
def const_rate_step_nb(q, w, dt):
    """Exact constant-rate step ``exp(ω dt) ⊗ q`` for 1-D float64 arrays; no validation."""
    th = np.empty(3)
    for i in range(3):
        th[i] = w[i] * dt
    return rot.qmul_nb(rot.rotvec2q_nb(th), q)
