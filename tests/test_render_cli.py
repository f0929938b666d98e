"""`cfteach render ...` commands: outputs land where asked, bad input gets a clear error."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

from PIL import Image

from cfteach.cli import app
from cli_runner import WideRunner

runner = WideRunner()


def test_state_prints_text_and_writes_pictures(tmp_path):
    result = runner.invoke(app, ["render", "state", "delivery", "000011"])
    assert result.exit_code == 0, result.output
    # b4: mud at (3, 1); b5: station at (4, 3); agent (2, 1), package (4, 2)
    assert "|#  h|\n|#  p|\n|d@~ |" in result.output
    svg = tmp_path / "s.svg"
    state = '{"agent": [2, 2], "skateboard": [2, 2], "carrying": true}'
    result = runner.invoke(
        app, ["render", "state", "skateboard", "7", "--state", state, "-o", str(svg)]
    )
    assert result.exit_code == 0, result.output
    agent = [e for e in ET.parse(svg).getroot().iter() if e.get("data-role") == "agent"]
    assert [a.get("data-cell") for a in agent] == ["2,2"]


def test_state_errors_are_named():
    result = runner.invoke(app, ["render", "state", "skateboard", "9"])
    assert result.exit_code == 2 and "instance index 9 out of range" in result.output
    result = runner.invoke(app, ["render", "state", "skateboard", "0x1"])
    assert result.exit_code == 2 and "give 3 bits" in result.output
    bad = '{"agent": [9, 9], "skateboard": null, "carrying": false}'
    result = runner.invoke(app, ["render", "state", "skateboard", "000", "--state", bad])
    assert result.exit_code == 2 and "Error" in result.output


def test_demos_and_belief_from_json_files(tmp_path):
    from test_report import make_results

    res = make_results()["skateboard"]
    cur = tmp_path / "proposed.json"
    cur.write_text(json.dumps(res["curricula"]["proposed"]))
    tests = tmp_path / "tests.json"
    tests.write_text(json.dumps(res["tests"]))
    out = tmp_path / "demos"
    result = runner.invoke(app, ["render", "demos", str(cur), "-o", str(out), "-f", "gif"])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == ["demo1.gif", "demo2.gif"]
    with Image.open(out / "demo2.gif") as im:
        assert im.n_frames == len(res["curricula"]["proposed"]["demos"][1]["states"])
    result = runner.invoke(app, ["render", "demos", str(tests), "-o", str(out), "-f", "txt"])
    assert result.exit_code == 0, result.output
    assert (out / "high-1.txt").read_text().count("@") == 1
    png = tmp_path / "b.png"
    result = runner.invoke(app, ["render", "belief", str(cur), "--demo", "1", "-o", str(png)])
    assert result.exit_code == 0, result.output
    assert Image.open(png).size[0] > 200
    result = runner.invoke(app, ["render", "belief", str(cur), "--demo", "5"])
    assert result.exit_code == 2 and "has 2 demonstrations" in result.output
    (tmp_path / "x.json").write_text("[1, 2]")
    result = runner.invoke(app, ["render", "demos", str(tmp_path / "x.json")])
    assert result.exit_code == 2 and "'schema' key" in result.output
    result = runner.invoke(app, ["render", "demos", str(cur), "-f", "bmp"])
    assert result.exit_code == 2 and "unknown format 'bmp'" in result.output
