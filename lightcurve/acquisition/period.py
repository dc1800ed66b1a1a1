"""Spin-period analysis of an apparent-magnitude lightcurve.

What is measured
----------------
The brightness of a spinning object repeats with its spin period only while the Sun and the
observer stay put; over a pass they move, so a periodogram measures the *synodic* period, the
period of the body's rotation relative to the phase-angle bisector (PAB, the unit vector halfway
between object→Sun and object→observer). The sidereal (inertial) spin period differs by the
PAB's apparent motion: with the PAB turning at ω_PAB about the spin axis,
``f_sid = f_syn ± ω_PAB/2π``, i.e. ``|P_sid − P_syn| ≈ ω_PAB P²/2π`` — the synodic–sidereal
difference of asteroid photometry (Harris et al. 1984, Icarus 57, 251; Pravec et al. 2005,
Icarus 173, 108). The spin axis (hence the sign and the projection) is unknown here, so the
mean angular rate of the PAB over the window bounds the correction and widens the stated
interval.

Method
------
1. Reduced magnitudes: the apparent magnitude minus ``5 log10(|r_obs|/1000 km)`` and
   ``5 log10(|r_sun|/1 au)`` (the distance terms of the magnitude equation, DESIGN.md), so a
   LEO pass's range sweep does not masquerade as a period. A polynomial trend in time (degree
   ``trend_degree``, one per site) absorbs the slow phase-angle dependence.
   Specular glints (a facet's mirror direction crossing the observer for one or two samples,
   several magnitudes bright) are not representable by a few harmonics and would dominate every
   least-squares statistic; the detrended magnitudes are winsorised at ``clip_mad`` robust
   standard deviations (1.4826 × the median absolute deviation; Huber 1981, Robust Statistics,
   §1.4) before steps 2–4. A harmonic signal of any amplitude is never clipped at the default 3
   (the MAD-σ of a sinusoid of amplitude A is 1.05 A); ``clip_mad=None`` turns this off.
2. Candidates: the Lomb–Scargle periodogram (astropy, one harmonic, floating mean) of the
   detrended magnitudes, and the phase-dispersion minimisation statistic θ (Stellingwerf 1978,
   ApJ 224, 953) on the same residuals. Each strong peak may be the fundamental or one of its
   harmonics (a faceted body brightens several times per turn), so every peak frequency f_c
   yields candidate fundamentals f_c/j, j = 1…``max_harmonics``.
3. Model choice: at every candidate the joint weighted least-squares fit of trend +
   H harmonics (a multi-harmonic periodogram, Schwarzenberg-Czerny 1996, ApJ 460, L107) is
   refined in frequency on a local grid; the (f, H) with the smallest Bayesian information
   criterion ``n ln(χ²/n) + k ln n`` (Gaussian residuals of unknown scale: a periodic model
   rarely fits a pass to the stated noise, and the scale-free form keeps the penalty in
   proportion to the misfit) is the answer (a multiple of the true period fits no better with
   the same number of harmonics, so it loses on k). Harmonics above the Nyquist frequency of
   the median cadence are not used. The brightness of a faceted body may repeat 2, 3 or 4
   times per turn, so these multiples of the best period are always scored and listed.
4. Uncertainty: a non-linear least-squares fit of frequency and linear terms together
   (scipy ``least_squares``); the frequency's 1σ from the Jacobian, inflated by √(χ²/dof) when
   the fit is worse than the noise. The 99 % interval of the sidereal period adds the synodic
   bound to ±2.576σ.
5. Significance: the F-test of trend + H harmonics against the trend alone, Bonferroni-
   corrected for the number of independent frequencies ``(f_max − f_min)·T``.
6. Spin period (turn-to-turn repetition): a fit of a few harmonics may prefer a fraction of the
   turn (a cube whose three bright faces pass by per turn, glints, a brightness that drifts while
   the bisector sweeps), and the multi-harmonic model at the full period then pays for many
   harmonics it cannot fit to a drifting curve. What tells the spin period is whether the
   brightness repeats *one turn later*: the autocorrelation of the lightcurve at the lag of one
   turn (the ACF method of McQuillan, Aigrain & Mazeh 2013, MNRAS 432, 1203, §3, which takes the
   higher of the first two ACF peaks for curves with two dips per turn). Here the correlation is
   Spearman's rank correlation ρ (Spearman 1904; robust to glints and heavy tails) between the
   detrended magnitudes r(t) and r(t + τ), r(t + τ) linearly interpolated in time within one
   site's series (a gap of at most two median cadences). For every candidate spin period (the
   best, the aliases with ΔBIC ≤ 6 and the 2–4 × multiples, each with at least two turns in the
   window) τ is searched over the candidate's 99 % interval (steps of 1/20 of the cadence, at
   most 401 lags) and the highest ρ kept. The best period stays the answer when the brightness
   repeats after one of its periods (ρ_best significantly positive: ``atanh ρ_best · √(n_best −
   3)/1.06 > 2.326``, one-sided 1 %; the Fisher-z standard error of a Spearman coefficient,
   Fieller, Hartley & Pearson 1957, Biometrika 44, 470): a longer candidate is then not needed.
   Otherwise the candidate with the highest ρ replaces it when that ρ is higher by ``z = (atanh
   ρ_k − atanh ρ_best)/√(1.06²/(n_k − 3) + 1.06²/(n_best − 3)) > 2.326`` (the two coefficients
   treated as independent, which overstates the variance of the difference of positively
   dependent coefficients, so the test is conservative). The first condition also keeps a
   strictly periodic curve sampled a few times per turn at its period: there the lag of one turn
   falls between samples, the interpolated partner is blurred, and a multiple whose lag happens
   to fall nearer a sample can show a higher ρ without being the period. Candidates whose ρ is
   not significantly below the chosen one's (same test) are stated as spin periods the data do
   not rule out. The stated spin period and its 99 % interval are the chosen candidate's (steps
   3–4: k × the best period, k × its σ and the synodic bound at k × P); the lag of the highest ρ,
   which lies in that interval by construction, is listed beside it (its precision is about one
   cadence: the correlation of a sharply varying curve is highest where the lag falls on
   samples).
   The stated 99 % set of the spin period (``spin_set_99_s``) is the union of the chosen
   candidate's interval and the intervals of the candidates not ruled out: the set of periods
   the test does not reject at 1 % (a confidence set by test inversion). A prism tumbling end
   over end looks the same after half a turn, so its set holds both the brightness period and
   twice it, and no lightcurve can shrink it to one.

Validity: a period between ``min_period_s`` (default 2.5 × the median cadence) and
``max_period_s`` (default the span / 1.5); several turns in the window make the estimate
reliable. A body whose brightness repeats more than once per turn (symmetric shapes) shows
its brightness period; the alias list names the multiples, and aliases that fit about as well
as the best (ΔBIC ≤ 6) are reported as candidates: the data cannot tell them apart. The stated
spin periods (``spin_candidates``) are those candidates plus the multiples 2–4 × best with
their ΔBIC: when the brightness does not repeat exactly from turn to turn (glints, a sweeping
phase-angle bisector) the fit prefers a fraction of the turn, and only the shape can say how
many times per turn the brightness repeats.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.constants import AU_M
from ..errors import InputError

__all__ = ["PeriodResult", "analyse_period", "reduced_magnitude", "pab_rate_rad_s",
           "truth_spin_period_s", "turn_correlation",
           "INDISTINGUISHABLE_DBIC", "MAX_FREQUENCIES"]

#: two-sided 99 % quantile of the standard normal distribution
Z99 = 2.5758293035489004
#: aliases within this BIC difference of the best are reported as indistinguishable (a BIC
#: difference above 6 is "strong" evidence, Kass & Raftery 1995, JASA 90, 773, §3.2)
INDISTINGUISHABLE_DBIC = 6.0
#: relations of the integer multiples of the best period that are always scored and listed
SPIN_MULTIPLE_RELATIONS = ("2x best", "3x best", "4x best")
#: one-sided 1 % quantile of the standard normal: a spin candidate replaces the best period
#: only when its turn-to-turn rank correlation is higher by more than this many standard errors
#: (module docstring, step 6)
Z_ONE_SIDED_01 = 2.3263478740408408
#: factor on the Fisher-z standard error 1/√(n − 3) of a Spearman coefficient (Fieller, Hartley
#: & Pearson 1957)
SPEARMAN_SE_FACTOR = 1.06
#: most trial frequencies of one analysis (memory and time stay bounded: a multi-month
#: recording asks for ~10⁹; analyse its passes one at a time)
MAX_FREQUENCIES = 500_000
_REF_RANGE_M = 1.0e6   # reduced magnitudes refer to 1000 km


def reduced_magnitude(curve) -> np.ndarray:
    """Apparent magnitude reduced to 1000 km from the observer and 1 au from the Sun, (N,).

    ``m_red = m − 5 log10(|r_obs|/1000 km) − 5 log10(|r_sun|/1 au)``: the two distance terms of
    the magnitude equation (DESIGN.md; Bernard 2021 eq. 5.2–5.6), so what remains depends on
    attitude and phase geometry only.
    """
    return (np.asarray(curve.mag, float) - 5.0 * np.log10(curve.range_obs_m / _REF_RANGE_M)
            - 5.0 * np.log10(curve.range_sun_m / AU_M))


def truth_spin_period_s(curve, inertia_kg_m2=None):
    """The simulated truth's brightness-relevant period, s, or None without a truth rate.

    From the truth body rate ω at the first epoch: for an axisymmetric body (two equal principal
    moments, given ``inertia_kg_m2``) the precession period of the symmetry axis 2π I_t / |H|
    (torque-free motion, e.g. Landau & Lifshitz, Mechanics §37), since a symmetric body looks the
    same after any roll about that axis; else the spin period 2π/|ω|.
    """
    w_all = getattr(curve, "truth_omega_rad_s", None)
    if w_all is None:
        return None
    w = np.asarray(w_all, float)[0]
    if not np.linalg.norm(w) > 0:
        return None
    if inertia_kg_m2 is not None:
        J = np.asarray(inertia_kg_m2, float)
        ev = np.sort(np.linalg.eigvalsh(J))
        low_pair = abs(ev[0] - ev[1]) < 1e-6 * ev[2]
        high_pair = abs(ev[1] - ev[2]) < 1e-6 * ev[2]
        if (low_pair or high_pair) and not abs(ev[0] - ev[2]) < 1e-6 * ev[2]:
            It = ev[1] if high_pair else ev[0]
            return float(2.0 * math.pi * It / np.linalg.norm(J @ w))
    return float(2.0 * math.pi / np.linalg.norm(w))


def pab_rate_rad_s(curve, rows=None) -> float:
    """Mean angular rate of the phase-angle bisector over the window, rad/s (per site; the
    largest). The bisector is ``normalize(ŝ + ô)`` with ŝ object→Sun and ô object→observer (ECI);
    its path length on the unit sphere divided by the time it took."""
    rows = np.arange(len(curve)) if rows is None else np.asarray(rows)
    b = curve.obj_to_sun_unit[rows] + curve.obj_to_obs_unit[rows]
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    t = np.asarray(curve.t, float)[rows]
    site = np.asarray(curve.site)[rows]
    best = 0.0
    for s in np.unique(site):
        m = site == s
        if m.sum() < 2:
            continue
        bs, ts = b[m], t[m]
        o = np.argsort(ts)
        bs, ts = bs[o], ts[o]
        ang = np.arccos(np.clip(np.sum(bs[1:] * bs[:-1], axis=1), -1.0, 1.0))
        span = ts[-1] - ts[0]
        if span > 0:
            best = max(best, float(ang.sum() / span))
    return best


def _trend_columns(t, site, degree, t_mid, half):
    """Per-site polynomial columns (n, n_sites·(degree+1)) in τ = (t − t_mid)/half."""
    tau = (t - t_mid) / half
    cols = []
    for s in np.unique(site):
        m = (site == s).astype(float)
        for d in range(degree + 1):
            cols.append(m * tau ** d)
    return np.column_stack(cols)


def _harmonic_columns(t, f, H):
    """(n, 2H) columns cos(2π h f t), sin(2π h f t), h = 1…H."""
    ph = 2.0 * np.pi * f * t
    cols = []
    for h in range(1, H + 1):
        cols.append(np.cos(h * ph))
        cols.append(np.sin(h * ph))
    return np.column_stack(cols)


def _wls_chi2(X, y, w):
    """χ² of the weighted least-squares fit of y on X (weights w = 1/σ²)."""
    sw = np.sqrt(w)
    coef, *_ = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)
    r = (y - X @ coef) * sw
    return float(r @ r), coef


def _pdm_theta(t, r, freqs, nbins=10):
    """Phase-dispersion minimisation statistic θ(f) (Stellingwerf 1978): pooled within-bin
    variance over the total variance of the residuals r, phases in ``nbins`` equal bins."""
    n = r.size
    var_tot = np.var(r, ddof=1)
    theta = np.empty(freqs.size)
    chunk = max(1, int(2_000_000 // max(n, 1)))
    for lo in range(0, freqs.size, chunk):
        f = freqs[lo:lo + chunk]
        ph = np.mod(np.outer(f, t), 1.0)
        b = np.minimum((ph * nbins).astype(np.int64), nbins - 1)
        idx = b + nbins * np.arange(f.size)[:, None]
        cnt = np.bincount(idx.ravel(), minlength=f.size * nbins).reshape(f.size, nbins)
        s1 = np.bincount(idx.ravel(), weights=np.broadcast_to(r, ph.shape).ravel(),
                         minlength=f.size * nbins).reshape(f.size, nbins)
        s2 = np.bincount(idx.ravel(), weights=np.broadcast_to(r * r, ph.shape).ravel(),
                         minlength=f.size * nbins).reshape(f.size, nbins)
        with np.errstate(invalid="ignore", divide="ignore"):
            within = np.where(cnt > 1, s2 - s1 * s1 / np.maximum(cnt, 1), 0.0).sum(axis=1)
            dof = np.where(cnt > 1, cnt - 1, 0).sum(axis=1)
            theta[lo:lo + chunk] = (within / np.maximum(dof, 1)) / var_tot
    return theta


def _site_series(t, r, site):
    """(t, r) of each site with at least two samples, in site order (``t`` sorted)."""
    out = []
    for s in np.unique(site):
        m = site == s
        if int(m.sum()) >= 2:
            out.append((t[m], r[m]))
    return out


def _lag_pairs(t, r, site, tau, max_gap):
    """Pairs (r(tᵢ), r(tᵢ + τ)) of one lag τ, s: r(tᵢ + τ) linearly interpolated within tᵢ's own
    site between two samples at most ``max_gap`` s apart (no pair across a larger gap or past the
    end). ``t`` sorted; returns two arrays."""
    return _lag_pairs_split(_site_series(t, r, site), tau, max_gap)


def _lag_pairs_split(series, tau, max_gap):
    """:func:`_lag_pairs` on the per-site series of :func:`_site_series`."""
    a_out, b_out = [], []
    for ts, rs in series:
        tq = ts + tau
        j = np.searchsorted(ts, tq, side="right")
        ok = (j > 0) & (j < ts.size)
        j = np.where(ok, j, 1)
        t0, t1 = ts[j - 1], ts[j]
        exact = ok & (t0 == tq)
        ok &= ((t1 - t0) <= max_gap) | exact
        frac = np.where(t1 > t0, (tq - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0)
        frac = np.where(exact, 0.0, frac)
        a_out.append(rs[ok])
        b_out.append((rs[j - 1] * (1.0 - frac) + rs[j] * frac)[ok])
    if not a_out:
        return np.empty(0), np.empty(0)
    return np.concatenate(a_out), np.concatenate(b_out)


def _spearman(a, b):
    """Spearman's rank correlation of two samples (average ranks for ties; 0 if constant)."""
    from scipy.stats import rankdata

    ra, rb = rankdata(a), rankdata(b)
    ra -= ra.mean()
    rb -= rb.mean()
    den = math.sqrt(float(ra @ ra) * float(rb @ rb))
    return float(ra @ rb / den) if den > 0 else 0.0


def turn_correlation(t, r, site, lo_s, hi_s, cadence_s):
    """Highest turn-to-turn rank correlation over lags τ ∈ [lo_s, hi_s] (module docstring,
    step 6) → (τ s, ρ, number of pairs). τ on a grid of cadence/20 (at most 401 lags, the
    cost bound of a long recording); lags with fewer than 10 pairs are skipped (ρ = nan,
    0 pairs when none qualifies)."""
    step = cadence_s / 20.0
    n_lag = int(min(401, max(1, math.floor((hi_s - lo_s) / step) + 1)))
    best = (float("nan"), float("nan"), 0)
    series = _site_series(t, r, site)
    for tau in np.linspace(lo_s, hi_s, n_lag) if n_lag > 1 else [0.5 * (lo_s + hi_s)]:
        a, b = _lag_pairs_split(series, float(tau), 2.0 * cadence_s)
        if a.size < 10:
            continue
        rho = _spearman(a, b)
        if not best[2] or rho > best[1]:
            best = (float(tau), rho, int(a.size))
    return best


def _fisher_z_gain(rho_k, n_k, rho_0, n_0):
    """Standard-normal score of ρ_k > ρ_0 for two Spearman coefficients treated as independent
    (Fisher z, standard error 1.06/√(n − 3); module docstring, step 6); ``n_0`` None: ρ_0 is a
    fixed value, not an estimate."""
    clip = 1.0 - 1e-12
    se = SPEARMAN_SE_FACTOR * math.sqrt(1.0 / max(n_k - 3, 1)
                                        + (0.0 if n_0 is None else 1.0 / max(n_0 - 3, 1)))
    return float((math.atanh(max(-clip, min(clip, rho_k)))
                  - math.atanh(max(-clip, min(clip, rho_0)))) / se)


def _local_peaks(power, k):
    """Indices of the k largest local maxima of ``power`` (interior points)."""
    if power.size < 3:
        return np.array([int(np.argmax(power))])
    p = power
    is_pk = np.r_[p[0] > p[1], (p[1:-1] >= p[:-2]) & (p[1:-1] >= p[2:]), p[-1] > p[-2]]
    idx = np.flatnonzero(is_pk)
    return idx[np.argsort(p[idx])[::-1][:k]]


@dataclass
class PeriodResult:
    """Spin-period analysis of one lightcurve (see the module docstring for the method).

    Periods in s, frequencies in Hz. ``period_s`` is the brightness (synodic) period: the
    fundamental of the chosen multi-harmonic model. ``interval_99_s`` is the 99 % interval of the
    sidereal period (±2.576σ plus the synodic bound). ``aliases`` lists other periods that fit
    (relation to the best, ΔBIC ≥ 0, harmonics used), best first.

    The stated spin period (module docstring, step 6): ``spin_period_s`` (the chosen candidate's
    period), ``spin_interval_99_s`` (its 99 % interval), ``spin_relation`` (which candidate:
    "best", "3x best", ...) and ``spin_turn_correlation`` (per scored candidate: relation,
    period_s, interval_99_s, lag_s, rho, n_pairs, z against the best period, z_below_chosen,
    not_ruled_out; the best's entry also z_repeat, the score of its ρ > 0).
    """

    period_s: float
    period_sigma_s: float
    n_harmonics: int
    synodic_bound_s: float
    interval_99_s: tuple
    false_alarm_probability: float
    chi2_dof: float
    aliases: list
    ls_period_s: float
    pdm_period_s: float
    pab_rate_rad_s: float
    n_points: int
    span_s: float
    n_clipped: int
    frequency_hz: np.ndarray = field(repr=False)
    power_ls: np.ndarray = field(repr=False)
    theta_pdm: np.ndarray = field(repr=False)
    fold: dict = field(repr=False, default_factory=dict)
    spin_period_s: float = float("nan")
    spin_interval_99_s: tuple = (float("nan"), float("nan"))
    spin_relation: str = "best"
    spin_turn_correlation: list = field(default_factory=list)

    @property
    def candidates(self) -> list:
        """The periods the data cannot tell apart: the best and every alias with ΔBIC ≤
        :data:`INDISTINGUISHABLE_DBIC` (dicts: period_s, relation, delta_bic, interval_99_s)."""
        best = {"period_s": self.period_s, "relation": "best", "delta_bic": 0.0,
                "n_harmonics": self.n_harmonics, "interval_99_s": tuple(self.interval_99_s)}
        return [best] + [a for a in self.aliases if a["delta_bic"] <= INDISTINGUISHABLE_DBIC]

    @property
    def spin_candidates(self) -> list:
        """The spin periods this analysis states: :attr:`candidates` plus the listed integer
        multiples 2, 3 and 4 × the best period, whatever their ΔBIC (each with its 99 %
        interval). A faceted body's brightness may repeat k times per turn; a fit of the
        brightness cannot tell k when the brightness does not repeat exactly from turn to turn
        (the phase-angle bisector moves over the pass), so the lightcurve alone does not rule
        them out; their ΔBIC says how much the data prefer the shorter period."""
        out = list(self.candidates)
        for a in self.aliases:
            if a["relation"] in SPIN_MULTIPLE_RELATIONS and a not in out:
                out.append(a)
        return out

    @property
    def spin_alternatives(self) -> list:
        """The other spin candidates the turn-to-turn correlation does not rule out (ρ not
        significantly below the chosen one's, one-sided 1 %) that the data also cannot tell apart
        by the fit (ΔBIC ≤ :data:`INDISTINGUISHABLE_DBIC`) or that are integer multiples of the
        best period — dicts of :attr:`spin_turn_correlation`."""
        return [c for c in self.spin_turn_correlation
                if c["not_ruled_out"] and c["relation"] != self.spin_relation]

    @property
    def spin_set_99_s(self) -> list:
        """The stated 99 % set of the spin period, s: the union of the chosen spin period's
        99 % interval and those of the :attr:`spin_alternatives` (the candidates the turn-to-turn
        test does not rule out at 1 %), as sorted, merged ``(lo, hi)`` pairs. A confidence set
        by test inversion: every candidate the data do not reject at the 1 % level keeps its
        interval. One pair when nothing else is left standing; several when the lightcurve
        cannot tell the periods apart (a body that looks the same after half a turn)."""
        ivs = sorted([tuple(self.spin_interval_99_s)]
                     + [tuple(c["interval_99_s"]) for c in self.spin_alternatives])
        out = []
        for lo, hi in ivs:
            if out and lo <= out[-1][1]:
                out[-1] = (out[-1][0], max(out[-1][1], hi))
            else:
                out.append((float(lo), float(hi)))
        return out

    def contains_spin(self, period_s, alternatives: bool = False) -> bool:
        """True when ``period_s`` lies in the 99 % interval of the stated spin period
        (``alternatives``: in the 99 % set :attr:`spin_set_99_s`, which adds the intervals of
        the :attr:`spin_alternatives`)."""
        ivs = self.spin_set_99_s if alternatives else [self.spin_interval_99_s]
        return any(lo <= period_s <= hi for lo, hi in ivs)

    @property
    def ambiguous(self) -> bool:
        """True when another period cannot be ruled out (ΔBIC ≤ :data:`INDISTINGUISHABLE_DBIC`)."""
        return len(self.candidates) > 1

    def contains(self, period_s, multiples: bool = False) -> bool:
        """True when ``period_s`` lies in the 99 % interval of one of the :attr:`candidates`
        (``multiples``: of one of the :attr:`spin_candidates`)."""
        cands = self.spin_candidates if multiples else self.candidates
        return any(c["interval_99_s"][0] <= period_s <= c["interval_99_s"][1] for c in cands)

    @property
    def significant(self) -> bool:
        """True when the periodic signal is significant at the 1 % false-alarm level."""
        return bool(self.false_alarm_probability < 0.01)

    def __repr__(self):
        return (f"PeriodResult(period_s={self.period_s:.4g} ± {self.period_sigma_s:.2g}, "
                f"H={self.n_harmonics}, 99% sidereal [{self.interval_99_s[0]:.4g}, "
                f"{self.interval_99_s[1]:.4g}] s, FAP={self.false_alarm_probability:.2g}, "
                f"{len(self.aliases)} aliases; spin {self.spin_period_s:.4g} s "
                f"({self.spin_relation}) 99% [{self.spin_interval_99_s[0]:.4g}, "
                f"{self.spin_interval_99_s[1]:.4g}] s)")

    def summary(self) -> dict:
        """JSON-ready summary (no arrays)."""
        return {"period_s": self.period_s, "period_sigma_s": self.period_sigma_s,
                "n_harmonics": self.n_harmonics, "synodic_bound_s": self.synodic_bound_s,
                "interval_99_s": list(self.interval_99_s),
                "false_alarm_probability": self.false_alarm_probability,
                "significant": self.significant, "chi2_dof": self.chi2_dof,
                "ambiguous": self.ambiguous,
                "candidates": [dict(c, interval_99_s=list(c["interval_99_s"]))
                               for c in self.candidates],
                "spin_candidates": [dict(c, interval_99_s=list(c["interval_99_s"]))
                                    for c in self.spin_candidates],
                "spin_period_s": self.spin_period_s,
                "spin_interval_99_s": list(self.spin_interval_99_s),
                "spin_set_99_s": [list(iv) for iv in self.spin_set_99_s],
                "spin_relation": self.spin_relation,
                "spin_turn_correlation": [dict(c, interval_99_s=list(c["interval_99_s"]))
                                          for c in self.spin_turn_correlation],
                "ls_period_s": self.ls_period_s, "pdm_period_s": self.pdm_period_s,
                "pab_rate_deg_s": math.degrees(self.pab_rate_rad_s),
                "n_points": self.n_points, "span_s": self.span_s, "n_clipped": self.n_clipped,
                "aliases": [dict(a, interval_99_s=list(a["interval_99_s"])) for a in self.aliases]}

    def rate_candidates(self, max_delta_bic=10.0, multiples=(2,), multiple_weight=0.25):
        """Spin-rate magnitude candidates for a rate prior, list of dicts.

        Each: ``omega_rad_s`` (2π/P), ``halfwidth_rad_s`` (2π × the best period's synodic bound
        / P², i.e. the bisector's rate ω_PAB at the best period and ω_PAB (P_best/P)² at
        another candidate — narrower than the rate bound ω_PAB itself, which is the same for
        every candidate; a sampler-efficiency choice kept because the prior with ω_PAB for every
        candidate made the rocket body's first sampler attempts miss, docs/acquisition.md),
        ``sigma_rad_s`` (statistical 1σ in rate), ``weight`` (normalised) and ``relation``.
        The best period and every alias with ΔBIC ≤ ``max_delta_bic`` (weights ∝ e^{−ΔBIC/2});
        ``multiples`` adds k × the best period with ``multiple_weight`` × the best's weight
        (bodies whose brightness repeats k times per turn). Empty when the period is not
        significant.
        """
        if not self.significant:
            return []
        out = []

        def add(P, dbic, relation, w=None):
            om = 2.0 * math.pi / P
            frac = self.period_sigma_s / self.period_s
            hw = 2.0 * math.pi * self.synodic_bound_s / P ** 2
            if any(abs(c["omega_rad_s"] - om) < 1e-9 * om for c in out):
                return
            out.append({"omega_rad_s": om, "halfwidth_rad_s": hw, "sigma_rad_s": om * frac,
                        "weight": math.exp(-0.5 * dbic) if w is None else w,
                        "relation": relation})

        add(self.period_s, 0.0, "best")
        for a in self.aliases:
            if a["delta_bic"] <= max_delta_bic:
                add(a["period_s"], a["delta_bic"], a["relation"])
        for k in multiples:
            add(k * self.period_s, 0.0, f"{k}x best", w=multiple_weight)
        tot = sum(c["weight"] for c in out)
        for c in out:
            c["weight"] /= tot
        return out

    def plot(self, path, title=None, true_period_s=None) -> Path:
        """Periodogram (Lomb–Scargle power and PDM 1−θ against period) and the folded
        lightcurve with the multi-harmonic fit; PNG written atomically. ``title`` is put above
        the result line; ``true_period_s`` (a simulation's truth) is marked when given."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from ..io.atomic import atomic_path

        fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 7), constrained_layout=True)
        P = 1.0 / self.frequency_hz
        a1.plot(P, self.power_ls, lw=1.0, color="C0", label="Lomb–Scargle power (1 harmonic)")
        a1.plot(P, 1.0 - self.theta_pdm, lw=1.0, color="C1", alpha=0.8, label="PDM 1 − θ")
        a1.axvspan(*self.interval_99_s, color="C2", alpha=0.2, label="99 % sidereal interval")
        a1.axvline(self.period_s, color="C2", lw=1.5, label=f"best {self.period_s:.4g} s")
        for a in self.aliases[:4]:
            a1.axvline(a["period_s"], color="0.5", lw=0.8, ls="--")
            a1.text(a["period_s"], 0.98, a["relation"], rotation=90, va="top", ha="right",
                    fontsize=7, color="0.35", transform=a1.get_xaxis_transform())
        if true_period_s is not None and np.isfinite(true_period_s):
            a1.axvline(true_period_s, color="k", lw=1.2, ls=":",
                       label=f"truth {true_period_s:.4g} s")
        a1.set_xscale("log")
        from matplotlib.ticker import LogLocator, ScalarFormatter

        a1.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        a1.xaxis.set_major_formatter(ScalarFormatter())
        a1.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        a1.set_xlabel("period (s)")
        a1.set_ylabel("power")
        a1.set_ylim(bottom=0)
        a1.legend(fontsize=8, loc="best", framealpha=0.85)
        fd = self.fold
        if fd:
            a2.errorbar(fd["phase"], fd["resid"], yerr=fd["sigma"], fmt=".", ms=3, lw=0.5,
                        color="C0", alpha=0.7, label="detrended reduced magnitude")
            a2.plot(fd["model_phase"], fd["model"], color="C3", lw=1.5,
                    label=f"{self.n_harmonics}-harmonic fit")
            a2.invert_yaxis()
            a2.set_xlabel(f"phase (period {self.period_s:.4g} s)")
            a2.set_ylabel("Δ magnitude")
            a2.legend(fontsize=8)
        sig = "significant" if self.significant else "NOT significant"
        line = (f"spin period {self.period_s:.4g} ± {self.period_sigma_s:.2g} s "
                f"({sig}, FAP {self.false_alarm_probability:.1e}); sidereal 99 %: "
                f"{self.interval_99_s[0]:.4g}–{self.interval_99_s[1]:.4g} s")
        fig.suptitle(f"{title}\n{line}" if title else line, fontsize=10)
        path = Path(path)
        with atomic_path(path, suffix=".png") as tmp:
            fig.savefig(tmp, dpi=110, format="png")
        plt.close(fig)
        return path


def analyse_period(curve, *, min_period_s=None, max_period_s=None, max_harmonics=6,
                   trend_degree=2, oversample=20, n_peaks=6, pdm_bins=10,
                   clip_mad=3.0) -> PeriodResult:
    """Spin-period analysis of a lightcurve (module docstring).

    Parameters
    ----------
    curve : lightcurve.io.lightcurve_h5.Lightcurve
        Rows with a finite magnitude are used (at least 12).
    min_period_s, max_period_s : float, optional
        Search range, s (defaults: 2.5 × median cadence; span / 1.5).
    max_harmonics : int ≥ 1
        Most harmonics of the multi-harmonic model.
    trend_degree : int ≥ 0
        Degree of the per-site polynomial trend in time.
    oversample : int ≥ 1
        Frequency-grid points per 1/span.
    n_peaks : int ≥ 1
        Periodogram peaks (Lomb–Scargle and PDM each) whose sub-harmonics are candidates.
    pdm_bins : int ≥ 2
        Phase bins of the PDM statistic.
    clip_mad : float > 0 or None
        Detrended magnitudes beyond this many robust standard deviations are winsorised
        (glints); None keeps every value as it is.

    Returns
    -------
    PeriodResult
    """
    from astropy.timeseries import LombScargle
    from scipy import stats
    from scipy.optimize import least_squares

    mag = np.asarray(curve.mag, float)
    rows = np.flatnonzero(np.isfinite(mag))
    if rows.size < 12:
        raise InputError("period analysis needs at least 12 finite magnitudes", field="mag",
                         value=int(rows.size), allowed=">= 12")
    for name, v, lo in (("max_harmonics", max_harmonics, 1), ("trend_degree", trend_degree, 0),
                        ("oversample", oversample, 1), ("n_peaks", n_peaks, 1),
                        ("pdm_bins", pdm_bins, 2)):
        if int(v) != v or v < lo:
            raise InputError("must be an integer", field=name, value=v, allowed=f">= {lo}")
    if clip_mad is not None and not (np.isfinite(clip_mad) and clip_mad > 0):
        raise InputError("must be a positive number or None", field="clip_mad", value=clip_mad,
                         allowed="> 0 (robust standard deviations), or None")
    t_all = np.asarray(curve.t, float)[rows]
    order = np.argsort(t_all, kind="stable")
    rows = rows[order]
    t = t_all[order]
    y = reduced_magnitude(curve)[rows]
    sig = np.asarray(curve.mag_sigma, float)[rows]
    if np.any(~(sig > 0)) or not np.all(np.isfinite(sig)):
        raise InputError("mag_sigma must be finite and > 0 where a magnitude is given",
                         field="mag_sigma", allowed="> 0")
    site = np.asarray(curve.site)[rows]
    w = 1.0 / sig ** 2
    span = float(t[-1] - t[0])
    dts = np.diff(t)
    dts = dts[dts > 0]
    if span <= 0 or dts.size == 0:
        raise InputError("the lightcurve spans no time", field="t")
    dt_med = float(np.median(dts))
    f_nyq = 0.5 / dt_med
    pmin = 2.5 * dt_med if min_period_s is None else float(min_period_s)
    pmax = span / 1.5 if max_period_s is None else float(max_period_s)
    if not (np.isfinite(pmin) and np.isfinite(pmax) and 0 < pmin < pmax):
        raise InputError("period search range must satisfy 0 < min < max", field="period range",
                         value=(pmin, pmax), allowed=f"e.g. [{2.5 * dt_med:.3g}, {span / 1.5:.3g}] s")
    f_lo, f_hi = 1.0 / pmax, 1.0 / pmin
    df = 1.0 / (oversample * span)
    n_freq = (f_hi - f_lo) / df
    if n_freq > MAX_FREQUENCIES:
        raise InputError(
            f"the period search would need {n_freq:.3g} trial frequencies (span {span:.4g} s, "
            f"periods {pmin:.3g}–{pmax:.3g} s): analyse one pass at a time or narrow the range "
            "(--min-period-s/--max-period-s)", field="period range", value=(pmin, pmax),
            allowed=f"at most {MAX_FREQUENCIES} frequencies, i.e. (1/min − 1/max) · span · "
            f"{oversample} ≤ {MAX_FREQUENCIES}")
    freqs = np.arange(f_lo, f_hi + 0.5 * df, df)
    if freqs.size < 3:
        raise InputError("period search range too narrow for this span", field="period range",
                         value=(pmin, pmax))

    t_mid, half = 0.5 * (t[0] + t[-1]), max(0.5 * span, 1e-9)
    T = _trend_columns(t, site, int(trend_degree), t_mid, half)
    chi2_trend, ctr = _wls_chi2(T, y, w)
    resid = y - T @ ctr
    n = y.size
    n_clipped = 0
    if clip_mad is not None:
        lim = float(clip_mad) * 1.4826 * float(np.median(np.abs(resid - np.median(resid))))
        if lim > 0:
            clipped = np.clip(resid, -lim, lim)
            n_clipped = int(np.count_nonzero(clipped != resid))
            if n_clipped:
                y = T @ ctr + clipped
                chi2_trend, ctr = _wls_chi2(T, y, w)
                resid = y - T @ ctr

    # --- 2. Lomb–Scargle and PDM on the detrended residuals ----------------------------
    ls = LombScargle(t, resid, sig, nterms=1, fit_mean=True, center_data=True)
    p_ls = np.asarray(ls.power(freqs), float)
    theta = _pdm_theta(t, resid, freqs, nbins=int(pdm_bins))
    cand_f = set()
    for i in np.r_[_local_peaks(p_ls, n_peaks), _local_peaks(1.0 - theta, n_peaks)]:
        for j in range(1, int(max_harmonics) + 1):
            fc = freqs[i] / j
            if f_lo - 1e-12 <= fc <= f_hi + 1e-12:
                cand_f.add(float(fc))

    # --- 3. multi-harmonic model choice by BIC -----------------------------------------
    def hmax(f):
        return max(1, min(int(max_harmonics), int(np.floor(f_nyq / f * (1 - 1e-9)))))

    def bic_at(f, H):
        X = np.column_stack([T, _harmonic_columns(t, f, H)])
        c2, _ = _wls_chi2(X, y, w)
        # Gaussian likelihood with the noise scale free (the misfit of a periodic model to a
        # real pass usually exceeds the stated noise): BIC = n ln(χ²/n) + k ln n
        return n * math.log(max(c2, 1e-300) / n) + (X.shape[1] + 2) * math.log(n), c2

    def refine(f0):
        """Best (bic, f, H, chi2) near f0 on a local grid of ±1.5 grid steps."""
        best = None
        for f in f0 + df * np.linspace(-1.5, 1.5, 13):
            if f <= 0:
                continue
            for H in range(1, hmax(f) + 1):
                b, c2 = bic_at(f, H)
                if best is None or b < best[0]:
                    best = (b, float(f), H, c2)
        return best

    fits = [r for r in (refine(fc) for fc in sorted(cand_f)) if r is not None]
    fits.sort(key=lambda r: r[0])
    b0, f0, H0, chi2_0 = fits[0]

    # --- 4. non-linear refinement and uncertainty ------------------------------------------
    sw = np.sqrt(w)

    def resfun(p):
        f = p[0]
        X = np.column_stack([T, _harmonic_columns(t, f, H0)])
        return (y - X @ p[1:]) * sw

    X0 = np.column_stack([T, _harmonic_columns(t, f0, H0)])
    _, coef0 = _wls_chi2(X0, y, w)
    sol = least_squares(resfun, np.r_[f0, coef0], method="lm", x_scale="jac")
    f_best = float(sol.x[0]) if abs(sol.x[0] - f0) < 3 * df else f0
    chi2_best = float(2.0 * sol.cost) if f_best != f0 else chi2_0
    dof = max(n - (X0.shape[1] + 1), 1)
    chi2_dof = chi2_best / dof
    J = sol.jac
    try:
        cov = np.linalg.inv(J.T @ J)
        sf = math.sqrt(max(cov[0, 0], 0.0)) * math.sqrt(max(1.0, chi2_dof))
    except np.linalg.LinAlgError:
        sf = df
    P_best = 1.0 / f_best
    sP = sf / f_best ** 2

    # --- 5. significance --------------------------------------------------------------
    p_harm = 2 * H0
    Fstat = ((chi2_trend - chi2_best) / p_harm) / (chi2_best / dof)
    p_single = float(stats.f.sf(Fstat, p_harm, dof)) if Fstat > 0 else 1.0
    n_indep = max(1.0, (f_hi - f_lo) * span)
    fap = float(-np.expm1(n_indep * np.log1p(-min(p_single, 1.0 - 1e-16)))) \
        if p_single < 1.0 else 1.0

    # synodic bound and the sidereal interval
    pab = pab_rate_rad_s(curve, rows)
    dP_syn = pab * P_best ** 2 / (2.0 * math.pi)

    def interval(P):
        """99 % interval of a sidereal period P: the synodic bound plus ±2.576σ, σ at the best
        period's relative precision."""
        half = pab * P ** 2 / (2.0 * math.pi) + Z99 * sP * P / P_best
        return (float(max(P - half, 1e-12)), float(P + half))

    lo, hi = interval(P_best)

    # aliases: other candidate fits and simple ratios of the best period
    aliases = []

    def relation(P):
        r = P / P_best
        for num in range(1, 7):
            for den in range(1, 7):
                if math.gcd(num, den) == 1 and abs(r - num / den) < 0.02 * num / den:
                    return "best" if num == den else (f"{num}x best" if den == 1 else
                                                      f"{num}/{den} x best")
        return f"{r:.3g} x best"

    seen = [P_best]

    def distinct(P):
        """Not within one frequency resolution element (1/span) of a listed period."""
        return all(abs(1.0 / P - 1.0 / s) > 1.0 / span for s in seen)

    for r in [(fits[i][0], fits[i][1], fits[i][2]) for i in range(1, len(fits))]:
        P = 1.0 / r[1]
        if distinct(P):
            seen.append(P)
            aliases.append({"period_s": P, "relation": relation(P),
                            "delta_bic": float(r[0] - b0), "n_harmonics": int(r[2]),
                            "interval_99_s": interval(P)})
    for k in (2, 3, 4):
        # always scored and listed (step 3), also beside a fitted alias in the same resolution
        # element: the integer multiples are the candidates a faceted body's turn implies
        P = k * P_best
        if P <= pmax * 1.5 and not any(a["relation"] == f"{k}x best" for a in aliases):
            f = 1.0 / P
            best = min((bic_at(f, H) + (H,) for H in range(1, hmax(f) + 1)), key=lambda x: x[0])
            seen.append(P)
            aliases.append({"period_s": P, "relation": f"{k}x best",
                            "delta_bic": float(best[0] - b0), "n_harmonics": int(best[2]),
                            "interval_99_s": interval(P)})
    aliases.sort(key=lambda a: a["delta_bic"])
    # at most 8 listed, the integer multiples 2–4 always among them (step 3)
    mult = [a for a in aliases if a["relation"] in SPIN_MULTIPLE_RELATIONS]
    rest = [a for a in aliases if a["relation"] not in SPIN_MULTIPLE_RELATIONS]
    aliases = sorted(mult + rest[:max(0, 8 - len(mult))], key=lambda a: a["delta_bic"])

    # --- 6. spin period: turn-to-turn rank correlation over the candidates ---------------
    spin = []
    cands6 = [("best", P_best, (float(lo), float(hi)))] + [
        (a["relation"], a["period_s"], tuple(a["interval_99_s"])) for a in aliases
        if a["delta_bic"] <= INDISTINGUISHABLE_DBIC or a["relation"] in SPIN_MULTIPLE_RELATIONS]
    for rel_, P, iv in cands6:
        if P > 0.5 * span:          # fewer than two turns in the window: no turn-to-turn test
            continue
        tau, rho, npair = turn_correlation(t, resid, site, max(iv[0], dt_med), iv[1], dt_med)
        if npair:
            spin.append({"relation": rel_, "period_s": float(P), "interval_99_s": iv,
                         "lag_s": tau, "rho": rho, "n_pairs": npair})
    spin_rel, spin_P, spin_iv = "best", P_best, (float(lo), float(hi))
    if spin and spin[0]["relation"] == "best":
        b6 = spin[0]
        for c in spin:
            c["z"] = _fisher_z_gain(c["rho"], c["n_pairs"], b6["rho"], b6["n_pairs"])
        b6["z_repeat"] = _fisher_z_gain(b6["rho"], b6["n_pairs"], 0.0, None)
        top = max(spin, key=lambda c: c["rho"])
        chosen = top if (b6["z_repeat"] <= Z_ONE_SIDED_01 and top["z"] > Z_ONE_SIDED_01) \
            else b6
        for c in spin:
            c["z_below_chosen"] = _fisher_z_gain(chosen["rho"], chosen["n_pairs"], c["rho"],
                                                 c["n_pairs"])
            c["not_ruled_out"] = bool(c["z_below_chosen"] <= Z_ONE_SIDED_01)
        spin_rel, spin_P, spin_iv = chosen["relation"], chosen["period_s"], chosen["interval_99_s"]
    else:                            # the best period itself cannot be tested: it stays
        for c in spin:
            c["z"] = c["z_below_chosen"] = float("nan")
            c["not_ruled_out"] = True

    # folded data and model for the plot
    Xb = np.column_stack([T, _harmonic_columns(t, f_best, H0)])
    _, cb = _wls_chi2(Xb, y, w)
    ntr = T.shape[1]
    r_fold = y - T @ cb[:ntr]
    ph = np.mod(t * f_best, 1.0)
    mp = np.linspace(0, 1, 200)
    mod = _harmonic_columns(mp / f_best, f_best, H0) @ cb[ntr:]
    fold = {"phase": ph, "resid": r_fold, "sigma": sig, "model_phase": mp, "model": mod}

    return PeriodResult(
        period_s=P_best, period_sigma_s=float(sP), n_harmonics=int(H0),
        synodic_bound_s=float(dP_syn), interval_99_s=(float(lo), float(hi)),
        false_alarm_probability=fap, chi2_dof=float(chi2_dof), aliases=aliases,
        ls_period_s=float(1.0 / freqs[int(np.argmax(p_ls))]),
        pdm_period_s=float(1.0 / freqs[int(np.argmin(theta))]),
        pab_rate_rad_s=float(pab), n_points=int(n), span_s=span, n_clipped=n_clipped,
        frequency_hz=freqs,
        power_ls=p_ls, theta_pdm=theta, fold=fold, spin_period_s=float(spin_P),
        spin_interval_99_s=(float(spin_iv[0]), float(spin_iv[1])), spin_relation=spin_rel,
        spin_turn_correlation=spin)
