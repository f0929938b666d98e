"""`cfteach domains` lists the built-in domains and checks user files."""

from __future__ import annotations

import json
from pathlib import Path

from cfteach.cli import app
from cli_runner import WideRunner


def test_domains_table() -> None:
    res = WideRunner().invoke(app, ["domains"])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert lines[0].split()[0] == "domain"
    rows = {ln.split()[0]: ln.split() for ln in lines[2:]}
    assert rows["delivery"][-2:] == ["64", "9312"]
    assert rows["tiles"][-2:] == ["512", "12288"]
    assert rows["skateboard"][-2:] == ["8", "1964"]


def test_domains_json() -> None:
    res = WideRunner().invoke(app, ["domains", "--json"])
    assert res.exit_code == 0, res.output
    data = {d["name"]: d for d in json.loads(res.output)}
    assert list(data) == ["delivery", "tiles", "skateboard"]
    assert data["delivery"]["feature_names"] == ["toll", "hotswap", "step"]
    assert abs(sum(w * w for w in data["tiles"]["weights"]) - 1) < 1e-12
    assert data["skateboard"]["weights_raw"] == [-0.175, -0.5125, -1.0]
    assert (data["skateboard"]["instances"], data["skateboard"]["demonstrations"]) == (8, 1964)


def test_domains_user_file_and_errors(tmp_path: Path) -> None:
    src = Path(__file__).resolve().parents[1] / "src/cfteach/domains/data/tiles.toml"
    good = tmp_path / "mine.toml"
    good.write_text(src.read_text().replace('name = "tiles"', 'name = "mine"'))
    res = WideRunner().invoke(app, ["domains", str(good), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)[0]["name"] == "mine"
    bad = tmp_path / "bad.toml"
    bad.write_text(src.read_text().replace("[agent]\nstart = [1, 1]", "[agent]\nstart = [9, 1]"))
    res = WideRunner().invoke(app, ["domains", str(bad)])
    assert res.exit_code == 2
    assert f"{bad}: agent.start" in res.output and "off the 5x5 grid" in res.output
