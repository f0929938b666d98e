"""`cfteach analyze` with closed_loop participants: the paper's statistics leave them out and
a closed-loop section compares them with every condition (hand-computed figures)."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from cfteach.analysis import AnalysisConfig, SyntheticConfig, analyze, generate, write_export
from cfteach.analysis import closed_loop as CL

SMALL = dict(n_participants=24, n_screened_out=0, n_abandoned=0, n_preview=0, n_outliers=0)


def _append(path: Path, rows: list[dict]) -> None:
    df = pd.read_csv(path, dtype=str, keep_default_na=False)
    add = pd.DataFrame(rows).astype(str).reindex(columns=df.columns, fill_value="")
    pd.concat([df, add]).to_csv(path, index=False)


def _with_closed_loop(d: Path) -> Path:
    """A synthetic export plus two closed-loop participants with known answers."""
    write_export(generate(SyntheticConfig(**SMALL)), d)
    base = {"condition": "closed_loop", "counterfactual": 1, "feature_scaffolding": 0,
            "status": "completed", "is_preview": 0, "domain_order": "delivery",
            "test_set": 0, "practice_attempts": 1}
    _append(d / "participants.csv", [
        {**base, "participant_id": "cl1", "started_at": "2026-01-12T10:00:00.000Z",
         "completed_at": "2026-01-12T10:20:00.000Z"},
        {**base, "participant_id": "cl2", "started_at": "2026-01-12T11:00:00.000Z",
         "completed_at": "2026-01-12T11:30:00.000Z"}])
    tests = []
    for pid, answers, ms in (("cl1", {"low": 10, "medium": 7, "high": 10}, 1000),
                             ("cl2", {"low": 8, "medium": 10, "high": 10}, 3000)):
        for k, (level, reward) in enumerate(answers.items()):
            tests.append({"participant_id": pid, "condition": "closed_loop",
                          "domain": "delivery", "domain_position": 1,
                          "test_id": f"delivery-{level}-{k}", "difficulty": level,
                          "trial_index": k + 1, "reward": reward, "optimal_reward": 10,
                          "optimal": int(reward == 10), "time_ms": ms, "confidence": 3})
    _append(d / "test_responses.csv", tests)
    items = [{"participant_id": "cl1", "domain": "delivery", "position": k, "kind": kind,
              "time_ms": 1000} for k, kind in enumerate(
                  ["demonstration", "test", "feedback", "demonstration"])]
    items += [{"participant_id": "cl2", "domain": "delivery", "position": k, "kind": kind,
               "time_ms": 3000} for k, kind in enumerate(["demonstration", "test"])]
    pd.DataFrame(items).to_csv(d / CL.ITEMS, index=False)
    return d


def test_compare_by_hand(tmp_path: Path) -> None:
    s = CL.compare(_with_closed_loop(tmp_path / "ex"))
    assert s is not None and s["participants"]["closed_loop"] == 2
    by = {(r["condition"], r["difficulty"]): r for r in s["by_difficulty"]}
    assert by["closed_loop", "low"]["regret"]["mean"] == pytest.approx(1.0)
    assert by["closed_loop", "low"]["proportion_optimal"]["mean"] == pytest.approx(0.5)
    assert by["closed_loop", "medium"]["regret"]["mean"] == pytest.approx(1.5)
    assert by["closed_loop", "high"]["regret"]["mean"] == 0
    assert by["closed_loop", "all"]["regret"]["mean"] == pytest.approx((3 / 3 + 2 / 3) / 2)
    assert by["closed_loop", "low"]["regret"]["n"] == 2
    assert {c for c, _ in by} == {"baseline", "feature_only", "counterfactual_only",
                                  "proposed", "closed_loop"}
    shown = {r["condition"]: r for r in s["items_shown"]}["closed_loop"]
    assert shown["items_per_domain"]["mean"] == 3 and shown["max_items"] == 4
    assert (shown["demonstration"], shown["test"], shown["feedback"]) == (1.5, 1.0, 0.5)
    assert shown["teaching_minutes_per_domain"]["mean"] == pytest.approx(5000 / 60000)
    tot = {r["condition"]: r for r in s["time_on_task"]}["closed_loop"]
    assert tot["session_minutes"]["mean"] == pytest.approx(25.0)
    assert tot["test_seconds"]["mean"] == pytest.approx(2.0)


def test_analyze_reports_closed_loop_and_keeps_the_paper_analysis(tmp_path: Path) -> None:
    cfg = AnalysisConfig(figures=False)
    plain = analyze(write_export(generate(SyntheticConfig(**SMALL)), tmp_path / "p"),
                    tmp_path / "out-plain", cfg, progress=False)
    assert "closed_loop" not in plain
    assert CL.SECTION not in (tmp_path / "out-plain" / "report.md").read_text()
    ex = _with_closed_loop(tmp_path / "ex")
    res = analyze(ex, tmp_path / "out", cfg, progress=False)
    # the paper's statistics are those of the four conditions alone
    assert res["participants"]["n_retained"] == plain["participants"]["n_retained"] == 24
    assert res["h1"] == plain["h1"]
    saved = json.loads((tmp_path / "out" / "results.json").read_text())
    assert saved["closed_loop"]["participants"]["closed_loop"] == 2
    md = (tmp_path / "out" / "report.md").read_text()
    assert f"## {CL.SECTION}" in md and "| closed_loop | low | 2 | 1.000" in md
    assert CL.SECTION in (tmp_path / "out" / "report.html").read_text()


def test_every_session_is_counted(tmp_path: Path) -> None:
    res = analyze(_with_closed_loop(tmp_path / "ex"), tmp_path / "out",
                  AnalysisConfig(figures=False), progress=False)
    assert res["participants"]["n_sessions"] == 26  # 24 of the paper's conditions + 2
    assert res["participants"]["n_closed_loop"] == 2
    md = (tmp_path / "out" / "report.md").read_text()
    assert "26 sessions in the export (2 closed_loop, compared in their own section" in md


def test_closed_loop_only_export_gets_its_section(tmp_path: Path) -> None:
    from cfteach.cli import app
    from cli_runner import WideRunner

    ex = _with_closed_loop(tmp_path / "ex")
    for name in CL.CONDITION_FILES:
        df = pd.read_csv(ex / name, dtype=str, keep_default_na=False)
        df[df["condition"] == "closed_loop"].to_csv(ex / name, index=False)
    out = tmp_path / "out"
    result = WideRunner().invoke(app, ["analyze", str(ex), "--out", str(out), "--no-figures"])
    assert result.exit_code == 0, result.output
    assert "header but no rows" not in result.output
    res = json.loads((out / "results.json").read_text())
    assert res["participants"]["n_sessions"] == 2
    assert "only closed_loop sessions (2)" in res["paper_analysis"]["skipped"]
    assert res["closed_loop"]["participants"] == {"closed_loop": 2}
    by = {(r["condition"], r["difficulty"]): r for r in res["closed_loop"]["by_difficulty"]}
    assert by["closed_loop", "medium"]["regret"]["mean"] == pytest.approx(1.5)
    md = (out / "report.md").read_text()
    assert "2 sessions in the export, all closed_loop" in md
    assert f"## {CL.SECTION}" in md and "| closed_loop | low | 2 | 1.000" in md
