"""The thesis-variant particle filter of Bernard Fig. 9.5–9.7 at the settings the text leaves open.

Two settings of the plain bootstrap filter (Bernard ch. 6–7) are not printed in the thesis and
were chosen once: the roughening constant 𝒢 of Table 6.6 / Table 7.9 (eq. 6.62 gives the form,
not the value; §9.1 does not print it; we use 0.2) and the level of N_eff (eq. 6.61) below
which the filter resamples (§6.3: resampling "is not necessary after each step", no level
given; we use 0.5 N). This sweep reruns one BPF study (default
``pipelines/studies/thesis-bpf-leo.toml``: same seeds, cells, truth and options) once per
setting, changing one of the two at a time through the study's ``[filters.bpf]`` table, and
prints per setting and cell: the share of runs ending below 5° RSS, the largest number of runs
outside 3σ over the six components, and the median final RSS error; then ONE JSON line.

It measures whether the thesis's single-run claims (Fig. 9.5: converges from σθ = 60°,
§9.4.1: robust up to σθ = 20° with σω = 0.2°/s, Fig. 9.7: fails at 30°) hinge on a setting the
text leaves open; it is not a configuration of the thesis cases.

    python benchmarks/bernard_bpf_open.py [STUDY] --roughening 0.2 0.05 0.5 1 \\
        --ess-threshold 1.0 -o OUT [--workers 2] [--runs 20]

The first roughening value with the filter's own ESS level (0.5) is the reference row. Each
setting's output folder is ``OUT/<study>-G<𝒢>-ess<level>``; rerunning resumes the stored runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from lightcurve.filters.bpf import BPFConfig  # noqa: E402
from study_sweep import derived_text, run_derived  # noqa: E402

DEFAULT = ROOT / "pipelines" / "studies" / "thesis-bpf-leo.toml"
#: the reference settings: the particle filter's own defaults (𝒢 and the N_eff level)
G_REF, ESS_REF = BPFConfig.roughening, BPFConfig.ess_threshold


def variant_text(base: Path, roughening: float, ess: float) -> str:
    """The study TOML text of ``base`` with a ``[filters.bpf]`` table setting ``roughening``
    and ``ess_threshold``, a new study name, and the relative scenario path made absolute."""
    txt = derived_text(base, f"{base.stem}-G{roughening:g}-ess{ess:g}")
    if "[filters" in txt:
        raise SystemExit(f"{base}: expected no [filters.*] table (this sweep writes one)")
    return (txt.rstrip() + f"\n\n[filters.bpf]\nroughening = {roughening!r}\n"
            f"ess_threshold = {ess!r}\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("study", type=Path, nargs="?", default=DEFAULT,
                    help="a BPF study TOML (default: pipelines/studies/thesis-bpf-leo.toml)")
    ap.add_argument("--roughening", type=float, nargs="+", default=[G_REF],
                    help="𝒢 values (≥ 0) run with the reference ESS level; the first is the "
                    f"reference (default: {G_REF:g}, the filter's)")
    ap.add_argument("--ess-threshold", type=float, nargs="*", default=[],
                    help="N_eff/N levels in [0, 1] run with the first 𝒢 (1: resample at "
                    "every measurement, Gordon et al.'s bootstrap filter)")
    ap.add_argument("-o", "--output", type=Path, required=True, help="output folder")
    ap.add_argument("--workers", type=int, default=2, help="process-pool size (default 2)")
    ap.add_argument("--runs", type=int, default=None, help="runs per cell (default: the study's)")
    a = ap.parse_args(argv)
    if not a.study.is_file():
        print(f"{a.study}: no such study file", file=sys.stderr)
        return 2
    bad = [x for x in a.roughening if not x >= 0.0]
    if bad:
        print(f"--roughening: {bad[0]} is outside [0, inf)", file=sys.stderr)
        return 2
    bad = [x for x in a.ess_threshold if not 0.0 <= x <= 1.0]
    if bad:
        print(f"--ess-threshold: {bad[0]} is outside [0, 1]", file=sys.stderr)
        return 2
    settings = [(g, ESS_REF) for g in a.roughening]
    settings += [(a.roughening[0], e) for e in a.ess_threshold if e != ESS_REF]
    a.output.mkdir(parents=True, exist_ok=True)
    rows = []
    for g, ess in settings:
        out = a.output / f"{a.study.stem}-G{g:g}-ess{ess:g}"
        s = run_derived(variant_text(a.study, g, ess), out, workers=a.workers, runs=a.runs)
        cells = [{"sigma_theta_deg": c["sigma_theta_deg"],
                  "sigma_omega_deg_s": c["sigma_omega_deg_s"], "runs": c["runs"],
                  "below_5deg": c["below_5deg"], "max_outside_3sigma": max(c["outside_3sigma"]),
                  "rss_att_deg_median": c["rss_att_deg_median"]} for c in s["cells"]]
        row = {"roughening": g, "ess_threshold": ess, "cells": cells,
               "sum_max_outside": sum(c["max_outside_3sigma"] for c in cells)}
        rows.append(row)
        print(f"𝒢 = {g:g}, resample below N_eff = {ess:g} N: Σ max outside 3σ "
              f"{row['sum_max_outside']}; below 5° per cell (σθ/σω): " + ", ".join(
                  f"{c['sigma_theta_deg']:g}/{c['sigma_omega_deg_s']:g} "
                  f"{100 * c['below_5deg']:.0f} %" for c in cells), flush=True)
    print(json.dumps({"study": a.study.stem, "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
