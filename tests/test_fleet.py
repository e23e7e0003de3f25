"""Fleet replay: discovery, per-buoy state across files, serial = process pool = Dask to the last
bit, the fleet report's risk ranking, and the command line."""

import json
from pathlib import Path

import pytest

from monitor.cli import main
from monitor.config import config_with, default_config
from replay.fleet import (BuoyArchive, active_alerts, discover, fleet_report, make_jobs,
                          replay_buoy, run_fleet)
from replay.runner import replay_logs
from replay.simulate import SimConfig, simulate

MINUTES = 4  # per file
FILES = 3
# buoy id -> (Hs m, Tp s): ids deliberately not in risk order
SEAS = {"delta": (2.4, 7.0), "alpha": (0.6, 4.0), "echo": (1.2, 5.0), "bravo": (3.0, 7.5),
        "fox": (0.9, 4.5), "charlie": (1.8, 6.0)}
RISK_ORDER = sorted(SEAS, key=lambda b: -SEAS[b][0])  # roughest sea first
RULES = [{"kind": "conductor_stress", "threshold": 1.0},
         {"kind": "damage_fraction", "name": "damage_high", "threshold": 1.0}]


def fleet_config():
    c = default_config()
    # measured tension only: these logs always have it, and the damage then comes from the
    # load cell alone (the motion estimator is not what this test is about); the free span
    # only (the shipped termination's locked bend is above the endurance stress in any sea)
    return config_with(c, load={**c.section("load"), "source": "measured"},
                       alerts={**c.section("alerts"), "rule": RULES},
                       component=[c.raw["component"][0]])


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    """6 buoys x 3 consecutive 4-minute files; file names do not sort in time order."""
    root = tmp_path_factory.mktemp("fleet")
    for k, (buoy, (hs, tp)) in enumerate(SEAS.items()):
        for i in range(FILES):
            start = f"2020-03-01T00:{i * MINUTES:02d}:00Z"
            d = root / ("north" if k % 2 else "south") / buoy
            d.mkdir(parents=True, exist_ok=True)
            simulate(SimConfig(hours=MINUTES / 60, hs_m=hs, tp_s=tp, seed=100 * k + i,
                               buoy_id=buoy, start=start), d / f"{chr(ord('z') - i)}.mcap")
    return root


@pytest.fixture(scope="module")
def serial(archive):
    archives = discover([archive / "north", archive / "south"])
    return archives, run_fleet(archives, fleet_config())


def test_discover_groups_by_buoy_and_orders_files_in_time(archive, serial):
    archives, _ = serial
    assert [a.buoy_id for a in archives] == sorted(SEAS)
    for a in archives:
        assert [Path(f).name for f in a.files] == ["z.mcap", "y.mcap", "x.mcap"]  # time order
    # naming a file again (or its folder twice) does not replay it twice
    again = discover([archive, archive / "north", archives[0].files[0]])
    assert again == archives


def test_buoy_job_is_the_replay_command_path_with_state_across_files(archive, serial, tmp_path):
    archives, reports = serial
    a = archives[0]
    rep = reports[0]
    cfg = config_with(fleet_config(), buoy={**fleet_config().section("buoy"), "id": a.buoy_id})
    # one `buoymon replay FILE1 FILE2 FILE3` pass
    assert replay_logs(cfg, list(a.files)).report == rep
    # file by file with the state carried: the same committed damage, to the last bit
    state = tmp_path / "state.json"
    for f in a.files:
        part = replay_logs(cfg, [f], state_path=state).report
    for name, c in rep["components"].items():
        assert part["components"][name]["damage_committed"] == c["damage_committed"]
        assert c["damage_committed"] > 0
    assert rep["samples"]["tension"]["accepted"] == FILES * MINUTES * 60 * 20


@pytest.mark.integration  # a process pool
def test_process_pool_equals_serial_to_the_last_bit(serial):
    archives, reports = serial
    pooled = run_fleet(archives, fleet_config(), workers=2)
    assert pooled == reports
    assert json.dumps(pooled) == json.dumps(reports)


@pytest.mark.integration  # a dask cluster
def test_dask_local_cluster_equals_serial_to_the_last_bit(serial):
    distributed = pytest.importorskip("dask.distributed")
    archives, reports = serial
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None,
                                  worker_dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        got = run_fleet(archives, fleet_config(), cluster=cluster.scheduler_address)
    assert got == reports
    assert json.dumps(got) == json.dumps(reports)


def test_fleet_report_ranks_by_risk(serial):
    _, reports = serial
    fleet = fleet_report(reports)
    ranked = [b["buoy_id"] for b in fleet["buoys"]]
    assert ranked == RISK_ORDER
    assert [b["rank"] for b in fleet["buoys"]] == list(range(1, len(SEAS) + 1))
    lives = [b["min_remaining_life_days"] for b in fleet["buoys"]]
    damages = [b["max_damage"] for b in fleet["buoys"]]
    assert lives == sorted(lives) and damages == sorted(damages, reverse=True)
    assert damages[0] > 10 * damages[-1]  # clearly different sea states
    by_id = {r["buoy_id"]: r for r in reports}
    for b in fleet["buoys"]:
        c = b["components"]["conductor"]
        src = by_id[b["buoy_id"]]["components"]["conductor"]
        assert c["damage"] == src["damage"] and c["remaining_life_days"] == src["remaining_life_days"]
        # active alerts = the last transition of each alert is "firing"
        assert b["active_alerts"] == len(active_alerts(by_id[b["buoy_id"]]["alerts"]))
        assert c["active_alerts"] == [f"{a['rule']}:{a['severity']}" for a in b["alerts"]]
    # the roughest sea exceeds the endurance stress, the calmest does not
    assert fleet["buoys"][0]["active_alerts"] >= 1
    assert fleet["buoys"][-1]["active_alerts"] == 0


def test_active_alerts_takes_the_last_transition():
    def rec(fp, state):
        return {"fingerprint": fp, "state": state}
    alerts = [rec("a", "firing"), rec("b", "firing"), rec("a", "resolved"), rec("c", "firing")]
    assert [r["fingerprint"] for r in active_alerts(alerts)] == ["b", "c"]


def test_no_buoy_without_a_rate_outranks_one_with_a_rate():
    def rep(buoy, damage, life):
        return {"buoy_id": buoy, "time_start": None, "time_end": None, "alerts": [],
                "inputs": {"files": []},
                "components": {"c": {"damage": damage, "damage_committed": damage,
                                     "damage_rate_per_day": None if life is None else 1.0,
                                     "remaining_life_days": life, "max_stress_Pa": 1.0}}}
    fleet = fleet_report([rep("quiet", 0.0, None), rep("old", 0.9, 5000.0), rep("young", 0.1, 100.0)])
    assert [b["buoy_id"] for b in fleet["buoys"]] == ["young", "old", "quiet"]


def test_summary_shows_alerts_on_streams_and_the_line():
    """A buoy whose only active alert is on its tension stream (rejected_rate): the table
    said "-" for every row while fleet.json counted the alert."""
    from replay.fleet import fleet_summary_text  # noqa: PLC0415

    def alert(rule, component):
        return {"fingerprint": rule + component, "state": "firing", "rule": rule,
                "severity": "warning", "labels": {"component": component}, "starts_at_ns": 0}
    rep = {"buoy_id": "b1", "time_start": None, "time_end": None, "inputs": {"files": []},
           "alerts": [alert("rejected_rate", "tension"), alert("conductor_stress", "c")],
           "components": {"c": {"damage": 0.1, "damage_committed": 0.1,
                                "damage_rate_per_day": 0.01, "remaining_life_days": 90.0,
                                "max_stress_Pa": 1.0}}}
    lines = fleet_summary_text(fleet_report([rep])).splitlines()
    assert lines[2].endswith("  conductor_stress:warning")
    assert lines[3].split() == ["also", "active:", "rejected_rate:warning", "(tension)"]
    assert len(lines) == 4


def test_a_file_shared_by_two_buoys_is_replayed_for_each(tmp_path):
    import numpy as np

    from monitor.blocks import SampleBlock
    from replay.writer import LogWriter

    t0 = 1_600_000_000 * 10**9
    with LogWriter(tmp_path / "shore.mcap") as w:
        for s in range(60):
            t = t0 + s * 10**9 + np.arange(20, dtype=np.int64) * 50_000_000
            for buoy, amp in (("b1", 1000.0), ("b2", 3000.0)):
                v = 5000.0 + amp * np.sin(2 * np.pi * (t - t0) / 5.25e9)
                w.write_block(SampleBlock(buoy, "tension", t, {"tension_N": v}))
    archives = discover([tmp_path])
    assert archives == [BuoyArchive("b1", (str(tmp_path / "shore.mcap"),)),
                        BuoyArchive("b2", (str(tmp_path / "shore.mcap"),))]
    r1, r2 = (replay_buoy(j) for j in make_jobs(archives, fleet_config()))
    assert (r1["buoy_id"], r2["buoy_id"]) == ("b1", "b2")
    assert r1["samples"]["tension"]["accepted"] == r2["samples"]["tension"]["accepted"] == 1200
    assert r1["tension_N"]["max"] < 6100 < r2["tension_N"]["max"]
    assert sum(r1["inputs"]["ignored_blocks_of_other_buoys"].values()) > 0


def write_fleet_config(path):
    """The shipped example with measured load (its own alert rules: the damage figures and the
    ranking do not depend on them)."""
    from importlib import resources

    text = resources.files("monitor").joinpath("vaps_seed004.toml").read_text()
    assert 'source = "auto"' in text
    text = text.replace('source = "auto"', 'source = "measured"')
    path.write_text(text)
    return path


def test_cli_fleet_mode_writes_per_buoy_and_fleet_reports(archive, serial, tmp_path, capsys):
    _, reports = serial
    out = tmp_path / "reports"
    code = main(["replay", str(archive), "--config", str(write_fleet_config(tmp_path / "f.toml")),
                 "--report-dir", str(out), "--no-progress"])
    assert code == 0
    text = capsys.readouterr().out
    assert "fleet: 6 buoy(s)" in text
    assert text.index(RISK_ORDER[0]) < text.index(RISK_ORDER[-1])
    fleet = json.loads((out / "fleet.json").read_text())
    assert [b["buoy_id"] for b in fleet["buoys"]] == RISK_ORDER
    for rep in reports:
        saved = json.loads((out / "buoys" / f"{rep['buoy_id']}.json").read_text())
        # the shipped file also monitors the termination, which fleet_config() leaves out
        assert {n: saved["components"][n] for n in rep["components"]} == rep["components"]
        assert "conductor_termination" in saved["components"]


def test_cli_rejects_single_buoy_options_in_fleet_mode(archive, capsys):
    assert main(["replay", str(archive), "--workers", "2", "--speed", "10"]) == 2
    assert "--speed applies to one buoy" in capsys.readouterr().err
    assert main(["replay", str(archive), "--workers", "0"]) == 2
    assert "--workers 0: must be >= 1" in capsys.readouterr().err


def test_cli_reads_a_file_without_summary_once_to_find_its_buoys(tmp_path, monkeypatch, capsys):
    """Two buoys, one file cut short (no summary: read whole for its buoys): the check for
    fleet mode and the fleet run share one discovery."""
    import numpy as np

    import replay.fleet as fleet
    from monitor.blocks import SampleBlock
    from replay.writer import LogWriter

    t0 = 1_600_000_000 * 10**9
    for buoy in ("b1", "b2"):
        with LogWriter(tmp_path / f"{buoy}.mcap") as w:
            for s in range(60):
                t = t0 + s * 10**9 + np.arange(20, dtype=np.int64) * 50_000_000
                w.write_block(SampleBlock(buoy, "tension", t, {"tension_N": 5000.0 + 0 * t}))
    cut = tmp_path / "b2.mcap"
    cut.write_bytes(cut.read_bytes()[:-200])  # the footer and summary gone
    scanned = []
    whole = fleet._scan_buoys_and_start
    monkeypatch.setattr(fleet, "_scan_buoys_and_start", lambda p: scanned.append(p) or whole(p))
    assert main(["replay", str(tmp_path), "--no-progress"]) == 0
    assert "fleet: 2 buoy(s)" in capsys.readouterr().out
    assert [Path(p).name for p in scanned] == ["b2.mcap"]


def test_pool_workers_read_ahead_only_when_a_core_is_left_for_the_thread(serial):
    """replay.fleet.pool_jobs: W workers on C usable CPUs read ahead only if C > W; a job
    that already says keeps its choice."""
    from dataclasses import replace

    from replay.fleet import pool_jobs

    archives, _ = serial
    jobs = make_jobs(archives, fleet_config())
    assert {j.read_ahead for j in jobs} == {None}  # serial: the reader's own rule
    assert {j.read_ahead for j in pool_jobs(jobs, 2, cpus=2)} == {False}
    assert {j.read_ahead for j in pool_jobs(jobs, 6, cpus=4)} == {False}
    assert {j.read_ahead for j in pool_jobs(jobs, 2, cpus=4)} == {True}
    fixed = [replace(jobs[0], read_ahead=True)] + jobs[1:]
    assert [j.read_ahead for j in pool_jobs(fixed, 2, cpus=2)] == [True] + [False] * 5
    assert [(j.buoy_id, j.files) for j in pool_jobs(jobs, 2, cpus=2)] == [
        (j.buoy_id, j.files) for j in jobs]
