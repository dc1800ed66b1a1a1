"""Concealed Earthshine and self-shadowing (issue 10), one seed each (the 10-seed matrix is
benchmarks/diagnosis_confusion.py). Scenarios and why they show the effect: diag_synth.py.

(The numba kernels run single-threaded in these tests: tests/diagnosis/conftest.py.)
"""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))


@pytest.mark.parametrize("effect", ["earthshine", "self_shadowing"])
def test_concealed_effect_ranks_first_and_fit_recovers(effect):
    """Seed 0: the concealed effect ranks first, is chosen first, and the final chi2/dof is
    below 1.5 (issue 10 asks >= 9/10 seeds; a failure of seed 0 is a regression)."""
    from diag_synth import run_case

    r = run_case(effect, 0)
    assert r["verdict"] == "mismatch", r
    assert r["top"] == effect, r
    assert r["chosen"][0] == effect, r
    assert r["final_chi2_dof"] < 1.5, r
    if effect == "earthshine":
        # the albedo scale is recovered: |fit − truth| < 4 sd + 0.02 (the model's 10° grid
        # differs from the truth's 5° grid by < 0.005 mag here)
        fit = r["json"]["chosen_params"]["earthshine"]["albedo_scale"]
        assert abs(fit["value"] - r["truth"]["albedo_scale"]) < 4 * fit["sd"] + 0.02, (fit, r["truth"])
