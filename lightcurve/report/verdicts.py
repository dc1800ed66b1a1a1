"""One-line verdicts of results (the first line of every report; :mod:`lightcurve.report.style`).

A verdict is ``(level, text)`` with level ``"ok"``, ``"warn"`` or ``"fail"`` and one plain
sentence. The rules are stated in each function; they use only the filters' own consistency
measures (3σ bounds, NIS) and, where a truth exists, the errors against it.

* :func:`estimate_verdict` — one filter run.
* :func:`filter_ranking` / :func:`study_verdict` — which filter is better in a Monte Carlo study
  (cells of ``compare``'s ``summary.json``).
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

__all__ = ["estimate_verdict", "filter_ranking", "study_verdict", "FILTER_NAMES"]

FILTER_NAMES = {"mekf": "EKF (MEKF)", "ukf": "UKF", "bpf": "PF"}
_RANK = {"green": 0, "yellow": 1, "red": 2}


def estimate_verdict(est) -> tuple:
    """Verdict of one :class:`~lightcurve.filters.result.Estimate`.

    fail: diverged. warn: with a truth, a final error component outside 3σ; without one, fewer
    than 95 % of the innovations inside ±3√S (for a consistent filter 99.7 % are). ok otherwise.
    """
    name = FILTER_NAMES.get(est.method, est.method)
    if est.diverged:
        return "fail", f"{name} diverged: {est.divergence_reason}."
    s = est.summary()
    s3 = 3 * float(np.linalg.norm(est.att_sigma_deg[-1]))
    nu, S = np.asarray(est.innovations, float), np.asarray(est.innovation_var, float)
    ok = np.isfinite(nu) & np.isfinite(S) & (S > 0)
    frac = float(np.mean(np.abs(nu[ok]) <= 3 * np.sqrt(S[ok]))) if ok.any() else float("nan")
    if "final_att_error_rss_deg" in s:
        e = s["final_att_error_rss_deg"]
        if s["inside_3sigma"]:
            return "ok", (f"{name} converged: final attitude error {e:.2g}° within its 3σ bound "
                          f"({s3:.2g}° RSS); rate error {s['final_omega_error_rss_deg_s']:.2g} °/s.")
        return "warn", (f"{name} is overconfident: final attitude error {e:.2g}° with a 3σ bound "
                        f"of {s3:.2g}° (RSS): some component lies outside 3σ.")
    if np.isfinite(frac) and frac < 0.95:
        return "warn", (f"{name}: only {100 * frac:.0f} % of the innovations inside ±3√S "
                        "(expected 99.7 %): the model does not fit the measurements well.")
    return "ok", (f"{name}: final attitude 3σ {s3:.2g}° (RSS); {100 * frac:.0f} % of the "
                  "innovations inside ±3√S (no truth to compare with).")


def filter_ranking(cells) -> list:
    """Rank the filters of a study over the cells they share.

    Cells are matched on every grid key but the filter. Per filter: number of cells, of
    green / yellow / red cells, failed runs, the median over its cells of the median final RSS
    attitude error, and ``wins`` — in how many matched groups it was the best, i.e. the best
    traffic light, then the fewest failed runs, then the lowest median error. Returns one dict
    per filter, best first (most wins, then best median error).
    """
    keys = [k for k in ("dynamics", "sites", "sigma_theta_deg", "sigma_omega_deg_s",
                        "r_percent", "reflection") if any(k in c for c in cells)]
    groups = defaultdict(list)
    for c in cells:
        groups[tuple(c.get(k) for k in keys)].append(c)
    stats = {}
    for c in cells:
        f = c["filter"]
        st = stats.setdefault(f, {"filter": f, "name": FILTER_NAMES.get(f, f), "cells": 0,
                                  "green": 0, "yellow": 0, "red": 0, "failures": 0, "wins": 0,
                                  "_med": [], "groups": 0})
        st["cells"] += 1
        st[c["color"]] += 1
        st["failures"] += int(c.get("failures", 0))
        st["_med"].append(c.get("rss_att_deg_median", np.nan))
    for g in groups.values():
        if len({c["filter"] for c in g}) < 2:
            continue
        for c in g:
            stats[c["filter"]]["groups"] += 1
        best = min(g, key=lambda c: (_RANK[c["color"]], c.get("failures", 0),
                                     np.nan_to_num(c.get("rss_att_deg_median", np.inf),
                                                   nan=np.inf)))
        stats[best["filter"]]["wins"] += 1
    out = []
    for st in stats.values():
        m = np.asarray(st.pop("_med"), float)
        st["median_rss_att_deg"] = float(np.nanmedian(m)) if np.any(np.isfinite(m)) else float("nan")
        out.append(st)
    out.sort(key=lambda s: (-s["wins"], np.nan_to_num(s["median_rss_att_deg"], nan=np.inf)))
    return out


def study_verdict(cells) -> tuple:
    """Which filter is better, in one sentence (:func:`filter_ranking`).

    ok: the best filter is green in every cell and no run failed; warn: it has yellow or red
    cells or failed runs; fail: no filter has a green cell. With a single filter the sentence
    says how consistent it is.
    """
    rank = filter_ranking(cells)
    if not rank:
        return "fail", "no cell finished."
    b = rank[0]
    level = "ok" if (b["green"] == b["cells"] and b["failures"] == 0) else "warn"
    if all(r["green"] == 0 for r in rank):
        level = "fail"
    cons = f"consistent (green) in {b['green']} of {b['cells']} cells"
    if len(rank) == 1:
        return level, (f"{b['name']} is {cons}; median final attitude error "
                       f"{b['median_rss_att_deg']:.3g}°" + (f"; {b['failures']} runs failed."
                                                            if b["failures"] else "."))
    others = "; ".join(f"{r['name']} best in {r['wins']}, green in {r['green']} of {r['cells']}, "
                       f"median {r['median_rss_att_deg']:.3g}°" for r in rank[1:])
    if b["wins"] == 0:
        return level, "no filter is better than the others in any matched cell; " + others + "."
    return level, (f"{b['name']} is the better filter here: best in {b['wins']} of {b['groups']} "
                   f"matched cells, {cons}, median final attitude error "
                   f"{b['median_rss_att_deg']:.3g}° ({others}).")
