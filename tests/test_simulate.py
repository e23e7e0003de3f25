"""Simulator: determinism, sensor rates, sea state, continuity across hours, faults, CLI."""

from __future__ import annotations

import hashlib
import math
import subprocess
import sys

import numpy as np
import pytest

from monitor.cli import main
from replay.csv_import import parse_iso_ns
from replay.reader import LogReader
from replay.simulate import EARTH_RADIUS_M, SimConfig, simulate

S = 10**9
START = parse_iso_ns("2000-01-01T00:00:00Z")


def _series(path):
    """topic sensor -> (t_ns, values (n_fields, n)) concatenated over the whole log."""
    out: dict[str, list] = {}
    for b in LogReader(path):
        out.setdefault(b.sensor, []).append((b.t_ns, np.vstack(list(b.fields.values()))))
    return {k: (np.concatenate([t for t, _ in v]), np.concatenate([x for _, x in v], axis=1))
            for k, v in out.items()}


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """1.25 h of a 1.5 m / 5.25 s sea (crosses an hour boundary), no faults."""
    path = tmp_path_factory.mktemp("sim") / "clean.mcap"
    cfg = SimConfig(hours=1.25, hs_m=1.5, tp_s=5.25, seed=7)
    summary = simulate(cfg, path)
    return cfg, path, summary, _series(path)


def test_rates_times_and_counts(clean):
    cfg, path, summary, s = clean
    n = int(1.25 * 3600)
    assert {k: v[0].shape[0] for k, v in s.items()} == {
        "tension": 20 * n, "imu": 10 * n, "motion": 10 * n, "gnss": n, "waves": 2}
    for sensor, hz in (("tension", 20), ("imu", 10), ("motion", 10), ("gnss", 1)):
        t = s[sensor][0]
        assert t[0] == START and np.all(np.diff(t) == S // hz)
    assert s["waves"][0].tolist() == [START + 1800 * S - S // 20, START + 3600 * S - S // 20]
    assert summary.samples == {k: v[0].shape[0] for k, v in s.items()}
    st = LogReader(path)
    list(st)
    assert st.stats[0].messages == summary.messages == 4 * n + 2


def test_sea_state_matches_the_request(clean):
    cfg, _, _, s = clean
    heave = s["motion"][1][0]
    hs = 4 * np.std(heave)  # Hs = 4 sqrt(m0); the 2 cm sensor noise is negligible
    assert hs == pytest.approx(cfg.hs_m, rel=0.1)
    f = np.fft.rfftfreq(heave.size, 0.1)
    spec = np.abs(np.fft.rfft(heave - heave.mean())) ** 2
    smooth = np.convolve(spec, np.ones(101) / 101, mode="same")
    assert 1 / f[np.argmax(smooth)] == pytest.approx(cfg.tp_s, rel=0.1)
    hs_reported, tp_reported = s["waves"][1]
    assert np.allclose(hs_reported, cfg.hs_m, rtol=0.15)
    assert np.allclose(tp_reported, cfg.tp_s, rtol=0.15)


def test_motion_and_tension_are_continuous_across_the_hour_join(clean):
    _, _, _, s = clean
    heave = s["motion"][1][0]
    tension = s["tension"][1][0]
    for x, i in ((heave, 36000), (tension, 72000)):
        steps = np.abs(np.diff(x))
        assert steps[i - 5:i + 5].max() < 6 * np.percentile(steps, 99)


def test_tension_follows_the_motion(clean):
    """Line tension is driven by the buoy's motion: strongly correlated with heave/surge."""
    _, _, summary, s = clean
    tension = s["tension"][1][0][::2]  # 10 Hz, aligned with motion
    heave, surge = s["motion"][1][0], s["motion"][1][1]
    design = np.vstack([heave, surge, np.ones_like(heave)]).T
    coef, *_ = np.linalg.lstsq(design, tension, rcond=None)
    resid = tension - design @ coef
    assert np.var(resid) < 0.7 * np.var(tension)
    lo, mean, hi = summary.tension_N
    assert 0 <= lo < mean < hi and np.mean(tension) == pytest.approx(mean, rel=0.02)


def test_gnss_sits_at_the_anchor_plus_the_mean_offset(clean):
    cfg, _, _, s = clean
    lat, lon = s["gnss"][1]
    north = np.radians(lat - cfg.anchor_lat_deg) * EARTH_RADIUS_M
    east_radius = EARTH_RADIUS_M * math.cos(math.radians(cfg.anchor_lat_deg))
    east = np.radians(lon - cfg.anchor_lon_deg) * east_radius
    assert np.mean(east) == pytest.approx(0.0, abs=0.2)  # bearing 0: the buoy is due north
    assert 5.0 < np.mean(north) < 40.0 and np.std(north) < 3.0


def test_deterministic_and_faults_leave_the_rest_untouched(clean, tmp_path):
    cfg, path, _, s = clean
    again = tmp_path / "again.mcap"
    simulate(cfg, again)
    assert hashlib.sha256(again.read_bytes()).digest() == hashlib.sha256(path.read_bytes()).digest()
    faulty = tmp_path / "faulty.mcap"
    fcfg = SimConfig(hours=1.25, hs_m=1.5, tp_s=5.25, seed=7,
                     dropouts=0.05, spikes=0.002, nans=0.01)
    simulate(fcfg, faulty)
    f = _series(faulty)
    t_clean, v_clean = s["tension"]
    t, v = f["tension"]
    blocks = np.unique(t_clean // S).size
    lost = blocks - np.unique(t // S).size
    assert abs(lost - 0.05 * blocks) < 4 * math.sqrt(0.05 * 0.95 * blocks)
    assert set(t.tolist()) <= set(t_clean.tolist())
    clean_here = v_clean[0][np.searchsorted(t_clean, t)]
    nan = np.isnan(v[0])
    assert abs(nan.mean() - 0.01) < 0.003
    spike = ~nan & (v[0] != clean_here)
    assert abs(spike.mean() - 0.002) < 0.001
    jump = np.abs(v[0][spike] - clean_here[spike])
    assert jump.min() > 4 * np.std(v_clean[0])  # spikes are 5-10 standard deviations
    # a different seed gives a different sea
    other = tmp_path / "other.mcap"
    simulate(SimConfig(hours=0.05, hs_m=1.5, tp_s=5.25, seed=8), other)
    assert not np.array_equal(_series(other)["tension"][1][0], v_clean[0][: 20 * 180])


def test_cli(tmp_path, capsys):
    out = tmp_path / "cli.mcap"
    assert main(["simulate", "-o", str(out), "--hours", "0.02", "--hs", "1", "--tp", "6",
                 "--seed", "3", "--buoy-id", "b9", "--start", "2024-05-01T00:00:00Z"]) == 0
    assert "messages" in capsys.readouterr().out
    blocks = list(LogReader(out))
    assert {b.buoy_id for b in blocks} == {"b9"}
    assert min(b.t_first_ns for b in blocks) == parse_iso_ns("2024-05-01T00:00:00Z")
    # --quantum: tension stored to 10 N (every value a multiple, within 5 N of the default
    # run's, which keeps it to 0.1 N); a bad one is named
    coarse = tmp_path / "coarse.mcap"
    assert main(["simulate", "-o", str(coarse), "--hours", "0.02", "--hs", "1", "--tp", "6",
                 "--seed", "3", "--buoy-id", "b9", "--start", "2024-05-01T00:00:00Z",
                 "--quantum", "tension_N=10"]) == 0
    fine, rough = (np.concatenate([b.fields["tension_N"] for b in LogReader(p)
                                   if b.sensor == "tension"]) for p in (out, coarse))
    assert np.array_equal(np.round(rough / 10) * 10, rough)
    assert np.all(np.abs(rough - fine) <= 5.05) and np.any(np.abs(rough - fine) > 1)
    assert main(["simulate", "-o", str(coarse), "--hours", "0.02", "--hs", "1", "--tp", "6",
                 "--seed", "3", "--quantum", "tension_N=-1"]) == 2
    assert "--quantum 'tension_N=-1'" in capsys.readouterr().err
    assert main(["simulate", "-o", str(out), "--hours", "1", "--hs", "1", "--tp", "6",
                 "--seed", "3", "--nans", "1.5"]) == 2
    assert "nans = 1.5: must be a probability" in capsys.readouterr().err
    assert main(["simulate", "-o", str(out), "--hours", "1", "--hs", "1", "--tp", "6",
                 "--seed", "3", "--mean-span", "33"]) == 2
    assert "cannot reach" in capsys.readouterr().err


def test_cli_warns_of_an_impossible_sea_and_refuses_a_meaningless_one(tmp_path, capsys):
    """Hs 50 m at Tp 8 s in the mooring's 23 m: waves of 8 s break above 12.0 m (Miche,
    tests/test_waves.py), and 50 m is beyond the 10 m sea-state table; the loads it produces
    are above the 45 kN break. A real process says all three on stderr and still writes the
    log (a design study may want it); a plausible sea says nothing."""
    out = tmp_path / "x.mcap"
    p = subprocess.run([sys.executable, "-m", "monitor.cli", "simulate", "-o", str(out),
                        "--hours", "0.01", "--hs", "50", "--tp", "8", "--seed", "1"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    warnings = [ln for ln in p.stderr.splitlines() if "warning:" in ln]
    assert len(warnings) == 3, p.stderr
    assert "Hs 50 m is not a possible sea at Tp 8 s in 23 m of water: waves of that period " \
           "break above 12 m" in warnings[0]
    assert "beyond the sea-state table" in warnings[1] and "Hs 0 to 10 m" in warnings[1]
    assert "above the cable's 45,000 N breaking load" in warnings[2]
    assert out.exists()
    # Hs beyond the table at a long period breaks nothing: only the table warning
    assert main(["simulate", "-o", str(out), "--hours", "0.01", "--hs", "1", "--tp", "26",
                 "--seed", "1"]) == 0
    err = capsys.readouterr().err
    assert "beyond the sea-state table" in err and "not a possible sea" not in err
    assert main(["simulate", "-o", str(out), "--hours", "0.01", "--hs", "1.5", "--tp", "5.25",
                 "--seed", "1"]) == 0
    assert "warning" not in capsys.readouterr().err
    for hs, message in (("0", "hs_m = 0.0: must be a finite number > 0"),
                        ("-2", "hs_m = -2.0: must be"), ("nan", "hs_m = nan: must be")):
        assert main(["simulate", "-o", str(out), "--hours", "0.01", "--hs", hs, "--tp", "8",
                     "--seed", "1"]) == 2
        assert message in capsys.readouterr().err
    assert main(["simulate", "-o", str(out), "--hours", "0.01", "--hs", "1", "--tp", "inf",
                 "--seed", "1"]) == 2
    assert "tp_s = inf: must be a finite number > 0" in capsys.readouterr().err


@pytest.mark.parametrize("kw, message", [
    ({"hours": 0}, "hours = 0"), ({"hs_m": float("nan")}, "hs_m = nan"),
    ({"seed": -1}, "seed = -1"), ({"dropouts": -0.1}, "dropouts"),
    ({"buoy_id": "a/b"}, "buoy id"), ({"start": "2000-01-01T00:00:00.5Z"}, "whole second"),
])
def test_bad_configuration_is_named(kw, message):
    args = {"hours": 1.0, "hs_m": 1.0, "tp_s": 5.0, "seed": 1, **kw}
    with pytest.raises(ValueError, match=message):
        SimConfig(**args)
