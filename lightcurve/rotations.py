"""Attitude parameterisations: quaternion, DCM, Euler axis/angle, rotation vector, Euler 3-2-1,
generalised Rodrigues parameters (GRP) and modified Rodrigues parameters (MRP).

Conventions (DESIGN.md; Bernard 2021 ch. 3, O'Keefe 2015 ch. 4)
-------------------------------------------------------------------
* Quaternion ``q = [q1, q2, q3, q4]`` with the **scalar first** (``q[..., 0]``), unit norm.
* Attitude is **inertial→body, passive**: ``v_b = A(q) v_I`` with (Bernard eq. 3.16–3.17)
  ``A(q) = (q1² − |q_v|²) I + 2 q_v q_vᵀ − 2 q1 [q_v×]``.
* Composition ``q ⊗ p`` (Bernard eq. 3.20) satisfies ``A(q ⊗ p) = A(q) A(p)``, so
  ``q_x→z = q_y→z ⊗ q_x→y``; ``q ⊙ p`` (eq. 3.21) satisfies ``A(q ⊙ p) = A(p) A(q)``.
* Rotation vector ``θ = φ ê`` maps to ``A = exp(−[θ×])`` (eq. 3.13) and
  ``q = [cos(φ/2), ê sin(φ/2)]`` (eq. 3.8–3.11).
* Euler 3-2-1 angles ``(φ, θ, ψ)`` about z, y, x: ``A = R1(ψ) R2(θ) R3(φ)`` (eq. 3.7), with the
  passive elementary rotations ``R3(φ) = [[c, s, 0], [−s, c, 0], [0, 0, 1]]`` etc.
* GRP (eq. 3.28–3.30): ``p = f q_v / (a + q1)``; default ``a = 1, f = 2(a + 1) = 4``; Gibbs is
  ``a = 0, f = 1``, MRP is ``a = f = 1``.
* MRP (O'Keefe eq. 4.1–4.4, Schaub & Junkins): ``σ = q_v/(1 + q1)``, shadow set
  ``σˢ = −σ/|σ|²``; DCM (O'Keefe eq. 4.21) ``C = I + (8[σ×]² − 4(1−|σ|²)[σ×])/(1+|σ|²)²``,
  identical to ``A(q)``.
* Attitude error (Bernard eq. 9.4–9.6): ``δq = q_true ⊗ q_est⁻¹``; the error angle is the
  rotation angle of ``δq`` and the error rotation vector its rotation vector (body axes).
* ``scipy.spatial.transform.Rotation`` stores quaternions scalar last and is *active*:
  :func:`to_scipy` returns the rotation ``R`` with ``R.as_matrix() == A(q)``, i.e.
  ``R.apply(v_I) == v_b``; ``R.inv()`` is the body→inertial (active attitude) rotation.

Every numpy-layer function accepts a single value (``(4,)`` or ``(3,)``) or stacked arrays
(``(..., 4)``, ``(..., 3)``) and raises ``ValueError`` naming the argument on wrong shapes, NaN or,
where a unit quaternion is required, a norm further than ``1e-6`` from one (no silent
renormalisation). The ``*_nb`` functions are ``numba.njit(cache=True)`` kernels on single 1-D
float64 arrays, for hot loops; they do not validate.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = [
    "UNIT_TOL",
    "skew",
    "check_unit_quat",
    "quat_mult",
    "quat_odot",
    "quat_conj",
    "quat_inv",
    "quat_normalize",
    "quat_average",
    "quat_identity",
    "quat_to_dcm",
    "dcm_to_quat",
    "quat_rotate",
    "quat_rotate_inv",
    "axis_angle_to_quat",
    "quat_to_axis_angle",
    "rotvec_to_quat",
    "quat_to_rotvec",
    "rotvec_to_dcm",
    "euler321_to_quat",
    "quat_to_euler321",
    "euler321_to_dcm",
    "quat_to_grp",
    "grp_to_quat",
    "quat_to_mrp",
    "mrp_to_quat",
    "mrp_shadow",
    "mrp_switch",
    "mrp_add",
    "mrp_compose",
    "mrp_to_dcm",
    "mrp_dcm_vec_jacobian",
    "attitude_error",
    "attitude_error_angle",
    "attitude_error_rotvec",
    "to_scipy",
    "from_scipy",
    "qmul_nb",
    "qrot_nb",
    "qrot_inv_nb",
    "q2dcm_nb",
    "q2grp_nb",
    "grp2q_nb",
    "qnormalize_nb",
    "rotvec2q_nb",
]

UNIT_TOL = 1e-6
"""Largest accepted deviation of a quaternion's norm from one."""


# ----------------------------------------------------------------------------------------
# validation helpers
# ----------------------------------------------------------------------------------------
def _as_array(x, last: int, name: str) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected an array of numbers, got {type(x).__name__}") from None
    if a.ndim == 0 or a.shape[-1] != last:
        raise ValueError(f"{name}: expected shape (..., {last}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return a


def _as_quat(q, name: str = "q", unit: bool = True) -> np.ndarray:
    a = _as_array(q, 4, name)
    if unit:
        n = np.linalg.norm(a, axis=-1)
        bad = np.abs(n - 1.0) > UNIT_TOL
        if np.any(bad):
            worst = float(np.max(np.abs(n - 1.0)))
            raise ValueError(
                f"{name}: not a unit quaternion (| |q| - 1 | = {worst:.3g} > {UNIT_TOL:g}); "
                "normalise it explicitly with quat_normalize if that is intended"
            )
    return a


def _as_vec3(v, name: str = "v") -> np.ndarray:
    return _as_array(v, 3, name)


def check_unit_quat(q, name: str = "q") -> np.ndarray:
    """Validate a unit quaternion (or stack) and return it as a float array.

    Raises ``ValueError`` for a wrong shape, NaN/inf, or a norm off by more than ``UNIT_TOL``.
    """
    return _as_quat(q, name, unit=True)


def skew(v) -> np.ndarray:
    """Cross-product matrix ``[v×]`` such that ``[v×] w = v × w``; shape (..., 3, 3)."""
    v = _as_vec3(v, "v")
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack(
        [np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2
    )


# ----------------------------------------------------------------------------------------
# quaternion algebra
# ----------------------------------------------------------------------------------------
def quat_identity(shape=()) -> np.ndarray:
    """Identity quaternion(s) ``[1, 0, 0, 0]`` of batch shape ``shape``."""
    q = np.zeros(tuple(np.atleast_1d(shape)) + (4,) if shape != () else (4,))
    q[..., 0] = 1.0
    return q


def _mult(q, p, sign):
    q0, qv = q[..., :1], q[..., 1:]
    p0, pv = p[..., :1], p[..., 1:]
    s = q0 * p0 - np.sum(qv * pv, axis=-1, keepdims=True)
    v = q0 * pv + p0 * qv + sign * np.cross(qv, pv)
    return np.concatenate([s, v], axis=-1)


def quat_mult(q, p) -> np.ndarray:
    """Quaternion product ``q ⊗ p`` (Bernard eq. 3.20): ``A(q ⊗ p) = A(q) A(p)``.

    ``q ⊗ p = [q1 p1 − q_v·p_v, q1 p_v + p1 q_v − q_v × p_v]``. Inputs need not be unit.
    """
    return _mult(_as_quat(q, "q", False), _as_quat(p, "p", False), -1.0)


def quat_odot(q, p) -> np.ndarray:
    """Quaternion product ``q ⊙ p`` (Bernard eq. 3.21): ``A(q ⊙ p) = A(p) A(q)``; equals ``p ⊗ q``."""
    return _mult(_as_quat(q, "q", False), _as_quat(p, "p", False), +1.0)


def quat_conj(q) -> np.ndarray:
    """Conjugate ``[q1, −q_v]``; the inverse of a unit quaternion."""
    q = _as_quat(q, "q", False)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_inv(q) -> np.ndarray:
    """Inverse ``q* / |q|²`` (any nonzero quaternion)."""
    q = _as_quat(q, "q", False)
    n2 = np.sum(q * q, axis=-1, keepdims=True)
    if np.any(n2 == 0):
        raise ValueError("q: the zero quaternion has no inverse")
    return quat_conj(q) / n2


def quat_normalize(q, positive_scalar: bool = True) -> np.ndarray:
    """Scale to unit norm; with ``positive_scalar`` flip the sign so that ``q1 >= 0``.

    ``q`` and ``−q`` are the same attitude; the sign convention makes comparisons and
    round trips well defined. Raises ``ValueError`` for a (near-)zero quaternion.
    """
    q = _as_quat(q, "q", False)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n < 1e-12):
        raise ValueError("q: cannot normalise a zero quaternion")
    out = q / n
    if positive_scalar:
        out = np.where(out[..., :1] < 0, -out, out)
    return out


def quat_to_dcm(q) -> np.ndarray:
    """Attitude matrix ``A(q)`` (inertial→body; Bernard eq. 3.16–3.17), shape (..., 3, 3)."""
    q = _as_quat(q)
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    A = np.empty(q.shape[:-1] + (3, 3))
    A[..., 0, 0] = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
    A[..., 0, 1] = 2 * (q1 * q2 + q0 * q3)
    A[..., 0, 2] = 2 * (q1 * q3 - q0 * q2)
    A[..., 1, 0] = 2 * (q1 * q2 - q0 * q3)
    A[..., 1, 1] = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
    A[..., 1, 2] = 2 * (q2 * q3 + q0 * q1)
    A[..., 2, 0] = 2 * (q1 * q3 + q0 * q2)
    A[..., 2, 1] = 2 * (q2 * q3 - q0 * q1)
    A[..., 2, 2] = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
    return A


def dcm_to_quat(A, orthonormal_tol: float = 1e-6) -> np.ndarray:
    """Unit quaternion (``q1 >= 0``) of an attitude matrix, by Shepperd's method.

    Robust for every rotation angle including 180°. Raises ``ValueError`` when ``A`` is not a
    proper orthonormal matrix within ``orthonormal_tol``.
    """
    try:
        A = np.asarray(A, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("A: expected an array of numbers") from None
    if A.ndim < 2 or A.shape[-2:] != (3, 3):
        raise ValueError(f"A: expected shape (..., 3, 3), got {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError("A: contains NaN or infinite values")
    err = np.abs(np.einsum("...ji,...jk->...ik", A, A) - np.eye(3)).max(axis=(-2, -1))
    det = np.linalg.det(A)
    if np.any(err > orthonormal_tol) or np.any(det < 0):
        raise ValueError("A: not a proper orthonormal rotation matrix "
                         f"(max |AᵀA − I| = {float(np.max(err)):.3g}, det min {float(np.min(det)):.3g})")
    tr = A[..., 0, 0] + A[..., 1, 1] + A[..., 2, 2]
    cand = np.stack([tr, A[..., 0, 0], A[..., 1, 1], A[..., 2, 2]], -1)
    k = np.argmax(cand, axis=-1)
    q = np.empty(A.shape[:-2] + (4,))
    # case 0: scalar largest
    s = 0.5 * np.sqrt(np.maximum(1.0 + tr, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        c0 = np.stack([s, (A[..., 1, 2] - A[..., 2, 1]) / (4 * s),
                       (A[..., 2, 0] - A[..., 0, 2]) / (4 * s), (A[..., 0, 1] - A[..., 1, 0]) / (4 * s)], -1)
        s1 = 0.5 * np.sqrt(np.maximum(1.0 + 2 * A[..., 0, 0] - tr, 0.0))
        c1 = np.stack([(A[..., 1, 2] - A[..., 2, 1]) / (4 * s1), s1,
                       (A[..., 0, 1] + A[..., 1, 0]) / (4 * s1), (A[..., 0, 2] + A[..., 2, 0]) / (4 * s1)], -1)
        s2 = 0.5 * np.sqrt(np.maximum(1.0 + 2 * A[..., 1, 1] - tr, 0.0))
        c2 = np.stack([(A[..., 2, 0] - A[..., 0, 2]) / (4 * s2), (A[..., 0, 1] + A[..., 1, 0]) / (4 * s2),
                       s2, (A[..., 1, 2] + A[..., 2, 1]) / (4 * s2)], -1)
        s3 = 0.5 * np.sqrt(np.maximum(1.0 + 2 * A[..., 2, 2] - tr, 0.0))
        c3 = np.stack([(A[..., 0, 1] - A[..., 1, 0]) / (4 * s3), (A[..., 0, 2] + A[..., 2, 0]) / (4 * s3),
                       (A[..., 1, 2] + A[..., 2, 1]) / (4 * s3), s3], -1)
    allc = np.stack([c0, c1, c2, c3], -2)
    q = np.take_along_axis(allc, k[..., None, None], axis=-2)[..., 0, :]
    return quat_normalize(q)


def quat_rotate(q, v) -> np.ndarray:
    """Transform a vector from inertial to body axes: ``v_b = A(q) v_I`` (Bernard eq. 3.26).

    ``q`` (..., 4) and ``v`` (..., 3) broadcast against each other.
    """
    q = _as_quat(q)
    v = _as_vec3(v, "v")
    q0, qv = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(qv, v)
    # A(q) v = v − q1 (2 q_v×v) + q_v×(2 q_v×v)
    return v - q0 * t + np.cross(qv, t)


def quat_rotate_inv(q, v) -> np.ndarray:
    """Transform a vector from body to inertial axes: ``v_I = A(q)ᵀ v_b``."""
    q = _as_quat(q)
    v = _as_vec3(v, "v")
    q0, qv = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(qv, v)
    return v + q0 * t + np.cross(qv, t)


# ----------------------------------------------------------------------------------------
# axis/angle and rotation vector
# ----------------------------------------------------------------------------------------
def axis_angle_to_quat(axis, angle_rad) -> np.ndarray:
    """Quaternion of a rotation by ``angle_rad`` about unit ``axis`` (Bernard eq. 3.8–3.11).

    The axis must be a unit vector (checked to 1e-6). The result has ``q1 = cos(φ/2)``
    (negative for φ > π).
    """
    e = _as_vec3(axis, "axis")
    n = np.linalg.norm(e, axis=-1)
    if np.any(np.abs(n - 1.0) > UNIT_TOL):
        raise ValueError("axis: not a unit vector")
    phi = np.asarray(angle_rad, dtype=float)
    if not np.all(np.isfinite(phi)):
        raise ValueError("angle_rad: contains NaN or infinite values")
    h = 0.5 * phi[..., None]
    return np.concatenate([np.cos(h), np.sin(h) * e], axis=-1)


def quat_to_axis_angle(q):
    """Euler axis ``ê`` (...,3) and angle ``φ ∈ [0, π]`` (rad) of a unit quaternion.

    ``q`` and ``−q`` give the same result. At φ = 0 the axis is undefined and ``[1, 0, 0]`` is
    returned; at φ = π the axis sign is that of the largest component of ``q_v`` made positive.
    """
    q = quat_normalize(_as_quat(q))
    n = np.linalg.norm(q[..., 1:], axis=-1)
    phi = 2.0 * np.arctan2(n, q[..., 0])
    safe = n > 1e-15
    with np.errstate(invalid="ignore", divide="ignore"):
        e = np.where(safe[..., None], q[..., 1:] / np.where(safe, n, 1.0)[..., None], 0.0)
    e = np.where(safe[..., None], e, np.array([1.0, 0.0, 0.0]))
    return e, phi


def rotvec_to_quat(theta) -> np.ndarray:
    """Quaternion of rotation vector ``θ = φ ê`` (rad): ``[cos(φ/2), ê sin(φ/2)]``; any |θ|."""
    th = _as_vec3(theta, "theta")
    phi = np.linalg.norm(th, axis=-1, keepdims=True)
    h = 0.5 * phi
    # sin(φ/2)/φ with its series near zero
    with np.errstate(invalid="ignore", divide="ignore"):
        sinc = np.where(phi > 1e-6, np.sin(h) / np.where(phi > 0, phi, 1.0), 0.5 - phi**2 / 48.0)
    return np.concatenate([np.cos(h), sinc * th], axis=-1)


def quat_to_rotvec(q) -> np.ndarray:
    """Rotation vector ``θ = φ ê`` with ``φ ∈ [0, π]`` of a unit quaternion (sign-independent)."""
    q = quat_normalize(_as_quat(q))
    n = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    q0 = q[..., :1]
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        fac = np.where(n > 1e-8, 2.0 * np.arctan2(n, q0) / np.where(n > 0, n, 1.0),
                       2.0 / q0 * (1.0 - n**2 / (3.0 * q0**2)))
    return fac * q[..., 1:]


def rotvec_to_dcm(theta) -> np.ndarray:
    """``A = exp(−[θ×]) = cos φ I + (1−cos φ) ê êᵀ − sin φ [ê×]`` (Bernard eq. 3.13)."""
    th = _as_vec3(theta, "theta")
    phi = np.linalg.norm(th, axis=-1)[..., None, None]
    K = skew(th)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(phi > 1e-6, np.sin(phi) / np.where(phi > 0, phi, 1), 1.0 - phi**2 / 6.0)
        c = np.where(phi > 1e-6, (1.0 - np.cos(phi)) / np.where(phi > 0, phi, 1) ** 2, 0.5 - phi**2 / 24.0)
    # exp(−K) = I − s K + c K²
    return np.eye(3) - s * K + c * (K @ K)


# ----------------------------------------------------------------------------------------
# Euler 3-2-1
# ----------------------------------------------------------------------------------------
def euler321_to_dcm(angles_rad) -> np.ndarray:
    """``A = R1(ψ) R2(θ) R3(φ)`` for angles ``(φ, θ, ψ)`` about z, y, x in rad (Bernard eq. 3.7)."""
    a = _as_vec3(angles_rad, "angles_rad")
    cf, sf = np.cos(a[..., 0]), np.sin(a[..., 0])
    ct, st = np.cos(a[..., 1]), np.sin(a[..., 1])
    cp, sp = np.cos(a[..., 2]), np.sin(a[..., 2])
    A = np.empty(a.shape[:-1] + (3, 3))
    A[..., 0, 0] = ct * cf
    A[..., 0, 1] = ct * sf
    A[..., 0, 2] = -st
    A[..., 1, 0] = sp * st * cf - cp * sf
    A[..., 1, 1] = sp * st * sf + cp * cf
    A[..., 1, 2] = sp * ct
    A[..., 2, 0] = cp * st * cf + sp * sf
    A[..., 2, 1] = cp * st * sf - sp * cf
    A[..., 2, 2] = cp * ct
    return A


def euler321_to_quat(angles_rad) -> np.ndarray:
    """Quaternion of 3-2-1 angles ``(φ, θ, ψ)`` (rad): ``q_x(ψ) ⊗ q_y(θ) ⊗ q_z(φ)``, ``q1 >= 0``."""
    a = _as_vec3(angles_rad, "angles_rad")
    h = 0.5 * a
    z = np.zeros(a.shape[:-1])
    qz = np.stack([np.cos(h[..., 0]), z, z, np.sin(h[..., 0])], -1)
    qy = np.stack([np.cos(h[..., 1]), z, np.sin(h[..., 1]), z], -1)
    qx = np.stack([np.cos(h[..., 2]), np.sin(h[..., 2]), z, z], -1)
    return quat_normalize(quat_mult(qx, quat_mult(qy, qz)))


def quat_to_euler321(q) -> np.ndarray:
    """3-2-1 angles ``(φ, θ, ψ)`` in rad, φ, ψ ∈ (−π, π], θ ∈ [−π/2, π/2].

    At gimbal lock (|θ| = π/2) φ and ψ are not unique; ψ = 0 is returned there.
    """
    A = quat_to_dcm(q)
    ct = np.hypot(A[..., 0, 0], A[..., 0, 1])
    theta = np.arctan2(-A[..., 0, 2], ct)  # better conditioned than arcsin near ±90°
    lock = ct < 1e-12
    phi = np.where(lock, np.arctan2(-A[..., 1, 0], A[..., 1, 1]), np.arctan2(A[..., 0, 1], A[..., 0, 0]))
    psi = np.where(lock, 0.0, np.arctan2(A[..., 1, 2], A[..., 2, 2]))
    return np.stack([phi, theta, psi], -1)


# ----------------------------------------------------------------------------------------
# GRP and MRP
# ----------------------------------------------------------------------------------------
def _grp_af(a, f):
    a = float(a)
    f = 2.0 * (a + 1.0) if f is None else float(f)
    if not (0.0 <= a <= 1.0) or f <= 0:
        raise ValueError(f"GRP parameters: need 0 <= a <= 1 and f > 0, got a={a}, f={f}")
    return a, f


def quat_to_grp(q, a: float = 1.0, f: float | None = None) -> np.ndarray:
    """Generalised Rodrigues parameters ``p = f q_v/(a + q1)`` (Bernard eq. 3.28).

    Default ``a = 1, f = 2(a+1) = 4`` (then ``|p| ≈ φ`` for small angles). Singular at
    ``q1 = −a``; the sign of ``q`` is kept as given (flip it beforehand to pick the short way).
    """
    a, f = _grp_af(a, f)
    q = _as_quat(q)
    den = a + q[..., :1]
    if np.any(np.abs(den) < 1e-12):
        raise ValueError("q: GRP singular at q1 = -a (rotation of 360 degrees for a = 1)")
    return f * q[..., 1:] / den


def grp_to_quat(p, a: float = 1.0, f: float | None = None) -> np.ndarray:
    """Quaternion from GRP (Bernard eq. 3.29–3.30).

    ``q1 = (−a|p|² + f √(f² + (1−a²)|p|²)) / (f² + |p|²)``, ``q_v = (a + q1) p / f``.
    """
    a, f = _grp_af(a, f)
    p = _as_vec3(p, "p")
    n2 = np.sum(p * p, axis=-1, keepdims=True)
    q0 = (-a * n2 + f * np.sqrt(f * f + (1.0 - a * a) * n2)) / (f * f + n2)
    return np.concatenate([q0, (a + q0) * p / f], axis=-1)


def quat_to_mrp(q) -> np.ndarray:
    """MRP ``σ = q_v/(1 + q1)`` of a unit quaternion, taking the sign with ``q1 >= 0``, so |σ| ≤ 1."""
    q = quat_normalize(_as_quat(q))
    return q[..., 1:] / (1.0 + q[..., :1])


def mrp_to_quat(s) -> np.ndarray:
    """Unit quaternion of an MRP: ``q1 = (1−|σ|²)/(1+|σ|²)``, ``q_v = 2σ/(1+|σ|²)``."""
    s = _as_vec3(s, "sigma")
    n2 = np.sum(s * s, axis=-1, keepdims=True)
    return np.concatenate([(1.0 - n2) / (1.0 + n2), 2.0 * s / (1.0 + n2)], axis=-1)


def mrp_shadow(s) -> np.ndarray:
    """Shadow MRP set ``σˢ = −σ/|σ|²`` (same attitude; O'Keefe eq. 4.2). Undefined at σ = 0."""
    s = _as_vec3(s, "sigma")
    n2 = np.sum(s * s, axis=-1, keepdims=True)
    if np.any(n2 == 0):
        raise ValueError("sigma: the shadow set of the zero MRP is at infinity")
    return -s / n2


def mrp_switch(s, threshold: float = 1.0) -> np.ndarray:
    """Replace σ by its shadow set where ``|σ| > threshold`` (default 1), keeping |σ| ≤ 1."""
    s = _as_vec3(s, "sigma")
    n2 = np.sum(s * s, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n2 > threshold**2, -s / np.where(n2 > 0, n2, 1.0), s)


def mrp_compose(s_outer, s_inner) -> np.ndarray:
    """MRP of ``C(σ_outer) C(σ_inner)`` (O'Keefe eq. 4.3–4.4; Schaub & Junkins eq. 3.152).

    For ``[FN] = [FB][BN]`` call ``mrp_compose(σ_FB, σ_BN)``. Where the formula's denominator
    vanishes (a 360° composite), the inner set is replaced by its shadow. The result is
    switched to |σ| ≤ 1.
    """
    s2 = _as_vec3(s_outer, "s_outer")
    s1 = _as_vec3(s_inner, "s_inner")
    s1, s2 = np.broadcast_arrays(s1, s2)
    s1 = s1.copy()

    def _den(a, b):
        return 1.0 + np.sum(a * a, -1) * np.sum(b * b, -1) - 2.0 * np.sum(a * b, -1)

    den = _den(s1, s2)
    small = np.abs(den) < 1e-6
    if np.any(small):
        n2 = np.sum(s1 * s1, -1, keepdims=True)
        s1 = np.where(small[..., None] & (n2 > 0), -s1 / np.where(n2 > 0, n2, 1.0), s1)
        den = _den(s1, s2)
    n1 = np.sum(s1 * s1, -1, keepdims=True)
    n2 = np.sum(s2 * s2, -1, keepdims=True)
    num = (1.0 - n1) * s2 + (1.0 - n2) * s1 - 2.0 * np.cross(s2, s1)
    return mrp_switch(num / den[..., None])


def mrp_add(s1, s2) -> np.ndarray:
    """MRP of the rotation ``σ1`` followed by ``σ2``: ``C(result) = C(σ2) C(σ1)``.

    (The Basilisk ``addMRP`` ordering; ``mrp_add(σ_BN, σ_FB) = σ_FN``.)
    """
    return mrp_compose(s2, s1)


def mrp_to_dcm(s) -> np.ndarray:
    """``C(σ) = I + (8[σ×]² − 4(1 − |σ|²)[σ×]) / (1 + |σ|²)²`` (O'Keefe eq. 4.21); equals A(q)."""
    s = _as_vec3(s, "sigma")
    n2 = np.sum(s * s, axis=-1)[..., None, None]
    S = skew(s)
    return np.eye(3) + (8.0 * (S @ S) - 4.0 * (1.0 - n2) * S) / (1.0 + n2) ** 2


def mrp_dcm_vec_jacobian(s, a) -> np.ndarray:
    """Jacobian ``∂(C(σ) a)/∂σ`` (3×3), the derivative of ``[BN] a`` used by O'Keefe eq. 4.32.

    Derivation: with ``s² = |σ|²`` and ``N = 8(σ(σ·a) − s² a) − 4(1−s²)(σ×a)``,
    ``C a = a + N/(1+s²)²``; ``∂N/∂σ = 8((σ·a)I + σaᵀ − 2aσᵀ) + 8(σ×a)σᵀ + 4(1−s²)[a×]``;
    ``∂(Ca)/∂σ = ∂N/∂σ/(1+s²)² − 4Nσᵀ/(1+s²)³``. Verified against finite differences in tests.
    """
    s = _as_vec3(s, "sigma")
    a = _as_vec3(a, "a")
    s, a = np.broadcast_arrays(s, a)
    n2 = np.sum(s * s, -1)[..., None, None]
    sa = np.sum(s * a, -1)[..., None, None]
    sxa = np.cross(s, a)
    outer = lambda u, v: u[..., :, None] * v[..., None, :]  # noqa: E731
    N = 8.0 * (s * sa[..., 0] - a * n2[..., 0]) - 4.0 * (1.0 - n2[..., 0]) * sxa
    dN = (8.0 * (sa * np.eye(3) + outer(s, a) - 2.0 * outer(a, s)) + 8.0 * outer(sxa, s)
          + 4.0 * (1.0 - n2) * skew(a))
    return dN / (1.0 + n2) ** 2 - 4.0 * outer(N, s) / (1.0 + n2) ** 3


# ----------------------------------------------------------------------------------------
# attitude error
# ----------------------------------------------------------------------------------------
def attitude_error(q_true, q_est) -> np.ndarray:
    """Error quaternion ``δq = q_true ⊗ q_est⁻¹`` (Bernard eq. 9.4), sign chosen with δq1 >= 0."""
    q_true = _as_quat(q_true, "q_true")
    q_est = _as_quat(q_est, "q_est")
    return quat_normalize(_mult(q_true, q_est * np.array([1.0, -1, -1, -1]), -1.0))


def attitude_error_angle(q_true, q_est) -> np.ndarray:
    """Total attitude error angle (rad, in [0, π]) between two attitudes (Bernard eq. 9.5)."""
    dq = attitude_error(q_true, q_est)
    return 2.0 * np.arctan2(np.linalg.norm(dq[..., 1:], axis=-1), np.abs(dq[..., 0]))


def attitude_error_rotvec(q_true, q_est) -> np.ndarray:
    """Error rotation vector (rad, body axes) of ``δq`` (Bernard eq. 9.6; exact, not small-angle)."""
    return quat_to_rotvec(attitude_error(q_true, q_est))


def quat_average(q, weights=None) -> np.ndarray:
    """Weighted average attitude of quaternions q (n,4) → (4,), ``q1 >= 0``.

    The maximiser of ``Σ wᵢ (qᵀqᵢ)²`` over unit q: the eigenvector of ``M = Σ wᵢ qᵢ qᵢᵀ`` with the
    largest eigenvalue (Markley, Cheng, Crassidis & Oshman 2007, "Averaging quaternions",
    JGCD 30(4), eq. 12–13). Independent of the signs of the qᵢ (q and −q are one attitude).
    """
    q = _as_quat(q).reshape(-1, 4)
    w = np.ones(q.shape[0]) if weights is None else np.asarray(weights, float).reshape(-1)
    if w.shape[0] != q.shape[0] or not np.all(w >= 0) or not w.sum() > 0:
        raise ValueError("weights must be non-negative, one per quaternion, not all zero")
    M = (q * w[:, None]).T @ q
    _, vec = np.linalg.eigh(M)
    return quat_normalize(vec[:, -1])


# ----------------------------------------------------------------------------------------
# scipy interoperability
# ----------------------------------------------------------------------------------------
def to_scipy(q):
    """``scipy.spatial.transform.Rotation`` ``R`` with ``R.as_matrix() == A(q)``.

    So ``R.apply(v_I)`` gives body components; ``R.inv()`` is the active body→inertial rotation
    (the orientation of the body axes in inertial space). scipy stores quaternions scalar last.
    """
    from scipy.spatial.transform import Rotation

    q = _as_quat(q)
    # scipy's matrix for scalar-last [x, y, z, w] is A(q)ᵀ, so A(q) belongs to the conjugate.
    return Rotation.from_quat(np.concatenate([-q[..., 1:], q[..., :1]], axis=-1))


def from_scipy(rot) -> np.ndarray:
    """Inverse of :func:`to_scipy`: the quaternion (``q1 >= 0``) with ``A(q) == rot.as_matrix()``."""
    x = np.asarray(rot.as_quat(), dtype=float)
    return quat_normalize(np.concatenate([x[..., 3:], -x[..., :3]], axis=-1))


# ----------------------------------------------------------------------------------------
# numba kernels (single 1-D float64 arrays; no validation)
# ----------------------------------------------------------------------------------------
@njit(cache=True, fastmath=False)
def qmul_nb(q, p):
    """``q ⊗ p`` for 1-D arrays of length 4 (scalar first)."""
    out = np.empty(4)
    out[0] = q[0] * p[0] - q[1] * p[1] - q[2] * p[2] - q[3] * p[3]
    out[1] = q[0] * p[1] + p[0] * q[1] - (q[2] * p[3] - q[3] * p[2])
    out[2] = q[0] * p[2] + p[0] * q[2] - (q[3] * p[1] - q[1] * p[3])
    out[3] = q[0] * p[3] + p[0] * q[3] - (q[1] * p[2] - q[2] * p[1])
    return out


@njit(cache=True, inline="always")
def qrot_xyz_nb(q0, q1, q2, q3, vx, vy, vz):
    """``A(q) v`` (inertial→body, passive, Bernard eq. 3.16) on scalars → ``(x, y, z)``;
    ``q = [q0, q1, q2, q3]`` scalar first. For kernels that keep vectors in registers."""
    tx = 2.0 * (q2 * vz - q3 * vy)
    ty = 2.0 * (q3 * vx - q1 * vz)
    tz = 2.0 * (q1 * vy - q2 * vx)
    return (vx - q0 * tx + (q2 * tz - q3 * ty),
            vy - q0 * ty + (q3 * tx - q1 * tz),
            vz - q0 * tz + (q1 * ty - q2 * tx))


@njit(cache=True)
def qrot_nb(q, v):
    """``A(q) v`` (inertial→body) for 1-D arrays."""
    x, y, z = qrot_xyz_nb(q[0], q[1], q[2], q[3], v[0], v[1], v[2])
    out = np.empty(3)
    out[0] = x
    out[1] = y
    out[2] = z
    return out


@njit(cache=True)
def qrot_inv_nb(q, v):
    """``A(q)ᵀ v`` (body→inertial) for 1-D arrays."""
    tx = 2.0 * (q[2] * v[2] - q[3] * v[1])
    ty = 2.0 * (q[3] * v[0] - q[1] * v[2])
    tz = 2.0 * (q[1] * v[1] - q[2] * v[0])
    out = np.empty(3)
    out[0] = v[0] + q[0] * tx + (q[2] * tz - q[3] * ty)
    out[1] = v[1] + q[0] * ty + (q[3] * tx - q[1] * tz)
    out[2] = v[2] + q[0] * tz + (q[1] * ty - q[2] * tx)
    return out


@njit(cache=True)
def q2dcm_nb(q):
    """``A(q)`` as a 3×3 array."""
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    A = np.empty((3, 3))
    A[0, 0] = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
    A[0, 1] = 2 * (q1 * q2 + q0 * q3)
    A[0, 2] = 2 * (q1 * q3 - q0 * q2)
    A[1, 0] = 2 * (q1 * q2 - q0 * q3)
    A[1, 1] = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
    A[1, 2] = 2 * (q2 * q3 + q0 * q1)
    A[2, 0] = 2 * (q1 * q3 + q0 * q2)
    A[2, 1] = 2 * (q2 * q3 - q0 * q1)
    A[2, 2] = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
    return A


@njit(cache=True)
def q2grp_nb(q, a, f):
    """GRP ``f q_v/(a + q1)`` of one quaternion."""
    d = a + q[0]
    out = np.empty(3)
    out[0] = f * q[1] / d
    out[1] = f * q[2] / d
    out[2] = f * q[3] / d
    return out


@njit(cache=True)
def grp2q_nb(p, a, f):
    """Quaternion of one GRP vector (Bernard eq. 3.29–3.30)."""
    n2 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2]
    q0 = (-a * n2 + f * np.sqrt(f * f + (1.0 - a * a) * n2)) / (f * f + n2)
    out = np.empty(4)
    out[0] = q0
    c = (a + q0) / f
    out[1] = c * p[0]
    out[2] = c * p[1]
    out[3] = c * p[2]
    return out


@njit(cache=True)
def qnormalize_nb(q):
    """Unit quaternion with non-negative scalar part."""
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if q[0] < 0:
        n = -n
    out = np.empty(4)
    for i in range(4):
        out[i] = q[i] / n
    return out


@njit(cache=True)
def rotvec2q_nb(th):
    """Quaternion ``[cos(φ/2), ê sin(φ/2)]`` of a rotation vector."""
    phi = np.sqrt(th[0] * th[0] + th[1] * th[1] + th[2] * th[2])
    out = np.empty(4)
    out[0] = np.cos(0.5 * phi)
    if phi > 1e-6:
        s = np.sin(0.5 * phi) / phi
    else:
        s = 0.5 - phi * phi / 48.0
    out[1] = s * th[0]
    out[2] = s * th[1]
    out[3] = s * th[2]
    return out
