"""``buoymon warmup``: compile every numerical kernel into numba's on-disk cache now.

numba compiles a kernel the first time a process calls it and keeps the machine code in its
cache (``__pycache__`` beside the source, or ``NUMBA_CACHE_DIR``); later processes load it.
Compiling them all takes about 35 s of CPU on the 2-core machine, so it happens here, when
the product is installed or the service starts (``make demo``, ``make test``, the systemd
unit's ``ExecStartPre``), never silently in a user's first command (a command that still
has to compile says so on stderr: monitor.numba_setup). With a filled cache this loads
each kernel once and exits (about 1 s of CPU, bench/bench_startup.py).

It runs each path through its kernels on throwaway data: a 36-second simulated log per load
model (sea, buoy motion, catenary, axial dynamics, WAVFOR; the log writer and encoder),
both logs replayed through the pipeline with the demo's components (reader, decoder,
validation, QARTOD, motion estimator, rainflow, Miner, alert ticks), the live daemon's
Zenoh codec, and the library's per-call path (conductor_stress -> StreamingRainflow.feed ->
MinerAccumulator.add_cycles, with the residue, the S-N curve's damage per cycle and a
mean-corrected curve's commit).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("warmup", description=__doc__.split("\n\n")[0])
    p.add_argument("--config", metavar="CFG.toml",
                   help="also build this configuration's pipeline, as `buoymon run` does "
                        "(its costly model builds then come from the model cache too)")
    p.set_defaults(func=run)


def warm_up(folder: Path, config_path: str | None = None) -> None:
    """Call every kernel once, writing scratch files in ``folder``; with ``config_path``,
    also build that configuration's pipeline (filling the model cache for it)."""
    # imported here, not with the module: `buoymon warmup --help` then stays instant (the
    # kernels' modules bring numpy and numba, 0.4 s)
    import numpy as np

    from models.fatigue import MinerAccumulator, SNCurve, StreamingRainflow
    from models.helix import HelixCable, conductor_stress
    from monitor import zenoh_io
    from replay.cmd_demo import demo_config
    from replay.reader import LogReader
    from replay.runner import replay_logs
    from replay.simulate import LOAD_MODELS, SimConfig, simulate

    logs = []
    for model in LOAD_MODELS:
        logs.append(folder / f"{model}.mcap")
        simulate(SimConfig(hours=0.01, hs_m=1.5, tp_s=5.25, seed=4, load_model=model), logs[-1])
    for log in logs:  # one at a time: two logs of one buoy overlap in time
        replay_logs(demo_config(), [log], show_progress=False, plain=False)  # compiled
    codec = zenoh_io.default_codec()
    block = next(iter(LogReader([logs[0]], coalesce=False)))
    codec.decode(f"buoy/{block.buoy_id}/sensor/{block.sensor}", codec.encode(block), 0)
    rainflow, miner = StreamingRainflow(), MinerAccumulator(SNCurve.vaps_copper())
    stress = conductor_stress(np.array([1e3, 3e3, 500.0, 2.5e3, 800.0]), HelixCable.vaps_biw())
    cycles = rainflow.feed(stress)
    miner.add_cycles(*cycles, time_s=0.0)
    miner.residue_damage(rainflow)
    miner.sn_curve.damage_per_cycle(*rainflow.residue_half_cycles())
    # a mean-corrected curve commits through its own loop (the damages given)
    goodman = miner.sn_curve.with_factors(mean_correction="goodman", ultimate_Pa=220e6)
    MinerAccumulator(goodman).add_cycles(*cycles)
    if config_path is not None:
        from monitor.config import load_config
        from monitor.load_source import build_estimator
        from monitor.pipeline import Pipeline

        config = load_config(config_path)
        Pipeline(config).close()  # runs each kernel once (Pipeline.warm_up_stream, warm_up_ticks)
        if config.load.source != "measured":  # built at the first motion block otherwise
            build_estimator(config)  # its catenary table goes to the model cache


def run(args: argparse.Namespace) -> int:
    from monitor.config import ConfigError

    start = time.perf_counter()
    try:
        with tempfile.TemporaryDirectory(prefix="buoymon-warmup-") as tmp:
            warm_up(Path(tmp), args.config)
    except ConfigError as exc:
        print(f"buoymon warmup: {exc}", file=sys.stderr)
        return 2
    print(f"buoymon warmup: kernels ready ({time.perf_counter() - start:.1f} s)")
    return 0
