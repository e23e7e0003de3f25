"""replay.merge's kernels against the formulation they replace (compiled and as plain
Python): the pending table's columns of a run of records, where a release's held-back
messages lie in their streams, and the coalesced blocks of a release."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from models import _jit
from replay.merge import LOG, N, PUB, SEQ, START, STREAM, _fill_rows, _groups, _held_runs


@pytest.mark.parametrize("plain", [False, True])
def test_fill_rows_is_the_columns_of_the_selected_messages(plain):
    rng = np.random.default_rng(7)
    pub = rng.integers(0, 10**6, 50)
    log = pub + rng.integers(0, 1000, 50)
    sel = np.sort(rng.choice(50, 20, replace=False))
    n = rng.integers(1, 30, 20)
    table = np.full((6, 25), -1, np.int64)
    with _jit.uncompiled() if plain else contextlib.nullcontext():
        lo, hi, late = _fill_rows(table[:, 3:23], 4, pub, log, sel, n, 100, 1000,
                                  int(np.median(pub[sel])))
    rows = table[:, 3:23]
    assert (rows[STREAM] == 4).all() and np.array_equal(rows[PUB], pub[sel])
    assert np.array_equal(rows[LOG], log[sel]) and np.array_equal(rows[N], n)
    assert np.array_equal(rows[START], 100 + np.cumsum(n) - n)
    assert np.array_equal(rows[SEQ], sel + 1000)
    assert (table[:, :3] == -1).all() and (table[:, 23:] == -1).all()  # only those columns
    assert (lo, hi) == (pub[sel].min(), pub[sel].max())
    assert late == np.count_nonzero(pub[sel] <= np.median(pub[sel])) == 10


@pytest.mark.parametrize("plain", [False, True])
def test_held_runs_finds_each_streams_run_or_says_it_is_broken(plain):
    # canonical order interleaves streams 0 and 2 (1 holds nothing); each stream's messages
    # are back to back: 0 from sample 40, 2 from sample 7
    stream = np.array([0, 2, 0, 2, 2, 0])
    start = np.array([40, 7, 43, 9, 14, 50])
    n = np.array([3, 2, 7, 5, 1, 2])
    with _jit.uncompiled() if plain else contextlib.nullcontext():
        lo, hi, starts = _held_runs(stream, start, n, 3)
        assert lo.tolist() == [40, 0, 7] and hi.tolist() == [52, 0, 15]
        assert starts.tolist() == [0, 0, 3, 2, 7, 10]  # keep_only's cumsum(n) - n per stream
        start[3] = 10  # a gap in stream 2: the caller gathers instead
        assert _held_runs(stream, start, n, 3)[2] is None
        start[3], start[5] = 9, 49  # stream 0's last message overlaps the one before
        assert _held_runs(stream, start, n, 3)[2] is None


def _groups_by_division(order, stream, pub, log, start, n, span_ns, n_streams):
    """The coalesced blocks as first written: each message's span by a division."""
    blocks, member, open_block, span = [], [], {}, 0
    for k in order:
        sp = (pub[k] - pub[order[0]]) // span_ns
        if sp != span:
            open_block, span = {}, sp
        b = open_block.get(stream[k])
        if b is None:
            b = open_block[stream[k]] = len(blocks)
            blocks.append([stream[k], start[k], start[k] + n[k], log[k], False])
        else:
            blocks[b][4] |= start[k] != blocks[b][2]
            blocks[b][3] = max(blocks[b][3], log[k])
            blocks[b][2] = start[k] + n[k]
        member.append(b)
    return blocks, member


@pytest.mark.parametrize("plain", [False, True])
@pytest.mark.parametrize("sorted_pub", [True, False])
def test_groups_cut_spans_as_a_division_per_message_does(plain, sorted_pub):
    rng = np.random.default_rng(11 + sorted_pub)
    m = 400
    pub = np.cumsum(rng.integers(0, 40, m)) if sorted_pub else rng.integers(-300, 900, m)
    stream = rng.integers(0, 3, m)
    n = rng.integers(1, 5, m)
    start = np.zeros(m, np.int64)
    for s in range(3):  # back to back in each stream, but for a few gaps
        mine = stream == s
        start[mine] = np.cumsum(n[mine]) - n[mine] + (rng.random(mine.sum()) < 0.05)
    log = pub + rng.integers(0, 50, m)
    order = np.arange(m)
    with _jit.uncompiled() if plain else contextlib.nullcontext():
        count, sid, lo, hi, latest, apart, member = _groups(order, stream, pub, log, start, n,
                                                             100, 3)
    blocks, want_member = _groups_by_division(order, stream, pub, log, start, n, 100, 3)
    assert count == len(blocks) > 20
    got = [list(x) for x in zip(sid.tolist(), lo.tolist(), hi.tolist(), latest.tolist(),
                                apart.tolist())]
    assert got == [[int(a), int(b), int(c), int(d), bool(e)] for a, b, c, d, e in blocks]
    assert member.tolist() == want_member
