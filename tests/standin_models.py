"""Test-only stand-ins for models.helix / models.fatigue until the real modules land on main.

They implement the documented API with simple, obviously-correct code (Knapp axial stress of
seed 004 App. 4, pure-Python four-point rainflow, log-log table S-N curve), so the pipeline
tests check real numbers. ``install()`` registers them only when the real modules are missing.
"""

from __future__ import annotations

import importlib
import math
import sys
import types
from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class HelixCable:
    core_area_m2: float = 42.1e-6
    core_modulus_Pa: float = 81.4e9
    core_twist_modulus: float = 24.4e-6
    pitch_m: float = 0.174
    helix_radius_m: float = 0.0092
    conductor_modulus_Pa: float = 19.5e9

    @classmethod
    def vaps_biw(cls) -> "HelixCable":
        return cls()


def conductor_stress(tension_N, cable: HelixCable, lay: str = "left"):
    t = np.asarray(tension_N, dtype=np.float64)
    e_c = t / (cable.core_area_m2 * cable.core_modulus_Pa)
    theta = cable.core_twist_modulus * t * cable.pitch_m
    r, p = cable.helix_radius_m, cable.pitch_m
    a = math.atan(2 * math.pi * r / p)
    sign = 1.0 if lay == "left" else -1.0
    a2 = np.arctan((2 * math.pi * r + sign * r * theta) / (p * (1 + e_c)))
    return cable.conductor_modulus_Pa * np.abs(math.cos(a) / np.cos(a2) * (1 + e_c) - 1)


@dataclass(frozen=True)
class SNCurve:
    stress_MPa: tuple
    cycles: tuple
    endurance_MPa: float | None = None
    derating: float = 1.0
    scf: float = 1.0
    dff: float = 1.0
    mean_correction: str = "none"
    ultimate_Pa: float | None = None

    @classmethod
    def vaps_copper(cls) -> "SNCurve":
        s = [75.2, 78.0, 90.0, 106.0, 130.0]
        return cls.tabulated(tuple(v * 0.42 for v in s), (1e7, 1e6, 1e5, 2.5e4, 1e4))

    @classmethod
    def tabulated(cls, stress_MPa, cycles) -> "SNCurve":
        return cls(tuple(stress_MPa), tuple(cycles), endurance_MPa=float(min(stress_MPa)))

    def with_factors(self, **changes) -> "SNCurve":
        return replace(self, **changes)

    def cycles_to_failure(self, range_Pa, mean_Pa=None):
        s = np.log10(np.asarray(range_Pa, float) / 1e6 * self.scf * self.derating)
        ls = np.log10(np.array(self.stress_MPa))
        ln = np.log10(np.array(self.cycles))
        order = np.argsort(ls)
        ls, ln = ls[order], ln[order]
        slope = (ln[-1] - ln[-2]) / (ls[-1] - ls[-2])
        n = np.where(s > ls[-1], ln[-1] + slope * (s - ls[-1]), np.interp(s, ls, ln))
        return np.where(s < ls[0], np.inf, 10.0 ** n)

    def damage_per_cycle(self, range_Pa, counts=1.0, mean_Pa=None):
        return np.asarray(counts, float) / self.cycles_to_failure(range_Pa) * self.dff

    def stress_range_at(self, cycles):
        return 1e6 * float(np.interp(np.log10(cycles), np.log10(self.cycles[::-1]),
                                     np.array(self.stress_MPa[::-1])))


class StreamingRainflow:
    def __init__(self, hysteresis: float = 0.0):
        self.hysteresis = hysteresis
        self._res: list[float] = []

    @property
    def residue(self):
        return np.array(self._res)

    def feed(self, block):
        x = np.asarray(block, dtype=np.float64)
        if not np.all(np.isfinite(x)):
            raise ValueError("StreamingRainflow.feed: block contains NaN or inf")
        r = self._res
        out_r, out_m = [], []
        for v in x.tolist():
            if len(r) >= 2 and (r[-1] - r[-2]) * (v - r[-1]) >= 0:
                r[-1] = v
            elif len(r) == 1 and v == r[0]:
                continue
            else:
                r.append(v)
            while len(r) >= 4:
                a, b, c, d = r[-4:]
                if abs(c - b) <= abs(b - a) and abs(c - b) <= abs(d - c):
                    out_r.append(abs(c - b))
                    out_m.append((b + c) / 2)
                    del r[-3:-1]
                else:
                    break
        return np.array(out_r), np.array(out_m), np.ones(len(out_r))

    def residue_half_cycles(self):
        r = self.residue
        if r.size < 2:
            return np.zeros(0), np.zeros(0), np.zeros(0)
        return np.abs(np.diff(r)), (r[1:] + r[:-1]) / 2, np.full(r.size - 1, 0.5)

    def state(self):
        return {"hysteresis": self.hysteresis, "residue": list(self._res)}

    @classmethod
    def from_state(cls, state):
        obj = cls(state["hysteresis"])
        obj._res = list(state["residue"])
        return obj


class MinerAccumulator:
    def __init__(self, sn_curve: SNCurve, histogram_edges_Pa=None, rate_window_s: float = 86400.0,
                 reference_cycles: float = 1e7):
        self.sn_curve = sn_curve
        self.rate_window_s = rate_window_s
        self.damage_committed = 0.0
        self.total_cycles = 0.0
        self.history: list[tuple[float, float]] = []

    def add_cycles(self, ranges, counts, means=None, time_s=None) -> float:
        d = self.sn_curve.damage_per_cycle(ranges, counts)
        start = self.damage_committed
        for x in d.tolist():  # sequential sum in closure order, as the real accumulator
            self.damage_committed += x
        self.total_cycles += float(np.sum(counts))
        if time_s is not None:
            self.history.append((float(time_s), self.damage_committed))
            while len(self.history) > 1 and self.history[1][0] <= time_s - self.rate_window_s:
                self.history.pop(0)
        return self.damage_committed - start

    @property
    def damage_rate_per_day(self) -> float:
        if len(self.history) < 2:
            return 0.0
        (t0, d0), (t1, d1) = self.history[0], self.history[-1]
        return (d1 - d0) / ((t1 - t0) / 86400.0) if t1 > t0 else 0.0

    def state(self):
        return {"committed": self.damage_committed, "cycles": self.total_cycles,
                "history": [list(h) for h in self.history], "rate_window_s": self.rate_window_s,
                "sn_curve": {k: getattr(self.sn_curve, k) for k in self.sn_curve.__dataclass_fields__}}

    @classmethod
    def from_state(cls, state):
        obj = cls(SNCurve(**state["sn_curve"]), rate_window_s=state["rate_window_s"])
        obj.damage_committed = state["committed"]
        obj.total_cycles = state["cycles"]
        obj.history = [tuple(h) for h in state["history"]]
        return obj


def install() -> None:
    """Register the stand-ins as models.helix / models.fatigue if those are not importable."""
    for name, attrs in {
        "models.helix": {"HelixCable": HelixCable, "conductor_stress": conductor_stress},
        "models.fatigue": {"SNCurve": SNCurve, "StreamingRainflow": StreamingRainflow,
                           "MinerAccumulator": MinerAccumulator},
    }.items():
        try:
            importlib.import_module(name)
        except ModuleNotFoundError:
            mod = types.ModuleType(name)
            mod.__dict__.update(attrs)
            sys.modules[name] = mod
