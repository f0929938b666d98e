"""Summaries of simulated test answers: proportion optimal by difficulty x condition with
95% confidence intervals, the H1 correlation between test overlap and correctness, and the
interaction plot in the analysis figures' style.

The unit of analysis is the learner, as the participant is in the study: each learner's
proportion of optimal answers per difficulty level (averaged over domains for the pooled
"all" rows, as the paper averages each participant over domains), then the mean over
learners with a t-based 95% CI (clipped to [0, 1]).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

LEVELS = ("low", "medium", "high")
ANSWER_COLUMNS = ("domain", "condition", "learner_model", "seed", "learner", "test",
                  "source", "difficulty", "overlap", "correct")


def _check(df: pd.DataFrame) -> None:
    missing = [c for c in ANSWER_COLUMNS if c not in df.columns]
    if missing:
        raise ValueError(f"answer table lacks columns {missing}; expected {list(ANSWER_COLUMNS)}")


def mean_ci(values: np.ndarray, level: float = 0.95) -> tuple[float, float, float]:
    """Mean and t-based confidence interval (a zero-width interval for n = 1 or no spread)."""
    from scipy import stats

    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return (float("nan"),) * 3
    m = float(v.mean())
    if v.size < 2 or np.all(v == v[0]):
        return m, m, m
    half = float(stats.t.ppf(0.5 + level / 2, v.size - 1) * v.std(ddof=1) / np.sqrt(v.size))
    return m, m - half, m + half


def proportion_ci(values: np.ndarray, level: float = 0.95) -> tuple[float, float, float]:
    """`mean_ci` of per-learner proportions, clipped to [0, 1] (a proportion's range)."""
    m, lo, hi = mean_ci(values, level)
    return m, max(0.0, lo), min(1.0, hi)


def proportion_table(df: pd.DataFrame) -> list[dict[str, Any]]:
    """Proportion optimal per learner model x domain (and "all") x condition x difficulty."""
    _check(df)
    levelled = df[df["difficulty"].isin(LEVELS)]
    if levelled.empty:
        return []
    per = (levelled.groupby(["learner_model", "domain", "condition", "difficulty", "seed",
                             "learner"], observed=True)["correct"].mean().reset_index())
    pooled = (per.groupby(["learner_model", "condition", "difficulty", "seed", "learner"],
                          observed=True)["correct"].mean().reset_index())
    pooled["domain"] = "all"
    rows: list[dict[str, Any]] = []
    domains = sorted(per["domain"].unique())
    if len(domains) > 1:
        both = pd.concat([per, pooled], ignore_index=True)
    else:
        both = per
    counts = levelled.groupby(["learner_model", "domain", "condition", "difficulty"],
                              observed=True).size()
    count_of = counts.to_dict()
    for (model, domain, cond, diff), g in both.groupby(
            ["learner_model", "domain", "condition", "difficulty"], observed=True):
        m, lo, hi = proportion_ci(g["correct"].to_numpy())
        n_answers = int(counts.xs((model, cond, diff), level=(0, 2, 3)).sum()) \
            if domain == "all" else int(count_of[(model, domain, cond, diff)])
        rows.append({"learner_model": model, "domain": domain, "condition": cond,
                     "difficulty": diff, "proportion_optimal": m, "ci_low": lo, "ci_high": hi,
                     "n_learners": int(len(g)), "n_answers": n_answers})
    order = {lv: i for i, lv in enumerate(LEVELS)}
    rows.sort(key=lambda r: (r["learner_model"], r["domain"] != "all", r["domain"],
                             r["condition"], order[r["difficulty"]]))
    return rows


def answer_regret(df: pd.DataFrame) -> np.ndarray:
    """Regret of each answer: optimal reward minus the answer's true reward, never below 0,
    and exactly 0 for an optimal answer (scored as the study scores it: `correct`), not a
    rounding error of the two sums.

    An answer that never finishes keeps the reward it collected until the rollout's step
    cap (4 x the instance's states + 4 steps), so its regret is what wandering that long
    costs: the documented cap for unfinished answers.
    """
    gap = np.maximum(0.0, df["optimal_reward"].to_numpy(float) - df["reward"].to_numpy(float))
    if "correct" in df.columns:
        gap = np.where(df["correct"].to_numpy(bool), 0.0, gap)
    return gap


def per_learner(df: pd.DataFrame) -> pd.DataFrame:
    """Each learner's mean regret (`answer_regret`) and proportion of optimal answers."""
    correct = df["correct"].astype(float) if "correct" in df.columns else np.nan
    return df.assign(regret=answer_regret(df), p_optimal=correct).groupby(
        ["learner_model", "domain", "condition", "seed", "learner"], observed=True
    )[["regret", "p_optimal"]].mean().reset_index()


def regret_table(df: pd.DataFrame) -> dict[str, dict[str, dict[str, dict[str, Any]]]]:
    """``regret[learner_model][domain][condition] = {mean, ci_low, ci_high, median,
    p_optimal, n_learners}``: each learner's mean regret over the tests (`answer_regret`),
    then the mean over learners with a t-based 95% CI, the median over learners, and the
    mean proportion of optimal answers."""
    if df.empty:
        return {}
    per = per_learner(df)
    out: dict[str, dict[str, dict[str, dict[str, Any]]]] = {}
    for (model, dom, cond), g in per.groupby(["learner_model", "domain", "condition"],
                                             observed=True):
        m, lo, hi = mean_ci(g["regret"].to_numpy(float))
        out.setdefault(str(model), {}).setdefault(str(dom), {})[str(cond)] = {
            "mean": m, "ci_low": max(0.0, lo), "ci_high": hi,
            "median": float(np.median(g["regret"])), "p_optimal": float(g["p_optimal"].mean()),
            "n_learners": int(len(g))}
    return out


def items_table(beliefs: pd.DataFrame) -> dict[str, dict[str, dict[str, dict[str, Any]]]]:
    """``items_shown[learner_model][domain][condition] = {mean, max, demonstrations,
    tests, feedback}``: items each learner was shown (demonstrations + tests + feedback),
    the mean of each kind beside them."""
    if beliefs.empty or "items" not in beliefs.columns:
        return {}
    out: dict[str, dict[str, dict[str, dict[str, Any]]]] = {}
    for (model, dom, cond), g in beliefs.groupby(["learner_model", "domain", "condition"],
                                                 observed=True):
        out.setdefault(str(model), {}).setdefault(str(dom), {})[str(cond)] = {
            "mean": float(g["items"].mean()), "max": int(g["items"].max()),
            "demonstrations": float(g["demos"].mean()), "tests": float(g["tests"].mean()),
            "feedback": float(g["feedback"].mean())}
    return out


def ordering(table: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Whether proportion optimal falls from low to medium to high difficulty."""
    groups: dict[tuple, dict[str, float]] = {}
    for r in table:
        key = (r["learner_model"], r["domain"], r["condition"])
        groups.setdefault(key, {})[r["difficulty"]] = r["proportion_optimal"]
    out = []
    for (model, domain, cond), p in groups.items():
        holds: bool | None
        weak: bool | None
        if all(lv in p for lv in LEVELS):
            holds = p["low"] > p["medium"] > p["high"]
            weak = p["low"] >= p["medium"] >= p["high"]
        else:
            holds = weak = None
        out.append({"learner_model": model, "domain": domain, "condition": cond,
                    "low_gt_medium_gt_high": holds, "non_increasing": weak,
                    **{lv: p.get(lv) for lv in LEVELS}})
    return out


def h1_correlations(df: pd.DataFrame) -> list[dict[str, Any]]:
    """H1: does the overlap (belief ∩ BEC') predict correctness? Spearman's rho and the
    point-biserial r between each answer's test overlap and whether it was optimal, per
    learner model and domain (and pooled over domains), over every answer given."""
    from scipy import stats

    _check(df)
    rows = []
    scopes = [(d, df[df["domain"] == d]) for d in sorted(df["domain"].unique())]
    if len(scopes) > 1:
        scopes.append(("all", df))
    for model in sorted(df["learner_model"].unique()):
        for domain, sub in scopes:
            s = sub[(sub["learner_model"] == model) & np.isfinite(sub["overlap"])]
            x = s["overlap"].to_numpy(float)
            y = s["correct"].to_numpy(bool).astype(float)
            row: dict[str, Any] = {"learner_model": model, "domain": domain, "n": int(len(s)),
                                   "proportion_optimal": float(y.mean()) if len(y) else None}
            if len(s) >= 3 and np.ptp(x) > 0 and np.ptp(y) > 0:
                rho, p_rho = stats.spearmanr(x, y)
                r, p_r = stats.pointbiserialr(y, x)
                row.update(spearman_rho=float(rho), spearman_p=float(p_rho),
                           pointbiserial_r=float(r), pointbiserial_p=float(p_r))
            else:
                row.update(spearman_rho=None, spearman_p=None, pointbiserial_r=None,
                           pointbiserial_p=None,
                           note="undefined: overlap or correctness does not vary")
            rows.append(row)
    return rows


def interaction_plot(table: list[dict[str, Any]], path: str | Path, *,
                     domain: str = "all", title: str | None = None) -> list[Path]:
    """Proportion optimal by difficulty x condition with 95% CIs, one panel per learner
    model; writes PNG and SVG (matplotlib, Agg). Returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in table if r["domain"] == domain]
    if not rows:
        doms = sorted({r["domain"] for r in table})
        raise ValueError(f"no rows for domain {domain!r} in the table (have {doms})")
    models = sorted({r["learner_model"] for r in rows})
    conditions = [c for c in ("baseline", "feature_only", "counterfactual_only", "proposed",
                              "none") if any(r["condition"] == c for r in rows)]
    conditions += sorted({r["condition"] for r in rows} - set(conditions))
    fig, axes = plt.subplots(1, len(models), figsize=(4.6 * len(models) + 1.2, 4.0),
                             sharey=True, squeeze=False)
    markers = "osD^vP*X"
    width = 0.08
    for ax, model in zip(axes[0], models, strict=True):
        for k, cond in enumerate(conditions):
            pts = {r["difficulty"]: r for r in rows
                   if r["learner_model"] == model and r["condition"] == cond}
            xs = [i + (k - (len(conditions) - 1) / 2) * width
                  for i, lv in enumerate(LEVELS) if lv in pts]
            ys = [pts[lv]["proportion_optimal"] for lv in LEVELS if lv in pts]
            lo = [pts[lv]["proportion_optimal"] - pts[lv]["ci_low"] for lv in LEVELS if lv in pts]
            hi = [pts[lv]["ci_high"] - pts[lv]["proportion_optimal"] for lv in LEVELS if lv in pts]
            if xs:
                ax.errorbar(xs, ys, yerr=[lo, hi], marker=markers[k % len(markers)],
                            capsize=4, linewidth=1.6, label=cond.replace("_", " "))
        ax.set_xticks(range(len(LEVELS)), [lv.capitalize() for lv in LEVELS])
        ax.set_xlabel("Test difficulty")
        ax.set_title(f"learner: {model}")
        ax.set_ylim(0, 1.05)
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylabel("Proportion optimal (95% CI)")
    axes[0][-1].legend(title="Condition", loc="center left", bbox_to_anchor=(1.02, 0.5),
                       frameon=False)
    fig.suptitle(title or f"Simulated learners, domain: {domain}")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    written = []
    for ext in (".png", ".svg"):
        out = path.with_suffix(ext)
        fig.savefig(out, dpi=130, bbox_inches="tight")
        written.append(out)
    plt.close(fig)
    return written
