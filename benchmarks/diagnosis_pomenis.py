"""Diagnosis of the real Pomenis Starlink recording: held-out numbers, transfer, run time.

Runs ``lightcurve diagnose`` on ``../shared/data/starlink_pomenis/pomenis_observations.csv``
with ``pipelines/real/starlink_pomenis.toml`` (the published two-surface model; 1,173 rows):

1. the full diagnosis, effects chosen by leave-nights-out held-out gain, with the baseline and
   the final model also held out leave-passes-out (the CSV has no satellite id, so
   leave-satellites-out is not possible; a pass — a run of rows without a 5-minute gap — is
   the finest unit that keeps one satellite's consecutive rows together);
2. the transfer: the recording split into two halves by night (first vs second half of the
   nights in time, and odd vs even nights); each half diagnosed, its fitted model applied
   unchanged (``--apply``) to the other half, against the unfitted model there;
3. where the time goes (``timings_s`` of diagnosis.json), the wall time and the CPU time of
   the full diagnosis (on a shared machine the wall time mostly measures the others' load).

Prints ONE JSON line (shared footer: wall time, cores, numba threads, load). The published
fit's RMS on these rows is 0.762 mag (Fankhauser et al. 2023).

Usage: python benchmarks/diagnosis_pomenis.py [--quick]   (--quick: only step 1)
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from reflection_bpf import print_with_machine  # noqa: E402  (shared JSON footer)

from lightcurve.studies.runner import limit_blas_threads  # noqa: E402

limit_blas_threads()   # small dense fits: threaded BLAS only spins (children inherit the env)

SCEN = ROOT / "pipelines" / "real" / "starlink_pomenis.toml"
PUBLISHED_RMS = 0.762


def _split(csv_path, tmp):
    """Two pairs of half files (by night order, and odd/even nights)."""
    from datetime import datetime, timedelta

    lines = csv_path.read_text(encoding="utf-8").splitlines()
    head = [ln for ln in lines if ln.startswith("#") or not ln.strip()]
    body = [ln for ln in lines if ln.strip() and not ln.startswith("#")]
    header, rows = body[0], body[1:]

    def night(row):   # local night at Mount Lemmon (UTC − 7.4 h, shifted by 12 h)
        t = datetime.fromisoformat(row.split(",", 1)[0])
        return (t - timedelta(hours=7.386 + 12)).date()

    nights = sorted({night(r) for r in rows})
    idx = {n: i for i, n in enumerate(nights)}
    out = {}
    for name, sel in (("by_time", lambda i: i < len(nights) // 2), ("odd_even", lambda i: i % 2 == 0)):
        a = [r for r in rows if sel(idx[night(r)])]
        b = [r for r in rows if not sel(idx[night(r)])]
        pa, pb = tmp / f"{name}_a.csv", tmp / f"{name}_b.csv"
        pa.write_text("\n".join(head + [header] + a) + "\n", encoding="utf-8")
        pb.write_text("\n".join(head + [header] + b) + "\n", encoding="utf-8")
        out[name] = (pa, pb, len(a), len(b))
    return out


def _diagnose(csv_path, out_dir, cv="nights,passes"):
    from lightcurve.cli import main

    t0 = time.perf_counter()
    c0 = time.process_time()
    rc = main(["diagnose", str(csv_path), "--scenario", str(SCEN), "-o", str(out_dir), "--cv", cv,
               "--quiet"])
    wall = time.perf_counter() - t0
    if rc != 0:
        raise SystemExit(f"diagnose failed with exit code {rc}")
    js = json.loads((out_dir / "diagnosis.json").read_text())
    js["_cpu_s"] = time.process_time() - c0
    return js, wall


def _apply(fit_json, csv_path, out_dir):
    from lightcurve.cli import main

    rc = main(["diagnose", str(csv_path), "--scenario", str(SCEN), "--apply", str(fit_json), "-o",
               str(out_dir), "--quiet"])
    if rc != 0:
        raise SystemExit(f"diagnose --apply failed with exit code {rc}")
    return json.loads((out_dir / "transfer.json").read_text())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="only the full diagnosis")
    a = ap.parse_args()
    from lightcurve._paths import shared_data_dir

    shared = shared_data_dir()
    csv_path = None if shared is None else shared / "starlink_pomenis" / "pomenis_observations.csv"
    if csv_path is None or not csv_path.exists():
        raise SystemExit("../shared/data/starlink_pomenis is not available")
    t0 = time.perf_counter()
    out = {"benchmark": "diagnosis_pomenis", "published_rms_mag": PUBLISHED_RMS}
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        js, wall = _diagnose(csv_path, tmp / "full")
        out["n_rows"] = js["n"]
        out["full"] = {"wall_s": round(wall, 1), "cpu_s": round(js["_cpu_s"], 1), "timings_s": {k: round(v, 2) for k, v in js["timings_s"].items()},
                       "verdict_line": js["verdict_line"], "chosen": js["chosen"],
                       "unidentified": [u["name"] for u in js["unidentified"]],
                       "in_sample_rms": [js["baseline"]["rms"], js["final"]["rms"]],
                       "held_out": {s["method"]: {"n_groups": s.get("n_groups"),
                                                  "rms_unfitted": s["baseline"]["rms"],
                                                  "rms_final": s["final"]["rms"],
                                                  "r_unfitted": s["baseline"]["r"],
                                                  "r_final": s["final"]["r"]}
                                    for s in js["cross_validation"]["schemes"] if s.get("possible")},
                       "params": {c["name"]: {k: (v.get("value"), v.get("sd"), v.get("status"))
                                              for k, v in s["params"].items()}
                                  for c in js["candidates"] for s in c["steps"]
                                  if str(s.get("decision", "")).startswith("added")}}
        if not a.quick:
            out["transfer"] = {}
            for name, (pa, pb, na, nb) in _split(csv_path, tmp).items():
                res = {}
                for src, dst, tag in ((pa, pb, "a_to_b"), (pb, pa, "b_to_a")):
                    jsa, wa = _diagnose(src, tmp / f"{name}_{tag}_fit", cv="nights")
                    tr = _apply(tmp / f"{name}_{tag}_fit" / "diagnosis.json", dst, tmp / f"{name}_{tag}_apply")
                    comps = {r["component"]: {"rms": r["rms"], "transfers": r["transfers"]}
                             for r in tr["components"]}
                    res[tag] = {"fitted_on_rows": na if tag == "a_to_b" else nb,
                                "chosen": jsa["chosen"], "components": comps,
                                "verdict": tr["verdict"], "fit_wall_s": round(wa, 1)}
                out["transfer"][name] = res
    print_with_machine(out, t0)


if __name__ == "__main__":
    main()
