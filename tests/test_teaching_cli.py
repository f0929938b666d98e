"""`cfteach teach` and `cfteach tests` through the typer app."""

from __future__ import annotations

import json
from pathlib import Path

from cfteach.cli import app
from cli_runner import WideRunner

runner = WideRunner()


def test_teach_then_tests(tmp_path: Path) -> None:
    cur = tmp_path / "cur.json"
    res = runner.invoke(app, ["teach", "skateboard", "--condition", "proposed", "--profile",
                              "reference", "--max-demos", "2", "--out", str(cur)])
    assert res.exit_code == 0, res.output
    data = json.loads(cur.read_text())
    assert data["schema"] == "cfteach.curriculum/1" and len(data["demos"]) == 2
    assert data["settings"]["max_demos"] == 2
    res = runner.invoke(app, ["tests", "skateboard", "--profile", "reference", "--per-level",
                              "2", "--training", str(cur), "--all"])
    assert res.exit_code == 0, res.output
    tests = json.loads(res.stdout)
    assert tests["schema"] == "cfteach.tests/1"
    assert {k: len(v) for k, v in tests["tests"].items()} == {"low": 2, "medium": 2, "high": 2}
    assert len(tests["excluded"]) == 2
    starts = {(c["env_index"], json.dumps(c["start_state"], sort_keys=True))
              for c in tests["candidates"]}
    for d in data["demos"]:
        assert (d["env_index"], json.dumps(d["start_state"], sort_keys=True)) not in starts


def test_errors_name_the_problem(tmp_path: Path) -> None:
    res = runner.invoke(app, ["teach", "skateboard", "--condition", "bogus"])
    assert res.exit_code == 2 and "bogus" in res.output
    res = runner.invoke(app, ["teach", "skateboard", "--proportion", "2"])
    assert res.exit_code == 2 and "proportion" in res.output
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    res = runner.invoke(app, ["tests", "skateboard", "--training", str(bad)])
    assert res.exit_code == 2 and "bad.json" in res.output


def test_two_workers_write_the_one_process_json(tmp_path: Path) -> None:
    """--workers 2 on teach and tests: the same JSON as one process (4-feature domain)."""
    dom = "random:6x6:f4:n16:s0"
    for cmd in (["teach", dom, "--condition", "proposed"], ["tests", dom, "--per-level", "2"]):
        one = runner.invoke(app, [*cmd, "--out", str(tmp_path / "one.json")])
        two = runner.invoke(app, [*cmd, "--workers", "2", "--out", str(tmp_path / "two.json")])
        assert one.exit_code == 0 and two.exit_code == 0, one.output + two.output
        assert json.loads((tmp_path / "one.json").read_text()) == \
            json.loads((tmp_path / "two.json").read_text())


def test_bad_parallel_options_name_the_problem() -> None:
    for cmd in ("teach", "tests"):
        res = runner.invoke(app, [cmd, "skateboard", "--workers", "0"])
        assert res.exit_code == 2 and "--workers must be at least 1" in res.output
        res = runner.invoke(app, [cmd, "skateboard", "--backend", "sparc"])
        assert res.exit_code == 2 and "--backend: unknown value 'sparc'" in res.output
        res = runner.invoke(app, [cmd, "skateboard", "--scheduler", "tcp://127.0.0.1:1"])
        assert res.exit_code == 2 and "--scheduler needs --backend dask or ray" in res.output
        assert "Traceback" not in res.output
