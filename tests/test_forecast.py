"""Damage per sea state: the rate table, projections, sea-state files, `buoymon forecast`
and `buoymon design`, and a hindcast on the measured NDBC 44007 sea-state sequence."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from models.sea_state_table import DamageRateTable, project_damage
from monitor.config import default_config
from replay.sea_state_files import read_sea_states

REPO = Path(__file__).resolve().parents[1]
SHARED = next(  # ../shared beside the repository root, or beside a worktree's parents
    (p / "shared" for p in REPO.parents if (p / "shared/realdata").is_dir()), REPO.parent / "shared")
NDBC = SHARED / "realdata" / "ndbc44007_ecbenchmarkA" / "ec-benchmark_dataset_A.txt"


def _table() -> DamageRateTable:
    return DamageRateTable(["a", "b"], [0.0, 1.0, 2.0], [2.0, 6.0, 10.0])


def test_learned_bins_give_their_mean_and_standard_error():
    t = _table()
    for d in (0.1, 0.3):  # two one-hour windows in the (1-2 m, 2-6 s) bin
        t.learn(1.5, 5.0, 1.0, [d, 2 * d])
    r = t.rates([1.5], [5.0])
    assert r.source.tolist() == [["learned"], ["learned"]]
    assert r.rate[:, 0].tolist() == pytest.approx([0.2, 0.4])
    se = np.std([0.1, 0.3], ddof=1) / math.sqrt(2)  # 0.1
    assert r.low[0, 0] == pytest.approx(max(0.2 - 1.96 * se, 0.0))
    assert r.high[0, 0] == pytest.approx(0.2 + 1.96 * se)
    assert r.hours_in_bin.tolist() == [2.0]


def test_a_learned_window_goes_to_the_bin_of_its_sea_state():
    """learn's own scalar bins are bin_of's: on the edges, between, beyond both ends; and a
    bad damage is refused before anything is learned."""
    for hs in (0.0, 0.5, 1.0, 1.0 - 1e-16, 1.5, 2.0, 7.0):
        for tp in (0.5, 2.0, 5.999999, 6.0, 10.0, 30.0):
            t = _table()
            t.learn(hs, tp, 0.5, [1e-3, 0.0])
            i, j = t.bin_of(hs, tp)
            assert np.argwhere(t.windows).tolist() == [[int(i), int(j)]], (hs, tp)
            assert t.damage[:, i, j].tolist() == [1e-3, 0.0]
    t = _table()
    for bad in ([1.0, math.nan], [1.0, -1e-30], [1.0], [math.inf, 0.0]):
        with pytest.raises(ValueError, match="damage"):
            t.learn(1.5, 5.0, 1.0, bad)
    assert t.windows.sum() == 0


def test_model_fills_empty_bins_with_its_band_and_unrated_bins_say_so():
    t = _table()
    rates = np.full((2, 2, 2), np.nan)
    rates[:, 0, 1] = [1e-3, 2e-3]
    t.set_model_rate(rates)
    r = t.rates([0.5, 0.5], [8.0, 3.0])
    assert r.source[0].tolist() == ["model", "none"]
    assert r.rate[1, 0] == 2e-3 and r.low[1, 0] == 1e-3 and r.high[1, 0] == 4e-3
    assert math.isnan(r.rate[0, 1])


def test_table_state_round_trips_exactly():
    t = _table()
    t.learn(0.3, 3.0, 0.5, [1e-5, 0.0])
    rates = np.full((2, 2, 2), np.nan)
    rates[0, 1, 1] = 7e-4
    t.set_model_rate(rates)
    u = DamageRateTable.from_state(json.loads(json.dumps(t.to_state())))
    for name in ("hours", "windows", "damage", "rate_sq"):
        assert np.array_equal(getattr(u, name), getattr(t, name))
    assert np.array_equal(u.model_rate, t.model_rate, equal_nan=True)


def test_projection_crosses_thresholds_where_a_hand_calculation_does():
    t = _table()
    t.set_model_rate(np.full((2, 2, 2), 0.05))  # 0.05 per hour everywhere
    rates = t.rates([1.5] * 4, [5.0] * 4)
    starts = np.arange(4) * 3600.0 * 3  # four 3-hour steps
    p = project_damage(starts, np.full(4, 3.0), rates, [0.2, 0.0], thresholds=[0.5])
    assert p.damage[:, -1].tolist() == pytest.approx([0.8, 0.6])
    # a: 0.2 + 0.05 h = 0.5 after 6 h; b: 0.05 h = 0.5 after 10 h; the high band (x2) halves it
    assert p.crossings[0][0.5] == (pytest.approx(6 * 3600.0), pytest.approx(3 * 3600.0))
    assert p.crossings[1][0.5] == (pytest.approx(10 * 3600.0), pytest.approx(5 * 3600.0))


def test_sea_state_files_in_three_formats(tmp_path):
    csv = tmp_path / "f.csv"
    csv.write_text("time,hs_m,tp_s,direction_deg\n2026-01-01T00:00:00Z,1.0,5,270\n"
                   "2026-01-01T01:00:00Z,nan,5,\n2026-01-01T00:00:00Z,1,5,\n"
                   "2026-01-01T03:00:00Z,2.0,7,\n")
    s = read_sea_states(csv)
    assert s.hs_m.tolist() == [1.0, 2.0] and s.direction_deg[0] == 270
    assert s.skipped == {"missing or impossible Hs/Tp": 1, "time not increasing": 1}
    ndbc = tmp_path / "n.txt"
    ndbc.write_text("#YY  MM DD hh mm WDIR WSPD GST  WVHT   DPD   APD MWD\n"
                    "#yr  mo dy hr mn degT m/s  m/s     m   sec   sec degT\n"
                    "2024 01 01 00 50 200  5.0  6.0  1.20  8.00  5.5 190\n"
                    "2024 01 01 01 50 200  5.0  6.0 99.00 99.00 99.0 999\n"
                    "2024 01 01 02 50 200  5.0  6.0  1.50  9.00  5.9 195\n")
    s = read_sea_states(ndbc)
    assert s.hs_m.tolist() == [1.2, 1.5] and s.tp_s.tolist() == [8.0, 9.0]
    assert s.step_hours().tolist() == [2.0, 2.0]
    bad = tmp_path / "b.txt"
    bad.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="not a sea-state file"):
        read_sea_states(bad)


@pytest.mark.skipif(not NDBC.exists(), reason="shared/realdata not beside the project")
def test_benchmark_format_reads_the_measured_decade():
    s = read_sea_states(NDBC)
    assert len(s) == 82_805 and not s.skipped
    assert s.hs_m.max() == pytest.approx(7.0994)
    assert s.tp_s[0] == pytest.approx(4.7252 / 0.7782)


def _buoymon(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "monitor.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


@pytest.mark.integration  # the CLI end to end
def test_forecast_command_of_the_seed_storm(tmp_path):
    """Ten hours of the seed 004 storm as a forecast: the projection reaches the demo's
    figure (about 0.6 in 10 h, docs/README) and dates the 0.1 and 0.5 alert thresholds."""
    fc = tmp_path / "storm.csv"
    rows = [f"2026-11-25T{h:02d}:00:00Z,1.5,5.25" for h in range(10)]
    fc.write_text("time,hs_m,tp_s\n" + "\n".join(rows) + "\n")
    out = tmp_path / "f.json"
    p = _buoymon("forecast", "--sea-states", str(fc), "--json", str(out),
                 "--save-table", str(tmp_path / "t.json"), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    c = json.loads(out.read_text())["components"]["conductor"]
    assert 0.4 < c["damage_end"] < 0.9
    assert c["damage_end_low"] == pytest.approx(c["damage_end"] / 2)
    assert c["thresholds"]["0.1"]["at"].startswith("2026-11-25T0")
    assert c["steps_model"] == 10 and c["steps_learned"] == 0
    assert "reaches 0.5" in p.stdout or "stays below 0.5" in p.stdout
    # the saved table answers again without re-running the model, with the same figures
    p2 = _buoymon("forecast", "--sea-states", str(fc), "--table", str(tmp_path / "t.json"),
                  "--json", str(tmp_path / "g.json"), cwd=tmp_path)
    assert p2.returncode == 0, p2.stderr
    assert json.loads((tmp_path / "g.json").read_text())["components"]["conductor"] == c


@pytest.mark.integration  # the CLI end to end
def test_forecast_prints_rate_and_remaining_life_of_a_hand_calculation(tmp_path):
    """docs/FORECAST.md promises the damage rate and the remaining life at the end, printed
    and in the JSON. A table rating every bin 0.02 / h (conductor) and 0.01 / h (termination),
    ten hourly steps, the conductor at 0.3 already: by hand the conductor ends at
    0.3 + 10 x 0.02 = 0.5 at 0.2 / (10/24) = 0.48 per day, so (1 - 0.5) / 0.48 = 1.0417 days
    remain; the termination ends at 0.1 at 0.24 per day, 0.9 / 0.24 = 3.75 days."""
    names = [c.name for c in default_config().components]
    assert names == ["conductor", "conductor_termination"]
    from models.sea_state_table import HS_EDGES_M, TP_EDGES_S  # noqa: PLC0415
    table = DamageRateTable(names, HS_EDGES_M, TP_EDGES_S)
    rate = np.ones_like(table.model_rate)
    rate[0] *= 0.02
    rate[1] *= 0.01
    table.set_model_rate(rate)
    (tmp_path / "t.json").write_text(json.dumps(table.to_state()))
    (tmp_path / "r.json").write_text(json.dumps(
        {"components": {"conductor": {"damage": 0.3}, "conductor_termination": {"damage": 0.0}}}))
    fc = tmp_path / "f.csv"
    fc.write_text("time_s,hs_m,tp_s\n" + "".join(f"{3600 * h},2.0,8.0\n" for h in range(10)))
    p = _buoymon("forecast", "--sea-states", str(fc), "--table", str(tmp_path / "t.json"),
                 "--report", str(tmp_path / "r.json"), "--json", str(tmp_path / "o.json"),
                 cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    comps = json.loads((tmp_path / "o.json").read_text())["components"]
    for name, end, per_day, life in (("conductor", 0.5, 0.48, 0.5 / 0.48),
                                     ("conductor_termination", 0.1, 0.24, 3.75)):
        c = comps[name]
        assert c["damage_end"] == pytest.approx(end, rel=1e-12)
        assert c["damage_rate_per_day"] == pytest.approx(per_day, rel=1e-12)
        assert c["remaining_life_days_at_end"] == pytest.approx(life, rel=1e-12)
    lines = p.stdout.splitlines()
    cond = lines.index(next(ln for ln in lines if ln.startswith("  conductor:")))
    assert lines[cond + 1] == ("    damage rate 0.48 per day (the forecast's mean); remaining "
                               "life at the end 1.04 days at that rate (25 h)")
    term = lines.index(next(ln for ln in lines if ln.startswith("  conductor_termination:")))
    assert lines[term + 1] == ("    damage rate 0.24 per day (the forecast's mean); remaining "
                               "life at the end 3.75 days at that rate")
    # calm seas: nothing accrues, the life is unlimited, and the JSON stays strict (null)
    table.set_model_rate(np.zeros_like(table.model_rate))
    (tmp_path / "t.json").write_text(json.dumps(table.to_state()))
    p = _buoymon("forecast", "--sea-states", str(fc), "--table", str(tmp_path / "t.json"),
                 "--json", str(tmp_path / "o.json"), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "remaining life at the end unlimited (no damage accrues)" in p.stdout
    text = (tmp_path / "o.json").read_text()
    assert "Infinity" not in text
    assert json.loads(text)["components"]["conductor"]["remaining_life_days_at_end"] is None


def _flat_table(path: Path, rate_per_hour: float) -> Path:
    """A table rating every bin of the shipped components ``rate_per_hour``."""
    from models.sea_state_table import HS_EDGES_M, TP_EDGES_S  # noqa: PLC0415
    table = DamageRateTable([c.name for c in default_config().components], HS_EDGES_M, TP_EDGES_S)
    table.set_model_rate(np.full_like(table.model_rate, rate_per_hour))
    path.write_text(json.dumps(table.to_state()))
    return path


def test_forecast_names_wrong_files_and_counts_skipped_and_impossible_rows(tmp_path, capsys):
    """A report given as --table, a CSV as --report, a report with a NaN damage: each named
    with the file and what it should be (was a bare KeyError: "buoymon forecast: 'hs_edges_m'").
    Rows skipped and sea states that cannot exist are said in the output's first line."""
    from monitor.cli import main  # noqa: PLC0415
    fc = tmp_path / "f.csv"
    fc.write_text("time,hs_m,tp_s\n2026-11-25T00:00:00Z,nan,5\n2026-11-25T01:00:00Z,1.5,5.25\n"
                  "2026-11-25T00:30:00Z,1.5,5.25\n2026-11-25T02:00:00Z,9,5.25\n")
    report = tmp_path / "r.json"
    report.write_text(json.dumps({"report_version": 1, "components": {}}))
    table = _flat_table(tmp_path / "t.json", 0.01)
    for args, message in (
            (["--table", str(report)], f"{report}: not a damage-rate table (buoymon forecast "
                                       "--save-table): no 'hs_edges_m'"),
            (["--table", str(fc)], f"{fc}: not JSON, expected a damage-rate table"),
            (["--table", str(table), "--report", str(fc)], f"{fc}: not JSON, expected a replay "
                                                           "report"),
            (["--table", str(table), "--report", str(table)], f"{table}: not a replay report "
                                                              "(buoymon replay --report)"),
            (["--table", str(table), "--report", str(report)], f"{report}: no component "
                                                               "'conductor' in the report")):
        assert main(["forecast", "--sea-states", str(fc), *args]) == 2
        assert message in capsys.readouterr().err
    report.write_text(json.dumps({"components": {"conductor": {"damage": "nan"},
                                                 "conductor_termination": {"damage": 0.0}}}))
    assert main(["forecast", "--sea-states", str(fc), "--table", str(table),
                 "--report", str(report)]) == 2
    assert "component 'conductor': damage = 'nan': must be a finite number >= 0" in \
        capsys.readouterr().err
    # Hs 9 m at 5.25 s breaks above 6.1 m in 23 m (tests/test_waves.py): not a possible sea
    assert main(["forecast", "--sea-states", str(fc), "--table", str(table)]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first == ("forecast 2026-11-25T01:00:00Z to 2026-11-25T03:00:00Z (2 steps, 1 not a "
                     "possible sea (Hs above the breaking height of its Tp); rows skipped: 1 "
                     "missing or impossible Hs/Tp; 1 time not increasing)")


@pytest.mark.integration  # the CLI end to end
def test_forecast_refuses_bad_input(tmp_path):
    bad = tmp_path / "x.csv"
    bad.write_text("time,hs_m,tp_s\n2026-01-01T00:00:00Z,-1,5\n")
    p = _buoymon("forecast", "--sea-states", str(bad), cwd=tmp_path)
    assert p.returncode == 2 and "no usable sea state" in p.stderr
    binary = tmp_path / "x.bin"  # was "buoymon forecast: 'utf-8' codec can't decode ..."
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\xe5\xff" * 8)
    for cmd in (("forecast", "--sea-states"), ("design", "--scatter")):
        p = _buoymon(*cmd, str(binary), cwd=tmp_path)
        assert p.returncode == 2 and f"buoymon {cmd[0]}: {binary}: not a text file" in p.stderr


@pytest.mark.integration  # the CLI end to end
@pytest.mark.skipif(not NDBC.exists(), reason="shared/realdata not beside the project")
def test_design_command_on_a_measured_month(tmp_path):
    month = tmp_path / "jan1996.txt"
    month.write_text("".join(NDBC.read_text().splitlines(keepends=True)[:745]))
    out = tmp_path / "d.json"
    p = _buoymon("design", "--scatter", str(month), "--json", str(out), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    d = json.loads(out.read_text())
    assert d["records"] == 744 and d["hours"] == 744.0
    c = d["components"]["conductor"]
    assert c["annual_damage"] > 0 and c["design_life_years"] == pytest.approx(1 / c["annual_damage"])
    assert 0 < c["worst_bin"]["share"] <= 1


def test_design_says_which_rows_it_skipped_and_which_cannot_be_a_sea(tmp_path, capsys):
    """Two corrupt rows after the record: a bad date is skipped, Hs 9 m at Tz 4.09 s (Tp 5.25
    s; breaks above 6.1 m in 23 m, tests/test_waves.py) cannot be a sea. Both were silent:
    the impossible row alone gave 100 % of the damage and a design life of 0.0 h."""
    from monitor.cli import main  # noqa: PLC0415
    scatter = tmp_path / "s.txt"
    scatter.write_text("time (YYYY-MM-DD-HH); significant wave height (m); zero-up-crossing "
                       "period (s)\n1996-01-01-00; 1.5; 4.0855\n1996-01-01-01; 9; 4.0855\n"
                       "1996-13-01-02; 1.5; 4.0855\n")
    out = tmp_path / "d.json"
    assert main(["design", "--scatter", str(scatter), "--duration", "60",
                 "--json", str(out)]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first == ("2 sea states (0.0 years) in 2 Hs/Tp bins, wavfor load model; 1 not a "
                     "possible sea (Hs above the breaking height of its Tp); rows skipped: "
                     "1 bad time")
    d = json.loads(out.read_text())
    assert (d["records"], d["records_breaking"], d["skipped"]) == (2, 1, {"bad time": 1})


@pytest.mark.skipif(not NDBC.exists(), reason="shared/realdata not beside the project")
def test_hindcast_forecast_of_the_second_half_within_20_percent():
    """Train the table on 15 days of hourly measured sea states (each hour's damage from the
    simulator's load model through the configured component), forecast the next 15 days
    from their sea states alone (learned bins, model-filled elsewhere), and compare with
    what those 15 days then cost."""
    from models.sea_state_table import HS_EDGES_M, TP_EDGES_S
    from replay.cmd_forecast import fill_model_rates
    from replay.sea_state_damage import physics_damage

    s = read_sea_states(NDBC)
    n = 720  # January 1996, hourly
    hs, tp = s.hs_m[:n], s.tp_s[:n]
    config = default_config()
    measured = physics_damage(config, hs, tp, duration_s=300.0, seed=1000).rainflow_per_hour[0]
    half = n // 2
    table = DamageRateTable(["conductor"], HS_EDGES_M, TP_EDGES_S)
    for k in range(half):
        table.learn(float(hs[k]), float(tp[k]), 1.0, [measured[k]])
    from replay.sea_state_files import SeaStates
    second = SeaStates(s.t_s[half:n], hs[half:], tp[half:], s.direction_deg[half:n])
    fill_model_rates(table, config, second, "wavfor")
    rates = table.rates(second.hs_m, second.tp_s)
    proj = project_damage(second.t_s, np.ones(half), rates, [0.0])
    actual = float(measured[half:].sum())
    assert actual > 0
    assert proj.damage[0, -1] == pytest.approx(actual, rel=0.20)
    assert (rates.source[0] == "learned").sum() > half // 2


def test_the_documented_forecast_payload_lies_ahead_of_its_issue_time():
    """docs/FORECAST.md's payload example: its steps start at its issue time (the example was
    issued 2026-11-25 with steps of 2025-11-25, so a daemon applying it projected 0 steps)."""
    from monitor.forecast import parse_forecast  # noqa: PLC0415
    doc = (REPO / "docs" / "FORECAST.md").read_text()
    example = doc.split("Payload (JSON):\n\n```json\n", 1)[1].split("```", 1)[0]
    fc = parse_forecast(json.loads(example))
    assert fc.issued_s == fc.t_s[0] == 1795608000.0  # 2026-11-25T12:00:00Z
    assert list(fc.hs_m) == [1.2, 1.5, 2.1]
