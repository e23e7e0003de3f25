"""Measured data through the whole chain (../shared/realdata, read in place, never copied).

* The Maine endline load cell (1.65 h of real tension at ~2.9 Hz, quantised to 0.6 lbf so a
  third of its steps are plateaus): CSV -> ``buoymon import`` -> ``buoymon replay``; the
  report's damage equals the hand computation with the ``rainflow`` package.
* qats' SIMO mooring-line tension (3 h at 2 Hz): the pipeline's streaming rainflow and Miner
  sum on an axial component equal qats' own counting and Miner sum.
* The Spotter buoy's measured motion, with its GPS glitches: the estimated load is counted as
  clamped where the glitches put the buoy outside the estimator's table, and a clean hour of
  the same record gives the calm-sea tension with nothing clamped.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import rainflow

from models import fatigue, helix
from monitor.blocks import SampleBlock
from monitor.cli import main
from monitor.config import config_with, default_config
from replay.reader import LogReader
from replay.runner import run_blocks

SHARED = next(
    (p / "shared" for p in Path(__file__).resolve().parents if (p / "shared/realdata").is_dir()),
    None,
)
pytestmark = [pytest.mark.integration, pytest.mark.skipif(SHARED is None, reason="../shared/realdata absent")]
LBF = 4.4482216152605  # N


def _replay_csv(tmp_path, header, rows, *extra):
    csv = tmp_path / "in.csv"
    csv.write_text(header + "\n" + "\n".join(rows) + "\n")
    log, report = tmp_path / "in.mcap", tmp_path / "r.json"
    assert main(["import", str(csv), "-o", str(log), "--buoy-id", "vaps"]) == 0
    assert main(["replay", str(log), "--report", str(report), "--no-progress", *extra]) == 0
    return json.loads(report.read_text())


def test_measured_load_cell_damage_equals_the_rainflow_package(tmp_path, capsys):
    raw = np.genfromtxt(SHARED / "realdata/maine_endline_loadcell/"
                        "17348481-2018.11.30-09.58.27-15.csv", delimiter=",", usecols=(1, 2))
    seconds, tension = raw[:, 0], raw[:, 1] * LBF
    assert tension.shape[0] > 17_000 and np.count_nonzero(np.diff(tension) == 0) > 5_000
    rep = _replay_csv(tmp_path, "time_s,tension_N",
                      [f"{s!r},{v!r}" for s, v in zip(seconds.tolist(), tension.tolist())])
    capsys.readouterr()
    # the log keeps every sample to within half of the 0.1 N quantum; the hand computation
    # below takes the samples as the log holds them (the replay's input)
    logged = np.concatenate([b.fields["tension_N"] for b in LogReader(tmp_path / "in.mcap")])
    assert logged.shape == tension.shape and np.all(np.abs(logged - tension) <= 0.05)
    assert np.any(logged != tension)
    tension = logged
    # every sample accepted (irregular ~2.9 Hz sampling kept), none rejected
    assert rep["samples"]["tension"]["accepted"] == tension.shape[0]
    assert not any(rep["samples"]["tension"]["rejected"].values())
    # hand computation: helix stress of the as-built conductor, ASTM rainflow, copper S-N
    stress = helix.conductor_stress(tension, helix.HelixCable.vaps_biw(), lay="left")
    cyc = np.array([(r, m, c) for r, m, c, _, _ in rainflow.extract_cycles(stress)])
    per_cycle = fatigue.SNCurve.vaps_copper().damage_per_cycle(cyc[:, 0], cyc[:, 1], cyc[:, 2])
    full = cyc[:, 2] == 1.0
    fig = rep["components"]["conductor"]
    assert fig["damage_committed"] == pytest.approx(float(per_cycle[full].sum()), rel=1e-12)
    assert fig["damage"] == pytest.approx(float(per_cycle.sum()), rel=1e-12)
    assert fig["damage_committed"] > 0.5 * fig["damage"] > 0
    assert fig["max_stress_Pa"] == pytest.approx(stress.max(), rel=1e-15)
    t = rep["tension_N"]
    assert (t["min"], t["max"]) == (tension.min(), tension.max())
    assert t["mean"] == pytest.approx(tension.mean(), abs=1e-3)
    assert t["samples_measured"] == tension.shape[0] and t["samples_estimate_clamped"] == 0


def test_simo_line_tension_counts_and_sums_like_qats():
    qrf = pytest.importorskip("qats.fatigue.rainflow")
    qsn = pytest.importorskip("qats.fatigue.sn")
    folder = SHARED / "realdata/qats_simo_reference"
    raw = np.fromfile(folder / "simo_p_out.ts", dtype="<f4")
    records = raw.reshape(-1, int(raw[:1].view("<i4")[0]))  # info, time, then the channels
    names = [n.strip() for n in (folder / "simo_p_out.key").read_text().split()][1:-1]
    t_s = records[1].astype(np.float64)
    tension = records[2 + names.index("Tension_1_qs")].astype(np.float64) * 1e3  # kN -> N
    assert t_s[-1] == 11_000.0 and 1e6 < tension.max() < 1e7
    # an 84 mm studless chain leg (2 x 84^2 pi / 4) on a one-slope curve N = 6e28 / S^3 (Pa)
    area = 2 * np.pi / 4 * 0.084**2
    curve = {"stress_range_Pa": [1.0, 1e9], "cycles": [6.0e28, 60.0]}
    c = default_config()
    config = config_with(
        c, component=[{"name": "chain", "kind": "axial", "area_m2": area, "sn_curve": curve}],
        validate={"tension": {"tension_N": {"min": 0.0, "max": 2e7, "max_rate_per_s": 1e8}}},
        alerts={"eval_interval_s": 10.0})
    t_ns = 1_600_000_000 * 10**9 + np.round(t_s * 1e9).astype(np.int64)
    blocks = [SampleBlock("vaps", "tension", t_ns[a:a + 600], {"tension_N": tension[a:a + 600]})
              for a in range(0, t_ns.shape[0], 600)]
    pipeline, _ = run_blocks(config, blocks)
    fig = pipeline.report()["components"]["chain"]
    stress = tension / area
    # (range, mean, count), half cycles 0.5; the record's first and last samples are cycle
    # ends, as in ASTM E1049 and the rainflow package (qats' default drops them)
    q = qrf.count_cycles(stress, endpoints=True)
    sn = {"m1": 3.0, "loga1": np.log10(6.0e28)}
    assert fig["damage"] == pytest.approx(qsn.minersum(q[:, 0], q[:, 2], sn), rel=1e-12)
    # qats merges equal (range, mean) rows: the closed cycles alone come from the rainflow package
    cyc = np.array([(r, c) for r, _, c, _, _ in rainflow.extract_cycles(stress)])
    full = cyc[:, 1] == 1.0
    assert fig["damage_committed"] == pytest.approx(qsn.minersum(cyc[full, 0], cyc[full, 1], sn),
                                                    rel=1e-12)
    assert 0.5 * fig["damage"] < fig["damage_committed"] < fig["damage"]
    assert fig["cycles"] == np.count_nonzero(full)


def _spotter(rows: slice):
    path = SHARED / "realdata/spotter_clallam_1945/0026_FLT.CSV"
    d = np.genfromtxt(path, delimiter=",", skip_header=1 + rows.start,
                      max_rows=rows.stop - rows.start, usecols=(1, 2, 3, 4))
    return d[:, 0] - d[0, 0], d[:, 1:] / 1000.0  # s from the first row; x, y, z in m


def _spotter_config(tmp_path, rate: str | None):
    """The shipped configuration, the load estimated from the Spotter's displacements, the
    check-factor test off (so that the glitches, which it rejects, reach the estimator), and
    ``motion_rate_hz`` as shipped ("auto") or set to ``rate``."""
    text = (Path(__file__).resolve().parents[1] / "monitor/vaps_seed004.toml").read_text()
    edits = [('source = "auto"', 'source = "estimated"'),
             ('motion_sensor = "auto"', 'motion_sensor = "motion"'),
             ("[validate.imu]\n", "[validate.motion]\ncheck_factor = false\n\n[validate.imu]\n")]
    if rate is not None:
        edits.append(('motion_rate_hz = "auto"', f"motion_rate_hz = {rate}"))
    for old, new in edits:
        assert old in text
        text = text.replace(old, new)
    config = tmp_path / f"motion-{rate}.toml"
    config.write_text(text)
    return config


def _spotter_replay(tmp_path, name, rows, config):
    s, xyz = _spotter(rows)
    out = tmp_path / name
    out.mkdir()
    return s, xyz, _replay_csv(out, "time_s,surge_m,sway_m,heave_m",
                               [f"{a!r},{x!r},{y!r},{z!r}"
                                for a, (x, y, z) in zip(s.tolist(), xyz.tolist())],
                               "--config", str(config))


def test_spotter_motion_glitches_are_counted_as_clamped_estimates(tmp_path, capsys):
    # the load estimated from the Spotter's 2.5 Hz displacements, the estimator's step taken
    # from the stream itself (motion_rate_hz = "auto", as shipped)
    config = _spotter_config(tmp_path, None)
    reports = {}
    for name, rows in (("clean", slice(466, 9466)), ("glitches", slice(180_000, 190_000))):
        s, xyz, reports[name] = _spotter_replay(tmp_path, name, rows, config)
        capsys.readouterr()
        assert reports[name]["motion_rate"] == {"setting": "auto", "hz": 2.5,
                                                "samples_rate_mismatch": 0, "rate_changes": 0}
        motion = reports[name]["samples"]["motion"]
        rejected = sum(motion["rejected"].values())  # QARTOD fails (issue 17): glitch jumps
        assert motion["accepted"] + rejected == s.shape[0]
        assert rejected == 0 if name == "clean" else rejected < 200
        # the glitches: positions outside the estimator's table (seed004_estimator: offsets
        # -3 .. +3.5 m from the 29 m span, heave +-2 m); the first two samples only settle,
        # and so do the two after each gap over 5 s (the estimator restarts there)
        offset = np.hypot(29.0 + xyz[2:, 0], xyz[2:, 1]) - 29.0
        outside = np.count_nonzero((offset < -3.0) | (offset > 3.5) | (np.abs(xyz[2:, 2]) > 2.0))
        clamped = reports[name]["tension_N"]["samples_estimate_clamped"]
        settled = motion["accepted"] - reports[name]["tension_N"]["samples_estimated"]
        assert settled == 2 if name == "clean" else 2 < settled < 100
        assert outside - rejected - (settled - 2) <= clamped <= outside
        assert outside == 0 if name == "clean" else outside > 100
    calm = reports["clean"]["tension_N"]
    assert 150.0 < calm["mean"] < 300.0 and calm["max"] < 2_000.0  # the ~220 N static tension
    assert reports["glitches"]["tension_N"]["max"] > 10 * calm["max"]
    # these figures from before the step was measured, with motion_rate_hz = 2.5 configured:
    # the same step (0.4 s), the same numbers to the bit
    assert calm["max"] == 391.2895059703259 and calm["mean"] == 218.7193252945099
    assert reports["glitches"]["tension_N"]["max"] == 54693.17641660233
    assert reports["glitches"]["components"]["conductor"]["damage"] == 0.43572055051176856


def test_spotter_auto_rate_equals_the_configured_rate_and_a_wrong_rate_is_reported(
        tmp_path, capsys):
    """The shipped "auto" gives the report of motion_rate_hz = 2.5 to the bit; the old
    default, 10 Hz, withholds every sample after the first from the estimator and says so."""
    rows = slice(466, 9466)
    _, _, auto = _spotter_replay(tmp_path, "auto", rows, _spotter_config(tmp_path, None))
    assert ("  motion estimator stepped at 2.5 Hz (the stream's own spacing)\n"
            in capsys.readouterr().out)
    _, _, fixed = _spotter_replay(tmp_path, "fixed", rows, _spotter_config(tmp_path, "2.5"))
    capsys.readouterr()
    s, _, wrong = _spotter_replay(tmp_path, "wrong", rows, _spotter_config(tmp_path, "10.0"))
    summary = capsys.readouterr().out
    assert "  motion estimator stepped at 10 Hz ([load] motion_rate_hz)\n" in summary
    assert "  LOAD: 8,999 motion samples gave no load estimate: their spacing is not" in summary
    assert fixed["motion_rate"] == {"setting": 2.5, "hz": 2.5, "samples_rate_mismatch": 0,
                                    "rate_changes": 0}
    for key in ("config", "motion_rate", "inputs"):
        del auto[key], fixed[key]
    assert auto == fixed
    n = s.shape[0]
    assert wrong["motion_rate"] == {"setting": 10.0, "hz": 10.0,
                                    "samples_rate_mismatch": n - 1, "rate_changes": 0}
    assert wrong["tension_N"]["samples_estimated"] == 0
    assert wrong["samples"]["motion"]["accepted"] == n
    assert (f"{n - 1:,d} motion samples gave no load estimate: their spacing is not [load] "
            "motion_rate_hz = 10 Hz (rate_mismatch; set motion_rate_hz = \"auto\" to take the "
            "stream's own)") in wrong["load_problems"]
    assert "no load could be formed: fatigue damage is not being computed" in wrong["load_problems"]
