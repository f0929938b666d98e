"""Power of the full 2 x 2 x 3 model vs the paper's separate two-way models, on planted data.

    python bench/analysis_power.py [N_SIMS] [N_PARTICIPANTS]   (defaults: 200, 216)

For each scenario, N_SIMS simulated studies (seeds 0..N_SIMS-1, completed participants
only) are analysed by both; printed is the share with p < .05 for each relevant test, with
Wilson 95% intervals, as a Markdown table (the one in docs/analysis.md), plus seconds; then
the whole pipeline (exclusions included) on seeds 0-19 of the default synthetic study.
"""

from __future__ import annotations

import sys
import time

from cfteach.analysis.power import rejection_rates, simulate
from cfteach.analysis.synthetic import SyntheticConfig

SCENARIOS = {
    "cf x difficulty (0.35 logit)": {"interaction": 0.35},
    "proposed-only x difficulty (0.7 logit; a three-way effect)": {
        "interaction": 0.0,
        "proposed_interaction": 0.7,
    },
    "cf x fs crossover (0.3 logit)": {"interaction": 0.0, "cf_fs_interaction": 0.3},
    "no group effect (difficulty only)": {"interaction": 0.0},
}
COLUMNS = [
    ("full:counterfactual:difficulty", "full: CF x D"),
    ("full:feature_scaffolding:difficulty", "full: FS x D"),
    ("full:counterfactual:feature_scaffolding", "full: CF x FS"),
    ("full:counterfactual:feature_scaffolding:difficulty", "full: CF x FS x D"),
    ("full:counterfactual", "full: CF"),
    ("full:feature_scaffolding", "full: FS"),
    ("separate:counterfactual:difficulty", "separate: CF x D"),
    ("separate:feature_scaffolding:difficulty", "separate: FS x D"),
    ("separate:counterfactual", "separate: CF"),
    ("separate:feature_scaffolding", "separate: FS"),
]


def pipeline_seeds(n_seeds: int = 20, n: int = 216) -> None:
    """The claim in docs/analysis.md: the whole pipeline (exclusions included) on the
    default synthetic study, seeds 0..n_seeds-1 and the same with no interaction."""
    from cfteach.analysis import compute_results, generate

    for inter in (0.35, 0.0):
        hits_sep = hits_full = 0
        for seed in range(n_seeds):
            r, _ = compute_results(
                generate(SyntheticConfig(n_participants=n, seed=seed, interaction=inter))
            )
            hits_sep += r["mixed"]["counterfactual"]["effects"]["interaction"]["p"] < 0.05
            term = {t["term"]: t for t in r["full_anova"]}["counterfactual:difficulty"]
            rejected = r["full_anova_detail"]["sphericity"]["rejected"]
            hits_full += (term["p_gg"] if rejected else term["p"]) < 0.05
        print(
            f"pipeline, {n} participants, interaction {inter}: separate CF x D p < .05 in "
            f"{hits_sep} of {n_seeds} seeds; full model CF x D in {hits_full} of {n_seeds}",
            flush=True,
        )


def main() -> None:
    n_sims = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 216
    print(f"{n_sims} simulated studies of {n} participants per scenario; p < .05\n")
    print("| scenario | " + " | ".join(label for _, label in COLUMNS) + " |")
    print("|---|" + "---|" * len(COLUMNS))
    for name, effects in SCENARIOS.items():
        t0 = time.perf_counter()
        ps = simulate(SyntheticConfig(n_participants=n, **effects), n_sims)
        rates = rejection_rates(ps)
        cells = [f"{100 * rates[c]['power']:.1f}%" for c, _ in COLUMNS]
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
        print(
            f"<!-- {name}: {time.perf_counter() - t0:.0f} s; Wilson 95% CIs: "
            + ", ".join(
                f"{label} [{100 * rates[c]['ci_low']:.1f}, {100 * rates[c]['ci_high']:.1f}]"
                for c, label in COLUMNS
            )
            + " -->",
            flush=True,
        )


if __name__ == "__main__":
    main()
    pipeline_seeds()
