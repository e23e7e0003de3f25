"""The monitor's alert-tick pass: stress -> rainflow -> Miner for whole ticks in one compiled call.

``commit_ticks(rainflow, miner, stress_Pa, stops, times_s, pending=None, residue=True)``
  tick k takes ``stress_Pa[stops[k-1]:stops[k]]``
  (from 0 for the first) and commits its closed cycles dated ``times_s[k]``, after the
  ``pending`` (ranges, means, counts) cycles closed earlier in the first tick. Returns a
  :class:`TickCommits` with each tick's committed damage, damage rate and (if
  ``residue``) the open residue's damage at its end (``MinerAccumulator.residue_damage``),
  the damage and remaining life (``remaining_life_days``) they give, and the closed
  cycles; or None for a mean-corrected curve (the pass commits nominal ranges), then the
  caller runs ``rainflow.feed`` and ``miner.add_cycles`` per tick, which give the same bits.
  Without numba the pass runs as plain Python.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from models.fatigue import _loops
from models.fatigue._loops import NS as _NS
from models.fatigue.miner import MinerAccumulator
from models.fatigue.rainflow import StreamingRainflow


@dataclass(frozen=True)
class TickCommits:
    """What :func:`commit_ticks` did, per tick (arrays of the ticks' length) and in all."""

    committed: np.ndarray  # committed Miner damage at each tick's end
    rate_per_day: np.ndarray  # the accumulator's damage rate after each tick
    residue: np.ndarray  # damage of the open residue at each tick's end (NaN if not asked)
    damage: np.ndarray  # committed + residue at each tick's end (NaN if not asked)
    life_days: np.ndarray  # remaining_life_days(damage, rate_per_day) (NaN if not asked)
    ranges: np.ndarray  # the closed cycles (counts 1), closure order; pending ones excluded
    means: np.ndarray


def commit_ticks(rainflow: StreamingRainflow, miner: MinerAccumulator, stress_Pa: np.ndarray,
                 stops: Sequence[int], times_s: Sequence[float],
                 pending: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                 residue: bool = True) -> TickCommits | None:
    """Stress samples through the counter and the accumulator tick by tick in one compiled
    pass (see the module docstring); None for a mean-corrected curve."""
    if miner._needs_means:
        return None
    ticks_loop = _loops.ticks_compiled or _loops.ticks_loop
    n_ticks = len(stops)
    x = np.ascontiguousarray(stress_Pa[:stops[-1]] if n_ticks else stress_Pa[:0], dtype=np.float64)
    pre_r, _, pre_c = pending if pending is not None else (np.zeros(0), None, np.zeros(0))
    # the compiled pass works on the components' own state arrays (same package)
    size = (int(rainflow._st[_NS]) + x.shape[0]) // 2 + 2  # each closed cycle pops two points
    out_r, out_m = np.empty(size), np.empty(size)
    committed, cycles = np.empty(n_ticks), np.empty(n_ticks)
    res = np.full(n_ticks, np.nan)
    stops_a = np.asarray(stops, dtype=np.int64)
    k, nc, total = 0, 0, miner._committed
    while k < n_ticks:
        k, nc, total = ticks_loop(x, stops_a, k, rainflow._st, miner._params, miner._table,
                                  miner._inv_width, total, np.asarray(pre_r, np.float64),
                                  np.asarray(pre_c, np.float64), out_r, out_m, nc,
                                  committed, cycles, res, residue)
        if k < 0:
            raise ValueError("stress_Pa contains NaN or inf; nothing counted")
        if k < n_ticks:
            rainflow._grow()  # the next tick may not fit the stack storage
    rainflow._samples += x.shape[0]
    # date each tick's damage in order, as add_cycles does
    rates, damage, life = miner._take_kernel_ticks(committed, cycles,
                                                   np.asarray(times_s, np.float64), res)
    return TickCommits(committed, rates, res, damage, life, out_r[:nc], out_m[:nc])
