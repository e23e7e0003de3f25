"""scan_records locates the records of a byte sequence (https://mcap.dev/spec) exactly as
they were laid out, compiled and as plain Python."""

from __future__ import annotations

import struct

import numpy as np

from models._jit import uncompiled
from replay.mcap_scan import scan_records


def _record(op: int, content: bytes) -> bytes:
    return struct.pack("<BQ", op, len(content)) + content


def _message(channel: int, seq: int, log: int, pub: int, payload: bytes) -> bytes:
    return _record(5, struct.pack("<HIQQ", channel, seq, log, pub) + payload)


def test_records_are_located_with_their_fields_and_the_end_status():
    big = 2**63 + 12345  # a time whose top bit is set reads as the int64 of the same bits
    parts = [_message(3, 1, 1_700_000_000_000_000_001, 1_700_000_000_000_000_002, b"abc"),
             _record(4, b"\x07" * 11),  # a channel record: another record
             _message(258, 2, big, 7, b""),
             _message(1, 3, 5, 6, bytes(range(200)))]
    whole = b"".join(parts)
    starts = np.cumsum([0] + [len(p) for p in parts])
    for cut, status in ((whole, 0), (whole[:-5], 1), (whole + b"\x00" * 12, 2)):
        for mode in ("compiled", "plain"):
            buf = np.frombuffer(cut, np.uint8)
            if mode == "plain":
                with uncompiled():
                    got = scan_records(buf)
            else:
                got = scan_records(buf)
            ch, log, pub, doff, dlen, oop, ooff, olen, end, st = got
            n = 3 if status != 1 else 2
            assert st == status
            assert ch.tolist() == [3, 258, 1][:n]
            assert log.tolist() == [1_700_000_000_000_000_001, big - 2**64, 5][:n]
            assert pub.tolist() == [1_700_000_000_000_000_002, 7, 6][:n]
            assert doff.tolist() == [int(starts[i]) + 9 + 22 for i in (0, 2, 3)][:n]
            assert dlen.tolist() == [3, 0, 200][:n]
            assert (oop.tolist(), ooff.tolist(), olen.tolist()) == ([4], [int(starts[1]) + 9], [11])
            assert end == (len(whole) if status != 1 else int(starts[3]))
