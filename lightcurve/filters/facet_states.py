"""Model 3 of Bernard (2021) ch. 8: the facet reflection parameters as filter states.

Instead of absorbing uncertain reflection parameters into a magnitude bias (Models 1–2,
:mod:`lightcurve.filters.reflection`), Model 3 estimates them directly: for every chosen
Cook–Torrance facet i the diffuse fraction ξ_i ∈ (0,1), the albedo / normal-incidence
reflectance a_i = F0 ∈ (0,1), the Beckmann rms slope m_i > 0 and the area A_i > 0 (m²).

Unconstrained coordinates (Bernard eq. 8.41–8.44, shared with
:mod:`lightcurve.studies.fit_reflection`)::

    z_ξ = logit ξ,   z_a = logit a,   z_m = ln m,   z_A = ln A,

so every filter state, sigma point or particle maps to physical values in range. Bernard
eq. 8.41–8.44 writes the bounded maps as ``p = ½ tanh z̃ + ½`` = logistic(2 z̃): the same map
up to the factor 2 on the coordinate, which a Kalman or particle filter does not see (the state
and its covariance scale together). Eq. 8.43 bounds m to (0, 1) that way too; ``bounded_m=True``
(the thesis variant, :func:`lightcurve.filters.invert.invert`) uses the logit for m as well,
the default keeps ln m (m > 0). The inverse
and the (diagonal) Jacobian are ``ξ = 1/(1+e^{−z})``, ``dξ/dz = ξ(1−ξ)``; ``m = e^z``,
``dm/dz = m``. (The shape files bound m ≤ 1; the log map lets m exceed 1, where the Beckmann
formula is still defined — stated, not hidden.)

Parameters on a closed bound of their range (ξ = 0 or 1 — Table 9.2's −Z facet is fully
diffuse, ξ = 1) have no finite unbounded coordinate: they are held fixed at that value and left
out of the state (listed in ``held``); the §10.1 truth draw
(:func:`lightcurve.studies.fit_reflection.perturb_reflection`) holds them fixed too.

Prior (§10.1): the truth perturbation is ``p ~ N(p₀, (frac·p₀)²)``, p₀ the shape file's value,
frac = 10 % by default. The filters' initial state is ``z₀ = z(p₀)`` with covariance
``diag(σ_z²)``, ``σ_z = frac · p₀ · dz/dp(p₀)``, i.e. ``frac/(1−p₀)`` for the logits and
``frac`` for the logs (first-order mapping of σ_p by the transform's derivative).

Dynamics (eq. 8.39): constant parameters, ``ż = w``, ``Φ = I``; the optional process noise w
is white with PSD ``process_noise`` (z-units²/s, default 0), so ``Q_d = process_noise·|Δt|·I``.

State ordering: ``names[d]`` = ``"<kind>[<facet>]"`` with kind-major order — all ξ first (in
facet order), then all a, m, A — e.g. 24 states ``xi[0] … xi[5], a[0] … A[5]`` for a 6-facet
cube. ``kind_col[d]`` ∈ {0: ξ, 1: a, 2: m, 3: A} and ``facet[d]`` (index into the shape's
facets) describe each state.

Use from a particle filter (per-particle facet arrays)::

    fs = FacetParameterStates(shape)                  # 24 states for cube_1u
    Z = fs.z0 + rng.standard_normal((N, fs.dim)) * fs.prior_sd_z
    areas, params = fs.facet_arrays(Z)                # (N,F), (N,F,7): kernel arrays per particle
    mags = fs.magnitudes(model, Q, Z, k)              # (N,) apparent magnitudes at epoch k
    # or directly: mag_states_nb(Q, s_eci, o_eci, normals, areas, ids, params, offset)

``areas``/``params`` are the shape's ``kernel_arrays()`` with the estimated entries replaced,
so facets that are not estimated (or have other BRDFs) keep their nominal values.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..core.photometry import (
    COOK_TORRANCE,
    COOK_TORRANCE_THESIS,
    brdf_product_nb,
    facet_flux_nb,
    magnitude_partials_q_nb,
)
from ..errors import InputError
from ..photometry.magnitude import apparent_magnitude
from ..photometry.partials import kernel_capable, magnitude_partials
from ..rotations import qrot_xyz_nb

__all__ = ["KINDS", "LOGIT_KINDS", "FacetParameterStates", "to_unbounded", "from_unbounded",
           "from_unbounded_xyz", "dp_dz", "mag_states_nb", "mag_z_states_nb", "partials_z_nb"]

#: the four Cook–Torrance facet parameters Model 3 can estimate
KINDS = ("xi", "a", "m", "A")
#: parameters in (0,1) (logit map); the others are > 0 (log map)
LOGIT_KINDS = ("xi", "a")
_KIND_COL = {"xi": 0, "a": 1, "m": 2, "A": 3}
#: kernel ids of the Cook–Torrance forms whose ξ, a, m Model 3 can estimate (physical and
#: Bernard eq. 5.8 diffuse term)
CT_IDS = (COOK_TORRANCE, COOK_TORRANCE_THESIS)


# --------------------------------------------------------------------------------------------
# transforms (the one implementation; fit_reflection uses these)
# --------------------------------------------------------------------------------------------

def to_unbounded(p, logit):
    """Physical (..., D) → unbounded z (..., D): logit where ``logit`` (D,) is True, else ln."""
    p = np.asarray(p, float)
    lg = np.broadcast_to(np.asarray(logit, bool), p.shape[-1:])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(lg, np.log(p / (1.0 - p)), np.log(p))


def from_unbounded(z, logit):
    """Unbounded z (..., D) → physical (..., D): logistic where ``logit`` (D,), else exp."""
    z = np.asarray(z, float)
    lg = np.broadcast_to(np.asarray(logit, bool), z.shape[-1:])
    with np.errstate(over="ignore"):
        return np.where(lg, 1.0 / (1.0 + np.exp(-z)), np.exp(z))


def dp_dz(z, logit):
    """Diagonal Jacobian dp/dz (..., D) at z: p(1−p) (logit) or p (log)."""
    p = from_unbounded(z, logit)
    lg = np.broadcast_to(np.asarray(logit, bool), p.shape[-1:])
    return np.where(lg, p * (1.0 - p), p)


# --------------------------------------------------------------------------------------------
# numba kernel: magnitudes with per-state facet arrays
# --------------------------------------------------------------------------------------------

@nb.njit(cache=True)
def mag_states_nb(Q, s, o, normals, areas, ids, params, offset):
    """Apparent magnitudes (S,) of S states at one epoch, each with its own facet arrays.

    Q (S,4) inertial→body quaternions (scalar first); s, o (3,) unit object→Sun and
    object→observer directions (ECI); normals (F,3) body axes; areas (S,F) m²; ids (F,) BRDF
    model ids; params (S,F,P) packed BRDF rows; offset (mag) = m_sun + 5 log10|r_obs|
    + 5 log10(|r_sun|/au) (+ eclipse term). ``m = offset − 2.5 log10 Σ_i A_i (n̂·ŝ)⁺(n̂·ô)⁺ f_r,i``
    (DESIGN.md magnitude equation); +inf where no light reaches the observer. Serial (the
    Kalman filters call it with ≤ 2n+1 states; a particle filter may wrap it in its own
    parallel loop).
    """
    S = Q.shape[0]
    F = normals.shape[0]
    out = np.empty(S)
    for i in range(S):
        q0, q1, q2, q3 = Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3]
        # ŝ, ô in body axes: A(q) v, the passive inertial→body rotation
        sx, sy, sz = qrot_xyz_nb(q0, q1, q2, q3, s[0], s[1], s[2])
        ox, oy, oz = qrot_xyz_nb(q0, q1, q2, q3, o[0], o[1], o[2])
        acc = 0.0
        for f in range(F):
            mid = ids[f]
            if mid < 0:
                continue
            nx, ny, nz = normals[f, 0], normals[f, 1], normals[f, 2]
            if nx * sx + ny * sy + nz * sz <= 0.0 or nx * ox + ny * oy + nz * oz <= 0.0:
                continue
            acc += areas[i, f] * brdf_product_nb(mid, params[i, f], nx, ny, nz, sx, sy, sz,
                                                 ox, oy, oz)
        out[i] = offset - 2.5 * math.log10(acc) if acc > 0.0 else np.inf
    return out


@nb.njit(cache=True, inline="always")
def from_unbounded_xyz(z, logit):
    """:func:`from_unbounded` of one scalar: ``1/(1+e^{−z})`` when ``logit``, else ``e^{z}``."""
    return 1.0 / (1.0 + math.exp(-z)) if logit else math.exp(z)


@nb.njit(cache=True, inline="always")
def fill_facet_arrays_nb(z, facet, kind_col, logit, areas0, params0, ar, pr):
    """Facet areas ``ar`` (F,) m² and BRDF parameters ``pr`` (F,P) of one Model 3 state z (D,).

    Starts from the nominal ``areas0``/``params0`` and overwrites the estimated entries with
    ``p = 1/(1+e^{−z})`` (``logit[d]``) or ``e^{z}``; ``kind_col[d] == 3`` is an area, otherwise
    the BRDF parameter column of facet ``facet[d]``.
    """
    F, P = params0.shape
    for f in range(F):
        ar[f] = areas0[f]
        for j in range(P):
            pr[f, j] = params0[f, j]
    for d in range(z.shape[0]):
        zz = z[d]
        v = from_unbounded_xyz(zz, logit[d])
        if kind_col[d] == 3:
            ar[facet[d]] = v
        else:
            pr[facet[d], kind_col[d]] = v


@nb.njit(cache=True)
def mag_z_states_nb(Q, s, o, normals, areas0, ids, params0, offset, Z, kind_col, facet, logit):
    """Apparent magnitudes (S,) of S (attitude, Model 3 state) pairs at one epoch.

    As :func:`mag_states_nb`, but the per-state facet arrays are filled inside the kernel
    from the unbounded states Z (S,D) and the layout (``kind_col``, ``facet``, ``logit``) —
    no (S,F,P) arrays built in NumPy. +inf where no light reaches the observer. Serial.
    """
    S = Q.shape[0]
    F = normals.shape[0]
    out = np.empty(S)
    areas = np.empty(F)
    params = np.empty(params0.shape)
    for i in range(S):
        fill_facet_arrays_nb(Z[i], facet, kind_col, logit, areas0, params0, areas, params)
        acc = facet_flux_nb(Q[i], s, o, normals, areas, ids, params)
        out[i] = offset - 2.5 * math.log10(acc) if acc > 0.0 else np.inf
    return out


@nb.njit(cache=True)
def partials_z_nb(q, s, o, normals, areas0, ids, params0, offset, z, kind_col, facet, logit):
    """Magnitude and partials at ONE attitude and Model 3 state, in one pass over the facets.

    q (4,) inertial→body quaternion; s, o (3,) unit ECI object→Sun / object→observer; the
    shape's nominal kernel arrays (``ids`` Lambert / Cook–Torrance / Phong only, see
    :func:`lightcurve.photometry.partials.kernel_capable`); offset (mag) as in
    :func:`mag_states_nb`; z (D,) and the state layout (``kind_col``, ``facet``, ``logit``
    of :class:`FacetParameterStates`). Returns ``(m, ∂m/∂δθ (3,), ∂m/∂z (D,))`` with
    ``∂m/∂z_d = ∂m/∂p_d · dp_d/dz_d``; m = +inf and NaN partials where no light is reflected.
    No shape copy, no Python loop over facets.
    """
    F = normals.shape[0]
    areas = np.empty(F)
    params = np.empty(params0.shape)
    fill_facet_arrays_nb(z, facet, kind_col, logit, areas0, params0, areas, params)
    D = z.shape[0]
    dp = np.empty(D)          # dp/dz: p(1−p) (logit) or p (log), as dp_dz
    for d in range(D):
        if logit[d]:
            p = 1.0 / (1.0 + math.exp(-z[d]))
            dp[d] = p * (1.0 - p)
        else:
            dp[d] = math.exp(z[d])
    dA = np.empty(F)
    dxi = np.empty(F)
    da = np.empty(F)
    dmm = np.empty(F)
    m, tx, ty, tz = magnitude_partials_q_nb(q, s, o, normals, areas, ids, params, offset,
                                            dA, dxi, da, dmm)
    dth = np.empty(3)
    dth[0] = tx
    dth[1] = ty
    dth[2] = tz
    dz = np.empty(D)
    for d in range(D):
        c = kind_col[d]
        f = facet[d]
        if c == 0:
            v = dxi[f]
        elif c == 1:
            v = da[f]
        elif c == 2:
            v = dmm[f]
        else:
            v = dA[f]
        dz[d] = v * dp[d]
    return m, dth, dz


# --------------------------------------------------------------------------------------------
# the state description
# --------------------------------------------------------------------------------------------

def check_kinds(kinds):
    """Validate a selection of reflection-parameter kinds (subset of :data:`KINDS`).

    Returns the kinds as a tuple in the order given; InputError (field ``params``) for an
    unknown, repeated or empty selection.
    """
    kinds = tuple(kinds)
    bad = [k for k in kinds if k not in KINDS]
    if bad or not kinds or len(set(kinds)) != len(kinds):
        raise InputError("unknown or repeated reflection parameter", field="params",
                         value=",".join(map(str, kinds)), allowed=", ".join(KINDS))
    return kinds


def select_ct_facets(shape, facets, purpose, field="facets", ids=(COOK_TORRANCE,)):
    """Indices of the Cook–Torrance facets (area > 0) whose parameters are estimated.

    ``facets`` None → all of them; otherwise each index must be such a facet (InputError
    naming it and the allowed ones). ``purpose`` completes the message when the shape has
    none ("estimated (Model 3)", "fitted"). ``ids``: the accepted kernel ids (default the
    physical Cook–Torrance only; Model 3 also takes the eq. 5.8 form, :data:`CT_IDS`). Returns a
    sorted int64 array.
    """
    F = shape.n_facets
    ct = np.flatnonzero(np.isin(shape.model_ids, ids) & (shape.areas_m2 > 0))
    if facets is None:
        fidx = ct
    else:
        fidx = np.asarray(sorted(set(int(i) for i in facets)), dtype=np.int64)
        for i in fidx:
            if not (0 <= i < F) or i not in ct:
                raise InputError("facet is not a Cook-Torrance facet with area > 0 of the shape",
                                 field="facets", value=int(i),
                                 allowed=",".join(str(x) for x in ct))
    if fidx.size == 0:
        raise InputError(f"the shape has no Cook-Torrance facet whose parameters could be "
                         f"{purpose}", field=field, value=shape.name)
    return np.ascontiguousarray(fidx, dtype=np.int64)


class FacetParameterStates:
    """Model 3 facet-parameter states (module docstring): layout, transforms, prior, dynamics.

    Parameters
    ----------
    shape : lightcurve.photometry.Shape
        Nominal parameters (prior centres p₀) and geometry.
    facets : sequence of int or None
        Facets to estimate (default: every Cook–Torrance facet with area > 0).
    kinds : subset of ("xi", "a", "m", "A")
        Parameters estimated per facet (default all four).
    prior_frac : float > 0
        σ_p / p₀ of the prior (§10.1: 0.1).
    process_noise : float ≥ 0
        PSD of the white z noise, z-units²/s (eq. 8.39 with optional noise; default 0).

    Attributes
    ----------
    dim : int — number of states D; names : list[str]; kind_col (D,) int; facet (D,) int;
    logit (D,) bool; p_nominal, z0 (D,); prior_sd_p, prior_sd_z (D,); P0 (D,D) = diag(σ_z²);
    fidx (K,) estimated facet indices.
    """

    def __init__(self, shape, *, facets=None, kinds=KINDS, prior_frac=0.1, process_noise=0.0,
                 bounded_m=False):
        self.kinds = tuple(k for k in KINDS if k in check_kinds(kinds))   # canonical order
        #: m through a bounded (0,1) map (Bernard eq. 8.43, the thesis variant) instead of ln
        self.bounded_m = bool(bounded_m)
        bounded = LOGIT_KINDS + (("m",) if self.bounded_m else ())
        self.prior_frac = float(prior_frac)
        if not (self.prior_frac > 0 and np.isfinite(self.prior_frac)):
            raise InputError("prior fraction must be > 0", field="reflection_frac",
                             value=prior_frac)
        self.process_noise = float(process_noise)
        if not (self.process_noise >= 0 and np.isfinite(self.process_noise)):
            raise InputError("process noise must be >= 0", field="process_noise",
                             value=process_noise)
        fidx = select_ct_facets(shape, facets, "estimated (Model 3)", field="reflection",
                                ids=CT_IDS)
        self.shape = shape
        self.fidx = np.ascontiguousarray(fidx, dtype=np.int64)
        _, areas, _, params = shape.kernel_arrays()
        self._areas0 = np.ascontiguousarray(areas, dtype=float)
        self._params0 = np.ascontiguousarray(params, dtype=float)
        names, kc, fc, held = [], [], [], []
        for kind in self.kinds:
            col = _KIND_COL[kind]
            for i in self.fidx:
                p = self._areas0[i] if col == 3 else self._params0[i, col]
                if kind in bounded and p in (0.0, 1.0):
                    # on a closed bound (Table 9.2's −Z: ξ = 1, fully diffuse): no unbounded
                    # coordinate reaches it, so the parameter is held fixed at its value
                    held.append(f"{kind}[{int(i)}]")
                    continue
                names.append(f"{kind}[{int(i)}]")
                kc.append(col)
                fc.append(int(i))
        if not names:
            raise InputError("every selected reflection parameter lies on a bound (held fixed): "
                             "nothing to estimate", field="reflection", value=",".join(held))
        self.names = names
        #: parameters on a closed bound of their range (ξ = 0 or 1), held at that value
        self.held = held
        self.dim = len(names)
        self.kind_col = np.asarray(kc, np.int64)
        self.facet = np.asarray(fc, np.int64)
        self.logit = (self.kind_col < 2) | ((self.kind_col == 2) & self.bounded_m)
        self.p_nominal = np.where(self.kind_col == 3, self._areas0[self.facet],
                                  self._params0[self.facet, np.minimum(self.kind_col, 2)])
        for d in range(self.dim):
            p = self.p_nominal[d]
            ok = np.isfinite(p) and p > 0 and (p < 1 or not self.logit[d])
            if not ok:
                raise InputError("nominal parameter outside the open range its transform needs",
                                 field=self.names[d], value=float(p),
                                 allowed="(0, 1)" if self.logit[d] else "> 0")
        self.z0 = self.to_z(self.p_nominal)
        # plain arrays of the one-pass kernels (partials_z_nb): no shape copy per call
        self._normals = np.ascontiguousarray(shape.normals_body, dtype=float)
        self._ids = np.ascontiguousarray(shape.model_ids, dtype=np.int64)
        self._kernel_partials = kernel_capable(self._ids)
        self.prior_sd_p = self.prior_frac * self.p_nominal
        self.prior_sd_z = self.prior_sd_p / dp_dz(self.z0, self.logit)
        self.P0 = np.diag(self.prior_sd_z ** 2)

    # -- transforms -------------------------------------------------------------------------
    def to_z(self, p):
        """Physical (..., D) → unbounded (..., D)."""
        return to_unbounded(p, self.logit)

    def to_p(self, z):
        """Unbounded (..., D) → physical (..., D) (ξ, a, m dimensionless; A m²)."""
        return from_unbounded(z, self.logit)

    def jacobian(self, z):
        """Diagonal dp/dz (..., D) at z (the full Jacobian is ``np.diag`` of it)."""
        return dp_dz(z, self.logit)

    def sigma_p(self, z, cov_z):
        """1σ in physical units (..., D) from the z covariance (..., D, D), first order:
        ``σ_p = |dp/dz| σ_z``."""
        var = np.clip(np.diagonal(np.asarray(cov_z, float), axis1=-2, axis2=-1), 0.0, None)
        return np.abs(self.jacobian(z)) * np.sqrt(var)

    # -- dynamics (eq. 8.39) ------------------------------------------------------------------
    def transition(self, dt):
        """``(Φ (D,D) = I, Q_d (D,D) = process_noise·|Δt|·I)`` over dt s."""
        return np.eye(self.dim), self.process_noise * abs(float(dt)) * np.eye(self.dim)

    # -- shape arrays ---------------------------------------------------------------------
    def facet_arrays(self, z):
        """Kernel arrays per state: z (S,D) or (D,) → ``areas (S,F)``, ``params (S,F,P)``
        (the shape's ``kernel_arrays()`` with the estimated entries set to p(z))."""
        Z = np.atleast_2d(np.asarray(z, float))
        S = Z.shape[0]
        p = self.to_p(Z)
        areas = np.repeat(self._areas0[None, :], S, axis=0)
        params = np.repeat(self._params0[None, :, :], S, axis=0)
        for d in range(self.dim):
            f, c = self.facet[d], self.kind_col[d]
            if c == 3:
                areas[:, f] = p[:, d]
            else:
                params[:, f, c] = p[:, d]
        return np.ascontiguousarray(areas), np.ascontiguousarray(params)

    def physical(self, z):
        """``{"xi", "a", "m", "A"}`` → (S,K) physical values of every estimated facet (z (S,D));
        kinds not estimated keep the nominal values."""
        areas, params = self.facet_arrays(z)
        f = self.fidx
        return {"xi": params[:, f, 0], "a": params[:, f, 1], "m": params[:, f, 2],
                "A": areas[:, f]}

    def shape_at(self, z):
        """A copy of the shape with the parameters p(z) (z (D,)); ranges not re-checked."""
        p = self.to_p(np.asarray(z, float).reshape(self.dim))
        areas = self._areas0.copy()
        kw = {}
        for d in range(self.dim):
            f, c = self.facet[d], self.kind_col[d]
            if c == 3:
                areas[f] = p[d]
            else:
                name = KINDS[c]
                if name not in kw:
                    kw[name] = np.where(np.isin(self.shape.model_ids, CT_IDS),
                                        self.shape.params[:, c], np.nan)
                kw[name][f] = p[d]
        return self.shape.copy_with(areas_m2=areas, check=False, **kw)

    # -- measurement ------------------------------------------------------------------------
    def magnitudes(self, model, Q, Z, k):
        """Predicted magnitudes (S,) at epoch k of ``model`` (a
        :class:`~lightcurve.filters.models.MagnitudeModel`) for attitudes Q (S,4) and states
        Z (S,D) (or one z (D,) shared by all attitudes); +inf where no light is reflected."""
        Q = np.ascontiguousarray(np.asarray(Q, float).reshape(-1, 4))
        Z = np.atleast_2d(np.asarray(Z, float))
        if Z.shape[0] == 1 and Q.shape[0] > 1:
            Z = np.repeat(Z, Q.shape[0], axis=0)
        if Z.shape != (Q.shape[0], self.dim):
            raise ValueError(f"Z must be ({Q.shape[0]}, {self.dim}), got {Z.shape}")
        if getattr(model, "kernel_ok", False):
            # per-state facet arrays filled inside the kernel (same values as facet_arrays)
            return mag_z_states_nb(Q, model.s_eci[k], model.o_eci[k], self._normals,
                                   self._areas0, self._ids, self._params0,
                                   float(model.offset[k]), np.ascontiguousarray(Z),
                                   self.kind_col, self.facet, self.logit)
        out = np.empty(Q.shape[0])
        with np.errstate(divide="ignore"):
            for i in range(Q.shape[0]):
                out[i] = apparent_magnitude(
                    self.shape_at(Z[i]), Q[i][None, None, :], model.s_eci[k:k + 1],
                    model.o_eci[k:k + 1], model.range_obs[k:k + 1], model.range_sun[k:k + 1],
                    sun_mag=model.sun_mag)[0, 0] + model.lit_offset[k]
        return out

    def partials(self, model, q, z, k):
        """Analytic ``(m, ∂m/∂δθ (3,), ∂m/∂z (D,))`` at attitude q (4,) and state z (D,), epoch k.

        ``∂m/∂z_d = ∂m/∂p_d · dp_d/dz_d`` with ∂m/∂ξ, ∂m/∂a, ∂m/∂m, ∂m/∂A of the shape with
        p(z); δθ is the body-frame error rotation of ``q = δq(δθ) ⊗ q̂``. NaN where m = +inf.
        Shapes whose facets are all Lambert / Cook–Torrance / Phong use the one-pass numba
        kernel :func:`partials_z_nb` (no shape copy); others :meth:`partials_numpy`. The two
        agree to rounding (tested to 1e-12).
        """
        if not self._kernel_partials:
            return self.partials_numpy(model, q, z, k)
        z = np.ascontiguousarray(z, dtype=float).reshape(self.dim)
        q = np.ascontiguousarray(q, dtype=float).reshape(4)
        m, dth, dz = partials_z_nb(q, model.s_eci[k], model.o_eci[k], self._normals,
                                   self._areas0, self._ids, self._params0,
                                   float(model.offset[k]), z, self.kind_col, self.facet,
                                   self.logit)
        return float(m), dth, dz

    def partials_numpy(self, model, q, z, k):
        """:meth:`partials` by :func:`lightcurve.photometry.magnitude_partials` (NumPy
        backend) on a copy of the shape with p(z) — any BRDF; the reference of the kernel."""
        z = np.asarray(z, float).reshape(self.dim)
        q = np.asarray(q, float).reshape(4)
        with np.errstate(divide="ignore", invalid="ignore"):
            mp = magnitude_partials(self.shape_at(z), q[None, :], model.s_eci[k:k + 1],
                                    model.o_eci[k:k + 1], model.range_obs[k:k + 1],
                                    model.range_sun[k:k + 1], sun_mag=model.sun_mag)
        cols = (mp.dm_dxi[0], mp.dm_da[0], mp.dm_dm[0], mp.dm_dA[0])
        dm_dp = np.array([cols[c][f] for c, f in zip(self.kind_col, self.facet)])
        m = float(mp.m[0]) + float(model.lit_offset[k])
        return m, np.asarray(mp.dm_dtheta[0], float), dm_dp * self.jacobian(z)

    @property
    def areas0(self) -> np.ndarray:
        """Nominal facet areas (F,), m² — the shape's, before any state is applied."""
        return self._areas0

    @property
    def params0(self) -> np.ndarray:
        """Nominal packed BRDF rows (F, 7) of the shape (:mod:`lightcurve.core.photometry`)."""
        return self._params0

    # -- metadata ---------------------------------------------------------------------------
    def describe(self) -> dict:
        """JSON-ready description of the states."""
        return {"model": "model3", "names": list(self.names),
                "facets": [int(i) for i in self.fidx], "kinds": list(self.kinds),
                "transform": {k: ("logit" if k in LOGIT_KINDS or (k == "m" and self.bounded_m)
                                  else "log") for k in self.kinds},
                "prior_frac": self.prior_frac, "p_nominal": self.p_nominal.tolist(),
                "prior_sigma_p": self.prior_sd_p.tolist(),
                "prior_sigma_z": self.prior_sd_z.tolist(),
                "process_noise_z2_per_s": self.process_noise, "held_fixed": list(self.held)}
