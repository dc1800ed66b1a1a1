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

``variant`` (a field of every filter configuration): ``"robust"`` (default) runs our improved
filters (innovation gate, …); ``"thesis"`` runs Bernard's ch. 7–8 filters as written — the MEKF
of Tables 7.1–7.2, the UKF of Tables 7.3–7.4 (:mod:`lightcurve.filters.ukf_thesis`), the
particle filter's ``BPFConfig.thesis()`` — without an innovation gate (unless one is given),
with Model 2's τ uncapped (eq. 8.12) and Model 3's m through a bounded map (eq. 8.43). Unless
given, the variant is the stored scenario's ``[filter] variant``, else robust.
``init_seed`` (:class:`~lightcurve.filters.config.ProblemConfig`) seeds the initial-estimate
draw alone: §9.3.1 starts every filter of a Monte Carlo run from the same initial estimate.
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot
from ..acquisition.global_init import global_initialise
from ..errors import InputError
from ..io.lightcurve_h5 import Lightcurve
from ..io.tomlio import Section, loads_toml
from ..studies.scenario import scenario_from_lightcurve
from . import bpf as _bpf
from ._common import FilterProblem
from .config import (ATTITUDE_MODES, BPF_KEYWORDS, INITIAL_MODES, METHOD_NAMES, VARIANTS,
                     ConfigBase, ProblemConfig, filter_config_class, split_options)
from .facet_states import FacetParameterStates
from .gating import set_gate
from .mekf import run_mekf
from .models import ControlledDynamics, MagnitudeModel, UncontrolledDynamics
from .reflection import SiteBias
from .result import Estimate
from .ukf import run_ukf
from .ukf_thesis import run_ukf_thesis

__all__ = ["invert", "build_problem", "initial_mode", "resolve_variant", "METHODS",
           "ATTITUDE_MODES", "INITIAL_MODES", "VARIANTS"]

METHODS = METHOD_NAMES
"""Filter methods: "mekf", "ukf", "bpf"."""

_RUNNERS = {"mekf": run_mekf, "ukf": run_ukf, "bpf": _bpf.run_bpf}
#: memory of the particle filter per particle (all working arrays; measured 420 B with the
#: 7-element attitude-and-rate state on the default scenario, rounded up for extra states)
BPF_BYTES_PER_PARTICLE = 512


def _scenario_table(curve, name):
    """The raw [name] table of the scenario TOML stored in the file ({} if none)."""
    txt = getattr(curve, "scenario_toml", "") or ""
    if not txt.strip():
        return {}
    src = (curve.attrs or {}).get("file") or "<lightcurve>"
    t = loads_toml(txt, file=f"{src}:scenario").get(name, {})
    return t if isinstance(t, dict) else {}


def resolve_variant(curve, variant=None) -> str:
    """The filter variant: ``variant`` if given, else the stored scenario's ``[filter]
    variant``, else ``"robust"``; InputError for anything else."""
    v = variant if variant is not None else _scenario_table(curve, "filter").get("variant",
                                                                                 "robust")
    if v not in VARIANTS:
        raise InputError("unknown filter variant", field="variant", value=v,
                         allowed=", ".join(VARIANTS))
    return v


def _scenario_attitude(curve, shape=None, library_dirs=None, site_dirs=None):
    """The ``[attitude]`` of the scenario stored in the file, validated: keys ``dynamics``,
    ``acs_sigma_deg``, ``acs_mode``, ``eta_sigma_deg_s2`` (sized from ``drift_deg_per_orbit``
    by the scenario loader when the file gives that, Bernard §9.2.4) and ``inertia_kg_m2``
    when set. ``{}`` when the file has no scenario.

    A complete scenario (a ``[scenario]`` table with its ``epoch_utc``, as ``simulate`` and
    ``import`` store) goes through the scenario loader
    (:func:`lightcurve.studies.scenario.scenario_from_lightcurve`, with ``shape`` as the
    resolved shape); any other text (synthetic test curves holding only an ``[attitude]``
    table) has those four keys validated with the loader's ranges. Invalid content is an
    :class:`InputError`, never silently ignored.
    """
    text = getattr(curve, "scenario_toml", "") or ""
    if not text.strip():
        return {}
    src = (curve.attrs or {}).get("file") or "<lightcurve>"
    doc = loads_toml(text, file=f"{src}:scenario")
    if isinstance(doc.get("scenario"), dict) and "epoch_utc" in doc["scenario"]:
        at = scenario_from_lightcurve(curve, src, shape=shape, library_dirs=library_dirs,
                                      site_dirs=site_dirs).attitude
        out = {"dynamics": at.dynamics, "acs_sigma_deg": at.acs_sigma_deg,
               "acs_mode": at.acs_mode, "eta_sigma_deg_s2": at.eta_sigma_deg_s2}
        if at.inertia_kg_m2 is not None:
            out["inertia_kg_m2"] = at.inertia_kg_m2
        return out
    sec = Section(doc.get("attitude", {}), file=f"{src}:scenario", name="attitude")
    out = {"dynamics": sec.str("dynamics", "controlled",
                               choices=("controlled", "uncontrolled", "law")),
           "acs_sigma_deg": sec.float("acs_sigma_deg", 0.0, min=0.0, max=30.0),
           "acs_mode": sec.str("acs_mode", "random_walk", choices=("random_walk", "jitter")),
           "eta_sigma_deg_s2": sec.float("eta_sigma_deg_s2", 0.0, min=0.0, max=10.0)}
    J = sec.matrix("inertia_kg_m2", None, shape=(3, 3))
    if J is not None:
        out["inertia_kg_m2"] = J
    return out


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
    sets ``FilterProblem.attitude_known`` (needs truth in the file). The shape is
    :meth:`Lightcurve.resolve_shape` (``shape`` > the file's stored shape > its
    ``attrs["shape"]`` from the library, with ``library_dirs``). The reflection settings and
    ``initial`` are not used here (:func:`invert` handles them).
    """
    if config is None:
        cfg = ProblemConfig(**options)
    else:
        cfg = config.replace(**options) if options else config
    _check_curve(curve)
    if cfg.attitude == "truth" and not curve.has_truth:
        raise InputError("attitude known (truth) needs a lightcurve with truth_q and "
                         "truth_omega_rad_s", field="attitude", value=cfg.attitude)
    shape = curve.resolve_shape(cfg.shape, library_dirs=cfg.library_dirs)
    at = _scenario_attitude(curve, shape, library_dirs=cfg.library_dirs,
                            site_dirs=cfg.site_dirs)
    dyn_kind = cfg.dynamics or at.get("dynamics", "controlled")
    if dyn_kind not in ("controlled", "uncontrolled"):
        raise InputError("unknown dynamics", field="dynamics", value=dyn_kind,
                         allowed="controlled, uncontrolled")
    if dyn_kind == "controlled":
        acs = float(at.get("acs_sigma_deg", 0.0)) if cfg.acs_sigma_deg is None \
            else cfg.acs_sigma_deg
        if not (acs >= 0 and np.isfinite(acs)):
            raise InputError("ACS sigma must be >= 0", field="acs_sigma_deg", value=acs)
        mode = cfg.acs_mode or at.get("acs_mode", "random_walk")
        dyn = ControlledDynamics(np.radians(acs), acs_mode=mode, pseudo_noise=cfg.pseudo_noise)
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
    init_seed = cfg.seed if cfg.init_seed is None else cfg.init_seed
    rng = np.random.default_rng(np.random.SeedSequence([int(init_seed), 0x1A77]))
    dth = rng.standard_normal(3) * st_r
    dw = rng.standard_normal(3) * sw_r
    if cfg.initial_q is None:
        if not curve.has_truth:
            # truth-free data (a recording): the filter needs a starting attitude from the user
            # (or from the global initialisation, invert(initial="global"))
            raise InputError("the lightcurve has no truth attitude to start from: give an "
                             "initial estimate (initial_q, initial_omega; CLI --initial-q "
                             "Q1,Q2,Q3,Q4 --initial-omega-deg-s WX,WY,WZ)", field="initial_q")
        q0 = rot.quat_mult(rot.rotvec_to_quat(dth), rot.quat_normalize(curve.truth_q[0]))
    else:
        q0 = np.asarray(cfg.initial_q, float)
    if cfg.initial_omega is None:
        if curve.truth_omega_rad_s is None:
            raise InputError("the lightcurve has no truth rate to start from: give "
                             "initial_omega (CLI --initial-omega-deg-s WX,WY,WZ)",
                             field="initial_omega")
        w0 = curve.truth_omega_rad_s[0] + dw
    else:
        w0 = np.asarray(cfg.initial_omega, float)
    P0 = np.diag([st_r ** 2] * 3 + [sw_r ** 2] * 3)
    meta = {"seed": int(cfg.seed), "init_seed": int(init_seed), "sigma_theta_deg": st,
            "sigma_omega_deg_s": sw,
            "dynamics": dyn_kind, "acs_sigma_deg": float(np.degrees(dyn.acs_sigma)),
            "acs_mode": dyn.acs_mode, "shape": getattr(shape, "name", "")}
    if cfg.attitude == "truth":
        meta["attitude"] = "truth"
    return FilterProblem(model=model, dynamics=dyn, q0=q0, omega0=w0, P0=P0,
                         truth_q=curve.truth_q, truth_omega=curve.truth_omega_rad_s, meta=meta,
                         attitude_known=cfg.attitude == "truth")


def _extra_states(problem, cfg: ProblemConfig, variant: str = "robust"):
    """The reflection states of ``cfg.reflection`` (Bernard ch. 8): ``(SiteBias | None,
    FacetParameterStates | None)``. The thesis variant: Model 3's m through a bounded map
    (eq. 8.43), Model 2's τ uncapped (eq. 8.12); its random walk (eq. 8.4) is not
    implemented."""
    if cfg.reflection == "none":
        return None, None
    thesis = variant == "thesis"
    if cfg.reflection == "model3":
        return None, FacetParameterStates(problem.model.shape, facets=cfg.reflection_facets,
                                          kinds=cfg.reflection_kinds,
                                          prior_frac=cfg.reflection_frac,
                                          process_noise=cfg.reflection_process_noise,
                                          bounded_m=thesis)
    if thesis and cfg.reflection == "random-walk":
        raise NotImplementedError(
            "thesis-variant random-walk bias: the noise strength of Bernard eq. 8.4 (second "
            "derivatives of the magnitude in the facet parameters, attitude and observer "
            "motion) is not implemented; the robust variant's constant strength σ_b²/T is a "
            "different model")
    return SiteBias.from_problem(cfg.reflection, problem, frac=cfg.reflection_frac,
                                 tau_max_s=np.inf if thesis else None), None




def initial_mode(initial, curve, initial_q=None, initial_omega=None) -> str:
    """Resolve ``invert(initial=…)`` to "truth", "given" or "global" (see :func:`invert`)."""
    if initial not in INITIAL_MODES:
        raise InputError("unknown initial-estimate mode", field="initial", value=initial,
                         allowed=", ".join(INITIAL_MODES))
    if initial == "auto":
        if initial_q is not None:
            return "given"
        return "truth" if curve.has_truth else "global"
    if initial == "given" and initial_q is None:
        raise InputError("initial='given' needs initial_q (CLI --initial-q)", field="initial_q")
    if initial == "truth" and not curve.has_truth:
        raise InputError("initial='truth' needs a lightcurve with a truth attitude",
                         field="initial", value=initial, allowed="given, global")
    return initial


def invert(curve, config="mekf", *, problem: ProblemConfig | None = None, method=None,
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
    method : "mekf" | "ukf" | "bpf", optional
        The keyword spelling of a method name (``invert(lc, method="ukf")``), in place of
        ``config``.
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
    where the filter starts (``initial``: "truth" = the file's truth perturbed by σθ, σω;
    "given" = ``initial_q`` / ``initial_omega``; "global" = the global initialisation of
    :mod:`lightcurve.acquisition.global_init`, which runs this filter from each posterior
    mode and returns the heaviest mode's estimate, every mode in ``meta["global_init"]``;
    "auto" = given, else truth, else global), and ``variant`` ("robust" default, "thesis"
    the source text). The estimate carries the measurements and the magnitudes predicted at
    the posterior attitude (:func:`attach_measurements`).

    Returns
    -------
    Estimate
    """
    if method is not None:
        if not (isinstance(config, str) and config == "mekf") and config != method:
            raise InputError("give the filter either as config or as method, not both",
                             field="method", value=method)
        config = method
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
    if fconf is None and filt_opts.get("variant") is None:
        # the stored scenario's [filter] variant, else robust
        filt_opts["variant"] = resolve_variant(curve)
    if problem is None:
        pcfg = ProblemConfig(**prob_opts)
    else:
        pcfg = problem.replace(**prob_opts) if prob_opts else problem
    cls = filter_config_class(method)
    if cls is not None:
        fconf = cls(**filt_opts) if fconf is None else (fconf.replace(**filt_opts) if filt_opts
                                                        else fconf)
    if method == "bpf":  # refuse before allocating (lightcurve.memory)
        from ..memory import check_allocation

        bo = dict(BPF_KEYWORDS)
        bo.update(fconf.as_options() if fconf is not None else filt_opts)
        n_p = int(bo["particles"])
        check_allocation(n_p * (BPF_BYTES_PER_PARTICLE + 8 * 7 * len(tuple(bo["keep_clouds"]))),
                         f"particle filter with {n_p} particles", field="particles", value=n_p)
    if initial_mode(pcfg.initial, curve, pcfg.initial_q, pcfg.initial_omega) == "global":
        # no first guess: the global initialisation (a layer below the filters: it gets the
        # model and a runner of this filter, and imports nothing from here)
        start = pcfg.replace(initial="given", initial_q=(1.0, 0.0, 0.0, 0.0),
                             initial_omega=(0.0, 0.0, 0.0), global_config=None)

        def run_from(q0, w0, sigma_theta_deg, sigma_omega_deg_s):
            p = start.replace(initial_q=tuple(float(x) for x in q0),
                              initial_omega=tuple(float(x) for x in w0),
                              sigma_theta_deg=float(sigma_theta_deg),
                              sigma_omega_deg_s=float(sigma_omega_deg_s))
            return invert(curve, fconf if fconf is not None else method, problem=p,
                          **({} if fconf is not None else filt_opts))

        return global_initialise(curve, build_problem(curve, start), run_from, seed=pcfg.seed,
                                 config=pcfg.global_config).best
    fp = build_problem(curve, pcfg)
    fp.meta["method"] = method
    variant = fconf.variant if fconf is not None else filt_opts.get("variant", "robust")
    fp.meta["variant"] = variant
    gate = pcfg.gate
    if gate is None and variant == "thesis":
        gate = "off"            # ch. 7's filters have no innovation gate
    if gate is not None:   # innovation gate / epoch screening settings (filters.gating)
        set_gate(fp, gate)
    bias, facets = _extra_states(fp, pcfg, variant)
    if fconf is not None:
        run = run_ukf_thesis if (method == "ukf" and variant == "thesis") else _RUNNERS[method]
        # the particle filter also takes its random seed and the attitude-known mode
        extra = {"seed": pcfg.seed, "attitude": pcfg.attitude} if method == "bpf" else {}
        est = run(fp, fconf, bias=bias, facets=facets, **extra)
        attach_measurements(est, curve, fp.model)
        return est
    # the particle filter's keyword form (no registered configuration class)
    bpf_opts = dict(BPF_KEYWORDS)
    filt_opts.pop("variant", None)
    bpf_opts.update(filt_opts)
    fp.meta.update({"particles": int(bpf_opts["particles"]),
                    "roughening": float(bpf_opts["roughening"]),
                    "resampling": bpf_opts["resampling"],
                    "ess_threshold": float(bpf_opts["ess_threshold"])})
    est = _bpf.run_bpf(fp, seed=pcfg.seed, bias=bias, facets=facets, attitude=pcfg.attitude,
                       **bpf_opts)
    attach_measurements(est, curve, fp.model)
    return est


def attach_measurements(est, curve, model) -> None:
    """Record what a real-data plot of ``est`` needs (:class:`Estimate` fields): the epoch,
    the source file, the measured magnitudes, their σ and sites, and ``predicted_mag`` — the
    measurement model's magnitude at the posterior attitude of every epoch (nominal shape,
    no bias states; +inf where no light reaches the observer)."""
    est.epoch_utc = str(curve.epoch_utc)
    est.source_file = str((curve.attrs or {}).get("file", "") or "")
    est.mag = np.asarray(curve.mag, float).copy()
    est.mag_sigma = np.asarray(curve.mag_sigma, float).copy()
    est.site = np.asarray(curve.site, np.int64).copy()
    est.site_names = list(curve.site_names)
    q = np.asarray(est.q, float)
    post = np.full(len(curve), np.nan)
    for k in range(len(curve)):
        if np.all(np.isfinite(q[k])):
            post[k] = float(model.predict_q(q[k], k)[0])
    est.predicted_mag = post
