"""Which instance and start each test of a study folder uses, read from `study.json`.

The study file stores each test as a playable table (states, successors, features) and a
drawing layout, not as an instance index, so the instance is found by matching: the layout's
cell sets and objects narrow the domain's instances down, and the table is then checked
transition by transition with `Instance.step` (so a wrong domain file cannot match).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True)
class TestRef:
    """Where a study test is played: the domain instance and the start state."""

    env_index: int
    env_code: str
    start_state: dict[str, Any]


def read_study(study_dir: str | Path) -> dict[str, Any]:
    """`study.json` of a study folder (ValueError with the path when missing or not one)."""
    path = Path(study_dir)
    if path.is_dir():
        path = path / "study.json"
    if not path.is_file():
        raise ValueError(f"{path}: no such file (give the folder `cfteach study init` wrote)")
    try:
        study = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not JSON ({e})") from None
    if not isinstance(study, dict) or study.get("schema") != "cfteach.study/1":
        raise ValueError(f"{path}: not a cfteach.study/1 file")
    return study


def load_tests(domain: Any, study_dir: str | Path) -> dict[str, TestRef]:
    """Every test of `domain` in the study folder, by test id."""
    study = read_study(study_dir)
    if domain.name not in study.get("tests", {}):
        raise ValueError(f"the study has no tests for domain {domain.name!r} "
                         f"(domains: {', '.join(study.get('domains', []))})")
    by_key: dict[tuple, list[Any]] = {}
    for inst in domain.instances():
        by_key.setdefault(_instance_key(inst), []).append(inst)
    out = {}
    for test_set in study["tests"][domain.name]:
        for t in test_set:
            inst = _match_instance(domain, t, by_key)
            start = t["game"]["states"][0]
            out[t["test_id"]] = TestRef(int(inst.index), "".join(map(str, inst.env_code)),
                                        start)
    return out


def _layout_key(layout: dict[str, Any]) -> tuple:
    regions = tuple(sorted((r["name"], tuple(map(tuple, r["cells"])))
                           for r in layout.get("regions", [])))
    cons = tuple(sorted(c["key"] for c in layout.get("consumables", [])))
    return regions, cons, layout.get("cargo") is not None


def _instance_key(inst: Any) -> tuple:
    spec = inst.domain.spec
    regions = tuple(sorted((n, tuple(sorted(tuple(int(v) for v in c) for c in inst.cells(n))))
                           for n in inst.cell_set_names))
    cons = tuple(sorted(n for (n, _), p in zip(spec.consumables, inst.consumables_present,
                                                 strict=True) if p))
    return regions, cons, bool(inst.cargo_present)


def _same_game(inst: Any, game: dict[str, Any]) -> bool:
    try:
        states = [inst.state_from_json(s) for s in game["states"]]
    except ValueError:
        return False
    for i, row in enumerate(game["next"]):
        if row is None:
            continue
        for a, j in enumerate(row):
            nxt, phi, _ = inst.step(states[i], a)
            if nxt != states[j] or not np.allclose(phi, game["phi"][i][a]):
                return False
    return True


def _match_instance(domain: Any, test: dict[str, Any], by_key: dict[tuple, list[Any]]) -> Any:
    for inst in by_key.get(_layout_key(test["layout"]), []):
        if _same_game(inst, test["game"]):
            return inst
    raise ValueError(f"test {test.get('test_id')!r}: no instance of domain {domain.name!r} "
                     "plays like it (was the study built from another domain file?)")
