"""Per-tick cost of the alert-tick bookkeeping of a replay slab (issue 22, part 3).

One slab of 144 ten-second alert ticks (a day's replay evaluates 8640) of 20 Hz tension
(wave-like, sensor noise, a load-cell outage of 10 minutes: two ticks mixing measured and
estimated samples; one tick without samples), with the default configuration's two conductor components. Prints the
CPU time per tick (best of ``--runs`` passes over ``--reps`` slabs) of

- ``run_ticks``: each component's ``Component.run_ticks`` with the per-tick figures (the
  compiled rainflow/Miner pass, the dating of each tick's damage for the rate, and the
  (damage, committed, rate, life) tuples the alert side reads), for both components;
- ``tick_load``: the pipeline's per-tick load figures (``_TickLoad``: extremes, peak
  stresses, per-source means);
- ``stream_health``: one stream's per-tick health (``_StreamSlab.prepare`` and its ``tick``
  at every tick end, as the rules ask for it);
- ``estimate_means``: the mean motion estimate per tick (``Pipeline._estimate_means``);
- ``damage_split``: the committed damage split by load source (``DamageSplit.ticks``, with
  the per-tick committed damages ``Pipeline._evaluate_ticks`` gathers for it);
- ``alert_batch``: the default rules over the slab through the alert engine's batch
  (``AlertEngine.tick_batch`` and its ``run``, the slab's inputs made as the pipeline makes
  them, the ordinary evaluations it asks for included), with the six rule instances the
  30-day benchmark log has firing from its second day, each re-sent hourly at staggered
  times: three re-sends in the slab (that log averages 2.2 per slab).

``--repo`` runs the same figures on another checkout (e.g. main) for a before/after in one
session: the parts' interfaces are the same there. ``--replay LOG`` instead replays a log
in-process (default configuration, no read-ahead thread) and prints the CPU seconds of the
alert-tick stage: ``Pipeline._due_ticks`` and ``_evaluate_ticks``, within them the sea-state
learner's windows and the damage split, and ``alerts``, the rest (best of ``--runs`` by
due + evaluate).

Measured 2026-11-25 19:07 UTC on the shared 2-core Xeon (Emerald Rapids, 2.3 GHz, load
average 8 from other work), CPU us per tick, best of 7, two interleaved sessions
(``--repo /work/main`` = before, main at 7e8ba84; after = branch ticks):

    part              before        after
    run_ticks         7.32 / 7.33   3.35 / 3.31
    tick_load         0.78 / 0.78   0.66 / 0.65
    stream_health     0.87 / 0.86   0.68 / 0.63
    estimate_means    1.33 / 1.32   0.13 / 0.13
    damage_split      0.56 / 0.55   0.53 / 0.53

Of ``run_ticks`` after, about 2.9 us is the compiled rainflow/Miner pass itself (per
component and tick 1.4 us counting and committing 200 samples, 0.4 us the open residue's
damage): the Python around it (dating each tick for the damage rate, the figure tuples)
went from about 4 to 0.3 us per tick. In the 1-day replay itself (thread CPU of
``Component.run_ticks`` over its 8640 ticks, two runs each): 74-89 ms before, 48 ms after,
of which the compiled pass is 30-32 ms both times. ``tick_load`` is now six ``reduceat``
passes over the slab's samples (data-bound), ``stream_health`` the ``StreamObs`` each
rule's tick asks for, ``damage_split`` three numpy passes per component and slab.

Alert batch (branch alerts, issue 22 parts 3 and 5), measured 2026-11-25 on the same
machine (CPU times; interleaved; main at c8bad01 = before). ``alert_batch``, CPU us per
tick, best of 7 x 20 slabs: before 4.19 / 3.09 / 2.73, after 1.68 / 1.50 / 1.40 (three
sessions, 21:48-22:06 UTC, load average 2-6.7 from other workers: about 2 x). What went:
the re-sends (most of the ordinary evaluations of a long replay: 1,900 of 1,950 in the
30-day log) are made in the compiled scan and built from the rule, without an Observation;
the rejected-rate window in one compiled pass, kept as an array between slabs; the firing
state read and written in one go; a stream's per-tick health computed only for the streams
a rule reads. ``--replay /tmp/perf_bench/log_30d.mcap`` (bench_replay.py's 30-day log,
1,785 batch slabs), one run each, three interleaved pairs at 22:10-22:14 UTC, load average
1.3-2.1, CPU s before / after:

    replay             12.41 / 11.24   14.84 / 11.16   11.98 / 11.81
    due                 0.72 / 0.40     0.90 / 0.42     0.69 / 0.44
    due + evaluate      3.15 / 2.33     3.89 / 2.35     2.98 / 2.48
    learner + split     1.25 / 1.20     1.50 / 1.17     1.19 / 1.22
    alerts (the rest)   1.90 / 1.14     2.39 / 1.19     1.79 / 1.26

(main's second run was slowed by other work: its learner too). Earlier pairs at load 4-6.7
(21:48-21:55, before the last two changes): alerts 2.14 / 1.47, 1.95 / 1.41, 1.95 / 1.38.
The brief's 2.5 x of the stage's ~3.9 CPU-s (cProfile; 2.98-3.15 s without it) is NOT
reached: best of each, due + evaluate 2.98 -> 2.33 (1.28 x), alerts 1.79 -> 1.14 (1.57 x),
due 0.69 -> 0.40 (1.7 x). A third of the stage is the sea-state learner's window closes
(Dirlik spectra, about 1.0 s) and the damage split (0.23 s), which this work does not
touch, and of ``alerts`` about 0.5 s is ``_TickLoad`` (the slab's and its first tick's
per-tick figures) and 0.1-0.2 s turning the components' per-tick figure tuples into the
rules' columns (cheaper if ``Component.run_ticks`` handed its arrays).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

N_TICKS, HZ, TICK_S = 144, 20, 10


def measure(reps: int, runs: int) -> dict[str, float]:
    import numpy as np

    from monitor.components import Component, build_cable
    from monitor.config import default_config
    from monitor.load_source import MEASURED
    from monitor.pipeline import Pipeline, _StreamSlab, _TickLoad

    config = default_config()
    cable = build_cable(config)
    per = HZ * TICK_S
    n = N_TICKS * per
    rng = np.random.default_rng(1)
    t0 = 1_700_000_000 * 10**9
    t = t0 + (np.arange(n, dtype=np.int64) * 10**9) // HZ
    v = 6000.0 + 1500.0 * np.sin(2 * np.pi * np.arange(n) / (HZ * 6.0)) + rng.normal(0, 50, n)
    src = np.full(n, MEASURED, np.int8)
    src[10 * per + per // 2:70 * per + per // 2] = MEASURED + 1  # a load-cell outage
    ends = t0 + TICK_S * 10**9 * np.arange(1, N_TICKS + 1, dtype=np.int64) - 1
    t_cut = np.concatenate([t[:50 * per], t[51 * per:]])  # tick 50 has no samples
    cuts = np.searchsorted(t_cut, ends, side="right")
    v_cut, src_cut = np.concatenate([v[:50 * per], v[51 * per:]]), np.concatenate(
        [src[:50 * per], src[51 * per:]])
    stops, ends_l = cuts.tolist(), ends.tolist()
    comps = [Component(c, cable, config.fatigue) for c in config.components]
    stresses = {c.name: c.stress(v_cut, record=False) for c in comps}
    pipeline = Pipeline(config)
    codes = np.zeros(t_cut.shape[0], np.int8)
    before = (0, {}, False, 0)

    def run_ticks() -> None:
        for c in comps:
            c.run_ticks(stresses[c.name], stops, ends_l)

    def tick_load() -> None:
        _TickLoad(v_cut, src_cut, stresses, np.append(0, cuts[:-1]), cuts)

    def stream_health() -> None:
        slab = _StreamSlab(t_cut, v_cut[None, :], codes, before)
        slab.prepare(ends)
        for k, end in enumerate(ends_l):
            slab.tick(k, end, 30e9)

    def estimate_means() -> None:
        pipeline._estimate_means(t_cut, v_cut, ends)

    figures = {c.name: c.run_ticks(stresses[c.name], stops, ends_l).figures for c in comps}
    load = _TickLoad(v_cut, src_cut, stresses, np.append(0, cuts[:-1]), cuts)
    rows = [(load.n_meas[k], load.n[k], load.meas[k], load.est[k]) for k in range(N_TICKS)]

    def damage_split() -> None:
        # as Pipeline._evaluate_ticks hands the slab's ticks to the split
        pipeline.damage_split.ticks({n: [f[k][1] for k in range(N_TICKS)]
                                     for n, f in figures.items()}, rows)

    out = {}
    for name, fn in (("run_ticks", run_ticks), ("tick_load", tick_load),
                     ("stream_health", stream_health), ("estimate_means", estimate_means),
                     ("damage_split", damage_split)):
        fn()  # compiled kernels loaded, caches warm
        best = float("inf")
        for _ in range(runs):
            start = time.process_time()
            for _ in range(reps):
                fn()
            best = min(best, time.process_time() - start)
        out[name] = best / reps / N_TICKS * 1e6
    out["alert_batch"] = _alert_batch(reps, runs, pipeline, figures, load, t_cut, v_cut, cuts,
                                      ends, _StreamSlab(t_cut, v_cut[None, :], codes, before))
    return out


def _alert_batch(reps: int, runs: int, pipeline, figures, load, t_cut, v_cut, cuts, ends,
                 slab) -> float:
    """CPU us per tick of the default rules' batch over the slab (``tick_batch`` and its
    ``run``, the ordinary evaluations it asks for included) with the six rule instances the
    30-day log has firing from its second day (damage fractions, conductor stress), each
    re-sent hourly at staggered times: three re-sends in the slab (2.2 per slab there)."""
    import inspect

    import numpy as np

    from monitor.alerts.batch import StreamTicks, TickInputs
    from monitor.alerts.engine import AlertEngine
    from monitor.events import ComponentObs, Observation, StreamObs

    engine, t0 = pipeline.alerts, int(ends[0]) - TICK_S * 10**9
    firing = [r for r in engine._rules if r.kind in ("damage_fraction", "conductor_stress")]
    for i, rule in enumerate(firing):
        rule.firing, rule.starts_at_ns = True, t0 - 86400 * 10**9
        rule.last_sent_ns = t0 - 3600 * 10**9 + i * 600 * 10**9
    state = engine.state()
    slab.prepare(ends)
    received, rejected, has, last = slab.tick_arrays
    tension = StreamTicks(np.where(has, last, 0), ~has | (ends - last > 30 * 10**9), received,
                          rejected)
    idle = StreamTicks(np.zeros(N_TICKS, np.int64), np.ones(N_TICKS, bool),
                       np.zeros(N_TICKS, np.int64), np.zeros(N_TICKS, np.int64))
    starts = np.append(0, cuts[:-1])

    def inputs() -> TickInputs:  # as the pipeline makes them for a slab
        columns: dict[tuple[str, int], np.ndarray] = {}

        def component(name: str, i: int) -> np.ndarray:
            if (name, i) not in columns:
                columns[name, i] = (np.array([f[i] for f in figures[name]]) if i < 4
                                    else np.array(load.smax[name]))
            return columns[name, i]
        return TickInputs(
            buoy_id=engine.buoy_id, ends=ends, tension_max=np.array(load.vmax),
            measured=np.array(load.meas), estimated=np.array(load.est), component=component,
            stream=lambda s: tension if s == "tension" else idle,
            load=lambda: (t_cut, v_cut, starts, cuts))

    def obs(k: int) -> Observation:
        a, b = int(starts[k]), int(cuts[k])
        return Observation(
            engine.buoy_id, int(ends[k]), float(TICK_S), "measured", t_cut[a:b], v_cut[a:b],
            load.meas[k], load.est[k],
            {n: ComponentObs(*f[k], load.smax[n][k]) for n, f in figures.items()},
            {"tension": StreamObs(int(last[k]), False, 0, {}, int(rejected[k]),
                                  int(received[k]))},
            (load.vmin[k], load.vmax[k]))
    best = float("inf")
    for _ in range(runs + 1):  # the first: compiled kernels loaded, caches warm
        spent = 0.0
        for _ in range(reps):
            eng = AlertEngine.from_state(state)
            start = time.process_time()
            batch = eng.tick_batch(inputs())
            tick = lambda k, eng=eng: eng.evaluate(obs(k))  # noqa: E731
            if "sent" in inspect.signature(batch.run).parameters:
                batch.run(tick, list)  # this build: re-sends come back as records
            else:
                batch.run(tick)  # main: every re-send tick evaluated the ordinary way
            spent += time.process_time() - start
        best = min(best, spent)
    return best / reps / N_TICKS * 1e6


def measure_replay(log: str, runs: int) -> dict[str, float]:
    """CPU seconds of the alert-tick stage in an in-process replay of ``log`` (default
    configuration, no read-ahead thread), best of ``runs`` by ``due + evaluate``: the
    pipeline's ``_due_ticks`` and ``_evaluate_ticks``, and within them the sea-state
    learner's ticks and the damage split (neither alert work: ``alerts`` is the rest)."""
    from monitor import damage_split, pipeline, sea_state_learner
    from monitor.config import default_config
    from replay.reader import LogReader
    from replay.runner import run_blocks

    spent: dict[str, float] = {}
    depth = {"learner": 0}

    def timed(cls: type, name: str, key: str) -> None:
        func = getattr(cls, name)

        def wrapper(*args, **kwargs):
            if key == "learner":  # tick() is also called from ticks(): count the outer call
                depth[key] += 1
                if depth[key] > 1:
                    try:
                        return func(*args, **kwargs)
                    finally:
                        depth[key] -= 1
            start = time.process_time()
            try:
                return func(*args, **kwargs)
            finally:
                spent[key] = spent.get(key, 0.0) + time.process_time() - start
                if key == "learner":
                    depth[key] -= 1
        setattr(cls, name, wrapper)

    timed(pipeline.Pipeline, "_due_ticks", "due")
    timed(pipeline.Pipeline, "_evaluate_ticks", "evaluate")
    timed(sea_state_learner.SeaStateLearner, "ticks", "learner")
    timed(sea_state_learner.SeaStateLearner, "tick", "learner")
    timed(damage_split.DamageSplit, "ticks", "split")
    config = default_config()
    run_blocks(config, LogReader([log], read_ahead=False))  # compiled kernels loaded
    best: dict[str, float] = {}
    for _ in range(runs):
        spent.clear()
        start = time.process_time()
        run_blocks(config, LogReader([log], read_ahead=False))
        run = {"replay": time.process_time() - start, **spent}
        if not best or run["due"] + run["evaluate"] < best["due"] + best["evaluate"]:
            best = run
    best["alerts"] = best["due"] + best["evaluate"] - best["learner"] - best["split"]
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--repo", help="measure this checkout instead (a child process)")
    ap.add_argument("--replay", metavar="LOG",
                    help="instead: the alert-tick stage's CPU in an in-process replay of LOG")
    args = ap.parse_args()
    if args.repo:
        env = {**os.environ, "PYTHONPATH": str(Path(args.repo).resolve())}
        subprocess.run([sys.executable, str(Path(__file__).resolve()), "--reps", str(args.reps),
                        "--runs", str(args.runs),
                        *(["--replay", str(Path(args.replay).resolve())] if args.replay else [])],
                       env=env, cwd=args.repo, check=True)
        return
    if args.replay:
        spent = measure_replay(args.replay, args.runs)
        print(f"CPU s, best of {args.runs}: " + "  ".join(
            f"{k} {spent[k]:.3f}" for k in ("replay", "due", "evaluate", "learner", "split",
                                           "alerts")))
        return
    figures = measure(args.reps, args.runs)
    print(f"CPU us per tick ({N_TICKS} ticks of {TICK_S} s at {HZ} Hz per slab, best of "
          f"{args.runs}):")
    for name, us in figures.items():
        print(f"  {name:<16} {us:8.2f}")


if __name__ == "__main__":
    main()
