"""One whole-table reading of Bernard Fig. 9.4 and B.1–B.4, composed from stored study outputs.

Each cell of a published table takes its colour from the study output that applies the
reading to it:

* MEKF, controlled: the thesis-variant base study (``thesis-<table>``);
* MEKF, uncontrolled: ``thesis-<table>-ablation-glints-hidden`` (the filters do not see the
  specular spikes that Bernard §9.4.5 says the thesis's uncontrolled curves lack);
* UKF, controlled: ``thesis-<table>-ablation-ukf-alpha`` (α = 0.5; §6.2.2 leaves α open);
* UKF, uncontrolled: ``thesis-<table>-ablation-glints-hidden-ukf-alpha`` (both).

This is a measurement of how far two readings the text leaves open (α) or contradicts in our
truth (the spikes) carry the agreement, not a configuration of the thesis cases. For every
table it prints the agreement of the base study and of the reading (by filter and half), the
Monte Carlo spread of the reading (:mod:`lightcurve.studies.agreement`: self-agreement,
expected agreement, cells within noise; colour probabilities from the run files where the
summaries predate them) and the reading's disagreeing cells, then ONE JSON line.

    python benchmarks/bernard_reading.py --study DIR [DIR ...]

``--study``: output folders of ``lightcurve compare`` (base studies and ablations; identified by
the study name in their ``summary.json``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lightcurve.studies.agreement import agreement, spread_text  # noqa: E402
from lightcurve.studies.reproduction import (_KEYS, _TABLES, _cell,  # noqa: E402
                                             add_color_spread, load_summaries)

#: (filter, dynamics) → suffix of the study whose cell applies the reading
READING = {("mekf", "controlled"): "",
           ("mekf", "uncontrolled"): "-ablation-glints-hidden",
           ("ukf", "controlled"): "-ablation-ukf-alpha",
           ("ukf", "uncontrolled"): "-ablation-glints-hidden-ukf-alpha"}


def compose(sums: dict, name: str):
    """The reading's cells of table ``name`` (copies of the source studies' cells), or None
    when a source study is missing."""
    base = sums.get(name)
    if base is None or any(name + suf not in sums for suf in READING.values()):
        return None
    cells = []
    for c in base["cells"]:
        if c.get("thesis_color") is None:
            continue
        src = sums[name + READING[(c["filter"], c["dynamics"])]]
        rc = _cell(src, **{k: c[k] for k in _KEYS})
        if rc is None:
            return None
        cells.append(dict(rc, thesis_color=c["thesis_color"]))
    return cells


def _by_half(cells):
    out = {}
    for c in cells:
        if c.get("thesis_color") not in ("green", "yellow", "red"):
            continue
        k = f"{c['filter']} {c['dynamics']}"
        n, a = out.get(k, (0, 0))
        out[k] = (n + 1, a + (c["color"] == c["thesis_color"]))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--study", nargs="+", required=True,
                   help="output folders of 'lightcurve compare' (bases and ablations)")
    a = p.parse_args(argv)
    sums = load_summaries(a.study)
    result = {}
    for name, fig, what in _TABLES:
        if name not in sums:
            continue
        needed = [name + s for s in READING.values()]
        for n in needed:
            if n in sums:
                add_color_spread(sums[n], keys=sums[name]["cells"])
        cells = compose(sums, name)
        if cells is None:
            print(f"Fig. {fig}: a source study is missing ({', '.join(needed)})")
            continue
        base = sums[name]["agreement"]
        agr = agreement(cells)
        halves = _by_half(cells)
        print(f"\nFig. {fig} ({what}): base {base['agree']}/{base['compared']}, reading "
              f"{agr['agree']}/{agr['compared']} ({100 * agr['agree'] / agr['compared']:.0f} %)")
        print("  " + "; ".join(f"{k} {a_}/{n}" for k, (n, a_) in halves.items()))
        if "self_agree" in agr:
            print("  " + spread_text(agr))
        for d in agr["disagree"]:
            print(f"  {d['filter'].upper():4s} {d['dynamics']:12s} {d['sites']} "
                  f"{d['sigma_theta_deg']:4g} {d['sigma_omega_deg_s']:4g} {d['r_percent']:3g}  "
                  f"ours {d['color']:6s} thesis {d['thesis_color']:6s} "
                  f"P(thesis) {100 * d.get('thesis_color_probability', float('nan')):.1f} %")
        result[name] = {"base": {"agree": base["agree"], "compared": base["compared"]},
                        "reading": {k: agr[k] for k in ("agree", "compared", "by_filter",
                                                        "expected_agree", "self_agree",
                                                        "within_noise") if k in agr},
                        "halves": {k: {"compared": n, "agree": a_}
                                   for k, (n, a_) in halves.items()},
                        "disagree": agr["disagree"]}
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
