"""Plain numpy/Python oracles of the compiled fatigue kernels (issue 18: the numpy twins that
used to ship as production "backends" live here, as the references the tests compare with).

- :func:`rainflow_oracle`: streaming four-point rainflow, sample by sample, from its
  definition (``models.fatigue.rainflow``'s docstring).
- :func:`damage_oracle`: S-N damage of each cycle, segment by ``searchsorted`` and the
  compiled loops' log/exp applied to arrays (``models.fatigue._loops.log_det``/``exp_det``
  are plain numpy outside compiled code).
- :func:`miner_oracle`: committed Miner sum (in order) and fixed-edge histogram in numpy.
- :func:`axial_stress_oracle`: the helix's Knapp axial stress on arrays.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from models.fatigue import SNCurve
from models.fatigue._loops import exp_det, log_det
from models.helix import HelixCable, axial_kernel_args


def rainflow_oracle(blocks: Iterable[np.ndarray], hysteresis: float = 0.0):
    """Closed cycles (ranges, means) in closure order and the open residue after feeding
    ``blocks``: the first sample is a turning point; a running extreme is extended while
    the signal keeps its direction and confirmed when the signal retreats by more than
    ``hysteresis``; each confirmed point closes four-point cycles (B, C) of A, B, C, D while
    |B - C| <= |A - B| and |B - C| <= |C - D|."""
    ranges: list[float] = []
    means: list[float] = []
    stack: list[float] = []
    cand, direction = None, 0

    def push(point: float) -> None:
        while len(stack) >= 3:
            a, b, c = stack[-3:]
            if abs(b - c) <= abs(c - point) and abs(b - c) <= abs(a - b):
                ranges.append(abs(b - c))
                means.append(0.5 * (b + c))
                del stack[-2:]
            else:
                break
        stack.append(point)

    for block in blocks:
        for v in np.asarray(block, dtype=np.float64).tolist():
            if cand is None:
                stack.append(v)
                cand = v
            elif direction == 0:
                if abs(v - cand) > hysteresis:
                    direction, cand = (1 if v > cand else -1), v
            elif (cand - v) * direction > hysteresis:
                push(cand)
                direction, cand = -direction, v
            elif (v - cand) * direction > 0.0:
                cand = v
    residue = stack + ([cand] if direction else [])
    return np.array(ranges), np.array(means), np.array(residue)


def damage_oracle(curve: SNCurve, ranges: np.ndarray, means=None, counts=1.0) -> np.ndarray:
    """Damage of each cycle, computed without the package's evaluation code."""
    m, log_a, bounds = curve._segments
    s = curve.effective_range_MPa(ranges, means)
    seg = m.size - 1 - np.searchsorted(bounds, s, side="right")
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        ln_coef = np.log(curve.dff * 10.0 ** -log_a)
        d = counts * exp_det(m[seg] * log_det(s) + ln_coef[seg])
    cutoff = curve.endurance_MPa if curve.low_stress == "cutoff" else 0.0
    return np.where(s >= cutoff, d, 0.0)


def sequential_sum(start: float, values: np.ndarray) -> float:
    """``start`` plus each value in order (numpy's ``sum`` is pairwise: other bits)."""
    return float(np.cumsum(np.concatenate(([start], values)))[-1])


def miner_oracle(curve: SNCurve, ranges: np.ndarray, means, counts: np.ndarray,
                 edges: np.ndarray) -> tuple[float, np.ndarray]:
    """(committed damage, counts per bin of ``edges`` then the overflow bin) of the cycles
    committed in order from nothing; ranges below the first edge are not binned."""
    committed = sequential_sum(0.0, damage_oracle(curve, ranges, means, counts))
    hist = np.zeros(edges.size)
    idx = np.searchsorted(edges, ranges, side="right") - 1
    inside = idx >= 0
    np.add.at(hist, idx[inside], np.broadcast_to(counts, ranges.shape)[inside])
    return committed, hist


def axial_stress_oracle(tension_N: np.ndarray, cable: HelixCable, lay: str) -> np.ndarray:
    """E |cos a sqrt((1 + e_c)^2 + (C'/P)^2) - 1| on arrays, the compiled kernel's constants."""
    args = axial_kernel_args(cable, lay)
    assert args is not None, "the cable needs the general formula"
    k, tan_a, cos_a, rg_signed, e_mod = args
    t = np.asarray(tension_N, dtype=np.float64)
    a = 1.0 + k * t
    b = tan_a + rg_signed * t
    return np.abs(cos_a * np.sqrt(a * a + b * b) - 1.0) * e_mod
