"""reprs, HTML views, pandas/xarray tables and derived quantities of Lightcurve and Estimate.

Oracles: scipy's Rotation for the Euler angles and the inertial spin axis; Monte Carlo draws
from the filter covariance for the first-order 1σ of the Euler angles and of the spin axis;
the simulator's noise-free magnitudes for the fitted lightcurve at the true attitude.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lightcurve import rotations as rot


def test_short_reprs_and_html(default_pass):
    lc, est = default_pass
    for obj, head in ((lc, "<Lightcurve 51 magnitudes"), (est, "<Estimate UKF, 51 epochs")):
        r = repr(obj)
        assert r.startswith(head) and "\n" not in r and len(r) < 250
        h = obj._repr_html_()
        assert h.startswith("<table>") and "</table>" in h and len(h) < 4000
    assert "2008-09-21 01:55:00" in repr(lc) and "inside 3σ" in repr(est)


def test_lightcurve_to_pandas_and_xarray(default_pass):
    lc, _ = default_pass
    df = lc.to_pandas()
    assert len(df) == len(lc) and str(df.index.tz) == "UTC"
    assert str(df.index[0]) == "2008-09-21 01:55:00+00:00"
    np.testing.assert_array_equal(df["mag"].to_numpy(), lc.mag)
    np.testing.assert_allclose(df["elevation_deg"], np.degrees(lc.elevation_rad))
    np.testing.assert_allclose((df.index - df.index[0]).total_seconds(), lc.t - lc.t[0])
    ds = lc.to_xarray()
    assert ds.sizes["time"] == len(lc) and ds.attrs["epoch_utc"] == lc.epoch_utc


def test_estimate_euler_angles_against_scipy_and_monte_carlo(default_pass):
    from lightcurve.filters.derived import euler321_with_sigma

    _, est = default_pass
    df = est.to_pandas()
    # A = R1(psi) R2(theta) R3(phi) (passive) = (Rz(phi) Ry(theta) Rx(psi))^T (active, scipy)
    ref = Rotation.from_matrix(np.swapaxes(rot.quat_to_dcm(est.q), 1, 2)).as_euler("ZYX",
                                                                                     degrees=True)
    np.testing.assert_allclose(df[["phi_deg", "theta_deg", "psi_deg"]].to_numpy(), ref, atol=1e-9)
    # first-order sigma vs 40,000 draws of δθ ~ N(0, P_θθ) at the final epoch (the σ are
    # below 1°, where the map is linear to <1 %); sample-σ error ~0.35 %: 3 % bound
    k = -1
    rng = np.random.default_rng(7)
    d = rng.multivariate_normal(np.zeros(3), est.cov[k, :3, :3], size=40_000)
    qs = rot.quat_mult(rot.rotvec_to_quat(d), est.q[k])
    e = np.degrees(rot.quat_to_euler321(qs))
    e0 = euler321_with_sigma(est.q[k:])[0][0]
    spread = np.std((e - e0 + 180.0) % 360.0 - 180.0, axis=0)
    np.testing.assert_allclose(df[["phi_sigma_deg", "theta_sigma_deg", "psi_sigma_deg"]]
                               .to_numpy()[k], spread, rtol=0.03)


def test_estimate_spin_axis_against_scipy_and_monte_carlo(default_pass):
    from lightcurve.filters.derived import spin_axis

    lc, est = default_pass
    df = est.to_pandas()
    w_i = np.einsum("nji,nj->ni", rot.quat_to_dcm(est.q), est.omega_rad_s)   # A(q)ᵀ ω
    ra = np.degrees(np.arctan2(w_i[:, 1], w_i[:, 0])) % 360
    dec = np.degrees(np.arcsin(w_i[:, 2] / np.linalg.norm(w_i, axis=1)))
    np.testing.assert_allclose(df["spin_ra_deg"], ra, atol=1e-9)
    np.testing.assert_allclose(df["spin_dec_deg"], dec, atol=1e-9)
    np.testing.assert_allclose(df["spin_rate_deg_s"], np.degrees(np.linalg.norm(w_i, axis=1)))
    # the truth rotates about a fixed inertial axis (constant body rate): recovered to 3σ
    tr = spin_axis(lc.truth_q, lc.truth_omega_rad_s)
    ang = np.degrees(np.arccos(np.clip(np.dot(
        w_i[-1] / np.linalg.norm(w_i[-1]),
        tr["omega_eci_rad_s"][-1] / np.linalg.norm(tr["omega_eci_rad_s"][-1])), -1, 1)))
    assert ang < 3 * df["spin_axis_sigma_deg"].iloc[-1] * np.sqrt(2)
    # the axis 1σ (largest axis) vs draws of [δθ, δω] ~ N(0, P)
    k = -1
    rng = np.random.default_rng(11)
    x = rng.multivariate_normal(np.zeros(6), est.cov[k], size=40_000)
    qs = rot.quat_mult(rot.rotvec_to_quat(x[:, :3]), est.q[k])
    ws = rot.quat_rotate_inv(qs, est.omega_rad_s[k] + x[:, 3:])
    u = ws / np.linalg.norm(ws, axis=1, keepdims=True)
    u0 = w_i[k] / np.linalg.norm(w_i[k])
    perp = u - np.outer(u @ u0, u0)
    lam = np.linalg.eigvalsh(np.cov(perp.T))[-1]
    assert df["spin_axis_sigma_deg"].iloc[k] == pytest.approx(np.degrees(np.sqrt(lam)), rel=0.03)


def test_fitted_magnitudes_at_the_truth_are_the_noise_free_magnitudes(default_pass):
    from lightcurve.filters.derived import fitted_magnitudes

    lc, est = default_pass
    np.testing.assert_allclose(fitted_magnitudes(lc.truth_q, lc), lc.truth_mag, atol=1e-9)
    fit = fitted_magnitudes(est.q, lc)
    late = slice(len(lc) // 2, None)  # converged half: residuals of the order of the noise
    z = (lc.mag[late] - fit[late]) / lc.mag_sigma[late]
    assert np.sqrt(np.nanmean(z ** 2)) < 3.0


def test_estimate_table_matches_file_and_xarray(default_pass, tmp_path):
    from lightcurve.filters.result import read_estimate

    _, est = default_pass
    back = read_estimate(est.write(tmp_path / "e.h5"))
    a, b = est.to_pandas(), back.to_pandas()
    assert list(a.columns) == list(b.columns) and a.index.equals(b.index)
    np.testing.assert_allclose(a.to_numpy(float), b.to_numpy(float), equal_nan=True)
    with np.errstate(invalid="ignore"):
        np.testing.assert_allclose(a["nis"], est.innovations ** 2 / est.innovation_var)
    ds = est.to_xarray()
    assert ds["cov"].shape == (len(est), 6, 6)
    np.testing.assert_array_equal(ds["cov"].to_numpy(), est.cov)


def test_to_pandas_without_pandas_says_how_to_install(default_pass, monkeypatch):
    import builtins

    real = builtins.__import__

    def fake(name, *a, **k):
        if name == "pandas" or name.startswith("pandas."):
            raise ImportError("no pandas")
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", fake)
    with pytest.raises(ImportError, match=r"lightcurve\[pandas\]"):
        default_pass[0].to_pandas()


def test_epochs_as_datetime_and_time_objects(default_pass):
    import datetime as dt

    from astropy.time import Time as ATime

    from lightcurve.geometry.time import epoch_iso, parse_epoch, sun_position_gcrs, timescale
    from lightcurve.io.lightcurve_h5 import Lightcurve

    lc, _ = default_pass
    ref = parse_epoch("2008-09-21T01:55:00Z")
    for e in (dt.datetime(2008, 9, 21, 1, 55), dt.datetime(2008, 9, 21, 3, 55,
                                                           tzinfo=dt.timezone(dt.timedelta(hours=2))),
              np.datetime64("2008-09-21T01:55:00"), timescale().utc(2008, 9, 21, 1, 55, 0),
              ATime("2008-09-21T01:55:00", scale="utc"),
              ATime("2008-09-21T01:56:05.184", scale="tt")):   # TT − UTC = 65.184 s in 2008
        assert parse_epoch(e) == ref, e
        assert epoch_iso(e) == "2008-09-21T01:55:00Z"
    t0 = timescale().utc(2008, 9, 21, 1, 55, 0)
    np.testing.assert_allclose(sun_position_gcrs(t0, lc.t), lc.r_sun_eci_m, rtol=1e-12)
    import dataclasses

    kw = {f.name: getattr(lc, f.name) for f in dataclasses.fields(lc)}
    kw["epoch_utc"] = ATime("2008-09-21T01:55:00", scale="utc")
    assert Lightcurve(**kw).epoch_utc == "2008-09-21T01:55:00Z"
