"""Palmgren-Miner damage accumulation for a stream of rainflow cycles.

``MinerAccumulator(sn_curve, histogram_edges_Pa=None, rate_window_s=86400.0,
rate_buckets=24, reference_cycles=1e7)``
  ``add_cycles(ranges_Pa, means_Pa, counts, time_s=None) -> float``
      commit closed cycles (never revised); returns the damage they added. ``time_s``
      (seconds, any epoch, non-decreasing) dates them for the damage rate.
  ``set_provisional(ranges_Pa, means_Pa, counts) -> float``
      replace the provisional damage (the rainflow residue's half cycles).
  ``set_provisional_from(rainflow) -> float``  the same from a ``StreamingRainflow``.
  ``residue_damage(rainflow) -> float``  that figure without storing it (one compiled pass,
                            cheap enough for every alert tick).
  ``damage_committed``, ``damage_provisional``, ``damage`` (= committed + provisional)
  ``damage_rate_per_day``   committed damage per day over the last ``rate_window_s``
  ``remaining_life_days``   (1 - damage) / rate (inf while the rate is zero, 0 once the
                            damage has reached 1)
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
import numpy as np

from models.fatigue import _loops
# a building block of the compiled tick dating, so it lives with the loops (numba's cache)
from models.fatigue._loops import remaining_life_days
from models.fatigue.sn_curve import SNCurve

_DAY_S = 86400.0
_STATE_VERSION = 1


class MinerAccumulator:
    """Committed + provisional Miner damage with rate, histogram and remaining life."""

    def __init__(self, sn_curve: SNCurve, histogram_edges_Pa=None, rate_window_s: float = _DAY_S,
                 rate_buckets: int = 24, reference_cycles: float = 1e7):
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
        self.sn_curve = sn_curve
        self.rate_window_s = float(rate_window_s)
        self.rate_buckets = int(rate_buckets)
        self.reference_cycles = float(reference_cycles)
        # row 0: edges; row 1: counts of the bins between edges, then the overflow bin
        self._table = np.zeros((2, edges.size))
        self._table[0] = edges
        self._committed = 0.0
        self._provisional = 0.0
        self._cycles = 0.0
        self._t_first: float | None = None
        self._t_last: float | None = None
        self._buckets: dict[int, float] = {}
        self._rate: float | None = None  # damage_rate_per_day until the next dated commit
        self._older: tuple[int, float] | None = None  # (newest bucket, sum of the older ones)
        self._setup_kernel()

    def _setup_kernel(self) -> None:
        self._params = self.sn_curve.kernel_params
        self._needs_means = self.sn_curve.mean_correction != "none"
        edges = self._table[0]
        width = (edges[-1] - edges[0]) / (edges.size - 1)
        uniform = np.allclose(np.diff(edges), width, rtol=1e-9, atol=0.0)
        self._inv_width = 1.0 / width if uniform else 0.0

    @property
    def _edges(self) -> np.ndarray:
        return self._table[0]

    @property
    def _hist(self) -> np.ndarray:
        return self._table[1]

    # ------------------------------------------------------------------ updating
    def add_cycles(self, ranges_Pa, means_Pa, counts, time_s: float | None = None) -> float:
        """Commit closed cycles; return the damage they add (see module docstring).

        The order of ``StreamingRainflow.feed``'s result: ``add_cycles(*rainflow.feed(x))``;
        ``means_Pa`` may be None for a curve without mean-stress correction."""
        r = np.asarray(ranges_Pa, dtype=np.float64)
        n = np.asarray(counts, dtype=np.float64)
        if n.shape != r.shape:
            n = np.broadcast_to(n, r.shape)
        time_s = self._check_time(time_s)
        if r.size == 0:
            added = 0.0
        else:
            start = self._committed
            if self._needs_means:
                if means_Pa is None:
                    raise ValueError(f"the S-N curve's mean_correction={self.sn_curve.mean_correction!r} needs means_Pa")
                # mean-corrected ranges drive the damage, the histogram keeps the nominal ones:
                # each cycle's damage first, then the compiled loop's in-order sum and binning
                _check_cycles(r, n)
                d = self.sn_curve.damage_per_cycle(r, means_Pa, n)
                committed, cycles = (_loops.commit_damage_compiled or _loops._commit_damage)(
                    r, n, np.ascontiguousarray(d, dtype=np.float64), self._table, self._inv_width, start)
            else:
                committed, _, cycles, bad = (_loops.commit_compiled or _loops.commit_loop)(
                    r, n, self._params, self._table, self._inv_width, start)
                if bad >= 0:  # nothing committed; the same test names the cycle
                    _check_cycles(r, n)
            self._committed = committed
            self._cycles += cycles
            added = committed - start
        if time_s is not None:
            self._date(added, time_s)
        return added

    def _check_time(self, time_s: float | None) -> float | None:
        if time_s is not None:
            time_s = float(time_s)
            if not math.isfinite(time_s) or (self._t_last is not None and time_s < self._t_last):
                raise ValueError(f"time_s must be finite and non-decreasing, got {time_s!r} after {self._t_last!r}")
        return time_s

    def _take_kernel_ticks(self, committed: np.ndarray, cycles: np.ndarray, times_s: np.ndarray,
                           residue: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Adopt the totals of a compiled loop that committed cycles on ``_params`` and
        ``_table`` (``models.fatigue.ticks``) for consecutive ticks (committed total, cycles
        and time of each, times non-decreasing), dating each tick's damage as
        :meth:`add_cycles` does; returns per tick the damage rate after it and, with the
        open residue's damage ``residue``, the damage and the remaining life. The ticks are
        a replay's per-tick hot path: one compiled pass (``_loops.date_loop``, the same
        float operations in the same order as :meth:`_date` and :meth:`_rate_per_day`)."""
        n_ticks = committed.shape[0]
        rates, damage, life = np.empty(n_ticks), np.empty(n_ticks), np.empty(n_ticks)
        if n_ticks == 0:
            return rates, damage, life
        n = len(self._buckets)
        keys, vals = np.empty(n + n_ticks, np.int64), np.empty(n + n_ticks)
        keys[:n], vals[:n] = list(self._buckets), list(self._buckets.values())
        prev, total, t_first, n = (_loops.date_compiled or _loops.date_loop)(
            committed, cycles, times_s, residue, self._committed, self._cycles,
            math.nan if self._t_first is None else self._t_first, keys, vals, n,
            self.rate_window_s / self.rate_buckets, self.rate_buckets, rates, damage, life)
        self._committed, self._cycles, self._t_first = float(prev), float(total), float(t_first)
        self._t_last = float(times_s[-1])
        self._buckets = dict(zip(keys[:int(n)].tolist(), vals[:int(n)].tolist()))
        self._rate, self._older = float(rates[-1]), None
        return rates, damage, life

    def set_provisional(self, ranges_Pa, means_Pa, counts) -> float:
        """Set the provisional damage from the rainflow residue half cycles; return it."""
        self._provisional = _in_order_sum(self.sn_curve.damage_per_cycle(ranges_Pa, means_Pa, counts))
        return self._provisional

    def residue_damage(self, rainflow) -> float:
        """Damage of a ``StreamingRainflow``'s open residue counted as ASTM E1049 counts the
        end of a series (``rainflow.residue_half_cycles()``), each cycle's damage as the
        committed ones', summed in counting order; nothing is stored. Cheap enough for
        every alert tick: one compiled pass over the residue without mean correction."""
        if not self._needs_means:
            return (_loops.residue_compiled or _loops.residue_loop)(rainflow._st, self._params)
        return _in_order_sum(self.sn_curve.damage_per_cycle(*rainflow.residue_half_cycles()))

    def set_provisional_from(self, rainflow) -> float:
        """Provisional damage from a ``StreamingRainflow``'s residue; return it."""
        self._provisional = self.residue_damage(rainflow)
        return self._provisional

    def _date(self, added: float, t: float) -> None:
        self._rate = None
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
        if self._rate is None:  # read at every alert tick: computed once per dated commit
            self._rate = self._rate_per_day()
        return self._rate

    def _rate_per_day(self) -> float:
        if self._t_last is None or self._t_first is None or self._t_last <= self._t_first:
            return 0.0
        width = self.rate_window_s / self.rate_buckets
        newest = math.floor(self._t_last / width)
        last = self._buckets.get(newest)
        if last is None or next(reversed(self._buckets)) != newest:  # not from _date: sum all
            in_window = sum(v for k, v in self._buckets.items() if k > newest - self.rate_buckets)
        else:
            # buckets are dated in time order, so the newest is summed last and only it changes
            # between commits: the sum of the older ones (in the same order) is kept per newest
            if self._older is None or self._older[0] != newest:
                self._older = (newest, sum(v for k, v in self._buckets.items()
                                           if newest - self.rate_buckets < k < newest))
            in_window = self._older[1] + last
        # the window's buckets span from the oldest kept bucket's start to now
        span = min(self._t_last - self._t_first, self._t_last - (newest - self.rate_buckets + 1) * width)
        return in_window / span * _DAY_S if span > 0 else 0.0

    @property
    def remaining_life_days(self) -> float:
        return remaining_life_days(self.damage, self.damage_rate_per_day)

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
            "histogram_edges_Pa": [float(v) for v in self._table[0]],
            "histogram_counts": [float(v) for v in self._table[1]],
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
    def from_state(cls, state: dict) -> "MinerAccumulator":
        if state.get("version") != _STATE_VERSION:
            raise ValueError(f"unsupported MinerAccumulator state version {state.get('version')!r}")
        acc = cls(SNCurve.from_dict(state["sn_curve"]), histogram_edges_Pa=state["histogram_edges_Pa"],
                  rate_window_s=state["rate_window_s"], rate_buckets=state["rate_buckets"],
                  reference_cycles=state["reference_cycles"])
        hist = np.asarray(state["histogram_counts"], dtype=np.float64)
        if hist.shape != acc._table[1].shape:
            raise ValueError("histogram_counts does not match histogram_edges_Pa")
        acc._table[1] = hist
        acc._committed = float(state["committed"])
        acc._provisional = float(state["provisional"])
        acc._cycles = float(state["cycles"])
        acc._t_first = None if state["t_first"] is None else float(state["t_first"])
        acc._t_last = None if state["t_last"] is None else float(state["t_last"])
        acc._buckets = {int(k): float(v) for k, v in state["buckets"]}
        acc._rate = acc._older = None
        return acc


def _check_cycles(ranges: np.ndarray, counts: np.ndarray) -> None:
    """ValueError naming the first cycle with a negative or non-finite range or count."""
    bad = np.flatnonzero(~((ranges >= 0) & np.isfinite(ranges) & (counts >= 0) & np.isfinite(counts)))
    if bad.size:
        raise ValueError(f"cycle {bad[0]} has an invalid range or count ({ranges[bad[0]]!r}, {counts[bad[0]]!r})")


def _in_order_sum(damages: np.ndarray) -> float:
    """The damages added one by one in order, as the compiled loops add them (numpy's
    ``sum`` is pairwise: other last bits)."""
    return float(np.cumsum(damages)[-1]) if damages.size else 0.0
