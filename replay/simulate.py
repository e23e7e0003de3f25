"""A synthetic buoy: irregular sea -> buoy motion -> line tension -> noisy sensors -> MCAP log.

Chain (per hour of sensor time, so memory does not grow with the log's length):

1. Sea and motion: :func:`models.waves.buoy_motion` (JONSWAP, random phases, heave-following
   buoy, surface orbit for surge/sway) at 20 Hz for one hour plus a 60 s overlap. Each hour
   has its own seed (derived from ``seed`` and the hour index); consecutive hours are joined by
   an energy-preserving cross-fade over the overlap (weights cos, sin of 0..pi/2) so the series
   stays stationary and continuous without one huge FFT.
2. Tension, by the configured ``load_model``:

   ``"catenary"`` (default): the streaming motion -> tension estimator of
   :mod:`models.estimator` (quasi-static catenary of the mooring + axial dynamics), fed hour
   after hour with its state carried. The buoy follows the waves freely, so the line only
   feels the buoy's excursions: a few hundred N on average for a 1.5 m sea.

   ``"wavfor"``: the seed 004 study's own load estimate (App. 6, WAVFOR) in the time domain.
   The buoy is held fixed and the cable supplies the Morison inertia + drag force
   (:func:`models.wavfor.morison_force`) of the SAME irregular sea's water-particle
   kinematics at the buoy (the surface orbit of :func:`models.waves.buoy_motion`):
   T = max(0, T0 + F_x cos(phi) + F_z sin(phi)), with T0 and phi the static top tension and
   its angle above horizontal of the mooring at the mean span (the wave force pulling the
   buoy away from the anchor along the line stretches it; the line cannot push, so it goes
   slack instead: 0-to-F cycles like the seed's lab test). Wave components shorter than
   ``wavfor_min_wavelength_m`` (twice the 8.5 m hull) are left out: Morison's held-fixed
   force assumes waves long compared with the hull, and shorter ones average out over it.
   Like WAVFOR itself this is an upper bound of the cable force.
3. Sensors: tension 20 Hz, IMU accelerations 10 Hz, motion displacements 10 Hz, GNSS 1 Hz
   (anchor position + offset + noise), wave statistics every 30 min (Hs, Tp estimated from the
   last 30 min of heave by :func:`models.waves.sea_state_from_heave`), each with Gaussian
   noise; 1 s blocks; receive time = last sample + ``link_delay_s``.
4. Faults on request: ``dropouts`` = probability that a 1 s block of a stream is lost,
   ``spikes`` = probability per sample of a spike of 5-10 times the stream's standard
   deviation, ``nans`` = probability per sample of a NaN.

Deterministic: the same configuration gives the same file, byte for byte. Every random draw
comes from a generator seeded by (seed, hour, stream, purpose), so e.g. enabling faults does
not change the sea or the noise.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Iterator, Mapping
from pathlib import Path

import numpy as np

from monitor.blocks import SENSOR_FIELDS, validate_buoy_id
from monitor.quanta import quanta as sensor_quanta
from replay.csv_import import LAST_NS, parse_iso_ns
from replay.writer import LogWriter, Series

SECOND = 1_000_000_000
BASE_HZ = 20  # physics rate = tension rate
OVERLAP_S = 60.0
EARTH_RADIUS_M = 6_371_008.8
_STREAM_IDS = {"sea": 0, "tension": 1, "imu": 2, "motion": 3, "gnss": 4, "waves": 5}
_PURPOSE_IDS = {"noise": 0, "dropouts": 1, "spikes": 2, "nans": 3}
LOAD_MODELS = ("catenary", "wavfor")


@dataclass(frozen=True)
class SimConfig:
    """Everything that defines a simulated log (SI units; rates are probabilities)."""

    hours: float
    hs_m: float
    tp_s: float
    seed: int
    buoy_id: str = "vaps"
    start: str = "2000-01-01T00:00:00Z"
    depth_m: float = 23.0
    wave_direction_deg: float = 0.0  # from the mooring's mean direction, counter-clockwise
    anchor_lat_deg: float = 41.85
    anchor_lon_deg: float = -82.4
    bearing_deg: float = 0.0  # anchor -> buoy, clockwise from north
    dropouts: float = 0.0
    spikes: float = 0.0
    nans: float = 0.0
    tension_noise_N: float = 5.0
    accel_noise_mps2: float = 0.02
    motion_noise_m: float = 0.02
    gnss_noise_m: float = 1.5
    link_delay_s: float = 0.2
    waves_interval_s: float = 1800.0
    mean_span_m: float = 31.0  # mean horizontal anchor -> buoy distance (steady drift)
    load_model: str = "catenary"  # "catenary" | "wavfor" (see the module docstring)
    wavfor_min_wavelength_m: float = 17.0  # shorter wave components exert no net force
    # quantum per field name of the log's samples (monitor.quanta.DEFAULT_QUANTA otherwise)
    quanta: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.load_model not in LOAD_MODELS:
            raise ValueError(f"load_model = {self.load_model!r}: must be one of {list(LOAD_MODELS)}")
        for name in ("hours", "hs_m", "tp_s", "depth_m", "waves_interval_s", "mean_span_m",
                     "wavfor_min_wavelength_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} = {v!r}: must be a finite number > 0")
        for name in ("dropouts", "spikes", "nans"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 <= v <= 1.0):
                raise ValueError(f"{name} = {v!r}: must be a probability in [0, 1]")
        for name in ("tension_noise_N", "accel_noise_mps2", "motion_noise_m", "gnss_noise_m",
                     "link_delay_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} = {v!r}: must be a finite number >= 0")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed = {self.seed!r}: must be an integer >= 0")
        validate_buoy_id(self.buoy_id)
        for sensor in SENSOR_FIELDS:
            sensor_quanta(sensor, self.quanta)
        if round(self.hours * 3600 * BASE_HZ) < 1:
            raise ValueError(f"hours = {self.hours!r}: shorter than one sample at {BASE_HZ} Hz")
        start_ns = parse_iso_ns(self.start)
        if start_ns % SECOND:
            raise ValueError(f"start = {self.start!r}: must be a whole second")
        if start_ns <= 0:
            raise ValueError(f"start = {self.start!r}: must be after 1970-01-01T00:00:00Z")
        if start_ns + self.hours * 3600 * SECOND > LAST_NS:
            raise ValueError(f"hours = {self.hours!r}: from {self.start} the log would end "
                             "after 2262-04-11, the last nanosecond time stamp")


def sea_state_warnings(cfg: SimConfig) -> list[str]:
    """Why ``cfg``'s sea state is not physical or not covered (empty when it is plausible):
    a significant height above the breaking height of its peak period in the mooring's depth
    (:func:`models.waves.breaking_height`), or a sea state beyond the damage-rate table that
    forecasts and design studies use (:data:`models.sea_state_table.HS_EDGES_M`, ``TP_EDGES_S``)."""
    from models.sea_state_table import HS_EDGES_M, TP_EDGES_S
    from models.waves import breaking_height

    out = []
    h_b = float(breaking_height(cfg.tp_s, cfg.depth_m))
    if cfg.hs_m > h_b:
        out.append(f"Hs {cfg.hs_m:g} m is not a possible sea at Tp {cfg.tp_s:g} s in "
                   f"{cfg.depth_m:g} m of water: waves of that period break above "
                   f"{h_b:.3g} m (steepness H/L = 1/7, Miche); the linear wave models are far "
                   "outside their range and the loads are not physical")
    if not (HS_EDGES_M[0] <= cfg.hs_m <= HS_EDGES_M[-1]
            and TP_EDGES_S[0] <= cfg.tp_s <= TP_EDGES_S[-1]):
        out.append(f"Hs {cfg.hs_m:g} m, Tp {cfg.tp_s:g} s is beyond the sea-state table of "
                   f"forecasts and design studies (Hs {HS_EDGES_M[0]:g} to {HS_EDGES_M[-1]:g} "
                   f"m, Tp {TP_EDGES_S[0]:g} to {TP_EDGES_S[-1]:g} s)")
    return out


@dataclass
class SimSummary:
    """What was written."""

    path: str
    messages: int = 0
    samples: dict[str, int] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0
    tension_N: tuple[float, float, float] = (math.nan, math.nan, math.nan)  # min, mean, max
    load_model: str = "catenary"

    def text(self) -> str:
        lo, mean, hi = self.tension_N
        per = ", ".join(f"{k} {v:,}" for k, v in self.samples.items())
        return (f"wrote {self.messages:,} messages to {self.path}\n"
                f"samples: {per}\n"
                f"line tension (noise-free, {self.load_model} load model): min {lo:,.0f} N, "
                f"mean {mean:,.0f} N, max {hi:,.0f} N")


def _rng(cfg: SimConfig, hour: int, stream: str, purpose: str) -> np.random.Generator:
    return np.random.default_rng([cfg.seed, hour, _STREAM_IDS[stream], _PURPOSE_IDS[purpose]])


def _hour_seed(cfg: SimConfig, hour: int) -> int:
    return int(np.random.SeedSequence([cfg.seed, hour, _STREAM_IDS["sea"]]).generate_state(1)[0])


class _Sea:
    """Continuous 20 Hz buoy motion, produced hour by hour with cross-faded joins.

    With the ``wavfor`` load model it also gives the water-particle kinematics at the buoy
    (``u``, ``w``, ``du_dt``, ``dw_dt``: along the mooring and up) without the wave components
    shorter than ``cfg.wavfor_min_wavelength_m``. Each hour's synthesized series is periodic
    over its length, so dropping those FFT bins is exactly dropping the components.
    """

    FIELDS = ("heave", "surge", "sway", "accel_x", "accel_y", "accel_z")
    KINEMATICS = {"u": "vel_x", "w": "vel_z", "du_dt": "accel_x", "dw_dt": "accel_z"}

    def __init__(self, cfg: SimConfig):
        self.cfg = cfg
        self.tail: dict[str, np.ndarray] | None = None
        self.fields = self.FIELDS + (tuple(self.KINEMATICS) if cfg.load_model == "wavfor" else ())

    def _kinematics(self, m) -> dict[str, np.ndarray]:
        """Particle kinematics at the buoy, wave components too short for the hull removed."""
        from models.waves import G_STANDARD

        k_max = 2.0 * math.pi / self.cfg.wavfor_min_wavelength_m
        f_max = math.sqrt(G_STANDARD * k_max * math.tanh(k_max * self.cfg.depth_m)) / (2 * math.pi)
        out = {}
        for name, src in self.KINEMATICS.items():
            x = np.asarray(getattr(m, src))
            spec = np.fft.rfft(x)
            spec[np.fft.rfftfreq(x.shape[0], 1.0 / BASE_HZ) > f_max] = 0.0
            out[name] = np.fft.irfft(spec, x.shape[0])
        return out

    def next(self, hour: int, n: int) -> dict[str, np.ndarray]:
        """The next ``n`` samples (at 20 Hz) of every motion field."""
        from models.waves import buoy_motion

        cfg = self.cfg
        n_over = int(OVERLAP_S * BASE_HZ)
        m = buoy_motion(cfg.hs_m, cfg.tp_s, (n + n_over) / BASE_HZ, 1.0 / BASE_HZ,
                        _hour_seed(cfg, hour), depth=cfg.depth_m,
                        direction_deg=cfg.wave_direction_deg)
        full = {f: np.asarray(getattr(m, f)) for f in self.FIELDS}
        if self.cfg.load_model == "wavfor":
            full.update(self._kinematics(m))
        seg = {f: full[f][:n + n_over] for f in self.fields}
        out = {f: seg[f][:n].copy() for f in self.fields}
        if self.tail is not None:
            k = min(n, n_over)
            theta = 0.5 * math.pi * (np.arange(k) + 0.5) / n_over
            for f in self.fields:
                out[f][:k] = np.cos(theta) * self.tail[f][:k] + np.sin(theta) * out[f][:k]
        self.tail = {f: seg[f][n:n + n_over] for f in self.fields}
        return out


@functools.lru_cache(maxsize=4)
def _tension_table(span_m: float, depth_m: float, cable_mass: float):
    """The seed 004 mooring's tension table around a mean fairlead position, with its
    limits: pure and about 0.1 s to solve, so solved once per position (a design check
    simulates hundreds of sea states on the same mooring)."""
    from models.catenary.tension_table import TensionTable
    from models.catenary.vaps import vaps_mooring

    x_lim = (max(span_m - 6.0, 0.5), span_m + 2.5)
    z_lim = (max(depth_m - 4.0, 0.0), depth_m + 4.0)
    table = TensionTable(vaps_mooring(cable_mass=cable_mass), x_lim, z_lim, nx=48, nz=12,
                         max_refinements=1)
    return table, x_lim, z_lim


class _Mooring:
    """Line tension from buoy motion through the physics models (stateful, streaming).

    Quasi-static part: the seed 004 mooring (:func:`models.catenary.vaps.vaps_mooring`, its
    assumed weights) tabulated around the mean fairlead position (``cfg.mean_span_m`` from the
    anchor horizontally, ``cfg.depth_m`` above it); dynamics: the axial inertia of the finite
    line in :class:`models.estimator.MotionTensionEstimator`, fed with the displacements.
    The mean span stands for the steady drift by wind and current, which sets how close to
    taut the 40 m line rides: at the 31 m default a 1.5 m sea gives tension peaks of a few kN.
    """

    MASS_PER_LENGTH = 1.10  # kg/m in air, the cable mass assumed by vaps_mooring()

    def __init__(self, cfg: SimConfig):
        from models.catenary.vaps import vaps_mooring
        from models.estimator import EstimatorConfig, Flag, MotionTensionEstimator

        line = vaps_mooring(cable_mass=self.MASS_PER_LENGTH)
        length = sum(seg.length for seg in line.segments)
        self.span_m = cfg.mean_span_m
        depth = cfg.depth_m
        if math.hypot(self.span_m, depth) >= length:
            raise ValueError(f"mean_span_m = {self.span_m}: the {length:g} m line cannot reach "
                             f"a buoy that far in {depth:g} m of water")
        table, x_lim, z_lim = _tension_table(self.span_m, depth, self.MASS_PER_LENGTH)
        out_bit = np.uint8(Flag.OUT_OF_RANGE)

        def quasi_static(x_off: np.ndarray, z: np.ndarray):
            x, zz = self.span_m + x_off, depth + z
            out = (x < x_lim[0]) | (x > x_lim[1]) | (zz < z_lim[0]) | (zz > z_lim[1])
            h, v, t = table.top_tension(np.clip(x, *x_lim), np.clip(zz, *z_lim))
            return t, h, v, out.astype(np.uint8) * out_bit

        self._est = MotionTensionEstimator(
            EstimatorConfig(dt=1.0 / BASE_HZ, span=self.span_m, height=depth, line_length=length,
                            mass_per_length=self.MASS_PER_LENGTH, ea=line.segments[-1].ea),
            quasi_static)
        h0, v0, t0 = (float(np.asarray(x).reshape(-1)[0])
                      for x in table.top_tension(np.array([self.span_m]), np.array([depth])))
        self.pretension_N, self.top_angle_rad = t0, math.atan2(v0, h0)
        self.load_model = cfg.load_model

    def tension(self, motion: dict[str, np.ndarray]) -> np.ndarray:
        if self.load_model == "wavfor":
            return self._wavfor_tension(motion)
        return self._est.update(motion["heave"], motion["surge"], motion["sway"]).tension

    def _wavfor_tension(self, motion: dict[str, np.ndarray]) -> np.ndarray:
        """Static pretension + the held-fixed buoy's Morison force along the line (seed 004
        App. 6 in the time domain); the line goes slack rather than push."""
        from models.wavfor import morison_force

        f = morison_force(motion["u"], motion["w"], motion["du_dt"], motion["dw_dt"])
        along = (f.horizontal * math.cos(self.top_angle_rad)
                 + f.vertical * math.sin(self.top_angle_rad))
        return np.maximum(self.pretension_N + along, 0.0)


def _faults(cfg: SimConfig, hour: int, stream: str, t: np.ndarray, vals: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """Apply spikes, NaNs and dropouts (in that order) to one stream's hour."""
    vals = vals.copy()
    if cfg.spikes > 0:
        rng = _rng(cfg, hour, stream, "spikes")
        hit = rng.random(vals.shape) < cfg.spikes
        size = rng.uniform(5.0, 10.0, vals.shape) * rng.choice([-1.0, 1.0], vals.shape)
        std = np.std(vals, axis=1, keepdims=True)
        vals = np.where(hit, vals + size * np.maximum(std, 1e-9), vals)
    if cfg.nans > 0:
        hit = _rng(cfg, hour, stream, "nans").random(vals.shape) < cfg.nans
        vals[hit] = np.nan
    if cfg.dropouts > 0:
        cell = t // SECOND
        cells = np.unique(cell)
        lost = cells[_rng(cfg, hour, stream, "dropouts").random(cells.shape[0]) < cfg.dropouts]
        keep = ~np.isin(cell, lost)
        t, vals = t[keep], vals[:, keep]
    return t, vals


def _gnss(cfg: SimConfig, surge: np.ndarray, sway: np.ndarray, span_m: float,
          rng: np.random.Generator) -> np.ndarray:
    """Latitude/longitude of the buoy: anchor + (span + surge, sway) along the bearing."""
    b = math.radians(cfg.bearing_deg)
    along = span_m + surge + rng.normal(0.0, cfg.gnss_noise_m, surge.shape)
    across = sway + rng.normal(0.0, cfg.gnss_noise_m, sway.shape)
    # sway is to port (left) looking from anchor to buoy, i.e. bearing - 90 deg
    north = along * math.cos(b) + across * math.cos(b - math.pi / 2)
    east = along * math.sin(b) + across * math.sin(b - math.pi / 2)
    lat = cfg.anchor_lat_deg + np.degrees(north / EARTH_RADIUS_M)
    east_radius = EARTH_RADIUS_M * math.cos(math.radians(cfg.anchor_lat_deg))
    lon = cfg.anchor_lon_deg + np.degrees(east / east_radius)
    return np.vstack([lat, lon])


def _hours(cfg: SimConfig) -> Iterator[tuple[int, int, dict[str, np.ndarray], np.ndarray, "_Mooring"]]:
    """Hour by hour: (hour, index of its first 20 Hz sample, motion, noise-free tension,
    the mooring model)."""
    total = int(round(cfg.hours * 3600 * BASE_HZ))
    per_hour = 3600 * BASE_HZ
    sea, mooring = _Sea(cfg), _Mooring(cfg)
    for hour in range(math.ceil(total / per_hour)):
        i0 = hour * per_hour
        motion = sea.next(hour, min(per_hour, total - i0))
        yield hour, i0, motion, mooring.tension(motion), mooring


def clean_tension(cfg: SimConfig) -> np.ndarray:
    """The noise-free line tension (N, 20 Hz) of ``cfg``'s sea and load model: the log's
    tension stream before sensor noise and faults."""
    return np.concatenate([tension for _, _, _, tension, _ in _hours(cfg)])


def simulate(cfg: SimConfig, path: str | Path) -> SimSummary:
    """Write the simulated log to ``path``; return what was written."""
    from models.waves import sea_state_from_heave

    start_ns = parse_iso_ns(cfg.start)
    total = int(round(cfg.hours * 3600 * BASE_HZ))
    summary = SimSummary(path=str(path), start_ns=start_ns, load_model=cfg.load_model)
    t_sum, t_min, t_max = 0.0, math.inf, -math.inf
    wave_n = int(round(cfg.waves_interval_s * BASE_HZ))
    heave_hist = np.empty(0)
    delay_ns = int(round(cfg.link_delay_s * SECOND))
    with LogWriter(path, quanta=cfg.quanta) as w:
        for hour, i0, motion, tension, mooring in _hours(cfg):
            n = tension.shape[0]
            idx = i0 + np.arange(n, dtype=np.int64)
            t = start_ns + idx * (SECOND // BASE_HZ)
            t_sum += float(tension.sum())
            t_min, t_max = min(t_min, float(tension.min())), max(t_max, float(tension.max()))
            series = []

            def add(stream: str, tt: np.ndarray, clean: np.ndarray, noise: float) -> None:
                rng = _rng(cfg, hour, stream, "noise")
                vals = clean + rng.normal(0.0, noise, clean.shape) if noise > 0 else clean
                tt, vals = _faults(cfg, hour, stream, tt, vals)
                summary.samples[stream] = summary.samples.get(stream, 0) + tt.shape[0]
                series.append(Series(cfg.buoy_id, stream, tt, vals))

            add("tension", t, tension[None, :], cfg.tension_noise_N)
            even = (idx % 2) == 0  # 10 Hz
            accel = np.vstack([motion[f][even] for f in ("accel_x", "accel_y", "accel_z")])
            add("imu", t[even], accel, cfg.accel_noise_mps2)
            add("motion", t[even], np.vstack([motion[f][even] for f in ("heave", "surge", "sway")]),
                cfg.motion_noise_m)
            sec = (idx % BASE_HZ) == 0  # 1 Hz
            gnss = _gnss(cfg, motion["surge"][sec], motion["sway"][sec], mooring.span_m,
                         _rng(cfg, hour, "gnss", "noise"))
            tt, vals = _faults(cfg, hour, "gnss", t[sec], gnss)
            summary.samples["gnss"] = summary.samples.get("gnss", 0) + tt.shape[0]
            series.append(Series(cfg.buoy_id, "gnss", tt, vals))
            # wave statistics at the end of every full interval, from the heave in it
            heave_hist = np.concatenate([heave_hist, motion["heave"]])
            ends = np.flatnonzero((idx + 1) % wave_n == 0)
            wt, wv = [], []
            for e in ends:
                ss = sea_state_from_heave(heave_hist[len(heave_hist) - n + e + 1 - wave_n:
                                                     len(heave_hist) - n + e + 1], 1.0 / BASE_HZ)
                wt.append(t[e])
                wv.append((ss.hs, ss.tp))
            heave_hist = heave_hist[-wave_n:]
            if wt:
                summary.samples["waves"] = summary.samples.get("waves", 0) + len(wt)
                series.append(Series(cfg.buoy_id, "waves", np.array(wt, np.int64),
                                     np.array(wv, np.float64).T))
            summary.messages += w.write_series(series, recv_delay_ns=delay_ns)
            summary.end_ns = int(t[-1])
    summary.tension_N = (t_min, t_sum / total, t_max)
    return summary
