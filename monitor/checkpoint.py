"""Crash-safe store for the pipeline's state (damage, rainflow residue, last times, alerts).

One SQLite database in WAL mode with ``synchronous=FULL``: a checkpoint is one transaction
that replaces the single state row (deflated JSON), so after a power cut or ``kill -9`` at any
moment the database holds either the previous checkpoint or the new one, never a mixture.
Together with the pipeline's per-stream last-timestamp check (samples at or before the
checkpoint are skipped when delivered again), no closed cycle is lost or counted twice.

The state is any nesting of dicts (string keys), lists, tuples, str, int, float, bool, None,
bytes and numpy arrays/scalars. It is stored as JSON in which numpy arrays keep their dtype,
shape and exact bytes, so a restored state is bit-identical.

Write-once parts (:class:`monitor.state_part.Part`: the late copies' closed minutes, ~60 % of
a daemon's state) are kept apart, one row each under their content's hash, in the same
transaction as the state that refers to them: a checkpoint writes the parts it is the first to
hold and deletes the ones no state refers to any more, so each is written once, not every few
seconds. A part missing or not matching its hash (a damaged card) is restored as None: the
pipeline loses what it held and says so (:class:`monitor.late_copies.LateCopies`), the rest
of the state loads.
"""

from __future__ import annotations

import base64
import json
import math
import os
import sqlite3
import time
import zlib
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from monitor.state_part import Part, part_key

_TAG = "__t"


def encode_state(state: Any, parts: dict[str, Part] | None = None) -> bytes:
    """Serialise ``state`` losslessly (see module doc for the supported types). With
    ``parts``, each :class:`Part` is written as a reference to its key and collected there
    (the caller stores it); without, as the string it is."""
    return json.dumps(_enc(state, parts), separators=(",", ":"), allow_nan=False).encode()


def decode_state(data: bytes, parts: Mapping[str, str] | None = None) -> Any:
    """Inverse of :func:`encode_state`: a reference to a part is the :class:`Part` in
    ``parts``, or None if it is not there (missing or damaged)."""
    return _dec(json.loads(data), parts or {})


def decode_checkpoint(path: str, seq: int, data: bytes,
                      parts: Mapping[str, str] | None = None) -> Any:
    """:func:`decode_state` of the checkpoint ``seq`` read from ``path`` (deflated, or plain
    JSON as written before); a damaged one is a ValueError naming the file (was a bare
    "Expecting value: line 1 column 1 (char 0)")."""
    try:
        return decode_state(data if data[:1] == b"{" else zlib.decompress(data), parts)
    except (ValueError, TypeError, KeyError, zlib.error) as exc:
        raise ValueError(f"{path}: checkpoint {seq} is damaged ({exc}); the file is left as "
                         "it is: move it aside to start afresh") from None


def _enc(x: Any, parts: dict[str, Part] | None) -> Any:
    if isinstance(x, Part) and parts is not None:
        parts[x.key] = x
        return {_TAG: "part", "k": x.key}
    if isinstance(x, np.ndarray):
        a = np.ascontiguousarray(x)
        if a.dtype.hasobject:
            raise ValueError(f"checkpoint: object arrays cannot be stored ({a.dtype})")
        return {_TAG: "nd", "dtype": a.dtype.str, "shape": list(a.shape),
                "b64": base64.b64encode(a.tobytes()).decode()}
    if isinstance(x, np.generic):
        # numpy scalars keep their dtype (a float32 must come back as float32)
        return {_TAG: "np", "dtype": x.dtype.str, "b64": base64.b64encode(x.tobytes()).decode()}
    if isinstance(x, bool) or x is None or isinstance(x, (int, str)):
        return x
    if isinstance(x, float):
        # repr round-trips exactly; non-finite values are not JSON so they get a tag
        return x if math.isfinite(x) else {_TAG: "f", "v": repr(x)}
    if isinstance(x, (bytes, bytearray)):
        return {_TAG: "b", "b64": base64.b64encode(bytes(x)).decode()}
    if isinstance(x, Mapping):
        out = {}
        for k, v in x.items():
            if not isinstance(k, str) or k == _TAG:
                raise ValueError(f"checkpoint: state keys must be strings other than {_TAG!r}, "
                                 f"got {k!r}")
            out[k] = _enc(v, parts)
        return out
    if isinstance(x, tuple):
        return {_TAG: "tuple", "v": [_enc(v, parts) for v in x]}
    if isinstance(x, list):
        return [_enc(v, parts) for v in x]
    raise ValueError(f"checkpoint: cannot store a value of type {type(x).__name__}")


def _dec(x: Any, parts: Mapping[str, str]) -> Any:
    if isinstance(x, list):
        return [_dec(v, parts) for v in x]
    if not isinstance(x, dict):
        return x
    tag = x.get(_TAG)
    if tag is None:
        return {k: _dec(v, parts) for k, v in x.items()}
    if tag == "part":
        text = parts.get(x["k"])
        return None if text is None else Part(text)
    if tag == "nd":
        raw = base64.b64decode(x["b64"])
        return np.frombuffer(raw, dtype=np.dtype(x["dtype"])).reshape(x["shape"]).copy()
    if tag == "np":
        return np.frombuffer(base64.b64decode(x["b64"]), dtype=np.dtype(x["dtype"]))[0]
    if tag == "f":
        return float(x["v"])
    if tag == "b":
        return base64.b64decode(x["b64"])
    if tag == "tuple":
        return tuple(_dec(v, parts) for v in x["v"])
    raise ValueError(f"checkpoint: unknown tag {tag!r} in stored state")


@dataclass(frozen=True)
class Checkpoint:
    """A stored state with its sequence number and wall-clock save time."""

    seq: int
    saved_ns: int
    state: Any


class CheckpointStore:
    """SQLite (WAL, synchronous=FULL) holding the latest checkpoint only, and the write-once
    parts it refers to (see the module doc)."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = os.fspath(path)
        parent = os.path.dirname(os.path.abspath(self.path))
        os.makedirs(parent, exist_ok=True)
        self._db = sqlite3.connect(self.path, isolation_level=None)
        try:
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            # this build zeroes every freed page (secure_delete=ON): the replaced state's pages
            # were written a second time, zeros, with each checkpoint
            self._db.execute("PRAGMA secure_delete=FAST")
            self._db.execute(
                "CREATE TABLE IF NOT EXISTS checkpoint ("
                " id INTEGER PRIMARY KEY CHECK (id = 1), seq INTEGER NOT NULL,"
                " saved_ns INTEGER NOT NULL, state BLOB NOT NULL)"
            )
            self._db.execute("CREATE TABLE IF NOT EXISTS parts ("
                             " key TEXT PRIMARY KEY, data BLOB NOT NULL)")
            # the parts in the file: a save writes the others it refers to, deletes the rest
            self._stored = {k for (k,) in self._db.execute("SELECT key FROM parts")}
            self._damaged: set[str] = set()  # of those, the ones found not matching their key
        except sqlite3.DatabaseError as exc:  # another file, or a damaged one: never overwritten
            self._db.close()
            raise ValueError(f"{self.path}: not a checkpoint database ({exc}); the file is "
                             "left as it is: move it aside to start afresh") from None

    def load(self) -> Checkpoint | None:
        """The latest checkpoint, or None if nothing was saved yet."""
        row = self._db.execute("SELECT seq, saved_ns, state FROM checkpoint WHERE id = 1").fetchone()
        if row is None:
            return None
        return Checkpoint(int(row[0]), int(row[1]),
                          decode_checkpoint(self.path, row[0], row[2], self._sound_parts()))

    def _sound_parts(self) -> dict[str, str]:
        """The stored parts that match their key; the others are left out (restored as None,
        deleted or rewritten by the next save). An unreadable table loses them all, not the
        start: a save then fails loudly (``checkpoint_failed``) if it stays unwritable."""
        sound = {}
        try:
            for key, data in self._db.execute("SELECT key, data FROM parts"):
                if isinstance(data, bytes) and part_key(data) == key:
                    sound[key] = data.decode()
                else:
                    self._damaged.add(key)
        except sqlite3.DatabaseError:
            return {}
        return sound

    def save(self, state: Any) -> int:
        """Store ``state`` atomically and durably (with the parts it is the first to hold,
        without those it no longer holds); returns the new sequence number."""
        parts: dict[str, Part] = {}
        # deflated (level 1: the daemon's row 0.59 -> 0.11 MB for ~14 ms, bench/
        # bench_checkpoint.py), as the logger's card wears by the bytes written
        blob = zlib.compress(encode_state(state, parts), 1)
        db = self._db
        db.execute("BEGIN IMMEDIATE")
        try:
            db.executemany("INSERT OR REPLACE INTO parts (key, data) VALUES (?, ?)",
                           [(k, p.encode()) for k, p in parts.items()
                            if k not in self._stored or k in self._damaged])
            db.executemany("DELETE FROM parts WHERE key = ?",
                           [(k,) for k in self._stored.difference(parts)])
            row = db.execute("SELECT seq FROM checkpoint WHERE id = 1").fetchone()
            seq = (row[0] if row else 0) + 1
            db.execute("INSERT OR REPLACE INTO checkpoint (id, seq, saved_ns, state) "
                       "VALUES (1, ?, ?, ?)", (seq, time.time_ns(), blob))
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise
        self._stored, self._damaged = set(parts), set()
        return seq

    def close(self) -> None:
        self._db.close()


class PeriodicCheckpointer:
    """Saves ``get_state()`` at most every ``interval_s`` of monotonic time, and on demand."""

    def __init__(self, store: CheckpointStore, get_state: Callable[[], Any], interval_s: float,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.store, self._get_state, self.interval_s, self._clock = store, get_state, interval_s, clock
        self._last = clock()
        self.saves = 0

    def due_in(self) -> float:
        """Seconds until the next periodic save (<= 0 when due)."""
        return self._last + self.interval_s - self._clock()

    def maybe_save(self) -> bool:
        if self.due_in() > 0:
            return False
        self.save_now()
        return True

    def save_now(self) -> int:
        try:
            seq = self.store.save(self._get_state())
        finally:  # a failed save is retried after the interval, not on every call
            self._last = self._clock()
        self.saves += 1
        return seq
