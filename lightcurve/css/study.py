"""CSS Monte Carlo studies: percentile envelopes of the angular error, time above 15°/30°,
time to sun pointing (O'Keefe 2015, ch. 3 results).

A study runs :func:`lightcurve.css.truth.simulate` for ``n_runs`` dispersed cases of each
(estimator, gyro) combination.  Metrics (angles in degrees, times in seconds):

* estimation error ``∠(ŝ, s)`` — percentile envelopes (50/90/99 %) over the runs that are
  sunlit at each time,
  and the 99th percentile over all *settled sunlit* samples (lit, and at least ``settle_s``
  after the last entry into sunlight — "after the first minutes in sunlight");
* time with the estimation error above 15° and 30° per orbit (sunlit samples);
* with control: pointing error ``∠(ĥ, s)`` of the solar-array axis, time to sun pointing
  (first time it stays below 15° for 60 s) and time above 15°/30° per orbit.

Study TOML (``pipelines/css/*.toml``)::

    [study]
    name = "css-tumbling-dual-pyramid"
    n_runs = 1000
    seed = 1
    settle_s = 300.0
    [scenario]
    configuration = "dual_pyramid"     # "cube" or a path to a sensor TOML
    fov_half_angle_deg = 70.0          # for the bundled configurations
    estimators = ["ekf", "eckf", "wavg", "lsmn", "wlsmn"]
    gyros = ["tactical"]               # grade names or "none"
    controlled = false
    duration_s = 1800.0
    dt_s = 0.5
    epoch_utc = "2015-03-01T00:00:00Z"
    albedo = "builtin"                 # "builtin", "none", or a CERES/TOMS file path
    filter_albedo = "builtin"          # the sun-line filters' own albedo model, same choices
    [dispersions]                      # optional overrides of Dispersions fields
    [filter]                           # optional overrides of FilterParams fields
    [control]                          # optional k_gain, p_gain, deadband_deg, u_max
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_path, atomic_write_text
from ..io.tomlio import Section, load_toml
from .albedo import load_albedo_map
from .configurations import DEFAULT_FOV_HALF_ANGLE_DEG, configuration_by_name
from .control import ControlParams
from .gyro import GYRO_GRADES
from .sunline_ekf import FilterParams
from .truth import ESTIMATORS, MU_EARTH, R_EARTH_M, Dispersions, Scenario, simulate

__all__ = ["StudySpec", "CaseSummary", "run_case", "run_study", "load_study", "write_report",
           "gyroless_params", "settled_mask", "direction_nees", "THESIS_P99_DEG"]

# Values quoted by the issue for the thesis's uncontrolled tumbling dual-pyramid study
# (99th percentile of the angular error after the first minutes in sunlight, degrees).
THESIS_P99_DEG = {"ekf": 5.0, "eckf": 6.0, "wavg": 45.0, "lsmn": 45.0, "wlsmn": 45.0}


def gyroless_params(base: FilterParams | None = None) -> FilterParams:
    """Filter tuning for gyro-less operation (eq. 3.67 rates): larger process noise, a
    slower rate low-pass and a larger considered rate error."""
    b = base or FilterParams()
    return replace(b, q_proc=1e-3, rate_alpha=0.95, sigma_meas=0.1, consider_sigma=2e-3)


def direction_nees(d_hat, P, s_true):
    """Normalised estimation error squared of the Sun *direction* (2 degrees of freedom).

    The sun-line state ``d`` carries an unknown scale, so only its direction is compared:
    with ``ŝ = d/|d|`` and an orthonormal basis ``B`` (3×2) of the plane perpendicular to
    ``ŝ``, ``e = |d| Bᵀ s_true`` (the error of d if its scale were right) and
    ``NEES = eᵀ (Bᵀ P B)⁻¹ e``, χ² with 2 degrees of freedom for a consistent filter
    (mean 2, 95 % below 5.991).  d_hat (K,3), P (K,3,3), s_true (K,3) unit; returns (K,)
    (NaN where d is zero).
    """
    d = np.atleast_2d(np.asarray(d_hat, dtype=float))
    P = np.asarray(P, dtype=float).reshape(-1, 3, 3)
    s = np.atleast_2d(np.asarray(s_true, dtype=float))
    nd = np.linalg.norm(d, axis=1)
    ok = nd > 0
    u = np.where(ok[:, None], d / np.where(ok, nd, 1.0)[:, None], [1.0, 0.0, 0.0])
    a = np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    b2 = a - np.sum(a * u, axis=1, keepdims=True) * u
    b2 /= np.linalg.norm(b2, axis=1, keepdims=True)
    b3 = np.cross(u, b2)
    B = np.stack([b2, b3], axis=2)  # (K,3,2)
    e = nd[:, None] * np.einsum("kij,ki->kj", B, s)
    P2 = np.einsum("kia,kij,kjb->kab", B, P, B)
    det = P2[:, 0, 0] * P2[:, 1, 1] - P2[:, 0, 1] * P2[:, 1, 0]
    good = ok & (det > 0)
    det = np.where(good, det, 1.0)
    q = (P2[:, 1, 1] * e[:, 0] ** 2 - 2 * P2[:, 0, 1] * e[:, 0] * e[:, 1]
         + P2[:, 0, 0] * e[:, 1] ** 2) / det
    return np.where(good, q, np.nan)


def settled_mask(t, lit, settle_s):
    """Samples that are sunlit (lit > 0.999) and at least ``settle_s`` seconds after the
    latest entry into sunlight (or the start)."""
    t = np.asarray(t)
    sun = np.asarray(lit) > 0.999
    last_entry = np.empty_like(t)
    entry = t[0]
    for k in range(t.size):
        if sun[k] and (k == 0 or not sun[k - 1]):
            entry = t[k]
        last_entry[k] = entry
    return sun & (t - last_entry >= settle_s)


_MAP_CACHE: dict = {}


def _albedo_choice(name):
    """'builtin' → None (built-in zonal model), 'none' → False (off), else a loaded map
    (cached per path so that every run shares one grid)."""
    if name == "builtin":
        return None
    if name == "none":
        return False
    if name not in _MAP_CACHE:
        _MAP_CACHE[name] = load_albedo_map(name)
    return _MAP_CACHE[name]


@dataclass
class StudySpec:
    """A study definition (see the module docstring for the TOML layout)."""

    name: str = "css-study"
    n_runs: int = 200
    seed: int = 1
    settle_s: float = 300.0
    configuration: str = "dual_pyramid"
    fov_half_angle_deg: float = DEFAULT_FOV_HALF_ANGLE_DEG
    estimators: tuple = ("ekf", "eckf", "wavg", "lsmn", "wlsmn")
    gyros: tuple = ("tactical",)
    controlled: bool = False
    duration_s: float = 1800.0
    dt_s: float = 0.5
    epoch_utc: str = "2015-03-01T00:00:00Z"
    albedo: str = "builtin"
    filter_albedo: str = "builtin"
    dispersions: Dispersions = field(default_factory=Dispersions)
    filter_params: FilterParams = field(default_factory=FilterParams)
    control: ControlParams = field(default_factory=ControlParams)

    def scenario(self, estimator: str, gyro) -> Scenario:
        """The :class:`Scenario` of one (estimator, gyro) case."""
        if self.configuration in ("dual_pyramid", "cube"):
            css = configuration_by_name(self.configuration, fov_half_angle_deg=self.fov_half_angle_deg)
        else:
            css = configuration_by_name(self.configuration)
        alb = _albedo_choice(self.albedo)
        falb = _albedo_choice(self.filter_albedo)
        g = None if gyro in (None, "none") else gyro
        fp = self.filter_params if g is not None else gyroless_params(self.filter_params)
        return Scenario(css, estimator=estimator, gyro=g, controlled=self.controlled,
                        duration_s=self.duration_s, dt_s=self.dt_s, epoch_utc=self.epoch_utc,
                        dispersions=self.dispersions, filter_params=fp, control=self.control,
                        albedo=alb, filter_albedo=falb)


@dataclass
class CaseSummary:
    """Metrics of one (estimator, gyro) case over all runs (degrees, seconds)."""

    estimator: str
    gyro: str
    n_runs: int
    p99_settled_deg: float
    p50_settled_deg: float
    time_above_15_per_orbit_s: float
    time_above_30_per_orbit_s: float
    pointing_time_to_15_s: float | None = None
    pointing_above_15_per_orbit_s: float | None = None
    pointing_above_30_per_orbit_s: float | None = None
    t: np.ndarray | None = None
    envelope_deg: dict | None = None
    pointing_envelope_deg: dict | None = None
    nees_mean: float | None = None
    nees_frac_95: float | None = None

    def as_dict(self):
        d = {k: v for k, v in asdict(self).items()
             if k not in ("t", "envelope_deg", "pointing_envelope_deg")}
        return d


def _orbit_period(alt_m=400e3):
    a = R_EARTH_M + alt_m
    return 2 * np.pi * np.sqrt(a ** 3 / MU_EARTH)


def run_case(spec: StudySpec, estimator: str, gyro, progress=None) -> CaseSummary:
    """Run ``spec.n_runs`` dispersed simulations of one case; returns its summary.

    Run ``i`` uses the seed sequence ``(spec.seed, i)`` so that every estimator and gyro sees
    the same dispersed spacecraft, orbit and noise."""
    sc = spec.scenario(estimator, gyro)
    period = _orbit_period(sc.altitude_m)
    errs, settled, above15, above30 = [], [], [], []
    perr, t15, pa15, pa30 = [], [], [], []
    nees = []
    t = None
    for i in range(spec.n_runs):
        r = simulate(sc, np.random.SeedSequence([spec.seed, i]))
        t = r.t
        dt = sc.dt_s
        m = settled_mask(r.t, r.lit, spec.settle_s)
        sun = r.lit > 0.999
        errs.append(np.where(sun, r.error_deg, np.nan))  # envelopes over sunlit samples
        settled.append(r.error_deg[m])
        if r.p_cov is not None:
            nees.append(direction_nees(r.d_hat[m], r.p_cov[m], r.s_true[m]))
        above15.append(np.sum((r.error_deg > 15) & sun) * dt)
        above30.append(np.sum((r.error_deg > 30) & sun) * dt)
        if spec.controlled:
            pe = np.degrees(np.arccos(np.clip(r.s_true @ r.info["pointing_axis"], -1, 1)))
            perr.append(pe)
            hold = int(round(60.0 / dt))
            below = pe < 15.0
            ok = np.convolve(below.astype(int), np.ones(hold, dtype=int), "valid") == hold
            idx = np.flatnonzero(ok)
            t15.append(r.t[idx[0]] if idx.size else np.nan)
            pa15.append(np.sum(pe > 15) * dt)
            pa30.append(np.sum(pe > 30) * dt)
        if progress is not None:
            progress(i)
    E = np.vstack(errs)
    allsettled = np.concatenate(settled) if settled else np.array([np.nan])
    if allsettled.size == 0:
        allsettled = np.array([np.nan])
    orbits = spec.duration_s / period
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-eclipse columns -> NaN
            env = {p: np.nanpercentile(E, p, axis=0) for p in (50, 90, 99)}
    summ = CaseSummary(estimator, str(gyro), spec.n_runs,
                       float(np.percentile(allsettled, 99)), float(np.percentile(allsettled, 50)),
                       float(np.mean(above15) / orbits), float(np.mean(above30) / orbits),
                       t=t, envelope_deg=env)
    if nees:
        allnees = np.concatenate(nees)
        allnees = allnees[np.isfinite(allnees)]
        if allnees.size:
            # consistency of the sun-line filters (2-DOF chi-square: mean 2, 95 % < 5.991)
            summ.nees_mean = float(np.mean(allnees))
            summ.nees_frac_95 = float(np.mean(allnees < 5.991))
    if spec.controlled:
        Pm = np.vstack(perr)
        summ.pointing_time_to_15_s = float(np.nanmedian(t15)) if np.any(np.isfinite(t15)) else None
        summ.pointing_above_15_per_orbit_s = float(np.mean(pa15) / orbits)
        summ.pointing_above_30_per_orbit_s = float(np.mean(pa30) / orbits)
        summ.pointing_envelope_deg = {p: np.percentile(Pm, p, axis=0) for p in (50, 90, 99)}
    return summ


def run_study(spec: StudySpec, progress=None) -> list[CaseSummary]:
    """All (estimator, gyro) cases of a study."""
    return [run_case(spec, est, g, progress) for g in spec.gyros for est in spec.estimators]


def _overrides(sec: Section | None, obj, rename=None):
    if sec is None:
        return obj
    kw = {}
    names = {f.name: f for f in fields(obj)}
    for key in list(sec.data):
        target = (rename or {}).get(key, key)
        if target not in names:
            continue
        cur = getattr(obj, target)
        if isinstance(cur, tuple):
            kw[target] = tuple(sec.vector(key, n=len(cur)))
        elif isinstance(cur, bool):
            kw[target] = sec.bool(key)
        elif isinstance(cur, int):
            kw[target] = sec.int(key, min=1)
        else:
            v = sec.float(key, min=0.0)
            kw[target] = np.radians(v) if key.endswith("_deg") and not target.endswith("_deg") else v
    sec.check_unknown()
    return replace(obj, **kw)


def load_study(path) -> StudySpec:
    """Read a study TOML (layout in the module docstring); :class:`InputError` on bad input."""
    doc = Section(load_toml(path), file=path)
    st = doc.section("study")
    sc = doc.section("scenario")
    spec = StudySpec(
        name=st.str("name", "css-study"),
        n_runs=st.int("n_runs", 200, min=1, max=100000),
        seed=st.int("seed", 1, min=0),
        settle_s=st.float("settle_s", 300.0, min=0.0),
    )
    st.check_unknown()
    conf = sc.str("configuration", "dual_pyramid")
    if conf not in ("dual_pyramid", "cube"):
        p = Path(conf)
        if not p.is_absolute():
            p = Path(path).parent / p
        conf = str(p)
    ests = sc.raw("estimators", list(spec.estimators))
    if not isinstance(ests, list) or not ests or any(e not in ESTIMATORS for e in ests):
        raise InputError("unknown estimator list", file=path, field="scenario.estimators",
                         value=ests, allowed=", ".join(ESTIMATORS))
    gyros = sc.raw("gyros", list(spec.gyros))
    allowed_g = tuple(GYRO_GRADES) + ("none",)
    if not isinstance(gyros, list) or not gyros or any(g not in allowed_g for g in gyros):
        raise InputError("unknown gyro list", file=path, field="scenario.gyros", value=gyros,
                         allowed=", ".join(allowed_g))
    alb = sc.str("albedo", "builtin")
    if alb not in ("builtin", "none"):
        p = Path(alb)
        if not p.is_absolute():
            p = Path(path).parent / p
        alb = str(p)
        try:
            load_albedo_map(alb)  # validate early
        except InputError as exc:  # name the study file and key, then the map's problem
            raise InputError(str(exc), file=path, field="scenario.albedo") from None
    falb = sc.str("filter_albedo", "builtin")
    if falb not in ("builtin", "none"):
        p = Path(falb)
        if not p.is_absolute():
            p = Path(path).parent / p
        falb = str(p)
        try:
            load_albedo_map(falb)  # validate early
        except InputError as exc:  # name the study file and key, then the map's problem
            raise InputError(str(exc), file=path, field="scenario.filter_albedo") from None
    spec = replace(
        spec, configuration=conf,
        fov_half_angle_deg=sc.float("fov_half_angle_deg", DEFAULT_FOV_HALF_ANGLE_DEG, min=0.0,
                                    max=90.0, min_open=True),
        estimators=tuple(ests), gyros=tuple(gyros), controlled=sc.bool("controlled", False),
        duration_s=sc.float("duration_s", 1800.0, min=1.0), dt_s=sc.float("dt_s", 0.5, min=1e-3, max=60.0),
        epoch_utc=sc.str("epoch_utc", "2015-03-01T00:00:00Z"), albedo=alb, filter_albedo=falb)
    sc.check_unknown()
    spec.dispersions = _overrides(doc.section("dispersions", None), spec.dispersions)
    spec.filter_params = _overrides(doc.section("filter", None), spec.filter_params)
    spec.control = _overrides(doc.section("control", None), spec.control,
                              rename={"deadband_deg": "deadband_rad"})
    doc.check_unknown()
    return spec


def write_report(spec: StudySpec, cases: list[CaseSummary], out_dir) -> Path:
    """Write ``summary.json``, ``summary.txt``, ``envelopes.png`` and ``error_maps.png``
    (noise-free single-point error maps, figs. 3.1-3.2) into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    payload = {"study": spec.name, "n_runs": spec.n_runs, "settle_s": spec.settle_s,
               "configuration": Path(spec.configuration).name, "controlled": spec.controlled,
               "thesis_p99_deg": THESIS_P99_DEG,
               "cases": [c.as_dict() for c in cases]}
    atomic_write_text(out / "summary.json", json.dumps(payload, indent=2, default=float) + "\n")
    lines = [f"CSS study {spec.name}: {spec.n_runs} runs, {Path(spec.configuration).name}, "
             f"{'controlled' if spec.controlled else 'uncontrolled tumbling'}",
             f"{'estimator':>9} {'gyro':>10} {'p50 deg':>8} {'p99 deg':>8} {'thesis':>7} "
             f"{'>15 s/orb':>9} {'>30 s/orb':>9}" + (f" {'t_point s':>9} {'pt>15 s/orb':>11}" if spec.controlled else "")]
    for c in cases:
        th = THESIS_P99_DEG.get(c.estimator)
        thesis = ("<" if c.estimator in ("ekf", "eckf") else ">") + f"{th:g}"
        row = (f"{c.estimator:>9} {c.gyro:>10} {c.p50_settled_deg:8.2f} {c.p99_settled_deg:8.2f} "
               f"{thesis:>7} {c.time_above_15_per_orbit_s:9.1f} {c.time_above_30_per_orbit_s:9.1f}")
        if spec.controlled:
            tp = "n/a" if c.pointing_time_to_15_s is None else f"{c.pointing_time_to_15_s:.0f}"
            row += f" {tp:>9} {c.pointing_above_15_per_orbit_s:11.1f}"
        lines.append(row)
    atomic_write_text(out / "summary.txt", "\n".join(lines) + "\n")
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    n = len(cases)
    fig, axes = plt.subplots(n, 1, figsize=(8, 2.2 * n), sharex=True, squeeze=False)
    for ax, c in zip(axes[:, 0], cases):
        tm = c.t / 60.0
        ax.fill_between(tm, 0, c.envelope_deg[99], color="C0", alpha=0.25, label="99 %")
        ax.fill_between(tm, 0, c.envelope_deg[90], color="C0", alpha=0.45, label="90 %")
        ax.plot(tm, c.envelope_deg[50], color="C0", label="median")
        if c.pointing_envelope_deg is not None:
            ax.plot(tm, c.pointing_envelope_deg[99], color="C3", lw=0.8, label="pointing 99 %")
        ax.axhline(15, color="k", lw=0.5, ls="--")
        ax.axhline(30, color="k", lw=0.5, ls=":")
        ax.set_ylim(0, 90)
        ax.set_ylabel("error (deg)")
        ax.set_title(f"{c.estimator.upper()}, gyro {c.gyro}", fontsize=9)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time (min)")
    fig.tight_layout()
    with atomic_path(out / "envelopes.png", suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    # noise-free single-point error maps of the configuration (figs. 3.1-3.2, 3.10)
    from .single_point import error_map

    css = spec.scenario("ekf", spec.gyros[0]).css
    fig, axes = plt.subplots(3, 1, figsize=(7, 8.5), squeeze=False)
    for ax, method in zip(axes[:, 0], ("wavg", "lsmn", "wlsmn")):
        em = error_map(css, method, n_az=121, n_el=61, threshold=0.0)
        pc = ax.pcolormesh(em.az_deg, em.el_deg, em.error_deg, shading="auto", cmap="viridis")
        fig.colorbar(pc, ax=ax, label="error (deg)")
        ax.set_title(f"{method.upper()} noise-free error, {css.name}", fontsize=9)
        ax.set_ylabel("Sun elevation (deg)")
    axes[-1, 0].set_xlabel("Sun azimuth in body axes (deg)")
    fig.tight_layout()
    with atomic_path(out / "error_maps.png", suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)
    return out
