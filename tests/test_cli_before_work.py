"""Errors before work: an output path that cannot be written, a server port or database URL
that cannot work, are one line each before anything is computed, started or printed; and
"own code" in an unexpected error is the installed package, wherever the clone lives."""

from __future__ import annotations

import socket
import tomllib
from pathlib import Path

import pytest

from cfteach.cli import app
from cli_runner import WideRunner

ROOT = Path(__file__).resolve().parents[1]
NOWHERE = "/proc/nope"  # exists nowhere, and not even root can create it


def _no_work(*_a, **_k):  # noqa: ANN002, ANN003, ANN202
    raise AssertionError("the work started before the output was checked")


def _one_error(res, *words: str) -> None:  # noqa: ANN001
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("Error:")]
    assert res.exit_code == 2, res.output
    assert len(errors) == 1, res.output
    for w in words:
        assert w in errors[0], res.output
    assert "Traceback" not in res.output and "please report" not in res.output


@pytest.mark.parametrize("args", [
    ["simulate", "--domain", "skateboard", "--learners", "2", "--out", f"{NOWHERE}/s"],
    ["teach", "skateboard", "--out", f"{NOWHERE}/c.json"],
    ["tests", "skateboard", "--out", f"{NOWHERE}/t.json"],
    ["reproduce", "--domain", "skateboard", "--out", f"{NOWHERE}/r"],
    ["power", "--n", "24", "--sims", "1", "--out", f"{NOWHERE}/p"],
    ["analyze", "--synthetic", "24", "--out", f"{NOWHERE}/a"],
    ["study", "init", "--toy", "--out", f"{NOWHERE}/st"],
    ["study", "screenshots", "--out", f"{NOWHERE}/png"],
    ["export", "minari", "demos", "skateboard", "--root", f"{NOWHERE}/m"],
    ["render", "belief", "x.json", "--out", f"{NOWHERE}/b.png"],
])
def test_an_output_that_cannot_be_written_stops_before_any_work(
        args: list[str], monkeypatch: pytest.MonkeyPatch) -> None:
    for target in ("cfteach.simulate.sweep.run_sweep", "cfteach.teaching.teach",
                   "cfteach.teaching.select_tests", "cfteach.report.reproduce.reproduce",
                   "cfteach.analysis.power.power_curve", "cfteach.analysis.generate",
                   "cfteach.study.build.toy_sources", "cfteach.ecosystem.candidate_episodes",
                   "cfteach.study.screenshots.take_screenshots"):
        monkeypatch.setattr(target, _no_work)
    _one_error(WideRunner().invoke(app, args), NOWHERE, "cannot write into /proc")


@pytest.fixture
def study_dir(tmp_path: Path) -> Path:
    (tmp_path / "study.json").write_text("{}")  # never read: every check comes first
    return tmp_path


def _serve(study: Path, *args: str, monkeypatch: pytest.MonkeyPatch):  # noqa: ANN202
    monkeypatch.setattr("cfteach.study.server.create_app", _no_work)
    return WideRunner().invoke(app, ["serve", "--study", str(study), *args])


def test_serve_names_a_port_in_use_before_printing_anything(
        study_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        res = _serve(study_dir, "--port", str(port), monkeypatch=monkeypatch)
    _one_error(res, f"--port {port}", "in use")
    assert "researcher page" not in res.output


@pytest.mark.parametrize(("args", "words"), [
    (["--port", "99999"], ["--port 99999", "1 to 65535"]),
    (["--db", "sqlite:///missing-folder/x.db"], ["the folder missing-folder does not exist"]),
    (["--db", "mysql://u@h/db"], ["'mysql' databases are not supported"]),
    (["--db", "not a url"], ["is not a database URL"]),
])
def test_serve_checks_port_and_database_first(study_dir: Path, args: list[str],
                                              words: list[str],
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    res = _serve(study_dir, *args, monkeypatch=monkeypatch)
    _one_error(res, *words)
    assert "researcher page" not in res.output


def test_study_export_and_progress_check_the_database_url(study_dir: Path,
                                                          tmp_path: Path) -> None:
    res = WideRunner().invoke(app, ["study", "export", "--db", "mysql://u@h/db",
                                    "--out", str(tmp_path / "x")])
    _one_error(res, "'mysql' databases are not supported")
    res = WideRunner().invoke(app, ["study", "progress", "--study", str(study_dir),
                                    "--db", "mysql://u@h/db"])
    _one_error(res, "'mysql' databases are not supported")


def test_own_code_is_the_installed_package_not_any_cfteach_folder(tmp_path: Path) -> None:
    from cfteach.cli.analyze_cmd import unexpected_error

    clone = tmp_path / "cfteach" / "tests"
    clone.mkdir(parents=True)
    script = clone / "test_user.py"
    script.write_text("def boom():\n    raise KeyError('difficulty')\n")
    namespace: dict = {}
    exec(compile(script.read_text(), str(script), "exec"), namespace)  # noqa: S102
    try:
        namespace["boom"]()
    except KeyError as exc:
        line = unexpected_error(exc, "analysis")
    assert "test_user.py" not in line and " in " not in line.split(":")[0]
    from cfteach.analysis import pipeline

    with pytest.raises(ValueError) as info:
        pipeline.AnalysisConfig(padjust="nope")
    assert "in pipeline.py:" in unexpected_error(info.value, "analysis")


def test_all_extra_installs_every_optional_feature() -> None:
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    optional = sorted(set(extras) - {"all", "dev"})
    assert optional == ["dask", "postgres", "ray", "rl"]
    (spec,) = extras["all"]
    assert spec.startswith("cfteach[") and sorted(spec[8:-1].split(",")) == optional


def test_ci_runs_the_readme_test_command_from_a_folder_named_cfteach() -> None:
    ci = (ROOT / ".ci" / "run").read_text()
    readme = (ROOT / "README.md").read_text()
    assert "bash scripts/test" in readme
    assert '"$work/cfteach"' in ci and "cd \"$work/cfteach\"" in ci
    assert "env -u COLUMNS bash scripts/test" in ci
    assert "COLUMNS=40" in ci
