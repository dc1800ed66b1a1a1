"""Closed-loop truth simulation for the CSS studies (O'Keefe 2015, §2.4).

Spacecraft (:class:`Spacecraft`, defaults §2.4): inertia diag(10.5, 8.0, 7.5) kg m² (total,
wheels included), four reaction wheels with the spin axes G_s printed in §2.4
(:data:`~lightcurve.css.okeefe2015.WHEEL_AXES`), spin-axis inertia J_s = 0.001 kg m², motor
torque limit 30 mN m.

Dynamics (O'Keefe eq. B.1; Schaub & Junkins §4.5, reaction wheels; SI units, body axes)::

    [I_RW] ω̇ = −ω × ([I] ω + J_s [G_s] Ω) − [G_s] u_s + L_gg,    [I_RW] = [I] − J_s G_s G_sᵀ
    Ω̇ = u_s / J_s − G_sᵀ ω̇,       q̇ = ½ [0, ω] ⊗ q   (q inertial→body, scalar first)
    L_gg = 3 μ/|r|⁵  r_B × ([I] r_B)                  (gravity gradient)

integrated with the core's RK4 step (:func:`lightcurve.core.dynamics.rk4_step_xyz` with the
wheel momenta ``h = G_s h_s``, ``h_s = J_s (Ω + G_sᵀ ω)``, which grow linearly under the
motor torques held over a step; the gravity-gradient torque is evaluated at the step start and
held).  Time grid: CSS samples every
``dt_s`` (§2.4: 2 Hz), each split into ``substeps`` propagation steps at which the gyro is
sampled, the sequential estimators are propagated and the controller runs (§2.4: gyro at
10 Hz, so ``substeps = 5`` in the thesis set-up).

Orbit: circular at ``altitude_m``, inclination, RAAN (``raan_deg``; None draws it uniformly),
true anomaly uniform (§2.4 "initial true anomaly ... uniformly distributed amongst all possible
values"; ``start_sunlit`` redraws it until the start is sunlit); ``perturbations`` adds EGM2008
J2–J6, drag (exponential atmosphere, C_D A/m of the spacecraft) and solar radiation pressure
(§2.4) through :func:`lightcurve.geometry.orbits.propagate_orbit`, otherwise Keplerian.

Sensors: the CSS outputs of eq. 2.21 with albedo (:func:`~lightcurve.css.albedo.albedo_vectors_nb`
over the cap visible from the spacecraft, the truth map given as an :class:`AlbedoMap` or as a
TOMS (mean, std) pair drawn once per run, :func:`~lightcurve.css.albedo.draw_albedo_map`), noise
added before (``noise_in_scale``, eq. 2.21: ``V = C C_κ (V_d + V_α + ν_V)``) or after the
scale factors, clipped at zero ("negative measurements are not possible", §3.2.2.2, §4.2); the
gyro of :mod:`lightcurve.css.gyro` (eq. 2.50).

Random numbers: each run draws, from child generators of its seed in a fixed order, the orbit
and attitude, the CSS errors and noise, the albedo realisation and the gyro bias and noise —
whether or not a gyro or albedo is used — so that every estimator, gyro grade and control
option of a study flies the same spacecraft (common random numbers).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from ..core.constants import MU_EARTH, OMEGA_EARTH, P_SUN_1AU, R_EARTH_M
from ..core.dynamics import mat9, rk4_step_xyz
from ..core.kalman import inverse_nb
from ..core.rotations import euler321_to_dcm_nb, qrot_inv_nb, qrot_nb
from ..estimation.rng import as_generator
from .albedo import (AlbedoCells, AlbedoMap, albedo_sun_frame_nb, albedo_vectors_nb,
                     builtin_albedo_map, cell_areas_m2, earth_rotation_angle, sun_nadir_axis_nb)
from .attitude_ekf import mv3_nb
from .control import ControlParams, mrp_control_nb, saturate_nb, sun_pointing_mrp_nb
from .gyro import GyroSpec, gyro_grade, gyro_step_nb
from .okeefe2015 import SPACECRAFT, WHEEL_AXES
from .sensors import CSSArray
from .single_point import lsmn_nb, wavg_nb
from .sunline_ekf import (FilterParams, default_filter_params, filter_init_nb,
                          filter_step_albedo_nb, rate_from_estimates_nb,
                          successive_rate_nb)
from .sunline_thesis import (THESIS_PRM, thesis_init_nb, thesis_propagate_nb, thesis_sunlit_nb,
                             thesis_update_nb)

__all__ = ["Spacecraft", "Dispersions", "CSSScenario", "SimResult", "simulate_css",
           "simulate_css_cases", "ESTIMATORS", "truth_loop_nb"]

ESTIMATORS = ("ekf", "eckf", "wavg", "lsmn", "wlsmn")


@dataclass(frozen=True)
class Spacecraft:
    """Mass properties, wheels and surfaces (§2.4). inertia kg m²; wheel_axes (3,n); J_s
    kg m²; torque limit N m; wheel speed limit rad/s relative to the body (§2.4 gives none:
    unlimited by default); drag and SRP areas m², C_D, C_R (see okeefe2015.SPACECRAFT)."""

    mass_kg: float = SPACECRAFT["mass_kg"]
    inertia: tuple = ((10.5, 0.0, 0.0), (0.0, 8.0, 0.0), (0.0, 0.0, 7.5))
    wheel_axes: np.ndarray = field(default_factory=lambda: WHEEL_AXES.copy())
    wheel_inertia: float = SPACECRAFT["wheel_inertia_kg_m2"]
    wheel_max_torque: float = SPACECRAFT["wheel_max_torque_nm"]
    wheel_max_speed_rad_s: float = np.inf
    drag_area_m2: float = SPACECRAFT["drag_area_m2"]
    drag_coefficient: float = SPACECRAFT["drag_coefficient"]
    srp_area_m2: float = SPACECRAFT["srp_area_m2"]
    srp_cr: float = SPACECRAFT["srp_cr"]


@dataclass(frozen=True)
class Dispersions:
    """Monte Carlo dispersions (angles in degrees at this edge).

    Initial body rates: uniform in ±``rate_max_deg_s`` per axis when that is set (§2.4: 2°/s),
    else N(0, ``rate_sigma_deg_s``²).  Common CSS scale factor: ``1 + U(0,
    css_scale_common_max)`` when that is set (§2.4: 0–50 %), else N(1, ``css_scale_common_sigma``²);
    individual C_κ ~ N(1, ``css_scale_sigma``²); misalignment angles N(0,
    ``css_misalignment_sigma_deg``²); output noise 1σ ``css_noise_sigma``.  The defaults are
    the package's generic test set-up; the thesis's values are built by
    :func:`lightcurve.css.experiments.thesis_dispersions`.
    """

    rate_sigma_deg_s: float = 1.0
    css_scale_common_sigma: float = 0.05
    css_scale_sigma: float = 0.02
    css_misalignment_sigma_deg: float = 1.0
    css_noise_sigma: float = 0.017
    rate_max_deg_s: float | None = None
    css_scale_common_max: float | None = None


@dataclass
class CSSScenario:
    """One CSS simulation case.

    css: nominal sensor set; estimator: one of ESTIMATORS; variant: "thesis" (O'Keefe's
    estimators and controller, :mod:`.sunline_thesis`, eq. 3.64 with its integral term) or
    "robust" (:mod:`.sunline_ekf` with its albedo model, :mod:`.control` without integral
    term); gyro: grade name, a GyroSpec, or None (gyro-less); controlled: run the controller;
    duration_s; dt_s: CSS sample period; substeps: propagation/gyro/control steps per CSS
    sample; albedo: an AlbedoMap, a (mean, std) pair of AlbedoMaps (drawn per run), None for
    the built-in 10° zonal model, or False (off); filter_params: the robust filters' tuning
    (None: :func:`~lightcurve.css.sunline_ekf.default_filter_params` of ``gyro``);
    filter_albedo: the albedo model of the robust filters, same choices except pairs; thesis_params: parameter array of the thesis
    filter (:func:`lightcurve.css.sunline_thesis.thesis_params`); thesis_control: (K, P, K_I,
    deadband rad) of eq. 3.64; noise_in_scale: eq. 2.21's noise inside the scale factors;
    shadow_model: Earth-shadow model of the truth, "conical" (umbra and penumbra: the direct
    term scales with the visible fraction of the solar disc) or "cylindrical" (binary, the
    ``B ∈ S`` of O'Keefe eq. 2.21, :func:`lightcurve.geometry.eclipse.lit_fraction`).
    """

    css: CSSArray
    estimator: str = "ekf"
    gyro: object = "tactical"
    controlled: bool = False
    duration_s: float = 1800.0
    dt_s: float = 0.5
    substeps: int = 1
    epoch_utc: str = "2015-03-01T00:00:00Z"
    altitude_m: float = 400e3
    inclination_deg: float = 90.0
    raan_deg: float | None = None
    perturbations: bool = False
    spacecraft: Spacecraft = field(default_factory=Spacecraft)
    dispersions: Dispersions = field(default_factory=Dispersions)
    filter_params: FilterParams | None = None
    control: ControlParams = field(default_factory=ControlParams)
    albedo: object = None
    filter_albedo: object = None
    gravity_gradient: bool = True
    start_sunlit: bool = True
    variant: str = "robust"
    thesis_params: np.ndarray | None = None
    thesis_control: tuple = (0.041, 0.5, 0.001, float(np.radians(1.0)))
    noise_in_scale: bool = False
    shadow_model: str = "conical"
    gyroless: dict = field(default_factory=lambda: {"rate_limit_deg_s": 10.0,
                                                    "lowpass_hz": 10.0, "sigma_s": 1.0})

    def __post_init__(self):
        from ..filters.config import VARIANTS   # here: importing lightcurve.filters costs ~0.5 s

        if self.estimator not in ESTIMATORS:
            raise ValueError(f"unknown estimator {self.estimator!r}; allowed: {', '.join(ESTIMATORS)}")
        if self.variant not in VARIANTS:
            raise ValueError(f"unknown variant {self.variant!r}; allowed: {', '.join(VARIANTS)}")
        if not (self.dt_s > 0 and self.duration_s > self.dt_s):
            raise ValueError("need dt_s > 0 and duration_s > dt_s")
        if self.shadow_model not in ("conical", "cylindrical"):
            raise ValueError(f"unknown shadow_model {self.shadow_model!r}; allowed: conical, "
                             "cylindrical")
        if int(self.substeps) < 1:
            raise ValueError("substeps must be >= 1")
        if self.filter_params is None:
            self.filter_params = default_filter_params(self.gyro)


@dataclass
class SimResult:
    """Time histories of one run at the CSS samples (K samples at t, s).

    q (K,4) true attitude (inertial→body); omega (K,3) true rate rad/s; s_true (K,3) true
    unit Sun direction in body axes; s_hat (K,3) estimate (zeros when none); y (K,N) CSS
    outputs; lit (K,); direct (K,) number of sensors truly lit by the Sun (noise-free direct
    term > 0, the thesis's "valid direct Sun measurement"); n_active (K,); omega_used (K,3)
    rate fed to estimator/controller; wheel_speed (K,n) rad/s; error_deg (K,) angle between
    s_hat and s_true (180 when none); p_cov (K,3,3) and d_hat (K,3): the sun-line filter's
    covariance and scaled Sun vector (EKF/ECKF only, zeros before the filter starts);
    nis (K,) the filter's NIS (NaN without an update).
    """

    t: np.ndarray
    q: np.ndarray
    omega: np.ndarray
    s_true: np.ndarray
    s_hat: np.ndarray
    y: np.ndarray
    lit: np.ndarray
    n_active: np.ndarray
    omega_used: np.ndarray
    wheel_speed: np.ndarray
    error_deg: np.ndarray
    info: dict
    p_cov: np.ndarray | None = None
    d_hat: np.ndarray | None = None
    direct: np.ndarray | None = None
    nis: np.ndarray | None = None


# ---------------------------------------------------------------------------------------
# numba core
# ---------------------------------------------------------------------------------------
@numba.njit(cache=True)
def _thesis_control_nb(s_est, valid, w_ctrl, I, G, G_pinv, h_abs, zint, dw0, gains, umax,
                       axis, dt):
    """Eq. 3.64 with ω_R = ω̇_R = 0 and L = 0: G_s u_s = Kσ + PΔω + P K_I z + [K_I z]× H,
    H = [I]ω + G_s h_s, z = K∫σ dt + [I](Δω − Δω₀) (integral feedback of ref. 90); σ of
    eq. 3.66 is zero inside the deadband.  Updates ``zint`` in place; returns u_s (n,)."""
    K, P, KI, deadband = gains[0], gains[1], gains[2], gains[3]
    sig = np.zeros(3)
    if valid:
        s, phi = sun_pointing_mrp_nb(s_est, axis)
        if phi >= deadband:
            sig = s
    for i in range(3):
        zint[i] += K * sig[i] * dt
    z = zint + I @ (w_ctrl - dw0)
    kz = KI * z
    H = I @ w_ctrl + G @ h_abs
    rhs = K * sig + P * w_ctrl + P * kz + np.cross(kz, H)
    u = G_pinv @ rhs
    saturate_nb(u, umax)
    return u


@numba.njit(cache=True)
def truth_loop_nb(geom, sens, gyro, body, init, est, ctrl):
    """The whole closed loop (module docstring), its inputs packed by subject.

    geom = (t, sub, r_I, sun_I, lit, theta): t (K,) CSS sample times; ``sub`` propagation
    steps per sample; r_I ((K−1)·sub+1, 3) positions at every propagation step (rows
    k·sub + j; see :func:`simulate_css`); sun_I, lit, theta at the CSS samples;
    sens = (cells, css_true, css_noise, noise_in_scale, alb_pre): ``cells`` =
    AlbedoCells.args() of the truth (with the run's ρA); css_true = (normals, cos_fov, gains,
    horizon); css_noise (K,N) standard normals × σ; noise_in_scale (bool, eq. 2.21);
    ``alb_pre`` (K,N): the albedo part of every output when already known (an uncontrolled
    run repeated with another estimator flies the same attitude), else an empty array;
    gyro = (use, arw, rrw, bias0 (3), n_u (K*sub,3), n_v (K*sub,3), lowpass_alpha,
    rate_max, sigma_s_gyroless); body = (I, G, Js, umax, om_max, mu_gg); init = (q0, w0);
    est = (kind, variant, thesis prm, robust prm, normals, az, el, cos_fov, horizon,
    falb cells tuple (centers, normals, rho_area)); ctrl = (controlled, thesis gains (4,),
    robust gains (3,), axis).  kind −1: no estimator.
    Returns Q, Wt, St, Sh, Y, NA, Wu, OM, PC, DH, DIR, NIS, ALB at the K samples and GYR, the
    gyro samples of every propagation step ((K−1)·sub, 3).
    """
    t, sub, r_I, sun_I, lit, theta = geom
    cells, css_true, css_noise, noise_in_scale, alb_pre = sens
    K = t.shape[0]
    n_true, cos_fov_t, gains_t, horizon_t = css_true
    N = n_true.shape[0]
    use_gyro, arw, rrw, gbias0, g_nu, g_nv, lp_alpha, rate_max, sig_s_nogyro = gyro
    I, G, Js, umax, om_max, mu_gg = body
    q0, w0 = init
    kind, variant, tprm, fprm, n_nom, az_nom, el_nom, cosf_nom, hor_nom, falb = est
    controlled, tgains, rgains, h_axis = ctrl
    falb_c, falb_n, falb_ra = falb
    cc, cn, cra, lat_c, nlat, nlon, lon_w0, dlon, dlat_max = cells
    thesis = variant == 0
    nw = G.shape[1]
    # O'Keefe eq. B.1 through the core's RK4 step: J = [I_RW] = [I] − J_s G_s G_sᵀ, wheel
    # momenta h_s = J_s (Ω + G_sᵀ ω), motor torques u_s (constant over a step)
    IRW = I - Js * (G @ G.T)
    IRW_inv, _ = inverse_nb(IRW)
    J_rw = mat9(IRW)
    K_rw = mat9(IRW_inv)
    GGi, _ = inverse_nb(G @ G.T)
    G_pinv = G.T @ GGi
    Q = np.zeros((K, 4))
    Wt = np.zeros((K, 3))
    St = np.zeros((K, 3))
    Sh = np.zeros((K, 3))
    Y = np.zeros((K, N))
    NA = np.zeros(K, dtype=np.int64)
    Wu = np.zeros((K, 3))
    OM = np.zeros((K, nw))
    PC = np.zeros((K, 3, 3))
    DH = np.zeros((K, 3))
    DIR = np.zeros(K, dtype=np.int64)
    NIS = np.full(K, np.nan)
    ALB = np.zeros((K, N))
    GYR = np.zeros((max(K - 1, 0) * sub, 3))
    have_pre = alb_pre.shape[0] == K
    q = q0.copy()
    w = w0.copy()
    Om = np.zeros(nw)
    bias = gbias0.copy()
    # ---- estimator state ----------------------------------------------------------------
    d = np.zeros(3)
    P = np.eye(3)
    Lb = np.zeros((3, 6))
    Lam = np.zeros((3, 4 * N))
    Beta = np.zeros((6, 6))
    Bnu = np.zeros(4 * N)
    Pxc = np.zeros((3, 3))
    started = False
    have_prev = False
    d_prev = np.zeros(3)
    om_f = np.zeros(3)
    s_est = np.zeros(3)
    valid = False
    shadow = True
    dark_r = False   # robust variant: no CSS output above its threshold at this sample
    dark = 0.0
    w_acc = np.zeros(3)
    n_acc = 0
    thr_r = fprm[2]
    alpha_r, rmax_r = fprm[9], fprm[10]
    f_alb = (not thesis) and kind <= 1 and fprm[15] > 0.5 and falb_c.shape[0] > 0
    phi_state = np.zeros(7 + int(fprm[17])) if (f_alb and fprm[18] > 0.5) else np.zeros(0)
    fa_coords = np.zeros((0, 3))
    fa_ratio = np.zeros(0)
    fa_m = 0
    e2_I = np.zeros(3)
    zint = np.zeros(3)
    dw0 = np.zeros(3)
    ctrl_started = False
    u = np.zeros(nw)
    u_f = np.zeros(nw)
    y_f = np.zeros(N)
    w_meas = np.zeros(3)
    sig_w_t = tprm[3] if use_gyro else 0.0
    sig_s_t = tprm[2] if use_gyro else sig_s_nogyro
    nE = np.empty((N, 3))
    hE = np.empty((N, 3))
    eye3 = np.eye(3)
    zeros_edge = np.zeros(N)
    for k in range(K):
        # ================= CSS sample ====================================================
        Q[k] = q
        Wt[k] = w
        OM[k] = Om
        s_b = qrot_nb(q, sun_I[k])
        St[k] = s_b
        alb = np.zeros(N)
        if have_pre:
            alb[:] = alb_pre[k]
        elif nlat > 0 and lit[k] > 0.0:
            E = euler321_to_dcm_nb(np.array([theta[k], 0.0, 0.0]))  # ECI → Earth-fixed, R3(θ)
            rE = mv3_nb(E, r_I[k * sub])
            sE = mv3_nb(E, sun_I[k])
            for j in range(N):
                nE[j] = mv3_nb(E, qrot_inv_nb(q, n_true[j]))
                hE[j] = mv3_nb(E, qrot_inv_nb(q, horizon_t[j]))
            V, _, _ = albedo_vectors_nb(cc, cn, cra, lat_c, nlat, nlon, lon_w0, dlon, dlat_max,
                                        rE, sE, nE, cos_fov_t, hE, zeros_edge)
            for j in range(N):
                alb[j] = nE[j, 0] * V[j, 0] + nE[j, 1] * V[j, 1] + nE[j, 2] * V[j, 2]
        nd_lit = 0
        for j in range(N):
            c = n_true[j, 0] * s_b[0] + n_true[j, 1] * s_b[1] + n_true[j, 2] * s_b[2]
            r = 0.0
            if lit[k] > 0.0 and c >= cos_fov_t[j] and c > 0.0:
                if (horizon_t[j, 0] * s_b[0] + horizon_t[j, 1] * s_b[1]
                        + horizon_t[j, 2] * s_b[2]) >= 0.0:
                    r = lit[k] * c
                    nd_lit += 1
            if noise_in_scale:
                v = gains_t[j] * (r + alb[j] + css_noise[k, j])
            else:
                v = gains_t[j] * (r + alb[j]) + css_noise[k, j]
            Y[k, j] = v if v > 0.0 else 0.0
        DIR[k] = nd_lit
        ALB[k] = alb
        ymax = 0.0
        for j in range(N):
            if Y[k, j] > ymax:
                ymax = Y[k, j]
        # ================= estimator update ==============================================
        if kind >= 0:
            dt_c = t[1] - t[0] if k == 0 else t[k] - t[k - 1]
            if kind <= 1 and thesis:
                shadow = not thesis_sunlit_nb(Y[k], d, tprm, started)
                if not started:
                    if thesis_init_nb(Y[k], n_nom, tprm, d, P, Lb, Lam, Beta, Bnu):
                        started = True
                        valid = True
                else:
                    m, nis = thesis_update_nb(d, P, Lb, Lam, Beta, Bnu, Y[k], n_nom, az_nom,
                                              el_nom, cosf_nom, hor_nom, tprm)
                    NA[k] = m
                    NIS[k] = nis
                if started:
                    if not use_gyro and not shadow:
                        if have_prev:
                            wr = rate_from_estimates_nb(d, d_prev, dt_c, rate_max, True)
                            om_f = lp_alpha * om_f + (1.0 - lp_alpha) * wr
                        d_prev[:] = d
                        have_prev = True
                    elif not use_gyro:
                        have_prev = False
            elif kind <= 1:
                # robust sun-line filters (sunline_ekf.py), propagated over the sample period
                if not started:
                    d, P, Pxc, ok = filter_init_nb(Y[k], n_nom, fprm)
                    if ok:
                        started = True
                        d_prev[:] = d
                else:
                    lit_now = False
                    for j in range(N):
                        if Y[k, j] > thr_r:
                            lit_now = True
                    if not use_gyro and not lit_now:
                        # §3.3.3: without a gyro the rate comes from Sun estimates only; none
                        # in the dark, so the filter is held (ω = 0) and the rate restarts
                        om_f[:] = 0.0
                        have_prev = False
                    om = w_acc / max(n_acc, 1) if use_gyro else om_f
                    reset = lit_now and fprm[14] > 0 and dark >= fprm[14]
                    if f_alb:
                        E = euler321_to_dcm_nb(np.array([theta[k], 0.0, 0.0]))
                        fa_coords, fa_ratio, fa_m = albedo_sun_frame_nb(
                            falb_c, falb_n, falb_ra, mv3_nb(E, r_I[k * sub]), mv3_nb(E, sun_I[k]))
                        e2_I = sun_nadir_axis_nb(r_I[k * sub], sun_I[k])
                    m, nis, infl = filter_step_albedo_nb(kind, d, P, Pxc, om, dt_c, Y[k], n_nom,
                                                         fprm, reset, fa_coords, fa_ratio, fa_m,
                                                         cosf_nom, hor_nom, phi_state, e2_I,
                                                         sun_I[k])
                    dark = 0.0 if lit_now else dark + dt_c
                    NA[k] = m
                    NIS[k] = nis if m > 0 else np.nan
                    if not use_gyro and lit_now:
                        if have_prev and not reset:
                            om_f = successive_rate_nb(d, d_prev, dt_c, om_f, alpha_r, rmax_r)
                        have_prev = True
                    d_prev[:] = d
                    dark_r = not lit_now
            else:
                yk = Y[k]
                thr_sp = 0.0 if thesis else thr_r
                if thesis and not use_gyro:
                    # §3.3.3: CSS measurements low-pass filtered for the single-point methods
                    for j in range(N):
                        y_f[j] = lp_alpha * y_f[j] + (1.0 - lp_alpha) * Y[k, j] if k > 0 else Y[k, j]
                    yk = y_f
                if kind == 2:
                    s_new = wavg_nb(yk, n_nom, thr_sp)
                else:
                    s_new = lsmn_nb(yk, n_nom, thr_sp, kind == 4)
                ok = (s_new[0] ** 2 + s_new[1] ** 2 + s_new[2] ** 2) > 0
                shadow = ymax < tprm[8]
                cnt = 0
                for j in range(N):
                    if yk[j] > thr_sp:
                        cnt += 1
                NA[k] = cnt
                dark_r = not ok
                if not use_gyro and not thesis and not ok:
                    om_f[:] = 0.0     # §3.3.3, as for the robust filters above
                    have_prev = False
                if not use_gyro:
                    if ok and have_prev and not (thesis and shadow):
                        if thesis:
                            wr = rate_from_estimates_nb(s_new, d_prev, dt_c, rate_max, True)
                            om_f = lp_alpha * om_f + (1.0 - lp_alpha) * wr
                        else:
                            om_f = successive_rate_nb(s_new, d_prev, dt_c, om_f, alpha_r, rmax_r)
                    if ok:
                        d_prev[:] = s_new
                        have_prev = True
                if ok:
                    s_est = s_new
                    valid = True
                else:
                    valid = False
            if kind <= 1 and started:
                # the sun-line filters (thesis and robust): unit estimate, covariance, d
                nd = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
                if nd > 0:
                    s_est = d / nd
                    valid = True
                PC[k] = P
                DH[k] = d
        Sh[k] = s_est if valid else np.zeros(3)
        w_acc[:] = 0.0
        n_acc = 0
        if k == K - 1:
            Wu[k] = w_meas if use_gyro else om_f
            break
        # ================= propagation steps =============================================
        h = (t[k + 1] - t[k]) / sub
        for j in range(sub):
            ks = k * sub + j
            if use_gyro:
                w_meas = gyro_step_nb(w, bias, eye3, arw, rrw, h, g_nu[ks], g_nv[ks])
            else:
                # the truth still draws the gyro's random numbers (common random numbers)
                gyro_step_nb(w, bias, eye3, arw, rrw, h, g_nu[ks], g_nv[ks])
            GYR[ks] = w_meas
            if j == 0:
                Wu[k] = w_meas if use_gyro else om_f
            w_acc += w_meas
            n_acc += 1
            # §3.3.3: without a gyro, propagation and all control effort are suspended in
            # the dark (thesis: its shadow test; robust: no output above threshold)
            suspended = (not use_gyro) and (shadow if thesis else dark_r)
            if kind <= 1 and kind >= 0 and thesis and started and not suspended:
                om = w_meas if use_gyro else om_f
                thesis_propagate_nb(d, P, Lb, Lam, Beta, om, h, tprm, sig_s_t, sig_w_t)
                nd = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
                if nd > 0:
                    s_est = d / nd
            # ---- control ------------------------------------------------------------
            u[:] = 0.0
            # robust variant with a gyro and FilterParams.hold_in_dark: no control in the dark
            held = use_gyro and not thesis and fprm.shape[0] > 24 and fprm[24] > 0.5 and dark_r
            if controlled and kind >= 0 and not suspended and not held:
                w_ctrl = w_meas if use_gyro else om_f
                if thesis:
                    if not ctrl_started:
                        dw0[:] = w_ctrl
                        ctrl_started = True
                    h_abs = Js * (G.T @ w_ctrl + Om)
                    u = _thesis_control_nb(s_est, valid, w_ctrl, I, G, G_pinv, h_abs, zint,
                                           dw0, tgains, umax, h_axis, h)
                    if not use_gyro and kind >= 2:
                        # §3.3.3: wheel torques low-pass filtered for single-point methods
                        u_f[:] = lp_alpha * u_f + (1.0 - lp_alpha) * u
                        u = u_f.copy()
                else:
                    h_w = Js * (G.T @ w_ctrl + Om)
                    u = mrp_control_nb(s_est, valid, w_ctrl, I, G, h_w, G_pinv, rgains[0],
                                       rgains[1], rgains[2], umax, h_axis, use_gyro)
                for i in range(nw):
                    if (Om[i] >= om_max and u[i] > 0.0) or (Om[i] <= -om_max and u[i] < 0.0):
                        u[i] = 0.0
            # ---- truth --------------------------------------------------------------
            # gravity-gradient torque on the whole spacecraft, held over the step
            Lext = np.zeros(3)
            if mu_gg > 0.0:
                rb = qrot_nb(q, r_I[ks])
                rn = np.sqrt(rb[0] ** 2 + rb[1] ** 2 + rb[2] ** 2)
                Lext = 3.0 * mu_gg / rn ** 5 * np.cross(rb, I @ rb)
            hs = Js * (G.T @ w + Om)
            hb = G @ hs
            tau = G @ u
            a0, a1, a2, a3, b0, b1, b2 = rk4_step_xyz(
                q[0], q[1], q[2], q[3], w[0], w[1], w[2], h, J_rw, K_rw,
                (Lext[0], Lext[1], Lext[2]), None, (hb[0], hb[1], hb[2], tau[0], tau[1], tau[2]))
            sgn = -1.0 if a0 < 0.0 else 1.0     # the truth keeps q1 ≥ 0
            q = np.array([sgn * a0, sgn * a1, sgn * a2, sgn * a3])
            w = np.array([b0, b1, b2])
            Om = (hs + h * u) / Js - G.T @ w
    return Q, Wt, St, Sh, Y, NA, Wu, OM, PC, DH, DIR, NIS, ALB, GYR


# ---------------------------------------------------------------------------------------
# object layer
# ---------------------------------------------------------------------------------------
def _random_quat(g):
    q = g.normal(size=4)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def _kepler_orbit(alt, inc, raan, u0, t):
    a = R_EARTH_M + alt
    n = np.sqrt(MU_EARTH / a ** 3)
    u = u0 + n * t
    cO, sO, ci, si = np.cos(raan), np.sin(raan), np.cos(inc), np.sin(inc)
    return a * np.column_stack([cO * np.cos(u) - sO * np.sin(u) * ci,
                                sO * np.cos(u) + cO * np.sin(u) * ci,
                                np.sin(u) * si])


def _perturbed_orbit(sc: CSSScenario, raan, u0, t, sun_dir0):
    """J2–J6 + drag + SRP (§2.4) from the circular state at argument of latitude u0."""
    from ..dynamics.atmosphere import density_kg_m3
    from ..geometry.frames import earth_pole_gcrs
    from ..geometry.orbits import coe_to_rv, propagate_orbit

    a = R_EARTH_M + sc.altitude_m
    r0, v0 = coe_to_rv(a, 0.0, np.radians(sc.inclination_deg), raan, 0.0, u0)
    scf = sc.spacecraft
    bd = scf.drag_coefficient * scf.drag_area_m2 / scf.mass_kg
    bs = P_SUN_1AU * scf.srp_cr * scf.srp_area_m2 / scf.mass_kg
    we = np.array([0.0, 0.0, OMEGA_EARTH])
    s = np.asarray(sun_dir0, float)

    def accel(_t, r, v):
        rn = np.linalg.norm(r)
        vr = v - np.cross(we, r)
        out = -0.5 * density_kg_m3(max(rn - R_EARTH_M, 0.0)) * bd * np.linalg.norm(vr) * vr
        rs = r @ s
        if rs > 0 or np.linalg.norm(r - rs * s) > R_EARTH_M:   # cylindrical shadow
            out = out - bs * s
        return out

    pole = earth_pole_gcrs(sc.epoch_utc, 0.0)[0]
    r, _ = propagate_orbit(r0, v0, t, gravity="J6", pole=pole, accel=accel, rtol=1e-10,
                           atol_m=1e-3)
    return r


_CELLS_CACHE: dict = {}


def _cells_for(spec, rng):
    """(AlbedoCells.args() with this run's ρA, label) of a truth/filter albedo spec."""
    if spec is False:
        c = AlbedoCells.none()
        return c.args(), "none"
    pair = isinstance(spec, tuple)
    base = spec[0] if pair else (builtin_albedo_map(10.0) if spec is None else spec)
    key = id(base) if spec is not None else "builtin10"
    if key not in _CELLS_CACHE:
        if not isinstance(base, AlbedoMap):
            raise ValueError("albedo must be an AlbedoMap, a (mean, std) pair, None (built-in) "
                             "or False (off)")
        cells = AlbedoCells.from_map(base)
        area = cell_areas_m2(base.lat_edges_rad, base.lon_edges_rad).reshape(-1)
        _CELLS_CACHE[key] = (cells, area, base)
    cells, area, base = _CELLS_CACHE[key]
    args = list(cells.args())
    if pair:
        mean, std = spec
        v = np.clip(mean.values + std.values * rng.standard_normal(mean.values.shape), 0.0, 1.0)
        args[2] = np.ascontiguousarray(area * v.reshape(-1))
    return tuple(args), base.source


def _grid_for_robust(spec):
    if spec is False:
        z = np.zeros((0, 3))
        return z, z.copy(), np.zeros(0)
    amap = builtin_albedo_map(10.0) if spec is None else (spec[0] if isinstance(spec, tuple) else spec)
    key = ("grid", id(amap) if spec is not None else "builtin10")
    if key not in _CELLS_CACHE:
        g = amap.grid()
        _CELLS_CACHE[key] = (g.centers_m, g.normals, g.rho_area_m2)
    return _CELLS_CACHE[key]


def simulate_css(sc: CSSScenario, rng, *, _albedo_cache=None) -> SimResult:
    """Draw the dispersions and run one closed-loop (or open-loop tumbling) case.

    ``rng`` is a numpy Generator or seed; a given seed reproduces the run bit for bit, and
    two scenarios that differ only in estimator, variant, gyro or control see the same
    spacecraft, orbit, albedo and noise (module docstring).
    """
    from ..geometry.eclipse import lit_fraction
    from ..geometry.time import sun_position_gcrs

    g = as_generator(rng)
    g_orb, g_css, g_alb, g_gyro = g.spawn(4)
    disp = sc.dispersions
    sub = int(sc.substeps)
    t = np.arange(0.0, sc.duration_s + 0.5 * sc.dt_s, sc.dt_s)
    K = t.size
    tf = (np.arange((K - 1) * sub + 1) * (sc.dt_s / sub))
    # ---- orbit and attitude --------------------------------------------------------------
    sun0 = sun_position_gcrs(sc.epoch_utc, np.array([0.0]))[0]
    inc = np.radians(sc.inclination_deg)
    raan = g_orb.uniform(0, 2 * np.pi) if sc.raan_deg is None else np.radians(sc.raan_deg)
    for _ in range(1000):
        u0 = g_orb.uniform(0, 2 * np.pi)
        r0 = _kepler_orbit(sc.altitude_m, inc, raan, u0, np.array([0.0]))
        if not sc.start_sunlit or lit_fraction(r0, sun0[None, :], sc.shadow_model)[0] > 0.999:
            break
    q0 = _random_quat(g_orb)
    if disp.rate_max_deg_s is not None:
        w0 = np.radians(g_orb.uniform(-disp.rate_max_deg_s, disp.rate_max_deg_s, 3))
    else:
        w0 = np.radians(g_orb.normal(0.0, disp.rate_sigma_deg_s, 3))
    if sc.perturbations:
        r_f = _perturbed_orbit(sc, raan, u0, tf, sun0 / np.linalg.norm(sun0))
    else:
        r_f = _kepler_orbit(sc.altitude_m, inc, raan, u0, tf)
    r_f = np.ascontiguousarray(r_f)
    r_I = r_f[::sub]
    tc = np.arange(0.0, t[-1] + 60.0, 60.0)
    sun_c = sun_position_gcrs(sc.epoch_utc, tc)
    sun_m = np.column_stack([np.interp(t, tc, sun_c[:, i]) for i in range(3)])
    lit = lit_fraction(r_I, sun_m, sc.shadow_model)
    sun_hat = np.ascontiguousarray(sun_m / np.linalg.norm(sun_m, axis=1, keepdims=True))
    theta = earth_rotation_angle(sc.epoch_utc, t)
    # ---- CSS errors and noise ----------------------------------------------------------
    css = sc.css
    N = css.n_sensors
    if disp.css_scale_common_max is not None:
        c_common = 1.0 + g_css.uniform(0.0, disp.css_scale_common_max)
    else:
        c_common = max(0.05, 1.0 + g_css.normal(0, disp.css_scale_common_sigma))
    true_css = css.with_errors(
        scale_common=c_common,
        scale_individual=np.maximum(0.05, 1.0 + g_css.normal(0, disp.css_scale_sigma, N)),
        misalignment_rad=np.radians(g_css.normal(0, disp.css_misalignment_sigma_deg, (N, 2))),
        noise_sigma=disp.css_noise_sigma)
    n_true, cos_fov, gains, horizon = true_css.kernel_args()
    css_noise = g_css.normal(0.0, disp.css_noise_sigma, (K, N))
    cells, alb_label = _cells_for(sc.albedo, g_alb)
    # ---- gyro (always drawn) ------------------------------------------------------------
    spec = None if sc.gyro is None else (sc.gyro if isinstance(sc.gyro, GyroSpec) else gyro_grade(sc.gyro))
    zb = g_gyro.standard_normal(3)
    g_nu = g_gyro.standard_normal((K * sub, 3))
    g_nv = g_gyro.standard_normal((K * sub, 3))
    if spec is not None:
        gb0, arw, rrw = zb * spec.bias_sigma, spec.arw, spec.rrw
    else:
        gb0, arw, rrw = np.zeros(3), 0.0, 0.0
    # ---- estimator ----------------------------------------------------------------------
    fparams = sc.filter_params.for_css(css)
    if spec is not None:
        fparams = fparams.for_gyro(spec)
    thesis = sc.variant == "thesis"
    if thesis and sc.thesis_params is None and sc.estimator in ("ekf", "eckf"):
        raise ValueError("variant 'thesis' needs thesis_params (lightcurve.css.experiments)")
    tprm = (np.asarray(sc.thesis_params, float) if sc.thesis_params is not None
            else np.zeros(len(THESIS_PRM)))
    if tprm[8] == 0.0:
        tprm = tprm.copy()
        tprm[8] = 0.25
    from .sensors import normal_to_azel

    az0, el0 = normal_to_azel(css.normals)
    falb = (_grid_for_robust(sc.filter_albedo) if (not thesis and sc.estimator in ("ekf", "eckf")
                                                   and sc.filter_params.albedo_model)
            else (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)))
    est_kind = ESTIMATORS.index(sc.estimator)
    gl = sc.gyroless
    lp_dt = sc.dt_s  # the eq. 3.67 rate is formed at the CSS samples
    lp_alpha = float(np.exp(-2.0 * np.pi * gl["lowpass_hz"] * lp_dt)) if thesis else 0.0
    scf = sc.spacecraft
    I = np.asarray(scf.inertia, dtype=float)
    G = np.ascontiguousarray(scf.wheel_axes, dtype=float)
    axis = np.asarray(sc.control.axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    out = truth_loop_nb(
        (t, sub, r_f, sun_hat, lit, theta),
        (cells, (n_true, cos_fov, gains, horizon), css_noise, bool(sc.noise_in_scale),
         _albedo_cache if _albedo_cache is not None else np.zeros((0, N))),
        (spec is not None, float(arw), float(rrw), gb0, g_nu, g_nv, lp_alpha,
         float(np.radians(gl["rate_limit_deg_s"])), float(gl["sigma_s"])),
        (I, G, float(scf.wheel_inertia), float(scf.wheel_max_torque),
         float(scf.wheel_max_speed_rad_s), MU_EARTH if sc.gravity_gradient else 0.0),
        (q0, w0),
        (est_kind, 0 if thesis else 1, tprm, fparams.as_array(), css.normals.copy(),
         np.ascontiguousarray(az0), np.ascontiguousarray(el0),
         np.cos(css.fov_half_angle_rad), np.ascontiguousarray(css.horizon_normals), falb),
        (bool(sc.controlled), np.asarray(sc.thesis_control, float),
         np.array([sc.control.k_gain, sc.control.p_gain, sc.control.deadband_rad]), axis))
    Q, Wt, St, Sh, Y, NA, Wu, OM, PC, DH, DIR, NIS, ALB, GYR = out
    if not (np.all(np.isfinite(Q)) and np.all(np.isfinite(Wt))):
        from ..errors import ConvergenceError

        raise ConvergenceError("truth integration diverged (non-finite attitude or rate); "
                               "reduce dt_s or check the control gains")
    from .single_point import angle_deg

    err_deg = angle_deg(Sh, St)
    info = {"raan_rad": raan, "u0_rad": u0, "q0": q0, "omega0_rad_s": w0,
            "css_scale_common": true_css.scale_common,
            "css_scale_individual": true_css.scale_individual,
            "css_misalignment_rad": true_css.misalignment_rad,
            "css_noise_sigma": disp.css_noise_sigma,
            "gyro": None if spec is None else spec.name, "r_I_m": r_I, "sun_I_hat": sun_hat,
            "pointing_axis": axis, "albedo": alb_label, "variant": sc.variant,
            "albedo_outputs": ALB, "gyro_substeps": GYR if spec is not None else None}
    is_filter = sc.estimator in ("ekf", "eckf")
    return SimResult(t, Q, Wt, St, Sh, Y, lit, NA, Wu, OM, err_deg, info,
                     PC if is_filter else None, DH if is_filter else None, DIR, NIS)


def simulate_css_cases(scenarios, seed) -> list[SimResult]:
    """Run several scenarios that differ only in estimator, variant or gyro on the same
    dispersed spacecraft (seed).  Uncontrolled scenarios fly the same attitude whatever the
    estimator, so the truth albedo (the costly part) is computed once and reused.  ``seed``:
    an int or a sequence of ints (the entropy of a :class:`numpy.random.SeedSequence`)."""
    out = []
    cache = None
    for sc in scenarios:
        reuse = cache if (not sc.controlled and cache is not None) else None
        # a fresh SeedSequence per scenario: spawning children advances a SeedSequence
        r = simulate_css(sc, np.random.SeedSequence(seed), _albedo_cache=reuse)
        if not sc.controlled and cache is None:
            cache = r.info["albedo_outputs"]
        out.append(r)
    return out
