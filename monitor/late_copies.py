"""Late exact copies: a re-sent sample behind the processed time is a ``duplicate``.

A publisher that restarts and re-sends its cache, or a late one with a backlog, delivers
samples behind the time the pipeline has processed (the live ordering horizon is 10 s). The
validation calls them ``time_backwards`` (:mod:`monitor.validate`), a rejection in the
``rejected_rate`` alert, so a routine re-send read as bad data. Here a ``time_backwards``
sample that is an exact copy of a sample already ACCEPTED on its stream (the same time, every
field equal) becomes a ``duplicate``: no measurement, outside a tick's received and rejected
counts, as the ordering's copies (:mod:`monitor.ordering`). A late sample that is no copy (other
values, or a time never accepted) stays ``time_backwards``.

Memory is bounded: per stream, the accepted samples of the last ``span_s`` of its sensor time
(``[ordering] copy_span_s``, default 3600 s: the sensor publishers' cache, 3,600 one-second
blocks), about 1.2 MB an hour of 20 Hz tension. A copy is recognised if its original is among
them when the copy is judged; they are part of the pipeline state (``late_copies``), so a
restored pipeline judges as one that never stopped. The arrays of the accepted samples are
kept as the pipeline made them (no copy per slab); only the state and a lookup join them.
"""

from __future__ import annotations

import base64
import zlib
from typing import Any, Mapping

import numpy as np

from monitor.blocks import SENSOR_FIELDS
from monitor.validate import REASONS

_DUP, _BACK = REASONS.index("duplicate") + 1, REASONS.index("time_backwards") + 1


def _pack(a: np.ndarray) -> str:
    """Base64 of the deflated bytes (level 1: ~3 x smaller on sensor data, ~10 ms an hour)."""
    return base64.b64encode(zlib.compress(np.ascontiguousarray(a).tobytes(), 1)).decode()


def _unpack(text: str, dtype: str) -> np.ndarray:
    return np.frombuffer(zlib.decompress(base64.b64decode(text)), dtype)


class _Accepted:
    """One stream's accepted samples within the span: parts in time order (times strictly
    increase across them: accepted times do)."""

    def __init__(self) -> None:
        self.parts: list[tuple[np.ndarray, np.ndarray]] = []

    def add(self, t: np.ndarray, values: np.ndarray, span_ns: int) -> None:
        self.parts.append((t, values))
        cut = int(t[-1]) - span_ns
        drop = 0
        while drop < len(self.parts) - 1 and int(self.parts[drop][0][-1]) < cut:
            drop += 1
        if drop:
            del self.parts[:drop]

    def within(self, span_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """The samples no older than ``span_ns`` before the newest (exactly: whatever the
        parts' cut), joined."""
        t = np.concatenate([p[0] for p in self.parts])
        values = np.concatenate([p[1] for p in self.parts], axis=1)
        keep = int(np.searchsorted(t, t[-1] - span_ns, side="left"))
        return t[keep:], values[:, keep:]


class LateCopies:
    """Per stream, the recent accepted samples, and the copy test of late samples."""

    def __init__(self, span_s: float, state: Mapping[str, Any] | None = None) -> None:
        self.span_ns = int(round(span_s * 1e9))
        self._streams: dict[str, _Accepted] = {}
        for sensor, saved in (state or {}).items():
            t = np.cumsum(_unpack(saved["t"], "<i8"), dtype=np.int64)
            values = _unpack(saved["v"], "<f8").astype(np.float64)
            self._streams[sensor] = acc = _Accepted()
            acc.parts.append((t, values.reshape(len(SENSOR_FIELDS[sensor]), t.shape[0])))

    def judge(self, sensor: str, t: np.ndarray, values: np.ndarray, codes: np.ndarray,
              rejected: dict[str, int]) -> None:
        """Turn the ``time_backwards`` verdicts (:meth:`StreamValidator.check`'s ``codes``) of
        exact copies of recent accepted samples into ``duplicate``, in ``codes`` and in the
        validator's counts ``rejected``."""
        acc = self._streams.get(sensor)
        if acc is None:
            return
        late = np.flatnonzero(codes == _BACK)
        if not late.shape[0]:
            return
        kept_t, kept_v = acc.within(self.span_ns)
        at = np.minimum(np.searchsorted(kept_t, t[late]), kept_t.shape[0] - 1)
        copy = (kept_t[at] == t[late]) & (kept_v[:, at] == values[:, late]).all(axis=0)
        codes[late[copy]] = _DUP
        n = int(np.count_nonzero(copy))
        rejected["time_backwards"] -= n
        rejected["duplicate"] += n

    def accepted(self, sensor: str, t: np.ndarray, values: np.ndarray) -> None:
        """The samples of ``sensor`` accepted now (after every earlier one)."""
        if t.shape[0]:
            self._streams.setdefault(sensor, _Accepted()).add(t, values, self.span_ns)

    def state(self) -> dict[str, Any]:
        """The samples within the span per stream: the first time and the steps after it
        (little-endian int64: regular sampling deflates to almost nothing), and the float64
        values field by field, deflated, in base64; independent of how the slabs were cut."""
        out = {}
        for sensor, acc in sorted(self._streams.items()):
            t, values = acc.within(self.span_ns)
            steps = np.diff(t, prepend=np.int64(0)).astype("<i8")
            out[sensor] = {"t": _pack(steps), "v": _pack(values.astype("<f8"))}
        return out
