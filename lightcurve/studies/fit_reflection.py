"""Batch Bayesian posterior of facet reflection parameters with emcee (`lightcurve fit-reflection`).

Given a lightcurve and a *known* attitude history (the file's truth, or a filter estimate), the
posterior of the Cook–Torrance parameters of the facets is sampled with the affine-invariant
ensemble sampler (:mod:`lightcurve.estimation.mcmc`).

Parameters and reparameterisation (Bernard eq. 8.41–8.44 style)
----------------------------------------------------------------
Per fitted facet i the physical parameters are ξ_i ∈ (0,1) (diffuse fraction), a_i = F0 ∈ (0,1)
(albedo / normal-incidence reflectance), m_i > 0 (Beckmann rms slope) and A_i > 0 (area, m²).
The sampler works in unbounded coordinates

    z_ξ = logit ξ,  z_a = logit a,  z_m = ln m,  z_A = ln A,

so every sample is in range. (m is bounded above by 1 in the shape files; the log map lets
m exceed 1, where the Beckmann formula is still defined — stated, not hidden.)

Prior (from the shape file): in the *physical* parameters, the distribution of the truth
perturbation of Bernard §10.1 — p ~ N(p₀, (``prior_frac`` · p₀)²) (default 10 %) truncated to
the parameter's range, p₀ the shape file's value — carried to z with the Jacobian of the
transform, log π(z) = log π(p(z)) + log |dp/dz| (|dp/dz| = p(1−p) for the logits, p for the
logs). The prior width in z used by the identifiability ratio is the standard deviation of
20 000 seeded prior draws mapped to z.

Likelihood: independent Gaussian magnitude errors with the file's ``mag_sigma``; the model is
the DESIGN.md magnitude equation with the attitude held fixed, evaluated by a numba kernel over
all walkers at once. Epochs without a finite magnitude, or where no facet is both lit and
visible for the given attitude (zero modelled flux whatever the parameters), are dropped and
counted. ``mag_sigma`` is held fixed: the simulator records σ = |m_true| r/300 (eq. 9.3), so
strictly σ depends on the parameters; letting it follow m(θ) changes the log likelihood by
≈ 0.01 (sd over the posterior of a 24-parameter, 300-epoch case) — negligible, not modelled.

Calibration: :func:`reflection_sbc` runs simulation-based calibration (truths drawn from
this prior, data from the simulator, posterior from :func:`fit_reflection`); the posterior CDF
at the truth must be uniform. Checked in ``tests/studies/test_studies_fit_reflection_sbc.py``
(2 parameters, 40 runs) and ``benchmarks/reflection_emcee.py`` (4 and 8 parameters).

Diagnostics
-----------
* convergence: autocorrelation time and acceptance (:func:`~lightcurve.estimation.mcmc.
  chain_diagnostics`); a posterior that has not converged is **refused** with
  :class:`ConvergenceError` naming the reasons (unless ``allow_unconverged=True``);
* identifiability: ``width_ratio`` = posterior sd / prior sd in z; a parameter is called
  *identified* when the data shrink its width by at least 2× (ratio < ``identify_ratio`` = 0.5,
  our criterion for thesis fig. 10.11f);
* posterior predictive lightcurve: quantile bands of the noise-free model and of model + noise
  over posterior draws, and the fraction of measurements inside the central 95 % band.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numba as nb
import numpy as np

from ..core.photometry import cook_torrance_xyz
from ..errors import ConvergenceError, InputError
from ..photometry.perturb import perturb_reflection

__all__ = ["KINDS", "ReflectionPosteriorModel", "ReflectionFit", "fit_reflection",
           "synthetic_reflection_case", "perturb_reflection", "reflection_sbc"]

KINDS = ("xi", "a", "m", "A")
_LOGIT = ("xi", "a")


# --------------------------------------------------------------------------------------------
# numba kernel: magnitudes of W parameter sets at N epochs
# --------------------------------------------------------------------------------------------

@nb.njit(cache=True)
def _walker_mags_nb(ns, no, nh, c, fidx, xi, a, m, A, fixed_flux, offset):
    """(W,N) magnitudes: offset_k − 2.5 log10(fixed_k + Σ_j A_wj P(ξ_wj, a_wj, m_wj)).

    ns, no, nh: (N,F) n̂·ŝ, n̂·ô, n̂·ĥ (body axes); c: (N,) ô·ĥ; fidx: (K,) facet indices of the
    fitted Cook–Torrance facets; xi, a, m, A: (W,K); fixed_flux (N,) m² sr⁻¹ of the other facets;
    offset (N,) mag. +inf where the flux is zero.
    """
    W = xi.shape[0]
    N = ns.shape[0]
    K = fidx.shape[0]
    out = np.empty((W, N))
    for w in range(W):
        for k in range(N):
            s = fixed_flux[k]
            for j in range(K):
                f = fidx[j]
                if ns[k, f] > 0.0 and no[k, f] > 0.0:
                    s += A[w, j] * cook_torrance_xyz(ns[k, f], no[k, f], nh[k, f], c[k],
                                                     xi[w, j], a[w, j], m[w, j], False)[0]
            out[w, k] = offset[k] - 2.5 * np.log10(s) if s > 0.0 else np.inf
    return out


# --------------------------------------------------------------------------------------------
# The posterior model
# --------------------------------------------------------------------------------------------

class ReflectionPosteriorModel:
    """Log posterior of facet reflection parameters given a lightcurve and a fixed attitude.

    Parameters
    ----------
    shape : lightcurve.photometry.Shape — nominal parameters (prior centres) and geometry.
    curve : Lightcurve — times, magnitudes, ``mag_sigma`` and observation geometry (ECI).
    q : (N,4) inertial→body attitude (scalar first) at ``curve.t``.
    facets : sequence of int or None — facets to fit (default: every Cook–Torrance facet with
        area > 0). Non-Cook–Torrance facets cannot be fitted (InputError).
    kinds : subset of ("xi", "a", "m", "A") — parameters fitted per facet.
    prior_frac : float > 0 — physical prior 1σ as a fraction of the nominal value.

    Attributes
    ----------
    names : list[str], e.g. ``"xi[5]"`` (kind[facet index]); ``dim`` = len(names)
    p_nominal, z_nominal, prior_sd_z : (D,)
    used : (N,) bool epochs used; ``n_dropped`` epochs dropped (see module docstring)
    """

    def __init__(self, shape, curve, q, *, facets=None, kinds=KINDS, prior_frac=0.1):
        from ..filters.models import MagnitudeModel
        from ..filters.facet_states import check_kinds, select_ct_facets
        from ..photometry.magnitude import body_directions

        self.kinds = kinds = check_kinds(kinds)
        self.prior_frac = float(prior_frac)
        if not (self.prior_frac > 0 and np.isfinite(self.prior_frac)):
            raise InputError("prior fraction must be > 0", field="prior_frac", value=prior_frac)
        fidx = select_ct_facets(shape, facets, "fitted")
        F = shape.n_facets
        self.shape = shape
        self.fidx = np.ascontiguousarray(fidx, dtype=np.int64)
        K = self.fidx.size
        self.nominal = {"xi": shape.params[fidx, 0].copy(), "a": shape.params[fidx, 1].copy(),
                        "m": shape.params[fidx, 2].copy(), "A": shape.areas_m2[fidx].copy()}
        self.names, self._slot = [], []
        for kind in kinds:
            for j in range(K):
                self.names.append(f"{kind}[{int(fidx[j])}]")
                self._slot.append((kind, j))
        self.dim = len(self.names)
        # (slot indices d, facet positions j) per kind, for facet_arrays
        self._fill = {k: (np.array([d for d, (kk, _) in enumerate(self._slot) if kk == k], int),
                          np.array([j for kk, j in self._slot if kk == k], int)) for k in KINDS}
        self.p_nominal = np.array([self.nominal[k][j] for k, j in self._slot])
        for (k, j), p in zip(self._slot, self.p_nominal):
            lo_ok = p > 0
            hi_ok = p < 1 if k in _LOGIT else True
            if not (lo_ok and hi_ok and np.isfinite(p)):
                raise InputError("nominal parameter outside the open range its transform needs",
                                 field=f"{k}[{int(fidx[j])}]", value=float(p),
                                 allowed="(0, 1)" if k in _LOGIT else "> 0")
        self.z_nominal = self.to_z(self.p_nominal)
        self._logit = np.array([k in _LOGIT for k, _ in self._slot])
        self.prior_sd_p = self.prior_frac * self.p_nominal
        # prior width in z: sd of truncated-normal prior draws mapped to z (seeded)
        prng = np.random.default_rng(0x9A1)
        draws = self.p_nominal + self.prior_sd_p * prng.standard_normal((20000, self.dim))
        ok = (draws > 0) & ((draws < 1) | ~self._logit)
        zd = self.to_z(np.where(ok, draws, self.p_nominal))
        self.prior_sd_z = np.array([np.std(zd[ok[:, d], d]) for d in range(self.dim)])

        # geometry in body axes with the attitude held fixed
        q = np.asarray(q, float)
        N = len(curve)
        if q.shape != (N, 4) or not np.all(np.isfinite(q)):
            raise InputError("attitude history must be finite (N,4) at the lightcurve times",
                             field="q", value=q.shape, allowed=f"({N}, 4)")
        mm = MagnitudeModel(shape, curve)
        sb, ob = body_directions(q / np.linalg.norm(q, axis=1, keepdims=True),
                                 mm.s_eci, mm.o_eci)
        sb, ob = sb[:, 0, :], ob[:, 0, :]
        nrm = shape.normals_body
        ns = sb @ nrm.T
        no = ob @ nrm.T
        wv = sb + ob
        wn = np.linalg.norm(wv, axis=1)
        h = wv / np.where(wn > 0, wn, 1.0)[:, None]
        nh = h @ nrm.T
        c = 0.5 * wn
        # flux of the facets that are not fitted (any BRDF), with the nominal shape
        from ..photometry.partials import facet_products

        P_all = facet_products(shape, sb, ob)                           # (N,F)
        other = np.ones(F, bool)
        other[self.fidx] = False
        fixed = P_all[:, other] @ shape.areas_m2[other]
        nominal_flux = P_all @ shape.areas_m2
        y = np.asarray(curve.mag, float)
        sig = np.asarray(curve.mag_sigma, float)
        vis_any = np.any((ns > 0) & (no > 0) & (shape.areas_m2 > 0)[None, :], axis=1)
        used = np.isfinite(y) & np.isfinite(mm.offset) & np.isfinite(sig) & (sig > 0) \
            & (nominal_flux > 0) & (vis_any | (fixed > 0))
        if not np.any(used):
            raise InputError("no epoch with a finite magnitude and a lit, visible facet",
                             field="mag", value=f"{N} epochs")
        self.used = used
        self.n_dropped = int(np.sum(np.isfinite(y)) - np.sum(used))
        u = used
        self.t = np.asarray(curve.t, float)
        self._ns = np.ascontiguousarray(ns[u])
        self._no = np.ascontiguousarray(no[u])
        self._nh = np.ascontiguousarray(nh[u])
        self._c = np.ascontiguousarray(c[u])
        self._fixed = np.ascontiguousarray(fixed[u])
        self._offset = np.ascontiguousarray(mm.offset[u])
        self.y = y[u]
        self.sigma = sig[u]
        # full-length arrays for predictive curves over every epoch with a finite offset
        self._all = (np.ascontiguousarray(ns), np.ascontiguousarray(no), np.ascontiguousarray(nh),
                     np.ascontiguousarray(c), np.ascontiguousarray(fixed),
                     np.ascontiguousarray(mm.offset))

    # -- transforms ---------------------------------------------------------------------
    def to_z(self, p):
        """Physical (..., D) → unbounded (..., D) (logit for ξ, a; log for m, A)."""
        from ..filters.facet_states import to_unbounded

        return to_unbounded(p, [k in _LOGIT for k, _ in self._slot])

    def to_p(self, z):
        """Unbounded (..., D) → physical (..., D)."""
        from ..filters.facet_states import from_unbounded

        return from_unbounded(z, [k in _LOGIT for k, _ in self._slot])

    def facet_arrays(self, p):
        """Physical (W,D) → (xi, a, m, A) each (W,K), non-fitted kinds at their nominal values."""
        p = np.atleast_2d(np.asarray(p, float))
        W = p.shape[0]
        out = []
        for k in KINDS:
            arr = np.empty((W, self.fidx.size))
            arr[:] = self.nominal[k]
            ds, js = self._fill[k]
            if ds.size:
                arr[:, js] = p[:, ds]
            out.append(arr)
        return tuple(out)

    # -- model ----------------------------------------------------------------------------
    def predict(self, p, all_epochs=False):
        """Magnitudes (W, N_used) (or (W, N) with ``all_epochs``) for physical parameters (W,D)."""
        xi, a, m, A = self.facet_arrays(p)
        if all_epochs:
            ns, no, nh, c, fixed, off = self._all
        else:
            ns, no, nh, c, fixed, off = (self._ns, self._no, self._nh, self._c, self._fixed,
                                         self._offset)
        return _walker_mags_nb(ns, no, nh, c, self.fidx, xi, a, m, A, fixed, off)

    def _log_prior_p(self, p):
        """Log prior (constants dropped) at physical p (W,D) → (W,); −inf outside the support."""
        r = (p - self.p_nominal) / self.prior_sd_p
        with np.errstate(divide="ignore", invalid="ignore"):
            logjac = np.where(self._logit, np.log(p) + np.log1p(-p), np.log(p))
        out = -0.5 * np.sum(r * r, axis=1) + np.sum(logjac, axis=1)
        return np.where(np.isfinite(out), out, -np.inf)

    def _log_likelihood_p(self, p):
        """Gaussian log likelihood (constant dropped) at physical p (W,D) → (W,)."""
        mag = self.predict(p)
        r = (mag - self.y[None, :]) / self.sigma[None, :]
        with np.errstate(invalid="ignore"):
            ll = -0.5 * np.sum(r * r, axis=1)
        return np.where(np.isfinite(ll), ll, -np.inf)

    @staticmethod
    def _valid(z):
        z = np.atleast_2d(np.asarray(z, float))
        return z, np.all(np.isfinite(z), axis=1) & np.all(np.abs(z) < 700, axis=1)

    def log_prior(self, z):
        """Log prior density of z, (W,D) → (W,) (constants dropped; module docstring): the
        truncated physical Gaussian at p(z) plus log |dp/dz|."""
        z = np.atleast_2d(np.asarray(z, float))
        return self._log_prior_p(self.to_p(z))

    def log_likelihood(self, z):
        """Gaussian magnitude log likelihood, (W,D) → (W,) (constant dropped); −inf if invalid."""
        z, ok = self._valid(z)
        out = np.full(z.shape[0], -np.inf)
        if np.any(ok):
            out[ok] = self._log_likelihood_p(self.to_p(z[ok]))
        return out

    def log_prob(self, z):
        """Log posterior (W,D) → (W,), the emcee target (vectorised); the z → p map is done
        once for prior and likelihood."""
        z, ok = self._valid(z)
        out = np.full(z.shape[0], -np.inf)
        if np.any(ok):
            p = self.to_p(z[ok])
            lp = self._log_prior_p(p)
            fin = np.isfinite(lp)
            if np.any(fin):
                lp[fin] += self._log_likelihood_p(p[fin])
            out[ok] = lp
        return out

    def map_estimate(self):
        """Maximum a posteriori z (D,) by L-BFGS from the prior centre."""
        from scipy.optimize import minimize

        def f(z):
            v = -float(self.log_prob(z[None, :])[0])
            return v if np.isfinite(v) else 1e300

        res = minimize(f, self.z_nominal.copy(), method="L-BFGS-B",
                       options={"maxiter": 500})
        z = res.x if np.isfinite(f(res.x)) and f(res.x) <= f(self.z_nominal) else self.z_nominal
        return np.asarray(z, float)

    def laplace_covariance(self, z, h=1e-5):
        """Gauss–Newton (Laplace) posterior covariance in z at z (D,):
        ``(Jᵀ R⁻¹ J + diag(1/σ_z²))⁻¹`` with J = ∂m/∂z by central differences (step h)."""
        z = np.asarray(z, float).reshape(self.dim)
        E = h * np.eye(self.dim)
        zz = np.concatenate([z + E, z - E])
        mag = self.predict(self.to_p(zz))
        J = (mag[: self.dim] - mag[self.dim:]).T / (2.0 * h)           # (N,D)
        J = np.where(np.isfinite(J), J, 0.0) / self.sigma[:, None]
        H = J.T @ J + np.diag(1.0 / self.prior_sd_z ** 2)
        C = np.linalg.inv(H)
        return 0.5 * (C + C.T)


# --------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------

@dataclass
class ReflectionFit:
    """Posterior of the reflection parameters (physical units: ξ, a, m dimensionless; A in m²).

    Attributes
    ----------
    names : list[str]; p_nominal (D,) prior centres
    samples_z, samples_p : (S,D) posterior samples (after burn-in and thinning)
    quantiles : dict level -> (D,) physical quantiles (levels 0.005, 0.025, 0.16, 0.5, 0.84,
        0.975, 0.995)
    prior_sd_z, posterior_sd_z, width_ratio : (D,) identifiability diagnostics
    identified : (D,) bool, width_ratio < identify_ratio
    diagnostics : ChainDiagnostics
    predictive : dict of (N,) arrays — t, y, sigma, used and model quantile bands
        (q025, q16, q50, q84, q975 of the noise-free model; n025/n975 with noise)
    truth : (D,) or None — true parameters if known (synthetic data)
    n_dropped : int — epochs dropped (module docstring)
    """

    names: list
    p_nominal: np.ndarray
    samples_z: np.ndarray
    samples_p: np.ndarray
    quantiles: dict
    prior_sd_z: np.ndarray
    posterior_sd_z: np.ndarray
    width_ratio: np.ndarray
    identified: np.ndarray
    identify_ratio: float
    diagnostics: object
    predictive: dict
    n_dropped: int = 0
    truth: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    def truth_inside(self, level=0.99):
        """(D,) bool: truth inside the central ``level`` interval (0.95 or 0.99); needs truth."""
        if self.truth is None:
            raise ValueError("no truth attached")
        lo, hi = {0.99: (0.005, 0.995), 0.95: (0.025, 0.975)}[level]
        return (self.truth >= self.quantiles[lo]) & (self.truth <= self.quantiles[hi])

    def summary(self) -> dict:
        """JSON-ready summary: per-parameter posterior table, diagnostics, predictive coverage."""
        rows = []
        for d, n in enumerate(self.names):
            row = {"name": n, "nominal": float(self.p_nominal[d]),
                   "median": float(self.quantiles[0.5][d]),
                   "sd": float(np.std(self.samples_p[:, d])),
                   "q005": float(self.quantiles[0.005][d]), "q995": float(self.quantiles[0.995][d]),
                   "width_ratio": float(self.width_ratio[d]),
                   "identified": bool(self.identified[d])}
            if self.truth is not None:
                row["truth"] = float(self.truth[d])
                row["truth_in_99"] = bool(self.truth_inside(0.99)[d])
            rows.append(row)
        pr = self.predictive
        u = pr["used"]
        inside = (pr["y"][u] >= pr["n025"][u]) & (pr["y"][u] <= pr["n975"][u])
        return {"parameters": rows, "diagnostics": self.diagnostics.as_dict(),
                "identify_ratio": self.identify_ratio,
                "identified": [n for n, i in zip(self.names, self.identified) if i],
                "not_identified": [n for n, i in zip(self.names, self.identified) if not i],
                "n_samples": int(self.samples_p.shape[0]), "n_dropped_epochs": int(self.n_dropped),
                "predictive_coverage_95": float(np.mean(inside)) if inside.size else float("nan"),
                "meta": self.meta}

    def write_json(self, path) -> Path:
        """Write :meth:`summary` as JSON (atomic)."""
        from ..io.atomic import atomic_write_text

        path = Path(path)
        atomic_write_text(path, json.dumps(self.summary(), indent=2) + "\n")
        return path

    def corner_plot(self, path, max_params=8):
        """Corner plot (matplotlib; histograms on the diagonal, sample scatter below) of at most
        ``max_params`` parameters (identified first; the title says how many of how many),
        prior centre dotted, truth in red when known. Screen-sized (≤ 12 in). Returns path."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from ..io.atomic import atomic_path
        from ..report.style import DPI

        order = list(np.flatnonzero(self.identified)) + list(np.flatnonzero(~self.identified))
        sel = order[:max_params]
        D = len(sel)
        side = min(1.9 * D + 1.2, 11.5)
        fig, axes = plt.subplots(D, D, figsize=(side, side), squeeze=False)
        S = self.samples_p
        for r, i in enumerate(sel):
            for cidx, j in enumerate(sel):
                ax = axes[r, cidx]
                if cidx > r:
                    ax.set_visible(False)
                    continue
                if r == cidx:
                    ax.hist(S[:, i], bins=30, color="C0", histtype="step")
                    ax.axvline(self.p_nominal[i], color="0.5", ls=":", lw=1)
                    if self.truth is not None:
                        ax.axvline(self.truth[i], color="C3", lw=1)
                    ax.set_yticks([])
                else:
                    ax.plot(S[:, j], S[:, i], ",", color="C0", alpha=0.3)
                    if self.truth is not None:
                        ax.plot(self.truth[j], self.truth[i], "+", color="C3", ms=8)
                if r == D - 1:
                    ax.set_xlabel(self.names[j] + ("" if self.identified[j] else " (n.i.)"),
                                  fontsize=8)
                if cidx == 0 and r > 0:
                    ax.set_ylabel(self.names[i], fontsize=8)
                ax.tick_params(labelsize=6)
        shown = (f"all {D} parameters" if D == len(self.names) else
                 f"{D} of {len(self.names)} parameters (identified first; all of them are in "
                 "the JSON)")
        legend = "dotted grey: prior centre" + (", red: truth" if self.truth is not None else
                                                "; no truth known")
        fig.suptitle(f"reflection-parameter posterior: {shown}\n{legend}; n.i. = not "
                     "identified by the data", fontsize=9)
        fig.tight_layout()
        path = Path(path)
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=DPI, format=path.suffix.lstrip(".") or "png")
        plt.close(fig)
        return path

    def predictive_plot(self, path):
        """Posterior predictive lightcurve with 68 %/95 % model bands and the 95 % band with
        noise; residual panel below. Returns path."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from ..io.atomic import atomic_path

        pr = self.predictive
        t, u = pr["t"], pr["used"]
        fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True,
                                     gridspec_kw={"height_ratios": [3, 1]})
        a1.fill_between(t, pr["n025"], pr["n975"], color="C1", alpha=0.2, lw=0,
                        label="95 % predictive (with noise)")
        a1.fill_between(t, pr["q025"], pr["q975"], color="C0", alpha=0.35, lw=0, label="95 % model")
        a1.plot(t, pr["q50"], color="C0", lw=0.8, label="posterior median")
        a1.plot(t[u], pr["y"][u], ".", ms=2, color="k", label="measured")
        a1.invert_yaxis()
        a1.set_ylabel("apparent magnitude")
        a1.legend(fontsize=7, loc="best")
        a2.fill_between(t, pr["n025"] - pr["q50"], pr["n975"] - pr["q50"], color="C1", alpha=0.2, lw=0)
        a2.fill_between(t, pr["q025"] - pr["q50"], pr["q975"] - pr["q50"], color="C0", alpha=0.35,
                        lw=0)
        a2.plot(t[u], pr["y"][u] - pr["q50"][u], ".", ms=2, color="k")
        a2.axhline(0, color="0.5", lw=0.5)
        a2.set_ylabel("residual, mag")
        a2.set_xlabel("t, s")
        path = Path(path)
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=90, format=path.suffix.lstrip(".") or "png")
        plt.close(fig)
        return path


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------

_LEVELS = (0.005, 0.025, 0.16, 0.5, 0.84, 0.975, 0.995)


def fit_reflection(curve, *, shape=None, attitude="truth", estimate=None, facets=None, kinds=KINDS,
                   prior_frac=0.1, walkers=None, seed=0, block=500, max_steps=20_000,
                   min_steps=1000, tau_factor=50.0, identify_ratio=0.5, n_predictive=200,
                   truth=None, allow_unconverged=False, progress=None,
                   library_dirs=None) -> ReflectionFit:
    """Sample the posterior of facet reflection parameters (module docstring).

    Parameters
    ----------
    curve : Lightcurve
    shape : Shape, str or None — default the shape the file carries, else
        ``curve.attrs["shape"]`` (:meth:`Lightcurve.resolve_shape`; ``library_dirs`` are extra
        shape-library folders for a named shape).
    attitude : {"truth", "estimate"} — use ``curve.truth_q`` or ``estimate.q`` (an
        :class:`~lightcurve.filters.result.Estimate` at the curve's times, or its file path).
        The attitude is held fixed: an estimate's own uncertainty is *not* marginalised, so the
        posterior is conditional on it and over-confident when the estimate is poor (a
        diverged estimate is accepted but flagged in ``meta["attitude_warning"]``).
    facets, kinds, prior_frac : see :class:`ReflectionPosteriorModel`.
    walkers : int or None — default max(2·D + 2, 32), rounded up to even.
    seed : int — seeds the walker initialisation, the sampler and the predictive draws.
    block, max_steps, min_steps, tau_factor : see
        :func:`lightcurve.estimation.mcmc.sample_until_converged`.
    identify_ratio : float — identified when posterior sd / prior sd (in z) is below this.
    n_predictive : int — posterior draws for the predictive bands.
    truth : (D,) physical true parameters (in ``model.names`` order) or None (default: the
        file's ``attrs["reflection_truth"]`` when it was simulated with ``[reflection]``; for
        a file simulated without it and fitted with its own shape, the shape file's values,
        which made the data).
    allow_unconverged : bool — return an unconverged posterior instead of raising.

    Raises
    ------
    ConvergenceError — the chain did not converge (reasons in the message).
    InputError — bad inputs (no truth attitude, mismatched estimate, unknown facet…).
    """
    from ..estimation.mcmc import sample_until_converged
    from ..memory import check_allocation

    if walkers is not None:  # a first, lower-bound estimate (one parameter) before any work
        check_allocation(8 * int(walkers) * int(max_steps) * 2,
                         f"MCMC with {int(walkers)} walkers, {int(max_steps)} steps",
                         field="walkers", value=int(walkers))

    own_shape = shape is None or shape == (curve.attrs or {}).get("shape")
    shape = curve.resolve_shape(shape, library_dirs=library_dirs)
    if attitude == "truth":
        if not curve.has_truth:
            raise InputError("the lightcurve has no truth attitude; use --attitude estimate",
                             field="truth/q")
        q = np.asarray(curve.truth_q, float)
    elif attitude == "estimate":
        if estimate is None:
            raise InputError("attitude 'estimate' needs an estimate file", field="estimate")
        if not hasattr(estimate, "q"):
            from ..filters.result import read_estimate

            estimate = read_estimate(estimate)
        q = np.asarray(estimate.q, float)
        te = np.asarray(estimate.t, float)
        if te.shape != np.asarray(curve.t).shape or not np.allclose(te, curve.t, atol=1e-6):
            raise InputError("estimate times do not match the lightcurve times", field="estimate.t",
                             value=te.shape, allowed=f"the {len(curve)} lightcurve times")
    else:
        raise InputError("unknown attitude source", field="attitude", value=attitude,
                         allowed="truth, estimate")
    model = ReflectionPosteriorModel(shape, curve, q, facets=facets, kinds=kinds,
                                     prior_frac=prior_frac)
    if truth is None and (curve.attrs or {}).get("reflection_truth"):
        # simulated with a [reflection] section: the file records the true parameters
        try:
            tv = json.loads(str(curve.attrs["reflection_truth"]))
            truth = [float(tv[n.split("[")[0]][int(n.split("[")[1][:-1])]) for n in model.names]
        except (ValueError, KeyError, IndexError, TypeError):
            raise InputError("unreadable reflection truth in the lightcurve file",
                             field="attrs.reflection_truth") from None
    elif truth is None and own_shape and curve.has_truth and (curve.attrs or {}).get("seed") is not None:
        # simulated without [reflection]: the data were made with the shape file's values
        truth = [float(v) for v in model.p_nominal]
    D = model.dim
    W = walkers if walkers is not None else max(2 * D + 2, 32)
    W = int(W) + (int(W) % 2)
    # the stored chain (positions and log-probabilities of every walker at every step) and
    # one ensemble evaluation (walkers x epochs x facets, a few temporaries)
    check_allocation(8 * W * int(max_steps) * (D + 1)
                     + 8 * 4 * W * len(curve) * max(1, int(getattr(shape, "n_facets", 1))),
                     f"MCMC with {W} walkers, {int(max_steps)} steps, {D} parameters",
                     field="walkers", value=W)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xEC3E]))
    z_map = model.map_estimate()
    # walkers start from the Laplace approximation at the MAP (a tiny ball would make the
    # ensemble spend thousands of steps expanding into the prior-dominated directions)
    L = np.linalg.cholesky(model.laplace_covariance(z_map))
    p0 = z_map + rng.standard_normal((W, D)) @ L.T
    bad = ~np.isfinite(model.log_prob(p0))
    for _ in range(100):
        if not np.any(bad):
            break
        p0[bad] = z_map + 0.5 * rng.standard_normal((int(bad.sum()), D)) @ L.T
        bad = ~np.isfinite(model.log_prob(p0))
    p0[bad] = z_map
    sampler, diag = sample_until_converged(model.log_prob, p0, seed=int(rng.integers(2**31)),
                                           block=block, max_steps=max_steps, min_steps=min_steps,
                                           tau_factor=tau_factor, progress=progress)
    if not diag.converged and not allow_unconverged:
        raise ConvergenceError("posterior refused: the MCMC chain did not converge: "
                               + "; ".join(diag.reasons), diag)
    zs = sampler.get_chain(discard=diag.burn, thin=diag.thin, flat=True)
    ps = model.to_p(zs)
    quant = {lv: np.quantile(ps, lv, axis=0) for lv in _LEVELS}
    post_sd = np.std(zs, axis=0)
    ratio = post_sd / model.prior_sd_z
    # posterior predictive over all epochs
    pick = rng.choice(zs.shape[0], size=min(int(n_predictive), zs.shape[0]), replace=False)
    with np.errstate(invalid="ignore"):
        mags = model.predict(ps[pick], all_epochs=True)                 # (S,N)
    sig = np.asarray(curve.mag_sigma, float)
    noisy = mags + rng.standard_normal(mags.shape) * np.where(np.isfinite(sig), sig, 0.0)[None, :]
    with np.errstate(invalid="ignore"):
        qm = np.quantile(mags, [0.025, 0.16, 0.5, 0.84, 0.975], axis=0)
        qn = np.quantile(noisy, [0.025, 0.975], axis=0)
    pred = {"t": np.asarray(curve.t, float), "y": np.asarray(curve.mag, float), "sigma": sig,
            "used": model.used.copy(), "q025": qm[0], "q16": qm[1], "q50": qm[2], "q84": qm[3],
            "q975": qm[4], "n025": qn[0], "n975": qn[1]}
    meta = {"attitude": attitude, "shape": shape.name, "prior_frac": model.prior_frac,
            "walkers": W, "seed": int(seed), "facets": [int(i) for i in model.fidx],
            "kinds": list(model.kinds)}
    if attitude == "estimate" and getattr(estimate, "diverged", False):
        meta["attitude_warning"] = ("the attitude estimate is flagged diverged ("
                                    + str(getattr(estimate, "divergence_reason", "")) + "); the "
                                    "posterior is conditional on a poor attitude")
    return ReflectionFit(names=list(model.names), p_nominal=model.p_nominal.copy(), samples_z=zs,
                         samples_p=ps, quantiles=quant, prior_sd_z=model.prior_sd_z.copy(),
                         posterior_sd_z=post_sd, width_ratio=ratio,
                         identified=ratio < float(identify_ratio),
                         identify_ratio=float(identify_ratio), diagnostics=diag, predictive=pred,
                         n_dropped=model.n_dropped,
                         truth=None if truth is None else np.asarray(truth, float), meta=meta)


# --------------------------------------------------------------------------------------------
# Truth perturbation and synthetic cases
# --------------------------------------------------------------------------------------------

def synthetic_reflection_case(shape, *, seed=0, n_epochs=300, duration_s=300.0, r_percent=1.0,
                              omega_rad_s=(0.035, 0.017, 0.063), frac=0.1, kinds=KINDS,
                              facets=None):
    """A synthetic LEO lightcurve with known attitude and perturbed reflection parameters.

    Geometry (ECI, m): object at 7000 km on the x axis, observer on the Earth's surface 30°
    away in the x–y plane, Sun at 1 au in a fixed direction giving a phase angle of ≈ 60°; the
    attitude spins at the constant body rate ``omega_rad_s`` (default ≈ Bernard's fast-spin
    [2, 1, 3.6] deg/s) from a seeded random initial attitude (exact step
    ``q_k = exp(ω t_k) ⊗ q_0``). Truth parameters: :func:`perturb_reflection` with ``frac``;
    noise σ = |m| r/100/3 (Bernard eq. 9.3). ``facets`` (default: every Cook–Torrance facet)
    limits the perturbation to those facets, the others keep the shape file's values — the
    generative model of a :class:`ReflectionPosteriorModel` with the same ``facets`` and
    ``kinds`` (used by the simulation-based calibration check).

    Returns (curve, truth_shape, truth_values dict kind -> (F,)).
    """
    from .. import rotations as rot
    from ..io.lightcurve_h5 import Lightcurve
    from ..photometry.magnitude import AU_M, apparent_magnitude
    from ..photometry.noise import add_noise

    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5EF1]))
    t = np.linspace(0.0, float(duration_s), int(n_epochs))
    N = t.size
    r_obj = np.tile([7.0e6, 0.0, 0.0], (N, 1))
    ang = np.radians(30.0)
    r_site = np.tile([6.378e6 * np.cos(ang), 6.378e6 * np.sin(ang), 0.0], (N, 1))
    o_dir = (r_site[0] - r_obj[0]) / np.linalg.norm(r_site[0] - r_obj[0])
    ph = np.radians(60.0)
    perp = np.cross(o_dir, [0.0, 0.0, 1.0])
    perp /= np.linalg.norm(perp)
    s_dir = np.cos(ph) * o_dir + np.sin(ph) * (0.6 * perp + 0.8 * np.array([0.0, 0.0, 1.0]))
    s_dir /= np.linalg.norm(s_dir)
    r_sun = r_obj + AU_M * s_dir
    q0 = rng.standard_normal(4)
    q0 /= np.linalg.norm(q0)
    w = np.asarray(omega_rad_s, float)
    q = rot.quat_mult(rot.rotvec_to_quat(w[None, :] * t[:, None]), np.broadcast_to(q0, (N, 4)))
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    truth_shape, vals = perturb_reflection(shape, rng, frac=frac, kinds=kinds, facets=facets)
    so = r_sun - r_obj
    oo = r_site - r_obj
    with np.errstate(divide="ignore"):
        m_true = apparent_magnitude(truth_shape, q, so / np.linalg.norm(so, axis=1, keepdims=True),
                                    oo / np.linalg.norm(oo, axis=1, keepdims=True),
                                    np.linalg.norm(oo, axis=1), np.linalg.norm(so, axis=1))
    mag, sigma = add_noise(m_true, r_percent, rng)
    mag = np.where(np.isfinite(mag), mag, np.nan)
    sigma = np.where(np.isfinite(sigma), sigma, np.nan)
    curve = Lightcurve(epoch_utc="2020-01-01T00:00:00Z", t=t, mag=mag, mag_sigma=sigma,
                       site=np.zeros(N, np.int64), site_names=["synthetic"],
                       site_lla_deg_m=np.array([[0.0, 30.0, 0.0]]), r_obj_eci_m=r_obj,
                       r_site_eci_m=r_site, r_sun_eci_m=r_sun, lit_fraction=np.ones(N),
                       truth_q=q, truth_omega_rad_s=np.tile(w, (N, 1)), truth_mag=m_true,
                       attrs={"shape": shape.name, "r_percent": float(r_percent)})
    return curve, truth_shape, vals


# --------------------------------------------------------------------------------------------
# Simulation-based calibration (Talts et al. 2018)
# --------------------------------------------------------------------------------------------

def reflection_sbc(shape, *, n_runs=100, facets=None, kinds=KINDS, n_epochs=150, seed0=0,
                   n_bins=5, false_alarm=0.01, progress=None, **fit_kwargs) -> dict:
    """Simulation-based calibration of :func:`fit_reflection` on synthetic cases.

    For run r = 0 … n_runs−1 the truth is drawn from exactly the prior of the posterior
    (:func:`synthetic_reflection_case` with ``seed = seed0 + r`` and the same ``facets`` and
    ``kinds``, §10.1 10 % truncated Gaussian), the lightcurve is simulated with the recorded
    noise σ (eq. 9.3), and the posterior is sampled with :func:`fit_reflection` (known
    attitude, same convergence rules; ``fit_kwargs`` are passed through). For each parameter
    the posterior CDF at the truth, u = P(θ < θ_true | y), is estimated from the samples. If
    the likelihood, the prior and the sampler are right, u ~ U(0, 1) for every parameter
    (Cook, Gelman & Rubin 2006; Talts et al. 2018), also for the subset of runs in which the
    diagnostics call the parameter identified (the selection is a function of the data only).

    Tests (per parameter, Bonferroni over the D parameters so that ``false_alarm`` is the
    family-wise false-alarm rate): Pearson chi-square of the u histogram with ``n_bins``
    equal bins against χ²(n_bins − 1); and the dispersion statistic Σ_r Φ⁻¹(u_r)² (u clipped
    to [10⁻³, 1 − 10⁻³]) against the two-sided χ²(R) bounds — a posterior too narrow (or
    too wide) makes it too large (too small), the sharper test against over-confidence.
    Coverage: number of truths outside the central 99 % and
    95 % posterior intervals, with the binomial tail probability of at least that many under
    calibration (pooled over parameters, which treats them as independent — approximate).

    Unconverged runs are counted and left out (a calibration statement needs converged
    posteriors). Returns a JSON-ready dict (lists, floats).
    """
    from scipy import stats

    rows_u, rows_id, n_unconv = [], [], 0
    names = None
    for r in range(int(n_runs)):
        curve, _, vals = synthetic_reflection_case(shape, seed=int(seed0) + r, n_epochs=n_epochs,
                                                   kinds=kinds, facets=facets)
        try:
            fit = fit_reflection(curve, shape=shape, facets=facets, kinds=kinds,
                                 seed=int(seed0) + r, **fit_kwargs)
        except ConvergenceError:
            n_unconv += 1
            continue
        names = fit.names
        truth = np.array([vals[n.split("[")[0]][int(n.split("[")[1][:-1])] for n in names])
        from ..filters.facet_states import to_unbounded

        zt = to_unbounded(truth, [n.split("[")[0] in _LOGIT for n in names])
        rows_u.append(np.mean(fit.samples_z < zt[None, :], axis=0))
        rows_id.append(fit.identified.copy())
        if progress is not None:
            progress(r, fit)
    if not rows_u:
        raise RuntimeError(f"no converged run among {n_runs}")
    u = np.array(rows_u)
    ident = np.array(rows_id)
    R, D = u.shape
    crit = stats.chi2.ppf(1.0 - false_alarm / D, n_bins - 1)
    ns_lo, ns_hi = stats.chi2.ppf([false_alarm / (2 * D), 1.0 - false_alarm / (2 * D)], R)
    nscore = np.sum(stats.norm.ppf(np.clip(u, 1e-3, 1.0 - 1e-3)) ** 2, axis=0)
    per = []
    for d in range(D):
        cnt = np.histogram(u[:, d], bins=n_bins, range=(0.0, 1.0))[0]
        e = R / n_bins
        x2 = float(np.sum((cnt - e) ** 2 / e))
        per.append({"name": names[d], "counts": cnt.tolist(), "chi2": x2,
                    "p_value": float(stats.chi2.sf(x2, n_bins - 1)),
                    "normal_score_sum_sq": float(nscore[d]),
                    "n_identified": int(ident[:, d].sum()),
                    "outside_99": int(np.sum((u[:, d] < 0.005) | (u[:, d] > 0.995))),
                    "outside_95": int(np.sum((u[:, d] < 0.025) | (u[:, d] > 0.975)))})
    out99 = (u < 0.005) | (u > 0.995)
    out95 = (u < 0.025) | (u > 0.975)
    n_all, n_id = u.size, int(ident.sum())

    def tail(k, n, p):
        return float(stats.binom.sf(int(k) - 1, int(n), p)) if n else 1.0

    return {"n_runs": int(n_runs), "n_converged": R, "n_unconverged": n_unconv, "names": names,
            "n_bins": n_bins, "false_alarm": false_alarm, "chi2_critical": float(crit),
            "uniform": bool(all(p["chi2"] <= crit for p in per)),
            "normal_score_bounds": [float(ns_lo), float(ns_hi)],
            "dispersion_ok": bool(np.all((nscore >= ns_lo) & (nscore <= ns_hi))),
            "per_parameter": per,
            "outside_99": int(out99.sum()), "expected_outside_99": 0.01 * n_all,
            "p_at_least_outside_99": tail(out99.sum(), n_all, 0.01),
            "outside_95": int(out95.sum()), "expected_outside_95": 0.05 * n_all,
            "p_at_least_outside_95": tail(out95.sum(), n_all, 0.05),
            "identified_outside_99": int(out99[ident].sum()), "n_identified": n_id,
            "p_at_least_identified_outside_99": tail(out99[ident].sum(), n_id, 0.01),
            "identified_outside_95": int(out95[ident].sum()),
            "p_at_least_identified_outside_95": tail(out95[ident].sum(), n_id, 0.05),
            "u": u.tolist(), "identified": ident.tolist()}
