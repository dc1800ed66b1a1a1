"""Rigid-body attitude dynamics: the one RK4 step, the exact constant-rate step, and the
linearised error dynamics Φ, Q_d (numba kernels on plain floats and float64 arrays).

Equations
---------
* Kinematics (Bernard 2021 eq. 4.12): ``q̇ = ½ [0, ω] ⊗ q`` — scalar first, inertial→body;
  ``q̇1 = −½ q_v·ω``, ``q̇_v = ½ (q1 ω − ω × q_v)``.
* Euler's equations with momentum wheels (Bernard eq. 4.13; O'Keefe 2015 eq. B.1):
  ``ω̇ = K (−ω × (J ω + h) + T)`` with ``J`` the inertia (kg m², body axes), ``K = J⁻¹``,
  ``T`` the external torque (N m) and ``h`` the wheels' spin angular momentum in body axes
  (N m s). For O'Keefe's reaction wheels ``J = [I_RW]`` (the spacecraft inertia less the
  wheels' spin-axis inertia), ``h = G_s h_s`` with the wheel momenta ``h_s = J_s ∘ (Ω + G_sᵀ ω)``
  and the motor torques ``u_s = ḣ_s``, so ``T = L − G_s u_s`` and ``ḣ = G_s u_s``: within a step
  of constant ``u_s`` the wheel momentum is linear in time and needs no state of its own.
  Without wheels ``h = 0`` and this is Bernard eq. 4.13 (η, the process noise, is added by
  the filters).
* Gravity-gradient torque (Bernard eq. 4.20):
  ``T_gg = 3μ/|r|³ û × (J û)``, ``û = A(q) r̂`` — optional inside the step, evaluated at every
  RK4 stage.
* Error dynamics of ``δx = [δθ, δω]`` (``q_true = δq(δθ) ⊗ q̂``): controlled
  ``F = [[−[ω×], I], [0, 0]]`` (Bernard eq. 7.24); uncontrolled (eq. 7.37, appendix A)
  ``F = [[−[ω×], I], [J⁻¹ ∂T/∂δθ, J⁻¹([(Jω)×] − [ω×] J)]]``; ``Φ = exp(F Δt)`` and
  ``Q_d = ∫ Φ Q_c Φᵀ`` by Van Loan's method.

Calling the RK4 step
--------------------
:func:`rk4_step_xyz` advances one state by one step on scalars (so a loop over particles keeps
the state in registers and vectorises). Inertia ``J`` and ``K = J⁻¹`` are passed as row-major
9-tuples (:func:`mat9`). The optional terms are ``None`` or tuples, resolved when numba compiles
the caller (a ``None`` term costs nothing):

* ``T`` — constant body torque over the step, ``(Tx, Ty, Tz)`` N m (e.g. SRP, drag, control);
* ``gg`` — gravity gradient ``(k, r̂x, r̂y, r̂z)`` with ``k = 3μ/|r|³`` (1/s²) and ``r̂`` the unit
  ECI position, held over the step;
* ``wheels`` — ``(hx, hy, hz, τx, τy, τz)``: wheel momentum ``h`` at the step start (N m s, body)
  and ``τ = G_s u_s`` (N m, body), constant over the step (O'Keefe eq. B.1); the caller advances
  ``h_s ← h_s + Δt u_s`` after the step (exact) and recovers ``Ω = h_s/J_s − G_sᵀ ω``.

The quaternion is renormalised (sign kept) at the end of every step. :func:`rk4_nb` is the same
step on 1-D arrays with ``nsub`` sub-steps; :func:`rk4_propagate_nb` runs it for many states in
parallel (results independent of the thread count).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .rotations import qmul_xyz, qrot_xyz_nb, rotvec2q_xyz

__all__ = [
    "mat9", "quat_rate_xyz", "omega_dot_xyz", "gravity_gradient_xyz", "rk4_step_xyz", "rk4_nb",
    "rk4_propagate_nb", "const_rate_xyz", "const_rate_nb", "const_rate_batch_nb",
    "omega_dot_batch_nb", "quat_rate_batch_nb", "gravity_gradient_batch_nb",
    "error_F_nb", "van_loan_nb", "uncontrolled_transition_nb", "controlled_transition_nb",
]


@njit(cache=True, inline="always")
def mat9(M):
    """Row-major 9-tuple of a 3×3 array (the form :func:`rk4_step_xyz` takes J and K in)."""
    return (M[0, 0], M[0, 1], M[0, 2], M[1, 0], M[1, 1], M[1, 2], M[2, 0], M[2, 1], M[2, 2])


@njit(cache=True, inline="always")
def quat_rate_xyz(q0, q1, q2, q3, w0, w1, w2):
    """``q̇ = ½ [0, ω] ⊗ q`` (Bernard eq. 4.12) on scalars → 4-tuple (1/s)."""
    return (-0.5 * (q1 * w0 + q2 * w1 + q3 * w2),
            0.5 * (q0 * w0 - (w1 * q3 - w2 * q2)),
            0.5 * (q0 * w1 - (w2 * q1 - w0 * q3)),
            0.5 * (q0 * w2 - (w0 * q2 - w1 * q1)))


@njit(cache=True, inline="always")
def omega_dot_xyz(w0, w1, w2, J, K, T, h):
    """Euler's equations ``ω̇ = K(−ω × (Jω + h) + T)`` (Bernard eq. 4.13; O'Keefe eq. B.1)
    → 3-tuple, rad/s².

    ``w*`` body rate (rad/s, body axes); ``J``, ``K = J⁻¹`` row-major 9-tuples (kg m², body
    axes); ``T`` torque 3-tuple (N m) or None; ``h`` wheel momentum 3-tuple (N m s, body) or
    None.
    """
    J00, J01, J02, J10, J11, J12, J20, J21, J22 = J
    K00, K01, K02, K10, K11, K12, K20, K21, K22 = K
    H0 = J00 * w0 + J01 * w1 + J02 * w2
    H1 = J10 * w0 + J11 * w1 + J12 * w2
    H2 = J20 * w0 + J21 * w1 + J22 * w2
    if h is not None:
        H0 = H0 + h[0]
        H1 = H1 + h[1]
        H2 = H2 + h[2]
    r0 = -(w1 * H2 - w2 * H1)
    r1 = -(w2 * H0 - w0 * H2)
    r2 = -(w0 * H1 - w1 * H0)
    if T is not None:
        r0 = r0 + T[0]
        r1 = r1 + T[1]
        r2 = r2 + T[2]
    return (K00 * r0 + K01 * r1 + K02 * r2,
            K10 * r0 + K11 * r1 + K12 * r2,
            K20 * r0 + K21 * r1 + K22 * r2)


@njit(cache=True, inline="always")
def gravity_gradient_xyz(q0, q1, q2, q3, k, rx, ry, rz, J):
    """Gravity-gradient torque ``k û × (J û)``, ``û = A(q) r̂`` (Bernard eq. 4.20) → 3-tuple
    N m; ``k = 3μ/|r|³`` (1/s²), ``r̂`` unit ECI position, ``J`` row-major 9-tuple (kg m²)."""
    ux, uy, uz = qrot_xyz_nb(q0, q1, q2, q3, rx, ry, rz)
    J00, J01, J02, J10, J11, J12, J20, J21, J22 = J
    a0 = J00 * ux + J01 * uy + J02 * uz
    a1 = J10 * ux + J11 * uy + J12 * uz
    a2 = J20 * ux + J21 * uy + J22 * uz
    return k * (uy * a2 - uz * a1), k * (uz * a0 - ux * a2), k * (ux * a1 - uy * a0)


@njit(cache=True)
def _stage(q0, q1, q2, q3, w0, w1, w2, J, K, T, gg, wheels, ts):
    """Derivative of ``[q, ω]`` at one RK4 stage, ``ts`` s after the step start."""
    d0, d1, d2, d3 = quat_rate_xyz(q0, q1, q2, q3, w0, w1, w2)
    # one `is None` test per branch: numba removes the branches of absent terms at compile time
    if gg is None:
        if wheels is None:
            e0, e1, e2 = omega_dot_xyz(w0, w1, w2, J, K, T, None)
            return d0, d1, d2, d3, e0, e1, e2
    t0 = 0.0
    t1 = 0.0
    t2 = 0.0
    if T is not None:
        t0, t1, t2 = T[0], T[1], T[2]
    if gg is not None:
        g0, g1, g2 = gravity_gradient_xyz(q0, q1, q2, q3, gg[0], gg[1], gg[2], gg[3], J)
        t0, t1, t2 = t0 + g0, t1 + g1, t2 + g2
    if wheels is not None:
        t0, t1, t2 = t0 - wheels[3], t1 - wheels[4], t2 - wheels[5]
        h = (wheels[0] + ts * wheels[3], wheels[1] + ts * wheels[4],
             wheels[2] + ts * wheels[5])
        e0, e1, e2 = omega_dot_xyz(w0, w1, w2, J, K, (t0, t1, t2), h)
    else:
        e0, e1, e2 = omega_dot_xyz(w0, w1, w2, J, K, (t0, t1, t2), None)
    return d0, d1, d2, d3, e0, e1, e2


@njit(cache=True, inline="always")
def rk4_step_xyz(q0, q1, q2, q3, w0, w1, w2, dt, J, K, T, gg, wheels):
    """One classical RK4 step of ``[q, ω]`` (Bernard eq. 4.12–4.13; O'Keefe eq. B.1 with wheels)
    over ``dt`` s (module docstring) → 7-tuple
    ``(q0, q1, q2, q3, ω0, ω1, ω2)``, the quaternion renormalised (sign kept).

    ``q`` scalar first, inertial→body; ``ω`` rad/s body axes; ``J``, ``K`` row-major 9-tuples
    of the inertia (kg m²) and its inverse; ``T``, ``gg``, ``wheels`` None or tuples (module
    docstring). Stages ``x + (dt/2) k``, combination ``x + (dt/6)(k1 + 2 k2 + 2 k3 + k4)``.
    """
    hh = 0.5 * dt
    k0, k1, k2, k3, l0, l1, l2 = _stage(q0, q1, q2, q3, w0, w1, w2, J, K, T, gg, wheels, 0.0)
    m0, m1, m2, m3, n0, n1, n2 = _stage(q0 + hh * k0, q1 + hh * k1, q2 + hh * k2, q3 + hh * k3,
                                        w0 + hh * l0, w1 + hh * l1, w2 + hh * l2,
                                        J, K, T, gg, wheels, hh)
    o0, o1, o2, o3, p0, p1, p2 = _stage(q0 + hh * m0, q1 + hh * m1, q2 + hh * m2, q3 + hh * m3,
                                        w0 + hh * n0, w1 + hh * n1, w2 + hh * n2,
                                        J, K, T, gg, wheels, hh)
    r0, r1, r2, r3, s0, s1, s2 = _stage(q0 + dt * o0, q1 + dt * o1, q2 + dt * o2, q3 + dt * o3,
                                        w0 + dt * p0, w1 + dt * p1, w2 + dt * p2,
                                        J, K, T, gg, wheels, dt)
    s6 = dt / 6.0
    a0 = q0 + s6 * (k0 + 2.0 * m0 + 2.0 * o0 + r0)
    a1 = q1 + s6 * (k1 + 2.0 * m1 + 2.0 * o1 + r1)
    a2 = q2 + s6 * (k2 + 2.0 * m2 + 2.0 * o2 + r2)
    a3 = q3 + s6 * (k3 + 2.0 * m3 + 2.0 * o3 + r3)
    n = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
    return (a0 / n, a1 / n, a2 / n, a3 / n,
            w0 + s6 * (l0 + 2.0 * n0 + 2.0 * p0 + s0),
            w1 + s6 * (l1 + 2.0 * n1 + 2.0 * p1 + s1),
            w2 + s6 * (l2 + 2.0 * n2 + 2.0 * p2 + s2))


@njit(cache=True)
def rk4_nb(q, w, dt, nsub, J, J_inv, torque):
    """In place on ``q`` (4,), ``w`` (3,): ``nsub`` RK4 steps of ``dt/nsub`` s
    (:func:`rk4_step_xyz`) with a constant body torque ``torque`` (3,) N m, or None.

    ``J``, ``J_inv`` (3,3) inertia (kg m², body axes) and its inverse.
    """
    h = dt / nsub
    Jt = mat9(J)
    Kt = mat9(J_inv)
    a0, a1, a2, a3, b0, b1, b2 = q[0], q[1], q[2], q[3], w[0], w[1], w[2]
    if torque is None:
        for _ in range(nsub):
            a0, a1, a2, a3, b0, b1, b2 = rk4_step_xyz(a0, a1, a2, a3, b0, b1, b2, h, Jt, Kt,
                                                      None, None, None)
    else:
        T = (torque[0], torque[1], torque[2])
        for _ in range(nsub):
            a0, a1, a2, a3, b0, b1, b2 = rk4_step_xyz(a0, a1, a2, a3, b0, b1, b2, h, Jt, Kt,
                                                      T, None, None)
    q[0], q[1], q[2], q[3] = a0, a1, a2, a3
    w[0], w[1], w[2] = b0, b1, b2


_BLOCK = 32
"""States per block of :func:`rk4_propagate_nb`: each block is copied into a (7, _BLOCK)
structure-of-arrays buffer so that the loop over states vectorises (SIMD)."""


@njit(cache=True, inline="always")
def _rk4_block(Q, W, lo, hi, Jt, Kt, dt, nsteps, T):
    m = hi - lo
    X = np.empty((7, _BLOCK))
    for j in range(m):
        for k in range(4):
            X[k, j] = Q[lo + j, k]
        for k in range(3):
            X[4 + k, j] = W[lo + j, k]
    for _ in range(nsteps):
        for j in range(m):
            a0, a1, a2, a3, b0, b1, b2 = rk4_step_xyz(X[0, j], X[1, j], X[2, j], X[3, j],
                                                      X[4, j], X[5, j], X[6, j], dt, Jt, Kt,
                                                      T, None, None)
            X[0, j] = a0
            X[1, j] = a1
            X[2, j] = a2
            X[3, j] = a3
            X[4, j] = b0
            X[5, j] = b1
            X[6, j] = b2
    for j in range(m):
        for k in range(4):
            Q[lo + j, k] = X[k, j]
        for k in range(3):
            W[lo + j, k] = X[4 + k, j]


@njit(cache=True, parallel=True)
def rk4_propagate_nb(Q, W, J, J_inv, dt, nsteps, torque=None):
    """RK4-propagate ``N`` attitude states in place, in parallel over blocks of states.

    Q (N,4) C-contiguous unit quaternions (scalar first, inertial→body), W (N,3) body rates
    (rad/s); J, J_inv (3,3) inertia (kg m², body axes) and its inverse; ``nsteps`` steps of
    ``dt`` s (:func:`rk4_step_xyz`); ``torque`` (3,) constant body torque N m, or None
    (torque free). Returns ``(Q, W)`` (the same arrays). Each state is propagated on its own,
    so results do not depend on the number of threads. No validation (see
    :func:`lightcurve.dynamics.rk4_propagate`).
    """
    N = Q.shape[0]
    Jt = mat9(J)
    Kt = mat9(J_inv)
    nb = (N + _BLOCK - 1) // _BLOCK
    # a zero torque adds exact zeros: the torque-free results are the same bit for bit
    T = (0.0, 0.0, 0.0) if torque is None else (torque[0], torque[1], torque[2])
    for c in prange(nb):
        lo = c * _BLOCK
        _rk4_block(Q, W, lo, min(N, lo + _BLOCK), Jt, Kt, dt, nsteps, T)
    return Q, W


# ----------------------------------------------------------------------------------------
# constant rate (controlled model)
# ----------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def const_rate_xyz(q0, q1, q2, q3, w0, w1, w2, dt):
    """Exact constant-rate step ``exp(ω Δt) ⊗ q`` (the solution of Bernard eq. 4.12 for
    constant ω; eq. 3.8–3.13, 3.20) on scalars → 4-tuple (not renormalised)."""
    d0, d1, d2, d3 = rotvec2q_xyz(w0 * dt, w1 * dt, w2 * dt)
    return qmul_xyz(d0, d1, d2, d3, q0, q1, q2, q3)


@njit(cache=True)
def const_rate_nb(q, w, dt):
    """``exp(ω dt) ⊗ q`` for 1-D arrays q (4,), ω (3,) rad/s, dt s (new array)."""
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = const_rate_xyz(q[0], q[1], q[2], q[3], w[0], w[1], w[2], dt)
    return out


@njit(cache=True)
def const_rate_batch_nb(Q, W, dt):
    """In place: ``Q[i] ← exp(W[i] dt) ⊗ Q[i]`` for Q (N,4), W (N,3) rad/s, dt s."""
    for i in range(Q.shape[0]):
        Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3] = const_rate_xyz(Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3],
                                                            W[i, 0], W[i, 1], W[i, 2], dt)


# ----------------------------------------------------------------------------------------
# error dynamics Φ, Q_d
# ----------------------------------------------------------------------------------------
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
def error_F_nb(w, J, J_inv, uncontrolled, F):
    """Fill ``F`` (6, 6) with the continuous error-dynamics matrix at the rate ``w`` (3,) rad/s.

    ``[[−[ω×], I], [0, Fωω]]`` with ``Fωω = J⁻¹([(Jω)×] − [ω×] J)`` (Bernard eq. 7.37, torque
    free) when ``uncontrolled`` is true, else 0 (controlled, eq. 7.24); ``J`` (kg m²) and
    ``J_inv`` are ignored then. Torque partials (appendix A) are added by the caller:
    ``F[3:, :3] = J⁻¹ ∂T/∂δθ``.
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

    ``F``, ``Qc`` (n, n); ``dt`` s (any sign; ``dt = 0`` gives I and 0). The exponential of
    ``M = [[−F, Qc], [0, Fᵀ]] Δt`` is a Taylor series with scaling and squaring, block-wise
    (``Mᵏ = [[Xᵏ, Yₖ], [0, Zᵏ]]``, ``Yₖ = Xᵏ⁻¹ Y + Yₖ₋₁ Z``), summed until the next term is
    below 1e-20 after scaling to ``‖M‖₁ ≤ ½`` (truncation far below the rounding of the
    result; SciPy's Padé ``expm`` gives the same matrix to rounding). ``Qd`` is symmetrised.
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
    # one product per term remains
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
    Wk = np.empty((n, n))
    sign = 1.0
    for k in range(1, 60):
        if not qzero:
            _mm(TX, Y, NY)
            _mm(TY, Z, Wk)
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
                    TY[i, j] = (NY[i, j] + Wk[i, j]) * inv_k
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
            _mm(EY, EZ, Wk)
            _mm(EX, EX, NX)
        for i in range(n):
            for j in range(n):
                EZ[i, j] = NZ[i, j]
                if not qzero:
                    EX[i, j] = NX[i, j]
                    EY[i, j] = NY[i, j] + Wk[i, j]
    for i in range(n):
        for j in range(n):
            Phi[i, j] = EZ[j, i]
    _mm(Phi, EY, Wk)
    for i in range(n):
        for j in range(n):
            Qd[i, j] = 0.5 * (Wk[i, j] + Wk[j, i])


@njit(cache=True)
def uncontrolled_transition_nb(w0, J, J_inv, eta_psd, dt, nsub):
    """``(Φ, Q_d)`` (6, 6) of the torque-free error dynamics over ``dt`` s in ``nsub`` sub-steps.

    On each sub-step ``h = dt/nsub`` the rate is advanced by RK4 of Euler's equations
    (:func:`omega_dot_xyz`); Φ_h, Q_h are the Van Loan discretisation of ``F(ω_mid)``
    (``ω_mid = ω + h/2 k₂``, Bernard eq. 7.37) with ``Qc = diag(0, 0, 0, η, η, η)``
    (``eta_psd`` rad²/s³); ``Φ ← Φ_h Φ``, ``Q ← Φ_h Q Φ_hᵀ + Q_h``; Q symmetrised at the end.
    """
    Phi = np.eye(6)
    Qd = np.zeros((6, 6))
    if dt == 0.0:
        return Phi, Qd
    h = dt / nsub
    Jt = mat9(J)
    Kt = mat9(J_inv)
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
    wm = np.empty(3)
    for _ in range(nsub):
        k10, k11, k12 = omega_dot_xyz(w[0], w[1], w[2], Jt, Kt, None, None)
        k20, k21, k22 = omega_dot_xyz(w[0] + 0.5 * h * k10, w[1] + 0.5 * h * k11,
                                      w[2] + 0.5 * h * k12, Jt, Kt, None, None)
        wm[0] = w[0] + 0.5 * h * k20
        wm[1] = w[1] + 0.5 * h * k21
        wm[2] = w[2] + 0.5 * h * k22
        error_F_nb(wm, J, J_inv, True, F)
        van_loan_nb(F, Qc, h, Ph, Qh)
        _mm(Ph, Phi, T1)
        Phi[:, :] = T1
        _mm(Ph, Qd, T1)
        _mm(T1, Ph.T, T2)
        for i in range(6):
            for j in range(6):
                Qd[i, j] = T2[i, j] + Qh[i, j]
        k30, k31, k32 = omega_dot_xyz(wm[0], wm[1], wm[2], Jt, Kt, None, None)
        k40, k41, k42 = omega_dot_xyz(w[0] + h * k30, w[1] + h * k31, w[2] + h * k32, Jt, Kt,
                                      None, None)
        w[0] = w[0] + h / 6.0 * (k10 + 2.0 * k20 + 2.0 * k30 + k40)
        w[1] = w[1] + h / 6.0 * (k11 + 2.0 * k21 + 2.0 * k31 + k41)
        w[2] = w[2] + h / 6.0 * (k12 + 2.0 * k22 + 2.0 * k32 + k42)
    out = np.empty((6, 6))
    for i in range(6):
        for j in range(6):
            out[i, j] = 0.5 * (Qd[i, j] + Qd[j, i])
    return Phi, out


@njit(cache=True)
def controlled_transition_nb(w, dt):
    """Closed-form Φ (6, 6) of the constant-rate error dynamics (Bernard eq. 7.24) over ``dt`` s.

    ``Φθθ = exp(−[ω×]Δt)`` (eq. 3.13), ``Φθω = I Δt − (1 − cos φ)/|ω|² [ω×]
    + (Δt − sin φ/|ω|)/|ω|² [ω×]²`` (φ = |ω| Δt; series ``I Δt − ½ [ω×] Δt²`` and
    ``I − [ω×]Δt`` for |ω Δt| < 1e-8), ``Φωω = I``.
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
    # exp(−[θ×]) with θ = ω Δt (Bernard eq. 3.13): I − s K + c K², K = [θ×] = Δt S
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


@njit(cache=True)
def omega_dot_batch_nb(W, J, J_inv, T, out):
    """Row-wise Euler's equations ``ω̇ = J⁻¹(−ω × Jω + T)`` (Bernard eq. 4.13,
    :func:`omega_dot_xyz`): W, T, out (N,3) (rad/s, N m, rad/s²); J, J_inv (3,3)."""
    Jt = mat9(J)
    Kt = mat9(J_inv)
    for i in range(W.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = omega_dot_xyz(W[i, 0], W[i, 1], W[i, 2], Jt, Kt,
                                                        (T[i, 0], T[i, 1], T[i, 2]), None)


@njit(cache=True)
def quat_rate_batch_nb(Q, W, out):
    """Row-wise ``q̇ = ½ [0, ω] ⊗ q`` (Bernard eq. 4.12, :func:`quat_rate_xyz`): Q, out (N,4),
    W (N,3) rad/s."""
    for i in range(Q.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = quat_rate_xyz(
            Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3], W[i, 0], W[i, 1], W[i, 2])


@njit(cache=True)
def gravity_gradient_batch_nb(Q, R, J, mu, out):
    """Row-wise gravity-gradient torque ``3μ/|r|³ û × (J û)``, ``û = A(q) r̂`` (Bernard eq. 4.20,
    :func:`gravity_gradient_xyz`): Q (N,4), R (N,3) ECI positions m, J (3,3) kg m², μ m³/s²;
    out (N,3) N m (body axes)."""
    Jt = mat9(J)
    for i in range(Q.shape[0]):
        rn = math.sqrt(R[i, 0] ** 2 + R[i, 1] ** 2 + R[i, 2] ** 2)
        out[i, 0], out[i, 1], out[i, 2] = gravity_gradient_xyz(
            Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3], 3.0 * mu / rn ** 3, R[i, 0] / rn, R[i, 1] / rn,
            R[i, 2] / rn, Jt)
