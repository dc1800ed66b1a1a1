"""docs/reproduction.md generator: verdicts from study summaries (hand-made summaries here)."""

from __future__ import annotations

import json

from lightcurve.cli import main
from lightcurve.studies.reproduction import bernard_section


def _cell(filter, dynamics, sites, st, so, r, color, thesis, rss, below=1.0, runs=100):
    return dict(filter=filter, dynamics=dynamics, sites=sites, sigma_theta_deg=st,
                sigma_omega_deg_s=so, r_percent=r, reflection="none", runs=runs, color=color,
                thesis_color=thesis, outside_3sigma=[0] * 6, rss_att_deg_median=rss,
                below_5deg=below)


def _write(tmp_path, name, cells, **extra):
    from lightcurve.studies.agreement import agreement

    d = tmp_path / name
    d.mkdir()
    s = {"study": name, "runs_per_cell": cells[0]["runs"], "variant": "thesis",
         "indicative": cells[0]["runs"] < 100, "cells": cells, **extra}
    if any(c["thesis_color"] for c in cells):
        s["agreement"] = agreement(cells)
        s["thesis_figure"] = "9.4"
    (d / "summary.json").write_text(json.dumps(s))
    return d


def test_tables_claims_and_not_testable(tmp_path):
    f94 = [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "green", "green", 0.3),
           _cell("ukf", "controlled", 2, 3.0, 0.02, 1.0, "green", "green", 0.28),
           _cell("ukf", "uncontrolled", 1, 3.0, 0.02, 1.0, "green", "green", 0.6),
           _cell("mekf", "controlled", 1, 3.0, 0.02, 1.0, "red", "green", 2.0),
           _cell("ukf", "controlled", 1, 10.0, 0.02, 1.0, "red", "red", 50.0, below=0.4)]
    nadir = [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "red", None, 3.0, runs=20),
             _cell("ukf", "controlled", 2, 3.0, 0.02, 1.0, "red", None, 1.0, runs=20),
             _cell("ukf", "uncontrolled", 1, 3.0, 0.02, 1.0, "red", None, 3.1, runs=20)]
    inert = [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "red", None, 4.0, runs=20)]
    beyond = [_cell("ukf", "controlled", 1, 20.0, 0.02, 1.0, "red", None, 90.0, runs=20),
              _cell("mekf", "controlled", 1, 30.0, 0.02, 1.0, "red", None, 90.0, runs=20)]
    dirs = [_write(tmp_path, "thesis-fig9-4", f94),
            _write(tmp_path, "thesis-claims-leo-nadir", nadir),
            _write(tmp_path, "thesis-claims-leo-inertial", inert),
            _write(tmp_path, "thesis-claims-beyond-10deg", beyond)]
    md = bernard_section(dirs)
    # 4 of 5 cells agree = 80 % < 85 %: the table disagrees, with its disagreeing cell listed
    assert "| Fig. 9.4 (LEO, fast spin) | 4/5 cells agree (80 %" in md
    assert "| disagrees |" in md.split("\n| Fig. B.1")[0]
    assert "| MEKF | controlled | 1 | 3 | 0.02 | 1 | red | green |" in md
    assert "not testable (no output of `thesis-fig-b1-meo-cubesat`)" in md
    lines = {ln.split(" | ")[0].lstrip("| "): ln for ln in md.splitlines() if ln.startswith("| ")}
    assert lines["EKF and UKF not suitable for initial attitude uncertainty σθ > 10°"].endswith(
        "| agrees |")
    assert lines["better attitude estimates with the faster spinning spacecraft"].endswith(
        "| agrees |")
    # second site: fast 0.28/0.3 ≈ 0.93 (not significant), nadir 1/3 (significant) → agrees
    assert "fast 0.93, nadir 0.33" in md
    # dynamics: fast 0.6/0.3 = 2 (differs), nadir 3.1/3 (same) → agrees
    assert "fast 2.00, nadir 1.03" in md
    assert "not testable (no `thesis-bpf-leo` output)" in md


def test_cli_writes_the_file(tmp_path):
    d = _write(tmp_path, "thesis-fig9-4",
               [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "green", "green", 0.3, runs=10)])
    out = tmp_path / "reproduction.md"
    assert main(["reproduction", "--study", str(d), "-o", str(out)]) == 0
    text = out.read_text()
    assert text.startswith("# Reproduction of the source documents")
    assert "indicative: 10 runs/cell" in text


def test_module_entry_point_is_the_cli_and_takes_both_spellings(tmp_path, capsys):
    # `--study A B` (one option, several folders) and `--study A --study B` read the same
    # studies, through `lightcurve reproduction` and through the module entry point alike
    from lightcurve.studies.reproduction import main as module_main

    a = _write(tmp_path, "thesis-fig9-4",
               [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "green", "green", 0.3, runs=10)])
    b = _write(tmp_path, "thesis-fig-b1-meo-cubesat",
               [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "red", "green", 0.3, runs=10)])
    texts = []
    for i, (entry, args) in enumerate([(main, ["reproduction", "--study", str(a), str(b)]),
                                       (main, ["reproduction", "--study", str(a), "--study", str(b)]),
                                       (module_main, ["--study", str(a), str(b)])]):
        out = tmp_path / f"r{i}.md"
        assert entry([*args, "-o", str(out)]) == 0
        assert "(2 Bernard and 0 CSS study output(s) read)" in capsys.readouterr().out
        texts.append(out.read_text())
    assert texts[0] == texts[1] == texts[2]
    assert "0/1 cells agree" in texts[0] and "1/1 cells agree" in texts[0]
    # bad input through the module entry point: one line, exit 2, nothing written
    assert module_main(["--only", "css", "-o", str(tmp_path / "none.md")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not (tmp_path / "none.md").exists()


def test_study_folders_named_by_the_user_must_hold_one_study_each(tmp_path, capsys):
    # a --study folder without a study summary, a summary of something else, or a second
    # folder of the same study: one line naming the file, exit 2, the existing document kept
    import json

    a = _write(tmp_path, "thesis-fig9-4",
               [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "green", "green", 0.3, runs=10)])
    out = tmp_path / "r.md"
    assert main(["reproduction", "--study", str(a), "-o", str(out)]) == 0
    capsys.readouterr()
    before = out.read_bytes()
    empty = tmp_path / "empty"
    empty.mkdir()
    other = tmp_path / "other"
    other.mkdir()
    (other / "summary.json").write_text(json.dumps({"cells": []}))
    twin = tmp_path / "twin"
    twin.mkdir()
    (twin / "summary.json").write_text((a / "summary.json").read_text())
    for bad, words in ((tmp_path / "missing", "no such study output folder"),
                       (empty, "summary.json"), (other, "not a study summary"),
                       (twin, "two folders hold the same study")):
        assert main(["reproduction", "--study", str(a), str(bad), "-o", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0] and str(bad) in err[0], err
        assert out.read_bytes() == before
    # the library call used by benchmarks keeps skipping what it cannot read
    from lightcurve.studies.reproduction import load_summaries
    assert list(load_summaries([a, empty, other, tmp_path / "missing"])) == ["thesis-fig9-4"]


def test_monte_carlo_spread_block_and_ablations_within_noise(tmp_path):
    # cells carrying color_probability: the spread table (self-agreement Σ Σ P², expected
    # agreement Σ P(thesis), cells within noise) and, per disagreeing cell, P(thesis) and the
    # ablations whose colour differs but under which the thesis's has P >= 5 %
    def spread(c, g, y, r):
        c["color_probability"] = {"green": g, "yellow": y, "red": r}
        return c

    base = [spread(_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "green", "green", 0.3),
                   0.9, 0.1, 0.0),
            spread(_cell("ukf", "controlled", 1, 5.0, 0.02, 1.0, "red", "yellow", 0.3),
                   0.0, 0.02, 0.98),
            spread(_cell("ukf", "controlled", 1, 10.0, 0.02, 1.0, "yellow", "green", 0.3),
                   0.3, 0.6, 0.1)]
    abl_a = [spread(_cell("ukf", "controlled", 1, 5.0, 0.02, 1.0, "green", "yellow", 0.3),
                    0.8, 0.2, 0.0)]
    abl_b = [spread(_cell("ukf", "controlled", 1, 5.0, 0.02, 1.0, "green", "yellow", 0.3),
                    0.97, 0.03, 0.0)]
    dirs = [_write(tmp_path, "thesis-fig9-4", base),
            _write(tmp_path, "thesis-fig9-4-ablation-a", abl_a),
            _write(tmp_path, "thesis-fig9-4-ablation-b", abl_b)]
    md = bernard_section(dirs)
    # self-agreement 0.82 + 0.9608 + 0.46 = 2.2408; expected 0.9 + 0.02 + 0.3 = 1.22
    assert "| Fig. 9.4 (LEO, fast spin) | 1/3 | 2.2/3 (75 %) |" in md
    assert "| 1.2/3 | 1 of 2 |" in md
    row5 = next(ln for ln in md.splitlines() if ln.startswith("| UKF | controlled | 1 | 5 |"))
    assert "| 2.0 % | none of the tested ablations; crossed by: a (green, 0 max), b (green, " \
           "0 max); within the noise of: a (green, 0 max; P(thesis) 20 %) |" in row5
    row10 = next(ln for ln in md.splitlines() if ln.startswith("| UKF | controlled | 1 | 10 |"))
    assert "| 30.0 % (noise) |" in row10


def test_disagreeing_cell_out_of_published_order(tmp_path):
    # the published σω = 0.2 cell is yellow while its easier σω = 0.02 neighbour is red: the
    # disagreeing cell's row says so; a disagreeing cell in order does not
    base = [_cell("mekf", "controlled", 2, 3.0, 0.02, 1.0, "red", "red", 1.0),
            _cell("mekf", "controlled", 2, 3.0, 0.2, 1.0, "red", "yellow", 1.0),
            _cell("mekf", "controlled", 2, 5.0, 0.02, 1.0, "green", "red", 1.0)]
    md = bernard_section([_write(tmp_path, "thesis-fig9-4", base)])
    row = next(ln for ln in md.splitlines() if ln.startswith("| MEKF | controlled | 2 | 3 | 0.2 |"))
    assert row.endswith("| no ablation run; published out of order: σθ 3°, σω 0.02°/s is red |")
    row = next(ln for ln in md.splitlines() if ln.startswith("| MEKF | controlled | 2 | 5 | 0.02 |"))
    assert row.endswith("| no ablation run |")
    assert ("Of the 2 disagreeing cells, a tested switch gives the thesis's colour in 0. Of the "
            "other 2, a switch carries 0 past it, 0 are within Monte Carlo noise (of our filter "
            "or of a switch), and 2 have no measured cause; 1 of these is published out of "
            "order.") in md



def test_only_one_section_keeps_the_other_byte_for_byte(tmp_path, capsys):
    out = tmp_path / "reproduction.md"
    # no file yet: --only has nothing to keep; one line, exit 2, nothing written
    assert main(["reproduction", "--only", "bernard", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(out) in err and "--only" in err
    assert not out.exists()
    assert main(["reproduction", "-o", str(out)]) == 0
    before = out.read_text()
    css_before = before[before.index("## Coarse sun sensors"):]
    # a hand-edited CSS section stays as it is when only the Bernard section is rewritten
    edited = before.replace(css_before, css_before + "\nA line kept by --only.\n")
    out.write_text(edited)
    d = _write(tmp_path, "thesis-fig9-4",
               [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "green", "green", 0.3, runs=10)])
    assert main(["reproduction", "--only", "bernard", "--study", str(d), "-o", str(out)]) == 0
    after = out.read_text()
    assert after[after.index("## Coarse sun sensors"):].rstrip() == edited[edited.index(
        "## Coarse sun sensors"):].rstrip()
    assert "indicative: 10 runs/cell" in after and "indicative" not in before
    assert after.startswith("# Reproduction of the source documents\n\n## Bernard (2021)")
    # a file without the sections is refused and left as it is
    other = tmp_path / "other.md"
    other.write_text("# Something else\n")
    assert main(["reproduction", "--only", "css", "-o", str(other)]) == 2
    assert other.read_text() == "# Something else\n"
    assert "section" in capsys.readouterr().err


def _kf(variant, m3_rss, known_rss=None):
    """A hand-made benchmarks/reflection_kf.py output: 3 parameters of which 1 is estimated."""
    per = {"a[0]": {"frac_shrink_ge2": 0.9}, "m[0]": {"frac_shrink_ge2": 0.1},
           "a[5]": {"frac_shrink_ge2": 0.8}, "m[5]": {"frac_shrink_ge2": 0.0}}
    s108 = {"geo_sth3_model1_ukf": {"success": 1, "runs": 10, "final_rss_deg": [1.0]},
            "geo_sth3_model2_ukf": {"success": 2, "runs": 10, "final_rss_deg": [1.0]},
            "leo_fast_sth3_model3_ukf": {"success": 8, "runs": 10, "final_rss_deg": m3_rss},
            "leo_fast_sth3_none_ukf": {"success": 0, "runs": 10, "final_rss_deg": [2.0, 3.0]}}
    if known_rss is not None:
        s108["leo_fast_sth3_known_ukf"] = {"success": 10, "runs": 10, "final_rss_deg": known_rss}
    return {"benchmark": "reflection_kf", "variant": variant,
            "sec10_7": {"ukf": per, "ukf_observable": ["a[0]", "a[5]"]}, "sec10_8": s108}


def test_chapter10_rows_per_variant_against_perfect_knowledge(tmp_path, capsys):
    # §10.4: Model 3's attitude is "not as accurate as when there was a perfect knowledge of the
    # shape model reflection parameters": compared with runs whose truth parameters are the
    # filter's (median final RSS), not with runs that leave wrong parameters unestimated
    paths = []
    for variant, m3, known in (("robust", [0.8, 0.9], [0.5, 0.6]), ("thesis", [0.4, 0.5], [0.6, 0.7])):
        p = tmp_path / f"kf-{variant}.json"
        p.write_text("progress line\n" + json.dumps(_kf(variant, m3, known)) + "\n")
        paths.append(p)
    md = bernard_section([], reflection_kf_json=paths)
    rows = [ln for ln in md.splitlines() if ln.startswith("| §10.")]
    assert len(rows) == 8 and all("thesis variant" in r for r in rows[:4])   # thesis first
    m3 = [r for r in rows if "perfect knowledge" in r]
    assert m3[0].endswith("| disagrees |") and "0.45° vs 0.65° with the parameters known" in m3[0]
    assert m3[1].endswith("| agrees |") and "0.85° vs 0.55° with the parameters known; 2.50° " \
        "with the parameters 10 % off and not estimated" in m3[1]
    some = next(r for r in rows if "some parameters are estimated" in r)
    assert "| 2 of 4 parameters: a[0], a[5] | agrees |" in some
    assert "| 3/20 runs succeed | agrees |" in md
    assert "Outputs of `benchmarks/reflection_kf.py` used: thesis variant" in md
    # an output from before the perfect-knowledge runs: that row is not testable
    old = _kf("robust", [0.8, 0.9])
    md = bernard_section([], reflection_kf_json=[_dump(tmp_path / "old.json", old)])
    row = next(ln for ln in md.splitlines() if "perfect knowledge" in ln)
    assert "not testable (no run with the parameters known" in row
    # a file that is not such an output: one line naming it, exit 2, the document kept
    out = tmp_path / "reproduction.md"
    assert main(["reproduction", "-o", str(out)]) == 0
    before = out.read_text()
    bad = tmp_path / "bad.json"
    bad.write_text('{"benchmark": "css"}\n')
    broken = _dump(tmp_path / "broken.json", {"benchmark": "reflection_kf", "variant": "thesis",
                                              "sec10_8": {"geo_sth3_model1_ukf": {"runs": 10}}})
    for f in (bad, broken):
        capsys.readouterr()
        assert main(["reproduction", "--reflection-kf", str(paths[0]), str(f), "-o",
                     str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(f) in err[0] and "reflection_kf" in err[0], err
        assert out.read_text() == before


def _dump(path, obj):
    path.write_text(json.dumps(obj))
    return path


def test_second_observatory_claim_reads_both_slow_cases(tmp_path):
    # §9.4.4: a second site "did greatly improve the attitude estimates of the nadir-pointing
    # and inertially-fixed spacecraft" and not the fast one; ratio = two sites / one site of
    # the UKF's median final RSS, significant below 0.7
    f94 = [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "green", "green", 0.30),
           _cell("ukf", "controlled", 2, 3.0, 0.02, 1.0, "green", "green", 0.30)]
    nadir = [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "red", None, 4.0, runs=100),
             _cell("ukf", "controlled", 2, 3.0, 0.02, 1.0, "red", None, 2.0, runs=100)]

    def row(inert_two_site_rss):
        inert = [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "red", None, 5.0, runs=100),
                 _cell("ukf", "controlled", 2, 3.0, 0.02, 1.0, "red", None, inert_two_site_rss,
                       runs=100)]
        d = tmp_path / str(inert_two_site_rss)
        d.mkdir()
        md = bernard_section([_write(d, "thesis-fig9-4", f94),
                              _write(d, "thesis-claims-leo-nadir", nadir),
                              _write(d, "thesis-claims-leo-inertial", inert)])
        return next(ln for ln in md.splitlines() if ln.startswith("| a second observatory"))

    assert row(3.0).endswith("| median RSS two sites / one site: fast 1.00, nadir 0.50, "
                             "inertial 0.60 | agrees |")
    assert row(4.0).endswith("nadir 0.50, inertial 0.80 | disagrees |")


def test_disagreeing_cells_flipped_crossed_or_unexplained(tmp_path):
    # per disagreeing cell: an ablation with the thesis's colour flips it; one on the far side
    # of a published yellow (ours red, ablation green) crosses it; the table's closing line
    # counts the cells by the first of flipped / crossed / within noise / none that applies
    base = [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "red", "green", 0.3),
            _cell("ukf", "controlled", 1, 5.0, 0.02, 1.0, "red", "yellow", 0.3),
            _cell("ukf", "controlled", 1, 10.0, 0.02, 1.0, "green", "yellow", 0.3),
            _cell("ukf", "controlled", 1, 10.0, 0.2, 1.0, "red", "yellow", 0.3),
            _cell("ukf", "controlled", 2, 3.0, 0.02, 1.0, "green", "green", 0.3)]
    abl = [_cell("ukf", "controlled", 1, 3.0, 0.02, 1.0, "green", "green", 0.3),
           _cell("ukf", "controlled", 1, 5.0, 0.02, 1.0, "green", "yellow", 0.3),
           _cell("ukf", "controlled", 1, 10.0, 0.02, 1.0, "red", "yellow", 0.3),
           _cell("ukf", "controlled", 1, 10.0, 0.2, 1.0, "red", "yellow", 0.3)]
    md = bernard_section([_write(tmp_path, "thesis-fig9-4", base),
                          _write(tmp_path, "thesis-fig9-4-ablation-a", abl)])
    rows = {tuple(ln.split(" | ")[3:5]): ln for ln in md.splitlines()
            if ln.startswith("| UKF | controlled | 1 |")}
    assert rows[("3", "0.02")].endswith("| a (green, 0 max) |")
    assert rows[("5", "0.02")].endswith(
        "| none of the tested ablations; crossed by: a (green, 0 max) |")
    assert rows[("10", "0.02")].endswith(
        "| none of the tested ablations; crossed by: a (red, 0 max) |")
    assert rows[("10", "0.2")].endswith("| none of the tested ablations |")
    assert ("Of the 4 disagreeing cells, a tested switch gives the thesis's colour in 1. Of "
            "the other 3, a switch carries 2 past it, 0 are within Monte Carlo noise (of our "
            "filter or of a switch), and 1 has no measured cause.") in md


def _spikes(con, unc, regime="GEO", shape="CubeSat", study="thesis-fig-b3-geo-cubesat"):
    """A hand-made benchmarks/bernard_spikes.py output: spike counts per truth."""
    case = dict(study=study, regime=regime, shape=shape, sites=1, sigma_omega_deg_s=0.02,
                r_percent=1.0, spike_times_s_run0=[])
    return {"benchmark": "bernard_spikes", "runs": len(con), "brighter_mag": 2.0,
            "cases": [dict(case, dynamics="controlled", spikes=con, largest_mag=[7.0] * len(con)),
                      dict(case, dynamics="uncontrolled", spikes=unc,
                           largest_mag=[1.0] * len(unc))]}


def test_spike_claim_of_section_9_4_5(tmp_path, capsys):
    # §9.4.5 / Fig. 9.19: the controlled curve's large spikes are not present in the uncontrolled
    # one — agrees when at most half of the uncontrolled truths have a spike; the Fig. 9.19 case
    # (GEO, CubeSat) is the first row
    md = bernard_section([])
    row = next(ln for ln in md.splitlines() if ln.startswith("| §9.4.5"))
    assert row.endswith("| – | not testable (no benchmarks/bernard_spikes.py output given) |")
    sp = _spikes([5, 5, 5, 5], [0, 0, 1, 2])
    leo = _spikes([8, 8, 8, 8], [8, 8, 8, 0], "LEO", "CubeSat", "thesis-fig9-4")
    sp["cases"] = leo["cases"] + sp["cases"]
    md = bernard_section([], spikes_json=_dump(tmp_path / "sp.json", sp))
    rows = [ln for ln in md.splitlines() if ln.startswith("| §9.4.5")]
    assert rows[0].startswith("| §9.4.5, Fig. 9.19 (GEO, CubeSat)")
    assert rows[0].endswith("controlled 5 (largest 7.0 mag), uncontrolled 0.5 (largest 1.0 "
                            "mag); uncontrolled truths with a spike: 2 of 4 | agrees |")
    assert "every fast-spinning case): LEO, CubeSat" in rows[1]
    assert rows[1].endswith("uncontrolled truths with a spike: 3 of 4 | disagrees |")
    none = _spikes([0, 0, 1], [0, 0, 0])
    md = bernard_section([], spikes_json=_dump(tmp_path / "none.json", none))
    assert "| not testable (no spikes in the controlled truths) |" in md
    # another benchmark's output: one line naming the file, exit 2, the document kept
    out = tmp_path / "reproduction.md"
    assert main(["reproduction", "-o", str(out)]) == 0
    before = out.read_text()
    bad = _dump(tmp_path / "bad.json", {"benchmark": "reflection_kf"})
    broken = dict(sp, cases=[{k: v for k, v in c.items() if k != "spikes"} for c in sp["cases"]])
    for f in (bad, _dump(tmp_path / "broken.json", broken)):
        capsys.readouterr()
        assert main(["reproduction", "--spikes", str(f), "-o", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(f) in err[0] and "bernard_spikes" in err[0], err
        assert out.read_text() == before
