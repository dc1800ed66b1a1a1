"""The package's own proof scenarios in ``pipelines/diagnosis/`` (used by the CLI test and the
physics observability tests; the concealed-effect proofs use the independent generator of
concealed.py). Where each effect is physically observable:

* ``diag-leo-lit-2site``: lit two-site LEO pass, elevations 5–73°: extinction, zero_point,
  unmodelled_facet, specular_glint, and the no-effect case. (Earthshine is NOT observable
  there: seen from a dark site, the LEO object sees almost no sunlit Earth, Δm < 1e-5 mag;
  the case ``earthshine@lit`` keeps that negative result runnable.)
* ``diag-meo-dusk-2site``: a box-wing at 12,000 km seen after dusk at solar phase 155° → 70°:
  its observer-facing side faces a gibbous sunlit Earth and is barely sunlit: earthshine
  (truth on a 5° grid of the built-in albedo map; the diagnosis model uses its default 10°
  grid — the two differ by < 0.005 mag here), and the no-effect case ``none@meo``;
* ``diag-leo-lit-2site-mesh``: the lit LEO pass with the box-wing as a mesh: self_shadowing
  (truth ray-cast with 96×96 samples per triangle, the diagnosis model with 48×48 —
  the effect has no fitted parameter, so seeds differ by noise and ACS jitter only), and the
  no-effect case ``none@mesh``;
* ``diag-leo-shadow-2site``: the pass ends with the object entering the Earth's shadow:
  penumbra;
* ``diag-geo-fast-1site``: a fast-tumbling GEO box-wing (light time 0.12 s, flashes of
  several mag/s): light_time, clock_offset, exposure_smearing.

"""

from __future__ import annotations

from lightcurve._paths import data_dir

SCEN = {
    "lit": "diag-leo-lit-2site.toml",
    "shadow": "diag-leo-shadow-2site.toml",
    "geo": "diag-geo-fast-1site.toml",
    "meo": "diag-meo-dusk-2site.toml",
    "mesh": "diag-leo-lit-2site-mesh.toml",
}
def scenario(key):
    from lightcurve.studies.scenario import load_scenario

    if key not in _CACHE:
        _CACHE[key] = load_scenario(data_dir("pipelines") / "diagnosis" / SCEN[key])
    return _CACHE[key]


_CACHE: dict = {}
