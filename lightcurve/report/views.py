"""Python conveniences for notebooks and scripts: short reprs, HTML views, tables, plots.

Mixed into the package's result objects (:class:`~lightcurve.io.lightcurve_h5.Lightcurve`,
:class:`~lightcurve.filters.result.Estimate`, :class:`~lightcurve.diagnosis.diagnose.Diagnosis`)
and used by :class:`StudySummary` (a ``dict`` — the ``summary.json`` of ``compare`` — with the
same views):

* ``repr(x)`` — one line with the key numbers (never the arrays);
* ``x._repr_html_()`` — the Jupyter view: a small table of the key numbers;
* ``x.to_pandas()`` — a ``pandas.DataFrame`` (one row per epoch, indexed by UTC time when the
  epoch is known; one row per cell or candidate for summaries); ``x.to_xarray()`` for the
  per-epoch objects (dimension ``time``, plus ``axis`` for vectors);
* ``x.plot(path=None)`` — the package's figure of it (a matplotlib figure; a PNG when ``path``).

pandas and xarray are optional: ``pip install "lightcurve[pandas]"``; without them
``to_pandas`` / ``to_xarray`` raise :class:`ImportError` saying so. Units are in the column
names (``_deg``, ``_deg_s``, ``_mag``, ``_s``, ``_km``).
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np

__all__ = ["LightcurveViews", "EstimateViews", "DiagnosisViews", "StudySummary",
           "read_study_summary", "require_pandas", "require_xarray"]


def require_pandas():
    """Import pandas or raise an ImportError that says how to install it."""
    try:
        import pandas as pd
    except ImportError:
        raise ImportError("to_pandas() needs pandas, an optional dependency of lightcurve: "
                          "pip install 'lightcurve[pandas]'  (or: pip install pandas)") from None
    return pd


def require_xarray():
    """Import xarray or raise an ImportError that says how to install it."""
    try:
        import xarray as xr
    except ImportError:
        raise ImportError("to_xarray() needs xarray, an optional dependency of lightcurve: "
                          "pip install 'lightcurve[pandas]'  (or: pip install xarray)") from None
    return xr


def _html_table(rows, title=None):
    body = "".join(f"<tr><th style='text-align:left'>{html.escape(str(k))}</th>"
                   f"<td style='text-align:left'>{html.escape(str(v))}</td></tr>"
                   for k, v in rows)
    cap = f"<caption style='text-align:left'><b>{html.escape(title)}</b></caption>" if title else ""
    return f"<table>{cap}{body}</table>"


def _utc_index(epoch, t):
    """A pandas DatetimeIndex (UTC) for ``epoch + t`` or None when the epoch is unusable."""
    pd = require_pandas()
    if not epoch:
        return None
    try:
        from .style import utc_times

        return pd.DatetimeIndex(utc_times(epoch, t), name="utc").tz_localize("UTC")
    except Exception:  # noqa: BLE001  a bad epoch: index by seconds instead
        return None


def _span_text(epoch, t):
    if not epoch or len(t) == 0:
        return ""
    try:
        from .style import utc_times

        x = utc_times(epoch, [t[0], t[-1]])
        a, b = str(x[0])[:19].replace("T", " "), str(x[1])[:19].replace("T", " ")
        if a[:10] == b[:10]:
            b = b[11:]
        return f"{a} – {b} UTC"
    except Exception:  # noqa: BLE001
        return f"epoch {epoch}"


# ------------------------------------------------------------------------------------------
class LightcurveViews:
    """Views of a :class:`~lightcurve.io.lightcurve_h5.Lightcurve` (module docstring)."""

    def _key_numbers(self):
        fin = np.isfinite(self.mag)
        rows = [("measurements", f"{int(fin.sum())} of {len(self)}"),
                ("sites", ", ".join(map(str, self.site_names))),
                ("span", _span_text(self.epoch_utc, self.t) or f"epoch {self.epoch_utc}"),
                ("magnitudes", f"{np.nanmin(self.mag):.2f} to {np.nanmax(self.mag):.2f}"
                 if fin.any() else "none"),
                ("median 1σ noise", f"{np.nanmedian(self.mag_sigma):.3f} mag" if len(self) else "–"),
                ("shape", (self.attrs or {}).get("shape", "") or "–"),
                ("truth", "yes (simulated)" if self.has_truth else "no")]
        if self.lit_fraction is not None and len(self):
            rows.append(("in the Earth's shadow", f"{np.mean(self.lit_fraction < 1) * 100:.0f} % of epochs"
                         + (" (computed as if sunlit)"
                            if int((self.attrs or {}).get("ignore_eclipse", 0)) else "")))
        return rows

    def __repr__(self):
        fin = np.isfinite(self.mag)
        span = _span_text(self.epoch_utc, self.t)
        mags = (f", {np.nanmin(self.mag):.1f}–{np.nanmax(self.mag):.1f} mag" if fin.any() else "")
        return (f"<Lightcurve {int(fin.sum())} magnitudes from {len(self.site_names)} site(s) "
                f"({', '.join(map(str, self.site_names))}), {span or self.epoch_utc}{mags}"
                f"{', with truth' if self.has_truth else ''}>")

    __str__ = __repr__

    def _repr_html_(self):
        return _html_table(self._key_numbers(), "Lightcurve")

    @property
    def utc(self):
        """Measurement times as numpy ``datetime64[us]`` (UTC)."""
        from .style import utc_times

        return utc_times(self.epoch_utc, self.t)

    def _columns(self):
        d = {"t_s": np.asarray(self.t, float),
             "site": [self.site_names[int(k)] for k in self.site],
             "mag": self.mag, "mag_sigma": self.mag_sigma,
             "range_km": self.range_obs_m / 1e3,
             "phase_angle_deg": np.degrees(self.phase_angle_rad)}
        if self.elevation_rad is not None:
            d["elevation_deg"] = np.degrees(self.elevation_rad)
        if self.lit_fraction is not None:
            d["lit_fraction"] = self.lit_fraction
        if self.truth_mag is not None:
            d["truth_mag"] = self.truth_mag
        if self.truth_q is not None:
            for j in range(4):
                d[f"truth_q{j + 1}"] = self.truth_q[:, j]
        if self.truth_omega_rad_s is not None:
            for j, n in enumerate("xyz"):
                d[f"truth_omega_{n}_deg_s"] = np.degrees(self.truth_omega_rad_s[:, j])
        return d

    def to_pandas(self):
        """One row per measurement, indexed by UTC time: ``t_s``, ``site``, ``mag``,
        ``mag_sigma``, ``range_km``, ``phase_angle_deg``, ``elevation_deg``, ``lit_fraction``
        and, for simulated data, ``truth_mag``, ``truth_q1…q4``, ``truth_omega_*_deg_s``."""
        pd = require_pandas()
        return pd.DataFrame(self._columns(), index=_utc_index(self.epoch_utc, self.t))

    def to_xarray(self):
        """An ``xarray.Dataset`` with dimension ``time`` (UTC) and the columns of to_pandas."""
        xr = require_xarray()
        return xr.Dataset.from_dataframe(self.to_pandas().rename_axis("time")).assign_attrs(
            epoch_utc=self.epoch_utc, **{k: v for k, v in (self.attrs or {}).items()
                                         if isinstance(v, (str, int, float))})

    def plot(self, path=None, title=None):
        """The lightcurve figure (:func:`lightcurve.report.plots.plot_lightcurve`)."""
        from .plots import plot_lightcurve

        return plot_lightcurve(self, path, title=title)


# ------------------------------------------------------------------------------------------
class EstimateViews:
    """Views of a :class:`~lightcurve.filters.result.Estimate` (module docstring)."""

    _NAMES = {"mekf": "MEKF", "ukf": "UKF", "bpf": "particle filter"}

    @property
    def _epoch(self):
        return getattr(self, "epoch_utc", None) or (self.meta or {}).get("epoch_utc")

    def _spin(self):
        from ..filters.derived import spin_axis

        return spin_axis(self.q[-1:], self.omega_rad_s[-1:], self.cov[-1:])

    def _key_numbers(self):
        sp = self._spin()
        s = self.summary()
        rows = [("filter", self._NAMES.get(self.method, self.method)),
                ("epochs", f"{len(self)}" + (f", {_span_text(self._epoch, self.t)}"
                                              if self._epoch else "")),
                ("final 3σ attitude (x, y, z)",
                 ", ".join(f"{v:.3g}°" for v in 3 * self.att_sigma_deg[-1])),
                ("final spin", f"{sp['rate_deg_s'][0]:.4g} ± {3 * sp['rate_sigma_deg_s'][0]:.2g} °/s "
                 f"about RA {sp['ra_deg'][0]:.1f}°, Dec {sp['dec_deg'][0]:.1f}° "
                 f"(± {3 * sp['axis_sigma_deg'][0]:.2g}°, 3σ)"),
                ("runtime", f"{self.runtime_s:.3g} s")]
        if "final_att_error_rss_deg" in s:
            rows.append(("truth: final errors",
                         f"{s['final_att_error_rss_deg']:.3g}° attitude, "
                         f"{s['final_omega_error_rss_deg_s']:.3g} °/s rate, "
                         + ("inside 3σ" if s["inside_3sigma"] else "OUTSIDE 3σ")))
        rows.append(("status", f"DIVERGED: {self.divergence_reason}" if self.diverged else "ok"))
        return rows

    def __repr__(self):
        sp = self._spin()
        s = self.summary()
        txt = (f"<Estimate {self._NAMES.get(self.method, self.method)}, {len(self)} epochs; final "
               f"3σ {3 * np.linalg.norm(self.att_sigma_deg[-1]):.2g}° (RSS); spin "
               f"{sp['rate_deg_s'][0]:.3g}°/s about RA {sp['ra_deg'][0]:.1f}° Dec "
               f"{sp['dec_deg'][0]:.1f}°")
        if "final_att_error_rss_deg" in s:
            txt += (f"; truth error {s['final_att_error_rss_deg']:.2g}° "
                    + ("(inside 3σ)" if s["inside_3sigma"] else "(OUTSIDE 3σ)"))
        if self.diverged:
            txt += "; DIVERGED"
        return txt + ">"

    __str__ = __repr__

    def _repr_html_(self):
        return _html_table(self._key_numbers(), "Estimate")

    def _columns(self):
        from ..filters.derived import euler321_with_sigma, spin_axis

        eul, es = euler321_with_sigma(self.q, self.cov)
        sp = spin_axis(self.q, self.omega_rad_s, self.cov)
        d = {"t_s": np.asarray(self.t, float)}
        for j in range(4):
            d[f"q{j + 1}"] = self.q[:, j]
        for j, n in enumerate(("phi", "theta", "psi")):
            d[f"{n}_deg"] = eul[:, j]
            d[f"{n}_sigma_deg"] = es[:, j]
        for j, n in enumerate("xyz"):
            d[f"omega_{n}_deg_s"] = np.degrees(self.omega_rad_s[:, j])
        for j, n in enumerate("xyz"):
            d[f"att_sigma_{n}_deg"] = self.att_sigma_deg[:, j]
        for j, n in enumerate("xyz"):
            d[f"omega_sigma_{n}_deg_s"] = np.degrees(self.omega_sigma_rad_s[:, j])
        d.update({"spin_ra_deg": sp["ra_deg"], "spin_dec_deg": sp["dec_deg"],
                  "spin_rate_deg_s": sp["rate_deg_s"], "spin_axis_sigma_deg": sp["axis_sigma_deg"],
                  "innovation_mag": self.innovations,
                  "innovation_sigma_mag": np.sqrt(self.innovation_var)})
        with np.errstate(invalid="ignore", divide="ignore"):
            d["nis"] = self.innovations ** 2 / self.innovation_var
        if np.any(np.isfinite(self.n_eff)):
            d["n_eff"] = self.n_eff
        d["flags"] = self.flags
        if self.att_error_deg is not None:
            for j, n in enumerate("xyz"):
                d[f"att_error_{n}_deg"] = self.att_error_deg[:, j]
            for j, n in enumerate("xyz"):
                d[f"omega_error_{n}_deg_s"] = np.degrees(self.omega_error_rad_s[:, j])
            if self.nees is not None:
                d["nees"] = self.nees
        return d

    def to_pandas(self):
        """One row per epoch, indexed by UTC time when the epoch is known: ``t_s``, ``q1…q4``,
        Euler angles ``phi/theta/psi_deg`` and their ``_sigma_deg`` (first order),
        ``omega_*_deg_s``, 1σ bounds, spin axis (``spin_ra_deg``, ``spin_dec_deg``,
        ``spin_rate_deg_s``), ``innovation_mag``, ``innovation_sigma_mag``, ``nis``, ``flags``
        and, with a truth, ``att_error_*_deg``, ``omega_error_*_deg_s``, ``nees``."""
        pd = require_pandas()
        return pd.DataFrame(self._columns(), index=_utc_index(self._epoch, self.t))

    def to_xarray(self):
        """An ``xarray.Dataset`` with dimension ``time`` (the columns of to_pandas) plus the
        covariance ``cov`` (time × state × state, state = δθx δθy δθz rad, δωx δωy δωz rad/s)."""
        xr = require_xarray()
        ds = xr.Dataset.from_dataframe(self.to_pandas().rename_axis("time"))
        state = ["dtheta_x", "dtheta_y", "dtheta_z", "domega_x", "domega_y", "domega_z"]
        ds["cov"] = (("time", "state", "state2"), np.asarray(self.cov))
        ds = ds.assign_coords(state=state, state2=state)
        return ds.assign_attrs(method=self.method, diverged=int(self.diverged),
                               **({"epoch_utc": self._epoch} if self._epoch else {}))

    def plot(self, path=None, curve=None, title=None):
        """The analyst figure (:func:`lightcurve.filters.plots.estimate_figure`); ``curve`` is
        the lightcurve it came from (measured and fitted magnitudes, UTC axis)."""
        from ..filters.plots import estimate_figure, plot_estimate

        if path is not None:
            return plot_estimate(self, path, title=title, curve=curve)
        return estimate_figure(self, curve=curve, title=title)


# ------------------------------------------------------------------------------------------
class DiagnosisViews:
    """Views of a :class:`~lightcurve.diagnosis.diagnose.Diagnosis` (module docstring)."""

    def __repr__(self):
        js = self.summary()
        return (f"<Diagnosis of {js.get('recording', '?')}: {js['verdict']}; baseline χ²/dof "
                f"{js['baseline']['chi2_dof']:.3g}; chosen: {', '.join(js['chosen']) or 'none'}; "
                f"final χ²/dof {js['final']['chi2_dof']:.3g}>")

    __str__ = __repr__

    def _repr_html_(self):
        js = self.summary()
        rows = [("recording", js.get("recording", "")), ("verdict", js["verdict"]),
                ("baseline χ²/dof", f"{js['baseline']['chi2_dof']:.3g}"),
                ("chosen effects", ", ".join(js["chosen"]) or "none"),
                ("final χ²/dof", f"{js['final']['chi2_dof']:.3g}")]
        if js.get("explanation"):
            rows.append(("explanation", js["explanation"] if isinstance(js["explanation"], str)
                         else " ".join(map(str, js["explanation"]))))
        return _html_table(rows, "Diagnosis")

    def to_pandas(self, table="candidates"):
        """A table of the diagnosis: ``"candidates"`` (one row per physics effect scored:
        applicability, ΔBIC, signature correlation …) or ``"segments"`` (the time spans whose
        residuals are not white noise)."""
        pd = require_pandas()
        js = self.summary()
        if table not in ("candidates", "segments"):
            raise ValueError(f"table {table!r}; allowed: candidates, segments")
        rows = js[table]
        flat = [{k: (json.dumps(v) if isinstance(v, (dict, list)) else v) for k, v in r.items()}
                for r in rows]
        df = pd.DataFrame(flat)
        if table == "candidates" and "name" in df:
            df = df.set_index("name")
        return df


# ------------------------------------------------------------------------------------------
class StudySummary(dict):
    """The ``summary.json`` of a Monte Carlo study (``lightcurve compare``) with views.

    A plain ``dict`` (JSON content unchanged) plus ``to_pandas()`` (one row per cell: the grid
    keys, runs, failures, the six outside-3σ counts, colour, median / p95 errors, runtime),
    ``verdict()`` (which filter is better), a short ``repr``, ``_repr_html_`` and ``plot()``.
    """

    def to_pandas(self):
        """One row per cell (grid keys as columns; ``outside_3sigma`` split into six
        ``outside_3sigma_{theta,omega}_{x,y,z}`` columns)."""
        pd = require_pandas()
        rows = []
        for c in self["cells"]:
            r = {k: v for k, v in c.items() if k != "outside_3sigma"
                 and not isinstance(v, (dict, list))}
            for j, n in enumerate(("theta_x", "theta_y", "theta_z", "omega_x", "omega_y",
                                   "omega_z")):
                r[f"outside_3sigma_{n}"] = c["outside_3sigma"][j]
            rows.append(r)
        return pd.DataFrame(rows)

    def verdict(self):
        """``(level, text)``: which filter is better (:func:`lightcurve.report.verdicts.study_verdict`)."""
        from .verdicts import study_verdict

        return study_verdict(self["cells"])

    def __repr__(self):
        cells = self["cells"]
        cnt = {c: sum(1 for x in cells if x["color"] == c) for c in ("green", "yellow", "red")}
        return (f"<StudySummary {self['study']}: {len(cells)} cells × {self['runs_per_cell']} "
                f"runs; {cnt['green']} green, {cnt['yellow']} yellow, {cnt['red']} red>")

    __str__ = __repr__

    def _repr_html_(self):
        from .style import verdict_html

        level, text = self.verdict()
        try:
            table = self.to_pandas().to_html(index=False, float_format=lambda v: f"{v:.4g}")
        except ImportError:
            table = ""
        return f"<b>Study {html.escape(self['study'])}</b>{verdict_html(level, text)}{table}"

    def plot(self, path=None):
        """Median / p95 final error per cell (:func:`lightcurve.report.plot_any.study_summary_figure`);
        a PNG when ``path`` is given (returns the path), else the figure."""
        from .plot_any import _save, study_summary_figure

        fig = study_summary_figure(self)
        return _save(fig, path) if path is not None else fig


def read_study_summary(path) -> StudySummary:
    """Read a study's ``summary.json`` (file or its folder) as a :class:`StudySummary`."""
    from ..errors import InputError

    p = Path(path)
    if p.is_dir():
        p = p / "summary.json"
    from ..io.safe_open import read_json

    doc = read_json(p, what="study summary")
    if not isinstance(doc, dict) or "cells" not in doc or "study" not in doc:
        raise InputError("not a study summary.json (no 'cells' / 'study')", file=p)
    return StudySummary(doc)
