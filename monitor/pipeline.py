"""The pipeline core shared by ``buoymon replay`` and the daemon.

``Pipeline.process(block)`` takes :class:`~monitor.blocks.SampleBlock` objects of one buoy in
any interleaving and block size and runs, on sensor time only::

    ordering (watermark slabs) -> validate -> motion estimate -> load source ->
    stress per component -> streaming rainflow -> Miner damage (per alert tick) ->
    alert rules on the fixed tick grid -> StepResult to the sinks

Determinism: every stage is a function of the samples in time order with its memory carried
across blocks (see monitor.ordering, monitor.validate, monitor.load_source,
monitor.components), so the same samples give the same committed damage and alert history
whichever driver cuts them into blocks. ``state()`` is complete and JSON-serialisable;
``Pipeline(config, state=s)`` continues exactly where ``s`` was taken.

Stages: ``process`` is a stream stage (``ingest``: ordering to stresses) handing each slab
(:class:`SlabIntake`) to a tick stage (``advance``: rainflow to sinks), each stage owning its
state; ``process`` runs them in turn, and replay.stages can run the stream stage ahead on
another thread with the same results to the bit. ``state()`` is taken between slabs.

Alert ticks: tick ``k`` covers sensor time ``((k-1) I, k I]`` with ``I = [alerts]
eval_interval_s``. A tick is evaluated once the ordering watermark has passed its end (or, at
``flush()``, once the slowest stream's data has); the trailing partial tick of a log waits for
data that would complete it, so a log replayed in parts gives the same history as one pass.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, NamedTuple, Protocol, Sequence, TypeVar

import numpy as np

from models.sea_state_table import DamageRateTable
from monitor.alerts.batch import StreamTicks, TickInputs, warm_up as alert_batch_warm_up
from monitor.blocks import SENSOR_FIELDS, SampleBlock
from monitor.components import Component, TickRun, build_cable, endurance_stress_Pa
from monitor.config import Config, ConfigError
from monitor.damage_split import DamageSplit
from monitor.events import ComponentObs, ComponentStep, Observation, Sink, StepResult, StreamObs
from monitor.forecast import ForecastAlerts, parse_forecast, refuse_expired
from monitor.late_copies import LateCopies
from monitor.load_source import MEASURED, SOURCE_NAMES, LoadSelector, build_estimator
from monitor.motion_rate import rate_problems
from monitor.ordering import SENSOR_ORDER, ReorderBuffer
from monitor.qartod import StreamQC
from monitor.sea_state_learner import SeaStateLearner
from monitor.stats_kernel import load_stats_pass
from monitor.time_ahead import drop_ahead
from monitor.validate import REASONS, StreamValidator

MOTION_SENSORS = ("imu", "motion")  # the streams a motion estimator can use
# what the sea-state learner takes of each stream (SeaStateLearner.<stream>)
_SEA_STATE_FIELDS = {"waves": ("hs_m", "tp_s"), "motion": ("heave_m",), "imu": ("accel_z_mps2",)}

STATE_VERSION = 1
ALERT_HISTORY_LIMIT = 10_000  # alert transitions kept for the report (oldest dropped first)
_T = TypeVar("_T")
_NEVER = np.iinfo(np.int64).min
# at least this much of a gap without samples is evaluated tick by tick, from its last sample
# in whatever slab (Pipeline._tick_ends)
_EMPTY_SPAN_S = 3600.0
# slabs of fewer ticks (live ingest: one or two) are evaluated tick by tick: the alert batch
# costs about 0.3 ms a slab to set up, some 20 ticks' worth of the per-tick path
BATCH_MIN_TICKS = 16


class AlertEngineLike(Protocol):
    """What the pipeline needs from monitor.alerts.engine.AlertEngine."""

    def evaluate(self, obs: Observation) -> list[Any]: ...

    def state(self) -> dict[str, Any]: ...


def build_alert_engine(config: Config, buoy_id: str, endurance_Pa: Mapping[str, float | None],
                       state: Mapping[str, Any] | None,
                       yield_Pa: Mapping[str, float | None] | None = None) -> AlertEngineLike:
    """The ``[alerts]`` rules engine, restored from ``state`` if given.

    ``endurance_Pa`` maps each component to its derated endurance stress (None if it has none),
    ``yield_Pa`` to the nominal stress at which its hot spot yields (None if it has none).
    """
    from monitor.alerts.engine import AlertEngine

    components = {name: {"endurance_stress_Pa": e, "yield_stress_Pa": (yield_Pa or {}).get(name)}
                  for name, e in endurance_Pa.items()}
    if state:
        return AlertEngine.from_state(state, config.alerts, buoy_id, components)
    return AlertEngine.from_config(config.alerts, buoy_id, components)


def alert_to_dict(record: Any) -> dict[str, Any]:
    if hasattr(record, "to_dict"):
        return record.to_dict()
    if dataclasses.is_dataclass(record) and not isinstance(record, type):
        return dataclasses.asdict(record)
    return dict(record)


# no load samples: (t_ns, tension_N, source); shared, never written to
_NO_LOAD = (np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int8))


class _TickLists(NamedTuple):
    """:class:`_TickLoad`'s figures as Python numbers, for the tick-by-tick path."""

    vmax: list[float]
    vmin: list[float]
    smax: dict[str, list[float]]
    n: list[int]
    n_meas: list[int]
    meas: list[float]
    est: list[float]


class _TickLoad:
    """Per-tick load figures of consecutive ticks in one pass, as arrays over the ticks (and
    as lists, :attr:`lists`, when a tick is evaluated on its own): max and min tension, the
    mean of each source, each component's peak stress. Tick ``k`` covers samples
    ``[starts[k], stops[k])``; every tick is reduced the same way (a sum is one
    ``np.add.reduceat`` segment: the first sample plus numpy's pairwise sum of the rest, the
    same bits wherever the segment starts), whichever slab it came in."""

    def __init__(self, v: np.ndarray, src: np.ndarray, stresses: Mapping[str, np.ndarray],
                 starts: np.ndarray, stops: np.ndarray) -> None:
        n = stops - starts
        every = bool(n.all())  # (the usual slab: no tick without samples)
        full = None if every else np.flatnonzero(n)

        def per_tick(values: np.ndarray, empty: float = math.nan) -> np.ndarray:
            """The non-empty ticks' values over all ticks."""
            if every:
                return values
            out = np.full(n.shape[0], empty, dtype=values.dtype)
            out[full] = values
            return out

        # the non-empty ticks are back to back: reduce over their span in one call each
        at, count = (starts, n) if full is None else (starts[full], n[full])
        span = slice(0, int(stops[-1] if full is None else stops[full[-1]]) if at.shape[0] else 0)
        self.vmax = per_tick(np.maximum.reduceat(v[span], at))
        self.vmin = per_tick(np.minimum.reduceat(v[span], at))
        peaks: dict[int, np.ndarray] = {}  # per stress array (components may share one)
        self.smax = {}
        for name, s in stresses.items():
            if id(s) not in peaks:
                peaks[id(s)] = per_tick(np.maximum.reduceat(s[span], at))
            self.smax[name] = peaks[id(s)]
        measured = src[span] == MEASURED
        mean = np.add.reduceat(v[span], at) / count
        self.n = n  # samples, and of them measured (n_meas)
        if measured.all():  # one source, the load cell (the usual case)
            self.n_meas, self.meas = per_tick(count, 0), per_tick(mean)
            self.est = np.full(n.shape[0], math.nan)
            return
        n_meas = np.add.reduceat(measured, at, dtype=np.int64)
        self.n_meas = per_tick(n_meas, 0)
        # a tick of one source (the usual case): the mean of its samples is that source's
        self.meas = per_tick(np.where(n_meas == count, mean, math.nan))
        self.est = per_tick(np.where(n_meas == 0, mean, math.nan))
        mixed = np.flatnonzero((n_meas != count) & (n_meas != 0))
        for i in (mixed if full is None else full[mixed]).tolist():
            a, b = int(starts[i]), int(stops[i])
            self.meas[i] = _seq_mean(v[a:b][measured[a:b]])
            self.est[i] = _seq_mean(v[a:b][~measured[a:b]])

    @functools.cached_property
    def lists(self) -> _TickLists:
        return _TickLists(self.vmax.tolist(), self.vmin.tolist(),
                          {name: s.tolist() for name, s in self.smax.items()},
                          self.n.tolist(), self.n_meas.tolist(), self.meas.tolist(),
                          self.est.tolist())


def _joined(parts: Sequence[np.ndarray]) -> np.ndarray:
    """The arrays end to end: the only non-empty one itself (the cycles a slab closed come
    in fresh arrays that nothing writes to), else a new one."""
    full = [p for p in parts if p.shape[0]]
    return full[0] if len(full) == 1 else np.concatenate(parts)


def _seq_mean(x: np.ndarray) -> float:
    """Mean by one ``np.add.reduceat`` segment, as ``_TickLoad`` reduces whole ticks (NaN if
    empty)."""
    return float(np.add.reduceat(x, [0])[0]) / x.shape[0] if x.shape[0] else math.nan


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


class _TensionStats:
    """Streaming min/mean/max/p99 of the fatigue load on a fixed histogram (flat memory)."""

    BINS = 65536

    def __init__(self, lo: float, hi: float, state: Mapping[str, Any] | None = None) -> None:
        self.lo, self.hi = lo, hi
        self.width = (hi - lo) / self.BINS
        self.hist = np.zeros(self.BINS, dtype=np.int64)
        self.n = {"measured": 0, "estimated": 0}
        self.total_mN = 0  # exact integer sum (millinewtons): the mean is split-invariant
        self.min = math.inf
        self.max = -math.inf
        if state is not None:
            idx, counts = state["hist"]
            self.hist[np.array(idx, dtype=np.int64)] = np.array(counts, dtype=np.int64)
            self.n = dict(state["n"])
            self.total_mN = int(state["total_mN"])
            self.min = math.inf if state["min"] is None else float(state["min"])
            self.max = -math.inf if state["max"] is None else float(state["max"])

    def add(self, v: np.ndarray, src: np.ndarray) -> None:
        if v.shape[0] == 0:
            return
        finite, n_meas, total, vmin, vmax = load_stats_pass(v, src, MEASURED, self.lo,
                                                            self.width, self.hist)
        if finite:  # the usual case, in one compiled pass
            self.n["measured"] += n_meas
            self.n["estimated"] += v.shape[0] - n_meas
            self.total_mN += int(total)
            self.min = min(self.min, float(vmin))
            self.max = max(self.max, float(vmax))
            return
        bins = np.clip(((v - self.lo) / self.width).astype(np.int64), 0, self.BINS - 1)
        first = int(bins.min())  # count over the occupied range only: blocks are small
        counts = np.bincount(bins - first)
        self.hist[first:first + counts.shape[0]] += counts
        n_meas = int(np.count_nonzero(src == MEASURED))
        self.n["measured"] += n_meas
        self.n["estimated"] += v.shape[0] - n_meas
        self.total_mN += int(np.rint(v * 1e3).astype(np.int64).sum())
        self.min = min(self.min, float(v.min()))
        self.max = max(self.max, float(v.max()))

    def summary(self) -> dict[str, Any]:
        count = self.n["measured"] + self.n["estimated"]
        if count == 0:
            return {"min": None, "mean": None, "max": None, "p99": None,
                    "samples_measured": 0, "samples_estimated": 0}
        k = int(np.searchsorted(np.cumsum(self.hist), math.ceil(0.99 * count)))
        p99 = min(max(self.lo + (k + 0.5) * self.width, self.min), self.max)
        return {"min": self.min, "mean": self.total_mN / 1e3 / count, "max": self.max, "p99": p99,
                "samples_measured": self.n["measured"], "samples_estimated": self.n["estimated"]}

    def state(self) -> dict[str, Any]:
        idx = np.flatnonzero(self.hist)
        return {"hist": [idx.tolist(), self.hist[idx].tolist()], "n": dict(self.n),
                "total_mN": self.total_mN, "min": _finite_or_none(self.min),
                "max": _finite_or_none(self.max)}


_DUP_CODE = REASONS.index("duplicate") + 1  # StreamValidator.check's verdict of a copy


class _StreamSlab:
    """One stream's share of a slab with its verdicts, and its health at each tick end."""

    # the health at the tick ends of the last prepare(), made when first read (only the
    # streams a rule looks at are): arrays (tick_arrays), and lists for tick() (the batch
    # path evaluates few ticks the ordinary way)
    _arrays: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None
    has_all: bool  # (with _arrays) a sample accepted by every tick end: has is all True
    _ticks: tuple[list[int], list[int], list[int], list[bool], list[int], list[list[int]] | None] | None

    def __init__(self, t: np.ndarray, values: np.ndarray, codes: np.ndarray,
                 validator_before: tuple[int, dict[str, int], bool, int],
                 verdicts: bool) -> None:
        """``verdicts``: ``codes.any()`` (some sample not accepted)."""
        self.t, self.codes = t, codes
        if verdicts:
            ok = codes == 0
            # a copy (a duplicate verdict) is no measurement: neither received nor rejected
            # in a tick's counts (the rejected_rate rule), only in the duplicate total
            copy = codes == _DUP_CODE
            self.acc_t, self.acc_values = t[ok], values[:, ok]
            self.rx_t, self.rej_t = t[~copy], t[~(ok | copy)]
        else:  # the usual case: no rejections
            self.acc_t, self.acc_values, self.rx_t, self.rej_t = t, values, t, t[:0]
        self._before = validator_before

    @staticmethod
    def before(v: StreamValidator) -> tuple[int, dict[str, int], bool, int]:
        return v.accepted, dict(v.rejected), v.has_last, v.last_t_ns

    def counts_after(self, lo: int) -> tuple[int, int]:
        """Samples received (copies aside) and rejected with time after ``lo``."""
        rx, rej = self.rx_t, self.rej_t
        return (rx.shape[0] - int(np.searchsorted(rx, lo, side="right")),
                rej.shape[0] - int(np.searchsorted(rej, lo, side="right")) if rej.shape[0] else 0)

    def prepare(self, ends: np.ndarray) -> None:
        """Health at every tick end of this slab (counts and last time) from now on."""
        self._ends, self._arrays, self._ticks = ends, None, None

    @property
    def tick_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per prepared tick end: samples received and rejected in the tick, whether a sample
        was ever accepted, the last accepted time (vectorised)."""
        if self._arrays is None:
            ends = self._ends
            cut = np.searchsorted(self.rx_t, ends, side="right")
            if self.rej_t.shape[0]:
                rejected = _counts(np.searchsorted(self.rej_t, ends, side="right"))
                k = np.searchsorted(self.acc_t, ends, side="right")
            else:  # the usual case: every sample accepted (and so rx_t is t)
                rejected, k = np.zeros(ends.shape[0], np.int64), cut
            # (k rises: the usual slab has accepted samples by its first tick end)
            self.has_all = bool(k[0] > 0) if k.shape[0] else True
            if self.has_all:
                has, last = np.ones(k.shape[0], bool), self.acc_t[k - 1]
            else:
                has = (k > 0) | self._before[2]
                last = np.where(k > 0, self.acc_t[np.maximum(k - 1, 0)] if self.acc_t.shape[0]
                                else 0, self._before[3])
            self._arrays = (_counts(cut), rejected, has, last)
            self._accepted_upto = k
        return self._arrays

    def _tick_lists(self) -> tuple[list[int], list[int], list[int], list[bool], list[int],
                                   list[list[int]] | None]:
        """The prepared health as python ints (the per-tick reads are then cheap)."""
        if self._ticks is None:
            received, rejected_tick, has, last = self.tick_arrays
            by_reason = None
            if self.rej_t.shape[0]:
                by_reason = np.stack([
                    np.searchsorted(self.t[self.codes == i], self._ends, side="right")
                    for i in range(1, len(REASONS) + 1)]).tolist()
            self._ticks = (received.tolist(), rejected_tick.tolist(),
                           (self._before[0] + self._accepted_upto).tolist(), has.tolist(),
                           np.where(has, last, 0).tolist(), by_reason)
        return self._ticks

    def tick(self, k: int, now: int, stale_ns: float) -> StreamObs:
        """Health at the ``k``-th prepared tick end; the tick's counts start at the slab start
        (the caller adds what earlier slabs contributed to the same tick) for ``k = 0``."""
        received, rejected_tick, accepted, has_last, last, by_reason = self._tick_lists()
        last_t, rejected = last[k], self._before[1]
        if by_reason is not None:
            rejected = {r: rejected[r] + by_reason[i][k] for i, r in enumerate(REASONS)}
        # positional (the fields' order): keywords cost 60 % more per call, at every tick
        return StreamObs(last_t, not has_last[k] or now - last_t > stale_ns, accepted[k],
                         rejected, rejected_tick[k], received[k])


def _counts(cut: np.ndarray) -> np.ndarray:
    """Each tick's count from the cumulative counts at the tick ends (``np.diff`` with
    ``prepend=0``, at a fraction of its cost)."""
    out = cut.copy()
    np.subtract(cut[1:], cut[:-1], out=out[1:])
    return out


@dataclasses.dataclass(slots=True)
class _SlabTicks:
    """The ticks one slab completes: their ends, the sample index after each end in the
    slab's load series (``cuts``, one more: the slab's length) and the first tick end after
    them; when they are evaluated, their load figures and (full-estimate mode) mean motion
    estimates."""

    ends: np.ndarray
    ends_l: list[int]
    n: int  # how many (len(ends_l))
    cuts: list[int]
    next_tick: int | None
    evaluate: bool
    load: _TickLoad | None
    est_means: list[float] | None


class _LazyStreams(Mapping[str, StreamObs]):
    """Per-tick stream health, computed only for the streams a rule looks at (each at most
    once: the first slab tick also takes the counts earlier slabs left for it)."""

    def __init__(self, pipeline: "Pipeline", now: int, streams: Mapping[str, _StreamSlab],
                 k: int) -> None:
        self._pipeline, self._now, self._streams, self._k = pipeline, now, streams, k
        self._done: dict[str, StreamObs] = {}

    def __getitem__(self, name: str) -> StreamObs:
        obs = self.get(name)
        if obs is None:
            raise KeyError(name)
        return obs

    def get(self, name: str, default: Any = None) -> Any:
        # the rules call get (once or twice a tick: stale and rejected rate ask for the same
        # stream), so it does the work and [] wraps it
        obs = self._done.get(name)
        if obs is None:
            if name not in self._pipeline.validators:
                return default
            obs = self._done[name] = self._pipeline._stream_one(name, self._now, self._streams,
                                                                self._k)
        return obs

    def __iter__(self):
        return iter(self._pipeline.validators)

    def __len__(self) -> int:
        return len(self._pipeline.validators)


@dataclasses.dataclass(frozen=True, slots=True)
class _Totals:
    """A stream's validation totals after one slab's checks: what a tick reads of a stream
    without samples in the slab (the validator itself may be a slab further on)."""

    accepted: int
    rejected: dict[str, int]
    has_last: bool
    last_t_ns: int

    @classmethod
    def of(cls, v: StreamValidator) -> "_Totals":
        return cls(v.accepted, dict(v.rejected), v.has_last, v.last_t_ns)


@dataclasses.dataclass(frozen=True, slots=True)
class SlabIntake:
    """One slab as the stream stage (:meth:`Pipeline.ingest`) hands it to the tick stage
    (:meth:`Pipeline.advance`): all the tick stage reads of the streams."""

    block: SampleBlock | None  # the block given, for the sinks' block hooks (None: flush)
    sensor: str  # the block's sensor, or "flush"
    upto: int | None  # the ordering watermark the slab was taken up to (None: everything)
    tick_limit: int | None  # the ticks ending at or before it are complete
    streams: dict[str, _StreamSlab]
    totals: dict[str, _Totals]  # every stream's, without the slab's copies
    span: tuple[int, int] | None  # first and last accepted sample time
    n_acc: int
    rejected: dict[str, int]  # per reason, the copies included
    qc: dict[str, Any]  # QC flag totals per stream of the slab, for sinks that want them
    t: np.ndarray  # the fatigue load: times, tension, source
    v: np.ndarray
    src: np.ndarray
    stresses: dict[str, np.ndarray]
    peaks: dict[str, tuple[float, int]]  # per component (Component.peak)
    estimate: tuple[np.ndarray, np.ndarray] | None  # the motion estimates, full-estimate mode
    measured_N: float | None  # the slab's newest measured and estimated tension
    estimated_N: float | None
    spectra: Any  # the sea-state learner's inputs (SeaStateLearner.hand_over), or None


class Pipeline:
    """The fatigue-monitoring core for one buoy. See the module docstring."""

    def __init__(self, config: Config, sinks: Iterable[Sink] = (),
                 state: Mapping[str, Any] | None = None, *, horizon_s: float | None = None,
                 gate_all: bool = False, warm: bool = True) -> None:
        if state is not None and state.get("version") != STATE_VERSION:
            raise ValueError(f"pipeline state version {state.get('version')!r} is not "
                             f"{STATE_VERSION}; cannot restore")
        st = state or {}
        self.config = config
        self.buoy_id = config.buoy.id
        self.sinks = tuple(sinks)  # fixed: the hooks below are taken from them once
        # optional sink hooks, called by the core so live and replay feed them alike: raw
        # blocks (e.g. GNSS positions for the Rerun map) and each alert tick's observation
        self._block_hooks = [s.on_block for s in self.sinks if hasattr(s, "on_block")]
        self._tick_hooks = [s.on_observation for s in self.sinks if hasattr(s, "on_observation")]
        # StepResult.qc is built only for sinks that read it (a dict per step otherwise)
        self._qc_sinks = any(getattr(s, "wants_qc", False) for s in self.sinks)
        self.tick_ns = int(round(config.alerts.eval_interval_s * 1e9))
        # ticks evaluated after the last sample of a gap without any (a sensor clock jumping
        # years ahead, logs far apart): enough for every sensor-time rule and the damage-rate
        # window to see the data stop; the rest of the gap is skipped, not walked tick by tick
        self._max_empty_ticks = -(-int(max(_EMPTY_SPAN_S, config.fatigue.rate_window_s) * 1e9)
                                  // self.tick_ns) + 1
        cable = build_cable(config)
        self.components = {
            c.name: Component(c, cable, config.fatigue, st.get("components", {}).get(c.name))
            for c in config.components
        }
        # components counting as an earlier one (Component.count_with) take its runs: the
        # default conductor and termination rainflow and commit the same stress once
        self._counts_as: dict[str, str] = {}
        names = list(self.components)
        for i, name in enumerate(names):
            lead = next((n for n in names[:i] if n not in self._counts_as
                         and self.components[name].count_with(self.components[n])), None)
            if lead is not None:
                self._counts_as[name] = lead
        self.validators = {
            s: StreamValidator(s, config.validate[s], st.get("validators", {}).get(s))
            for s in SENSOR_ORDER
        }
        self._stale_ns = {s: config.validate[s].stale_after_s * 1e9 for s in SENSOR_ORDER}
        self._idle_obs: dict[str, tuple[tuple, StreamObs]] = {}
        self._totals: dict[str, _Totals] = {}  # the streams as the slab's ticks see them
        self.selector = LoadSelector(config.load, st.get("load"))
        # [load] motion_sensor = "auto": the first motion stream (imu or motion) to arrive
        # feeds the estimator from then on (None until one has)
        self.motion_sensor: str | None = st.get("motion_sensor", (
            None if config.load.motion_sensor == "auto" else config.load.motion_sensor))
        self.estimator = None
        if config.load.source != "measured" and self.motion_sensor is not None:
            self.estimator = build_estimator(config, st.get("estimator"), self.motion_sensor)
        load_streams = []
        if config.load.source != "estimated":
            load_streams.append("tension")
        if self.estimator is not None:
            load_streams.append(self.motion_sensor)
        elif config.load.source != "measured":
            # "auto" before a motion stream has arrived: both gate (a stream arriving after a
            # slab was released would be late), until _choose_motion keeps the one that came
            load_streams.extend(MOTION_SENSORS)
        horizon = config.ordering.horizon_s if horizon_s is None else horizon_s
        self.reorder = ReorderBuffer(load_streams or ["tension"], int(round(horizon * 1e9)),
                                     gate_all, st.get("reorder"))
        # sensor time processed so far by watermark (not by flush): older samples are late
        self.processed_ns = int(st.get("processed_ns", _NEVER))
        # a late exact copy of a recent received sample is a duplicate, not time_backwards
        # (stream stage, as the validators)
        self.late_copies = LateCopies(config.ordering.copy_span_s, st.get("late_copies"))
        self._max_ahead_ns = int(round(config.ordering.max_ahead_s * 1e9))
        self.alerts = build_alert_engine(
            config, self.buoy_id,
            {n: endurance_stress_Pa(c.cfg, c.sn_curve) for n, c in self.components.items()},
            st.get("alerts"), {n: c.yield_stress_Pa for n, c in self.components.items()})
        # without rules there is nothing to evaluate: skip building the per-tick observations
        rule_keys = getattr(self.alerts, "rule_keys", None)
        self._has_rules = rule_keys is None or bool(rule_keys())
        # the model-residual rule compares the tick means of the measured tension and of the
        # motion estimate over every motion sample, not only where the estimate feeds fatigue
        rule_kinds = getattr(self.alerts, "rule_kinds", None)
        self._residual_rule = rule_kinds is None or "model_residual" in rule_kinds()
        self._full_estimate = self.estimator is not None and self._residual_rule
        lim = config.validate["tension"].fields["tension_N"]
        self.stats = _TensionStats(lim.min, lim.max, st.get("stats"))
        self.taken_upto: dict[str, int] = {k: int(v) for k, v in st.get("taken_upto", {}).items()}
        self.next_tick_ns: int | None = st.get("next_tick_ns")
        # the end of the tick holding the newest sample the tick stage has had: a run of
        # ticks without samples counts from there, in whatever slab it began (_tick_ends)
        self.sample_tick_ns: int | None = st.get("sample_tick_ns")
        # per-stream counts in the tick being filled: {sensor: [received, rejected]}
        self.tick_counts: dict[str, list[int]] = {s: list(v) for s, v in st.get("tick_counts", {}).items()}
        self.last = dict(st.get("last", {"measured_N": None, "estimated_N": None,
                                          "source": "none", "now_ns": 0,
                                          "load_t_ns": None, "load_src": 0,
                                          "time_start_ns": None, "time_end_ns": None}))
        self.new_alerts: list[Any] = []
        # load samples of the tick not yet evaluated: (t_ns, tension_N, source)
        self.open_tick: tuple[np.ndarray, np.ndarray, np.ndarray] = (
            _NO_LOAD if "open_tick" not in st else
            (np.array(st["open_tick"][0], np.int64), np.array(st["open_tick"][1], np.float64),
             np.array(st["open_tick"][2], np.int8)))
        # motion estimates of the tick not yet evaluated (t_ns, tension_N), full-estimate mode
        self.open_estimate = (np.array(st["open_estimate"][0], np.int64),
                              np.array(st["open_estimate"][1], np.float64)
                              ) if st.get("open_estimate") else _NO_LOAD[:2]
        self.damage_split = DamageSplit({n: c.sn_curve.m[0] for n, c in self.components.items()},
                                        st.get("damage_split"))
        self.alert_history: list[dict[str, Any]] = list(st.get("alert_history", []))
        self.alerts_dropped = int(st.get("alerts_dropped", 0))  # oldest, past the limit
        self.sea_states, self.forecasts = _build_forecasting(config, self.components,
                                                             self.tick_ns / 1e9, st)
        if warm:  # (False: the caller loads the kernels of the stage it runs, or none)
            self.warm_up_stream()
            self.warm_up_ticks()

    # Pay the compiled kernels' first-call cost now (over a second for the first numba call
    # in a process), before a daemon reports ready: the first block after a restart is then
    # processed at once. Per stage, so that a process running one stage
    # (replay.stage_process) loads only that stage's. Neither touches any state.
    def warm_up_stream(self) -> None:
        """The stream stage's kernels (:meth:`ingest`): validation, QC, the stresses."""
        tension = self.validators["tension"]
        tension.check(np.zeros(0, np.int64), np.zeros((1, 0)), _NEVER)
        # both QARTOD kernels (the general one for a stream's first samples, then the fast
        # one), on a throwaway copy of the tests
        qc = StreamQC(tension.qc.fields)
        for part in (np.arange(3, dtype=np.int64), np.arange(3, 6, dtype=np.int64)):
            qc.check(part, np.zeros((1, 3)))
        self.stresses(np.array([1000.0, 2000.0]))

    def warm_up_ticks(self) -> None:
        """The tick stage's kernels (:meth:`advance`): rainflow and Miner sums, the sea-state
        learner's spectra, the alerts."""
        for comp in self.components.values():
            comp.warm_up()
        if self.sea_states is not None:
            self.sea_states.warm_up()
        alert_batch_warm_up()

    # ------------------------------------------------------------------ driving
    @classmethod
    def from_state(cls, config: Config, state: Mapping[str, Any], sinks: Iterable[Sink] = (),
                   **kwargs: Any) -> "Pipeline":
        return cls(config, sinks, state, **kwargs)

    def process(self, block: SampleBlock) -> StepResult:
        """Buffer one block and process everything the ordering watermark now allows (the
        stream stage, then the tick stage: :meth:`ingest`, :meth:`advance`)."""
        return self.advance(self.ingest(block))

    def _choose_motion(self, sensor: str) -> None:
        """``motion_sensor = "auto"``: ``sensor`` feeds the estimator from now on and gates the
        ordering as a load stream (split-invariant for a buoy with one motion stream; a buoy
        sending both should name the one to use)."""
        self.motion_sensor = sensor
        self.estimator = build_estimator(self.config, None, sensor)
        self.reorder.load_streams = tuple(s for s in self.reorder.load_streams
                                          if s not in MOTION_SENSORS or s == sensor)
        self._full_estimate = self._residual_rule

    def load_problems(self) -> list[str]:
        """Why the fatigue chain has (or had) no load, in words ([] when it has one)."""
        cfg = self.config.load
        seen = {s for s, v in self.validators.items() if v.accepted or any(v.rejected.values())}
        out = []
        if cfg.source == "measured" and "tension" not in seen:
            out.append("[load] source = 'measured' but no tension samples arrived")
        elif cfg.source == "auto" and "tension" not in seen and seen:
            out.append("no tension samples (no load cell)" + (
                ": the load is the motion estimate" if self.stats.n["estimated"] else ""))
        if cfg.source != "measured":
            present = [s for s in MOTION_SENSORS if s in seen]
            if cfg.motion_sensor != "auto" and cfg.motion_sensor not in seen:
                out.append(f"[load] motion_sensor = {cfg.motion_sensor!r} but no "
                           f"{cfg.motion_sensor} samples arrived"
                           + (f" (the buoy sends {', '.join(present)}: set motion_sensor = "
                              f"\"auto\")" if present else ""))
            elif cfg.motion_sensor == "auto" and not present:
                out.append("no motion samples (imu or motion) for the estimator" + (
                    ": nothing stands in for the load cell if it stops" if "tension" in seen
                    else ""))
        if self.estimator is not None:
            out += rate_problems(self.estimator.rate_figures())
        if self.stats.n["measured"] + self.stats.n["estimated"] == 0 and seen:
            out.append("no load could be formed: fatigue damage is not being computed")
        return out

    def add_forecast(self, doc: Any, not_before_ns: int | None = None) -> int:
        """A sea-state forecast (JSON payload, :mod:`monitor.forecast`), applied at the first
        tick at or after its issue time and ``not_before_ns`` (default: the first tick not
        yet evaluated); returns that due time. ValueError if it is malformed or forecasting
        is off; ForecastExpired (a ValueError) if no step would be left to project."""
        if self.forecasts is None:
            raise ValueError("forecasting is off ([forecast] enabled = false)")
        fc = parse_forecast(doc, self.next_tick_ns if not_before_ns is None else not_before_ns)
        refuse_expired(fc, self.tick_ns)
        self.forecasts.add(fc)
        return fc.due_ns

    def flush(self) -> StepResult:
        """End of input: process every buffered sample; evaluate ticks the data completes."""
        return self.advance(self.ingest_end())

    def silence(self, silent_s: float) -> StepResult | None:
        """Live (the daemon's idle loop): no data arrived for ``silent_s`` s of wall-clock
        time. Past the ordering horizon, the load streams never seen (or dead) stop holding
        back the newest horizon of sensor time (:meth:`ReorderBuffer.silence`): what they
        held is processed now, its ticks' alerts sent (None: nothing changed)."""
        if not self.reorder.silence(int(silent_s * 1e9)):
            return None
        upto = self.reorder.watermark()
        return self.advance(self._ingest_slab(None, "flush", upto, upto))

    def close(self) -> None:
        for sink in self.sinks:
            sink.close()

    # ------------------------------------------------------------------ core step
    # Two stages, each owning its state (see SlabIntake). The stream stage: the ordering,
    # validators (and QC), taken_upto, processed_ns, the motion sensor and estimator, the load
    # selector, the tension statistics and the sea-state learner's inputs. The tick stage:
    # the components' rainflow and Miner sums and peaks, the alerts, forecasts, the learner's
    # windows and table, the damage split, the tick grid and whatever waits for the next tick,
    # ``last``, the alert history and the sinks. The stream stage never reads the tick
    # stage's state, and the tick stage reads the stream stage's only in the hand-over, so
    # the stream stage of the next slab may run while the tick stage runs (replay.stages);
    # the results are the same to the bit.
    def ingest(self, block: SampleBlock, *more: SampleBlock) -> SlabIntake:
        """Stream stage of :meth:`process`: buffer the block and take the slab the ordering
        watermark allows through the per-stream work. ``more``: blocks buffered after it,
        before the slab is taken (a replay's blocks of one span of the log, replay.spans):
        one slab for them all, the same results (the ordering's rule); the slab's block is
        the last (ValueError with block hooks, which would miss the others)."""
        blocks = (block, *more)
        for b in blocks:
            if b.buoy_id != self.buoy_id:
                raise ValueError(f"block of buoy {b.buoy_id!r} given to the pipeline of buoy "
                                 f"{self.buoy_id!r}")
        if more and self._block_hooks:
            raise ValueError("blocks given together to a pipeline with block hooks")
        total_ahead = 0
        for b in blocks:
            block, ahead = drop_ahead(b, self._max_ahead_ns)
            if ahead:  # counted before the slab's checks, so its ticks' totals include them
                self.validators[block.sensor].rejected["time_ahead"] += ahead
                total_ahead += ahead
            if (self.motion_sensor is None and block.sensor in MOTION_SENSORS
                    and self.config.load.source != "measured" and len(block)):
                self._choose_motion(block.sensor)
            self.reorder.push(block)
        upto = self.reorder.watermark()
        intake = self._ingest_slab(block, block.sensor, upto, upto)
        intake.rejected["time_ahead"] += total_ahead
        return intake

    def ingest_end(self) -> SlabIntake:
        """Stream stage of :meth:`flush`: every buffered sample."""
        return self._ingest_slab(None, "flush", None, self.reorder.end_of_data())

    def _ingest_slab(self, block: SampleBlock | None, sensor: str, upto: int | None,
                     tick_limit: int | None) -> SlabIntake:
        slab = self.reorder.take(upto)
        streams: dict[str, _StreamSlab] = {}
        n_acc = 0
        rejected = dict.fromkeys(REASONS, 0)
        span: tuple[int, int] | None = None
        for s, (t, values) in slab.items():
            validator = self.validators[s]
            before = _StreamSlab.before(validator)
            codes = validator.check(t, values, max(self.processed_ns, self.taken_upto.get(s, _NEVER)))
            verdicts = bool(codes.any())  # (usually none: every sample accepted)
            if verdicts:
                self.late_copies.judge(s, t, values, codes, validator.rejected)
            self.taken_upto[s] = max(self.taken_upto.get(s, _NEVER), int(t[-1]))
            streams[s] = info = _StreamSlab(t, values, codes, before, verdicts)
            self.late_copies.received(s, t, values, codes)
            n_acc += info.acc_t.shape[0]
            if verdicts:  # the validator counted them (none without a verdict)
                for reason, n in before[1].items():
                    rejected[reason] += validator.rejected[reason] - n
            if info.acc_t.shape[0]:
                first, last = int(info.acc_t[0]), int(info.acc_t[-1])
                span = (first, last) if span is None else (min(span[0], first), max(span[1], last))
        m_t, m_v = np.zeros(0, np.int64), np.zeros(0)
        if "tension" in streams:
            m_t, m_v = streams["tension"].acc_t, streams["tension"].acc_values[0]
        e_t, e_v, e_clamped = np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool)
        if self.estimator is not None and self.motion_sensor in streams:
            info = streams[self.motion_sensor]
            if info.acc_t.shape[0]:
                fields = dict(zip(SENSOR_FIELDS[self.motion_sensor], info.acc_values))
                # estimate only where it feeds fatigue, and the newest sample for the status
                # (or everywhere for the model-residual rule)
                if self._full_estimate:
                    want = np.ones(info.acc_t.shape, bool)
                else:
                    want = self.selector.needed(m_t, info.acc_t)
                    want[-1] = True
                e_t, e_v, e_clamped = self.estimator.feed(info.acc_t, fields, want)
        t, v, src = self.selector.select(m_t, m_v, e_t, e_v, e_clamped)
        self.stats.add(v, src)
        stresses = self.stresses(v)
        spectra = self.feed_learner(streams, t, stresses)  # before the ticks the slab completes
        # the ticks see every stream's totals without this slab's copies, counted after them
        totals = {s: _Totals.of(val) for s, val in self.validators.items()}
        for s, n in slab.copies.items():
            self.validators[s].rejected["duplicate"] += n
            rejected["duplicate"] += n
        if upto is not None:
            self.processed_ns = max(self.processed_ns, upto)
        return SlabIntake(
            block, sensor, upto, tick_limit, streams, totals, span, n_acc, rejected,
            {s: self.validators[s].qc_counts() for s in streams} if self._qc_sinks else {},
            t, v, src, stresses, self.peaks(stresses),
            (e_t, e_v) if self._full_estimate else None,
            float(m_v[-1]) if m_t.shape[0] else None, float(e_v[-1]) if e_t.shape[0] else None,
            spectra)

    def stresses(self, v: np.ndarray) -> dict[str, np.ndarray]:
        """Each component's stress under the load ``v``; a component counting as an earlier
        one (the default conductor and its termination) has the same function of the load,
        so the same array, computed once."""
        return self._per_counting(lambda name, c: c.stress(v, record=False))

    def peaks(self, stresses: Mapping[str, np.ndarray]) -> dict[str, tuple[float, int]]:
        """Each component's :meth:`Component.peak` of its ``stresses``; a component counting
        as an earlier one has its stress and yield stress: its peak, computed once."""
        return self._per_counting(lambda name, c: c.peak(stresses[name]))

    def _per_counting(self, f: Callable[[str, Component], _T]) -> dict[str, _T]:
        """``f(name, component)`` per component, once per counting group: a component
        counting as an earlier one (:meth:`Component.count_with`) takes that one's result."""
        out: dict[str, _T] = {}
        for name, c in self.components.items():
            lead = self._counts_as.get(name)
            out[name] = out[lead] if lead is not None else f(name, c)
        return out

    def feed_learner(self, streams: Mapping[str, _StreamSlab], t: np.ndarray,
                     stresses: Mapping[str, np.ndarray]) -> Any:
        """Stream-stage part of :meth:`ingest`: the sea-state learner fed a slab's accepted
        samples (``streams``) and fatigue load; returns its hand-over (None without a
        learner). Reads only the learner's feeding side, so replay.stage_process can run it
        in the tick stage's process."""
        if self.sea_states is None:
            return None
        for name, wanted in _SEA_STATE_FIELDS.items():
            part = streams.get(name)
            if part is not None and part.acc_t.shape[0]:
                fields = dict(zip(SENSOR_FIELDS[name], part.acc_values))
                getattr(self.sea_states, name)(part.acc_t, *(fields[f] for f in wanted))
        self.sea_states.load(t, stresses)
        return self.sea_states.hand_over()

    def advance(self, intake: SlabIntake) -> StepResult:
        """Tick stage of :meth:`process` and :meth:`flush`, given their stream stage's
        hand-over (in the same order): fatigue, the ticks the slab completes, the sinks."""
        step = self._advance(intake, True)
        assert step is not None  # (asked for)
        return step

    def advance_unread(self, intake: SlabIntake) -> None:
        """:meth:`advance` for a caller that does not read the step (a replay's driver): none
        is made unless a sink takes it (the slab's cycles joined and every component's
        figures: ~0.1 ms a slab)."""
        self._advance(intake, False)

    def _advance(self, intake: SlabIntake, result: bool) -> StepResult | None:
        """:meth:`advance`, the step made only if ``result`` or a sink takes it."""
        if intake.block is not None:
            for hook in self._block_hooks:
                hook(intake.block)
        t, v, src = intake.t, intake.v, intake.src
        stresses = intake.stresses
        if intake.span is not None:
            first, last = intake.span
            start, end = self.last["time_start_ns"], self.last["time_end_ns"]
            self.last["time_start_ns"] = first if start is None else min(start, first)
            self.last["time_end_ns"] = last if end is None else max(end, last)
        if intake.measured_N is not None:
            self.last["measured_N"] = intake.measured_N
        if intake.estimated_N is not None:
            self.last["estimated_N"] = intake.estimated_N
        for name, c in self.components.items():
            c.record(*intake.peaks[name])
        self.new_alerts = []
        if self.sea_states is not None:
            self.sea_states.receive(intake.spectra)
        self._totals = intake.totals
        closed = self._feed_by_tick(t, v, src, stresses, intake.streams, intake.tick_limit,
                                    intake.estimate)
        if t.shape[0]:
            self.last["load_t_ns"], self.last["load_src"] = int(t[-1]), int(src[-1])
        now = intake.upto if intake.upto is not None else intake.tick_limit
        if now is not None:
            self.last["now_ns"] = max(self.last["now_ns"], now)
        self.last["source"] = self._source_at(self.last["now_ns"])
        if not (result or self.sinks):
            if self.sea_states is not None:  # (what a step would have taken)
                self.sea_states.take_windows()
            if self.forecasts is not None:
                self.forecasts.take_new()
            return None
        step = self._step(intake.sensor, t, v, stresses, closed, intake.n_acc, intake.rejected,
                          intake.qc)
        for sink in self.sinks:
            sink.on_step(step)
        return step

    def _tick_ends(self, first_end: int, k: int, times: Sequence[np.ndarray],
                   sample_tick: int | None = None) -> np.ndarray:
        """Ends of the ticks to evaluate, ``first_end + tick * i`` for i in 0..k, leaving out
        all but the first ``_max_empty_ticks`` of a run of ticks without any sample of
        ``times``: memory and time then depend on the data, not on how far the clock jumped.
        A run begun before the slab counts from ``sample_tick`` (the end of the tick of the
        newest earlier sample, :attr:`sample_tick_ns`; None: from the slab's first tick), so
        the ticks do not depend on where the slabs were cut."""
        # the tick index of the newest earlier sample (0 if it is in this slab's first tick
        # or later: its tick then starts a run here, as a sample of this slab's would)
        s0 = 0 if sample_tick is None else min(0, (sample_tick - first_end) // self.tick_ns)
        if k - s0 < self._max_empty_ticks or any(self._dense(first_end, k, x, s0) for x in times
                                                 if x.shape[0]):  # the usual slab: every tick
            return first_end + self.tick_ns * np.arange(k + 1, dtype=np.int64)
        # index of the tick each sample falls in (its end at or after the sample)
        starts = np.unique(np.concatenate([np.full(1, s0, np.int64)] + [
            np.clip(-((first_end - x) // self.tick_ns), 0, k) for x in times if x.shape[0]]))
        stops = np.minimum(starts + self._max_empty_ticks, np.append(starts[1:], k + 1))
        lo = np.maximum(starts, 0)
        lengths = np.maximum(stops - lo, 0)
        offsets = np.cumsum(lengths) - lengths
        keep = (np.arange(int(lengths.sum()), dtype=np.int64)
                + np.repeat(lo - offsets, lengths))
        return first_end + self.tick_ns * keep

    def _dense(self, first_end: int, k: int, x: np.ndarray, s0: int = 0) -> bool:
        """Whether the sorted sample times ``x`` alone leave no run of ticks :meth:`_tick_ends`
        would cut short (then no run is, whatever the other streams'): with the tick ``s0``
        (of the newest earlier sample, <= 0) and the tick after the slab's last, every
        ``len(x) // 64``-th sample and the last are at most ``_max_empty_ticks`` ticks apart
        (so are the samples between them). A slab of hours (replay.spans) takes the usual
        path without a pass over its samples."""
        idx = np.clip(-((first_end - np.concatenate((x[::max(1, x.shape[0] // 64)], x[-1:])))
                        // self.tick_ns), 0, k)
        most = self._max_empty_ticks
        return bool(idx[0] - s0 <= most and k + 1 - idx[-1] <= most
                    and (idx[1:] - idx[:-1]).max(initial=0) <= most)

    def _source_at(self, now: int) -> str:
        """The load source of the newest load sample, "none" once it is older than stale_after_s."""
        t = self.last["load_t_ns"]
        if t is None or now - t > self.selector.stale_ns:
            return "none"
        return SOURCE_NAMES[self.last["load_src"]]

    def _feed_by_tick(self, t: np.ndarray, v: np.ndarray, src: np.ndarray,
                      stresses: Mapping[str, np.ndarray], streams: Mapping[str, "_StreamSlab"],
                      tick_limit: int | None, estimate: tuple[np.ndarray, np.ndarray] | None
                      ) -> dict[str, list[tuple[np.ndarray, ...]]]:
        """Rainflow and Miner damage over the slab's whole ticks (each committed at its end),
        the alert rules at every tick end, and the samples after the last end kept pending;
        returns each component's closed cycles in parts ((ranges, means, counts) each)."""
        ticks = self._due_ticks(t, v, src, stresses, streams, tick_limit, estimate)
        closed: dict[str, list[tuple[np.ndarray, ...]]] = {n: [] for n in self.components}
        figures = self._commit_ticks(stresses, ticks, closed)
        self._evaluate_ticks(t, v, src, streams, ticks, figures)
        self._carry_estimate(estimate, ticks.ends)
        if ticks.n:
            self.next_tick_ns = ticks.next_tick
            self.tick_counts = {}
        self._keep_open_tick(t, v, src, stresses, streams, ticks, closed)
        return closed

    def _due_ticks(self, t: np.ndarray, v: np.ndarray, src: np.ndarray,
                   stresses: Mapping[str, np.ndarray], streams: Mapping[str, "_StreamSlab"],
                   tick_limit: int | None, estimate: tuple[np.ndarray, np.ndarray] | None
                   ) -> _SlabTicks:
        """The ticks this slab completes (those ending at or before ``tick_limit``; the grid
        starts at the first sample's tick) and, when they are evaluated, their load figures,
        stream health and mean motion estimates."""
        if self.next_tick_ns is None and streams:
            first = min(int(x.t[0]) for x in streams.values())
            self.next_tick_ns = -(-first // self.tick_ns) * self.tick_ns
        ends: np.ndarray = np.zeros(0, np.int64)
        next_tick = self.next_tick_ns
        times = [t, *(x.t for x in streams.values())]
        if tick_limit is not None and next_tick is not None and tick_limit >= next_tick:
            k = (tick_limit - next_tick) // self.tick_ns
            ends = self._tick_ends(next_tick, k, times, self.sample_tick_ns)
            next_tick += (k + 1) * self.tick_ns
        newest = max((int(x[-1]) for x in times if x.shape[0]), default=None)
        if newest is not None:
            end = -(-newest // self.tick_ns) * self.tick_ns
            self.sample_tick_ns = (end if self.sample_tick_ns is None
                                   else max(self.sample_tick_ns, end))
        cuts = np.empty(ends.shape[0] + 1, np.int64)
        cuts[:-1] = np.searchsorted(t, ends, side="right")
        cuts[-1] = t.shape[0]
        evaluate = (self._has_rules or bool(self._tick_hooks) or self.sea_states is not None
                    ) and ends.shape[0] > 0
        load, est_means = None, None
        if evaluate:
            for info in streams.values():
                info.prepare(ends)
            starts = np.empty(ends.shape[0], np.int64)  # (np.append costs three times more)
            starts[0] = 0
            starts[1:] = cuts[:-2]
            load = _TickLoad(v, src, stresses, starts, cuts[:-1])
            if estimate is not None:
                est_means = self._estimate_means(*estimate, ends)
        # python ints for the per-tick loop
        ends_l = ends.tolist()
        return _SlabTicks(ends, ends_l, len(ends_l), cuts.tolist(), next_tick, evaluate, load,
                          est_means)

    def _commit_ticks(self, stresses: Mapping[str, np.ndarray], ticks: _SlabTicks,
                      closed: Mapping[str, list[tuple[np.ndarray, ...]]]) -> dict[str, TickRun]:
        """Rainflow and Miner over the slab's whole ticks, each committed at its end; returns
        every component's run, with its figures at every tick end when the ticks are
        evaluated."""
        runs = self._per_counting(lambda name, c: c.run_ticks(
            stresses[name], ticks.cuts[:ticks.n], ticks.ends, ticks.evaluate))
        for name, run in runs.items():
            closed[name].append(run.cycles)
        return runs

    def _evaluate_ticks(self, t: np.ndarray, v: np.ndarray, src: np.ndarray,
                        streams: Mapping[str, "_StreamSlab"], ticks: _SlabTicks,
                        figures: Mapping[str, TickRun]) -> None:
        """Each tick end in turn: the newest load sample so far, then (when evaluated) the
        alert rules, all ticks at once when nothing needs an observation per tick; the
        damage split of the evaluated ticks."""
        split = None
        if ticks.evaluate and not self._tick_hooks and ticks.n >= BATCH_MIN_TICKS:
            split = self._evaluate_batch(t, v, src, streams, ticks, figures)
        # each component's committed damage at each tick end
        committed = {n: f.columns[1] for n, f in figures.items()}
        split_rows: Any  # an array, or a list of tuples, of a row per evaluated tick
        if split is not None:
            split_rows = split
        else:
            split_rows = []
            start = 0
            for k in range(ticks.n):
                stop = ticks.cuts[k]
                if stop > start:
                    self.last["load_t_ns"], self.last["load_src"] = int(t[stop - 1]), int(src[stop - 1])
                if ticks.evaluate:
                    split_rows.append(self._evaluate_tick(k, t, v, src, streams, ticks, figures))
                self.open_tick = _NO_LOAD
                start = stop
        if len(split_rows):
            self.damage_split.ticks(committed, split_rows)

    def _evaluate_batch(self, t: np.ndarray, v: np.ndarray, src: np.ndarray,
                        streams: Mapping[str, "_StreamSlab"], ticks: _SlabTicks,
                        figures: Mapping[str, TickRun]) -> np.ndarray | None:
        """The slab's ticks through the alert engine's batch (:mod:`monitor.alerts.batch`):
        only the ticks where something happens get an Observation; the sea-state learner
        still sees every tick. Returns the damage-split rows (an array: measured samples,
        samples, measured mean, estimated mean), None when the engine has no batch for these
        rules (the caller then evaluates tick by tick)."""
        tick_batch = getattr(self.alerts, "tick_batch", None)
        if tick_batch is None:
            return None
        assert ticks.load is not None  # prepared whenever the ticks are evaluated
        load, n = ticks.load, ticks.n
        first = self._tick_view(0, t, v, src, ticks)  # with the samples left by earlier slabs
        load0, j0 = first[3], first[4]
        # the slab's per-tick figures with the first tick's as it began in an earlier slab
        if ticks.est_means is not None:
            est = np.array(ticks.est_means)
        else:
            est = load.est.copy()
            est[0] = load0.est[j0]
        meas, n_meas, n_load, tension_max = (
            a.copy() for a in (load.meas, load.n_meas, load.n, load.vmax))
        meas[0], n_meas[0], n_load[0] = load0.meas[j0], load0.n_meas[j0], load0.n[j0]
        tension_max[0] = load0.vmax[j0]
        peaks: dict[str, np.ndarray] = {}  # each component's peak stress, once asked for

        def component(name: str, i: int) -> np.ndarray:
            if i < 4:
                return figures[name].columns[i]
            if name not in peaks:
                peaks[name] = load.smax[name].copy()
                peaks[name][0] = load0.smax[name][j0]
            return peaks[name]
        health: dict[str, StreamTicks] = {}  # stale and rejected-rate rules ask for the same

        def stream(s: str) -> StreamTicks:
            if s not in health:
                health[s] = self._stream_ticks(s, ticks.ends, streams)
            return health[s]
        batch = tick_batch(TickInputs(
            buoy_id=self.buoy_id, ends=ticks.ends, tension_max=tension_max,
            measured=meas, estimated=est, component=component, stream=stream,
            load=lambda: self._load_by_tick(t, v, ticks),
            receives=lambda s: s in streams or s in self.tick_counts))
        if batch is None:
            return None
        learner, forecasts = self.sea_states, self.forecasts
        quiet, next_due = None, None
        if learner is not None and forecasts is not None:
            def committed(q: int) -> dict[str, float]:
                return {name: float(f.columns[1][q]) for name, f in figures.items()}

            def quiet(a: int, b: int) -> None:  # the learner sees every tick
                learner.ticks(ticks.ends, committed, n_load, a, b)
            next_due = forecasts.next_due_ns

        def tick(k: int) -> None:  # something happens: the ordinary evaluation
            self._note_load(t, src, ticks.cuts[k])
            tt, tv, _, tick_load, j = first if k == 0 else self._tick_view(k, t, v, src, ticks)
            self._evaluate(k, ticks.ends_l[k], tt, tv, tick_load, j, streams, figures,
                           float(est[k]))
        batch.run(tick, self._emit, quiet, next_due)
        self._note_load(t, src, ticks.cuts[n - 1])
        self.open_tick = _NO_LOAD
        return np.column_stack((n_meas, n_load, meas, est)).astype(np.float64, copy=False)

    def _note_load(self, t: np.ndarray, src: np.ndarray, stop: int) -> None:
        """The newest load sample is the one before index ``stop`` of the slab (if any)."""
        if stop > 0:
            self.last["load_t_ns"], self.last["load_src"] = int(t[stop - 1]), int(src[stop - 1])

    def _load_by_tick(self, t: np.ndarray, v: np.ndarray, ticks: _SlabTicks
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The load samples of the slab's ticks (the first with those earlier slabs left for
        it) and each tick's start and stop in them."""
        o_t, o_v, _ = self.open_tick
        end = ticks.cuts[ticks.n - 1]
        stops = np.array(ticks.cuts[:ticks.n], np.int64) + o_t.shape[0]
        return (np.concatenate([o_t, t[:end]]), np.concatenate([o_v, v[:end]]),
                np.concatenate([np.zeros(1, np.int64), stops[:-1]]), stops)

    def _stream_ticks(self, s: str, ends: np.ndarray, streams: Mapping[str, _StreamSlab]
                      ) -> StreamTicks:
        """Health of stream ``s`` at each of the slab's tick ends, as ``_stream_one`` gives
        it tick by tick (the first tick with the counts earlier slabs left for it). An idle
        stream's totals are the hand-over's: the validator may be a slab further on."""
        val, n = self._totals[s], ends.shape[0]
        info = streams.get(s)
        if info is None:  # nothing new on this stream
            received, rejected = np.zeros(n, np.int64), np.zeros(n, np.int64)
            if val.has_last:
                last = np.full(n, val.last_t_ns, np.int64)
                stale = ends - last > self._stale_ns[s]
            else:  # never seen (the usual idle stream): stale, and no time
                last, stale = np.zeros(n, np.int64), np.ones(n, bool)
        else:
            received, rejected, has, last = info.tick_arrays
            if info.has_all:  # (the usual slab)
                stale = ends - last > self._stale_ns[s]
            else:  # (a stream never seen is stale whatever its age, even where ends - last wraps)
                stale = ~has | (ends - last > self._stale_ns[s])
                last = np.where(has, last, 0)
        if s in self.tick_counts:
            if info is not None:  # the slab's own arrays: not to be written to
                received, rejected = received.copy(), rejected.copy()
            received[0] += self.tick_counts[s][0]
            rejected[0] += self.tick_counts[s][1]
        return StreamTicks(last, stale, received, rejected)

    def _tick_view(self, k: int, t: np.ndarray, v: np.ndarray, src: np.ndarray,
                   ticks: _SlabTicks) -> tuple[np.ndarray, np.ndarray, np.ndarray, _TickLoad, int]:
        """The slab's ``k``-th tick: its load samples (the first with those an earlier slab
        left for it), and the load figures holding it with its index there."""
        assert ticks.load is not None  # prepared whenever the ticks are evaluated
        start = ticks.cuts[k - 1] if k else 0
        stop = ticks.cuts[k]
        tt, tv, ts = t[start:stop], v[start:stop], src[start:stop]
        if k == 0 and self.open_tick[0].shape[0]:  # the tick began in an earlier slab
            tt, tv, ts = (np.concatenate([o, x]) for o, x in zip(self.open_tick, (tt, tv, ts)))
            tick = _TickLoad(tv, ts, self.stresses(tv), np.zeros(1, np.int64), np.full(1, tv.shape[0]))
            return tt, tv, ts, tick, 0
        return tt, tv, ts, ticks.load, k

    def _evaluate_tick(self, k: int, t: np.ndarray, v: np.ndarray, src: np.ndarray,
                       streams: Mapping[str, "_StreamSlab"], ticks: _SlabTicks,
                       figures: Mapping[str, TickRun]) -> tuple[int, int, float, float]:
        """The alert rules at the end of the slab's ``k``-th tick; returns the tick's
        damage-split row (measured samples, samples, measured mean, estimated mean)."""
        tt, tv, _, tick, j = self._tick_view(k, t, v, src, ticks)
        load = tick.lists
        est_mean = ticks.est_means[k] if ticks.est_means is not None else load.est[j]
        self._evaluate(k, ticks.ends_l[k], tt, tv, tick, j, streams, figures, est_mean)
        return load.n_meas[j], load.n[j], load.meas[j], est_mean

    def _carry_estimate(self, estimate: tuple[np.ndarray, np.ndarray] | None,
                        ends: np.ndarray) -> None:
        """Full-estimate mode (``estimate`` given): keep the motion estimates after the last
        tick end for the tick still open."""
        if estimate is None:
            return
        e_t, e_v = estimate
        rest = int(np.searchsorted(e_t, ends[-1], side="right")) if ends.shape[0] else 0
        base = _NO_LOAD[:2] if ends.shape[0] else self.open_estimate
        self.open_estimate = (np.concatenate([base[0], e_t[rest:]]),
                              np.concatenate([base[1], e_v[rest:]]))

    def _keep_open_tick(self, t: np.ndarray, v: np.ndarray, src: np.ndarray,
                        stresses: Mapping[str, np.ndarray], streams: Mapping[str, "_StreamSlab"],
                        ticks: _SlabTicks, closed: Mapping[str, list[tuple[np.ndarray, ...]]]
                        ) -> None:
        """The samples after the last tick end: their cycles close now but are committed at
        that tick's end; their load and each stream's counts wait for the tick's evaluation."""
        start = ticks.cuts[ticks.n - 1] if ticks.n else 0
        stop = ticks.cuts[ticks.n]
        if stop > start:
            fed = self._per_counting(lambda name, c: c.feed(stresses[name][start:stop]))
            for name, cycles in fed.items():
                closed[name].append(cycles)
            o_t, o_v, o_src = self.open_tick
            self.open_tick = (np.concatenate([o_t, t[start:]]), np.concatenate([o_v, v[start:]]),
                              np.concatenate([o_src, src[start:]]))
        prev_end = ticks.ends_l[-1] if ticks.n else _NEVER
        for s, info in streams.items():
            # what this slab adds to the tick still open
            received, rej = info.counts_after(prev_end)
            counts = self.tick_counts.setdefault(s, [0, 0])
            counts[0] += received
            counts[1] += rej

    def _estimate_means(self, e_t: np.ndarray, e_v: np.ndarray, ends: np.ndarray) -> list[float]:
        """Mean motion estimate in each tick ending at ``ends`` (the first one with the
        estimates an earlier slab left for it), each reduced as ``_seq_mean`` reduces it:
        split invariant."""
        cuts = np.searchsorted(e_t, ends, side="right")
        starts = np.append(0, cuts[:-1])
        n = cuts - starts
        full = np.flatnonzero(n > 0)
        # the non-empty ticks are back to back: one reduction for all of them
        sums = np.add.reduceat(e_v[:int(cuts[full[-1]]) if full.shape[0] else 0], starts[full])
        means = np.full(ends.shape[0], math.nan)
        means[full] = sums / n[full]
        out = means.tolist()
        if out and self.open_estimate[0].shape[0]:
            out[0] = _seq_mean(np.concatenate([self.open_estimate[1], e_v[:int(cuts[0])]]))
        return out

    def _evaluate(self, k: int, end: int, t: np.ndarray, v: np.ndarray, tick_load: _TickLoad,
                  j: int, streams: Mapping[str, _StreamSlab],
                  figures: Mapping[str, TickRun], estimated: float) -> None:
        """Evaluate the alert rules at the end of the slab's ``k``-th tick (``tick_load``'s
        ``j``-th); ``figures[name].figures[k]`` are each component's (damage,
        damage_committed, rate, life) at that tick's end, ``estimated`` the tick's mean
        motion estimate."""
        load = tick_load.lists
        obs = Observation(
            buoy_id=self.buoy_id, t_ns=end, tick_s=self.tick_ns / 1e9,
            load_source=self._source_at(end), load_t_ns=t, tension_N=v,
            measured_tension_N=load.meas[j], estimated_tension_N=estimated,
            components={n: ComponentObs(*f.figures[k], load.smax[n][j])
                        for n, f in figures.items()},
            streams=_LazyStreams(self, end, streams, k),
            tension_range_N=(load.vmin[j], load.vmax[j]),
        )
        for hook in self._tick_hooks:
            hook(obs)
        records = self.alerts.evaluate(obs)
        learner, forecasts = self.sea_states, self.forecasts
        if learner is not None and forecasts is not None:
            committed = {n: c.damage_committed for n, c in obs.components.items()}
            learner.tick(end, committed, load.n[j])
            if forecasts.due(end):
                records = [*records, *forecasts.apply(end, committed, learner.table)]
        self._emit(records)

    def _emit(self, records: list[Any]) -> None:
        """Alert records (a tick's, or the re-sends of a run of quiet ticks), in order, for
        the step's result and the alert history."""
        for rec in records:
            self.new_alerts.append(rec)
            self.alert_history.append(alert_to_dict(rec))
        if len(self.alert_history) > ALERT_HISTORY_LIMIT:
            self.alerts_dropped += len(self.alert_history) - ALERT_HISTORY_LIMIT
            del self.alert_history[:-ALERT_HISTORY_LIMIT]

    def _stream_obs(self, now: int) -> dict[str, StreamObs]:
        """Stream health of every stream at any time ``now`` (totals, no tick counts)."""
        return {s: self._stream_one(s, now, None, 0) for s in self.validators}

    def _stream_one(self, s: str, now: int, streams: Mapping[str, _StreamSlab] | None,
                    k: int) -> StreamObs:
        """Health of stream ``s`` at ``now`` (the end of the slab's ``k``-th tick, or any time
        when ``streams`` is None): totals up to ``now`` and counts within the tick."""
        val = self.validators[s] if streams is None else self._totals[s]
        stale_ns = self._stale_ns[s]
        info = None if streams is None else streams.get(s)
        if info is not None:
            obs = info.tick(k, now, stale_ns)
        else:  # nothing new on this stream: reuse the last answer while it holds
            stale = not val.has_last or now - val.last_t_ns > stale_ns
            key = (val.accepted, val.last_t_ns, stale, sum(val.rejected.values()))
            cached = self._idle_obs.get(s)
            if cached is not None and cached[0] == key:
                obs = cached[1]
            else:
                obs = StreamObs(
                    last_t_ns=val.last_t_ns if val.has_last else 0, stale=stale,
                    accepted=val.accepted, rejected=dict(val.rejected),
                    rejected_in_tick=0, received_in_tick=0)
                self._idle_obs[s] = (key, obs)
        if k == 0 and streams is not None and s in self.tick_counts:
            # samples of earlier slabs that fell into this same tick
            received, rejected = self.tick_counts.pop(s)
            obs = dataclasses.replace(obs, received_in_tick=obs.received_in_tick + received,
                                      rejected_in_tick=obs.rejected_in_tick + rejected)
        return obs

    def _step(self, sensor: str, t: np.ndarray, v: np.ndarray,
              stresses: Mapping[str, np.ndarray],
              parts: Mapping[str, list[tuple[np.ndarray, ...]]], n_acc: int,
              rejected: Mapping[str, int],
              qc: Mapping[str, Mapping[str, Mapping[str, int]]]) -> StepResult:
        # each component's closed cycles (ranges, means, counts); a component counting as an
        # earlier one closed the same
        closed = self._per_counting(lambda name, c: [_joined(p) for p in zip(*parts[name])])
        comps = {}
        counting: dict[str, Mapping[str, float]] = {}  # of each component counting
        for name, comp in self.components.items():
            lead = self._counts_as.get(name, name)
            if lead not in counting:
                counting[lead] = comp.counting_figures()
            f = comp.figures(counting[lead])
            r, m, c = closed[name]
            comps[name] = ComponentStep(
                name=name, stress_Pa=stresses[name], ranges_Pa=r, means_Pa=m, counts=c,
                damage=f["damage"], damage_committed=f["damage_committed"],
                damage_rate_per_day=f["damage_rate_per_day"],
                remaining_life_days=f["remaining_life_days"], max_stress_Pa=f["max_stress_Pa"],
            )
        nan = math.nan
        return StepResult(
            buoy_id=self.buoy_id, sensor=sensor, now_ns=self.last["now_ns"], t_ns=t, tension_N=v,
            load_source=self.last["source"],
            measured_tension_N=nan if self.last["measured_N"] is None else self.last["measured_N"],
            estimated_tension_N=nan if self.last["estimated_N"] is None else self.last["estimated_N"],
            components=comps, accepted=n_acc, rejected=dict(rejected),
            alerts=list(self.new_alerts), qc=qc,
            windows=self.sea_states.take_windows() if self.sea_states is not None else [],
            forecasts=self.forecasts.take_new() if self.forecasts is not None else [],
        )

    # ------------------------------------------------------------------ outputs
    def status(self) -> dict[str, Any]:
        """Current figures for the daemon's periodic status message (JSON-serialisable)."""
        now = self.last["now_ns"]
        return {
            "buoy_id": self.buoy_id,
            "now_ns": now,
            "load_source": self.last["source"],
            "load_t_ns": self.last["load_t_ns"],  # newest load sample that fed fatigue
            "measured_tension_N": self.last["measured_N"],
            "estimated_tension_N": self.last["estimated_N"],
            "estimates_clamped": self.selector.estimates_clamped,
            "samples_above_break": dict(self.selector.above_break),
            "motion_sensor": self.motion_sensor,
            "motion_rate": self.estimator.rate_figures() if self.estimator is not None else None,
            "load_problems": self.load_problems(),
            "components": {n: {**{k: _finite_or_none(x) for k, x in c.figures().items()},
                               "damage_by_source": self.damage_split.figures(
                                   n, c.figures()["damage_committed"])}
                           for n, c in self.components.items()},
            "streams": {s: {"last_t_ns": o.last_t_ns, "stale": o.stale, "accepted": o.accepted,
                            "rejected": dict(o.rejected),
                            "qc": self.validators[s].qc_counts()}
                        for s, o in self._stream_obs(now).items()},
            "buffered_samples": self.reorder.buffered(),
            "next_tick_ns": self.next_tick_ns,
            **self._forecast_figures(),
        }

    def _forecast_figures(self) -> dict[str, Any]:
        """The learned table's coverage and the last forecast (status and report)."""
        if self.sea_states is None or self.forecasts is None:
            return {}
        return {"sea_state_table": self.sea_states.summary(),
                "forecast": self.forecasts.status()}

    def report(self) -> dict[str, Any]:
        """The replay report's pipeline part (see replay.report for the full contract)."""
        return {
            "buoy_id": self.buoy_id,
            "time_start_ns": self.last["time_start_ns"],
            "time_end_ns": self.last["time_end_ns"],
            "samples": {s: {"accepted": val.accepted, "rejected": dict(val.rejected),
                            "qc": val.qc_counts()}
                        for s, val in self.validators.items()
                        if val.accepted or any(val.rejected.values())},
            "tension_N": {**self.stats.summary(),
                          "samples_estimate_clamped": self.selector.estimates_clamped,
                          "samples_above_break": sum(self.selector.above_break.values()),
                          "samples_estimate_above_break": self.selector.above_break["estimated"]},
            "load_source": self.last["source"],
            "motion_sensor": self.motion_sensor,
            "motion_rate": self.estimator.rate_figures() if self.estimator is not None else None,
            "load_problems": self.load_problems(),
            "components": {n: {**{k: _finite_or_none(x) for k, x in c.figures().items()},
                               "damage_by_source": self.damage_split.figures(
                                   n, c.figures()["damage_committed"])}
                           for n, c in self.components.items()},
            "alerts": list(self.alert_history),
            "alerts_dropped": self.alerts_dropped,
            **self._forecast_figures(),
            **({"spectral_windows": list(self.sea_states.history)}
               if self.sea_states is not None else {}),
        }

    def state(self) -> dict[str, Any]:
        """Everything needed to continue exactly from here (JSON-serialisable)."""
        return {
            "version": STATE_VERSION,
            "buoy_id": self.buoy_id,
            "components": {n: c.state() for n, c in self.components.items()},
            "validators": {s: v.state() for s, v in self.validators.items()},
            "load": self.selector.state(),
            "estimator": self.estimator.state() if self.estimator is not None else None,
            "motion_sensor": self.motion_sensor,
            "damage_split": self.damage_split.state(),
            "reorder": self.reorder.state(),
            "alerts": self.alerts.state(),
            "stats": self.stats.state(),
            "taken_upto": dict(self.taken_upto),
            "processed_ns": self.processed_ns,
            "late_copies": self.late_copies.state(),
            "next_tick_ns": self.next_tick_ns,
            "sample_tick_ns": self.sample_tick_ns,
            "tick_counts": {s: list(c) for s, c in self.tick_counts.items()},
            "open_tick": [a.tolist() for a in self.open_tick],
            "open_estimate": [a.tolist() for a in self.open_estimate],
            "last": dict(self.last),
            "alert_history": list(self.alert_history),
            "alerts_dropped": self.alerts_dropped,
            "sea_states": self.sea_states.state() if self.sea_states is not None else None,
            "forecasts": self.forecasts.state() if self.forecasts is not None else None,
        }


def _build_forecasting(config: Config, components: Mapping[str, Component], tick_s: float,
                       st: Mapping[str, Any]) -> tuple[SeaStateLearner | None,
                                                       ForecastAlerts | None]:
    """The ``[forecast]`` learner and forecast alerts (None, None when switched off)."""
    cfg = config.forecast
    if not cfg.enabled:
        return None, None
    prior = None
    if cfg.table is not None and not st.get("sea_states"):
        prior = load_forecast_table(config, cfg.table)
    curves = {n: c.sn_curve for n, c in components.items()}
    try:
        learner = SeaStateLearner(cfg, curves, tick_s, prior, st.get("sea_states"))
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    return learner, ForecastAlerts(cfg, config.buoy.id, tuple(curves), st.get("forecasts"))


def load_forecast_table(config: Config, path: str) -> DamageRateTable:
    """A saved table, its path relative to the configuration file's directory."""
    p = Path(path)
    if not p.is_absolute() and config.source and not config.source.startswith("<"):
        p = Path(config.source).resolve().parent / p
    try:
        return DamageRateTable.from_state(json.loads(p.read_text()))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        detail = (f"no {exc}: not a table written by buoymon forecast --save-table"
                  if isinstance(exc, KeyError) else exc)
        raise ConfigError(f"config error: forecast.table = {path!r}: {detail}") from None
