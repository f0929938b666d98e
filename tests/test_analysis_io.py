"""Export loading: the agreed format round-trips, and broken exports fail with clear errors."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest

from cfteach.analysis import ExportError, SyntheticConfig, generate, load_export, write_export
from cfteach.analysis.io import CONDITIONS, SCHEMA


@pytest.fixture(scope="module")
def export_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("export")
    write_export(generate(SyntheticConfig(n_participants=16, seed=3)), d)
    return d


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def test_written_export_has_exactly_the_agreed_columns(export_dir: Path) -> None:
    for fname, spec in SCHEMA.items():
        header = (export_dir / fname).read_text(encoding="utf-8").splitlines()[0]
        assert header.split(",") == list(spec), fname
    dd = pd.read_csv(export_dir / "data_dictionary.csv")
    assert list(dd.columns) == ["file", "column", "type", "description"]
    assert len(dd) == sum(len(s) for s in SCHEMA.values())


def test_round_trip_keeps_values(export_dir: Path) -> None:
    ex = load_export(export_dir)
    orig = generate(SyntheticConfig(n_participants=16, seed=3))
    assert list(ex.participants["participant_id"]) == list(orig.participants["participant_id"])
    assert ex.tests["reward"].tolist() == pytest.approx(orig.tests["reward"].tolist())
    assert ex.tests["optimal"].tolist() == orig.tests["optimal"].tolist()
    # ids that look numeric or like NA stay strings
    assert ex.participants["participant_id"].map(type).eq(str).all()
    # completed_at is empty for sessions that did not complete
    not_done = ex.participants["status"] != "completed"
    assert ex.participants.loc[not_done, "completed_at"].isna().all()


def test_missing_directory(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match="does not exist"):
        load_export(tmp_path / "nope")


def test_missing_file_names_it(export_dir: Path, tmp_path: Path) -> None:
    d = _copy(export_dir, tmp_path / "e")
    (d / "likert.csv").unlink()
    with pytest.raises(ExportError, match="likert.csv not found"):
        load_export(d)


def test_missing_column_names_file_and_column(export_dir: Path, tmp_path: Path) -> None:
    d = _copy(export_dir, tmp_path / "e")
    df = pd.read_csv(d / "test_responses.csv", dtype=str)
    df.drop(columns=["optimal_reward"]).to_csv(d / "test_responses.csv", index=False)
    msg = r"test_responses.csv: missing column\(s\) 'optimal_reward'"
    with pytest.raises(ExportError, match=msg):
        load_export(d)


@pytest.mark.parametrize(
    ("fname", "column", "value", "message"),
    [
        ("participants.csv", "condition", "placebo", "column 'condition' has value 'placebo'"),
        ("test_responses.csv", "reward", "abc", "column 'reward' has non-numeric value 'abc'"),
        ("test_responses.csv", "optimal", "2", "column 'optimal' must be 0 or 1"),
        ("test_responses.csv", "confidence", "7", "column 'confidence' value 7 outside 1..5"),
        ("likert.csv", "value", "", "column 'value' has an empty cell"),
        ("demo_views.csv", "demo_index", "1.5", "column 'demo_index' must hold integers"),
        (
            "likert.csv",
            "value",
            "99999999999999999999",
            "column 'value' has an out-of-range integer '?99999999999999999999",
        ),
    ],
)
def test_bad_values(
    export_dir: Path, tmp_path: Path, fname: str, column: str, value: str, message: str
) -> None:
    d = _copy(export_dir, tmp_path / "e")
    df = pd.read_csv(d / fname, dtype=str, keep_default_na=False)
    df.loc[0, column] = value
    df.to_csv(d / fname, index=False)
    with pytest.raises(ExportError, match=f"{fname}: {message}"):
        load_export(d)


def test_unknown_participant_in_tests(export_dir: Path, tmp_path: Path) -> None:
    d = _copy(export_dir, tmp_path / "e")
    df = pd.read_csv(d / "test_responses.csv", dtype=str, keep_default_na=False)
    df.loc[0, "participant_id"] = "ghost"
    df.to_csv(d / "test_responses.csv", index=False)
    with pytest.raises(ExportError, match="test_responses.csv: column 'participant_id'.*'ghost'"):
        load_export(d)


def test_duplicate_participant(export_dir: Path, tmp_path: Path) -> None:
    d = _copy(export_dir, tmp_path / "e")
    df = pd.read_csv(d / "participants.csv", dtype=str, keep_default_na=False)
    pd.concat([df, df.iloc[[0]]]).to_csv(d / "participants.csv", index=False)
    with pytest.raises(ExportError, match="participants.csv: column 'participant_id' repeats"):
        load_export(d)


def test_empty_file(export_dir: Path, tmp_path: Path) -> None:
    d = _copy(export_dir, tmp_path / "e")
    (d / "demo_views.csv").write_text("", encoding="utf-8")
    with pytest.raises(ExportError, match="demo_views.csv is empty"):
        load_export(d)


def test_scaffolding_flags_must_match_condition(export_dir: Path, tmp_path: Path) -> None:
    d = _copy(export_dir, tmp_path / "e")
    df = pd.read_csv(d / "participants.csv", dtype=str, keep_default_na=False)
    i = df.index[df["condition"] == "baseline"][0]
    df.loc[i, "counterfactual"] = "1"
    df.to_csv(d / "participants.csv", index=False)
    with pytest.raises(ExportError, match="participants.csv: column 'counterfactual' is 1"):
        load_export(d)


def test_condition_must_agree_across_files(export_dir: Path, tmp_path: Path) -> None:
    d = _copy(export_dir, tmp_path / "e")
    df = pd.read_csv(d / "likert.csv", dtype=str, keep_default_na=False)
    df.loc[0, "condition"] = next(c for c in CONDITIONS if c != df.loc[0, "condition"])
    df.to_csv(d / "likert.csv", index=False)
    with pytest.raises(ExportError, match="likert.csv: column 'condition' is"):
        load_export(d)
