"""One S-N damage per cycle on every path: ``SNCurve.damage_per_cycle``, the Miner
accumulator's compiled and uncompiled commits, its mean-corrected commit, the residue damage
and a component's figures give the same bits for the same cycle (issue 18: two of three
former formulas differed in the last bits for 98.5 % of 200,000 random ranges).

The oracle (``fatigue_oracles.damage_oracle``) is the formula evaluated independently with
numpy: segment by ``searchsorted``, then exp(m ln S + ln(dff / a)) with the compiled loops'
log and exp applied to arrays (``models.fatigue._loops.log_det``/``exp_det`` are plain numpy
there).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fatigue_oracles import damage_oracle, sequential_sum
from models.fatigue import MinerAccumulator, SNCurve, StreamingRainflow
from models.fatigue._loops import damage_loop
from monitor.components import Component, build_cable
from monitor.config import default_config

N = 200_000
CURVES = {
    "copper_haibach": SNCurve.vaps_copper(),
    "copper_cutoff": SNCurve.vaps_copper("cutoff", derating=2.0, scf=1.3),
    "dnv_d_seawater": SNCurve.dnv_rp_c203("D", "seawater_cp", dff=3.0, scf=1.1),
    "chain": SNCurve.dnv_chain_studless(),
}


@pytest.fixture(scope="module")
def cycles():
    rng = np.random.default_rng(18)
    ranges = rng.uniform(0.0, 120e6, N)
    ranges[:50] = 0.0  # zero range: no damage on every path
    counts = np.where(rng.random(N) < 0.1, 0.5, 1.0)
    means = rng.uniform(-30e6, 60e6, N)
    return ranges, means, counts


@pytest.mark.parametrize("name", sorted(CURVES))
def test_every_path_gives_the_same_bits(name, cycles, monkeypatch):
    curve = CURVES[name]
    ranges, means, counts = cycles
    d = curve.damage_per_cycle(ranges, None, counts)
    # the formula, evaluated independently: every one of 200,000 cycles to the last bit
    np.testing.assert_array_equal(d, damage_oracle(curve, ranges, None, counts))
    assert np.count_nonzero(d) > N // 2 and np.all(d[:50] == 0.0)
    # the uncompiled loop (numba is optional) is the same code, hence the same bits
    np.testing.assert_array_equal(damage_loop(ranges[:3000] * curve.kernel_params[0], counts[:3000],
                                              curve._mpa_params), d[:3000])
    # committed Miner sums: each cycle's damage added in order
    miner = MinerAccumulator(curve)
    assert miner.add_cycles(ranges, None, counts) == sequential_sum(0.0, d)
    assert miner.damage_committed == sequential_sum(0.0, d)
    with monkeypatch.context() as patch:  # the uncompiled loop (on a part: it is slow)
        patch.setattr("models.fatigue._loops.commit_compiled", None)
        miner = MinerAccumulator(curve)
        assert miner.add_cycles(ranges[:3000], None, counts[:3000]) == sequential_sum(0.0, d[:3000])
    # one cycle per accumulator: the committed figure is the cycle's damage itself
    for i in range(0, N, 997):
        miner = MinerAccumulator(curve)
        miner.add_cycles(ranges[i:i + 1], None, counts[i:i + 1])
        assert miner.damage_committed == d[i]


def test_mean_corrected_paths_give_the_same_bits(cycles):
    curve = SNCurve.vaps_copper(mean_correction="goodman", ultimate_Pa=220e6)
    ranges, means, counts = cycles
    d = curve.damage_per_cycle(ranges, means, counts)
    np.testing.assert_array_equal(d, damage_oracle(curve, ranges, means, counts))
    assert d.max() > 0 and np.count_nonzero(d) > N // 2
    miner = MinerAccumulator(curve)
    miner.add_cycles(ranges, means, counts)
    assert miner.damage_committed == sequential_sum(0.0, d)


@pytest.mark.parametrize("name", sorted(CURVES) + ["goodman"])
def test_residue_damage_is_the_per_cycle_damage_summed(name):
    """The compiled residue pass (mean-free curves) and the counted residue through
    ``damage_per_cycle`` (mean-corrected ones) both give the per-cycle damage summed."""
    curve = CURVES.get(name) or SNCurve.vaps_copper(mean_correction="goodman", ultimate_Pa=220e6)
    rf = StreamingRainflow()
    rng = np.random.default_rng(5)
    # a growing then decaying swing stays open: a long residue
    amp = np.concatenate((np.linspace(1.0, 60.0, 60), np.linspace(60.0, 1.0, 60))) * 1e6
    rf.feed(amp * (-1.0) ** np.arange(amp.size) + rng.uniform(0.0, 0.4e6, amp.size))
    r, m, c = rf.residue_half_cycles()
    assert r.size > 100
    want = float(np.cumsum(curve.damage_per_cycle(r, m, c))[-1])
    assert want > 0
    assert MinerAccumulator(curve).residue_damage(rf) == want


def test_component_figures_price_pending_cycles_as_the_commit_does():
    """Figures read between ticks add the pending cycles, each cycle's damage the bits the
    commit at the tick end gives it (one S-N function; before issue 18 a second formula)."""
    config = default_config()
    comp = Component(dataclasses.replace(config.components[0]), build_cable(config), config.fatigue)
    rng = np.random.default_rng(9)
    tension = 6e3 + np.cumsum(rng.normal(0.0, 300.0, 40_000))
    stress = comp.stress(np.abs(tension))
    comp.feed(stress[:20_000])
    comp.commit(10**9)
    comp.feed(stress[20_000:])
    ranges, means, counts = comp._pending
    assert ranges.size > 100
    d = damage_oracle(comp.sn_curve, ranges, means, counts)
    assert comp.figures()["damage_committed"] == comp.miner.damage_committed + float(np.sum(d))
    for i in range(0, ranges.size, 7):  # each pending cycle, committed on its own
        miner = MinerAccumulator(comp.sn_curve)
        miner.add_cycles(ranges[i:i + 1], means[i:i + 1], counts[i:i + 1])
        assert miner.damage_committed == d[i]
