"""One fatigue component: load -> stress -> streaming rainflow -> Miner damage.

A thin adapter over ``models.helix`` and ``models.fatigue`` so the pipeline sees one small
interface per ``[[component]]``: conductors get the helix stress of their lay
(``models.helix.conductor_stress``), axial members ``tension / area_m2``.

Damage bookkeeping keeps the result independent of block sizes, to the last bit: cycles closed
by the rainflow are held as *pending* until the alert tick that contains their closing sample
ends, and only then added to the Miner accumulator, one addition per tick. Tick boundaries are
a fixed sensor-time grid, so the floating-point summation order is the same for any split of
the data. Pending cycles (at most one tick's worth) are part of the saved state.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np

from models import fatigue, helix
from monitor.config import ComponentConfig, Config, FatigueConfig


def build_sn_curve(cfg: ComponentConfig) -> Any:
    """The component's S-N curve with its derating, SCF and DFF applied."""
    sn = cfg.sn_curve
    if sn.preset is not None:
        factory = getattr(fatigue.SNCurve, sn.preset, None)
        if factory is None:
            raise ValueError(f"config error: component {cfg.name!r}: sn_curve = {sn.preset!r} "
                             "is not a models.fatigue.SNCurve preset")
        curve = factory()
    else:
        curve = fatigue.SNCurve.tabulated(sn.stress_range_Pa, sn.cycles)
    return dataclasses.replace(curve, derating=cfg.derating, scf=cfg.scf, dff=cfg.dff)


def build_cable(config: Config) -> Any:
    factory = getattr(helix.HelixCable, config.cable.preset, None)
    if factory is None:
        raise ValueError(f"config error: cable.preset = {config.cable.preset!r}: "
                         "not a models.helix.HelixCable preset")
    try:
        return dataclasses.replace(factory(), **config.cable.overrides)
    except TypeError as exc:
        raise ValueError(f"config error: cable: {exc}") from None


_EMPTY = np.zeros(0)


class Component:
    """Stress, rainflow and damage of one ``[[component]]``."""

    def __init__(self, cfg: ComponentConfig, cable: Any, fcfg: FatigueConfig,
                 state: Mapping[str, Any] | None = None) -> None:
        self.name = cfg.name
        self.cfg = cfg
        self._cable = cable
        self.sn_curve = build_sn_curve(cfg)
        if state is None:
            self.rainflow = fatigue.StreamingRainflow(hysteresis=cfg.hysteresis_Pa)
            self.miner = fatigue.MinerAccumulator(
                self.sn_curve, rate_window_s=fcfg.rate_window_s,
                histogram_edges=np.array(fcfg.histogram_edges_Pa),
                reference_cycles=fcfg.reference_cycles,
            )
            self._pending: list[np.ndarray] = [_EMPTY, _EMPTY, _EMPTY]
            self.max_stress_Pa = -math.inf
        else:
            self.rainflow = fatigue.StreamingRainflow.from_state(state["rainflow"])
            self.miner = fatigue.MinerAccumulator.from_state(state["miner"], self.sn_curve)
            self._pending = [np.array(v, dtype=np.float64) for v in state["pending"]]
            peak = state["max_stress_Pa"]
            self.max_stress_Pa = -math.inf if peak is None else float(peak)

    def stress(self, tension_N: np.ndarray) -> np.ndarray:
        if self.cfg.kind == "conductor":
            return helix.conductor_stress(tension_N, self._cable, lay=self.cfg.lay)
        return tension_N / self.cfg.area_m2

    def feed(self, stress_Pa: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rainflow the next stress samples; returns the cycles they closed (kept pending)."""
        if stress_Pa.shape[0] == 0:
            return _EMPTY, _EMPTY, _EMPTY
        self.max_stress_Pa = max(self.max_stress_Pa, float(stress_Pa.max()))
        ranges, means, counts = self.rainflow.feed(stress_Pa)
        if len(ranges):
            self._pending = [np.concatenate([p, c]) for p, c in zip(self._pending, (ranges, means, counts))]
        return ranges, means, counts

    def commit(self, tick_end_ns: int) -> None:
        """End of an alert tick: add the pending cycles to the Miner sum in one step."""
        self.miner.add(*self._pending, t_ns=tick_end_ns)
        self._pending = [_EMPTY, _EMPTY, _EMPTY]

    def figures(self) -> dict[str, float]:
        """damage (with pending cycles and the open residue as half cycles), committed, rate, life.

        ``damage_committed`` includes cycles closed since the last tick, computed fresh here
        and not accumulated, so reading figures never changes the state.
        """
        pending = self.miner.provisional(*self._pending) if len(self._pending[0]) else 0.0
        residue = self.miner.provisional(*self.rainflow.residue_half_cycles())
        committed = self.miner.committed + pending
        return {
            "damage": committed + residue,
            "damage_committed": committed,
            "damage_rate_per_day": float(self.miner.damage_rate_per_day()),
            "remaining_life_days": float(self.miner.remaining_life_days()),
            "cycles": float(self.miner.cycles + float(np.sum(self._pending[2]))),
            "max_stress_Pa": self.max_stress_Pa if math.isfinite(self.max_stress_Pa) else math.nan,
        }

    def state(self) -> dict[str, Any]:
        return {
            "rainflow": self.rainflow.state(),
            "miner": self.miner.state(),
            "pending": [p.tolist() for p in self._pending],
            "max_stress_Pa": self.max_stress_Pa if math.isfinite(self.max_stress_Pa) else None,
        }
