"""End-to-end simulator checks.

* Bernard §9.3.3: at the epoch of the LEO fast-spin case the +X facet normal lies within 0.5°
  of the bisector of the object→Sun and object→Socorro directions (the thesis designed the
  initial attitude so that the first measurement is a specular glint).
* ``truth/mag`` of a simulated thesis scenario recomputed from the file's own geometry and
  truth attitude with an independent plain-numpy implementation of DESIGN.md's magnitude
  equation and Cook–Torrance BRDF (Beckmann D, G, standard Fresnel, a = F0), to 1e-9 mag.
"""

import warnings

import numpy as np
import pytest

from lightcurve import InputError
from lightcurve._paths import data_dir
from lightcurve.io.lightcurve_h5 import read_lightcurve
from lightcurve.studies.scenario import load_scenario, parse_scenario
from lightcurve.studies.simulate import EclipseWarning, simulate

THESIS = data_dir("pipelines") / "thesis"


def _sim(path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EclipseWarning)
        return simulate(load_scenario(path), **kw)


def A_of_q(q):
    """Bernard eq. 3.16, written out independently of lightcurve.rotations."""
    q1, q2, q3, q4 = q
    v = np.array([q2, q3, q4])
    S = np.array([[0, -q4, q3], [q4, 0, -q2], [-q3, q2, 0]])
    return (q1**2 - v @ v) * np.eye(3) + 2 * np.outer(v, v) - 2 * q1 * S


def cook_torrance(n, s, o, xi, F0, m):
    """DESIGN.md Cook–Torrance, sr^-1 (independent plain-numpy version)."""
    h = (s + o) / np.linalg.norm(s + o)
    ns, no, nh, oh = n @ s, n @ o, n @ h, o @ h
    alpha = np.arccos(np.clip(nh, -1, 1))
    D = np.exp(-(np.tan(alpha) / m) ** 2) / (np.pi * m**2 * nh**4)
    G = min(1.0, 2 * nh * no / oh, 2 * nh * ns / oh)
    eta = (1 + np.sqrt(F0)) / (1 - np.sqrt(F0))
    c = oh
    g = np.sqrt(eta**2 + c**2 - 1)
    F = 0.5 * (g - c) ** 2 / (g + c) ** 2 * (1 + (c * (g + c) - 1) ** 2 / (c * (g - c) + 1) ** 2)
    return xi * F0 / np.pi + (1 - xi) * F * D * G / (4 * ns * no)


def test_fast_spin_first_epoch_is_specular_glint():
    lc = _sim(THESIS / "leo-ic1-fast-spin-controlled-1site.toml")
    assert lc.t[0] == 0.0
    s = lc.obj_to_sun_unit[0]
    o = lc.obj_to_obs_unit[0]
    bis = (s + o) / np.linalg.norm(s + o)
    # +X body axis in ECI: first row of A(q) (v_b = A v_I, so x_b = A^T e1)
    x_eci = A_of_q(lc.truth_q[0]).T @ np.array([1.0, 0, 0])
    ang = np.degrees(np.arccos(np.clip(x_eci @ bis, -1, 1)))
    assert ang < 0.5, f"+X normal is {ang:.3f} deg from the Sun/observer bisector"


def test_truth_mag_recomputed_independently(tmp_path):
    lc = _sim(THESIS / "leo-ic1-fast-spin-controlled-2site.toml")
    p = lc.write(tmp_path / "lc.h5")
    f = read_lightcurve(p)
    from lightcurve.photometry import load_shape

    shape = load_shape(f.attrs["shape"])
    tab = shape.param_table
    m_ref = np.empty(len(f))
    for k in range(len(f)):
        A = A_of_q(f.truth_q[k])
        rs = f.r_sun_eci_m[k] - f.r_obj_eci_m[k]
        ro = f.r_site_eci_m[k] - f.r_obj_eci_m[k]
        s = A @ (rs / np.linalg.norm(rs))
        o = A @ (ro / np.linalg.norm(ro))
        flux = 0.0
        for i in range(len(shape.areas_m2)):
            n = shape.normals_body[i]
            if n @ s <= 0 or n @ o <= 0:
                continue
            fr = cook_torrance(n, s, o, tab["xi"][i], tab["a"][i], tab["m"][i])
            flux += shape.areas_m2[i] * (n @ s) * (n @ o) * fr
        m_ref[k] = (-26.74 - 2.5 * np.log10(flux / (ro @ ro))
                    + 5 * np.log10(np.linalg.norm(rs) / 1.495978707e11))
    np.testing.assert_allclose(f.truth_mag, m_ref, atol=1e-9, rtol=0)
    assert set(np.unique(f.site)) == {0, 1}  # both sites measured (switching windows)
    # noise level: sigma = m (r/100)/3, Bernard eq. 9.3
    np.testing.assert_allclose(f.mag_sigma, f.truth_mag * 0.01 / 3, rtol=1e-12)


def test_reproducible_and_seed_dependent():
    a = _sim(THESIS / "leo-ic1-fast-spin-controlled-1site.toml")
    b = _sim(THESIS / "leo-ic1-fast-spin-controlled-1site.toml")
    c = _sim(THESIS / "leo-ic1-fast-spin-controlled-1site.toml", seed=2)
    np.testing.assert_array_equal(a.mag, b.mag)
    assert not np.allclose(a.mag, c.mag)


def test_noise_is_consistent_with_sigma():
    # standardised residuals (mag - truth)/sigma of 1 % noise are N(0,1):
    # chi-square over N samples inside its 99.9 % two-sided band (false alarm 1e-3)
    from scipy.stats import chi2

    lc = _sim(THESIS / "leo-ic1-fast-spin-controlled-1site.toml")
    z = (lc.mag - lc.truth_mag) / lc.mag_sigma
    n = len(z)
    assert chi2.ppf(0.0005, n) < np.sum(z**2) < chi2.ppf(0.9995, n)


def test_eclipse_warning_and_drop():
    text = (THESIS / "leo-ic1-fast-spin-controlled-1site.toml").read_text()
    with pytest.warns(EclipseWarning, match="AS IF SUNLIT"):
        simulate(parse_scenario(text))
    dark = text.replace("ignore_eclipse = true", "ignore_eclipse = false")
    with pytest.warns(EclipseWarning), pytest.raises(InputError, match="no visible measurement"):
        simulate(parse_scenario(dark, file="dark.toml"))


def test_nadir_frame_initial_attitude():
    # frame = "nadir": zero angles relative to the nadir frame -> body +z points at the Earth's
    # centre and the body rate is the orbit rate about the negative orbit normal ([0, -n, 0])
    text = (THESIS / "leo-ic2-nadir-controlled-1site.toml").read_text()
    text = text.replace('frame = "inertial"', 'frame = "nadir"')
    text = text.replace("euler321_deg = [-174.911, 35.9513, 8.6586]", "euler321_deg = [0.0, 0.0, 0.0]")
    text = text.replace("omega_deg_s = [0.0, 0.0635, 0.0]", "omega_deg_s = [0.0, 0.0, 0.0]")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lc = simulate(parse_scenario(text, file="nadir.toml"))
    r = lc.r_obj_eci_m[0]
    z_eci = A_of_q(lc.truth_q[0]).T @ np.array([0, 0, 1.0])
    assert np.degrees(np.arccos(np.clip(z_eci @ (-r / np.linalg.norm(r)), -1, 1))) < 0.5  # ACS noise 0.1 deg
    n = np.sqrt(3.986004418e14 / 6871.14e3**3)
    np.testing.assert_allclose(lc.truth_omega_rad_s[0], [0, -n, 0], rtol=0.03, atol=1e-6)


def test_bad_scenario_errors(tmp_path):
    text = (THESIS / "leo-ic1-fast-spin-controlled-1site.toml").read_text()
    with pytest.raises(InputError, match=r"shape.*nonexistent|nonexistent"):
        parse_scenario(text.replace('name = "cube_1u"', 'name = "nonexistent"'), file="x.toml")
    with pytest.raises(InputError, match="orbit.e"):
        parse_scenario(text.replace("e = 0.01", "e = 1.5"), file="x.toml")
    with pytest.raises(InputError, match="unknown key"):
        parse_scenario(text.replace("seed = 1", "seed = 1\nsede = 2"), file="x.toml")
    with pytest.raises(InputError, match="windows_s"):
        parse_scenario(text.replace("windows_s = [[0.0, 360.0]]", "windows_s = [[10.0, 5.0]]"), file="x.toml")
