"""Publishing a log recorded or simulated at another time to a live daemon: `buoymon simulate`
dates its logs 2000-01-01, so a daemon judged every block 26.9 years behind its clock
(clock_skew) and nothing said why. `buoymon publish --retime now` moves the log to the
current time; without it the publisher says at once that the log is far off the clock and
what to do; `buoymon simulate --start now` dates a log now. Real `buoymon run`, real
`buoymon publish` and `buoymon simulate` processes on loopback."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("monitor.pipeline")

from monitor.blocks import SampleBlock  # noqa: E402
from daemon_harness import ENV, free_port, wait_until_state  # noqa: E402
from replay.publish import ClockCheck, retime_target, retimed  # noqa: E402
from replay.reader import iter_blocks  # noqa: E402
from test_daemon_e2e import BUOY, start_daemon, write_config  # noqa: E402

pytestmark = pytest.mark.integration  # processes on loopback: not in `make test-fast`

NS = 10**9
Y2000_NS = 946_684_800 * NS  # 2000-01-01T00:00:00Z, simulate's default start
MINUTES = 3


def _cli(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "monitor.cli", *args], env=ENV,
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def sim(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("retime") / "sim.mcap"
    run = _cli("simulate", "-o", str(path), "--hours", str(MINUTES / 60), "--hs", "1",
               "--tp", "6", "--seed", "5")
    assert run.returncode == 0, run.stderr
    return path


def test_retimed_moves_every_sample_by_one_whole_second_count(sim):
    blocks = list(iter_blocks(sim, coalesce=False))
    assert blocks[0].t_first_ns == Y2000_NS
    target = retime_target("now", clock=lambda: 1_764_126_000 * NS + 700_000_000)
    assert target == 1_764_126_000 * NS
    moved = list(retimed(iter(blocks), target))
    assert moved[0].t_first_ns == target
    for a, b in zip(blocks, moved):
        assert (a.sensor, len(a)) == (b.sensor, len(b))
        assert np.array_equal(b.t_ns - a.t_ns, np.full(len(a), target - Y2000_NS))
        assert b.recv_ns - a.recv_ns == target - Y2000_NS
        assert all(np.array_equal(a.fields[f], b.fields[f]) for f in a.fields)
    # a first sample off the whole second keeps its phase (the shift is whole seconds)
    t = Y2000_NS + 300_000_000 + 50_000_000 * np.arange(20, dtype=np.int64)
    block = SampleBlock(BUOY, "tension", t, {"tension_N": np.ones(20)}, int(t[-1]))
    (moved,) = retimed([block], retime_target("2026-01-01T00:00:00Z"))
    assert moved.t_first_ns == retime_target("2026-01-01T00:00:00.3Z")
    assert moved.recv_ns - block.recv_ns == moved.t_first_ns - block.t_first_ns


def test_the_clock_check_says_how_far_off_which_way_and_what_to_do():
    """Each block is compared with the clock right after it went out (when the next is asked
    for): 600 s off is allowed, 600 s and a nanosecond is not; said once, counted always."""
    now = 1_764_126_000 * NS
    sent = []

    def block(t_last_ns: int) -> SampleBlock:
        t = t_last_ns - 50_000_000 * np.arange(19, -1, -1, dtype=np.int64)
        return SampleBlock(BUOY, "tension", t, {"tension_N": np.ones(20)}, t_last_ns)

    cases = [(False, [now - 600 * NS, now - 3 * 3600 * NS - 1, now - 600 * NS - 1],
              "3 h behind this machine's clock: a daemon raises clock_skew for blocks more "
              "than 600 s off; re-time it with --retime now"),
             (False, [now + 900 * NS], "15 min ahead of this machine's clock: a daemon raises "
              "clock_skew for blocks more than 600 s off; samples more than 600 s ahead are "
              "rejected as time_ahead; re-time it with --retime now, and publish at real time "
              "(--speed 1)"),
             (True, [now + 600 * NS, now + 601 * NS], "10 min ahead of this machine's clock: a "
              "daemon raises clock_skew for blocks more than 600 s off; samples more than 600 s "
              "ahead are rejected as time_ahead; publish at real time (--speed 1) to keep a "
              "re-timed log on the clock")]
    for was_retimed, times, said in cases:
        sent.clear()
        check = ClockCheck([block(t) for t in times], sent.append, was_retimed,
                           clock=lambda: now)
        assert [b.t_last_ns for b in check] == times
        (first,) = sent
        assert first.startswith("the log's sensor time (") and first.endswith(said), first
        off = sum(abs(t - now) > 600 * NS for t in times)
        assert check.off == off and check.blocks == len(times)
        assert check.summary() == (f"{off} of {len(times)} blocks were published more than "
                                   "600 s off this machine's clock")
    quiet = ClockCheck([block(now - 600 * NS), block(now + 600 * NS)], sent.append, False,
                       clock=lambda: now)
    assert len(list(quiet)) == 2 and quiet.summary() is None


def test_a_log_of_another_time_is_re_timed_for_a_live_daemon_or_said_far_off(sim, tmp_path):
    port = free_port()
    cfg = write_config(tmp_path, port, load_source="measured")
    d = start_daemon(cfg, tmp_path)
    n_blocks = len(list(iter_blocks(sim, coalesce=False)))
    tension_blocks = MINUTES * 60
    try:
        before = time.time_ns()
        run = _cli("publish", str(sim), "--connect", f"tcp/127.0.0.1:{port}", "--retime", "now")
        assert run.returncode == 0 and run.stdout.strip() == str(n_blocks), run.stderr
        assert "warning" not in run.stderr, run.stderr  # 3 min from now: within 600 s
        st = wait_until_state(port, lambda s: s["status"]["counters"]["messages"] == n_blocks,
                              buoy=BUOY)["status"]
        tension = st["streams"]["tension"]
        # every sample taken (none time_ahead), but the last ones the live ordering horizon
        # (10 s) still holds for the other streams
        assert not any(tension["rejected"].values()), tension["rejected"]
        assert (MINUTES * 60 - 10) * 20 <= tension["accepted"] <= MINUTES * 60 * 20
        assert tension["clock_skewed_blocks"] == 0 and abs(tension["clock_skew_s"]) <= 600
        assert before // NS * NS - NS <= tension["last_t_ns"] - MINUTES * 60 * NS \
            <= time.time_ns()
        assert not [a for a in st["alerts"]["active"] if a["rule"] == "clock_skew"]
        # the same log as it is, dated 2000: said at once, and counted at the end
        run = _cli("publish", str(sim), "--connect", f"tcp/127.0.0.1:{port}")
        assert run.returncode == 0 and run.stdout.strip() == str(n_blocks), run.stderr
        lines = run.stderr.splitlines()
        assert any(line.startswith("buoymon publish: warning: the log's sensor time "
                                   "(2000-01-01T00:") and "is 26.9 years behind this "
                   "machine's clock: a daemon raises clock_skew for blocks more than 600 s "
                   "off; re-time it with --retime now" in line for line in lines), run.stderr
        assert (f"buoymon publish: warning: {n_blocks:,} of {n_blocks:,} blocks were published "
                "more than 600 s off this machine's clock") in lines
        # the live rules judge each status as it is built: the alert is in a later one
        st = wait_until_state(port, lambda s: s["status"]["counters"]["messages"]
                              == 2 * n_blocks and any(a["rule"] == "clock_skew" for a in
                                                      s["status"]["alerts"]["active"]),
                              buoy=BUOY)["status"]
        assert st["streams"]["tension"]["clock_skewed_blocks"] == tension_blocks
    finally:
        assert d.terminate() == 0


def test_simulate_start_now_dates_the_log_now_and_the_default_stays_2000(sim, tmp_path):
    before = time.time_ns() // NS * NS
    path = tmp_path / "now.mcap"
    run = _cli("simulate", "-o", str(path), "--hours", "0.01", "--hs", "1", "--tp", "6",
               "--seed", "5", "--start", "now")
    after = time.time_ns()
    assert run.returncode == 0, run.stderr
    first = next(iter(iter_blocks(path, coalesce=False))).t_first_ns
    assert before <= first <= after and first % NS == 0
    assert next(iter(iter_blocks(sim, coalesce=False))).t_first_ns == Y2000_NS
