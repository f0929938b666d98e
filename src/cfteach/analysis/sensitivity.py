"""Sensitivity of the main results to the exclusions.

An outlier rule is a choice; a reader should see whether the conclusions depend on it. The
H1 ANOVA and the full 2 x 2 x 3 model are recomputed (a) as analysed, (b) without any
outlier or manual exclusion (preview, status and incomplete data still apply: the tests
cannot use those), and (c) with the robust rule, median - 3 MAD, in place of mean - 3 SD.
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from typing import Any

from cfteach.analysis.exclusions import ExclusionConfig, apply_exclusions
from cfteach.analysis.io import StudyExport

ROBUST_K = 3.0


def variants(cfg: ExclusionConfig) -> dict[str, ExclusionConfig]:
    """name -> exclusion config of each sensitivity analysis."""
    none = replace(
        cfg, aggregate_sd=None, aggregate_mad=None, item_sd=None, manual={}, min_minutes=None
    )
    out = {"as analysed": cfg, "without outlier or manual exclusions": none}
    if cfg.aggregate_mad is None:
        out[f"median - {ROBUST_K:g} MAD instead of mean - k SD"] = replace(
            cfg, aggregate_sd=None, aggregate_mad=ROBUST_K
        )
    return out


def _main_tests(export: StudyExport, cfg: ExclusionConfig) -> dict[str, Any]:
    from cfteach.analysis import stats
    from cfteach.analysis.aggregate import build_frames
    from cfteach.analysis.factorial import full_anova

    kept, excluded = apply_exclusions(export, cfg)
    row: dict[str, Any] = {
        "n_retained": int(len(kept.participants)),
        "n_excluded_by_rule": excluded["rule"].value_counts().to_dict(),
    }
    if kept.tests.empty:
        return {**row, "skipped": "no participant left"}
    frames = build_frames(kept)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rm = stats.rm_anova_difficulty(frames)
    row["h1"] = {k: rm.get(k) for k in ("F", "df1", "df2", "p", "n_participants", "skipped")}
    full = full_anova(stats.complete_cells(frames.cells))
    rejected = bool(full.get("sphericity", {}).get("rejected"))
    row["full_anova"] = {
        t["term"]: {"F": t["F"], "p": t["p_gg"] if rejected and t["p_gg"] is not None else t["p"]}
        for t in full.get("terms", [])
    }
    if "skipped" in full:
        row["full_anova_skipped"] = full["skipped"]
    return row


def sensitivity(export: StudyExport, cfg: ExclusionConfig) -> dict[str, Any]:
    """The main tests under each exclusion variant (`variants`)."""
    return {
        "note": "p of the full model is GG-corrected where Mauchly rejects, as in the report",
        "variants": [{"name": name, **_main_tests(export, c)} for name, c in variants(cfg).items()],
    }
