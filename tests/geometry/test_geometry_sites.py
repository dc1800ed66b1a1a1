"""Site catalog, loading errors, and GCRS site positions (skyfield oracle, 1e-6 relative)."""

import numpy as np
import pytest

from lightcurve.cli import main
from lightcurve.errors import InputError
from lightcurve.geometry import sites as gs
from lightcurve.geometry.frames import itrs_rotation
from lightcurve.geometry.time import skyfield_times
from lightcurve.io.tomlio import Section

EPOCH = "2020-03-01T08:08:40Z"


def test_bundled_catalog_values():
    s = gs.load_sites()
    # Bernard (2021) tables 9.3-9.4; Mount Lemmon: Fankhauser et al. (2023)
    expect = {"socorro": (33.8173, -106.66, 1500.0), "bear_lake": (41.93, -111.4, 1815.0),
              "maui": (20.7081, -156.257, 3059.0), "mount_lemmon": (32.4434, -110.7881, 2791.0)}
    for sid, (lat, lon, h) in expect.items():
        assert (s[sid].lat_deg, s[sid].lon_deg, s[sid].height_m) == (lat, lon, h)


def test_site_position_matches_skyfield_and_shared_rotation():
    from skyfield.api import wgs84

    t_s = np.linspace(0.0, 86400.0, 9)
    t = skyfield_times(EPOCH, t_s)
    R = itrs_rotation(t)
    for sid in ("socorro", "bear_lake", "maui", "mount_lemmon"):
        site = gs.get_site(sid)
        ref = wgs84.latlon(site.lat_deg, site.lon_deg, elevation_m=site.height_m).at(t)
        mine = gs.site_position_gcrs(site, EPOCH, t_s)
        rel = np.linalg.norm(mine - ref.position.m.T, axis=1) / np.linalg.norm(mine, axis=1)
        assert rel.max() < 1e-6
        # our own WGS84 geodetic->ECEF formula rotated with R^T (what compute_geometry uses)
        own = np.einsum("nji,j->ni", R, gs.site_itrs_m(site))
        assert np.max(np.linalg.norm(own - ref.position.m.T, axis=1)) < 1e-3  # metres
        # ECEF formula against skyfield's own geodetic conversion
        np.testing.assert_allclose(gs.site_itrs_m(site),
                                   wgs84.latlon(site.lat_deg, site.lon_deg,
                                                elevation_m=site.height_m).itrs_xyz.m, atol=1e-6)
        # a ground site moves at omega*R*cos(lat) ≈ 465 m/s * cos(lat) in GCRS
        _, v = gs.site_position_velocity_gcrs(site, EPOCH, t_s)
        speed = np.linalg.norm(v, axis=1)
        assert np.allclose(speed, 7.2921e-5 * np.hypot(*gs.site_itrs_m(site)[:2]), rtol=1e-3)


def test_unknown_site_lists_known_ids():
    with pytest.raises(InputError) as ei:
        gs.get_site("nowhere")
    msg = str(ei.value)
    for sid in ("socorro", "bear_lake", "maui", "mount_lemmon"):
        assert sid in msg


def test_inline_site_and_section():
    s = gs.get_site({"lat_deg": 10.0, "lon_deg": 20.0, "height_m": 5.0})
    assert (s.id, s.lat_deg, s.height_m) == ("inline", 10.0, 5.0)
    s2 = gs.get_site(Section({"id": "x1", "lat_deg": 1.0, "lon_deg": 2.0, "height_m": 3.0},
                             name="sites[0]"))
    assert s2.id == "x1"
    with pytest.raises(InputError, match="lat_deg"):
        gs.get_site({"lat_deg": 95.0, "lon_deg": 0.0, "height_m": 0.0})
    with pytest.raises(InputError, match="unknown key"):
        gs.get_site({"lat_deg": 5.0, "lon_deg": 0.0, "height_m": 0.0, "heigth": 1})


def test_user_folder_overrides_and_errors(tmp_path):
    d = tmp_path / "mysites"
    d.mkdir()
    (d / "socorro.toml").write_text('id = "socorro"\nname = "moved"\nlat_deg = 34.0\n'
                                    'lon_deg = -106.0\nheight_m = 10.0\n')
    (d / "home.toml").write_text('name = "Home"\nlat_deg = 50.0\nlon_deg = 8.0\nheight_m = 100.0\n'
                                 '[horizon_mask]\naz_deg = [0, 90, 180, 270]\n'
                                 'alt_deg = [10, 20, 10, 0]\n')
    s = gs.load_sites([d])
    assert s["socorro"].name == "moved" and s["home"].id == "home"  # id defaults to file stem
    assert "maui" in s
    home = s["home"]
    # linear interpolation with wrap-around through north: az 315 → between 0 (270) and 10 (360)
    np.testing.assert_allclose(np.degrees(home.horizon_rad(np.radians([45, 315, 90]))),
                               [15.0, 5.0, 20.0])
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "b.toml").write_text('lat_deg = 30.0\nlon_deg = 0.0\nheight_m = 20000.0\n')
    with pytest.raises(InputError) as ei:
        gs.load_sites([bad])
    assert "b.toml" in str(ei.value) and "height_m" in str(ei.value)
    with pytest.raises(InputError, match="not found"):
        gs.load_sites([tmp_path / "missing"])


def test_cli_sites(capsys, tmp_path):
    assert main(["sites", "list"]) == 0
    out = capsys.readouterr().out
    assert "socorro" in out and "bear_lake" in out and "33.8173" in out
    assert main(["sites", "show", "mount_lemmon"]) == 0
    assert "2791.0 m" in capsys.readouterr().out
    assert main(["sites", "show", "atlantis"]) == 2
    assert "socorro" in capsys.readouterr().err
    (tmp_path / "z.toml").write_text('id = "zz"\nlat_deg = 1\nlon_deg = 2\nheight_m = 3\n')
    assert main(["sites", "list", "--sites", str(tmp_path)]) == 0
    assert "zz" in capsys.readouterr().out
