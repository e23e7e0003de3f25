"""Time-stamped blocks of sensor samples: the unit of data that flows through buoymon.

Every source (an MCAP log, a Zenoh subscription, a CSV import, the simulator) produces
:class:`SampleBlock` objects and every consumer (the pipeline core, recorders) takes them.
A block carries consecutive samples of ONE sensor of ONE buoy, e.g. one second of 20 Hz
tension. Times are sensor times in integer nanoseconds since the Unix epoch (UTC); values are
float64 in SI units, one array per field, all the same length as ``t_ns``.

Sensors, fields and units (the log format and the Zenoh payloads carry exactly these):

============  =================  =======  ==============================================
sensor        field              unit     meaning
============  =================  =======  ==============================================
``tension``   ``tension_N``      N        top tension measured by the load cell
``motion``    ``heave_m``        m        vertical displacement, up positive
              ``surge_m``        m        horizontal displacement along the mooring's
                                          mean direction (anchor -> buoy)
              ``sway_m``         m        horizontal displacement, perpendicular to surge
                                          (to port when looking from anchor to buoy)
``imu``       ``accel_x_mps2``   m/s^2    acceleration along surge, gravity removed
              ``accel_y_mps2``   m/s^2    acceleration along sway
              ``accel_z_mps2``   m/s^2    vertical acceleration, gravity removed
``gnss``      ``lat_deg``        deg      WGS84 latitude
              ``lon_deg``        deg      WGS84 longitude
``waves``     ``hs_m``           m        significant wave height (low rate, e.g. 30 min)
              ``tp_s``           s        peak period
============  =================  =======  ==============================================

Topics / Zenoh key expressions: ``buoy/<id>/sensor/<sensor>``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Mapping

import numpy as np

SENSOR_FIELDS: Mapping[str, Mapping[str, str]] = {
    "tension": {"tension_N": "N"},
    "motion": {"heave_m": "m", "surge_m": "m", "sway_m": "m"},
    "imu": {"accel_x_mps2": "m/s^2", "accel_y_mps2": "m/s^2", "accel_z_mps2": "m/s^2"},
    "gnss": {"lat_deg": "deg", "lon_deg": "deg"},
    "waves": {"hs_m": "m", "tp_s": "s"},
}

_BUOY_ID = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
_TOPIC = re.compile(r"^buoy/(?P<buoy>[^/]+)/sensor/(?P<sensor>[^/]+)$")


def validate_buoy_id(buoy_id: str) -> str:
    """Return ``buoy_id`` if it is usable as one Zenoh key chunk, else raise ValueError."""
    if not isinstance(buoy_id, str) or not _BUOY_ID.match(buoy_id):
        raise ValueError(
            f"buoy id {buoy_id!r} must be 1-64 characters of letters, digits, '_', '.', '-'"
        )
    return buoy_id


def sensor_topic(buoy_id: str, sensor: str) -> str:
    """The MCAP topic and Zenoh key expression of one buoy's sensor stream."""
    return f"buoy/{validate_buoy_id(buoy_id)}/sensor/{sensor}"


def parse_sensor_topic(topic: str) -> tuple[str, str]:
    """Split ``buoy/<id>/sensor/<name>`` into ``(buoy_id, sensor)``; ValueError otherwise."""
    m = _TOPIC.match(topic)
    if m is None:
        raise ValueError(f"topic {topic!r} is not of the form buoy/<id>/sensor/<name>")
    return m["buoy"], m["sensor"]


@dataclass(frozen=True, eq=False)
class SampleBlock:
    """Consecutive samples of one sensor of one buoy.

    Attributes:
        buoy_id: buoy identifier (one key chunk).
        sensor: a key of :data:`SENSOR_FIELDS`.
        t_ns: int64 sensor time of every sample, ns since the Unix epoch, shape ``(n,)``.
        fields: float64 arrays, one per field of the sensor, each shape ``(n,)``, SI units.
        recv_ns: receive time of the block (MCAP ``log_time``), ns since the epoch; 0 if unknown.
    """

    buoy_id: str
    sensor: str
    t_ns: np.ndarray
    fields: Mapping[str, np.ndarray]
    recv_ns: int = 0

    def __post_init__(self) -> None:
        if self.sensor not in SENSOR_FIELDS:
            raise ValueError(
                f"unknown sensor {self.sensor!r}; expected one of {sorted(SENSOR_FIELDS)}"
            )
        t = np.asarray(self.t_ns)
        if t.ndim != 1 or t.dtype != np.int64:
            raise ValueError(f"{self.sensor}: t_ns must be a 1-D int64 array, got {t.dtype}{t.shape}")
        expected = SENSOR_FIELDS[self.sensor]
        missing = set(expected) - set(self.fields)
        extra = set(self.fields) - set(expected)
        if missing or extra:
            raise ValueError(
                f"{self.sensor}: fields must be {sorted(expected)}; "
                f"missing {sorted(missing)}, unexpected {sorted(extra)}"
            )
        for name, values in self.fields.items():
            v = np.asarray(values)
            if v.shape != t.shape or v.dtype != np.float64:
                raise ValueError(
                    f"{self.sensor}.{name}: expected float64 of shape {t.shape}, "
                    f"got {v.dtype}{v.shape}"
                )

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    @property
    def topic(self) -> str:
        return sensor_topic(self.buoy_id, self.sensor)

    @property
    def t_first_ns(self) -> int:
        return int(self.t_ns[0]) if len(self) else 0

    @property
    def t_last_ns(self) -> int:
        return int(self.t_ns[-1]) if len(self) else 0
