"""Multi-stream ordering: turn blocks arriving in any interleaving into sensor-time slabs.

The rule (why live and replay agree): the pipeline never processes a sample before it knows
every GATING stream (the streams that feed the fatigue load: tension and/or the motion stream)
up to that sample's time. Each stream has a watermark::

    watermark(s) = max(newest sample time received on s, newest time received on ANY stream - horizon)

and the pipeline watermark is ``W = min(watermark(s) for s in gating streams)``. All buffered
samples of ALL streams with ``t <= W`` are released together as one slab, each stream's samples
sorted by time (stable, so duplicates stay adjacent and the later copy is the one rejected).
Everything downstream is a function of the samples in time order, so the result does not
depend on how the samples were cut into blocks or interleaved, provided no stream lags the
newest data by more than ``horizon``: a silent stream (a dead sensor) is passed by after the
horizon instead of stalling everything, and samples that then arrive late, at or before the
processed time, are rejected as ``time_backwards``. Live ingest uses ``[ordering] horizon_s``;
replay, whose log blocks are coalesced per channel, uses ``replay_horizon_s``. Memory is
bounded by the horizon. Non-gating streams (gnss, waves, a motion stream the estimator does not
use) are released with the same slabs but never hold them back.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from monitor.blocks import SENSOR_FIELDS, SampleBlock

# canonical processing order of streams inside one slab
SENSOR_ORDER: tuple[str, ...] = tuple(SENSOR_FIELDS)
_NEVER = np.iinfo(np.int64).min


class Slab(dict):
    """``{sensor: (t_ns int64 (n,), values float64 (n_fields, n))}``, samples sorted by time."""


class ReorderBuffer:
    """Per-stream buffers of received samples and the watermark rule above."""

    def __init__(self, gating: Sequence[str], horizon_ns: int,
                 state: Mapping[str, Any] | None = None) -> None:
        self.gating = tuple(gating)
        self.horizon_ns = int(horizon_ns)
        self._pending: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {s: [] for s in SENSOR_ORDER}
        self.received_max: dict[str, int] = {}
        if state is not None:
            self.received_max = {k: int(v) for k, v in state["received_max"].items()}
            for sensor, (t, values) in state["pending"].items():
                self._pending[sensor].append(
                    (np.array(t, dtype=np.int64),
                     np.array(values, dtype=np.float64).reshape(len(SENSOR_FIELDS[sensor]), -1))
                )

    def push(self, block: SampleBlock) -> None:
        if len(block) == 0:
            return
        values = np.stack([block.fields[f] for f in SENSOR_FIELDS[block.sensor]])
        self._pending[block.sensor].append((block.t_ns, values))
        newest = int(block.t_ns.max())
        self.received_max[block.sensor] = max(self.received_max.get(block.sensor, _NEVER), newest)

    @property
    def newest_ns(self) -> int | None:
        return max(self.received_max.values()) if self.received_max else None

    def watermark(self) -> int | None:
        """Sensor time up to which every gating stream is known (None before any data)."""
        newest = self.newest_ns
        if newest is None:
            return None
        floor = newest - self.horizon_ns
        return min(max(self.received_max.get(s, _NEVER), floor) for s in self.gating)

    def end_of_data(self) -> int | None:
        """Newest time of the slowest gating stream that has delivered data (for a final flush)."""
        seen = [self.received_max[s] for s in self.gating if s in self.received_max]
        if seen:
            return min(seen)
        return self.newest_ns

    def take(self, upto_ns: int | None) -> Slab:
        """Remove and return every buffered sample with ``t <= upto_ns`` (all if None)."""
        slab = Slab()
        for sensor in SENSOR_ORDER:
            parts = self._pending[sensor]
            if not parts:
                continue
            if len(parts) == 1:
                t, values = parts[0]
            else:
                t = np.concatenate([p[0] for p in parts])
                values = np.concatenate([p[1] for p in parts], axis=1)
            if t.shape[0] > 1 and bool(np.any(t[1:] < t[:-1])):
                order = np.argsort(t, kind="stable")
                t, values = t[order], values[:, order]
            cut = t.shape[0] if upto_ns is None else int(np.searchsorted(t, upto_ns, side="right"))
            self._pending[sensor] = [(t[cut:], values[:, cut:])] if cut < t.shape[0] else []
            if cut:
                slab[sensor] = (t[:cut], values[:, :cut])
        return slab

    def buffered(self) -> int:
        return sum(p[0].shape[0] for parts in self._pending.values() for p in parts)

    def state(self) -> dict[str, Any]:
        pending = {}
        for sensor in SENSOR_ORDER:
            parts = self._pending[sensor]
            if parts:
                t = np.concatenate([p[0] for p in parts])
                values = np.concatenate([p[1] for p in parts], axis=1)
                pending[sensor] = [t.tolist(), values.ravel().tolist()]
        return {"received_max": dict(self.received_max), "pending": pending}
