"""lightcurve: attitude and reflection-parameter estimation from photometry.

Conventions (see DESIGN.md): SI units inside; quaternions scalar first, inertial→body
passive (``v_b = A(q) v_I``); ECI is skyfield's GCRS; time ``t`` in seconds since a scenario
epoch (UTC).
"""

from .errors import InputError, ConvergenceError

__version__ = "0.1.0"

__all__ = ["InputError", "ConvergenceError", "__version__"]
