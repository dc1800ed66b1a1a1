"""Per-measurement screening of the attitude filters: innovation (outlier) gate and epochs the
model cannot explain (object unlit or below the horizon).

One place for the rules, called from the update step of the MEKF, the UKF and the BPF: bad
measurements are rejected or skipped with counts in the result, never silently used.

Innovation gate
---------------
For a scalar magnitude ``y`` (mag) with predicted value ``ŷ`` and predicted innovation variance
``S = P_yy + R`` (mag²) — MEKF ``S = H P⁻ Hᵀ + R``; UKF ``S = Σ Wᶜ (Yᵢ − ŷ)² + R`` over the sigma
points; BPF ``S = Σ wᵢ (m(qᵢ) − ŷ)² + R`` with ``ŷ = Σ wᵢ m(qᵢ)`` over the weighted particles —
the normalised innovation squared ``NIS = ν²/S`` (``ν = y − ŷ``) is χ²-distributed with one
degree of freedom when the filter is consistent. The gate flags the measurement when
``NIS > γ`` with ``γ = χ²₁⁻¹(1 − α)``, α the false-alarm rate (default 10⁻⁴ → γ = 15.137,
i.e. |ν| > 3.89 √S). Because ``S`` contains the prior spread ``P_yy``, a wide prior (BPF from
60°, UKF/MEKF from 10°) widens the gate by itself: measurements are not rejected merely because
the estimate has not converged yet.

Particle filter: the weighted mean and variance summarise a cloud that may be multimodal
while the filter has not converged (from a 60° prior the cloud splits into several attitude
hypotheses), so the moment test alone rejects good measurements (docs/measurements.md). The
particle filter flags a measurement only when, in addition, no particle explains it: every
particle's own ``(y − m(q_i))²/R`` exceeds γ. A gross outlier is outside every particle's prediction;
an informative measurement that the mean does not expect but some hypotheses do is used. For
the particle filter α is therefore an upper bound of the false-alarm rate.

Modes (:class:`GateConfig`):

* ``"auto"`` (default): ``"reject"`` in the UKF (consistent: its NIS can be trusted),
  ``"inflate"`` in the MEKF and the particle filter, which are over-confident, so good
  measurements exceed the gate more often than α says (hard rejection kept the particle cloud
  on a biased attitude and raised the MEKF's NEES; the measurements behind this choice are in
  docs/measurements.md). Inflation keeps the direction of a surprising good measurement,
  while a gross outlier, whose noise is widened to |ν|/√γ, barely moves the estimate.
* ``"reject"``: the flagged measurement is not used (no update; the prior is kept, the
  epoch gets :data:`~lightcurve.filters.result.FLAG_OUTLIER`); its ν and S are still stored in
  the Estimate (``innovations``, ``innovation_var``) for inspection, but do not enter the
  sliding-window NIS divergence test.
* ``"inflate"``: the measurement is used with its noise variance inflated so that its NIS equals
  γ — ``R' = R + ν²/γ − S``, hence ``S' = ν²/γ`` (the gain shrinks in proportion; a robust
  "soft" gate). Flag :data:`~lightcurve.filters.result.FLAG_INFLATED`.
* ``"off"``: no gate.

Release (our choice, documented): a gate that rejects ``max_consecutive`` measurements in a row
is more likely facing a lost filter (or a model mismatch) than a burst of outliers; the next
flagged measurement is then used as it is (flag
:data:`~lightcurve.filters.result.FLAG_GATE_RELEASED`) so that a diverging filter can recover
or be caught by the sliding-window NIS divergence test instead of silently coasting on its
prior. ``warmup`` (default 0) leaves the first ``warmup`` measurement updates ungated; it is 0
by default because S already carries the prior spread and a warm-up would let early outliers
through.

Epoch screening
---------------
``skip_epoch`` skips — flagged and counted, never used — measurements at epochs where

* the object is in the Earth's full shadow (the model's lit fraction is 0, i.e.
  ``MagnitudeModel.lit_offset`` is +inf; a lightcurve with ``attrs["ignore_eclipse"]`` models
  such epochs as sunlit, as Bernard's published cases do, and they are then used):
  :data:`~lightcurve.filters.result.FLAG_UNLIT`;
* the object is below the site's geometric horizon (``elevation_rad < 0`` when the lightcurve
  carries elevations): :data:`~lightcurve.filters.result.FLAG_BELOW_HORIZON`.

Without the screening an unlit epoch makes every prediction +inf: the Kalman filters skipped it
as "invisible" and the BPF's weights all became zero (a collapse flagged as divergence).

Configuration travels with the problem: ``problem.meta["gate"]`` (a :class:`GateConfig` or a
dict of its fields; :func:`set_gate`), so that it is recorded in the Estimate's metadata, and
the run's counts are added there by :meth:`InnovationGate.finish` (``est.meta["gate"]``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np
from scipy.stats import chi2

from .result import (
    FLAG_BELOW_HORIZON,
    FLAG_GATE_RELEASED,
    FLAG_INFLATED,
    FLAG_OUTLIER,
    FLAG_UNLIT,
)

__all__ = ["GateConfig", "InnovationGate", "GATE_MODES", "set_gate", "nis_threshold"]

GATE_MODES = ("auto", "reject", "inflate", "off")

#: status codes of :attr:`InnovationGate.status`
_USED, _REJECTED, _INFLATED, _RELEASED, _UNLIT, _BELOW = 0, 1, 2, 3, 4, 5


def nis_threshold(false_alarm: float, dof: int = 1) -> float:
    """χ² threshold γ with ``P(χ²_dof > γ) = false_alarm`` (dimensionless)."""
    return float(chi2.isf(float(false_alarm), int(dof)))


@dataclass(frozen=True)
class GateConfig:
    """Settings of the innovation gate and the epoch screening (module docstring).

    Attributes
    ----------
    mode : {"auto", "reject", "inflate", "off"} ("auto": reject in the UKF, inflate in the
        MEKF and the particle filter)
    false_alarm : float in (0, 0.5] — probability that a consistent, correct measurement is
        flagged (default 1e-4 → NIS threshold 15.137 for one magnitude).
    max_consecutive : int ≥ 1 — after this many rejections in a row the next flagged
        measurement is used (release; 0 disables the release).
    warmup : int ≥ 0 — measurement updates before the gate starts acting.
    skip_unlit : bool — skip epochs with the object in full shadow.
    skip_below_horizon : bool — skip epochs with the object below the horizon.
    """

    mode: str = "auto"
    false_alarm: float = 1e-4
    max_consecutive: int = 3
    warmup: int = 0
    skip_unlit: bool = True
    skip_below_horizon: bool = True

    def __post_init__(self):
        if self.mode not in GATE_MODES:
            raise ValueError(f"gate mode must be one of {', '.join(GATE_MODES)}, got {self.mode!r}")
        a = float(self.false_alarm)
        if not (0.0 < a <= 0.5):
            raise ValueError(f"gate false_alarm must lie in (0, 0.5], got {self.false_alarm}")
        if int(self.max_consecutive) < 0 or int(self.warmup) < 0:
            raise ValueError("gate max_consecutive and warmup must be >= 0")

    @property
    def threshold(self) -> float:
        """NIS threshold γ (χ²₁ quantile at 1 − false_alarm)."""
        return nis_threshold(self.false_alarm, 1)

    @classmethod
    def coerce(cls, value) -> "GateConfig":
        """A GateConfig from None (defaults), a GateConfig, a mode string or a dict of fields."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if isinstance(value, str):
            return cls(mode=value)
        if isinstance(value, dict):
            names = {f.name for f in fields(cls)}
            return cls(**{k: v for k, v in value.items() if k in names})
        raise TypeError(f"gate settings must be a GateConfig, a mode or a dict, got {value!r}")

    def as_dict(self) -> dict:
        """JSON-ready settings (plus the threshold)."""
        d = asdict(self)
        d["threshold_nis"] = self.threshold
        return d


def set_gate(problem, config=None, **kw) -> GateConfig:
    """Set the gate of a :class:`~lightcurve.filters._common.FilterProblem` (stored in
    ``problem.meta["gate"]``); ``config`` as :meth:`GateConfig.coerce`, ``kw`` override fields."""
    cfg = GateConfig.coerce(config)
    if kw:
        cfg = GateConfig(**{**asdict(cfg), **kw})
    problem.meta["gate"] = cfg.as_dict()
    return cfg


class InnovationGate:
    """Run-time gate of one filter run (module docstring).

    Parameters
    ----------
    problem : FilterProblem — its ``meta["gate"]`` (default settings when absent) and its
        measurement model (lit offsets, elevations).
    auto : {"reject", "inflate"} — what mode "auto" means in the calling filter (module
        docstring: reject in the UKF, inflate in the MEKF and the particle filter).
    """

    def __init__(self, problem, auto="reject"):
        cfg = GateConfig.coerce(problem.meta.get("gate"))
        if cfg.mode == "auto":
            cfg = GateConfig(**{**asdict(cfg), "mode": auto})
        self.cfg = cfg
        self.gamma = self.cfg.threshold
        m = problem.model
        n = len(m)
        self.status = np.zeros(n, dtype=np.int8)
        self.nis = np.full(n, np.nan)
        self._run = 0          # consecutive rejections
        self._updates = 0      # measurement updates seen by the gate (accepted ones)
        lit_off = getattr(m, "lit_offset", None)
        self.unlit = (np.zeros(n, bool) if lit_off is None or not self.cfg.skip_unlit
                      else ~np.isfinite(np.asarray(lit_off, float)))
        el = getattr(m, "elevation_rad", None)
        self.below = (np.zeros(n, bool) if el is None or not self.cfg.skip_below_horizon
                      else ~(np.asarray(el, float) >= 0.0))
        # an epoch both unlit and below the horizon is counted once, as below the horizon
        self.unlit &= ~self.below

    # ------------------------------------------------------------------------------------
    def skip_epoch(self, k, rec) -> bool:
        """True (and flag epoch k in ``rec``) when its measurement must not be used: the object
        is below the horizon or unlit. Call after the NaN check (a NaN stays a NaN)."""
        if self.below[k]:
            rec.flags[k] |= FLAG_BELOW_HORIZON
            self.status[k] = _BELOW
            return True
        if self.unlit[k]:
            rec.flags[k] |= FLAG_UNLIT
            self.status[k] = _UNLIT
            return True
        return False

    def check(self, k, nu, S, R, rec, nu_nearest=None):
        """Gate the innovation ``nu`` (mag) with predicted variance ``S`` (mag², including R)
        at epoch k → the measurement variance to use (``R``, or the inflated ``R'``), or None
        when the measurement is rejected (then ν and S are stored in ``rec`` without entering
        its NIS divergence test).

        ``nu_nearest`` (particle filter): the smallest ``|y − m(q_i)|`` over the particles; a
        measurement that some particle explains within its own gate (``ν_i²/R ≤ γ``) is never
        flagged (module docstring, "particle filter")."""
        nu, S, R = float(nu), float(S), float(R)
        if not (np.isfinite(nu) and S > 0.0 and np.isfinite(S)):
            return R                       # the filter's own failure paths handle these
        nis = nu * nu / S
        self.nis[k] = nis
        near = nu_nearest is not None and float(nu_nearest) ** 2 <= self.gamma * R
        if (self.cfg.mode == "off" or self._updates < self.cfg.warmup or nis <= self.gamma
                or near):
            self._run = 0
            self._updates += 1
            return R
        if self.cfg.mode == "inflate":
            self._run = 0
            self._updates += 1
            self.status[k] = _INFLATED
            rec.flags[k] |= FLAG_INFLATED
            return R + nu * nu / self.gamma - S
        if self.cfg.max_consecutive and self._run >= self.cfg.max_consecutive:
            self._run = 0
            self._updates += 1
            self.status[k] = _RELEASED
            rec.flags[k] |= FLAG_GATE_RELEASED
            return R
        self._run += 1
        self.status[k] = _REJECTED
        rec.flags[k] |= FLAG_OUTLIER
        rec.nu[k] = nu
        rec.S[k] = S
        return None

    # ------------------------------------------------------------------------------------
    def counts(self) -> dict:
        """Counts of this run: rejected, inflated, released, skipped_unlit,
        skipped_below_horizon."""
        s = self.status
        return {"rejected": int(np.sum(s == _REJECTED)), "inflated": int(np.sum(s == _INFLATED)),
                "released": int(np.sum(s == _RELEASED)), "skipped_unlit": int(np.sum(s == _UNLIT)),
                "skipped_below_horizon": int(np.sum(s == _BELOW))}

    def finish(self, est):
        """Record the settings and counts in ``est.meta["gate"]``; return ``est``."""
        est.meta["gate"] = dict(self.cfg.as_dict(), **self.counts())
        return est
