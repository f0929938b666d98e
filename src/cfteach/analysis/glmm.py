"""Trial-level logistic mixed model of the binary `optimal` outcome.

Reviewers now ask for this instead of ANOVAs on proportions of six binary trials: every
answer is one Bernoulli trial, participants and test items get random intercepts, and the
domain and its position in the participant's order are covariates.

    logit P(optimal) = cf * fs * difficulty + domain + domain_position
                       + u_participant + v_item,   u ~ N(0, s_p^2), v ~ N(0, s_i^2)

Fitted by maximum likelihood on the Laplace approximation exactly as lme4's
`glmer(..., nAGQ = 1)` (see `cfteach.analysis.laplace`; the tests compare it with glmer
through Rscript). SDs may be estimated at 0 ("singular fit", reported). Why not a library:
statsmodels' `BinomialBayesMixedGLM` (variational Bayes) gave between-subjects SEs about
30% too small; bambi/PyMC pull in a C toolchain and take minutes per fit.

Separation (a cell where everybody was right, common in pilots: the paper's low tests were
answered optimally by most people) makes some log odds infinite. It is detected per term
before fitting (`cfteach.analysis.separation`); the model is then fitted with independent
normal priors on the fixed effects (SD 10 for the intercept, 2.5 for the rest, as
`blme::bglmer(fixef.prior = normal)`), i.e. a posterior mode, and results.json and the
report say so. A response without any variation is not modelled (skipped with the reason).

Coding makes each odds ratio readable: counterfactual and feature scaffolding are centred
(-1/2, +1/2), so their coefficient is the log odds ratio *with vs without*, averaged over
the other factors; difficulty is sum-coded (`difficulty[low]`, `difficulty[high]`: the level
vs the mean of the three), interactions are products of those codes. CIs and p are Wald
(estimate +- 1.96 SE; p = 2 Phi(-|z|)).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats as sps

from cfteach.analysis.io import DIFFICULTIES

METHOD = (
    "logistic mixed model, random intercepts for participant and test item "
    "(maximum likelihood, Laplace approximation with nAGQ = 1 as lme4::glmer: variance "
    "parameters optimised on the Laplace deviance, fixed effects profiled)"
)
METHOD_NAGQ0 = (
    "logistic mixed model, random intercepts for participant and test item "
    "(lme4's nAGQ = 0 approximation: fixed and random effects jointly by penalised IRLS, "
    "variance parameters on the Laplace deviance at that mode)"
)
PRIOR_SD = {"intercept": 10.0, "other": 2.5}
METHOD_PRIOR = (
    " with independent normal priors on the fixed effects (SD 10 for the intercept, 2.5 for "
    "the others, as blme::bglmer with fixef.prior = normal): a posterior mode, because of "
    "separation"
)
MIN_PER_CONDITION = 2


def design(tests: pd.DataFrame) -> tuple[pd.DataFrame, list[str]]:
    """The fixed-effect columns (named as in results.json) and the covariate names."""
    d, covariates, _ = design_with_notes(tests)
    return d, covariates


def design_with_notes(tests: pd.DataFrame) -> tuple[pd.DataFrame, list[str], dict[str, str]]:
    """`design`, plus each covariate that could not be used and why (the report says so
    rather than claiming to adjust for it)."""
    dropped: dict[str, str] = {}
    d = pd.DataFrame(index=tests.index)
    cf = tests["counterfactual"].astype(float) - 0.5
    fs = tests["feature_scaffolding"].astype(float) - 0.5
    diff = tests["difficulty"].astype(str)
    last = DIFFICULTIES[1]  # medium is the level coded -1 in both difficulty columns
    codes = {
        f"difficulty[{lvl}]": (diff == lvl).astype(float) - (diff == last).astype(float)
        for lvl in (DIFFICULTIES[0], DIFFICULTIES[2])
    }
    d["counterfactual"] = cf
    d["feature_scaffolding"] = fs
    for name, c in codes.items():
        d[name] = c
    d["counterfactual:feature_scaffolding"] = cf * fs
    for name, c in codes.items():
        d[f"counterfactual:{name}"] = cf * c
    for name, c in codes.items():
        d[f"feature_scaffolding:{name}"] = fs * c
    for name, c in codes.items():
        d[f"counterfactual:feature_scaffolding:{name}"] = cf * fs * c
    covariates = []
    domains = sorted(tests["domain"].astype(str).unique())
    if len(domains) < 2:
        dropped["domain"] = f"every answer is from one domain ({domains[0]!r})"
    for dom in domains[:-1]:  # sum coding against the last domain
        name = f"domain[{dom}]"
        d[name] = (tests["domain"] == dom).astype(float) - (tests["domain"] == domains[-1])
        covariates.append(name)
    raw = tests["domain_position"] if "domain_position" in tests else None
    pos = pd.to_numeric(raw, errors="coerce") if raw is not None else None
    if pos is None or pos.isna().all():
        dropped["domain_position"] = "not in the export"
    elif pos.isna().any():
        dropped["domain_position"] = f"missing for {int(pos.isna().sum())} answer(s)"
    elif pos.nunique() < 2:
        dropped["domain_position"] = f"the same ({int(pos.iloc[0])}) for every answer"
    else:
        d["domain_position"] = pos.astype(float) - pos.mean()
        covariates.append("domain_position")
    return d, covariates, dropped


def _skip_reason(tests: pd.DataFrame) -> str | None:
    cond = tests.groupby(["counterfactual", "feature_scaffolding"])["participant_id"].nunique()
    short = [
        f"counterfactual={a}, feature_scaffolding={b}: {int(cond.get((a, b), 0))}"
        for a in (0, 1)
        for b in (0, 1)
        if cond.get((a, b), 0) < MIN_PER_CONDITION
    ]
    if short:
        return (
            f"needs at least {MIN_PER_CONDITION} participants in each of the four conditions "
            f"(have {'; '.join(short)})"
        )
    y = tests["optimal"].astype(float)
    if y.nunique() < 2:
        what = "optimal" if y.iloc[0] > 0.5 else "not optimal"
        return f"all {len(y)} answers are {what}: there is no variation to model"
    missing = [d for d in DIFFICULTIES if not (tests["difficulty"].astype(str) == d).any()]
    if missing:
        return f"no answers at difficulty {', '.join(missing)}"
    return None


def trial_glmm(
    tests: pd.DataFrame,
    *,
    nagq: int = 1,
    se: str = "hessian",
    start: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Fit the trial-level GLMM on the long test frame (one row per answer).

    `nagq` 1 (default) is glmer's Laplace fit; 0 is lme4's faster nAGQ = 0 scheme, kept as
    an explicit option (its estimates are pulled towards 0). `se`: see `laplace.fit`.
    `start`: a previous result of this function to start from (simulations); the optimum
    does not depend on it.
    """
    from threadpoolctl import threadpool_limits

    from cfteach.analysis import laplace
    from cfteach.analysis.separation import separation

    method = METHOD if nagq else METHOD_NAGQ0
    why = _skip_reason(tests)
    if why:
        return {"method": method, "skipped": why}
    x, covariates, dropped = design_with_notes(tests)
    names = ["Intercept", *x.columns]
    exog = np.column_stack([np.ones(len(x)), x.to_numpy(float)])
    if np.linalg.matrix_rank(exog) < exog.shape[1]:
        return {
            "method": method,
            "skipped": "the fixed effects are not estimable from these data (the design "
            "matrix is rank deficient: some condition x difficulty cell is empty)",
        }
    y = tests["optimal"].astype(float).to_numpy()
    sep = separation(y, exog, names)
    prior = None
    notes = []
    if sep["separated"]:
        prior = np.r_[PRIOR_SD["intercept"], np.full(exog.shape[1] - 1, PRIOR_SD["other"])]
        method += METHOD_PRIOR
        notes.append(
            f"{sep['kind'].capitalize()} separation: the maximum-likelihood log odds of "
            + ", ".join(f"{t} ({v})" for t, v in sep["terms"].items())
            + " are infinite (some cell is all right or all wrong), so the estimates are "
            "posterior modes under normal priors (SD 2.5 on the log-odds scale, 10 for the "
            "intercept) and shrink those terms; read their ORs as bounded, not as measured."
        )
    pid = pd.Categorical(tests["participant_id"])
    item = pd.Categorical(tests["test_id"])
    data = laplace.Data(
        y,
        exog,
        [pid.codes, item.codes],
        prior_precision=None if prior is None else 1.0 / prior**2,
    )
    with threadpool_limits(1):  # small solves: BLAS threads only contend
        fit = laplace.fit(data, nagq=nagq, se=se, **_warm(start, len(names)))
    sd = {"participant": float(fit["theta"][0]), "item": float(fit["theta"][1])}
    singular = [k for k, s in zip(sd, fit["singular"], strict=True) if s]
    if singular:
        notes.append(
            "Singular fit: the random-intercept SD of "
            + " and ".join(singular)
            + " is estimated at 0 (a boundary estimate, as lme4 reports it; the model is "
            "then the one without that random effect)."
        )
    for name, reason in dropped.items():
        notes.append(f"Covariate {name} not included: {reason}.")
    return {
        "method": method,
        "nAGQ": nagq,
        "coding": "counterfactual, feature_scaffolding centred (-1/2, +1/2): OR = with vs "
        "without; difficulty sum-coded (level vs mean of the three, medium = -1); "
        "interactions are products; domain sum-coded, domain_position centred",
        "terms": _terms(fit, names, covariates),
        "intercept_log_odds": float(fit["beta"][0]),
        "random_effect_sd": sd,
        "singular": singular,
        "separation": sep if sep["separated"] else None,
        "fixed_effect_prior": None
        if prior is None
        else {"distribution": "normal", "mean": 0.0, **{f"sd_{k}": v for k, v in PRIOR_SD.items()}},
        "covariates": covariates,
        "covariates_dropped": dropped,
        "notes": notes,
        "deviance": fit["deviance"],
        "converged": fit["converged"],
        "n_observations": int(len(y)),
        "n_participants": int(len(pid.categories)),
        "n_items": int(len(item.categories)),
    }


def _warm(start: dict[str, Any] | None, p: int) -> dict[str, Any]:
    if not start or "terms" not in start or len(start["terms"]) + 1 != p:
        return {}
    sd = start["random_effect_sd"]
    return {
        "theta_start": np.array([max(sd["participant"], 0.05), max(sd["item"], 0.05)]),
        "beta_start": np.r_[start["intercept_log_odds"], [t["log_odds"] for t in start["terms"]]],
    }


def _terms(fit: dict[str, Any], names: list[str], covariates: list[str]) -> list[dict[str, Any]]:
    terms = []
    for i in range(1, len(names)):
        m, s = float(fit["beta"][i]), float(fit["se"][i])
        zval = m / s if s > 0 else math.inf
        terms.append(
            {
                "term": names[i],
                "log_odds": m,
                "se": s,
                "odds_ratio": math.exp(m),
                "ci_low": math.exp(m - 1.959964 * s),
                "ci_high": math.exp(m + 1.959964 * s),
                "p": float(2 * sps.norm.sf(abs(zval))),
                "covariate": names[i] in covariates,
            }
        )
    return terms
