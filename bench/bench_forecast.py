"""Forecast benchmarks: a year of hourly forecasts, and the hindcast of a measured year.

Measured on the 2-core development machine (Xeon, 24 GiB), 2026-11-24:

- evaluating a year (8,766 hourly steps) of forecast against a filled damage-rate table
  (rates + projection with two thresholds): see the printed figure (target < 1 s);
- hindcast: the 1996 sea states of NDBC 44007 (Gulf of Maine, measured, hourly): every hour
  simulated for 5 minutes with the simulator's WAVFOR load model through the shipped
  configuration's conductor component ("what the monitor measures"); the table learned on
  the first half, the second half forecast from its sea states alone; printed: forecast and
  actual damage of the second half and their ratio (target within 20 %);
- hindcast through the pipeline (replay/hindcast.py): the first 90 days of 1996, five
  simulated minutes per hourly sea state laid end to end, the table learned by the pipeline
  from the tension and waves streams on the first half, the second half forecast and
  compared with the damage the pipeline committed (target within 20 %).

Measured 2026-11-25, same machine: pipeline hindcast see docs/FORECAST.md.

Run: ``python bench/bench_forecast.py``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from models.sea_state_table import HS_EDGES_M, TP_EDGES_S, DamageRateTable, project_damage
from monitor.config import default_config
from replay.cmd_forecast import fill_model_rates
from replay.hindcast import pipeline_hindcast
from replay.sea_state_damage import physics_damage
from replay.sea_state_files import SeaStates, read_sea_states

REPO = Path(__file__).resolve().parents[1]
SHARED = next((p / "shared" for p in REPO.parents if (p / "shared/realdata").is_dir()),
              REPO.parent / "shared")
NDBC = SHARED / "realdata" / "ndbc44007_ecbenchmarkA" / "ec-benchmark_dataset_A.txt"
PIPELINE_DAYS = 90  # the hindcast through the pipeline: the first 90 days of 1996


def main() -> None:
    config = default_config()
    s = read_sea_states(NDBC)
    year = s.t_s < s.t_s[0] + 365.25 * 86400
    hs, tp, t = s.hs_m[year], s.tp_s[year], s.t_s[year]
    n = hs.size
    t0 = time.perf_counter()
    measured = physics_damage(config, hs, tp, duration_s=300.0, seed=7).rainflow_per_hour[0]
    sim_s = time.perf_counter() - t0
    half = n // 2
    table = DamageRateTable(["conductor"], HS_EDGES_M, TP_EDGES_S)
    for k in range(half):
        table.learn(float(hs[k]), float(tp[k]), 1.0, [measured[k]])
    second = SeaStates(t[half:], hs[half:], tp[half:], np.full(n - half, np.nan))
    fill_model_rates(table, config, second, "wavfor")
    rates = table.rates(second.hs_m, second.tp_s)
    proj = project_damage(second.t_s, np.ones(n - half), rates, [0.0])
    actual = float(measured[half:].sum())
    forecast = float(proj.damage[0, -1])
    print(f"hindcast NDBC 44007, {n:,} hourly sea states ({sim_s:.1f} s to simulate them)")
    print(f"  second half: forecast damage {forecast:.4g} (band {proj.low[0, -1]:.4g} to "
          f"{proj.high[0, -1]:.4g}), actual {actual:.4g}, ratio {forecast / actual:.3f}; "
          f"{(rates.source[0] == 'learned').mean():.0%} of the hours from learned bins")
    # a year of hourly forecasts against the filled table
    year_states = SeaStates(t, hs, tp, np.full(n, np.nan))
    fill_model_rates(table, config, year_states, "wavfor")
    best = float("inf")
    for _ in range(5):
        t0 = time.perf_counter()
        r = table.rates(year_states.hs_m, year_states.tp_s)
        project_damage(year_states.t_s, year_states.step_hours(), r, [0.0], [0.1, 0.5])
        best = min(best, time.perf_counter() - t0)
    print(f"  a year of hourly forecast steps ({n:,}) evaluated in {best * 1e3:.1f} ms")
    # the same through the pipeline: the table learned from the data stream
    m = 24 * PIPELINE_DAYS
    t0 = time.perf_counter()
    h = pipeline_hindcast(config, SeaStates(t[:m], hs[:m], tp[:m], np.full(m, np.nan)),
                          half=m // 2, seed=7)
    print(f"hindcast through the pipeline, first {PIPELINE_DAYS} days ({m:,} sea states, "
          f"{time.perf_counter() - t0:.1f} s): second half forecast {h.forecast[0]:.4g} (band "
          f"{h.low[0]:.4g} to {h.high[0]:.4g}), committed {h.actual[0]:.4g}, ratio "
          f"{h.forecast[0] / h.actual[0]:.3f}; {h.learned_share[0]:.0%} of the steps from "
          "learned bins")


if __name__ == "__main__":
    main()
