"""The :class:`Estimate` of an attitude filter run, its truth comparison and its HDF5 file.

Per epoch k (N epochs, the lightcurve's rows): posterior ``q̂`` (inertial→body, scalar first),
``ω̂`` (rad/s, body axes), the 6×6 error covariance of ``[δθ (rad), δω (rad/s)]`` (δθ body-frame
rotation vector / GRP, ``q_true = δq ⊗ q̂``), 1σ bounds, the measurement innovation
``ν = y − ŷ`` (mag) and its predicted variance (mag²), N_eff for particle filters, and status
flags. When the lightcurve has truth: attitude error ``δθ`` of ``q_true ⊗ q̂⁻¹`` as a rotation
vector (deg, body axes; Bernard eq. 9.4–9.6), rate error ``ω_true − ω̂`` (rad/s) and the NEES
``εₖ = eᵀ P⁻¹ e`` with ``e = [δθ (rad), δω]`` (6 degrees of freedom).

Flags (bit mask per epoch): :data:`FLAG_NAN` measurement NaN (skipped), :data:`FLAG_REFUSED`
update refused (Cholesky or non-finite; prior kept), :data:`FLAG_INVISIBLE` the estimate
predicts no reflected light (update skipped), :data:`FLAG_COLLAPSE` all particle weights zero
(weights reset), :data:`FLAG_RESAMPLED` the PF resampled, :data:`FLAG_NIS` the sliding-window
NIS test exceeded its 99.9 % bound, :data:`FLAG_OUTLIER` the innovation gate rejected the
measurement (not used; :mod:`lightcurve.filters.gating`), :data:`FLAG_INFLATED` the gate used it
with an inflated noise variance, :data:`FLAG_GATE_RELEASED` the gate would have rejected it but
had already rejected its limit of measurements in a row (used), :data:`FLAG_UNLIT` the object is
in the Earth's full shadow (skipped), :data:`FLAG_BELOW_HORIZON` the object is below the site's
horizon (skipped).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import rotations as rot
from ..errors import InputError
from ..io.atomic import atomic_path
from ..report.views import EstimateViews

__all__ = ["Estimate", "FLAG_NAN", "FLAG_REFUSED", "FLAG_INVISIBLE", "FLAG_COLLAPSE",
           "FLAG_RESAMPLED", "FLAG_NIS", "FLAG_OUTLIER", "FLAG_INFLATED", "FLAG_GATE_RELEASED",
           "FLAG_UNLIT", "FLAG_BELOW_HORIZON", "read_estimate"]

FLAG_NAN = 1
FLAG_REFUSED = 2
FLAG_INVISIBLE = 4
FLAG_COLLAPSE = 8
FLAG_RESAMPLED = 16
FLAG_NIS = 32
FLAG_OUTLIER = 64
FLAG_INFLATED = 128
FLAG_GATE_RELEASED = 256
FLAG_UNLIT = 512
FLAG_BELOW_HORIZON = 1024

_FAIL = FLAG_REFUSED | FLAG_COLLAPSE


@dataclass(repr=False)
class Estimate(EstimateViews):
    """Result of one filter run (module docstring for meanings and units).

    Attributes
    ----------
    method : str — "mekf", "ukf" or "bpf"
    t : (N,) s since the lightcurve's epoch
    q : (N,4) posterior attitude, inertial→body, scalar first
    omega_rad_s : (N,3) posterior body rate, rad/s, body axes
    cov : (N,6,6) error covariance of [δθ (rad), δω (rad/s)]
    att_sigma_deg : (N,3) 1σ attitude bounds per body axis, deg
    omega_sigma_rad_s : (N,3) 1σ rate bounds, rad/s
    innovations : (N,) y − ŷ (mag; NaN when no update)
    innovation_var : (N,) predicted innovation variance (mag²; NaN when no update)
    n_eff : (N,) effective sample size (particle filter; NaN otherwise)
    flags : (N,) int bit mask
    skipped_nan : int — NaN magnitudes skipped
    diverged : bool
    divergence_reason : str
    runtime_s : float
    att_error_deg, omega_error_rad_s, nees : truth comparison or None
    meta : dict of settings (seed, sigmas, particles …)
    clouds : dict epoch index → (M,3) particle error rotation vectors ``q_true ⊗ q_i⁻¹`` in deg
        (body axes; BPF with ``keep_clouds`` and truth) or None
    bias, bias_sigma : (N,S) per-site reflection biases and 1σ, mag (Models 1–2) or None
    refl_names : list of Model 3 state names (``"xi[5]"`` …) or None
    refl_z, refl_z_sigma : (N,D) Model 3 states in unconstrained coordinates (logit/ln) and 1σ
    refl_p, refl_p_sigma : (N,D) the same in physical units (ξ, a, m dimensionless; A m²)
    epoch_utc : str — ISO 8601 UTC epoch that ``t`` counts from ('' if unknown)
    source_file : str — the lightcurve file inverted ('' if unknown)
    mag, mag_sigma : (N,) measured magnitudes and their 1σ (mag) or None
    site : (N,) int site index of every epoch, ``site_names`` the site ids, or None
    predicted_mag : (N,) model magnitude at the posterior attitude of every epoch (mag; nominal
        shape, no bias states; +inf where no light reaches the observer) or None

    Derived: :attr:`prior_predicted_mag` = ``mag − innovations`` (the prior prediction ŷ used
    by the update) and :attr:`nis` = ``ν² / S`` (normalised innovation squared, χ²₁ when
    consistent).
    """

    method: str
    t: np.ndarray
    q: np.ndarray
    omega_rad_s: np.ndarray
    cov: np.ndarray
    att_sigma_deg: np.ndarray
    omega_sigma_rad_s: np.ndarray
    innovations: np.ndarray
    innovation_var: np.ndarray
    n_eff: np.ndarray
    flags: np.ndarray
    skipped_nan: int = 0
    diverged: bool = False
    divergence_reason: str = ""
    runtime_s: float = 0.0
    att_error_deg: np.ndarray | None = None
    omega_error_rad_s: np.ndarray | None = None
    nees: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    clouds: dict | None = None
    bias: np.ndarray | None = None
    bias_sigma: np.ndarray | None = None
    refl_names: list | None = None
    refl_z: np.ndarray | None = None
    refl_z_sigma: np.ndarray | None = None
    refl_p: np.ndarray | None = None
    refl_p_sigma: np.ndarray | None = None
    epoch_utc: str = ""
    source_file: str = ""
    mag: np.ndarray | None = None
    mag_sigma: np.ndarray | None = None
    site: np.ndarray | None = None
    site_names: list | None = None
    predicted_mag: np.ndarray | None = None

    def __len__(self):
        return int(self.t.shape[0])

    @property
    def prior_predicted_mag(self) -> np.ndarray | None:
        """(N,) prior predicted magnitude ``ŷ = y − ν`` (mag; NaN where no update)."""
        if self.mag is None:
            return None
        return np.asarray(self.mag, float) - np.asarray(self.innovations, float)

    @property
    def nis(self) -> np.ndarray:
        """(N,) normalised innovation squared ``ν² / S`` (NaN where no update)."""
        v = np.asarray(self.innovation_var, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(v > 0, np.asarray(self.innovations, float) ** 2 / v, np.nan)

    # ------------------------------------------------------------------------------------
    def attach_truth(self, truth_q, truth_omega_rad_s, extra_att_var=0.0):
        """Fill ``att_error_deg``, ``omega_error_rad_s`` and ``nees`` from the truth.

        ``extra_att_var`` (rad²) is added to the attitude diagonal of the covariance used for
        the NEES (the ACS jitter of the controlled "jitter" model, which the estimate does not
        track but the truth contains).
        """
        tq = np.asarray(truth_q, float)
        tw = np.asarray(truth_omega_rad_s, float)
        if tq.shape != self.q.shape or tw.shape != self.omega_rad_s.shape:
            raise ValueError(f"truth shapes {tq.shape}, {tw.shape} do not match the estimate "
                             f"{self.q.shape}, {self.omega_rad_s.shape}")
        tq = tq / np.linalg.norm(tq, axis=1, keepdims=True)
        dth = rot.attitude_error_rotvec(tq, rot.quat_normalize(self.q))
        self.att_error_deg = np.degrees(dth)
        self.omega_error_rad_s = tw - self.omega_rad_s
        e = np.concatenate([dth, self.omega_error_rad_s], axis=1)
        C = self.cov.copy()
        if extra_att_var:
            C[:, 0, 0] += extra_att_var
            C[:, 1, 1] += extra_att_var
            C[:, 2, 2] += extra_att_var
        nees = np.full(len(self), np.nan)
        for k in range(len(self)):
            try:
                L = np.linalg.cholesky(C[k])
            except np.linalg.LinAlgError:
                continue
            z = np.linalg.solve(L, e[k])
            nees[k] = float(z @ z)
        self.nees = nees
        return self

    # ------------------------------------------------------------------------------------
    def consistency(self, prob=0.99) -> dict:
        """Are the filter's innovations and the fitted lightcurve consistent with the noise?

        Two tests at probability ``prob`` (default 99 %), independent of the truth:

        * NIS: the mean of ``νₖ²/Sₖ`` over the updated epochs against the two-sided interval of
          the mean of n χ²₁ variables (Bar-Shalom, Li & Kirubarajan 2001 §5.4.2,
          :func:`lightcurve.estimation.consistency.chi2_interval`): above it, the filter's own
          covariance does not explain its innovations (``"nis_high"``); below, it is
          pessimistic (``"nis_low"``).
        * Residuals (when the estimate carries ``predicted_mag`` from the posterior attitude and
          the measured ``mag``, ``mag_sigma``): the lower median of ``((y − ŷ)/σ)²`` over the
          epochs against the exact two-sided interval of the ⌈n/2⌉-th order statistic of n χ²₁
          variables (:func:`lightcurve.estimation.consistency.order_statistic_interval`):
          above it, most of the pass is not explained by the noise — a model mismatch or a wrong
          attitude, whatever the covariance says (``"residuals_high"``). The median, not the
          mean: a specular glint turns a 0.2° attitude error into a residual of hundreds of σ at
          one or two epochs, and the filter's first epochs from a wide prior are off by design;
          neither is a misfit of the pass. The mean χ²/dof (6 fitted states removed) and the
          count of |residual| > 5σ are reported beside it.

        Returns a dict: ``nis_mean``, ``nis_band``, ``n_updates``, ``residual_median_sq``,
        ``residual_median_band``, ``residual_chi2_dof``, ``residuals_over_5sigma``,
        ``n_residuals``, ``flags`` (list of str) and ``consistent`` (no flag).
        """
        from ..estimation.consistency import chi2_interval, order_statistic_interval

        out = {"nis_mean": None, "nis_band": None, "n_updates": 0, "residual_median_sq": None,
               "residual_median_band": None, "residual_chi2_dof": None,
               "residuals_over_5sigma": 0, "n_residuals": 0, "flags": []}
        nu = np.asarray(self.innovations, float)
        S = np.asarray(self.innovation_var, float)
        ok = np.isfinite(nu) & np.isfinite(S) & (S > 0)
        n = int(ok.sum())
        if n:
            m = float(np.mean(nu[ok] ** 2 / S[ok]))
            lo, hi = chi2_interval(1, prob, n_avg=n)
            out.update(nis_mean=m, nis_band=[lo, hi], n_updates=n)
            if m > hi:
                out["flags"].append("nis_high")
            elif m < lo:
                out["flags"].append("nis_low")
        yhat = getattr(self, "predicted_mag", None)
        y = getattr(self, "mag", None)
        sig = getattr(self, "mag_sigma", None)
        if yhat is not None and y is not None and sig is not None:
            with np.errstate(invalid="ignore"):
                r = (np.asarray(y, float) - np.asarray(yhat, float)) / np.asarray(sig, float)
            # a prediction of an invisible body (±inf residual) against a measured magnitude
            # counts as a gross residual, not a missing one
            r = r[~np.isnan(r)]
            if r.size >= 7:
                k = (r.size + 1) // 2
                r2 = np.sort(r * r)
                med = float(r2[k - 1])
                lo, hi = order_statistic_interval(1, k, r.size, prob)
                fin = np.isfinite(r)
                dof = int(fin.sum()) - 6
                out.update(residual_median_sq=med, residual_median_band=[lo, hi],
                           residual_chi2_dof=float(r[fin] @ r[fin] / dof) if dof >= 1 else None,
                           residuals_over_5sigma=int(np.sum(np.abs(r) > 5.0)),
                           n_residuals=int(r.size))
                if med > hi:
                    out["flags"].append("residuals_high")
        out["consistent"] = not out["flags"]
        return out

    # ------------------------------------------------------------------------------------
    def summary(self) -> dict:
        """Final-epoch summary (JSON-ready): RSS errors, 3σ bounds, inside-3σ, runtime."""
        out = {
            "method": self.method,
            "epochs": len(self),
            "runtime_s": round(float(self.runtime_s), 4),
            "diverged": bool(self.diverged),
            "divergence_reason": self.divergence_reason,
            "skipped_nan": int(self.skipped_nan),
            "refused_updates": int(np.sum((self.flags & FLAG_REFUSED) > 0)),
            "invisible_predictions": int(np.sum((self.flags & FLAG_INVISIBLE) > 0)),
            # innovation gate and epoch screening (lightcurve.filters.gating)
            "rejected_outliers": int(np.sum((self.flags & FLAG_OUTLIER) > 0)),
            "inflated_outliers": int(np.sum((self.flags & FLAG_INFLATED) > 0)),
            "gate_released": int(np.sum((self.flags & FLAG_GATE_RELEASED) > 0)),
            "skipped_unlit": int(np.sum((self.flags & FLAG_UNLIT) > 0)),
            "skipped_below_horizon": int(np.sum((self.flags & FLAG_BELOW_HORIZON) > 0)),
            "final_3sigma_att_deg": [float(x) for x in 3.0 * self.att_sigma_deg[-1]],
            "final_3sigma_omega_deg_s": [float(x) for x in
                                         np.degrees(3.0 * self.omega_sigma_rad_s[-1])],
        }
        if np.any(np.isfinite(self.n_eff)):
            out["final_n_eff"] = float(self.n_eff[-1])
        cons = self.consistency()
        out["consistency"] = cons
        out["flagged"] = bool(cons["flags"])
        gi = (self.meta or {}).get("global_init")
        if gi:   # global initialisation (lightcurve.acquisition.global_init): the modes
            out["global_init"] = {k: gi[k] for k in ("ambiguous", "statement", "n_modes",
                                                     "n_modes_total", "symmetries",
                                                     "n_rejected", "modes") if k in gi}
        if self.bias is not None and self.bias_sigma is not None:
            out["final_bias_mag"] = [float(x) for x in self.bias[-1]]
            out["final_bias_sigma_mag"] = [float(x) for x in self.bias_sigma[-1]]
        if self.refl_names is not None and self.refl_p is not None:
            r = self.meta.get("reflection") or {}
            r = r.get("facet_states", r)
            s0 = r.get("prior_sigma_p") or [float("nan")] * len(self.refl_names)
            out["final_reflection"] = {
                n: {"value": float(v), "sigma": float(sd), "prior_sigma": float(p0)}
                for n, v, sd, p0 in zip(self.refl_names, self.refl_p[-1], self.refl_p_sigma[-1],
                                        s0)}
        if self.att_error_deg is not None:
            ea = self.att_error_deg[-1]
            ew = np.degrees(self.omega_error_rad_s[-1])
            inside = (np.all(np.abs(ea) <= 3.0 * self.att_sigma_deg[-1])
                      and np.all(np.abs(ew) <= np.degrees(3.0 * self.omega_sigma_rad_s[-1])))
            out.update({
                "final_att_error_rss_deg": float(np.linalg.norm(ea)),
                "final_omega_error_rss_deg_s": float(np.linalg.norm(ew)),
                "final_att_error_deg": [float(x) for x in ea],
                "final_omega_error_deg_s": [float(x) for x in ew],
                "inside_3sigma": bool(inside),
                "final_nees": float(self.nees[-1]) if self.nees is not None else None,
            })
        return out

    # ------------------------------------------------------------------------------------
    def write(self, path) -> Path:
        """Write the estimate to an HDF5 file (atomic: temporary file, then rename)."""
        import json

        import h5py

        path = Path(path)
        with atomic_path(path) as tmp:
            with h5py.File(tmp, "w") as h:
                h.attrs["format"] = "lightcurve-estimate"
                h.attrs["format_version"] = 1
                h.attrs["method"] = self.method
                h.attrs["skipped_nan"] = int(self.skipped_nan)
                h.attrs["diverged"] = int(self.diverged)
                h.attrs["divergence_reason"] = self.divergence_reason
                h.attrs["runtime_s"] = float(self.runtime_s)
                h.attrs["meta_json"] = json.dumps(self.meta, default=str)
                for name, units in (("t", "s"), ("q", "inertial->body quaternion, scalar first"),
                                    ("omega_rad_s", "rad/s body axes"),
                                    ("cov", "[dtheta rad, domega rad/s] covariance"),
                                    ("att_sigma_deg", "deg"), ("omega_sigma_rad_s", "rad/s"),
                                    ("innovations", "mag"), ("innovation_var", "mag^2"),
                                    ("n_eff", "particles"), ("flags", "bit mask"),
                                    ("att_error_deg", "deg body axes"),
                                    ("omega_error_rad_s", "rad/s"), ("nees", ""),
                                    ("bias", "mag"), ("bias_sigma", "mag"),
                                    ("refl_z", "logit/ln of the facet parameters"),
                                    ("refl_z_sigma", "logit/ln units"),
                                    ("refl_p", "xi, a, m dimensionless; A m^2"),
                                    ("refl_p_sigma", "xi, a, m dimensionless; A m^2"),
                                    ("mag", "mag, measured"), ("mag_sigma", "mag, 1 sigma"),
                                    ("site", "index into site_names"),
                                    ("predicted_mag", "mag, model at the posterior attitude"),
                                    ("prior_predicted_mag", "mag, prior prediction y - innovation"),
                                    ("nis", "innovation^2 / innovation_var")):
                    v = getattr(self, name)
                    if v is None:
                        continue
                    d = h.create_dataset(name, data=np.asarray(v))
                    d.attrs["units"] = units
                if self.refl_names is not None:
                    h.attrs["refl_names_json"] = json.dumps(list(self.refl_names))
                h.attrs["epoch_utc"] = str(self.epoch_utc)
                h.attrs["source_file"] = str(self.source_file)
                if self.site_names is not None:
                    h.attrs["site_names_json"] = json.dumps([str(x) for x in self.site_names])
                if self.clouds:
                    g = h.create_group("clouds")
                    g.attrs["units"] = "deg, particle error rotation vectors, body axes"
                    for kk, arr in self.clouds.items():
                        g.create_dataset(f"epoch_{int(kk)}", data=np.asarray(arr))
        return path


def read_estimate(path) -> Estimate:
    """Read an HDF5 estimate written by :meth:`Estimate.write` (opened through
    :func:`lightcurve.io.safe_open.open_hdf5`: regular file, no external data, declared sizes
    checked before reading)."""
    import json

    from ..io.safe_open import open_hdf5, read_dataset

    path = Path(path)
    cap = 4 * 10**8  # elements per dataset (the particle clouds are the largest)
    with open_hdf5(path) as h:
        if h.attrs.get("format") != "lightcurve-estimate":
            raise InputError("not a lightcurve estimate file", file=path, field="format",
                             value=h.attrs.get("format"), allowed="lightcurve-estimate")
        kw = {n: (None if n not in h else np.asarray(read_dataset(h, n, max_elements=cap,
                                                                    file=path)))
              for n in ("t", "q", "omega_rad_s", "cov", "att_sigma_deg", "omega_sigma_rad_s",
                        "innovations", "innovation_var", "n_eff", "flags", "att_error_deg",
                        "omega_error_rad_s", "nees", "bias", "bias_sigma", "refl_z",
                        "refl_z_sigma", "refl_p", "refl_p_sigma", "mag", "mag_sigma", "site",
                        "predicted_mag")}
        kw["epoch_utc"] = str(h.attrs.get("epoch_utc", ""))
        kw["source_file"] = str(h.attrs.get("source_file", ""))
        if "site_names_json" in h.attrs:
            kw["site_names"] = json.loads(str(h.attrs["site_names_json"]))
        if "refl_names_json" in h.attrs:
            kw["refl_names"] = json.loads(str(h.attrs["refl_names_json"]))
        clouds = None
        if "clouds" in h:
            clouds = {int(n.split("_")[1]): np.asarray(read_dataset(h, f"clouds/{n}",
                                                                    max_elements=cap, file=path))
                      for n in h["clouds"]}
        return Estimate(method=str(h.attrs["method"]), skipped_nan=int(h.attrs["skipped_nan"]),
                        clouds=clouds,
                        diverged=bool(h.attrs["diverged"]),
                        divergence_reason=str(h.attrs["divergence_reason"]),
                        runtime_s=float(h.attrs["runtime_s"]),
                        meta=json.loads(str(h.attrs["meta_json"])), **kw)
