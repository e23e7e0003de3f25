"""The replay with its reading and stream stage in a child process (replay.stage_process)
gives what one process gives, to the last bit: report, state, every step, tick observation
and block the sinks see, the reader's statistics; on the faulty feed of test_stages and on
the Maine load cell's measured tension (../shared/realdata, imported to a log). A child that
fails, dies or outlives an error here leaves a clear error and no process behind."""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from monitor.blocks import SampleBlock
from monitor.cli import main
from replay import stage_process
from replay.reader import LogReader
from replay.runner import run_blocks
from replay.stage_process import ChildDied, child_pays
from test_stages import CONFIG, Recorder, faulty_blocks

SHARED = next((p / "shared" for p in Path(__file__).resolve().parents
               if (p / "shared/realdata").is_dir()), None)
MAINE = None if SHARED is None else (
    SHARED / "realdata/maine_endline_loadcell/17348481-2018.11.30-09.58.27-15.csv")
LBF = 4.4482216152605  # N

needs_fork = pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(),
                                reason="no fork on this platform")
pytestmark = needs_fork


def _replay(blocks, child: bool, sinks=(), config=CONFIG) -> tuple[bytes, object]:
    pipeline, result = run_blocks(config, blocks, sinks=sinks, child=child)
    out = json.dumps([pipeline.report(), pipeline.state()], allow_nan=True).encode()
    return out, result


@pytest.fixture(scope="module")
def feed():
    return faulty_blocks()[0]


@pytest.mark.parametrize("sink", [Recorder, None], ids=["sink-with-block-hook", "no-sink"])
def test_the_child_gives_the_same_bits_as_one_process_on_the_faulty_feed(feed, sink):
    seen = {}
    outs = {}
    for child in (False, True):
        sinks = [sink()] if sink is not None else []
        outs[child], result = _replay(iter(feed), child, sinks)
        assert (result.blocks, result.samples) == (len(feed), sum(len(b) for b in feed))
        seen[child] = sinks[0].seen if sinks else None
    assert outs[True] == outs[False]
    assert seen[True] == seen[False]
    if sink is not None:
        assert len(seen[True]) > 1000
    assert multiprocessing.active_children() == []


def test_blocks_of_another_buoy_are_counted_in_the_child_as_in_one_process(feed):
    other = [SampleBlock("other", b.sensor, b.t_ns, b.fields) for b in feed[10:40:3]]
    blocks = feed[:10] + other + feed[10:]
    results = [_replay(iter(blocks), child)[1] for child in (False, True)]
    assert results[0].ignored_blocks == results[1].ignored_blocks == {"other": len(other)}
    assert results[0].blocks == results[1].blocks == len(feed)


def test_an_empty_source_gives_the_empty_pipeline():
    assert _replay(iter([]), True)[0] == _replay(iter([]), False)[0]


@pytest.mark.integration
@pytest.mark.skipif(MAINE is None or not MAINE.exists(), reason="../shared/realdata absent")
def test_the_child_gives_the_same_bits_and_reader_statistics_on_measured_tension(tmp_path,
                                                                                  capsys):
    raw = np.genfromtxt(MAINE, delimiter=",", usecols=(1, 2))
    csv = tmp_path / "in.csv"
    csv.write_text("time_s,tension_N\n" + "\n".join(
        f"{s!r},{v!r}" for s, v in zip(raw[:, 0].tolist(), (raw[:, 1] * LBF).tolist())) + "\n")
    log = tmp_path / "in.mcap"
    assert main(["import", str(csv), "-o", str(log), "--buoy-id", "vaps"]) == 0
    capsys.readouterr()
    outs, stats = [], []
    for child in (False, True):
        reader = LogReader([log])
        out, result = _replay(reader, child)
        outs.append(out)
        stats.append([s.as_dict() for s in reader.stats])
        assert result.samples == raw.shape[0]
    assert outs[0] == outs[1]
    assert stats[0] == stats[1] and stats[1][0]["messages"] > 0
    report = json.loads(outs[1])[0]
    assert report["samples"]["tension"]["accepted"] == raw.shape[0]
    assert report["components"]["conductor"]["damage_committed"] > 0


def test_an_error_in_the_child_is_raised_here_and_no_child_is_left(feed):
    def failing():
        yield from feed[:200]
        raise OSError("disk went away")

    with pytest.raises(OSError, match="disk went away"):
        run_blocks(CONFIG, failing(), child=True)
    assert multiprocessing.active_children() == []


def test_an_exception_that_does_not_pickle_arrives_as_its_text(feed):
    class Odd(Exception):
        def __reduce__(self):
            raise TypeError("no pickling")

    def failing():
        yield from feed[:20]
        raise Odd("the odd one")

    with pytest.raises(RuntimeError, match="the odd one"):
        run_blocks(CONFIG, failing(), child=True)
    assert multiprocessing.active_children() == []


def test_a_child_that_dies_is_a_clear_error_not_a_hang(feed):
    parent = os.getpid()

    def killed():
        yield from feed[:100]
        if os.getpid() != parent:  # in the child: as if the kernel's OOM killer struck
            os.kill(os.getpid(), signal.SIGKILL)
        yield from feed[100:]

    with pytest.raises(ChildDied, match="killed by SIGKILL"):
        run_blocks(CONFIG, killed(), child=True)
    assert multiprocessing.active_children() == []


def test_an_error_here_stops_the_child(feed):
    class Failing(Recorder):
        steps = 0

        def on_step(self, step) -> None:
            self.steps += 1
            if self.steps == 30:
                raise OSError("sink full")

    with pytest.raises(OSError, match="sink full"):
        run_blocks(CONFIG, iter(feed * 3), sinks=[Failing()], child=True)
    assert multiprocessing.active_children() == []


def test_idle_cpus_counts_a_busy_cpu_as_busy():
    """Another process spinning through the whole sample: at most all CPUs but about one
    idle (a thread of this process would count as idle: its CPU is the replay's own)."""
    import time

    other = subprocess.Popen([sys.executable, "-c", "import time\nstop = time.monotonic() + 0.6"
                              "\nwhile time.monotonic() < stop: pass"])
    time.sleep(0.2)  # started and spinning
    idle = stage_process.idle_cpus(0.2)
    other.wait()
    assert 0 <= idle <= (os.cpu_count() or 1) - 0.7


def test_idle_cpus_counts_the_work_it_runs_meanwhile_as_idle():
    """The replay loads its kernels while it measures: that CPU is this process's own,
    which the replay will have, so it counts as idle (else a busy measurement)."""
    import time

    def spin() -> None:
        stop = time.monotonic() + 0.3
        while time.monotonic() < stop:
            pass

    # another process busy meanwhile (on a 2-CPU machine: nothing idle but this one's CPU)
    other = subprocess.Popen([sys.executable, "-c", "import time\nstop = time.monotonic() + 0.5"
                              "\nwhile time.monotonic() < stop: pass"])
    time.sleep(0.05)
    wall, cpu = time.monotonic(), time.process_time()
    idle = stage_process.idle_cpus(0.05, meanwhile=spin)
    wall, cpu = time.monotonic() - wall, time.process_time() - cpu
    other.wait()
    assert wall >= 0.3
    # at least the CPU this process had meanwhile (/proc/stat counts in 10-ms ticks)
    assert cpu / wall - 0.1 <= idle <= (os.cpu_count() or 1)


def test_the_child_is_used_with_two_cpus_and_a_large_enough_log(tmp_path, monkeypatch, capsys):
    csv = tmp_path / "in.csv"
    csv.write_text("time_s,tension_N\n" + "\n".join(f"{i / 20},{5000 + i % 7}"
                                                     for i in range(2000)) + "\n")
    log = tmp_path / "in.mcap"
    assert main(["import", str(csv), "-o", str(log), "--buoy-id", "vaps"]) == 0
    capsys.readouterr()
    assert not child_pays([log])  # a small log: one process
    monkeypatch.setattr(stage_process, "CHILD_MIN_BYTES", 1)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(stage_process, "idle_cpus", lambda **_: 1.6)
    assert child_pays([log])
    monkeypatch.setattr(stage_process, "idle_cpus", lambda **_: 1.4)
    assert not child_pays([log])  # another job on the second CPU: one process
    monkeypatch.setattr(stage_process, "idle_cpus", lambda **_: 1.6)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {1})
    assert not child_pays([log])  # one CPU: one process
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(stage_process.sys, "platform", "darwin")
    assert not child_pays([log])  # not Linux: one process


def test_buoymon_replay_says_why_two_processes_were_not_used(tmp_path, feed, monkeypatch,
                                                             capsys):
    """Asked for two processes on a small log (or a busy machine), the replay ran in one and
    said nothing: the operator could not tell the flag had no effect."""
    from replay.writer import LogWriter

    log = tmp_path / "in.mcap"
    with LogWriter(log) as w:
        for b in feed:
            w.write_block(b)
    capsys.readouterr()
    args = ["replay", str(log), "--no-progress", "--two-processes"]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "two processes not used, one process replays: the logs hold less than 20 MB" in err
    monkeypatch.setattr(stage_process, "CHILD_MIN_BYTES", 1)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(stage_process, "idle_cpus", lambda **_: 0.7)
    assert main(args) == 0
    assert "one process replays: 0.7 of the machine's CPUs idle, 1.5 needed" in capsys.readouterr().err
    monkeypatch.setattr(stage_process, "idle_cpus", lambda **_: 2.0)
    assert main(args) == 0
    assert "two processes not used" not in capsys.readouterr().err
    assert main(["replay", str(log), "--no-progress"]) == 0  # not asked: nothing to say
    assert "two processes not used" not in capsys.readouterr().err


def test_buoymon_replay_says_so_when_the_child_dies_and_keeps_the_state(tmp_path, feed,
                                                                         monkeypatch, capsys):
    from monitor.pipeline import Pipeline
    from replay.writer import LogWriter

    log, state = tmp_path / "in.mcap", tmp_path / "state.json"
    with LogWriter(log) as w:
        for b in feed:
            w.write_block(b)
    assert main(["replay", str(log), "--state", str(state), "--no-progress"]) == 0
    saved = state.read_bytes()
    monkeypatch.setattr(stage_process, "CHILD_MIN_BYTES", 1)
    # the child whatever the machine's load (child_pays measures the idle CPUs: on a busy
    # machine one process replayed, nothing died and the test failed)
    monkeypatch.setattr(stage_process, "idle_cpus", lambda **_: 2.0)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    parent, ingest = os.getpid(), Pipeline.ingest

    def dying(self, *blocks):  # in the child only: as if the kernel's OOM killer struck
        if os.getpid() != parent:
            os.kill(os.getpid(), signal.SIGKILL)
        return ingest(self, *blocks)

    monkeypatch.setattr(Pipeline, "ingest", dying)
    capsys.readouterr()
    # --one-process: no child to die
    assert main(["replay", str(log), "--report", str(tmp_path / "r.json"), "--no-progress",
                 "--one-process"]) == 0
    for asked in ([], ["--two-processes"]):  # the child by default, as when asked
        assert main(["replay", str(log), "--state", str(state), "--no-progress", *asked]) == 1
        err = capsys.readouterr().err
        assert "reading process ended without finishing the log (killed by SIGKILL)" in err
        assert "no report or state written" in err
        assert state.read_bytes() == saved
        assert multiprocessing.active_children() == []


def test_a_pipe_that_cannot_grow_still_gives_the_same_bits(feed, monkeypatch):
    """F_SETPIPE_SZ refused (EPERM: pipe-max-size lowered, or the user's pipe pages spent):
    the replay goes on through the default pipe; it crashed with the refusal."""
    import fcntl

    want = _replay(iter(feed), False)[0]
    real = fcntl.fcntl

    def refused(fd, cmd, *arg):
        if cmd == fcntl.F_SETPIPE_SZ:
            raise PermissionError(1, "Operation not permitted")
        return real(fd, cmd, *arg)

    monkeypatch.setattr(fcntl, "fcntl", refused)
    assert _replay(iter(feed), True)[0] == want
    assert multiprocessing.active_children() == []


def _slots(monkeypatch) -> list:
    """The parent's slot readers of the replays to come."""
    made = []
    real = stage_process._SlotReader.__init__

    def init(self, *args):
        real(self, *args)
        made.append(self)

    monkeypatch.setattr(stage_process._SlotReader, "__init__", init)
    return made


def test_the_hand_overs_go_through_the_shared_slots_and_come_back(feed, monkeypatch):
    slots = _slots(monkeypatch)
    sent = []
    real = stage_process._SlotReader.load
    monkeypatch.setattr(stage_process._SlotReader, "load",
                        lambda self, *a: sent.append(a[1]) or real(self, *a))
    assert _replay(iter(feed), True)[0] == _replay(iter(feed), False)[0]
    # the slabs with samples came through the slots, each slot reused many times, and every
    # slot was back with the child at the end
    assert len(sent) > 50 and set(sent) == set(range(stage_process.SLOTS))
    assert slots[0].lost == 0 and slots[0].owners == {}


class Keeper(Recorder):
    """A sink that keeps each step's load arrays (views of a slot's memory) for a while."""

    def __init__(self, keep: int) -> None:
        super().__init__()
        self.keep, self.kept = keep, []

    def on_step(self, step) -> None:
        super().on_step(step)
        self.kept = [*self.kept, (step.t_ns, step.tension_N)][-self.keep:]


@pytest.mark.parametrize("keep", [1, 50])
def test_a_slot_something_still_refers_to_is_not_given_back(feed, monkeypatch, keep):
    """A sink keeping the steps' arrays (one slab's, or more than there are slots): those
    slots are held until it lets go, the child sends through the pipe meanwhile, and every
    kept array still holds its own samples: the same bits and steps as one process."""
    slots = _slots(monkeypatch)
    outs, kept = {}, {}
    for child in (False, True):
        keeper = Keeper(keep)
        outs[child] = _replay(iter(feed), child, [keeper])[0]
        kept[child] = [(t.tolist(), v.tolist()) for t, v in keeper.kept]
        assert kept[child] and len(kept[child][-1][0]) > 0
    assert outs[True] == outs[False] and kept[True] == kept[False]
    assert slots[0].lost > 0  # held by the sink, answered so
    assert multiprocessing.active_children() == []


def test_a_slab_larger_than_a_slot_goes_through_the_pipe(feed, monkeypatch):
    want = _replay(iter(feed), False)[0]
    monkeypatch.setattr(stage_process, "SLOT_BYTES", 4096)
    slots = _slots(monkeypatch)
    assert _replay(iter(feed), True)[0] == want
    assert slots[0].lost == 0


def test_a_slot_is_released_only_once_nothing_refers_to_its_arrays():
    """The two sides of the slots in this process: a slab's arrays live in the slot (no
    copy); while one of them, or a view of one, is referred to, the slot is answered held
    and the writer does not take it; once let go, it is freed and taken again."""
    maps = stage_process._shared_slots(2, 1 << 16)
    answers_read, answers_write = os.pipe()
    data_read, data_write = os.pipe()
    writer = stage_process._SlotWriter(data_write, maps, answers_read)
    reader = stage_process._SlotReader(maps, answers_write)
    os.set_blocking(data_read, False)
    try:
        def send(values):
            writer.send("slab", values, stage_process._Pickler)
            writer.flush()
            got = stage_process._receive(data_read, reader)[1]
            reader.flush()  # (answers are written two at a time, or before a wait)
            return got

        got = send([np.arange(1000.0), np.arange(7, dtype=np.int8)])
        assert got[0].tolist() == list(range(1000)) and got[1].tolist() == list(range(7))
        first = next(iter(reader.owners))
        assert np.shares_memory(got[0], np.frombuffer(maps[first], np.uint8))  # no copy
        view = got[0][10:20]
        del got
        reader.release()
        reader.flush()
        assert reader.held == {first} and reader.lost == 1
        other = send([np.full(100, 3.0)])  # the other slot
        reader.release()
        reader.flush()
        assert reader.held == {0, 1} and reader.lost == 2
        # both held, none on its way: the writer sends through the pipe rather than wait
        assert writer.take(800) is None
        third = send([np.arange(5.0)])
        assert third[0].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0] and len(reader.owners) == 2
        assert other[0].tolist() == [3.0] * 100  # the slots untouched meanwhile
        del other
        reader.release()
        reader.flush()
        assert reader.held == {first}
        assert writer.take(800) == 1 - first  # freed: taken again
        assert view.tolist() == list(range(10, 20))  # still its own samples
        # a writer that broke the protocol (wrote the held slot) is caught, not trusted
        writer.free.append(first)
        with pytest.raises(RuntimeError, match=f"slot {first} written while still in use"):
            send([np.zeros(10)])
        del view
        reader.release()
        assert not reader.held and reader.owners == {}
    finally:
        for fd in (answers_read, answers_write, data_read, data_write):
            os.close(fd)


def test_a_replay_keeps_freed_memory_with_glibc_and_goes_on_without(monkeypatch):
    """glibc's malloc takes the replay's thresholds; another C library (no mallopt, or no
    libc.so.6) leaves the replay as it is."""
    import ctypes
    import platform

    from replay import runner

    if platform.libc_ver()[0] != "glibc":
        pytest.skip("not a glibc system")
    assert runner.keep_freed_memory() is True

    def no_libc(name):
        raise OSError(f"{name}: cannot open shared object file")

    monkeypatch.setattr(ctypes, "CDLL", no_libc)
    assert runner.keep_freed_memory() is False


def test_a_log_cut_short_replays_in_two_processes_by_its_size_on_disk(tmp_path, feed,
                                                                      monkeypatch, capsys):
    """A log cut short by a crash (no summary) replayed in one process whatever its size,
    and --two-processes said it held "less than 20 MB of data": a 30-day log whose logger
    died took the slow path with a false reason. Its bytes on disk bound its data from
    below; with them, the child runs, to the same bits as one process."""
    from replay.log_files import inflated_size
    from replay.writer import LogWriter

    whole, cut = tmp_path / "whole.mcap", tmp_path / "cut.mcap"
    with LogWriter(whole) as w:
        for b in feed:
            w.write_block(b)
    data = whole.read_bytes()
    cut.write_bytes(data[:len(data) * 9 // 10])
    assert inflated_size([cut]) is None
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(stage_process, "idle_cpus", lambda **_: 2.0)
    monkeypatch.setattr(stage_process, "CHILD_MIN_BYTES", cut.stat().st_size + 1)
    assert stage_process.one_process_reason([cut]) == (
        f"the logs have no summary (cut short or damaged) and their files hold less than "
        f"{(cut.stat().st_size + 1) / 1e6:g} MB")
    monkeypatch.setattr(stage_process, "CHILD_MIN_BYTES", cut.stat().st_size)
    assert child_pays([cut])
    capsys.readouterr()
    reports = {}
    for mode in ("--one-process", "--two-processes"):
        out = tmp_path / f"r{mode}.json"
        assert main(["replay", str(cut), "--no-progress", mode, "--report", str(out)]) == 0
        assert "two processes not used" not in capsys.readouterr().err
        reports[mode] = out.read_bytes()
    assert reports["--one-process"] == reports["--two-processes"]
    assert json.loads(reports["--one-process"])["inputs"]["read"]["incomplete_files"] == [str(cut)]
    assert multiprocessing.active_children() == []


def test_buoymon_replay_says_why_two_processes_were_not_used_in_a_fleet(tmp_path, feed,
                                                                        capsys):
    """Logs of two buoys (a fleet replay) with --two-processes replayed each buoy in one
    process and said nothing, where one buoy's replay says why."""
    from replay.writer import LogWriter

    for buoy in ("vaps", "other"):
        (tmp_path / buoy).mkdir()
        with LogWriter(tmp_path / buoy / "a.mcap") as w:
            for b in feed[:200]:
                w.write_block(SampleBlock(buoy, b.sensor, b.t_ns, b.fields))
    said = "--two-processes not used: a fleet replay runs each buoy in one process"
    capsys.readouterr()
    for flags, says in ((["--two-processes"], True), ([], False)):
        args = ["replay", str(tmp_path / "vaps"), str(tmp_path / "other"), "--no-progress",
                "--report-dir", str(tmp_path / "out"), *flags]
        assert main(args) == 0
        assert (said in capsys.readouterr().err) is says
    assert sorted(p.name for p in (tmp_path / "out/buoys").iterdir()) == ["other.json",
                                                                          "vaps.json"]


@pytest.mark.skipif(not Path("/proc/self/comm").exists(), reason="Linux's /proc only")
def test_the_child_is_named_so_an_operator_can_find_it_in_ps():
    """The child's command line is its parent's: ps, top and pgrep showed two identical
    `buoymon replay` processes, and `pkill -9 -f` of the reading one killed both. It names
    itself: `pgrep -x buoymon-stream`, `ps -C buoymon-stream`."""
    def blocks():  # read in the child: it tells the name it runs under
        raise RuntimeError(Path("/proc/self/comm").read_text().strip())
        yield

    with pytest.raises(RuntimeError) as caught:
        run_blocks(CONFIG, blocks(), child=True)
    assert str(caught.value) == stage_process.CHILD_NAME == "buoymon-stream"
    assert Path("/proc/self/comm").read_text().strip() != "buoymon-stream"  # not this one
    assert multiprocessing.active_children() == []
