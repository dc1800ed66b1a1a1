"""Sequential sun-line estimators (O'Keefe 2015, §3.2): EKF and extended consider KF.

State: the *scaled* Sun vector ``d`` in body axes (eq. 3.27).  Its direction is the Sun
direction; its norm absorbs the unknown common scale factor C of the sensors (and part of
the albedo), so no calibration is needed.

Dynamics (eq. 3.29): the Sun is inertially fixed over a pass, so in body axes
``ḋ = −ω × d`` with ω the body rate (rad/s) from the gyro — or, without a gyro, from
successive estimates (eq. 3.67, :func:`successive_rate_nb`).  Over a step Δt with constant ω
the exact solution is ``d⁺ = Φ d``, ``Φ = exp(−[ω×]Δt)`` (a rotation), used for both the
state and the covariance: ``P⁻ = Φ P Φᵀ + q Δt I`` with process noise spectral density ``q``
(1/s).

Measurement (eq. 3.29-3.31): for every *active* sensor (output above ``threshold``)
``y_κ = n̂_κ·d + v_κ``, so ``H`` is the stack of active nominal normals and ``R = σ² I``.
Inactive sensors are not used (their zero output carries only inequality information).

Robustness logic (our implementation of §3.2.1.2 and §3.2.3, whose printed form we could
not consult; the behaviour follows the description in the issue):

* strong-measurement inflation — when the normalised innovation squared
  ``NIS = νᵀS⁻¹ν`` exceeds ``gate`` × (number of measurements), the prior is judged
  over-confident for this (strong, many-sensor) measurement and ``P⁻`` is inflated by
  ``min(NIS/(gate m), inflate_max)`` before the update, so one step can pull the state;
* a covariance floor ``p_floor`` (added to the diagonal when the smallest variance drops
  below it) keeps the filter responsive after long spells of many active sensors;
* Joseph-form update and symmetrisation every step.

Earth-albedo model in the filter (our addition; ``FilterParams.albedo_model``, on by default,
used where the spacecraft position and the Sun are known — the truth simulation — and off
for recordings without positions).  Unmodelled albedo (up to ~0.1 of full scale on the
*active* sensors at 400 km) was the dominant error of the filter (error budget in
``tests/css/test_css_albedo_filter.py``).  The filter knows its position and the Sun, hence
the sunlit Earth cells in an attitude-free Sun–nadir frame
(:func:`~lightcurve.css.albedo.albedo_sun_frame_nb`, its own albedo model, default the
built-in zonal one), and the Sun direction in body axes (its state), but not the rotation φ
of the body about the Sun line, which decides where the Earth is in body axes.  A grid
(point-mass) filter over φ (``albedo_n_phi`` hypotheses, each a constant once the body
reference is propagated with the gyro rate and the known orbital rotation of the Sun–nadir
axis) is updated by the readings of the "dark" sensors — those that cannot see the Sun, whose
output is albedo only.  Its posterior gives each active sensor's expected albedo ā and its
variance; the update then uses ``h = n̂·d + |d| ā`` (the common scale multiplies the albedo
too), ``H = n̂ + ā d/|d|`` and ``R = σ² + |d|² (var + (albedo_rel_sigma ā)²)``.  With
``albedo_phi = False`` φ is instead averaged with a uniform prior (much weaker: the mean over
φ removes only a third of the albedo error).

Extended consider Kalman filter (§3.2.2, continuous-discrete): the rate error ``c`` (gyro
bias, or the error of the successive-estimate rate without a gyro) is a *consider*
parameter with fixed covariance ``P_cc = σ_c² I``: it is not estimated, but its effect on
``d`` is carried in ``P_xx`` and the cross covariance ``P_xc``.  With ``ḋ = −(ω_m − c)×d``,
``F = −[ω×]`` and ``F_c = ∂ḋ/∂c = −[d×]``, between measurements (integrated with
``n_sub`` RK4 sub-steps)::

    Ṗ_xx = F P_xx + P_xx Fᵀ + F_c P_cx + P_xc F_cᵀ + q I,   Ṗ_xc = F P_xc + F_c P_cc

and the Schmidt consider update uses ``K = P_xx Hᵀ S⁻¹``, ``S = H P_xx Hᵀ + R``,
``P_xx ← (I−KH)P_xx(I−KH)ᵀ + K R Kᵀ``, ``P_xc ← (I−KH)P_xc``.

Gyro-less rate (eq. 3.67): from two successive unit estimates, the observable rate
component perpendicular to the Sun line is ``ω = (θ/Δt) (d̂_k × d̂_{k−1})/|d̂_k × d̂_{k−1}|``,
``θ = ∠(d̂_k, d̂_{k−1})``; it is bounded by ``rate_max`` and low-pass filtered
``ω_f ← α ω_f + (1−α) ω``.

Kernels are numba-compiled; :func:`run_filter_nb` runs a whole recorded trajectory in one
compiled loop (see ``benchmarks/css.py`` for the per-step cost).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numba
import numpy as np

from ..core.kalman import consider_update_nb, symmetrize_nb
from ..core.rotations import q2dcm_nb, qrot_inv_nb, rotvec2q_nb, skew_nb
from .albedo import albedo_phi_nb, expected_albedo_nb
from .single_point import lsmn_nb

__all__ = ["FilterParams", "FILTER_KINDS", "run_filter", "run_filter_nb", "ekf_propagate_nb",
           "ekf_update_nb", "ekf_update_albedo_nb", "albedo_measurement_nb",
           "filter_step_albedo_nb", "phi_state_size", "eckf_propagate_nb", "eckf_update_nb",
           "successive_rate_nb", "rate_from_estimates_nb", "rotation_step_nb",
           "gyroless_params", "default_filter_params"]

FILTER_KINDS = ("ekf", "eckf")


HOLD_DRIFT_DEG = 15.0
"""Gyro attitude drift over an eclipse (deg, 1σ) above which :meth:`FilterParams.for_gyro`
suspends control in the dark (the error level of O'Keefe's time-above-15° metric)."""


@dataclass(frozen=True)
class FilterParams:
    """Tuning of the sun-line filters (dimensionless outputs, SI time).

    Defaults were tuned on the §2.4 tumbling Monte Carlo with the filter
    *without* an albedo model: Earth albedo (up to ~0.27 of full scale on an Earth-facing
    sensor at 400 km) treated as measurement noise — a high activity threshold (0.5)
    keeps albedo-dominated sensors out and σ = 0.3 lets the tumbling average the remaining
    albedo bias.  They were kept when the albedo model (``albedo_model``, on by default
    where position and Sun are known; see the module docstring) was added.  The optional scale
    pseudo-measurement and dark-sensor updates are off by default (both made the
    albedo/misalignment case worse in that study).  The field-of-view reading (``fov_model``)
    is on by default: without it an albedo-lit sensor whose scale error lifts it over the
    activity threshold is read as direct Sun (docs/measurements.md has the fig. 3.9–3.13
    comparison with it off).

    sigma_meas: CSS output noise σ used in R; q_proc: process noise density (1/s) on d;
    threshold: activity threshold on the outputs; p0: initial variance of d;
    gate: NIS gate per measurement for strong-measurement inflation; inflate_max: largest
    inflation factor; p_floor: smallest allowed variance of d; consider_sigma: σ_c of the
    considered rate error (rad/s); n_sub: RK4 sub-steps of the ECKF covariance;
    rate_alpha: low-pass coefficient of the gyro-less rate; rate_max: bound on it (rad/s);
    norm_sigma: σ of the scale pseudo-measurement |d| = 1 (0 switches it off);
    use_dark_sensors: also update with sensors whose predicted output exceeds the threshold
    while their measured output does not and the predicted Sun is inside the FOV
    ``fov_half_angle_deg`` (the nominal FOV of the sensors; use :meth:`for_css`);
    reset_after_s: after this long without any active sensor (eclipse), the covariance is
    reset to ``p0`` at the first new measurement (0 disables);
    albedo_model: model the expected Earth albedo in the measurement (see
    :func:`expected_albedo_nb` and the module docstring) — needs the spacecraft position and
    the Sun (the truth simulation supplies them; recordings without positions run with it
    off); albedo_rel_sigma: 1σ relative error of the filter's albedo model (fraction of the
    predicted albedo, added to R); albedo_n_phi: number of rotation angles φ about the Sun
    line on the grid; albedo_phi: estimate φ with a grid (point-mass) filter from the
    albedo-only readings of the sensors that cannot see the Sun (otherwise φ is averaged
    with a uniform prior); albedo_sigma: noise σ of those readings (full scale 1);
    albedo_phi_mix: fraction of uniform weight mixed in per step (lets the φ estimate move
    and recover); albedo_dark_margin: a sensor is "dark" when n̂·ŝ < cos ψ − margin;
    albedo_phi_temper: exponent (≤ 1) on the φ likelihood (1: none);
    fov_model: read the sensors' field of view from the outputs: an active sensor reading
    below ``|d| cos ψ`` (the smallest direct reading, the Sun at its FOV edge) is modelled as
    albedo alone (see :func:`_update_core`; used by :func:`filter_step_albedo_nb`);
    hold_in_dark: with a gyro, suspend all control effort while no sensor is active once the
    filter has started (it still propagates with the gyro; before the first Sun the gyro
    still damps the initial rates), as §3.3.3 does without a gyro — O'Keefe
    (§3.3.4, under fig. 3.20's discussion of the low-grade gyro) suggests it: with a gyro the
    control "spends the entire 36 min in the shadow of the Earth driving the spacecraft
    away from the true sun-direction" and "the 99th percentile bounds for the low
    performance gyro case can be reduced by adopting a similar control approach".
    None (default): decided by :meth:`for_gyro` from the gyro's drift over an eclipse
    (off where no gyro model is known); True/False: forced.
    """

    sigma_meas: float = 0.3
    q_proc: float = 1e-7
    threshold: float = 0.5
    p0: float = 0.25
    gate: float = 9.0
    inflate_max: float = 100.0
    p_floor: float = 1e-5
    consider_sigma: float = 1e-4
    n_sub: int = 2
    rate_alpha: float = 0.8
    rate_max: float = 0.1
    norm_sigma: float = 0.0
    use_dark_sensors: bool = False
    fov_half_angle_deg: float = 60.0
    reset_after_s: float = 60.0
    albedo_model: bool = True
    albedo_rel_sigma: float = 0.3
    albedo_n_phi: int = 36
    albedo_phi: bool = True
    albedo_sigma: float = 0.02
    albedo_phi_mix: float = 1e-3
    albedo_dark_margin: float = 0.1
    albedo_phi_temper: float = 1.0
    fov_model: bool = True
    hold_in_dark: bool | None = None

    def as_array(self) -> np.ndarray:
        """Parameters packed for the numba kernels (order of the fields; the FOV as its
        cosine; an undecided ``hold_in_dark`` as 0)."""
        a = np.array([0.0 if v is None else float(v) for v in asdict(self).values()])
        a[13] = np.cos(np.radians(self.fov_half_angle_deg))
        return a

    def for_gyro(self, spec) -> "FilterParams":
        """A copy whose process noise and considered rate error cover the rate errors of gyro
        ``spec`` (:class:`~lightcurve.css.gyro.GyroSpec`): q ≥ σ_v² + σ_B² × 100 s and
        σ_c ≥ σ_B, where σ_B² = σ_b² + σ_u² × 1000 s is the bias spread after the drift
        time of the Table 2.3 grades (O'Keefe 2015 §2.4, "over 1000 s";
        :data:`~lightcurve.css.okeefe2015.GYRO_DRIFT_TAU_S`).  The angle random walk σ_v
        enters d as white noise; the bias, nearly constant over ~100 s, as a random walk
        over that window.

        ``hold_in_dark`` left at None is set from the gyro's 1σ attitude drift over one
        eclipse, ``√(σ_v² T + σ_B² T²)`` with T the 36 min of O'Keefe §3.3.4: control
        stops in the dark when that drift exceeds :data:`HOLD_DRIFT_DEG` (15°, the error
        level of the thesis's time-above-15° metric, figs. 3.12-3.20), i.e. when steering
        through the shadow on the gyro cannot keep the Sun within it."""
        from dataclasses import replace

        from .okeefe2015 import ECLIPSE_S, GYRO_DRIFT_TAU_S

        sb2 = spec.bias_sigma ** 2 + spec.rrw ** 2 * GYRO_DRIFT_TAU_S
        hold = self.hold_in_dark
        if hold is None:
            drift = np.sqrt(spec.arw ** 2 * ECLIPSE_S + sb2 * ECLIPSE_S ** 2)
            hold = bool(drift > np.radians(HOLD_DRIFT_DEG))
        return replace(self, q_proc=max(self.q_proc, spec.arw ** 2 + sb2 * 100.0),
                       consider_sigma=max(self.consider_sigma, float(np.sqrt(sb2))),
                       hold_in_dark=hold)

    def for_css(self, css) -> "FilterParams":
        """A copy with the FOV of a :class:`~lightcurve.css.sensors.CSSArray` (largest one)."""
        from dataclasses import replace

        return replace(self, fov_half_angle_deg=float(np.degrees(np.max(css.fov_half_angle_rad))))


# ---------------------------------------------------------------------------------------
# small kernels
# ---------------------------------------------------------------------------------------
@numba.njit(cache=True)
def rotation_step_nb(omega, dt):
    """Φ = exp(−[ω×]Δt) (3×3), the exact transition of the sun-line dynamics ``ḋ = −ω × d``
    (O'Keefe eq. 3.29 without noise) for a rate ω (rad/s, body) held over Δt (s): the attitude
    matrix of the rotation vector ω Δt (Bernard eq. 3.13) through
    :func:`lightcurve.core.rotations.rotvec2q_nb` and
    :func:`~lightcurve.core.rotations.q2dcm_nb`."""
    return q2dcm_nb(rotvec2q_nb(omega * dt))


@numba.njit(cache=True)
def _floor(P, p_floor):
    m = P[0, 0]
    for i in range(1, 3):
        if P[i, i] < m:
            m = P[i, i]
    if m < p_floor:
        for i in range(3):
            P[i, i] += p_floor - m


@numba.njit(cache=True)
def ekf_propagate_nb(d, P, omega, dt, q_proc):
    """EKF time update in place: d ← Φ d, P ← Φ P Φᵀ + q Δt I."""
    Phi = rotation_step_nb(omega, dt)
    dn = Phi @ d
    Pn = Phi @ P @ Phi.T
    for i in range(3):
        d[i] = dn[i]
        for j in range(3):
            P[i, j] = Pn[i, j]
        P[i, i] += q_proc * dt


@numba.njit(cache=True)
def _active(y, threshold, d, normals, use_predicted, cos_fov):
    """Sensors used in the update: measured output above the threshold, or (with
    ``use_predicted``) predicted output n̂·d above the threshold although the sensor reads
    less while the predicted Sun is inside its FOV (cosine ``cos_fov``) — the "the Sun is
    not where you think" information of a dark sensor."""
    idx = np.empty(y.shape[0], dtype=np.int64)
    nd = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    m = 0
    for k in range(y.shape[0]):
        on = y[k] > threshold
        if not on and use_predicted:
            c = normals[k, 0] * d[0] + normals[k, 1] * d[1] + normals[k, 2] * d[2]
            on = c > threshold and c >= cos_fov * nd
        if on:
            idx[m] = k
            m += 1
    return idx[:m]


@numba.njit(cache=True)
def albedo_measurement_nb(d, normal, a):
    """Predicted output and Jacobian row of one active sensor with expected albedo ``a``:
    ``h = n̂·d + |d| a``, ``∂h/∂d = n̂ + a d/|d|`` (a held fixed).  Returns (h, H (3,))."""
    nd = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    h = normal[0] * d[0] + normal[1] * d[1] + normal[2] * d[2] + nd * a
    H = np.empty(3)
    for j in range(3):
        H[j] = normal[j] + a * d[j] / nd
    return h, H


@numba.njit(cache=True)
def ekf_update_albedo_nb(d, P, y, normals, sigma, threshold, gate, inflate_max, p_floor,
                         alb_mean, alb_var, alb_rel):
    """:func:`ekf_update_nb` with the expected-albedo measurement (see
    :func:`albedo_measurement_nb`; ``alb_mean``/``alb_var`` (N,) per sensor,
    ``R_κ = σ² + |d|² (var_κ + (alb_rel ā_κ)²)``).  Returns (m, NIS, inflation)."""
    dummy = np.zeros((3, 3))
    return _update_core(d, P, dummy, y, normals, sigma, threshold, gate, inflate_max, p_floor,
                        False, 0.0, False, 0.0, alb_mean, alb_var, alb_rel,
                        np.zeros(0))


@numba.njit(cache=True)
def _update_core(d, P, Pxc, y, normals, sigma, threshold, gate, inflate_max, p_floor, consider,
                 norm_sigma, use_predicted, cos_fov, alb_mean, alb_var, alb_rel, view_cos):
    """Shared EKF / consider update; returns (m, NIS, inflation).

    ``alb_mean``/``alb_var`` (N,) are the expected albedo on each sensor and its variance
    (:func:`~lightcurve.css.albedo.expected_albedo_nb`, units of the solar irradiance) or
    empty arrays (no albedo model).  With them the measurement of sensor κ is
    ``h_κ(d) = n̂_κ·d + |d| ā_κ`` (the common scale |d| multiplies the albedo exactly as it
    multiplies the direct term), ``H_κ = n̂_κ + ā_κ d/|d|`` (ā's slow dependence on the
    direction is neglected) and ``R_κ = σ² + |d|² (var_κ + (alb_rel ā_κ)²)``.

    ``view_cos`` (N,) (the sensors' nominal FOV cosines; empty: off) reads the sensors' field of
    view from the outputs, as eq. 2.21 bounds them: a directly lit sensor reads at least
    ``|d| cos ψ_κ`` (the Sun at its FOV edge; |d| the common scale), so an active sensor that
    reads less sees no direct Sun and measures albedo alone (``h = |d| ā_κ``, ``H = ā_κ d/|d|``;
    without the albedo model it is not used); the brightest active sensor is always read as
    direct. Without it, a sensor made active by albedo alone
    (Earth in view, Sun outside the FOV: up to ≈ 0.27 of full scale at 400 km, times a common
    scale factor above 1) is read as a direct Sun measurement.
    """
    idx = _active(y, threshold, d, normals, use_predicted, cos_fov)
    nd = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    use_alb = alb_mean.shape[0] == normals.shape[0] and nd > 1e-9
    direct = np.ones(idx.shape[0], dtype=np.bool_)
    if view_cos.shape[0] == normals.shape[0] and nd > 1e-9 and idx.shape[0] > 0:
        # the brightest active sensor stays a direct measurement: were every reading below
        # the floor, the floor (|d| too large) would be the error, and explaining the
        # readings by albedo would only scale |d| up further
        kb = idx[0]
        for i in range(idx.shape[0]):
            if y[idx[i]] > y[kb]:
                kb = idx[i]
        keep = 0
        for i in range(idx.shape[0]):
            k = idx[i]
            inside = y[k] >= view_cos[k] * nd or k == kb
            if inside or use_alb:
                idx[keep] = k
                direct[keep] = inside
                keep += 1
        idx = idx[:keep]
        direct = direct[:keep]
    m_css = idx.shape[0]
    if m_css == 0:
        return 0, 0.0, 1.0
    use_norm = norm_sigma > 0.0 and nd > 1e-9
    m = m_css + (1 if use_norm else 0)
    H = np.empty((m, 3))
    nu = np.empty(m)
    rv = np.empty(m)
    r = sigma * sigma
    for i in range(m_css):
        k = idx[i]
        H[i, 0] = normals[k, 0]
        H[i, 1] = normals[k, 1]
        H[i, 2] = normals[k, 2]
        nu[i] = y[k] - (H[i, 0] * d[0] + H[i, 1] * d[1] + H[i, 2] * d[2])
        rv[i] = r
        if use_alb:
            a = alb_mean[k]
            h, Hr = albedo_measurement_nb(d, normals[k], a)
            if not direct[i]:      # reads below the direct-light floor: albedo alone
                h -= normals[k, 0] * d[0] + normals[k, 1] * d[1] + normals[k, 2] * d[2]
                for j in range(3):
                    Hr[j] -= normals[k, j]
            nu[i] = y[k] - h
            for j in range(3):
                H[i, j] = Hr[j]
            rv[i] += nd * nd * (alb_var[k] + (alb_rel * a) ** 2)
    if use_norm:
        # scale pseudo-measurement |d| = 1 (outputs are normalised to full scale 1)
        H[m_css, 0] = d[0] / nd
        H[m_css, 1] = d[1] / nd
        H[m_css, 2] = d[2] / nd
        nu[m_css] = 1.0 - nd
        rv[m_css] = norm_sigma * norm_sigma
    R = np.zeros((m, m))
    for i in range(m):
        R[i, i] = rv[i]
    # Kalman update through the core, Joseph form; the ECKF's rate error c is a Schmidt
    # consider parameter that does not enter the measurement (J = 0, so its covariance P_cc
    # does not enter the update either: P_xc ← (I − KH) P_xc)
    nc = Pxc.shape[1] if consider else 0
    Bc = np.zeros((nc, nc))
    Jc = np.zeros((m, nc))
    Pc = Pxc if consider else np.zeros((3, 0))
    dn, Pn, Xn, nis, ok = consider_update_nb(d, P, Pc, Bc, nu, H, Jc, R, True)
    if not ok:
        return 0, 0.0, 1.0
    infl = 1.0
    if nis > gate * m:
        # strong-measurement inflation of the prior, then the update again
        infl = min(nis / (gate * m), inflate_max)
        dn, Pn, Xn, _, ok = consider_update_nb(d, P * infl, Pc * np.sqrt(infl), Bc, nu, H, Jc,
                                               R, True)
        if not ok:
            return 0, 0.0, 1.0
    for i in range(3):
        d[i] = dn[i]
        for j in range(3):
            P[i, j] = Pn[i, j]
    if consider:
        for i in range(3):
            for j in range(nc):
                Pxc[i, j] = Xn[i, j]
    _floor(P, p_floor)
    return m_css, nis, infl


@numba.njit(cache=True)
def ekf_update_nb(d, P, y, normals, sigma, threshold, gate, inflate_max, p_floor, norm_sigma,
                  use_predicted, cos_fov):
    """EKF measurement update in place (Joseph form, strong-measurement inflation, floor,
    optional scale pseudo-measurement).  Returns (number of sensors used, NIS before
    inflation, inflation factor)."""
    dummy = np.zeros((3, 3))
    return _update_core(d, P, dummy, y, normals, sigma, threshold, gate, inflate_max, p_floor,
                        False, norm_sigma, use_predicted, cos_fov, np.zeros(0), np.zeros(0), 0.0,
                        np.zeros(0))


@numba.njit(cache=True)
def _eckf_rhs(Pxx, Pxc, F, Fc, pcc, q):
    A = F @ Pxx
    B = Fc @ Pxc.T
    dP = A + A.T + B + B.T
    for i in range(3):
        dP[i, i] += q
    dX = F @ Pxc + pcc * Fc
    return dP, dX


@numba.njit(cache=True)
def eckf_propagate_nb(d, Pxx, Pxc, omega, dt, q_proc, pcc, n_sub):
    """Continuous-discrete consider time update in place (RK4 on the covariance ODEs with
    ``n_sub`` sub-steps; d rotated exactly).  ``pcc`` is the scalar σ_c² of P_cc = σ_c² I."""
    F = -skew_nb(omega)
    h = dt / n_sub
    Phi_h = rotation_step_nb(omega, h)
    for _ in range(n_sub):
        # F_c = -[d x], evaluated at the start of the sub-step (d changes slowly)
        Fc = -skew_nb(d)
        k1p, k1x = _eckf_rhs(Pxx, Pxc, F, Fc, pcc, q_proc)
        k2p, k2x = _eckf_rhs(Pxx + 0.5 * h * k1p, Pxc + 0.5 * h * k1x, F, Fc, pcc, q_proc)
        k3p, k3x = _eckf_rhs(Pxx + 0.5 * h * k2p, Pxc + 0.5 * h * k2x, F, Fc, pcc, q_proc)
        k4p, k4x = _eckf_rhs(Pxx + h * k3p, Pxc + h * k3x, F, Fc, pcc, q_proc)
        Pn = Pxx + h / 6.0 * (k1p + 2 * k2p + 2 * k3p + k4p)
        Xn = Pxc + h / 6.0 * (k1x + 2 * k2x + 2 * k3x + k4x)
        dn = Phi_h @ d
        for i in range(3):
            d[i] = dn[i]
            for j in range(3):
                Pxx[i, j] = Pn[i, j]
                Pxc[i, j] = Xn[i, j]
    symmetrize_nb(Pxx)


@numba.njit(cache=True)
def eckf_update_nb(d, Pxx, Pxc, y, normals, sigma, threshold, gate, inflate_max, p_floor,
                   norm_sigma, use_predicted, cos_fov):
    """Schmidt consider update in place; returns (m, NIS, inflation)."""
    return _update_core(d, Pxx, Pxc, y, normals, sigma, threshold, gate, inflate_max, p_floor,
                        True, norm_sigma, use_predicted, cos_fov, np.zeros(0), np.zeros(0), 0.0,
                        np.zeros(0))


@numba.njit(cache=True)
def rate_from_estimates_nb(a, b, dt, rate_max, per_axis):
    """O'Keefe (2015) eq. 3.67, the gyro-less rate from two successive Sun estimates:
    ω̄ = (d̂_k × d̂_{k−1})/|d̂_k × d̂_{k−1}| · arccos(d̂_k·d̂_{k−1})/Δt (rad/s, body axes; the
    angle via atan2 for accuracy at small steps).  ``a`` = d_k, ``b`` = d_{k−1} (any length,
    not both zero), ``dt`` s.  Bounded by ``rate_max`` rad/s per axis (``per_axis``, the
    §3.3.3 limiter) or in norm.  Only the part of ω across the Sun line is observable; zeros
    when either estimate is zero or the two are parallel."""
    w = np.zeros(3)
    na = np.sqrt(a[0] ** 2 + a[1] ** 2 + a[2] ** 2)
    nb = np.sqrt(b[0] ** 2 + b[1] ** 2 + b[2] ** 2)
    if na == 0.0 or nb == 0.0 or dt <= 0.0:
        return w
    ua = a / na
    ub = b / nb
    cx = ua[1] * ub[2] - ua[2] * ub[1]
    cy = ua[2] * ub[0] - ua[0] * ub[2]
    cz = ua[0] * ub[1] - ua[1] * ub[0]
    sn = np.sqrt(cx * cx + cy * cy + cz * cz)
    if sn < 1e-15:
        return w
    ang = np.arctan2(sn, ua[0] * ub[0] + ua[1] * ub[1] + ua[2] * ub[2])
    w[0] = cx / sn * ang / dt
    w[1] = cy / sn * ang / dt
    w[2] = cz / sn * ang / dt
    if per_axis:
        for i in range(3):
            w[i] = min(rate_max, max(-rate_max, w[i]))
    else:
        nw = np.sqrt(w[0] ** 2 + w[1] ** 2 + w[2] ** 2)
        if nw > rate_max:
            w *= rate_max / nw
    return w


@numba.njit(cache=True)
def successive_rate_nb(d_k, d_km1, dt, omega_f, alpha, rate_max):
    """Gyro-less rate (eq. 3.67, :func:`rate_from_estimates_nb` bounded in norm by
    ``rate_max`` rad/s) through a first-order low-pass: α ω_f + (1 − α) ω̄.

    Returns the new filtered rate (3,) rad/s (body axes); ``omega_f`` is the previous one.
    """
    w = rate_from_estimates_nb(d_k, d_km1, dt, rate_max, False)
    return alpha * omega_f + (1.0 - alpha) * w


# ---------------------------------------------------------------------------------------
# filter state carried through a simulation loop
# ---------------------------------------------------------------------------------------
@numba.njit(cache=True)
def filter_init_nb(y, normals, prm):
    """Initial d from a single-point LSMN estimate scaled to the brightest output (or +x
    with a large covariance when no sensor is active).  Returns (d, P, Pxc, ok)."""
    thr = prm[2]
    p0 = prm[3]
    s = lsmn_nb(y, normals, thr, False)
    ok = (s[0] ** 2 + s[1] ** 2 + s[2] ** 2) > 0
    d = np.zeros(3)
    if ok:
        d[:] = s
    else:
        d[0] = 1.0
    P = np.eye(3) * p0
    return d, P, np.zeros((3, 3)), ok


@numba.njit(cache=True)
def filter_step_nb(kind, d, P, Pxc, omega, dt, y, normals, prm, reset=False):
    """One propagate+update of the EKF (kind 0) or ECKF (kind 1), in place; ``reset`` first
    sets the covariance back to p0 (end of an eclipse).  Returns (m, NIS, inflation).
    No albedo model (see :func:`filter_step_albedo_nb`)."""
    e3 = np.zeros((0, 3))
    return filter_step_albedo_nb(kind, d, P, Pxc, omega, dt, y, normals, prm, reset,
                                 e3, np.zeros(0), 0, np.zeros(0), e3, np.zeros(0), np.zeros(3),
                                 np.zeros(3))


def phi_state_size(params: "FilterParams") -> int:
    """Length of the φ grid-filter state array of :func:`filter_step_albedo_nb`."""
    return 7 + int(params.albedo_n_phi)


@numba.njit(cache=True)
def _phi_filter_nb(d, omega, dt, y, normals, prm, alb_coords, alb_ratio, alb_m, cos_fov_s,
                   horizon, phi_state, e2_I, s_I, a_mean, a_var):
    """Propagate and update the φ grid filter; fill the albedo mean/variance per sensor.

    ``phi_state`` = [r_b (3), e2 of the previous step (3, inertial), started flag,
    log-weights (n_phi)].  ``r_b`` is the body-axes image of the Sun–nadir axis e₂ under
    hypothesis φ = 0: it rotates with the body (gyro rate, like d) and about the Sun line by
    the known inertial rotation δψ of e₂ (orbital motion), so every hypothesis φ_i is a
    constant.  The likelihood of φ_i uses the "dark" sensors (Sun at least a margin outside
    the FOV): y_κ = |d| a_κ(φ_i) + noise, σ² = σ_a² + |d|² (rel a_κ(φ_i))².
    Returns True when the albedo mean/variance were filled.
    """
    n_phi = int(prm[17])
    nd = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    if nd < 1e-9:
        return False
    sb = d / nd
    if phi_state[6] < 0.5:
        k = 0 if abs(sb[0]) < 0.9 else 1
        rb = -sb[k] * sb
        rb[k] += 1.0
        for i in range(3):
            phi_state[i] = rb[i]
            phi_state[3 + i] = e2_I[i]
        for i in range(n_phi):
            phi_state[7 + i] = 0.0
        phi_state[6] = 1.0
    else:
        Phi = rotation_step_nb(omega, dt)
        rb = Phi @ phi_state[0:3]
        e2p = phi_state[3:6]
        cx = e2p[1] * e2_I[2] - e2p[2] * e2_I[1]
        cy = e2p[2] * e2_I[0] - e2p[0] * e2_I[2]
        cz = e2p[0] * e2_I[1] - e2p[1] * e2_I[0]
        dpsi = np.arctan2(s_I[0] * cx + s_I[1] * cy + s_I[2] * cz,
                          e2p[0] * e2_I[0] + e2p[1] * e2_I[1] + e2p[2] * e2_I[2])
        # active rotation of r_b by δψ about the Sun line: A(q(δψ ŝ))ᵀ r_b (eq. 3.13)
        rb = qrot_inv_nb(rotvec2q_nb(dpsi * sb), rb)
        c = rb[0] * sb[0] + rb[1] * sb[1] + rb[2] * sb[2]
        rb = rb - c * sb
        nr = np.sqrt(rb[0] ** 2 + rb[1] ** 2 + rb[2] ** 2)
        if nr < 1e-9:
            return False
        for i in range(3):
            phi_state[i] = rb[i] / nr
            phi_state[3 + i] = e2_I[i]
    if alb_m == 0:
        return False
    n_s = normals.shape[0]
    tab = np.empty((n_phi, n_s))
    albedo_phi_nb(alb_coords, alb_ratio, alb_m, sb, phi_state[0:3], normals, cos_fov_s,
                  horizon, n_phi, tab)
    rel, sa, mix, margin, temper = prm[16], prm[19], prm[20], prm[21], prm[22]
    lw = phi_state[7:7 + n_phi]
    for k in range(n_s):
        ck = normals[k, 0] * sb[0] + normals[k, 1] * sb[1] + normals[k, 2] * sb[2]
        if ck >= cos_fov_s[k] - margin:
            continue
        for i in range(n_phi):
            a = nd * tab[i, k]
            v = sa * sa + (rel * a) ** 2
            lw[i] += temper * (-0.5 * (y[k] - a) ** 2 / v - 0.5 * np.log(v))
    mx = lw[0]
    for i in range(1, n_phi):
        if lw[i] > mx:
            mx = lw[i]
    w = np.empty(n_phi)
    tot = 0.0
    for i in range(n_phi):
        w[i] = np.exp(lw[i] - mx)
        tot += w[i]
    for i in range(n_phi):
        w[i] = (1.0 - mix) * w[i] / tot + mix / n_phi
        lw[i] = np.log(w[i])
    for k in range(n_s):
        mu = 0.0
        for i in range(n_phi):
            mu += w[i] * tab[i, k]
        v = 0.0
        for i in range(n_phi):
            v += w[i] * (tab[i, k] - mu) ** 2
        a_mean[k] = mu
        a_var[k] = v
    return True


@numba.njit(cache=True)
def filter_step_albedo_nb(kind, d, P, Pxc, omega, dt, y, normals, prm, reset,
                          alb_coords, alb_ratio, alb_m, cos_fov_s, horizon,
                          phi_state, e2_I, s_I):
    """:func:`filter_step_nb` with the expected-albedo measurement model.

    ``alb_coords``/``alb_ratio``/``alb_m``: the sunlit, in-view albedo cells of the filter's
    albedo model in the Sun–nadir frame at this time
    (:func:`~lightcurve.css.albedo.albedo_sun_frame_nb`, computed from the known position
    and Sun); ``cos_fov_s`` (N,) and ``horizon`` (N,3): nominal FOV cosines and structure
    horizons of the sensors.  When ``prm`` has ``albedo_model`` on and ``alb_m > 0``, the
    expected albedo on each sensor given the *propagated* Sun direction (mean and variance
    over the rotation φ about the Sun line: uniform, or the posterior of the φ grid filter
    :func:`_phi_filter_nb` when ``albedo_phi`` is on and ``phi_state`` (length
    :func:`phi_state_size`, zeros to start) with the inertial Sun–nadir axis ``e2_I`` and Sun
    direction ``s_I`` are given; pass an empty ``phi_state`` otherwise) enters the update;
    otherwise this is exactly :func:`filter_step_nb`.
    """
    sigma, q, thr = prm[0], prm[1], prm[2]
    gate, infl_max, p_floor = prm[4], prm[5], prm[6]
    if reset:
        for i in range(3):
            for j in range(3):
                P[i, j] = prm[3] if i == j else 0.0
                Pxc[i, j] = 0.0
    norm_sigma, use_pred, cos_fov = prm[11], prm[12] > 0.5, prm[13]
    if kind == 0:
        ekf_propagate_nb(d, P, omega, dt, q)
    else:
        eckf_propagate_nb(d, P, Pxc, omega, dt, q, prm[7] * prm[7], int(prm[8]))
    a_mean = np.zeros(0)
    a_var = np.zeros(0)
    if prm[15] > 0.5:
        n_s = normals.shape[0]
        if prm[18] > 0.5 and phi_state.shape[0] == 7 + int(prm[17]):
            am = np.zeros(n_s)
            av = np.zeros(n_s)
            if _phi_filter_nb(d, omega, dt, y, normals, prm, alb_coords, alb_ratio, alb_m,
                              cos_fov_s, horizon, phi_state, e2_I, s_I, am, av):
                a_mean = am
                a_var = av
        elif alb_m > 0:
            nd = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
            if nd > 1e-9:
                a_mean = np.zeros(n_s)
                a_var = np.zeros(n_s)
                expected_albedo_nb(alb_coords, alb_ratio, alb_m, d / nd, normals, cos_fov_s,
                                   horizon, int(prm[17]), a_mean, a_var)
    if prm.shape[0] > 23 and prm[23] > 0.5:
        return _update_core(d, P, Pxc, y, normals, sigma, thr, gate, infl_max, p_floor,
                            kind == 1, norm_sigma, use_pred, cos_fov, a_mean, a_var, prm[16],
                            cos_fov_s)
    return _update_core(d, P, Pxc, y, normals, sigma, thr, gate, infl_max, p_floor, kind == 1,
                        norm_sigma, use_pred, cos_fov, a_mean, a_var, prm[16],
                        np.zeros(0))


@numba.njit(cache=True)
def run_filter_nb(kind, t, Y, W, use_gyro, normals, prm):
    """Run a sun-line filter over a recording in one compiled loop.

    kind: 0 EKF, 1 ECKF; t (K,) s; Y (K,N) CSS outputs; W (K,3) gyro rates rad/s (ignored
    unless use_gyro); normals (N,3) nominal body normals; prm: FilterParams.as_array().
    Returns D (K,3) scaled Sun vector estimates (body), Pdiag (K,3), n_active (K,),
    omega_used (K,3).
    """
    K = Y.shape[0]
    D = np.zeros((K, 3))
    Pd = np.zeros((K, 3))
    nact = np.zeros(K, dtype=np.int64)
    Wout = np.zeros((K, 3))
    started = False
    d = np.zeros(3)
    P = np.eye(3)
    Pxc = np.zeros((3, 3))
    d_prev = np.zeros(3)
    om_f = np.zeros(3)
    alpha, rmax = prm[9], prm[10]
    dark = 0.0
    # no albedo model offline (recordings carry no positions); work arrays allocated once
    e3 = np.zeros((0, 3))
    e0 = np.zeros(0)
    z3 = np.zeros(3)
    for k in range(K):
        if not started:
            d, P, Pxc, ok = filter_init_nb(Y[k], normals, prm)
            if ok:
                started = True
                d_prev[:] = d
            D[k] = d if ok else np.zeros(3)
            Pd[k] = np.array([P[0, 0], P[1, 1], P[2, 2]])
            continue
        dt = t[k] - t[k - 1]
        if use_gyro:
            om = W[k - 1]
        else:
            om = om_f
        lit_now = False
        for j in range(Y.shape[1]):
            if Y[k, j] > prm[2]:
                lit_now = True
        reset = lit_now and prm[14] > 0 and dark >= prm[14]
        m, nis, infl = filter_step_albedo_nb(kind, d, P, Pxc, om, dt, Y[k], normals, prm,
                                             reset, e3, e0, 0, e0, e3, e0, z3, z3)
        dark = 0.0 if lit_now else dark + dt
        if not use_gyro:
            om_f = successive_rate_nb(d, d_prev, dt, om_f, alpha, rmax)
        d_prev[:] = d
        D[k] = d
        Pd[k] = np.array([P[0, 0], P[1, 1], P[2, 2]])
        nact[k] = m
        Wout[k] = om
    return D, Pd, nact, Wout


def run_filter(kind: str, t, Y, normals, gyro=None, params: FilterParams | None = None):
    """Object-layer wrapper of :func:`run_filter_nb`.

    kind: 'ekf' or 'eckf'; t (K,) s; Y (K,N) CSS outputs; normals (N,3) nominal body
    normals; gyro (K,3) rad/s or None (gyro-less, eq. 3.67).  Returns a dict with
    ``d`` (K,3), ``s_hat`` (K,3) unit estimates (zeros before the first active sensor),
    ``p_diag`` (K,3), ``n_active`` (K,), ``omega`` (K,3) rates used.
    """
    if kind not in FILTER_KINDS:
        raise ValueError(f"unknown filter {kind!r}; allowed: {', '.join(FILTER_KINDS)}")
    prm = (params or FilterParams()).as_array()
    t = np.ascontiguousarray(t, dtype=float)
    Y = np.ascontiguousarray(Y, dtype=float)
    if Y.ndim != 2 or Y.shape[0] != t.shape[0]:
        raise ValueError("Y must have shape (len(t), N)")
    W = np.zeros((t.shape[0], 3)) if gyro is None else np.ascontiguousarray(gyro, dtype=float)
    D, Pd, nact, Wu = run_filter_nb(FILTER_KINDS.index(kind), t, Y, W, gyro is not None,
                                    np.ascontiguousarray(normals, dtype=float), prm)
    n = np.linalg.norm(D, axis=1, keepdims=True)
    s = np.divide(D, n, out=np.zeros_like(D), where=n > 0)
    return {"d": D, "s_hat": s, "p_diag": Pd, "n_active": nact, "omega": Wu}


def gyroless_params(base: FilterParams | None = None) -> FilterParams:
    """Robust-filter tuning for gyro-less operation (eq. 3.67 rates): larger process noise
    and considered rate error, and a light rate low-pass (α = 0.3 per 0.5 s sample, a
    0.38 Hz corner): under control a slower one lags the controller's own action and the
    loop loses the Sun (the choice and its measurement: docs/measurements.md)."""
    from dataclasses import replace

    b = base or FilterParams()
    return replace(b, q_proc=1e-3, rate_alpha=0.3, sigma_meas=0.1, consider_sigma=2e-3)


def default_filter_params(gyro) -> FilterParams:
    """The robust filters' default tuning for a case: :class:`FilterParams` with a gyro
    (``gyro`` a grade name, a GyroSpec or recorded rates), :func:`gyroless_params` without
    (``gyro`` None or "none").  Every simulation, study and command line path takes its
    default here."""
    none = gyro is None or (isinstance(gyro, str) and gyro == "none")
    return gyroless_params() if none else FilterParams()
