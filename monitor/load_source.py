"""Which load feeds fatigue: the measured tension, or the motion estimate when the cell is stale.

``[load] source``:

``measured``   the accepted load-cell samples only;
``estimated``  the motion -> tension estimate (models.estimator) only;
``auto``       the load cell while it is fresh and good, the estimate while it is not.

The ``auto`` rule, per estimated sample at time ``e``: it is used if and only if no ACCEPTED
tension sample lies in ``[e - stale_after_s, e]``. Measured samples are always used. So each
stretch of time is fed by exactly one source (no double counting): the cell's samples where it
is alive, the estimate inside gaps (silence or runs of rejected samples) longer than
``stale_after_s``, and nothing in the first ``stale_after_s`` of a gap. The decision for ``e``
only needs the tension stream up to ``e``, which the ordering watermark guarantees, so it is the
same for any split of the data into blocks.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, Mapping, Protocol

import numpy as np

from models._jit import kernel
from monitor import model_cache
from monitor.config import Config, LoadConfig, MooringConfig
from monitor.motion_rate import GAP, RESUME, STEP, WITHHOLD, MotionRate

MEASURED, ESTIMATED = 1, 2
SOURCE_NAMES = {0: "none", MEASURED: "measured", ESTIMATED: "estimated"}


class MotionEstimator(Protocol):
    """What the pipeline needs from a motion -> tension estimator (adapter over models.estimator)."""

    def feed(self, t_ns: np.ndarray, fields: Mapping[str, np.ndarray],
             want: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Accepted motion samples in time order -> ``(t_ns, tension_N, clamped)`` of the
        estimate of the samples in the boolean mask ``want`` (all if None) and, NaN if not
        wanted, of the newest sample of each run between the stream's rate events (the
        block's newest dates the stream's newest estimate); settling samples give none.
        ``clamped`` marks estimates of motion outside the model's range, held at the value at
        its edge."""
        ...

    def state(self) -> dict[str, Any]: ...

    def rate_figures(self) -> dict[str, Any]:
        """The step in use and the spacing mismatches (monitor.motion_rate.MotionRate.figures)."""
        ...


@functools.lru_cache(maxsize=8)
def _estimator_model(mooring: MooringConfig) -> tuple[Any, Any]:
    """(EstimatorConfig, quasi-static model) of the mooring, at a placeholder step (the stream
    sets it: :func:`_at_step`): pure and costly (a catenary tension table, about a second), so
    built once per mooring, shared by every estimator and kept in the on-disk model cache
    for the next process."""
    return model_cache.cached("estimator", (mooring,), lambda: _build_model(mooring, 1.0))


def _at_step(mooring: MooringConfig, dt: float) -> tuple[Any, Any]:
    """The mooring's estimator configuration at the step ``dt`` (s) and its quasi-static model
    (nothing in either but ``dt`` depends on the step)."""
    est_cfg, quasi_static = _estimator_model(mooring)
    return dataclasses.replace(est_cfg, dt=dt), quasi_static


def _build_model(m: MooringConfig, dt: float) -> tuple[Any, Any]:
    from models import catenary, estimator

    if m.preset == "vaps_seed004":
        return estimator.seed004_estimator(dt=dt, span=m.span_m)
    line = catenary.Line(segments=tuple(
        catenary.Segment(s.length_m, s.weight_N_per_m, s.ea_N, s.name) for s in m.segments))
    mass = sum(abs(s.weight_N_per_m) * s.length_m for s in m.segments) / m.length_m / 9.81
    return estimator.catenary_estimator(
        line, m.span_m, m.depth_m, dt, mass_per_length=1.15 * mass, drag_cd=1.2,
        drag_diameter=m.segments[-1].diameter_m)


_EMPTY = (np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool))


@kernel(nogil=True)
def _longest_step(t_ns):  # pragma: no cover - compiled
    """The longest interval between consecutive times (0 for fewer than two)."""
    longest = 0
    for i in range(1, t_ns.shape[0]):
        longest = max(longest, t_ns[i] - t_ns[i - 1])
    return longest


class _ModelsEstimator:
    """Adapter over ``models.estimator.MotionTensionEstimator`` for one motion stream.

    The model works on a fixed time step, the stream's own (:mod:`monitor.motion_rate`: under
    ``[load] motion_rate_hz = "auto"`` measured from its first samples, which wait for it;
    under a configured rate the samples of a stream spaced otherwise are withheld, counted);
    the model is built once the step is known, and afresh when it changes. Samples it flags
    as SETTLING (the IMU integrator warming up, a stream's first samples) give no estimate.
    Samples it flags OUT_OF_RANGE (a position outside its tension table) keep the tension at
    the table's edge, marked ``clamped``: in a storm these are the buoy's largest excursions,
    the line near taut, and leaving them out would understate fatigue; the
    :class:`LoadSelector` counts the ones that feed fatigue, so the report shows them.

    A gap in the accepted displacement samples longer than the stream's ``stale_after_s``
    (silence, or a run of QC rejections) restarts the model: its velocities and accelerations
    are differences of consecutive samples, and across a gap they are none (the Spotter
    record's 501 s gap ends in a displacement filter reset, 17 m from the last position:
    differenced as one step, 445 kN). The two samples after the gap settle (no estimate).
    """

    def __init__(self, mooring: MooringConfig, sensor: str, rate: MotionRate,
                 state: Mapping[str, Any] | None) -> None:
        from models import estimator

        self._est, self.mooring, self.sensor, self.rate = estimator, mooring, sensor, rate
        self._fields = _FIELDS[sensor]
        st = dict(state or {})
        # samples that arrived before the step was known ("auto"): rows of their fields
        self.pending: list[list[float]] = [list(r) for r in st.pop("pending", [])]
        st.pop("rate", None)
        st.pop("last_t_ns", None)
        self.model: Any = None
        self.waiting = rate.dt is None
        if rate.dt is not None and not rate.withholding:
            saved = estimator.EstimatorState.from_dict(st) if st else None
            self.model = estimator.MotionTensionEstimator(*_at_step(mooring, rate.dt), saved)

    def feed(self, t_ns: np.ndarray, fields: Mapping[str, np.ndarray],
             want: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = t_ns.shape[0]
        events = self.rate.plan(t_ns)
        bounds = sorted({0, n, *(i for i, _, _ in events)})
        parts = []
        k = 0
        for a, b in zip(bounds[:-1], bounds[1:]):
            while k < len(events) and events[k][0] == a:  # in order: they apply from sample a
                self._event(events[k][1], events[k][2])
                k += 1
            part = self._run(t_ns[a:b], {f: fields[f][a:b] for f in self._fields},
                             None if want is None else want[a:b])
            if part[0].shape[0]:
                parts.append(part)
        if len(parts) <= 1:
            return parts[0] if parts else _EMPTY
        return tuple(np.concatenate(x) for x in zip(*parts))  # type: ignore[return-value]

    def _event(self, kind: str, dt: float | None) -> None:
        if kind == GAP:
            if self.model is None:
                self.pending = []  # the spacing so far was another stretch's (the rate forgot it)
            elif self.sensor == "motion":
                self.model.restart()
        elif (kind == STEP or kind == RESUME) and dt is not None:
            self.waiting = False
            self.model = self._est.MotionTensionEstimator(*_at_step(self.mooring, dt))
            if self.pending:  # a stream's first samples: they only settle the model
                rows = np.asarray(self.pending, dtype=np.float64).T
                self.pending = []
                self._update(dict(zip(self._fields, rows)), None)
        elif kind == WITHHOLD:
            self.model = None

    def _run(self, t_ns: np.ndarray, fields: Mapping[str, np.ndarray],
             want: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.model is None:
            if self.waiting:  # the step is not known yet: the samples wait for it
                self.pending += np.column_stack([fields[k] for k in self._fields]).tolist()
            return _EMPTY  # (else withheld: the stream is not at the configured rate)
        newest_unwanted = False
        if want is not None and not want[-1]:  # estimated all the same, returned as NaN
            want, newest_unwanted = want.copy(), True
            want[-1] = True
        # the wanted samples' estimates only (compact), in order
        flags, tension = self._update(fields, want)
        if want is not None:
            t_ns = t_ns[want]
        # the model flags a block's first samples only as SETTLING
        settled = 0
        if flags.shape[0] and flags[0] & self._est.Flag.SETTLING:
            settled = int(np.count_nonzero(flags & np.uint8(self._est.Flag.SETTLING)))
        clamped = (flags[settled:] & np.uint8(self._est.Flag.OUT_OF_RANGE)) != 0
        if newest_unwanted and flags.shape[0] > settled:
            tension[-1], clamped[-1] = np.nan, False
        return t_ns[settled:], tension[settled:], clamped

    def _update(self, fields: Mapping[str, np.ndarray],
                want: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """(flags, tension) of the wanted samples (all if ``want`` is None)."""
        if self.sensor == "imu":
            e = self.model.update_accel(fields["accel_x_mps2"], fields["accel_y_mps2"],
                                        fields["accel_z_mps2"], want=want, compact=True)
        else:
            e = self.model.update(fields["heave_m"], fields["surge_m"], fields["sway_m"],
                                  want=want, compact=True)
        return e.flags, e.tension

    def rate_figures(self) -> dict[str, Any]:
        return self.rate.figures()

    def state(self) -> dict[str, Any]:
        model = {} if self.model is None else self.model.state.to_dict()
        return {**model, "pending": [list(r) for r in self.pending],
                "rate": self.rate.state()}


_FIELDS = {"imu": ("accel_x_mps2", "accel_y_mps2", "accel_z_mps2"),
           "motion": ("heave_m", "surge_m", "sway_m")}


def build_estimator(config: Config, state: Mapping[str, Any] | None = None,
                    sensor: str | None = None) -> MotionEstimator:
    """The motion estimator of ``config``'s mooring for the motion stream ``sensor`` ("imu" or
    "motion"; default ``[load] motion_sensor``, imu for "auto"), continuing from ``state``,
    on the stream's time step (``[load] motion_rate_hz``, :mod:`monitor.motion_rate`).

    The seed 004 preset uses ``models.estimator.seed004_estimator``; a line given as segments
    uses ``catenary_estimator`` with drag on its top segment's diameter (C_D 1.2) and an in-air
    mass per metre estimated from the submerged weight of steel-like line (weight / g x 1.15).
    The tension table is built now (it does not depend on the step).
    """
    _estimator_model(config.mooring)
    configured = config.load.motion_sensor
    sensor = sensor or ("imu" if configured == "auto" else configured)
    setting = config.load.motion_rate_hz
    st = dict(state or {})
    rate_state = st.get("rate")
    if rate_state is None and st:  # a checkpoint from before the rate was tracked
        # its model ran at motion_rate_hz, 10 Hz when that was the default
        rate_state = {"dt": 1.0 / float(setting) if setting != "auto" else 0.1,
                      "last_t_ns": st.get("last_t_ns")}
    rate = MotionRate(None if setting == "auto" else float(setting),
                      config.validate[sensor].stale_after_s * 1e9, rate_state)
    return _ModelsEstimator(config.mooring, sensor, rate, st)


class LoadSelector:
    """Merges measured and estimated tension into the one fatigue load series."""

    def __init__(self, cfg: LoadConfig, state: Mapping[str, Any] | None = None) -> None:
        self.mode = cfg.source
        self.stale_ns = int(round(cfg.stale_after_s * 1e9))
        self.last_measured_ns: int | None = None
        self.estimates_clamped = 0  # clamped estimates (see MotionEstimator.feed) used
        self.breaking_N = cfg.breaking_load_N
        # load samples used above the breaking load, by source: the line would have parted
        # (measured) or the estimate left the range where it means anything (estimated)
        self.above_break = {"measured": 0, "estimated": 0}
        if state is not None:
            if state["last_measured_ns"] is not None:
                self.last_measured_ns = int(state["last_measured_ns"])
            self.estimates_clamped = int(state.get("estimates_clamped", 0))
            self.above_break.update(state.get("above_break", {}))

    def needed(self, m_t: np.ndarray, e_t: np.ndarray) -> np.ndarray:
        """Boolean mask of the estimated samples at times ``e_t`` that :meth:`select` will
        use with the measured times ``m_t`` of the same slab (pure: nothing changes)."""
        use = self._use(m_t, e_t)
        if isinstance(use, np.ndarray):
            return use
        mask = np.zeros(e_t.shape, bool)
        mask[use:] = True
        return mask

    def _use(self, m_t: np.ndarray, e_t: np.ndarray) -> int | np.ndarray:
        """:meth:`needed` as the index from which on every estimate is used (the usual
        case), or as the mask. Both series are strictly increasing (accepted samples)."""
        if self.mode == "estimated":
            return 0
        if self.mode == "measured" or e_t.shape[0] == 0:
            return e_t.shape[0]
        prev = self.last_measured_ns
        if (m_t.shape[0] and prev is not None and int(m_t[0]) - prev <= self.stale_ns
                and _longest_step(m_t) <= self.stale_ns):
            # the usual case, the cell alive all along: only estimates more than stale_after_s
            # past its newest sample are needed (the general rule below gives the same)
            return int(np.searchsorted(e_t, m_t[-1] + np.int64(self.stale_ns), side="right"))
        # latest accepted tension time at or before each estimated sample
        idx = np.searchsorted(m_t, e_t, side="right") - 1
        never = idx < 0
        latest = m_t[np.maximum(idx, 0)] if m_t.shape[0] else np.zeros(e_t.shape, np.int64)
        if self.last_measured_ns is not None:
            latest = np.where(never, np.int64(self.last_measured_ns), latest)
            never[:] = False
        return never | (e_t - latest > self.stale_ns)

    def select(self, m_t: np.ndarray, m_v: np.ndarray, e_t: np.ndarray, e_v: np.ndarray,
               e_clamped: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(t_ns, tension_N, source)`` in time order; ``source`` is MEASURED or ESTIMATED.
        The estimates used that ``e_clamped`` marks are counted in ``estimates_clamped``."""
        use = self._use(m_t, e_t)
        if isinstance(use, np.ndarray):
            if e_clamped is not None:
                self.estimates_clamped += int(np.count_nonzero(use & e_clamped))
            self.above_break["estimated"] += int(np.count_nonzero(use & (e_v > self.breaking_N)))
            used_t, used_v = e_t[use], e_v[use]
        else:  # the estimates from index ``use`` on
            if e_clamped is not None:
                self.estimates_clamped += int(np.count_nonzero(e_clamped[use:]))
            self.above_break["estimated"] += int(np.count_nonzero(e_v[use:] > self.breaking_N))
            used_t, used_v = e_t[use:], e_v[use:]
        if self.mode != "estimated":
            self.above_break["measured"] += int(np.count_nonzero(m_v > self.breaking_N))
        if self.mode == "estimated":
            return e_t, e_v, np.full(e_t.shape, ESTIMATED, np.int8)
        if m_t.shape[0]:
            self.last_measured_ns = int(m_t[-1])
        measured = (m_t, m_v, np.full(m_t.shape, MEASURED, np.int8))
        if not used_t.shape[0]:
            return measured
        t = np.concatenate([m_t, used_t])
        v = np.concatenate([m_v, used_v])
        src = np.concatenate([measured[2], np.full(used_t.shape[0], ESTIMATED, np.int8)])
        if not m_t.shape[0] or m_t[-1] < used_t[0]:  # already in time order
            return t, v, src
        order = np.argsort(t, kind="stable")
        return t[order], v[order], src[order]

    def state(self) -> dict[str, Any]:
        return {"last_measured_ns": self.last_measured_ns,
                "estimates_clamped": self.estimates_clamped,
                "above_break": dict(self.above_break)}
