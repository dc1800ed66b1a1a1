"""Configuration objects of the attitude filters: validated, frozen dataclasses.

One object per concern, built the same way by the Python API, the CLI and the study TOML:

* :class:`ProblemConfig` — the filter *problem*: initial estimate (Bernard 2021 ch. 9: truth
  perturbed by ``sigma_theta_deg`` / ``sigma_omega_deg_s``, seeded), dynamics model
  (controlled / uncontrolled, ACS noise, η, inertia), extra states (reflection biases, Model 3
  facet parameters; Bernard ch. 8), the innovation gate, the attitude-known mode (§10.7);
* :class:`MEKFConfig`, :class:`UKFConfig` — the filter's own settings; the particle filter's
  ``BPFConfig`` lives in :mod:`lightcurve.filters.bpf` and registers itself with
  :func:`register_filter_config`.

Every filter configuration carries ``variant``: ``"robust"`` (the default, our improvements) or
``"thesis"`` (the source text as written; DESIGN.md "Source variant and robust variant").

Bad values raise :class:`~lightcurve.errors.InputError` naming the field, the value and what
is allowed; :meth:`from_mapping` adds the file (study TOML) to the message.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields
from typing import ClassVar

from ..errors import InputError

__all__ = ["VARIANTS", "INITIAL_MODES", "ConfigBase", "ProblemConfig", "MEKFConfig", "UKFConfig", "register_filter_config",
           "filter_config", "filter_config_class", "split_options", "METHOD_NAMES"]

VARIANTS = ("robust", "thesis")
"""``variant`` values: our improved default, or the source text as written."""

DYNAMICS = ("controlled", "uncontrolled")
ACS_MODES = ("random_walk", "jitter")
ATTITUDE_MODES = ("estimate", "truth")
INITIAL_MODES = ("auto", "truth", "given", "global")
"""``initial``: where the filter starts (:func:`lightcurve.filters.invert.invert`)."""
REFLECTION_MODELS = ("none", "random-walk", "model1", "model2", "model3")
REFLECTION_KINDS = ("xi", "a", "m", "A")


def _num(name, v, *, lo=None, hi=None, lo_open=False, allow_none=False, file=None):
    if v is None and allow_none:
        return None
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise InputError("must be a number", file=file, field=name, value=v) from None
    bad = not math.isfinite(x) or (lo is not None and (x <= lo if lo_open else x < lo)) \
        or (hi is not None and x > hi)
    if bad:
        lo_s = "" if lo is None else f"{lo} {'<' if lo_open else '<='} "
        hi_s = "" if hi is None else f" <= {hi}"
        raise InputError("out of range", file=file, field=name, value=v,
                         allowed=f"{lo_s}{name}{hi_s}, finite")
    return x


def _choice(name, v, choices, file=None):
    if v not in choices:
        raise InputError("unknown value", file=file, field=name, value=v,
                         allowed=", ".join(map(str, choices)))
    return v


class ConfigBase:
    """Shared behaviour of the configuration dataclasses: construction from a mapping (a TOML
    table), conversion back to keyword options, validated copies."""

    @classmethod
    def from_mapping(cls, values: dict, *, file=None, table: str = ""):
        """Build from a mapping (e.g. the TOML table ``table`` of ``file``); unknown keys and
        bad values raise :class:`~lightcurve.errors.InputError` naming the file and the key."""
        names = {f.name for f in fields(cls)}
        pre = f"{table}." if table else ""
        unknown = sorted(set(values) - names)
        if unknown:
            raise InputError("unknown key", file=file, field=pre + unknown[0],
                             allowed=", ".join(sorted(names)))
        try:
            return cls(**values)
        except InputError as exc:
            if exc.file:
                raise
            raise InputError(exc.bare_message, file=file, field=pre + str(exc.field),
                             value=exc.value, allowed=exc.allowed) from None
        except (ValueError, TypeError) as exc:   # a value of the wrong type (float("abc"), …)
            raise InputError(str(exc), file=file, field=table or None) from None

    def as_options(self) -> dict:
        """The fields as keyword arguments of :func:`lightcurve.filters.invert`."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    #: ``{variant: {field: default}}``: the fields that, left None, take their variant's default
    #: on construction (empty: no such field)
    VARIANT_DEFAULTS: ClassVar[dict] = {}

    def _fill_variant_defaults(self):
        """Check ``self.variant`` (InputError naming the allowed variants) and set every field
        of :attr:`VARIANT_DEFAULTS` left None to that variant's default (call first in
        ``__post_init__``)."""
        _choice("variant", self.variant, VARIANTS)
        for k, v in self.VARIANT_DEFAULTS.get(self.variant, {}).items():
            if getattr(self, k) is None:
                object.__setattr__(self, k, v)

    def replace(self, **changes):
        """A copy with some fields changed (validated again). When ``variant`` changes, a field
        of :attr:`VARIANT_DEFAULTS` that holds the old variant's default and is not changed
        too takes the new variant's default (a value set away from the old default is kept)."""
        old = getattr(self, "variant", None)
        if self.VARIANT_DEFAULTS and changes.get("variant", old) != old:
            for k, v in self.VARIANT_DEFAULTS.get(old, {}).items():
                if k not in changes and getattr(self, k) == v:
                    changes[k] = None
        return dataclasses.replace(self, **changes)

    @classmethod
    def resolve(cls, config=None, **overrides):
        """``config`` (default: the default settings) with the non-None ``overrides`` applied —
        the keyword form of the filter runners (``run_ukf(problem, alpha=0.5)``)."""
        config = cls() if config is None else config
        changes = {k: v for k, v in overrides.items() if v is not None}
        return config.replace(**changes) if changes else config


@dataclass(frozen=True)
class ProblemConfig(ConfigBase):
    """The filter problem (initial estimate, dynamics, extra states, screening).

    Attributes
    ----------
    seed : int ≥ 0 — seeds the initial-estimate perturbation and every random draw.
    sigma_theta_deg, sigma_omega_deg_s : float > 0 — 1σ of the initial attitude (deg per axis)
        and rate (deg/s) errors; also ``P₀`` (Bernard ch. 9).
    initial_q, initial_omega : optional — a user initial estimate (inertial→body quaternion,
        scalar first; rad/s body axes) instead of the perturbed truth.
    shape : Shape, library name or None — default the file's shape.
    dynamics : "controlled" | "uncontrolled" | None — default the file's scenario.
    acs_sigma_deg : float ≥ 0 or None — ACS noise 1σ, deg (controlled; default the scenario's).
    acs_mode : "random_walk" | "jitter" | None — how ζ acts (:mod:`lightcurve.filters.models`;
        Bernard eq. 7.10 is "jitter"); default the stored scenario's ``[attitude] acs_mode``,
        else random_walk.
    pseudo_noise : float ≥ 0 — rate pseudo-noise PSD, (rad/s)²/s.
    eta_sigma_deg_s2 : float ≥ 0 or None — uncontrolled η level (default the scenario's).
    inertia_kg_m2 : (3,3) or None — uncontrolled inertia (default scenario, then shape).
    substep_s : float > 0 — largest RK4 sub-step of the uncontrolled model, s.
    attitude : "estimate" | "truth" — "truth": attitude known (§10.7).
    reflection : "none" | "random-walk" | "model1" | "model2" | "model3" — extra states for
        uncertain reflection parameters (Bernard ch. 8).
    reflection_frac : float > 0 — relative 1σ of the reflection parameters (eq. 8.10; §10.1).
    reflection_process_noise : float ≥ 0 — Model 3 process-noise PSD, z-units²/s.
    reflection_facets : tuple of int or None — Model 3 facets (default every Cook–Torrance).
    reflection_kinds : tuple of "xi", "a", "m", "A" — Model 3 parameters.
    gate : None, "auto", "reject", "inflate", "off", dict or GateConfig — innovation gate and
        epoch screening (:mod:`lightcurve.filters.gating`).
    library_dirs, site_dirs : tuple of paths or None — extra shape-library / observatory
        folders for a shape named by ``shape`` or by the file, and for the file's scenario.
    initial : "auto" | "truth" | "given" | "global" — where the filter starts
        (:func:`lightcurve.filters.invert.invert`).
    global_config : :class:`lightcurve.acquisition.global_init.GlobalInitConfig` or None —
        settings of ``initial="global"``.
    init_seed : int ≥ 0 or None — seeds the initial-estimate draw alone (default ``seed``):
        every filter of a Monte Carlo run given one ``init_seed`` starts from the same
        estimate (Bernard §9.3.1).
    """

    seed: int = 0
    sigma_theta_deg: float = 3.0
    sigma_omega_deg_s: float = 0.02
    initial_q: tuple | None = None
    initial_omega: tuple | None = None
    shape: object = None
    dynamics: str | None = None
    acs_sigma_deg: float | None = None
    acs_mode: str | None = None
    pseudo_noise: float = 0.0
    eta_sigma_deg_s2: float | None = None
    inertia_kg_m2: object = None
    substep_s: float = 0.5
    attitude: str = "estimate"
    reflection: str = "none"
    reflection_frac: float = 0.1
    reflection_process_noise: float = 0.0
    reflection_facets: tuple | None = None
    reflection_kinds: tuple = REFLECTION_KINDS
    gate: object = None
    library_dirs: tuple | None = None
    site_dirs: tuple | None = None
    initial: str = "auto"
    global_config: object = None
    init_seed: int | None = None

    def __post_init__(self):
        s = object.__setattr__
        try:
            seed = int(self.seed)
        except (TypeError, ValueError):
            raise InputError("must be an integer", field="seed", value=self.seed) from None
        if seed < 0 or seed != self.seed:
            raise InputError("must be an integer >= 0", field="seed", value=self.seed)
        s(self, "seed", seed)
        s(self, "sigma_theta_deg", _num("sigma_theta_deg", self.sigma_theta_deg, lo=0.0,
                                        hi=180.0, lo_open=True))
        s(self, "sigma_omega_deg_s", _num("sigma_omega_deg_s", self.sigma_omega_deg_s, lo=0.0,
                                          lo_open=True))
        for name, n in (("initial_q", 4), ("initial_omega", 3)):
            v = getattr(self, name)
            if v is not None:
                try:
                    t = tuple(float(x) for x in v)
                except (TypeError, ValueError):
                    raise InputError("must be a sequence of numbers", field=name,
                                     value=v) from None
                if len(t) != n or not all(math.isfinite(x) for x in t):
                    raise InputError(f"must be {n} finite numbers", field=name, value=v)
                s(self, name, t)
        if self.initial_q is not None and abs(math.sqrt(sum(x * x for x in self.initial_q))
                                              - 1.0) > 1e-6:
            raise InputError("must be a unit quaternion (to 1e-6)", field="initial_q",
                             value=self.initial_q)
        if self.dynamics is not None:
            _choice("dynamics", self.dynamics, DYNAMICS)
        s(self, "acs_sigma_deg", _num("acs_sigma_deg", self.acs_sigma_deg, lo=0.0,
                                      allow_none=True))
        if self.acs_mode is not None:
            _choice("acs_mode", self.acs_mode, ACS_MODES)
        if self.init_seed is not None:
            try:
                iseed = int(self.init_seed)
            except (TypeError, ValueError):
                raise InputError("must be an integer", field="init_seed",
                                 value=self.init_seed) from None
            if iseed < 0 or iseed != self.init_seed:
                raise InputError("must be an integer >= 0", field="init_seed",
                                 value=self.init_seed)
            s(self, "init_seed", iseed)
        s(self, "pseudo_noise", _num("pseudo_noise", self.pseudo_noise, lo=0.0))
        s(self, "eta_sigma_deg_s2", _num("eta_sigma_deg_s2", self.eta_sigma_deg_s2, lo=0.0,
                                         allow_none=True))
        s(self, "substep_s", _num("substep_s", self.substep_s, lo=0.0, lo_open=True))
        _choice("attitude", self.attitude, ATTITUDE_MODES)
        _choice("reflection", self.reflection, REFLECTION_MODELS)
        if self.attitude == "truth" and self.reflection == "none":
            raise InputError("attitude known (truth) leaves nothing to estimate without "
                             "reflection states", field="reflection", value=self.reflection,
                             allowed="random-walk, model1, model2, model3")
        s(self, "reflection_frac", _num("reflection_frac", self.reflection_frac, lo=0.0,
                                        lo_open=True))
        s(self, "reflection_process_noise", _num("reflection_process_noise",
                                                 self.reflection_process_noise, lo=0.0))
        if self.reflection_facets is not None:
            try:
                fac = tuple(int(i) for i in self.reflection_facets)
            except (TypeError, ValueError):
                raise InputError("must be facet indices", field="reflection_facets",
                                 value=self.reflection_facets) from None
            if any(i < 0 for i in fac):
                raise InputError("facet indices must be >= 0", field="reflection_facets",
                                 value=self.reflection_facets)
            s(self, "reflection_facets", fac)
        kinds = (self.reflection_kinds,) if isinstance(self.reflection_kinds, str) \
            else tuple(self.reflection_kinds)
        for k in kinds:
            _choice("reflection_kinds", k, REFLECTION_KINDS)
        s(self, "reflection_kinds", kinds)
        for name in ("library_dirs", "site_dirs"):
            v = getattr(self, name)
            if v is not None:
                s(self, name, (v,) if isinstance(v, (str, bytes)) or hasattr(v, "__fspath__")
                  else tuple(v))
        _choice("initial", self.initial, INITIAL_MODES)


@dataclass(frozen=True)
class MEKFConfig(ConfigBase):
    """Multiplicative EKF settings (:mod:`lightcurve.filters.mekf`; Bernard tables 7.1–7.2).

    error : "grp" | "small_angle" — how δθ⁺ is mapped back to a quaternion at the reset.
    jacobian : "analytic" | "numeric" — ∂m/∂δθ analytic or by central differences.
    variant : "robust" | "thesis".
    """

    method: ClassVar[str] = "mekf"
    error: str = "grp"
    jacobian: str = "analytic"
    variant: str = "robust"

    def __post_init__(self):
        _choice("error", self.error, ("grp", "small_angle"))
        _choice("jacobian", self.jacobian, ("analytic", "numeric"))
        _choice("variant", self.variant, VARIANTS)


#: the scaled-unscented α of each filter variant when none is given. Bernard §6.2.2 gives only
#: its range (0 < α ≤ 1) and §7.2 (eq. 7.64) no value. Thesis variant: 0.25, the value at which
#: the thesis-variant UKF leaves the fewest runs outside its own 3σ bounds over the Monte Carlo
#: of Fig. 9.4 and B.1–B.4 (α = 1, 0.5, 0.25, 10⁻³ tried; docs/measurements.md) — a criterion
#: that does not read the published colours, one value for every case. Robust variant: 1.
UKF_DEFAULT_ALPHA = {"robust": 1.0, "thesis": 0.25}


@dataclass(frozen=True)
class UKFConfig(ConfigBase):
    """USQUE/GRP unscented filter settings (:mod:`lightcurve.filters.ukf`; Bernard eq.
    7.51–7.87): the scaled-unscented parameters α > 0, β, κ (λ = α²(n+κ) − n) and ``variant``.
    ``alpha`` left None takes the variant's default (:data:`UKF_DEFAULT_ALPHA`) on
    construction; ``replace(variant=...)`` moves an α at the old variant's default to the new
    one's and keeps any other.
    """

    method: ClassVar[str] = "ukf"
    VARIANT_DEFAULTS: ClassVar[dict] = {v: {"alpha": a} for v, a in UKF_DEFAULT_ALPHA.items()}
    alpha: float | None = None
    beta: float = 2.0
    kappa: float = 0.0
    variant: str = "robust"

    def __post_init__(self):
        self._fill_variant_defaults()
        object.__setattr__(self, "alpha", _num("alpha", self.alpha, lo=0.0, lo_open=True))
        object.__setattr__(self, "beta", _num("beta", self.beta))
        object.__setattr__(self, "kappa", _num("kappa", self.kappa))


_FILTER_CONFIGS: dict = {"mekf": MEKFConfig, "ukf": UKFConfig}
METHOD_NAMES = ("mekf", "ukf", "bpf")
"""Filter method names known to :func:`lightcurve.filters.invert`."""


def register_filter_config(cls) -> type:
    """Register a filter configuration class under its ``method`` name (a class attribute).

    The class must be a frozen dataclass with a ``variant`` field, deriving from the same
    mapping/validation behaviour as :class:`MEKFConfig`; its runner takes it as
    ``run(problem, config, *, bias, facets, …)``. Returns the class (usable as a decorator).
    """
    _FILTER_CONFIGS[cls.method] = cls
    return cls


def filter_config_class(method: str):
    """The configuration class of ``method`` ("mekf", "ukf", "bpf"), or None when the method
    has no registered class."""
    _choice("method", method, METHOD_NAMES)
    return _FILTER_CONFIGS.get(method)


def filter_config(method: str, **values):
    """The configuration object of ``method`` built from keyword values."""
    cls = filter_config_class(method)
    if cls is None:
        raise InputError("this filter has no configuration class", field="method",
                         value=method)
    return cls(**values)


BPF_KEYWORDS = {"particles": 10_000, "roughening": 0.2, "resampling": "systematic",
                "ess_threshold": 0.5, "rejuvenation": "auto", "keep_clouds": ()}
"""Keyword options (and defaults) of the particle filter's keyword form."""


def _filter_names(method):
    cls = _FILTER_CONFIGS.get(method)
    if cls is not None:
        return {f.name for f in fields(cls)}
    return set(BPF_KEYWORDS) | {"variant"} if method == "bpf" else set()


def split_options(method: str, options: dict):
    """Split :func:`~lightcurve.filters.invert`-style keywords into ``(problem keywords,
    keywords of this filter)``.

    Keywords of another filter (e.g. ``particles`` in an MEKF call) are dropped, as the keyword
    form of ``invert`` always did; a keyword known to no configuration raises TypeError.
    """
    _choice("method", method, METHOD_NAMES)
    prob_names = {f.name for f in fields(ProblemConfig)}
    mine = _filter_names(method)
    known = set().union(*(_filter_names(m) for m in METHOD_NAMES))
    unknown = sorted(set(options) - prob_names - known)
    if unknown:
        raise TypeError(f"invert() got an unexpected keyword argument {unknown[0]!r}")
    prob = {k: v for k, v in options.items() if k in prob_names}
    filt = {k: v for k, v in options.items() if k in mine}
    return prob, filt

