"""User domain files: the documented example loads; malformed files name file, key and problem."""

from __future__ import annotations

import copy
import re
from pathlib import Path

import pytest

from cfteach.domains import DomainFileError, from_dict, load
from cfteach.domains.spec import load_toml

DOCS = Path(__file__).resolve().parents[1] / "docs" / "domains.md"


def _doc_example() -> str:
    text = DOCS.read_text()
    m = re.search(r"<!-- example-domain -->\s*```toml\n(.*?)```", text, re.S)
    assert m, "docs/domains.md lost its marked example"
    return m.group(1)


def test_documented_example_loads(tmp_path: Path) -> None:
    path = tmp_path / "corridor.toml"
    path.write_text(_doc_example())
    dom = load(path)
    assert dom.name == "corridor"
    insts = dom.instances()
    assert len(insts) == 4
    # Instance (0, 0): no key, no ice. Agent cells: 5x3 grid minus 2 walls minus the goal.
    assert len(insts[0].states()) == 12
    # With the key: (agent cells) x (key positions) + carrying.
    assert len(insts[1].states()) > 12
    assert insts[3].complexity == 3


def _valid() -> dict:
    return load_toml(Path(__file__).resolve().parents[1] / "src" / "cfteach" / "domains"
                     / "data" / "delivery.toml")


def _mutate(path: str, value: object) -> dict:
    data = copy.deepcopy(_valid())
    keys = re.findall(r"[^.\[\]]+|\[\d+\]", path)
    obj = data
    for k in keys[:-1]:
        obj = obj[int(k[1:-1])] if k.startswith("[") else obj[k]
    last = keys[-1]
    if value is _DELETE:
        del obj[last]
    elif last.startswith("["):
        obj[int(last[1:-1])] = value
    else:
        obj[last] = value
    return data


_DELETE = object()


@pytest.mark.parametrize(("path", "value", "key", "problem"), [
    ("domain.widht", 4, "domain.widht", "unknown key"),
    ("domain.width", "4", "domain.width", "must be an integer"),
    ("domain.width", _DELETE, "domain.width", "missing required key"),
    ("domain.walls", [[1, 4]], "domain.walls[0]", "off the 4x3 grid"),
    ("cells.mud", [[1, 2]], "cells.mud[0]", "on a wall"),
    ("agent.start", [1, 3], "agent.start", "on a wall"),
    ("agent.start", [0, 1], "agent.start", "off the"),
    ("goal.cargo_delivered_at", [1, 2], "goal.cargo_delivered_at", "on a wall"),
    ("variants[0].add_cells", {"lava": [[2, 2]]}, "variants[0].add_cells.lava",
     "unknown cell set 'lava'"),
    ("variants[5].switch_on", ["battery"], "variants[5].switch_on[0]", "unknown object"),
    ("features[0].when", {"leaves_cells": "swamp"}, "features[0].when.leaves_cells",
     "unknown cell set 'swamp'"),
    ("features[0].when", {"from_cell": "mud"}, "features[0].when.from_cell", "unknown key"),
    ("features[1].when", {"consumes": "fuel"}, "features[1].when.consumes", "unknown consumable"),
    ("features[1].when", {"action": ["jump"]}, "features[1].when.action[0]", "unknown action"),
    ("features[2].unless", ["later"], "features[2].unless[0]", "not an earlier feature"),
    ("features[2].name", "toll", "features[2].name", "duplicate feature name"),
    ("features[0].weight", "heavy", "features[0].weight", "must be a number"),
    ("features[0].weight", float("nan"), "features[0].weight", "must be finite"),
    ("beliefs.prior", [[0, 0]], "beliefs.prior[0]", "has 2 entries"),
    ("beliefs.prior", [[0, 0, 0.5]], "beliefs.prior[0][2]", "must be an integer"),
    ("consumables[0].name", "passenger", "consumables[0].name", "already used"),
    ("domain.actions", ["up", "up"], "domain.actions[1]", "twice"),
    ("domain.discount", 0.9, "domain.discount", "only 1.0"),
    ("teaching.max_demos", 0, "teaching.max_demos", "must be at least 1"),
    ("teaching.max_demos", "5", "teaching.max_demos", "must be an integer"),
    ("teaching.max_demo", 5, "teaching.max_demo", "unknown key"),
    ("teaching", 5, "teaching", "must be a table"),
])
def test_malformed_dict_errors(path: str, value: object, key: str, problem: str) -> None:
    with pytest.raises(DomainFileError) as exc:
        from_dict(_mutate(path, value), source="bad.toml")
    msg = str(exc.value)
    assert msg.startswith("bad.toml: "), msg
    assert exc.value.key == key, msg
    assert problem in msg, msg


def test_zero_weights_rejected() -> None:
    data = _valid()
    for f in data["features"]:
        f["weight"] = 0
    with pytest.raises(DomainFileError, match="all zero"):
        from_dict(data)


def test_goal_needs_exactly_one_kind() -> None:
    data = _valid()
    data["goal"] = {"agent_at": [4, 3], "cargo_delivered_at": [1, 1]}
    with pytest.raises(DomainFileError, match="exactly one"):
        from_dict(data)


def test_bad_toml_file_names_file(tmp_path: Path) -> None:
    p = tmp_path / "broken.toml"
    p.write_text("[domain\nname = 'x'\n")
    with pytest.raises(DomainFileError) as exc:
        load(p)
    assert str(p) in str(exc.value) and "not valid TOML" in str(exc.value)


def test_file_error_names_file(tmp_path: Path) -> None:
    p = tmp_path / "typo.toml"
    p.write_text(_doc_example().replace("width = 5", "width = 5\ncolour = 'red'"))
    with pytest.raises(DomainFileError) as exc:
        load(p)
    assert str(exc.value).startswith(f"{p}: domain.colour: unknown key")


def test_unknown_name_or_missing_path() -> None:
    with pytest.raises(ValueError, match="neither a built-in domain"):
        load("no_such_domain")


def test_teaching_max_demos_from_file_or_default() -> None:
    # the study's n_train_demos per built-in domain
    assert [load(n).max_demos for n in ("delivery", "tiles", "skateboard")] == [5, 5, 7]
    data = _mutate("teaching", _DELETE)
    assert from_dict(data).max_demos == 5
    assert from_dict(_mutate("teaching.max_demos", 3)).max_demos == 3
