"""Exactly-once intake across restarts: per-stream publisher sequence numbers.

Sensor publishers (:class:`monitor.sensors.SensorPublisher`, ``buoymon simulate --publish``,
``buoymon bridge``) are Zenoh advanced publishers: every message carries its publisher's id
and a sequence number that grows by one per message, and the publisher keeps a cache of its
last messages. A daemon that (re)starts asks for that cache, so it receives again messages it
had already processed before its last checkpoint, then the ones it never saw.

:class:`SequenceTracker` keeps, per stream and publisher, the last sequence number taken into
the pipeline; it is saved in the daemon's checkpoint together with the pipeline state, so the
two always agree. For each arriving message it says:

* ``redelivered``: its number is at or below the last one taken (already in the restored
  state): skip it, count it;
* a gap: the number jumped. The daemon first asks the publisher's cache for the missing
  numbers (:meth:`gap`, ``monitor.zenoh_io.fetch_cached``) and takes those first; what the
  cache no longer holds (a daemon down for longer than the cache covers) is ``missed``:
  counted per stream as ``samples_missed`` (Zenoh samples, i.e. messages, one block each) and
  alerted on; the message itself is taken.

A publisher seen for the first time (or one that restarted: a new id) starts a fresh count;
messages without publisher information (ordinary publishers) are always taken, and the
pipeline's own rule (samples at or before a stream's last time are duplicates) applies.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

# publishers remembered per stream; the oldest is forgotten beyond this (a sensor node that
# restarts gets a new id each time)
_MAX_SOURCES = 8


@dataclass(frozen=True)
class Verdict:
    """What to do with one message: ``redelivered`` (skip it) and how many were ``missed``
    just before it."""

    redelivered: bool
    missed: int


TAKE = Verdict(False, 0)


class SequenceTracker:
    """Per-stream, per-publisher sequence numbers, counted misses and redeliveries.

    Args:
        state: what :meth:`state` returned (restores exactly), or None to start empty.
    """

    def __init__(self, state: Mapping[str, Any] | None = None) -> None:
        state = state or {}
        self._last: dict[str, dict[str, int]] = {
            s: {src: int(sn) for src, sn in d.items()} for s, d in state.get("last", {}).items()}
        self.missed: dict[str, int] = {s: int(n) for s, n in state.get("missed", {}).items()}
        self.redelivered: dict[str, int] = {
            s: int(n) for s, n in state.get("redelivered", {}).items()}
        self.recovered: dict[str, int] = {
            s: int(n) for s, n in state.get("recovered", {}).items()}

    def observe(self, stream: str, source: str | None, sn: int | None) -> Verdict:
        """Classify the message numbered ``sn`` from publisher ``source`` on ``stream`` and
        take it into the count unless it is a redelivery."""
        if source is None or sn is None:
            return TAKE
        sources = self._last.setdefault(stream, {})
        last = sources.get(source)
        if last is not None and sn <= last:
            self.redelivered[stream] = self.redelivered.get(stream, 0) + 1
            return Verdict(True, 0)
        missed = 0 if last is None else sn - last - 1
        if missed:
            self.missed[stream] = self.missed.get(stream, 0) + missed
        sources.pop(source, None)  # re-insert: most recently used last
        sources[source] = sn
        while len(sources) > _MAX_SOURCES:
            sources.pop(next(iter(sources)))
        return Verdict(False, missed)

    def gap(self, stream: str, source: str,
            sn: int | None) -> tuple[int, int | None] | None:
        """The numbers (first, last) missing before message ``sn`` of ``source`` on
        ``stream``: after the last one taken from a known publisher, from 0 for a publisher
        not seen before; None when nothing is missing. ``sn`` None: (first, None), all
        after the last one taken."""
        last = self._last.get(stream, {}).get(source, -1)
        if sn is None:
            return (last + 1, None)
        return (last + 1, sn - 1) if sn > last + 1 else None

    def latest_sources(self) -> set[tuple[str, str]]:
        """(stream, publisher) of the publisher each stream heard from last."""
        return {(stream, next(reversed(d))) for stream, d in self._last.items() if d}

    def recovered_from_cache(self, stream: str, n: int) -> None:
        """Count ``n`` messages fetched from a publisher's cache to fill a gap."""
        self.recovered[stream] = self.recovered.get(stream, 0) + n

    def fields(self, stream: str) -> dict[str, int]:
        """The status fields of ``stream``: ``samples_missed``, ``redelivered`` and
        ``recovered`` (fetched from a publisher's cache to fill a gap)."""
        return {"samples_missed": self.missed.get(stream, 0),
                "redelivered": self.redelivered.get(stream, 0),
                "recovered": self.recovered.get(stream, 0)}

    def streams(self) -> set[str]:
        return set(self._last)

    def state(self) -> dict[str, Any]:
        """JSON-able state (round-trips exactly through the constructor)."""
        return {"last": {s: dict(d) for s, d in self._last.items()},
                "missed": dict(self.missed), "redelivered": dict(self.redelivered),
                "recovered": dict(self.recovered)}
