"""The bulk parser of delimited lines (all the lines of a read at once, with numpy) gives the
bridge exactly the blocks, samples and rejections of the line-by-line parser: on the Maine
load cell (its own date-time cells, and as Unix seconds) with faults injected, read in
chunks of every size."""

from __future__ import annotations

from datetime import datetime, timezone

import numpy as np
import pytest

from monitor.bridge.config import parse_bridge_config
from monitor.bridge.formats import Rejected, instrument_time, unix_times
from monitor.bridge.runner import Bridge
from test_bridge import LBF, MAINE, maine_lines

pytestmark = pytest.mark.skipif(not MAINE.exists(), reason="shared/realdata not beside the project")
MAINE_FORMAT = "%Y-%m-%d-%H:%M:%S.%f"


class Blocks:
    """Keeps what the bridge publishes (the publisher's one method it calls)."""

    def __init__(self) -> None:
        self.blocks: list = []

    def publish_block(self, block) -> None:
        self.blocks.append(block)


def _unix(line: str) -> str:
    """A Maine line with its time cell as Unix seconds to the ms (a fixed-width layout)."""
    cell, rest = line.split(",", 1)
    dt = datetime.strptime(cell, MAINE_FORMAT).replace(tzinfo=timezone.utc)
    return f"{dt.timestamp():.3f},{rest}"


def _faulty(lines: list[str]) -> list[bytes]:
    """Faults in place of lines of ``lines`` (a cell edited) and inserted between them."""
    out = [ln.encode() for ln in lines]

    def cell(k: int, i: int, text: str) -> bytes:
        cells = lines[k].split(",")
        cells[i] = text
        return ",".join(cells).encode()

    edits = {130: cell(130, 2, "nan"), 260: cell(260, 2, "4e400"), 600: cell(600, 2, "abc"),
             500: cell(500, 0, "2018x"), 300: out[300] + b"\t",  # rejected
             200: out[200] + b",extra,columns", 400: cell(400, 2, " 41 "),  # read
             450: cell(450, 2, "1_0"), 560: b" " + out[560]}
    for k, line in edits.items():
        out[k] = line
    inserted = {7: b"\xf0\x0f\xaa garbage", 40: b"1.0, 2.0",  # garbled, columns
                90: out[89], 340: cell(340, 0, lines[10].split(",")[0])}  # backwards
    for k in sorted(inserted, reverse=True):
        out.insert(k, inserted[k])
    return out


def _run(lines: list[bytes], time_format: str, bulk: bool, cuts: list[int]):
    connect = {"connect": ["tcp/127.0.0.1:7447"]}  # never opened: handle() alone is driven
    cfg = parse_bridge_config({"buoy": {"id": "t1"}, "bridge": connect, "source": [{
        "name": "lc", "sensor": "tension", "transport": "stdin", "columns": {"tension_N": 2},
        "scale": {"tension_N": LBF}, "offset": {"tension_N": -3.0}, "time_column": 0,
        "time_format": time_format, "block_s": 20.0}]})
    out = Blocks()
    bridge = Bridge(cfg, out)
    src = bridge.sources[0]
    used = [0]
    if bulk:
        many = src.parse_many

        def counted(chunk, recv_ns):
            got = many(chunk, recv_ns)
            used[0] += got is not None
            return got

        src.parse_many = counted
    else:
        src.parse_many = None
    for a, b in zip(cuts[:-1], cuts[1:]):
        bridge.handle(0, "lines", lines[a:b], 1_800_000_000 * 10**9)
    bridge._flush(src)
    return out.blocks, src, used[0]


@pytest.mark.parametrize("unix", [False, True])
@pytest.mark.parametrize("chunks", ["random", "long"])
def test_bulk_and_line_by_line_give_the_same_blocks_and_rejections(unix, chunks):
    raw = maine_lines(1500)
    lines = _faulty([_unix(ln) for ln in raw] if unix else raw)
    rng = np.random.default_rng(4)
    cuts = [0]
    while cuts[-1] < len(lines):  # long: each fault in a chunk of 40 (most lines clean)
        step = int(rng.choice([1, 2, 3, 5, 17, 60, 150])) if chunks == "random" else 40
        cuts.append(min(len(lines), cuts[-1] + step))
    fmt = "unix" if unix else MAINE_FORMAT
    one, src1, _ = _run(lines, fmt, False, cuts)
    many, src2, used = _run(lines, fmt, True, cuts)
    assert used >= 10  # most chunks went the bulk way
    assert len(one) == len(many) >= 20  # ~8 min of 3-Hz samples in 20-s blocks
    for a, b in zip(one, many):
        assert a.t_ns.tolist() == b.t_ns.tolist()
        assert a.fields["tension_N"].view(np.int64).tolist() == \
            b.fields["tension_N"].view(np.int64).tolist()
    assert (src1.samples, src1.lines) == (src2.samples, src2.lines) == (1500 - 5, len(lines))
    assert dict(src1.rejected) == dict(src2.rejected) == {
        "garbled": 2, "columns": 1, "time_backwards": 2, "non_numeric": 3, "bad_time": 1}
    v = np.concatenate([b.fields["tension_N"] for b in many])
    assert v[0] == float(raw[0].split(",")[2]) * LBF - 3.0


def test_unix_time_cells_in_bulk_are_exact_or_left_to_the_line_parser():
    assert unix_times([b"1750000012.345", b"1750000013.001"]) == [
        1_750_000_012_345_000_000, 1_750_000_013_001_000_000]
    assert unix_times([b"1750000012.1234567891", b"0000000000.0000000009"]) == [
        1_750_000_012_123_456_789, 0]  # beyond the ns: cut, as one by one
    assert unix_times([b"1750000012", b"9223372036"]) == [
        1_750_000_012 * 10**9, 9_223_372_036 * 10**9]
    for cells in ([b"1750000012.5", b"1750000012.25"], [b"1750000012.5", b"17500000.125"],
                  [b"1750000012.", b"1750000013."], [b".5", b".6"], [b"-750000012.5"],
                  [b"1750000012.5", b"1750.0000125"], [b"17500.00012.5", b"1750000012.5"],
                  [b"9223372037"], [b"1750000012.x"], [b"1e9"], [b"+1750000012"], [b""]):
        assert unix_times(cells) is None, cells
    assert instrument_time("9223372036.854775807", "unix") == 2**63 - 1
    for cell, fmt in (("9223372036.854775808", "unix"), ("9999-12-31", "%Y-%m-%d")):
        with pytest.raises(Rejected, match="bad_time"):  # beyond the ns a block can hold
            instrument_time(cell, fmt)


def test_a_udp_flood_loses_no_datagram_while_reads_gather(tmp_path):
    """4,000 datagrams of two Maine lines each (Unix times), 200 at a time every 20 ms
    (10,000 a second): the bridge pauses its reads between blocks, yet every line arrives,
    in blocks, as sent."""
    import socket
    import time

    from daemon_harness import free_port
    from test_bridge import run_bridge

    raw = maine_lines(8000)
    lines = [_unix(ln) for ln in raw]
    udp_port, port = free_port(), free_port()

    def feed() -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as u:
            for k in range(0, len(lines), 400):
                for j in range(k, k + 400, 2):
                    u.sendto(f"{lines[j]}\n{lines[j + 1]}\n".encode(), ("127.0.0.1", udp_port))
                time.sleep(0.02)

    cfg = {"buoy": {"id": "t1"}, "bridge": {"connect": [f"tcp/127.0.0.1:{port}"]},
           "source": [{"name": "lc", "sensor": "tension", "transport": "udp", "port": udp_port,
                       "columns": {"tension_N": 2}, "time_column": 0, "block_s": 60.0}]}
    bridge, col = run_bridge(cfg, feed, port, lambda b: b.sources[0].lines >= len(lines))
    try:
        src = bridge.sources[0]
        assert (src.lines, src.samples, dict(src.rejected)) == (len(lines), len(lines), {})
        blocks = col.blocks()
        assert len(blocks) >= 40  # 8,000 samples at ~3 Hz in 60-s blocks
        v = np.concatenate([b.fields["tension_N"] for b in blocks])
        assert v.tolist() == [round(float(ln.split(",")[2]), 1) for ln in lines]
    finally:
        col.close()


@pytest.mark.parametrize("bulk", [False, True])
def test_one_corrupt_future_time_stamp_is_dropped_not_every_later_sample(bulk):
    """The Maine load cell re-timed to the logger's clock (Unix seconds), one line's time 10
    years ahead: that line is ``time_ahead`` and the other 299 go out. Was: the bridge took
    it, and every later line was ``time_backwards`` for good (seen on a pty: samples 101 of
    400 lines, rejected time_backwards 299, state "reading"). An instrument whose clock runs
    steadily an hour ahead, across a two-hour silence, loses nothing."""
    raw = maine_lines(300)
    r0 = 1_800_000_000 * 10**9
    step = 350_000_000

    def feed(offset_ns: int, leap_at: int | None, pause_at: int | None):
        cfg = parse_bridge_config({"buoy": {"id": "t1"}, "bridge": {"connect": [
            "tcp/127.0.0.1:7447"]}, "source": [{
                "name": "lc", "sensor": "tension", "transport": "stdin",
                "columns": {"tension_N": 2}, "time_column": 0, "time_format": "unix"}]})
        out = Blocks()
        bridge = Bridge(cfg, out)
        src = bridge.sources[0]
        if not bulk:
            src.parse_many = None
        recv = r0
        for k0 in range(0, len(raw), 10):  # reads of 10 lines, received as the last is sent
            chunk = []
            for k in range(k0, k0 + 10):
                recv += step + (7200 * 10**9 if k == pause_at else 0)
                t = recv + offset_ns + (10 * 365 * 86400 * 10**9 if k == leap_at else 0)
                chunk.append(f"{t // 10**9}.{t % 10**9:09d},{raw[k].split(',', 1)[1]}".encode())
            bridge.handle(0, "lines", chunk, recv)
        bridge._flush(src)
        return src, np.concatenate([b.t_ns for b in out.blocks])

    src, t = feed(-200_000_000, 105, None)  # the leap mid-read (bulk falls back to lines)
    assert (src.samples, dict(src.rejected)) == (299, {"time_ahead": 1})
    assert t.size == 299 and np.all(np.diff(t) > 0) and t[-1] < r0 + 300 * step
    src, t = feed(-200_000_000, 109, None)  # the leap as a read's last line
    assert (src.samples, dict(src.rejected)) == (299, {"time_ahead": 1})
    src, t = feed(3600 * 10**9, None, 150)  # steadily an hour ahead, then 2 h of silence
    assert (src.samples, dict(src.rejected), t.size) == (300, {}, 300)
