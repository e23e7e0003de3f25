"""Kernels run compiled or as plain Python give the same bits (models._jit): a small log is
replayed without numba (replay.runner.plain_python_pays), a larger one compiled, and the
report is the same to the byte either way. Real logs: a simulated 36-second log (every
stream: load cell, IMU, motion estimator, GNSS) and the Maine end-line load cell."""

from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path

import mcap.reader
from mcap.writer import IndexType, Writer
import numpy as np
import pytest

from models import _jit
from monitor.cli import main
from monitor.config import config_with, default_config
from replay import runner
from replay.log_files import inflated_size
from replay.report import write_report
from replay.runner import PLAIN_PYTHON_BYTES, plain_python_pays, replay_logs
from replay.simulate import SimConfig, simulate

REPO = Path(__file__).resolve().parents[1]
# ../shared/realdata beside the repository (or beside a parent: a worktree)
SHARED = next((p / "shared" / "realdata" for p in REPO.parents
               if (p / "shared" / "realdata").is_dir()), REPO.parent / "shared" / "realdata")
MAINE = SHARED / "maine_endline_loadcell" / "17348481-2018.11.30-09.58.27-15.csv"
LBF = 4.4482216152605  # N per pound-force (the load cell logs lbf)


def _report_bytes(log: Path, out: Path, plain: bool, config) -> bytes:
    result = replay_logs(config, [log], show_progress=False, plain=plain)
    write_report(out, result.report)
    return out.read_bytes()


def _both_ways(log: Path, tmp_path: Path, config=None) -> dict:
    config = config or default_config()
    calls = {"plain": 0}
    py_call = _jit.Kernel.__call__

    def counting(self, *args):
        calls["plain"] += bool(_jit._Dispatch.depth)
        return py_call(self, *args)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(_jit.Kernel, "__call__", counting)
        plain = _report_bytes(log, tmp_path / "plain.json", True, config)
        assert calls["plain"] > 50  # the reader, decoder, validation, fatigue loops...
        ran_plain = calls["plain"]
        compiled = _report_bytes(log, tmp_path / "compiled.json", False, config)
        assert calls["plain"] == ran_plain  # nothing ran uncompiled the second time
    assert plain == compiled
    return json.loads(plain)


def test_a_simulated_36_s_log_gives_the_same_report_bytes_plain_and_compiled(tmp_path):
    log = tmp_path / "tiny.mcap"
    simulate(SimConfig(hours=0.01, hs_m=2.0, tp_s=8.0, seed=1), log)
    assert inflated_size([log]) <= PLAIN_PYTHON_BYTES  # what `buoymon replay` runs plain
    report = _both_ways(log, tmp_path)
    assert {s: report["samples"][s]["accepted"] for s in ("tension", "imu", "motion", "gnss")} \
        == {"tension": 720, "imu": 360, "motion": 360, "gnss": 36}
    damage = [c["damage"] for c in report["components"].values()]
    assert len(damage) == 2 and all(d > 0 for d in damage)


def test_a_faulty_log_with_the_load_estimated_from_motion_gives_the_same_report_bytes(tmp_path):
    # dropouts, spikes and NaN on every stream (rejections, QC flags, gaps), and the fatigue
    # load taken from the motion estimator instead of the load cell (which forms its first
    # estimates after a minute: a 3-minute log, still one that replays as plain Python)
    log = tmp_path / "faulty.mcap"
    simulate(SimConfig(hours=0.05, hs_m=3.0, tp_s=6.0, seed=5, dropouts=0.02, spikes=0.01,
                       nans=0.01), log)
    assert inflated_size([log]) <= PLAIN_PYTHON_BYTES
    config = config_with(default_config(), load={**default_config().section("load"),
                                                 "source": "estimated"})
    report = _both_ways(log, tmp_path, config)
    rejected = report["samples"]["tension"]["rejected"]
    assert sum(rejected.values()) > 10 and rejected["nan"] > 0 and rejected["spike"] > 0
    assert report["tension_N"]["samples_estimated"] > 300
    assert report["tension_N"]["samples_measured"] == 0


@pytest.mark.skipif(not MAINE.exists(), reason="shared/realdata not beside the project")
def test_a_real_load_cell_log_gives_the_same_report_bytes_plain_and_compiled(tmp_path, capsys):
    raw = np.genfromtxt(MAINE, delimiter=",", usecols=(1, 2), max_rows=1500)
    csv = tmp_path / "in.csv"
    csv.write_text("time_s,tension_N\n" + "".join(
        f"{s!r},{v * LBF!r}\n" for s, v in zip(raw[:, 0].tolist(), raw[:, 1].tolist())))
    log = tmp_path / "in.mcap"
    assert main(["import", str(csv), "-o", str(log), "--buoy-id", "vaps"]) == 0
    capsys.readouterr()
    report = _both_ways(log, tmp_path)
    assert report["samples"]["tension"]["accepted"] == 1500
    assert all(c["cycles"] > 100 for c in report["components"].values())


def test_inflated_size_is_the_chunks_uncompressed_as_the_mcap_library_reads_them(tmp_path):
    log = tmp_path / "two.mcap"
    simulate(SimConfig(hours=0.02, hs_m=2.0, tp_s=8.0, seed=2), log)
    with open(log, "rb") as f:
        chunks = mcap.reader.make_reader(f).get_summary().chunk_indexes
    assert len(chunks) >= 1
    expected = log.stat().st_size + sum(c.uncompressed_size - c.compressed_size for c in chunks)
    assert expected > 1.5 * log.stat().st_size  # the chunks are compressed
    assert inflated_size([log]) == expected
    assert inflated_size([log, log]) == 2 * expected
    # another writer (the mcap package's, chunks of 4 kB): the same sum; a summary that does
    # not index every chunk (MCAP allows it) or has no statistics tells no size
    for index, stats, expected_size in ((IndexType.ALL, True, True),
                                        (IndexType.MESSAGE, True, False),
                                        (IndexType.ALL, False, False)):
        other = tmp_path / "other.mcap"
        with open(other, "wb") as f:
            w = Writer(f, chunk_size=4096, index_types=index, use_statistics=stats)
            w.start()
            ch = w.register_channel("buoy/x/sensor/tension", "protobuf",
                                    w.register_schema("x", "protobuf", b""))
            for i in range(400):
                w.add_message(ch, log_time=i, data=bytes(100), publish_time=i)
            w.finish()
        with open(other, "rb") as f:
            chunks = mcap.reader.make_reader(f).get_summary().chunk_indexes
        size = other.stat().st_size + sum(c.uncompressed_size - c.compressed_size for c in chunks)
        assert inflated_size([other]) == (size if expected_size else None)
        assert len(chunks) > 5 or not expected_size
    # a file cut short has no summary: its size is not known up front, so it is compiled
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(log.read_bytes()[: log.stat().st_size // 2])
    assert inflated_size([cut]) is None and inflated_size([log, cut]) is None


def test_only_small_logs_in_a_process_without_numba_run_plain(tmp_path, monkeypatch):
    small = tmp_path / "small.mcap"
    simulate(SimConfig(hours=0.01, hs_m=2.0, tp_s=8.0, seed=1), small)
    size = inflated_size([small])
    monkeypatch.delitem(__import__("sys").modules, "numba", raising=False)
    monkeypatch.setattr(runner, "PLAIN_PYTHON_BYTES", size)
    assert plain_python_pays([small])
    monkeypatch.setattr(runner, "PLAIN_PYTHON_BYTES", size - 1)
    assert not plain_python_pays([small])
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(small.read_bytes()[:-100])
    monkeypatch.setattr(runner, "PLAIN_PYTHON_BYTES", 10 ** 12)
    assert not plain_python_pays([cut])


def test_kernels_call_kernels_compiled_and_plain():
    # the encoder (a kernel) calls _regular_period and _put_quantized (kernels) and inlines
    # _put_varint: the same bytes compiled and as plain Python, for regular and irregular times
    from monitor import codec

    vals = np.array([[1.0, 2.5, np.nan, -4.0, 1e300, 0.2]])
    quanta = np.array([0.1])
    for t in (np.arange(6, dtype=np.int64) * 50_000_000 + 10**18,
              np.array([0, 3, 99, 100, 7_000_000_000, 7_000_000_001], np.int64) + 10**18):
        payloads = []
        for plain in (False, True):
            out = np.zeros(codec.payload_bound(6, 1), np.uint8)
            with _jit.uncompiled() if plain else contextlib.nullcontext():
                k = codec.put_payload(out, 0, t, vals, quanta, 0, 6)
            payloads.append(out[:k].tobytes())
        assert payloads[0] == payloads[1]
        for plain in (False, True):
            with _jit.uncompiled() if plain else contextlib.nullcontext():
                block = codec.decode_block("b", "tension", payloads[0])
            assert block.t_ns.tolist() == t.tolist()
            assert block.fields["tension_N"][[0, 1, 3, 5]].tolist() == [1.0, 2.5, -4.0, 0.2]
            assert np.isnan(block.fields["tension_N"][2]) and block.fields["tension_N"][4] == 1e300


def test_catenary_solves_give_the_same_bits_compiled_and_plain():
    # the seed's mooring (suspended, grounded, slack) and a chain + clump + rope line with
    # seabed friction: Newton on asinh, sinh, log1p, hypot... all libm's both ways
    from models.catenary import Joint, Line, Segment, solve, vaps_mooring

    rng = np.random.default_rng(3)
    lines = {"vaps": (vaps_mooring(), rng.uniform(0.0, 31.5, 40), rng.uniform(21.0, 25.0, 40)),
             "clump": (Line((Segment(86.7, 10.7), Segment(41.2, 1.03, 2e8)), (Joint(467.0),),
                            True, 0.9), rng.uniform(60.0, 120.0, 40), rng.uniform(30.0, 45.0, 40))}
    for name, (line, x, z) in lines.items():
        out = []
        for plain in (False, True):
            with _jit.uncompiled() if plain else contextlib.nullcontext():
                sol = solve(line, x, z)
            out.append(np.stack([sol.h, sol.v_top, sol.h_anchor, sol.grounded_length]))
        assert np.isfinite(out[0]).sum() > 100, name
        assert out[0].tobytes() == out[1].tobytes(), name


def test_gnss_location_qc_gives_the_same_flags_compiled_and_plain():
    # fixes wandering by ~450 m a step around the anchor against a 300 m location limit: the
    # haversine distance (sin, cos, asin) on both sides of it, and NaN fixes
    from monitor.config import FieldLimits
    from monitor.qartod import StreamQC

    rng = np.random.default_rng(4)
    n = 400
    t = (np.arange(n) * 1_000_000_000 + 10**18).astype(np.int64)
    lat = 41.85 + np.cumsum(rng.normal(0.0, 0.004, n))
    lon = -82.4 + np.cumsum(rng.normal(0.0, 0.004, n))
    lat[::50] = np.nan
    fields = (FieldLimits(-90.0, 90.0, math.inf), FieldLimits(-180.0, 180.0, math.inf))
    flags = []
    for plain in (False, True):
        qc = StreamQC(fields, location_range_max_m=300.0)
        with _jit.uncompiled() if plain else contextlib.nullcontext():
            flags.append(qc.check(t, np.stack([lat, lon])))
    location = flags[0][0][4]
    assert (location == 3).sum() > 10 and (location == 1).sum() > 10 and (location == 4).sum() > 3
    assert all(np.array_equal(a, b) for a, b in zip(flags[0], flags[1]))


def test_catenary_building_blocks_give_the_same_bits_compiled_and_plain():
    # _quotients (hypot(1, a), asinh, log1p of slopes) over many slope pairs: Python's own
    # math.hypot differs from libm's in the last bit for some of these, numpy's does not
    from models.catenary import kernel

    rng = np.random.default_rng(5)
    pairs = rng.normal(0.0, 3.0, (3000, 2)) * rng.choice([1e-3, 1.0, 1e3], (3000, 1))
    pairs[:1000, 1] = pairs[:1000, 0] * (1.0 + rng.normal(0.0, 1e-9, 1000))  # a -> b
    out = []
    for plain in (False, True):
        with _jit.uncompiled() if plain else contextlib.nullcontext():
            out.append(np.array([kernel._quotients(a, b) for a, b in pairs.tolist()]))
    assert np.isfinite(out[0]).all()
    assert out[0].tobytes() == out[1].tobytes()
