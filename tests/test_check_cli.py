"""`cfteach check`: sizes and estimates before any planning, every error listed, exit 1."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from typer.testing import CliRunner

from cfteach.cli import app

DOCS = Path(__file__).resolve().parents[1] / "docs" / "domains.md"


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


def test_check_skips_planning_of_a_domain_too_big_for_memory(monkeypatch) -> None:
    monkeypatch.setattr("cfteach.domains.size.available_memory", lambda: 1e6)
    res = CliRunner().invoke(app, ["check", "random:30x30:f3:n512:s0"])
    assert res.exit_code == 0, res.output
    out = " ".join(res.stdout.split())
    assert "instances: 512" in out and "about" in out
    assert "make the domain smaller: fewer variant bits (9 bits = 512 instances" in out
    assert "planning checks skipped" in out


def test_no_traceback_reaches_the_user_from_the_console_script(tmp_path: Path) -> None:
    # An unexpected failure inside a command becomes one line (CFTEACH_DEBUG shows it all).
    code = ("import cfteach.cli as c, sys\n"
            "import cfteach.domains.check as k\n"
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
