"""The default scenario is a physically real, lit pass (checked independently of the simulator's
own bookkeeping), and the demo explains it."""

from __future__ import annotations

import numpy as np


def test_default_pass_is_lit_above_the_horizon_at_night(default_pass):
    """Object sunlit at every epoch (conical shadow model), above 10° elevation, Sun more than
    10° below the site's horizon — recomputed here from the file's geometry with the
    package's eclipse and topocentric functions (skyfield/DE421 for the Sun)."""
    from lightcurve.geometry.eclipse import lit_fraction
    from lightcurve.geometry.frames import altaz
    from lightcurve.geometry.sites import get_site
    from lightcurve.geometry.time import sun_position_gcrs

    lc, _ = default_pass
    assert len(lc) >= 40 and lc.site_names == ["socorro"]
    assert int(lc.attrs.get("ignore_eclipse", 0)) == 0
    np.testing.assert_array_equal(lit_fraction(lc.r_obj_eci_m, lc.r_sun_eci_m), 1.0)
    site = get_site("socorro")
    el = np.degrees(altaz(site, lc.r_obj_eci_m, lc.epoch_utc, lc.t)[0])
    assert el.min() > 10.0 and el.max() > 35.0
    sun = sun_position_gcrs(lc.epoch_utc, lc.t)
    sun_el = np.degrees(altaz(site, sun, lc.epoch_utc, lc.t)[0])
    assert sun_el.max() < -10.0            # nautical twilight or darker at every epoch
    np.testing.assert_allclose(lc.r_sun_eci_m, sun, rtol=1e-9)
    # 1U CubeSat at 550-1300 km: magnitudes a telescope measures
    assert 8.0 < np.nanmin(lc.mag) and np.nanmax(lc.mag) < 18.0


def test_demo_default_and_thesis(tmp_path, capsys):
    from lightcurve.cli import main

    assert main(["demo", "-o", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    assert "object sunlit 100 %" in out and "Sun 11 to 12 deg below the horizon" in out
    assert "consistent, inside 3σ" in out and "spin 4.2" in out
    for f in ("cubesat-pass-socorro.h5", "cubesat-pass-socorro.png",
              "cubesat-pass-socorro.ukf.h5", "cubesat-pass-socorro.ukf.png"):
        assert (tmp_path / "d" / f).stat().st_size > 0
    assert main(["demo", "-o", str(tmp_path / "t"), "--scenario", "thesis", "--method",
                 "none"]) == 0
    cap = capsys.readouterr()
    assert "AS IF SUNLIT" in cap.out and "leo-ic1-fast-spin-controlled-1site.h5" in cap.out
    assert main(["demo", "-o", str(tmp_path / "x"), "--scenario", "no-such-case"]) == 2
