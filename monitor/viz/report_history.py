"""A sink that gathers the report's optional plot fields (docs/REPORT_FORMAT.md) in bounded
memory: ``tension_history``, ``sea_state`` (from the buoy's wave reports), and per component
``damage_history`` and ``histogram``.

Time bins start at ``bin_s`` and double in width whenever there would be more than
``max_points`` of them, so any log length ends with between ``max_points / 2`` and
``max_points`` bins (bins are aligned to whole multiples of their width since the epoch, so
doubling merges neighbours exactly). The replay engine merges :meth:`ReportHistory.fields`
into its report.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from models.fatigue.sn_curve import SNCurve
from monitor.blocks import SampleBlock
from monitor.events import StepResult
from monitor.viz.cycle_histogram import CycleHistogram, check_edges

# the report's stress-range bins: 2 MPa wide up to 1 GPa (far above any conductor's or
# chain's strength, so the last bin, which also holds anything larger, stays empty for real
# loads); fields() trims the empty bins above the largest counted range
REPORT_RANGE_EDGES_Pa: tuple[float, ...] = tuple(np.linspace(0.0, 1000e6, 501).tolist())

def sn_curve_field(curve: SNCurve, max_range_Pa: float, n: int = 60) -> dict[str, Any]:
    """The report's ``components[name].sn_curve`` for a ``models.fatigue.sn_curve.SNCurve``: cycles to
    failure at ``n`` log-spaced nominal zero-mean stress ranges from ``max_range_Pa / 1000`` to
    ``3 * max_range_Pa``, and the nominal endurance stress when the curve has one."""
    if not np.isfinite(max_range_Pa) or max_range_Pa <= 0:
        raise ValueError(f"max_range_Pa = {max_range_Pa!r}: must be > 0")
    ranges = np.logspace(np.log10(max_range_Pa / 1000.0), np.log10(3.0 * max_range_Pa), n)
    means = None if curve.mean_correction == "none" else np.zeros_like(ranges)
    with np.errstate(over="ignore", divide="ignore"):  # N is inf far below the endurance
        cycles = curve.cycles_to_failure(ranges, means)
    out: dict[str, Any] = {"ranges_Pa": ranges.tolist(),
                           # inf (below a cut-off) is written as the JSON-safe string "inf"
                           "cycles": [c if np.isfinite(c) else "inf" for c in cycles.tolist()]}
    if curve.endurance_MPa:
        out["endurance_Pa"] = curve.endurance_MPa * 1e6 / (curve.scf * curve.derating)
    return out


_REDUCERS = {"min": np.minimum.reduceat, "max": np.maximum.reduceat, "sum": np.add.reduceat}


class _Binned:
    """Per-time-bin reductions of named columns: "min", "max", "sum" or "last"."""

    def __init__(self, kinds: Mapping[str, str], bin_ns: int, max_bins: int) -> None:
        self.kinds = dict(kinds)
        self.bin_ns = bin_ns
        self.max_bins = max_bins
        self.idx = np.empty(0, np.int64)
        self.cols = {k: np.empty(0) for k in kinds}

    def _regroup(self, idx: np.ndarray, cols: dict[str, np.ndarray]
                 ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        if len(idx) > 1 and not np.all(idx[1:] >= idx[:-1]):
            order = np.argsort(idx, kind="stable")
            idx, cols = idx[order], {k: v[order] for k, v in cols.items()}
        starts = np.flatnonzero(np.concatenate(([True], idx[1:] != idx[:-1])))
        ends = np.concatenate((starts[1:], [len(idx)])) - 1
        out = {k: (v[ends] if self.kinds[k] == "last" else _REDUCERS[self.kinds[k]](v, starts))
               for k, v in cols.items()}
        return idx[starts], out

    def add(self, t_ns: np.ndarray, cols: Mapping[str, np.ndarray]) -> None:
        if not len(t_ns):
            return
        idx, red = self._regroup(np.asarray(t_ns, np.int64) // self.bin_ns,
                                 {k: np.asarray(v, float) for k, v in cols.items()})
        self.idx, self.cols = self._regroup(
            np.concatenate((self.idx, idx)),
            {k: np.concatenate((self.cols[k], red[k])) for k in self.kinds})
        while len(self.idx) > self.max_bins:
            self.bin_ns *= 2
            self.idx, self.cols = self._regroup(self.idx // 2, self.cols)

    @property
    def t_s(self) -> np.ndarray:
        """Start of every bin, s since the epoch."""
        return self.idx * (self.bin_ns / 1e9)


class _Stats:
    """Running min / sum / max / count of a series."""

    def __init__(self) -> None:
        self.min, self.max, self.sum, self.n = np.inf, -np.inf, 0.0, 0

    def add(self, x: np.ndarray) -> None:
        if len(x):
            self.min, self.max = min(self.min, float(x.min())), max(self.max, float(x.max()))
            self.sum += float(x.sum())
            self.n += len(x)

    def fields(self) -> dict[str, float]:
        return {"min": self.min, "mean": self.sum / self.n, "max": self.max}


class ReportHistory:
    """Sink collecting tension, damage and cycle histories for the report's plots.

    Args:
        max_points: most time bins per series (the format asks for <= 1000).
        bin_s: initial bin width.
        range_edges_Pa: stress-range bins of the histogram (ranges above the last edge are
            counted in the last bin; the field keeps the bins up to the largest range).
    """

    def __init__(self, max_points: int = 1000, bin_s: float = 1.0,
                 range_edges_Pa: tuple[float, ...] = REPORT_RANGE_EDGES_Pa) -> None:
        if not isinstance(max_points, int) or max_points < 2:
            raise ValueError(f"max_points = {max_points!r}: must be an integer >= 2")
        if not np.isfinite(bin_s) or bin_s <= 0:
            raise ValueError(f"bin_s = {bin_s!r}: must be > 0")
        self._max = max_points
        self._bin_ns = max(1, int(round(bin_s * 1e9)))
        self._edges = check_edges(range_edges_Pa, "range_edges_Pa")
        self._tension = _Binned({"min": "min", "max": "max", "sum": "sum", "count": "sum"},
                                self._bin_ns, max_points)
        self._damage: dict[str, _Binned] = {}
        self._hist: dict[str, CycleHistogram] = {}
        self._max_range: dict[str, float] = {}
        self._last_load_ns: int | None = None
        self._waves = {"reports": 0, "hs_m": _Stats(), "tp_s": _Stats()}

    def on_block(self, block: SampleBlock) -> None:
        """Wave reports (``waves`` blocks) for the report's ``sea_state``. Raw blocks arrive
        before validation, so only physical values count: finite, Hs >= 0, Tp > 0."""
        if block.sensor != "waves" or not len(block.t_ns):
            return
        hs, tp = (np.asarray(block.fields[k], float) for k in ("hs_m", "tp_s"))
        ok = np.isfinite(hs) & np.isfinite(tp) & (hs >= 0) & (tp > 0)
        self._waves["reports"] += int(ok.sum())
        self._waves["hs_m"].add(hs[ok])
        self._waves["tp_s"].add(tp[ok])

    def on_step(self, step: StepResult) -> None:
        ok = np.isfinite(step.tension_N)
        t, v = step.t_ns[ok], step.tension_N[ok]
        self._tension.add(t, {"min": v, "max": v, "sum": v, "count": np.ones(len(v))})
        if len(t):
            self._last_load_ns = max(self._last_load_ns or 0, int(t.max()))
        if self._last_load_ns is None:
            return  # no load yet: nothing has accrued, and step.now_ns lies before the data
        # a step's damage covers the load up to its newest sample; step.now_ns (the replay's
        # processing horizon) can lag the data by the reorder window
        now = np.array([self._last_load_ns], np.int64)
        for name, c in step.components.items():
            if name not in self._damage:
                self._damage[name] = _Binned(
                    {"t_ns": "last", "damage_committed": "last", "damage": "last"},
                    self._bin_ns, self._max)
                self._hist[name] = CycleHistogram(self._edges, (-1e300, 1e300))
            self._damage[name].add(now, {"t_ns": now.astype(float),
                                         "damage_committed": [c.damage_committed],
                                         "damage": [c.damage]})
            self._hist[name].add(c.ranges_Pa, c.means_Pa, c.counts)
            if len(c.ranges_Pa):
                self._max_range[name] = max(self._max_range.get(name, 0.0),
                                            float(np.max(c.ranges_Pa)))

    def close(self) -> None:
        """Nothing to release; the fields stay readable."""

    def fields(self) -> dict[str, Any]:
        """The optional report fields, JSON-ready (lists of floats)."""
        out: dict[str, Any] = {}
        tb = self._tension
        if len(tb.idx):
            out["tension_history"] = {
                "t_s": tb.t_s.tolist(), "min": tb.cols["min"].tolist(),
                "mean": (tb.cols["sum"] / tb.cols["count"]).tolist(),
                "max": tb.cols["max"].tolist()}
        comps: dict[str, Any] = {}
        for name, d in self._damage.items():
            hist = self._hist[name]
            hist.update()
            comps[name] = {
                # the time of the step whose damage is shown, not the bin start
                "damage_history": {"t_s": (d.cols["t_ns"] / 1e9).tolist(),
                                   "damage_committed": d.cols["damage_committed"].tolist(),
                                   "damage": d.cols["damage"].tolist()},
                "histogram": self._histogram_field(name),
            }
        if comps:
            out["components"] = comps
        if self._waves["reports"]:
            out["sea_state"] = {"reports": self._waves["reports"],
                                "hs_m": self._waves["hs_m"].fields(),
                                "tp_s": self._waves["tp_s"].fields()}
        return out

    def _histogram_field(self, name: str) -> dict[str, Any]:
        """Edges and counts up to the bin of the largest counted range, and that range."""
        counts = self._hist[name].counts
        used = np.flatnonzero(counts)
        n = int(used[-1]) + 1 if len(used) else 1
        out: dict[str, Any] = {"edges_Pa": self._edges[:n + 1].tolist(),
                               "counts": counts[:n].tolist()}
        if name in self._max_range:
            out["max_range_Pa"] = self._max_range[name]
        return out
