"""Evaluate a scenario's model against a lightcurve (a recording or a simulation).

:func:`model_magnitudes` is the scenario's noise-free magnitude at each epoch of a lightcurve,
computed from the lightcurve's own geometry (object, site and Sun GCRS positions); the
attitude comes from the scenario's ``[attitude]`` (an attitude law, or the deterministic part
of the controlled/uncontrolled truth model: no ACS or process noise). :func:`fit_statistics`
compares two magnitude series (RMS, Pearson R, mean offset).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

__all__ = ["model_attitude", "model_magnitudes", "fit_statistics"]


def model_attitude(scenario, lightcurve, *, return_omega: bool = False):
    """Model attitude quaternions ``(N, 4)`` (scalar first, GCRS→body) at the lightcurve epochs.

    ``dynamics = "law"``: :func:`lightcurve.dynamics.laws.attitude_law` on the lightcurve's
    object and Sun positions. Otherwise the scenario's truth model without noise
    (``acs_sigma_deg = eta_sigma_deg_s2 = 0``), which needs the scenario's ``[orbit]`` for the
    nadir frame and the uncontrolled torques. The model attitude is the scenario's initial
    attitude AT the scenario epoch (``[scenario] epoch_utc``), propagated to every recorded
    time — whatever rows the recording has (a recording starting later, or with rows
    dropped, sees the same attitude at the same instant). Rows before the scenario epoch:
    the controlled (constant-rate) model is propagated backwards exactly,
    ``q(t) = exp(ω t) ⊗ q0``; the uncontrolled model is refused there (InputError: move
    ``epoch_utc`` to or before the first row).

    ``return_omega``: also return the model body rates ``(N, 3)`` (rad/s, body axes).
    """
    from ..dynamics.laws import attitude_law, law_body_rates
    from .simulate import initial_attitude, truth_attitude

    at = scenario.attitude
    t = np.asarray(lightcurve.t, float)
    if at.dynamics == "law":
        q = attitude_law(at.law, lightcurve.r_obj_eci_m, lightcurve.r_sun_eci_m,
                         lightcurve.epoch_utc, t)
        return (q, law_body_rates(q, t)) if return_omega else q
    quiet = replace(scenario, attitude=replace(at, acs_sigma_deg=0.0, eta_sigma_deg_s2=0.0))
    # the scenario's t = 0 is its own epoch: shift the lightcurve's times onto it
    from ..geometry.time import parse_epoch

    shift = (parse_epoch(lightcurve.epoch_utc) - parse_epoch(quiet.epoch_utc)).total_seconds()
    tu, inv = np.unique(t + shift, return_inverse=True)
    q = np.empty((tu.size, 4))
    w = np.empty((tu.size, 3))
    after = tu >= 0.0
    if np.any(after):
        q[after], w[after] = truth_attitude(quiet, tu[after], np.random.default_rng(0))
    if not np.all(after):
        if at.dynamics != "controlled":
            from ..errors import InputError

            raise InputError("recording rows before the scenario epoch: the uncontrolled model "
                             "is propagated forward from [scenario] epoch_utc; set epoch_utc at "
                             "or before the first row", field="scenario.epoch_utc",
                             value=quiet.epoch_utc)
        from ..rotations import quat_mult, rotvec_to_quat

        q0, w0 = initial_attitude(quiet)
        before = np.flatnonzero(~after)
        for k in before:  # constant body rate: exact backwards propagation
            q[k] = quat_mult(rotvec_to_quat(w0 * tu[k]), q0)
            w[k] = w0
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return (q[inv], w[inv]) if return_omega else q[inv]


def model_magnitudes(scenario, lightcurve, *, attitude=None) -> np.ndarray:
    """The model's noise-free apparent magnitude ``(N,)`` at each epoch of ``lightcurve``.

    Uses the lightcurve's geometry (GCRS, m), the scenario's shape and
    ``measurement.sun_mag``; scaled by the lit fraction of the solar disc
    (``−2.5 log10 lit_fraction``) unless ``measurement.ignore_eclipse``. Epochs where no lit
    facet faces the observer (zero reflected flux) are ``+inf``; epochs in umbra (lit fraction
    0, not ignored) are ``+inf`` too.

    Parameters
    ----------
    scenario : Scenario
    lightcurve : Lightcurve
    attitude : (N, 4), optional
        Quaternions to use instead of :func:`model_attitude`.
    """
    from ..photometry import apparent_magnitude

    lc = lightcurve
    q = model_attitude(scenario, lc) if attitude is None else np.asarray(attitude, float)
    meas = scenario.measurement
    with np.errstate(divide="ignore"):
        m = apparent_magnitude(scenario.shape, q, lc.obj_to_sun_unit, lc.obj_to_obs_unit,
                               lc.range_obs_m, lc.range_sun_m, sun_mag=meas.sun_mag)
        if not meas.ignore_eclipse:
            lit = lc.lit_fraction
            if lit is None:
                from ..geometry.eclipse import lit_fraction

                lit = lit_fraction(lc.r_obj_eci_m, lc.r_sun_eci_m)
            m = m - 2.5 * np.log10(np.where(lit > 0, lit, 0.0))
    return np.where(np.isfinite(m), m, np.inf)


def fit_statistics(m_obs, m_model) -> dict:
    """Agreement between observed and modelled magnitudes.

    Pairs where either value is not finite (NaN observations, ``+inf`` model magnitudes of
    unlit/invisible epochs) are excluded and counted.

    Returns
    -------
    dict
        ``rms_mag`` = sqrt(mean((m_model − m_obs)²)), ``pearson_r`` (Pearson correlation of the
        two series; NaN for fewer than 2 pairs or a constant series), ``mean_offset_mag`` =
        mean(m_model − m_obs), ``n`` pairs used, ``n_excluded``.
    """
    a = np.asarray(m_obs, float).ravel()
    b = np.asarray(m_model, float).ravel()
    if a.shape != b.shape:
        raise ValueError(f"m_obs and m_model must have the same length, got {a.shape} and {b.shape}")
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    n = int(a.size)
    if n == 0:
        return {"rms_mag": float("nan"), "pearson_r": float("nan"), "mean_offset_mag": float("nan"),
                "n": 0, "n_excluded": int((~ok).sum())}
    d = b - a
    r = float("nan")
    if n >= 2:
        da, db = a - a.mean(), b - b.mean()
        den = np.sqrt(np.sum(da * da) * np.sum(db * db))
        if den > 0:
            r = float(np.sum(da * db) / den)
    return {"rms_mag": float(np.sqrt(np.mean(d * d))), "pearson_r": r,
            "mean_offset_mag": float(d.mean()), "n": n, "n_excluded": int((~ok).sum())}
