"""O'Keefe (2015) tables 5.1-5.2 in the thesis's set-up (lightcurve.css.fault_tables)."""

import json

import numpy as np
import pytest


def test_thesis_detector_values_from_the_text():
    # §5.2: "thresholds of 3.0, 1.2, and 1.2 are used for the 1°×1.25°, 5°×5°, and 10°×10°
    # albedo data sets"; fig. 5.3: "100 sample averaged NIS"; tables 5.1-5.2: CSS 1 fails at
    # 1950 s
    from lightcurve.css.fault_tables import thesis_detector
    from lightcurve.css.okeefe2015 import FAULT

    assert [thesis_detector(g).limit() for g in ("1p25x1", "5x5", "10x10")] == [3.0, 1.2, 1.2]
    assert thesis_detector("5x5").window == 100 and thesis_detector("5x5").t_start_s == 0.0
    assert FAULT["sensor"] == 0 and FAULT["t_fail_s"] == 1950.0


def test_averaged_nis_needs_a_full_window_and_a_new_value():
    from lightcurve.css.fault import AveragedNISDetector

    d = AveragedNISDetector(window=3, threshold=2.0, t_start_s=0.0)
    nis = np.array([[5.0], [np.nan], [5.0], [5.0], [np.nan], [0.1], [0.1], [0.1]])
    avg = d.averages(nis)[:, 0]
    # windows: (5,5,5) at k=3; (5,5,0.1) at k=5; (5,0.1,0.1) at 6; (0.1,0.1,0.1) at 7
    assert np.isnan(avg[:3]).all() and np.isnan(avg[4])
    assert avg[3] == pytest.approx(5.0) and avg[5] == pytest.approx(10.1 / 3)
    assert avg[6] == pytest.approx(5.2 / 3) and avg[7] == pytest.approx(0.1)
    assert d.flags(np.arange(8.0), nis)[:, 0].tolist() == [False, False, False, True, False,
                                                           True, False, False]


def test_thesis_noise_floor_on_the_prediction_exposes_an_off_sensor():
    """§4.2 drops measurements below the noise floor, but §5.2.1 flags a failed sensor "once
    the expected observations ... rise above the noise floor": with the floor on the
    predicted output (the thesis variant) or on either output, a sensor that reads 0 while
    predicted lit is evaluated, and its innovations are many σ; with the measured output
    alone it is never evaluated."""
    from dataclasses import replace

    from lightcurve.css.calibration import (run_calibration, simulate_thesis_calibration_case,
                                            thesis_filter_setup)
    from lightcurve.css.fault import inject_fault, sensor_nis

    case = simulate_thesis_calibration_case(5, duration_s=240.0, albedo="builtin")
    prm, alb = thesis_filter_setup("reduced")
    assert prm.floor_rule == "predicted"
    t_fail = 120.0
    after = case.t >= t_fail
    lit_before = np.sum(case.Y[~after] > 0.4, axis=0)
    lit_after = np.sum(case.Y[after] > 0.3, axis=0)
    s = int(np.argmax(np.minimum(lit_before, lit_after)))
    assert lit_before[s] > 0 and lit_after[s] > 20
    Y = inject_fault(case.Y, case.t, s, "off", t_fail)

    def nis_of(p):
        r = run_calibration(case.css_nominal, case.t, Y, case.gyro, case.sun_N, case.lit,
                            case.r_I_m, case.epoch_utc, params=p, albedo=alb,
                            q_star=case.q_star, star_valid=case.star_valid)
        return sensor_nis(r.innov, r.innov_var)

    on = nis_of(replace(prm, floor_rule="either"))[after, s]
    off = nis_of(replace(prm, floor_rule="measured"))[after, s]
    pred = nis_of(prm)[after, s]
    assert np.isnan(off).all()
    v = on[np.isfinite(on)]
    assert v.size >= 5 and np.median(v[:5]) > 25.0   # 5σ innovations at least
    # the predicted-output rule evaluates the off sensor too: at the same first samples
    assert np.array_equal(np.isfinite(pred)[:20], np.isfinite(on)[:20])


def _rec(init, false, detected, ttd=None):
    return {"initialised": {"off": init},
            "thesis": {"5x5": {"off": {"false": false, "detected": detected, "ttd_s": ttd,
                                       "ttd_eval_s": ttd, "css1_max_avg": 9.0,
                                       "healthy_max_avg": [0.5] * (sum(init[1:]))}}}}


def test_summary_counts_like_the_text_under_tables_5_1_5_2():
    # false detections: reported failures among the initialised sensors of all runs (CSS 1
    # before the failure counted, after it not); correct: runs with CSS 1 initialised
    from lightcurve.css.fault_tables import summarise

    runs = [_rec([True, True, False], [1], True, 4.0),      # CSS 2 false, CSS 1 caught
            _rec([False, True, True], [], False),            # CSS 1 never initialised
            _rec([True, True, True], [0, 2], False)]         # CSS 1 early flag, CSS 3 false
    t = summarise(runs, grids=("5x5",), modes=("off",), variants=("thesis",))
    r = t["thesis"]["5x5"]["off"]
    assert (r["false"], r["false_total"], r["correct"], r["total"]) == (3, 7, 1, 2)
    assert r["ttd_s"]["p50"] == 4.0 and t["thesis"]["5x5"]["nis_healthy"] == [0.5] * 5


def test_cli_table_options_are_checked_and_the_generator_reads_the_output(tmp_path, capsys):
    """``--window`` belongs to our own experiment: with the thesis's tables it is a usage
    error (exit 2, one line, nothing written). A summary file feeds the reproduction
    generator, whose table row shows the thesis's numbers beside ours."""
    from lightcurve.cli import main
    from lightcurve.studies.reproduction import css_section

    out = tmp_path / "t.json"
    assert main(["css", "faults", "--experiment", "table5_1", "--window", "10",
                 "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--window" in err[0] and "ours" in err[0]
    assert not out.exists()
    assert main(["css", "faults", "--plot"]) == 2
    from lightcurve.css.okeefe2015 import THESIS_RESULTS

    row = {"false": 2, "false_total": 800, "correct": 90, "total": 100,
           "ttd_s": {"p50": 12.0}, "ttd_eval_s": {"p50": 1.5},
           "css1_max_avg": {"p10": 20.0, "p50": 40.0}, "nis_failed": []}
    summ = {"experiment": "table5_2", "controlled": True, "runs": 100, "seed": 0,
            "grids": ["1p25x1"], "modes": ["off", "stuck", "random"], "variants": ["thesis"],
            "detectors": {"thesis": {"1p25x1": {"window": 100, "threshold": 3.0}}},
            "thesis_results": THESIS_RESULTS["table5_2"],
            "tables": {"thesis": {"1p25x1": {"off": row, "stuck": {**row, "correct": 5},
                                             "random": row, "nis_healthy": [],
                                             "healthy_max_avg": {"p50": 1.0, "p99": 2.5}}}}}
    out.write_text(json.dumps(summ))
    txt = css_section([], faults=[out])
    assert ("| 1°×1.25° | off | 1/2427 (0.04 %) | 489/489 (100.00 %) | 2/800 (0.25 %) | "
            "90/100 (90.00 %) | 12.0 / 1.5 |") in txt
    assert "stuck failures nearly undetectable (Table 5.2: 0–10 %): ours 1°×1.25° 5 %" in txt
    assert "| thesis | 1°×1.25° | 3.00 | 1.00 / 2.50 | 20.00 / 40.00 |" in txt
    # the robust variant of the same runs, from a second output, is merged beside it; a
    # second output from other runs is refused
    rob = tmp_path / "r.json"
    rsum = {**summ, "variants": ["robust"],
            "tables": {"robust": {"1p25x1": {m: {**row, "false": 7} for m in
                                             ("off", "stuck", "random")} | {
                "nis_healthy": [], "healthy_max_avg": {"p50": 1.0, "p99": 2.0}}}},
            "detectors": {"robust": {"threshold": 2.3}}}
    rob.write_text(json.dumps(rsum))
    txt2 = css_section([], faults=[out, rob])
    assert ("90/100 (90.00 %) | 12.0 / 1.5 | 7/800 (0.88 %) | 90/100 (90.00 %) | 12.0 / 1.5 |"
            in txt2)
    other = tmp_path / "o.json"
    other.write_text(json.dumps({**rsum, "runs": 50}))
    from lightcurve.errors import InputError

    with pytest.raises(InputError, match="runs"):
        css_section([], faults=[out, other])
    # an ablation of the thesis filter (same runs and seed) is shown against the table
    abl = tmp_path / "a.json"
    summ["thesis_filter"] = {"skip_in_shadow": True}
    summ["tables"]["thesis"]["1p25x1"]["stuck"] = {**row, "correct": 1}
    abl.write_text(json.dumps(summ))
    txt = css_section([], faults=[out, abl])
    assert ("| table5_2 | `skip_in_shadow = True` | 100 | 1°×1.25° | stuck | 2/800 (0.25 %) → "
            "2/800 (0.25 %) | 5/100 (5.00 %) → 1/100 (1.00 %) | 12.0 → 12.0 |") in txt
    # an ablation of fewer runs is shown against the thesis-variant output of those runs,
    # which is not merged into the table; without that ablation it is refused
    base50 = tmp_path / "b50.json"
    base50.write_text(json.dumps({**{k: v for k, v in summ.items() if k != "thesis_filter"},
                                  "runs": 50, "tables": {"thesis": {"1p25x1": {
                                      **summ["tables"]["thesis"]["1p25x1"],
                                      "stuck": {**row, "correct": 3, "total": 48}}}}}))
    abl50 = tmp_path / "a50.json"
    abl50.write_text(json.dumps({**summ, "runs": 50}))
    txt = css_section([], faults=[out, base50, abl50])
    assert ("| table5_2 | `skip_in_shadow = True` | 50 | 1°×1.25° | stuck | 2/800 (0.25 %) → "
            "2/800 (0.25 %) | 3/48 (6.25 %) → 1/100 (1.00 %) | 12.0 → 12.0 |") in txt
    assert "100 runs (thesis: 500), seed 0." in txt and "50 runs (thesis" not in txt
    with pytest.raises(InputError, match="runs"):
        css_section([], faults=[out, base50, abl])


def test_thesis_filter_ablation_switches():
    """The two switches the fault-table ablations use, off in the thesis variant: with
    ``skip_in_shadow`` no sensor is evaluated at a sample the truth marks as shadow (where
    the floor on the measured output would admit noise above it); with a
    FOV-edge margin of 0.2 (cosine) no evaluated sample has the Sun within ≈ 0.15 of the
    60° cut-off (cos 0.5) — the estimated normals are within ≈ 3° of the true ones here."""
    from dataclasses import replace

    from lightcurve.css.calibration import (run_calibration, simulate_thesis_calibration_case,
                                            thesis_filter_setup)
    from lightcurve.css.fault import sensor_nis
    from lightcurve.rotations import quat_rotate

    case = simulate_thesis_calibration_case(5, duration_s=240.0, albedo="builtin")
    prm, alb = thesis_filter_setup("reduced")
    assert prm.fov_edge_margin == 0.0 and not prm.skip_in_shadow
    lit = case.lit.copy()
    shade = (case.t > 100.0) & (case.t < 140.0)
    lit[shade] = 0.0

    def nis_of(p):
        r = run_calibration(case.css_nominal, case.t, case.Y, case.gyro, case.sun_N, lit,
                            case.r_I_m, case.epoch_utc, params=p, albedo=alb,
                            q_star=case.q_star, star_valid=case.star_valid)
        return sensor_nis(r.innov, r.innov_var)

    # with the floor on the measured output the thesis update runs in the shadow too
    pe = replace(prm, floor_rule="either")
    base = nis_of(pe)
    assert np.isfinite(base[shade]).any()
    sk = nis_of(replace(pe, skip_in_shadow=True))
    assert not np.isfinite(sk[shade]).any() and np.isfinite(sk[~shade]).any()
    ed = nis_of(replace(prm, fov_edge_margin=0.2))
    true_css = case.css_nominal.with_errors(scale_individual=case.scale_true,
                                            misalignment_rad=case.misalignment_true)
    c = quat_rotate(case.q_true, case.sun_N) @ true_css.normals.T
    ev = np.isfinite(ed) & (lit[:, None] > 0)
    near = np.abs(c - 0.5) < 0.15
    assert ev.sum() > 50 and not (ev & near).any()
    assert (np.isfinite(base) & (lit[:, None] > 0) & near).any()   # the margin removed some


def test_fig_5_5_plot_is_written(tmp_path):
    from lightcurve.css.fault_tables import plot_fault_nis, summarise

    runs = [_rec([True, True, True], [], True, 2.0), _rec([True, True, False], [1], True, 3.0)]
    t = summarise(runs, grids=("5x5",), modes=("off",), variants=("thesis",))
    s = {"experiment": "table5_1", "runs": 2, "variants": ["thesis"], "grids": ["5x5"],
         "modes": ["off"], "tables": t,
         "detectors": {"thesis": {"5x5": {"threshold": 1.2, "window": 100}}}}
    png = tmp_path / "f.png"
    plot_fault_nis(s, png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_tables_4_section_shows_both_variants_and_the_quoted_means(tmp_path):
    # §4.4.2 quotes the mean misalignment 3σ of the Monte Carlo (cube 1.66°/0.93°, dual
    # pyramid 1.05°/0.9°): printed beside ours; the robust filters' rows follow the thesis's
    from lightcurve.css.okeefe2015 import THESIS_RESULTS
    from lightcurve.studies.reproduction import css_section

    e = {"c": [0.02, 0.004], "theta_deg": [1.0, 0.6], "phi_deg": [1.5, 0.5],
         "mean_theta_phi_deg": [1.1, 0.8], "inside_3sigma": 0.9}
    b = {"seed": 4, "runs": 3,
         "thesis": {k: THESIS_RESULTS[k] for k in ("table4_1", "table4_2", "table4_3")},
         "dual_pyramid_case": {"1p25x1": e}, "dual_pyramid_case_robust": {"1p25x1": e},
         "dual_pyramid_mc_mean": {"1p25x1": e}, "dual_pyramid_mc_mean_robust": {"1p25x1": e}}
    f = tmp_path / "t4.json"
    f.write_text(json.dumps(b))
    txt = css_section([], tables4=f)
    assert "| 4.1 | full, 1°×1.25° | 0.018/0.0036 / 0.02/0.004 |" in txt
    assert "| 4.1 | full, 1°×1.25° — robust variant | 0.018/0.0036 / 0.02/0.004 |" in txt
    assert "| dual pyramid | full, 1°×1.25° | 0.02/0.004 | 1/0.6 | 1.5/0.5 | 1.05 / 0.9 / 1.1 / 0.8 |" in txt
    assert "Mean over 3 Monte Carlo cases" in txt


def test_one_run_of_table_5_1_end_to_end():
    # the whole path on a short run (failure at 1950 s, 150 s after it): both variants on the
    # same truth, the counts tied to the sensors initialised in that run
    from lightcurve.css.fault_tables import fault_table_run, fault_table_study

    kw = dict(grids=("10x10",), modes=("random",), duration_s=2100.0)
    o = fault_table_study("table5_1", 1, seed=3, **kw)
    r = fault_table_run(np.random.SeedSequence([3, 0]), **kw)
    n_init = sum(r["initialised"]["random"])
    for v in ("thesis", "robust"):
        row = o["tables"][v]["10x10"]["random"]
        assert row["false_total"] == n_init
        assert row["total"] == int(r["initialised"]["random"][0])
        assert row["false"] == len(r[v]["10x10"]["random"]["false"])
    assert o["detectors"]["thesis"]["10x10"] == {"window": 100, "threshold": 1.2}
    assert o["variants"] == ["thesis", "robust"] and o["failed_sensor"] == 1
    assert o["workers"] == 1 and o["cpu_s_per_run"] > 0.0


def test_generator_merges_a_table_computed_in_parts_by_grid(tmp_path):
    """Outputs of one table from the same runs with other ``--grids`` are merged (grids in
    the thesis's order); a (variant, grid) given twice, or a variant left without a grid that
    another part has, is refused with the file and field named."""
    from lightcurve.css.okeefe2015 import THESIS_RESULTS
    from lightcurve.errors import InputError
    from lightcurve.studies.reproduction import css_section

    def part(variant, grid, false, cpu_s):
        row = {"false": false, "false_total": 800, "correct": 90, "total": 100,
               "ttd_s": {"p50": 12.0}, "ttd_eval_s": {"p50": 1.5},
               "css1_max_avg": {"p10": 20.0, "p50": 40.0}, "nis_failed": []}
        det = ({"thesis": {grid: {"window": 100, "threshold": 1.2}}} if variant == "thesis"
               else {"robust": {"threshold": 2.3}})
        return {"experiment": "table5_1", "controlled": False, "runs": 100, "seed": 0,
                "grids": [grid], "modes": ["off", "stuck", "random"], "variants": [variant],
                "detectors": det,
                "thesis_results": {grid: THESIS_RESULTS["table5_1"][grid]},
                "cpu_s_per_run": cpu_s,
                "tables": {variant: {grid: {m: row for m in ("off", "stuck", "random")}
                                     | {"nis_healthy": [],
                                        "healthy_max_avg": {"p50": 1.0, "p99": 2.0}}}}}

    files = {}
    for v, g, n, c in (("thesis", "5x5", 3, 1.5), ("thesis", "1p25x1", 2, 2.0),
                       ("robust", "1p25x1", 7, 3.0), ("robust", "5x5", 9, 4.0)):
        files[v, g] = tmp_path / f"{v}_{g}.json"
        files[v, g].write_text(json.dumps(part(v, g, n, c)))
    txt = css_section([], faults=list(files.values()))
    rows = [ln for ln in txt.splitlines() if ln.startswith("| 1°×1.25° | off")
            or ln.startswith("| 5°×5° | off")]
    assert len(rows) == 2 and rows[0].startswith("| 1°×1.25°")   # the thesis's grid order
    assert "| 2/800 (0.25 %) |" in rows[0] and "| 7/800 (0.88 %) |" in rows[0]
    assert "| 3/800 (0.38 %) |" in rows[1] and "| 9/800 (1.12 %) |" in rows[1]
    # one run of the merged table costs the parts' sum: 10.5 CPU-s, 100 runs = 8.75 min
    # on 2 cores, 500 = 43.75 min; 30 min on 2 cores = 3600 CPU-s hold 342 runs
    assert ("takes 10.5 CPU-s: 100 runs are 9 min on 2 cores, the thesis's 500 would be "
            "44 min, and 30 min on 2 cores hold 342 runs.") in txt
    with pytest.raises(InputError, match="same variant and grid"):
        css_section([], faults=[files["thesis", "5x5"], files["thesis", "5x5"]])
    with pytest.raises(InputError, match="lacks grids") as ei:
        css_section([], faults=[files["thesis", "5x5"], files["thesis", "1p25x1"],
                                files["robust", "1p25x1"]])
    assert ei.value.field == "grids" and ei.value.value == "5x5"


def test_tables_4_monte_carlo_cases_are_seeded_by_index():
    """Case i of the Tables 4.1-4.3 Monte Carlo (thesis_calibration_monte_carlo) is the
    §4.4 case seeded (seed, i), i from 1, whatever the variant: its table entries equal those
    of the case simulated and filtered directly (the docs name their cases this way)."""
    from lightcurve.css.calibration import (simulate_thesis_calibration_case,
                                            thesis_calibration_monte_carlo,
                                            thesis_calibration_table)

    mc = thesis_calibration_monte_carlo("cube", ("reduced",), 2, seed=7)
    assert set(mc) == {"thesis", "robust"} and len(mc["thesis"]["reduced"]) == 2
    case = simulate_thesis_calibration_case(np.random.SeedSequence([7, 2]), "cube")
    for v in ("thesis", "robust"):
        direct = thesis_calibration_table(case, ("reduced",), variant=v)["reduced"]
        assert mc[v]["reduced"][1] == direct
    assert mc["thesis"]["reduced"][0] != mc["thesis"]["reduced"][1]
