"""Damage rate per sea state: a table over (Hs, Tp) bins, learned from data, filled by physics.

Per component, each bin holds what was *seen* (hours of data in that sea state, the damage
they produced, and the sum of squares of the per-window damage rates, for their spread) and,
where the physics model was run, a *model* rate. A bin's rate is the learned mean when it
holds at least ``min_hours`` of data, else the model's; each answer says which it used and
how many hours it holds.

Band of a bin's rate (per component, per hour):

* learned: mean +/- 1.96 standard errors of the per-window rates (n >= 2 windows); with a
  single window the model band below applies around it;
* model: the rate divided / multiplied by ``model_factor`` (default 2: the spread between
  the dynamic estimate and the WAVFOR bound at the seed 004 storm, docs/FORECAST.md).

A forecast over many sea states adds the bins' rates x hours; its band adds the bins' lows
and highs (fully correlated errors: the conservative choice, since one model error affects
every bin alike).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

LEARNED, MODEL, NONE = "learned", "model", "none"

# default bins: 0.1 m of Hs up to 10 m, 1 s of Tp from 1 to 25 s (a hindcast of NDBC 44007,
# bench/bench_forecast.py, forecast the second half of 1996 12 % high with these, 22 % with
# 0.25 m bins: the damage rate is steep in Hs, so narrow Hs bins matter most)
HS_EDGES_M = np.arange(0.0, 10.0 + 1e-9, 0.1)
TP_EDGES_S = np.arange(1.0, 25.0 + 1e-9, 1.0)


def step_hours(t_s: ArrayLike) -> NDArray[np.float64]:
    """How long each sea state of a series at increasing times ``t_s`` (s) lasts: until the
    next one, at most 3 times the median step (a longer gap is missing data, not a long sea
    state); the last one lasts one median step (a single one, one hour)."""
    t = np.asarray(t_s, dtype=float)
    if t.size < 2:
        return np.ones(t.size)
    gaps = np.diff(t) / 3600.0
    step = float(np.median(gaps))
    return np.append(np.minimum(gaps, 3.0 * step), step)


@dataclass(frozen=True)
class BinRates:
    """Rates (damage per hour) for a series of sea states, per component (rows) and state
    (columns), with their band, the source per state and the hours of data per bin."""

    rate: NDArray[np.float64]
    low: NDArray[np.float64]
    high: NDArray[np.float64]
    source: NDArray[np.str_]
    hours_in_bin: NDArray[np.float64]


class DamageRateTable:
    """Damage rate per component over (Hs, Tp) bins (see the module docstring).

    Args:
        components: component names (rows of every figure).
        hs_edges_m, tp_edges_s: bin edges, strictly increasing; sea states outside them go
            into the edge bins (a forecast storm beyond the table is then flagged by
            :meth:`outside`).
        min_hours: data hours from which a bin's learned rate is used.
        model_factor: the model rate's band factor (> 1).
    """

    def __init__(self, components: Sequence[str], hs_edges_m: ArrayLike, tp_edges_s: ArrayLike,
                 min_hours: float = 1.0, model_factor: float = 2.0) -> None:
        self.components = tuple(components)
        self.hs_edges = _edges("hs_edges_m", hs_edges_m)
        self.tp_edges = _edges("tp_edges_s", tp_edges_s)
        if not (math.isfinite(min_hours) and min_hours > 0):
            raise ValueError(f"min_hours = {min_hours!r}: must be > 0")
        if not (math.isfinite(model_factor) and model_factor > 1):
            raise ValueError(f"model_factor = {model_factor!r}: must be > 1")
        self.min_hours = float(min_hours)
        self.model_factor = float(model_factor)
        shape = (self.hs_edges.size - 1, self.tp_edges.size - 1)
        nc = len(self.components)
        self.hours = np.zeros(shape)
        self.windows = np.zeros(shape)
        self.damage = np.zeros((nc, *shape))
        self.rate_sq = np.zeros((nc, *shape))  # sum over windows of (damage / hours)^2
        self.model_rate = np.full((nc, *shape), np.nan)

    @property
    def shape(self) -> tuple[int, int]:
        return self.hours.shape  # type: ignore[return-value]

    def centres(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Bin centres (Hs in m, Tp in s)."""
        return (0.5 * (self.hs_edges[:-1] + self.hs_edges[1:]),
                0.5 * (self.tp_edges[:-1] + self.tp_edges[1:]))

    def bin_of(self, hs_m: ArrayLike, tp_s: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Bin indices of sea states (clipped to the edge bins)."""
        hs = np.asarray(hs_m, dtype=float)
        tp = np.asarray(tp_s, dtype=float)
        i = np.clip(np.searchsorted(self.hs_edges, hs, side="right") - 1, 0, self.shape[0] - 1)
        j = np.clip(np.searchsorted(self.tp_edges, tp, side="right") - 1, 0, self.shape[1] - 1)
        return i, j

    def outside(self, hs_m: ArrayLike, tp_s: ArrayLike) -> NDArray[np.bool_]:
        """True for sea states beyond the table's edges (their rate is an edge bin's)."""
        hs = np.asarray(hs_m, dtype=float)
        tp = np.asarray(tp_s, dtype=float)
        return ((hs < self.hs_edges[0]) | (hs > self.hs_edges[-1])
                | (tp < self.tp_edges[0]) | (tp > self.tp_edges[-1]))

    def learn(self, hs_m: float, tp_s: float, hours: float, damage: Sequence[float]) -> None:
        """Add one window of data: its sea state, duration and damage per component."""
        d = np.asarray(damage, dtype=float)
        # scalar checks and bins (bin_of's, by bisection): the learner calls this once a
        # window, where numpy's per-call overhead on a few values was most of the cost
        if d.shape != (len(self.components),) or not all(
                math.isfinite(v) and v >= 0 for v in d.tolist()):
            raise ValueError("damage: one finite value >= 0 per component")
        if not (math.isfinite(hs_m) and math.isfinite(tp_s) and hs_m >= 0 and tp_s > 0):
            raise ValueError(f"sea state Hs = {hs_m!r} m, Tp = {tp_s!r} s: need Hs >= 0, Tp > 0")
        if not (math.isfinite(hours) and hours > 0):
            raise ValueError(f"hours = {hours!r}: must be > 0")
        i = min(max(bisect.bisect_right(self.hs_edges.tolist(), hs_m) - 1, 0), self.shape[0] - 1)
        j = min(max(bisect.bisect_right(self.tp_edges.tolist(), tp_s) - 1, 0), self.shape[1] - 1)
        self.hours[i, j] += hours
        self.windows[i, j] += 1
        self.damage[:, i, j] += d
        self.rate_sq[:, i, j] += (d / hours) ** 2

    def set_model_rate(self, rate_per_hour: ArrayLike) -> None:
        """The physics model's damage per hour, shape (components, Hs bins, Tp bins); NaN
        where the model was not run."""
        r = np.asarray(rate_per_hour, dtype=float)
        if r.shape != self.model_rate.shape:
            raise ValueError(f"model rate shape {r.shape} != {self.model_rate.shape}")
        if np.any(r[np.isfinite(r)] < 0):
            raise ValueError("model rates must be >= 0")
        self.model_rate = r.copy()

    def rates(self, hs_m: ArrayLike, tp_s: ArrayLike) -> BinRates:
        """Per component and sea state: damage per hour, its band and where it came from."""
        i, j = self.bin_of(hs_m, tp_s)
        hours = self.hours[i, j]
        n = self.windows[i, j]
        learned = hours >= self.min_hours
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = self.damage[:, i, j] / hours
            var = (self.rate_sq[:, i, j] / n - mean**2) * n / (n - 1)
            se = np.sqrt(np.maximum(var, 0.0) / n)
        model = self.model_rate[:, i, j]
        use_model = ~learned & np.isfinite(model)
        rate = np.where(learned, mean, np.where(use_model, model, np.nan))
        f = self.model_factor
        # a learned bin of a single window has no spread of its own: the model's band
        single = learned & (n < 2)
        low = np.where(learned & ~single, np.maximum(mean - 1.96 * se, 0.0), rate / f)
        high = np.where(learned & ~single, mean + 1.96 * se, rate * f)
        source = np.where(learned, LEARNED, np.where(use_model, MODEL, NONE))
        return BinRates(rate, low, high, source, hours)

    def to_state(self) -> dict[str, Any]:
        return {"components": list(self.components), "hs_edges_m": self.hs_edges.tolist(),
                "tp_edges_s": self.tp_edges.tolist(), "min_hours": self.min_hours,
                "model_factor": self.model_factor, "hours": self.hours.tolist(),
                "windows": self.windows.tolist(), "damage": self.damage.tolist(),
                "rate_sq": self.rate_sq.tolist(),
                "model_rate": [[[None if not math.isfinite(v) else v for v in row]
                                for row in comp] for comp in self.model_rate.tolist()]}

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> "DamageRateTable":
        t = cls(state["components"], state["hs_edges_m"], state["tp_edges_s"],
                state["min_hours"], state["model_factor"])
        t.hours = np.array(state["hours"], dtype=float).reshape(t.shape)
        t.windows = np.array(state["windows"], dtype=float).reshape(t.shape)
        nc = len(t.components)
        t.damage = np.array(state["damage"], dtype=float).reshape(nc, *t.shape)
        t.rate_sq = np.array(state["rate_sq"], dtype=float).reshape(nc, *t.shape)
        t.model_rate = np.array(state["model_rate"], dtype=float).reshape(nc, *t.shape)
        return t


def _edges(name: str, e: ArrayLike) -> NDArray[np.float64]:
    a = np.asarray(e, dtype=float)
    if a.ndim != 1 or a.size < 2 or not np.all(np.isfinite(a)) or np.any(np.diff(a) <= 0):
        raise ValueError(f"{name} must be at least two finite, strictly increasing edges")
    return a


@dataclass(frozen=True)
class Projection:
    """Damage projected over a forecast, per component (rows) at the end of each step
    (columns), with its band; ``crossings[c][threshold] = (central, earliest)`` step-end
    times (s) at which the threshold is first reached, None if not within the forecast."""

    t_end_s: NDArray[np.float64]
    damage: NDArray[np.float64]
    low: NDArray[np.float64]
    high: NDArray[np.float64]
    crossings: list[dict[float, tuple[float | None, float | None]]]


def project_damage(t_start_s: ArrayLike, hours: ArrayLike, rates: BinRates,
                   damage_now: Sequence[float], thresholds: Sequence[float] = ()) -> Projection:
    """Cumulative damage over forecast steps starting at ``t_start_s`` and lasting ``hours``,
    from per-step rates (:meth:`DamageRateTable.rates`), added to ``damage_now``.

    A step whose rate is unknown (source ``none``) adds nothing and makes the rest of that
    component's projection NaN: a forecast never pretends to know a sea state it cannot rate.
    A threshold is reached within a step by linear interpolation of that step's damage.
    """
    t0 = np.asarray(t_start_s, dtype=float)
    h = np.asarray(hours, dtype=float)
    d0 = np.asarray(damage_now, dtype=float)
    if t0.shape != h.shape or t0.ndim != 1 or np.any(~np.isfinite(h)) or np.any(h < 0):
        raise ValueError("t_start_s and hours: 1-D, same length, hours finite and >= 0")
    cum = [d0[:, None] + np.cumsum(r * h[None, :], axis=1)
           for r in (rates.rate, rates.low, rates.high)]
    t_end = t0 + 3600.0 * h
    crossings: list[dict[float, tuple[float | None, float | None]]] = []
    for c in range(d0.size):
        per: dict[float, tuple[float | None, float | None]] = {}
        for thr in thresholds:
            per[float(thr)] = (_first_crossing(thr, d0[c], cum[0][c], t0, t_end),
                               _first_crossing(thr, d0[c], cum[2][c], t0, t_end))
        crossings.append(per)
    return Projection(t_end, cum[0], cum[1], cum[2], crossings)


def _first_crossing(threshold: float, d0: float, cum: NDArray[np.float64],
                    t0: NDArray[np.float64], t_end: NDArray[np.float64]) -> float | None:
    if d0 >= threshold:
        return float(t0[0]) if t0.size else None
    hit = np.flatnonzero(cum >= threshold)  # NaN compares False: unknown steps never cross
    if hit.size == 0:
        return None
    k = int(hit[0])
    before = d0 if k == 0 else float(cum[k - 1])
    frac = (threshold - before) / (float(cum[k]) - before)
    return float(t0[k] + frac * (t_end[k] - t0[k]))
