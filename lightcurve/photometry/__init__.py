"""Photometry: faceted shapes, the BRDF registry, apparent magnitudes, noise and partials.

Conventions (DESIGN.md): SI units; body-frame facet geometry; quaternions scalar first,
inertial→body (``v_b = A(q) v_I``); ŝ object→Sun, ô object→observer; BRDFs in sr⁻¹.

Public API::

    load_shape(spec, library_dirs=None) -> Shape      # library name, TOML path, (mesh, toml)
    list_shapes(library_dirs=None) -> list[str]
    validate_shape(shape_or_path) -> list[str]
    apparent_magnitude(shape, q, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m, sun_mag=-26.74)
    magnitude_partials(...) -> MagnitudePartials       # ∂m/∂A, ∂m/∂ξ, ∂m/∂a, ∂m/∂m, ∂m/∂δθ
    magnitude_sigma(m, r_percent), add_noise(m, r_percent, rng)
    register_brdf(name), get_brdf(name), available_brdfs()
    brightness_kernel(normals, areas, model_ids, params, s_body, o_body)   # numba
"""

from .brdf import BRDF, available_brdfs, get_brdf, register_brdf, unregister_brdf
from .brdf_models import AshikhminShirley, CookTorrance, CookTorranceBernard, Lambert, Phong
from .facets import Shape
from ..core.photometry import brightness_kernel
from .magnitude import AU_M, SUN_MAG_V, apparent_magnitude, body_directions, flux_factor, magnitude_from_flux
from .materials import Material
from .noise import add_noise, magnitude_sigma
from .partials import MagnitudePartials, magnitude_partials
from .shapes_io import list_shapes, load_shape, shape_library, validate_shape
from .tabulated import TabulatedBRDF

__all__ = [
    "BRDF", "available_brdfs", "get_brdf", "register_brdf", "unregister_brdf",
    "Lambert", "CookTorrance", "CookTorranceBernard", "Phong", "AshikhminShirley", "TabulatedBRDF",
    "Shape", "Material", "brightness_kernel",
    "AU_M", "SUN_MAG_V", "apparent_magnitude", "body_directions", "flux_factor",
    "magnitude_from_flux", "add_noise", "magnitude_sigma", "MagnitudePartials",
    "magnitude_partials", "list_shapes", "load_shape", "shape_library", "validate_shape",
]
