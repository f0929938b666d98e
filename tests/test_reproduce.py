"""`cfteach reproduce` on the smallest domain (skateboard): JSON that follows docs/schemas.md
(keys and types checked here, independently of the code that writes them; every
demonstration replayed in the domain), and an index.html whose images all resolve."""

from __future__ import annotations

import json
import math
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from cfteach import domains
from cfteach.cli import app
from cli_runner import WideRunner

pytestmark = pytest.mark.slow

CONDITIONS = ["baseline", "feature_only", "counterfactual_only", "proposed"]
ACTIONS = ["up", "down", "left", "right", "pickup", "dropoff"]
SKATE = domains.load("skateboard")
F = 3


def is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def check_cell(v, where):
    assert isinstance(v, list) and len(v) == 2 and all(is_int(c) for c in v), where
    assert 1 <= v[0] <= 6 and 1 <= v[1] <= 4, where


def check_state(s, where):
    """docs/schemas.md: skateboard states are agent, skateboard ([x, y] | null), carrying."""
    assert isinstance(s, dict) and set(s) == {"agent", "skateboard", "carrying"}, (where, s)
    check_cell(s["agent"], f"{where}.agent")
    assert s["skateboard"] is None or check_cell(s["skateboard"], where) is None
    assert isinstance(s["carrying"], bool), where


def check_constraints(rows, where):
    assert isinstance(rows, list), where
    for r in rows:
        assert isinstance(r, list) and len(r) == F and all(is_int(c) for c in r), (where, r)


def check_demo(d, where, weights):
    for key, test in {
        "env_code": lambda v: isinstance(v, list) and len(v) == 3 and set(v) <= {0, 1},
        "env_index": is_int,
        "start_state": lambda v: isinstance(v, dict),
        "actions": lambda v: isinstance(v, list) and all(a in ACTIONS for a in v),
        "states": lambda v: isinstance(v, list),
        "feature_counts": lambda v: (
            isinstance(v, list) and len(v) == F and all(is_int(c) for c in v)
        ),
        "reward": is_num,
        "constraints": lambda v: isinstance(v, list),
    }.items():
        assert key in d, f"{where}: missing {key}"
        assert test(d[key]), f"{where}.{key}: bad value {d[key]!r}"
    assert d["env_index"] == int("".join(map(str, d["env_code"])), 2), where
    check_state(d["start_state"], f"{where}.start_state")
    assert len(d["states"]) == len(d["actions"]) + 1, where
    for k, s in enumerate(d["states"]):
        check_state(s, f"{where}.states[{k}]")
    assert d["states"][0] == d["start_state"], where
    check_constraints(d["constraints"], f"{where}.constraints")
    # replay the actions in the domain: states, feature counts and reward must agree
    inst = SKATE.instance(tuple(d["env_code"]))
    s = inst.state_from_json(d["start_state"])
    mu = np.zeros(F)
    for k, a in enumerate(d["actions"]):
        s, phi, terminal = inst.step(s, ACTIONS.index(a))
        mu += phi
        assert inst.state_to_json(s) == d["states"][k + 1], f"{where}: replay differs at {k}"
    assert mu.tolist() == d["feature_counts"], where
    assert d["reward"] == pytest.approx(float(np.dot(weights, mu)), abs=1e-9), where


def check_common(data, schema):
    assert data["schema"] == schema
    assert data["domain"] == "skateboard"
    assert data["profile"] in ("default", "reference")
    assert is_int(data["seed"])
    assert isinstance(data["settings"], dict)
    assert data["feature_names"] == list(SKATE.feature_names)
    w = data["weights"]
    assert isinstance(w, list) and len(w) == F and all(is_num(v) for v in w)
    assert np.linalg.norm(w) == pytest.approx(1.0)
    assert np.allclose(w, SKATE.weights)


@pytest.fixture(scope="module")
def out(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("reproduce")
    result = WideRunner().invoke(
        app, ["reproduce", "--out", str(out), "--domains", "skateboard", "--seed", "0"]
    )
    assert result.exit_code == 0, result.output + repr(result.exception)
    assert "Report:" in result.output
    return out


def test_curricula_follow_the_schema(out):
    for cond in CONDITIONS:
        data = json.loads((out / "skateboard" / f"{cond}.json").read_text())
        check_common(data, "cfteach.curriculum/1")
        assert data["condition"] == cond
        # schemas.md: every curriculum records these; null where its condition uses none
        settings = data["settings"]
        for key in ("human_models", "max_demos", "proportion"):
            assert key in settings, (cond, key)
        assert isinstance(settings["max_demos"], int), cond
        uses_models = cond in ("counterfactual_only", "proposed")
        assert (settings["human_models"] is not None) == uses_models, cond
        assert (settings["proportion"] is not None) == uses_models, cond
        check_constraints(data["prior"], "prior")
        assert isinstance(data["demos"], list) and data["demos"], cond
        for k, d in enumerate(data["demos"]):
            where = f"{cond}.demos[{k}]"
            check_demo(d, where, data["weights"])
            assert is_num(d["knowledge_gain"]), where
            assert is_num(d["belief_area_after"]) and 0 < d["belief_area_after"] <= 4 * math.pi
            assert d["masked_feature"] is None or d["masked_feature"] in data["feature_names"]
        fb = data["final_belief"]
        assert set(fb) >= {"constraints", "area"}
        check_constraints(fb["constraints"], "final_belief")
        assert is_num(fb["area"]) and fb["area"] > 0
        # the true weights satisfy the final belief
        assert (np.array(fb["constraints"]) @ np.array(data["weights"]) >= -1e-9).all()


def test_tests_follow_the_schema(out):
    data = json.loads((out / "skateboard" / "tests.json").read_text())
    check_common(data, "cfteach.tests/1")
    check_constraints(data["belief"]["constraints"], "belief")
    assert is_num(data["belief"]["area"])
    for pair in data["excluded"]:
        assert isinstance(pair, list) and len(pair) == 2 and is_int(pair[0])
        check_state(pair[1], "excluded")
    centres = data["cluster_centres"]
    assert len(centres) == 5 and all(is_num(c) for c in centres) and centres == sorted(centres)
    assert set(data["tests"]) == {"low", "medium", "high"}
    excluded = {(p[0], json.dumps(p[1], sort_keys=True)) for p in data["excluded"]}
    for level, tests in data["tests"].items():
        assert tests, level
        for k, t in enumerate(tests):
            where = f"tests.{level}[{k}]"
            check_demo(t, where, data["weights"])
            assert is_num(t["overlap"]) and t["overlap"] >= 0, where
            assert t["difficulty"] == level, where
            assert isinstance(t["all_optimal_actions"], list) and t["all_optimal_actions"]
            for seq in t["all_optimal_actions"]:
                assert isinstance(seq, list) and all(a in ACTIONS for a in seq), where
            assert is_num(t["optimal_reward"]), where
            key = (t["env_index"], json.dumps(t["start_state"], sort_keys=True))
            assert key not in excluded, f"{where} is a training demonstration"
    # harder tests have smaller overlaps
    mean = {lv: np.mean([t["overlap"] for t in ts]) for lv, ts in data["tests"].items()}
    assert mean["high"] < mean["medium"] < mean["low"]


class _Srcs(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.srcs: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.srcs.append(a["src"])
        if tag == "a" and not a.get("href", "#").startswith("#"):
            self.srcs.append(a["href"])


def test_report_images_all_resolve(out):
    html = (out / "index.html").read_text(encoding="utf-8")
    parser = _Srcs()
    parser.feed(html)
    n_demos = sum(
        len(json.loads((out / "skateboard" / f"{c}.json").read_text())["demos"]) for c in CONDITIONS
    )
    assert len([s for s in parser.srcs if s.endswith(".gif")]) == n_demos
    for src in parser.srcs:
        assert not re.match(r"^[a-z]+:", src), src
        assert (out / src).is_file(), src
    assert all(p.suffix in {".gif", ".png"} for p in (out / "skateboard" / "img").iterdir())


def test_report_only_rebuilds_from_the_json(out):
    (out / "index.html").unlink()
    result = WideRunner().invoke(app, ["reproduce", "--out", str(out), "--report-only"])
    assert result.exit_code == 0, result.output
    html = (out / "index.html").read_text(encoding="utf-8")
    run = json.loads((out / "run.json").read_text())
    assert run["schema"] == "cfteach.run/1" and run["domains"] == ["skateboard"]
    assert run["profile"] == "default" and run["seed"] == 0 and run["seconds"] > 0
    assert "profile <b>default</b>" in html and "computed in" in html


def test_unknown_domain_is_a_clear_error(tmp_path):
    result = WideRunner().invoke(app, ["reproduce", "--out", str(tmp_path), "-d", "nowhere"])
    assert result.exit_code != 0
    assert "nowhere" in result.output


USER_TOML = """
[domain]
name = "keys"
title = "Keys"
description = "a user domain"
width = 4
height = 3
discount = 1.0
walls = [[2, 3]]

[cells]
lava = [[3, 1]]

[agent]
start = [1, 1]

[cargo]
name = "key"
start = [1, 3]

[[consumables]]
name = "coin"
cell = [4, 3]

[goal]
agent_at = [4, 1]

[[variants]]
add_cells = { lava = [[3, 2]] }

[[variants]]
add_cells = { lava = [[2, 2]] }

[[variants]]
switch_on = ["coin"]

[[features]]
name = "burn"
label = "Lava"
weight = -2.0
when = { leaves_cells = "lava" }

[[features]]
name = "coin"
label = "Coin"
weight = 1.0
when = { consumes = "coin" }

[[features]]
name = "step"
label = "Step"
weight = -1.0

[beliefs]
prior = [[0, 0, -1]]
posterior = [[-1, 0, 0], [0, 1, 0], [0, 0, -1]]
"""


def test_a_user_domain_file_goes_through_the_whole_job(tmp_path):
    path = tmp_path / "keys.toml"
    path.write_text(USER_TOML, encoding="utf-8")
    out = tmp_path / "out"
    result = WideRunner().invoke(app, ["reproduce", "--out", str(out), "-d", str(path)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    run = json.loads((out / "run.json").read_text())
    assert run["domains"] == ["keys"] and run["domain_files"] == {"keys": str(path.resolve())}
    (out / "index.html").unlink()
    result = WideRunner().invoke(app, ["reproduce", "--out", str(out), "--report-only"])
    assert result.exit_code == 0, result.output + repr(result.exception)
    parser = _Srcs()
    parser.feed((out / "index.html").read_text(encoding="utf-8"))
    assert any(s.endswith(".gif") for s in parser.srcs)
    for src in parser.srcs:
        assert (out / src).is_file(), src


def test_an_unknown_profile_is_named_before_any_work(tmp_path: Path) -> None:
    from cfteach.report.reproduce import reproduce

    with pytest.raises(ValueError, match=r"unknown profile 'nope'.*reference.*default"):
        reproduce(tmp_path / "out", ["skateboard"], profile="nope", report=False)
    assert not (tmp_path / "out").exists()


def test_domains_taught_side_by_side_give_the_one_process_json(tmp_path: Path) -> None:
    """Two local workers (one domain each, and a user domain file loaded by path in the
    worker) write exactly the JSON of one process, k-means centres included."""
    from cfteach.report.reproduce import reproduce

    path = tmp_path / "keys.toml"
    path.write_text(USER_TOML, encoding="utf-8")
    names = ["skateboard", str(path)]
    one, _ = reproduce(tmp_path / "one", names, report=False, workers=1)
    two, _ = reproduce(tmp_path / "two", names, report=False, workers=2)
    assert list(one) == list(two) == ["skateboard", "keys"]
    for name in one:
        assert one[name].curricula == two[name].curricula
        assert one[name].tests == two[name].tests
        for f in (tmp_path / "one" / name).glob("*.json"):
            assert f.read_text() == (tmp_path / "two" / name / f.name).read_text(), f


@pytest.mark.parametrize("args, message", [
    (["--workers", "0"], "--workers must be at least 1"),
    (["--backend", "daks"], "did you mean 'dask'"),
    (["--scheduler", "tcp://127.0.0.1:1"], "--scheduler needs --backend dask or ray"),
])
def test_bad_parallel_options_are_one_line_errors(tmp_path, args, message):
    result = WideRunner().invoke(app, ["reproduce", "--out", str(tmp_path / "o"), *args])
    assert result.exit_code == 2
    assert message in result.output and "Traceback" not in result.output
    assert not (tmp_path / "o").exists()
