"""CSS measurement model (O'Keefe eq. 2.19, 2.21) and configurations (tables 2.1, 2.2).

Basilisk-style: every routine is compared with an independent inline numpy version and with
hand-computed truth values.
"""

import numpy as np
import pytest

from lightcurve.css.configurations import (CUBE_AZEL_DEG, DUAL_PYRAMID_AZEL_DEG, cube,
                                           dual_pyramid, load_configuration)
from lightcurve.css.sensors import CSSArray, azel_to_normal
from lightcurve.errors import InputError


def _inline_model(normals, fov, gains, s, lit):
    s = s / np.linalg.norm(s)
    c = normals @ s
    return gains * lit * np.where((c >= np.cos(fov)) & (c > 0), c, 0.0)


def test_dual_pyramid_table_2_1_normals():
    # Table 2.1: +z sensors at azimuth 0/90/180/270, elevation +45; -z sensors rotated 45 deg.
    css = dual_pyramid(fov_half_angle_deg=90.0)
    h = np.sqrt(0.5)
    assert np.allclose(css.normals[0], [h, 0, h])
    assert np.allclose(css.normals[1], [0, h, h], atol=1e-15)
    assert np.allclose(css.normals[4], [0.5, 0.5, -h])
    assert np.allclose(css.normals[7], [0.5, -0.5, -h])
    assert np.allclose(np.linalg.norm(css.normals, axis=1), 1.0)
    assert DUAL_PYRAMID_AZEL_DEG.shape == (8, 2)


def test_cube_table_2_2_sensor4_is_minus_y():
    # Table 2.2 prints azimuth "20" for sensor 4: a typo for 270 -> the -y face.
    c = cube()
    assert CUBE_AZEL_DEG[3, 0] == 270.0
    assert np.allclose(c.normals[3], [0, -1, 0], atol=1e-15)
    # six faces: the normals sum to zero and are pairwise orthogonal or opposite
    assert np.allclose(c.normals.sum(axis=0), 0, atol=1e-14)
    g = c.normals @ c.normals.T
    assert np.all(np.isclose(np.abs(g), 0, atol=1e-14) | np.isclose(np.abs(g), 1))


def test_signals_match_inline_cosine_model_and_hand_values():
    css = dual_pyramid(fov_half_angle_deg=70.0)
    rng = np.random.default_rng(1)
    S = rng.normal(size=(200, 3))
    y = css.signals(S)
    exp = np.array([_inline_model(css.normals, css.fov_half_angle_rad, 1.0, s, 1.0) for s in S])
    assert np.allclose(y, exp, atol=1e-14)
    # hand value: Sun along +z sees the four upper sensors at cos45 = 0.7071..., lower ones 0
    y = css.signals([0, 0, 1.0])
    assert np.allclose(y, [np.sqrt(0.5)] * 4 + [0.0] * 4)
    # Sun along +x: sensor 1 at cos45, sensors 5 and 8 at cos(angle) = 0.5, FOV 70 deg keeps
    # 0.5 > cos70 = 0.342
    y = css.signals([1.0, 0, 0])
    assert np.allclose(y, [np.sqrt(0.5), 0, 0, 0, 0.5, 0, 0, 0.5], atol=1e-15)
    # eclipse: zero output
    assert np.all(css.signals([1.0, 0, 0], lit=0.0) == 0)


def test_fov_cutoff():
    css = CSSArray([[0, 0, 1.0]], np.radians(30.0))
    for ang, expect in ((29.0, np.cos(np.radians(29.0))), (31.0, 0.0)):
        s = [np.sin(np.radians(ang)), 0, np.cos(np.radians(ang))]
        assert css.signals(s)[0] == pytest.approx(expect, abs=1e-15)


def test_scale_factors_and_misalignment_eq_2_19():
    css = dual_pyramid(fov_half_angle_deg=90.0)
    ci = np.linspace(0.9, 1.1, 8)
    mis = np.radians(np.column_stack([np.linspace(-2, 2, 8), np.linspace(1, -1, 8)]))
    e = css.with_errors(scale_common=0.95, scale_individual=ci, misalignment_rad=mis)
    # independent inline eq. 2.19: offset azimuth and elevation of each normal
    az = np.radians(DUAL_PYRAMID_AZEL_DEG[:, 0]) + mis[:, 0]
    el = np.radians(DUAL_PYRAMID_AZEL_DEG[:, 1]) + mis[:, 1]
    n_true = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    assert np.allclose(e.true_normals(), n_true, atol=1e-14)
    s = np.array([0.3, -0.2, 0.9])
    assert np.allclose(e.signals(s), _inline_model(n_true, np.pi / 2, 0.95 * ci, s, 1.0))
    # angle between nominal and true normal equals the great-circle offset
    cosang = np.sum(n_true * e.normals, axis=1)
    hav = np.cos(np.radians(DUAL_PYRAMID_AZEL_DEG[:, 1])) * np.cos(el)
    cos_expected = np.sin(np.radians(DUAL_PYRAMID_AZEL_DEG[:, 1])) * np.sin(el) + hav * np.cos(mis[:, 0])
    assert np.allclose(cosang, cos_expected)


def test_noise_statistics_and_seed_reproducible():
    css = dual_pyramid(noise_sigma=0.02)
    s = np.tile([0.0, 0.0, 1.0], (4000, 1))
    y1 = css.signals(s, rng=7, clip=False)
    y2 = css.signals(s, rng=7, clip=False)
    assert np.array_equal(y1, y2)
    r = (y1 - css.signals(s))[:, :4].ravel()
    # chi-square bound on the variance: 16000 samples, 99.9 % two-sided -> +-3.3 sigma of
    # the sample variance (relative std sqrt(2/n) = 1.1 %)
    assert abs(r.var() / 0.02 ** 2 - 1) < 3.3 * np.sqrt(2 / r.size)
    assert np.all(css.signals(s, rng=3) >= 0)


def test_structure_horizon():
    css = CSSArray([[1.0, 0, 0]], np.pi / 2, horizon_normals=[[0, 0, 1.0]])
    assert css.signals([1, 0, 0.1])[0] > 0
    assert css.signals([1, 0, -0.1])[0] == 0


def _write(tmp_path, text):
    p = tmp_path / "css.toml"
    p.write_text(text)
    return p


def test_toml_loader_roundtrip(tmp_path):
    p = _write(tmp_path, """
name = "t"
fov_half_angle_deg = 80
noise_sigma = 0.01
[[sensor]]
azimuth_deg = 90
elevation_deg = 0
[[sensor]]
normal = [0, 0, -2]
fov_half_angle_deg = 45
""")
    c = load_configuration(p)
    assert np.allclose(c.normals, [[0, 1, 0], [0, 0, -1]], atol=1e-15)
    assert np.allclose(np.degrees(c.fov_half_angle_rad), [80, 45])
    assert c.noise_sigma == 0.01


@pytest.mark.parametrize("body,field", [
    ("[[sensor]]\nnormal = [0, 0, 0]\n", "sensor[0].normal"),
    ("[[sensor]]\nnormal = [1, 0, 0]\nfov_half_angle_deg = 0\n", "sensor[0].fov_half_angle_deg"),
    ("[[sensor]]\nnormal = [1, 0, 0]\nfov_half_angle_deg = 95\n", "sensor[0].fov_half_angle_deg"),
    ("fov_half_angle_deg = -3\n[[sensor]]\nnormal = [1, 0, 0]\n", "fov_half_angle_deg"),
    ("[[sensor]]\nnormal = [1, 0, 0]\nfov = 3\n", "sensor[0]"),
])
def test_toml_bad_input_names_file_and_field(tmp_path, body, field):
    p = _write(tmp_path, body)
    with pytest.raises(InputError) as ei:
        load_configuration(p)
    assert str(p) in str(ei.value) and field in str(ei.value)


def test_programmer_misuse_value_errors():
    with pytest.raises(ValueError):
        CSSArray([[0, 0, 0.0]], 1.0)
    with pytest.raises(ValueError):
        CSSArray([[0, 0, 1.0]], 2.0)
    assert np.allclose(azel_to_normal(0.0, np.pi / 2), [0, 0, 1], atol=1e-16)
