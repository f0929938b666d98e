"""One command-line grammar (docs/cli.md): how domains, lists, counts, outputs and databases
are named; old spellings still work with a note; every choice option suggests a close match;
help text never cuts a word, at any terminal width."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
import typer
from typer.testing import CliRunner

from cfteach.cli import app
from cfteach.cli._aliases import ALIASES, rewrite
from cli_runner import WideRunner

DOCS = Path(__file__).resolve().parents[1] / "docs" / "cli.md"


def _commands() -> list[tuple[str, Any]]:
    """Every leaf command with its path, e.g. ("export minari demos", cmd)."""
    root = typer.main.get_command(app)
    out: list[tuple[str, Any]] = []

    def walk(cmd: Any, path: str) -> None:  # noqa: ANN401
        subs = getattr(cmd, "commands", None)
        if subs:
            for name, sub in subs.items():
                walk(sub, f"{path} {name}".strip())
        else:
            out.append((path, cmd))

    walk(root, "")
    return out


def _options(cmd: Any) -> list[Any]:  # noqa: ANN401 - click's (or Typer's copy of) Option
    return [p for p in cmd.params if p.param_type_name == "option"]


def test_no_command_keeps_an_old_spelling() -> None:
    old = {"--domains", "--conditions", "--seeds", "--learner"}
    found = [(path, o) for path, cmd in _commands() for p in _options(cmd)
             for o in p.opts if o in old]
    assert found == []


def test_outputs_are_out_or_o_and_force_is_a_flag() -> None:
    for path, cmd in _commands():
        for p in _options(cmd):
            if "--out" in p.opts:
                assert "-o" in p.opts, path
            if "--force" in p.opts:
                assert p.is_flag and not p.secondary_opts, path
            if "--workers" in p.opts:  # one default, said the same way everywhere
                assert "one per independent job, up to every local core" in p.help, path


def test_a_set_of_domains_is_domain_or_d() -> None:
    with_domains = {path for path, cmd in _commands()
                    for p in _options(cmd) if "--domain" in p.opts}
    assert {"reproduce", "simulate", "study init", "export minari answers"} <= with_domains
    for path, cmd in _commands():
        for p in _options(cmd):
            if "--domain" in p.opts and path != "render demos":  # that one overrides a file's
                assert "-d" in p.opts and p.multiple, path


def test_export_demos_takes_the_domain_as_its_argument() -> None:
    cmd = dict(_commands())["export minari demos"]
    args = [p for p in cmd.params if p.param_type_name == "argument"]
    assert [a.name for a in args] == ["domain"]


def test_study_export_finds_the_database_like_serve(tmp_path: Path) -> None:
    res = WideRunner().invoke(app, ["study", "export", "--study", str(tmp_path / "s"),
                                    "--out", str(tmp_path / "x")])
    assert res.exit_code == 2
    assert f"no database file at {tmp_path / 's' / 'study.db'}" in res.output


def test_old_spellings_are_rewritten_with_one_note(capsys: pytest.CaptureFixture) -> None:
    assert rewrite(["simulate", "--domains", "a,b", "--seeds=2", "--domains", "c",
                    "--learner", "irl", "--conditions", "none"]) == [
        "simulate", "--domain", "a,b", "--replications=2", "--domain", "c",
        "--learner-model", "irl", "--condition", "none"]
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 4 and all(ln.startswith("note: `cfteach simulate --") for ln in err)
    assert rewrite(["export", "minari", "demos", "--domain", "tiles", "--root", "r"]) == [
        "export", "minari", "demos", "tiles", "--root", "r"]
    assert rewrite(["export", "minari", "demos", "--domain=tiles"])[-1] == "tiles"
    assert rewrite(["teach", "--domains", "x"]) == ["teach", "--domains", "x"]  # not aliased
    assert rewrite(["simulate", "--", "--domains"]) == ["simulate", "--", "--domains"]


def test_every_old_spelling_is_documented() -> None:
    text = DOCS.read_text(encoding="utf-8")
    for olds in ALIASES.values():
        for old, new in olds.items():
            assert f"`{old}" in text and (not new or f"`{new}`" in text), old


def test_an_old_spelling_reaches_the_command(tmp_path: Path) -> None:
    res = WideRunner().invoke(app, ["simulate", "--domains", "nowhere", "--out",
                                    str(tmp_path)])
    assert res.exit_code == 2
    assert "note: `cfteach simulate --domains` is deprecated; use --domain" in res.output
    assert "nowhere" in res.output.splitlines()[-1]


@pytest.mark.parametrize(("args", "suggestion"), [
    (["simulate", "--condition", "propsed"], "did you mean 'proposed'?"),
    (["simulate", "--conditions", "feature_onyl"], "did you mean 'feature_only'?"),
    (["simulate", "--learner-model", "noisey"], "did you mean 'noisy'?"),
    (["simulate", "--learner", "counterfactal:temperature=1"], "did you mean 'counterfactual'?"),
    (["study", "init", "--condition", "closed_lop"], "did you mean 'closed_loop'?"),
    (["analyze", "--synthetic", "24", "--padjust", "bonferoni"], "did you mean 'bonf'?"),
])
def test_every_choice_option_suggests_a_close_match(args: list[str], suggestion: str,
                                                    tmp_path: Path) -> None:
    res = WideRunner().invoke(app, [*args, "--out", str(tmp_path / "o")])
    assert res.exit_code == 2, res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert len(errors) == 1 and errors[0].endswith(suggestion), res.output
    assert not (tmp_path / "o" / "results.json").exists()


def test_padjust_accepts_bonferroni() -> None:
    from cfteach.cli.analyze_cmd import _padjust

    assert _padjust("bonferroni") == "bonf"
    assert _padjust("Holm") == "holm"


def test_help_never_cuts_a_word_at_40_columns() -> None:
    res = CliRunner().invoke(app, ["study", "init", "--help"], env={"COLUMNS": "40"})
    assert res.exit_code == 0
    assert "https://app.prolific.com/submissions/complete?cc=" in res.output
    for path, cmd in _commands():
        res = CliRunner().invoke(app, [*path.split(), "--help"], env={"COLUMNS": "40"})
        assert res.exit_code == 0, path
        words = set(re.findall(r"[\w-]+", res.output))
        for p in _options(cmd):
            for opt in p.opts:
                if not p.hidden:
                    assert opt in words or opt.lstrip("-") in words, (path, opt)


def test_teach_show_names_the_masked_feature_as_the_legend_does() -> None:
    res = WideRunner().invoke(app, ["teach", "delivery", "--max-demos", "2", "--show", "-q"])
    assert res.exit_code == 0, res.output
    heads = [ln for ln in res.stderr.splitlines() if ln.startswith("demo ")]
    masks = [ln.split("  mask ")[1].split("  actions")[0] for ln in heads]
    assert masks and all(m in ("mud (toll)", "battery (hotswap)", "step", "none")
                         for m in masks), masks
    legend = next(ln for ln in res.stderr.splitlines() if ln.startswith("@ agent"))
    assert "~ mud" in legend  # the word the mask line uses for `toll`
