"""Environmental torques in body axes (N m): gravity gradient, solar radiation pressure, drag.

Conventions: ``q`` scalar first, inertial→body (``v_b = A(q) v_I``); ECI is GCRS; positions in
m, velocities in m/s; facet geometry in body axes with centres of pressure measured from the
centre of mass (m); facet normals are outward unit vectors. Facet inputs are plain arrays
(``areas_m2 (F,)``, ``normals_body (F,3)``, ``centers_body_m (F,3)``) so a photometry shape can
feed them directly.

* Gravity gradient (Bernard 2021 eq. 4.20; Markley & Crassidis 2014 §3.3.6):
  ``T = 3μ/|r|³ r̂_b × (J r̂_b)`` with ``r̂_b = A(q) r̂`` the unit geocentric position in body axes.
* Solar radiation pressure (Bernard eq. 4.16–4.19; Markley & Crassidis §3.3.6):
  for each facet with ``cos θ_i = n̂_i·ŝ > 0`` (``ŝ`` object→Sun, body axes)
  ``F_i = −P A_i cos θ_i [(1 − C_s,i) ŝ + 2 (C_s,i cos θ_i + C_d,i/3) n̂_i]``,
  ``T = Σ c_i × F_i``, with ``P = P_1au (1 au/|r_sun|)²`` and ``P_1au = 4.56e-6 N/m²``;
  the absorbed fraction is ``C_a = 1 − C_s − C_d``. Multiplied by the lit fraction (0 in
  umbra, 1 in full sunlight), so it vanishes in eclipse.
* Aerodynamic drag (Bernard eq. 4.21–4.23; Markley & Crassidis §3.3.6): with the
  atmosphere co-rotating with the Earth, ``v_rel = v − ω_E × r`` (inertial), ``v_b = A(q) v_rel``,
  each facet with ``n̂_i·v_b > 0`` feels ``F_i = −½ ρ C_D |v_b| v_b A_i cos α_i
  = −½ ρ C_D (n̂_i·v_b) A_i v_b`` (``cos α_i = n̂_i·v̂_b``),
  ``T = Σ c_i × F_i``; ``ρ`` from :func:`lightcurve.dynamics.atmosphere.density_kg_m3` at the
  altitude above a spherical Earth. Facet self-shadowing (for SRP) and shielding (for drag)
  are not modelled.
  ``form="normal"`` is Bernard's eq. 4.21 as written: the facet force acts along the facet
  normal, ``F_i = −½ ρ C_D A_i |v|² max(v̂·n̂_i, 0) n̂_i`` (body axes), so a facet whose centre
  of pressure lies on its normal line (a cube) feels no drag torque. The ``max(·, 0)`` is the
  text's "projected area in the direction of the velocity vector" (§4.2.4: facets facing away
  from the flow present none); eq. 4.21 itself writes no clamp. The thesis's v is "the orbital
  velocity vector" — pass ``omega_earth = 0`` for that reading.

The ``*Torque`` classes bundle a torque with its geometry (functions of time) for the truth
models and expose ``torque(t, q, omega)`` and the attitude partial ``dtheta(t, q, omega)``
``= ∂T/∂δθ`` (see :mod:`lightcurve.dynamics.jacobians`).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.interpolate import CubicSpline

from .. import rotations as rot
from ..core.constants import AU_M, MU_EARTH, OMEGA_EARTH, P_SUN_1AU
from ..core.dynamics import gravity_gradient_batch_nb
from ..core.specialise import jit_copy
from . import _checks as ck
from .atmosphere import _H0_M, _H_M, _RHO0, R_EARTH_M, altitude_m, density_kg_m3
from .rigid_body import check_inertia

__all__ = [
    "MU_EARTH",
    "P_SUN_1AU",
    "AU_M",
    "OMEGA_EARTH",
    "gravity_gradient_torque",
    "gravity_gradient_torque_nb",
    "gravity_gradient_jacobian",
    "srp_torque_jacobian",
    "drag_torque_jacobian",
    "srp_torque",
    "srp_torque_nb",
    "srp_facet_forces",
    "drag_torque",
    "drag_torque_nb",
    "drag_relative_velocity",
    "as_time_function",
    "GravityGradientTorque",
    "SRPTorque",
    "DragTorque",
    "ConstantTorque",
    "TorqueSum",
    "SampledEnvironment",
    "environment_torque_nb",
]



# ----------------------------------------------------------------------------------------
# gravity gradient
# ----------------------------------------------------------------------------------------
def gravity_gradient_torque(r_eci_m, q, J, mu: float = MU_EARTH):
    """Gravity-gradient torque ``3μ/|r|³ r̂_b × (J r̂_b)`` (N m, body axes; Bernard eq. 4.20).

    Parameters
    ----------
    r_eci_m : array (..., 3)
        Geocentric position of the centre of mass, ECI (GCRS), m.
    q : array (..., 4)
        Attitude quaternion, scalar first, inertial→body.
    J : array (3, 3)
        Inertia tensor about the centre of mass, body axes, kg m².
    mu : float
        Gravitational parameter, m³/s².
    """
    r = ck.vec3(r_eci_m, "r_eci_m")
    J = check_inertia(J)
    mu = ck.finite_scalar(mu, "mu", positive=True)
    rn = np.linalg.norm(r, axis=-1, keepdims=True)
    if np.any(rn == 0):
        raise ValueError("r_eci_m: zero position vector")
    q = rot.check_unit_quat(q, "q")
    lead = np.broadcast_shapes(r.shape[:-1], q.shape[:-1])
    R = np.ascontiguousarray(np.broadcast_to(r, lead + (3,))).reshape(-1, 3)
    Q = np.ascontiguousarray(np.broadcast_to(q, lead + (4,))).reshape(-1, 4)
    out = np.empty((R.shape[0], 3))
    gravity_gradient_batch_nb(Q, R, np.ascontiguousarray(J), mu, out)
    return out.reshape(lead + (3,))


@njit(cache=True)
def gravity_gradient_torque_nb(q, r_eci_m, J, mu):
    """Numba kernel of :func:`gravity_gradient_torque` for one state (1-D float64 arrays).

    ``q`` (4,) unit quaternion, ``r_eci_m`` (3,) m, ``J`` (3, 3) kg m², ``mu`` m³/s²; returns the
    body torque (3,) in N m. No validation.
    """
    out = np.empty((1, 3))
    gravity_gradient_batch_nb(q.reshape(1, 4), r_eci_m.reshape(1, 3), J, mu, out)
    return out[0]


# ----------------------------------------------------------------------------------------
# solar radiation pressure
# ----------------------------------------------------------------------------------------
def srp_inputs(q, sun_dir_eci, areas_m2, normals_body, centers_body_m, c_spec, c_diff, c_abs,
               lit_fraction, sun_distance_m, p_sun_1au):
    """Validated SRP inputs shared by :func:`srp_torque` and its Jacobian: ``(A, n̂, c, C_s, C_d,
    ŝ_b, P)`` — facet areas, normals, centres, specular/diffuse coefficients, the body-frame
    Sun direction and the pressure ``P = P_1au (au/d)² · lit`` (N/m²)."""
    A, n, c = ck.facets(areas_m2, normals_body, centers_body_m)
    F = A.shape[0]
    cs = ck.per_facet(c_spec, F, "c_spec")
    cd = ck.per_facet(c_diff, F, "c_diff")
    if np.any(cs + cd > 1.0 + 1e-12):
        raise ValueError("c_spec + c_diff: must not exceed 1 (the absorbed fraction is 1 - c_spec - c_diff)")
    if c_abs is not None:
        ca = ck.per_facet(c_abs, F, "c_abs")
        if np.any(np.abs(cs + cd + ca - 1.0) > 1e-9):
            raise ValueError("c_spec + c_diff + c_abs: must sum to 1 for every facet")
    s = ck.unit_vec3(sun_dir_eci, "sun_dir_eci")
    lit = np.asarray(lit_fraction, dtype=float)
    if not np.all(np.isfinite(lit)) or np.any(lit < 0) or np.any(lit > 1):
        raise ValueError("lit_fraction: must lie in [0, 1] (0 = umbra, 1 = full sunlight)")
    d = np.asarray(sun_distance_m, dtype=float)
    if not np.all(np.isfinite(d)) or np.any(d <= 0):
        raise ValueError("sun_distance_m: must be finite and > 0 (m)")
    p1 = ck.finite_scalar(p_sun_1au, "p_sun_1au", nonneg=True)
    P = p1 * (AU_M / d) ** 2 * lit
    s_b = rot.quat_rotate(q, s)
    return A, n, c, cs, cd, s_b, P


def srp_facet_forces(s_b, P, areas_m2, normals_body, c_spec, c_diff):
    """Facet SRP forces (N, body axes), shape (..., F, 3), for body-frame Sun direction ``s_b``.

    ``F_i = −P A_i max(cos θ_i, 0) [(1 − C_s) ŝ + 2 (C_s cos θ_i + C_d/3) n̂_i]`` with
    ``cos θ_i = n̂_i·ŝ`` (Markley & Crassidis §3.3.6). No validation (internal helper).
    """
    cos = s_b[..., None, :] @ normals_body.T  # (..., 1, F)
    cos = cos[..., 0, :]
    lit = np.maximum(cos, 0.0)
    P = np.asarray(P, dtype=float)[..., None]
    a = (-P * areas_m2 * lit)[..., None]
    term = (1.0 - c_spec)[:, None] * s_b[..., None, :] + 2.0 * (c_spec * cos + c_diff / 3.0)[..., None] * normals_body
    return a * term


def srp_torque(q, sun_dir_eci, areas_m2, normals_body, centers_body_m, c_spec, c_diff, *,
               c_abs=None, lit_fraction=1.0, sun_distance_m=AU_M, p_sun_1au: float = P_SUN_1AU):
    """Solar-radiation-pressure torque from facets (N m, body axes; Bernard eq. 4.16–4.19).

    Parameters
    ----------
    q : array (..., 4)
        Attitude quaternion, scalar first, inertial→body.
    sun_dir_eci : array (..., 3)
        Unit vector from the object to the Sun, ECI.
    areas_m2, normals_body, centers_body_m : arrays (F,), (F, 3), (F, 3)
        Facet areas (m²), outward unit normals (body axes), centres of pressure relative to
        the centre of mass (body axes, m).
    c_spec, c_diff : float or array (F,)
        Specular and diffuse reflection coefficients in [0, 1]; absorbed = 1 − c_spec − c_diff.
    c_abs : float or array (F,), optional
        Absorption coefficient; when given, checked to complete the sum to 1.
    lit_fraction : float or array (...)
        Fraction of the solar disk visible (0 in umbra; eclipse → zero torque).
    sun_distance_m : float or array (...)
        Object–Sun distance, m; the pressure scales as ``(1 au/d)²``.
    p_sun_1au : float
        Radiation pressure at 1 au, N/m² (default 4.56e-6).
    """
    A, n, c, cs, cd, s_b, P = srp_inputs(q, sun_dir_eci, areas_m2, normals_body, centers_body_m,
                                          c_spec, c_diff, c_abs, lit_fraction, sun_distance_m, p_sun_1au)
    Fi = srp_facet_forces(s_b, P, A, n, cs, cd)
    return np.sum(np.cross(c, Fi), axis=-2)


@njit(cache=True, inline="always")
def _add_moment(out, c, fx, fy, fz):
    """``out += c × F`` (N m, body axes): the moment of a facet force ``F`` (N) applied at
    the facet's centre of pressure ``c`` (3,) (m, from the centre of mass)."""
    out[0] += c[1] * fz - c[2] * fy
    out[1] += c[2] * fx - c[0] * fz
    out[2] += c[0] * fy - c[1] * fx


def _facing_facet_torque(q, d_eci, scale, areas, normals, centers, prm1, prm2=None):
    db = rot.qrot_nb(q, d_eci)
    dn = np.sqrt(db[0] ** 2 + db[1] ** 2 + db[2] ** 2)   # |d_b|, once per call
    out = np.zeros(3)
    for i in range(areas.shape[0]):
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        c = nx * db[0] + ny * db[1] + nz * db[2]
        if c <= 0.0:
            continue
        fx, fy, fz = _force(i, c, db, dn, nx, ny, nz, scale, areas, prm1, prm2)  # noqa: F821
        _add_moment(out, centers[i], fx, fy, fz)
    return out


def _facet_torque_kernel(force, name):
    """The kernel ``name(q, d_eci, scale, areas, normals, centers, prm1[, prm2])`` → body
    torque (3,), N m: ``Σ c_i × F_i`` (:func:`_add_moment`) over the facets that face the
    body-frame direction ``d_b = A(q) d_eci`` (``c = n̂_i·d_b > 0``), with the facet force
    ``F_i = force(i, c, d_b, |d_b|, n̂_i, scale, areas, prm1, prm2)``. One compiled copy of the facet
    loop per force (:func:`~lightcurve.core.specialise.jit_copy`); fixed arguments, not
    ``*args``, which numba's dispatcher packs more slowly per call."""
    doc = f"Facet torque of :func:`{force.__name__}` (no validation): {force.__doc__}"
    return jit_copy(_facing_facet_torque, name, doc, {"cache": True}, _force=force)


@njit(cache=True, inline="always")
def _srp_facet_force(i, cos, sb, _sn, nx, ny, nz, P, areas, c_spec, c_diff):
    """Numba kernel of :func:`srp_torque` for one state, ``srp_torque_nb(q, s_eci, P, areas,
    normals, centers, c_spec, c_diff)``: ``q`` (4,) unit quaternion inertial→body; ``s_eci``
    (3,) unit object→Sun; ``P`` the pressure already scaled by distance and lit fraction
    (N/m²); facet arrays (F,), (F,3), (F,3); ``c_spec``, ``c_diff`` (F,). Returns the body
    torque (3,), N m — the same sum ``Σ c_i × F_i`` as :func:`srp_facet_forces`."""
    a = -P * areas[i] * cos
    kn = 2.0 * (c_spec[i] * cos + c_diff[i] / 3.0)
    ks = 1.0 - c_spec[i]
    return a * (ks * sb[0] + kn * nx), a * (ks * sb[1] + kn * ny), a * (ks * sb[2] + kn * nz)


srp_torque_nb = _facet_torque_kernel(_srp_facet_force, "srp_torque_nb")


# ----------------------------------------------------------------------------------------
# aerodynamic drag
# ----------------------------------------------------------------------------------------
def drag_relative_velocity(r_eci_m, v_eci_m_s, omega_earth: float = OMEGA_EARTH):
    """Velocity relative to the co-rotating atmosphere ``v − ω_E ẑ × r`` (m/s, ECI)."""
    r = ck.vec3(r_eci_m, "r_eci_m")
    v = ck.vec3(v_eci_m_s, "v_eci_m_s")
    we = np.array([0.0, 0.0, ck.finite_scalar(omega_earth, "omega_earth")])
    return v - np.cross(we, r)


def drag_torque(q, r_eci_m, v_eci_m_s, areas_m2, normals_body, centers_body_m, *, Cd: float = 2.2,
                density_fn=density_kg_m3, omega_earth: float = OMEGA_EARTH, form: str = "velocity"):
    """Aerodynamic drag torque from facets (N m, body axes; Bernard eq. 4.21–4.23).

    Parameters
    ----------
    q : array (..., 4)
        Attitude quaternion, scalar first, inertial→body.
    r_eci_m, v_eci_m_s : array (..., 3)
        Position (m) and velocity (m/s) of the centre of mass, ECI.
    areas_m2, normals_body, centers_body_m : arrays (F,), (F, 3), (F, 3)
        Facet areas, outward unit normals (body), centres of pressure from the centre of mass (m).
    Cd : float
        Drag coefficient (default 2.2).
    density_fn : callable ``h_m -> kg/m³``
        Density at altitude above the spherical Earth (default: exponential atmosphere).
    omega_earth : float
        Rotation rate of the atmosphere about ECI z, rad/s (0 for a non-rotating atmosphere).
    form : {"velocity", "normal"}
        Facet force along the flow (default) or along the facet normal (Bernard eq. 4.21 as
        written; module docstring).
    """
    ck.one_of(form, "form", ("velocity", "normal"))
    A, n, c = ck.facets(areas_m2, normals_body, centers_body_m)
    Cd = ck.finite_scalar(Cd, "Cd", nonneg=True)
    vrel = drag_relative_velocity(r_eci_m, v_eci_m_s, omega_earth)
    rho = np.asarray(density_fn(altitude_m(r_eci_m)), dtype=float)
    v_b = rot.quat_rotate(q, vrel)
    nv = (v_b[..., None, :] @ n.T)[..., 0, :]  # n_i · v_b = |v| cos α_i, (..., F)
    k = np.asarray(-0.5 * Cd * rho)[..., None] * A * np.maximum(nv, 0.0)  # (..., F), N/(m/s)
    if form == "normal":  # −½ρC_D A |v|² (v̂·n̂)⁺ n̂ = k |v| n̂
        vn = np.linalg.norm(v_b, axis=-1, keepdims=True)  # (..., 1)
        Fi = (k * vn)[..., None] * n
    else:
        Fi = k[..., None] * v_b[..., None, :]
    return np.sum(np.cross(c, Fi), axis=-2)


@njit(cache=True, inline="always")
def _drag_facet_force(i, nv, vb, vn, nx, ny, nz, rho_cd, areas, along_normal, _):
    """Numba kernel of :func:`drag_torque` for one state, ``drag_torque_nb(q, vrel_eci, rho_cd,
    areas, normals, centers, along_normal)``: ``vrel_eci`` (3,) flow velocity (m/s, ECI;
    relative to the atmosphere, or the orbital velocity for the thesis form); ``rho_cd`` =
    ρ C_D (kg/m³); ``along_normal`` selects Bernard's eq. 4.21 form (force along n̂) instead
    of along the flow. Returns N m, body axes."""
    k = -0.5 * rho_cd * areas[i] * nv
    if along_normal:
        return k * vn * nx, k * vn * ny, k * vn * nz
    return k * vb[0], k * vb[1], k * vb[2]


drag_torque_nb = _facet_torque_kernel(_drag_facet_force, "drag_torque_nb")


# ----------------------------------------------------------------------------------------
# time-dependent torque models for the truth simulators
# ----------------------------------------------------------------------------------------
# ----------------------------------------------------------------------------------------
# attitude partials of the torques (Bernard appendix A; lightcurve.dynamics.jacobians)
# ----------------------------------------------------------------------------------------
def gravity_gradient_jacobian(r_eci_m, q, J, mu: float = MU_EARTH) -> np.ndarray:
    """``∂T_gg/∂δθ`` (N m/rad, 3×3) of the gravity-gradient torque (Bernard appendix A).

    ``k ([u×] J − [(J u)×]) [u×]`` with ``u = A(q) r̂``, ``k = 3μ/|r|³``. Inputs as in
    :func:`lightcurve.dynamics.torques.gravity_gradient_torque` (single state).
    """
    r = ck.single_vec(r_eci_m, "r_eci_m")
    q = ck.single_quat(q)
    J = check_inertia(J)
    mu = ck.finite_scalar(mu, "mu", positive=True)
    rn = np.linalg.norm(r)
    if rn == 0:
        raise ValueError("r_eci_m: zero position vector")
    u = rot.quat_rotate(q, r / rn)
    U = rot.skew(u)
    return 3.0 * mu / rn**3 * (U @ J - rot.skew(J @ u)) @ U


def srp_torque_jacobian(q, sun_dir_eci, areas_m2, normals_body, centers_body_m, c_spec, c_diff, *,
                        c_abs=None, lit_fraction=1.0, sun_distance_m=AU_M,
                        p_sun_1au: float = P_SUN_1AU) -> np.ndarray:
    """``∂T_srp/∂δθ`` (N m/rad, 3×3); arguments as :func:`~lightcurve.dynamics.torques.srp_torque`."""
    q = ck.single_quat(q)
    A, n, c, cs, cd, s_b, P = srp_inputs(q, sun_dir_eci, areas_m2, normals_body, centers_body_m,
                                          c_spec, c_diff, c_abs, lit_fraction, sun_distance_m, p_sun_1au)
    if s_b.shape != (3,):
        raise ValueError("sun_dir_eci: expected a single vector of shape (3,)")
    P = float(P)
    S = rot.skew(s_b)
    out = np.zeros((3, 3))
    cos = n @ s_b
    for i in np.nonzero(cos > 0)[0]:
        x = cos[i]
        dF = -P * A[i] * ((1.0 - cs[i]) * (np.outer(s_b, n[i]) + x * np.eye(3))
                          + 2.0 * (2.0 * cs[i] * x + cd[i] / 3.0) * np.outer(n[i], n[i]))
        out += rot.skew(c[i]) @ dF @ S
    return out


def drag_torque_jacobian(q, r_eci_m, v_eci_m_s, areas_m2, normals_body, centers_body_m, *,
                         Cd: float = 2.2, density_fn=density_kg_m3,
                         omega_earth: float = OMEGA_EARTH) -> np.ndarray:
    """``∂T_drag/∂δθ`` (N m/rad, 3×3); arguments as :func:`~lightcurve.dynamics.torques.drag_torque`."""
    q = ck.single_quat(q)
    r = ck.single_vec(r_eci_m, "r_eci_m")
    v = ck.single_vec(v_eci_m_s, "v_eci_m_s")
    A, n, c = ck.facets(areas_m2, normals_body, centers_body_m)
    Cd = ck.finite_scalar(Cd, "Cd", nonneg=True)
    rho = float(density_fn(altitude_m(r)))
    v_b = rot.quat_rotate(q, drag_relative_velocity(r, v, omega_earth))
    V = rot.skew(v_b)
    out = np.zeros((3, 3))
    cos = n @ v_b
    for i in np.nonzero(cos > 0)[0]:
        dF = -0.5 * rho * Cd * A[i] * (np.outer(v_b, n[i]) + cos[i] * np.eye(3))
        out += rot.skew(c[i]) @ dF @ V
    return out


def as_time_function(x, name: str):
    """Turn ``x`` into a function of time ``t (s) -> array``.

    ``x`` may be a callable (returned as is), a constant array, or a tuple ``(t_s, values)`` of
    samples (interpolated with a cubic spline along the first axis of ``values``).
    """
    if callable(x):
        return x
    if isinstance(x, tuple) and len(x) == 2:
        t = np.asarray(x[0], dtype=float)
        vals = np.asarray(x[1], dtype=float)
        if t.ndim != 1 or vals.shape[0] != t.shape[0] or t.shape[0] < 2:
            raise ValueError(f"{name}: samples (t_s, values) need matching first dimensions >= 2")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(vals))):
            raise ValueError(f"{name}: samples contain NaN or infinite values")
        if np.any(np.diff(t) <= 0):
            raise ValueError(f"{name}: sample times must be strictly increasing")
        return CubicSpline(t, vals, axis=0)
    a = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return lambda t, _a=a: _a


class GravityGradientTorque:
    """Gravity-gradient torque along an orbit.

    Parameters
    ----------
    J : array (3, 3)
        Inertia, body axes, kg m².
    position : callable ``t -> r_eci_m (3,)``, constant array or ``(t_s, r (N,3))`` samples.
    mu : float
        Gravitational parameter, m³/s².
    """

    def __init__(self, J, position, mu: float = MU_EARTH):
        self.J = check_inertia(J)
        self.position = as_time_function(position, "position")
        self.mu = ck.finite_scalar(mu, "mu", positive=True)

    def torque(self, t, q, omega=None):
        """Torque (N m, body axes) at time ``t`` (s) and attitude ``q``.

        One state (``q`` shape (4,), one position) goes through the numba kernel
        :func:`gravity_gradient_torque_nb` (the truth integrators call this once per
        right-hand-side evaluation; same formula, equal to rounding); stacks and invalid
        inputs through the validating :func:`gravity_gradient_torque`.
        """
        r = self.position(t)
        qa = np.asarray(q, dtype=float)
        if qa.shape == (4,):
            ra = np.asarray(r, dtype=float)
            if (ra.shape == (3,) and np.isfinite(qa).all() and np.isfinite(ra).all()
                    and ra @ ra > 0.0):
                return gravity_gradient_torque_nb(np.ascontiguousarray(qa),
                                                  np.ascontiguousarray(ra), self.J, self.mu)
        return gravity_gradient_torque(r, q, self.J, self.mu)

    def dtheta(self, t, q, omega=None):
        """``∂T/∂δθ`` (N m/rad, 3×3) for ``q_true = δq(δθ) ⊗ q``."""
        return gravity_gradient_jacobian(self.position(t), q, self.J, self.mu)

    __call__ = torque


class SRPTorque:
    """Solar-radiation-pressure torque of a faceted body along an orbit.

    Parameters
    ----------
    areas_m2, normals_body, centers_body_m, c_spec, c_diff : see :func:`srp_torque`.
    sun_dir : callable ``t -> (3,)`` unit object→Sun vector (ECI), constant, or samples.
    lit_fraction : callable ``t -> float`` in [0, 1], constant, or samples (default 1).
    sun_distance_m : callable ``t -> float``, constant, or samples (default 1 au).
    p_sun_1au : float
        Pressure at 1 au, N/m².
    """

    def __init__(self, areas_m2, normals_body, centers_body_m, c_spec, c_diff, sun_dir,
                 lit_fraction=1.0, sun_distance_m=AU_M, p_sun_1au: float = P_SUN_1AU):
        self.areas, self.normals, self.centers = ck.facets(areas_m2, normals_body, centers_body_m)
        F = self.areas.shape[0]
        self.c_spec = ck.per_facet(c_spec, F, "c_spec")
        self.c_diff = ck.per_facet(c_diff, F, "c_diff")
        if np.any(self.c_spec + self.c_diff > 1 + 1e-12):
            raise ValueError("c_spec + c_diff: must not exceed 1")
        self.sun_dir = as_time_function(sun_dir, "sun_dir")
        self.lit_fraction = as_time_function(lit_fraction, "lit_fraction")
        self.sun_distance_m = as_time_function(sun_distance_m, "sun_distance_m")
        self.p_sun_1au = ck.finite_scalar(p_sun_1au, "p_sun_1au", nonneg=True)

    def _args(self, t):
        s = np.asarray(self.sun_dir(t), dtype=float)
        s = s / np.linalg.norm(s)  # spline-interpolated directions drift slightly off unit
        lit = float(np.clip(self.lit_fraction(t), 0.0, 1.0))
        return s, lit, float(self.sun_distance_m(t))

    def torque(self, t, q, omega=None):
        """Torque (N m, body axes) at time ``t`` (s) and attitude ``q``.

        One finite state goes through the numba kernel :func:`srp_torque_nb` (the truth
        integrators call this once per right-hand-side evaluation; same formula); stacks and
        anything else through the validating :func:`srp_torque`.
        """
        s, lit, d = self._args(t)
        qa = np.asarray(q, dtype=float)
        if qa.shape == (4,) and np.isfinite(qa).all() and np.isfinite(s).all() and d > 0:
            P = self.p_sun_1au * (AU_M / d) ** 2 * lit
            return srp_torque_nb(np.ascontiguousarray(qa), np.ascontiguousarray(s), P, self.areas,
                                 self.normals, self.centers, self.c_spec, self.c_diff)
        return srp_torque(q, s, self.areas, self.normals, self.centers, self.c_spec, self.c_diff,
                          lit_fraction=lit, sun_distance_m=d, p_sun_1au=self.p_sun_1au)

    def dtheta(self, t, q, omega=None):
        """``∂T/∂δθ`` (N m/rad, 3×3)."""
        s, lit, d = self._args(t)
        return srp_torque_jacobian(q, s, self.areas, self.normals, self.centers, self.c_spec,
                                   self.c_diff, lit_fraction=lit, sun_distance_m=d,
                                   p_sun_1au=self.p_sun_1au)

    __call__ = torque


class DragTorque:
    """Aerodynamic drag torque of a faceted body along an orbit.

    Parameters
    ----------
    areas_m2, normals_body, centers_body_m : see :func:`drag_torque`.
    position, velocity : callables ``t -> (3,)`` (ECI, m and m/s), constants or samples.
    Cd, density_fn, omega_earth, form : see :func:`drag_torque`.
    """

    def __init__(self, areas_m2, normals_body, centers_body_m, position, velocity, Cd: float = 2.2,
                 density_fn=density_kg_m3, omega_earth: float = OMEGA_EARTH, form: str = "velocity"):
        self.form = ck.one_of(form, "form", ("velocity", "normal"))
        self.areas, self.normals, self.centers = ck.facets(areas_m2, normals_body, centers_body_m)
        self.position = as_time_function(position, "position")
        self.velocity = as_time_function(velocity, "velocity")
        self.Cd = ck.finite_scalar(Cd, "Cd", nonneg=True)
        self.density_fn = density_fn
        self.omega_earth = ck.finite_scalar(omega_earth, "omega_earth")

    def torque(self, t, q, omega=None):
        """Torque (N m, body axes) at time ``t`` (s) and attitude ``q``.

        One finite state goes through the numba kernel :func:`drag_torque_nb` (same formula);
        stacks and anything else through the validating :func:`drag_torque`.
        """
        r, v = self.position(t), self.velocity(t)
        qa = np.asarray(q, dtype=float)
        ra, va = np.asarray(r, dtype=float), np.asarray(v, dtype=float)
        if (qa.shape == (4,) and ra.shape == (3,) and va.shape == (3,) and np.isfinite(qa).all()
                and np.isfinite(ra).all() and np.isfinite(va).all()):
            vrel = drag_relative_velocity(ra, va, self.omega_earth)
            rho = float(self.density_fn(altitude_m(ra)))
            return drag_torque_nb(np.ascontiguousarray(qa), np.ascontiguousarray(vrel),
                                  rho * self.Cd, self.areas, self.normals, self.centers,
                                  self.form == "normal")
        return drag_torque(q, r, v, self.areas, self.normals, self.centers, Cd=self.Cd,
                           density_fn=self.density_fn, omega_earth=self.omega_earth,
                           form=self.form)

    def dtheta(self, t, q, omega=None):
        """``∂T/∂δθ`` (N m/rad, 3×3)."""
        if self.form != "velocity":
            raise NotImplementedError("the attitude Jacobian of the along-normal drag form "
                                      "(Bernard eq. 4.21) is not implemented")
        return drag_torque_jacobian(q, self.position(t), self.velocity(t), self.areas, self.normals,
                                    self.centers, Cd=self.Cd, density_fn=self.density_fn,
                                    omega_earth=self.omega_earth)

    __call__ = torque


class ConstantTorque:
    """A constant torque in body axes (N m); attitude-independent, so ``∂T/∂δθ = 0``."""

    def __init__(self, torque_body_nm):
        self.value = ck.vec3(torque_body_nm, "torque_body_nm").reshape(3)

    def torque(self, t, q, omega=None):
        return self.value.copy()

    def dtheta(self, t, q, omega=None):
        return np.zeros((3, 3))

    __call__ = torque


class TorqueSum:
    """Sum of torque models (each with ``torque(t, q, omega)`` and ``dtheta(t, q, omega)``)."""

    def __init__(self, models):
        self.models = list(models)
        for m in self.models:
            if not (hasattr(m, "torque") and hasattr(m, "dtheta")):
                raise ValueError(f"torque model {m!r} lacks torque()/dtheta() methods")

    def torque(self, t, q, omega=None):
        out = np.zeros(3)
        for m in self.models:
            out = out + np.asarray(m.torque(t, q, omega), dtype=float)
        return out

    def dtheta(self, t, q, omega=None):
        out = np.zeros((3, 3))
        for m in self.models:
            out = out + np.asarray(m.dtheta(t, q, omega), dtype=float)
        return out

    __call__ = torque


# ----------------------------------------------------------------------------------------
# the named torques of a sampled orbit, summed in one kernel (truth integrators)
# ----------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _piece(knots, t):
    """Index ``i`` of the knot interval with ``knots[i] <= t < knots[i+1]``, clipped to the end
    pieces (``t`` at or beyond the last knot uses the last piece): scipy ``PPoly``'s rule."""
    i = np.searchsorted(knots, t, side="right") - 1
    if i < 0:
        return 0
    if i > knots.shape[0] - 2:
        return knots.shape[0] - 2
    return i


@njit(cache=True, inline="always")
def _cubic(c, i, s, k):
    """Component ``k`` of piece ``i`` of a piecewise cubic with scipy ``PPoly`` coefficients
    ``c`` (4, pieces, m) at the local coordinate ``s = t − knot_i``, summed lowest power first
    as ``PPoly`` sums it, so that it equals ``CubicSpline.__call__`` bit for bit."""
    res = 0.0
    z = 1.0
    for kp in range(4):
        res = res + c[3 - kp, i, k] * z
        if kp < 3:
            z *= s
    return res


@njit(cache=True)
def environment_torque_nb(t, q, knots, pos_c, vel_c, sun_c, dist_c, lit, use_gg, J, mu,
                          use_drag, rho_scale, omega_earth, along_normal, use_srp, p_sun_1au,
                          areas, normals, centers, c_spec, c_diff):
    """Sum of the named environmental torques (N m, body axes) at time ``t`` (s) and unit
    attitude ``q`` (4,), scalar first, inertial→body — the same sum, in the same order
    (gravity gradient, drag, SRP) and through the same facet kernels as
    :class:`GravityGradientTorque`, :class:`DragTorque` and :class:`SRPTorque` called on the
    cubic splines of :class:`SampledEnvironment`; no validation (use :class:`SampledEnvironment`).

    ``knots`` (n,) s; ``pos_c``, ``vel_c``, ``sun_c`` (4, n−1, 3) and ``dist_c`` (4, n−1, 1) the
    ``CubicSpline`` coefficients of the ECI position (m), velocity (m/s), object→Sun direction
    and object–Sun distance (m) on those knots; ``lit`` (n,) the lit fraction at the knots
    (interpolated linearly, as ``numpy.interp``). ``rho_scale`` is C_D (drag, with the
    exponential atmosphere of :func:`~lightcurve.dynamics.atmosphere.density_kg_m3`);
    ``omega_earth`` rad/s; ``along_normal`` Bernard's eq. 4.21 drag form.
    """
    i = _piece(knots, t)
    s = t - knots[i]
    out = np.zeros(3)
    r = np.empty(3)
    if use_gg or use_drag:
        for k in range(3):
            r[k] = _cubic(pos_c, i, s, k)
    if use_gg:
        out = out + gravity_gradient_torque_nb(q, r, J, mu)
    if use_drag:
        v = np.empty(3)
        for k in range(3):
            v[k] = _cubic(vel_c, i, s, k)
        # v_rel = v − [0, 0, ω_E] × r, in numpy.cross's order of operations
        vrel = np.empty(3)
        vrel[0] = v[0] - (0.0 * r[2] - omega_earth * r[1])
        vrel[1] = v[1] - (omega_earth * r[0] - 0.0 * r[2])
        vrel[2] = v[2] - (0.0 * r[1] - 0.0 * r[0])
        h = np.sqrt(np.dot(r, r)) - R_EARTH_M
        if not h >= 0.0:
            raise ValueError("r_eci_m: altitude below 0 km is outside the exponential atmosphere table")
        b = np.searchsorted(_H0_M, h, side="right") - 1
        rho = _RHO0[b] * np.exp(-(h - _H0_M[b]) / _H_M[b])
        out = out + drag_torque_nb(q, vrel, rho * rho_scale, areas, normals, centers, along_normal)
    if use_srp:
        u = np.empty(3)
        for k in range(3):
            u[k] = _cubic(sun_c, i, s, k)
        u = u / np.sqrt(np.dot(u, u))
        # numpy.interp on the knots, clipped to [0, 1] as SRPTorque does
        if t >= knots[-1]:
            f = lit[-1]
        elif t <= knots[0]:
            f = lit[0]
        elif knots[i] == t:  # inside the knot span the spline's piece i is numpy.interp's
            f = lit[i]
        else:
            f = (lit[i + 1] - lit[i]) / (knots[i + 1] - knots[i]) * (t - knots[i]) + lit[i]
        f = min(max(f, 0.0), 1.0)
        d = _cubic(dist_c, i, s, 0)
        P = p_sun_1au * (AU_M / d) ** 2 * f
        out = out + srp_torque_nb(q, u, P, areas, normals, centers, c_spec, c_diff)
    return out


class SampledEnvironment:
    """The named torques of one orbit arc, sampled on a time grid and summed in
    :func:`environment_torque_nb` (one compiled call per right-hand-side evaluation of a truth
    integrator instead of one Python call per torque model).

    Parameters
    ----------
    t_s : array (n,)
        Sample times, s, strictly increasing (n >= 2).
    r_eci_m, v_eci_m_s : arrays (n, 3)
        ECI (GCRS) position (m) and velocity (m/s) at ``t_s``.
    sun_rel_m : array (n, 3) or None
        Object→Sun vector (m, ECI) at ``t_s``; needed for SRP.
    lit : array (n,) or None
        Lit fraction in [0, 1] at ``t_s``; needed for SRP.
    gravity_gradient : bool
        Include :class:`GravityGradientTorque` (needs ``J``; ``mu`` m³/s²).
    drag : dict or None
        ``{"areas_m2", "normals_body", "centers_body_m", "Cd", "omega_earth", "form"}`` as
        :class:`DragTorque` takes them (the default exponential atmosphere).
    srp : dict or None
        ``{"areas_m2", "normals_body", "centers_body_m", "c_spec", "c_diff"}`` as
        :class:`SRPTorque` takes them (``p_sun_1au`` optional).

    :meth:`models` returns the equivalent torque model objects (for their attitude partials);
    :meth:`torque` equals the sum of their ``torque`` to rounding.
    """

    def __init__(self, t_s, r_eci_m, v_eci_m_s, sun_rel_m=None, lit=None, *, gravity_gradient=False,
                 J=None, mu: float = MU_EARTH, drag=None, srp=None):
        t = ck.times(t_s, "t_s")
        if t.size < 2 or np.any(np.diff(t) <= 0):
            raise ValueError("t_s: need at least 2 strictly increasing sample times")
        r = np.asarray(r_eci_m, dtype=float)
        v = np.asarray(v_eci_m_s, dtype=float)
        for name, a in (("r_eci_m", r), ("v_eci_m_s", v)):
            if a.shape != (t.size, 3) or not np.all(np.isfinite(a)):
                raise ValueError(f"{name}: expected finite values of shape ({t.size}, 3), got {a.shape}")
        self.knots = np.ascontiguousarray(t)
        self.position = CubicSpline(t, r, axis=0)
        self.velocity = CubicSpline(t, v, axis=0)
        self.use_gg = bool(gravity_gradient)
        self.J = check_inertia(J) if self.use_gg else np.eye(3)
        self.mu = ck.finite_scalar(mu, "mu", positive=True)
        empty_f, empty_f3 = np.zeros(0), np.zeros((0, 3))
        self.use_drag = drag is not None
        self.use_srp = srp is not None
        geom = drag if self.use_drag else srp
        if geom is not None:
            self.areas, self.normals, self.centers = ck.facets(
                geom["areas_m2"], geom["normals_body"], geom["centers_body_m"])
        else:
            self.areas, self.normals, self.centers = empty_f, empty_f3, empty_f3
        if self.use_drag and self.use_srp:
            a2, n2, c2 = ck.facets(srp["areas_m2"], srp["normals_body"], srp["centers_body_m"])
            if not (np.array_equal(a2, self.areas) and np.array_equal(n2, self.normals)
                    and np.array_equal(c2, self.centers)):
                raise ValueError("srp and drag: must share one facet geometry")
        d = drag or {}
        self.Cd = ck.finite_scalar(d.get("Cd", 2.2), "Cd", nonneg=True)
        self.omega_earth = ck.finite_scalar(d.get("omega_earth", OMEGA_EARTH), "omega_earth")
        self.drag_form = ck.one_of(d.get("form", "velocity"), "form", ("velocity", "normal"))
        F = self.areas.shape[0]
        if self.use_srp:
            if sun_rel_m is None or lit is None:
                raise ValueError("srp: needs sun_rel_m and lit samples")
            rel = np.asarray(sun_rel_m, dtype=float)
            f = np.asarray(lit, dtype=float)
            if rel.shape != (t.size, 3) or not np.all(np.isfinite(rel)):
                raise ValueError(f"sun_rel_m: expected finite values of shape ({t.size}, 3)")
            if f.shape != (t.size,) or not np.all(np.isfinite(f)) or np.any(f < 0) or np.any(f > 1):
                raise ValueError("lit: expected values in [0, 1], one per sample time")
            dist = np.linalg.norm(rel, axis=1)
            self.sun_dir = CubicSpline(t, rel / dist[:, None], axis=0)
            self.sun_distance = CubicSpline(t, dist)
            self.lit = np.ascontiguousarray(f)
            self.c_spec = ck.per_facet(srp["c_spec"], F, "c_spec")
            self.c_diff = ck.per_facet(srp["c_diff"], F, "c_diff")
            if np.any(self.c_spec + self.c_diff > 1 + 1e-12):
                raise ValueError("c_spec + c_diff: must not exceed 1")
            self.p_sun_1au = ck.finite_scalar(srp.get("p_sun_1au", P_SUN_1AU), "p_sun_1au", nonneg=True)
            sun_c, dist_c = self.sun_dir.c, self.sun_distance.c[..., None]
        else:
            self.lit, self.c_spec, self.c_diff, self.p_sun_1au = np.zeros(t.size), empty_f, empty_f, 0.0
            sun_c = dist_c = np.zeros((4, t.size - 1, 1))
        c3 = lambda a: np.ascontiguousarray(a, dtype=float)  # noqa: E731
        self._args = (self.knots, c3(self.position.c), c3(self.velocity.c), c3(sun_c), c3(dist_c),
                      self.lit, self.use_gg, np.ascontiguousarray(self.J), self.mu, self.use_drag,
                      self.Cd, self.omega_earth, self.drag_form == "normal", self.use_srp,
                      self.p_sun_1au, self.areas, self.normals, self.centers, self.c_spec,
                      self.c_diff)

    def torque(self, t, q, omega=None):
        """Total named torque (N m, body axes) at time ``t`` (s) for one unit quaternion ``q`` (4,)."""
        return environment_torque_nb(float(t), np.ascontiguousarray(q, dtype=float), *self._args)

    def models(self):
        """The equivalent :class:`GravityGradientTorque`, :class:`DragTorque` and
        :class:`SRPTorque` objects on the same splines, in the order the kernel sums them."""
        out = []
        if self.use_gg:
            out.append(GravityGradientTorque(self.J, self.position, self.mu))
        if self.use_drag:
            out.append(DragTorque(self.areas, self.normals, self.centers, self.position, self.velocity,
                                  Cd=self.Cd, omega_earth=self.omega_earth, form=self.drag_form))
        if self.use_srp:
            knots, lit = self.knots, self.lit
            out.append(SRPTorque(self.areas, self.normals, self.centers, self.c_spec, self.c_diff,
                                 self.sun_dir, lit_fraction=lambda tt: np.interp(tt, knots, lit),
                                 sun_distance_m=self.sun_distance, p_sun_1au=self.p_sun_1au))
        return out

    __call__ = torque
