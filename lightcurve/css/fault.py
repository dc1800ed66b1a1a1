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

A run is *exposed* when the failed sensor's noise-free direct output exceeds 0.5 at some
sample after ``t_fail`` (a sensor that stays dark for the rest of the run cannot be caught by
any innovation test); detection rates are reported over all runs, over exposed runs, and over exposed runs whose
failed sensor had been calibrated before the failure (scale-factor 3σ < 0.1 at ``t_fail``):
a sensor that never saw the Sun before failing has a scale factor known only to ±0.9 (3σ),
and the filter explains its silence by a small scale factor instead of flagging it.
A *false alarm* is a flag of any sensor in a fault-free run, or before ``t_fail`` (after the
``t_start_s`` convergence period).  Detection is counted when the failed sensor is flagged
after ``t_fail``; the time to detection is the delay of its first flag.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..estimation.consistency import chi2_interval, windowed_average
from ..estimation.rng import as_generator

__all__ = ["FAULT_MODES", "inject_fault", "sensor_nis", "AveragedNISDetector", "FaultRun",
           "run_fault_case", "fault_study"]

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
    """

    window: int = 50
    prob: float = 0.999999
    threshold: float | None = None
    t_start_s: float = 600.0

    def limit(self) -> float:
        """Threshold on the averaged NIS."""
        if self.threshold is not None:
            return float(self.threshold)
        return chi2_interval(1, self.prob, self.window)[1]

    def flags(self, t, nis_kn) -> np.ndarray:
        """Boolean (K,N): sensor flagged at sample k (full window, average above the limit,
        t ≥ t_start_s)."""
        nis_kn = np.asarray(nis_kn, dtype=float)
        t = np.asarray(t, dtype=float)
        lim = self.limit()
        out = np.zeros(nis_kn.shape, dtype=bool)
        for j in range(nis_kn.shape[1]):
            avg, cnt = windowed_average(nis_kn[:, j], self.window)
            out[:, j] = (cnt >= self.window) & (avg > lim) & (t >= self.t_start_s)
            # a sample without a new value keeps the previous decision only if it had one
            out[:, j] &= np.isfinite(nis_kn[:, j])
        return out


@dataclass
class FaultRun:
    """Outcome of one run: mode (None for fault-free), failed sensor, detected (bool),
    time_to_detect_s (NaN if not), false_alarm (bool: flag of any sensor before t_fail, or at
    all in a fault-free run), wrong_sensor (another sensor flagged after t_fail), exposed
    (the failed sensor's noise-free direct output exceeded ``exposure_level`` after t_fail,
    i.e. the failure was observable at all), calibrated (the failed sensor's scale-factor 3σ
    was below 0.1 at t_fail, i.e. it had been calibrated before failing), info (first flag
    time and sensor)."""

    mode: str | None
    sensor: int
    detected: bool
    time_to_detect_s: float
    false_alarm: bool
    wrong_sensor: bool
    exposed: bool = True
    calibrated: bool = True
    info: dict = field(default_factory=dict)


def run_fault_case(seed, mode, *, t_fail_s=1950.0, detector=AveragedNISDetector(),
                   duration_s=None, dt_s=1.0, albedo="builtin", params=None,
                   sensor=None, exposure_level=0.5) -> FaultRun:
    """Simulate one §4.4-type orbit, fail one random sensor (``mode`` in FAULT_MODES, or None
    for a fault-free run), run the full calibration filter and the averaged-NIS detector."""
    from .calibration import CalibrationParams, run_calibration, simulate_calibration_case

    g = as_generator(seed)
    case = simulate_calibration_case(g, duration_s=duration_s, dt_s=dt_s, albedo_truth=albedo)
    N = case.Y.shape[1]
    s = int(g.integers(N)) if sensor is None else int(sensor)
    Y = case.Y if mode is None else inject_fault(case.Y, case.t, s, mode, t_fail_s, g)
    p = (params or CalibrationParams()).for_gyro(case.info["spec"])
    res = run_calibration(case.css_nominal, case.t, Y, case.gyro, case.sun_N, case.lit,
                          case.r_I_m, case.epoch_utc, params=p, q_star=case.q_star,
                          star_valid=case.star_valid, albedo=albedo)
    F = detector.flags(case.t, sensor_nis(res.innov, res.innov_var))
    before = case.t < t_fail_s
    fk, fs = np.nonzero(F)
    info = {"first_flag_t_s": float(case.t[fk[0]]) if fk.size else None,
            "first_flag_sensor": int(fs[0]) if fk.size else None}
    if mode is None:
        fa = bool(F.any())
        return FaultRun(None, s, False, float("nan"), fa, False, True, True, info)
    fa = bool(F[before].any())
    after = ~before
    # exposed: the failed sensor would have been clearly lit (noise-free direct output above
    # exposure_level) at some sample after the failure — otherwise no detector can see it
    from ..rotations import quat_rotate

    true_css = case.css_nominal.with_errors(scale_individual=case.scale_true,
                                            misalignment_rad=case.misalignment_true)
    direct = true_css.signals(quat_rotate(case.q_true, case.sun_N), case.lit)[:, s]
    exposed = bool(np.any(direct[after] > exposure_level))
    hit = np.flatnonzero(F[:, s] & after)
    det = hit.size > 0
    ttd = float(case.t[hit[0]] - t_fail_s) if det else float("nan")
    others = np.delete(F, s, axis=1)
    wrong = bool(others[after].any())
    kf = min(int(np.searchsorted(case.t, t_fail_s)), case.t.size - 1)
    calibrated = bool(3.0 * np.sqrt(res.p_diag[kf, res.layout["scale"]][s]) < 0.1)
    return FaultRun(mode, s, det, ttd, fa, wrong, exposed, calibrated, info)


def _worker(arg):
    seed, mode, kw = arg
    return run_fault_case(seed, mode, **kw)


def fault_study(n_runs=300, modes=FAULT_MODES + (None,), *, seed=0, workers=1, **kw) -> dict:
    """Monte Carlo of :func:`run_fault_case`: ``n_runs`` per mode (None = fault-free).

    Returns per mode: runs, detection rate (all runs, and among the runs whose failure was
    observable — ``exposed``), false-alarm rate, wrong-sensor rate and the
    median / 90th percentile / max time to detection (s); plus the detector settings.
    Seeds: run i of mode m uses ``(seed, index of m, i)``.
    """
    jobs = []
    for mi, m in enumerate(modes):
        for i in range(int(n_runs)):
            jobs.append((np.random.SeedSequence([int(seed), mi, i]), m, kw))
    if workers > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers) as ex:
            runs = list(ex.map(_worker, jobs, chunksize=4))
    else:
        runs = [_worker(j) for j in jobs]
    det = kw.get("detector", AveragedNISDetector())
    out = {"detector": {"window": det.window, "prob": det.prob, "threshold": det.limit(),
                        "t_start_s": det.t_start_s}, "modes": {}}
    for m in modes:
        rs = [r for r in runs if r.mode == m]
        ttd = np.array([r.time_to_detect_s for r in rs if r.detected])
        ex = [r for r in rs if r.exposed]
        exc = [r for r in ex if r.calibrated]
        out["modes"][str(m)] = {
            "runs": len(rs),
            "detection_rate": float(np.mean([r.detected for r in rs])) if m else None,
            "exposed_runs": len(ex) if m else None,
            "detection_rate_exposed": (float(np.mean([r.detected for r in ex]))
                                       if m and ex else None),
            "exposed_calibrated_runs": len(exc) if m else None,
            "detection_rate_exposed_calibrated": (float(np.mean([r.detected for r in exc]))
                                                  if m and exc else None),
            "false_alarm_rate": float(np.mean([r.false_alarm for r in rs])),
            "wrong_sensor_rate": float(np.mean([r.wrong_sensor for r in rs])) if m else None,
            "ttd_median_s": float(np.median(ttd)) if ttd.size else None,
            "ttd_p90_s": float(np.percentile(ttd, 90)) if ttd.size else None,
            "ttd_max_s": float(np.max(ttd)) if ttd.size else None,
        }
    return out
