"""Integrators for the attitude state ``[q, ω]``.

* :func:`rk4_propagate_nb` — fixed-step classical Runge–Kutta (4th order) numba kernel for many
  states at once (particles, sigma points), torque-free or with a constant body torque, with
  the quaternion renormalised after every step; parallel over states with ``numba.prange``.
* :func:`integrate_truth` — ``scipy.integrate.solve_ivp`` with DOP853 and tight tolerances for
  truth trajectories.

Conventions: ``q`` scalar first, inertial→body; ``ω`` body rate in body axes (rad/s);
``J`` inertia in body axes (kg m²); torque in body axes (N m); times in s. Dynamics:
``q̇ = ½ [0, ω] ⊗ q`` (Bernard eq. 4.12), ``J ω̇ = −ω × Jω + T`` (eq. 4.13).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .. import rotations as rot
from .rigid_body import check_inertia

__all__ = ["rk4_propagate_nb", "rk4_propagate_serial_nb", "rk4_propagate", "integrate_truth"]


@njit(cache=True, inline="always")
def _deriv(q0, q1, q2, q3, w0, w1, w2,
           J00, J01, J02, J10, J11, J12, J20, J21, J22,
           K00, K01, K02, K10, K11, K12, K20, K21, K22, T0, T1, T2):
    # q̇ = ½ [0, ω] ⊗ q  (q̇1 = −½ q_v·ω, q̇_v = ½ (q1 ω − ω × q_v))
    d0 = -0.5 * (q1 * w0 + q2 * w1 + q3 * w2)
    d1 = 0.5 * (q0 * w0 - (w1 * q3 - w2 * q2))
    d2 = 0.5 * (q0 * w1 - (w2 * q1 - w0 * q3))
    d3 = 0.5 * (q0 * w2 - (w0 * q2 - w1 * q1))
    # h = J ω ; r = −ω × h + T ; ω̇ = J⁻¹ r
    h0 = J00 * w0 + J01 * w1 + J02 * w2
    h1 = J10 * w0 + J11 * w1 + J12 * w2
    h2 = J20 * w0 + J21 * w1 + J22 * w2
    r0 = -(w1 * h2 - w2 * h1) + T0
    r1 = -(w2 * h0 - w0 * h2) + T1
    r2 = -(w0 * h1 - w1 * h0) + T2
    e0 = K00 * r0 + K01 * r1 + K02 * r2
    e1 = K10 * r0 + K11 * r1 + K12 * r2
    e2 = K20 * r0 + K21 * r1 + K22 * r2
    return d0, d1, d2, d3, e0, e1, e2


_BLOCK = 32
"""States per block: each block is copied into a (7, _BLOCK) structure-of-arrays buffer so the
inner loop over states vectorises (SIMD) while the step loop runs outside it."""


@njit(cache=True, inline="always")
def _rk4_block(q, w, lo, hi, J, K, dt, nsteps, T):
    J00, J01, J02 = J[0, 0], J[0, 1], J[0, 2]
    J10, J11, J12 = J[1, 0], J[1, 1], J[1, 2]
    J20, J21, J22 = J[2, 0], J[2, 1], J[2, 2]
    K00, K01, K02 = K[0, 0], K[0, 1], K[0, 2]
    K10, K11, K12 = K[1, 0], K[1, 1], K[1, 2]
    K20, K21, K22 = K[2, 0], K[2, 1], K[2, 2]
    T0, T1, T2 = T[0], T[1], T[2]
    h = 0.5 * dt
    s6 = dt / 6.0
    m = hi - lo
    X = np.empty((7, _BLOCK))
    for j in range(m):
        for k in range(4):
            X[k, j] = q[lo + j, k]
        for k in range(3):
            X[4 + k, j] = w[lo + j, k]
    for _ in range(nsteps):
        for j in range(m):
            a0, a1, a2, a3 = X[0, j], X[1, j], X[2, j], X[3, j]
            b0, b1, b2 = X[4, j], X[5, j], X[6, j]
            k0, k1, k2, k3, l0, l1, l2 = _deriv(a0, a1, a2, a3, b0, b1, b2, J00, J01, J02, J10, J11,
                                                J12, J20, J21, J22, K00, K01, K02, K10, K11, K12, K20,
                                                K21, K22, T0, T1, T2)
            m0, m1, m2, m3, n0, n1, n2 = _deriv(a0 + h * k0, a1 + h * k1, a2 + h * k2, a3 + h * k3,
                                                b0 + h * l0, b1 + h * l1, b2 + h * l2, J00, J01, J02,
                                                J10, J11, J12, J20, J21, J22, K00, K01, K02, K10, K11,
                                                K12, K20, K21, K22, T0, T1, T2)
            o0, o1, o2, o3, p0, p1, p2 = _deriv(a0 + h * m0, a1 + h * m1, a2 + h * m2, a3 + h * m3,
                                                b0 + h * n0, b1 + h * n1, b2 + h * n2, J00, J01, J02,
                                                J10, J11, J12, J20, J21, J22, K00, K01, K02, K10, K11,
                                                K12, K20, K21, K22, T0, T1, T2)
            r0, r1, r2, r3, s0, s1, s2 = _deriv(a0 + dt * o0, a1 + dt * o1, a2 + dt * o2, a3 + dt * o3,
                                                b0 + dt * p0, b1 + dt * p1, b2 + dt * p2, J00, J01, J02,
                                                J10, J11, J12, J20, J21, J22, K00, K01, K02, K10, K11,
                                                K12, K20, K21, K22, T0, T1, T2)
            a0 += s6 * (k0 + 2.0 * (m0 + o0) + r0)
            a1 += s6 * (k1 + 2.0 * (m1 + o1) + r1)
            a2 += s6 * (k2 + 2.0 * (m2 + o2) + r2)
            a3 += s6 * (k3 + 2.0 * (m3 + o3) + r3)
            # renormalise the quaternion after every step (sign kept)
            inv = 1.0 / np.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
            X[0, j] = a0 * inv
            X[1, j] = a1 * inv
            X[2, j] = a2 * inv
            X[3, j] = a3 * inv
            X[4, j] = b0 + s6 * (l0 + 2.0 * (n0 + p0) + s0)
            X[5, j] = b1 + s6 * (l1 + 2.0 * (n1 + p1) + s1)
            X[6, j] = b2 + s6 * (l2 + 2.0 * (n2 + p2) + s2)
    for j in range(m):
        for k in range(4):
            q[lo + j, k] = X[k, j]
        for k in range(3):
            w[lo + j, k] = X[4 + k, j]


@njit(cache=True, parallel=True)
def rk4_propagate_nb(q, w, J, J_inv, dt, nsteps, torque=None):
    """RK4-propagate ``N`` attitude states in place, in parallel over blocks of states.

    Parameters
    ----------
    q : float64 array (N, 4), C-contiguous
        Unit quaternions (scalar first, inertial→body); overwritten.
    w : float64 array (N, 3)
        Body rates (rad/s, body axes); overwritten.
    J, J_inv : float64 arrays (3, 3)
        Inertia (kg m², body axes) and its inverse.
    dt : float
        Step, s.
    nsteps : int
        Number of steps.
    torque : float64 array (3,), optional
        Constant body torque, N m (omitted or None: torque-free motion).

    Returns ``(q, w)`` (the same, updated arrays). The quaternion is renormalised after every
    step (sign kept). Results do not depend on the number of threads (each state is propagated
    independently, no reductions). No validation: use :func:`rk4_propagate` from Python code.
    """
    if torque is None:
        T = np.zeros(3)
    else:
        T = torque
    N = q.shape[0]
    nb = (N + _BLOCK - 1) // _BLOCK
    for c in prange(nb):
        lo = c * _BLOCK
        _rk4_block(q, w, lo, min(N, lo + _BLOCK), J, J_inv, dt, nsteps, T)
    return q, w


@njit(cache=True)
def rk4_propagate_serial_nb(q, w, J, J_inv, dt, nsteps, torque=None):
    """Serial version of :func:`rk4_propagate_nb` (for calling from other parallel kernels)."""
    if torque is None:
        T = np.zeros(3)
    else:
        T = torque
    N = q.shape[0]
    for lo in range(0, N, _BLOCK):
        _rk4_block(q, w, lo, min(N, lo + _BLOCK), J, J_inv, dt, nsteps, T)
    return q, w


def rk4_propagate(q, omega, J, dt: float, nsteps: int, torque=None):
    """Validated wrapper of :func:`rk4_propagate_nb`; returns new arrays ``(q, ω)``.

    ``q`` (N,4) or (4,) unit quaternions, ``omega`` (N,3) or (3,) rad/s, ``J`` (3,3) kg m²,
    ``dt`` s, ``nsteps`` ≥ 0, ``torque`` (3,) N m in body axes (constant).
    """
    q = rot.check_unit_quat(q, "q")
    single = q.ndim == 1
    q2 = np.array(np.atleast_2d(q), dtype=np.float64, order="C")
    w = np.asarray(omega, dtype=float)
    if w.shape[-1:] != (3,) or not np.all(np.isfinite(w)):
        raise ValueError(f"omega: expected finite values of shape (..., 3), got {w.shape}")
    if q2.ndim != 2 or w.ndim > 2 or (np.atleast_2d(w).shape[0] not in (1, q2.shape[0])):
        raise ValueError(f"q and omega: incompatible shapes {q.shape} and {w.shape} "
                         "(expected (N,4) with (N,3) or (3,))")
    w2 = np.array(np.broadcast_to(np.atleast_2d(w), (q2.shape[0], 3)), dtype=np.float64, order="C")
    J = check_inertia(J)
    if not np.isfinite(dt):
        raise ValueError("dt: must be finite")
    nsteps = int(nsteps)
    if nsteps < 0:
        raise ValueError("nsteps: must be >= 0")
    T = np.zeros(3) if torque is None else np.asarray(torque, dtype=float).reshape(3)
    if not np.all(np.isfinite(T)):
        raise ValueError("torque: contains NaN or infinite values")
    rk4_propagate_nb(q2, w2, np.ascontiguousarray(J), np.ascontiguousarray(np.linalg.inv(J)),
                     float(dt), nsteps, T)
    return (q2[0], w2[0]) if single else (q2, w2)


def integrate_truth(x0, t_eval, rhs, rtol: float = 1e-12, atol: float = 1e-12, t0: float | None = None,
                    normalize: bool = True):
    """Integrate ``ẋ = rhs(t, x)`` with ``solve_ivp`` DOP853 and return ``x`` at ``t_eval``.

    Parameters
    ----------
    x0 : array (n,)
        State at ``t0`` (for the attitude state ``[q (4), ω (3)]``).
    t_eval : array (N,)
        Output times, s, non-decreasing (repeats allowed), all ``>= t0``.
    rhs : callable ``(t, x) -> (n,)``
        e.g. ``lambda t, x: state_derivative(t, x, J, torque_fn)``.
    rtol, atol : float
        Tolerances (default 1e-12 each).
    t0 : float, optional
        Initial time (default ``t_eval[0]``).
    normalize : bool
        Renormalise the first four components (the quaternion) of each output row.

    Returns
    -------
    array (N, n). Raises ``RuntimeError`` if the integrator fails.
    """
    from scipy.integrate import solve_ivp

    x0 = np.asarray(x0, dtype=float)
    t_eval = np.atleast_1d(np.asarray(t_eval, dtype=float))
    if x0.ndim != 1 or not np.all(np.isfinite(x0)):
        raise ValueError("x0: expected a finite 1-D state vector")
    if t_eval.ndim != 1 or t_eval.size == 0 or not np.all(np.isfinite(t_eval)):
        raise ValueError("t_eval: expected a non-empty finite 1-D array of times (s)")
    if np.any(np.diff(t_eval) < 0):
        raise ValueError("t_eval: times must be non-decreasing")
    t0 = float(t_eval[0]) if t0 is None else float(t0)
    if t_eval[0] < t0:
        raise ValueError("t_eval: times must not precede t0")
    if t_eval[-1] == t0:
        out = np.repeat(x0[None, :], t_eval.size, axis=0)
    else:
        tu, inverse = np.unique(t_eval, return_inverse=True)  # solve_ivp needs strictly increasing
        sol = solve_ivp(rhs, (t0, float(tu[-1])), x0, method="DOP853", t_eval=tu,
                        rtol=rtol, atol=atol)
        if not sol.success:
            raise RuntimeError(f"solve_ivp (DOP853) failed: {sol.message}")
        out = sol.y.T[inverse].copy()
    if normalize and x0.size >= 4:
        out[:, :4] /= np.linalg.norm(out[:, :4], axis=1, keepdims=True)
    return out
