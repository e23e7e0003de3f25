"""Palmgren-Miner damage accumulation for a stream of rainflow cycles.

``MinerAccumulator(sn_curve, histogram_edges_Pa=None, rate_window_s=86400.0,
rate_buckets=24, reference_cycles=1e7, backend="auto")``
  ``add_cycles(ranges_Pa, counts, means_Pa=None, time_s=None) -> float``
      commit closed cycles (never revised); returns the damage they added. ``time_s``
      (seconds, any epoch, non-decreasing) dates them for the damage rate.
  ``set_provisional(ranges_Pa, counts, means_Pa=None) -> float``
      replace the provisional damage (the rainflow residue's half cycles).
  ``damage_committed``, ``damage_provisional``, ``damage`` (= committed + provisional)
  ``damage_rate_per_day``   committed damage per day over the last ``rate_window_s``
  ``remaining_life_days``   (1 - damage) / rate (inf while the rate is zero)
  ``histogram``             (edges_Pa, counts, overflow_count): committed cycles per
                            nominal stress-range bin on fixed edges (never data dependent);
                            ranges below the first edge are not binned
  ``total_cycles``, ``equivalent_stress_range(reference_cycles=None) -> Pa``
      the zero-mean range whose ``reference_cycles`` cycles give the committed damage
  ``state() -> dict`` / ``MinerAccumulator.from_state(dict)``  JSON-serialisable; the
      S-N curve is included; floats round-trip exactly.

Split invariance: each closed cycle's damage is computed on its own and added to the
committed total one by one in closure order (a sequential sum, not numpy's pairwise
``sum``), and four-point closure order does not depend on block boundaries. Hence
feeding a series in any blocks, with state saved and restored in between, gives the same
``damage_committed`` to the last bit. The damage rate is bucketed by the times passed in,
which do depend on blocking; it is a monitoring figure, not an exact one.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from models.sn_curve import SNCurve

try:
    import numba
except ImportError:  # pragma: no cover - exercised only where numba is missing
    numba = None

_DAY_S = 86400.0
_STATE_VERSION = 1


def _commit_loop(ranges, counts, scale, seg_m, seg_coef, bounds, cutoff, committed, edges, hist):
    """Damage of each cycle added in order; histogram updated. Returns (committed, added, bad).

    ``bad`` is -1, or the index of the first invalid cycle (nothing is changed then).
    Range S (MPa) = range * scale; damage = count * coef_i * S**m_i on segment i.
    """
    n = ranges.shape[0]
    for i in range(n):
        if not (ranges[i] >= 0.0 and math.isfinite(ranges[i]) and counts[i] >= 0.0 and math.isfinite(counts[i])):
            return committed, 0.0, i
    nseg = seg_m.shape[0]
    nb = edges.shape[0]
    start = committed
    for i in range(n):
        s = ranges[i] * scale
        seg = nseg - 1
        for j in range(bounds.shape[0]):  # a handful of knees: a linear scan is fastest
            if s >= bounds[j]:
                seg -= 1
        d = 0.0
        if s >= cutoff:
            d = counts[i] * (seg_coef[seg] * s ** seg_m[seg])
        committed += d
        r = ranges[i]
        if r >= edges[nb - 1]:
            hist[nb - 1] += counts[i]
        else:
            lo = 0
            hi = nb - 1
            while hi - lo > 1:
                mid = (lo + hi) >> 1
                if r >= edges[mid]:
                    lo = mid
                else:
                    hi = mid
            if r >= edges[0]:
                hist[lo] += counts[i]
    return committed, committed - start, -1


_commit_compiled = numba.njit(cache=True, nogil=True)(_commit_loop) if numba is not None else None


class MinerAccumulator:
    """Committed + provisional Miner damage with rate, histogram and remaining life."""

    def __init__(self, sn_curve: SNCurve, histogram_edges_Pa=None, rate_window_s: float = _DAY_S,
                 rate_buckets: int = 24, reference_cycles: float = 1e7,
                 backend: Literal["auto", "numba", "numpy"] = "auto"):
        if not isinstance(sn_curve, SNCurve):
            raise ValueError(f"sn_curve must be an SNCurve, got {type(sn_curve).__name__}")
        edges = np.asarray(np.linspace(0.0, 100e6, 101) if histogram_edges_Pa is None else histogram_edges_Pa,
                           dtype=np.float64)
        if edges.ndim != 1 or edges.size < 2 or not np.all(np.isfinite(edges)) or np.any(np.diff(edges) <= 0):
            raise ValueError("histogram_edges_Pa must be >= 2 finite, strictly increasing values")
        if not (math.isfinite(rate_window_s) and rate_window_s > 0):
            raise ValueError(f"rate_window_s must be positive, got {rate_window_s!r}")
        if int(rate_buckets) < 1:
            raise ValueError(f"rate_buckets must be >= 1, got {rate_buckets!r}")
        if not (math.isfinite(reference_cycles) and reference_cycles > 0):
            raise ValueError(f"reference_cycles must be positive, got {reference_cycles!r}")
        if backend == "auto":
            backend = "numba" if _commit_compiled is not None else "numpy"
        if backend not in ("numba", "numpy") or (backend == "numba" and _commit_compiled is None):
            raise ValueError(f"backend {backend!r} is not available")
        self.sn_curve = sn_curve
        self.backend = backend
        self.rate_window_s = float(rate_window_s)
        self.rate_buckets = int(rate_buckets)
        self.reference_cycles = float(reference_cycles)
        self._edges = edges
        # bins between edges, then one overflow bin (ranges >= last edge)
        self._hist = np.zeros(edges.size)
        self._committed = 0.0
        self._provisional = 0.0
        self._cycles = 0.0
        self._t_first: float | None = None
        self._t_last: float | None = None
        self._buckets: dict[int, float] = {}
        self._setup_kernel()

    def _setup_kernel(self) -> None:
        m, log_a, bounds = self.sn_curve._segments
        c = self.sn_curve
        self._seg_m = m
        self._seg_coef = c.dff * 10.0 ** -log_a
        self._bounds = bounds
        self._cutoff = float(c.endurance_MPa) if c.low_stress == "cutoff" else 0.0
        # mean-free curves go straight to the compiled loop with this range scale
        self._scale = c.scf * c.derating / 1e6
        self._needs_means = c.mean_correction != "none"

    # ------------------------------------------------------------------ updating
    def add_cycles(self, ranges_Pa, counts, means_Pa=None, time_s: float | None = None) -> float:
        """Commit closed cycles; return the damage they add (see module docstring)."""
        r = np.asarray(ranges_Pa, dtype=np.float64)
        n = np.asarray(counts, dtype=np.float64)
        if n.shape != r.shape:
            n = np.broadcast_to(n, r.shape)
        if time_s is not None:
            self._check_time(time_s)
        if r.size == 0:
            if time_s is not None:
                self._date(0.0, float(time_s))
            return 0.0
        if self._needs_means:
            if means_Pa is None:
                raise ValueError(f"the S-N curve's mean_correction={self.sn_curve.mean_correction!r} needs means_Pa")
            # mean-corrected effective ranges replace the ranges; the histogram keeps the raw ones
            eff = self.sn_curve.effective_range_MPa(r, means_Pa) / self._scale
            added = self._commit(eff, n, r)
        else:
            added = self._commit(r, n, r)
        self._cycles += float(np.sum(n))
        if time_s is not None:
            self._date(added, float(time_s))
        return added

    def _commit(self, eff: np.ndarray, n: np.ndarray, raw: np.ndarray) -> float:
        if self.backend == "numba" and eff is raw:
            committed, added, bad = _commit_compiled(eff, n, self._scale, self._seg_m, self._seg_coef,
                                                     self._bounds, self._cutoff, self._committed,
                                                     self._edges, self._hist)
            if bad >= 0:
                raise ValueError(f"cycle {bad} has an invalid range or count ({raw[bad]!r}, {n[bad]!r})")
            self._committed = committed
            return added
        bad = np.flatnonzero(~((raw >= 0) & np.isfinite(raw) & (n >= 0) & np.isfinite(n)))
        if bad.size:
            raise ValueError(f"cycle {bad[0]} has an invalid range or count ({raw[bad[0]]!r}, {n[bad[0]]!r})")
        s = eff * self._scale
        seg = self._seg_m.size - 1 - np.searchsorted(self._bounds, s, side="right")
        d = n * (self._seg_coef[seg] * np.power(s, self._seg_m[seg]))
        if self._cutoff > 0:
            d = np.where(s >= self._cutoff, d, 0.0)
        start = self._committed
        # sequential (cumulative) sum in closure order: split invariant, unlike np.sum
        self._committed = float(np.cumsum(np.concatenate(([start], d)))[-1])
        idx = np.searchsorted(self._edges, raw, side="right") - 1
        inside = idx >= 0
        np.add.at(self._hist, idx[inside], n[inside])
        return self._committed - start

    def set_provisional(self, ranges_Pa, counts, means_Pa=None) -> float:
        """Set the provisional damage from the rainflow residue half cycles; return it."""
        d = self.sn_curve.damage_per_cycle(np.asarray(ranges_Pa, dtype=np.float64),
                                           np.asarray(counts, dtype=np.float64), means_Pa)
        self._provisional = float(np.sum(d))
        return self._provisional

    def _check_time(self, time_s: float) -> None:
        if not math.isfinite(time_s):
            raise ValueError(f"time_s must be finite, got {time_s!r}")
        if self._t_last is not None and time_s < self._t_last:
            raise ValueError(f"time_s went backwards: {time_s!r} < {self._t_last!r}")

    def _date(self, added: float, t: float) -> None:
        if self._t_first is None:
            self._t_first = t
        self._t_last = t
        width = self.rate_window_s / self.rate_buckets
        b = math.floor(t / width)
        self._buckets[b] = self._buckets.get(b, 0.0) + added
        oldest = b - self.rate_buckets
        if len(self._buckets) > self.rate_buckets + 1:
            self._buckets = {k: v for k, v in self._buckets.items() if k > oldest}

    # ------------------------------------------------------------------ results
    @property
    def damage_committed(self) -> float:
        return self._committed

    @property
    def damage_provisional(self) -> float:
        return self._provisional

    @property
    def damage(self) -> float:
        return self._committed + self._provisional

    @property
    def total_cycles(self) -> float:
        return self._cycles

    @property
    def damage_rate_per_day(self) -> float:
        """Committed damage per day over the last window (0 until time has passed)."""
        if self._t_last is None or self._t_last <= self._t_first:
            return 0.0
        width = self.rate_window_s / self.rate_buckets
        newest = math.floor(self._t_last / width)
        in_window = sum(v for k, v in self._buckets.items() if k > newest - self.rate_buckets)
        # the window's buckets span from the oldest kept bucket's start to now
        span = min(self._t_last - self._t_first, self._t_last - (newest - self.rate_buckets + 1) * width)
        return in_window / span * _DAY_S if span > 0 else 0.0

    @property
    def remaining_life_days(self) -> float:
        rate = self.damage_rate_per_day
        if rate <= 0.0:
            return math.inf
        return max(0.0, 1.0 - self.damage) / rate

    @property
    def histogram(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(edges_Pa, counts per bin, overflow count above the last edge), committed cycles."""
        return self._edges.copy(), self._hist[:-1].copy(), float(self._hist[-1])

    def equivalent_stress_range(self, reference_cycles: float | None = None) -> float:
        """Zero-mean stress range [Pa] whose ``reference_cycles`` give the committed damage."""
        n_ref = self.reference_cycles if reference_cycles is None else float(reference_cycles)
        if not (math.isfinite(n_ref) and n_ref > 0):
            raise ValueError(f"reference_cycles must be positive, got {reference_cycles!r}")
        if self._committed <= 0.0:
            return 0.0
        return float(self.sn_curve.stress_range_at(n_ref * self.sn_curve.dff / self._committed))

    # --------------------------------------------------------------- persistence
    def state(self) -> dict:
        return {
            "version": _STATE_VERSION,
            "sn_curve": self.sn_curve.to_dict(),
            "histogram_edges_Pa": [float(v) for v in self._edges],
            "histogram_counts": [float(v) for v in self._hist],
            "rate_window_s": self.rate_window_s,
            "rate_buckets": self.rate_buckets,
            "reference_cycles": self.reference_cycles,
            "committed": self._committed,
            "provisional": self._provisional,
            "cycles": self._cycles,
            "t_first": self._t_first,
            "t_last": self._t_last,
            "buckets": [[int(k), float(v)] for k, v in sorted(self._buckets.items())],
        }

    @classmethod
    def from_state(cls, state: dict, backend: Literal["auto", "numba", "numpy"] = "auto") -> "MinerAccumulator":
        if state.get("version") != _STATE_VERSION:
            raise ValueError(f"unsupported MinerAccumulator state version {state.get('version')!r}")
        acc = cls(SNCurve.from_dict(state["sn_curve"]), histogram_edges_Pa=state["histogram_edges_Pa"],
                  rate_window_s=state["rate_window_s"], rate_buckets=state["rate_buckets"],
                  reference_cycles=state["reference_cycles"], backend=backend)
        hist = np.asarray(state["histogram_counts"], dtype=np.float64)
        if hist.shape != acc._hist.shape:
            raise ValueError("histogram_counts does not match histogram_edges_Pa")
        acc._hist[:] = hist
        acc._committed = float(state["committed"])
        acc._provisional = float(state["provisional"])
        acc._cycles = float(state["cycles"])
        acc._t_first = None if state["t_first"] is None else float(state["t_first"])
        acc._t_last = None if state["t_last"] is None else float(state["t_last"])
        acc._buckets = {int(k): float(v) for k, v in state["buckets"]}
        return acc
