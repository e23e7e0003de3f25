"""A durable outbox: alert notifications survive restarts and are retried with backoff.

Messages are rows of a SQLite database (WAL journal, ``synchronous=FULL``, so an enqueued
message is on disk before :meth:`Outbox.enqueue` returns). A background thread delivers them,
per channel strictly in enqueue order (a "clear" never overtakes its "fire"): the head message
of a channel is retried with capped exponential backoff and jitter (``retry_base_s`` doubling
up to ``retry_max_s``, each wait drawn between half and all of that) until its sender
succeeds, and only then is it marked delivered, in its own transaction.

A sender that raises :class:`PermanentDeliveryError` (the receiver refused the message: an
HTTP 4xx) makes the message a *dead letter*: kept in the database with the receiver's
answer, logged, counted, and skipped, so it never holds back the messages after it. Dead
letters are listed by ``buoymon alerts outbox`` and stay until an operator retries or
discards them. Each channel holds at most ``max_pending`` undelivered messages: beyond that
the oldest are dropped (and counted), so an outage of the receiver costs bounded disk. Enqueueing is idempotent on ``(channel, dedup_key)``, so a pipeline that re-emits
the same transitions after resuming from a checkpoint does not notify twice.

Delivery is at-least-once only across a crash between a successful send and the commit that
marks it delivered (no HTTP/SMTP receiver can be made transactional with SQLite); receivers
can use the ``dedup_key`` (sent as the webhook's ``Idempotency-Key`` header) to drop that rare
repeat.

Retry timing is the only place in the alert path that uses the wall clock: sensor time does
not advance while a receiver is down. A pending message's age (``oldest_pending_age_s``, the
live rule ``alert_delivery_stalled``) is on the monotonic clock for the messages enqueued by
this process: a wall-clock step (a logger's RTC set from GNSS/NTP at boot) would age them by
the step. A message from before it is as old as its wall-clock age now (only the wall clock
spans processes; read at each look, so an RTC still behind at opening and stepped later does
not freeze it near 0), and a channel's age is the older of the two.
"""

from __future__ import annotations

import logging
import os
import random
import sqlite3
import threading
import time
from typing import Any, Callable, Mapping

log = logging.getLogger(__name__)

# A sender delivers one payload or raises; the dedup key lets it pass an idempotency key on.
Sender = Callable[[bytes, str], None]


class PermanentDeliveryError(Exception):
    """The receiver refused the message (e.g. HTTP 4xx): retrying cannot help."""


# the figures per channel (Outbox.stats) as the status document names them
COUNTERS = ("delivered_total", "failures_total", "dropped_total", "dead_total")

_SCHEMA = """
CREATE TABLE IF NOT EXISTS outbox (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    channel TEXT NOT NULL,
    dedup_key TEXT NOT NULL,
    payload BLOB NOT NULL,
    created_s REAL NOT NULL,
    attempts INTEGER NOT NULL DEFAULT 0,
    next_attempt_s REAL NOT NULL,
    delivered_s REAL,
    last_error TEXT,
    UNIQUE (channel, dedup_key)
);
CREATE INDEX IF NOT EXISTS outbox_pending ON outbox (channel, id) WHERE delivered_s IS NULL;
CREATE TABLE IF NOT EXISTS outbox_counters (
    channel TEXT NOT NULL,
    name TEXT NOT NULL,
    value INTEGER NOT NULL,
    PRIMARY KEY (channel, name)
);
"""
# undelivered and not dead: what the sender thread still has to send
_PENDING = "delivered_s IS NULL AND dead_s IS NULL"


class Outbox:
    """SQLite-backed queue of notifications with a background sender thread.

    Args:
        path: database file (created if missing).
        senders: channel name -> callable(payload, dedup_key) that delivers or raises.
        retry_base_s, retry_max_s: backoff after the n-th failure is drawn uniformly between
            half and all of ``min(retry_max_s, retry_base_s * 2**(n-1))`` seconds.
        max_pending: undelivered messages kept per channel; the oldest beyond are dropped.
        clock: wall-clock seconds (injectable for tests).
        rng: the jitter's random source (injectable for tests).
        monotonic: monotonic seconds, for the pending messages' ages (injectable for tests).
    """

    def __init__(self, path: str, senders: Mapping[str, Sender], retry_base_s: float = 5.0,
                 retry_max_s: float = 600.0, max_pending: int = 10000,
                 clock: Callable[[], float] = time.time,
                 rng: random.Random | None = None,
                 monotonic: Callable[[], float] = time.monotonic) -> None:
        if not retry_base_s > 0 or not retry_max_s >= retry_base_s:
            raise ValueError(f"outbox retry_base_s = {retry_base_s!r}, retry_max_s = "
                             f"{retry_max_s!r}: need 0 < retry_base_s <= retry_max_s")
        if not (isinstance(max_pending, int) and max_pending >= 1):
            raise ValueError(f"outbox max_pending = {max_pending!r}: need an integer >= 1")
        self.max_pending = max_pending
        self.rng = rng or random.Random()
        self.path = str(path)
        self.senders = dict(senders)
        self.retry_base_s = float(retry_base_s)
        self.retry_max_s = float(retry_max_s)
        self.clock = clock
        self.monotonic = monotonic
        # row id -> (channel, monotonic time of its enqueue), for the messages of this process
        # still pending, oldest first (under the lock; delivered, dead and dropped ones removed)
        self._enqueued: dict[int, tuple[str, float]] = {}
        # one connection shared by the enqueuing thread and the sender thread, serialised by
        # a lock; the lock is never held while a sender talks to the network
        os.makedirs(os.path.dirname(os.path.abspath(self.path)), exist_ok=True)  # as the state
        self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        try:
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.executescript(_SCHEMA)
            columns = {row[1] for row in self._db.execute("PRAGMA table_info(outbox)")}
            if "dead_s" not in columns:  # an outbox written before dead letters existed
                self._db.execute("ALTER TABLE outbox ADD COLUMN dead_s REAL")
        except sqlite3.DatabaseError as exc:  # another file, or a damaged one: never overwritten
            self._db.close()
            raise ValueError(f"{self.path}: not an alert outbox database ({exc}); the file is "
                             "left as it is: move it aside to start afresh (its undelivered "
                             "alerts are lost)") from None
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # --- producer side ---------------------------------------------------------------------
    def enqueue(self, channel: str, dedup_key: str, payload: bytes) -> bool:
        """Store a message durably; False if ``(channel, dedup_key)`` was already stored."""
        if channel not in self.senders:
            raise ValueError(f"outbox channel {channel!r}: no sender; have {sorted(self.senders)}")
        now, mono = self.clock(), self.monotonic()
        with self._lock:
            cur = self._db.execute(
                "INSERT OR IGNORE INTO outbox (channel, dedup_key, payload, created_s, "
                "next_attempt_s) VALUES (?, ?, ?, ?, ?)",
                (channel, dedup_key, bytes(payload), now, now),
            )
            added = cur.rowcount == 1
            dropped = 0
            if added:
                if cur.lastrowid is not None:  # the row inserted (always, with rowcount 1)
                    self._enqueued[cur.lastrowid] = (channel, mono)
                # select then delete in one transaction, not DELETE ... RETURNING: that needs
                # SQLite >= 3.35 (Debian 11 has 3.34)
                self._db.execute("BEGIN IMMEDIATE")
                try:
                    ids = self._db.execute(
                        f"SELECT id FROM outbox WHERE channel = ? AND {_PENDING} "
                        "ORDER BY id DESC LIMIT -1 OFFSET ?", (channel, self.max_pending)
                    ).fetchall()
                    self._db.executemany("DELETE FROM outbox WHERE id = ?", ids)
                    dropped = len(ids)
                    if dropped:
                        self._count(channel, "dropped_total", dropped)
                    self._db.execute("COMMIT")
                except BaseException:
                    self._db.execute("ROLLBACK")
                    raise
                for (row_id,) in ids:
                    self._enqueued.pop(row_id, None)
        if dropped:
            log.error("alert outbox full: oldest undelivered messages dropped",
                      extra={"fields": {"channel": channel, "dropped": dropped,
                                        "max_pending": self.max_pending}})
        if added:
            self._wake.set()
        return added

    def _count(self, channel: str, name: str, n: int = 1) -> None:
        """Add to a persistent counter (the caller holds the lock)."""
        self._db.execute(
            "INSERT INTO outbox_counters (channel, name, value) VALUES (?, ?, ?) "
            "ON CONFLICT (channel, name) DO UPDATE SET value = value + excluded.value",
            (channel, name, n))

    # --- consumer side ---------------------------------------------------------------------
    def _heads(self) -> list[tuple[int, str, str, bytes, int, float]]:
        with self._lock:
            return self._db.execute(
                "SELECT o.id, o.channel, o.dedup_key, o.payload, o.attempts, o.next_attempt_s "
                "FROM outbox o JOIN (SELECT channel, MIN(id) AS id FROM outbox "
                f"WHERE {_PENDING} GROUP BY channel) h ON o.id = h.id ORDER BY o.id"
            ).fetchall()

    def run_once(self) -> float | None:
        """Try every channel's due head message once (and its successors while they succeed).

        Returns the wall-clock time of the next retry due, or None when nothing is pending.
        """
        next_due: float | None = None
        for msg_id, channel, key, payload, attempts, due in self._heads():
            while msg_id is not None:
                now = self.clock()
                if due > now:
                    next_due = due if next_due is None else min(next_due, due)
                    break
                try:
                    self.senders[channel](payload, key)
                except PermanentDeliveryError as exc:  # refused: keep it aside, go on
                    with self._lock:
                        self._db.execute(
                            "UPDATE outbox SET attempts = ?, dead_s = ?, last_error = ? "
                            "WHERE id = ?", (attempts + 1, now, str(exc)[:2000], msg_id))
                        self._count(channel, "dead_total")
                        self._enqueued.pop(msg_id, None)
                    log.error("alert delivery refused; kept as a dead letter "
                              "(buoymon alerts outbox)",
                              extra={"fields": {"channel": channel, "key": key,
                                                "error": str(exc)[:2000]}})
                except Exception as exc:  # any other failure of the receiver: retry later
                    attempts += 1
                    backoff = min(self.retry_max_s, self.retry_base_s * 2 ** (attempts - 1))
                    due = now + backoff * self.rng.uniform(0.5, 1.0)
                    with self._lock:
                        self._db.execute(
                            "UPDATE outbox SET attempts = ?, next_attempt_s = ?, last_error = ? "
                            "WHERE id = ?", (attempts, due, repr(exc)[:500], msg_id))
                        self._count(channel, "failures_total")
                    log.warning("alert delivery failed; will retry",
                                extra={"fields": {"channel": channel, "key": key,
                                                  "attempts": attempts, "error": repr(exc)}})
                    next_due = due if next_due is None else min(next_due, due)
                    break
                else:
                    with self._lock:
                        self._db.execute(
                            "UPDATE outbox SET delivered_s = ?, attempts = ? WHERE id = ? "
                            "AND delivered_s IS NULL", (self.clock(), attempts + 1, msg_id))
                        self._count(channel, "delivered_total")
                        self._enqueued.pop(msg_id, None)
                with self._lock:
                    row = self._db.execute(
                        "SELECT id, dedup_key, payload, attempts, next_attempt_s FROM outbox "
                        f"WHERE channel = ? AND {_PENDING} ORDER BY id LIMIT 1",
                        (channel,)).fetchone()
                msg_id, key, payload, attempts, due = row if row else (None,) * 5
        return next_due

    def start(self) -> None:
        """Start the background sender thread (idempotent)."""
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._loop, name="alert-outbox", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            # clear before looking, so an enqueue during run_once still wakes the wait below
            self._wake.clear()
            try:
                next_due = self.run_once()
            except sqlite3.Error:
                log.exception("alert outbox database error")
                next_due = self.clock() + self.retry_base_s
            wait = 3600.0 if next_due is None else max(0.0, next_due - self.clock())
            self._wake.wait(wait)

    def stop(self, timeout: float = 10.0) -> None:
        """Stop the sender thread (pending messages stay stored for the next start)."""
        if self._thread is None:
            return
        self._stop.set()
        self._wake.set()
        self._thread.join(timeout)
        self._thread = None

    def close(self) -> None:
        self.stop()
        with self._lock:
            self._db.close()

    # --- inspection ------------------------------------------------------------------------
    def pending(self) -> int:
        with self._lock:
            return self._db.execute(f"SELECT COUNT(*) FROM outbox WHERE {_PENDING}").fetchone()[0]

    def pending_by_channel(self) -> dict[str, int]:
        """Messages still to send, per channel (every channel, 0 included)."""
        return {ch: int(st["pending"]) for ch, st in self.stats().items()}

    def stats(self) -> dict[str, dict[str, Any]]:
        """Per channel: ``pending``, ``dead_letters`` (held now), ``oldest_pending_age_s``
        and the persistent counters of :data:`COUNTERS` (status["delivery"]["channels"])."""
        with self._lock:
            # the oldest pending message: the first enqueued (ids increase); when an earlier
            # process left it, this process's own oldest one may still be older by now
            pend = self._db.execute(
                f"SELECT o.channel, h.n, o.id, o.created_s FROM outbox o JOIN (SELECT "
                f"channel, COUNT(*) AS n, MIN(id) AS id FROM outbox WHERE {_PENDING} GROUP BY "
                "channel) h ON o.id = h.id").fetchall()
            wall, mono = self.clock(), self.monotonic()
            mine: dict[str, float] = {}
            for ch, t in self._enqueued.values():
                mine.setdefault(ch, mono - t)
            ages = {ch: max(mine.get(ch, 0.0), 0.0 if i in self._enqueued else wall - created)
                    for ch, _, i, created in pend}
            dead = dict(self._db.execute(
                "SELECT channel, COUNT(*) FROM outbox WHERE dead_s IS NOT NULL "
                "GROUP BY channel").fetchall())
            counts = self._db.execute("SELECT channel, name, value FROM outbox_counters"
                                      ).fetchall()
        channels = sorted(set(self.senders) | {r[0] for r in pend} | set(dead)
                          | {r[0] for r in counts})
        out = {ch: {"pending": 0, "dead_letters": dead.get(ch, 0), "oldest_pending_age_s": None,
                    **dict.fromkeys(COUNTERS, 0)} for ch in channels}
        for ch, n, _, _ in pend:
            out[ch]["pending"] = n
            out[ch]["oldest_pending_age_s"] = max(0.0, ages[ch])
        for ch, name, value in counts:
            if ch in out and name in out[ch]:
                out[ch][name] = value
        return out

    def messages(self, dead_only: bool = False) -> list[dict]:
        """Stored messages (delivered, pending or dead), oldest first; ``dead_only`` lists the
        dead letters alone."""
        where = "WHERE dead_s IS NOT NULL " if dead_only else ""
        with self._lock:
            rows = self._db.execute(
                "SELECT id, channel, dedup_key, attempts, created_s, delivered_s, dead_s, "
                f"last_error FROM outbox {where}ORDER BY id").fetchall()
        keys = ("id", "channel", "dedup_key", "attempts", "created_s", "delivered_s", "dead_s",
                "last_error")
        return [dict(zip(keys, r)) for r in rows]

    def settle_dead(self, retry: bool) -> int:
        """Retry every dead letter (queued again, in its original order) or discard them all;
        returns how many."""
        with self._lock:
            if retry:
                cur = self._db.execute("UPDATE outbox SET dead_s = NULL, next_attempt_s = ? "
                                       "WHERE dead_s IS NOT NULL", (self.clock(),))
            else:
                cur = self._db.execute("DELETE FROM outbox WHERE dead_s IS NOT NULL")
        self._wake.set()
        return cur.rowcount

    def prune(self, older_than_s: float) -> int:
        """Delete messages delivered more than ``older_than_s`` ago; returns how many."""
        with self._lock:
            cur = self._db.execute("DELETE FROM outbox WHERE delivered_s IS NOT NULL AND "
                                   "delivered_s < ?", (self.clock() - older_than_s,))
        return cur.rowcount
