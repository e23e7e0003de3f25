"""monitor.strict_json: the one JSON sanitiser (MCAP JSON records, live messages, report)."""

import json
import types

import numpy as np

from monitor.strict_json import json_ready, to_json_bytes


def test_nonfinite_as_null_or_text_and_numpy_as_python():
    doc = types.MappingProxyType({1: (np.float32("nan"), np.inf), "b": np.array([1.5, -np.inf]),
                                  "c": np.int64(7), "d": [True, None, "x"]})
    assert json_ready(doc) == {"1": [None, None], "b": [1.5, None], "c": 7, "d": [True, None, "x"]}
    text = json_ready(doc, "text")
    assert text["1"] == ["nan", "inf"] and text["b"] == [1.5, "-inf"]
    assert type(text["c"]) is int
    assert json.loads(to_json_bytes(doc)) == json_ready(doc)
    assert to_json_bytes({"a": float("nan"), "b": 1.5}) == b'{"a":null,"b":1.5}'
