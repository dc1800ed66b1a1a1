"""Published tables (Fig. 9.4, B.1–B.4) as data, the scaled traffic light and the agreement.

* The transcribed tables: spot cells typed here from the text, and the grey / unknown counts
  of each figure (Fig. 9.4 has 2 grey cells; B.3's controlled two-site halves are lost).
* Traffic light: the 100-run rule unchanged at 100 runs; with n runs a count c reads as
  c·100/n (5 runs with 4 diverged is red, not green).
* The Monte Carlo spread of a colour: the vectorised rule is the rule row by row (an
  independent transcription of §9.4.1 in the test); one component's colour probabilities are
  beta-binomial tails (scipy) within a 4.5σ Monte Carlo bound; the agreement's expected and
  self-agreement sums; a summary that predates the spread gets it from its run files.
* A small thesis-variant study: grey cells are not run, every cell carries ``thesis_color``,
  the summary the agreement counts and ``indicative``; the report shows the thesis colour; all
  filters of one run share the initial-estimate seed (§9.3.1), the robust variant does not.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from lightcurve._paths import data_dir
from lightcurve.studies.agreement import agreement, load_thesis_table, order_inversions
from lightcurve.studies.metrics import (COLORS, color_probability, traffic_light,
                                        traffic_lights)
from lightcurve.studies.study import load_study

STUDIES = data_dir("pipelines") / "studies"


def _benchmark(name):
    """The module ``benchmarks/<name>.py`` of the source tree (skip when the tests run from an
    installed package without it)."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benchmarks" / f"{name}.py"
    if not path.is_file():
        pytest.skip("benchmarks/ not beside the tests (installed package)")
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
TABLES = STUDIES / "tables"


def _count(tab, color):
    return sum(1 for v in tab.cells.values() if v == color)


def test_tables_transcribed():
    t94 = load_thesis_table(TABLES / "bernard2021-fig9-4.toml")
    assert t94.figure == "9.4" and len(t94.cells) == 96
    # Fig. 9.4, typed from the text: controlled σω 0.02, 1 %: EKF red, UKF green at 3° one site;
    # UKF yellow at 5°; two sites 10° UKF yellow; controlled σω 0.2, 1 %, one site 10°: grey
    assert t94.color("mekf", "controlled", 1, 3.0, 0.02, 1.0) == "red"
    assert t94.color("ukf", "controlled", 1, 3.0, 0.02, 1.0) == "green"
    assert t94.color("ukf", "controlled", 1, 5.0, 0.02, 1.0) == "yellow"
    assert t94.color("ukf", "controlled", 2, 10.0, 0.02, 1.0) == "yellow"
    assert t94.color("ukf", "controlled", 1, 10.0, 0.2, 1.0) == "grey"
    assert t94.color("mekf", "controlled", 2, 3.0, 0.2, 1.0) == "yellow"
    assert t94.color("ukf", "uncontrolled", 2, 10.0, 0.2, 10.0) == "green"
    assert _count(t94, "grey") == 2 and _count(t94, "unknown") == 0
    # the UKF 10° row of Fig. 9.4: 8 red, 1 grey of 16 cells (counted from the text)
    ukf10 = [v for k, v in t94.cells.items() if k[0] == "ukf" and k[3] == 10.0]
    assert ukf10.count("red") == 8 and ukf10.count("grey") == 1
    grey = {"b1-meo-cubesat": 2, "b2-meo-scaled": 4, "b3-geo-cubesat": 2, "b4-geo-scaled": 6}
    for name, n_grey in grey.items():
        t = load_thesis_table(TABLES / f"bernard2021-fig-{name}.toml")
        assert len(t.cells) == 96 and _count(t, "grey") == n_grey, name
        assert _count(t, "unknown") == (24 if name == "b3-geo-cubesat" else 0), name
    b1 = load_thesis_table(TABLES / "bernard2021-fig-b1-meo-cubesat.toml")
    # B.1 uncontrolled σω 0.02, 10 %: all green; the text's second "0.02" group is σω 0.2
    assert all(b1.color(f, "uncontrolled", s, th, 0.02, 10.0) == "green"
               for f in ("mekf", "ukf") for s in (1, 2) for th in (3.0, 5.0, 10.0))
    assert b1.color("mekf", "uncontrolled", 1, 10.0, 0.2, 10.0) == "yellow"


def test_traffic_light_scales_with_the_run_count():
    # the thesis's rule at 100 runs
    assert traffic_light([5, 4, 0, 0, 0, 0]) == "green"
    assert traffic_light([5, 5, 0, 0, 0, 0]) == "yellow"
    assert traffic_light([0, 10, 0, 0, 0, 0]) == "yellow"
    assert traffic_light([0, 11, 0, 0, 0, 0]) == "red"
    # 5 runs with 4 outside: 80 per 100 -> red (the raw count 4 < 5 would read green)
    assert traffic_light([4, 0, 0, 0, 0, 0], 5) == "red"
    # 10 runs: one outside = 10 per 100 -> yellow; two = 20 -> red; 20 runs: one = 5 -> green,
    # two components with one each -> yellow
    assert traffic_light([1, 0, 0, 0, 0, 0], 10) == "yellow"
    assert traffic_light([2, 0, 0, 0, 0, 0], 10) == "red"
    assert traffic_light([1, 0, 0, 0, 0, 0], 20) == "green"
    assert traffic_light([1, 1, 0, 0, 0, 0], 20) == "yellow"
    assert traffic_light([0] * 6, 1) == "green" and traffic_light([1] + [0] * 5, 1) == "red"


def _rule_100(c):
    """§9.4.1 at 100 runs, transcribed independently: red when more than ten samples are
    outside for any component; yellow when any component has six to nine (ten: yellow here,
    module docstring of metrics) or two or more components have exactly five; else green."""
    if any(x > 10 for x in c):
        return "red"
    if any(6 <= x <= 10 for x in c) or sum(1 for x in c if x == 5) >= 2:
        return "yellow"
    return "green"


def test_traffic_lights_is_the_rule_on_every_row():
    rng = np.random.default_rng(7)
    counts = rng.choice([0, 1, 3, 4, 5, 6, 9, 10, 11, 40], size=(5000, 6),
                        p=[.2, .05, .05, .1, .25, .1, .05, .05, .1, .05])
    got = traffic_lights(counts, 100)
    assert got.shape == (5000,)
    assert [COLORS[i] for i in got] == [_rule_100(c) for c in counts]
    # other run counts: c out of n is read as c·100/n; 1000 runs with 10·c outside is the
    # 100-run colour of c, and a count per 100 that is not an integer never equals five
    assert [COLORS[i] for i in traffic_lights(counts * 10, 1000)] == [_rule_100(c) for c in counts]
    assert COLORS[int(traffic_lights([1, 1, 0, 0, 0, 0], 21))] == "green"
    assert [traffic_light(c, 20) for c in counts[:50]] == \
        [COLORS[i] for i in traffic_lights(counts[:50], 20)]


@pytest.mark.parametrize("k", [3, 8, 14])
def test_color_probability_of_one_component_is_beta_binomial(k):
    # one component with k of R runs outside: the predictive count is BB(100, k, R - k)
    # (Dirichlet weights summed over the k runs are Beta(k, R - k)). 20,000 draws: standard
    # error at most 0.0035; the 4.5σ bound has a two-sided false-alarm rate of 7e-6.
    from scipy.stats import betabinom

    R = 100
    f = np.zeros((R, 6), int)
    f[:k, 0] = 1
    bb = betabinom(100, k, R - k)
    p = color_probability(f, 100, draws=20_000, seed=3)
    assert sum(p.values()) == pytest.approx(1.0)
    assert p["red"] == pytest.approx(bb.sf(10), abs=0.016)
    assert p["yellow"] == pytest.approx(bb.cdf(10) - bb.cdf(5), abs=0.016)
    # the same runs outside in two components: exactly five in both is yellow too
    f[:k, 1] = 1
    p2 = color_probability(f, 100, draws=20_000, seed=3)
    assert p2["yellow"] == pytest.approx(bb.cdf(10) - bb.cdf(4), abs=0.016)
    assert p2["green"] == pytest.approx(bb.cdf(4), abs=0.016)
    # reproducible; no runs outside: green for sure
    assert color_probability(f, 100, draws=500, seed=3) == color_probability(f, 100, draws=500,
                                                                             seed=3)
    assert color_probability(np.zeros((40, 6)), 100, draws=200) == {"green": 1.0, "yellow": 0.0,
                                                                     "red": 0.0}


def test_agreement_counts():
    cells = [dict(filter="mekf", dynamics="controlled", sites=1, sigma_theta_deg=3.0,
                  sigma_omega_deg_s=0.02, r_percent=1.0, runs=100, color="red",
                  thesis_color="red"),
             dict(filter="ukf", dynamics="controlled", sites=1, sigma_theta_deg=3.0,
                  sigma_omega_deg_s=0.02, r_percent=1.0, runs=100, color="yellow",
                  thesis_color="green"),
             dict(filter="ukf", dynamics="controlled", sites=2, sigma_theta_deg=3.0,
                  sigma_omega_deg_s=0.02, r_percent=1.0, runs=100, color="red",
                  thesis_color="unknown"),
             dict(filter="bpf", dynamics="controlled", sites=1, sigma_theta_deg=3.0,
                  sigma_omega_deg_s=0.02, r_percent=1.0, runs=100, color="green",
                  thesis_color=None)]
    a = agreement(cells)
    assert a["compared"] == 2 and a["agree"] == 1
    assert a["by_filter"] == {"mekf": {"compared": 1, "agree": 1},
                              "ukf": {"compared": 1, "agree": 0}}
    assert a["disagree"][0]["thesis_color"] == "green"
    assert "self_agree" not in a     # no colour probabilities: no spread
    # with the spread: Σ P(published colour), Σ Σ P², disagreeing cells with P ≥ 5 %
    cells[0]["color_probability"] = {"green": 0.0, "yellow": 0.2, "red": 0.8}
    cells[1]["color_probability"] = {"green": 0.06, "yellow": 0.5, "red": 0.44}
    a = agreement(cells)
    assert a["expected_agree"] == pytest.approx(0.8 + 0.06)
    assert a["self_agree"] == pytest.approx(0.04 + 0.64 + 0.0036 + 0.25 + 0.1936)
    assert a["within_noise"] == 1 and a["disagree"][0]["thesis_color_probability"] == 0.06
    cells[1]["color_probability"] = {"green": 0.04, "yellow": 0.5, "red": 0.46}
    assert agreement(cells)["within_noise"] == 0


def test_reproduction_gives_old_summaries_their_colour_spread(tmp_path):
    # a summary written before color_probability existed: its spread from the run files
    from lightcurve.studies.reproduction import add_color_spread, load_summaries
    from lightcurve.studies.runner import write_run

    key = dict(filter="ukf", dynamics="controlled", sites=1, sigma_theta_deg=3.0,
               sigma_omega_deg_s=0.02, r_percent=1.0, reflection="none")
    rng = np.random.default_rng(0)
    flags = (rng.random((100, 6)) < 0.07).astype(int)
    from lightcurve.studies.study import Cell

    tag = Cell(**key).tag      # run files are <cell tag>_r<run>.h5
    for i, fl in enumerate(flags):
        write_run(tmp_path, {"run_id": f"{tag}_r{i:05d}", "status": "ok", "error": "", "run": i,
                             "sim_seed": 1, "filter_seed": 2, "wall_s": 0.0, "cell": key,
                             "metrics": {"outside": [int(x) for x in fl]},
                             **{n: np.zeros((1, 3)) for n in ("att_error_deg", "att_sigma_deg",
                                                              "omega_error_rad_s",
                                                              "omega_sigma_rad_s")},
                             "t": np.zeros(1)}, "h")
    counts = flags.sum(axis=0)
    cell = dict(key, runs=100, outside_3sigma=[int(x) for x in counts],
                color=traffic_light(counts), thesis_color="green")
    summ = {"study": "thesis-fig9-4", "runs_per_cell": 100, "cells": [cell],
            "agreement": agreement([cell])}
    (tmp_path / "summary.json").write_text(json.dumps(summ))
    s = load_summaries([tmp_path])["thesis-fig9-4"]
    assert "color_probability" not in s["cells"][0]
    other = dict(key, sites=2)
    add_color_spread(s, keys=[other])          # another cell only: nothing read
    assert "color_probability" not in s["cells"][0]
    add_color_spread(s)
    assert s["cells"][0]["color_probability"] == color_probability(flags, 100)
    a = s["agreement"]
    assert a["expected_agree"] == pytest.approx(s["cells"][0]["color_probability"]["green"])
    assert a["self_agree"] == pytest.approx(sum(v * v for v in
                                                s["cells"][0]["color_probability"].values()))


def _small_study(tmp_path, variant):
    txt = (STUDIES / "thesis-fig9-4.toml").read_text()
    txt = txt.replace('thesis_table = "tables/', f'thesis_table = "{TABLES}/')
    txt = txt.replace('scenario = "../thesis/', f'scenario = "{STUDIES.parent}/thesis/')
    txt = txt.replace('dynamics = ["controlled", "uncontrolled"]', 'dynamics = ["controlled"]')
    txt = txt.replace("sites = [1, 2]", "sites = [1]")
    txt = txt.replace("sigma_theta_deg = [3.0, 5.0, 10.0]", "sigma_theta_deg = [3.0, 10.0]")
    txt = txt.replace("sigma_omega_deg_s = [0.02, 0.2]", "sigma_omega_deg_s = [0.2]")
    txt = txt.replace("r_percent = [1.0, 10.0]", "r_percent = [1.0]")
    txt = txt.replace('variant = "thesis"', f'variant = "{variant}"')
    f = tmp_path / f"small-{variant}.toml"
    f.write_text(txt)
    return load_study(f)


def test_thesis_variant_study_grey_cells_colours_and_shared_initial_estimate(tmp_path, capsys):
    from lightcurve.cli import main
    from lightcurve.studies.runner import run_study

    st = _small_study(tmp_path, "thesis")
    # σθ 10° with σω 0.2, 1 %, one site, controlled is grey in Fig. 9.4: not run
    assert [c.sigma_theta_deg for c in st.cells] == [3.0, 3.0]
    assert len(st.skipped_cells) == 2
    tasks = st.tasks(2)
    by_run = {}
    for t in tasks:
        by_run.setdefault(t.run, set()).add(t.init_seed)
    assert all(len(v) == 1 and None not in v for v in by_run.values())   # shared per run
    assert len({next(iter(v)) for v in by_run.values()}) == 2             # differs per run
    rob = _small_study(tmp_path, "robust")
    assert all(t.init_seed is None for t in rob.tasks(2))
    s = run_study(st, tmp_path / "out", runs=1, workers=1, progress=False)
    assert s["indicative"] and s["variant"] == "thesis" and s["thesis_figure"] == "9.4"
    assert {c["thesis_color"] for c in s["cells"]} == {"red", "green"}   # EKF red, UKF green
    assert s["agreement"]["compared"] == 2 and len(s["not_run_grey"]) == 2
    js = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert all("thesis_color" in c for c in js["cells"])
    # one run per cell: a new 100-run Monte Carlo repeats that run's flags 100 times, so the
    # colour probability is 1 for the colour of the run's counts × 100
    for c in js["cells"]:
        assert c["color_probability"][traffic_light([100 * x for x in c["outside_3sigma"]])] == 1
    a = js["agreement"]
    assert a["self_agree"] == pytest.approx(2.0) and 0 <= a["within_noise"] <= len(a["disagree"])
    html = (tmp_path / "out" / "report.html").read_text()
    assert "thesis: red" in html and "not run" in html and "INDICATIVE" in html
    assert "Monte Carlo spread of the colours" in html and "colour in a new 100-run" in html
    # the command line resumes (nothing left to run) and prints the agreement and the spread
    capsys.readouterr()
    assert main(["compare", str(tmp_path / "small-thesis.toml"), "--runs", "1", "--workers",
                 "1", "-q", "-o", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "run cells agree" in out and "would agree with itself on 2.0 of 2 cells" in out


@pytest.mark.parametrize("name", ["thesis-fig9-4", "thesis-fig-b1-meo-cubesat",
                                  "thesis-fig-b2-meo-scaled", "thesis-fig-b3-geo-cubesat",
                                  "thesis-fig-b4-geo-scaled"])
def test_study_pairs_share_everything_but_the_variant(name):
    a = load_study(STUDIES / f"{name}.toml")
    b = load_study(STUDIES / f"{name}-robust.toml")
    assert a.options["variant"] == "thesis" and b.options["variant"] == "robust"
    assert a.seed == b.seed and a.cells == b.cells and a.runs == b.runs == 100
    assert a.scenario_files == b.scenario_files
    assert len(a.cells) + len(a.skipped_cells) == 96


def test_ablation_options(tmp_path):
    """[options] gate, alpha/beta/kappa, shared_init reach the tasks (the ablations of the
    disagreeing cells switch one of them at a time)."""
    from lightcurve.errors import InputError

    st = _small_study(tmp_path, "thesis")
    txt = st.text.replace('[options]\n', '[options]\ngate = "auto"\nalpha = 0.5\nshared_init = false\n')
    f = tmp_path / "abl.toml"
    f.write_text(txt)
    ab = load_study(f)
    assert ab.options == {"variant": "thesis", "cook_torrance": "thesis", "gate": "auto",
                          "alpha": 0.5, "shared_init": False}
    assert all(t.init_seed is None for t in ab.tasks(1))
    f.write_text(txt.replace('gate = "auto"', 'gate = "sometimes"'))
    with pytest.raises(InputError, match="gate"):
        load_study(f)


@pytest.mark.parametrize("path", sorted((STUDIES / "ablations").glob("thesis-*-ablation-*.toml")),
                         ids=lambda p: p.stem)
def test_ablation_studies_share_the_base_seeds_and_cells(path):
    """An ablation is one switch on the same runs: it loads, keeps its base study's seed, table
    and variant, and runs a subset of the base's cells (so each of its cells has the base's
    simulated lightcurves and initial estimates)."""
    ab = load_study(path)
    stem, label = path.stem.split("-ablation-")
    base = load_study(STUDIES / (stem + ".toml"))
    assert ab.name == path.stem
    # the two switches that are the seed and the variant themselves
    assert (ab.seed != base.seed) == (label == "seeds") and ab.runs == base.runs
    assert ((ab.options.get("variant") != base.options.get("variant"))
            == label.startswith("robust-"))
    assert ab.thesis_table_text == base.thesis_table_text
    assert set(ab.cells) <= set(base.cells) and ab.cells


@pytest.mark.parametrize("path", sorted((STUDIES / "ablations").glob("thesis-*eta-window.toml")),
                         ids=lambda p: p.stem)
def test_eta_window_ablations_size_eta_from_the_section_9_2_4_drift(path):
    """The window-sized η ablations derive the filters' η from each scenario's §9.2.4 drift
    (LEO 2°, MEO 10°, GEO 15° after one orbit; Bernard §9.2.4) reached after the 360 s window
    (§9.3.1): σ_η = d·√(3/360³), computed here by hand."""
    from lightcurve.studies.runner import _filter_eta

    st = load_study(path)
    assert st.options["filter_drift_horizon_s"] == 360.0
    d = {"fig9-4": 2.0, "b1": 10.0, "b2": 10.0, "b3": 15.0, "b4": 15.0}[
        path.stem.split("-")[2] if path.stem.startswith("thesis-fig-") else "fig9-4"]
    for (dyn, ns), f in st.scenario_files.items():
        assert dyn == "uncontrolled"
        eta = _filter_eta(st.scenario_texts[(dyn, ns)], str(f), 360.0)
        assert eta == pytest.approx(d * (3.0 / 360.0 ** 3) ** 0.5, rel=1e-12)


def test_reach_probability_is_poisson_binomial():
    # equal cells: binomial; mixed cells: enumeration of the 2^6 agree/disagree patterns
    import itertools

    from scipy.stats import binom

    from lightcurve.studies.reproduction import _reach_probability

    def cell(p):
        return {"thesis_color": "green", "runs": 100, "color_probability": p}

    s = {"cells": [cell({"green": 0.9, "yellow": 0.1, "red": 0.0})] * 20
         + [dict(cell({"green": 0.5, "yellow": 0.5, "red": 0.0}), thesis_color="grey")]}
    assert _reach_probability(s) == pytest.approx(binom.sf(16, 20, 0.82), rel=1e-12)
    probs = [{"green": a, "yellow": 1 - a, "red": 0.0} for a in (1.0, 0.9, 0.7, 0.5, 0.6, 0.2)]
    q = [a * a + (1 - a) ** 2 for a in (1.0, 0.9, 0.7, 0.5, 0.6, 0.2)]
    want = sum(np.prod([qi if b else 1 - qi for qi, b in zip(q, bits)])
               for bits in itertools.product([0, 1], repeat=6) if sum(bits) >= 6 * 0.85)
    assert _reach_probability({"cells": [cell(p) for p in probs]}) == pytest.approx(want,
                                                                                   rel=1e-12)


def test_order_inversions_of_the_published_tables():
    """Bernard Fig. 9.4 (text lines 2793-2800): three cells have a better colour than the same
    cell with the ten times smaller initial rate error, all of them two-site cells with
    σω = 0.2°/s, read off the text here: EKF controlled 1 % σθ 3° (Yellow; 0.02°/s: Red), UKF
    controlled 1 % σθ 10° (Green; Yellow) and UKF uncontrolled 10 % σθ 10° (Green; Red).
    Figs. B.1-B.4 have none."""
    t94 = load_thesis_table(TABLES / "bernard2021-fig9-4.toml")
    inv = order_inversions(t94.cells)
    assert inv == {
        ("mekf", "controlled", 2, 3.0, 0.2, 1.0): [("mekf", "controlled", 2, 3.0, 0.02, 1.0)],
        ("ukf", "controlled", 2, 10.0, 0.2, 1.0): [("ukf", "controlled", 2, 10.0, 0.02, 1.0)],
        ("ukf", "uncontrolled", 2, 10.0, 0.2, 10.0): [
            ("ukf", "uncontrolled", 2, 10.0, 0.02, 10.0)]}
    for name in ("b1-meo-cubesat", "b2-meo-scaled", "b3-geo-cubesat", "b4-geo-scaled"):
        assert order_inversions(load_thesis_table(TABLES / f"bernard2021-fig-{name}.toml").cells) == {}


def test_order_inversions_rule():
    k = ("ukf", "controlled", 1)
    cells = {k + (3.0, 0.02, 1.0): "red", k + (5.0, 0.02, 1.0): "yellow",    # harder, better
             k + (5.0, 0.2, 1.0): "green", k + (3.0, 0.2, 1.0): "grey",       # grey ignored
             k + (10.0, 0.02, 10.0): "green",                                  # other r
             ("mekf",) + k[1:] + (10.0, 0.2, 1.0): "green",                    # other filter
             ("ukf", "controlled", 2, 10.0, 0.2, 1.0): "green"}                # other sites
    assert order_inversions(cells) == {
        k + (5.0, 0.02, 1.0): [k + (3.0, 0.02, 1.0)],
        k + (5.0, 0.2, 1.0): [k + (3.0, 0.02, 1.0), k + (5.0, 0.02, 1.0)]}
    # equal colours and equal errors are never out of order
    assert order_inversions({k + (3.0, 0.02, 1.0): "red", k + (5.0, 0.2, 1.0): "red"}) == {}



def test_alpha_sweep_study_is_the_base_ukf_cells_with_alpha(tmp_path):
    """benchmarks/bernard_ukf_alpha.py: each α's study is the base study's UKF cells, seeds and
    options with ``alpha`` added, and its table and scenarios are the base's files."""
    mod = _benchmark("bernard_ukf_alpha")
    base_path = STUDIES / "thesis-fig-b1-meo-cubesat.toml"
    base = load_study(base_path)
    f = tmp_path / "sweep.toml"
    f.write_text(mod.variant_text(base_path, 0.25))
    sw = load_study(f)
    assert sw.name == "thesis-fig-b1-meo-cubesat-alpha-0.25" and sw.seed == base.seed
    assert sw.options == dict(base.options, alpha=0.25)
    assert set(sw.cells) == {c for c in base.cells if c.filter == "ukf"} and sw.cells
    assert sw.thesis_table_text == base.thesis_table_text
    assert {k: v.resolve() for k, v in sw.scenario_files.items()} == \
        {k: v.resolve() for k, v in base.scenario_files.items()}
    t0, t1 = list(base.tasks(2)), list(sw.tasks(2))
    seeds = {(t.cell, t.run): (t.sim_seed, t.filter_seed, t.init_seed) for t in t0}
    assert all(seeds[(t.cell, t.run)] == (t.sim_seed, t.filter_seed, t.init_seed) for t in t1)


def test_bernard_regeneration_reruns_every_study_the_document_read():
    """benchmarks/bernard_reproduction.py: its study list holds every study output that
    docs/reproduction.md's Bernard section names as read, and every ablation file."""
    import re
    from pathlib import Path

    doc = Path(__file__).resolve().parents[2] / "docs" / "reproduction.md"
    if not doc.is_file():
        pytest.skip("docs/ not beside the tests (installed package)")
    mod = _benchmark("bernard_reproduction")
    names = [p.stem for p in mod.studies({"thesis-fig9-4-bpf"})]
    assert len(names) == len(set(names))
    line = next(x for x in doc.read_text(encoding="utf-8").splitlines()
                if x.startswith("Study outputs used:"))
    used = set(re.findall(r"`(thesis-[a-z0-9-]+)`", line))
    assert len(used) >= 50 and used <= set(names), sorted(used - set(names))
    assert {p.stem for p in (STUDIES / "ablations").glob("thesis-*.toml")} <= set(names)
    assert names[:10] == sorted(n for n in names if n.startswith("thesis-fig") and "ablation" not in n)
    assert "thesis-fig9-4-bpf" not in names and "thesis-fig9-4-bpf" in [
        p.stem for p in mod.studies(set())]


def test_bpf_open_settings_sweep_changes_only_its_two_settings(tmp_path):
    """benchmarks/bernard_bpf_open.py: each derived study is the BPF study with only 𝒢 and the
    resampling level changed — same name stem, seeds, cells and tasks, the thesis variant kept
    (the per-filter table must not switch the runs to the robust filter)."""
    mod = _benchmark("bernard_bpf_open")
    base_file = STUDIES / "thesis-bpf-leo.toml"
    f = tmp_path / "sweep.toml"
    f.write_text(mod.variant_text(base_file, 0.05, 1.0))
    base, sw = load_study(base_file), load_study(f)
    assert sw.name == "thesis-bpf-leo-G0.05-ess1"
    assert sw.options["variant"] == "thesis" == base.options["variant"]
    assert dict(sw.options["filters"]) == {"bpf": (("ess_threshold", 1.0), ("roughening", 0.05))}
    assert {k: v for k, v in sw.options.items() if k != "filters"} == base.options
    t0, t1 = list(base.tasks(2)), list(sw.tasks(2))
    assert [(t.cell, t.run, t.sim_seed, t.filter_seed) for t in t0] == \
        [(t.cell, t.run, t.sim_seed, t.filter_seed) for t in t1]
    assert mod.main(["--roughening", "-1", "-o", str(tmp_path / "o")]) == 2


def test_spike_benchmark_finds_the_plus_x_glints_of_the_fig_9_19_case(tmp_path):
    """benchmarks/bernard_spikes.py on the Fig. 9.19 case (B.3: GEO, CubeSat, one site,
    σω 0.02°/s, 1 %). §9.3.5 puts the +X facet normal (m = 0.04, Table 9.2) on the Sun–Socorro
    bisector at t = 0 and the body spins at the constant rate [2, 1, 3.6]°/s, so the +X glint
    recurs once per spin period 360°/|ω| (the bisector barely moves in GEO): the spikes of the
    controlled truth fall on the 5 s samples nearest k·360°/|ω|, k = 0, 1, …"""
    mod = _benchmark("bernard_spikes")
    out = tmp_path / "spikes.json"
    assert mod.main(["--studies", "thesis-fig-b3-geo-cubesat", "--runs", "2", "-o",
                     str(out)]) == 0
    sp = json.loads(out.read_text())
    assert sp["benchmark"] == "bernard_spikes" and sp["runs"] == 2
    by = {c["dynamics"]: c for c in sp["cases"]}
    period = 360.0 / np.linalg.norm([2.0, 1.0, 3.6])
    expect = [5.0 * round(k * period / 5.0) for k in range(int(360 // period) + 1)]
    assert expect == [0.0, 85.0, 170.0, 255.0, 340.0]
    assert by["controlled"]["spike_times_s_run0"] == expect
    assert by["controlled"]["spikes"] == [5, 5]
    assert all(h > 5.0 for h in by["controlled"]["largest_mag"])   # far above the 2 mag rule
    # the specified uncontrolled truth keeps them (the §9.4.5 disagreement of the document)
    assert by["uncontrolled"]["spike_times_s_run0"] == expect
    with pytest.raises(SystemExit) as exc:   # argparse's usage error
        mod.main(["--runs", "0"])
    assert exc.value.code == 2


def test_glint_height_is_the_brightening_over_the_local_median_per_site():
    """lightcurve.studies.runner.glint_height: median of the same site's epochs within ±4
    minus the epoch's magnitude (hand-computed here); sites never mix."""
    from types import SimpleNamespace

    from lightcurve.errors import InputError
    from lightcurve.studies.runner import glint_height

    m = np.array([10.0, 10, 10, 5, 10, 10, 10, 20, 20, 19, 20])
    site = np.array([0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1])
    h = glint_height(SimpleNamespace(truth_mag=m, site=site))
    assert h[3] == 5.0 and np.all(h[[0, 1, 2, 4, 5, 6]] == 0.0)
    assert h[9] == 1.0 and np.all(h[[7, 8, 10]] == 0.0)
    with pytest.raises(InputError, match="truth_mag"):
        glint_height(SimpleNamespace(truth_mag=None, site=None))


def test_glint_height_matches_a_plain_loop_on_long_runs_with_gaps():
    """glint_height against a plain per-epoch loop written here (median of the same site's
    epochs within ±4, the window shortened at the ends, NaN epochs ignored): long two-site
    runs with unlit (NaN) epochs, fixed seed."""
    from types import SimpleNamespace

    from lightcurve.studies.runner import glint_height

    rng = np.random.default_rng(7)
    m = 12 + rng.normal(0, 1.5, 150)
    m[rng.choice(150, 20, replace=False)] = np.nan
    site = np.repeat([0, 1, 0], [60, 50, 40])
    ref = np.empty(150)
    for s in (0, 1):
        idx = np.flatnonzero(site == s)
        for j, k in enumerate(idx):
            ref[k] = np.nanmedian(m[idx][max(0, j - 4):j + 5]) - m[k]
    h = glint_height(SimpleNamespace(truth_mag=m, site=site))
    np.testing.assert_array_equal(np.isnan(h), np.isnan(ref))
    np.testing.assert_allclose(h[~np.isnan(h)], ref[~np.isnan(ref)], rtol=0, atol=1e-12)
