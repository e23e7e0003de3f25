"""A durable outbox: alert notifications survive restarts and are retried with backoff.

Messages are rows of a SQLite database (WAL journal, ``synchronous=FULL``, so an enqueued
message is on disk before :meth:`Outbox.enqueue` returns). A background thread delivers them,
per channel strictly in enqueue order (a "clear" never overtakes its "fire"): the head message
of a channel is retried with exponential backoff (``retry_base_s`` doubling up to
``retry_max_s``) until its sender succeeds, and only then is it marked delivered, in its own
transaction. Enqueueing is idempotent on ``(channel, dedup_key)``, so a pipeline that re-emits
the same transitions after resuming from a checkpoint does not notify twice.

Delivery is at-least-once only across a crash between a successful send and the commit that
marks it delivered (no HTTP/SMTP receiver can be made transactional with SQLite); receivers
can use the ``dedup_key`` (sent as the webhook's ``Idempotency-Key`` header) to drop that rare
repeat.

Retry timing is the only place in the alert path that uses the wall clock: sensor time does
not advance while a receiver is down.
"""

from __future__ import annotations

import logging
import sqlite3
import threading
import time
from typing import Callable, Mapping

log = logging.getLogger(__name__)

# A sender delivers one payload or raises; the dedup key lets it pass an idempotency key on.
Sender = Callable[[bytes, str], None]

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
"""


class Outbox:
    """SQLite-backed queue of notifications with a background sender thread.

    Args:
        path: database file (created if missing).
        senders: channel name -> callable(payload, dedup_key) that delivers or raises.
        retry_base_s, retry_max_s: backoff after the n-th failure is
            ``min(retry_max_s, retry_base_s * 2**(n-1))`` seconds.
        clock: wall-clock seconds (injectable for tests).
    """

    def __init__(self, path: str, senders: Mapping[str, Sender], retry_base_s: float = 5.0,
                 retry_max_s: float = 600.0, clock: Callable[[], float] = time.time) -> None:
        if not retry_base_s > 0 or not retry_max_s >= retry_base_s:
            raise ValueError(f"outbox retry_base_s = {retry_base_s!r}, retry_max_s = "
                             f"{retry_max_s!r}: need 0 < retry_base_s <= retry_max_s")
        self.path = str(path)
        self.senders = dict(senders)
        self.retry_base_s = float(retry_base_s)
        self.retry_max_s = float(retry_max_s)
        self.clock = clock
        # one connection shared by the enqueuing thread and the sender thread, serialised by
        # a lock; the lock is never held while a sender talks to the network
        self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=FULL")
        self._db.executescript(_SCHEMA)
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # --- producer side ---------------------------------------------------------------------
    def enqueue(self, channel: str, dedup_key: str, payload: bytes) -> bool:
        """Store a message durably; False if ``(channel, dedup_key)`` was already stored."""
        if channel not in self.senders:
            raise ValueError(f"outbox channel {channel!r}: no sender; have {sorted(self.senders)}")
        now = self.clock()
        with self._lock:
            cur = self._db.execute(
                "INSERT OR IGNORE INTO outbox (channel, dedup_key, payload, created_s, "
                "next_attempt_s) VALUES (?, ?, ?, ?, ?)",
                (channel, dedup_key, bytes(payload), now, now),
            )
        added = cur.rowcount == 1
        if added:
            self._wake.set()
        return added

    # --- consumer side ---------------------------------------------------------------------
    def _heads(self) -> list[tuple[int, str, str, bytes, int, float]]:
        with self._lock:
            return self._db.execute(
                "SELECT o.id, o.channel, o.dedup_key, o.payload, o.attempts, o.next_attempt_s "
                "FROM outbox o JOIN (SELECT channel, MIN(id) AS id FROM outbox "
                "WHERE delivered_s IS NULL GROUP BY channel) h ON o.id = h.id ORDER BY o.id"
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
                except Exception as exc:  # any failure of the receiver means: retry later
                    attempts += 1
                    due = now + min(self.retry_max_s, self.retry_base_s * 2 ** (attempts - 1))
                    with self._lock:
                        self._db.execute(
                            "UPDATE outbox SET attempts = ?, next_attempt_s = ?, last_error = ? "
                            "WHERE id = ?", (attempts, due, repr(exc)[:500], msg_id))
                    log.warning("alert delivery failed; will retry",
                                extra={"fields": {"channel": channel, "key": key,
                                                  "attempts": attempts, "error": repr(exc)}})
                    next_due = due if next_due is None else min(next_due, due)
                    break
                with self._lock:
                    self._db.execute(
                        "UPDATE outbox SET delivered_s = ?, attempts = ? WHERE id = ? "
                        "AND delivered_s IS NULL", (self.clock(), attempts + 1, msg_id))
                    row = self._db.execute(
                        "SELECT id, dedup_key, payload, attempts, next_attempt_s FROM outbox "
                        "WHERE channel = ? AND delivered_s IS NULL ORDER BY id LIMIT 1",
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
            return self._db.execute(
                "SELECT COUNT(*) FROM outbox WHERE delivered_s IS NULL").fetchone()[0]

    def pending_by_channel(self) -> dict[str, int]:
        """Messages not yet delivered, per channel (every channel, 0 included)."""
        with self._lock:
            rows = self._db.execute("SELECT channel, COUNT(*) FROM outbox WHERE delivered_s IS "
                                    "NULL GROUP BY channel").fetchall()
        return {**dict.fromkeys(self.senders, 0), **dict(rows)}

    def messages(self) -> list[dict]:
        """All stored messages (delivered or not), oldest first, for inspection and tests."""
        with self._lock:
            rows = self._db.execute(
                "SELECT id, channel, dedup_key, attempts, delivered_s, last_error FROM outbox "
                "ORDER BY id").fetchall()
        keys = ("id", "channel", "dedup_key", "attempts", "delivered_s", "last_error")
        return [dict(zip(keys, r)) for r in rows]

    def prune(self, older_than_s: float) -> int:
        """Delete messages delivered more than ``older_than_s`` ago; returns how many."""
        with self._lock:
            cur = self._db.execute("DELETE FROM outbox WHERE delivered_s IS NOT NULL AND "
                                   "delivered_s < ?", (self.clock() - older_than_s,))
        return cur.rowcount
