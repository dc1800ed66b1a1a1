"""The thesis's published Monte Carlo tables as data, and cell-by-cell agreement with a study.

A table file (``pipelines/studies/tables/bernard2021-*.toml``, transcribed from Bernard 2021
Fig. 9.4 and Figs. B.1–B.4) holds ``figure``, ``title`` and eight ``[[row]]`` entries
(``dynamics``, ``sigma_omega_deg_s``, ``r_percent``, ``colors``: twelve cells — one site
σθ = 3°, 5°, 10°, then two sites, each σθ as EKF (our MEKF) and UKF). Cell colours are
``green`` / ``yellow`` / ``red``, ``grey`` (not run by the thesis) or ``unknown`` (lost in the
text; not compared).

:func:`thesis_color` gives a study cell's published colour (``None`` when the table has no
such cell, e.g. the particle filter or a σθ the thesis did not tabulate); :func:`agreement`
counts, per filter, the cells both ran (published green/yellow/red and ours finished) and
those whose colours match.

Monte Carlo spread (cells carrying ``color_probability``,
:func:`lightcurve.studies.metrics.color_probability`): ``expected_agree`` is the expected
number of matches if the published table were one 100-run Monte Carlo of *our* filter (the sum
over the compared cells of P(published colour)); ``self_agree`` the expected number of matches
between two independent 100-run Monte Carlos of our filter (Σ over cells of Σ_c P(c)²) — what
a perfect reproduction would reach on average. A disagreeing cell whose published colour has
P ≥ :data:`NOISE_LEVEL` is within our Monte Carlo noise (a test with a 5 % false-alarm rate
per cell when the two filters are the same).

Order of a table (:func:`order_inversions`): a larger initial error (σθ or σω) with everything
else equal is a harder case, so a colour better than that of a strictly easier cell of the same
filter, dynamics, site count and noise level is out of order. Such a cell may still be right
(a filter's larger initial covariance can help it), but an inversion in a published table is a
sign of its own Monte Carlo noise.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError

__all__ = ["ThesisTable", "load_thesis_table", "thesis_color", "agreement", "TABLE_COLORS",
           "COMPARED", "NOISE_LEVEL", "spread_text", "order_inversions", "TABLE_KEYS",
           "table_key"]

TABLE_COLORS = ("green", "yellow", "red", "grey", "unknown")
#: published colours that are compared with ours
COMPARED = ("green", "yellow", "red")
#: a published colour with at least this probability under our Monte Carlo spread is "within
#: Monte Carlo noise" (module docstring)
NOISE_LEVEL = 0.05
#: the fields that identify a cell of a published table, in the order of the keys of
#: :attr:`ThesisTable.cells`
TABLE_KEYS = ("filter", "dynamics", "sites", "sigma_theta_deg", "sigma_omega_deg_s", "r_percent")
_SIGMA_THETA = (3.0, 5.0, 10.0)
_FILTERS = ("mekf", "ukf")


@dataclass
class ThesisTable:
    """A published Monte Carlo table: ``cells`` maps (filter, dynamics, sites, σθ, σω, r) to
    its colour."""

    figure: str
    title: str
    cells: dict = field(default_factory=dict)
    source: str = ""
    text: str = ""      # the file's text as read (part of a study's input hash)

    def color(self, filter, dynamics, sites, sigma_theta_deg, sigma_omega_deg_s, r_percent):
        """The published colour of one cell, or None (not in the table)."""
        return self.cells.get((str(filter), str(dynamics), int(sites), float(sigma_theta_deg),
                               float(sigma_omega_deg_s), float(r_percent)))


def load_thesis_table(path) -> ThesisTable:
    """Load a table file (module docstring); InputError naming the file and key otherwise."""
    from ..io.tomlio import Section, load_toml

    path = Path(path)
    doc, text = load_toml(path, with_text=True)
    root = Section(doc, file=path)
    fig = root.str("figure")
    title = root.str("title", "")
    root.str("columns", "")
    tab = ThesisTable(figure=fig, title=title, source=str(path), text=text)
    rows = root.sections("row")
    if not rows:
        raise InputError("a thesis table needs [[row]] entries", file=path, field="row")
    for r in rows:
        dyn = r.str("dynamics", choices=("controlled", "uncontrolled"))
        so = r.float("sigma_omega_deg_s", min=0.0, min_open=True)
        rp = r.float("r_percent", min=0.0, min_open=True, max=100.0)
        cols = r.raw("colors")
        if (not isinstance(cols, list) or len(cols) != 12
                or any(c not in TABLE_COLORS for c in cols)):
            raise InputError("expected 12 colours", file=path, field=f"{r.name}.colors",
                             value=cols, allowed=", ".join(TABLE_COLORS))
        r.check_unknown()
        i = 0
        for sites in (1, 2):
            for st in _SIGMA_THETA:
                for flt in _FILTERS:
                    key = (flt, dyn, sites, st, so, rp)
                    if key in tab.cells:
                        raise InputError("duplicate row", file=path, field=r.name,
                                         value=f"{dyn}, {so}, {rp}")
                    tab.cells[key] = cols[i]
                    i += 1
    root.check_unknown()
    return tab


def thesis_color(table, cell: dict):
    """Published colour of a study cell dict (keys of :data:`lightcurve.studies.study.GRID_KEYS`),
    or None without a table, for a reflection model, or for a cell the table lacks."""
    if table is None or cell.get("reflection", "none") != "none":
        return None
    return table.color(cell["filter"], cell["dynamics"], cell["sites"], cell["sigma_theta_deg"],
                       cell["sigma_omega_deg_s"], cell["r_percent"])


def agreement(cells) -> dict:
    """Agreement counts over summary cells carrying ``thesis_color`` and ``color``.

    Returns ``{"compared": n, "agree": k, "by_filter": {filter: {"compared", "agree"}},
    "disagree": [cell keys…]}``; a cell counts when its published colour is green, yellow or
    red and it has finished runs here. When every compared cell carries ``color_probability``
    the result also has ``expected_agree``, ``self_agree`` and ``within_noise`` (disagreeing
    cells whose published colour has P ≥ :data:`NOISE_LEVEL`), and each disagreeing entry its
    ``thesis_color_probability`` (module docstring).
    """
    out = {"compared": 0, "agree": 0, "by_filter": {}, "disagree": []}
    spread = True
    expected = selfa = 0.0
    for c in cells:
        tc = c.get("thesis_color")
        if tc not in COMPARED or not c.get("runs"):
            continue
        f = out["by_filter"].setdefault(c["filter"], {"compared": 0, "agree": 0})
        out["compared"] += 1
        f["compared"] += 1
        prob = c.get("color_probability") or None
        if prob is None:
            spread = False
        else:
            expected += float(prob.get(tc, 0.0))
            selfa += sum(float(v) ** 2 for v in prob.values())
        if c["color"] == tc:
            out["agree"] += 1
            f["agree"] += 1
        else:
            d = {k: c[k] for k in TABLE_KEYS}
            d |= {"color": c["color"], "thesis_color": tc}
            if prob is not None:
                d["thesis_color_probability"] = float(prob.get(tc, 0.0))
            out["disagree"].append(d)
    if spread and out["compared"]:
        out["expected_agree"] = expected
        out["self_agree"] = selfa
        out["within_noise"] = sum(d["thesis_color_probability"] >= NOISE_LEVEL
                                  for d in out["disagree"])
    return out


def spread_text(agr: dict) -> str:
    """One sentence on the Monte Carlo spread of an :func:`agreement` result that carries it
    (``self_agree``; module docstring), for the command line and the study report."""
    return (f"Monte Carlo spread of the colours: a perfect reproduction of these filters would "
            f"agree with itself on {agr['self_agree']:.1f} of {agr['compared']} cells on "
            f"average; the published table, read as one 100-run Monte Carlo of ours, on "
            f"{agr['expected_agree']:.1f}; {agr['within_noise']} of {len(agr['disagree'])} "
            f"disagreeing cells have the published colour with probability >= "
            f"{100 * NOISE_LEVEL:.0f} % in such a Monte Carlo (within noise).")


def table_key(cell: dict) -> tuple:
    """The :data:`TABLE_KEYS` values of a summary cell dict, as a key of
    :attr:`ThesisTable.cells` and of :func:`order_inversions`."""
    return tuple(cell[k] for k in TABLE_KEYS)


def order_inversions(cells: dict) -> dict:
    """Cells whose colour is better than that of a strictly easier cell (module docstring).

    ``cells`` maps ``(filter, dynamics, sites, σθ, σω, r)`` (as :attr:`ThesisTable.cells`) to a
    colour; only green / yellow / red cells take part. Returns ``{key: [easier keys]}``: for
    each out-of-order cell, the cells with the same filter, dynamics, sites and r, σθ and σω
    both no larger (one smaller), and a worse colour (green < yellow < red)."""
    rank = {c: i for i, c in enumerate(COMPARED)}
    col = {k: rank[c] for k, c in cells.items() if c in rank}
    out = {}
    for k, c in col.items():
        worse = [e for e, ce in col.items()
                 if e[:3] == k[:3] and e[5] == k[5] and e != k
                 and e[3] <= k[3] and e[4] <= k[4] and ce > c]
        if worse:
            out[k] = sorted(worse)
    return out
