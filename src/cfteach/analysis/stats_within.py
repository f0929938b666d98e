"""H1's statistics: difficulty as the within-subjects factor (repeated-measures ANOVA, its
post hocs, within-subject CIs), the domains' ICC and the confidence correlations."""

from __future__ import annotations

import math
from typing import Any

import pandas as pd
import pingouin as pg
from scipy import stats as sps

from cfteach.analysis.aggregate import Frames
from cfteach.analysis.effects import hedges_ci
from cfteach.analysis.io import DIFFICULTIES
from cfteach.analysis.stats_base import (
    _ci,
    _get,
    _num,
    complete_cells,
    mean_ci,
    no_variance,
    skipped,
)

_ICC_CK = ("ICC(C,k)", "ICC3k")


def icc_domains(frames: Frames) -> dict[str, Any]:
    """ICC(C,k) = ICC3k: two-way mixed, consistency, mean of k raters (domains)."""
    dm = frames.domain_means
    wide = dm.pivot_table(index="participant_id", columns="domain", values="optimal").dropna()
    if len(wide) < 2 or wide.shape[1] < 2:
        return skipped(
            "ICC(C,k)",
            f"needs at least 2 participants with every domain and 2 domains (have "
            f"{len(wide)} participant(s), {wide.shape[1]} domain(s))",
        )
    dm = dm[dm["participant_id"].isin(wide.index)]
    res = pg.intraclass_corr(
        data=dm, targets="participant_id", raters="domain", ratings="optimal", nan_policy="omit"
    )
    row = res[res["Type"].isin(_ICC_CK)]
    if row.empty:
        raise RuntimeError(f"pingouin ICC result lacks {_ICC_CK}: {list(res['Type'])}")
    r = row.iloc[0]
    complete = dm.pivot_table(index="participant_id", columns="domain", values="optimal").dropna()
    return {
        "type": "ICC(C,k) (ICC3k): two-way mixed, consistency, mean of k raters",
        "icc": _num(r["ICC"]),
        "F": _num(r["F"]),
        "df1": _num(r["df1"]),
        "df2": _num(r["df2"]),
        "p": _num(r["pval"]),
        "ci95": _ci(_get(r, "CI95")),
        "n_targets": int(len(complete)),
        "k": int(complete.shape[1]),
        "per_domain_mean": {d: _num(v) for d, v in complete.mean().items()},
    }


def within_subject_ci(cells: pd.DataFrame, dv: str = "optimal", level: float = 0.95) -> dict:
    """Cousineau-Morey within-subject CIs per difficulty: each participant's values are
    centred on their own mean (plus the grand mean), the t-interval of those normalised
    values is widened by sqrt(J / (J - 1)) (Morey 2008). Between-person differences, which
    a within factor's tests remove, no longer inflate the bars."""
    wide = cells.pivot_table(index="participant_id", columns="difficulty", values=dv, observed=True)
    wide = wide.reindex(columns=list(DIFFICULTIES)).dropna()
    n, j = wide.shape
    out: dict[str, dict[str, float | None]] = {}
    if n == 0:
        return {d: {"mean": None, "half": None, "n": 0} for d in DIFFICULTIES}
    norm = wide.sub(wide.mean(axis=1), axis=0) + float(wide.to_numpy().mean())
    t = float(sps.t.ppf(0.5 + level / 2, n - 1)) if n > 1 else float("nan")
    for d in DIFFICULTIES:
        sd = float(norm[d].std(ddof=1)) if n > 1 else float("nan")
        half = t * sd / math.sqrt(n) * math.sqrt(j / (j - 1)) if n > 1 else None
        out[d] = {"mean": float(wide[d].mean()), "half": _num(half), "n": int(n)}
    return out


def difficulty_means(cells: pd.DataFrame, dv: str = "optimal") -> dict[str, Any]:
    """Mean with 95% CI of `dv` per difficulty (over participants)."""
    return {d: mean_ci(cells.loc[cells["difficulty"] == d, dv]) for d in DIFFICULTIES}


def rm_anova_difficulty(frames: Frames) -> dict[str, Any]:
    """H1: one-way repeated-measures ANOVA of proportion optimal on difficulty.

    Mauchly's test and the Greenhouse-Geisser correction come with it; the F test reported
    in the paper's style uses the uncorrected df (as the paper did), the GG p is alongside.
    """
    cells = complete_cells(frames.cells)
    n = int(cells["participant_id"].nunique())
    test = "one-way repeated-measures ANOVA (pingouin.rm_anova)"
    if n < len(DIFFICULTIES):  # pingouin always runs Mauchly's test: it needs n - 1 >= k - 1
        return skipped(
            test, f"needs at least 3 participants with all three difficulties (have {n})"
        )
    if why := no_variance(cells):
        return {**skipped(test, why), "means": difficulty_means(cells)}
    res = pg.rm_anova(
        data=cells,
        dv="optimal",
        within="difficulty",
        subject="participant_id",
        correction=True,
        effsize="ng2",
    )
    r = res.iloc[0]
    used = frames.tests["participant_id"].isin(set(cells["participant_id"]))
    return {
        "test": test,
        "F": _num(r["F"]),
        "df1": _num(r["ddof1"]),
        "df2": _num(r["ddof2"]),
        "p": _num(_get(r, "p_unc")),
        "p_gg": _num(_get(r, "p_GG_corr")),
        "eps_gg": _num(r.get("eps")),
        "mauchly_W": _num(_get(r, "W_spher")),
        "mauchly_p": _num(_get(r, "p_spher")),
        "sphericity": None if r.get("sphericity") is None else bool(r.get("sphericity")),
        "ng2": _num(r.get("ng2")),
        "n_participants": n,
        "n_observations": int(used.sum()),
        "means": difficulty_means(cells),
    }


def posthoc_difficulty(
    frames: Frames, padjust: str = "holm", authors_tukey: bool = True
) -> dict[str, Any]:
    """H1 post hocs: paired t-tests (correct for a within factor) and the authors' Tukey.

    The authors ran a between-groups Tukey HSD on the 3N participant x difficulty means,
    which ignores that the three means come from the same person; it is kept, labelled, so
    the paper's numbers can be compared.
    """
    cells = complete_cells(frames.cells).copy()
    n = int(cells["participant_id"].nunique())
    if n < 2:
        few = f"needs at least 2 participants with all three difficulties (have {n})"
        return {"paired": skipped("paired t-tests", few)}
    if why := no_variance(cells):
        return {"paired": skipped("paired t-tests", why)}
    cells["difficulty"] = cells["difficulty"].astype(str)
    paired = pg.pairwise_tests(
        data=cells,
        dv="optimal",
        within="difficulty",
        subject="participant_id",
        padjust=padjust,
        effsize="hedges",
    )
    means = cells.groupby("difficulty")["optimal"].mean()
    rows = []
    for _, r in paired.iterrows():
        rows.append(
            {
                "A": r["A"],
                "B": r["B"],
                "mean_A": _num(means[r["A"]]),
                "mean_B": _num(means[r["B"]]),
                "T": _num(r["T"]),
                "dof": _num(r["dof"]),
                "p_unc": _num(_get(r, "p_unc")),
                "p_corr": _num(_get(r, "p_corr", _get(r, "p_unc"))),
                "hedges": _num(r["hedges"]),
                "hedges_ci95": hedges_ci(_num(r["hedges"]), n, n, paired=True),
            }
        )
    out: dict[str, Any] = {
        "paired": {
            "test": "paired t-tests (pingouin.pairwise_tests, within-subjects)",
            "padjust": padjust,
            "n_participants": int(cells["participant_id"].nunique()),
            "rows": rows,
        }
    }
    if not authors_tukey:
        return out
    tukey = pg.pairwise_tukey(data=cells, dv="optimal", between="difficulty")
    trows = [
        {
            "A": r["A"],
            "B": r["B"],
            "mean_A": _num(_get(r, "mean_A")),
            "mean_B": _num(_get(r, "mean_B")),
            "T": _num(r["T"]),
            "p_tukey": _num(_get(r, "p_tukey")),
            "hedges": _num(r["hedges"]),
        }
        for _, r in tukey.iterrows()
    ]
    out["authors_tukey"] = {
        "test": "authors' variant: between-groups Tukey HSD on participant x difficulty "
        "means (ignores pairing)",
        "n_observations": int(len(cells)),
        "rows": trows,
    }
    return out


def spearman_confidence(frames: Frames) -> dict[str, Any]:
    """H1: Spearman correlation of (median) confidence with difficulty (0/1/2), n = 3N."""
    c = frames.cells.dropna(subset=["confidence"])
    test = "Spearman rank correlation (pingouin.corr)"
    if c.empty:
        return skipped(test, "no confidence ratings in the export (the column is optional)")
    n = int(c["participant_id"].nunique())
    if n < 3 or c["confidence"].nunique() < 2 or c["difficulty_code"].nunique() < 2:
        return skipped(
            test,
            f"needs at least 3 participants and varying confidence (have {n} participant(s), "
            f"{c['confidence'].nunique()} distinct value(s))",
        )
    res = pg.corr(c["difficulty_code"], c["confidence"], method="spearman")
    r = res.iloc[0]
    return {
        "test": test,
        "r": _num(r["r"]),
        "p": _num(_get(r, "p_val")),
        "ci95": _ci(_get(r, "CI95")),
        "n": int(r["n"]),
        "confidence_median_by_difficulty": {
            d: _num(c.loc[c["difficulty"] == d, "confidence"].median()) for d in DIFFICULTIES
        },
    }


def rm_corr_confidence(frames: Frames) -> dict[str, Any]:
    """H1 at the right level: the repeated-measures correlation of confidence with
    difficulty (Bakdash & Marusich, 2017; checked against pingouin.rm_corr). It uses each
    participant's three cells as repeated measures of one person, where the paper's
    Spearman treated the 3N cells as independent observations."""
    test = "repeated-measures correlation (Bakdash & Marusich)"
    c = frames.cells.dropna(subset=["confidence"])
    if c.empty:
        return skipped(test, "no confidence ratings in the export (the column is optional)")
    per = c.groupby("participant_id", observed=True)["difficulty_code"].nunique()
    c = c[c["participant_id"].isin(per.index[per >= 2])]
    n = int(c["participant_id"].nunique())
    if n < 3 or len(c) - n - 1 < 2:
        return skipped(
            test, f"needs at least 3 participants with two or more difficulties (have {n})"
        )
    # Bakdash & Marusich's r_rm is the correlation of the within-person deviations (the
    # ANCOVA pingouin.rm_corr fits gives the same number, but its participant dummies make it
    # cubic in N: minutes for 3000 people); CI as pingouin computes it (Fisher z, n = dof + 2)
    x = c["difficulty_code"].astype(float)
    y = c["confidence"].astype(float)
    xc = (x - x.groupby(c["participant_id"], observed=True).transform("mean")).to_numpy()
    yc = (y - y.groupby(c["participant_id"], observed=True).transform("mean")).to_numpy()
    dof = int(len(c) - n - 1)
    denom = math.sqrt(float(xc @ xc) * float(yc @ yc))
    if denom == 0:
        return skipped(test, "confidence or difficulty does not vary within participants")
    r = float(xc @ yc) / denom
    t = r * math.sqrt(dof / (1 - r * r)) if abs(r) < 1 else math.inf
    ci = pg.compute_esci(stat=r, nx=dof + 2, eftype="pearson", decimals=6)
    return {
        "test": test,
        "r": r,
        "dof": float(dof),
        "p": float(2 * sps.t.sf(abs(t), dof)),
        "ci95": _ci(ci),
        "n_participants": n,
        "n_observations": int(len(c)),
    }
