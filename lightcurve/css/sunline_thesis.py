"""The sun-line EKF and extended consider KF exactly as O'Keefe (2015) §3.2 describes them
(``variant = "thesis"``): no orbit, no albedo knowledge, the text's tuning.

State (eq. 3.27): the scaled Sun vector ``d = C s`` in body axes.  Dynamics (eq. 3.29, 3.55)
``ḋ = d × (ω̃ − ω̂_β − η_ω) [+ ḋ_β] − η_s`` with the gyro rate ω̃ (rad/s, [BG] = I) and the a
priori bias estimate ω̂_β = 0.  Jacobians (eq. 3.31a-b, 3.57a-c)::

    F = −[ω̃×],   G = [−I₃, −[d̂×]],   S = ∂f/∂β_η = [I₃, −[d̂×]]

with process noise densities η_s: σ_s² I, η_ω: σ_ω² I.  The covariance is propagated with the
continuous Riccati equation (eq. 3.19, 3.42) by RK4 together with d (§3.3.5: "propagation
updates are computed using an RK4 integrator").

Measurement (modified eq. 3.1, 3.31c-d, 3.57d-e): sensor ``i`` predicts ``h_i = Ĉ_κ n̂_iᵀ d``
(nominal normals n̂_i, Ĉ_κ = 1) with ``H_i = Ĉ_κ n̂_iᵀ`` when the predicted Sun is inside its
field of view (``n̂_iᵀ d̂/|d̂| ≥ cos ψ``) and, for the dual pyramid, above the structure horizon
(§3.2.3 treats that horizon as the sensor's second measurement discontinuity); ``M = |d̂| diag(Ĉ_κ)`` so ``R_i = |d̂|² σ_V²``.  Sensors
whose output is "above 50% of the expected maximum output" (``y_i > 0.5 |d̂|``) are processed
too, with increased uncertainty (§3.2.1.2; the increase is left open — σ_V doubled,
:data:`~lightcurve.css.okeefe2015.EKF_TUNING`).  No update in the Earth's shadow (eq. 3.1's
``B ∈ S``), which the filter decides from the outputs alone (:func:`thesis_sunlit_nb`: no output
reaches 50 % of the expected maximum).

EKF (§3.2.1): Joseph-form update (eq. 3.24) through
:func:`lightcurve.core.kalman.joseph_update_nb`; σ_V = 1.84 and σ_s from §3.3.

ECKF (§3.2.2): consider parameters ``β_η = [ḋ_β (3), ω_β (3)]`` and
``β_ν = [C_κ (N), θ_β (N), φ_β (N), V_αβ (N)]`` (eq. 3.56) with covariance blocks
``P_x, L, Λ, B_η, B_ν`` (eq. 3.35), propagated by eq. 3.42 (``Ḃ_η`` = σ_ωd² on the gyro-bias
block, the bias random walk of eq. 2.23b) and updated by the traditional Schmidt consider update
eq. 3.51-3.52 (§3.2.2.2: "the traditional, non-optimal, version of the ECKF is implemented"),
:func:`lightcurve.core.kalman.consider_update_nb`::

    W = H P_x Hᵀ + J Λᵀ Hᵀ + H Λ Jᵀ + J B_ν Jᵀ + M R Mᵀ          (eq. 3.47)
    K = (P_x Hᵀ + Λ Jᵀ) W⁻¹                                        (eq. 3.51)
    P_x⁺ = P_x − K W Kᵀ,  L⁺ = (I − K H) L,  Λ⁺ = (I − K H) Λ − K J B_ν   (eq. 3.52)

with J from eq. 3.57f.  Measurement consistency (§3.2.3): for a sensor whose predicted Sun lies
within γ of its visibility boundary (inside or outside) (field of view, or for the dual pyramid the structure
horizon, whichever is nearer along the great circle through the Sun), γ = the 3σ misalignment
offset of eq. 3.61 plus 3σ of the Sun-direction angle of eq. 3.62, the innovation variance gets
the maximum error of eq. 3.63, ``(|d̂| Ĉ_κ {cos(ψ_b − min(ψ_b, γ)) + σ_Vα + σ_V})²``; a strong
output from a sensor predicted dark (the "increased measurement uncertainty" of §3.2.1.2, left
open by the text) gets the same bound with γ = π, i.e. the sensor's whole range.

Numba kernels on plain arrays; the state of one filter is the tuple made by
:func:`thesis_state`.
"""

from __future__ import annotations

import numba
import numpy as np

from ..core.kalman import consider_update_nb, joseph_update_nb
from ..core.rotations import skew_nb

__all__ = ["thesis_state", "thesis_init_nb", "thesis_propagate_nb", "thesis_update_nb",
           "thesis_sunlit_nb", "THESIS_PRM", "thesis_params"]

# layout of the parameter array of the thesis filters
THESIS_PRM = ("kind", "sigma_v", "sigma_s", "sigma_w", "sigma_wd", "sigma_wr", "strong_frac",
              "strong_factor", "shadow_level", "cons_sigmas", "sigma_mis", "sigma_valpha",
              "sigma_ck", "sdd_x", "sdd_y", "sdd_z", "p0", "shadow_frac")


def thesis_params(kind: str, *, sigma_v, sigma_s, sigma_w, sigma_wd, sigma_wr, strong_frac=0.5,
                  strong_factor=2.0, shadow_level=0.25, cons_sigmas=3.0, sigma_mis=0.0,
                  sigma_valpha=0.0, sigma_ck=0.0, sigma_d_dot=(0.0, 0.0, 0.0), p0=1.0,
                  shadow_frac=0.0):
    """The parameter array of :func:`thesis_update_nb` / :func:`thesis_propagate_nb` (SI units;
    kind 'ekf' or 'eckf'; see :data:`THESIS_PRM` for the order).  ``shadow_level``: absolute
    output level below which every sample is shadow; ``shadow_frac``: once the filter runs, a
    sample is shadow too when no output reaches ``shadow_frac |d̂|`` (0: off; see
    :func:`thesis_sunlit_nb`)."""
    k = {"ekf": 0.0, "eckf": 1.0}[kind]
    return np.array([k, sigma_v, sigma_s, sigma_w, sigma_wd, sigma_wr, strong_frac, strong_factor,
                     shadow_level, cons_sigmas, sigma_mis, sigma_valpha, sigma_ck,
                     sigma_d_dot[0], sigma_d_dot[1], sigma_d_dot[2], p0, shadow_frac],
                    dtype=float)


def thesis_state(n_sensors: int):
    """Fresh filter state: (d (3), P_x (3,3), L (3,6), Λ (3,4N), B_η (6,6), B_ν (4N,))."""
    N = int(n_sensors)
    return (np.zeros(3), np.eye(3), np.zeros((3, 6)), np.zeros((3, 4 * N)), np.zeros((6, 6)),
            np.zeros(4 * N))


@numba.njit(cache=True)
def thesis_sunlit_nb(y, d, prm, started):
    """The filter's own decision ``B ∉ S`` of eq. 3.1/3.31 (the spacecraft sees the Sun) from
    the CSS outputs ``y`` alone (the ch. 3 filters know no orbit, §3 intro): False when every
    output is below the absolute level ``prm[8]``, or, once the filter runs (``started``), below
    ``prm[17] |d̂|`` — the "50 % of the expected maximum output" of §3.2.1.2.  With the 60° field
    of view of §2.1.3 a sensor that sees the Sun directly reads at least cos 60° = 50 % of the
    maximum, so a sample with no output that high carries no direct Sun (Earth's shadow, the
    penumbra's fading Sun, or a coverage gap) and eq. 3.1's ``B ∈ S`` branch applies.  How the
    filter decides ``B ∈ S`` is left open by §3.2 (okeefe2015.OPEN_CHOICES "shadow_detection")."""
    ymax = 0.0
    for i in range(y.shape[0]):
        if y[i] > ymax:
            ymax = y[i]
    if ymax < prm[8]:
        return False
    if started and prm[17] > 0.0:
        nd = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
        if ymax < prm[17] * nd:
            return False
    return True


@numba.njit(cache=True)
def thesis_init_nb(y, normals, prm, d, P, L, Lam, Beta, Bnu):
    """Start the filter from one sample (choice named in okeefe2015.OPEN_CHOICES: the WAVG
    direction (eq. 3.3) scaled by the largest output, P = p0 I, L = Λ = 0 (§3.2.2.2), B_η and
    B_ν from the prior σ's).  Returns False (nothing changed) when every output is below the
    shadow level."""
    N = y.shape[0]
    ymax = 0.0
    s = np.zeros(3)
    for i in range(N):
        if y[i] > ymax:
            ymax = y[i]
        if y[i] > 0.0:
            for j in range(3):
                s[j] += y[i] * normals[i, j]
    ns = np.sqrt(s[0] ** 2 + s[1] ** 2 + s[2] ** 2)
    if not thesis_sunlit_nb(y, d, prm, False) or ns == 0.0:
        return False
    for j in range(3):
        d[j] = s[j] / ns * ymax
    P[:, :] = 0.0
    for j in range(3):
        P[j, j] = prm[16]
    L[:, :] = 0.0
    Lam[:, :] = 0.0
    Beta[:, :] = 0.0
    if prm[0] > 0.5:
        for j in range(3):
            Beta[j, j] = prm[13 + j] ** 2
            Beta[3 + j, 3 + j] = prm[5] ** 2
        for i in range(N):
            Bnu[i] = prm[12] ** 2
            Bnu[N + i] = prm[10] ** 2
            Bnu[2 * N + i] = prm[10] ** 2
            Bnu[3 * N + i] = prm[11] ** 2
    return True


@numba.njit(cache=True)
def _deriv(d, P, L, Lam, Beta, w, sig_s, sig_w, sig_wd, eckf):
    """Right-hand sides of eq. 3.29/3.55 (d) and 3.42 (P_x, L, Λ, B_η)."""
    F = -skew_nb(w)
    dd = F @ d
    Dx = skew_nb(d)
    GQG = -(sig_w * sig_w) * (Dx @ Dx)
    for i in range(3):
        GQG[i, i] += sig_s * sig_s
    FP = F @ P
    dP = FP + FP.T + GQG
    dL = np.zeros((3, 6))
    dLam = np.zeros(Lam.shape)
    dB = np.zeros((6, 6))
    if eckf:
        # S = [I, -[d×]]
        S = np.zeros((3, 6))
        for i in range(3):
            S[i, i] = 1.0
            for j in range(3):
                S[i, 3 + j] = -Dx[i, j]
        SLt = S @ L.T
        dP += SLt + SLt.T
        dL = F @ L + S @ Beta
        dLam = F @ Lam
        for i in range(3):
            dB[3 + i, 3 + i] = sig_wd * sig_wd
    return dd, dP, dL, dLam, dB


@numba.njit(cache=True)
def thesis_propagate_nb(d, P, L, Lam, Beta, omega, dt, prm, sig_s, sig_w):
    """One RK4 step of length dt (s) of d (eq. 3.29, 3.55) and the covariance blocks P_x, L, Λ,
    B_η (eq. 3.42; §3.3.5: "propagation updates are computed using an RK4 integrator"), in
    place.  ``omega``
    (rad/s, body) is held over the step; ``sig_s``/``sig_w`` are the process-noise σ's in use
    (the gyro-less case of §3.3.3 sets σ_ω = 0 and σ_s = 1 rad/√s)."""
    eckf = prm[0] > 0.5
    sig_wd = prm[4] if eckf else 0.0
    k1 = _deriv(d, P, L, Lam, Beta, omega, sig_s, sig_w, sig_wd, eckf)
    h2 = 0.5 * dt
    k2 = _deriv(d + h2 * k1[0], P + h2 * k1[1], L + h2 * k1[2], Lam + h2 * k1[3],
                Beta + h2 * k1[4], omega, sig_s, sig_w, sig_wd, eckf)
    k3 = _deriv(d + h2 * k2[0], P + h2 * k2[1], L + h2 * k2[2], Lam + h2 * k2[3],
                Beta + h2 * k2[4], omega, sig_s, sig_w, sig_wd, eckf)
    k4 = _deriv(d + dt * k3[0], P + dt * k3[1], L + dt * k3[2], Lam + dt * k3[3],
                Beta + dt * k3[4], omega, sig_s, sig_w, sig_wd, eckf)
    c = dt / 6.0
    d += c * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
    P += c * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    for i in range(3):
        for j in range(i):
            a = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = a
            P[j, i] = a
    if eckf:
        L += c * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
        Lam += c * (k1[3] + 2 * k2[3] + 2 * k3[3] + k4[3])
        Beta += c * (k1[4] + 2 * k2[4] + 2 * k3[4] + k4[4])


@numba.njit(cache=True)
def _boundary_angle(n, b, u):
    """Angle (rad) from normal ``n`` to the nearest visibility boundary along the great circle
    through unit ``u``: the structure-horizon plane (normal ``b``, zero vector: none)."""
    c = n[0] * u[0] + n[1] * u[1] + n[2] * u[2]
    e = u - c * n
    ne = np.sqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2)
    bb = b[0] * b[0] + b[1] * b[1] + b[2] * b[2]
    if ne < 1e-12 or bb == 0.0:
        return np.pi
    e = e / ne
    bn = b[0] * n[0] + b[1] * n[1] + b[2] * n[2]
    be = b[0] * e[0] + b[1] * e[1] + b[2] * e[2]
    # b·(cos t n + sin t e) = 0 for the first t in (0, π) where it turns negative
    if be >= 0.0:
        return np.pi
    return np.arctan2(bn, -be)


@numba.njit(cache=True)
def thesis_update_nb(d, P, L, Lam, Beta, Bnu, y, normals, az, el, cos_fov, horizon, prm):
    """Measurement update in place (module docstring): EKF eq. 3.31c-d with the Joseph form of
    eq. 3.24; ECKF eq. 3.57d-f (H, M, J), the §3.2.3 consistency bound (eq. 3.61-3.63) and the
    consider update of eq. 3.47-3.52.  ``normals``/``az``/``el``/``cos_fov``/
    ``horizon``: the nominal sensor model the flight software knows.  Returns (number of
    sensors used, NIS), (0, NaN) when nothing was processed (shadow, or no sensor)."""
    N = y.shape[0]
    eckf = prm[0] > 0.5
    sig_v, strong_frac, strong_fac = prm[1], prm[6], prm[7]
    if not thesis_sunlit_nb(y, d, prm, True):
        return 0, np.nan
    nd = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    if nd < 1e-12:
        return 0, np.nan
    u = d / nd
    idx = np.empty(N, dtype=np.int64)
    fac = np.empty(N)
    inview = np.zeros(N, dtype=np.bool_)
    m = 0
    for i in range(N):
        c = normals[i, 0] * u[0] + normals[i, 1] * u[1] + normals[i, 2] * u[2]
        # predicted in view: inside the FOV (eq. 3.31c, 3.57d) and, for the dual pyramid,
        # above the structure horizon — the "second measurement discontinuity" of §3.2.3
        iv = c >= cos_fov[i] and (horizon[i, 0] * u[0] + horizon[i, 1] * u[1]
                                  + horizon[i, 2] * u[2]) >= 0.0
        strong = y[i] > strong_frac * nd
        if iv or strong:
            idx[m] = i
            fac[m] = 1.0 if iv else strong_fac
            inview[m] = iv
            m += 1
    if m == 0:
        return 0, np.nan
    H = np.empty((m, 3))
    nu = np.empty(m)
    R = np.zeros((m, m))
    for a in range(m):
        i = idx[a]
        for j in range(3):
            H[a, j] = normals[i, j]
        nu[a] = y[i] - (H[a, 0] * d[0] + H[a, 1] * d[1] + H[a, 2] * d[2])
        R[a, a] = (nd * sig_v * fac[a]) ** 2
    if not eckf:
        x_post, P_post, nis, ok = joseph_update_nb(d, P, nu, H, R, np.zeros(3, dtype=np.bool_))
        if not ok:
            return 0, np.nan
        d[:] = x_post
        P[:, :] = P_post
        return m, nis
    # ---- ECKF: J (eq. 3.57f) over β_ν = [C_κ, θ_β, φ_β, V_αβ] ---------------------------
    nb = 4 * N
    J = np.zeros((m, nb))
    smis = prm[10]
    for a in range(m):
        i = idx[a]
        J[a, 3 * N + i] = nd                      # V_αβ: |d̂| Ĉ_κ
        th, ph = az[i], el[i]
        if inview[a]:
            J[a, i] = H[a, 0] * d[0] + H[a, 1] * d[1] + H[a, 2] * d[2]
            J[a, N + i] = np.cos(ph) * (-d[0] * np.sin(th) + d[1] * np.cos(th))
            J[a, 2 * N + i] = (-(d[0] * np.cos(th) + d[1] * np.sin(th)) * np.sin(ph)
                               + d[2] * np.cos(ph))
        # §3.2.3 consistency: within γ of the visibility boundary (either side), add the
        # maximum error of eq. 3.63
        ci = H[a, 0] * u[0] + H[a, 1] * u[1] + H[a, 2] * u[2]
        ang = np.arccos(min(1.0, max(-1.0, ci)))
        psi_b = min(np.arccos(min(1.0, max(-1.0, cos_fov[i]))),
                    _boundary_angle(normals[i], horizon[i], u))
        cs = prm[9]
        # eq. 3.61 with cs × σ misalignments
        gm = np.arccos(min(1.0, np.cos(cs * smis) * np.cos(ph) * np.cos(ph + cs * smis)
                           + np.sin(ph) * np.sin(ph + cs * smis)))
        # eq. 3.62 (Appendix D): first-order variance of the angle between d̂ and c = n̂_i,
        # J_γ = (u (cᵀu) − c)ᵀ / (|d̂| √(1 − (cᵀu)²)) — the 1/|d̂| of the derivative is
        # missing from the printed eq. D.7
        den = np.sqrt(max(1e-12, 1.0 - ci * ci))
        Jg = (u * ci - H[a]) / (den * nd)
        vg = 0.0
        for p in range(3):
            for q in range(3):
                vg += Jg[p] * P[p, q] * Jg[q]
        gamma = gm + cs * np.sqrt(max(vg, 0.0))
        if not inview[a]:
            # a strong output from a sensor predicted dark (§3.2.1.2): the model's error can
            # be the sensor's whole range — eq. 3.63 with the Sun anywhere in the FOV
            gamma = np.pi
        if abs(psi_b - ang) < gamma:
            emax = nd * (np.cos(psi_b - min(psi_b, gamma)) + prm[11] + sig_v)
            R[a, a] += emax * emax
    # eq. 3.47-3.52 through the core: x = d, consider parameters [β_η, β_ν] with
    # cross-covariance [L, Λ] and covariance blockdiag(B_η, diag B_ν); only β_ν enters the
    # measurement (J); P_x⁺ = P_x − K W Kᵀ as printed (eq. 3.52a)
    nq = 6 + nb
    C = np.zeros((3, nq))
    C[:, :6] = L
    C[:, 6:] = Lam
    Bq = np.zeros((nq, nq))
    Bq[:6, :6] = Beta
    Jq = np.zeros((m, nq))
    for b in range(nb):
        Bq[6 + b, 6 + b] = Bnu[b]
        for a in range(m):
            Jq[a, 6 + b] = J[a, b]
    x_post, P_post, C_post, nis, ok = consider_update_nb(d, P, C, Bq, nu, H, Jq, R, False)
    if not ok:
        return 0, np.nan
    d[:] = x_post
    P[:, :] = P_post
    L[:, :] = C_post[:, :6]
    Lam[:, :] = C_post[:, 6:]
    return m, nis
