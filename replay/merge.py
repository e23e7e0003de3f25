"""The cross-file merge of the reader: messages of all files through one reorder window,
released in sensor-time order and coalesced into blocks (the ordering guarantees in
:mod:`replay.reader`). Every copy of a message is delivered: duplicates are the pipeline's
to drop and count (:mod:`monitor.ordering`, :mod:`monitor.validate`), live and in replay
alike."""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from typing import Iterator

import numpy as np

from models._jit import kernel
from monitor import codec
from monitor.blocks import SENSOR_FIELDS, SampleBlock, parse_sensor_topic
from replay.mcap_scan import Digest, distinct
from replay.salvage import FileContext, FileStats


class _Stream:
    """Pending (not yet released) samples of one topic, across files: one part per run of
    records, each holding whole messages, kept as decoded (never joined into one store:
    a block is a view of one part, or joins only its own samples)."""

    def __init__(self, topic: str, buoy_id: str, sensor: str):
        self.topic, self.buoy_id, self.sensor = topic, buoy_id, sensor
        self.nf = len(SENSOR_FIELDS[sensor])
        self.parts: list[tuple[np.ndarray, np.ndarray]] = []
        self.bounds = [0]  # start index of each part, then the end of the last one
        self.held = 0  # samples held back by the latest release

    @property
    def length(self) -> int:
        return self.bounds[-1]

    def add(self, t: np.ndarray, v: np.ndarray, front: int = 0) -> int:
        """Append the samples of ``t[front:]``, ``v[:, front:]``; return their start index in
        the stream's pending samples. When the samples pending so far fit in the ``front``
        unset ones, they are copied there: the stream is then one part, so the release's
        first block of it is a view too, not a join of the two parts (it spans the latest
        reorder window of the previous release and most of a new run of records)."""
        start = self.length
        if 0 < start <= front:
            a = front - start
            t[a:front], v[:, a:front] = self._span(0, start)
            self.parts = [(t[a:], v[:, a:])]
            self.bounds = [0, start + t.shape[0] - front]
            return start
        self.parts.append((t[front:], v[:, front:]) if front else (t, v))
        self.bounds.append(start + t.shape[0] - front)
        return start

    def take(self, start: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Samples of messages (start, n) in that order: views of a part when they are
        contiguous in it (usual)."""
        if start.shape[0] == 0:
            return np.empty(0, np.int64), np.empty((self.nf, 0))
        if (start[1:] == start[:-1] + n[:-1]).all():
            return self._span(int(start[0]), int(start[-1] + n[-1]))
        t, v = self._span(0, self.length)  # out of read order (rare): join, then gather
        idx = _gather_index(start, n)
        return t[idx], v[:, idx]

    def _span(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """Samples ``a .. b - 1``: views when they lie in one part."""
        if a >= b:
            return np.empty(0, np.int64), np.empty((self.nf, 0))
        first = bisect_right(self.bounds, a) - 1
        last = bisect_left(self.bounds, b) - 1
        pieces = [(t[max(a - lo, 0):b - lo], v[:, max(a - lo, 0):b - lo])
                  for (t, v), lo in zip(self.parts[first:last + 1], self.bounds[first:last + 1])]
        if len(pieces) == 1:
            return pieces[0]
        return (np.concatenate([p[0] for p in pieces]),
                np.concatenate([p[1] for p in pieces], axis=1))

    def keep_span(self, a: int, b: int) -> None:
        """Drop every sample but ``a .. b - 1`` (none when ``a >= b``)."""
        t, v = self._span(a, b)
        self.parts = [(t, v)] if t.shape[0] else []
        self.bounds = [0, t.shape[0]] if t.shape[0] else [0]

    def keep_only(self, start: np.ndarray, n: np.ndarray) -> np.ndarray:
        """Drop every sample but those of messages (start, n); return their new starts."""
        t, v = self.take(start, n)
        self.parts = [(t, v)] if t.shape[0] else []
        self.bounds = [0, t.shape[0]] if t.shape[0] else [0]
        return np.cumsum(n) - n


def _gather_index(start: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Indices ``start[i] .. start[i] + n[i]`` of all messages, concatenated."""
    total = int(n.sum())
    if total == 0:
        return np.empty(0, np.int64)
    first = np.cumsum(n) - n
    return np.repeat(start - first, n) + np.arange(total)


def order_times(pub: np.ndarray, log: np.ndarray, max_ahead_ns: int) -> np.ndarray:
    """The times messages are ordered by: the publish time, or the log (receive) time of a
    message published more than ``max_ahead_ns`` after it (:func:`monitor.time_ahead.is_ahead`,
    a log time 0 being unknown; the ordering guarantees in :mod:`replay.reader`)."""
    lead = pub - log
    if lead.shape[0] == 0 or lead.max() <= max_ahead_ns:  # (usual) none ahead
        return pub
    ahead = (lead > max_ahead_ns) & (log > 0)
    return np.where(ahead, log, pub) if ahead.any() else pub


# the rows of the table of pending messages (one column per message)
STREAM, PUB, LOG, START, N, SEQ = range(6)
# Longest stretch of sensor time (by publish time) one coalesced block covers. The replay's
# ordering passes by a stream lagging the newest data by more than [ordering]
# replay_horizon_s (1 h) and rejects what then arrives as late: a chunk of compact samples
# holds more than an hour of the default streams, so a release of a whole chunk must be cut;
# at half the horizon, as long as the chunks of the float64 format, as few blocks as that
# allows (the pipeline's cost per block is the fleet benchmark's: 600 s cost 15 % more CPU).
COALESCE_S = 1800
COALESCE_NS = COALESCE_S * 1_000_000_000


class StreamMerge:
    """Pending messages of every sensor topic across files (a :class:`replay.salvage.RecordSink`)
    and their release in order (:meth:`release`)."""

    def __init__(self, window_ns: int, coalesce: bool, max_ahead_ns: int) -> None:
        self.window_ns = window_ns
        self.coalesce = coalesce
        self.max_ahead_ns = max_ahead_ns
        self._streams: list[_Stream] = []
        self._stream_of: dict[str, int] = {}
        # the pending messages, one column each (rows STREAM ... SEQ), in the first ``_n``
        # columns of a table that grows as needed: records fill it in place, a release reads
        # it without joining parts and puts the held-back messages back at its start
        self._tab = np.empty((6, 0), np.int64)
        self._n = 0
        self._rank = np.empty(0, np.int64)  # each stream's rank in topic order
        self._max_pub = np.iinfo(np.int64).min
        self._released_to = np.iinfo(np.int64).min
        self._seq = 0

    def sensor(self, idx: int) -> str:
        return self._streams[idx].sensor

    def fronts(self, ahead: bool = False) -> dict[int, int]:
        """Room to leave before each stream's samples of the next run of records decoded
        (:func:`replay.mcap_scan.digest`): the samples each holds now, or, for a run decoded
        ahead (before the release of the current one), those the latest release held back
        (the next one holds back about as many: one reorder window), with a margin."""
        if ahead:
            return {i: s.held + s.held // 4 + 64 for i, s in enumerate(self._streams) if s.held}
        return {i: s.length for i, s in enumerate(self._streams) if s.length}

    def records(self, d: Digest, ctx: FileContext, st: FileStats) -> int:
        """Take the messages of a run of records (its channel definitions already in ``ctx``);
        return their number."""
        buf = d.buf
        ch, log, pub, doff, dlen = d.scan[:5]
        if ch.shape[0] == 0:
            return 0
        pub = order_times(pub, log, self.max_ahead_ns)
        ctx.last_log = int(log[-1])
        seq0 = self._seq  # read order: the message's index in the run, from here
        self._seq += ch.shape[0]
        for c, sel in d.groups.items():
            target = ctx.channels.get(c)
            if target is None or isinstance(target, str):
                topic = target if isinstance(target, str) else f"<unknown channel {c}>"
                st.skipped[topic] = st.skipped.get(topic, 0) + sel.shape[0]
                continue
            sidx, numbers = target
            decoded = d.decoded.get(c)  # else defined in this very run of records
            front = d.fronts.get(c, 0) if decoded is not None else 0
            status, n, t, vals = (decoded if decoded is not None
                                  else codec.decode_many(buf, doff[sel], dlen[sel], numbers))
            bad = int(np.count_nonzero(status))  # (usually none: no copies then)
            if bad:
                good = status == codec.OK
                st.bad_payloads += bad
                sel, n = sel[good], n[good]
            stream = self._streams[sidx]
            start0 = stream.add(t, vals, front)
            topic = stream.topic
            st.messages_by_topic[topic] = st.messages_by_topic.get(topic, 0) + sel.shape[0]
            st.messages += sel.shape[0]
            st.samples += t.shape[0] - front
            if sel.shape[0]:
                lo, hi, late = (int(x) for x in _fill_rows(
                    self._room(sel.shape[0]), sidx, pub, log, sel, n, start0, seq0,
                    self._released_to))
                st.first_ns = lo if st.first_ns is None else min(st.first_ns, lo)
                st.last_ns = hi if st.last_ns is None else max(st.last_ns, hi)
                st.late += late
                self._max_pub = max(self._max_pub, hi)
        return int(ch.shape[0])

    def _room(self, k: int) -> np.ndarray:
        """The next ``k`` columns of the pending table, to fill (growing it if needed)."""
        n = self._n
        if n + k > self._tab.shape[1]:
            grown = np.empty((6, max(2 * self._tab.shape[1], n + k)), np.int64)
            grown[:, :n] = self._tab[:, :n]
            self._tab = grown
        self._n = n + k
        return self._tab[:, n:n + k]

    def stream_index(self, topic: str) -> int | None:
        """Index of a sensor topic's stream, creating it (None if not a sensor topic)."""
        idx = self._stream_of.get(topic)
        if idx is None:
            try:
                buoy, sensor = parse_sensor_topic(topic)
            except ValueError:
                return None
            if sensor not in SENSOR_FIELDS:
                return None
            idx = self._stream_of[topic] = len(self._streams)
            self._streams.append(_Stream(topic, buoy, sensor))
            self._rank = np.argsort(np.argsort([s.topic for s in self._streams]))
        return idx

    def release(self, final: bool) -> Iterator[SampleBlock]:
        if not self._n:
            return
        if not final and self._max_pub - self.window_ns <= self._released_to:
            return
        tab = self._tab[:, :self._n]
        cut = np.iinfo(np.int64).max if final else self._max_pub - self.window_ns
        n_out = int(np.count_nonzero(tab[PUB] <= cut))
        if not n_out:
            return
        # canonical order: publish time, topic, read order (topic rank and read order in one
        # key, exact while streams x messages read < 2**63; every key distinct, so the
        # order is unique: stable sorts by the second key, then by publish time, give
        # lexsort's, in a fifth of its time on these nearly sorted runs). The messages
        # released (publish time <= cut) come first, those held back after them.
        by_topic = np.argsort(self._rank[tab[STREAM]] * self._seq + tab[SEQ], kind="stable")
        order = by_topic[np.argsort(tab[PUB][by_topic], kind="stable")]
        rel, held = order[:n_out], order[n_out:]
        self._released_to = max(self._released_to, int(tab[PUB][rel[-1]]))
        blocks = self._blocks(tab, rel)
        keep = tab[:, held]
        # compact: keep only the held-back samples (usually each stream's are one run)
        lo, hi, starts = _held_runs(keep[STREAM], keep[START], keep[N], len(self._streams))
        if starts is not None:
            for s, a, b in zip(self._streams, lo.tolist(), hi.tolist()):
                s.keep_span(a, b)
            keep[START] = starts
        else:
            for i in distinct(tab[STREAM]):
                mine = keep[STREAM] == i
                keep[START][mine] = self._streams[i].keep_only(keep[START][mine], keep[N][mine])
        self._tab[:, :held.shape[0]] = keep
        self._n = held.shape[0]
        for s in self._streams:
            s.held = s.length
        yield from blocks

    def _blocks(self, tab: np.ndarray, rel: np.ndarray) -> list[SampleBlock]:
        """The messages ``tab[rel]`` (in canonical order) as blocks."""
        if not self.coalesce:
            return [self._message_block(*m) for m in zip(
                *(tab[k][rel].tolist() for k in (STREAM, START, N, LOG)))]
        count, *per_block, member = _groups(rel, tab[STREAM], tab[PUB], tab[LOG],
                                            tab[START], tab[N], COALESCE_NS,
                                            len(self._streams))
        sid, lo, hi, log, apart = (x.tolist() for x in per_block)
        out = []
        for g in range(count):
            stream = self._streams[sid[g]]
            if apart[g]:  # (rare) messages not back to back in their stream
                mine = rel[member == g]
                tt, vv = stream.take(tab[START][mine], tab[N][mine])
            else:
                tt, vv = stream._span(lo[g], hi[g])
            out.append(SampleBlock(stream.buoy_id, stream.sensor, tt, {
                f: vv[q] for q, f in enumerate(SENSOR_FIELDS[stream.sensor])}, log[g]))
        return out

    def _message_block(self, s: int, a: int, n: int, log: int) -> SampleBlock:
        """One message's samples as a block of their own (copies)."""
        stream = self._streams[s]
        t, v = stream._span(a, a + n)
        return SampleBlock(stream.buoy_id, stream.sensor, t.copy(),
                           {f: v[q].copy() for q, f in enumerate(SENSOR_FIELDS[stream.sensor])},
                           log)


@kernel()
def _groups(order, stream, pub, log, start, n, span_ns, n_streams):
    """The coalesced blocks of the messages ``order`` (indices, in canonical order; at least
    one): a release is as long as a chunk, so it is cut into spans of ``span_ns`` of publish
    time from its first message (no coalesced block then runs ahead of the other streams by
    more than that), and each span gives one block per stream, the blocks in the order of
    their first messages. Returns their count and, per block: stream, first and end sample
    (the stream's pending indices), the latest receive time, whether its messages are
    apart (not back to back in the stream: then ``lo``/``hi`` do not describe it), and the
    block of every message."""
    m = order.shape[0]
    sid = np.empty(m, np.int64)
    lo = np.empty(m, np.int64)
    hi = np.empty(m, np.int64)
    latest = np.empty(m, np.int64)
    apart = np.zeros(m, np.bool_)
    member = np.empty(m, np.int64)
    open_block = np.full(n_streams, -1, np.int64)  # each stream's block in the current span
    count = 0
    first_pub = pub[order[0]]
    span = 0
    # the span's range of pub - first_pub: a message inside it needs no division (a 64-bit
    # one per message was a third of this loop)
    span_lo = 0
    span_hi = span_ns
    for i in range(m):
        k = order[i]
        d = pub[k] - first_pub
        if d < span_lo or d >= span_hi:
            sp = d // span_ns
            span_lo = sp * span_ns
            span_hi = span_lo + span_ns
            if sp != span:
                open_block[:] = -1
                span = sp
        s = stream[k]
        b = open_block[s]
        if b < 0:
            b = open_block[s] = count
            count += 1
            sid[b], lo[b], latest[b] = s, start[k], log[k]
        else:
            apart[b] |= start[k] != hi[b]
            latest[b] = max(latest[b], log[k])
        hi[b] = start[k] + n[k]
        member[i] = b
    return count, sid[:count], lo[:count], hi[:count], latest[:count], apart[:count], member


@kernel()
def _held_runs(stream, start, n, n_streams):
    """Where the messages held back by a release (in canonical order: ``stream``, ``start``,
    ``n``) lie in their streams, when each stream's are back to back (usual): per stream the
    first and end sample (``lo >= hi``: none held), and each message's start once only those
    are kept (``start - lo``: :meth:`_Stream.keep_only`'s). ``None`` for the starts when some
    stream's are not: the caller then gathers them."""
    lo = np.zeros(n_streams, np.int64)
    hi = np.zeros(n_streams, np.int64)
    seen = np.zeros(n_streams, np.bool_)
    for k in range(stream.shape[0]):
        s = stream[k]
        if not seen[s]:
            seen[s] = True
            lo[s] = start[k]
        elif start[k] != hi[s]:
            return lo, hi, None
        hi[s] = start[k] + n[k]
    starts = np.empty(stream.shape[0], np.int64)
    for k in range(stream.shape[0]):
        starts[k] = start[k] - lo[stream[k]]
    return lo, hi, starts


@kernel()
def _fill_rows(rows, stream, pub, log, sel, n, start0, seq0, released_to):
    """Fill the pending table's columns ``rows`` (rows STREAM ... SEQ) with the messages
    ``sel`` of a run of records (``n`` samples each, the first at ``start0`` of ``stream``'s
    pending samples; ``seq0``: the run's first read order); return their earliest and latest
    order time and how many are at or before ``released_to`` (late)."""
    lo = pub[sel[0]]
    hi = lo
    late = 0
    at = start0
    for k in range(sel.shape[0]):
        j = sel[k]
        p = pub[j]
        lo = min(lo, p)
        hi = max(hi, p)
        late += p <= released_to
        rows[STREAM, k] = stream
        rows[PUB, k] = p
        rows[LOG, k] = log[j]
        rows[START, k] = at
        rows[N, k] = n[k]
        rows[SEQ, k] = j + seq0
        at += n[k]
    return lo, hi, late
