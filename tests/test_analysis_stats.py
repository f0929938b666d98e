"""Every statistic against an independent computation (statsmodels, scipy, or by hand)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps
from statsmodels.stats.anova import AnovaRM

from cfteach.analysis import SyntheticConfig, apply_exclusions, generate
from cfteach.analysis import stats as S
from cfteach.analysis.aggregate import build_frames
from cfteach.analysis.io import CONDITIONS, DIFFICULTIES


@pytest.fixture(scope="module")
def frames():
    ex = generate(SyntheticConfig(n_participants=48, seed=11))
    kept, _ = apply_exclusions(ex)
    return build_frames(kept)


def test_cells_aggregate_like_the_paper(frames) -> None:
    t, cells = frames.tests, frames.cells
    pid = cells["participant_id"].iloc[0]
    for d in DIFFICULTIES:
        sub = t[(t.participant_id == pid) & (t.difficulty == d)]
        row = cells[(cells.participant_id == pid) & (cells.difficulty == d)].iloc[0]
        assert row["optimal"] == pytest.approx(sub["optimal"].mean())
        assert row["confidence"] == pytest.approx(np.median(sub["confidence"]))
        assert row["n_tests"] == 6
    assert len(cells) == 3 * cells["participant_id"].nunique()


def test_rm_anova_matches_statsmodels(frames) -> None:
    res = S.rm_anova_difficulty(frames)
    cells = frames.cells.copy()
    cells["difficulty"] = cells["difficulty"].astype(str)
    sm = AnovaRM(cells, "optimal", "participant_id", within=["difficulty"]).fit().anova_table
    row = sm.loc["difficulty"]
    assert res["F"] == pytest.approx(row["F Value"], rel=1e-9)
    assert res["df1"] == row["Num DF"] and res["df2"] == row["Den DF"]
    assert res["p"] == pytest.approx(row["Pr > F"], rel=1e-6)
    n = cells["participant_id"].nunique()
    assert res["n_participants"] == n and res["df2"] == 2 * (n - 1)
    assert res["p_gg"] >= res["p"]  # the correction can only make p larger
    assert 0.5 <= res["eps_gg"] <= 1.0


def test_paired_posthoc_matches_scipy_with_holm(frames) -> None:
    res = S.posthoc_difficulty(frames, padjust="holm")["paired"]
    wide = frames.cells.pivot(index="participant_id", columns="difficulty", values="optimal")
    raw = {}
    for r in res["rows"]:
        t = sps.ttest_rel(wide[r["A"]], wide[r["B"]])
        assert r["T"] == pytest.approx(t.statistic, rel=1e-9)
        assert r["p_unc"] == pytest.approx(t.pvalue, rel=1e-6)
        raw[(r["A"], r["B"])] = t.pvalue
    # Holm by hand: sort ascending, multiply by (m - rank), running max, cap at 1
    keys = sorted(raw, key=raw.get)
    adj, running = {}, 0.0
    for i, k in enumerate(keys):
        running = max(running, min(1.0, raw[k] * (len(keys) - i)))
        adj[k] = running
    for r in res["rows"]:
        assert r["p_corr"] == pytest.approx(adj[(r["A"], r["B"])], rel=1e-6)


def test_authors_tukey_matches_statsmodels(frames) -> None:
    from statsmodels.stats.multicomp import pairwise_tukeyhsd

    res = S.posthoc_difficulty(frames)["authors_tukey"]
    c = frames.cells
    sm = pairwise_tukeyhsd(c["optimal"].to_numpy(), c["difficulty"].astype(str).to_numpy())
    table = pd.DataFrame(sm._results_table.data[1:], columns=sm._results_table.data[0])
    for r in res["rows"]:
        row = table[
            ((table.group1 == r["A"]) & (table.group2 == r["B"]))
            | ((table.group1 == r["B"]) & (table.group2 == r["A"]))
        ].iloc[0]
        assert r["p_tukey"] == pytest.approx(float(row["p-adj"]), abs=2e-3)


def test_spearman_matches_scipy(frames) -> None:
    res = S.spearman_confidence(frames)
    c = frames.cells
    sp = sps.spearmanr(c["difficulty_code"], c["confidence"])
    assert res["r"] == pytest.approx(sp.statistic, rel=1e-9)
    assert res["p"] == pytest.approx(sp.pvalue, rel=1e-6)
    assert res["n"] == len(c)
    assert res["r"] < 0  # planted: confidence falls with difficulty


def test_icc_matches_hand_computation_from_anova_mean_squares() -> None:
    table = np.array(
        [[9, 2, 5, 8], [6, 1, 3, 2], [8, 4, 6, 8], [7, 1, 2, 6], [10, 5, 6, 9], [6, 2, 4, 7]],
        dtype=float,
    )  # Shrout & Fleiss (1979): ICC(3,k) = 0.91
    n, k = table.shape
    dm = pd.DataFrame(
        [
            {"participant_id": f"s{i}", "domain": f"d{j}", "optimal": table[i, j]}
            for i in range(n)
            for j in range(k)
        ]
    )
    res = S.icc_domains(SimpleNamespace(domain_means=dm))
    grand = table.mean()
    ss_rows = k * ((table.mean(axis=1) - grand) ** 2).sum()
    ss_cols = n * ((table.mean(axis=0) - grand) ** 2).sum()
    ss_err = ((table - grand) ** 2).sum() - ss_rows - ss_cols
    msr, mse = ss_rows / (n - 1), ss_err / ((n - 1) * (k - 1))
    assert res["icc"] == pytest.approx((msr - mse) / msr, rel=1e-9)
    assert res["icc"] == pytest.approx(0.91, abs=0.005)
    assert res["F"] == pytest.approx(msr / mse, rel=1e-9)
    assert (res["df1"], res["df2"]) == (n - 1, (n - 1) * (k - 1))
    assert res["p"] == pytest.approx(sps.f.sf(msr / mse, n - 1, (n - 1) * (k - 1)), rel=1e-6)
    assert res["n_targets"] == n and res["k"] == k


def _split_plot(y: np.ndarray, group: np.ndarray) -> dict[str, tuple[float, float, float]]:
    """Balanced split-plot ANOVA by hand: y[subject, level], group[subject]."""
    n_s, b = y.shape
    groups = np.unique(group)
    a = len(groups)
    n = n_s // a
    grand = y.mean()
    gm = np.array([y[group == g].mean() for g in groups])
    jm = y.mean(axis=0)
    gjm = np.array([y[group == g].mean(axis=0) for g in groups])
    sm = y.mean(axis=1)
    ss_a = b * n * ((gm - grand) ** 2).sum()
    ss_sa = b * sum(((sm[group == g] - gm[i]) ** 2).sum() for i, g in enumerate(groups))
    ss_b = a * n * ((jm - grand) ** 2).sum()
    ss_ab = n * ((gjm - gm[:, None] - jm[None, :] + grand) ** 2).sum()
    ss_err = ((y - grand) ** 2).sum() - ss_a - ss_sa - ss_b - ss_ab
    df_a, df_sa, df_b = a - 1, a * (n - 1), b - 1
    df_ab, df_err = (a - 1) * (b - 1), a * (n - 1) * (b - 1)
    fa = (ss_a / df_a) / (ss_sa / df_sa)
    fb = (ss_b / df_b) / (ss_err / df_err)
    fab = (ss_ab / df_ab) / (ss_err / df_err)
    return {
        "between": (fa, df_a, df_sa),
        "within": (fb, df_b, df_err),
        "interaction": (fab, df_ab, df_err),
    }


@pytest.mark.parametrize("factor", ["counterfactual", "feature_scaffolding", "condition"])
def test_mixed_anova_matches_hand_split_plot(factor: str) -> None:
    rng = np.random.default_rng(4)
    n_per = 5
    conds = np.repeat(CONDITIONS, n_per)
    y = rng.random((len(conds), 3)).round(3)
    y[:, 2] -= 0.2 * (np.isin(conds, ["counterfactual_only", "proposed"]))
    rows = []
    for i, c in enumerate(conds):
        for j, d in enumerate(DIFFICULTIES):
            rows.append(
                {
                    "participant_id": f"s{i:02d}",
                    "condition": c,
                    "difficulty": d,
                    "counterfactual": int(c in ("counterfactual_only", "proposed")),
                    "feature_scaffolding": int(c in ("feature_only", "proposed")),
                    "optimal": y[i, j],
                }
            )
    cells = pd.DataFrame(rows)
    cells["difficulty"] = pd.Categorical(cells["difficulty"], list(DIFFICULTIES), ordered=True)
    res = S.mixed_anova(SimpleNamespace(cells=cells), factor)
    group = cells.drop_duplicates("participant_id")[factor].to_numpy().astype(str)
    hand = _split_plot(y, group)
    for key, (f, df1, df2) in hand.items():
        e = res["effects"][key]
        assert e["F"] == pytest.approx(f, rel=1e-9), key
        assert (e["df1"], e["df2"]) == (df1, df2), key
        assert e["p"] == pytest.approx(sps.f.sf(f, df1, df2), rel=1e-6), key
    assert res["n_participants"] == len(conds)
    # simple effects at each difficulty: Tukey; with two groups that is Student's t-test
    if factor != "condition":
        for s in res["simple_effects"]["rows"]:
            sub = cells[cells.difficulty == s["difficulty"]]
            t = sps.ttest_ind(
                sub.loc[sub[factor] == 0, "optimal"], sub.loc[sub[factor] == 1, "optimal"]
            )
            assert s["p_tukey"] == pytest.approx(t.pvalue, rel=1e-6)
            assert s["p_holm_across"] >= s["p_tukey"]
    else:
        assert len(res["simple_effects"]["rows"]) == 3 * 6
        assert len(res["overall_pairwise"]["rows"]) == 6


def test_mann_whitney_and_kruskal_match_scipy(frames) -> None:
    res = S.likert_tests(frames)
    s = frames.subjects
    for item in ("informativeness", "mental_effort"):
        for factor in ("counterfactual", "feature_scaffolding"):
            x, y = s.loc[s[factor] == 0, item], s.loc[s[factor] == 1, item]
            mw = sps.mannwhitneyu(x, y, use_continuity=True, alternative="two-sided")
            r = res[item][factor]
            assert r["U"] == pytest.approx(mw.statistic)  # U of the group without (x)
            assert r["p"] == pytest.approx(mw.pvalue, rel=1e-9)
            assert (r["n_x"], r["n_y"]) == (len(x), len(y))
        kw = sps.kruskal(*[s.loc[s["condition"] == c, item] for c in CONDITIONS])
        assert res[item]["condition"]["H"] == pytest.approx(kw.statistic, rel=1e-9)
        assert res[item]["condition"]["p"] == pytest.approx(kw.pvalue, rel=1e-9)
        pairs = res[item]["condition_pairwise"]["rows"]
        assert len(pairs) == 6
        assert all(p["p_corr"] >= p["p"] - 1e-12 for p in pairs)


def test_exploratory_anova_matches_scipy(frames) -> None:
    res = S.exploratory(frames)
    s = frames.subjects
    for measure in ("plays_completed", "time_norm"):
        for factor, levels in (("counterfactual", [0, 1]), ("condition", list(CONDITIONS))):
            f = sps.f_oneway(*[s.loc[s[factor] == lv, measure] for lv in levels])
            r = res[measure][factor]
            assert r["F"] == pytest.approx(f.statistic, rel=1e-9)
            assert r["p"] == pytest.approx(f.pvalue, rel=1e-6)
            assert (r["df1"], r["df2"]) == (len(levels) - 1, len(s) - len(levels))
    # time per optimal step: the mean over the participant's tests of time / (1000 * length)
    t = frames.tests
    pid = s["participant_id"].iloc[0]
    sub = t[t.participant_id == pid]
    expected = (sub["time_ms"] / (1000.0 * sub["optimal_length"])).mean()
    assert s.set_index("participant_id").at[pid, "time_norm"] == pytest.approx(expected)


def test_mean_ci_matches_scipy_t_interval() -> None:
    v = np.array([0.2, 0.5, 0.4, 0.9, 0.7, 0.3])
    lo, hi = sps.t.interval(0.95, len(v) - 1, loc=v.mean(), scale=sps.sem(v))
    res = S.mean_ci(v)
    assert res["ci95"] == pytest.approx([lo, hi])
    assert S.mean_ci(np.array([]))["mean"] is None


def test_unknown_factor() -> None:
    with pytest.raises(ValueError, match="factor must be one of"):
        S.mixed_anova(SimpleNamespace(cells=None), "domain")


def test_old_pingouin_column_names_are_accepted(frames, monkeypatch) -> None:
    """pingouin < 0.6 spelled 'p-unc', 'p-GG-corr', ... and < 0.7 labelled ICC3k."""
    import pingouin as pg

    new = S.rm_anova_difficulty(frames)
    real_rm, real_icc = pg.rm_anova, pg.intraclass_corr
    renames = {
        "p_unc": "p-unc",
        "p_GG_corr": "p-GG-corr",
        "W_spher": "W-spher",
        "p_spher": "p-spher",
    }
    monkeypatch.setattr(pg, "rm_anova", lambda **kw: real_rm(**kw).rename(columns=renames))
    old = S.rm_anova_difficulty(frames)
    assert old["p"] == new["p"] and old["p_gg"] == new["p_gg"]
    assert old["mauchly_W"] == new["mauchly_W"]

    def old_icc(**kw):
        res = real_icc(**kw).rename(columns={"CI95": "CI95%"})
        res["Type"] = ["ICC1", "ICC2", "ICC3", "ICC1k", "ICC2k", "ICC3k"]
        return res

    icc_new = S.icc_domains(frames)
    monkeypatch.setattr(pg, "intraclass_corr", old_icc)
    icc_old = S.icc_domains(frames)
    assert icc_old["icc"] == icc_new["icc"] and icc_old["ci95"] == icc_new["ci95"]
    monkeypatch.setattr(
        pg,
        "mwu",
        lambda x, y, **kw: pd.DataFrame(
            {"U-val": [1.0], "p-val": [0.5], "RBC": [0.1], "CLES": [0.5]}, index=["MWU"]
        ),
    )
    lk = S.likert_tests(frames)
    assert lk["mental_effort"]["counterfactual"]["U"] == 1.0
    assert lk["mental_effort"]["counterfactual"]["p"] == 0.5


def test_posthoc_without_authors_variant_and_without_correction(frames) -> None:
    res = S.posthoc_difficulty(frames, padjust="none", authors_tukey=False)
    assert "authors_tukey" not in res
    for r in res["paired"]["rows"]:
        assert r["p_corr"] == pytest.approx(r["p_unc"])
