"""Study files, seeds, metrics and the traffic-light rule (no filter runs; fast)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lightcurve.errors import InputError
from lightcurve.studies.metrics import (cell_summary, outside_3sigma, rss_envelope,
                                        traffic_light)
from lightcurve.studies.study import Cell, load_study, run_seeds


def test_load_study_grid_and_seeds(study_file):
    s = load_study(study_file)
    assert [c.filter for c in s.cells] == ["ukf", "mekf"]
    assert s.runs == 3 and s.seed == 7
    tasks = s.tasks()
    assert len(tasks) == 6 and len({t.run_id for t in tasks}) == 6
    # common random numbers: the simulation seed depends on (dynamics, sites, r, run) only,
    # so both filters see the same lightcurve of run i; the filter seeds differ
    a = {(t.cell.filter, t.run): t for t in tasks}
    for i in range(3):
        assert a["ukf", i].sim_seed == a["mekf", i].sim_seed
        assert a["ukf", i].filter_seed != a["mekf", i].filter_seed
    assert len({a["ukf", i].sim_seed for i in range(3)}) == 3
    # seeds are a pure function of (study seed, cell, run): recomputing gives the same numbers,
    # another study seed gives others
    c = s.cells[0]
    assert run_seeds(7, c, 2) == run_seeds(7, c, 2) == (a["ukf", 2].sim_seed, a["ukf", 2].filter_seed)
    assert run_seeds(8, c, 2)[0] != run_seeds(7, c, 2)[0]
    assert all(0 <= x < 2**63 for t in tasks for x in (t.sim_seed, t.filter_seed))
    # the hash covers the scenario texts: editing a scenario changes it
    h = s.hash
    f = study_file.parent / "tiny-controlled-1site.toml"
    f.write_text(f.read_text().replace("acs_sigma_deg = 0.1", "acs_sigma_deg = 0.2"))
    assert load_study(study_file).hash != h


def test_cell_key_is_canonical():
    c1 = Cell("ukf", "controlled", 1, 3.0, 0.02, 1.0)
    c2 = Cell("ukf", "controlled", 1, 3.0, 0.02, 10.0)
    assert c1.key == ("filter=ukf|dynamics=controlled|sites=1|sigma_theta_deg=3.0|"
                      "sigma_omega_deg_s=0.02|r_percent=1.0|reflection=none")
    assert c1.tag != c2.tag and c1.scenario_key != c2.scenario_key


def test_reflection_models_accepted_unknown_refused(tmp_path, make_study):
    # the grid accepts exactly the filters' reflection choices (not only "none")
    from lightcurve.filters.reflection import REFLECTION_CHOICES

    p = make_study(tmp_path, reflection=["none", "model1"])
    st = load_study(p)
    assert [c.reflection for c in st.cells] == ["none", "model1"] * 2
    p = make_study(tmp_path, reflection=["lambert?"])
    with pytest.raises(InputError, match="grid.reflection") as ei:
        load_study(p)
    assert all(m in str(ei.value) for m in REFLECTION_CHOICES)


@pytest.mark.parametrize("bad, field", [
    ('filter = ["kf"]', "grid.filter"),
    ('sigma_theta_deg = [-1.0]', "grid.sigma_theta_deg"),
    ('sites = [2]', "study.scenario"),  # no 2-site file next to the study
])
def test_bad_study_entries(tmp_path, make_study, bad, field):
    p = make_study(tmp_path)
    key = bad.split(" =")[0]
    lines = [bad if ln.startswith(key + " =") else ln for ln in p.read_text().splitlines()]
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as ei:
        load_study(p)
    assert field in str(ei.value) and str(p.name) in str(ei.value)


def test_dynamics_mismatch_refused(tmp_path, make_study):
    p = make_study(tmp_path)
    # the template points both dynamics at the controlled file
    p.write_text(p.read_text().replace('"tiny-{dynamics}-{sites}site.toml"',
                                       '"tiny-controlled-{sites}site.toml"')
                 .replace('dynamics = ["controlled"]', 'dynamics = ["controlled", "uncontrolled"]'))
    with pytest.raises(InputError, match="needs 'uncontrolled'"):
        load_study(p)


def test_traffic_light_rule():
    # Bernard (2021) fig. 9.4 legend: red if > 10 runs outside for any component; yellow for
    # 6-9 or for two or more components with exactly 5; green otherwise
    assert traffic_light([0] * 6) == "green"
    assert traffic_light([5, 0, 0, 0, 0, 0]) == "green"
    assert traffic_light([5, 4, 4, 4, 4, 4]) == "green"
    assert traffic_light([5, 5, 0, 0, 0, 0]) == "yellow"
    assert traffic_light([0, 0, 6, 0, 0, 0]) == "yellow"
    assert traffic_light([0, 0, 0, 0, 0, 9]) == "yellow"
    assert traffic_light([0, 0, 0, 0, 0, 11]) == "red"
    assert traffic_light([100, 0, 0, 0, 0, 0]) == "red"


def test_outside_3sigma_matches_direct_check():
    rng = np.random.default_rng(3)
    for _ in range(50):
        ea, sa = rng.normal(size=3), rng.uniform(0.1, 1, 3)
        ew, sw = rng.normal(size=3) * 1e-3, rng.uniform(1e-4, 1e-3, 3)
        got = outside_3sigma(ea, sa, ew, sw)
        want = [abs(ea[i]) > 3 * sa[i] for i in range(3)] + [abs(ew[i]) > 3 * sw[i] for i in range(3)]
        assert got.tolist() == want
    # NaN error or bound counts as outside
    assert outside_3sigma([np.nan, 0, 0], [1, 1, 1], [0, 0, 0], [1, np.nan, 1]).tolist() == \
        [True, False, False, False, True, False]


def test_cell_summary_counts_and_percentiles():
    runs = [{"outside": [1, 0, 0, 0, 0, 1], "rss_att_deg": float(i), "rss_omega_deg_s": 0.0,
             "diverged": False, "runtime_s": 0.1} for i in range(1, 21)]
    c = cell_summary({"filter": "ukf"}, runs, failures=2)
    assert c["outside_3sigma"] == [20, 0, 0, 0, 0, 20] and c["color"] == "red"
    assert c["runs"] == 20 and c["failures"] == 2
    # numpy linear-interpolation percentiles of 1..20: median 10.5, p95 = 1 + 0.95*19
    assert c["rss_att_deg_median"] == pytest.approx(10.5)
    assert c["rss_att_deg_p95"] == pytest.approx(19.05)
    json.dumps(c)  # JSON-ready


def test_rss_envelope_percentiles():
    t = np.linspace(0, 10, 11)
    curves = [np.full(11, float(k)) for k in range(101)]  # constant curves 0..100
    g, p50, p95, p5 = rss_envelope([t] * 101, curves, n_grid=5)
    assert g[0] == 0 and g[-1] == 10
    assert np.allclose(p50, 50) and np.allclose(p95, 95) and np.allclose(p5, 5)


def test_filter_eta_option_reaches_the_filter_only(tmp_path, make_study):
    # [options] eta_sigma_deg_s2 sets the filters' process noise (ProblemConfig.eta_sigma_deg_s2)
    # and leaves the simulated truth alone: the run equals a direct invert() of the same
    # simulated lightcurve with that η, and differs from the study without the option
    from lightcurve.filters import invert
    from lightcurve.studies.runner import _lightcurve, execute_task

    p = make_study(tmp_path, filters=("mekf",), dynamics=("uncontrolled",), runs=1)
    base = load_study(p)
    p.write_text(p.read_text() + "[options]\neta_sigma_deg_s2 = 0.05\n")
    st = load_study(p)
    assert st.options["eta_sigma_deg_s2"] == 0.05 and "eta_sigma_deg_s2" not in base.options
    t, t0 = st.tasks(1)[0], base.tasks(1)[0]
    assert (t.sim_seed, t.filter_seed) == (t0.sim_seed, t0.filter_seed)
    r, r0 = execute_task(t), execute_task(t0)
    assert r["status"] == r0["status"] == "ok"
    lc = _lightcurve(t.scenario_text, t.scenario_file, 1.0, int(t.sim_seed))
    est = invert(lc, "mekf", seed=int(t.filter_seed), sigma_theta_deg=3.0,
                 sigma_omega_deg_s=0.02, eta_sigma_deg_s2=0.05)
    np.testing.assert_array_equal(r["omega_sigma_rad_s"], est.omega_sigma_rad_s)
    # η = 0.05 deg/s^1.5 over 60 s adds σ_η² T ≈ (0.39 deg/s)² of rate variance per axis (before
    # any update) against the 0.02 deg/s start: the final rate σ must exceed the scenario-η run's
    assert np.all(r["omega_sigma_rad_s"][-1] > 2.0 * r0["omega_sigma_rad_s"][-1])
    p.write_text(p.read_text().replace("eta_sigma_deg_s2 = 0.05", "eta_sigma_deg_s2 = -1.0"))
    with pytest.raises(InputError, match="options.eta_sigma_deg_s2"):
        load_study(p)


def test_filter_drift_horizon_sizes_eta_from_the_scenario_drift(tmp_path, make_study):
    # [options] filter_drift_horizon_s = T: the filters' η is d·√(3/T³) from the scenario's
    # drift_deg_per_orbit d (Bernard §9.2.4 sizes it over one orbit; eta_sigma_from_drift) —
    # the run equals the study with eta_sigma_deg_s2 set to that number by hand
    from lightcurve.studies.runner import execute_task

    p = make_study(tmp_path, filters=("mekf",), dynamics=("uncontrolled",), runs=1)
    scen = tmp_path / "tiny-uncontrolled-1site.toml"
    scen.write_text(scen.read_text().replace('torques = ["gravity_gradient"]',
                                             'torques = ["gravity_gradient"]\n'
                                             "drift_deg_per_orbit = 10.0"))
    text = p.read_text()
    p.write_text(text + "[options]\nfilter_drift_horizon_s = 60.0\n")
    st = load_study(p)
    eta = float(10.0 * np.sqrt(3.0 / 60.0 ** 3))   # 0.0373 deg/s^1.5, by hand
    p.write_text(text + f"[options]\neta_sigma_deg_s2 = {eta!r}\n")
    ref = load_study(p)
    r, r_ref = execute_task(st.tasks(1)[0]), execute_task(ref.tasks(1)[0])
    assert r["status"] == r_ref["status"] == "ok"
    np.testing.assert_array_equal(r["omega_sigma_rad_s"], r_ref["omega_sigma_rad_s"])
    np.testing.assert_array_equal(r["att_error_deg"], r_ref["att_error_deg"])
    # both options at once, and a scenario that gives η instead of a drift, are refused
    p.write_text(text + f"[options]\neta_sigma_deg_s2 = {eta!r}\nfilter_drift_horizon_s = 60.0\n")
    with pytest.raises(InputError, match="options.filter_drift_horizon_s"):
        load_study(p)
    scen.write_text(scen.read_text().replace("drift_deg_per_orbit = 10.0", ""))
    p.write_text(text + "[options]\nfilter_drift_horizon_s = 60.0\n")
    with pytest.raises(InputError, match="attitude.drift_deg_per_orbit"):
        load_study(p)


def test_hide_glints_option_hides_the_spike_epochs_from_the_filters_only(tmp_path, make_study):
    # [options] hide_glints_mag (diagnostic; Bernard §9.4.5: the uncontrolled fast-spinning
    # curves lack the controlled ones' large spikes): the filters run on the epochs whose
    # noise-free magnitude is not more than that many mag brighter than the median of the
    # nearby epochs (selected here by hand), with the study's seeds; the truth is unchanged
    from lightcurve.filters import invert
    from lightcurve.studies.runner import _lightcurve, execute_task

    p = make_study(tmp_path, filters=("mekf",), dynamics=("uncontrolled",), runs=1)
    text = p.read_text()
    p.write_text(text + "[options]\nhide_glints_mag = 2.0\n")
    st = load_study(p)
    t = st.tasks(1)[0]
    lc = _lightcurve(t.scenario_text, t.scenario_file, 1.0, int(t.sim_seed))
    m = lc.truth_mag   # one site: the median of the epochs within ±4 of each epoch
    keep = [k for k in range(len(m)) if not m[k] < np.median(m[max(0, k - 4):k + 5]) - 2.0]
    assert len(lc) == 13 and 0 not in keep and len(keep) >= 10  # the IC's glint at t = 0 (§9.3.3)
    r = execute_task(t)
    assert r["status"] == "ok"
    np.testing.assert_array_equal(r["t"], lc.t[keep])
    est = invert(lc.subset(keep), "mekf", seed=int(t.filter_seed), sigma_theta_deg=3.0,
                 sigma_omega_deg_s=0.02)
    np.testing.assert_array_equal(r["att_error_deg"], est.att_error_deg)
    for bad in ("0.0", "-1.0", "31.0"):
        p.write_text(text + f"[options]\nhide_glints_mag = {bad}\n")
        with pytest.raises(InputError, match="options.hide_glints_mag"):
            load_study(p)
    # hide_glints_after_s: only with hide_glints_mag, and not negative
    for opts in ("hide_glints_after_s = 0.0", "hide_glints_mag = 2.0\nhide_glints_after_s = -1.0"):
        p.write_text(text + f"[options]\n{opts}\n")
        with pytest.raises(InputError, match="options.hide_glints_after_s"):
            load_study(p)
    p.write_text(text + "[options]\nhide_glints_mag = 2.0\nhide_glints_after_s = 0.0\n")
    t = load_study(p).tasks(1)[0]
    r = execute_task(t)   # the glint at t = 0 is seen now, the rest as before
    np.testing.assert_array_equal(r["t"], lc.t[sorted(set(keep) | {0})])


def test_hide_glints_finds_spikes_per_site_and_not_a_pass_trend():
    # a made-up two-site curve: site 0 brightens steadily by 0.3 mag per epoch (a pass) and has
    # one spike 5 mag above its neighbours; site 1 is flat at 12 mag with spikes at its first
    # and its last epoch (the window is cut at the ends) and a 1.5 mag bump that stays
    from dataclasses import dataclass

    from lightcurve.studies.runner import hide_glints

    @dataclass
    class Curve:
        truth_mag: np.ndarray
        site: np.ndarray
        kept: np.ndarray = None
        t: np.ndarray = None

        def subset(self, mask):
            return Curve(self.truth_mag[mask], self.site[mask], np.asarray(mask))

    m0 = 15.0 - 0.3 * np.arange(20)
    m0[7] -= 5.0
    m1 = np.full(12, 12.0)
    m1[[0, 11]] = 8.0
    m1[5] = 10.5
    mag = np.empty(32)
    site = np.empty(32, int)
    mag[:24:2], site[:24:2] = m1, 1           # interleaved in time with site 0
    mag[1:24:2], site[1:24:2] = m0[:12], 0
    mag[24:], site[24:] = m0[12:], 0
    out = hide_glints(Curve(mag, site), 2.0)
    assert np.flatnonzero(~out.kept).tolist() == [0, 15, 22]  # site 1's ends, site 0's spike
    assert hide_glints(Curve(mag, site), 6.0).kept.all()       # no spike of 6 mag
    # hide_glints_after_s: only the spikes later than that after the first epoch (5 s cadence,
    # starting at t = 100 s): after 0 s keeps the first epoch's, after 75 s also the one at 175 s
    t = 100.0 + 5.0 * np.arange(32)
    out = hide_glints(Curve(mag, site, t=t), 2.0, after_s=0.0)
    assert np.flatnonzero(~out.kept).tolist() == [15, 22]
    out = hide_glints(Curve(mag, site, t=t), 2.0, after_s=75.0)
    assert np.flatnonzero(~out.kept).tolist() == [22]
