"""The report's plots, drawn with matplotlib's Agg backend (no display needed).

Each ``plot_*`` function takes a :class:`~monitor.viz.report_data.Report` and returns a
matplotlib Figure, or None when the report lacks the data for it (the page then says so).
"""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")  # headless: never try to open a window

import matplotlib.dates as mdates  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from monitor.viz.report_data import Report  # noqa: E402

SEVERITY_COLOURS = {"info": "#4c9be8", "warning": "#f0a202", "critical": "#d62828"}
_DAYS_PER_YEAR = 365.25


def _dates(t_s: np.ndarray) -> np.ndarray:
    return (np.asarray(t_s) * 1e9).astype("int64").astype("datetime64[ns]")


def _figure(width: float = 8.0, height: float = 3.6) -> Figure:
    # Figure() directly (not pyplot): no global figure registry, nothing to close
    return Figure(figsize=(width, height), dpi=100, layout="constrained")


def _time_axis(ax) -> None:
    locator = mdates.AutoDateLocator()
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))
    ax.set_xlabel("sensor time (UTC)")


def plot_tension(r: Report) -> Figure:
    fig = _figure()
    ax = fig.add_subplot()
    h = r.tension_history
    if h is not None and len(h.t_s):
        d = _dates(h.t_s)
        ax.fill_between(d, h.columns["min"] / 1e3, h.columns["max"] / 1e3, step="post",
                        color="#9ecae1", label="min-max per bin")
        ax.plot(d, h.columns["mean"] / 1e3, drawstyle="steps-post", color="#08519c", label="mean")
        if math.isfinite(r.tension["p99"]):
            ax.axhline(r.tension["p99"] / 1e3, color="#d62828", ls="--", lw=1,
                       label=f"p99 {r.tension['p99'] / 1e3:.3g} kN")
        _time_axis(ax)
        ax.legend(loc="upper right", fontsize=8)
    else:
        names = ["min", "mean", "p99", "max"]
        ax.bar(names, [r.tension[k] / 1e3 for k in names], color="#3182bd")
    ax.set_ylabel("tension (kN)")
    ax.set_title(f"Cable tension, buoy {r.buoy_id}")
    return fig


def plot_damage(r: Report) -> Figure | None:
    if not r.components:
        return None
    fig = _figure()
    ax = fig.add_subplot()
    histories = {n: c.damage_history for n, c in r.components.items()
                 if c.damage_history is not None and len(c.damage_history.t_s)}
    if histories:
        for i, (name, h) in enumerate(sorted(histories.items())):
            colour = f"C{i}"
            ax.plot(_dates(h.t_s), h.columns["damage_committed"], color=colour,
                    label=f"{name} committed")
            if "damage" in h.columns:
                ax.plot(_dates(h.t_s), h.columns["damage"], color=colour, ls="--", lw=1,
                        label=f"{name} incl. open residue")
        _time_axis(ax)
    else:
        names = sorted(r.components)
        x = np.arange(len(names))
        ax.bar(x - 0.2, [r.components[n].damage_committed for n in names], 0.4, label="committed")
        ax.bar(x + 0.2, [r.components[n].damage for n in names], 0.4,
               label="incl. open residue")
        ax.set_xticks(x, names)
    ax.set_ylabel("Miner damage (1 = failure)")
    ax.set_title("Damage accumulation")
    ax.legend(fontsize=8)
    return fig


def plot_histogram(r: Report) -> Figure | None:
    comps = [c for _, c in sorted(r.components.items()) if c.hist_counts is not None]
    if not comps:
        return None
    fig = _figure()
    ax = fig.add_subplot()
    for i, c in enumerate(comps):
        edges = c.hist_edges_Pa / 1e6
        ax.stairs(c.hist_counts, edges, color=f"C{i}", fill=len(comps) == 1, alpha=0.8,
                  label=c.name)
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_xlabel("stress range (MPa)")
    ax.set_ylabel("cycles")
    ax.set_title("Rainflow histogram of conductor stress ranges")
    ax.legend(fontsize=8)
    return fig


def plot_sn(r: Report) -> Figure | None:
    comps = [c for _, c in sorted(r.components.items()) if c.sn_cycles is not None]
    if not comps:
        return None
    fig = _figure()
    ax = fig.add_subplot()
    for i, c in enumerate(comps):
        ok = (c.sn_cycles > 0) & (c.sn_ranges_Pa > 0) & np.isfinite(c.sn_cycles)
        ax.loglog(c.sn_cycles[ok], c.sn_ranges_Pa[ok] / 1e6, color=f"C{i}",
                  label=f"{c.name} S-N curve")
        if c.sn_endurance_Pa:
            ax.axhline(c.sn_endurance_Pa / 1e6, color=f"C{i}", ls=":", lw=1)
        if c.hist_counts is not None:
            # counted cycles as an exceedance spectrum: cycles with range >= each bin's lower
            # edge; where the spectrum crosses the S-N curve the damage is concentrated
            exceed = np.cumsum(c.hist_counts[::-1])[::-1]
            keep = exceed > 0
            ax.step(exceed[keep], c.hist_edges_Pa[:-1][keep] / 1e6, where="post",
                    color=f"C{i}", ls="--", label=f"{c.name} counted cycles (exceedance)")
    ax.set_xlabel("cycles")
    ax.set_ylabel("stress range (MPa)")
    ax.set_title("S-N curve and counted cycles")
    ax.legend(fontsize=8)
    return fig


def plot_life(r: Report) -> Figure | None:
    if not r.components:
        return None
    names = sorted(r.components)
    life = np.array([r.components[n].remaining_life_days for n in names]) / _DAYS_PER_YEAR
    fig = _figure(height=max(1.8, 0.6 * len(names) + 1.2))
    ax = fig.add_subplot()
    finite = np.isfinite(life) & (life > 0)
    cap = float(np.max(life[finite])) * 10 if finite.any() else 100.0
    if r.design_life_years:
        cap = max(cap, r.design_life_years * 10)
    spent = life == 0  # damage >= 1: no life left
    floor = float(np.min(life[finite])) / 10 if finite.any() else 1e-3
    shown = np.where(finite, life, np.where(spent, floor, cap))
    colours = ["#2b8cbe" if f else "#d62828" if s else "#bdbdbd" for f, s in zip(finite, spent)]
    ax.barh(names, shown, color=colours)
    for y, (v, f, s) in enumerate(zip(life, finite, spent)):
        text = f" {v:.3g} y" if f else " none left (damage >= 1)" if s else " no damage accrued"
        ax.text(shown[y], y, text, va="center", fontsize=8)
    if r.design_life_years:
        ax.axvline(r.design_life_years, color="#d62828", ls="--",
                   label=f"design life {r.design_life_years:g} y")
        ax.legend(fontsize=8, loc="lower right")
    ax.set_xscale("log")
    ax.set_xlabel("remaining life at the current damage rate (years)")
    ax.set_title("Remaining life")
    return fig


def plot_alerts(r: Report) -> Figure:
    fig = _figure(height=max(1.8, 0.45 * len({(a.rule, a.component) for a in r.alerts}) + 1.4))
    ax = fig.add_subplot()
    t0, t1 = r.time_start_ns, max(r.time_end_ns, r.time_start_ns + 1)
    lanes: dict[tuple[str, str], list] = {}
    for a in sorted(r.alerts, key=lambda a: a.at_ns):
        lanes.setdefault((a.rule, a.component), []).append(a)
    for y, ((rule, comp), events) in enumerate(sorted(lanes.items())):
        firing: tuple[int, str] | None = None
        for a in events:
            if a.state == "firing" and firing is None:
                firing = (a.starts_at_ns, a.severity)
            elif a.state == "firing" and firing is not None and a.severity != firing[1]:
                _span(ax, y, firing[0], a.at_ns, firing[1])
                firing = (a.at_ns, a.severity)
            elif a.state == "resolved" and firing is not None:
                _span(ax, y, firing[0], a.ends_at_ns or a.at_ns, firing[1])
                firing = None
        if firing is not None:
            _span(ax, y, firing[0], t1, firing[1])
        ax.plot(_dates(np.array([a.at_ns for a in events]) / 1e9), [y] * len(events), "k|", ms=10)
    ax.set_yticks(range(len(lanes)), [f"{rule} / {comp}" for rule, comp in sorted(lanes)])
    ax.set_xlim(_dates(np.array([t0, t1]) / 1e9))
    _time_axis(ax)
    if not lanes:
        ax.set_yticks([])
        ax.text(0.5, 0.5, "no alerts", transform=ax.transAxes, ha="center", va="center",
                color="#636363")
    handles = [Patch(color=c, label=s) for s, c in SEVERITY_COLOURS.items()]
    ax.legend(handles=handles, fontsize=8, loc="upper right")
    ax.set_title("Alert timeline")
    return fig


def _span(ax, y: int, start_ns: int, end_ns: int, severity: str) -> None:
    d = _dates(np.array([start_ns, max(end_ns, start_ns)]) / 1e9)
    ax.barh(y, d[1] - d[0], left=d[0], height=0.6,
            color=SEVERITY_COLOURS.get(severity, "#969696"))


def plot_spectral(r: Report) -> Figure | None:
    """Dirlik against rainflow damage per window (log-log), the agreement band, flags."""
    if not r.spectral:
        return None
    fig = _figure()
    ax = fig.add_subplot()
    lo, hi = math.inf, 0.0
    for name, s in sorted(r.spectral.items()):
        ok = (s.rainflow > 0) & (s.dirlik > 0)
        if not ok.any():
            continue
        ax.scatter(s.rainflow[ok & ~s.flagged], s.dirlik[ok & ~s.flagged], s=12, label=name)
        lo = min(lo, float(s.rainflow[ok].min()), float(s.dirlik[ok].min()))
        hi = max(hi, float(s.rainflow[ok].max()), float(s.dirlik[ok].max()))
        if (ok & s.flagged).any():
            ax.scatter(s.rainflow[ok & s.flagged], s.dirlik[ok & s.flagged], s=24,
                       marker="x", color=SEVERITY_COLOURS["critical"],
                       label=f"{name}: flagged")
    if not hi > 0:
        return None
    line = np.array([lo / 2, hi * 2])
    ax.plot(line, line, color="#555", lw=0.8, label="Dirlik = rainflow")
    f = r.spectral_flag_factor
    if math.isfinite(f):
        for k in (f, 1 / f):
            ax.plot(line, k * line, color="#999", lw=0.8, ls="--")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("rainflow damage per window")
    ax.set_ylabel("Dirlik damage per window")
    ax.legend(fontsize="small")
    return fig


PLOTS = {
    "tension": plot_tension,
    "damage": plot_damage,
    "histogram": plot_histogram,
    "sn": plot_sn,
    "life": plot_life,
    "alerts": plot_alerts,
    "spectral": plot_spectral,
}
