"""The sensor-time ``stale`` rule across an instrument replug, live (horizon 10 s), with the
shipped config (load source and motion sensor "auto") and a load cell but no motion stream:
the operator's `buoymon run` finding (bridge in the daemon, pty load cell unplugged, replugged
for ~10 s, stopped again). The never-seen motion streams gated the ordering for ever at
``newest - 10 s``, so when the data stopped its last 10 s of sensor time waited for the next
data: the ``stale`` clear of the 10 s of data went out together with the next stop's fire, in
one step (a clear and a fire in the same millisecond). monitor.ordering: a load stream not
seen within the first horizon of live data no longer gates."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monitor.blocks import SampleBlock
from monitor.config import load_config
from monitor.pipeline import Pipeline

SHIPPED = Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml"
T0_NS = 1_750_000_000 * 10**9  # on the 10 s tick grid


def second(s: float) -> SampleBlock:
    """One second of 20 Hz tension from ``s`` s after T0 (a load cell line per 50 ms)."""
    t = T0_NS + int(round(s * 1e9)) + 50_000_000 * np.arange(20, dtype=np.int64)
    x = 20000.0 + 3000.0 * np.sin(np.arange(20.0) / 3.0 + s)
    return SampleBlock("vaps", "tension", t, {"tension_N": x}, int(t[-1]))


# data to 52.95 s, unplugged, replugged 69.0 .. 79.95 s, stopped, back from 146 s
SECONDS = [*range(0, 53), *np.arange(69.0, 79.4, 1.0), *range(146, 160)]


def stale_steps(p: Pipeline) -> list[tuple[float, list[tuple[str, float]]]]:
    """Per block with stale transitions: the block's start (s) and (event, tick end s)."""
    out = []
    for s in SECONDS:
        ev = [(a.event, (a.at_ns - T0_NS) / 1e9) for a in p.process(second(s)).alerts
              if a.rule == "stale"]
        if ev:
            out.append((float(s), ev))
    return out


def test_stale_clear_goes_out_with_the_data_not_with_the_next_stop():
    p = Pipeline(load_config(SHIPPED), horizon_s=10.0)
    # tick 60: last sample 52.95 s, 7.05 s > stale_after_s 5 s (fired once data resumes,
    # the first sensor time past 60 s); tick 70: sample at 70.0 s, clear, by the block that
    # carries it (before the fix: with the next stop's fire, by the block at 146 s); tick 80:
    # age 0.05 s; tick 90: last sample 79.95 s, 10.05 s: fire, with the data at 146 s.
    assert stale_steps(p) == [(69.0, [("fire", 60.0)]), (70.0, [("clear", 70.0)]),
                              (146.0, [("fire", 90.0)]), (150.0, [("clear", 150.0)])]
    assert p.reorder.load_streams == ("tension", "imu", "motion")  # still "auto", unseen


def test_a_motion_stream_arriving_with_the_load_cell_still_gates():
    """The start-up gate kept: an IMU block arriving just after the load cell's first block
    (same sensor time) is not late."""
    p = Pipeline(load_config(SHIPPED), horizon_s=10.0)
    p.process(second(0))
    t = T0_NS + 50_000_000 * np.arange(20, dtype=np.int64)
    a = np.sin(np.arange(20.0))
    p.process(SampleBlock("vaps", "imu", t, {"accel_x_mps2": 0.1 * a, "accel_y_mps2": 0.1 * a,
                                             "accel_z_mps2": 9.81 + a}, int(t[-1])))
    assert p.validators["imu"].accepted == 20
    assert not any(p.validators["imu"].rejected.values())
