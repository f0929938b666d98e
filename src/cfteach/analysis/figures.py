"""The report's figures (matplotlib, Agg backend), each saved as PNG and SVG.

Error bars are 95% t-intervals of the mean over participants, computed in `stats.mean_ci`
(deterministic: no bootstrap).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from cfteach.analysis.aggregate import CF_LABELS, FS_LABELS, Frames  # noqa: E402
from cfteach.analysis.descriptives import CONDITION_LABELS  # noqa: E402
from cfteach.analysis.io import CONDITIONS, DIFFICULTIES, LIKERT_ITEMS  # noqa: E402

plt.rcParams["svg.hashsalt"] = "cfteach"  # stable SVG ids, so re-runs give identical files
COND_COLORS = {
    "baseline": "#4c72b0",
    "feature_only": "#55a868",
    "counterfactual_only": "#dd8452",
    "proposed": "#c44e52",
}
LIKERT_LABELS = {
    "informativeness": ["Not", "Slightly", "Moderately", "Very", "Extremely"],
    "mental_effort": ["No", "Slight", "Moderate", "Significant", "Extreme"],
    "confidence": ["Not", "Slightly", "Somewhat", "Very", "Extremely"],
}
LIKERT_CMAPS = {"informativeness": "Greens", "mental_effort": "Oranges", "confidence": "GnBu"}
DIFF_LABELS = [d.capitalize() for d in DIFFICULTIES]


def _save(fig: plt.Figure, out_dir: Path, stem: str) -> list[str]:
    out_dir.mkdir(parents=True, exist_ok=True)
    names = []
    for ext in ("png", "svg"):
        path = out_dir / f"{stem}.{ext}"
        fig.savefig(
            path,
            dpi=150,
            bbox_inches="tight",
            metadata={"Date": None} if ext == "svg" else {"Software": None},
        )
        names.append(path.name)
    plt.close(fig)
    return names


def interaction_plot(results: dict[str, Any], out_dir: Path) -> list[str]:
    """Mean proportion optimal by difficulty x each between factor, with 95% CIs."""
    panels: list[tuple[str, str, Mapping[Any, str]]] = [
        ("counterfactual", "Counterfactual scaffolding", CF_LABELS),
        ("feature_scaffolding", "Feature scaffolding", FS_LABELS),
        ("condition", "Condition", CONDITION_LABELS),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), sharey=True)
    x = np.arange(len(DIFFICULTIES))
    for ax, (factor, title, labels) in zip(axes, panels, strict=True):
        if "skipped" in results[factor]:
            ax.text(
                0.5,
                0.5,
                "not enough participants",
                ha="center",
                va="center",
                transform=ax.transAxes,
            )
            ax.set_title(title)
            continue
        means = pd.DataFrame(results[factor]["means"])
        levels = list(dict.fromkeys(means["level"]))
        for i, lvl in enumerate(levels):
            m = means[means["level"] == lvl].set_index("difficulty").loc[list(DIFFICULTIES)]
            lo = m["mean"] - m["ci95"].map(lambda c: c[0] if c[0] is not None else np.nan)
            hi = m["ci95"].map(lambda c: c[1] if c[1] is not None else np.nan) - m["mean"]
            shift = (i - (len(levels) - 1) / 2) * 0.07
            key = lvl if factor == "condition" else int(lvl)
            color = COND_COLORS.get(lvl) if factor == "condition" else f"C{i}"
            ax.errorbar(
                x + shift,
                m["mean"].astype(float),
                yerr=[lo.astype(float), hi.astype(float)],
                marker="o",
                capsize=3,
                label=labels.get(key, str(lvl)),
                color=color,
            )
        ax.set_xticks(x, DIFF_LABELS)
        ax.set_xlabel("Test difficulty")
        ax.set_title(title)
        ax.set_ylim(0, 1)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=8, loc="lower left")
    axes[0].set_ylabel("Proportion optimal (mean, 95% CI)")
    fig.tight_layout()
    return _save(fig, out_dir, "interaction")


def likert_bars(frames: Frames, out_dir: Path) -> list[str]:
    """Stacked percentage bars of the Likert ratings by condition, one panel per item.

    One value per participant (the median over domains), as the tests use them; a median
    of an even number of answers (x.5) is rounded up.
    """
    fig, axes = plt.subplots(1, 2, figsize=(13, 3.6), sharey=True)
    s = frames.subjects.copy()
    s["condition"] = s["condition"].astype(str)
    for ax, item in zip(axes, LIKERT_ITEMS, strict=True):
        data = s.dropna(subset=[item])
        values = np.floor(data[item].astype(float) + 0.5).astype(int)
        counts = pd.crosstab(data["condition"], values).reindex(
            index=list(CONDITIONS), columns=range(1, 6), fill_value=0
        )
        pct = counts.div(counts.sum(axis=1).replace(0, np.nan), axis=0).fillna(0) * 100
        _stacked(ax, pct, item)
        ax.set_xlabel("% of participants (median rating over domains)")
        ax.set_title(item.replace("_", " ").capitalize() + " of the demonstrations")
    axes[0].set_yticks(range(len(CONDITIONS)), [CONDITION_LABELS[c] for c in CONDITIONS])
    fig.tight_layout()
    return _save(fig, out_dir, "likert")


def _stacked(ax: plt.Axes, pct: pd.DataFrame, item: str) -> None:
    colors = plt.get_cmap(LIKERT_CMAPS[item])(np.linspace(0.25, 0.9, 5))
    left = np.zeros(len(pct))
    for j, col in enumerate(pct.columns):
        vals = pct[col].to_numpy(dtype=float)
        ax.barh(
            range(len(pct)),
            vals,
            left=left,
            color=colors[j],
            label=f"{col} {LIKERT_LABELS[item][j]}",
            edgecolor="white",
        )
        for yi, (lft, v) in enumerate(zip(left, vals, strict=True)):
            if v >= 8:
                ax.text(lft + v / 2, yi, f"{v:.0f}", ha="center", va="center", fontsize=7)
        left += vals
    ax.set_xlim(0, 100)
    ax.set_xlabel("% of answers")
    ax.invert_yaxis()
    ax.legend(fontsize=7, ncol=5, loc="upper center", bbox_to_anchor=(0.5, -0.22), frameon=False)


def confidence_plot(frames: Frames, spearman: dict[str, Any], out_dir: Path) -> list[str]:
    """Confidence by difficulty: bubbles sized by count, plus stacked answer shares."""
    cells = frames.cells.dropna(subset=["confidence"])
    if cells.empty:  # the confidence item is optional in the export
        return []
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.2))
    counts = cells.groupby(["difficulty_code", "confidence"]).size().reset_index(name="n")
    ax.scatter(
        counts["difficulty_code"],
        counts["confidence"],
        s=counts["n"] * 8,
        alpha=0.5,
        color="#2a9d8f",
        edgecolor="k",
        linewidth=0.5,
    )
    m = cells.groupby("difficulty_code")["confidence"].mean()
    ax.plot(m.index, m.to_numpy(), "k-o", label="mean")
    ax.set_xticks(range(3), DIFF_LABELS)
    ax.set_yticks(range(1, 6))
    ax.set_xlabel("Test difficulty")
    ax.set_ylabel("Confidence (median per participant x difficulty)")
    r, n = spearman.get("r"), len(cells)
    ax.set_title(f"r_s = {r:.2f}, N = {n}" if r is not None else f"N = {n}")
    ax.legend(loc="lower left", fontsize=8)
    ax.set_xlim(-0.5, 2.5)
    ax.set_ylim(0.5, 5.5)
    data = [
        cells.loc[cells["difficulty"] == d, "confidence"].to_numpy(dtype=float)
        for d in DIFFICULTIES
    ]
    ax2.boxplot(data, positions=range(3), widths=0.5)
    ax2.set_xticks(range(3), DIFF_LABELS)
    ax2.set_yticks(range(1, 6), [f"{i} {LIKERT_LABELS['confidence'][i - 1]}" for i in range(1, 6)])
    ax2.set_ylim(0.5, 5.5)
    ax2.set_xlabel("Test difficulty")
    ax2.set_ylabel("Median confidence per participant")
    ax2.set_title("Per participant x difficulty (as the tests use it)")
    fig.tight_layout()
    return _save(fig, out_dir, "confidence")


def _stars(p: float | None) -> str:
    if p is None:
        return "n/a"
    return "***" if p < 0.001 else "**" if p < 0.01 else "*" if p < 0.05 else "n.s."


def difficulty_plot(frames: Frames, results: dict[str, Any], out_dir: Path) -> list[str]:
    """H1: mean proportion optimal per difficulty with within-subject 95% CIs
    (Cousineau-Morey) and the paired post hocs' corrected p under the axis."""
    from cfteach.analysis.stats import complete_cells, within_subject_ci

    ph = results["h1"]["posthoc"]["paired"]
    cells = complete_cells(frames.cells)
    if cells.empty:
        cells = frames.cells
    ci = within_subject_ci(cells)
    n = int(cells["participant_id"].nunique())
    fig, ax = plt.subplots(figsize=(5.2, 4.4))
    x = np.arange(len(DIFFICULTIES))
    m_arr = np.array([np.nan if ci[d]["mean"] is None else ci[d]["mean"] for d in DIFFICULTIES])
    half = np.array([np.nan if ci[d]["half"] is None else ci[d]["half"] for d in DIFFICULTIES])
    ax.bar(x, m_arr, color=["#8fbc8f", "#e9c46a", "#e76f51"], edgecolor="k", width=0.6)
    ax.errorbar(x, m_arr, yerr=half, fmt="none", ecolor="k", capsize=4)
    pairs = {(r["A"], r["B"]): r["p_corr"] for r in ph.get("rows", [])}
    notes = []
    for a, b in [("low", "medium"), ("medium", "high"), ("low", "high")]:
        p = pairs.get((a, b), pairs.get((b, a)))
        if pairs:
            notes.append(f"{a}-{b} {_stars(p)}")
    ax.set_xticks(x, DIFF_LABELS)
    ax.set_xlabel("Test difficulty")
    ax.set_ylabel("Proportion optimal (mean, within-subject 95% CI)")
    ax.set_ylim(0, 1)
    test = (
        f"paired t-tests ({ph['padjust']}): " + ", ".join(notes) if pairs else "too few for tests"
    )
    ax.set_title(f"N = {n}; {test}", fontsize=8)
    fig.tight_layout()
    return _save(fig, out_dir, "difficulty")


def simple_effect_label(row: dict[str, Any]) -> str:
    """The p printed over a difficulty: Holm across the difficulties, the one the report uses
    (never the uncorrected t-test p)."""
    p = row.get("p_holm_across")
    if p is None:
        return ""
    return "p_Holm < .001" if p < 0.001 else f"p_Holm = {p:.3f}".replace("0.", ".", 1)


def paper_bars(results: dict[str, Any], out_dir: Path) -> list[str]:
    """The paper's Fig. 5 form: grouped bars of proportion optimal by difficulty, one bar per
    counterfactual level, here with 95% CIs and the per-difficulty simple-effect p."""
    res = results["counterfactual"]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    if "skipped" in res:
        ax.text(
            0.5, 0.5, "not enough participants", ha="center", va="center", transform=ax.transAxes
        )
        return _save(fig, out_dir, "paper_bars")
    means = pd.DataFrame(res["means"])
    levels = list(dict.fromkeys(means["level"]))
    x = np.arange(len(DIFFICULTIES))
    width = 0.8 / len(levels)
    colors = plt.get_cmap("viridis")(np.linspace(0.2, 0.8, len(levels)))
    for i, lvl in enumerate(levels):
        m = means[means["level"] == lvl].set_index("difficulty").loc[list(DIFFICULTIES)]
        mean = m["mean"].astype(float).to_numpy()
        lo = mean - np.array([np.nan if c[0] is None else c[0] for c in m["ci95"]], float)
        hi = np.array([np.nan if c[1] is None else c[1] for c in m["ci95"]], float) - mean
        pos = x + (i - (len(levels) - 1) / 2) * width
        ax.bar(pos, mean, width * 0.95, color=colors[i], label=CF_LABELS.get(int(lvl), lvl))
        ax.errorbar(pos, mean, yerr=[lo, hi], fmt="none", ecolor="k", capsize=3)
    by_diff = {row["difficulty"]: simple_effect_label(row) for row in res["simple_effects"]["rows"]}
    ax.set_xticks(
        x,
        [f"{lbl}\n{by_diff.get(d, '')}" for lbl, d in zip(DIFF_LABELS, DIFFICULTIES, strict=True)],
    )
    ax.set_xlabel("Test difficulty (simple effect of counterfactual scaffolding)")
    ax.set_ylabel("Proportion optimal (mean, 95% CI)")
    ax.set_ylim(0, 1)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.24), ncol=2, frameon=False)
    ax.set_title("Counterfactual scaffolding (paper's Fig. 5 form)", fontsize=10)
    fig.tight_layout()
    return _save(fig, out_dir, "paper_bars")


def exploratory_plot(
    frames: Frames, out_dir: Path, tests: dict[str, Any] | None = None
) -> list[str]:
    """Per-participant demonstration plays and test time per optimal step, by condition,
    with the one-way ANOVA by condition in each panel's title."""
    from cfteach.analysis.report_format import fmt_F

    s = frames.subjects
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    panels = [
        ("plays_completed", "Plays per demonstration"),
        ("time_norm", "Test time per optimal step (s)"),
    ]
    rng = np.random.default_rng(0)  # horizontal jitter only
    for ax, (col, label) in zip(axes, panels, strict=True):
        data = [
            s.loc[s["condition"].astype(str) == c, col].dropna().to_numpy(dtype=float)
            for c in CONDITIONS
        ]
        ax.boxplot(data, positions=range(len(CONDITIONS)), widths=0.5, showfliers=False)
        for i, (c, d) in enumerate(zip(CONDITIONS, data, strict=True)):
            ax.scatter(
                i + rng.uniform(-0.15, 0.15, len(d)), d, s=8, alpha=0.5, color=COND_COLORS[c]
            )
        names = [CONDITION_LABELS[c].replace(" + ", " +\n") for c in CONDITIONS]
        ax.set_xticks(range(len(CONDITIONS)), names, fontsize=8)
        ax.set_xlabel("Condition (one point per participant)")
        ax.set_ylabel(label)
        a = ((tests or {}).get(col) or {}).get("condition") or {}
        ax.set_title(
            "one-way ANOVA: " + fmt_F(a["df1"], a["df2"], a["F"], a["p"])
            if "F" in a
            else "not tested: "
            + str(a.get("skipped", (tests or {}).get(col, {}).get("skipped", "n/a"))),
            fontsize=9,
        )
        ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return _save(fig, out_dir, "exploratory")


def make_figures(frames: Frames, results: dict[str, Any], out_dir: Path) -> dict[str, list[str]]:
    """All figures into `out_dir`; returns figure name -> file names."""
    figures = {
        "difficulty": difficulty_plot(frames, results, out_dir),
        "interaction": interaction_plot(results["mixed"], out_dir),
        "paper_bars": paper_bars(results["mixed"], out_dir),
        "likert": likert_bars(frames, out_dir),
        "confidence": confidence_plot(frames, results["h1"]["spearman"], out_dir),
        "exploratory": exploratory_plot(frames, out_dir, results.get("exploratory")),
    }
    return {name: files for name, files in figures.items() if files}
