"""Part 4 of issue 13: the repeated-measures correlation, Holm across difficulties for every
simple effect, effect-size CIs, and the p that paper_bars prints."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as sps

from cfteach.analysis import SyntheticConfig, apply_exclusions, generate
from cfteach.analysis import stats as S
from cfteach.analysis.aggregate import build_frames
from cfteach.analysis.effects import eta2_partial_ci
from cfteach.analysis.figures import simple_effect_label


@pytest.fixture(scope="module")
def frames():
    kept, _ = apply_exclusions(generate(SyntheticConfig(n_participants=60, seed=9)))
    return build_frames(kept)


def test_rm_corr_is_the_correlation_of_within_person_deviations(frames) -> None:
    res = S.rm_corr_confidence(frames)
    c = frames.cells.dropna(subset=["confidence"]).copy()
    x = c["difficulty_code"].astype(float)
    y = c["confidence"].astype(float)
    xc = x - x.groupby(c["participant_id"]).transform("mean")
    yc = y - y.groupby(c["participant_id"]).transform("mean")
    r = float(np.corrcoef(xc, yc)[0, 1])
    n_subj = c["participant_id"].nunique()
    dof = len(c) - n_subj - 1
    t = r * np.sqrt(dof / (1 - r**2))
    assert res["r"] == pytest.approx(r, rel=1e-9)
    assert res["dof"] == dof
    assert res["p"] == pytest.approx(2 * sps.t.sf(abs(t), dof), rel=1e-6)
    assert res["ci95"][0] < res["r"] < res["ci95"][1]
    import pingouin as pg

    ref = pg.rm_corr(
        data=c.assign(difficulty_code=x),
        x="difficulty_code",
        y="confidence",
        subject="participant_id",
    ).iloc[0]
    assert res["r"] == pytest.approx(ref["r"], rel=1e-9)
    assert res["dof"] == ref["dof"]
    assert res["p"] == pytest.approx(ref["pval"], rel=1e-6)
    assert res["ci95"] == pytest.approx(list(ref["CI95"]), abs=0.006)  # pingouin rounds to .01
    # the paper's Spearman uses the same cells as if independent
    assert S.spearman_confidence(frames)["n"] == len(c)


def _holm(ps: list[float]) -> list[float]:
    order = np.argsort(ps)
    m = len(ps)
    adj = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, (m - rank) * ps[i])
        adj[i] = min(1.0, running)
    return list(adj)


@pytest.mark.parametrize("factor", ["counterfactual", "condition"])
def test_simple_effects_are_holm_corrected_across_difficulties(frames, factor) -> None:
    rows = S.mixed_anova(frames, factor)["simple_effects"]["rows"]
    pairs = {(r["A"], r["B"]) for r in rows}
    assert len(pairs) == (1 if factor == "counterfactual" else 6)
    for pair in pairs:
        mine = [r for r in rows if (r["A"], r["B"]) == pair]
        assert len(mine) == 3
        want = _holm([r["p_tukey"] for r in mine])
        assert [r["p_holm_across"] for r in mine] == pytest.approx(want, rel=1e-9)


def test_paper_bars_prints_the_holm_p() -> None:
    row = {"difficulty": "high", "p_tukey": 0.02, "p_holm_across": 0.06}
    assert simple_effect_label(row) == "p_Holm = .060"
    assert simple_effect_label({**row, "p_holm_across": 0.0004}) == "p_Holm < .001"


def test_eta2_partial_ci_inverts_the_noncentral_f() -> None:
    f, df1, df2 = 6.0, 2, 120
    lo, hi = eta2_partial_ci(f, df1, df2)
    denom = df1 + df2 + 1
    lam_lo, lam_hi = lo * denom / (1 - lo), hi * denom / (1 - hi)
    assert sps.ncf.cdf(f, df1, df2, lam_lo) == pytest.approx(0.975, abs=1e-6)
    assert sps.ncf.cdf(f, df1, df2, lam_hi) == pytest.approx(0.025, abs=1e-6)
    point = f * df1 / (f * df1 + df2)
    assert lo < point < hi
    assert eta2_partial_ci(0.2, 2, 120)[0] == 0.0  # F below its null median: no lower bound


def test_effect_size_cis_in_results(frames) -> None:
    mixed = S.mixed_anova(frames, "counterfactual")
    for e in mixed["effects"].values():
        lo, hi = e["np2_ci95"]
        assert lo <= e["np2"] <= hi
    for r in S.posthoc_difficulty(frames)["paired"]["rows"]:
        lo, hi = r["hedges_ci95"]
        assert lo < r["hedges"] < hi


def test_report_gives_the_gg_corrected_h1_test_when_sphericity_is_rejected() -> None:
    from cfteach.analysis.report_format import fmt_F
    from cfteach.analysis.report_h1 import _gg_sentence

    rm = {"F": 10.0, "df1": 2.0, "df2": 100.0, "p": 1e-4, "p_gg": 3e-4, "eps_gg": 0.8}
    assert _gg_sentence({**rm, "mauchly_p": 0.2}) == ""
    text = _gg_sentence({**rm, "mauchly_p": 0.01})
    assert fmt_F(1.6, 80.0, 10.0, 3e-4) in text and "F(1.60, 80) = 10.00" in text


def test_mixed_interaction_sentence_uses_gg_when_sphericity_is_rejected(frames) -> None:
    from cfteach.analysis.report_format import fmt_F
    from cfteach.analysis.report_groups import _within_test

    inter = S.mixed_anova(frames, "counterfactual")["effects"]["interaction"]
    assert inter["mauchly_p"] is not None
    e = {**inter, "mauchly_p": 0.01, "eps_gg": 0.8}
    assert _within_test(e).startswith(
        fmt_F(e["df1"] * 0.8, e["df2"] * 0.8, e["F"], e["p_gg"]) + " (Greenhouse-Geisser"
    )
    e = {**inter, "mauchly_p": 0.5}
    assert _within_test(e) == fmt_F(e["df1"], e["df2"], e["F"], e["p"])
