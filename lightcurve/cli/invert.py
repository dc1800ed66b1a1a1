"""``lightcurve invert``: attitude filters on lightcurve files."""

from __future__ import annotations

import sys
from pathlib import Path

from ._args import SEED, csv_ints, csv_list, number

__all__ = ["register"]


def _cmd_invert(args) -> int:
    from ..studies.batch import expand_inputs, invert_files

    n_files = len(expand_inputs(args.files))  # a pattern matching nothing: InputError, exit 2
    bar = n_files > 1 and not args.quiet

    def report(text, kind="info"):
        if kind == "info":
            line, stream = text, sys.stdout
        else:
            line, stream = f"lightcurve: {kind}: {text}", sys.stderr
        if bar:
            from tqdm import tqdm

            tqdm.write(line, file=stream)
        else:
            print(line, file=stream)

    res = invert_files(args.files, args.method, args.output, workers=args.workers,
                       scheduler=args.scheduler, dask_local=args.dask_local, progress=bar,
                       plot=args.plot, report=report, seed=args.seed,
                       sigma_theta_deg=args.sigma_theta_deg,
                       sigma_omega_deg_s=args.sigma_omega_deg_s, particles=args.particles,
                       roughening=args.roughening, resampling=args.resampling,
                       rejuvenation=args.rejuvenation,
                       ess_threshold=args.ess_threshold, acs_mode=args.acs_mode,
                       pseudo_noise=args.pseudo_noise, alpha=args.alpha, beta=args.beta,
                       kappa=args.kappa, reflection=args.reflection,
                       attitude="truth" if args.attitude_known else "estimate",
                       reflection_frac=args.reflection_frac,
                       reflection_kinds=csv_list(args.reflection_params, "--reflection-params"),
                       reflection_facets=(None if args.reflection_facets is None else
                                          csv_ints(args.reflection_facets,
                                                    "--reflection-facets")),
                       gate={"mode": args.gate, "false_alarm": args.gate_false_alarm},
                       **({"device": args.device} if args.method == "bpf" else {}))
    out = Path(args.output)
    print(f"wrote {out / 'summary.json'} ({res['n_files']} file(s), {res['n_diverged']} diverged, "
          f"{res['n_input_errors']} rejected, {res['n_failed'] - res['n_input_errors']} failed)")
    # exit 2 when an input was rejected (bad file or setting), 1 when a run failed otherwise
    return 2 if res["n_input_errors"] else (1 if res["n_failed"] else 0)


def register(sub) -> None:
    p = sub.add_parser(
        "invert",
        help="estimate attitude and rate from lightcurve files (MEKF, UKF, particle filter)",
        description="Run an attitude filter on each lightcurve HDF5 file and write one result "
        "HDF5 per input plus DIR/summary.json (per file: method, final RSS attitude and rate "
        "error, final 3-sigma bounds, whether every component ended inside 3 sigma, "
        "divergence flag, runtime; or the error of a file that failed — the others go on). "
        "The initial estimate is the file's truth perturbed by --sigma-theta-deg / "
        "--sigma-omega-deg-s using --seed (Bernard 2021 ch. 9). Many files run in parallel on "
        "the executors of 'compare' (process pool, Dask); the results do not depend on the "
        "executor. Exit code 2 if an input was rejected, 1 if a run failed.")
    p.add_argument("files", nargs="+", metavar="FILE.h5",
                   help="lightcurve HDF5 file(s) or glob patterns (expanded here, so quoted "
                   "patterns work; a pattern matching nothing is an error)")
    ex = p.add_mutually_exclusive_group()
    ex.add_argument("--workers", type=number(1, 4096, integer=True), default=None,
                    help="local process-pool size (default: one per CPU, at most one per file; "
                    "1 runs in this process)")
    ex.add_argument("--scheduler", metavar="ADDRESS", default=None,
                    help="address of an existing Dask scheduler, e.g. tcp://10.0.0.5:8786")
    ex.add_argument("--dask-local", type=number(1, 4096, integer=True), default=None, metavar="W",
                    help="start a Dask LocalCluster with W worker processes")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("--method", choices=("mekf", "ukf", "bpf"), default="ukf",
                   help="filter (default: ukf)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=SEED, default=0, help="random seed (default 0)")
    p.add_argument("--sigma-theta-deg", type=number(0.0, 180.0, lo_open=True), default=3.0,
                   help="1-sigma initial attitude error per axis, deg (default 3)")
    p.add_argument("--sigma-omega-deg-s", type=number(0.0, lo_open=True), default=0.02,
                   help="1-sigma initial rate error per axis, deg/s (default 0.02)")
    p.add_argument("--particles", type=number(2, 10_000_000, integer=True), default=10_000, help="BPF particles (default 10000)")
    p.add_argument("--roughening", type=number(0.0), default=0.2,
                   help="BPF roughening constant G (Bernard table 7.9; used with --rejuvenation "
                   "separate; default 0.2)")
    p.add_argument("--resampling", choices=("systematic", "multinomial"), default=None,
                   help="BPF resampling (default: systematic; multinomial, Bernard table 6.3, "
                   "in the thesis variant)")
    p.add_argument("--rejuvenation", choices=("auto", "separate", "joint", "table7.9", "none"),
                   default=None,
                   help="BPF: how the resampled cloud is moved: joint = one Liu-West kernel on "
                   "the whole state with the Musso et al. (2001) bandwidth; separate = the "
                   "table-7.9 sigma added in the GRP chart (uses --roughening); table7.9 = "
                   "Bernard's table 7.9 as written; none; auto = joint while the attitude cloud "
                   "is compact, else separate (default: auto; table7.9 in the thesis variant)")
    p.add_argument("--ess-threshold", type=number(0.0, 1.0), default=0.5,
                   help="BPF: resample when N_eff < threshold * N (default 0.5)")
    p.add_argument("--acs-mode", choices=("random_walk", "jitter"), default="random_walk",
                   help="controlled model: ACS noise as attitude random walk or jitter")
    p.add_argument("--pseudo-noise", type=number(0.0), default=0.0,
                   help="rate pseudo-noise PSD, (rad/s)^2/s (default 0)")
    p.add_argument("--alpha", type=number(0.0, lo_open=True), default=1.0, help="UKF alpha (default 1)")
    p.add_argument("--beta", type=number(), default=2.0, help="UKF beta (default 2)")
    p.add_argument("--kappa", type=number(), default=0.0, help="UKF kappa (default 0)")
    p.add_argument("--reflection", choices=("none", "random-walk", "model1", "model2", "model3"),
                   default="none",
                   help="states for uncertain reflection parameters (Bernard ch. 8): per-site "
                   "magnitude biases (random-walk, model1, model2) or the facet parameters "
                   "xi, a, m, A themselves (model3); MEKF, UKF and particle filter "
                   "(default none)")
    p.add_argument("--reflection-params", default="xi,a,m,A", metavar="LIST",
                   help="model3: comma-separated parameters to estimate per facet, from xi "
                   "(diffuse fraction), a (albedo = F0), m (Beckmann slope), A (area) "
                   "(default xi,a,m,A). a and A reach the magnitude almost only as the product "
                   "a*A (diffuse term, and the specular term near normal incidence): estimated "
                   "together with equal priors neither shrinks by more than ~sqrt(2); leave A "
                   "out when the areas are known to make a observable")
    p.add_argument("--reflection-facets", default=None, metavar="LIST",
                   help="model3: comma-separated facet indices (0-based, shape-file order) "
                   "whose parameters are estimated (default: every Cook-Torrance facet)")
    p.add_argument("--reflection-frac", type=number(0.0, lo_open=True), default=0.1,
                   help="relative 1-sigma of the reflection parameters: prior of model3, "
                   "eq. 8.10 bias variance of model1/2 (default 0.1 = Bernard sec. 10.1)")
    p.add_argument("--attitude-known", action="store_true",
                   help="hold attitude and rate at the file's truth and estimate only the "
                   "reflection states (thesis sec. 10.7 parameter-only runs; needs --reflection)")
    p.add_argument("--gate", choices=("auto", "reject", "inflate", "off"), default="auto",
                   help="innovation (outlier) gate: skip a magnitude whose normalised innovation "
                   "squared exceeds the chi-square threshold (reject), use it with inflated noise "
                   "(inflate), or no gate; auto = reject in the UKF, inflate in the MEKF and the "
                   "particle filter (default auto; counts in summary.json)")
    p.add_argument("--gate-false-alarm", type=number(0.0, 0.5, lo_open=True), default=1e-4,
                   help="probability that the gate flags a good magnitude (default 1e-4: "
                   "NIS > 15.14)")
    p.add_argument("--device", choices=("cpu", "gpu"), default="cpu",
                   help="BPF: numba CPU kernels or CUDA kernels (needs the gpu extra, "
                   "pip install 'lightcurve[gpu]', and a CUDA device; default cpu)")
    p.add_argument("--plot", action="store_true", help="also write a PNG per file")
    p.set_defaults(func=_cmd_invert, resume_hint="finished files are kept in {output} and "
                   "listed in {output}/summary.json; run the command again on the others")
