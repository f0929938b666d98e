"""Inputs that used to give a wrong result (or a traceback) now give a named error or a
correct result: duplicates, the optimal rule, test items, timestamps, optional confidence,
header-only files, pilots of 1-3 participants, and unexpected errors in the CLI."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from cfteach.analysis import (
    ExportError,
    SyntheticConfig,
    compute_results,
    generate,
    load_export,
    write_export,
)
from cfteach.cli import app


@pytest.fixture(scope="module")
def export_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("export")
    write_export(generate(SyntheticConfig(n_participants=24, seed=5)), d)
    return d


def _edit(src: Path, dst: Path, fname: str, change) -> Path:
    shutil.copytree(src, dst)
    df = pd.read_csv(dst / fname, dtype=str, keep_default_na=False)
    change(df).to_csv(dst / fname, index=False)
    return dst


def _completed(export_dir: Path) -> list[str]:
    p = pd.read_csv(export_dir / "participants.csv", dtype=str, keep_default_na=False)
    return p.loc[(p.status == "completed") & (p.is_preview == "0"), "participant_id"].tolist()


def test_one_duplicated_test_row_is_named(export_dir: Path, tmp_path: Path) -> None:
    d = _edit(export_dir, tmp_path / "e", "test_responses.csv", lambda df: pd.concat([df, df[5:6]]))
    with pytest.raises(ExportError, match=r"test_responses.csv: 1 duplicated row\(s\)") as err:
        load_export(d)
    tests = pd.read_csv(export_dir / "test_responses.csv", dtype=str)
    assert tests.loc[5, "test_id"] in str(err.value)


def test_duplicates_in_four_participants_and_a_whole_file(export_dir: Path, tmp_path: Path) -> None:
    ids = _completed(export_dir)[:4]

    def four(df: pd.DataFrame) -> pd.DataFrame:
        first = df[df.participant_id.isin(ids)].groupby("participant_id").head(1)
        return pd.concat([df, first])

    d = _edit(export_dir, tmp_path / "four", "test_responses.csv", four)
    with pytest.raises(ExportError, match=r"4 duplicated row\(s\).* and 1 more"):
        load_export(d)
    d = _edit(export_dir, tmp_path / "all", "test_responses.csv", lambda df: pd.concat([df, df]))
    with pytest.raises(ExportError, match="duplicated row"):
        load_export(d)


def test_duplicated_likert_row_is_named(export_dir: Path, tmp_path: Path) -> None:
    d = _edit(export_dir, tmp_path / "e", "likert.csv", lambda df: pd.concat([df, df[:1]]))
    with pytest.raises(ExportError, match=r"likert.csv: 1 duplicated row\(s\) of \(participant"):
        load_export(d)


@pytest.mark.parametrize(("optimal", "delta"), [("1", -0.5), ("0", 0.0)])
def test_optimal_must_follow_the_rewards(
    export_dir: Path, tmp_path: Path, optimal: str, delta: float
) -> None:
    def change(df: pd.DataFrame) -> pd.DataFrame:
        df.loc[3, "optimal"] = optimal
        df.loc[3, "reward"] = repr(float(df.loc[3, "optimal_reward"]) + delta)
        return df

    d = _edit(export_dir, tmp_path / "e", "test_responses.csv", change)
    with pytest.raises(ExportError, match=r"column 'optimal' disagrees .* line\(s\) 5"):
        load_export(d)


def test_rewards_within_the_tolerance_count_as_optimal(export_dir: Path, tmp_path: Path) -> None:
    def change(df: pd.DataFrame) -> pd.DataFrame:
        i = df.index[df.optimal == "1"][0]
        df.loc[i, "reward"] = repr(float(df.loc[i, "optimal_reward"]) * (1 + 1e-12))
        return df

    load_export(_edit(export_dir, tmp_path / "e", "test_responses.csv", change))


def test_test_listed_under_another_domain(export_dir: Path, tmp_path: Path) -> None:
    def change(df: pd.DataFrame) -> pd.DataFrame:
        i = df.index[df.domain == "tiles"][0]
        df.loc[i, "domain"] = "skateboard"
        return df

    d = _edit(export_dir, tmp_path / "e", "test_responses.csv", change)
    with pytest.raises(ExportError, match="column 'domain': test '.*' is listed under"):
        load_export(d)


def test_domain_outside_the_participants_order(export_dir: Path, tmp_path: Path) -> None:
    shutil.copytree(export_dir, tmp_path / "e")
    p = pd.read_csv(tmp_path / "e" / "participants.csv", dtype=str, keep_default_na=False)
    i = p.index[p.participant_id == _completed(export_dir)[0]][0]
    p.loc[i, "domain_order"] = "delivery;tiles"
    p.to_csv(tmp_path / "e" / "participants.csv", index=False)
    with pytest.raises(ExportError, match="column 'domain' is 'skateboard' for participant"):
        load_export(tmp_path / "e")


@pytest.mark.parametrize("value", ["yesterday", "2026-13-45T10:00:00Z"])
def test_malformed_timestamp(export_dir: Path, tmp_path: Path, value: str) -> None:
    def change(df: pd.DataFrame) -> pd.DataFrame:
        df.loc[2, "started_at"] = value
        return df

    d = _edit(export_dir, tmp_path / "e", "participants.csv", change)
    with pytest.raises(
        ExportError, match=f"column 'started_at' has a malformed timestamp '{value}'"
    ):
        load_export(d)


def test_header_only_likert_says_so(export_dir: Path, tmp_path: Path) -> None:
    d = _edit(export_dir, tmp_path / "e", "likert.csv", lambda df: df.iloc[:0])
    with pytest.raises(ExportError, match="likert.csv has a header but no rows"):
        load_export(d)


def test_extra_columns_and_files_are_ignored(export_dir: Path, tmp_path: Path) -> None:
    def change(df: pd.DataFrame) -> pd.DataFrame:
        df["client_time_ms"] = df["time_ms"]
        return df

    d = _edit(export_dir, tmp_path / "e", "test_responses.csv", change)
    (d / "comments.csv").write_text("participant_id,comment\nx,hello\n", encoding="utf-8")
    assert len(load_export(d).tests) == len(pd.read_csv(export_dir / "test_responses.csv"))


def test_empty_confidence_skips_only_the_confidence_analyses(
    export_dir: Path, tmp_path: Path
) -> None:
    def change(df: pd.DataFrame) -> pd.DataFrame:
        df["confidence"] = ""
        return df

    d = _edit(export_dir, tmp_path / "e", "test_responses.csv", change)
    res = CliRunner().invoke(app, ["analyze", str(d), "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    r = json.loads((tmp_path / "o" / "results.json").read_text())
    assert "no confidence ratings" in r["h1"]["spearman"]["skipped"]
    assert r["h1"]["rm_anova"]["F"] is not None
    md = (tmp_path / "o" / "report.md").read_text()
    assert "Spearman correlation of confidence with difficulty not computed" in md
    assert not (tmp_path / "o" / "figures" / "confidence.png").exists()


@pytest.mark.parametrize("n", [1, 2, 3])
def test_pilot_exports_get_a_report(export_dir: Path, tmp_path: Path, n: int) -> None:
    """A real 1-3 participant pilot: descriptives, and a plain note for each test it lacks."""
    export = load_export(export_dir)
    pilot = export.subset(_completed(export_dir)[:n])
    write_export(pilot, tmp_path / "pilot")
    res = CliRunner().invoke(
        app, ["analyze", str(tmp_path / "pilot"), "--out", str(tmp_path / "o")]
    )
    assert res.exit_code == 0, res.output
    r = json.loads((tmp_path / "o" / "results.json").read_text())
    assert r["participants"]["n_retained"] == n
    assert r["descriptives"]["rows"][-1]["n"] == n
    rm = r["h1"]["rm_anova"]
    if n < 3:
        assert "needs at least 3 participants" in rm["skipped"]
        assert "H1: not computed" in res.output
        assert "needs at least 3 participants" in r["h1"]["spearman"]["skipped"]
    else:
        assert rm["n_participants"] == 3 and rm["df2"] == 4
    md = (tmp_path / "o" / "report.md").read_text()
    assert "## Descriptives per condition" in md
    assert "Traceback" not in res.output


@pytest.mark.parametrize("n", [1, 2])
def test_cli_synthetic_pilots(tmp_path: Path, n: int) -> None:
    res = CliRunner().invoke(app, ["analyze", "--synthetic", str(n), "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "report.html").exists()


def test_reported_n_is_the_n_the_test_used() -> None:
    """Without the completeness rule a participant lacking 'high' is dropped by the test,
    and the N (and df) say so."""
    from cfteach.analysis import AnalysisConfig, ExclusionConfig

    ex = generate(SyntheticConfig(n_participants=12, seed=2, n_outliers=0))
    t = ex.tests
    pid = ex.participants.loc[ex.participants.status == "completed", "participant_id"].iloc[0]
    ex = type(ex)(
        ex.participants,
        t[~((t.participant_id == pid) & (t.difficulty == "high"))],
        ex.likert,
        ex.demo_views,
    )
    cfg = AnalysisConfig(exclusions=ExclusionConfig(require_complete_data=False, item_sd=None))
    r, _ = compute_results(ex, cfg)
    kept = r["participants"]["n_retained"]
    rm = r["h1"]["rm_anova"]
    assert rm["n_participants"] == kept - 1
    assert rm["df2"] == 2 * (kept - 2)
    assert r["mixed"]["counterfactual"]["n_participants"] == kept - 1


def test_unexpected_error_is_one_line_without_traceback(
    export_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from cfteach.analysis import stats

    def boom(*_a, **_k):
        raise KeyError("difficulty")

    # a step outside any guarded model: a failing model is recorded as skipped instead
    monkeypatch.setattr(stats, "complete_cells", boom)
    res = CliRunner().invoke(app, ["analyze", str(export_dir), "--out", str(tmp_path)])
    assert res.exit_code == 1
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1, res.output
    assert lines[0].startswith("Error: analysis of ") and "KeyError: 'difficulty'" in lines[0]
    assert "in pipeline.py:" in lines[0]  # the innermost frame of cfteach's own code
    assert "Traceback" not in res.output


def test_nobody_left_names_the_rules(export_dir: Path, tmp_path: Path) -> None:
    res = CliRunner().invoke(
        app, ["analyze", str(export_dir), "--out", str(tmp_path), "--expected-tests", "17"]
    )
    assert res.exit_code == 2
    assert "no participant is left after the exclusions" in res.output
    assert "incomplete: 24" in res.output


@pytest.mark.slow
def test_random_corruptions_never_reach_the_user_as_a_traceback(
    export_dir: Path, tmp_path: Path
) -> None:
    """Seeded corruptions of random cells (blank, junk, negative, huge, dropped rows, values
    copied from another column or row): every run ends in a report (exit 0) or a named
    one-line error (exit 2), never an unexpected error (exit 1) or a traceback."""
    import random

    rng = random.Random(13)
    files = ["participants.csv", "test_responses.csv", "likert.csv", "demo_views.csv"]
    for trial in range(25):
        d = tmp_path / f"e{trial}"
        shutil.copytree(export_dir, d)
        fname = rng.choice(files)
        df = pd.read_csv(d / fname, dtype=str, keep_default_na=False)
        col = rng.choice(list(df.columns))
        rows = rng.sample(range(len(df)), k=min(len(df), rng.choice([1, 3, 50])))
        kind = rng.choice(["blank", "junk", "drop", "copy", "same"])
        if kind == "blank":
            df.loc[rows, col] = ""
        elif kind == "junk":
            df.loc[rows, col] = rng.choice(
                ["x", "1e400", "nan", "-1", "3.5", "99999999999999999999"]
            )
        elif kind == "drop":
            df = df.drop(index=rows)
        elif kind == "copy":
            df.loc[rows, col] = df.loc[rows, rng.choice(list(df.columns))].to_numpy()
        else:
            df.loc[rows, col] = df.loc[rows[0], col]
        df.to_csv(d / fname, index=False)
        res = CliRunner().invoke(app, ["analyze", str(d), "--out", str(d / "o"), "--no-figures"])
        what = f"{fname} {kind} {col}: {res.output}"
        assert res.exit_code in (0, 2), what
        assert "Traceback" not in res.output, what
        if res.exit_code == 2:
            assert len([ln for ln in res.output.splitlines() if ln.strip()]) == 1, what
