"""A piece of saved state that never changes once made, so a store writes it once.

The late copies (:mod:`monitor.late_copies`) keep the last hour of received samples in the
state, per closed minute: 0.8 MB of a daemon's 1.4 MB state, of which one minute in sixty
changes between two checkpoints. A :class:`Part` marks such a piece: the daemon's checkpoint
store (:class:`monitor.checkpoint.CheckpointStore`) keeps it under its content's hash,
writes it with the first checkpoint that holds it and deletes it with the first that no
longer does, instead of rewriting it every few seconds. Everywhere else (a replay's state
file, the state queryable, ``json.dumps``) it is the plain string it is.
"""

from __future__ import annotations

import hashlib
from functools import cached_property


def part_key(data: bytes) -> str:
    """The key a part is stored under: a hash of its bytes (a damaged part does not match)."""
    return hashlib.blake2b(data, digest_size=16).hexdigest()


class Part(str):
    """A string of state made once and never changed (see the module doc)."""

    @cached_property
    def key(self) -> str:
        """:func:`part_key` of its ASCII/UTF-8 bytes (hashed once per part, not per save)."""
        return part_key(self.encode())
