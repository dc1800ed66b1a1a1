"""On-orbit CSS calibration filters (O'Keefe 2015, §4.2-4.4): full and reduced.

Extended consider Kalman filter over (indices for N sensors)::

    x = [ σ (0:3),  β (3:6),  g_κ (6:6+N),  (δα_κ, δε_κ) (6+N:6+3N),  b_κ (6+3N:6+4N) ]

* ``σ``: MRP attitude σ_BN (inertial→body), ``β``: gyro bias (rad/s) — the MRP EKF of
  :mod:`lightcurve.css.attitude_ekf` (eq. 4.5-4.11) is the core;
* ``g_κ = C C_κ``: total scale factor of sensor κ (the common factor C is not separable
  from the individual ones with CSS data alone, so the product is estimated);
* ``δα_κ, δε_κ``: azimuth/elevation misalignment of the normal (rad, eq. 2.19);
* ``b_κ``: *considered* albedo-model error of sensor κ (units of the solar irradiance):
  never updated (Schmidt gain rows zero), first-order Gauss-Markov with 1σ ``consider_sigma``
  and time constant ``consider_tau_s``; its covariance and cross covariances are carried.

Measurement of sensor κ (eq. 2.21, 4.12-4.20)::

    h_κ = g_κ [ ν f(n̂'_κ · C(σ) ŝ_N) + n̂'_κ · C(σ) V_κ,N + b_κ ]
    V_κ = Σ_{j ∈ sunlit ∩ in view ∩ FOV_κ} a_j ĉ_j               (albedo vector sum, eq. 2.15)

with ``n̂'_κ`` the nominal normal rotated by the estimated misalignment, ``ν`` the lit
fraction, ``a_j`` the cell irradiance ratios of :mod:`lightcurve.css.albedo` and ``ĉ_j`` the
spacecraft→cell directions.  Because ``C(σ) V`` is linear in ``V``, the albedo part of every
Jacobian needs only the per-sensor *vector sum* ``V_κ`` (eq. 4.21-4.34 in compact form)::

    ∂h/∂σ   = g_κ n̂'ᵀ [ ν ∂(C ŝ_N)/∂σ  +  ∂(C V_κ,N)/∂σ ]     (∂(C a)/∂σ: rotations.mrp_dcm_vec_jacobian)
    ∂h/∂g_κ = ν f + n̂'·V_κ,B
    ∂h/∂δα  = g_κ (∂n̂'/∂α)·(ν ŝ_B + V_κ,B),   ∂n̂'/∂α = [−cos ε sin α, cos ε cos α, 0]
    ∂h/∂δε  = g_κ (∂n̂'/∂ε)·(ν ŝ_B + V_κ,B),   ∂n̂'/∂ε = [−sin ε cos α, −sin ε sin α, cos ε]
    ∂h/∂b_κ = g_κ

(cell membership of the FOV is not differentiated).  Cells are evaluated only inside the
latitude/longitude window of the spherical cap visible from the spacecraft, and only when
sunlit and in view — the cost is independent of the grid's global size (benchmark
``benchmarks/css_calibration.py``).

Measurement noise (§4.2, our concrete form):
``R_κ = max(σ_n², σ_floor²) + (k_alb g_κ A_κ)² + (g_κ A_edge,κ)²`` (white noise σ_n with
a floor — σ_n = σ_css, or g_κ σ_css when the noise lies inside the scale factor as in
eq. 2.21 — a relative albedo-model uncertainty, and the irradiance of the albedo cells
lying within the FOV-edge margin, whose membership of the FOV is uncertain — large for coarse
grids), plus, when the filter's albedo grid is coarser than the truth, the grid's
representation error ``(g_κ (k_grid A_κ + a_grid))²`` (:func:`albedo_grid_error`; CERES 10° vs 1° at 400 km:
k ≈ 0.39, a ≈ 0.012; 5°: 0.075, 0.0035 — without it the 10° filter is over-confident);
sensors are used when
their *predicted* output exceeds ``threshold`` (selecting on the noisy measured output would
bias weak-signal innovations) or their output exceeds 3 × ``threshold`` (so a badly predicted
sensor cannot lock itself out), and the model predicts light on them, except near the FOV
edge (``fov_edge_margin`` in cosine, widened by the 3σ uncertainty of the normal) or, inside
the FOV, near the structure-horizon plane (the same margin); a per-sensor
innovation gate (``gate_sensor``, χ²₁) rejects outliers; when the NIS of the accepted set
exceeds ``gate × m`` the whole R is inflated by ``NIS/(gate m)`` (at most ``inflate_max``).

Reduced filter (§4.3): no albedo model (``V_κ = 0``), the albedo enters only through the
considered bias ``b_κ`` with a larger σ.

Star-tracker updates (a separate update, :func:`~lightcurve.css.attitude_ekf.star_tracker_update_nb`)
make the attitude observable about the Sun line; without them the calibration of a tumbling
spacecraft is not observable from CSS data alone.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numba
import numpy as np

from ..core.kalman import joseph_update_nb
from ..core.rotations import euler321_to_dcm_nb, mrp2dcm_nb, mrp_dcm_vec_jac_nb
from ..estimation.rng import as_generator
from ..rotations import quat_mult, quat_to_mrp, rotvec_to_quat
from .albedo import (AlbedoCells, AlbedoMap, albedo_vectors_nb, builtin_albedo_map,
                     cap_cells_nb, cells_coefficient_cov_nb, cells_vectors_nb,
                     earth_rotation_angle)
from .attitude_ekf import (mrp_apply_correction_nb, mrp_propagate_nb, mtv3_nb, mv3_nb,
                           star_tracker_update_nb)
from .sensors import CSSArray, normal_to_azel

__all__ = ["AlbedoCells", "CalibrationParams", "CalibrationResult", "run_calibration",
           "calibration_measurement_nb", "calibration_update_nb", "albedo_vectors_nb",
           "CalibrationCase", "simulate_calibration_case", "state_layout", "acceptance_summary",
           "albedo_grid_error", "initialised_sensors", "albedo_subdivision",
           "ALBEDO_SUBCELL_DEG"]


# ---------------------------------------------------------------------------------------
# measurement model and update
# ---------------------------------------------------------------------------------------
@numba.njit(cache=True)
def calibration_measurement_nb(x, az0, el0, cos_fov, horizon_B, s_N, lit, theta, r_E, s_E,
                               cells_c, cells_n, cells_ra, lat_c, nlat, nlon, lon_w0, dlon,
                               dlat_max, edge_m):
    """Predicted outputs h (N,), Jacobian H (N, n) over the full state (n = 6 + 4N), the
    direct part D (N,) and the albedo part A (N,) of each sensor (before the gain g_κ), and
    the cosine c (N,) between each (misaligned) normal and the Sun direction, and the albedo
    irradiance A_edge (N,) of the cells within ``edge_m`` (N,) of each FOV cut-off.

    az0, el0 (N,) nominal azimuth/elevation of the normals (rad); cos_fov (N,); horizon_B
    (N,3) structure-horizon normals, body; s_N unit Sun direction (inertial); lit fraction;
    theta Earth rotation angle (rad); r_E, s_E spacecraft position (m) and unit Sun
    direction, Earth-fixed; the rest: :meth:`AlbedoCells.args`.
    """
    U, a, _, m, _ = cap_cells_nb(cells_c, cells_n, cells_ra, lat_c, nlat, nlon, lon_w0, dlon,
                                 dlat_max, r_E, s_E)
    return _measurement_cells_nb(x, az0, el0, cos_fov, horizon_B, s_N, lit, theta, U, a, m,
                                 edge_m)


@numba.njit(cache=True)
def _measurement_cells_nb(x, az0, el0, cos_fov, horizon_B, s_N, lit, theta, U, a_cells, mc,
                          edge_m):
    """:func:`calibration_measurement_nb` on the sunlit cells in view already found
    (:func:`~lightcurve.css.albedo.cap_cells_nb`: directions U, irradiance ratios a_cells,
    count mc; Earth-fixed)."""
    N = az0.shape[0]
    n = x.shape[0]
    s = x[0:3].copy()
    C = mrp2dcm_nb(s)
    s_B = mv3_nb(C, s_N)
    nb = np.empty((N, 3))
    da = np.empty((N, 3))
    de = np.empty((N, 3))
    for k in range(N):
        a = az0[k] + x[6 + N + 2 * k]
        e = el0[k] + x[6 + N + 2 * k + 1]
        ca, sa, ce, se = np.cos(a), np.sin(a), np.cos(e), np.sin(e)
        nb[k, 0] = ce * ca
        nb[k, 1] = ce * sa
        nb[k, 2] = se
        da[k, 0] = -ce * sa
        da[k, 1] = ce * ca
        da[k, 2] = 0.0
        de[k, 0] = -se * ca
        de[k, 1] = -se * sa
        de[k, 2] = ce
    # albedo vector sums (Earth-fixed -> inertial)
    V_N = np.zeros((N, 3))
    Aedge = np.zeros(N)
    if mc > 0:
        nE = np.empty((N, 3))
        hE = np.empty((N, 3))
        E = euler321_to_dcm_nb(np.array([theta, 0.0, 0.0]))   # ECI → Earth-fixed, R3(θ)
        for k in range(N):
            nE[k] = mv3_nb(E, mtv3_nb(C, nb[k]))
            hE[k] = mv3_nb(E, mtv3_nb(C, horizon_B[k]))
        V_E, Aedge = cells_vectors_nb(U, a_cells, mc, nE, cos_fov, hE, edge_m)
        for k in range(N):
            V_N[k] = mtv3_nb(E, V_E[k])
    Js = mrp_dcm_vec_jac_nb(s, s_N)
    h = np.zeros(N)
    H = np.zeros((N, n))
    D = np.zeros(N)
    A = np.zeros(N)
    cosd = np.zeros(N)
    for k in range(N):
        g = x[6 + k]
        c = nb[k, 0] * s_B[0] + nb[k, 1] * s_B[1] + nb[k, 2] * s_B[2]
        cosd[k] = c
        direct = False
        if lit > 0.0 and c >= cos_fov[k] and c > 0.0:
            if (horizon_B[k, 0] * s_B[0] + horizon_B[k, 1] * s_B[1]
                    + horizon_B[k, 2] * s_B[2]) >= 0.0:
                direct = True
        u = np.zeros(3)  # ν ŝ_B (if direct) + V_B
        if direct:
            D[k] = lit * c
            u += lit * s_B
        has_alb = V_N[k, 0] != 0.0 or V_N[k, 1] != 0.0 or V_N[k, 2] != 0.0
        if has_alb:
            V_B = mv3_nb(C, V_N[k])
            A[k] = nb[k, 0] * V_B[0] + nb[k, 1] * V_B[1] + nb[k, 2] * V_B[2]
            u += V_B
        h[k] = g * (D[k] + A[k] + x[6 + 3 * N + k])
        # σ columns
        row = np.zeros(3)
        if direct:
            row += lit * mtv3_nb(Js, nb[k])
        if has_alb:
            row += mtv3_nb(mrp_dcm_vec_jac_nb(s, V_N[k]), nb[k])
        for j in range(3):
            H[k, j] = g * row[j]
        H[k, 6 + k] = D[k] + A[k] + x[6 + 3 * N + k]
        H[k, 6 + N + 2 * k] = g * (da[k, 0] * u[0] + da[k, 1] * u[1] + da[k, 2] * u[2])
        H[k, 6 + N + 2 * k + 1] = g * (de[k, 0] * u[0] + de[k, 1] * u[1] + de[k, 2] * u[2])
        H[k, 6 + 3 * N + k] = g
    return h, H, D, A, cosd, Aedge


@numba.njit(cache=True)
def _gather_rows(idx, m, H, y, h):
    """Rows ``idx[:m]`` of the Jacobian and their innovations y − h."""
    Hm = np.empty((m, H.shape[1]))
    nu = np.empty(m)
    for i in range(m):
        Hm[i] = H[idx[i]]
        nu[i] = y[idx[i]] - h[idx[i]]
    return Hm, nu


@numba.njit(cache=True)
def _consider_mask(n, N):
    """Consider-state mask of the n-state calibration filter with N sensors: the albedo
    errors after attitude, gyro bias and the 3N sensor parameters."""
    cons = np.zeros(n, dtype=np.bool_)
    for i in range(6 + 3 * N, n):
        cons[i] = True
    return cons


@numba.njit(cache=True)
def _innovation_variance(P, Hrow, r):
    """``Hrow P Hrowᵀ + r``: the prior variance of one sensor's innovation (zero entries of
    the Jacobian row skipped)."""
    n = P.shape[0]
    v = r
    for a in range(n):
        if Hrow[a] != 0.0:
            acc = 0.0
            for b in range(n):
                acc += P[a, b] * Hrow[b]
            v += Hrow[a] * acc
    return v


@numba.njit(cache=True)
def _selected_update(x, P, nu, Hm, R, N, gate, infl_max):
    """Measurement update of both filters with the m selected sensors (rows ``Hm``,
    innovations ``nu``, covariance ``R``), in place: the Joseph update with the albedo errors
    considered (:func:`_consider_mask`) and, when ``NIS > gate·m``, once more with R inflated
    by ``min(NIS/(gate·m), infl_max)`` (gate = inf: never; module docstring), then the MRP
    correction (:func:`~lightcurve.css.attitude_ekf.mrp_apply_correction_nb`). Returns
    ``(m, NIS, inflation)``; ``(0, NaN, 1)`` when no sensor is selected or the update fails."""
    m = nu.shape[0]
    if m == 0:
        return 0, np.nan, 1.0
    n = x.shape[0]
    cons = _consider_mask(n, N)
    xn, Pn, nis, ok = joseph_update_nb(np.zeros(n), P, nu, Hm, R, cons)
    if not ok:
        return 0, np.nan, 1.0
    infl = 1.0
    if nis > gate * m:
        infl = min(nis / (gate * m), infl_max)
        xn, Pn, nis2, ok = joseph_update_nb(np.zeros(n), P, nu, Hm, R * infl, cons)
        if not ok:
            return 0, np.nan, 1.0
    mrp_apply_correction_nb(x, P, xn, Pn)
    return m, nis, infl


@numba.njit(cache=True)
def _albedo_spread_cov(x, az0, el0, cos_fov, horizon_B, lit, theta, U, w, mc, have_sig,
                       diag_only=False):
    """(N,N) covariance of the albedo irradiance on the sensors from the spread of the cells'
    albedo coefficients (O'Keefe eq. 4.30b, :func:`cells_coefficient_cov_nb` on the sunlit
    cells in view U, σ-weighted irradiances w, count mc of
    :func:`~lightcurve.css.albedo.cap_cells_nb`) at the estimated attitude and misalignments,
    before the scale factors; zeros without a spread map (``have_sig`` False), without cells,
    or in the shadow; ``diag_only``: the variances only (what a diagonal R needs)."""
    N = az0.shape[0]
    Ra = np.zeros((N, N))
    if have_sig and mc > 0 and lit > 0.0:
        C = mrp2dcm_nb(x[0:3].copy())
        nE = np.empty((N, 3))
        hE = np.empty((N, 3))
        E = euler321_to_dcm_nb(np.array([theta, 0.0, 0.0]))   # ECI → Earth-fixed, R3(θ)
        for k in range(N):
            a = az0[k] + x[6 + N + 2 * k]
            e = el0[k] + x[6 + N + 2 * k + 1]
            nb = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
            nE[k] = mv3_nb(E, mtv3_nb(C, nb))
            hE[k] = mv3_nb(E, mtv3_nb(C, horizon_B[k]))
        Ra = cells_coefficient_cov_nb(U, w, mc, nE, cos_fov, hE, diag_only)
    return Ra


@numba.njit(cache=True)
def _thesis_update(x, P, y, prm, az0, el0, cos_fov, horizon_B, s_N, lit, theta, r_E, s_E,
                   cells_c, cells_n, cells_ra, lat_c, nlat, nlon, lon_w0, dlon, dlat_max,
                   nu_out, s_out, u_out, cells_sig, init):
    """O'Keefe §4.2-4.3 measurement update (see :func:`calibration_update_nb`)."""
    N = az0.shape[0]
    sig_v, floor_y, init_thr = prm[0], prm[18], prm[19]
    floor_rule = int(prm[20]) if prm.shape[0] > 20 else 0   # FLOOR_RULES index
    edge = prm[13]
    if prm.shape[0] > 21 and prm[21] > 0.5 and lit <= 0.0:   # no CSS update in the shadow
        for k in range(N):
            nu_out[k] = np.nan
            s_out[k] = np.nan
            u_out[k] = np.nan
        return 0, np.nan, 1.0
    U, a, w, mc, _ = cap_cells_nb(cells_c, cells_n, cells_ra, lat_c, nlat, nlon, lon_w0, dlon,
                                  dlat_max, r_E, s_E, cells_sig)
    h, H, D, A, cosd, _ = _measurement_cells_nb(x, az0, el0, cos_fov, horizon_B, s_N, lit,
                                                theta, U, a, mc, np.zeros(N))
    Ra = _albedo_spread_cov(x, az0, el0, cos_fov, horizon_B, lit, theta, U, w, mc,
                            cells_sig.shape[0] == cells_ra.shape[0])
    idx = np.empty(N, dtype=np.int64)
    m = 0
    for k in range(N):
        nu_out[k] = np.nan
        s_out[k] = np.nan
        u_out[k] = D[k] + A[k]
        if init.shape[0] == N and init[k] < 0.5:
            if y[k] > init_thr:
                init[k] = 1.0
            else:
                continue
        if floor_rule == 2:
            if h[k] <= floor_y:
                continue
        elif y[k] <= floor_y and not (floor_rule == 1 and h[k] > floor_y):
            continue
        if edge > 0.0 and lit > 0.0 and abs(cosd[k] - cos_fov[k]) < edge:
            continue   # Sun within ``edge`` (cosine) of the FOV cut-off (not in the thesis)
        idx[m] = k
        m += 1
    Hm, nu = _gather_rows(idx, m, H, y, h)
    R = np.zeros((m, m))
    for i in range(m):
        k = idx[i]
        gk = x[6 + k]
        for j in range(m):
            R[i, j] = gk * x[6 + idx[j]] * Ra[k, idx[j]]
        R[i, i] += (gk * sig_v) ** 2
    # per-sensor prior innovation statistics (the fault detector of §5.1)
    for i in range(m):
        k = idx[i]
        nu_out[k] = nu[i]
        s_out[k] = _innovation_variance(P, Hm[i], R[i, i])
    return _selected_update(x, P, nu, Hm, R, N, np.inf, 1.0)


@numba.njit(cache=True, inline="always")
def _near_plane(normal, v, margin):
    """True when the unit vector ``v`` lies within ``margin`` (cosine of the angle to the
    normal) of the plane with normal ``normal``; False for a zero normal (no plane)."""
    nn = normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]
    if nn <= 0.0:
        return False
    return abs(normal[0] * v[0] + normal[1] * v[1] + normal[2] * v[2]) < margin * np.sqrt(nn)


@numba.njit(cache=True)
def calibration_update_nb(x, P, y, prm, az0, el0, cos_fov, horizon_B, s_N, lit, theta, r_E,
                          s_E, cells_c, cells_n, cells_ra, lat_c, nlat, nlon, lon_w0, dlon,
                          dlat_max, nu_out, s_out, u_out, cells_sig=np.zeros(0),
                          init=np.zeros(0), c_out=np.zeros(0)):
    """CSS measurement update in place (see module docstring).

    prm: :meth:`CalibrationParams.as_array`.  nu_out, s_out (N,) receive every sensor's prior
    innovation y − h and its variance H P Hᵀ + R for sensors whose predicted output is above
    the threshold (NaN otherwise) — the per-sensor statistics of the fault detector.
    u_out (N,) receives each sensor's *gain-free* predicted irradiance ``D_κ + A_κ`` (direct
    plus modelled albedo, before the scale factor g_κ and the considered bias), NaN when the
    Sun is within the FOV-edge margin — the input of the dark-sensor test of
    :mod:`lightcurve.css.fault`, which must not depend on the estimated scale factor.
    c_out (N,), when given (length N), receives the part of ``s_out`` that is correlated in
    time — the albedo-grid representation error, which changes only as the spacecraft
    crosses the grid's cells (0 where the grid is the truth's; NaN where ``s_out`` is) — for
    the averaged-NIS detector's effective number of samples
    (:meth:`~lightcurve.css.fault.AveragedNISDetector.limit`).
    Returns (m used, NIS of the used set (NaN if none), inflation factor).

    With ``prm`` of :meth:`CalibrationParams.thesis_full` / ``thesis_reduced`` (thesis flag
    set) the update is O'Keefe's §4.2-4.3 as written instead: no gates or inflation, no
    FOV-edge margin unless ``prm`` sets one, updates in the shadow unless
    ``skip_in_shadow``; ``M = diag(Ĉ)`` so ``R = Ĉ_i² σ_V²`` plus, for the full filter, the albedo
    coefficient uncertainty ``M_α R_α M_αᵀ`` of eq. 4.30 (:func:`albedo_coefficient_cov_nb`
    with ``cells_sig`` = σ_j A_j of the filter's TOMS grid, full N×N); a sensor is processed
    once it has been initialised (an output above ``init_threshold`` once, §5.2; ``init`` (N,)
    flags, updated here) and while its measured output, its measured or predicted output, or
    its predicted output is above the noise floor (``floor_rule``, §4.2; see
    :class:`CalibrationParams`).
    """
    N = az0.shape[0]
    if prm.shape[0] > 17 and prm[17] > 0.5:
        return _thesis_update(x, P, y, prm, az0, el0, cos_fov, horizon_B, s_N, lit, theta,
                              r_E, s_E, cells_c, cells_n, cells_ra, lat_c, nlat, nlon, lon_w0,
                              dlon, dlat_max, nu_out, s_out, u_out, cells_sig, init)
    sig, floor, kalb, thr = prm[0], prm[1], prm[2], prm[3]
    gate, infl_max, gate_s = prm[4], prm[5], prm[6]
    margin = prm[13]
    # FOV-edge margin per sensor: base + 3σ of the normal's direction (misalignment)
    mk = np.empty(N)
    for k in range(N):
        ia = 6 + N + 2 * k
        sin_fov = np.sqrt(max(0.0, 1.0 - cos_fov[k] * cos_fov[k]))
        mk[k] = margin + prm[14] * sin_fov * np.sqrt(P[ia, ia] + P[ia + 1, ia + 1])
    want_sig = prm.shape[0] > 23 and prm[23] > 0.5
    U, a, w, mc, _ = cap_cells_nb(cells_c, cells_n, cells_ra, lat_c, nlat, nlon, lon_w0, dlon,
                                  dlat_max, r_E, s_E, cells_sig if want_sig else np.zeros(0))
    h, H, D, A, cosd, Aedge = _measurement_cells_nb(x, az0, el0, cos_fov, horizon_B, s_N, lit,
                                                    theta, U, a, mc, mk)
    s_B = mv3_nb(mrp2dcm_nb(x[0:3].copy()), s_N)
    in_scale = prm.shape[0] > 22 and prm[22] > 0.5
    want_c = c_out.shape[0] == N
    # the albedo map's spread (TOMS σ per cell): a time-correlated error of the modelled albedo
    Ra = (_albedo_spread_cov(x, az0, el0, cos_fov, horizon_B, lit, theta, U, w, mc,
                             cells_sig.shape[0] == cells_ra.shape[0], True)
          if want_sig else np.zeros((N, N)))
    idx = np.empty(N, dtype=np.int64)
    Rk = np.empty(N)
    Rc = np.zeros(N)
    m = 0
    for k in range(N):
        # output noise (inside the scale factor when the sensor model is eq. 2.21's)
        sk = x[6 + k] * sig if in_scale else sig
        # albedo-model uncertainty: relative part + the cells whose FOV membership is uncertain
        Rk[k] = (max(sk * sk, floor * floor) + (kalb * x[6 + k] * A[k]) ** 2
                 + (x[6 + k] * Aedge[k]) ** 2)
        if A[k] > 0.0:
            # albedo-grid representation error (coarse grid vs a fine one), see
            # albedo_grid_error: 1σ = k_grid A + a_grid
            Rc[k] = (x[6 + k] * (prm[15] * A[k] + prm[16])) ** 2
        Rc[k] += x[6 + k] * x[6 + k] * Ra[k, k]
        Rk[k] += Rc[k]
        nu_out[k] = np.nan
        if want_c:
            c_out[k] = np.nan
        s_out[k] = np.nan
        u_out[k] = np.nan
        if lit > 0.0 and abs(cosd[k] - cos_fov[k]) < mk[k]:
            continue  # Sun at the FOV edge: the cut-off makes the model unreliable
        if lit > 0.0 and cosd[k] > cos_fov[k] and _near_plane(horizon_B[k], s_B, margin):
            continue  # Sun at the structure horizon inside the FOV: the same kind of step
        u_out[k] = D[k] + A[k]
        pred = h[k] > thr
        # selection on the *prediction*: selecting on the noisy output (y > thr) would bias
        # the innovations of weakly lit sensors upwards; a clearly lit output (y > 3 thr)
        # is used as well, so that a badly predicted sensor cannot lock itself out
        if pred or (y[k] > 3.0 * thr and D[k] + A[k] > 0.0):
            v = _innovation_variance(P, H[k], Rk[k])
            if pred:
                nu_out[k] = y[k] - h[k]
                s_out[k] = v
                if want_c:
                    c_out[k] = Rc[k]
            if D[k] + A[k] > 0.0:
                if gate_s <= 0.0 or (y[k] - h[k]) ** 2 / v <= gate_s:
                    idx[m] = k
                    m += 1
    Hm, nu = _gather_rows(idx, m, H, y, h)
    R = np.zeros((m, m))
    for i in range(m):
        R[i, i] = Rk[idx[i]]
    return _selected_update(x, P, nu, Hm, R, N, gate, infl_max)


@numba.njit(cache=True)
def _consider_propagate(x, P, N, dt, tau, sig_b):
    """Gauss-Markov propagation of the considered albedo errors b (estimate stays 0)."""
    n = x.shape[0]
    if tau <= 0.0:
        return
    e = np.exp(-dt / tau)
    q = sig_b * sig_b * (1.0 - e * e)
    i0 = 6 + 3 * N
    for i in range(i0, n):
        x[i] *= e
        for j in range(n):
            P[i, j] *= e
            P[j, i] *= e
    for i in range(i0, n):
        P[i, i] += q


@numba.njit(cache=True)
def _propagate_sample_nb(x, P, W, j0, sub, dt, arw, rrw, qp, N, tau, sig_b):
    """Time update over one CSS sample interval ``dt`` (s), in place: ``sub`` gyro steps of
    :func:`~lightcurve.css.attitude_ekf.mrp_propagate_nb` with the samples ``W[j0:j0+sub]``,
    the random walk ``qp`` (density) on the scale-factor and misalignment variances, and the
    Gauss-Markov decay of the considered albedo errors (:func:`_consider_propagate`)."""
    h = dt / sub
    for j in range(sub):
        mrp_propagate_nb(x, P, W[j0 + j], h, arw, rrw, 0.0)
    if qp > 0.0:
        for i in range(6, 6 + 3 * N):
            P[i, i] += qp * dt
    _consider_propagate(x, P, N, dt, tau, sig_b)


def run_calibration_loop(t, Y, W, sun_N, lit, theta, r_E, s_E, QST, stvalid, x0, P0, prm,
                         az0, el0, cos_fov, horizon_B, cells_args, cells_sig=None, timings=None):
    """Whole-recording loop: propagate with the gyro, star-tracker update, CSS update.

    ``timings``: a dict to receive per-call wall times in µs (O'Keefe table 4.4's
    measurement): ``"propagation_us"`` one entry per gyro-rate propagation step (a sample's
    steps and its consider-state propagation timed together and shared equally among its
    steps) and ``"update_us"`` one per CSS measurement update (model, Jacobian and Joseph
    update; the star-tracker update is not included).

    ``W`` holds one gyro sample per interval (K,3), or ``sub`` samples per interval
    ((K−1)·sub, 3: propagation at the gyro rate, e.g. 10 Hz for 2 Hz CSS samples, §2.4).

    A Python loop over the compiled per-sample kernels (:func:`_propagate_sample_nb`, the
    star-tracker update, :func:`calibration_update_nb`; no separate whole-loop kernel to
    compile).  Returns X (K,n), Pdiag (K,n), P_end (n,n),
    nis (K,), m (K,), NU (K,N), S (K,N), nis_st (K,), U (K,N) gain-free predicted irradiance,
    C (K,N) the time-correlated part of S (see :func:`calibration_update_nb`).
    """
    K = t.shape[0]
    N = az0.shape[0]
    n = x0.shape[0]
    X = np.zeros((K, n))
    Pd = np.zeros((K, n))
    NIS = np.full(K, np.nan)
    NISST = np.full(K, np.nan)
    M = np.zeros(K, dtype=np.int64)
    NU = np.full((K, N), np.nan)
    SS = np.full((K, N), np.nan)
    UU = np.full((K, N), np.nan)
    CC = np.full((K, N), np.nan)
    x = x0.copy()
    P = P0.copy()
    arw, rrw, qp = prm[7], prm[8], prm[9]
    tau, sig_b, sig_st = prm[10], prm[11], prm[12]
    cons = _consider_mask(n, N)
    nu_k = np.empty(N)
    s_k = np.empty(N)
    u_k = np.empty(N)
    c_k = np.empty(N)
    sub = 1 if W.shape[0] == K else max(1, W.shape[0] // max(K - 1, 1))
    sig_cells = np.zeros(0) if cells_sig is None else np.ascontiguousarray(cells_sig)
    init = np.zeros(N) if prm.shape[0] > 17 and prm[17] > 0.5 else np.zeros(0)
    timed = timings is not None
    if timed:
        from time import perf_counter

        t_prop = np.zeros((K - 1) * sub) if K > 1 else np.zeros(0)
        t_upd = np.zeros(K)
    for k in range(K):
        if k > 0:
            if timed:
                t0 = perf_counter()
            dt = t[k] - t[k - 1]
            _propagate_sample_nb(x, P, W, (k - 1) * sub, sub, dt, arw, rrw, qp, N, tau, sig_b)
            if timed:
                t_prop[(k - 1) * sub:k * sub] = (perf_counter() - t0) * 1e6 / sub
        if stvalid[k]:
            nis_st, ok = star_tracker_update_nb(x, P, QST[k], sig_st, cons)
            if ok:
                NISST[k] = nis_st
        if timed:
            t0 = perf_counter()
        c_k[:] = np.nan   # the thesis update does not fill it
        m, nis, infl = calibration_update_nb(x, P, Y[k], prm, az0, el0, cos_fov, horizon_B,
                                             sun_N[k], lit[k], theta[k], r_E[k], s_E[k],
                                             *cells_args, nu_k, s_k, u_k, sig_cells, init,
                                             c_k)
        if timed:
            t_upd[k] = (perf_counter() - t0) * 1e6
        M[k] = m
        NIS[k] = nis
        NU[k] = nu_k
        SS[k] = s_k
        UU[k] = u_k
        CC[k] = c_k
        X[k] = x
        Pd[k] = np.diagonal(P)
    if timed:
        timings["propagation_us"] = t_prop
        timings["update_us"] = t_upd
    return X, Pd, P, NIS, M, NU, SS, NISST, UU, CC


# ---------------------------------------------------------------------------------------
# object layer
# ---------------------------------------------------------------------------------------
FLOOR_RULES = ("measured", "either", "predicted")
"""Noise-floor rules of the thesis update (:attr:`CalibrationParams.floor_rule`)."""


@dataclass(frozen=True)
class CalibrationParams:
    """Tuning of the calibration filter (dimensionless outputs, SI otherwise).

    sigma_css: CSS output noise 1σ; noise_floor: smallest measurement 1σ; albedo_frac:
    relative 1σ of the modelled albedo part; threshold: activity threshold; gate: NIS gate per
    measurement above which R is inflated; inflate_max; gate_sensor: per-sensor χ²₁ outlier
    gate on the prior innovation (0: off); arw, rrw: gyro σ_v (rad/√s), σ_u (rad/s^1.5);
    q_param: random-walk density on scale/misalignment states (1/s, rad²/s); consider_tau_s,
    consider_sigma: Gauss-Markov time constant (s) and 1σ of the considered albedo error;
    sigma_st_rad: star-tracker 1σ per axis (rad); fov_edge_margin: sensors whose predicted
    Sun cosine lies within this distance (plus ``fov_edge_sigmas`` × sin ψ × the 1σ direction
    uncertainty of the sensor normal, √(P_δαδα + P_δεδε)) of the FOV cut-off cos ψ are skipped (the step of
    the output at the edge, ≈ cos ψ, makes small attitude/misalignment errors look like huge
    innovations), and so are sensors whose Sun, inside the FOV, lies within
    ``fov_edge_margin`` of their structure-horizon plane (§2.2.1; the output steps there
    from the full n̂·ŝ to 0); use_albedo: full (True) or reduced (False)
    filter; albedo_grid_frac, albedo_grid_floor: representation error of a coarse albedo
    grid added to R as 1σ = g (albedo_grid_frac · A + albedo_grid_floor) for sensors with
    modelled albedo A > 0 (0 when the filter's grid is the truth's; values for a CERES grid
    against the 1° one from :func:`albedo_grid_error`); sigma_att0_rad, sigma_bias0, sigma_scale0, sigma_mis0_rad: initial 1σ.
    thesis: O'Keefe's §4.2-4.3 update as written (:func:`calibration_update_nb`); meas_floor:
    its noise floor (output units); init_threshold: output a sensor must exceed once before
    it is used (§5.2); floor_rule: a sample is used when its "measured" output, its
    measured or predicted output ("either"), or its "predicted" output is above
    ``meas_floor``; skip_in_shadow:
    no CSS update while the spacecraft is in the Earth's shadow (thesis update only; chapters
    4-5 do not say, the ch. 3 filters of eq. 3.1/3.31 update only outside it). The thesis
    update uses ``fov_edge_margin`` too (0 in :meth:`thesis_full`: the text has no FOV-edge
    rule); both switches exist for ablations. noise_in_scale: the output noise lies inside
    the scale factors, as in O'Keefe eq. 2.21 (``V = C C_κ (V_d + V_α + ν_V)``), so the noise
    1σ of sensor κ is ``g_κ sigma_css`` with the estimated total scale factor g_κ (our update;
    the thesis update always uses ``Ĉ_κ σ_V``, §4.2); False: additive noise after the scale
    factor (our own simulations). albedo_spread: our update adds the spread of the albedo
    map's coefficients (the TOMS σ per cell, O'Keefe eq. 4.30b; needs a (mean, std) map pair)
    to each sensor's R, as an error correlated in time (the draw of a cell stays for the
    run; the thesis update always uses it for the full filter).
    """

    sigma_css: float = 0.017
    noise_floor: float = 0.01
    albedo_frac: float = 0.1
    threshold: float = 0.05
    gate: float = 9.0
    inflate_max: float = 100.0
    gate_sensor: float = 25.0
    arw: float = 2.9e-5
    rrw: float = 1e-8
    q_param: float = 0.0
    consider_tau_s: float = 300.0
    consider_sigma: float = 0.003
    sigma_st_rad: float = float(np.radians(0.02))
    fov_edge_margin: float = 0.03
    fov_edge_sigmas: float = 2.0
    use_albedo: bool = True
    albedo_grid_frac: float = 0.0
    albedo_grid_floor: float = 0.0
    sigma_att0_rad: float = float(np.radians(1.0))
    sigma_bias0: float = float(np.radians(0.05))
    sigma_scale0: float = 0.3
    sigma_mis0_rad: float = float(np.radians(2.0))
    thesis: bool = False
    meas_floor: float = 0.0
    init_threshold: float = 0.0
    floor_rule: str = "measured"
    skip_in_shadow: bool = False
    noise_in_scale: bool = False
    albedo_spread: bool = False

    @classmethod
    def thesis_full(cls, grid: str = "1p25x1", **kw) -> "CalibrationParams":
        """O'Keefe §4.2 full filter (``variant = "thesis"``): σ_V = 0.05 + {0.01, 0.1, 0.4}
        for the {1°×1.25°, 5°×5°, 10°×10°} grid (§4.4.3), noise floor 2 × 0.05 (§4.2),
        initialisation above 0.4 (§5.2), initial 3σ 0.9 and 3° (tables 4.1-4.3), no
        considered albedo bias (the albedo model's coefficient uncertainty enters R).

        The noise floor: §4.2 drops "CSS measurement values" below it, while §5.2.1 has a
        failed sensor flagged "once the expected observations for the failed sensor rise
        above the noise floor", and tables 5.1-5.2 detect every initialised sensor that
        fails off (output 0, below any floor). The thesis variant applies the floor to the
        expected (predicted) output (``floor_rule = "predicted"``), in chapters 4 and 5
        alike. Selecting on the measured output instead ("measured", or "either": measured
        or predicted) keeps only the upper tail of the noise where the prediction is below
        the floor (in the Earth's shadow, on unlit sensors), which biases the normalised
        innovations upwards; both stay selectable for ablations (docs/measurements.md)."""
        from .okeefe2015 import CALIBRATION, CSS_SIM

        base = dict(thesis=True, sigma_css=CSS_SIM["noise_sigma"]
                    + CALIBRATION["sigma_v_increase"][grid],
                    meas_floor=CALIBRATION["noise_floor_sigmas"] * CSS_SIM["noise_sigma"],
                    init_threshold=CALIBRATION["init_threshold"], use_albedo=True,
                    floor_rule="predicted", fov_edge_margin=0.0, skip_in_shadow=False,
                    consider_sigma=0.0, consider_tau_s=0.0, q_param=0.0,
                    sigma_scale0=CALIBRATION["scale_sigma"],
                    sigma_mis0_rad=float(np.radians(CALIBRATION["misalignment_sigma_deg"])))
        base.update(kw)
        return cls(**base)

    @classmethod
    def thesis_reduced(cls, **kw) -> "CalibrationParams":
        """O'Keefe §4.3 reduced filter: no albedo model; the albedo irradiance a considered
        constant bias per sensor (eq. 4.36) with σ 0.1 (the value of §3.2.3), σ_V 0.05."""
        from .okeefe2015 import CSS_SIM, ECKF_TUNING

        base = dict(sigma_css=CSS_SIM["noise_sigma"], use_albedo=False,
                    consider_sigma=ECKF_TUNING["sigma_v_alpha"], consider_tau_s=0.0)
        base.update(kw)
        return cls.thesis_full(**base)

    @classmethod
    def reduced(cls, **kw) -> "CalibrationParams":
        """§4.3 defaults: no albedo model; albedo as a considered bias of 1σ 0.05 full scale
        correlated over 300 s (Earth-facing sensors see up to ~0.27 at 400 km)."""
        base = dict(use_albedo=False, consider_sigma=0.05, consider_tau_s=300.0)
        base.update(kw)
        return cls(**base)

    def as_array(self) -> np.ndarray:
        if self.floor_rule not in FLOOR_RULES:
            raise ValueError(f"floor_rule must be one of {', '.join(FLOOR_RULES)}, got "
                             f"{self.floor_rule!r}")
        return np.array([self.sigma_css, self.noise_floor, self.albedo_frac, self.threshold,
                         self.gate, self.inflate_max, self.gate_sensor, self.arw, self.rrw,
                         self.q_param, self.consider_tau_s, self.consider_sigma,
                         self.sigma_st_rad, self.fov_edge_margin,
                         self.fov_edge_sigmas, self.albedo_grid_frac,
                         self.albedo_grid_floor, float(self.thesis), self.meas_floor,
                         self.init_threshold, float(FLOOR_RULES.index(self.floor_rule)),
                         float(self.skip_in_shadow), float(self.noise_in_scale),
                         float(self.albedo_spread)], dtype=float)

    def for_gyro(self, spec) -> "CalibrationParams":
        """A copy with the ARW/RRW of a :class:`~lightcurve.css.gyro.GyroSpec`."""
        from dataclasses import replace

        return replace(self, arw=float(spec.arw), rrw=float(spec.rrw))


def state_layout(n_sensors: int) -> dict:
    """Slices of the state vector: sigma, bias, scale, misalignment ((N,2) via reshape),
    consider (albedo error)."""
    N = int(n_sensors)
    return {"sigma": slice(0, 3), "bias": slice(3, 6), "scale": slice(6, 6 + N),
            "misalignment": slice(6 + N, 6 + 3 * N), "consider": slice(6 + 3 * N, 6 + 4 * N),
            "n": 6 + 4 * N}


def initial_state(css: CSSArray, q0, params: CalibrationParams):
    """x0 (nominal calibration, zero bias, attitude q0) and diagonal P0."""
    N = css.n_sensors
    L = state_layout(N)
    x0 = np.zeros(L["n"])
    x0[L["sigma"]] = quat_to_mrp(np.asarray(q0, dtype=float))
    x0[L["scale"]] = 1.0
    p = np.zeros(L["n"])
    p[L["sigma"]] = params.sigma_att0_rad ** 2 / 16.0
    p[L["bias"]] = params.sigma_bias0 ** 2
    p[L["scale"]] = params.sigma_scale0 ** 2
    p[L["misalignment"]] = params.sigma_mis0_rad ** 2
    p[L["consider"]] = params.consider_sigma ** 2
    return x0, np.diag(p)


@dataclass
class CalibrationResult:
    """Filter output. t (K,); x (K,n) state history; p_diag (K,n); P_end (n,n); nis (K,) NIS
    of the CSS update (NaN when none); n_used (K,); innov, innov_var (K,N) per-sensor prior
    innovations and variances (NaN when not evaluated); nis_st (K,) star-tracker NIS;
    layout: :func:`state_layout`; u_model (K,N) gain-free predicted irradiance D_κ + A_κ
    (NaN at the FOV edge; see :func:`calibration_update_nb`); innov_var_corr (K,N) the part
    of innov_var that is correlated in time (albedo-grid representation error)."""

    t: np.ndarray
    x: np.ndarray
    p_diag: np.ndarray
    P_end: np.ndarray
    nis: np.ndarray
    n_used: np.ndarray
    innov: np.ndarray
    innov_var: np.ndarray
    nis_st: np.ndarray
    layout: dict
    u_model: np.ndarray | None = None
    innov_var_corr: np.ndarray | None = None

    def correlated_share(self) -> np.ndarray:
        """(K,N) share of each innovation variance that is correlated in time (0-1; NaN
        where the sensor was not evaluated; 0 everywhere when not recorded)."""
        if self.innov_var_corr is None:
            return np.where(np.isfinite(self.innov_var), 0.0, np.nan)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.clip(self.innov_var_corr / self.innov_var, 0.0, 1.0)

    def scale(self):
        """(K,N) estimated total scale factors g_κ."""
        return self.x[:, self.layout["scale"]]

    def misalignment_rad(self):
        """(K,N,2) estimated (δα, δε), rad."""
        m = self.x[:, self.layout["misalignment"]]
        return m.reshape(m.shape[0], -1, 2)

    def sigma3_scale(self):
        return 3.0 * np.sqrt(self.p_diag[:, self.layout["scale"]])

    def sigma3_misalignment_rad(self):
        v = 3.0 * np.sqrt(self.p_diag[:, self.layout["misalignment"]])
        return v.reshape(v.shape[0], -1, 2)


def run_calibration(css: CSSArray, t, Y, gyro, sun_N, lit, r_I_m, epoch_utc, *,
                    params: CalibrationParams = CalibrationParams(), albedo="builtin",
                    q_star=None, star_valid=None, q0=None, theta=None,
                    timings=None) -> CalibrationResult:
    """Run the full (``params.use_albedo``) or reduced calibration filter on a recording.

    css: nominal sensor set; t (K,) s; Y (K,N) outputs; gyro (K,3) rad/s; sun_N (K,3) unit
    Sun directions (ECI/GCRS); lit (K,) lit fractions; r_I_m (K,3) spacecraft positions (ECI,
    m); epoch_utc: scenario epoch (for the Earth rotation angle); albedo: "builtin" (10°
    zonal), an :class:`AlbedoMap`, an :class:`AlbedoCells`, or a (mean, std) pair of TOMS
    :class:`AlbedoMap` (the std enters R in the thesis variant); gyro (K,3), or (K−1)·sub
    samples for sub propagation steps per sample; q_star (K,4) star-tracker
    quaternions (inertial→body) with star_valid (K,) flags; q0 initial attitude (defaults to
    the first star-tracker sample); timings: a dict receiving per-call times
    (:func:`run_calibration_loop`).
    """
    t = np.ascontiguousarray(t, dtype=float)
    K = t.size
    Y = np.ascontiguousarray(Y, dtype=float)
    N = css.n_sensors
    if Y.shape != (K, N):
        raise ValueError(f"Y must have shape ({K}, {N})")
    W = np.ascontiguousarray(gyro, dtype=float)
    sun_N = np.ascontiguousarray(sun_N, dtype=float)
    r_I = np.ascontiguousarray(r_I_m, dtype=float)
    lit = np.ascontiguousarray(np.broadcast_to(lit, (K,)), dtype=float)
    if theta is None:
        theta = earth_rotation_angle(epoch_utc, t)
    theta = np.ascontiguousarray(theta, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    r_E = np.column_stack([c * r_I[:, 0] + s * r_I[:, 1], -s * r_I[:, 0] + c * r_I[:, 1], r_I[:, 2]])
    s_E = np.column_stack([c * sun_N[:, 0] + s * sun_N[:, 1], -s * sun_N[:, 0] + c * sun_N[:, 1],
                           sun_N[:, 2]])
    sig_area = None
    if not params.use_albedo:
        cells = AlbedoCells.none()
    elif isinstance(albedo, tuple):
        from .albedo import cell_areas_m2

        cells = _cells_cache(albedo[0])
        sig_area = (cell_areas_m2(albedo[1].lat_edges_rad, albedo[1].lon_edges_rad)
                    * albedo[1].values).reshape(-1)
    elif isinstance(albedo, AlbedoCells):
        cells = albedo
    elif isinstance(albedo, AlbedoMap):
        cells = AlbedoCells.from_map(albedo)
    elif albedo == "builtin" or albedo is None:
        cells = AlbedoCells.from_map(builtin_albedo_map(10.0))
    else:
        raise ValueError("albedo must be 'builtin', an AlbedoMap or AlbedoCells")
    if q_star is None:
        QS = np.zeros((K, 4))
        QS[:, 0] = 1.0
        sv = np.zeros(K, dtype=bool)
    else:
        QS = np.ascontiguousarray(q_star, dtype=float)
        sv = np.ones(K, dtype=bool) if star_valid is None else np.asarray(star_valid, dtype=bool)
    if q0 is None:
        if not sv.any():
            raise ValueError("q0 is required when there is no star-tracker sample")
        q0 = QS[np.flatnonzero(sv)[0]]
    x0, P0 = initial_state(css, q0, params)
    az0, el0 = normal_to_azel(css.normals)
    out = run_calibration_loop(t, Y, W, sun_N, lit, theta, r_E, s_E, QS, sv, x0, P0,
                               params.as_array(), np.ascontiguousarray(az0),
                               np.ascontiguousarray(el0), np.cos(css.fov_half_angle_rad),
                               np.ascontiguousarray(css.horizon_normals), cells.args(),
                               sig_area, timings)
    X, Pd, Pend, NIS, M, NU, SS, NISST, UU, CC = out
    return CalibrationResult(t, X, Pd, Pend, NIS, M, NU, SS, NISST, state_layout(N), UU, CC)


_CELLS: dict = {}


def _cells_cache(amap: AlbedoMap) -> AlbedoCells:
    key = id(amap)
    if key not in _CELLS:
        _CELLS[key] = (AlbedoCells.from_map(amap), amap)
    return _CELLS[key][0]


# The sub-cell size (deg) on which the robust calibration filter integrates a coarse albedo
# grid: finer sub-cells hardly reduce the 10° map's irradiance error at 400 km any further
# (docs/measurements.md, "Coarse TOMS grids").
ALBEDO_SUBCELL_DEG = 2.5


def albedo_grid_error(coarse: AlbedoCells, fine: AlbedoCells, *, altitude_m=400e3,
                      fov_half_angle_deg=70.0, n_geometries=300, n_sensors=8, seed=0):
    """Representation error of a coarse albedo grid, as the 1σ model ``k A + a``.

    The coarse grid's albedo irradiance A_c on a sensor (cell-centre geometry, cell-mean
    reflectivity) differs from the fine grid's A_f because the cosine factors and the
    reflectivity vary inside a cell (at 400 km a 10° cell is ≈ 1100 km wide while the visible
    cap has a radius of ≈ 20°) and because whole cells enter or leave the FOV.  This error is
    a *model* error of the filter; we represent it as extra measurement noise whose 1σ grows
    with the modelled albedo.  Estimated empirically: random spacecraft positions (uniform on
    the sphere at ``altitude_m``), Sun 0-90° from the local zenith, random sensor normals;
    (k, a) fitted by least squares to d² = (A_c − A_f)² ≈ (k A_c + a)² over the samples
    with A_c > 0, in bins of A_c (binned RMS, so that a few outliers do not dominate).
    An assumption: the error is treated as white, although it is correlated over the time
    the spacecraft needs to cross a coarse cell (≈ 140 s for 10°).

    Returns (k, a) — dimensionless, irradiance in units of the solar one.
    """
    rng = np.random.default_rng(seed)
    N = int(n_sensors)
    cf = np.full(N, np.cos(np.radians(fov_half_angle_deg)))
    hz = np.zeros((N, 3))
    Ac, Af = [], []
    for _ in range(int(n_geometries)):
        lat = np.arcsin(rng.uniform(-1.0, 1.0))
        lon = rng.uniform(-np.pi, np.pi)
        up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
        east = np.array([-np.sin(lon), np.cos(lon), 0.0])
        a = rng.uniform(0.0, 0.5 * np.pi)
        s_E = np.cos(a) * up + np.sin(a) * east
        r_E = (6378137.0 + altitude_m) * up
        nE = rng.normal(size=(N, 3))
        nE /= np.linalg.norm(nE, axis=1, keepdims=True)
        for cells, acc in ((coarse, Ac), (fine, Af)):
            V, _, _ = albedo_vectors_nb(*cells.args(), r_E, s_E, nE, cf, hz, np.zeros(N))
            acc.append(np.sum(nE * V, axis=1))
    Ac = np.concatenate(Ac)
    Af = np.concatenate(Af)
    m = Ac > 0.0
    if m.sum() < 20:
        return 0.0, 0.0
    edges = np.quantile(Ac[m], np.linspace(0.0, 1.0, 11))
    xb, yb = [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        b = m & (Ac >= lo) & (Ac <= hi)
        if b.sum() >= 5:
            xb.append(np.mean(Ac[b]))
            yb.append(np.sqrt(np.mean((Ac[b] - Af[b]) ** 2)))
    xb, yb = np.array(xb), np.array(yb)
    # linear fit of the binned RMS: rms ≈ k A + a (non-negative coefficients)
    from scipy.optimize import nnls

    coef, _ = nnls(np.column_stack([xb, np.ones_like(xb)]), yb)
    return float(coef[0]), float(coef[1])


# ---------------------------------------------------------------------------------------
# §4.4 case: one orbit, uncontrolled, dual pyramid, scale factors dispersed 30 %
# ---------------------------------------------------------------------------------------
@dataclass
class CalibrationCase:
    """A simulated calibration case (truth + measurements).

    css_nominal: the flight-software model; t, Y, gyro (K,3), gyro_bias (K,3) true bias,
    q_true (K,4), sun_N, lit, r_I_m; scale_true (N,) true g_κ; misalignment_true (N,2) rad;
    q_star (K,4), star_valid (K,) star-tracker samples; epoch_utc; info: truth info dict.
    """

    css_nominal: CSSArray
    t: np.ndarray
    Y: np.ndarray
    gyro: np.ndarray
    gyro_bias: np.ndarray
    q_true: np.ndarray
    sun_N: np.ndarray
    lit: np.ndarray
    r_I_m: np.ndarray
    scale_true: np.ndarray
    misalignment_true: np.ndarray
    q_star: np.ndarray
    star_valid: np.ndarray
    epoch_utc: str
    info: dict = field(default_factory=dict)


ORBIT_PERIOD_400KM_S = 2.0 * np.pi * np.sqrt((6378137.0 + 400e3) ** 3 / 3.986004418e14)


def simulate_calibration_case(rng, *, css: CSSArray | None = None, duration_s=None, dt_s=1.0,
                              albedo_truth="builtin", scale_sigma=0.3,
                              misalignment_sigma_deg=2.0, noise_sigma=0.017, gyro="tactical",
                              rate_sigma_deg_s=1.0, star_period_s=10.0,
                              sigma_st_rad=float(np.radians(0.02)),
                              epoch_utc="2015-03-01T00:00:00Z") -> CalibrationCase:
    """Simulate the §4.4 case: 400 km polar orbit, uncontrolled tumbling (initial rates
    N(0, rate_sigma²) per axis), dual pyramid (70° FOV) by default, total scale factors
    N(1, scale_sigma²) (clipped to ≥ 0.05 by the truth model), misalignments N(0,
    misalignment_sigma²) per angle, CSS noise, Earth albedo (``albedo_truth``: "builtin",
    an AlbedoMap, or False), Farrenkopf gyro of the given grade (no scale/misalignment
    errors) and a star tracker every ``star_period_s`` s (0: none) with 1σ ``sigma_st_rad``
    per axis.  ``duration_s`` defaults to one orbit (5553 s).
    """
    from .configurations import dual_pyramid
    from .gyro import gyro_grade, simulate_gyro
    from .truth import CSSScenario, Dispersions, simulate_css

    g = as_generator(rng)
    # our robust calibration set-up (70° FOV, no structure horizon), not the thesis ch. 4 one
    css = dual_pyramid(fov_half_angle_deg=70.0) if css is None else css
    dur = ORBIT_PERIOD_400KM_S if duration_s is None else float(duration_s)
    alb = None if albedo_truth == "builtin" else albedo_truth
    disp = Dispersions(rate_sigma_deg_s=rate_sigma_deg_s, css_scale_common_sigma=0.0,
                       css_scale_sigma=scale_sigma,
                       css_misalignment_sigma_deg=misalignment_sigma_deg,
                       css_noise_sigma=noise_sigma)
    sc = CSSScenario(css, estimator="wavg", gyro=None, controlled=False, duration_s=dur, dt_s=dt_s,
                     epoch_utc=epoch_utc, albedo=alb, dispersions=disp)
    r = simulate_css(sc, g)
    spec = gyro_grade(gyro) if isinstance(gyro, str) else gyro
    w_meas, bias = simulate_gyro(r.omega, dt_s, spec, g, detailed=False)
    K = r.t.size
    sv = np.zeros(K, dtype=bool)
    if star_period_s > 0:
        step = max(1, int(round(star_period_s / dt_s)))
        sv[::step] = True
    dq = rotvec_to_quat(g.normal(0.0, sigma_st_rad, (K, 3)))
    qst = quat_mult(dq, r.q)
    scale_true = r.info["css_scale_common"] * np.asarray(r.info["css_scale_individual"])
    return CalibrationCase(css, r.t, r.y, w_meas, bias, r.q, r.info["sun_I_hat"], r.lit,
                           r.info["r_I_m"], scale_true, np.asarray(r.info["css_misalignment_rad"]),
                           qst, sv, epoch_utc, {"spec": spec, **r.info})


def acceptance_summary(case: CalibrationCase, res: CalibrationResult, *, lit_threshold=0.3):
    """End-of-run calibration summary per sensor.

    Returns a dict with ``saw_sun`` (N,) (direct-Sun output above ``lit_threshold`` at some
    sample), ``exposure_s`` (N,) (time with the direct output above ``lit_threshold``), final ``scale_err``, ``scale_3sigma``, ``mis_err_deg`` (N,2), ``mis_3sigma_deg``
    (N,2), the ``attitude_err_deg`` history and ``bias_err`` (K,3) rad/s.
    """
    from ..rotations import attitude_error_angle, mrp_to_quat

    N = case.css_nominal.n_sensors
    true_css = case.css_nominal.with_errors(scale_individual=case.scale_true,
                                            misalignment_rad=case.misalignment_true)
    s_B = np.einsum("kij,kj->ki", _dcm_batch(case.q_true), case.sun_N)
    direct = true_css.signals(s_B, case.lit, clip=True)
    saw = np.any(direct > lit_threshold, axis=0)
    dt = float(np.median(np.diff(case.t))) if case.t.size > 1 else 0.0
    exposure_s = np.sum(direct > lit_threshold, axis=0) * dt
    g_hat = res.scale()[-1]
    m_hat = res.misalignment_rad()[-1]
    q_hat = mrp_to_quat(res.x[:, 0:3])
    return {
        "saw_sun": saw,
        "exposure_s": exposure_s,
        "scale_err": case.scale_true - g_hat,
        "scale_3sigma": res.sigma3_scale()[-1],
        "mis_err_deg": np.degrees(case.misalignment_true - m_hat),
        "mis_3sigma_deg": np.degrees(res.sigma3_misalignment_rad()[-1]),
        "attitude_err_deg": np.degrees(attitude_error_angle(case.q_true, q_hat)),
        "bias_err": case.gyro_bias - res.x[:, 3:6],
        "n_sensors": N,
    }


def _dcm_batch(q):
    from ..rotations import quat_to_dcm

    return quat_to_dcm(q)


def params_dict(p: CalibrationParams) -> dict:
    """Parameters as a plain dict (for reports)."""
    return asdict(p)


# ---------------------------------------------------------------------------------------
# O'Keefe (2015) §4.4 in the thesis's own set-up (thesis variant) and tables 4.1-4.3
# ---------------------------------------------------------------------------------------
def simulate_thesis_calibration_case(rng, configuration="dual_pyramid", *, duration_s=None,
                                     albedo="toms", star_period_s=10.0,
                                     sigma_st_rad=float(np.radians(0.02)),
                                     controlled=False) -> CalibrationCase:
    """§4.4: one orbit (92.5 min, §2.4) of the uncontrolled tumbling spacecraft of §2.4 with
    individual scale factors N(1, 0.3²) ("distributed by 30%", no common error — the filter
    estimates each sensor's total factor), misalignments N(0, 1°²), CSS noise 0.05 at 2 Hz,
    the intermediate gyro at 10 Hz, TOMS 1°×1.25° albedo with its spread; the star tracker's
    rate and accuracy are left open by §4.1-4.2 (our choice: every 10 s, 0.02° per axis).

    ``controlled``: the spacecraft of §5.2.2 instead, keeping its +Z axis on the Sun with the
    control law of §3.3.2 (eq. 3.64); which Sun estimate drives the controller §5.2.2 leaves
    open: the thesis-variant sun-line EKF of ch. 3 (the most accurate of §3.3.2)."""
    from .experiments import thesis_scenario
    from .okeefe2015 import CALIBRATION, ORBIT

    g = as_generator(rng)
    g_truth, g_st = g.spawn(2)
    sc = thesis_scenario(configuration, "ekf" if controlled else "wavg", variant="thesis",
                         gyro="intermediate", controlled=bool(controlled),
                         duration_s=ORBIT["period_s_quoted"] if duration_s is None else duration_s,
                         albedo=albedo,
                         sim={"scale_individual_sigma": CALIBRATION["scale_sigma"],
                              "scale_common_max": 0.0,
                              "misalignment_sigma_deg": CALIBRATION["misalignment_sigma_deg"]})
    from .truth import simulate_css

    r = simulate_css(sc, g_truth)
    K = r.t.size
    sv = np.zeros(K, dtype=bool)
    if star_period_s > 0:
        step = max(1, int(round(star_period_s / sc.dt_s)))
        sv[::step] = True
    dq = rotvec_to_quat(g_st.normal(0.0, sigma_st_rad, (K, 3)))
    qst = quat_mult(dq, r.q)
    scale_true = r.info["css_scale_common"] * np.asarray(r.info["css_scale_individual"])
    return CalibrationCase(sc.css, r.t, r.y, r.info["gyro_substeps"], np.zeros((K, 3)), r.q,
                           r.info["sun_I_hat"], r.lit, r.info["r_I_m"], scale_true,
                           np.asarray(r.info["css_misalignment_rad"]), qst, sv, sc.epoch_utc,
                           {"spec": None, **r.info})


_SETUPS: dict = {}


def thesis_filter_setup(name: str, albedo_dir=None):
    """Parameters and albedo input of one thesis-variant calibration filter of §4.4 (tables
    4.1-4.4): ``name`` "1p25x1", "5x5" or "10x10" — the full filter with that TOMS grid
    (mean and spread, §2.1.2.1) — or "reduced" (no albedo model); intermediate gyro (§4.4).
    Returns ``(CalibrationParams, albedo)`` for :func:`run_calibration`."""
    from .albedo import load_toms
    from .gyro import gyro_grade

    key = ("thesis", name, None if albedo_dir is None else str(albedo_dir))
    if key not in _SETUPS:   # one map object per grid: run_calibration caches its cells by map
        if name == "reduced":
            prm, alb = CalibrationParams.thesis_reduced(), "builtin"
        else:
            prm, alb = CalibrationParams.thesis_full(name), load_toms(name, albedo_dir)
        _SETUPS[key] = (prm.for_gyro(gyro_grade("intermediate")), alb)
    return _SETUPS[key]


def albedo_subdivision(amap: AlbedoMap, subcell_deg: float = ALBEDO_SUBCELL_DEG) -> int:
    """How many sub-cells per side (:meth:`AlbedoMap.subdivided`) bring ``amap``'s widest
    cell down to ``subcell_deg`` degrees (1 for a map already that fine)."""
    widest = max(float(np.max(np.diff(amap.lat_edges_rad))),
                 float(np.max(np.diff(amap.lon_edges_rad))))
    return max(1, int(np.ceil(np.degrees(widest) / float(subcell_deg) - 1e-9)))


def robust_filter_setup(name: str, albedo_dir=None):
    """Our calibration filter (``variant = "robust"``) on the §4.4 thesis case, with the CSS
    noise of §2.4 (0.05) inside the scale factors as in the case's sensor model (eq. 2.21,
    ``noise_in_scale``) and the intermediate gyro: ``name`` "1p25x1", "5x5" or "10x10" —
    the full filter with that TOMS grid (the mean map, with the map's spread in R as a
    time-correlated error, ``albedo_spread``) — or "reduced"
    (:meth:`CalibrationParams.reduced`).  Returns ``(CalibrationParams, albedo)`` for
    :func:`run_calibration`.

    A coarse grid keeps its values (the filter knows the 5° or 10° map, no more) but its
    irradiance is integrated over sub-cells of at most :data:`ALBEDO_SUBCELL_DEG`
    (:func:`albedo_subdivision`): one cell centre misrepresents a cell as wide as the
    altitude.  The spread term then treats the sub-cells as independent draws, as the
    truth does its 1°×1.25° cells.  The grid's remaining representation error
    (:func:`albedo_grid_error` of the sub-divided map against the 1°×1.25° one, 60° FOV,
    §2.1.3) enters R.  The thesis variant (:func:`thesis_filter_setup`) uses cell centres."""
    from .albedo import load_toms
    from .gyro import gyro_grade
    from .okeefe2015 import CSS_SIM

    key = ("robust", name, None if albedo_dir is None else str(albedo_dir))
    if key not in _SETUPS:
        if name == "reduced":
            prm, alb = CalibrationParams.reduced(sigma_css=CSS_SIM["noise_sigma"],
                                                 noise_in_scale=True), "builtin"
        else:
            pair = load_toms(name, albedo_dir)
            n = albedo_subdivision(pair[0])
            pair = (pair[0].subdivided(n), pair[1].subdivided(n))
            cells = AlbedoCells.from_map(pair[0])
            k, a = 0.0, 0.0
            if name != "1p25x1":
                fine = AlbedoCells.from_map(load_toms("1p25x1", albedo_dir)[0])
                k, a = albedo_grid_error(cells, fine, fov_half_angle_deg=60.0)
            prm = CalibrationParams(sigma_css=CSS_SIM["noise_sigma"], albedo_grid_frac=k,
                                    albedo_grid_floor=a, noise_in_scale=True,
                                    albedo_spread=True)
            alb = pair
        _SETUPS[key] = (prm.for_gyro(gyro_grade("intermediate")), alb)
    return _SETUPS[key]


def calibration_filter_setup(variant: str, name: str, albedo_dir=None):
    """:func:`thesis_filter_setup` (``variant`` "thesis") or :func:`robust_filter_setup`
    ("robust") of the filter ``name``."""
    if variant == "thesis":
        return thesis_filter_setup(name, albedo_dir)
    if variant == "robust":
        return robust_filter_setup(name, albedo_dir)
    raise ValueError(f"variant must be 'thesis' or 'robust', got {variant!r}")


def initialised_sensors(Y) -> np.ndarray:
    """(N,) bool: the sensors whose output (Y (K,N), full scale 1) exceeded
    ``CALIBRATION["init_threshold"]`` (0.4) at least once — O'Keefe §5.2's rule for a sensor
    being initialised in the filter; only those count in tables 4.1-4.3 and 5.1-5.2."""
    from .okeefe2015 import CALIBRATION

    return np.any(np.asarray(Y) > CALIBRATION["init_threshold"], axis=0)


def thesis_calibration_table(case: CalibrationCase, filters=("1p25x1", "5x5", "10x10", "reduced"),
                             *, albedo_dir=None, variant="thesis") -> dict:
    """Tables 4.1-4.3 for one case: for each filter (the full filter with the TOMS grid named,
    or "reduced"), the largest and smallest final 3σ of the scale factor C and of the
    misalignments θ (azimuth) and φ (elevation) over the sensors that were initialised
    (an output above 0.4 once, §5.2), the mean misalignment 3σ over them
    (``mean_theta_phi_deg``), and the fraction of final errors inside 3σ.

    ``variant``: "thesis" or "robust" (our filters on the same case,
    :func:`calibration_filter_setup`); the same sensors count as initialised in both."""
    init = initialised_sensors(case.Y)
    out = {}
    for f in filters:
        prm, alb = calibration_filter_setup(variant, f, albedo_dir)
        res = run_calibration(case.css_nominal, case.t, case.Y, case.gyro, case.sun_N, case.lit,
                              case.r_I_m, case.epoch_utc, params=prm, albedo=alb,
                              q_star=case.q_star, star_valid=case.star_valid)
        c3 = res.sigma3_scale()[-1][init]
        m3 = np.degrees(res.sigma3_misalignment_rad()[-1][init])
        err_c = np.abs(case.scale_true - res.scale()[-1])[init]
        err_m = np.degrees(np.abs(case.misalignment_true - res.misalignment_rad()[-1]))[init]
        out[f] = {"c": (float(c3.max()), float(c3.min())),
                  "theta_deg": (float(m3[:, 0].max()), float(m3[:, 0].min())),
                  "phi_deg": (float(m3[:, 1].max()), float(m3[:, 1].min())),
                  "mean_theta_phi_deg": (float(m3[:, 0].mean()), float(m3[:, 1].mean())),
                  "initialised": int(init.sum()),
                  "inside_3sigma": float(np.mean(np.concatenate([err_c <= c3,
                                                                 (err_m <= m3).ravel()])))}
    return out


def _calibration_mc_case(arg):
    """One Monte Carlo case of :func:`thesis_calibration_monte_carlo` (a pool task)."""
    seed_seq, config, filters, variants, albedo_dir, duration_s = arg
    case = simulate_thesis_calibration_case(seed_seq, config, duration_s=duration_s)
    return {v: thesis_calibration_table(case, filters, albedo_dir=albedo_dir, variant=v)
            for v in variants}


def thesis_calibration_monte_carlo(config="dual_pyramid", filters=("1p25x1", "5x5", "10x10",
                                                                   "reduced"),
                                   n_runs=300, *, seed=4, variants=("thesis", "robust"),
                                   workers=1, progress=None, albedo_dir=None,
                                   duration_s=None) -> dict:
    """Monte Carlo of tables 4.1-4.3 (O'Keefe 2015 figs. 4.4, 4.7, 4.10: 300 runs): case i
    (i = 1…``n_runs``) is :func:`simulate_thesis_calibration_case` seeded ``(seed, i)`` for
    ``config``, and each variant's filters run on it (:func:`thesis_calibration_table`).
    ``workers`` local processes (:func:`lightcurve.studies.runner.map_in_pool`, numba threads
    sized to the cores); ``progress``: called after each case; ``duration_s``: the case
    length (None: one orbit, as in the thesis).  Returns {variant: {filter: [table entry of
    each case]}} in case order."""
    from ..studies.runner import map_in_pool

    filters, variants = tuple(filters), tuple(variants)
    jobs = [(np.random.SeedSequence([int(seed), 1 + i]), config, filters, variants, albedo_dir,
             duration_s) for i in range(int(n_runs))]
    runs = map_in_pool(_calibration_mc_case, jobs, int(workers), progress)
    return {v: {f: [r[v][f] for r in runs] for f in filters} for v in variants}
