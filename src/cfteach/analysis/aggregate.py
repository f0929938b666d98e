"""The analysis frames built from a (retained) export, aggregated the way the paper did.

Correctness per participant x difficulty is the **mean** of the binary scores, confidence the
**median** (it can be x.5), Likert ratings per participant the **median** over domains.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from cfteach.analysis.io import CF_CONDITIONS, CONDITIONS, DIFFICULTIES, FS_CONDITIONS, StudyExport

CF_LABELS = {0: "no counterfactual", 1: "counterfactual"}
FS_LABELS = {0: "no feature scaffolding", 1: "feature scaffolding"}


@dataclass(frozen=True)
class Frames:
    """Long and aggregated frames the statistics run on."""

    tests: pd.DataFrame  # one row per test, with design columns and time_norm
    cells: pd.DataFrame  # participant x difficulty: optimal (mean), confidence (median), ...
    domain_means: pd.DataFrame  # participant x domain: optimal (mean)
    subjects: pd.DataFrame  # one row per participant: Likert medians, replays, time
    likert_long: pd.DataFrame  # one row per Likert answer (the export's likert.csv)
    participants: pd.DataFrame | None = None  # the retained rows of participants.csv


def _design(participants: pd.DataFrame) -> pd.DataFrame:
    d = participants[["participant_id", "condition"]].copy()
    d["counterfactual"] = d["condition"].isin(CF_CONDITIONS).astype(int)
    d["feature_scaffolding"] = d["condition"].isin(FS_CONDITIONS).astype(int)
    d["condition"] = pd.Categorical(d["condition"], categories=list(CONDITIONS), ordered=True)
    return d


def build_frames(export: StudyExport) -> Frames:
    """Aggregate a retained export into the frames the paper's statistics use."""
    design = _design(export.participants)
    t = export.tests.drop(columns=["condition"]).merge(design, on="participant_id")
    t["difficulty"] = pd.Categorical(t["difficulty"], categories=list(DIFFICULTIES), ordered=True)
    t["difficulty_code"] = t["difficulty"].cat.codes.astype(int)
    t["optimal"] = t["optimal"].astype(float)
    length = pd.to_numeric(t["optimal_length"], errors="coerce").astype(float)
    t["time_norm"] = pd.to_numeric(t["time_ms"], errors="coerce").astype(float) / (
        1000.0 * length.where(length > 0)
    )
    t["confidence"] = pd.to_numeric(t["confidence"], errors="coerce").astype(float)
    keys = ["participant_id", "condition", "counterfactual", "feature_scaffolding"]
    cells = (
        t.groupby([*keys, "difficulty"], observed=True)
        .agg(
            optimal=("optimal", "mean"),
            confidence=("confidence", "median"),
            time_norm=("time_norm", "mean"),
            n_tests=("optimal", "size"),
        )
        .reset_index()
    )
    cells["difficulty_code"] = cells["difficulty"].cat.codes.astype(int)
    domain_means = (
        t.groupby(["participant_id", "domain"], observed=True)["optimal"].mean().reset_index()
    )
    lk = export.likert.pivot_table(
        index="participant_id", columns="item", values="value", aggfunc="median"
    )
    dv = export.demo_views.copy()
    dv["plays_completed"] = pd.to_numeric(dv["plays_completed"], errors="coerce").astype(float)
    dv["replays"] = pd.to_numeric(dv["replays"], errors="coerce").astype(float)
    views = dv.groupby("participant_id")[["plays_completed", "replays"]].mean()
    per = t.groupby("participant_id").agg(
        proportion_optimal=("optimal", "mean"), time_norm=("time_norm", "mean")
    )
    subjects = design.set_index("participant_id").join(per).join(lk).join(views)
    for col in ("informativeness", "mental_effort", "plays_completed", "replays"):
        if col not in subjects:
            subjects[col] = np.nan
    return Frames(
        t, cells, domain_means, subjects.reset_index(), export.likert, export.participants
    )
