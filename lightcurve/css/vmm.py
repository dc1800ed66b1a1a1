"""Voltage measurement model (VMM) versus sun-vector measurement model (SMM) in a full-attitude
MEKF with magnetometer, photodiodes and gyro (after DiGregorio, *Improved model for low cost
sun sensor attitude filtering*).

Both filters are the same multiplicative EKF (Lefferts, Markley & Shuster 1982; Crassidis &
Junkins, *Optimal Estimation of Dynamic Systems*, §7.2) on the same data:

* global attitude ``q̂`` (scalar first, inertial→body, ``v_B = A(q) v_N``), error state
  ``[δθ, Δβ]`` with ``q = δq(δθ) ⊗ q̂``, ``A(q) ≈ (I − [δθ×]) A(q̂)``, gyro bias β (rad/s);
* propagation ``q̂⁺ = δq(ω̂ Δt) ⊗ q̂``, ``ω̂ = ω̃ − β̂`` (the exact constant-rate step,
  :func:`lightcurve.core.dynamics.const_rate_nb`), ``F = [[−[ω̂×], −I], [0, 0]]`` and its
  closed-form ``Φ = exp(F Δt)`` (:func:`lightcurve.core.dynamics.controlled_transition_nb`, the
  bias block with the opposite sign), Farrenkopf discrete process noise; Joseph-form updates
  (:func:`lightcurve.core.kalman.joseph_update_nb`);
* magnetometer: unit field direction ``b̂_B = A(q) b̂_N``, ``H_θ = [(A b̂_N)×]``, ``R = σ_m² I``.

They differ only in how the photodiodes enter:

* **SMM**: the photodiode outputs are first turned into a unit Sun vector by the
  least-squares minimum-norm solution (LSMN, O'Keefe eq. 3.9-3.10; the pseudo-inverse for
  fewer than three lit diodes), which is then used as a unit-vector measurement
  ``ŝ_B = A(q) ŝ_N`` with ``R = σ_s² I``.  With fewer than three lit diodes the minimum-norm
  vector is biased toward the lit normals and the filter is fed a wrong direction;
* **VMM**: every lit photodiode (output above ``threshold``) is a scalar measurement
  ``y_κ = n̂_κ · A(q) ŝ_N`` with ``H_θ = n̂_κᵀ [(A ŝ_N)×]`` and ``R = σ_y²`` — one or two lit
  diodes still constrain the attitude correctly.

Truth: the torque-free/gravity-gradient tumbling of :mod:`lightcurve.css.truth` (400 km polar
orbit), photodiodes of the cube configuration (table 2.2, 90° FOV by default, so that one to
three diodes are lit), Farrenkopf gyro, a tilted-dipole geomagnetic field (dipole moment
7.94e22 A m², pole at 80.65° N, 72.68° W — IGRF-2015 first-degree terms, rounded; our choice:
the DiGregorio slides give no field model, only 'zero-mean Gaussian noise' on the truth).  Earth albedo is off by default (neither
filter models it); ``albedo=True`` switches the built-in model on in the truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..core.dynamics import const_rate_nb, controlled_transition_nb
from ..core.kalman import joseph_update_nb
from ..core.rotations import qmul_nb, qnormalize_nb, qrot_nb, rotvec2q_nb, skew_nb
from ..estimation.rng import as_generator
from ..rotations import quat_mult, rotvec_to_quat
from .single_point import lsmn_nb

__all__ = ["VMMParams", "dipole_field_eci", "mekf_run_nb", "VMMCase", "simulate_vmm_case",
           "run_vmm_smm", "vmm_study", "plot_vmm_study"]

MU0_4PI = 1e-7
DIPOLE_MOMENT_AM2 = 7.94e22
DIPOLE_POLE_LAT_DEG = 80.65
DIPOLE_POLE_LON_DEG = -72.68


def dipole_field_eci(r_I_m, theta_rad) -> np.ndarray:
    """Tilted-dipole geomagnetic field (T), ECI axes, at positions r_I_m (K,3) m for Earth
    rotation angles theta_rad (K,).  B = μ0/(4π r³) [3 (m·r̂) r̂ − m]; the dipole moment points
    to the southern geomagnetic pole (antipode of the northern one)."""
    r = np.atleast_2d(np.asarray(r_I_m, dtype=float))
    th = np.broadcast_to(np.asarray(theta_rad, dtype=float), (r.shape[0],))
    lat, lon = np.radians(DIPOLE_POLE_LAT_DEG), np.radians(DIPOLE_POLE_LON_DEG)
    m_E = -DIPOLE_MOMENT_AM2 * np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon),
                                         np.sin(lat)])
    c, s = np.cos(th), np.sin(th)
    # ECEF -> ECI: R3(-θ)
    m_I = np.column_stack([c * m_E[0] - s * m_E[1], s * m_E[0] + c * m_E[1],
                           np.full_like(c, m_E[2])])
    rn = np.linalg.norm(r, axis=1, keepdims=True)
    rh = r / rn
    mr = np.sum(m_I * rh, axis=1, keepdims=True)
    return MU0_4PI / rn ** 3 * (3.0 * mr * rh - m_I)


@dataclass(frozen=True)
class VMMParams:
    """Filter tuning (SI).  arw/rrw gyro σ_v (rad/√s), σ_u (rad/s^1.5); sigma_mag_rad
    magnetometer direction 1σ; sigma_sun_rad SMM Sun-vector 1σ; sigma_y VMM output 1σ;
    threshold photodiode activity threshold; sigma_att0_rad, sigma_bias0 initial 1σ."""

    arw: float = 0.5 * np.pi / 180 / 60
    rrw: float = 2e-6
    sigma_mag_rad: float = float(np.radians(1.0))
    sigma_sun_rad: float = float(np.radians(2.0))
    sigma_y: float = 0.02
    threshold: float = 0.1
    sigma_att0_rad: float = float(np.radians(10.0))
    sigma_bias0: float = float(np.radians(0.1))

    def as_array(self):
        return np.array([self.arw, self.rrw, self.sigma_mag_rad, self.sigma_sun_rad,
                         self.sigma_y, self.threshold], dtype=float)


@numba.njit(cache=True)
def _apply(q, b, dx):
    dq = rotvec2q_nb(dx[0:3])
    qn = qnormalize_nb(qmul_nb(dq, q))
    for i in range(4):
        q[i] = qn[i]
    for i in range(3):
        b[i] += dx[3 + i]


@numba.njit(cache=True)
def mekf_run_nb(mode, t, W, Y, normals, mag_B, mag_N, sun_N, q0, P0, prm):
    """Run the MEKF with the SMM (mode 0) or VMM (mode 1) photodiode model.

    t (K,); W (K,3) gyro rad/s; Y (K,N) photodiode outputs; normals (N,3) body; mag_B
    (K,3) measured unit field (body); mag_N (K,3) unit reference field (ECI); sun_N (K,3)
    unit Sun (ECI); q0 (4,); P0 (6,6); prm: VMMParams.as_array().
    Returns Q (K,4) estimates, Pd (K,6) variances, n_lit (K,).
    """
    K = t.shape[0]
    N = normals.shape[0]
    arw, rrw, sm, ss, sy, thr = prm[0], prm[1], prm[2], prm[3], prm[4], prm[5]
    q = q0.copy()
    b = np.zeros(3)
    P = P0.copy()
    Qo = np.zeros((K, 4))
    Pd = np.zeros((K, 6))
    NL = np.zeros(K, dtype=np.int64)
    cons = np.zeros(6, dtype=np.bool_)
    for k in range(K):
        if k > 0:
            dt = t[k] - t[k - 1]
            w = W[k - 1] - b
            qn = qnormalize_nb(const_rate_nb(q, w, dt))
            for i in range(4):
                q[i] = qn[i]
            # error state [δθ, Δβ] with δθ̇ = −[ω̂×]δθ − Δβ: the constant-rate Φ with δω = −Δβ
            Phi = controlled_transition_nb(w, dt)
            for i in range(3):
                for j in range(3):
                    Phi[i, 3 + j] = -Phi[i, 3 + j]
            Qd = np.zeros((6, 6))
            for i in range(3):
                Qd[i, i] = arw * arw * dt + rrw * rrw * dt ** 3 / 3.0
                Qd[i, 3 + i] = -rrw * rrw * dt * dt / 2.0
                Qd[3 + i, i] = Qd[i, 3 + i]
                Qd[3 + i, 3 + i] = rrw * rrw * dt
            P = Phi @ P @ Phi.T + Qd
        # magnetometer
        hm = qrot_nb(q, mag_N[k])
        H = np.zeros((3, 6))
        Hx = skew_nb(hm)
        for i in range(3):
            for j in range(3):
                H[i, j] = Hx[i, j]
        dx, Pn, nis, ok = joseph_update_nb(np.zeros(6), P, mag_B[k] - hm, H,
                                           np.eye(3) * sm * sm, cons)
        if ok:
            P = Pn
            _apply(q, b, dx)
        # photodiodes
        nl = 0
        for j in range(N):
            if Y[k, j] > thr:
                nl += 1
        NL[k] = nl
        if nl > 0:
            hs = qrot_nb(q, sun_N[k])
            Sx = skew_nb(hs)
            if mode == 0:
                s_meas = lsmn_nb(Y[k], normals, thr, False)
                if s_meas[0] ** 2 + s_meas[1] ** 2 + s_meas[2] ** 2 > 0.0:
                    H = np.zeros((3, 6))
                    for i in range(3):
                        for j in range(3):
                            H[i, j] = Sx[i, j]
                    dx, Pn, nis, ok = joseph_update_nb(np.zeros(6), P, s_meas - hs, H,
                                                       np.eye(3) * ss * ss, cons)
                    if ok:
                        P = Pn
                        _apply(q, b, dx)
            else:
                H = np.zeros((nl, 6))
                nu = np.zeros(nl)
                i = 0
                for j in range(N):
                    if Y[k, j] > thr:
                        row = normals[j] @ Sx
                        for c in range(3):
                            H[i, c] = row[c]
                        pred = normals[j, 0] * hs[0] + normals[j, 1] * hs[1] + normals[j, 2] * hs[2]
                        nu[i] = Y[k, j] - max(pred, 0.0)
                        i += 1
                dx, Pn, nis, ok = joseph_update_nb(np.zeros(6), P, nu, H,
                                                   np.eye(nl) * sy * sy, cons)
                if ok:
                    P = Pn
                    _apply(q, b, dx)
        Qo[k] = q
        for i in range(6):
            Pd[k, i] = P[i, i]
    return Qo, Pd, NL


@dataclass
class VMMCase:
    """One simulated data set: t, q_true (K,4), gyro (K,3), Y (K,N), normals (N,3), mag_B,
    mag_N, sun_N (K,3) unit vectors, lit (K,)."""

    t: np.ndarray
    q_true: np.ndarray
    gyro: np.ndarray
    Y: np.ndarray
    normals: np.ndarray
    mag_B: np.ndarray
    mag_N: np.ndarray
    sun_N: np.ndarray
    lit: np.ndarray


def simulate_vmm_case(rng, *, duration_s=3000.0, dt_s=1.0, fov_half_angle_deg=90.0,
                      noise_sigma=0.01, gyro="rate", sigma_mag_T=3e-7, albedo=False,
                      rate_sigma_deg_s=1.0, epoch_utc="2015-03-01T00:00:00Z") -> VMMCase:
    """Simulate tumbling truth, cube photodiodes (nominal calibration), a gyro of the given
    grade and a magnetometer with white noise ``sigma_mag_T`` per axis (T)."""
    from .albedo import earth_rotation_angle
    from .configurations import cube
    from .gyro import gyro_grade, simulate_gyro
    from .truth import CSSScenario, Dispersions, simulate_css

    g = as_generator(rng)
    css = cube(fov_half_angle_deg=fov_half_angle_deg)
    disp = Dispersions(rate_sigma_deg_s=rate_sigma_deg_s, css_scale_common_sigma=0.0,
                       css_scale_sigma=0.0, css_misalignment_sigma_deg=0.0,
                       css_noise_sigma=noise_sigma)
    sc = CSSScenario(css, estimator="wavg", gyro=None, controlled=False, duration_s=duration_s,
                     dt_s=dt_s, epoch_utc=epoch_utc, albedo=None if albedo else False,
                     dispersions=disp)
    r = simulate_css(sc, g)
    spec = gyro_grade(gyro) if isinstance(gyro, str) else gyro
    w_meas, _ = simulate_gyro(r.omega, dt_s, spec, g, detailed=False)
    theta = earth_rotation_angle(epoch_utc, r.t)
    B_N = dipole_field_eci(r.info["r_I_m"], theta)
    from ..rotations import quat_rotate

    B_B = quat_rotate(r.q, B_N) + g.normal(0.0, sigma_mag_T, B_N.shape)
    nb = B_B / np.linalg.norm(B_B, axis=1, keepdims=True)
    nn = B_N / np.linalg.norm(B_N, axis=1, keepdims=True)
    return VMMCase(r.t, r.q, w_meas, r.y, css.normals.copy(), nb, nn, r.info["sun_I_hat"], r.lit)


def run_vmm_smm(case: VMMCase, params: VMMParams = VMMParams(), *, rng=None):
    """Run both filters from the same (dispersed) initial estimate.  Returns a dict with
    ``err_smm_deg``, ``err_vmm_deg`` (K,), ``n_lit`` (K,), ``t``."""
    from ..rotations import attitude_error_angle

    g = as_generator(0 if rng is None else rng)
    dq = rotvec_to_quat(g.normal(0.0, params.sigma_att0_rad, 3))
    q0 = quat_mult(dq, case.q_true[0])
    P0 = np.diag([params.sigma_att0_rad ** 2] * 3 + [params.sigma_bias0 ** 2] * 3)
    out = {"t": case.t}
    for name, mode in (("smm", 0), ("vmm", 1)):
        Q, Pd, NL = mekf_run_nb(mode, case.t, case.gyro, case.Y, case.normals, case.mag_B,
                                case.mag_N, case.sun_N, q0, P0, params.as_array())
        out[f"err_{name}_deg"] = np.degrees(attitude_error_angle(case.q_true, Q))
        out["n_lit"] = NL
    return out


def vmm_study(n_runs=20, *, seed=0, settle_s=300.0, params: VMMParams = VMMParams(),
              progress=None, **kw):
    """Monte Carlo of :func:`run_vmm_smm`.  Errors are pooled over samples after
    ``settle_s`` and grouped by the number of lit photodiodes (0, 1, 2, ≥3).

    Returns ``{"by_n_lit": {n: {"samples", "smm_median_deg", "vmm_median_deg",
    "smm_rms_deg", "vmm_rms_deg"}}, "lt3": {...}, "runs": n_runs, "example": one run}``.
    ``progress``: callable called with no argument after each run, or None.
    """
    ss = np.random.SeedSequence(int(seed)).spawn(int(n_runs))
    es, ev, nl = [], [], []
    example = None
    for i, s in enumerate(ss):
        g = np.random.default_rng(s)
        case = simulate_vmm_case(g, **kw)
        r = run_vmm_smm(case, params, rng=g)
        m = r["t"] >= settle_s
        es.append(r["err_smm_deg"][m])
        ev.append(r["err_vmm_deg"][m])
        nl.append(r["n_lit"][m])
        if example is None:
            example = r
        if progress is not None:
            progress()
    es, ev, nl = np.concatenate(es), np.concatenate(ev), np.concatenate(nl)

    def stats(mask):
        if not mask.any():
            return {"samples": 0}
        return {"samples": int(mask.sum()), "smm_median_deg": float(np.median(es[mask])),
                "vmm_median_deg": float(np.median(ev[mask])),
                "smm_rms_deg": float(np.sqrt(np.mean(es[mask] ** 2))),
                "vmm_rms_deg": float(np.sqrt(np.mean(ev[mask] ** 2)))}

    by = {str(n): stats(nl == n) for n in (0, 1, 2)}
    by["3+"] = stats(nl >= 3)
    return {"runs": int(n_runs), "by_n_lit": by, "lt3": stats((nl >= 1) & (nl < 3)),
            "example": example}


def plot_vmm_study(result, path):
    """Figure: attitude error of both filters over time for the example run (number of lit
    photodiodes below), and the median error per number of lit diodes.  Written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io.atomic import atomic_path

    ex = result["example"]
    fig, ax = plt.subplots(3, 1, figsize=(8, 9), gridspec_kw={"height_ratios": [3, 1, 2]})
    ax[0].semilogy(ex["t"], np.maximum(ex["err_smm_deg"], 1e-3), lw=0.7, label="SMM")
    ax[0].semilogy(ex["t"], np.maximum(ex["err_vmm_deg"], 1e-3), lw=0.7, label="VMM")
    ax[0].set_ylabel("attitude error (deg)")
    ax[0].legend()
    ax[1].step(ex["t"], ex["n_lit"], where="post", lw=0.7, color="k")
    ax[1].set_ylabel("lit diodes")
    ax[1].set_xlabel("t (s)")
    keys = ["1", "2", "3+"]
    sm = [result["by_n_lit"][k].get("smm_median_deg", np.nan) for k in keys]
    vm = [result["by_n_lit"][k].get("vmm_median_deg", np.nan) for k in keys]
    x = np.arange(len(keys))
    ax[2].bar(x - 0.2, sm, 0.4, label="SMM")
    ax[2].bar(x + 0.2, vm, 0.4, label="VMM")
    ax[2].set_xticks(x, keys)
    ax[2].set_xlabel("number of lit photodiodes")
    ax[2].set_ylabel(f"median error (deg), {result['runs']} runs")
    ax[2].legend()
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
