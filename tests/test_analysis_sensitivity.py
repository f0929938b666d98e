"""Results with and without the exclusions, and with the robust outlier rule."""

from __future__ import annotations

from dataclasses import replace

import pytest

from cfteach.analysis import AnalysisConfig, SyntheticConfig, compute_results, generate
from cfteach.analysis.exclusions import ExclusionConfig


def test_sensitivity_variants_match_separate_runs() -> None:
    ex = generate(SyntheticConfig(n_participants=48, seed=4))
    r, _ = compute_results(ex)
    by = {v["name"]: v for v in r["sensitivity"]["variants"]}
    assert list(by) == [
        "as analysed",
        "without outlier or manual exclusions",
        "median - 3 MAD instead of mean - k SD",
    ]
    assert by["as analysed"]["n_retained"] == r["participants"]["n_retained"]
    assert by["as analysed"]["h1"]["F"] == pytest.approx(r["h1"]["rm_anova"]["F"])
    none = ExclusionConfig(aggregate_sd=None, item_sd=None)
    r_none, _ = compute_results(ex, AnalysisConfig(exclusions=none))
    v = by["without outlier or manual exclusions"]
    assert v["n_retained"] == r_none["participants"]["n_retained"] > by["as analysed"]["n_retained"]
    assert v["h1"]["F"] == pytest.approx(r_none["h1"]["rm_anova"]["F"])
    full = {t["term"]: t for t in r_none["full_anova"]}
    assert v["full_anova"]["counterfactual:difficulty"]["F"] == pytest.approx(
        full["counterfactual:difficulty"]["F"]
    )
    mad = replace(ExclusionConfig(), aggregate_sd=None, aggregate_mad=3.0)
    r_mad, _ = compute_results(ex, AnalysisConfig(exclusions=mad))
    assert (
        by["median - 3 MAD instead of mean - k SD"]["n_retained"]
        == (r_mad["participants"]["n_retained"])
    )
    assert "median - 3 MAD" not in {x["name"] for x in r_mad["sensitivity"]["variants"][1:]}
