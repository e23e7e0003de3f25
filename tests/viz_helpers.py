"""Shared test helpers for the viz tests: synthetic pipeline steps and reading an .rrd back."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from rerun.chunk import RrdReader

from monitor.events import ComponentStep, StepResult

T0_NS = 1_700_000_000_000_000_000  # 2023-11-14T22:13:20Z
RATE_HZ = 20
STRESS_PER_N = {"left": 2000.0, "right": 1000.0}  # Pa per N of tension, per component


def make_steps(n_steps: int, block_s: float = 1.0, seed: int = 1) -> list[StepResult]:
    """Blocks of a noisy 0.2 Hz tension swell with known stress, cycles and damage per step."""
    rng = np.random.default_rng(seed)
    n = int(round(block_s * RATE_HZ))
    steps = []
    damage = {c: 0.0 for c in STRESS_PER_N}
    for k in range(n_steps):
        i = np.arange(k * n, (k + 1) * n)
        t = T0_NS + i * (1_000_000_000 // RATE_HZ)
        tension = 5000.0 + 1500.0 * np.sin(2 * np.pi * 0.2 * i / RATE_HZ) + rng.normal(0, 50, n)
        comps = {}
        for name, k_pa in STRESS_PER_N.items():
            ranges = np.array([3000.0 * k_pa, 400.0 * k_pa]) * (1 + 0.1 * (k % 7))
            means = np.array([5000.0 * k_pa, 4800.0 * k_pa])
            counts = np.array([1.0, 0.5])
            damage[name] += 1e-6 * (k_pa / 1000.0)
            comps[name] = ComponentStep(
                name=name, stress_Pa=tension * k_pa, ranges_Pa=ranges, means_Pa=means,
                counts=counts, damage=damage[name] * 1.1, damage_committed=damage[name],
                damage_rate_per_day=0.0864 * k_pa / 1000.0,
                remaining_life_days=1e4 / (k + 1), max_stress_Pa=float(tension.max() * k_pa))
        steps.append(StepResult(
            buoy_id="B1", sensor="tension", now_ns=int(t[-1]), t_ns=t.astype(np.int64),
            tension_N=tension, load_source="measured", measured_tension_N=float(tension[-1]),
            estimated_tension_N=float("nan"), components=comps, accepted=n,
            rejected={"spike": k % 2}, alerts=[]))
    return steps


def read_rrd(path: str | Path) -> dict[str, dict[str, list[Any]]]:
    """{entity: {column: values}} of the recording in an .rrd, rows sorted by (time, sample)
    within each entity; static rows have no time and come first."""
    rows: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch().to_pydict()
        names = [c for c in batch if c != "rerun.controls.RowId"]
        for r in range(chunk.num_rows):
            rows[chunk.entity_path.lstrip("/")].append({c: batch[c][r] for c in names})

    def key(row: dict[str, Any]) -> tuple:
        t = row.get("sensor_time")
        return (t is not None, t.value if hasattr(t, "value") else (t or 0), row.get("sample") or 0)

    out: dict[str, dict[str, list[Any]]] = {}
    for entity, rs in rows.items():
        rs.sort(key=key)
        cols: dict[str, list[Any]] = defaultdict(list)
        for row in rs:
            for c, v in row.items():
                cols[c].append(v)
        out[entity] = dict(cols)
    return out


def ns(value: Any) -> int:
    """A timestamp read back from arrow (pandas/np/datetime) as int ns since the epoch."""
    if hasattr(value, "value"):
        return int(value.value)
    return int(np.datetime64(value, "ns").astype(np.int64))
