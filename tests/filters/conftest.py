"""Fixtures of the filter tests (helpers live in filters_synth.py)."""

from __future__ import annotations

import pytest

from filters_synth import make_curve


@pytest.fixture(scope="session")
def curve():
    """60-epoch synthetic controlled lightcurve (seed 1)."""
    return make_curve()


@pytest.fixture(scope="session")
def default_scenario():
    """The bundled thesis LEO fast-spin scenario (pipelines/thesis/leo-ic1-fast-spin-controlled-1site.toml), loaded once."""
    from lightcurve._paths import data_dir
    from lightcurve.studies.scenario import load_scenario

    return load_scenario(data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml")
