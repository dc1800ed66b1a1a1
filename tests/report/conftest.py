import warnings

import pytest


@pytest.fixture(scope="session")
def default_pass():
    """The bundled default scenario (lit pass over Socorro) simulated once, and its UKF estimate."""
    import lightcurve
    from lightcurve._paths import data_dir

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a lit pass: no eclipse warning may appear
        lc = lightcurve.simulate(data_dir("pipelines") / "default.toml")
    est = lightcurve.invert(lc, "ukf", seed=1)
    return lc, est
