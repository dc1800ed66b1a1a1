"""Measurements in the simulator: epochs below the horizon, in site daylight, in the
Earth's shadow or without reflected light are dropped and counted; nothing non-finite reaches
the lightcurve; every scheduled epoch is accounted for exactly once.
"""

from __future__ import annotations

import tomllib
import warnings

import numpy as np
import pytest

from hardening_util import dumps_toml
from lightcurve import InputError
from lightcurve._paths import data_dir
from lightcurve.io.lightcurve_h5 import Lightcurve
from lightcurve.studies.scenario import parse_scenario
from lightcurve.studies.simulate import simulate

DEFAULT = tomllib.loads((data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml").read_text())


def _scenario(**measurement):
    doc = {**DEFAULT, "scenario": {**DEFAULT["scenario"], "duration_s": 3 * 3600.0, "cadence_s": 60.0},
           "measurement": {**DEFAULT["measurement"], **measurement},
           "sites": [{"name": "socorro", "windows_s": [[0.0, 3 * 3600.0]]}]}
    return parse_scenario(dumps_toml(doc), file="acct.toml")


@pytest.mark.parametrize("measurement", [
    {"ignore_eclipse": False, "require_dark_site": True},
    {"ignore_eclipse": False, "require_dark_site": False, "min_elevation_deg": 20.0},
    {"ignore_eclipse": True, "require_dark_site": False},
])
def test_every_scheduled_epoch_counted_once(measurement):
    scen = _scenario(**measurement)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            lc, c = simulate(scen, return_counts=True)
        except InputError as exc:  # nothing visible at all is an error naming the file
            assert "acct.toml" in str(exc) and "no visible measurement" in str(exc)
            return
    # 3 h at 60 s, inclusive ends: 181 epochs (schedules.cadence_grid)
    assert c.scheduled == 181
    assert c.below_horizon + c.site_daylight + c.eclipsed + c.kept == c.scheduled
    assert len(lc) + lc.attrs["dropped_no_reflection"] == c.kept
    assert lc.attrs["dropped_below_horizon"] == c.below_horizon
    assert lc.attrs["dropped_eclipsed"] == c.eclipsed
    assert np.all(np.isfinite(lc.mag)) and np.all(np.isfinite(lc.truth_mag))
    assert np.all(lc.elevation_rad >= np.radians(measurement.get("min_elevation_deg", 0.0)) - 1e-12)
    if not measurement["ignore_eclipse"]:
        assert np.all(lc.lit_fraction > 0)


def test_in_memory_lightcurve_rejects_inf_and_duplicates():
    from hardening_util import small_curve

    lc = small_curve()
    kw = {f: getattr(lc, f) for f in lc.__dataclass_fields__}
    with pytest.raises(InputError, match="infinite magnitude"):
        Lightcurve(**{**kw, "mag": np.where(np.arange(8) == 3, np.inf, lc.mag)})
    t = lc.t.copy()
    t[3] = t[2]
    site = lc.site.copy()
    site[3] = site[2]
    with pytest.raises(InputError, match="duplicated measurement"):
        Lightcurve(**{**kw, "t": t, "site": site})
