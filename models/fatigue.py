"""Fatigue engine: the stable import path for S-N curves, streaming rainflow and Miner damage.

- ``SNCurve`` (``models.sn_curve``): S-N curves for stress RANGES in Pa.
- ``StreamingRainflow`` (``models.rainflow_stream``): incremental four-point counting.
- ``MinerAccumulator`` (``models.miner``): committed/provisional damage, rate, histogram;
  ``remaining_life_days(damage, rate)``.
- ``FatigueStream`` (``models.fatigue_stream``): the three steps below fused in one
  compiled pass per chunk, ``feed_tension(tension_N, time_s) -> damage added``; the same
  bits as the separate calls, several times faster on large blocks.
- ``damage(stress_series_Pa, sn_curve, hysteresis=0.0, include_residue=True) -> float``:
  one-shot Miner damage of a whole stress history.

The monitor's hot path per block of tension samples::

    stress = conductor_stress(tension_N, cable, lay)          # models.helix
    ranges, means, counts = rainflow.feed(stress)
    miner.add_cycles(ranges, counts, means, time_s=t_end)
    miner.set_provisional_from(rainflow)                       # when a fresh figure is wanted

Note the orders: the rainflow returns (ranges, means, counts); ``add_cycles`` takes
(ranges, counts, means) so that means may be omitted for mean-free curves.
"""

from __future__ import annotations

import numpy as np

from models.fatigue_stream import FatigueStream, TickCommits, commit_ticks
from models.miner import MinerAccumulator, remaining_life_days
from models.rainflow_stream import StreamingRainflow
from models.sn_curve import SNCurve

__all__ = ["SNCurve", "StreamingRainflow", "MinerAccumulator", "FatigueStream", "TickCommits",
           "commit_ticks", "damage", "remaining_life_days"]


def damage(stress_series_Pa, sn_curve: SNCurve, hysteresis: float = 0.0, include_residue: bool = True) -> float:
    """Miner damage of a stress history [Pa]: four-point cycles plus, by default, the
    residue counted as ASTM half cycles (i.e. the ASTM E1049 total)."""
    rainflow = StreamingRainflow(hysteresis=hysteresis)
    miner = MinerAccumulator(sn_curve)
    ranges, means, counts = rainflow.feed(np.asarray(stress_series_Pa, dtype=np.float64))
    miner.add_cycles(ranges, counts, means)
    if include_residue:
        miner.set_provisional_from(rainflow)
    return miner.damage
