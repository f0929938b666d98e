"""Descriptives and demographics per condition: what every report shows, even for a pilot.

Inferential tests need enough participants; these numbers do not, so a pilot of one or two
people still gets a table of what they did (and the report says which tests need more).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from cfteach.analysis.aggregate import Frames
from cfteach.analysis.io import CONDITIONS, DIFFICULTIES, LIKERT_ITEMS

#: Readable names of the four conditions (report and figures).
CONDITION_LABELS = {
    "baseline": "Baseline",
    "feature_only": "Feature scaffolding",
    "counterfactual_only": "Counterfactual",
    "proposed": "Counterfactual + feature scaffolding",
}


def _m_sd(values: pd.Series) -> dict[str, float | int | None]:
    v = pd.to_numeric(values, errors="coerce").dropna().astype(float)
    n = int(len(v))
    return {
        "n": n,
        "mean": float(v.mean()) if n else None,
        "sd": float(v.std(ddof=1)) if n > 1 else None,
    }


def descriptives(frames: Frames, participants: pd.DataFrame | None = None) -> dict[str, Any]:
    """Per condition (and overall): N, proportion optimal per difficulty and overall,
    median confidence, Likert medians, and age / gender of the retained participants."""
    cells, subj = frames.cells, frames.subjects.copy()
    subj["condition"] = subj["condition"].astype(str)
    demo = participants if participants is not None else frames.participants
    if demo is None:
        demo = pd.DataFrame({"participant_id": [], "age": [], "gender": []})
    rows = []
    for cond in [*CONDITIONS, "all"]:
        mine = subj if cond == "all" else subj[subj["condition"] == cond]
        ids = mine["participant_id"]
        if cond != "all" and ids.empty:
            continue
        c = cells[cells["participant_id"].isin(ids)]
        s = subj[subj["participant_id"].isin(ids)]
        d = demo[demo["participant_id"].isin(ids)]
        gender = d["gender"].fillna("not given").astype(str).value_counts()
        rows.append(
            {
                "condition": cond,
                "label": CONDITION_LABELS.get(cond, "All conditions"),
                "n": int(len(ids)),
                "proportion_optimal": _m_sd(s["proportion_optimal"]),
                "by_difficulty": {
                    dd: _m_sd(c.loc[c["difficulty"] == dd, "optimal"]) for dd in DIFFICULTIES
                },
                "confidence": _m_sd(c["confidence"]),
                "likert_median": {
                    it: (float(np.nanmedian(s[it])) if s[it].notna().any() else None)
                    for it in LIKERT_ITEMS
                },
                "age": _m_sd(d["age"]),
                "gender": {str(k): int(v) for k, v in gender.items()},
            }
        )
    return {"test": "descriptives per condition (means, SDs over participants)", "rows": rows}
