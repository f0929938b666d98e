"""What every wrapper of the paper's statistics shares: reading pingouin's result rows
under either spelling, JSON-ready numbers, and the cells a repeated-measures test can use.

pingouin renamed its columns in 0.6 (`p-unc` -> `p_unc`, ...) and its ICC labels in 0.7
(`ICC3k` -> `ICC(C,k)`); `_get` accepts either spelling so the pipeline runs on both.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats as sps

from cfteach.analysis.io import DIFFICULTIES

# new name -> old names, for pingouin < 0.6
_ALIASES = {
    "p_unc": ("p-unc",),
    "p_GG_corr": ("p-GG-corr",),
    "W_spher": ("W-spher",),
    "p_spher": ("p-spher",),
    "p_val": ("p-val",),
    "U_val": ("U-val",),
    "p_tukey": ("p-tukey",),
    "p_corr": ("p-corr",),
    "p_adjust": ("p-adjust",),
    "mean_A": ("mean(A)",),
    "mean_B": ("mean(B)",),
    "CI95": ("CI95%",),
}


def _num(x: Any) -> float | None:
    """A float for JSON, with NaN as None."""
    if x is None:
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(v) else v


def _get(row: pd.Series, name: str, default: Any = None) -> Any:
    """Column `name` of a pingouin result row under its new or old spelling."""
    for key in (name, *_ALIASES.get(name, ())):
        if key in row.index:
            return row[key]
    return default


def _ci(x: Any) -> list[float | None]:
    if x is None:
        return [None, None]
    arr = np.asarray(x, dtype=float).ravel()
    return [_num(arr[0]), _num(arr[1])] if arr.size == 2 else [None, None]


def mean_ci(values: pd.Series | np.ndarray, level: float = 0.95) -> dict[str, Any]:
    """Mean, SD, n and the t-based confidence interval of the mean."""
    v = np.asarray(values, dtype=float)
    v = v[~np.isnan(v)]
    n = int(v.size)
    if n == 0:
        return {"mean": None, "sd": None, "n": 0, "ci95": [None, None]}
    m = float(v.mean())
    if n < 2:
        return {"mean": m, "sd": None, "n": n, "ci95": [None, None]}
    sd = float(v.std(ddof=1))
    half = float(sps.t.ppf(0.5 + level / 2, n - 1)) * sd / math.sqrt(n)
    return {"mean": m, "sd": sd, "n": n, "ci95": [m - half, m + half]}


def skipped(test: str, why: str) -> dict[str, Any]:
    """The entry of a test the data cannot support (a pilot, a missing group, no ratings)."""
    return {"test": test, "skipped": why}


def no_variance(cells: pd.DataFrame, dv: str = "optimal") -> str | None:
    """Why a test of `dv` is undefined when every cell has the same value (else None)."""
    v = cells[dv].dropna()
    if len(v) and float(v.max() - v.min()) == 0.0:
        return (
            f"every participant x difficulty value of {dv} is {float(v.iloc[0]):.2f}: "
            "there is no variance to test"
        )
    return None


def complete_cells(cells: pd.DataFrame) -> pd.DataFrame:
    """The participant x difficulty cells of participants who have all three difficulties.

    Repeated-measures tests drop anyone else; doing it here means the N we report is the
    N the test used.
    """
    n = cells.dropna(subset=["optimal"]).groupby("participant_id", observed=True)["difficulty"]
    full = n.nunique()
    keep = full.index[full == len(DIFFICULTIES)]
    return cells[cells["participant_id"].isin(keep)]
