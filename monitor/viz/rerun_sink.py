"""Rerun sink: logs pipeline output to a Rerun recording in bulk (``rr.send_columns``).

The same sink serves live runs and replay; only :class:`~monitor.viz.rerun_options.RerunOptions`
(sampling intervals) and the recording's sinks (file, viewer) differ. Data is buffered per entity
and sent as columns when ``flush_samples`` input samples or ``flush_interval_s`` wall-clock seconds
have accumulated, so logging costs a few numpy operations per step and one Rerun call per entity
per flush; memory is bounded by the flush thresholds.

Timelines: ``sensor_time`` (timestamp, ns since the epoch) and ``sample`` (index of the load
sample since the sink started). Entities (display units as the report's page and terminal:
kN for tension, MPa for stress; the unit is in each series' display name):

==================================  ==========================  =============================
entity                              archetype                   content
==================================  ==========================  =============================
``tension/load``                    Scalars [min, max]          load used for fatigue (kN),
                                                                envelope per ``envelope_s``
``tension/measured``                Scalars                     measured tension (kN)
``tension/estimated``               Scalars                     motion estimate (kN)
``tension/source``                  StateChange                 measured / estimated / none
``stress/<component>``              Scalars [min, max]          conductor stress (MPa)
``damage/<component>/committed``    Scalars                     Miner sum of closed cycles
``damage/<component>/provisional``  Scalars                     committed + open residue
``damage_rate/<component>``         Scalars                     damage per day (1/d)
``remaining_life/<component>``      Scalars                     remaining life (d), capped at
                                                                1,000 years (infinite too)
``rainflow/<component>/histogram``  BarChart                    cumulative cycle counts per
                                                                stress-range bin (x: MPa)
``rainflow/<component>/range_mean`` Tensor (range x mean)       cumulative range-mean counts
``alerts/state/<rule>/<component>`` StateChange                 ok / info / warning / critical
``alerts/log``                      TextLog (levels)            one line per alert transition
``health/<sensor>/accepted``        Scalars                     accepted samples (total)
``health/<sensor>/rejected``        Scalars                     rejected samples (total)
``health/<sensor>/state``           StateChange                 ok / stale (from alert ticks)
``health/<sensor>/qc/<test>/<flag>`` Scalars                    QARTOD suspect / fail flags of
                                                                the test (total)
``position/buoy``                   Points2D                    buoy east/north of anchor (m)
``position/anchor``, ``position/watch_circle``  Points2D / LineStrips2D (static)
``mooring/line``                    LineStrips3D                cable shape (m, z up)
``spectral/<component>/rainflow``   Scalars                     damage of each closed sea-state
``spectral/<component>/dirlik``     Scalars                     window: rainflow, Dirlik
``spectral_flags/<component>``      StateChange                 agree / flagged (the factor)
``sea_state/hs_m``, ``/tp_s``       Scalars                     each window's Hs (m), Tp (s)
``forecast/<component>/damage_end`` Scalars                     projected damage at a forecast's
(``_low``, ``_high``)                                           end, at the time it was applied
==================================  ==========================  =============================

Rows are logged at sensor times of the data: the slow rows (damage, health, histograms, shape)
at the step's newest load sample, none before the first sample any block carried, so the
``sensor_time`` timeline spans the replayed data and no panel opens empty.

With ``envelope_s = 0`` the ``tension/load`` and ``stress/*`` entities hold every sample as a
single scalar instead of a [min, max] pair.

Feeding the sink: :meth:`RerunSink.on_step` for every pipeline step (alert transitions in
``step.alerts`` are logged from there), :meth:`RerunSink.on_block` for raw GNSS blocks (buoy
position), :meth:`RerunSink.on_observation` at alert ticks (stale lanes), and
:meth:`RerunSink.on_alert` only for records that do not travel in a step (e.g. an operator reset).
"""

from __future__ import annotations

import functools
import logging
import math
import re
import threading
import time
from collections import defaultdict
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import pyarrow as pa
import rerun as rr

from monitor.blocks import SampleBlock
from monitor.events import Observation, StepResult
from monitor.viz.alert_view import alert_fields
from monitor.viz.cycle_histogram import CycleHistogram
from monitor.viz.human import DAYS_PER_YEAR, LONG_LIFE_YEARS
from monitor.viz.rerun_options import RerunOptions

log = logging.getLogger(__name__)

SENSOR_TIME = "sensor_time"
SAMPLE = "sample"

# A cable-shape provider: top tension (N) -> (x, z) arrays in metres, x horizontal from the
# anchor towards the buoy, z up from the anchor (see monitor.viz.cable_shape).
ShapeProvider = Callable[[float], tuple[np.ndarray, np.ndarray]]

LONG_LIFE_DAYS = LONG_LIFE_YEARS * DAYS_PER_YEAR  # remaining lives are drawn up to this
_TEXT_LEVEL = {"critical": "CRITICAL", "warning": "WARN", "info": "INFO"}
_EARTH_RADIUS_M = 6_371_008.8  # mean Earth radius (IUGG); local tangent-plane approximation


def entity_part(name: str) -> str:
    """``name`` made safe as one entity-path part (component, sensor, rule names)."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", str(name)) or "_"


def local_east_north(lat_deg: np.ndarray, lon_deg: np.ndarray, lat0_deg: float,
                     lon0_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """East/north metres of WGS84 points from an origin (equirectangular tangent plane; the
    error is far below GNSS noise over a watch circle of a few hundred metres)."""
    lat0 = math.radians(lat0_deg)
    east = np.radians(np.asarray(lon_deg) - lon0_deg) * _EARTH_RADIUS_M * math.cos(lat0)
    north = np.radians(np.asarray(lat_deg) - lat0_deg) * _EARTH_RADIUS_M
    return east, north


def _locked(method):
    """Run a sink method under the sink's (re-entrant) lock."""

    @functools.wraps(method)
    def locked(self, *args, **kwargs):
        with self._lock:
            return method(self, *args, **kwargs)

    return locked


class _ArrowBatch:
    """A prebuilt arrow array presented as a Rerun component batch (for batched tensors,
    which the Python encoder only accepts one at a time)."""

    def __init__(self, descriptor: Any, array: pa.Array) -> None:
        self._descriptor = descriptor
        self._array = array

    def as_arrow_array(self) -> pa.Array:
        return self._array

    def component_descriptor(self) -> Any:
        return self._descriptor


class _Rows:
    """Buffered rows of one entity: sensor times, sample indices and values."""

    __slots__ = ("t", "n", "v")

    def __init__(self) -> None:
        self.t: list[Any] = []
        self.n: list[Any] = []
        self.v: list[Any] = []

    def add(self, t_ns: int, sample: int, value: Any) -> None:
        self.t.append(t_ns)
        self.n.append(sample)
        self.v.append(value)

    def take(self) -> tuple[np.ndarray, np.ndarray, list[Any]]:
        t, n, v = np.asarray(self.t, dtype=np.int64), np.asarray(self.n, dtype=np.int64), self.v
        self.t, self.n, self.v = [], [], []
        return t, n, v


class _HighRate:
    """Buffered high-rate series sharing one time base (the step's load samples): the load and
    every component's stress. Reduced on flush to a min/max envelope per bin, or sent as is.

    Samples of the last (possibly incomplete) envelope bin are carried to the next flush so a
    bin is never split between two rows. Sample indices are consecutive from ``first``.
    """

    def __init__(self) -> None:
        self.t: list[np.ndarray] = []
        self.v: dict[str, list[np.ndarray]] = defaultdict(list)
        self.first = 0  # sample index of the first buffered sample
        self.count = 0

    def add(self, t_ns: np.ndarray, first_sample: int, values: Mapping[str, np.ndarray]) -> None:
        """One step's samples; every entity already buffered must be in ``values``."""
        n = len(t_ns)
        if not n:
            return
        if not self.t:
            self.first = first_sample
        for entity in self.v.keys() | values.keys():
            if entity not in self.v:  # a series that starts late: NaN-pad what came before
                self.v[entity] = [np.full(self.count, np.nan)] if self.count else []
            self.v[entity].append(np.asarray(values.get(entity, np.full(n, np.nan)),
                                             dtype=np.float64))
        self.t.append(t_ns)
        self.count += n

    def take(self, bin_ns: int, final: bool
             ) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
        """Rows per entity (entity, t, sample, values); values (k,) or (k, 2) for an envelope."""
        if not self.t:
            return []
        t = np.concatenate(self.t)
        n = np.arange(self.first, self.first + len(t), dtype=np.int64)
        v = {e: np.concatenate(parts) for e, parts in self.v.items()}
        self.t, self.v, self.count = [], defaultdict(list), 0
        if len(t) > 1 and not np.all(t[1:] >= t[:-1]):  # the pipeline emits sensor-time order;
            order = np.argsort(t, kind="stable")       # stay correct (and deterministic) if not
            t, n = t[order], n[order]
            v = {e: x[order] for e, x in v.items()}
        if bin_ns <= 0:
            out = []
            for e, x in v.items():
                ok = np.isfinite(x)
                out.append((e, t[ok], n[ok], x[ok]))
            return out
        # first sample of every occupied bin, by bisection on the sorted times (cheaper than
        # dividing every sample)
        edges = np.arange(t[0] // bin_ns, t[-1] // bin_ns + 1, dtype=np.int64) * bin_ns
        starts = np.searchsorted(t, edges)
        starts = starts[np.concatenate(([True], np.diff(starts) > 0)) & (starts < len(t))]
        if not final:  # keep the open (last) bin for the next flush
            last = int(starts[-1])
            self.add(t[last:], int(n[last]), {e: x[last:] for e, x in v.items()})
            t, n, starts = t[:last], n[:last], starts[:-1]
            if not len(t):
                return []
        bin_t = t[starts] // bin_ns * bin_ns
        out = []
        for e, x in v.items():
            # fmin/fmax skip NaN; a bin with no finite sample stays NaN and is dropped
            env = np.column_stack((np.fmin.reduceat(x[:len(t)], starts),
                                   np.fmax.reduceat(x[:len(t)], starts)))
            ok = np.isfinite(env[:, 0])
            out.append((e, bin_t[ok], n[starts][ok], env[ok]))
        return out


class RerunSink:
    """A pipeline sink writing to a Rerun recording stream (see the module docstring).

    Args:
        recording: an open ``rr.RecordingStream`` with its sinks set (see
            :func:`monitor.viz.rerun_outputs.open_recording`).
        options: sampling and layout settings.
        shape_provider: top tension -> cable profile, drawn as ``mooring/line``; None: no 3D view.
        send_blueprint: send the default dashboard layout once the component names are known.
        own_recording: :meth:`close` also flushes and disconnects the recording.
    """

    def __init__(self, recording: rr.RecordingStream, options: RerunOptions | None = None, *,
                 shape_provider: ShapeProvider | None = None, send_blueprint: bool = True,
                 own_recording: bool = True) -> None:
        self.rec = recording
        self.opt = options or RerunOptions()
        self._shape = shape_provider
        self._want_blueprint = send_blueprint
        self._own = own_recording
        self._env_ns = int(round(self.opt.envelope_s * 1e9))
        self._slow_ns = int(round(self.opt.slow_interval_s * 1e9))
        self._snap_ns = int(round(self.opt.snapshot_interval_s * 1e9))
        self._shape_ns = int(round(self.opt.shape_interval_s * 1e9))
        self._range_edges = np.asarray(self.opt.range_edges_Pa, dtype=float)
        self._mean_edges = np.asarray(self.opt.mean_edges_Pa, dtype=float)
        self._high = _HighRate()
        self._rows: dict[tuple[str, str], _Rows] = defaultdict(_Rows)  # (entity, kind) -> rows
        self._hist: dict[str, CycleHistogram] = {}
        self._styled: set[str] = set()
        self._life_named: set[str] = set()
        self._health: dict[str, list[int]] = {}  # sensor -> [accepted, rejected]
        self._qc: dict[str, Any] = {}  # sensor -> {test: {"suspect": n, "fail": n}} totals
        self._alert_state: dict[str, str] = {}  # state lane -> last state logged
        self._source = ""
        self._samples = 0
        self._now_ns = 0  # sensor time the sink's slow rows are logged at (see _row_time)
        self._first_data_ns: int | None = None  # first sample of any raw block
        self._next_slow = self._next_snap = self._next_shape = self._last_snap = 0
        self._last_fix: tuple[int, float, float] | None = None
        self._origin: tuple[float, float] | None = None
        if math.isfinite(self.opt.anchor_lat_deg) and math.isfinite(self.opt.anchor_lon_deg):
            self._set_origin(self.opt.anchor_lat_deg, self.opt.anchor_lon_deg)
        self._pending = 0
        self._last_flush = time.monotonic()
        self._closed = False
        # the daemon may deliver alerts or ticks from another thread than the steps
        self._lock = threading.RLock()

    # ---- Sink interface -------------------------------------------------------------------

    wants_qc = True  # the pipeline fills StepResult.qc for this sink

    @_locked
    def on_step(self, step: StepResult) -> None:
        """Buffer one step's output; flush when the thresholds are reached."""
        if self._closed:
            raise ValueError("RerunSink.on_step called after close()")
        comps = {entity_part(n): c for n, c in step.components.items()}
        if self._want_blueprint and comps:
            from monitor.viz.blueprint import default_blueprint

            self.rec.send_blueprint(default_blueprint(sorted(comps)))
            self._want_blueprint = False
        n0, n = self._samples, len(step.t_ns)
        self._samples += n
        t = self._row_time(step)
        if t is not None:
            self._now_ns = max(self._now_ns, t)
        # display units, as the report's page and terminal: kN, MPa
        high = {"tension/load": step.tension_N / 1e3}
        high.update({f"stress/{name}": c.stress_Pa / 1e6 for name, c in comps.items()})
        self._high.add(step.t_ns, n0, high)
        for name, comp in comps.items():
            hist = self._hist.get(name)
            if hist is None:
                hist = self._hist[name] = CycleHistogram(self._range_edges, self._mean_edges)
                self._log_bar_axis(name)
            hist.add(comp.ranges_Pa, comp.means_Pa, comp.counts)
        health = self._health.setdefault(entity_part(step.sensor), [0, 0])
        health[0] += int(step.accepted)
        health[1] += int(sum(step.rejected.values()))
        for sensor, counts in step.qc.items():
            self._qc[entity_part(sensor)] = counts
        for record in step.alerts:
            self.on_alert(record)
        for window in step.windows:
            self._log_window(window)
        for projection in step.forecasts:
            self._log_forecast(projection)
        if t is None:  # before the first sample: nothing to show yet
            self._pending += n + 1
            self._maybe_flush()
            return
        t = self._now_ns
        if step.load_source != self._source:
            self._source = step.load_source
            self._rows[("tension/source", "state")].add(t, self._samples, step.load_source)
        if t >= self._next_slow:
            self._sample_slow(step, comps)
            self._next_slow = self._next_after(t, self._slow_ns)
        if t >= self._next_snap and self._hist:
            self._snapshot_histograms(t)
            self._next_snap = self._next_after(t, self._snap_ns)
        if self._shape is not None and t >= self._next_shape:
            if self._log_shape(step, t):
                self._next_shape = self._next_after(t, self._shape_ns)
        self._pending += n + 1
        self._maybe_flush()

    @_locked
    def on_block(self, block: SampleBlock) -> None:
        """Raw sensor blocks the pipeline does not summarise in a step: GNSS positions."""
        if len(block):
            first = int(block.t_ns.min())
            if self._first_data_ns is None or first < self._first_data_ns:
                self._first_data_ns = first
        if block.sensor != "gnss" or not len(block):
            return
        lat, lon = block.fields["lat_deg"], block.fields["lon_deg"]
        # NaN or out-of-range fixes (the validator normally rejects them) are not drawn
        ok = (np.abs(lat) <= 90.0) & (np.abs(lon) <= 180.0)
        if not ok.any():
            return
        i = int(np.flatnonzero(ok)[-1])
        if self._origin is None:
            self._set_origin(float(lat[i]), float(lon[i]))
        # logged on the slow grid by the next step, at the fix's own time
        self._last_fix = (int(block.t_ns[i]), float(lat[i]), float(lon[i]))

    @_locked
    def on_observation(self, obs: Observation) -> None:
        """Sensor staleness at an alert-evaluation tick, as ok/stale lanes (logged on change)."""
        for sensor, stream in obs.streams.items():
            lane = f"health/{entity_part(sensor)}/state"
            state = "stale" if stream.stale else "ok"
            if self._alert_state.get(lane) != state:
                self._alert_state[lane] = state
                self._rows[(lane, "state")].add(int(obs.t_ns), self._samples, state)

    @_locked
    def on_alert(self, record: Any) -> None:
        """Log one alert transition: a state lane per (rule, component) and a text-log line."""
        a = alert_fields(record)
        lane = f"alerts/state/{entity_part(a['rule'])}/{entity_part(a['component'])}"
        state = a["severity"] if a["state"] == "firing" else "ok"
        if self._alert_state.get(lane) != state:
            self._alert_state[lane] = state
            self._rows[(lane, "state")].add(a["at_ns"], self._samples, state)
        level = _TEXT_LEVEL.get(a["severity"], "INFO") if a["state"] == "firing" else "INFO"
        text = f"[{a['event'] or a['state']}] {a['rule']}/{a['component']}: {a['summary']}"
        self._rows[("alerts/log", "text")].add(a["at_ns"], self._samples, (text, level))
        self._pending += 1

    @_locked
    def flush(self, final: bool = False) -> None:
        """Send everything buffered to Rerun (``final`` also closes the open envelope bins)."""
        for hist in self._hist.values():
            hist.update()
        for entity, t, n, v in self._high.take(self._env_ns, final):
            if len(t):
                self._style(entity, v.ndim == 2)
                self._send(entity, t, n, rr.Scalars.columns(scalars=v))
        for (entity, kind), rows in self._rows.items():
            if rows.t:
                self._send_rows(entity, kind, *rows.take())
        self._pending = 0
        self._last_flush = time.monotonic()

    @_locked
    def close(self) -> None:
        """Flush everything (including a last snapshot) and, if owned, close the recording."""
        if self._closed:
            return
        if self._hist and self._now_ns > self._last_snap:
            self._snapshot_histograms(self._now_ns)
        if self._last_fix is not None:
            self._log_position()
        if self._want_blueprint:  # no component ever seen: still give the viewer a layout
            from monitor.viz.blueprint import default_blueprint

            self.rec.send_blueprint(default_blueprint([]))
        self.flush(final=True)
        self._closed = True
        if self._own:
            try:
                self.rec.flush()
            except RuntimeError as exc:  # its file writer failed (a full disk): an I/O
                # error, which the command line reports in one line
                raise OSError(f"Rerun recording not written whole: {exc}") from None
            self.rec.disconnect()

    # ---- internals --------------------------------------------------------------------------

    def _row_time(self, step: StepResult) -> int | None:
        """Sensor time for the step's slow rows (damage, health, histograms, shape): its
        newest load sample, or ``step.now_ns`` when later (live). The replay's ``now_ns`` is
        its processing horizon, which lags the data by the reorder window: rows there would
        start the timeline before the first sample. None while that time precedes the data."""
        t = int(step.now_ns)
        if len(step.t_ns):
            t = max(t, int(step.t_ns.max()))
        if self._first_data_ns is not None and t < self._first_data_ns:
            return None
        return t

    @staticmethod
    def _next_after(t_ns: int, interval_ns: int) -> int:
        return (t_ns // interval_ns + 1) * interval_ns if interval_ns > 0 else t_ns + 1

    def _maybe_flush(self) -> None:
        if (self._pending >= self.opt.flush_samples
                or time.monotonic() - self._last_flush >= self.opt.flush_interval_s):
            self.flush()

    def _log_window(self, w: Mapping[str, Any]) -> None:
        """One closed sea-state window: rainflow and Dirlik damage per component (the
        spectral cross-check), a flag lane, and the window's Hs and Tp."""
        t, s = int(w["end_ns"]), self._samples
        for name, rainflow in w["rainflow"].items():
            part = entity_part(name)
            self._rows[(f"spectral/{part}/rainflow", "scalar")].add(t, s, float(rainflow))
            if w["dirlik"][name] is not None:
                self._rows[(f"spectral/{part}/dirlik", "scalar")].add(t, s, float(w["dirlik"][name]))
            lane = f"spectral_flags/{part}"
            state = "flagged" if name in w["flagged"] else "agree"
            if self._alert_state.get(lane) != state:
                self._alert_state[lane] = state
                self._rows[(lane, "state")].add(t, s, state)
        for key in ("hs_m", "tp_s"):
            if w[key] is not None:
                self._rows[(f"sea_state/{key}", "scalar")].add(t, s, float(w[key]))
        self._pending += 1

    def _log_forecast(self, p: Mapping[str, Any]) -> None:
        """A forecast applied: per component the projected damage at the forecast's end
        with its band, at the sensor time it was applied."""
        t, s = int(p["applied_ns"]), self._samples
        for name, c in p["components"].items():
            for key in ("damage_end", "damage_end_low", "damage_end_high"):
                if c[key] is not None and math.isfinite(c[key]):
                    self._rows[(f"forecast/{entity_part(name)}/{key}", "scalar")].add(
                        t, s, float(c[key]))
        self._pending += 1

    def _sample_slow(self, step: StepResult, comps: Mapping[str, Any]) -> None:
        t, s = self._now_ns, self._samples
        for entity, value in (("tension/measured", step.measured_tension_N),
                              ("tension/estimated", step.estimated_tension_N)):
            if math.isfinite(value):
                self._rows[(entity, "scalar")].add(t, s, float(value) / 1e3)  # kN
        for name, c in comps.items():
            if name not in self._life_named:
                self._life_named.add(name)
                self.rec.log(f"remaining_life/{name}", rr.SeriesLines(
                    names=[f"{name} [d] (more than {LONG_LIFE_YEARS:,.0f} years at the cap)"]),
                    static=True)
            # as the report says "more than 1,000 years", a 4e107-day life (a curve's tail)
            # is drawn at that cap, where it would otherwise flatten every other line
            life = min(c.remaining_life_days, LONG_LIFE_DAYS)
            for entity, value in ((f"damage/{name}/committed", c.damage_committed),
                                  (f"damage/{name}/provisional", c.damage),
                                  (f"damage_rate/{name}", c.damage_rate_per_day),
                                  (f"remaining_life/{name}", life)):
                if math.isfinite(value):
                    self._rows[(entity, "scalar")].add(t, s, float(value))
        for sensor, (acc, rej) in self._health.items():
            self._rows[(f"health/{sensor}/accepted", "scalar")].add(t, s, float(acc))
            self._rows[(f"health/{sensor}/rejected", "scalar")].add(t, s, float(rej))
        for sensor, tests in self._qc.items():
            for test, flags in tests.items():
                for flag, n in flags.items():
                    self._rows[(f"health/{sensor}/qc/{test}/{flag}", "scalar")].add(t, s, float(n))
        if self._last_fix is not None:
            self._log_position()
            self._last_fix = None

    def _set_origin(self, lat: float, lon: float) -> None:
        self._origin = (lat, lon)
        self.rec.log("position/anchor", rr.Points2D([[0.0, 0.0]], radii=[1.0], labels=["anchor"]),
                     static=True)
        r = self.opt.watch_circle_m
        if r > 0:
            a = np.linspace(0.0, 2 * np.pi, 181)
            self.rec.log("position/watch_circle",
                         rr.LineStrips2D([np.column_stack((r * np.sin(a), r * np.cos(a)))]),
                         static=True)

    def _log_position(self) -> None:
        assert self._last_fix is not None and self._origin is not None
        t, lat, lon = self._last_fix
        e, n = local_east_north(np.array([lat]), np.array([lon]), *self._origin)
        self._rows[("position/buoy", "point2d")].add(t, self._samples, (float(e[0]), float(n[0])))

    def _log_bar_axis(self, name: str) -> None:
        """The histogram bars' x axis in MPa, as the report's: static bin centres and widths
        (as component batches: ``BarChart.from_fields`` cannot leave the values out)."""
        edges = self._range_edges / 1e6
        self.rec.log(f"rainflow/{name}/histogram", [
            rr.components.TensorDataBatch(rr.TensorData(array=(edges[:-1] + edges[1:]) / 2))
            .described(rr.BarChart.descriptor_abscissa()),
            rr.components.LengthBatch(np.diff(edges)).described(rr.BarChart.descriptor_widths()),
        ], static=True)

    def _snapshot_histograms(self, t_ns: int) -> None:
        self._last_snap = t_ns
        for name, hist in self._hist.items():
            hist.update()
            self._rows[(f"rainflow/{name}/histogram", "bars")].add(t_ns, self._samples,
                                                                  hist.counts.copy())
            self._rows[(f"rainflow/{name}/range_mean", "tensor")].add(t_ns, self._samples,
                                                                      hist.matrix.copy())

    def _log_shape(self, step: StepResult, t_ns: int) -> bool:
        tension = float(step.tension_N[-1]) if len(step.tension_N) else math.nan
        if not math.isfinite(tension):
            tension = next((v for v in (step.measured_tension_N, step.estimated_tension_N)
                            if math.isfinite(v)), math.nan)
        if not math.isfinite(tension):
            return False
        try:
            x, z = self._shape(tension)  # type: ignore[misc]
        except ValueError as exc:  # e.g. a tension the line model cannot reach: skip the frame
            log.debug("cable shape skipped", extra={"fields": {"tension_N": tension,
                                                               "error": str(exc)}})
            return False
        b = math.radians(self.opt.bearing_deg)
        pts = np.column_stack((np.asarray(x) * math.sin(b), np.asarray(x) * math.cos(b),
                               np.asarray(z))).astype(np.float32)
        self._rows[("mooring/line", "strip3d")].add(t_ns, self._samples, pts)
        return True

    def _style(self, entity: str, envelope: bool) -> None:
        if entity in self._styled:
            return
        self._styled.add(entity)
        unit = "kN" if entity.startswith("tension") else "MPa"
        label = entity.split("/", 1)[-1]
        names = [f"{label} min [{unit}]", f"{label} max [{unit}]"] if envelope else [
            f"{label} [{unit}]"]
        self.rec.log(entity, rr.SeriesLines(names=names), static=True)

    def _send(self, entity: str, t: np.ndarray, n: np.ndarray, columns: Any) -> None:
        rr.send_columns(
            entity,
            indexes=[rr.TimeColumn(SENSOR_TIME, timestamp=t.view("datetime64[ns]")),
                     rr.TimeColumn(SAMPLE, sequence=n)],
            columns=columns,
            recording=self.rec,
        )

    def _send_rows(self, entity: str, kind: str, t: np.ndarray, n: np.ndarray,
                   v: list[Any]) -> None:
        if kind == "scalar":
            cols = rr.Scalars.columns(scalars=np.asarray(v, dtype=np.float64))
        elif kind == "state":
            cols = rr.StateChange.columns(state=[str(x) for x in v])
        elif kind == "text":
            cols = rr.TextLog.columns(text=[x[0] for x in v], level=[x[1] for x in v])
        elif kind == "point2d":
            cols = rr.Points2D.columns(positions=np.asarray(v, dtype=np.float32))
        elif kind == "strip3d":
            cols = rr.LineStrips3D.columns(strips=v).partition(np.ones(len(v), dtype=np.int32))
        elif kind in ("bars", "tensor"):
            cols = [self._tensor_column(kind, v)]
        else:  # pragma: no cover - kinds are fixed above
            raise ValueError(f"unknown row kind {kind!r}")
        self._send(entity, t, n, cols)

    @staticmethod
    def _tensor_column(kind: str, arrays: Sequence[np.ndarray]) -> rr.ComponentColumn:
        if kind == "bars":
            desc = rr.BarChart.descriptor_values()
            parts = [rr.components.TensorDataBatch(rr.TensorData(array=a)) for a in arrays]
        else:
            desc = rr.Tensor.descriptor_data()
            parts = [rr.components.TensorDataBatch(
                rr.TensorData(array=a, dim_names=["stress_range", "stress_mean"]))
                for a in arrays]
        array = pa.concat_arrays([p.as_arrow_array() for p in parts])
        return rr.ComponentColumn(desc, _ArrowBatch(desc, array))
