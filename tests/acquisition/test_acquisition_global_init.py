"""Global initialisation (lightcurve.acquisition.global_init): attitude with no first guess.

The truth in the simulated files is used only to score the answer, never by the estimator.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from lightcurve import rotations as rot
from lightcurve.acquisition.global_init import (GlobalInitConfig, axis_group_quaternions,
                                                global_initialise, uniform_quaternions)

SYMMETRIC_CUBE = """
[shape]
name = "sym_cube"
description = "1U cube, one material on all six faces (octahedral symmetry)"
mass_kg = 1.33
inertia_diag_kg_m2 = [0.0022166666666666667, 0.0022166666666666667, 0.0022166666666666667]

[materials.all]
brdf = "cook_torrance"
xi = 0.3
a = 0.8
m = 0.2
""" + "".join(f"""
[[facets]]
normal = {n}
area_m2 = 0.01
center_m = {[0.05 * x for x in n]}
material = "all"
""" for n in ([1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0],
              [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]))

SCENARIO = """
[scenario]
name = "sym-cube-fast-spin"
epoch_utc = "2020-03-01T08:08:40Z"
duration_s = 200.0
cadence_s = 5.0
seed = 1

[orbit]
type = "keplerian"
a_km = 6871.14
e = 0.01
i_deg = 83.0
raan_deg = 0.0
argp_deg = 0.0
nu_deg = 126.264
gravity = "J4"

[shape]
name = "sym_cube"

[attitude]
dynamics = "controlled"
frame = "inertial"
euler321_deg = [-42.4122, 59.1601, 48.9897]
omega_deg_s = [2.0, 1.0, 3.6]
acs_sigma_deg = 0.0

[[sites]]
name = "socorro"
windows_s = [[0.0, 200.0]]

[measurement]
r_percent = 1.0
ignore_eclipse = true
"""


def test_uniform_quaternions_are_haar_distributed():
    """Under the Haar measure the rotation angle θ has density (2/π) sin²(θ/2) on [0, π], so
    |q1| = cos(θ/2) has mean 4/(3π); also E[q1²] = 1/4. 200,000 samples, 5 standard errors."""
    q = uniform_quaternions(200_000, np.random.default_rng(3))
    m = np.abs(q[:, 0]).mean()
    se = np.abs(q[:, 0]).std() / math.sqrt(q.shape[0])
    assert abs(m - 4 / (3 * math.pi)) < 5 * se
    sq = q[:, 0] ** 2
    assert abs(sq.mean() - 0.25) < 5 * sq.std() / math.sqrt(q.shape[0])


def test_axis_group_is_the_24_rotations_of_the_cube():
    G = axis_group_quaternions()
    assert G.shape == (24, 4)
    A = rot.quat_to_dcm(G)
    assert np.allclose(np.abs(A).sum(axis=2), 1.0)           # signed permutation matrices
    assert np.allclose(np.linalg.det(A), 1.0)
    assert np.allclose(G[0], [1, 0, 0, 0])
    # closed under composition
    for i in range(24):
        for j in range(24):
            c = rot.quat_mult(G[i], G[j])
            assert np.min(1 - np.abs(G @ c)) < 1e-12


def test_quat_average_of_symmetric_perturbations_is_the_centre():
    """Markley et al. (2007): ±δ rotations about each axis average back to the centre, whatever
    the quaternion signs."""
    q0 = rot.quat_normalize(np.array([0.6, -0.2, 0.5, 0.3]))
    qs = []
    for ax in np.eye(3):
        for sgn in (1, -1):
            q = rot.quat_mult(rot.rotvec_to_quat(sgn * 0.3 * ax), q0)
            qs.append(q if sgn > 0 else -q)
    avg = rot.quat_average(np.array(qs))
    assert np.degrees(rot.attitude_error_angle(q0, avg)) < 1e-9


@pytest.fixture(scope="module")
def symmetric_curve(tmp_path_factory):
    import lightcurve
    from lightcurve.photometry import load_shape
    from lightcurve.studies.scenario import parse_scenario

    d = tmp_path_factory.mktemp("symcube")
    (d / "sym_cube.toml").write_text(SYMMETRIC_CUBE)
    scen = parse_scenario(SCENARIO, library_dirs=[str(d)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lc = lightcurve.simulate(scen, seed=2)
    return lc, load_shape("sym_cube", library_dirs=[str(d)])


def test_a_symmetric_body_is_reported_ambiguous(symmetric_curve):
    """All six faces alike: the 24 attitudes related by the cube's rotations give the same
    lightcurve. The result must say it is ambiguous and list several modes, and its best mode
    must be the truth up to one of those rotations (within 5°) — never one confident answer."""
    lc, shape = symmetric_curve
    res = global_initialise(lc, "ukf", seed=0, shape=shape,
                            config=GlobalInitConfig(particles=4000, moves=2))
    assert res.ambiguous and len(res.modes) >= 2
    assert "ambiguous" in res.statement
    G = axis_group_quaternions()
    q_true = lc.truth_q[-1]
    err = min(float(np.degrees(rot.attitude_error_angle(rot.quat_mult(g, q_true),
                                                         res.best.q[-1]))) for g in G)
    assert err < 5.0
    s = res.summary()
    assert s["ambiguous"] and len(s["modes"]) == len(res.modes)
    assert res.best.meta["global_init"]["ambiguous"]
