"""Rerun every Bernard (2021) study that docs/reproduction.md reads, then rewrite its Bernard
section alone (``lightcurve reproduction --only bernard``; the CSS section stays as it is).

The studies are the thesis studies under ``pipelines/studies/`` (the five tables, their
``-robust`` twins, ``thesis-claims-*``, ``thesis-bpf-*``) and every ablation under
``pipelines/studies/ablations/``; ``--skip`` leaves some out (default: ``thesis-fig9-4-bpf``, a
BPF column over the whole Fig. 9.4 grid that the section does not read, ≈ 25 min on 2 cores).
Each study runs with ``lightcurve compare STUDY -o OUT/<name> --workers W -q`` and resumes the
runs already stored in ``OUT/<name>``, so an interrupted regeneration goes on where it stopped.
With ``--reflection-kf`` the §10.4/§10.7/§10.8 runs (``benchmarks/reflection_kf.py``, a few
seconds each) are run too, once per filter variant: the thesis variant with the eq. 5.8 diffuse
term (``OUT/reflection_kf-thesis.json``), then the robust variant with the physical form
(``OUT/reflection_kf-robust.json``); a file already there is reused. With ``--spikes`` the
§9.4.5 spike counts of the thesis truths (``benchmarks/bernard_spikes.py``, ≈ 35 s) go to
``OUT/spikes.json`` (reused when there).

Prints one line per study (name, runs per cell, wall seconds) and the total; ``--list`` prints
the studies and stops.

    python benchmarks/bernard_reproduction.py -o OUT [--workers 2] [--skip NAME ...]
        [--reflection-kf] [--spikes] [--doc docs/reproduction.md] [--list]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ROOT / "pipelines" / "studies"
#: filter variant and Cook–Torrance form of each benchmarks/reflection_kf.py run (thesis first)
KF_VARIANTS = (("thesis", "thesis"), ("robust", "physical"))


def studies(skip) -> list[Path]:
    """The study files, base tables first (their outputs are the ones read most), then the
    other thesis studies, then the ablations; each group sorted by name."""
    def by_name(paths):
        return sorted(paths, key=lambda p: p.stem)

    base = by_name(STUDIES.glob("thesis-fig*.toml"))
    other = by_name(p for p in STUDIES.glob("thesis-*.toml") if p not in base)
    abl = by_name((STUDIES / "ablations").glob("thesis-*.toml"))
    return [p for p in base + other + abl if p.stem not in skip]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", required=True, type=Path, metavar="DIR",
                    help="folder of the study outputs (one sub-folder per study; reused to resume)")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                    help="process-pool size of each study (default: all CPUs)")
    ap.add_argument("--skip", nargs="*", default=["thesis-fig9-4-bpf"], metavar="NAME",
                    help="study names to leave out (default: thesis-fig9-4-bpf)")
    ap.add_argument("--reflection-kf", action="store_true",
                    help="also run benchmarks/reflection_kf.py for the ch. 10 rows")
    ap.add_argument("--spikes", action="store_true",
                    help="also run benchmarks/bernard_spikes.py for the sec. 9.4.5 row")
    ap.add_argument("--doc", type=Path, default=ROOT / "docs" / "reproduction.md",
                    help="reproduction file whose Bernard section is rewritten "
                    "(default: docs/reproduction.md)")
    ap.add_argument("--list", action="store_true", help="print the studies and stop")
    a = ap.parse_args()
    files = studies(set(a.skip))
    if a.list:
        print("\n".join(str(p.relative_to(ROOT)) for p in files))
        return 0
    a.output.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    t_all = time.perf_counter()
    for p in files:
        t0 = time.perf_counter()
        r = subprocess.run([sys.executable, "-m", "lightcurve", "compare", str(p), "-o",
                            str(a.output / p.stem), "--workers", str(a.workers), "-q"],
                           env=env, capture_output=True, text=True)
        if r.returncode != 0:
            sys.stderr.write(r.stderr)
            print(f"{p.stem}: failed (exit {r.returncode})", file=sys.stderr)
            return r.returncode
        print(f"{p.stem}: {time.perf_counter() - t0:.0f} s", flush=True)
    extra = []
    if a.reflection_kf:
        extra = ["--reflection-kf"]
        for variant, form in KF_VARIANTS:
            kf = a.output / f"reflection_kf-{variant}.json"
            if not kf.exists():
                t0 = time.perf_counter()
                r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "reflection_kf.py"),
                                    "--variant", variant, "--cook-torrance", form],
                                   env=env, capture_output=True, text=True)
                if r.returncode != 0:
                    sys.stderr.write(r.stderr)
                    return r.returncode
                kf.write_text(r.stdout)
                print(f"reflection_kf ({variant}): {time.perf_counter() - t0:.0f} s", flush=True)
            extra.append(str(kf))
    if a.spikes:
        sp = a.output / "spikes.json"
        if not sp.exists():
            t0 = time.perf_counter()
            r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bernard_spikes.py"),
                                "-o", str(sp)], env=env, capture_output=True, text=True)
            if r.returncode != 0:
                sys.stderr.write(r.stderr)
                return r.returncode
            print(f"bernard_spikes: {time.perf_counter() - t0:.0f} s", flush=True)
        extra += ["--spikes", str(sp)]
    cmd = [sys.executable, "-m", "lightcurve", "reproduction", "--only", "bernard", "-o", str(a.doc)]
    for p in files:
        cmd += ["--study", str(a.output / p.stem)]
    r = subprocess.run(cmd + extra, env=env)
    print(f"total: {time.perf_counter() - t_all:.0f} s for {len(files)} studies", flush=True)
    return r.returncode


if __name__ == "__main__":
    raise SystemExit(main())
