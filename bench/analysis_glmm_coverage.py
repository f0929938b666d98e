"""Coverage of the GLMM's Wald 95% CIs for planted effects (a bench script, not a test).

Simulates studies with `cfteach.analysis.synthetic` at known effects, fits the trial-level
GLMM exactly as `cfteach analyze` does (`trial_glmm`: glmer's nAGQ = 1 Laplace fit, SEs
from the Hessian with theta uncertainty), and counts how often each interval holds the
planted value, per family of terms, with Wilson 95% intervals on the coverage. The planted
values in the model's coding (centred cf/fs, sum-coded difficulty) follow from the
generator's formula (see `truth`). Each replicate starts from the previous fit (the optimum
does not depend on the start; it only saves iterations). Exclusions are off and no outliers
are planted, so every participant follows the model being checked.

    .venv/bin/python bench/analysis_glmm_coverage.py --n 96 216 --reps 100
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import pandas as pd

from cfteach.analysis import ExclusionConfig, SyntheticConfig, apply_exclusions, generate
from cfteach.analysis.aggregate import build_frames
from cfteach.analysis.glmm import trial_glmm
from cfteach.analysis.power import wilson
from cfteach.analysis.synthetic import DEV, DOMAIN_SHIFT

EFFECTS = dict(interaction=0.6, feature_effect=0.4, cf_fs_interaction=0.2, proposed_interaction=0.3)
FAMILIES = {
    "between (CF, FS, CF x FS)": ("counterfactual", "feature_scaffolding",
                                  "counterfactual:feature_scaffolding"),
    "difficulty": ("difficulty[low]", "difficulty[high]"),
    "CF x difficulty, FS x difficulty": (
        "counterfactual:difficulty[low]", "counterfactual:difficulty[high]",
        "feature_scaffolding:difficulty[low]", "feature_scaffolding:difficulty[high]"),
    "CF x FS x difficulty": ("counterfactual:feature_scaffolding:difficulty[low]",
                             "counterfactual:feature_scaffolding:difficulty[high]"),
    "covariates (domain, position)": ("domain[delivery]", "domain[skateboard]",
                                      "domain_position"),
}


def truth(cfg: SyntheticConfig) -> dict[str, float]:
    """The generator's logit in the GLMM's coding: cf = c + 1/2, fs = f + 1/2 with c, f
    centred, and sign = (-1, 0, 1) = -difficulty[low] + difficulty[high] in sum coding."""
    ia, pi = cfg.interaction, cfg.proposed_interaction
    sign = {"low": -1.0, "high": 1.0}
    dev = {"low": DEV[0], "high": DEV[2]}
    t = {
        "counterfactual": 0.0,
        "feature_scaffolding": cfg.feature_effect,
        "counterfactual:feature_scaffolding": 4 * cfg.cf_fs_interaction,
        "domain[delivery]": DOMAIN_SHIFT["delivery"],
        "domain[skateboard]": DOMAIN_SHIFT["skateboard"],
        "domain_position": 0.0,
    }
    for lvl in ("low", "high"):
        s = sign[lvl]
        t[f"difficulty[{lvl}]"] = cfg.difficulty_effect * dev[lvl] + s * (ia / 2 + pi / 4)
        t[f"counterfactual:difficulty[{lvl}]"] = s * (ia + pi / 2)
        t[f"feature_scaffolding:difficulty[{lvl}]"] = s * pi / 2
        t[f"counterfactual:feature_scaffolding:difficulty[{lvl}]"] = s * pi
    return t


def run(n: int, reps: int, seed: int) -> pd.DataFrame:
    rows, prev = [], None
    excl = ExclusionConfig(aggregate_sd=None, item_sd=None)
    for i in range(reps):
        cfg = SyntheticConfig(n_participants=n, seed=seed + i, n_screened_out=0, n_abandoned=0,
                              n_preview=0, n_outliers=0, **EFFECTS)
        kept, _ = apply_exclusions(generate(cfg), excl)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            g = trial_glmm(build_frames(kept).tests, start=prev)
        prev = g
        true = truth(cfg)
        for t in g["terms"]:
            lo, hi = t["log_odds"] - 1.959964 * t["se"], t["log_odds"] + 1.959964 * t["se"]
            rows.append({"n": n, "rep": i, "term": t["term"], "estimate": t["log_odds"],
                         "se": t["se"], "true": true[t["term"]],
                         "covered": lo <= true[t["term"]] <= hi,
                         "converged": g["converged"], "separated": g["separation"] is not None})
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[96, 216])
    ap.add_argument("--reps", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--csv", default=None, help="also write every interval to this CSV")
    a = ap.parse_args()
    frames = []
    for n in a.n:
        load0, t0 = os.getloadavg()[0], time.perf_counter()
        df = run(n, a.reps, a.seed)
        secs = time.perf_counter() - t0
        frames.append(df)
        print(f"N = {n}: {a.reps} replicates in {secs:.0f} s ({secs / a.reps:.1f} s per fit), "
              f"load {load0:.1f} -> {os.getloadavg()[0]:.1f}; "
              f"not converged {int((~df.groupby('rep')['converged'].first()).sum())}, "
              f"separated {int(df.groupby('rep')['separated'].first().sum())}")
        print("| family | intervals | coverage [Wilson 95%] | mean bias |")
        print("|---|---|---|---|")
        for fam, terms in FAMILIES.items():
            sub = df[df["term"].isin(terms)]
            hits, tot = int(sub["covered"].sum()), len(sub)
            lo, hi = wilson(hits, tot)
            bias = float((sub["estimate"] - sub["true"]).mean())
            print(f"| {fam} | {tot} | {100 * hits / tot:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}] "
                  f"| {bias:+.3f} |")
        print(flush=True)
    if a.csv:
        pd.concat(frames).to_csv(a.csv, index=False)


if __name__ == "__main__":
    main()
