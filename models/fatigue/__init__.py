"""Fatigue engine: the stable import path for S-N curves, streaming rainflow and Miner damage.

Modules: ``sn_curve``, ``rainflow``, ``miner``, ``ticks`` (the alert-tick pass), ``_loops``
(their compiled loops, one file for numba's cache), ``spectral`` (damage rate from a stress
spectrum), ``lab_calibration`` (seed 004's lab test and the curve calibrated to it).

- ``SNCurve`` (``models.fatigue.sn_curve``): S-N curves for stress RANGES in Pa.
- ``StreamingRainflow`` (``models.fatigue.rainflow``): incremental four-point counting.
- ``MinerAccumulator`` (``models.fatigue.miner``): committed/provisional damage, rate, histogram;
  ``remaining_life_days(damage, rate)``.
- ``commit_ticks`` (``models.fatigue.ticks``): the steps below for whole alert ticks in
  one compiled call (the monitor's path); the same bits as the separate calls.
- ``damage(stress_series_Pa, sn_curve, hysteresis=0.0, include_residue=True) -> float``:
  one-shot Miner damage of a whole stress history.

The monitor's hot path per block of tension samples::

    stress = conductor_stress(tension_N, cable, lay)          # models.helix
    ranges, means, counts = rainflow.feed(stress)
    miner.add_cycles(ranges, means, counts, time_s=t_end)
    miner.set_provisional_from(rainflow)                       # when a fresh figure is wanted

Cycles go as (ranges, means, counts) everywhere: ``feed`` returns them in that order and
``add_cycles`` takes them in it (means may be None for a curve without mean correction).
"""

from __future__ import annotations

import numpy as np

from models.fatigue.miner import MinerAccumulator, remaining_life_days
from models.fatigue.rainflow import StreamingRainflow
from models.fatigue.sn_curve import SNCurve
from models.fatigue.ticks import TickCommits, commit_ticks

__all__ = ["SNCurve", "StreamingRainflow", "MinerAccumulator", "TickCommits",
           "commit_ticks", "damage", "remaining_life_days"]


def damage(stress_series_Pa, sn_curve: SNCurve, hysteresis: float = 0.0, include_residue: bool = True) -> float:
    """Miner damage of a stress history [Pa]: four-point cycles plus, by default, the
    residue counted as ASTM half cycles (i.e. the ASTM E1049 total)."""
    rainflow = StreamingRainflow(hysteresis=hysteresis)
    miner = MinerAccumulator(sn_curve)
    ranges, means, counts = rainflow.feed(np.asarray(stress_series_Pa, dtype=np.float64))
    miner.add_cycles(ranges, means, counts)
    if include_residue:
        miner.set_provisional_from(rainflow)
    return miner.damage
