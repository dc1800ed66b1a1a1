"""Random-generator handling shared by every stochastic routine of the estimation core.

Every stochastic function of :mod:`lightcurve.estimation` takes ``rng`` that is either a
:class:`numpy.random.Generator` or an integer seed. A given seed always produces the same
numbers, bit for bit (DESIGN.md, "Randomness").
"""

from __future__ import annotations

import numbers

import numpy as np

__all__ = ["as_generator"]


def as_generator(rng) -> np.random.Generator:
    """Return a :class:`numpy.random.Generator` for ``rng``.

    Parameters
    ----------
    rng : numpy.random.Generator or int or numpy.random.SeedSequence
        A generator is returned unchanged (so the caller's stream advances); an integer seed
        (>= 0) or a ``SeedSequence`` builds a fresh ``PCG64`` generator.

    Raises
    ------
    ValueError
        For ``None`` (implicit OS entropy would break reproducibility), negative seeds, or
        any other type.
    """
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, np.random.SeedSequence):
        return np.random.default_rng(rng)
    if isinstance(rng, numbers.Integral) and not isinstance(rng, bool):
        if int(rng) < 0:
            raise ValueError(f"seed must be a non-negative integer, got {rng}")
        return np.random.default_rng(int(rng))
    raise ValueError(
        "rng must be a numpy.random.Generator, a SeedSequence or a non-negative integer seed "
        f"(got {type(rng).__name__}); None is refused because results must be reproducible"
    )
