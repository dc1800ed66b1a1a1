"""MRP attitude EKF with gyro-bias estimation (O'Keefe 2015, eq. 4.5-4.11).

State ``x = [σ, β, p]``: the modified Rodrigues parameters ``σ = σ_BN`` of the attitude
(inertial→body, passive: ``v_B = C(σ) v_N``, ``C(σ)`` of :func:`lightcurve.rotations.mrp_to_dcm`,
equal to ``A(q)`` for ``σ = q_v/(1+q_1)``), the gyro bias ``β`` (rad/s, body axes), and any
number of static parameters ``p`` appended by a user (the CSS calibration states of
:mod:`lightcurve.css.calibration`).  Full covariance ``P`` (n×n).

Dynamics (gyro model ω̃ = ω + β + η_v, β̇ = η_u, :mod:`lightcurve.css.gyro`)::

    σ̇ = ¼ B(σ) (ω̃ − β),   B(σ) = (1 − σᵀσ) I + 2[σ×] + 2σσᵀ          (eq. 4.5)
    β̇ = 0 (+ η_u),        ṗ = 0 (+ optional random walk q_p)

Linearisation (eq. 4.6-4.8, derived here)::

    ∂σ̇/∂σ = ½ (σ ωᵀ − ω σᵀ − [ω×] + (ωᵀσ) I),   ∂σ̇/∂β = −¼ B(σ)

The state is advanced with the exact constant-rate step of the attitude (ω̃ − β̂ held over the
step; :func:`lightcurve.core.dynamics.const_rate_nb` on the quaternion of σ, the MRP algebra of
:mod:`lightcurve.core.rotations`), the covariance with ``Φ = I + F Δt + F² Δt²/2`` on the
(σ, β) block and the discrete process noise
(Farrenkopf, with ``B Bᵀ = (1+σᵀσ)² I``)::

    Q_σσ = (1+σᵀσ)²/16 (σ_v² Δt + σ_u² Δt³/3) I,  Q_σβ = −¼ B σ_u² Δt²/2,  Q_ββ = σ_u² Δt I

Shadow-set switching (eq. 4.2): when ``|σ| > 1`` the state is replaced by ``σˢ = −σ/|σ|²``
and the covariance rows/columns of σ are mapped with ``J = ∂σˢ/∂σ = (2σσᵀ − |σ|² I)/|σ|⁴``
(Karlgaard & Schaub 2009).

Updates:

* unit-vector measurement ``ẑ_B = C(σ) r_N`` (sun sensor, magnetometer; eq. 4.9-4.11) with
  ``H_σ = ∂(C(σ) r_N)/∂σ`` (:func:`lightcurve.core.rotations.mrp_dcm_vec_jac_nb`);
* star-tracker attitude measurement (a separate update): the small rotation vector
  ``δθ = 4 σ(C(σ_meas) C(σ̂)ᵀ)`` from the estimate to the measurement, ``h = 0`` and
  ``H_σ = 4 Bᵀ(σ̂)/(1+σ̂ᵀσ̂)²`` (from ``Δσ = ¼ B(σ̂) δθ``), ``R = σ_st² I`` (rad²).

Every update is :func:`lightcurve.core.kalman.joseph_update_nb` (Joseph form, optional
Schmidt consider mask); a failed factorisation leaves the state untouched.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..core.dynamics import const_rate_nb
from ..core.kalman import joseph_update_nb
from ..core.rotations import (mrp2dcm_nb, mrp2q_nb, mrp_B_nb, mrp_dcm_vec_jac_nb, mrp_shadow_nb,
                              q2mrp_nb, qmul_nb, skew_nb)
from ..rotations import quat_to_mrp

__all__ = [
    "mv3_nb", "mtv3_nb", "mrp_propagate_nb", "mrp_switch_cov_nb", "star_tracker_update_nb",
    "vector_update_nb", "mrp_apply_correction_nb",
    "MRPEKFParams", "run_mrp_ekf",
]


@numba.njit(cache=True)
def mv3_nb(A, v):
    """A v for 3×3 A."""
    return np.array([A[0, 0] * v[0] + A[0, 1] * v[1] + A[0, 2] * v[2],
                     A[1, 0] * v[0] + A[1, 1] * v[1] + A[1, 2] * v[2],
                     A[2, 0] * v[0] + A[2, 1] * v[1] + A[2, 2] * v[2]])


@numba.njit(cache=True)
def mtv3_nb(A, v):
    """Aᵀ v for 3×3 A."""
    return np.array([A[0, 0] * v[0] + A[1, 0] * v[1] + A[2, 0] * v[2],
                     A[0, 1] * v[0] + A[1, 1] * v[1] + A[2, 1] * v[2],
                     A[0, 2] * v[0] + A[1, 2] * v[1] + A[2, 2] * v[2]])


@numba.njit(cache=True)
def mrp_switch_cov_nb(x, P):
    """Shadow-set switch in place when |σ| > 1 (state x[0:3], covariance rows/cols 0:3).
    Returns True when switched."""
    n2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2]
    if n2 <= 1.0:
        return False
    s = x[0:3].copy()
    J = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            J[i, j] = 2.0 * s[i] * s[j] / (n2 * n2)
        J[i, i] -= 1.0 / n2
    for i in range(3):
        x[i] = -s[i] / n2
    _left_right_nb(P, J, 3)
    return True


@numba.njit(cache=True)
def _left_nb(P, T, m, tmp):
    """P[:m, :] ← T P[:m, :] in place (T (m, m); ``tmp`` (m,) work), column by column."""
    for j in range(P.shape[1]):
        for i in range(m):
            acc = 0.0
            for l in range(m):
                acc += T[i, l] * P[l, j]
            tmp[i] = acc
        for i in range(m):
            P[i, j] = tmp[i]


@numba.njit(cache=True)
def _left_right_nb(P, T, m):
    """P ← T P Tᵀ in place where T acts on the first m rows/columns only (identity
    elsewhere): the rows (T P), then the columns as the rows of the transposed view
    ((T (T P)ᵀ)ᵀ = T P Tᵀ)."""
    tmp = np.empty(m)
    _left_nb(P, T, m, tmp)
    _left_nb(P.T, T, m, tmp)


@numba.njit(cache=True)
def mrp_apply_correction_nb(x, P, xn, Pn):
    """In place ``x += δx``, ``P ← P⁺`` (a Kalman update's result), then the MRP shadow-set
    switch (O'Keefe eq. 4.2)."""
    n = x.shape[0]
    for i in range(n):
        x[i] += xn[i]
        for j in range(n):
            P[i, j] = Pn[i, j]
    mrp_switch_cov_nb(x, P)


@numba.njit(cache=True)
def _mrp_update_nb(x, P, nu, H, R, consider):
    """The measurement update of the MRP state in place: the core's Joseph update with
    innovation ``nu``, ``H``, ``R`` (``consider`` as there), applied by
    :func:`mrp_apply_correction_nb`. Returns (NIS, ok)."""
    xn, Pn, nis, ok = joseph_update_nb(np.zeros(x.shape[0]), P, nu, H, R, consider)
    if ok:
        mrp_apply_correction_nb(x, P, xn, Pn)
    return nis, ok


@numba.njit(cache=True)
def mrp_propagate_nb(x, P, omega_meas, dt, arw, rrw, q_param):
    """EKF time update (O'Keefe eq. 4.5-4.8) in place over Δt (s) with the gyro sample
    ``omega_meas`` (rad/s): the attitude by the core's constant-rate step, the covariance by
    the module docstring's Φ and Farrenkopf noise, then the shadow-set switch (eq. 4.2).

    x (n,) = [σ, β, p...]; P (n,n); arw σ_v (rad/√s), rrw σ_u (rad/s^1.5); q_param: random-
    walk density added to the diagonal of the parameter block (units²/s, 0 for constants).
    """
    n = x.shape[0]
    s = x[0:3].copy()
    w = omega_meas - x[3:6]
    # state: the exact constant-rate step of the attitude (ω held over the step) through the
    # core, q⁺ = exp(ω Δt) ⊗ q(σ); σ⁺ continued from σ (|σ⁺| > 1 is switched below with the
    # covariance)
    qn = const_rate_nb(mrp2q_nb(s), w, dt)
    sn = q2mrp_nb(qn)
    if qn[0] < 0.0:
        sn = mrp_shadow_nb(sn, 0.0)
    # linearisation at the start of the step
    F = np.zeros((6, 6))
    sw = s[0] * w[0] + s[1] * w[1] + s[2] * w[2]
    W = skew_nb(w)
    B = mrp_B_nb(s)
    for i in range(3):
        for j in range(3):
            F[i, j] = 0.5 * (s[i] * w[j] - w[i] * s[j] - W[i, j])
            F[i, 3 + j] = -0.25 * B[i, j]
        F[i, i] += 0.5 * sw
    Phi = np.eye(6) + F * dt + (0.5 * dt * dt) * (F @ F)
    # P <- Phi P Phi^T on the (σ, β) rows/columns only
    _left_right_nb(P, Phi, 6)
    n2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    qss = (1.0 + n2) ** 2 / 16.0 * (arw * arw * dt + rrw * rrw * dt ** 3 / 3.0)
    qsb = rrw * rrw * dt * dt / 2.0
    for i in range(3):
        P[i, i] += qss
        P[3 + i, 3 + i] += rrw * rrw * dt
        for j in range(3):
            P[i, 3 + j] += -0.25 * B[i, j] * qsb
            P[3 + j, i] += -0.25 * B[i, j] * qsb
    if q_param > 0.0:
        for i in range(6, n):
            P[i, i] += q_param * dt
    for i in range(3):
        x[i] = sn[i]
    for i in range(n):
        for j in range(i):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v
    mrp_switch_cov_nb(x, P)


@numba.njit(cache=True)
def star_tracker_update_nb(x, P, q_meas, sigma_rad, consider):
    """Star-tracker update in place from a measured attitude quaternion (inertial→body).

    Innovation δθ = 4 σ(C(σ_meas) C(σ̂)ᵀ) (rad, body axes), H_σ = 4 Bᵀ(σ̂)/(1+σ̂ᵀσ̂)²,
    R = σ_st² I.  Returns (NIS, ok).
    """
    n = x.shape[0]
    s = x[0:3].copy()
    qe = mrp2q_nb(s)
    # δq = q_meas ⊗ q_est⁻¹ (scalar first)
    for i in range(1, 4):
        qe[i] = -qe[i]
    nu = 4.0 * q2mrp_nb(qmul_nb(q_meas, qe))
    n2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    B = mrp_B_nb(s)
    H = np.zeros((3, n))
    for i in range(3):
        for j in range(3):
            H[i, j] = 4.0 * B[j, i] / (1.0 + n2) ** 2
    R = np.eye(3) * sigma_rad * sigma_rad
    return _mrp_update_nb(x, P, nu, H, R, consider)


@numba.njit(cache=True)
def vector_update_nb(x, P, z_b, r_n, sigma, consider):
    """Unit-vector update in place (eq. 4.9-4.11): z_B = C(σ) r_N + v, R = σ² I.
    Returns (NIS, ok)."""
    n = x.shape[0]
    s = x[0:3].copy()
    h = mv3_nb(mrp2dcm_nb(s), r_n)
    J = mrp_dcm_vec_jac_nb(s, r_n)
    H = np.zeros((3, n))
    for i in range(3):
        for j in range(3):
            H[i, j] = J[i, j]
    nu = z_b - h
    return _mrp_update_nb(x, P, nu, H, np.eye(3) * sigma * sigma, consider)


@dataclass(frozen=True)
class MRPEKFParams:
    """Tuning of :func:`run_mrp_ekf` (SI units).

    arw σ_v (rad/√s) and rrw σ_u (rad/s^1.5) of the gyro model; sigma_att0 initial attitude
    1σ (rad); sigma_bias0 initial bias 1σ (rad/s); sigma_vec unit-vector measurement 1σ
    (rad, small angle); sigma_st star-tracker 1σ per axis (rad).
    """

    arw: float = 2.9e-5
    rrw: float = 1e-8
    sigma_att0: float = np.radians(5.0)
    sigma_bias0: float = np.radians(0.1)
    sigma_vec: float = np.radians(1.0)
    sigma_st: float = np.radians(0.01)


def run_mrp_ekf(t, gyro, q0, params: MRPEKFParams = MRPEKFParams(), *, vec_body=None,
                vec_inertial=None, vec_valid=None, q_star=None, star_valid=None):
    """Run the MRP EKF with gyro bias over a recording.

    t (K,) s; gyro (K,3) rad/s body; q0 (4,) initial attitude estimate (inertial→body);
    vec_body/vec_inertial (K,J,3): J unit-vector measurements per sample (body) and their
    inertial references; vec_valid (K,J) bool; q_star (K,4) star-tracker quaternions and
    star_valid (K,) bool.  Returns dict ``sigma`` (K,3), ``bias`` (K,3) rad/s, ``P`` (K,6,6),
    ``nis`` (K,) of the last vector update of each sample (NaN when none).
    """
    t = np.ascontiguousarray(t, dtype=float)
    K = t.size
    W = np.ascontiguousarray(gyro, dtype=float)
    if W.shape != (K, 3):
        raise ValueError("gyro must have shape (len(t), 3)")
    if vec_body is None:
        Z = np.zeros((K, 0, 3))
        RN = np.zeros((K, 0, 3))
        zv = np.zeros((K, 0), dtype=bool)
    else:
        Z = np.ascontiguousarray(vec_body, dtype=float)
        RN = np.ascontiguousarray(vec_inertial, dtype=float)
        zv = np.ones(Z.shape[:2], dtype=bool) if vec_valid is None else np.asarray(vec_valid, bool)
    QS = np.zeros((K, 4)) if q_star is None else np.ascontiguousarray(q_star, dtype=float)
    sv = np.zeros(K, dtype=bool) if star_valid is None else np.asarray(star_valid, dtype=bool)
    if q_star is not None and star_valid is None:
        sv = np.ones(K, dtype=bool)
    x0 = np.zeros(6)
    x0[:3] = quat_to_mrp(np.asarray(q0, dtype=float))
    P0 = np.diag([params.sigma_att0 ** 2 / 16.0] * 3 + [params.sigma_bias0 ** 2] * 3)
    # a Python loop over the compiled kernels (shared with the calibration filter): a few µs
    # of call overhead per sample, but no separate whole-loop kernel to compile
    X = np.zeros((K, 6))
    Pd = np.zeros((K, 6, 6))
    NIS = np.full(K, np.nan)
    x, P = x0.copy(), P0.copy()
    cons = np.zeros(6, dtype=np.bool_)
    for k in range(K):
        if k > 0:
            mrp_propagate_nb(x, P, W[k - 1], t[k] - t[k - 1], params.arw, params.rrw, 0.0)
        if sv[k]:
            star_tracker_update_nb(x, P, QS[k], params.sigma_st, cons)
        for j in range(Z.shape[1]):
            if zv[k, j]:
                nis, ok = vector_update_nb(x, P, Z[k, j], RN[k, j], params.sigma_vec, cons)
                if ok:
                    NIS[k] = nis
        X[k] = x
        Pd[k] = P
    return {"sigma": X[:, :3], "bias": X[:, 3:6], "P": Pd, "nis": NIS}
