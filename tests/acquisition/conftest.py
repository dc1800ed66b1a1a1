from __future__ import annotations

import pytest

from lightcurve._paths import data_dir


@pytest.fixture(scope="session")
def thesis_fast_spin():
    """Bernard (2021) §9.3.3 LEO fast-spin case, controlled, one site (scenario path)."""
    return str(data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml")
