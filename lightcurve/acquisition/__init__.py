"""Attitude acquisition without a starting guess.

- :mod:`.period` — spin-period analysis of a lightcurve (multi-harmonic least-squares
  periodogram with a trend, Lomb–Scargle, phase-dispersion minimisation, the synodic–sidereal
  correction, aliases and an uncertainty); it seeds the rate prior.
- :mod:`.global_init` — global initialisation: attitude uniform over SO(3), rate from the
  period analysis, a tempered sequential Monte Carlo sampler over the initial state, the
  posterior modes, then the user's filter from every mode.
"""

from .period import PeriodResult, analyse_period

__all__ = ["PeriodResult", "analyse_period"]
