"""Concealed-effect cases: a recording from the independent generator (:mod:`concealed`) with
one registry effect switched on at random realistic parameters, diagnosed against the
package's model without it (the scenario's geometry, attitude and Table 9.2 shape).

Scenario per effect (chosen where the effect is observable; all analytic, see
:mod:`concealed`):

* ``lit2`` — LEO 700 km, two sites, a lit pass from 10° to 86° elevation (air mass 1–5.6),
  phase 29–108°, 5 s cadence, slow tumble: none, extinction, zero_point;
* ``spin`` — a GEO object spinning at 2°/s about a fixed axis, one site, 0.75 s cadence over
  9 minutes (three turns): the geometry repeats every turn, so a glint or an extra facet
  shows up three times: specular_glint, unmodelled_facet;
* ``fast`` — a GEO object tumbling at ~38°/s (flashes of several mag/s, light time 0.12 s),
  1 s cadence: light_time, clock_offset;
* ``smear`` — the same at ~4°/s, so that a 1–10 s exposure averages 4–40° of rotation (at
  38°/s it would average whole turns): exposure_smearing;
* ``shadow`` — LEO, two sites, the object crosses the Earth's shadow boundary during the pass,
  1 s cadence: penumbra;
* ``earthshine`` — LEO over sunlit ground at high solar phase (the observer sees the faces lit
  by the Earth): earthshine;
* ``mesh`` — ``lit2`` with a non-convex body (a 1 m box and a 5 m × 1 m panel beside it, as a
  mesh): self_shadowing;
* ``css`` — the offset dual pyramid of coarse sun sensors on a 500 km orbit, one orbit every
  30 s, the body turning at 0.47°/s about an oblique axis relative to the local-vertical frame
  (so the Sun crosses every sensor's field — each sees it 12–21 % of the time — along
  different paths, and misalignments are identifiable in azimuth and elevation): css_albedo,
  css_misalignment, css_scale_factor, css_fault.

Parameters are drawn from the ranges the diagnosis assumes for realistic values (the
registry's priors, written out here), with two stated conditionings: a glint or extra facet
normal is the body-frame Sun–observer bisector at a random epoch turned by up to 5° (a random
orientation may never face both Sun and observer — nothing would be concealed), and the
glint's Phong exponent is drawn from [20, 100] (narrower lobes last less than the cadence:
the flash would be unresolved, i.e. unidentifiable — the case of
``test_unresolved_glint_is_unidentifiable``).
"""

from __future__ import annotations

import functools
import tempfile
from pathlib import Path

import numpy as np

import concealed as G

MAG_CASES = {"none": "lit2", "extinction": "lit2", "zero_point": "lit2",
             "specular_glint": "spin", "unmodelled_facet": "spin", "light_time": "fast",
             "clock_offset": "fast", "exposure_smearing": "smear", "penumbra": "shadow",
             "earthshine": "earthshine", "self_shadowing": "mesh"}
CSS_CASES = {"css_albedo": "css", "css_misalignment": "css", "css_scale_factor": "css",
             "css_fault": "css", "none@css": "css"}
CASES = {**MAG_CASES, **CSS_CASES}

_Q0 = (0.8, 0.2, -0.3, 0.4)
SITE_NAMES = ["s0", "s1"]


def scenario(key):
    """(Geometry, shape (Facets or Boxes), label times t (s))."""
    d2 = np.radians
    if key in ("lit2", "mesh"):
        geo = G.Geometry(G.R_E + 700e3, 60.0, 0.0, 30.0, [(28.0, 10.0), (33.0, 22.0)], (0, -1, 0),
                         _Q0, d2([0.2, 0.1, 0.36]))
        shape = G.cube() if key == "lit2" else mesh_boxes()
        return geo, shape, np.arange(-400.0, 400.0, 5.0)
    if key == "shadow":
        geo = G.Geometry(G.R_E + 700e3, 60.0, 0.0, 30.0, [(28.0, 10.0), (33.0, 22.0)], (0, 0, -1),
                         _Q0, d2([0.2, 0.1, 0.36]))
        return geo, G.cube(), _shadow_window(geo)
    if key == "earthshine":
        geo = G.Geometry(G.R_E + 700e3, 60.0, 0.0, 30.0, [(28.0, 10.0), (33.0, 22.0)], (0.3, 1, -0.3),
                         _Q0, d2([0.2, 0.1, 0.36]))
        return geo, G.cube(), np.arange(-400.0, 400.0, 5.0)
    if key == "spin":
        geo = G.Geometry(42164e3, 0.1, 0.0, 0.0, [(33.0, 0.0)], (-0.8, -1.0, 0.3), _Q0,
                         d2(2.0) * G.unit(np.array([0.3, -0.5, 0.8])))
        return geo, G.cube(), np.arange(0.0, 540.0, 0.75)
    if key in ("fast", "smear"):
        w = [18.0, 9.0, 32.4] if key == "fast" else [1.9, 0.95, 3.4]
        geo = G.Geometry(42164e3, 0.1, 0.0, 0.0, [(33.0, 0.0)], (-0.8, -1.0, 0.3), _Q0, d2(w))
        return geo, G.cube(), np.arange(0.0, 300.0, 1.0)
    if key == "css":
        geo = G.Geometry(G.R_E + 500e3, 51.6, 30.0, 0.0, [], (0.2, 0.9, 0.3), (1, 0, 0, 0),
                         d2([0.3, 0.2, 0.3]))
        geo.lvlh = True
        return geo, None, np.arange(0.0, 5700.0, 30.0)
    raise KeyError(key)


def _shadow_window(geo):
    """1 s epochs from 250 s before to 30 s after the shadow entry seen from the sites."""
    t = np.arange(-600.0, 600.0, 1.0)
    r, _ = geo.obj(t)
    lit = G.lit_fraction(r, geo.sun[None])
    i = int(np.argmax(lit < 1.0))
    return t[max(i - 250, 0):i + 30]


def mesh_boxes():
    """A 1 m box and a 5 m × 1 m × 5 cm panel beside it along +Y (not touching)."""
    return G.Boxes([((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)), ((-0.5, 0.7, -0.025), (0.5, 5.7, 0.025))])


# ------------------------------------------------------------------------------------------
# random realistic parameters (the registry's priors, written out)
# ------------------------------------------------------------------------------------------
def _signed(rng, lo, hi):
    return float(rng.uniform(lo, hi) * (1 if rng.random() < 0.5 else -1))


def draw(effect, rng, geo, shape, t):
    """(effects per site (list of dicts), truth dict for reports)."""
    n = len(geo.sites)
    if effect == "none":
        return [{} for _ in range(n)], {}
    if effect == "extinction":
        k = rng.uniform(0.1, 0.4, n)
        return [{effect: {"k_mag_per_airmass": float(k[i])}} for i in range(n)], {"k": k.tolist()}
    if effect == "zero_point":
        z = [_signed(rng, 0.1, 0.4) for _ in range(n)]
        return [{effect: {"offset_mag": z[i]}} for i in range(n)], {"offset_mag": z}
    if effect == "clock_offset":
        d = [_signed(rng, 0.2, 2.0) for _ in range(n)]
        return [{effect: {"dt_s": d[i]}} for i in range(n)], {"dt_s": d}
    if effect == "exposure_smearing":
        T = rng.uniform(1.0, 10.0, n)
        return [{effect: {"exposure_s": float(T[i])}} for i in range(n)], {"exposure_s": T.tolist()}
    if effect == "light_time":
        return [{effect: {}} for _ in range(n)], {}
    if effect == "self_shadowing":
        return [{effect: {}} for _ in range(n)], {}
    if effect == "penumbra":
        h = float(rng.uniform(0.0, 50e3))
        return [{effect: {"shadow_height_m": h}} for _ in range(n)], {"shadow_height_m": h}
    if effect == "earthshine":
        s = float(rng.uniform(0.7, 1.3))
        return [{effect: {"albedo_scale": s}} for _ in range(n)], {"albedo_scale": s}
    if effect in ("specular_glint", "unmodelled_facet"):
        az, el = _bisector(geo, rng, t)
        p = {"az_deg": az, "el_deg": el,
             "area_m2": float(np.exp(rng.uniform(np.log(0.05), np.log(2.0)))) if effect == "specular_glint"
             else float(np.exp(rng.uniform(np.log(0.1), np.log(3.0))))}
        if effect == "specular_glint":
            p["exponent"] = float(np.exp(rng.uniform(np.log(20.0), np.log(100.0))))
        return [{effect: p} for _ in range(n)], p
    raise KeyError(effect)


def _bisector(geo, rng, t):
    k = float(t[int(rng.integers(t.size))])
    r, _ = geo.obj(np.array([k]))
    h = G.unit(G.unit(geo.sun[None] - r) + G.unit(geo.site(0, np.array([k])) - r))
    hb = G.to_body(geo.q(np.array([k])), h)[0]
    a = rng.normal(size=3)
    a -= a.dot(hb) * hb
    a /= np.linalg.norm(a)
    ang = np.radians(rng.uniform(0.0, 5.0))
    nrm = hb * np.cos(ang) + np.cross(a, hb) * np.sin(ang)
    return float(np.degrees(np.arctan2(nrm[1], nrm[0]))), float(np.degrees(np.arcsin(np.clip(nrm[2], -1, 1))))


def draw_css(effect, rng, t):
    if effect in ("none", "none@css"):
        return {}, {}
    if effect == "css_albedo":
        s = float(rng.uniform(0.7, 1.3))
        return {effect: {"albedo_scale": s}}, {"albedo_scale": s}
    if effect == "css_misalignment":
        p = {"d_az_deg": rng.normal(0.0, 2.0, 8), "d_el_deg": rng.normal(0.0, 2.0, 8)}
        return {effect: p}, {k: v.tolist() for k, v in p.items()}
    if effect == "css_scale_factor":
        p = {"common": float(rng.uniform(0.85, 1.05)), "individual": rng.normal(1.0, 0.05, 8)}
        return {effect: p}, {"common": p["common"], "individual": p["individual"].tolist()}
    if effect == "css_fault":
        p = {"sensor": int(rng.integers(8)), "gain": float(rng.uniform(0.0, 0.5)),
             "t_start_s": float(np.quantile(t, rng.uniform(0.0, 0.8)))}
        return {effect: p}, p
    raise KeyError(effect)


# ------------------------------------------------------------------------------------------
# the package's model of a generated recording
# ------------------------------------------------------------------------------------------
_DIR = {}


def _shape_dir():
    if "d" not in _DIR:
        _DIR["d"] = Path(tempfile.mkdtemp(prefix="concealed-shapes-"))
        _write_shapes(_DIR["d"])
    return _DIR["d"]


def _materials_toml():
    out = []
    for key, (xi, a, m) in G.TABLE_9_2.items():
        nm = ("p" if key[0] == "+" else "m") + key[1].lower()
        out.append(f'[materials.{nm}]\nbrdf = "cook_torrance"\nxi = {xi}\na = {a}\nm = {m}\n')
    return "\n".join(out)


def _write_shapes(d):
    mats = _materials_toml()
    facets = []
    for key, ax in G.AXES.items():
        nm = ("p" if key[0] == "+" else "m") + key[1].lower()
        facets.append(f"[[facets]]\nnormal = {list(map(float, ax))}\narea_m2 = 1.0\n"
                      f"center_m = {[0.5 * x for x in ax]}\nmaterial = \"{nm}\"\n")
    (d / "cube92.toml").write_text(
        '[shape]\nname = "cube92"\ndescription = "1 m cube, Bernard Table 9.2 materials"\n'
        "mass_kg = 100.0\ninertia_diag_kg_m2 = [16.7, 16.7, 16.7]\n\n" + mats + "\n" + "\n".join(facets))
    boxes = mesh_boxes()
    (d / "boxpanel.obj").write_text(boxes.obj_text())
    mm = []
    for key, ax in G.AXES.items():
        nm = ("p" if key[0] == "+" else "m") + key[1].lower()
        mm.append(f'[[material_map]]\nmaterial = "{nm}"\nnormal = {list(map(float, ax))}\n')
    (d / "boxpanel.toml").write_text(
        '[shape]\nname = "boxpanel"\ndescription = "box + panel mesh, Table 9.2 materials"\n'
        'mesh = "boxpanel.obj"\nmerge_coplanar = true\nmass_kg = 100.0\n'
        "inertia_diag_kg_m2 = [30.0, 10.0, 30.0]\n\n" + mats + "\n" + "\n".join(mm))


@functools.lru_cache(maxsize=None)
def model_shape(kind):
    from lightcurve.photometry import load_shape

    return load_shape(_shape_dir() / ("boxpanel.toml" if kind == "mesh" else "cube92.toml"))


def magnitude_problem(rec, key, label):
    """The package's diagnosis Problem: the recording against the model without effects."""
    from lightcurve.diagnosis.problem import Problem, _shadow_margin
    from lightcurve.physics import ModelContext

    names = SITE_NAMES[: int(rec["site"].max()) + 1]
    ctx = ModelContext(epoch_utc=G.EPOCH, t=rec["t"], site_index=rec["site"], site_names=names,
                       shape=model_shape(key), q=rec["q"], omega=rec["omega"],
                       r_obj_eci_m=rec["r_obj"], v_obj_eci_m_s=rec["v_obj"],
                       r_site_eci_m=rec["r_site"], r_sun_eci_m=rec["r_sun"],
                       elevation_rad=rec["el"], sun_mag=G.SUN_MAG)
    m0 = ctx.evaluate()
    keep = np.isfinite(m0) & np.isfinite(rec["mag"])
    n = rec["t"].size
    prob = Problem("magnitude", ctx, rec["mag"], rec["sigma"], rec["t"], rec["site"], np.arange(n),
                   names, [], elevation_rad=rec["el"],
                   shadow_margin=_shadow_margin(rec["r_obj"], rec["r_sun"]), label=label)
    return prob if keep.all() else prob.subset(keep)


def css_model_problem(geo, t, y, sigma, label):
    from lightcurve.css.sensors import CSSArray
    from lightcurve.diagnosis.problem import css_problem
    from lightcurve.physics import CSSContext

    arr = CSSArray(G.css_normals(), np.full(8, np.radians(G.FOV_HALF_DEG)), name="dual pyramid")
    r, _ = geo.obj(t)
    sun = G.unit(geo.sun[None] - r)
    lit = (G.lit_fraction(r, geo.sun[None]) > 0).astype(float)
    ctx = CSSContext(arr, t, G.EPOCH, geo.q(t), r, sun, lit)
    return css_problem(ctx, y, sigma, label=label)


CSS_SIGMA = 0.005


def generate(case, seed):
    """(problem, truth) of a concealed-effect case."""
    effect = case.split("@", 1)[0]
    key = CASES[case]
    rng = np.random.default_rng(10_000 + seed)
    geo, shape, t = scenario(key)
    if key == "css":
        eff, truth = draw_css(effect, rng, t)
        y = G.css_outputs(geo, t, eff) + rng.normal(0.0, CSS_SIGMA, (t.size, 8))
        return css_model_problem(geo, t, y, CSS_SIGMA, f"{case}-{seed}"), truth
    per_site, truth = draw(effect, rng, geo, shape, t)
    rec = G.record(geo, shape, t, per_site, rng)
    return magnitude_problem(rec, key, f"{case}-{seed}"), truth


def run_case(case, seed, **kw):
    """Generate and diagnose; a summary dict (the json, the verdict, the first named effect)."""
    import warnings

    from lightcurve.diagnosis.diagnose import diagnose

    prob, truth = generate(case, seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(prob, **kw)
    js = d.summary()
    ho = (js["cross_validation"].get("schemes") or [{}])[0]
    dof_n = max(prob.n, 1)
    final_held = ho.get("final", {}).get("chi2_per_n") if ho.get("possible") else None
    named_unidentified = [n for n in js["chosen"]
                          for c in js["candidates"] if c["name"] == n
                          for s in c["steps"] if str(s.get("decision", "")).startswith("added") and not s["identified"]]
    return {"case": case, "seed": seed, "n": dof_n, "verdict": js["verdict"],
            "first": js["chosen"][0] if js["chosen"] else None, "chosen": js["chosen"],
            "baseline_chi2_dof": js["baseline"]["chi2_dof"], "final_chi2_dof": js["final"]["chi2_dof"],
            "held_out_chi2_per_n": final_held, "unidentified": [u["name"] for u in js["unidentified"]],
            "named_unidentified": named_unidentified, "truth": truth, "json": js,
            "wall_s": js["timings_s"].get("total_s")}


def single_flash_case(seed, exponent=300.0):
    """A glint seen in one flash only: the lit two-site LEO pass with its slow tumble (the
    body turns once in ~14 min, the pass lasts 13 min), a narrow lobe (``exponent``) whose
    normal bisects Sun and observer at one epoch. Returns (problem, truth)."""
    rng = np.random.default_rng(20_000 + seed)
    geo, shape, t = scenario("lit2")
    az, el = _bisector(geo, rng, t[40:120])
    p = {"az_deg": az, "el_deg": el, "area_m2": 0.5, "exponent": float(exponent)}
    rec = G.record(geo, shape, t, [{"specular_glint": p} for _ in geo.sites], rng)
    return magnitude_problem(rec, "lit2", f"single-flash-{seed}"), p
