"""Multi-stream ordering: turn blocks arriving in any interleaving into sensor-time slabs.

The rule (why live and replay agree): the pipeline processes sensor time in slabs ``(W', W]``
and never processes a sample before every GATING stream is known up to that sample's time.
Each stream has a watermark::

    newest  = newest sample time received on any stream
    wm(s)   = max(newest time received on s, newest - horizon)

and ``W = min(wm(s) for s in gating streams)``. All buffered samples of ALL streams with
``t <= W`` are released as one slab, each stream's samples sorted by time (stable, so a
duplicate stays behind its original and is the copy rejected). A copy met here, the same time
and values as the sample before it (a message delivered twice, a recording's re-recorded
messages), is dropped and counted (:attr:`Slab.copies`, reported with the validation's
``duplicate`` rejections): it is no measurement, so no rejection in a tick's counts either. Everything downstream is a
function of the samples in time order, so the results do not depend on how samples were cut
into blocks or interleaved, as long as no stream lags the newest data by more than
``horizon``: a silent stream (a dead sensor) is passed by after the horizon instead of stalling
everything, and samples that then arrive, at or before the processed time, are rejected as
``time_backwards``. Memory is bounded by the horizon.

Gating streams: the LOAD streams (tension, and the motion stream when the estimator is used)
always gate, even before their first sample. Other streams (gnss, waves, ...) gate in replay
(``gate_all``: the log holds them all, coalesced per channel, with ``[ordering]
replay_horizon_s``). Live (``[ordering] horizon_s``), they gate only while active (newest
sample within the horizon), so a low-rate or absent stream never delays the fatigue chain;
their health figures then reflect what had arrived when a tick was evaluated.

Live, a load stream never seen (``motion_sensor = "auto"`` on a buoy with a load cell and no
motion stream), or seen and then dead, gates at ``newest - horizon``: the grace that lets a
stream stamped just behind the load data (waves at a window's end) arrive in time. When the
data stops, it holds the last horizon of sensor time until the next data, so a tick's alerts
(a ``stale`` clear) would go out with the next stop's. :meth:`ReorderBuffer.silence`: after a
WALL-CLOCK silence of all data longer than the horizon (the daemon's idle loop), such a stream
(none, or nothing within the horizon, received) is taken as known up to the newest data: its
mark never falls behind that again, and from the next data on it gates at ``newest -
horizon`` again (the grace back). A load stream still talking when the data stopped is not
released. Replay (``gate_all``) never releases.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from monitor.blocks import SENSOR_FIELDS, SampleBlock

# canonical processing order of streams inside one slab
SENSOR_ORDER: tuple[str, ...] = tuple(SENSOR_FIELDS)
_NEVER = np.iinfo(np.int64).min


def same_values(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per column of two ``(n_fields, n)`` arrays: every field equal, NaN matching NaN (a
    re-sent missing value is still a copy; NaN != NaN)."""
    return ((a == b) | (np.isnan(a) & np.isnan(b))).all(axis=0)


class Slab(dict):
    """``{sensor: (t_ns int64 (n,), values float64 (n_fields, n))}``, samples sorted by time;
    ``copies``: per sensor, the exact copies dropped while sorting."""

    def __init__(self) -> None:
        super().__init__()
        self.copies: dict[str, int] = {}


# One buffered run of samples: times and one array per field. The arrays are the blocks' own
# (no copy when a block is pushed); take() copies the values it releases once, into the slab
# (not those of one part of a one-field stream: its slab views them).
_Part = tuple[np.ndarray, tuple[np.ndarray, ...]]


def _joined(parts: Sequence[_Part]) -> tuple[np.ndarray, np.ndarray]:
    """The parts' samples in one time array and one ``(n_fields, n)`` value array: one
    part's own arrays (a view) if only one with one field, else new ones. (Nothing writes
    into a slab's samples, so the view needs no copy.)"""
    if len(parts) == 1 and len(parts[0][1]) == 1:
        return parts[0][0], np.asarray(parts[0][1][0])[None]
    t = parts[0][0] if len(parts) == 1 else np.concatenate([p[0] for p in parts])
    values = np.empty((len(parts[0][1]), t.shape[0]))
    at = 0
    for pt, fields in parts:
        n = pt.shape[0]
        for row, f in zip(values, fields):
            row[at:at + n] = f
        at += n
    return t, values


class ReorderBuffer:
    """Per-stream buffers of received samples and the watermark rule above."""

    def __init__(self, load_streams: Sequence[str], horizon_ns: int, gate_all: bool = False,
                 state: Mapping[str, Any] | None = None) -> None:
        self.load_streams = tuple(load_streams)
        self.horizon_ns = int(horizon_ns)
        self.gate_all = gate_all
        self._pending: dict[str, list[_Part]] = {s: [] for s in SENSOR_ORDER}
        self.received_max: dict[str, int] = {}
        self._in_order = dict.fromkeys(SENSOR_ORDER, True)
        # live: per released load stream, the newest time at the wall-clock silence that
        # released it (silence()); not in the state: after a restart processed_ns (the
        # pipeline's) keeps what was processed from being processed again
        self._released: dict[str, int] = {}
        if state is not None:
            self.received_max = {k: int(v) for k, v in state["received_max"].items()}
            for sensor, (t, values) in state["pending"].items():
                t = np.array(t, dtype=np.int64)
                values = np.array(values, dtype=np.float64)  # null -> NaN
                self._pending[sensor].append(
                    (t, tuple(values.reshape(len(SENSOR_FIELDS[sensor]), -1))))
                self._in_order[sensor] = not bool(np.any(t[1:] < t[:-1]))

    def push(self, block: SampleBlock) -> None:
        if len(block) == 0:
            return
        t, sensor = block.t_ns, block.sensor
        parts = self._pending[sensor]
        # the usual case: sorted blocks arriving in order; then take() never re-sorts
        sorted_block = False
        if self._in_order[sensor]:
            sorted_block = not (t[1:] < t[:-1]).any()
            if not sorted_block or (parts and t[0] < parts[-1][0][-1]):
                self._in_order[sensor] = False
        fields = block.fields
        parts.append((t, tuple(fields[f] for f in SENSOR_FIELDS[sensor])))
        newest = int(t[-1] if sorted_block else t.max())
        self.received_max[sensor] = max(self.received_max.get(sensor, _NEVER), newest)

    @property
    def newest_ns(self) -> int | None:
        return max(self.received_max.values()) if self.received_max else None

    def watermark(self) -> int | None:
        """Sensor time up to which every gating stream is known (None before any data)."""
        newest = self.newest_ns
        if newest is None:
            return None
        floor = newest - self.horizon_ns
        marks = [newest]
        for s in SENSOR_ORDER:
            received = self.received_max.get(s)
            if s in self.load_streams or self.gate_all:
                mark = max(_NEVER if received is None else received, floor)
                marks.append(max(mark, self._released[s]) if s in self._released else mark)
            elif received is not None and received >= floor:
                marks.append(received)
        return min(marks)

    def silence(self, silent_ns: int) -> bool:
        """Live: no data arrived for ``silent_ns`` of wall-clock time. Longer than the horizon,
        a load stream with nothing received within the horizon of the newest data (never
        seen, or dead) is taken as known up to the newest data. True if that may move the
        watermark (such a stream was not released up to the newest data yet)."""
        newest = self.newest_ns
        if self.gate_all or newest is None or silent_ns <= self.horizon_ns:
            return False
        moved = False
        for s in self.load_streams:
            if (self.received_max.get(s, _NEVER) < newest - self.horizon_ns
                    and self._released.get(s, _NEVER) < newest):
                self._released[s] = newest
                moved = True
        return moved

    def end_of_data(self) -> int | None:
        """Newest time of the slowest load stream that has delivered data (for a final flush)."""
        seen = [self.received_max[s] for s in self.load_streams if s in self.received_max]
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
            if not self._in_order[sensor]:
                t, values = _joined(parts)
                order = np.argsort(t, kind="stable")
                t, values = t[order], values[:, order]
                copy = (t[1:] == t[:-1]) & same_values(values[:, 1:], values[:, :-1])
                if copy.any():
                    keep = np.r_[True, ~copy]
                    t, values = t[keep], values[:, keep]
                    slab.copies[sensor] = int(np.count_nonzero(copy))
                parts = [(t, tuple(values))]
                self._in_order[sensor] = True
            # parts are sorted and in order: the samples taken are a prefix of them
            taken, rest = [], []
            for t, fields in parts:
                if upto_ns is None or t[-1] <= upto_ns:
                    taken.append((t, fields))
                elif t[0] > upto_ns:
                    rest.append((t, fields))
                else:
                    cut = int(np.searchsorted(t, upto_ns, side="right"))
                    taken.append((t[:cut], tuple(f[:cut] for f in fields)))
                    rest.append((t[cut:], tuple(f[cut:] for f in fields)))
            self._pending[sensor] = rest
            if taken:
                slab[sensor] = _joined(taken)
        return slab

    def buffered(self) -> int:
        return sum(p[0].shape[0] for parts in self._pending.values() for p in parts)

    def state(self) -> dict[str, Any]:
        pending = {}
        for sensor in SENSOR_ORDER:
            parts = self._pending[sensor]
            if parts:
                t, values = _joined(parts)
                values = values.ravel()
                # strict JSON: NaN/inf (not validated yet) become null, read back as NaN,
                # which validation rejects with the same reason ("nan")
                flat = [v if np.isfinite(v) else None for v in values.tolist()]
                pending[sensor] = [t.tolist(), flat]
        return {"received_max": dict(self.received_max), "pending": pending}
