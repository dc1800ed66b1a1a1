"""lightcurve: attitude and reflection-parameter estimation from photometry.

Conventions (see DESIGN.md): SI units inside; quaternions scalar first, inertial→body
passive (``v_b = A(q) v_I``); ECI is skyfield's GCRS; time ``t`` in seconds since a scenario
epoch (UTC).

Top-level API (imported lazily so that ``import lightcurve`` stays fast):

- :func:`simulate` — scenario (object or TOML path) → :class:`Lightcurve`
- :func:`read_lightcurve` — HDF5 file → :class:`Lightcurve`; :meth:`Lightcurve.write`
- :func:`load_scenario` — validated scenario from TOML
- :func:`invert` — Lightcurve → :class:`~lightcurve.filters.Estimate` (MEKF, UKF, particle filter)
"""

from .errors import ConvergenceError, InputError
from .numba_cache import install_when_imported
from .threads import configure_threading

configure_threading()
install_when_imported()   # numba's cache keyed by the whole package (numba_cache.py)

__version__ = "0.1.0"

__all__ = ["InputError", "ConvergenceError", "__version__", "simulate", "read_lightcurve",
           "Lightcurve", "load_scenario", "invert"]


def __getattr__(name):
    if name == "simulate":   # the one simulate: lightcurve.studies.simulate.simulate (a
        # Scenario, a TOML path or a bundled scenario name: "default", "thesis", "thesis/<case>")
        from .studies.simulate import simulate

        return simulate
    if name in ("read_lightcurve", "Lightcurve"):
        from .io import lightcurve_h5

        return getattr(lightcurve_h5, name)
    if name == "invert":
        from .filters.invert import invert

        return invert
    if name == "load_scenario":
        from .studies.scenario import load_scenario

        return load_scenario
    raise AttributeError(f"module 'lightcurve' has no attribute {name!r}")
