"""The number of generated fuzz cases per loader, printed so that a run can report it.

Runs last in tests/hardening (file name order). When the fuzz tests ran in this pytest session,
every loader must have received at least ``MIN_CASES`` generated inputs; the table is printed
(``pytest -s`` shows it). Run alone, the test skips.
"""

from __future__ import annotations

import pytest

from hardening_util import CASES

MIN_CASES = 40
LOADERS = ("load_toml", "Section getters", "site TOML (load_sites)", "inline site (get_site)",
           "shape TOML (load_shape)", "mesh shape TOML (load_shape)", "OBJ mesh (load_shape)",
           "STL mesh (load_shape)", "BRDF table (TabulatedBRDF.from_csv)",
           "scenario TOML (load_scenario)", "CSV recording (read_recording)", "[recording] table",
           "lightcurve HDF5 (read_lightcurve)", "CSS HDF5 recording (css read_recording)",
           "albedo map (load_albedo_map)", "CSS configuration TOML", "CSS study TOML (load_study)")


def test_case_counts_per_loader():
    if not CASES:
        pytest.skip("run together with the fuzz tests (pytest tests/hardening) to count cases")
    print("\ngenerated fuzz cases per loader:")
    for name in sorted(CASES):
        print(f"  {name:45s} {CASES[name]:6d}")
    print(f"  {'total':45s} {sum(CASES.values()):6d}")
    ran = [n for n in LOADERS if n in CASES]
    low = {n: CASES[n] for n in ran if CASES[n] < MIN_CASES}
    assert not low, f"loaders with fewer than {MIN_CASES} generated cases: {low}"
