"""Rotation algebra on plain floats and float64 arrays (numba kernels, no validation).

Conventions (DESIGN.md; Bernard 2021 ch. 3, O'Keefe 2015 §4.1)
---------------------------------------------------------------
* Quaternion ``q = [q1, q2, q3, q4]``, scalar first, unit norm, **inertial→body passive**:
  ``v_b = A(q) v_I`` with ``A(q) = (q1² − |q_v|²) I − 2 q1 [q_v×] + 2 q_v q_vᵀ``
  (Bernard eq. 3.16–3.17).
* Product ``q ⊗ p`` (Bernard eq. 3.20): ``A(q ⊗ p) = A(q) A(p)``;
  ``q ⊗ p = [q1 p1 − q_v·p_v, q1 p_v + p1 q_v − q_v × p_v]``.
* Rotation vector ``θ = φ ê``: ``A = exp(−[θ×])`` (Bernard eq. 3.13), ``q = [cos φ/2, ê sin φ/2]``.
* GRP (Bernard eq. 3.28–3.30): ``p = f q_v/(a + q1)``, inverse
  ``q1 = (−a|p|² + f √(f² + (1 − a²)|p|²))/(f² + |p|²)``, ``q_v = (a + q1) p / f``.
* MRP (O'Keefe eq. 4.1–4.4, 4.21): ``σ = q_v/(1 + q1)``, shadow ``σˢ = −σ/|σ|²``,
  kinematics ``σ̇ = ¼ B(σ) ω``, composition eq. 4.4, DCM eq. 4.21.
* Euler 3-2-1 ``(φ, θ, ψ)`` about z, y, x: ``A = R1(ψ) R2(θ) R3(φ)`` (Bernard eq. 3.7).

Three kinds of kernels:

* ``*_xyz`` — ``inline="always"`` functions on scalars returning tuples, for hot loops that
  keep vectors in registers (particles, sigma points, facets);
* ``*_nb`` — one value on 1-D arrays;
* ``*_batch_nb`` — row-wise over (N, 4) / (N, 3) arrays into a given output, used by the array
  layer :mod:`lightcurve.rotations` (validation, broadcasting) so that each equation exists once.

Every kernel evaluates its equation with the same arithmetic in every form (same operation
order), so the three forms agree bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .specialise import jit_copy

__all__ = [
    "qmul_xyz", "qrot_xyz_nb", "qrot_inv_xyz", "rotvec2q_xyz", "rotvec2q_sc_xyz",
    "q2grp_xyz", "grp2q_xyz",
    "skew_nb", "qmul_nb", "qmul_into_nb", "qrot_nb", "qrot_inv_nb", "q2dcm_nb", "dcm2q_nb",
    "qnormalize_nb", "normalize_into_nb", "rotvec2q_nb", "q2rotvec_nb", "q2grp_nb", "grp2q_nb",
    "grp_rel_nb", "from_grp_rel_nb", "q2mrp_nb", "mrp2q_nb", "mrp_shadow_nb", "mrp_compose_nb",
    "mrp2dcm_nb", "mrp_B_nb", "mrp_dcm_vec_jac_nb", "euler321_to_dcm_nb", "euler321_to_q_nb",
    "q2euler321_nb", "perturb_rotvec_nb",
    "qmul_batch_nb", "qrot_batch_nb", "q2dcm_batch_nb", "dcm2q_batch_nb", "rotvec2q_batch_nb",
    "q2rotvec_batch_nb", "q2grp_batch_nb", "grp2q_batch_nb", "q2mrp_batch_nb",
    "mrp2q_batch_nb", "mrp_compose_batch_nb", "mrp2dcm_batch_nb", "euler321_to_dcm_batch_nb",
    "q2euler321_batch_nb", "skew_batch_nb", "euler321_to_q_batch_nb", "mrp_shadow_batch_nb",
    "mrp_dcm_vec_jac_batch_nb",
]


# ----------------------------------------------------------------------------------------
# templates of the array-valued forms (one loop each; every copy binds its own ``_kernel``)
# ----------------------------------------------------------------------------------------
def _new_filled(x):
    out = np.empty(_shape)  # noqa: F821  (bound per copy, see _filled_by)
    _kernel(x, out)  # noqa: F821
    return out


def _value_rows(X, out):
    for i in range(X.shape[0]):
        out[i] = _kernel(X[i])  # noqa: F821


def _value_rows2(X, Y, out):
    for i in range(X.shape[0]):
        out[i] = _kernel(X[i], Y[i])  # noqa: F821


def _into_rows(X, out):
    for i in range(X.shape[0]):
        _kernel(X[i], out[i])  # noqa: F821


def _filled_by(kernel, shape, name, doc):
    """``name(x)``: a new array of ``shape`` filled by ``kernel(x, out)`` (:func:`_new_filled`)."""
    return jit_copy(_new_filled, name, doc, {"cache": True}, _kernel=kernel, _shape=shape)


def _row_kernels(template, *kernels):
    """The row-wise forms of ``kernels``, one compiled copy of ``template`` each
    (:func:`~lightcurve.core.specialise.jit_copy`): :func:`_value_rows`
    ``out[i] = kernel(X[i])``, :func:`_value_rows2` ``out[i] = kernel(X[i], Y[i])`` or
    :func:`_into_rows` ``kernel(X[i], out[i])``. The form of ``name_nb`` or ``name_into_nb`` is
    ``name_batch_nb``."""
    out = []
    for k in kernels:
        stem = k.__name__.removesuffix("_nb").removesuffix("_into")
        name = stem + "_batch_nb"
        doc = (f"Row-wise :func:`{k.__name__}` ({template.__name__.strip('_')}: the rows of "
               "(N, …) arrays into ``out``); equation and units as there.")
        out.append(jit_copy(template, name, doc, {"cache": True}, _kernel=k))
    return tuple(out)


# ----------------------------------------------------------------------------------------
# scalar forms (inline)
# ----------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def qmul_xyz(a0, a1, a2, a3, b0, b1, b2, b3):
    """``a ⊗ b`` (Bernard eq. 3.20) on scalars → 4-tuple (scalar first).

    ``[a1 b1 − a_v·b_v, a1 b_v + b1 a_v − a_v × b_v]``; the scalar part is evaluated as
    ``a1 b1 − (a2 b2 + a3 b3 + a4 b4)``.
    """
    return (a0 * b0 - (a1 * b1 + a2 * b2 + a3 * b3),
            a0 * b1 + b0 * a1 - (a2 * b3 - a3 * b2),
            a0 * b2 + b0 * a2 - (a3 * b1 - a1 * b3),
            a0 * b3 + b0 * a3 - (a1 * b2 - a2 * b1))


@njit(cache=True, inline="always")
def qrot_xyz_nb(q0, q1, q2, q3, vx, vy, vz):
    """``A(q) v`` (inertial→body, passive; Bernard eq. 3.16) on scalars → ``(x, y, z)``.

    Evaluated as ``v − q1 t + q_v × t`` with ``t = 2 q_v × v``.
    """
    tx = 2.0 * (q2 * vz - q3 * vy)
    ty = 2.0 * (q3 * vx - q1 * vz)
    tz = 2.0 * (q1 * vy - q2 * vx)
    return (vx - q0 * tx + (q2 * tz - q3 * ty),
            vy - q0 * ty + (q3 * tx - q1 * tz),
            vz - q0 * tz + (q1 * ty - q2 * tx))


@njit(cache=True, inline="always")
def qrot_inv_xyz(q0, q1, q2, q3, vx, vy, vz):
    """``A(q)ᵀ v`` (body→inertial) on scalars → ``(x, y, z)``: ``A(q)ᵀ = A(q⁻¹)`` and
    ``q⁻¹ = [q1, −q_v]`` is the rotation of ``[−q1, q_v]`` (Bernard eq. 3.17 is even in q), so
    :func:`qrot_xyz_nb` of ``(−q1, q_v)``: ``v + q1 t + q_v × t``."""
    return qrot_xyz_nb(-q0, q1, q2, q3, vx, vy, vz)


@njit(cache=True, inline="always")
def rotvec2q_xyz(tx, ty, tz):
    """Quaternion ``[cos(φ/2), θ sin(φ/2)/φ]`` of the rotation vector θ (rad; Bernard eq.
    3.8–3.13), with the series ``sin(φ/2)/φ ≈ ½ − φ²/48`` below φ = 1e-6 → 4-tuple."""
    phi = math.sqrt(tx * tx + ty * ty + tz * tz)
    return rotvec2q_sc_xyz(tx, ty, tz, phi, math.sin(0.5 * phi), math.cos(0.5 * phi))


@njit(cache=True, inline="always")
def rotvec2q_sc_xyz(tx, ty, tz, phi, sh, ch):
    """:func:`rotvec2q_xyz` with ``φ = |θ|``, ``sh = sin(φ/2)`` and ``ch = cos(φ/2)`` given (for
    callers that evaluate the sines and cosines of many rotations in a separate pass)."""
    s = sh / phi if phi > 1e-6 else 0.5 - phi * phi / 48.0
    return ch, s * tx, s * ty, s * tz


@njit(cache=True, inline="always")
def q2grp_xyz(q0, q1, q2, q3, a, f):
    """GRP ``p = f q_v/(a + q1)`` (Bernard eq. 3.28) → 3-tuple; the sign of q is kept."""
    d = a + q0
    return f * q1 / d, f * q2 / d, f * q3 / d


@njit(cache=True, inline="always")
def grp2q_xyz(p0, p1, p2, a, f):
    """Quaternion of a GRP vector (Bernard eq. 3.29–3.30) → 4-tuple."""
    n2 = p0 * p0 + p1 * p1 + p2 * p2
    q0 = (-a * n2 + f * math.sqrt(f * f + (1.0 - a * a) * n2)) / (f * f + n2)
    c = (a + q0) / f
    return q0, c * p0, c * p1, c * p2


# ----------------------------------------------------------------------------------------
# one value on 1-D arrays
# ----------------------------------------------------------------------------------------
@njit(cache=True)
def skew_nb(v):
    """Cross-product matrix ``[v×]`` (3×3) with ``[v×] w = v × w``."""
    S = np.zeros((3, 3))
    S[0, 1] = -v[2]
    S[0, 2] = v[1]
    S[1, 0] = v[2]
    S[1, 2] = -v[0]
    S[2, 0] = -v[1]
    S[2, 1] = v[0]
    return S


@njit(cache=True)
def qmul_into_nb(q, p, out):
    """``out = q ⊗ p`` (Bernard eq. 3.20); ``out`` may alias neither input."""
    a0, a1, a2, a3 = qmul_xyz(q[0], q[1], q[2], q[3], p[0], p[1], p[2], p[3])
    out[0] = a0
    out[1] = a1
    out[2] = a2
    out[3] = a3


@njit(cache=True)
def qmul_nb(q, p):
    """``q ⊗ p`` (Bernard eq. 3.20) for 1-D arrays of length 4 (scalar first)."""
    out = np.empty(4)
    qmul_into_nb(q, p, out)
    return out


@njit(cache=True)
def _qrot_signed_nb(q, v, sign):
    """``A(q) v`` (sign +1) or ``A(q)ᵀ v`` (sign −1, :func:`qrot_inv_xyz`) for 1-D arrays."""
    out = np.empty(3)
    out[0], out[1], out[2] = qrot_xyz_nb(sign * q[0], q[1], q[2], q[3], v[0], v[1], v[2])
    return out


@njit(cache=True)
def qrot_nb(q, v):
    """``A(q) v`` (inertial→body; Bernard eq. 3.16) for 1-D arrays."""
    return _qrot_signed_nb(q, v, 1.0)


@njit(cache=True)
def qrot_inv_nb(q, v):
    """``A(q)ᵀ v`` (body→inertial) for 1-D arrays."""
    return _qrot_signed_nb(q, v, -1.0)


@njit(cache=True)
def q2dcm_into_nb(q, A):
    """Fill ``A`` (3,3) with the attitude matrix ``A(q)`` (Bernard eq. 3.17)."""
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    A[0, 0] = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
    A[0, 1] = 2 * (q1 * q2 + q0 * q3)
    A[0, 2] = 2 * (q1 * q3 - q0 * q2)
    A[1, 0] = 2 * (q1 * q2 - q0 * q3)
    A[1, 1] = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
    A[1, 2] = 2 * (q2 * q3 + q0 * q1)
    A[2, 0] = 2 * (q1 * q3 + q0 * q2)
    A[2, 1] = 2 * (q2 * q3 - q0 * q1)
    A[2, 2] = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3


q2dcm_nb = _filled_by(q2dcm_into_nb, (3, 3), "q2dcm_nb",
                      "``A(q)`` (inertial→body; Bernard eq. 3.17) as a 3×3 array.")


@njit(cache=True)
def dcm2q_into_nb(A, out):
    """Unit quaternion (scalar ≥ 0) of a proper rotation matrix by Shepperd's method.

    The largest of ``(tr A, A11, A22, A33)`` selects the well-conditioned branch, so every
    angle including 180° is handled (Markley & Crassidis 2014 §2.9.3). Writes ``out`` (4,).
    """
    tr = A[0, 0] + A[1, 1] + A[2, 2]
    k = 0
    best = tr
    for i in range(3):
        if A[i, i] > best:
            best = A[i, i]
            k = i + 1
    if k == 0:
        s = 0.5 * math.sqrt(max(1.0 + tr, 0.0))
        a0, a1 = s, (A[1, 2] - A[2, 1]) / (4 * s)
        a2, a3 = (A[2, 0] - A[0, 2]) / (4 * s), (A[0, 1] - A[1, 0]) / (4 * s)
    elif k == 1:
        s = 0.5 * math.sqrt(max(1.0 + 2 * A[0, 0] - tr, 0.0))
        a0, a1 = (A[1, 2] - A[2, 1]) / (4 * s), s
        a2, a3 = (A[0, 1] + A[1, 0]) / (4 * s), (A[0, 2] + A[2, 0]) / (4 * s)
    elif k == 2:
        s = 0.5 * math.sqrt(max(1.0 + 2 * A[1, 1] - tr, 0.0))
        a0, a1 = (A[2, 0] - A[0, 2]) / (4 * s), (A[0, 1] + A[1, 0]) / (4 * s)
        a2, a3 = s, (A[1, 2] + A[2, 1]) / (4 * s)
    else:
        s = 0.5 * math.sqrt(max(1.0 + 2 * A[2, 2] - tr, 0.0))
        a0, a1 = (A[0, 1] - A[1, 0]) / (4 * s), (A[0, 2] + A[2, 0]) / (4 * s)
        a2, a3 = (A[1, 2] + A[2, 1]) / (4 * s), s
    n = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
    if a0 < 0:
        n = -n
    out[0] = a0 / n
    out[1] = a1 / n
    out[2] = a2 / n
    out[3] = a3 / n


dcm2q_nb = _filled_by(dcm2q_into_nb, (4,), "dcm2q_nb",
                      "Unit quaternion (scalar ≥ 0) of the attitude matrix ``A`` "
                      "(Shepperd's method).")


@njit(cache=True)
def normalize_into_nb(q, positive_scalar):
    """In place: ``q ← q/|q|`` (4,); with ``positive_scalar`` the sign makes ``q1 ≥ 0``."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if positive_scalar and q[0] < 0:
        n = -n
    for i in range(4):
        q[i] = q[i] / n


@njit(cache=True)
def qnormalize_nb(q):
    """Unit quaternion with non-negative scalar part (new array)."""
    out = q.copy()
    normalize_into_nb(out, True)
    return out


@njit(cache=True)
def rotvec2q_nb(th):
    """Quaternion ``[cos(φ/2), ê sin(φ/2)]`` of a rotation vector (rad; Bernard eq. 3.8–3.13)."""
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = rotvec2q_xyz(th[0], th[1], th[2])
    return out


@njit(cache=True)
def q2rotvec_into_nb(q, out):
    """Rotation vector ``φ ê`` (rad, φ ∈ [0, π]) of a unit quaternion, sign-independent.

    ``φ ê = 2 atan2(|q_v|, q1) q_v/|q_v|`` for the sign with ``q1 ≥ 0``; below
    ``|q_v| = 1e-8`` the series ``(2/q1)(1 − |q_v|²/(3 q1²)) q_v``.
    """
    s = 1.0 if q[0] >= 0 else -1.0
    q0 = s * q[0]
    v0, v1, v2 = s * q[1], s * q[2], s * q[3]
    n = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if n > 1e-8:
        fac = 2.0 * math.atan2(n, q0) / n
    else:
        fac = 2.0 / q0 * (1.0 - n * n / (3.0 * q0 * q0))
    out[0] = fac * v0
    out[1] = fac * v1
    out[2] = fac * v2


q2rotvec_nb = _filled_by(q2rotvec_into_nb, (3,), "q2rotvec_nb",
                         "Rotation vector (rad) of a unit quaternion (:func:`q2rotvec_into_nb`).")


@njit(cache=True)
def q2grp_nb(q, a, f):
    """GRP ``f q_v/(a + q1)`` of one quaternion (Bernard eq. 3.28; sign of q kept)."""
    out = np.empty(3)
    out[0], out[1], out[2] = q2grp_xyz(q[0], q[1], q[2], q[3], a, f)
    return out


@njit(cache=True)
def grp2q_nb(p, a, f):
    """Quaternion of one GRP vector (Bernard eq. 3.29–3.30)."""
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = grp2q_xyz(p[0], p[1], p[2], a, f)
    return out


@njit(cache=True)
def grp_rel_nb(Q, qref, a, f):
    """GRP (N,3) of the error ``δq_i = Q[i] ⊗ qref⁻¹`` (Bernard eq. 3.28, 7.71) with the
    sign of δq chosen so that ``δq1 ≥ 0`` (the short rotation)."""
    N = Q.shape[0]
    out = np.empty((N, 3))
    r0, r1, r2, r3 = qref[0], -qref[1], -qref[2], -qref[3]
    for i in range(N):
        d0, d1, d2, d3 = qmul_xyz(Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3], r0, r1, r2, r3)
        if d0 < 0.0:
            d0, d1, d2, d3 = -d0, -d1, -d2, -d3
        out[i, 0], out[i, 1], out[i, 2] = q2grp_xyz(d0, d1, d2, d3, a, f)
    return out


@njit(cache=True)
def from_grp_rel_nb(P, qref, a, f):
    """Unit quaternions (N,4) ``normalise(grp2q(P[i]) ⊗ qref)`` — the inverse of
    :func:`grp_rel_nb` (Bernard eq. 3.29–3.30, 7.65–7.67); the sign of the product is kept."""
    N = P.shape[0]
    out = np.empty((N, 4))
    for i in range(N):
        d0, d1, d2, d3 = grp2q_xyz(P[i, 0], P[i, 1], P[i, 2], a, f)
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = qmul_xyz(d0, d1, d2, d3, qref[0], qref[1],
                                                              qref[2], qref[3])
        normalize_into_nb(out[i], False)
    return out


@njit(cache=True)
def perturb_rotvec_nb(Q, theta):
    """New array ``exp(θ_i) ⊗ Q[i]``: each attitude (N,4) turned by the body-frame rotation
    vector ``theta[i]`` (N,3), rad (Bernard eq. 3.20 with eq. 3.8–3.13)."""
    N = Q.shape[0]
    out = np.empty_like(Q)
    for i in range(N):
        d0, d1, d2, d3 = rotvec2q_xyz(theta[i, 0], theta[i, 1], theta[i, 2])
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = qmul_xyz(d0, d1, d2, d3, Q[i, 0], Q[i, 1],
                                                              Q[i, 2], Q[i, 3])
    return out


@njit(cache=True)
def q2mrp_nb(q):
    """MRP ``σ = q_v/(1 + q1)`` (O'Keefe eq. 4.1) for the sign with ``q1 ≥ 0`` (|σ| ≤ 1)."""
    out = np.empty(3)
    if q[0] < 0.0:
        d = 1.0 - q[0]
        out[0] = -q[1] / d
        out[1] = -q[2] / d
        out[2] = -q[3] / d
    else:
        d = 1.0 + q[0]
        out[0] = q[1] / d
        out[1] = q[2] / d
        out[2] = q[3] / d
    return out


@njit(cache=True)
def mrp2q_nb(s):
    """Unit quaternion of an MRP: ``q1 = (1 − |σ|²)/(1 + |σ|²)``, ``q_v = 2σ/(1 + |σ|²)``."""
    n2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    out = np.empty(4)
    out[0] = (1.0 - n2) / (1.0 + n2)
    out[1] = 2.0 * s[0] / (1.0 + n2)
    out[2] = 2.0 * s[1] / (1.0 + n2)
    out[3] = 2.0 * s[2] / (1.0 + n2)
    return out


@njit(cache=True)
def mrp_shadow_nb(s, threshold):
    """σ, or its shadow set ``σˢ = −σ/|σ|²`` (O'Keefe eq. 4.2) when ``|σ| > threshold``."""
    n2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    out = s.copy()
    if n2 > threshold * threshold:
        for i in range(3):
            out[i] = -s[i] / n2
    return out


@njit(cache=True)
def mrp_compose_nb(s_outer, s_inner):
    """MRP of ``C(σ_outer) C(σ_inner)`` (O'Keefe eq. 4.4), switched to ``|σ| ≤ 1``.

    ``((1 − |σ_i|²) σ_o + (1 − |σ_o|²) σ_i − 2 σ_o × σ_i) / (1 + |σ_i|²|σ_o|² − 2 σ_o·σ_i)``;
    where the denominator is below 1e-6 (a composite near 360°) the inner set is replaced by
    its shadow (O'Keefe eq. 4.2) first.
    """
    s1 = s_inner.copy()
    s2 = s_outer
    n1 = s1[0] * s1[0] + s1[1] * s1[1] + s1[2] * s1[2]
    n2 = s2[0] * s2[0] + s2[1] * s2[1] + s2[2] * s2[2]
    dot = s1[0] * s2[0] + s1[1] * s2[1] + s1[2] * s2[2]
    den = 1.0 + n1 * n2 - 2.0 * dot
    if abs(den) < 1e-6 and n1 > 0:
        for i in range(3):
            s1[i] = -s1[i] / n1
        n1 = s1[0] * s1[0] + s1[1] * s1[1] + s1[2] * s1[2]
        dot = s1[0] * s2[0] + s1[1] * s2[1] + s1[2] * s2[2]
        den = 1.0 + n1 * n2 - 2.0 * dot
    cx = s2[1] * s1[2] - s2[2] * s1[1]
    cy = s2[2] * s1[0] - s2[0] * s1[2]
    cz = s2[0] * s1[1] - s2[1] * s1[0]
    out = np.empty(3)
    out[0] = ((1.0 - n1) * s2[0] + (1.0 - n2) * s1[0] - 2.0 * cx) / den
    out[1] = ((1.0 - n1) * s2[1] + (1.0 - n2) * s1[1] - 2.0 * cy) / den
    out[2] = ((1.0 - n1) * s2[2] + (1.0 - n2) * s1[2] - 2.0 * cz) / den
    return mrp_shadow_nb(out, 1.0)


@njit(cache=True)
def mrp2dcm_nb(s):
    """``C(σ) = I + (8[σ×]² − 4(1 − |σ|²)[σ×])/(1 + |σ|²)²`` (O'Keefe eq. 4.21); equals A(q)."""
    n2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    S = skew_nb(s)
    d = (1.0 + n2) ** 2
    C = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            s2 = S[i, 0] * S[0, j] + S[i, 1] * S[1, j] + S[i, 2] * S[2, j]
            C[i, j] = (8.0 * s2 - 4.0 * (1.0 - n2) * S[i, j]) / d
        C[i, i] += 1.0
    return C


@njit(cache=True)
def mrp_B_nb(s):
    """``B(σ) = (1 − σᵀσ) I + 2[σ×] + 2σσᵀ`` (3×3), so that ``σ̇ = ¼ B(σ) ω`` (O'Keefe eq. 4.3)."""
    n2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    B = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            B[i, j] = 2.0 * s[i] * s[j]
        B[i, i] += 1.0 - n2
    B[0, 1] -= 2.0 * s[2]
    B[0, 2] += 2.0 * s[1]
    B[1, 0] += 2.0 * s[2]
    B[1, 2] -= 2.0 * s[0]
    B[2, 0] -= 2.0 * s[1]
    B[2, 1] += 2.0 * s[0]
    return B


@njit(cache=True)
def mrp_dcm_vec_jac_nb(s, a):
    """Jacobian ``∂(C(σ) a)/∂σ`` (3×3) of the MRP attitude matrix times a vector (O'Keefe
    eq. 4.32): with ``N = 8(σ(σ·a) − |σ|² a) − 4(1 − |σ|²)(σ × a)``,
    ``∂N/∂σ = 8((σ·a) I + σ aᵀ − 2 a σᵀ) + 8 (σ × a) σᵀ + 4 (1 − |σ|²)[a×]`` and
    ``∂(C a)/∂σ = ∂N/∂σ/(1 + |σ|²)² − 4 N σᵀ/(1 + |σ|²)³``."""
    n2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    sa = s[0] * a[0] + s[1] * a[1] + s[2] * a[2]
    sxa = np.array([s[1] * a[2] - s[2] * a[1], s[2] * a[0] - s[0] * a[2],
                    s[0] * a[1] - s[1] * a[0]])
    N = 8.0 * (s * sa - a * n2) - 4.0 * (1.0 - n2) * sxa
    A = skew_nb(a)
    d1 = (1.0 + n2) ** 2
    d2 = (1.0 + n2) ** 3
    J = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            dN = 8.0 * (s[i] * a[j] - 2.0 * a[i] * s[j]) + 8.0 * sxa[i] * s[j] \
                + 4.0 * (1.0 - n2) * A[i, j]
            if i == j:
                dN += 8.0 * sa
            J[i, j] = dN / d1 - 4.0 * N[i] * s[j] / d2
    return J


@njit(cache=True)
def euler321_to_dcm_into_nb(ang, A):
    """Fill ``A`` with ``R1(ψ) R2(θ) R3(φ)`` for 3-2-1 angles ``ang = (φ, θ, ψ)`` rad (Bernard
    eq. 3.7)."""
    cf, sf = math.cos(ang[0]), math.sin(ang[0])
    ct, st = math.cos(ang[1]), math.sin(ang[1])
    cp, sp = math.cos(ang[2]), math.sin(ang[2])
    A[0, 0] = ct * cf
    A[0, 1] = ct * sf
    A[0, 2] = -st
    A[1, 0] = sp * st * cf - cp * sf
    A[1, 1] = sp * st * sf + cp * cf
    A[1, 2] = sp * ct
    A[2, 0] = cp * st * cf + sp * sf
    A[2, 1] = cp * st * sf - sp * cf
    A[2, 2] = cp * ct


euler321_to_dcm_nb = _filled_by(euler321_to_dcm_into_nb, (3, 3), "euler321_to_dcm_nb",
                                "``A = R1(ψ) R2(θ) R3(φ)`` (Bernard eq. 3.7) for "
                                "``ang = (φ, θ, ψ)``, rad.")


@njit(cache=True)
def euler321_to_q_nb(ang):
    """Quaternion ``q_x(ψ) ⊗ q_y(θ) ⊗ q_z(φ)`` of 3-2-1 angles (rad; Bernard eq. 3.7, 3.20),
    normalised with ``q1 ≥ 0``."""
    h0, h1, h2 = 0.5 * ang[0], 0.5 * ang[1], 0.5 * ang[2]
    a = qmul_xyz(math.cos(h1), 0.0, math.sin(h1), 0.0, math.cos(h0), 0.0, 0.0, math.sin(h0))
    b = qmul_xyz(math.cos(h2), math.sin(h2), 0.0, 0.0, a[0], a[1], a[2], a[3])
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = b
    normalize_into_nb(out, True)
    return out


@njit(cache=True)
def q2euler321_into_nb(q, out):
    """3-2-1 angles ``(φ, θ, ψ)`` (rad) of ``A(q)`` (Bernard eq. 3.7): φ, ψ ∈ (−π, π],
    θ ∈ [−π/2, π/2] (from atan2, better conditioned than asin near ±90°). At gimbal lock
    (``cos θ < 1e-12``) ψ = 0 and φ takes the whole rotation about z."""
    A = np.empty((3, 3))
    q2dcm_into_nb(q, A)
    ct = math.hypot(A[0, 0], A[0, 1])
    out[1] = math.atan2(-A[0, 2], ct)
    if ct < 1e-12:
        out[0] = math.atan2(-A[1, 0], A[1, 1])
        out[2] = 0.0
    else:
        out[0] = math.atan2(A[0, 1], A[0, 0])
        out[2] = math.atan2(A[1, 2], A[2, 2])


q2euler321_nb = _filled_by(q2euler321_into_nb, (3,), "q2euler321_nb",
                           "3-2-1 angles (rad) of one quaternion (:func:`q2euler321_into_nb`).")


# ----------------------------------------------------------------------------------------
# row-wise forms for the array layer (rotations.py)
# ----------------------------------------------------------------------------------------
@njit(cache=True)
def qmul_batch_nb(Q, P, sign, out):
    """Row-wise ``out[i] = Q[i] ⊗ P[i]`` (sign −1, Bernard eq. 3.20) or ``Q[i] ⊙ P[i]``
    (sign +1, eq. 3.21: the cross product enters with +). Q, P, out (N,4)."""
    for i in range(Q.shape[0]):
        if sign < 0:
            out[i, 0], out[i, 1], out[i, 2], out[i, 3] = qmul_xyz(
                Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3], P[i, 0], P[i, 1], P[i, 2], P[i, 3])
        else:
            out[i, 0], out[i, 1], out[i, 2], out[i, 3] = qmul_xyz(
                P[i, 0], P[i, 1], P[i, 2], P[i, 3], Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3])


@njit(cache=True)
def qrot_batch_nb(Q, V, inverse, out):
    """Row-wise ``A(Q[i]) V[i]`` (inverse False) or ``A(Q[i])ᵀ V[i]`` (:func:`qrot_inv_xyz`);
    Q (N,4), V, out (N,3)."""
    sign = -1.0 if inverse else 1.0
    for i in range(Q.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = qrot_xyz_nb(sign * Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3],
                                                      V[i, 0], V[i, 1], V[i, 2])


@njit(cache=True)
def rotvec2q_batch_nb(TH, out):
    """Row-wise quaternions (N,4) of rotation vectors TH (N,3), rad."""
    for i in range(TH.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = rotvec2q_xyz(TH[i, 0], TH[i, 1], TH[i, 2])


@njit(cache=True)
def q2grp_batch_nb(Q, a, f, out):
    """Row-wise GRP (N,3) of Q (N,4) (Bernard eq. 3.28; sign kept)."""
    for i in range(Q.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = q2grp_xyz(Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3], a, f)


@njit(cache=True)
def grp2q_batch_nb(P, a, f, out):
    """Row-wise quaternions (N,4) of GRP vectors P (N,3) (Bernard eq. 3.29–3.30)."""
    for i in range(P.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = grp2q_xyz(P[i, 0], P[i, 1], P[i, 2], a, f)


(q2mrp_batch_nb, mrp2q_batch_nb, mrp2dcm_batch_nb, skew_batch_nb,
 euler321_to_q_batch_nb) = _row_kernels(_value_rows, q2mrp_nb, mrp2q_nb, mrp2dcm_nb, skew_nb,
                                        euler321_to_q_nb)
mrp_compose_batch_nb, mrp_dcm_vec_jac_batch_nb = _row_kernels(_value_rows2, mrp_compose_nb,
                                                              mrp_dcm_vec_jac_nb)
(q2dcm_batch_nb, dcm2q_batch_nb, q2rotvec_batch_nb, euler321_to_dcm_batch_nb,
 q2euler321_batch_nb) = _row_kernels(_into_rows, q2dcm_into_nb, dcm2q_into_nb, q2rotvec_into_nb,
                                     euler321_to_dcm_into_nb, q2euler321_into_nb)


@njit(cache=True)
def mrp_shadow_batch_nb(S, threshold, out):
    """Row-wise :func:`mrp_shadow_nb` (O'Keefe eq. 4.2): out (N,3)."""
    for i in range(S.shape[0]):
        out[i] = mrp_shadow_nb(S[i], threshold)


