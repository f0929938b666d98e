"""Ordinal models of the ratings: the cumulative logit against logistic regression (with two
categories they are the same model), and a planted effect on mental effort."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm

from cfteach.analysis import SyntheticConfig, apply_exclusions, compute_results, generate
from cfteach.analysis.aggregate import build_frames
from cfteach.analysis.ordinal import ordinal_fit, ordinal_models


def test_two_categories_equal_logistic_regression() -> None:
    rng = np.random.default_rng(0)
    n = 600
    x = pd.DataFrame({"a": rng.normal(size=n), "b": rng.integers(0, 2, n) - 0.5})
    y = (rng.random(n) < 1 / (1 + np.exp(-(0.3 + 0.8 * x["a"] - 0.5 * x["b"])))).astype(int)
    groups = pd.Series(np.arange(n) // 3)
    got = {t["term"]: t for t in ordinal_fit(pd.Series(y), x, groups)["terms"]}
    logit = sm.Logit(y, sm.add_constant(x)).fit(
        disp=0, cov_type="cluster", cov_kwds={"groups": groups.to_numpy()}
    )
    for name in ("a", "b"):
        assert got[name]["log_odds"] == pytest.approx(logit.params[name], abs=1e-4)
        assert got[name]["se"] == pytest.approx(logit.bse[name], rel=0.02)
        assert got[name]["p"] == pytest.approx(logit.pvalues[name], rel=0.05, abs=1e-6)


def test_planted_mental_effort_and_confidence_effects() -> None:
    kept, _ = apply_exclusions(generate(SyntheticConfig(n_participants=216, seed=3)))
    res = ordinal_models(build_frames(kept))
    effort = {t["term"]: t for t in res["mental_effort"]["terms"]}
    assert effort["counterfactual"]["odds_ratio"] > 1.5 and effort["counterfactual"]["p"] < 1e-3
    assert effort["feature_scaffolding"]["p"] > 0.01  # nothing planted
    conf = {t["term"]: t for t in res["confidence"]["terms"]}
    assert conf["difficulty[high]"]["odds_ratio"] < 1 < conf["difficulty[low]"]["odds_ratio"]
    assert res["confidence"]["n_observations"] == len(kept.tests)


def test_in_results_and_skipped_without_confidence() -> None:
    ex = generate(SyntheticConfig(n_participants=24, seed=1))
    ex.tests["confidence"] = np.nan
    r, _ = compute_results(ex)
    assert "no ratings" in r["ordinal"]["confidence"]["skipped"]
    assert r["ordinal"]["informativeness"]["terms"][0]["term"] == "counterfactual"
