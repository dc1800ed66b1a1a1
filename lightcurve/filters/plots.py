"""Figures of a filter run for analysts (matplotlib, Agg; conventions of :mod:`lightcurve.report.style`).

* :func:`estimate_figure` / :func:`plot_estimate` — what the filter says about the object, one
  figure: the estimated 3-2-1 Euler angles and body rates with ±3σ bands (truth dashed when
  the lightcurve has one), the spin axis on the sky (right ascension / declination of
  ``ω_I = A(q̂)ᵀ ω̂`` with its final 3σ circle), the measured lightcurve with the lightcurve
  fitted from the posterior attitude, and the innovations ``ν = y − ŷ⁻`` (measured minus
  predicted before the update) with the ``±3√S`` band (NIS ``ν²/S`` < 9). Only when a truth
  exists: attitude and rate errors with the filter's ±3σ and the NEES with its χ²(6) band.
  Key numbers in the title. Time axes in UTC when the epoch is known.
* :func:`plot_particle_clouds` — particle error rotation vectors (deg, body axes) at the stored
  epochs, projected on the three coordinate planes (Bernard fig. 9.6-style).

Derived quantities and their first-order σ come from :mod:`lightcurve.filters.derived`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.atomic import atomic_path

__all__ = ["estimate_figure", "plot_estimate", "plot_particle_clouds"]

_NAMES = {"mekf": "MEKF", "ukf": "UKF", "bpf": "particle filter"}


def _fig():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _segments(y, jump=180.0):
    """Index slices of ``y`` without NaN and without jumps larger than ``jump`` (wrapped angles)."""
    y = np.asarray(y, float)
    ok = np.isfinite(y)
    cuts = np.zeros(len(y), bool)
    cuts[1:] = (~ok[1:]) | (~ok[:-1]) | (np.abs(np.diff(np.where(ok, y, 0.0))) > jump)
    starts = [0] + list(np.flatnonzero(cuts))
    out = []
    for a, b in zip(starts, starts[1:] + [len(y)]):
        idx = np.arange(a, b)
        idx = idx[ok[idx]]
        if idx.size:
            out.append(idx)
    return out


def _runs(t, y):
    """Index runs of finite ``y`` without time gaps (step > 1.5 × the median step)."""
    t = np.asarray(t, float)
    ok = np.isfinite(y)
    step = np.median(np.diff(t)) if len(t) > 1 else 1.0
    brk = np.zeros(len(t), bool)
    brk[1:] = np.diff(t) > 1.5 * step
    out, cur = [], []
    for i in range(len(t)):
        if not ok[i] or brk[i]:
            if cur:
                out.append(np.array(cur))
            cur = []
        if ok[i]:
            cur.append(i)
    if cur:
        out.append(np.array(cur))
    return out


def _time_axis(est, curve):
    """x values (UTC datetimes, or seconds) and the axis formatter for an estimate."""
    from ..report.style import utc_times

    epoch = getattr(est, "epoch_utc", None) or (curve.epoch_utc if curve is not None else None) \
        or (est.meta or {}).get("epoch_utc")
    t = np.asarray(est.t, float)
    if epoch:
        try:
            return utc_times(epoch, t), True, epoch
        except Exception:  # noqa: BLE001  a bad epoch text: fall back to seconds
            pass
    return t - t[0], False, None


def _measured(est, curve):
    """(mag, mag_sigma, site, site_names) of the estimate's epochs, or None."""
    if curve is not None and len(curve) == len(est):
        return (np.asarray(curve.mag, float), np.asarray(curve.mag_sigma, float),
                np.asarray(curve.site, int), list(curve.site_names))
    mag = getattr(est, "mag", None)
    if mag is not None:
        sig = getattr(est, "mag_sigma", None)
        site = getattr(est, "site", None)
        names = getattr(est, "site_names", None)
        return (np.asarray(mag, float),
                np.full(len(est), np.nan) if sig is None else np.asarray(sig, float),
                np.zeros(len(est), int) if site is None else np.asarray(site, int),
                list(names) if names is not None else ["site"])
    return None


def _fitted(est, curve):
    pred = getattr(est, "predicted_mag", None)   # model magnitude at the posterior attitude
    if pred is not None:
        pred = np.asarray(pred, float)
        return np.where(np.isfinite(pred), pred, np.nan)
    if curve is None or len(curve) != len(est):
        return None
    try:
        from .derived import fitted_magnitudes

        return fitted_magnitudes(est.q, curve, shape=(est.meta or {}).get("shape") or None)
    except Exception:  # noqa: BLE001  no shape available: the panel shows the prior prediction
        return None


def estimate_figure(est, curve=None, title=None):
    """The analyst figure of an :class:`~lightcurve.filters.result.Estimate` (module docstring).

    ``curve`` is the lightcurve the estimate was computed from (truth lines, sites); without it
    the estimate's ``source_file`` is tried, and the panels use what the estimate stores.
    ``title`` prefixes the key numbers. Returns the matplotlib figure.
    """
    plt = _fig()
    from matplotlib.gridspec import GridSpec

    from ..report.style import DPI, figsize, utc_axis
    from .derived import euler321_with_sigma, spin_axis

    if curve is None:  # the file it came from, when it can be found (truth lines, sites)
        from ..report.plot_any import source_lightcurve

        curve = source_lightcurve(est)
    x, is_utc, epoch = _time_axis(est, curve)
    attitude_known = (est.meta or {}).get("attitude") == "truth"  # reflection-only runs
    truth = est.att_error_deg is not None and not attitude_known
    has_nees = est.nees is not None and bool(np.any(np.isfinite(est.nees)))
    refl = _reflection_info(est, curve)
    tq = tw = None
    if curve is not None and curve.has_truth and len(curve) == len(est):
        tq, tw = curve.truth_q, curve.truth_omega_rad_s
    meas = _measured(est, curve)
    fitted = _fitted(est, curve)
    has_lc = meas is not None or fitted is not None
    # rows: angles, rates, [lightcurve + sky], innovations + (rate | sky), [truth errors]
    r_lc = 2 if has_lc else None
    r_nu = 3 if has_lc else 2
    r_refl = r_nu + 1 if refl else None
    r_err = r_nu + 1 + (1 if refl else 0)
    nrow = r_err + (1 if truth else 0)
    ratios = ([1, 1] + ([1.25] if has_lc else []) + [0.9 if has_lc else 1.1] + ([1.1] if refl else [])
              + ([1] if truth else []))
    fig = plt.figure(figsize=figsize(12, 2.3 * nrow + 0.9), dpi=DPI, layout="constrained")
    gs = GridSpec(nrow, 3, figure=fig, height_ratios=ratios)
    ax_all = []

    def axis(r, c, **kw):
        a = fig.add_subplot(gs[r, c], **kw)
        ax_all.append(a)
        return a

    # ---- row 0: Euler angles with 3σ, row 1: body rates with 3σ ---------------------------
    eul, eul_s = euler321_with_sigma(est.q, est.cov)
    teul = euler321_with_sigma(tq)[0] if tq is not None else None
    lab = ("φ (about z)", "θ (about y)", "ψ (about x)")
    for j in range(3):
        a = axis(0, j)
        for seg in _segments(eul[:, j]):
            a.fill_between(x[seg], eul[seg, j] - 3 * eul_s[seg, j], eul[seg, j] + 3 * eul_s[seg, j],
                           color="C0", alpha=0.2, lw=0)
            a.plot(x[seg], eul[seg, j], "C0", lw=1.2)
        if teul is not None:
            for seg in _segments(teul[:, j]):
                a.plot(x[seg], teul[seg, j], "k--", lw=0.8)
        a.set_ylabel(f"{lab[j]} [deg]")
        a.set_ylim(-185 if j != 1 else -95, 185 if j != 1 else 95)
    ax_all[0].set_title("attitude: 3-2-1 Euler angles, inertial→body", loc="left", fontsize=9)
    w = np.degrees(est.omega_rad_s)
    ws = np.degrees(est.omega_sigma_rad_s)
    for j, n in enumerate("xyz"):
        a = axis(1, j)
        a.fill_between(x, w[:, j] - 3 * ws[:, j], w[:, j] + 3 * ws[:, j], color="C1", alpha=0.25,
                       lw=0)
        a.plot(x, w[:, j], "C1", lw=1.2)
        if tw is not None:
            a.plot(x, np.degrees(tw[:, j]), "k--", lw=0.8)
        a.set_ylabel(f"ω_{n} [deg/s]")
    ax_all[3].set_title("body rates", loc="left", fontsize=9)
    handles = [plt.Line2D([], [], color="C0", label="estimate"),
               plt.Rectangle((0, 0), 1, 1, color="C0", alpha=0.2, label="±3σ")]
    if tq is not None:
        handles.append(plt.Line2D([], [], color="k", ls="--", lw=0.8, label="truth"))
    ax_all[0].legend(handles=handles, fontsize=7, loc="upper left", ncol=3)

    # ---- row 2: lightcurve (measured, fitted) + spin axis on the sky -----------------------
    nu = np.asarray(est.innovations, float)
    S = np.asarray(est.innovation_var, float)
    a = fig.add_subplot(gs[r_lc, 0:2]) if has_lc else None
    if a is not None:
        ax_all.append(a)
    if meas is not None:
        mag, sig, site, names = meas
        for k, name in enumerate(names):
            m = (site == k) & np.isfinite(mag)
            if np.any(m):
                a.errorbar(x[m], mag[m], yerr=np.where(np.isfinite(sig[m]), sig[m], 0), fmt=".",
                           ms=4, lw=0.6, color=f"C{k}",
                           label=f"measured ({name})" if len(names) > 1 else "measured (1σ)")
        if fitted is None:
            fitted = mag - nu
            flab = "predicted before each update"
        else:
            flab = "fitted (posterior attitude)"
        for i, seg in enumerate(_runs(est.t, fitted)):
            a.plot(x[seg], fitted[seg], ".-", color="C3", lw=0.9, ms=2,
                   label=flab if i == 0 else None)
        a.invert_yaxis()
        a.legend(fontsize=7, loc="best")
    elif fitted is not None:
        a.plot(x, fitted, "-", color="C3", lw=1.0, label="fitted (posterior attitude)")
        a.invert_yaxis()
        a.legend(fontsize=7)
    if a is not None:
        a.set_ylabel("apparent magnitude")
        a.set_title("lightcurve: measured and fitted", loc="left", fontsize=9)

    sp = spin_axis(est.q, est.omega_rad_s, est.cov)
    a = axis(r_lc if has_lc else r_nu, 2)
    ax_sky = a
    ra, dec = sp["ra_deg"], sp["dec_deg"]
    # keep the track continuous across RA = 0/360
    ra_c = np.degrees(np.unwrap(np.radians(ra)))
    ra_c += 360.0 * np.round((np.nanmedian(ra) - np.nanmedian(ra_c)) / 360.0)
    n = len(ra)
    sc = a.scatter(ra_c, dec, c=np.arange(n), cmap="viridis", s=8, zorder=3)
    a.plot(ra_c[-1], dec[-1], "o", mfc="none", mec="C3", ms=9, zorder=4, label="final estimate")
    s3 = 3 * sp["axis_sigma_deg"][-1]
    if np.isfinite(s3) and s3 < 90:
        ang = np.linspace(0, 2 * np.pi, 100)
        cd = max(np.cos(np.radians(dec[-1])), 0.05)
        a.plot(ra_c[-1] + s3 * np.cos(ang) / cd, dec[-1] + s3 * np.sin(ang), "C3-", lw=0.8,
               label=f"final 3σ ({s3:.2g}°)")
    if tq is not None:
        st = spin_axis(tq, tw)
        tra = np.degrees(np.unwrap(np.radians(st["ra_deg"])))
        tra += 360.0 * np.round((ra_c[-1] - tra[-1]) / 360.0)
        a.plot(tra, st["dec_deg"], "k--", lw=0.8, label="truth")
    gi = (est.meta or {}).get("global_init") or {}
    for j, m in enumerate(gi.get("modes", [])[1:], start=1):
        # the other attitude modes of a global initialisation: their final spin axes
        if "final_q" not in m:
            continue
        sm = spin_axis(np.asarray(m["final_q"]), np.radians(np.asarray(m["final_omega_deg_s"])))
        mra = float(sm["ra_deg"][0])
        mra += 360.0 * np.round((ra_c[-1] - mra) / 360.0)
        a.plot(mra, float(sm["dec_deg"][0]), "s", mfc="none", mec="C1", ms=8, zorder=4,
               label="other modes (global initialisation)" if j == 1 else None)
        a.annotate(f"{100 * m['weight']:.0f}%", (mra, float(sm["dec_deg"][0])), fontsize=7,
                   color="C1", xytext=(4, 4), textcoords="offset points")
    a.set_xlabel("right ascension [deg] (GCRS)")
    a.set_ylabel("declination [deg]")
    a.set_title("spin axis on the sky (colour: time)", loc="left", fontsize=9)
    a.invert_xaxis()  # sky convention: RA grows to the left
    a.legend(fontsize=7, loc="best")
    fig.colorbar(sc, ax=a, label="epoch index", shrink=0.8)

    # ---- row 3: innovations with the NIS band -------------------------------------------------
    a = fig.add_subplot(gs[r_nu, 0:2] if has_lc else gs[r_nu, 0])
    ax_all.append(a)
    band = 3 * np.sqrt(S)
    okb = np.isfinite(band)
    a.fill_between(x, np.where(okb, -band, np.nan), np.where(okb, band, np.nan), color="0.85",
                   lw=0, label="±3√S (NIS < 9)")
    okn = np.isfinite(nu)
    inside = okn & okb & (np.abs(nu) <= band)
    a.plot(x[inside], nu[inside], ".", color="C0", ms=4, label="innovation ν = y − ŷ⁻")
    if np.any(okn & ~inside):
        a.plot(x[okn & ~inside], nu[okn & ~inside], "x", color="C3", ms=5, label="outside ±3√S")
    a.axhline(0, color="0.4", lw=0.6)
    # y range from every innovation and the band after its first epochs: a prior band of tens
    # of magnitudes at the first epoch would flatten the rest (it runs off the panel instead)
    scale = np.concatenate([np.abs(nu[okn]), band[okb][min(3, okb.sum() - 1):] if okb.any()
                            else np.zeros(0)])
    if scale.size and np.isfinite(scale).any():
        top = 1.15 * float(np.nanmax(scale))
        if top > 0:
            a.set_ylim(-top, top)
    a.set_ylabel("innovation [mag]")
    a.legend(fontsize=7, loc="upper right", ncol=3)
    frac_in = inside.sum() / max(1, (okn & okb).sum())
    # rate magnitude and its 3σ on the free cell
    a = axis(r_nu, 2 if has_lc else 1)
    a.fill_between(x, sp["rate_deg_s"] - 3 * sp["rate_sigma_deg_s"],
                   sp["rate_deg_s"] + 3 * sp["rate_sigma_deg_s"], color="C2", alpha=0.25, lw=0,
                   label="±3σ")
    a.plot(x, sp["rate_deg_s"], "C2", lw=1.2, label="|ω| estimate")
    if tw is not None:
        a.plot(x, np.degrees(np.linalg.norm(tw, axis=1)), "k--", lw=0.8, label="truth")
    a.set_ylabel("spin rate |ω| [deg/s]")
    a.legend(fontsize=7, loc="best")

    # ---- reflection states (Bernard ch. 8): Model 3 parameters or per-site biases -----------
    non_time = {id(ax_sky)}
    if refl:
        a = fig.add_subplot(gs[r_refl, :])
        ax_all.append(a)
        if refl["kind"] == "model3":
            non_time.add(id(a))
            _model3_panel(a, refl)
        else:
            _bias_panel(a, x, refl)

    # ---- errors against the truth (when there is one and the attitude was estimated) --------
    if truth:
        _error_panel(axis(r_err, 0), x, est.att_error_deg, 3 * est.att_sigma_deg, "δθ",
                     "attitude error [deg]")
        ax_all[-1].set_title("errors against the truth", loc="left", fontsize=9)
        _error_panel(axis(r_err, 1), x, np.degrees(est.omega_error_rad_s),
                     np.degrees(3 * est.omega_sigma_rad_s), "δω", "rate error [deg/s]")
        if has_nees:
            a = axis(r_err, 2)
            from scipy.stats import chi2

            lo, hi = chi2.ppf([0.005, 0.995], 6)
            a.axhspan(lo, hi, color="0.88", lw=0, label="χ²(6) 99 % band")
            a.plot(x, est.nees, "C4", lw=1, label="NEES")
            a.set_yscale("log")
            from matplotlib.ticker import LogLocator, ScalarFormatter

            a.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 3.0)))
            f = ScalarFormatter()
            f.set_scientific(False)
            a.yaxis.set_major_formatter(f)
            a.set_ylabel("NEES (6 dof)")
            a.legend(fontsize=7, loc="upper right")

    # ---- axes, title -------------------------------------------------------------------------
    time_axes = [a for a in ax_all if id(a) not in non_time]
    last_row = max(a.get_subplotspec().rowspan.stop for a in time_axes)
    bottom = {id(a) for a in time_axes if a.get_subplotspec().rowspan.stop == last_row}
    for a in ax_all:
        if id(a) not in non_time:  # the sky and Model 3 panels have their own x axes
            if is_utc:
                utc_axis(a, label="UTC" if id(a) in bottom else "", offset=id(a) in bottom)
            elif id(a) in bottom:
                a.set_xlabel("t − t₀ [s]")
        a.grid(True, alpha=0.3)
    import textwrap

    head = _title(est, sp, eul, eul_s, frac_in, epoch)
    head = f"{title} · {head}" if title else head
    head = "\n".join(textwrap.fill(line, 140) for line in head.split("\n"))
    fig.suptitle(head, fontsize=10, ha="left", x=0.01)
    return fig


def _reflection_info(est, curve):
    """What the reflection panel draws, or None: Model 3 facet parameters at the last epoch
    (with the prior from the estimate's meta and the truth the lightcurve records), or the
    per-site magnitude biases of Models 1–2 over time."""
    if est.refl_p is not None and est.refl_names is not None:
        r = (est.meta or {}).get("reflection") or {}
        r = r.get("facet_states", r)
        p0 = r.get("p_nominal")
        s0 = r.get("prior_sigma_p")
        if p0 is None or s0 is None:
            return None
        truth = None
        rt = ((curve.attrs or {}).get("reflection_truth") if curve is not None else None)
        if rt:
            import json

            try:
                tv = json.loads(str(rt))
                truth = np.array([float(tv[n.split("[")[0]][int(n.split("[")[1][:-1])])
                                  for n in est.refl_names])
            except (ValueError, KeyError, IndexError, TypeError):
                truth = None
        return {"kind": "model3", "names": list(est.refl_names), "p": est.refl_p[-1],
                "sd": est.refl_p_sigma[-1], "p0": np.asarray(p0, float),
                "s0": np.asarray(s0, float), "truth": truth}
    if est.bias is not None and est.bias_sigma is not None:
        names = list(est.site_names) if getattr(est, "site_names", None) else \
            [f"site {k}" for k in range(est.bias.shape[1])]
        return {"kind": "bias", "b": est.bias, "sd": est.bias_sigma, "names": names}
    return None


def _model3_panel(a, r):
    """Model 3: each facet parameter's final estimate in units of its prior σ from the shape
    file's value, ±3 posterior σ; truth (when recorded) as red crosses."""
    k = np.arange(len(r["names"]))
    z = (r["p"] - r["p0"]) / r["s0"]
    a.axhspan(-3, 3, color="0.92", lw=0, label="prior ±3σ")
    a.errorbar(k, z, yerr=3 * r["sd"] / r["s0"], fmt="o", ms=3, color="C0", lw=1,
               label="final estimate ±3σ")
    if r["truth"] is not None:
        a.plot(k, (r["truth"] - r["p0"]) / r["s0"], "x", color="C3", ms=6, label="truth")
    a.axhline(0, color="0.4", lw=0.6)
    a.set_xticks(k, r["names"], fontsize=7, rotation=90 if len(k) > 16 else 0)
    a.set_xlim(-0.7, len(k) - 0.3)
    a.set_ylabel("(p − shape value) / prior σ")
    a.set_title("reflection parameters at the last epoch (Model 3), in prior σ from the shape "
                "file's values", loc="left", fontsize=9)
    a.legend(fontsize=7, loc="upper right", ncol=3)


def _bias_panel(a, x, r):
    """Models 1–2: per-site magnitude bias with its ±3σ band over time."""
    for j, name in enumerate(r["names"]):
        b, sd = r["b"][:, j], r["sd"][:, j]
        a.fill_between(x, b - 3 * sd, b + 3 * sd, color=f"C{j}", alpha=0.15, lw=0)
        a.plot(x, b, color=f"C{j}", lw=1.2, label=f"bias, {name} (±3σ shaded)")
    a.axhline(0, color="0.4", lw=0.6)
    a.set_ylabel("magnitude bias [mag]")
    a.set_title("reflection bias states (Bernard ch. 8, Models 1–2)", loc="left", fontsize=9)
    a.legend(fontsize=7, loc="upper right")


def _error_panel(a, x, err, s3, sym, ylabel):
    """Per-axis errors against the truth with the filter's ±3σ (dotted), y range from the
    last 80 % of the run (the first epochs' large errors would flatten the rest)."""
    for j, n in enumerate("xyz"):
        a.plot(x, err[:, j], color=f"C{j}", lw=1, label=f"{sym}_{n}")
        a.plot(x, s3[:, j], color=f"C{j}", lw=0.6, ls=":")
        a.plot(x, -s3[:, j], color=f"C{j}", lw=0.6, ls=":")
    a.plot([], [], color="0.3", ls=":", lw=0.6, label="±3σ")
    k = len(err) // 5
    lim = np.nanpercentile(np.abs(np.concatenate([err[k:].ravel(), s3[k:].ravel()])), 99) * 1.6
    if np.isfinite(lim) and lim > 0:
        a.set_ylim(-lim, lim)
    a.set_ylabel(ylabel)
    a.legend(fontsize=7, ncol=4, loc="upper right")


def _title(est, sp, eul, eul_s, frac_in, epoch):
    name = _NAMES.get(est.method, est.method)
    s = est.summary()
    if (est.meta or {}).get("attitude") == "truth":
        n_refl = len(est.refl_names) if est.refl_names is not None else 0
        return (f"{name}: {len(est)} epochs"
                + (f" from {str(epoch).replace('T', ' ').rstrip('Z')} UTC" if epoch else "")
                + "; attitude and rate HELD AT THE TRUTH (reflection-only run, Bernard §10.7)"
                + (f"; {n_refl} reflection parameters estimated" if n_refl else "")
                + f"\n{100 * frac_in:.0f} % of innovations inside ±3√S (expected 99.7 %)")
    s3 = 3 * np.linalg.norm(est.att_sigma_deg[-1])
    line1 = (f"{name}: {len(est)} epochs"
             + (f" from {str(epoch).replace('T', ' ').rstrip('Z')} UTC" if epoch else "")
             + f"; final attitude (φ, θ, ψ) = ({eul[-1, 0]:.1f}°, {eul[-1, 1]:.1f}°, "
             f"{eul[-1, 2]:.1f}°), 3σ (RSS) {s3:.2g}°; spin {sp['rate_deg_s'][-1]:.3g} ± "
             f"{3 * sp['rate_sigma_deg_s'][-1]:.2g} °/s about RA {sp['ra_deg'][-1]:.1f}°, "
             f"Dec {sp['dec_deg'][-1]:.1f}°")
    line2 = f"{100 * frac_in:.0f} % of innovations inside ±3√S (expected 99.7 %)"
    if "final_att_error_rss_deg" in s:
        line2 += (f"; truth: final attitude error {s['final_att_error_rss_deg']:.2g}°, rate "
                  f"error {s['final_omega_error_rss_deg_s']:.2g} °/s, "
                  + ("inside 3σ" if s["inside_3sigma"] else "OUTSIDE 3σ"))
    if est.diverged:
        line2 += f"; DIVERGED ({est.divergence_reason})"
    cons = s.get("consistency") or {}
    if cons.get("flags"):
        why = []
        if cons.get("nis_mean") is not None:
            why.append(f"NIS mean {cons['nis_mean']:.2g}, 99 % band "
                       f"{cons['nis_band'][0]:.2g}–{cons['nis_band'][1]:.2g}")
        if cons.get("residual_median_sq") is not None:
            why.append(f"median squared residual {cons['residual_median_sq']:.2g}σ², 99 % band "
                       f"{cons['residual_median_band'][0]:.2g}–"
                       f"{cons['residual_median_band'][1]:.2g}")
        line2 += f"; FLAGGED: {', '.join(cons['flags'])}" + (f" ({'; '.join(why)})" if why else "")
    gi = (est.meta or {}).get("global_init")
    if gi:
        line2 += "\nglobal initialisation: " + (
            f"AMBIGUOUS, {gi['n_modes']} attitude modes (this plot: the heaviest, "
            f"{100 * gi['modes'][0]['weight']:.0f} %)" if gi["ambiguous"] else
            f"one attitude mode ({100 * gi['modes'][0]['weight']:.0f} % of the posterior)")
    return line1 + "\n" + line2


def plot_estimate(est, path, title=None, *, curve=None):
    """Write :func:`estimate_figure` of ``est`` to ``path`` (PNG, atomic); returns the path."""
    plt = _fig()
    from ..report.style import DPI

    fig = estimate_figure(est, curve=curve, title=title)
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=DPI, format="png")
    plt.close(fig)
    return path


def plot_particle_clouds(est, path, title=None):
    """Write the particle-cloud figure (error rotation vectors, deg) of a BPF estimate."""
    if not est.clouds:
        raise ValueError("the estimate has no particle clouds (run the BPF with keep_clouds=… "
                         "on a lightcurve with truth)")
    plt = _fig()
    from ..report.style import DPI, figsize

    ks = sorted(est.clouds)
    fig, ax = plt.subplots(len(ks), 3, figsize=figsize(11, 3.4 * len(ks)), squeeze=False)
    pairs = ((0, 1), (0, 2), (1, 2))
    lab = ("δθx", "δθy", "δθz")
    for r, k in enumerate(ks):
        c = est.clouds[k]
        for j, (a_, b_) in enumerate(pairs):
            a = ax[r, j]
            a.plot(c[:, a_], c[:, b_], ".", ms=1, alpha=0.4)
            a.plot([0], [0], "r+", ms=10, label="truth")
            a.set_xlabel(f"{lab[a_]} [deg]")
            a.set_ylabel(f"{lab[b_]} [deg]")
            a.set_title(f"t = {est.t[k] - est.t[0]:.0f} s", fontsize=9)
    ax[0, 0].legend(fontsize=7)
    fig.suptitle(title or "particle error clouds (truth at the red cross)")
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=DPI, format="png")
    plt.close(fig)
    return path
