"""CSS fault detection by averaged per-sensor NIS (O'Keefe 2015, §5.1, tables 5.1-5.2).

Each sensor κ contributes, at every sample where its predicted output exceeds the activity
threshold (selection on the prediction, which does not depend on the current noise), the scalar normalised innovation squared ``ε_κ = ν_κ²/S_κ`` with
``ν_κ = y_κ − h_κ(x̂⁻)`` and ``S_κ = H_κ P⁻ H_κᵀ + R_κ`` (prior, from
:func:`lightcurve.css.calibration.calibration_update_nb`).  For a healthy sensor and a
consistent filter ``ε_κ ~ χ²₁``; the trailing average of its last ``K`` valid values then
satisfies ``K ε̄ ~ χ²_K`` (O'Keefe eq. 5.5-5.11; :func:`lightcurve.estimation.chi2_interval`),
and the sensor is declared failed when ``ε̄`` exceeds the upper bound of the two-sided
``prob`` interval (the threshold).  Selecting on the prediction matters twice: a dead sensor never reads above the threshold
(only its predicted output exposes it), and selecting on the measured output would bias the
statistic of weakly lit healthy sensors upwards (false alarms).  A sensor stuck at a high
value while predicted dark is therefore seen only once it is predicted lit again.

Failure modes injected at ``t_fail`` (default 1950 s, tables 5.1-5.2):

* ``off``    — the output is 0 from then on;
* ``stuck``  — the output keeps the value it had at ``t_fail``;
* ``random`` — the output is uniform on [0, 1] (full scale) at every sample.

A failure is *observable* when the failed output differs from what the healthy sensor would
have read (its simulated output: direct Sun + albedo + noise) by more than 5σ of the output
noise (0.085 full scale) at 30 or more samples after ``t_fail`` — the failure changed the data
by well above the noise for at least 30 s; a sensor that stays dark for the rest of the run
(or an off/stuck failure of a sensor that stays near zero anyway) cannot be caught by any
test.  The previous definition, *exposed* (noise-free direct output above 0.5 at some sample
after ``t_fail``), is also reported.

Scale factors and off failures: a sensor that never saw the Sun before failing has a scale
factor known only to ±0.9 (3σ), and at its first lit sample the filter explains its silence
by a small scale factor (one update, ν²/S ≈ 1/P_gg ≈ 11, below the per-sensor gate) instead
of flagging it; afterwards its predicted output is below the activity threshold and the NIS
is no longer evaluated.  A sensor calibrated before the failure has a small P_gg and no
scale-factor process noise (``q_param`` = 0: sensitivity ageing over an orbit is
negligible), so its drop cannot be absorbed and the averaged NIS fires.  The
:class:`DarkSensorDetector` closes the gap: it tests the raw outputs against the filter's
*gain-free* prediction and a prior-derived lower bound on a healthy gain.
A *false alarm* is a flag of any sensor in a fault-free run, or before ``t_fail`` (after the
``t_start_s`` convergence period).  Detection is counted when the failed sensor is flagged
after ``t_fail``; the time to detection is the delay of its first flag.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..estimation.consistency import chi2_interval, correlated_average_upper, windowed_average
from ..estimation.rng import as_generator

__all__ = ["FAULT_MODES", "inject_fault", "sensor_nis", "AveragedNISDetector",
           "DarkSensorDetector", "FaultRun", "run_fault_case", "fault_study"]

FAULT_MODES = ("off", "stuck", "random")


def inject_fault(Y, t, sensor: int, mode: str, t_fail_s: float, rng=None) -> np.ndarray:
    """Copy of the outputs Y (K,N) with sensor ``sensor`` failed from ``t_fail_s`` on."""
    Y = np.array(Y, dtype=float, copy=True)
    t = np.asarray(t, dtype=float)
    if mode not in FAULT_MODES:
        raise ValueError(f"unknown failure mode {mode!r}; allowed: {', '.join(FAULT_MODES)}")
    if not 0 <= sensor < Y.shape[1]:
        raise ValueError(f"sensor index {sensor} outside 0..{Y.shape[1] - 1}")
    k0 = int(np.searchsorted(t, t_fail_s))
    if k0 >= t.size:
        return Y
    if mode == "off":
        Y[k0:, sensor] = 0.0
    elif mode == "stuck":
        Y[k0:, sensor] = Y[k0, sensor]
    else:
        Y[k0:, sensor] = as_generator(rng).uniform(0.0, 1.0, t.size - k0)
    return Y


def sensor_nis(innov, innov_var) -> np.ndarray:
    """Per-sensor scalar NIS ν²/S (K,N); NaN where the sensor was not evaluated."""
    nu = np.asarray(innov, dtype=float)
    S = np.asarray(innov_var, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = nu * nu / S
    out[~(S > 0)] = np.nan
    return out


@dataclass(frozen=True)
class AveragedNISDetector:
    """Window-averaged per-sensor NIS test.

    window: number of valid samples K averaged; prob: probability of the two-sided χ²
    interval whose upper bound is the threshold (unless ``threshold`` is given explicitly);
    t_start_s: no decision before this time (filter convergence).

    When the filter reports which share of each innovation variance is correlated in time
    (:meth:`~lightcurve.css.calibration.CalibrationResult.correlated_share`: a coarse albedo
    grid's representation error, which changes only from cell to cell), the K values of a
    window are not independent and the χ²_K/K bound is too tight; the limit then uses the
    effective number of samples of :func:`~lightcurve.estimation.correlated_average_upper`
    with the share averaged over the same window.  With no correlated share the limit is
    the χ²_K/K bound.
    """

    window: int = 50
    prob: float = 0.999999
    threshold: float | None = None
    t_start_s: float = 600.0

    def limit(self, share=None):
        """Threshold on the averaged NIS; ``share``: window-averaged correlated share of the
        innovation variance (array-like, 0-1; None: 0).  An explicit ``threshold`` is used
        as given."""
        if self.threshold is not None:
            return float(self.threshold)
        if share is None:
            return chi2_interval(1, self.prob, self.window)[1]
        return correlated_average_upper(self.prob, self.window, np.nan_to_num(share))

    def averages(self, nis_kn) -> np.ndarray:
        """(K,N) averaged NIS of the last ``window`` valid values, at the samples that bring
        a new value once the window is full; NaN elsewhere."""
        nis_kn = np.asarray(nis_kn, dtype=float)
        out = np.full(nis_kn.shape, np.nan)
        for j in range(nis_kn.shape[1]):
            avg, cnt = windowed_average(nis_kn[:, j], self.window)
            ok = (cnt >= self.window) & np.isfinite(nis_kn[:, j])
            out[ok, j] = avg[ok]
        return out

    def flags(self, t, nis_kn, share_kn=None) -> np.ndarray:
        """Boolean (K,N): sensor flagged at sample k (a new value, full window, average above
        the limit, t ≥ t_start_s); ``share_kn`` (K,N): the correlated share of each sample's
        innovation variance (NaN where not evaluated), averaged over the same window."""
        t = np.asarray(t, dtype=float)
        lim = self.limit() if share_kn is None else self.limit(self.averages(share_kn))
        with np.errstate(invalid="ignore"):
            return (self.averages(nis_kn) > lim) & (t >= self.t_start_s)[:, None]


@dataclass(frozen=True)
class DarkSensorDetector:
    """Sensor-level consistency test for a *dead* (off, or stuck near zero) sensor.

    Why it is needed: the calibration filter estimates every sensor's scale factor g_κ.  A
    sensor that fails before it has ever been lit (prior g_κ ~ N(1, 0.3²)) and then reads 0
    when it is first predicted lit produces a prior innovation −ĝ u with variance ≈
    u² P_gg + R, i.e. ν²/S ≈ 1/P_gg ≈ 11 < the per-sensor gate: the update is accepted, ĝ
    collapses to ≈ 0.05 in one step, the predicted output drops below the activity threshold
    and the sensor is never evaluated again — the averaged NIS never sees the failure.  This
    test therefore does *not* use the filter's scale factor: it uses the filter's gain-free
    predicted irradiance ``u_κ = D_κ + A_κ`` (direct + modelled albedo, from the attitude and
    misalignment estimates, :attr:`CalibrationResult.u_model`) and the raw outputs y_κ.

    Over the last ``window`` samples with ``u_κ ≥ u_min`` it forms the least-squares gain
    ``ĝ_w = Σ u y / Σ u²`` with standard deviation ``σ_w = σ_n / √Σu²`` (white output noise
    σ_n; outputs clipped at zero only bias ĝ_w upwards, i.e. towards "healthy") and flags
    the sensor when ``ĝ_w + z σ_w < g_min``: the sensor's gain is, with confidence Φ(z),
    below the smallest gain a healthy sensor plausibly has.

    ``g_min`` is the Neyman-Pearson boundary of the scale-factor *prior* (the same prior the
    filter starts from): a healthy gain drawn from N(1, σ_g0²) falls below
    ``g_min = 1 − Φ⁻¹(1 − α/N) σ_g0`` with probability α/N, so over N sensors the test's
    false-alarm budget per run is α (default α = 0.005, the acceptance's 0.5 %; N = 8,
    σ_g0 = 0.3 → g_min = 0.032).  This is an *assumption about healthy hardware* that any
    off-failure test of a never-calibrated sensor needs: with data alone "off" and "gain ≈ 0"
    are the same hypothesis.  A sensor whose gain is known (calibrated before the failure)
    is caught earlier by the averaged NIS.
    """

    window: int = 60
    u_min: float = 0.2
    z: float = 3.0
    sigma_noise: float = 0.017
    g_min: float | None = None
    prior_sigma: float = 0.3
    alpha_run: float = 0.005
    n_sensors: int = 8
    min_samples: int = 10
    t_start_s: float = 600.0

    def limit(self) -> float:
        """g_min (see the class docstring)."""
        if self.g_min is not None:
            return float(self.g_min)
        from scipy import stats

        zq = stats.norm.ppf(1.0 - self.alpha_run / max(1, int(self.n_sensors)))
        return max(0.0, 1.0 - float(zq) * self.prior_sigma)

    def gain_stats(self, y, u):
        """Windowed gain ĝ_w, σ_w and the number of samples used (K,) for one sensor's
        outputs y (K,) and gain-free predictions u (K,) (NaN/below u_min: not used);
        NaN where no sample has been used yet."""
        y = np.asarray(y, dtype=float)
        u = np.asarray(u, dtype=float)
        ok = np.isfinite(u) & (u >= self.u_min) & np.isfinite(y)
        uu = np.where(ok, u * u, 0.0)
        uy = np.where(ok, u * y, 0.0)
        c = np.cumsum(ok.astype(np.int64))
        cuu = np.cumsum(uu)
        cuy = np.cumsum(uy)
        # sums over the last `window` valid samples: subtract the sums up to the valid sample
        # `window` places back (position of the (c − window)-th valid sample)
        idx = np.flatnonzero(ok)
        Suu, Suy, cnt = cuu.copy(), cuy.copy(), c.copy()
        W = int(self.window)
        if idx.size > W:
            back = np.zeros(c.size, dtype=np.int64) - 1
            has = c > W
            back[has] = idx[c[has] - W - 1]
            Suu[has] -= cuu[back[has]]
            Suy[has] -= cuy[back[has]]
            cnt[has] = W
        with np.errstate(invalid="ignore", divide="ignore"):
            g = Suy / Suu
            sg = self.sigma_noise / np.sqrt(Suu)
        g[cnt == 0] = np.nan
        sg[cnt == 0] = np.nan
        return g, sg, cnt

    def flags(self, t, Y, U) -> np.ndarray:
        """Boolean (K,N): sensor flagged dead at sample k (a valid sample, at least
        ``min_samples`` in the window, ĝ_w + z σ_w < g_min, t ≥ t_start_s)."""
        Y = np.asarray(Y, dtype=float)
        U = np.asarray(U, dtype=float)
        t = np.asarray(t, dtype=float)
        lim = self.limit()
        out = np.zeros(Y.shape, dtype=bool)
        for j in range(Y.shape[1]):
            g, sg, cnt = self.gain_stats(Y[:, j], U[:, j])
            valid = np.isfinite(U[:, j]) & (U[:, j] >= self.u_min)
            with np.errstate(invalid="ignore"):
                out[:, j] = (valid & (cnt >= self.min_samples) & (g + self.z * sg < lim)
                             & (t >= self.t_start_s))
        return out


@dataclass
class FaultRun:
    """Outcome of one run: mode (None for fault-free), failed sensor, detected (bool),
    time_to_detect_s (NaN if not), false_alarm (bool: flag of any sensor before t_fail, or at
    all in a fault-free run), wrong_sensor (another sensor flagged after t_fail), exposed
    (the failed sensor's noise-free direct output exceeded ``exposure_level`` at some sample
    after t_fail — a lit-sensor criterion), calibrated (the failed sensor's
    scale-factor 3σ was below 0.1 at t_fail, i.e. it had been calibrated before failing),
    observable (the failed output differed from what the healthy sensor would have read —
    its simulated noisy output, direct Sun + albedo — by more than ``observe_level`` at
    ``observe_min_samples`` or more samples after t_fail: the failure changed the data by
    well above the noise for a while), detected_by ("nis", "dark", "both" or ""), gain_true
    (true g of the failed sensor, or the smallest true g in a fault-free run), info (first
    flag time and sensor, per-detector first-flag delays)."""

    mode: str | None
    sensor: int
    detected: bool
    time_to_detect_s: float
    false_alarm: bool
    wrong_sensor: bool
    exposed: bool = True
    calibrated: bool = True
    info: dict = field(default_factory=dict)
    observable: bool = True
    detected_by: str = ""
    gain_true: float = float("nan")


def run_fault_case(seed, mode, *, t_fail_s=1950.0, detector=AveragedNISDetector(),
                   dark=DarkSensorDetector(), duration_s=None, dt_s=1.0, albedo="builtin",
                   params=None, sensor=None, exposure_level=0.5, observe_level=None,
                   observe_min_samples=30, star_period_s=10.0) -> FaultRun:
    """Simulate one §4.4-type orbit, fail one random sensor (``mode`` in FAULT_MODES, or None
    for a fault-free run), run the full calibration filter, the averaged-NIS detector and
    (unless ``dark`` is None) the dark-sensor test; a sensor is flagged when either flags it.

    observe_level defaults to 5 × the CSS noise 1σ (0.085 full scale)."""
    from ..rotations import quat_rotate
    from .calibration import CalibrationParams, run_calibration, simulate_calibration_case

    g = as_generator(seed)
    case = simulate_calibration_case(g, duration_s=duration_s, dt_s=dt_s, albedo_truth=albedo,
                                     star_period_s=star_period_s)
    N = case.Y.shape[1]
    s = int(g.integers(N)) if sensor is None else int(sensor)
    Y = case.Y if mode is None else inject_fault(case.Y, case.t, s, mode, t_fail_s, g)
    p = (params or CalibrationParams()).for_gyro(case.info["spec"])
    q0 = None if star_period_s > 0 else case.q_true[0]
    res = run_calibration(case.css_nominal, case.t, Y, case.gyro, case.sun_N, case.lit,
                          case.r_I_m, case.epoch_utc, params=p, q_star=case.q_star,
                          star_valid=case.star_valid, albedo=albedo, q0=q0)
    Fn = detector.flags(case.t, sensor_nis(res.innov, res.innov_var))
    Fd = (dark.flags(case.t, Y, res.u_model) if dark is not None
          else np.zeros_like(Fn))
    F = Fn | Fd
    before = case.t < t_fail_s
    fk, fs = np.nonzero(F)
    info = {"first_flag_t_s": float(case.t[fk[0]]) if fk.size else None,
            "first_flag_sensor": int(fs[0]) if fk.size else None}
    if mode is None:
        fa = bool(F.any())
        info["false_alarm_by"] = ("both" if Fn.any() and Fd.any() else "nis" if Fn.any()
                                  else "dark" if Fd.any() else "")
        gt = float(case.scale_true[fs[0]]) if fk.size else float(np.min(case.scale_true))
        return FaultRun(None, s, False, float("nan"), fa, False, True, True, info, True, "", gt)
    fa = bool(F[before].any())
    after = ~before
    # exposed (previous definition): noise-free direct output above exposure_level once
    true_css = case.css_nominal.with_errors(scale_individual=case.scale_true,
                                            misalignment_rad=case.misalignment_true)
    direct = true_css.signals(quat_rotate(case.q_true, case.sun_N), case.lit)[:, s]
    exposed = bool(np.any(direct[after] > exposure_level))
    lvl = 5.0 * p.sigma_css if observe_level is None else float(observe_level)
    observable = bool(np.sum(np.abs(Y[after, s] - case.Y[after, s]) > lvl)
                      >= observe_min_samples)
    hit = np.flatnonzero(F[:, s] & after)
    det = hit.size > 0
    ttd = float(case.t[hit[0]] - t_fail_s) if det else float("nan")
    for name, FF in (("nis", Fn), ("dark", Fd)):
        h = np.flatnonzero(FF[:, s] & after)
        info[f"ttd_{name}_s"] = float(case.t[h[0]] - t_fail_s) if h.size else None
    by = ""
    if det:
        a, b = info["ttd_nis_s"], info["ttd_dark_s"]
        by = "both" if a == b else "nis" if (b is None or (a is not None and a < b)) else "dark"
    others = np.delete(F, s, axis=1)
    wrong = bool(others[after].any())
    kf = min(int(np.searchsorted(case.t, t_fail_s)), case.t.size - 1)
    calibrated = bool(3.0 * np.sqrt(res.p_diag[kf, res.layout["scale"]][s]) < 0.1)
    if mode == "stuck":
        info["stuck_value"] = float(Y[kf, s])
    return FaultRun(mode, s, det, ttd, fa, wrong, exposed, calibrated, info, observable, by,
                    float(case.scale_true[s]))


def _worker(arg):
    seed, mode, kw = arg
    return run_fault_case(seed, mode, **kw)


def fault_study(n_runs=300, modes=FAULT_MODES + (None,), *, seed=0, workers=1,
                return_runs=False, progress=None, **kw) -> dict:
    """Monte Carlo of :func:`run_fault_case`: ``n_runs`` per mode (None = fault-free).

    Returns per mode: runs, detection rate over all runs, over the runs whose failure was
    ``observable`` (see :class:`FaultRun`), over the ``exposed`` runs and
    over exposed runs with a calibrated sensor; false-alarm rate; wrong-sensor rate; which
    detector flagged first; the time-to-detection distribution (s: 10/25/50/75/90th
    percentiles and max) overall and for the observable runs; plus the detector settings.
    Seeds: run i of mode m uses ``(seed, index of m, i)``.  ``return_runs``: also return the
    per-run records (list of dicts) under "runs". ``progress``: callable called with no
    argument after each finished run (a progress bar), or None.
    """
    jobs = []
    for mi, m in enumerate(modes):
        for i in range(int(n_runs)):
            jobs.append((np.random.SeedSequence([int(seed), mi, i]), m, kw))
    from ..studies.runner import map_in_pool

    runs = map_in_pool(_worker, jobs, workers, progress, chunksize=4)
    det = kw.get("detector", AveragedNISDetector())
    dk = kw.get("dark", DarkSensorDetector())
    out = {"detector": {"window": det.window, "prob": det.prob, "threshold": det.limit(),
                        "t_start_s": det.t_start_s},
           "dark_detector": None if dk is None else {
               "window": dk.window, "u_min": dk.u_min, "z": dk.z, "g_min": dk.limit(),
               "sigma_noise": dk.sigma_noise, "min_samples": dk.min_samples},
           "modes": {}}

    def rate(rs):
        return float(np.mean([r.detected for r in rs])) if rs else None

    def pct(v):
        v = np.asarray(v, dtype=float)
        if not v.size:
            return None
        q = np.percentile(v, [10, 25, 50, 75, 90])
        return {"p10": float(q[0]), "p25": float(q[1]), "median": float(q[2]),
                "p75": float(q[3]), "p90": float(q[4]), "max": float(np.max(v))}

    for m in modes:
        rs = [r for r in runs if r.mode == m]
        row = {"runs": len(rs), "false_alarm_rate": float(np.mean([r.false_alarm for r in rs])),
               "false_alarms": int(sum(r.false_alarm for r in rs))}
        if m is None:
            fa = [r for r in rs if r.false_alarm]
            row["false_alarm_by"] = {k: sum(r.info.get("false_alarm_by") == k for r in fa)
                                     for k in ("nis", "dark", "both")}
            row["false_alarm_gain_true"] = [r.gain_true for r in fa]
        else:
            ob = [r for r in rs if r.observable]
            ex = [r for r in rs if r.exposed]
            exc = [r for r in ex if r.calibrated]
            obu = [r for r in ob if not r.calibrated]
            row.update({
                "detection_rate": rate(rs),
                "observable_runs": len(ob), "detection_rate_observable": rate(ob),
                "observable_uncalibrated_runs": len(obu),
                "detection_rate_observable_uncalibrated": rate(obu),
                "exposed_runs": len(ex), "detection_rate_exposed": rate(ex),
                "exposed_calibrated_runs": len(exc),
                "detection_rate_exposed_calibrated": rate(exc),
                "wrong_sensor_rate": float(np.mean([r.wrong_sensor for r in rs])),
                "detected_by": {k: sum(r.detected_by == k for r in rs)
                                for k in ("nis", "dark", "both")},
                "ttd_s": pct([r.time_to_detect_s for r in rs if r.detected]),
                "ttd_observable_s": pct([r.time_to_detect_s for r in ob if r.detected]),
                "ttd_median_s": (float(np.median([r.time_to_detect_s for r in rs if r.detected]))
                                 if any(r.detected for r in rs) else None),
                "ttd_p90_s": (float(np.percentile([r.time_to_detect_s for r in rs
                                                   if r.detected], 90))
                              if any(r.detected for r in rs) else None),
                "missed_observable": [{"sensor": r.sensor, "calibrated": r.calibrated,
                                       "gain_true": r.gain_true, **r.info}
                                      for r in ob if not r.detected],
            })
        out["modes"][str(m)] = row
    if return_runs:
        out["runs"] = [{"mode": r.mode, "sensor": r.sensor, "detected": r.detected,
                        "ttd_s": r.time_to_detect_s, "false_alarm": r.false_alarm,
                        "wrong_sensor": r.wrong_sensor, "exposed": r.exposed,
                        "calibrated": r.calibrated, "observable": r.observable,
                        "detected_by": r.detected_by, "gain_true": r.gain_true, **r.info}
                       for r in runs]
    return out
