"""Power by simulation: plan N before paying for a study.

Each simulated study is drawn from the synthetic generator (completed participants only,
no exclusions) at planted effect sizes, and analysed with the same code as a real export:
the H1 repeated-measures ANOVA, the full 2 x 2 x 3 model (GG-corrected p when Mauchly
rejects, as the report does) and the paper's separate two-way mixed ANOVAs. Power is the
share of studies with p < alpha; its 95% interval is Wilson's.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd

from cfteach.analysis.io import DIFFICULTIES
from cfteach.analysis.synthetic import SyntheticConfig, generate

#: hypothesis -> (column of `pvalues`, label)
HYPOTHESES = {
    "H1": ("h1:difficulty", "H1: difficulty (RM-ANOVA)"),
    "H2": ("full:counterfactual:difficulty", "H2: counterfactual x difficulty (full model)"),
    "H3": ("full:feature_scaffolding:difficulty", "H3: feature x difficulty (full model)"),
    "CFxFS": ("full:counterfactual:feature_scaffolding", "counterfactual x feature (full model)"),
    "3-way": (
        "full:counterfactual:feature_scaffolding:difficulty",
        "counterfactual x feature x difficulty (full model)",
    ),
}


def study_cells(config: SyntheticConfig) -> pd.DataFrame:
    """Participant x difficulty proportions of one simulated study (completed only)."""
    ex = generate(replace(config, n_screened_out=0, n_abandoned=0, n_preview=0, n_outliers=0))
    t = ex.tests.merge(
        ex.participants[["participant_id", "counterfactual", "feature_scaffolding"]],
        on="participant_id",
    )
    cells = (
        t.groupby(["participant_id", "counterfactual", "feature_scaffolding", "difficulty"])[
            "optimal"
        ]
        .mean()
        .reset_index()
    )
    cells["difficulty"] = pd.Categorical(cells["difficulty"], list(DIFFICULTIES), ordered=True)
    return cells


def pvalues(cells: pd.DataFrame) -> dict[str, float]:
    """p of every test the power table can use, for one study."""
    import pingouin as pg

    from cfteach.analysis.factorial import full_anova

    out: dict[str, float] = {}
    full = full_anova(cells)
    rejected = bool(full.get("sphericity", {}).get("rejected"))
    for t in full.get("terms", []):
        p = t["p_gg"] if rejected and t["p_gg"] is not None else t["p"]
        out[f"full:{t['term']}"] = np.nan if p is None else p
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rm = pg.rm_anova(data=cells, dv="optimal", within="difficulty", subject="participant_id")
        out["h1:difficulty"] = float(rm["p_unc" if "p_unc" in rm else "p-unc"].iloc[0])
        for factor in ("counterfactual", "feature_scaffolding"):
            res = pg.mixed_anova(
                data=cells,
                dv="optimal",
                within="difficulty",
                between=factor,
                subject="participant_id",
            ).set_index("Source")
            col = "p_unc" if "p_unc" in res else "p-unc"
            out[f"separate:{factor}"] = float(res.loc[factor, col])
            out[f"separate:{factor}:difficulty"] = float(res.loc["Interaction", col])
    return out


def simulate(config: SyntheticConfig, n_sims: int, seed: int = 0) -> pd.DataFrame:
    """One row of p values per simulated study (seeds seed .. seed + n_sims - 1)."""
    rows = [pvalues(study_cells(replace(config, seed=seed + i))) for i in range(n_sims)]
    return pd.DataFrame(rows)


def wilson(hits: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson's 95% interval of a proportion."""
    if n == 0:
        return (float("nan"), float("nan"))
    p = hits / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    lo = 0.0 if hits == 0 else max(0.0, float(centre - half))  # exact at the ends, not
    hi = 1.0 if hits == n else min(1.0, float(centre + half))  # -1e-17 or 0.99999...
    return (lo, hi)


def rejection_rates(ps: pd.DataFrame, alpha: float = 0.05) -> dict[str, dict[str, float]]:
    """column -> {power, ci_low, ci_high, n} (share of studies with p < alpha; a test that
    could not run counts as not significant)."""
    out = {}
    n = len(ps)
    for col in ps.columns:
        hits = int((ps[col] < alpha).sum())
        lo, hi = wilson(hits, n)
        out[col] = {"power": hits / n if n else float("nan"), "ci_low": lo, "ci_high": hi, "n": n}
    return out


def power_curve(
    ns: Iterable[int],
    n_sims: int,
    effects: dict[str, Any] | None = None,
    *,
    seed: int = 0,
    alpha: float = 0.05,
    progress: bool | None = False,
) -> pd.DataFrame:
    """Power vs N for each hypothesis in `HYPOTHESES` (rows: N x hypothesis)."""
    from tqdm import tqdm

    base = SyntheticConfig(**(effects or {}))
    ns = list(ns)
    rows = []
    with tqdm(
        total=len(ns) * n_sims,
        disable=None if progress is None else not progress,
        desc="power",
        unit="study",
    ) as bar:
        for n in ns:
            ps = []
            for i in range(n_sims):
                cfg = replace(base, n_participants=n, seed=seed + i)
                ps.append(pvalues(study_cells(cfg)))
                bar.update()
            rates = rejection_rates(pd.DataFrame(ps), alpha)
            for key, (col, label) in HYPOTHESES.items():
                r = rates.get(col) or {"power": 0.0, "ci_low": 0.0, "ci_high": 0.0, "n": n_sims}
                rows.append({"n_participants": n, "hypothesis": key, "label": label, **r})
    return pd.DataFrame(rows)


def _pct_ci(r: pd.Series) -> str:
    """'100% [96, 100]': the rate with its Wilson interval (a bare 100% hides that it is
    an estimate from a finite number of simulations)."""
    return f"{100 * r['power']:.0f}% [{100 * r['ci_low']:.0f}, {100 * r['ci_high']:.0f}]"


MIN_PARTICIPANTS = 8  # two per condition: below that the between tests cannot run


def write_power_report(table: pd.DataFrame, out_dir: Any, alpha: float = 0.05) -> dict[str, str]:
    """power.csv, power.md (N x hypothesis table) and power.png/.svg (curves with Wilson
    95% intervals) in `out_dir`; returns name -> path."""
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    table.to_csv(out / "power.csv", index=False, lineterminator="\n")
    wide = table.pivot(index="n_participants", columns="hypothesis", values="power")
    wide = wide[[h for h in HYPOTHESES if h in wide.columns]]
    cell = table.set_index(["n_participants", "hypothesis"])
    sims = int(table["n"].max()) if "n" in table and len(table) else 0
    lines = [
        f"Power (share of simulated studies with p < {alpha:g}) by number of participants, "
        f"with its Wilson 95% interval over {sims} simulated studies per N (as in power.csv)",
        "",
        "| N | " + " | ".join(HYPOTHESES[h][1] for h in wide.columns) + " |",
        "|---|" + "---|" * len(wide.columns),
    ]
    for n in wide.index:
        lines.append(
            f"| {n} | "
            + " | ".join(_pct_ci(cell.loc[(n, h)]) for h in wide.columns)
            + " |"
        )
    (out / "power.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    plt.rcParams["svg.hashsalt"] = "cfteach"
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for h in wide.columns:
        sub = table[table["hypothesis"] == h].sort_values("n_participants")
        ax.errorbar(
            sub["n_participants"],
            sub["power"],
            yerr=[
                (sub["power"] - sub["ci_low"]).clip(lower=0),
                (sub["ci_high"] - sub["power"]).clip(lower=0),
            ],
            marker="o",
            capsize=3,
            label=HYPOTHESES[h][1],
        )
    ax.axhline(0.8, color="grey", lw=0.8, ls="--")
    ax.set_ylim(0, 1)
    ax.set_xlabel("Participants (completed, equal per condition)")
    ax.set_ylabel(f"Power (p < {alpha:g}), Wilson 95% CI")
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    for ext in ("png", "svg"):
        fig.savefig(
            out / f"power.{ext}",
            dpi=150,
            metadata={"Date": None} if ext == "svg" else {"Software": None},
        )
    plt.close(fig)
    return {k: str(out / f"power.{k}") for k in ("csv", "md", "png", "svg")}
