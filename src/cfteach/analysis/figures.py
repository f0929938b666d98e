"""The report's figures (matplotlib, Agg backend), each saved as PNG and SVG.

Error bars are 95% t-intervals of the mean over participants, computed in `stats.mean_ci`
(deterministic: no bootstrap).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from cfteach.analysis.aggregate import CF_LABELS, FS_LABELS, Frames  # noqa: E402
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
    panels = [
        ("counterfactual", "Counterfactual scaffolding", CF_LABELS),
        ("feature_scaffolding", "Feature scaffolding", FS_LABELS),
        ("condition", "Condition", {c: c for c in CONDITIONS}),
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
    """Stacked percentage bars of the Likert answers by condition, one panel per item."""
    fig, axes = plt.subplots(1, 2, figsize=(13, 3.6), sharey=True)
    lk = frames.tests[["participant_id", "condition"]].drop_duplicates()
    for ax, item in zip(axes, LIKERT_ITEMS, strict=True):
        data = frames.likert_long[frames.likert_long["item"] == item]
        data = data.drop(columns=["condition"]).merge(lk, on="participant_id")
        counts = pd.crosstab(data["condition"].astype(str), data["value"]).reindex(
            index=list(CONDITIONS), columns=range(1, 6), fill_value=0
        )
        pct = counts.div(counts.sum(axis=1).replace(0, np.nan), axis=0).fillna(0) * 100
        _stacked(ax, pct, item)
        ax.set_title(item.replace("_", " ").capitalize() + " of the demonstrations")
    axes[0].set_yticks(range(len(CONDITIONS)), list(CONDITIONS))
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
    t = frames.tests.dropna(subset=["confidence"])
    cnt = pd.crosstab(t["difficulty"].astype(str), t["confidence"].astype(int)).reindex(
        index=list(DIFFICULTIES), columns=range(1, 6), fill_value=0
    )
    pct = cnt.div(cnt.sum(axis=1).replace(0, np.nan), axis=0).fillna(0) * 100
    _stacked(ax2, pct, "confidence")
    ax2.set_yticks(range(3), DIFF_LABELS)
    ax2.set_title("Confidence answers by difficulty")
    fig.tight_layout()
    return _save(fig, out_dir, "confidence")


def _stars(p: float | None) -> str:
    if p is None:
        return "n/a"
    return "***" if p < 0.001 else "**" if p < 0.01 else "*" if p < 0.05 else "n.s."


def difficulty_plot(frames: Frames, results: dict[str, Any], out_dir: Path) -> list[str]:
    """H1: mean proportion optimal per difficulty (95% CI) with the paired post hocs."""
    from cfteach.analysis.stats import difficulty_means

    ph = results["h1"]["posthoc"]["paired"]
    means = difficulty_means(frames.cells)
    n = int(frames.cells["participant_id"].nunique())
    fig, ax = plt.subplots(figsize=(5.2, 4.2))
    x = np.arange(len(DIFFICULTIES))
    m = [means[d]["mean"] for d in DIFFICULTIES]
    ci = [means[d]["ci95"] for d in DIFFICULTIES]
    m_arr = np.array([np.nan if v is None else v for v in m], dtype=float)
    lo = np.array([np.nan if c[0] is None else c[0] for c in ci], dtype=float)
    hi = np.array([np.nan if c[1] is None else c[1] for c in ci], dtype=float)
    ax.bar(x, m_arr, color=["#8fbc8f", "#e9c46a", "#e76f51"], edgecolor="k", width=0.6)
    ax.errorbar(x, m_arr, yerr=[m_arr - lo, hi - m_arr], fmt="none", ecolor="k", capsize=4)
    top = np.nanmax(hi) if np.isfinite(hi).any() else 1.0
    pairs = {(r["A"], r["B"]): r["p_corr"] for r in ph.get("rows", [])}
    for k, (a, b) in enumerate([("low", "medium"), ("medium", "high"), ("low", "high")]):
        if not pairs:
            break
        p = pairs.get((a, b), pairs.get((b, a)))
        i, j = DIFFICULTIES.index(a), DIFFICULTIES.index(b)
        y = top + 0.06 + 0.08 * k
        ax.plot([i, i, j, j], [y - 0.02, y, y, y - 0.02], color="k", lw=0.8)
        ax.text((i + j) / 2, y + 0.005, _stars(p), ha="center", va="bottom", fontsize=9)
    ax.set_xticks(x, DIFF_LABELS)
    ax.set_xlabel("Test difficulty")
    ax.set_ylabel("Proportion optimal (mean, 95% CI)")
    ax.set_ylim(0, max(1.0, top + 0.35))
    test = f"paired t-tests, {ph['padjust']}" if pairs else "too few participants for tests"
    ax.set_title(f"N = {n}; {test}", fontsize=9)
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
    for row in res["simple_effects"]["rows"]:
        j = DIFFICULTIES.index(row["difficulty"])
        ax.text(j, 1.02, simple_effect_label(row), ha="center", fontsize=8)
    ax.set_xticks(x, DIFF_LABELS)
    ax.set_xlabel("Test difficulty")
    ax.set_ylabel("Proportion optimal (mean, 95% CI)")
    ax.set_ylim(0, 1.1)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False)
    ax.set_title("Counterfactual scaffolding (paper's Fig. 5 form)", fontsize=10)
    fig.tight_layout()
    return _save(fig, out_dir, "paper_bars")


def exploratory_plot(frames: Frames, out_dir: Path) -> list[str]:
    """Per-participant demonstration plays and test time per optimal step, by condition."""
    s = frames.subjects
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
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
        ax.set_xticks(range(len(CONDITIONS)), list(CONDITIONS), fontsize=8)
        ax.set_ylabel(label)
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
        "exploratory": exploratory_plot(frames, out_dir),
    }
    return {name: files for name, files in figures.items() if files}
