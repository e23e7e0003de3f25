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

import functools
from typing import Any, Mapping, Protocol

import numpy as np

from monitor import model_cache
from monitor.config import Config, LoadConfig, MooringConfig

MEASURED, ESTIMATED = 1, 2
SOURCE_NAMES = {0: "none", MEASURED: "measured", ESTIMATED: "estimated"}


class MotionEstimator(Protocol):
    """What the pipeline needs from a motion -> tension estimator (adapter over models.estimator)."""

    def feed(self, t_ns: np.ndarray, fields: Mapping[str, np.ndarray],
             want: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Accepted motion samples in time order -> ``(t_ns, tension_N, clamped)`` of the
        estimate; only the samples in the boolean mask ``want`` (all if None) get a value, the
        others are NaN. ``clamped`` marks estimates of motion outside the model's range, held
        at the value at its edge."""
        ...

    def state(self) -> dict[str, Any]: ...


@functools.lru_cache(maxsize=8)
def _estimator_model(mooring: MooringConfig, dt: float) -> tuple[Any, Any]:
    """(EstimatorConfig, quasi-static model): pure and costly (a catenary tension table, about
    a second), so built once per mooring and step, shared by every estimator and kept in the
    on-disk model cache for the next process."""
    return model_cache.cached("estimator", (mooring, dt), lambda: _build_model(mooring, dt))


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


class _ModelsEstimator:
    """Adapter over ``models.estimator.MotionTensionEstimator`` for one motion stream.

    The model works on a fixed time step (``[load] motion_rate_hz``); samples it flags as
    SETTLING (the IMU integrator warming up, a stream's first samples) give no estimate.
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

    def __init__(self, est_module: Any, model: Any, sensor: str, gap_ns: float,
                 last_t_ns: int | None) -> None:
        self._flags = est_module.Flag
        self.model, self.sensor = model, sensor
        self.gap_ns, self.last_t_ns = gap_ns, last_t_ns

    def feed(self, t_ns: np.ndarray, fields: Mapping[str, np.ndarray],
             want: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        if self.sensor == "imu":
            e = self.model.update_accel(fields["accel_x_mps2"], fields["accel_y_mps2"],
                                        fields["accel_z_mps2"], want=want)
            flags, tension = e.flags, e.tension
        else:
            flags, tension = self._displacements(t_ns, fields, want)
        if t_ns.shape[0]:
            self.last_t_ns = int(t_ns[-1])
        ok = (flags & np.uint8(self._flags.SETTLING)) == 0
        clamped = (flags & np.uint8(self._flags.OUT_OF_RANGE)) != 0
        return t_ns[ok], np.asarray(tension, dtype=np.float64)[ok], clamped[ok]

    def _displacements(self, t_ns: np.ndarray, fields: Mapping[str, np.ndarray],
                       want: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The model over the stretches between gaps, restarted at each gap."""
        n = t_ns.shape[0]
        last = self.last_t_ns if self.last_t_ns is not None else (int(t_ns[0]) if n else 0)
        cuts = np.flatnonzero(np.diff(t_ns, prepend=np.int64(last)) > self.gap_ns).tolist()
        bounds = sorted({0, *cuts, n})
        flags, tension = [], []
        for a, b in zip(bounds[:-1], bounds[1:]) if n else [(0, 0)]:
            if cuts and a == cuts[0]:
                cuts.pop(0)
                self.model.restart()
            e = self.model.update(fields["heave_m"][a:b], fields["surge_m"][a:b],
                                  fields["sway_m"][a:b], want=None if want is None else want[a:b])
            flags.append(e.flags)
            tension.append(e.tension)
        if len(flags) == 1:
            return flags[0], tension[0]
        return np.concatenate(flags), np.concatenate(tension)

    def state(self) -> dict[str, Any]:
        return {**self.model.state.to_dict(), "last_t_ns": self.last_t_ns}


def build_estimator(config: Config, state: Mapping[str, Any] | None = None,
                    sensor: str | None = None) -> MotionEstimator:
    """The motion estimator of ``config``'s mooring for the motion stream ``sensor`` ("imu" or
    "motion"; default ``[load] motion_sensor``, imu for "auto"), continuing from ``state``.

    The seed 004 preset uses ``models.estimator.seed004_estimator``; a line given as segments
    uses ``catenary_estimator`` with drag on its top segment's diameter (C_D 1.2) and an in-air
    mass per metre estimated from the submerged weight of steel-like line (weight / g x 1.15).
    """
    from models import estimator

    est_cfg, quasi_static = _estimator_model(config.mooring, 1.0 / config.load.motion_rate_hz)
    saved = None if not state else estimator.EstimatorState.from_dict(dict(state))
    model = estimator.MotionTensionEstimator(est_cfg, quasi_static, saved)
    configured = config.load.motion_sensor
    sensor = sensor or ("imu" if configured == "auto" else configured)
    last = None if not state or state.get("last_t_ns") is None else int(state["last_t_ns"])
    return _ModelsEstimator(estimator, model, sensor,
                            config.validate[sensor].stale_after_s * 1e9, last)


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
        if self.mode == "estimated":
            return np.ones(e_t.shape, bool)
        if self.mode == "measured" or e_t.shape[0] == 0:
            return np.zeros(e_t.shape, bool)
        prev = self.last_measured_ns
        if (m_t.shape[0] and prev is not None and int(m_t[0]) - prev <= self.stale_ns
                and (m_t.shape[0] == 1 or int(np.max(m_t[1:] - m_t[:-1])) <= self.stale_ns)):
            # the usual case, the cell alive all along: only estimates more than stale_after_s
            # past its newest sample are needed (the general rule below gives the same)
            return e_t - m_t[-1] > self.stale_ns
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
        use = self.needed(m_t, e_t)
        if e_clamped is not None:
            self.estimates_clamped += int(np.count_nonzero(use & e_clamped))
        if self.mode != "estimated":
            self.above_break["measured"] += int(np.count_nonzero(m_v > self.breaking_N))
        self.above_break["estimated"] += int(np.count_nonzero(use & (e_v > self.breaking_N)))
        if self.mode == "estimated":
            return e_t, e_v, np.full(e_t.shape, ESTIMATED, np.int8)
        if m_t.shape[0]:
            self.last_measured_ns = int(m_t[-1])
        measured = (m_t, m_v, np.full(m_t.shape, MEASURED, np.int8))
        if not use.any():
            return measured
        t = np.concatenate([m_t, e_t[use]])
        v = np.concatenate([m_v, e_v[use]])
        src = np.concatenate([measured[2], np.full(int(use.sum()), ESTIMATED, np.int8)])
        order = np.argsort(t, kind="stable")
        return t[order], v[order], src[order]

    def state(self) -> dict[str, Any]:
        return {"last_measured_ns": self.last_measured_ns,
                "estimates_clamped": self.estimates_clamped,
                "above_break": dict(self.above_break)}
