"""monitor.components.Component.run_ticks: the compiled pass (models.fatigue.ticks.commit_ticks)
equals the feed/commit loop."""

import dataclasses
import json
import math

import numpy as np
import pytest

import models.fatigue._loops as fatigue_loops
from monitor.components import Component, build_cable
from monitor.config import default_config


def make(hysteresis_Pa: float = 0.0, state=None) -> Component:
    config = default_config()
    cfg = dataclasses.replace(config.components[0], hysteresis_Pa=hysteresis_Pa)
    return Component(cfg, build_cable(config), config.fatigue, state)


def drive(comp: Component, stress: np.ndarray, rng, reference: bool, monkeypatch):
    """Slabs of random size with whole ticks and a partial tail (pending cycles)."""
    if reference:
        monkeypatch.setattr(fatigue_loops, "ticks_compiled", None)
    else:
        monkeypatch.undo()
    runs, tick_end, a = [], 10**9, 0
    while a < stress.shape[0]:
        b = min(stress.shape[0], a + int(rng.integers(1, 4000)))
        slab = stress[a:b]
        stops = np.unique(np.sort(rng.integers(0, slab.shape[0] + 1, int(rng.integers(0, 8)))))
        stops = stops.tolist()
        ends = [tick_end + 10**9 * i for i in range(len(stops))]
        tick_end += 10**9 * len(stops)
        runs.append(comp.run_ticks(slab, stops, ends))
        last = stops[-1] if stops else 0
        comp.feed(slab[last:])  # the open tick's samples: pending until its end
        a = b
    return runs


@pytest.mark.parametrize("hysteresis", [0.0, 1e5])
def test_compiled_ticks_equal_the_reference_loop_bit_for_bit(hysteresis, monkeypatch):
    rng = np.random.default_rng(3)
    # waves with noise, then a slowly converging oscillation: no cycle closes, so the
    # residue outgrows the initial stack storage (8192 points)
    t = np.arange(30_000)
    stress = 20e6 + 8e6 * np.sin(t / 9.0) + rng.normal(0, 5e5, t.size)
    i = np.arange(25_000)
    stress = np.concatenate([stress, 20e6 + (1e7 - 300.0 * i) * np.where(i % 2, 1.0, -1.0)])
    fast, ref = make(hysteresis), make(hysteresis)
    runs_fast = drive(fast, stress, np.random.default_rng(9), False, monkeypatch)
    runs_ref = drive(ref, stress, np.random.default_rng(9), True, monkeypatch)
    assert len(runs_fast) == len(runs_ref) > 10
    n_ticks = 0
    for a, b in zip(runs_fast, runs_ref):
        for x, y in zip(a.cycles, b.cycles):
            np.testing.assert_array_equal(x, y)
        assert a.figures == b.figures  # exact: damage, committed, rate, remaining life
        n_ticks += len(a.figures)
    assert n_ticks > 50
    assert json.dumps(fast.state()) == json.dumps(ref.state())
    assert fast.figures() == ref.figures()
    assert fast.miner.damage_committed > 0 and math.isfinite(fast.figures()["damage"])
    assert fast.rainflow._st.shape[0] > 5 + 4 * 2048  # the stack storage did grow


def test_compiled_ticks_continue_from_saved_state(monkeypatch):
    rng = np.random.default_rng(5)
    stress = 20e6 + 8e6 * np.sin(np.arange(8000) / 7.0) + rng.normal(0, 1e6, 8000)
    one = make()
    one.run_ticks(stress, [2000, 4000, 6000, 8000], [1, 2, 3, 4])
    two = make()
    two.run_ticks(stress[:3000], [2000], [1])
    two.feed(stress[2000:3000])
    two = make(state=json.loads(json.dumps(two.state())))
    two.run_ticks(stress[3000:], [1000, 3000, 5000], [2, 3, 4])
    assert json.dumps(one.state()) == json.dumps(two.state())


def test_bad_stress_counts_nothing():
    comp = make()
    before = json.dumps(comp.state())
    with pytest.raises(ValueError, match="NaN or inf"):
        comp.run_ticks(np.array([1e6, np.nan, 2e6]), [3], [1])
    assert json.dumps(comp.state()) == before


def test_remaining_life_is_zero_once_the_damage_passes_one():
    comp = make()
    swing = np.tile([0.0, 400e6], 2000)  # huge cycles: the copper conductors fail
    comp.feed(swing)
    fig = comp.figures()
    assert fig["damage"] > 1.0 and fig["damage_rate_per_day"] == 0.0
    assert fig["remaining_life_days"] == 0.0
    fresh = make().figures()
    assert fresh["damage"] == 0.0 and fresh["remaining_life_days"] == math.inf


def test_tick_figures_give_zero_life_once_the_damage_passes_one(monkeypatch):
    """The compiled tick pass and the reference loop agree past failure too."""
    swing = np.tile([0.0, 400e6], 2000)
    figures = []
    for reference in (False, True):
        if reference:
            monkeypatch.setattr(fatigue_loops, "ticks_compiled", None)
        comp = make()
        run = comp.run_ticks(swing, [1000, 2000, 4000], [10**9, 2 * 10**9, 3 * 10**9])
        figures.append(run.figures)
    assert figures[0] == figures[1]
    assert figures[0][-1][0] > 1.0 and figures[0][-1][3] == 0.0


@pytest.mark.parametrize("mean_stress", ["none", "goodman"])
def test_tick_ends_as_an_array_give_the_per_tick_feed_and_commit(mean_stress):
    """The pipeline hands the tick ends as an int64 array (seconds = ns / 1e9 vectorised):
    the figures and state equal feeding and committing tick by tick with Python ints, for
    the compiled pass and for a mean-corrected curve's per-tick path."""
    config = default_config()
    cfg = dataclasses.replace(config.components[0], mean_stress=mean_stress,
                              ultimate_Pa=None if mean_stress == "none" else 250e6)
    rng = np.random.default_rng(11)
    stress = 20e6 + 8e6 * np.sin(np.arange(9000) / 5.0) + rng.normal(0, 1e6, 9000)
    stops = [1500, 1500, 4000, 6500, 9000]
    ends = [1_700_000_000_123_456_789 + 10**10 * i for i in range(len(stops))]  # > 2**53
    fast = Component(cfg, build_cable(config), config.fatigue)
    run = fast.run_ticks(stress, stops, np.array(ends, np.int64))
    slow = Component(cfg, build_cable(config), config.fatigue)
    rows, start = [], 0
    for stop, end in zip(stops, ends):
        slow.feed(stress[start:stop])
        slow.commit(end)
        f = slow.figures()
        rows.append((f["damage"], f["damage_committed"], f["damage_rate_per_day"],
                     f["remaining_life_days"]))
        start = stop
    assert run.figures == rows and rows[-1][2] > 0.0
    assert json.dumps(fast.state()) == json.dumps(slow.state())


def test_components_of_the_same_stress_and_state_count_together():
    """The default conductor and its termination (no bend) count the same stress: the
    termination shares the conductor's counting, and feeding the conductor alone gives it
    the figures and state of a component fed on its own; a bend, another S-N factor or
    another counting state keeps them apart."""
    config = default_config()
    cable = build_cable(config)
    free, term = (Component(c, cable, config.fatigue) for c in config.components)
    alone = Component(config.components[1], cable, config.fatigue)
    assert term.count_with(free)
    rng = np.random.default_rng(4)
    stress = 20e6 + 8e6 * np.sin(np.arange(6000) / 7.0) + rng.normal(0, 1e6, 6000)
    for comp in (free, alone):
        comp.run_ticks(stress[:5000], [2000, 4000, 5000], [1, 2, 3])
        comp.feed(stress[5000:])
    assert term.figures() == alone.figures() and term.figures()["damage"] > 0
    assert json.dumps(term.state()) == json.dumps(alone.state())
    # a bend configured on both, which bends the termination only; another SCF
    bend = {"bend_radius_m": 0.5, "bend_angle_deg": 20.0}
    for a, b in ((dataclasses.replace(config.components[1], **bend),
                  dataclasses.replace(config.components[0], **bend)),
                 (dataclasses.replace(config.components[1], scf=1.2), config.components[0])):
        assert not Component(a, cable, config.fatigue).count_with(
            Component(b, cable, config.fatigue))
    assert not Component(config.components[1], cable, config.fatigue).count_with(free)


def test_a_pipeline_counting_twins_once_replays_as_counting_each(monkeypatch):
    """A pipeline of the default components (the termination counts with the conductor)
    gives the steps, report and state of one counting each on its own, through a state
    saved and restored mid-log."""
    from monitor.pipeline import Pipeline
    from synthetic_buoy import blocks_interleaved, sea

    config = default_config()
    blocks = blocks_interleaved(sea(900, gap=(300, 360)), 20)

    def replay() -> tuple[dict, str]:
        steps = []
        p = Pipeline(config)
        for b in blocks[:len(blocks) // 2]:
            steps.append(p.process(b))
        p = Pipeline(config, state=json.loads(json.dumps(p.state())))
        for b in blocks[len(blocks) // 2:]:
            steps.append(p.process(b))
        steps.append(p.flush())
        figures = [[(c.damage, c.damage_committed, c.damage_rate_per_day, c.remaining_life_days,
                     c.max_stress_Pa, c.stress_Pa.tolist(), c.ranges_Pa.tolist())
                    for c in step.components.values()] for step in steps]
        return p._counts_as, json.dumps([figures, p.report(), p.state()])
    shared, out = replay()
    monkeypatch.setattr(Component, "count_with", lambda self, other: False)
    assert shared == {"conductor_termination": "conductor"}
    assert replay() == ({}, out)
