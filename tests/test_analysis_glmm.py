"""The trial-level GLMM against independent fits: statsmodels GEE on planted effects
(direction and significance), and an ordinary logistic regression when there is no
participant variability (the mixed model must then reduce to it)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm

from cfteach.analysis import SyntheticConfig, apply_exclusions, compute_results, generate
from cfteach.analysis.aggregate import build_frames
from cfteach.analysis.glmm import design, trial_glmm


def _tests(**kw) -> pd.DataFrame:
    kept, _ = apply_exclusions(generate(SyntheticConfig(**kw)))
    return build_frames(kept).tests


def _gee(t: pd.DataFrame) -> pd.DataFrame:
    x, _ = design(t)
    fit = sm.GEE(
        t["optimal"].astype(float),
        sm.add_constant(x),
        groups=t["participant_id"],
        family=sm.families.Binomial(),
        cov_struct=sm.cov_struct.Exchangeable(),
    ).fit()
    return pd.DataFrame({"b": fit.params, "p": fit.pvalues})


@pytest.fixture(scope="module")
def planted() -> tuple[dict, pd.DataFrame]:
    t = _tests(n_participants=216, seed=4, interaction=0.6, feature_effect=0.6)
    return trial_glmm(t), _gee(t)


def test_planted_effects_agree_with_gee(planted) -> None:
    g, gee = planted
    terms = {r["term"]: r for r in g["terms"]}
    planted_terms = {
        "feature_scaffolding": 1,
        "difficulty[low]": 1,
        "difficulty[high]": -1,
        "counterfactual:difficulty[low]": -1,
        "counterfactual:difficulty[high]": 1,
    }
    for term, sign in planted_terms.items():
        r = terms[term]
        assert np.sign(np.log(r["odds_ratio"])) == sign == np.sign(gee.loc[term, "b"]), term
        assert r["p"] < 0.01 and gee.loc[term, "p"] < 0.01, term
        assert (r["ci_low"] > 1) == (sign > 0) and (r["ci_high"] < 1) == (sign < 0), term
    # terms with nothing planted: not significant in either fit
    for term in ("counterfactual:feature_scaffolding:difficulty[high]", "domain_position"):
        assert terms[term]["p"] > 0.01 and gee.loc[term, "p"] > 0.01, term
    assert g["converged"]
    assert 0.4 < g["random_effect_sd"]["participant"] < 0.8  # planted subject_sd = 0.6


def test_without_participant_variability_it_is_logistic_regression() -> None:
    t = _tests(n_participants=96, seed=6, subject_sd=0.0)
    g = trial_glmm(t)
    x, _ = design(t)
    logit = sm.Logit(t["optimal"].astype(float), sm.add_constant(x)).fit(disp=0)
    assert g["random_effect_sd"]["participant"] < 0.25
    for r in g["terms"]:
        assert np.log(r["odds_ratio"]) == pytest.approx(logit.params[r["term"]], abs=0.03)
        assert r["se"] == pytest.approx(logit.bse[r["term"]], rel=0.1)


def test_in_results_and_skipped_for_pilots() -> None:
    r, _ = compute_results(generate(SyntheticConfig(n_participants=24, seed=2)))
    g = r["glmm"]
    assert g["method"].startswith("logistic mixed model")
    assert {"counterfactual", "counterfactual:feature_scaffolding:difficulty[high]"} <= {
        t["term"] for t in g["terms"]
    }
    for t in g["terms"]:
        assert set(t) >= {"term", "odds_ratio", "ci_low", "ci_high", "p"}
        assert t["ci_low"] <= t["odds_ratio"] <= t["ci_high"]
    r3, _ = compute_results(generate(SyntheticConfig(n_participants=3, seed=2)))
    assert "needs at least 2 participants in each of the four conditions" in r3["glmm"]["skipped"]


def test_constant_domain_position_is_said_not_claimed() -> None:
    from cfteach.analysis.report import build_document

    e = generate(SyntheticConfig(n_participants=24, seed=5))
    tests = e.tests.assign(domain_position=2)
    r, _ = compute_results(type(e)(e.participants, tests, e.likert, e.demo_views))
    g = r["glmm"]
    assert "domain_position" not in {t["term"] for t in g["terms"]}
    assert g["covariates_dropped"] == {"domain_position": "the same (2) for every answer"}
    assert "domain_position" not in g["covariates"]
    text = build_document(r, {}).markdown()
    assert "with domain as covariates" in text
    assert "domain position as covariates" not in text
    assert "Covariate domain_position not included: the same (2) for every answer." in text


def test_nagq0_is_an_explicit_option_and_named() -> None:
    t = _tests(n_participants=48, seed=0)
    g0, g1 = trial_glmm(t, nagq=0), trial_glmm(t)
    assert "nAGQ = 0" in g0["method"] and "nAGQ = 1" in g1["method"]
    assert (g0["nAGQ"], g1["nAGQ"]) == (0, 1)
    # nAGQ = 0 pulls the difficulty estimates towards 0 (the issue's -1.104 vs -1.141)
    b0 = {x["term"]: x["log_odds"] for x in g0["terms"]}
    b1 = {x["term"]: x["log_odds"] for x in g1["terms"]}
    assert abs(b0["difficulty[high]"]) < abs(b1["difficulty[high]"])
    assert g1["deviance"] <= g0["deviance"] + 1e-6  # the Laplace optimum is the lower one
