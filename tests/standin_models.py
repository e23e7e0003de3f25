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
    stress_range_Pa: tuple
    cycles: tuple
    derating: float = 1.0
    scf: float = 1.0
    dff: float = 1.0

    @classmethod
    def vaps_copper(cls) -> "SNCurve":
        s = [75.2e6, 78e6, 90e6, 106e6, 130e6]
        return cls(tuple(v * 0.42 for v in s), (1e7, 1e6, 1e5, 2.5e4, 1e4))

    @classmethod
    def tabulated(cls, stress_range_Pa, cycles) -> "SNCurve":
        return cls(tuple(stress_range_Pa), tuple(cycles))

    def cycles_to_failure(self, ranges):
        s = np.log10(np.asarray(ranges, float) * self.scf / self.derating)
        ls = np.log10(np.array(self.stress_range_Pa))
        ln = np.log10(np.array(self.cycles))
        order = np.argsort(ls)
        ls, ln = ls[order], ln[order]
        slope = (ln[-1] - ln[-2]) / (ls[-1] - ls[-2])
        n = np.where(s > ls[-1], ln[-1] + slope * (s - ls[-1]), np.interp(s, ls, ln))
        return np.where(s < ls[0], np.inf, 10.0 ** n)

    def damage(self, ranges, counts):
        r = np.asarray(ranges, float)
        if r.size == 0:
            return 0.0
        return float(np.sum(np.asarray(counts) / self.cycles_to_failure(r))) * self.dff


class StreamingRainflow:
    def __init__(self, hysteresis: float = 0.0):
        self.hysteresis = hysteresis
        self.residue: list[float] = []

    def feed(self, block):
        x = np.asarray(block, dtype=np.float64)
        if not np.all(np.isfinite(x)):
            raise ValueError("StreamingRainflow.feed: block contains NaN or inf")
        r = self.residue
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
        r = np.array(self.residue)
        if r.size < 2:
            return np.zeros(0), np.zeros(0), np.zeros(0)
        return np.abs(np.diff(r)), (r[1:] + r[:-1]) / 2, np.full(r.size - 1, 0.5)

    def state(self):
        return {"hysteresis": self.hysteresis, "residue": list(self.residue)}

    @classmethod
    def from_state(cls, state):
        obj = cls(state["hysteresis"])
        obj.residue = list(state["residue"])
        return obj


class MinerAccumulator:
    def __init__(self, sn_curve: SNCurve, rate_window_s: float = 3600.0, **_):
        self.sn_curve = sn_curve
        self.rate_window_s = rate_window_s
        self.committed = 0.0
        self.cycles = 0.0
        self.history: list[tuple[int, float]] = []

    def add(self, ranges, means, counts, t_ns: int) -> None:
        self.committed += self.sn_curve.damage(ranges, counts)
        self.cycles += float(np.sum(counts)) if len(counts) else 0.0
        self.history.append((int(t_ns), self.committed))
        cutoff = int(t_ns) - int(self.rate_window_s * 1e9)
        while len(self.history) > 1 and self.history[1][0] <= cutoff:
            self.history.pop(0)

    def provisional(self, ranges, means, counts) -> float:
        return self.sn_curve.damage(ranges, counts)

    def damage_rate_per_day(self) -> float:
        if len(self.history) < 2:
            return 0.0
        (t0, d0), (t1, d1) = self.history[0], self.history[-1]
        return (d1 - d0) / ((t1 - t0) / 86400e9) if t1 > t0 else 0.0

    def remaining_life_days(self) -> float:
        rate = self.damage_rate_per_day()
        return (1.0 - self.committed) / rate if rate > 0 else math.inf

    def state(self):
        return {"committed": self.committed, "cycles": self.cycles,
                "history": [list(h) for h in self.history], "rate_window_s": self.rate_window_s}

    @classmethod
    def from_state(cls, state, sn_curve):
        obj = cls(sn_curve, state["rate_window_s"])
        obj.committed = state["committed"]
        obj.cycles = state["cycles"]
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
