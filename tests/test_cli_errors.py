"""Every command, fed a table of bad inputs, stops before any work with one line
``Error: ...`` naming the problem on stderr, a non-zero exit status, and no traceback."""

from __future__ import annotations

import json
import re
import sqlite3
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cfteach.cli import app

DOCS = Path(__file__).resolve().parents[1] / "docs" / "domains.md"


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bad")
    example = re.search(r"<!-- example-domain -->\s*```toml\n(.*?)```", DOCS.read_text(),
                        re.S).group(1)
    walled = d / "walled.toml"
    walled.write_text(example.replace("walls = [[3, 2], [3, 3]]",
                                      "walls = [[3, 1], [3, 2], [3, 3]]"))
    (d / "a_file").write_text("x")
    (d / "bad.json").write_text("{not json")
    tiles = d / "tiles_proposed.json"
    tiles.write_text(json.dumps({"schema": "cfteach.curriculum/1", "domain": "tiles",
                                 "demos": [{"env_index": 600, "states": []}]}))
    busy = d / "busy_study"
    busy.mkdir()
    with sqlite3.connect(busy / "study.db") as con:
        con.execute("CREATE TABLE sessions (id INTEGER PRIMARY KEY)")
        con.execute("INSERT INTO sessions (id) VALUES (1)")
    return {"dir": d, "walled": walled, "file": d / "a_file", "bad_json": d / "bad.json",
            "tiles": tiles, "busy": busy}


# (arguments, a piece of the expected error line); {name} is replaced by the files above.
CASES = [
    (["teach", "delivry"], "did you mean 'delivery'"),
    (["teach", "delivery", "-c", "propsed"], "did you mean 'proposed'"),
    (["teach", "delivery", "--profile", "refrence"], "did you mean 'reference'"),
    (["teach", "delivery", "--max-demos", "0"], "--max-demos must be at least 1"),
    (["teach", "delivery", "--human-models", "0"], "--human-models must be at least 1"),
    (["teach", "delivery", "--proportion", "1.5"], "--proportion must lie in (0, 1]"),
    (["teach", "delivery", "-o", "{dir}"], "is a directory"),
    (["teach", "delivery", "-o", "{file}/x.json"], "cannot write into"),
    (["teach", "{walled}"], "cannot be reached from the start"),
    (["teach", "random:5x5:f2:n4:s0"], "at least 3"),
    (["teach", "random:5x5"], "random:WxH:fF:nN:sS"),
    (["teach", "{dir}"], "is a directory, not a domain file"),
    (["teach"], "Missing argument"),
    (["teach", "delivery", "--bogus"], "No such option"),
    (["tests", "delivery", "--per-level", "0"], "--per-level must be at least 1"),
    (["tests", "delivery", "-t", "{dir}/missing.json"], "--training"),
    (["tests", "delivery", "-t", "{bad_json}"], "not JSON"),
    (["tests", "{walled}"], "cannot be reached"),
    (["domains", "nope.toml"], "neither a built-in domain"),
    (["domains", "random:5x5:f2:n4:s0"], "at least 3"),
    (["check", "delivry"], "did you mean 'delivery'"),
    (["reproduce", "-d", "random:5x5:f4:n4:s0", "-o", "{dir}/r"], "need exactly 3"),
    (["reproduce", "-o", "{file}"], "is a file, not a directory"),
    (["reproduce", "-d", "{walled}", "-o", "{dir}/r"], "cannot be reached"),
    (["reproduce", "--profile", "refrence", "-o", "{dir}/r"], "did you mean"),
    (["render", "state", "delivery", "0101"], "has 4 bits; delivery instances have 6"),
    (["render", "state", "delivery", "000000", "--state", "x"], "is not JSON"),
    (["render", "state", "delivery", "0", "-o", "{dir}/x.gif"], ".svg, .png or .txt"),
    (["render", "state", "delivery", "000000", "--state", '{"agent": [9, 9]}'], "state keys"),
    (["render", "demos", "{tiles}", "--domain", "delivery", "-o", "{dir}/d"],
     "holds 'tiles' demonstrations"),
    (["render", "demos", "{tiles}", "-o", "{dir}/d"], "instance index 600 out of range"),
    (["render", "demos", "{dir}/missing.json"], "missing.json"),
    (["render", "demos", "{tiles}", "-f", "bmp"], "unknown format"),
    (["render", "belief", "{bad_json}"], "not valid JSON"),
    (["study", "export", "--db", "sqlite:///{dir}/typo.db", "--out", "{dir}/e"],
     "export never creates one"),
    (["study", "export", "--db", "nonsense", "--out", "{dir}/e"], "not a database URL"),
    (["study", "init", "--toy", "--out", "{busy}"], "holds 1 session"),
    (["study", "progress", "--study", "{dir}/nostudy"], "no study at"),
    (["serve", "--study", "{dir}/nostudy"], "no study at"),
    (["simulate", "-d", "delivry", "-o", "{dir}/s"], "did you mean 'delivery'"),
    (["analyze", "{dir}/missing"], "does not exist"),
    (["analyze", "--synthetic", "10", "-o", "{file}"], "is a file, not a directory"),
    (["simulate", "-d", "skateboard", "-o", "{file}"], "is a file, not a directory"),
    (["simulate", "-d", "{walled}", "-o", "{dir}/s"], "cannot be reached"),
    (["study", "init", "--domains", "delivery,{walled}", "--out", "{dir}/st"],
     "cannot be reached"),
    (["no-such-command"], "No such command"),
]


@pytest.mark.parametrize("columns", [None, "40"])
@pytest.mark.parametrize(("args", "expected"), CASES, ids=[" ".join(c[0]) for c in CASES])
def test_bad_input_gives_one_error_line(files: dict[str, Path], args: list[str], expected: str,
                                        columns: str | None, monkeypatch) -> None:
    if columns is None:
        monkeypatch.delenv("COLUMNS", raising=False)
    else:
        monkeypatch.setenv("COLUMNS", columns)
    argv = [a.format(**files) if "{" in a and '"' not in a else a for a in args]
    result = CliRunner().invoke(app, argv)
    assert result.exception is None or isinstance(result.exception, SystemExit), \
        repr(result.exception)
    assert result.exit_code != 0
    err = result.stderr
    assert "Traceback" not in result.output + err
    error_lines = [line for line in err.splitlines() if line.startswith("Error")]
    assert len(error_lines) == 1, err
    assert expected in " ".join(err.split()), err


def test_export_never_creates_a_database(files: dict[str, Path]) -> None:
    CliRunner().invoke(app, ["study", "export", "--db", f"sqlite:///{files['dir']}/t.db",
                             "--out", str(files["dir"] / "e2")])
    assert not (files["dir"] / "t.db").exists()
    assert not (files["dir"] / "e2").exists()


def test_study_init_with_force_replaces_the_study(files: dict[str, Path]) -> None:
    res = CliRunner().invoke(app, ["study", "init", "--toy", "--out", str(files["busy"]),
                                   "--force"])
    assert res.exit_code == 0, res.output
    assert (files["busy"] / "study.json").is_file()


def test_too_big_for_memory_is_refused_unless_forced(monkeypatch, tmp_path: Path) -> None:
    monkeypatch.setattr("cfteach.domains.size.available_memory", lambda: 1e6)
    res = CliRunner().invoke(app, ["teach", "skateboard", "-o", str(tmp_path / "c.json")])
    assert res.exit_code == 2
    assert "of memory" in res.stderr and "--force" in res.stderr
    assert "make the domain smaller" in res.stderr
    assert not (tmp_path / "c.json").exists()
    res = CliRunner().invoke(app, ["teach", "skateboard", "--force", "--max-demos", "1",
                                   "-o", str(tmp_path / "c.json")])
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "c.json").read_text())["domain"] == "skateboard"


def test_version_and_short_help() -> None:
    from cfteach import __version__

    res = CliRunner().invoke(app, ["--version"])
    assert res.exit_code == 0 and res.stdout.strip() == f"cfteach {__version__}"
    res = CliRunner().invoke(app, ["teach", "-h"])
    assert res.exit_code == 0 and "--max-demos" in res.stdout


@pytest.mark.parametrize("columns", ["40", "200"])
def test_help_never_cuts_an_option_or_a_summary(monkeypatch, columns: str) -> None:
    monkeypatch.setenv("COLUMNS", columns)
    for argv in (["-h"], ["study", "-h"], ["render", "-h"], ["teach", "-h"], ["tests", "-h"]):
        out = CliRunner().invoke(app, argv).stdout
        body = [ln for ln in out.splitlines() if not ln.startswith("Usage:")]
        text = "\n".join(body).replace("=...", "")
        assert "\u2026" not in text and "..." not in text, out
    out = " ".join(CliRunner().invoke(app, ["teach", "-h"]).stdout.split())
    assert "--unbounded-models" in out and "--human-models" in out
