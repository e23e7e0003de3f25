"""The damage-rate table learned inside the pipeline, with the per-window spectral cross-check.

Sensor time is cut into windows of ``[forecast] window_s`` on a fixed grid (window ``k``
covers ``((k-1) W, k W]``, like the alert ticks, of which it is a whole number). At the end
of each window, per component:

* the **rainflow damage** of the window is the committed damage at its end minus that at its
  start (the pipeline's own Miner sum: the same cycles, the same S-N curve);
* its **sea state** is the mean Hs and Tp of the accepted ``waves`` samples inside it, else
  the newest earlier sample if at most ``waves_max_age_s`` old at the window's end;
* with at least ``min_coverage`` of the window covered by load samples (alert ticks holding
  one), the window is added to :class:`models.sea_state_table.DamageRateTable` with the
  covered hours;
* the **Dirlik damage** of the window's stress (Welch PSD of Hann-windowed, non-overlapping
  segments of ``SEGMENT`` load samples, :class:`models.fatigue.spectral.Periodograms`; a
  segment's rate is taken from its samples' times, and a segment whose rate differs from the
  window's first by more than 2 % spans a gap and is left out) times the covered seconds is
  set beside the rainflow damage; a window where they differ by more than
  ``spectral_flag_factor`` either way is flagged (non-Gaussian or non-stationary load).

Everything is a function of the samples in sensor-time order: the pipeline feeds the
accepted waves samples and the load samples of each slab before the ticks the slab
completes, and a window closes at a tick end, when every sample up to it has been seen; so
the table is the same for any block split, and :meth:`state` restores it exactly.

The inputs (the spectra of the open windows, the new waves samples) belong to the
pipeline's stream stage, the windows' closing to its tick stage: the one hands a slab's
inputs over (:meth:`SeaStateLearner.hand_over`) and the other takes them
(:meth:`SeaStateLearner.receive`) before the slab's ticks, so the stream stage may already
be feeding the next slab while the ticks close windows.
"""

from __future__ import annotations

import functools
import math
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from models.sea_state_table import HS_EDGES_M, TP_EDGES_S, DamageRateTable
from models.fatigue._spectral_loops import steady_segments, window_segments
from models.fatigue.spectral import Periodograms, damage_rate_from_psd, hann
from models.waves import sea_state_from_psd
from monitor.forecast_config import ForecastConfig

SEGMENT = 1024  # load samples per PSD segment: 51 s at 20 Hz (0.02 Hz resolution)
WINDOW_HISTORY = 2000  # closed windows kept for the report (about 6 weeks of 30 min)
_RATE_TOLERANCE = 0.02
_WAVE_F_MAX_HZ = 0.5  # the wave band's top for Hs and Tp from motion (models.waves)
_COMPARE_FLOOR = 1e-12  # both damages below this: nothing to compare (a calm window)
_BATCH_ROWS = 128  # segments transformed per batch (buffers of about 2.6 MB per signal set)
_SPARE_BUFFERS = 2  # closed windows' segment buffers kept for new windows


class _Spectra:
    """Welch PSD sums of one window's stress, per component, segment by segment.

    Feeding keeps each whole segment, its mean removed and the Hann window applied
    (``rows``: signal x segment x sample, ready for the FFT); the
    periodograms are added to the sums (``acc``) when the window's spectrum is asked for
    (:meth:`summed`), all the kept segments in a few large batches rather than a small one
    per slab; the additions are the same, one segment after another in time order.

    Signals whose samples have all been equal to the bit so far (``same[i]``: the first
    such signal; components of the same stress, as the default conductor and termination
    are) keep and transform their segments once: same inputs, same operations, same bits.
    """

    def __init__(self, names: Sequence[str], state: Mapping[str, Any] | None = None,
                 room: int = 0, rows: np.ndarray | None = None) -> None:
        st = state or {}
        self.names = tuple(names)
        self.index: int | None = st.get("index")
        self.fs: float | None = st.get("fs")
        self.segments = int(st.get("segments", 0))
        self.dropped = int(st.get("dropped", 0))
        self.t = np.array(st.get("t", []), np.int64)  # the open segment's samples
        self.x = {n: np.array(st.get("x", {}).get(n, []), float) for n in self.names}
        psd = st.get("psd", {})
        # the sums of the segments added so far (a sum starts at 0.0: 0.0 + p is p)
        self.acc = np.zeros((len(self.names), SEGMENT // 2 + 1))
        if psd:
            self.acc[:] = [psd[n] for n in self.names]
        # segments kept, rows[:, added:filled] not yet added; a snapshot shares the buffer
        # (feeding only writes rows past its own ``filled``; a full buffer is replaced);
        # ``rows``: a closed window's buffer to reuse (no new pages to fault in)
        self.rows = (rows if rows is not None and rows.shape[1] >= room
                     else np.empty((len(self.names), room, SEGMENT)))
        self.added = self.filled = 0
        # a new window's signals are taken as one until their samples differ; a restored
        # one's as different (replaced, never changed in place: a snapshot shares it)
        self.same = [0] * len(self.names) if state is None else list(range(len(self.names)))

    def feed(self, t: np.ndarray, stresses: Mapping[str, np.ndarray]) -> None:
        """Samples in time order: every segment they complete is kept for the sums."""
        self._part(stresses)  # every sample compared, the open segment's too
        nc = self.t.shape[0]  # the open segment's samples come first
        full = (nc + t.shape[0]) // SEGMENT * SEGMENT  # of the open and new samples
        if not full:
            self.t = np.concatenate([self.t, t])
            self.x = {n: np.concatenate([self.x[n], stresses[n]]) for n in self.names}
            return
        count = full // SEGMENT
        taken = np.empty(count, np.int64)
        # a segment spanning a gap (its rate off the window's first) is dropped
        kept, fs = steady_segments(t, nc, int(self.t[0]) if nc else 0, count, SEGMENT,
                                   math.nan if self.fs is None else self.fs, _RATE_TOLERANCE,
                                   taken)
        if self.fs is None and math.isfinite(fs):
            self.fs = float(fs)
        self.dropped += count - kept
        taken = taken[:kept]
        if kept:
            rows = self._room(taken.shape[0])
            for i, n in enumerate(self.names):
                if self.same[i] == i:  # kept detrended and windowed, ready for the FFT
                    window_segments(rows[i], taken, self.x[n],
                                    np.asarray(stresses[n], np.float64), _window())
            self.filled += taken.shape[0]
        self.segments += taken.shape[0]
        self.t = t[full - nc:].astype(np.int64)
        self.x = {n: stresses[n][full - nc:].astype(float) for n in self.names}

    def _part(self, stresses: Mapping[str, np.ndarray]) -> None:
        """Signals taken as one whose new samples differ get their own kept segments (a copy
        of the ones they shared; their sums so far are equal)."""
        if all(j == i for i, j in enumerate(self.same)):
            return
        same = list(self.same)
        for i, n in enumerate(self.names):
            j = same[i]
            if j != i and not _same_bits(stresses[n], stresses[self.names[j]]):
                self.rows[i, self.added:self.filled] = self.rows[j, self.added:self.filled]
                same[i] = i
        self.same = same

    def _room(self, m: int) -> np.ndarray:
        """The rows for ``m`` more segments (a larger buffer when full: the kept segments
        not yet added move to its start)."""
        if self.filled + m > self.rows.shape[1]:
            keep = self.rows[:, self.added:self.filled]
            rows = np.empty((len(self.names), max(2 * self.rows.shape[1], keep.shape[1] + m),
                             SEGMENT))
            rows[:, :keep.shape[1]] = keep
            self.rows, self.added, self.filled = rows, 0, keep.shape[1]
        return self.rows[:, self.filled:self.filled + m]

    def summed(self, work: Periodograms) -> "_Spectra":
        """Itself with every kept segment added to the sums (in ``work``'s buffers; the
        sums are a new array: a snapshot may share the old one)."""
        if self.added == self.filled:
            return self
        self.acc = self.acc.copy()
        own = [i for i, j in enumerate(self.same) if i == j]
        for lo, hi in _runs(own):  # signals lo..hi-1 together
            per = work.max_rows // (hi - lo)  # segments of each signal per batch
            for a in range(self.added, self.filled, per):
                b = min(a + per, self.filled)
                work.add(self.rows[lo:hi], a, b, self.fs,  # type: ignore[arg-type]
                         self.acc[lo:hi])
        for i, j in enumerate(self.same):
            self.acc[i] = self.acc[j]
        self.added = self.filled
        return self

    def sums(self) -> dict[str, np.ndarray]:
        """The PSD sum of each signal (empty before the first segment)."""
        if not self.segments:
            return {}
        if self.added < self.filled:
            # room for at least one segment of every signal, as _WindowSpectra's work
            self.summed(Periodograms(SEGMENT, max(_BATCH_ROWS, len(self.names))))
        return {n: self.acc[i] for i, n in enumerate(self.names)}

    def mean_psd(self, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        """(frequencies, mean PSD) of the window, None without a whole segment."""
        if not self.segments or self.fs is None:
            return None
        return _frequencies(self.fs), self.sums()[name] / self.segments

    def dirlik_rate(self, name: str, curve: Any) -> float:
        """Damage per second from the window's mean PSD (NaN without a whole segment)."""
        spec = self.mean_psd(name)
        if spec is None or not np.any(spec[1][1:] > 0):
            return math.nan
        return damage_rate_from_psd(curve, spec[0][1:], spec[1][1:])

    def sea_state(self, name: str, accel: bool) -> tuple[float, float] | None:
        """(Hs, Tp) of the window from a heave PSD, or an acceleration PSD divided by
        (2 pi f)^4 (0 at f = 0) (:func:`models.waves.sea_state_from_psd`); None without one."""
        spec = self.mean_psd(name)
        if spec is None:
            return None
        f, psd = spec
        if accel:  # in place: psd is the new array of the mean
            np.divide(psd[1:], _omega4(self.fs)[1:], out=psd[1:])  # type: ignore[arg-type]
            psd[0] = 0.0
        try:
            ss = sea_state_from_psd(f, psd, f_max=min(_WAVE_F_MAX_HZ, float(f[-1])))
        except ValueError:  # too short a segment for the band, or no wave energy
            return None
        return ss.hs, ss.tp

    def snapshot(self) -> "_Spectra":
        """A copy that later feeding leaves as it is: feed replaces the open segment's
        arrays and writes kept segments past the copy's, and :meth:`summed` replaces the
        sums, so the copy shares every array (a shallow copy, made directly: copy.copy's
        generic path cost more than the rest of a slab's hand-over)."""
        out = _Spectra.__new__(_Spectra)
        out.__dict__.update(self.__dict__)
        return out

    def state(self) -> dict[str, Any]:
        return {"index": self.index, "fs": self.fs, "segments": self.segments,
                "dropped": self.dropped, "t": self.t.tolist(),
                "x": {n: v.tolist() for n, v in self.x.items()},
                "psd": {n: v.tolist() for n, v in self.sums().items()}}


@functools.lru_cache(maxsize=8)
def _frequencies(fs: float) -> np.ndarray:
    """The segments' PSD frequencies at ``fs`` (read-only; a window's rate rarely changes)."""
    f = np.fft.rfftfreq(SEGMENT, 1.0 / fs)
    f.flags.writeable = False
    return f


@functools.lru_cache(maxsize=1)
def _window() -> np.ndarray:
    """The segments' Hann window (read-only)."""
    w = hann(SEGMENT)
    w.flags.writeable = False
    return w


@functools.lru_cache(maxsize=8)
def _omega4(fs: float) -> np.ndarray:
    """``(2 pi f)^4`` of :func:`_frequencies` (read-only)."""
    w4 = (2.0 * np.pi * _frequencies(fs)) ** 4
    w4.flags.writeable = False
    return w4


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two signals' samples are equal to the bit as float64 (NaN, -0.0 included)."""
    if a is b:
        return True
    if a.shape != b.shape:
        return False
    return bool(np.array_equal(np.ascontiguousarray(a, float).view(np.int64),
                               np.ascontiguousarray(b, float).view(np.int64)))


def _runs(indices: Sequence[int]) -> list[tuple[int, int]]:
    """Runs of consecutive increasing ``indices`` as (first, last + 1)."""
    out: list[tuple[int, int]] = []
    for i in indices:
        if out and out[-1][1] == i:
            out[-1] = (out[-1][0], i + 1)
        else:
            out.append((i, i + 1))
    return out


class _WindowSpectra:
    """:class:`_Spectra` of each learning window for one set of signals fed together.

    Feeding (:meth:`feed`) owns the open window (``current``) and the ones it finished since
    :meth:`hand_over`; taking (:meth:`take`) owns the finished windows handed over (``done``)
    and its copy of the open one as it was then, and computes the periodograms of the
    window it takes (in ``work``)."""

    def __init__(self, names: Sequence[str], window_ns: int,
                 state: Mapping[str, Any] | None = None) -> None:
        st = state or {}
        self.names, self.window_ns = tuple(names), window_ns
        self.current = _Spectra(self.names, st.get("current"))
        # room for a batch of at least one segment of every signal
        self.work = Periodograms(SEGMENT, max(_BATCH_ROWS, len(self.names)))
        self._room = 0  # segments a window kept at most so far: a new one's first buffer
        # buffers of closed windows for new ones (appended by taking, popped by feeding:
        # each a single atomic step, so the two sides may run in two threads)
        self._spare: list[np.ndarray] = []
        self._finished: list[tuple[int, _Spectra]] = []
        self._copy: _Spectra | None = None  # the open window as last handed over
        self.done: dict[int, _Spectra] = {
            int(k): _Spectra(self.names, v) for k, v in st.get("done", {}).items()}
        self._open = self.current

    def feed(self, t_ns: np.ndarray, values: Mapping[str, np.ndarray]) -> None:
        """Samples in time order; cut at window ends (window k: ((k-1) W, k W])."""
        if t_ns.shape[0] == 0:
            return
        self._copy = None
        w = self.window_ns
        first, last = -(-int(t_ns[0]) // w), -(-int(t_ns[-1]) // w)
        if first == last:  # the usual case: the slab lies in one window
            self._feed(first, t_ns, values)
            return
        # window k takes ((k-1) W, k W]: cut after each window end (t_ns is in time order)
        cuts = np.searchsorted(t_ns, np.arange(first, last, dtype=np.int64) * w, side="right")
        bounds = [0, *cuts.tolist(), t_ns.shape[0]]
        for k, a, b in zip(range(first, last + 1), bounds[:-1], bounds[1:]):
            if b > a:
                # one view of each array: signals sharing one stay one (_Spectra._part)
                views: dict[int, np.ndarray] = {}
                self._feed(k, t_ns[a:b], {n: views.setdefault(id(s), s[a:b])
                                          for n, s in values.items()})

    def _feed(self, k: int, t_ns: np.ndarray, values: Mapping[str, np.ndarray]) -> None:
        if self.current.index != k:
            if self.current.index is not None:
                self._finished.append((self.current.index, self.current))
                self._room = max(self._room, self.current.filled)
            self.current = _Spectra(self.names, room=self._room,
                                    rows=self._spare.pop() if self._spare else None)
            self.current.index = k
        self.current.feed(t_ns, values)

    def hand_over(self) -> tuple[list[tuple[int, _Spectra]], _Spectra]:
        """The windows finished since the last call, and a copy of the open one (the last
        call's copy again if nothing was fed since)."""
        finished, self._finished = self._finished, []
        if self._copy is None:
            self._copy = self.current.snapshot()
        return finished, self._copy

    def receive(self, part: tuple[list[tuple[int, _Spectra]], _Spectra]) -> None:
        """Take a :meth:`hand_over` (in order)."""
        finished, self._open = part
        for index, spectra in finished:
            self.done[index] = spectra

    def take(self, k: int) -> _Spectra | None:
        """Window ``k``'s spectra (None if it had no samples), its periodograms not yet
        added (:meth:`summed`: only if it is used); older windows are dropped."""
        out = self.done.pop(k, None)
        if out is None and self._open.index == k:
            out = self._open
        self.drop_before(k)
        return out

    def summed(self, spectra: _Spectra) -> _Spectra:
        """A taken window's spectra with its periodograms added (in :attr:`work`)."""
        return spectra.summed(self.work)

    def release(self, spectra: _Spectra) -> None:
        """A taken window is closed: its buffer serves a new window, unless the window is
        the open one (still fed). Fresh buffers cost a page fault every 4 kB, about as much
        as the rest of the feed."""
        if spectra is not self._open and len(self._spare) < _SPARE_BUFFERS:
            self._spare.append(spectra.rows)

    def drop_before(self, k: int) -> None:
        """Forget the finished windows before window ``k`` (closed, or never to be): one
        taken from the open copy and handed over again when the next window's samples came
        would otherwise stay until a later :meth:`take`, in the state of some block splits
        and not others."""
        for old in [i for i in self.done if i < k]:
            del self.done[old]

    def state(self) -> dict[str, Any]:
        return {"current": self.current.state(),
                "done": {str(k): v.state() for k, v in self.done.items()}}


class SeaStateLearner:
    """Learns the damage-rate table and cross-checks each window (module docstring).

    Args:
        cfg: the ``[forecast]`` section.
        curves: S-N curve (``damage_per_cycle``) per component, in table order.
        tick_s: the alert tick; ``cfg.window_s`` must be a whole number of ticks.
        prior: the table to start from (a saved one), else empty default bins.
        state: :meth:`state` of an earlier learner.
    """

    def __init__(self, cfg: ForecastConfig, curves: Mapping[str, Any], tick_s: float,
                 prior: DamageRateTable | None = None,
                 state: Mapping[str, Any] | None = None) -> None:
        ticks = cfg.window_s / tick_s
        if abs(ticks - round(ticks)) > 1e-9 or round(ticks) < 1:
            raise ValueError(f"config error: forecast.window_s = {cfg.window_s:g}: must be a "
                             f"whole number of alert ticks (alerts.eval_interval_s = {tick_s:g})")
        self.cfg = cfg
        self.curves = dict(curves)
        self.names = tuple(curves)
        # each component's first one with an equal S-N curve: equal spectra, equal damage
        curve_list = list(self.curves.values())
        self._same_curve = [curve_list.index(c) for c in curve_list]
        self.window_ns = int(round(cfg.window_s * 1e9))
        self.tick_s = tick_s
        st = state or {}
        if "table" in st:
            self.table = DamageRateTable.from_state(st["table"])
        elif prior is not None:
            if list(prior.components) != list(self.names):
                raise ValueError(f"config error: forecast.table: components "
                                 f"{list(prior.components)} != the configuration's "
                                 f"{list(self.names)}")
            self.table = prior
            self.table.min_hours = cfg.min_hours  # the configuration decides, not the file
        else:
            self.table = DamageRateTable(self.names, HS_EDGES_M, TP_EDGES_S,
                                         min_hours=cfg.min_hours)
        self.window_end: int | None = st.get("window_end")
        self.start_damage: dict[str, float] = dict(st.get("start_damage", {}))
        self.covered_s = float(st.get("covered_s", 0.0))
        self.waves_t: list[int] = list(st.get("waves_t", []))
        self.waves_v: list[tuple[float, float]] = [tuple(v) for v in st.get("waves_v", [])]
        self._new_waves: tuple[list[int], list[tuple[float, float]]] = ([], [])
        self.counts: dict[str, int] = {"windows": 0, "learned": 0, "no_sea_state": 0,
                                       "short": 0, "flagged": 0, "compared": 0,
                                       **st.get("counts", {})}
        self.stress = _WindowSpectra(self.names, self.window_ns, st.get("stress"))
        # the sea state of a window without waves samples: heave (motion) or accel_z (imu)
        self.heave = _WindowSpectra(("heave",), self.window_ns, st.get("heave"))
        self.accel = _WindowSpectra(("accel",), self.window_ns, st.get("accel"))
        self.history: list[dict[str, Any]] = list(st.get("history", []))
        self.new_windows: list[dict[str, Any]] = []  # closed since the last take_windows()

    def warm_up(self) -> None:
        """Run the compiled kernels once on throwaway data (a process's first numba call
        costs a second or more; :meth:`monitor.pipeline.Pipeline.warm_up_ticks`): a window's
        periodograms and the Dirlik damage of its spectrum."""
        t = np.arange(SEGMENT, dtype=np.int64) * 50_000_000  # 20 Hz
        x = np.sin(np.arange(SEGMENT) * 0.3)
        spectra = _Spectra(self.names)
        spectra.feed(t, {n: x for n in self.names})
        spectra.summed(Periodograms(SEGMENT, max(2, len(self.names))))
        for n in self.names:
            spectra.dirlik_rate(n, self.curves[n])

    # ---- inputs, in sensor-time order ------------------------------------------------------

    def waves(self, t_ns: np.ndarray, hs_m: np.ndarray, tp_s: np.ndarray) -> None:
        """Accepted ``waves`` samples of a slab."""
        self._new_waves[0].extend(int(x) for x in t_ns.tolist())
        self._new_waves[1].extend(zip(hs_m.tolist(), tp_s.tolist()))

    def load(self, t_ns: np.ndarray, stresses: Mapping[str, np.ndarray]) -> None:
        """The slab's load samples (time order) and each component's stress."""
        self.stress.feed(t_ns, stresses)

    def motion(self, t_ns: np.ndarray, heave_m: np.ndarray) -> None:
        """Accepted ``motion`` heave samples of a slab."""
        self.heave.feed(t_ns, {"heave": heave_m})

    def imu(self, t_ns: np.ndarray, accel_z_mps2: np.ndarray) -> None:
        """Accepted ``imu`` vertical accelerations of a slab."""
        self.accel.feed(t_ns, {"accel": accel_z_mps2})

    def hand_over(self) -> tuple[Any, ...]:
        """A slab's inputs, once fed, for :meth:`receive` (module docstring)."""
        waves, self._new_waves = self._new_waves, ([], [])
        return waves, self.stress.hand_over(), self.heave.hand_over(), self.accel.hand_over()

    def receive(self, inputs: tuple[Any, ...]) -> None:
        """A slab's :meth:`hand_over`, before its ticks (in slab order)."""
        waves, stress, heave, accel = inputs
        self.waves_t.extend(waves[0])
        self.waves_v.extend(waves[1])
        self.stress.receive(stress)
        self.heave.receive(heave)
        self.accel.receive(accel)
        self._drop_closed()

    def _drop_closed(self) -> None:
        """Keep only the finished windows still to be closed (from the open learning window
        on): what is kept is then the same for any block split (:meth:`_WindowSpectra.drop_before`)."""
        if self.window_end is not None:
            for spectra in (self.stress, self.heave, self.accel):
                spectra.drop_before(self.window_end // self.window_ns)

    def tick(self, end_ns: int, committed: Mapping[str, float], n_samples: int) -> None:
        """An alert tick ended at ``end_ns`` with these committed damages."""
        if self.window_end is None:  # the first tick seen: a window starts here
            self.window_end = (end_ns // self.window_ns + 1) * self.window_ns
            self.start_damage = dict(committed)
            self._drop_closed()  # windows before it are never closed
            return
        if n_samples:
            self.covered_s += self.tick_s
        if end_ns >= self.window_end:
            self._close(self.window_end, committed)
            self.window_end = (end_ns // self.window_ns + 1) * self.window_ns
            self.start_damage = dict(committed)
            self.covered_s = 0.0
            self._drop_closed()  # windows skipped by a gap in the ticks too

    def ticks(self, ends: np.ndarray, committed: Callable[[int], Mapping[str, float]],
              n_samples: np.ndarray, a: int, b: int) -> None:
        """Ticks ``a..b-1`` of ``ends`` (increasing), as :meth:`tick` on each in turn with
        ``committed(q)`` and ``n_samples[q]``: only the first tick and those closing a window
        go through :meth:`tick` (and ask for ``committed``); the ticks between only add
        ``tick_s`` to ``covered_s`` when they had samples, one addition after another in
        order (``np.cumsum`` is a sequential sum), so the state is the same to the bit."""
        q = a
        if q < b and self.window_end is None:
            self.tick(int(ends[q]), committed(q), int(n_samples[q]))
            q += 1
        while q < b:
            assert self.window_end is not None  # set by the first tick
            # the first tick at or after the window's end closes it: none before c does
            c = min(b, max(q, int(np.searchsorted(ends, self.window_end))))
            k = int(np.count_nonzero(n_samples[q:c]))
            if k:
                terms = np.full(k + 1, self.tick_s)
                terms[0] = self.covered_s
                self.covered_s = float(np.cumsum(terms)[-1])
            if c < b:
                self.tick(int(ends[c]), committed(c), int(n_samples[c]))
            q = c + 1

    # ---- windows ---------------------------------------------------------------------------

    def _sea_state(self, start: int, end: int) -> tuple[tuple[float, float] | None, str | None]:
        """The window's (Hs, Tp) and where it came from: ``waves`` samples, else the
        ``motion`` heave spectrum, else the ``imu`` acceleration spectrum."""
        k = end // self.window_ns
        heave, accel = self.heave.take(k), self.accel.take(k)
        out = self._sea_state_of(start, end, heave, accel)
        for taken, spectra in ((heave, self.heave), (accel, self.accel)):
            if taken is not None:
                spectra.release(taken)
        return out

    def _sea_state_of(self, start: int, end: int, heave: _Spectra | None,
                      accel: _Spectra | None) -> tuple[tuple[float, float] | None, str | None]:
        """:meth:`_sea_state` of the window's taken heave and acceleration spectra."""
        inside = [v for t, v in zip(self.waves_t, self.waves_v) if start < t <= end]
        if inside:
            return (math.fsum(v[0] for v in inside) / len(inside),
                    math.fsum(v[1] for v in inside) / len(inside)), "waves"
        before = [(t, v) for t, v in zip(self.waves_t, self.waves_v) if t <= start]
        if before and (end - before[-1][0]) / 1e9 <= self.cfg.waves_max_age_s:
            return before[-1][1], "waves"
        for taken, spectra, name, source in ((heave, self.heave, "heave", "motion"),
                                             (accel, self.accel, "accel", "imu")):
            sea = (None if taken is None
                   else spectra.summed(taken).sea_state(name, name == "accel"))
            if sea is not None:
                return sea, source
        return None, None

    def _close(self, end: int, committed: Mapping[str, float]) -> None:
        start = end - self.window_ns
        spectra = self.stress.take(end // self.window_ns)
        if spectra is not None:
            spectra = self.stress.summed(spectra)
        rainflow = {n: committed[n] - self.start_damage.get(n, committed[n]) for n in self.names}
        rates: dict[tuple[int, int], float] = {}  # per (spectrum, curve): equal ones once
        for i, n in enumerate(self.names):
            if spectra is not None:
                key = (spectra.same[i], self._same_curve[i])
                if key not in rates:
                    rates[key] = spectra.dirlik_rate(n, self.curves[n])
        dirlik = {n: (rates[(spectra.same[i], self._same_curve[i])] * self.covered_s
                      if spectra is not None else math.nan)
                  for i, n in enumerate(self.names)}
        flagged = []
        for n in self.names:
            a, b = rainflow[n], dirlik[n]
            if math.isfinite(b) and max(a, b) > _COMPARE_FLOOR:
                self.counts["compared"] += 1
                if max(a, b) > self.cfg.spectral_flag_factor * min(a, b):
                    flagged.append(n)
        self.counts["flagged"] += len(flagged)
        sea, sea_source = self._sea_state(start, end)
        hours = self.covered_s / 3600.0
        self.counts["windows"] += 1
        if sea is None:
            status = "no_sea_state"
        elif self.covered_s < self.cfg.min_coverage * self.cfg.window_s:
            status = "short"
        else:
            status = "learned"
            self.table.learn(sea[0], sea[1], hours, [max(rainflow[n], 0.0) for n in self.names])
        self.counts[status] += 1
        window = {"end_ns": end, "hours": hours, "hs_m": None if sea is None else sea[0],
                  "tp_s": None if sea is None else sea[1], "sea_state_from": sea_source,
                  "status": status,
                  "segments": 0 if spectra is None else spectra.segments,
                  "rainflow": rainflow,
                  "dirlik": {n: (v if math.isfinite(v) else None) for n, v in dirlik.items()},
                  "flagged": flagged}
        self.new_windows.append(window)
        self.history.append(window)
        del self.history[:-WINDOW_HISTORY]
        if spectra is not None:
            self.stress.release(spectra)
        # keep the newest waves sample at or before this window's end for the next one
        keep = max((i for i, t in enumerate(self.waves_t) if t <= end), default=0)
        del self.waves_t[:keep], self.waves_v[:keep]

    def take_windows(self) -> list[dict[str, Any]]:
        """Windows closed since the last call (for the sinks)."""
        out, self.new_windows = self.new_windows, []
        return out

    # ---- outputs ---------------------------------------------------------------------------

    def summary(self) -> dict[str, Any]:
        """Counts and the table's coverage, for the status and the report."""
        learned = self.table.hours >= self.table.min_hours
        return {"window_s": self.cfg.window_s, "flag_factor": self.cfg.spectral_flag_factor,
                **self.counts,
                "bins_learned": int(learned.sum()), "hours_learned": float(self.table.hours.sum()),
                "bins_model": int(np.sum(~learned & np.all(np.isfinite(self.table.model_rate),
                                                             axis=0)))}

    def state(self) -> dict[str, Any]:
        return {"table": self.table.to_state(), "window_end": self.window_end,
                "start_damage": dict(self.start_damage), "covered_s": self.covered_s,
                "waves_t": list(self.waves_t), "waves_v": [list(v) for v in self.waves_v],
                "counts": dict(self.counts), "stress": self.stress.state(),
                "heave": self.heave.state(), "accel": self.accel.state(),
                "history": list(self.history)}
