"""Summaries of simulated answers: proportions, CIs, H1 correlations, the plot."""

from __future__ import annotations

import math
import statistics

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from cfteach.simulate.scoring import TOLERANCE, is_optimal, score_answers
from cfteach.simulate.summary import (
    h1_correlations,
    interaction_plot,
    mean_ci,
    ordering,
    proportion_table,
)


def _answers(rng: np.random.Generator, p: dict[str, float], n_learners: int = 20,
             domains: tuple[str, ...] = ("d1",), conditions: tuple[str, ...] = ("proposed",),
             tests_per_level: int = 4) -> pd.DataFrame:
    overlap = {"low": 2.0, "medium": 1.0, "high": 0.2}
    rows = []
    for d in domains:
        for c in conditions:
            for i in range(n_learners):
                for lv in ("low", "medium", "high"):
                    for t in range(tests_per_level):
                        rows.append({"domain": d, "condition": c, "learner_model": "cf",
                                     "seed": 0, "learner": i, "test": f"{lv}{t}",
                                     "source": "selected", "difficulty": lv,
                                     "overlap": overlap[lv] + 0.01 * t,
                                     "correct": bool(rng.random() < p[lv])})
    return pd.DataFrame(rows)


def test_mean_ci_matches_hand_t_interval() -> None:
    v = np.array([0.5, 0.75, 1.0, 0.25, 0.5])
    m, lo, hi = mean_ci(v)
    sd = statistics.stdev(v.tolist())
    half = 2.7764451051977987 * sd / math.sqrt(5)  # t(0.975, df=4)
    assert m == pytest.approx(0.6)
    assert lo == pytest.approx(0.6 - half) and hi == pytest.approx(0.6 + half)
    assert mean_ci(np.array([1.0, 1.0])) == (1.0, 1.0, 1.0)


def test_proportion_table_by_hand_on_a_tiny_design() -> None:
    # Two learners, two domains; learner 0 gets 1/2 low in d1 and 2/2 in d2.
    rows = []
    for d, answers in (("d1", {0: [1, 0], 1: [1, 1]}), ("d2", {0: [1, 1], 1: [0, 0]})):
        for learner, cs in answers.items():
            for t, c in enumerate(cs):
                rows.append({"domain": d, "condition": "baseline", "learner_model": "irl",
                             "seed": 0, "learner": learner, "test": f"t{t}",
                             "source": "selected", "difficulty": "low", "overlap": 1.0,
                             "correct": bool(c)})
    table = proportion_table(pd.DataFrame(rows))
    by = {r["domain"]: r for r in table}
    assert by["d1"]["proportion_optimal"] == pytest.approx(0.75)
    assert by["d2"]["proportion_optimal"] == pytest.approx(0.5)
    # pooled: learner 0 -> (0.5 + 1)/2 = 0.75, learner 1 -> (1 + 0)/2 = 0.5
    assert by["all"]["proportion_optimal"] == pytest.approx(0.625)
    assert by["all"]["n_learners"] == 2 and by["all"]["n_answers"] == 8
    assert by["d1"]["n_answers"] == 4


def test_planted_difficulty_effect_is_found_and_ordered() -> None:
    rng = np.random.default_rng(0)
    df = _answers(rng, {"low": 0.9, "medium": 0.6, "high": 0.2}, n_learners=40)
    table = proportion_table(df)
    order = ordering(table)
    assert order[0]["low_gt_medium_gt_high"] is True
    h1 = h1_correlations(df)[0]
    assert h1["spearman_rho"] > 0.3 and h1["spearman_p"] < 1e-6
    # independent check of the point-biserial r: Pearson's r on 0/1 correctness
    r = np.corrcoef(df["overlap"], df["correct"].astype(float))[0, 1]
    assert h1["pointbiserial_r"] == pytest.approx(r)
    rho = stats.pearsonr(stats.rankdata(df["overlap"]), stats.rankdata(df["correct"]))[0]
    assert h1["spearman_rho"] == pytest.approx(rho)


def test_no_effect_gives_no_reliable_correlation() -> None:
    rng = np.random.default_rng(1)
    df = _answers(rng, {"low": 0.5, "medium": 0.5, "high": 0.5}, n_learners=40)
    h1 = h1_correlations(df)[0]
    assert abs(h1["spearman_rho"]) < 0.15


def test_constant_correctness_reports_undefined_correlation() -> None:
    df = _answers(np.random.default_rng(2), {"low": 1.0, "medium": 1.0, "high": 1.0},
                  n_learners=3)
    h1 = h1_correlations(df)[0]
    assert h1["spearman_rho"] is None and "does not vary" in h1["note"]


def test_plot_has_every_condition(tmp_path) -> None:
    rng = np.random.default_rng(3)
    df = _answers(rng, {"low": 0.9, "medium": 0.6, "high": 0.3}, n_learners=5,
                  domains=("d1", "d2"), conditions=("baseline", "proposed"))
    files = interaction_plot(proportion_table(df), tmp_path / "fig")
    assert [f.suffix for f in files] == [".png", ".svg"]
    svg = files[1].read_text()
    assert "baseline" in svg and "proposed" in svg and "Test difficulty" in svg
    with pytest.raises(ValueError, match="no rows for domain 'd9'"):
        interaction_plot(proportion_table(df), tmp_path / "x", domain="d9")


def test_missing_columns_are_named() -> None:
    with pytest.raises(ValueError, match="lacks columns"):
        proportion_table(pd.DataFrame({"domain": ["a"]}))


def test_scoring_follows_the_study_rule() -> None:
    assert is_optimal(-3.0, -3.0)
    assert is_optimal(-3.0, -3.0 + 1e-12)
    assert not is_optimal(-3.0, -3.0 + 1e-6)
    got = score_answers(np.array([-1.0, -1.0, -1.5, -1.0 - 1e-12]),
                        np.array([True, False, True, True]), -1.0)
    assert got.tolist() == [True, False, False, True]
    assert TOLERANCE == 1e-9
    # the scalar rule (the study's) and the vectorised one (the simulation's) agree
    for a, b in [(-3.0, -3.0 + 1e-12), (-3.0, -3.0 + 1e-6), (0.0, 1e-10), (-200.0, -200.0001)]:
        assert is_optimal(a, b) == bool(score_answers(a, True, b))
