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

import tomllib

import numpy as np

from .. import rotations as rot
from ..errors import InputError
from ..io.lightcurve_h5 import Lightcurve
from ..photometry import load_shape
from . import bpf as _bpf
from ._common import FilterProblem
from .config import (ATTITUDE_MODES, BPF_KEYWORDS, METHOD_NAMES, ConfigBase, ProblemConfig,
                     filter_config_class, split_options)
from .facet_states import FacetParameterStates
from .gating import set_gate
from .mekf import run_mekf
from .models import ControlledDynamics, MagnitudeModel, UncontrolledDynamics
from .reflection import SiteBias
from .result import Estimate
from .ukf import run_ukf

__all__ = ["invert", "build_problem", "METHODS", "ATTITUDE_MODES"]

METHODS = METHOD_NAMES
"""Filter methods: "mekf", "ukf", "bpf"."""

_RUNNERS = {"mekf": run_mekf, "ukf": run_ukf, "bpf": _bpf.run_bpf}


def _scenario_attitude(curve):
    """The [attitude] table of the scenario TOML stored in the file ({} if none)."""
    txt = getattr(curve, "scenario_toml", "") or ""
    if not txt.strip():
        return {}
    try:
        doc = tomllib.loads(txt)
    except tomllib.TOMLDecodeError:
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


def build_problem(curve, config: ProblemConfig | None = None, **options) -> FilterProblem:
    """Build the :class:`FilterProblem` (model, dynamics, initial estimate) for ``invert``.

    ``config``: a :class:`~lightcurve.filters.config.ProblemConfig`; keyword ``options`` (its
    field names, as :func:`invert` takes them) build one or change the given one.
    ``acs_sigma_deg`` / ``eta_sigma_deg_s2`` / ``dynamics`` default to the scenario stored in
    the lightcurve file (ACS 0 and "controlled" when the file has none). ``attitude="truth"``
    sets ``FilterProblem.attitude_known`` (needs truth in the file). The reflection settings
    are not used here (:func:`invert` adds those states).
    """
    if config is None:
        cfg = ProblemConfig(**options)
    else:
        cfg = config.replace(**options) if options else config
    _check_curve(curve)
    if cfg.attitude == "truth" and not curve.has_truth:
        raise InputError("attitude known (truth) needs a lightcurve with truth_q and "
                         "truth_omega_rad_s", field="attitude", value=cfg.attitude)
    shape = cfg.shape
    if shape is None:
        name = (curve.attrs or {}).get("shape", "")
        if not name:
            raise InputError("the lightcurve names no shape (attrs['shape']); pass shape=",
                             field="attrs.shape")
        shape = load_shape(str(name))
    elif isinstance(shape, str):
        shape = load_shape(shape)
    at = _scenario_attitude(curve)
    dyn_kind = cfg.dynamics or at.get("dynamics", "controlled")
    if dyn_kind not in ("controlled", "uncontrolled"):
        raise InputError("unknown dynamics", field="dynamics", value=dyn_kind,
                         allowed="controlled, uncontrolled")
    if dyn_kind == "controlled":
        acs = float(at.get("acs_sigma_deg", 0.0)) if cfg.acs_sigma_deg is None \
            else cfg.acs_sigma_deg
        if not (acs >= 0 and np.isfinite(acs)):
            raise InputError("ACS sigma must be >= 0", field="acs_sigma_deg", value=acs)
        dyn = ControlledDynamics(np.radians(acs), acs_mode=cfg.acs_mode,
                                 pseudo_noise=cfg.pseudo_noise)
    else:
        J = cfg.inertia_kg_m2
        if J is None:
            J = at.get("inertia_kg_m2")
        if J is None:
            J = shape.inertia_kg_m2
        eta = float(at.get("eta_sigma_deg_s2", 0.0)) if cfg.eta_sigma_deg_s2 is None \
            else cfg.eta_sigma_deg_s2
        dyn = UncontrolledDynamics(J, eta_psd=np.radians(eta) ** 2, substep_s=cfg.substep_s,
                                   pseudo_noise=cfg.pseudo_noise)
    model = MagnitudeModel(shape, curve)

    st, sw = cfg.sigma_theta_deg, cfg.sigma_omega_deg_s
    st_r, sw_r = np.radians(st), np.radians(sw)
    rng = np.random.default_rng(np.random.SeedSequence([int(cfg.seed), 0x1A77]))
    dth = rng.standard_normal(3) * st_r
    dw = rng.standard_normal(3) * sw_r
    if cfg.initial_q is None:
        if not curve.has_truth:
            raise InputError("no truth in the lightcurve: give initial_q (and initial_omega)",
                             field="initial_q")
        q0 = rot.quat_mult(rot.rotvec_to_quat(dth), rot.quat_normalize(curve.truth_q[0]))
    else:
        q0 = np.asarray(cfg.initial_q, float)
    if cfg.initial_omega is None:
        if curve.truth_omega_rad_s is None:
            raise InputError("no truth rate in the lightcurve: give initial_omega",
                             field="initial_omega")
        w0 = curve.truth_omega_rad_s[0] + dw
    else:
        w0 = np.asarray(cfg.initial_omega, float)
    P0 = np.diag([st_r ** 2] * 3 + [sw_r ** 2] * 3)
    meta = {"seed": int(cfg.seed), "sigma_theta_deg": st, "sigma_omega_deg_s": sw,
            "dynamics": dyn_kind, "acs_sigma_deg": float(np.degrees(dyn.acs_sigma)),
            "acs_mode": dyn.acs_mode, "shape": getattr(shape, "name", "")}
    if cfg.attitude == "truth":
        meta["attitude"] = "truth"
    return FilterProblem(model=model, dynamics=dyn, q0=q0, omega0=w0, P0=P0,
                         truth_q=curve.truth_q, truth_omega=curve.truth_omega_rad_s, meta=meta,
                         attitude_known=cfg.attitude == "truth")


def _extra_states(problem, cfg: ProblemConfig):
    """The reflection states of ``cfg.reflection`` (Bernard ch. 8): ``(SiteBias | None,
    FacetParameterStates | None)``."""
    if cfg.reflection == "none":
        return None, None
    if cfg.reflection == "model3":
        return None, FacetParameterStates(problem.model.shape, facets=cfg.reflection_facets,
                                          kinds=cfg.reflection_kinds,
                                          prior_frac=cfg.reflection_frac,
                                          process_noise=cfg.reflection_process_noise)
    return SiteBias.from_problem(cfg.reflection, problem, frac=cfg.reflection_frac), None


def invert(curve, config="mekf", *, problem: ProblemConfig | None = None,
           **options) -> Estimate:
    """Estimate attitude and body rate from a lightcurve.

    Parameters
    ----------
    curve : Lightcurve
    config : "mekf" | "ukf" | "bpf" or a filter configuration object
        (:class:`~lightcurve.filters.config.MEKFConfig`,
        :class:`~lightcurve.filters.config.UKFConfig`, the particle filter's ``BPFConfig``).
        A method name takes the default settings of that filter.
    problem : :class:`~lightcurve.filters.config.ProblemConfig`, optional
        Initial estimate, dynamics, reflection states, gate (default settings).
    **options :
        Any field of :class:`~lightcurve.filters.config.ProblemConfig` or of the filter's
        configuration, by name — the keyword form of the call, e.g.
        ``invert(lc, "ukf", seed=3, sigma_theta_deg=5.0, alpha=0.5)``. They change the
        corresponding field of ``problem`` / ``config``. Particle filter without a
        registered configuration class: its keywords (``particles``, ``roughening``,
        ``resampling``, ``ess_threshold``, ``rejuvenation``, ``keep_clouds``) go to
        :func:`lightcurve.filters.bpf.run_bpf`.

    The fields, their units and sources are documented on the configuration classes:
    1σ of the initial attitude / rate errors (Bernard ch. 9), dynamics model and noise,
    reflection states (ch. 8: per-site biases, Model 3 facet parameters; ``attitude="truth"``
    is the §10.7 attitude-known mode), the innovation gate (:mod:`lightcurve.filters.gating`),
    and ``variant`` ("robust" default, "thesis" the source text).

    Returns
    -------
    Estimate
    """
    if isinstance(config, str):
        method, fconf = config, None
    elif isinstance(config, ConfigBase) and hasattr(type(config), "method"):
        method, fconf = type(config).method, config
    else:
        raise InputError("config must be a method name or a filter configuration",
                         field="config", value=type(config).__name__,
                         allowed=", ".join(METHODS))
    if method not in METHODS:
        raise InputError("unknown filter method", field="method", value=method,
                         allowed=", ".join(METHODS))
    prob_opts, filt_opts = split_options(method, options)
    if problem is None:
        pcfg = ProblemConfig(**prob_opts)
    else:
        pcfg = problem.replace(**prob_opts) if prob_opts else problem
    cls = filter_config_class(method)
    if cls is not None:
        fconf = cls(**filt_opts) if fconf is None else (fconf.replace(**filt_opts) if filt_opts
                                                        else fconf)
    fp = build_problem(curve, pcfg)
    fp.meta["method"] = method
    if fconf is not None:
        fp.meta["variant"] = fconf.variant
    if pcfg.gate is not None:   # innovation gate / epoch screening settings (filters.gating)
        set_gate(fp, pcfg.gate)
    bias, facets = _extra_states(fp, pcfg)
    if fconf is not None:
        return _RUNNERS[method](fp, fconf, bias=bias, facets=facets)
    # the particle filter's keyword form (no registered configuration class)
    bpf_opts = dict(BPF_KEYWORDS)
    filt_opts.pop("variant", None)
    bpf_opts.update(filt_opts)
    fp.meta.update({"particles": int(bpf_opts["particles"]),
                    "roughening": float(bpf_opts["roughening"]),
                    "resampling": bpf_opts["resampling"],
                    "ess_threshold": float(bpf_opts["ess_threshold"])})
    return _bpf.run_bpf(fp, seed=pcfg.seed, bias=bias, facets=facets, attitude=pcfg.attitude,
                        **bpf_opts)
