"""The one Cook–Torrance (lightcurve.core.photometry) against the DESIGN.md / Bernard 2021
eq. 5.7–5.15 form written here in plain NumPy, its derivatives against finite differences,
and the magnitude partials against differences of the magnitude kernel."""

import numpy as np
import pytest

from lightcurve.core import photometry as PH
from lightcurve.core import rotations as R

RNG = np.random.default_rng(8)


def _unit(v):
    return v / np.linalg.norm(v)


def _ct_reference(n, s, o, xi, a, m, thesis=False):
    """(n̂·ŝ)(n̂·ô) f_r, Cook–Torrance of DESIGN.md (standard Fresnel; eq. 5.8's extra n̂·ŝ only
    in the thesis form)."""
    ns, no = n @ s, n @ o
    h = _unit(s + o)
    c = o @ h
    nr = (1 + np.sqrt(a)) / (1 - np.sqrt(a))
    g = np.sqrt(nr ** 2 + c ** 2 - 1)
    F = 0.5 * (g - c) ** 2 / (g + c) ** 2 * (1 + (c * (g + c) - 1) ** 2 / (c * (g - c) + 1) ** 2)
    cg = n @ h
    D = np.exp(-((1 - cg ** 2) / cg ** 2) / m ** 2) / (np.pi * m ** 2 * cg ** 4)
    G = min(1.0, 2 * cg * no / c, 2 * cg * ns / c)
    fd = xi * a / np.pi * (ns if thesis else 1.0)
    return ns * no * (fd + (1 - xi) * F * D * G / (4 * ns * no))


@pytest.mark.parametrize("thesis", [False, True])
def test_cook_torrance_product_matches_reference(thesis):
    mid = PH.COOK_TORRANCE_THESIS if thesis else PH.COOK_TORRANCE
    for _ in range(50):
        n = _unit(RNG.normal(size=3))
        s = _unit(n + 0.8 * RNG.normal(size=3))
        o = _unit(n + 0.8 * RNG.normal(size=3))
        if n @ s <= 0.05 or n @ o <= 0.05:
            continue
        p = np.zeros(7)
        p[:3] = RNG.uniform(0.05, 0.95), RNG.uniform(0.05, 0.9), RNG.uniform(0.05, 1.0)
        got = PH.brdf_product_nb(mid, p, *n, *s, *o)
        assert np.isclose(got, _ct_reference(n, s, o, *p[:3], thesis=thesis), rtol=1e-12)
    # the thesis form differs exactly by the extra n̂·ŝ on the diffuse term
    n, s, o = np.array([0, 0, 1.0]), _unit(np.array([0.3, 0, 1.0])), _unit(np.array([0, 0.4, 1.0]))
    p = np.array([1.0, 0.5, 0.3, 0, 0, 0, 0])                   # ξ = 1: diffuse only
    assert np.isclose(PH.brdf_product_nb(4, p, *n, *s, *o), (n @ s) * PH.brdf_product_nb(1, p, *n, *s, *o))


def test_cook_torrance_scalar_derivatives_by_finite_differences():
    import numba

    @numba.njit
    def ct(x, thesis):
        return np.array(PH.cook_torrance_xyz(x[0], x[1], x[2], x[3], x[4], x[5], x[6], thesis))

    h = 1e-7
    for thesis in (False, True):
        for _ in range(20):
            x = np.array([RNG.uniform(0.2, 0.9), RNG.uniform(0.2, 0.9), RNG.uniform(0.7, 0.99),
                          RNG.uniform(0.5, 0.95), RNG.uniform(0.1, 0.9), RNG.uniform(0.1, 0.8),
                          RNG.uniform(0.1, 0.9)])
            full = ct(x, thesis)
            for j in range(7):
                e = np.zeros(7)
                e[j] = h
                fd = (ct(x + e, thesis)[0] - ct(x - e, thesis)[0]) / (2 * h)
                # G's min() kinks: skip samples where a branch switches inside ±h
                if abs(ct(x + e, thesis)[0] - 2 * full[0] + ct(x - e, thesis)[0]) > 1e-9:
                    continue
                assert np.isclose(full[1 + j], fd, rtol=1e-5, atol=1e-8), (thesis, j)


def _shape():
    normals = np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0.6, 0.8, 0]])
    areas = np.array([1.0, 2.0, 1.5, 0.5, 0.8])
    ids = np.array([1, 0, 2, 4, 1])
    prm = np.zeros((5, 7))
    prm[0, :3] = 0.3, 0.6, 0.2
    prm[1, 0] = 0.4
    prm[2, :3] = 0.2, 0.5, 12.0
    prm[3, :3] = 0.5, 0.4, 0.35
    prm[4, :3] = 0.1, 0.8, 0.15
    return normals, areas, ids, prm


def test_magnitude_attitude_partials_by_finite_differences():
    normals, areas, ids, prm = _shape()
    s = _unit(np.array([0.4, 0.5, 0.7]))
    o = _unit(np.array([0.6, 0.2, 0.75]))
    h = 1e-6
    checked = 0
    for _ in range(30):
        q = _unit(RNG.normal(size=4))
        work = [np.empty(5) for _ in range(4)]
        m, *d = PH.magnitude_partials_q_nb(q, s, o, normals, areas, ids, prm, 1.0, *work)
        if not np.isfinite(m):
            continue
        dq = np.array([R.rotvec2q_nb(h * e) for e in np.eye(3)] + [R.rotvec2q_nb(-h * e) for e in np.eye(3)])
        Q = np.array([R.qmul_nb(d_, q) for d_ in dq])
        mm = PH.mag_kernel_nb(Q, s, o, normals, areas, ids, prm, 1.0)
        fd = (mm[:3] - mm[3:]) / (2 * h)
        if not np.all(np.isfinite(fd)) or np.max(np.abs(fd)) > 1e3:
            continue
        np.testing.assert_allclose(d, fd, rtol=2e-4, atol=2e-6)
        assert np.isclose(m, PH.mag_kernel_nb(q[None], s, o, normals, areas, ids, prm, 1.0)[0])
        checked += 1
    assert checked >= 5


def test_thesis_cook_torrance_is_registered_with_analytic_partials():
    """``cook_torrance_bernard`` (Bernard eq. 5.8 as printed) is a registered BRDF on kernel id 4;
    its diffuse value is the physical one times n̂·ŝ, and the magnitude partials of a shape made
    of it are analytic (no finite-difference fallback)."""
    from lightcurve.photometry import Material, get_brdf
    from lightcurve.photometry.partials import kernel_capable

    b = get_brdf("cook_torrance_bernard")
    assert b.kernel_id == PH.COOK_TORRANCE_THESIS and b.param_names == ("xi", "a", "m")
    n, s, o = np.array([0, 0, 1.0]), _unit(np.array([0.6, 0, 0.8])), _unit(np.array([0, 0.3, 1.0]))
    prm = {"xi": 1.0, "a": 0.4, "m": 0.3}
    phys = get_brdf("cook_torrance").evaluate(n, s, o, prm)
    assert np.isclose(b.evaluate(n, s, o, prm), phys * (n @ s), rtol=1e-14)
    assert Material.create("t", "cook_torrance_bernard", **prm).brdf is b
    assert kernel_capable([PH.COOK_TORRANCE_THESIS, PH.LAMBERT])
