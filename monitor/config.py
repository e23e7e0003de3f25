"""The one TOML configuration file: loading, validation, and the core sections.

Every model parameter lives in one file (see docs/ARCHITECTURE.md for the layout and
``monitor/vaps_seed004.toml`` for the shipped example, which is also the default). Errors are
:class:`ConfigError` (a ValueError) whose message names the key path and the bad value::

    config error: component[1].lay = 'up': must be one of ['left', 'right']

This module parses the sections the pipeline core needs (``buoy``, ``mooring``, ``cable``,
``component``, ``fatigue``, ``load``, ``validate``, ``ordering`` and the ``alerts`` timing keys).
Sections owned by other modules (``zenoh``, ``state``, ``record``, ``health``, ``rerun``, the
alert rules) are kept as raw tables (:meth:`Config.section`) for their owners to parse
(:class:`SectionReader` helps), and ``buoymon check-config`` runs every parser listed in
:data:`SECTION_PARSERS`, so one command validates the whole file.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping, Sequence

from monitor.blocks import SENSOR_FIELDS, validate_buoy_id

DEFAULT_CONFIG_RESOURCE = "vaps_seed004.toml"
# longest time span a duration key may give: time is int64 ns, and a span in ns must fit with
# room to add it to a time stamp (1e9 s is about 32 years)
MAX_DURATION_S = 1e9

# Top-level sections parsed by other modules: name -> "module:attribute.path", a callable
# taking the section's raw table and raising ValueError on a bad value. A module that is not
# installed yet leaves its section unchecked (check-config says so).
SECTION_PARSERS: dict[str, str] = {
    "alerts": "monitor.alerts.config:AlertsConfig.from_dict",
    "zenoh": "monitor.daemon_config:ZenohConfig.from_dict",
    "state": "monitor.daemon_config:StateConfig.from_dict",
    "record": "monitor.daemon_config:RecordConfig.from_dict",
    "health": "monitor.daemon_config:HealthConfig.from_dict",
    "metrics": "monitor.daemon_config:MetricsConfig.from_dict",
    "rerun": "monitor.viz.rerun_options:RerunOptions.from_toml",
    "bridge": "monitor.bridge.config:parse_bridge_section",
    "source": "monitor.bridge.config:parse_sources",
    "forecast": "monitor.forecast_config:ForecastConfig.from_dict",
}
# external sections that are arrays of tables ([[source]]), not tables
LIST_SECTIONS = ("source",)

CORE_SECTIONS = (
    "buoy", "mooring", "cable", "component", "fatigue", "load", "validate", "ordering", "alerts",
)

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


class ConfigError(ValueError):
    """A configuration value is missing, of the wrong type or out of range."""


def _fmt(value: Any) -> str:
    return repr(value)


class SectionReader:
    """Typed, path-aware access to one TOML table; unknown keys are errors.

    ``r = SectionReader(table, "alerts.rule[2]")``; ``r.float("threshold", gt=0)``;
    ``r.done()`` raises if the table holds a key nobody read (a typo, usually).
    """

    def __init__(self, table: Any, path: str) -> None:
        if not isinstance(table, Mapping):
            raise ConfigError(f"config error: {path} = {_fmt(table)}: must be a table")
        self.table = table
        self.path = path
        self._seen: set[str] = set()

    def _key(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def error(self, key: str, value: Any, why: str) -> ConfigError:
        return ConfigError(f"config error: {self._key(key)} = {_fmt(value)}: {why}")

    def has(self, key: str) -> bool:
        return key in self.table

    def raw(self, key: str, default: Any = None) -> Any:
        self._seen.add(key)
        return self.table.get(key, default)

    def _required(self, key: str) -> Any:
        self._seen.add(key)
        if key not in self.table:
            raise ConfigError(f"config error: {self._key(key)} is missing")
        return self.table[key]

    def str(self, key: str, default: str | None = None, choices: Sequence[str] | None = None) -> str:
        value = self._required(key) if default is None else self.raw(key, default)
        if not isinstance(value, str):
            raise self.error(key, value, "must be a string")
        if choices is not None and value not in choices:
            raise self.error(key, value, f"must be one of {list(choices)}")
        return value

    def float(self, key: str, default: float | None = None, *, gt: float | None = None,
              ge: float | None = None, le: float | None = None, allow_inf: bool = False) -> float:
        value = self._required(key) if default is None else self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key, value, "must be a number")
        value = float(value)
        if math.isnan(value) or (math.isinf(value) and not allow_inf):
            raise self.error(key, value, "must be a finite number")
        if gt is not None and not value > gt:
            raise self.error(key, value, f"must be > {gt:g}")
        if ge is not None and not value >= ge:
            raise self.error(key, value, f"must be >= {ge:g}")
        if le is not None and not value <= le:
            raise self.error(key, value, f"must be <= {le:g}")
        return value

    def int(self, key: str, default: int | None = None, *, ge: int | None = None) -> int:
        value = self._required(key) if default is None else self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, value, "must be an integer")
        if ge is not None and value < ge:
            raise self.error(key, value, f"must be >= {ge}")
        return value

    def bool(self, key: str, default: bool | None = None) -> bool:
        value = self._required(key) if default is None else self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(key, value, "must be true or false")
        return value

    def floats(self, key: str, default: Sequence[float] | None = None, *,
               increasing: bool = False, min_len: int = 1) -> tuple[float, ...]:
        value = self._required(key) if default is None else self.raw(key, default)
        if not isinstance(value, (list, tuple)) or len(value) < min_len or any(
            isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
            for v in value
        ):
            raise self.error(key, value, f"must be a list of at least {min_len} finite numbers")
        out = tuple(float(v) for v in value)
        if increasing and any(b <= a for a, b in zip(out, out[1:])):
            raise self.error(key, value, "must be strictly increasing")
        return out

    def table_list(self, key: str) -> list[Mapping[str, Any]]:
        value = self.raw(key, [])
        if not isinstance(value, list):
            raise self.error(key, value, "must be an array of tables ([[...]])")
        return value

    def done(self) -> None:
        extra = sorted(set(self.table) - self._seen)
        if extra:
            raise ConfigError(
                f"config error: {self.path or 'top level'}: unknown key(s) {extra}"
            )


@dataclass(frozen=True)
class BuoyConfig:
    id: str
    design_life_years: float


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
    # (where a moulding fixes the conductors: models.termination, with this bend geometry)
    location: str = "free_span"
    bend_radius_m: float | None = None
    bend_angle_deg: float | None = None
    bend_gauge_length_m: float | None = None  # None: conductors locked at the bend


@dataclass(frozen=True)
class FatigueConfig:
    rate_window_s: float
    histogram_edges_Pa: tuple[float, ...]
    reference_cycles: float


@dataclass(frozen=True)
class LoadConfig:
    source: str  # "auto" | "measured" | "estimated"
    stale_after_s: float
    # stream that feeds the motion estimator: "imu", "motion", or "auto" (the first of the two
    # that delivers an accepted sample, see monitor.load_source)
    motion_sensor: str
    # its sample rate (Hz) for the estimator's fixed step, or "auto": the stream's own spacing
    # (monitor.motion_rate)
    motion_rate_hz: float | str
    breaking_load_N: float = 45_000.0  # the line's breaking strength (seed 004 BIW cable)
    slack_limit_N: float = 0.0  # below this the line is slack: QC suspect


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


@dataclass(frozen=True)
class OrderingConfig:
    horizon_s: float  # live: how far a stream may lag the newest data before it is passed by
    replay_horizon_s: float  # replay: same, sized for coalesced log blocks


@dataclass(frozen=True)
class AlertsTiming:
    eval_interval_s: float
    resend_interval_s: float


@dataclass(frozen=True)
class Config:
    buoy: BuoyConfig
    mooring: MooringConfig
    cable: CableConfig
    components: tuple[ComponentConfig, ...]
    fatigue: FatigueConfig
    load: LoadConfig
    validate: Mapping[str, SensorLimits]
    ordering: OrderingConfig
    alerts: AlertsTiming
    raw: Mapping[str, Any] = field(repr=False)
    source: str = "<dict>"

    def section(self, name: str) -> Any:
        """The raw table of a top-level section ({} when absent; the list of tables of a
        :data:`LIST_SECTIONS` one), for the module that owns it."""
        value = self.raw.get(name, {})
        if not isinstance(value, Mapping) and not (name in LIST_SECTIONS
                                                   and isinstance(value, list)):
            raise ConfigError(f"config error: {name} = {_fmt(value)}: must be a table")
        return value


def _parse_buoy(r: SectionReader) -> BuoyConfig:
    buoy_id = r.str("id")
    try:
        validate_buoy_id(buoy_id)
    except ValueError as exc:
        raise r.error("id", buoy_id, str(exc)) from None
    out = BuoyConfig(buoy_id, r.float("design_life_years", 20.0, gt=0))
    r.done()
    return out


def _parse_mooring(r: SectionReader) -> MooringConfig:
    preset = r.raw("preset")
    tables = r.table_list("segment")
    if preset is not None and tables:
        raise r.error("preset", preset, "give either a preset or [[mooring.segment]], not both")
    segments: list[SegmentConfig] = []
    if preset is not None:
        if preset not in MOORING_PRESETS:
            raise r.error("preset", preset, f"must be one of {sorted(MOORING_PRESETS)}")
        p = MOORING_PRESETS[preset]
        length = p["length_m"]
        depth = r.float("depth_m", p["depth_m"], gt=0)
        span = r.float("span_m", p["span_m"], gt=0)
    else:
        if not tables:
            raise ConfigError("config error: mooring: needs preset or [[mooring.segment]] tables")
        for i, t in enumerate(tables):
            s = SectionReader(t, f"mooring.segment[{i}]")
            segments.append(SegmentConfig(
                s.str("name"), s.float("length_m", gt=0), s.float("weight_N_per_m"),
                s.float("ea_N", gt=0, allow_inf=True), s.float("diameter_m", gt=0),
            ))
            s.done()
        length = sum(seg.length_m for seg in segments)
        depth = r.float("depth_m", gt=0)
        span = r.float("span_m", gt=0)
    if length < depth:
        raise r.error("depth_m", depth, f"deeper than the line is long ({length:g} m)")
    if span >= length:
        raise r.error("span_m", span, f"must be shorter than the line ({length:g} m)")
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
            if r.has(key):
                raise r.error(key, r.raw(key), 'only with twist = "limited"')
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
        raise ConfigError(
            f"config error: {path} = {_fmt(value)}: stress_range_Pa and cycles must be "
            "positive lists of the same length"
        )
    return SNCurveConfig(None, ranges, cycles)


def _parse_component(r: SectionReader) -> ComponentConfig:
    kind = r.str("kind", "conductor", choices=("conductor", "axial"))
    lay = r.str("lay", choices=("left", "right")) if kind == "conductor" else None
    area = r.float("area_m2", gt=0) if kind == "axial" else None
    sn_raw = r.raw("sn_curve", "vaps_copper")
    out = ComponentConfig(
        name=r.str("name"),
        kind=kind,
        lay=lay,
        area_m2=area,
        sn_curve=_parse_sn(sn_raw, f"{r.path}.sn_curve"),
        mean_stress=r.str("mean_stress", "none",
                          choices=("none", "goodman", "gerber", "walker", "swt")),
        ultimate_Pa=r.float("ultimate_Pa", gt=0) if r.has("ultimate_Pa") else None,
        derating=r.float("derating", 1.0, gt=0),
        scf=r.float("scf", 1.0, gt=0),
        dff=r.float("dff", 1.0, gt=0),
        hysteresis_Pa=r.float("hysteresis_Pa", 0.0, ge=0),
        **_parse_location(r, kind),
    )
    if out.mean_stress != "none" and out.ultimate_Pa is None:
        raise r.error("mean_stress", out.mean_stress, "needs ultimate_Pa")
    r.done()
    return out


_BEND_KEYS = ("bend_radius_m", "bend_angle_deg", "bend_gauge_length_m")


def _parse_location(r: SectionReader, kind: str) -> dict[str, Any]:
    """``location`` and, at a termination, its bend (models.termination.TerminationBend)."""
    choices = ("free_span", "termination") if kind == "conductor" else ("free_span",)
    location = r.str("location", "free_span", choices=choices)
    if location == "free_span":
        for key in _BEND_KEYS:
            if r.has(key):
                raise r.error(key, r.raw(key), 'only with location = "termination"')
        return {"location": location}
    return {
        "location": location,
        "bend_radius_m": r.float("bend_radius_m", gt=0),
        "bend_angle_deg": r.float("bend_angle_deg", ge=0, le=180.0),
        "bend_gauge_length_m": (r.float("bend_gauge_length_m", gt=0)
                                if r.has("bend_gauge_length_m") else None),
    }


def _parse_fatigue(r: SectionReader) -> FatigueConfig:
    edges = r.floats("histogram_edges_Pa", [i * 5.0e6 for i in range(41)], increasing=True,
                     min_len=2)
    out = FatigueConfig(
        rate_window_s=r.float("rate_window_s", 3600.0, gt=0, le=MAX_DURATION_S),
        histogram_edges_Pa=edges,
        reference_cycles=r.float("reference_cycles", 1.0e7, gt=0),
    )
    r.done()
    return out


def _parse_load(r: SectionReader) -> LoadConfig:
    out = LoadConfig(
        source=r.str("source", "auto", choices=("auto", "measured", "estimated")),
        stale_after_s=r.float("stale_after_s", 5.0, gt=0, le=MAX_DURATION_S),
        motion_sensor=r.str("motion_sensor", "auto", choices=("auto", "imu", "motion")),
        motion_rate_hz=("auto" if r.raw("motion_rate_hz", "auto") == "auto"
                        else r.float("motion_rate_hz", gt=0)),
        breaking_load_N=r.float("breaking_load_N", 45_000.0, gt=0),
        slack_limit_N=r.float("slack_limit_N", 0.0),
    )
    if not out.slack_limit_N < out.breaking_load_N:
        raise r.error("slack_limit_N", out.slack_limit_N,
                      f"must be < breaking_load_N ({out.breaking_load_N:g})")
    r.done()
    return out


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
            raise r.error(key, r.table[key], f"unknown sensor; expected one of {sorted(SENSOR_FIELDS)}")
    derived = qc_defaults(mooring, load)
    for sensor, defaults in DEFAULT_LIMITS.items():
        s = SectionReader(r.raw(sensor, {}), f"validate.{sensor}")
        fields = {}
        for name, (lo, hi, rate) in defaults.items():
            f = SectionReader(s.raw(name, {}), f"validate.{sensor}.{name}")
            fields[name] = _parse_field(f, lo, hi, rate, derived[sensor].get(name, {}))
        stale_default = load.stale_after_s if sensor == "tension" else DEFAULT_STALE_S[sensor]
        stale = s.float("stale_after_s", stale_default, gt=0, le=MAX_DURATION_S)
        if sensor == "tension" and s.has("stale_after_s") and stale != load.stale_after_s:
            raise s.error("stale_after_s", stale, "tension staleness is set by load.stale_after_s")
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
        out[sensor] = SensorLimits(fields, stale, location, watch, check)
    return out


def _parse_ordering(r: SectionReader) -> OrderingConfig:
    out = OrderingConfig(r.float("horizon_s", 10.0, gt=0, le=MAX_DURATION_S),
                         r.float("replay_horizon_s", 3600.0, gt=0, le=MAX_DURATION_S))
    r.done()
    return out


def _parse_alert_timing(raw: Any) -> AlertsTiming:
    # Only the timing keys are core; rules and delivery belong to monitor.alerts.
    r = SectionReader(raw, "alerts")
    interval = r.float("eval_interval_s", 10.0, gt=0, le=MAX_DURATION_S)
    if interval * 1e9 != round(interval * 1e9):
        raise r.error("eval_interval_s", interval, "must be a whole number of nanoseconds")
    return AlertsTiming(interval, r.float("resend_interval_s", 3600.0, ge=0,  # 0 = never
                                          le=MAX_DURATION_S))


def parse_config(data: Mapping[str, Any], source: str = "<dict>") -> Config:
    """Validate a parsed TOML document and return the typed configuration."""
    top = SectionReader(data, "")
    known = set(CORE_SECTIONS) | set(SECTION_PARSERS)
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(f"config error: unknown section(s) {unknown}; expected {sorted(known)}")
    load = _parse_load(SectionReader(top.raw("load", {}), "load"))
    tables = top.table_list("component")
    if not tables:
        raise ConfigError("config error: component: at least one [[component]] is required")
    components = tuple(
        _parse_component(SectionReader(t, f"component[{i}]")) for i, t in enumerate(tables)
    )
    names = [c.name for c in components]
    for i, name in enumerate(names):
        if names.index(name) != i:
            raise ConfigError(f"config error: component[{i}].name = {name!r}: duplicate name")
    mooring = _parse_mooring(SectionReader(top.raw("mooring", {"preset": "vaps_seed004"}),
                                           "mooring"))
    return Config(
        buoy=_parse_buoy(SectionReader(top.raw("buoy", {}), "buoy")),
        mooring=mooring,
        cable=_parse_cable(SectionReader(top.raw("cable", {}), "cable")),
        components=components,
        fatigue=_parse_fatigue(SectionReader(top.raw("fatigue", {}), "fatigue")),
        load=load,
        validate=_parse_validate(SectionReader(top.raw("validate", {}), "validate"), load,
                                 mooring),
        ordering=_parse_ordering(SectionReader(top.raw("ordering", {}), "ordering")),
        alerts=_parse_alert_timing(top.raw("alerts", {})),
        raw=data,
        source=source,
    )


def load_config(path: str | Path) -> Config:
    """Read and validate a TOML configuration file."""
    path = Path(path)
    try:
        with path.open("rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"config error: file {str(path)!r} not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config error: {path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"config error: {path}: not valid TOML (not UTF-8 text)") from None
    return parse_config(data, source=str(path))


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


def run_section_parsers(config: Config) -> dict[str, str]:
    """Run every external section parser; return ``{section: "ok" | "not checked: ..."}``.

    A ConfigError from a parser propagates.
    """
    results: dict[str, str] = {}
    for name, target in SECTION_PARSERS.items():
        if name not in config.raw:
            continue
        module_name, func_name = target.split(":")
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            missing = exc.name or ""
            if module_name == missing or module_name.startswith(missing + "."):
                results[name] = f"not checked: {module_name} is not installed"
                continue
            raise
        parser: Any = module
        for attr in func_name.split("."):
            parser = getattr(parser, attr, None)
        if not callable(parser):
            results[name] = f"not checked: {module_name} has no {func_name}"
            continue
        try:
            parser(config.section(name))
        except ConfigError:
            raise
        except ValueError as exc:
            msg = str(exc)
            raise ConfigError(msg if msg.startswith("config error") else f"config error: {msg}") from None
        results[name] = "ok"
    return results
