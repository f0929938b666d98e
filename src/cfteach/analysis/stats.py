"""The paper's statistics, each a thin wrapper over one pingouin (or scipy) call.

Every function returns a plain, JSON-ready dict with the test statistic, degrees of freedom,
p value, effect size and the numbers of participants/observations. The wrappers live in
`stats_within` (H1: difficulty within subjects, ICC, confidence), `stats_between` (H2-H4,
Likert and exploratory measures by group) and `stats_base` (what they share); this module
gathers them under the one name the pipeline, the docs and the tests use.
"""

from __future__ import annotations

from cfteach.analysis.stats_base import complete_cells, mean_ci, no_variance, skipped
from cfteach.analysis.stats_between import (
    BETWEEN_FACTORS,
    EXPLORATORY_MEASURES,
    exploratory,
    group_difficulty_means,
    likert_tests,
    mixed_anova,
    usable_levels,
)
from cfteach.analysis.stats_within import (
    difficulty_means,
    icc_domains,
    posthoc_difficulty,
    rm_anova_difficulty,
    rm_corr_confidence,
    spearman_confidence,
    within_subject_ci,
)

__all__ = [
    "BETWEEN_FACTORS",
    "EXPLORATORY_MEASURES",
    "complete_cells",
    "difficulty_means",
    "exploratory",
    "group_difficulty_means",
    "icc_domains",
    "likert_tests",
    "mean_ci",
    "mixed_anova",
    "no_variance",
    "posthoc_difficulty",
    "rm_anova_difficulty",
    "rm_corr_confidence",
    "skipped",
    "spearman_confidence",
    "usable_levels",
    "within_subject_ci",
]
