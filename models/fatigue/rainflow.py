"""Streaming four-point rainflow counting with the residue carried across blocks.

``StreamingRainflow(hysteresis=0.0)``
  ``feed(block) -> (ranges, means, counts)``  cycles closed by this block, numpy float64
      arrays in closure order (counts are all 1.0: four-point counting closes whole cycles).
  ``residue``                    open turning points (numpy array), oldest first; the last
                                 element is the running extreme, which later data may extend.
  ``residue_half_cycles() -> (ranges, means, counts)``  the residue counted as ASTM E1049
                                 would at the end of the series: half cycles (0.5), plus a
                                 full cycle (1.0) where ASTM's three-point rule pairs two
                                 residue ranges.
  ``state() -> dict`` / ``StreamingRainflow.from_state(dict)``  small, JSON-serialisable;
                                 floats are stored as Python floats so a JSON round trip
                                 restores the counter bit for bit.
  ``samples``                    number of samples fed so far.

Algorithm. Turning points are found sample by sample: a running extreme ``candidate``
is extended while the signal keeps its direction and confirmed as a turning point when
the signal retreats from it by MORE than ``hysteresis`` (so repeated values and plateaus
never make turning points; with hysteresis > 0 no range below the threshold is counted).
The first sample is a turning point, as in ASTM E1049. Each confirmed turning point is
pushed on a stack; while the stack holds four points A, B, C, D with |B - C| <= |A - B|
and |B - C| <= |C - D|, the cycle (B, C) is closed and B, C removed. Because a closed
cycle never depends on later samples, the cycles and the order in which they close are the
same for any split of the series into blocks; together with the residue half cycles they
total the ASTM E1049 (``rainflow.extract_cycles``) counts for every (range, mean).

The counting runs in one compiled loop, ``_loops.feed_loop`` (a few microseconds per call;
per chunk of samples, a branch-free pass finds the confirmed turning points, then the
four-point stack consumes them); without numba the same loop runs as plain Python. A NaN
or inf in a block raises ValueError and nothing from that block is counted.
"""

from __future__ import annotations

import math

import numpy as np

# the compiled loop and the layout of the counter state vector
from models.fatigue import _loops
from models.fatigue._loops import CAND as _CAND
from models.fatigue._loops import CHUNK as _CHUNK
from models.fatigue._loops import DIR as _DIR
from models.fatigue._loops import HEADER as _HEADER
from models.fatigue._loops import HYST as _HYST
from models.fatigue._loops import NS as _NS
from models.fatigue._loops import STARTED as _STARTED
from models.fatigue._loops import cycle_room as _cycle_room

_STATE_VERSION = 1


def _feed(st: np.ndarray, x: np.ndarray):
    """The counting loop (compiled, else plain Python) into an output allocated here."""
    out = np.empty((3, _cycle_room(st, x.size)))
    k, used = (_loops.feed_compiled or _loops.feed_loop)(st, x, out)
    return out[:, :k], used


class StreamingRainflow:
    """Incremental four-point rainflow counter (see module docstring for the API)."""

    def __init__(self, hysteresis: float = 0.0, _capacity: int = 4 * _CHUNK):
        if not (isinstance(hysteresis, (int, float)) and math.isfinite(hysteresis) and hysteresis >= 0):
            raise ValueError(f"hysteresis must be a finite number >= 0, got {hysteresis!r}")
        self._st = np.zeros(_HEADER + max(int(_capacity), 2 * _CHUNK))
        self._st[_HYST] = float(hysteresis)
        self._samples = 0

    @property
    def hysteresis(self) -> float:
        return float(self._st[_HYST])

    @property
    def samples(self) -> int:
        return self._samples

    def _grow(self, need: int = 0) -> None:
        """Room for ``need`` stack points, at least twice the present room."""
        bigger = np.zeros(_HEADER + max(need, 2 * (self._st.size - _HEADER)))
        bigger[: self._st.size] = self._st
        self._st = bigger

    def feed(self, block) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Count a block of samples; return (ranges, means, counts) of the cycles it closed."""
        x = np.asarray(block, dtype=np.float64)
        if x.ndim != 1:
            x = x.reshape(-1) if x.ndim == 0 else _reject_shape(x)
        cycles, used = _feed(self._st, x)
        if used < 0:
            raise ValueError(f"stress block contains NaN or inf at index {-used - 1}; block not counted")
        if used < x.size:  # stack storage full: grow it and finish the block
            parts = [cycles]
            while used < x.size:
                self._grow()
                more, n = _feed(self._st, x[used:])
                parts.append(more)
                used += n
            cycles = np.concatenate(parts, axis=1)
        self._samples += x.size
        return cycles[0], cycles[1], cycles[2]

    @property
    def residue(self) -> np.ndarray:
        """Open turning points, oldest first, ending with the running extreme."""
        ns = int(self._st[_NS])
        stack = self._st[_HEADER:_HEADER + ns]
        if self._st[_DIR] != 0.0:
            return np.append(stack, self._st[_CAND])
        return stack.copy()

    def residue_half_cycles(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The residue counted as ASTM E1049 would at the end of the series.

        Returns (ranges, means, counts): mostly half cycles (0.5); ASTM's three-point rule
        may still pair two residue ranges into a full cycle (1.0) that the four-point rule
        keeps open, which is what makes closed + residue cycles total the ASTM counts.
        """
        loop = _loops.residue_cycles_compiled or _loops.residue_cycles_loop
        cycles = loop(self._st)
        return cycles[0], cycles[1], cycles[2]

    def state(self) -> dict:
        """Everything needed to resume, as a small JSON-serialisable dict."""
        ns = int(self._st[_NS])
        return {
            "version": _STATE_VERSION,
            "hysteresis": float(self._st[_HYST]),
            "started": bool(self._st[_STARTED]),
            "direction": int(self._st[_DIR]),
            "candidate": float(self._st[_CAND]),
            "stack": [float(v) for v in self._st[_HEADER:_HEADER + ns]],
            "samples": self._samples,
        }

    @classmethod
    def from_state(cls, state: dict) -> "StreamingRainflow":
        """Rebuild a counter saved with ``state()``."""
        if state.get("version") != _STATE_VERSION:
            raise ValueError(f"unsupported StreamingRainflow state version {state.get('version')!r}")
        stack = [float(v) for v in state["stack"]]
        if state["direction"] not in (-1, 0, 1) or not all(math.isfinite(v) for v in stack):
            raise ValueError("corrupt StreamingRainflow state")
        rf = cls(hysteresis=float(state["hysteresis"]), _capacity=2 * len(stack) + 4 * _CHUNK)
        rf._st[_NS] = len(stack)
        rf._st[_CAND] = float(state["candidate"])
        rf._st[_DIR] = float(state["direction"])
        rf._st[_STARTED] = 1.0 if state["started"] else 0.0
        rf._st[_HEADER:_HEADER + len(stack)] = stack
        rf._samples = int(state["samples"])
        return rf


def _reject_shape(x: np.ndarray):
    raise ValueError(f"feed() takes a 1-D block of samples, got shape {x.shape}")
