"""Fused fatigue hot path for one helical conductor: tension -> stress -> rainflow -> Miner.

``FatigueStream(cable, lay, rainflow, miner)``
  ``feed_tension(tension_N, time_s=None) -> float``  count a block of cable tensions [N]
      and commit the cycles it closes; returns the damage added. The same as ::

          stress = conductor_stress(tension_N, cable, lay)
          ranges, means, counts = rainflow.feed(stress)
          miner.add_cycles(ranges, counts, means, time_s=time_s)

      to the last bit of every state (rainflow stack, committed damage, cycle count,
      histogram, damage rate), so both may be mixed on the same counter and accumulator.
      With numba it runs as one compiled pass per cache-sized chunk of samples
      (``_fatigue_loops.tension_loop``), without the block-sized stress and cycle arrays.
      ``time_s`` is checked before anything is counted (the three calls above would
      have consumed the block before rejecting it). NaN/inf tension raises ValueError
      and counts nothing.
  ``rainflow``, ``miner``  the components it updates; persist them with their own
      ``state()``/``from_state`` and build a new ``FatigueStream`` around the restored ones.

The fused pass needs the numba backend on both components, the axial stress
(``combined=False``, an incompressible core) and a mean-free S-N curve; otherwise
``feed_tension`` runs the three calls above.

``commit_ticks(rainflow, miner, stress_Pa, stops, times_s, pending=None, residue=True)``
  the alert-tick pass of the monitor: tick k takes ``stress_Pa[stops[k-1]:stops[k]]``
  (from 0 for the first) and commits its closed cycles dated ``times_s[k]``, after the
  ``pending`` (ranges, counts) cycles closed earlier in the first tick. Returns a
  :class:`TickCommits` with each tick's committed damage, damage rate and (if
  ``residue``) the open residue's damage at its end (``MinerAccumulator.residue_damage``),
  and the closed cycles; or None when the compiled pass is unavailable (a numpy backend, a
  mean-corrected curve), then the caller runs ``rainflow.feed`` and ``miner.add_cycles``
  per tick, which give the same bits.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from models import _fatigue_loops as _loops
from models._fatigue_loops import CHUNK as _CHUNK
from models._fatigue_loops import HEADER as _HEADER
from models._fatigue_loops import NS as _NS
from models._jit import HAVE_NUMBA
from models.helix import HelixCable, Lay, axial_kernel_args, conductor_stress
from models.miner import MinerAccumulator
from models.rainflow_stream import StreamingRainflow


class FatigueStream:
    """Tension blocks -> conductor stress -> streaming rainflow -> committed Miner damage."""

    def __init__(self, cable: HelixCable, lay: Lay, rainflow: StreamingRainflow, miner: MinerAccumulator):
        if not isinstance(cable, HelixCable):
            raise ValueError(f"cable must be a HelixCable, got {type(cable).__name__}")
        if not isinstance(rainflow, StreamingRainflow) or not isinstance(miner, MinerAccumulator):
            raise ValueError("rainflow must be a StreamingRainflow and miner a MinerAccumulator")
        self.cable = cable
        self.lay = lay
        self.rainflow = rainflow
        self.miner = miner
        self._args = axial_kernel_args(cable, lay)  # checks lay
        self._fused = (HAVE_NUMBA and self._args is not None and rainflow.backend == "numba"
                       and miner.backend == "numba" and not miner._needs_means)

    def feed_tension(self, tension_N, time_s: float | None = None) -> float:
        """Count a block of tensions [N]; return the Miner damage of the cycles it closed."""
        t = np.asarray(tension_N, dtype=np.float64)
        time_s = self.miner._check_time(time_s)
        if not self._fused or t.ndim != 1:
            stress = conductor_stress(t, self.cable, self.lay)
            ranges, means, counts = self.rainflow.feed(stress)
            return self.miner.add_cycles(ranges, counts, means, time_s=time_s)
        # the compiled pass works on the components' own state arrays (same package)
        rf, miner = self.rainflow, self.miner
        # a bad sample after the first chunk is found once earlier chunks are counted:
        # keep what they may change (the state header and stack, the histogram)
        undo = (rf._st[:_HEADER + int(rf._st[_NS])].copy(), miner._table[1].copy()) if t.size > _CHUNK else None
        committed, cycles, used = miner._committed, 0.0, 0
        while True:
            committed, more, n = _loops.tension_compiled(t[used:], *self._args, rf._st, miner._params,
                                                         miner._table, miner._inv_width, committed)
            if n < 0:
                if undo is not None:
                    rf._st[:undo[0].size] = undo[0]
                    miner._table[1] = undo[1]
                raise ValueError(f"tension_N contains NaN or inf, or is out of range (index {used - n - 1}); "
                                 "block not counted")
            cycles += more
            used += n
            if used == t.size:
                break
            rf._grow()  # stack storage full: grow it and finish the block
        rf._samples += t.size
        return miner._take_kernel_totals(committed, cycles, time_s)


@dataclass(frozen=True)
class TickCommits:
    """What :func:`commit_ticks` did, per tick (arrays of the ticks' length) and in all."""

    committed: np.ndarray  # committed Miner damage at each tick's end
    rate_per_day: np.ndarray  # the accumulator's damage rate after each tick
    residue: np.ndarray  # damage of the open residue at each tick's end (NaN if not asked)
    ranges: np.ndarray  # the closed cycles (counts 1), closure order; pending ones excluded
    means: np.ndarray


def commit_ticks(rainflow: StreamingRainflow, miner: MinerAccumulator, stress_Pa: np.ndarray,
                 stops: Sequence[int], times_s: Sequence[float],
                 pending: tuple[np.ndarray, np.ndarray] | None = None,
                 residue: bool = True) -> TickCommits | None:
    """Stress samples through the counter and the accumulator tick by tick in one compiled
    pass (see the module docstring); None when that pass is unavailable."""
    ticks_compiled = _loops.ticks_compiled
    if (ticks_compiled is None or rainflow.backend != "numba" or miner.backend != "numba"
            or miner._needs_means):
        return None
    n_ticks = len(stops)
    x = np.ascontiguousarray(stress_Pa[:stops[-1]] if n_ticks else stress_Pa[:0], dtype=np.float64)
    pre_r, pre_c = pending if pending is not None else (np.zeros(0), np.zeros(0))
    # the compiled pass works on the components' own state arrays (same package)
    size = (int(rainflow._st[_NS]) + x.shape[0]) // 2 + 2  # each closed cycle pops two points
    out_r, out_m = np.empty(size), np.empty(size)
    committed, cycles = np.empty(n_ticks), np.empty(n_ticks)
    res = np.full(n_ticks, np.nan)
    stops_a = np.asarray(stops, dtype=np.int64)
    k, nc, total = 0, 0, miner._committed
    while k < n_ticks:
        k, nc, total = ticks_compiled(x, stops_a, k, rainflow._st, miner._params, miner._table,
                                      miner._inv_width, total, np.asarray(pre_r, np.float64),
                                      np.asarray(pre_c, np.float64), out_r, out_m, nc,
                                      committed, cycles, res, residue)
        if k < 0:
            raise ValueError("stress_Pa contains NaN or inf; nothing counted")
        if k < n_ticks:
            rainflow._grow()  # the next tick may not fit the stack storage
    rainflow._samples += x.shape[0]
    rates = np.empty(n_ticks)
    for i in range(n_ticks):  # date each tick's damage in order, as add_cycles does
        miner._take_kernel_totals(float(committed[i]), float(cycles[i]), float(times_s[i]))
        rates[i] = miner.damage_rate_per_day
    return TickCommits(committed, rates, res, out_r[:nc], out_m[:nc])
