"""The command line under bad input and unusual use: a clear message and a non-zero status,
never a traceback, a silent wrong number or a destroyed input file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from replay.writer import LogWriter, Series

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`

T0 = 946_684_800 * 10**9  # 2000-01-01T00:00:00Z


def tiny_log(path: Path, buoy: str = "qa", n: int = 40, t0_ns: int = T0) -> Path:
    """A 20 Hz tension log of ``n`` samples (a gentle sine, so a few cycles are counted)."""
    t = t0_ns + np.arange(n, dtype=np.int64) * 50_000_000
    v = 3000.0 + 500.0 * np.sin(np.arange(n) * 0.7)
    with LogWriter(path) as w:
        w.write_series([Series(buoy, "tension", t, v[None, :])], block_ns=10**9)
    return path


def test_replay_html_of_a_log_without_damage_rate(tmp_path, capsys):
    # a 2 s log accrues no damage rate: its report holds null for remaining life ("nothing
    # accrues"), which the HTML renderer must show as unlimited instead of failing
    log = tiny_log(tmp_path / "a.mcap")
    assert main(["replay", str(log), "--report", str(tmp_path / "r.json"),
                 "--html", str(tmp_path / "r.html")]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["components"]["conductor"]["remaining_life_days"] is None
    assert "<td>unlimited (no damage accrues)</td>" in (tmp_path / "r.html").read_text()
    capsys.readouterr()
    # and `buoymon report` renders the same JSON again
    assert main(["report", str(tmp_path / "r.json"), "-o", str(tmp_path / "again.html")]) == 0
    # a missing sample count is still named, not read as NaN
    report["samples"]["tension"].pop("accepted")
    (tmp_path / "bad.json").write_text(json.dumps(report))
    assert main(["report", str(tmp_path / "bad.json")]) == 2
    assert "samples.tension.accepted = None" in capsys.readouterr().err


def test_outputs_never_overwrite_an_input_file(tmp_path, capsys):
    log = tiny_log(tmp_path / "a.mcap")
    data = log.read_bytes()
    for option in ("--report", "--html", "--rrd"):
        assert main(["replay", str(log), option, str(log)]) == 2
        assert f"{option} {log}: is the input file" in capsys.readouterr().err
    # also when the log comes from a folder given on the command line
    assert main(["replay", str(tmp_path), "--report", str(log)]) == 2
    assert log.read_bytes() == data
    report = tmp_path / "r.json"
    assert main(["replay", str(log), "--report", str(report)]) == 0
    text = report.read_text()
    assert main(["report", str(report), "-o", str(report)]) == 2
    assert "is the input file" in capsys.readouterr().err
    assert report.read_text() == text
    csv = tmp_path / "m.csv"
    csv.write_text("time_s,tension_N\n0,100\n0.5,200\n")
    assert main(["import", str(csv), "-o", str(csv)]) == 2
    assert "-o" in capsys.readouterr().err
    assert csv.read_text() == "time_s,tension_N\n0,100\n0.5,200\n"


def test_an_output_that_is_a_folder_is_refused_before_any_work(tmp_path, capsys):
    log = tiny_log(tmp_path / "a.mcap")
    folder = tmp_path / "out"
    folder.mkdir()
    assert main(["replay", str(log), "--report", str(folder)]) == 2
    assert f"--report {folder}: is a folder" in capsys.readouterr().err
    assert main(["report", str(log), "-o", str(folder)]) == 2
    assert "is a folder" in capsys.readouterr().err
    csv = tmp_path / "m.csv"
    csv.write_text("time_s,tension_N\n0,100\n")
    assert main(["import", str(csv), "-o", str(folder)]) == 2
    assert "is a folder" in capsys.readouterr().err
    assert main(["simulate", "-o", str(folder), "--hours", "0.001", "--hs", "1", "--tp", "5",
                 "--seed", "1"]) == 2
    assert "is a folder" in capsys.readouterr().err


def test_an_output_that_cannot_be_written_is_refused_before_any_work(tmp_path, capsys):
    """Was: the whole replay ran, then "buoymon replay: [Errno 2] No such file or directory:
    '/proc/.x.json.691lshzr.tmp'" (a temporary file's name), exit status 1."""
    log = tiny_log(tmp_path / "a.mcap")
    assert main(["replay", str(log), "--report", "/proc/x.json"]) == 2
    out = capsys.readouterr()
    assert "replay: --report /proc/x.json: cannot write in /proc (" in out.err
    assert out.out == ""  # refused before the replay, not after it
    assert main(["replay", str(log), "--html", str(log / "sub" / "r.html")]) == 2
    assert f"--html {log / 'sub' / 'r.html'}: {log} is a file, not a folder" in \
        capsys.readouterr().err
    csv = tmp_path / "m.csv"
    csv.write_text("time_s,tension_N\n0,100\n")
    assert main(["import", str(csv), "-o", "/proc/m.mcap"]) == 2
    assert "-o /proc/m.mcap: cannot write in /proc" in capsys.readouterr().err


def test_files_that_cannot_be_read_or_written_give_a_message(tmp_path, capsys):
    missing = tmp_path / "no" / "such" / "x.mcap"
    assert main(["simulate", "-o", str(missing), "--hours", "0.001", "--hs", "1", "--tp", "5",
                 "--seed", "1"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("buoymon simulate: ") and str(missing) in err
    csv = tmp_path / "m.csv"
    csv.write_text("time_s,tension_N\n0,100\n")
    assert main(["import", str(csv), "-o", str(missing)]) == 1
    assert str(missing) in capsys.readouterr().err
    assert main(["simulate", "-o", "/dev/full", "--hours", "0.001", "--hs", "1", "--tp", "5",
                 "--seed", "1"]) == 1
    assert "No space left on device" in capsys.readouterr().err
    assert main(["check-config", str(tmp_path)]) in (1, 2)
    assert str(tmp_path) in capsys.readouterr().err


def test_state_file_continues_its_own_buoy_and_refuses_another(tmp_path, capsys):
    # a log of a buoy that is not the config's: the state saved by part 1 continues in part 2
    # (it used to be restored under the config's buoy id, so part 2 read nothing)
    one = tiny_log(tmp_path / "one.mcap", buoy="b7", n=400)
    assert main(["replay", str(one), "--report", str(tmp_path / "one.json")]) == 0
    first = tiny_log(tmp_path / "p1.mcap", buoy="b7", n=200)
    t = T0 + np.arange(200, 400, dtype=np.int64) * 50_000_000
    v = 3000.0 + 500.0 * np.sin(np.arange(200, 400) * 0.7)
    with LogWriter(tmp_path / "p2.mcap") as w:
        w.write_series([Series("b7", "tension", t, v[None, :])], block_ns=10**9)
    state = tmp_path / "state.json"
    assert main(["replay", str(first), "--state", str(state)]) == 0
    assert main(["replay", str(tmp_path / "p2.mcap"), "--state", str(state),
                 "--report", str(tmp_path / "two.json")]) == 0
    one_pass = json.loads((tmp_path / "one.json").read_text())
    two_parts = json.loads((tmp_path / "two.json").read_text())
    assert two_parts["samples"]["tension"]["accepted"] == 400
    assert (two_parts["components"]["conductor"]["damage_committed"]
            == one_pass["components"]["conductor"]["damage_committed"] > 0)
    capsys.readouterr()
    # a log of another buoy against that state: said so, and the state file is left as it was
    saved = state.read_text()
    other = tiny_log(tmp_path / "other.mcap", buoy="c9", t0_ns=T0 + 3600 * 10**9)
    assert main(["replay", str(other), "--state", str(state)]) == 1
    assert "the state is for buoy 'b7', the log for buoy 'c9'" in capsys.readouterr().err
    assert state.read_text() == saved


@pytest.mark.parametrize("text", ["[1, 2]", "42", '"state"', "null"])
def test_state_file_that_is_json_but_not_a_state(tmp_path, capsys, text):
    log = tiny_log(tmp_path / "a.mcap")
    (tmp_path / "s.json").write_text(text)
    assert main(["replay", str(log), "--state", str(tmp_path / "s.json")]) == 1
    assert "expected a JSON object" in capsys.readouterr().err


def test_times_beyond_nanosecond_time_stamps(tmp_path, capsys):
    # int64 ns since the epoch end in 2262; before, such times overflowed with a traceback
    csv = tmp_path / "far.csv"
    csv.write_text("time,tension_N\n2024-01-01T00:00:00Z,1\n2300-01-01T00:00:00Z,2\n"
                   "1969-12-31T23:59:59Z,3\n")
    assert main(["import", str(csv), "-o", str(tmp_path / "far.mcap")]) == 0
    err = capsys.readouterr().err
    assert "line 3: bad time '2300-01-01T00:00:00Z': after 2262-04-11T23:47:16" in err
    assert "line 4: bad time '1969-12-31T23:59:59Z': not after the Unix epoch" in err
    csv.write_text("time_s,tension_N\n1e30,1\n0,2\n")
    assert main(["import", str(csv), "-o", str(tmp_path / "far.mcap")]) == 0
    assert "line 2: bad time_s '1e30': after 2262" in capsys.readouterr().err
    assert main(["import", str(csv), "-o", str(tmp_path / "far.mcap"),
                 "--start", "2300-01-01T00:00:00Z"]) == 2
    assert "after 2262" in capsys.readouterr().err
    for block_s in ("1e-12", "1e30"):
        assert main(["import", str(csv), "-o", str(tmp_path / "far.mcap"),
                     "--block-s", block_s]) == 2
        assert f"--block-s {float(block_s)}: must be between" in capsys.readouterr().err
    sim = ["simulate", "-o", str(tmp_path / "s.mcap"), "--hs", "1", "--tp", "5", "--seed", "1"]
    assert main([*sim, "--hours", "1e9"]) == 2  # it used to write until the disk was full
    assert "hours = 1000000000.0: from 2000-01-01T00:00:00Z the log would end after 2262" in \
        capsys.readouterr().err
    assert main([*sim, "--hours", "0.01", "--start", "9999-01-01T00:00:00Z"]) == 2
    assert "after 2262" in capsys.readouterr().err
    assert main([*sim, "--hours", "0.01", "--start", "1960-01-01T00:00:00Z"]) == 2
    assert "start = '1960-01-01T00:00:00Z': must be after 1970" in capsys.readouterr().err
    assert not (tmp_path / "s.mcap").exists()


def test_files_of_the_wrong_kind_are_named(tmp_path, capsys):
    log = tiny_log(tmp_path / "a.mcap")  # binary, not UTF-8
    assert main(["import", str(log), "-o", str(tmp_path / "b.mcap")]) == 2
    assert f"{log}: not UTF-8 text (byte 0x89); expected a CSV file" in capsys.readouterr().err
    assert main(["check-config", str(log)]) == 2
    assert f"config error: {log}: not valid TOML (not UTF-8 text)" in capsys.readouterr().err
    assert main(["replay", str(log), "--config", str(log)]) == 2
    assert "not valid TOML" in capsys.readouterr().err
    assert main(["report", str(log), "-o", str(tmp_path / "r.html")]) == 2
    assert f"{log} is not a JSON report" in capsys.readouterr().err
    assert main(["alerts", "list", "--state", str(log)]) == 1
    assert f"{log}: neither a daemon checkpoint nor a JSON state file" in capsys.readouterr().err
    assert main(["replay", str(log), "--state", str(log)]) == 1
    assert "not valid JSON" in capsys.readouterr().err
    semi = tmp_path / "semi.csv"
    semi.write_text("time_s;tension_N\n0;100\n")
    assert main(["import", str(semi), "-o", str(tmp_path / "b.mcap")]) == 2
    assert "looks ';'-separated" in capsys.readouterr().err


def test_state_file_of_other_components_is_refused(tmp_path, capsys):
    # continuing with a config whose components differ dropped the saved damage silently
    log = tiny_log(tmp_path / "a.mcap", n=200)
    state = tmp_path / "state.json"
    assert main(["replay", str(log), "--state", str(state)]) == 0
    saved = state.read_text()
    text = (Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml").read_text()
    renamed = tmp_path / "renamed.toml"
    renamed.write_text(text.replace('name = "conductor"', 'name = "wire"', 1))
    capsys.readouterr()
    assert main(["replay", str(log), "--state", str(state), "--config", str(renamed)]) == 1
    assert "holds components ['conductor', 'conductor_termination'], the config ['conductor_termination', 'wire']" in capsys.readouterr().err
    assert state.read_text() == saved


def test_summary_names_an_unreadable_file(tmp_path, capsys):
    tiny_log(tmp_path / "good.mcap")
    (tmp_path / "junk.mcap").write_bytes(b"garbage\n")
    assert main(["replay", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert (f"damaged input: unreadable {tmp_path / 'junk.mcap'} (not an MCAP file" in out)
    assert "without footer" not in out and ": ;" not in out


@pytest.mark.parametrize("timeout", ["-1", "0", "nan", "inf"])
def test_alerts_timeout_must_be_positive(capsys, timeout):
    # -1 waited no time and blamed the daemon; nan said 'negative timeout'
    assert main(["alerts", "list", "--buoy", "nobuoy", "--timeout", timeout]) == 1
    assert f"--timeout {float(timeout)}: must be a number of seconds > 0" in \
        capsys.readouterr().err


def test_view_refuses_a_file_that_is_not_a_recording(tmp_path, capsys):
    # the viewer used to start, show nothing and end with 'exited with status 0'
    report = tmp_path / "r.json"
    report.write_text("{}")
    assert main(["view", str(report)]) == 2
    assert f"not a Rerun recording (.rrd): {report}" in capsys.readouterr().err


@pytest.mark.parametrize("old, new, message", [
    ("replay_horizon_s = 3600.0", "replay_horizon_s = 1e300",
     "ordering.replay_horizon_s = 1e+300: must be a finite number > 0 and <= 1e+09"),
    ("eval_interval_s = 10.0", "eval_interval_s = 1e12",
     "alerts.eval_interval_s = 1000000000000.0: must be a finite number > 0 and <= 1e+09"),
    ("on_delay_s = 60.0", "on_delay_s = 1e300", "alerts.rule[2].on_delay_s = 1e+300: must be a finite number >= 0 and <= 1e+09"),
    ("window_s = 600.0", "window_s = 1e300", "window_s = 1e+300: must be a finite number > 0 and <= 1e+09"),
])
def test_config_durations_have_a_ceiling(tmp_path, capsys, old, new, message):
    # durations become int64 nanoseconds: 1e300 s passed check-config and then the replay
    # died with an OverflowError
    text = (Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml").read_text()
    assert old in text
    cfg = tmp_path / "c.toml"
    cfg.write_text(text.replace(old, new, 1))
    assert main(["check-config", str(cfg)]) == 2
    assert message in capsys.readouterr().err
    log = tiny_log(tmp_path / "a.mcap")
    assert main(["replay", str(log), "--config", str(cfg)]) in (1, 2)  # [alerts]: 1
    assert message in capsys.readouterr().err


def test_bad_sn_table_names_the_component(tmp_path, capsys):
    text = (Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml").read_text()
    cfg = tmp_path / "c.toml"
    cfg.write_text(text.replace('sn_curve = "vaps_copper"', 'sn_curve = { stress_range_Pa = '
                                '[1e8, 2e8], cycles = [1e6, 1e7] }', 1))
    assert main(["check-config", str(cfg)]) == 2
    assert ("config error: component 'conductor': sn_curve table: tabulated cycles must "
            "increase") in capsys.readouterr().err


def test_fleet_report_dir_that_is_a_file_is_refused_before_the_replay(tmp_path, capsys):
    a, b = tiny_log(tmp_path / "a.mcap", buoy="a1"), tiny_log(tmp_path / "b.mcap", buoy="b1")
    taken = tmp_path / "taken.json"
    taken.write_text("{}")
    assert main(["replay", str(a), str(b), "--report-dir", str(taken)]) == 2
    assert f"--report-dir {taken}: is a file" in capsys.readouterr().err
    assert taken.read_text() == "{}"


def test_simulate_shorter_than_one_sample(tmp_path, capsys):
    # it divided by the zero samples it wrote
    assert main(["simulate", "-o", str(tmp_path / "s.mcap"), "--hours", "1e-9", "--hs", "1",
                 "--tp", "5", "--seed", "1"]) == 2
    assert "hours = 1e-09: shorter than one sample at 20 Hz" in capsys.readouterr().err


@pytest.mark.parametrize("speed", ["1e-300", "0", "-1", "nan"])
def test_pace_speed_has_a_floor(tmp_path, capsys, speed):
    # 1e-300 overflowed time.sleep with a traceback
    log = tiny_log(tmp_path / "a.mcap", n=100)
    assert main(["replay", str(log), "--speed", speed]) == 2
    assert f"--speed {float(speed)}: must be >= 1e-06" in capsys.readouterr().err
    assert main(["simulate", "-o", str(tmp_path / "s.mcap"), "--hours", "0.01", "--hs", "1",
                 "--tp", "5", "--seed", "1", "--publish", "--speed", speed]) == 2
    assert f"--speed {float(speed)}: must be >= 1e-06" in capsys.readouterr().err


@pytest.mark.parametrize("extra, message", [
    ('[[alerts.rule]]\nkind = "damage_rate"\nthreshold = 1.0\ncomponent = "mid"\n',
     "config error: alerts.rule[8].component = 'mid': unknown component"),
    ('[cable]\npreset = "vaps_biw"\nno_such_field = 1.0\n', "config error: cable"),
])
def test_replay_exits_2_for_config_errors_found_when_the_pipeline_is_built(tmp_path, capsys,
                                                                          extra, message):
    from importlib import resources

    text = (resources.files("monitor") / "vaps_seed004.toml").read_text()
    if extra.startswith("[cable]"):
        text = text.replace('[cable]\n', '[cable]\nno_such_field = 1.0\n', 1)
    else:
        text += "\n" + extra
    cfg = tmp_path / "c.toml"
    cfg.write_text(text)
    log = tiny_log(tmp_path / "a.mcap")
    capsys.readouterr()
    assert main(["replay", str(log), "--config", str(cfg)]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("args", [
    ["status", "--connect", "garbage"],
    ["alerts", "list", "--buoy", "vaps", "--connect", "garbage"],
    ["forecast", "--sea-states", "x.csv", "--publish", "garbage"],
])
def test_a_malformed_endpoint_is_a_usage_error(args, capsys):
    """Was a zenoh.ZError traceback (alerts, forecast) or "daemon NOT RUNNING" (status)."""
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2
    assert ("'garbage' is not a Zenoh endpoint: expected <proto>/<address>, e.g. "
            "tcp/127.0.0.1:7447") in capsys.readouterr().err


@pytest.mark.parametrize("content, message", [
    (None, "forecast.table = 't.json': [Errno 2] No such file or directory"),
    ("{}", "forecast.table = 't.json': no 'components': not a table written by buoymon "
           "forecast --save-table"),
    ("[1,", "forecast.table = 't.json': Expecting value"),
])
def test_check_config_reads_the_forecast_table_as_the_replay_does(tmp_path, capsys, content,
                                                                  message):
    """A [forecast] table the pipeline cannot read: check-config said "[forecast] ok"."""
    text = (Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml").read_text()
    old = '# table = "table.json"'
    assert old in text
    cfg = tmp_path / "c.toml"
    cfg.write_text(text.replace(old, 'table = "t.json"', 1))
    if content is not None:
        (tmp_path / "t.json").write_text(content)
    assert main(["check-config", str(cfg)]) == 2
    assert message in capsys.readouterr().err
    log = tiny_log(tmp_path / "a.mcap")
    assert main(["replay", str(log), "--config", str(cfg)]) == 2
    assert message in capsys.readouterr().err


def test_check_config_refuses_what_the_pipeline_refuses(tmp_path, capsys):
    """A [forecast] window that is not whole alert ticks: check-config said ok, the replay
    and the daemon then refused the file."""
    text = (Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml").read_text()
    old = "window_s = 1800.0 "
    assert text.count(old) == 1
    cfg = tmp_path / "c.toml"
    cfg.write_text(text.replace(old, "window_s = 15.0 ", 1))
    message = ("config error: forecast.window_s = 15: must be a whole number of alert ticks "
               "(alerts.eval_interval_s = 10)")
    assert main(["check-config", str(cfg)]) == 2
    assert message in capsys.readouterr().err
    assert main(["replay", str(tiny_log(tmp_path / "a.mcap")), "--config", str(cfg)]) == 2
    assert message in capsys.readouterr().err


def test_check_config_accepts_a_saved_forecast_table(tmp_path, capsys):
    from models.sea_state_table import HS_EDGES_M, TP_EDGES_S, DamageRateTable
    from monitor.config import default_config

    names = [c.name for c in default_config().components]
    (tmp_path / "t.json").write_text(json.dumps(
        DamageRateTable(names, HS_EDGES_M, TP_EDGES_S).to_state()))
    text = (Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml").read_text()
    cfg = tmp_path / "c.toml"
    cfg.write_text(text.replace('# table = "table.json"', 'table = "t.json"', 1))
    assert main(["check-config", str(cfg)]) == 0
    assert "[forecast] ok" in capsys.readouterr().out
    # a table of other components: refused as the pipeline refuses it
    (tmp_path / "t.json").write_text(json.dumps(
        DamageRateTable(["wire"], HS_EDGES_M, TP_EDGES_S).to_state()))
    assert main(["check-config", str(cfg)]) == 2
    assert ("config error: forecast.table: components ['wire'] != the configuration's "
            f"{names}") in capsys.readouterr().err


@pytest.mark.parametrize("rule, message", [
    ('kind = "damage_fraction"\nname = "x"\ncomponent = "conductr"\nthreshold = 0.2\n',
     "alerts.rule[8].component = 'conductr': unknown component (did you mean 'conductor'?); "
     "expected one of "
     "['conductor', 'conductor_termination']"),
    ('kind = "stale"\nname = "y"\ncomponent = "tensoin"\n',
     "alerts.rule[8].component = 'tensoin': unknown sensor stream"),
])
def test_check_config_refuses_a_rule_for_a_component_the_config_lacks(tmp_path, capsys, rule,
                                                                        message):
    """check-config said ok; the replay then refused the file."""
    text = (Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml").read_text()
    cfg = tmp_path / "c.toml"
    cfg.write_text(text + "\n[[alerts.rule]]\n" + rule)
    assert main(["check-config", str(cfg)]) == 2
    assert f"config error: {message}" in capsys.readouterr().err
    assert main(["replay", str(tiny_log(tmp_path / "a.mcap")), "--config", str(cfg)]) in (1, 2)
    assert message in capsys.readouterr().err
