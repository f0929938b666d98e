"""The paper's statistics, each a thin wrapper over one pingouin (or scipy) call.

Every function returns a plain, JSON-ready dict with the test statistic, degrees of freedom,
p value, effect size and the numbers of participants/observations. pingouin renamed its
columns in 0.6 (`p-unc` -> `p_unc`, ...) and its ICC labels in 0.7 (`ICC3k` -> `ICC(C,k)`);
`_get` accepts either spelling so the pipeline runs on both.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pandas as pd
import pingouin as pg
from scipy import stats as sps

from cfteach.analysis.aggregate import Frames
from cfteach.analysis.effects import eta2_partial_ci, hedges_ci
from cfteach.analysis.io import CONDITIONS, DIFFICULTIES, LIKERT_ITEMS

BETWEEN_FACTORS = ("counterfactual", "feature_scaffolding", "condition")
EXPLORATORY_MEASURES = {
    "plays_completed": "plays per demonstration",
    "replays": "replays per demonstration",
    "time_norm": "test time per optimal step (s)",
}

# new name -> old names, for pingouin < 0.6
_ALIASES = {
    "p_unc": ("p-unc",),
    "p_GG_corr": ("p-GG-corr",),
    "W_spher": ("W-spher",),
    "p_spher": ("p-spher",),
    "p_val": ("p-val",),
    "U_val": ("U-val",),
    "p_tukey": ("p-tukey",),
    "p_corr": ("p-corr",),
    "p_adjust": ("p-adjust",),
    "mean_A": ("mean(A)",),
    "mean_B": ("mean(B)",),
    "CI95": ("CI95%",),
}
_ICC_CK = ("ICC(C,k)", "ICC3k")


def _num(x: Any) -> float | None:
    """A float for JSON, with NaN as None."""
    if x is None:
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(v) else v


def _get(row: pd.Series, name: str, default: Any = None) -> Any:
    """Column `name` of a pingouin result row under its new or old spelling."""
    for key in (name, *_ALIASES.get(name, ())):
        if key in row.index:
            return row[key]
    return default


def _ci(x: Any) -> list[float | None]:
    if x is None:
        return [None, None]
    arr = np.asarray(x, dtype=float).ravel()
    return [_num(arr[0]), _num(arr[1])] if arr.size == 2 else [None, None]


def mean_ci(values: pd.Series | np.ndarray, level: float = 0.95) -> dict[str, float | None]:
    """Mean, SD, n and the t-based confidence interval of the mean."""
    v = np.asarray(values, dtype=float)
    v = v[~np.isnan(v)]
    n = int(v.size)
    if n == 0:
        return {"mean": None, "sd": None, "n": 0, "ci95": [None, None]}
    m = float(v.mean())
    if n < 2:
        return {"mean": m, "sd": None, "n": n, "ci95": [None, None]}
    sd = float(v.std(ddof=1))
    half = float(sps.t.ppf(0.5 + level / 2, n - 1)) * sd / math.sqrt(n)
    return {"mean": m, "sd": sd, "n": n, "ci95": [m - half, m + half]}


def skipped(test: str, why: str) -> dict[str, Any]:
    """The entry of a test the data cannot support (a pilot, a missing group, no ratings)."""
    return {"test": test, "skipped": why}


def no_variance(cells: pd.DataFrame, dv: str = "optimal") -> str | None:
    """Why a test of `dv` is undefined when every cell has the same value (else None)."""
    v = cells[dv].dropna()
    if len(v) and float(v.max() - v.min()) == 0.0:
        return (
            f"every participant x difficulty value of {dv} is {float(v.iloc[0]):.2f}: "
            "there is no variance to test"
        )
    return None


def complete_cells(cells: pd.DataFrame) -> pd.DataFrame:
    """The participant x difficulty cells of participants who have all three difficulties.

    Repeated-measures tests drop anyone else; doing it here means the N we report is the
    N the test used.
    """
    n = cells.dropna(subset=["optimal"]).groupby("participant_id", observed=True)["difficulty"]
    full = n.nunique()
    keep = full.index[full == len(DIFFICULTIES)]
    return cells[cells["participant_id"].isin(keep)]


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
        why = f"needs at least 2 participants with all three difficulties (have {n})"
        return {"paired": skipped("paired t-tests", why)}
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
    xc = x - x.groupby(c["participant_id"], observed=True).transform("mean")
    yc = y - y.groupby(c["participant_id"], observed=True).transform("mean")
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


def _levels(factor: str) -> list[Any]:
    return list(CONDITIONS) if factor == "condition" else [0, 1]


def usable_levels(df: pd.DataFrame, factor: str, min_n: int = 2) -> list[Any]:
    """Levels of `factor` (in design order) with at least `min_n` participants in `df`."""
    counts = df.groupby(df[factor].astype(str), observed=True)["participant_id"].nunique()
    return [lvl for lvl in _levels(factor) if counts.get(str(lvl), 0) >= min_n]


def _skip(df: pd.DataFrame, factor: str, levels: list[Any]) -> dict[str, Any] | None:
    """A 'skipped' result when fewer than two levels have two or more participants."""
    if len(levels) >= 2:
        return None
    counts = df.groupby(df[factor].astype(str), observed=True)["participant_id"].nunique()
    have = ", ".join(f"{k}: {v}" for k, v in counts.items()) or "none"
    return {
        "factor": factor,
        "skipped": f"needs two groups of at least 2 participants (have {have})",
    }


def group_difficulty_means(cells: pd.DataFrame, factor: str, dv: str = "optimal") -> list[dict]:
    """Mean and 95% CI of `dv` for every level of `factor` at every difficulty."""
    out = []
    for lvl in usable_levels(cells, factor, min_n=1):
        for d in DIFFICULTIES:
            sel = cells[(cells[factor] == lvl) & (cells["difficulty"] == d)][dv]
            out.append({"level": str(lvl), "difficulty": d, **mean_ci(sel)})
    return out


def _tukey_rows(df: pd.DataFrame, dv: str, between: str) -> list[dict[str, Any]]:
    tk = pg.pairwise_tukey(data=df, dv=dv, between=between)
    return [
        {
            "A": str(r["A"]),
            "B": str(r["B"]),
            "mean_A": _num(_get(r, "mean_A")),
            "mean_B": _num(_get(r, "mean_B")),
            "diff": _num(r["diff"]),
            "T": _num(r["T"]),
            "p_tukey": _num(_get(r, "p_tukey")),
            "hedges": _num(r["hedges"]),
        }
        for _, r in tk.iterrows()
    ]


def mixed_anova(frames: Frames, factor: str) -> dict[str, Any]:
    """H2-H4: two-way mixed ANOVA difficulty (within) x `factor` (between).

    Simple effects: at each difficulty, Tukey HSD between the levels of `factor` on that
    difficulty's participant means (with two levels this is Student's t-test). These p are
    corrected within a difficulty (Tukey); `p_holm_across` adds Holm's correction across the
    three difficulties for each pair (the family the simple-effects claim is about).
    """
    if factor not in BETWEEN_FACTORS:
        raise ValueError(f"factor must be one of {BETWEEN_FACTORS}, got {factor!r}")
    cells = complete_cells(frames.cells).copy()
    if factor == "condition":
        cells["condition"] = cells["condition"].astype(str)
    levels = usable_levels(cells, factor)
    skipped = _skip(cells, factor, levels)
    if skipped:
        return skipped
    if why := no_variance(cells):
        return {"factor": factor, "skipped": why}
    cells = cells[cells[factor].astype(str).isin([str(lv) for lv in levels])]
    res = pg.mixed_anova(
        data=cells,
        dv="optimal",
        within="difficulty",
        between=factor,
        subject="participant_id",
        correction=True,
    )
    effects = {}
    for _, r in res.iterrows():
        key = {factor: "between", "difficulty": "within", "Interaction": "interaction"}[r["Source"]]
        effects[key] = {
            "source": str(r["Source"]),
            "SS": _num(r["SS"]),
            "df1": _num(r["DF1"]),
            "df2": _num(r["DF2"]),
            "MS": _num(r["MS"]),
            "F": _num(r["F"]),
            "p": _num(_get(r, "p_unc")),
            "p_gg": _num(_get(r, "p_GG_corr")),
            "eps_gg": _num(r.get("eps")),
            "mauchly_p": _num(_get(r, "p_spher")),
            "np2": _num(r.get("np2")),
        }
        e = effects[key]
        e["np2_ci95"] = eta2_partial_ci(e["F"], e["df1"], e["df2"])
    simple = []
    for d in DIFFICULTIES:
        sub = cells[cells["difficulty"] == d]
        for row in _tukey_rows(sub, "optimal", factor):
            simple.append({"difficulty": d, **row})
    # the same comparison at the three difficulties is one family: Holm over the 3
    by_pair: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for s in simple:
        by_pair.setdefault((s["A"], s["B"]), []).append(s)
    for rows in by_pair.values():
        ps = [s["p_tukey"] if s["p_tukey"] is not None else np.nan for s in rows]
        _, adj = pg.multicomp(ps, method="holm")
        for s, a in zip(rows, adj, strict=True):
            s["p_holm_across"] = _num(a)
    subj = cells.groupby(["participant_id", factor], observed=True)["optimal"].mean()
    subj = subj.reset_index()
    n_by = subj.groupby(factor, observed=True).size()
    out: dict[str, Any] = {
        "test": "two-way mixed ANOVA (pingouin.mixed_anova)",
        "factor": factor,
        "effects": effects,
        "n_participants": int(len(subj)),
        "n_by_level": {str(k): int(v) for k, v in n_by.items()},
        "means": group_difficulty_means(cells, factor),
        "simple_effects": {
            "test": "Tukey HSD between levels at each difficulty (pingouin.pairwise_tukey)",
            "rows": simple,
        },
    }
    if factor == "condition":
        out["overall_pairwise"] = {
            "test": "Tukey HSD on per-participant mean proportion optimal",
            "rows": _tukey_rows(subj, "optimal", "condition"),
        }
    return out


def _mwu(x: pd.Series, y: pd.Series) -> dict[str, Any]:
    x, y = x.dropna(), y.dropna()
    r = pg.mwu(x, y, alternative="two-sided").iloc[0]
    return {
        "U": _num(_get(r, "U_val")),
        "p": _num(_get(r, "p_val")),
        "rbc": _num(r.get("RBC")),
        "cles": _num(r.get("CLES")),
        "n_x": int(len(x)),
        "n_y": int(len(y)),
        "median_x": _num(x.median()),
        "median_y": _num(y.median()),
    }


def likert_tests(frames: Frames, padjust: str = "holm") -> dict[str, Any]:
    """M2/M3: Mann-Whitney U by each scaffolding factor, Kruskal-Wallis by condition.

    Ratings are per-participant medians over domains. U is reported for the group *without*
    the scaffolding (x), as in the paper. Pairwise condition tests come uncorrected (the
    paper) and `padjust`-corrected.
    """
    s = frames.subjects
    out: dict[str, Any] = {"padjust": padjust}
    for item in LIKERT_ITEMS:
        res: dict[str, Any] = {}
        sub = s.dropna(subset=[item]).copy()
        sub["condition"] = sub["condition"].astype(str)
        for factor in ("counterfactual", "feature_scaffolding"):
            skipped = _skip(sub, factor, usable_levels(sub, factor))
            res[factor] = skipped or {
                "test": "Mann-Whitney U (pingouin.mwu), x = without",
                **_mwu(sub.loc[sub[factor] == 0, item], sub.loc[sub[factor] == 1, item]),
            }
        conds = usable_levels(sub, "condition")
        skipped = _skip(sub, "condition", conds)
        if skipped:
            res["condition"] = skipped
            res["condition_pairwise"] = {
                "test": "Mann-Whitney U per pair of conditions",
                "rows": [],
            }
            out[item] = res
            continue
        sub = sub[sub["condition"].isin(conds)]
        kw = pg.kruskal(data=sub, dv=item, between="condition").iloc[0]
        h, n = float(kw["H"]), len(sub)
        res["condition"] = {
            "test": "Kruskal-Wallis H (pingouin.kruskal)",
            "H": _num(h),
            "df": _num(kw["ddof1"]),
            "p": _num(_get(kw, "p_unc")),
            "epsilon_sq": _num(h / (n - 1)) if n > 1 else None,  # Tomczak & Tomczak (2014)
            "n": int(n),
            "medians": {c: _num(sub.loc[sub["condition"] == c, item].median()) for c in conds},
        }
        pairs = []
        for a, b in itertools.combinations(conds, 2):
            pairs.append(
                {
                    "A": a,
                    "B": b,
                    **_mwu(sub.loc[sub.condition == a, item], sub.loc[sub.condition == b, item]),
                }
            )
        if pairs:
            _, adj = pg.multicomp([p["p"] for p in pairs], method=padjust)
            for p, a in zip(pairs, adj, strict=True):
                p["p_corr"] = _num(a)
        res["condition_pairwise"] = {"test": "Mann-Whitney U per pair of conditions", "rows": pairs}
        out[item] = res
    return out


def exploratory(frames: Frames) -> dict[str, Any]:
    """Demonstration replays and normalised test time by condition (one-way ANOVAs + Tukey)."""
    s = frames.subjects.copy()
    s["condition"] = s["condition"].astype(str)
    out: dict[str, Any] = {}
    for measure, label in EXPLORATORY_MEASURES.items():
        sub = s.dropna(subset=[measure])
        if sub[measure].nunique() < 2:
            out[measure] = {"label": label, "skipped": "no variation"}
            continue
        res: dict[str, Any] = {"label": label}
        for factor in BETWEEN_FACTORS:
            levels = usable_levels(sub, factor)
            skipped = _skip(sub, factor, levels)
            if skipped:
                res[factor] = skipped
                continue
            fsub = sub[sub[factor].astype(str).isin([str(lv) for lv in levels])]
            a = pg.anova(data=fsub, dv=measure, between=factor).iloc[0]
            res[factor] = {
                "test": "one-way ANOVA (pingouin.anova)",
                "F": _num(a["F"]),
                "df1": _num(a["ddof1"]),
                "df2": _num(a["ddof2"]),
                "p": _num(_get(a, "p_unc")),
                "np2": _num(a.get("np2")),
                "n": int(len(fsub)),
                "means": {
                    str(lvl): mean_ci(fsub.loc[fsub[factor] == lvl, measure]) for lvl in levels
                },
                "tukey": _tukey_rows(fsub, measure, factor),
            }
        out[measure] = res
    return out
