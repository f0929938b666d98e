"""End to end: simulated exports through `analyze`, the CLI, and the error rates of H1's test."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps

from cfteach.analysis import (
    AnalysisConfig,
    SyntheticConfig,
    analyze,
    compute_results,
    generate,
    write_export,
)
from cfteach.analysis import stats as S
from cfteach.analysis.io import DIFFICULTIES
from cfteach.cli import app
from cli_runner import WideRunner

SMALL = dict(n_screened_out=0, n_abandoned=0, n_preview=0, n_outliers=0)


def _rm_p(seed: int, effect: float, n: int = 12) -> float:
    ex = generate(
        SyntheticConfig(
            n_participants=n, seed=seed, difficulty_effect=effect, interaction=0.0, **SMALL
        )
    )
    cells = ex.tests.groupby(["participant_id", "difficulty"])["optimal"].mean().reset_index()
    cells["difficulty"] = pd.Categorical(cells["difficulty"], list(DIFFICULTIES), ordered=True)
    return S.rm_anova_difficulty(SimpleNamespace(cells=cells, tests=ex.tests))["p"]


@pytest.mark.slow
def test_rm_anova_false_positive_rate_is_near_alpha() -> None:
    """No planted difficulty effect: p < .05 in about 5% of 200 simulated studies."""
    n_seeds, alpha = 200, 0.05
    hits = sum(_rm_p(seed, effect=0.0) < alpha for seed in range(n_seeds))
    lo, hi = sps.binom.ppf([0.001, 0.999], n_seeds, alpha)
    assert lo <= hits <= hi, f"{hits} false positives in {n_seeds}"


def test_rm_anova_detects_planted_difficulty_effect() -> None:
    ps = [_rm_p(seed, effect=1.0) for seed in range(20)]
    assert sum(p < 0.05 for p in ps) >= 19  # power is ~1 for the paper's effect, N = 12


def test_synthetic_is_reproducible_and_seeded() -> None:
    a = generate(SyntheticConfig(n_participants=20, seed=7))
    b = generate(SyntheticConfig(n_participants=20, seed=7))
    c = generate(SyntheticConfig(n_participants=20, seed=8))
    pd.testing.assert_frame_equal(a.tests, b.tests)
    pd.testing.assert_frame_equal(a.participants, b.participants)
    assert not a.tests["optimal"].equals(c.tests["optimal"])


def test_synthetic_design_is_counterbalanced() -> None:
    ex = generate(SyntheticConfig(n_participants=216, seed=0))
    done = ex.participants[
        (ex.participants.status == "completed") & (ex.participants.is_preview == 0)
    ]
    assert len(done) == 216
    assert done.condition.value_counts().tolist() == [54] * 4
    cells = done.groupby(["condition", "domain_order", "test_set"]).size()
    assert len(cells) == 72 and set(cells) == {3}
    per = (
        ex.tests[ex.tests.participant_id.isin(done.participant_id)]
        .groupby(["participant_id", "domain", "difficulty"])
        .size()
    )
    assert set(per) == {2}  # two tests per domain x difficulty
    # the reward rule the platform uses: optimal iff reward equals the optimal reward
    t = ex.tests
    assert (np.isclose(t.reward, t.optimal_reward) == t.optimal.astype(bool)).all()


def test_bad_synthetic_config() -> None:
    with pytest.raises(ValueError, match="n_participants must be at least 1"):
        SyntheticConfig(n_participants=0)
    with pytest.raises(ValueError, match="padjust must be one of"):
        AnalysisConfig(padjust="tukey")


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    base = tmp_path_factory.mktemp("run")
    export = write_export(generate(SyntheticConfig(n_participants=72, seed=2)), base / "export")
    results = analyze(export, base / "out")
    return base / "out", results


def test_analyze_writes_every_output(report) -> None:
    out, results = report
    for name in ("report.md", "report.html", "results.json"):
        assert (out / name).stat().st_size > 1000
    for fig in ("difficulty", "interaction", "paper_bars", "likert", "confidence", "exploratory"):
        for ext in ("png", "svg"):
            assert (out / "figures" / f"{fig}.{ext}").stat().st_size > 5000
    on_disk = json.loads((out / "results.json").read_text())
    assert on_disk == json.loads(json.dumps(results))


def test_report_numbers_match_results(report) -> None:
    out, r = report
    n = r["participants"]["n_retained"]
    rm = r["h1"]["rm_anova"]
    assert (rm["df1"], rm["df2"]) == (2, 2 * (n - 1))
    md = (out / "report.md").read_text()
    assert f"F(2, {2 * (n - 1)}) = {rm['F']:.2f}" in md
    inter = r["mixed"]["condition"]["effects"]["interaction"]
    assert (inter["df1"], inter["df2"]) == (6, 2 * (n - 4))
    assert f"F(6, {2 * (n - 4)}) = {inter['F']:.2f}" in md
    betw = r["mixed"]["counterfactual"]["effects"]["between"]
    assert (betw["df1"], betw["df2"]) == (1, n - 2)
    html = (out / "report.html").read_text()
    assert "<table>" in html and 'src="figures/interaction.png"' in html
    assert "authors' variant" in md
    # every exclusion is listed with its reason
    for e in r["exclusions"]:
        assert f"| {e['participant_id']} | {e['condition']} | {e['rule']} |" in md
    assert r["participants"]["n_retained"] + len(r["exclusions"]) == r["participants"]["n_sessions"]


def test_planted_effects_show_up_in_the_paper_tests(report) -> None:
    _, r = report
    assert r["h1"]["rm_anova"]["p"] < 1e-6
    m = r["h1"]["rm_anova"]["means"]
    assert m["low"]["mean"] > m["medium"]["mean"] > m["high"]["mean"]
    assert r["h1"]["spearman"]["r"] < 0
    rules = {e["rule"] for e in r["exclusions"]}
    assert {"preview", "status"} <= rules
    planted = {e["participant_id"] for e in r["exclusions"] if e["rule"].endswith("outlier")}
    assert len(planted) >= 1


def test_missing_conditions_skip_only_what_cannot_run() -> None:
    ex = generate(SyntheticConfig(n_participants=16, seed=1, **SMALL))
    p = ex.participants
    no_fs = ex.subset(p.loc[~p.condition.isin(["feature_only", "proposed"]), "participant_id"])
    r, _ = compute_results(no_fs)
    assert r["participants"]["conditions_missing"] == ["feature_only", "proposed"]
    assert "skipped" in r["mixed"]["feature_scaffolding"]
    assert "skipped" in r["likert"]["mental_effort"]["feature_scaffolding"]
    assert "skipped" in r["exploratory"]["time_norm"]["feature_scaffolding"]
    cond = r["mixed"]["condition"]  # two conditions left: still a valid 2-group model
    assert cond["effects"]["between"]["df1"] == 1
    assert cond["effects"]["between"]["F"] == pytest.approx(
        r["mixed"]["counterfactual"]["effects"]["between"]["F"]
    )
    assert r["h1"]["rm_anova"]["n_participants"] == 8
    one = ex.subset(p.loc[p.condition == "baseline", "participant_id"])
    r1, _ = compute_results(one)
    assert all("skipped" in r1["mixed"][f] for f in S.BETWEEN_FACTORS)
    assert "skipped" in r1["likert"]["informativeness"]["condition"]
    first = p.loc[p.status == "completed", "participant_id"].iloc[:1]
    pilot, _ = compute_results(ex.subset(first))  # one person: descriptives, tests skipped
    assert pilot["participants"]["n_retained"] == 1
    assert "needs at least 3 participants" in pilot["h1"]["rm_anova"]["skipped"]
    assert [r["n"] for r in pilot["descriptives"]["rows"]] == [1, 1]


def test_cli_synthetic_then_analyze_export(tmp_path: Path) -> None:
    runner = WideRunner()
    res = runner.invoke(
        app,
        [
            "analyze",
            "--synthetic",
            "40",
            "--seed",
            "3",
            "--export-only",
            "--out",
            str(tmp_path / "syn"),
        ],
    )
    assert res.exit_code == 0, res.output
    assert (tmp_path / "syn" / "export" / "participants.csv").exists()
    assert not (tmp_path / "syn" / "report.md").exists()
    manual = tmp_path / "manual.csv"
    pid = pd.read_csv(tmp_path / "syn" / "export" / "participants.csv", dtype=str)[
        "participant_id"
    ].iloc[0]
    manual.write_text(f"participant_id,reason\n{pid},withdrew consent\n")
    res = runner.invoke(
        app,
        [
            "analyze",
            str(tmp_path / "syn" / "export"),
            "--out",
            str(tmp_path / "rep"),
            "--no-figures",
            "--padjust",
            "bonf",
            "--exclude-file",
            str(manual),
        ],
    )
    assert res.exit_code == 0, res.output
    assert "H1: F(2, " in res.output
    r = json.loads((tmp_path / "rep" / "results.json").read_text())
    assert r["config"]["padjust"] == "bonf"
    assert r["h1"]["posthoc"]["paired"]["padjust"] == "bonf"
    first = {e["participant_id"]: e for e in r["exclusions"]}
    if first.get(pid, {}).get("rule") == "manual":
        assert first[pid]["reason"] == "withdrew consent"
    else:  # already excluded by an earlier rule (preview/status)
        assert first[pid]["rule"] in ("preview", "status")


def test_cli_errors(tmp_path: Path) -> None:
    runner = WideRunner()
    res = runner.invoke(app, ["analyze", "--out", str(tmp_path)])
    assert res.exit_code != 0 and "exactly one" in res.output
    (tmp_path / "e").mkdir()
    res = runner.invoke(app, ["analyze", str(tmp_path / "e"), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "participants.csv not found" in res.output
