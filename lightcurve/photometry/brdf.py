"""BRDF registry: the base class, the ``@register_brdf`` decorator and entry-point discovery.

A BRDF (bidirectional reflectance distribution function, unit sr⁻¹) maps a facet's unit
normal ``n``, the unit direction to the light source ``s`` (object→Sun) and the unit direction
to the observer ``o`` (object→observer) — all three in the same frame, usually body axes — to
the reflected radiance per unit incident irradiance.

Two kinds of BRDF live in one registry:

* built-in analytic models (Lambert, Cook–Torrance, Phong, Ashikhmin–Shirley) that also have a
  numba kernel id (:attr:`BRDF.kernel_id`), so the hot loop in
  :func:`lightcurve.core.photometry.brightness_kernel` evaluates them without Python;
* user models (a class or a plain function) evaluated vectorised in numpy by the object layer.

Users add a model in one of two ways (see ``docs/extending.md``)::

    from lightcurve.photometry import register_brdf

    @register_brdf("minnaert")
    def minnaert(n, s, o, *, albedo=0.5, k=0.8):
        ns = (n * s).sum(-1); no = (n * o).sum(-1)
        return albedo / np.pi * (ns * no) ** (k - 1.0)

or, from another installed package, an entry point in the group ``lightcurve.brdfs``::

    [project.entry-points."lightcurve.brdfs"]
    minnaert = "mypkg.brdfs:minnaert"

Entry points are loaded lazily the first time a name is looked up that is not registered yet.
"""

from __future__ import annotations

import inspect
import math
import threading
import warnings
from importlib import metadata

import numpy as np

from ..core.photometry import PARAM_COLUMNS  # width of the packed per-facet parameter rows
from ..errors import InputError

__all__ = [
    "BRDF",
    "FunctionBRDF",
    "register_brdf",
    "unregister_brdf",
    "get_brdf",
    "available_brdfs",
    "ENTRY_POINT_GROUP",
    "PARAM_COLUMNS",
]

#: Entry-point group scanned for third-party BRDFs.
ENTRY_POINT_GROUP = "lightcurve.brdfs"


_REGISTRY: dict[str, "BRDF"] = {}
_LOCK = threading.Lock()
_ENTRY_POINTS_LOADED = False


class BRDF:
    """Base class of a reflectance model.

    Subclasses set the class attributes and implement :meth:`evaluate`.

    Attributes
    ----------
    name : str
        Registry name (set by :func:`register_brdf`).
    param_names : tuple of str
        Material parameters in packing order (default for a subclass: the keys of its
        ``param_bounds``, in order).
    param_bounds : dict
        ``name -> (lo, hi, lo_open, hi_open)``; ``None`` for an unbounded side.
    defaults : dict
        Default values of the parameters (a parameter without a default is required).
    kernel_id : int or None
        Model id understood by the numba kernels, or None (numpy evaluation only).
    """

    name: str = ""
    param_names: tuple = ()
    param_bounds: dict = {}
    defaults: dict = {}
    kernel_id: int | None = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "param_bounds" in vars(cls) and "param_names" not in vars(cls):
            cls.param_names = tuple(cls.param_bounds)

    # -- evaluation ------------------------------------------------------------------------
    def evaluate(self, n, s, o, params: dict):
        """BRDF value f_r in sr⁻¹.

        Parameters
        ----------
        n, s, o : array_like (..., 3)
            Unit facet normal, unit direction to the Sun and unit direction to the observer,
            all in the same frame. Arrays broadcast against each other.
        params : dict
            Parameter name -> scalar or array broadcastable to the leading shape.

        Returns
        -------
        ndarray (...)
            f_r in sr⁻¹, defined for ``n·s > 0`` and ``n·o > 0`` (callers multiply by
            ``max(n·s, 0) max(n·o, 0)``, so the value elsewhere is irrelevant but finite).
        """
        raise NotImplementedError(f"BRDF {self.name!r} does not implement evaluate()")

    # -- parameters ------------------------------------------------------------------------
    def resolve_params(self, given: dict, *, file=None, field=None, problems=None) -> dict:
        """Fill defaults, reject unknown/missing keys and values outside ``param_bounds``.

        Raises :class:`InputError` naming ``file`` and ``field`` (e.g. ``materials.panel``).
        With a list ``problems``, out-of-range values are appended to it (one
        :class:`InputError` per parameter) and kept, instead of raising.
        """
        out = {}
        unknown = [k for k in given if k not in self.param_names]
        if unknown:
            raise InputError(
                f"unknown parameter(s) {', '.join(map(repr, unknown))} for BRDF '{self.name}'",
                file=file, field=field, allowed=", ".join(self.param_names) or "no parameters")
        for p in self.param_names:
            fld = f"{field}.{p}" if field else p
            if p in given:
                v = given[p]
            elif p in self.defaults:
                v = self.defaults[p]
            else:
                raise InputError(f"missing parameter of BRDF '{self.name}'", file=file, field=fld)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
                raise InputError("expected a number", file=file, field=fld, value=v)
            v = float(v)
            if not math.isfinite(v):
                raise InputError("expected a finite number", file=file, field=fld, value=v)
            lo, hi, lo_open, hi_open = self.param_bounds.get(p, (None, None, False, False))
            bad = (lo is not None and (v < lo or (lo_open and v == lo))) or (
                hi is not None and (v > hi or (hi_open and v == hi)))
            if bad:
                allowed = (f"{'(' if lo_open else '['}{'-inf' if lo is None else lo}, "
                           f"{'inf' if hi is None else hi}{')' if hi_open else ']'}")
                exc = InputError("value out of range", file=file, field=fld, value=v,
                                 allowed=allowed)
                if problems is None:
                    raise exc
                problems.append(exc)
            out[p] = v
        return out

    def pack(self, params: dict) -> np.ndarray:
        """Parameters in ``param_names`` order, zero-padded to :data:`PARAM_COLUMNS`."""
        row = np.zeros(PARAM_COLUMNS)
        vals = [params[p] for p in self.param_names]
        if len(vals) > PARAM_COLUMNS:
            raise ValueError(f"BRDF {self.name!r} has more than {PARAM_COLUMNS} parameters")
        row[: len(vals)] = vals
        return row

    def __repr__(self):
        return f"<BRDF {self.name!r} params={self.param_names}>"


class FunctionBRDF(BRDF):
    """A BRDF made from a plain function ``f(n, s, o, *, p1=d1, p2=d2, ...) -> f_r``.

    The keyword-only arguments are the material parameters; their defaults are the
    defaults (a keyword-only argument without default is a required parameter). Optional
    ``bounds={"p1": (lo, hi)}`` closed ranges are checked on load.
    """

    def __init__(self, func, name: str, bounds: dict | None = None):
        sig = inspect.signature(func)
        pos = [p for p in sig.parameters.values()
               if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
        if len(pos) != 3:
            raise ValueError(f"BRDF function {func.__name__} must take (n, s, o, *, params...)")
        kw = [p for p in sig.parameters.values() if p.kind == p.KEYWORD_ONLY]
        self.func = func
        self.name = name
        self.param_names = tuple(p.name for p in kw)
        self.defaults = {p.name: p.default for p in kw if p.default is not p.empty}
        self.param_bounds = {k: (lo, hi, False, False) for k, (lo, hi) in (bounds or {}).items()}
        self.kernel_id = None
        self.__doc__ = func.__doc__

    def evaluate(self, n, s, o, params: dict):
        return np.asarray(self.func(n, s, o, **params), dtype=float)


def _load_entry_points() -> None:
    global _ENTRY_POINTS_LOADED
    if _ENTRY_POINTS_LOADED:
        return
    _ENTRY_POINTS_LOADED = True
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name not in _REGISTRY:
            _load_ep(ep, stacklevel=2)


def _load_entry_point(name: str) -> None:
    """Load only the plug-in registered under ``name`` (a name read from a data file must not
    import every installed plug-in)."""
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name != name:
            continue  # never imported
        if ep.name not in _REGISTRY:
            _load_ep(ep, stacklevel=3)
        return


def _load_ep(ep, stacklevel: int) -> None:
    """Import entry point ``ep`` and register its BRDF; a plug-in that fails to load is a
    warning (``stacklevel`` as seen from the caller), never an error."""
    try:
        obj = ep.load()
    except Exception as exc:  # a broken plug-in must not break the built-ins
        warnings.warn(f"BRDF entry point {ep.name!r} ({ep.value}) failed to load: {exc}",
                      RuntimeWarning, stacklevel=stacklevel + 1)
        return
    if ep.name not in _REGISTRY:  # the module may have registered itself on import
        _register(ep.name, obj, replace=False)


def _entry_point_names() -> list:
    """Names of the installed BRDF plug-ins (nothing is imported)."""
    from importlib.metadata import entry_points

    return [ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)]


def _register(name, obj, replace, bounds=None) -> BRDF:
    if isinstance(obj, BRDF):
        inst = obj
    elif inspect.isclass(obj) and issubclass(obj, BRDF):
        inst = obj()
    elif callable(obj):
        inst = FunctionBRDF(obj, name, bounds)
    else:
        raise TypeError(f"cannot register {obj!r} as a BRDF: need a BRDF subclass, instance "
                        "or a function f(n, s, o, *, params)")
    inst.name = name
    with _LOCK:
        if name in _REGISTRY and not replace and _REGISTRY[name] is not inst:
            raise ValueError(f"BRDF {name!r} is already registered (pass replace=True)")
        _REGISTRY[name] = inst
    return inst


def register_brdf(name: str, *, replace: bool = False, bounds: dict | None = None):
    """Decorator registering a BRDF class, instance or function under ``name``.

    The decorated object is returned unchanged (classes stay classes), so it can still be
    used directly. ``bounds`` (functions only): ``{"param": (lo, hi)}`` closed ranges.
    Registering an existing name raises ``ValueError`` unless ``replace=True``.
    """
    if not isinstance(name, str) or not name:
        raise ValueError("BRDF name must be a non-empty string")

    def deco(obj):
        _register(name, obj, replace, bounds)
        return obj

    return deco


def unregister_brdf(name: str) -> None:
    """Remove ``name`` from the registry (no error if absent). Meant for tests."""
    with _LOCK:
        _REGISTRY.pop(name, None)


def get_brdf(name: str, *, file=None, field=None) -> BRDF:
    """The registered BRDF called ``name``; :class:`InputError` naming file/field if unknown.

    The built-ins are registered when :mod:`lightcurve.photometry` is imported (its
    ``brdf_models``), which Python does before any of its modules."""
    if name not in _REGISTRY and isinstance(name, str):
        _load_entry_point(name)
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise InputError("unknown BRDF (a user BRDF must be registered first: on the command "
                         "line load its module with --plugin MODULE_OR_FILE.py, or install a "
                         "package with a 'lightcurve.brdfs' entry point; docs/extending.md)",
                         file=file, field=field, value=name,
                         allowed=", ".join(sorted(set(_REGISTRY) | set(_entry_point_names()))))\
            from None


def available_brdfs() -> list[str]:
    """Sorted names of all registered BRDFs (built-ins, user registrations, entry points).

    Measured tables are not registry names: a material uses one with ``brdf = "tabulated"``
    and ``table = "file.csv"``, or code passes a :class:`~.tabulated.TabulatedBRDF` instance.
    """
    _load_entry_points()
    return sorted(_REGISTRY)
