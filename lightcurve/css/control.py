"""MRP nonlinear sun-pointing control with reaction wheels (O'Keefe 2015, eq. 3.64).

Sun-pointing attitude error: with ``ĥ`` the body axis to point at the Sun (solar-array
normal) and ``ŝ`` the estimated unit Sun direction (both body axes), the principal angle is
``φ = arccos(ĥ·ŝ)`` and the error MRP of the body B relative to the Sun-pointing reference
R is (Schaub & Junkins, *Analytical Mechanics of Space Systems*, MRP definition
``σ = tan(φ/4) ê``)::

    σ_B/R = tan(φ/4) (ŝ × ĥ)/|ŝ × ĥ|

(any axis normal to ĥ when ŝ = −ĥ).  The nonlinear feedback law (eq. 3.64; Schaub &
Junkins eq. 8.141 for a reaction-wheel spacecraft with a non-rotating reference) is::

    L_r = −K σ − P ω + ω × ([I] ω + [G_s] h_s),     u_s = −[G_s]⁺ L_r

with ``h_s`` the wheel angular momenta about their spin axes (N m s), ``[G_s]`` (3×n) the
wheel spin axes (body axes) and ``u_s`` the motor torques, each saturated at ``u_max``.
Inside the 1° deadband (``φ < deadband``) the attitude term ``−Kσ`` is switched off so that
sensor noise does not make the wheels chatter; rate damping stays on.  Without a valid Sun
estimate only the rate damping is applied.

K in N m, P in N m s, angles in rad, rates in rad/s, torques in N m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["ControlParams", "sun_pointing_mrp_nb", "mrp_control_nb", "saturate_nb",
           "sun_pointing_mrp"]


@dataclass(frozen=True)
class ControlParams:
    """Gains and limits of the sun-pointing controller.

    k_gain: K (N m); p_gain: P (N m s); deadband_rad: attitude deadband (default 1°);
    u_max: wheel motor torque limit (N m); axis: body axis to point at the Sun.
    """

    k_gain: float = 0.02
    p_gain: float = 0.3
    deadband_rad: float = np.radians(1.0)
    u_max: float = 0.03
    axis: tuple = (0.0, 0.0, 1.0)


@numba.njit(cache=True)
def saturate_nb(u, u_max):
    """Clip each wheel motor torque of ``u`` to [−u_max, u_max] in place (N m)."""
    for i in range(u.shape[0]):
        if u[i] > u_max:
            u[i] = u_max
        elif u[i] < -u_max:
            u[i] = -u_max


@numba.njit(cache=True)
def sun_pointing_mrp_nb(s_hat, h_axis):
    """Error MRP σ_B/R (3,) and principal angle φ (rad) from unit ŝ and ĥ (body axes)."""
    c = s_hat[0] * h_axis[0] + s_hat[1] * h_axis[1] + s_hat[2] * h_axis[2]
    c = min(1.0, max(-1.0, c))
    phi = np.arccos(c)
    e = np.empty(3)
    e[0] = s_hat[1] * h_axis[2] - s_hat[2] * h_axis[1]
    e[1] = s_hat[2] * h_axis[0] - s_hat[0] * h_axis[2]
    e[2] = s_hat[0] * h_axis[1] - s_hat[1] * h_axis[0]
    n = np.sqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2)
    if n < 1e-12:
        if c > 0:
            return np.zeros(3), 0.0
        # anti-aligned: any axis normal to h
        a = np.array([1.0, 0.0, 0.0]) if abs(h_axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e[0] = a[1] * h_axis[2] - a[2] * h_axis[1]
        e[1] = a[2] * h_axis[0] - a[0] * h_axis[2]
        e[2] = a[0] * h_axis[1] - a[1] * h_axis[0]
        n = np.sqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2)
    t = np.tan(phi / 4.0)
    return e * (t / n), phi


@numba.njit(cache=True)
def mrp_control_nb(s_hat, valid, omega, I, G, h_w, G_pinv, k_gain, p_gain, deadband, u_max,
                   h_axis, gyroscopic=True):
    """Wheel motor torques u_s (n,) N m of eq. 3.64 (see module docstring).

    ``gyroscopic=False`` drops the ω × H feed-forward term — used without a gyro, where the
    rate about the Sun line is unobservable and a wrong ω in that term pumps momentum into
    the unobserved spin."""
    L = np.zeros(3)
    if valid:
        sig, phi = sun_pointing_mrp_nb(s_hat, h_axis)
        if phi >= deadband:
            L -= k_gain * sig
    L -= p_gain * omega
    if gyroscopic:
        H = I @ omega + G @ h_w
        L[0] += omega[1] * H[2] - omega[2] * H[1]
        L[1] += omega[2] * H[0] - omega[0] * H[2]
        L[2] += omega[0] * H[1] - omega[1] * H[0]
    u = -(G_pinv @ L)
    saturate_nb(u, u_max)
    return u


def sun_pointing_mrp(s_hat, axis=(0.0, 0.0, 1.0)):
    """Object-layer helper: (σ_B/R, φ rad) for a Sun direction ``s_hat`` (body axes)."""
    s = np.asarray(s_hat, dtype=float)
    s = s / np.linalg.norm(s)
    h = np.asarray(axis, dtype=float)
    h = h / np.linalg.norm(h)
    return sun_pointing_mrp_nb(s, h)
