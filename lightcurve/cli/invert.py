"""``lightcurve invert``: attitude filters on lightcurve files."""

from __future__ import annotations

import sys
from dataclasses import fields
from pathlib import Path

from ..errors import InputError
from ._args import (add_command, add_device, add_executors, add_model_options, add_output, add_plot,
                    add_quiet, add_seed, add_variant, csv_ints, csv_list, initial_omega_rad_s,
                    initial_q, number, refuse_inapplicable)

__all__ = ["register", "configs_from_args"]


#: options that only one filter uses (``--method``)
METHOD_OPTIONS = {"particles": {"bpf"}, "roughening": {"bpf"}, "resampling": {"bpf"},
                  "rejuvenation": {"bpf"}, "ess_threshold": {"bpf"}, "device": {"bpf"},
                  "alpha": {"ukf"}, "beta": {"ukf"}, "kappa": {"ukf"}}
#: options that only some reflection models use (``--reflection``)
REFLECTION_OPTIONS = {"reflection_params": {"model3"}, "reflection_facets": {"model3"},
                      "reflection_frac": {"random-walk", "model1", "model2", "model3"},
                      "attitude_known": {"random-walk", "model1", "model2", "model3"}}


def _refuse_inapplicable_options(args) -> None:
    """An option the chosen filter, reflection model or gate ignores is an input error."""
    refuse_inapplicable(args, "method", METHOD_OPTIONS)
    refuse_inapplicable(args, "reflection", REFLECTION_OPTIONS)
    refuse_inapplicable(args, "gate", {"gate_false_alarm": {"auto", "reject", "inflate"}})


def configs_from_args(args):
    """``(ProblemConfig, filter options dict)`` from the parsed ``invert`` options — the same
    validated objects the Python API and the study TOML build."""
    from ..acquisition.global_init import GlobalInitConfig
    from ..filters.config import BPF_KEYWORDS, ProblemConfig, filter_config_class

    start = {}  # the user's initial estimate (truth-free recordings); None: the file's truth
    if args.initial_q is not None:
        start["initial_q"] = initial_q(args.initial_q)
    if args.initial_omega_deg_s is not None:
        start["initial_omega"] = initial_omega_rad_s(args.initial_omega_deg_s)
    if args.initial == "given" and args.initial_q is None:
        raise InputError("--initial given needs --initial-q (and --initial-omega-deg-s)",
                         field="--initial", value="given")
    if args.global_particles is not None:
        if args.initial not in ("global", "auto"):
            raise InputError("--global-particles applies to the global initialisation only",
                             field="--global-particles", allowed="--initial global or auto")
        start["global_config"] = GlobalInitConfig(particles=args.global_particles)
    problem = ProblemConfig(
        seed=args.seed, sigma_theta_deg=args.sigma_theta_deg,
        sigma_omega_deg_s=args.sigma_omega_deg_s, acs_mode=args.acs_mode,
        pseudo_noise=args.pseudo_noise, reflection=args.reflection,
        attitude="truth" if args.attitude_known else "estimate",
        reflection_frac=args.reflection_frac,
        reflection_kinds=tuple(csv_list(args.reflection_params, "--reflection-params")),
        reflection_facets=(None if args.reflection_facets is None else
                           tuple(csv_ints(args.reflection_facets, "--reflection-facets"))),
        gate=(None if args.gate is None else
              {"mode": args.gate, "false_alarm": args.gate_false_alarm}),
        shape=args.shape, library_dirs=tuple(args.library) if args.library else None,
        site_dirs=tuple(args.sites) if args.sites else None, initial=args.initial, **start)
    cls = filter_config_class(args.method)
    names = [f.name for f in fields(cls)] if cls is not None else list(BPF_KEYWORDS)
    opts = {n: getattr(args, n) for n in names if hasattr(args, n)}
    if getattr(args, "variant", None) is None:
        opts.pop("variant", None)   # the file's scenario [filter] variant, else robust (invert)
    if cls is not None:
        unset = [k for k, v in opts.items() if v is None]   # the variant's defaults (invert)
        opts = cls(**opts).as_options()    # validated here (InputError → exit 2)
        for k in unset:
            opts.pop(k, None)
    return problem, opts


def _cmd_invert(args) -> int:
    """Run an attitude filter on each lightcurve HDF5 file and write one result HDF5 per input plus
    DIR/summary.json (per file: method, final RSS attitude and rate error, final 3-sigma bounds,
    whether every component ended inside 3 sigma, divergence flag, runtime; or the error of a
    file that failed — the others go on). The initial estimate (--initial) is the file's truth
    perturbed by --sigma-theta-deg / --sigma-omega-deg-s using --seed (Bernard 2021 ch. 9), or
    --initial-q / --initial-omega-deg-s with those sigmas as their uncertainty, or — for a
    recording with neither — the global initialisation, which needs no first guess and reports
    every attitude mode the data allow. The shape is the one the file carries unless --shape is
    given. Many files run in parallel on the executors of 'compare' (process pool, Dask); the
    results do not depend on the executor. Exit code 2 if an input was rejected, 1 if a run
    failed.
    """
    from ..studies.batch import expand_inputs, invert_files

    _refuse_inapplicable_options(args)
    n_files = len(expand_inputs(args.files))  # a pattern matching nothing: InputError, exit 2
    problem, filter_options = configs_from_args(args)
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
                       plot=args.plot, report=report, **problem.as_options(), **filter_options)
    out = Path(args.output)
    print(f"wrote {out / 'summary.json'} ({res['n_files']} file(s), {res['n_diverged']} diverged, "
          f"{res['n_input_errors']} rejected, {res['n_failed'] - res['n_input_errors']} failed)")
    # exit 2 when an input was rejected (bad file or setting), 1 when a run failed otherwise
    return 2 if res["n_input_errors"] else (1 if res["n_failed"] else 0)


def register(sub) -> None:
    p = add_command(
        sub, "invert", _cmd_invert, resume_hint="finished files are kept in {output} and listed "
        "in {output}/summary.json; run the command again on the others",
        help="estimate attitude and rate from lightcurve files (MEKF, UKF, particle filter)")
    p.add_argument("files", nargs="+", metavar="FILE.h5",
                   help="lightcurve HDF5 file(s) or glob patterns (expanded here, so quoted "
                   "patterns work; a pattern matching nothing is an error)")
    add_executors(p, workers_help="local process-pool size (default: one per CPU, at most one "
                  "per file; 1 runs in this process)")
    add_quiet(p, help="no progress bar")
    p.add_argument("--method", choices=("mekf", "ukf", "bpf"), default="ukf",
                   help="filter (default: ukf)")
    add_output(p, what="folder", required=True)
    add_seed(p, default=0, help="random seed of the initial-estimate perturbation and of the "
             "particle filter")
    p.add_argument("--sigma-theta-deg", type=number(0.0, 180.0, lo_open=True), default=3.0,
                   help="1-sigma initial attitude error per axis, deg (default 3)")
    p.add_argument("--sigma-omega-deg-s", type=number(0.0, 360.0, lo_open=True), default=0.02,
                   help="1-sigma initial rate error per axis, deg/s, in (0, 360] (default 0.02)")
    p.add_argument("--initial", choices=("auto", "truth", "given", "global"), default="auto",
                   help="where the filter starts: truth = the file's truth perturbed by "
                   "--sigma-theta-deg/--sigma-omega-deg-s (simulations, Bernard ch. 9); given = "
                   "--initial-q/--initial-omega-deg-s; global = no first guess: attitude "
                   "uniform over all rotations, rate from the spin-period analysis, a tempered "
                   "Monte Carlo search for every attitude the data allow, then this filter "
                   "from each (ambiguities are reported, not hidden). auto (default): given if "
                   "--initial-q is set, else truth if the file has one, else global")
    p.add_argument("--global-particles", type=number(100, 5_000_000, integer=True), default=None,
                   metavar="N", help="particles of the global initialisation (default 20000)")
    p.add_argument("--initial-q", default=None, metavar="Q1,Q2,Q3,Q4",
                   help="initial attitude estimate (inertial->body quaternion, scalar first, "
                   "at the first epoch) instead of the file's perturbed truth; needed for "
                   "recordings without truth. Its 1-sigma error is --sigma-theta-deg. Write "
                   "--initial-q=-0.5,... when the first value is negative")
    p.add_argument("--initial-omega-deg-s", default=None, metavar="WX,WY,WZ",
                   help="initial body-rate estimate, deg/s body axes (default: the file's "
                   "perturbed truth; needed without truth). Its 1-sigma error is "
                   "--sigma-omega-deg-s. Write --initial-omega-deg-s=-1,... when the first "
                   "value is negative")
    add_model_options(p)
    p.add_argument("--particles", type=number(2, 10_000_000, integer=True), default=10_000, help="BPF particles (default 10000)")
    p.add_argument("--roughening", type=number(0.0, 10.0), default=0.2,
                   help="BPF roughening constant G in [0, 10] (Bernard table 7.9: sigma = G E "
                   "N^(-1/n), E the spread of the cloud; used by --rejuvenation separate and "
                   "table7.9; default 0.2)")
    p.add_argument("--resampling", choices=("systematic", "multinomial"), default=None,
                   help="BPF resampling scheme (default: systematic; multinomial, Bernard "
                   "table 6.3, with --variant thesis)")
    p.add_argument("--rejuvenation", choices=("auto", "separate", "joint", "table7.9", "none"),
                   default=None,
                   help="BPF: how the resampled cloud is moved: joint = one Liu-West kernel on "
                   "the whole state with the Musso et al. (2001) bandwidth; separate = the "
                   "table-7.9 sigma added in the GRP chart (uses --roughening); table7.9 = "
                   "Bernard's table 7.9 as written; none; auto = joint while the attitude cloud "
                   "is compact, else separate (default: auto; table7.9 with --variant thesis)")
    p.add_argument("--ess-threshold", type=number(0.0, 1.0), default=0.5,
                   help="BPF: resample when N_eff < threshold * N (default 0.5)")
    p.add_argument("--acs-mode", choices=("random_walk", "jitter"), default=None,
                   help="controlled model: ACS noise as attitude random walk or jitter "
                   "(Bernard eq. 7.10; default: the file's scenario, else random_walk)")
    p.add_argument("--pseudo-noise", type=number(0.0, 1.0), default=0.0,
                   help="rate pseudo-noise PSD, (rad/s)^2/s, in [0, 1] (1 already lets the rate "
                   "wander by 1 rad/s in 1 s; default 0)")
    add_variant(p, default=None)
    add_device(p)
    p.add_argument("--alpha", type=number(1e-4, 1.0), default=None,
                   help="UKF alpha in [1e-4, 1] (Bernard sec. 6: between 0 and 1; below 1e-4 "
                   "the sigma-point weights lose all precision; default: 1 with --variant "
                   "robust, 0.25 with --variant thesis)")
    p.add_argument("--beta", type=number(0.0, 100.0), default=2.0,
                   help="UKF beta in [0, 100] (Bernard sec. 6: non-negative, 2 for a Gaussian "
                   "prior; default 2)")
    p.add_argument("--kappa", type=number(0.0, 100.0), default=0.0,
                   help="UKF kappa in [0, 100] (Bernard sec. 6: kappa >= 0; default 0)")
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
    p.add_argument("--reflection-frac", type=number(0.0, 10.0, lo_open=True), default=0.1,
                   help="relative 1-sigma of the reflection parameters: prior of model3, "
                   "eq. 8.10 bias variance of model1/2 (default 0.1 = Bernard sec. 10.1)")
    p.add_argument("--attitude-known", action="store_true",
                   help="hold attitude and rate at the file's truth and estimate only the "
                   "reflection states (thesis sec. 10.7 parameter-only runs; needs --reflection)")
    p.add_argument("--gate", choices=("auto", "reject", "inflate", "off"), default=None,
                   help="innovation (outlier) gate: skip a magnitude whose normalised innovation "
                   "squared exceeds the chi-square threshold (reject), use it with inflated noise "
                   "(inflate), or no gate; auto = reject in the UKF, inflate in the MEKF and the "
                   "particle filter (default auto; off with --variant thesis; counts in "
                   "summary.json)")
    p.add_argument("--gate-false-alarm", type=number(0.0, 0.5, lo_open=True), default=1e-4,
                   help="probability that the gate flags a good magnitude (default 1e-4: "
                   "NIS > 15.14)")
    add_plot(p, help="also write the estimate figure (PNG) next to each result")
