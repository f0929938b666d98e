"""The Python example in docs/study.md runs as written, and the CLI commands work."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

from cfteach.cli import app
from cli_runner import WideRunner
from doc_examples import code_blocks, run_script


def test_doc_example_runs(tmp_path: Path) -> None:
    blocks = code_blocks("study.md")
    assert blocks
    done = run_script("\n".join(blocks), tmp_path)
    assert "cc=C1A2B3C4" in done.stdout


def test_cli_init_progress_export(tmp_path: Path) -> None:
    runner = WideRunner()
    study = tmp_path / "study"
    r = runner.invoke(app, ["study", "init", "--toy", "--out", str(study)])
    assert r.exit_code == 0, r.output
    assert (study / "study.json").exists()
    db = f"sqlite:///{tmp_path / 'x.db'}"
    r = runner.invoke(app, ["study", "progress", "--study", str(study), "--db", db])
    assert r.exit_code == 0, r.output
    assert r.output.count("occupied 0") == 72
    r = runner.invoke(app, ["study", "export", "--db", db, "--out", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    with open(tmp_path / "out" / "participants.csv", encoding="utf-8") as f:
        assert next(csv.reader(f))[0] == "participant_id"
    r = runner.invoke(app, ["study", "init", "--out", str(tmp_path / "bad"), "--from",
                            str(tmp_path / "missing")])
    assert r.exit_code != 0 and "does not exist" in r.output


def test_init_rejects_bad_inputs_with_clear_errors(tmp_path: Path) -> None:
    import pytest

    from cfteach.study.build import init_study, toy_sources

    src = toy_sources()
    del src[0].curricula["proposed"]
    with pytest.raises(ValueError, match="toy_a.*no curriculum for condition.*proposed"):
        init_study(tmp_path, src)
    src = toy_sources()
    src[1].tests["tests"]["low"][0]["optimal_reward"] = 99.0
    with pytest.raises(ValueError, match=r"toy_b/tests low\[0\].*not optimal_reward 99"):
        init_study(tmp_path, src)
    src = toy_sources()
    src[2].tests["schema"] = "something/9"
    with pytest.raises(ValueError, match="expected schema 'cfteach.tests/1'"):
        init_study(tmp_path, src)


def test_cli_init_from_reproduce_layout(tmp_path: Path) -> None:
    """`study init --from DIR` reads DIR/<domain>/<condition>.json and DIR/<domain>/tests.json
    (the layout `cfteach reproduce --out DIR` writes) for the real domains."""
    import json

    from cfteach.study.build import preview_sources
    from cfteach.study.config import load_study

    src_dir = tmp_path / "results"
    for src in preview_sources(seed=1):
        folder = src_dir / src.domain.name
        folder.mkdir(parents=True)
        for cond, cur in src.curricula.items():
            (folder / f"{cond}.json").write_text(json.dumps(cur))
        (folder / "tests.json").write_text(json.dumps(src.tests))
    r = WideRunner().invoke(app, ["study", "init", "--from", str(src_dir), "--out",
                                 str(tmp_path / "study"), "--completion-code", "ABC123"])
    assert r.exit_code == 0, r.output
    study = load_study(tmp_path / "study")
    assert study["domains"] == ["delivery", "tiles", "skateboard"]
    assert study["completion"]["completed"] == "ABC123"
    assert study["domain_info"]["tiles"]["keys"] == ["up", "down", "left", "right"]
    (src_dir / "tiles" / "proposed.json").unlink()
    r = WideRunner().invoke(app, ["study", "init", "--from", str(src_dir), "--out",
                                 str(tmp_path / "study2")])
    assert r.exit_code != 0 and "proposed.json" in r.output


def test_cfteach_serve_starts_and_migrates(tmp_path: Path) -> None:
    import time

    import httpx

    from cfteach.study.build import init_study, toy_sources
    from cfteach.study.livesrv import free_port

    init_study(tmp_path / "study", toy_sources())
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-c", "from cfteach.cli import main; main()", "serve", "--study",
         str(tmp_path / "study"), "--port", str(port), "--researcher-token", "tok"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        base = f"http://127.0.0.1:{port}"
        for _ in range(150):
            try:
                if httpx.get(base + "/", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
        else:
            raise AssertionError("server did not start")
        r = httpx.get(base + "/api/researcher/progress", headers={"X-Researcher-Token": "tok"})
        assert r.status_code == 200 and len(r.json()["cells"]) == 72
        assert (tmp_path / "study" / "study.db").exists()  # default SQLite file, migrated
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=20)
    assert "researcher page: http://127.0.0.1:" in err


def test_cli_init_consent_file(tmp_path: Path) -> None:
    from cfteach.study.config import load_study

    good = tmp_path / "consent.html"
    good.write_text("<p>Our consent text.</p>", encoding="utf-8")
    r = WideRunner().invoke(app, ["study", "init", "--toy", "--out", str(tmp_path / "s"),
                                 "--consent", str(good)])
    assert r.exit_code == 0, r.output
    assert load_study(tmp_path / "s")["consent_html"] == "<p>Our consent text.</p>"
    bad = tmp_path / "bad.html"
    bad.write_text("<p>x</p><SCRIPT>alert(1)</script>", encoding="utf-8")
    r = WideRunner().invoke(app, ["study", "init", "--toy", "--out", str(tmp_path / "t"),
                                 "--consent", str(bad)])
    assert r.exit_code != 0 and "may not contain <script>" in r.output
