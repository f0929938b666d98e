"""The full 2 x 2 x 3 split-plot ANOVA against an independent computation.

The check builds sum-to-zero design matrices by hand (numpy) and gets each type-III sum of
squares by dropping that term's columns from the full model: between terms from the
participants' means, within terms from the long data with one dummy per participant (which
absorbs the whole between stratum). Nothing is shared with the implementation (statsmodels
formulas and orthonormal contrasts).
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps

from cfteach.analysis import SyntheticConfig, apply_exclusions, compute_results, generate
from cfteach.analysis.aggregate import build_frames
from cfteach.analysis.factorial import full_anova, sphericity
from cfteach.analysis.io import DIFFICULTIES

TERMS = [
    "counterfactual",
    "feature_scaffolding",
    "difficulty",
    "counterfactual:feature_scaffolding",
    "counterfactual:difficulty",
    "feature_scaffolding:difficulty",
    "counterfactual:feature_scaffolding:difficulty",
]


def _sum_code(x: np.ndarray, levels: list) -> np.ndarray:
    """Sum-to-zero (deviation) coding: last level is -1 in every column."""
    cols = [(x == lv).astype(float) - (x == levels[-1]).astype(float) for lv in levels[:-1]]
    return np.column_stack(cols)


def _rss(y: np.ndarray, x: np.ndarray) -> float:
    beta, *_ = np.linalg.lstsq(x, y, rcond=None)
    r = y - x @ beta
    return float(r @ r)


def _blocks(df: pd.DataFrame, factors: list[str]) -> dict[str, np.ndarray]:
    codes = {
        "counterfactual": _sum_code(df["counterfactual"].to_numpy(), [0, 1]),
        "feature_scaffolding": _sum_code(df["feature_scaffolding"].to_numpy(), [0, 1]),
    }
    if "difficulty" in factors:
        codes["difficulty"] = _sum_code(df["difficulty"].astype(str).to_numpy(), list(DIFFICULTIES))
    out = {}
    for r in range(1, len(factors) + 1):
        for combo in itertools.combinations(factors, r):
            mats = [codes[f] for f in combo]
            cols = [np.prod(c, axis=0) for c in itertools.product(*[m.T for m in mats])]
            out[":".join(combo)] = np.column_stack(cols)
    return out


def hand_split_plot(cells: pd.DataFrame) -> dict[str, tuple[float, float, float]]:
    """term -> (F, df1, df2) by model comparison in each stratum."""
    cells = cells.copy()
    cells["difficulty"] = cells["difficulty"].astype(str)
    subj = cells.groupby("participant_id").agg(
        y=("optimal", "mean"),
        counterfactual=("counterfactual", "first"),
        feature_scaffolding=("feature_scaffolding", "first"),
    )
    n = len(subj)
    blocks = _blocks(subj, ["counterfactual", "feature_scaffolding"])
    full = np.column_stack([np.ones(n), *blocks.values()])
    rss_full = _rss(subj["y"].to_numpy(), full)
    df_err_b = n - full.shape[1]
    out = {}
    for name, b in blocks.items():
        reduced = np.column_stack([np.ones(n), *(v for k, v in blocks.items() if k != name)])
        ss = _rss(subj["y"].to_numpy(), reduced) - rss_full
        out[name] = (ss / b.shape[1] / (rss_full / df_err_b), b.shape[1], df_err_b)
    # within: participant dummies + every term containing difficulty
    wb = _blocks(cells, ["counterfactual", "feature_scaffolding", "difficulty"])
    wb = {k: v for k, v in wb.items() if "difficulty" in k}
    ids = cells["participant_id"].to_numpy()
    dummies = (ids[:, None] == np.unique(ids)[None, :]).astype(float)
    y = cells["optimal"].to_numpy(float)
    x_full = np.column_stack([dummies, *wb.values()])
    rss = _rss(y, x_full)
    df_err_w = len(y) - np.linalg.matrix_rank(x_full)
    for name, b in wb.items():
        reduced = np.column_stack([dummies, *(v for k, v in wb.items() if k != name)])
        ss = _rss(y, reduced) - rss
        out[name] = (ss / b.shape[1] / (rss / df_err_w), b.shape[1], df_err_w)
    return out


def _cells(seed: int, n: int, drop: int = 0, **kw) -> pd.DataFrame:
    ex = generate(SyntheticConfig(n_participants=n, seed=seed, **kw))
    kept, _ = apply_exclusions(ex)
    cells = build_frames(kept).cells
    if drop:  # unbalance the groups: drop some participants of one condition
        ids = cells.loc[cells.condition == "proposed", "participant_id"].unique()[:drop]
        cells = cells[~cells.participant_id.isin(ids)]
    return cells


@pytest.mark.parametrize(("seed", "n", "drop"), [(1, 48, 0), (4, 60, 5)])
def test_full_anova_matches_hand_strata(seed: int, n: int, drop: int) -> None:
    cells = _cells(seed, n, drop)
    res = full_anova(cells)
    got = {t["term"]: t for t in res["terms"]}
    assert [t["term"] for t in res["terms"]] == TERMS
    hand = hand_split_plot(cells)
    for term in TERMS:
        f, df1, df2 = hand[term]
        assert got[term]["F"] == pytest.approx(f, rel=1e-8), term
        assert (got[term]["df1"], got[term]["df2"]) == (df1, df2), term
        assert got[term]["p"] == pytest.approx(sps.f.sf(f, df1, df2), rel=1e-6)
    n_used = len(res["participants"])
    assert n_used == cells.participant_id.nunique()
    assert got["counterfactual"]["df2"] == n_used - 4
    assert got["difficulty"]["df2"] == 2 * (n_used - 4)


def test_sphericity_matches_pingouin_on_one_group() -> None:
    """With one between cell the pooled SSCP is the plain covariance: pingouin's Mauchly/GG."""
    import pingouin as pg

    rng = np.random.default_rng(3)
    y = rng.normal(size=(20, 3)) @ np.array([[1, 0.5, 0.2], [0, 1, 0.8], [0, 0, 0.6]])
    df = pd.DataFrame(y, columns=list(DIFFICULTIES))
    c = np.array([[1, 1], [-1, 1], [0, -2]]) / np.array([np.sqrt(2), np.sqrt(6)])
    z = y @ c
    z = z - z.mean(axis=0)
    got = sphericity(z.T @ z, len(y) - 1)
    s = pg.sphericity(df)
    assert got["mauchly_W"] == pytest.approx(s.W, rel=1e-9)
    assert got["mauchly_p"] == pytest.approx(s.pval, rel=1e-6)
    assert got["eps_gg"] == pytest.approx(pg.epsilon(df, correction="gg"), rel=1e-9)


def test_planted_crossover_only_the_full_model_sees() -> None:
    """A cf x fs crossover (cf helps without fs, hurts with it) has no marginal effects."""
    cells = _cells(7, 216, interaction=0.0).copy()
    cross = (2 * cells["counterfactual"] - 1) * (2 * cells["feature_scaffolding"] - 1)
    cells["optimal"] = (cells["optimal"] + 0.12 * cross).clip(0, 1)
    got = {t["term"]: t for t in full_anova(cells)["terms"]}
    assert got["counterfactual:feature_scaffolding"]["p"] < 1e-3


def test_results_and_skips() -> None:
    r, _ = compute_results(generate(SyntheticConfig(n_participants=40, seed=3)))
    assert [t["term"] for t in r["full_anova"]] == TERMS
    ids = set(r["full_anova_participants"])
    assert len(ids) == r["participants"]["n_retained"]
    for t in r["full_anova"]:
        assert set(t) >= {"term", "F", "df1", "df2", "p", "p_gg", "eta2_partial"}
        assert (t["p_gg"] is None) == ("difficulty" not in t["term"])
    small = generate(SyntheticConfig(n_participants=5, seed=3))
    r5, _ = compute_results(small)
    assert r5["full_anova"] == [] and "needs at least 6 participants" in r5["full_anova_skipped"]
