"""Quanta of the log format: the resolution each sensor field is stored to (docs/LOG_FORMAT.md).

A light module (no numba) so that command-line parsing can check ``--quantum`` options
without loading the codec.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from monitor.blocks import SENSOR_FIELDS

# Default quantum per field: the resolution of a typical sensor of that kind (a 0.1 N load
# cell, a 16-bit +-2 g accelerometer is ~6e-4 m/s^2 so 1e-4 keeps it, 1 mm displacement, 1e-7
# deg ~ 1 cm of GNSS position, 1 mm / 1 ms for the wave statistics). Override per field.
DEFAULT_QUANTA: Mapping[str, float] = {
    "tension_N": 0.1,
    "heave_m": 1e-3, "surge_m": 1e-3, "sway_m": 1e-3,
    "accel_x_mps2": 1e-4, "accel_y_mps2": 1e-4, "accel_z_mps2": 1e-4,
    "lat_deg": 1e-7, "lon_deg": 1e-7,
    "hs_m": 1e-3, "tp_s": 1e-3,
}


def quanta(sensor: str, overrides: Mapping[str, float] | None = None) -> np.ndarray:
    """Quantum of each field of ``sensor`` (SENSOR_FIELDS order): ``overrides`` by field name,
    else :data:`DEFAULT_QUANTA`. ValueError for an unknown field or a quantum not finite > 0
    (fields of other sensors in ``overrides`` are ignored, so one mapping serves all)."""
    if sensor not in SENSOR_FIELDS:
        raise ValueError(f"unknown sensor {sensor!r}; expected one of {sorted(SENSOR_FIELDS)}")
    overrides = overrides or {}
    unknown = sorted(set(overrides) - set(DEFAULT_QUANTA))
    if unknown:
        raise ValueError(f"quantum for unknown fields {unknown}; known: {sorted(DEFAULT_QUANTA)}")
    out = np.array([float(overrides.get(f, DEFAULT_QUANTA[f])) for f in SENSOR_FIELDS[sensor]])
    bad = [f for f, q in zip(SENSOR_FIELDS[sensor], out) if not (math.isfinite(q) and q > 0)]
    if bad:
        raise ValueError(f"quantum of {bad} must be finite and > 0, got "
                         f"{[overrides.get(f) for f in bad]}")
    return out


def parse_quanta(items: Sequence[str]) -> dict[str, float]:
    """``["tension_N=0.01", ...]`` (the ``--quantum`` options) as a field -> quantum mapping;
    ValueError naming the bad item."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            q = float(value)
        except ValueError:
            q = math.nan
        if not sep or name not in DEFAULT_QUANTA or not (math.isfinite(q) and q > 0):
            raise ValueError(f"--quantum {item!r}: expected FIELD=Q with FIELD one of "
                             f"{sorted(DEFAULT_QUANTA)} and Q a number > 0")
        out[name] = q
    return out


def add_quantum_option(parser: Any) -> None:
    """The ``--quantum FIELD=Q`` option (repeatable) of the commands that write logs."""
    parser.add_argument(
        "--quantum", action="append", default=[], metavar="FIELD=Q",
        help="store FIELD to a resolution of Q (its unit; repeatable), e.g. tension_N=0.01; "
             "every sample is kept to within Q/2. Defaults: "
             + ", ".join(f"{k}={v:g}" for k, v in DEFAULT_QUANTA.items()))
