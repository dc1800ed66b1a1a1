"""The background compilation of the suite (tests/_precompile.py) must keep working: a step that
raises is skipped silently there (it only fills numba's cache), so an API change that breaks one
would only show as a slower suite. Here every step must run without error."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _precompile  # noqa: E402


@pytest.mark.parametrize("step", _precompile.STEPS, ids=lambda s: s.__name__)
def test_precompile_step_runs(step):
    step()
