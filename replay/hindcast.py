"""Hindcast through the pipeline: learn the damage-rate table from data, forecast the rest.

A sea-state sequence (e.g. the measured hourly NDBC 44007 records) drives the simulator:
each sea state gives ``sample_s`` of noise-free tension (:func:`replay.simulate.clean_tension`,
seed ``seed + index``), laid end to end in sensor time (one learning window each,
``[forecast] window_s = sample_s``), with a ``waves`` sample of its Hs and Tp at the window's
end. The pipeline learns the table as it would on the buoy. When the first ``half`` windows
are learned, the table is copied; the rest of the sequence is then forecast from its sea
states alone with that table (learned bins, the physics model's rate elsewhere,
:func:`replay.cmd_forecast.fill_model_rates`) and compared with the damage the pipeline goes
on to commit over those windows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from models.sea_state_table import DamageRateTable, project_damage
from monitor.blocks import SampleBlock
from monitor.config import Config, config_with
from monitor.pipeline import Pipeline
from replay.cmd_forecast import fill_model_rates
from replay.sea_state_files import SeaStates
from replay.simulate import BASE_HZ, SimConfig, clean_tension

_T0_NS = 946_684_800 * 10**9  # 2000-01-01 UTC: on every window grid


@dataclass(frozen=True)
class Hindcast:
    """Per component: the forecast damage of the second part with its band, and the damage
    the pipeline committed over it; the share of forecast steps rated from learned bins."""

    components: tuple[str, ...]
    forecast: NDArray[np.float64]
    low: NDArray[np.float64]
    high: NDArray[np.float64]
    actual: NDArray[np.float64]
    learned_share: NDArray[np.float64]
    windows: int


def pipeline_hindcast(config: Config, states: SeaStates, half: int, sample_s: float = 300.0,
                      min_hours: float = 0.25, seed: int = 0,
                      load_model: str = "wavfor") -> Hindcast:
    """See the module docstring; ``states`` with Hs > 0 throughout, ``half`` < its length."""
    if not 0 < half < len(states) or np.any(states.hs_m <= 0):
        raise ValueError("hindcast: need 0 < half < len(states) and Hs > 0 throughout")
    prior = {k: v for k, v in config.section("forecast").items() if k != "table"}
    cfg = config_with(config, forecast={**prior, "window_s": sample_s, "min_hours": min_hours})
    p = Pipeline(cfg, horizon_s=cfg.ordering.replay_horizon_s)
    learner = p.sea_states
    if learner is None:
        raise ValueError("hindcast: [forecast] enabled = false in the configuration")
    w_ns = int(round(sample_s * 1e9))
    n = int(round(sample_s * BASE_HZ))
    trained: DamageRateTable | None = None
    at_half = 0.0
    for k in range(len(states)):
        tension = clean_tension(SimConfig(hours=sample_s / 3600.0, hs_m=float(states.hs_m[k]),
                                          tp_s=float(states.tp_s[k]), seed=seed + k,
                                          depth_m=cfg.mooring.depth_m, load_model=load_model))
        end = _T0_NS + (k + 1) * w_ns
        t = end - w_ns + (np.arange(n, dtype=np.int64) + 1) * (10**9 // BASE_HZ)
        p.process(SampleBlock(cfg.buoy.id, "tension", t, {"tension_N": tension}, end))
        p.process(SampleBlock(cfg.buoy.id, "waves", np.array([end], np.int64),
                              {"hs_m": states.hs_m[k:k + 1], "tp_s": states.tp_s[k:k + 1]}, end))
        if trained is None and learner.counts["windows"] >= half:
            trained = DamageRateTable.from_state(learner.table.to_state())
            at_half = learner.counts["windows"]
    p.flush()
    assert trained is not None  # half < len(states) windows close before the flush ends
    start = int(at_half)  # windows (= sea states) from here on are forecast
    rest = SeaStates(states.t_s[start:], states.hs_m[start:], states.tp_s[start:],
                     states.direction_deg[start:])
    fill_model_rates(trained, cfg, rest, load_model)
    rates = trained.rates(rest.hs_m, rest.tp_s)
    proj = project_damage(rest.t_s, np.full(len(rest), sample_s / 3600.0), rates,
                          [0.0] * len(trained.components))
    actual = learner.table.damage.sum(axis=(1, 2)) - trained.damage.sum(axis=(1, 2))
    return Hindcast(trained.components, proj.damage[:, -1], proj.low[:, -1], proj.high[:, -1],
                    actual, (rates.source == "learned").mean(axis=1),
                    int(learner.counts["windows"]))
