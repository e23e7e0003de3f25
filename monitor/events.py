"""What the pipeline core emits after each block, and the sink interface that receives it.

The data flow is: source -> decode -> :class:`~monitor.blocks.SampleBlock` -> pipeline core
(validate -> load -> stress -> rainflow -> damage -> alerts) -> :class:`StepResult` -> sinks.
Sinks (Rerun, MCAP recorder, Zenoh publisher, report builder) only read these objects; they
never change pipeline state, so adding or removing a sink cannot change damage or alerts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Protocol

import numpy as np


@dataclass(frozen=True, eq=False)
class ComponentStep:
    """One fatigue component (e.g. the conductors with a given lay) after one step.

    ``stress_Pa`` is the stress series computed from this step's load samples; ``ranges_Pa``,
    ``means_Pa`` and ``counts`` are the rainflow cycles CLOSED by this step (counts 1.0 or 0.5).
    Damage figures are totals after the step.
    """

    name: str
    stress_Pa: np.ndarray
    ranges_Pa: np.ndarray
    means_Pa: np.ndarray
    counts: np.ndarray
    damage: float
    damage_committed: float
    damage_rate_per_day: float
    remaining_life_days: float
    max_stress_Pa: float


@dataclass(frozen=True, eq=False)
class StepResult:
    """Everything one processed block produced.

    Attributes:
        buoy_id: the buoy.
        sensor: the stream the block came from.
        now_ns: sensor time the pipeline has reached after this step.
        t_ns: times of the load samples used for fatigue in this step (may be empty, e.g. for a
            GNSS block while the measured tension is the load source).
        tension_N: load samples used for fatigue (measured or estimated), same length as t_ns.
        load_source: ``"measured"``, ``"estimated"`` or ``"none"``.
        measured_tension_N / estimated_tension_N: latest values (NaN when unavailable).
        components: per-component results, keyed by component name.
        accepted / rejected: samples of this block accepted, and rejected by reason.
        alerts: alert transitions raised by this step (see :mod:`monitor.alerts`).
        windows: sea-state windows closed by this step (``[forecast]``,
            :mod:`monitor.sea_state_learner`): end time, sea state, rainflow and Dirlik
            damage per component, the components flagged.
        forecasts: forecast projections applied in this step (:mod:`monitor.forecast`):
            applied time, and per component the damage now and at the forecast's end with
            its band, and when ``[forecast] alert_damage`` is reached.
        qc: QARTOD flag totals of the streams this step processed,
            ``{sensor: {test: {"suspect": n, "fail": n}}}`` (see :mod:`monitor.qartod`); filled
            only when a sink has ``wants_qc = True``.
    """

    buoy_id: str
    sensor: str
    now_ns: int
    t_ns: np.ndarray
    tension_N: np.ndarray
    load_source: str
    measured_tension_N: float
    estimated_tension_N: float
    components: Mapping[str, ComponentStep]
    accepted: int
    rejected: Mapping[str, int]
    alerts: list[Any] = field(default_factory=list)
    windows: list[dict[str, Any]] = field(default_factory=list)
    forecasts: list[dict[str, Any]] = field(default_factory=list)
    qc: Mapping[str, Mapping[str, Mapping[str, int]]] = field(default_factory=dict)


class Sink(Protocol):
    """Receives pipeline output. Must not raise on ordinary data; must not block for long."""

    def on_step(self, step: StepResult) -> None: ...

    def close(self) -> None: ...


# The per-tick observation classes below are built at every alert tick: plain dataclasses
# with slots (a frozen one pays an object.__setattr__ per field). Consumers only read them.
@dataclass(slots=True, eq=False)
class ComponentObs:
    """One component's fatigue figures at the end of an alert-evaluation tick."""

    damage: float
    damage_committed: float
    damage_rate_per_day: float
    remaining_life_days: float
    max_stress_Pa: float  # maximum conductor stress within the tick (NaN if no samples)


@dataclass(slots=True, eq=False)
class StreamObs:
    """Health of one sensor stream at the end of a tick (counters are totals since start)."""

    last_t_ns: int  # sensor time of the newest accepted sample, 0 if none yet
    stale: bool  # no accepted sample for longer than the stream's stale_after_s
    accepted: int
    rejected: Mapping[str, int]  # reason -> count
    rejected_in_tick: int
    received_in_tick: int


@dataclass(slots=True, eq=False)
class Observation:
    """Input of one alert evaluation.

    The pipeline evaluates alerts on a fixed sensor-time grid (ticks at whole multiples of
    ``[alerts] eval_interval_s`` since the epoch), whatever the block sizes: a tick is
    evaluated once every stream's data up to its end has been processed. So live ingest in
    1-s blocks and replay in large blocks give the same alert history.

    ``t_ns`` is the tick's end. ``load_t_ns``/``tension_N`` are the load samples used for
    fatigue inside the tick (measured or estimated, in time order).
    """

    buoy_id: str
    t_ns: int
    tick_s: float
    load_source: str
    load_t_ns: np.ndarray
    tension_N: np.ndarray
    measured_tension_N: float  # mean of measured tension in the tick (NaN if none)
    # mean of the motion estimate in the tick: over every motion sample when a model_residual
    # rule is configured, else over the samples that fed fatigue (NaN if none)
    estimated_tension_N: float
    components: Mapping[str, ComponentObs]
    streams: Mapping[str, StreamObs]
    # (min, max) of tension_N when the producer has it already (NaN if no samples)
    tension_range_N: tuple[float, float] | None = None
