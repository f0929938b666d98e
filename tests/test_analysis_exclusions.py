"""Exclusion rules on hand-made exports whose right answer is known."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cfteach.analysis import ExclusionConfig, StudyExport, apply_exclusions
from cfteach.analysis.exclusions import aggregate_outliers, item_outliers
from cfteach.analysis.io import CONDITIONS, DIFFICULTIES

DOMAINS = ("delivery", "tiles", "skateboard")
ITEMS = [(d, diff, f"{d}-{diff}-{ab}") for d in DOMAINS for diff in DIFFICULTIES for ab in "ab"]


def make_export(
    optimal: np.ndarray,
    reward: np.ndarray,
    *,
    status: list[str] | None = None,
    preview: list[int] | None = None,
) -> StudyExport:
    """An export of P participants x 18 items with the given scores and rewards."""
    p = optimal.shape[0]
    ids = [f"p{i:02d}" for i in range(p)]
    conds = [CONDITIONS[i % 4] for i in range(p)]
    parts = pd.DataFrame(
        {
            "participant_id": ids,
            "condition": conds,
            "status": status or ["completed"] * p,
            "is_preview": preview or [0] * p,
        }
    )
    rows, lk = [], []
    for i, pid in enumerate(ids):
        for j, (dom, diff, tid) in enumerate(ITEMS):
            rows.append(
                {
                    "participant_id": pid,
                    "condition": conds[i],
                    "domain": dom,
                    "test_id": tid,
                    "difficulty": diff,
                    "optimal": int(optimal[i, j]),
                    "reward": reward[i, j],
                    "optimal_reward": -1.0,
                }
            )
        for dom in DOMAINS:
            for item in ("informativeness", "mental_effort"):
                lk.append(
                    {
                        "participant_id": pid,
                        "condition": conds[i],
                        "domain": dom,
                        "item": item,
                        "value": 3,
                    }
                )
    demos = pd.DataFrame(columns=["participant_id", "condition", "domain"])
    return StudyExport(parts, pd.DataFrame(rows), pd.DataFrame(lk), demos)


def _clean(p: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    opt = (rng.random((p, 18)) < 0.7).astype(int)
    reward = np.where(opt == 1, -1.0, -1.2 + rng.normal(0, 0.01, (p, 18)))
    return opt, reward


def test_preview_status_and_manual_rules_in_order() -> None:
    opt, rew = _clean(8)
    ex = make_export(
        opt,
        rew,
        status=[
            "completed",
            "screened_out",
            "abandoned",
            "completed",
            "in_progress",
            "completed",
            "completed",
            "completed",
        ],
        preview=[0, 0, 0, 1, 0, 0, 0, 0],
    )
    cfg = ExclusionConfig(aggregate_sd=None, item_sd=None, manual={"p05": "asked to withdraw"})
    kept, table = apply_exclusions(ex, cfg)
    assert table.set_index("participant_id")["rule"].to_dict() == {
        "p03": "preview",
        "p01": "status",
        "p02": "status",
        "p04": "status",
        "p05": "manual",
    }
    assert table.set_index("participant_id").at["p01", "reason"] == "status is screened_out"
    assert table.set_index("participant_id").at["p05", "reason"] == "asked to withdraw"
    assert list(kept.participants["participant_id"]) == ["p00", "p06", "p07"]
    assert set(kept.tests["participant_id"]) == {"p00", "p06", "p07"}
    # each excluded participant appears once, even if several rules apply
    ex2 = make_export(opt, rew, status=["screened_out"] * 8, preview=[1] * 8)
    _, t2 = apply_exclusions(ex2, ExclusionConfig(aggregate_sd=None, item_sd=None))
    assert len(t2) == 8 and set(t2["rule"]) == {"preview"}


def test_options_keep_preview_and_unknown_manual_id() -> None:
    opt, rew = _clean(4)
    ex = make_export(opt, rew, preview=[1, 0, 0, 0])
    kept, table = apply_exclusions(
        ex, ExclusionConfig(drop_preview=False, aggregate_sd=None, item_sd=None)
    )
    assert len(kept.participants) == 4 and table.empty
    with pytest.raises(ValueError, match="unknown participant_id 'zz'"):
        apply_exclusions(ex, ExclusionConfig(manual={"zz": "x"}))


def test_incomplete_data() -> None:
    opt, rew = _clean(5)
    ex = make_export(opt, rew)
    tests = ex.tests.drop(ex.tests.index[(ex.tests.participant_id == "p01")][:3])
    likert = ex.likert.drop(ex.likert.index[(ex.likert.participant_id == "p02")][:1])
    ex = StudyExport(ex.participants, tests, likert, ex.demo_views)
    kept, table = apply_exclusions(ex, ExclusionConfig(aggregate_sd=None, item_sd=None))
    reasons = table.set_index("participant_id")["reason"].to_dict()
    assert reasons == {
        "p01": "15 of 18 test responses (delivery/low 0 of 2, delivery/medium 1 of 2)",
        "p02": "5 of 6 Likert answers (missing delivery/informativeness)",
    }
    # an explicit expected count overrides the inferred one
    _, t2 = apply_exclusions(
        ex, ExclusionConfig(aggregate_sd=None, item_sd=None, expected_tests=15)
    )
    assert set(t2[t2.rule == "incomplete"]["participant_id"]) == {"p00", "p02", "p03", "p04"}


def test_complete_is_defined_by_the_design_not_by_the_others() -> None:
    """Everybody lacks the same three tests: before, the most anyone had (15) was 'complete'."""
    opt, rew = _clean(5)
    ex = make_export(opt, rew)
    tests = ex.tests[~ex.tests.test_id.isin(["tiles-high-a", "tiles-high-b", "tiles-low-a"])]
    ex = StudyExport(ex.participants, tests, ex.likert, ex.demo_views)
    kept, table = apply_exclusions(ex, ExclusionConfig(aggregate_sd=None, item_sd=None))
    assert kept.participants.empty
    assert set(table["reason"]) == {"15 of 18 test responses (tiles/low 1 of 2, tiles/high 0 of 2)"}


def test_eighteen_rows_without_a_high_test_are_incomplete() -> None:
    """18 rows but no 'high' cell: kept before, and then silently dropped by pingouin."""
    opt, rew = _clean(5)
    ex = make_export(opt, rew)
    t = ex.tests.copy()
    mine = (t.participant_id == "p03") & (t.difficulty == "high")
    t.loc[mine, "difficulty"] = "medium"
    t.loc[mine, "test_id"] = t.loc[mine, "test_id"] + "-as-medium"
    ex = StudyExport(ex.participants, t, ex.likert, ex.demo_views)
    _, table = apply_exclusions(ex, ExclusionConfig(aggregate_sd=None, item_sd=None))
    assert table["participant_id"].tolist() == ["p03"]
    assert table["reason"].iloc[0].startswith("18 of 18 test responses (delivery/medium 4 of 2")
    assert "delivery/high 0 of 2" in table["reason"].iloc[0]


def test_aggregate_rule_matches_hand_threshold() -> None:
    opt, rew = _clean(25, seed=1)
    opt[7] = 0  # one participant gets nothing right
    opt[8, :3] = 1
    opt[8, 3:] = 0  # another 1/6 correct
    ex = make_export(opt, rew)
    prop = opt.mean(axis=1)
    for k in (3.0, 2.0, 1.0):
        thr = prop.mean() - k * prop.std(ddof=1)
        expected = {f"p{i:02d}" for i in np.flatnonzero(prop < thr)}
        got = set(aggregate_outliers(ex.tests, k)["participant_id"])
        assert got == expected
        _, table = apply_exclusions(ex, ExclusionConfig(aggregate_sd=k, item_sd=None))
        assert set(table["participant_id"]) == expected
    assert set(aggregate_outliers(ex.tests, 3.0)["participant_id"]) == {"p07"}
    assert set(aggregate_outliers(ex.tests, 1.0)["participant_id"]) == {"p07", "p08"}


def _item_case() -> np.ndarray:
    """30 participants, rewards -1 +- 0.01 except p00 low on 3 items, p01 and p02 on 1."""
    rng = np.random.default_rng(5)
    reward = -1.0 + rng.normal(0, 0.01, (30, 18))
    reward[0, [0, 1, 2]] = -3.0
    reward[1, 3] = -3.0
    reward[2, 4] = -3.0
    return reward


def _hand_item_flags(reward: np.ndarray, k_item: float, k_count: float, nonzero: bool) -> set:
    low_counts = []
    for i in range(reward.shape[0]):
        c = 0
        for j in range(reward.shape[1]):
            col = reward[:, j]
            if reward[i, j] < col.mean() - k_item * col.std(ddof=1):
                c += 1
        low_counts.append(c)
    counts = np.array(low_counts, dtype=float)
    pool = counts[counts > 0] if nonzero else counts
    thr = pool.mean() + k_count * pool.std(ddof=1)
    return {f"p{i:02d}" for i in np.flatnonzero(counts > thr)}


def test_item_rule_authors_choice_vs_all_participants() -> None:
    reward = _item_case()
    ex = make_export(np.ones((30, 18), int), reward)
    nonzero = set(item_outliers(ex.tests, 3.0, 3.0, counts_among_nonzero=True)["participant_id"])
    everyone = set(item_outliers(ex.tests, 3.0, 3.0, counts_among_nonzero=False)["participant_id"])
    assert nonzero == _hand_item_flags(reward, 3.0, 3.0, True) == set()
    assert everyone == _hand_item_flags(reward, 3.0, 3.0, False) == {"p00"}
    _, table = apply_exclusions(
        ex, ExclusionConfig(aggregate_sd=None, item_counts_among_nonzero=False)
    )
    assert table["participant_id"].tolist() == ["p00"]
    assert table["rule"].tolist() == ["item_outlier"]
    assert table["reason"].iloc[0].startswith("3 test rewards more than 3 SD below")


def test_item_means_exclude_flagged_option() -> None:
    """A participant flagged by rule 1 widens the item SDs only when kept in the means."""
    reward = _item_case()
    opt = np.ones((30, 18), int)
    opt[29] = 0
    reward[29] = -40.0  # far below everything: huge SDs if it enters the item statistics
    ex = make_export(opt, reward)
    base = dict(aggregate_sd=3.0, item_counts_among_nonzero=False)
    _, t_excl = apply_exclusions(ex, ExclusionConfig(item_means_exclude_flagged=True, **base))
    _, t_incl = apply_exclusions(ex, ExclusionConfig(item_means_exclude_flagged=False, **base))
    assert t_excl.set_index("participant_id")["rule"].to_dict() == {
        "p29": "aggregate_outlier",
        "p00": "item_outlier",
    }
    assert t_incl.set_index("participant_id")["rule"].to_dict() == {"p29": "aggregate_outlier"}


def test_bad_config() -> None:
    with pytest.raises(ValueError, match="aggregate_sd must be positive"):
        ExclusionConfig(aggregate_sd=-1)
    with pytest.raises(ValueError, match="expected_tests must be >= 1"):
        ExclusionConfig(expected_tests=0)


def _timed(ex: StudyExport, minutes: list[float], attempts: list[int]) -> StudyExport:
    parts = ex.participants.copy()
    start = pd.Timestamp("2026-01-12T14:00:00Z")
    parts["started_at"] = [start.isoformat()] * len(parts)
    parts["completed_at"] = [(start + pd.Timedelta(minutes=m)).isoformat() for m in minutes]
    parts["practice_attempts"] = attempts
    return StudyExport(parts, ex.tests, ex.likert, ex.demo_views)


def test_quality_flags_and_optional_speed_rule() -> None:
    from cfteach.analysis.exclusions import quality_flags

    opt, rew = _clean(4)
    ex = _timed(make_export(opt, rew), [25.0, 9.5, 30.0, 4.0], [1, 3, 2, 1])
    flags = quality_flags(ex.participants)
    assert sorted(zip(flags.participant_id, flags.rule, strict=True)) == [
        ("p01", "practice_attempts"),
        ("p01", "short_session"),
        ("p03", "short_session"),
    ]
    assert "9.5 min < 10 min" in set(flags.reason)
    # flags are not exclusions ...
    kept, table = apply_exclusions(ex, ExclusionConfig(aggregate_sd=None, item_sd=None))
    assert table.empty
    # ... unless min_minutes is set
    kept, table = apply_exclusions(
        ex, ExclusionConfig(aggregate_sd=None, item_sd=None, min_minutes=5)
    )
    assert table[["participant_id", "rule"]].values.tolist() == [["p03", "too_fast"]]
    assert table.reason.iloc[0] == "finished in 4.0 min < 5 min"
    with pytest.raises(ValueError, match="min_minutes must be positive"):
        ExclusionConfig(min_minutes=0)


def test_mad_rule_catches_what_mean_minus_3_sd_misses() -> None:
    """Two all-wrong participants among 30 inflate the SD so much that mean - 3 SD is below
    zero; median - 3 MAD is not pulled down by them."""
    rng = np.random.default_rng(0)
    opt = (rng.random((30, 18)) < rng.uniform(0.45, 0.8, (30, 1))).astype(int)
    opt[[4, 17]] = 0
    reward = np.where(opt == 1, -1.0, -1.2)
    ex = make_export(opt, reward)
    base = dict(item_sd=None)
    _, sd = apply_exclusions(ex, ExclusionConfig(**base))
    assert sd.empty  # the SD rule misses both
    prop = opt.mean(axis=1)
    med = np.median(prop)
    mad = 1.4826 * np.median(np.abs(prop - med))
    want = {f"p{i:02d}" for i in np.flatnonzero(prop < med - 3 * mad)}
    assert want == {"p04", "p17"}
    _, rob = apply_exclusions(ex, ExclusionConfig(aggregate_mad=3.0, **base))
    assert set(rob["participant_id"]) == want
    assert set(rob["rule"]) == {"aggregate_mad_outlier"}
    assert "median" in rob["reason"].iloc[0] and "3 MAD" in rob["reason"].iloc[0]
    with pytest.raises(ValueError, match="aggregate_mad must be positive"):
        ExclusionConfig(aggregate_mad=0)
