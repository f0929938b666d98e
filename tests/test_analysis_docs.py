"""The examples in docs/analysis.md run (python blocks as code, bash blocks through the CLI)."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import pytest

from cfteach.cli import app
from cli_runner import WideRunner
from doc_examples import code_blocks

DOC = Path(__file__).resolve().parents[1] / "docs" / "analysis.md"
EXAMPLE = DOC.parent / "examples" / "analysis-synthetic-216"


def _blocks(lang: str) -> list[str]:
    return code_blocks("analysis.md", lang)


@pytest.mark.slow
def test_bash_examples_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    runner = WideRunner()
    commands = [ln for b in _blocks("bash") for ln in b.splitlines() if ln.startswith("cfteach")]
    # the command that regenerates the committed example is checked below, without figures
    commands = [c for c in commands if "docs/examples" not in c]
    assert len(commands) >= 3
    for cmd in commands:
        args = shlex.split(cmd)[1:]
        result = runner.invoke(app, args)
        assert result.exit_code == 0, f"{cmd}\n{result.output}"
    assert (tmp_path / "demo-report" / "report.html").exists()


def _close(a: object, b: object) -> bool:
    """Equal JSON, floats within 1e-4 relative or 1e-9 absolute: a difference between library
    versions (pandas, numpy: 1 ulp; the GLMM's optimiser: up to 6e-6 relative, and tiny p
    values such as 1e-68) is no change of the example; other data or settings are."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) or isinstance(b, float):
        if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
            return a == b
        return a == pytest.approx(b, rel=1e-4, abs=1e-9, nan_ok=True)
    return a == b


def test_close_tolerates_one_ulp_only() -> None:
    import math

    x = 0.1 + 0.2
    assert _close({"a": [x, "s", None, 3]}, {"a": [math.nextafter(x, 1.0), "s", None, 3]})
    assert _close({"se": 0.11959638550925362}, {"se": 0.11959638308278775})  # GLMM, seen
    assert _close({"p": 1.8431029220536874e-68}, {"p": 1.8423636128234012e-68})
    assert not _close({"a": [x]}, {"a": [x * (1 + 1e-3)]})
    assert not _close({"a": 1.0}, {"a": None})
    assert not _close({"a": "x"}, {"a": "y"})


@pytest.mark.slow
def test_committed_example_is_up_to_date(tmp_path: Path) -> None:
    """Regenerating the example from its seed gives the committed numbers."""
    committed = json.loads((EXAMPLE / "results.json").read_text(encoding="utf-8"))
    cmd = next(ln for b in _blocks("bash") for ln in b.splitlines() if "docs/examples" in ln)
    args = shlex.split(cmd)[1:]
    args[args.index("--out") + 1] = str(tmp_path)
    result = WideRunner().invoke(app, [*args, "--no-figures"])
    assert result.exit_code == 0, result.output
    fresh = json.loads((tmp_path / "results.json").read_text(encoding="utf-8"))
    for key in (
        "participants",
        "exclusions",
        "descriptives",
        "icc",
        "h1",
        "full_anova",
        "full_anova_participants",
        "glmm",
        "ordinal",
        "sensitivity",
        "mixed",
        "likert",
        "exploratory",
    ):
        assert _close(fresh[key], committed[key]), key
    assert set(committed["figures"]) == {
        "difficulty",
        "interaction",
        "paper_bars",
        "likert",
        "confidence",
        "exploratory",
    }
    for files in committed["figures"].values():
        for f in files:
            assert (EXAMPLE / f).exists()


def _differences(a: object, b: object, path: str, tol: float) -> list[str]:
    """Where two JSON values differ: structure and strings exactly, numbers to `tol`
    (relative, and absolute near 0)."""
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            return [f"{path}: keys {sorted(set(a) ^ set(b))}"]
        return [d for k in a for d in _differences(a[k], b[k], f"{path}.{k}", tol)]
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: length {len(a)} vs {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in _differences(x, y, f"{path}[{i}]", tol)]
    num = (int, float)
    if isinstance(a, num) and isinstance(b, num) and not isinstance(a, bool):
        return [] if a == pytest.approx(b, rel=tol, abs=tol) else [f"{path}: {a} vs {b}"]
    return [] if a == b else [f"{path}: {a!r} vs {b!r}"]


def test_python_examples_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    blocks = _blocks("python")
    assert blocks
    for code in blocks:
        exec(compile(code, str(DOC), "exec"), {})
    assert (tmp_path / "api-demo" / "report" / "results.json").exists()
