"""Figures: `lightcurve plot` on every file the tool writes, the analyst estimate figure (no
empty panels, truth panels only with a truth), verdicts and the study summary views."""

from __future__ import annotations

import json

import numpy as np
import pytest

PNG = b"\x89PNG\r\n\x1a\n"


def _visible_axes_have_data(fig):
    for ax in fig.axes:
        if ax.get_visible() and ax.get_label() != "<colorbar>":
            assert ax.lines or ax.collections or ax.patches or ax.images, ax.get_title()


def test_estimate_figure_panels(default_pass):
    import matplotlib.pyplot as plt

    from lightcurve.filters.plots import estimate_figure

    lc, est = default_pass
    fig = estimate_figure(est, curve=lc)
    _visible_axes_have_data(fig)
    titles = " ".join(a.get_title(loc="left") for a in fig.axes)
    assert "spin axis on the sky" in titles and "errors against the truth" in titles
    assert "lightcurve: measured and fitted" in titles
    w, h = fig.get_size_inches()
    assert w <= 12.0 and h <= 14.0
    assert "inside 3σ" in fig._suptitle.get_text()
    n_with_truth = len(fig.axes)
    plt.close(fig)
    # without truth and without the lightcurve: no truth row, no lightcurve panel, no empty axes
    import dataclasses

    bare = dataclasses.replace(est, att_error_deg=None, omega_error_rad_s=None, nees=None,
                               mag=None, mag_sigma=None, site=None, predicted_mag=None,
                               epoch_utc="", source_file="")
    fig = estimate_figure(bare)
    _visible_axes_have_data(fig)
    titles = " ".join(a.get_title(loc="left") for a in fig.axes)
    assert "errors against the truth" not in titles and "lightcurve:" not in titles
    assert len(fig.axes) == n_with_truth - 4
    plt.close(fig)


def test_plot_every_file_kind(default_pass, tmp_path):
    from lightcurve.cli import main
    from lightcurve.errors import InputError
    from lightcurve.report.plot_any import file_kind, plot_file

    lc, est = default_pass
    files = {"lightcurve": lc.write(tmp_path / "p.h5"), "estimate": est.write(tmp_path / "p.ukf.h5")}
    # CSS recording and 'css estimate' CSV through the command line
    css = tmp_path / "css.h5"
    assert main(["css", "simulate", "--duration-s", "60", "--dt-s", "1", "--out", str(css)]) == 0
    csv = tmp_path / "s.csv"
    assert main(["css", "estimate", str(css), "--estimator", "wlsmn", "--out", str(csv)]) == 0
    files["css-recording"], files["css-estimate-csv"] = css, csv
    s = est.summary()
    s["file"] = "p.h5"
    (tmp_path / "summary.json").write_text(json.dumps({"p": s}))
    files["invert-summary"] = tmp_path / "summary.json"
    cells = [{"filter": f, "dynamics": "controlled", "sites": 1, "sigma_theta_deg": 3.0,
              "sigma_omega_deg_s": 0.02, "r_percent": 1.0, "reflection": "none", "runs": 5,
              "outside_3sigma": [0] * 6, "color": "green", "rss_att_deg_median": m,
              "rss_att_deg_p95": 2 * m, "rss_omega_deg_s_median": 0.01, "failures": 0}
             for f, m in (("mekf", 1.0), ("ukf", 0.5))]
    (tmp_path / "study.json").write_text(json.dumps({"study": "s", "runs_per_cell": 5,
                                                      "grid_keys": ["filter"], "cells": cells}))
    files["study-summary"] = tmp_path / "study.json"
    for kind, path in files.items():
        assert file_kind(path) == kind
        out = plot_file(path, tmp_path / f"{kind}.png")
        assert out.read_bytes()[:8] == PNG
    # the estimate found its source lightcurve (p.h5 next to p.ukf.h5): lightcurve panel drawn
    from lightcurve.filters.result import read_estimate
    from lightcurve.report.plot_any import source_lightcurve

    src = source_lightcurve(read_estimate(files["estimate"]), files["estimate"])
    assert src is not None and np.array_equal(src.mag, lc.mag)
    for bad in (tmp_path / "lightcurve.png", tmp_path / "nope.h5"):
        with pytest.raises(InputError):
            file_kind(bad)
    (tmp_path / "other.json").write_text("{\"a\": 1}")
    with pytest.raises(InputError, match="unknown kind"):
        file_kind(tmp_path / "other.json")
    assert main(["plot", str(files["estimate"]), "-o", str(tmp_path / "cli.png")]) == 0
    assert main(["plot", str(tmp_path / "other.json")]) == 2


def test_filter_ranking_and_study_verdict():
    from lightcurve.report.verdicts import filter_ranking, study_verdict

    def cell(f, sth, color, med, fail=0):
        return {"filter": f, "dynamics": "controlled", "sites": 1, "sigma_theta_deg": sth,
                "sigma_omega_deg_s": 0.02, "r_percent": 1.0, "reflection": "none",
                "color": color, "rss_att_deg_median": med, "failures": fail}

    cells = [cell("mekf", 3, "green", 1.0), cell("ukf", 3, "green", 0.5),
             cell("mekf", 10, "red", 2.0), cell("ukf", 10, "green", 3.0),   # colour beats error
             cell("mekf", 5, "green", 0.4), cell("ukf", 5, "green", 0.6, fail=1)]  # failures too
    rank = filter_ranking(cells)
    assert [r["filter"] for r in rank] == ["ukf", "mekf"]
    assert (rank[0]["wins"], rank[1]["wins"]) == (2, 1) and rank[0]["groups"] == 3
    assert rank[1]["red"] == 1 and rank[0]["failures"] == 1
    level, text = study_verdict(cells)
    assert level == "warn" and text.startswith("UKF is the better filter here: best in 2 of 3")
    assert study_verdict([c for c in cells if c["filter"] == "ukf" and not c["failures"]])[0] == "ok"
    assert study_verdict([cell("mekf", 3, "red", 9.0)])[0] == "fail"


def test_study_summary_views_and_report(tmp_path):
    from lightcurve.report.html import write_study_report
    from lightcurve.report.views import StudySummary, read_study_summary

    cells = [{"filter": f, "dynamics": "controlled", "sites": 1, "sigma_theta_deg": 3.0,
              "sigma_omega_deg_s": 0.02, "r_percent": 1.0, "reflection": "none", "runs": 5,
              "outside_3sigma": [0, 1, 0, 0, 0, 2], "color": "green", "rss_att_deg_median": m,
              "rss_att_deg_p95": 2 * m, "rss_omega_deg_s_median": 0.01,
              "rss_omega_deg_s_p95": 0.02, "diverged": 0, "runtime_s_median": 0.01,
              "failures": 0} for f, m in (("mekf", 1.0), ("ukf", 0.5))]
    summary = {"study": "demo", "runs_per_cell": 5, "seed": 1, "study_hash": "0" * 64,
               "grid_keys": ["filter", "dynamics", "sites", "sigma_theta_deg",
                             "sigma_omega_deg_s", "r_percent", "reflection"], "cells": cells}
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    s = read_study_summary(tmp_path)
    assert isinstance(s, StudySummary) and dict(s) == summary
    df = s.to_pandas()
    assert list(df["filter"]) == ["mekf", "ukf"] and list(df["outside_3sigma_omega_z"]) == [2, 2]
    assert repr(s) == "<StudySummary demo: 2 cells × 5 runs; 2 green, 0 yellow, 0 red>"
    assert "UKF is the better filter" in s._repr_html_()
    write_study_report(tmp_path / "report.html", summary, [])
    page = (tmp_path / "report.html").read_text()
    assert page.index("Verdict:") < page.index("Which filter is better") < page.index("fig. 9.4")


def test_estimate_figure_reflection_states(default_pass):
    """Reflection runs show their states; an attitude-known run has no (trivial) error row and
    no empty NEES panel, and says that the attitude was held at the truth."""
    import matplotlib.pyplot as plt

    import lightcurve
    from lightcurve.filters.plots import estimate_figure

    lc, _ = default_pass
    est = lightcurve.invert(lc, "ukf", seed=1, reflection="model3", attitude="truth",
                            reflection_kinds=("xi", "m"))
    fig = estimate_figure(est, curve=lc)
    _visible_axes_have_data(fig)
    titles = " ".join(a.get_title(loc="left") for a in fig.axes)
    assert "reflection parameters at the last epoch (Model 3)" in titles
    assert "errors against the truth" not in titles
    assert "HELD AT THE TRUTH" in fig._suptitle.get_text()
    ax = next(a for a in fig.axes if a.get_title(loc="left").startswith("reflection parameters"))
    assert [t.get_text() for t in ax.get_xticklabels()] == list(est.refl_names)
    plt.close(fig)
    est = lightcurve.invert(lc, "ukf", seed=1, reflection="model1")
    fig = estimate_figure(est, curve=lc)
    _visible_axes_have_data(fig)
    titles = " ".join(a.get_title(loc="left") for a in fig.axes)
    assert "reflection bias states" in titles and "errors against the truth" in titles
    plt.close(fig)


def test_lightcurve_elevation_line_spans_dropped_epochs(default_pass):
    """The default pass drops epochs with no lit facet facing the observer (tens of seconds
    at a 5 s step); the object's elevation is a smooth function of time through them, so its
    line is one piece over the pass, while the noise-free truth still breaks at the gaps."""
    import matplotlib.pyplot as plt

    from lightcurve.report.plots import plot_lightcurve

    lc, _ = default_pass
    dt = np.diff(lc.t)
    assert np.any(dt > 1.5 * np.median(dt))  # the pass has gaps (else the test proves nothing)
    fig = plot_lightcurve(lc)
    lines = {ln.get_label(): ln for ax in fig.axes for ln in ax.lines}
    elev = np.asarray(lines["elevation (right axis)"].get_ydata(), float)
    truth = np.asarray(lines["noise-free truth"].get_ydata(), float)
    assert np.all(np.isfinite(elev)) and elev.size == lc.t.size
    assert np.any(np.isnan(truth))
    plt.close(fig)


def test_innovation_panel_scaled_to_the_innovations_not_the_prior_band(default_pass):
    """The innovation panel's y range covers every innovation and the ±3√S band after the
    first epochs, not a first-epoch prior band of many magnitudes."""
    import matplotlib.pyplot as plt

    from lightcurve.filters.plots import estimate_figure

    lc, est = default_pass
    fig = estimate_figure(est, curve=lc)
    ax = next(a for a in fig.axes if a.get_ylabel() == "innovation [mag]")
    lo, hi = ax.get_ylim()
    nu = np.asarray(est.innovations, float)
    nu = np.abs(nu[np.isfinite(nu)])
    band = 3 * np.sqrt(np.asarray(est.innovation_var, float))
    band = band[np.isfinite(band)]
    assert hi == -lo and hi >= nu.max()
    assert hi >= band[3:].max() and hi <= 1.2 * max(nu.max(), band[3:].max())
    plt.close(fig)
