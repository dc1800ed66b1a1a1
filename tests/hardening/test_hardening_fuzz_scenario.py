"""Fuzz: scenario TOML files (load_scenario / parse_scenario) and the simulator's input checks.

Property: any damaged or hostile scenario gives an InputError naming the scenario
file (or a valid Scenario); simulate() on a loaded scenario raises only InputError.
"""

from __future__ import annotations

import tomllib
import warnings
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardening_util import (damaged_bytes, dumps_toml, fuzz_settings, mutated_docs, new_tmp_dir,
                            only_input_error)
from lightcurve import InputError
from lightcurve._paths import data_dir
from lightcurve.studies.scenario import load_scenario, parse_scenario

PIPE = data_dir("pipelines")
DEFAULT = tomllib.loads((PIPE / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml").read_text())
BUNDLED_DEFAULT = tomllib.loads((PIPE / "default.toml").read_text())  # TLE orbit, lit pass
UNCONTROLLED = tomllib.loads((PIPE / "thesis" / "leo-ic2-nadir-uncontrolled-2site.toml").read_text())
STARLINK = tomllib.loads((PIPE / "real" / "starlink_pomenis.toml").read_text())


def _write(text: str | bytes, name="scen.toml") -> Path:
    p = new_tmp_dir() / name
    p.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return p


@fuzz_settings(120)
@given(st.one_of(mutated_docs(DEFAULT), mutated_docs(BUNDLED_DEFAULT), mutated_docs(UNCONTROLLED),
                 mutated_docs(STARLINK)))
def test_scenario_mutated(doc):
    p = _write(dumps_toml(doc))
    only_input_error("scenario TOML (load_scenario)", load_scenario, p, file=p)


@fuzz_settings(60)
@given(damaged_bytes((PIPE / "default.toml").read_bytes()))
def test_scenario_damaged_bytes(data):
    p = _write(data)
    only_input_error("scenario TOML (load_scenario)", load_scenario, p, file=p)


@fuzz_settings(40)
@given(st.sampled_from(["lat_deg", "lon_deg", "height_m"]),
       st.sampled_from([1e9, -1e9, float("nan"), "x", True, [1.0]]))
def test_inline_site_errors_name_the_scenario(key, value):
    doc = dict(DEFAULT)
    doc["sites"] = [{"lat_deg": 10.0, "lon_deg": 20.0, "height_m": 0.0, key: value}]
    p = _write(dumps_toml(doc))
    out = only_input_error("scenario TOML (load_scenario)", load_scenario, p, file=p)
    assert isinstance(out, InputError)
    assert f"sites[0].{key}" in str(out)


def test_unknown_catalog_site_names_scenario_and_field():
    doc = dict(DEFAULT)
    doc["sites"] = [{"name": "atlantis"}]
    p = _write(dumps_toml(doc))
    with pytest.raises(InputError) as exc:
        load_scenario(p)
    msg = str(exc.value)
    assert str(p) in msg and "sites[0].name" in msg and "atlantis" in msg and "socorro" in msg


def test_bad_epoch_names_scenario_file():
    doc = {**DEFAULT, "scenario": {**DEFAULT["scenario"], "epoch_utc": "2020-02-30T00:00:00Z"}}
    p = _write(dumps_toml(doc))
    with pytest.raises(InputError) as exc:
        load_scenario(p)
    assert str(p) in str(exc.value) and "scenario.epoch_utc" in str(exc.value)


@pytest.mark.parametrize("epoch, duration, ok", [
    # DE421 covers 1899-07-29 .. 2053-10-09 (JPL IOM 343R-08-003); the package uses the
    # conservative 1899-07-30 .. 2053-10-08
    ("2053-10-07T23:00:00Z", 3600.0, True),
    ("2053-10-07T23:00:00Z", 2 * 86400.0, False),   # the scenario runs off the ephemeris
    ("1899-07-29T00:00:00Z", 60.0, False),          # starts before it
])
def test_scenario_span_checked_against_the_ephemeris(epoch, duration, ok):
    doc = {**DEFAULT, "scenario": {**DEFAULT["scenario"], "epoch_utc": epoch, "duration_s": duration,
                                  "cadence_s": 60.0},
           "sites": [{"name": "socorro", "windows_s": [[0.0, duration]]}]}
    p = _write(dumps_toml(doc))
    if ok:
        load_scenario(p)
    else:
        with pytest.raises(InputError) as exc:
            load_scenario(p)
        assert str(p) in str(exc.value) and "DE421" in str(exc.value)


def test_too_many_epochs_refused_at_load():
    """30 days at 1 ms cadence would be 2.6e9 epochs: refused when loading, not when allocating."""
    doc = {**DEFAULT, "scenario": {**DEFAULT["scenario"], "duration_s": 30 * 86400.0,
                                  "cadence_s": 1e-3}}
    p = _write(dumps_toml(doc))
    with pytest.raises(InputError) as exc:
        load_scenario(p)
    assert str(p) in str(exc.value) and "cadence_s" in str(exc.value)


@fuzz_settings(12)
@given(st.sampled_from([("scenario", "duration_s", 5.0), ("scenario", "cadence_s", 360.0),
                        ("measurement", "min_elevation_deg", 89.0),
                        ("measurement", "ignore_eclipse", False),
                        ("measurement", "r_percent", 0.0), ("measurement", "r_percent", 100.0),
                        ("attitude", "omega_deg_s", [3600.0, -3600.0, 0.0]),
                        ("measurement", "require_dark_site", False)]))
def test_simulate_only_input_error(change):
    """Valid-but-extreme scenarios: simulate() succeeds or raises InputError naming the file."""
    from lightcurve.studies.simulate import simulate

    sec, key, value = change
    doc = {**DEFAULT, sec: {**DEFAULT.get(sec, {}), key: value}}
    p = _write(dumps_toml(doc))
    scen = only_input_error("scenario TOML (load_scenario)", lambda: parse_scenario(doc, file=p),
                            file=p)
    if isinstance(scen, InputError):  # e.g. r_percent = 0: sigma must stay > 0 (format rule)
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = only_input_error("simulate (scenario)", simulate, scen, file=p)
    if not isinstance(out, InputError):
        import numpy as np

        assert np.all(np.isfinite(out.mag)) and np.all(np.isfinite(out.t))
