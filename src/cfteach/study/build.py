"""`cfteach study init`: turn curricula + test sets into a self-contained study folder.

The folder holds one `study.json` with, per domain, every demonstration (states to replay and
the static layout to draw) and every test as a playable transition table built with the
domain's own `Instance.step`, so the server needs no teaching code at run time and a running
study cannot change under the participants' feet.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cfteach.mdp.scoring import is_optimal

from .controls import action_specs_of, controls
from .games import best_path, build_game, optimal_value, replay
from .identity import new_study_key
from .layout import instance_layout
from .practice import (
    ACTIONS,
    PRACTICE,
    PRACTICE_START_ENERGY,
    PRACTICE_WEIGHTS,
    CargoGrid,
)
from .texts import DOMAIN_TEXT, domain_text

CONDITIONS = ("baseline", "feature_only", "counterfactual_only", "proposed")
#: The live closed-loop condition: the server's `ClosedLoopTeacher` picks every item.
CLOSED_LOOP = "closed_loop"
ALL_CONDITIONS = (*CONDITIONS, CLOSED_LOOP)
LEVELS = ("low", "medium", "high")
STUDY_SCHEMA = "cfteach.study/1"


@dataclass
class DomainSource:
    """One domain's inputs: the domain object, a curriculum per condition, its test set."""

    domain: Any
    curricula: dict[str, dict]
    tests: dict


def init_study(out: str | Path, sources: Iterable[DomainSource], *,
               title: str = "Machine Teaching Study",
               completion_code: str = "COMPLETED", screened_out_code: str = "SCREENED",
               no_consent_code: str = "NOCONSENT",
               completion_url: str = "https://app.prolific.com/submissions/complete?cc=",
               test_sets: int = 3, demo_step_ms: int = 500, cutoff_minutes: float = 30.0,
               practice_attempts: int = 3, consent_html: str | None = None,
               conditions: Iterable[str] = CONDITIONS, teacher: dict | None = None,
               human_models: int = 32) -> Path:
    """Write `out/study.json` and return its path.

    `conditions`: any of the paper's four and ``closed_loop``. A ``closed_loop`` domain needs
    a built-in domain: its cell carries the teacher's settings (`teacher`, fields of
    `TeacherSettings`), the pool's parameters and the held-out tests (every test of the
    domain's test sets, the ones all conditions are tested on); the server rebuilds the
    lesson pool from them at start (`cfteach.study.live`).

    `consent_html`: your ethics board's consent text (HTML without scripts) shown above the
    three consent check boxes instead of the built-in generic one. `no_consent_code` is shown
    (and redirected to) when someone declines consent, for Prolific's "no consent" code.
    """
    sources = list(sources)
    if not sources:
        raise ValueError("a study needs at least one domain")
    chosen = check_conditions(conditions)
    open_loop = [c for c in chosen if c != CLOSED_LOOP]
    settings = _teacher_json(teacher) if CLOSED_LOOP in chosen else None
    domains: list[str] = []
    info: dict[str, dict] = {}
    curricula: dict[str, dict] = {}
    tests: dict[str, list] = {}
    closed: dict[str, dict] = {}
    for src in sources:
        name = src.domain.name
        if name in domains:
            raise ValueError(f"domain {name!r} is given twice")
        domains.append(name)
        missing = [c for c in open_loop if c not in src.curricula]
        if missing:
            raise ValueError(f"domain {name!r}: no curriculum for condition(s) {missing}")
        actions = tuple(src.domain.actions)
        instances = src.domain.instances()
        text = domain_text(name, tuple(src.domain.feature_names))
        # The built-in study domains keep the paper's key lists; any other domain plays
        # every action it declares, on the keys its ActionSpecs name.
        keys = list(text["keys"]) if name in DOMAIN_TEXT else list(actions)
        info[name] = {**text, "keys": keys, "feature_names": list(src.domain.feature_names),
                      "weights": [float(x) for x in src.domain.weights],
                      "action_names": list(actions),
                      "controls": controls(action_specs_of(src.domain), keys, name)}
        curricula[name] = {}
        for cond in open_loop:
            cur = src.curricula[cond]
            _check_schema(cur, "cfteach.curriculum/1", f"{name}/{cond}")
            if cur.get("domain") != name:
                raise ValueError(f"curriculum {name}/{cond} is for domain {cur.get('domain')!r}")
            demos = []
            for k, d in enumerate(cur["demos"]):
                inst = _instance(instances, d, f"{name}/{cond} demo {k}")
                if len(d["states"]) != len(d["actions"]) + 1:
                    raise ValueError(f"{name}/{cond} demo {k}: states must be actions + 1 long")
                demos.append({"layout": instance_layout(name, inst), "states": d["states"],
                              "actions": d["actions"]})
            if not demos:
                raise ValueError(f"curriculum {name}/{cond} has no demonstrations")
            curricula[name][cond] = demos
        _check_schema(src.tests, "cfteach.tests/1", f"{name}/tests")
        tests[name] = _split_tests(name, src.tests, instances, actions, info[name]["weights"],
                                   test_sets)
        if settings is not None:
            closed[name] = _closed_loop_cell(src, instances, settings, test_sets, human_models)
    pgame = build_game(PRACTICE, PRACTICE.initial_state, ACTIONS)
    best = optimal_value(pgame, list(PRACTICE_WEIGHTS))
    study = {
        "schema": STUDY_SCHEMA,
        "title": title,
        "conditions": chosen,
        "domains": domains,
        "test_sets": test_sets,
        "demo_step_ms": demo_step_ms,
        "cutoff_minutes": cutoff_minutes,
        "practice_attempts": practice_attempts,
        "consent_html": consent_html,
        "completion": {"completed": completion_code, "screened_out": screened_out_code,
                       "declined": no_consent_code, "url": completion_url},
        "practice": {"layout": PRACTICE.study_layout(), "game": pgame,
                     "weights": list(PRACTICE_WEIGHTS), "start_energy": PRACTICE_START_ENERGY,
                     "target_energy": PRACTICE_START_ENERGY + best},
        "domain_info": info,
        "curricula": curricula,
        "tests": tests,
    }
    if closed:  # absent otherwise, so a paper study's file (and version) stays as it was
        study["closed_loop"] = closed
    body = json.dumps(study, sort_keys=True, separators=(",", ":"))
    study["version"] = hashlib.sha256(body.encode()).hexdigest()[:12]
    # the study's identity (one session per Prolific participant): outside the version,
    # and kept when the folder is initialised again
    study["study_key"] = new_study_key(out)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "study.json"
    path.write_text(json.dumps(study, separators=(",", ":")))
    return path


def check_conditions(conditions: Iterable[str]) -> list[str]:
    """The chosen conditions in the given order; ValueError names an unknown or repeated one."""
    chosen = [c.strip() for c in conditions if c.strip()]
    if not chosen:
        raise ValueError("a study needs at least one condition")
    for c in chosen:
        if c not in ALL_CONDITIONS:
            raise ValueError(f"unknown condition {c!r} (known: {', '.join(ALL_CONDITIONS)})")
    if len(set(chosen)) != len(chosen):
        raise ValueError(f"a condition is given twice: {', '.join(chosen)}")
    return chosen


def _teacher_json(teacher: dict | None) -> dict:
    from cfteach.closedloop import TeacherSettings

    try:
        return TeacherSettings(**(teacher or {})).to_json()
    except TypeError as e:
        raise ValueError(f"closed-loop teacher settings: {e}") from None


def _closed_loop_cell(src: DomainSource, instances: list, settings: dict, n_sets: int,
                      human_models: int) -> dict:
    """What the server needs to run `closed_loop` in one domain (the pool is derived)."""
    from cfteach.domains import Domain, builtin_names

    name = src.domain.name
    if not isinstance(src.domain, Domain) or name not in builtin_names():
        raise ValueError(f"domain {name!r}: closed_loop needs a built-in domain "
                         f"({', '.join(builtin_names())}), which the server can rebuild")
    held = []
    for level in LEVELS:
        items = src.tests.get("tests", {}).get(level, [])
        per = len(items) // n_sets
        held += [{"env_index": t["env_index"], "start_state": t["start_state"]}
                 for t in items[: per * n_sets]]
    examples = [{"layout": instance_layout(name, inst),
                 "state": inst.state_to_json(inst.initial_state)} for inst in instances[:3]]
    # The teacher covers the `proposed` curriculum in order before it may stop, as in
    # `cfteach simulate` (docs/closed-loop.md, "The backbone"); without one, it teaches alone.
    proposed = src.curricula.get("proposed")
    backbone = [{"env_index": d["env_index"], "start_state": d["start_state"]}
                for d in (proposed or {}).get("demos", [])]
    return {"domain": name, "settings": settings, "held_out": held, "examples": examples,
            "backbone": backbone,
            "pool": {"profile": "default", "human_models": human_models, "seed": 0}}


def _check_schema(obj: dict, schema: str, what: str) -> None:
    if not isinstance(obj, dict) or obj.get("schema") != schema:
        got = obj.get("schema") if isinstance(obj, dict) else type(obj).__name__
        raise ValueError(f"{what}: expected schema {schema!r}, got {got!r}")


def _instance(instances: list, d: dict, what: str) -> Any:
    idx = d.get("env_index")
    if not isinstance(idx, int) or not 0 <= idx < len(instances):
        raise ValueError(f"{what}: env_index {idx!r} is not one of the domain's "
                         f"{len(instances)} instances")
    return instances[idx]


def _split_tests(name: str, ts: dict, instances: list, actions: tuple[str, ...],
                 weights: list[float], n_sets: int) -> list[list[dict]]:
    """Test set k gets tests [2k, 2k+1] of each difficulty (the paper's 3 alternative pairs)."""
    sets: list[list[dict]] = [[] for _ in range(n_sets)]
    for level in LEVELS:
        items = ts.get("tests", {}).get(level, [])
        per = len(items) // n_sets
        if per < 1:
            raise ValueError(f"{name}/tests: {len(items)} {level} test(s) cannot fill "
                             f"{n_sets} test sets")
        for i, t in enumerate(items[: per * n_sets]):
            what = f"{name}/tests {level}[{i}]"
            inst = _instance(instances, t, what)
            start = inst.state_from_json(t["start_state"])
            game = build_game(inst, start, actions)
            opt = float(t["optimal_reward"])
            check = replay(game, weights, list(t["actions"]))
            if not is_optimal(check.reward, opt, 1e-6):
                raise ValueError(f"{what}: replaying its optimal actions gives reward "
                                 f"{check.reward}, not optimal_reward {opt}")
            sets[i // per].append({
                "test_id": f"{name}-{level}-{i}", "difficulty": level,
                "overlap": _overlap(t.get("overlap")),
                "layout": instance_layout(name, inst), "game": game,
                "optimal_reward": opt, "optimal_length": len(t["actions"]),
            })
    return sets


def _overlap(x: Any) -> float | None:
    return None if x is None or x != x else float(x)  # NaN = unknown


def teaching_sources(names: Iterable[str] = ("delivery", "tiles", "skateboard"), *,
                     profile: str = "default", seed: int = 0,
                     progress: bool = False, known: str | None = None) -> list[DomainSource]:
    """The paper's study material: a curriculum per condition (`cfteach.teaching.teach`)
    and the domain's tests (`select_tests`, excluding every condition's demonstrations).
    `known`: as in `teach` (None: each domain file's ``[beliefs] known``)."""
    from cfteach.domains import load
    from cfteach.teaching import select_tests, teach

    out = []
    for name in names:
        dom = load(name)
        curricula = {c: teach(dom, c, profile=profile, seed=seed, progress=progress,
                              known=known) for c in CONDITIONS}
        tests = select_tests(dom, training=tuple(curricula.values()), profile=profile,
                             seed=seed, progress=progress, known=known)
        out.append(DomainSource(dom, {c: k.to_json() for c, k in curricula.items()},
                                tests.to_json()))
    return out


# ---------------------------------------------------------------------------------------
# A tiny self-contained study ("toy"), for trying the platform and for its tests.


class ToyDomain:
    """A 4 x 3 delivery-like domain on `CargoGrid`, following the `Domain` contract."""

    actions = ACTIONS
    feature_names = ("mud", "battery", "step")
    weights = (-0.635999, 0.741999, -0.211999)

    def __init__(self, name: str = "toy") -> None:
        self.name = name
        mud_sets = [frozenset(), frozenset({(2, 2)}), frozenset({(3, 1), (3, 2)}),
                    frozenset({(2, 1), (3, 3)})]
        self._instances = [
            CargoGrid(width=4, height=3, start=(2, 1), walls=frozenset({(1, 2), (1, 3)}),
                      cargo=(4, 2), destination=(1, 1), leave_cells=(("mud", m),),
                      consumable=("station", (4, 3)), consumable_initially=bool(k % 2),
                      cargo_name="passenger",
                      styles={"mud": "mud", "station": "station", "passenger": "package"})
            for k, m in enumerate(mud_sets)
        ]

    def instances(self) -> list[CargoGrid]:
        return list(self._instances)


def _optimal_path(inst: CargoGrid, start: tuple, weights) -> list[str]:  # noqa: ANN001
    return best_path(build_game(inst, start, ACTIONS), list(weights))


def _toy_demo(dom: ToyDomain, idx: int, start: tuple) -> dict:
    inst = dom.instances()[idx]
    acts = _optimal_path(inst, start, dom.weights)
    states, mu, s = [inst.state_to_json(start)], [0, 0, 0], start
    for a in acts:
        s, f, _ = inst.step(s, ACTIONS.index(a))
        states.append(inst.state_to_json(s))
        mu = [x + y for x, y in zip(mu, f, strict=True)]
    reward = float(sum(w * m for w, m in zip(dom.weights, mu, strict=True)))
    return {"env_code": [idx >> 1 & 1, idx & 1], "env_index": idx,
            "start_state": inst.state_to_json(start), "actions": acts, "states": states,
            "feature_counts": mu, "reward": reward, "constraints": []}


def toy_sources(names: tuple[str, ...] = ("toy_a", "toy_b", "toy_c"),
                demos: int = 2) -> list[DomainSource]:
    """Three small domains with short curricula and 6 tests per level."""
    out = []
    for name in names:
        dom = ToyDomain(name)
        cur = {}
        for c, cond in enumerate(CONDITIONS):
            ds = [_toy_demo(dom, (k + c) % 4, dom.instances()[(k + c) % 4].initial_state)
                  for k in range(demos)]
            for d in ds:
                d.update(knowledge_gain=0.0, belief_area_after=0.0, masked_feature=None)
            cur[cond] = {"schema": "cfteach.curriculum/1", "domain": name, "condition": cond,
                         "profile": "default", "seed": 0, "settings": {},
                         "feature_names": list(dom.feature_names), "weights": list(dom.weights),
                         "prior": [[0, 0, -1]], "demos": ds,
                         "final_belief": {"constraints": [], "area": 0.0}}
        starts = [(2, 1, 4, 2, 0, 1), (3, 3, 4, 2, 0, 1), (4, 1, 4, 2, 0, 1),
                  (2, 1, 2, 1, 1, 1), (4, 3, 4, 2, 0, 1), (3, 1, 3, 3, 0, 1)]
        tests: dict[str, list] = {}
        for li, level in enumerate(LEVELS):
            tests[level] = []
            for k in range(6):
                idx = (k + li) % 4
                inst = dom.instances()[idx]
                st = starts[(k + 2 * li) % 6]
                st = (*st[:5], int(inst.consumable_initially))
                t = _toy_demo(dom, idx, st)
                t.update(overlap=1.0 / (li + 1), difficulty=level,
                         all_optimal_actions=[t["actions"]], optimal_reward=t["reward"])
                tests[level].append(t)
        ts = {"schema": "cfteach.tests/1", "domain": name, "profile": "default", "seed": 0,
              "settings": {}, "feature_names": list(dom.feature_names),
              "weights": list(dom.weights), "belief": {"constraints": [], "area": 0.0},
              "excluded": [], "cluster_centres": [], "tests": tests}
        out.append(DomainSource(dom, cur, ts))
    return out


# ---------------------------------------------------------------------------------------
# Placeholder material on the real domains, to preview pages before curricula exist.


def _demo_from(dom: Any, inst: Any, start: Any) -> dict:
    game = build_game(inst, start, tuple(dom.actions))
    acts = best_path(game, [float(w) for w in dom.weights])
    states, s, mu = [inst.state_to_json(start)], start, None
    for a in acts:
        s, f, _ = inst.step(s, list(dom.actions).index(a))
        mu = f if mu is None else mu + f
        states.append(inst.state_to_json(s))
    mu = [0] * len(dom.weights) if mu is None else [int(x) for x in mu]
    reward = float(sum(float(w) * m for w, m in zip(dom.weights, mu, strict=True)))
    return {"env_code": list(inst.env_code), "env_index": inst.index,
            "start_state": inst.state_to_json(start), "actions": acts, "states": states,
            "feature_counts": mu, "reward": reward, "constraints": []}


def preview_sources(names: Iterable[Any] = ("delivery", "tiles", "skateboard"), *,
                    demos: int = 3, seed: int = 0) -> list[DomainSource]:
    """Placeholder curricula and tests on real domains (NOT the paper's: optimal
    demonstrations from random instances, tests with arbitrary difficulty labels), for
    previewing and load-testing the platform before `cfteach reproduce` has run.
    `names` holds domain names or paths, or domain objects."""
    import random

    from cfteach.domains import load

    rng = random.Random(seed)
    out = []
    for given in names:
        dom = load(given) if isinstance(given, str | Path) else given
        name = dom.name
        insts = dom.instances()
        rich = sorted(insts, key=lambda i: -i.complexity)[: max(1, len(insts) // 2)]
        picks = [rng.choice(rich) for _ in range(demos)]
        ds = [_demo_from(dom, i, i.initial_state) for i in picks]
        cur = {c: {"schema": "cfteach.curriculum/1", "domain": name, "condition": c,
                   "profile": "preview", "seed": seed, "settings": {},
                   "feature_names": list(dom.feature_names),
                   "weights": [float(w) for w in dom.weights], "prior": [], "demos": ds,
                   "final_belief": {"constraints": [], "area": 0.0}} for c in CONDITIONS}
        tests: dict[str, list] = {lv: [] for lv in LEVELS}
        for lv in LEVELS:
            while len(tests[lv]) < 6:
                inst = rng.choice(rich)
                start = rng.choice(inst.states())
                t = _demo_from(dom, inst, start)
                if not t["actions"]:
                    continue
                t.update(overlap=None, difficulty=lv,
                         all_optimal_actions=[t["actions"]], optimal_reward=t["reward"])
                tests[lv].append(t)
        ts = {"schema": "cfteach.tests/1", "domain": name, "profile": "preview", "seed": seed,
              "settings": {}, "feature_names": list(dom.feature_names),
              "weights": [float(w) for w in dom.weights],
              "belief": {"constraints": [], "area": 0.0}, "excluded": [],
              "cluster_centres": [], "tests": tests}
        out.append(DomainSource(dom, cur, ts))
    return out
