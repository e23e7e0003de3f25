"""Replay: split replay with a state file equals one pass to the last bit; the report contract;
the command line on real MCAP logs, including damaged ones."""

import io
import json
import struct
from pathlib import Path

from monitor.blocks import SampleBlock
from monitor.cli import main
from monitor.config import config_with, default_config
from replay.report import build_report, summary_text, write_report
from replay.runner import Progress, load_state, run_blocks, save_state
from replay.writer import LogWriter
from synthetic_buoy import S, T0, blocks_interleaved, sea

RULES = [
    {"kind": "damage_fraction", "name": "damage_warning", "threshold": 1e-6},
    {"kind": "conductor_stress", "threshold": 1.2},
    {"kind": "stale", "component": "tension", "on_delay_s": 0},
]


def config_with_rules():
    c = default_config()
    return config_with(c, alerts={**c.raw["alerts"], "rule": RULES}, component=[
        c.raw["component"][0], {**c.raw["component"][0], "name": "right", "lay": "right"}])


def test_split_replay_with_state_file_equals_one_pass(tmp_path):
    config = config_with_rules()
    blocks = blocks_interleaved(sea(1800, gap=(600, 660)), 60)
    one, _ = run_blocks(config, blocks)
    ref = one.report()
    assert ref["alerts"], "the rules must fire for this test to mean something"
    state_file = tmp_path / "state.json"
    cut = next(i for i, b in enumerate(blocks) if b.t_first_ns >= T0 + 777 * S)
    for part in (blocks[:cut], blocks[cut:]):
        p, _ = run_blocks(config, part, state=load_state(state_file))
        save_state(state_file, p.state())
    got = p.report()
    for name in ref["components"]:
        assert got["components"][name]["damage_committed"] == ref["components"][name]["damage_committed"]
        assert got["components"][name]["damage"] == ref["components"][name]["damage"]
    assert got["alerts"] == ref["alerts"]
    assert got == ref
    assert [f.name for f in tmp_path.iterdir()] == ["state.json"]  # no temporary files left


def test_report_contract_and_summary(tmp_path):
    config = config_with_rules()
    p, result = run_blocks(config, blocks_interleaved(sea(300), 30))
    report = build_report(p.config, p.report(), ["a.mcap"], {"messages": 10, "lost_ranges": 2})
    assert result.samples == sum(len(b) for b in blocks_interleaved(sea(300), 30))
    for key in ("buoy_id", "time_start", "time_end", "samples", "tension_N", "components", "alerts"):
        assert key in report
    assert report["time_start"] == "2023-11-14T22:13:20.000Z"  # T0 = 1.7e9 s
    assert set(report["samples"]) == {"tension", "imu", "gnss"}
    assert set(report["samples"]["tension"]["rejected"]) == {
        "nan", "out_of_range", "spike", "duplicate", "time_backwards", "flat_line",
        "check_factor", "time_ahead"}
    assert set(report["samples"]["tension"]["qc"]) == {
        "gross_range", "spike", "rate_of_change", "flat_line"}
    assert set(report["samples"]["gnss"]["qc"]) >= {"location"}
    assert report["motion_sensor"] == "imu" and report["load_problems"] == []
    assert set(report["tension_N"]) >= {"min", "mean", "max", "p99"}
    for comp in report["components"].values():
        assert set(comp) >= {"damage", "damage_committed", "cycles", "max_stress_Pa",
                             "damage_rate_per_day", "remaining_life_days"}
    left, right = report["components"]["conductor"], report["components"]["right"]
    assert left["lay"] == "left" and right["lay"] == "right"
    assert left["damage"] > right["damage"] >= 0
    path = tmp_path / "r.json"
    write_report(path, report)
    assert json.loads(path.read_text()) == report
    text = summary_text(report)
    assert "conductor" in text and "right" in text and "lost ranges 2" in text


def test_progress_bar_only_when_enabled():
    out = io.StringIO()
    bar = Progress(out, span_ns=100 * S, enabled=True)
    bar.update(T0, 0, force=True)
    bar.update(T0 + 50 * S, 1000, force=True)
    bar.close()
    assert "50.0%" in out.getvalue()
    quiet = io.StringIO()
    Progress(quiet, None, enabled=False).update(T0, 10, force=True)
    assert quiet.getvalue() == ""


def test_buoy_of_the_log_replaces_the_default_config_buoy():
    blocks = [SampleBlock("b7", b.sensor, b.t_ns, b.fields) for b in blocks_interleaved(sea(60), 10)]
    p, result = run_blocks(default_config(), blocks)
    assert p.buoy_id == "b7" and p.report()["samples"]["tension"]["accepted"] > 0


# ------------------------------------------------------------------- on real MCAP logs
def write_log(path: Path, blocks) -> None:
    with LogWriter(path) as w:
        for b in blocks:
            w.write_block(b, recv_ns=b.t_last_ns + 1)


def test_replay_command_split_logs_and_state(tmp_path, capsys):
    blocks = blocks_interleaved(sea(1200), 1)
    cut = len(blocks) // 2
    write_log(tmp_path / "all.mcap", blocks)
    (tmp_path / "parts").mkdir()
    write_log(tmp_path / "parts" / "a.mcap", blocks[:cut])
    write_log(tmp_path / "parts" / "b.mcap", blocks[cut:])
    assert main(["replay", str(tmp_path / "all.mcap"), "--report", str(tmp_path / "one.json")]) == 0
    out = capsys.readouterr().out
    assert "conductor" in out and "one.json" in out
    state = tmp_path / "state.json"
    for part in ("a", "b"):
        assert main(["replay", str(tmp_path / "parts" / f"{part}.mcap"), "--state", str(state),
                     "--report", str(tmp_path / f"{part}.json")]) == 0
    one = json.loads((tmp_path / "one.json").read_text())
    two = json.loads((tmp_path / "b.json").read_text())
    assert two["components"] == one["components"]
    assert two["samples"] == one["samples"]
    # a missing file among others is skipped, not fatal
    assert main(["replay", str(tmp_path / "all.mcap"), str(tmp_path / "gone.mcap"),
                 "--report", str(tmp_path / "skip.json")]) == 0
    assert json.loads((tmp_path / "skip.json").read_text())["components"] == one["components"]
    # a directory replays its files in order: the same as one pass
    assert main(["replay", str(tmp_path / "parts"), "--report", str(tmp_path / "dir.json")]) == 0
    assert json.loads((tmp_path / "dir.json").read_text())["components"] == one["components"]


def test_replay_exits_non_zero_only_when_nothing_could_be_read(tmp_path, capsys):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all" * 10)
    assert main(["replay", str(junk)]) == 1
    assert "nothing could be read" in capsys.readouterr().err
    assert main(["replay", str(tmp_path / "missing.mcap")]) == 1
    assert "no log files" in capsys.readouterr().err
    # a log cut in the middle still replays what is intact
    write_log(tmp_path / "cut.mcap", blocks_interleaved(sea(600), 1))
    data = (tmp_path / "cut.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    assert main(["replay", str(tmp_path / "cut.mcap"), "--report", str(tmp_path / "r.json")]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert 0 < report["samples"]["tension"]["accepted"] < 600 * 20
    assert report["inputs"]["read"]["incomplete_files"]


def test_paced_replay_follows_sensor_time():
    import time

    blocks = blocks_interleaved(sea(3), 1)
    run_blocks(default_config(), blocks)  # warm-up: compiled code, the estimator's table
    start = time.monotonic()
    run_blocks(default_config(), blocks)
    fast = time.monotonic() - start
    start = time.monotonic()
    run_blocks(default_config(), blocks, speed=4.0)
    paced = time.monotonic() - start
    # 3 s of data at 4 x real time: the last blocks start 2 s after the first, i.e. 0.5 s
    assert paced - fast >= 0.45


def test_ctrl_c_ends_a_replay_with_status_130_and_leaves_the_state_file(tmp_path, capsys,
                                                                         monkeypatch):
    import replay.runner

    write_log(tmp_path / "a.mcap", blocks_interleaved(sea(60), 1))
    state = tmp_path / "state.json"
    assert main(["replay", str(tmp_path / "a.mcap"), "--state", str(state)]) == 0
    before = state.read_bytes()
    capsys.readouterr()

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(replay.runner, "run_blocks", interrupted)
    report = tmp_path / "r.json"
    assert main(["replay", str(tmp_path / "a.mcap"), "--state", str(state),
                 "--report", str(report)]) == 130
    captured = capsys.readouterr()
    assert "buoymon: interrupted" in captured.err and "Traceback" not in captured.err
    assert not report.exists() and state.read_bytes() == before


def test_logs_are_replayed_in_time_order_from_folders_and_sub_folders(tmp_path, capsys):
    blocks = blocks_interleaved(sea(600), 1)
    third = len(blocks) // 3
    write_log(tmp_path / "one.mcap", blocks)
    (tmp_path / "arch" / "2").mkdir(parents=True)
    # names that sort against time, one file in a sub-folder, one cut short (no summary)
    write_log(tmp_path / "arch" / "a.mcap", blocks[2 * third:])
    write_log(tmp_path / "arch" / "2" / "z.mcap", blocks[:third])
    write_log(tmp_path / "arch" / "b.mcap", blocks[third:2 * third])
    data = (tmp_path / "arch" / "b.mcap").read_bytes()
    (summary_start,) = struct.unpack_from("<Q", data, len(data) - 37 + 9)  # from the Footer
    assert data[summary_start - 13] == 0x0F  # the DataEnd record before the summary
    (tmp_path / "arch" / "b.mcap").write_bytes(data[:summary_start - 13])  # no DataEnd on
    assert main(["replay", str(tmp_path / "one.mcap"), "--report", str(tmp_path / "one.json")]) == 0
    assert main(["replay", str(tmp_path / "arch"), "--report", str(tmp_path / "arch.json")]) == 0
    one = json.loads((tmp_path / "one.json").read_text())
    arch = json.loads((tmp_path / "arch.json").read_text())
    assert arch["samples"] == one["samples"]
    assert arch["components"] == one["components"]
    assert [Path(f).name for f in arch["inputs"]["files"]] == ["z.mcap", "b.mcap", "a.mcap"]
    # a file named twice (itself and through its folder) is read once
    assert main(["replay", str(tmp_path / "arch" / "a.mcap"), str(tmp_path / "arch"),
                 "--report", str(tmp_path / "twice.json")]) == 0
    twice = json.loads((tmp_path / "twice.json").read_text())
    assert twice["samples"] == arch["samples"] and len(twice["inputs"]["files"]) == 3
    capsys.readouterr()
    # a folder without logs among others is named (was silent)
    (tmp_path / "empty").mkdir()
    assert main(["replay", str(tmp_path / "one.mcap"), str(tmp_path / "empty"),
                 "--report", str(tmp_path / "e.json")]) == 0
    assert capsys.readouterr().err.count(f"{tmp_path / 'empty'}: no *.mcap file in this folder") == 1
    assert json.loads((tmp_path / "e.json").read_text())["samples"] == one["samples"]


def test_replay_reads_ahead_only_with_a_cpu_to_spare(tmp_path, monkeypatch):
    """replay_logs in one process follows the reader's rule (replay.chunks.read_ahead_pays):
    allowed one CPU, no read-ahead thread (it costs CPU and saves no time); allowed two, one."""
    import os

    import replay.reader
    from replay.runner import replay_logs

    path = tmp_path / "a.mcap"
    write_log(path, blocks_interleaved(sea(20.0), 1.0))
    made = []

    class Spy(replay.reader.LogReader):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            made.append(self.read_ahead)

    monkeypatch.setattr(replay.reader, "LogReader", Spy)
    for cpus in ({0}, {0, 1}):
        monkeypatch.setattr(os, "sched_getaffinity", lambda pid, c=cpus: set(c))
        assert replay_logs(default_config(), [path], show_progress=False).samples > 0
    assert made == [False, True]


def test_the_progress_bar_of_a_finished_replay_reads_100_percent(tmp_path, capsys):
    """The bar counted from the first block's last time, not the log's start: coalesced
    blocks reach up to half an hour in, so a whole day's replay ended at 97.9% (23.5 h) and
    a 3-min log's at 0.0%: the operator could not tell it had read everything."""
    from monitor.cli import main
    from replay.runner import replay_logs

    log = tmp_path / "a.mcap"
    assert main(["simulate", "-o", str(log), "--hours", "0.05", "--hs", "1", "--tp", "6",
                 "--seed", "1"]) == 0
    capsys.readouterr()
    replay_logs(default_config(), [log], show_progress=True, two_processes=False)
    last = capsys.readouterr().err.rstrip("\n").split("\r")[-1]
    assert "100.0%" in last and "0.0 h" in last, last
