"""Cumulative-logit (proportional odds) models for the 1-5 ratings, beside the paper's
Mann-Whitney / Kruskal-Wallis tests.

A rank test on per-participant medians throws away the ordering information of each answer
and cannot test cf x fs; here every rating is one observation of statsmodels'
`OrderedModel` (logit link), with cluster-robust standard errors by participant because
each person answers once per domain (Likert) or per test (confidence). The sandwich has
statsmodels' default small-sample correction (CR1): G/(G - 1) x (N - 1)/(N - K) for G
participants, N ratings and K parameters (thresholds included), about 1.05 at G = 24; the
tests recompute it from R's `clm` fit. Codes as in the
GLMM: counterfactual and feature scaffolding centred (-1/2, +1/2), so an odds ratio above 1
means *with* the scaffolding people answer in higher categories; confidence also has
difficulty (sum-coded) as a covariate.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import pandas as pd
from scipy import stats as sps

from cfteach.analysis.aggregate import Frames
from cfteach.analysis.io import DIFFICULTIES, LIKERT_ITEMS

METHOD = (
    "cumulative-logit ordinal regression (statsmodels OrderedModel), "
    "cluster-robust SE by participant with the CR1 small-sample correction "
    "G/(G-1) x (N-1)/(N-K)"
)


def _between(df: pd.DataFrame) -> pd.DataFrame:
    x = pd.DataFrame(index=df.index)
    x["counterfactual"] = df["counterfactual"].astype(float) - 0.5
    x["feature_scaffolding"] = df["feature_scaffolding"].astype(float) - 0.5
    x["counterfactual:feature_scaffolding"] = x["counterfactual"] * x["feature_scaffolding"]
    return x


def ordinal_fit(y: pd.Series, x: pd.DataFrame, groups: pd.Series) -> dict[str, Any]:
    """Fit one proportional-odds model; odds ratios with Wald 95% CIs for each column of x."""
    from statsmodels.miscmodels.ordinal_model import OrderedModel

    y = y.astype(int)
    model = OrderedModel(y.to_numpy(), x, distr="logit")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = model.fit(
            method="bfgs",
            disp=False,
            maxiter=500,
            cov_type="cluster",
            cov_kwds={"groups": pd.factorize(groups)[0]},
        )
    terms = []
    for name in x.columns:
        b, se = float(fit.params[name]), float(fit.bse[name])
        terms.append(
            {
                "term": name,
                "log_odds": b,
                "se": se,
                "odds_ratio": math.exp(b),
                "ci_low": math.exp(b - 1.959964 * se),
                "ci_high": math.exp(b + 1.959964 * se),
                "p": float(2 * sps.norm.sf(abs(b / se))) if se > 0 else None,
            }
        )
    return {
        "method": METHOD,
        "terms": terms,
        "converged": bool(fit.mle_retvals.get("converged", True)),
        "n_observations": int(len(y)),
        "n_participants": int(groups.nunique()),
    }


def _skip_reason(df: pd.DataFrame, col: str) -> str | None:
    if df.empty:
        return "no ratings"
    conds = df.groupby(["counterfactual", "feature_scaffolding"])["participant_id"].nunique()
    if len(conds) < 4 or conds.min() < 2:
        return "needs at least 2 participants in each of the four conditions"
    if df[col].nunique() < 2:
        return "all ratings are the same"
    return None


def ordinal_models(frames: Frames) -> dict[str, Any]:
    """Likert items (one rating per domain) and confidence (one per test)."""
    design = frames.subjects[["participant_id", "counterfactual", "feature_scaffolding"]]
    out: dict[str, Any] = {}
    lk = frames.likert_long.drop(columns=["condition"], errors="ignore").merge(
        design, on="participant_id"
    )
    for item in LIKERT_ITEMS:
        d = lk[lk["item"] == item].reset_index(drop=True)
        why = _skip_reason(d, "value")
        out[item] = (
            {"method": METHOD, "skipped": why}
            if why
            else ordinal_fit(d["value"], _between(d), d["participant_id"])
        )
    t = frames.tests.dropna(subset=["confidence"]).reset_index(drop=True)
    why = _skip_reason(t, "confidence")
    if why:
        out["confidence"] = {"method": METHOD, "skipped": why}
    else:
        x = _between(t)
        diff = t["difficulty"].astype(str)
        for lvl in (DIFFICULTIES[0], DIFFICULTIES[2]):
            x[f"difficulty[{lvl}]"] = (diff == lvl).astype(float) - (diff == DIFFICULTIES[1])
        out["confidence"] = ordinal_fit(t["confidence"], x, t["participant_id"])
    return out
