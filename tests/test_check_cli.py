"""`cfteach check`: sizes and estimates before any planning, every error listed, exit 1."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cfteach.cli import app

DOCS = Path(__file__).resolve().parents[1] / "docs" / "domains.md"
TAXI = Path(__file__).resolve().parents[1] / "examples" / "domains" / "augmented_taxi_2021.toml"


def _example() -> str:
    return re.search(r"<!-- example-domain -->\s*```toml\n(.*?)```", DOCS.read_text(),
                     re.S).group(1)


def test_check_prints_sizes_and_ok_for_a_good_domain() -> None:
    res = CliRunner().invoke(app, ["check", "skateboard"])
    assert res.exit_code == 0, res.output
    out = " ".join(res.stdout.split())
    assert "instances: 8" in out
    assert "demonstrations (candidates): 1964" in out  # exact (8 instances)
    assert re.search(r"teach \(one condition\), estimate: .* peak memory [\d.]+ [MG]B", out)
    assert out.endswith("ok")


def test_check_lists_every_error_and_exits_1(tmp_path: Path) -> None:
    path = tmp_path / "walled.toml"
    path.write_text(_example().replace("walls = [[3, 2], [3, 3]]",
                                       "walls = [[3, 1], [3, 2], [3, 3]]"))
    res = CliRunner().invoke(app, ["check", str(path), "delivery"])
    assert res.exit_code == 1
    errs = [ln for ln in res.stderr.splitlines() if ln.strip().startswith("error:")]
    assert len(errs) == 4 and all("cannot be reached" in e for e in errs)
    assert "Error: corridor: 4 error(s)" in res.stderr
    assert "delivery" in res.stdout  # the next domain is still checked


def test_check_refuses_a_domain_too_big_for_memory_unless_forced(monkeypatch) -> None:
    monkeypatch.setattr("cfteach.domains.size.available_memory", lambda: 1e6)
    res = CliRunner().invoke(app, ["check", "random:30x30:f3:n512:s0"])
    assert res.exit_code == 1, res.output
    out = " ".join(res.stdout.split())
    assert "instances: 512" in out and "about" in out
    assert "checks run: (not the planning checks)" in out
    err = " ".join(res.stderr.split())
    assert "make the domain smaller: fewer variant bits (9 bits = 512 instances" in err
    assert "or pass --force" in err and not out.endswith("ok")


def _peak(name: str) -> int:
    from cfteach import domains
    from cfteach.domains.size import estimate_size

    return estimate_size(domains.load(name)).teach_peak_bytes


@pytest.mark.parametrize(("free_per_peak", "code", "words"), [
    (1.5, 0, ["warning: teaching needs about", "more than half of the free memory"]),
    (0.5, 1, ["error: teaching needs about", "or pass --force"]),
    (3.0, 0, []),
])
def test_check_warns_above_half_the_free_memory_and_refuses_above_it(
        monkeypatch, free_per_peak: float, code: int, words: list[str]) -> None:
    free = _peak("skateboard") * free_per_peak
    monkeypatch.setattr("cfteach.domains.size.available_memory", lambda: free)
    res = CliRunner().invoke(app, ["check", "skateboard"])
    assert res.exit_code == code, res.output
    for w in words:
        assert w in " ".join(res.output.split())
    if not words:
        assert "warning:" not in res.output and "error:" not in res.output
    if code:  # --force runs the planning checks anyway
        res = CliRunner().invoke(app, ["check", "skateboard", "--force"])
        assert res.exit_code == 0 and "passed: no reward loop that w* pays for" in res.stdout


def test_check_prints_the_checks_it_ran() -> None:
    from cfteach.domains.check import CHECKS

    res = CliRunner().invoke(app, ["check", "skateboard"])
    assert res.exit_code == 0, res.output
    lines = [ln.strip() for ln in res.stdout.splitlines()]
    ran = lines[lines.index("checks run:") + 1:][: len(CHECKS)]
    assert ran == [f"passed: {text}" for _, text, _ in CHECKS]


def _taxi(tmp_path: Path, old: str, new: str) -> Path:
    text = TAXI.read_text()
    assert old in text
    path = tmp_path / "taxi.toml"
    path.write_text(text.replace(old, new))
    return path


def test_check_warns_per_instance_when_no_optimal_path_reaches_the_goal(tmp_path) -> None:
    # Delivering is worth 1, walking there costs more: a free `exit` at the start beats it.
    path = _taxi(tmp_path, "weight = 26", "weight = 1")
    res = CliRunner().invoke(app, ["check", str(path)])
    assert res.exit_code == 0, res.output
    warns = [ln for ln in res.stdout.splitlines() if "no optimal path under w* reaches" in ln]
    assert len(warns) == 256  # one per instance
    assert "warning: some optimal path under w* reaches the goal" in res.stdout
    assert res.stdout.rstrip().endswith("ok (256 warning(s))")
    # An independent look: every optimal first move from the start is `exit`.
    from cfteach import domains, mdp

    dom = domains.load(str(path))
    batch = mdp.compile_domain(dom)
    Q = mdp.value_iteration(batch, np.asarray(dom.weights)[None]).Q[:, 0, 0]
    assert (mdp.tied_actions(Q).argmax(axis=1) == list(dom.actions).index("exit")).all()
    assert mdp.tied_actions(Q).sum(axis=1).max() == 1


def test_check_is_quiet_about_a_domain_whose_goal_is_worth_walking_to() -> None:
    res = CliRunner().invoke(app, ["check", str(TAXI)])
    assert res.exit_code == 0, res.output
    assert "no optimal path" not in res.output
    assert "passed: some optimal path under w* reaches the goal" in res.stdout


def test_no_traceback_reaches_the_user_from_the_console_script(tmp_path: Path) -> None:
    # An unexpected failure inside a command becomes one line (CFTEACH_DEBUG shows it all).
    code = ("import cfteach.cli as c, sys\n"
            "import cfteach.mdp.soundness as k\n"
            "def boom(*a, **kw): raise RuntimeError('boom')\n"
            "k.check_domain = boom\n"
            "sys.argv = ['cfteach', 'check', 'skateboard']\n"
            "c.main()\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 1
    assert "Traceback" not in res.stderr
    assert res.stderr.strip().splitlines() == [
        "Error: RuntimeError: boom (an unexpected failure; set CFTEACH_DEBUG=1 to see the "
        "traceback and please report it)"]


def test_domains_lists_a_big_domain_with_an_estimate() -> None:
    import json

    res = CliRunner().invoke(app, ["domains", "--json", "random:30x30:f3:n512:s0", "tiles"])
    assert res.exit_code == 0, res.output
    big, tiles = json.loads(res.stdout)
    assert big["instances"] == 512 and big["demonstrations_exact"] is False
    assert 100_000 < big["demonstrations"] < 1_000_000
    assert (tiles["demonstrations"], tiles["demonstrations_exact"]) == (12288, True)
