"""The report's plots, drawn with matplotlib's Agg backend (no display needed).

Each ``plot_*`` function takes a :class:`~monitor.viz.report_data.Report` and returns a
matplotlib Figure, or None when the report lacks the data for it (the page then says so).

Readability rules (issue 19): time axes span the replayed data (first to last sample); damage
is on a log axis so a 0.04 and a 15 are both visible; every component has its own colour and
line style, and components whose curves coincide (equal cycle histograms; S-N curves within
``SAME_CURVE_DECADES`` of each other) share one curve whose legend names them all, so no
curve hides under another;
legends sit outside the data; stresses in MPa, tensions in kN.
"""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")  # headless: never try to open a window

import matplotlib.dates as mdates  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from monitor.viz.human import DAYS_PER_YEAR, remaining_life_text  # noqa: E402
from monitor.viz.report_data import Component, Report  # noqa: E402

SEVERITY_COLOURS = {"info": "#4c9be8", "warning": "#f0a202", "critical": "#d62828"}
# per component (in the report's order): colour-blind-safe colours and distinct dashes
STYLES = [("#0072b2", "-"), ("#d55e00", "--"), ("#009e73", "-."), ("#cc79a7", ":"),
          ("#e69f00", (0, (5, 1, 1, 1))), ("#56b4e9", (0, (1, 1)))]


def _dates(t_s: np.ndarray) -> np.ndarray:
    return (np.asarray(t_s) * 1e9).astype("int64").astype("datetime64[ns]")


def _figure(width: float = 8.0, height: float = 3.6) -> Figure:
    # Figure() directly (not pyplot): no global figure registry, nothing to close
    return Figure(figsize=(width, height), dpi=100, layout="constrained")


def _time_axis(ax, r: Report | None = None) -> None:
    """Date ticks; with ``r`` the axis spans the replayed data, first to last sample."""
    locator = mdates.AutoDateLocator()
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))
    ax.set_xlabel("sensor time (UTC)")
    if r is not None and r.time_end_ns > r.time_start_ns:
        ax.set_xlim(_dates(np.array([r.time_start_ns, r.time_end_ns]) / 1e9))


def _legend_outside(ax, **kwargs) -> None:
    """The legend right of the axes, never over the data."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0,
              **kwargs)


def style(r: Report, name: str) -> tuple[str, object]:
    """(colour, line style) of a component: fixed by its place in the report."""
    return STYLES[list(r.components).index(name) % len(STYLES)]


def shared_groups(comps: list[Component], same) -> list[list[Component]]:
    """Components grouped, in order, by ``same(a, b)`` with each group's first member."""
    groups: list[list[Component]] = []
    for c in comps:
        for members in groups:
            if same(members[0], c):
                members.append(c)
                break
        else:
            groups.append([c])
    return groups


def same_histogram(a: Component, b: Component) -> bool:
    return (np.array_equal(a.hist_edges_Pa, b.hist_edges_Pa)
            and np.array_equal(a.hist_counts, b.hist_counts))


def _sn_points(c: Component) -> tuple[np.ndarray, np.ndarray]:
    ok = (c.sn_cycles > 0) & (c.sn_ranges_Pa > 0) & np.isfinite(c.sn_cycles)
    return c.sn_ranges_Pa[ok], c.sn_cycles[ok]


SAME_CURVE_DECADES = 0.02  # S-N curves closer than this in log10(stress) (4.7 %) are one
#                           line on the plot: drawn once, named together


def same_sn_curve(a: Component, b: Component) -> bool:
    """True when the two S-N curves would be drawn on top of each other: the same endurance,
    and each one's points within the other's span less than ``SAME_CURVE_DECADES`` from the
    other's (log-log interpolated) stress at the same cycles. The points are sampled over
    each component's own stress span, so equal curves come with unequal arrays."""
    if (a.sn_endurance_Pa or 0.0) != (b.sn_endurance_Pa or 0.0):
        return False
    (sa, na), (sb, nb) = _sn_points(a), _sn_points(b)
    if len(sa) < 2 or len(sb) < 2:
        return len(sa) == len(sb) == 0
    for (s1, n1), (s2, n2) in (((sa, na), (sb, nb)), ((sb, nb), (sa, na))):
        order = np.argsort(n2)
        inside = (n1 >= n2.min()) & (n1 <= n2.max())
        want = np.interp(np.log10(n1[inside]), np.log10(n2[order]), np.log10(s2[order]))
        if np.any(np.abs(np.log10(s1[inside]) - want) > SAME_CURVE_DECADES):
            return False
    return True


def _names(group: list[Component]) -> str:
    return ", ".join(c.name for c in group)


def plot_tension(r: Report) -> Figure:
    fig = _figure()
    ax = fig.add_subplot()
    h = r.tension_history
    if h is not None and len(h.t_s):
        # the first bin starts on the bin grid, up to a bin before the first sample
        d = _dates(np.maximum(h.t_s, r.time_start_ns / 1e9))
        ax.fill_between(d, h.columns["min"] / 1e3, h.columns["max"] / 1e3, step="post",
                        color="#9ecae1", label="min-max per bin")
        ax.plot(d, h.columns["mean"] / 1e3, drawstyle="steps-post", color="#08519c", label="mean")
        if math.isfinite(r.tension["p99"]):
            ax.axhline(r.tension["p99"] / 1e3, color="#d62828", ls="--", lw=1,
                       label=f"p99 {r.tension['p99'] / 1e3:.3g} kN")
        if r.breaking_load_N and r.tension["max"] > 0.5 * r.breaking_load_N:
            ax.axhline(r.breaking_load_N / 1e3, color="k", ls="-.", lw=1,
                       label=f"breaking load {r.breaking_load_N / 1e3:.3g} kN")
        _time_axis(ax, r)
        _legend_outside(ax)
    else:
        names = ["min", "mean", "p99", "max"]
        ax.bar(names, [r.tension[k] / 1e3 for k in names], color="#3182bd")
    ax.set_ylabel("tension (kN)")
    ax.set_title(f"Cable tension, buoy {r.buoy_id}")
    return fig


def plot_damage(r: Report) -> Figure | None:
    """Miner damage incl. the open cycles per component, log axis, with the failure line."""
    if not r.components:
        return None
    fig = _figure()
    ax = fig.add_subplot()
    histories = {n: c.damage_history for n, c in r.components.items()
                 if c.damage_history is not None and len(c.damage_history.t_s)}
    if histories:
        for name, h in histories.items():
            d = h.columns.get("damage", h.columns["damage_committed"])
            ok = d > 0  # a log axis has no 0; nothing accrued yet there
            colour, ls = style(r, name)
            ax.plot(_dates(h.t_s[ok]), d[ok], color=colour, ls=ls, marker=".", ms=4,
                    label=name, gid=f"damage-{name}")
        _time_axis(ax, r)
    else:
        names = list(r.components)
        values = [r.components[n].damage for n in names]
        ax.bar(names, [v if v > 0 else np.nan for v in values],
               color=[style(r, n)[0] for n in names])
        ax.tick_params(axis="x", labelsize=8)
    ax.set_yscale("log")
    ax.axhline(1.0, color="#d62828", lw=1, ls=(0, (6, 3)), label="failure (damage 1)")
    ax.set_ylabel("Miner damage incl. open cycles")
    ax.set_title("Damage accumulation (log scale)")
    _legend_outside(ax)
    return fig


def plot_histogram(r: Report) -> Figure | None:
    """Cycle counts per stress-range bin; identical histograms share one curve."""
    comps = [c for c in r.components.values() if c.hist_counts is not None]
    if not comps:
        return None
    fig = _figure()
    ax = fig.add_subplot()
    top = 0.0
    for group in shared_groups(comps, same_histogram):
        c = group[0]
        colour, ls = style(r, c.name)
        edges = c.hist_edges_Pa / 1e6
        ax.stairs(c.hist_counts, edges, color=colour, ls=ls, lw=1.5, label=_names(group))
        top = max(top, edges[-1])
        peak = c.hist_max_range_Pa
        if peak is not None and peak > 0:
            ax.axvline(peak / 1e6, color=colour, ls=ls, lw=0.8)
            ax.annotate(f"largest range {peak / 1e6:.3g} MPa", (peak / 1e6, 1.0),
                        xycoords=("data", "axes fraction"), rotation=90, va="top",
                        ha="right", fontsize=7, color=colour)
            top = max(top, peak / 1e6)
        elif c.hist_counts[-1] > 0:  # an older report: the last bin holds every larger range
            ax.annotate(f"last bin: all ranges >= {edges[-2]:.3g} MPa", (edges[-2], 1.0),
                        xycoords=("data", "axes fraction"), rotation=90, va="top",
                        ha="right", fontsize=7, color=colour)
    ax.set_xlim(0.0, top * 1.03)
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_xlabel("stress range (MPa)")
    ax.set_ylabel("cycles")
    ax.set_title("Rainflow histogram of stress ranges")
    _legend_outside(ax)
    return fig


def plot_sn(r: Report) -> Figure | None:
    """S-N curves (identical curves drawn once) with labelled endurance lines, and each
    distinct counted-cycle spectrum as an exceedance curve."""
    comps = [c for c in r.components.values() if c.sn_cycles is not None]
    if not comps:
        return None
    fig = _figure(height=4.2)
    ax = fig.add_subplot()
    for group in shared_groups(comps, same_sn_curve):
        c = group[0]
        colour, ls = style(r, c.name)
        # one curve over the members' joint span
        ranges, cycles = (np.concatenate(x) for x in zip(*map(_sn_points, group)))
        order = np.argsort(ranges)
        ax.loglog(cycles[order], ranges[order] / 1e6, color=colour, ls=ls, lw=2,
                  label=f"S-N curve: {_names(group)}", gid=f"sn-{c.name}")
        if c.sn_endurance_Pa:
            mpa = c.sn_endurance_Pa / 1e6
            ax.axhline(mpa, color=colour, ls=":", lw=1)
            ax.annotate(f"endurance {mpa:.3g} MPa ({_names(group)})", (0.01, mpa),
                        xycoords=("axes fraction", "data"), va="bottom", fontsize=7,
                        color=colour)
    counted = [c for c in comps if c.hist_counts is not None]
    for group in shared_groups(counted, same_histogram):
        c = group[0]
        colour, _ = style(r, c.name)
        # counted cycles as an exceedance spectrum: cycles with range >= each bin's lower
        # edge; where the spectrum crosses the S-N curve the damage is concentrated
        exceed = np.cumsum(c.hist_counts[::-1])[::-1]
        keep = exceed > 0
        ax.step(exceed[keep], c.hist_edges_Pa[:-1][keep] / 1e6, where="post", color=colour,
                lw=1, alpha=0.8, marker="|", ms=3,
                label=f"counted cycles (exceedance): {_names(group)}")
    ax.set_xlim(left=1.0)  # fewer than one cycle to failure: off the chart
    ax.set_xlabel("cycles")
    ax.set_ylabel("stress range (MPa)")
    ax.set_title("S-N curves and counted cycles")
    _legend_outside(ax)
    return fig


def plot_life(r: Report) -> Figure | None:
    if not r.components:
        return None
    names = list(r.components)
    days = [r.components[n].remaining_life_days for n in names]
    life = np.array(days) / DAYS_PER_YEAR
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
    for y, d in enumerate(days):
        ax.text(shown[y], y, " " + remaining_life_text(d), va="center", fontsize=8)
    if r.design_life_years:
        ax.axvline(r.design_life_years, color="#d62828", ls="--",
                   label=f"design life {r.design_life_years:g} y")
        _legend_outside(ax)
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
    _legend_outside(ax, handles=handles)
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


def caption(fig: Figure) -> str:
    """What the figure's first axes show, read back from them: the x and y labels and
    ranges (dates for a time axis), the y scale, and the legend's entries. The page prints
    it under the plot (and its tests read it there)."""
    ax = fig.axes[0]
    x0, x1 = ax.get_xlim()
    if isinstance(ax.xaxis.get_major_formatter(), mdates.ConciseDateFormatter):
        fmt = "%Y-%m-%d %H:%M:%S UTC"
        xr = f"{mdates.num2date(x0).strftime(fmt)} to {mdates.num2date(x1).strftime(fmt)}"
    else:
        xr = f"{x0:.3g} to {x1:.3g}" + (f" ({ax.get_xscale()} scale)"
                                        if ax.get_xscale() != "linear" else "")
    y0, y1 = ax.get_ylim()
    parts = [f"x: {ax.get_xlabel()}, {xr}"]
    if ax.get_ylabel():  # (no range for categories: components, alert lanes)
        parts.append(f"y: {ax.get_ylabel()}, {y0:.3g} to {y1:.3g}"
                     + (f" ({ax.get_yscale()} scale)" if ax.get_yscale() != "linear" else ""))
    legend = ax.get_legend()
    if legend is not None:
        parts.append("shown: " + "; ".join(t.get_text() for t in legend.get_texts()))
    return ". ".join(parts) + "."


PLOTS = {
    "tension": plot_tension,
    "damage": plot_damage,
    "histogram": plot_histogram,
    "sn": plot_sn,
    "life": plot_life,
    "alerts": plot_alerts,
    "spectral": plot_spectral,
}
