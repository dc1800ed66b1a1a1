"""The thesis-variant UKF of one Bernard table at several scaled-unscented spreads α.

Bernard §6.2.2 gives only the range of α ("a term between 0 and 1", eq. 6.21–6.23 with β = 2,
κ ≥ 0); the thesis studies use the thesis variant's α = 0.25 (β = 2, κ = 0). This sweep runs
the UKF cells of one thesis study (``pipelines/studies/thesis-*.toml``: same seeds, cells,
truth and options; only ``filter = ["ukf"]`` and ``alpha`` differ) once per α with ``lightcurve compare`` and prints,
per α: the agreement with the published table, the colour counts, the sum over cells of the
largest outside-3σ count, the self-agreement of the Monte Carlo spread
(:mod:`lightcurve.studies.agreement`), and the cells that change colour against the first α
given; then ONE JSON line. It measures whether agreement depends on α smoothly (a plateau) or
at one value only, for the one-time choice that §6.2.2 leaves open; it is not a configuration
of the thesis cases.

    python benchmarks/bernard_ukf_alpha.py pipelines/studies/thesis-fig9-4.toml \\
        --alpha 1 0.75 0.5 0.25 0.1 0.001 -o OUT [--workers 2] [--runs 100]

Each α's output folder is ``OUT/<study>-alpha-<α>``; rerunning resumes the stored runs.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from lightcurve.studies.agreement import table_key  # noqa: E402
from lightcurve.studies.metrics import COLORS  # noqa: E402
from study_sweep import derived_text, run_derived  # noqa: E402


def variant_text(base: Path, alpha: float) -> str:
    """The study TOML text of ``base`` with the UKF cells only, ``alpha`` in [options] and the
    relative paths (published table, scenario template) made absolute."""
    txt = derived_text(base, f"{base.stem}-alpha-{alpha:g}")
    txt, n = re.subn(r'^filter = \[[^\]]*\]', 'filter = ["ukf"]', txt, count=1, flags=re.M)
    if n != 1 or "[options]" not in txt or re.search(r"^alpha\s*=", txt, flags=re.M):
        raise SystemExit(f"{base}: expected a [grid] filter list, an [options] table and no "
                         "alpha setting")
    return txt.replace("[options]", f"[options]\nalpha = {alpha!r}", 1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("study", type=Path, help="a thesis study TOML (pipelines/studies/thesis-*.toml)")
    ap.add_argument("--alpha", type=float, nargs="+", required=True,
                    help="spreads to run, each in (0, 1]; the first is the reference")
    ap.add_argument("-o", "--output", type=Path, required=True, help="output folder")
    ap.add_argument("--workers", type=int, default=2, help="process-pool size (default 2)")
    ap.add_argument("--runs", type=int, default=None, help="runs per cell (default: the study's)")
    a = ap.parse_args(argv)
    bad = [x for x in a.alpha if not 0.0 < x <= 1.0]
    if bad:
        print(f"--alpha: {bad[0]} is outside (0, 1] (Bernard §6.2.2)", file=sys.stderr)
        return 2
    a.output.mkdir(parents=True, exist_ok=True)
    rows, ref = [], None
    for alpha in a.alpha:
        out = a.output / f"{a.study.stem}-alpha-{alpha:g}"
        s = run_derived(variant_text(a.study, alpha), out, workers=a.workers, runs=a.runs)
        cells = {table_key(c): c for c in s["cells"]
                 if c.get("thesis_color") in COLORS}
        agr = s["agreement"]
        row = {"alpha": alpha, "agree": agr["agree"], "compared": agr["compared"],
               "self_agree": agr.get("self_agree"),
               "colors": {k: sum(c["color"] == k for c in cells.values()) for k in COLORS},
               "sum_max_outside": sum(max(c["outside_3sigma"]) for c in cells.values())}
        if ref is None:
            ref = cells
        else:
            ch = [k for k in cells if k in ref and cells[k]["color"] != ref[k]["color"]]
            row["changed"] = len(ch)
            row["flips"] = sum(cells[k]["color"] == cells[k]["thesis_color"] for k in ch)
            row["breaks"] = sum(ref[k]["color"] == ref[k]["thesis_color"] for k in ch)
        rows.append(row)
        sa = f"{row['self_agree']:.1f}" if row["self_agree"] is not None else "–"
        print(f"α = {alpha:g}: UKF {row['agree']}/{row['compared']} agree; green/yellow/red "
              f"{row['colors']['green']}/{row['colors']['yellow']}/{row['colors']['red']}; "
              f"Σ max outside {row['sum_max_outside']}; self-agreement {sa}"
              + (f"; vs α = {a.alpha[0]:g}: {row['changed']} changed, {row['flips']} flips, "
                 f"{row['breaks']} breaks" if "changed" in row else ""), flush=True)
    print(json.dumps({"study": a.study.stem, "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
