"""``lightcurve plot FILE``: a figure of any file the package writes, chosen by its content.

=====================================  =============================================================
file                                   figure
=====================================  =============================================================
lightcurve HDF5 (simulate, import)     :func:`lightcurve.report.plots.plot_lightcurve`
estimate HDF5 (invert, demo)           :func:`lightcurve.filters.plots.plot_estimate` (with the
                                       source lightcurve when it can be found)
CSS recording HDF5 (css simulate)      :func:`plot_css_recording`: sensor outputs, Sun-direction
                                       error of the stored estimate, rates
CSS estimate CSV (css estimate)        :func:`plot_css_estimate_csv`: estimated Sun direction
invert ``summary.json``                :func:`plot_invert_summary`: final errors and 3σ per file
compare ``summary.json``               :func:`plot_study_summary`: median / p95 final error per cell
fit-reflection ``*.reflection.json``   :func:`plot_reflection_summary`: posterior vs prior intervals
=====================================  =============================================================

Reports that are already figures (``report.html``, ``*.png``) are refused with a message saying
so; a file of unknown kind is an :class:`~lightcurve.errors.InputError` naming what is accepted.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_path
from ..io.safe_open import read_json

__all__ = ["plot_file", "file_kind", "plot_css_recording", "plot_css_estimate_csv",
           "plot_invert_summary", "plot_study_summary", "study_summary_figure", "plot_reflection_summary", "KINDS"]

KINDS = ("lightcurve", "estimate", "css-recording", "css-estimate-csv", "invert-summary",
         "study-summary", "reflection-summary")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def file_kind(path) -> str:
    """The kind of a file written by the package (one of :data:`KINDS`); InputError otherwise."""
    from ..io.safe_open import HDF5_MAX_BYTES, open_hdf5, open_regular

    path = Path(path)
    # a regular file only (no FIFO or device), its first bytes read from the checked descriptor
    with open_regular(path, max_bytes=HDF5_MAX_BYTES, what="file") as fh:
        head = fh.read(8)
    if head.startswith(b"\x89HDF"):
        with open_hdf5(path) as h:  # external links/storage, VDS refused before any lookup
            fmt = h.attrs.get("format", "")
            fmt = fmt.decode() if isinstance(fmt, bytes) else str(fmt)
            if fmt == "lightcurve-estimate":
                return "estimate"
            if fmt == "lightcurve-css":
                return "css-recording"
            if "mag" in h and "t" in h:
                return "lightcurve"
        raise InputError("HDF5 file of unknown kind", file=path, field="format",
                         allowed="a lightcurve, estimate or CSS recording file")
    if head.startswith(b"\x89PNG") or path.suffix.lower() in (".png", ".html", ".htm"):
        raise InputError("already a figure or report: open it in an image viewer or browser",
                         file=path)
    if path.suffix.lower() == ".json":
        doc = read_json(path)
        if isinstance(doc, dict) and "cells" in doc and "study" in doc:
            return "study-summary"
        if isinstance(doc, dict) and "parameters" in doc and "diagnostics" in doc:
            return "reflection-summary"
        if isinstance(doc, dict) and doc and all(isinstance(v, dict) and ("method" in v or "error" in v)
                                                 for v in doc.values()):
            return "invert-summary"
        raise InputError("JSON file of unknown kind (its command writes the figures itself: "
                         "see the PNG/HTML next to it)", file=path,
                         allowed="an invert or compare summary.json, a *.reflection.json")
    if path.suffix.lower() == ".csv":
        with open_regular(path, max_bytes=1 << 40, what="CSV file") as fh:
            first = fh.readline(4096).decode("utf-8", "replace").splitlines()[:1]
        if first and first[0].startswith("t_s,s_hat_x"):
            return "css-estimate-csv"
        raise InputError("CSV of unknown kind (a recording CSV is imported with 'lightcurve "
                         "import' or read with --scenario by 'diagnose')", file=path,
                         allowed="a 'css estimate' CSV (t_s,s_hat_x,s_hat_y,s_hat_z)")
    raise InputError("unknown file kind", file=path,
                     allowed="lightcurve/estimate/CSS HDF5, summary JSON, 'css estimate' CSV")


def plot_file(path, output=None) -> Path:
    """Draw the figure of ``path`` (kind from :func:`file_kind`) into ``output`` (PNG).

    ``output`` defaults to ``path`` with the suffix ``.png``. Returns the PNG path.
    """
    path = Path(path)
    kind = file_kind(path)
    out = Path(output) if output else path.with_suffix(".png")
    if out.resolve() == path.resolve():
        raise InputError("the figure would overwrite its input", file=path, field="--output")
    if kind == "lightcurve":
        from ..io.lightcurve_h5 import read_lightcurve
        from .plots import plot_lightcurve

        plot_lightcurve(read_lightcurve(path), out, title=path.name)
        return out
    if kind == "estimate":
        from ..filters.plots import plot_estimate
        from ..filters.result import read_estimate

        est = read_estimate(path)
        plot_estimate(est, out, curve=source_lightcurve(est, path))
        return out
    fn = {"css-recording": plot_css_recording, "css-estimate-csv": plot_css_estimate_csv,
          "invert-summary": plot_invert_summary, "study-summary": plot_study_summary,
          "reflection-summary": plot_reflection_summary}[kind]
    return fn(path, out)


def source_lightcurve(est, est_path=None):
    """The lightcurve an estimate was computed from, when its file can be found (else None).

    Looks at the estimate's ``source_file`` (absolute, or relative to the estimate file's
    folder or the current folder) and checks that the number of epochs matches.
    """
    from ..io.lightcurve_h5 import read_lightcurve

    src = getattr(est, "source_file", None) or (est.meta or {}).get("source_file")
    cands = []
    if src:
        cands.append(Path(src))
        if est_path is not None and not Path(src).is_absolute():
            cands.insert(0, Path(est_path).parent / Path(src).name)
    if est_path is not None:  # 'demo' / 'invert' naming: STEM.METHOD.h5 next to STEM.h5
        p = Path(est_path)
        suffix = f".{est.method}.h5"
        if p.name.endswith(suffix):
            cands.append(p.with_name(p.name[: -len(suffix)] + ".h5"))
    for c in cands:
        if c.is_file():
            try:
                lc = read_lightcurve(c)
            except InputError:
                continue
            if len(lc) == len(est) and np.allclose(lc.t, est.t):
                return lc
    return None


def _save(fig, out):
    plt = _plt()
    from .style import DPI

    out = Path(out)
    with atomic_path(out, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=DPI, format="png")
    plt.close(fig)
    return out


def plot_css_recording(path, out) -> Path:
    """CSS recording: outputs of every sensor, Sun-direction error of the stored estimate
    (deg, against the truth; eclipse shaded) and the gyro rates, versus UTC."""
    from ..css.recording import read_css_recording
    from ..io.safe_open import open_hdf5, read_dataset
    from .style import figsize, utc_axis, utc_times

    rec = read_css_recording(path)
    with open_hdf5(path) as h:
        s_hat = (np.asarray(read_dataset(h, "estimate/s_hat", max_elements=2 * 10**8, file=path))
                 if "estimate/s_hat" in h else None)
    plt = _plt()
    truth = rec["truth"] or {}
    has_err = s_hat is not None and "s_body" in truth
    rows = 1 + int(has_err) + int(rec["gyro"] is not None)
    fig, ax = plt.subplots(rows, 1, figsize=figsize(11, 2.6 * rows + 0.8), sharex=True,
                           squeeze=False, layout="constrained")
    ax = ax[:, 0]
    try:
        x = utc_times(rec["epoch_utc"], rec["t"])
        utc = True
    except Exception:  # noqa: BLE001
        x, utc = rec["t"], False
    lit = truth.get("lit")

    def shade(a):
        if lit is None:
            return
        from .plots import _spans

        for t0, t1 in _spans(rec["t"], lit < 0.999):
            a.axvspan(*(utc_times(rec["epoch_utc"], [t0, t1]) if utc else (t0, t1)),
                      color="0.9", lw=0, zorder=0)
        a.plot([], [], "s", color="0.9", label="eclipse")

    y = rec["y"]
    for j in range(y.shape[1]):
        ax[0].plot(x, y[:, j], lw=0.7, label=f"CSS {j}")
    shade(ax[0])
    ax[0].set_ylabel("output (full scale 1)")
    ax[0].legend(fontsize=6, ncol=min(8, y.shape[1] + 1), loc="upper right")
    ax[0].set_title(f"{y.shape[1]} coarse sun sensors", loc="left", fontsize=9)
    r = 1
    title = f"{Path(path).name}: {len(rec['t'])} samples"
    if has_err:
        s = truth["s_body"]
        c = np.sum(s_hat * s, axis=1) / (np.linalg.norm(s_hat, axis=1) * np.linalg.norm(s, axis=1))
        err = np.degrees(np.arccos(np.clip(c, -1, 1)))
        ax[r].plot(x, err, "C3", lw=0.8, label="stored estimate vs truth")
        for lim in (15.0, 30.0):
            ax[r].axhline(lim, color="0.4", lw=0.7, ls="--")
        ax[r].plot([], [], color="0.4", ls="--", lw=0.7, label="15° and 30° thresholds")
        shade(ax[r])
        ax[r].set_ylabel("Sun-direction error [deg]")
        ax[r].set_yscale("log")
        ax[r].legend(fontsize=7, loc="upper right")
        sun = lit > 0.999 if lit is not None else np.ones(len(err), bool)
        if np.any(sun):
            title += f"; sunlit error median {np.median(err[sun]):.2f}°, 99th pct {np.percentile(err[sun], 99):.2f}°"
        r += 1
    if rec["gyro"] is not None:
        for j, n in enumerate("xyz"):
            ax[r].plot(x, np.degrees(rec["gyro"][:, j]), lw=0.8, label=f"ω_{n} (gyro)")
        ax[r].set_ylabel("rate [deg/s]")
        ax[r].legend(fontsize=7, ncol=3, loc="upper right")
    for a in ax:
        a.grid(True, alpha=0.3)
    if utc:
        utc_axis(ax[-1])
    else:
        ax[-1].set_xlabel("t [s]")
    fig.suptitle(title, fontsize=10)
    return _save(fig, out)


def plot_css_estimate_csv(path, out) -> Path:
    """``css estimate`` CSV: the estimated Sun direction (body axes) versus time."""
    from .style import figsize

    import io

    from ..io.safe_open import CSV_MAX_BYTES, read_bytes

    d = np.loadtxt(io.BytesIO(read_bytes(path, max_bytes=CSV_MAX_BYTES, what="CSV file")),
                   delimiter=",", skiprows=1, ndmin=2)
    if d.shape[1] != 4:
        raise InputError("expected 4 columns t_s,s_hat_x,s_hat_y,s_hat_z", file=path,
                         value=d.shape[1])
    plt = _plt()
    fig, ax = plt.subplots(figsize=figsize(10, 3.6), layout="constrained")
    for j, n in enumerate("xyz"):
        ax.plot(d[:, 0], d[:, 1 + j], lw=0.8, label=f"ŝ_{n}")
    ax.set_xlabel("t since the recording's epoch [s]")
    ax.set_ylabel("Sun direction, body axes")
    ax.set_ylim(-1.05, 1.05)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, ncol=3)
    fig.suptitle(f"{Path(path).name}: {len(d)} Sun-direction estimates", fontsize=10)
    return _save(fig, out)


def plot_invert_summary(path, out) -> Path:
    """invert ``summary.json``: final RSS attitude error and final 3σ (RSS) per file."""
    from .style import figsize

    doc = read_json(path)
    keys = list(doc)
    plt = _plt()
    fig, ax = plt.subplots(figsize=figsize(10, 1.2 + 0.28 * max(4, len(keys))),
                           layout="constrained")
    yy = np.arange(len(keys))
    err = [doc[k].get("final_att_error_rss_deg", np.nan) for k in keys]
    s3 = [np.linalg.norm(doc[k]["final_3sigma_att_deg"]) if "final_3sigma_att_deg" in doc[k]
          else np.nan for k in keys]
    ax.barh(yy, s3, color="0.85", label="final 3σ (RSS of the axes)")
    ok = [bool(doc[k].get("inside_3sigma", True)) and not doc[k].get("diverged") for k in keys]
    ax.scatter(err, yy, c=["C2" if o else "C3" for o in ok], zorder=3,
               label="final RSS error vs truth (red: outside 3σ or diverged)")
    for i, k in enumerate(keys):
        if "error" in doc[k]:
            ax.text(0, i, f"  failed: {doc[k]['error'][:60]}", va="center", fontsize=7, color="C3")
    ax.set_yticks(yy, keys, fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("attitude [deg]")
    ax.grid(True, axis="x", alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    n_bad = sum(not o for o in ok)
    fig.suptitle(f"{Path(path).name}: {len(keys)} file(s), {n_bad} outside 3σ, diverged or failed",
                 fontsize=10)
    return _save(fig, out)


def plot_study_summary(path, out) -> Path:
    """compare ``summary.json``: median and 95th-percentile final RSS attitude error per cell,
    coloured by the cell's traffic light (:func:`study_summary_figure`)."""
    return _save(study_summary_figure(read_json(path)), out)


def study_summary_figure(doc):
    """The figure of :func:`plot_study_summary` from the summary dict; returns the figure."""
    from .style import figsize

    cells = doc["cells"]
    keys = [k for k in doc.get("grid_keys", []) if len({str(c.get(k)) for c in cells}) > 1]
    labels = [", ".join(f"{k}={c.get(k)}" for k in keys) or f"cell {i}" for i, c in enumerate(cells)]
    col = {"green": "#5cb85c", "yellow": "#e0c030", "red": "#d9534f"}
    plt = _plt()
    fig, ax = plt.subplots(figsize=figsize(11, 1.3 + 0.26 * max(4, len(cells))),
                           layout="constrained")
    yy = np.arange(len(cells))
    ax.barh(yy, [c["rss_att_deg_p95"] for c in cells], color=[col.get(c["color"], "0.7") for c in cells],
            alpha=0.45, label="95th percentile")
    ax.plot([c["rss_att_deg_median"] for c in cells], yy, "k|", ms=12, mew=2, label="median")
    ax.set_yticks(yy, labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("final RSS attitude error [deg] (bar colour: the cell's traffic light)")
    ax.grid(True, axis="x", which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    fig.suptitle(f"study {doc['study']}: {len(cells)} cells × {doc.get('runs_per_cell', '?')} runs",
                 fontsize=10)
    return fig


def plot_reflection_summary(path, out) -> Path:
    """fit-reflection JSON: posterior median and 99 % interval per parameter, relative to the
    prior (value / prior centre), with the truth when the file has it."""
    from .style import figsize

    doc = read_json(path)
    rows = doc["parameters"]
    plt = _plt()
    fig, ax = plt.subplots(figsize=figsize(9, 1.3 + 0.3 * max(4, len(rows))), layout="constrained")
    yy = np.arange(len(rows))
    for i, r in enumerate(rows):
        c = r.get("prior_center", r.get("nominal", r["median"])) or r["median"]
        ax.plot([r["q005"] / c, r["q995"] / c], [i, i], "C0-", lw=3, alpha=0.6,
                label="posterior 99 % interval" if i == 0 else None)
        ax.plot(r["median"] / c, i, "C0o", ms=4, label="posterior median" if i == 0 else None)
        if "truth" in r:
            ax.plot(r["truth"] / c, i, "C3x", ms=7, label="truth" if i == 0 else None)
    ax.axvline(1.0, color="0.4", lw=0.8, ls="--", label="prior centre")
    ax.set_yticks(yy, [r["name"] for r in rows], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("value / prior centre")
    ax.grid(True, axis="x", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.suptitle(f"{Path(path).name}: {len(rows)} reflection parameters", fontsize=10)
    return _save(fig, out)
