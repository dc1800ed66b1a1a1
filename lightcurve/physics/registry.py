"""The physics-effects registry: one list of optional effects for simulation AND diagnosis.

An *effect* is a piece of physics the baseline measurement model leaves out (atmospheric
extinction, Earthshine, the penumbra, self-shadowing, light time, exposure smearing, a clock
offset, a photometric zero point, an unmodelled glint, and for coarse sun sensors albedo,
misalignment, scale factors and faults). Each registered effect is a subclass of
:class:`Effect` with

* ``name`` — the key used in the scenario's ``[effects.<name>]`` table and in reports;
* ``description`` — one plain-language sentence: what the physics is and what it does to
  the measurements;
* ``params`` — the fittable parameters (:class:`ParamSpec`: unit, default, prior, allowed
  range, whether there is one value per site or per sensor);
* ``options`` — non-fitted settings (an albedo map path, a number of sub-samples…);
* ``kind`` — ``"magnitude"`` (lightcurves; context :class:`~.context.ModelContext`) or
  ``"css"`` (coarse-sun-sensor voltages; context :class:`~.context.CSSContext`);
* ``apply(ctx, params)`` — the forward model: the measurements with the effect on;
* ``signature(ctx)`` — the (N,) geometric quantity the residual of a model *without* the
  effect follows (airmass for extinction, dm/dt for a clock offset…), and
  ``signature_columns(ctx)`` — the same split into columns (one per site for per-site
  effects) for linear screening;
* ``sample_params(rng, ctx)`` — random realistic parameters (draws from the prior).

Effects compose through the context: "model" effects return a modified context
(:meth:`Effect.transform`), "observation" effects add a magnitude offset
(:meth:`Effect.offset`). :func:`apply_effects` applies a list of configured effects in the
documented order (:data:`ORDER`), so the result does not depend on the order in the file.

Parameter values: a scalar float for ordinary parameters, an array of shape (K,) for a
per-site parameter (K sites of the context) and (S,) for a per-sensor parameter.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError

__all__ = [
    "Prior", "ParamSpec", "Effect", "ConfiguredEffect", "register_effect", "get_effect",
    "available_effects", "effect_class", "apply_effects", "parse_effects", "effects_to_json",
    "ORDER",
]

#: Application order of the effect groups (lower first). Model effects change what light
#: leaves the object (illumination, extra reflectors, occlusion), timing effects change when
#: the model is evaluated, atmosphere and instrument effects add magnitude offsets.
ORDER = {"illumination": 10, "reflection": 20, "occlusion": 30, "timing": 40,
         "atmosphere": 50, "instrument": 60, "sensor": 70}


# ------------------------------------------------------------------------------------------
# priors and parameter specifications
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Prior:
    """A prior distribution of one parameter value.

    kind:
      ``"normal"`` (a = mean, b = standard deviation), ``"uniform"`` (a = low, b = high),
      ``"log_uniform"`` (a = low > 0, b = high), ``"signed_uniform"`` (|x| uniform in
      [a, b], sign ±1 with equal probability: "an offset of unknown sign of this size"),
      ``"int_uniform"`` (integers a … b inclusive; b < 0 means "up to size − 1 + b + 1",
      resolved by the caller with ``size``).
    """

    kind: str
    a: float
    b: float

    _KINDS = ("normal", "uniform", "log_uniform", "signed_uniform", "int_uniform")

    def __post_init__(self):
        if self.kind not in self._KINDS:
            raise ValueError(f"unknown prior kind {self.kind!r}; allowed: {', '.join(self._KINDS)}")
        if self.kind == "normal" and not self.b > 0:
            raise ValueError("normal prior needs a positive standard deviation")
        if self.kind in ("uniform", "signed_uniform") and not self.b > self.a:
            raise ValueError("uniform prior needs high > low")
        if self.kind == "log_uniform" and not (0 < self.a < self.b):
            raise ValueError("log_uniform prior needs 0 < low < high")

    def sample(self, rng, size=None, n_max: int | None = None):
        """Draw from the prior with a ``numpy.random.Generator`` (``size`` as numpy)."""
        if self.kind == "normal":
            return rng.normal(self.a, self.b, size)
        if self.kind == "uniform":
            return rng.uniform(self.a, self.b, size)
        if self.kind == "log_uniform":
            return np.exp(rng.uniform(math.log(self.a), math.log(self.b), size))
        if self.kind == "signed_uniform":
            mag = rng.uniform(self.a, self.b, size)
            return mag * np.where(rng.random(size) < 0.5, -1.0, 1.0)
        hi = int(self.b) if self.b >= 0 or n_max is None else n_max - 1
        return rng.integers(int(self.a), hi + 1, size).astype(float)

    def logpdf(self, x):
        """Log prior density (up to the normalisation of ``int_uniform``); −inf outside."""
        x = np.asarray(x, float)
        if self.kind == "normal":
            return -0.5 * ((x - self.a) / self.b) ** 2 - math.log(self.b * math.sqrt(2 * math.pi))
        if self.kind == "uniform":
            return np.where((x >= self.a) & (x <= self.b), -math.log(self.b - self.a), -np.inf)
        if self.kind == "log_uniform":
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.where((x >= self.a) & (x <= self.b),
                                -np.log(x) - math.log(math.log(self.b / self.a)), -np.inf)
        if self.kind == "signed_uniform":
            ax = np.abs(x)
            return np.where((ax >= self.a) & (ax <= self.b), -math.log(2 * (self.b - self.a)), -np.inf)
        return np.where(x == np.round(x), 0.0, -np.inf)

    def as_dict(self) -> dict:
        return {"kind": self.kind, "a": self.a, "b": self.b}


@dataclass(frozen=True)
class ParamSpec:
    """One fittable parameter of an effect.

    ``name`` (TOML key), ``unit`` (SI or mag, stated), ``default`` (value used when the
    TOML omits it), ``prior`` (:class:`Prior`, also used by :meth:`Effect.sample_params`),
    ``min``/``max`` (allowed closed range; a value outside raises InputError naming
    ``effects.<effect>.<param>``), ``per`` (None, ``"site"``, ``"camera"`` or ``"sensor"``:
    one value per site / per camera / per sensor; a context without cameras has one camera
    per site, named after it), ``integer`` (whole numbers only), ``description``,
    ``null`` (the value at which the effect vanishes — an amplitude such as an area, an
    offset or an extinction coefficient — or None when no value switches it off; the
    diagnosis names an effect only when its amplitudes differ from ``null`` by more than
    their uncertainty), ``fixable`` (the default is a physically meaningful reference value
    — e.g. the geometric shadow — at which the diagnosis may hold the parameter when the
    data do not identify it, saying so).
    """

    name: str
    unit: str
    default: float
    prior: Prior
    min: float = -math.inf
    max: float = math.inf
    per: str | None = None
    integer: bool = False
    description: str = ""
    null: float | None = None
    fixable: bool = False

    _PER = (None, "site", "camera", "sensor")

    def __post_init__(self):
        if self.per not in self._PER:
            raise ValueError(f"ParamSpec {self.name!r}: per must be one of {self._PER}")

    def as_dict(self) -> dict:
        return {"name": self.name, "unit": self.unit, "default": self.default,
                "prior": self.prior.as_dict(), "min": self.min, "max": self.max,
                "per": self.per, "integer": self.integer, "description": self.description,
                "null": self.null, "fixable": self.fixable}


# ------------------------------------------------------------------------------------------
# the effect base class and the registry
# ------------------------------------------------------------------------------------------
class Effect:
    """Base class of a physics effect (module docstring).

    Subclasses set the class attributes (their docstring is the plain-language
    ``description``, see :func:`register_effect`) and implement :meth:`transform` and/or
    :meth:`offset`; instances carry the validated ``options`` (constructor keywords).
    """

    name: str = ""
    description: str = ""
    params: tuple = ()
    options: dict = {}
    kind: str = "magnitude"
    group: str = "illumination"
    #: options whose value (other than the default in :attr:`options`) names a file to read;
    #: a scenario stored inside a data file may not set them (:func:`parse_effects`)
    file_options: tuple = ()
    #: parameters the diagnosis never fits separately, with the reason (only a combination
    #: with other parameters is identifiable; they stay at their default)
    diagnosis_hold: dict = {}
    #: parameters a fit holds at the value it is given (set per instance by the diagnosis)
    hold: frozenset = frozenset()
    #: components of per-site/camera/sensor parameters a fit holds at the value it is given,
    #: {name: frozenset(indices)} (set per instance by the diagnosis)
    hold_components: dict = {}

    def __init__(self, **options):
        unknown = set(options) - set(self.options)
        if unknown:
            raise ValueError(f"effect {self.name!r}: unknown option(s) {sorted(unknown)}; "
                             f"allowed: {', '.join(self.options) or 'none'}")
        self.opts = {**self.options, **options}

    # -- parameters ----------------------------------------------------------------------
    @property
    def order(self) -> int:
        """Position in the application order (:data:`ORDER`)."""
        return ORDER[self.group]

    def param_names(self) -> list[str]:
        return [p.name for p in self.params]

    def _size(self, spec: ParamSpec, ctx) -> int | None:
        if spec.per is None:
            return None
        if ctx is None:
            raise ValueError(f"parameter {spec.name!r} of {self.name!r} is per {spec.per}: "
                             "a context is needed to know how many values")
        if spec.per == "site":
            return ctx.n_sites
        if spec.per == "camera":
            # a size-only context without cameras: one camera per site
            return getattr(ctx, "n_cameras", None) or ctx.n_sites
        return ctx.n_sensors

    def default_params(self, ctx=None) -> dict:
        """Every parameter at its default (per-site/sensor parameters as arrays)."""
        out = {}
        for p in self.params:
            n = self._size(p, ctx)
            out[p.name] = float(p.default) if n is None else np.full(n, float(p.default))
        return out

    def sample_params(self, rng, ctx=None) -> dict:
        """Random realistic parameters: independent draws from each prior, clipped to range."""
        rng = np.random.default_rng(rng) if not isinstance(rng, np.random.Generator) else rng
        out = {}
        for p in self.params:
            n = self._size(p, ctx)
            nmax = ctx.n_sensors if (p.per is None and p.integer and ctx is not None
                                     and hasattr(ctx, "n_sensors")) else None
            v = np.clip(p.prior.sample(rng, n, n_max=nmax), p.min, p.max)
            out[p.name] = float(v) if n is None else np.asarray(v, float)
        return out

    def check_params(self, params: dict, ctx=None) -> dict:
        """Fill defaults, check names, shapes and ranges (ValueError: programmer misuse)."""
        known = {p.name: p for p in self.params}
        bad = set(params) - set(known)
        if bad:
            raise ValueError(f"effect {self.name!r}: unknown parameter(s) {sorted(bad)}; "
                             f"allowed: {', '.join(known) or 'none'}")
        out = self.default_params(ctx)
        for k, v in params.items():
            spec = known[k]
            n = self._size(spec, ctx)
            a = np.asarray(v, float)
            if n is None:
                if a.ndim != 0:
                    raise ValueError(f"{self.name}.{k}: expected a scalar")
                val = float(a)
            else:
                a = np.broadcast_to(a, (n,)).astype(float)
                val = a.copy()
            arr = np.atleast_1d(val)
            if not np.all(np.isfinite(arr)) or np.any(arr < spec.min) or np.any(arr > spec.max):
                raise ValueError(f"{self.name}.{k} = {val!r} outside [{spec.min}, {spec.max}]")
            out[k] = val
        return out

    # -- the forward model -----------------------------------------------------------------
    def transform(self, ctx, params: dict):
        """Return a context with the effect switched on (default: unchanged)."""
        return ctx

    def offset(self, ctx, params: dict):
        """Additive magnitude (or voltage) offset (N,) of the effect (default: None = 0)."""
        return None

    def apply(self, ctx, params: dict | None = None):
        """Measurements with this effect on (magnitudes (N,) or CSS voltages (N, S))."""
        params = self.check_params(params or {}, ctx)
        c2 = self.transform(ctx, params)
        y = c2.evaluate()
        off = self.offset(c2, params)
        return y if off is None else y + off

    def signature(self, ctx) -> np.ndarray:
        """(N,) geometric quantity the residual of a model without this effect follows.

        Default: the change of the measurement caused by the effect at its prior's typical
        parameters (:meth:`typical_params`), i.e. ``apply(ctx) − ctx.evaluate()``; for CSS
        effects the change summed over sensors. Subclasses override with the named
        geometric quantity.
        """
        d = self.apply(ctx, self.typical_params(ctx)) - ctx.evaluate()
        d = np.where(np.isfinite(d), d, 0.0)
        return d if d.ndim == 1 else d.sum(axis=1)

    def signature_columns(self, ctx) -> np.ndarray:
        """(N, P) signature columns; per-site (per-camera) effects give one column per site
        (camera), zero elsewhere."""
        s = np.asarray(self.signature(ctx), float)
        pers = {p.per for p in self.params}
        if "site" in pers or "camera" in pers:
            idx, n = ((ctx.site_index, ctx.n_sites) if "site" in pers
                      else (ctx.camera_index_rows, ctx.n_cameras))
            cols = np.zeros((s.size, n))
            for k in range(n):
                m = idx == k
                cols[m, k] = s[m]
            return cols
        return s[:, None]

    def typical_params(self, ctx=None) -> dict:
        """Parameters of typical size: the default, or the prior's centre/scale if default = 0."""
        out = self.default_params(ctx)
        for p in self.params:
            pr = p.prior
            if p.default != 0.0 or p.integer:
                continue
            # only the formula of the prior's own kind is evaluated (sqrt needs a, b > 0)
            if pr.kind == "normal":
                typ = pr.a + pr.b
            elif pr.kind in ("uniform", "signed_uniform"):
                typ = 0.5 * (pr.a + pr.b)
            elif pr.kind == "log_uniform":
                typ = math.sqrt(pr.a * pr.b)
            else:
                typ = p.default
            typ = min(max(typ, p.min), p.max)
            out[p.name] = typ if np.ndim(out[p.name]) == 0 else np.full(np.shape(out[p.name]), typ)
        return out

    # -- TOML ------------------------------------------------------------------------------
    def parse_options(self, sec) -> dict:
        """Read this effect's options from a :class:`~lightcurve.io.tomlio.Section`.

        Default: float/int/str options read with the type of their default. Subclasses
        override for range checks (raising InputError through the Section getters).
        """
        out = {}
        for k, d in self.options.items():
            if isinstance(d, bool):
                out[k] = sec.bool(k, d)
            elif isinstance(d, int):
                out[k] = sec.int(k, d, min=1)
            elif isinstance(d, float):
                out[k] = sec.float(k, d)
            else:
                out[k] = sec.str(k, d)
        return out

    def describe(self) -> dict:
        """JSON-able description (name, description, kind, params, options)."""
        return {"name": self.name, "description": self.description, "kind": self.kind,
                "group": self.group, "params": [p.as_dict() for p in self.params],
                "options": dict(self.options)}

    def __repr__(self):
        return f"<Effect {self.name}{' ' + str(self.opts) if self.opts else ''}>"


_REGISTRY: dict[str, type] = {}


def register_effect(cls):
    """Class decorator: add an :class:`Effect` subclass to the registry under ``cls.name``.

    The class docstring is the effect's plain-language ``description`` (whitespace folded to
    single spaces) unless the class sets ``description`` itself."""
    if not (isinstance(cls, type) and issubclass(cls, Effect)):
        raise TypeError("register_effect decorates Effect subclasses")
    if "description" not in vars(cls) and cls.__doc__:
        cls.description = " ".join(cls.__doc__.split())
    if not cls.name or not cls.description:
        raise ValueError(f"{cls.__name__}: an effect needs a name and a description")
    if cls.group not in ORDER:
        raise ValueError(f"{cls.__name__}: unknown group {cls.group!r}; allowed: {', '.join(ORDER)}")
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise ValueError(f"an effect named {cls.name!r} is already registered")
    _REGISTRY[cls.name] = cls
    return cls


def _load_builtin():
    from . import (atmosphere, css_effects, earthshine, glint, photometric,  # noqa: F401
                   self_shadowing, shadow, timing)


def available_effects(kind: str | None = None) -> list[str]:
    """Sorted names of the registered effects (optionally only ``"magnitude"`` or ``"css"``)."""
    _load_builtin()
    return sorted(n for n, c in _REGISTRY.items() if kind is None or c.kind == kind)


def effect_class(name: str) -> type:
    """The registered class of ``name`` (KeyError listing the available names)."""
    _load_builtin()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise KeyError(f"unknown effect {name!r}; available: {', '.join(sorted(_REGISTRY))}") from None


def get_effect(name: str, **options) -> Effect:
    """An instance of the registered effect ``name`` configured with ``options``."""
    return effect_class(name)(**options)


# ------------------------------------------------------------------------------------------
# configured effects, application and TOML parsing
# ------------------------------------------------------------------------------------------
@dataclass
class ConfiguredEffect:
    """An effect instance with its parameter values (``params``: name → float or array)."""

    effect: Effect
    params: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.effect.name


def apply_effects(ctx, configured) -> np.ndarray:
    """Measurements with every configured effect on, applied in :data:`ORDER`.

    Transforms are chained (each sees the context the previous ones produced); offsets
    are evaluated on the final context and added.
    """
    items = sorted(configured, key=lambda c: c.effect.order)
    checked = [(c.effect, c.effect.check_params(c.params, ctx)) for c in items]
    for eff, p in checked:
        ctx = eff.transform(ctx, p)
    y = ctx.evaluate()
    for eff, p in checked:
        off = eff.offset(ctx, p)
        if off is not None:
            y = y + off
    return y


def _param_value(sec, spec: ParamSpec, site_names, n_sensors, effect_name, camera_names=None):
    """Read one parameter (scalar; per-site: scalar or {site = value}; per-camera: scalar or
    {camera = value}, cameras named after their sites when the scenario has none;
    per-sensor: list)."""
    fld = f"effects.{effect_name}.{spec.name}"
    raw = sec.raw(spec.name, None)
    if raw is None:
        return None

    def num(x, where):
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(float(x)):
            raise InputError("expected a finite number", file=sec.file, field=where, value=x)
        x = float(x)
        if spec.integer and x != round(x):
            raise InputError("expected a whole number", file=sec.file, field=where, value=x)
        if x < spec.min or x > spec.max:
            raise InputError("value out of range", file=sec.file, field=where, value=x,
                             allowed=f"[{spec.min}, {spec.max}] {spec.unit}")
        return x

    if spec.per is None:
        return num(raw, fld)
    if spec.per in ("site", "camera"):
        names = site_names if spec.per == "site" or camera_names is None else list(camera_names)
        word = "site" if spec.per == "site" else "camera"
        if isinstance(raw, dict):
            unknown = [k for k in raw if k not in names]
            if unknown:
                raise InputError(f"unknown {word} id", file=sec.file, field=f"{fld}.{unknown[0]}",
                                 value=unknown[0], allowed=", ".join(names))
            vals = np.full(len(names), float(spec.default))
            for k, v in raw.items():
                vals[names.index(k)] = num(v, f"{fld}.{k}")
            return vals
        return np.full(len(names), num(raw, fld))
    # per sensor
    if isinstance(raw, list):
        if n_sensors is not None and len(raw) != n_sensors:
            raise InputError(f"expected {n_sensors} values (one per sensor)", file=sec.file,
                             field=fld, value=raw)
        return np.array([num(v, f"{fld}[{i}]") for i, v in enumerate(raw)])
    v = num(raw, fld)
    return v if n_sensors is None else np.full(n_sensors, v)


def parse_effects(raw, file=None, site_names=(), n_sensors=None, kind: str | None = "magnitude",
                  camera_names=None, embedded: bool = False):
    """Validate a scenario's ``[effects]`` table into a list of :class:`ConfiguredEffect`.

    ``raw``: the parsed table ``{effect_name: {key: value}}``; ``site_names``: the scenario's
    site ids (for per-site values ``{site_id = value}``); ``camera_names``: camera ids for
    per-camera values (default: one camera per site, named after it); ``n_sensors``: for
    per-sensor CSS parameters. A table may set ``enabled = false`` to keep its settings but switch it off.
    ``embedded``: the table comes from a scenario stored inside a data file; an option that
    names a file (:attr:`Effect.file_options`) may then only keep its default, so a received
    file cannot make the program open a file of its choosing.
    Raises :class:`InputError` for an unknown effect (listing the available ones), an effect
    of the wrong kind, an unknown key, or a value outside its range (naming
    ``effects.<name>.<param>``).
    """
    from ..io.tomlio import Section

    if raw is None:
        return []
    if not isinstance(raw, dict):
        raise InputError("expected a table", file=file, field="effects", value=raw)
    site_names = list(site_names)
    out = []
    for name, body in raw.items():
        avail = available_effects(kind)
        if name not in avail:
            raise InputError("unknown effect", file=file, field=f"effects.{name}", value=name,
                             allowed=", ".join(avail))
        if not isinstance(body, dict):
            raise InputError("expected a table [effects.<name>]", file=file,
                             field=f"effects.{name}", value=body)
        sec = Section(body, file=file, name=f"effects.{name}")
        cls = effect_class(name)
        if embedded:
            for key in cls.file_options:
                if key in body and body[key] != cls.options.get(key):
                    raise InputError("a scenario stored in a data file may not name files",
                                     file=file, field=f"effects.{name}.{key}", value=body[key],
                                     allowed=f"{cls.options.get(key)!r} (the default); give the "
                                     "model scenario as a file instead")
        proto = cls()
        opts = proto.parse_options(sec)
        enabled = sec.bool("enabled", True)
        vals = {}
        for spec in cls.params:
            v = _param_value(sec, spec, site_names, n_sensors, name, camera_names)
            if v is not None:
                vals[spec.name] = v
        sec.check_unknown()
        if not enabled:
            continue
        try:
            eff = cls(**opts)
        except ValueError as exc:
            raise InputError(str(exc), file=file, field=f"effects.{name}") from None
        out.append(ConfiguredEffect(eff, vals))
    return sorted(out, key=lambda c: c.effect.order)


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return [float(x) for x in v]
    if isinstance(v, (np.floating, np.integer)):
        return float(v)
    return v


def effects_to_json(configured, site_names=None, camera_names=None) -> str:
    """JSON text ``{name: {"params": {...}, "options": {...}, "order": i}}`` for file attrs.

    Per-site (per-camera) parameters are written as ``{site_id: value}`` when ``site_names``
    is given (``{camera_id: value}``; cameras default to the sites).
    """
    out = {}
    cams = site_names if camera_names is None else list(camera_names)
    for i, c in enumerate(configured):
        params = {}
        specs = {p.name: p for p in c.effect.params}
        for k, v in c.params.items():
            names = site_names if specs[k].per == "site" else cams
            if names is not None and specs[k].per in ("site", "camera"):
                params[k] = {s: float(x) for s, x in zip(names, np.broadcast_to(v, (len(names),)))}
            else:
                params[k] = _jsonable(v)
        out[c.name] = {"params": params, "options": {k: _jsonable(v) for k, v in c.effect.opts.items()},
                       "order": i, "group": c.effect.group}
    return json.dumps(out, sort_keys=False)
