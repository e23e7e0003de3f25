"""Sea-state statistics -> fatigue load environment (load-cycle histogram, damage).

The 1981 study (seed 004, App. 6, Fig. A6.4) built its "fatigue load environment" this way:
wave heights from a percentage-exceedance graph, a period per height (T = H + 2.5 s), a cable
force per wave from WAVFOR, and the number of waves per year. This module does the same for
any source of sea states:

* :func:`sea_states_from_exceedance`: an exceedance distribution of wave height (percent of
  the time a height is exceeded) and a period rule -> a table of (H, T, hours).
* :func:`sea_states_from_records`: hourly (Hs, T) records (e.g. NDBC) -> a scatter table.
* :func:`load_cycles`: per sea state, the number of waves (hours x 3600 / period) and the
  load range of each through a transfer function ``load_range(H, T) -> N``. ``"regular"``
  treats each row as waves of height H (seed 004); ``"rayleigh"`` treats H as Hs of an
  irregular sea whose individual heights are Rayleigh distributed, P(H > h) = exp(-2 h^2/Hs^2),
  all with the zero-crossing period.
* :func:`simulated_load_cycles`: per sea state, a simulated buoy motion
  (:func:`models.waves.buoy_motion`) through the motion -> tension estimator, rainflow-counted
  (ASTM E1049, package ``rainflow``) and scaled to the row's duration: the dynamic
  estimate instead of the WAVFOR bound.
* :meth:`LoadCycles.histogram` bins the cycles; :func:`damage` gives the Miner damage of each
  entry against an S-N curve (``models.fatigue.SNCurve`` or any object with
  ``damage_per_cycle(range_Pa, mean_Pa, counts)``) after an optional tension -> stress map
  (e.g. ``models.helix.conductor_stress``); per storm with :func:`damage_per_row`, per year
  with :func:`annual_damage`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Literal

import numpy as np
import rainflow
from numpy.typing import ArrayLike, NDArray

from models.estimator import EstimatorConfig, QuasiStatic, simulate_tension
from models.fatigue.spectral import DamageCurve
from models.waves import buoy_motion
from models.wavfor import WavforBuoy, seed004_period, wavfor

HOURS_PER_YEAR = 8766.0  # 365.25 days
# Tz / Tp of a JONSWAP spectrum with gamma = 3.3 (DNV-RP-C205 3.5.5.4).
TZ_OVER_TP_JONSWAP = 0.7782

LoadRange = Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]]


@dataclass(frozen=True)
class SeaStateTable:
    """Rows of sea states: height (m; H of regular waves or Hs), period (s), duration (h)."""

    height: NDArray[np.float64]
    period: NDArray[np.float64]
    hours: NDArray[np.float64]

    def __post_init__(self) -> None:
        h, t, d = (np.asarray(a, dtype=float) for a in (self.height, self.period, self.hours))
        if not (h.shape == t.shape == d.shape and h.ndim == 1):
            raise ValueError("height, period and hours must be 1-D arrays of the same length")
        for name, a in (("height", h), ("period", t), ("hours", d)):
            if not np.all(np.isfinite(a)) or np.any(a < 0):
                raise ValueError(f"sea-state {name} must be finite and >= 0")
        if np.any(t[d > 0] <= 0):
            raise ValueError("sea-state period must be > 0 where hours > 0")
        object.__setattr__(self, "height", h)
        object.__setattr__(self, "period", t)
        object.__setattr__(self, "hours", d)

    @property
    def total_hours(self) -> float:
        return float(self.hours.sum())


def sea_states_from_exceedance(
    heights: ArrayLike,
    exceedance_pct: ArrayLike,
    total_hours: float = HOURS_PER_YEAR,
    period_rule: Callable[[NDArray[np.float64]], NDArray[np.float64]] = seed004_period,
    representative: Literal["upper", "mid"] = "upper",
) -> SeaStateTable:
    """Exceedance curve (height m ascending, % of time exceeded, descending) -> sea states.

    Bin i spans heights[i]..heights[i+1] and lasts (P_i - P_{i+1}) / 100 x total_hours; the
    last bin (above heights[-1]) lasts P_last / 100 x total_hours at heights[-1]. The bin's
    height is its upper edge (conservative, default) or its midpoint; the period comes from
    ``period_rule`` (default seed 004's T = H + 2.5 s). Time below heights[0] is calm.
    """
    h = np.asarray(heights, dtype=float)
    p = np.asarray(exceedance_pct, dtype=float)
    if h.ndim != 1 or h.shape != p.shape or h.size < 1:
        raise ValueError("heights and exceedance_pct must be 1-D arrays of the same length")
    if not (np.all(np.isfinite(h)) and np.all(np.isfinite(p))):
        raise ValueError("heights and exceedance_pct must be finite")
    if np.any(np.diff(h) <= 0) or np.any(h < 0):
        raise ValueError("heights must be >= 0 and strictly increasing")
    if np.any(np.diff(p) > 0) or np.any(p < 0) or np.any(p > 100):
        raise ValueError("exceedance_pct must be within 0..100 and non-increasing")
    if not (math.isfinite(total_hours) and total_hours > 0):
        raise ValueError(f"total_hours must be > 0, got {total_hours!r}")
    frac = np.append(p[:-1] - p[1:], p[-1]) / 100.0
    if representative == "upper":
        rep = np.append(h[1:], h[-1])
    elif representative == "mid":
        rep = np.append(0.5 * (h[:-1] + h[1:]), h[-1])
    else:
        raise ValueError(f"representative must be 'upper' or 'mid', got {representative!r}")
    return SeaStateTable(rep, np.asarray(period_rule(rep), dtype=float), frac * total_hours)


def sea_states_from_records(
    height: ArrayLike,
    period: ArrayLike,
    hours_per_record: float,
    height_edges: ArrayLike,
    period_edges: ArrayLike,
) -> SeaStateTable:
    """Scatter table from sea-state records (e.g. hourly Hs, Tz): one row per occupied cell,
    at the cell's centre, lasting (records in the cell) x ``hours_per_record``.

    Records with NaN or outside the edges are dropped (count them from the arrays if needed).
    """
    hs = np.asarray(height, dtype=float)
    tt = np.asarray(period, dtype=float)
    he = np.asarray(height_edges, dtype=float)
    te = np.asarray(period_edges, dtype=float)
    if hs.shape != tt.shape or hs.ndim != 1:
        raise ValueError("height and period must be 1-D arrays of the same length")
    if not (math.isfinite(hours_per_record) and hours_per_record > 0):
        raise ValueError(f"hours_per_record must be > 0, got {hours_per_record!r}")
    for name, e in (("height_edges", he), ("period_edges", te)):
        if e.ndim != 1 or e.size < 2 or not np.all(np.isfinite(e)) or np.any(np.diff(e) <= 0):
            raise ValueError(f"{name} must be finite and strictly increasing")
    ok = np.isfinite(hs) & np.isfinite(tt)
    counts, _, _ = np.histogram2d(hs[ok], tt[ok], bins=(he, te))
    i, j = np.nonzero(counts)
    return SeaStateTable(
        0.5 * (he[i] + he[i + 1]), 0.5 * (te[j] + te[j + 1]), counts[i, j] * hours_per_record
    )


@dataclass(frozen=True)
class LoadCycles:
    """Load cycles as (range, count) pairs (N); ``row`` = the sea-state row each came from;
    ``means`` = the cycle mean loads (N) where known, else None."""

    ranges: NDArray[np.float64]
    counts: NDArray[np.float64]
    row: NDArray[np.int64]
    means: NDArray[np.float64] | None = None

    @property
    def total_cycles(self) -> float:
        return float(self.counts.sum())

    def histogram(self, edges: ArrayLike) -> NDArray[np.float64]:
        """Cycle counts per load-range bin (edges in N); ranges beyond the edges go into the
        last bin so no cycle is lost."""
        e = np.asarray(edges, dtype=float)
        if e.ndim != 1 or e.size < 2 or np.any(np.diff(e) <= 0):
            raise ValueError("edges must be strictly increasing")
        idx = np.clip(np.searchsorted(e, self.ranges, side="right") - 1, 0, e.size - 2)
        return np.bincount(idx, weights=self.counts, minlength=e.size - 1).astype(np.float64, copy=False)


def wavfor_load_range(buoy: WavforBuoy = WavforBuoy()) -> LoadRange:
    """Seed 004's transfer: the WAVFOR bound as a 0-to-F cycle (range = F, N) per wave."""

    def load_range(height: NDArray[np.float64], period: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.zeros_like(height, dtype=float)
        pos = height > 0
        out[pos] = wavfor(height[pos], period[pos], buoy).max_force
        return out

    return load_range


def load_cycles(
    table: SeaStateTable,
    load_range: LoadRange,
    waves: Literal["regular", "rayleigh"] = "regular",
    period_is: Literal["tz", "tp"] = "tz",
    tz_over_tp: float = TZ_OVER_TP_JONSWAP,
    n_heights: int = 40,
    max_height_ratio: float = 2.5,
    zero_to_peak: bool = False,
) -> LoadCycles:
    """Waves per sea state and their load ranges (see the module docstring).

    ``period_is`` says whether the table's period is the zero-crossing or the peak period
    (Tz = tz_over_tp x Tp). For ``"rayleigh"`` the individual heights are discretised into
    ``n_heights`` equal bins up to ``max_height_ratio`` x Hs (the tail beyond holds
    exp(-2 x 2.5^2) = 4e-6 of the waves and is put in the last bin), each at its
    probability-weighted RMS height. ``zero_to_peak``: each cycle goes from zero load to its
    range (mean = range / 2), as seed 004 read its WAVFOR bound and ran its lab test.
    """
    if period_is == "tz":
        tz = table.period
    elif period_is == "tp":
        tz = table.period * tz_over_tp
    else:
        raise ValueError(f"period_is must be 'tz' or 'tp', got {period_is!r}")
    live = table.hours > 0
    rows = np.flatnonzero(live)
    n_waves = table.hours[live] * 3600.0 / tz[live]
    if waves == "regular":
        h, t, n, row = table.height[live], tz[live], n_waves, rows
    elif waves == "rayleigh":
        if not (isinstance(n_heights, int) and n_heights >= 2 and max_height_ratio > 1):
            raise ValueError("n_heights must be an int >= 2 and max_height_ratio > 1")
        r = np.linspace(0.0, max_height_ratio, n_heights + 1)
        exceed = np.exp(-2.0 * r**2)
        p = exceed[:-1] - exceed[1:]
        p[-1] += exceed[-1]
        # E[r^2 | bin] for the Rayleigh law, so that sum p r^2 = E[r^2] = 1/2 exactly.
        moment = np.exp(-2.0 * r**2) * (r**2 + 0.5)  # integral of r^2 dP from r to infinity
        r2 = moment[:-1] - moment[1:]
        r2[-1] += moment[-1]
        r_rep = np.sqrt(r2 / p)
        h = (table.height[live][:, None] * r_rep[None, :]).ravel()
        t = np.repeat(tz[live], n_heights)
        n = (n_waves[:, None] * p[None, :]).ravel()
        row = np.repeat(rows, n_heights)
    else:
        raise ValueError(f"waves must be 'regular' or 'rayleigh', got {waves!r}")
    rng = np.asarray(load_range(h, t), dtype=float)
    if rng.shape != h.shape or not np.all(np.isfinite(rng)) or np.any(rng < 0):
        raise ValueError("load_range must return one finite range >= 0 per wave")
    return LoadCycles(ranges=rng, counts=n, row=row, means=0.5 * rng if zero_to_peak else None)


def simulated_load_cycles(
    table: SeaStateTable,
    config: EstimatorConfig,
    quasi_static: QuasiStatic,
    depth: float,
    duration_s: float = 1800.0,
    seed: int = 0,
    direction_deg: float = 0.0,
    gamma: float = 3.3,
) -> LoadCycles:
    """Rainflow cycles of the estimated tension in each sea state (height = Hs, period = Tp).

    Each row is simulated for ``duration_s`` at ``config.dt`` (seed ``seed + row``, so the
    result is deterministic) and its cycle counts are scaled by hours x 3600 / duration_s.
    Half cycles count 0.5. Rows with no hours or Hs = 0 contribute nothing.
    """
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be > 0, got {duration_s!r}")
    ranges, means, counts, rows = [], [], [], []
    for i in np.flatnonzero((table.hours > 0) & (table.height > 0)):
        m = buoy_motion(float(table.height[i]), float(table.period[i]), duration_s, config.dt,
                        seed + int(i), depth=depth, direction_deg=direction_deg, gamma=gamma)
        est = simulate_tension(m.heave, m.surge, m.sway, config, quasi_static)
        cyc = np.array([(r, mn, c) for r, mn, c, _, _ in rainflow.extract_cycles(est.tension)])
        if cyc.size == 0:
            continue
        scale = table.hours[i] * 3600.0 / duration_s
        ranges.append(cyc[:, 0])
        means.append(cyc[:, 1])
        counts.append(cyc[:, 2] * scale)
        rows.append(np.full(cyc.shape[0], i))
    if not ranges:
        return LoadCycles(np.empty(0), np.empty(0), np.empty(0, np.int64), np.empty(0))
    return LoadCycles(
        np.concatenate(ranges), np.concatenate(counts), np.concatenate(rows),
        np.concatenate(means),
    )


def damage(
    cycles: LoadCycles,
    sn_curve: DamageCurve,
    to_stress: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None,
) -> NDArray[np.float64]:
    """Palmgren-Miner damage of each load-cycle entry: counts / N(stress range).

    ``to_stress`` maps a tension (N) to a stress (Pa), applied to the ranges and, where
    known, the means (valid for a stress proportional to tension, as the helix model is
    for T >= 0); None = the loads are already stresses. The S-N curve applies its own
    factors (scf, derating, dff) and mean-stress correction. Sum the result for the total.
    """
    conv = (lambda a: a) if to_stress is None else (lambda a: np.asarray(to_stress(a), float))
    mean = None if cycles.means is None else conv(cycles.means)
    return np.asarray(sn_curve.damage_per_cycle(conv(cycles.ranges), mean, cycles.counts), float)


def damage_per_row(
    cycles: LoadCycles, per_cycle_damage: NDArray[np.float64], n_rows: int
) -> NDArray[np.float64]:
    """Damage per sea-state row (e.g. per storm) from :func:`damage`'s per-entry values."""
    return np.bincount(cycles.row, weights=per_cycle_damage, minlength=n_rows).astype(np.float64, copy=False)


def annual_damage(table: SeaStateTable, total_damage: float) -> float:
    """Scale the damage of ``table`` to one year (the table may cover any number of hours)."""
    if table.total_hours <= 0:
        raise ValueError("the sea-state table covers no time")
    return total_damage * HOURS_PER_YEAR / table.total_hours
