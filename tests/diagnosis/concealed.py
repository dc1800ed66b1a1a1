"""Independent concealed-effect generator for the diagnosis proofs (plain NumPy).

Nothing here imports the package: geometry, attitude, Cook–Torrance photometry, every physics
effect of the registry and the coarse-sun-sensor model are written out again from their
sources, so a recording made here tests the package's forward models *and* its search. The
package is only used afterwards, by :mod:`concealed_cases`, to build the model the diagnosis
checks the recording against (the scenario without the effect).

Sources of every formula and number:

* Quaternions scalar first, inertial→body passive: A(q) = (q1² − |q_v|²) I + 2 q_v q_vᵀ
  − 2 q1 [q_v×] (Bernard 2021 eq. 3.16); composition q ⊗ p (eq. 3.20,
  ``s = q1 p1 − q_v·p_v``, ``v = q1 p_v + p1 q_v − q_v × p_v``); constant body rate:
  q(t) = [cos(|ω|t/2), sin(|ω|t/2) ω̂] ⊗ q0 (eq. 4.12 integrated).
* Magnitude (DESIGN.md, Bernard eq. 5.2–5.6 in consistent form, Sun at −26.74 mag at 1 au):
  m = −26.74 − 2.5 log10( Σ_i A_i (n̂·ŝ)(n̂·ô) f_r,i / |r_obs|² · (1 au/|r_sun|)² ).
* Cook–Torrance (DESIGN.md): f_r = ξa/π + (1−ξ) F D G / (4 (n̂·ŝ)(n̂·ô)); Beckmann
  D = exp(−tan²α/m²)/(π m² cos⁴α); G = min(1, 2(n̂·ĥ)(n̂·ô)/(ô·ĥ), 2(n̂·ĥ)(n̂·ŝ)/(ô·ĥ));
  F = ½ (g−c)²/(g+c)² [1 + (c(g+c)−1)²/(c(g−c)+1)²], c = ô·ĥ, g² = n² + c² − 1,
  n = (1+√F0)/(1−√F0), F0 = a.
* Materials: Bernard 2021 Table 9.2 (ξ, a, m per axis), written below.
* Noise: R = (m r/3)², r = 1 % (Bernard eq. 9.3).
* Extinction: Δm = k X, X = 1/(sin h + 0.50572 (h + 6.07995°)^−1.6364) (Kasten & Young 1989).
* Penumbra: fraction of the solar disc (angular radius asin(R☉/d)) not covered by the Earth
  disc (angular radius asin((R⊕ + h)/|r|)) — the conical model of Montenbruck & Gill (2000)
  §3.4.2; R⊕ = 6378137 m, R☉ = 6.957e8 m (IAU 2015 B3).
* Earthshine / CSS albedo: Lambertian Earth cells, a_j = ρ_j A_j (n̂_j·ŝ)(n̂_j·û_j)/(π d_j²)
  (O'Keefe 2015 eq. 2.15), on a spherical 1.5° grid with the zonal albedo ρ(φ) =
  Σ c_k P_k(sin φ) whose Legendre coefficients (a cos φ-weighted fit of the CERES 2018 all-sky
  zonal means, RMS 0.012) are written below.
* Glint: normalised Phong lobe A (n̂·ŝ)(n̂·ô)(k+2)/(2π) max(r̂·ô, 0)^k, r̂ = 2(n̂·ŝ)n̂ − ŝ;
  extra facet: A/π (n̂·ŝ)(n̂·ô); both times the lit fraction.
* Self-shadowing: exact ray casting against axis-aligned boxes (slab method, Kay & Kajiya
  1986) from a regular 40×40 grid of points on every rectangular face.
* Light time: the object (position and attitude) at t − τ, τ = |r_site(t) − r_obj(t − τ)|/c
  (three fixed-point iterations); clock offset: everything at t + δ; exposure smearing: the
  mean *flux* over [t − T/2, t + T/2] by a 201-point composite Simpson rule.
* CSS (O'Keefe 2015 eq. 2.19, 2.21): y_κ = C C_κ (ν max(n̂'_κ·ŝ, 0) + Σ_j a_j max(n̂'_κ·ĉ_j, 0)),
  each term only inside the field of view n̂'·û ≥ cos ψ; n̂' from azimuth/elevation plus the
  misalignment offsets; the offset dual pyramid of §2.2.1 / Table 2.1 (−z sensors turned by
  45°), ψ = 60° (120° edge to edge); a failed sensor's output times its gain from t₀ on.

Geometry is analytic: circular orbits, a spherical Earth turning about the GCRS z axis at
7.292115e-5 rad/s, sites on its surface, the Sun fixed at 1 au (it moves 0.04″/s).
"""

from __future__ import annotations

import numpy as np

AU = 149_597_870_700.0
MU = 3.986004418e14
R_E = 6378137.0
R_SUN = 6.957e8
W_E = 7.292115e-5
C_LIGHT = 299_792_458.0
SUN_MAG = -26.74
R_PERCENT = 1.0
EPOCH = "2024-03-20T00:00:00Z"

#: Bernard 2021 Table 9.2: (ξ, a, m) of the cube's facets by normal axis
TABLE_9_2 = {"+X": (0.1, 0.95, 0.04), "-X": (0.5, 0.95, 0.08), "+Y": (0.1, 0.5, 0.5),
             "-Y": (0.5, 0.8, 0.5), "+Z": (0.1, 0.7, 0.4), "-Z": (1.0, 0.95, 0.6)}
AXES = {"+X": (1, 0, 0), "-X": (-1, 0, 0), "+Y": (0, 1, 0), "-Y": (0, -1, 0),
        "+Z": (0, 0, 1), "-Z": (0, 0, -1)}
#: zonal albedo: Legendre coefficients in sin(latitude) of the CERES 2018 all-sky zonal means
ZONAL = np.array([0.31661599, -0.0120705, 0.24989466, -0.04124043, 0.08316421, -0.01023705,
                  -0.00765326])


# ------------------------------------------------------------------------------------------
# attitude and geometry
# ------------------------------------------------------------------------------------------
def qmul(q, p):
    q1, qv = q[..., :1], q[..., 1:]
    p1, pv = p[..., :1], p[..., 1:]
    return np.concatenate([q1 * p1 - np.sum(qv * pv, -1, keepdims=True),
                           q1 * pv + p1 * qv - np.cross(qv, pv)], -1)


def attitude_matrix(q):
    """A(q) (N,3,3), Bernard eq. 3.16."""
    q = np.asarray(q, float)
    q1, qv = q[:, 0], q[:, 1:]
    n = q.shape[0]
    A = np.empty((n, 3, 3))
    x = np.zeros((n, 3, 3))
    x[:, 0, 1], x[:, 0, 2], x[:, 1, 2] = -qv[:, 2], qv[:, 1], -qv[:, 0]
    x[:, 1, 0], x[:, 2, 0], x[:, 2, 1] = qv[:, 2], -qv[:, 1], qv[:, 0]
    A[:] = ((q1 ** 2 - np.sum(qv * qv, 1))[:, None, None] * np.eye(3)
            + 2 * qv[:, :, None] * qv[:, None, :] - 2 * q1[:, None, None] * x)
    return A


def to_body(q, v):
    return np.einsum("nij,nj->ni", attitude_matrix(q), v)


def spin(q0, w, t):
    """q(t) = [cos(|ω|t/2), sin(|ω|t/2) ω̂] ⊗ q0 (N,4)."""
    t = np.asarray(t, float)[:, None]
    wn = np.linalg.norm(w)
    dq = np.concatenate([np.cos(wn * t / 2), np.sin(wn * t / 2) * (np.asarray(w) / wn)], 1)
    return qmul(dq, np.broadcast_to(q0, dq.shape))


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


class Geometry:
    """Circular orbit (a, i, Ω, u0), spherical-Earth sites, a fixed Sun, a spinning body."""

    def __init__(self, a_m, inc_deg, raan_deg, u0_deg, sites, sun_dir, q0, w_body):
        self.a = a_m
        self.n = np.sqrt(MU / a_m ** 3)
        i, raan = np.radians(inc_deg), np.radians(raan_deg)
        self.P = np.array([np.cos(raan), np.sin(raan), 0.0])
        self.Q = np.array([-np.sin(raan) * np.cos(i), np.cos(raan) * np.cos(i), np.sin(i)])
        self.u0 = np.radians(u0_deg)
        self.sites = [(np.radians(lat), np.radians(lon)) for lat, lon in sites]
        self.sun = AU * unit(sun_dir)
        self.q0 = unit(q0)
        self.w = np.asarray(w_body, float)

    def obj(self, t):
        u = self.u0 + self.n * np.asarray(t, float)
        r = self.a * (np.cos(u)[:, None] * self.P + np.sin(u)[:, None] * self.Q)
        v = self.a * self.n * (-np.sin(u)[:, None] * self.P + np.cos(u)[:, None] * self.Q)
        return r, v

    def site(self, k, t):
        lat, lon = self.sites[k]
        lam = lon + W_E * np.asarray(t, float)
        return R_E * np.stack([np.cos(lat) * np.cos(lam), np.cos(lat) * np.sin(lam),
                               np.full_like(lam, np.sin(lat))], 1)

    lvlh = False

    def q(self, t):
        """Attitude (N,4): a constant body rate from q0 — or, with ``lvlh``, the same spin on
        top of the local-vertical frame (body z to zenith, y along the orbit normal), whose
        Sun direction then sweeps the body sphere in two dimensions."""
        if not self.lvlh:
            return spin(self.q0, self.w, t)
        r, v = self.obj(t)
        z = unit(r)
        y = unit(np.cross(r, v))
        x = np.cross(y, z)
        ql = dcm_to_quat(np.stack([x, y, z], 1))
        return qmul(spin(np.array([1.0, 0, 0, 0]), self.w, t), ql)


def dcm_to_quat(A):
    """Quaternion (N,4) of attitude matrices A (N,3,3) (Shepperd's method; q1 ≥ 0)."""
    A = np.asarray(A, float)
    out = np.empty((A.shape[0], 4))
    for n, M in enumerate(A):
        tr = np.trace(M)
        cand = np.array([tr, M[0, 0], M[1, 1], M[2, 2]])
        i = int(np.argmax(cand))
        if i == 0:
            q1 = 0.5 * np.sqrt(1 + tr)
            q = [q1, (M[1, 2] - M[2, 1]) / (4 * q1), (M[2, 0] - M[0, 2]) / (4 * q1), (M[0, 1] - M[1, 0]) / (4 * q1)]
        elif i == 1:
            q2 = 0.5 * np.sqrt(1 + 2 * M[0, 0] - tr)
            q = [(M[1, 2] - M[2, 1]) / (4 * q2), q2, (M[0, 1] + M[1, 0]) / (4 * q2), (M[2, 0] + M[0, 2]) / (4 * q2)]
        elif i == 2:
            q3 = 0.5 * np.sqrt(1 + 2 * M[1, 1] - tr)
            q = [(M[2, 0] - M[0, 2]) / (4 * q3), (M[0, 1] + M[1, 0]) / (4 * q3), q3, (M[1, 2] + M[2, 1]) / (4 * q3)]
        else:
            q4 = 0.5 * np.sqrt(1 + 2 * M[2, 2] - tr)
            q = [(M[0, 1] - M[1, 0]) / (4 * q4), (M[2, 0] + M[0, 2]) / (4 * q4), (M[1, 2] + M[2, 1]) / (4 * q4), q4]
        q = np.asarray(q)
        out[n] = q if q[0] >= 0 else -q
    return out


def elevation(r_obj, r_site):
    d = r_obj - r_site
    return np.arcsin(np.sum(d * unit(r_site), 1) / np.linalg.norm(d, axis=1))


def lit_fraction(r_obj, r_sun, extra_m=0.0):
    """Visible fraction of the solar disc (conical model), (N,)."""
    d = r_sun - r_obj
    ds = np.linalg.norm(d, axis=1)
    rr = np.linalg.norm(r_obj, axis=1)
    a = np.arcsin(R_SUN / ds)
    b = np.arcsin(np.clip((R_E + extra_m) / rr, -1, 1))
    c = np.arccos(np.clip(np.sum(-r_obj * d, 1) / (rr * ds), -1, 1))
    out = np.ones_like(c)
    full = c <= b - a
    part = (c < a + b) & ~full
    out[full] = 0.0
    x = (c[part] ** 2 + a[part] ** 2 - b[part] ** 2) / (2 * c[part])
    y = np.sqrt(np.maximum(a[part] ** 2 - x ** 2, 0))
    area = (a[part] ** 2 * np.arccos(np.clip(x / a[part], -1, 1))
            + b[part] ** 2 * np.arccos(np.clip((c[part] - x) / b[part], -1, 1)) - c[part] * y)
    out[part] = 1 - area / (np.pi * a[part] ** 2)
    return out


def airmass(h):
    """Kasten & Young (1989); NaN below −6.07995° (outside the formula's range)."""
    hd = np.maximum(np.degrees(h), -6.0)
    return 1.0 / (np.sin(h) + 0.50572 * (hd + 6.07995) ** -1.6364)


# ------------------------------------------------------------------------------------------
# photometry
# ------------------------------------------------------------------------------------------
def cook_torrance_product(n, s, o, xi, a, m):
    """(n̂·ŝ)(n̂·ô) f_r, broadcast over leading axes; 0 unless both cosines are positive."""
    ns = np.sum(n * s, -1)
    no = np.sum(n * o, -1)
    h = unit(s + o)
    nh = np.sum(n * h, -1)
    c = np.sum(o * h, -1)
    vis = (ns > 0) & (no > 0)
    with np.errstate(all="ignore"):
        nh2 = nh * nh
        D = np.exp((nh2 - 1) / (nh2 * m * m)) / (np.pi * m * m * nh2 * nh2)
        G = np.minimum(1.0, np.minimum(2 * nh * no / c, 2 * nh * ns / c))
        nn = (1 + np.sqrt(a)) / (1 - np.sqrt(a))
        g = np.sqrt(nn * nn + c * c - 1)
        F = 0.5 * (g - c) ** 2 / (g + c) ** 2 * (1 + (c * (g + c) - 1) ** 2 / (c * (g - c) + 1) ** 2)
        spec = np.where((nh > 0) & (c > 0), (1 - xi) * F * D * G / 4.0, 0.0)
    return np.where(vis, xi * a / np.pi * ns * no + spec, 0.0)


class Facets:
    """Flat facets: normals (F,3), areas (F,), Table 9.2 materials by normal axis."""

    def __init__(self, normals, areas):
        self.normals = np.asarray(normals, float)
        self.areas = np.asarray(areas, float)
        mats = []
        for nrm in self.normals:
            key = next(k for k, ax in AXES.items() if np.dot(nrm, ax) > 0.999)
            mats.append(TABLE_9_2[key])
        self.mat = np.array(mats)

    def products(self, sb, ob):
        """(N,F) products of every facet."""
        return cook_torrance_product(self.normals[None], sb[:, None], ob[:, None],
                                     self.mat[None, :, 0], self.mat[None, :, 1], self.mat[None, :, 2])

    def flux(self, sb, ob, visible=None):
        P = self.products(sb, ob) * self.areas[None]
        if visible is not None:
            P = P * visible
        return P.sum(1)


def cube(side_m=1.0):
    return Facets([AXES[k] for k in AXES], np.full(6, side_m ** 2))


class Boxes:
    """Disjoint axis-aligned boxes [(lo (3,), hi (3,))]: facets, OBJ text, exact shadows."""

    def __init__(self, boxes, grid=40):
        self.boxes = [(np.asarray(lo, float), np.asarray(hi, float)) for lo, hi in boxes]
        normals, areas, pts, owner = [], [], [], []
        for b, (lo, hi) in enumerate(self.boxes):
            for ax in range(3):
                for sgn in (1, -1):
                    nrm = np.zeros(3)
                    nrm[ax] = sgn
                    o1, o2 = [k for k in range(3) if k != ax]
                    u = (np.arange(grid) + 0.5) / grid
                    U, V = np.meshgrid(lo[o1] + u * (hi[o1] - lo[o1]), lo[o2] + u * (hi[o2] - lo[o2]))
                    p = np.zeros((U.size, 3))
                    p[:, ax] = hi[ax] if sgn > 0 else lo[ax]
                    p[:, o1], p[:, o2] = U.ravel(), V.ravel()
                    normals.append(nrm)
                    areas.append((hi[o1] - lo[o1]) * (hi[o2] - lo[o2]))
                    pts.append(p)
                    owner.append(b)
        self.facets = Facets(normals, areas)
        self.points = pts
        self.owner = owner

    def _blocked(self, p, d, skip):
        """(P,) True where the ray p + t d (t > 0) hits a box other than ``skip``."""
        hit = np.zeros(p.shape[0], bool)
        with np.errstate(divide="ignore", invalid="ignore"):
            for b, (lo, hi) in enumerate(self.boxes):
                if b == skip:
                    continue
                inv = 1.0 / d
                t1 = (lo - p) * inv
                t2 = (hi - p) * inv
                tmin = np.nanmax(np.minimum(t1, t2), axis=1)
                tmax = np.nanmin(np.maximum(t1, t2), axis=1)
                hit |= (tmax >= np.maximum(tmin, 0.0))
        return hit

    def visible_fractions(self, sb, ob):
        """(N,F) lit-and-seen fraction of every facet (only where it faces both)."""
        N, F = sb.shape[0], len(self.points)
        out = np.zeros((N, F))
        for i in range(N):
            for f in range(F):
                nrm = self.facets.normals[f]
                if nrm @ sb[i] <= 0 or nrm @ ob[i] <= 0:
                    continue
                p = self.points[f] + 1e-9 * nrm
                free = ~self._blocked(p, sb[i], self.owner[f]) & ~self._blocked(p, ob[i], self.owner[f])
                out[i, f] = free.mean()
        return out

    def obj_text(self):
        """Wavefront OBJ of the boxes (12 outward-wound triangles each)."""
        lines, base = [], 1
        for lo, hi in self.boxes:
            c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in c]
            quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
            for a, b, cc, d in quads:
                lines.append(f"f {base + a} {base + b} {base + cc}")
                lines.append(f"f {base + a} {base + cc} {base + d}")
            base += 8
        return "\n".join(lines) + "\n"


def earth_cells(step_deg=1.5):
    """Spherical Earth grid: centres (M,3) m, unit normals, ρ·area (m²)."""
    lat_e = np.radians(np.arange(-90.0, 90.0 + 1e-9, step_deg))
    lon_e = np.radians(np.arange(-180.0, 180.0 + 1e-9, step_deg))
    lat_c = 0.5 * (lat_e[:-1] + lat_e[1:])
    lon_c = 0.5 * (lon_e[:-1] + lon_e[1:])
    area = R_E ** 2 * np.outer(np.diff(np.sin(lat_e)), np.diff(lon_e))
    rho = np.clip(np.polynomial.legendre.legval(np.sin(lat_c), ZONAL), 0, 1)
    LA, LO = np.meshgrid(lat_c, lon_c, indexing="ij")
    nrm = np.stack([np.cos(LA) * np.cos(LO), np.cos(LA) * np.sin(LO), np.sin(LA)], -1).reshape(-1, 3)
    return R_E * nrm, nrm, (rho[:, None] * area).reshape(-1)


_CELLS = {}


def albedo_cells(r, sun_dir):
    """Directions (M,3) object→cell and irradiance ratios a_j (M,) of sunlit visible cells."""
    if "g" not in _CELLS:
        _CELLS["g"] = earth_cells()
    cen, nrm, ra = _CELLS["g"]
    d = r[None] - cen
    dist = np.linalg.norm(d, axis=1)
    cs = nrm @ sun_dir
    cv = np.sum(nrm * d, 1) / dist
    ok = (cs > 0) & (cv > 0)
    a = ra[ok] * cs[ok] * cv[ok] / (np.pi * dist[ok] ** 2)
    return -d[ok] / dist[ok, None], a


# ------------------------------------------------------------------------------------------
# the magnitude simulator
# ------------------------------------------------------------------------------------------
def _state(geo, k, t, dt_obj):
    """Object, site, Sun geometry and attitude for site k at label times t (object at t+dt_obj)."""
    r_site = geo.site(k, t)
    r_obj, _ = geo.obj(t + dt_obj)
    q = geo.q(t + dt_obj)
    return r_obj, r_site, q


def magnitudes(geo, shape, k, t, effects, *, t_shift=0.0):
    """Apparent magnitudes (N,) of site k at label times t with ``effects`` on (dict name → params).

    Per-site parameters are given as scalars for this site.
    """
    t = np.asarray(t, float)
    e = effects
    if "exposure_smearing" in e and not isinstance(t_shift, np.ndarray):
        T = e["exposure_smearing"]["exposure_s"]
        nodes = np.linspace(-0.5, 0.5, 201)
        w = np.ones(201)
        w[1:-1:2], w[2:-1:2] = 4, 2
        w /= w.sum()
        rest = {kk: v for kk, v in e.items() if kk not in ("exposure_smearing", "extinction", "zero_point")}
        flux = sum(wj * _irradiance(geo, shape, k, t + xj * T, rest) for xj, wj in zip(nodes, w))
    else:
        flux = _irradiance(geo, shape, k, t + t_shift, e)
    with np.errstate(divide="ignore"):
        m = SUN_MAG - 2.5 * np.log10(np.where(flux > 0, flux, np.nan))
    if "extinction" in e:
        r_obj, _ = geo.obj(t)
        m = m + e["extinction"]["k_mag_per_airmass"] * airmass(elevation(r_obj, geo.site(k, t)))
    if "zero_point" in e:
        m = m + e["zero_point"]["offset_mag"]
    return m


def _irradiance(geo, shape, k, t, e):
    """(ν F_sun + F_extra)/|r_obs|² (au/|r_sun|)² at reception times t (clock offset applied)."""
    t = np.asarray(t, float)
    if "clock_offset" in e:
        t = t + e["clock_offset"]["dt_s"]
    r_site = geo.site(k, t)
    dt = np.zeros_like(t)
    if "light_time" in e:
        for _ in range(3):
            r_o, _ = geo.obj(t - dt)
            dt = np.linalg.norm(r_site - r_o, axis=1) / C_LIGHT
    r_obj, _ = geo.obj(t - dt)
    q = geo.q(t - dt)
    d_sun = geo.sun[None] - r_obj
    d_obs = r_site - r_obj
    s_hat, o_hat = unit(d_sun), unit(d_obs)
    sb, ob = to_body(q, s_hat), to_body(q, o_hat)
    if "penumbra" in e:
        nu = lit_fraction(r_obj, geo.sun[None], e["penumbra"]["shadow_height_m"])
    else:
        nu = (lit_fraction(r_obj, geo.sun[None]) > 0).astype(float)
    vis = shape.visible_fractions(sb, ob) if ("self_shadowing" in e and isinstance(shape, Boxes)) else None
    facets = shape.facets if isinstance(shape, Boxes) else shape
    F = nu * facets.flux(sb, ob, vis)
    for name in ("specular_glint", "unmodelled_facet"):
        if name in e:
            p = e[name]
            a, el = np.radians(p["az_deg"]), np.radians(p["el_deg"])
            n = np.array([np.cos(el) * np.cos(a), np.cos(el) * np.sin(a), np.sin(el)])
            ns, no = sb @ n, ob @ n
            if name == "unmodelled_facet":
                extra = p["area_m2"] / np.pi * ns * no
            else:
                kk = p["exponent"]
                ro = 2 * ns * no - np.sum(sb * ob, 1)
                extra = p["area_m2"] * ns * no * (kk + 2) / (2 * np.pi) * np.maximum(ro, 0) ** kk
            F = F + nu * np.where((ns > 0) & (no > 0), extra, 0.0)
    if "earthshine" in e:
        Fe = np.zeros_like(t)
        for i in range(t.size):
            dirs, ratio = albedo_cells(r_obj[i], unit(geo.sun))
            if ratio.size == 0:
                continue
            cb = to_body(np.repeat(q[i:i + 1], ratio.size, 0), dirs)
            obi = np.repeat(ob[i:i + 1], ratio.size, 0)
            Fe[i] = ratio @ facets.flux(cb, obi)
        F = F + e["earthshine"]["albedo_scale"] * Fe
    rng_obs = np.linalg.norm(d_obs, axis=1)
    rng_sun = np.linalg.norm(d_sun, axis=1)
    return F / rng_obs ** 2 * (AU / rng_sun) ** 2


def record(geo, shape, t, effects_by_site, rng, *, min_elevation_deg=10.0):
    """Simulated recording: dict of rows over every site (times t for each site).

    ``effects_by_site``: list (per site) of effect dicts. Rows below ``min_elevation_deg`` or
    with the object not lit (the model's lit-or-dark Sun, or the penumbra effect's ν = 0) or
    not seen are dropped. Noise σ = |m| r/3 with r = 1 % (Bernard eq. 9.3).
    """
    rows = {k: [] for k in ("t", "site", "mag", "sigma", "r_obj", "v_obj", "r_site", "q", "el")}
    for k in range(len(geo.sites)):
        r_obj, v_obj = geo.obj(t)
        r_site = geo.site(k, t)
        el = elevation(r_obj, r_site)
        eff = effects_by_site[k]
        m = magnitudes(geo, shape, k, t, eff)
        m0 = magnitudes(geo, shape, k, t, {})
        ok = (el > np.radians(min_elevation_deg)) & np.isfinite(m) & np.isfinite(m0)
        sig = np.abs(m) * R_PERCENT / 100.0 / 3.0
        y = m + rng.standard_normal(m.size) * np.where(np.isfinite(sig), sig, 0.0)
        for key, v in (("t", t), ("site", np.full(t.size, k)), ("mag", y), ("sigma", sig),
                       ("r_obj", r_obj), ("v_obj", v_obj), ("r_site", r_site), ("q", geo.q(t)),
                       ("el", el)):
            rows[key].append(np.asarray(v)[ok])
    out = {k: np.concatenate(v) for k, v in rows.items()}
    order = np.lexsort((out["site"], out["t"]))
    out = {k: v[order] for k, v in out.items()}
    out["r_sun"] = np.broadcast_to(geo.sun, out["r_obj"].shape).copy()
    out["omega"] = np.broadcast_to(geo.w, out["r_obj"].shape).copy()
    return out


# ------------------------------------------------------------------------------------------
# coarse sun sensors
# ------------------------------------------------------------------------------------------
#: O'Keefe 2015 Table 2.1 (offset dual pyramid, §2.2.1): (azimuth, elevation) in degrees
DUAL_PYRAMID = [(0, 45), (90, 45), (180, 45), (270, 45), (45, -45), (135, -45), (225, -45), (315, -45)]
FOV_HALF_DEG = 60.0


def css_normals(d_az_deg=None, d_el_deg=None):
    az = np.radians([a for a, _ in DUAL_PYRAMID])
    el = np.radians([e for _, e in DUAL_PYRAMID])
    if d_az_deg is not None:
        az = az + np.radians(d_az_deg)
        el = el + np.radians(d_el_deg)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)


def css_outputs(geo, t, effects):
    """Noise-free CSS outputs (N, 8) with effects (css_albedo, css_misalignment,
    css_scale_factor, css_fault)."""
    e = effects
    r, _ = geo.obj(t)
    q = geo.q(t)
    s_hat = unit(geo.sun[None] - r)
    sb = to_body(q, s_hat)
    nu = (lit_fraction(r, geo.sun[None]) > 0).astype(float)
    mis = e.get("css_misalignment")
    n = css_normals(mis["d_az_deg"], mis["d_el_deg"]) if mis else css_normals()
    cf = np.cos(np.radians(FOV_HALF_DEG))

    def resp(u):  # (M,3) → (M,8)
        c = u @ n.T
        return np.where((c >= cf) & (c > 0), c, 0.0)

    y = nu[:, None] * resp(sb)
    if "css_albedo" in e:
        for i in range(len(t)):
            dirs, ratio = albedo_cells(r[i], unit(geo.sun))
            if ratio.size:
                y[i] += e["css_albedo"]["albedo_scale"] * (ratio @ resp(to_body(np.repeat(q[i:i + 1], ratio.size, 0), dirs)))
    if "css_scale_factor" in e:
        y = y * e["css_scale_factor"]["common"] * np.asarray(e["css_scale_factor"]["individual"])[None]
    if "css_fault" in e:
        f = e["css_fault"]
        m = np.asarray(t) >= f["t_start_s"]
        y[m, int(f["sensor"])] *= f["gain"]
    return y
