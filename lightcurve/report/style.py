"""Shared look of every figure and HTML report: UTC time axes, screen-sized figures, verdicts.

Conventions (every report and figure of the package follows them):

* **Time axes in UTC.** A quantity sampled at ``t`` seconds since ``epoch_utc`` is drawn
  against :func:`utc_times` and the axis is formatted by :func:`utc_axis` (concise dates, label
  "UTC"). Seconds-since-epoch axes are for short intervals only and say so in their label.
* **Screen-sized figures.** Width at most :data:`MAX_WIDTH_IN` inches at :data:`DPI` dots per
  inch (≤ 1,200 px), height at most :data:`MAX_HEIGHT_IN` inches; :func:`figsize` clips.
  Panels without data are not drawn (:func:`hide_empty`).
* **A one-line verdict at the top of every HTML report**: :func:`verdict_html` with a level
  ``"ok"`` (green), ``"warn"`` (amber) or ``"fail"`` (red) and one plain sentence saying what
  the analyst should conclude; :func:`page_html` assembles a self-contained page with it.
* Every reference line drawn (3σ bands, thresholds, truth) has a legend entry saying what it is.
"""

from __future__ import annotations

import html as _html
import numpy as np

__all__ = ["DPI", "MAX_WIDTH_IN", "MAX_HEIGHT_IN", "figsize", "utc_times", "utc_axis",
           "hide_empty", "verdict_html", "page_html", "PAGE_CSS", "VERDICT_COLOURS"]

DPI = 100
MAX_WIDTH_IN = 12.0
MAX_HEIGHT_IN = 14.0

VERDICT_COLOURS = {"ok": ("#e5f5e0", "#2e7d32"), "warn": ("#fff4d6", "#a66f00"),
                   "fail": ("#fde3e1", "#b3261e")}

PAGE_CSS = """
body{font-family:system-ui,sans-serif;margin:1.2em auto;max-width:1250px;padding:0 1em;
     line-height:1.4;color:#222}
h1{font-size:1.5em;margin-bottom:.2em} h2{font-size:1.2em;margin-top:1.6em}
p.verdict{font-size:1.15em;padding:.6em .9em;border-left:6px solid;border-radius:3px;margin:.6em 0 1em}
table{border-collapse:collapse;margin:1em 0;font-size:13px}
td,th{border:1px solid #bbb;padding:3px 6px;text-align:center}
img{max-width:100%;height:auto}
code{background:#f3f3f3;padding:0 .2em}
.small{font-size:.9em;color:#555}
"""


def figsize(width_in, height_in):
    """``(w, h)`` in inches clipped to the screen-sized limits of this module."""
    return (min(float(width_in), MAX_WIDTH_IN), min(float(height_in), MAX_HEIGHT_IN))


def utc_times(epoch_utc, t_s):
    """``epoch_utc + t_s`` as a numpy ``datetime64[us]`` array (naive, UTC) for plotting.

    ``epoch_utc`` is anything :func:`lightcurve.geometry.time.parse_epoch` accepts; ``t_s``
    seconds (NaN stays NaT). Leap seconds inside the span are ignored (plotting only).
    """
    from ..geometry.time import parse_epoch

    dt = parse_epoch(epoch_utc).replace(tzinfo=None)
    base = np.datetime64(dt, "us")
    t = np.asarray(t_s, dtype=float)
    us = np.where(np.isfinite(t), np.round(np.nan_to_num(t) * 1e6), 0).astype("int64")
    out = base + us.astype("timedelta64[us]")
    return np.where(np.isfinite(t), out, np.datetime64("NaT"))


def utc_axis(ax, label="UTC", offset=True):
    """Format ``ax``'s x axis for datetimes (concise ticks) and label it.

    ``offset`` shows the date below the ticks (turn it off on all but the bottom panels).
    """
    import matplotlib.dates as mdates

    loc = mdates.AutoDateLocator(minticks=3, maxticks=8)
    ax.xaxis.set_major_locator(loc)
    ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(loc, show_offset=offset))
    if label:
        ax.set_xlabel(label)


def hide_empty(axes):
    """Hide every axes in ``axes`` that has no lines, collections, images or patches drawn."""
    for ax in np.ravel(axes):
        if not (ax.lines or ax.collections or ax.images or ax.patches or ax.texts):
            ax.set_visible(False)


def verdict_html(level: str, text: str) -> str:
    """The one-line verdict paragraph (``level`` in ``ok``/``warn``/``fail``)."""
    if level not in VERDICT_COLOURS:
        raise ValueError(f"verdict level {level!r}; allowed: {', '.join(VERDICT_COLOURS)}")
    bg, fg = VERDICT_COLOURS[level]
    mark = {"ok": "✔", "warn": "⚠", "fail": "✘"}[level]
    return (f'<p class="verdict verdict-{level}" style="background:{bg};border-color:{fg}">'
            f"<b style='color:{fg}'>{mark} Verdict:</b> {_html.escape(text)}</p>")


def page_html(title: str, verdict: tuple, body: str, subtitle: str = "") -> str:
    """A self-contained HTML page: title, the verdict line, an optional subtitle, the body.

    ``verdict`` is ``(level, text)`` (see :func:`verdict_html`); ``body`` is trusted HTML.
    """
    sub = f"<p class='small'>{_html.escape(subtitle)}</p>" if subtitle else ""
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'>"
            f"<meta name='viewport' content='width=device-width, initial-scale=1'>"
            f"<title>{_html.escape(title)}</title><style>{PAGE_CSS}</style></head><body>"
            f"<h1>{_html.escape(title)}</h1>{verdict_html(*verdict)}{sub}\n{body}\n"
            f"</body></html>\n")
