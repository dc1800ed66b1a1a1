"""``invert``: estimate attitude and rate from a lightcurve with the MEKF, the UKF or the BPF.

The filter setup follows Bernard (2021) ch. 9: the initial estimate is the truth at the first
epoch perturbed by the given 1σ values (``q̂₀ = exp(δθ₀) ⊗ q_true,0`` with
``δθ₀ ~ N(0, σθ² I)`` rad body axes, ``ω̂₀ = ω_true,0 + N(0, σω² I)``), drawn from the seed,
and ``P₀ = diag(σθ² I₃, σω² I₃)``; a user-given ``initial_q`` / ``initial_omega`` replaces the
perturbed truth (needed for recordings without truth). Dynamics come from the scenario stored in
the file (controlled / uncontrolled, ACS σ, inertia) unless overridden; the shape from
``curve.attrs["shape"]`` unless given.

``reflection`` adds states for uncertain reflection parameters (Bernard ch. 8): per-site
magnitude biases (``"random-walk"``, ``"model1"``, ``"model2"``,
:mod:`lightcurve.filters.reflection`) or Model 3, the facet parameters themselves
(``"model3"``, :mod:`lightcurve.filters.facet_states`). ``attitude="truth"`` is the
"attitude known" mode of §10.7: q, ω are held at the file's truth and only the reflection
states are estimated.
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot
from ..errors import InputError
from ..io.lightcurve_h5 import Lightcurve
from ._common import FilterProblem
from .models import ControlledDynamics, MagnitudeModel, UncontrolledDynamics
from .result import Estimate

__all__ = ["invert", "build_problem", "METHODS", "ATTITUDE_MODES"]

METHODS = ("mekf", "ukf", "bpf")
#: ``invert(attitude=…)``: estimate attitude and rate, or hold them at the file's truth (§10.7)
ATTITUDE_MODES = ("estimate", "truth")


def _scenario_attitude(curve):
    """The [attitude] table of the scenario TOML stored in the file ({} if none)."""
    txt = getattr(curve, "scenario_toml", "") or ""
    if not txt.strip():
        return {}
    import tomllib

    try:
        doc = tomllib.loads(txt)
    except (tomllib.TOMLDecodeError, RecursionError):  # RecursionError: hostile nesting
        return {}
    at = doc.get("attitude", {})
    return at if isinstance(at, dict) else {}


def _check_curve(curve):
    if not isinstance(curve, Lightcurve):
        raise InputError("invert needs a lightcurve.io.Lightcurve", field="curve",
                         value=type(curve).__name__)
    n = len(curve)
    t = np.asarray(curve.t, float)
    for name in ("mag", "mag_sigma"):
        v = np.asarray(getattr(curve, name))
        if v.shape != (n,):
            raise InputError("inconsistent shapes", field=name, value=v.shape, allowed=f"({n},)")
    for name in ("r_obj_eci_m", "r_site_eci_m", "r_sun_eci_m"):
        v = np.asarray(getattr(curve, name))
        if v.shape != (n, 3):
            raise InputError("inconsistent shapes", field=name, value=v.shape,
                             allowed=f"({n}, 3)")
    if n == 0 or not np.any(np.isfinite(curve.mag)):
        raise InputError("the lightcurve has no visible (finite) magnitude to filter",
                         field="mag", value=f"{n} rows, 0 finite")
    if np.any(np.diff(t) < 0):
        raise InputError("times must be non-decreasing", field="t")
    fin = np.isfinite(curve.mag)
    sig = np.asarray(curve.mag_sigma, float)
    if np.any(~(sig[fin] > 0)):
        raise InputError("mag_sigma must be > 0 where a magnitude is given", field="mag_sigma",
                         allowed="> 0")


def build_problem(curve, *, seed=0, sigma_theta_deg=3.0, sigma_omega_deg_s=0.02,
                  initial_q=None, initial_omega=None, shape=None, dynamics=None,
                  acs_sigma_deg=None, acs_mode="random_walk", pseudo_noise=0.0,
                  eta_sigma_deg_s2=None, inertia_kg_m2=None, substep_s=0.5,
                  attitude="estimate") -> FilterProblem:
    """Build the :class:`FilterProblem` (model, dynamics, initial estimate) for ``invert``.

    Parameters mirror :func:`invert`; ``acs_sigma_deg`` / ``eta_sigma_deg_s2`` /
    ``dynamics`` default to the scenario stored in the lightcurve file (ACS 0 and
    "controlled" when the file has none). ``attitude="truth"`` sets
    ``FilterProblem.attitude_known`` (needs truth in the file).
    """
    _check_curve(curve)
    if attitude not in ATTITUDE_MODES:
        raise InputError("unknown attitude mode", field="attitude", value=attitude,
                         allowed=", ".join(ATTITUDE_MODES))
    if attitude == "truth" and not curve.has_truth:
        raise InputError("attitude known (truth) needs a lightcurve with truth_q and "
                         "truth_omega_rad_s", field="attitude", value=attitude)
    if shape is None:
        name = (curve.attrs or {}).get("shape", "")
        if not name:
            raise InputError("the lightcurve names no shape (attrs['shape']); pass shape=",
                             field="attrs.shape")
        from ..photometry import load_shape

        shape = load_shape(str(name), library_only=True)  # a name from a data file
    elif isinstance(shape, str):
        from ..photometry import load_shape

        shape = load_shape(shape)
    at = _scenario_attitude(curve)
    dyn_kind = dynamics or at.get("dynamics", "controlled")
    if dyn_kind not in ("controlled", "uncontrolled"):
        raise InputError("unknown dynamics", field="dynamics", value=dyn_kind,
                         allowed="controlled, uncontrolled")
    if dyn_kind == "controlled":
        acs = float(at.get("acs_sigma_deg", 0.0)) if acs_sigma_deg is None else float(acs_sigma_deg)
        if not (acs >= 0 and np.isfinite(acs)):
            raise InputError("ACS sigma must be >= 0", field="acs_sigma_deg", value=acs)
        dyn = ControlledDynamics(np.radians(acs), acs_mode=acs_mode, pseudo_noise=pseudo_noise)
    else:
        J = inertia_kg_m2
        if J is None:
            J = at.get("inertia_kg_m2")
        if J is None:
            J = shape.inertia_kg_m2
        eta = float(at.get("eta_sigma_deg_s2", 0.0)) if eta_sigma_deg_s2 is None \
            else float(eta_sigma_deg_s2)
        dyn = UncontrolledDynamics(J, eta_psd=np.radians(eta) ** 2, substep_s=substep_s,
                                   pseudo_noise=pseudo_noise)
    model = MagnitudeModel(shape, curve)

    st = float(sigma_theta_deg)
    sw = float(sigma_omega_deg_s)
    if not (st > 0 and np.isfinite(st)):
        raise InputError("must be > 0", field="sigma_theta_deg", value=st)
    if not (sw > 0 and np.isfinite(sw)):
        raise InputError("must be > 0", field="sigma_omega_deg_s", value=sw)
    st_r, sw_r = np.radians(st), np.radians(sw)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x1A77]))
    dth = rng.standard_normal(3) * st_r
    dw = rng.standard_normal(3) * sw_r
    if initial_q is None:
        if not curve.has_truth:
            raise InputError("no truth in the lightcurve: give initial_q (and initial_omega)",
                             field="initial_q")
        q0 = rot.quat_mult(rot.rotvec_to_quat(dth), rot.quat_normalize(curve.truth_q[0]))
    else:
        q0 = np.asarray(initial_q, float).reshape(4)
        if not np.all(np.isfinite(q0)) or abs(np.linalg.norm(q0) - 1) > 1e-6:
            raise InputError("initial_q must be a finite unit quaternion", field="initial_q",
                             value=q0.tolist())
    if initial_omega is None:
        if curve.truth_omega_rad_s is None:
            raise InputError("no truth rate in the lightcurve: give initial_omega",
                             field="initial_omega")
        w0 = curve.truth_omega_rad_s[0] + dw
    else:
        w0 = np.asarray(initial_omega, float).reshape(3)
        if not np.all(np.isfinite(w0)):
            raise InputError("initial_omega must be finite", field="initial_omega")
    P0 = np.diag([st_r ** 2] * 3 + [sw_r ** 2] * 3)
    meta = {"seed": int(seed), "sigma_theta_deg": st, "sigma_omega_deg_s": sw,
            "dynamics": dyn_kind, "acs_sigma_deg": float(np.degrees(dyn.acs_sigma)),
            "acs_mode": dyn.acs_mode, "shape": getattr(shape, "name", "")}
    if attitude == "truth":
        meta["attitude"] = "truth"
    return FilterProblem(model=model, dynamics=dyn, q0=q0, omega0=w0, P0=P0,
                         truth_q=curve.truth_q, truth_omega=curve.truth_omega_rad_s, meta=meta,
                         attitude_known=attitude == "truth")


def invert(curve, method="mekf", *, seed=0, sigma_theta_deg=3.0, sigma_omega_deg_s=0.02,
           particles=10_000, roughening=0.2, resampling=None, ess_threshold=0.5,
           initial_q=None, initial_omega=None, shape=None, dynamics=None, acs_sigma_deg=None,
           acs_mode="random_walk", pseudo_noise=0.0, eta_sigma_deg_s2=None, inertia_kg_m2=None,
           alpha=1.0, beta=2.0, kappa=0.0, error="grp", jacobian="analytic",
           keep_clouds=(), reflection="none", reflection_frac=0.1, attitude="estimate",
           reflection_process_noise=0.0, reflection_facets=None,
           reflection_kinds=("xi", "a", "m", "A"), gate=None,
           rejuvenation=None, device="cpu") -> Estimate:
    """Estimate attitude and body rate from a lightcurve.

    Parameters
    ----------
    curve : Lightcurve
    method : {"mekf", "ukf", "bpf"}
    seed : int
        Seeds the initial-estimate perturbation and (BPF) every random draw; reproducible.
    sigma_theta_deg, sigma_omega_deg_s : float
        1σ of the initial attitude (deg, per axis) and rate (deg/s) errors; also ``P₀``.
    particles, roughening, resampling, ess_threshold :
        BPF: number of particles, roughening constant 𝒢 (Bernard table 7.9), "systematic" or
        "multinomial" (None: the variant's, :class:`~lightcurve.filters.bpf.BPFConfig`),
        resample when ``N_eff < ess_threshold · N``. The variant is
        ``problem.meta["variant"]`` ("robust" when absent).
    rejuvenation : {"auto", "separate", "joint", "table7.9", "none"} or None (the variant's)
        BPF: how the resampled cloud is moved (:func:`lightcurve.filters.bpf.run_bpf`): "joint"
        = one Liu–West kernel on the full state ("auto": joint while the cloud is compact),
        "separate" = the table-7.9 σ added in the GRP chart, "table7.9" = Bernard's table 7.9
        as written (the thesis variant's), "none".
    device : {"cpu", "gpu"} — BPF: the numba CPU kernels or the CUDA kernels of
        :mod:`lightcurve.filters.bpf_gpu` (needs the ``gpu`` extra and a CUDA device).
    initial_q, initial_omega :
        User initial estimate (inertial→body quaternion; rad/s body axes) instead of the
        perturbed truth.
    shape : Shape or str, optional (default ``curve.attrs["shape"]``)
    dynamics : {"controlled", "uncontrolled"}, optional (default: the file's scenario)
    acs_sigma_deg : float, optional — ACS noise 1σ (deg); default the scenario's.
    acs_mode : {"random_walk", "jitter"} — see :mod:`lightcurve.filters.models`.
    pseudo_noise : float — rate pseudo-noise PSD, (rad/s)²/s.
    eta_sigma_deg_s2 : float, optional — uncontrolled η level (deg/s^{3/2} as a PSD root).
    inertia_kg_m2 : (3,3), optional — uncontrolled inertia (default scenario, then shape).
    alpha, beta, kappa : UKF scaling parameters.
    error, jacobian : MEKF options (see :func:`lightcurve.filters.mekf.run_mekf`).
    keep_clouds : BPF epochs whose particle error clouds are kept (fig. 9.6-style plots).
    reflection : {"none", "random-walk", "model1", "model2", "model3"}
        Extra states for uncertain reflection parameters (Bernard ch. 8): per-site magnitude
        biases (:mod:`lightcurve.filters.reflection`; the estimate then carries ``bias`` and
        ``bias_sigma`` (N,S)) or Model 3 facet-parameter states
        (:mod:`lightcurve.filters.facet_states`; ``refl_z``, ``refl_p`` and 1σ (N,D), final
        values in ``meta["reflection"]``). All three filters.
    reflection_frac : float > 0 — relative 1σ of the reflection parameters (eq. 8.10 for the
        bias models; the Model 3 prior, §10.1).
    attitude : {"estimate", "truth"} — "truth": attitude known (§10.7), only the reflection
        states are estimated (needs ``reflection != "none"``).
    reflection_process_noise : float ≥ 0 — Model 3 process-noise PSD in z-units²/s (default 0,
        constant parameters, eq. 8.39).
    reflection_facets, reflection_kinds : Model 3 facets (default every Cook–Torrance facet)
        and parameters (default ξ, a, m, A).
    gate : None, "auto", "reject", "inflate", "off", dict or GateConfig — the innovation
        (outlier) gate and unlit/below-horizon screening of :mod:`lightcurve.filters.gating`;
        None = its defaults (NIS > 15.14, false-alarm rate 1e-4; reject in the UKF, inflate
        in the MEKF and the BPF). Counts land in
        ``est.meta["gate"]`` and :meth:`Estimate.summary`.

    Returns
    -------
    Estimate
    """
    if method not in METHODS:
        raise InputError("unknown filter method", field="method", value=method,
                         allowed=", ".join(METHODS))
    problem = build_problem(curve, seed=seed, sigma_theta_deg=sigma_theta_deg,
                            sigma_omega_deg_s=sigma_omega_deg_s, initial_q=initial_q,
                            initial_omega=initial_omega, shape=shape, dynamics=dynamics,
                            acs_sigma_deg=acs_sigma_deg, acs_mode=acs_mode,
                            pseudo_noise=pseudo_noise, eta_sigma_deg_s2=eta_sigma_deg_s2,
                            inertia_kg_m2=inertia_kg_m2, attitude=attitude)
    problem.meta["method"] = method
    if gate is not None:   # innovation gate / epoch screening settings (filters.gating)
        from .gating import set_gate

        set_gate(problem, gate)
    bias = facets = None
    from .reflection import REFLECTION_CHOICES

    if reflection not in REFLECTION_CHOICES:
        raise InputError("unknown reflection model", field="reflection", value=reflection,
                         allowed=", ".join(REFLECTION_CHOICES))
    if attitude == "truth" and reflection == "none":
        raise InputError("attitude known (truth) leaves nothing to estimate without "
                         "reflection states", field="reflection", value=reflection,
                         allowed="random-walk, model1, model2, model3")
    if reflection != "none":
        from .reflection import SiteBias

        fr = float(reflection_frac)
        if not (fr > 0 and np.isfinite(fr)):
            raise InputError("must be > 0", field="reflection_frac", value=reflection_frac)
        if reflection == "model3":
            from .facet_states import FacetParameterStates

            facets = FacetParameterStates(problem.model.shape, facets=reflection_facets,
                                          kinds=reflection_kinds, prior_frac=fr,
                                          process_noise=reflection_process_noise)
        else:
            bias = SiteBias.from_problem(reflection, problem, frac=fr)
    if method == "mekf":
        from .mekf import run_mekf

        return run_mekf(problem, error=error, jacobian=jacobian, bias=bias, facets=facets)
    if method == "ukf":
        from .ukf import run_ukf

        return run_ukf(problem, alpha=alpha, beta=beta, kappa=kappa, bias=bias, facets=facets)
    from .bpf import BPFConfig, run_bpf

    # the variant's defaults (BPFConfig) unless a setting is given explicitly
    cfg = BPFConfig(variant=problem.meta.get("variant", "robust"), particles=int(particles),
                    roughening=float(roughening), ess_threshold=float(ess_threshold),
                    **{k: v for k, v in (("resampling", resampling),
                                         ("rejuvenation", rejuvenation)) if v is not None})
    problem.meta.update({"particles": cfg.particles, "roughening": cfg.roughening,
                         "resampling": cfg.resampling, "ess_threshold": cfg.ess_threshold})
    if device == "gpu":
        from .bpf_gpu import run_bpf_gpu

        return run_bpf_gpu(problem, cfg, seed=seed, bias=bias, facets=facets,
                           attitude=attitude, keep_clouds=keep_clouds)
    if device != "cpu":
        raise InputError("unknown device", field="device", value=device, allowed="cpu, gpu")
    return run_bpf(problem, cfg, seed=seed, bias=bias, facets=facets, attitude=attitude,
                   keep_clouds=keep_clouds)
