"""Study files: a Monte Carlo grid of filter runs over simulated lightcurves.

A study TOML (documented in docs/formats.md, section "Studies") names base scenario files and a
grid of settings; every combination of the grid values is one *cell*, and each cell is run
``runs`` times. Example::

    [study]
    name = "thesis-fig9-4"
    seed = 94                 # study seed; every run's seeds derive from it and the cell
    runs = 100
    # base scenario per (dynamics, sites); {dynamics} and {sites} are filled from the grid;
    # relative paths resolve against the study file's folder
    scenario = "../thesis/leo-ic1-fast-spin-{dynamics}-{sites}site.toml"

    [grid]
    filter = ["mekf", "ukf"]              # lightcurve.filters.METHODS
    dynamics = ["controlled", "uncontrolled"]
    sites = [1, 2]                        # number of sites (the scenario file's [[sites]])
    sigma_theta_deg = [3.0, 5.0, 10.0]    # 1σ initial attitude error per axis, deg
    sigma_omega_deg_s = [0.02, 0.2]       # 1σ initial rate error per axis, deg/s
    r_percent = [1.0, 10.0]               # measurement noise r (Bernard eq. 9.3), overrides
                                          # the scenario's measurement.r_percent
    reflection = ["none", "model1"]       # reflection-parameter states estimated with the
                                          # attitude (lightcurve.filters.reflection.
                                          # REFLECTION_CHOICES); the truth perturbation is the
                                          # base scenario's [reflection] table (Bernard §10.1)

    [options]                             # optional filter settings shared by every cell
    particles = 1000                      # BPF particles
    acs_mode = "random_walk"              # controlled model: "random_walk" or "jitter"
                                          # (default: each scenario's [attitude] acs_mode)
    variant = "thesis"                    # filters: "robust" (default) or "thesis" (Bernard
                                          # ch. 7 as written; lightcurve.filters.invert)
    cook_torrance = "thesis"              # diffuse term of the shape's Cook–Torrance materials
                                          # for truth and filters: "physical" (default) or
                                          # "thesis" (eq. 5.8 as printed)
    gate = "off"                          # innovation gate (default: the variant's)
    alpha = 0.25                          # UKF α, β, κ (default: α 1 robust, 0.25 thesis; 2, 0)
    shared_init = true                    # one initial estimate for all filters of a run
                                          # (default: true with variant = "thesis")
    truth_acs_mode = "random_walk"        # controlled TRUTH model (default: the scenario's)
    eta_sigma_deg_s2 = 2.5e-3             # uncontrolled FILTER process noise σ_η, deg/s^1.5
                                          # (default: each scenario's; the truth keeps its own)
    filter_drift_horizon_s = 360.0        # or: the FILTER σ_η sized so that the scenario's
                                          # drift_deg_per_orbit is reached after this many
                                          # seconds instead of one orbit (not with
                                          # eta_sigma_deg_s2; every uncontrolled scenario of
                                          # the study must give drift_deg_per_orbit)
    hide_glints_mag = 2.0                 # DIAGNOSTIC: the filters do not see the epochs
                                          # whose noise-free magnitude is more than this many
                                          # mag brighter than the median of the same site's
                                          # epochs within ±4 of it (the specular spikes;
                                          # lightcurve.studies.runner.hide_glints)
    hide_glints_after_s = 0.0             # DIAGNOSTIC, with hide_glints_mag: hide only the
                                          # spikes later than this many seconds after the
                                          # first epoch (0: the glint at the start is seen)

A study may name the thesis's published table of its grid (``[study] thesis_table =
"tables/bernard2021-fig9-4.toml"``, relative to the study file;
:mod:`lightcurve.studies.agreement`): the summary then carries the published colour of every
cell (``thesis_color``) and the agreement counts, and cells the thesis did not run (grey) are
not run here either.

    [filters.ukf]                         # optional per-filter settings: the fields of the
    variant = "thesis"                    # filter's configuration (lightcurve.filters.config;
    alpha = 1.0                           # MEKFConfig, UKFConfig, the particle filter's);
                                          # without variant: [options] variant; the fields
                                          # left out keep that variant's defaults

Seeds (reproducible, independent of worker count and executor): the simulation seed of run
``i`` derives from the study seed, the *scenario* part of the cell key (dynamics, sites,
r_percent) and ``i`` — so every filter and every initial-error setting sees the same simulated
lightcurves (common random numbers) — and the filter seed from the study seed, the full cell
key and ``i``; both through :class:`numpy.random.SeedSequence` seeded with SHA-256 words of the
key text. With ``variant = "thesis"`` the initial estimate is drawn from a third seed, of the
cell key *without the filter*, so every filter of a run starts from the same initial estimate
(Bernard §9.3.1: "all of the filters were initialized to the same values").
"""

from __future__ import annotations

import hashlib
import itertools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..filters.config import VARIANTS
from ..filters.reflection import REFLECTION_CHOICES as _FILTER_REFLECTION_CHOICES
from ..io.tomlio import Section, load_toml

__all__ = ["Study", "Cell", "RunTask", "load_study", "GRID_KEYS", "REFLECTION_MODELS",
           "cell_key", "run_seeds", "init_seed", "study_hash", "input_hash", "code_fingerprint"]

#: grid axes in table order (also the order of the cell key)
GRID_KEYS = ("filter", "dynamics", "sites", "sigma_theta_deg", "sigma_omega_deg_s", "r_percent",
             "reflection")
#: reflection models accepted in the grid: the filters' choices (read from
#: :data:`lightcurve.filters.reflection.REFLECTION_CHOICES` at import time, so a model added
#: to the filters is accepted here without an edit)
REFLECTION_MODELS = tuple(_FILTER_REFLECTION_CHOICES)
_DYNAMICS = ("controlled", "uncontrolled")
_MAX_RUNS = 1_000_000


def _fmt(v) -> str:
    """Canonical text of a grid value for the cell key (floats via repr: exact, stable)."""
    if isinstance(v, float):
        return repr(float(v))
    return str(v)


@dataclass(frozen=True)
class Cell:
    """One combination of grid values (degrees in the *_deg keys, r in percent)."""

    filter: str
    dynamics: str
    sites: int
    sigma_theta_deg: float
    sigma_omega_deg_s: float
    r_percent: float
    reflection: str = "none"

    @property
    def key(self) -> str:
        """Canonical text key, e.g. ``filter=ukf|dynamics=controlled|sites=1|…``."""
        return cell_key(self)

    @property
    def scenario_key(self) -> str:
        """The part of the key that fixes the simulated lightcurve (dynamics, sites, r)."""
        return f"dynamics={self.dynamics}|sites={self.sites}|r_percent={_fmt(self.r_percent)}"

    @property
    def tag(self) -> str:
        """Short file-name-safe hash of the key (12 hex digits)."""
        return hashlib.sha256(self.key.encode()).hexdigest()[:12]

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in GRID_KEYS}


def cell_key(cell: Cell) -> str:
    """Canonical key text of a cell: ``name=value`` pairs in :data:`GRID_KEYS` order."""
    return "|".join(f"{k}={_fmt(getattr(cell, k))}" for k in GRID_KEYS)


def _seed_from(study_seed: int, text: str, run: int) -> int:
    words = np.frombuffer(hashlib.sha256(text.encode()).digest(), dtype="<u4").tolist()
    ss = np.random.SeedSequence([int(study_seed) & 0xFFFFFFFF, int(study_seed) >> 32, *words,
                                 int(run)])
    return int(ss.generate_state(1, np.uint64)[0] >> np.uint64(1))  # in [0, 2**63)


def init_seed(study_seed: int, cell: Cell, run: int) -> int:
    """Seed of run ``run``'s initial-estimate draw, the same for every filter of the run: the
    cell key without the filter (module docstring)."""
    key = "|".join(f"{k}={_fmt(getattr(cell, k))}" for k in GRID_KEYS if k != "filter")
    return _seed_from(study_seed, "init|" + key, run)


def run_seeds(study_seed: int, cell: Cell, run: int) -> tuple[int, int]:
    """``(simulation_seed, filter_seed)`` of run ``run`` (0-based) of ``cell`` (module doc)."""
    return (_seed_from(study_seed, "sim|" + cell.scenario_key, run),
            _seed_from(study_seed, "filter|" + cell.key, run))


@dataclass(frozen=True)
class RunTask:
    """Everything a worker needs for one run (small and picklable; scenario as TOML text)."""

    cell: Cell
    run: int
    sim_seed: int
    filter_seed: int
    scenario_text: str
    scenario_file: str
    options: tuple = ()  # sorted (name, value) pairs of [options]
    library_dirs: tuple = ()  # extra shape-library folders (absolute paths)
    site_dirs: tuple = ()     # extra observatory folders (absolute paths)
    init_seed: int | None = None  # initial-estimate seed shared by the filters (thesis variant)

    @property
    def run_id(self) -> str:
        """File stem of the run's result: ``<cell tag>_r<run>``."""
        return f"{self.cell.tag}_r{self.run:05d}"


@dataclass
class Study:
    """A validated study (module docstring)."""

    name: str
    seed: int
    runs: int
    cells: list
    scenario_files: dict  # (dynamics, sites) -> Path
    scenario_texts: dict  # (dynamics, sites) -> str
    options: dict = field(default_factory=dict)
    source: str = ""
    text: str = ""
    #: extra shape-library / observatory folders (``lightcurve compare --library/--sites``)
    library_dirs: tuple = ()
    site_dirs: tuple = ()
    #: fingerprints of the shapes resolved from ``library_dirs`` (part of the input hash)
    shape_fingerprints: dict = field(default_factory=dict)
    #: the published table of the grid (:class:`lightcurve.studies.agreement.ThesisTable`)
    thesis_table: object = None
    #: text of the table file (part of the input hash: it decides which cells run)
    thesis_table_text: str = ""
    #: grid cells not run because the thesis did not run them (grey)
    skipped_cells: list = field(default_factory=list)

    @property
    def hash(self) -> str:
        """SHA-256 of the inputs and the code (:func:`study_hash`)."""
        return study_hash(self)

    @property
    def input_hash(self) -> str:
        """SHA-256 of the study text and every scenario text it uses (:func:`input_hash`)."""
        return input_hash(self)

    def _task(self, c: Cell, i: int, opts: tuple) -> "RunTask":
        s, fs = run_seeds(self.seed, c, i)
        shared = self.options.get("shared_init", self.options.get("variant") == "thesis")
        return RunTask(c, i, s, fs, self.scenario_texts[(c.dynamics, c.sites)],
                       str(self.scenario_files[(c.dynamics, c.sites)]), opts,
                       self.library_dirs, self.site_dirs,
                       init_seed(self.seed, c, i) if shared else None)

    def iter_tasks(self, runs: int | None = None):
        """Every :class:`RunTask`, generated lazily in execution order: scenario keys sorted,
        then run index, then the cells sharing that scenario key in grid order — runs that
        share a simulated lightcurve (common random numbers) come back to back. The same set
        as :meth:`tasks`."""
        n = self.runs if runs is None else int(runs)
        opts = tuple(sorted(self.options.items()))
        groups: dict = {}
        for c in self.cells:
            groups.setdefault(c.scenario_key, []).append(c)
        for key in sorted(groups):
            for i in range(n):
                for c in groups[key]:
                    yield self._task(c, i, opts)

    def tasks(self, runs: int | None = None) -> list:
        """Every :class:`RunTask` (cells in grid order, runs 0…runs−1 in each)."""
        n = self.runs if runs is None else int(runs)
        opts = tuple(sorted(self.options.items()))
        return [self._task(c, i, opts) for c in self.cells for i in range(n)]


def input_hash(study: Study) -> str:
    """Hex SHA-256 over the study file text and the scenario texts (sorted by key).

    ``--runs`` is not part of it: adding runs to a finished study reuses the stored ones.
    """
    h = hashlib.sha256(study.text.encode())
    if study.thesis_table_text:
        h.update(b"\0thesis_table\0" + study.thesis_table_text.encode())
    for k in sorted(study.scenario_texts):
        h.update(f"\0{k[0]}|{k[1]}\0".encode())
        h.update(study.scenario_texts[k].encode())
    for k in sorted(study.shape_fingerprints):  # shapes from --library folders (content)
        h.update(f"\0shape {k[0]}|{k[1]}\0{study.shape_fingerprints[k]}".encode())
    return h.hexdigest()


def shape_fingerprint(shape) -> str:
    """Hex SHA-256 of a resolved shape's geometry, mass properties and materials."""
    import numpy as np

    h = hashlib.sha256()
    for a in (shape.areas_m2, shape.normals_body, shape.centers_body_m, shape.inertia_kg_m2):
        h.update(np.ascontiguousarray(a, float).tobytes())
    h.update(repr((shape.name, float(shape.mass_kg),
                   [(m.name, m.brdf_name, sorted(m.params.items())) for m in shape.materials])
                  ).encode())
    return h.hexdigest()


def source_tree_hash(root) -> tuple:
    """``(hex SHA-256, file count)`` over every ``*.py`` below ``root`` (relative path and
    bytes of each, sorted by path; ``__pycache__`` skipped)."""
    root = Path(root)
    h = hashlib.sha256()
    n = 0
    for f in sorted(root.rglob("*.py")):
        if "__pycache__" in f.relative_to(root).parts:
            continue
        h.update(f.relative_to(root).as_posix().encode() + b"\0")
        h.update(f.read_bytes())
        h.update(b"\0")
        n += 1
    return h.hexdigest(), n


_FP_CACHE: dict = {}


def _source_fingerprint() -> tuple:
    """``(version, source hash, n files)`` of the package's files on disk now (re-hashed when
    any file's size or modification time changed since the last call)."""
    from .. import __version__

    root = Path(__file__).resolve().parents[1]  # the lightcurve package folder
    sig = []
    for f in sorted(root.rglob("*.py")):
        if "__pycache__" not in f.relative_to(root).parts:
            st = f.stat()
            sig.append((str(f), st.st_size, st.st_mtime_ns))
    sig = tuple(sig)
    if _FP_CACHE.get("sig") != sig:
        _FP_CACHE["sig"] = sig
        _FP_CACHE["value"] = source_tree_hash(root)
    h, n = _FP_CACHE["value"]
    return str(__version__), h, n


def code_fingerprint() -> dict:
    """The code that produces a study's numbers: ``package_version`` and ``source_sha256``.

    ``source_sha256`` hashes every ``lightcurve/**/*.py`` file of the imported package (path
    and bytes, sorted by path; ``n_source_files`` of them) as they are on disk at the call
    (so a process and the workers or later processes it is compared with agree). Part of
    :func:`study_hash`, so stored runs made by other code are not mixed with new ones.
    """
    v, h, n = _source_fingerprint()
    return {"package_version": v, "source_sha256": h, "n_source_files": n}


def study_hash(study: Study) -> str:
    """Hex SHA-256 over :func:`input_hash` (study and scenario texts) and
    :func:`code_fingerprint` (package version and source hash).

    A stored study whose hash differs was made from other inputs or by other code; resuming it
    is refused unless ``--force`` (:func:`lightcurve.studies.runner.prepare_output`).
    """
    fp = code_fingerprint()
    h = hashlib.sha256(input_hash(study).encode())
    h.update(f"\0version={fp['package_version']}\0source={fp['source_sha256']}".encode())
    return h.hexdigest()


def _list(sec: Section, key, kind, *, min=None, max=None, choices=None, min_open=False):
    raw = sec.raw(key)
    vals = raw if isinstance(raw, list) else [raw]
    if not vals:
        raise InputError("expected a non-empty list", file=sec.file, field=sec.field_name(key), value=raw)
    out = []
    for v in vals:
        ok = (kind is str and isinstance(v, str)) or (kind is int and isinstance(v, int)
              and not isinstance(v, bool)) or (kind is float and isinstance(v, (int, float))
              and not isinstance(v, bool) and np.isfinite(v))
        if not ok:
            raise InputError(f"expected a list of {kind.__name__}", file=sec.file,
                             field=sec.field_name(key), value=raw)
        if choices is not None and v not in choices:
            raise InputError("unknown value", file=sec.file, field=sec.field_name(key), value=v,
                             allowed=", ".join(map(str, choices)))
        if (min is not None and (v < min or (min_open and v == min))) or (max is not None and v > max):
            raise InputError("out of range", file=sec.file, field=sec.field_name(key), value=v,
                             allowed=f"{'(' if min_open else '['}{min}, {max}]")
        out.append(kind(v))
    if len(set(out)) != len(out):
        raise InputError("duplicate values", file=sec.file, field=sec.field_name(key), value=raw)
    return out


def _fill_template(template: str, file, **values) -> str:
    """``template`` with its ``{name}`` placeholders replaced by ``values``.

    Only bare placeholders are allowed: no attribute or index access (``{dynamics.x}``), no
    conversion and no format spec (``{sites:>300}`` would pad a path to any length).
    """
    import string

    def bad(why):
        return InputError(f"bad placeholder in the scenario template ({why})", file=file,
                          field="study.scenario", value=template,
                          allowed="text with {dynamics} and {sites} placeholders only")

    out = []
    try:
        parts = list(string.Formatter().parse(template))
    except ValueError as exc:
        raise bad(str(exc)) from None
    for literal, name, spec, conv in parts:
        out.append(literal)
        if name is None:
            continue
        if name not in values:
            raise bad(f"unknown placeholder {{{name}}}")
        if spec or conv:
            raise bad(f"{{{name}}} with a format spec or conversion")
        out.append(str(values[name]))
    return "".join(out)


def load_study(path, library_dirs=None, site_dirs=None) -> Study:
    """Load and validate a study TOML (module docstring); every scenario file is parsed.

    ``library_dirs`` / ``site_dirs``: extra shape-library and observatory folders for the
    scenarios (they travel with every run task; with ``library_dirs`` the resolved shapes'
    content is part of the input hash, so a changed library shape is a changed study).

    Reflection models: every value of ``grid.reflection`` is a filter option
    (:data:`REFLECTION_MODELS`); the simulated lightcurves do not depend on it (common random
    numbers across reflection models), and the truth reflection parameters are perturbed as
    the base scenario's ``[reflection]`` table says (none → nominal truth, on which the
    reflection states should stay near zero).

    Raises
    ------
    InputError
        Naming the file, key and allowed values for any bad entry.
    """
    from ..filters import METHODS
    from ..filters.config import BPF_KEYWORDS, filter_config_class
    from .scenario import parse_scenario

    path = Path(path)
    doc, text = load_toml(path, with_text=True)
    root = Section(doc, file=path)
    st = root.section("study")
    name = st.str("name", path.stem)
    seed = st.int("seed", 0, min=0, max=2**63 - 1)
    runs = st.int("runs", 100, min=1, max=_MAX_RUNS)
    template = st.str("scenario")
    table_rel = st.str("thesis_table", "")
    st.check_unknown(extra_allowed=("description",))
    table, table_text = None, ""
    if table_rel:
        from .agreement import load_thesis_table

        tp = Path(table_rel)
        if not tp.is_absolute():
            tp = path.parent / tp
        if not tp.is_file():
            raise InputError("thesis table not found", file=path, field="study.thesis_table",
                             value=str(tp))
        table = load_thesis_table(tp)
        table_text = table.text

    g = root.section("grid")
    axes = {
        "filter": _list(g, "filter", str, choices=METHODS),
        "dynamics": _list(g, "dynamics", str, choices=_DYNAMICS),
        "sites": _list(g, "sites", int, min=1, max=16),
        "sigma_theta_deg": _list(g, "sigma_theta_deg", float, min=0.0, max=180.0, min_open=True),
        "sigma_omega_deg_s": _list(g, "sigma_omega_deg_s", float, min=0.0, max=360.0, min_open=True),
        "r_percent": _list(g, "r_percent", float, min=0.0, max=100.0, min_open=True),
        "reflection": _list(g, "reflection", str, choices=REFLECTION_MODELS) if g.has("reflection")
        else ["none"],
    }
    g.check_unknown()

    opts = {}
    o = root.section("options", {})
    if o.has("particles"):
        opts["particles"] = o.int("particles", min=2, max=10_000_000)
        from ..filters.invert import BPF_BYTES_PER_PARTICLE
        from ..memory import check_allocation

        check_allocation(opts["particles"] * BPF_BYTES_PER_PARTICLE,
                         f"particle filter with {opts['particles']} particles (per worker)",
                         file=path, field="options.particles", value=opts["particles"])
    if o.has("acs_mode"):
        opts["acs_mode"] = o.str("acs_mode", choices=("random_walk", "jitter"))
    if o.has("variant"):
        opts["variant"] = o.str("variant", choices=VARIANTS)
    if o.has("cook_torrance"):
        opts["cook_torrance"] = o.str("cook_torrance", choices=("physical", "thesis"))
    if o.has("gate"):
        opts["gate"] = o.str("gate", choices=("auto", "reject", "inflate", "off"))
    for k in ("alpha", "beta", "kappa"):
        if o.has(k):
            opts[k] = o.float(k, min=0.0 if k == "alpha" else None,
                              min_open=k == "alpha", max=None)
    if o.has("shared_init"):
        opts["shared_init"] = o.bool("shared_init")
    if o.has("truth_acs_mode"):
        opts["truth_acs_mode"] = o.str("truth_acs_mode", choices=("random_walk", "jitter"))
    if o.has("eta_sigma_deg_s2"):
        opts["eta_sigma_deg_s2"] = o.float("eta_sigma_deg_s2", min=0.0, max=10.0)
    if o.has("filter_drift_horizon_s"):
        if "eta_sigma_deg_s2" in opts:
            raise InputError("give either eta_sigma_deg_s2 or filter_drift_horizon_s, not both",
                             file=path, field="options.filter_drift_horizon_s")
        opts["filter_drift_horizon_s"] = o.float("filter_drift_horizon_s", min=1.0, max=1e8)
    if o.has("hide_glints_mag"):
        opts["hide_glints_mag"] = o.float("hide_glints_mag", min=0.0, min_open=True, max=30.0)
    if o.has("hide_glints_after_s"):
        if "hide_glints_mag" not in opts:
            raise InputError("hide_glints_after_s needs hide_glints_mag (which spikes to hide)",
                             file=path, field="options.hide_glints_after_s")
        opts["hide_glints_after_s"] = o.float("hide_glints_after_s", min=0.0, max=1e6)
    o.check_unknown()
    # per-filter settings ([filters.mekf], [filters.ukf], [filters.bpf]): the filters'
    # configuration objects validate them (lightcurve.filters.config)
    fs = root.section("filters", {})
    filt = {}
    for method in METHODS:
        tab = fs.section(method, None)
        if tab is None:
            continue
        cls = filter_config_class(method)
        values = dict(tab.data)
        if cls is not None:
            # validated under the variant the runs will use (the table's own, else [options]
            # variant, else robust); only the keys given are kept, so the fields left out keep
            # that variant's defaults instead of the robust variant's
            cls.from_mapping({"variant": opts.get("variant", "robust"), **values}, file=path,
                             table=f"filters.{method}")
            filt[method] = values
        else:
            bad = sorted(set(values) - set(BPF_KEYWORDS) - {"variant"})
            if bad:
                raise InputError("unknown key", file=path, field=f"filters.{method}.{bad[0]}",
                                 allowed=", ".join(sorted(BPF_KEYWORDS)))
            filt[method] = values
    fs.check_unknown()
    if filt:   # hashable: sorted (method, sorted (name, value) pairs) pairs
        opts["filters"] = tuple(sorted((m, tuple(sorted(v.items()))) for m, v in filt.items()))
    root.check_unknown()

    lib = tuple(str(Path(d).resolve()) for d in (library_dirs or ()))
    sdirs = tuple(str(Path(d).resolve()) for d in (site_dirs or ()))
    files, texts, prints = {}, {}, {}
    for dyn in axes["dynamics"]:
        for ns in axes["sites"]:
            rel = _fill_template(template, path, dynamics=dyn, sites=ns)
            f = Path(rel)
            if not f.is_absolute():
                f = path.parent / f
            if not f.exists():
                raise InputError("scenario file not found", file=path, field="study.scenario",
                                 value=str(f), allowed="an existing scenario TOML for every "
                                 "(dynamics, sites) of the grid")
            doc_f, txt = load_toml(f, with_text=True)  # regular file, size cap
            sc = parse_scenario(doc_f, file=f, text=txt, library_dirs=lib or None,
                                site_dirs=sdirs or None)
            if lib:
                prints[(dyn, ns)] = shape_fingerprint(sc.shape)
            if sc.attitude.dynamics != dyn:
                raise InputError(f"scenario {f.name} has dynamics {sc.attitude.dynamics!r}, the "
                                 f"grid cell needs {dyn!r}", file=path, field="study.scenario",
                                 value=str(f))
            if ("filter_drift_horizon_s" in opts and dyn == "uncontrolled"
                    and sc.attitude.drift_deg_per_orbit is None):
                raise InputError(f"options.filter_drift_horizon_s sizes the filters' η from the "
                                 f"scenario's drift; scenario {f.name} gives eta_sigma_deg_s2 "
                                 "instead", file=f, field="attitude.drift_deg_per_orbit",
                                 allowed="a drift in degrees after one orbit (Bernard §9.2.4)")
            if len(sc.sites) != ns:
                raise InputError(f"scenario {f.name} has {len(sc.sites)} site(s), the grid cell "
                                 f"needs {ns}", file=path, field="study.scenario", value=str(f))
            files[(dyn, ns)] = f.resolve()
            texts[(dyn, ns)] = txt
    cells = [Cell(*vals) for vals in itertools.product(*(axes[k] for k in GRID_KEYS))]
    skipped = []
    if table is not None:
        from .agreement import thesis_color

        skipped = [c for c in cells if thesis_color(table, c.as_dict()) == "grey"]
        cells = [c for c in cells if c not in skipped]
    return Study(name=name, seed=seed, runs=runs, cells=cells, scenario_files=files,
                 scenario_texts=texts, options=opts, source=str(path), text=text,
                 library_dirs=lib, site_dirs=sdirs, shape_fingerprints=prints,
                 thesis_table=table, thesis_table_text=table_text, skipped_cells=skipped)

