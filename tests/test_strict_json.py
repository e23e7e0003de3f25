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


def test_plain_values_and_their_subclasses_come_out_as_the_same_json():
    """The exact plain types take a short way (a report's numbers and strings); a float
    subclass (numpy's float64) or a dict subclass still goes the general way."""
    import collections

    class Half(float):
        pass

    doc = collections.OrderedDict(a=float("-inf"), b=np.float64("inf"), c=Half("nan"),
                                  d={"e": [1, 2.5, "s", False, None, float("nan")]})
    assert json_ready(doc) == {"a": None, "b": None, "c": None,
                               "d": {"e": [1, 2.5, "s", False, None, None]}}
    text = json_ready(doc, "text")
    assert (text["a"], text["b"], text["c"]) == ("-inf", "inf", "nan")
    assert text["d"]["e"][5] == "nan" and text["d"]["e"][3] is False
    assert type(json_ready(doc)) is dict and type(json_ready(np.float64(2.0))) is float
