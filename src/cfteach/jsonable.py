"""Turn results holding numpy scalars into plain JSON values (a utility every layer may use).

`json.dumps` writes non-finite floats as `NaN`/`Infinity`, which is not JSON; other tools
then fail to read the file. Results therefore carry `null` for a value that does not exist.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def to_jsonable(obj: Any) -> Any:
    """Dict keys as strings, tuples as lists, numpy scalars as Python ones, NaN/inf as None."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
