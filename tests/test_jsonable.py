"""Results files stay valid JSON whatever numpy values they hold."""

import json

import numpy as np

from cfteach.jsonable import to_jsonable


def test_numpy_values_and_missing_numbers_become_plain_json() -> None:
    data = {1: (np.float64("nan"), np.int64(3), np.bool_(True)), "x": [np.inf, -np.inf, 0.5]}
    plain = to_jsonable(data)
    assert plain == {"1": [None, 3, True], "x": [None, None, 0.5]}
    # strict JSON: a NaN or Infinity token would make this raise
    json.loads(json.dumps(plain), parse_constant=lambda name: (_ for _ in ()).throw(
        ValueError(name)))
