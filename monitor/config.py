"""The one TOML configuration file: loaded once, parsed once into typed sections.

Every model parameter lives in one file (see docs/ARCHITECTURE.md for the layout and
``monitor/vaps_seed004.toml`` for the shipped example, which is also the default).
:func:`load_config` reads it and :func:`parse_config` turns every section into its typed
object, which the modules receive from :class:`Config`: the core sections (``buoy``,
``mooring``, ``cable``, ``component``, ``fatigue``, ``load``, ``validate``, ``ordering``)
here, and the service's sections declared by their owners (``alerts``: monitor.alerts.config;
``zenoh``, ``state``, ``record``, ``health``, ``metrics``: monitor.daemon_config; ``rerun``:
monitor.viz.rerun_options; ``bridge``/``[[source]]``: monitor.bridge.config; ``forecast``:
monitor.forecast_config). Errors are :class:`ConfigError` (a ValueError) whose message names
the key path and the bad value, with the nearest known name for a misspelt key or section::

    config error: component[1].lay = 'up': must be one of ['left', 'right']
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Callable, Literal, Mapping

import msgspec
from msgspec import Meta

from monitor.alerts.config import AlertsConfig
from monitor.blocks import SENSOR_FIELDS, validate_buoy_id
from monitor.bridge.config import BridgeConfig, parse_bridge_config
from monitor.daemon_config import DaemonConfig, parse_daemon_sections
from monitor.forecast_config import ForecastConfig
from monitor.schema import (MAX_DURATION_S, ConfigError, Errors, SectionReader, error,
                            parse_struct, read_toml, unknown)
from monitor.time_ahead import DEFAULT_MAX_AHEAD_S
from monitor.viz.rerun_options import RerunOptions


DEFAULT_CONFIG_RESOURCE = "vaps_seed004.toml"

CORE_SECTIONS = (
    "buoy", "mooring", "cable", "component", "fatigue", "load", "validate", "ordering", "alerts",
)
# the sections of the live service, each declared by its owner; check-config lists them
SERVICE_SECTIONS = ("zenoh", "state", "record", "health", "metrics", "rerun", "bridge", "source",
                    "forecast")

# Default physical limits and spike rates per sensor field; [validate.<sensor>] overrides them.
# Rates are generous on purpose: a spike check must never reject real wave loading.
DEFAULT_LIMITS: Mapping[str, Mapping[str, tuple[float, float, float]]] = {
    # field: (min, max, max_rate_per_s); rate inf = no rate check
    "tension": {"tension_N": (-5.0e3, 2.0e5, 5.0e5)},
    "motion": {"heave_m": (-20.0, 20.0, 50.0), "surge_m": (-200.0, 200.0, 50.0),
               "sway_m": (-200.0, 200.0, 50.0)},
    "imu": {"accel_x_mps2": (-100.0, 100.0, math.inf), "accel_y_mps2": (-100.0, 100.0, math.inf),
            "accel_z_mps2": (-100.0, 100.0, math.inf)},
    "gnss": {"lat_deg": (-90.0, 90.0, math.inf), "lon_deg": (-180.0, 180.0, math.inf)},
    "waves": {"hs_m": (0.0, 30.0, math.inf), "tp_s": (0.5, 40.0, math.inf)},
}
DEFAULT_STALE_S: Mapping[str, float] = {
    "tension": 5.0, "motion": 5.0, "imu": 5.0, "gnss": 60.0, "waves": 7200.0,
}


Positive = Annotated[float, Meta(gt=0)]
Seconds = Annotated[float, Meta(gt=0, le=MAX_DURATION_S)]  # a span becomes int64 ns


class BuoyConfig(msgspec.Struct, frozen=True):
    id: str
    design_life_years: Positive = 20.0

    def check(self, where: str, raw: Mapping[str, Any]) -> "BuoyConfig":
        try:
            validate_buoy_id(self.id)
        except ValueError as exc:
            raise error(where, "id", self.id, str(exc)) from None
        return self


@dataclass(frozen=True)
class SegmentConfig:
    """One homogeneous mooring segment, listed from the anchor up."""

    name: str
    length_m: float
    weight_N_per_m: float  # submerged weight per metre; negative = buoyant
    ea_N: float
    diameter_m: float


@dataclass(frozen=True)
class MooringConfig:
    """The line from anchor to buoy: a named preset (built by ``models.catenary``) or segments."""

    depth_m: float
    span_m: float  # nominal horizontal distance anchor -> buoy (for the motion estimator)
    bearing_deg: float
    anchor_lat_deg: float
    anchor_lon_deg: float
    preset: str | None
    segments: tuple[SegmentConfig, ...]  # empty for a preset
    length_m: float


# Presets are built by models.catenary (the seed 004 line: models.catenary.vaps_mooring(),
# bridle, 17.5 m of floated cable, 20 m of bare cable; 40 m in 23 m of water). Only what the
# configuration needs to check itself is listed here.
MOORING_PRESETS: Mapping[str, Mapping[str, float]] = {
    "vaps_seed004": {"depth_m": 23.0, "length_m": 40.0, "span_m": 29.0},
}


@dataclass(frozen=True)
class CableConfig:
    """``preset`` names a ``models.helix.HelixCable`` constructor; ``overrides`` replace fields
    (numbers, and ``twist_restraint`` from the ``twist`` key)."""

    preset: str
    overrides: Mapping[str, Any]


@dataclass(frozen=True)
class SNCurveConfig:
    """A preset name (a ``models.fatigue.SNCurve`` constructor) or a table of points."""

    preset: str | None
    stress_range_Pa: tuple[float, ...] = ()
    cycles: tuple[float, ...] = ()


@dataclass(frozen=True)
class ComponentConfig:
    name: str
    kind: str  # "conductor" (helix stress) or "axial" (tension / area)
    lay: str | None  # conductor lay hand, "left" or "right"
    area_m2: float | None  # axial components
    sn_curve: SNCurveConfig
    mean_stress: str
    ultimate_Pa: float | None
    derating: float
    scf: float
    dff: float
    hysteresis_Pa: float
    # where along a conductor: "free_span" (the helix far from the ends) or "termination"
    # (where a moulding fixes the conductors: models.termination, with this bend geometry;
    # without one the bend is not configured and the stress is the free span's)
    location: str = "free_span"
    bend_radius_m: float | None = None
    bend_angle_deg: float | None = None
    bend_gauge_length_m: float | None = None  # None: conductors locked at the bend


class FatigueConfig(msgspec.Struct, frozen=True):
    rate_window_s: Seconds = 3600.0
    histogram_edges_Pa: Annotated[tuple[float, ...], Meta(
        min_length=2, description="a list of at least 2 finite numbers")] = tuple(
            i * 5.0e6 for i in range(41))
    reference_cycles: Positive = 1.0e7

    def check(self, where: str, raw: Mapping[str, Any]) -> "FatigueConfig":
        edges = self.histogram_edges_Pa
        if not all(math.isfinite(e) for e in edges):
            raise error(where, "histogram_edges_Pa", raw.get("histogram_edges_Pa"),
                        "must be a list of at least 2 finite numbers")
        if any(b <= a for a, b in zip(edges, edges[1:])):
            raise error(where, "histogram_edges_Pa", raw.get("histogram_edges_Pa"),
                        "must be strictly increasing")
        return self


class LoadConfig(msgspec.Struct, frozen=True):
    source: Literal["auto", "measured", "estimated"] = "auto"
    stale_after_s: Seconds = 5.0
    # stream that feeds the motion estimator: "imu", "motion", or "auto" (the first of the two
    # that delivers an accepted sample, see monitor.load_source)
    motion_sensor: Literal["auto", "imu", "motion"] = "auto"
    # its sample rate (Hz) for the estimator's fixed step, or "auto": the stream's own spacing
    # (monitor.motion_rate)
    motion_rate_hz: Positive | Literal["auto"] = "auto"
    breaking_load_N: Positive = 45_000.0  # the line's breaking strength (seed 004 BIW cable)
    slack_limit_N: float = 0.0  # below this the line is slack: QC suspect

    def check(self, where: str, raw: Mapping[str, Any]) -> "LoadConfig":
        if not self.slack_limit_N < self.breaking_load_N:
            raise error(where, "slack_limit_N", self.slack_limit_N,
                        f"must be < breaking_load_N ({self.breaking_load_N:g})")
        return self


@dataclass(frozen=True)
class FieldLimits:
    """One field's validation limits: ``min``/``max`` are the sensor span (outside = QARTOD
    gross-range fail, rejected), ``max_rate_per_s`` the fastest physical change (faster =
    rate-of-change fail, rejected as ``spike``); the rest are the QARTOD suspect thresholds
    and the flat-line test (monitor.qartod; inf / 0 = test off)."""

    min: float
    max: float
    max_rate_per_s: float  # inf = no rate-of-change check
    suspect_min: float = -math.inf
    suspect_max: float = math.inf
    spike_suspect: float = math.inf
    spike_fail: float = math.inf
    rate_suspect_per_s: float = math.inf
    flat_tolerance: float = 0.0
    flat_suspect_s: float = math.inf
    flat_fail_s: float = math.inf


@dataclass(frozen=True)
class SensorLimits:
    fields: Mapping[str, FieldLimits]
    stale_after_s: float
    location_range_max_m: float = 0.0  # gnss: QARTOD location test, 0 = off
    # motion: the watch circle (span_m, stretched line length m, depth m): a position the
    # line cannot reach is a location fail (None = off)
    watch_circle: tuple[float, float, float] | None = None
    # motion: the check-factor test (depth m, longest wave period s), None = off
    check_factor: tuple[float, float] | None = None


class OrderingConfig(msgspec.Struct, frozen=True):
    horizon_s: Seconds = 10.0  # live: how far a stream may lag the newest data before it is
    #                            passed by
    replay_horizon_s: Seconds = 3600.0  # replay: same, sized for coalesced log blocks
    max_ahead_s: Seconds = DEFAULT_MAX_AHEAD_S  # a sample time further ahead of its receive time is
    #                               time_ahead (monitor.time_ahead)
    copy_span_s: Seconds = 3600.0  # a late exact copy of a sample received within this much
    #                               sensor time is a duplicate (monitor.late_copies)


@dataclass(frozen=True)
class Config:
    """The whole file, parsed: every section as its owner's typed object."""

    buoy: BuoyConfig
    mooring: MooringConfig
    cable: CableConfig
    components: tuple[ComponentConfig, ...]
    fatigue: FatigueConfig
    load: LoadConfig
    validate: Mapping[str, SensorLimits]
    ordering: OrderingConfig
    alerts: AlertsConfig
    forecast: ForecastConfig
    daemon: DaemonConfig
    rerun: RerunOptions
    bridge: BridgeConfig | None  # the [[source]] tables: the bridge runs inside the daemon
    raw: Mapping[str, Any] = field(repr=False)  # the document, for config_with's edits
    source: str = "<dict>"

    def section(self, name: str) -> Mapping[str, Any]:
        """The raw table of a top-level section ({} when absent), to edit with config_with."""
        return self.raw.get(name, {})



def _parse_mooring(r: SectionReader) -> MooringConfig:
    preset = r.raw("preset")
    tables = r.table_list("segment")
    if preset is not None and tables:
        raise r.error("preset", preset, "give either a preset or [[mooring.segment]], not both")
    segments: list[SegmentConfig] = []
    if preset is not None:
        if not isinstance(preset, str) or preset not in MOORING_PRESETS:
            raise r.error("preset", preset, f"must be one of {sorted(MOORING_PRESETS)}")
        p = MOORING_PRESETS[preset]
        length = p["length_m"]
        depth = r.float("depth_m", p["depth_m"], gt=0)
        span = r.float("span_m", p["span_m"], gt=0)
    else:
        if not tables:
            raise ConfigError("config error: mooring: needs preset or [[mooring.segment]] tables")
        read = [r.part(_parse_segment, t, f"mooring.segment[{i}]") for i, t in enumerate(tables)]
        segments = [seg for seg in read if seg is not None]
        length = sum(seg.length_m for seg in segments)
        depth = r.float("depth_m", gt=0)
        span = r.float("span_m", gt=0)
    if r.ok():  # (a stand-in is no length to check against)
        if length < depth:
            r.reject("depth_m", depth, f"deeper than the line is long ({length:g} m)")
        elif span >= length:
            r.reject("span_m", span, f"must be shorter than the line ({length:g} m)")
    out = MooringConfig(
        depth_m=depth,
        span_m=span,
        bearing_deg=r.float("bearing_deg", 0.0, ge=0, le=360),
        anchor_lat_deg=r.float("anchor_lat_deg", 0.0, ge=-90, le=90),
        anchor_lon_deg=r.float("anchor_lon_deg", 0.0, ge=-180, le=180),
        preset=preset,
        segments=tuple(segments),
        length_m=length,
    )
    r.done()
    return out


def _parse_segment(s: SectionReader) -> SegmentConfig:
    out = SegmentConfig(s.str("name"), s.float("length_m", gt=0), s.float("weight_N_per_m"),
                        s.float("ea_N", gt=0, allow_inf=True), s.float("diameter_m", gt=0))
    s.done()
    return out


_TWIST_KEYS = ("twist", "twist_limit_deg", "twist_length_m")


def _parse_cable(r: SectionReader) -> CableConfig:
    preset = r.str("preset", "vaps_biw")
    overrides: dict[str, Any] = {}
    for key in list(r.table):
        if key != "preset" and key not in _TWIST_KEYS:
            overrides[key] = r.float(key, gt=0)
    # the twist boundary condition (models.helix): free | restrained | limited (to an angle
    # twist_limit_deg over twist_length_m)
    twist = r.str("twist", "free", choices=("free", "restrained", "limited"))
    if twist == "limited":
        overrides["twist_limit_rad"] = math.radians(r.float("twist_limit_deg", ge=0, le=36000.0))
        overrides["twist_length_m"] = r.float("twist_length_m", gt=0)
    else:
        for key in _TWIST_KEYS[1:]:
            if r.has(key) and r.ok("twist"):  # (with twist itself bad, no telling)
                r.reject(key, r.raw(key), 'only with twist = "limited"')
            r.raw(key)
    if twist != "free":
        overrides["twist_restraint"] = twist
    r.done()
    return CableConfig(preset, overrides)


def _parse_sn(value: Any, path: str) -> SNCurveConfig:
    if isinstance(value, str):
        return SNCurveConfig(preset=value)
    s = SectionReader(value, path)
    ranges = s.floats("stress_range_Pa", min_len=2)
    cycles = s.floats("cycles", min_len=2)
    s.done()
    if len(ranges) != len(cycles) or any(v <= 0 for v in ranges + cycles):
        raise error("", path, value,
                    "stress_range_Pa and cycles must be positive lists of the same length")
    return SNCurveConfig(None, ranges, cycles)


def _parse_component(r: SectionReader) -> ComponentConfig:
    kind = r.str("kind", "conductor", choices=("conductor", "axial"))
    if r.ok("kind"):
        lay = r.str("lay", choices=("left", "right")) if kind == "conductor" else None
        area = r.float("area_m2", gt=0) if kind == "axial" else None
    else:  # (which of them the kind needs is unknown: its own error says enough)
        lay, area = r.raw("lay"), r.raw("area_m2")
    sn_raw = r.raw("sn_curve", "vaps_copper")
    out = ComponentConfig(
        name=r.str("name"),
        kind=kind,
        lay=lay,
        area_m2=area,
        sn_curve=r.checked("sn_curve", lambda: _parse_sn(sn_raw, f"{r.path}.sn_curve"),
                           SNCurveConfig(preset="vaps_copper")),
        mean_stress=r.str("mean_stress", "none",
                          choices=("none", "goodman", "gerber", "walker", "swt")),
        ultimate_Pa=r.float("ultimate_Pa", gt=0) if r.has("ultimate_Pa") else None,
        derating=r.float("derating", 1.0, gt=0),
        scf=r.float("scf", 1.0, gt=0),
        dff=r.float("dff", 1.0, gt=0),
        hysteresis_Pa=r.float("hysteresis_Pa", 0.0, ge=0),
        **_parse_location(r, kind),
    )
    if out.mean_stress != "none" and out.ultimate_Pa is None and r.ok("ultimate_Pa"):
        r.reject("mean_stress", out.mean_stress, "needs ultimate_Pa")
    r.done()
    return out


_BEND_KEYS = ("bend_radius_m", "bend_angle_deg", "bend_gauge_length_m")


def _parse_location(r: SectionReader, kind: str) -> dict[str, Any]:
    """``location`` and, at a termination, its bend (models.termination.TerminationBend)."""
    choices = ("free_span", "termination") if kind == "conductor" else ("free_span",)
    location = r.str("location", "free_span", choices=choices)
    if location == "free_span":
        for key in _BEND_KEYS:
            if r.has(key) and r.ok("location"):  # (with location itself bad, no telling)
                r.reject(key, r.raw(key), 'only with location = "termination"')
            r.raw(key)
        return {"location": location}
    if not any(r.has(key) for key in _BEND_KEYS):
        # bend not measured: no bend strain (an assumed one would put the locked copper
        # beyond yield at rest, docs/CONDUCTOR.md), said by check-config
        return {"location": location}
    return {
        "location": location,
        "bend_radius_m": r.float("bend_radius_m", gt=0),
        "bend_angle_deg": r.float("bend_angle_deg", ge=0, le=180.0),
        "bend_gauge_length_m": (r.float("bend_gauge_length_m", gt=0)
                                if r.has("bend_gauge_length_m") else None),
    }


_G = 9.81
LONGEST_WAVE_S = 25.0  # the longest wave period (s) the QC takes for a sea (waves tp_s, motion)


def qc_defaults(mooring: MooringConfig, load: LoadConfig) -> dict[str, dict[str, dict[str, float]]]:
    """Default QARTOD thresholds per sensor field, derived from the mooring and the line so the
    shipped configuration catches instrument glitches with no tuning (docs/QC.md gives the
    reasoning). Keys as in ``[validate.<sensor>.<field>]``."""
    d, length, b = mooring.depth_m, mooring.length_m, load.breaking_load_N
    watch = math.sqrt(max(length ** 2 - d ** 2, 0.0))  # watch-circle radius, line straight
    fastest = math.sqrt(_G * d)  # phase speed of the longest wave the depth allows
    flat = {"flat_suspect_s": 60.0, "flat_fail_s": 600.0}
    out: dict[str, dict[str, dict[str, float]]] = {
        "tension": {"tension_N": {
            "suspect_min": load.slack_limit_N, "suspect_max": b,
            "max_rate_per_s": b, "rate_suspect_per_s": 0.5 * b,
            "spike_suspect": 0.1 * b, "spike_fail": 0.25 * b, "flat_tolerance": 0.1, **flat}},
        "motion": {},
        "imu": {},
        "gnss": {},
        "waves": {"hs_m": {"suspect_max": 0.78 * d}, "tp_s": {"suspect_min": 1.0,
                                                             "suspect_max": LONGEST_WAVE_S}},
    }
    for name in SENSOR_FIELDS["motion"]:
        span = d if name == "heave_m" else length
        suspect = 0.39 * d if name == "heave_m" else watch
        out["motion"][name] = {"min": -span, "max": span, "suspect_min": -suspect,
                               "suspect_max": suspect, "max_rate_per_s": fastest,
                               "rate_suspect_per_s": 2.0, "spike_suspect": 1.0,
                               "spike_fail": 3.0, "flat_tolerance": 1e-3, **flat}
    for name in SENSOR_FIELDS["imu"]:
        out["imu"][name] = {"suspect_min": -3 * _G, "suspect_max": 3 * _G,
                            "spike_suspect": 2 * _G, "spike_fail": 5 * _G,
                            "flat_tolerance": 1e-4, **flat}
    return out


_QC_KEYS = ("suspect_min", "suspect_max", "spike_suspect", "spike_fail", "rate_suspect_per_s",
            "flat_tolerance", "flat_suspect_s", "flat_fail_s")


def _parse_field(f: SectionReader, lo: float, hi: float, rate: float,
                 qc: Mapping[str, float]) -> FieldLimits:
    lo, hi = f.float("min", qc.get("min", lo)), f.float("max", qc.get("max", hi))
    values = {k: f.float(k, qc.get(k, getattr(FieldLimits, k)), allow_inf=True,
                         **({"ge": 0} if k.startswith(("spike", "rate", "flat")) else {}))
              for k in _QC_KEYS}
    limits = FieldLimits(lo, hi, f.float("max_rate_per_s", qc.get("max_rate_per_s", rate),
                                         gt=0, allow_inf=True), **values)
    if not f.ok():  # (a stand-in is no bound to check against)
        f.done()
    if not limits.max > limits.min:
        raise f.error("max", limits.max, f"must be > min ({limits.min:g})")
    # the operator (suspect) span lies inside the sensor (fail) span, as QARTOD has it
    limits = dataclasses.replace(limits, suspect_min=max(limits.suspect_min, limits.min),
                                 suspect_max=min(limits.suspect_max, limits.max))
    if not limits.suspect_max >= limits.suspect_min:
        raise f.error("suspect_max", limits.suspect_max,
                      f"must be >= suspect_min ({limits.suspect_min:g})")
    f.done()
    return limits


def _parse_validate(r: SectionReader, load: LoadConfig,
                    mooring: MooringConfig) -> dict[str, SensorLimits]:
    out: dict[str, SensorLimits] = {}
    for key in r.table:
        if key not in SENSOR_FIELDS:
            r.reject(key, r.table[key], f"unknown sensor; expected one of {sorted(SENSOR_FIELDS)}")
    derived = qc_defaults(mooring, load)
    for sensor, defaults in DEFAULT_LIMITS.items():
        limits = r.part(_parse_sensor, r.raw(sensor, {}), f"validate.{sensor}", sensor, defaults,
                        derived[sensor], load, mooring)
        if limits is not None:
            out[sensor] = limits
    return out


def _parse_sensor(s: SectionReader, sensor: str,
                  defaults: Mapping[str, tuple[float, float, float]],
                  derived: Mapping[str, Mapping[str, float]], load: LoadConfig,
                  mooring: MooringConfig) -> SensorLimits:
    """One sensor's ``[validate.<sensor>]`` table (see :func:`_parse_validate`)."""
    fields = {}
    for name, (lo, hi, rate) in defaults.items():
        field = s.part(_parse_field, s.raw(name, {}), f"validate.{sensor}.{name}", lo, hi,
                       rate, derived.get(name, {}))
        if field is not None:
            fields[name] = field
    stale_default = load.stale_after_s if sensor == "tension" else DEFAULT_STALE_S[sensor]
    stale = s.float("stale_after_s", stale_default, gt=0, le=MAX_DURATION_S)
    if sensor == "tension" and s.has("stale_after_s") and stale != load.stale_after_s and \
            s.ok("stale_after_s"):
        s.reject("stale_after_s", stale, "tension staleness is set by load.stale_after_s")
    location = 0.0
    if sensor == "gnss":
        # consecutive fixes further apart than the watch circle's diameter (line straight)
        # plus two 50 m GNSS errors are suspect
        location = s.float("location_range_max_m", 2 * mooring.length_m + 100.0, ge=0)
    watch = None
    if sensor == "motion" and s.bool("watch_circle", True):
        # 2 % stretch: about a steel-cored cable's elongation near its breaking load
        watch = (mooring.span_m, 1.02 * mooring.length_m, mooring.depth_m)
    check = None
    if sensor == "motion" and s.bool("check_factor", True):
        check = (mooring.depth_m, LONGEST_WAVE_S)
    s.done()
    return SensorLimits(fields, stale, location, watch, check)


def _read(parse: Callable[..., Any], table: Any, path: str, *args: Any) -> Any:
    """``parse(SectionReader(table, path), *args)``: a table that is no table is its error;
    every error of the table (and of the tables in it) is raised at once."""
    r = SectionReader(table, path, gather=True)
    try:
        out = parse(r, *args)
    except ConfigError as exc:  # a structural error the parser cannot read past
        r.errors.add(exc)
    r.errors.raise_any()
    return out


def _parse_components(top: SectionReader) -> tuple[ComponentConfig, ...]:
    """The ``[[component]]`` tables, each one's errors gathered; names unique."""
    tables = top.table_list("component")
    if not tables:
        raise ConfigError("config error: component: at least one [[component]] is required")
    errors = Errors()
    parsed = [errors.parse(_read, _parse_component, t, f"component[{i}]")
              for i, t in enumerate(tables)]
    errors.raise_any()
    components = tuple(c for c in parsed if c is not None)
    names = [c.name for c in components]
    for i, name in enumerate(names):
        if names.index(name) != i:
            raise ConfigError(f"config error: component[{i}].name = {name!r}: duplicate name")
    return components


def parse_config(data: Mapping[str, Any], source: str = "<dict>") -> Config:
    """Validate a parsed TOML document and return the typed configuration.

    Each section is parsed on its own and their errors gathered, so one run names every
    mistake (:class:`monitor.schema.ConfigErrors` when there are several); ``[validate]``,
    whose defaults derive from ``[load]`` and ``[mooring]``, is checked once those are valid.
    """
    errors = Errors()
    top = SectionReader(data, "")
    for name in data:
        if name not in CORE_SECTIONS + SERVICE_SECTIONS:
            errors.add(unknown("", name, data[name], CORE_SECTIONS + SERVICE_SECTIONS, "section"))
    load = errors.parse(parse_struct, LoadConfig, data.get("load"), "load")
    mooring = errors.parse(_read, _parse_mooring, top.raw("mooring", {"preset": "vaps_seed004"}),
                           "mooring")
    sections: dict[str, Any] = dict(
        buoy=errors.parse(parse_struct, BuoyConfig, data.get("buoy"), "buoy"),
        mooring=mooring,
        cable=errors.parse(_read, _parse_cable, top.raw("cable", {}), "cable"),
        components=errors.parse(_parse_components, top),
        fatigue=errors.parse(parse_struct, FatigueConfig, data.get("fatigue"), "fatigue"),
        load=load,
        validate=None if load is None or mooring is None else errors.parse(
            _read, _parse_validate, top.raw("validate", {}), "validate", load, mooring),
        ordering=errors.parse(parse_struct, OrderingConfig, data.get("ordering"), "ordering"),
        alerts=errors.parse(AlertsConfig.from_dict, data.get("alerts")),
        forecast=errors.parse(parse_struct, ForecastConfig, data.get("forecast"), "forecast"),
        daemon=errors.parse(parse_daemon_sections, data),
        rerun=errors.parse(parse_struct, RerunOptions, data.get("rerun"), "rerun"),
        bridge=errors.parse(parse_bridge_config, data) if "source" in data else None,
    )
    errors.raise_any()
    return Config(**sections, raw=data, source=source)


def load_config(path: str | Path) -> Config:
    """Read and validate a TOML configuration file."""
    return parse_config(read_toml(path), source=str(path))


def default_config() -> Config:
    """The shipped example: the seed 004 VAPS mooring (``monitor/vaps_seed004.toml``)."""
    text = resources.files("monitor").joinpath(DEFAULT_CONFIG_RESOURCE).read_text()
    return parse_config(tomllib.loads(text), source=f"monitor/{DEFAULT_CONFIG_RESOURCE}")


def config_with(config: Config, **sections: Any) -> Config:
    """A copy of ``config`` with whole raw top-level sections replaced, re-validated.

    ``config_with(cfg, component=[{...}, {...}])`` is how the demo adds a right-lay component.
    """
    data = dict(config.raw)
    data.update(sections)
    return parse_config(data, source=config.source)
