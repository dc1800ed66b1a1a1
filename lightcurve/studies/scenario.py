"""Scenario files: loading and validating the TOML that defines one simulated observation.

Sections (documented in docs/formats.md): ``[scenario]`` (epoch_utc, duration_s, cadence_s,
seed), ``[orbit]`` (keplerian / cartesian / tle, gravity model), ``[shape]`` (library name or
mesh + materials; ``cook_torrance = "physical" | "thesis"`` selects the diffuse term,
:func:`with_cook_torrance_form`), ``[attitude]`` (controlled | uncontrolled, initial 3-2-1 angles, body rates,
ACS noise, inertia, process noise, torques), ``[[sites]]`` (id or inline lat/lon/height, windows),
``[measurement]`` (noise, eclipse handling, visibility limits, Sun magnitude), ``[filter]``
(``variant = "robust" | "thesis"``: the filters ``invert`` runs on the simulated file by
default, :mod:`lightcurve.filters.invert`), ``[effects]``
(physics effects switched on; :mod:`lightcurve.physics`), ``[reflection]`` (truth reflection
parameters perturbed from the shape file's values, Bernard §10.1; see :class:`ReflectionSpec`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._paths import data_dir
from ..errors import InputError
from ..io.tomlio import REQUIRED, Section, load_toml, loads_toml

__all__ = [
    "SCENARIO_ALIASES", "resolve_scenario", "Scenario", "SiteSpec", "AttitudeSpec",
    "MeasurementSpec", "load_scenario", "parse_scenario", "scenario_from_lightcurve",
    "eta_sigma_from_drift", "orbital_period_s", "with_cook_torrance_form", "COOK_TORRANCE_FORMS"]


@dataclass
class SiteSpec:
    """One observing site of a scenario: the resolved site and its observing windows (s)."""

    site: object  # lightcurve.geometry.sites.Site
    windows_s: list


@dataclass
class AttitudeSpec:
    """Initial attitude and the truth dynamics.

    ``euler321_deg`` = (φ about z, θ about y, ψ about x), inertial→body (Bernard eq. 3.7);
    ``omega_deg_s`` body rates in body axes; ``acs_sigma_deg`` the 1σ ACS attitude noise applied
    at measurement times (controlled model, Bernard eq. 7.8–7.11); ``eta_sigma_deg_s2`` the 1σ
    white angular-acceleration noise density of the uncontrolled model; ``torques`` the
    environmental torques of the uncontrolled model; ``inertia_kg_m2`` overrides the shape's.
    ``frame = "nadir"`` makes ``euler321_deg`` relative to the nadir (LVLH) frame at the epoch
    (z to the Earth's centre, y along the negative orbit normal) and ``omega_deg_s`` relative to
    it, so zero angles and rates give a nadir-pointing object turning at the orbit rate.

    ``acs_mode`` (controlled): ``"random_walk"`` (default; ζ accumulates,
    ``q_k = exp(ζ_k) ⊗ exp(ωΔt) ⊗ q_{k−1}``) or ``"jitter"`` (Bernard eq. 7.10: the true attitude
    is the commanded constant-rate profile perturbed by ζ_k at each measurement time, without
    accumulation). ``torque_forms`` (uncontrolled): ``"physical"`` (default) or ``"thesis"``
    (Bernard eq. 4.16–4.21 as written; see :class:`lightcurve.dynamics.truth.UncontrolledTruth`).
    ``drift_deg_per_orbit`` (uncontrolled, instead of ``eta_sigma_deg_s2``): the process noise is
    sized so that η alone gives a 1σ attitude error of this many degrees per axis after one
    orbital period T (Bernard §9.2.4: 2° LEO, 10° MEO, 15° GEO), i.e. for white η of PSD σ_η²
    the double integral has variance ``σ_η² T³/3`` (gyroscopic coupling neglected), so
    ``σ_η = d √(3/T³)`` (:func:`eta_sigma_from_drift`); T from the osculating semi-major axis
    at the epoch.

    ``omega_frame`` (TOML ``[attitude] omega_frame``, default ``"body"``) says in which axes the
    file gave the rates. ``"body"``: the file's ``omega_deg_s`` are body-axis components and are
    used as they are. ``"inertial"`` (only with ``frame = "inertial"``): the file gave the
    components ω_I of the angular velocity in the inertial axes (ECI = GCRS), the frame the
    Euler angles are relative to; they are converted ONCE, at the epoch, to body axes,
    ``ω_B = A(q0) ω_I`` with q0 the quaternion of ``euler321_deg`` (Bernard eq. 3.7, 3.16).
    After parsing, ``omega_deg_s`` therefore always holds the epoch body rates (deg/s, body
    axes) and ``omega_input_deg_s`` the values as written in the file. For a torque-free
    isotropic (or constant-rate controlled) body the inertial angular velocity is constant, so
    the truth then turns about the fixed inertial axis ω̂_I. With ``frame = "nadir"`` the
    rates are relative to the rotating nadir frame (see above) and an inertial-axes reading
    is ambiguous (relative or total rate?), so ``omega_frame = "inertial"`` is refused there.
    """

    dynamics: str
    euler321_deg: np.ndarray
    omega_deg_s: np.ndarray
    acs_sigma_deg: float = 0.0
    frame: str = "inertial"
    eta_sigma_deg_s2: float = 0.0
    torques: tuple = ()
    inertia_kg_m2: np.ndarray | None = None
    #: ``dynamics = "law"``: the attitude law's name (lightcurve.dynamics.laws.LAWS)
    law: str = ""
    #: axes of the file's rates: "body" or "inertial" (converted to body at parse time)
    omega_frame: str = "body"
    #: the rates exactly as written in the file (deg/s, in ``omega_frame`` axes); None = omega_deg_s
    omega_input_deg_s: np.ndarray | None = None
    #: controlled truth: how the ACS error ζ acts — "random_walk" (accumulates) or "jitter"
    #: (perturbs the commanded profile without accumulating, Bernard eq. 7.10)
    acs_mode: str = "random_walk"
    #: uncontrolled truth: forms of the named torques — "physical" or "thesis" (Bernard
    #: eq. 4.16–4.21 as written: SRP reflectivities R_d = ξ, R_s = 1 − ξ; drag along the facet
    #: normal with the orbital velocity)
    torque_forms: str = "physical"
    #: uncontrolled truth: 1σ attitude drift per axis after one orbital period that sized
    #: ``eta_sigma_deg_s2`` (Bernard §9.2.4); None when the file gave η directly
    drift_deg_per_orbit: float | None = None


@dataclass
class MeasurementSpec:
    """Measurement model settings.

    ``r_percent``: noise level r of Bernard eq. 9.3 (σ = m·r/3 with r as a fraction);
    ``ignore_eclipse``: compute magnitudes as if the object were sunlit (thesis cases);
    ``min_elevation_deg``: lowest usable object elevation; ``require_dark_site`` with
    ``twilight_deg``: measure only when the Sun is below that altitude at the site;
    ``sun_mag``: apparent magnitude of the Sun in the band (V: −26.74); ``band``: a band of
    :data:`lightcurve.photometry.bands.SUN_MAGNITUDES` setting ``sun_mag`` ('' = not given).
    """

    r_percent: float = 1.0
    ignore_eclipse: bool = False
    min_elevation_deg: float = 0.0
    require_dark_site: bool = True
    twilight_deg: float = -12.0
    sun_mag: float = -26.74
    band: str = ""


@dataclass
class ReflectionSpec:
    """``[reflection]``: perturb the truth reflection parameters (Bernard §10.1).

    Every selected parameter p of every Cook–Torrance facet becomes p + N(0, (sigma_frac·p)²)
    (redrawn until in range: ξ, a in (0,1); m, A > 0) from a stream seeded by the scenario seed
    and independent of the attitude and noise streams. ``params`` ⊆ {"xi", "a", "m", "A"}
    (A = facet area, m²). The filters keep using the nominal shape; the truth values are stored
    in the lightcurve file's ``attrs["reflection_truth"]`` (JSON).
    """

    perturb: bool = True
    sigma_frac: float = 0.1
    params: tuple = ("xi", "a", "m", "A")


@dataclass
class Scenario:
    """A validated scenario (see module docstring)."""

    epoch_utc: str
    duration_s: float
    cadence_s: float
    seed: int
    orbit: object  # lightcurve.geometry.orbits.Orbit
    shape: object  # lightcurve.photometry Shape
    attitude: AttitudeSpec
    sites: list
    measurement: MeasurementSpec
    effects: dict = field(default_factory=dict)
    #: ``[recording]`` column mapping (lightcurve.io.recording.RecordingSpec) or None
    recording: object = None
    #: ``[reflection]`` truth perturbation (:class:`ReflectionSpec`) or None
    reflection: object = None
    name: str = ""
    source: str = ""
    text: str = ""

    def with_seed(self, seed: int) -> "Scenario":
        """A copy with another random seed."""
        from dataclasses import replace

        return replace(self, seed=int(seed))


_DYNAMICS = ("controlled", "uncontrolled", "law")
#: most epochs a scenario may schedule (same cap as geometry.schedules.cadence_grid)
_MAX_EPOCHS = 50_000_000
#: memory of the simulator per scheduled epoch and site (measured 520 B on the default
#: scenario at 1 s cadence, 2·10⁴ to 8·10⁴ epochs; rounded up)
SIMULATE_BYTES_PER_EPOCH = 600
_TORQUES = ("gravity_gradient", "srp", "drag")
_ACS_MODES = ("random_walk", "jitter")
_TORQUE_FORMS = ("physical", "thesis")


#: ``[shape] cook_torrance``: the Cook–Torrance diffuse term of the shape's materials
COOK_TORRANCE_FORMS = ("physical", "thesis")
_CT_BRDF = {"physical": "cook_torrance", "thesis": "cook_torrance_bernard"}


def with_cook_torrance_form(shape, form: str):
    """A copy of ``shape`` whose Cook–Torrance materials use the ``form`` diffuse term:
    ``"physical"`` (``cook_torrance``, f_d = ξ a/π) or ``"thesis"`` (``cook_torrance_bernard``,
    Bernard eq. 5.8 as printed, f_d = ξ a (n̂·ŝ)/π); other materials are kept. Same parameters."""
    from ..photometry.facets import Shape
    from ..photometry.materials import Material

    if form not in _CT_BRDF:
        raise ValueError(f"form: expected one of {', '.join(_CT_BRDF)}, got {form!r}")
    mats, changed = [], False
    for m in shape.materials:
        if m.brdf_name in _CT_BRDF.values() and m.brdf_name != _CT_BRDF[form]:
            mats.append(Material.create(m.name, _CT_BRDF[form], **dict(m.params)))
            changed = True
        else:
            mats.append(m)
    if not changed:
        return shape
    return Shape(shape.name, shape.areas_m2, shape.normals_body, shape.centers_body_m, mats,
                 shape.mass_kg, shape.inertia_kg_m2, convex=shape.convex,
                 tangents_body=shape.tangents_body, description=shape.description,
                 source=shape.source, vertices_m=shape.vertices_m, faces=shape.faces)


def orbital_period_s(orbit, epoch_utc) -> float:
    """Osculating period 2π√(a³/μ) (s) of ``orbit`` at ``epoch_utc`` (a from the vis-viva
    equation with the epoch state; μ = 3.986004418e14 m³/s²)."""
    from ..dynamics.torques import MU_EARTH

    r, v = orbit.positions(epoch_utc, np.array([0.0]))
    rn, vn = float(np.linalg.norm(r[0])), float(np.linalg.norm(v[0]))
    a = 1.0 / (2.0 / rn - vn * vn / MU_EARTH)
    return float(2.0 * np.pi * np.sqrt(a ** 3 / MU_EARTH))


def eta_sigma_from_drift(drift_deg: float, period_s: float) -> float:
    """σ_η (deg/s^{3/2}) of white angular-acceleration noise whose double integral has a 1σ of
    ``drift_deg`` (deg, per axis) after ``period_s`` seconds: ``σ_η = d √(3/T³)``
    (variance of ∫∫η over T is σ_η² T³/3; Bernard §9.2.4 sizes the process noise this way)."""
    return float(drift_deg) * float(np.sqrt(3.0 / float(period_s) ** 3))


def load_scenario(path, library_dirs=None, site_dirs=None, *, shape=None) -> Scenario:
    """Load and validate a scenario TOML file; relative mesh paths resolve against its folder.

    ``shape``: a resolved :class:`~lightcurve.photometry.Shape` used instead of the file's
    ``[shape]`` (whose keys are still validated), e.g. the shape a lightcurve file carries.
    """
    path = Path(path)
    doc, text = load_toml(path, with_text=True)
    return parse_scenario(doc, file=path, text=text, library_dirs=library_dirs,
                          site_dirs=site_dirs, shape=shape)


def parse_scenario(doc, file="<scenario>", text: str | None = None, library_dirs=None,
                   site_dirs=None, *, embedded: bool = False, shape=None,
                   sites=None) -> Scenario:
    """Validate a parsed scenario document (dict) or TOML text and build a :class:`Scenario`.

    Parameters
    ----------
    library_dirs, site_dirs : optional
        Extra shape-library and observatory folders (searched before the bundled ones).
    embedded : bool
        True for a scenario read from inside a data file (the ``scenario`` attribute of a
        lightcurve HDF5 file): it may name a library shape only, never a mesh or shape file by
        path, so a received file cannot make the program read an arbitrary file.
    shape : Shape, optional
        A resolved shape used instead of loading ``[shape]`` (its keys are still validated;
        ``areas_m2`` is then not applied: the given shape is final).
    sites : mapping id -> Site, optional
        Sites consulted first for ``[[sites]] name = "<id>"`` references (e.g. the sites a
        lightcurve file carries), before ``site_dirs`` and the bundled catalogue.

    Site ids (docs/formats.md "Sites"): a ``name`` without coordinates is a catalogue id;
    an inline table's id follows :func:`lightcurve.geometry.sites.inline_site_id`. Two
    entries with one id are an error.
    """
    from ..geometry.orbits import orbit_from_section
    from ..geometry.sites import get_site
    from ..geometry.time import parse_epoch
    from ..photometry import load_shape

    if isinstance(doc, str):
        text = doc
        doc = loads_toml(doc, file=file)
    root = Section(doc, file=file)
    sc = root.section("scenario")
    epoch = sc.str("epoch_utc")
    try:
        epoch_dt = parse_epoch(epoch)  # validates ISO 8601 and the DE421 range
    except InputError as exc:
        raise InputError(exc.bare_message, file=file, field="scenario.epoch_utc", value=epoch,
                         allowed=exc.allowed) from None
    # a scenario that models a recording ([recording]) may span more than 30 days and need
    # no duration or [orbit]: the recording gives the epochs and (topocentric) positions
    has_rec = isinstance(doc.get("recording"), dict)
    duration = sc.float("duration_s", None if has_rec else REQUIRED, min=0.0, min_open=True,
                        max=None if has_rec else 30 * 86400.0)
    cadence = sc.float("cadence_s", 5.0, min=1e-3, max=duration)
    if duration is not None:
        from ..geometry.time import DE421_END_UTC

        # refuse huge schedules here (bounded memory), naming the file, before allocating them
        if duration / cadence > _MAX_EPOCHS:
            raise InputError("too many epochs (duration_s / cadence_s)", file=file,
                             field="scenario.cadence_s", value=cadence,
                             allowed=f"duration_s / cadence_s <= {_MAX_EPOCHS:.0e}")
        if (DE421_END_UTC - epoch_dt).total_seconds() < duration:
            raise InputError("epoch_utc + duration_s runs past the end of the DE421 ephemeris",
                             file=file, field="scenario.duration_s", value=duration,
                             allowed=f"<= {(DE421_END_UTC - epoch_dt).total_seconds():.0f} s "
                             "(DE421 ends 2053-10-08 UTC)")
    seed = sc.int("seed", 0, min=0, max=2**63 - 1)
    name = sc.str("name", Path(str(file)).stem)
    sc.check_unknown(extra_allowed=("description",))

    orbit = orbit_from_section(root.section("orbit")) if (root.has("orbit") or not has_rec) else None

    sh = root.section("shape")
    base = Path(str(file)).parent if file and not str(file).startswith("<") else Path.cwd()
    if embedded and (sh.has("mesh") or sh.has("materials")):
        raise InputError("a scenario stored in a data file may not name mesh or material "
                         "files", file=file, field="shape.mesh" if sh.has("mesh") else
                         "shape.materials", allowed="a library shape name (shape.name); give "
                         "the model scenario as a file instead")
    if sh.has("mesh"):
        mesh = base / sh.str("mesh")
        materials = base / sh.str("materials")
        spec = (mesh, materials)
    else:
        spec = sh.str("name")
    areas = sh.vector("areas_m2", None, min=0.0, min_open=True)
    ct_form = sh.str("cook_torrance", "physical", choices=COOK_TORRANCE_FORMS)
    sh.check_unknown()
    given_shape = shape is not None
    if not given_shape:
        try:
            shape = load_shape(spec, library_dirs=library_dirs, library_only=embedded)
        except InputError:
            raise
        except (FileNotFoundError, KeyError) as exc:
            raise InputError(f"cannot load shape: {exc}", file=file, field="shape") from None
    if areas is not None and not given_shape:  # facet areas overriding the library's
        if areas.size != shape.n_facets:
            raise InputError(f"expected {shape.n_facets} facet areas", file=file,
                             field="shape.areas_m2", value=areas.tolist())
        shape = shape.copy_with(areas_m2=areas)
    if ct_form == "thesis" and not given_shape:
        shape = with_cook_torrance_form(shape, "thesis")

    at = root.section("attitude")
    dyn = at.str("dynamics", "controlled", choices=_DYNAMICS)
    att = AttitudeSpec(
        dynamics=dyn,
        euler321_deg=at.vector("euler321_deg", [0.0] * 3 if dyn == "law" else REQUIRED, n=3,
                               min=-360.0, max=360.0),
        omega_deg_s=at.vector("omega_deg_s", [0.0] * 3 if dyn == "law" else REQUIRED, n=3,
                              min=-3600.0, max=3600.0),
        acs_sigma_deg=at.float("acs_sigma_deg", 0.0, min=0.0, max=30.0),
        frame=at.str("frame", "inertial", choices=("inertial", "nadir")),
        eta_sigma_deg_s2=at.float("eta_sigma_deg_s2", 0.0, min=0.0, max=10.0),
        inertia_kg_m2=at.matrix("inertia_kg_m2", None, shape=(3, 3)),
        acs_mode=at.str("acs_mode", "random_walk", choices=_ACS_MODES),
        torque_forms=at.str("torque_forms", "physical", choices=_TORQUE_FORMS),
    )
    if at.has("drift_deg_per_orbit"):
        if at.has("eta_sigma_deg_s2"):
            raise InputError("give either eta_sigma_deg_s2 or drift_deg_per_orbit, not both",
                             file=file, field="attitude.drift_deg_per_orbit")
        if orbit is None:
            raise InputError("drift_deg_per_orbit needs an [orbit] (its period sizes the "
                             "process noise)", file=file, field="attitude.drift_deg_per_orbit")
        att.drift_deg_per_orbit = at.float("drift_deg_per_orbit", min=0.0, max=180.0)
        att.eta_sigma_deg_s2 = eta_sigma_from_drift(att.drift_deg_per_orbit,
                                                    orbital_period_s(orbit, epoch))
    if att.inertia_kg_m2 is not None:
        from ..photometry.shapes_io import check_inertia_magnitude

        check_inertia_magnitude(att.inertia_kg_m2, file, "attitude.inertia_kg_m2")
    torques = at.raw("torques", ["gravity_gradient"] if dyn == "uncontrolled" else [])
    if not isinstance(torques, list) or any(t not in _TORQUES for t in torques):
        raise InputError("unknown torque model", file=file, field="attitude.torques", value=torques,
                         allowed=", ".join(_TORQUES))
    att.torques = tuple(torques)
    if att.inertia_kg_m2 is not None:
        J = att.inertia_kg_m2
        if not np.allclose(J, J.T) or np.any(np.linalg.eigvalsh(0.5 * (J + J.T)) <= 0):
            raise InputError("inertia must be symmetric positive definite", file=file,
                             field="attitude.inertia_kg_m2", value=J.tolist())
    if dyn == "law":
        from ..dynamics.laws import LAWS

        att.law = at.str("law", choices=LAWS)
    att.omega_frame = at.str("omega_frame", "body", choices=("body", "inertial"))
    att.omega_input_deg_s = att.omega_deg_s.copy()
    if att.omega_frame == "inertial":
        if att.frame != "inertial":
            # nadir rates are relative to the rotating nadir frame (AttitudeSpec docstring):
            # "inertial axes" would not say whether the orbit rate is included - refuse
            raise InputError('omega_frame = "inertial" needs frame = "inertial" (with a nadir '
                             "frame the rates are relative to the nadir frame, in body axes)",
                             file=file, field="attitude.omega_frame", value=att.omega_frame,
                             allowed='"body" (with frame = "nadir")')
        if dyn == "law":
            raise InputError("an attitude law prescribes its own rates", file=file,
                             field="attitude.omega_frame", value=att.omega_frame,
                             allowed='"body" (with dynamics = "law")')
        from ..rotations import euler321_to_quat, quat_rotate

        # ω_B = A(q0) ω_I once at the epoch (v_b = A(q) v_I, Bernard eq. 3.16/3.26)
        q0 = euler321_to_quat(np.radians(att.euler321_deg))
        att.omega_deg_s = quat_rotate(q0, att.omega_input_deg_s)  # linear: deg/s in, deg/s out
    at.check_unknown()

    from ..geometry.sites import inline_site_id, site_from_section

    known = dict(sites or {})
    sites = []
    for k_site, s in enumerate(root.sections("sites")):
        if s.has("name") and isinstance(s.data.get("name"), str) and not s.has("lat_deg"):
            sid = s.str("name")
            try:
                site = known[sid] if sid in known else get_site(sid, dirs=site_dirs)
            except InputError as exc:  # name the scenario file and the [[sites]] entry
                if exc.file and exc.file != str(file):  # the fault is in the site's own file
                    raise InputError(f"{exc.bare_message} (site {sid!r} of {file}, "
                                     f"{s.name})", file=exc.file, field=exc.field,
                                     value=exc.value, allowed=exc.allowed) from None
                allowed = exc.allowed
                if known:
                    allowed = ", ".join(sorted(known)) + ", " + (allowed or "")
                raise InputError(exc.bare_message, file=file, field=f"{s.name}.name", value=sid,
                                 allowed=allowed) from None
        else:
            inline = {k: s.raw(k) for k in ("name", "id", "lat_deg", "lon_deg", "height_m") if s.has(k)}
            site = site_from_section(Section(inline, file=file, name=s.name),
                                     site_id=inline_site_id(inline, k_site))
        if any(x.site.id == site.id for x in sites):
            raise InputError("two [[sites]] entries with one id (give each inline site its own "
                             "id or name)", file=file, field=f"{s.name}", value=site.id,
                             allowed="distinct site ids")
        windows = s.raw("windows_s", [[0.0, duration if duration is not None else 0.0]])
        ok = isinstance(windows, list) and all(
            isinstance(w, list) and len(w) == 2 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in w)
            and all(np.isfinite(float(x)) for x in w) and 0 <= w[0] <= w[1] for w in windows)
        if not ok:
            raise InputError("expected a list of [start_s, end_s] pairs of finite seconds with "
                             "0 <= start <= end", file=file, field=f"{s.name}.windows_s",
                             value=windows)
        s.check_unknown(extra_allowed=("lat_deg", "lon_deg", "height_m", "id"))
        # one place under two ids would count its measurements as independent twice over
        for j, other in enumerate(sites):
            if (other.site.lat_deg, other.site.lon_deg, other.site.height_m) == \
                    (site.lat_deg, site.lon_deg, site.height_m):
                raise InputError(f"the same place as sites[{j}] ({other.site.id}); give each "
                                 "site once, with all its windows in windows_s", file=file,
                                 field=s.name, value=site.id,
                                 allowed="distinct sites (id and position)")
        sites.append(SiteSpec(site=site, windows_s=[(float(a), float(b)) for a, b in windows]))
    if not sites:
        raise InputError("a scenario needs at least one [[sites]] entry", file=file, field="sites")
    if duration is not None:  # the simulator's arrays, per scheduled epoch and site
        from ..memory import check_allocation

        n_ep = int(duration / cadence) + 1
        check_allocation(n_ep * len(sites) * SIMULATE_BYTES_PER_EPOCH,
                         f"simulating {n_ep} epochs at {len(sites)} site(s)", file=file,
                         field="scenario.cadence_s", value=cadence)

    me = root.section("measurement", {})
    meas = MeasurementSpec(
        r_percent=me.float("r_percent", 1.0, min=0.0, min_open=True, max=100.0),
        ignore_eclipse=me.bool("ignore_eclipse", False),
        min_elevation_deg=me.float("min_elevation_deg", 0.0, min=-5.0, max=90.0),
        require_dark_site=me.bool("require_dark_site", True),
        twilight_deg=me.float("twilight_deg", -12.0, min=-90.0, max=10.0),
        sun_mag=me.float("sun_mag", -26.74, min=-30.0, max=-20.0),
    )
    band = me.str("band", None)
    if band is not None:  # the Sun's magnitude of that band (lightcurve.photometry.bands)
        from ..photometry.bands import sun_magnitude

        if me.has("sun_mag"):
            raise InputError("give measurement.band or measurement.sun_mag, not both", file=file,
                             field="measurement.band", value=band)
        meas.sun_mag = sun_magnitude(band, file=file, field="measurement.band")
        meas.band = band
    me.check_unknown()

    rec = root.section("recording", None)
    if rec is not None:
        from ..io.recording import recording_spec_from_section

        rec = recording_spec_from_section(rec)

    effects = root.raw("effects", {})
    if not isinstance(effects, dict):
        raise InputError("expected a table", file=file, field="effects", value=effects)
    if effects:
        # validated here (InputError names effects.<name>.<param>); lightcurve.physics
        # re-parses the same table when simulating (studies.simulate)
        from ..physics.registry import parse_effects

        parse_effects(effects, file=file, site_names=[s.site.id for s in sites],
                      embedded=embedded)
        if meas.ignore_eclipse and "penumbra" in effects and effects["penumbra"].get("enabled", True):
            raise InputError("the penumbra effect contradicts measurement.ignore_eclipse = true",
                             file=file, field="effects.penumbra")
    flt = root.section("filter", None)
    if flt is not None:   # [filter] variant: the default of invert (lightcurve.filters.invert)
        flt.str("variant", "robust", choices=("robust", "thesis"))
        flt.check_unknown()
    refl = root.section("reflection", None)
    if refl is not None:
        kinds = refl.raw("params", ["xi", "a", "m", "A"])
        if (not isinstance(kinds, list) or not kinds
                or any(k not in ("xi", "a", "m", "A") for k in kinds) or len(set(kinds)) != len(kinds)):
            raise InputError("expected a non-empty list of distinct reflection parameters",
                             file=file, field="reflection.params", value=kinds,
                             allowed='"xi", "a", "m", "A"')
        refl_spec = ReflectionSpec(perturb=refl.bool("perturb", True),
                                   sigma_frac=refl.float("sigma_frac", 0.1, min=0.0, max=1.0),
                                   params=tuple(kinds))
        refl.check_unknown()
        refl = refl_spec
    root.check_unknown()
    return Scenario(epoch_utc=epoch, duration_s=duration, cadence_s=cadence, seed=seed, orbit=orbit,
                    shape=shape, attitude=att, sites=sites, measurement=meas, effects=effects,
                    recording=rec, name=name, source=str(file), text=text or "", reflection=refl)


def scenario_from_lightcurve(curve, file=None, *, drop=(), library_dirs=None, site_dirs=None,
                             scenario=None, shape=None) -> Scenario:
    """The validated scenario of a lightcurve file, resolved from what the file carries.

    ``scenario``: a scenario TOML path given by the user (it overrides the file's own
    scenario text); otherwise the scenario text stored in the file (root attribute
    ``scenario``). Either way ``shape`` (a resolved Shape from the caller) or else the shape
    the file carries (:attr:`Lightcurve.shape`) replaces the scenario's ``[shape]`` when present, and the file's sites (ids and WGS84 coordinates)
    answer the scenario's ``[[sites]] name = "<id>"`` references before ``site_dirs`` and the
    catalogue — so a received file needs neither the shape library nor the site folder it was
    made with. ``drop``: top-level tables removed before validation (e.g. ``("effects",
    "diagnosis")``).

    Raises
    ------
    InputError
        No scenario (neither given nor stored), or an invalid one (naming the file).
    """
    from ..geometry.sites import Site

    src = str(file) if file is not None else "<lightcurve>"
    if scenario is not None:
        path = Path(scenario)
        doc, text = load_toml(path, with_text=True)   # read once (regular file, size cap)
        fname = path
        embedded = False
    else:
        text = getattr(curve, "scenario_toml", "") or ""
        if not text.strip():
            raise InputError("the file has no embedded scenario: give --scenario MODEL.toml",
                             file=src, field="scenario")
        fname = f"{src}:scenario"
        doc = loads_toml(text, file=fname)
        embedded = True      # from inside a data file: library shapes only, no file paths
    for key in drop:
        doc.pop(key, None)
    lla = np.asarray(curve.site_lla_deg_m, float).reshape(-1, 3)
    known = {}
    for sid, (lat, lon, h) in zip(curve.site_names, lla):
        try:
            known[sid] = Site(sid, sid, float(lat), float(lon), float(h), source=f"{src}")
        except InputError:
            continue
    return parse_scenario(doc, file=fname, text=text, library_dirs=library_dirs,
                          site_dirs=site_dirs, sites=known, embedded=embedded,
                          shape=shape if shape is not None else getattr(curve, "shape", None))


#: ``--scenario`` short names of the bundled pipelines (``lightcurve demo --scenario thesis``)
SCENARIO_ALIASES = {
    "default": "default.toml",
    "thesis": "thesis/leo-ic1-fast-spin-controlled-1site.toml",
    "thesis-2site": "thesis/leo-ic1-fast-spin-controlled-2site.toml",
}


def resolve_scenario(spec) -> Path:
    """A scenario path from a user's spec (``--scenario``, :func:`lightcurve.simulate`): a file,
    an alias (:data:`SCENARIO_ALIASES`) or a bundled pipeline name relative to ``pipelines/``
    (``thesis/geo-ic1-…``, ``.toml`` optional)."""
    p = Path(spec)
    if p.is_file():
        return p
    base = data_dir("pipelines")
    name = SCENARIO_ALIASES.get(str(spec), str(spec))
    for cand in (base / name, base / f"{name}.toml"):
        if cand.is_file() and base.resolve() in cand.resolve().parents:
            return cand
    if str(spec).endswith(".toml") or p.parent != Path("."):
        return p  # a path: the loader names the missing file
    raise InputError("scenario not found", field="--scenario", value=str(spec),
                     allowed="a TOML file, " + ", ".join(SCENARIO_ALIASES)
                     + ", or a name under the bundled pipelines/ (e.g. thesis/geo-ic1-fast-spin-controlled-1site)")
