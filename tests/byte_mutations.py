"""Random byte edits of encoded payloads, shared by the decoders' fuzz tests."""

from __future__ import annotations

import numpy as np


def mutated(payload: bytes, rng: np.random.Generator, k: int) -> bytes:
    """``payload`` with one random edit at a random offset: the ``k``-th mutant overwrites a
    byte (k % 3 == 0), deletes 1-3 bytes (1) or inserts two random bytes (2)."""
    b = bytearray(payload)
    i = int(rng.integers(0, len(b)))
    edit = k % 3
    if edit == 0:
        b[i] = int(rng.integers(0, 256))
    elif edit == 1:
        del b[i:i + int(rng.integers(1, 4))]
    else:
        b[i:i] = bytes(rng.integers(0, 256, 2).astype(np.uint8))
    return bytes(b)
