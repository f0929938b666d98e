"""H2-H4, M2/M3 and the exploratory measures: the between-subjects factors (counterfactual,
feature scaffolding, condition) by mixed ANOVA, rank tests and one-way ANOVAs."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pandas as pd
import pingouin as pg

from cfteach.analysis.aggregate import Frames
from cfteach.analysis.effects import eta2_partial_ci
from cfteach.analysis.io import CONDITIONS, DIFFICULTIES, LIKERT_ITEMS
from cfteach.analysis.stats_base import _get, _num, complete_cells, mean_ci, no_variance

BETWEEN_FACTORS = ("counterfactual", "feature_scaffolding", "condition")
EXPLORATORY_MEASURES = {
    "plays_completed": "plays per demonstration",
    "replays": "replays per demonstration",
    "time_norm": "test time per optimal step (s)",
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
    effects: dict[str, dict[str, Any]] = {}
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
    subj = cells.groupby(["participant_id", factor], observed=True)["optimal"].mean().reset_index()
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
