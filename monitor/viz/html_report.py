"""The static fatigue report: one self-contained HTML page plus the same plots as PNG files.

Self-contained means no scripts and no external resources: the plots are PNG data URIs and the
style sheet is inline, so the file can be mailed or archived and opens offline.
"""

from __future__ import annotations

import base64
import html
import io
import math
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from monitor.atomic_file import atomic_write_bytes, atomic_write_text
from monitor.viz.alert_view import alert_episodes
from monitor.viz.findings import findings
from monitor.viz.human import number_text, remaining_life_text, stress_text
from monitor.viz.report_data import Report
from monitor.viz.report_plots import PLOTS, caption

_TITLES = {
    "tension": "Tension summary",
    "damage": "Damage accumulation",
    "histogram": "Rainflow histogram",
    "sn": "S-N curve with the counted cycles",
    "life": "Remaining life",
    "alerts": "Alert timeline",
    "spectral": "Spectral cross-check: Dirlik vs rainflow damage per window",
}
_MISSING = {
    "damage": "no fatigue components in the report",
    "histogram": "the report has no components[...].histogram (see docs/REPORT_FORMAT.md)",
    "sn": "the report has no components[...].sn_curve (see docs/REPORT_FORMAT.md)",
    "life": "no fatigue components in the report",
    "spectral": "the report has no spectral_windows ([forecast], docs/FORECAST.md)",
}
_CSS = """
body{font-family:system-ui,sans-serif;margin:2em;color:#222;max-width:1100px}
h1{font-size:1.5em}h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:.25em .6em;
text-align:right}th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}
img{max-width:100%;border:1px solid #eee}.note{color:#777;font-style:italic}
.critical{color:#d62828;font-weight:bold}.warning{color:#b07500;font-weight:bold}
#findings{background:#f7f9fc;border:1px solid #d0d7e2;padding:.2em 1.2em 1em}
#findings h3{font-size:1em;margin:.9em 0 .3em}#findings ul{margin:0;padding-left:1.3em}
#findings li{margin:.2em 0}figure{margin:0}figcaption{font-size:.85em}
table.alerts td,table.alerts th{text-align:left}table.alerts td:nth-child(4),
table.alerts td:nth-child(5){white-space:nowrap}
"""


@dataclass(frozen=True)
class RenderedReport:
    """Where :func:`write_report` put things."""

    html_path: Path
    png_paths: dict[str, Path]


def _iso(t_ns: int) -> str:
    dt = datetime.fromtimestamp(t_ns // 1_000_000_000, tz=timezone.utc)
    return dt.strftime("%Y-%m-%d %H:%M:%S UTC")


def _fmt(x: float, unit: str = "", scale: float = 1.0) -> str:
    if math.isnan(x):
        return "n/a"
    if math.isinf(x):
        return "&infin;" if x > 0 else "-&infin;"
    return f"{x / scale:.4g}{(' ' + unit) if unit else ''}"


def _table(header: list[str], rows: list[list[str]], cls: str = "") -> str:
    head = "".join(f"<th>{h}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table{f' class={cls!r}' if cls else ''}><tr>{head}</tr>{body}</table>"


def _findings(r: Report) -> str:
    """The findings (monitor.viz.findings), the first thing on the page."""
    e = html.escape
    parts = ["<section id='findings'><h2>Findings</h2>"]
    for heading, sentences in findings(r).sections():
        items = "".join(
            f"<li class='critical'>{e(s)}</li>" if "FAILED" in s else f"<li>{e(s)}</li>"
            for s in sentences)
        parts.append(f"<h3>{e(heading)}</h3><ul>{items}</ul>")
    parts.append("</section>")
    return "".join(parts)


def _summary(r: Report) -> str:
    e = html.escape
    parts = [f"<h2>Details</h2><p>Buoy <b>{e(r.buoy_id)}</b>, sensor time {_iso(r.time_start_ns)} to "
             f"{_iso(r.time_end_ns)} ({(r.time_end_ns - r.time_start_ns) / 86400e9:.3g} days)."
             "</p>"]
    parts.append(_table(
        ["channel", "accepted", "rejected", "rejected by reason"],
        [[e(ch), f"{acc:,d}", f"{sum(rej.values()):,d}",
          e(", ".join(f"{k}: {v:,d}" for k, v in sorted(rej.items()) if v) or "-")]
         for ch, (acc, rej) in sorted(r.samples.items())]))
    t = r.tension
    parts.append(_table(["tension", "min", "mean", "p99", "max"],
                        [["kN"] + [_fmt(t[k], scale=1e3) for k in ("min", "mean", "p99", "max")]]))
    parts.append(_table(
        ["component", "damage (committed)", "damage (incl. residue)", "cycles",
         "max stress", "damage rate (1/day)", "remaining life"],
        [[e(n), number_text(c.damage_committed), number_text(c.damage), f"{c.cycles:,.0f}",
          stress_text(c.max_stress_Pa), number_text(c.damage_rate_per_day),
          remaining_life_text(c.remaining_life_days)]
         for n, c in r.components.items()]))
    return "\n".join(parts)


def _alert_table(r: Report) -> str:
    """One row per alert episode: re-sends collapsed into a count."""
    if not r.alerts:
        return "<p>No alerts were raised.</p>"
    e = html.escape
    episodes = alert_episodes(r.alerts)
    rows = [[f'<span class="{e(a.severity)}">{e(a.severity)}</span>', e(a.rule),
             e(a.component), _iso(a.first_fired_ns),
             _iso(a.last_resent_ns) if a.resends else "-", str(a.resends),
             (_iso(a.cleared_ns) + (" (operator reset)" if a.cleared_by == "reset" else ""))
             if a.cleared_ns else "still firing at the end", e(a.summary)]
            for a in episodes]
    note = (f"<p class='note'>{len(r.alerts)} alert transitions in {len(episodes)} "
            "episodes; re-sent notifications are counted, not listed.</p>")
    return _table(["severity", "rule", "component", "first fired", "last re-sent",
                   "re-sends", "cleared", "summary"], rows, "alerts") + note


def _spectral_table(r: Report) -> str:
    """Per component: windows compared, flagged, and the median Dirlik / rainflow ratio."""
    rows = []
    for name, s in sorted((r.spectral or {}).items()):
        ok = (s.rainflow > 0) & np.isfinite(s.dirlik)
        ratio = float(np.median(s.dirlik[ok] / s.rainflow[ok])) if ok.any() else math.nan
        rows.append([html.escape(name), str(int(ok.sum())), str(int(s.flagged.sum())),
                     _fmt(ratio)])
    return _table(["component", "windows compared", "flagged",
                   "median Dirlik / rainflow"], rows)


def render_png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def write_report(report: Report, html_path: str | Path) -> RenderedReport:
    """Write ``html_path`` and ``<stem>_<plot>.png`` beside it; returns the paths."""
    html_path = Path(html_path)
    html_path.parent.mkdir(parents=True, exist_ok=True)
    sections, pngs = [], {}
    for key, plot in PLOTS.items():
        fig = plot(report)
        title = _TITLES[key]
        if fig is None:
            sections.append(f"<h2>{title}</h2><p class='note'>Not shown: {_MISSING[key]}.</p>")
            continue
        data = render_png(fig)
        png = html_path.with_name(f"{html_path.stem}_{key}.png")
        atomic_write_bytes(png, data)  # a full disk leaves no PNG cut short
        pngs[key] = png
        uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
        what = html.escape(caption(fig), quote=True)
        sections.append(f"<h2>{title}</h2><figure><img id='plot-{key}' alt='{title}: {what}' "
                        f"src='{uri}'><figcaption id='caption-{key}' class='note'>{what}"
                        "</figcaption></figure>")
        if key == "alerts":
            sections.append(_alert_table(report))
        if key == "spectral":
            sections.append(_spectral_table(report))
    title = f"Fatigue report: buoy {html.escape(report.buoy_id)}"
    page = (
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
        f"<title>{title}</title><style>{_CSS}</style></head><body>"
        f"<h1>{title}</h1>{_findings(report)}{_summary(report)}{''.join(sections)}"
        "<p class='note'>Damage is a Miner sum (1 = predicted failure); 'committed' counts "
        "closed rainflow cycles, 'incl. residue' adds the open cycles as half cycles.</p>"
        "</body></html>\n"
    )
    atomic_write_text(html_path, page)
    return RenderedReport(html_path, pngs)
