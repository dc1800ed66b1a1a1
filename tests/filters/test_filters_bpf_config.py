"""BPFConfig and the thesis variant (Bernard 2021 §7.3, tables 6.3 and 7.9); counter-based draws;
thread budget of the multi-process paths."""

from __future__ import annotations

import operator

import numba
import numpy as np
import pytest
from filters_synth import make_curve
from scipy import stats

from lightcurve import threads
from lightcurve.core import particles as CP
from lightcurve.filters import FLAG_INFLATED, build_problem, run_bpf
from lightcurve.filters import _bpf_kernels as BK
from lightcurve.filters import bpf as bpf_mod
from lightcurve.filters.bpf import BPFConfig


@pytest.fixture(scope="module")
def easy():
    return build_problem(make_curve(n=40, seed=3), seed=2, sigma_theta_deg=3.0)


def test_config_variants_and_validation():
    t = BPFConfig.thesis()
    # Bernard ch. 7: multinomial resampling (table 6.3), table 7.9 roughening, no progressive
    # correction, no gate, the estimate about one particle (eq. 7.100, "some i-th particle")
    assert (t.resampling, t.rejuvenation, t.progressive, t.gating, t.reference) == (
        "multinomial", "table7.9", False, False, "heaviest")
    r = BPFConfig()
    assert (r.variant, r.resampling, r.rejuvenation, r.progressive, r.gating, r.reference) == (
        "robust", "systematic", "auto", True, True, "refined")
    # an explicit field is a named departure from the variant
    assert BPFConfig(variant="thesis", resampling="systematic").resampling == "systematic"
    assert r.replace(particles=50).particles == 50
    for bad in (dict(particles=1), dict(particles=2.5), dict(variant="x"),
                dict(resampling="residual"), dict(ess_threshold=1.5), dict(roughening=-1),
                dict(rejuvenation="musso"), dict(kernel_bandwidth=1.0), dict(max_stages=0),
                dict(joint_max_spread_deg=0), dict(param_discount=0), dict(rng="mt")):
        with pytest.raises(ValueError):
            BPFConfig(**bad)


def test_table_7_9_roughening_kernel_matches_the_text():
    """Table 7.9: σ_l = 𝒢 E_l N^(−1/n) from the ranges of the error GRPs and rates, then
    q ← q(c_θ) ⊗ q (eq. 7.108, c_θ a GRP, eq. 7.2–7.4) and ω ← c_ω + ω (eq. 7.109); checked
    against a plain-NumPy evaluation of the same equations written here."""
    rng = np.random.default_rng(5)
    N = 500
    Q = rng.standard_normal((N, 4))
    Q /= np.linalg.norm(Q, axis=1, keepdims=True)
    W = rng.standard_normal((N, 3)) * 0.03
    X = np.hstack([rng.standard_normal((N, 3)) * 0.1, W])
    E = np.empty(6)
    CP.column_ranges(X, E)
    np.testing.assert_array_equal(E, X.max(axis=0) - X.min(axis=0))
    G = 0.2
    sig = CP.roughening_sigma_nb(E, G, N, 6)
    np.testing.assert_allclose(sig, G * E * N ** (-1 / 6), rtol=1e-15)
    z = rng.standard_normal((N, 6))
    Qn, Wn = Q.copy(), W.copy()
    BK.roughen_compose(Qn, Wn, z, sig, 1.0, 4.0)
    c = z * sig
    # eq. 7.2–7.4 (a = 1, f = 4): δq4 = (−a|p|² + f√(f² + (1−a²)|p|²))/(f² + |p|²), δq_v = (a+δq4)/f p
    n2 = np.sum(c[:, :3] ** 2, axis=1)
    q4 = (-n2 + 4 * np.sqrt(16.0)) / (16 + n2)
    dq = np.hstack([q4[:, None], ((1 + q4) / 4)[:, None] * c[:, :3]])
    a0, av = dq[:, 0], dq[:, 1:]
    b0, bv = Q[:, 0], Q[:, 1:]
    ref = np.hstack([(a0 * b0 - np.sum(av * bv, axis=1))[:, None],
                     a0[:, None] * bv + b0[:, None] * av - np.cross(av, bv)])   # eq. 3.20
    np.testing.assert_allclose(Qn, ref / np.linalg.norm(ref, axis=1, keepdims=True), atol=1e-14)
    np.testing.assert_allclose(Wn, W + c[:, 3:], atol=1e-16)


def test_thesis_variant_is_the_plain_filter(easy):
    c = make_curve(n=40, seed=3)
    c.mag = c.mag.copy()
    c.mag[20] += 3.0                       # a gross outlier: the thesis filter has no gate
    p = build_problem(c, seed=2, sigma_theta_deg=3.0)
    est = run_bpf(p, BPFConfig.thesis(particles=2000), seed=1)
    assert sum(est.meta["tempering_stages"]) == 0
    assert not np.any(est.flags & FLAG_INFLATED)
    assert est.meta["gate"]["mode"] == "off" and est.meta["bpf"]["variant"] == "thesis"
    robust = run_bpf(p, particles=2000, seed=1)
    assert robust.flags[20] & FLAG_INFLATED
    # on the easy case (σθ = 3° per axis, r = 1 %) the thesis filter converges too: its final
    # error lies inside its own 3σ and below the prior's RSS σ (3°·√3 = 5.2°)
    e2 = run_bpf(easy, BPFConfig.thesis(particles=2000), seed=1)
    s2 = e2.summary()
    assert s2["inside_3sigma"] and not e2.diverged
    assert s2["final_att_error_rss_deg"] < 3.0 * np.sqrt(3.0)


def test_thread_count_follows_the_cloud_size():
    # one thread per PARTICLES_PER_THREAD particles, at least one
    n = bpf_mod.PARTICLES_PER_THREAD
    assert [bpf_mod.bpf_threads(k) for k in (1, n, n + 1, 10 * n)] == [1, 1, 2, 10]


def test_runs_are_reproducible_and_thread_count_independent(easy, monkeypatch):
    # a small share per thread, so that this small cloud runs on several threads
    monkeypatch.setattr(bpf_mod, "PARTICLES_PER_THREAD", 1024)
    assert bpf_mod.bpf_threads(3000) == 3
    a = run_bpf(easy, particles=3000, seed=4)
    b = run_bpf(easy, particles=3000, seed=4)
    np.testing.assert_array_equal(a.q, b.q)
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one numba thread (NUMBA_NUM_THREADS=1): no second thread count to compare")
    with threads.limited_threads(1):
        c = run_bpf(easy, particles=3000, seed=4)
    np.testing.assert_array_equal(a.q, c.q)
    np.testing.assert_array_equal(a.cov, c.cov)


def test_initial_cloud_is_used(easy):
    N = 500
    Q = np.tile(easy.truth_q[0], (N, 1))
    W = np.tile(easy.truth_omega[0], (N, 1))
    est = run_bpf(easy, particles=N, seed=0, initial_cloud=(Q, W))
    # every particle at the truth: the first estimate is the truth (to round-off)
    assert est.att_error_deg is not None and np.max(np.abs(est.att_error_deg[0])) < 1e-6
    with pytest.raises(ValueError):
        run_bpf(easy, particles=N, seed=0, initial_cloud=(Q[:10], W))


def test_philox_normals_are_standard_normal_and_counter_based():
    # Philox4x32-10 known-answer vectors (Salmon et al. 2011, Random123 kat_vectors)
    u = np.uint64
    assert CP.philox4x32(u(0), u(0), u(0), u(0), u(0), u(0)) == (
        0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)
    m = u(0xFFFFFFFF)
    assert CP.philox4x32(m, m, m, m, m, m) == (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD)
    z = np.empty((100_000, 3))
    CP.philox_normals(11, 22, 3, z)
    # Kolmogorov–Smirnov against N(0, 1) per column; false-alarm rate 3 × 1e-3
    for j in range(3):
        assert stats.kstest(z[:, j], "norm").pvalue > 1e-3
    # |corr| between columns below 4.4/√N (two-sided 1e-5 each)
    c = np.corrcoef(z.T)
    assert np.max(np.abs(c[np.triu_indices(3, 1)])) < 4.4 / np.sqrt(z.shape[0])
    # row i of a call does not depend on how many rows are drawn (counter-based)
    z2 = np.empty((10, 3))
    CP.philox_normals(11, 22, 3, z2)
    np.testing.assert_array_equal(z2, z[:10])
    z3 = np.empty((10, 3))
    CP.philox_normals(11, 22, 4, z3)
    assert not np.any(z3 == z2)


@numba.njit
def _ziggurat_entries(k0, k1, call, N, r):
    """Entry (i, j) of philox_normals by its definition: ziggurat_normal of counter
    (i, j, call mod 2³², call div 2³²), one entry at a time."""
    out = np.empty((N, r))
    cl = np.uint64(call) & np.uint64(0xFFFFFFFF)
    ch = np.uint64(call) >> np.uint64(32)
    for i in range(N):
        for j in range(r):
            out[i, j] = CP.ziggurat_normal(np.uint64(i), np.uint64(j), cl, ch, np.uint64(k0),
                                           np.uint64(k1), CP._ZIG_X, CP._ZIG_R)
    return out


def test_philox_normals_two_pass_kernel_is_the_definition():
    # the kernel draws every entry's first attempt in a vectorised pass and finishes the
    # rejected ones (≈ 1 %: wedges and the tail) with ziggurat_normal: the same bits as
    # drawing entry by entry, for a call number above 2³² and a partial last chunk
    N, r, call = 3 * 2048 + 5, 7, 2**33 + 9
    z = np.empty((N, r))
    CP.philox_normals(5, 2**31 + 7, call, z)
    ref = _ziggurat_entries(5, 2**31 + 7, call, N, r)
    assert np.array_equal(z, ref)
    assert np.sum(np.abs(ref) > CP._ZIG_TAIL) > 0      # the tail branch was exercised


def test_thread_budget(monkeypatch):
    monkeypatch.setattr(threads, "available_cores", lambda: 16)
    monkeypatch.setattr(threads, "_USER_LIMIT", None)
    assert threads.threads_per_worker(2) == 8
    assert threads.threads_per_worker(16) == 1 and threads.threads_per_worker(40) == 1
    monkeypatch.setattr(threads, "_USER_LIMIT", "3")      # the user's NUMBA_NUM_THREADS caps it
    assert threads.threads_per_worker(2) == 3
    assert threads.threads_per_worker(2, cores=2) == 1


def test_openmp_waits_spin_briefly_unless_the_user_chose(monkeypatch):
    # lightcurve's default: spin SPIN_COUNT iterations, then sleep (docs/bpf.md); a user's
    # OMP_WAIT_POLICY or GOMP_SPINCOUNT is left as it is
    for k in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT"):
        monkeypatch.delenv(k, raising=False)
    assert threads.configure_threading() == f"GOMP_SPINCOUNT={threads.SPIN_COUNT}"
    assert threads.os.environ["GOMP_SPINCOUNT"] == str(threads.SPIN_COUNT)
    monkeypatch.setenv("GOMP_SPINCOUNT", "50")
    assert threads.configure_threading() == "GOMP_SPINCOUNT=50"
    monkeypatch.delenv("GOMP_SPINCOUNT")
    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")
    assert threads.configure_threading() == "OMP_WAIT_POLICY=PASSIVE"
    assert "GOMP_SPINCOUNT" not in threads.os.environ


def test_pool_workers_get_their_share_of_the_cores():
    from lightcurve.studies.runner import iter_results

    cores = threads.available_cores()
    got = list(iter_results([numba.get_num_threads] * 4, operator.call, workers=2))
    assert all(1 <= n <= max(1, cores // 2) for n in got), got


def test_unmoved_copies_keep_their_predictions(monkeypatch):
    """Between tempering stages without a move (rejuvenation "none"), the resampled copies keep
    their predicted magnitudes instead of being predicted again: same posterior as re-predicting
    (to round-off: a re-prediction renormalises the quaternions)."""
    import lightcurve.filters.bpf as B

    p = build_problem(make_curve(n=12, seed=4), seed=1, sigma_theta_deg=30.0)
    a = run_bpf(p, particles=1500, seed=2, rejuvenation="none")
    assert sum(a.meta["tempering_stages"]) > 0
    orig = B._Run._stage_move
    monkeypatch.setattr(B._Run, "_stage_move",
                        lambda self, k, rest, zeta: (orig(self, k, rest, zeta)[0], True))
    b = run_bpf(p, particles=1500, seed=2, rejuvenation="none")
    assert a.meta["tempering_stages"] == b.meta["tempering_stages"]
    np.testing.assert_allclose(a.q, b.q, atol=1e-10)


def test_exp_or_zero_is_exp():
    """The weight sums' exp with its underflow shortcut returns math.exp's value for every
    argument: below −746 exp is below half the least subnormal (2⁻¹⁰⁷⁵, ln = −745.133…) and
    rounds to 0 (IEEE 754 round to nearest); NaN stays NaN."""
    import math

    f = numba.njit(lambda x: CP.exp_or_zero(x))
    xs = np.concatenate([np.linspace(-760.0, -700.0, 6001), [-746.0, np.nextafter(-746.0, 0.0),
                         -745.2, -745.13, -1e300, -np.inf, 0.0, -1.0, 3.0]])
    for x in xs:
        assert f(x) == math.exp(x), x
    assert np.isnan(f(np.nan))


def test_loglik_pass_equals_innovation_loglik():
    """The log-likelihood-only pass fills the ll of innovation_loglik (Bernard eq. 6.55–6.56
    without the constant; −inf for a non-finite prediction) to the last bit."""
    rng = np.random.default_rng(3)
    N = 5000
    m = 8.0 + rng.normal(size=N)
    m[::17] = np.inf
    logw = np.log(rng.random(N))
    a, b = np.empty(N), np.empty(N)
    CP.innovation_loglik(logw, m, 8.3, 0.02, a)
    CP.gaussian_loglik_into(m, 8.3, 0.02, b)
    np.testing.assert_array_equal(a, b)
    assert np.all(b[::17] == -np.inf)


def test_jitter_rotation_kept_through_stages_is_exact(monkeypatch):
    """ACS jitter model (Bernard eq. 7.8–7.11): the quaternions exp(ζ_i) formed once per epoch
    and resampled with the cloud give the posterior of forming them again at every tempering
    stage's prediction, bit for bit."""
    import lightcurve.filters.bpf as B

    p = build_problem(make_curve(n=12, seed=4, acs_mode="jitter"), seed=1, sigma_theta_deg=30.0,
                      acs_mode="jitter")
    assert p.jitter_zeta()
    modes = []
    orig = B._Run.dq_mode
    monkeypatch.setattr(B._Run, "dq_mode", lambda self, zeta: modes.append(orig(self, zeta))
                        or modes[-1])
    a = run_bpf(p, particles=3000, seed=2)
    assert sum(a.meta["tempering_stages"]) > 0 and 1 in modes and 2 in modes
    monkeypatch.setattr(B._Run, "dq_mode", lambda self, zeta: 0)
    b = run_bpf(p, particles=3000, seed=2)
    assert a.meta["tempering_stages"] == b.meta["tempering_stages"]
    for key in ("q", "omega_rad_s", "cov", "n_eff"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key), err_msg=key)


def test_bracketed_temper_solver():
    """The bracketed root finder (octave bisection, then Illinois regula falsi; Dowell &
    Jarratt 1971) returns a tempering exponent whose N_eff is at or above the target and within
    0.1 % of φ of the root (Oudjane & Musso 2000: the largest φ keeping N_eff at the target),
    with fewer N_eff evaluations than the 24-step bisection; the option is validated and runs
    on the numba backend only."""
    rng = np.random.default_rng(5)
    N = 20000
    logw = np.full(N, -np.log(N))
    ll = -0.5 * (rng.normal(size=N) * 40.0) ** 2
    target = 0.5 * N
    phi = CP.temper_exponent_bracketed(logw, ll, 1.0, target, 1e-3, 40)
    assert CP.ess_tempered(logw, ll, phi) >= target
    assert CP.ess_tempered(logw, ll, phi * (1.0 + 2e-3)) < target
    ref = CP.temper_exponent(logw, ll, 1.0, target, 40)
    assert abs(phi - ref) <= 1e-3 * ref
    assert CP.temper_exponent_bracketed(logw, np.full(N, -np.inf), 1.0, target, 1e-3, 40) == 0.0
    with pytest.raises(ValueError):
        BPFConfig(temper_solver="newton")
    # the filter with either solver converges on the synthetic case (σθ = 10°, 40 epochs;
    # measured: final per-axis errors ≤ 1.22° (bisection) and ≤ 1.00° (bracketed), seeds 0–3)
    p = build_problem(make_curve(n=40, seed=4), seed=1, sigma_theta_deg=10.0)
    a = run_bpf(p, particles=2000, seed=0, temper_solver="bracketed")
    assert sum(a.meta["tempering_stages"]) > 0
    assert a.meta["bpf"]["temper_solver"] == "bracketed"
    assert np.max(np.abs(a.att_error_deg[-1])) < 3.0
    from lightcurve.filters import run_bpf_numpy
    with pytest.raises(NotImplementedError):
        run_bpf_numpy(p, particles=500, seed=2, temper_solver="bracketed")
