"""Late exact copies: a re-sent sample behind the processed time is a ``duplicate``.

A publisher that restarts and re-sends its cache, or a late one with a backlog, delivers
samples behind the time the pipeline has processed (the live ordering horizon is 10 s). The
validation calls them ``time_backwards`` (:mod:`monitor.validate`), a rejection in the
``rejected_rate`` alert, so a routine re-send read as bad data. Here a ``time_backwards``
sample that is an exact copy of a sample already RECEIVED on its stream (the same time, every
field equal, NaN matching NaN as in the ordering's copy test) becomes a ``duplicate``: no
measurement, outside a tick's received and rejected counts, as the ordering's copies
(:mod:`monitor.ordering`). Received: accepted, or rejected for its values (``nan``, a spike,
...): a cache re-sent holds those too, and their first verdict was counted. A late sample
that is no copy (other values, or a time never received) stays ``time_backwards``.

Memory is bounded: per stream, the received samples of the last ``span_s`` of its sensor time
(``[ordering] copy_span_s``, default 3600 s: the sensor publishers' cache, 3,600 one-second
blocks), from the start of the minute (UTC) that reaches back that far: about 1.2 MB an hour
of 20 Hz tension. A copy is recognised if its original is among them when the copy is
judged. They are part of the pipeline state (``late_copies``), so a restored pipeline judges
as one that never stopped: per whole minute of sensor time, deflated (0.29 MB an hour of
20 Hz tension), each minute packed once when the next has begun (a daemon checkpoints every
few seconds), independent of how the slabs were cut. A closed minute is a
:class:`~monitor.state_part.Part`, which the daemon's checkpoint store writes once rather than
with every checkpoint. The arrays of the received samples are kept as the pipeline made them
(no copy per slab when none was rejected), a minute's joined once it is over.

A saved minute that cannot be read (missing from the store, damaged, or not of its stream's
shape) is left out of what is restored, logged, and counted per stream in :attr:`LateCopies.lost`
(the daemon's status and metrics): late copies of that minute are then ``time_backwards``, as
they would be with no late copies kept; the rest of the state is restored.
"""

from __future__ import annotations

import base64
import logging
import zlib
from typing import Any, Mapping

import numpy as np

from monitor.blocks import SENSOR_FIELDS
from monitor.ordering import same_values
from monitor.state_part import Part
from monitor.validate import REASONS

log = logging.getLogger(__name__)

_DUP, _BACK = REASONS.index("duplicate") + 1, REASONS.index("time_backwards") + 1
_MINUTE_NS = 60 * 10**9


def _pack(a: np.ndarray) -> str:
    """Base64 of the deflated bytes (~3 x smaller on sensor data; a minute is packed once)."""
    return base64.b64encode(zlib.compress(np.ascontiguousarray(a).tobytes(), 6)).decode()


def _unpack(text: str, dtype: str) -> np.ndarray:
    return np.frombuffer(zlib.decompress(base64.b64decode(text)), dtype)


def _restored(steps: str, vals: str, nf: int) -> tuple[np.ndarray, np.ndarray]:
    """A saved minute's times and values (``nf`` fields); ValueError/TypeError/zlib.error if
    it is not one (None, not base64, not deflated, not of that shape, times not increasing)."""
    t = np.cumsum(_unpack(steps, "<i8"), dtype=np.int64)
    if not t.shape[0] or np.any(np.diff(t) <= 0):
        raise ValueError("no samples, or times not increasing")
    return t, _unpack(vals, "<f8").reshape(nf, t.shape[0]).copy()


def _cut(newest_ns: int, span_ns: int) -> int:
    """The oldest time kept: the start of the minute ``span_ns`` before the newest."""
    return (newest_ns - span_ns) // _MINUTE_NS * _MINUTE_NS


class _Accepted:
    """One stream's received samples within the span: parts in time order (times strictly
    increase across them: a sample not late nor a duplicate is after every one before it),
    and the packed minutes already complete."""

    def __init__(self) -> None:
        self.parts: list[tuple[np.ndarray, np.ndarray]] = []
        self.packed: dict[int, tuple[str, str]] = {}  # minute -> packed steps, values
        self._tail = 0  # the first part of the minute not joined yet

    def add(self, t: np.ndarray, values: np.ndarray, span_ns: int) -> None:
        parts = self.parts
        # a part per slab costs ~0.3 kB of array headers, as much as a live slab of tension
        # holds: the parts of a minute are joined once a later one begins (which also lets
        # go of any larger arrays the slabs' were views of)
        if parts and t[0] // _MINUTE_NS > parts[self._tail][0][0] // _MINUTE_NS:
            if len(parts) - self._tail > 1:
                parts[self._tail:] = [(np.concatenate([p[0] for p in parts[self._tail:]]),
                                       np.concatenate([p[1] for p in parts[self._tail:]],
                                                      axis=1))]
            self._tail = len(parts)
        parts.append((t, values))
        cut = _cut(int(t[-1]), span_ns)
        drop = 0
        while drop < len(parts) - 1 and int(parts[drop][0][-1]) < cut:
            drop += 1
        if drop:
            del parts[:drop]
            self._tail = max(0, self._tail - drop)

    def within(self, span_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """The samples kept (from :func:`_cut` exactly, whatever the parts' cut), joined."""
        t = np.concatenate([p[0] for p in self.parts])
        values = np.concatenate([p[1] for p in self.parts], axis=1)
        keep = int(np.searchsorted(t, _cut(int(t[-1]), span_ns), side="left"))
        return t[keep:], values[:, keep:]

    def state(self, span_ns: int) -> dict[str, list[str]]:
        """Per minute: the first time and the steps after it (little-endian int64: regular
        sampling deflates to almost nothing), and the float64 values field by field."""
        t, values = self.within(span_ns)
        minute = t // _MINUTE_NS
        bounds = [0, *(np.flatnonzero(np.diff(minute)) + 1).tolist(), t.shape[0]]
        steps, vals, packed = [], [], {}
        for a, b in zip(bounds[:-1], bounds[1:]):
            m = int(minute[a])
            closed = b < t.shape[0]  # a later minute has begun: this one never changes
            kind = Part if closed else str
            pair = self.packed.get(m) or (
                kind(_pack(np.diff(t[a:b], prepend=np.int64(0)).astype("<i8"))),
                kind(_pack(values[:, a:b].astype("<f8"))))
            if closed:
                packed[m] = pair
            steps.append(pair[0])
            vals.append(pair[1])
        self.packed = packed
        return {"t": steps, "v": vals}


class LateCopies:
    """Per stream, the recent received samples, and the copy test of late samples."""

    def __init__(self, span_s: float, state: Mapping[str, Any] | None = None) -> None:
        self.span_ns = int(round(span_s * 1e9))
        self._streams: dict[str, _Accepted] = {}
        self.lost: dict[str, int] = {}  # per stream, the saved minutes that could not be read
        errors = []
        for sensor, saved in (state or {}).items():
            acc = _Accepted()
            try:
                minutes = list(zip(saved["t"], saved["v"], strict=True))
                nf = len(SENSOR_FIELDS[sensor])
            except (KeyError, TypeError, ValueError) as exc:
                self.lost[sensor] = 1  # how many it held is unknown
                errors.append(f"{sensor}: {exc!r}")
                continue
            for steps, vals in minutes:
                try:
                    part = _restored(steps, vals, nf)
                    if acc.parts and part[0][0] <= acc.parts[-1][0][-1]:
                        raise ValueError("times not after the minute before")
                except (TypeError, ValueError, zlib.error) as exc:  # a None: missing or damaged
                    self.lost[sensor] = self.lost.get(sensor, 0) + 1
                    errors.append(f"{sensor}: {exc!r}")
                    continue
                acc.parts.append(part)
            if acc.parts:
                self._streams[sensor] = acc
                # restored per minute: the minutes before the newest are over (joined they
                # would be one part, dropped only once its newest sample left the span)
                acc._tail = len(acc.parts) - 1
        if self.lost:
            log.error("late copies not restored: saved minutes missing or damaged; late exact "
                      "copies of their samples count as time_backwards", extra={"fields": {
                          "minutes_lost": self.lost, "first_error": errors[0][:300]}})

    def judge(self, sensor: str, t: np.ndarray, values: np.ndarray, codes: np.ndarray,
              rejected: dict[str, int]) -> None:
        """Turn the ``time_backwards`` verdicts (:meth:`StreamValidator.check`'s ``codes``) of
        exact copies of recent received samples into ``duplicate``, in ``codes`` and in the
        validator's counts ``rejected``."""
        acc = self._streams.get(sensor)
        if acc is None:
            return
        late = np.flatnonzero(codes == _BACK)
        if not late.shape[0]:
            return
        kept_t, kept_v = acc.within(self.span_ns)
        at = np.minimum(np.searchsorted(kept_t, t[late]), kept_t.shape[0] - 1)
        copy = (kept_t[at] == t[late]) & same_values(kept_v[:, at], values[:, late])
        codes[late[copy]] = _DUP
        n = int(np.count_nonzero(copy))
        rejected["time_backwards"] -= n
        rejected["duplicate"] += n

    def received(self, sensor: str, t: np.ndarray, values: np.ndarray,
                 codes: np.ndarray) -> None:
        """A slab of ``sensor`` with its final verdicts ``codes``: keeps the samples neither
        late nor duplicates (after every earlier one kept)."""
        if codes.any():
            new = (codes != _DUP) & (codes != _BACK)
            t, values = t[new], values[:, new]
        if t.shape[0]:
            self._streams.setdefault(sensor, _Accepted()).add(t, values, self.span_ns)

    def state(self) -> dict[str, Any]:
        """The samples kept per stream, per minute (:meth:`_Accepted.state`)."""
        return {sensor: acc.state(self.span_ns) for sensor, acc in sorted(self._streams.items())}
