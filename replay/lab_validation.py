"""Seed 004's lab fatigue test through the product: predicted against observed cycles to failure.

The App. 2 (c) test cycles a piece of the cable from 0 to F kN at 13.6 cycles/min
(``models.fatigue.lab_calibration.cam_tension``). Here that tension is a synthetic load-cell log fed through
the same pipeline as a buoy's (validation, load selection, stress per component, streaming
rainflow, Miner damage); each component's predicted life is the cycles fed over the damage they
caused. The observed lives (``models.fatigue.lab_calibration.LAB_FAILURES``) and the method are documented
in docs/CONDUCTOR.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from models.fatigue.lab_calibration import LAB_FAILURES, LAB_RATE_HZ, cam_tension
from monitor.blocks import SampleBlock
from monitor.config import Config
from replay.runner import run_blocks

T0_NS = 1_600_000_000 * 10 ** 9  # an arbitrary, fixed start (sensor time)


@dataclass(frozen=True)
class LabPrediction:
    """One test load: observed cycles and each component's predicted cycles to failure."""

    load_N: float
    observed_cycles: float
    predicted_cycles: dict[str, float]


def lab_tension_blocks(buoy_id: str, peak_N: float, n_cycles: int, sample_rate_hz: float = 10.0,
                       block_s: float = 1.0) -> list[SampleBlock]:
    """The cam test as load-cell blocks of ``block_s`` seconds at ``sample_rate_hz``."""
    per_cycle = int(round(sample_rate_hz / LAB_RATE_HZ))
    t_s, tension = cam_tension(peak_N, n_cycles, per_cycle)
    t_ns = T0_NS + np.round(t_s * 1e9).astype(np.int64)
    step = max(1, int(round(block_s * sample_rate_hz)))
    return [SampleBlock(buoy_id, "tension", t_ns[i:i + step], {"tension_N": tension[i:i + step]})
            for i in range(0, t_ns.shape[0], step)]


def predict(config: Config, peak_N: float, n_cycles: int = 200) -> dict[str, float]:
    """Cycles to failure per component for the 0 -> ``peak_N`` cam cycle: ``n_cycles`` fed
    through the pipeline, divided by the damage they caused (inf when there is none)."""
    pipeline, _ = run_blocks(config, lab_tension_blocks(config.buoy.id, peak_N, n_cycles))
    out = {}
    for name, figures in pipeline.report()["components"].items():
        damage = figures["damage"]
        out[name] = n_cycles / damage if damage else float("inf")
    return out


def lab_validation(config: Config, n_cycles: int = 200) -> list[LabPrediction]:
    """``predict`` at each failure load of App. 2 (c), with the observed cycles."""
    cache: dict[float, dict[str, float]] = {}
    rows = []
    for load, observed in LAB_FAILURES:
        if load not in cache:
            cache[load] = predict(config, load, n_cycles)
        rows.append(LabPrediction(load, observed, cache[load]))
    return rows
