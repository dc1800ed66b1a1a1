"""Which facets are lit by the Sun and seen by the observer along an attitude history.

A facet i contributes to the magnitude (DESIGN.md magnitude equation) only at epochs where
``n̂_i·ŝ > 0`` (lit) AND ``n̂_i·ô > 0`` (visible), with ŝ (object→Sun) and ô (object→observer)
unit vectors in body axes, ``v_b = A(q) v_I`` (Bernard eq. 3.16). A facet that is never both
lit and visible contributes nothing to any measurement, so none of its reflection parameters
(ξ, a = F0, m, A) can be learned from the lightcurve: that is the geometry behind the
observability statements of Bernard §10.7. Self-shadowing is not considered (the
convex-shape assumption of the magnitude model).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..rotations import quat_rotate
from .shapes_io import load_shape

__all__ = ["facet_lit_visible", "facet_exposure_fractions"]


def facet_lit_visible(normals_body, q, s_eci_unit, o_eci_unit):
    """Per-epoch, per-facet lit and visible flags.

    Parameters
    ----------
    normals_body : (F, 3) unit outward facet normals, body axes.
    q : (N, 4) quaternions, scalar first, inertial→body passive.
    s_eci_unit, o_eci_unit : (N, 3) unit object→Sun and object→observer vectors, ECI (GCRS).

    Returns
    -------
    lit, visible : (N, F) bool arrays (``n̂·ŝ > 0`` and ``n̂·ô > 0``).
    """
    n = np.asarray(normals_body, float)
    s_b = quat_rotate(np.asarray(q, float), np.asarray(s_eci_unit, float))
    o_b = quat_rotate(np.asarray(q, float), np.asarray(o_eci_unit, float))
    return s_b @ n.T > 0.0, o_b @ n.T > 0.0


def facet_exposure_fractions(curve, shape=None) -> dict:
    """Fractions of the lightcurve's epochs at which each facet is lit / visible / both.

    ``curve`` is a :class:`lightcurve.io.lightcurve_h5.Lightcurve` with a truth attitude
    (``truth/q``); ``shape`` defaults to the library shape named in ``curve.attrs["shape"]``.
    Returns plain lists (facet order of the shape): ``lit``, ``visible``, ``lit_and_visible``
    over all epochs, and ``lit_and_visible_by_site`` {site name: list}.
    """
    if curve.truth_q is None:
        raise InputError("facet exposure needs the truth attitude of a simulated lightcurve",
                         field="truth/q")
    if shape is None:
        shape = load_shape(curve.attrs["shape"])
    lit, vis = facet_lit_visible(shape.normals_body, curve.truth_q, curve.obj_to_sun_unit,
                                 curve.obj_to_obs_unit)
    both = lit & vis
    by_site = {}
    for i, name in enumerate(str(x) for x in curve.site_names):
        sel = np.asarray(curve.site) == i
        if sel.any():
            by_site[name] = [round(float(x), 4) for x in both[sel].mean(axis=0)]
    return {"lit": [round(float(x), 4) for x in lit.mean(axis=0)],
            "visible": [round(float(x), 4) for x in vis.mean(axis=0)],
            "lit_and_visible": [round(float(x), 4) for x in both.mean(axis=0)],
            "lit_and_visible_by_site": by_site}
