"""The diagnosis problem: observations, their noise, a baseline model and its free parameters.

A :class:`Problem` holds

* ``y`` (M,) the measurements (apparent magnitudes, or CSS outputs flattened epoch-major)
  and ``sigma`` (M,) their 1σ noise (same units);
* ``ctx`` the baseline forward model (:class:`~lightcurve.physics.ModelContext` or
  :class:`~lightcurve.physics.CSSContext`) — the scenario's model with no effect on;
* ``free`` the baseline's free parameters (:class:`FreeParam`): a per-site photometric zero
  point (mag, additive) and/or per-facet reflection parameters of the shape's BRDFs
  (``Kd``, ``Ks``, ``n`` of Phong, ``xi``/``a``/``m`` of Cook–Torrance …), each with bounds;
* per-measurement bookkeeping for the residual analysis and the cross-validation folds:
  time ``t`` (s since the epoch), ``site`` index, ``epoch_index`` (row of ``ctx``), geometry
  regimes, and per epoch the local night, the object and the camera (when the recording
  names them).

:meth:`Problem.predict` evaluates the model for a baseline parameter vector and a list of
effect terms ``[(Effect, params), …]`` through :func:`lightcurve.physics.apply_effects`
(the registry's forward models: the same code that simulates data with effects on).
Standardised residuals are ``z = (y − ŷ)/σ`` (dimensionless). Predictions that are not
finite (an effect that puts the object in full shadow, no reflected light) are mapped to a
fixed large standardised residual (:data:`Z_NONFINITE`) so that optimisers stay defined.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InputError

__all__ = ["FreeParam", "Problem", "Z_NONFINITE", "magnitude_problem", "css_problem",
           "parse_free", "recording_columns", "combine_problems", "with_free_words", "clipped_gaussian_mean", "clipped_gaussian_sd"]

#: Standardised residual assigned to a non-finite prediction (e.g. an epoch put in umbra).
Z_NONFINITE = 30.0

#: Finite upper bound used for reflection parameters whose allowed range is unbounded-ish.
_BRDF_CAP = {"n": 200.0, "m": 1.0}


@dataclass
class FreeParam:
    """One free baseline parameter.

    ``kind`` is ``"zero_point"`` (``index`` = site index; additive mag, bounds ±``span``) or
    ``"brdf"`` (``key`` = BRDF parameter name, ``index`` = facet index). ``x0`` is the
    scenario's value, ``lo``/``hi`` the fit bounds, ``unit`` the unit.
    """

    name: str
    kind: str
    key: str
    index: int
    x0: float
    lo: float
    hi: float
    unit: str = "1"


@dataclass
class Problem:
    """Observations + baseline model + free parameters (module docstring)."""

    kind: str
    ctx: object
    y: np.ndarray
    sigma: np.ndarray
    t: np.ndarray
    site: np.ndarray
    epoch_index: np.ndarray
    site_names: list
    free: list = field(default_factory=list)
    #: (E,) per-epoch geometric descriptors for segment tests (NaN when unknown)
    elevation_rad: np.ndarray | None = None
    phase_rad: np.ndarray | None = None
    shadow_margin: np.ndarray | None = None
    #: optional (E,) UTC-day-of-night index per epoch, for cross-validation
    night: np.ndarray | None = None
    #: names of effects the diagnosis must not propose (e.g. duplicates of free parameters)
    exclude: tuple = ()
    label: str = ""
    #: CSS outputs recorded as max(signal + noise, 0) (the simulator's photodiode clipping):
    #: predictions are then the mean of that clipped Gaussian, s Φ(s/σ) + σ φ(s/σ), so
    #: residuals of dark sensors are unbiased (:meth:`predict`)
    censored_at_zero: bool = False
    #: optional (E,) object index per epoch (several satellites in one recording) and names
    object: np.ndarray | None = None
    object_names: list | None = None
    #: optional (E,) camera index per epoch and names (the context carries them too)
    camera: np.ndarray | None = None
    camera_names: list | None = None

    def __post_init__(self):
        self.y = np.asarray(self.y, float).ravel()
        self.sigma = np.asarray(self.sigma, float).ravel()
        if self.y.shape != self.sigma.shape:
            raise ValueError("y and sigma must have the same length")
        if not np.all(self.sigma > 0):
            raise InputError("every measurement sigma must be positive", field="mag_sigma")

    # -- sizes --------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of measurements M."""
        return int(self.y.size)

    @property
    def n_free(self) -> int:
        return len(self.free)

    def x0(self) -> np.ndarray:
        return np.array([p.x0 for p in self.free], float)

    def bounds(self):
        return (np.array([p.lo for p in self.free], float), np.array([p.hi for p in self.free], float))

    # -- the model ------------------------------------------------------------------------
    def base_context(self, theta=None):
        """The baseline context with the reflection parameters of ``theta`` applied."""
        ctx = self.ctx
        if theta is None or self.kind != "magnitude":
            return ctx
        brdf = {}
        for p, v in zip(self.free, np.asarray(theta, float)):
            if p.kind == "brdf":
                brdf.setdefault(p.key, ctx.shape.facet_params(p.key))[p.index] = v
        if not brdf:
            return ctx
        return ctx.with_state(shape=ctx.shape.copy_with(check=False, **brdf))

    def zero_point(self, theta) -> np.ndarray:
        """Additive magnitude (M,) of the free per-site zero points (0 when none)."""
        out = np.zeros(self.n)
        if theta is None:
            return out
        ch = self.channel
        for p, v in zip(self.free, np.asarray(theta, float)):
            if p.kind == "zero_point":
                out[ch == p.index] += v
        return out

    @property
    def channel(self) -> np.ndarray:
        """(M,) photometric channel of each measurement: its camera, else its site."""
        if self.camera is not None:
            return np.asarray(self.camera)[self.epoch_index]
        return self.site

    @property
    def channel_names(self) -> list:
        """Names of the photometric channels (cameras, else sites)."""
        return list(self.camera_names) if self.camera_names is not None else list(self.site_names)

    def predict(self, theta=None, terms=()) -> np.ndarray:
        """Model measurements (M,) for baseline parameters ``theta`` and effect ``terms``.

        ``terms``: sequence of ``(Effect, params)``; applied with
        :func:`lightcurve.physics.apply_effects` (documented order).
        """
        from ..physics import ConfiguredEffect, apply_effects

        ctx = self.base_context(theta)
        if terms:
            y = apply_effects(ctx, [ConfiguredEffect(e, dict(p)) for e, p in terms])
        else:
            y = ctx.evaluate()
        y = np.asarray(y, float)
        y = y.ravel() if self.kind == "css" else y[self.epoch_index]
        if self.censored_at_zero:
            y = clipped_gaussian_mean(y, self.sigma)
        return y + self.zero_point(theta)

    def standardized(self, pred) -> np.ndarray:
        """z = (y − ŷ)/σ (M,), non-finite predictions mapped to ±:data:`Z_NONFINITE`.

        For outputs censored at zero, σ is the standard deviation of the clipped Gaussian
        with mean ŷ (:func:`clipped_gaussian_sd`; 0.58 σ for a dark sensor).
        """
        sd = clipped_gaussian_sd(pred, self.sigma) if self.censored_at_zero else self.sigma
        z = (self.y - pred) / sd
        return np.where(np.isfinite(z), z, Z_NONFINITE)

    def chi2(self, pred) -> float:
        z = self.standardized(pred)
        return float(z @ z)

    def subset(self, mask) -> "Problem":
        """The problem restricted to the measurements where ``mask`` (M,) is true.

        The context keeps only the epochs those measurements need (so expensive effects
        evaluate fewer epochs).
        """
        from ..physics.context import CSSContext

        mask = np.asarray(mask, bool)
        ep = np.unique(self.epoch_index[mask])
        remap = -np.ones(len(self.ctx), np.int64)
        remap[ep] = np.arange(ep.size)
        ctx = _subset_context(self.ctx, ep)

        def sel(a):
            return None if a is None else np.asarray(a)[ep]

        if isinstance(self.ctx, CSSContext):
            # CSS measurements are epoch-major (K, S): keep whole epochs
            S = self.ctx.n_sensors
            full = np.zeros(len(self.ctx), bool)
            full[ep] = True
            mask = np.repeat(full, S)
        return replace(self, ctx=ctx, y=self.y[mask], sigma=self.sigma[mask], t=self.t[mask],
                       site=self.site[mask], epoch_index=remap[self.epoch_index[mask]],
                       free=list(self.free), elevation_rad=sel(self.elevation_rad),
                       phase_rad=sel(self.phase_rad), shadow_margin=sel(self.shadow_margin),
                       night=sel(self.night), object=sel(self.object), camera=sel(self.camera))

    def with_free(self, free) -> "Problem":
        """The same problem with the free baseline parameters ``free`` (list of FreeParam)."""
        return replace(self, free=list(free))


def clipped_gaussian_mean(s, sigma):
    """Mean of max(s + n, 0) for n ~ N(0, σ²): s Φ(s/σ) + σ φ(s/σ) (same unit as s).

    Tends to s for s ≫ σ and to 0.399 σ at s = 0 (a dark photodiode still reads its positive
    noise half).
    """
    from scipy.special import ndtr

    s = np.asarray(s, float)
    sig = np.broadcast_to(np.asarray(sigma, float), s.shape)
    u = s / sig
    return s * ndtr(u) + sig * np.exp(-0.5 * u * u) / np.sqrt(2.0 * np.pi)


_U_TABLE = np.linspace(-8.0, 40.0, 9601)


def _g(u):
    from scipy.special import ndtr

    return u * ndtr(u) + np.exp(-0.5 * u * u) / np.sqrt(2.0 * np.pi)


_G_TABLE = _g(_U_TABLE)


def clipped_gaussian_sd(mean, sigma):
    """Standard deviation of max(s + n, 0), n ~ N(0, σ²), given its mean (same unit).

    s/σ = u is found from mean/σ = g(u) = u Φ(u) + φ(u) (monotonic; tabulated on
    u ∈ [−8, 40], u = mean/σ above), then Var/σ² = (u² + 1) Φ(u) + u φ(u) − g(u)².
    Tends to σ for mean ≫ σ and to σ √(1/2 − 1/(2π)) = 0.584 σ at s = 0.
    """
    from scipy.special import ndtr

    m = np.asarray(mean, float)
    sig = np.broadcast_to(np.asarray(sigma, float), m.shape)
    r = np.where(np.isfinite(m), m / sig, 0.0)
    u = np.where(r > _G_TABLE[-1], r, np.interp(r, _G_TABLE, _U_TABLE))
    g = _g(u)
    var = (u * u + 1.0) * ndtr(u) + u * np.exp(-0.5 * u * u) / np.sqrt(2.0 * np.pi) - g * g
    return sig * np.sqrt(np.clip(var, 1e-12, None))


def _subset_context(ctx, ep):
    """A context restricted to epochs ``ep`` (sorted indices)."""
    from dataclasses import fields, replace

    from ..physics.context import CSSContext

    n = len(ctx)
    changes = {}
    for f in fields(ctx):
        if f.name.startswith("_"):
            continue
        v = getattr(ctx, f.name)
        if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == n and f.name not in ("array",):
            changes[f.name] = v[ep]
    if isinstance(ctx, CSSContext):
        return replace(ctx, **changes)
    attitude_fn = ctx.attitude_fn
    if attitude_fn is not None:
        # row-aligned callables see the rows of the subset only
        changes["attitude_fn"] = _RowSubset(attitude_fn, ep, n)
    return replace(ctx, _cache={}, **changes)


class _RowSubset:
    """Wrap a row-aligned ``attitude_fn(t (N,))`` so it can be called with a subset of rows."""

    def __init__(self, fn, rows, n):
        self.fn, self.rows, self.n = fn, np.asarray(rows), n

    def __call__(self, t_rows):
        if hasattr(self.fn, "rows_call"):
            return self.fn.rows_call(self.rows, t_rows)
        raise ValueError("attitude_fn of a subset context must support rows_call")


# ----------------------------------------------------------------------------------------
# construction
# ----------------------------------------------------------------------------------------
_FREE_WORDS = ("none", "zero_point", "reflection")


def parse_free(text, shape=None) -> list[str]:
    """Validate a ``--free`` value: comma-separated words from ``none``, ``zero_point``,
    ``reflection`` (every BRDF parameter of every facet) or BRDF parameter names
    (``Kd``, ``Ks``, ``n``, ``xi``, ``a``, ``m`` …). Raises InputError naming the field."""
    words = [w.strip() for w in str(text).split(",") if w.strip()]
    allowed = list(_FREE_WORDS) + (sorted(shape.param_table) if shape is not None else [])
    for w in words:
        if w not in _FREE_WORDS and (shape is None or w not in shape.param_table):
            raise InputError("unknown free-parameter name", field="--free", value=w,
                             allowed=", ".join(allowed))
    if "none" in words:
        if len(words) > 1:
            raise InputError("'none' cannot be combined with other names", field="--free", value=text)
        return []
    return words


def _free_params(words, shape, site_names, zero_point_span_mag=3.0):
    """Free baseline parameters for ``words`` (``site_names``: the photometric channels —
    cameras, else sites — of the per-channel zero points)."""
    from ..photometry.brdf import get_brdf  # noqa: F401  (registry import for bounds)

    out = []
    if "zero_point" in words:
        for k, s in enumerate(site_names):
            out.append(FreeParam(f"zero_point[{s}]", "zero_point", s, k, 0.0,
                                 -zero_point_span_mag, zero_point_span_mag, "mag"))
    keys = set()
    if "reflection" in words:
        keys = set(shape.param_table)
    keys |= {w for w in words if w not in _FREE_WORDS}
    for key in sorted(keys, key=lambda k: list(shape.param_table).index(k)):
        vals = shape.param_table[key]
        for i, v in enumerate(vals):
            if np.isnan(v):
                continue
            m = shape.materials[i]
            lo, hi = m.brdf.param_bounds.get(key, (-np.inf, np.inf, False, False))[:2]
            hi = min(hi, _BRDF_CAP.get(key, hi))
            lo = max(lo, 1e-6 if key in ("a", "m") else lo)
            if not np.isfinite(lo) or not np.isfinite(hi):
                raise InputError(f"BRDF parameter {key!r} has no finite range to fit within",
                                 field="--free", value=key)
            x0 = float(min(max(v, lo), hi))
            out.append(FreeParam(f"{key}[{i}:{m.name}]", "brdf", key, i, x0, float(lo), float(hi)))
    return out


def _night_index(t, site_index, site_lla_deg_m, epoch_utc):
    """Local-night index (E,) of each epoch: UTC day of (t + longitude/15 h − 12 h)."""
    from ..geometry.time import parse_epoch

    ep = parse_epoch(epoch_utc)
    sec0 = ep.hour * 3600 + ep.minute * 60 + ep.second + ep.microsecond * 1e-6
    lon = np.asarray(site_lla_deg_m, float)[np.asarray(site_index), 1]
    local = sec0 + np.asarray(t, float) + lon / 15.0 * 3600.0 - 12 * 3600.0
    return np.floor(local / 86400.0).astype(np.int64)


def _shadow_margin(r_obj, r_sun):
    """Distance (m) of the object outside the Earth's (cylindrical) shadow boundary.

    Positive when the object is sunward of the terminator plane or outside the cylinder:
    ``|r⊥| − R⊕`` on the night side, +inf on the day side (a coarse "near-shadow" measure).
    """
    s = r_sun / np.linalg.norm(r_sun, axis=1, keepdims=True)
    along = np.sum(r_obj * s, axis=1)
    perp = np.linalg.norm(r_obj - along[:, None] * s, axis=1)
    return np.where(along > 0, np.inf, perp - 6378137.0)


def magnitude_problem(lc, shape, *, q=None, omega=None, attitude_fn=None, sun_mag=None,
                      ignore_eclipse=None, free=(), label="") -> Problem:
    """A magnitude :class:`Problem` from a :class:`~lightcurve.io.Lightcurve`.

    ``q``/``omega``: the model attitude (N,4)/(N,3) (default: the file's truth);
    ``attitude_fn``: attitude at shifted times (row-aligned, see ModelContext);
    ``free``: words of :func:`parse_free`. Epochs whose baseline magnitude is not finite
    (no lit facet towards the observer) or whose measurement is NaN are left out.
    """
    from ..physics import ModelContext

    ctx = ModelContext.from_lightcurve(lc, shape, q=q, omega=omega, sun_mag=sun_mag,
                                       ignore_eclipse=ignore_eclipse, attitude_fn=attitude_fn)
    obj, obj_names, cam, cam_names = recording_columns(lc)
    if cam is not None:
        ctx = ctx.with_state(camera_index=cam, camera_names=cam_names)
    m0 = ctx.evaluate()
    keep = np.isfinite(m0) & np.isfinite(lc.mag) & np.isfinite(lc.mag_sigma)
    if not np.any(keep):
        raise InputError("no epoch where both the model and the recording have a magnitude",
                         file=lc.attrs.get("file"), field="mag")
    free_words = list(free)
    phase = lc.phase_angle_rad
    n = len(lc)
    channels = cam_names if cam_names is not None else list(lc.site_names)
    prob = Problem("magnitude", ctx, lc.mag, lc.mag_sigma, lc.t, lc.site, np.arange(n),
                   list(lc.site_names), _free_params(free_words, shape, channels),
                   elevation_rad=lc.elevation_rad, phase_rad=phase,
                   shadow_margin=_shadow_margin(lc.r_obj_eci_m, lc.r_sun_eci_m),
                   night=_night_index(lc.t, lc.site, lc.site_lla_deg_m, lc.epoch_utc),
                   exclude=("zero_point",) if "zero_point" in free_words else (),
                   label=label, object=obj, object_names=obj_names, camera=cam,
                   camera_names=cam_names)
    return prob if np.all(keep) else prob.subset(keep)


def recording_columns(lc):
    """``(object (N,) | None, object names, camera (N,) | None, camera names)`` of a lightcurve.

    Read from the optional attributes ``object_index``/``object_names`` and
    ``camera_index``/``camera_names`` of :class:`~lightcurve.io.Lightcurve` (recordings of
    several objects or cameras); None when the recording has no such column or only one.
    """
    out = []
    for idx, names in (("object_index", "object_names"), ("camera_index", "camera_names")):
        i = getattr(lc, idx, None)
        nm = getattr(lc, names, None)
        if i is None or nm is None or len(nm) < 1:
            out += [None, None]
            continue
        i = np.asarray(i, np.int64).reshape(-1)
        if i.size != len(lc) or i.min() < 0 or i.max() >= len(nm):
            raise InputError(f"{idx} must index {names} for every row", field=idx)
        out += [i, [str(x) for x in nm]]
    return tuple(out)


def _union(names_list):
    out = []
    for names in names_list:
        for n in names:
            if n not in out:
                out.append(n)
    return out


def combine_problems(problems, object_names) -> Problem:
    """One magnitude problem of several recordings, one object each (``lightcurve import``
    writes one file per object): rows concatenated, times rebased onto the first recording's
    epoch, sites and cameras merged by name, and ``object`` = the recording's index (named
    ``object_names``), so that objects can be held out (:mod:`.folds`). The recordings must
    share the model (shape, Sun magnitude, eclipse handling) and have no free baseline
    parameters yet (:func:`with_free_words` adds them for the merged channels).
    """
    from dataclasses import replace as _replace

    from ..geometry.time import parse_epoch
    from ..physics import ModelContext

    problems = list(problems)
    if len(problems) == 1:
        return _replace(problems[0], object=np.zeros(len(problems[0].ctx), np.int64),
                        object_names=list(object_names))
    p0 = problems[0]
    for k, p in enumerate(problems):
        if p.kind != "magnitude" or p.free:
            raise ValueError("combine_problems takes magnitude problems without free parameters")
        c, c0 = p.ctx, p0.ctx
        same = (c.shape.n_facets == c0.shape.n_facets
                and np.allclose(c.shape.normals_body, c0.shape.normals_body)
                and np.allclose(c.shape.areas_m2, c0.shape.areas_m2)
                and all(np.allclose(c.shape.param_table[key], c0.shape.param_table[key], equal_nan=True)
                        for key in c0.shape.param_table) and set(c.shape.param_table) == set(c0.shape.param_table))
        if not same:
            raise InputError("the recordings are modelled with different shapes; diagnose them "
                             "separately or give one --scenario/--shape", field="recording",
                             value=object_names[k])
        if c.sun_mag != c0.sun_mag or c.ignore_eclipse != c0.ignore_eclipse:
            raise InputError("the recordings use different Sun magnitudes (bands) or eclipse "
                             "handling", field="recording", value=object_names[k])
        if c.attitude_fn is not None or c.orbit_fn is not None:
            raise ValueError("cannot combine contexts with attitude/orbit callables")
    e0 = parse_epoch(p0.ctx.epoch_utc)
    shifts = [(parse_epoch(p.ctx.epoch_utc) - e0).total_seconds() for p in problems]
    sites = _union([p.site_names for p in problems])
    chans = _union([p.channel_names for p in problems])
    has_cam = any(p.camera is not None for p in problems)

    def cat(get):
        vals = [get(p) for p in problems]
        if any(v is None for v in vals):
            return None
        return np.concatenate([np.asarray(v) for v in vals])

    site_map = [np.array([sites.index(n) for n in p.site_names], np.int64) for p in problems]
    ctx_site = np.concatenate([m[p.ctx.site_index] for m, p in zip(site_map, problems)])
    cam_ctx = None
    if has_cam:
        cam_ctx = np.concatenate([np.array([chans.index(n) for n in p.channel_names], np.int64)
                                  [p.ctx.camera_index_rows] for p in problems])
    omega = cat(lambda p: p.ctx.omega)
    ctx = ModelContext(epoch_utc=p0.ctx.epoch_utc,
                       t=np.concatenate([p.ctx.t + s for p, s in zip(problems, shifts)]),
                       site_index=ctx_site, site_names=sites, shape=p0.ctx.shape,
                       q=cat(lambda p: p.ctx.q), omega=omega,
                       r_obj_eci_m=cat(lambda p: p.ctx.r_obj_eci_m),
                       v_obj_eci_m_s=cat(lambda p: p.ctx.v_obj_eci_m_s),
                       r_site_eci_m=cat(lambda p: p.ctx.r_site_eci_m),
                       r_sun_eci_m=cat(lambda p: p.ctx.r_sun_eci_m),
                       elevation_rad=cat(lambda p: p.ctx.elevation_rad), sun_mag=p0.ctx.sun_mag,
                       ignore_eclipse=p0.ctx.ignore_eclipse,
                       camera_index=cam_ctx, camera_names=chans if has_cam else None)
    offs = np.cumsum([0] + [len(p.ctx) for p in problems[:-1]])
    obj = np.concatenate([np.full(len(p.ctx), k, np.int64) for k, p in enumerate(problems)])
    night = None
    if all(p.night is not None for p in problems):
        night = np.concatenate([np.asarray(p.night) for p in problems])
    return Problem("magnitude", ctx, cat(lambda p: p.y), cat(lambda p: p.sigma),
                   np.concatenate([p.t + s for p, s in zip(problems, shifts)]),
                   np.concatenate([m[p.site] for m, p in zip(site_map, problems)]),
                   np.concatenate([p.epoch_index + o for p, o in zip(problems, offs)]),
                   sites, [], elevation_rad=cat(lambda p: p.elevation_rad),
                   phase_rad=cat(lambda p: p.phase_rad), shadow_margin=cat(lambda p: p.shadow_margin),
                   night=night, label=", ".join(p.label for p in problems), object=obj,
                   object_names=list(object_names),
                   camera=cam_ctx, camera_names=chans if has_cam else None)


def with_free_words(problem, words) -> Problem:
    """``problem`` with the free baseline parameters of ``words`` (:func:`parse_free`) for
    its shape and photometric channels; a free zero point excludes the zero_point effect."""
    free = _free_params(list(words), problem.ctx.shape, problem.channel_names)
    ex = tuple(problem.exclude) + (("zero_point",) if "zero_point" in words else ())
    from dataclasses import replace as _replace

    return _replace(problem, free=free, exclude=ex)


def css_problem(ctx, y, sigma, *, label="", censored_at_zero=False) -> Problem:
    """A CSS :class:`Problem`: ``ctx`` a :class:`~lightcurve.physics.CSSContext` (the model
    without effects), ``y`` (K,S) measured outputs, ``sigma`` scalar or (K,S) noise;
    ``censored_at_zero``: the outputs were recorded as max(signal + noise, 0)."""
    y = np.asarray(y, float)
    K, S = y.shape
    if K != len(ctx) or S != ctx.n_sensors:
        raise ValueError(f"y must have shape ({len(ctx)}, {ctx.n_sensors}), got {y.shape}")
    sig = np.broadcast_to(np.asarray(sigma, float), y.shape)
    ep = np.repeat(np.arange(K), S)
    return Problem("css", ctx, y.ravel(), sig.ravel(), np.asarray(ctx.t)[ep], np.tile(np.arange(S), K),
                   ep, [f"css{k}" for k in range(S)], [], label=label,
                   censored_at_zero=bool(censored_at_zero))
