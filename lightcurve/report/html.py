"""Self-contained HTML reports (figures embedded as base64 PNG; open offline).

:func:`write_study_report` writes the Monte Carlo filter-comparison report of a study: a
one-line verdict saying which filter is better and a ranking table
(:mod:`lightcurve.report.verdicts`); the traffic-light table laid out like Bernard (2021) fig. 9.4 — rows are filter × σθ, columns are
dynamics × number of sites × σω × r — each cell coloured green / yellow / red
(:func:`lightcurve.studies.metrics.traffic_light`) and showing the six counts of runs whose
final error left the 3σ bound ``[θx θy θz | ωx ωy ωz]``; then a table of every cell with the
median and 95th-percentile final RSS attitude error, failures and median runtime; then the
RSS-attitude-error-versus-time envelopes (median and 95th percentile over the runs of every σω
and r) per filter, dynamics, number of sites and σθ.
"""

from __future__ import annotations

import base64
import html
import io
import itertools

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..io.atomic import atomic_write_text  # noqa: E402
from .style import PAGE_CSS, figsize, verdict_html  # noqa: E402

__all__ = ["write_study_report", "figure_to_data_uri", "fig94_table_html"]

_BG = {"green": "#8fd18f", "yellow": "#f3e27a", "red": "#ee8a80"}
_THESIS_BG = dict(_BG, grey="#c8c8c8", unknown="#ffffff")
_ROW_AXES = ("filter", "reflection", "sigma_theta_deg")
_COL_AXES = ("dynamics", "sites", "sigma_omega_deg_s", "r_percent")
_LABEL = {"filter": "filter", "reflection": "reflection", "sigma_theta_deg": "σθ (°)",
          "dynamics": "dynamics", "sites": "sites", "sigma_omega_deg_s": "σω (°/s)",
          "r_percent": "r (%)"}
_FILTER_NAME = {"mekf": "EKF (MEKF)", "ukf": "UKF", "bpf": "PF"}


def figure_to_data_uri(fig) -> str:
    """PNG data URI (``data:image/png;base64,…``) of a matplotlib figure (which is closed)."""
    from .style import DPI

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _uniq(cells, key):
    out = []
    for c in cells:
        if c[key] not in out:
            out.append(c[key])
    return out


def _fmt(key, v):
    if key == "filter":
        return _FILTER_NAME.get(v, v)
    if key == "sites":
        return f"{v} site" + ("s" if int(v) != 1 else "")
    return html.escape(str(v))


def _order(key):
    """Sort key of a grid axis: the study's order for names, numeric order for numbers."""
    if key == "filter":
        return lambda v: ("mekf", "ukf", "bpf").index(v) if v in ("mekf", "ukf", "bpf") else 9
    if key == "dynamics":
        return lambda v: ("controlled", "uncontrolled").index(v) \
            if v in ("controlled", "uncontrolled") else 9
    if key == "reflection":
        return lambda v: 0 if v == "none" else 1
    return float


def fig94_table_html(cells: list, not_run=()) -> str:
    """The traffic-light table (module docstring) as an HTML ``<table>``.

    A cell with a published colour (``thesis_color``, :mod:`lightcurve.studies.agreement`)
    shows it beside ours in a small box labelled "thesis" (✓ when they agree); ``not_run``
    cells (the thesis's grey cells) are drawn grey, "not run".
    """
    skip = {tuple(c[k] for k in ("filter", "reflection", "sigma_theta_deg", "dynamics", "sites",
                                 "sigma_omega_deg_s", "r_percent")) for c in not_run}
    allc = list(cells) + [dict(c, reflection=c.get("reflection", "none")) for c in not_run]
    rows_axes = [k for k in _ROW_AXES if len(_uniq(allc, k)) > 1 or k != "reflection"]
    col_axes = list(_COL_AXES)
    rvals = [sorted(_uniq(allc, k), key=_order(k)) for k in rows_axes]
    cvals = [sorted(_uniq(allc, k), key=_order(k)) for k in col_axes]
    index = {tuple(c[k] for k in rows_axes + col_axes): c for c in cells}
    cols = list(itertools.product(*cvals))
    out = ['<table class="fig94">']
    # header rows: one per column axis, with colspans
    for level, key in enumerate(col_axes):
        span = int(np.prod([len(v) for v in cvals[level + 1:]])) if level + 1 < len(cvals) else 1
        out.append("<tr>" + "".join(f'<th class="corner">{_LABEL[k]}</th>' if level == len(col_axes) - 1
                                    else '<th class="corner"></th>' for k in rows_axes))
        reps = int(np.prod([len(v) for v in cvals[:level]])) if level else 1
        cells_h = [f'<th colspan="{span}">{_LABEL[key]} = {_fmt(key, v)}</th>' if key not in
                   ("dynamics", "sites") else f'<th colspan="{span}">{_fmt(key, v)}</th>'
                   for _ in range(reps) for v in cvals[level]]
        out.append("".join(cells_h) + "</tr>")
    for rv in itertools.product(*rvals):
        out.append("<tr>" + "".join(f"<th>{_fmt(k, v)}</th>" for k, v in zip(rows_axes, rv)))
        for cv in cols:
            c = index.get(tuple(rv) + tuple(cv))
            if c is None:
                key = dict(zip(rows_axes + col_axes, tuple(rv) + tuple(cv)))
                key.setdefault("reflection", "none")
                if tuple(key.get(k) for k in ("filter", "reflection", "sigma_theta_deg",
                                              "dynamics", "sites", "sigma_omega_deg_s",
                                              "r_percent")) in skip:
                    out.append(f'<td style="background:{_THESIS_BG["grey"]}">not run<br>'
                               '(thesis: grey)</td>')
                else:
                    out.append('<td class="none">–</td>')
                continue
            o = c["outside_3sigma"]
            title = (f"{c['runs']} runs, {c['failures']} failed; median RSS "
                     f"{c['rss_att_deg_median']:.3g}°, p95 {c['rss_att_deg_p95']:.3g}°")
            if c.get("color_probability"):
                title += "; colour in a new 100-run Monte Carlo: " + ", ".join(
                    f"{k} {100 * v:.0f} %" for k, v in c["color_probability"].items())
            tc = c.get("thesis_color")
            thesis = ""
            if tc:
                mark = " ✓" if tc == c["color"] else ("" if tc in ("grey", "unknown") else " ✗")
                thesis = (f'<br><span class="thesis" style="background:{_THESIS_BG[tc]}">'
                          f'thesis: {html.escape(tc)}{mark}</span>')
            out.append(f'<td style="background:{_BG[c["color"]]}" title="{html.escape(title)}">'
                       f'{o[0]} {o[1]} {o[2]}<br>{o[3]} {o[4]} {o[5]}'
                       + (f'<br><b>{c["failures"]} failed</b>' if c["failures"] else "")
                       + thesis + "</td>")
        out.append("</tr>")
    out.append("</table>")
    return "\n".join(out)


def _cells_table_html(cells: list, keys: list) -> str:
    head = "".join(f"<th>{html.escape(_LABEL.get(k, k))}</th>" for k in keys)
    head += ("<th>runs</th><th>outside 3σ θx θy θz ωx ωy ωz</th><th>colour</th>"
             "<th>RSS att. median (°)</th><th>RSS att. p95 (°)</th>"
             "<th>RSS rate median (°/s)</th><th>diverged</th><th>failures</th>"
             "<th>runtime median (s)</th>")
    rows = []
    for c in cells:
        r = "".join(f"<td>{_fmt(k, c[k])}</td>" for k in keys)
        r += (f"<td>{c['runs']}</td><td>{' '.join(map(str, c['outside_3sigma']))}</td>"
              f'<td style="background:{_BG[c["color"]]}">{c["color"]}</td>'
              f"<td>{c['rss_att_deg_median']:.4g}</td><td>{c['rss_att_deg_p95']:.4g}</td>"
              f"<td>{c['rss_omega_deg_s_median']:.4g}</td><td>{c['diverged']}</td>"
              f"<td>{c['failures']}</td><td>{c['runtime_s_median']:.3g}</td>")
        rows.append(f"<tr>{r}</tr>")
    return f'<table class="cells"><tr>{head}</tr>' + "\n".join(rows) + "</table>"


def _envelope_figures(envelopes) -> list:
    """One figure per filter: panels per (dynamics, sites), median (solid) and p95 (dashed)
    RSS attitude error versus time per σθ (runs of every σω and r pooled)."""
    figs = []
    filters = []
    for cell, _ in envelopes:
        if cell["filter"] not in filters:
            filters.append(cell["filter"])
    for flt in filters:
        sub = [(c, e) for c, e in envelopes if c["filter"] == flt and len(e[0])]
        if not sub:
            continue
        panels = []
        for c, _ in sub:
            if (c["dynamics"], c["sites"], c.get("reflection", "none")) not in panels:
                panels.append((c["dynamics"], c["sites"], c.get("reflection", "none")))
        several_refl = len({p[2] for p in panels}) > 1
        thetas = sorted({c["sigma_theta_deg"] for c, _ in sub})
        cmap = plt.get_cmap("viridis")
        colours = {th: cmap(i / max(1, len(thetas) - 1) * 0.85) for i, th in enumerate(thetas)}
        ncol = 2 if len(panels) in (2, 4) else min(3, len(panels))
        nrow = int(np.ceil(len(panels) / ncol))
        # full page width whatever the number of panels (a lone panel used half the page)
        fig, axes = plt.subplots(nrow, ncol, figsize=figsize(12, (3.6 if ncol > 1 else 4.2) * nrow + 0.6),
                                 squeeze=False, sharey=True, layout="constrained")
        for ax, (dyn, ns, refl) in zip(axes.ravel(), panels):
            for c, (t, p50, p95, _p5) in sub:
                if (c["dynamics"], c["sites"], c.get("reflection", "none")) != (dyn, ns, refl):
                    continue
                col = colours[c["sigma_theta_deg"]]
                ax.semilogy(t, p50, color=col, lw=1.4)
                ax.semilogy(t, p95, color=col, lw=0.9, ls="--")
            ax.set_title(f"{_FILTER_NAME.get(flt, flt)} — {dyn}, {_fmt('sites', ns)}"
                         + (f", reflection {refl}" if several_refl else ""), fontsize=9)
            ax.set_xlabel("time since the first measurement (s)")
            ax.grid(True, which="both", alpha=0.3)
            ax.yaxis.set_major_formatter(_plain_log_formatter())
        for ax in axes[:, 0]:
            ax.set_ylabel("RSS attitude error (°)")
        for ax in axes.ravel()[len(panels):]:
            ax.set_visible(False)
        handles = [plt.Line2D([], [], color=colours[th], label=f"σθ = {th:g}°") for th in thetas]
        handles += [plt.Line2D([], [], color="k", label="median"),
                    plt.Line2D([], [], color="k", ls="--", lw=0.7, label="95th percentile")]
        fig.legend(handles=handles, loc="outside upper center", ncol=len(handles), fontsize=8)
        figs.append((flt, figure_to_data_uri(fig)))
    return figs


def _plain_log_formatter():
    """Log-axis tick labels as plain numbers (0.1, 1, 10), never 4×10⁰."""
    from matplotlib.ticker import FuncFormatter

    return FuncFormatter(lambda v, _: f"{v:g}")


_CSS = """
table.fig94 td{font-family:monospace;min-width:4.5em}
span.thesis{display:inline-block;border:1px solid #555;padding:0 3px;margin-top:2px;
font-size:10px}
th.corner{border:none}
"""


def write_study_report(path, summary: dict, envelopes=()) -> None:
    """Write the study report (module docstring) to ``path`` (atomic, self-contained HTML).

    Parameters
    ----------
    path : path of ``report.html``
    summary : the dict written to ``summary.json`` (:func:`lightcurve.studies.runner.summarize`)
    envelopes : sequence of ``(group dict, (t_s, p50_deg, p95_deg, p5_deg))`` from
        :func:`lightcurve.studies.metrics.rss_envelope`; the dict has ``filter``, ``dynamics``,
        ``sites``, ``sigma_theta_deg``
    """
    from .verdicts import filter_ranking, study_verdict

    cells = summary["cells"]
    keys = [k for k in summary.get("grid_keys", []) if k != "reflection"
            or len(_uniq(cells, "reflection")) > 1]
    ncol = {c: sum(1 for x in cells if x["color"] == c) for c in _BG}
    n_runs = sum(c["runs"] for c in cells)
    n_fail = sum(c["failures"] for c in cells)
    ind = summary.get("indicative")
    agr = summary.get("agreement")
    head = ""
    if agr is not None:
        byf = ", ".join(f"{_FILTER_NAME.get(f, f)} {v['agree']}/{v['compared']}"
                        for f, v in agr["by_filter"].items())
        head = (f"<p><b>Bernard (2021) Fig. {html.escape(str(summary.get('thesis_figure')))}, "
                f"cell by cell: {agr['agree']} of {agr['compared']} run cells agree ({byf}); "
                f"variant {html.escape(str(summary.get('variant')))}.</b></p>")
        if "self_agree" in agr:
            from ..studies.agreement import spread_text

            head += (f"<p>{html.escape(spread_text(agr))} Hover a box for its colour "
                     "probabilities.</p>")
    if ind:
        head += (f"<p><b>INDICATIVE</b>: {summary['runs_per_cell']} runs per cell; the thesis's "
                 "rule is defined for 100 runs and its thresholds are scaled to the run count "
                 "(a count c out of n read as c·100/n).</p>")
    title = f"Study {summary['study']}"
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}"
             f"</title><style>{PAGE_CSS}{_CSS}</style></head><body>",
             f"<h1>{html.escape(title)}</h1>",
             verdict_html(*study_verdict(cells)), head,
             f"<p>{len(cells)} cells × {summary['runs_per_cell']} runs; {n_runs} runs finished, "
             f"{n_fail} failed. Colours: {ncol['green']} green, {ncol['yellow']} yellow, "
             f"{ncol['red']} red. Study seed {summary['seed']}, hash "
             f"<code>{summary['study_hash'][:16]}</code>.</p>",
             "<h2>Which filter is better</h2>", _ranking_table_html(filter_ranking(cells)),
             "<h2>Runs outside the 3σ bound at the final epoch (layout of Bernard 2021 fig. 9.4)</h2>",
             "<p>Each box: number of runs whose final error component lies outside ±3σ of the "
             "filter's own covariance; first line attitude θx θy θz, second line rate ωx ωy ωz. "
             "Red: more than 10 runs outside for any component; yellow: 6–10 for some component, "
             "or two or more components with exactly 5; green: otherwise (per 100 runs). A "
             "'thesis' box gives the colour Bernard (2021) published for the cell (✓ agree, "
             "✗ disagree).</p>",
             fig94_table_html(cells, summary.get("not_run_grey", ())),
             "<h2>RSS attitude error versus time</h2>",
             "<p>Median (solid) and 95th percentile (dashed) over the runs of every σω and r, "
             "per initial attitude error σθ (colour).</p>"]
    for flt, uri in _envelope_figures(list(envelopes)):
        parts.append(f"<h3>{html.escape(_FILTER_NAME.get(flt, flt))}</h3><img src='{uri}' "
                     f"alt='RSS attitude error envelopes, {html.escape(flt)}'>")
    parts += ["<h2>Every cell</h2>", _cells_table_html(cells, keys), "</body></html>"]
    atomic_write_text(path, "\n".join(parts) + "\n")


def _ranking_table_html(rank) -> str:
    """The "which filter is better" table (:func:`lightcurve.report.verdicts.filter_ranking`)."""
    head = ("<tr><th>filter</th><th>best in (matched cells)</th><th>green</th><th>yellow</th>"
            "<th>red</th><th>failed runs</th><th>median final RSS attitude error (°)</th></tr>")
    rows = "".join(
        f"<tr><td>{html.escape(r['name'])}</td><td>{r['wins']} of {r['groups']}</td>"
        f"<td>{r['green']}</td><td>{r['yellow']}</td><td>{r['red']}</td><td>{r['failures']}</td>"
        f"<td>{r['median_rss_att_deg']:.4g}</td></tr>" for r in rank)
    return (f"<table>{head}{rows}</table><p class='small'>Cells are matched on every grid key but "
            "the filter; in each matched set the best filter has the best traffic light, then "
            "the fewest failed runs, then the lowest median final error.</p>")
