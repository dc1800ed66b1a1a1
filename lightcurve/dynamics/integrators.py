"""Integrators for the attitude state ``[q, ω]``.

* :func:`rk4_propagate` — validated wrapper of :func:`lightcurve.core.dynamics.rk4_propagate_nb`:
  the one fixed-step classical Runge–Kutta step of the package
  (:func:`lightcurve.core.dynamics.rk4_step_xyz`) for many states at once, torque-free or with a
  constant body torque, the quaternion renormalised after every step.
* :func:`integrate_truth` — ``scipy.integrate.solve_ivp`` with DOP853 and tight tolerances for
  truth trajectories.

Conventions: ``q`` scalar first, inertial→body; ``ω`` body rate in body axes (rad/s);
``J`` inertia in body axes (kg m²); torque in body axes (N m); times in s. Dynamics:
``q̇ = ½ [0, ω] ⊗ q`` (Bernard eq. 4.12), ``J ω̇ = −ω × Jω + T`` (eq. 4.13).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from .. import rotations as rot
from ..core.dynamics import rk4_propagate_nb
from . import _checks as ck
from .rigid_body import check_inertia

__all__ = ["rk4_propagate_nb", "rk4_propagate", "integrate_truth"]


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
    x0 = np.asarray(x0, dtype=float)
    if x0.ndim != 1 or not np.all(np.isfinite(x0)):
        raise ValueError("x0: expected a finite 1-D state vector")
    t_eval = ck.times(t_eval, "t_eval")
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
