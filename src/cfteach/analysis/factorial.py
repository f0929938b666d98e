"""The full 2 x 2 x 3 split-plot ANOVA: counterfactual x feature scaffolding (between) x
difficulty (within), type III sums of squares with sum-to-zero coding.

The paper ran three separate two-way models, which can neither test cf x fs nor the
three-way term, and which attribute a three-way effect to each factor alone. Here one model
has all seven terms. It is computed the way SPSS's GLM repeated measures computes its
univariate tests: the between terms from the participants' means over difficulty, the
within terms from the orthonormal difficulty contrasts of each participant, each regressed
on the between design (statsmodels OLS, `anova_lm(typ=3)`), summing the contrasts' sums of
squares. Greenhouse-Geisser's epsilon and Mauchly's test use the pooled within-cell
covariance of those contrasts (the error SSCP matrix); `p_gg` is the corrected p, and the
report uses it (with the corrected df) when Mauchly's test rejects sphericity.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats as sps

from cfteach.analysis.effects import eta2_partial_ci
from cfteach.analysis.io import DIFFICULTIES

BETWEEN = ("counterfactual", "feature_scaffolding")
WITHIN = "difficulty"
ALPHA_SPHERICITY = 0.05
_FORMULA_TERMS = {
    "Intercept": (),
    "C(counterfactual, Sum)": ("counterfactual",),
    "C(feature_scaffolding, Sum)": ("feature_scaffolding",),
    "C(counterfactual, Sum):C(feature_scaffolding, Sum)": ("counterfactual", "feature_scaffolding"),
}


def _helmert(k: int) -> np.ndarray:
    """k x (k-1) orthonormal contrasts (columns sum to zero, unit length, orthogonal)."""
    c = np.zeros((k, k - 1))
    for j in range(1, k):
        c[:j, j - 1] = 1.0
        c[j, j - 1] = -float(j)
        c[:, j - 1] /= math.sqrt(j * (j + 1))
    return c


def _type3(y: np.ndarray, design: pd.DataFrame) -> tuple[dict[tuple[str, ...], float], float, int]:
    """Type-III SS of each between term (and the intercept) for one response; residual SS, df."""
    import statsmodels.formula.api as smf
    from statsmodels.stats.anova import anova_lm

    d = design.assign(y=y)
    fit = smf.ols("y ~ C(counterfactual, Sum) * C(feature_scaffolding, Sum)", data=d).fit()
    table = anova_lm(fit, typ=3)
    ss = {_FORMULA_TERMS[name]: float(table.loc[name, "sum_sq"]) for name in _FORMULA_TERMS}
    return ss, float(fit.ssr), int(round(fit.df_resid))


def _term_name(factors: tuple[str, ...]) -> str:
    return ":".join(factors)


def sphericity(error_sscp: np.ndarray, df_error: int) -> dict[str, float | None]:
    """Greenhouse-Geisser epsilon and Mauchly's W (chi-square approximation) from the
    pooled error SSCP matrix of p orthonormal contrasts."""
    p = error_sscp.shape[0]
    s = error_sscp / df_error
    tr = float(np.trace(s))
    eps = tr**2 / (p * float(np.trace(s @ s))) if tr > 0 else None
    if p < 2 or df_error < p or tr <= 0:
        return {"eps_gg": eps, "mauchly_W": None, "mauchly_chi2": None, "mauchly_p": None}
    w = float(np.linalg.det(s) / (tr / p) ** p)
    f = 1 - (2 * p**2 + p + 2) / (6 * p * df_error)
    chi2 = -df_error * f * math.log(w) if w > 0 else math.inf
    dof = p * (p + 1) / 2 - 1
    return {
        "eps_gg": eps,
        "mauchly_W": w,
        "mauchly_chi2": chi2,
        "mauchly_p": float(sps.chi2.sf(chi2, dof)),
    }


def full_anova(cells: pd.DataFrame, dv: str = "optimal") -> dict[str, Any]:
    """All seven terms of the 2 x 2 x 3 split-plot ANOVA on participant x difficulty cells.

    Returns {"terms": [{term, F, df1, df2, p, p_gg, eta2_partial, ...}], "participants": ids,
    "sphericity": {...}} or {"skipped": why} when the design cannot be fitted (an empty
    between cell, or fewer participants than the error df needs).
    """
    wide = cells.pivot_table(
        index=["participant_id", *BETWEEN], columns=WITHIN, values=dv, observed=True
    )
    wide = wide.reindex(columns=list(DIFFICULTIES)).dropna()
    design = wide.index.to_frame(index=False)[list(BETWEEN)].astype(int)
    counts = design.value_counts()
    empty = [
        f"counterfactual={a}, feature_scaffolding={b}"
        for a in (0, 1)
        for b in (0, 1)
        if counts.get((a, b), 0) == 0
    ]
    n = len(design)
    if empty:
        return {
            "skipped": "needs participants in all four conditions (none in "
            + "; ".join(empty)
            + ")"
        }
    if n - 4 < 2:
        return {"skipped": f"needs at least 6 participants with all three difficulties (have {n})"}
    y = wide.to_numpy(float)
    k = y.shape[1]
    # below this an error SS is rounding noise: F is undefined, not 2.6 (all-right pilots)
    tiny = 1e-12 * max(float(np.sum((y - y.mean()) ** 2)), 1e-12 * y.size)
    means = y.mean(axis=1)
    contrasts = y @ _helmert(k)  # n x (k-1)
    # between stratum: SS on the scale of the k cells per participant
    ss_b, ssr_b, df_b = _type3(means * math.sqrt(k), design)
    # within stratum: one regression per contrast, summed
    ss_w: dict[tuple[str, ...], float] = dict.fromkeys(_FORMULA_TERMS.values(), 0.0)
    resid = np.zeros_like(contrasts)
    ssr_w = 0.0
    for j in range(k - 1):
        ss, ssr, _ = _type3(contrasts[:, j], design)
        for key, v in ss.items():
            ss_w[key] += v
        ssr_w += ssr
        resid[:, j] = _residuals(contrasts[:, j], design)
    df_w = (k - 1) * df_b
    sph = sphericity(resid.T @ resid, df_b)
    eps = sph["eps_gg"]
    rejected = sph["mauchly_p"] is not None and sph["mauchly_p"] < ALPHA_SPHERICITY
    terms = []
    for factors, ss_term in ss_b.items():
        if not factors:
            continue
        terms.append(_row(_term_name(factors), ss_term, 1, ssr_b, df_b, None, False, tiny))
    for factors, ss_term in ss_w.items():
        name = _term_name((*factors, WITHIN))
        terms.append(_row(name, ss_term, k - 1, ssr_w, df_w, eps, rejected, tiny))
    order = [
        "counterfactual",
        "feature_scaffolding",
        "difficulty",
        "counterfactual:feature_scaffolding",
        "counterfactual:difficulty",
        "feature_scaffolding:difficulty",
        "counterfactual:feature_scaffolding:difficulty",
    ]
    terms.sort(key=lambda t: order.index(t["term"]))
    note = None
    if np.ptp(y) == 0:
        note = (
            f"every participant x difficulty proportion is {y.flat[0]:.2f}: there is no "
            "variance, so no F can be computed"
        )
    elif any(t["F"] is None for t in terms):
        note = "an error stratum has no variance (every participant alike), so its F is undefined"
    return {
        "note": note,
        "test": "2 x 2 x 3 split-plot ANOVA, type III SS, sum-to-zero coding "
        "(statsmodels OLS per stratum)",
        "terms": terms,
        "participants": [str(p) for p in wide.index.get_level_values("participant_id")],
        "n_by_condition": {f"{a}{b}": int(counts.get((a, b), 0)) for a in (0, 1) for b in (0, 1)},
        "sphericity": {**sph, "rejected": rejected, "alpha": ALPHA_SPHERICITY},
    }


def _residuals(y: np.ndarray, design: pd.DataFrame) -> np.ndarray:
    """Residuals of y on the full 2 x 2 cell means (the within-cell deviations)."""
    cell = design["counterfactual"].to_numpy() * 2 + design["feature_scaffolding"].to_numpy()
    out = y.astype(float).copy()
    for c in np.unique(cell):
        out[cell == c] -= y[cell == c].mean()
    return out


def _row(
    term: str,
    ss: float,
    df1: int,
    ss_err: float,
    df2: int,
    eps: float | None,
    rejected: bool,
    tiny: float = 0.0,
) -> dict[str, Any]:
    if ss_err <= tiny:
        ss, ss_err = (0.0 if ss <= tiny else ss), 0.0
    f = (ss / df1) / (ss_err / df2) if ss_err > 0 else math.nan
    p = float(sps.f.sf(f, df1, df2)) if math.isfinite(f) else None
    row: dict[str, Any] = {
        "term": term,
        "SS": ss,
        "F": f if math.isfinite(f) else None,
        "df1": float(df1),
        "df2": float(df2),
        "p": p,
        "p_gg": None,
        "eta2_partial": ss / (ss + ss_err) if ss + ss_err > 0 else None,
        "eta2_partial_ci95": eta2_partial_ci(f if math.isfinite(f) else None, df1, df2),
    }
    if eps is not None and WITHIN in term:
        row["eps_gg"] = eps
        row["df1_gg"] = df1 * eps
        row["df2_gg"] = df2 * eps
        row["p_gg"] = float(sps.f.sf(f, df1 * eps, df2 * eps)) if p is not None else None
        row["sphericity_rejected"] = rejected
    return row
