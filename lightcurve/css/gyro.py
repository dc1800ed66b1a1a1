"""Rate-gyro models (O'Keefe 2015, eq. 2.23-2.50; table 2.3 grades).

Farrenkopf model (continuous)::

    ω̃ = ω + β + η_v,        β̇ = η_u,
    E[η_v η_vᵀ] = σ_v² I δ(t−τ)   (angle random walk, ARW, σ_v in rad/√s)
    E[η_u η_uᵀ] = σ_u² I δ(t−τ)   (rate random walk, RRW, σ_u in rad/s^{3/2})

sampled exactly at interval Δt (Farrenkopf's discrete solution, as in Crassidis & Junkins,
*Optimal Estimation of Dynamic Systems*, 2nd ed., eq. 4.31 there)::

    β_{k+1} = β_k + σ_u √Δt N_u
    ω̃_{k+1} = ω_{k+1} + ½(β_{k+1} + β_k) + √(σ_v²/Δt + σ_u² Δt/12) N_v

Detailed model: scale-factor errors ``S = diag(s_x, s_y, s_z)`` and small misalignments
``Γ`` (zero diagonal, six independent angles in rad) multiply the true rate before the
Farrenkopf noise is added::

    ω̃ = (I + S)(I + Γ) ω + β + noise.

All rates are body-axes rad/s.  The output noise is what a perfectly synchronised gyro
integrating over Δt would deliver (ARW converted to a per-sample rate noise σ_v/√Δt).

Grades (:data:`GYRO_GRADES`): the four of O'Keefe (2015) Table 2.3 — "inertial",
"intermediate", "moderate", "low" — with ARW σ_v = the table's rate noise σ_ω, the initial
bias 1σ = its bias stability σ_ωr and RRW σ_u = σ_ωd = √(2/τ) σ_ωr, τ = 1000 s (§2.3.3, §2.4);
the table gives no scale-factor or misalignment errors (zero).  Three further classes
("rate", "tactical", "navigation") are generic commercial-catalogue values of our own, not
from the thesis (ARW in rad/√s, RRW in rad/s^{3/2}, bias 1σ rad/s, scale factor 1σ,
misalignment 1σ rad).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..estimation.rng import as_generator

__all__ = ["GyroSpec", "GYRO_GRADES", "gyro_grade", "GyroErrors", "draw_gyro_errors",
           "simulate_gyro", "gyro_step_nb"]

_DEG = np.pi / 180.0
_ARW = _DEG / 60.0          # 1 deg/sqrt(h) in rad/sqrt(s)
_BIAS = _DEG / 3600.0       # 1 deg/h in rad/s


@dataclass(frozen=True)
class GyroSpec:
    """Noise and error statistics of a 3-axis rate gyro (SI units, see module docstring)."""

    name: str
    arw: float               # σ_v, rad/√s
    rrw: float               # σ_u, rad/s^{3/2}
    bias_sigma: float        # initial bias 1σ per axis, rad/s
    scale_sigma: float = 0.0         # scale-factor 1σ, dimensionless
    misalignment_sigma: float = 0.0  # misalignment angles 1σ, rad

    def __post_init__(self):
        for k in ("arw", "rrw", "bias_sigma", "scale_sigma", "misalignment_sigma"):
            v = getattr(self, k)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"GyroSpec.{k} must be finite and >= 0, got {v}")


def _table_2_3(name):
    from .okeefe2015 import gyro_sigmas

    sw, sr, sd = gyro_sigmas(name)
    return GyroSpec(name, sw, sd, sr)


GYRO_GRADES = {
    # O'Keefe (2015) Table 2.3
    "inertial": _table_2_3("inertial"),
    "intermediate": _table_2_3("intermediate"),
    "moderate": _table_2_3("moderate"),
    "low": _table_2_3("low"),
    # generic catalogue classes (not from the thesis)
    # rate grade (MEMS): ARW 0.5 deg/sqrt(h), bias 100 deg/h, 1000 ppm, 1 mrad
    "rate": GyroSpec("rate", 0.5 * _ARW, 2.0e-6, 100.0 * _BIAS, 1e-3, 1e-3),
    # tactical grade: ARW 0.1 deg/sqrt(h), bias 1 deg/h, 100 ppm, 0.1 mrad
    "tactical": GyroSpec("tactical", 0.1 * _ARW, 1.0e-8, 1.0 * _BIAS, 1e-4, 1e-4),
    # navigation grade: ARW 0.003 deg/sqrt(h), bias 0.01 deg/h, 10 ppm, 20 urad
    "navigation": GyroSpec("navigation", 0.003 * _ARW, 1.0e-10, 0.01 * _BIAS, 1e-5, 2e-5),
}


def gyro_grade(name: str) -> GyroSpec:
    """The :class:`GyroSpec` of a grade name (Table 2.3: 'inertial', 'intermediate',
    'moderate', 'low'; generic: 'rate', 'tactical', 'navigation')."""
    try:
        return GYRO_GRADES[name]
    except KeyError:
        raise ValueError(f"unknown gyro grade {name!r}; allowed: {', '.join(GYRO_GRADES)}") from None


@dataclass(frozen=True)
class GyroErrors:
    """One realisation of the deterministic gyro errors: ``M = (I+S)(I+Γ)`` (3×3) and the
    initial bias β₀ (3,) rad/s."""

    M: np.ndarray
    bias0: np.ndarray


def draw_gyro_errors(spec: GyroSpec, rng, detailed: bool = True) -> GyroErrors:
    """Draw scale factors, misalignments (detailed model only) and the initial bias."""
    g = as_generator(rng)
    b0 = g.normal(0.0, spec.bias_sigma, 3)
    M = np.eye(3)
    if detailed:
        S = np.diag(g.normal(0.0, spec.scale_sigma, 3))
        G = np.zeros((3, 3))
        off = g.normal(0.0, spec.misalignment_sigma, 6)
        G[0, 1], G[0, 2], G[1, 0], G[1, 2], G[2, 0], G[2, 1] = off
        M = (np.eye(3) + S) @ (np.eye(3) + G)
    return GyroErrors(M, b0)


@numba.njit(cache=True)
def gyro_step_nb(omega_true, bias, M, arw, rrw, dt, n_u, n_v):
    """One sample of the detailed/Farrenkopf model.  ``bias`` (3,) is updated in place
    (β_k → β_{k+1}); n_u, n_v are standard-normal draws (3,).  Returns ω̃_{k+1} (3,)."""
    out = np.empty(3)
    sv = np.sqrt(arw * arw / dt + rrw * rrw * dt / 12.0)
    for i in range(3):
        b_old = bias[i]
        bias[i] = b_old + rrw * np.sqrt(dt) * n_u[i]
        out[i] = (M[i, 0] * omega_true[0] + M[i, 1] * omega_true[1] + M[i, 2] * omega_true[2]
                  + 0.5 * (bias[i] + b_old) + sv * n_v[i])
    return out


def simulate_gyro(omega_true, dt: float, spec: GyroSpec, rng, *, detailed: bool = True,
                  errors: GyroErrors | None = None):
    """Simulate gyro samples for true rates ``omega_true`` (K, 3) rad/s at interval ``dt`` s.

    Returns ``(omega_meas (K,3), bias (K,3))`` — ``bias[k]`` is β_k after sample ``k``.
    ``detailed=False`` gives the pure Farrenkopf model (no scale factor or misalignment).
    """
    w = np.atleast_2d(np.asarray(omega_true, dtype=float))
    if not dt > 0:
        raise ValueError("dt must be > 0")
    g = as_generator(rng)
    err = errors if errors is not None else draw_gyro_errors(spec, g, detailed)
    K = w.shape[0]
    nu = g.standard_normal((K, 3))
    nv = g.standard_normal((K, 3))
    out = np.empty((K, 3))
    bias_hist = np.empty((K, 3))
    b = err.bias0.astype(float).copy()
    for k in range(K):
        out[k] = gyro_step_nb(w[k], b, err.M, spec.arw, spec.rrw, dt, nu[k], nv[k])
        bias_hist[k] = b
    return out, bias_hist
