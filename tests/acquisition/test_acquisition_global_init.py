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
                                                uniform_quaternions)

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
def symmetric_curve(sym_cube_library):
    import lightcurve
    from lightcurve.photometry import load_shape
    from lightcurve.studies.scenario import parse_scenario

    d = sym_cube_library
    scen = parse_scenario(SCENARIO, library_dirs=[str(d)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lc = lightcurve.simulate(scen, seed=2)
    return lc, load_shape("sym_cube", library_dirs=[str(d)])


def test_a_symmetric_body_is_reported_unique_only_up_to_its_symmetries(symmetric_curve):
    """All six faces alike: the 24 attitudes related by the cube's rotations give the same
    lightcurve. The result must say so ("unique up to the shape's 24 rotation symmetries"),
    merge those copies into one mode instead of listing them as rival answers, and its best
    mode must be the truth up to one of those rotations (within 5°) — as must every listed
    mode."""
    import lightcurve

    lc, shape = symmetric_curve
    est = lightcurve.invert(lc, "ukf", shape=shape, initial="global",
                            global_config=GlobalInitConfig(particles=6000, moves=2))
    gi = est.meta["global_init"]
    assert gi["symmetries"] == 24
    assert "unique up to the shape's 24 rotation symmetries" in gi["statement"]
    G = axis_group_quaternions()
    q_true = lc.truth_q[-1]
    err = min(float(np.degrees(rot.attitude_error_angle(rot.quat_mult(g, q_true), est.q[-1])))
              for g in G)
    assert err < 5.0
    s = est.summary()
    assert s["global_init"]["symmetries"] == 24
    # no two listed modes are copies of each other under the cube's rotations
    q0s = [np.asarray(m["q0"]) for m in gi["modes"]]
    for a in range(len(q0s)):
        for b in range(a + 1, len(q0s)):
            d = min(float(np.degrees(rot.attitude_error_angle(rot.quat_mult(g, q0s[a]), q0s[b])))
                    for g in G)
            assert d > 10.0
    # every listed mode ends at the truth up to a rotation of the cube (all equally good)
    for m in gi["modes"]:
        e = min(float(np.degrees(rot.attitude_error_angle(rot.quat_mult(g, q_true),
                                                           np.asarray(m["final_q"]))))
                for g in G)
        assert e < 5.0


class _FakeEstimate:
    """What global_initialise reads from a filter run: a constant attitude, the innovations
    (zero) with a chosen variance (which sets the evidence), and the consistency verdict."""

    def __init__(self, q0, w0, consistent, var):
        n = 10
        self.q = np.tile(q0, (n, 1))
        self.omega_rad_s = np.tile(w0, (n, 1))
        self.att_sigma_deg = np.ones((n, 3))
        self.diverged = False
        self.att_error_deg = None
        self.innovations = np.zeros(n)
        self.innovation_var = np.full(n, var)
        self.meta = {}
        self._flags = [] if consistent else ["nis_high"]

    def consistency(self):
        return {"flags": list(self._flags), "consistent": not self._flags}


def _cube_1u_problem():
    """The SCENARIO pass with the one-material cube (seed 3) and a filter problem on it whose
    initial estimate is never used (the global initialisation replaces it)."""
    import lightcurve
    from lightcurve.filters.config import ProblemConfig
    from lightcurve.filters.invert import build_problem
    from lightcurve.studies.scenario import parse_scenario

    scen = parse_scenario(SCENARIO.replace('name = "sym_cube"', 'name = "cube_1u"'))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lc = lightcurve.simulate(scen, seed=3)
    return lc, build_problem(lc, ProblemConfig(initial="given", initial_q=(1.0, 0, 0, 0),
                                               initial_omega=(0.0, 0, 0)))


def test_rejected_heaviest_mode_is_replaced_by_the_consistent_candidates(sym_cube_library):
    """The filter from the heaviest mode is rejected (stub): the result must start the filter
    from ``refine_modes`` more candidates, report only the accepted ones, weigh them by the
    filters' evidence Σ −½(ν²/S + ln 2πS) (here 10 updates, ν = 0: the weight ratio of two
    accepted starts with S = 1 and S = e is e^{10/2}), and state the ambiguity only when a second
    accepted mode holds ≥ ``report_weight``."""
    from lightcurve.acquisition.global_init import global_initialise

    lc, prob = _cube_1u_problem()
    cfg = GlobalInitConfig(particles=600, moves=1, window_epochs=20, refine_modes=3,
                           restarts=0)

    def make(variances):
        calls = []

        def run_filter(q0, w0, st, sw):
            k = len(calls)
            calls.append(np.array(q0))
            # the first start (the heaviest mode) is rejected; the others accepted
            return _FakeEstimate(q0, w0, k > 0, variances[min(k, len(variances) - 1)])
        return run_filter, calls

    run, calls = make([1.0, 1.0, math.e, math.e ** 3])
    res = global_initialise(lc, prob, run, seed=1, config=cfg, period="none")
    assert res.n_refined == 3 and res.n_rejected == 1 and len(res.modes) == len(calls) - 1
    assert {m.source for m in res.modes} <= {"sampler", "cloud", "image"}
    assert all(m.consistent for m in res.modes)
    assert not any(abs(float(m.q0 @ calls[0])) > 1 - 1e-12 for m in res.modes)
    w = np.array([m.weight for m in res.modes])
    assert w.sum() == pytest.approx(1.0)
    assert w[0] / w[1] == pytest.approx(math.exp(5.0), rel=1e-9)
    assert res.ambiguous is False            # e^{-5}/(1 + …) < 5 %: one answer
    assert "rejected by the data" in res.statement
    # two equally good accepted starts: an ambiguity is stated
    run, calls = make([1.0, 1.0, 1.0, math.e ** 3])
    res = global_initialise(lc, prob, run, seed=1, config=cfg, period="none")
    assert res.ambiguous and "ambiguous" in res.statement
    assert res.modes[0].weight == pytest.approx(res.modes[1].weight)


def test_restarts_use_restart_factor_times_the_particles_and_stop_at_the_limit(sym_cube_library):
    """Every started filter rejected (stub): the search runs 1 + ``restarts`` independent
    samplers, the restarts with ``restart_factor`` × ``particles``, keeps one of them, and says
    that the data reject the result; a bad ``restart_factor`` is one clear error."""
    from lightcurve.acquisition.global_init import global_initialise
    from lightcurve.errors import InputError

    lc, prob = _cube_1u_problem()
    sizes = []

    def run_filter(q0, w0, st, sw):
        return _FakeEstimate(q0, w0, False, 1.0)

    def progress(line):
        if line.startswith("stage 1:") or "restarting with" in line:
            sizes.append(line)

    for factor, expect in ((1.0, {400}), (1.5, {400, 600})):
        cfg = GlobalInitConfig(particles=400, moves=1, window_epochs=20, refine_modes=0,
                               restarts=2, restart_factor=factor)
        res = global_initialise(lc, prob, run_filter, seed=1, config=cfg, period="none",
                                progress=progress)
        assert res.attempts == 3
        assert res.particles in expect
        assert "not consistent with the data" in res.statement
    starts = [x for x in sizes if x.startswith("stage 1:")]
    assert len(starts) == 6                      # 2 × (1 + 2) samplers started
    restarts = [x for x in sizes if "restarting with" in x]
    assert restarts == ["no started filter is consistent with the data: restarting with 400 "
                        "particles"] * 2 + ["no started filter is consistent with the data: "
                                            "restarting with 600 particles"] * 2
    with pytest.raises(InputError, match="restart_factor"):
        GlobalInitConfig(restart_factor=0.5)
