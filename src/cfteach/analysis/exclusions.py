"""Which participants enter the analysis, and why the others do not.

Rules run in a fixed order and every excluded participant gets exactly one row naming the
first rule that removed them. Nothing is hard-coded: the paper's two 3-SD outlier rules have
their thresholds (and the authors' two implementation choices) as options, and a manual list
of IDs can be passed with its own reason.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np
import pandas as pd
from scipy import stats as sps

from cfteach.analysis.io import (
    DIFFICULTIES,
    LIKERT_ITEMS,
    TESTS_PER_DOMAIN_DIFFICULTY,
    StudyExport,
)


@dataclass(frozen=True)
class ExclusionConfig:
    """Options of the exclusion rules (None disables a rule)."""

    drop_preview: bool = True
    drop_incomplete_status: bool = True  # status other than 'completed'
    require_complete_data: bool = True  # all tests, both Likert items in every domain
    expected_tests: int | None = None  # None: the design's 6 tests in each of their domains
    aggregate_sd: float | None = 3.0  # rule 1: proportion correct below mean - k SD
    aggregate_mad: float | None = None  # robust rule 1: below median - k MAD (off by default)
    item_sd: float | None = 3.0  # rule 2: reward below item mean - k SD ...
    item_count_sd: float | None = 3.0  # ... on more items than mean + k SD of the counts
    item_counts_among_nonzero: bool = True  # authors: count stats over participants with >= 1
    item_means_exclude_flagged: bool = True  # authors: item means without already-flagged IDs
    manual: dict[str, str] = field(default_factory=dict)  # participant_id -> reason
    min_minutes: float | None = None  # exclude completions faster than this (off by default)

    def __post_init__(self) -> None:
        for name in ("aggregate_sd", "aggregate_mad", "item_sd", "item_count_sd"):
            v = getattr(self, name)
            if v is not None and not v > 0:
                raise ValueError(f"{name} must be positive or None, got {v}")
        if self.min_minutes is not None and not self.min_minutes > 0:
            raise ValueError(f"min_minutes must be positive or None, got {self.min_minutes}")
        if self.expected_tests is not None and self.expected_tests < 1:
            raise ValueError(f"expected_tests must be >= 1, got {self.expected_tests}")


EXCLUSION_COLUMNS = ["participant_id", "condition", "rule", "reason"]


def session_minutes(participants: pd.DataFrame) -> pd.Series:
    """Minutes from `started_at` to `completed_at` (NaN when either is missing)."""
    start = pd.to_datetime(participants["started_at"], utc=True, errors="coerce", format="ISO8601")
    end = pd.to_datetime(participants["completed_at"], utc=True, errors="coerce", format="ISO8601")
    return (end - start).dt.total_seconds() / 60.0


def quality_flags(
    participants: pd.DataFrame, *, min_minutes: float = 10.0, practice_attempts: int = 3
) -> pd.DataFrame:
    """The authors' soft data-quality flags, reported (not excluded): sessions shorter than
    `min_minutes`, and participants who needed at least `practice_attempts` practice tries."""
    if not {"started_at", "completed_at"} <= set(participants.columns):
        return pd.DataFrame(columns=EXCLUSION_COLUMNS)
    minutes = session_minutes(participants).to_dict()  # by the participants' index labels
    rows = []
    for i, p in participants.iterrows():
        if pd.notna(minutes[i]) and minutes[i] < min_minutes:
            rows.append(_row(p, "short_session", f"{minutes[i]:.1f} min < {min_minutes:g} min"))
        tries = p.get("practice_attempts")
        if pd.notna(tries) and int(tries) >= practice_attempts:
            rows.append(_row(p, "practice_attempts", f"{int(tries)} practice attempts"))
    return pd.DataFrame(rows, columns=EXCLUSION_COLUMNS)


def _at(table: pd.DataFrame, p: pd.Series, column: str) -> float:
    """A participant's number in an outlier table indexed by participant_id (pandas types
    `.at` as any scalar; these columns are numeric)."""
    return cast(float, table.at[p["participant_id"], column])


def _row(p: pd.Series, rule: str, reason: str) -> dict[str, str]:
    return {
        "participant_id": p["participant_id"],
        "condition": p["condition"],
        "rule": rule,
        "reason": reason,
    }


def aggregate_outliers(tests: pd.DataFrame, k: float) -> pd.DataFrame:
    """Participants whose proportion correct is below mean - k SD (across participants).

    Returns participant_id, value, threshold, mean, sd for the flagged ones.
    """
    prop = tests.groupby("participant_id")["optimal"].mean().astype(float)
    mean, sd = float(prop.mean()), float(prop.std(ddof=1)) if len(prop) > 1 else float("nan")
    thr = mean - k * sd
    flagged = prop[prop < thr] if np.isfinite(thr) else prop.iloc[:0]
    return _flagged(flagged, thr, mean, sd)


def aggregate_mad_outliers(tests: pd.DataFrame, k: float) -> pd.DataFrame:
    """Participants whose proportion correct is below median - k MAD (MAD scaled by 1.4826,
    so it estimates the SD for normal data). Unlike mean - k SD, two all-wrong participants
    cannot pull the threshold below themselves. Columns as `aggregate_outliers` (mean = the
    median, sd = the scaled MAD)."""
    prop = tests.groupby("participant_id")["optimal"].mean().astype(float)
    med = float(prop.median()) if len(prop) else float("nan")
    mad = float(sps.median_abs_deviation(prop, scale="normal")) if len(prop) > 1 else float("nan")
    thr = med - k * mad
    flagged = prop[prop < thr] if np.isfinite(thr) and mad > 0 else prop.iloc[:0]
    return _flagged(flagged, thr, med, mad)


def item_outliers(
    tests: pd.DataFrame,
    k_item: float,
    k_count: float,
    *,
    counts_among_nonzero: bool = True,
    reference: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """Participants with too many rewards far below the item mean (the paper's second rule).

    For each test item (`test_id`) the mean and SD of the raw reward are taken over
    `reference` (default: `tests` itself); a response is *low* when its reward is below
    mean - k_item SD. A participant is flagged when their number of low responses exceeds
    mean + k_count SD of that number, taken over participants with at least one low response
    (`counts_among_nonzero`, the authors' choice) or over everybody.
    Returns participant_id, value (count), threshold, mean, sd for the flagged ones.
    """
    base = tests if reference is None else reference
    stats = base.groupby("test_id")["reward"].agg(["mean", "std"])
    t = tests.join(stats, on="test_id")
    low = t["reward"] < t["mean"] - k_item * t["std"].fillna(0.0)
    counts = low.groupby(t["participant_id"]).sum().astype(float)
    pool = counts[counts > 0] if counts_among_nonzero else counts
    mean = float(pool.mean()) if len(pool) else float("nan")
    sd = float(pool.std(ddof=1)) if len(pool) > 1 else float("nan")
    thr = mean + k_count * sd
    flagged = counts[counts > thr] if np.isfinite(thr) else counts.iloc[:0]
    return _flagged(flagged, thr, mean, sd)


def _flagged(flagged: pd.Series, thr: float, mean: float, sd: float) -> pd.DataFrame:
    """The flagged participants (index) with their values and the rule's statistics."""
    return pd.DataFrame(
        {
            "participant_id": flagged.index,
            "value": flagged.to_numpy(),
            "threshold": thr,
            "mean": mean,
            "sd": sd,
        }
    )


def _domains(export: StudyExport, participants: pd.DataFrame) -> dict[str, list[str]]:
    """Each participant's domains: their `domain_order`, else every domain of the export."""
    every = sorted(set(export.tests["domain"]) | set(export.likert["domain"]))
    orders = (
        participants["domain_order"]
        if "domain_order" in participants
        else pd.Series([None] * len(participants), index=participants.index)
    )
    return {
        pid: order.split(";") if isinstance(order, str) and order else every
        for pid, order in zip(participants["participant_id"], orders, strict=True)
    }


def _listing(items: list[str]) -> str:
    return ", ".join(items[:4]) + (f" and {len(items) - 4} more" if len(items) > 4 else "")


def missing_responses(
    export: StudyExport, participants: pd.DataFrame, expected_tests: int | None = None
) -> dict[str, str]:
    """participant_id -> what is missing, for participants without a complete set of tests.

    Complete is defined by the design (`TESTS_PER_DOMAIN_DIFFICULTY` tests of every
    difficulty in each of the participant's domains), never by what other participants
    have. With `expected_tests` the total must equal it and every difficulty must appear.
    """
    doms = _domains(export, participants)
    t = export.tests[export.tests["participant_id"].isin(doms)]
    per: dict[str, dict[tuple[str, str], int]] = {}
    sizes = t.groupby(["participant_id", "domain", "difficulty"]).size()
    for (pid, dom, d), n in zip(sizes.index, sizes, strict=True):
        per.setdefault(pid, {})[(dom, d)] = int(n)
    out: dict[str, str] = {}
    for pid, domains in doms.items():
        mine = per.get(pid, {})
        total = sum(mine.values())
        no_diff = [d for d in DIFFICULTIES if not any(k[1] == d for k in mine)]
        if expected_tests is not None:
            if total != expected_tests or no_diff:
                out[pid] = f"{total} of {expected_tests} test responses" + (
                    f"; no {'/'.join(no_diff)} test" if no_diff else ""
                )
            continue
        need = TESTS_PER_DOMAIN_DIFFICULTY
        gaps = [
            f"{dom}/{d} {mine.get((dom, d), 0)} of {need}"
            for dom in domains
            for d in DIFFICULTIES
            if mine.get((dom, d), 0) != need
        ]
        gaps += [
            f"{dom} not in domain_order" for dom in sorted({k[0] for k in mine} - set(domains))
        ]
        if gaps:
            expected = len(domains) * len(DIFFICULTIES) * need
            out[pid] = f"{total} of {expected} test responses ({_listing(gaps)})"
    return out


def missing_likert(export: StudyExport, participants: pd.DataFrame) -> dict[str, str]:
    """participant_id -> what is missing, for participants without both items in each domain."""
    doms = _domains(export, participants)
    lk = export.likert[export.likert["participant_id"].isin(doms)]
    have = set(zip(lk["participant_id"], lk["domain"], lk["item"], strict=True))
    out = {}
    for pid, domains in doms.items():
        gaps = [
            f"{dom}/{it}" for dom in domains for it in LIKERT_ITEMS if (pid, dom, it) not in have
        ]
        if gaps:
            need = len(domains) * len(LIKERT_ITEMS)
            out[pid] = f"{need - len(gaps)} of {need} Likert answers (missing {_listing(gaps)})"
    return out


def apply_exclusions(
    export: StudyExport, config: ExclusionConfig | None = None
) -> tuple[StudyExport, pd.DataFrame]:
    """The retained export and a table of exclusions (participant, condition, rule, reason)."""
    cfg = config or ExclusionConfig()
    parts = export.participants
    out: list[dict[str, str]] = []
    remaining = parts.copy()

    def drop(mask: pd.Series, rule: str, reason_of) -> None:
        nonlocal remaining
        for _, p in remaining[mask].iterrows():
            out.append(_row(p, rule, reason_of(p)))
        remaining = remaining[~mask]

    unknown_manual = set(cfg.manual) - set(parts["participant_id"])
    if unknown_manual:
        raise ValueError(
            f"manual exclusion lists unknown participant_id {sorted(unknown_manual)[0]!r}"
        )
    if cfg.drop_preview:
        drop(remaining["is_preview"] == 1, "preview", lambda p: "preview/test session")
    if cfg.drop_incomplete_status:
        drop(remaining["status"] != "completed", "status", lambda p: f"status is {p['status']}")
    if cfg.manual:
        drop(
            remaining["participant_id"].isin(cfg.manual),
            "manual",
            lambda p: cfg.manual[p["participant_id"]],
        )
    if cfg.min_minutes is not None:
        minutes = session_minutes(remaining)
        drop(
            minutes < cfg.min_minutes,
            "too_fast",
            lambda p: f"finished in {minutes[p.name]:.1f} min < {cfg.min_minutes:g} min",
        )
    if cfg.require_complete_data:
        ids = remaining["participant_id"]
        missing_tests = missing_responses(export, remaining, cfg.expected_tests)
        drop(
            ids.isin(missing_tests),
            "incomplete",
            lambda p: missing_tests[p["participant_id"]],
        )
        missing_lk = missing_likert(export, remaining)
        drop(
            remaining["participant_id"].isin(missing_lk),
            "incomplete",
            lambda p: missing_lk[p["participant_id"]],
        )
    flagged: set[str] = set()
    if cfg.aggregate_sd is not None:
        t = export.tests[export.tests["participant_id"].isin(remaining["participant_id"])]
        agg = aggregate_outliers(t, cfg.aggregate_sd).set_index("participant_id")
        flagged |= set(agg.index)
        drop(
            remaining["participant_id"].isin(agg.index),
            "aggregate_outlier",
            lambda p: (
                f"proportion correct {_at(agg, p, 'value'):.3f} < "
                f"{_at(agg, p, 'threshold'):.3f} (mean "
                f"{_at(agg, p, 'mean'):.3f} - {cfg.aggregate_sd:g} SD "
                f"{_at(agg, p, 'sd'):.3f})"
            ),
        )
    if cfg.aggregate_mad is not None:
        t = export.tests[
            export.tests["participant_id"].isin(set(remaining["participant_id"]) | flagged)
        ]
        mad = aggregate_mad_outliers(t, cfg.aggregate_mad).set_index("participant_id")
        flagged |= set(mad.index)
        drop(
            remaining["participant_id"].isin(mad.index),
            "aggregate_mad_outlier",
            lambda p: (
                f"proportion correct {_at(mad, p, 'value'):.3f} < "
                f"{_at(mad, p, 'threshold'):.3f} (median "
                f"{_at(mad, p, 'mean'):.3f} - {cfg.aggregate_mad:g} MAD "
                f"{_at(mad, p, 'sd'):.3f})"
            ),
        )
    if cfg.item_sd is not None and cfg.item_count_sd is not None:
        t = export.tests[export.tests["participant_id"].isin(remaining["participant_id"])]
        ref = None
        if not cfg.item_means_exclude_flagged:
            ref = export.tests[
                export.tests["participant_id"].isin(set(remaining["participant_id"]) | flagged)
            ]
        items = item_outliers(
            t,
            cfg.item_sd,
            cfg.item_count_sd,
            counts_among_nonzero=cfg.item_counts_among_nonzero,
            reference=ref,
        ).set_index("participant_id")
        drop(
            remaining["participant_id"].isin(items.index),
            "item_outlier",
            lambda p: (
                f"{int(_at(items, p, 'value'))} test rewards more than "
                f"{cfg.item_sd:g} SD below the item mean; more than "
                f"{_at(items, p, 'threshold'):.2f} (mean "
                f"{_at(items, p, 'mean'):.2f} + {cfg.item_count_sd:g} SD "
                f"{_at(items, p, 'sd'):.2f})"
            ),
        )
    table = pd.DataFrame(out, columns=EXCLUSION_COLUMNS)
    return export.subset(list(remaining["participant_id"])), table
