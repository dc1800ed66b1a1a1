"""Quaternion kinematics (Bernard 2021 eq. 4.12, scalar-first form).

Conventions: ``q`` scalar first, unit, inertial→body passive (``v_b = A(q) v_I``); ``ω`` is the
angular velocity of the body relative to inertial space, expressed in body axes (rad/s).

    q̇1 = −½ q_v·ω,      q̇_v = ½ (q1 ω − ω × q_v),      i.e.   q̇ = ½ [0, ω] ⊗ q

with :func:`lightcurve.rotations.quat_mult`'s ``⊗`` (``A(q ⊗ p) = A(q) A(p)``). For a constant
body rate the exact solution is ``q(t + Δt) = exp(ω Δt) ⊗ q(t)`` with ``exp(θ)`` the quaternion
of the rotation vector ``θ`` (:func:`lightcurve.rotations.rotvec_to_quat`). The kernels are
:func:`lightcurve.core.dynamics.quat_rate_xyz` and :func:`lightcurve.core.dynamics.const_rate_xyz`.
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot
from ..core.dynamics import quat_rate_batch_nb

__all__ = ["quat_derivative", "propagate_constant_rate"]


def check_omega(omega, name="omega"):
    """``omega`` as a float array of shape (..., 3); ValueError naming ``name`` for a wrong
    shape or NaN/inf."""
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
    w = check_omega(omega)
    shape = np.broadcast_shapes(q.shape[:-1], w.shape[:-1])
    Q = np.ascontiguousarray(np.broadcast_to(q, shape + (4,))).reshape(-1, 4)
    W = np.ascontiguousarray(np.broadcast_to(w, shape + (3,))).reshape(-1, 3)
    out = np.empty((Q.shape[0], 4))
    quat_rate_batch_nb(Q, W, out)
    return out.reshape(shape + (4,))


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
    w = check_omega(omega)
    dt = np.asarray(dt, dtype=float)
    if not np.all(np.isfinite(dt)):
        raise ValueError("dt: contains NaN or infinite values")
    dq = rot.rotvec_to_quat(w * dt[..., None])
    return rot.quat_mult(dq, q)
