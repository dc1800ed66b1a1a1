"""Published tables (Fig. 9.4, B.1–B.4) as data, the scaled traffic light and the agreement.

* The transcribed tables: spot cells typed here from the text, and the grey / unknown counts
  of each figure (Fig. 9.4 has 2 grey cells; B.3's controlled two-site halves are lost).
* Traffic light: the 100-run rule unchanged at 100 runs; with n runs a count c reads as
  c·100/n (5 runs with 4 diverged is red, not green).
* A small thesis-variant study: grey cells are not run, every cell carries ``thesis_color``,
  the summary the agreement counts and ``indicative``; the report shows the thesis colour; all
  filters of one run share the initial-estimate seed (§9.3.1), the robust variant does not.
"""

from __future__ import annotations

import json

import pytest

from lightcurve._paths import data_dir
from lightcurve.studies.agreement import agreement, load_thesis_table
from lightcurve.studies.metrics import traffic_light
from lightcurve.studies.study import load_study

STUDIES = data_dir("pipelines") / "studies"
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


def test_thesis_variant_study_grey_cells_colours_and_shared_initial_estimate(tmp_path):
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
    html = (tmp_path / "out" / "report.html").read_text()
    assert "thesis: red" in html and "not run" in html and "INDICATIVE" in html


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
