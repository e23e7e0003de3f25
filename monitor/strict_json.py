"""Strict JSON for everything the service and its files write (RFC 8259 has no NaN or
infinity, and numpy values are not JSON types).

- ``json_ready(obj, nonfinite="null")``: a copy with mappings as dicts with string keys,
  tuples and numpy arrays as lists, numpy scalars as Python values, and each NaN or
  infinity as None (``"null"``: live messages and MCAP records) or as the string "nan",
  "inf" or "-inf" (``"text"``: the report, see docs/REPORT_FORMAT.md).
- ``to_json_bytes(doc)``: compact strict JSON of ``json_ready(doc)``, UTF-8.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np


def json_ready(obj: Any, nonfinite: Literal["null", "text"] = "null") -> Any:
    """JSON-ready copy of ``obj`` (see the module docstring)."""
    # the plain types first, by their exact type: a report's ~100,000 numbers and strings
    # went through the Mapping check (an abstract class's, ~3 us each: 0.1-0.2 s at the
    # end of a 30-day replay)
    kind = type(obj)
    if kind is float:
        return _number(obj, nonfinite)
    if kind is int or kind is str or kind is bool or obj is None:
        return obj
    if kind is dict or isinstance(obj, Mapping):
        return {str(k): json_ready(v, nonfinite) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [json_ready(v, nonfinite) for v in (obj.tolist() if isinstance(obj, np.ndarray) else obj)]
    if isinstance(obj, np.generic):
        obj = obj.item()
    return _number(obj, nonfinite) if isinstance(obj, float) else obj


def _number(x: float, nonfinite: Literal["null", "text"]) -> Any:
    if math.isfinite(x):
        return x
    return str(x) if nonfinite == "text" else None


def to_json_bytes(doc: Any) -> bytes:
    """Compact strict JSON (non-finite floats become null), UTF-8."""
    return json.dumps(json_ready(doc), separators=(",", ":"), allow_nan=False).encode()
