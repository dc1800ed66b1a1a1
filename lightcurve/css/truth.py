"""Closed-loop truth simulation for the CSS studies (O'Keefe 2015, §2.4).

Spacecraft (§2.4): 100 kg, inertia diag(10.5, 8.0, 7.5) kg m² (total, wheels included),
four reaction wheels with spin-axis inertia J_s = 0.001 kg m² and 30 mN m motor torque
limit, in a 400 km circular polar orbit.  Wheel spin axes G_s: a symmetric pyramid, the
four axes at azimuths 45/135/225/315° and 35.26° (arctan(1/√2)) elevation — §2.4's printed
matrix could not be consulted; this is the common four-wheel pyramid, full rank 3.

Dynamics (Schaub & Junkins §4.5, reaction wheels; SI units, body axes)::

    [I_RW] ω̇ = −ω × ([I] ω + J_s [G_s] Ω) − [G_s] u_s + L_gg,    [I_RW] = [I] − J_s G_s G_sᵀ
    Ω̇ = u_s / J_s − G_sᵀ ω̇,       q̇ = ½ [0, ω] ⊗ q   (q inertial→body, scalar first)
    L_gg = 3 μ/|r|⁵  r_B × ([I] r_B)                  (gravity gradient)

integrated with fixed-step RK4 (motor torques held over a step).  The sensors (CSS with
albedo, gyro), the estimator and the controller run once per step inside one numba loop.

Dispersions (§2.4, as implemented — see :class:`Dispersions`): uniformly random initial
attitude; initial body rates N(0, σ_ω²) per axis; right ascension of the ascending node
uniform; start point uniform among sunlit orbit positions; CSS common scale factor,
individual scale factors and misalignment angles normal about their nominal values; gyro
bias, scale factors and misalignments from the grade (:mod:`lightcurve.css.gyro`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from ..estimation.rng import as_generator
from ..rotations import qmul_nb, qnormalize_nb, qrot_inv_nb, qrot_nb
from ._linalg import inv_nb
from .albedo import (AlbedoMap, albedo_on_sensors_nb, albedo_sun_frame_nb, builtin_albedo_map,
                     earth_rotation_angle, sun_nadir_axis_nb)
from .control import ControlParams, mrp_control_nb
from .gyro import GyroSpec, draw_gyro_errors, gyro_grade, gyro_step_nb
from .sensors import CSSArray
from .single_point import lsmn_nb, wavg_nb
from .sunline_ekf import FilterParams, filter_init_nb, filter_step_albedo_nb, successive_rate_nb

__all__ = ["Spacecraft", "Dispersions", "Scenario", "SimResult", "simulate", "ESTIMATORS",
           "wheel_pyramid", "MU_EARTH", "R_EARTH_M"]

MU_EARTH = 3.986004418e14
R_EARTH_M = 6378137.0
ESTIMATORS = ("ekf", "eckf", "wavg", "lsmn", "wlsmn")


def wheel_pyramid(elevation_rad=np.arctan(1 / np.sqrt(2))) -> np.ndarray:
    """G_s (3×4): unit spin axes at azimuths 45/135/225/315° and the given elevation."""
    az = np.radians([45.0, 135.0, 225.0, 315.0])
    c = np.cos(elevation_rad)
    return np.vstack([c * np.cos(az), c * np.sin(az), np.full(4, np.sin(elevation_rad))])


@dataclass(frozen=True)
class Spacecraft:
    """Mass properties and wheels (§2.4). inertia kg m²; wheel_axes (3,n); J_s kg m²;
    torque limit N m; wheel speed limit rad/s (relative to the body)."""

    mass_kg: float = 100.0
    inertia: tuple = ((10.5, 0.0, 0.0), (0.0, 8.0, 0.0), (0.0, 0.0, 7.5))
    wheel_axes: np.ndarray = field(default_factory=wheel_pyramid)
    wheel_inertia: float = 0.001
    wheel_max_torque: float = 0.030
    wheel_max_speed_rad_s: float = 628.0  # 6000 rpm (our assumption; 0.63 N m s per wheel)


@dataclass(frozen=True)
class Dispersions:
    """Monte Carlo dispersions (§2.4 as implemented; angles in degrees at this edge).

    rate_sigma_deg_s: initial body-rate 1σ per axis; css_scale_common_sigma and
    css_scale_sigma: 1σ of C and C_κ about 1; css_misalignment_sigma_deg: 1σ of each
    misalignment angle; css_noise_sigma: output noise (full scale 1).
    """

    rate_sigma_deg_s: float = 1.0
    css_scale_common_sigma: float = 0.05
    css_scale_sigma: float = 0.02
    css_misalignment_sigma_deg: float = 1.0
    css_noise_sigma: float = 0.017


@dataclass
class Scenario:
    """One CSS simulation case.

    css: nominal sensor set; estimator: one of ESTIMATORS; gyro: grade name, a GyroSpec, or
    None (gyro-less); controlled: run the eq. 3.64 controller; albedo: an AlbedoMap, None for
    the built-in 10° zonal model, or False to switch albedo off (truth); filter_albedo: the
    albedo model of the sun-line filters, same choices (used only when
    ``filter_params.albedo_model`` is on).
    """

    css: CSSArray
    estimator: str = "ekf"
    gyro: object = "tactical"
    controlled: bool = False
    duration_s: float = 1800.0
    dt_s: float = 0.5
    epoch_utc: str = "2015-03-01T00:00:00Z"
    altitude_m: float = 400e3
    inclination_deg: float = 90.0
    spacecraft: Spacecraft = field(default_factory=Spacecraft)
    dispersions: Dispersions = field(default_factory=Dispersions)
    filter_params: FilterParams = field(default_factory=FilterParams)
    control: ControlParams = field(default_factory=ControlParams)
    albedo: object = None
    filter_albedo: object = None
    gravity_gradient: bool = True
    start_sunlit: bool = True

    def __post_init__(self):
        if self.estimator not in ESTIMATORS:
            raise ValueError(f"unknown estimator {self.estimator!r}; allowed: {', '.join(ESTIMATORS)}")
        if not (self.dt_s > 0 and self.duration_s > self.dt_s):
            raise ValueError("need dt_s > 0 and duration_s > dt_s")


@dataclass
class SimResult:
    """Time histories of one run (K samples at t, s).

    q (K,4) true attitude (inertial→body); omega (K,3) true rate rad/s; s_true (K,3) true
    unit Sun direction in body axes; s_hat (K,3) estimate (zeros when none); y (K,N) CSS
    outputs; lit (K,); n_active (K,); omega_used (K,3) rate fed to estimator/controller;
    wheel_speed (K,4) rad/s; error_deg (K,) angle between s_hat and s_true (180 when none);
    p_cov (K,3,3) and d_hat (K,3): the sun-line filter's covariance and scaled Sun vector
    after each update (EKF/ECKF only, zeros before the filter starts; None otherwise).
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


# ---------------------------------------------------------------------------------------
# numba core
# ---------------------------------------------------------------------------------------
@numba.njit(cache=True)
def _deriv(q, w, Om, u, I, IRW_inv, G, Js, Lext):
    H = I @ w + Js * (G @ Om)
    rhs = -np.cross(w, H) - G @ u + Lext
    wd = IRW_inv @ rhs
    Omd = u / Js - G.T @ wd
    wq = np.array([0.0, w[0], w[1], w[2]])
    qd = 0.5 * qmul_nb(wq, q)
    return qd, wd, Omd


@numba.njit(cache=True)
def _rk4(q, w, Om, u, I, IRW_inv, G, Js, Lext, h):
    k1q, k1w, k1o = _deriv(q, w, Om, u, I, IRW_inv, G, Js, Lext)
    k2q, k2w, k2o = _deriv(q + 0.5 * h * k1q, w + 0.5 * h * k1w, Om + 0.5 * h * k1o, u, I,
                           IRW_inv, G, Js, Lext)
    k3q, k3w, k3o = _deriv(q + 0.5 * h * k2q, w + 0.5 * h * k2w, Om + 0.5 * h * k2o, u, I,
                           IRW_inv, G, Js, Lext)
    k4q, k4w, k4o = _deriv(q + h * k3q, w + h * k3w, Om + h * k3o, u, I, IRW_inv, G, Js, Lext)
    qn = q + h / 6.0 * (k1q + 2 * k2q + 2 * k3q + k4q)
    wn = w + h / 6.0 * (k1w + 2 * k2w + 2 * k3w + k4w)
    On = Om + h / 6.0 * (k1o + 2 * k2o + 2 * k3o + k4o)
    return qnormalize_nb(qn), wn, On


@numba.njit(cache=True)
def _r3(theta, v):
    c = np.cos(theta)
    s = np.sin(theta)
    return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])


@numba.njit(cache=True)
def sim_loop_nb(t, r_I, sun_I, lit, theta_E, alb_c, alb_n, alb_ra, falb_c, falb_n, falb_ra,
                n_true, cos_fov, gains, horizon, n_nom, css_noise,
                use_gyro, gM, gbias0, arw, rrw, g_nu, g_nv,
                I, G, Js, umax, om_max, mu_gg,
                q0, w0, Om0,
                est_kind, fprm, controlled, kK, kP, deadband, h_axis):
    """The whole closed loop (see module docstring); est_kind 0 EKF, 1 ECKF, 2 WAVG, 3 LSMN,
    4 WLSMN.  ``alb_*``: the truth albedo grid (empty: no albedo); ``falb_*``: the sun-line
    filters' own albedo model grid (used when ``fprm`` switches the albedo model on; it sees
    the known position and Sun, never the true attitude).
    Returns q, ω, s_true, s_hat, y, n_active, ω_used, Ω (wheel speeds)."""
    K = t.shape[0]
    N = n_true.shape[0]
    nw = G.shape[1]
    IRW = I - Js * (G @ G.T)
    IRW_inv, _ = inv_nb(IRW)
    GGi, _ = inv_nb(G @ G.T)
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
    q = q0.copy()
    w = w0.copy()
    Om = Om0.copy()
    bias = gbias0.copy()
    thr = fprm[2]
    alpha, rmax = fprm[9], fprm[10]
    d = np.zeros(3)
    P = np.eye(3)
    Pxc = np.zeros((3, 3))
    started = False
    d_prev = np.zeros(3)
    om_f = np.zeros(3)
    w_meas_prev = np.zeros(3)
    dark = 0.0
    n_nadir = np.zeros((N, 3))
    h_nadir = np.zeros((N, 3))
    have_alb = alb_c.shape[0] > 0
    f_alb = est_kind <= 1 and fprm[15] > 0.5 and falb_c.shape[0] > 0
    fa_coords = np.zeros((0, 3))
    fa_ratio = np.zeros(0)
    fa_m = 0
    phi_state = np.zeros(7 + int(fprm[17])) if (f_alb and fprm[18] > 0.5) else np.zeros(0)
    e2_I = np.zeros(3)
    for k in range(K):
        Q[k] = q
        Wt[k] = w
        OM[k] = Om
        s_b = qrot_nb(q, sun_I[k])
        St[k] = s_b
        # ---- CSS outputs (eq. 2.21) -------------------------------------------------
        alb = np.zeros(N)
        if have_alb:
            th = theta_E[k]
            rE = _r3(th, r_I[k])
            sE = _r3(th, sun_I[k])
            for j in range(N):
                n_nadir[j] = _r3(th, qrot_inv_nb(q, n_true[j]))
                h_nadir[j] = _r3(th, qrot_inv_nb(q, horizon[j]))
            alb = albedo_on_sensors_nb(alb_c, alb_n, alb_ra, rE, sE, n_nadir, cos_fov, h_nadir)
        for j in range(N):
            c = n_true[j, 0] * s_b[0] + n_true[j, 1] * s_b[1] + n_true[j, 2] * s_b[2]
            r = 0.0
            if lit[k] > 0.0 and c >= cos_fov[j] and c > 0.0:
                if (horizon[j, 0] * s_b[0] + horizon[j, 1] * s_b[1] + horizon[j, 2] * s_b[2]) >= 0.0:
                    r = lit[k] * c
            v = gains[j] * (r + alb[j]) + css_noise[k, j]
            Y[k, j] = v if v > 0.0 else 0.0
        # ---- gyro ---------------------------------------------------------------------
        w_meas = np.zeros(3)
        if use_gyro:
            dtg = t[1] - t[0] if k == 0 else t[k] - t[k - 1]
            w_meas = gyro_step_nb(w, bias, gM, arw, rrw, dtg, g_nu[k], g_nv[k])
        # ---- estimator ----------------------------------------------------------------
        s_est = np.zeros(3)
        valid = False
        if est_kind <= 1:
            if not started:
                d, P, Pxc, ok = filter_init_nb(Y[k], n_nom, fprm)
                if ok:
                    started = True
                    d_prev[:] = d
            else:
                dt = t[k] - t[k - 1]
                om = w_meas_prev if use_gyro else om_f
                lit_now = False
                for j in range(N):
                    if Y[k, j] > thr:
                        lit_now = True
                reset = lit_now and fprm[14] > 0 and dark >= fprm[14]
                if f_alb:
                    # the filter's albedo model from the known position and Sun (Earth-fixed)
                    th = theta_E[k]
                    fa_coords, fa_ratio, fa_m = albedo_sun_frame_nb(
                        falb_c, falb_n, falb_ra, _r3(th, r_I[k]), _r3(th, sun_I[k]))
                    e2_I = sun_nadir_axis_nb(r_I[k], sun_I[k])
                m, nis, infl = filter_step_albedo_nb(est_kind, d, P, Pxc, om, dt, Y[k], n_nom,
                                                     fprm, reset, fa_coords, fa_ratio, fa_m,
                                                     cos_fov, horizon, phi_state, e2_I,
                                                     sun_I[k])
                dark = 0.0 if lit_now else dark + dt
                NA[k] = m
                Wu[k] = om
                if not use_gyro:
                    om_f = successive_rate_nb(d, d_prev, dt, om_f, alpha, rmax)
                d_prev[:] = d
            if started:
                nd = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
                if nd > 0:
                    s_est = d / nd
                    valid = True
        else:
            if est_kind == 2:
                s_est = wavg_nb(Y[k], n_nom, thr)
            else:
                s_est = lsmn_nb(Y[k], n_nom, thr, est_kind == 4)
            valid = (s_est[0] ** 2 + s_est[1] ** 2 + s_est[2] ** 2) > 0
            cnt = 0
            for j in range(N):
                if Y[k, j] > thr:
                    cnt += 1
            NA[k] = cnt
            if not use_gyro and k > 0:
                dt = t[k] - t[k - 1]
                if valid and (d_prev[0] ** 2 + d_prev[1] ** 2 + d_prev[2] ** 2) > 0:
                    om_f = successive_rate_nb(s_est, d_prev, dt, om_f, alpha, rmax)
                Wu[k] = om_f
            if valid:
                d_prev[:] = s_est
        Sh[k] = s_est
        if est_kind <= 1 and started:
            PC[k] = P
            DH[k] = d
        if use_gyro:
            Wu[k] = w_meas
        w_meas_prev[:] = w_meas
        # ---- control (eq. 3.64) -------------------------------------------------------
        u = np.zeros(nw)
        if controlled:
            w_ctrl = w_meas if use_gyro else om_f
            h_w = Js * (G.T @ w_ctrl + Om)
            u = mrp_control_nb(s_est, valid, w_ctrl, I, G, h_w, G_pinv, kK, kP, deadband,
                               umax, h_axis, use_gyro)
            for i in range(nw):
                # wheel speed limit: the motor cannot spin a saturated wheel further up
                if (Om[i] >= om_max and u[i] > 0.0) or (Om[i] <= -om_max and u[i] < 0.0):
                    u[i] = 0.0
        # ---- propagate truth ------------------------------------------------------------
        if k < K - 1:
            h = t[k + 1] - t[k]
            Lext = np.zeros(3)
            if mu_gg > 0.0:
                rb = qrot_nb(q, r_I[k])
                rn = np.sqrt(rb[0] ** 2 + rb[1] ** 2 + rb[2] ** 2)
                Lext = 3.0 * mu_gg / rn ** 5 * np.cross(rb, I @ rb)
            q, w, Om = _rk4(q, w, Om, u, I, IRW_inv, G, Js, Lext, h)
    return Q, Wt, St, Sh, Y, NA, Wu, OM, PC, DH


# ---------------------------------------------------------------------------------------
# object layer
# ---------------------------------------------------------------------------------------
def _random_quat(g):
    q = g.normal(size=4)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def _orbit(alt, inc, raan, u0, t):
    a = R_EARTH_M + alt
    n = np.sqrt(MU_EARTH / a ** 3)
    u = u0 + n * t
    cO, sO, ci, si = np.cos(raan), np.sin(raan), np.cos(inc), np.sin(inc)
    return a * np.column_stack([cO * np.cos(u) - sO * np.sin(u) * ci,
                                sO * np.cos(u) + cO * np.sin(u) * ci,
                                np.sin(u) * si])


_ALBEDO_CACHE: dict = {}


def _albedo_grid(spec):
    if spec is False:
        z = np.zeros((0, 3))
        return z, z.copy(), np.zeros(0)
    amap = builtin_albedo_map(10.0) if spec is None else spec
    key = id(amap) if spec is not None else "builtin10"
    if key not in _ALBEDO_CACHE:
        if not isinstance(amap, AlbedoMap):
            raise ValueError("albedo must be an AlbedoMap, None (built-in) or False (off)")
        g = amap.grid()
        _ALBEDO_CACHE[key] = (g.centers_m, g.normals, g.rho_area_m2)
    return _ALBEDO_CACHE[key]


def simulate(sc: Scenario, rng) -> SimResult:
    """Draw the §2.4 dispersions and run one closed-loop (or open-loop tumbling) case.

    ``rng`` is a numpy Generator or seed; a given seed reproduces the run bit for bit.
    """
    from ..geometry.eclipse import lit_fraction
    from ..geometry.time import sun_position_gcrs

    g = as_generator(rng)
    disp = sc.dispersions
    t = np.arange(0.0, sc.duration_s + 0.5 * sc.dt_s, sc.dt_s)
    K = t.size
    # orbit: RAAN uniform, start point uniform among sunlit positions
    sun0 = sun_position_gcrs(sc.epoch_utc, np.array([0.0]))[0]
    inc = np.radians(sc.inclination_deg)
    raan = g.uniform(0, 2 * np.pi)
    for _ in range(1000):
        u0 = g.uniform(0, 2 * np.pi)
        r0 = _orbit(sc.altitude_m, inc, raan, u0, np.array([0.0]))
        if not sc.start_sunlit or lit_fraction(r0, sun0[None, :])[0] > 0.999:
            break
    r_I = _orbit(sc.altitude_m, inc, raan, u0, t)
    # the Sun moves ~0.04 deg/h: sample it every 60 s and interpolate
    tc = np.arange(0.0, t[-1] + 60.0, 60.0)
    sun_c = sun_position_gcrs(sc.epoch_utc, tc)
    sun_m = np.column_stack([np.interp(t, tc, sun_c[:, i]) for i in range(3)])
    lit = lit_fraction(r_I, sun_m)
    sun_hat = sun_m / np.linalg.norm(sun_m, axis=1, keepdims=True)
    theta = earth_rotation_angle(sc.epoch_utc, t)
    alb_c, alb_n, alb_ra = _albedo_grid(sc.albedo)
    falb_c, falb_n, falb_ra = _albedo_grid(sc.filter_albedo)
    # CSS dispersions
    css = sc.css
    N = css.n_sensors
    true_css = css.with_errors(
        scale_common=max(0.05, 1.0 + g.normal(0, disp.css_scale_common_sigma)),
        scale_individual=np.maximum(0.05, 1.0 + g.normal(0, disp.css_scale_sigma, N)),
        misalignment_rad=np.radians(g.normal(0, disp.css_misalignment_sigma_deg, (N, 2))),
        noise_sigma=disp.css_noise_sigma)
    n_true, cos_fov, gains, horizon = true_css.kernel_args()
    css_noise = g.normal(0.0, disp.css_noise_sigma, (K, N))
    # gyro
    spec = None if sc.gyro is None else (sc.gyro if isinstance(sc.gyro, GyroSpec) else gyro_grade(sc.gyro))
    if spec is not None:
        err = draw_gyro_errors(spec, g, detailed=True)
        gM, gb0, arw, rrw = err.M, err.bias0, spec.arw, spec.rrw
        g_nu = g.standard_normal((K, 3))
        g_nv = g.standard_normal((K, 3))
    else:
        gM, gb0, arw, rrw = np.eye(3), np.zeros(3), 0.0, 0.0
        g_nu = np.zeros((K, 3))
        g_nv = np.zeros((K, 3))
    fparams = sc.filter_params.for_css(css)
    if spec is not None:
        fparams = fparams.for_gyro(spec)
    q0 = _random_quat(g)
    w0 = np.radians(g.normal(0.0, disp.rate_sigma_deg_s, 3))
    scf = sc.spacecraft
    I = np.asarray(scf.inertia, dtype=float)
    G = np.ascontiguousarray(scf.wheel_axes, dtype=float)
    Om0 = np.zeros(G.shape[1])
    axis = np.asarray(sc.control.axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    out = sim_loop_nb(
        t, r_I, sun_hat, lit, theta, alb_c, alb_n, alb_ra, falb_c, falb_n, falb_ra,
        n_true, cos_fov, gains, horizon, css.normals.copy(), css_noise,
        spec is not None, gM, gb0, arw, rrw, g_nu, g_nv,
        I, G, float(scf.wheel_inertia), float(scf.wheel_max_torque),
        float(scf.wheel_max_speed_rad_s), MU_EARTH if sc.gravity_gradient else 0.0,
        q0, w0, Om0,
        ESTIMATORS.index(sc.estimator), fparams.as_array(), bool(sc.controlled),
        float(sc.control.k_gain), float(sc.control.p_gain), float(sc.control.deadband_rad), axis)
    Q, Wt, St, Sh, Y, NA, Wu, OM, PC, DH = out
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
            "pointing_axis": axis}
    is_filter = sc.estimator in ("ekf", "eckf")
    return SimResult(t, Q, Wt, St, Sh, Y, lit, NA, Wu, OM, err_deg, info,
                     PC if is_filter else None, DH if is_filter else None)
